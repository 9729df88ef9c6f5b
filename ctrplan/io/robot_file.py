"""Robot model files: TOML in SI units, parsed with pydantic, built into :class:`ctrplan.robot.Robot`.

Parsing (``tomllib`` then a pydantic schema with ``extra="forbid"`` and strict types) is separate
from building the model (:func:`robot_from_document`), as in ``pytransform3d.urdf``. The format is
documented in ``docs/file-formats.md``; the shipped files are in ``model/``.

Every key's unit is named by its suffix: ``_m`` metres, ``_rad`` radians, ``_N_m2`` N m^2,
``_per_m`` 1/m. Array indices in error keys are 1-based and count the ``[[...]]`` tables in file
order, so ``tubes[2].sections[1].length_m`` is the first section of tube 2.
"""

from __future__ import annotations

import os
import re
import tomllib
import typing
from pathlib import Path
from typing import Annotated

import pydantic
from pydantic import AfterValidator, BaseModel, ConfigDict, Field

from ..cache import file_hash
from ..calibration import CalibratedBound, PredictionValidation, RobotCalibration
from ..errors import ModelFileError, PhysicalParameterError
from ..models import MODEL_REGISTRY, MODELS, check_model
from ..robot import ROTATION, TRANSLATION, Joint, Robot, Section, TranslationLink, Tube

__all__ = ["load_robot", "load_robot_calibration", "robot_from_toml_text", "robot_from_document",
           "calibration_from_document", "robot_to_toml", "file_hash", "RobotDocument", "MODELS"]

MEMORY = "<memory>"

#: Lengths [m] above this magnitude are taken to be millimetres: a concentric tube robot and its
#: workspace are far smaller than 2 m. Shared by the robot, scenario and CSV readers.
MAX_METRES = 2.0
#: Tube diameters [m] above this are taken to be millimetres.
MAX_DIAMETER_M = 0.1

#: Joint names of the robot file and of the CSV schema: ``alpha_i`` [rad] or ``beta_i`` [m], 1-based.
JOINT_NAME = re.compile(r"^(alpha|beta)_([1-9][0-9]*)$")


class _Strict(BaseModel):
    """Base of every file schema: unknown keys, coercions and non-finite numbers are errors."""

    model_config = ConfigDict(extra="forbid", strict=True, frozen=True, allow_inf_nan=False)


PositiveFloat = Annotated[float, Field(gt=0.0)]


class SectionDoc(_Strict):
    length_m: PositiveFloat
    precurvature_per_m: Annotated[list[float], Field(min_length=2, max_length=2)]


class TubeDoc(_Strict):
    name: Annotated[str, Field(min_length=1)]
    k_xy_N_m2: PositiveFloat | None = None
    k_xy_relative: PositiveFloat | None = None
    poisson_ratio: Annotated[float, Field(gt=-1.0, le=0.5)]
    outer_diameter_m: PositiveFloat | None = None
    inner_diameter_m: PositiveFloat | None = None
    sections: Annotated[list[SectionDoc], Field(min_length=1)]


class PairDoc(_Strict):
    friction_coefficient: Annotated[float, Field(ge=0.0)]
    # Not constrained here: a non-positive clearance is a physical impossibility reported by
    # Robot with the names of both tubes.
    clearance_m: float | None = None


class HomeDoc(_Strict):
    alpha_rad: list[float]
    beta_m: list[float]


class LinkDoc(_Strict):
    follower: Annotated[int, Field(ge=1)]
    leader: Annotated[int, Field(ge=1)]
    offset_m: float


class JointDoc(_Strict):
    name: str
    lower: float
    upper: float


class RegistrationDoc(_Strict):
    """Tracker frame from robot base frame: ``p_tracker = R p_base + t``."""

    rotation_vector_rad: Annotated[list[float], Field(min_length=3, max_length=3)]
    translation_m: Annotated[list[float], Field(min_length=3, max_length=3)]


class EffectsSourceDoc(_Strict):
    """Where the values of a robot file's ``[effects]`` come from (``[effects_source]``)."""

    method: str = ""
    data_file: str = ""
    data_sha256: str = ""
    date: str = ""
    samples: Annotated[int, Field(ge=0)] | None = None
    held_out_position_mean_m: Annotated[float, Field(ge=0.0)] | None = None
    held_out_position_p95_m: Annotated[float, Field(ge=0.0)] | None = None
    held_out_position_max_m: Annotated[float, Field(ge=0.0)] | None = None
    note: str = ""
    # values written outside their typical range, each with what to check
    cautions: list[str] = []


def _registered_model(name: str) -> str:
    """``name`` if it is a registered mechanics model (read at load time: a model registered by
    the user is accepted)."""
    if name not in MODEL_REGISTRY:
        names = [repr(n) for n in MODEL_REGISTRY.names()]
        listed = ", ".join(names[:-1]) + " or " + names[-1] if len(names) > 1 else names[0]
        raise ValueError(f"should be a registered mechanics model: {listed}; got {name!r}")
    return name


class RobotDocument(_Strict):
    """Schema of a robot model file (see ``docs/file-formats.md``)."""

    name: Annotated[str, Field(min_length=1)]
    source: str = ""
    # the model the parameters were calibrated for: a name of the model registry (ctrplan.models)
    model: Annotated[str, AfterValidator(_registered_model)] | None = None
    tracker_registration: RegistrationDoc | None = None
    k_xy_reference_N_m2: PositiveFloat | None = None
    tubes: Annotated[list[TubeDoc], Field(min_length=1)]
    pairs: list[PairDoc] = []
    home: HomeDoc | None = None
    links: list[LinkDoc] = []
    joints: list[JointDoc] = []
    # effects on the motion or the measurement: {effect: {parameter key: value}}, checked against
    # the registry of ctrplan.effects once the robot is built
    effects: dict[str, dict[str, typing.Any]] = {}
    effects_source: EffectsSourceDoc | None = None
    bound_calibration: CalibratedBound | None = None   # ctrplan.calibration: the schema is the typed record
    prediction_validation: PredictionValidation | None = None


# --------------------------------------------------------------------------- error reporting
def format_key(loc: tuple, drop_tags: frozenset[str] = frozenset()) -> str:
    """Dotted key of a pydantic error location, list indices 1-based: ``tubes[2].sections[1].length_m``.

    ``drop_tags`` are discriminator values that pydantic inserts after a list index for tagged
    unions (``goals[1].task.q``); they are not keys of the file and are left out.
    """
    out = ""
    prev_int = False
    for part in loc:
        if isinstance(part, int):
            out += f"[{part + 1}]"
            prev_int = True
            continue
        if prev_int and part in drop_tags:
            prev_int = False
            continue
        out += ("." if out else "") + str(part)
        prev_int = False
    return out or "<top level>"


def _models_in(annotation) -> list[type[BaseModel]]:
    """Pydantic model classes reachable through list/Optional/Union/Annotated wrappers."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return [annotation]
    found = []
    for arg in typing.get_args(annotation):
        found.extend(_models_in(arg))
    return found


def _model_at(root: type[BaseModel], loc: tuple) -> type[BaseModel] | None:
    """Schema class holding the key at ``loc`` (its parent path), or None if not found."""
    current: list[type[BaseModel]] = [root]
    for part in loc:
        if isinstance(part, int):
            continue
        if len(current) > 1:  # tagged union: the tag value picks the variant
            tagged = [m for m in current if _tag_of(m) == part]
            if tagged:
                current = tagged
                continue
        nxt = []
        for m in current:
            if part in m.model_fields:
                nxt.extend(_models_in(m.model_fields[part].annotation))
        if not nxt:
            return None
        current = nxt
    return current[0] if len(current) == 1 else None


def _tag_of(model: type[BaseModel]):
    f = model.model_fields.get("type")
    if f is None:
        return None
    args = typing.get_args(f.annotation)
    return args[0] if args else f.default


def _describe(err: dict, root: type[BaseModel]) -> str:
    kind = err["type"]
    value = err.get("input")
    if kind == "missing":
        return "missing required key"
    if kind == "extra_forbidden":
        parent = _model_at(root, tuple(err["loc"][:-1]))
        allowed = f"; allowed keys here: {', '.join(parent.model_fields)}" if parent else ""
        return f"unknown key (value {value!r}){allowed}"
    if kind == "value_error":   # a validator's own message, which names the value
        return str(err["ctx"]["error"]) if "ctx" in err else err["msg"].removeprefix("Value error, ")
    return f"{err['msg']}; got {value!r} ({type(value).__name__})"


def validate_document(model: type[BaseModel], data: dict, file: str,
                      drop_tags: frozenset[str] = frozenset(), context: dict | None = None):
    """Validate parsed TOML against a schema, turning the first pydantic error into ModelFileError.

    ``context`` is pydantic's validation context (the scenario loader passes ``base_dir``, the
    folder that relative file names in the document are resolved against).

    Raises
    ------
    ModelFileError
        Naming the file, the dotted key and the offending value.
    """
    try:
        return model.model_validate(data, context=context)
    except pydantic.ValidationError as exc:
        errors = exc.errors(include_url=False)
        first = errors[0]
        more = f" (and {len(errors) - 1} more problem(s) in this file)" if len(errors) > 1 else ""
        raise ModelFileError(file, format_key(tuple(first["loc"]), drop_tags),
                             _describe(first, model) + more) from None


def parse_toml(text: str, file: str) -> dict:
    """Parse TOML text; syntax errors become ModelFileError with key ``<syntax>``."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ModelFileError(file, "<syntax>", f"not valid TOML: {exc}") from None


def read_text(path: str | os.PathLike) -> str:
    """Read a UTF-8 file; a missing or unreadable file raises ModelFileError."""
    try:
        return Path(path).read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ModelFileError(str(path), "<file>", "file does not exist") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ModelFileError(str(path), "<file>", f"cannot read file: {exc}") from None


# --------------------------------------------------------------------------- public API
def load_robot(path: str | os.PathLike) -> Robot:
    """Load a robot model file.

    Parameters
    ----------
    path : str or path-like
        TOML robot file (format in ``docs/file-formats.md``).

    Returns
    -------
    Robot
        In SI units. ``robot.metadata`` holds ``file`` (resolved path) and ``sha256`` (and the
        file's other tables as dicts; planning reads ``[bound_calibration]`` and
        ``[prediction_validation]`` through :func:`load_robot_calibration`).

    Raises
    ------
    ModelFileError
        Unreadable file, TOML syntax error, unknown or missing key, wrong type or bad value;
        names the file, the dotted key and the value.
    PhysicalParameterError
        Physically impossible tubes (e.g. non-positive clearance, inner diameter not below the
        outer diameter); the message starts with the file name and names the tubes.
    """
    return _load_robot_file(path)[0]


def load_robot_calibration(path: str | os.PathLike) -> RobotCalibration:
    """What a robot model file records about measurements: its ``[bound_calibration]`` and
    ``[prediction_validation]`` tables as typed objects (``ctrplan discrepancy`` writes them).

    Parameters
    ----------
    path : str or path-like
        TOML robot file.

    Returns
    -------
    RobotCalibration
        Each table, or None where the file has none.

    Raises
    ------
    ModelFileError, PhysicalParameterError
        As :func:`load_robot` (the whole file is checked).
    """
    return _load_robot_file(path)[1]


def _load_robot_file(path) -> tuple[Robot, RobotCalibration]:
    """The robot of a robot file and its records of measurements, from one reading of the file."""
    path = Path(path)
    doc = validate_document(RobotDocument, parse_toml(read_text(path), str(path)), str(path))
    robot = robot_from_document(doc, str(path))
    robot.metadata.update(file=str(path.resolve()), sha256=file_hash(path))
    return robot, calibration_from_document(doc)


def calibration_from_document(doc: RobotDocument) -> RobotCalibration:
    """The ``[bound_calibration]`` and ``[prediction_validation]`` tables of a validated robot
    document as typed objects (SI units, as in the file).

    Parameters
    ----------
    doc : RobotDocument

    Returns
    -------
    RobotCalibration
    """
    return RobotCalibration(bound=doc.bound_calibration, prediction=doc.prediction_validation)


def robot_from_toml_text(text: str, file: str = MEMORY) -> Robot:
    """Build a robot from the text of a robot model file.

    Parameters
    ----------
    text : str
        TOML text.
    file : str
        Name used in error messages.

    Returns
    -------
    Robot

    Raises
    ------
    ModelFileError, PhysicalParameterError
        As :func:`load_robot`.
    """
    doc = validate_document(RobotDocument, parse_toml(text, file), file)
    return robot_from_document(doc, file)


def robot_from_document(doc: RobotDocument, file: str = MEMORY) -> Robot:
    """Build a :class:`Robot` from a validated document (cross-key checks happen here).

    Raises
    ------
    ModelFileError, PhysicalParameterError
        As :func:`load_robot`.
    """
    n = len(doc.tubes)
    tubes = tuple(_build_tube(doc, i, file) for i in range(n))

    if len(doc.pairs) != n - 1:
        raise ModelFileError(file, "pairs", f"needs one [[pairs]] table per adjacent tube pair, i.e. "
                                            f"{n - 1} for {n} tubes; got {len(doc.pairs)}")
    friction = tuple(p.friction_coefficient for p in doc.pairs)
    given = [p.clearance_m is not None for p in doc.pairs]
    if any(given) and not all(given):
        missing = given.index(False) + 1
        raise ModelFileError(file, f"pairs[{missing}].clearance_m",
                             "give clearance_m for every pair or for none (then it comes from the "
                             "diameters)")
    clearances = tuple(p.clearance_m for p in doc.pairs) if all(given) and n > 1 else None

    if doc.home is None:
        home_alpha, home_beta = (0.0,) * n, (0.0,) * n
    else:
        for key, seq in (("home.alpha_rad", doc.home.alpha_rad), ("home.beta_m", doc.home.beta_m)):
            if len(seq) != n:
                raise ModelFileError(file, key, f"needs {n} values (one per tube), got {seq!r}")
        if max(abs(b) for b in doc.home.beta_m) > MAX_METRES:
            raise ModelFileError(file, "home.beta_m",
                                 f"{doc.home.beta_m!r} looks like millimetres; beta is in metres")
        home_alpha, home_beta = tuple(doc.home.alpha_rad), tuple(doc.home.beta_m)

    links = []
    for k, link in enumerate(doc.links, start=1):
        for key in ("follower", "leader"):
            v = getattr(link, key)
            if v > n:
                raise ModelFileError(file, f"links[{k}].{key}",
                                     f"tube number {v} does not exist (tubes are numbered 1..{n})")
        links.append(TranslationLink(follower=link.follower - 1, leader=link.leader - 1,
                                     offset=link.offset_m))

    joints = []
    for k, jd in enumerate(doc.joints, start=1):
        m = JOINT_NAME.match(jd.name)
        if m is None or int(m.group(2)) > n:
            raise ModelFileError(file, f"joints[{k}].name",
                                 f"{jd.name!r} is not a joint name: expected alpha_i (rotation, rad) "
                                 f"or beta_i (translation, m) with i in 1..{n}")
        if not jd.lower < jd.upper:
            raise ModelFileError(file, f"joints[{k}].upper",
                                 f"lower limit {jd.lower!r} must be below upper limit {jd.upper!r}")
        kind = ROTATION if m.group(1) == "alpha" else TRANSLATION
        if kind == TRANSLATION and max(abs(jd.lower), abs(jd.upper)) > MAX_METRES:
            raise ModelFileError(file, f"joints[{k}]",
                                 f"limits [{jd.lower!r}, {jd.upper!r}] look like millimetres; "
                                 f"translations are in metres")
        joints.append(Joint(kind=kind, tube=int(m.group(2)) - 1, lower=jd.lower, upper=jd.upper))

    try:
        robot = Robot(name=doc.name, tubes=tubes, friction_coefficients=friction,
                      joints=tuple(joints), home_alpha=home_alpha, home_beta=home_beta,
                      links=tuple(links), source=doc.source, clearances_override=clearances,
                      metadata={"file": file,
                               "k_xy_reference_N_m2": doc.k_xy_reference_N_m2,
                               "model": doc.model,
                               "tracker_registration": (
                                   None if doc.tracker_registration is None else
                                   {"rotation_vector_rad": list(doc.tracker_registration.rotation_vector_rad),
                                    "translation_m": list(doc.tracker_registration.translation_m)}),
                                "effects_source": (None if doc.effects_source is None
                                                   else doc.effects_source.model_dump()),
                                "bound_calibration": (None if doc.bound_calibration is None
                                                      else doc.bound_calibration.model_dump()),
                                "prediction_validation": (None if doc.prediction_validation is None
                                                          else doc.prediction_validation.model_dump())})
    except PhysicalParameterError as exc:
        hint = ""
        if clearances is not None:
            hint = f" (clearances set by [[pairs]] clearance_m = {list(clearances)!r} m)"
        raise PhysicalParameterError(f"{file}: {exc}{hint}") from exc
    if doc.effects:
        from ..effects import effects_from_file

        robot = robot.replace(effects=effects_from_file(robot, doc.effects, file))
    elif doc.effects_source is not None:
        raise ModelFileError(file, "effects_source", "describes the source of [effects], but the file has none")
    return robot


def _build_tube(doc: RobotDocument, i: int, file: str) -> Tube:
    td = doc.tubes[i]
    key = f"tubes[{i + 1}]"
    if (td.k_xy_N_m2 is None) == (td.k_xy_relative is None):
        raise ModelFileError(file, f"{key}.k_xy_N_m2",
                             "give exactly one of k_xy_N_m2 [N m^2] and k_xy_relative [-]; got "
                             f"k_xy_N_m2={td.k_xy_N_m2!r}, k_xy_relative={td.k_xy_relative!r}")
    if td.k_xy_relative is not None:
        if doc.k_xy_reference_N_m2 is None:
            raise ModelFileError(file, "k_xy_reference_N_m2",
                                 f"missing required key: {key}.k_xy_relative needs the top-level "
                                 f"k_xy_reference_N_m2 [N m^2]")
        k_xy = td.k_xy_relative * doc.k_xy_reference_N_m2
    else:
        k_xy = td.k_xy_N_m2
    for dkey in ("outer_diameter_m", "inner_diameter_m"):
        v = getattr(td, dkey)
        if v is not None and v > MAX_DIAMETER_M:
            raise ModelFileError(file, f"{key}.{dkey}",
                                 f"{v!r} m looks like millimetres; diameters are in metres")
    sections = []
    for j, sd in enumerate(td.sections, start=1):
        if sd.length_m > MAX_METRES:
            raise ModelFileError(file, f"{key}.sections[{j}].length_m",
                                 f"{sd.length_m!r} m looks like millimetres; lengths are in metres")
        sections.append(Section(length=sd.length_m,
                                precurvature=(float(sd.precurvature_per_m[0]),
                                              float(sd.precurvature_per_m[1]))))
    try:
        return Tube(name=td.name, sections=tuple(sections), k_xy=k_xy,
                    poisson_ratio=td.poisson_ratio, outer_diameter=td.outer_diameter_m,
                    inner_diameter=td.inner_diameter_m)
    except PhysicalParameterError as exc:
        raise PhysicalParameterError(f"{file}: {exc}") from exc


# --------------------------------------------------------------------------- writer
def _num(x: float) -> str:
    return repr(float(x))


def _vec(v) -> str:
    return "[" + ", ".join(_num(x) for x in v) + "]"


def robot_to_toml(robot: Robot, *, header: str = "", model: str | None = None,
                  registration: dict | None = None, effects_source: dict | None = None,
                  bound_calibration: dict | None = None, prediction_validation: dict | None = None) -> str:
    """Write a robot as the text of a robot model file (the inverse of :func:`robot_from_toml_text`).

    Stiffnesses are written as absolute ``k_xy_N_m2``; clearances as ``clearance_m`` only when
    the robot overrides the diameters. ``robot_from_toml_text(robot_to_toml(r))`` equals ``r``
    (floats are written with ``repr``, so they round-trip exactly).

    Parameters
    ----------
    robot : Robot
    header : str
        Comment lines put at the top (each line is prefixed with ``# ``), e.g. where the
        parameters come from.
    model : {"standard", "clearance", "friction"}, optional
        The mechanics model the parameters were calibrated for (top-level ``model`` key).
    registration : dict, optional
        ``{"rotation_vector_rad": (3,), "translation_m": (3,)}``: tracker frame from robot base
        frame, ``p_tracker = R p_base + t`` (table ``[tracker_registration]``).
    effects_source : dict, optional
        Where ``robot.effects`` come from (table ``[effects_source]``: ``method``,
        ``data_file``, ``data_sha256``, ``date``, ``samples``, ``held_out_position_mean_m``,
        ``held_out_position_p95_m``, ``held_out_position_max_m``, ``note``, ``cautions``: a list of
        strings).
    bound_calibration : dict, optional
        Table ``[bound_calibration]`` (:class:`ctrplan.calibration.CalibratedBound`).
    prediction_validation : dict, optional
        Table ``[prediction_validation]`` (:class:`ctrplan.calibration.PredictionValidation`).

    Returns
    -------
    str

    Raises
    ------
    ValueError
        ``model`` not one of :data:`ctrplan.models.MODELS`.
    """
    if model is not None:
        check_model(model)
    out = [f"# {line}".rstrip() for line in header.splitlines()] if header else []
    out.append("# ctrplan robot model file. Units: SI (m, rad, N m^2); key suffixes name the unit.")
    out.append(f"name = {_toml_str(robot.name)}")
    out.append(f"source = {_toml_str(robot.source)}")
    if model is not None:
        out.append(f'model = "{model}"')
    for tube in robot.tubes:
        out += ["", "[[tubes]]", f"name = {_toml_str(tube.name)}", f"k_xy_N_m2 = {_num(tube.k_xy)}",
                f"poisson_ratio = {_num(tube.poisson_ratio)}"]
        if tube.outer_diameter is not None:
            out.append(f"outer_diameter_m = {_num(tube.outer_diameter)}")
        if tube.inner_diameter is not None:
            out.append(f"inner_diameter_m = {_num(tube.inner_diameter)}")
        for sec in tube.sections:
            out += ["[[tubes.sections]]", f"length_m = {_num(sec.length)}",
                    f"precurvature_per_m = {_vec(sec.precurvature)}"]
    for k, mu in enumerate(robot.friction_coefficients):
        out += ["", f"[[pairs]]                          # tubes {k + 1}-{k + 2}",
                f"friction_coefficient = {_num(mu)}"]
        if robot.clearances_override is not None:
            out.append(f"clearance_m = {_num(robot.clearances_override[k])}")
    out += ["", "[home]", f"alpha_rad = {_vec(robot.home_alpha)}", f"beta_m = {_vec(robot.home_beta)}"]
    for link in robot.links:
        out += ["", "[[links]]", f"follower = {link.follower + 1}", f"leader = {link.leader + 1}",
                f"offset_m = {_num(link.offset)}"]
    for j in robot.joints:
        out += ["", "[[joints]]", f'name = "{j.name}"', f"lower = {_num(j.lower)}", f"upper = {_num(j.upper)}"]
    if registration is not None:
        out += ["", "[tracker_registration]                # p_tracker = R(rotation_vector) p_base + t",
                f"rotation_vector_rad = {_vec(registration['rotation_vector_rad'])}",
                f"translation_m = {_vec(registration['translation_m'])}"]
    if robot.effects:
        from ..effects import effects_to_file

        out += effects_to_file(robot)
        if effects_source:
            out += ["", "[effects_source]"]
            for key, value in effects_source.items():
                if value is None:
                    continue
                if isinstance(value, str):
                    text = _toml_str(value)
                elif isinstance(value, (list, tuple)):
                    text = "[" + ", ".join(_toml_str(v) if isinstance(v, str) else repr(v) for v in value) + "]"
                else:
                    text = repr(value)
                out.append(f"{key} = {text}")
    for table, values in (("bound_calibration", bound_calibration), ("prediction_validation", prediction_validation)):
        if values:
            out += ["", f"[{table}]"]
            for key, value in values.items():
                if value is None:
                    continue
                if isinstance(value, bool):
                    text = "true" if value else "false"
                elif isinstance(value, str):
                    text = _toml_str(value)
                else:
                    text = repr(float(value)) if isinstance(value, float) else repr(value)
                out.append(f"{key} = {text}")
    return "\n".join(out) + "\n"


def _toml_str(text: str) -> str:
    return '"' + str(text).replace("\\", "\\\\").replace('"', '\\"') + '"'
