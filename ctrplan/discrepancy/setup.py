"""Stage 1 of the discrepancy workflow: the robot, the data, the baseline and the candidate effects."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any, Mapping

from ..choices import PoseFrame
from ..effects import REGISTRY, curved_tubes, get
from ..errors import CtrplanError
from ..mechanics import ModelSettings
from .measured.data import MeasuredData, load_measured_data
from .options import DiscrepancyOptions
from .fits.parameters import REGISTRATION
from .stages import StageStore, stage_key

__all__ = ["DiscrepancySetup", "load_inputs", "default_baseline_parameters", "effect_parameters",
           "reported_parameters"]


def default_baseline_parameters(robot, register: bool) -> tuple:
    """Default baseline parameters: in-plane precurvature of every curved tube [1/m], bending
    stiffness of tubes 2..n relative to tube 1 [-] (the calibrated parameters of Tables VI and
    VII of Ha et al. 2019), and the six registration parameters [rad, m] when ``register``.

    Returns
    -------
    tuple of str
        Names in :mod:`ctrplan.discrepancy.fits.parameters`.
    """
    names = [f"precurvature_y_{i + 1}" for i in curved_tubes(robot)]
    names += [f"k_xy_relative_{i + 1}" for i in range(1, robot.n_tubes)]
    if register:
        names += list(REGISTRATION)
    return tuple(names)


def effect_parameters(robot, effect: str, data=None) -> tuple:
    """The parameters the workflow fits for ``effect`` (``Effect.fitted_names``), e.g. the
    backlash of only the drives that move in ``data``.

    Raises
    ------
    KeyError
        ``effect`` is not registered.
    """
    return get(effect).fitted_names(robot, data)


def reported_parameters(robot, effect: str, data=None) -> tuple:
    """Parameters a candidate reports as its own: its fitted ones, then those of the effect it
    follows (``Effect.after``: gradual friction carries the friction coefficients)."""
    e = get(effect)
    own = effect_parameters(robot, effect, data)
    return own + (effect_parameters(robot, e.after, data) if e.after else ())


@dataclass(frozen=True, eq=False)
class DiscrepancySetup:
    """Stage 1: what a run works on.

    Attributes
    ----------
    robot_path, data_path : pathlib.Path
        The robot model file and the measured data as given.
    out_dir : pathlib.Path
        Report folder.
    robot : Robot
        The loaded robot (lengths [m], precurvatures [1/m], angles [rad]).
    data : MeasuredData
        All measured samples (joints [rad, m], tip [m], time [s]).
    register : bool
        The data are in a tracker frame: the baseline fits a registration.
    settings : ModelSettings
        Model settings of every fit and evaluation (arc-length step ``ds`` [m], no multistart).
    base_names : tuple of str
        Baseline parameters (:mod:`ctrplan.discrepancy.fits.parameters`).
    effects : tuple of str
        Candidate effects to test and try, in registry order.
    skipped : mapping of str to str
        Requested effects that cannot be tried on this robot or data -> why.
    key : str
        Stage key (:func:`~ctrplan.discrepancy.stages.stage_key`).
    stages : StageStore
        Finished stages on disk (``out_dir/.stages``), read and written under ``key``.
    """

    robot_path: Path
    data_path: Path
    out_dir: Path
    robot: Any
    data: MeasuredData
    register: bool
    settings: ModelSettings
    base_names: tuple
    effects: tuple
    skipped: Mapping[str, str]
    key: str
    stages: StageStore


def load_inputs(robot_path, data_path, out_dir, options: DiscrepancyOptions) -> DiscrepancySetup:
    """Stage 1: read the robot and the data, and choose the baseline parameters and the effects.

    Each requested effect is tried unless its entry says why it cannot be on this robot and data
    (``Effect.requires``: e.g. friction and clearance need tube diameters, backlash a rotation
    that moves, a time offset a ``time`` column), or it follows an effect that is not tried
    (gradual friction without friction); those are listed in ``skipped`` with the reason.

    Parameters
    ----------
    robot_path : path
        Robot model file (TOML, SI units).
    data_path : path
        Measured data (:func:`~ctrplan.discrepancy.measured.data.load_measured_data`; SI units).
    out_dir : path
        Report folder.
    options : DiscrepancyOptions

    Returns
    -------
    DiscrepancySetup

    Raises
    ------
    DataFileError
        Bad data.
    ModelFileError, PhysicalParameterError
        Bad robot file.
    CtrplanError
        An unknown effect, or a baseline parameter that belongs to a candidate effect.
    """
    from ..io.robot_file import load_robot

    robot = load_robot(robot_path)
    data = load_measured_data(data_path, robot, frame=options.frame, bag=options.bag)
    register = data.frame == PoseFrame.TRACKER
    base_names = tuple(options.fit) if options.fit else default_baseline_parameters(robot, register)
    requested = tuple(options.effects) if options.effects is not None else tuple(REGISTRY)
    unknown = [e for e in requested if e not in REGISTRY]
    if unknown:
        raise CtrplanError(f"unknown effect {unknown[0]!r}; registered: {', '.join(REGISTRY)}")
    effects, skipped = [], {}
    for name in REGISTRY:
        if name not in requested:
            continue
        e = REGISTRY[name]
        why = e.why_not(robot, data)
        if why is None and e.after is not None and e.after not in effects:
            why = f"it starts from the {get(e.after).label} candidate, which is not tried"
        if why is not None:
            skipped[name] = why
            continue
        clash = set(effect_parameters(robot, name, data)) & set(base_names)
        if clash:
            raise CtrplanError(f"baseline parameters {sorted(clash)} belong to the candidate effect {name!r}; a "
                               f"parameter of a tested effect cannot be fitted in the baseline (calibration would "
                               f"absorb the effect)")
        effects.append(name)
    key = stage_key(robot_path, data_path, options)
    out_dir = Path(out_dir)
    return DiscrepancySetup(robot_path=Path(robot_path), data_path=Path(data_path), out_dir=out_dir, robot=robot,
                            data=data, register=register, settings=options.settings(), base_names=base_names,
                            effects=tuple(effects), skipped=MappingProxyType(skipped), key=key,
                            stages=StageStore(out_dir, key))
