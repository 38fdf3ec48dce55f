"""A triangle mesh of the shape in an image: its outline, its holes and interior points.

The shape is the image's opaque part (alpha above a threshold) or, for an image without
alpha, every pixel away from a key colour (:func:`shape_mask`). :func:`mesh_mask` meshes a
mask:

1. the outlines (outer and holes) are the mask's 0.5 iso-lines (scikit-image's marching
   squares), resampled at the mesh's spacing ``h``;
2. interior points on a triangular lattice of spacing ``h``, kept at least ``h / 2`` inside
   the outline (shapely's vectorised point-in-polygon);
3. a constrained Delaunay triangulation of both with the outlines as fixed edges, the
   outside and the holes removed (PythonCDT).

Pins given to the mesher become vertices, so a pin sits exactly where it was put. The mask
is grown by two pixels first, so that the mesh covers every pixel that is not fully
transparent (the picture's own soft edge is then drawn by sampling, not cut by the mesh).

Licences of the ``image`` extra: scikit-image and shapely BSD-3-Clause, PythonCDT MPL-2.0
(file-level copyleft, fine to depend on), Pillow MIT-CMU. Shewchuk's ``triangle`` is not
used (its licence forbids commercial use).

Examples
--------
>>> import numpy as np
>>> yy, xx = np.mgrid[:64, :64]
>>> ring = (np.hypot(xx - 32, yy - 32) < 28) & (np.hypot(xx - 32, yy - 32) > 10)
>>> m = mesh_mask(ring, spacing=6.0)
>>> m.n_components, len(m.boundary_loops)  # one part, an outline and a hole
(1, 2)
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import InputError, require_extra
from ..mesh.model import Mesh

__all__ = ["DEFAULT_CELLS", "MAX_VERTICES", "default_spacing", "mesh_mask", "shape_mask"]

#: the default spacing is the shape's longer side over this many cells
DEFAULT_CELLS = 40
#: the most vertices a density may ask for (memory and time stay bounded)
MAX_VERTICES = 2_000_000


def shape_mask(rgba: np.ndarray, *, alpha_threshold: int = 0, key=None, key_tol: float = 32.0,
               name: str = "image") -> np.ndarray:
    """The shape's pixels: alpha above ``alpha_threshold``, or, with a ``key`` colour
    (RGB) or for an image without any transparency, every pixel farther than ``key_tol``
    (RGB distance) from the key (default: the colour of the top-left corner).

    Examples
    --------
    >>> img = np.zeros((4, 4, 4), np.uint8); img[1:3, 1:3] = 255
    >>> int(shape_mask(img).sum())
    4
    """
    a = rgba[..., 3]
    if key is None and (a < 255).any():
        mask = a > alpha_threshold
    else:
        k = np.asarray(rgba[0, 0, :3] if key is None else key, dtype=np.float64)
        mask = np.linalg.norm(rgba[..., :3].astype(np.float64) - k, axis=-1) > key_tol
    if not mask.any():
        raise InputError(f"{name}: no opaque pixels (nothing to mesh: the image is fully "
                         "transparent or all of the key colour)")
    return mask


def default_spacing(mask: np.ndarray) -> float:
    """The longer side of the shape's bounding box over :data:`DEFAULT_CELLS`, at least 3
    pixels.

    Examples
    --------
    >>> m = np.zeros((100, 400), bool); m[10:90, 20:380] = True
    >>> default_spacing(m)
    9.0
    """
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    side = max(rows[-1] - rows[0] + 1, cols[-1] - cols[0] + 1)
    return max(3.0, float(side) / DEFAULT_CELLS)


def _resample(ring: np.ndarray, h: float) -> np.ndarray:
    """A closed polyline resampled at about spacing ``h`` by arc length (last point not
    repeated)."""
    seg = np.linalg.norm(np.diff(ring, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    n = max(3, int(round(s[-1] / h)))
    t = np.linspace(0.0, s[-1], n, endpoint=False)
    return np.stack([np.interp(t, s, ring[:, 0]), np.interp(t, s, ring[:, 1])], axis=1)


def _polygons(mask: np.ndarray, h: float):
    """Shapely polygons (outer rings with their holes) of the mask's 0.5 iso-lines, in
    pixel coordinates (x right, y down, pixel centres at half integers)."""
    from scipy.ndimage import binary_dilation
    from shapely import Polygon
    from skimage.measure import find_contours

    grown = binary_dilation(mask, iterations=2)
    padded = np.pad(grown, 1).astype(np.float32)
    rings = []
    for c in find_contours(padded, 0.5):
        xy = np.stack([c[:, 1] - 0.5, c[:, 0] - 0.5], axis=1)  # padded index -> pixels
        p = Polygon(xy)
        if p.area >= 0.5 * h * h / 4:  # specks smaller than a cell are dropped
            rings.append((p.area, xy))
    if not rings:
        return []
    rings.sort(key=lambda r: -r[0])
    polys = [Polygon(xy) for _, xy in rings]
    depth = [sum(q.contains(p.representative_point()) for q in polys[:i])
             for i, p in enumerate(polys)]
    out = []
    for i, p in enumerate(polys):
        if depth[i] % 2:
            continue
        holes = [j for j in range(i + 1, len(polys)) if depth[j] == depth[i] + 1
                 and p.contains(polys[j].representative_point())]
        out.append((rings[i][1], [rings[j][1] for j in holes]))
    return out


def _lattice(bounds, h: float) -> np.ndarray:
    """Points of a triangular lattice of spacing ``h`` over a bounding box."""
    x0, y0, x1, y1 = bounds
    dy = h * math.sqrt(3) / 2
    ys = np.arange(y0 + dy / 2, y1, dy)
    xs = np.arange(x0 + h / 2, x1, h)
    X = xs[None, :] + (np.arange(len(ys)) % 2)[:, None] * (h / 2)
    Y = np.broadcast_to(ys[:, None], X.shape)
    return np.stack([X.ravel(), Y.ravel()], axis=1)


def mesh_mask(mask: np.ndarray, spacing: float | None = None, pins=None,
              name: str = "image") -> Mesh:
    """Mesh the shape of a boolean mask (rows = y down, columns = x).

    Parameters
    ----------
    mask : (H, W) bool
    spacing : float, optional
        Edge length in pixels (default :func:`default_spacing`): the density.
    pins : (p, 2) float, optional
        Points (x, y in pixels) that must be vertices (pins), each inside the shape.
    name : str

    Returns
    -------
    Mesh
        Vertices ``(x, y, 0)`` in pixels; the pins are vertices ``0 .. p-1``, in order.
    """
    require_extra(["skimage", "shapely", "pythoncdt"], "image", "meshing an image")
    import pythoncdt as cdt
    from shapely import Polygon, contains_xy

    mask = np.asarray(mask, dtype=bool)
    if mask.ndim != 2 or not mask.any():
        raise InputError(f"{name}: no opaque pixels to mesh")
    h = default_spacing(mask) if spacing is None else float(spacing)
    if not math.isfinite(h) or h <= 0:
        raise InputError(f"density: the spacing must be a positive number of pixels, got "
                         f"{spacing}")
    h = max(h, 1.0)
    estimate = float(mask.sum()) / (0.866 * h * h)
    if estimate > MAX_VERTICES:
        raise InputError(f"density: {h:g} px would give about {estimate:,.0f} vertices (at "
                         f"most {MAX_VERTICES:,}); use a coarser density")
    parts = _polygons(mask, h)
    if not parts:
        raise InputError(f"{name}: the shape is smaller than one mesh cell ({h:g} px); "
                         "use a finer density")
    P = np.zeros((0, 2)) if pins is None else np.asarray(pins, dtype=np.float64).reshape(-1, 2)
    points, edges = [P], []
    n = len(P)
    shapes = [Polygon(outer, holes) for outer, holes in parts]
    for outer, holes in parts:
        for ring in [outer, *holes]:
            r = _resample(ring, h)
            k = len(r)
            idx = n + np.arange(k)
            edges.append(np.stack([idx, np.roll(idx, -1)], axis=1))
            points.append(r)
            n += k
    inside_any = np.zeros(len(P), dtype=bool)
    for s in shapes:
        inside_any |= contains_xy(s, P[:, 0], P[:, 1]) if len(P) else inside_any
    if len(P) and not inside_any.all():
        bad = int(np.flatnonzero(~inside_any)[0])
        raise InputError(f"pin {bad} at ({P[bad, 0]:g}, {P[bad, 1]:g}) is outside the "
                         f"shape of {name}")
    for s in shapes:
        core = s.buffer(-0.5 * h)
        if core.is_empty:
            continue
        L = _lattice(s.bounds, h)
        L = L[contains_xy(core, L[:, 0], L[:, 1])]
        if len(P):  # no lattice point on top of a pin
            d = np.min(np.linalg.norm(L[:, None, :] - P[None], axis=2), axis=1)
            L = L[d > 0.5 * h]
        points.append(L)
    V = np.ascontiguousarray(np.concatenate(points))
    E = np.ascontiguousarray(np.concatenate(edges).astype(np.uint32))
    t = cdt.Triangulation(cdt.VertexInsertionOrder.AS_PROVIDED,
                          cdt.IntersectingConstraintEdges.TRY_RESOLVE, 0.0)
    t.insert_vertices(V)
    t.insert_edges(E)
    t.erase_outer_triangles_and_holes()
    va = t.vertices_array()
    F = np.asarray(t.triangles_array()["vertices"], dtype=np.int64)
    W = np.stack([va["x"], va["y"], np.zeros(len(va))], axis=1)
    used = np.zeros(len(W), dtype=bool)
    used[F.ravel()] = True
    used[:len(P)] = True  # pins keep their numbers
    if not used.all():  # outline points the triangulation left unused (specks): renumber
        new = np.cumsum(used) - 1
        W, F = W[used], new[F]
    return Mesh(W, F, name=name)
