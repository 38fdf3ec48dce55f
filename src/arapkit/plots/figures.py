"""Headless figures: shaded meshes coloured by energy or rigidity, energy curves.

Each figure is a :class:`matplotlib.figure.Figure` drawn by :mod:`arapkit.plots.render` (flat
shading, painter's algorithm, display simplification of large meshes), built without pyplot:
importing this module never changes Matplotlib's backend. :func:`save_figure` writes one.

Views are upright: the up axis is :func:`arapkit.mesh.orientation.guess_up`'s guess unless
``up`` is given, and ``view`` picks *front* (default), *side*, *top* or *iso* (see
:func:`arapkit.mesh.orientation.view_frame`). Colours: r always uses
:data:`arapkit.plots.colors.RING_COLORS` (1 blue ... 6+ red, as the editor), energy always
:data:`arapkit.plots.colors.ENERGY_CMAP` (pale at 0); panels that are compared share one scale.

Examples
--------
>>> from arapkit.plots.figures import energy_curves_figure
>>> fig = energy_curves_figure({"r = 1": [1.0, 0.5, 0.4]})
>>> len(fig.axes)
1
"""

from __future__ import annotations

import os
import sys
from collections.abc import Mapping, Sequence

from ..errors import InputError, require_extra

# one line naming the extra instead of a bare "No module named 'matplotlib'"
require_extra("matplotlib", "plots", "arapkit.plots")

import numpy as np  # noqa: E402
from matplotlib.colors import BoundaryNorm, Colormap, ListedColormap, Normalize  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402
from matplotlib.ticker import MaxNLocator  # noqa: E402

from ..io import atomic_open, check_figure_format  # noqa: E402
from ..mesh.orientation import view_frame  # noqa: E402
from .colors import ENERGY_CMAP  # noqa: E402
from .render import (  # noqa: E402
    DEFAULT_MAX_FACES,
    FIXED_COLOR,
    MOVED_COLOR,
    REST_COLOR,
    cluster_simplify,
    colorbar,
    colormap,
    mark,
    new_figure,
    render_mesh,
    rings_colormap,
    value_norm,
    view_basis,
)

# the renderer's names stay importable from here, where they lived before the split
__all__ = [
    "DEFAULT_MAX_FACES",
    "ENERGY_CMAP",
    "cluster_simplify",
    "deformation_figure",
    "groups_figure",
    "energy_curves_figure",
    "iterations_figure",
    "render_mesh",
    "rings_colormap",
    "rings_figure",
    "save_figure",
    "series_figure",
    "value_norm",
    "view_basis",
]

# handle sets up to this size are also drawn as dots (larger ones only paint their faces)
_FEW_HANDLES = 100


def _camera(points: np.ndarray, view: str, up: str | None) -> np.ndarray:
    return view_frame(points, view, up)[0]


# --------------------------------------------------------------------------- figures


def deformation_figure(
    rest: np.ndarray,
    faces: np.ndarray,
    deformed: np.ndarray,
    vertex_energy: np.ndarray,
    handles: np.ndarray,
    history: Sequence[float],
    *,
    targets: np.ndarray | None = None,
    fixed_mask: np.ndarray | None = None,
    rings: np.ndarray | None = None,
    title: str | None = None,
    max_faces: int = DEFAULT_MAX_FACES,
    view: str = "front",
    up: str | None = None,
) -> Figure:
    """Summary figure of one deformation.

    Panels: the rest shape with the faces around handles painted (fixed dark blue, moved
    red; small handle sets are also marked with dots), the deformed shape
    coloured by per-vertex energy, the deformed shape coloured by r (only when ``rings``
    varies) and the energy per iteration.

    Parameters
    ----------
    rest, deformed : (n, 3)
    faces : (m, 3)
    vertex_energy : (n,)
    handles : (h,) int
    history : energies after each iteration
    targets : (h, 3), optional
        Handle targets (defaults to ``deformed[handles]``).
    fixed_mask : (h,) bool, optional
        Which handles are fixed (drawn black); others are drawn red.
    rings : (n,) int, optional
    title : str, optional
    max_faces : int
        Display budget per panel (see :func:`cluster_simplify`).
    view, up : camera (see :func:`arapkit.mesh.orientation.view_frame`), set from the rest shape
        and shared by all panels.

    Examples
    --------
    >>> import numpy as np
    >>> V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    >>> F = np.array([[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]])
    >>> fig = deformation_figure(V, F, V * 1.1, np.ones(4), np.array([0]), [2.0, 1.0])
    >>> len(fig.axes) >= 3
    True
    """
    handles = np.asarray(handles, dtype=np.int64)
    targets = deformed[handles] if targets is None else np.asarray(targets)
    fixed = np.zeros(len(handles), bool) if fixed_mask is None else np.asarray(fixed_mask, bool)
    varying = rings is not None and np.unique(rings).size > 1
    n_panels = 4 if varying else 3
    fig = new_figure(figsize=(4.0 * n_panels, 4.2), dpi=110, layout="constrained")
    axes = fig.subplots(1, n_panels, width_ratios=[1.0] * (n_panels - 1) + [0.9])
    basis = _camera(rest, view, up)

    # paint the faces around handles (occlusion-correct at any handle count); add markers
    # only for small handle sets, where single vertices would be too small to see
    labels = np.zeros(len(rest))
    labels[handles[fixed]] = 1.0
    labels[handles[~fixed]] = 2.0
    hcmap = ListedColormap([REST_COLOR, FIXED_COLOR, MOVED_COLOR])
    hnorm = BoundaryNorm([-0.5, 0.5, 1.5, 2.5], 3)
    render_mesh(
        axes[0],
        rest,
        faces,
        labels,
        basis=basis,
        cmap=hcmap,
        norm=hnorm,
        max_faces=max_faces,
        reduce="max",
    )
    if len(handles) <= _FEW_HANDLES:
        mark(axes[0], rest[handles[fixed]], basis, FIXED_COLOR, "fixed")
        mark(axes[0], rest[handles[~fixed]], basis, MOVED_COLOR, "moved")
        mark(axes[1], targets[~fixed], basis, MOVED_COLOR, "targets")
    axes[0].set_title("rest shape and handles", fontsize=9)
    if len(handles):
        kinds = [("fixed", FIXED_COLOR, fixed.any()), ("moved", MOVED_COLOR, (~fixed).any())]
        axes[0].legend(
            handles=[Patch(color=c, label=k) for k, c, present in kinds if present],
            loc="upper center",
            bbox_to_anchor=(0.5, 0.0),
            ncol=2,
            fontsize=7,
            frameon=False,
        )

    norm = render_mesh(
        axes[1], deformed, faces, vertex_energy, basis=basis, cmap=ENERGY_CMAP,
        max_faces=max_faces,
    )
    axes[1].set_title("deformed: per-vertex energy", fontsize=9)
    colorbar(fig, axes[1], norm, ENERGY_CMAP, "per-vertex energy (clipped at 99th percentile)")

    if varying:
        cmap, rnorm, levels = rings_colormap(rings)
        render_mesh(
            axes[2], deformed, faces, rings, basis=basis, cmap=cmap, norm=rnorm, max_faces=max_faces
        )
        axes[2].set_title("deformed: rigidity r", fontsize=9)
        colorbar(fig, axes[2], rnorm, cmap, "r (rings)")

    _energy_axes(axes[-1], {"": history})
    if title:
        fig.suptitle(title, fontsize=10)
    return fig


def _energy_axes(ax, histories: Mapping[str, Sequence[float]]) -> None:
    for label, h in histories.items():
        h = np.asarray(h, dtype=np.float64)
        if h.size:
            ax.plot(np.arange(1, h.size + 1), h, lw=1.4, label=label or None)
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel("iteration", fontsize=8)
    ax.set_ylabel("energy", fontsize=8)
    positive = [np.asarray(h) for h in histories.values() if len(h)]
    if positive and all(np.all(h > 0) for h in positive):
        ax.set_yscale("log")
    ax.tick_params(labelsize=7)
    ax.grid(alpha=0.3)
    ax.set_title("energy per iteration", fontsize=9)
    if any(histories):
        ax.legend(fontsize=7, frameon=False)


def energy_curves_figure(histories: Mapping[str, Sequence[float]]) -> Figure:
    """Energy after each iteration, one curve per labelled run (the paper's Fig. 4).

    Examples
    --------
    >>> fig = energy_curves_figure({"r = 1": [3.0, 2.0], "r = 2": [4.0, 3.5, 3.4]})
    >>> len(fig.axes[0].lines)
    2
    """
    fig = new_figure(figsize=(5.0, 3.6), dpi=110, layout="constrained")
    ax = fig.subplots()
    _energy_axes(ax, histories)
    return fig


def iterations_figure(rings: Sequence[int], iterations: Sequence[int]) -> Figure:
    """Iterations to convergence against ring size r (the paper's Fig. 5).

    Examples
    --------
    >>> fig = iterations_figure([1, 2, 4], [40, 20, 10])
    >>> fig.axes[0].get_xlabel()
    'ring size r'
    """
    fig = new_figure(figsize=(4.6, 3.4), dpi=110, layout="constrained")
    ax = fig.subplots()
    ax.plot(list(rings), list(iterations), "o-", lw=1.5)
    for r, it in zip(rings, iterations, strict=True):
        ax.annotate(str(it), (r, it), textcoords="offset points", xytext=(4, 4), fontsize=7)
    ax.set_xlabel("ring size r")
    ax.set_ylabel("iterations to converge")
    ax.set_xticks(list(rings))
    ax.grid(alpha=0.3)
    return fig


def series_figure(
    faces: np.ndarray,
    panels: Sequence[tuple[str, np.ndarray, np.ndarray | None]],
    *,
    cmap: str | Colormap = ENERGY_CMAP,
    norm: Normalize | None = None,
    colorbar_label: str = "energy",
    ncols: int | None = None,
    max_faces: int = DEFAULT_MAX_FACES,
    view: str = "front",
    up: str | None = None,
) -> Figure:
    """Several shapes of one mesh side by side in a common view (the paper's Fig. 3 / 8).

    Parameters
    ----------
    faces : (m, 3)
    panels : list of (title, vertices (n, 3), values (n,) or None)
        Panels without values are drawn plain grey.
    cmap, norm : colouring of the values. All panels share one scale (``norm``, default
        :func:`value_norm` of all panels' values) and one colour bar that says so, so that
        colours compare across panels.
    ncols : int, optional
        Panels per row (default: all in one row).
    view, up : camera (see :func:`arapkit.mesh.orientation.view_frame`), set from the first
        panel's shape and shared by all.

    Examples
    --------
    >>> import numpy as np
    >>> V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]); F = np.array([[0, 1, 2]])
    >>> fig = series_figure(F, [("rest", V, None), ("bent", V, np.ones(3))])
    >>> [a.get_title() for a in fig.axes[:2]]
    ['rest', 'bent']
    """
    ncols = ncols or len(panels)
    nrows = -(-len(panels) // ncols)
    fig = new_figure(figsize=(3.0 * ncols, 3.3 * nrows), dpi=110, layout="constrained")
    axes = np.atleast_1d(fig.subplots(nrows, ncols)).ravel()
    basis = _camera(panels[0][1], view, up)
    F = np.asarray(faces)
    valued = [np.asarray(v, float)[F].mean(axis=1) for _, _, v in panels if v is not None]
    ours = norm is None
    if ours and valued:
        norm = value_norm(valued)
    for ax, (title, V, vals) in zip(axes, panels, strict=False):
        render_mesh(ax, V, faces, vals, basis=basis, cmap=cmap, norm=norm, max_faces=max_faces)
        ax.set_title(title, fontsize=9)
    for ax in axes[len(panels) :]:
        ax.set_axis_off()
    if valued:
        clip = ", clipped at the 99th percentile" if ours else ""
        label = f"{colorbar_label} (one scale for all panels{clip})"
        colorbar(fig, list(axes[: len(panels)]), norm, cmap, label)
    return fig


def rings_figure(
    vertices: np.ndarray,
    faces: np.ndarray,
    rings: np.ndarray,
    r_min: int = 1,
    r_max: int = 6,
    title: str | None = None,
    views: Sequence[str] = ("front", "back"),
    up: str | None = None,
    max_faces: int = DEFAULT_MAX_FACES,
) -> Figure:
    """A shape coloured by ring size r (one bin per r from ``r_min`` to ``r_max``).

    One labelled panel per view (see :func:`arapkit.mesh.orientation.view_frame`); colours as
    everywhere else (:data:`arapkit.plots.colors.RING_COLORS`).

    Examples
    --------
    >>> from arapkit.mesh.shapes import bar
    >>> m = bar()
    >>> fig = rings_figure(m.vertices, m.faces, [3] * m.n_vertices)
    >>> [a.get_title() for a in fig.axes[:2]]
    ['front view (up +z)', 'back view (up +z)']
    """
    levels = np.arange(r_min, r_max + 1)
    cmap, norm, _ = rings_colormap(levels, levels)
    # at least 8 inches wide: the title (file name, counts, omega) must fit one view too
    width = max(5.0 * len(views), 8.0)
    fig = new_figure(figsize=(width, 3.8), layout="constrained")
    axes = fig.subplots(1, len(views), squeeze=False)
    values = np.asarray(rings, dtype=np.float64)
    for ax, view in zip(axes[0], views, strict=True):
        basis, used_up = view_frame(vertices, view, up)
        render_mesh(ax, vertices, faces, values, basis=basis, cmap=cmap, norm=norm,
                    max_faces=max_faces)
        ax.set_title(f"{view} view (up {used_up})", fontsize=9)
    colorbar(fig, list(axes[0]), norm, cmap, "learned ring size r (1 soft ... 6+ rigid)")
    if title:
        fig.suptitle(title, fontsize=10)
    return fig


def groups_figure(
    vertices: np.ndarray,
    faces: np.ndarray,
    groups: Sequence[tuple[str, np.ndarray]],
    *,
    title: str | None = None,
    view: str = "front",
    up: str | None = None,
    max_faces: int = DEFAULT_MAX_FACES,
) -> Figure:
    """The rest shape with each handle group's faces in its own colour (``--dry-run``).

    Parameters
    ----------
    groups : list of (label, vertex indices)
        Faces touching a group's vertices take its colour (later groups win).

    Examples
    --------
    >>> from arapkit.mesh.shapes import bar
    >>> m = bar()
    >>> fig = groups_figure(m.vertices, m.faces, [("left", [0, 1]), ("right", [5])])
    >>> len(fig.axes)
    1
    """
    palette = colormap("tab10").colors
    labels = np.zeros(len(vertices))
    for k, (_, idx) in enumerate(groups):
        labels[np.asarray(idx, dtype=np.int64)] = k + 1
    colours = [REST_COLOR] + [palette[k % 10] for k in range(len(groups))]
    cmap = ListedColormap(colours)
    norm = BoundaryNorm(np.arange(len(colours) + 1) - 0.5, len(colours))
    fig = new_figure(figsize=(6.0, 4.6), dpi=110, layout="constrained")
    ax = fig.subplots()
    basis, used_up = view_frame(vertices, view, up)
    render_mesh(ax, vertices, faces, labels, basis=basis, cmap=cmap, norm=norm,
                max_faces=max_faces, reduce="max")
    ax.legend(handles=[Patch(color=colours[k + 1], label=f"{name} ({len(idx)})")
                       for k, (name, idx) in enumerate(groups)],
              loc="center left", bbox_to_anchor=(1.0, 0.5), fontsize=7, frameon=False)
    ax.set_title(title or f"handle groups on the rest shape ({view} view, up {used_up})",
                 fontsize=9)
    return fig


def save_figure(fig: Figure, path: str | os.PathLike, dpi: int | None = None) -> None:
    """Save ``fig`` atomically (format from the extension: png, pdf, svg ...) and close it.

    The figures of this module are not pyplot's, so there is nothing to close; a figure the
    caller made with pyplot is closed there, so that a loop of figures does not pile up.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "f.png"
    >>> save_figure(energy_curves_figure({"a": [2.0, 1.0]}), p)
    >>> p.read_bytes()[:4]
    b'\\x89PNG'
    """
    try:
        fmt = check_figure_format(path)
    except InputError:
        _release(fig)
        raise
    try:
        with atomic_open(path, "wb") as f:
            fig.savefig(f, format=fmt, dpi=dpi)
    finally:
        _release(fig)


def _release(fig: Figure) -> None:
    # never import pyplot here: without it loaded, no figure can be registered with it
    pyplot = sys.modules.get("matplotlib.pyplot")
    if pyplot is not None:
        pyplot.close(fig)
