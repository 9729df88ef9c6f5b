"""The probability that the discrepancy workflow prefers the true hypothesis over a rival after a
motion, judged as the workflow judges it: its fold comparison, simulated on the linearized
hypotheses.

With hypothesis A true and B refitted to A's predicted tips over the whole motion (the recording
and the follow-up together), B keeps the part of A's signature its parameters cannot reproduce,
``u_k = r_k - J_B,k delta`` at sample k (``r = y_A - y_B``, ``delta`` B's least-squares step; the
same linearization as the separation ``T = sum |u_k|^2 / s^2`` of :mod:`._criteria`). A simulated
recording draws the sensor noise ``n_k`` of :class:`~ctrplan.design.SensorNoise` (a white part and
an AR(1) part, per tip coordinate); A's error at sample k is ``|n_k|`` and B's ``|n_k + u_k|``. The
samples are split as the workflow splits a record of their number (:func:`workflow_split`, the rule
of :mod:`ctrplan.discrepancy.measured.split`): time blocks, those spread over the motion held back
as the test split, the others dealt in turn to the cross-validation folds; and the workflow's own
test decides: :func:`ctrplan.discrepancy.verdict.statistics.cv_comparison`, the corrected
resampled t test of the folds' log error ratios, one-sided at ``level``. The probability is the share
of :data:`DRAWS` simulated recordings in which A's error is significantly lower.

What it leaves out: the longer blocks the workflow cuts where the residuals stay correlated past
half a block, the buffers beside each validated block, the refits per fold (B is refitted once, on
all samples: its out-of-fold error is a little larger in the workflow), the tangent angles the
workflow's error also holds where the tracker measures them, and the other gates of naming. :func:`naming_probability` adds the first of them: on the same
simulated recordings, the true hypothesis's error must also be significantly lower than the
baseline's (the model with no effect, its tube parameters refitted) at ``level / m``, Holm's first
step over the ``m`` candidates the workflow tried alone. What the naming probability still leaves
out: the later steps of Holm's procedure (a rival significant against the baseline only at a looser
step), the separability check of the leading two (their fields' correlation on the motion) and
the second-effect stage (which may add a rival beside the truth). Its baseline is refitted
linearly, without the workflow's prior toward the robot file's tube parameters: on a lag hidden
in a motion with rests, the refit keeps part of the signature in every block and the prediction
is overconfident (``docs/design.md``, the benchmark's calibration).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

__all__ = ["unexplained", "preference_probability", "predicted_preference", "preference_table", "recorded_rows",
           "naming_probability", "predicted_naming", "naming_table",
           "workflow_split", "FoldPlan", "DRAWS", "MAX_RECORDED_SAMPLES"]

#: Simulated recordings per probability [-].
DRAWS = 400
#: Recorded samples the hypotheses are differentiated at, at most (evenly spaced, both ends kept).
MAX_RECORDED_SAMPLES = 300


def recorded_rows(n_samples: int) -> np.ndarray:
    """The recorded samples the hypotheses are differentiated at: at most
    :data:`MAX_RECORDED_SAMPLES`, evenly spaced with both ends kept; indices, shape (k,)."""
    return np.unique(np.linspace(0, n_samples - 1, min(n_samples, MAX_RECORDED_SAMPLES)).round().astype(int))


def unexplained(sens_true, sens_rival) -> np.ndarray:
    """What the rival hypothesis cannot reproduce of the true one's tips after its best linearized
    refit over all the samples given.

    Parameters
    ----------
    sens_true, sens_rival : sequence of Sensitivities
        The two hypotheses' predicted tips and Jacobians (:func:`~ctrplan.design._criteria.sensitivities`),
        one per recording, the same samples for both (the recording, then the follow-up).

    Returns
    -------
    ndarray, shape (K, 3)
        ``u_k`` [m] at every sample where both converged, in the order given.
    """
    ra, jb = [], []
    for sa, sb in zip(sens_true, sens_rival):
        ok = sa.ok & sb.ok
        ra.append(sa.tip[ok] - sb.tip[ok])
        jb.append(sb.jacobian[ok])
    r = np.concatenate(ra) if ra else np.zeros((0, 3))
    J = np.concatenate(jb) if jb else np.zeros((0, 3, 0))
    if not r.size:
        return r.reshape(0, 3)
    if J.shape[2]:              # a rival without free parameters (a baseline held at the robot file) is not refitted
        flat_j = J.reshape(-1, J.shape[2])
        delta = np.linalg.lstsq(flat_j, r.reshape(-1), rcond=None)[0]
        r = r - (flat_j @ delta).reshape(r.shape)
    return r


def preference_probability(u, noise, *, level: float, draws: int = DRAWS, plan: "FoldPlan | None" = None,
                           seed: int = 0) -> float:
    """Probability that the workflow's fold comparison finds the true hypothesis's error lower than
    the rival's at ``level`` (module docstring).

    Parameters
    ----------
    u : array-like, shape (K, 3)
        What the rival cannot reproduce at each sample, in time order [m] (:func:`unexplained`).
    noise : SensorNoise
        Noise per tip coordinate [m], its lag-one correlation and the share of its variance in the
        correlated part.
    level : float
        One-sided level of the comparison, in (0, 1).
    draws : int
        Simulated recordings.
    plan : FoldPlan, optional
        The split in ``u``'s samples; default :func:`workflow_split` of their number.
    seed : int
        Seed of the simulated noise.

    Returns
    -------
    float
        In [0, 1]; NaN when the samples make fewer than two folds.

    Raises
    ------
    ValueError
        ``level`` outside (0, 1), ``u`` not of shape (K, 3), or ``draws`` below 1.
    """
    u = np.asarray(u, dtype=float)
    if u.ndim != 2 or u.shape[1] != 3:
        raise ValueError(f"u needs shape (K, 3) [m], got {u.shape}")
    return _all_significant([u], [level], noise, draws=draws, plan=plan, seed=seed)


def _all_significant(us, levels, noise, *, draws: int, plan, seed: int) -> float:
    """Share of ``draws`` simulated recordings in which the truth's error (the noise alone) is
    significantly below every rival's (the noise plus ``us[i]``, shape (K, 3) [m]) at
    ``levels[i]`` by the workflow's fold comparison; samples where any ``u`` is not finite left
    out; NaN when the samples make fewer than two folds."""
    from ..discrepancy.verdict.statistics import cv_comparison

    bad = [lv for lv in levels if not 0.0 < lv < 1.0]
    if bad:
        raise ValueError(f"level {bad[-1]!r} must be in (0, 1)")
    if draws < 1:
        raise ValueError(f"draws must be >= 1, got {draws}")
    keep = np.all([np.all(np.isfinite(u), axis=1) for u in us], axis=0)
    folds = _folds(int(keep.sum()), plan)
    if folds is None:
        return float("nan")
    n = _noise_draws(int(keep.sum()), noise, draws, seed)[folds >= 0]
    us, folds = [u[keep][folds >= 0] for u in us], folds[folds >= 0]
    err_true = np.linalg.norm(n, axis=2)
    errs = [np.linalg.norm(n + u[:, None, :], axis=2) for u in us]
    hits = sum(all(cv_comparison(e[:, d], err_true[:, d], folds).p_value < lv for e, lv in zip(errs, levels))
               for d in range(draws))
    return hits / draws


class FoldPlan(NamedTuple):
    """The workflow's split of a record, in samples of the record the prediction evaluates.

    Attributes
    ----------
    block : int
        Samples per time block (a unit), >= 1.
    n_folds : int
        Cross-validation folds the development blocks are dealt to.
    n_test : int
        Blocks held back as the test split.
    """

    block: int
    n_folds: int
    n_test: int


def workflow_split(n_samples, evaluated: int | None = None, *, test_fraction: float = 0.2) -> FoldPlan:
    """The split the discrepancy workflow makes of continuous recordings of ``n_samples`` samples
    (:func:`ctrplan.discrepancy.measured.split.make_split` with its defaults): at most
    ``MAX_BLOCKS`` time blocks of at least ``MIN_BLOCK_SAMPLES`` over all the samples, each
    recording cut into blocks of that length; a test split of at least ``MIN_TEST_UNITS`` blocks
    and ``test_fraction`` of them; the other blocks dealt to at most ``MAX_FOLDS`` folds of at
    least ``MIN_UNITS_PER_FOLD`` blocks.

    Parameters
    ----------
    n_samples : int or sequence of int
        Samples of each recording the workflow will split together (the recording, then the
        follow-up).
    evaluated : int, optional
        Samples the prediction evaluates of them all (fewer where the recording is thinned,
        :func:`recorded_rows`): the block is scaled to them. Default all.
    test_fraction : float
        The workflow's ``test_fraction`` [-].

    Returns
    -------
    FoldPlan
        ``n_folds`` below 2 when the recordings are too short for the workflow's comparison.
    """
    from ..discrepancy.measured.split import (MAX_BLOCKS, MAX_FOLDS, MIN_BLOCK_SAMPLES, MIN_TEST_UNITS,
                                              MIN_UNITS_PER_FOLD)

    lengths = [int(n) for n in np.atleast_1d(n_samples)]
    total = sum(lengths)
    block = max(MIN_BLOCK_SAMPLES, math.ceil(total / max(2, min(MAX_BLOCKS, total // MIN_BLOCK_SAMPLES))))
    n_units = sum(math.ceil(n / block) for n in lengths)
    n_test = max(MIN_TEST_UNITS, int(round(test_fraction * n_units)))
    n_folds = min(MAX_FOLDS, max(n_units - n_test, 0) // MIN_UNITS_PER_FOLD)
    evaluated = total if evaluated is None else int(evaluated)
    return FoldPlan(max(1, round(block * evaluated / max(total, 1))), n_folds, n_test)


def _folds(K: int, plan: "FoldPlan | None"):
    """Fold of each of K samples in time order under ``plan`` (default :func:`workflow_split` of
    K): -1 for the test split's blocks (evenly spread), the others' blocks dealt in turn to the
    folds; None when that gives fewer than two folds."""
    plan = workflow_split(K) if plan is None else plan
    n_blocks = math.ceil(K / plan.block) if K else 0
    if plan.n_folds < 2 or n_blocks - plan.n_test < 2:
        return None
    unit = np.arange(K) // plan.block
    test = np.unique(np.linspace(0, n_blocks - 1, plan.n_test).round().astype(int))
    dev = np.setdiff1d(np.arange(n_blocks), test)
    fold_of_block = np.full(n_blocks, -1)
    fold_of_block[dev] = np.arange(dev.size) % min(plan.n_folds, dev.size)
    return fold_of_block[unit]


def _noise_draws(K: int, noise, draws: int, seed: int) -> np.ndarray:
    """``draws`` simulated noise records of K samples, shape (K, draws, 3) [m]: a white part and a
    stationary AR(1) part of :class:`~ctrplan.design.SensorNoise`."""
    rng = np.random.default_rng(seed)
    s = float(noise.position)
    phi = float(noise.lag1) if noise.lag1 else 0.0
    share = float(noise.correlated_share) if phi else 0.0
    white = rng.standard_normal((K, draws, 3)) * (s * math.sqrt(1.0 - share))
    corr = np.empty((K, draws, 3))
    innov = rng.standard_normal((K, draws, 3)) * (s * math.sqrt(share))
    corr[0] = innov[0]
    step = math.sqrt(max(1.0 - phi * phi, 0.0))
    for k in range(1, K):                    # stationary AR(1) of variance s^2 share
        corr[k] = phi * corr[k - 1] + step * innov[k]
    return white + corr


def naming_probability(u_baseline, u_rivals, noise, *, level: float, n_candidates: int, draws: int = DRAWS,
                       plan: "FoldPlan | None" = None, seed: int = 0) -> float:
    """Probability that the workflow names the true hypothesis alone, as far as its fold
    comparisons decide it: on one simulated recording, the truth's error is significantly lower than
    the baseline's at ``level / n_candidates`` (Holm's first step) and than every rival's at
    ``level`` (module docstring for what is left out).

    Parameters
    ----------
    u_baseline : array-like, shape (K, 3)
        What the baseline cannot reproduce of the truth at each sample, in time order [m]
        (:func:`unexplained`).
    u_rivals : sequence of array-like, each shape (K, 3)
        The same for each rival hypothesis, at the same samples [m].
    noise : SensorNoise
    level : float
        The workflow's significance level, in (0, 1).
    n_candidates : int
        Candidates the workflow tries alone (its Holm family), >= 1.
    draws, plan, seed
        As :func:`preference_probability`.

    Returns
    -------
    float
        In [0, 1]; NaN when the samples make fewer than two folds.

    Raises
    ------
    ValueError
        ``level`` outside (0, 1), ``n_candidates`` below 1, arrays not of shape (K, 3) for one K, or
        ``draws`` below 1.
    """
    if n_candidates < 1:
        raise ValueError(f"n_candidates must be >= 1, got {n_candidates}")
    us = [np.asarray(u, dtype=float) for u in (u_baseline, *u_rivals)]
    if any(u.ndim != 2 or u.shape[1] != 3 or u.shape[0] != us[0].shape[0] for u in us):
        raise ValueError(f"every u needs shape (K, 3) [m] for one K, got {[u.shape for u in us]}")
    return _all_significant(us, [level / n_candidates] + [level] * (len(us) - 1), noise, draws=draws, plan=plan,
                            seed=seed)


def _pair_name(hyps, a, b) -> str:
    return f"{hyps[a].key}>{hyps[b].key}"


def preference_table(hyps, parts, noise, *, level: float, plan: "FoldPlan | None" = None, seed: int = 0) -> dict:
    """:func:`preference_probability` for every ordered pair of hypotheses over recordings ``parts``.

    Parameters
    ----------
    hyps : sequence of Hypothesis
    parts : sequence of sequence of Sensitivities
        Per recording, one :class:`~ctrplan.design.Sensitivities` per hypothesis, in the order of
        ``hyps`` (the recordings in the order they are run).
    noise : SensorNoise
    level : float
        One-sided level of the comparison, in (0, 1).
    plan : FoldPlan, optional
        The workflow's split (:func:`workflow_split`); default that of the samples given.
    seed : int

    Returns
    -------
    dict
        ``{"A>B": probability}`` [-] for every ordered pair (A true, B its rival).
    """
    n = len(hyps)
    return {_pair_name(hyps, a, b): preference_probability(
        unexplained([p[a] for p in parts], [p[b] for p in parts]), noise, level=level, plan=plan, seed=seed)
        for a in range(n) for b in range(n) if a != b}


def predicted_preference(robot, recorded, hypotheses, follow_up=None, *, noise, level: float = 0.01,
                         settings=None, n_jobs: int = 1, seed: int = 0) -> dict:
    """Probability that the workflow's fold comparison prefers each hypothesis, when true, over each
    rival after ``recorded`` and a follow-up recording of any motion (module docstring).

    The same figure as :attr:`DesignResult.preference` for a motion of the caller's: a follow-up
    planned by hand, a random one, a repetition of the recording. The recorded samples are thinned
    evenly to at most :data:`MAX_RECORDED_SAMPLES`, as in :func:`~ctrplan.design.design_experiment`.

    Parameters
    ----------
    robot : Robot
        The robot file the hypotheses were fitted to.
    recorded : MeasuredData
        The recording the hypotheses were fitted on (its joints and times; its tips are not read).
    hypotheses : sequence of Hypothesis
        Two or more (:func:`~ctrplan.design.result_hypotheses`).
    follow_up : MeasuredData, optional
        The follow-up's samples with their motion history (a recording loaded with
        :func:`ctrplan.discrepancy.load_measured_data`, or :func:`~ctrplan.design.motion_data` of a
        planned motion); None: the recording alone.
    noise : SensorNoise
        Sensor noise per tip coordinate [m].
    level : float
        One-sided level of the comparison, in (0, 1) (the workflow's default 0.01).
    settings : ModelSettings, optional
    n_jobs : int
        Processes the model evaluations run on.
    seed : int
        Seed of the simulated noise.

    Returns
    -------
    dict
        ``{"A>B": probability}`` [-] for every ordered pair of the hypotheses' keys.

    Raises
    ------
    DesignInputError
        Fewer than two hypotheses.
    ValueError
        ``level`` outside (0, 1).
    """
    from ._hypotheses import DesignInputError

    hyps = tuple(hypotheses)
    if len(hyps) < 2:
        raise DesignInputError(f"a preference needs two or more hypotheses, got {len(hyps)}")
    parts, plan = _parts(robot, recorded, hyps, follow_up, settings, n_jobs)
    return preference_table(hyps, parts, noise, level=level, plan=plan, seed=seed)


def _parts(robot, recorded, hyps, follow_up, settings, n_jobs) -> tuple:
    """The hypotheses' sensitivities on the thinned recording (:func:`recorded_rows`) and on the
    follow-up, one list per recording, and the workflow's split of the two in those samples."""
    from ._criteria import sensitivities

    thinned = recorded.take(recorded_rows(recorded.n_samples))
    recordings = [thinned] if follow_up is None else [thinned, follow_up]
    parts = [[sensitivities(robot, h, d, settings, n_jobs=n_jobs) for h in hyps] for d in recordings]
    more = [] if follow_up is None else [follow_up.n_samples]
    return parts, workflow_split([recorded.n_samples, *more], thinned.n_samples + sum(more))


def _on_common_samples(sens: list) -> list:
    """The hypotheses' sensitivities of one recording, each marked converged only where all are."""
    from dataclasses import replace

    ok = np.all([s.ok for s in sens], axis=0)
    return [replace(s, ok=ok) for s in sens]


def naming_table(hyps, parts, noise, *, level: float, n_candidates: int, plan: "FoldPlan | None" = None,
                 seed: int = 0) -> dict:
    """:func:`naming_probability` with each hypothesis true and the others its rivals.

    Parameters
    ----------
    hyps : sequence of Hypothesis
        Two or more.
    parts : sequence of sequence of Sensitivities
        Per recording, one :class:`~ctrplan.design.Sensitivities` per hypothesis in the order of
        ``hyps``, then the baseline's (the model with no effect,
        ``result_hypotheses(results, ["baseline"])``).
    noise : SensorNoise
    level : float
        The workflow's significance level, in (0, 1).
    n_candidates : int
        Candidates the workflow tries alone (its Holm family).
    plan : FoldPlan, optional
        The workflow's split (:func:`workflow_split`); default that of the samples given.
    seed : int

    Returns
    -------
    dict
        ``{key: probability}`` [-] per hypothesis.
    """
    n = len(hyps)
    parts = [_on_common_samples(list(p)) for p in parts]
    out = {}
    for a in range(n):
        truth = [p[a] for p in parts]
        u_base = unexplained(truth, [p[n] for p in parts])
        u_rivals = [unexplained(truth, [p[b] for p in parts]) for b in range(n) if b != a]
        out[hyps[a].key] = naming_probability(u_base, u_rivals, noise, level=level, n_candidates=n_candidates,
                                              plan=plan, seed=seed)
    return out


def predicted_naming(robot, recorded, hypotheses, baseline, follow_up=None, *, noise, level: float = 0.01,
                     n_candidates: int | None = None, settings=None, n_jobs: int = 1, seed: int = 0) -> dict:
    """Probability that the discrepancy workflow names each hypothesis alone, when it is true, after
    ``recorded`` and a follow-up recording of any motion: its error significantly below the
    baseline's (Holm's first step) and below every rival's (:func:`naming_probability`).

    Parameters
    ----------
    robot : Robot
        The robot file the hypotheses were fitted to.
    recorded : MeasuredData
        The recording the hypotheses were fitted on (its joints and times; its tips are not read).
    hypotheses : sequence of Hypothesis
        Two or more, the baseline not among them (:func:`~ctrplan.design.result_hypotheses`).
    baseline : Hypothesis
        The model with no effect, as the recording's run fitted it
        (``result_hypotheses(results, ["baseline"])[0]``).
    follow_up : MeasuredData, optional
        The follow-up's samples with their motion history; None: the recording alone.
    noise : SensorNoise
        Sensor noise per tip coordinate [m].
    level : float
        The workflow's significance level, in (0, 1) (its default 0.01).
    n_candidates : int, optional
        Candidates the workflow tries alone (``results.json["decision"]["family"]``); default the
        number of hypotheses.
    settings : ModelSettings, optional
    n_jobs : int
        Processes the model evaluations run on.
    seed : int
        Seed of the simulated noise.

    Returns
    -------
    dict
        ``{key: probability}`` [-] per hypothesis.

    Raises
    ------
    DesignInputError
        Fewer than two hypotheses, or the baseline among them.
    ValueError
        ``level`` outside (0, 1) or ``n_candidates`` below 1.
    """
    from ._hypotheses import DesignInputError

    hyps = tuple(hypotheses)
    if len(hyps) < 2:
        raise DesignInputError(f"a naming probability needs two or more hypotheses, got {len(hyps)}")
    if any(h.key == baseline.key for h in hyps):
        raise DesignInputError(f"the baseline {baseline.key!r} is given among the hypotheses")
    parts, plan = _parts(robot, recorded, (*hyps, baseline), follow_up, settings, n_jobs)
    return naming_table(hyps, parts, noise, level=level,
                        n_candidates=len(hyps) if n_candidates is None else n_candidates, plan=plan, seed=seed)
