"""Accuracy and cost of forward-difference columns of the friction model's tips, as the experiment
design (``ctrplan.design.sensitivities``) and the discrepancy fits
(``ctrplan.discrepancy.fits.objective.ComponentJacobians``) take them, against central differences
of tightly converged solves.

Two cases, both continuous rotations back and forth sampled along the motion (every sample's
friction direction follows from the motion history, Eq. (39) of Ha, Fagogenis & Dupont 2019):

- ``pair``: the Table I tube pair (``model/ha2019-table1-tube-pair.toml``), mu_1 = 1.5, free
  parameters precurvature_y_2 and mu_1, 41 samples;
- ``three-tube``: the calibrated Table VII robot (``model/ha2019-table7-calibrated.toml``),
  mu = (0.6, 0.4), free parameters precurvature_y_1, precurvature_y_3, k_xy_relative_2, mu_1,
  mu_2, 40 samples.

The reference is the central difference over three times the design's step (1e-3 of the
parameter's scale, ``SENSITIVITY_STEP``) of cold solves with outer and complementarity tolerance
1e-12 (at most 300 outer iterations). Compared, each a forward difference:

- the design's step at the solver's default tolerance (1e-6), cold;
- the design's step at the design's ``SENSITIVITY_TOL``, each column's solves started from the
  base solution (:func:`ctrplan.design.sensitivities`);
- the fits' step (``DIFF_STEP`` times max(1, |value|), the step of ``least_squares``'s
  ``"2-point"`` scheme) at the fits' ``WARM_OUTER_TOL`` with warm starts, as a contact fit's
  columns are taken;

and, not a difference, the implicit-function derivatives of the solutions
(:func:`ctrplan.mechanics.contact_sensitivity.contact_tip_jacobian`) from solves at the solver's
default tolerance and at 1e-10, chained to
the named parameters (a precurvature_y_i scales every curved section of tube i; k_xy_relative_i
moves k_xy_i with the Poisson ratio held; mu_k acts where the history applies friction).

BLAS runs on one thread, as under ``ctrplan`` commands. Printed per setting: the CPU time of the base solve and its columns (one process; for the
implicit columns also that of the derivatives alone) and the relative error of each column
(Frobenius norm over the samples), with the load average.

Usage::

    python benchmarks/friction_columns_accuracy.py [--results benchmarks/results/friction-columns.json]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time
from pathlib import Path

# BLAS on one thread, as the command line runs (ctrplan.cli): OpenBLAS's idle threads otherwise
# spin after a threaded product and are counted in the CPU time of what follows
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

REFERENCE_TOL = 1e-12
REFERENCE_MAX_OUTER = 300
DEFAULT_TOL = 1e-6
# the implicit columns from solves this tight as well: a loose solve can settle a contact at the
# edge of the active set on the other side, and the derivative is that of the set it found
IMPLICIT_TIGHT_TOL = 1e-10


def _case(name):
    """``(robot, names, values, data)`` of a case of the module docstring."""
    from ctrplan.design import motion_data
    from ctrplan.discrepancy.fits.parameters import read_parameters
    from ctrplan.io.robot_file import load_robot

    if name == "pair":
        robot = load_robot(ROOT / "model" / "ha2019-table1-tube-pair.toml")
        names = ("precurvature_y_2", "mu_1")
        values = read_parameters(robot, names)
        values[1] = 1.5
        # alpha_2 through 0 -> 1.5 -> -0.5 -> 1.0 rad at 0.5 rad/s, sampled every 0.25 s
        path = np.array([0.0, 1.5, -0.5, 1.0])
        s = np.concatenate([[0.0], np.cumsum(np.abs(np.diff(path)))])
        t = np.arange(0.0, s[-1] / 0.5 + 1e-9, 0.25)
        q = np.interp(t * 0.5, s, path)[:, None]
        return robot, names, values, motion_data(robot, t, q)
    robot = load_robot(ROOT / "model" / "ha2019-table7-calibrated.toml")
    names = ("precurvature_y_1", "precurvature_y_3", "k_xy_relative_2", "mu_1", "mu_2")
    values = read_parameters(robot, names)
    values[3:] = (0.6, 0.4)
    q0 = robot.joint_vector(robot.home_alpha, robot.home_beta)
    t = np.arange(0.0, 8.0, 0.2)
    q = np.tile(q0, (len(t), 1))
    q[:, 0] += 1.5 * np.sin(2 * np.pi * t / 8)
    q[:, 1] -= 1.0 * np.sin(2 * np.pi * t / 4)
    return robot, names, values, motion_data(robot, t, q)


def _columns(robot, names, values, data, settings, *, warm: bool, central: float = 0.0, fit_step: bool = False):
    """Forward differences (``central`` = 0) over the design's step (the fits' with ``fit_step``),
    or central differences over ``central`` times the design's step; returns (J (K, 3, m), CPU
    seconds, share of samples converged)."""
    from ctrplan.design._criteria import SENSITIVITY_STEP
    from ctrplan.discrepancy import predict
    from ctrplan.discrepancy.fits.objective import DIFF_STEP
    from ctrplan.discrepancy.fits.parameters import parameter
    from ctrplan.discrepancy.fits.simulate import WarmStarts

    store = WarmStarts() if warm else None
    c0 = time.process_time()
    base = predict(robot, names, values, data, "friction", settings, warm_starts=store)
    ok = base.ok.copy()
    cols = []
    for j, name in enumerate(names):
        spec = parameter(robot, name)
        if fit_step:
            h = DIFF_STEP * max(1.0, abs(values[j])) * (1.0 if values[j] >= 0 else -1.0)
            h = h if spec.within_limit(values[j] + h) else -h
        else:
            h = SENSITIVITY_STEP * spec.scale * (central or 1.0)
        up = values.copy()
        up[j] += h
        p_up = predict(robot, names, up, data, "friction", settings, warm_starts=store)
        ok &= p_up.ok
        if central:
            down = values.copy()
            down[j] -= h
            p_down = predict(robot, names, down, data, "friction", settings, warm_starts=store)
            ok &= p_down.ok
            cols.append((p_up.tip - p_down.tip) / (2 * h))
        else:
            cols.append((p_up.tip - base.tip) / h)
    return np.stack(cols, axis=2), time.process_time() - c0, float(ok.mean())


def _directions(robot, names, rob):
    """(P, m) combinations of the tube parameters (``contact_parameter_columns``) that the named
    parameters move, at the robot ``rob`` with the values set; a mu column is per unit of the
    friction applied (scaled per sample)."""
    from ctrplan.discrepancy.fits.parameters import parameter
    from ctrplan.mechanics.contact_sensitivity import contact_parameter_columns

    cols = {c: i for i, c in enumerate(contact_parameter_columns(rob))}
    D = np.zeros((len(cols), len(names)))
    for j, name in enumerate(names):
        spec = parameter(robot, name)
        i = spec.index
        if spec.kind == "precurvature_y":
            curved = [(jj, sec) for jj, sec in enumerate(rob.tubes[i].sections) if not sec.is_straight]
            ref = curved[0][1].precurvature[1]
            for jj, sec in curved:
                D[cols[("precurvature", i, jj, 1)], j] = sec.precurvature[1] / ref
        elif spec.kind == "k_xy_relative":
            k_ref = rob.tubes[0].k_xy
            D[cols[("k_xy", i)], j] = k_ref
            D[cols[("k_z", i)], j] = k_ref / (1.0 + rob.tubes[i].poisson_ratio)
        elif name.startswith("mu_"):
            D[cols[("mu", i)], j] = 1.0
        else:
            raise ValueError(f"no implicit column for {name!r} in this benchmark")
    return D


def _implicit_columns(robot, names, values, data, settings):
    """Implicit-function columns (module docstring): (J (K, 3, m), CPU seconds, share of samples
    whose solve and derivative succeeded, CPU seconds of the derivatives alone)."""
    from ctrplan.discrepancy.fits.parameters import apply_parameters
    from ctrplan.effects import EffectSet
    from ctrplan.errors import CtrplanError
    from ctrplan.mechanics import solve_contact, solve_standard
    from ctrplan.mechanics.contact_sensitivity import contact_tip_jacobian

    c0 = time.process_time()
    rob = apply_parameters(robot, names, values)
    effects, _ = EffectSet.from_parameters(robot, names, values)
    state = data.state(rob, effects)
    eta, mu = state.applied(rob.friction_coefficients)
    mu_robot = np.asarray(rob.friction_coefficients, float)
    D = _directions(robot, names, rob)
    is_mu = np.array([name.startswith("mu_") for name in names])
    K = state.alpha.shape[0]
    J = np.full((K, 3, len(names)), np.nan)
    prev = None
    cpu_derivative = 0.0
    for k in range(K):
        a, b = state.alpha[k], state.beta[k]
        friction = bool(np.any(mu[k] > 0))
        try:
            std = solve_standard(rob, a, b, settings, check_stability=False)
            # a pair the history has not rotated yet carries no friction: any direction (as simulate)
            eta_k = np.where(eta[k] == 0, 1, eta[k])
            sol = solve_contact(rob, a, b, settings, eta=eta_k if friction else None, mu=mu[k] if friction else None,
                                standard=std, warm_start=prev)
            finite = np.all(np.isfinite(np.concatenate(sol.curvatures)))
            if friction and not (sol.diagnostics.converged and finite):
                # started from the clearance solution here instead, as simulate does
                start = solve_contact(rob, a, b, settings, standard=std)
                sol = solve_contact(rob, a, b, settings, eta=eta_k, mu=mu[k], standard=std, warm_start=start)
            prev = sol
            # the friction applied at this sample per unit of the robot's coefficient
            scale = np.ones(len(names))
            for j in np.nonzero(is_mu)[0]:
                i = int(names[j].rpartition("_")[2]) - 1
                scale[j] = mu[k, i] / mu_robot[i] if mu_robot[i] > 0 else 0.0
            c1 = time.process_time()
            jac = contact_tip_jacobian(rob, a, b, sol, settings, directions=D * scale[None, :], standard=std)
            cpu_derivative += time.process_time() - c1
        except CtrplanError:
            prev = None
            continue
        J[k] = jac.d_position
    return J, time.process_time() - c0, float(np.isfinite(J).all(axis=(1, 2)).mean()), cpu_derivative


def main(argv=None):
    from _records import run_record

    from ctrplan.design._criteria import SENSITIVITY_TOL
    from ctrplan.discrepancy.fits.simulate import WARM_OUTER_TOL
    from ctrplan.mechanics import ModelSettings

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--results", default=None, help="write the figures to this JSON file")
    args = ap.parse_args(argv)
    load0 = os.getloadavg()
    print(f"load average {load0[0]:.2f}")
    out = {"cases": {}}
    for case in ("pair", "three-tube"):
        robot, names, values, data = _case(case)
        ref_settings = dataclasses.replace(ModelSettings(), outer_tol=REFERENCE_TOL, complementarity_tol=REFERENCE_TOL,
                                           max_outer_iterations=REFERENCE_MAX_OUTER)
        ref, _, ref_ok = _columns(robot, names, values, data, ref_settings, warm=False, central=3.0)
        rows = {}
        for label, tol, warm, fit_step in (("design step, default tol", DEFAULT_TOL, False, False),
                                           ("design step, design tol", SENSITIVITY_TOL, True, False),
                                           ("fit step, fit tol", WARM_OUTER_TOL, True, True),
                                           ("implicit, default tol", DEFAULT_TOL, False, None),
                                           ("implicit, tol 1e-10", IMPLICIT_TIGHT_TOL, False, None)):
            settings = dataclasses.replace(ModelSettings(), outer_tol=tol, complementarity_tol=tol)
            cpu_derivative = None
            if fit_step is None:
                J, cpu, ok, cpu_derivative = _implicit_columns(robot, names, values, data, settings)
            else:
                J, cpu, ok = _columns(robot, names, values, data, settings, warm=warm, fit_step=fit_step)
            good = np.isfinite(J).all(axis=(1, 2)) & np.isfinite(ref).all(axis=(1, 2))
            err = {n: float(np.linalg.norm(J[good, :, j] - ref[good, :, j]) / np.linalg.norm(ref[good, :, j]))
                   for j, n in enumerate(names)}
            rows[label] = {"tolerance": tol, "warm": warm, "step": {True: "fit", False: "design", None: "implicit"}[fit_step], "cpu_s": cpu,
                           "converged": ok, "relative_error": err}
            if cpu_derivative is not None:
                rows[label]["derivative_cpu_s"] = cpu_derivative
            part = "" if cpu_derivative is None else f" (derivatives {cpu_derivative:.2f} s)"
            print(f"{case:10s} {label:25s} tol {tol:.0e}: CPU {cpu:6.2f} s{part}, converged {100 * ok:.0f} %, error "
                  + ", ".join(f"{n} {100 * e:.3g} %" for n, e in err.items()), flush=True)
        out["cases"][case] = {"samples": int(data.n_samples), "parameters": dict(zip(names, values.tolist())),
                              "reference_converged": ref_ok, "settings": rows}
    out["run"] = run_record("python benchmarks/friction_columns_accuracy.py", load0, os.getloadavg())
    if args.results:
        Path(args.results).write_text(json.dumps(out, indent=1) + "\n")
        print(f"wrote {args.results}")


if __name__ == "__main__":
    main()
