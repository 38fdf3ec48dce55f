"""Decimation candidates for the coarse proxy: time to 20K / 50K vertices, correspondence.

For each library the dragon (437,645 vertices) is decimated to about 20K and 50K vertices
(a target of twice as many faces). Reported: the time, the vertex count reached, the
Hausdorff-like distance of the full mesh to the proxy's vertices (nearest-vertex distance,
95th percentile and max, as a fraction of the bounding-box diagonal), and what
correspondence the library gives. The cost of making one where it is missing (a k-d tree
query of every full vertex, and a closest-point-on-triangle projection) is timed too.

Usage::

    python benchmarks/scale/decimate.py                  # every installed candidate
    python benchmarks/scale/decimate.py --libs fast-simplification libigl --targets 20000

Optional libraries are looked up in /tmp/scale-pkgs as well (see
docs/studies/interactive-at-scale.md).
"""

from __future__ import annotations

import argparse
import importlib.util
import time

import numpy as np
from common import dragon, machine_load, table, timed
from scipy.spatial import cKDTree


def fast_simplification_run(V, F, n):
    """fast-simplification (MIT): Fast-Quadric-Mesh-Simplification + collapse replay."""
    import fast_simplification as fs

    U, G, collapses = fs.simplify(V.astype(np.float32), F, target_count=2 * n,
                                  return_collapses=True)
    t0 = time.perf_counter()
    _, _, mapping = fs.replay_simplification(V.astype(np.float32), F, collapses)
    return U, G, f"cluster map (full -> proxy vertex), replay {time.perf_counter() - t0:.2f} s", \
        mapping


def pyfqmr_run(V, F, n):
    """pyfqmr (MIT): the same Fast-Quadric-Mesh-Simplification, another wrapper."""
    import pyfqmr

    s = pyfqmr.Simplify()
    s.setMesh(V, F)
    s.simplify_mesh(target_count=2 * n, aggressiveness=7, preserve_border=True, verbose=False)
    U, G, _ = s.getMesh()
    return U, G, "none", None


def trimesh_run(V, F, n):
    """trimesh.simplify_quadric_decimation: calls fast-simplification (no own backend)."""
    import trimesh

    m = trimesh.Trimesh(V, F, process=False).simplify_quadric_decimation(face_count=2 * n)
    return m.vertices, m.faces, "none (drops fast-simplification's collapses)", None


def libigl_run(V, F, n):
    """libigl decimate (MPL-2.0): shortest edge first, midpoint placement."""
    import igl

    U, G, _, birth = igl.decimate(np.asfortranarray(V), np.asfortranarray(F.astype(np.int32)),
                                  2 * n)
    return U, G, "birth vertex per proxy vertex (proxy -> full)", None


def libigl_qslim_run(V, F, n):
    """libigl qslim (MPL-2.0): quadric error; refuses non-manifold input."""
    import igl

    out = igl.qslim(np.asfortranarray(V), np.asfortranarray(F.astype(np.int32)), 2 * n)
    return out[0], out[1], "birth vertex per proxy vertex (proxy -> full)", None


def open3d_run(V, F, n):
    """open3d (MIT): simplify_quadric_decimation."""
    import open3d as o3d

    m = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(V), o3d.utility.Vector3iVector(F))
    s = m.simplify_quadric_decimation(target_number_of_triangles=2 * n)
    return np.asarray(s.vertices), np.asarray(s.triangles), "none", None


CANDIDATES = {
    "fast-simplification": ("fast_simplification", fast_simplification_run),
    "pyfqmr": ("pyfqmr", pyfqmr_run),
    "trimesh": ("fast_simplification", trimesh_run),
    "libigl-decimate": ("igl", libigl_run),
    "libigl-qslim": ("igl", libigl_qslim_run),
    "open3d": ("open3d", open3d_run),
}


def projection_costs(V: np.ndarray, U: np.ndarray, G: np.ndarray) -> tuple[float, float]:
    """Seconds to map every full vertex to (nearest proxy vertex, closest proxy point)."""
    import igl

    _, t_tree = timed(lambda: cKDTree(U).query(V, k=1))
    _, t_proj = timed(igl.point_mesh_squared_distance, V, U, G.astype(np.int64))
    return t_tree, t_proj


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--libs", nargs="+", default=list(CANDIDATES))
    ap.add_argument("--targets", nargs="+", type=int, default=[20000, 50000])
    args = ap.parse_args(argv)
    mesh = dragon()
    # writable, contiguous copies: some wrappers refuse the mesh's read-only arrays
    V, F = np.array(mesh.vertices, dtype=np.float64), np.array(mesh.faces, dtype=np.int64)
    diag = mesh.bounding_box_diagonal
    print(f"dragon: {mesh.n_vertices} vertices, {len(F)} faces; {machine_load()}")
    rows = []
    for name in args.libs:
        module, run = CANDIDATES[name]
        if importlib.util.find_spec(module) is None:
            rows.append([name, "-", "not installed", "", "", "", ""])
            continue
        for n in args.targets:
            try:
                (U, G, corr, _), t = timed(run, V, F, n)
            except Exception as exc:  # a candidate's refusal is a result of the study
                rows.append([name, n, f"failed: {type(exc).__name__}: {str(exc)[:60]}",
                             "", "", "", ""])
                continue
            d = cKDTree(U).query(V, k=1)[0] / diag
            rows.append([name, n, len(U), t, float(np.percentile(d, 95)), float(d.max()), corr])
            print(rows[-1], flush=True)
    print()
    print(table(["library", "target", "vertices", "seconds", "p95 dist", "max dist",
                 "correspondence"], rows))
    m = [r for r in rows if r[0] == "fast-simplification" and isinstance(r[2], int)]
    if m:
        import fast_simplification as fs

        for n in args.targets:
            U, G = fs.simplify(V.astype(np.float32), F, target_count=2 * n)
            t_tree, t_proj = projection_costs(V, U.astype(np.float64), G)
            print(f"\nmaking a correspondence at {len(U)} proxy vertices: nearest vertex "
                  f"(k-d tree build + {len(V)} queries) {t_tree:.2f} s; closest point on "
                  f"the proxy's triangles (igl.point_mesh_squared_distance) {t_proj:.2f} s")
    print(machine_load())


if __name__ == "__main__":
    main()
