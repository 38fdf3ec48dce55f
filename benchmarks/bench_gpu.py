"""The PyTorch layer (arapkit.torch) on CPU and CUDA: batching and GPU throughput.

Sections (each prints a markdown table):

1. CPU: a batch of 16 target sets on ``bunny00.off`` against one single solve, per
   iteration and to convergence (the target: the batch costs <= 6x one solve);
2. GPU (only where torch sees CUDA): ~1M vertices at r = 1 in float32, iterations/s
   (``homer.off`` subdivided 4 times, 1.26M vertices);
3. GPU: time per iteration at ~150K vertices (``bunny00.off`` subdivided once) against the
   numba CPU backend of this machine;
4. GPU: a batch of 64 poses of a ~10K-vertex mesh (``cow.off`` subdivided once), poses per
   second to convergence at the default tolerance.

Every figure is a median over rounds; GPU times are taken after ``torch.cuda.synchronize``.

Usage::

    python benchmarks/bench_gpu.py             # section 1, and 2-4 when CUDA is visible
    python benchmarks/bench_gpu.py --cpu-only  # section 1 only
    python benchmarks/bench_gpu.py --converge  # section 1 also to convergence
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch
from bench_arap import DATA, drag_problem, subdivided, table

from arapkit import Deformer, load_mesh
from arapkit.torch import ARAPLayer


def timed(fn, rounds: int, device: torch.device) -> float:
    """Median wall time of ``fn()`` in seconds (synchronising CUDA)."""
    ts = []
    for _ in range(rounds):
        if device.type == "cuda":
            torch.cuda.synchronize(device)
        t0 = time.perf_counter()
        fn()
        if device.type == "cuda":
            torch.cuda.synchronize(device)
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts))


def poses(mesh, B: int, seed: int = 0):
    """Handles and B target sets: the drag problem with the moved cap shifted randomly."""
    h, T = drag_problem(mesh)
    rng = np.random.default_rng(seed)
    k = len(h) // 2
    out = np.repeat(T[None], B, axis=0)
    out[:, k:] += 0.1 * mesh.bounding_box_diagonal * rng.standard_normal((B, 1, 3))
    return h, out


def cpu_batch(rounds: int, iters: int, converge: bool) -> list[list]:
    mesh = load_mesh(DATA / "bunny00.off")
    h, T = poses(mesh, 16)
    rows = []
    dev = torch.device("cpu")
    d = Deformer(mesh, h)
    d.solve(T[0], max_iter=1, tol=0)
    numba = timed(lambda: d.solve(T[0], max_iter=iters, tol=0), rounds, dev) / iters
    rows.append(["numba Deformer, float64", mesh.n_vertices, f"{1e3 * numba:.0f}", "", ""])
    for dtype in (torch.float64, torch.float32):
        fixed = ARAPLayer(mesh, h, dtype=dtype, tol=0.0, max_iter=iters)
        one, many = torch.tensor(T[0], dtype=dtype), torch.tensor(T, dtype=dtype)
        fixed(one)  # warm-up
        t1 = timed(lambda m=fixed, x=one: m(x), rounds, dev) / iters
        t16 = timed(lambda m=fixed, x=many: m(x), rounds, dev) / iters
        row = [f"ARAPLayer, {str(dtype).replace('torch.', '')}", mesh.n_vertices, f"{1e3 * t1:.0f}",
               f"{1e3 * t16:.0f}", f"{t16 / t1:.1f}x"]
        if converge:  # to the default tolerance: each pose stops at its own test; "it" is the most
            conv = ARAPLayer(mesh, h, dtype=dtype)
            s1 = timed(lambda m=conv, x=one: m(x), 1, dev)
            it1 = conv.last_info["iterations"]
            s16 = timed(lambda m=conv, x=many: m(x), 1, dev)
            it16 = conv.last_info["iterations"]
            row += [f"{s1:.1f} ({it1} it)", f"{s16:.1f} ({it16} it)", f"{s16 / s1:.1f}x"]
        rows.append(row)
    if converge:
        rows[0] += ["", "", ""]
    return rows


def gpu_big(dev: torch.device, rounds: int, iters: int) -> list[list]:
    mesh = subdivided("homer.off", 4)
    h, T = drag_problem(mesh)
    t0 = time.perf_counter()
    layer = ARAPLayer(mesh, h, weights="cotan-clamped", dtype=torch.float32, device=dev,
                      tol=0.0, max_iter=iters)
    pre = time.perf_counter() - t0
    x = torch.tensor(T, dtype=torch.float32, device=dev)
    layer(x)
    t = timed(lambda: layer(x), rounds, dev) / iters
    return [[mesh.name, mesh.n_vertices, 1, "float32", f"{pre:.1f}", f"{1e3 * t:.1f}",
             f"{1 / t:.0f}"]]


def gpu_vs_cpu(dev: torch.device, rounds: int, iters: int) -> list[list]:
    mesh = subdivided("bunny00.off", 1)
    h, T = drag_problem(mesh)
    d = Deformer(mesh, h, weights="cotan-clamped")
    d.prepare()
    d.solve(T, max_iter=1, tol=0)
    cpu = timed(lambda: d.solve(T, max_iter=iters, tol=0), rounds, torch.device("cpu")) / iters
    rows = [[mesh.n_vertices, "numba CPU, float64", f"{1e3 * cpu:.1f}", "1.0x"]]
    for dtype in (torch.float32, torch.float64):
        layer = ARAPLayer(mesh, h, weights="cotan-clamped", dtype=dtype, device=dev, tol=0.0,
                          max_iter=iters)
        x = torch.tensor(T, dtype=dtype, device=dev)
        layer(x)
        t = timed(lambda m=layer, x=x: m(x), rounds, dev) / iters
        rows.append([mesh.n_vertices, f"ARAPLayer {dev}, {str(dtype)[6:]}", f"{1e3 * t:.2f}",
                     f"{cpu / t:.1f}x"])
    return rows


def gpu_batch(dev: torch.device, rounds: int) -> list[list]:
    mesh = subdivided("cow.off", 1)
    h, T = poses(mesh, 64)
    layer = ARAPLayer(mesh, h, dtype=torch.float32, device=dev)
    x = torch.tensor(T, dtype=torch.float32, device=dev)
    layer(x)
    t = timed(lambda: layer(x), rounds, dev)
    return [[mesh.name, mesh.n_vertices, 64, layer.last_info["iterations"], f"{t:.2f}",
             f"{64 / t:.0f}"]]


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cpu-only", action="store_true", help="section 1 only")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--iters", type=int, default=20, help="iterations per timed solve")
    ap.add_argument("--converge", action="store_true",
                    help="section 1 also to convergence (slow on CPU: minutes)")
    a = ap.parse_args(argv)
    print(f"torch {torch.__version__}, {torch.get_num_threads()} CPU threads, "
          f"CUDA: {torch.cuda.get_device_name(0) if torch.cuda.is_available() else 'none'}")
    head = ["solver", "n", "ms/it, 1 pose", "ms/it, 16 poses", "ratio"]
    if a.converge:
        head += ["s to tol 1e-3, 1 pose", "s, 16 poses", "ratio"]
    table("1. CPU: batch of 16 target sets vs one solve (bunny00.off, r = 1)", head,
          cpu_batch(a.rounds, a.iters, a.converge))
    if a.cpu_only or not torch.cuda.is_available():
        print("\nno CUDA device (or --cpu-only): GPU sections skipped")
        return
    dev = torch.device("cuda")
    table("2. GPU: ~1M vertices at r = 1", ["mesh", "n", "r", "dtype", "setup s", "ms/it",
                                             "it/s"], gpu_big(dev, a.rounds, a.iters))
    table("3. GPU vs the numba CPU backend per iteration (r = 1)",
          ["n", "backend", "ms/it", "speed-up"], gpu_vs_cpu(dev, a.rounds, a.iters))
    table("4. GPU: a batch of 64 poses (float32, tol 1e-3)",
          ["mesh", "n", "poses", "iterations", "s", "poses/s"], gpu_batch(dev, a.rounds))


if __name__ == "__main__":
    main()
