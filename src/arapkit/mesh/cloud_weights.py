"""Edge weights of a point cloud's graph: a Gaussian of the distance, uniform, or the
point-cloud Laplacian's.

Every kind is positive, so eq. (1) is a sum of squares (E >= 0), the rest shape is an
exact minimum and the reduced system is positive definite for every r, as with the
meshes' ``cotan-clamped``.

Weight kinds (:data:`CLOUD_WEIGHT_KINDS`)
-----------------------------------------
* ``"gaussian"`` (the default, :data:`DEFAULT_CLOUD_WEIGHTS`):
  ``w_ij = exp(-|p_i - p_j|^2 / (2 s_i s_j))`` with ``s_i`` the mean length of point i's
  edges: a Gaussian of the distance whose width follows the local spacing, so a cloud
  that is denser in one place than another is weighted alike everywhere (one global width
  cut the sparse parts of CGAL's cow loose: 3.1 % of the diagonal from the mesh's result,
  against 0.46 % with the local width).
* ``"uniform"``: ``w_ij = 1``.
* ``"laplacian"``: the off-diagonal entries of the robust point-cloud Laplacian of Sharp
  & Crane 2020 (``robust-laplacian``, MIT: the cotangent weights of a tufted intrinsic
  Delaunay cover of local triangulations, built from the same ``k`` nearest points), read
  on the graph's edges; an edge the Laplacian does not link, or links with a weight below
  ``1e-3`` times the mean, gets that floor (as ``cotan-clamped`` does). Extra
  ``clouds``: ``pip install 'arapkit[clouds]'``.

Why the Gaussian is the default: a cloud sampled from a mesh should deform as the mesh does
under the same handles. On four meshes sampled uniformly by area, the Gaussian's and uniform
weights' RMS distances from the mesh's own result are within 6 % of each other (0.23-0.46 %
of the diagonal), the Laplacian's 1.8-2.5 times theirs on three of four; on the meshes' own,
unevenly dense vertex sets the Gaussian is up to 19 % closer than uniform weights (and the
Laplacian, which recovers their triangulation, closest). ``docs/clouds.md`` has the tables
and the command.

Examples
--------
>>> import numpy as np
>>> P = np.array([[0.0, 0, 0], [1, 0, 0], [3, 0, 0]])
>>> E = np.array([[0, 1], [1, 2]])
>>> np.round(graph_weights(P, E, "gaussian"), 4).tolist()  # spacings 1, 1.5, 2
[0.7165, 0.5134]
>>> graph_weights(P, E, "uniform").tolist()
[1.0, 1.0]
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError, require_extra
from .neighbours import DEFAULT_NEIGHBOURS, edge_lengths
from .weights import WEIGHT_KINDS

__all__ = ["CLAMP_FRACTION", "CLOUD_WEIGHT_KINDS", "DEFAULT_CLOUD_WEIGHTS", "graph_weights",
           "laplacian_weights", "point_spacing"]

CLOUD_WEIGHT_KINDS = ("gaussian", "uniform", "laplacian")
#: the weighting of a point cloud's graph unless the user names another
DEFAULT_CLOUD_WEIGHTS = "gaussian"
#: the floor of the Laplacian's weights, as a fraction of their mean (``cotan-clamped``'s)
CLAMP_FRACTION = 1e-3


def point_spacing(points: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Each point's mean edge length (0 for a point without edges).

    Examples
    --------
    >>> point_spacing(np.array([[0.0, 0, 0], [1, 0, 0], [3, 0, 0]]),
    ...               np.array([[0, 1], [1, 2]])).tolist()
    [1.0, 1.5, 2.0]
    """
    n = len(points)
    E = np.asarray(edges, dtype=np.int64)
    d = edge_lengths(points, E)
    total = np.bincount(E.ravel(), np.repeat(d, 2), n)
    count = np.bincount(E.ravel(), minlength=n)
    return total / np.maximum(count, 1)


def _gaussian(points: np.ndarray, edges: np.ndarray) -> np.ndarray:
    d = edge_lengths(points, edges)
    s = point_spacing(points, edges)
    width = 2.0 * s[edges[:, 0]] * s[edges[:, 1]]
    # an edge between coincident points (width 0) is as short as an edge can be: weight 1
    with np.errstate(divide="ignore", invalid="ignore"):
        w = np.where(width > 0, np.exp(-np.square(d) / np.where(width > 0, width, 1.0)), 1.0)
    # the shortest-lived weights are those of a far outlier's edges: exp(-50) and below
    # would drop them from the solve's matrix in double precision, leaving it singular
    return np.maximum(w, np.exp(-50.0))


def laplacian_weights(points: np.ndarray, edges: np.ndarray, k: int = DEFAULT_NEIGHBOURS,
                      name: str = "cloud") -> np.ndarray:
    """The robust point-cloud Laplacian's weights on ``edges`` (see the module docstring).

    Examples
    --------
    >>> P = np.random.default_rng(0).random((40, 3))
    >>> from arapkit.mesh.neighbours import knn_edges
    >>> E = knn_edges(P, 8)
    >>> bool((laplacian_weights(P, E, 8) > 0).all())  # doctest: +SKIP
    True
    """
    (rl,) = require_extra("robust_laplacian", "clouds", "weights='laplacian'")
    P = np.ascontiguousarray(points, dtype=np.float64)
    if len(P) < 3:
        raise InputError(f"{name}: weights='laplacian' needs at least 3 points")
    L = rl.point_cloud_laplacian(P, n_neighbors=max(int(k), 3))[0].tocsr()
    E = np.asarray(edges, dtype=np.int64)
    w = -np.asarray(L[E[:, 0], E[:, 1]]).ravel()
    w = np.where(np.isfinite(w), w, 0.0)
    positive = w[w > 0]
    floor = CLAMP_FRACTION * (positive.mean() if len(positive) else 1.0)
    return np.maximum(w, floor)


def graph_weights(points: np.ndarray, edges: np.ndarray, kind: str,
                  k: int = DEFAULT_NEIGHBOURS, name: str = "cloud") -> np.ndarray:
    """Weights of ``kind`` (one of :data:`CLOUD_WEIGHT_KINDS`) on a point cloud's edges.

    A kind of the triangle meshes (``cotan``, ``cotan-clamped`` ...) is refused in one
    line: it needs triangles.

    Examples
    --------
    >>> graph_weights(np.eye(3), np.array([[0, 1]]), "cotan-clamped", name="c.ply")
    Traceback (most recent call last):
    ...
    arapkit.errors.InputError: c.ply: weights 'cotan-clamped' need triangles; a point cloud ...
    """
    E = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    if kind == "uniform":
        return np.ones(len(E))
    if kind == "gaussian":
        return _gaussian(np.asarray(points, dtype=np.float64), E)
    if kind == "laplacian":
        return laplacian_weights(points, E, k, name)
    shown = kind if isinstance(kind, str) else type(kind).__name__
    need = " need triangles;" if kind in WEIGHT_KINDS else " are unknown;"
    raise InputError(f"{name}: weights '{shown}'{need} a point cloud takes "
                     f"{CLOUD_WEIGHT_KINDS[0]} (default), {CLOUD_WEIGHT_KINDS[1]} or "
                     f"{CLOUD_WEIGHT_KINDS[2]}")
