"""A bound map corrected to exact samples (ctrplan.boundmap.refine), and the preview map's spec."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.interpolate import RegularGridInterpolator

from ctrplan.boundmap import (QUANTITIES, BoundField, ExactSamples, MapSpec, cell_nodes, preview_spec, refined_field,
                              subdivided, with_nodes)


def _field(rng, shape=(7, 6), periodic=(False, False)):
    """A bounded 2-D map with positive random node values (bounds of a few mm)."""
    axes = [np.sort(rng.uniform(0.0, 1.0, n)) if not p else np.arange(n) * 2 * np.pi / n
            for n, p in zip(shape, periodic)]
    for a in axes:
        a[0], a[-1] = (0.0, 1.0) if a[-1] <= 1.0 else (a[0], a[-1])
    values = rng.uniform(1e-3, 5e-3, shape + (len(QUANTITIES),))
    return BoundField(axes, periodic, values, np.ones(shape, bool), key="k")


def test_refined_map_interpolates_the_exact_samples_and_keeps_the_rest():
    """Twelve samples in different cells of a 7 x 6 map, their exact values off the map by a
    smooth residual of up to 1 mm: after the correction the map's
    multilinear interpolation (scipy's, independent of the map's kernel) equals the exact values
    there, for every quantity; nodes of cells without a sample keep their values. Catches a
    correction with the wrong weights, one applied to the wrong nodes, and one that leaks
    outside the samples' cells."""
    rng = np.random.default_rng(11)
    field = _field(rng)
    ax0, ax1 = field.axes
    # one sample in each of 12 distinct cells
    cells = rng.choice((ax0.size - 1) * (ax1.size - 1), 12, replace=False)
    i, j = np.divmod(cells, ax1.size - 1)
    u = np.stack([ax0[i] + rng.uniform(0.1, 0.9, 12) * np.diff(ax0)[i],
                  ax1[j] + rng.uniform(0.1, 0.9, 12) * np.diff(ax1)[j]], axis=1)
    # the map's error is smooth, as a bound's between nodes is: exact = map + a smooth residual
    before, _ = field.interpolate(u)
    exact = before + 1e-3 * np.sin(3.0 * u[:, :1] + 2.0 * u[:, 1:] + np.arange(len(QUANTITIES)))
    out = refined_field(field, ExactSamples(u, exact, np.ones(12, bool)))
    for c in range(len(QUANTITIES)):
        interp = RegularGridInterpolator((ax0, ax1), out.values[..., c])
        np.testing.assert_allclose(interp(u), exact[:, c], rtol=0, atol=1e-8)   # 10 nm: the ridge
    touched = np.zeros(field.shape, bool)
    for a, b in zip(i, j):
        touched[a:a + 2, b:b + 2] = True
    np.testing.assert_array_equal(out.values[~touched], field.values[~touched])
    assert not np.allclose(out.values[touched], field.values[touched])
    assert out.metadata["refined_samples"] == 12 and out.metadata["refined_nodes"] == touched.sum()
    assert out.key == field.key


def test_one_sample_at_a_cell_centre_moves_its_corners_by_the_residual():
    """The minimum-norm correction of one sample at the centre of a 2-D cell (weights 1/4 each)
    moves each of the four corners by the whole residual (delta_j = w_j r / sum w^2); two
    samples at the same point asking for different values meet at their mean; a correction
    below zero stops at zero. Catches a correction that is not the minimum-norm one and a
    negative bound."""
    rng = np.random.default_rng(5)
    field = _field(rng, shape=(4, 4))
    ax0, ax1 = field.axes
    centre = np.array([[0.5 * (ax0[1] + ax0[2]), 0.5 * (ax1[1] + ax1[2])]])
    before, _ = field.interpolate(centre)
    exact = before + 1e-3
    out = refined_field(field, ExactSamples(centre, exact, [True]))
    np.testing.assert_allclose(out.values[1:3, 1:3] - field.values[1:3, 1:3], 1e-3, rtol=1e-6)
    both = ExactSamples(np.repeat(centre, 2, axis=0), np.concatenate([before + 1e-3, before + 3e-3]), [True, True])
    got, _ = refined_field(field, both).interpolate(centre)
    np.testing.assert_allclose(got, before + 2e-3, rtol=1e-6)
    low = refined_field(field, ExactSamples(centre, before - 1.0, [True]))
    assert np.all(low.values >= 0.0) and np.all(low.values[1:3, 1:3] == 0.0)


def test_samples_that_failed_or_lie_on_invalid_cells_change_nothing():
    """A sample whose model failed (ok False), one with a NaN value and one in a cell with an
    invalid node leave the map as it was. Catches a correction that writes a failed solve into
    the map."""
    rng = np.random.default_rng(8)
    field = _field(rng, shape=(5, 5))
    valid = np.ones((5, 5), bool)
    valid[3, 3] = False
    field = BoundField(field.axes, field.periodic, np.where(valid[..., None], field.values, np.nan), valid, "k")
    ax0, ax1 = field.axes
    u = np.array([[0.5 * (ax0[0] + ax0[1]), 0.5 * (ax1[0] + ax1[1])],
                  [0.5 * (ax0[1] + ax0[2]), 0.5 * (ax1[1] + ax1[2])],
                  [0.5 * (ax0[2] + ax0[3]), 0.5 * (ax1[2] + ax1[3])]])
    values = np.full((3, 4), 9e-3)
    values[1, 2] = np.nan
    out = refined_field(field, ExactSamples(u, values, [False, True, True]))
    np.testing.assert_array_equal(np.nan_to_num(out.values), np.nan_to_num(field.values))
    assert out.metadata["refined_samples"] == 0


def test_periodic_coordinate_wraps_the_correction():
    """A sample in the last cell of a periodic coordinate (between its last node and 2 pi) moves
    the last and the first node, and the map then interpolates it there and at the same point
    unwrapped by 2 pi. Catches a correction that ignores the wrap."""
    rng = np.random.default_rng(3)
    field = _field(rng, shape=(8, 4), periodic=(True, False))
    ax0, ax1 = field.axes
    u = np.array([[ax0[-1] + 0.5 * (2 * np.pi - ax0[-1]), 0.5 * (ax1[0] + ax1[1])]])
    exact = np.full((1, 4), 7e-3)
    out = refined_field(field, ExactSamples(u, exact, [True]))
    for shift in (0.0, 2 * np.pi, -4 * np.pi):
        got, ok = out.interpolate(u + [shift, 0.0])
        assert ok[0]
        np.testing.assert_allclose(got[0], exact[0], rtol=0, atol=1e-8)
    changed = np.any(out.values != field.values, axis=(1, 2))
    assert changed[0] and changed[-1] and not np.any(changed[1:-1])


def test_exact_samples_merge_without_repeats_and_round_trip(tmp_path):
    """Merging keeps one sample per coordinate vector (the later one) and saving and loading
    gives the same arrays. Catches a sample set that grows with every round at the same
    waypoints."""
    a = ExactSamples(np.array([[0.1, 0.2], [0.3, 0.4]]), np.full((2, 4), 1.0), [True, True])
    b = ExactSamples(np.array([[0.3, 0.4], [0.5, 0.6]]), np.full((2, 4), 2.0), [True, False])
    m = a.merged(b)
    assert m.n == 3
    row = np.flatnonzero(np.all(m.u == [0.3, 0.4], axis=1))
    assert row.size == 1 and np.all(m.values[row[0]] == 2.0)
    back = ExactSamples.load(m.save(tmp_path / "s.npz"))
    np.testing.assert_array_equal(back.u, m.u)
    np.testing.assert_array_equal(back.values, m.values)
    np.testing.assert_array_equal(back.ok, m.ok)
    assert ExactSamples.empty(2).merged(a).n == 2


def test_preview_spec_halves_every_coordinate():
    """16 nodes along a periodic coordinate become 8, 5 and 14 along translations 3 and 7, and
    no coordinate drops below its minimum. Catches a preview as fine as the map."""
    spec = MapSpec((16, 16, 5, 14), "adaptive")
    assert preview_spec(spec, (True, True, False, False)).resolution == (8, 8, 3, 7)
    assert preview_spec(MapSpec((4, 2)), (True, False)).resolution == (3, 2)
    assert preview_spec(spec, (True, True, False, False)).placement == "adaptive"


def test_subdivided_map_keeps_its_nodes_and_interpolates_between_them():
    """Subdividing twice gives 4 n nodes along a periodic coordinate (uniform, 2 pi / 4 n apart)
    and 4 n - 3 along a bounded one; the old nodes keep their values, and the map's value at
    any point is unchanged (multilinear interpolation of a multilinear interpolation on a finer
    grid is the same function). Catches misplaced midpoints and a shifted periodic axis."""
    rng = np.random.default_rng(21)
    field = _field(rng, shape=(6, 5), periodic=(True, False))
    fine = subdivided(field, 2)
    assert fine.shape == (24, 17)
    np.testing.assert_allclose(np.diff(fine.axes[0]), 2 * np.pi / 24)
    assert fine.axes[0][0] == field.axes[0][0]
    np.testing.assert_array_equal(fine.values[::4, ::4], field.values)
    u = np.stack([rng.uniform(-7.0, 7.0, 200), rng.uniform(0.0, 1.0, 200)], axis=1)
    np.testing.assert_allclose(fine.interpolate(u)[0], field.interpolate(u)[0], rtol=1e-12, atol=1e-15)


def test_with_nodes_and_cell_nodes_address_the_same_nodes():
    """``cell_nodes`` of a point lists the 4 corners of its 2-D cell; writing values there with
    ``with_nodes`` changes the interpolation at the point to the interpolation of the new
    values, and marking one corner invalid makes the point invalid. Catches a flat index in
    another order than the map's."""
    rng = np.random.default_rng(2)
    field = _field(rng, shape=(5, 4))
    ax0, ax1 = field.axes
    u = np.array([[0.5 * (ax0[2] + ax0[3]), 0.25 * ax1[1] + 0.75 * ax1[2]]])
    nodes = cell_nodes(field, u)
    i, j = np.unravel_index(nodes, field.shape)
    assert set(zip(i.tolist(), j.tolist())) == {(2, 1), (2, 2), (3, 1), (3, 2)}
    out = with_nodes(field, nodes, np.full((4, 4), 2e-3), np.ones(4, bool))
    np.testing.assert_allclose(out.interpolate(u)[0], 2e-3)
    bad = with_nodes(field, nodes[:1], np.full((1, 4), 2e-3), [False])
    assert not bad.interpolate(u)[1][0]


def test_exact_nodes_are_the_map_nodes():
    """The exact bound at nodes of a computed map of the Table VII robot (3 x 3 x 2 nodes,
    ds 4 mm), evaluated again by ``evaluate_nodes``, equals the map's stored values there.
    Catches nodes evaluated at another configuration than the map's (a coordinate order or
    representative-configuration mistake)."""
    from ctrplan.boundmap import compute_field, evaluate_nodes
    from ctrplan.io.robot_file import load_robot
    from ctrplan.mechanics import ModelSettings, evaluate_bound

    robot = load_robot(Path(__file__).resolve().parents[1] / "model" / "ha2019-table7-calibrated.toml")
    settings = ModelSettings(ds=0.004)
    field = compute_field(robot, evaluate_bound, MapSpec((3, 3, 2)), settings)
    index = np.array([0, 5, 11, 17])
    values, ok = evaluate_nodes(robot, field, index, settings)
    flat = field.values.reshape(-1, 4)
    np.testing.assert_array_equal(ok, field.valid.reshape(-1)[index])
    np.testing.assert_allclose(values[ok], flat[index][ok], rtol=1e-12)
