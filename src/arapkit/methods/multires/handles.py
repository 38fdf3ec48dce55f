"""What the full mesh's handles ask of a coarser mesh: their regions, the rigid motion each
region's targets make, and the coarse vertices that carry them.

A coarser mesh (the proxy, a level) poses the full mesh's problem at its own scale: its
handles are its vertices bound to a full handle (:func:`coarse_handles`), moved by the
rigid motion fitted to each connected handle region
(:func:`arapkit.arap.constraints.rigid_motions`; exact for the editor's rigid gizmo moves).

Examples
--------
>>> import numpy as np
>>> from arapkit.mesh.shapes import bar, bar_bend
>>> mesh = bar()
>>> h, t = bar_bend(mesh, 0)
>>> m = HandleMotions(mesh, h)
>>> bool(np.allclose(m.moved(t, mesh.vertices[h], m.region), t))
True
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ...arap.constraints import rigid_motions
from ...mesh.cloud import PointCloud
from ...mesh.model import Mesh
from .binding import Binding

__all__ = ["FIT_POINTS", "HandleMotions", "coarse_handles", "handle_regions", "region_sample"]

#: points per handle region that fit its rigid motion (a scan's region holds 10^5: fitting
#: them all cost 57 ms a move at 1.75M; a rigid motion is found exactly from any three)
FIT_POINTS = 2048


def handle_regions(mesh: Mesh | PointCloud, handles: np.ndarray) -> np.ndarray:
    """The connected region (of the handle vertices' own edges) of each handle."""
    pos = np.full(mesh.n_vertices, -1, dtype=np.int64)
    pos[handles] = np.arange(len(handles))
    # the edges of the faces with two or more handle corners (no sorted edge list built,
    # nothing the size of all the faces' edges), kept where both ends are handles; a
    # point cloud's graph edges as they are
    links = mesh.faces if mesh.faces is not None else mesh.edges
    P = pos[links]
    P = P[(P >= 0).sum(axis=1) >= 2]
    c = P.shape[1]
    pairs = np.concatenate([P[:, [i, (i + 1) % c]] for i in range(c if c > 2 else 1)])
    a, b = pairs[(pairs[:, 0] >= 0) & (pairs[:, 1] >= 0)].T
    n = len(handles)
    graph = coo_matrix((np.ones(len(a)), (a, b)), shape=(n, n))
    return connected_components(graph, directed=False)[1]


def region_sample(region: np.ndarray, most: int) -> np.ndarray:
    """Up to ``most`` evenly spaced members of each region (indices into ``region``)."""
    order = np.argsort(region, kind="stable")
    counts = np.bincount(region) if len(region) else np.zeros(0, np.int64)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
    picks = [order[a + np.unique(np.linspace(0, c - 1, min(c, most)).astype(np.int64))]
             for a, c in zip(starts, counts)]
    return np.sort(np.concatenate(picks)) if picks else np.zeros(0, np.int64)


def coarse_handles(binding: Binding, handles: np.ndarray, region: np.ndarray,
                   n_full: int) -> tuple[np.ndarray, np.ndarray]:
    """A coarser mesh's handles: its vertices bound to a full handle, with their regions.

    Those whose nearest full vertex is a handle, and the nearest of each handle vertex
    (so that a one-vertex handle is not lost); each takes the region of the handle it
    reads (``region``: the region of each row of ``handles``).

    Examples
    --------
    >>> import numpy as np
    >>> b = Binding.between(np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]]),
    ...                     np.array([[0.1, 0, 0], [2.1, 0, 0]]))
    >>> [a.tolist() for a in coarse_handles(b, np.array([2]), np.array([0]), 3)]
    [[1], [0]]
    """
    pos = np.full(n_full, -1, dtype=np.int64)
    pos[handles] = np.arange(len(handles))
    near = binding.near_full
    q1 = np.flatnonzero(pos[near] >= 0)
    own = np.arange(len(handles))
    covered = None if binding.covered is None else binding.covered[handles]
    if covered is not None and covered.any():
        # a handle on a speck would pin the nearest vertex of another part: the speck
        # follows its handle in the exact solve, the part stays free there
        own = own[covered]
    q = np.concatenate([q1, binding.idx[handles[own]]])
    src = np.concatenate([pos[near[q1]], own])
    picked, first = np.unique(q, return_index=True)
    return picked, region[src[first]]


class HandleMotions:
    """The handles of the full mesh, grouped in connected regions, and the rigid motion of
    each region fitted to its targets (kept for the last read-only target array: a drag
    passes one array chunk after chunk).

    Parameters
    ----------
    mesh : Mesh
        The full mesh.
    handles : (h,) int
        Its handle vertices (checked).

    Attributes
    ----------
    region : (h,) int64
        The connected region (of the handle vertices' own edges) of each handle.
    n_regions : int
    """

    def __init__(self, mesh: Mesh, handles: np.ndarray) -> None:
        self.rest = np.asarray(mesh.vertices, dtype=np.float64)[handles]
        self.region = handle_regions(mesh, handles)
        self.n_regions = int(self.region.max()) + 1 if len(handles) else 0
        self._fit = region_sample(self.region, FIT_POINTS)
        self._last: tuple[np.ndarray, tuple[np.ndarray, np.ndarray]] | None = None

    def moved(self, T: np.ndarray, Q: np.ndarray, region: np.ndarray) -> np.ndarray:
        """Rest points ``Q`` moved by the rigid motion fitted to each one's handle region
        (``region``: the region of each row of ``Q``) for the handles' targets ``T``."""
        last = self._last
        if last is not None and last[0] is T and not T.flags.writeable:
            R, t = last[1]
        else:
            fit = self._fit
            R, t = rigid_motions(self.rest[fit], T[fit], self.region[fit], self.n_regions)
            self._last = (T, (R, t))
        return np.einsum("vij,vj->vi", R[region], Q) + t[region]
