"""Motion history: one model of how a recorded or planned motion sets the friction state.

The friction of a tube pair depends on the pair's last relative rotation and on whether a
translation followed it (Ha, Fagogenis & Dupont, IEEE T-RO 35(2) 2019, Eqs. (38)-(39) and
Section V-B, doi:10.1109/TRO.2018.2878906). Measured data (``ctrplan.discrepancy``), the
history-aware prediction (:func:`ctrplan.mechanics.predict_tip`) and planning
(``ctrplan.planning``) all read it from here:

- :class:`MotionRecord`: joint values in time order, in one or more continuous motions;
- :func:`motion_state` -> :class:`HistoryState`: per sample and pair the direction eta, the
  release by a translation, and the (gradually developing) friction state; :class:`PairState`
  for one configuration and :func:`pair_friction`, the friction it applies;
- operators that change a record into what the tubes did or what the tracker saw:
  :func:`play` (drive backlash), :func:`time_shift` (tracker time offset; :func:`joints_at`, the
  smooth interpolant it reads the record with), and
  :func:`apply_history`, which applies a set of them and reads the state along the result;
- :func:`rotation_directions`, :func:`drive_directions`, :func:`rotation_since_reversal`.

Pure numerics: arrays and frozen dataclasses, SI units (rad, m, s).
"""

from ._apply import STAGES, HistoryOperator, apply_history
from ._operators import joints_at, play, play_side, time_shift
from ._record import MotionRecord, sequence_segments
from ._state import (PAIR_CASES, HistoryState, PairState, drive_directions, motion_state, pair_friction,
                     rotation_directions, rotation_since_reversal)

__all__ = ["MotionRecord", "sequence_segments", "HistoryState", "PairState", "PAIR_CASES", "motion_state",
           "pair_friction", "rotation_directions", "drive_directions", "rotation_since_reversal", "play",
           "play_side", "time_shift", "joints_at", "HistoryOperator", "STAGES", "apply_history"]
