"""Speed of learning per-vertex rigidity (paper sec. 3.4) on a 13,750-vertex human.

Times :func:`arapkit.learn_rings` on ``anny_makehuman_pose_seq.npz`` (9 poses of a
MakeHuman body, 13,750 vertices) for r = 1..6, after a warm-up call that compiles (or
loads from the numba cache) every kernel. Reported per stage (the one BFS to r_max, the
energy kernel) and as milliseconds per vertex per model, the paper's unit: it counts all
M models, reference included (0.68 ms for 12.5K vertices x 71 models, i.e. 10 minutes);
the per-example figure (M - 1 examples, what the kernel actually fits) is given too.

Usage::

    python benchmarks/bench_learn.py                  # anny, r = 1..6, best of 5
    python benchmarks/bench_learn.py --data x.npz --repeat 3 --r-max 4

Target (issue #4): <= 0.01 ms per vertex per model, about a second for the human.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numba
import numpy as np

DEFAULT_DATA = (Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "sequences"
                / "anny_makehuman_pose_seq.npz")
PAPER_MS = 0.68
TARGET_MS = 0.01


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", default=str(DEFAULT_DATA), help=".npz with V (frames x n x 3), F")
    p.add_argument("--repeat", type=int, default=5, help="timed runs (best is reported)")
    p.add_argument("--r-min", type=int, default=1)
    p.add_argument("--r-max", type=int, default=6)
    args = p.parse_args(argv)
    if not os.path.exists(args.data):
        print(f"skipped: {args.data} not found (benchmarks need ../shared/data)")
        return 0

    from arapkit import Mesh, learn_rings

    data = np.load(args.data)
    V, F = data["V"].astype(np.float64), data["F"]
    mesh = Mesh(V[0], F, name=Path(args.data).name)
    n, models = mesh.n_vertices, len(V)
    t = time.perf_counter()
    learn_rings(mesh, V[1:], args.r_min, args.r_max, omega="auto")
    warm = time.perf_counter() - t

    runs = [learn_rings(mesh, V[1:], args.r_min, args.r_max, omega="auto").timings
            for _ in range(args.repeat)]
    best = min(runs, key=lambda r: r["total_s"])
    energy = min(r["energy_s"] for r in runs)
    bfs = min(r["neighbourhood_s"] for r in runs)
    total = best["total_s"]

    print(f"{mesh.name}: {n} vertices, {models} models ({models - 1} examples), "
          f"r = {args.r_min}..{args.r_max}, {numba.get_num_threads()} numba threads")
    print(f"first call (compile or cache load + run): {warm:.2f} s")
    print(f"best of {args.repeat}: total {total * 1e3:.0f} ms = BFS to r_max "
          f"{bfs * 1e3:.0f} ms + energies {energy * 1e3:.0f} ms (+ weights, areas, checks)")
    per_model = total * 1e3 / (n * models)
    per_example = total * 1e3 / (n * (models - 1))
    print(f"ms per vertex per model: {per_model:.5f} (paper {PAPER_MS}, target <= {TARGET_MS}; "
          f"{PAPER_MS / per_model:.0f}x faster than the paper)")
    print(f"ms per vertex per example: {per_example:.5f}; energy kernel alone "
          f"{energy * 1e3 / (n * (models - 1)):.5f}")
    print(f"target met: {per_model <= TARGET_MS}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
