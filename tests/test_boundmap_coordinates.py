"""Map coordinates (relative base rotations and translations), their physics, and the shipped maps.

- the exact bound is invariant under a common rotation and a common translation of all tubes
  (what lets a six-joint robot have a 4-D map), to the contact solver's tolerance;
- the coordinates of the shipped robots, and joint vectors <-> representative configurations;
- every shipped map equals the current exact model at sampled nodes (a map left stale by a
  change of the mechanics fails here) and is named by its current key.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ctrplan.boundmap import BoundField, compute_field, field_key, load_bound_map, map_coordinates
from ctrplan.boundmap.compute import node_values
from ctrplan.io.robot_file import load_robot
from ctrplan.mechanics import ModelSettings, evaluate_bound

REPO = Path(__file__).resolve().parents[1]
SIX = REPO / "model" / "ha2019-table2-six-joint.toml"
T7 = REPO / "model" / "ha2019-table7-calibrated.toml"


def test_coordinates_of_the_shipped_robots():
    c3 = map_coordinates(load_robot(T7))
    assert c3.names == ("alpha_2-alpha_1", "alpha_3-alpha_1", "beta_3-beta_1")
    assert c3.periodic == (True, True, False) and c3.lower[2] == -0.104 and c3.upper[2] == -0.034
    c6 = map_coordinates(load_robot(SIX))
    assert c6.names == ("alpha_2-alpha_1", "alpha_3-alpha_1", "beta_2-beta_1", "beta_3-beta_1")
    # beta_2 - beta_1 over [-17, -10] - [-10, 0] mm; beta_3 - beta_1 over [-104, -34] - [-10, 0] mm
    np.testing.assert_allclose(c6.lower[2:], [-0.017, -0.104])
    np.testing.assert_allclose(c6.upper[2:], [0.0, -0.024])


@pytest.mark.parametrize("path", [T7, SIX], ids=lambda p: p.stem)
def test_representative_configuration_has_the_same_relative_placement(path):
    robot = load_robot(path)
    coords = map_coordinates(robot)
    rng = np.random.default_rng(3)
    q = robot.joint_lower + rng.random((20, len(robot.joints))) * (robot.joint_upper - robot.joint_lower)
    alpha_r, beta_r = coords.configuration(coords.from_joints(q))
    for k in range(len(q)):
        alpha, beta = robot.configuration(q[k])
        np.testing.assert_allclose(alpha_r[k] - alpha_r[k, 0], alpha - alpha[0], atol=1e-15)
        np.testing.assert_allclose(beta_r[k] - beta_r[k, 0], beta - beta[0], atol=1e-15)
        robot.check_configuration(alpha_r[k], beta_r[k])


def test_bound_is_invariant_under_common_rotation_and_translation():
    """Turning and pushing the whole tube set moves every solution rigidly (no feature of the model
    is fixed in space), so the bound, a distance between tips, does not change. Checked on the
    exact model at the contact solver's tolerance (outer loop stops at a 1 um centerline change;
    the iteration path itself is not rotation invariant to rounding)."""
    robot = load_robot(SIX)
    settings = ModelSettings(ds=6e-3)
    tol = 5 * settings.outer_tol
    for q in ([0.0, 1.0, 2.0, -0.005, -0.015, -0.07], [0.3, -2.5, 0.4, -0.002, -0.012, -0.04]):
        alpha, beta = robot.configuration(np.array(q))
        ref = evaluate_bound(robot, alpha, beta, settings)
        assert ref.position > 1e-3 and ref.diagnostics.ok
        for turn, push in ((0.7, 0.0), (0.0, -0.003), (-2.0, 0.002)):
            b = evaluate_bound(robot, alpha + turn, beta + push, settings)
            assert b.position == pytest.approx(ref.position, abs=tol)
            assert b.translation_last_position == pytest.approx(ref.translation_last_position, abs=tol)
            # the tips themselves move rigidly: rotated about z, shifted along z
            c, s = np.cos(turn), np.sin(turn)
            moved = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) @ ref.standard.tip_position + [0, 0, push]
            np.testing.assert_allclose(b.standard.tip_position, moved, atol=1e-9)


def test_six_joint_field_takes_joint_vectors_and_ignores_common_motion():
    """A 4-D map of the six-joint robot answers joint vectors; a common rotation or translation
    (within the limits) leaves the interpolated bound unchanged."""
    robot = load_robot(SIX)

    def relative_bound(robot, alpha, beta, settings=None):
        from types import SimpleNamespace

        p = 1e-3 * (3 + np.cos(alpha[1] - alpha[0]) + np.sin(alpha[2] - alpha[0])) * (1 + 20 * (beta[2] - beta[0]))
        return SimpleNamespace(position=p, angle=p, translation_last_position=p, translation_last_angle=p,
                               diagnostics=SimpleNamespace(converged=True, unstable=False))

    relative_bound.name = "relative-bound"
    field = compute_field(robot, relative_bound, (8, 8, 3, 5))
    assert field.shape == (8, 8, 3, 5) and field.n_joints == 6
    q = np.array([0.2, 1.0, -2.0, -0.004, -0.014, -0.06])
    b = field(q)
    assert field(q + [0.9, 0.9, 0.9, 0, 0, 0]) == pytest.approx(b, rel=1e-12)
    assert field(q + [0, 0, 0, -0.003, -0.003, -0.003]) == pytest.approx(b, rel=1e-12)
    assert field(q + [0, 0.3, 0, 0, 0, 0]) != pytest.approx(b, rel=1e-3)


def _shipped_maps():
    return sorted((REPO / "model" / "boundmaps").glob("*.npz"))


@pytest.mark.parametrize("path", _shipped_maps(), ids=lambda p: p.stem)
def test_shipped_map_matches_the_current_model(path):
    """Nodes of a shipped map, recomputed with today's mechanics, equal the stored values (the map
    is not stale), and its file name carries its current key.

    Tolerances are those of the contact solver, not of the rounding: the outer loop stops at a
    1 um centerline change (``outer_tol``), so, as in the invariance test above, a position bound
    may move by a few outer_tol when only the iteration path changes (measured: up to 1.9 um
    with Anderson depth 0 or 5 instead of 3); 5 outer_tol. A tangent is fixed by nodes one step
    apart, each known to about 5 outer_tol, so the angle bounds get 2 x 5 outer_tol over the
    finest step (refine_ratio x ds, 0.75 mm at ds = 3 mm: 0.013 rad; a changed path moved them
    by up to 3.2e-5 rad, beyond the former 2e-6). A stale map from a change of the mechanics
    (say a 30 % error in the friction torque radius) moves position bounds by far more than 5 um."""
    field = load_bound_map(path)
    meta = field.metadata
    robot_path = REPO / "model" / meta["robot_file"]
    robot = load_robot(robot_path)
    settings = ModelSettings(**meta["settings"])
    from ctrplan.boundmap import MapSpec

    spec = MapSpec(tuple(meta["spec"]["resolution"]), meta["spec"]["placement"])
    key = field_key(robot, settings, spec, evaluate_bound, robot_path.read_text())
    assert field.key == key and path.stem.endswith(key[:12]), "stale map: recompute it (docs/boundmaps.md)"
    rng = np.random.default_rng(0)
    nodes = field.nodes()
    flat_valid = field.valid.reshape(-1)
    picks = rng.choice(np.flatnonzero(flat_valid), size=3, replace=False)
    stored = field.values.reshape(-1, 4)
    for k in picks:
        alpha, beta = field.coordinates.configuration(nodes[k])
        vals, ok = node_values(robot, evaluate_bound, alpha, beta, settings)
        assert ok
        tol_m = 5 * settings.outer_tol
        tol_rad = 2 * tol_m / (settings.refine_ratio * settings.ds)
        assert np.all(np.abs(vals - stored[k]) <= [tol_m, tol_rad, tol_m, tol_rad]), (k, vals, stored[k])


def test_field_constructor_checks():
    ax = [np.linspace(-np.pi, np.pi, 4, endpoint=False), np.array([0.0, 1.0, 3.0])]
    vals = np.zeros((4, 3, 4))
    ok = np.ones((4, 3), bool)
    BoundField(ax, [True, False], vals, ok, "k")
    with pytest.raises(ValueError, match="increasing"):
        BoundField([ax[0], np.array([0.0, 2.0, 1.0])], [True, False], vals, ok, "k")
    with pytest.raises(ValueError, match="uniform"):
        BoundField([np.array([0.0, 1.0, 1.5, 3.0]), ax[1]], [True, False], vals, ok, "k")
