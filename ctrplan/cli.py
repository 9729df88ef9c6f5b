"""Command line: ``ctrplan evaluate``, ``ctrplan plan``, ``ctrplan boundmap``.

A thin layer over the library: it reads files, sets one BLAS thread per process (the dense
solves here are small; more threads only oversubscribe the cores), calls the numerics and
writes outputs atomically.

It also shows the library's messages: for the length of a command, the ``ctrplan`` logger gets a
handler that prints each message as a plain line on standard output, at INFO (progress lines and
summaries, and cautions), WARNING with ``--quiet`` (cautions only, and no progress bars) or DEBUG
with ``--verbose``.
"""

from __future__ import annotations

import logging
import os
import shlex
import sys
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MPLBACKEND", "Agg")

import click  # noqa: E402

from .choices import BagStorage, MapPlacement, PoseFrame, ProtocolKind, RosDistro, TangentAxis
from .errors import CtrplanError, JointLimitError  # noqa: E402
from .models import MODEL_INFO, MODELS  # noqa: E402

def _choice(choices) -> click.Choice:
    """The strings of a :mod:`ctrplan.choices` enum as a click choice (click would list the names)."""
    return click.Choice([m.value for m in choices])


logger = logging.getLogger("ctrplan.cli")   # by name: the same logger under ``python -m ctrplan.cli``


class _ConsoleHandler(logging.Handler):
    """Each record's message as a plain line on standard output (``click.echo``: the stream of the
    moment, so a test runner's capture sees it)."""

    def emit(self, record):
        try:
            click.echo(self.format(record))
        except Exception:  # noqa: BLE001 - logging's own convention: report, never raise
            self.handleError(record)


def _show_messages(ctx: click.Context, level: int) -> None:
    """Print the ``ctrplan`` logger's messages from ``level`` up until the command ends."""
    package = logging.getLogger("ctrplan")
    handler, previous = _ConsoleHandler(), package.level
    package.addHandler(handler)
    package.setLevel(level)

    def restore():
        package.removeHandler(handler)
        package.setLevel(previous)

    ctx.call_on_close(restore)


def _progress(no_progress: bool = False) -> bool:
    """Progress bars: unless ``--no-progress``, or ``--quiet`` (INFO messages not shown)."""
    return not no_progress and logging.getLogger("ctrplan").isEnabledFor(logging.INFO)


def _settings(ds):
    from .mechanics import ModelSettings

    return ModelSettings() if ds is None else ModelSettings(ds=ds)


def _limit_threads():
    try:
        from threadpoolctl import threadpool_limits

        threadpool_limits(1)
    except ImportError:  # pragma: no cover
        pass


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="ctrplan")
@click.option("-q", "--quiet", is_flag=True,
              help="Print only warnings and errors: no progress lines, summaries or progress bars.")
@click.option("-v", "--verbose", is_flag=True, help="Also print details (debug messages).")
@click.pass_context
def main(ctx, quiet, verbose):
    """Friction-bounded motion planning for concentric tube robots.

    Mechanics from Ha, Fagogenis & Dupont, IEEE T-RO 35(2) 2019, doi:10.1109/TRO.2018.2878906.
    """
    if quiet and verbose:
        raise click.UsageError("--quiet and --verbose exclude each other")
    _show_messages(ctx, logging.WARNING if quiet else logging.DEBUG if verbose else logging.INFO)
    _limit_threads()


@main.command()
@click.option("--robot", "robot_path", required=True, type=click.Path(exists=True, dir_okay=False),
              help="Robot model file (TOML, SI units).")
@click.option("--configs", "configs_path", required=True, type=click.Path(exists=True, dir_okay=False),
              help="CSV with alpha_1..n [rad], beta_1..n [m] and optionally eta_1..n-1.")
@click.option("--model", type=click.Choice(list(MODELS)), required=True)
@click.option("--out", "out_path", type=click.Path(dir_okay=False), default=None,
              help="Output CSV (default: <configs>-<model>.csv).")
@click.option("--ds", type=float, default=None, help="Arc-length step [m] (default 0.003).")
@click.option("--jobs", type=int, default=None,
              help="Parallel workers (default: all cores): worker processes for the contact models, "
                   "compiled threads for the standard model.")
@click.option("--no-progress", is_flag=True, help="Hide the progress bar.")
@click.option("--explain-failures", is_flag=True,
              help="Friction model: follow each friction solution that did not converge in mu from the "
                   "clearance solution, and say in its message whether it snaps under friction (its branch "
                   "ends at a fold below mu) or the solver failed. About 15 extra solves per such row.")
def evaluate(robot_path, configs_path, model, out_path, ds, jobs, no_progress, explain_failures):
    """Evaluate a model at every configuration of a CSV.

    One output row per configuration, and per friction direction eta for the friction model
    (all 2^(n-1) unless the input gives eta). Interrupted runs resume from
    <out>.partial.jsonl.
    """
    from .batch import evaluate_table, job_key
    from .io.robot_file import load_robot
    from .io.tables import read_configurations, write_table

    if explain_failures and not MODEL_INFO[model].friction:
        raise click.UsageError(f"--explain-failures applies to --model friction only, not {model!r}")
    robot = load_robot(robot_path)
    if MODEL_INFO[model].contact:
        from .mechanics import warmup
        warmup.start()   # on a cold start, the contact kernels compile beside the standard model's
    alpha, beta, eta, _ = read_configurations(configs_path, robot.n_tubes)
    import numpy as np

    # one vectorized test of all rows (same tests and tolerances); failing rows are re-checked
    # one by one for the message (a check per row took ~5 % of a standard-model run)
    for k in np.flatnonzero(~robot.configurations_possible(alpha, beta)):
        try:
            robot.check_configuration(alpha[k], beta[k])
        except CtrplanError as exc:
            raise JointLimitError(f"{configs_path}: row {k + 1}: {exc}") from None
    settings = _settings(ds)
    out = Path(out_path) if out_path else Path(configs_path).with_name(Path(configs_path).stem + f"-{model}.csv")
    key = job_key(Path(robot_path).read_text(), Path(configs_path).read_text(), model, settings,
                  explain_failures)
    ck = out.with_name(out.name + ".partial.jsonl")
    frame = evaluate_table(robot, alpha, beta, model, settings, eta, n_jobs=jobs or os.cpu_count() or 1,
                           checkpoint=ck, progress=_progress(no_progress), job_key=key,
                           explain_failures=explain_failures)
    write_table(out, frame)
    ck.unlink(missing_ok=True)
    bad = frame[frame["status"] != "ok"]
    logger.info(f"wrote {len(frame)} rows to {out} ({len(bad)} not ok)")
    if len(bad):
        for _, r in bad.head(10).iterrows():
            logger.info(f"  row {int(r['row'])}: {r['status']}: {r['message']}")


@main.command("plan")
@click.argument("scenario_paths", nargs=-1, required=True, type=click.Path(exists=True))
@click.option("--out", "out_dir", type=click.Path(file_okay=False), default=None,
              help="Output folder (one scenario: default its [output] dir or out/<name>; several: the root of "
                   "one folder per scenario and the table scenarios.csv, default out/scenarios).")
@click.option("--jobs", type=int, default=None,
              help="One scenario: worker processes for a bound map (default: all cores). Several: scenarios "
                   "planned at once on that many local worker processes (default 1: in this process).")
@click.option("--scheduler", default=None,
              help="Several scenarios: address of a running dask.distributed scheduler (e.g. tcp://host:8786); "
                   "its workers need ctrplan installed.")
@click.option("--iterations", type=int, default=None, help="Override the planner's iteration budget.")
@click.option("--no-blind", is_flag=True, help="Skip the bound-blind comparison plan.")
@click.option("--ros2", "ros2_out", type=click.Path(file_okay=False), default=None,
              help="One scenario: also write the plan as a ROS 2 bag in this folder (joint trajectory, tip path, "
                   "bound spheres) and joint_trajectory.yaml for `ros2 topic pub` in the output folder.")
@click.option("--ros2-storage", type=_choice(BagStorage), default=BagStorage.MCAP.value, show_default=True)
@click.option("--ros2-distro", type=_choice(RosDistro), default=RosDistro.JAZZY.value, show_default=True,
              help="Message definitions written into the bag (visualization_msgs/msg/Marker differs).")
@click.option("--ros2-frame", default="ctr_base", show_default=True,
              help="frame_id of the tip path and the bound spheres (the robot's base frame).")
@click.option("--no-full-map", is_flag=True,
              help="One scenario planned with a preview map (its robot has no map yet): do not compute the full "
                   "map after the plan (a later run computes it).")
def plan_command(scenario_paths, out_dir, jobs, scheduler, iterations, no_blind, ros2_out, ros2_storage, ros2_distro,
         ros2_frame, no_full_map):
    """Plan a friction-bound-aware motion for a scenario and write the drive trajectory.

    Several scenario files or folders of them are planned in one process (or spread over local
    worker processes or Dask workers), each into its own folder, with one table across them; a rerun reuses the complete
    outputs of unchanged scenarios.

    A robot without a shipped or cached bound map is planned with a coarse preview map refined
    where the plan goes; with one scenario, the full map is then computed (resumably: interrupt
    it and the next run goes on), so that later plans read it.
    """
    single = len(scenario_paths) == 1 and Path(scenario_paths[0]).is_file() and scheduler is None
    scenario = scenario_paths[0] if single else None     # the file, or the scenario once it is loaded
    if ros2_out is not None:
        from .errors import ModelFileError, PhysicalParameterError
        from .io.ros2 import check_plan_bag_target
        from .io.scenario import load_scenario

        if not single:
            raise PhysicalParameterError("option --ros2 writes the plan of one scenario file; give one")
        try:
            check_plan_bag_target(ros2_out)
        except FileExistsError as exc:
            raise PhysicalParameterError(f"option --ros2: {exc}") from None
        scenario = load_scenario(scenario_paths[0])
        if scenario.drive is None:
            raise ModelFileError(str(scenario_paths[0]), "drive", "option --ros2 needs the drive limits that make "
                                 "the joint trajectory; the scenario has no [drive] table")
    if single:
        from .api import plan_scenario, write_plan_ros2

        result = plan_scenario(scenario, out_dir, n_jobs=jobs or os.cpu_count() or 1, iterations=iterations,
                               compare_blind=not no_blind, progress=_progress())
        logger.info(f"outputs in {result.output_dir}")
        if ros2_out is not None:
            written = write_plan_ros2(result, ros2_out, storage=ros2_storage, distro=ros2_distro, frame_id=ros2_frame)
            logger.info(f"ROS 2 bag in {written['bag']} ({ros2_storage}, {ros2_distro} messages); trajectory for "
                        f"`ros2 topic pub` in {written['yaml']}")
        if result.run.bound_map.preview and not no_full_map:
            from .planning.bound_map import complete_bound_map

            logger.info("the plan is written; computing the robot's full bound map now (interrupt to stop: the next "
                        "run goes on from its finished chunks)")
            complete_bound_map(result.run.setup, jobs or os.cpu_count() or 1, progress=_progress())
        return
    from .studies import plan_many

    study = plan_many(scenario_paths, out_dir or "out/scenarios", n_jobs=jobs or 1, scheduler=scheduler,
                      iterations=iterations, compare_blind=not no_blind, progress=_progress())
    if study.n_failed:
        raise SystemExit(1)


@main.command()
@click.option("--robot", "robot_path", required=True, type=click.Path(exists=True, dir_okay=False))
@click.option("--resolution", default=None,
              help="Grid nodes per map coordinate, comma-separated in the order the command prints (base "
                   "rotations, then translations, of tubes 2..n relative to tube 1; e.g. 16,16,14). One "
                   "number applies to all. Default 16 per rotation, 6 per translation.")
@click.option("--placement", type=_choice(MapPlacement), default=MapPlacement.UNIFORM.value, show_default=True,
              help="Nodes of bounded coordinates: uniform, or placed where pilot lines of the exact bound "
                   "show it bends (docs/boundmaps.md).")
@click.option("--ds", type=float, default=None, help="Arc-length step [m] (default 0.003).")
@click.option("--out", "out_path", type=click.Path(), default=None,
              help="The map: a chunked zarr store DIR.zarr or FILE.npz (exported when its store is complete). "
                   "Default: boundmaps/<robot>-<key>.<format> next to the robot file.")
@click.option("--format", "fmt", type=click.Choice(["zarr", "npz"]), default="zarr", show_default=True,
              help="Suffix of the default --out; an .npz map is computed through a store in boundmaps/ of the cache folder ($CTRPLAN_CACHE_DIR, else the user cache folder).")
@click.option("--store", "--cache-dir", "store_path", type=click.Path(file_okay=False), default=None,
              help="Chunk store of an .npz output (default: boundmaps/<robot>-<key>.zarr in the cache folder).")
@click.option("--jobs", type=int, default=None,
              help="Local worker processes (default: all cores; 1 computes in this process).")
@click.option("--scheduler", default=None,
              help="Address of a running dask.distributed scheduler (e.g. tcp://host:8786); its workers "
                   "need ctrplan installed. Default: the local cores.")
@click.option("--chunk-size", type=click.IntRange(min=1), default=None,
              help="Grid nodes per chunk of a new store (default 64).")
@click.option("--no-progress", is_flag=True, help="Hide the progress bars.")
def boundmap(robot_path, resolution, placement, ds, out_path, fmt, store_path, jobs, scheduler, chunk_size,
             no_progress):
    """Compute the friction-bound map of a robot over its joint space.

    The map's coordinates are the base rotations and translations of tubes 2..n relative to
    tube 1 that the robot's joints change (the bound depends on nothing else), so a robot whose
    three tubes each rotate and translate has a 4-D map. Chunks are written to a zarr store as
    they finish; rerunning the same command after an interruption computes only the missing
    chunks. The store records the robot file's sha256, the model settings, the grid spec and the
    mechanics version, and refuses to resume a map made for others.
    """
    import numpy as np

    from .boundmap import (DEFAULT_CHUNK_SIZE, ComputeOptions, MapSpec, default_spec, map_coordinates, map_file,
                           map_identity, map_paths)
    from .boundmap.files import compute_bound_map
    from .io.robot_file import load_robot
    from .mechanics import evaluate_bound

    robot = load_robot(robot_path)
    coords = map_coordinates(robot)
    if resolution:
        try:
            res = tuple(int(x) for x in resolution.split(","))
        except ValueError:
            raise click.BadParameter(f"{resolution!r} is not a comma-separated list of integers",
                                     param_hint="--resolution") from None
        if len(res) not in (1, coords.dim) or min(res) < 2:
            raise click.BadParameter(
                f"{resolution!r}: needs 1 or {coords.dim} integers >= 2, one per map coordinate "
                f"({', '.join(coords.names)}) of {robot_path}", param_hint="--resolution")
        spec = MapSpec(res * coords.dim if len(res) == 1 else res, placement)
    else:
        spec = MapSpec(default_spec(robot).resolution, placement)
    if out_path and Path(out_path).suffix not in (".zarr", ".npz"):
        raise click.BadParameter(f"{out_path!r} must end in .zarr (chunked store) or .npz", param_hint="--out")
    settings = _settings(ds)
    ident = map_identity(robot, settings, spec, evaluate_bound, Path(robot_path).read_text())
    shipped, cache = map_paths(robot_path, ident.key)
    out = Path(out_path) if out_path else map_file(shipped, "." + fmt)
    if store_path and out.suffix != ".npz":
        raise click.BadParameter(f"{store_path!r}: a separate store needs an .npz output (a .zarr output is the "
                                 "store)", param_hint="--store")
    if out.suffix == ".npz" and not store_path:
        store_path = map_file(cache, ".zarr") if not out_path else out.with_suffix(".zarr")
    logger.info(f"map coordinates: {', '.join(f'{n} ({r} nodes)' for n, r in zip(coords.names, spec.resolution))}; "
                f"placement {spec.placement}; key {ident.key[:12]}; mechanics {ident.mechanics_version}")
    options = ComputeOptions(n_jobs=1 if scheduler else (jobs or os.cpu_count() or 1), scheduler=scheduler,
                             chunk_size=chunk_size or DEFAULT_CHUNK_SIZE, progress=_progress(no_progress))
    run, path = compute_bound_map(robot_path, spec, settings, out_path=out, store_path=store_path, options=options)
    field = run.field
    secs = np.asarray(run.chunk_seconds)
    timing = (f"; chunk time mean {secs.mean():.2f} s, max {secs.max():.2f} s" if secs.size else "")
    pilots = (f"; {run.pilot_evaluations} pilot evaluations in {run.pilot_seconds:.1f} s"
              if run.pilot_evaluations else "")
    logger.info(f"{run.executor}: {run.n_computed} chunks computed, {run.n_reused} reused of {run.n_chunks} "
                f"in {run.wall_seconds:.1f} s{timing}{pilots}")
    for name, axis in zip(coords.names, field.axes):
        unit, f = ("deg", np.degrees(1.0)) if "alpha" in name else ("mm", 1e3)
        logger.info(f"  {name} nodes [{unit}]: {np.array2string(axis * f, precision=1, max_line_width=200)}")
    v = field.values[..., 0][field.valid] * 1e3
    stats = (f"bound median {float(np.median(v)):.2f} mm, max {v.max():.2f} mm" if v.size else "no valid node")
    logger.info(f"wrote {path}: {int(field.valid.sum())} of {field.valid.size} nodes valid; {stats}")


def _effect_options(command):
    """One ``ctrplan synth`` option per registered effect that has one (``Effect.synth_option``)."""
    from .effects import REGISTRY

    for effect in reversed(list(REGISTRY.values())):
        if effect.synth_option:
            note = " (trajectory protocol)" if effect.needs_motion else ""
            command = click.option(effect.synth_option, f"effect__{effect.name}", default=None,
                                   help=f"{effect.label}: {effect.synth_help}{note} Default: off.")(command)
    return command


@main.command()
@click.option("--robot", "robot_path", required=True, type=click.Path(exists=True, dir_okay=False),
              help="Nominal robot model file (TOML, SI units).")
@click.option("--out", "out_path", required=True, type=click.Path(dir_okay=False),
              help="Output CSV; the truth goes to <out>.truth.json.")
@click.option("--protocol", type=_choice(ProtocolKind), default="paper", show_default=True,
              help="paper: joint grid, 2^(n-1) approach directions (Section V-C); trajectory: "
                   "continuous motion with reversals at 10 Hz.")
@click.option("--grid", type=int, default=8, show_default=True, help="Paper protocol: nodes per joint.")
@click.option("--samples", type=int, default=1200, show_default=True, help="Trajectory protocol: samples.")
@_effect_options
@click.option("--noise-position-mm", "noise_mm", type=float, default=1.4, show_default=True,
              help="rms tip position noise [mm].")
@click.option("--noise-angle-deg", "noise_deg", type=float, default=0.5, show_default=True,
              help="rms tip tangent noise [deg].")
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--ds", type=float, default=None, help="Arc-length step [m] (default 0.003).")
@click.option("--jobs", type=int, default=None, help="Worker processes (default: all cores).")
@click.option("--no-progress", is_flag=True, help="Hide the progress bar.")
def synth(robot_path, out_path, protocol, grid, samples, noise_mm, noise_deg, seed, ds, jobs, no_progress,
          **effect_options):
    """Generate measured-like data from a robot model with hidden effects and sensor noise.

    Each effect option takes comma-separated values of the effect's parameters in SI units, in
    the order of its parameters (one per tube or pair; see ``docs/discrepancy.md``).
    """
    import numpy as np

    from .discrepancy.measured.synth import Noise, SynthProtocol, parse_values, synthesize, write_synth
    from .effects import REGISTRY, EffectSet
    from .errors import PhysicalParameterError
    from .io.robot_file import file_hash, load_robot

    robot = load_robot(robot_path)
    values, used = {}, []
    for key, text in effect_options.items():
        if text is None:
            continue
        effect = REGISTRY[key.split("__", 1)[1]]
        names = effect.parameter_names(robot)
        parsed = parse_values(effect.synth_option, text, len(names))
        try:
            EffectSet({effect.name: dict(zip(names, parsed))}, robot)
        except PhysicalParameterError as exc:
            raise PhysicalParameterError(f"option {effect.synth_option} {text!r}: {exc}") from None
        values[effect.name] = dict(zip(names, parsed))
        used.append(effect.synth_option)
    for option, value in (("--noise-position-mm", noise_mm), ("--noise-angle-deg", noise_deg)):
        if not np.isfinite(value) or value < 0:
            raise PhysicalParameterError(f"option {option} {value!r}: must be >= 0")
    for option, value, low in (("--grid", grid, 2), ("--samples", samples, 2), ("--jobs", jobs or 1, 1)):
        if value < low:
            raise PhysicalParameterError(f"option {option} {value!r}: must be >= {low}")
    if ds is not None and not (np.isfinite(ds) and ds > 0):
        raise PhysicalParameterError(f"option --ds {ds!r}: must be > 0 m")
    moving = []
    try:
        effects = EffectSet(values, robot)
        moving = [REGISTRY[n].synth_option for n in effects.active() if REGISTRY[n].needs_motion]
        if moving and protocol != ProtocolKind.TRAJECTORY:
            raise PhysicalParameterError("needs --protocol trajectory (the paper protocol solves every target "
                                         "without its approach path)")
    except PhysicalParameterError as exc:
        raise PhysicalParameterError(f"option {(moving or used or ['--effects'])[-1]}: {exc}") from None
    noise = Noise(position_rms=noise_mm * 1e-3, angle_rms=float(np.deg2rad(noise_deg)))
    result = synthesize(robot, effects, protocol=SynthProtocol(protocol, grid, samples), noise=noise,
                        seed=seed, settings=_settings(ds), n_jobs=jobs or os.cpu_count() or 1,
                        progress=_progress(no_progress))
    sidecar = write_synth(out_path, result, robot_file=robot_path, robot_hash=file_hash(robot_path))
    t = result.truth
    logger.info(f"wrote {t['counts']['rows']} rows to {out_path} ({t['protocol']} protocol, "
                f"{t['truth_model']} truth model, {t['counts']['dropped']} samples dropped, "
                f"{t['elapsed_s']:.1f} s); truth in {sidecar}")


def _bag_options(f):
    """The options that choose what to read from a ROS 2 bag (:class:`ctrplan.io.ros2.BagSelection`)."""
    for option in reversed([
        click.option("--joint-topic", default=None,
                     help="Bag: sensor_msgs/msg/JointState topic (default: the bag's only one)."),
        click.option("--pose-topic", default=None,
                     help="Bag: tip pose topic, geometry_msgs/msg/PoseStamped, TransformStamped or "
                          "tf2_msgs/msg/TFMessage (default: the bag's only PoseStamped or TransformStamped topic, "
                          "else its only TFMessage topic)."),
        click.option("--child-frame", default=None,
                     help="Bag: child frame of the tip in a TFMessage or TransformStamped topic (default: the only "
                          "one)."),
        click.option("--joint-names", "joint_names", default=None,
                     help="Bag: joint names that differ from the robot file's, BAG_NAME=ROBOT_JOINT,... "
                          "(e.g. tube2_rotation=alpha_2)."),
        click.option("--max-joint-gap", type=float, default=5.0, show_default=True,
                     help="Bag: a pause in the joint stream longer than this many median joint periods starts a "
                          "new continuous motion."),
        click.option("--tangent-axis", type=_choice(TangentAxis), default=TangentAxis.Z.value, show_default=True,
                     help="Bag: axis of the pose orientation that is the tip tangent (none: positions only)."),
    ]):
        f = option(f)
    return f


def _bag_selection(data_path, joint_topic, pose_topic, child_frame, joint_names, max_joint_gap, tangent_axis):
    """The BagSelection of the bag options; refuses them for data that is not a bag."""
    from .errors import PhysicalParameterError
    from .io.ros2 import BagSelection, is_bag

    try:
        pairs = BagSelection.parse_joint_names(joint_names)
    except ValueError as exc:
        raise PhysicalParameterError(f"option --joint-names {joint_names!r}: {exc}") from None
    try:
        bag = BagSelection(joint_topic=joint_topic, pose_topic=pose_topic, child_frame=child_frame, joint_names=pairs,
                           max_gap_periods=max_joint_gap, tangent_axis=tangent_axis)
    except ValueError as exc:
        raise PhysicalParameterError(f"option --max-joint-gap {max_joint_gap!r}: {exc}") from None
    if bag != BagSelection() and not is_bag(data_path):
        raise PhysicalParameterError(f"options --joint-topic, --pose-topic, --child-frame, --joint-names, "
                                     f"--max-joint-gap and --tangent-axis read a ROS 2 bag; {data_path} is not one")
    return bag


@main.command("bag-info")
@click.argument("bag_path", type=click.Path(exists=True))
@click.option("--robot", "robot_path", default=None, type=click.Path(exists=True, dir_okay=False),
              help="Robot model file: also say what `ctrplan discrepancy` would read from the bag (topics, joints, "
                   "rates, time span, poses outside the joint stream).")
@_bag_options
def bag_info(bag_path, robot_path, **bag_options):
    """List a ROS 2 bag's topics and, with --robot, what the discrepancy workflow would read from it."""
    from .io.ros2 import bag_topics, describe_bag_summary, read_bag_measurements

    for t in bag_topics(bag_path):
        click.echo(f"{t['topic']}  {t['type']}  {t['count']} messages")
    if robot_path is not None:
        from .io.robot_file import load_robot

        read = read_bag_measurements(bag_path, load_robot(robot_path), _bag_selection(bag_path, **bag_options))
        for line in describe_bag_summary(read.summary):
            click.echo(line)


@main.command()
@click.option("--robot", "robot_path", required=True, type=click.Path(exists=True, dir_okay=False),
              help="Robot model file with the candidate effects switched off (TOML, SI units).")
@click.option("--data", "data_paths", required=True, multiple=True, type=click.Path(exists=True),
              help="Measured data: CSV in the project schema (SI units), a ROS 2 bag (rosbag2 folder, .mcap or "
                   ".db3 file), or Ha's whitespace trajectory format (any other file). Given more than once: "
                   "several recordings of the same robot, analysed together as separate motions (combined "
                   "into <out>/recordings.csv).")
@click.option("--out", "out_dir", required=True, type=click.Path(file_okay=False),
              help="Report folder (report.md, results.json, PNG plots, updated model file).")
@click.option("--fit", default=None,
              help="Baseline parameters, comma-separated (default: precurvature_y_i of curved tubes, "
                   "k_xy_relative_2..n, and the registration for tracker-frame data).")
@click.option("--effects", default=None,
              help="Candidate effects to test and try, comma-separated (default: every registered effect: "
                   "friction, clearance, offplane, poisson, registration, backlash, time_offset, gradual_friction).")
@click.option("--noise-position-mm", "noise_mm", type=float, default=None,
              help="rms tip position noise of the sensor [mm] as the data's source states it (used when the data has "
                   "too few rests to estimate it from).")
@click.option("--reference-mu", "reference_mu", default=None,
              help="Friction coefficients per pair (e.g. published for the robot) with which the history-aware "
                   "prediction and the envelope are also evaluated, e.g. 0.22,0.12.")
@click.option("--envelope-samples", type=int, default=0, show_default=True,
              help="Held-out samples at which to evaluate the friction envelope (all bounding solutions) "
                   "for the coverage figures; 0 skips it.")
@click.option("--frame", type=_choice(PoseFrame), default=None,
              help="Frame of the measured poses (default: tracker for Ha's format and bags, robot for CSV); "
                   "tracker fits a rigid registration.")
@_bag_options
@click.option("--test-fraction", type=float, default=0.2, show_default=True,
              help="Share of the units (time blocks or configuration groups) held back as the untouched test split "
                   "(at least 8 units).")
@click.option("--folds", type=int, default=None,
              help="Cross-validation folds of the rest (default: 10, fewer for fewer than 2 units a fold).")
@click.option("--blocks", type=int, default=None,
              help="Time blocks a continuous motion is cut into (the units of the split and the tests; default: 50, "
                   "fewer for blocks shorter than 10 samples).")
@click.option("--prior-strengths", default=None,
              help="Strengths tau of the prior toward the robot file's tube parameters that the out-of-fold error "
                   "chooses among, comma-separated ('inf': no prior; 0, the robot file's parameters with only a "
                   "registration, is always tried; default 0.003,0.01,0.03,0.1,inf).")
@click.option("--max-calibration-samples", type=int, default=300, show_default=True,
              help="Samples a fit uses at most.")
@click.option("--max-contact-samples", type=int, default=150, show_default=True,
              help="Of those, the samples a fit of the clearance or friction model uses at most.")
@click.option("--bound-target", type=float, default=0.9, show_default=True,
              help="Share of measured tips the calibrated bound is to cover (written to the updated robot file).")
@click.option("--bound-samples", type=int, default=200, show_default=True,
              help="Development and test samples at which the friction bound is evaluated for its calibration; "
                   "0 skips it.")
@click.option("--significance", type=float, default=0.01, show_default=True)
@click.option("--permutations", type=int, default=999, show_default=True)
@click.option("--ds", type=float, default=None, help="Arc-length step [m] (default 0.003).")
@click.option("--jobs", type=int, default=None, help="Worker processes (default: all cores).")
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--no-progress", is_flag=True, help="Hide progress bars.")
def discrepancy(robot_path, data_paths, out_dir, fit, effects, noise_mm, reference_mu, envelope_samples, frame,
                test_fraction, folds, blocks, prior_strengths, max_calibration_samples, max_contact_samples, bound_target,
                bound_samples, significance, permutations, ds, jobs, seed, no_progress, **bag_options):
    """Find where model and measurement disagree, name the missing effect, add it, show the gap shrink.

    Interrupted runs resume from <out>/.stages (finished calibrations and evaluations are kept).
    """
    from .discrepancy.outputs.report import write_report
    from .discrepancy.workflow import DiscrepancyOptions, run_discrepancy
    from .effects import REGISTRY
    from .errors import PhysicalParameterError

    chosen = None
    if effects is not None:
        chosen = tuple(e.strip() for e in effects.split(",") if e.strip())
        bad = [e for e in chosen if e not in REGISTRY]
        if bad:
            raise PhysicalParameterError(f"option --effects {effects!r}: unknown effect {bad[0]!r}; "
                                         f"expected some of {', '.join(REGISTRY)}")
    if not 0.0 < test_fraction <= 0.5:
        raise PhysicalParameterError(f"option --test-fraction {test_fraction!r}: must be in (0, 0.5]")
    if (folds is not None and folds < 2) or (blocks is not None and blocks < 2):
        raise PhysicalParameterError(f"options --folds {folds!r} and --blocks {blocks!r}: must be >= 2")
    strengths = None
    if prior_strengths is not None:
        try:
            strengths = tuple(float(x) for x in prior_strengths.split(",") if x.strip())
        except ValueError:
            strengths = ()
        if not strengths or any(not (t >= 0) for t in strengths):
            raise PhysicalParameterError(f"option --prior-strengths {prior_strengths!r}: expected comma-separated "
                                         f"numbers >= 0 or 'inf'")
    if ds is not None and not ds > 0:
        raise PhysicalParameterError(f"option --ds {ds!r}: must be > 0 m")
    if noise_mm is not None and not (noise_mm > 0 and noise_mm < float("inf")):
        raise PhysicalParameterError(f"option --noise-position-mm {noise_mm!r}: must be > 0 mm")
    if envelope_samples < 0:
        raise PhysicalParameterError(f"option --envelope-samples {envelope_samples!r}: must be >= 0")
    if not 0.0 < bound_target < 1.0:
        raise PhysicalParameterError(f"option --bound-target {bound_target!r}: must be in (0, 1)")
    if bound_samples < 0:
        raise PhysicalParameterError(f"option --bound-samples {bound_samples!r}: must be >= 0")
    from .io.ros2 import BagSelection

    bag = BagSelection()
    for data_path in data_paths:
        bag = _bag_selection(data_path, **bag_options)
    if len(data_paths) > 1:
        data_path, frame = _combine_recordings(robot_path, data_paths, frame, bag, out_dir)
    else:
        data_path = data_paths[0]
    ref_mu = None
    if reference_mu is not None:
        from .discrepancy.measured.synth import parse_values
        from .io.robot_file import load_robot

        ref_mu = parse_values("--reference-mu", reference_mu, load_robot(robot_path).n_tubes - 1)
        if min(ref_mu) < 0:
            raise PhysicalParameterError(f"option --reference-mu {reference_mu!r}: must be >= 0")
    opts = DiscrepancyOptions(
        fit=tuple(x.strip() for x in fit.split(",")) if fit else None, effects=chosen, frame=frame,
        bag=bag if bag != BagSelection() else None,
        test_fraction=test_fraction, n_folds=folds, n_blocks=blocks, max_calibration_samples=max_calibration_samples,
        max_contact_samples=max_contact_samples,
        significance=significance, n_permutations=permutations, ds=ds or 3e-3,
        n_jobs=jobs or os.cpu_count() or 1, seed=seed,
        noise_position=None if noise_mm is None else noise_mm * 1e-3, envelope_samples=envelope_samples,
        reference_friction=ref_mu, bound_target=bound_target, bound_samples=bound_samples,
        **({} if strengths is None else {"prior_strengths": strengths}))
    result = run_discrepancy(robot_path, data_path, out_dir, opts, progress=_progress(no_progress))
    try:
        paths = write_report(result, out_dir)
    except Exception as exc:  # noqa: BLE001 - the run's results are on disk: say how to write the report again
        _report_failed(result, out_dir, exc)
        raise SystemExit(1) from None
    logger.info(f"report: {paths['markdown']}")


def _combine_recordings(robot_path, data_paths, frame, bag, out_dir) -> tuple[str, str]:
    """Several recordings as one table of separate motions: ``<out>/recordings.csv`` (each recording's
    motions keep their own ids, offset past the previous recording's; its ``eta_*`` columns and
    tangents kept where every recording has them). Returns the table's path and the frame.

    Raises
    ------
    DataFileError
        A recording that does not load, or recordings in different frames without ``--frame``.
    """
    import numpy as np
    import pandas as pd

    from .discrepancy import load_measured_data
    from .errors import DataFileError
    from .io.atomic import atomic_write_text
    from .io.robot_file import load_robot

    from .io.ros2 import BagSelection

    robot = load_robot(robot_path)
    loaded = [load_measured_data(p, robot, frame=frame, bag=bag if bag != BagSelection() else None)
              for p in data_paths]
    frames = {d.frame for d in loaded}
    if len(frames) > 1:
        raise DataFileError(f"options --data {', '.join(map(str, data_paths))}: recordings in different frames "
                            f"({', '.join(f'{d.file}: {d.frame}' for d in loaded)}); give --frame")
    n = robot.n_tubes
    tables, offset = [], 0
    tangents = all(d.tangent is not None for d in loaded)
    for d in loaded:
        if d.record.alpha.shape[0] != d.n_samples:
            raise DataFileError(f"{d.file}: {d.record.alpha.shape[0] - d.n_samples} recorded rows are not samples; "
                                f"combine such recordings by hand")
        cols = {"time": d.time if d.time is not None else np.arange(d.n_samples, dtype=float),
                "sequence": d.sequence - d.sequence.min() + offset}
        cols.update({f"alpha_{i + 1}": d.alpha[:, i] for i in range(n)})
        cols.update({f"beta_{i + 1}": d.beta[:, i] for i in range(n)})
        cols.update({f"tip_{c}": d.tip[:, a] for a, c in enumerate("xyz")})
        if tangents:
            cols.update({f"tangent_{c}": d.tangent[:, a] for a, c in enumerate("xyz")})
        cols.update({f"eta_{k + 1}": d.given_eta[d.rows, k] for k in range(n - 1)})
        tables.append(pd.DataFrame(cols))
        offset = int(cols["sequence"].max()) + 1
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "recordings.csv"
    atomic_write_text(path, pd.concat(tables, ignore_index=True).to_csv(index=False))
    logger.info(f"data: {len(loaded)} recordings ({', '.join(f'{d.file}: {d.n_samples} samples' for d in loaded)}) "
                f"combined as separate motions into {path}")
    return str(path), loaded[0].frame


def _report_failed(result, out_dir, exc: Exception) -> None:
    """Log that the report of a finished discrepancy run could not be written, what is on disk,
    and the command that writes it (the traceback at DEBUG, ``ctrplan -v``)."""
    import json

    from .discrepancy.outputs.report import REWRITE_COMMAND

    logger.debug("the report's traceback:", exc_info=exc)
    path = Path(out_dir) / "results.json"
    try:                 # this run's results.json (not an earlier run's): it holds this run's wall time
        written = json.loads(path.read_text()).get("seconds") == result.seconds
    except Exception:  # noqa: BLE001 - missing or unreadable: not written
        written = False
    command = REWRITE_COMMAND.format(out=shlex.quote(str(out_dir)))
    retry = (f"{path} is written; write the report from it with: {command}" if written else
             f"run the same command again to write it (finished stages are reused from {Path(out_dir) / '.stages'})")
    logger.error(f"the report could not be written ({type(exc).__name__}: {exc}); the updated robot file "
                 f"{result.updated_model_file} is written; {retry}")


@main.command()
@click.option("--result", "result_dir", required=True, type=click.Path(exists=True, file_okay=False),
              help="Output folder of `ctrplan discrepancy` (its results.json gives the hypotheses, the noise, the robot "
                   "file and the data).")
@click.option("--out", "out_dir", required=True, type=click.Path(file_okay=False),
              help="Output folder (trajectory.csv, trajectory_bag/, samples.csv, design.json, separation.png, design.md).")
@click.option("--hypotheses", default=None,
              help="Candidates to separate or determine, comma-separated (effects, 'baseline', or 'first+second' for a "
                   "pair the run tried; default: the ambiguous pair, else the named model).")
@click.option("--parameters", default=None,
              help="With one hypothesis: the parameters to determine, comma-separated (default: those the recorded "
                   "data left undetermined).")
@click.option("--robot", "robot_path", default=None, type=click.Path(exists=True, dir_okay=False),
              help="Robot model file the result was fitted to (default: the result's).")
@click.option("--data", "data_path", default=None, type=click.Path(exists=True),
              help="The recorded data (default: the result's).")
@click.option("--scenario", "scenario_path", default=None, type=click.Path(exists=True, dir_okay=False),
              help="Scenario file whose obstacles the motion stays clear of, whose [drive] limits it keeps and whose "
                   "start it begins at (default: no obstacles, the drive the recorded motion shows, the robot's home).")
@click.option("--duration", type=float, default=None, help="Budget [s] (default: the recorded trajectory's duration).")
@click.option("--rest", type=float, default=1.0, show_default=True, help="Rest after each motion primitive [s].")
@click.option("--noise-position-mm", "noise_mm", type=float, default=None,
              help="3-D rms tip position noise [mm], as in synth and discrepancy (default: the result's estimate).")
@click.option("--random-motions", type=int, default=3, show_default=True,
              help="Random motions of the same budget the design is compared with.")
@click.option("--no-bag", is_flag=True, help="Do not write the ROS 2 bag.")
@click.option("--jobs", type=int, default=None,
              help="Processes the candidate motions are evaluated on (default: all cores).")
@click.option("--seed", type=int, default=0, show_default=True, help="Seed of the random motions.")
@click.option("--compound", is_flag=True,
              help="Offer the search two-step primitives too: a move, then a reversal about the new value.")
def design(result_dir, out_dir, hypotheses, parameters, robot_path, data_path, scenario_path, duration, rest, noise_mm,
           random_motions, no_bag, jobs, seed, compound):
    """Plan the measured trajectory that best settles what a discrepancy run left open.

    Two or more hypotheses: the motion that best separates them, each refitted to the others'
    predictions (T-optimality). One: the motion that best determines its parameters (Ds-optimality).
    The motion is made of primitives the effects respond to, stays inside the joint limits, stable and
    clear of the scenario's obstacles, and is time-parameterized within the drive limits (ruckig).
    """
    from .design import DesignInputError, DesignSearch, design_from_result, write_design

    if noise_mm is not None and not (noise_mm > 0 and noise_mm < float("inf")):
        raise DesignInputError(f"option --noise-position-mm {noise_mm!r}: must be > 0 mm")
    if duration is not None and not duration > 0:
        raise DesignInputError(f"option --duration {duration!r}: must be > 0 s")

    def items(text):
        return [k.strip() for k in text.split(",") if k.strip()] if text else None

    search = DesignSearch(n_random=random_motions, seed=seed, n_jobs=jobs or os.cpu_count() or 1, compound=compound)
    res, robot, data = design_from_result(
        result_dir, hypotheses=items(hypotheses), parameters=items(parameters), robot_file=robot_path,
        data_file=data_path, scenario_file=scenario_path, duration=duration, rest=rest,
        noise_position=None if noise_mm is None else noise_mm * 1e-3, search=search)
    command = "ctrplan " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    paths = write_design(res, robot, out_dir, command=command, bag=not no_bag, frame=data.frame)
    logger.info(f"design: {res.duration:.1f} s, {len(res.primitives)} primitives; report: {paths['markdown']}")


@main.command("discrepancy-report")
@click.argument("out_dir", type=click.Path(exists=True, file_okay=False))
def discrepancy_report(out_dir):
    """Write report.md of a `ctrplan discrepancy` folder again from its results.json.

    For a run whose report could not be written, or a report to be formatted by the present code.
    The plots are not made again (they need the run's arrays): the report shows those in the folder.
    """
    from .discrepancy.outputs.report import write_report_from_results

    paths = write_report_from_results(out_dir)
    logger.info(f"report: {paths['markdown']}")


def run():  # pragma: no cover - entry point wrapper
    try:
        main(standalone_mode=True)
    except CtrplanError as exc:
        click.echo(f"error: {exc}", err=True)
        sys.exit(2)


if __name__ == "__main__":  # pragma: no cover
    main()
