"""Can the recorded motion tell two candidate effects apart? The correlation of their fitted tip
displacement fields.

Two effects that move the tip the same way on the recorded motion cannot be told apart by any
statistic of those data, however small their p-values: on a robot whose outer tube does not
rotate, a constant off-plane precurvature and a rotation of the tracker frame about the base axis
are such a pair. Which of the two fits a little better then hinges on the small part of the
residual where their fields differ, which a second unmodelled effect or correlated noise can
supply as well as the truth can.

A candidate's **displacement field** is what it adds to the baseline at every development sample,
out of fold: the baseline's out-of-fold residual minus the candidate's (both measured minus
predicted tip, in the robot's base frame [m]), i.e. the candidate's predicted tip minus the
baseline's, each predicted by models fitted without the sample's fold. Two fields f_a, f_b
(K x 3, stacked) have the uncentred correlation

    rho = <f_a, f_b> / (|f_a| |f_b|)

(a constant offset is part of a field). The part of f_a that a multiple of f_b cannot reproduce
has the relative size sqrt(1 - rho^2). The pair is **not separable on this motion** when
rho^2 >= 1 - 1 / :data:`INSEPARABLE_VIF`: the collinearity rule of regression (a variance
inflation factor of 10, R^2 = 0.9 between two regressors, rho >= 0.949; Marquardt,
Technometrics 12:591, 1970; Kutner, Nachtsheim, Neter & Li, *Applied Linear Statistical Models*,
5th ed., 2005, Sec. 10.5), applied to the two effects' fitted signatures instead of two
regressors: their coefficients cannot be estimated apart, and here the coefficients are the
effects. The rule is stated before any data are seen and does not depend on the noise: a motion
that makes two fields collinear leaves them collinear however long it is recorded.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["INSEPARABLE_VIF", "INSEPARABLE_CORRELATION", "Separability", "displacement_field", "separability"]

#: Variance inflation factor at which two fitted displacement fields are too collinear for the
#: data to tell their effects apart (module docstring).
INSEPARABLE_VIF = 10.0
#: The same as a correlation of the two fields: |rho| at or above it is not separable.
INSEPARABLE_CORRELATION = float(np.sqrt(1.0 - 1.0 / INSEPARABLE_VIF))


@dataclass(frozen=True)
class Separability:
    """Two candidates' fitted tip displacement fields on the recorded motion compared.

    Attributes
    ----------
    first, second : str
        The effects (``first`` the named one).
    correlation : float
        Uncentred correlation rho of their out-of-fold displacement fields [-], in [-1, 1]; NaN
        when either field is zero or no sample is finite.
    unreproduced : float
        ``sqrt(1 - rho^2)``: the share of either field's rms that a multiple of the other cannot
        reproduce [-] (NaN with ``correlation``).
    rms_first_m, rms_second_m : float
        rms length of each field over the samples [m].
    n_samples : int
        Development samples where both candidates and the baseline have finite residuals.
    threshold : float
        :data:`INSEPARABLE_CORRELATION` at the time of the run.
    """

    first: str
    second: str
    correlation: float
    unreproduced: float
    rms_first_m: float
    rms_second_m: float
    n_samples: int
    threshold: float = INSEPARABLE_CORRELATION

    @property
    def separable(self) -> bool:
        """The motion tells them apart: ``|rho|`` below the threshold (True when rho is undefined:
        a zero field is no signature to confuse)."""
        return not (np.isfinite(self.correlation) and abs(self.correlation) >= self.threshold)

    def as_dict(self) -> dict:
        """Plain JSON form (fields' rms in mm, as the report prints them)."""
        return {"first": self.first, "second": self.second, "correlation": _plain(self.correlation),
                "unreproduced": _plain(self.unreproduced), "rms_first_mm": _plain(1e3 * self.rms_first_m),
                "rms_second_mm": _plain(1e3 * self.rms_second_m), "n_samples": int(self.n_samples),
                "threshold": float(self.threshold), "separable": bool(self.separable)}


def _plain(x: float):
    return float(x) if np.isfinite(x) else None


def displacement_field(baseline_residual, candidate_residual) -> np.ndarray:
    """A candidate's tip displacement field over the baseline's: ``baseline_residual -
    candidate_residual``.

    Parameters
    ----------
    baseline_residual, candidate_residual : array-like, shape (K, 3)
        Out-of-fold residuals (measured minus predicted tip) at the same K samples, in the robot's
        base frame [m] (``Errors.residual_base``).

    Returns
    -------
    ndarray, shape (K, 3)
        [m]; NaN rows where either residual is not finite.

    Raises
    ------
    ValueError
        The shapes differ or are not (K, 3).
    """
    a, b = np.asarray(baseline_residual, float), np.asarray(candidate_residual, float)
    if a.shape != b.shape or a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"displacement_field: residuals of shapes {a.shape} and {b.shape}; expected two (K, 3)")
    return a - b


def separability(first: str, second: str, baseline_residual, first_residual, second_residual,
                 threshold: float = INSEPARABLE_CORRELATION) -> Separability:
    """Whether the recorded motion tells two candidates apart (module docstring).

    Parameters
    ----------
    first, second : str
        Their effects' names.
    baseline_residual, first_residual, second_residual : array-like, shape (K, 3)
        Out-of-fold residuals of the baseline and of each candidate at the same development samples,
        robot base frame [m].
    threshold : float
        Correlation at or above which they are not separable, in (0, 1].

    Returns
    -------
    Separability

    Raises
    ------
    ValueError
        Shapes that differ or are not (K, 3); a threshold outside (0, 1].
    """
    if not 0.0 < threshold <= 1.0:
        raise ValueError(f"separability: threshold {threshold!r} is not in (0, 1]")
    fa = displacement_field(baseline_residual, first_residual)
    fb = displacement_field(baseline_residual, second_residual)
    ok = np.all(np.isfinite(fa), axis=1) & np.all(np.isfinite(fb), axis=1)
    fa, fb = fa[ok], fb[ok]
    n = int(ok.sum())
    na, nb = float(np.sqrt(np.sum(fa * fa))), float(np.sqrt(np.sum(fb * fb)))
    rho = float(np.clip(np.sum(fa * fb) / (na * nb), -1.0, 1.0)) if n and na > 0.0 and nb > 0.0 else float("nan")
    rms = (lambda norm: norm / np.sqrt(n) if n else float("nan"))
    return Separability(first=first, second=second, correlation=rho,
                        unreproduced=float(np.sqrt(max(0.0, 1.0 - rho * rho))) if np.isfinite(rho) else float("nan"),
                        rms_first_m=rms(na), rms_second_m=rms(nb), n_samples=n, threshold=float(threshold))
