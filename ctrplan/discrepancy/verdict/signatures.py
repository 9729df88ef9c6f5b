"""Statistical tests of residual signatures, one per candidate missing effect.

Each test looks for the pattern an effect leaves in the tip position residuals ``e = p_measured
- p_model`` [m] (robot base frame) of a calibrated model, and returns an effect size [m] and a
permutation (or sign-flip) p-value, ``p = (1 + #{T_null >= T}) / (1 + B)``:

=====================  ==================================================  =======================
effect                 signature                                           null (exchangeability)
=====================  ==================================================  =======================
torsional friction     residual differs by approach direction eta_k at     eta permuted within
                       the same configuration (Section III: the friction   each configuration
                       solutions differ by the direction of the last       group
                       relative rotation)
clearance              residual explained by tube overlaps: curved-curved  features permuted
                       overlap and transmission (straight) sections        across configurations
                       entering a curved outer section (Section II-B)      (or circularly shifted
                                                                           along one trajectory)
off-plane              residual periodic in the absolute tube angles       as above
precurvature           (first and second harmonics)
stiffness / Poisson    residual explained by the twist of the most         as above
                       strained tube (Section V-C: tube 3's nonlinear
                       strain, negative calibrated Poisson ratio)
registration           a rigid pattern: residual = t + w x p               sign flips per group
=====================  ==================================================  =======================

Which test an effect uses, and with which features, is the effect's own
(``Effect.signature`` of :mod:`ctrplan.effects`); :class:`SignatureContext` gives it the
held-out arrays and the tests, and :func:`diagnose_residuals` runs every candidate's.

Regression tests use the fraction of residual variance explained by the effect's features
(least squares with intercept, the three residual components pooled) as statistic, and the RMS
of the explained part (less the mean explained by chance under the null) as effect size. When configurations repeat (e.g. the four approach
directions of the paper's protocol), residuals and features are first averaged per
configuration, so that direction-dependent (friction) residuals do not leak into the other
tests.
"""

from __future__ import annotations

import logging
from dataclasses import asdict, dataclass

import numpy as np

from ..._log import progress_level
from ...effects import REGISTRY

__all__ = ["SignatureTest", "SignatureContext", "diagnose_residuals", "friction_signature", "regression_signature",
           "registration_signature", "vector_signature", "untestable", "tip_velocity", "label"]

logger = logging.getLogger(__name__)


def label(effect: str) -> str:
    """The report label of a registered effect (its name otherwise)."""
    e = REGISTRY.get(effect)
    return e.label if e is not None else effect


@dataclass(frozen=True)
class SignatureTest:
    """Result of one signature test.

    Attributes
    ----------
    effect : str
        Name of the effect (:data:`ctrplan.effects.REGISTRY`).
    statistic : float
        Observed test statistic (its meaning in ``description``).
    effect_size_m : float
        Size of the pattern in the residuals [m].
    p_value : float
        Permutation / sign-flip p-value.
    n_permutations : int
    n_units : int
        Exchangeable units (groups, rows) the test used.
    description : str
    testable : bool
        False when the data cannot show the signature at all (``description`` says why); the
        statistic, size and p-value are then placeholders (0, 0, 1) and mean nothing.
    """

    effect: str
    statistic: float
    effect_size_m: float
    p_value: float
    n_permutations: int
    n_units: int
    description: str
    testable: bool = True

    def _replace_effect(self, effect: str) -> "SignatureTest":
        """The same test filed under another effect name."""
        from dataclasses import replace

        return replace(self, effect=effect)

    def as_dict(self) -> dict:
        """The attributes (SI) and the effect's report ``label``."""
        d = asdict(self)
        d["label"] = label(self.effect)
        return d


def _p_value(observed: float, null: np.ndarray) -> float:
    return float((1 + np.count_nonzero(null >= observed * (1 - 1e-12))) / (1 + null.size))


# --------------------------------------------------------------------------- friction
def friction_signature(residual, eta, groups, *, n_permutations: int = 999, seed: int = 0) -> SignatureTest:
    """Dependence of the residual on the approach direction at the same configuration.

    For each configuration group ``g`` and pair ``k`` with both directions present, the
    difference ``d_gk`` of the mean residuals of ``eta_k = +1`` and ``eta_k = -1`` rows; the
    statistic is ``T = sum_gk w_gk |d_gk|^2`` with ``w = n+ n- / (n+ + n-)``. Null: the rows'
    eta vectors permuted within each group. Effect size: the weighted RMS of ``|d_gk| / 2``,
    half the tip displacement between opposite approach directions [m].

    Parameters
    ----------
    residual : ndarray, shape (K, 3) [m]
        Rows with NaN are dropped.
    eta : ndarray of int, shape (K, n - 1)
    groups : ndarray of int, shape (K,)
        Configuration groups (same or nearby configurations).
    n_permutations : int
    seed : int

    Returns
    -------
    SignatureTest
    """
    residual = np.asarray(residual, float)
    eta = np.asarray(eta, int).reshape(residual.shape[0], -1)
    keep = np.all(np.isfinite(residual), axis=1)
    residual, eta, groups = residual[keep], eta[keep], np.asarray(groups)[keep]
    _, g = np.unique(groups, return_inverse=True)
    g = g.ravel()
    n_g = int(g.max()) + 1 if g.size else 0
    # only groups where some pair has both directions can inform the test
    informative = np.zeros(n_g, bool)
    for k in range(eta.shape[1]):
        plus = np.bincount(g, weights=(eta[:, k] == 1), minlength=n_g)
        minus = np.bincount(g, weights=(eta[:, k] == -1), minlength=n_g)
        informative |= (plus > 0) & (minus > 0)
    rows = informative[g]
    residual, eta, g = residual[rows], eta[rows], g[rows]
    if not rows.any():
        return SignatureTest("friction", 0.0, 0.0, 1.0, 0, 0,
                             "not testable, because no configuration group holds rows from both approach "
                             "directions of any pair", testable=False)
    _, g = np.unique(g, return_inverse=True)
    g = g.ravel()
    n_g = int(g.max()) + 1

    def stat(e):
        total, wsum = 0.0, 0.0
        for k in range(e.shape[1]):
            p = (e[:, k] == 1).astype(float)
            m = (e[:, k] == -1).astype(float)
            n_p, n_m = np.bincount(g, p, n_g), np.bincount(g, m, n_g)
            ok = (n_p > 0) & (n_m > 0)
            sp = np.stack([np.bincount(g, p * residual[:, j], n_g) for j in range(3)], axis=1)
            sm = np.stack([np.bincount(g, m * residual[:, j], n_g) for j in range(3)], axis=1)
            d = sp[ok] / n_p[ok, None] - sm[ok] / n_m[ok, None]
            w = n_p[ok] * n_m[ok] / (n_p[ok] + n_m[ok])
            total += float(w @ np.sum(d * d, axis=1))
            wsum += float(w.sum())
        return total, wsum

    t_obs, wsum = stat(eta)
    rng = np.random.default_rng(seed)
    order = np.argsort(g, kind="stable")
    null = np.empty(n_permutations)
    for b in range(n_permutations):
        perm = np.empty_like(order)
        perm[order] = np.lexsort((rng.random(g.size), g))   # a random order within every group
        null[b] = stat(eta[perm])[0]
    size = 0.5 * np.sqrt(max(t_obs - _noise_part(residual, eta, g, null), 0.0) / wsum) if wsum > 0 else 0.0
    return SignatureTest("friction", t_obs, float(size), _p_value(t_obs, null), n_permutations, n_g,
                         "T = sum over configuration groups and pairs of w |mean residual(eta=+1) - "
                         "mean residual(eta=-1)|^2 [m^2]; effect size = RMS half difference between "
                         "approach directions, less what noise alone gives (noise from the within-group fit)")


def _noise_part(residual, eta, g, null) -> float:
    """Expected T from noise alone: each term w |d|^2 has expectation 3 sigma^2, with sigma^2
    (per component) from the within-group fit ``e = mean_g + sum_k eta_k b_gk``; the mean of
    the permutation null where that fit leaves no degrees of freedom."""
    rss, dof, terms = 0.0, 0, 0
    order = np.argsort(g, kind="stable")
    for rows in np.split(order, np.flatnonzero(np.diff(g[order])) + 1):
        cols = [k for k in range(eta.shape[1]) if np.unique(eta[rows, k]).size > 1]
        X = np.column_stack([np.ones(rows.size)] + [eta[rows, k] for k in cols])
        rank = np.linalg.matrix_rank(X)
        terms += sum(1 for k in cols if (eta[rows, k] == 1).any() and (eta[rows, k] == -1).any())
        if rows.size > rank:
            coef, *_ = np.linalg.lstsq(X, residual[rows], rcond=None)
            r = residual[rows] - X @ coef
            rss += float(np.sum(r * r))
            dof += rows.size - rank
    if dof == 0:
        return float(null.mean())
    return 3.0 * (rss / (3 * dof)) * terms


# --------------------------------------------------------------------------- regression tests
def _group_means(values, g, n_g):
    w = np.bincount(g, minlength=n_g).astype(float)
    return np.stack([np.bincount(g, values[:, j], n_g) for j in range(values.shape[1])], axis=1) / w[:, None]


def _explained(E, F):
    """Fraction of the (centred) variance of E explained by F (with intercept), and fitted E."""
    Ec = E - E.mean(axis=0)
    Fc = F - F.mean(axis=0)
    coef, *_ = np.linalg.lstsq(Fc, Ec, rcond=None)
    fit = Fc @ coef
    tss = float(np.sum(Ec * Ec))
    return (float(np.sum(fit * fit)) / tss if tss > 0 else 0.0), fit


def regression_signature(effect: str, residual, features, groups, *, sequence=None, n_permutations: int = 999,
                         seed: int = 0, description: str = "") -> SignatureTest:
    """Fraction of the residual variance explained by an effect's features, with a permutation null.

    When configuration groups repeat, residuals and features are averaged per group and the
    group rows are permuted. Otherwise, along one continuous motion (``sequence`` with a single
    value), the features are circularly shifted by a random lag (at least 10% of the samples),
    which keeps the serial correlation of both series; else rows are permuted.

    Parameters
    ----------
    effect : str
    residual : ndarray, shape (K, 3) [m]
    features : ndarray, shape (K, p)
    groups : ndarray of int, shape (K,)
    sequence : ndarray of int, shape (K,), optional
    n_permutations : int
    seed : int
    description : str

    Returns
    -------
    SignatureTest
        ``statistic`` = explained fraction R^2; effect size = RMS of the explained residual [m].
    """
    residual = np.asarray(residual, float)
    F = np.asarray(features, float).reshape(residual.shape[0], -1)
    keep = np.all(np.isfinite(residual), axis=1) & np.all(np.isfinite(F), axis=1)
    E, F, groups = residual[keep], F[keep], np.asarray(groups)[keep]
    seq = None if sequence is None else np.asarray(sequence)[keep]
    _, g = np.unique(groups, return_inverse=True)
    g = g.ravel()
    n_g = int(g.max()) + 1 if g.size else 0
    rng = np.random.default_rng(seed)
    if n_g < E.shape[0]:
        E, F = _group_means(E, g, n_g), _group_means(F, g, n_g)
        mode = "configuration groups permuted"
    elif seq is not None and np.unique(seq).size == 1:
        mode = "features circularly shifted along the trajectory"
    else:
        mode = "rows permuted"
    m = E.shape[0]
    if m <= F.shape[1] + 2:
        return SignatureTest(effect, 0.0, 0.0, 1.0, 0, m, f"not testable, because there are too few units "
                             f"({m}) for {F.shape[1]} features", testable=False)
    r2, fit = _explained(E, F)
    null = np.empty(n_permutations)
    for b in range(n_permutations):
        if mode.startswith("features circularly"):
            lag = rng.integers(max(1, m // 10), m - max(1, m // 10))
            Fp = np.roll(F, lag, axis=0)
        else:
            Fp = F[rng.permutation(m)]
        null[b] = _explained(E, Fp)[0]
    # debiased: the part of the explained variance that chance alone does not give
    tss = float(np.sum((E - E.mean(axis=0)) ** 2))
    size = float(np.sqrt(max(r2 - float(null.mean()), 0.0) * tss / m))
    return SignatureTest(effect, r2, size, _p_value(r2, null), n_permutations, m,
                         f"R^2 of residual on {F.shape[1]} features ({description}); null: {mode}")


def registration_signature(residual, model_tip, groups, *, n_permutations: int = 999, seed: int = 0) -> SignatureTest:
    """A rigid pattern in the residuals: ``e ~ t + w x p`` (small rotation w, translation t).

    Statistic: explained fraction of ``sum |e|^2`` (not centred: a constant offset is the
    translation). Null: the residual of each configuration group multiplied by a random sign
    (symmetric noise has no rigid pattern).

    Parameters
    ----------
    residual : ndarray, shape (K, 3) [m]
    model_tip : ndarray, shape (K, 3) [m]
        Model tip positions (base frame) at which the residuals were taken.
    groups : ndarray of int, shape (K,)

    Returns
    -------
    SignatureTest
    """
    residual = np.asarray(residual, float)
    keep = np.all(np.isfinite(residual), axis=1) & np.all(np.isfinite(model_tip), axis=1)
    E, P, groups = residual[keep], np.asarray(model_tip, float)[keep], np.asarray(groups)[keep]
    _, g = np.unique(groups, return_inverse=True)
    g = g.ravel()
    n_g = int(g.max()) + 1
    k = E.shape[0]
    # design: e = t + w x p  ->  rows of [I | -[p]x] acting on (t, w)
    A = np.zeros((k, 3, 6))
    A[:, :, :3] = np.eye(3)
    px, py, pz = P[:, 0], P[:, 1], P[:, 2]
    A[:, 0, 4], A[:, 0, 5] = pz, -py
    A[:, 1, 3], A[:, 1, 5] = -pz, px
    A[:, 2, 3], A[:, 2, 4] = py, -px
    A = A.reshape(3 * k, 6)
    pinv = np.linalg.pinv(A)

    def stat(e):
        y = e.reshape(-1)
        fit = A @ (pinv @ y)
        return float(fit @ fit) / float(y @ y), fit

    r2, fit = stat(E)
    rng = np.random.default_rng(seed)
    null = np.empty(n_permutations)
    for b in range(n_permutations):
        s = rng.choice((-1.0, 1.0), size=n_g)[g]
        null[b] = stat(E * s[:, None])[0]
    size = float(np.sqrt(max(r2 - float(null.mean()), 0.0) * float(np.sum(E * E)) / k))
    return SignatureTest("registration", r2, size, _p_value(r2, null), n_permutations, n_g,
                         "fraction of sum |e|^2 explained by a rigid displacement t + w x p; null: "
                         "sign flips per configuration group")


# --------------------------------------------------------------------------- vector patterns
def untestable(effect: str, reason: str) -> SignatureTest:
    """A signature test that cannot run on the data: ``reason`` completes "not testable, because"."""
    return SignatureTest(effect, 0.0, 0.0, 1.0, 0, 0, f"not testable, because {reason}", testable=False)


def _project_out(C, Y):
    """Y minus its least-squares fit on the columns of C (C (N, c), Y (N,) or (N, m))."""
    if C is None or C.shape[1] == 0:
        return Y
    coef, *_ = np.linalg.lstsq(C, Y, rcond=None)
    return Y - C @ coef


def vector_signature(effect: str, residual, columns, groups, *, sequence=None, control=None, signs=None,
                     n_permutations: int = 999, seed: int = 0, description: str = "") -> SignatureTest:
    """Does the residual point along effect-specific vectors? ``e_k ~ sum_j c_j X_kj`` (+ control).

    For effects whose tip displacement is a known vector per sample times an unknown scalar: a
    drive backlash moves the tip along ``-s_i d tip / d alpha_i`` (s_i the direction of the last
    rotation of tube i), a tracker lag along ``-d tip / dt``. The statistic is the fraction of the
    residual (after an intercept per component and the ``control`` columns are projected out)
    explained by the columns. Null: along one continuous motion, the columns circularly shifted
    by a random lag (at least 10 % of the samples; keeps the serial correlation of both series);
    else the rows permuted.

    Parameters
    ----------
    effect : str
    residual : ndarray, shape (K, 3) [m]
    columns : ndarray, shape (K, 3, m)
        The effect's displacement per unit of each of its m parameters [m per unit].
    groups : ndarray of int, shape (K,)
        Configuration groups (only their count is reported).
    sequence : ndarray of int, shape (K,), optional
    control : ndarray, shape (K, 3, c), optional
        Columns of a related effect whose part is removed first (the test then asks what the
        effect explains beyond it).
    signs : ndarray, shape (K, m), optional
        A direction series that multiplies the columns (e.g. the direction of the last rotation
        of each tube for the backlash): the effect's columns are ``signs * columns``, the
        unsigned ``columns`` join the control (an offset along them is no evidence), and the
        null shifts only the signs, so it asks whether the *direction* matters.
    n_permutations, seed : int
    description : str

    Returns
    -------
    SignatureTest
        ``statistic`` = explained fraction; effect size = RMS of the explained displacement less
        what chance explains [m]; not testable when the columns vanish.
    """
    E = np.asarray(residual, float)
    X = np.asarray(columns, float).reshape(E.shape[0], 3, -1)
    C = None if control is None else np.asarray(control, float).reshape(E.shape[0], 3, -1)
    S = None if signs is None else np.asarray(signs, float).reshape(E.shape[0], X.shape[2])
    if S is not None:
        C = X.copy() if C is None else np.concatenate([C, X], axis=2)
    keep = np.all(np.isfinite(E), axis=1) & np.all(np.isfinite(X), axis=(1, 2))
    if C is not None:
        keep &= np.all(np.isfinite(C), axis=(1, 2))
    E, X = E[keep], X[keep]
    C = None if C is None else C[keep]
    S = None if S is None else S[keep]
    if S is not None and not np.any(S != 0):
        return untestable(effect, f"its direction series is zero everywhere ({description})")
    k, m = E.shape[0], X.shape[2]
    if k < 3 * (m + 2) or not np.any(np.abs(X) > 0):
        return untestable(effect, f"its displacement vectors vanish or too few samples remain ({k}) "
                                  f"({description})")
    intercept = np.tile(np.eye(3), (k, 1))
    Cm = intercept if C is None else np.concatenate([intercept, C.reshape(3 * k, -1)], axis=1)
    y = _project_out(Cm, E.reshape(-1))
    tss = float(y @ y)
    if tss <= 0:
        return untestable(effect, "the residual is zero")

    def stat(Xs):
        A = _project_out(Cm, Xs.reshape(3 * k, m))
        coef, *_ = np.linalg.lstsq(A, y, rcond=None)
        fit = A @ coef
        return float(fit @ fit) / tss

    seq = None if sequence is None else np.asarray(sequence)[keep]
    shift = seq is not None and np.unique(seq).size == 1
    signed = (lambda Sx: X * Sx[:, None, :]) if S is not None else (lambda Sx: Sx)
    series = S if S is not None else X
    r2 = stat(signed(series))
    rng = np.random.default_rng(seed)
    null = np.empty(n_permutations)
    for b in range(n_permutations):
        if shift:
            lag = rng.integers(max(1, k // 10), k - max(1, k // 10))
            null[b] = stat(signed(np.roll(series, lag, axis=0)))
        else:
            null[b] = stat(signed(series[rng.permutation(k)]))
    size = float(np.sqrt(max(r2 - float(null.mean()), 0.0) * tss / k))
    what = "direction series" if S is not None else "columns"
    mode = f"{what} circularly shifted along the trajectory" if shift else f"{what} permuted over rows"
    n_units = int(np.unique(np.asarray(groups)[keep]).size)
    return SignatureTest(effect, r2, size, _p_value(r2, null), n_permutations, n_units,
                         f"fraction of the residual along {m} displacement vector(s) ({description}); "
                         f"null: {mode}")


# --------------------------------------------------------------------------- context and stage
def tip_velocity(tip, time, sequence=None) -> np.ndarray:
    """Tip velocity along each sequence by central differences in time, shape (K, 3) [m/s].

    Within runs of contiguous samples (a gap longer than 1.5 median steps, e.g. between the
    held-out blocks of a trajectory, starts a new run); one-sided at run ends; NaN for runs of
    one sample, NaN tips, or without times.

    Parameters
    ----------
    tip : array-like, shape (K, 3) [m]
    time : array-like, shape (K,) [s], or None
    sequence : array-like of int, shape (K,), optional
    """
    from ...history import sequence_segments

    tip = np.asarray(tip, dtype=float)
    K = tip.shape[0]
    v = np.full((K, 3), np.nan)
    if time is None:
        return v
    t = np.asarray(time, dtype=float)
    for idx in sequence_segments(sequence, K):
        if idx.size < 2:
            continue
        dt = np.diff(t[idx])
        step = np.median(dt[dt > 0]) if np.any(dt > 0) else 0.0
        cuts = np.flatnonzero((dt > 1.5 * step) | (dt <= 0)) + 1
        for run in np.split(idx, cuts):
            if run.size >= 2:
                v[run] = np.gradient(tip[run], t[run], axis=0)
    return v


class SignatureContext:
    """What a signature test of an effect entry (``Effect.signature``) reads and runs.

    Attributes
    ----------
    robot : Robot
        The robot as loaded.
    base_robot : Robot
        The calibrated baseline robot (its Jacobians and twists).
    data : MeasuredData
        The held-out samples (K).
    residual : ndarray, shape (K, 3)
        Baseline residual ``p_measured - p_model`` in the robot base frame [m].
    model_tip : ndarray, shape (K, 3)
        Baseline model tip in the robot base frame [m].
    groups : ndarray of int, shape (K,)
        Configuration groups (exact configurations when the protocol revisits them, else bins of
        nearby configurations).
    state : HistoryState
        The held-out samples' history along the whole recorded motion (no history effects).

    Parameters
    ----------
    settings : ModelSettings
    n_jobs, n_permutations, seed : int
    cache : StageStore, optional
        Keeps the Jacobians across runs.
    """

    def __init__(self, robot, base_robot, data, residual, model_tip, groups, settings, *, n_jobs=1,
                 n_permutations=999, seed=0, cache=None, alpha_step=1e-3):
        self.robot, self.base_robot, self.data = robot, base_robot, data
        self.residual, self.model_tip, self.groups = residual, model_tip, groups
        self.settings, self.n_jobs, self.cache, self.alpha_step = settings, n_jobs, cache, alpha_step
        self._perm = dict(n_permutations=n_permutations, seed=seed)
        self._jac = {}
        self.state = data.state(robot)

    # ---------------------------------------------------------------- quantities
    def alpha_jacobian(self, tubes) -> dict:
        """d tip / d alpha_i of the baseline along the held-out motion, per tube i:
        ``{i: ndarray (K, 3) [m/rad]}`` by central differences of ``alpha_step``, branch
        following (NaN where a solve failed)."""
        from ..fits.simulate import simulate

        stored = self.cache.load("alpha-jacobian") if self.cache is not None and not self._jac else None
        if stored:
            self._jac.update({int(i): np.array(v, float) for i, v in stored.items()})
        missing = [i for i in tubes if i not in self._jac]
        for i in missing:
            tips = []
            for sign in (1.0, -1.0):
                a = self.data.alpha.copy()
                a[:, i] += sign * self.alpha_step
                tips.append(simulate(self.base_robot, a, self.data.beta, model="standard", sequence=self.data.sequence,
                                     settings=self.settings, n_jobs=self.n_jobs).tip)
            self._jac[i] = (tips[0] - tips[1]) / (2.0 * self.alpha_step)
        if missing and self.cache is not None:
            self.cache.save("alpha-jacobian", {str(i): v for i, v in self._jac.items()})
        return {i: self._jac[i] for i in tubes}

    def twist(self, tube: int) -> np.ndarray:
        """Twist psi(end) - psi(base) of one tube in the baseline's standard model, shape (K,) [rad]."""
        from ...errors import CtrplanError
        from ...mechanics import solve_standard

        out = np.full(self.data.n_samples, np.nan)
        for k in range(self.data.n_samples):
            try:
                sol = solve_standard(self.base_robot, self.data.alpha[k], self.data.beta[k], self.settings)
            except CtrplanError:
                continue
            psi = sol.psi[:, tube]
            fin = np.flatnonzero(np.isfinite(psi))
            if fin.size:
                out[k] = psi[fin[-1]] - psi[fin[0]]
        return out

    def tip_velocity(self) -> np.ndarray:
        """Velocity of the baseline's model tip along the recorded motion, shape (K, 3) [m/s]."""
        return tip_velocity(self.model_tip, self.data.time, self.data.sequence)

    def drive_directions(self) -> np.ndarray:
        """Direction of the last rotation of each drive, shape (K, n), along the whole record."""
        from ...history import drive_directions

        rec = self.data.record
        return drive_directions(rec.alpha, sequence=rec.sequence)[self.data.rows]

    def rotation_since_reversal(self) -> np.ndarray:
        """Relative rotation of each pair since its last reversal, shape (K, n - 1) [rad]."""
        from ...history import rotation_since_reversal

        rec = self.data.record
        return rotation_since_reversal(rec.alpha, sequence=rec.sequence)[self.data.rows]

    # ---------------------------------------------------------------- tests
    def direction_test(self, effect: str) -> SignatureTest:
        """:func:`friction_signature` on the held-out eta and configuration groups."""
        return friction_signature(self.residual, self.data.eta, self.groups, **self._perm)._replace_effect(effect)

    def regression_test(self, effect: str, features, description: str) -> SignatureTest:
        """:func:`regression_signature` of ``features`` (K, p)."""
        return regression_signature(effect, self.residual, features, self.data.config_id, sequence=self.data.sequence,
                                    description=description, **self._perm)

    def rigid_test(self, effect: str) -> SignatureTest:
        """:func:`registration_signature` at the model tips."""
        return registration_signature(self.residual, self.model_tip, self.data.config_id,
                                      **self._perm)._replace_effect(effect)

    def vector_test(self, effect: str, columns, description: str, *, signs=None, control=None) -> SignatureTest:
        """:func:`vector_signature` of ``columns`` (K, 3, m)."""
        return vector_signature(effect, self.residual, columns, self.groups, sequence=self.data.sequence,
                                signs=signs, control=control, description=description, **self._perm)

    def untestable(self, effect: str, reason: str) -> SignatureTest:
        """:func:`untestable`."""
        return untestable(effect, reason)


def diagnose_residuals(setup, split, baseline, options) -> dict:
    """Stage 4: one signature test per candidate effect on the baseline's out-of-fold residuals
    at the development samples.

    Each effect's own test (``Effect.signature``) runs on a :class:`SignatureContext` of those
    samples.

    Parameters
    ----------
    setup : DiscrepancySetup
    split : DataSplit
        Only its development samples are read.
    baseline : Baseline
        Its out-of-fold residual vectors [m] are tested.
    options : DiscrepancyOptions
        ``n_permutations``, ``seed``, ``n_jobs``.

    Returns
    -------
    dict of str to SignatureTest
        One per candidate effect (``effect_size_m`` [m]), in registry order.
    """
    from ..measured.data import configuration_groups
    from ..options import ALPHA_STEP, TRAJECTORY_ROTATION_BIN, TRAJECTORY_TRANSLATION_BIN
    from ..fits.parameters import apply_parameters
    from ..measured.split import configurations_repeat

    dev, params = setup.data.take(split.dev_rows), baseline.params
    logger.log(progress_level(), "testing residual signatures ...")
    groups = dev.config_id if configurations_repeat(dev.config_id) else configuration_groups(
        dev.alpha, dev.beta, TRAJECTORY_ROTATION_BIN, TRAJECTORY_TRANSLATION_BIN)
    base_robot = apply_parameters(setup.robot, tuple(params), tuple(params.values()))
    ctx = SignatureContext(setup.robot, base_robot, dev, baseline.oof.residual_base, baseline.oof.tip_base,
                           groups, setup.settings, n_jobs=options.n_jobs, n_permutations=options.n_permutations,
                           seed=options.seed, cache=setup.stages, alpha_step=ALPHA_STEP)
    tests = {}
    for e in setup.effects:
        entry = REGISTRY[e]
        tests[e] = (entry.signature(ctx) if entry.signature is not None
                    else untestable(e, "its entry defines no signature test"))
    for e, t in tests.items():
        if t.testable:
            logger.log(progress_level(),
                       f"  {label(e):>30s}: effect {t.effect_size_m * 1e3:.3f} mm, p = {t.p_value:.4f}")
        else:
            logger.log(progress_level(), f"  {label(e):>30s}: {t.description}")
    return tests
