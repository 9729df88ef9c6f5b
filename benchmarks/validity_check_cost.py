"""Cost of the planner's validity checks per state and per motion: the batched checker against
the per-state reference checker, side by side, with their decisions compared.

On ``scenarios/obstacles.toml`` (its robot, obstacles, model settings with ``multistart=0`` and
the shipped bound map, loaded as ``ctrplan.pipeline.load_bound_map`` loads it), in one process:

1. states: the same seeded random states (default 600) go, one at a time, through the per-state
   :class:`ctrplan.planning.ValidityChecker` and the batched
   :class:`ctrplan.planning.validity.BatchValidityChecker` (``__call__``), alternating which
   goes first; per-state wall times of both (mean, median, 90th percentile, max, and the
   ratios), how many states reached the model, the collision test, and the fcl narrow phase
   (states whose capsules survived the broad phase), the per-state checker's time split into
   ``solve_standard`` and the capsule-manager collision query (first 100 states), and the batched
   checker's cost per state when all states come in one ``check`` call;
2. motions: the same seeded random straight motions (default 200, at most 40 mm long in the
   weighted metric, about RRT*'s default range on this space) checked by the batched
   ``check_motion`` and by the per-state checker at the same states in the same order with the same
   early exit (what OMPL's DiscreteMotionValidator does with it), each with fresh caches; cost
   per motion and per evaluated state, and the ratios.

Decisions of both checkers are compared and mismatches counted. The machine is shared: the
load average (``os.getloadavg()``) is printed before and after, and the ratios matter more than
the absolute times. The first calls (numba cache loading) are run before timing.

Usage::

    python benchmarks/validity_check_cost.py      # 600 states, 200 motions
    python benchmarks/validity_check_cost.py --states 200 --motions 50 --seed 3
"""

from __future__ import annotations

import argparse
import logging
import os
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
SCENARIO = REPO / "scenarios" / "obstacles.toml"
# Longest benchmark motion [m of the weighted joint metric]: about RRT*'s default range
# (0.2 x the space's maximum extent, 0.196 m for the Table VII joints).
MAX_MOTION_LENGTH = 0.04


def _load_field(sc, settings):
    """The scenario's bound map, loaded as ctrplan.pipeline.load_bound_map loads it (shipped, cached, else
    computed)."""
    from ctrplan.boundmap import load_or_compute_bound_map
    from ctrplan.pipeline import map_spec

    return load_or_compute_bound_map(sc.robot_file, sc.robot, map_spec(sc), settings, n_jobs=1,
                                     progress=True)


def _stats(label, t_single, t_batch, unit="ms"):
    """Print mean, median, p90, max of two arrays of times [s] and their ratios."""
    f = 1e3
    rows = []
    for name, t in (("per-state ValidityChecker", t_single), ("BatchValidityChecker", t_batch)):
        rows.append(f"  {name:26s} mean {t.mean() * f:8.3f}  median {np.median(t) * f:8.3f}  "
                    f"p90 {np.percentile(t, 90) * f:8.3f}  max {t.max() * f:8.3f}  [{unit}]")
    print(label)
    print("\n".join(rows))
    print(f"  ratio per-state/batched    mean {t_single.mean() / t_batch.mean():8.1f}  median "
          f"{np.median(t_single) / np.median(t_batch):8.1f}  "
          f"p90 {np.percentile(t_single, 90) / np.percentile(t_batch, 90):8.1f}"
          f"  max {t_single.max() / t_batch.max():8.1f}  [-]")


def main(argv=None) -> int:
    logging.basicConfig(format="%(message)s")       # ctrplan's messages (INFO and up) as plain lines
    logging.getLogger("ctrplan").setLevel(logging.INFO)
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--states", type=int, default=600, help="random states (default 600)")
    ap.add_argument("--motions", type=int, default=200, help="random motions (default 200)")
    ap.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    args = ap.parse_args(argv)

    from threadpoolctl import threadpool_limits

    threadpool_limits(1)
    from ctrplan.io.scenario import load_scenario
    from ctrplan.mechanics import ModelSettings, solve_standard
    from ctrplan.planning.route import DEFAULT_COLLISION_SEGMENT as COLLISION_SEGMENT
    from ctrplan.planning import CollisionChecker, JointStateSpace, ValidityChecker
    from ctrplan.planning.planners import DEFAULT_VALIDITY_RESOLUTION
    from ctrplan.planning.validity import BatchValidityChecker

    print(f"load average before (1, 5, 15 min): {os.getloadavg()}")
    sc = load_scenario(SCENARIO)
    robot = sc.robot
    settings = ModelSettings(ds=sc.bound_field.ds) if sc.bound_field.ds else ModelSettings()
    field, source, seconds = _load_field(sc, settings)
    print(f"bound map: {source} in {seconds:.2f} s")
    check_settings = settings.replace(multistart=0)   # as the pipeline builds its checker
    js = JointStateSpace(robot)
    obstacles = [o.as_dict() for o in sc.obstacles]

    def checkers():
        collision = CollisionChecker(obstacles, segment_length=COLLISION_SEGMENT)
        single = ValidityChecker(robot, collision=collision, field=field, settings=check_settings)
        batch = BatchValidityChecker(robot, collision=collision, field=field, settings=check_settings,
                                   joint_space=js, resolution=DEFAULT_VALIDITY_RESOLUTION)
        return single, batch, collision

    rng = np.random.default_rng(args.seed)
    lo, hi = robot.joint_lower, robot.joint_upper
    warm = lo + (hi - lo) * rng.random((4, lo.size))
    single, batch, _ = checkers()
    for q in warm:                       # numba cache loading, imports, first fcl objects
        single(q), batch(q)
    batch.check(warm + 1e-3)

    # ------------------------------------------------------------------ states
    Q = lo + (hi - lo) * rng.random((args.states, lo.size))
    single, batch, collision = checkers()
    t_single = np.empty(len(Q))
    t_batch = np.empty(len(Q))
    v_single = np.empty(len(Q), dtype=bool)
    v_batch = np.empty(len(Q), dtype=bool)
    clock = time.perf_counter
    for i, q in enumerate(Q):
        single_first = i % 2 == 0
        for which in ((0, 1) if single_first else (1, 0)):
            t0 = clock()
            if which == 0:
                v_single[i] = single(q)
                t_single[i] = clock() - t0
            else:
                v_batch[i] = batch(q)
                t_batch[i] = clock() - t0
    print(f"\n{len(Q)} random states of {SCENARIO.name} (one call per state, the same states, side by side):")
    _stats("per-state wall time", t_single, t_batch)
    print(f"  valid: per-state {v_single.sum()}, batched {v_batch.sum()}, mismatches {np.sum(v_single != v_batch)}")
    print(f"  batched checker: {batch.n_model} states reached the standard model, {batch.n_collision_checked} the "
          f"collision test, {collision.n_batch_narrow_bodies} the fcl narrow phase "
          f"({collision.n_batch_narrow_calls} fcl.collide calls); time in the model "
          f"{batch.seconds_model / len(Q) * 1e3:.3f} ms/state, in collision "
          f"{batch.seconds_collision / len(Q) * 1e3:.3f} ms/state")
    n_split = min(100, len(Q))
    t_solve, t_body = np.empty(n_split), np.empty(n_split)
    for i, q in enumerate(Q[:n_split]):     # where the per-state checker's time goes
        alpha, beta = robot.configuration(q)
        t0 = clock()
        sol = solve_standard(robot, alpha, beta, check_settings)
        t_solve[i] = clock() - t0
        t0 = clock()
        collision.check_body(*sol.body(robot))
        t_body[i] = clock() - t0
    print(f"  per-state checker, first {n_split} states: solve_standard {t_solve.mean() * 1e3:.3f} ms/state, body + "
          f"capsule manager + fcl {t_body.mean() * 1e3:.3f} ms/state (means)")
    _, fresh, _ = checkers()
    t0 = clock()
    v_all = fresh.check(Q)
    t_all = clock() - t0
    print(f"  batched checker, all {len(Q)} states in one check() call: {t_all / len(Q) * 1e3:.3f} ms/state "
          f"(ratio to the per-state mean {t_single.mean() / (t_all / len(Q)):.1f}); "
          f"mismatches {np.sum(v_all != v_single)}")

    # ------------------------------------------------------------------ motions
    q0 = lo + (hi - lo) * rng.random((args.motions, lo.size))
    q1 = lo + (hi - lo) * rng.random((args.motions, lo.size))
    lengths = MAX_MOTION_LENGTH * rng.random(args.motions)
    d = js.difference(q0, q1)
    scale = np.minimum(1.0, lengths / js.distance(q0, q1))
    q1 = q0 + d * scale[:, None]
    single, batch, collision = checkers()
    tm_single = np.empty(args.motions)
    tm_batch = np.empty(args.motions)
    n_single = np.zeros(args.motions, dtype=np.int64)
    n_batch = np.zeros(args.motions, dtype=np.int64)
    r_single = np.empty(args.motions, dtype=bool)
    r_batch = np.empty(args.motions, dtype=bool)
    n_states = np.empty(args.motions, dtype=np.int64)
    for i in range(args.motions):
        states = batch.motion_states(q0[i], q1[i])
        n_states[i] = len(states)
        for which in ((0, 1) if i % 2 == 0 else (1, 0)):
            if which == 0:
                before = single.n_evaluations
                t0 = clock()
                ok = True
                for q in states:          # OMPL's DiscreteMotionValidator with the per-state checker
                    if not single(q):
                        ok = False
                        break
                tm_single[i] = clock() - t0
                r_single[i], n_single[i] = ok, single.n_evaluations - before
            else:
                before = batch.n_evaluations
                t0 = clock()
                r_batch[i] = batch.check_motion(q0[i], q1[i])
                tm_batch[i] = clock() - t0
                n_batch[i] = batch.n_evaluations - before
    print(f"\n{args.motions} random straight motions (<= {MAX_MOTION_LENGTH * 1e3:.0f} mm in the weighted metric, "
          f"{n_states.mean():.1f} states on average at {DEFAULT_VALIDITY_RESOLUTION * 1e3:.0f} mm resolution):")
    _stats("per-motion wall time", tm_single, tm_batch)
    print(f"  per evaluated state: per-state {tm_single.sum() / max(n_single.sum(), 1) * 1e3:.3f} ms "
          f"({n_single.sum()} states), "
          f"batched {tm_batch.sum() / max(n_batch.sum(), 1) * 1e3:.3f} ms ({n_batch.sum()} states, batches up to "
          f"{batch.batch_size}); total time ratio per-state/batched {tm_single.sum() / tm_batch.sum():.1f}")
    print(f"  valid motions: per-state {r_single.sum()}, batched {r_batch.sum()}, "
          f"mismatches {np.sum(r_single != r_batch)}; "
          f"states reaching the fcl narrow phase (batched) {collision.n_batch_narrow_bodies}")
    print(f"\nload average after (1, 5, 15 min): {os.getloadavg()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
