"""The renderer under arapkit's figures: flat-shaded meshes and point clouds (splats) on a
Matplotlib axes, no pyplot.

Meshes are drawn as flat-shaded 2-D polygons in an orthographic view, sorted back to
front (painter's algorithm), which is much faster than ``mplot3d`` and looks the same for
the closed and open surfaces arapkit deforms. Meshes with more faces than ``max_faces`` are
first simplified by vertex clustering on a regular grid, so a 100K- or 1M-face mesh draws in
about the time of a ``max_faces`` one.

Figures are :class:`matplotlib.figure.Figure` objects drawn by the Agg canvas
(:func:`new_figure`): nothing here imports ``matplotlib.pyplot`` or calls
``matplotlib.use``, so importing arapkit's figures never changes the backend of a notebook or
an application, and a figure is never registered with pyplot (nothing to close, no leak).

Examples
--------
>>> import numpy as np
>>> fig = new_figure(figsize=(3, 3))
>>> ax = fig.subplots()
>>> V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]); F = np.array([[0, 1, 2]])
>>> render_mesh(ax, V, F, np.array([0.0, 1, 2])).vmax > 0
True
"""

from __future__ import annotations

from collections.abc import Sequence

from ..errors import require_extra
from ..mesh.orientation import view_frame
from .colors import ENERGY_CMAP, ring_rgb

# one line naming the extra instead of a bare "No module named 'matplotlib'"
require_extra("matplotlib", "plots", "arapkit.plots")

import matplotlib  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.axes import Axes  # noqa: E402
from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: E402
from matplotlib.cm import ScalarMappable  # noqa: E402
from matplotlib.collections import PolyCollection  # noqa: E402
from matplotlib.colors import BoundaryNorm, Colormap, ListedColormap, Normalize  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.ticker import FuncFormatter, MaxNLocator  # noqa: E402

__all__ = [
    "DEFAULT_MAX_FACES",
    "FIXED_COLOR",
    "MOVED_COLOR",
    "REST_COLOR",
    "cluster_points",
    "cluster_simplify",
    "colorbar",
    "colormap",
    "frame",
    "mark",
    "new_figure",
    "render_mesh",
    "render_points",
    "rings_colormap",
    "value_norm",
    "view_basis",
]

#: Faces drawn per panel before the mesh is simplified for display.
DEFAULT_MAX_FACES = 40_000
#: Colours of the rest shape and of fixed and moved handles, in every figure.
REST_COLOR = np.array([0.78, 0.80, 0.84])
FIXED_COLOR = np.array([0.15, 0.15, 0.35])
MOVED_COLOR = np.array([0.85, 0.15, 0.10])
# mark() draws every k-th point, k chosen for about this many dots: more would hide the mesh
_MAX_MARKERS = 2_000


def new_figure(**kwargs) -> Figure:
    """A figure drawn by the Agg canvas, outside pyplot (``kwargs`` go to :class:`Figure`).

    Examples
    --------
    >>> fig = new_figure(figsize=(2, 1), dpi=50)
    >>> type(fig.canvas).__name__, fig.get_size_inches().tolist()
    ('FigureCanvasAgg', [2.0, 1.0])
    """
    fig = Figure(**kwargs)
    FigureCanvasAgg(fig)  # attaches itself: savefig then needs no backend
    return fig


def colormap(cmap: str | Colormap) -> Colormap:
    """The colour map named ``cmap`` (a :class:`Colormap` is returned as is).

    Examples
    --------
    >>> colormap("YlOrRd").name
    'YlOrRd'
    """
    return matplotlib.colormaps[cmap] if isinstance(cmap, str) else cmap


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
    ax: Axes,
    vertices: np.ndarray,
    faces: np.ndarray | None,
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
    vertices : (n, 3), faces : (m, 3) or None
        None: a point cloud, drawn by :func:`render_points` (``max_faces`` points at most).
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
    >>> import numpy as np
    >>> ax = new_figure().subplots()
    >>> V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]); F = np.array([[0, 1, 2]])
    >>> render_mesh(ax, V, F, np.array([0.0, 1, 2])).vmax > 0
    True
    """
    if faces is None:  # a point cloud: points drawn as splats
        return render_points(ax, vertices, values, basis=basis, cmap=cmap, norm=norm,
                             max_points=max_faces, color=color, reduce=reduce)
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
        rgb = colormap(cmap)(norm(fv))[:, :3]
    else:
        rgb = np.tile(np.asarray(color if color is not None else REST_COLOR), (len(F), 1))
    rgb = np.clip(rgb * shade[:, None], 0.0, 1.0)
    order = np.argsort(tri[:, :, 2].mean(axis=1), kind="stable")  # back to front
    coll = PolyCollection(
        tri[order, :, :2], facecolors=rgb[order], edgecolors="none", antialiased=False
    )
    ax.add_collection(coll)
    frame(ax, P[:, :2])
    return norm


def cluster_points(points: np.ndarray, max_points: int, values: np.ndarray | None = None,
                   reduce: str = "mean") -> tuple[np.ndarray, np.ndarray | None]:
    """At most ``max_points`` points for display: the centroids of the occupied cells of a
    regular grid (refined as :func:`cluster_simplify`'s), each with the mean (or, with
    ``reduce="max"``, the largest) of its points' values.

    Examples
    --------
    >>> P = np.random.default_rng(0).random((5000, 3))
    >>> Q, v = cluster_points(P, 500, np.arange(5000.0), "max")
    >>> len(Q) <= 500 and float(v.max()) == 4999.0
    True
    """
    P = np.asarray(points, dtype=np.float64)
    if len(P) <= max_points:
        return P, None if values is None else np.asarray(values, np.float64)
    lo, span = P.min(0), np.maximum(np.ptp(P, 0), 1e-300)
    g = max(int(max_points ** (1 / 2)), 2)
    while True:
        cell = np.minimum((((P - lo) / span) * g).astype(np.int64), g - 1)
        key = (cell[:, 0] * g + cell[:, 1]) * g + cell[:, 2]
        uniq, label = np.unique(key, return_inverse=True)
        if len(uniq) <= max_points or g <= 2:
            break
        g = max(int(g * np.sqrt(max_points / len(uniq)) * 0.95), 2)
    label = label.ravel()
    count = np.bincount(label, minlength=len(uniq)).astype(np.float64)
    Q = np.stack([np.bincount(label, P[:, k], len(uniq)) for k in range(3)], 1) / count[:, None]
    if values is None:
        return Q, None
    v = np.asarray(values, np.float64)
    if reduce == "max":
        out = np.full(len(uniq), -np.inf)
        np.maximum.at(out, label, v)
        return Q, out
    return Q, np.bincount(label, v, len(uniq)) / count


def render_points(
    ax: Axes,
    points: np.ndarray,
    values: np.ndarray | None = None,
    *,
    basis: np.ndarray | None = None,
    cmap: str | Colormap = ENERGY_CMAP,
    norm: Normalize | None = None,
    max_points: int = DEFAULT_MAX_FACES,
    color: Sequence[float] | None = None,
    reduce: str = "mean",
) -> Normalize | None:
    """Draw a point cloud into ``ax`` as round splats, back to front, optionally coloured by
    per-point ``values`` (as :func:`render_mesh`); nearer points are drawn lighter.

    Clouds of more than ``max_points`` points are drawn as their grid clusters
    (:func:`cluster_points`); the splat size follows the points' count.

    Examples
    --------
    >>> ax = new_figure().subplots()
    >>> render_points(ax, np.random.default_rng(0).random((100, 3)), np.arange(100.0)).vmax > 0
    True
    """
    Q, vals = cluster_points(points, max_points, values, reduce)
    B = view_frame(Q)[0] if basis is None else np.asarray(basis)
    S = Q @ B.T  # screen x, screen y, depth (towards viewer)
    depth = S[:, 2]
    span = float(np.ptp(depth)) if len(depth) > 1 else 0.0
    # depth cue: the far side darker, as the mesh's shading would show it
    shade = 0.55 + 0.45 * ((depth - depth.min()) / span if span > 0 else np.ones(len(S)))
    if vals is not None:
        if norm is None:
            norm = value_norm([vals])
        rgb = colormap(cmap)(norm(vals))[:, :3]
    else:
        rgb = np.tile(np.asarray(color if color is not None else REST_COLOR), (len(S), 1))
    rgb = np.clip(rgb * shade[:, None], 0.0, 1.0)
    order = np.argsort(depth, kind="stable")  # back to front
    size = float(np.clip(6e4 / max(len(S), 1), 0.3, 30.0))
    ax.scatter(S[order, 0], S[order, 1], s=size, c=rgb[order], marker="o", linewidths=0)
    frame(ax, S[:, :2])
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


def frame(ax: Axes, xy: np.ndarray) -> None:
    """Fit ``ax`` to the screen points ``xy`` with a small margin, equal scales, no axes.

    Examples
    --------
    >>> ax = new_figure().subplots()
    >>> frame(ax, np.array([[0.0, 0.0], [2.0, 1.0]]))
    >>> [float(x) for x in ax.get_xlim()]  # 4 % of the larger extent on each side
    [-0.08, 2.08]
    """
    lo, hi = xy.min(0), xy.max(0)
    pad = 0.04 * max(float(np.max(hi - lo)), 1e-12)
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.set_aspect("equal")
    ax.set_axis_off()


def mark(ax: Axes, points: np.ndarray, basis: np.ndarray, color, label: str) -> None:
    """Scatter (a deterministic subsample of) ``points`` on top of a rendered mesh.

    ``basis`` is the view basis the mesh was rendered with; ``label`` names the dots in a legend.

    Examples
    --------
    >>> ax = new_figure().subplots()
    >>> mark(ax, np.zeros((6000, 3)), np.eye(3), MOVED_COLOR, "moved")
    >>> len(ax.collections[0].get_offsets())  # every 3rd point
    2000
    """
    if len(points) == 0:
        return
    step = max(1, len(points) // _MAX_MARKERS)
    xy = np.asarray(points)[::step] @ basis[:2].T
    ax.scatter(xy[:, 0], xy[:, 1], s=6, color=color, edgecolors="none", label=label, zorder=3)


def colorbar(fig: Figure, ax, norm: Normalize, cmap, label: str) -> None:
    """A horizontal colour bar under ``ax`` (one axes or a list): r levels or a value scale.

    A :class:`BoundaryNorm` (from :func:`rings_colormap`) gets one labelled bin per level;
    any other scale gets four short ticks.

    Examples
    --------
    >>> fig = new_figure(); ax = fig.subplots()
    >>> colorbar(fig, ax, value_norm([np.arange(5.0)]), ENERGY_CMAP, "energy")
    >>> len(fig.axes)
    2
    """
    sm = ScalarMappable(norm=norm, cmap=cmap)
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
