from types import SimpleNamespace

import numpy as np
import pytest

from ctrplan.boundmap import (BoundField, BoundFieldKeyError, ComputeOptions, compute_field, field_key,
                              interpolation_error, load_bound_map, uniform_axis)
from ctrplan.mechanics.results import ModelSettings
from test_planning_helpers import fake_bound, fake_robot

RES = (8, 6, 4)


class CountingBound:
    """Same name (hence same cache key) as fake_bound; counts evaluations."""

    name = "fake-bound"

    def __init__(self):
        self.calls = 0

    def __call__(self, robot, alpha, beta, settings=None):
        self.calls += 1
        return fake_bound(robot, alpha, beta, settings)


@pytest.fixture(scope="module")
def field():
    return compute_field(fake_robot(), fake_bound, RES)


def exact(robot, q, quantity="position"):
    alpha, beta = robot.configuration(q)
    return getattr(fake_bound(robot, alpha, beta), quantity)


def test_grid_axes(field):
    ax = field.axes
    assert [len(a) for a in ax] == list(RES)
    # periodic: no duplicated endpoint
    assert ax[0][0] == -np.pi and ax[0][-1] == pytest.approx(np.pi - 2 * np.pi / 8)
    np.testing.assert_array_equal(ax[0], uniform_axis(-np.pi, np.pi, 8, True))
    # bounded: both limits (beta_3 - beta_1 with beta_1 = 0 for the fake robot)
    assert ax[2][0] == -0.104 and ax[2][-1] == -0.034
    assert field.coordinate_names == ["alpha_2-alpha_1", "alpha_3-alpha_1", "beta_3-beta_1"]


def test_exact_at_nodes(field):
    robot = fake_robot()
    nodes = field.nodes()
    for quantity in ("position", "angle", "translation_last_position", "translation_last_angle"):
        want = np.array([exact(robot, q, quantity) for q in nodes])
        np.testing.assert_allclose(field(nodes, quantity), want, rtol=1e-12, atol=1e-15)
    assert np.all(field.is_valid(nodes))
    assert field(nodes[5]) == pytest.approx(exact(robot, nodes[5]))


def test_periodic_wrap_and_clamp(field):
    robot = fake_robot()
    ax = field.axes
    q_node = np.array([ax[0][3], ax[1][2], ax[2][1]])
    # a full turn on either periodic axis lands on the same node
    for shift in ([2 * np.pi, 0, 0], [0, -2 * np.pi, 0], [4 * np.pi, 2 * np.pi, 0]):
        assert field(q_node + shift) == pytest.approx(field(q_node), rel=1e-12)
    # between the last node and the first (across +pi): linear between those two nodes
    h = 2 * np.pi / 8
    q_last = np.array([ax[0][-1], ax[1][2], ax[2][1]])
    q_first = np.array([ax[0][0], ax[1][2], ax[2][1]])
    mid = q_last + [0.25 * h, 0, 0]
    assert field(mid) == pytest.approx(0.75 * exact(robot, q_last) + 0.25 * exact(robot, q_first), rel=1e-12)
    # translation clamped to its limits
    assert field(q_node + [0, 0, -1.0]) == pytest.approx(field([q_node[0], q_node[1], -0.104]))


def test_invalid_nodes_give_inf(field):
    valid = field.valid.copy()
    valid[3, 2, 1] = False
    f2 = BoundField(field.axes, field.periodic, field.values, valid, field.key, coordinates=field.coordinates)
    ax = field.axes
    bad = np.array([ax[0][3], ax[1][2], ax[2][1]])
    near = bad + [0.1, 0.1, 0.001]
    far = np.array([ax[0][0], ax[1][0], ax[2][3]])
    assert f2(bad) == np.inf and f2(near) == np.inf
    assert not f2.is_valid(near) and f2.is_valid(far)
    assert np.isfinite(f2(far))
    # exactly on the neighbouring node: the invalid node has zero weight
    assert f2.is_valid([ax[0][4], ax[1][2], ax[2][1]])


def test_save_load_and_key(field, tmp_path):
    path = field.save(tmp_path / "field.npz")
    f2 = BoundField.load(path, key=field.key)
    q = np.random.default_rng(0).uniform([-4, -4, -0.11], [4, 4, -0.03], (50, 3))
    np.testing.assert_array_equal(f2(q), field(q))
    assert f2.metadata["joint_names"] == ["alpha_2", "alpha_3", "beta_3"]
    other = field_key(fake_robot(), ModelSettings(ds=2e-3), RES, fake_bound)
    assert other != field.key
    with pytest.raises(BoundFieldKeyError, match="another robot"):
        BoundField.load(path, key=other)


def test_resume_computes_only_missing_chunks(tmp_path):
    robot = fake_robot()
    store = tmp_path / "map.zarr"
    n_nodes = int(np.prod(RES))  # 192 nodes, chunks of (1, 3, 4) = 12 nodes -> 16 chunks
    partial = compute_field(robot, fake_bound, RES, store=store, options=ComputeOptions(chunk_size=12, max_chunks=5))
    assert partial is None  # interrupted
    counter = CountingBound()
    full = compute_field(robot, counter, RES, store=store, options=ComputeOptions(chunk_size=12))
    assert counter.calls == n_nodes - 5 * 12
    ref = compute_field(robot, fake_bound, RES)
    np.testing.assert_array_equal(full.values, ref.values)
    assert full.key == ref.key
    # the finished store is a map the planner reads
    np.testing.assert_array_equal(load_bound_map(store, key=ref.key).values, ref.values)
    # a finished store evaluates nothing
    counter2 = CountingBound()
    compute_field(robot, counter2, RES, store=store, options=ComputeOptions(chunk_size=12))
    assert counter2.calls == 0
    # another model setting with the same store raises, naming the store and the setting
    with pytest.raises(BoundFieldKeyError, match="settings.ds"):
        compute_field(robot, fake_bound, RES, settings=ModelSettings(ds=2e-3), store=store,
                      options=ComputeOptions(chunk_size=12))


def test_failed_and_unstable_points_are_invalid():
    from ctrplan.errors import ConvergenceError

    def flaky(robot, alpha, beta, settings=None):
        if alpha[1] == -np.pi and alpha[2] == -np.pi:
            raise ConvergenceError("no")
        res = fake_bound(robot, alpha, beta)
        if beta[2] == -0.034:
            res.diagnostics = SimpleNamespace(converged=True, unstable=True)
        return res

    f = compute_field(fake_robot(), flaky, (4, 4, 3))
    assert not f.valid[0, 0, 0] and not f.valid[1, 1, 2] and f.valid[1, 1, 1]
    assert f.metadata["n_invalid"] == 4 * 4 + 3 - 1


def test_interpolation_error_reports(field):
    err = interpolation_error(field, fake_robot(), fake_bound, n=30, seed=2)
    assert err.errors.shape == (30,) and err.n_invalid == 0
    assert 0.0 <= err.median <= err.p95 < 5e-3
    # translation-last position is linear in beta_3: its own error part is tiny where the bump is flat
    np.testing.assert_allclose(err.interpolated, field(err.q))


def test_interpolation_matches_scipy_on_nonuniform_periodic_grid():
    """The compiled kernel against scipy's RegularGridInterpolator (linear) on a grid with a
    periodic uniform axis and two nonuniform bounded ones; the periodic axis is closed for scipy
    by repeating its first node at +2 pi. Queries outside the bounded range are clamped."""
    from scipy.interpolate import RegularGridInterpolator

    rng = np.random.default_rng(7)
    a0 = -np.pi + 2 * np.pi * np.arange(6) / 6
    a1 = np.sort(np.concatenate([[-1.0, 2.0], rng.uniform(-1.0, 2.0, 5)]))
    a2 = np.array([-0.104, -0.09, -0.05, -0.045, -0.04, -0.034])
    vals = rng.random((6, a1.size, a2.size, 4))
    field = BoundField([a0, a1, a2], [True, False, False], vals, np.ones(vals.shape[:3], bool), "k")
    closed = np.concatenate([vals, vals[:1]], axis=0)
    ref = RegularGridInterpolator((np.append(a0, np.pi), a1, a2), closed[..., 0])
    u = np.column_stack([rng.uniform(-10, 10, 500), rng.uniform(-2, 3, 500), rng.uniform(-0.12, -0.02, 500)])
    clamped = np.column_stack([(u[:, 0] + np.pi) % (2 * np.pi) - np.pi, np.clip(u[:, 1], -1, 2),
                               np.clip(u[:, 2], -0.104, -0.034)])
    np.testing.assert_allclose(field(u), ref(clamped), rtol=1e-12, atol=1e-12)


def test_multilinear_reproduces_a_function_linear_in_each_cell():
    """On any grid, multilinear interpolation of f = (a + b x)(c + d y) is exact."""
    x = np.array([0.0, 0.3, 1.0, 1.1])
    y = np.array([-2.0, 0.0, 5.0])
    X, Y = np.meshgrid(x, y, indexing="ij")
    f = lambda x, y: (1 + 2 * x) * (3 - 0.5 * y)  # noqa: E731
    vals = np.repeat(f(X, Y)[..., None], 4, axis=2)
    field = BoundField([x, y], [False, False], vals, np.ones(X.shape, bool), "k")
    rng = np.random.default_rng(1)
    u = np.column_stack([rng.uniform(0, 1.1, 200), rng.uniform(-2, 5, 200)])
    np.testing.assert_allclose(field(u), f(u[:, 0], u[:, 1]), rtol=1e-13)


def test_adaptive_placement_finds_the_kinks_of_a_piecewise_linear_profile():
    """Pilot values that are piecewise linear with kinks at three abscissae: four greedy insertions
    beyond the ends put nodes exactly on the kinks, after which interpolation is exact."""
    from ctrplan.boundmap import place_nodes

    x = np.linspace(-0.104, -0.034, 71)           # 1 mm pilot step
    kinks = x[[40, 55, 62]]
    def profile(x, slope):
        return 2e-3 + slope * (x + 0.104) + 0.3 * np.maximum(x - kinks[0], 0) - 0.9 * np.maximum(x - kinks[1], 0) \
            + 0.4 * np.maximum(x - kinks[2], 0)
    lines = np.array([profile(x, s) for s in (0.05, 0.1, 0.2)])
    lines[1, 7] = np.nan                            # a failed pilot sample is ignored
    nodes = place_nodes(x, lines, 5)
    np.testing.assert_allclose(nodes, np.sort(np.concatenate([x[[0, -1]], kinks])))
    fit = np.interp(x, nodes, lines[0][np.searchsorted(x, nodes)])
    np.testing.assert_allclose(fit, lines[0], atol=1e-15)
    with pytest.raises(ValueError, match="cannot place"):
        place_nodes(x, lines, 72)


def test_adaptive_spec_puts_translation_nodes_where_the_bound_bends(tmp_path):
    """An adaptive map of a fake bound with a sharp drop in beta_3 - beta_1 places most nodes in
    the drop; the pilots are stored with the map and the spec is part of the key."""
    from types import SimpleNamespace

    from ctrplan.boundmap import BoundMapStore, MapSpec, compute_bound_map_store

    def drop(robot, alpha, beta, settings=None):
        b3 = beta[2] - beta[0]
        p = 5e-3 / (1.0 + np.exp((b3 + 0.040) / 0.002)) + 1e-3 * (1 + np.cos(alpha[1]))
        return SimpleNamespace(position=p, angle=p, translation_last_position=p, translation_last_angle=p,
                               diagnostics=SimpleNamespace(converged=True, unstable=False))

    drop.name = "drop"
    spec = MapSpec((4, 4, 8), "adaptive", pilot_lines=2)
    run = compute_bound_map_store(fake_robot(), drop, spec, store=tmp_path / "m.zarr")
    nodes = run.field.axes[2]
    assert nodes[0] == -0.104 and nodes[-1] == -0.034
    assert np.sum(np.abs(nodes + 0.040) < 0.008) >= 5       # most nodes within 8 mm of the drop
    assert run.pilot_evaluations == 2 * 71
    pts, vals = BoundMapStore.open(tmp_path / "m.zarr").pilots()[2]
    assert pts.shape == (2, 71, 3) and vals.shape == (2, 71, 4) and np.all(np.isfinite(vals))
    assert run.field.key != field_key(fake_robot(), None, MapSpec((4, 4, 8)), drop)
    # the adaptive map beats the uniform one with the same nodes
    uni = compute_bound_map_store(fake_robot(), drop, MapSpec((4, 4, 8))).field
    q = np.column_stack([np.zeros(300), np.zeros(300), np.linspace(-0.104, -0.034, 300)])
    exact = np.array([drop(None, *fake_robot().configuration(x)).position for x in q])
    assert np.max(np.abs(run.field(q) - exact)) < 0.5 * np.max(np.abs(uni(q) - exact))
