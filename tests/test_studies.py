"""Many scenarios in one run (ctrplan.studies.plan_many, ``ctrplan plan A B ...``): a table across
scenarios, a failing scenario reported while the others go on, a rerun that reuses complete
outputs for the same inputs and redoes a changed one, and the same rows from dask workers."""

from __future__ import annotations

import re
from pathlib import Path

import pandas as pd
import pytest

from ctrplan.studies import COLUMNS, TABLE_FILE, StudyStatus, plan_many

REPO = Path(__file__).resolve().parents[1]


def _copy(tmp_path, name, seed=1):
    """A copy of a shipped scenario with absolute robot and mesh paths and its own seed."""
    text = (REPO / "scenarios" / f"{name}.toml").read_text()
    text = text.replace('"../model/', f'"{(REPO / "model").as_posix()}/')
    text = text.replace('file = "meshes/', f'file = "{(REPO / "scenarios" / "meshes").as_posix()}/')
    text = re.sub(r"(?m)^seed = .*$", f"seed = {seed}", text)
    folder = tmp_path / "scenarios"
    folder.mkdir(exist_ok=True)
    path = folder / f"{name}-{seed}.toml"
    path.write_text(text)
    return path


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("study")
    a = _copy(tmp, "task-target", 1)
    b = _copy(tmp, "task-target", 2)
    broken = tmp / "scenarios" / "broken.toml"
    broken.write_text(a.read_text().replace("ha2019-table7-calibrated.toml", "no-such-robot.toml"))
    return tmp, a, b, broken


def test_a_table_across_scenarios_with_a_failure_reported(study, monkeypatch):
    """Three scenarios in a folder, one naming a robot file that does not exist: two are planned,
    the third is a row with status "failed" and the error naming the missing file; the rows are in
    SI and the table on disk is the same rows in report units (bounds in mm), with every column.
    Catches a batch that stops at the first failure, a table that loses a scenario, and a unit
    slip between the result and the file."""
    tmp, a, b, broken = study
    monkeypatch.chdir(tmp)
    study_result = plan_many([tmp / "scenarios"], tmp / "out", iterations=60, compare_blind=True)
    assert len(study_result.rows) == 3 and study_result.n_failed == 1
    by = {r.scenario.stem: r for r in study_result.rows}
    assert by["broken"].status is StudyStatus.FAILED and "no-such-robot.toml" in by["broken"].error
    for name in ("task-target-1", "task-target-2"):
        r = by[name]
        assert r.status is StudyStatus.PLANNED and 0 < r.max_bound_m < 0.05 and r.failures == 0
        assert 0 < r.blind_max_bound_m < 0.05 and (tmp / "out" / name / "summary.json").exists()
    on_disk = pd.read_csv(tmp / "out" / TABLE_FILE)
    assert list(on_disk.columns) == list(COLUMNS)
    assert list(on_disk["status"]) == [r.status.value for r in study_result.rows]
    planned = on_disk[on_disk["status"] == "planned"]
    assert list(planned["max_bound_mm"]) == pytest.approx(
        [r.max_bound_m * 1e3 for r in study_result.rows if r.status is StudyStatus.PLANNED], rel=1e-12)
    assert list(study_result.to_frame()["max_bound_m"].dropna()) == pytest.approx(list(planned["max_bound_mm"] / 1e3))
    with pytest.warns(DeprecationWarning, match="use .rows"):
        assert list(study_result["status"]) == list(on_disk["status"])
    assert study_result.plot_file.stat().st_size > 1000


def test_a_rerun_reuses_complete_outputs_and_redoes_a_changed_scenario(study, monkeypatch):
    """Run again after the first test: the unchanged scenario is "reused" with the same figures; the
    one whose file changed (another seed) is planned again. Catches a rerun that starts from scratch
    and one that reuses outputs of other inputs."""
    tmp, a, b, broken = study
    monkeypatch.chdir(tmp)
    first = pd.read_csv(tmp / "out" / TABLE_FILE)
    b.write_text(re.sub(r"(?m)^seed = .*$", "seed = 7", b.read_text()))
    rows = plan_many([a, b], tmp / "out", iterations=60, compare_blind=True).rows
    assert {r.scenario.stem: r.status.value for r in rows} == {"task-target-1": "reused", "task-target-2": "planned"}
    (reused,) = [r for r in rows if r.status is StudyStatus.REUSED]
    before = first[first["scenario"] == str(a)].iloc[0]
    assert reused.max_bound_m * 1e3 == pytest.approx(before["max_bound_mm"], rel=1e-12)


def test_dask_workers_give_the_same_plans(study, tmp_path, monkeypatch):
    """The two scenarios on a local dask cluster of two workers: the same costs and bounds as in
    this process (the plans are seeded). Catches workers that plan with other inputs."""
    tmp, a, b, _ = study
    monkeypatch.chdir(tmp)
    serial = plan_many([a, b], tmp_path / "serial", iterations=60, compare_blind=False).rows
    spread = plan_many([a, b], tmp_path / "dask", n_jobs=2, iterations=60, compare_blind=False).rows
    assert [r.status for r in spread] == [StudyStatus.PLANNED, StudyStatus.PLANNED]
    for col in ("cost", "max_bound_m", "final_bound_m", "joint_path_length_m"):
        assert [getattr(r, col) for r in spread] == pytest.approx([getattr(r, col) for r in serial], rel=1e-9), col


def test_the_plan_command_takes_several_scenarios_and_fails_when_one_fails(study, tmp_path, monkeypatch):
    """``ctrplan plan GOOD BROKEN --out DIR``: both get a row in DIR/scenarios.csv, the exit status is
    1 and the console names the failing scenario, with one line per scenario and no scenario's own
    progress lines (DEBUG in a study). Catches a command that still takes one file, and a study
    that prints every scenario's stages."""
    from click.testing import CliRunner

    from ctrplan.cli import main

    tmp, a, _, broken = study
    monkeypatch.chdir(tmp)
    r = CliRunner().invoke(main, ["plan", str(a), str(broken), "--out", str(tmp_path / "cli"), "--iterations", "60",
                                  "--no-blind"])
    assert r.exit_code == 1, r.output
    assert "broken.toml: failed" in r.output
    assert f"{a}: planned in " in r.output and "ordered waypoints" not in r.output, r.output
    table = pd.read_csv(tmp_path / "cli" / TABLE_FILE)
    assert list(table["status"]) == ["planned", "failed"]
