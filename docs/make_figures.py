"""Make the pictures of ``docs/figures.md`` (run from the repository root).

* ``docs/figures/gallery.png``: every mesh of ``../shared/data`` and the first frame of
  each sequence, drawn with the default camera (guessed up axis, front view); the title
  of each says the guess. This is the picture to look at after changing the guess.
* ``docs/figures/cactus-groups.png``: ``arapkit deform --dry-run --figure`` on the example
  cactus (handle groups in colour on the rest shape).
* ``docs/figures/cactus-bent.png``: the deformation figure of the same handles, r = 2.
* ``docs/figures/bar-shared-scale.png``: the bar bent 180 degrees with r = 1, 2, 10 on one
  energy scale (the demo's Fig. 3 style).
* ``docs/figures/readme-bend.png``: the README's picture: the example finger under
  ``examples/handles/rotate-limb.json`` at r = 1 and r = 3 (the same handles and targets).

Usage::

    python docs/make_figures.py
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data"
OUT = ROOT / "docs" / "figures"


def gallery() -> None:
    import matplotlib.pyplot as plt

    from arapkit import guess_up, load_mesh
    from arapkit.mesh.orientation import view_frame
    from arapkit.plots.figures import render_mesh, save_figure

    items = []
    for p in sorted((DATA / "meshes").iterdir()):
        m = load_mesh(p)
        items.append((p.name, m.vertices, m.faces))
    for p in sorted((DATA / "sequences").glob("*.npz")):
        d = np.load(p)
        items.append((p.name, d["V"][0], d["F"]))
    cols = 5
    rows = -(-len(items) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(2.4 * cols, 2.5 * rows), dpi=60,
                             layout="constrained")
    for ax, (name, V, F) in zip(axes.ravel(), items, strict=False):
        g = guess_up(V)
        render_mesh(ax, V, F, basis=view_frame(V, "front", g.axis)[0], max_faces=8000)
        ax.set_title(f"{name}\nup {g.axis} ({g.confidence:.2f})", fontsize=8)
    for ax in axes.ravel()[len(items):]:
        ax.set_axis_off()
    save_figure(fig, OUT / "gallery.png")


def cactus() -> None:
    from arapkit import Deformer, load_handles, load_mesh
    from arapkit.plots.figures import deformation_figure, groups_figure, save_figure

    mesh = load_mesh(ROOT / "examples" / "cactus.off")
    hs = load_handles(ROOT / "examples" / "cactus.json", mesh.vertices)
    fig = groups_figure(mesh.vertices, mesh.faces, [(g.name, g.indices) for g in hs.groups],
                        title="cactus.json on cactus.off (--dry-run)")
    save_figure(fig, OUT / "cactus-groups.png", dpi=70)
    res = Deformer(mesh, hs.indices, rings=2).solve(hs.targets)
    fig = deformation_figure(mesh.vertices, mesh.faces, res.vertices, res.vertex_energy,
                             hs.indices, res.history, targets=hs.targets,
                             fixed_mask=hs.fixed_mask, title="cactus.off, r = 2")
    save_figure(fig, OUT / "cactus-bent.png", dpi=70)


def bar_scale() -> None:
    from arapkit import Deformer
    from arapkit.mesh.shapes import bar, bar_bend
    from arapkit.plots.figures import save_figure, series_figure

    mesh = bar()
    h, t = bar_bend(mesh, 180)
    panels = [("rest", mesh.vertices, None)]
    for r in (1, 2, 10):
        res = Deformer(mesh, h, rings=r).solve(t)
        panels.append((f"r = {r}", res.vertices, res.vertex_energy))
    fig = series_figure(mesh.faces, panels, colorbar_label="per-vertex energy")
    save_figure(fig, OUT / "bar-shared-scale.png", dpi=70)


def readme_bend() -> None:
    """The same bend at r = 1 and r = 3: r = 1 kinks at the joint, r = 3 bends as one piece."""
    from arapkit import Deformer, load_handles, load_mesh
    from arapkit.plots.figures import save_figure, series_figure

    mesh = load_mesh(ROOT / "examples" / "finger.off")
    hs = load_handles(ROOT / "examples" / "handles" / "rotate-limb.json", mesh.vertices)
    panels = [("rest", mesh.vertices, None)]
    for r, what in ((1, "standard ARAP"), (3, "stiffer")):
        res = Deformer(mesh, hs.indices, rings=r).solve(hs.targets)
        panels.append((f"r = {r} ({what})", res.vertices, None))
    save_figure(series_figure(mesh.faces, panels), OUT / "readme-bend.png", dpi=80)


def main() -> int:
    OUT.mkdir(exist_ok=True)
    if DATA.is_dir():
        gallery()
    else:
        print(f"skipped the gallery: {DATA} not found")
    cactus()
    bar_scale()
    readme_bend()
    print(f"wrote {', '.join(sorted(p.name for p in OUT.glob('*.png')))}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
