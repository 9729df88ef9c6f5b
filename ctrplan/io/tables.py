"""The project's one CSV column schema, and readers/writers that check it.

Every CSV that ctrplan reads or writes (configurations to evaluate, measured tip poses, model
results, planned paths) uses the same column names and SI units:

=====================  ========  ==========================================================
column                 unit      meaning
=====================  ========  ==========================================================
``time``               s         sample time (optional)
``sequence``           -         id of one continuous motion (optional, int); within a sequence
                                 the rows are in time order, so each sample keeps its history
``alpha_1..alpha_n``   rad       base rotation of tube i (tube 1 outermost), Eq. (3)
``beta_1..beta_n``     m         base translation of tube i, Eq. (3)
``eta_1..eta_(n-1)``   -         last relative rotation direction of tube i+1 w.r.t. tube i:
                                 +1 CCW (alpha_(i+1) - alpha_i increasing, right-hand rule
                                 about +z), -1 CW, 0 unknown (optional); eta_k of Eq. (38)
``tip_x, tip_y, tip_z``  m       tip position
``tangent_x..z``       -         unit tip tangent (optional in measurements)
``R_11..R_33``         -         tip orientation, columns = tip frame x, y, z axes; R_13,
                                 R_23, R_33 is the tangent (optional)
``status``             -         text status of a computed row, e.g. ``ok`` (optional)
``bound_tip_m``        m         friction-induced tip position error bound (optional)
``bound_tangent_rad``  rad       friction-induced tip tangent error bound (optional)
=====================  ========  ==========================================================

Other columns are allowed and passed through untouched. Files are plain comma-separated text with
one header line. Checks raise :class:`~ctrplan.errors.DataFileError` naming the file, the column
and the data row (1-based, header excluded; line = row + 1).

The measured trajectory of the paper's robot (a whitespace format without header, see
``shared/data/ha-three-tube-trajectory/README.md``) is converted to this schema by
:func:`load_ha_trajectory`.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass

import numpy as np
import pandas as pd

from ..errors import DataFileError
from ..history import rotation_directions
from .atomic import atomic_path
from .robot_file import MAX_METRES

__all__ = [
    "SCHEMA",
    "Measurements",
    "config_columns",
    "read_configurations",
    "read_measurements",
    "measurements_from_frame",
    "write_table",
    "load_ha_trajectory",
]

# Column name pattern -> (unit, meaning). The order here is the canonical column order.
SCHEMA: dict[str, tuple[str, str]] = {
    "time": ("s", "sample time"),
    "sequence": ("-", "id of one continuous motion (rows in time order within it)"),
    r"alpha_(\d+)": ("rad", "base rotation of tube i"),
    r"beta_(\d+)": ("m", "base translation of tube i"),
    r"eta_(\d+)": ("-", "relative rotation direction of tube i+1 w.r.t. tube i (+1 CCW, -1 CW, 0 unknown)"),
    r"tip_[xyz]": ("m", "tip position"),
    r"tangent_[xyz]": ("-", "unit tip tangent"),
    r"R_[123][123]": ("-", "tip orientation (columns: tip x, y, z axes)"),
    "status": ("-", "status text"),
    "bound_tip_m": ("m", "friction-induced tip position error bound"),
    "bound_tangent_rad": ("rad", "friction-induced tip tangent error bound"),
}

# Above this magnitude a base rotation [rad] is taken to be in degrees (16 turns).
MAX_RADIANS = 100.0
# Allowed deviation of a measured tangent's norm from 1 and of R^T R from I.
UNIT_TOL = 1e-2

TIP = ["tip_x", "tip_y", "tip_z"]
TANGENT = ["tangent_x", "tangent_y", "tangent_z"]
ROTATION = [f"R_{i}{j}" for i in (1, 2, 3) for j in (1, 2, 3)]
_TEXT_COLUMNS = {"status"}


def config_columns(n_tubes: int, with_eta: bool = False) -> list[str]:
    """Input column names for ``n_tubes`` tubes: alpha_1..n, beta_1..n [, eta_1..n-1]."""
    if not isinstance(n_tubes, (int, np.integer)) or n_tubes < 1:
        raise ValueError(f"n_tubes must be a positive integer, got {n_tubes!r}")
    cols = [f"alpha_{i}" for i in range(1, n_tubes + 1)] + [f"beta_{i}" for i in range(1, n_tubes + 1)]
    if with_eta:
        cols += [f"eta_{i}" for i in range(1, n_tubes)]
    return cols


@dataclass(frozen=True, eq=False)
class Measurements:
    """Measured (or computed) tip poses at K configurations, SI units.

    Attributes
    ----------
    alpha : ndarray, shape (K, n)
        Base rotations [rad].
    beta : ndarray, shape (K, n)
        Base translations [m].
    eta : ndarray of int or None, shape (K, n - 1)
        Relative rotation directions (+1, -1, 0), if the file has them.
    tip : ndarray, shape (K, 3)
        Tip positions [m].
    tangent : ndarray or None, shape (K, 3)
        Unit tip tangents [-]; from ``R_13, R_23, R_33`` when only the rotation is given.
    rotation : ndarray or None, shape (K, 3, 3)
        Tip orientations (columns: tip frame axes) [-].
    time : ndarray or None, shape (K,)
        Sample times [s].
    frame : pandas.DataFrame
        The whole table, schema columns converted to numbers.
    """

    alpha: np.ndarray
    beta: np.ndarray
    eta: np.ndarray | None
    tip: np.ndarray
    tangent: np.ndarray | None
    rotation: np.ndarray | None
    time: np.ndarray | None
    frame: pd.DataFrame


# --------------------------------------------------------------------------- readers
def read_configurations(path: str | os.PathLike, n_tubes: int):
    """Read robot configurations from a CSV in the project schema.

    Parameters
    ----------
    path : str or path-like
    n_tubes : int
        Number of tubes n of the robot.

    Returns
    -------
    alpha : ndarray, shape (K, n)
        Base rotations [rad].
    beta : ndarray, shape (K, n)
        Base translations [m].
    eta : ndarray of int, shape (K, n - 1), or None
        Relative rotation directions, if all ``eta_i`` columns are present.
    frame : pandas.DataFrame
        The whole table (schema columns numeric, others as read).

    Raises
    ------
    DataFileError
        Missing file or column, empty or non-numeric cell, values in millimetres or degrees
        where metres or radians are expected, eta outside {-1, 0, 1}, columns for more tubes
        than ``n_tubes``. The message names the file, column and row.
    """
    frame = _read_csv(path)
    alpha, beta, eta = _configurations(frame, n_tubes, str(path))
    return alpha, beta, eta, frame


def read_measurements(path: str | os.PathLike, n_tubes: int) -> Measurements:
    """Read configurations with measured tip poses (``tip_*`` required).

    Parameters
    ----------
    path : str or path-like
    n_tubes : int

    Returns
    -------
    Measurements

    Raises
    ------
    DataFileError
        As :func:`read_configurations`, plus: missing tip column, only some of the tangent or
        ``R_ij`` columns, a tangent that is not a unit vector or a matrix that is not a rotation
        (tolerance 1e-2), tip coordinates that look like millimetres.
    """
    return measurements_from_frame(_read_csv(path), n_tubes, str(path))


def measurements_from_frame(frame: pd.DataFrame, n_tubes: int, source: str) -> Measurements:
    """:func:`read_measurements` on a table already in memory (e.g. converted from a ROS 2 bag by
    :func:`ctrplan.io.ros2.read_bag_measurements`), with the same checks.

    Parameters
    ----------
    frame : pandas.DataFrame
        Columns of the schema, numeric.
    n_tubes : int
    source : str
        Named in the error messages (the file the table came from).

    Returns
    -------
    Measurements

    Raises
    ------
    DataFileError
        As :func:`read_measurements`.
    """
    file = source
    alpha, beta, eta = _configurations(frame, n_tubes, file)
    _require(frame, TIP, file)
    tip = frame[TIP].to_numpy(float)
    tangent = rotation = None
    if _group_present(frame, TANGENT, file):
        tangent = frame[TANGENT].to_numpy(float)
        norm = np.linalg.norm(tangent, axis=1)
        bad = np.flatnonzero(np.abs(norm - 1.0) > UNIT_TOL)
        if bad.size:
            raise DataFileError(f"{file}: columns tangent_x..z, {_row(bad[0])}: tangent has norm "
                                f"{norm[bad[0]]:.6g}, expected a unit vector")
    if _group_present(frame, ROTATION, file):
        rotation = frame[ROTATION].to_numpy(float).reshape(-1, 3, 3)
        err = np.abs(np.einsum("kji,kjl->kil", rotation, rotation) - np.eye(3)).max(axis=(1, 2))
        bad = np.flatnonzero((err > UNIT_TOL) | (np.linalg.det(rotation) < 0.0))
        if bad.size:
            raise DataFileError(f"{file}: columns R_11..R_33, {_row(bad[0])}: not a rotation matrix "
                                f"(max |R^T R - I| = {err[bad[0]]:.3g}, "
                                f"det {np.linalg.det(rotation[bad[0]]):.3g})")
        if tangent is None:
            tangent = rotation[:, :, 2].copy()
    time = frame["time"].to_numpy(float) if "time" in frame else None
    return Measurements(alpha=alpha, beta=beta, eta=eta, tip=tip, tangent=tangent,
                        rotation=rotation, time=time, frame=frame)


# --------------------------------------------------------------------------- writer
def write_table(path: str | os.PathLike, frame: pd.DataFrame) -> None:
    """Write a table in the project schema atomically (no half-written file on failure).

    Schema columns are put first in canonical order (time, sequence, alpha, beta, eta, tip,
    tangent, R, status, bounds), other columns follow in their order. The index is not written.

    Parameters
    ----------
    path : str or path-like
    frame : pandas.DataFrame
        Columns named per the schema, SI units. NaN is allowed (e.g. a failed solve) and
        written as an empty cell.

    Raises
    ------
    DataFileError
        Non-numeric schema column, values that look like millimetres or degrees, eta outside
        {-1, 0, 1}, duplicated column names.
    """
    file = str(path)
    if not isinstance(frame, pd.DataFrame):
        raise TypeError(f"write_table needs a pandas DataFrame, got {type(frame).__name__}")
    if frame.columns.duplicated().any():
        raise DataFileError(f"{file}: duplicated columns {list(frame.columns[frame.columns.duplicated()])}")
    for col in frame.columns:
        if _schema_rank(col) is None or col in _TEXT_COLUMNS:
            continue
        series = frame[col]
        if series.dtype.kind in "fiub":
            values = series.to_numpy(float)   # numeric already: nothing to coerce
        else:
            values = pd.to_numeric(series, errors="coerce").to_numpy(float)
            bad = np.flatnonzero(np.isnan(values) & series.notna().to_numpy())
            if bad.size:
                raise DataFileError(f"{file}: column '{col}', {_row(bad[0])}: non-numeric value "
                                    f"{series.iloc[bad[0]]!r}")
        _check_units(col, values, file)
    ordered = sorted(frame.columns, key=lambda c: _sort_key(c, list(frame.columns)))
    with atomic_path(path) as tmp:
        _write_csv(frame[ordered], tmp)


def _write_csv(frame: pd.DataFrame, path) -> None:
    """``frame`` as CSV text at ``path``: one header line, no index, ``\\n`` line ends, NaN and
    None as empty cells, numbers in a form that reads back to the same double, text values in
    double quotes (the header only where a name needs them).

    The rows are written by Apache Arrow's CSV writer, not ``DataFrame.to_csv``: formatting the
    floats took pandas about 11 us per row of a standard-model result (12 numbers), Arrow about
    3 us (5228 rows; every number read back bit for bit)."""
    import csv
    import io

    import pyarrow as pa
    import pyarrow.csv as pacsv

    header = io.StringIO()
    csv.writer(header, lineterminator="\n").writerow([str(c) for c in frame.columns])
    table = pa.Table.from_pandas(frame, preserve_index=False)
    with open(path, "wb") as fh:
        fh.write(header.getvalue().encode())
        pacsv.write_csv(table, fh, write_options=pacsv.WriteOptions(include_header=False))


# --------------------------------------------------------------------------- Ha et al. data
def load_ha_trajectory(path: str | os.PathLike) -> pd.DataFrame:
    """Read the measured trajectory of Ha et al.'s three-tube robot into the project schema.

    The source format (``jointTipTrajectory_measured.txt`` of github.com/hjhdog1/ConcentricTubes,
    described in ``shared/data/ha-three-tube-trajectory/README.md``) is whitespace-separated,
    one sample per line: time [s]; alpha_1..n [rad]; beta_1..n [mm]; tip position [mm];
    3x3 EM-sensor orientation, row-major (here n = 3, 19 columns).

    Orientation: the nine values are the EM sensor's x, y and z axes in the tracker frame (the
    rows of the matrix), and the sensor's x axis points *backwards* along the tube. This follows
    the data's author (``SyntheticDataGenerator::ReadJointAndTipTrajectory``: "EM tracker has
    been attached on the robot tip with its x-axis colinearly aligned to z-axis of robot tip in
    opposite direction"), who swaps the axes as done here. So the tip tangent is minus the first
    row, and the tip frame is ``R = [sensor z, sensor y, -sensor x]`` (columns), a proper rotation.
    Only the tangent (third column) is meaningful: the roll of the sensor about the tube, hence
    the tip x and y axes, is not calibrated. The data agree: the tracker frame is roughly
    aligned with the robot base (at home the tip is at (53, 0, 155) mm, in the xz bending plane),
    and minus the first row is the only candidate among the six rows and columns (and their
    negatives) that points forward (mean z component +0.37) and bends the same way as the tip
    (median azimuth difference between tangent and tip position 16 deg, against >= 20 deg for
    minus the first column, which points sideways on average, and >= 55 deg for the others);
    at home it is (0.83, 0.01, 0.56), in the bending plane.

    Positions are in the tracker frame, not the robot base frame (no registration is given).

    Parameters
    ----------
    path : str or path-like

    Returns
    -------
    pandas.DataFrame, K rows
        Columns ``time`` [s], ``sequence`` (0: one continuous motion), ``alpha_1..n``
        [rad], ``beta_1..n`` [m], ``eta_1..n-1`` (from :func:`ctrplan.history.rotation_directions` on the
        recorded history), ``tip_x..z`` [m], ``tangent_x..z``, ``R_11..R_33``.

    Raises
    ------
    DataFileError
        Missing file, non-numeric entry, rows of different lengths or a column count that is not
        1 + 2 n + 12.
    """
    file = str(path)
    try:
        raw = np.loadtxt(path, dtype=float, ndmin=2)
    except FileNotFoundError:
        raise DataFileError(f"{file}: file does not exist") from None
    except ValueError as exc:
        raise DataFileError(f"{file}: not a whitespace-separated table of numbers: {exc}") from None
    n_cols = raw.shape[1]
    if (n_cols - 13) % 2 or n_cols < 15:
        raise DataFileError(f"{file}: expected 1 + 2 n + 12 columns (time, alpha, beta, tip, "
                            f"rotation), got {n_cols}")
    if not np.all(np.isfinite(raw)):
        k, c = np.argwhere(~np.isfinite(raw))[0]
        raise DataFileError(f"{file}: column {c + 1}, {_row(k)}: value {raw[k, c]!r} is not finite")
    n = (n_cols - 13) // 2
    time = raw[:, 0]
    alpha = raw[:, 1:1 + n]
    beta = raw[:, 1 + n:1 + 2 * n] * 1e-3          # mm -> m
    tip = raw[:, 1 + 2 * n:4 + 2 * n] * 1e-3        # mm -> m
    sensor = raw[:, 4 + 2 * n:13 + 2 * n].reshape(-1, 3, 3)   # rows: sensor x, y, z axes
    rot = np.stack([sensor[:, 2, :], sensor[:, 1, :], -sensor[:, 0, :]], axis=2)
    data = {"time": time, "sequence": np.zeros(len(raw), dtype=int)}
    for i in range(n):
        data[f"alpha_{i + 1}"] = alpha[:, i]
    for i in range(n):
        data[f"beta_{i + 1}"] = beta[:, i]
    eta = rotation_directions(alpha)
    for i in range(n - 1):
        data[f"eta_{i + 1}"] = eta[:, i]
    for j, c in enumerate(TIP):
        data[c] = tip[:, j]
    for j, c in enumerate(TANGENT):
        data[c] = rot[:, j, 2]
    for a in range(3):
        for b in range(3):
            data[f"R_{a + 1}{b + 1}"] = rot[:, a, b]
    return pd.DataFrame(data)


# --------------------------------------------------------------------------- helpers
def _row(k: int) -> str:
    return f"row {k + 1} (line {k + 2})"


def _read_csv(path) -> pd.DataFrame:
    file = str(path)
    fast = _read_numeric_csv(path)
    if fast is not None:
        return fast
    try:
        frame = pd.read_csv(path, dtype=str, keep_default_na=False, skipinitialspace=True)
    except FileNotFoundError:
        raise DataFileError(f"{file}: file does not exist") from None
    except pd.errors.EmptyDataError:
        raise DataFileError(f"{file}: file is empty (expected a header line)") from None
    except (pd.errors.ParserError, UnicodeDecodeError) as exc:
        raise DataFileError(f"{file}: not a valid CSV file: {exc}") from None
    frame.columns = [str(c).strip() for c in frame.columns]
    for col in frame.columns:
        if _schema_rank(col) is not None and col not in _TEXT_COLUMNS:
            frame[col] = _to_numeric(frame[col], col, file)
    return frame


def _read_numeric_csv(path) -> pd.DataFrame | None:
    """The table if every column is a numeric schema column and every cell a finite number,
    read by the parser's own number conversion; None otherwise (then :func:`_read_csv` reads
    the cells as text and names the first bad one). The numbers are the same doubles either way
    (both parsers round correctly); this path takes about a fifth of the time (0.4 instead of
    2.2 us per row of a configuration file)."""
    try:
        frame = pd.read_csv(path, skipinitialspace=True)
    except (OSError, ValueError, UnicodeDecodeError, pd.errors.ParserError, pd.errors.EmptyDataError):
        return None
    frame.columns = [str(c).strip() for c in frame.columns]
    if frame.empty or frame.columns.duplicated().any():
        return None
    for col in frame.columns:
        if _schema_rank(col) is None or col in _TEXT_COLUMNS:
            return None
        values = frame[col]
        if values.dtype.kind not in "if" or not np.all(np.isfinite(values.to_numpy(float))):
            return None
    return frame


def _to_numeric(series: pd.Series, col: str, file: str) -> pd.Series:
    text = series.astype(str).str.strip()
    values = pd.to_numeric(text, errors="coerce")
    bad = np.flatnonzero(values.isna().to_numpy() | ~np.isfinite(values.to_numpy(float)))
    if bad.size:
        k = bad[0]
        raw = text.iloc[k]
        what = ("empty cell" if raw == "" else
                f"value {raw!r} is not a finite number" if raw.lower() in ("nan", "inf", "-inf", "na")
                else f"non-numeric value {raw!r}")
        more = f" ({bad.size} such rows)" if bad.size > 1 else ""
        raise DataFileError(f"{file}: column '{col}', {_row(k)}: {what}{more}")
    return values.astype(float)


def _require(frame: pd.DataFrame, cols: list[str], file: str) -> None:
    missing = [c for c in cols if c not in frame.columns]
    if missing:
        raise DataFileError(f"{file}: missing column '{missing[0]}'"
                            f"{' (also ' + ', '.join(missing[1:]) + ')' if len(missing) > 1 else ''}; "
                            f"columns found: {', '.join(frame.columns)}")


def _group_present(frame: pd.DataFrame, cols: list[str], file: str) -> bool:
    present = [c in frame.columns for c in cols]
    if any(present) and not all(present):
        _require(frame, cols, file)
    return all(present)


def _configurations(frame: pd.DataFrame, n_tubes: int, file: str):
    cols = config_columns(n_tubes)
    _require(frame, cols, file)
    for col in frame.columns:
        m = re.fullmatch(r"(alpha|beta|eta)_(\d+)", col)
        if m:
            i = int(m.group(2))
            limit = n_tubes - 1 if m.group(1) == "eta" else n_tubes
            if not 1 <= i <= limit:
                raise DataFileError(f"{file}: column '{col}' does not fit a robot with {n_tubes} "
                                    f"tubes (expected {m.group(1)}_1..{m.group(1)}_{limit})")
    for col in frame.columns:
        if _schema_rank(col) is not None and col not in _TEXT_COLUMNS:
            _check_units(col, frame[col].to_numpy(float), file)
    alpha = frame[[f"alpha_{i}" for i in range(1, n_tubes + 1)]].to_numpy(float)
    beta = frame[[f"beta_{i}" for i in range(1, n_tubes + 1)]].to_numpy(float)
    eta_cols = [f"eta_{i}" for i in range(1, n_tubes)]
    eta = None
    if n_tubes > 1 and _group_present(frame, eta_cols, file):
        eta = frame[eta_cols].to_numpy(float).astype(int)
    return alpha, beta, eta


def _check_units(col: str, values: np.ndarray, file: str) -> None:
    """Raise DataFileError for values that are evidently in the wrong unit."""
    finite = np.where(np.isfinite(values), values, 0.0)
    if re.fullmatch(r"beta_\d+|tip_[xyz]|bound_tip_m", col):
        bad = np.flatnonzero(np.abs(finite) > MAX_METRES)
        if bad.size:
            raise DataFileError(f"{file}: column '{col}', {_row(bad[0])}: value {float(values[bad[0]])!r} "
                                f"looks like millimetres; this column is in metres")
    elif re.fullmatch(r"alpha_\d+", col):
        bad = np.flatnonzero(np.abs(finite) > MAX_RADIANS)
        if bad.size:
            raise DataFileError(f"{file}: column '{col}', {_row(bad[0])}: value {float(values[bad[0]])!r} "
                                f"looks like degrees; this column is in radians")
    elif re.fullmatch(r"eta_\d+", col):
        bad = np.flatnonzero(~np.isin(values, (-1.0, 0.0, 1.0)))
        if bad.size:
            raise DataFileError(f"{file}: column '{col}', {_row(bad[0])}: value {float(values[bad[0]])!r} "
                                f"is not a rotation direction; expected -1 (CW), 0 (unknown) or +1 (CCW)")


def _schema_rank(col: str):
    """(group rank, index within group) of a schema column, or None for other columns."""
    for rank, pattern in enumerate(SCHEMA):
        m = re.fullmatch(pattern, col)
        if m:
            return rank, (int(m.group(1)) if m.groups() else col)
    return None


def _sort_key(col: str, original: list[str]):
    r = _schema_rank(col)
    if r is None:
        return (len(SCHEMA), 0, original.index(col))
    rank, sub = r
    if isinstance(sub, str):  # xyz / R_ij order: keep the schema's own order
        order = TIP + TANGENT + ROTATION
        sub = order.index(sub) if sub in order else 0
    return (rank, sub, 0)
