"""Output files of a plan: ``path.csv``, ``trajectory.csv``, ``summary.json`` and figures, plus a
short human-readable summary.

Every file is written atomically (:mod:`ctrplan.io.atomic`: temporary file in the same folder, then
``os.replace``), so an interrupted run leaves either the complete file or none. ``summary.json`` is
written last: its presence means every other output of the run is complete.

Column schema (SI units, full float precision):

``path.csv``
    ``waypoint`` (0-based index), ``motion`` (``start``, ``rotation``, ``translation``), one column
    per joint (``alpha_i`` [rad], ``beta_i`` [m]), ``tip_x``, ``tip_y``, ``tip_z`` [m],
    ``bound_position_m`` [m] (the exact bound given the last motion), ``calibrated_bound_m`` [m] (the
    calibrated bound of the robot file's ``[bound_calibration]``, ``factor (bound + noise margin)``;
    empty without one), ``planned_bound_m`` [m] (the same
    quantity as the planner's bound map gave it; empty when no map was used), ``bound_angle_rad``
    [rad], ``bound_kind`` (``friction`` or ``translation_last``), ``predicted_tip_x``,
    ``predicted_tip_y``, ``predicted_tip_z`` [m] (the tip predicted for the motion history the
    ordered plan creates, :func:`ctrplan.mechanics.predict_tip`), ``predicted_offset_m`` [m] (its
    distance from the standard-model tip), ``prediction_eta`` (friction direction applied per
    pair, ``+1;-1``, 0 where the pair is frictionless in the prediction) and
    ``prediction_cases`` (per pair: ``friction``, ``translation_last``, ``no_history`` or
    ``frictionless``, joined by ``;``); the prediction columns are empty where no prediction was
    given or it failed.
``trajectory.csv``
    ``t`` [s], then per joint ``<name>`` [rad or m], ``<name>_vel`` [per s], ``<name>_acc``
    [per s^2].
``summary.json``
    Flat or nested dict; numeric keys carry their unit as a suffix (``max_bound_mm``,
    ``duration_s``).
"""

from __future__ import annotations

import csv
import io
import json
import math
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from ...choices import BoundKind, MotionKind
from ...io.atomic import atomic_write_text
from ...trajectory import Trajectory

__all__ = ["PATH_FILE", "TRAJECTORY_FILE", "SUMMARY_FILE", "BOUND_KINDS", "path_columns",
           "write_plan_outputs", "write_trajectory_csv", "format_summary", "jsonable", "PlanFolder",
           "read_plan_folder"]

#: File name of the ordered waypoints.
PATH_FILE = "path.csv"
#: File name of the time-parameterized trajectory.
TRAJECTORY_FILE = "trajectory.csv"
#: File name of the summary, written last.
SUMMARY_FILE = "summary.json"
#: Values of the ``bound_kind`` column of ``path.csv``: the friction bound, or the
#: translation-last bound (the waypoint is reached by a translation).
BOUND_KINDS = tuple(BoundKind)
_MOTIONS = tuple(MotionKind)
_TIP_COLUMNS = ("tip_x", "tip_y", "tip_z")
_BOUND_COLUMNS = ("bound_position_m", "calibrated_bound_m", "planned_bound_m", "bound_angle_rad", "bound_kind")
_PREDICTION_COLUMNS = ("predicted_tip_x", "predicted_tip_y", "predicted_tip_z", "predicted_offset_m",
                       "prediction_eta", "prediction_cases")

# Unit suffixes of summary keys -> (unit shown, factor from the key's unit to the shown unit).
# Longest suffix first; lengths in m are shown in mm and angles in rad in degrees.
_SUMMARY_UNITS = (
    ("_rad_s", "deg/s", math.degrees(1.0)),
    ("_m_s", "mm/s", 1e3),
    ("_mm", "mm", 1.0),
    ("_deg", "deg", 1.0),
    ("_rad", "deg", math.degrees(1.0)),
    ("_hz", "Hz", 1.0),
    ("_ms", "ms", 1.0),
    ("_m", "mm", 1e3),
    ("_s", "s", 1.0),
)


@dataclass(frozen=True, eq=False)
class PlanFolder:
    """A plan's output folder read back (:func:`read_plan_folder`), in SI units.

    Attributes
    ----------
    folder : pathlib.Path
    joint_names : tuple of str
        From ``path.csv``'s columns, in robot joint order.
    q : ndarray, shape (K, n_joints)
        Ordered waypoints [rad or m].
    motion : tuple of str, length K
        ``"start"``, ``"rotation"`` or ``"translation"``: the motion that reaches each waypoint.
    tip_position : ndarray, shape (K, 3)
        Standard-model tip at each waypoint [m].
    bound_position_m : ndarray, shape (K,)
        Exact bound given the last motion [m] (NaN where empty).
    bound_kind : tuple of str, length K
        ``"friction"`` or ``"translation_last"``.
    goal_waypoints : tuple of int
        Waypoint index of each goal (``summary.json``'s ``goal_prediction``).
    final_motion : str
        How the motion reaching each goal ends (``summary.json``), ``""`` if not recorded.
    scenario_file : str or None
        The scenario the plan was made from (``summary.json``), None if not recorded.
    trajectory : dict of str to ndarray, or None
        ``t`` (T,) [s], ``position``, ``velocity``, ``acceleration`` (T, n_joints) [rad or m per
        s^k] from ``trajectory.csv``; None without that file.
    summary : mapping
        ``summary.json`` as written (report units in its keys' suffixes), read-only.
    """

    folder: Path
    joint_names: tuple
    q: np.ndarray
    motion: tuple
    tip_position: np.ndarray
    bound_position_m: np.ndarray
    bound_kind: tuple
    goal_waypoints: tuple
    final_motion: str
    scenario_file: str | None
    trajectory: Mapping[str, np.ndarray] | None
    summary: Mapping[str, Any]


def read_plan_folder(out_dir) -> PlanFolder:
    """Read a plan's output folder (``path.csv``, ``trajectory.csv`` if written, ``summary.json``)
    back into a :class:`PlanFolder`: the one reader of the files :func:`write_plan_outputs`
    writes.

    Parameters
    ----------
    out_dir : str or path-like
        A folder written by :func:`ctrplan.plan` (``out_dir``) or ``ctrplan plan``.

    Returns
    -------
    PlanFolder

    Raises
    ------
    FileNotFoundError
        No ``summary.json`` (the run did not finish: it is written last) or no ``path.csv``.
    ValueError
        A file that is not what :func:`write_plan_outputs` writes (naming the file and what is
        missing).
    """
    out = Path(out_dir)
    summary_path, path_path = out / SUMMARY_FILE, out / PATH_FILE
    if not summary_path.is_file():
        raise FileNotFoundError(f"{summary_path}: no summary (a plan's folder has it once its run finished)")
    try:
        summary = json.loads(summary_path.read_text())
    except json.JSONDecodeError as exc:
        raise ValueError(f"{summary_path}: not JSON ({exc})") from None
    with open(path_path, newline="") as fh:
        reader = csv.DictReader(fh)
        header = list(reader.fieldnames or [])
        rows = list(reader)
    if header[:2] != ["waypoint", "motion"] or "tip_x" not in header:
        raise ValueError(f"{path_path}: not a plan's path.csv (columns {header[:4]}...)")
    names = tuple(header[2:header.index("tip_x")])

    def column(key, convert=float):
        return [convert(r[key]) if r[key] != "" else math.nan for r in rows]

    traj = None
    if (out / TRAJECTORY_FILE).is_file():
        table = np.genfromtxt(out / TRAJECTORY_FILE, delimiter=",", names=True)
        try:
            traj = MappingProxyType({
                "t": np.atleast_1d(table["t"]),
                "position": np.column_stack([np.atleast_1d(table[n]) for n in names]),
                "velocity": np.column_stack([np.atleast_1d(table[f"{n}_vel"]) for n in names]),
                "acceleration": np.column_stack([np.atleast_1d(table[f"{n}_acc"]) for n in names])})
        except ValueError as exc:
            raise ValueError(f"{out / TRAJECTORY_FILE}: a column is missing ({exc})") from None
    goals = summary.get("goal_prediction") or {}
    try:
        goal_waypoints = tuple(int(goals[f"goal_{k + 1}"]["waypoint"]) for k in range(len(goals)))
    except (KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"{summary_path}: goal_prediction without a waypoint per goal ({exc})") from None
    q = np.array([column(n) for n in names], dtype=float).T.reshape(len(rows), len(names))
    return PlanFolder(folder=out, joint_names=names, q=q, motion=tuple(r["motion"] for r in rows),
                      tip_position=np.array([column(c) for c in _TIP_COLUMNS], dtype=float).T.reshape(len(rows), 3),
                      bound_position_m=np.array(column("bound_position_m"), dtype=float),
                      bound_kind=tuple(r.get("bound_kind", "") for r in rows), goal_waypoints=goal_waypoints,
                      final_motion=str(summary.get("final_motion", "")), scenario_file=summary.get("scenario_file"),
                      trajectory=traj, summary=MappingProxyType(summary))


def path_columns(joint_names: Sequence[str]) -> list[str]:
    """Columns of ``path.csv`` for the given joints, in order."""
    return ["waypoint", "motion", *joint_names, *_TIP_COLUMNS, *_BOUND_COLUMNS, *_PREDICTION_COLUMNS]


def write_plan_outputs(out_dir, ordered_path_rows: Sequence[Mapping[str, Any]],
                       trajectory: Trajectory | None, summary: Mapping[str, Any], *,
                       joint_names: Sequence[str] | None = None,
                       figures: Mapping[str, Callable[[Path], Any]] | None = None) -> dict[str, Path]:
    """Write ``path.csv``, ``trajectory.csv``, the figures and ``summary.json`` into ``out_dir``.

    Parameters
    ----------
    out_dir : str or Path
        Output folder (created if missing).
    ordered_path_rows : sequence of mapping
        One per waypoint, in path order, with keys ``motion``; the joint values, either ``q``
        (array-like, shape (n_joints,), [rad or m], in the order of ``joint_names``) or one key per
        joint name; the tip position, either ``tip`` (shape (3,) [m]) or ``tip_x``, ``tip_y``,
        ``tip_z`` [m]; ``bound_position_m`` [m]; ``bound_angle_rad`` [rad]; ``bound_kind``
        (``"friction"`` or ``"translation_last"``). Optional: ``calibrated_bound_m`` [m] (empty when
        missing or NaN), ``planned_bound_m`` [m] (the bound
        map's value of the same quantity; NaN, written empty, when missing), ``predicted_tip``
        (shape (3,) [m]), ``predicted_offset_m`` [m], ``prediction_eta`` and
        ``prediction_cases`` (str) (empty when missing or NaN), and a ``waypoint`` index
        (default: the row number). Other keys are ignored.
    trajectory : Trajectory or None
        Written to ``trajectory.csv`` (skipped when None).
    summary : mapping
        JSON-serializable after converting numpy scalars and arrays; non-finite numbers are
        written as ``null``. ``duration_s``, ``n_waypoints`` and ``n_segments`` are added from the
        trajectory when missing.
    joint_names : sequence of str, optional
        Default ``trajectory.joint_names``; required without a trajectory.
    figures : mapping of str to callable, optional
        File name -> function that writes that figure to the path it is given (e.g. a partial
        of :func:`~ctrplan.planning.outputs.figures.plot_joint_trajectories`); called with ``out_dir / name``.

    Returns
    -------
    dict of str to Path
        Written files by name.

    Raises
    ------
    ValueError
        A row lacks a key or has a bad motion or bound kind (naming the row and the key), or the
        joint names are missing.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if joint_names is None:
        if trajectory is None:
            raise ValueError("joint_names is required when no trajectory is given")
        joint_names = trajectory.joint_names
    names = list(joint_names)
    written: dict[str, Path] = {}

    atomic_write_text(out / PATH_FILE, _path_csv(ordered_path_rows, names))
    written[PATH_FILE] = out / PATH_FILE
    if trajectory is not None:
        atomic_write_text(out / TRAJECTORY_FILE, _trajectory_csv(trajectory))
        written[TRAJECTORY_FILE] = out / TRAJECTORY_FILE
    for name, draw in (figures or {}).items():
        draw(out / name)
        written[name] = out / name

    data = dict(summary)
    if trajectory is not None:
        data.setdefault("duration_s", trajectory.duration)
        data.setdefault("n_waypoints", int(trajectory.waypoints.shape[0]))
        data.setdefault("n_segments", len(trajectory.segments))
    atomic_write_text(out / SUMMARY_FILE, json.dumps(jsonable(data), indent=2) + "\n")
    written[SUMMARY_FILE] = out / SUMMARY_FILE
    return written


def format_summary(summary: Mapping[str, Any], indent: int = 0) -> str:
    """Human-readable summary, one ``label: value unit`` line per key.

    Keys ending in a unit suffix are converted for reading: ``_m`` is shown in mm, ``_rad`` in
    degrees, ``_mm``, ``_deg``, ``_s``, ``_ms``, ``_hz`` as they are (e.g. ``max_bound_m = 0.0012``
    prints ``max bound: 1.2 mm``). Nested mappings are indented.

    Parameters
    ----------
    summary : mapping
    indent : int
        Spaces before each line.

    Returns
    -------
    str
    """
    pad = " " * indent
    lines = []
    for key, value in summary.items():
        if isinstance(value, Mapping):
            lines.append(f"{pad}{key}:")
            lines.append(format_summary(value, indent + 2))
            continue
        label, unit, factor = _unit_of(str(key))
        lines.append(f"{pad}{label}: {_format_value(value, factor)}{' ' + unit if unit else ''}")
    return "\n".join(line for line in lines if line)


# ---------------------------------------------------------------------------------- helpers
def _path_csv(rows: Sequence[Mapping[str, Any]], names: list[str]) -> str:
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(path_columns(names))
    for r, row in enumerate(rows):
        motion = _require(row, "motion", r)
        if motion not in _MOTIONS:
            raise ValueError(f"path row {r}: motion must be one of {_MOTIONS}, got {motion!r}")
        if "q" in row:
            q = np.asarray(row["q"], dtype=float).reshape(-1)
            if q.size != len(names):
                raise ValueError(f"path row {r}: q needs {len(names)} values ({', '.join(names)}), got {q.size}")
        else:
            q = np.array([_require(row, nm, r) for nm in names], dtype=float)
        if "tip" in row:
            tip = np.asarray(row["tip"], dtype=float).reshape(-1)
            if tip.size != 3:
                raise ValueError(f"path row {r}: tip needs 3 values [m], got {tip.size}")
        else:
            tip = np.array([_require(row, c, r) for c in _TIP_COLUMNS], dtype=float)
        kind = _require(row, "bound_kind", r)
        if kind not in BOUND_KINDS:
            raise ValueError(f"path row {r}: bound_kind must be one of {BOUND_KINDS}, got {kind!r}")
        planned = float(row.get("planned_bound_m", float("nan")))
        calibrated = float(row.get("calibrated_bound_m", float("nan")))
        ptip = np.asarray(row.get("predicted_tip", np.full(3, np.nan)), dtype=float).reshape(-1)
        if ptip.size != 3:
            raise ValueError(f"path row {r}: predicted_tip needs 3 values [m], got {ptip.size}")
        offset = float(row.get("predicted_offset_m", float("nan")))
        writer.writerow([int(row.get("waypoint", r)), motion, *map(_num, q), *map(_num, tip),
                         _num(_require(row, "bound_position_m", r)), _opt(calibrated), _opt(planned),
                         _num(_require(row, "bound_angle_rad", r)), kind, *map(_opt, ptip), _opt(offset),
                         str(row.get("prediction_eta", "")), str(row.get("prediction_cases", ""))])
    return buf.getvalue()


def write_trajectory_csv(path, traj: Trajectory) -> None:
    """Write ``traj`` as ``trajectory.csv`` is written by ``ctrplan plan``: a column ``t`` [s], then per
    joint its position, velocity and acceleration (``<joint>``, ``<joint>_vel``, ``<joint>_acc``)
    [rad or m, per s, per s^2], one row per control period.

    Parameters
    ----------
    path : str or path-like
    traj : Trajectory
    """
    atomic_write_text(path, _trajectory_csv(traj))


def _trajectory_csv(traj: Trajectory) -> str:
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    header = ["t"]
    for name in traj.joint_names:
        header += [name, f"{name}_vel", f"{name}_acc"]
    writer.writerow(header)
    # Columns per joint interleaved: position, velocity, acceleration.
    table = np.stack([traj.position, traj.velocity, traj.acceleration], axis=2).reshape(len(traj.t), -1)
    for tk, values in zip(traj.t, table):
        writer.writerow([_num(tk), *map(_num, values)])
    return buf.getvalue()


def _require(row: Mapping[str, Any], key: str, r: int):
    if key not in row:
        raise ValueError(f"path row {r}: missing key {key!r}")
    return row[key]


def _num(x) -> str:
    """Shortest text that reads back to the same float."""
    return repr(float(x))


def _opt(x) -> str:
    """:func:`_num`, or an empty cell for NaN / infinity."""
    return _num(x) if math.isfinite(float(x)) else ""


def jsonable(value):
    """``value`` with numpy scalars and arrays, tuples and paths turned into JSON types.

    Parameters
    ----------
    value : any
        Nested mappings, sequences, numpy arrays and scalars, paths, and JSON types.

    Returns
    -------
    object
        Mappings with string keys, lists, bool, int, float, str and None; a non-finite float
        becomes None (written ``null``); an object of another type is returned as it is.
    """
    if isinstance(value, Mapping):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [jsonable(v) for v in value]
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, Path):
        return str(value)
    return value


def _unit_of(key: str) -> tuple[str, str, float]:
    low = key.lower()
    for suffix, unit, factor in _SUMMARY_UNITS:
        if low.endswith(suffix) and len(key) > len(suffix):
            return key[: -len(suffix)].replace("_", " "), unit, factor
    return key.replace("_", " "), "", 1.0


def _format_value(value, factor: float) -> str:
    if isinstance(value, (bool, np.bool_)) or value is None or isinstance(value, str):
        return str(value)
    if isinstance(value, (int, np.integer)) and factor == 1.0:
        return str(int(value))
    if isinstance(value, (int, float, np.integer, np.floating)):
        return f"{float(value) * factor:.4g}"
    if isinstance(value, (list, tuple, np.ndarray)):
        return "[" + ", ".join(_format_value(v, factor) for v in value) + "]"
    return str(value)
