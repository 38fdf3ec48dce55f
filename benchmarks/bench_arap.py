"""arapkit's solver against libigl's ARAP, side by side in one process (issues 2 and 6).

Prints, for real meshes from ``../shared/data/meshes``:

1. time per iteration at r = 1, 3, 6 against libigl's (``igl.arap_solve``, SPOKES) and
   against the bare CHOLMOD 3-right-hand-side solve of the same system;
2. precomputation (neighbourhoods + factorisation) against ``igl.arap_precomputation``;
3. wall time to reach the energy libigl reaches after 200 iterations, plain and with
   Anderson acceleration (energies compared under arapkit's eq. (1) at libigl's positions
   with best-fit rotations; libigl's SPOKES energy with cotmatrix weights is the same
   function, factor 1, checked below);
4. the paper's bar bent 180 degrees at r = 10 with the Table-1 breakdown;
5. with ``--scale``: a >= 1M-vertex subdivided mesh at r = 1 and r = 3 in a subprocess,
   reporting time per iteration and peak resident memory.

Timings on a shared machine are noisy: every figure is a median over interleaved rounds
and each ratio compares figures taken in the same rounds.

Usage::

    python benchmarks/bench_arap.py            # sections 1-4 (a few minutes)
    python benchmarks/bench_arap.py --quick    # bunny only, fewer rounds
    python benchmarks/bench_arap.py --scale    # also section 5 (several minutes, ~5 GB)
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from arapkit import Deformer, Mesh, load_mesh
from arapkit.mesh.shapes import bar, bar_bend

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "meshes"


def median_time(fn, repeat: int) -> float:
    """Median wall time of ``fn()`` in seconds."""
    ts = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts))


def drag_problem(mesh: Mesh, frac: float = 0.05, move: float = 0.25):
    """Fix the lowest ``frac`` of vertices (along y), drag the highest by ``move`` x bbox."""
    V = mesh.vertices
    order = np.argsort(V[:, 1], kind="stable")
    k = max(1, int(frac * len(V)))
    h = np.concatenate([order[:k], order[-k:]])
    T = V[h].copy()
    T[k:] += np.array([move, 0.0, 0.5 * move]) * mesh.bounding_box_diagonal
    return h, T


def subdivided(name: str, times: int) -> Mesh:
    """A real mesh split ``times`` times (each triangle into four), vertices kept first."""
    import trimesh.remesh

    m = load_mesh(DATA / name)
    V, F = m.vertices, m.faces
    for _ in range(times):
        V, F = trimesh.remesh.subdivide(V, F)
    return Mesh(V, F, name=f"{name} x{4 ** times}")


def igl_data(V, F, h, iters: int):
    import igl

    data = igl.ARAPData()
    data.energy = igl.ARAP_ENERGY_TYPE_SPOKES
    data.max_iter = iters
    igl.arap_precomputation(V, F, 3, h.astype(np.int32), data)
    return data


def table(title: str, header: list[str], rows: list[list]) -> None:
    print(f"\n## {title}\n")
    print("| " + " | ".join(header) + " |")
    print("|" + "|".join("---" for _ in header) + "|")
    for r in rows:
        print("| " + " | ".join(str(x) for x in r) + " |")
    sys.stdout.flush()


# -- 1. per iteration -------------------------------------------------------------------


def per_iteration(mesh: Mesh, rounds: int, iters: int = 20) -> list[list]:
    import igl

    h, T = drag_problem(mesh)
    V, F = mesh.vertices, mesh.faces
    data = igl_data(V, F, h, iters)
    ds = {}
    for r in (1, 3, 6):
        ds[r] = Deformer(mesh, h, rings=r, weights="cotan")
        ds[r].solve(T, max_iter=2, tol=0)  # factorise, compile
    f = ds[1]._factor
    rhs = np.random.default_rng(0).normal(size=(f.n, 3))
    out = np.empty_like(rhs)
    samples: dict[str, list[float]] = {k: [] for k in ("bare", "igl", 1, 3, 6)}
    for _ in range(rounds):  # interleaved, so that load from other processes hits all alike
        samples["bare"].append(median_time(lambda: f.solve(rhs, out), 15))
        samples["igl"].append(median_time(lambda: igl.arap_solve(T, data, V.copy()), 1) / iters)
        for r in (1, 3, 6):
            samples[r].append(median_time(lambda r=r: ds[r].solve(T, max_iter=iters, tol=0), 1)
                              / iters)
    med = {k: 1e3 * float(np.median(v)) for k, v in samples.items()}
    rows = []
    for r in (1, 3, 6):
        rows.append([mesh.name, mesh.n_vertices, r, f"{med[r]:.2f}", f"{med['igl']:.2f}",
                     f"{med['igl'] / med[r]:.1f}x", f"{med['bare']:.2f}",
                     f"{med[r] / med['bare']:.2f}", f"{med[r] / med[1]:.2f}"])
    return rows


# -- 2. precomputation ----------------------------------------------------------------------


def precomputation(mesh: Mesh, rounds: int) -> list[list]:
    h, _ = drag_problem(mesh)
    V, F = mesh.vertices, mesh.faces
    _ = mesh.edges  # a loaded mesh has its topology; both sides start from arrays + handles

    def ours(r):
        d = Deformer(mesh, h, rings=r, weights="cotan")
        d.prepare()

    def ours_raw():
        d = Deformer(Mesh(V, F), h, rings=1, weights="cotan")
        d.prepare()

    t_igl, t1, t3, traw = [], [], [], []
    for _ in range(rounds):
        t_igl.append(median_time(lambda: igl_data(V, F, h, 1), 1))
        t1.append(median_time(lambda: ours(1), 1))
        t3.append(median_time(lambda: ours(3), 1))
        traw.append(median_time(ours_raw, 1))
    ti, a, b, c = (1e3 * float(np.median(x)) for x in (t_igl, t1, t3, traw))
    return [[mesh.name, mesh.n_vertices, f"{a:.0f}", f"{c:.0f}", f"{b:.0f}", f"{ti:.0f}",
             f"{ti / a:.1f}x", f"{ti / c:.1f}x"]]


# -- 3. time to libigl's 200-iteration energy --------------------------------------------


def energy_at(d: Deformer, T, P) -> float:
    """arapkit's eq. (1) at positions P with best-fit rotations (no iteration)."""
    return d.solve(T, init=P, max_iter=0).energy


def check_energy_factor(mesh: Mesh) -> float:
    """Ratio of libigl's SPOKES energy weights (cotmatrix) to arapkit's r = 1 weights."""
    import igl

    L = igl.cotmatrix(mesh.vertices, mesh.faces).tocsr()
    from arapkit.mesh.weights import edge_weights

    w = edge_weights(mesh)
    Lw = np.asarray(L[mesh.edges[:, 0], mesh.edges[:, 1]]).ravel()
    ok = np.abs(w) > 1e-12 * np.abs(w).max()
    return float(np.median(Lw[ok] / w[ok]))


def time_to_energy(mesh: Mesh, igl_iters: int = 200) -> list[list]:
    import igl

    h, T = drag_problem(mesh)
    V, F = mesh.vertices, mesh.faces
    t0 = time.perf_counter()
    data = igl_data(V, F, h, igl_iters)
    t_igl_pre = time.perf_counter() - t0
    U0 = V.copy()
    U0[h] = T
    t0 = time.perf_counter()
    U = igl.arap_solve(T, data, U0)
    t_igl = time.perf_counter() - t0
    small = bar()
    hb, tb = bar_bend(small, 90)
    for acc in (False, True):  # compile both loops outside the timing
        Deformer(small, hb, weights="cotan", accelerate=acc).solve(tb, max_iter=8)
    rows = []
    for acc in (False, True):
        t0 = time.perf_counter()
        d = Deformer(mesh, h, rings=1, weights="cotan", accelerate=acc)
        d.prepare()
        t_pre = time.perf_counter() - t0
        target = energy_at(d, T, U)
        E0 = energy_at(d, T, V)
        t0 = time.perf_counter()
        res = d.solve(T, tol=0.0, max_iter=5 * igl_iters,
                      callback=lambda i, e, P, target=target: e <= target)
        t_solve = time.perf_counter() - t0
        reached = res.history[-1] <= target
        rows.append([
            mesh.name, mesh.n_vertices, "Anderson m=5" if acc else "plain",
            f"{E0:.4g} -> {target:.4g}", res.iterations if reached else f">{res.iterations}",
            f"{t_solve:.3f}", f"{t_igl:.2f}", f"{t_igl / t_solve:.1f}x",
            f"{(t_igl + t_igl_pre) / (t_solve + t_pre):.1f}x",
            res.timings.get("accel_rejected", "-"),
        ])
    return rows


# -- 4. the paper's bar -------------------------------------------------------------------


def paper_bar() -> list[list]:
    m = bar()
    h, t = bar_bend(m, 180)
    # compile outside the timing
    Deformer(m, h, rings=10, weights="cotan").solve(t, max_iter=2)
    rows = []
    for r in (1, 2, 4, 6, 10):
        best = None
        for _ in range(5):
            t0 = time.perf_counter()
            d = Deformer(m, h, rings=r, weights="cotan")
            res = d.solve(t)
            total = time.perf_counter() - t0
            if best is None or total < best[0]:
                best = (total, res.timings)
        total, tm = best
        rows.append([m.n_vertices, r, f"{tm['neighbourhood_ms']:.1f}",
                     f"{tm['factorisation_ms']:.1f}", f"{tm['global_ms_per_iter']:.3f}",
                     f"{tm['local_ms_per_iter']:.3f}", tm["iterations"], f"{1e3 * total:.1f}"])
    return rows


# -- 5. scale -------------------------------------------------------------------------------


def scale_child(name: str, times: int, r: int, iters: int) -> None:
    """Runs in a fresh process so that ru_maxrss is this case's peak alone."""
    import resource

    t0 = time.perf_counter()
    m = subdivided(name, times)
    t_mesh = time.perf_counter() - t0
    h, T = drag_problem(m)
    t0 = time.perf_counter()
    # clamped: the subdivided scan has obtuse triangles whose negative weights, multiplied
    # by d_e at r = 3, make the exact-cotangent system indefinite
    d = Deformer(m, h, rings=r, weights="cotan-clamped")
    d.prepare()
    t_pre = time.perf_counter() - t0
    d.solve(T, max_iter=1, tol=0)
    t0 = time.perf_counter()
    res = d.solve(T, max_iter=iters, tol=0)
    t_it = (time.perf_counter() - t0) / iters
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20  # KiB -> GiB
    print(json.dumps(dict(mesh=m.name, n=m.n_vertices, r=r, mesh_s=t_mesh, pre_s=t_pre,
                          iter_ms=1e3 * t_it, global_ms=res.timings["global_ms_per_iter"],
                          local_ms=res.timings["local_ms_per_iter"], rss_gib=rss,
                          nnz=int(len(d.problem.energy.nbh.disk_idx)))))


def scale(name: str, times: int, iters: int) -> list[list]:
    rows = []
    for r in (1, 3):
        out = subprocess.run(
            [sys.executable, __file__, "--scale-child", name, str(times), str(r), str(iters)],
            capture_output=True, text=True, check=True,
        ).stdout.strip().splitlines()[-1]
        s = json.loads(out)
        rows.append([s["mesh"], s["n"], r, f"{s['pre_s']:.1f}", f"{s['iter_ms']:.0f}",
                     f"{s['global_ms']:.0f}", f"{s['local_ms']:.0f}", f"{s['rss_gib']:.2f}"])
    return rows


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="bunny only, fewer rounds")
    ap.add_argument("--scale", action="store_true", help="also the >= 1M-vertex case")
    ap.add_argument("--scale-child", nargs=4, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.scale_child:
        name, times, r, iters = a.scale_child
        scale_child(name, int(times), int(r), int(iters))
        return
    try:
        import igl  # noqa: F401
    except ImportError:
        print("libigl (pip install libigl) is needed for the side-by-side benchmark")
        return
    import numba

    print(f"# arapkit solver vs libigl — {os.cpu_count()} cores, "
          f"{numba.get_num_threads()} numba threads ({numba.threading_layer()})")
    bunny = load_mesh(DATA / "bunny00.off")
    meshes = [bunny] if a.quick else [bunny, load_mesh(DATA / "refined_elephant.off")]
    rounds = 3 if a.quick else 7
    rows = [row for m in meshes for row in per_iteration(m, rounds)]
    table("Time per iteration (ms; median of interleaved rounds)",
          ["mesh", "n", "r", "arapkit", "libigl", "libigl/arapkit", "bare solve",
           "arapkit/bare", "vs our r=1"], rows)
    rows = [row for m in meshes for row in precomputation(m, rounds)]
    table("Precomputation (ms): neighbourhoods + factorisation vs igl.arap_precomputation",
          ["mesh", "n", "arapkit r=1", "arapkit r=1 incl. Mesh()", "arapkit r=3", "libigl",
           "speed-up", "speed-up incl. Mesh()"], rows)
    print(f"\nlibigl cotmatrix weight / arapkit cotan weight (median over edges): "
          f"{check_energy_factor(bunny):.6f} -> the SPOKES energy is eq. (1) at r = 1, "
          "factor 1")
    big = [bunny] if a.quick else [bunny, subdivided("bunny00.off", 1)]
    rows = [row for m in big for row in time_to_energy(m)]
    table("Time to reach libigl's energy after 200 iterations (r = 1; solve only, s)",
          ["mesh", "n", "arapkit", "E(start) -> E(libigl 200)", "iterations", "arapkit s",
           "libigl 200 it s", "speed-up", "speed-up incl. precomp.", "AA rejected"], rows)
    table("Paper's bar bent 180 degrees (Table 1 breakdown, best of 5)",
          ["n", "r", "neighbourhoods ms", "factorisation ms", "global ms/it", "local ms/it",
           "iterations", "total ms"], paper_bar())
    if a.scale:
        table("Scale: dragon_vrip x4 (r = 1, 3; cotan-clamped; 10 iterations; own process)",
              ["mesh", "n", "r", "precomp. s", "ms/iter", "global ms/it", "local ms/it",
               "peak RSS GiB"], scale("dragon_vrip.ply.gz", 1, 10))


if __name__ == "__main__":
    main()
