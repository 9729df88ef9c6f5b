"""Stage 9 of the discrepancy workflow: the history-aware prediction and the friction envelope on
the untouched test split."""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from ..._log import progress_level
from ...effects import EffectSet, registration_transform
from ..measured.data import MeasuredData
from ..fits.evaluation import evaluate_rows
from ..outputs.logtext import UNDEFINED, figure
from ..measured.noise import NoiseEstimate
from ..options import ENVELOPE_NOISE_FACTOR, DiscrepancyOptions
from ..fits.parameters import apply_parameters

__all__ = ["EnvelopeCoverage", "HistoryPrediction", "PREDICTION_DESCRIPTION", "predict_with_history",
           "envelope_coverage", "hull_distance"]

logger = logging.getLogger(__name__)

#: What the prediction comparison reports (``results.json["prediction"]["description"]``).
PREDICTION_DESCRIPTION = (
    "Tip position errors on the untouched test split. The first two rows are the written robot file (the final "
    "model's parameters, fitted on the development split only; its friction coefficients, the robot file's where "
    "friction was not fitted into it) evaluated two ways, which [prediction_validation] compares: standard, the "
    "standard model, which ignores the motion history; history-aware, the friction model (Section III of Ha et al. "
    "2019) with each sample's recorded history (eta of the last relative rotation of each pair; a pair released by "
    "a later translation is solved frictionless). Effects on the motion or the measurement in the file (a time "
    "offset, backlash) apply to both. Then the friction candidate fitted alone, the reference coefficients (if "
    "given) on its tube parameters, and the named effect alone.")


@dataclass(frozen=True, eq=False)
class EnvelopeCoverage:
    """Coverage of the friction envelope at evenly spaced held-out samples.

    Attributes
    ----------
    n, inside : int
        Samples with every bounding solution, and those within the envelope plus the margin.
    fraction_inside : float
    margin_m : float
        :data:`ENVELOPE_NOISE_FACTOR` times the noise rms [m] (0 when unknown).
    outside_median_m, outside_p95_m, outside_max_m : float or None
        How far beyond the margin the others lie [m]; None if none.
    size_median_m : float or None
        Median largest distance between two bounding tips [m].
    n_samples : int
        Held-out samples evaluated (evenly spaced).
    n_solutions : int
        Bounding friction solutions whose tips span the envelope.
    noise_factor : float
        :data:`ENVELOPE_NOISE_FACTOR` [-].
    coefficients : dict of str to float
        Friction coefficients used [-].
    label : str
        ``"fitted"`` or ``"reference ..."``.
    """

    n: int
    inside: int
    fraction_inside: float
    margin_m: float
    outside_median_m: float | None
    outside_p95_m: float | None
    outside_max_m: float | None
    size_median_m: float | None
    n_samples: int
    n_solutions: int
    noise_factor: float
    coefficients: dict
    label: str


@dataclass(frozen=True, eq=False)
class HistoryPrediction:
    """Stage 9: held-out errors of the standard and the history-aware models.

    Attributes
    ----------
    rows : tuple of (str, ndarray of shape (K,))
        Label and test-split position errors [m] of each model compared.
    envelopes : tuple of EnvelopeCoverage
        Empty when ``options.envelope_samples`` is 0.
    """

    rows: tuple
    envelopes: tuple


def hull_distance(points, x) -> float:
    """Distance from ``x`` (3,) to the convex hull of ``points`` (m, 3) [same unit]: the nearest
    convex combination, by non-negative least squares with the weights' sum held at 1 by a
    heavily weighted row."""
    from scipy.optimize import nnls

    P = np.asarray(points, float)
    w_row = 1e3 * max(1.0, float(np.abs(P).max()))
    A = np.vstack([P.T, np.full((1, P.shape[0]), w_row)])
    b = np.concatenate([np.asarray(x, float), [w_row]])
    w, _ = nnls(A, b)
    return float(np.linalg.norm(P.T @ w - x))


def _mm(x):
    return "-" if x is None else f"{1e3 * x:.2f} mm"


def _prediction_line(label: str, position) -> str:
    """The log line of one prediction row: mean, p95 and maximum of its finite tip position errors
    ``position`` (array, shape (K,) [m]) in mm, each "undefined" where no error is finite (every
    evaluation failed, or no test sample)."""
    p = np.asarray(position, float)
    p = p[np.isfinite(p)]
    if not p.size:
        return f"  prediction: {label}: mean, p95 and max {UNDEFINED} (no finite error of {np.size(position)})"
    return (f"  prediction: {label}: mean {1e3 * p.mean():.3f}, p95 {1e3 * np.percentile(p, 95):.3f}, max "
            f"{1e3 * p.max():.3f} mm ({p.size} samples)")


def envelope_coverage(setup, params, sub: MeasuredData, noise: NoiseEstimate, stage: str, n_jobs: int, *,
                      label: str) -> EnvelopeCoverage:
    """Coverage of the friction envelope: the convex hull of the 2^(n-1) bounding friction
    solutions (fixed eta, no release) at each sample of ``sub``, plus
    :data:`ENVELOPE_NOISE_FACTOR` times the noise rms; the bounding tips are kept in the stage
    ``stage``.

    Parameters
    ----------
    setup : DiscrepancySetup
        The input robot, the solver settings and the stage store.
    params : mapping of str to float
        Calibrated parameters [SI] (tube parameters, friction coefficients ``mu_*``, registration);
        the friction coefficients are reported with the coverage.
    sub : MeasuredData
        The samples.
    noise : NoiseEstimate
        :func:`~ctrplan.discrepancy.measured.noise.estimate_noise` (its rms sets the margin; 0 when unknown).
    stage : str
        Name of the stage that keeps the bounding tips.
    n_jobs : int
    label : str, keyword-only
        ``"fitted"`` or ``"reference ..."``.

    Returns
    -------
    EnvelopeCoverage
    """
    from ...mechanics import all_eta
    from ..fits.simulate import simulate

    robot, stages, settings = setup.robot, setup.stages, setup.settings
    sigma = noise.position_rms_m
    margin = ENVELOPE_NOISE_FACTOR * sigma if sigma else 0.0
    cached = stages.load(stage)
    if cached is None:
        etas = all_eta(robot.n_tubes)
        logger.log(progress_level(), f"  friction envelope: {len(etas)} bounding solutions at {sub.n_samples} "
                                     f"held-out samples ...")
        robot_p = apply_parameters(robot, tuple(params), tuple(params.values()))
        effects, _ = EffectSet.from_parameters(robot, tuple(params), tuple(params.values()))
        R, t = registration_transform(effects["registration"] if "registration" in effects else {})
        tips = []
        for eta in etas:
            sim = simulate(robot_p, sub.alpha, sub.beta, model="friction",
                           eta=np.tile(np.asarray(eta, int), (sub.n_samples, 1)), sequence=sub.sequence,
                           settings=settings, n_jobs=n_jobs)
            tips.append(sim.tip @ R.T + t)
        cached = {"tips": np.stack(tips, axis=1)}
        stages.save(stage, cached)
    tips = np.asarray(cached["tips"], float)            # (k, 2^(n-1), 3) in the data's frame
    dist = np.full(sub.n_samples, np.nan)
    size = np.full(sub.n_samples, np.nan)
    for k in range(sub.n_samples):
        P = tips[k]
        if np.all(np.isfinite(P)):
            dist[k] = hull_distance(P, sub.tip[k])
            size[k] = max(np.linalg.norm(P[a] - P[b]) for a in range(len(P)) for b in range(len(P)))
    ok = np.isfinite(dist)
    outside = dist[ok] - margin
    far = outside[outside > 0]
    return EnvelopeCoverage(
        n=int(ok.sum()), inside=int(np.sum(outside <= 0)),
        fraction_inside=float(np.mean(outside <= 0)) if ok.any() else float("nan"), margin_m=margin,
        outside_median_m=float(np.median(far)) if far.size else None,
        outside_p95_m=float(np.percentile(far, 95)) if far.size else None,
        outside_max_m=float(far.max()) if far.size else None,
        size_median_m=float(np.nanmedian(size)) if ok.any() else None,
        n_samples=int(sub.n_samples), n_solutions=int(tips.shape[1]), noise_factor=ENVELOPE_NOISE_FACTOR,
        coefficients={k: float(v) for k, v in params.items() if k.startswith("mu_")}, label=label)


def predict_with_history(setup, split, baseline, naming, noise, options: DiscrepancyOptions, progress: bool = False, *,
                         final_params: dict | None = None) -> HistoryPrediction | None:
    """Stage 9: prediction errors of the standard and the history-aware models on the test split,
    and the coverage of the friction envelope there (every model fitted on the development
    samples only).

    The first two rows compare what planning chooses between (``[prediction_validation]``): the
    robot file the run writes, with ``final_params`` (the final model's parameters [SI]; the
    baseline's when None), evaluated with the standard model and with the friction model along
    the recorded history (its friction coefficients: ``mu_k`` of ``final_params``, else the robot
    file's). Then the friction model with the friction candidate's own fit and, when
    ``options.reference_friction`` is given, with those coefficients (e.g. published ones) on the
    friction candidate's tube parameters; and the named effect alone. With
    ``options.envelope_samples`` > 0, the envelope (convex hull of the 2^(n-1) bounding friction
    solutions plus :data:`ENVELOPE_NOISE_FACTOR` times the noise rms) is evaluated at that many
    evenly spaced test samples, for each coefficient set.

    Parameters
    ----------
    setup : DiscrepancySetup
    split : DataSplit
    baseline : Baseline
    naming : Naming
    noise : NoiseCheck
        Its estimate sets the envelope's margin.
    options : DiscrepancyOptions
    progress : bool
        Progress bars of the model evaluations.
    final_params : dict, optional, keyword-only

    Returns
    -------
    HistoryPrediction or None
        None without a friction candidate.
    """
    from ...mechanics import all_eta

    candidates, named = naming.candidates, naming.named
    if "friction" not in candidates:
        return None
    test = split.test_rows
    val = setup.data.take(test)

    def on_test(name, model, params):
        return evaluate_rows(setup, test, f"test-{name}", model, params, n_jobs=options.n_jobs, progress=progress)

    fr = candidates["friction"]
    written = dict(baseline.params if final_params is None else final_params)
    mu = [written.get(f"mu_{k + 1}", m) for k, m in enumerate(setup.robot.friction_coefficients)]
    mu_text = ", ".join(f"mu_{k + 1} = {m:.3g}" for k, m in enumerate(mu))
    rows = [("standard model, the written robot file (no history)",
             on_test("written-standard", "standard", written).position),
            (f"history-aware: friction model along the recorded history, the written robot file ({mu_text})",
             on_test("written-friction", "friction", written).position),
            ("history-aware, the friction candidate fitted alone: "
             + ", ".join(f"{k} = {v:.3g}" for k, v in fr.shown.items()), on_test("friction", fr.model, fr.params).position)]
    sets = [("fitted", fr.params, f"{len(all_eta(setup.robot.n_tubes))}")]
    if options.reference_friction is not None:
        mu = tuple(float(v) for v in options.reference_friction)
        ref = dict(fr.params)
        ref.update({f"mu_{k + 1}": v for k, v in enumerate(mu)})
        tag = "-".join(f"{v:g}" for v in mu)
        val_ref = on_test(f"reference-friction-{tag}", "friction", ref)
        rows.append(("history-aware with the reference friction coefficients "
                     + ", ".join(f"mu_{k + 1} = {v:.3g}" for k, v in enumerate(mu)), val_ref.position))
        sets.append((f"reference {tag}", ref, f"reference-{tag}"))
    if named and named != "friction":
        rows.append((f"named effect: {candidates[named].label}",
                     on_test(named, candidates[named].model, candidates[named].params).position))
    level = progress_level()
    for label, pos in rows:
        logger.log(level, _prediction_line(label, pos))
    k_env = min(int(options.envelope_samples), val.n_samples)
    if k_env <= 0:
        return HistoryPrediction(rows=tuple(rows), envelopes=())
    rows_env = np.unique(np.linspace(0, val.n_samples - 1, k_env).round().astype(int))
    sub = val.take(rows_env)
    envelopes = []
    for label, params, key in sets:
        stage = f"envelope-{rows_env.size}" if label == "fitted" else f"envelope-{key}-{rows_env.size}"
        env = envelope_coverage(setup, params, sub, noise.noise, stage, options.n_jobs, label=label)
        envelopes.append(env)
        inside = figure(env.fraction_inside, ".0f", 100, " %")
        logger.log(level, f"  envelope ({label}): {env.inside} of {env.n} inside ({inside}), "
                          f"outside by median {_mm(env.outside_median_m)}, max {_mm(env.outside_max_m)}; size median "
                          f"{_mm(env.size_median_m)}")
    return HistoryPrediction(rows=tuple(rows), envelopes=tuple(envelopes))
