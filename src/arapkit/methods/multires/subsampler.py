"""The proxy of a large point cloud: a voxel-grid subsample, each point's home in it.

A cloud has no faces to collapse, so its coarse copy keeps one real point per occupied
cell of a uniform grid, the one nearest the cell's centroid, with the cell size found (by
bisection on a log scale) that leaves about ``n_target`` occupied cells. Every point's
home is its cell's kept point, so the binding's rotation-aware skinning
(:class:`~arapkit.methods.multires.binding.Binding`) lets each point follow the kept
point of its own cell and that one's graph neighbours. The subsample has the full cloud's
graph rule (k nearest neighbours; a radius graph's proxy takes the default k, since its
spacing is the grid's). Deterministic, and fast: about 20 grid passes (``np.unique`` of
the cell keys), 0.3 s at 400K points.

Examples
--------
>>> import numpy as np
>>> from arapkit.mesh.cloud import PointCloud
>>> c = PointCloud(np.random.default_rng(0).random((3000, 3)) * [4, 1, 0.01])
>>> p, home = subsample(c, 500)
>>> 400 <= p.n_vertices <= 600 and home.shape == (3000,) and int(home.max()) == p.n_vertices - 1
True
"""

from __future__ import annotations

import numpy as np

from ...mesh.cloud import PointCloud
from ...mesh.neighbours import DEFAULT_NEIGHBOURS
from ...validate import integer
from .coarsening import Coarsening, register_coarsening

__all__ = ["cell_size", "subsample", "voxel_cells"]

#: the bisection's passes over the grid size (a factor of 2^(-steps) of the bracket)
_STEPS = 24


def voxel_cells(P: np.ndarray, size: float) -> tuple[np.ndarray, np.ndarray]:
    """The occupied cells of a grid of ``size`` over ``P``: each point's cell number (0..c-1,
    in the order of the cells' keys) and the number of cells.

    Examples
    --------
    >>> cells, count = voxel_cells(np.array([[0.0, 0, 0], [0.1, 0, 0], [2, 0, 0]]), 1.0)
    >>> cells.tolist(), count
    ([0, 0, 1], 2)
    """
    lo = P.min(axis=0)
    idx = np.floor((P - lo) / size).astype(np.int64)
    dims = idx.max(axis=0) + 1
    key = (idx[:, 0] * dims[1] + idx[:, 1]) * dims[2] + idx[:, 2]
    _, cells = np.unique(key, return_inverse=True)
    return cells.ravel(), int(cells.max()) + 1 if len(cells) else 0


def cell_size(P: np.ndarray, n_target: int) -> float:
    """A grid size with about ``n_target`` occupied cells (bisection on a log scale).

    Examples
    --------
    >>> P = np.random.default_rng(0).random((5000, 3))
    >>> 900 <= voxel_cells(P, cell_size(P, 1000))[1] <= 1100
    True
    """
    extent = float(np.max(np.ptp(P, axis=0)))
    lo, hi = extent * 1e-6, extent * 2.0  # hi: one cell; lo: (nearly) a cell per point
    for _ in range(_STEPS):
        mid = np.sqrt(lo * hi)
        count = voxel_cells(P, mid)[1]
        if count > n_target:
            lo = mid
        else:
            hi = mid
        if abs(count - n_target) <= 0.02 * n_target:
            return mid
    return hi


def subsample(cloud: PointCloud, n_target: int) -> tuple[PointCloud, np.ndarray]:
    """A subsample of about ``n_target`` points and each point's home in it (see the
    module's docstring); the cloud itself where it has at most twice ``n_target`` points.

    Examples
    --------
    >>> c = PointCloud(np.random.default_rng(1).random((100, 3)))
    >>> p, home = subsample(c, 100)
    >>> p is c, home[:3].tolist()
    (True, [0, 1, 2])
    """
    n_target = integer(n_target, "proxy_vertices", lo=100)
    n = cloud.n_vertices
    if n <= 2 * n_target:
        return cloud, np.arange(n, dtype=np.int32)
    P = np.asarray(cloud.points, dtype=np.float64)
    cells, count = voxel_cells(P, cell_size(P, n_target))
    # the kept point of a cell: the one nearest the cell's centroid (ties: the lowest index)
    centroid = np.zeros((count, 3))
    np.add.at(centroid, cells, P)
    centroid /= np.bincount(cells, minlength=count)[:, None]
    d = np.linalg.norm(P - centroid[cells], axis=1)
    order = np.lexsort((np.arange(n), d, cells))
    first = np.ones(n, dtype=bool)
    first[1:] = cells[order[1:]] != cells[order[:-1]]
    keep = np.sort(order[first])  # in the cloud's order
    rank = np.empty(count, dtype=np.int32)
    rank[cells[keep]] = np.arange(len(keep), dtype=np.int32)
    proxy = PointCloud(P[keep], name=f"{cloud.name} proxy",
                       neighbours=cloud.neighbours or DEFAULT_NEIGHBOURS)
    return proxy, rank[cells]


register_coarsening("cloud", Coarsening("subsample", subsample, lambda cloud, n: False,
                                        lambda cloud, n: None))
