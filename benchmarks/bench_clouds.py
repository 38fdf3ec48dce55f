"""Point clouds: which graph and weights deform a cloud as its mesh deforms, and what an
iteration costs against a mesh's (``docs/clouds.md``, ``docs/benchmarks.md``).

Parts (``--parts``, default all):

* ``weights``: each mesh is sampled at twice its vertex count, uniformly by area (seed 0),
  and the cloud is deformed with the same handle groups as the mesh (``examples/cactus.json``
  on the cactus; on CGAL's cow, elephant and homer the lowest tenth along the longest axis
  held and the highest tenth moved by a quarter of the extent sideways). The figure is the
  RMS, p95 and max distance of the cloud's result (r = 1, tol 1e-6) from the mesh's own
  r = 1 result at the same surface points (barycentric), as a percentage of the bounding
  box diagonal, for each weight kind and k; also the iterations and the milliseconds per
  iteration. ``--vertices`` adds the clouds made of the meshes' own vertices.
* ``speed``: a plain local/global iteration (tol 0, no acceleration) of a ~100K-point cloud
  (k = 10, gaussian weights) against a ~100K-vertex mesh (cotan-clamped), both r = 1 and the
  same handles, interleaved in one process: the cloud is the mesh's own vertex set, so the
  two differ by the graph alone. The meshes: the bar (100K vertices) and the dragon scan
  decimated to 100K. Reports the median time per iteration of each and their ratio
  (issue 46's bar: at most 1.5).

Usage::

    python benchmarks/bench_clouds.py                       # every part
    python benchmarks/bench_clouds.py --parts weights --k 6 8 10 12 16
    python benchmarks/bench_clouds.py --parts speed --repeats 5
    python benchmarks/bench_clouds.py --quick               # the cactus, and a 40K speed case
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from arapkit import Deformer, PointCloud  # noqa: E402
from arapkit.io import load_handles, load_mesh  # noqa: E402
from arapkit.mesh.cloud_weights import CLOUD_WEIGHT_KINDS  # noqa: E402

DATA = ROOT.parent / "shared" / "data" / "meshes"


def _load() -> str:
    return " ".join(f"{x:.1f}" for x in os.getloadavg())


def _sample(mesh, n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    V, F = mesh.vertices, mesh.faces
    area = np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)
    f = rng.choice(len(F), n, p=area / area.sum())
    u, v = rng.random(n), rng.random(n)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    return f, np.stack([1 - u - v, u, v], axis=1)


def _axis_handles(lo: np.ndarray, hi: np.ndarray):
    ax = int(np.argmax(hi - lo))
    span = hi[ax] - lo[ax]
    shift = np.zeros(3)
    shift[(ax + 1) % 3] = 0.25 * span

    def select(P: np.ndarray):
        a = P[:, ax] < lo[ax] + 0.1 * span
        b = P[:, ax] > hi[ax] - 0.1 * span
        h = np.flatnonzero(a | b)
        return h, P[h] + shift * b[h, None]
    return select


def _cases(quick: bool):
    mesh = load_mesh(ROOT / "examples" / "cactus.off")
    yield "cactus", mesh, lambda P: (lambda hs: (hs.indices, hs.targets))(
        load_handles(ROOT / "examples" / "cactus.json", P))
    if quick:
        return
    for name in ("cow", "elephant", "homer"):
        path = DATA / f"{name}.off"
        if not path.exists():
            print(f"({name}: {path} absent, skipped)")
            continue
        m = load_mesh(path)
        yield name, m, _axis_handles(m.vertices.min(axis=0), m.vertices.max(axis=0))


def weights_part(args) -> None:
    print(f"\n## weights: cloud vs mesh result (load {_load()})")
    print("| shape | cloud | k | weights | RMS % | p95 % | max % | iterations | ms/it |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name, mesh, select in _cases(args.quick):
        diag = mesh.bounding_box_diagonal
        h, t = select(mesh.vertices)
        ref = Deformer(mesh, h, tol=1e-6, multires=False).solve(t).vertices
        kinds = ["vertices", "samples"] if args.vertices else ["samples"]
        for kind in kinds:
            if kind == "vertices":
                P, R = mesh.vertices, ref
            else:
                f, B = _sample(mesh, 2 * mesh.n_vertices)
                P = np.einsum("nk,nkd->nd", B, mesh.vertices[mesh.faces[f]])
                R = np.einsum("nk,nkd->nd", B, ref[mesh.faces[f]])
            hc, tc = select(P)
            free = np.setdiff1d(np.arange(len(P)), hc)
            for k in args.k:
                cloud = PointCloud(P, neighbours=k)
                for w in args.weights:
                    try:
                        d = Deformer(cloud, hc, weights=w, tol=1e-6, multires=False)
                    except ImportError as e:
                        print(f"| {name} | {kind} | {k} | {w} | ({e}) |||||")
                        continue
                    t0 = time.perf_counter()
                    res = d.solve(tc)
                    ms = 1e3 * (time.perf_counter() - t0) / max(res.iterations, 1)
                    err = np.linalg.norm(res.vertices[free] - R[free], axis=1) / diag * 100
                    print(f"| {name} | {kind} ({len(P)}) | {k} | {w} | "
                          f"{np.sqrt(np.mean(err**2)):.3f} | {np.percentile(err, 95):.3f} | "
                          f"{err.max():.3f} | {res.iterations} | {ms:.2f} |", flush=True)


def _speed_meshes(args):
    """The ~100K-vertex meshes of the speed part: the bar, and the dragon scan decimated
    to 100K (when the shared data is there)."""
    from arapkit.mesh.shapes import bar
    from arapkit.methods.multires import decimate

    yield "bar", bar(segments=(450, 24, 24)) if args.quick else bar(segments=(820, 30, 30))
    if args.quick:
        return
    path = DATA / "dragon_vrip.ply.gz"
    if path.exists():
        yield "dragon scan decimated", decimate(load_mesh(path), 100_000)
    else:
        print(f"(dragon: {path} absent, skipped)")


def speed_part(args) -> None:
    print(f"\n## speed: plain iteration, cloud (k = 10) vs mesh (load {_load()})")
    print("| shape | points | edges | setup s | ms/it median (best) | cloud / mesh: best over "
          "best, median of the paired ratios (each pair) |")
    print("|---|---|---|---|---|---|")
    for name, mesh in _speed_meshes(args):
        V = mesh.vertices
        h, t = _axis_handles(V.min(axis=0), V.max(axis=0))(V)
        cloud = PointCloud(V, neighbours=10)
        t0 = time.perf_counter()
        dc = Deformer(cloud, h, multires=False, accelerate=False)
        dc.prepare()
        cloud_setup = time.perf_counter() - t0
        t0 = time.perf_counter()
        dm = Deformer(mesh, h, multires=False, accelerate=False)
        dm.prepare()
        mesh_setup = time.perf_counter() - t0
        for d in (dc, dm):  # compile and warm
            d.solve(t, max_iter=2, tol=0)
        times = {"cloud": [], "mesh": []}
        for _ in range(args.repeats):  # interleaved: the same load for both
            for label, d in (("cloud", dc), ("mesh", dm)):
                t0 = time.perf_counter()
                res = d.solve(t, max_iter=args.iterations, tol=0)
                times[label].append((time.perf_counter() - t0) / res.iterations)
        c, m = np.median(times["cloud"]), np.median(times["mesh"])
        cmin, mmin = np.min(times["cloud"]), np.min(times["mesh"])
        ratios = np.array(times["cloud"]) / np.array(times["mesh"])
        print(f"| {name}: mesh | {mesh.n_vertices} | {len(mesh.edges)} | {mesh_setup:.2f} | "
              f"{m * 1e3:.1f} (best {mmin * 1e3:.1f}) | |")
        # the best of the repeats is the least disturbed by other processes on a loaded
        # machine; the median of the paired ratios is the other estimate
        print(f"| {name}: its vertices as a cloud | {cloud.n_vertices} | {len(cloud.edges)} | "
              f"{cloud_setup:.2f} | {c * 1e3:.1f} (best {cmin * 1e3:.1f}) | "
              f"best {cmin / mmin:.2f}, median {np.median(ratios):.2f} ("
              + ", ".join(f"{r:.2f}" for r in ratios) + ") |", flush=True)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--parts", nargs="+", default=["weights", "speed"],
                   choices=["weights", "speed"])
    p.add_argument("--k", nargs="+", type=int, default=[10])
    p.add_argument("--weights", nargs="+", default=list(CLOUD_WEIGHT_KINDS))
    p.add_argument("--vertices", action="store_true",
                   help="also the clouds made of the meshes' own vertices")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--iterations", type=int, default=10)
    p.add_argument("--quick", action="store_true")
    args = p.parse_args()
    if "weights" in args.parts:
        weights_part(args)
    if "speed" in args.parts:
        speed_part(args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
