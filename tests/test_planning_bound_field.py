from types import SimpleNamespace

import numpy as np
import pytest

from ctrplan.mechanics.results import ModelSettings
from ctrplan.planning import BoundField, BoundFieldKeyError, field_key, grid_axes, interpolation_error
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
    return BoundField.compute(fake_robot(), fake_bound, RES, progress=False)


def exact(robot, q, quantity="position"):
    alpha, beta = robot.configuration(q)
    return getattr(fake_bound(robot, alpha, beta), quantity)


def test_grid_axes():
    robot = fake_robot()
    ax = grid_axes(robot, RES)
    assert [len(a) for a in ax] == list(RES)
    # periodic: no duplicated endpoint
    assert ax[0][0] == -np.pi and ax[0][-1] == pytest.approx(np.pi - 2 * np.pi / 8)
    # bounded: both limits
    assert ax[2][0] == -0.104 and ax[2][-1] == -0.034


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
    f2 = BoundField(field.axes, field.periodic, field.values, valid, field.key)
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
    partial = BoundField.compute(robot, fake_bound, RES, store=store, chunk_size=12,
                                 progress=False, max_chunks=5)
    assert partial is None  # interrupted
    counter = CountingBound()
    full = BoundField.compute(robot, counter, RES, store=store, chunk_size=12, progress=False)
    assert counter.calls == n_nodes - 5 * 12
    ref = BoundField.compute(robot, fake_bound, RES, progress=False)
    np.testing.assert_array_equal(full.values, ref.values)
    assert full.key == ref.key
    # the finished store is a map the planner reads
    np.testing.assert_array_equal(BoundField.load(store, key=ref.key).values, ref.values)
    # a finished store evaluates nothing
    counter2 = CountingBound()
    BoundField.compute(robot, counter2, RES, store=store, chunk_size=12, progress=False)
    assert counter2.calls == 0
    # another model setting with the same store raises, naming the store and the setting
    with pytest.raises(BoundFieldKeyError, match="settings.ds"):
        BoundField.compute(robot, fake_bound, RES, settings=ModelSettings(ds=2e-3), store=store,
                           chunk_size=12, progress=False)


def test_failed_and_unstable_points_are_invalid():
    from ctrplan.errors import ConvergenceError

    def flaky(robot, alpha, beta, settings=None):
        if alpha[1] == -np.pi and alpha[2] == -np.pi:
            raise ConvergenceError("no")
        res = fake_bound(robot, alpha, beta)
        if beta[2] == -0.034:
            res.diagnostics = SimpleNamespace(converged=True, unstable=True)
        return res

    f = BoundField.compute(fake_robot(), flaky, (4, 4, 3), progress=False)
    assert not f.valid[0, 0, 0] and not f.valid[1, 1, 2] and f.valid[1, 1, 1]
    assert f.metadata["n_invalid"] == 4 * 4 + 3 - 1


def test_interpolation_error_reports(field):
    err = interpolation_error(field, fake_robot(), fake_bound, n=30, seed=2)
    assert err.errors.shape == (30,) and err.n_invalid == 0
    assert 0.0 <= err.median <= err.p95 < 5e-3
    # translation-last position is linear in beta_3: its own error part is tiny where the bump is flat
    np.testing.assert_allclose(err.interpolated, field(err.q))
