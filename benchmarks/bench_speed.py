"""Speed of the mechanics, side by side in one run.

1. Median and 90th-percentile time per configuration over the 4x4x4 grid of Section IV-D
   (Table II robot, one thread) of: the standard model with and without the multistart
   stability search, the clearance model, one friction solution and the full bound
   (``evaluate_bound``), next to the paper's Table VIII MATLAB times, and the ratio to the frozen
   slow reference implementation in tests/ctrplan_reference (on every ``--ref-every``-th configuration).
2. Batch throughput of the standard model (``solve_standard_batch``) [configurations/s], on one
   thread and on all cores.
3. Discretization convergence: tip-position error [mm] against a step four times finer for the
   standard, clearance and friction models at a few grid configurations, on the default graded
   grid and on the paper's uniform grid.
4. Every time also as a ratio to the project's own single standard solve
   (determinant test only) measured in the same run, with mean, median, p90 and max:
   ``ctrplan evaluate`` through the command line (process start subtracted, measured on a
   one-row file): the friction model (full bound) on the 4x4x4 grid with ``--jobs 1``, the
   standard model on the 1307 rows of the measured trajectory (if ../shared/data is there)
   with ``--jobs 1`` for the Table II robot (the case with multistart searches) and the Table VII robot,
   and with the default jobs for Table II (throughput scaling; also of the batch call itself on
   2 threads). The rows are read ``--tile`` (32) times over, and the runs with one and with the
   default jobs alternate: read once, the rows are about 0.1 s of work behind 1.2 s of process
   start, and at 8 times over the work (about 0.7 s with ``--jobs 1``) is still only half the
   process start subtracted from it, which understates the scaling.
   Also the in-process bound on the 8x8x8 grid (``paper_section_4d.grid_8x8x8``; slowest over
   median). Figures with their conditions: docs/mechanics.md Sec. 10.

Run:  OPENBLAS_NUM_THREADS=1 python benchmarks/bench_speed.py [--ref-every 4] [--conv-configs 8]
      OPENBLAS_NUM_THREADS=1 python benchmarks/bench_speed.py --ratios-only [--repeat 3] [--tile 32]
      (section 4 only)
The speed table of docs/mechanics.md Sec. 10 is made (``python benchmarks/docs_tables.py``) from
the results file of
      OPENBLAS_NUM_THREADS=1 python benchmarks/bench_speed.py --skip-convergence \
          --results benchmarks/results/speed.json
(sections 1, 2 and 4; section 3 is the discretization table, benchmarks/discretization_accuracy.py).
The machine load (``os.getloadavg``) is printed and written: timings on a shared machine are noisy.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import subprocess
import sys
import time
import warnings
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))  # the frozen reference ctrplan_reference (tests/, not installed)

from ctrplan.io.robot_file import load_robot  # noqa: E402
from ctrplan.mechanics import MECHANICS_VERSION  # noqa: E402
from ctrplan.mechanics import (ModelSettings, evaluate_bound, solve_clearance, solve_friction,  # noqa: E402
                               solve_standard, solve_standard_batch)
from ctrplan_reference.paper_grids import PAPER_TIMES_S, grid_4x4x4, grid_8x8x8  # noqa: E402
from ctrplan_reference import bound_reference, contact_reference, standard_reference  # noqa: E402


def _t(fn, *a, **k):
    t0 = time.perf_counter()
    out = fn(*a, **k)
    return out, time.perf_counter() - t0


def _guarded(fn):
    """The frozen reference diverges at some configurations of the graded grid (overflow, then
    numpy.linalg.LinAlgError in its Anderson step): such a call returns None (counted as not
    converged) instead of ending the benchmark, and its floating-point warnings are silenced."""
    def call(*a, **k):
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore")
            try:
                return fn(*a, **k)
            except (np.linalg.LinAlgError, FloatingPointError, ValueError):
                return None
    return call


def _converged(result):
    return result is not None and bool(result.diagnostics.converged)


def _keep(rows, failed, name, t, converged):
    if converged:
        rows[name].append(t)
    else:
        failed[name] += 1


def timing_table(robot, settings, ref_every):
    _, Q = grid_4x4x4(robot)
    no_ms = settings.replace(multistart=0)
    names = ["standard (det + multistart)", "standard (det only)", "clearance",
             "one friction solution", "full bound (clearance + 4 friction)"]
    fast = {k: [] for k in names}
    ref = {k: [] for k in names}
    failed = {"fast": {k: 0 for k in names}, "ref": {k: 0 for k in names}}
    a0, b0 = robot.configuration(Q[0])
    evaluate_bound(robot, a0, b0, settings)                   # load compiled kernels
    ref_std = _guarded(standard_reference.solve_standard)
    ref_contact = _guarded(contact_reference.solve_contact)
    ref_bound = _guarded(bound_reference.evaluate_bound)
    ref_std(robot, a0, b0, settings)
    for idx, q in enumerate(Q):
        a, b = robot.configuration(q)
        do_ref = idx % ref_every == 0
        impls = [("fast", fast, solve_standard, solve_clearance, solve_friction, evaluate_bound)]
        if do_ref:
            impls.append(("ref", ref, ref_std, ref_contact,
                          lambda r, a_, b_, eta, s, **k: ref_contact(r, a_, b_, s, eta=eta, **k),
                          ref_bound))
        for kind, rows, std_f, cl_f, fr_f, bd_f in impls:
            st, t = _t(std_f, robot, a, b, settings)
            rows[names[0]].append(t)
            _, t = _t(std_f, robot, a, b, no_ms)
            rows[names[1]].append(t)
            if st is None or not st.diagnostics.ok:
                continue
            # a time counts only if that solve converged (the frozen reference does not at some
            # configurations of the graded grid; it then runs to its iteration limits)
            cl, t = _t(cl_f, robot, a, b, settings, standard=st)
            if cl is None:   # the bound's clearance solve is the same one
                for k in names[2:]:
                    failed[kind][k] += 1
                continue
            _keep(rows, failed[kind], names[2], t, _converged(cl))
            fr, t = _t(fr_f, robot, a, b, (1, -1), settings, standard=st, warm_start=cl)
            _keep(rows, failed[kind], names[3], t, _converged(fr))
            bd, t = _t(bd_f, robot, a, b, settings)
            _keep(rows, failed[kind], names[4], t, _converged(bd))
    paper = {names[0]: PAPER_TIMES_S["standard"], names[2]: PAPER_TIMES_S["clearance"],
             names[4]: PAPER_TIMES_S["friction"]}
    print(f"1. Time per configuration: {robot.name}, 4x4x4 grid of Section IV-D, ds = {settings.ds * 1e3:.1f} mm, "
          f"1 BLAS thread; reference on every {ref_every}th configuration")
    print(f"{'model':<38} {'n':>3} {'median [ms]':>12} {'p90 [ms]':>9} {'paper T.VIII [ms]':>18} "
          f"{'vs paper':>9} {'n ref':>5} {'ref median [ms]':>16} {'speed-up vs ref':>16}")
    for k in names:
        ts = np.asarray(fast[k]) * 1e3
        rs = np.asarray(ref[k]) * 1e3
        p = paper.get(k)
        print(f"{k:<38} {ts.size:>3} {np.median(ts):>12.2f} {np.percentile(ts, 90):>9.2f} "
              f"{(f'{p * 1e3:.0f}' if p else '-'):>18} {(f'{p * 1e3 / np.median(ts):.0f}x' if p else '-'):>9} "
              f"{rs.size:>5} {np.median(rs):>16.2f} {np.median(rs) / np.median(ts):>15.1f}x")
    for kind in ("fast", "ref"):
        bad = {k: v for k, v in failed[kind].items() if v}
        if bad:
            print(f"   not converged, left out of the {kind} times: " + ", ".join(f"{k}: {v}" for k, v in bad.items()))
    print("(paper: MATLAB on an i5-3470; its friction time is clearance + all friction solutions, "
          "Section V-C)")
    return {"robot": robot.name, "ds_m": settings.ds, "ref_every": ref_every,
            "models": {k: {"seconds": list(map(float, fast[k])), "paper_s": paper.get(k),
                           "reference_seconds": list(map(float, ref[k])),
                           "not_converged": failed["fast"][k], "reference_not_converged": failed["ref"][k]}
                       for k in names}}


def batch_throughput(robot, settings, repeats=5):
    rng = np.random.default_rng(0)
    qs = np.column_stack([rng.uniform(j.lower, j.upper, 2000) for j in robot.joints])
    cfg = [robot.configuration(q) for q in qs]
    A = np.array([a for a, _ in cfg])
    B = np.array([b for _, b in cfg])
    print(f"\n2. Standard model, batch mode (solve_standard_batch, {A.shape[0]} random configurations, "
          f"no multistart)")
    cores = len(os.sched_getaffinity(0))   # the cores this process may run on (taskset)
    out = {"configurations": int(A.shape[0]), "rates_per_s": {}}
    for threads in (1, cores):
        solve_standard_batch(robot, A[:2], B[:2], settings, n_threads=threads)
        rates = []
        for _ in range(repeats):
            _, t = _t(solve_standard_batch, robot, A, B, settings, n_threads=threads)
            rates.append(A.shape[0] / t)
        print(f"   {threads} thread(s): median {np.median(rates):.0f} configurations/s (best {max(rates):.0f})")
        out["rates_per_s"][str(threads)] = list(map(float, rates))
        if cores == 1:
            break
    return out


def convergence_table(robot, n_configs, steps_mm=(12.0, 6.0, 3.0, 1.5), ref_mm=0.75):
    """Largest tip error against ``ref_mm`` over ``n_configs`` grid configurations, for the default
    graded grid and for the uniform grid of the paper (``refine_ratio = 1``), side by side."""
    _, Q = grid_4x4x4(robot)
    picks = [Q[i] for i in np.linspace(3, len(Q) - 4, n_configs).astype(int)]
    grids = (("graded (default)", {}), ("uniform (paper)", {"refine_ratio": 1.0}))
    print(f"\n3. Discretization convergence: largest tip-position error [mm] over {n_configs} grid "
          f"configurations against ds = {ref_mm} mm on the same kind of grid; G = mean grid nodes")
    print(f"{'grid':>17} {'ds [mm]':>8} {'G':>5} {'standard':>10} {'clearance':>10} {'friction (1,-1)':>16}")

    def tips(q, s):
        a, b = robot.configuration(q)
        st = solve_standard(robot, a, b, s, check_stability=False)
        cl = solve_clearance(robot, a, b, s, standard=st)
        fr = solve_friction(robot, a, b, (1, -1), s, standard=st, warm_start=cl)
        return (st.tip_position, cl.tip_position, fr.tip_position), st.s.size

    for name, extra in grids:
        refs = [tips(q, ModelSettings(ds=ref_mm * 1e-3, **extra))[0] for q in picks]
        for ds in steps_mm:
            errs = np.zeros(3)
            nodes = []
            for q, r in zip(picks, refs):
                t, G = tips(q, ModelSettings(ds=ds * 1e-3, **extra))
                nodes.append(G)
                for j in range(3):
                    errs[j] = max(errs[j], np.linalg.norm(t[j] - r[j]) * 1e3)
            print(f"{name:>17} {ds:>8.2f} {np.mean(nodes):>5.0f} {errs[0]:>10.4f} {errs[1]:>10.4f} {errs[2]:>16.4f}")


def _stats(x):
    x = np.asarray(x, dtype=float)
    return x.mean(), np.median(x), np.percentile(x, 90), x.max()


def _single_standard_times(robot, Q, settings, repeat=5):
    """Per-configuration time [s] of solve_standard (determinant test only), best of ``repeat``."""
    no_ms = settings.replace(multistart=0)
    out = []
    for q in Q:
        a, b = robot.configuration(q)
        best = np.inf
        for _ in range(repeat):
            _, t = _t(solve_standard, robot, a, b, no_ms)
            best = min(best, t)
        out.append(best)
    return np.array(out)


def _cli(robot_file, configs, model, jobs, out):
    cmd = [sys.executable, "-m", "ctrplan.cli", "evaluate", "--robot", str(robot_file), "--configs", str(configs),
           "--model", model, "--out", str(out), "--no-progress"]
    if jobs is not None:
        cmd += ["--jobs", str(jobs)]
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, capture_output=True)
    return time.perf_counter() - t0


def _write_configs(path, alpha, beta):
    import pandas as pd
    n = alpha.shape[1]
    frame = pd.DataFrame({**{f"alpha_{i + 1}": alpha[:, i] for i in range(n)},
                          **{f"beta_{i + 1}": beta[:, i] for i in range(n)}})
    frame.to_csv(path, index=False)


def ratio_table(repeat=3, tile=32):
    """Section 4: times as ratios to the single standard solve of the same run; the trajectory's
    rows are read ``tile`` times over by the command-line standard-model runs."""
    import tempfile
    from ctrplan.io.tables import load_ha_trajectory
    robot_file = ROOT / "model" / "ha2019-table2-nominal.toml"
    robot = load_robot(robot_file)
    settings = ModelSettings()
    _, Q = grid_4x4x4(robot)
    a0, b0 = robot.configuration(Q[0])
    evaluate_bound(robot, a0, b0, settings)
    single = _single_standard_times(robot, Q, settings)
    unit = float(np.median(single))
    print(f"\n4. Ratios to the project's own single standard solve (determinant test only, Table II "
          f"robot, 4x4x4 grid): median {unit * 1e3:.3f} ms (mean {single.mean() * 1e3:.3f}, max "
          f"{single.max() * 1e3:.3f}); load average {os.getloadavg()}")
    rows = []
    extra = {}
    bound = []
    for q in Q:
        a, b = robot.configuration(q)
        _, t = _t(evaluate_bound, robot, a, b, settings)
        bound.append(t)
    rows.append(("full bound, in-process, 4x4x4", bound))
    b8 = []
    for a, b in grid_8x8x8():
        _, t = _t(evaluate_bound, robot, a, b, settings)
        b8.append(t)
    rows.append(("full bound, in-process, 8x8x8", b8))
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        A = np.array([robot.configuration(q)[0] for q in Q])
        B = np.array([robot.configuration(q)[1] for q in Q])
        _write_configs(tmp / "one.csv", A[:1], B[:1])
        _write_configs(tmp / "grid.csv", A, B)
        start = min(_cli(robot_file, tmp / "one.csv", "standard", 1, tmp / "o.csv") for _ in range(repeat))
        fr = [(_cli(robot_file, tmp / "grid.csv", "friction", 1, tmp / "f.csv") - start) / len(Q)
              for _ in range(repeat)]
        rows.append(("CLI friction (full bound), --jobs 1, 4x4x4, per configuration", fr))
        data = ROOT.parent / "shared" / "data" / "ha-three-tube-trajectory" / "jointTipTrajectory_measured.txt"
        if data.exists():
            frame = load_ha_trajectory(data)
            TA = frame[[f"alpha_{i}" for i in (1, 2, 3)]].to_numpy()
            TB = frame[[f"beta_{i}" for i in (1, 2, 3)]].to_numpy()
            _write_configs(tmp / "traj.csv", np.tile(TA, (tile, 1)), np.tile(TB, (tile, 1)))
            n_rows = tile * len(TA)
            _write_configs(tmp / "one_row.csv", TA[:1], TB[:1])
            # The Table II robot: 93 % of the rows certified by the uniqueness screen, the others
            # get the multistart search; the Table VII robot (the calibrated tubes, every row
            # certified) is the cheaper case.
            for tag, rf in (("Table II", robot_file), ("Table VII", ROOT / "model" / "ha2019-table7-calibrated.toml")):
                # Table II also with the default jobs (the threaded kernel, whose compiled code a
                # one-row run with --jobs 1 does not load: each is measured against a one-row run
                # with the same jobs), the two alternated so that a busy spell of the machine
                # does not fall on one of them only
                variants = (1, None) if tag == "Table II" else (1,)
                start_rows = {j: min(_cli(rf, tmp / "one_row.csv", "standard", j, tmp / "o.csv")
                                     for _ in range(repeat))
                              for j in variants}
                per_row = {j: [] for j in variants}
                for r in range(repeat):
                    for j in (variants if r % 2 == 0 else variants[::-1]):
                        per_row[j].append((_cli(rf, tmp / "traj.csv", "standard", j, tmp / "s.csv") - start_rows[j]) / n_rows)
                rows.append((f"CLI standard, --jobs 1, {len(TA)} rows x {tile}, {tag}, per row", per_row[1]))
                if tag == "Table II":
                    rows.append((f"CLI standard, default jobs ({os.cpu_count()}), {len(TA)} rows x {tile}, {tag}, "
                                 "per row", per_row[None]))
                    pairs = np.array(per_row[1]) / np.array(per_row[None])
                    extra["cli_scaling_runs"] = list(map(float, pairs))
                    extra["process_start_s"] = {"jobs_1": start_rows[1], "default_jobs": start_rows[None]}
                    print(f"   throughput scaling, default jobs over --jobs 1 (Table II): "
                          f"{np.median(per_row[1]) / np.median(per_row[None]):.2f}x (whole command, process start "
                          f"subtracted; run by run {', '.join(f'{x:.2f}' for x in pairs)})")
                    print(f"   process start (one-row file, Table II robot), subtracted: {start_rows[1]:.2f} s "
                          f"(--jobs 1), {start_rows[None]:.2f} s (default jobs)")
            # The command's standard-model work on these rows is a fraction of a second behind
            # ~2 s of process start, so its scaling is also measured on the work itself: the same
            # call that `evaluate --jobs N` makes (solve_standard_batch with the stability screen
            # on N numba threads), on the rows repeated 8 times, threads 1 and 2 alternated.
            RA, RB = np.tile(TA, (8, 1)), np.tile(TB, (8, 1))
            for nt in (1, 2):   # both compiled paths (serial and prange) loaded before timing
                solve_standard_batch(robot, RA[:64], RB[:64], settings, check_stability=True, n_threads=nt)
            per = {1: [], 2: []}
            for _ in range(max(repeat, 3)):
                for nt in (1, 2):
                    _, t = _t(solve_standard_batch, robot, RA, RB, settings, check_stability=True, n_threads=nt)
                    per[nt].append(t / len(RA))
            rows.append((f"in-process batch + screen, 1 thread, {len(RA)} rows, per row", per[1]))
            rows.append((f"in-process batch + screen, 2 threads, {len(RA)} rows, per row", per[2]))
            extra["batch_scaling"] = float(np.median(per[1]) / np.median(per[2]))
            print(f"   throughput scaling of the batch call (Table II), 2 threads over 1: "
                  f"{np.median(per[1]) / np.median(per[2]):.2f}x")
        else:
            print("   (measured trajectory not found: CLI standard-model rows skipped)")
        print(f"   process start (one-row file, for the CLI friction row), subtracted: {start:.2f} s")
    print(f"{'what':<48} {'mean':>9} {'median':>9} {'p90':>9} {'max':>9}   [ms]   {'mean':>7} {'median':>7} "
          f"{'p90':>7} {'max':>7}   [x single standard solve]")
    for name, ts in rows:
        m = _stats(np.asarray(ts) * 1e3)
        r = _stats(np.asarray(ts) / unit)
        print(f"{name:<48} " + " ".join(f"{v:>9.3f}" for v in m) + "          "
              + " ".join(f"{v:>7.1f}" for v in r))
    t8 = np.asarray(b8)
    print(f"   8x8x8: slowest / median = {t8.max() / np.median(t8):.1f}")
    print(f"   load average at the end of section 4: {os.getloadavg()}")
    return {"repeat": repeat, "tile": tile, "single_standard_s": list(map(float, single)),
            "rows": {name: list(map(float, ts)) for name, ts in rows}, **extra}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ds", type=float, default=3e-3)
    ap.add_argument("--ref-every", type=int, default=4, help="run the slow reference on every k-th configuration")
    ap.add_argument("--conv-configs", type=int, default=8)
    ap.add_argument("--skip-convergence", action="store_true")
    ap.add_argument("--ratios-only", action="store_true", help="run section 4 only")
    ap.add_argument("--repeat", type=int, default=3, help="command-line runs per measurement (section 4)")
    ap.add_argument("--tile", type=int, default=32,
                    help="times the trajectory's rows are repeated in the command-line standard-model runs")
    ap.add_argument("--results", type=Path, default=None,
                    help="write the times [s] of sections 1, 2 and 4 with the run's conditions to this JSON file")
    args = ap.parse_args(argv)
    load0 = os.getloadavg()
    print(f"load average (1, 5, 15 min) at start: {load0}, cores: {os.cpu_count()}")
    results = {"command": "OPENBLAS_NUM_THREADS=1 python benchmarks/bench_speed.py " + " ".join(sys.argv[1:] if argv is None else argv),
               "mechanics_version": MECHANICS_VERSION, "commit": _commit(),
               "date": datetime.date.today().isoformat(), "cores": os.cpu_count(), "cpu": _cpu(),
               "python": platform.python_version(), "openblas_threads": os.environ.get("OPENBLAS_NUM_THREADS"),
               "load_average_start": list(load0)}
    if not args.ratios_only:
        robot = load_robot(ROOT / "model" / "ha2019-table2-nominal.toml")
        settings = ModelSettings(ds=args.ds)
        results["per_configuration"] = timing_table(robot, settings, args.ref_every)
        results["batch_throughput"] = batch_throughput(robot, settings)
        if not args.skip_convergence:
            convergence_table(robot, args.conv_configs)
    results["ratios"] = ratio_table(args.repeat, args.tile)
    results["load_average_end"] = list(os.getloadavg())
    print(f"\nload average at end: {results['load_average_end']}")
    if args.results:
        args.results.parent.mkdir(parents=True, exist_ok=True)
        args.results.write_text(json.dumps(results, indent=1) + "\n")
        print(f"wrote {args.results}")


def _commit() -> str | None:
    """The checked-out commit, with ``+`` when the tree has changes (None outside git)."""
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True,
                              check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=ROOT,
                               capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None
    return head + ("+" if dirty else "")


def _cpu() -> str:
    """The processor's model name (Linux), else the platform's."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


if __name__ == "__main__":
    main()
