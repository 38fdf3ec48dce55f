"""Throughput of ``arapkit batch``: jobs per minute with 1 and 2 local workers.

Writes ``--augment``-style jobs (random handle placements and moves, reproducible by seed)
for real meshes of ``../shared/data/meshes`` and runs them with ``arapkit batch --workers N
--no-resume`` as a subprocess, timing the whole command (cluster start, worker imports and
the jobs) and, from the summary, the summed job seconds. Rounds alternate between the
worker counts so that load from other processes on a shared machine hits both alike; the
table shows the median round.

Three job sets: ``start-up`` (one 1,197-vertex job: the fixed cost of starting the
cluster and importing arapkit in its workers), ``small`` (5 meshes of 1,197-4,930 vertices,
4 jobs each) and ``large`` (bunny00 and refined_elephant, 37,706 and 44,460 vertices, 3 jobs
each). Jobs use ``cotan-clamped`` weights (plain cotangent weights make some of the random
set-ups indefinite on hand and homer).

Usage::

    python benchmarks/bench_batch.py                 # every set, 2 rounds (about 10 minutes)
    python benchmarks/bench_batch.py --sets small --rounds 1
"""

from __future__ import annotations

import argparse
import csv
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from arapkit.workflows.batch import augment_jobs, write_jobs

ROOT = Path(__file__).resolve().parents[1]
MESHES = ROOT.parent / "shared" / "data" / "meshes"
SETS = {
    "start-up": (["hand.off"], 1),
    "small": (["hand.off", "elephant.off", "cow.off", "knot1.off", "homer.off"], 4),
    "large": (["bunny00.off", "refined_elephant.off"], 3),
}


def one_run(jobs: Path, out: Path, workers: int) -> dict:
    """Run the batch command once; wall time and summed job seconds."""
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src")}
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "arapkit.cli", "batch", str(jobs), "-o",
                           str(out), "--workers", str(workers), "--no-resume", "-q"],
                          capture_output=True, text=True, env=env, timeout=3600)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"batch failed ({proc.returncode}): {proc.stderr}")
    with open(out / "summary.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    return {"wall": wall, "jobs": len(rows), "job_s": sum(float(r["seconds"]) for r in rows),
            "workers_seen": len({r["worker"] for r in rows})}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sets", nargs="+", default=list(SETS), choices=list(SETS))
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--weights", default="cotan-clamped")
    args = ap.parse_args()
    table = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for name in args.sets:
            meshes, per_mesh = SETS[name]
            paths = [MESHES / m for m in meshes]
            missing = [p for p in paths if not p.exists()]
            if missing:
                raise SystemExit(f"{missing[0]} not found: this benchmark needs "
                                 "../shared/data/meshes")
            jobs = tmp / f"{name}.jsonl"
            write_jobs(jobs, [{**j, "weights": args.weights}
                              for j in augment_jobs(paths, per_mesh, args.seed)])
            runs: dict[int, list[dict]] = {w: [] for w in args.workers}
            for r in range(args.rounds):
                for w in args.workers:
                    res = one_run(jobs, tmp / f"out-{name}-{w}", w)
                    runs[w].append(res)
                    print(f"{name} round {r}: {w} worker(s): {res['jobs']} jobs in "
                          f"{res['wall']:.1f} s ({60 * res['jobs'] / res['wall']:.1f} jobs/min;"
                          f" summed job time {res['job_s']:.1f} s; {res['workers_seen']} "
                          f"worker(s) used; load {os.getloadavg()[0]:.2f})", flush=True)
            base = None
            for w in args.workers:
                med = statistics.median(x["wall"] for x in runs[w])
                job_s = statistics.median(x["job_s"] for x in runs[w])
                n = runs[w][0]["jobs"]
                base = base or med
                table.append(f"| {name} | {w} | {n} | {med:.1f} | {60 * n / med:.1f} | "
                             f"{job_s:.1f} | {base / med:.2f}x |")
    print(f"\n{os.cpu_count()} cores; load average at the end: {os.getloadavg()[0]:.2f}")
    print("| set | workers | jobs | wall s (median) | jobs/min | summed job s | speed-up |")
    print("|---|---|---|---|---|---|---|")
    print("\n".join(table))


if __name__ == "__main__":
    main()
