"""Make ``docs/volumetric-cactus.png``: surface ARAP against volumetric ARAP, same handles.

The project's cactus (``examples/cactus.off``) is twisted with
``examples/cactus-twist.json`` (pot fixed, top of the trunk turned 150° about the
trunk) at r = 1, once by surface ARAP and once by volumetric ARAP (default settings,
solved to convergence: tol 1e-5, accelerated). Faces that intersect another face are drawn
red (``tests/selfintersect.py``); the titles give the volume change and that count.

Usage::

    python docs/volumetric_figure.py [OUT.png]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
MESH = ROOT / "examples" / "cactus.off"
HANDLES = ROOT / "examples" / "cactus-twist.json"
CONVERGED = {"tol": 1e-5, "max_iter": 20000}


def main(argv: list[str]) -> int:
    import matplotlib.pyplot as plt

    from arapkit import Deformer, load_mesh
    from arapkit.io import load_handles
    from arapkit.mesh.orientation import view_frame
    from arapkit.methods.volumetric import VolumetricDeformer, mesh_volume
    from arapkit.plots.figures import render_mesh, save_figure

    sys.path.insert(0, str(ROOT / "tests"))
    from selfintersect import self_intersecting_faces

    out = Path(argv[0]) if argv else ROOT / "docs" / "volumetric-cactus.png"
    mesh = load_mesh(MESH)
    hs = load_handles(HANDLES, mesh.vertices)
    v0 = mesh_volume(mesh.vertices, mesh.faces)
    results = {
        "surface ARAP": Deformer(mesh, hs.indices, accelerate=True).solve(
            hs.targets, **CONVERGED).vertices,
        "volumetric ARAP": VolumetricDeformer(mesh, hs.indices, accelerate=True).solve(
            hs.targets, **CONVERGED).vertices,
    }
    basis = view_frame(mesh.vertices)[0]  # upright, from the rest shape, as every figure
    fig, axes = plt.subplots(1, 3, figsize=(13, 4.6))
    render_mesh(axes[0], mesh.vertices, mesh.faces, (np.isin(np.arange(mesh.n_vertices),
                hs.indices)).astype(float), basis=basis, cmap="coolwarm", reduce="max",
                max_faces=10**6)
    axes[0].set_title("rest\nhandles red: pot fixed, top turned 150°",
                      fontsize=11)
    for ax, (name, V) in zip(axes[1:], results.items()):
        bad = np.zeros(mesh.n_vertices)
        hit = self_intersecting_faces(V, mesh.faces)
        bad[np.unique(mesh.faces[hit])] = 1.0
        render_mesh(ax, V, mesh.faces, bad, basis=basis, cmap="coolwarm", reduce="max",
                    max_faces=10**6)
        dv = 100 * (mesh_volume(V, mesh.faces) - v0) / abs(v0)
        ax.set_title(f"{name}\nvolume {dv:+.1f} %, {len(hit)} self-intersecting faces (red)",
                     fontsize=11)
        print(f"{name}: volume change {dv:+.2f} %, self-intersecting faces {len(hit)}")
    for ax in axes:
        ax.set_axis_off()
        ax.set_aspect("equal")
    fig.tight_layout()
    save_figure(fig, out)
    print(out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
