"""The output folder of ``ctrplan design``: the trajectory ready to run, the hypotheses' predicted
tip paths, what the design is predicted to show, and where along the motion the hypotheses part.

Files (SI units; only ``design.md`` prints mm):

- ``trajectory.csv``: the drive's jerk-limited trajectory at its control rate (the columns of
  ``ctrplan plan``'s);
- ``trajectory_bag/``: the same as a ROS 2 ``JointTrajectory`` bag (:func:`ctrplan.io.ros2.write_plan_bag`);
- ``samples.csv``: the sensor's samples (``time``, ``sequence``, ``alpha_i``, ``beta_i``, the
  project's data schema) with each hypothesis's predicted tip ``tip_x__<key>`` ... [m];
- ``design.json``: hypotheses, criterion, predicted separation or standard errors (recorded,
  designed, repeated, random), the motion's primitives, work and wall time;
- ``separation.png``: the hypotheses' tip distance and the accumulated separation along the motion;
- ``design.md``: a short report.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from ..choices import DesignMode, PoseFrame
from ..io.atomic import atomic_write_text
from ..planning.outputs.folder import jsonable

#: Output files by role.
FILES = {"trajectory": "trajectory.csv", "bag": "trajectory_bag", "samples": "samples.csv", "json": "design.json",
         "plot": "separation.png", "markdown": "design.md"}


def design_dict(result, robot, *, command: str = "") -> dict:
    """What ``design.json`` holds (SI units)."""
    hyps = [{"key": h.key, "label": h.label, "model": h.model, "parameters": dict(zip(h.names, h.values.tolist())),
             "free": list(h.free), "stderr": h.stderr} for h in result.hypotheses]
    criterion = ("T-optimality: the smallest over ordered pairs of the expected evidence for one hypothesis "
                 "against the other refitted to its predictions (linearized), in units of the noise"
                 if result.mode == DesignMode.SEPARATE else
                 "Ds-optimality: log det of the predicted covariance of the parameters of interest, the other free "
                 "parameters as nuisance, with a weak prior of one typical-range half-width each")
    return jsonable({
        "mode": result.mode, "criterion": criterion, "hypotheses": hyps, "interest": list(result.interest),
        "duration_s": result.duration, "budget_s": result.budget, "n_samples": int(len(result.time)),
        "primitives": [p.describe(robot.joint_names) for p in result.primitives],
        "separation": result.separation, "power": result.power, "preference": result.preference,
        "naming": result.naming,
        "stderr": result.stderr,
        "confounded": result.confounded,
        "noise_position_m": result.noise_position, "noise_inflation": result.noise_inflation,
        "noise_lower_bound": result.noise_lower_bound,
        "evaluations": result.evaluations, "seconds": result.seconds, "command": command,
        "search": (None if result.search is None else
                   {"random_motions": result.search.n_random, "seed": result.search.seed,
                    "compound": result.search.compound}),
        "joint_names": list(robot.joint_names),
        "drive": {"control_rate_hz": result.trajectory.control_rate_hz,
                  "max_velocity": result.trajectory.max_velocity, "max_acceleration": result.trajectory.max_acceleration,
                  "max_jerk": result.trajectory.max_jerk}})


def _samples_frame(result, robot) -> pd.DataFrame:
    cols = {"time": result.time, "sequence": np.zeros(len(result.time), int)}
    alpha = np.empty((len(result.time), robot.n_tubes))
    beta = np.empty_like(alpha)
    for k, q in enumerate(result.joints):
        alpha[k], beta[k] = robot.configuration(q, check_limits=False)
    for i in range(robot.n_tubes):
        cols[f"alpha_{i + 1}"] = alpha[:, i]
    for i in range(robot.n_tubes):
        cols[f"beta_{i + 1}"] = beta[:, i]
    for h, tips in zip(result.hypotheses, result.tips):
        for c, axis in enumerate("xyz"):
            cols[f"tip_{axis}__{h.key}"] = tips[:, c]
    return pd.DataFrame(cols)


def _plot(result, path: Path) -> None:
    from ..plots import new_figure, save_figure

    fig = new_figure((8, 5.5))
    axes = fig.subplots(2, 1, sharex=True)
    hyps = result.hypotheses
    t = result.time
    ref = result.tips[0]
    for h, tips in zip(hyps[1:], result.tips[1:]):
        axes[0].plot(t, 1e3 * np.linalg.norm(tips - ref, axis=1), label=f"{h.label} vs {hyps[0].label}")
    axes[0].axhline(1e3 * result.noise_position, color="0.5", ls=":", label="sensor noise per coordinate")
    axes[0].set_ylabel("tip distance [mm]")
    if len(hyps) > 1:
        axes[0].legend(fontsize=8)
    for seg in result.trajectory.segments:
        for ax in axes:
            ax.axvspan(seg.t_start, seg.t_end, color="0.92", lw=0)
    if result.mode == DesignMode.SEPARATE:
        w = 1.0 / (result.noise_position ** 2 * result.noise_inflation)
        for h, tips in zip(hyps[1:], result.tips[1:]):
            d2 = np.nansum((tips - ref) ** 2, axis=1) * w
            axes[1].plot(t, np.cumsum(d2), label=f"{h.label} vs {hyps[0].label}")
        axes[1].set_ylabel("accumulated squared distance\nbefore refit / noise variance [-]")
        axes[1].legend(fontsize=8)
    else:
        q = result.joints
        for i, name in enumerate(result.trajectory.joint_names):
            axes[1].plot(t, q[:, i], label=name)
        axes[1].set_ylabel("joint [rad or m]")
        axes[1].legend(fontsize=8)
    axes[1].set_xlabel("time [s] (grey: the drive moves)")
    save_figure(fig, path)


def _share(p) -> str:
    """A probability for the report; ``n/a`` where it could not be made (too few samples)."""
    return "n/a" if p is None or not np.isfinite(p) else f"{p:.2f}"


def _g(x, spec: str = ".3g") -> str:
    """A figure for the report; ``n/a`` where it is undefined (null in ``design.json``)."""
    return "n/a" if x is None or not np.isfinite(x) else format(x, spec)


def _median(values) -> float:
    """Median of the defined values (NaN when none is)."""
    v = [x for x in values if x is not None and np.isfinite(x)]
    return float(np.median(v)) if v else float("nan")


def _markdown(d: dict) -> str:
    lines = [f"# Designed experiment ({d['mode']})", "", f"Criterion: {d['criterion']}.", "",
             f"Duration {d['duration_s']:.1f} s of a budget of {d['budget_s']:.1f} s, {d['n_samples']} sensor samples; "
             f"sensor noise {1e3 * d['noise_position_m']:.3g} mm per coordinate (long-run variance factor "
             f"{d['noise_inflation']:.3g})."
             + (" **The noise is only a lower bound** (the discrepancy run's rests were too short to see its "
                "correlation): the noise may be larger, so the predicted separations and powers below are upper "
                "bounds and the standard errors lower bounds." if d.get("noise_lower_bound") else ""),
             "", "Hypotheses:", ""]
    for h in d["hypotheses"]:
        lines.append(f"- `{h['key']}`: {h['label']} ({h['model']} model; refit over {len(h['free'])} parameters)")
    lines += ["", "Motion:", ""] + [f"{k + 1}. {p}" for k, p in enumerate(d["primitives"])] + [""]
    if d["mode"] == DesignMode.SEPARATE:
        lines += ["| pair (true > refitted) | recorded | designed alone | recorded + designed | recorded + repeated | "
                  "recorded + random (median) |", "| --- | --- | --- | --- | --- | --- |"]
        for pair, t in d["separation"]["recorded"].items():
            rnd = [r[pair] for r in d["separation"]["random"]]
            lines.append(f"| {pair} | {_g(t)} | {_g(d['separation']['designed_alone'][pair])} | "
                         f"{_g(d['separation']['designed'][pair])} | {_g(d['separation']['repeated'][pair])} | "
                         f"{_g(_median(rnd))} |")
        rnd = d["power"]["random"]
        lines += ["", f"Smallest predicted power over the pairs (1-df likelihood-ratio test at 0.01): recorded "
                      f"{_g(d['power']['recorded'], '.3f')}, designed {_g(d['power']['designed'], '.3f')}, repeated "
                      f"{_g(d['power']['repeated'], '.3f')}, random median {_g(_median(rnd), '.3f')}."]
        for key, text in (("preference", "Probability that the discrepancy workflow's fold comparison prefers the "
                                         "true hypothesis (the first of the pair) at 0.01 (simulated on the "
                                         "linearized hypotheses; the comparison of the two, not the whole verdict): "),
                          ("naming", "Probability that the workflow names the hypothesis alone when it is true "
                                     "(its error significantly below the baseline's at Holm's first step and below "
                                     "every rival's at 0.01; simulated on the linearized hypotheses): ")):
            table = d.get(key) or {}
            if table:
                lines += ["", text + "; ".join(f"{k}: recorded {_share(table['recorded'][k])}, with the design "
                                               f"{_share(table['designed'][k])}" for k in table.get("designed", {}))
                          + "."]
    else:
        lines += ["| parameter | recorded | designed alone | recorded + designed | recorded + repeated | "
                  "recorded + random (median) |", "| --- | --- | --- | --- | --- | --- |"]
        for n, se in d["stderr"]["recorded"].items():
            rnd = [r[n] for r in d["stderr"]["random"]]
            lines.append(f"| {n} | {_g(se)} | {_g(d['stderr']['designed_alone'][n])} | {_g(d['stderr']['designed'][n])} | "
                         f"{_g(d['stderr']['repeated'][n])} | {_g(_median(rnd))} |")
        lines += ["", "Predicted standard errors, SI units (prior-limited where the recorded data determine nothing)."]
        for n, others in d.get("confounded", {}).items():
            if others:
                lines.append(f"- `{n}`: predicted correlation after the design with " +
                             ", ".join(f"`{k}` {v:+.2f}" for k, v in others.items()) +
                             " (what keeps it undetermined where the design does not shrink its standard error).")
    lines += ["", f"{d['evaluations']} model evaluations; " +
              ", ".join(f"{k} {v:.1f} s" for k, v in d["seconds"].items()) + "."]
    return "\n".join(lines) + "\n"


def write_design(result, robot, out_dir, *, command: str = "", bag: bool = True, frame: str = "robot") -> dict:
    """Write the output folder of a design.

    Parameters
    ----------
    result : DesignResult
    robot : Robot
    out_dir : str or path-like
        Created if missing.
    command : str
        The command that made it (recorded in ``design.json``).
    bag : bool
        Write the ROS 2 bag.
    frame : PoseFrame or str
        ``"robot"`` or ``"tracker"``.
        Frame of the predicted tips (the recorded data's): the bag's tip path is in ``ctr_base`` or
        ``tracker``.

    Returns
    -------
    dict of str to Path
        Written files by role (:data:`FILES`).

    Raises
    ------
    FileExistsError
        ``trajectory_bag`` exists and is not a bag written by ctrplan.
    """
    from ..io.ros2 import PlanBagContent, write_plan_bag
    from ..planning.outputs.folder import write_trajectory_csv

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = {}
    write_trajectory_csv(out / FILES["trajectory"], result.trajectory)
    written["trajectory"] = out / FILES["trajectory"]
    samples = _samples_frame(result, robot)
    atomic_write_text(out / FILES["samples"], samples.to_csv(index=False))
    written["samples"] = out / FILES["samples"]
    d = design_dict(result, robot, command=command)
    atomic_write_text(out / FILES["json"], json.dumps(d, indent=2) + "\n")
    written["json"] = out / FILES["json"]
    _plot(result, out / FILES["plot"])
    written["plot"] = out / FILES["plot"]
    atomic_write_text(out / FILES["markdown"], _markdown(d))
    written["markdown"] = out / FILES["markdown"]
    if bag:
        traj = result.trajectory
        idx = [int(np.argmin(np.abs(result.time - s.t_end))) for s in traj.segments]
        idx = [0] + idx
        tips = np.nan_to_num(result.tips[0][idx])
        content = PlanBagContent(joint_names=traj.joint_names, t=traj.t, position=traj.position,
                                 velocity=traj.velocity, acceleration=traj.acceleration, tips=tips,
                                 tip_rotations=None, bound_radius=np.full(len(idx), np.nan),
                                 bound_label="none", frame_id="ctr_base" if frame == PoseFrame.ROBOT else "tracker")
        written["bag"] = write_plan_bag(out / FILES["bag"], content)
    return written
