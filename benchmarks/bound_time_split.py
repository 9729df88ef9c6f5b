"""Where the full bound's time goes: solves, outer iterations, kernels, Python.

Three parts, all in CPU time of this process (``time.process_time``; run it alone, the load
average is printed at the start and the end):

1. **Per solve** on the 4x4x4 grid of the paper's Section IV-D (Table II robot): the clearance
   solve and the 2^(n-1) friction solves of each bound, with their outer iterations, Newton
   iterations and time in the compiled outer loop, and the rest of ``evaluate_bound`` (building
   the problem, the warm starts, the results: Python).
2. **Per outer iteration**: the kernels of one re-linearization, each timed in a compiled loop of
   ``--repeat`` calls at a converged friction solution of a grid configuration: forward
   kinematics, the linearization (prefix sums), contact frames and projections, the compliance
   columns of the active contacts, the active-block factorization with the displacements, the
   displacements of the other contacts, the generalized curvatures, one complete
   ``solve_contacts`` from the converged multipliers; and LAPACK's LU and multi-right-hand-side
   solve at the active block's size.
3. **Six-joint robot** (``--six-joint N``, default 40): the bound per configuration on N random
   valid configurations of ``model/ha2019-table2-six-joint.toml`` (seeded), and how many exact
   bounds two cores compute in a given wall time (``--budget``, seconds) at that rate.

Run:  OPENBLAS_NUM_THREADS=1 python benchmarks/bound_time_split.py [--repeat 2000] [--six-joint 40]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402
from numba import njit  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

from ctrplan.io.robot_file import load_robot  # noqa: E402
from ctrplan.mechanics import ModelSettings, evaluate_bound, solve_standard  # noqa: E402
from ctrplan.mechanics import _contact_fast as cf, _contact_kernels as ck  # noqa: E402
from ctrplan.mechanics._chain_kernels import chain_kinematics  # noqa: E402
from ctrplan.mechanics._lapack import PIVOT_DTYPE, lu_factor, lu_solve_matrix  # noqa: E402


def _stats(x):
    x = np.asarray(x)
    return (f"mean {x.mean():8.3f}  median {np.median(x):8.3f}  p90 {np.percentile(x, 90):8.3f}  "
            f"max {x.max():8.3f}")


def per_solve(robot, configs, settings):
    """Part 1: time in the compiled outer loop per solve kind, and the rest of the bound [ms]."""
    records = []
    outer_loop = cf._outer_loop

    def timed(u, lam, arr, scr, work, opt):
        t0 = time.process_time()
        out = outer_loop(u, lam, arr, scr, work, opt)
        records.append((bool(arr.friction), out[5], out[6], time.process_time() - t0))
        return out

    standards = [solve_standard(robot, a, b, settings) for a, b in configs]
    evaluate_bound(robot, *configs[0], settings, standard=standards[0])
    total = []
    cf._outer_loop = timed
    try:
        for (a, b), st in zip(configs, standards):
            records.clear()
            t0 = time.process_time()
            evaluate_bound(robot, a, b, settings, standard=st)
            total.append((time.process_time() - t0, list(records)))
    finally:
        cf._outer_loop = outer_loop
    bound = np.array([t for t, _ in total]) * 1e3
    loops = np.array([sum(r[3] for r in rec) for _, rec in total]) * 1e3
    print(f"\n1. full bound per configuration (standard solution given), {len(configs)} configurations [ms]:")
    print(f"   evaluate_bound       {_stats(bound)}")
    print(f"   compiled outer loops {_stats(loops)}")
    print(f"   the rest (Python)    {_stats(bound - loops)}  ({np.sum(bound - loops) / np.sum(bound):.1%} of the time)")
    for kind, name in ((False, "clearance"), (True, "friction")):
        rec = np.array([r for _, rs in total for r in rs if r[0] == kind], dtype=float)
        print(f"   {name:9s} solves: {len(rec) / len(configs):.0f} per bound, outer iterations "
              f"{rec[:, 1].mean():.2f}, Newton {rec[:, 2].mean():.1f} per solve, "
              f"{rec[:, 3].mean() * 1e3:.3f} ms per solve, {rec[:, 3].sum() / rec[:, 1].sum() * 1e6:.0f} us "
              f"per outer iteration")


@njit
def _k_chain(n, u, arr, R, p):
    for _ in range(n):
        chain_kinematics(u, arr.h, arr.alpha, arr.beta, arr.node_off, R, p)


@njit
def _k_linearize(n, u, arr, scr, R, p):
    for _ in range(n):
        ck.linearize(u, arr.uhat, arr.kinv, arr.h, arr.node_off, R, p, scr.Omega, scr.base, scr.H1, scr.H2,
                     scr.F3, scr.Jpv)


@njit
def _k_frames(n, R, p, arr, scr):
    for _ in range(n):
        ck.contact_frames(R, p, arr.jo, arr.ji, scr.Jpv, scr.B, scr.dfree, scr.diagW, scr.H1, scr.H2, arr.pair)
        ck.contact_projections(scr.B, p, arr.jo, arr.ji, scr.H1, scr.H2, scr.Pc)


@njit
def _k_columns(n, work, geometry, law, active_mask, active):
    for _ in range(n):
        work.have[:] = False
        work.rows[:] = False
        ck.extend_rows(active_mask, work, geometry, law)
        ck.fill_columns(active, work, geometry, law)


@njit
def _k_displacements(n, lam, active, dfree, law, work):
    d = np.empty((lam.shape[0], 2))
    for _ in range(n):
        ck._displacements(lam, active, dfree, law.Mblk, work.Wt, work.Zt, law.friction, d, active)


@njit
def _k_complete(n, lam, d, known, dfree, geometry, law):
    for _ in range(n):
        ck._complete_displacements(lam, d, known, True, dfree, geometry, law)


@njit
def _k_curvature(n, lam, d, geometry, law, uhat, g):
    for _ in range(n):
        ck.generalized_curvature(lam, d, geometry, law, uhat, g)


@njit
def _k_solve(n, lam, dfree, geometry, law, work, tol, maxit):
    its = 0
    for _ in range(n):
        work.have[:] = False
        work.rows[:] = False
        its = ck.solve_contacts(lam, dfree, geometry, law, work, tol, maxit).iterations
    return its


@njit
def _k_lu(n, A):
    B = np.empty_like(A)
    piv = np.empty(A.shape[0], dtype=PIVOT_DTYPE)
    for _ in range(n):
        B[:, :] = A
        lu_factor(B, piv)


@njit
def _k_copy(n, A):
    B = np.empty_like(A)
    for _ in range(n):
        B[:, :] = A


@njit
def _k_solve_matrix(n, LU, piv, C):
    X = np.empty_like(C)
    for _ in range(n):
        X[:, :] = C
        lu_solve_matrix(LU, piv, X)


def _per_call(kernel, *args, repeat):
    kernel(1, *args)   # compile
    t0 = time.process_time()
    kernel(repeat, *args)
    return (time.process_time() - t0) / repeat * 1e6


def per_iteration(robot, config, settings, repeat):
    """Part 2: the kernels of one re-linearization at a converged friction solution [us]."""
    a, b = config
    bound = evaluate_bound(robot, a, b, settings)
    eta = sorted(bound.friction)[0]
    sol = bound.friction[eta]
    prob = cf.FlatProblem(robot, bound.standard, np.asarray(eta, dtype=float),
                          np.asarray(robot.friction_coefficients, dtype=float))
    arr, scr, work = prob.outer_arrays(), prob.outer_scratch(), prob._work
    u = np.concatenate(sol.curvatures)
    lam = np.asarray(sol.multipliers, dtype=float)
    R, p = prob.kinematics(u)
    ck.linearize(u, arr.uhat, arr.kinv, arr.h, arr.node_off, R, p, scr.Omega, scr.base, scr.H1, scr.H2, scr.F3,
                 scr.Jpv)
    ck.contact_frames(R, p, arr.jo, arr.ji, scr.Jpv, scr.B, scr.dfree, scr.diagW, scr.H1, scr.H2, arr.pair)
    ck.contact_projections(scr.B, p, arr.jo, arr.ji, scr.H1, scr.H2, scr.Pc)
    M = prob.M
    kappa = 1.0 / ((scr.diagW[:, 0, 0].sum() + scr.diagW[:, 1, 1].sum()) / (2 * M))
    geometry = cf._contact_geometry(arr, scr, R, p)
    law = cf._contact_law(arr, kappa)
    mask = lam > 0
    active = np.nonzero(mask)[0]
    d = np.zeros((M, 2))
    g = np.empty_like(u)
    rows = [
        ("forward kinematics", _per_call(_k_chain, u, arr, R, p, repeat=repeat)),
        ("linearization (prefix sums)", _per_call(_k_linearize, u, arr, scr, R, p, repeat=repeat)),
        ("contact frames + projections", _per_call(_k_frames, R, p, arr, scr, repeat=repeat)),
        ("compliance columns, active set", _per_call(_k_columns, work, geometry, law, mask, active, repeat=repeat)),
        ("active block LU + displacements", _per_call(_k_displacements, lam, active, scr.dfree, law, work,
                                                      repeat=repeat)),
    ]
    ck._displacements(lam, active, scr.dfree, law.Mblk, work.Wt, work.Zt, law.friction, d, active)
    rows += [
        ("displacements of the others", _per_call(_k_complete, lam, d, mask, scr.dfree, geometry, law,
                                                  repeat=repeat)),
        ("generalized curvatures", _per_call(_k_curvature, lam, d, geometry, law, arr.uhat, g, repeat=repeat)),
    ]
    its = _k_solve(1, lam, scr.dfree, geometry, law, work, settings.complementarity_tol,
                   settings.max_newton_iterations)
    rows.append((f"solve_contacts from the solution ({its} Newton)",
                 _per_call(_k_solve, lam, scr.dfree, geometry, law, work, settings.complementarity_tol,
                           settings.max_newton_iterations, repeat=max(repeat // 4, 1))))
    m = 2 * active.size
    rng = np.random.default_rng(1)
    A = np.eye(m) + 0.1 * rng.standard_normal((m, m))
    LU = A.copy()
    piv = np.empty(m, dtype=PIVOT_DTYPE)
    lu_factor(LU, piv)
    C = rng.standard_normal((active.size + 5, m))
    copy_us = _per_call(_k_copy, A, repeat=repeat)
    rows += [
        (f"LAPACK LU, n = {m}", _per_call(_k_lu, A, repeat=repeat) - copy_us),
        (f"LAPACK solve, n = {m}, {C.shape[0]} right-hand sides", _per_call(_k_solve_matrix, LU, piv, C,
                                                                           repeat=repeat)),
    ]
    print(f"\n2. one re-linearization at a converged friction solution ({prob.N} nodes, {M} contacts, "
          f"{active.size} active, eta = {eta}), per call [us]:")
    for name, us in rows:
        print(f"   {name:48s} {us:8.1f}")


def six_joint(n, budget, settings):
    """Part 3: the bound on random valid configurations of the six-joint robot [ms]."""
    robot = load_robot(ROOT / "model" / "ha2019-table2-six-joint.toml")
    rng = np.random.default_rng(7)
    lo, hi = robot.joint_lower, robot.joint_upper
    configs = []
    while len(configs) < n:
        q = lo + (hi - lo) * rng.random(lo.size)
        try:
            a, b = robot.configuration(q)
            robot.check_configuration(a, b)
        except ValueError:
            continue
        configs.append((a, b))
    evaluate_bound(robot, *configs[0], settings)
    T, S = [], []
    for a, b in configs:
        t0 = time.process_time()
        st = solve_standard(robot, a, b, settings)
        S.append(time.process_time() - t0)
        t0 = time.process_time()
        evaluate_bound(robot, a, b, settings, standard=st)
        T.append(time.process_time() - t0)
    T = np.array(T) * 1e3
    print(f"\n3. six-joint robot, {n} random valid configurations (seed 7) [ms]:")
    print(f"   full bound (standard given) {_stats(T)}")
    print(f"   standard model (multistart) {_stats(np.array(S) * 1e3)}")
    print(f"   exact bounds two cores compute in {budget:.0f} s at the mean rate: {int(2 * budget / (T.mean() * 1e-3))}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=2000, help="calls per kernel timing")
    ap.add_argument("--six-joint", type=int, default=40, help="random configurations of the six-joint robot")
    ap.add_argument("--budget", type=float, default=235.0,
                    help="wall seconds of exact bounds for the projection of part 3")
    args = ap.parse_args(argv)
    from paper_section_4d import grid_4x4x4
    print(f"load average at the start: {os.getloadavg()}")
    settings = ModelSettings()
    robot = load_robot(ROOT / "model" / "ha2019-table2-nominal.toml")
    _, Q = grid_4x4x4(robot)
    configs = [robot.configuration(q) for q in Q]
    per_solve(robot, configs, settings)
    per_iteration(robot, configs[20], settings, args.repeat)
    if args.six_joint > 0:
        six_joint(args.six_joint, args.budget, settings)
    print(f"\nload average at the end: {os.getloadavg()}")


if __name__ == "__main__":
    main()
