"""Batch evaluation of many configurations (``ctrplan evaluate``): parallel, resumable.

Configurations are evaluated in chunks: the standard model solves a whole chunk in one compiled
call (``solve_standard_batch``, with the stability check of ``solve_standard`` screened in
batch), the contact models one configuration after another. Each finished chunk is appended to
a checkpoint file (one JSON line per chunk) as it arrives, so an interrupted run resumes without
recomputing it; the final CSV is written atomically and the checkpoint removed.
"""

from __future__ import annotations

import base64
import json
import logging
import os
from pathlib import Path

import numpy as np
import pandas as pd

from .cache import content_key, mechanics_version
from .errors import CtrplanError
from .mechanics import ModelSettings, angle_between, solve_standard, solve_standard_batch
from .models import MODEL_INFO, MODELS, check_model  # the one registry of models

__all__ = ["MODELS", "evaluate_configuration", "evaluate_table", "job_key"]

logger = logging.getLogger(__name__)

# Configurations per task: the standard model's compiled batch takes about 0.05-0.4 ms per
# configuration, so a chunk of this many keeps the per-task overhead (one checkpoint line, the
# start of the compiled threads, and per thread a first row that follows no other) small: on
# the trajectory four times over with two threads, 32 us per row in chunks of 256, 29 in chunks
# of 1024 and 28 in one chunk, against 55 on one thread; a contact-model
# configuration takes 10-100 ms.
STANDARD_CHUNK = 2048
CONTACT_CHUNK = 4


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


def _friction_message(sol, explain, robot, alpha, beta, eta, settings, standard, clearance):
    """The message of friction solution ``sol``; with ``explain``, if it did not converge, also
    where its branch in mu ends (:func:`ctrplan.mechanics.continue_friction`): a fold below the
    robot's mu, or mu reached (then the direct solve failed)."""
    message = sol.diagnostics.message
    if not explain or sol.diagnostics.converged:
        return message
    from .mechanics import continue_friction
    try:
        branch = continue_friction(robot, alpha, beta, eta, settings, standard=standard, clearance=clearance)
    except (CtrplanError, np.linalg.LinAlgError, FloatingPointError) as exc:
        return f"{message}; not explained: {exc}"
    verdict = ("snaps under friction" if not branch.reached else
               "solver failure: the branch reaches the robot's mu")
    return f"{message}; {verdict}: {branch.message}"


def evaluate_configuration(robot, alpha, beta, model: str, settings: ModelSettings | None = None,
                           eta=None, *, explain_failures: bool = False) -> list[dict]:
    """Evaluate one configuration; returns rows in the project's CSV schema.

    Parameters
    ----------
    robot : Robot
    alpha, beta : array-like, shape (n,)
        Base rotations [rad] and translations [m].
    model : str
        A registered mechanics model (:data:`ctrplan.models.MODEL_REGISTRY`: ``"standard"``,
        ``"clearance"``, ``"friction"`` or one registered by the user), solved by its entry's
        ``solve`` on top of the standard solve.
    settings : ModelSettings, optional
    eta : array-like of int, shape (n - 1,), optional
        Friction directions (+1 CCW, -1 CW). For the friction model: None or any zero entry
        evaluates all 2^(n-1) directions and adds the bound columns ``bound_tip_m`` and
        ``bound_tangent_rad`` (Section III of Ha et al. 2019); otherwise only that direction.
    explain_failures : bool
        For each friction solve that did not converge, follow it in mu from the clearance
        solution (:func:`ctrplan.mechanics.continue_friction`) and add to its message whether its
        branch ends at a fold below the robot's mu ("snaps under friction") or reaches mu
        ("solver failure"). Costs about 14-16 friction solves per such row.

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
    info = MODEL_INFO[check_model(model)]
    settings = settings or ModelSettings()
    alpha = np.asarray(alpha, dtype=float)
    beta = np.asarray(beta, dtype=float)
    try:
        std = solve_standard(robot, alpha, beta, settings)
        if not info.contact:
            sol = info.solve(robot, alpha, beta, settings, standard=std)
            return [_row(alpha, beta, None, sol, _status(sol.diagnostics), sol.diagnostics.message, model)]
        if not info.friction:
            cl = info.solve(robot, alpha, beta, settings, standard=std)
            row = _row(alpha, beta, None, cl, _status(cl.diagnostics), cl.diagnostics.message, model)
            row["translation_last_tip_m"] = float(np.linalg.norm(cl.tip_position - std.tip_position))
            row["translation_last_tangent_rad"] = float(angle_between(cl.tip_tangent, std.tip_tangent))
            return [row]
        given = eta is not None and np.all(np.isin(np.asarray(eta), (-1, 1)))
        if given:
            # the frictionless solution first: a friction solve started from it converges in a few steps
            cl = info.solve(robot, alpha, beta, settings, standard=std)
            fr = info.solve(robot, alpha, beta, settings, eta=np.asarray(eta, dtype=int), standard=std, warm_start=cl)
            message = _friction_message(fr, explain_failures, robot, alpha, beta, np.asarray(eta, dtype=int),
                                        settings, std, cl)
            row = _row(alpha, beta, np.asarray(eta, dtype=int), fr, _status(fr.diagnostics), message, model)
            row["translation_last_tip_m"] = float(np.linalg.norm(cl.tip_position - std.tip_position))
            row["translation_last_tangent_rad"] = float(angle_between(cl.tip_tangent, std.tip_tangent))
            return [row]
        # the bound over every direction (Section III), imported here: a standard-model run does not
        # import the contact kernels (ctrplan.mechanics imports them lazily; about 40 ms)
        from .mechanics import all_eta, evaluate_bound
        b = evaluate_bound(robot, alpha, beta, settings, standard=std)
        rows = []
        for e in all_eta(robot.n_tubes):
            f = b.friction[e]
            message = _friction_message(f, explain_failures, robot, alpha, beta, e, settings, b.standard,
                                        b.clearance)
            row = _row(alpha, beta, np.asarray(e), f, _status(f.diagnostics), message, model)
            row.update(bound_tip_m=b.position, bound_tangent_rad=b.angle,
                       translation_last_tip_m=b.translation_last_position,
                       translation_last_tangent_rad=b.translation_last_angle)
            rows.append(row)
        return rows
    except (CtrplanError, np.linalg.LinAlgError, FloatingPointError) as exc:
        return [_row(alpha, beta, None if eta is None else np.asarray(eta, dtype=int), None, "error",
                     str(exc), model)]


def _standard_columns(robot, alpha, beta, settings, indices, n_threads=1):
    """Rows of the standard model for the configurations ``indices`` (1-based row numbers) in one
    compiled call, with the same status and stability flag as :func:`evaluate_configuration`
    (``n_threads`` > 1: compiled threads share the rows in contiguous blocks, each followed in order).

    Returns the rows as columns (dict of column name -> array, one entry per configuration):
    built with array operations, not a dict per row, which cost about as much as the compiled
    solve once the uniqueness screen certified most rows."""
    res = solve_standard_batch(robot, alpha, beta, settings, check_stability=True, follow=True,
                               n_threads=n_threads)
    n = robot.n_tubes
    K = len(indices)
    valid, conv, unst = res.valid, res.converged, res.unstable
    status = np.full(K, "ok", dtype=object)
    message = np.full(K, "converged", dtype=object)
    status[unst] = "unstable"
    message[unst] = "elastically unstable: shooting Jacobian determinant <= 0"
    for k in np.flatnonzero(unst & (res.n_equilibria > 1)):
        message[k] = f"elastically unstable: {int(res.n_equilibria[k])} equilibria found by the multistart search"
    status[~conv] = "not_converged"
    message[~conv] = "shooting did not converge"
    tips = res.tip_position.copy()
    tans = res.tip_tangent.copy()
    for k in np.flatnonzero(~valid):
        status[k] = "error"
        try:
            robot.check_configuration(alpha[k], beta[k])
            message[k] = "kinematically impossible configuration"
        except CtrplanError as exc:
            message[k] = str(exc)
        tips[k] = np.nan
        tans[k] = np.nan
    cols = {f"alpha_{i + 1}": np.array(alpha[:, i], dtype=float) for i in range(n)}
    cols.update({f"beta_{i + 1}": np.array(beta[:, i], dtype=float) for i in range(n)})
    for j, c in enumerate("xyz"):
        cols[f"tip_{c}"] = tips[:, j].copy()
    for j, c in enumerate("xyz"):
        cols[f"tangent_{c}"] = tans[:, j].copy()
    cols.update(status=status, model=np.full(K, "standard", dtype=object), message=message,
                row=np.array(indices, dtype=np.int64))
    return cols


def _columns_record(indices, cols) -> dict:
    """Checkpoint line of a chunk of columns (:func:`_standard_columns`): float and integer
    columns as base64 of their little-endian float64 / int64 bytes (``arrays``, ``integers``;
    exact, and about a tenth of the time of writing the numbers as JSON text, which took 4.4 us
    per standard-model row), text columns as their distinct values and base64 int32
    codes (``categories``)."""
    arrays, integers, categories = {}, {}, {}
    for name, values in cols.items():
        values = np.asarray(values)
        if values.dtype.kind == "f":
            arrays[name] = base64.b64encode(values.astype("<f8").tobytes()).decode("ascii")
        elif values.dtype.kind in "iu":
            integers[name] = base64.b64encode(values.astype("<i8").tobytes()).decode("ascii")
        else:
            # hashed, not sorted: np.unique of the strings took 0.75 us per row, about a
            # fifth of what does not run on threads in a command-line run
            codes, uniq = pd.factorize(values, use_na_sentinel=False)
            categories[name] = {"values": [str(v) for v in uniq],
                                "codes": base64.b64encode(codes.astype("<i4").tobytes()).decode("ascii")}
    return {"indices": [int(i) - 1 for i in indices], "columns": {}, "arrays": arrays,
            "integers": integers, "categories": categories}


def _record_columns(rec: dict) -> dict:
    """The columns of a checkpoint line written by :func:`_columns_record` (or, by earlier
    versions, with columns as JSON lists in ``columns``; a column there takes precedence)."""
    cols = {}
    for name, text in rec.get("arrays", {}).items():
        cols[name] = np.frombuffer(base64.b64decode(text), dtype="<f8").astype(float)
    for name, text in rec.get("integers", {}).items():
        cols[name] = np.frombuffer(base64.b64decode(text), dtype="<i8").astype(np.int64)
    for name, cat in rec.get("categories", {}).items():
        codes = np.frombuffer(base64.b64decode(cat["codes"]), dtype="<i4")
        cols[name] = np.asarray(cat["values"], dtype=object)[codes]
    cols.update(rec["columns"])
    return cols


def _chunk_task(robot, alpha, beta, model, settings, eta, indices, n_threads=1, explain_failures=False):
    """Evaluate the configurations ``alpha``, ``beta`` (m, n) of the 1-based rows ``indices``;
    returns (indices, list of m lists of rows), or for the standard model (indices, columns) with
    the columns of :func:`_standard_columns`."""
    if MODEL_INFO[model].standard_only:
        return indices, _standard_columns(robot, alpha, beta, settings, indices, n_threads)
    rows = []
    for k, index in enumerate(indices):
        found = evaluate_configuration(robot, alpha[k], beta[k], model, settings,
                                       None if eta is None else eta[k], explain_failures=explain_failures)
        for r in found:
            r["row"] = index
        rows.append(found)
    return indices, rows


def _run_tasks(tasks, n_local, n_jobs):
    """Results of ``tasks`` ([(tag, args of :func:`_chunk_task`)]) in order of completion: the first
    ``n_local`` in this process, then the others on ``n_jobs`` workers
    (:class:`ctrplan.parallel.Executor`), started only after those (a generator: the workers
    start when it gets there)."""
    from .parallel import Executor

    for _, args in tasks[:n_local]:
        yield _chunk_task(*args)
    if n_local < len(tasks):
        with Executor(n_jobs) as ex:
            for _, result in ex.run(_chunk_task, tasks[n_local:]):
                yield result


def _chunks(todo, model, n_jobs):
    """Split the 0-based rows ``todo`` into tasks: at most the model's chunk size, and (contact
    models in worker processes) at least four tasks per worker so that they stay busy to the end."""
    contact = MODEL_INFO[model].contact
    size = CONTACT_CHUNK if contact else STANDARD_CHUNK
    if n_jobs != 1 and todo and contact:
        size = max(1, min(size, -(-len(todo) // (4 * max(n_jobs, 1)))))
    return [todo[i:i + size] for i in range(0, len(todo), size)]


def _read_checkpoint(ck: Path, job_key: str) -> tuple[dict[int, list | None], list[dict]]:
    """Finished rows of a checkpoint, or nothing if it belongs to another job (then it is
    deleted). Lines cut by an interruption are skipped. Reads the per-chunk lines of rows
    ({"indices", "rows"}: contact models) and of columns ({"indices", "columns", "arrays"}: the standard
    model), and the per-row lines of earlier versions ({"index", "rows"}).

    Returns
    -------
    done : dict
        0-based row -> its list of row dicts, or None where the row is in ``columns``.
    columns : list of dict
        Column chunks (column name -> list or array of values, with the 1-based ``row``).
    """
    done: dict[int, list | None] = {}
    columns: list[dict] = []
    with open(ck) as fh:
        lines = fh.read().splitlines()
    if not lines or json.loads(lines[0]).get("job_key") != job_key:
        ck.unlink()
        return done, columns
    for line in lines[1:]:
        try:
            rec = json.loads(line)
        except json.JSONDecodeError:  # a line cut by an interruption
            continue
        if "columns" in rec:
            columns.append(_record_columns(rec))
            for index in rec["indices"]:
                done[int(index)] = None
        elif "indices" in rec:
            for index, rows in zip(rec["indices"], rec["rows"]):
                done[int(index)] = rows
        else:
            done[int(rec["index"])] = rec["rows"]
    return done, columns


def _assemble(done: dict, columns: list[dict], K: int) -> pd.DataFrame:
    """All finished rows as one frame in input order (column ``row``; rows of one configuration
    keep their order)."""
    parts = [pd.DataFrame(c) for c in columns]
    rows = [r for k in range(K) if done[k] is not None for r in done[k]]
    if rows:
        parts.append(pd.DataFrame(rows))
    if not parts:
        return pd.DataFrame()
    frame = parts[0] if len(parts) == 1 else pd.concat(parts, ignore_index=True)
    if frame["row"].is_monotonic_increasing:    # chunks finished in order (the usual case)
        return frame.reset_index(drop=True)
    return frame.sort_values("row", kind="stable").reset_index(drop=True)


def evaluate_table(robot, alpha, beta, model: str, settings: ModelSettings | None = None, eta=None,
                   *, n_jobs: int = 1, checkpoint: str | os.PathLike | None = None,
                   progress: bool = False, job_key: str = "", explain_failures: bool = False) -> pd.DataFrame:
    """Evaluate K configurations in chunks, in parallel, resuming from a checkpoint.

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
        Parallel workers (1: in this process, serially). The contact models use local worker
        processes (:class:`ctrplan.parallel.Executor`), started once, that take chunks of
        ``CONTACT_CHUNK`` rows. The standard model
        runs in this process, ``n_jobs`` compiled threads sharing each chunk of
        ``STANDARD_CHUNK`` rows: its whole run takes less than starting worker processes.
    checkpoint : path, optional
        JSON-lines file of finished chunks; rows already in it (same ``job_key``) are skipped.
    progress : bool
        Show a tqdm progress bar (default none).
    job_key : str
        Identifies the job (robot file, inputs, model, settings); a checkpoint with another key
        is not reused.
    explain_failures : bool
        Contact models: see :func:`evaluate_configuration`.

    Returns
    -------
    pandas.DataFrame
        All rows in input order (column ``row`` = input row, 1-based). The standard model's
        rows are those of :func:`evaluate_configuration` (tips to the shooting tolerance, the
        same stability flag), computed by ``solve_standard_batch`` with ``check_stability``;
        its ``message`` omits the residual and determinant values.
    """
    from tqdm.auto import tqdm

    from .mechanics import warmup

    check_model(model)
    settings = settings or ModelSettings()
    alpha = np.asarray(alpha, dtype=float)
    beta = np.asarray(beta, dtype=float)
    K = alpha.shape[0]
    ck = Path(checkpoint) if checkpoint is not None else None
    done, columns = _read_checkpoint(ck, job_key) if ck is not None and ck.exists() else ({}, [])
    todo = [k for k in range(K) if k not in done]
    if done:
        logger.debug(f"{model} model: {K - len(todo)} of {K} rows read from the checkpoint {ck}")
    fh = None
    if ck is not None:
        new = not ck.exists()
        fh = open(ck, "a")
        if new:
            fh.write(json.dumps({"job_key": job_key}) + "\n")
            fh.flush()
    try:
        in_process = n_jobs == 1 or not MODEL_INFO[model].contact
        # worker processes on a cold start: the first row runs here first, so that the compiled
        # kernels are on disk before the workers start (else each worker compiles them again);
        # warm, the workers start at once (loading the kernels here too would cost about 0.5 s)
        cold = not in_process and todo and not warmup.contact_kernels_cached()
        first = [todo[:1]] if cold else []
        chunks = first + _chunks(todo[len(first):], model, n_jobs)
        threads = 1 if MODEL_INFO[model].contact else n_jobs
        tasks = [(i, (robot, alpha[c], beta[c], model, settings, None if eta is None else eta[c],
                      [k + 1 for k in c], threads, explain_failures))
                 for i, c in enumerate(chunks)]
        results = _run_tasks(tasks, len(tasks) if in_process else len(first), n_jobs)
        with tqdm(total=K, initial=K - len(todo), disable=not progress, unit="config",
                  desc=f"{model} model") as bar:
            for indices, rows in results:
                if isinstance(rows, dict):      # the standard model's columns
                    columns.append(rows)
                    for index in indices:
                        done[index - 1] = None
                    record = _columns_record(indices, rows)
                else:
                    for index, r in zip(indices, rows):
                        done[index - 1] = r
                    record = {"indices": [i - 1 for i in indices], "rows": rows}
                if fh is not None:
                    fh.write(json.dumps(record) + "\n")
                    fh.flush()
                bar.update(len(indices))
    finally:
        if fh is not None:
            fh.close()
    return _assemble(done, columns, K)


def job_key(robot_file_text: str, config_file_text: str, model: str, settings: ModelSettings,
            explain_failures: bool = False) -> str:
    """Checkpoint key of a batch job (:mod:`ctrplan.cache`): the robot and configuration files'
    text, the model, its settings and the mechanics version, so that a checkpoint written by
    other mechanics is not reused.

    Returns
    -------
    str
        64 hexadecimal digits.
    """
    inputs = [robot_file_text, config_file_text, model, settings.as_dict(), {"mechanics": mechanics_version()}]
    if explain_failures:
        inputs.append("explain_failures")
    return content_key(inputs)
