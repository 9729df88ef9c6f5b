"""Batch evaluation of many configurations (``ctrplan evaluate``): parallel, resumable.

Each configuration is one task. Finished rows are appended to a checkpoint file (one JSON line
per configuration) as they arrive, so an interrupted run resumes without recomputing them; the
final CSV is written atomically and the checkpoint removed.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import numpy as np
import pandas as pd

from .errors import CtrplanError
from .mechanics import (ModelSettings, all_eta, evaluate_bound, solve_clearance, solve_friction,
                        solve_standard)
from .mechanics._lie import angle_between

__all__ = ["MODELS", "evaluate_configuration", "evaluate_table", "job_key"]

MODELS = ("standard", "clearance", "friction")


def _status(diag) -> str:
    if not diag.converged:
        return "not_converged"
    if diag.unstable:
        return "unstable"
    return "ok"


def _row(alpha, beta, eta, sol, status, message, model):
    n = alpha.size
    row = {f"alpha_{i + 1}": float(alpha[i]) for i in range(n)}
    row.update({f"beta_{i + 1}": float(beta[i]) for i in range(n)})
    if eta is not None:
        row.update({f"eta_{i + 1}": int(eta[i]) for i in range(n - 1)})
    tip = sol.tip_position if sol is not None else np.full(3, np.nan)
    tan = sol.tip_tangent if sol is not None else np.full(3, np.nan)
    row.update(tip_x=float(tip[0]), tip_y=float(tip[1]), tip_z=float(tip[2]),
               tangent_x=float(tan[0]), tangent_y=float(tan[1]), tangent_z=float(tan[2]),
               status=status, model=model, message=message)
    return row


def evaluate_configuration(robot, alpha, beta, model: str, settings: ModelSettings | None = None,
                           eta=None) -> list[dict]:
    """Evaluate one configuration; returns rows in the project's CSV schema.

    Parameters
    ----------
    robot : Robot
    alpha, beta : array-like, shape (n,)
        Base rotations [rad] and translations [m].
    model : {"standard", "clearance", "friction"}
    settings : ModelSettings, optional
    eta : array-like of int, shape (n - 1,), optional
        Friction directions (+1 CCW, -1 CW). For the friction model: None or any zero entry
        evaluates all 2^(n-1) directions and adds the bound columns ``bound_tip_m`` and
        ``bound_tangent_rad`` (Section III of Ha et al. 2019); otherwise only that direction.

    Returns
    -------
    list of dict
        One row (standard, clearance, or friction with a given eta) or 2^(n-1) rows. Failures
        give a row with status ``error`` and the message, never an exception. Clearance and
        friction rows carry the translation-last bound ``translation_last_tip_m`` [m] and
        ``translation_last_tangent_rad`` [rad] (Section V-B).

    Raises
    ------
    ValueError
        Unknown model name.
    """
    if model not in MODELS:
        raise ValueError(f"model must be one of {', '.join(MODELS)}, got {model!r}")
    settings = settings or ModelSettings()
    alpha = np.asarray(alpha, dtype=float)
    beta = np.asarray(beta, dtype=float)
    try:
        std = solve_standard(robot, alpha, beta, settings)
        if model == "standard":
            return [_row(alpha, beta, None, std, _status(std.diagnostics), std.diagnostics.message, model)]
        if model == "clearance":
            cl = solve_clearance(robot, alpha, beta, settings, standard=std)
            row = _row(alpha, beta, None, cl, _status(cl.diagnostics), cl.diagnostics.message, model)
            row["translation_last_tip_m"] = float(np.linalg.norm(cl.tip_position - std.tip_position))
            row["translation_last_tangent_rad"] = float(angle_between(cl.tip_tangent, std.tip_tangent))
            return [row]
        given = eta is not None and np.all(np.isin(np.asarray(eta), (-1, 1)))
        if given:
            cl = solve_clearance(robot, alpha, beta, settings, standard=std)
            fr = solve_friction(robot, alpha, beta, np.asarray(eta, dtype=int), settings, standard=std,
                                warm_start=cl)
            row = _row(alpha, beta, np.asarray(eta, dtype=int), fr, _status(fr.diagnostics),
                       fr.diagnostics.message, model)
            row["translation_last_tip_m"] = float(np.linalg.norm(cl.tip_position - std.tip_position))
            row["translation_last_tangent_rad"] = float(angle_between(cl.tip_tangent, std.tip_tangent))
            return [row]
        b = evaluate_bound(robot, alpha, beta, settings, standard=std)
        rows = []
        for e in all_eta(robot.n_tubes):
            f = b.friction[e]
            row = _row(alpha, beta, np.asarray(e), f, _status(f.diagnostics), f.diagnostics.message, model)
            row.update(bound_tip_m=b.position, bound_tangent_rad=b.angle,
                       translation_last_tip_m=b.translation_last_position,
                       translation_last_tangent_rad=b.translation_last_angle)
            rows.append(row)
        return rows
    except (CtrplanError, np.linalg.LinAlgError, FloatingPointError) as exc:
        return [_row(alpha, beta, None if eta is None else np.asarray(eta, dtype=int), None, "error",
                     str(exc), model)]


def _task(robot, alpha, beta, model, settings, eta, index):
    rows = evaluate_configuration(robot, alpha, beta, model, settings, eta)
    for r in rows:
        r["row"] = index
    return index, rows


def evaluate_table(robot, alpha, beta, model: str, settings: ModelSettings | None = None, eta=None,
                   *, n_jobs: int = 1, checkpoint: str | os.PathLike | None = None,
                   progress: bool = True, job_key: str = "") -> pd.DataFrame:
    """Evaluate K configurations in parallel, resuming from a checkpoint.

    Parameters
    ----------
    robot : Robot
    alpha, beta : ndarray, shape (K, n)
        [rad], [m].
    model : {"standard", "clearance", "friction"}
    settings : ModelSettings, optional
    eta : ndarray of int, shape (K, n - 1), optional
        Per-row friction directions (0 = unknown: all directions).
    n_jobs : int
        joblib worker processes (1: in this process).
    checkpoint : path, optional
        JSON-lines file of finished rows; rows already in it (same ``job_key``) are skipped.
    progress : bool
        Show a tqdm progress bar.
    job_key : str
        Identifies the job (robot file, inputs, model, settings); a checkpoint with another key
        is not reused.

    Returns
    -------
    pandas.DataFrame
        All rows in input order (column ``row`` = input row, 1-based).
    """
    from joblib import Parallel, delayed
    from tqdm.auto import tqdm

    settings = settings or ModelSettings()
    K = alpha.shape[0]
    done: dict[int, list] = {}
    ck = Path(checkpoint) if checkpoint is not None else None
    if ck is not None and ck.exists():
        with open(ck) as fh:
            lines = fh.read().splitlines()
        if lines and json.loads(lines[0]).get("job_key") == job_key:
            for line in lines[1:]:
                try:
                    rec = json.loads(line)
                except json.JSONDecodeError:  # a line cut by an interruption
                    continue
                done[int(rec["index"])] = rec["rows"]
        else:
            ck.unlink()
    todo = [k for k in range(K) if k not in done]
    fh = None
    if ck is not None:
        new = not ck.exists()
        fh = open(ck, "a")
        if new:
            fh.write(json.dumps({"job_key": job_key}) + "\n")
            fh.flush()
    try:
        tasks = (delayed(_task)(robot, alpha[k], beta[k], model, settings,
                                None if eta is None else eta[k], k + 1) for k in todo)
        runner = Parallel(n_jobs=n_jobs, return_as="generator_unordered") if n_jobs != 1 else None
        results = runner(tasks) if runner is not None else (t[0](*t[1], **t[2]) for t in tasks)
        with tqdm(total=K, initial=K - len(todo), disable=not progress, unit="config",
                  desc=f"{model} model") as bar:
            for index, rows in results:
                done[index - 1] = rows
                if fh is not None:
                    fh.write(json.dumps({"index": index - 1, "rows": rows}) + "\n")
                    fh.flush()
                bar.update(1)
    finally:
        if fh is not None:
            fh.close()
    rows = [r for k in range(K) for r in done[k]]
    return pd.DataFrame(rows)


def job_key(robot_file_text: str, config_file_text: str, model: str, settings: ModelSettings) -> str:
    """Checkpoint key of a batch job (sha256 of its inputs)."""
    payload = json.dumps([robot_file_text, config_file_text, model, settings.as_dict()], sort_keys=True)
    return hashlib.sha256(payload.encode()).hexdigest()
