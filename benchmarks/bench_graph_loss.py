"""The graph ARAP loss (arapkit.torch.GraphARAPLoss): forward plus backward at 100K points.

Target (issue 46, section 2): 100K points, k = 20, forward plus backward <= 200 ms on CPU,
with no n x n allocation. Compared, in the same run and interleaved round by round, with
the straightforward torch implementation that Gaussian-splatting code writes (each point's
k neighbours gathered into ``(n, k, 3)`` tensors, covariances by ``einsum``, rotations by
``torch.linalg.svd`` with the reflection fix, autograd for the backward), on the same
directed kNN graph, where both compute the same number (checked). A dense ``n x n`` form
does not fit at this size (one float32 ``n x n`` matrix is 40 GB).

Rows:

* ``arapkit``: the default loss (symmetrised kNN graph, r = 1, rotations detached) on the
  compiled CPU kernels, float32 and float64 positions;
* ``arapkit, directed``: ``symmetric=False`` (each point's own 20 neighbours, as Dynamic 3D
  Gaussians), the baseline's energy;
* ``arapkit, torch ops``: ``backend="torch"`` (the CUDA code path, run on CPU tensors);
* ``arapkit, differentiated``: rotations differentiated through the batched SVD;
* ``naive gather``: the baseline above.

Wall time is a median over rounds; CPU time (``time.process_time``, all threads) is given
beside it because the machine is shared: wall time there includes waiting for a core.

Usage::

    PYTHONPATH=src python benchmarks/bench_graph_loss.py                 # 100K in a cube
    PYTHONPATH=src python benchmarks/bench_graph_loss.py --cloud dragon  # 100K scan points
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np
import torch

from arapkit.torch import GraphARAPLoss

DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data"


def cloud(kind: str, n: int, seed: int = 0) -> np.ndarray:
    """n points: uniform in a unit cube (Gaussians fill a volume), or vertices of the
    dragon scan (``../shared/data/meshes/dragon_vrip.ply.gz``, 437K) drawn at random."""
    rng = np.random.default_rng(seed)
    if kind == "cube":
        return rng.random((n, 3))
    from arapkit import load_mesh

    V = load_mesh(DATA / "meshes" / "dragon_vrip.ply.gz").vertices
    V = V[rng.choice(len(V), n, replace=False)]
    return (V - V.min(0)) / np.ptp(V, 0).max()


def deformed(P: np.ndarray) -> np.ndarray:
    """A smooth twist about z and a stretch: every neighbourhood rotates and strains."""
    a = 0.8 * (P[:, 2] - 0.5)
    c, s = np.cos(a), np.sin(a)
    x, y = P[:, 0] - 0.5, P[:, 1] - 0.5
    return np.column_stack([c * x - s * y, s * x + c * y, 1.1 * P[:, 2]])


class NaiveGather(torch.nn.Module):
    """The straightforward torch loss on a directed kNN graph (n, k): gathers, einsum,
    ``torch.linalg.svd`` with the reflection fix, autograd."""

    def __init__(self, P: torch.Tensor, nbr: torch.Tensor, w: torch.Tensor) -> None:
        super().__init__()
        self.nbr, self.w = nbr, w
        self.d = P[nbr] - P[:, None]  # rest offsets (n, k, 3)

    def forward(self, X: torch.Tensor) -> torch.Tensor:
        w, d = self.w.to(X.dtype), self.d.to(X.dtype)
        D = X[self.nbr] - X[:, None]
        with torch.no_grad():
            S = torch.einsum("nk,nka,nkb->nab", w, d, D)
            U, _, Vh = torch.linalg.svd(S)
            V = Vh.mT
            sign = torch.sign(torch.linalg.det(V @ U.mT))
            V = torch.cat([V[..., :2], V[..., 2:] * sign[:, None, None]], dim=-1)
            R = V @ U.mT
        r = D - torch.einsum("nab,nkb->nka", R, d)
        return (w * (r * r).sum(-1)).sum()


def step(loss, X: torch.Tensor) -> tuple[float, float]:
    """Wall and CPU seconds of one forward plus backward."""
    X.grad = None
    t, c = time.perf_counter(), time.process_time()
    loss(X).backward()
    return time.perf_counter() - t, time.process_time() - c


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cloud", choices=["cube", "dragon"], default="cube")
    ap.add_argument("-n", type=int, default=100_000)
    ap.add_argument("-k", type=int, default=20)
    ap.add_argument("--rounds", type=int, default=7)
    args = ap.parse_args()
    n, k = args.n, args.k
    load0 = os.getloadavg()[0]
    P = cloud(args.cloud, n)
    X = deformed(P)
    print(f"{n} points ({args.cloud}), k = {k}, torch {torch.__version__}, "
          f"{torch.get_num_threads()} threads, load average {load0:.1f}")

    t = time.perf_counter()
    default = GraphARAPLoss(P, k=k)
    build_s = time.perf_counter() - t
    weights = "gaussian"
    losses = {
        "arapkit, float32": (default, torch.float32),
        "arapkit, float64": (default, torch.float64),
        "arapkit, directed, float32": (GraphARAPLoss(P, k=k, symmetric=False, weights=weights),
                                       torch.float32),
        "arapkit, torch ops, float32": (GraphARAPLoss(P, k=k, backend="torch"), torch.float32),
        "arapkit, differentiated, float32": (GraphARAPLoss(P, k=k, rotations="differentiated"),
                                             torch.float32),
    }
    # the baseline on the directed graph's neighbours and weights (the same energy)
    directed = losses["arapkit, directed, float32"][0]
    nbh = directed.neighbourhoods
    nbr = torch.from_numpy(nbh.perm[nbh.ei.reshape(n, k)][directed.iperm_np])
    w = torch.from_numpy(nbh.w.reshape(n, k)[directed.iperm_np])
    naive = NaiveGather(torch.tensor(P), nbr, w)
    losses["naive gather, directed, float32"] = (naive, torch.float32)
    Xs = {dt: torch.tensor(X, dtype=dt, requires_grad=True)
          for dt in (torch.float32, torch.float64)}
    x64 = Xs[torch.float64]
    a, b = directed(x64).item(), naive(x64).item()
    assert abs(a - b) <= 1e-9 * a, (a, b)  # the baseline computes the same energy

    times: dict[str, list] = {name: [] for name in losses}
    for loss, dt in losses.values():  # warm up (compiles the kernels once)
        step(loss, Xs[dt])
    for _ in range(args.rounds):
        for name, (loss, dt) in losses.items():
            times[name].append(step(loss, Xs[dt]))
    load1 = os.getloadavg()[0]
    base = np.median([w for w, _ in times["naive gather, directed, float32"]])
    print(f"\nbuild (kNN, symmetrised graph, order, rings): {1e3 * build_s:.0f} ms; "
          f"{default.n_terms} terms ({len(default.edges)} edges)\n")
    print("| implementation | wall ms (median) | CPU ms (median) | naive / this (wall) |")
    print("|---|---|---|---|")
    for name, ts in times.items():
        wall, cpu = np.median(np.array(ts), axis=0)
        print(f"| {name} | {1e3 * wall:.0f} | {1e3 * cpu:.0f} | {base / wall:.1f}x |")
    print(f"\nload average {load0:.1f} at the start, {load1:.1f} at the end; "
          f"{args.rounds} rounds, interleaved")


if __name__ == "__main__":
    main()
