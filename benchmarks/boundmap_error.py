"""Where a shipped bound map's interpolation error comes from.

For a shipped map (default: the six-joint robot's), draws ``--n`` configurations uniformly from the
joint box (seeded), keeps those valid in the exact model and not refused by the map, and prints:

1. the friction bound's error of the map as shipped (multilinear), of periodic cubic-spline
   interpolation along the rotation coordinates (``scipy.ndimage.map_coordinates``, order 3,
   linear along the translations) on the same nodes, and of both on every other rotation node
   (half the rotation resolution): median, p95 and max [mm];
2. for the ``--worst`` configurations with the largest error, the exact bound there and, per map
   coordinate, the local node spacing and the error that linear interpolation across one such
   cell centred on the configuration makes there, (b(u - h) + b(u + h)) / 2 - b(u) with h half
   the spacing, from exact bounds (``x``: u - h or u + h is outside the joint box or not valid in
   the exact model).

Part 2 tells which coordinate's spacing the largest errors come from: a coordinate whose cell
error is as large as the map's error at that configuration needs more nodes (or the bound has a
kink or an edge of validity there, which no interpolation order follows).

Run:  OPENBLAS_NUM_THREADS=1 python benchmarks/boundmap_error.py [--n 260] [--worst 6] [--seed 0]
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402
from scipy.ndimage import map_coordinates  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def _rotation_cubic(field, U, values, step, order):
    """Bound at map coordinates U (m, d) from ``values`` (the map's node values of one quantity,
    invalid nodes filled), with every ``step``-th rotation node, interpolated with spline
    ``order`` along the (periodic, uniform) rotation coordinates and linearly along the others."""
    rot = np.flatnonzero(field.periodic)
    lin = np.flatnonzero(~field.periodic)
    if rot.size != 2 or lin.size != 2:
        raise ValueError("needs two periodic rotation and two translation coordinates")
    V = values[::step, ::step]
    n_rot = V.shape[0]
    h = 2.0 * np.pi / n_rot
    out = np.empty(len(U))
    for i, u in enumerate(U):
        cell, weight = [], []
        for k in lin:
            a = field.axes[k]
            x = float(np.clip(u[k], a[0], a[-1]))
            j = min(int(np.searchsorted(a, x, side="right")) - 1, a.size - 2)
            cell.append(j)
            weight.append((x - a[j]) / (a[j + 1] - a[j]))
        r = [((u[k] - field.axes[k][0]) / h) % n_rot for k in rot]
        total = 0.0
        for dj in (0, 1):
            for dk in (0, 1):
                w = (weight[0] if dj else 1.0 - weight[0]) * (weight[1] if dk else 1.0 - weight[1])
                plane = V[:, :, cell[0] + dj, cell[1] + dk]
                total += w * map_coordinates(plane, [[r[0]], [r[1]]], order=order, mode="grid-wrap")[0]
        out[i] = total
    return out


def _stats(e):
    return f"median {np.median(e):6.3f}  p95 {np.percentile(e, 95):6.3f}  max {e.max():6.3f}"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robot", default=str(ROOT / "model" / "ha2019-table2-six-joint.toml"))
    ap.add_argument("--map", default=str(ROOT / "model" / "boundmaps" / "ha2019-table2-six-joint-a5557fdc6849.npz"))
    ap.add_argument("--n", type=int, default=260, help="configurations drawn")
    ap.add_argument("--worst", type=int, default=6, help="largest errors analysed in part 2")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    from ctrplan.boundmap import BoundField
    from ctrplan.boundmap.accuracy import sample_exact
    from ctrplan.boundmap.field import QUANTITIES
    from ctrplan.io.robot_file import load_robot
    from ctrplan.mechanics import evaluate_bound

    print(f"load average at the start: {os.getloadavg()}")
    robot = load_robot(args.robot)
    field = BoundField.load(args.map)
    col = QUANTITIES.index("position")
    rng = np.random.default_rng(args.seed)
    lo, hi = robot.joint_lower, robot.joint_upper
    qs = lo + rng.random((args.n, lo.size)) * (hi - lo)
    t0 = time.perf_counter()
    exact, ok = sample_exact(robot, evaluate_bound, qs, None, 1)
    print(f"{args.n} configurations drawn (seed {args.seed}), {int(ok.sum())} valid in the exact model "
          f"({time.perf_counter() - t0:.0f} s)")
    keep = ok & field.is_valid(qs)
    qs, b = qs[keep], exact[keep, col]
    U = field.to_map(qs)
    values = np.where(field.valid, field.values[..., col], np.nan)
    values = np.where(np.isnan(values), np.nanmean(values), values)   # spline input only
    print(f"\n1. friction bound, map minus exact at {keep.sum()} configurations not refused by the map [mm] "
          f"({Path(args.map).name}, {' x '.join(map(str, field.shape))} nodes):")
    err_map = np.abs(field(qs) - b) * 1e3
    print(f"   as shipped (multilinear)                 {_stats(err_map)}")
    n_rot = field.shape[int(np.flatnonzero(field.periodic)[0])]
    for step in (1, 2):
        for order, name in ((1, "linear"), (3, "cubic spline")):
            if step == 1 and order == 1:
                continue
            e = np.abs(_rotation_cubic(field, U, values, step, order) - b) * 1e3
            label = f"{n_rot // step} rotation nodes, {name}"
            print(f"   {label:40s} {_stats(e)}")
    print(f"\n2. the {args.worst} largest errors: error of linear interpolation across one local cell of "
          f"each map coordinate, from exact bounds [mm]:")
    names = field.coordinate_names
    matrix = field.coordinates.matrix
    joint_of = []
    for k in range(len(names)):   # a joint that moves map coordinate k alone
        j = next(j for j in range(matrix.shape[1])
                 if matrix[k, j] != 0.0 and np.count_nonzero(matrix[:, j]) == 1)
        joint_of.append((j, 1.0 / matrix[k, j]))
    for i in np.argsort(err_map)[::-1][:args.worst]:
        parts = []
        for k, (j, scale) in enumerate(joint_of):
            a = field.axes[k]
            if field.periodic[k]:
                h = 0.5 * (a[1] - a[0])
            else:
                x = float(np.clip(U[i, k], a[0], a[-1]))
                c = min(int(np.searchsorted(a, x, side="right")) - 1, a.size - 2)
                h = 0.5 * (a[c + 1] - a[c])
            side = []
            for sgn in (-1.0, 1.0):
                q = qs[i].copy()
                q[j] += sgn * h * scale
                if np.isclose(hi[j] - lo[j], 2.0 * np.pi):   # a full turn: wrap
                    q[j] = lo[j] + (q[j] - lo[j]) % (2.0 * np.pi)
                if not (lo[j] <= q[j] <= hi[j]):   # outside the joint box
                    side.append(np.nan)
                    continue
                v, g = sample_exact(robot, evaluate_bound, q[None, :], None, 1)
                side.append(v[0, col] if g[0] else np.nan)
            unit = "deg" if field.periodic[k] else "mm"
            spacing = np.degrees(2 * h) if field.periodic[k] else 2e3 * h
            cell = "x" if np.any(np.isnan(side)) else f"{abs(0.5 * (side[0] + side[1]) - b[i]) * 1e3:.2f}"
            parts.append(f"{names[k]} ({spacing:.1f} {unit}): {cell}")
        print(f"   map error {err_map[i]:.2f} mm, exact {b[i] * 1e3:.2f} mm; " + "; ".join(parts))
    print(f"\nload average at the end: {os.getloadavg()}")


if __name__ == "__main__":
    main()
