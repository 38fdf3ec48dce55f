"""Precomputation against libigl's ``arap_precomputation``, from 10K vertices to the scan.

Goal 4 of the large-mesh work asks for a precomputation at least 2x faster than libigl's on
the same mesh at every size from 10K up. Three arapkit figures per mesh, each on a mesh
whose topology is already built (as a loaded mesh has it):

* ``full``: ``Deformer(mesh, handles, weights="cotan", multires=False).prepare()``, the
  exact problem's neighbourhoods and factor (libigl's weights, so the same system);
* ``ready``: from 100K vertices, ``Deformer(mesh, handles)`` (coarse to fine) until it can
  preview: decimation (cache emptied first), binding and the proxy's factor. The full
  factor is then built in the background (the editor) or at the first ``solve``;
* ``igl``: ``igl.arap_precomputation`` (SPOKES, dim 3, the same handles).

Meshes: the dragon scan and its decimations cut to their largest connected component
(libigl's precomputation fails on a component without a handle; the scan has 151), and
bunny00. Handles: the lowest and the highest 5 % of the vertices along y. One process, sequential,
after a warm-up on the smallest mesh (numba kernels loaded). Usage::

    PYTHONPATH=src .venv/bin/python benchmarks/scale/precompute.py [--skip-igl-above N]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import DATA, base_and_top, dragon, dragon_decimated, machine_load  # noqa: E402


def seconds(fn, *args, **kwargs) -> float:
    t0 = time.perf_counter()
    fn(*args, **kwargs)
    return time.perf_counter() - t0


def full_precompute(mesh, h) -> None:
    from arapkit import Deformer

    Deformer(mesh, h, weights="cotan", multires=False).prepare()


def igl_precompute(mesh, h) -> None:
    import igl

    data = igl.ARAPData()
    data.energy = igl.ARAP_ENERGY_TYPE_SPOKES
    data.max_iter = 1
    igl.arap_precomputation(mesh.vertices, mesh.faces, 3, h.astype(np.int32), data)


def largest_component(mesh):
    """``mesh`` cut to its largest connected component (vertices renumbered)."""
    import arapkit

    labels = mesh.component_labels
    keep = labels == np.argmax(np.bincount(labels))
    new = np.cumsum(keep) - 1
    F = mesh.faces[keep[mesh.faces].all(axis=1)]
    return arapkit.Mesh(mesh.vertices[keep], new[F], name=f"{mesh.name} (largest part)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--skip-igl-above", type=int, default=10**9,
                    help="leave libigl out above this many vertices")
    args = ap.parse_args()

    import arapkit
    from arapkit import Deformer
    from arapkit.methods import multires
    from arapkit.methods.multires import decimator

    meshes = [largest_component(dragon_decimated(10_000)),
              arapkit.load_mesh(DATA / "bunny00.off"),
              largest_component(dragon_decimated(100_000)), largest_component(dragon())]
    print(machine_load())
    rows = []
    for k, mesh in enumerate(meshes):
        _ = mesh.edges
        base, top = base_and_top(mesh.vertices)
        h = np.concatenate([base, top])
        if k == 0:  # warm-up: kernels loaded, libigl imported
            Deformer(mesh, h, weights="cotan", multires=False).prepare()
            igl_precompute(mesh, h)
        full = seconds(full_precompute, mesh, h)
        ready = float("nan")
        if mesh.n_vertices >= multires.AUTO_MIN_VERTICES:
            decimator._cache.clear()
            ready = seconds(Deformer, mesh, h)
        igl_s = float("nan")
        if mesh.n_vertices <= args.skip_igl_above:
            igl_s = seconds(igl_precompute, mesh, h)
        rows.append((mesh.name, mesh.n_vertices, full, ready, igl_s))
        print(f"{mesh.name}: {mesh.n_vertices} vertices · full {full:.2f} s · "
              f"ready {ready:.2f} s · libigl {igl_s:.2f} s", flush=True)
    print("\n| mesh | vertices | arapkit full s | arapkit ready to preview s | libigl s "
          "| libigl / full | libigl / ready |")
    print("|---|---|---|---|---|---|---|")
    for name, n, full, ready, igl_s in rows:
        print(f"| {name} | {n:,} | {full:.2f} | {ready:.2f} | {igl_s:.2f} | "
              f"{igl_s / full:.1f}x | {igl_s / ready:.1f}x |")
    print(machine_load())


if __name__ == "__main__":
    main()
