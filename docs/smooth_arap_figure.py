"""Make ``docs/smooth-arap.png``: ARAP and Smooth ARAP under the same single-vertex drag.

The cases of ``tests/spike_cases.py`` (bar, cactus, bumpy sphere; the shared cylinder when
present): a region held, one vertex dragged along its normal by 20 % of the bounding-box
diagonal, solved with the library's defaults by r-ring ARAP (r = 1) and by Smooth ARAP
(lambda = 0.99). Each row shows both shapes whole and close to the dragged vertex (red dot),
with the spike (height above the 2-ring's plane, less the rest height, in mean edge
lengths) in the titles.

Usage::

    python docs/smooth_arap_figure.py [OUT.png]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
#: the close-up's half width, in mean edge lengths
ZOOM = 9.0
#: the library's defaults (``--converged``: solved to tol 1e-5 with acceleration)
SOLVE: dict = {}


def main(argv: list[str]) -> int:
    from arapkit import Deformer
    from arapkit.plots.figures import render_mesh, save_figure
    from arapkit.plots.render import new_figure

    sys.path.insert(0, str(ROOT / "tests"))
    from spike_cases import cases, spike, vertex_normals

    if "--converged" in argv:
        argv = [a for a in argv if a != "--converged"]
        SOLVE.update(tol=1e-5, accelerate=True, max_iter=20000)
    out = Path(argv[0]) if argv else ROOT / "docs" / "smooth-arap.png"
    todo = cases()
    fig = new_figure(figsize=(13, 3.2 * len(todo)), dpi=80, layout="constrained")
    axes = np.atleast_2d(fig.subplots(len(todo), 4))
    for row, case in zip(axes, todo, strict=True):
        m = case.mesh
        shapes = {}
        for label, energy in (("ARAP", "rring"), ("Smooth ARAP", "smooth-arap")):
            res = Deformer(m, case.handles, energy=energy).solve(case.targets, **SOLVE)
            shapes[label] = (res.vertices, spike(m, res.vertices, case.vertex),
                             res.iterations)
            print(f"{case.name}: {label} spike {shapes[label][1]:.4f}, "
                  f"{res.iterations} iterations")
        # look across the drag: the view's depth axis is perpendicular to the drag
        drag = vertex_normals(m)[case.vertex]
        X = m.vertices - m.vertices.mean(axis=0)
        for axis in np.linalg.svd(X, full_matrices=False)[2]:  # the longest way across
            side = axis - (axis @ drag) * drag
            if np.linalg.norm(side) > 0.3:
                break
        side /= np.linalg.norm(side)
        basis = np.stack([side, drag, np.cross(side, drag)])
        h = m.mean_edge_length
        for k, (label, (V, s, its)) in enumerate(shapes.items()):
            for zoom in (False, True):
                ax = row[k + 2 * zoom]
                render_mesh(ax, V, m.faces, basis=basis, max_faces=10**6)
                p = V[case.vertex] @ basis.T
                ax.plot(p[0], p[1], "o", color="red", ms=4 if zoom else 3)
                if zoom:
                    ax.set_xlim(p[0] - ZOOM * h, p[0] + ZOOM * h)
                    ax.set_ylim(p[1] - 1.4 * ZOOM * h, p[1] + 0.6 * ZOOM * h)
                    ax.set_title(f"{label}, close up: spike {s:.3f} h", fontsize=10)
                else:
                    ax.set_title(f"{case.name}: {label} ({its} iterations)", fontsize=10)
    save_figure(fig, out)
    print(out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
