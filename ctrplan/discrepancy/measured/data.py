"""Measured data for the discrepancy workflow: loading, motion history and configuration groups.

Three inputs are accepted:

- a CSV in the project's one column schema (:mod:`ctrplan.io.tables`), SI units: ``alpha_i``
  [rad], ``beta_i`` [m], ``tip_x..z`` [m], optionally ``tangent_x..z`` or ``R_11..R_33``,
  ``time`` [s], ``sequence`` (id of one continuous motion), ``eta_i``, and the pass-through
  columns ``config_id`` (same id = same configuration, e.g. the four approaches of the paper's
  protocol) and ``subset`` (``calibration`` / ``validation``);
- the whitespace format of Ha's measured trajectory (``../shared/data/ha-three-tube-trajectory``),
  read by :func:`ctrplan.io.tables.load_ha_trajectory` (any other file not ending in ``.csv``);
- a ROS 2 bag (rosbag2 folder, or ``.mcap`` / ``.db3`` file): joint states and tip poses at their
  own stamps and rates, the joints read at the pose stamps within each continuous motion
  (:func:`ctrplan.io.ros2.read_bag_measurements`).

The motion history of every sample (direction of each pair's last rotation, release by a later
translation, history effects such as backlash or a tracker lag) is read by
:mod:`ctrplan.history` along the whole recorded motion, so that a subset of samples (a
calibration block) keeps the history of the samples before it.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pandas as pd

from ...choices import PoseFrame
from ...errors import CtrplanError, DataFileError
from ...history import HistoryState, MotionRecord, motion_state
from ...io.ros2 import BagSelection, is_bag, read_bag_measurements
from ...io.tables import measurements_from_frame, read_measurements

__all__ = ["MeasuredData", "load_measured_data", "configuration_groups"]

#: Joints that differ by less than these are "the same configuration" [rad], [m].
SAME_ROTATION = 1e-3
SAME_TRANSLATION = 1e-5


@dataclass(frozen=True, eq=False)
class MeasuredData:
    """Measured tip poses along a motion history, SI units.

    Attributes
    ----------
    alpha, beta : ndarray, shape (K, n)
        Base rotations [rad] and translations [m].
    tip : ndarray, shape (K, 3)
        Measured tip positions [m] (tracker frame if ``frame == "tracker"``).
    tangent : ndarray or None, shape (K, 3)
        Measured unit tip tangents.
    eta : ndarray of int, shape (K, n - 1)
        Direction of the last relative rotation of each pair (+1 CCW, -1 CW, 0 unknown), Eq. (38),
        from the recorded motion (:func:`ctrplan.history.motion_state`), or from the file's
        ``eta_*`` columns where the record holds no rotation of the pair (e.g. one sample per
        sequence).
    translation_last : ndarray of bool, shape (K, n - 1)
        A translation came after the pair's last rotation (twist released, Section V-B).
    sequence : ndarray of int, shape (K,)
        Continuous-motion id; rows of one sequence are in time order.
    config_id : ndarray of int, shape (K,)
        Configuration group (rows at the same joint values share it).
    subset : ndarray of str or None, shape (K,)
        ``"calibration"`` / ``"validation"`` when the file gives the split.
    time : ndarray or None, shape (K,) [s]
    file : str
    frame : PoseFrame
        Frame of ``tip`` and ``tangent``.
    record : MotionRecord
        The whole recorded motion (every row of the file), joints [rad, m], times [s].
    rows : ndarray of int, shape (K,)
        Index of each sample in ``record``.
    given_eta : ndarray of int, shape (N, n - 1)
        The file's ``eta_*`` columns for the whole record (0 where not given).
    source : dict or None
        For a bag, what was read from it (:attr:`ctrplan.io.ros2.BagMeasurements.summary`).
    """

    alpha: np.ndarray
    beta: np.ndarray
    tip: np.ndarray
    tangent: np.ndarray | None
    eta: np.ndarray
    translation_last: np.ndarray
    sequence: np.ndarray
    config_id: np.ndarray
    subset: np.ndarray | None
    time: np.ndarray | None
    file: str
    frame: PoseFrame
    record: MotionRecord
    rows: np.ndarray
    given_eta: np.ndarray
    source: dict | None = None
    _states: dict = field(default_factory=dict, repr=False, compare=False)

    @property
    def n_samples(self) -> int:
        return self.alpha.shape[0]

    def take(self, rows) -> "MeasuredData":
        """The rows ``rows`` (index array or boolean mask), in their original order; the record
        stays whole, so their history is the one the whole motion gives."""
        rows = np.flatnonzero(rows) if np.asarray(rows).dtype == bool else np.asarray(rows, dtype=int)
        pick = (lambda a: None if a is None else a[rows])
        return replace(self, alpha=self.alpha[rows], beta=self.beta[rows], tip=self.tip[rows],
                       tangent=pick(self.tangent), eta=self.eta[rows],
                       translation_last=self.translation_last[rows], sequence=self.sequence[rows],
                       config_id=self.config_id[rows], subset=pick(self.subset), time=pick(self.time),
                       rows=self.rows[rows])

    def state(self, robot, effects=None) -> HistoryState:
        """The history state of these samples with ``robot``'s and the given history effects,
        computed along the whole recorded motion (:func:`ctrplan.effects.history_state`, tracker
        effects included) and taken at :attr:`rows`.

        Parameters
        ----------
        robot : Robot
        effects : mapping, optional
            ``{effect: {parameter: value}}`` [SI].

        Returns
        -------
        HistoryState
            K samples.

        Raises
        ------
        ValueError
            A time offset on data without times.
        """
        from ...effects import REGISTRY, history_state, robot_effects

        # the state depends only on the effects that act on the motion: keep one per such set
        acting = robot_effects(robot).merged(effects or {})
        key = tuple((n, tuple(sorted(acting[n].items()))) for n in acting
                    if REGISTRY[n].operator is not None or REGISTRY[n].friction_angle is not None)
        state = self._states.get(key)
        if state is None:
            if len(self._states) > 32:
                self._states.clear()
            state = self._states[key] = history_state(robot, self.record, effects, given_eta=self.given_eta)
        return state.take(self.rows)


def _is_whitespace_format(path: Path) -> bool:
    return path.suffix.lower() != ".csv"


def load_measured_data(path: str | os.PathLike, robot, *, frame: PoseFrame | str | None = None,
                       bag: BagSelection | None = None) -> MeasuredData:
    """Load measured data and complete its motion history.

    Parameters
    ----------
    path : str or path-like
        CSV in the project schema, a ROS 2 bag (folder, ``.mcap`` or ``.db3``), or Ha's whitespace
        trajectory format (any other file).
    robot : Robot
        Gives the number of tubes (and, for a bag, the joint names); joints are checked against
        its limits.
    frame : PoseFrame or str, optional
        Frame of the measured poses (``"robot"`` or ``"tracker"``). Default: ``"tracker"`` for Ha's format (its README: the
        registration is not given) and for a bag (a tracker's poses), ``"robot"`` for CSV.
    bag : BagSelection, optional
        Topics, child frame and joint names to read from a bag (default: the bag's only ones).

    Returns
    -------
    MeasuredData

    Raises
    ------
    DataFileError
        Missing file or column, non-numeric or non-finite value (named by column and row),
        values that look like millimetres or degrees, a tangent that is not a unit vector, fewer
        than 2 samples, a bad ``subset`` value, or a configuration outside the robot's joint
        limits (named by row); for a bag, what :func:`ctrplan.io.ros2.read_bag_measurements` raises.
    """
    path = Path(path)
    file = str(path)
    n = robot.n_tubes
    if not path.exists():
        raise DataFileError(f"{file}: file does not exist")
    source = None
    if is_bag(path):
        read = read_bag_measurements(path, robot, bag or BagSelection())
        source = read.summary
        meas = measurements_from_frame(read.table, n, file)
        tmp = dict(alpha=meas.alpha, beta=meas.beta, tip=meas.tip, tangent=meas.tangent, eta=None,
                   time=meas.time, table=meas.frame)
        default_frame = PoseFrame.TRACKER
    elif _is_whitespace_format(path):
        from ...io.tables import load_ha_trajectory

        table = load_ha_trajectory(path)
        tmp = _frame_to_arrays(table, n, file)
        default_frame = PoseFrame.TRACKER
    else:
        meas = read_measurements(path, n)
        tmp = dict(alpha=meas.alpha, beta=meas.beta, tip=meas.tip, tangent=meas.tangent, eta=meas.eta,
                   time=meas.time, table=meas.frame)
        default_frame = PoseFrame.ROBOT
    try:
        frame = PoseFrame(frame or default_frame)
    except ValueError:
        raise ValueError(f"frame must be 'robot' or 'tracker', got {frame!r}") from None
    table = tmp["table"]
    k = tmp["alpha"].shape[0]
    if k < 2:
        raise DataFileError(f"{file}: {k} sample(s); the workflow needs many more")
    sequence = (table["sequence"].to_numpy(float).astype(int) if "sequence" in table
                else np.arange(k))
    for r in range(k):
        try:
            robot.check_configuration(tmp["alpha"][r], tmp["beta"][r])
        except CtrplanError as exc:  # JointLimitError / PhysicalParameterError
            raise DataFileError(f"{file}: row {r + 1}: {exc}") from None
    time = tmp["time"]
    try:
        record = MotionRecord(tmp["alpha"], tmp["beta"], time, sequence)
    except ValueError as exc:
        raise DataFileError(f"{file}: {exc}") from None
    given_eta = (np.zeros((k, n - 1), dtype=int) if tmp["eta"] is None
                 else np.asarray(tmp["eta"], dtype=int).reshape(k, n - 1))
    hist = motion_state(record, given_eta=given_eta)
    if "config_id" in table:
        config_id = pd.to_numeric(table["config_id"], errors="coerce").to_numpy(float)
        bad = np.flatnonzero(~np.isfinite(config_id))
        if bad.size:
            raise DataFileError(f"{file}: column 'config_id', row {bad[0] + 1}: not an integer "
                                f"({table['config_id'].iloc[bad[0]]!r})")
        config_id = config_id.astype(int)
    else:
        config_id = configuration_groups(tmp["alpha"], tmp["beta"])
    subset = None
    if "subset" in table:
        subset = table["subset"].astype(str).str.strip().to_numpy()
        bad = np.flatnonzero(~np.isin(subset, ("calibration", "validation")))
        if bad.size:
            raise DataFileError(f"{file}: column 'subset', row {bad[0] + 1}: {subset[bad[0]]!r} is "
                                f"neither 'calibration' nor 'validation'")
    return MeasuredData(alpha=tmp["alpha"], beta=tmp["beta"], tip=tmp["tip"], tangent=tmp["tangent"],
                        eta=hist.eta.astype(int), translation_last=np.asarray(hist.released, bool),
                        sequence=sequence, config_id=config_id, subset=subset, time=time,
                        file=file, frame=frame, record=record, rows=np.arange(k), given_eta=given_eta,
                        source=source)


def _frame_to_arrays(table: pd.DataFrame, n: int, file: str) -> dict:
    alpha = table[[f"alpha_{i}" for i in range(1, n + 1)]].to_numpy(float)
    beta = table[[f"beta_{i}" for i in range(1, n + 1)]].to_numpy(float)
    if alpha.shape[1] != n:
        raise DataFileError(f"{file}: data for {alpha.shape[1]} tubes, robot has {n}")
    tip = table[["tip_x", "tip_y", "tip_z"]].to_numpy(float)
    tangent = table[["tangent_x", "tangent_y", "tangent_z"]].to_numpy(float)
    return dict(alpha=alpha, beta=beta, tip=tip, tangent=tangent, eta=None,
                time=table["time"].to_numpy(float), table=table)


def configuration_groups(alpha, beta, rotation_bin: float | None = None,
                         translation_bin: float | None = None) -> np.ndarray:
    """Group rows by configuration.

    Parameters
    ----------
    alpha, beta : array-like, shape (K, n)
        [rad], [m].
    rotation_bin, translation_bin : float, optional
        Bin widths [rad], [m]. Default: "the same configuration" (1e-3 rad, 1e-5 m). Coarser
        bins group nearby configurations of a continuous trajectory. Rotations are binned on
        the circle (wrapped to [-pi, pi)).

    Returns
    -------
    ndarray of int, shape (K,)
        Group ids 0..G-1 in order of first appearance.
    """
    alpha, beta = np.asarray(alpha, float), np.asarray(beta, float)
    rb = SAME_ROTATION if rotation_bin is None else rotation_bin
    tb = SAME_TRANSLATION if translation_bin is None else translation_bin
    wrapped = (alpha + np.pi) % (2 * np.pi) - np.pi
    ka = np.round(wrapped / rb).astype(np.int64)
    # -pi and +pi are the same angle
    ka[ka == np.round(np.pi / rb)] = np.round(-np.pi / rb)
    kb = np.round(beta / tb).astype(np.int64)
    keys = np.concatenate([ka, kb], axis=1)
    _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(np.argsort(first))
    return order[inverse.ravel()]
