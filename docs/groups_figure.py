"""Make ``docs/figures/groups-cactus.png``: the cactus without and with vertex groups.

``examples/cactus.off`` deformed by ``examples/cactus.json`` (pot fixed, both hands swung
out about their shoulders) at r = 1: plain ARAP, then with ``examples/cactus-groups.json``
(the left arm a rigid part, held by its hand: it turns as one piece; the right arm one
shared rotation, libigl's G). Colour: how much each vertex's edges changed length (the
largest relative change over its edges), the same scale in both; inside the left arm it
stays 0 (its rim shows the edges that leave it: the shoulder bends).

Usage::

    PYTHONPATH=src python docs/groups_figure.py [OUT.png]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def stretch(mesh, X) -> np.ndarray:
    """Per vertex, the largest relative length change of its edges."""
    E = mesh.edges
    rest = np.linalg.norm(mesh.vertices[E[:, 0]] - mesh.vertices[E[:, 1]], axis=1)
    rel = np.abs(np.linalg.norm(X[E[:, 0]] - X[E[:, 1]], axis=1) / rest - 1)
    out = np.zeros(mesh.n_vertices)
    np.maximum.at(out, E[:, 0], rel)
    np.maximum.at(out, E[:, 1], rel)
    return out


def main(argv: list[str]) -> int:
    from matplotlib.colors import ListedColormap, Normalize

    from arapkit import Deformer, load_groups, load_handles, load_mesh
    from arapkit.mesh.orientation import view_frame
    from arapkit.plots.figures import render_mesh, save_figure
    from arapkit.plots.render import colorbar, new_figure

    out = Path(argv[0]) if argv else ROOT / "docs" / "figures" / "groups-cactus.png"
    mesh = load_mesh(ROOT / "examples" / "cactus.off")
    hs = load_handles(ROOT / "examples" / "cactus.json", mesh.vertices)
    groups = load_groups(ROOT / "examples" / "cactus-groups.json", mesh)
    plain = Deformer(mesh, hs.indices).solve(hs.targets, tol=1e-6)
    grouped = Deformer(mesh, hs.indices, groups=groups).solve(hs.targets, tol=1e-6)
    basis = view_frame(mesh.vertices)[0]
    fig = new_figure(figsize=(13, 4.8))
    axes = fig.subplots(1, 3)
    # 0 free, 1 handle, 2 rigid part, 3 shared rotation
    kind = np.where(groups.ids < 0, 0.0, np.where(groups.rigid[groups.ids], 2.0, 3.0))
    kind[hs.indices] = 1.0
    render_mesh(axes[0], mesh.vertices, mesh.faces, kind, basis=basis,
                cmap=ListedColormap(["#c8ccd4", "#5a5f6b", "tab:blue", "tab:orange"]),
                norm=Normalize(-0.5, 3.5), reduce="max", max_faces=10**6)
    axes[0].set_title("rest: rigid left arm (blue), right arm\none shared rotation "
                      "(orange), handles dark", fontsize=10)
    s_plain, s_grouped = stretch(mesh, plain.vertices), stretch(mesh, grouped.vertices)
    norm = Normalize(0, float(np.percentile(np.concatenate([s_plain, s_grouped]), 99)))
    inside = np.isin(mesh.edges, groups.members(0)).all(axis=1)  # the left arm's edges
    worst = {}
    for ax, name, res, s in ((axes[1], "ARAP", plain, s_plain),
                             (axes[2], "ARAP with the groups", grouped, s_grouped)):
        render_mesh(ax, res.vertices, mesh.faces, s, basis=basis, cmap="magma_r", norm=norm,
                    reduce="max", max_faces=10**6)
        E = mesh.edges[inside]
        rest = np.linalg.norm(mesh.vertices[E[:, 0]] - mesh.vertices[E[:, 1]], axis=1)
        now = np.linalg.norm(res.vertices[E[:, 0]] - res.vertices[E[:, 1]], axis=1)
        worst[name] = float(np.abs(now / rest - 1).max())
        ax.set_title(f"{name}, {res.iterations} iterations:\nleft arm's edges change "
                     f"<= {worst[name]:.1e}", fontsize=10)
    for ax in axes:
        ax.set_axis_off()
        ax.set_aspect("equal")
    colorbar(fig, axes[1:], norm, "magma_r", "largest relative edge-length change")
    save_figure(fig, out)
    print(f"{out}: largest edge change inside the left arm " +
          ", ".join(f"{k} {v:.2e}" for k, v in worst.items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
