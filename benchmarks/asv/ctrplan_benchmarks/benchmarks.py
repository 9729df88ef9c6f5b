"""Speed benchmarks of ctrplan for airspeed velocity (asv), run against each commit asked for.

What they time (in-process unless said otherwise):

- ``Bound.time_*``: the friction bound (Section III of Ha, Fagogenis & Dupont 2019) and the
  standard model at configurations of the paper's 4x4x4 grid (Table II robot);
- ``ScenarioPlan.time_plan``: ``ctrplan.plan`` of each shipped scenario with its shipped map,
  bound-aware only, no files;
- ``RoadmapQuery.time_plan_to``: one goal planned on a built roadmap of the obstacles scenario
  (``ctrplan.Planner.plan_to``: search, ordering and final check, exact bound, trajectory);
- ``Discrepancy.time_workflow``: the discrepancy workflow on a small synthetic case (the Table I
  tube pair, 400 samples along a trajectory with a 0.2 s tracker lag hidden, two candidates,
  5 folds);
- ``Evaluate.time_*``: the work of ``ctrplan evaluate --jobs 1`` (``ctrplan.batch.evaluate_table``,
  one process): the friction model (the full bound: every friction solution and the clearance
  solution) on the paper's 4x4x4 grid and the standard model on the rows of Ha's measured
  trajectory (Table II robot; skipped without ``../shared/data``);
- ``Simulate.time_standard_along_trajectory``: the standard model along Ha's measured
  trajectory, each sequence followed in order, as a discrepancy fit evaluates it (skipped
  without the data);
- ``CandidateFit.time_clearance_fit``: one discrepancy candidate's fit, the tube parameters and
  the registration with the clearance model on 48 samples of Ha's measured trajectory (skipped
  without the data);
- ``Design.time_design``: one ``ctrplan.design.design_experiment`` search separating drive
  backlash from torsional friction on the Table I tube pair (a 10-s motion after a 12-s
  recording, no random comparison);
- ``ContactDerivatives.time_jacobian``: the implicit-function derivatives of friction solutions'
  tips with respect to every tube parameter (``contact_tip_jacobian``) at 8 configurations of the
  Table VII robot's grid (skipped on commits without them);
- ``timeraw_*``: importing ctrplan, the first bound, and the Quick start's plan
  (``ctrplan plan scenarios/obstacles.toml`` with its files: summary, plots, 3-D view) in a fresh
  interpreter (the compiled kernels read from their cache; the plan's bound map read from the
  shipped file).

Run from the repository root: ``asv --config benchmarks/asv/asv.conf.json continuous --factor 1.15
main HEAD`` (docs/benchmarks.md).
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[3]


def _grid_configurations(robot, n: int = 4):
    """Joint vectors of the paper's grid over the robot's joint box (n per joint), every
    ``len // 8``-th, so that each benchmark call sees the same 8 configurations."""
    axes = [np.linspace(lo, hi, n) for lo, hi in zip(robot.joint_lower, robot.joint_upper)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(axes))
    return grid[:: max(1, len(grid) // 8)][:8]


class Bound:
    """The friction bound and the standard model at 8 configurations of the 4x4x4 grid."""

    timeout = 300

    def setup(self):
        from ctrplan.io.robot_file import load_robot
        from ctrplan.mechanics import ModelSettings, evaluate_bound, solve_standard

        self.robot = load_robot(REPO / "model" / "ha2019-table2-nominal.toml")
        self.settings = ModelSettings()
        self.configs = [self.robot.configuration(q) for q in _grid_configurations(self.robot)]
        self.evaluate_bound, self.solve_standard = evaluate_bound, solve_standard
        self.evaluate_bound(self.robot, *self.configs[0], self.settings)   # load the compiled kernels

    def time_bound(self):
        for alpha, beta in self.configs:
            self.evaluate_bound(self.robot, alpha, beta, self.settings)

    def time_standard(self):
        for alpha, beta in self.configs:
            self.solve_standard(self.robot, alpha, beta, self.settings)


class ScenarioPlan:
    """``ctrplan.plan`` of a shipped scenario (bound-aware only, no files)."""

    params = ["obstacles", "sequence", "task-target", "six-joint"]
    param_names = ["scenario"]
    timeout = 900
    number = 1
    repeat = (1, 3, 120.0)
    warmup_time = 0.0

    def setup(self, scenario):
        import ctrplan
        from ctrplan.io.scenario import load_scenario

        self.scenario = load_scenario(REPO / "scenarios" / f"{scenario}.toml")
        self.plan = ctrplan.plan
        # caches (the sequence scenario's roadmap) go to a folder of their own; the first run
        # fills them, the timed runs read them
        self.cache = tempfile.TemporaryDirectory(prefix="ctrplan-asv-")
        self.cwd = os.getcwd()
        os.chdir(self.cache.name)
        self.plan(self.scenario, compare_blind=False)

    def teardown(self, scenario):
        os.chdir(self.cwd)
        self.cache.cleanup()

    def time_plan(self, scenario):
        self.plan(self.scenario, compare_blind=False)


class RoadmapQuery:
    """One goal on the obstacles scenario's roadmap, from the scenario's start."""

    timeout = 600
    number = 1
    repeat = (3, 10, 60.0)

    def setup_cache(self):
        import ctrplan

        if not hasattr(ctrplan, "Planner"):    # a commit before interactive planning
            return ""
        folder = tempfile.mkdtemp(prefix="ctrplan-asv-roadmap-")
        ctrplan.Planner.from_scenario(REPO / "scenarios" / "obstacles.toml", cache_dir=folder)
        return folder

    def setup(self, folder):
        import ctrplan

        if not folder:
            raise NotImplementedError("no ctrplan.Planner in this commit")
        self.planner = ctrplan.Planner.from_scenario(REPO / "scenarios" / "obstacles.toml", cache_dir=folder)
        self.goal = np.array([2.0, 2.0, -0.06])
        self.planner.plan_to(self.goal, move=False)

    def time_plan_to(self, folder):
        self.planner.plan_to(self.goal, move=False)


class ValidityCheck:
    """The planner's validity check of 200 seeded random states of the obstacles scenario (its
    robot, obstacles and bound map; the standard model without the multistart search, as the
    pipeline checks): one state per call through the per-state reference ``ValidityChecker``, and
    all of them in one call of the compiled ``BatchValidityChecker``. Fresh checkers (empty state
    caches) for every sample."""

    timeout = 600
    number = 1
    repeat = (3, 10, 60.0)

    def setup(self):
        from ctrplan.boundmap import load_or_compute_bound_map
        from ctrplan.io.scenario import load_scenario
        from ctrplan.mechanics import ModelSettings
        from ctrplan.planning import CollisionChecker, JointStateSpace, ValidityChecker
        try:
            from ctrplan.planning import map_spec
        except ImportError:       # a commit before the stages of a plan joined ctrplan.planning
            from ctrplan.pipeline import map_spec
        from ctrplan.planning.route import DEFAULT_COLLISION_SEGMENT
        from ctrplan.planning.validity import BatchValidityChecker

        sc = load_scenario(REPO / "scenarios" / "obstacles.toml")
        robot = sc.robot
        settings = ModelSettings(ds=sc.bound_field.ds) if sc.bound_field.ds else ModelSettings()
        field = load_or_compute_bound_map(sc.robot_file, robot, map_spec(sc), settings, n_jobs=1)[0]
        settings = settings.replace(multistart=0)
        collision = CollisionChecker([o.as_dict() for o in sc.obstacles], segment_length=DEFAULT_COLLISION_SEGMENT)
        self.single = ValidityChecker(robot, collision=collision, field=field, settings=settings)
        self.batch = BatchValidityChecker(robot, collision=collision, field=field, settings=settings,
                                          joint_space=JointStateSpace(robot))
        rng = np.random.default_rng(0)
        lo, hi = robot.joint_lower, robot.joint_upper
        self.states = lo + (hi - lo) * rng.random((200, lo.size))
        warm = lo + (hi - lo) * rng.random((2, lo.size))     # imports, compiled kernels, first fcl objects
        for q in warm:
            self.single(q)
        self.batch.check(warm)

    def time_per_state_checker(self):
        for q in self.states:
            self.single(q)

    def time_batch_checker(self):
        self.batch.check(self.states)


class Discrepancy:
    """The discrepancy workflow on a small case with a hidden tracker lag."""

    timeout = 1800
    number = 1
    repeat = (1, 2, 600.0)
    warmup_time = 0.0

    def setup_cache(self):
        from ctrplan.discrepancy.measured.synth import Noise, SynthProtocol, synthesize
        from ctrplan.io.robot_file import load_robot, robot_to_toml
        from ctrplan.mechanics import ModelSettings

        folder = Path(tempfile.mkdtemp(prefix="ctrplan-asv-discrepancy-"))
        robot = load_robot(REPO / "model" / "ha2019-table1-tube-pair.toml").replace(friction_coefficients=(0.0,))
        (folder / "pair.toml").write_text(robot_to_toml(robot, header="Table I tube pair, friction off"))
        made = synthesize(robot, {"time_offset": {"time_offset": 0.2}}, protocol=SynthProtocol.trajectory(400),
                          noise=Noise(position_rms=5e-4), seed=7, settings=ModelSettings(ds=6e-3))
        made.frame.to_csv(folder / "data.csv", index=False)
        return str(folder)

    def time_workflow(self, folder):
        from ctrplan.discrepancy.workflow import DiscrepancyOptions, run_discrepancy

        out = tempfile.mkdtemp(prefix="ctrplan-asv-report-")
        options = DiscrepancyOptions(effects=("time_offset", "backlash"), ds=6e-3, n_permutations=99, n_folds=5,
                                     max_evaluations=100, prior_strengths=(0.03, float("inf")),
                                     max_calibration_samples=100, bound_samples=30, n_jobs=1)
        run_discrepancy(Path(folder) / "pair.toml", Path(folder) / "data.csv", out, options, progress=False)


HA_DATA = REPO.parent / "shared" / "data" / "ha-three-tube-trajectory" / "jointTipTrajectory_measured.txt"


class Evaluate:
    """The work of ``ctrplan evaluate --jobs 1``: the full bound on the 4x4x4 grid, the standard
    model on the measured trajectory's rows."""

    timeout = 900
    number = 1
    repeat = (2, 5, 120.0)
    warmup_time = 0.0

    def setup(self):
        from ctrplan.batch import evaluate_table
        from ctrplan.io.robot_file import load_robot
        from ctrplan.mechanics import ModelSettings

        self.robot = load_robot(REPO / "model" / "ha2019-table2-nominal.toml")
        self.settings = ModelSettings()
        axes = [np.linspace(lo, hi, 4) for lo, hi in zip(self.robot.joint_lower, self.robot.joint_upper)]
        grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(axes))
        configs = [self.robot.configuration(q) for q in grid]
        self.grid = (np.array([a for a, _ in configs]), np.array([b for _, b in configs]))
        self.rows = None
        if HA_DATA.exists():
            from ctrplan.io.tables import load_ha_trajectory

            frame = load_ha_trajectory(HA_DATA)
            self.rows = (frame[[f"alpha_{i}" for i in (1, 2, 3)]].to_numpy(),
                         frame[[f"beta_{i}" for i in (1, 2, 3)]].to_numpy())
        self.evaluate_table = evaluate_table
        evaluate_table(self.robot, self.grid[0][:1], self.grid[1][:1], "friction", self.settings, n_jobs=1)
        evaluate_table(self.robot, self.grid[0][:1], self.grid[1][:1], "standard", self.settings, n_jobs=1)

    def time_friction_grid(self):
        self.evaluate_table(self.robot, *self.grid, "friction", self.settings, n_jobs=1)

    def time_standard_trajectory_rows(self):
        if self.rows is None:
            raise NotImplementedError(f"no measured trajectory at {HA_DATA}")
        self.evaluate_table(self.robot, *self.rows, "standard", self.settings, n_jobs=1)


def _ha_measured():
    """The Table II nominal robot and Ha's measured trajectory read for it (``MeasuredData``);
    raises ``NotImplementedError`` (asv: skipped) without the data."""
    if not HA_DATA.exists():
        raise NotImplementedError(f"no measured trajectory at {HA_DATA}")
    from ctrplan.discrepancy.measured.data import load_measured_data
    from ctrplan.io.robot_file import load_robot

    robot = load_robot(REPO / "model" / "ha2019-table2-nominal.toml")
    return robot, load_measured_data(HA_DATA, robot)


class Simulate:
    """The standard model along Ha's measured trajectory as every standard-model evaluation of a
    discrepancy fit runs it (``ctrplan.discrepancy.fits.simulate.simulate``: each sequence
    followed in order, one process)."""

    timeout = 300
    warmup_time = 0.0

    def setup(self):
        from ctrplan.discrepancy.fits.simulate import simulate

        robot, data = _ha_measured()

        def run():
            return simulate(robot, data.alpha, data.beta, model="standard", sequence=data.sequence)

        self.run = run
        run()            # compiled kernels loaded

    def time_standard_along_trajectory(self):
        self.run()


class CandidateFit:
    """One candidate's fit: tube parameters and registration with the clearance model, 48 samples
    of Ha's measured trajectory, the workflow's default budget of model evaluations."""

    timeout = 900
    number = 1
    repeat = (2, 3, 120.0)
    warmup_time = 0.0

    def setup(self):
        from ctrplan.discrepancy.fits.calibrate import calibrate
        from ctrplan.discrepancy.fits.fitoptions import FitRun, FitStart
        from ctrplan.discrepancy.options import DiscrepancyOptions
        from ctrplan.discrepancy.setup import default_baseline_parameters

        robot, data = _ha_measured()
        sub = data.take(np.linspace(0, data.n_samples - 1, 48).astype(int))
        opts = DiscrepancyOptions()
        register = data.frame == "tracker"
        names = default_baseline_parameters(robot, register)
        run = FitRun(settings=opts.settings(), uncertainty=False)

        def fit(budget):
            return calibrate(robot, sub, "clearance", names, start=FitStart(None, register=register),
                             max_evaluations=budget, run=run)

        self.fit, self.budget = fit, opts.max_contact_evaluations
        fit(2)           # compiled kernels loaded

    def time_clearance_fit(self):
        self.fit(self.budget)


class Design:
    """One experiment design separating drive backlash from torsional friction (Table I pair)."""

    timeout = 900
    number = 1
    repeat = (2, 3, 120.0)
    warmup_time = 0.0

    def setup(self):
        import ctrplan.design as design
        from ctrplan.discrepancy.measured.data import load_measured_data
        from ctrplan.discrepancy.measured.synth import Noise, SynthProtocol, synthesize
        from ctrplan.io.robot_file import load_robot
        from ctrplan.mechanics import ModelSettings

        robot = load_robot(REPO / "model" / "ha2019-table1-tube-pair.toml").replace(friction_coefficients=(0.0,))
        self.settings = ModelSettings(ds=6e-3)
        made = synthesize(robot, {"backlash": {"backlash_2": np.deg2rad(3.0)}},
                          protocol=SynthProtocol.trajectory(120), noise=Noise(position_rms=5e-4), seed=3,
                          settings=self.settings)
        with tempfile.TemporaryDirectory(prefix="ctrplan-asv-design-") as folder:
            made.frame.to_csv(Path(folder) / "data.csv", index=False)
            self.data = load_measured_data(Path(folder) / "data.csv", robot)
        self.robot, self.design = robot, design
        self.hypotheses = (
            design.Hypothesis("backlash", "drive backlash", "standard", ("backlash_2",), np.array([np.deg2rad(3.0)]),
                              ("backlash_2",)),
            design.Hypothesis("friction", "torsional friction", "friction", ("mu_1",), np.array([0.3]), ("mu_1",)))
        self.limits = design.ExperimentLimits(duration=10.0)
        self.noise = design.SensorNoise(5e-4 / np.sqrt(3.0))

    def time_design(self):
        self.design.design_experiment(self.robot, self.data, self.hypotheses, noise=self.noise, limits=self.limits,
                                      settings=self.settings, search=self.design.DesignSearch(n_random=0))


class ContactDerivatives:
    """Tip derivatives of friction solutions (all columns) at 8 configurations of the 4x4x4 grid
    of the Table VII robot."""

    timeout = 300

    def setup(self):
        try:
            from ctrplan.mechanics.contact_sensitivity import contact_tip_jacobian
        except ImportError:
            raise NotImplementedError("no contact_tip_jacobian on this commit") from None
        from ctrplan.io.robot_file import load_robot
        from ctrplan.mechanics import ModelSettings, solve_contact, solve_standard

        robot = load_robot(REPO / "model" / "ha2019-table7-calibrated.toml")
        settings = ModelSettings()
        cases = []
        for q in _grid_configurations(robot):
            alpha, beta = robot.configuration(q)
            std = solve_standard(robot, alpha, beta, settings, check_stability=False)
            sol = solve_contact(robot, alpha, beta, settings, eta=np.ones(robot.n_tubes - 1), standard=std)
            if sol.diagnostics.converged:
                cases.append((alpha, beta, sol, std))
        self.robot, self.settings, self.cases, self.jacobian = robot, settings, cases, contact_tip_jacobian
        self.time_jacobian()   # compiled kernels loaded

    def time_jacobian(self):
        for alpha, beta, sol, std in self.cases:
            self.jacobian(self.robot, alpha, beta, sol, self.settings, standard=std)


def timeraw_quickstart_plan():
    """The Quick start's plan with its files, through the command line's entry point."""
    return f"""
import os, shutil, tempfile
from ctrplan.cli import main
out = tempfile.mkdtemp(prefix="ctrplan-asv-quickstart-")
os.chdir(out)
try:
    main(["plan", {str(REPO / "scenarios" / "obstacles.toml")!r}, "--out", out], standalone_mode=False)
finally:
    os.chdir("/")
    shutil.rmtree(out, ignore_errors=True)
"""


def timeraw_import():
    """``import ctrplan`` with the planning stages and their building blocks, in a fresh interpreter
    (through ``ctrplan.api``, which imports them at every commit)."""
    return "import ctrplan.api"


def timeraw_first_bound():
    """Import and the first friction bound in a fresh interpreter (compiled kernels from cache)."""
    return f"""
from ctrplan.io.robot_file import load_robot
from ctrplan.mechanics import evaluate_bound
robot = load_robot({str(REPO / "model" / "ha2019-table2-nominal.toml")!r})
evaluate_bound(robot, *robot.configuration(robot.joint_lower * 0.5 + robot.joint_upper * 0.5))
"""
