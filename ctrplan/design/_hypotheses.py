"""Hypotheses a new experiment is to separate: robot models with their effects and fitted values.

A hypothesis is what the discrepancy workflow fitted for one candidate (or a pair of effects): the
mechanics model, every parameter it set (the robot file's baseline parameters refitted, the
effects' parameters, the registration) and which of them the fit moved. The design refits the
moved ones (:mod:`._criteria`), so a difference that a refit absorbs is not counted as separation.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import CtrplanError
from ..models import check_model


class DesignInputError(CtrplanError, ValueError):
    """A discrepancy result folder, a hypothesis or a parameter the design cannot use."""


@dataclass(frozen=True, eq=False)
class Hypothesis:
    """One robot model the measurements may come from.

    Attributes
    ----------
    key : str
        Short name: the effect (``"offplane"``) or ``"first+second"`` for a pair.
    label : str
        Words for reports (``"off-plane precurvature"``).
    model : {"standard", "clearance", "friction"}
        Mechanics model the hypothesis needs (Sections II-III of Ha et al. 2019).
    names : tuple of str
        Every parameter the hypothesis sets (baseline, effect and registration parameters).
    values : ndarray, shape (m,)
        Their values, SI units (1/m, -, rad, m, s).
    free : tuple of str
        The parameters its fit moved: a refit to another hypothesis's predictions may move them.
    stderr : dict of str to float
        Standard errors of the free parameters as the fit gave them (inf: undetermined by the
        recorded data; NaN: not computed).
    """

    key: str
    label: str
    model: str
    names: tuple
    values: np.ndarray
    free: tuple
    stderr: dict = field(default_factory=dict)

    def __post_init__(self):
        check_model(self.model)
        values = np.asarray(self.values, float).reshape(-1)
        if values.size != len(self.names):
            raise DesignInputError(f"hypothesis {self.key!r}: {len(self.names)} names but {values.size} values")
        missing = [n for n in self.free if n not in self.names]
        if missing:
            raise DesignInputError(f"hypothesis {self.key!r}: free parameter(s) {', '.join(missing)} not among its "
                                   f"parameters")
        object.__setattr__(self, "values", values)

    def value(self, name: str) -> float:
        """The value of parameter ``name`` (SI)."""
        return float(self.values[self.names.index(name)])

    def effect_parameters(self, robot) -> tuple:
        """Free parameters of the hypothesis's own effects (not the baseline's tube parameters, nor a
        registration the baseline fits unless the registration is the effect)."""
        from ..effects import effect_of_parameter

        own = set(self.key.split("+"))
        out = []
        for n in self.free:
            e = effect_of_parameter(robot, n)
            if e is not None and e.name in own:
                out.append(n)
        return tuple(out)

    def undetermined(self, robot=None) -> tuple:
        """Free parameters the recorded data left undetermined or poorly determined: a standard
        error that is infinite, or whose 95 % interval is wider than the parameter's typical range
        (:func:`ctrplan.discrepancy.fits.parameters.parameter`)."""
        out = []
        for n in self.free:
            se = self.stderr.get(n, math.nan)
            if se == math.inf:
                out.append(n)
                continue
            if robot is not None and np.isfinite(se):
                from ..discrepancy.fits.parameters import parameter

                typical = parameter(robot, n).typical
                if typical is not None and 2 * 1.96 * se > abs(typical[1] - typical[0]):
                    out.append(n)
        return tuple(out)


def _fit_hypothesis(key: str, label: str, fit: dict, where: str) -> Hypothesis:
    try:
        fixed = dict(fit.get("fixed") or {})
        params = dict(fit["parameters"])
        model = fit["model"]
    except (KeyError, TypeError) as exc:
        raise DesignInputError(f"{where}: no fit with 'model' and 'parameters' ({exc})") from None
    names = tuple(fixed) + tuple(params)
    values = [float(v) for v in (*fixed.values(), *params.values())]
    stderr = {n: (math.nan if v is None else float(v)) for n, v in (fit.get("stderr") or {}).items()}
    return Hypothesis(key=key, label=label, model=model, names=names, values=np.array(values), free=tuple(params),
                      stderr=stderr)


def read_results(folder) -> dict:
    """``results.json`` of a ``ctrplan discrepancy`` folder.

    Raises
    ------
    DesignInputError
        No such folder or file, or a file that is not JSON.
    """
    path = Path(folder) / "results.json"
    if not path.is_file():
        raise DesignInputError(f"{folder}: no results.json (a `ctrplan discrepancy` output folder is expected)")
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise DesignInputError(f"{path}: not valid JSON ({exc})") from None


def result_hypotheses(results: dict, keys=None, *, where: str = "results.json") -> tuple[Hypothesis, ...]:
    """The hypotheses a discrepancy result leaves open.

    Parameters
    ----------
    results : dict
        ``results.json`` of ``ctrplan discrepancy`` (:func:`read_results`).
    keys : sequence of str, optional
        Candidates to take (an effect, ``"baseline"``, or ``"first+second"`` for a pair the
        workflow tried). Default: the ambiguous pair when the verdict is ambiguous, else the named
        model (the pair when one was named), else the baseline.
    where : str
        Where ``results`` came from, for messages.

    Returns
    -------
    tuple of Hypothesis

    Raises
    ------
    DesignInputError
        A key the result has no fit for (naming the keys it has).
    """
    candidates = results.get("candidates") or {}
    combination = results.get("combination") or {}
    tried = combination.get("tried") or {}
    first = combination.get("first")
    available = {"baseline": None, **{e: None for e in candidates}, **{f"{first}+{e}": None for e in tried}}
    if keys is None:
        named = results.get("named_effect")
        if results.get("verdict") == "ambiguous" and results.get("ambiguous_with"):
            keys = [named, results["ambiguous_with"]]
        elif combination.get("named"):
            keys = [f"{first}+{combination['named']}"]
        elif named:
            keys = [named]
        else:
            keys = ["baseline"]
    out = []
    for key in keys:
        if key == "baseline":
            base = results.get("baseline") or {}
            fit = base.get("fit") or base.get("development_fit")
            if fit is None:
                raise DesignInputError(f"{where}: the baseline has no fit")
            out.append(_fit_hypothesis("baseline", "baseline (no effect)", fit, f"{where}: baseline"))
        elif key in candidates:
            c = candidates[key]
            out.append(_fit_hypothesis(key, c.get("label", key), c.get("fit"), f"{where}: candidate {key!r}"))
        elif "+" in key and key.split("+", 1)[0] == first and key.split("+", 1)[1] in tried:
            c = tried[key.split("+", 1)[1]]
            out.append(_fit_hypothesis(key, c.get("label", key), c.get("fit"), f"{where}: pair {key!r}"))
        else:
            raise DesignInputError(f"{where}: no fitted candidate {key!r}; it has {', '.join(available)}")
    if len({h.key for h in out}) != len(out):
        raise DesignInputError(f"{where}: a hypothesis is named twice in {', '.join(keys)}")
    return tuple(out)
