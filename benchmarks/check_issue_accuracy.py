"""Accuracy of this checkout against a reference commit: friction-model tips and stability flags.

The check: friction-model tips move by at most 0.01 mm against the reference commit on the 4x4x4
grid, and every configuration that the reference commit's ``evaluate --model standard`` flags
unstable on the 8x8x8 grid is still flagged. The reference commit (default 10e8828, the last
before ``evaluate`` solved the standard model in batch; see bench_issue_units.py) is checked out
into a temporary git worktree; both codes run the same commands:

- ``ctrplan evaluate --model friction`` on the paper's 4x4x4 grid (Table II robot): every
  friction solution (all four directions eta per configuration), matched by row and eta. Printed:
  the largest tip difference [mm] over the solutions both codes report converged (status ok), its
  99th percentile, and the rows whose status differs (a solution ok before and not now fails);
- ``ctrplan evaluate --model standard`` on the 8x8x8 grid (``paper_section_4d.grid_8x8x8``): the
  rows flagged unstable by the reference commit and not by this checkout (must be none), and the
  other way round; the largest tip difference [mm] on the rows both report ok.

A tip that moved by more than 0.01 mm can have moved towards the solution: commit 10e8828
stopped the outer loop of the contact models with an error of up to 11.8 um on this grid (full
Anderson steps; docs/mechanics.md Sec. 4, "Why beta = 0.5"). Each such solution is therefore
also solved tightly (this checkout, ``outer_tol`` = ``complementarity_tol`` = 1e-9) and both
codes' tips are measured against it. The check passes if every moved tip is closer to the tight
solve now than before and no flag is lost; the literal 0.01 mm is printed either way.

It exits with status 1 if the check fails, so it can be run before merging a solver change. Not a
test: it checks out and compiles a second copy of the code (a few minutes).

Run:  OPENBLAS_NUM_THREADS=1 python benchmarks/check_issue_accuracy.py [--issue-commit 10e8828] [--jobs 2] [--keep DIR]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _checkouts import ROOT, child_env, cli_command, worktree  # noqa: E402

ROBOT = ROOT / "model" / "ha2019-table2-nominal.toml"
TIP_TOL_MM = 0.01   # largest tip move accepted without the tight-solve comparison [mm]


def _evaluate(code, cache, configs, model, out, jobs):
    """Run ``ctrplan evaluate`` of the checkout ``code``; returns its output table.

    Raises
    ------
    subprocess.CalledProcessError
        If the command fails (its output is printed)."""
    import pandas as pd
    cmd = cli_command(code, "evaluate", "--robot", ROBOT, "--configs", configs, "--model", model, "--out", out,
                      "--jobs", jobs, "--no-progress")
    r = subprocess.run(cmd, capture_output=True, text=True, env=child_env(code, cache), cwd=str(code))
    if r.returncode:
        print(r.stdout, r.stderr)
        r.check_returncode()
    return pd.read_csv(out)


def _grids(tmp):
    """The 4x4x4 grid (Section IV-D) and the 8x8x8 grid (``grid_8x8x8``) as configuration files."""
    import pandas as pd
    from paper_section_4d import grid_4x4x4, grid_8x8x8

    from ctrplan.io.robot_file import load_robot
    from ctrplan.io.tables import write_table
    robot = load_robot(ROBOT)
    _, Q = grid_4x4x4(robot)
    A4, B4 = (np.array(x) for x in zip(*(robot.configuration(q) for q in Q)))
    A8, B8 = (np.array(x) for x in zip(*grid_8x8x8()))
    files = {}
    for name, A, B in (("grid4", A4, B4), ("grid8", A8, B8)):
        files[name] = tmp / f"{name}.csv"
        write_table(files[name], pd.DataFrame({**{f"alpha_{i + 1}": A[:, i] for i in range(3)},
                                               **{f"beta_{i + 1}": B[:, i] for i in range(3)}}))
    return files


def _tip_mm(frame, suffix=""):
    """Tip positions [mm], shape (rows, 3), of an output table (columns ``tip_x`` + ``suffix`` ...)."""
    return frame[[f"tip_{a}{suffix}" for a in "xyz"]].to_numpy(float) * 1e3


def compare_friction(old, new):
    """Compare the friction tables of the reference commit (``old``) and this checkout (``new``),
    rows matched on ``row`` and the eta columns. Returns the largest and 99th-percentile tip
    difference [mm] over the solutions ok in both, their number, the keys (row, eta...) whose
    status differs (with both statuses), and the merged rows ok in both whose tips moved by more
    than ``TIP_TOL_MM`` (with ``moved_mm``).

    Raises
    ------
    RuntimeError
        If a (row, eta) is in one table only."""
    keys = ["row"] + sorted(c for c in old.columns if c.startswith("eta_"))
    m = old.merge(new, on=keys, suffixes=("_old", "_new"), how="outer", indicator=True)
    if (m["_merge"] != "both").any():
        raise RuntimeError(f"friction rows of one code only: {m.loc[m['_merge'] != 'both', keys].to_dict('records')}")
    both_ok = (m["status_old"] == "ok") & (m["status_new"] == "ok")
    d = np.linalg.norm(_tip_mm(m.loc[both_ok], "_old") - _tip_mm(m.loc[both_ok], "_new"), axis=1)
    differ = m.loc[m["status_old"] != m["status_new"], keys + ["status_old", "status_new"]]
    moved = m.loc[both_ok].assign(moved_mm=d)
    moved = moved.loc[moved["moved_mm"] > TIP_TOL_MM]
    return float(d.max()), float(np.percentile(d, 99)), int(both_ok.sum()), differ, moved


def against_tight(moved):
    """For each friction solution in ``moved`` (rows of :func:`compare_friction`'s merge), the
    distance [mm] of the reference commit's and this checkout's tips to a tight solve of this checkout
    (``outer_tol`` = ``complementarity_tol`` = 1e-9, up to 2000 outer iterations)."""
    from ctrplan.batch import evaluate_configuration
    from ctrplan.io.robot_file import load_robot
    from ctrplan.mechanics import ModelSettings
    robot = load_robot(ROBOT)
    tight = ModelSettings(outer_tol=1e-9, complementarity_tol=1e-9, max_outer_iterations=2000)
    out = []
    for idx, r in moved.iterrows():
        alpha = r[[f"alpha_{j}_old" for j in (1, 2, 3)]].to_numpy(float)
        beta = r[[f"beta_{j}_old" for j in (1, 2, 3)]].to_numpy(float)
        eta = r[sorted(c for c in moved.columns if c.startswith("eta_"))].to_numpy(int)
        row = evaluate_configuration(robot, alpha, beta, "friction", tight, eta)[0]
        t = _tip_mm(pd.DataFrame([row]))[0]
        old, new = _tip_mm(moved.loc[[idx]], "_old")[0], _tip_mm(moved.loc[[idx]], "_new")[0]
        out.append((int(r["row"]), tuple(int(e) for e in eta), float(r["moved_mm"]), row["status"],
                    float(np.linalg.norm(old - t)), float(np.linalg.norm(new - t))))
    return out


def compare_standard(old, new):
    """Rows (1-based) unstable in ``old`` only, in ``new`` only, and the largest tip difference
    [mm] over the rows ok in both."""
    old = old.set_index("row").sort_index()
    new = new.set_index("row").sort_index()
    if not old.index.equals(new.index):
        raise RuntimeError("the two codes reported different rows")
    u_old = old["status"] == "unstable"
    u_new = new["status"] == "unstable"
    both_ok = (old["status"] == "ok") & (new["status"] == "ok")
    d = np.linalg.norm(_tip_mm(old[both_ok]) - _tip_mm(new[both_ok]), axis=1)
    return (list(old.index[u_old & ~u_new]), list(old.index[u_new & ~u_old]), int(u_old.sum()), int(u_new.sum()),
            float(d.max()) if d.size else 0.0)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--issue-commit", default="10e8828", help="reference commit to compare with (default 10e8828)")
    ap.add_argument("--jobs", type=int, default=2, help="--jobs of the evaluate commands")
    ap.add_argument("--keep", type=Path, default=None,
                    help="folder to copy the four output tables to (issue-/this-friction.csv, -standard.csv; "
                         "issue- is the reference commit)")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        files = _grids(tmp)
        out = {}
        with worktree(args.issue_commit, tmp / "issue") as old_code:
            for name, code in (("issue", old_code), ("this", ROOT)):
                cache = tmp / f"cache-{name}"
                out[name] = {m: _evaluate(code, cache, files[g], m, tmp / f"{name}-{m}.csv", args.jobs)
                             for g, m in (("grid4", "friction"), ("grid8", "standard"))}
        if args.keep is not None:
            args.keep.mkdir(parents=True, exist_ok=True)
            for name in out:
                for m, frame in out[name].items():
                    frame.to_csv(args.keep / f"{name}-{m}.csv", index=False)
    dmax, d99, n_ok, differ, moved = compare_friction(out["issue"]["friction"], out["this"]["friction"])
    print(f"friction model, 4x4x4 grid, this checkout against {args.issue_commit}: {n_ok} solutions ok in both, "
          f"tips differ by at most {dmax:.5f} mm (99th percentile {d99:.5f} mm; target <= {TIP_TOL_MM} mm)")
    if len(differ):
        print(f"  status differs on {len(differ)} solutions:\n{differ.to_string(index=False)}")
    closer = True
    for row, eta, dm, status, d_old, d_new in against_tight(moved):
        closer = closer and status == "ok" and d_new < d_old
        print(f"  row {row}, eta {eta}: moved {dm:.5f} mm; against a tight solve ({status}): "
              f"{args.issue_commit} {d_old:.5f} mm, this checkout {d_new:.5f} mm")
    lost, gained, n_old, n_new, dstd = compare_standard(out["issue"]["standard"], out["this"]["standard"])
    print(f"standard model, 8x8x8 grid: flagged unstable {n_old} ({args.issue_commit}) and {n_new} (this checkout); "
          f"flagged before and not now: {lost or 'none'}; flagged now and not before: {gained or 'none'}; "
          f"tips of rows ok in both differ by at most {dstd * 1e3:.2e} um")
    # a solution that the reference commit solved and this one does not would escape the tip check
    ok = closer and not lost and not (differ["status_old"] == "ok").any()
    print(f"tips within {TIP_TOL_MM} mm of the reference commit: {'yes' if dmax <= TIP_TOL_MM else 'no'}; "
          f"every tip that moved more is closer to the tight solve now: {'yes' if closer else 'no'}")
    print("accuracy check: " + ("holds" if ok else "FAILS"))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
