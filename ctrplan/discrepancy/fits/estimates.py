"""Fitted parameter values as a report reads them: value, standard error and interval, the robot
file's value, and the parameter's typical range with its source (:mod:`ctrplan.discrepancy.fits.parameters`).

- :func:`covariance`: standard errors and correlations of a least-squares fit, clustered over
  units of samples; neighbouring time blocks whose scores are correlated across their seam are
  merged first (:func:`merge_neighbouring_units`);
- :func:`parameter_table`: the values with intervals from the t distribution with ``G - 1``
  degrees of freedom over ``G`` clusters.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Mapping

import numpy as np

from ..options import CONFIDENCE
from .parameters import parameter
from ..measured.split import BUFFER_AUTOCORRELATION

__all__ = ["ParameterEstimate", "AtypicalValue", "Uncertainty", "parameter_table", "atypical_values", "display_value",
           "covariance", "merge_neighbouring_units", "interval_quantile", "MIN_CLUSTERS", "SEAM_CORRELATION"]

#: Clusters the merging of neighbouring units leaves at least (fewer units are not merged): the
#: t quantile with 7 degrees of freedom is 2.36 at 95 %, and fewer clusters make the interval
#: uninformative (as for the test split, :data:`~ctrplan.discrepancy.measured.split.MIN_TEST_UNITS`).
MIN_CLUSTERS = 8
#: Neighbouring clusters are merged while the correlation of their score sums exceeds this (the
#: threshold at which the split's buffer deems the residuals' autocorrelation negligible): the
#: cluster-robust variance, which leaves the correlation between clusters out, is then at most
#: about ``1 / (1 + 2 * 0.1)`` of the true one (standard errors about 9 % low).
SEAM_CORRELATION = BUFFER_AUTOCORRELATION


@dataclass(frozen=True, eq=False)
class Uncertainty:
    """Standard errors and correlations of fitted values (:func:`covariance`); unpacks as
    ``stderr, correlation = uncertainty``.

    Attributes
    ----------
    stderr : ndarray, shape (m,), or None
        In the parameters' units; inf where the data do not determine the parameter; NaN where
        undefined (fewer than two clusters); None when not computed.
    correlation : ndarray, shape (m, m), or None
    n_clusters : int or None
        G, the clusters the standard errors are clustered over (after merging neighbours); None
        without clustering (independent residuals assumed).
    note : str
        How the clusters were formed (empty without clustering).
    """

    stderr: np.ndarray
    correlation: np.ndarray
    n_clusters: int | None = None
    note: str = ""

    @property
    def dof(self) -> int | None:
        """Degrees of freedom of the interval's t quantile, ``G - 1``; None without clustering."""
        return None if self.n_clusters is None else self.n_clusters - 1

    def __iter__(self):
        return iter((self.stderr, self.correlation))


def interval_quantile(dof: int | None) -> float:
    """Two-sided quantile of a :data:`~ctrplan.discrepancy.options.CONFIDENCE` interval: Student's t
    with ``dof`` degrees of freedom (clustered standard errors, ``G - 1``; Cameron & Miller, J.
    Human Resources 50:317, 2015, Sec. VI), the normal one for ``dof`` None (no clustering); NaN for
    ``dof`` < 1."""
    from scipy import stats

    if dof is None:
        return float(stats.norm.ppf(0.5 + CONFIDENCE / 2))
    return float(stats.t.ppf(0.5 + CONFIDENCE / 2, dof)) if dof >= 1 else float("nan")


def _score_autocorrelation(score, motion, position, threshold: float, max_lag: int) -> np.ndarray:
    """Autocorrelation of the per-sample scores along each motion, lag by lag from 1 until it falls to
    ``threshold`` (or ``max_lag``), pooled over the score's components (each scaled to a mean
    square of 1 and centred per motion) as :func:`~ctrplan.discrepancy.measured.split.residual_autocorrelation`
    pools the residual's.

    Parameters
    ----------
    score : ndarray, shape (K, m)
    motion, position : ndarray of int, shape (K,)
        Continuous motion of each sample and its index in the record; lags count record positions.
    threshold : float
    max_lag : int

    Returns
    -------
    ndarray, shape (L + 1,)
        Lags 0..L, L the first lag at which it is at most ``threshold`` (or ``max_lag``); NaN at a
        lag without pairs of samples.
    """
    z = score[:, np.any(score != 0.0, axis=0)]
    z = z / np.sqrt(np.mean(z * z, axis=0))
    grids, var = [], 0.0
    for s in np.unique(motion):
        on = motion == s
        x = z[on] - z[on].mean(axis=0)
        var += float(np.sum(x * x))
        grid = np.full((int(position[on].max() - position[on].min()) + 1, z.shape[1]), np.nan)
        grid[position[on] - position[on].min()] = x
        grids.append(grid)
    acf = [1.0]
    for lag in range(1, max_lag + 1):
        prods = [np.sum(g[lag:] * g[:-lag], axis=1) for g in grids if g.shape[0] > lag]
        prod = np.concatenate(prods) if prods else np.zeros(0)
        prod = prod[np.isfinite(prod)]
        acf.append(float(prod.mean() / (var / len(z))) if prod.size and var > 0 else np.nan)
        if acf[-1] <= threshold or var <= 0:
            break
    return np.array(acf)


def merge_neighbouring_units(units, motion, position, score, *, threshold: float = SEAM_CORRELATION,
                             min_clusters: int = MIN_CLUSTERS) -> tuple[np.ndarray, str]:
    """Clusters of neighbouring units of one motion whose scores are nearly uncorrelated across
    their seams.

    Units that are consecutive stretches of one motion (time blocks) share the serial
    correlation of the residuals across each seam, which the cluster-robust variance leaves
    out. The autocorrelation ``rho`` of the scores along the motions (:func:`_score_autocorrelation`)
    is kept up to the lag L at which it first falls to ``threshold`` (0 from there, as the
    split's buffer, :func:`~ctrplan.discrepancy.measured.split.choose_buffer`); with it, the correlation
    of two neighbouring clusters' score sums is ``C_ab / sqrt(V_a V_b)``, ``V_a = sum_{i, j in a}
    rho(|p_i - p_j|)``, ``C_ab = sum_{i in a, j in b} rho(p_j - p_i)`` (p: record positions). The
    neighbours with the largest such correlation are merged, one pair at a time, until none
    exceeds ``threshold`` or ``min_clusters`` are left. Units that are not stretches of one motion
    each (configuration groups, linked over several motions) have no serial order and are left
    as they are, as are ``min_clusters`` units or fewer.

    Parameters
    ----------
    units : array-like, shape (K,)
        Unit of each sample.
    motion : array-like of int, shape (K,)
        Continuous motion of each sample (``MeasuredData.sequence``).
    position : array-like of int, shape (K,)
        Its index in the record (``MeasuredData.rows``): time order within a motion.
    score : ndarray, shape (K, m)
        Per-sample score ``J_i^T f_i`` of the fit.
    threshold : float
        Largest correlation of neighbouring clusters' score sums left.
    min_clusters : int

    Returns
    -------
    clusters : ndarray of int, shape (K,)
        Cluster of each sample, 0..G-1.
    note : str
        What was merged and why, one line.
    """
    _, labels = np.unique(np.asarray(units), return_inverse=True)
    labels = labels.ravel()
    motion = np.asarray(motion).ravel()
    position = np.asarray(position, dtype=np.int64).ravel()
    n_units = int(labels.max()) + 1 if labels.size else 0
    if n_units <= min_clusters:
        return labels, f"{n_units} units, too few to merge (at most {min_clusters})"
    order = np.lexsort((position, motion))
    new_run = np.r_[True, (np.diff(labels[order]) != 0) | (np.diff(motion[order]) != 0)]
    if int(new_run.sum()) != n_units:
        return labels, f"{n_units} units, not merged: not consecutive stretches of one motion each"
    run_of = np.empty(labels.size, dtype=np.int64)
    run_of[order] = np.cumsum(new_run) - 1
    first = order[new_run]
    last = order[np.r_[new_run[1:], True]]
    if np.all(np.diff(motion[first]) != 0):
        return labels, f"{n_units} units, not merged: no two are stretches of the same motion"
    # a cluster of the fewest allowed is as long as the motions' record positions over min_clusters
    span = sum(int(np.ptp(position[motion == s])) + 1 for s in np.unique(motion))
    acf = _score_autocorrelation(score, motion, position, threshold, max(1, span // min_clusters))
    L = acf.size - 1 if acf[-1] <= threshold else acf.size
    rho = np.nan_to_num(acf[1:L], nan=0.0)
    # per motion, c[l - 1, j]: pairs of samples at lag l (1..L-1) whose first lies below position j
    pairs = {}
    for s in np.unique(motion):
        p0 = position[motion == s].min()
        ind = np.zeros(int(position[motion == s].max() - p0) + 1)
        ind[position[motion == s] - p0] = 1.0
        c = np.zeros((max(L - 1, 0), ind.size + 1))
        for lag in range(1, min(L, ind.size)):
            cum = np.cumsum(ind[:-lag] * ind[lag:])
            c[lag - 1, 1:cum.size + 1] = cum
            c[lag - 1, cum.size + 1:] = cum[-1]
        pairs[s] = (c, p0)

    def within(s, lo, hi):
        """``sum_l rho_l`` (pairs at lag l inside record positions lo..hi of motion s)."""
        c, p0 = pairs[s]
        lags = np.arange(1, L)
        end = np.maximum(hi - p0 - lags + 1, lo - p0)
        return float(rho @ (c[lags - 1, end] - c[lags - 1, lo - p0])) if L > 1 else 0.0

    # clusters as (motion, first position, last position, samples), in the motions' time order
    size = np.bincount(run_of, minlength=n_units)
    cl = [(motion[a], position[a], position[b], int(size[r])) for r, (a, b) in enumerate(zip(first, last))]
    runs = [[r] for r in range(len(cl))]

    def var(c):
        return max(c[3] + 2.0 * within(c[0], c[1], c[2]), 1e-12)

    def seam(a, b):
        if a[0] != b[0]:
            return -np.inf
        cross = within(a[0], a[1], b[2]) - within(a[0], a[1], a[2]) - within(b[0], b[1], b[2])
        return cross / np.sqrt(var(a) * var(b))

    seams = [seam(cl[i], cl[i + 1]) for i in range(len(cl) - 1)]
    while len(cl) > min_clusters and seams and max(seams) > threshold:
        i = int(np.argmax(seams))
        cl[i:i + 2] = [(cl[i][0], cl[i][1], cl[i + 1][2], cl[i][3] + cl[i + 1][3])]
        runs[i:i + 2] = [runs[i] + runs[i + 1]]
        del seams[i]
        if i > 0:
            seams[i - 1] = seam(cl[i - 1], cl[i])
        if i < len(seams):
            seams[i] = seam(cl[i], cl[i + 1])
    cluster_of_run = np.empty(n_units, dtype=np.int64)
    for g, rs in enumerate(runs):
        cluster_of_run[rs] = g
    left = max(seams) if seams else -np.inf
    fell = (f"falls to {threshold:g} at lag {L}" if L < acf.size else
            f"is still {np.nan_to_num(acf[-1]):.2f} at lag {acf.size - 1}")
    note = (f"{n_units} units merged into {len(cl)} clusters of neighbours: the scores' autocorrelation {fell}; the "
            f"largest correlation left between neighbouring clusters is {max(left, 0.0):.2f}"
            + (f" (at the fewest clusters allowed, {min_clusters})" if left > threshold else ""))
    return cluster_of_run[run_of], note


def covariance(rows: np.ndarray, residual: np.ndarray, n_samples: int, *, clusters=None, width: int = 1,
               motion=None, position=None) -> Uncertainty:
    """Standard errors (m,) and correlations (m, m) of a least-squares fit from its Gauss-Newton rows.

    Without ``clusters``: ``cov = s^2 (J^T J)^+``, ``s^2 = RSS / (n_samples - m)`` (independent,
    equal-variance residuals). With ``clusters`` (the unit of each sample): the cluster-robust
    sandwich ``cov = (J^T J)^+ M (J^T J)^+``, ``M = G / (G - 1) sum_g S_g S_g^T`` with ``S_g`` the
    sum of the scores ``J_i^T f_i`` over the samples of cluster g (Liang & Zeger, Biometrika 73:13,
    1986; Cameron & Miller, J. Human Resources 50:317, 2015): samples of a motion are serially
    correlated, so the errors of one unit are not independent. With ``motion`` and ``position``
    too, neighbouring units of one motion are merged first until the correlation across the
    clusters' seams is negligible (:func:`merge_neighbouring_units`); G is the number of clusters
    then, and an interval uses the t quantile with ``G - 1`` degrees of freedom
    (:func:`interval_quantile`). With fewer than two clusters the standard errors are undefined
    (NaN): the scores of a single cluster sum to the fit's zero gradient. A direction the rows do
    not determine (a zero singular value of ``J``) gives an infinite standard error.

    Parameters
    ----------
    rows : ndarray, shape (n_samples * width + P, m)
        Gauss-Newton rows: ``width`` per sample in sample order, then P rows of a prior (which
        enter ``J^T J`` but not ``M`` or ``RSS``).
    residual : ndarray, shape (n_samples * width + P,)
        The residual vector the rows belong to.
    n_samples : int
    clusters : array-like, shape (n_samples,), optional
        Unit of each sample.
    width : int
        Rows per sample.
    motion, position : array-like of int, shape (n_samples,), optional
        Continuous motion of each sample and its index in the record (``MeasuredData.sequence``,
        ``MeasuredData.rows``); without them the units are the clusters.

    Returns
    -------
    Uncertainty
        Unpacks as ``stderr (m,), correlation (m, m)``; ``n_clusters`` and ``dof`` for the interval.
    """
    J = np.asarray(rows, float)
    f = np.asarray(residual, float)
    m = J.shape[1]
    n_data = n_samples * width
    H = J.T @ J
    w, V = np.linalg.eigh(H)
    tiny = w <= 1e-12 * max(float(w.max()), 1e-300)
    inv_w = np.where(tiny, 0.0, 1.0 / np.where(tiny, 1.0, w))
    Hinv = (V * inv_w) @ V.T
    n_g, note = None, ""
    if clusters is None:
        s2 = float(f[:n_data] @ f[:n_data]) / max(n_samples - m, 1)
        cov = Hinv * s2
    else:
        score = np.einsum("kwm,kw->km", J[:n_data].reshape(n_samples, width, m), f[:n_data].reshape(n_samples, width))
        if motion is not None and position is not None:
            g, note = merge_neighbouring_units(clusters, motion, position, score)
        else:
            _, g = np.unique(np.asarray(clusters), return_inverse=True)
            note = "the units as given"
        n_g = int(g.max()) + 1
        S = np.zeros((n_g, m))
        np.add.at(S, g.ravel(), score)
        cov = Hinv @ (S.T @ S * (n_g / max(n_g - 1, 1))) @ Hinv
        if n_g < 2:
            cov = np.full((m, m), np.nan)
    var = np.diag(cov).copy()
    undetermined = np.any(np.abs(V[:, tiny]) > 1e-6, axis=1) if tiny.any() else np.zeros(m, bool)
    se = np.where(undetermined, np.inf, np.sqrt(np.maximum(var, 0.0)))
    d = np.sqrt(np.maximum(var, 1e-300))
    corr = cov / np.outer(d, d)
    corr[undetermined] = np.nan
    corr[:, undetermined] = np.nan
    return Uncertainty(se, corr, n_g, note)


@dataclass(frozen=True)
class ParameterEstimate:
    """One fitted (or held) parameter of a fit.

    Attributes
    ----------
    name : str
        Its name (:mod:`ctrplan.discrepancy.fits.parameters`).
    unit : str
        Its SI unit (``"1/m"``, ``"rad"``, ``"m"``, ``"s"``, ``"-"``).
    value : float
        The value [unit]; NaN when the fit neither fitted nor held it.
    stderr : float or None
        Standard error [unit] (clustered over clusters of units where the fit computed it so; inf
        when the data do not determine it; NaN when undefined, over fewer than two clusters); None
        when the fit computed none.
    ci : tuple of float, or None
        Interval (low, high) [unit] at :data:`~ctrplan.discrepancy.options.CONFIDENCE`: ``value +- q
        stderr`` with ``q`` the t quantile with ``G - 1`` degrees of freedom for standard errors
        clustered over G clusters, the normal one without clustering (:func:`interval_quantile`);
        None without a finite standard error.
    typical : tuple of float, or None
        Typical range (low, high) [unit]; None when any value is typical.
    in_typical_range : bool
    typical_source : str or None
        Where the typical range comes from.
    check : str or None
        What to check on the robot when the value is outside its typical range.
    at_bound : bool
        The fit flagged the value at a bound or a scan's or grid's end it could not widen.
    resolution : float or None
        Step of a scan or grid that sets it [unit].
    fitted : bool
        Fitted (False: held at a fixed value).
    reference : float or None
        The robot file's value [unit], when given.
    relative_change : float or None
        ``(value - reference) / reference`` [-]; None without a reference or for a reference of 0.
    """

    name: str
    unit: str
    value: float
    stderr: float | None
    ci: tuple | None
    typical: tuple | None
    in_typical_range: bool
    typical_source: str | None
    check: str | None
    at_bound: bool
    resolution: float | None
    fitted: bool
    reference: float | None = None
    relative_change: float | None = None

    def as_dict(self) -> dict:
        """Plain JSON form (SI; intervals and ranges as lists; ``reference`` and
        ``relative_change`` only with a reference)."""
        out = {"name": self.name, "unit": self.unit, "value": self.value, "stderr": self.stderr,
               "ci": None if self.ci is None else list(self.ci),
               "typical": None if self.typical is None else list(self.typical),
               "in_typical_range": self.in_typical_range, "typical_source": self.typical_source, "check": self.check,
               "at_bound": self.at_bound, "resolution": self.resolution, "fitted": self.fitted}
        if self.reference is not None:
            out.update(reference=self.reference, relative_change=self.relative_change)
        return out


@dataclass(frozen=True)
class AtypicalValue:
    """A fitted value outside its parameter's typical range.

    Attributes
    ----------
    name : str
    value : float
        [unit]
    typical : tuple of float
        The typical range (low, high) [unit].
    typical_text : str
        The range as a report prints it.
    unit : str
    why : str
        The range's source.
    check : str or None
        What to check on the robot.
    """

    name: str
    value: float
    typical: tuple
    typical_text: str
    unit: str
    why: str
    check: str | None

    def as_dict(self) -> dict:
        """Plain JSON form (SI; the range as a list)."""
        return {"name": self.name, "value": self.value, "typical": list(self.typical),
                "typical_text": self.typical_text, "unit": self.unit, "why": self.why, "check": self.check}


def display_value(name: str, value: float, unit: str) -> str:
    """A parameter for a printed report or message: rad as deg, m as mm, others in their SI unit."""
    if unit == "rad":
        return f"{name} = {np.rad2deg(value):.4g} deg"
    if unit == "m":
        return f"{name} = {value * 1e3:.4g} mm"
    return f"{name} = {value:.4g}" + ("" if unit == "-" else f" {unit}")


def atypical_values(robot, params: Mapping) -> tuple:
    """The values of ``params`` ({name: value} [SI]) outside their typical range.

    Returns
    -------
    tuple of AtypicalValue
    """
    out = []
    for name, value in params.items():
        p = parameter(robot, name)
        if not p.is_typical(value):
            out.append(AtypicalValue(name=name, value=float(value), typical=tuple(p.typical), unit=p.unit,
                                     typical_text=p.typical_text(), why=p.typical_source, check=p.check))
    return tuple(out)


def parameter_table(robot, fit, names, *, reference: Mapping | None = None) -> tuple:
    """The parameters ``names`` of ``fit`` with their uncertainty and typical range.

    Parameters
    ----------
    robot : Robot
        Gives each parameter's unit and typical range.
    fit : CalibrationResult
        Fitted and fixed values [SI], standard errors and the clusters they were computed over
        (``dof``; :class:`~ctrplan.discrepancy.fits.calibrate.CalibrationResult`).
    names : sequence of str
    reference : mapping of str to float, optional
        E.g. the robot file's values [SI]: each estimate's ``reference`` and ``relative_change``.

    Returns
    -------
    tuple of ParameterEstimate
        In the order of ``names``.
    """
    z = interval_quantile(fit.dof)
    values = dict(zip(fit.names, fit.values))
    errors = dict(zip(fit.names, fit.stderr)) if fit.stderr is not None else {}
    flagged = {b.split(" ")[0] for b in fit.at_bound}
    out = []
    for n in names:
        v = float(values.get(n, fit.fixed.get(n, np.nan)))
        p = parameter(robot, n)
        se = errors.get(n)
        row = ParameterEstimate(
            name=n, unit=p.unit, value=v, stderr=None if se is None else float(se),
            ci=None if se is None or not np.isfinite(se * z) else (v - z * se, v + z * se),
            typical=None if p.typical is None else tuple(p.typical), in_typical_range=p.is_typical(v),
            typical_source=p.typical_source, check=p.check, at_bound=n in flagged, resolution=p.resolution,
            fitted=n in values)
        if reference is not None and n in reference:
            ref = float(reference[n])
            row = replace(row, reference=ref, relative_change=(v - ref) / ref if ref else None)
        out.append(row)
    return tuple(out)
