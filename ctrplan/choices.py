"""The choices of ctrplan's files and functions, as string enums.

Each choice is a :class:`enum.StrEnum`: a member *is* the string written in files and on the
command line (``JointKind.ROTATION == "rotation"``, ``json.dumps`` writes ``"rotation"``), so the
file formats are those of the strings, and code that compares, hashes or formats a member gets
the string's result. Functions accept either the member or its string; loaders turn a file's
string into the member and refuse any other with the choices listed.

This module imports nothing from the package, so that every layer can use it.
"""

from __future__ import annotations

from enum import StrEnum

__all__ = ["JointKind", "MotionKind", "FinalMotion", "BoundKind", "AimWith", "MapPlacement", "FirstPlan",
           "MapSource", "BagStorage", "RosDistro", "TangentAxis", "DesignMode", "PoseFrame", "ProtocolKind", "Verdict",
           "NoEffectCase", "SplitUnit", "EffectStore", "NotNamedReason", "DecisionNoteKind", "CautionKind",
           "NotPairedReason", "FitNoteKind", "BufferReason", "BlocksKept"]


class JointKind(StrEnum):
    """What a joint moves: a tube base's rotation alpha [rad] or its translation beta [m]; also
    the kind of a bound-map coordinate (a relative rotation or translation)."""

    ROTATION = "rotation"
    TRANSLATION = "translation"


class MotionKind(StrEnum):
    """The motion that reaches a waypoint of an ordered path: the start, a rotation phase (the
    rotation joints move, the translations hold) or a translation phase."""

    START = "start"
    ROTATION = "rotation"
    TRANSLATION = "translation"


class FinalMotion(StrEnum):
    """How the motion that reaches a goal ends (``[planner] final_motion``): with its translations
    (rotations first, the paper's order: the final translation releases most friction-induced
    twist, Section V-B of Ha et al. 2019) or with its rotations."""

    TRANSLATION_LAST = "translation-last"
    ROTATION_LAST = "rotation-last"

    @property
    def last(self) -> MotionKind:
        """The phase that ends the motion."""
        return MotionKind.TRANSLATION if self is FinalMotion.TRANSLATION_LAST else MotionKind.ROTATION


class BoundKind(StrEnum):
    """Which error bound holds at a waypoint: the friction bound (after a rotation or at the
    start; Section III of Ha et al. 2019) or the smaller bound after a final translation."""

    FRICTION = "friction"
    TRANSLATION_LAST = "translation_last"


class AimWith(StrEnum):
    """How task-space goals are aimed (``[planner] aim_with``): by the robot file's
    validation (``auto``), always with the history-aware prediction, or with the standard model."""

    AUTO = "auto"
    HISTORY = "history"
    STANDARD = "standard"


class MapPlacement(StrEnum):
    """Where a bound map puts its nodes along each coordinate: evenly, or denser where the bound
    bends (pilot lines)."""

    UNIFORM = "uniform"
    ADAPTIVE = "adaptive"


class FirstPlan(StrEnum):
    """What a robot without a map plans with first (``[bound_field] first_plan``): the preview map
    refined where the plan goes, or the full map."""

    PREVIEW = "preview"
    FULL = "full"


class MapSource(StrEnum):
    """Where a plan's bound map came from: shipped beside the robot file, the cache folder,
    computed for this plan, or given by the caller."""

    SHIPPED = "shipped"
    CACHE = "cache"
    COMPUTED = "computed"
    GIVEN = "given"


class BagStorage(StrEnum):
    """The storage plugin of a written ROS 2 bag."""

    MCAP = "mcap"
    SQLITE3 = "sqlite3"


class RosDistro(StrEnum):
    """The ROS 2 distribution whose message definitions a written bag carries (``rosbags``
    typestores)."""

    HUMBLE = "humble"
    JAZZY = "jazzy"


class TangentAxis(StrEnum):
    """The axis of a tracker pose's orientation that is the tip tangent; ``none``: positions only."""

    X = "x"
    Y = "y"
    Z = "z"
    NONE = "none"


class DesignMode(StrEnum):
    """What a designed experiment is for: separating two or more hypotheses (T-optimality) or
    determining the parameters of one (Ds-optimality)."""

    SEPARATE = "separate"
    PARAMETERS = "parameters"


class ProtocolKind(StrEnum):
    """Where synthetic data are sampled: the paper's grid of configurations, each approached
    from every relative rotation direction (Section V-C of Ha et al. 2019), or a seeded
    continuous trajectory like Ha's measured one."""

    PAPER = "paper"
    TRAJECTORY = "trajectory"


class PoseFrame(StrEnum):
    """The frame tip poses are given in: the robot's base frame, or the tracker's (through the
    robot file's tracker registration)."""

    ROBOT = "robot"
    TRACKER = "tracker"


class Verdict(StrEnum):
    """What the discrepancy workflow concludes: one effect named, two that explain the data
    equally well (ambiguous), or none."""

    NAMED = "named"
    AMBIGUOUS = "ambiguous"
    NONE = "none"


class NoEffectCase(StrEnum):
    """Why the discrepancy workflow named no effect, by its noise test: the residual is
    consistent with the sensor noise, it is not (unexplained), it is not but the noise is only a
    lower bound (inconclusive), or no noise is known."""

    NOISE = "noise"
    UNEXPLAINED = "unexplained"
    INCONCLUSIVE = "inconclusive"
    UNKNOWN = "unknown"


class SplitUnit(StrEnum):
    """The units a discrepancy split never cuts: contiguous time blocks of a motion, or groups of
    samples at one configuration."""

    TIME_BLOCK = "time block"
    CONFIGURATION_GROUP = "configuration group"


class EffectStore(StrEnum):
    """Where a robot file keeps an effect's values: in the tube and pair tables (the effect
    changes the robot itself), in the ``[effects]`` table, or in ``[tracker_registration]``."""

    ROBOT = "robot"
    EFFECTS = "effects"
    REGISTRATION = "registration"


class NotNamedReason(StrEnum):
    """Why the discrepancy workflow may not name a candidate effect: its improvement over the
    baseline is not significant within the Holm family, another candidate's out-of-fold error is
    significantly lower, a value sits at a limit it could not widen, or a fit of the baseline it
    is compared with stopped at its evaluation budget before converging."""

    NOT_SIGNIFICANT = "not significant"
    OUTPERFORMED = "outperformed"
    AT_LIMIT = "at limit"
    BASELINE_UNFINISHED = "baseline unfinished"


class DecisionNoteKind(StrEnum):
    """What a note of the discrepancy verdict records: a candidate that improves significantly
    but is not named, a containing candidate passed over for the simpler one it contains, an
    ambiguous pair (two eligible candidates, or two whose fitted tip displacement fields the
    recorded motion cannot separate), a best explanation that cannot be named, or two effects
    named together that neither could be alone."""

    SIGNIFICANT_NOT_NAMED = "significant, not named"
    SIMPLER_NAMED = "simpler named"
    AMBIGUOUS = "ambiguous"
    NOT_SEPARABLE = "not separable"
    BEST_NOT_NAMED = "best, not named"
    NAMED_JOINTLY = "named jointly"


class CautionKind(StrEnum):
    """What a caution of the discrepancy workflow flags: a named value outside its typical range,
    a test-split maximum error that rises while the mean falls, or a baseline parameter outside its
    typical range or at its bound."""

    ATYPICAL_VALUE = "atypical value"
    MAXIMUM_RISES = "maximum rises"
    BASELINE_PARAMETER = "baseline parameter"


class NotPairedReason(StrEnum):
    """Why the discrepancy workflow does not fit a candidate together with the named effect: one
    contains the other, it is fitted on top of a third effect, it adds no parameter, or alone it
    does not lower the baseline's out-of-fold error (it is then counted in the pairs' Holm family)."""

    CONTAINS = "contains"
    CONTAINED = "contained"
    ON_A_THIRD_EFFECT = "on a third effect"
    ADDS_NO_PARAMETER = "adds no parameter"
    NO_IMPROVEMENT_ALONE = "no improvement alone"


class BufferReason(StrEnum):
    """Why the discrepancy workflow's buffer has the length it has: configuration groups need
    none, the residuals' autocorrelation falls to its threshold within half a block, or the buffer
    is capped at half a block with the autocorrelation still above it."""

    CONFIGURATION_GROUPS = "configuration groups"
    AUTOCORRELATION_FALLS = "autocorrelation falls"
    HALF_A_BLOCK = "half a block"


class BlocksKept(StrEnum):
    """Why the development blocks were not lengthened for a buffer capped at half a block: the
    blocks were asked for, or longer ones would cut across test blocks or break a minimum."""

    ASKED = "asked"
    MINIMUMS = "minimums"


class FitNoteKind(StrEnum):
    """What a discrepancy candidate's fits say about themselves: the clearance-model refit it
    shares stopped at its budget, a fit stopped at its budget, a value at its limit, a fit worse on
    the calibration data than the baseline it contains or than the standard baseline, a fit better
    there but worse out of fold (overfitting), or a pair's fit not converged or at its limit."""

    CONTACT_REFIT_NOT_CONVERGED = "contact refit not converged"
    NOT_CONVERGED = "not converged"
    AT_LIMIT = "at limit"
    WORSE_THAN_CONTAINED_BASELINE = "worse than the baseline it contains"
    WORSE_THAN_STANDARD_BASELINE = "worse than the standard baseline"
    OVERFITS = "overfits"
    PAIR_NOT_CONVERGED = "pair not converged"
