"""The shipped robot files of Ha et al.'s robot against its measured trajectory: standard model,
history-aware prediction, friction bound and a calibrated bound, and which parameters make the
Table VII file fit the trajectory worse than the Table II one.

    python benchmarks/ha_robot_files.py [--data ../shared/data/ha-three-tube-trajectory/jointTipTrajectory_measured.txt]
                                        [--ds 3e-3] [--jobs 2]
                                        [--results benchmarks/results/ha-robot-files.json]

For each robot file (``model/ha2019-table2-nominal.toml``, ``model/ha2019-table7-calibrated.toml``,
with their own friction coefficients): the standard model along the recorded motion (each sample
solved from the previous one), registered to the tracker by a rigid (Kabsch) fit on the first 300
rows; the history-aware prediction (the friction model along the recorded history, the same
registration); the friction bound of every row (:func:`ctrplan.mechanics.evaluate_bound`). Errors
are reported on the other 1007 rows: mean / p95 / max of the standard model and of the prediction,
the bound's mean / max, the share of rows with error <= bound + 0.6 mm (the margin of the
original comparison), and a split-conformal calibrated bound (target 90 %, noise margin 1.62 x
the noise rms from the rests of the first 300 rows) calibrated on the first 300 rows and checked on
the rest. The results file records the digest of the code that made it
(:mod:`ctrplan.discrepancy.provenance`).
Then, one parameter (or group) at a time, the Table VII value put into the Table II file and the
Table II value into the Table VII file (standard model only): which differences cause the gap.

The data has no licence and is not in the repository: get it from github.com/hjhdog1/ConcentricTubes.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "ha-three-tube-trajectory" / "jointTipTrajectory_measured.txt"
FILES = ("ha2019-table2-nominal.toml", "ha2019-table7-calibrated.toml")
REGISTRATION_ROWS = 300
ORIGINAL_MARGIN = 0.6e-3
SWAPS = (("precurvature_y_1",), ("precurvature_y_2",), ("precurvature_y_3",), ("precurvature_x_2",),
         ("precurvature_x_3",), ("k_xy_relative_3",), ("poisson_ratio_3",), ("precurvature_y_2", "precurvature_y_3"),
         ("precurvature_y_2", "precurvature_y_3", "k_xy_relative_3"))


def _stats(e) -> dict:
    import numpy as np

    e = e[np.isfinite(e)] * 1e3
    return {"mean_mm": float(e.mean()), "p95_mm": float(np.percentile(e, 95)), "max_mm": float(e.max()), "n": int(e.size)}


def _registered_errors(data, tip_base, rows):
    """Errors [m] at ``rows`` after a Kabsch registration of ``tip_base`` on the first rows."""
    import numpy as np
    from scipy.spatial.transform import Rotation

    from ctrplan.discrepancy.fits.predictions import kabsch_registration

    rv, t = kabsch_registration(tip_base[:REGISTRATION_ROWS], data.tip[:REGISTRATION_ROWS])
    tip = Rotation.from_rotvec(rv).apply(tip_base) + t
    return np.linalg.norm(tip - data.tip, axis=1)[rows], (rv, t)


def evaluate_file(path: Path, data_path: Path, ds: float, n_jobs: int) -> dict:
    import numpy as np

    from ctrplan.discrepancy.fits.predictions import predict
    from ctrplan.discrepancy.verdict.coverage import NOISE_MULTIPLE, BoundSamples, bound_values, calibrate_bound
    from ctrplan.discrepancy.measured.data import load_measured_data
    from ctrplan.discrepancy.measured.noise import estimate_noise
    from ctrplan.discrepancy.outputs.words import noise_text
    from ctrplan.io.robot_file import load_robot
    from ctrplan.mechanics import ModelSettings

    robot = load_robot(path)
    data = load_measured_data(data_path, robot)
    settings = ModelSettings(ds=ds, multistart=0)
    k = data.n_samples
    rest = np.arange(REGISTRATION_ROWS, k)
    t0 = time.perf_counter()
    std = predict(robot, (), (), data, "standard", settings, n_jobs=n_jobs)
    e_std_all, reg = _registered_errors(data, std.tip_base, np.arange(k))
    hist = predict(robot, (), (), data, "friction", settings, n_jobs=n_jobs)
    from scipy.spatial.transform import Rotation

    e_hist = np.linalg.norm(Rotation.from_rotvec(reg[0]).apply(hist.tip_base) + reg[1] - data.tip, axis=1)[rest]
    bounds = bound_values(robot, data.alpha, data.beta, settings, n_jobs=n_jobs)
    b = np.where(bounds.ok, bounds.position, np.nan)
    e_std = e_std_all[rest]
    calibration = np.zeros(k, bool)
    calibration[:REGISTRATION_ROWS] = True
    noise = estimate_noise(data, rows=calibration)
    units = np.arange(k) // 50
    cal = calibrate_bound(BoundSamples(e_std_all[:REGISTRATION_ROWS], b[:REGISTRATION_ROWS]),
                          BoundSamples(e_std, b[rest], units[rest]), noise_rms=noise.position_rms_m or 0.0)
    ok = np.isfinite(e_std) & np.isfinite(b[rest])
    return {"robot_file": f"model/{path.name}", "friction_coefficients": list(robot.friction_coefficients),
            "rows_registered": REGISTRATION_ROWS, "rows_evaluated": int(rest.size),
            "standard": _stats(e_std), "prediction": _stats(e_hist),
            "bound_mean_mm": float(np.nanmean(b[rest]) * 1e3), "bound_max_mm": float(np.nanmax(b[rest]) * 1e3),
            "bound_failed": int(np.sum(~bounds.ok[rest])),
            "within_bound_plus_0_6_mm": float(np.mean(e_std[ok] <= b[rest][ok] + ORIGINAL_MARGIN)),
            "median_error_over_bound": float(np.median(e_std[ok] / b[rest][ok])),
            "noise": noise_text(noise.as_dict()), "noise_multiple": NOISE_MULTIPLE,
            "calibrated_bound": {"factor": cal.factor, "margin_mm": cal.margin_m * 1e3, "status": cal.status,
                                 "test_coverage": cal.test.covered, "test_coverage_ci": list(cal.test.ci),
                                 "median_size_mm": cal.test.bound_median_m * 1e3,
                                 "raw_coverage": cal.raw_test.covered},
            "seconds": time.perf_counter() - t0}


def swaps(data_path: Path, ds: float) -> list:
    """Standard-model error after putting one file's value(s) into the other."""
    import numpy as np

    from ctrplan.discrepancy.fits.predictions import predict
    from ctrplan.discrepancy.measured.data import load_measured_data
    from ctrplan.discrepancy.fits.parameters import apply_parameters, read_parameters
    from ctrplan.io.robot_file import load_robot
    from ctrplan.mechanics import ModelSettings

    nominal, table7 = (load_robot(ROOT / "model" / f) for f in FILES)
    data = load_measured_data(data_path, nominal)
    settings = ModelSettings(ds=ds, multistart=0)
    rest = np.arange(REGISTRATION_ROWS, data.n_samples)

    def err(robot):
        e, _ = _registered_errors(data, predict(robot, (), (), data, "standard", settings).tip_base, rest)
        return _stats(e)

    out = []
    for group in SWAPS:
        vn, v7 = read_parameters(nominal, group), read_parameters(table7, group)
        out.append({"parameters": list(group), "table2": [float(v) for v in vn], "table7": [float(v) for v in v7],
                    "table2_with_table7_values": err(apply_parameters(nominal, group, tuple(v7))),
                    "table7_with_table2_values": err(apply_parameters(table7, group, tuple(vn)))})
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=str(DATA))
    ap.add_argument("--ds", type=float, default=3e-3)
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--results", default=str(ROOT / "benchmarks" / "results" / "ha-robot-files.json"))
    args = ap.parse_args(argv)
    data = Path(args.data).resolve()
    if not data.exists():
        print(f"no data at {data}: get it from github.com/hjhdog1/ConcentricTubes and pass --data", file=sys.stderr)
        return 2
    from ctrplan.io.robot_file import file_hash

    t0 = time.perf_counter()
    files = [evaluate_file(ROOT / "model" / f, data, args.ds, args.jobs) for f in FILES]
    for r in files:
        c = r["calibrated_bound"]
        print(f"{r['robot_file']}: standard {r['standard']['mean_mm']:.2f} / {r['standard']['p95_mm']:.2f} / "
              f"{r['standard']['max_mm']:.2f} mm; prediction {r['prediction']['mean_mm']:.2f} / "
              f"{r['prediction']['p95_mm']:.2f} / {r['prediction']['max_mm']:.2f} mm; bound mean / max "
              f"{r['bound_mean_mm']:.2f} / {r['bound_max_mm']:.2f} mm; within bound + 0.6 mm "
              f"{100 * r['within_bound_plus_0_6_mm']:.1f} %; calibrated bound {c['factor']:.3g} x (b + "
              f"{c['margin_mm']:.2f} mm) covers {100 * c['test_coverage']:.0f} % (target 90 %, {c['status']})",
              flush=True)
    sw = swaps(data, args.ds)
    for s in sw:
        print(f"  {', '.join(s['parameters'])}: Table II file with Table VII values "
              f"{s['table2_with_table7_values']['mean_mm']:.2f} mm mean; Table VII file with Table II values "
              f"{s['table7_with_table2_values']['mean_mm']:.2f} mm mean")
    out = Path(args.results)
    out.parent.mkdir(parents=True, exist_ok=True)
    from ctrplan.discrepancy.provenance import provenance

    out.write_text(json.dumps({"command": "python benchmarks/ha_robot_files.py", "data_file": data.name,
                               "data_sha256": file_hash(data), "ds_m": args.ds, "files": files, "swaps": sw,
                               "provenance": provenance({"ds": args.ds, "registration_rows": REGISTRATION_ROWS}),
                               "seconds": time.perf_counter() - t0}, indent=1) + "\n")
    print(f"wrote {out} ({time.perf_counter() - t0:.0f} s; load average {os.getloadavg()[0]:.2f})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
