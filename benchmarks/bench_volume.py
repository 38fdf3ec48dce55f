"""Volumetric r-ring ARAP against surface ARAP on bends and twists (docs/benchmarks.md).

For every case (handle files in ``benchmarks/volume/``, the cactus twist in ``examples/``; the
bar is :func:`arapkit.mesh.shapes.bar`)
it solves surface ARAP (``arapkit.Deformer``, default weights) and volumetric ARAP
(:class:`arapkit.methods.volumetric.VolumetricDeformer`) with the same handles and r, and prints:

* self-intersecting faces of the deformed surface beyond those at rest (``tests/selfintersect``:
  libigl's triangle-triangle test on AABB-overlapping, non-adjacent pairs);
* the change of enclosed volume in percent;
* the largest handle error over the bounding-box diagonal;
* time: tetrahedralisation, factorisation, per iteration (global + local), total solve.

``--libigl`` adds libigl's tetrahedral ARAP (per-tet rotations, cotangent weights) on the same
tets, as an independent reference for what the ARAP energy itself does to the volume.
The default tolerance is 1e-5 (converged: the figures no longer change at 1e-7); at the
solver's default 1e-3 slow cases stop early and can look better than their minimum (the
elephant: 0 self-intersecting faces at 1e-3, 46 converged).

``--timing`` instead times tetrahedralisation + factorisation + solve on bunny00 (37.7K
vertices) for the interior densities given.

Usage::

    python benchmarks/bench_volume.py                      # all cases, default settings
    python benchmarks/bench_volume.py --cases cactus-twist --libigl --accelerate
    python benchmarks/bench_volume.py --cases bar-twist --weights tet-volume uniform
    python benchmarks/bench_volume.py --cases cactus620-twist --rings 1 2 3 5 mixed --libigl
    python benchmarks/bench_volume.py --timing --density 3 6
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

from arapkit import Deformer, load_mesh
from arapkit.io import load_handles
from arapkit.mesh.shapes import bar, bar_bend
from arapkit.methods.volumetric import (
    DEFAULT_DENSITY,
    DEFAULT_VOLUME_WEIGHTS,
    VOLUME_WEIGHTS,
    VolumetricDeformer,
    mesh_volume,
    tetrahedralise,
)

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))
from selfintersect import self_intersecting_faces  # noqa: E402
from tet_arap_oracle import libigl_tet_arap  # noqa: E402

DATA = HERE.parents[1] / "shared" / "data" / "meshes"
EXAMPLES = HERE.parent / "examples"
CASES = ("bar-bend", "thick-bar-bend", "thick-bar-twist", "bar-twist", "cactus-twist120",
         "cactus-twist", "cactus620-twist", "knot1-twist", "elephant-bend", "cow-bend",
         "hand-open", "hand-close")
#: the ``--rings mixed`` rigidity map: r = 1 on the half below the middle of the longest
#: bounding-box axis, r = 5 above (a soft half and a stiff half, not tuned to any case)
MIXED = (1, 5)


def case(name: str):
    """(mesh, handles, targets) of a case."""
    if name == "bar-bend":  # the paper's bar, bent into a half circle
        m = bar()
        h, t = bar_bend(m, 180)
        return m, h, t
    if name == "thick-bar-bend":  # 5 x 1 x 1, bent by 90 degrees
        m = bar(5.0, 1.0, 1.0, (20, 4, 4))
        h, t = bar_bend(m, 90)
        return m, h, t
    if name == "thick-bar-twist":  # 5 x 1 x 1: the far end turned 90 degrees about the axis
        m = bar(5.0, 1.0, 1.0, (20, 4, 4))
        return (m, *_end_twist(m, 90))
    stem = name.split("-")[0]
    if name == "bar-twist":
        m = bar()
    elif stem == "cactus":  # the project's own model (examples/)
        m = load_mesh(EXAMPLES / "cactus.off")
    elif stem == "cactus620":  # the same, coarsened (volume/make_cactus620.py)
        m = load_mesh(HERE / "volume" / "cactus620.off")
    else:
        m = load_mesh(DATA / f"{stem}.off")
    handles = HERE / "volume" / f"{name}.json"
    if not handles.exists():  # the cactus twist is also a README example
        handles = EXAMPLES / f"{name}.json"
    hs = load_handles(handles, m.vertices)
    return m, hs.indices, hs.targets


def _end_twist(m, degrees: float):
    """Handles and targets: the x = min end fixed, the x = max end turned about the bar's axis
    (the line through its centroid along x)."""
    V = m.vertices
    lo, hi = V[:, 0].min(), V[:, 0].max()
    fixed, moved = np.flatnonzero(V[:, 0] <= lo + 1e-9), np.flatnonzero(V[:, 0] >= hi - 1e-9)
    c = V.mean(axis=0)
    a = np.radians(degrees)
    R = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    h = np.concatenate([fixed, moved])
    return h, np.concatenate([V[fixed], (V[moved] - c) @ R.T + c])


def rigidity(mesh, rings: str) -> np.ndarray:
    """Per-vertex r of a ``--rings`` value: an integer, or ``mixed`` (:data:`MIXED`)."""
    if rings != "mixed":
        return np.full(mesh.n_vertices, int(rings))
    V = mesh.vertices
    axis = int(np.argmax(V.max(axis=0) - V.min(axis=0)))
    mid = (V[:, axis].max() + V[:, axis].min()) / 2
    return np.where(V[:, axis] < mid, *MIXED)


def measure(mesh, handles, targets, res, rest_hits: int) -> dict:
    """Quality figures of one result."""
    V = res.vertices
    v0 = mesh_volume(mesh.vertices, mesh.faces)
    return {
        "selfx": len(self_intersecting_faces(V, mesh.faces)) - rest_hits,
        "dvol_pct": 100 * (mesh_volume(V, mesh.faces) - v0) / abs(v0),
        "handle_err": float(np.abs(V[handles] - targets).max()) / mesh.bounding_box_diagonal,
        "iters": res.iterations,
        "factor_ms": res.timings["factorisation_ms"],
        "iter_ms": res.timings["global_ms_per_iter"] + res.timings["local_ms_per_iter"],
        "solve_s": res.timings["total_s"],
        "tet_s": res.timings.get("tetrahedralisation_ms", 0.0) / 1e3,
    }


def row(label: str, m: dict) -> str:
    return (f"  {label:<28} selfx {m['selfx']:>4}  dV {m['dvol_pct']:+7.2f} %  "
            f"handles {m['handle_err']:.1e}  it {m['iters']:>4}  tet {m['tet_s']:5.1f} s  "
            f"factor {m['factor_ms']:7.0f} ms  iter {m['iter_ms']:6.1f} ms  "
            f"solve {m['solve_s']:6.2f} s")


def run_cases(args) -> None:
    for name in args.cases:
        mesh, h, t = case(name)
        rest = len(self_intersecting_faces(mesh.vertices, mesh.faces))
        print(f"{name}: {mesh.n_vertices} vertices, {rest} self-intersecting faces at rest",
              flush=True)
        tets = {d: tetrahedralise(mesh, d) for d in args.density}
        for rings in args.rings:
            r = rigidity(mesh, rings)
            print(f" r = {rings}", flush=True)
            res = Deformer(mesh, h, rings=r, max_iter=args.max_iter,
                           accelerate=args.accelerate).solve(t, tol=args.tol)
            print(row("surface", measure(mesh, h, t, res, rest)), flush=True)
            for density, tm in tets.items():
                for w in args.weights:
                    d = VolumetricDeformer(mesh, h, rings=r, weights=w, tet=tm,  # accelerated
                                           max_iter=args.max_iter)
                    res = d.solve(t, tol=args.tol)
                    label = f"volume {w} d={density:g} ({tm.n_vertices - tm.n_surface} in)"
                    print(row(label, measure(mesh, h, t, res, rest)), flush=True)
        if args.libigl:  # per-tet rotations: no r; the energy's own answer on these tets
            for tm in tets.values():
                libigl_row(mesh, tm, h, t, rest)


def libigl_row(mesh, tm, h, t, rest: int) -> None:
    """libigl's tetrahedral ARAP on the tets ``tm``: self-intersections and volume change."""
    U = libigl_tet_arap(tm, h, t, 1000)
    v0 = mesh_volume(mesh.vertices, mesh.faces)
    if not np.isfinite(U).all():  # its cotangent weights on slivers
        print(f"  {'libigl tet ARAP, same tets':<28} non-finite result", flush=True)
        return
    print(f"  {'libigl tet ARAP, same tets':<28} selfx "
          f"{len(self_intersecting_faces(U, mesh.faces)) - rest:>4}  dV "
          f"{100 * (mesh_volume(U, mesh.faces) - v0) / abs(v0):+7.2f} %", flush=True)


def run_timing(args) -> None:
    mesh = load_mesh(DATA / "bunny00.off")
    lo = mesh.vertices[:, 1].min()
    h = np.flatnonzero(mesh.vertices[:, 1] < lo + 0.1)
    top = np.flatnonzero(mesh.vertices[:, 1] > mesh.vertices[:, 1].max() - 0.15)
    h = np.concatenate([h, top])
    t = mesh.vertices[h].copy()
    t[-len(top):, 0] += 0.1
    for density in args.density:
        t0, c0 = time.perf_counter(), time.process_time()
        r = rigidity(mesh, args.rings[0])
        d = VolumetricDeformer(mesh, h, rings=r, density=density,
                               max_iter=args.max_iter)
        t1, c1 = time.perf_counter(), time.process_time()
        res = d.solve(t, tol=args.tol)
        t2, c2 = time.perf_counter(), time.process_time()
        s = Deformer(mesh, h, rings=r, max_iter=args.max_iter).solve(t, tol=args.tol)
        ti = res.timings
        print(f"bunny00 d={density:g}: {d.tet.n_vertices} tet vertices, {len(d.tet.tets)} tets; "
              f"tetrahedralise {d.tet.seconds:.1f} s (CPU {d.tet.cpu_seconds:.1f} s), "
              f"set-up total {t1 - t0:.1f} s, "
              f"factorise {ti['factorisation_ms'] / 1e3:.1f} s, solve {t2 - t1:.1f} s "
              f"({res.iterations} it, {ti['global_ms_per_iter'] + ti['local_ms_per_iter']:.0f}"
              f" ms/it); all {t2 - t0:.1f} s. CPU: mesher {d.tet.cpu_seconds:.1f} s + "
              f"set-up {c1 - c0:.1f} s + solve {c2 - c1:.1f} s = "
              f"{d.tet.cpu_seconds + c2 - c0:.1f} s. Surface: "
              f"{s.timings['global_ms_per_iter'] + s.timings['local_ms_per_iter']:.0f} ms/it, "
              f"{s.iterations} it; load average {os.getloadavg()[0]:.1f}", flush=True)


def _rings_arg(text: str) -> str:
    if text != "mixed" and not (text.isdigit() and int(text) >= 1):
        raise argparse.ArgumentTypeError(f"{text}: an integer >= 1 or 'mixed'")
    return text


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--cases", nargs="+", default=list(CASES), choices=CASES)
    p.add_argument("--weights", nargs="+", default=[DEFAULT_VOLUME_WEIGHTS], choices=VOLUME_WEIGHTS)
    p.add_argument("--density", nargs="+", type=float, default=[DEFAULT_DENSITY])
    p.add_argument("--rings", nargs="+", default=["1"], type=_rings_arg,
                   help="r values to run: integers, or 'mixed' (r = 1 on one half, 5 on the other)")
    p.add_argument("--tol", type=float, default=1e-5)
    p.add_argument("--max-iter", type=int, default=20000)
    p.add_argument("--accelerate", action="store_true",
                   help="accelerate surface ARAP too (volumetric ARAP is by default)")
    p.add_argument("--libigl", action="store_true", help="add libigl's tetrahedral ARAP")
    p.add_argument("--timing", action="store_true")
    args = p.parse_args()
    run_timing(args) if args.timing else run_cases(args)


if __name__ == "__main__":
    main()
