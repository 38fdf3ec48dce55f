"""Headless matplotlib figures: shaded meshes coloured by energy or rigidity, energy curves.

Meshes are drawn as flat-shaded 2-D polygons in an orthographic view, sorted back to
front (painter's algorithm), which is much faster than ``mplot3d`` and looks the same for
the closed and open surfaces arapkit deforms. Meshes with more faces than ``max_faces`` are
first simplified by vertex clustering on a regular grid, so a 100K- or 1M-face mesh draws in
about the time of a ``max_faces`` one.

Views are upright: the up axis is :func:`arapkit.mesh.orientation.guess_up`'s guess unless
``up`` is given, and ``view`` picks *front* (default), *side*, *top* or *iso* (see
:func:`arapkit.mesh.orientation.view_frame`). Colours: r always uses
:data:`arapkit.plots.colors.RING_COLORS` (1 blue ... 6+ red, as the editor), energy always
:data:`arapkit.plots.colors.ENERGY_CMAP` (pale at 0); panels that are compared share one scale.

Examples
--------
>>> import numpy as np
>>> from arapkit.plots.figures import energy_curves_figure
>>> fig = energy_curves_figure({"r = 1": [1.0, 0.5, 0.4]})
>>> len(fig.axes)
1
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence

import matplotlib

from arapkit.mesh.orientation import view_frame
from arapkit.plots.colors import ENERGY_CMAP, ring_rgb

matplotlib.use("Agg")  # headless: never needs a display

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import PolyCollection  # noqa: E402
from matplotlib.colors import BoundaryNorm, Colormap, ListedColormap, Normalize  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.ticker import FuncFormatter, MaxNLocator  # noqa: E402

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

#: Faces drawn per panel before the mesh is simplified for display.
DEFAULT_MAX_FACES = 40_000
_MAX_MARKERS = 2_000
_REST_COLOR = np.array([0.78, 0.80, 0.84])
_FIXED_COLOR = np.array([0.15, 0.15, 0.35])
_MOVED_COLOR = np.array([0.85, 0.15, 0.10])
_FEW_HANDLES = 100


# --------------------------------------------------------------------------- view and shading


def _principal_axes(points: np.ndarray) -> np.ndarray:
    """Rows: principal directions of ``points``, largest spread first, with fixed signs."""
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    C = np.cov((P - P.mean(0)).T) if len(P) > 1 else np.eye(3)
    _, vecs = np.linalg.eigh(C)  # ascending eigenvalues
    axes = vecs[:, ::-1].T.copy()
    for k in range(3):
        # eigenvector signs are arbitrary: fix them so repeated calls agree
        if axes[k][np.argmax(np.abs(axes[k]))] < 0:
            axes[k] = -axes[k]
    return axes


def view_basis(
    points: np.ndarray,
    elev: float = 20.0,
    azim: float = -30.0,
    right: np.ndarray | None = None,
) -> np.ndarray:
    """Orthonormal view basis (rows: screen right, screen up, towards the viewer).

    The viewer looks along the direction of least spread of ``points`` (so a bent bar is
    seen face-on), with ``right`` (default: the longest direction of ``points``) horizontal,
    then the view is tilted by ``elev`` and ``azim`` degrees so that depth stays readable.

    Parameters
    ----------
    points : (n, 3)
        All shapes that will be drawn with this basis.
    elev, azim : float
        Tilt about the screen's horizontal and vertical axes, in degrees.
    right : (3,), optional
        Direction to show horizontally, e.g. the long axis of the rest shape.

    Examples
    --------
    >>> import numpy as np
    >>> B = view_basis(np.random.default_rng(0).normal(size=(50, 3)) * [5, 2, 0.1], 0, 0)
    >>> np.round(np.abs(B[2]), 2).tolist()  # looks along z, the thinnest direction
    [0.0, 0.0, 1.0]
    """
    axes = _principal_axes(points)
    towards = axes[2]
    if right is not None:
        r = np.asarray(right, dtype=np.float64)
        r = r - (r @ towards) * towards
        if np.linalg.norm(r) > 1e-9 * max(np.linalg.norm(right), 1e-300):
            axes[0] = r / np.linalg.norm(r)
    B = np.stack([axes[0], np.cross(towards, axes[0]), towards])
    a, e = np.radians(azim), np.radians(elev)
    Ry = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    Rx = np.array([[1, 0, 0], [0, np.cos(e), -np.sin(e)], [0, np.sin(e), np.cos(e)]])
    return Rx @ Ry @ B


def cluster_simplify(
    vertices: np.ndarray,
    faces: np.ndarray,
    max_faces: int,
    values: np.ndarray | None = None,
    reduce: str = "mean",
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Simplify a mesh for display by merging the vertices in each cell of a regular grid.

    The grid is refined until the simplified mesh has at most ``max_faces`` faces; per-vertex
    ``values`` are averaged over each cell (``reduce="mean"``) or take the cell's largest
    value (``reduce="max"``, for labels that must not vanish). Meshes already small enough are
    returned as is.

    Returns
    -------
    vertices, faces, values

    Examples
    --------
    >>> import numpy as np
    >>> from arapkit.plots.figures import cluster_simplify
    >>> V = np.random.default_rng(1).random((3000, 3)); F = np.arange(3000).reshape(-1, 3)
    >>> len(cluster_simplify(V, F, 300)[1]) <= 300
    True
    """
    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(faces, dtype=np.int64)
    if len(F) <= max_faces:
        return V, F, values
    lo, span = V.min(0), np.ptp(V, axis=0).max() or 1.0
    # a surface with g cells per side occupies roughly g^2 cells, each giving ~2 triangles
    g = max(int(np.sqrt(max_faces / 2.0)), 2)
    while True:
        cell = np.floor((V - lo) / span * (g - 1e-9)).astype(np.int64)
        key = (cell[:, 0] * g + cell[:, 1]) * g + cell[:, 2]
        uniq, label = np.unique(key, return_inverse=True)
        G = label[F]
        keep = (G[:, 0] != G[:, 1]) & (G[:, 1] != G[:, 2]) & (G[:, 0] != G[:, 2])
        G = G[keep]
        # drop faces that collapse onto the same three cells, whatever their orientation
        _, first = np.unique(np.sort(G, axis=1), axis=0, return_index=True)
        G = G[np.sort(first)]
        if len(G) <= max_faces or g <= 2:
            break
        g = max(int(g * np.sqrt(max_faces / len(G)) * 0.95), 2)
    count = np.bincount(label, minlength=len(uniq)).astype(np.float64)
    Vs = np.stack([np.bincount(label, V[:, k], len(uniq)) for k in range(3)], 1) / count[:, None]
    vals = None
    if values is not None and reduce == "max":
        vals = np.full(len(uniq), -np.inf)
        np.maximum.at(vals, label, np.asarray(values, float))
    elif values is not None:
        vals = np.bincount(label, np.asarray(values, float), len(uniq)) / count
    return Vs, G, vals


def render_mesh(
    ax: plt.Axes,
    vertices: np.ndarray,
    faces: np.ndarray,
    values: np.ndarray | None = None,
    *,
    basis: np.ndarray | None = None,
    cmap: str | Colormap = ENERGY_CMAP,
    norm: Normalize | None = None,
    max_faces: int = DEFAULT_MAX_FACES,
    color: Sequence[float] | None = None,
    reduce: str = "mean",
) -> Normalize | None:
    """Draw a flat-shaded mesh into ``ax``, optionally coloured by per-vertex ``values``.

    Parameters
    ----------
    ax : matplotlib Axes (2-D)
    vertices : (n, 3), faces : (m, 3)
    values : (n,) float, optional
        Per-vertex scalar; each face takes the mean of its corners.
    basis : (3, 3), optional
        View basis from :func:`arapkit.mesh.orientation.view_frame` (default: its upright front
        view of ``vertices``). Pass the same basis to several panels to compare shapes.
    cmap, norm : colour map and normalisation for ``values``; ``norm`` defaults to
        ``[0, 99th percentile]`` so a few extreme faces do not wash out the rest.
    max_faces : int
        Larger meshes are simplified with :func:`cluster_simplify` first.
    color : RGB, optional
        Uniform colour when ``values`` is None.
    reduce : {"mean", "max"}
        How a face (and a display-simplification cell) combines its corners' values; "max"
        suits labels such as "is a handle".

    Returns
    -------
    The normalisation used (None without values), for a colour bar.

    Examples
    --------
    >>> import numpy as np, matplotlib.pyplot as plt
    >>> fig, ax = plt.subplots()
    >>> V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]); F = np.array([[0, 1, 2]])
    >>> render_mesh(ax, V, F, np.array([0.0, 1, 2])).vmax > 0
    True
    """
    V, F, vals = cluster_simplify(vertices, faces, max_faces, values, reduce)
    B = view_frame(V)[0] if basis is None else np.asarray(basis)
    P = V @ B.T  # screen x, screen y, depth (towards viewer)
    tri = P[F]
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    lengths = np.linalg.norm(normals, axis=1)
    # two-sided headlight shading: open surfaces show their back faces too
    shade = 0.35 + 0.65 * np.abs(normals[:, 2]) / np.where(lengths > 0, lengths, 1.0)
    if vals is not None:
        corner = np.asarray(vals, dtype=np.float64)[F]
        fv = corner.max(axis=1) if reduce == "max" else corner.mean(axis=1)
        if norm is None:
            norm = value_norm([fv])
        rgb = plt.get_cmap(cmap)(norm(fv))[:, :3]
    else:
        rgb = np.tile(np.asarray(color if color is not None else _REST_COLOR), (len(F), 1))
    rgb = np.clip(rgb * shade[:, None], 0.0, 1.0)
    order = np.argsort(tri[:, :, 2].mean(axis=1), kind="stable")  # back to front
    coll = PolyCollection(
        tri[order, :, :2], facecolors=rgb[order], edgecolors="none", antialiased=False
    )
    ax.add_collection(coll)
    _frame(ax, P[:, :2])
    return norm


def value_norm(values: Sequence[np.ndarray]) -> Normalize:
    """One colour scale for several arrays: [min(0, lowest), 99th percentile of all].

    Examples
    --------
    >>> n = value_norm([np.zeros(999), np.ones(1) * 1e6])   # one spike does not set the scale
    >>> n.vmin, n.vmax
    (0.0, 1.0)
    """
    finite = np.concatenate([np.ravel(v) for v in values]).astype(np.float64)
    finite = finite[np.isfinite(finite)]
    hi = float(np.percentile(finite, 99)) if finite.size else 1.0
    lo = min(0.0, float(finite.min())) if finite.size else 0.0
    return Normalize(lo, hi if hi > lo else lo + 1.0)


def _frame(ax: plt.Axes, xy: np.ndarray) -> None:
    lo, hi = xy.min(0), xy.max(0)
    pad = 0.04 * max(float(np.max(hi - lo)), 1e-12)
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.set_aspect("equal")
    ax.set_axis_off()


def _mark(ax: plt.Axes, points: np.ndarray, basis: np.ndarray, color, label: str) -> None:
    """Scatter (a deterministic subsample of) ``points`` on top of a rendered mesh."""
    if len(points) == 0:
        return
    step = max(1, len(points) // _MAX_MARKERS)
    xy = np.asarray(points)[::step] @ basis[:2].T
    ax.scatter(xy[:, 0], xy[:, 1], s=6, color=color, edgecolors="none", label=label, zorder=3)


def _colorbar(fig: Figure, ax, norm: Normalize, cmap, label: str) -> None:
    sm = plt.cm.ScalarMappable(norm=norm, cmap=cmap)
    kwargs: dict = {}
    if isinstance(norm, BoundaryNorm):
        # discrete levels (r values): equal-width bins labelled at their centres
        b = np.asarray(norm.boundaries, dtype=np.float64)
        kwargs = {"spacing": "uniform", "ticks": (b[:-1] + b[1:]) / 2}
    cb = fig.colorbar(sm, ax=ax, orientation="horizontal", fraction=0.05, pad=0.02, **kwargs)
    if isinstance(norm, BoundaryNorm):
        # rings_colormap puts each level's lower bound at level - 0.5
        cb.set_ticklabels([f"{v + 0.5:g}" for v in norm.boundaries[:-1]])
    else:
        # few ticks: long labels such as 0.00025 would otherwise run into each other
        # and no "1e-5" offset text, which lands on the label
        cb.locator = MaxNLocator(nbins=4)
        cb.formatter = FuncFormatter(lambda v, _: f"{v:.3g}")
        cb.update_ticks()
    cb.set_label(label, fontsize=8)
    cb.ax.tick_params(labelsize=7)


def rings_colormap(
    rings: np.ndarray, levels: Sequence[int] | None = None
) -> tuple[Colormap, BoundaryNorm, np.ndarray]:
    """Discrete colour map for a rigidity map: one bin per r, coloured as everywhere else.

    Colours come from :data:`arapkit.plots.colors.RING_COLORS` (1 blue ... 6 and above red, the
    editor's colours), so r = 2 has the same colour in every figure.

    Parameters
    ----------
    rings : (n,) int
    levels : the r values to give a bin (default: the distinct values of ``rings``).

    Returns
    -------
    cmap, norm, levels

    Examples
    --------
    >>> import numpy as np
    >>> rings_colormap(np.array([2, 6, 6]))[2].tolist()
    [2, 6]
    """
    if levels is None:
        levels = np.unique(np.asarray(rings, dtype=np.int64))
    levels = np.asarray(levels, dtype=np.int64)
    bounds = np.concatenate([levels - 0.5, [levels[-1] + 0.5]])
    colors = np.concatenate([ring_rgb(levels) / 255.0, np.ones((len(levels), 1))], axis=1)
    return ListedColormap(colors), BoundaryNorm(bounds, len(levels)), levels


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
    fig = plt.figure(figsize=(4.0 * n_panels, 4.2), dpi=110, layout="constrained")
    axes = fig.subplots(1, n_panels, width_ratios=[1.0] * (n_panels - 1) + [0.9])
    basis = _camera(rest, view, up)

    # paint the faces around handles (occlusion-correct at any handle count); add markers
    # only for small handle sets, where single vertices would be too small to see
    labels = np.zeros(len(rest))
    labels[handles[fixed]] = 1.0
    labels[handles[~fixed]] = 2.0
    hcmap = ListedColormap([_REST_COLOR, _FIXED_COLOR, _MOVED_COLOR])
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
        _mark(axes[0], rest[handles[fixed]], basis, _FIXED_COLOR, "fixed")
        _mark(axes[0], rest[handles[~fixed]], basis, _MOVED_COLOR, "moved")
        _mark(axes[1], targets[~fixed], basis, _MOVED_COLOR, "targets")
    axes[0].set_title("rest shape and handles", fontsize=9)
    if len(handles):
        from matplotlib.patches import Patch

        kinds = [("fixed", _FIXED_COLOR, fixed.any()), ("moved", _MOVED_COLOR, (~fixed).any())]
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
    _colorbar(fig, axes[1], norm, ENERGY_CMAP, "per-vertex energy (clipped at 99th percentile)")

    if varying:
        cmap, rnorm, levels = rings_colormap(rings)
        render_mesh(
            axes[2], deformed, faces, rings, basis=basis, cmap=cmap, norm=rnorm, max_faces=max_faces
        )
        axes[2].set_title("deformed: rigidity r", fontsize=9)
        _colorbar(fig, axes[2], rnorm, cmap, "r (rings)")

    _energy_axes(axes[-1], {"": history})
    if title:
        fig.suptitle(title, fontsize=10)
    return fig


def _energy_axes(ax: plt.Axes, histories: Mapping[str, Sequence[float]]) -> None:
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
    fig, ax = plt.subplots(figsize=(5.0, 3.6), dpi=110, layout="constrained")
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
    fig, ax = plt.subplots(figsize=(4.6, 3.4), dpi=110, layout="constrained")
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
    fig = plt.figure(figsize=(3.0 * ncols, 3.3 * nrows), dpi=110, layout="constrained")
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
        _colorbar(fig, list(axes[: len(panels)]), norm, cmap, label)
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
    fig, axes = plt.subplots(1, len(views), figsize=(width, 3.8), squeeze=False,
                             layout="constrained")
    values = np.asarray(rings, dtype=np.float64)
    for ax, view in zip(axes[0], views, strict=True):
        basis, used_up = view_frame(vertices, view, up)
        render_mesh(ax, vertices, faces, values, basis=basis, cmap=cmap, norm=norm,
                    max_faces=max_faces)
        ax.set_title(f"{view} view (up {used_up})", fontsize=9)
    _colorbar(fig, list(axes[0]), norm, cmap, "learned ring size r (1 soft ... 6+ rigid)")
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
    from matplotlib.patches import Patch

    palette = plt.get_cmap("tab10").colors
    labels = np.zeros(len(vertices))
    for k, (_, idx) in enumerate(groups):
        labels[np.asarray(idx, dtype=np.int64)] = k + 1
    colours = [_REST_COLOR] + [palette[k % 10] for k in range(len(groups))]
    cmap = ListedColormap(colours)
    norm = BoundaryNorm(np.arange(len(colours) + 1) - 0.5, len(colours))
    fig, ax = plt.subplots(figsize=(6.0, 4.6), dpi=110, layout="constrained")
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

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "f.png"
    >>> save_figure(energy_curves_figure({"a": [2.0, 1.0]}), p)
    >>> p.read_bytes()[:4]
    b'\\x89PNG'
    """
    from arapkit.errors import InputError
    from arapkit.io import atomic_open, check_figure_format

    try:
        fmt = check_figure_format(path)
    except InputError:
        plt.close(fig)
        raise
    try:
        with atomic_open(path, "wb") as f:
            fig.savefig(f, format=fmt, dpi=dpi)
    finally:
        plt.close(fig)
