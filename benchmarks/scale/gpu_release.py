"""Coarse to fine with the full iterations on a CUDA GPU: the release time on a large scan.

The proxy (preview and coarse start) runs on the CPU (numba); ``device="cuda"`` moves the
full-resolution local/global iterations to the GPU (torch backend, cholespy's CUDA
triangular solves; the factorisation itself is CHOLMOD's, on the CPU). For the dragon
(``--subdivide 0``) and its Loop subdivision (``1``), with the handles and drag of
``common.py`` ("bend"), this prints per device: the full problem's build (neighbourhoods +
factor), ``solve`` from rest (proxy + full iterations), the time per full iteration, and
the energy; and the largest distance between the CPU and the GPU results.

Usage (on a machine with a GPU; the mesh path is an argument so that it can be a copy)::

    python benchmarks/scale/gpu_release.py --mesh ../shared/data/meshes/dragon_vrip.ply.gz \\
        --subdivide 0 1
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from common import base_and_top, drag_targets, peak_rss_mb, table


def main(argv=None) -> None:
    import torch
    import trimesh.remesh

    from arapkit import Deformer, Mesh, load_mesh

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mesh", required=True)
    ap.add_argument("--subdivide", type=int, nargs="+", default=[0, 1])
    ap.add_argument("--devices", nargs="+", default=["cpu", "cuda"])
    args = ap.parse_args(argv)
    base_mesh = load_mesh(args.mesh)
    print(f"torch {torch.__version__}, CUDA: "
          f"{torch.cuda.get_device_name(0) if torch.cuda.is_available() else 'none'}")
    rows = []
    for sub in args.subdivide:
        mesh = base_mesh
        if sub:
            V, F = trimesh.remesh.subdivide_loop(base_mesh.vertices, base_mesh.faces,
                                                 iterations=sub)
            mesh = Mesh(V, F, name=f"{base_mesh.name} x{4 ** sub}")
        V = mesh.vertices
        base, top = base_and_top(V)
        h = np.concatenate([base, top])
        T = drag_targets(V, base, top, "bend")
        results = {}
        for device in args.devices:
            t0 = time.perf_counter()
            d = Deformer(mesh, h, device=device)
            t_open = time.perf_counter() - t0
            t0 = time.perf_counter()
            d.prepare()
            t_build = time.perf_counter() - t0
            d.solve(T, max_iter=2)  # warm: kernels compiled, GPU buffers allocated
            if device == "cuda":
                torch.cuda.synchronize()
            t0 = time.perf_counter()
            res = d.solve(T)
            if device == "cuda":
                torch.cuda.synchronize()
            t_solve = time.perf_counter() - t0
            results[device] = res
            full_s = t_solve - res.timings["proxy_s"]
            rows.append([mesh.name, f"{mesh.n_vertices:,}", device, f"{t_open:.1f}",
                         f"{t_build:.1f}", f"{t_solve:.2f}", f"{res.timings['proxy_s']:.2f}",
                         res.iterations, f"{1e3 * full_s / max(res.iterations, 1):.0f}",
                         f"{res.energy:.6e}", f"{peak_rss_mb() / 1024:.1f}"])
            print(rows[-1], flush=True)
        if len(results) == 2:
            a, b = results.values()
            gap = np.abs(a.vertices - b.vertices).max() / mesh.bounding_box_diagonal
            print(f"{mesh.name}: CPU vs GPU result, max distance {gap:.2e} of the diagonal")
    print(table(["mesh", "n", "device", "open s", "full build s", "solve s", "proxy s",
                 "full its", "ms / full it", "energy", "peak GiB"], rows))


if __name__ == "__main__":
    main()
