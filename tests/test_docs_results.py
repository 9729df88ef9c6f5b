"""docs/discrepancy.md and docs/mechanics.md quote the results files of their benchmarks, and those
files come from the data they name and from the code at hand: catches figures in the docs edited by
hand or left behind by a newer run, a results file made from another version of the measured data,
and one made by code that has changed since (its digest of the discrepancy, effects, history and
mechanics sources, or the mechanics version), or, for the sweep, by other scoring or reference
synthesizer code."""

from __future__ import annotations

import hashlib
import importlib.util
import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
HA_DATA = ROOT.parent / "shared" / "data" / "ha-three-tube-trajectory" / "jointTipTrajectory_measured.txt"


def _tables():
    spec = importlib.util.spec_from_file_location("docs_tables", ROOT / "benchmarks" / "docs_tables.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.parametrize("name", ["sweep-table", "ha-table", "robot-files-table", "discretization-table", "speed-table"])
def test_docs_tables_are_the_results_files(name):
    """The table between the docs' markers is exactly what the results file renders to."""
    tables = _tables()
    source, page = tables.SOURCES[name], tables.DOCS[name]
    assert source.exists(), f"{source.relative_to(ROOT)} is quoted by {page.name} and missing"
    doc = page.read_text()
    assert f"<!-- {name} -->" in doc and f"<!-- /{name} -->" in doc, f"no {name} block in {page}"
    table = tables.MAKERS[name](json.loads(source.read_text()))
    assert f"<!-- {name} -->\n{table}\n<!-- /{name} -->" in doc, (
        f"{page.name} differs from {source.name}: run python benchmarks/docs_tables.py")


def test_discretization_results_come_from_the_present_mechanics():
    """The discretization table of docs/mechanics.md was measured with the present mechanics
    (:data:`ctrplan.constants.MECHANICS_VERSION`, changed whenever a tip, bound or flag moves)."""
    from ctrplan.constants import MECHANICS_VERSION

    stored = json.loads((ROOT / "benchmarks" / "results" / "discretization-accuracy.json").read_text())
    assert stored["mechanics_version"] == MECHANICS_VERSION, (
        "discretization-accuracy.json was measured with other mechanics: run benchmarks/discretization_accuracy.py "
        "again, then benchmarks/docs_tables.py")


def test_new_robot_results_come_from_the_present_mechanics():
    """The new-robot figures of docs/boundmaps.md (benchmarks/results/new-robot.json) were measured
    with the present mechanics: catches maps and bounds quoted from a solver that has changed since."""
    from ctrplan.constants import MECHANICS_VERSION

    stored = json.loads((ROOT / "benchmarks" / "results" / "new-robot.json").read_text())
    assert stored["mechanics_version"] == MECHANICS_VERSION, (
        "new-robot.json was measured with other mechanics: run OPENBLAS_NUM_THREADS=1 python benchmarks/new_robot.py "
        "--full-map --results benchmarks/results/new-robot.json again and update docs/boundmaps.md")


@pytest.mark.parametrize("name", ["discrepancy-sweep.json", "ha-trajectory-discrepancy.json", "ha-robot-files.json"])
def test_quoted_results_come_from_the_present_code(name):
    """Each results file the docs quote records the digest of the code that can move its figures
    (ctrplan.discrepancy.provenance), and it is the present code's: a change to that code
    without running the benchmark again fails here. The sweep's cases all come from that code."""
    from ctrplan.discrepancy.provenance import source_digest

    results = ROOT / "benchmarks" / "results" / name
    assert results.exists(), f"benchmarks/results/{name} is quoted by the docs and missing"
    stored = json.loads(results.read_text())
    digest = source_digest()
    assert stored.get("provenance", {}).get("source_sha256") == digest, (
        f"{name} was made by other code than the present (run its benchmark again, then benchmarks/docs_tables.py)")
    if "cases" in stored:
        assert {c["source_sha256"] for c in stored["cases"]} == {digest}


def test_sweep_results_come_from_the_present_sweep_code():
    """The sweep's results file records the digest of the benchmark that scored it and of the
    reference synthesizer that made its data (``sweep_code_sha256``), and it is the present
    code's: catches outcomes scored by rules that have changed since, or data from another
    synthesizer, quoted as today's."""
    spec = importlib.util.spec_from_file_location("bench_discrepancy_sweep",
                                                  ROOT / "benchmarks" / "bench_discrepancy_sweep.py")
    sweep = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(sweep)
    stored = json.loads((ROOT / "benchmarks" / "results" / "discrepancy-sweep.json").read_text())
    assert stored.get("provenance", {}).get("sweep_code_sha256") == sweep.sweep_code_digest(), (
        "discrepancy-sweep.json was scored or synthesized by other sweep code than the present: rescore it with "
        "python benchmarks/bench_discrepancy_sweep.py --results-only (a change of the scoring), or run the sweep "
        "again (a change of the reference synthesizer or of the cases), then benchmarks/docs_tables.py")


@pytest.mark.skipif(not HA_DATA.exists(), reason=f"measured data not present at {HA_DATA} (not redistributable; "
                                                  f"get it from github.com/hjhdog1/ConcentricTubes)")
@pytest.mark.parametrize("name", ["ha-trajectory-discrepancy.json", "ha-robot-files.json"])
def test_ha_results_come_from_the_present_data(name):
    """Each Ha results file names the SHA-256 of the data file it was computed from."""
    results = ROOT / "benchmarks" / "results" / name
    if not results.exists():
        pytest.skip(f"benchmarks/results/{name} not written yet")
    stored = json.loads(results.read_text())
    assert stored["data_sha256"] == hashlib.sha256(HA_DATA.read_bytes()).hexdigest()
