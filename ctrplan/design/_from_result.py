"""The design from a ``ctrplan discrepancy`` output folder: its hypotheses, its noise estimate, its
robot file and its data, read and checked as the command reads them."""

from __future__ import annotations

import math
from pathlib import Path

from ._design import DesignSearch, ExperimentLimits, SensorNoise, design_experiment
from ._hypotheses import DesignInputError, read_results, result_hypotheses

__all__ = ["design_from_result"]


def _located(result_dir: Path, results: dict, given, key: str, option: str) -> Path:
    """``given``, else the path ``results[key]`` relative to the working directory or to the result
    folder's parent."""
    if given is not None:
        return Path(given)
    value = results.get(key)
    for base in (Path.cwd(), result_dir.resolve().parent):
        if value and (base / value).exists():
            return base / value
    raise DesignInputError(f"{result_dir / 'results.json'}: {key} {value!r} not found; give {option}")


def design_from_result(result_dir, *, hypotheses=None, parameters=None, robot_file=None, data_file=None,
                       scenario_file=None, duration: float | None = None, rest: float = 1.0,
                       noise_position: float | None = None, search: DesignSearch = DesignSearch()):
    """Design the follow-up of a ``ctrplan discrepancy`` run from its output folder.

    Parameters
    ----------
    result_dir : str or Path
        Output folder of ``ctrplan discrepancy`` (its ``results.json`` gives the hypotheses, the noise
        estimate, the robot file and the data).
    hypotheses : sequence of str, optional
        Candidates to separate or determine (effects, ``"baseline"``, or ``"first+second"`` for a pair
        the run tried); default the ambiguous pair, else the named model.
    parameters : sequence of str, optional
        With one hypothesis: the parameters to determine (default: those the recording left
        undetermined).
    robot_file, data_file : str or Path, optional
        The robot file the result was fitted to and the recorded data (default: the result's).
    scenario_file : str or Path, optional
        A scenario whose obstacles the motion stays clear of, whose ``[drive]`` limits it keeps and
        whose start it begins at (default: no obstacles, the drive the recording shows, the robot's
        home).
    duration : float, optional
        Budget [s] (default: the recording's duration).
    rest : float
        Rest after each primitive [s].
    noise_position : float, optional
        3-D rms tip position noise [m], as ``ctrplan synth`` and ``ctrplan discrepancy`` take it
        (default: the result's estimate).
    search : DesignSearch
        Random motions compared with, their seed, worker processes, compound primitives.

    Returns
    -------
    tuple
        ``(DesignResult, Robot, MeasuredData)``: the design, the robot file and the recording read.

    Raises
    ------
    DesignInputError
        A result folder without ``results.json``, a robot file or data that cannot be found, a
        candidate the run did not fit, no noise estimate and none given, a noise or duration that is
        not positive, and every error of :func:`~ctrplan.design.design_experiment`.
    """
    from ..discrepancy import load_measured_data
    from ..io.robot_file import load_robot

    result_dir = Path(result_dir)
    results = read_results(result_dir)
    where = str(result_dir / "results.json")
    robot = load_robot(_located(result_dir, results, robot_file, "robot_file", "--robot"))
    data = load_measured_data(_located(result_dir, results, data_file, "data_file", "--data"), robot,
                              frame=results.get("frame"))
    hyps = result_hypotheses(results, list(hypotheses) if hypotheses else None, where=where)
    estimate = (results.get("noise") or {}).get("noise") or {}
    if noise_position is not None:
        if not (noise_position > 0 and math.isfinite(noise_position)):
            raise DesignInputError(f"noise position {noise_position!r} m: must be > 0")
        noise = SensorNoise.from_estimate({"position_rms_m": float(noise_position)}, where="the noise given")
    elif estimate.get("position_rms_m"):
        noise = SensorNoise.from_estimate(estimate, where=f"{where}: noise")
    else:
        raise DesignInputError(f"{where}: no sensor noise estimate; give the noise (--noise-position-mm)")
    if duration is not None and not duration > 0:
        raise DesignInputError(f"duration {duration!r} s: must be > 0")
    drive = obstacles = start = None
    if scenario_file is not None:
        from ..io.scenario import load_scenario

        sc = load_scenario(scenario_file)
        drive, obstacles, start = sc.drive, sc.obstacles, sc.start
    limits = ExperimentLimits(drive=drive, obstacles=tuple(obstacles or ()), start=start, duration=duration, rest=rest)
    baseline = family = None
    if len(hyps) > 1 and all(h.key != "baseline" for h in hyps):
        try:
            baseline = result_hypotheses(results, ["baseline"], where=where)[0]
        except DesignInputError:
            baseline = None     # a result without a baseline fit: no naming probability
        family = ((results.get("decision") or {}).get("family")) or None
    res = design_experiment(robot, data, hyps, noise=noise, limits=limits,
                            interest=list(parameters) if parameters else None, search=search, baseline=baseline,
                            n_candidates=len(family) if family else None)
    return res, robot, data
