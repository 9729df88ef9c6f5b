"""A robot without a bound map: planned with the preview map refined where the plan goes, then with
its full map (ctrplan.planning.map_refinement, ctrplan.planning.bound_map)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import ctrplan
from ctrplan.mechanics import evaluate_bound
from ctrplan.planning import complete_bound_map
from ctrplan.planning import bounds_given_last_motion

REPO = Path(__file__).resolve().parents[1]
TABLE7 = REPO / "model" / "ha2019-table7-calibrated.toml"


def _new_robot(tmp_path: Path) -> Path:
    """The Table VII robot with tube 1's precurvature 10 % larger: a robot file with no map."""
    text = TABLE7.read_text()
    old = "precurvature_per_m = [-0.0034328870580157913, 3.536067892503536]"
    assert old in text
    path = tmp_path / "new-robot.toml"
    path.write_text(text.replace(old, "precurvature_per_m = [-0.0034328870580157913, 3.8896746817538896]"))
    return path


def _scenario(tmp_path: Path, robot: Path, extra: str = "") -> Path:
    path = tmp_path / "new.toml"
    path.write_text(f"""
name = "new"
robot = "{robot.as_posix()}"

[start]
q = {{alpha_2 = 0.0, alpha_3 = 0.0, beta_3 = -0.07}}

[[goals]]
type = "joint"
q = {{alpha_2 = 2.5, alpha_3 = -1.5, beta_3 = -0.045}}

[planner]
name = "RRTstar"
iterations = 40
seed = 3
bound_weight = 500.0

[bound_field]
resolution = [6, 6, 4]
ds_m = 0.004
{extra}
""")
    return path


def test_a_new_robot_plans_with_a_refined_preview_map_then_with_its_full_map(tmp_path, monkeypatch):
    """With no map of the robot: the plan reads a preview map of half the nodes per coordinate
    (3 x 3 x 2), refined on a grid four times as fine until the map is within the tolerance of
    the exact bound at the waypoints or the rounds run out; the exact bound, recomputed here at
    the final plan's waypoints, matches the refined map's there within the tolerance when it
    converged; a second run reads the cached preview map and starts from the exact nodes and
    samples of the first; after ``complete_bound_map`` a plan reads the full
    map and refines nothing. Catches a refinement whose map does not match the exact bound
    where the plan goes, a preview map that is recomputed every run, and a full map that is
    never used."""
    monkeypatch.chdir(tmp_path)
    sc = _scenario(tmp_path, _new_robot(tmp_path))
    first = ctrplan.plan(sc, compare_blind=True, n_jobs=1).run
    assert first.bound_map.preview and first.bound_map.source == "computed"
    assert first.bound_map.field.shape == (3, 3, 2)
    ref = first.refinement
    assert ref is not None and 1 <= len(ref.rounds) <= 5 and ref.field.shape == (12, 12, 5)
    if len(ref.rounds) > 1:
        assert ref.samples.n > 0 and ref.rounds[-1].n_samples == ref.samples.n
    ordered = first.plans.aware.ordered
    exact = bounds_given_last_motion(ordered, first.setup.robot, evaluate_bound, first.setup.settings)
    motions = np.array(ordered.motions)
    planned = np.where(motions == "translation", ref.field(ordered.q, "translation_last_position"),
                       ref.field(ordered.q, "position"))
    ok = exact.valid & np.isfinite(exact.position)
    err = np.abs(planned - exact.position)[ok]
    assert err.max() == pytest.approx(ref.rounds[-1].max_error, abs=1e-9)
    if ref.converged:
        assert err.max() <= ref.tolerance
    assert first.plans.blind is not None and first.comparison.blind is not None
    assert first.timings_s["refinement"] == pytest.approx(ref.time_s)

    # the second plan starts from the cached preview map and the exact nodes and samples of the first
    again = ctrplan.plan(sc, compare_blind=False, n_jobs=1).run
    assert again.bound_map.preview and again.bound_map.source == "cache"
    assert again.refinement.rounds[0].n_samples >= ref.samples.n - first.plans.aware.bounds.exact.position.size
    assert again.refinement.rounds[0].n_nodes > 0 and again.refinement.cache == ref.cache

    full = complete_bound_map(first.setup, 1)
    assert not full.preview and full.field.shape == (6, 6, 4)
    last = ctrplan.plan(sc, compare_blind=False, n_jobs=1).run
    assert not last.bound_map.preview and last.bound_map.source == "cache" and last.refinement is None


def test_refinement_can_be_asked_for_with_any_map_and_turned_off_with_a_preview(tmp_path, monkeypatch):
    """``refine_rounds = 0`` plans once with the preview map; ``first_plan = "full"`` computes the
    full map first and, with ``refine_rounds = 2``, refines it too. Catches settings that are
    read and ignored."""
    monkeypatch.chdir(tmp_path)
    robot = _new_robot(tmp_path)
    off = ctrplan.plan(_scenario(tmp_path, robot, "refine_rounds = 0"), compare_blind=False, n_jobs=1).run
    assert off.bound_map.preview and off.refinement is None
    full = ctrplan.plan(_scenario(tmp_path, robot, 'first_plan = "full"\nrefine_rounds = 2'),
                        compare_blind=False, n_jobs=1).run
    assert not full.bound_map.preview and full.bound_map.field.shape == (6, 6, 4)
    assert full.refinement is not None and 1 <= len(full.refinement.rounds) <= 3
