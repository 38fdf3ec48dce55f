"""Vertex groups: agreement with libigl's ``G`` and what groups and rigid parts cost.

Three tables for ``docs/benchmarks.md`` ("Vertex groups") and ``docs/groups.md``:

1. **Agreement.** Shared-rotation groups against libigl's ``arap_solve`` with ``G`` (spokes
   energy, raw cotangent weights, the same start and iteration count), and against
   libigl's algorithm replayed in double precision (``tests/igl_arap_oracle.py``), which in
   single precision reproduces libigl's binary. Also libigl without groups, for its own
   single-precision spread. Largest vertex distance over the bounding-box diagonal.
2. **Cost.** Time per iteration and precomputation, plain / shared-rotation groups / rigid
   parts / libigl with ``G``, rounds interleaved (medians); iterations to converge.
3. **Rigidity.** The largest relative change of an edge inside a rigid part.

Cases: ``examples/cactus.off`` with ``examples/cactus.json`` (both arms as shared groups for
libigl, which has no rigid parts; ``examples/cactus-groups.json`` for the parts), and
``bunny00.off`` from ``../shared/data`` (lowest 5 % held, highest 5 % dragged by (0.25, 0,
0.125) of the diagonal, as ``bench_arap.py``) with 12 patches of a voxel grid as groups.
Usage, from the repository root (about 5 minutes on 2 cores)::

    PYTHONPATH=src python benchmarks/bench_groups.py [--rounds 3]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from igl_arap_oracle import igl_arap_groups  # noqa: E402

from arapkit import Deformer, VertexGroups, load_groups, load_handles, load_mesh  # noqa: E402

DATA = ROOT.parent / "shared" / "data" / "meshes"


def cactus_case():
    m = load_mesh(ROOT / "examples" / "cactus.off")
    hs = load_handles(ROOT / "examples" / "cactus.json", m.vertices)
    parts = load_groups(ROOT / "examples" / "cactus-groups.json", m)
    shared = VertexGroups.from_ids(parts.ids, m.n_vertices)  # both arms, shared rotations
    return "cactus.off", m, hs.indices, hs.targets, shared, parts


def bunny_case():
    m = load_mesh(DATA / "bunny00.off")
    V = m.vertices
    order = np.argsort(V[:, 1])
    k = len(V) // 20
    h = np.concatenate([order[:k], order[-k:]])
    t = V[h].copy()
    t[k:] += np.array([0.25, 0.0, 0.125]) * m.bounding_box_diagonal
    # 12 patches: the cells of a coarse voxel grid that hold the most free vertices
    free = np.setdiff1d(np.arange(len(V)), h)
    cell = np.floor((V - V.min(0)) / (np.ptp(V, 0).max() / 6)).astype(int) @ [1, 100, 10000]
    cells, counts = np.unique(cell[free], return_counts=True)
    chosen = cells[np.argsort(counts)[::-1][:12]]
    ids = np.full(len(V), -1)
    for g, c in enumerate(chosen):
        ids[free[cell[free] == c]] = g
    shared = VertexGroups.from_ids(ids, len(V))
    parts = VertexGroups.from_ids(ids, len(V), rigid=True)
    return "bunny00.off", m, h, t, shared, parts


def libigl_G(n: int, groups: VertexGroups) -> np.ndarray:
    """libigl's G for ``groups``: each vertex's group, the ungrouped alone."""
    G = np.arange(n)
    for g in range(groups.n_groups):
        mem = groups.members(g)
        G[mem] = mem[0]
    return G


def agreement(case, iterations=(1, 10, 100)) -> None:
    import igl

    name, m, h, t, shared, _ = case
    V, F, n = m.vertices, m.faces, m.n_vertices
    diag = m.bounding_box_diagonal
    G = libigl_G(n, shared)
    for it in iterations:
        row = [name, str(it)]
        for with_groups in (True, False):
            d = igl.ARAPData()
            d.energy = igl.ARAP_ENERGY_TYPE_SPOKES
            d.max_iter = it
            if with_groups:
                d.G = G
            igl.arap_precomputation(V, F.astype(np.int64), 3, h.astype(np.int32), d)
            U = igl.arap_solve(t, d, V.copy())
            groups = shared if with_groups else None
            res = Deformer(m, h, weights="cotan", groups=groups).solve(t, init=V, tol=0,
                                                                      max_iter=it)
            if with_groups:
                G64 = igl_arap_groups(V, F, h, t, G, it, False)
                G32 = igl_arap_groups(V, F, h, t, G, it, True)
                row += [f"{np.abs(res.vertices - U).max() / diag:.2g}",
                        f"{np.abs(res.vertices - G64).max() / diag:.2g}",
                        f"{np.abs(G32 - U).max() / diag:.2g}"]
            else:
                row.append(f"{np.abs(res.vertices - U).max() / diag:.2g}")
        print("| " + " | ".join(row) + " |", flush=True)


def cost(case, rounds: int) -> None:
    import igl

    name, m, h, t, shared, parts = case
    n = m.n_vertices
    kinds = {"plain": None, "shared groups": shared, "rigid parts": parts}
    pre = {k: [] for k in [*kinds, "libigl G"]}
    per = {k: [] for k in pre}
    its = {}
    G = libigl_G(n, shared)
    for _ in range(rounds):  # interleaved: each round times every kind once
        for k, g in kinds.items():
            t0 = time.perf_counter()
            d = Deformer(m, h, groups=g)
            d.prepare()
            pre[k].append(time.perf_counter() - t0)
            res = d.solve(t, tol=0, max_iter=30)
            per[k].append(res.timings["total_s"] / res.iterations)
            if k not in its:
                conv = d.solve(t)
                its[k] = (conv.iterations, conv.converged)
        t0 = time.perf_counter()
        data = igl.ARAPData()
        data.energy = igl.ARAP_ENERGY_TYPE_SPOKES
        data.max_iter = 30
        data.G = G
        igl.arap_precomputation(m.vertices, m.faces.astype(np.int64), 3, h.astype(np.int32),
                                data)
        pre["libigl G"].append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        igl.arap_solve(t, data, m.vertices.copy())
        per["libigl G"].append((time.perf_counter() - t0) / 30)
    base = np.median(per["plain"])
    for k in pre:
        it = its.get(k)
        print(f"| {name} | {n} | {k} | {1e3 * np.median(per[k]):.2f} | "
              f"{np.median(per[k]) / base:.2f} | {1e3 * np.median(pre[k]):.0f} | "
              f"{'-' if it is None else f'{it[0]}' + ('' if it[1] else ' (cap)')} |",
              flush=True)


def rigidity(case) -> None:
    name, m, h, t, _, parts = case
    res = Deformer(m, h, groups=parts).solve(t)
    ids = parts.of_kind(True)  # the rigid parts only
    E = m.edges[(ids[m.edges[:, 0]] >= 0) & (ids[m.edges[:, 0]] == ids[m.edges[:, 1]])]
    rest = np.linalg.norm(m.vertices[E[:, 0]] - m.vertices[E[:, 1]], axis=1)
    now = np.linalg.norm(res.vertices[E[:, 0]] - res.vertices[E[:, 1]], axis=1)
    H = np.diff(res.history)
    print(f"| {name} | {parts.summary()} | {len(E)} | {np.abs(now / rest - 1).max():.1e} | "
          f"{res.iterations} | {H.max() / res.history[0]:.1e} |", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    cases = [cactus_case()]
    if (DATA / "bunny00.off").exists():
        cases.append(bunny_case())
    else:
        print(f"({DATA} not found: the cactus only)")
    print("\n| mesh | iterations | arapkit vs libigl G | arapkit vs libigl's algorithm in "
          "double | libigl's algorithm in single vs libigl | arapkit vs libigl, no groups |")
    print("|---|---|---|---|---|---|")
    for c in cases:
        agreement(c)
    print("\n| mesh | n | kind | ms / iteration | vs plain | precomputation ms | "
          "iterations to converge |")
    print("|---|---|---|---|---|---|---|")
    for c in cases:
        cost(c, args.rounds)
    print("\n| mesh | parts | edges inside | largest relative edge change | iterations | "
          "largest energy rise / E1 |")
    print("|---|---|---|---|---|---|")
    for c in cases:
        rigidity(c)


if __name__ == "__main__":
    main()
