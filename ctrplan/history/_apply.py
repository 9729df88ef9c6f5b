"""Composition of history effects: the motion the tubes made, then the friction state along it."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from ..constants import HISTORY_ROTATION_TOL, HISTORY_TRANSLATION_TOL
from ._record import MotionRecord
from ._state import HistoryState, motion_state

__all__ = ["HistoryOperator", "STAGES", "apply_history"]

#: Where an operator acts, in the order they are applied: ``"drive"`` changes what the tubes do
#: (backlash), ``"tracker"`` what a measurement shows of it (a time offset). Planning applies
#: only the drive stage.
STAGES = ("drive", "tracker")


@dataclass(frozen=True)
class HistoryOperator:
    """One effect on a motion record.

    Attributes
    ----------
    name : str
        The effect it comes from (for messages).
    stage : {"drive", "tracker"}
        See :data:`STAGES`.
    apply : callable
        ``apply(record: MotionRecord) -> MotionRecord``, run over the whole record (every
        continuous motion from its start).
    """

    name: str
    stage: str
    apply: Callable[[MotionRecord], MotionRecord]

    def __post_init__(self):
        if self.stage not in STAGES:
            raise ValueError(f"history operator {self.name!r}: stage must be one of {STAGES}, got {self.stage!r}")


def apply_history(record: MotionRecord, operators=(), *, friction_angle: float = 0.0, tracker: bool = True,
                  given_eta=None, rotation_tol: float = HISTORY_ROTATION_TOL,
                  translation_tol: float = HISTORY_TRANSLATION_TOL) -> HistoryState:
    """Apply a set of history effects to a commanded motion and read the friction state along it.

    Drive operators first (in the order given), then, with ``tracker``, the tracker operators;
    then :func:`~ctrplan.history.motion_state` on the resulting motion with the friction angle
    of gradually developing friction.

    Parameters
    ----------
    record : MotionRecord
        The commanded (encoder or planned) motion [rad, m].
    operators : sequence of HistoryOperator
    friction_angle : float
        theta_c [rad], >= 0 (0: the paper's abrupt friction switch).
    tracker : bool
        Apply the tracker stage (True for measured data; planning predicts the robot, not a
        tracker, and passes False).
    given_eta : array-like of int, shape (K, n - 1), optional
        Approach directions before the record (:func:`~ctrplan.history.motion_state`).
    rotation_tol, translation_tol : float
        [rad], [m] (:func:`~ctrplan.history.motion_state`).

    Returns
    -------
    HistoryState
        Configurations the tubes reach (``alpha``, ``beta``), their offsets from the commanded
        ones, and eta, release and friction state per pair.

    Raises
    ------
    ValueError
        From an operator (e.g. a time offset without times) or :func:`motion_state`.
    """
    seen = record
    for stage in STAGES:
        if stage == "tracker" and not tracker:
            continue
        for op in operators:
            if op.stage == stage:
                seen = op.apply(seen)
    return motion_state(record, seen, friction_angle=friction_angle, given_eta=given_eta,
                        rotation_tol=rotation_tol, translation_tol=translation_tol)
