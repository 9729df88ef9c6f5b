"""Bound-map cost: per-chunk times of a real map and the wall time projected for N workers.

Computes (or resumes, or just reads) a bound map in a zarr store with ``n_jobs`` local workers,
reads the evaluation time the store recorded for every chunk, and projects the wall time of the
same map, and of a larger target map, on a Dask cluster of N single-threaded workers:

- chunk cost: the CPU time of the thread that evaluated the chunk (``--cost cpu``, default), which
  is what the chunk takes on a worker with a core of its own, or its wall time (``--cost wall``),
  which on this shared machine includes waiting for a core;
- per-node cost: total cost of the warm chunks / their nodes (a chunk is *cold* when it was the
  first of its worker process: its time includes imports and numba warm-up, counted once per
  worker as ``warm-up``);
- schedule: chunks in submission order, each to the worker that frees first (what the Dask
  scheduler does with equal-priority tasks), plus the warm-up on every worker;
- client: this process writes every finished chunk to the store, so the wall time is at least
  ``n_chunks x write time`` (measured here on a scratch store);
- cluster start-up (``LocalCluster`` here, measured) is listed apart: a running remote cluster
  has none.

The target map's chunk times are drawn (seeded) from the measured per-node rates of the warm
chunks, times the target chunk's node count. Timings on a shared 2-core machine are noisy.

Usage::

    python benchmarks/bench_boundmap.py                       # six-joint robot, 4-D map 4x4x2x3, 2 workers
    python benchmarks/bench_boundmap.py --store out/boundmaps/six-joint-4x4x2x3.zarr   # reuse a run
    python benchmarks/bench_boundmap.py --robot model/ha2019-table2-nominal.toml --resolution 4,4,3 \\
        --target-resolution 24,24,8
"""

from __future__ import annotations

import argparse
import heapq
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
WORKERS = (1, 2, 8, 32, 128)


def schedule(times, n_workers, warmup_s, overhead_s=0.0) -> float:
    """Makespan [s] of ``times`` (in order) on ``n_workers`` greedy workers, each starting after
    ``warmup_s``; every task also costs ``overhead_s``."""
    heap = [float(warmup_s)] * min(n_workers, max(1, len(times)))
    heapq.heapify(heap)
    for t in times:
        heapq.heappush(heap, heapq.heappop(heap) + float(t) + overhead_s)
    return max(heap)


def measure_write_seconds(store, n=20) -> float:
    """Mean time [s] for the client to write one chunk like the store's into a scratch store."""
    from ctrplan.boundmap import BoundMapStore, MapIdentity

    with tempfile.TemporaryDirectory(prefix="ctrplan-bench-") as tmp:
        ident = MapIdentity(key="0" * 64, robot_sha256="0" * 64, robot_hash_of="robot file",
                            spec={"resolution": list(store.resolution), "placement": "uniform"}, settings={},
                            evaluator="bench", mechanics_version="bench",
                            joint_names=tuple(store.attrs["joint_names"]),
                            coordinate_names=tuple(store.coordinates.names))
        scratch = BoundMapStore.create_or_resume(Path(tmp) / "w.zarr", ident, store.axes, store.periodic, store.chunks,
                                                 store.coordinates)
        m = int(np.prod(store.chunks))
        vals, valid = np.random.default_rng(0).random((m, 4)), np.ones(m, dtype=bool)
        n = min(n, scratch.n_chunks)
        t0 = time.perf_counter()
        for c in range(n):
            if scratch.chunk_sizes()[c] == m:
                scratch.write_chunk(c, vals, valid, 1.0, False, 1)
        return (time.perf_counter() - t0) / n


def measure_cluster_startup(n_workers) -> float:
    """Wall time [s] to start and stop a LocalCluster of ``n_workers`` processes."""
    from distributed import Client

    from ctrplan.boundmap import start_local_cluster

    t0 = time.perf_counter()
    with start_local_cluster(n_workers) as lc:
        with Client(lc) as c:
            c.wait_for_workers(n_workers)
            t = time.perf_counter() - t0
    return t


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--robot", default=str(REPO / "model" / "ha2019-table2-six-joint.toml"))
    ap.add_argument("--resolution", default="4,4,2,3",
                    help="nodes per map coordinate (six-joint robot: alpha_2-alpha_1, alpha_3-alpha_1, "
                         "beta_2-beta_1, beta_3-beta_1)")
    ap.add_argument("--ds", type=float, default=3e-3, help="arc-length step [m]")
    ap.add_argument("--chunk-size", type=int, default=8, help="nodes per chunk of a new store")
    ap.add_argument("--jobs", type=int, default=2, help="local workers for computing")
    ap.add_argument("--scheduler", default=None, help="dask scheduler address instead of local workers")
    ap.add_argument("--store", default=None, help="zarr store (default out/bench/<robot>-<res>.zarr)")
    ap.add_argument("--target-resolution", default="16,16,5,14",
                    help="larger map to project (same map coordinates)")
    ap.add_argument("--target-chunk-size", type=int, default=64)
    ap.add_argument("--workers", default=",".join(map(str, WORKERS)))
    ap.add_argument("--cost", choices=("cpu", "wall"), default="cpu",
                    help="chunk cost used in the projection: thread CPU time or wall time")
    ap.add_argument("--overhead-ms", type=float, default=1.0,
                    help="scheduler cost per chunk [ms] added in the projection")
    args = ap.parse_args(argv)

    from ctrplan.boundmap import DEFAULT_CHUNK_SIZE, ComputeOptions, chunk_shape_for, compute_bound_map
    from ctrplan.mechanics import ModelSettings

    res = tuple(int(x) for x in args.resolution.split(","))
    target = tuple(int(x) for x in args.target_resolution.split(","))
    workers = [int(x) for x in args.workers.split(",")]
    robot_path = Path(args.robot)
    store = Path(args.store) if args.store else \
        REPO / "out" / "bench" / f"{robot_path.stem}-{'x'.join(map(str, res))}.zarr"
    store.parent.mkdir(parents=True, exist_ok=True)
    print(f"robot {robot_path.name}, resolution {res} ({int(np.prod(res))} nodes), ds {args.ds * 1e3:g} mm, "
          f"store {store}")
    options = ComputeOptions(n_jobs=args.jobs, scheduler=args.scheduler,
                             chunk_size=args.chunk_size or DEFAULT_CHUNK_SIZE, progress=True)
    run, _ = compute_bound_map(robot_path, res, ModelSettings(ds=args.ds), out_path=store, options=options)
    st = run.store
    print(f"this invocation: {run.executor}, {run.n_computed} chunks computed, {run.n_reused} reused, "
          f"wall {run.wall_seconds:.1f} [s]")
    for k, r in enumerate(st.runs(), start=1):
        if "wall_seconds" in r:
            print(f"  store run {k}: {r.get('executor')}, {r.get('chunks_computed')} chunks, "
                  f"wall {r['wall_seconds']:.1f} [s] (started {r.get('started_utc')})")
    wall, cpu, cold, sizes = st.chunk_seconds(), st.chunk_cpu_seconds(), st.chunk_cold(), st.chunk_sizes()
    secs = cpu if args.cost == "cpu" else wall
    warm = ~cold
    if not warm.any():
        print("no warm chunk recorded: use a map with more chunks than workers", file=sys.stderr)
        return 1
    per_node = secs[warm].sum() / sizes[warm].sum()
    rates = secs[warm] / sizes[warm]
    warmup = float(np.mean(secs[cold] - sizes[cold] * per_node)) if cold.any() else 0.0
    print(f"chunks: {st.n_chunks} of {tuple(st.chunks)} nodes")
    for label, x in (("wall", wall), ("cpu", cpu)):
        print(f"  chunk {label:>4} time [s]: mean {x.mean():.2f}, median {np.median(x):.2f}, "
              f"p95 {np.percentile(x, 95):.2f}, max {x.max():.2f}, sum {x.sum():.1f}")
    print(f"  cpu / wall of the chunks: {cpu.sum() / wall.sum():.2f} (1.0 = a core of its own)")
    print(f"per node ({args.cost}): {per_node:.3f} [s] (warm chunks; chunk rates {rates.min():.3f}-{rates.max():.3f} "
          f"[s/node]); warm-up per worker process {max(warmup, 0.0):.2f} [s] ({int(cold.sum())} cold chunks)")
    write_s = measure_write_seconds(st)
    startup = measure_cluster_startup(min(2, os.cpu_count() or 1)) if args.scheduler is None else 0.0
    print(f"client write per chunk: {write_s * 1e3:.1f} [ms]; LocalCluster start-up (2 workers): {startup:.1f} [s]")

    times = np.where(cold, sizes * per_node, secs)  # cold chunks at the warm rate; warm-up added per worker
    n_target = int(np.prod(target))
    tchunks = chunk_shape_for(target, args.target_chunk_size)
    t_nchunks = int(np.prod([-(-n // c) for n, c in zip(target, tchunks)]))
    rng = np.random.default_rng(0)
    t_times = rng.choice(rates, size=t_nchunks) * int(np.prod(tchunks))
    overhead = args.overhead_ms * 1e-3
    print()
    print(f"projected wall time, {st.n_chunks} chunks of this map and {t_nchunks} chunks "
          f"({tuple(tchunks)}) of the target map {target} ({n_target} nodes):")
    print(f"{'workers':>8} | {'this map [s]':>12} | {'speed-up':>8} | {'target map [h]':>14} | {'efficiency':>10}")
    serial_target = t_times.sum() + warmup
    for n in workers:
        w = max(schedule(times, n, max(warmup, 0.0), overhead), st.n_chunks * write_s)
        wt = max(schedule(t_times, n, max(warmup, 0.0), overhead), t_nchunks * write_s)
        w1 = max(schedule(times, 1, max(warmup, 0.0), overhead), st.n_chunks * write_s)
        print(f"{n:>8} | {w:>12.1f} | {w1 / w:>8.2f} | {wt / 3600:>14.2f} | {serial_target / (n * wt):>10.2f}")
    if run.n_computed == st.n_chunks and args.scheduler is None:
        model = schedule(times, args.jobs, max(warmup, 0.0), overhead) + startup
        print(f"\ncheck: this invocation computed the whole map on {args.jobs} local workers in "
              f"{run.wall_seconds:.1f} [s]; the model gives {model:.1f} [s] with start-up")
    return 0


if __name__ == "__main__":
    sys.exit(main())
