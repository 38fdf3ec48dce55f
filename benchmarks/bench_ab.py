"""Per-iteration time of two arapkit source trees, interleaved (A/B on a shared machine).

Default: each round runs a fresh process per tree (each compiles and caches its own
kernels) that solves the bunny drag of ``bench_arap.py`` at r = 1 and r = 3 for 20
iterations, several times, and reports its fastest repeat. Rounds alternate A, B, A, B ...;
the summary is the minimum over rounds.

``--same-process``: tree A's package is copied as ``arapkit_a`` and both deformers run in
one process, alternating 20-iteration blocks, so that load from other processes hits both
within a fraction of a second (much steadier on a busy machine). Both must produce the same
iterates; min and median over blocks are printed.

Usage::

    git archive <commit> src | tar -x -C /tmp/base
    python benchmarks/bench_ab.py /tmp/base/src src --rounds 6
    python benchmarks/bench_ab.py /tmp/base/src src --same-process --blocks 30
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def child(repeats: int) -> None:
    """Runs inside one tree: the fastest of ``repeats`` 20-iteration solves per r, in ms/it."""
    sys.path.insert(0, str(HERE))
    from bench_arap import DATA, drag_problem

    import arapkit
    from arapkit import Deformer, load_mesh

    m = load_mesh(DATA / "bunny00.off")
    h, T = drag_problem(m)
    out = {"src": str(Path(arapkit.__file__).parent)}
    for r in (1, 3):
        d = Deformer(m, h, rings=r, weights="cotan")
        d.solve(T, max_iter=2, tol=0)  # factorise and compile outside the timing
        best = float("inf")
        for _ in range(repeats):
            t0 = time.perf_counter()
            d.solve(T, max_iter=20, tol=0)
            best = min(best, (time.perf_counter() - t0) / 20)
        out[f"r{r}"] = 1e3 * best
    print(json.dumps(out))


def same_process(a: str, b: str, blocks: int) -> None:
    """Both trees in one process (A imported as ``arapkit_a``), alternating blocks."""
    import shutil
    import tempfile

    import numpy as np

    tmp = Path(tempfile.mkdtemp())
    shutil.copytree(Path(a) / "arapkit", tmp / "arapkit_a")
    sys.path.insert(0, str(Path(b).resolve()))
    sys.path.insert(0, str(tmp))
    sys.path.insert(0, str(HERE))
    try:  # tree A in the layered layout, or older (flat modules)
        from arapkit_a.methods.deformer import Deformer as DeformerA
    except ImportError:
        from arapkit_a.solver import Deformer as DeformerA
    from bench_arap import DATA, drag_problem

    from arapkit import Deformer, load_mesh

    m = load_mesh(DATA / "bunny00.off")
    h, T = drag_problem(m)
    print("| r | A min | B min | A median | B median | B / A (min) | B / A (median) |")
    print("|---|---|---|---|---|---|---|")
    for r in (1, 3):
        ds = {"A": DeformerA(m, h, rings=r, weights="cotan"),
              "B": Deformer(m, h, rings=r, weights="cotan")}
        res = {k: d.solve(T, max_iter=20, tol=0) for k, d in ds.items()}  # compile, factorise
        drift = np.abs(res["A"].vertices - res["B"].vertices).max()
        assert drift < 1e-9 * m.bounding_box_diagonal, f"the trees disagree by {drift}"
        t: dict[str, list[float]] = {"A": [], "B": []}
        for i in range(blocks):
            for k in ("A", "B") if i % 2 == 0 else ("B", "A"):
                t0 = time.perf_counter()
                ds[k].solve(T, max_iter=20, tol=0)
                t[k].append(1e3 * (time.perf_counter() - t0) / 20)
        mn = {k: min(v) for k, v in t.items()}
        md = {k: float(np.median(v)) for k, v in t.items()}
        print(f"| {r} | {mn['A']:.2f} | {mn['B']:.2f} | {md['A']:.2f} | {md['B']:.2f} | "
              f"{mn['B'] / mn['A']:.3f} | {md['B'] / md['A']:.3f} |", flush=True)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("a", nargs="?", help="source folder A (holds the arapkit package)")
    ap.add_argument("b", nargs="?", help="source folder B")
    ap.add_argument("--rounds", type=int, default=6)
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--same-process", action="store_true",
                    help="both trees in one process, alternating blocks")
    ap.add_argument("--blocks", type=int, default=30, help="blocks per tree (--same-process)")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.child:
        child(a.repeats)
        return
    if a.same_process:
        same_process(a.a, a.b, a.blocks)
        return
    runs: dict[str, list[dict]] = {a.a: [], a.b: []}
    for i in range(a.rounds):
        for src in (a.a, a.b) if i % 2 == 0 else (a.b, a.a):
            proc = subprocess.run([sys.executable, __file__, "--child", "--repeats",
                                   str(a.repeats)], capture_output=True, text=True, check=True,
                                  env={**os.environ, "PYTHONPATH": str(Path(src).resolve())})
            runs[src].append(json.loads(proc.stdout.strip().splitlines()[-1]))
            print(src, runs[src][-1], flush=True)
    print("\n| tree | r = 1 ms/it (min) | r = 3 ms/it (min) | rounds |")
    print("|---|---|---|---|")
    for src, rs in runs.items():
        print(f"| {src} | {min(r['r1'] for r in rs):.2f} | {min(r['r3'] for r in rs):.2f} "
              f"| {len(rs)} |")
    b1 = min(r["r1"] for r in runs[a.b]) / min(r["r1"] for r in runs[a.a])
    b3 = min(r["r3"] for r in runs[a.b]) / min(r["r3"] for r in runs[a.a])
    print(f"\nB / A: r = 1 {b1:.3f}, r = 3 {b3:.3f}")


if __name__ == "__main__":
    main()
