"""Sentences of the plan's reports from the stages' enums and numbers (the stages carry no prose).

:func:`aim_reason` words an :class:`~ctrplan.pipeline.goals.AimDecision` (which model task-space
goals are aimed with, and why) for the log, ``summary.json`` and ``report.md``; it prints lengths
in mm.
"""

from __future__ import annotations

__all__ = ["aim_reason"]


def aim_reason(decision) -> str:
    """Why task-space goals are aimed with ``decision.model``, in one sentence.

    Parameters
    ----------
    decision : AimDecision
        Its ``why`` (:class:`~ctrplan.pipeline.goals.AimReason`) and ``validation`` (the robot
        file's ``[prediction_validation]``: data file, test samples, mean and largest tip errors
        of both models and the paired difference's interval [m]).

    Returns
    -------
    str
        E.g. ``on measurements (run.csv, 200 test samples) the history-aware prediction's tip
        error is mean 0.91 / max 2.10 mm against the standard model's 1.52 / 3.40 mm (mean
        difference -0.61 mm, 95 % interval -0.80..-0.42 mm)``.
    """
    why = getattr(decision.why, "value", decision.why)
    pv = decision.validation
    figures = ""
    if pv is not None:
        figures = (f"on measurements ({pv.data_file or 'unnamed data'}, {pv.test_samples} test samples) "
                   f"the history-aware prediction's tip error is mean {pv.history_mean_m * 1e3:.2f} / max "
                   f"{pv.history_max_m * 1e3:.2f} mm against the standard model's {pv.standard_mean_m * 1e3:.2f}"
                   f" / {pv.standard_max_m * 1e3:.2f} mm")
        if pv.difference_low_m is not None:
            figures += (f" (mean difference {pv.difference_mean_m * 1e3:+.2f} mm, 95 % interval "
                        f"{pv.difference_low_m * 1e3:+.2f}..{pv.difference_high_m * 1e3:+.2f} mm)")
    if why == "asked_history":
        return "[planner] aim_with = \"history\"" + (f"; {figures}" if figures else "; not validated on measurements")
    if why == "asked_standard":
        return "[planner] aim_with = \"standard\""
    if why == "not_validated":
        return ("the robot file has no [prediction_validation]: the history-aware prediction is not validated on "
                "measurements (ctrplan discrepancy writes it)")
    if why == "beats_standard":
        return figures
    return figures + ": it does not beat the standard model"
