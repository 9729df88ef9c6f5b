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

Regression tests use the fraction of residual variance explained by the effect's features
(least squares with intercept, the three residual components pooled) as statistic, and the RMS
of the explained part (less the mean explained by chance under the null) as effect size. When configurations repeat (e.g. the four approach
directions of the paper's protocol), residuals and features are first averaged per
configuration, so that direction-dependent (friction) residuals do not leak into the other
tests.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

__all__ = ["SignatureTest", "friction_signature", "regression_signature", "registration_signature",
           "vector_signature", "untestable",
           "overlap_features", "angle_features", "twist_features", "EFFECT_LABELS"]

#: Human-readable effect names used in reports.
EFFECT_LABELS = {
    "friction": "torsional friction",
    "clearance": "clearance",
    "offplane": "off-plane precurvature",
    "poisson": "stiffness ratio / Poisson ratio (torsional stiffness)",
    "registration": "registration",
    "backlash": "drive backlash",
    "time_offset": "time offset (tracker lag)",
    "gradual_friction": "gradually developing friction",
}


@dataclass(frozen=True)
class SignatureTest:
    """Result of one signature test.

    Attributes
    ----------
    effect : str
        Key of :data:`EFFECT_LABELS`.
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

    def as_dict(self) -> dict:
        d = asdict(self)
        d["label"] = EFFECT_LABELS.get(self.effect, self.effect)
        d["effect_size_mm"] = self.effect_size_m * 1e3
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


# --------------------------------------------------------------------------- features
def overlap_features(robot, beta) -> np.ndarray:
    """Tube-overlap features of the clearance signature, shape (K, 3 (n - 1)) [m].

    For each pair (i, i+1): the length over which curved sections of both overlap, the length of
    tube i+1's straight (transmission) sections inside curved sections of tube i, and of tube
    i's straight sections around curved sections of tube i+1 (Section II-B: clearance lets an
    inner tube move inside an outer one where their curvatures differ).
    """
    beta = np.atleast_2d(np.asarray(beta, float))
    n = robot.n_tubes
    out = np.zeros((beta.shape[0], 3 * (n - 1)))

    def spans(i, b, curved):
        br = robot.tubes[i].section_breaks() + b
        return [(br[j], br[j + 1]) for j, sec in enumerate(robot.tubes[i].sections)
                if (not sec.is_straight) == curved]

    def overlap(a, c):
        return sum(max(0.0, min(x1, y1) - max(x0, y0)) for x0, x1 in a for y0, y1 in c)

    for r, b in enumerate(beta):
        for i in range(n - 1):
            co, ci = spans(i, b[i], True), spans(i + 1, b[i + 1], True)
            so, si = spans(i, b[i], False), spans(i + 1, b[i + 1], False)
            out[r, 3 * i:3 * i + 3] = (overlap(co, ci), overlap(si, co), overlap(so, ci))
    return out


def angle_features(alpha, moving=None) -> np.ndarray:
    """First and second harmonics of the absolute tube angles, shape (K, 4 m).

    Parameters
    ----------
    alpha : ndarray, shape (K, n) [rad]
    moving : sequence of int, optional
        Tubes to use (default: those whose angle varies in the data).
    """
    alpha = np.asarray(alpha, float)
    if moving is None:
        moving = [i for i in range(alpha.shape[1]) if np.ptp(alpha[:, i]) > 1e-6]
    cols = []
    for i in moving:
        a = alpha[:, i]
        cols += [np.cos(a), np.sin(a), np.cos(2 * a), np.sin(2 * a)]
    return np.column_stack(cols) if cols else np.zeros((alpha.shape[0], 0))


def twist_features(twist, model_tip) -> np.ndarray:
    """Twist features of the stiffness / Poisson signature, shape (K, 6).

    ``[tau, tau^2] x [1, cos phi, sin phi]`` with ``tau`` the twist of the most strained tube
    [rad] and ``phi`` the azimuth of the model tip (the direction the residual takes rotates
    with the bending plane).
    """
    twist = np.asarray(twist, float)
    phi = np.arctan2(model_tip[:, 1], model_tip[:, 0])
    base = [np.ones_like(phi), np.cos(phi), np.sin(phi)]
    return np.column_stack([t * b for t in (twist, twist ** 2) for b in base])


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
