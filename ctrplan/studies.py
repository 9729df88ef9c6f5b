"""Many scenarios in one run: :func:`plan_many` (``ctrplan plan A.toml B.toml DIR/ ...``).

Each scenario is planned by :func:`ctrplan.plan_scenario` (:func:`ctrplan.plan` writing its files)
into its own folder ``<out>/<scenario stem>/`` (the files of ``ctrplan plan``); the compiled kernels
and bound maps are loaded once per process. One table across scenarios, ``<out>/scenarios.csv`` (and ``scenarios.png``), has a row per
scenario: its status (``planned``, ``reused``, ``failed``), the reason of a failure, the time,
cost, joint-path length, largest and final exact bound of the bound-aware plan and the
bound-blind plan's largest bound, and the final check's repairs and failures. A failing scenario is
reported and the others go on.

A scenario whose folder holds a complete run (``summary.json``, written last) for the same inputs
(the scenario and robot files' bytes, the options, the mechanics version) is not planned again:
its row is read from that summary (``reused``; :func:`ctrplan.planning.read_plan_record`); the
other rows come from the typed results of the plans (``PlanResult.run.comparison``). With
``n_jobs`` > 1 or a ``scheduler`` address the scenarios are spread over worker processes
(:class:`ctrplan.parallel.Executor`: ``n_jobs`` local processes, or the workers of the Dask
cluster at that address, which need ctrplan installed).

Messages go to the ``ctrplan.studies`` logger (:mod:`logging`): one line per scenario (WARNING for
a failed one) and the closing summary at INFO. Each scenario's own progress lines (:mod:`ctrplan.planning`) are DEBUG
records here; its cautions stay WARNING.
"""

from __future__ import annotations

import logging
import math
import os
import time
import warnings
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Sequence

from ._log import deprecated_echo, details
from .cache import content_key, file_hash, mechanics_version
from .errors import CtrplanError

if TYPE_CHECKING:
    from .planning import PlanComparison, PlanRecord

__all__ = ["scenario_files", "plan_many", "input_key", "StudyStatus", "StudyRow", "StudyResult", "TABLE_FILE",
           "PLOT_FILE", "COLUMNS"]

#: File name of the table across scenarios, in the output folder.
TABLE_FILE = "scenarios.csv"
#: File name of its figure.
PLOT_FILE = "scenarios.png"
#: Columns of the table across scenarios, ``scenarios.csv`` (units in their suffixes: the report's
#: mm for bounds).
COLUMNS = ("scenario", "status", "reason", "time_s", "cost", "joint_path_length_m", "max_bound_mm", "final_bound_mm",
           "blind_max_bound_mm", "repairs", "failures", "output_dir")

logger = logging.getLogger(__name__)


class StudyStatus(StrEnum):
    """What became of a scenario of a study."""

    #: Planned in this run.
    PLANNED = "planned"
    #: A complete run of its folder for the same inputs was read back.
    REUSED = "reused"
    #: Its planning raised; ``StudyRow.error`` says what.
    FAILED = "failed"


@dataclass(frozen=True)
class StudyRow:
    """One scenario of a study, in SI units (the bound-aware plan's figures; None where it failed).

    Attributes
    ----------
    scenario : pathlib.Path
    status : StudyStatus
    error : str
        The first line of the exception a failed scenario raised (``Type: message``); "" otherwise.
    time_s : float or None
        Its planning time, or the recorded one of a reused run [s].
    cost : float or None
        The planner's cost of the bound-aware path (path length + weight x integral of the bound).
    joint_path_length_m, max_bound_m, final_bound_m : float or None
        Joint-path length [m of the weighted metric]; largest and final exact bound at the
        waypoints [m].
    blind_max_bound_m : float or None
        The bound-blind plan's largest exact bound [m] (None when not planned).
    repairs, failures : int or None
        The final check's repairs and failing phases.
    output_dir : pathlib.Path
    """

    scenario: Path
    status: StudyStatus
    error: str
    time_s: float | None
    output_dir: Path
    cost: float | None = None
    joint_path_length_m: float | None = None
    max_bound_m: float | None = None
    final_bound_m: float | None = None
    blind_max_bound_m: float | None = None
    repairs: int | None = None
    failures: int | None = None

    def report_row(self) -> dict:
        """The row of ``scenarios.csv`` (:data:`COLUMNS`; bounds in mm)."""
        mm = (lambda x: None if x is None else x * 1e3)
        return {"scenario": str(self.scenario), "status": self.status.value, "reason": self.error,
                "time_s": self.time_s, "cost": self.cost, "joint_path_length_m": self.joint_path_length_m,
                "max_bound_mm": mm(self.max_bound_m), "final_bound_mm": mm(self.final_bound_m),
                "blind_max_bound_mm": mm(self.blind_max_bound_m), "repairs": self.repairs, "failures": self.failures,
                "output_dir": str(self.output_dir)}


@dataclass(frozen=True)
class StudyResult:
    """The scenarios of a study (:func:`plan_many`), in the order given.

    Attributes
    ----------
    rows : tuple of StudyRow
    table_file, plot_file : pathlib.Path
        ``scenarios.csv`` (the rows in report units) and ``scenarios.png``.
    """

    rows: tuple
    table_file: Path
    plot_file: Path

    @property
    def n_failed(self) -> int:
        """Scenarios whose planning failed."""
        return sum(r.status is StudyStatus.FAILED for r in self.rows)

    def to_frame(self):
        """The rows as a pandas DataFrame, in SI units (the fields of :class:`StudyRow`)."""
        import pandas as pd

        return pd.DataFrame([{f: getattr(r, f) for f in StudyRow.__dataclass_fields__} for r in self.rows])

    def __getitem__(self, column):
        warnings.warn("indexing plan_many's result as the report table is deprecated: use .rows (SI), "
                      ".to_frame() or the table file", DeprecationWarning, stacklevel=2)
        return _report_table(self.rows)[column]


def scenario_files(paths: Sequence[str | os.PathLike]) -> list[Path]:
    """The scenario files named by ``paths``: files as given, folders as their ``*.toml``, sorted.

    Raises
    ------
    FileNotFoundError
        A path that does not exist, or a folder without scenario files.
    """
    out = []
    for p in map(Path, paths):
        if p.is_dir():
            found = sorted(p.glob("*.toml"))
            if not found:
                raise FileNotFoundError(f"{p}: no scenario files (*.toml) in this folder")
            out += found
        elif p.is_file():
            out.append(p)
        else:
            raise FileNotFoundError(f"{p}: no such scenario file or folder")
    return out


def input_key(scenario: Path, iterations: int | None, compare_blind: bool) -> str:
    """Key of a scenario's outputs (:mod:`ctrplan.cache`): the bytes of the scenario file and of
    every file it reads (the robot file, and the files its obstacles are read from:
    :meth:`ctrplan.obstacles.Obstacle.input_files`), the options and the mechanics version.

    A scenario that does not load (:class:`~ctrplan.errors.CtrplanError`, ``OSError``,
    ``ValueError``: the planning run reports it as its row) is keyed by its own bytes and the
    options; any other exception is raised.
    """
    payload = {"scenario": file_hash(scenario), "iterations": iterations, "compare_blind": compare_blind,
               "mechanics": mechanics_version()}
    from .io.scenario import load_scenario

    try:
        sc = load_scenario(scenario)
    except (CtrplanError, OSError, ValueError):
        return content_key(payload)
    payload["robot"] = file_hash(sc.robot_file)
    files = sorted({str(f) for o in sc.obstacles for f in o.input_files()})
    if files:
        payload["obstacle_files"] = {f: file_hash(f) for f in files}
    return content_key(payload)


def _row(scenario: Path, status: StudyStatus, comparison: PlanComparison | None, seconds: float | None, out: Path,
         error: str = "") -> StudyRow:
    """A scenario's row from its plans' comparison (SI)."""
    if comparison is None:
        return StudyRow(scenario=Path(scenario), status=status, error=error, time_s=seconds, output_dir=Path(out))
    a, b = comparison.aware, comparison.blind
    return StudyRow(scenario=Path(scenario), status=status, error=error, time_s=seconds, output_dir=Path(out),
                    cost=a.cost, joint_path_length_m=a.joint_path_length_m, max_bound_m=a.max_bound_at_waypoints_m,
                    final_bound_m=a.final_bound_m, blind_max_bound_m=None if b is None else b.max_bound_at_waypoints_m,
                    repairs=a.repairs, failures=len(a.failures))


def _report_table(rows):
    """``scenarios.csv``'s table (:data:`COLUMNS`, report units)."""
    import pandas as pd

    return pd.DataFrame([r.report_row() for r in rows], columns=list(COLUMNS))


def _plan_one(scenario: Path, out: Path, key: str, iterations, compare_blind: bool, progress: bool = False) -> StudyRow:
    """Plan one scenario (in this process or on a worker), its progress lines as DEBUG records; a
    failure becomes a row."""
    from .api import plan_scenario

    t0 = time.perf_counter()
    logger.debug(f"{scenario}: planning into {out}")
    try:
        with details():
            result = plan_scenario(scenario, out, n_jobs=1, iterations=iterations, compare_blind=compare_blind,
                                   progress=progress)
    except Exception as exc:                             # noqa: BLE001 - reported, the others go on
        reason = (f"{type(exc).__name__}: {exc}".splitlines() or [type(exc).__name__])[0]
        return _row(scenario, StudyStatus.FAILED, None, time.perf_counter() - t0, out, reason)
    (out / "inputs.sha256").write_text(key + "\n")
    return _row(scenario, StudyStatus.PLANNED, result.run.comparison, time.perf_counter() - t0, out)


def _log_row(scenario, row: StudyRow) -> None:
    """One line per planned scenario: INFO, WARNING if it failed."""
    level = logging.WARNING if row.status is StudyStatus.FAILED else logging.INFO
    logger.log(level, f"{scenario}: {row.status.value} in {row.time_s:.1f} s {row.error}".rstrip())


def _reusable(out: Path, key: str) -> PlanRecord | None:
    """The record of a complete run in ``out`` for the same inputs (``inputs.sha256``), else None
    (also for a summary this version cannot read)."""
    from .planning import read_plan_record

    summary, stamp = out / "summary.json", out / "inputs.sha256"
    if summary.exists() and stamp.exists() and stamp.read_text().strip() == key:
        try:
            return read_plan_record(summary)
        except ValueError:
            return None
    return None


@deprecated_echo
def plan_many(scenarios: Sequence[str | os.PathLike], out_dir: str | os.PathLike, *, n_jobs: int = 1,
              scheduler: str | None = None, iterations: int | None = None, compare_blind: bool = True,
              echo: Callable[[str], Any] | None = None, progress: bool = False):
    """Plan several scenarios and tabulate them (module docstring).

    Parameters
    ----------
    scenarios : sequence of path
        Scenario files or folders of them (:func:`scenario_files`).
    out_dir : path
        Root folder: ``<out_dir>/<scenario stem>/`` per scenario, the table and its plot.
    n_jobs : int
        Scenarios planned at once: 1 in this process; more on that many local worker processes.
    scheduler : str, optional
        Address of a running Dask scheduler (``tcp://host:8786``); overrides ``n_jobs``.
    iterations : int, optional
        Overrides every scenario's planner iterations.
    compare_blind : bool
        Also plan each bound-blind.
    echo : callable, optional
        Deprecated (``DeprecationWarning``): receives the messages this call logs at INFO and
        higher (a line per scenario and the summary); configure :mod:`logging` instead.
    progress : bool
        tqdm bars while a bound map is computed (default none).

    Returns
    -------
    StudyResult
        One :class:`StudyRow` per scenario, in SI units; ``scenarios.csv`` holds the same rows in
        report units (:data:`COLUMNS`: bounds in mm).

    Raises
    ------
    FileNotFoundError
        A scenario path that does not exist.
    ValueError
        Two scenarios with the same file stem (their folders would collide).
    """
    files = scenario_files(scenarios)
    stems = [f.stem for f in files]
    dup = {s for s in stems if stems.count(s) > 1}
    if dup:
        raise ValueError(f"scenarios with the same name would share an output folder: {', '.join(sorted(dup))}")
    root = Path(out_dir)
    root.mkdir(parents=True, exist_ok=True)
    rows, todo = {}, []
    for f in files:
        out, key = root / f.stem, input_key(f, iterations, compare_blind)
        done = _reusable(out, key)
        if done is not None:
            rows[f] = _row(f, StudyStatus.REUSED, done.comparison, done.time_s, out)
            logger.info(f"{f}: complete outputs for the same inputs in {out}, reused")
        else:
            todo.append((f, out, key))
    t0 = time.perf_counter()
    from .parallel import Executor

    with Executor(n_jobs, scheduler) as ex:
        for f, row in ex.run(_plan_one, [(f, (f, out, key, iterations, compare_blind, progress)) for f, out, key in todo]):
            rows[f] = row
            _log_row(f, row)
    result = StudyResult(rows=tuple(rows[f] for f in files), table_file=root / TABLE_FILE, plot_file=root / PLOT_FILE)
    from .io.atomic import atomic_write_text

    atomic_write_text(result.table_file, _report_table(result.rows).to_csv(index=False))
    _plot(result.rows, result.plot_file)
    logger.info(f"{len(files)} scenarios: {len(files) - result.n_failed} planned or reused, {result.n_failed} failed; "
                f"{time.perf_counter() - t0:.1f} s; table {result.table_file}")
    return result


def _plot(rows, path: Path) -> None:
    """Largest exact bound per scenario, bound-aware against bound-blind [mm]."""
    import numpy as np

    from .plots import new_figure, save_figure

    names = [r.scenario.stem for r in rows]
    x = np.arange(len(names))
    fig = new_figure((max(4.0, 0.6 * len(names) + 2), 3.2))
    ax = fig.subplots()
    mm = (lambda v: math.nan if v is None else v * 1e3)
    aware = np.array([mm(r.max_bound_m) for r in rows])
    blind = np.array([mm(r.blind_max_bound_m) for r in rows])
    ax.bar(x - 0.2, aware, 0.4, label="bound-aware")
    ax.bar(x + 0.2, blind, 0.4, label="bound-blind")
    ax.set_xticks(x, names, rotation=45, ha="right")
    ax.set_ylabel("largest exact bound at the waypoints [mm]")
    ax.legend()
    save_figure(fig, path)
