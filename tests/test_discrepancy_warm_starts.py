"""Contact solves of a fit started from the previous evaluation's solutions
(:class:`ctrplan.discrepancy.fits.simulate.WarmStarts`).

What must hold, checked against solves that do not use the store (Sections II-E and III of Ha,
Fagogenis & Dupont 2019, doi:10.1109/TRO.2018.2878906; Table II robot of tests/_robots.py):

- the same tips, to the solver's tolerance, whatever the store holds;
- forward differences over a relative parameter step of 1e-4 (the least-squares Jacobian of
  :mod:`ctrplan.discrepancy.fits.calibrate`) as accurate as central differences of tightly converged
  cold solves: the reason for :data:`~ctrplan.discrepancy.fits.simulate.WARM_OUTER_TOL`;
- the same values in one process and in worker processes (what a fit finds may not depend on how
  many workers run it);
- fewer outer iterations (the point of the store).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from ctrplan.discrepancy.fits.parameters import apply_parameters, read_parameters
from ctrplan.discrepancy.fits.simulate import WARM_OUTER_TOL, WarmStarts, simulate
from ctrplan.history import MotionRecord, motion_state
from ctrplan.mechanics import ModelSettings

from _robots import table2_robot

DS = 0.004  # [m] coarse arc-length step, for speed
TIGHT = ModelSettings(ds=DS, multistart=0, outer_tol=WARM_OUTER_TOL, complementarity_tol=WARM_OUTER_TOL)
REFERENCE = dataclasses.replace(TIGHT, outer_tol=1e-9, complementarity_tol=1e-10, max_outer_iterations=200)


@pytest.fixture(scope="module")
def robot():
    return table2_robot(mu=0.2)


@pytest.fixture(scope="module")
def motion(robot):
    """A continuous motion of the Table II robot: tube rotations back and forth with a translation
    of tube 3 (friction directions change along it), one sequence of 16 samples."""
    rng = np.random.default_rng(7)
    K = 16
    t = np.linspace(0.0, 1.0, K)
    q = np.column_stack([1.2 * np.sin(2 * np.pi * t), -0.8 * np.sin(3 * np.pi * t + 0.3),
                         -0.06 + 0.02 * np.cos(2 * np.pi * t)])
    q += rng.normal(0.0, 1e-3, q.shape)
    alpha, beta = zip(*[robot.configuration(x) for x in q])
    alpha, beta = np.array(alpha), np.array(beta)
    seq = np.zeros(K, dtype=int)
    state = motion_state(MotionRecord(alpha, beta, sequence=seq))
    eta, mu = state.applied(robot.friction_coefficients)
    return alpha, beta, seq, eta, mu


def _tips(robot, motion, settings, model, store=None, n_jobs=1, mu_scale=1.0):
    alpha, beta, seq, eta, mu = motion
    friction = model == "friction"
    sim = simulate(robot, alpha, beta, model=model, eta=eta if friction else None,
                   mu=mu * mu_scale if friction else None, sequence=seq, settings=settings,
                   warm_starts=store, n_jobs=n_jobs)
    assert sim.ok.all(), sim.message
    return sim


@pytest.mark.parametrize("model", ["clearance", "friction"])
def test_stored_starts_give_the_cold_solution(robot, motion, model):
    """Tips from a store filled at other parameters (another precurvature, other friction
    coefficients) equal the cold tightly converged ones to far below a micrometre. A store that
    handed a solution of the wrong configuration or friction direction, or returned a start
    without iterating, fails this."""
    reference = _tips(robot, motion, REFERENCE, model).tip
    store = WarmStarts()
    other = apply_parameters(robot, ("precurvature_y_1",), read_parameters(robot, ("precurvature_y_1",)) * 1.03)
    _tips(other, motion, TIGHT, model, store, mu_scale=1.5)
    assert len(store) > 0
    warm = _tips(robot, motion, TIGHT, model, store)
    assert warm.n_warm > 0
    assert np.max(np.linalg.norm(warm.tip - reference, axis=1)) < 2e-8


@pytest.mark.parametrize("model", ["clearance", "friction"])
def test_forward_differences_from_stored_starts_are_accurate(robot, motion, model):
    """A forward difference of the tip over a relative step of 1e-4 in tube 1's precurvature,
    the perturbed solve started from the base solution, agrees with a central difference of
    cold solves converged to 1e-9 m within 1 % of its size at every sample. With the default
    outer tolerance (1e-6 m) the same forward difference is off by tens of per cent (checked
    here too, so that the test keeps measuring the tolerance it is about)."""
    name = ("precurvature_y_1",)
    x = read_parameters(robot, name)
    h = 1e-4 * abs(x[0])
    plus, minus = (apply_parameters(robot, name, x + d) for d in (h, -h))
    reference = (_tips(plus, motion, REFERENCE, model).tip - _tips(minus, motion, REFERENCE, model).tip) / (2 * h)
    size = np.linalg.norm(reference, axis=1)
    assert np.all(size > 1e-4)

    def forward(settings):
        store = WarmStarts()
        base = _tips(robot, motion, settings, model, store).tip
        return (_tips(plus, motion, settings, model, store).tip - base) / h

    err = np.linalg.norm(forward(TIGHT) - reference, axis=1) / size
    assert np.max(err) < 0.01
    loose = dataclasses.replace(TIGHT, outer_tol=1e-6, complementarity_tol=1e-6)
    err_loose = np.linalg.norm(forward(loose) - reference, axis=1) / size
    assert np.max(err_loose) > 0.05


def test_store_gives_the_same_values_in_worker_processes(robot, motion, monkeypatch):
    """The same evaluations through the same store in one process and on two workers give the
    same tips to 1e-12 m: a store scoped to one sequence of evaluations keeps a fit's values
    independent of the number of workers."""
    import importlib

    simulate_module = importlib.import_module("ctrplan.discrepancy.fits.simulate")

    monkeypatch.setattr(simulate_module, "_MIN_PARALLEL_SECONDS", 0.0)   # this short motion on two workers
    other = apply_parameters(robot, ("precurvature_y_1",), read_parameters(robot, ("precurvature_y_1",)) * 1.01)
    tips = []
    for n_jobs in (1, 2):
        store = WarmStarts()
        _tips(robot, motion, TIGHT, "friction", store, n_jobs=n_jobs)
        sim = _tips(other, motion, TIGHT, "friction", store, n_jobs=n_jobs)
        assert sim.n_warm > 0
        tips.append(sim.tip)
    assert np.max(np.abs(tips[0] - tips[1])) < 1e-12


def test_stored_starts_need_fewer_outer_iterations(robot, motion):
    """Started from the solutions at a nearby precurvature, the friction solves of the motion take
    at most two thirds of the outer iterations of cold solves to the same tolerance."""
    from ctrplan.mechanics import solve_contact, solve_standard

    alpha, beta, seq, eta, mu = motion
    other = apply_parameters(robot, ("precurvature_y_1",), read_parameters(robot, ("precurvature_y_1",)) * 1.001)
    store = WarmStarts()
    _tips(robot, motion, TIGHT, "friction", store)
    cold = warm = 0
    for k in range(len(alpha)):
        std = solve_standard(other, alpha[k], beta[k], TIGHT, check_stability=False)
        friction = bool(np.any(mu[k] > 0))
        e = np.where(eta[k] == 0, 1, eta[k]) if friction else None
        start = store.get(WarmStarts.key(alpha[k], beta[k], e))
        assert start is not None
        kw = dict(eta=e, mu=mu[k] if friction else None, standard=std)
        clearance = solve_contact(other, alpha[k], beta[k], TIGHT, standard=std) if friction else None
        cold += solve_contact(other, alpha[k], beta[k], TIGHT, warm_start=clearance, **kw).diagnostics.iterations
        warm += solve_contact(other, alpha[k], beta[k], TIGHT, warm_start=start, **kw).diagnostics.iterations
    assert warm <= 2 * cold / 3
