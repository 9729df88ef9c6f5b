"""Command line ``ctrplan evaluate`` and the batch layer under it (``ctrplan.batch``).

Checks the output schema and invariants of the evaluated tables (one row per configuration for
the standard model, 2^(n-1) per configuration for the friction model; the bound column is the
largest tip distance of any friction solution from the standard model's tip, Section III of
Ha, Fagogenis & Dupont 2019, doi:10.1109/TRO.2018.2878906), checkpoint resumption, and that bad
inputs stop with a non-zero exit code and a message naming the offending column, row, key or
tubes. The robot is the nominal Table II robot at ds = 4 mm to keep each run to seconds.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from ctrplan import batch, cli
from ctrplan.batch import evaluate_table, job_key
from ctrplan.io.robot_file import load_robot
from ctrplan.mechanics import ModelSettings, all_eta, solve_clearance, solve_friction, solve_standard

REPO = Path(__file__).resolve().parents[1]
TABLE2 = REPO / "model" / "ha2019-table2-nominal.toml"
DS = 0.004  # [m] arc-length step: coarse, for speed
FAST = ["--ds", str(DS), "--jobs", "1", "--no-progress"]

# Configurations of the Table II robot: (alpha_1..3 [rad], beta_1..3 [m]); tube 2 sits 17 mm
# behind tube 1 (linked), beta_3 within its joint range [-104, -34] mm.
CONFIGS = [
    ((0.0, 0.0, 0.0), (0.0, -0.017, -0.070)),
    ((0.0, 1.0, 0.5), (0.0, -0.017, -0.050)),
    ((0.0, 2.0, -1.0), (0.0, -0.017, -0.090)),
]
N_TUBES = 3
ALPHA = [f"alpha_{i}" for i in (1, 2, 3)]
BETA = [f"beta_{i}" for i in (1, 2, 3)]
ETA = ["eta_1", "eta_2"]
TIP = ["tip_x", "tip_y", "tip_z"]
TANGENT = ["tangent_x", "tangent_y", "tangent_z"]
HEADER = ",".join(ALPHA + BETA)


def _csv_text(configs, eta=None) -> str:
    head = HEADER + ("," + ",".join(ETA) if eta is not None else "")
    lines = [head]
    for k, (a, b) in enumerate(configs):
        cells = [repr(float(x)) for x in (*a, *b)]
        if eta is not None:
            cells += [str(int(e)) for e in eta[k]]
        lines.append(",".join(cells))
    return "\n".join(lines) + "\n"


def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def _evaluate(configs: Path, model: str, out: Path):
    res = CliRunner().invoke(cli.main, ["evaluate", "--robot", str(TABLE2), "--configs", str(configs),
                                        "--model", model, "--out", str(out), *FAST])
    assert res.exit_code == 0, (res.output, res.exception)
    return pd.read_csv(out)


def _run_entry(monkeypatch, capsys, args):
    """Run the console entry ``ctrplan.cli.run`` in-process; returns (exit code, stdout, stderr)."""
    monkeypatch.setattr(sys, "argv", ["ctrplan", *args])
    with pytest.raises(SystemExit) as info:
        cli.run()
    out = capsys.readouterr()
    code = info.value.code
    return (0 if code is None else code), out.out, out.err


@pytest.fixture(scope="module")
def robot():
    return load_robot(TABLE2)


@pytest.fixture(scope="module")
def evaluated(tmp_path_factory):
    """The CSV of CONFIGS evaluated with the standard and the friction model through the CLI."""
    d = tmp_path_factory.mktemp("evaluate")
    configs = _write(d / "configs.csv", _csv_text(CONFIGS))
    std = _evaluate(configs, "standard", d / "standard.csv")
    fr = _evaluate(configs, "friction", d / "friction.csv")
    return {"dir": d, "standard": std, "friction": fr}


# --------------------------------------------------------------------------- output tables
def test_standard_one_row_per_configuration_matching_solve_standard(evaluated, robot):
    std = evaluated["standard"]
    assert len(std) == len(CONFIGS)
    for col in ALPHA + BETA + TIP + TANGENT + ["status"]:
        assert col in std.columns, col
    assert not any(c in std.columns for c in ETA)
    assert (std["status"] == "ok").all()
    settings = ModelSettings(ds=DS)
    for k, (a, b) in enumerate(CONFIGS):
        row = std.iloc[k]
        np.testing.assert_array_equal(row[ALPHA].to_numpy(float), a)
        np.testing.assert_array_equal(row[BETA].to_numpy(float), b)
        sol = solve_standard(robot, np.array(a), np.array(b), settings)
        # the same equilibrium to the shooting tolerance: the CLI starts a row certified unique
        # from the row before (measured differences up to 4e-11)
        np.testing.assert_allclose(row[TIP].to_numpy(float), sol.tip_position, rtol=0, atol=1e-9)
        np.testing.assert_allclose(row[TANGENT].to_numpy(float), sol.tip_tangent, rtol=0, atol=1e-9)
    # distinct configurations give distinct tips (the rows are not copies of one solve)
    tips = std[TIP].to_numpy(float)
    assert np.min(np.linalg.norm(tips[:, None] - tips[None], axis=2)[np.triu_indices(len(tips), 1)]) > 1e-3


def test_friction_rows_per_configuration_and_bound_is_max_distance_to_standard(evaluated):
    std, fr = evaluated["standard"], evaluated["friction"]
    n_eta = 2 ** (N_TUBES - 1)
    assert len(fr) == n_eta * len(CONFIGS)
    for col in ALPHA + BETA + ETA + TIP + TANGENT + ["status", "bound_tip_m", "bound_tangent_rad"]:
        assert col in fr.columns, col
    assert (fr["status"] == "ok").all()
    for k in range(len(CONFIGS)):
        rows = fr[fr["row"] == k + 1]
        assert len(rows) == n_eta
        # every direction eta exactly once
        assert sorted(map(tuple, rows[ETA].to_numpy(int))) == sorted(all_eta(N_TUBES))
        np.testing.assert_array_equal(rows[ALPHA + BETA].to_numpy(float),
                                      np.tile(np.r_[CONFIGS[k][0], CONFIGS[k][1]], (n_eta, 1)))
        std_tip = std.iloc[k][TIP].to_numpy(float)
        std_tan = std.iloc[k][TANGENT].to_numpy(float)
        dist = np.linalg.norm(rows[TIP].to_numpy(float) - std_tip, axis=1)
        ang = np.arccos(np.clip(rows[TANGENT].to_numpy(float) @ std_tan, -1.0, 1.0))
        # the bound is one value per configuration, repeated on its eta rows
        assert rows["bound_tip_m"].nunique() == 1
        np.testing.assert_allclose(rows["bound_tip_m"].iloc[0], dist.max(), rtol=1e-6, atol=1e-9)
        np.testing.assert_allclose(rows["bound_tangent_rad"].iloc[0], ang.max(), rtol=1e-4, atol=1e-6)
        # friction moves the tip (a zero bound would make the comparison above vacuous)
        assert dist.max() > 1e-4


def test_tangents_are_unit_vectors(evaluated):
    for model in ("standard", "friction"):
        t = evaluated[model][TANGENT].to_numpy(float)
        np.testing.assert_allclose(np.linalg.norm(t, axis=1), 1.0, atol=1e-9)


def test_given_eta_evaluates_only_that_direction(tmp_path, robot, evaluated):
    eta = [(1, -1), (-1, 1)]
    configs = _write(tmp_path / "eta.csv", _csv_text(CONFIGS[:2], eta=eta))
    out = _evaluate(configs, "friction", tmp_path / "eta-friction.csv")
    assert len(out) == 2
    np.testing.assert_array_equal(out[ETA].to_numpy(int), eta)
    assert (out["status"] == "ok").all()
    # no bound over all directions when only one direction is evaluated
    assert "bound_tip_m" not in out.columns or out["bound_tip_m"].isna().all()
    settings = ModelSettings(ds=DS)
    full = evaluated["friction"]
    for k, e in enumerate(eta):
        a, b = (np.array(x) for x in CONFIGS[k])
        # the library's solution of this direction on the command's path (standard model, then
        # the friction solve started from the clearance solution): the same iterates, so it
        # agrees to round-off; a solve started elsewhere agrees only to the outer loop's
        # stopping error (below)
        st = solve_standard(robot, a, b, settings)
        cl = solve_clearance(robot, a, b, settings, standard=st)
        sol = solve_friction(robot, a, b, np.array(e), settings, standard=st, warm_start=cl)
        np.testing.assert_allclose(out.iloc[k][TIP].to_numpy(float), sol.tip_position, atol=1e-12)
        # the same direction's row of the all-directions run: that run starts this direction from
        # the mirror image of the opposite one (bound.py), another iteration path to the same
        # solution, so the two agree to the contact solver's tolerance (outer loop: 1 um steps;
        # 5 outer_tol as in test_boundmap_coordinates), not to round-off
        same = full[(full["row"] == k + 1) & (full["eta_1"] == e[0]) & (full["eta_2"] == e[1])]
        assert len(same) == 1
        np.testing.assert_allclose(out.iloc[k][TIP].to_numpy(float), same[TIP].to_numpy(float)[0],
                                   rtol=0, atol=5 * settings.outer_tol)


# --------------------------------------------------------------------------- resumption
class _Interrupt(Exception):
    pass


def _arrays(configs):
    return (np.array([c[0] for c in configs], dtype=float), np.array([c[1] for c in configs], dtype=float))


RESUME_CONFIGS = CONFIGS + [((0.0, -1.5, 2.5), (0.0, -0.017, -0.060))]


def test_resume_after_interruption_computes_only_missing_rows(tmp_path, robot, monkeypatch):
    """Chunks of two rows: the run dies while computing the second chunk; the checkpoint holds
    the first chunk, and the rerun computes only the rows that are not in it."""
    alpha, beta = _arrays(RESUME_CONFIGS)
    settings = ModelSettings(ds=DS)
    ck = tmp_path / "out.csv.partial.jsonl"
    monkeypatch.setattr(batch, "STANDARD_CHUNK", 2)
    real = batch._chunk_task
    calls = []

    def dying(robot_, a, b, model, s, eta, indices, *options):
        if len(calls) == 1:
            raise _Interrupt("killed")
        calls.append(list(indices))
        return real(robot_, a, b, model, s, eta, indices, *options)

    monkeypatch.setattr(batch, "_chunk_task", dying)
    with pytest.raises(_Interrupt):
        evaluate_table(robot, alpha, beta, "standard", settings, checkpoint=ck, progress=False, job_key="job-A")
    lines = ck.read_text().splitlines()
    assert json.loads(lines[0]) == {"job_key": "job-A"}
    assert [json.loads(x)["indices"] for x in lines[1:]] == [[0, 1]]

    # mark the finished rows: a rerun must keep them, not recompute them
    rec = json.loads(lines[1])
    rec["columns"]["message"] = [f"from checkpoint {index}" for index in rec["indices"]]
    ck.write_text("\n".join([lines[0], json.dumps(rec)]) + "\n")

    calls.clear()

    def counting(robot_, a, b, model, s, eta, indices, *options):
        calls.append(list(indices))
        return real(robot_, a, b, model, s, eta, indices, *options)

    monkeypatch.setattr(batch, "_chunk_task", counting)
    frame = evaluate_table(robot, alpha, beta, "standard", settings, checkpoint=ck, progress=False,
                           job_key="job-A")
    assert calls == [[3, 4]]  # 1-based rows not in the checkpoint
    assert list(frame["row"]) == [1, 2, 3, 4]
    assert list(frame["message"][:2]) == ["from checkpoint 0", "from checkpoint 1"]
    fresh = evaluate_table(robot, alpha, beta, "standard", settings, progress=False)
    np.testing.assert_array_equal(frame[TIP].to_numpy(float), fresh[TIP].to_numpy(float))


def test_checkpoint_line_of_columns_reads_back_exactly():
    """A standard-model chunk written to the checkpoint (floats and integers as bytes, text as
    distinct values and codes) reads back to the same columns: floats bit for bit (NaN of a
    failed row included), integers, and text whose first-seen order differs from its sorted
    order (a code paired with the wrong value would swap "ok" and "unstable" rows)."""
    rng = np.random.default_rng(7)
    cols = {"tip_x": rng.normal(size=6) * 1e-2, "row": np.array([3, 4, 5, 6, 7, 8], dtype=np.int64),
            "status": np.array(["unstable", "ok", "unstable", "error", "ok", "ok"], dtype=object),
            "message": np.array(["b", "a", "b", "c", "a", "a"], dtype=object)}
    cols["tip_x"][3] = np.nan
    rec = json.loads(json.dumps(batch._columns_record([3, 4, 5, 6, 7, 8], cols)))
    back = batch._record_columns(rec)
    assert rec["indices"] == [2, 3, 4, 5, 6, 7]
    assert set(back) == set(cols)
    np.testing.assert_array_equal(back["tip_x"].view(np.int64), cols["tip_x"].view(np.int64))
    np.testing.assert_array_equal(back["row"], cols["row"])
    assert back["row"].dtype == np.int64
    for name in ("status", "message"):
        assert back[name].tolist() == cols[name].tolist()


def test_checkpoint_of_another_job_is_discarded(tmp_path, robot, monkeypatch):
    alpha, beta = _arrays(CONFIGS[:2])
    ck = tmp_path / "ck.jsonl"
    ck.write_text(json.dumps({"job_key": "old"}) + "\n"
                  + json.dumps({"index": 0, "rows": [{"tip_x": 9.0, "row": 1}]}) + "\n")
    calls = []
    real = batch._chunk_task

    def counting(*args):
        calls.extend(args[6])
        return real(*args)

    monkeypatch.setattr(batch, "_chunk_task", counting)
    frame = evaluate_table(robot, alpha, beta, "standard", ModelSettings(ds=DS), checkpoint=ck,
                           progress=False, job_key="new")
    assert calls == [1, 2]
    assert np.all(frame["tip_x"].to_numpy(float) < 1.0)
    assert json.loads(ck.read_text().splitlines()[0]) == {"job_key": "new"}


def test_batched_standard_rows_equal_single_solves_with_the_same_stability_flag(robot):
    """The CLI's batched standard model (uniqueness screen, multistart only where the screen
    cannot prove one equilibrium, warm starts along the rows) gives the tips and the status of
    ``solve_standard`` with its multistart search, row by row, on configurations that include
    elastically unstable ones (Table II robot, tube 3's curved section inside tubes 1 and 2,
    tubes 2 and 3 opposed). Catches a screen that certifies an unstable configuration, a
    multistart that differs from solve_standard's, or a warm start that lands on another
    branch."""
    from ctrplan.mechanics import solve_standard
    rng = np.random.default_rng(7)
    K = 40
    alpha = np.zeros((K, 3))
    alpha[:, 1] = rng.uniform(-np.pi, np.pi, K)
    alpha[:, 2] = alpha[:, 1] + np.pi + rng.normal(0.0, 0.6, K)
    beta = np.tile([0.0, -0.017, 0.0], (K, 1))
    beta[:, 2] = rng.uniform(-0.1204, -0.104, K)
    settings = ModelSettings(ds=DS)
    cols = batch._standard_columns(robot, alpha, beta, settings, list(range(1, K + 1)))
    assert cols["row"].tolist() == list(range(1, K + 1))
    rows = [{c: v[k] for c, v in cols.items()} for k in range(K)]
    status = []
    for k in range(K):
        ref = solve_standard(robot, alpha[k], beta[k], settings)
        want = "unstable" if ref.diagnostics.unstable else "ok" if ref.diagnostics.converged else "not_converged"
        status.append(want)
        assert rows[k]["status"] == want, (k, rows[k]["message"], ref.diagnostics.message)
        got = np.array([rows[k][c] for c in TIP])
        np.testing.assert_allclose(got, ref.tip_position, atol=1e-9)
    assert "unstable" in status and "ok" in status   # both kinds were exercised


def test_cli_resumes_from_partial_file_and_removes_it(tmp_path):
    """A checkpoint left next to the output by an interrupted ``ctrplan evaluate`` (same job key)
    is reused: its rows (sentinel tip) go to the output unchanged, the others are computed."""
    text = _csv_text(CONFIGS)
    configs = _write(tmp_path / "configs.csv", text)
    out = tmp_path / "res.csv"
    ck = tmp_path / "res.csv.partial.jsonl"
    key = job_key(TABLE2.read_text(), text, "standard", ModelSettings(ds=DS))
    a, b = CONFIGS[0]
    sentinel = {**{c: v for c, v in zip(ALPHA + BETA, (*a, *b))}, "tip_x": 0.123, "tip_y": 0.0,
                "tip_z": 0.2, "tangent_x": 0.0, "tangent_y": 0.0, "tangent_z": 1.0, "status": "ok",
                "model": "standard", "message": "sentinel", "row": 1}
    ck.write_text(json.dumps({"job_key": key}) + "\n"
                  + json.dumps({"index": 0, "rows": [sentinel]}) + "\n"
                  + '{"index": 1, "rows": [{"tip_x"')  # a line cut by the interruption
    frame = _evaluate(configs, "standard", out)
    assert not ck.exists()
    assert len(frame) == 3
    assert frame["tip_x"].iloc[0] == 0.123 and frame["message"].iloc[0] == "sentinel"
    assert (frame["message"].iloc[1:] != "sentinel").all()
    assert np.all(np.abs(frame["tip_x"].iloc[1:] - 0.123) > 1e-6)


# --------------------------------------------------------------------------- bad inputs
GOOD_ROW = "0,1,0.5,0,-0.017,-0.05"


@pytest.mark.parametrize("name, text, expected", [
    ("missing-column", ",".join(ALPHA + BETA[:2]) + "\n0,0,0,0,-0.017\n", ["beta_3"]),
    ("nan", HEADER + "\n" + GOOD_ROW + "\n0,1,nan,0,-0.017,-0.05\n", ["alpha_3", "row 2"]),
    ("empty-cell", HEADER + "\n" + GOOD_ROW + "\n0,1,,0,-0.017,-0.05\n", ["alpha_3", "row 2"]),
    ("millimetres", HEADER + "\n" + GOOD_ROW + "\n0,1,0.5,0,-0.017,-50\n", ["beta_3", "row 2", "millimetres"]),
])
def test_bad_configuration_file_exits_with_message(tmp_path, monkeypatch, capsys, name, text, expected):
    configs = _write(tmp_path / f"{name}.csv", text)
    out = tmp_path / "out.csv"
    code, _, err = _run_entry(monkeypatch, capsys, ["evaluate", "--robot", str(TABLE2), "--configs", str(configs),
                                                    "--model", "standard", "--out", str(out), *FAST])
    assert code == 2
    assert err.startswith("error: ") and f"{name}.csv" in err
    for word in expected:
        assert word in err, (word, err)
    assert not out.exists()


def test_configuration_with_inner_base_in_front_names_the_row(tmp_path, monkeypatch, capsys):
    configs = _write(tmp_path / "front.csv", HEADER + "\n" + GOOD_ROW + "\n0,1,0.5,0,-0.017,-0.01\n")
    out = tmp_path / "out.csv"
    code, _, err = _run_entry(monkeypatch, capsys, ["evaluate", "--robot", str(TABLE2), "--configs", str(configs),
                                                    "--model", "standard", "--out", str(out), *FAST])
    assert code == 2 and err.startswith("error: ")
    assert "row 2" in err and "tube 3" in err and "in front" in err
    assert "row 1" not in err
    assert not out.exists()


# configuration 97 of the 8x8x8 grid and its mirror image 481: under maximal friction in
# directions (-1, -1), resp. (1, 1), the friction branch ends at a fold below mu = 0.2 (0.194 at
# ds = 4 mm; docs/mechanics.md Sec. 5), so the direct solve does not converge
FOLD_CONFIGS = [((0.0, np.pi / 4, np.pi), (0.0, -0.017, -0.1204 + 0.0864 / 7)),
                ((0.0, 7 * np.pi / 4, np.pi), (0.0, -0.017, -0.1204 + 0.0864 / 7))]


def test_explain_failures_says_where_an_unconverged_friction_solution_snaps(tmp_path):
    """With --explain-failures, each unconverged friction row's message gains where its branch
    in mu ends; nothing else in the table changes (tips, statuses, the converged rows' messages)."""
    configs = _write(tmp_path / "fold.csv", _csv_text(FOLD_CONFIGS + CONFIGS[1:2]))
    plain = _evaluate(configs, "friction", tmp_path / "plain.csv")
    res = CliRunner().invoke(cli.main, ["evaluate", "--robot", str(TABLE2), "--configs", str(configs),
                                        "--model", "friction", "--out", str(tmp_path / "explained.csv"),
                                        "--explain-failures", *FAST])
    assert res.exit_code == 0, (res.output, res.exception)
    explained = pd.read_csv(tmp_path / "explained.csv")
    np.testing.assert_array_equal(explained[TIP].to_numpy(float), plain[TIP].to_numpy(float))
    assert (explained["status"] == plain["status"]).all()
    failed = plain["status"] == "not_converged"
    assert failed[plain["row"] <= 2].any() and not failed[plain["row"] == 3].any()
    assert (explained["message"][~failed] == plain["message"][~failed]).all()
    for before, after in zip(plain["message"][failed], explained["message"][failed]):
        assert after.startswith(before + "; snaps under friction: friction branch ends between mu = 0.19")
    assert "snaps under friction" in res.output


def test_explain_failures_is_for_the_friction_model_only(tmp_path):
    configs = _write(tmp_path / "c.csv", _csv_text(CONFIGS[:1]))
    res = CliRunner().invoke(cli.main, ["evaluate", "--robot", str(TABLE2), "--configs", str(configs),
                                        "--model", "standard", "--explain-failures", *FAST])
    assert res.exit_code == 2 and "--explain-failures" in res.output and "friction" in res.output
    assert not (tmp_path / "c-standard.csv").exists()


def test_job_key_tells_explained_runs_apart():
    """A checkpoint of a run without --explain-failures holds other messages: not reused by a
    run with it (and keys of runs without it are those of before the option)."""
    args = ("robot", "configs", "friction", ModelSettings())
    assert job_key(*args) == job_key(*args, False) != job_key(*args, True)


def test_unknown_model_is_a_usage_error(tmp_path):
    configs = _write(tmp_path / "c.csv", _csv_text(CONFIGS[:1]))
    res = CliRunner().invoke(cli.main, ["evaluate", "--robot", str(TABLE2), "--configs", str(configs),
                                        "--model", "stiffness", *FAST])
    assert res.exit_code == 2  # click usage error
    assert "--model" in res.output and "stiffness" in res.output
    assert not (tmp_path / "c-stiffness.csv").exists()


def _robot_text(replace_from: str, replace_to: str) -> str:
    text = TABLE2.read_text()
    assert text.count(replace_from) == 1, replace_from
    return text.replace(replace_from, replace_to)


# tube 3's outer diameter 2.0 mm > tube 2's bore 1.95 mm
WIDE_INNER = ('outer_diameter_m = 1.825e-3', 'outer_diameter_m = 2.0e-3')
UNKNOWN_KEY = ('name = "tube 2"\n', 'name = "tube 2"\ncolour = "blue"\n')


def test_inner_tube_wider_than_outer_bore_names_both_tubes(tmp_path, monkeypatch, capsys):
    robot_file = _write(tmp_path / "wide.toml", _robot_text(*WIDE_INNER))
    configs = _write(tmp_path / "c.csv", _csv_text(CONFIGS[:1]))
    code, _, err = _run_entry(monkeypatch, capsys, ["evaluate", "--robot", str(robot_file), "--configs",
                                                    str(configs), "--model", "standard", *FAST])
    assert code == 2
    assert err.startswith("error: ")
    assert "wide.toml" in err and "tube 2" in err and "tube 3" in err, err


def test_unknown_robot_key_names_file_and_key(tmp_path, monkeypatch, capsys):
    robot_file = _write(tmp_path / "typo.toml", _robot_text(*UNKNOWN_KEY))
    configs = _write(tmp_path / "c.csv", _csv_text(CONFIGS[:1]))
    code, _, err = _run_entry(monkeypatch, capsys, ["evaluate", "--robot", str(robot_file), "--configs",
                                                    str(configs), "--model", "standard", *FAST])
    assert code == 2
    assert "typo.toml" in err and "colour" in err, err
    assert "tubes[2]" in err, err  # 1-based index of the [[tubes]] table


def test_console_script_exit_code(tmp_path):
    """The installed ``ctrplan`` script (not only the click group) exits 2 with ``error:``."""
    exe = shutil.which("ctrplan") or str(Path(sys.executable).parent / "ctrplan")
    if not Path(exe).exists():
        pytest.skip("the ctrplan console script is not installed (pip install -e .)")
    robot_file = _write(tmp_path / "wide.toml", _robot_text(*WIDE_INNER))
    configs = _write(tmp_path / "c.csv", _csv_text(CONFIGS[:1]))
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    proc = subprocess.run([exe, "evaluate", "--robot", str(robot_file), "--configs", str(configs),
                           "--model", "standard", *FAST], capture_output=True, text=True, timeout=120, env=env)
    assert proc.returncode == 2, (proc.stdout, proc.stderr)
    assert "error:" in proc.stderr and "tube 3" in proc.stderr
    assert "Traceback" not in proc.stderr
