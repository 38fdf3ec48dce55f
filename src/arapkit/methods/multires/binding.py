"""How a full mesh follows a coarser one: the binding at rest and its skinning kernels.

Every full vertex ``v`` follows the coarse vertex it was collapsed into (its home) and
that one's nearest neighbours ``q`` on the coarse mesh, with inverse squared distance
weights: ``x_v = sum_q a_vq (y_q + R_q (v - q))``, ``R_q`` the coarse solution's fitted
rotation (:meth:`Binding.skin`). A rigid motion of the coarse mesh is then one of the full
mesh too.

Examples
--------
>>> import numpy as np
>>> b = Binding.between(np.array([[0.0, 0, 0], [1, 0, 0]]), np.array([[0.0, 0, 0]]))
>>> b.skin(np.array([[2.0, 0, 0]]), np.eye(3)[None]).tolist()
[[2.0, 0.0, 0.0], [3.0, 0.0, 0.0]]
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
from scipy.spatial import cKDTree

from ...mesh.model import Mesh

__all__ = ["SKIN_NEIGHBOURS", "Binding", "full_tree_of", "proxy_rings"]

#: proxy vertices each full vertex follows at most (inverse squared distance weights;
#: :class:`Binding`): with its one nearest, the cells' seams put the 437K scan's settled
#: preview 0.99 % of the diagonal from the exact result at its worst vertex, 0.65 % with four
SKIN_NEIGHBOURS = 4
#: nearest proxy vertices looked at for those, of which only the full vertex's home and
#: the home's neighbours on the proxy are taken
_CANDIDATES = 8
#: full vertices queried at once (the candidates' arrays: 16 bytes each per candidate)
_QUERY_ROWS = 1 << 18


@numba.njit(parallel=True, cache=True, nogil=True)
def _skin(Y, R, Q, V, near, wts, out):  # pragma: no cover - compiled
    for v in numba.prange(near.shape[0]):
        x0 = x1 = x2 = tot = 0.0
        for j in range(near.shape[1]):
            q = near[v, j]
            w = np.float64(wts[v, j])
            d0, d1, d2 = V[v, 0] - Q[q, 0], V[v, 1] - Q[q, 1], V[v, 2] - Q[q, 2]
            x0 += w * (Y[q, 0] + R[q, 0, 0] * d0 + R[q, 0, 1] * d1 + R[q, 0, 2] * d2)
            x1 += w * (Y[q, 1] + R[q, 1, 0] * d0 + R[q, 1, 1] * d1 + R[q, 1, 2] * d2)
            x2 += w * (Y[q, 2] + R[q, 2, 0] * d0 + R[q, 2, 1] * d1 + R[q, 2, 2] * d2)
            tot += w
        # normalised here, in double: a rigid motion of the proxy stays one to round-off
        out[v, 0] = x0 / tot
        out[v, 1] = x1 / tot
        out[v, 2] = x2 / tot


@numba.njit(parallel=True, cache=True, nogil=True)
def _pick(V, Q, cand, dist, home, adj_ptr, adj_idx, floor, near, wts):  # pragma: no cover
    """Up to ``near.shape[1]`` proxy vertices per full vertex, nearest first among those
    it may follow, with inverse squared distance weights (0 in unused slots).

    A vertex with a home follows the home and the home's neighbours on the proxy that are
    among its candidates; one without follows its nearest candidates. The weights are
    scaled in double to a largest of 1 before they are stored as float32.
    """
    k = near.shape[1]
    for v in numba.prange(cand.shape[0]):
        w = np.zeros(k)
        h = home[v]
        c = 0
        if h >= 0:
            d = np.sqrt((V[v, 0] - Q[h, 0]) ** 2 + (V[v, 1] - Q[h, 1]) ** 2
                        + (V[v, 2] - Q[h, 2]) ** 2)
            near[v, 0] = h
            w[0] = 1.0 / max(d, floor) ** 2
            c = 1
        for j in range(cand.shape[1]):
            if c == k:
                break
            q = cand[v, j]
            if h >= 0:
                if q == h:
                    continue
                found = False
                for t in range(adj_ptr[h], adj_ptr[h + 1]):
                    if adj_idx[t] == q:
                        found = True
                        break
                if not found:
                    continue
            near[v, c] = q
            w[c] = 1.0 / max(dist[v, j], floor) ** 2
            c += 1
        top = w.max()
        for j in range(c):
            wts[v, j] = w[j] / top
        for j in range(c, k):
            near[v, j] = near[v, 0]
            wts[v, j] = 0.0


def full_tree_of(full: np.ndarray) -> cKDTree:
    """The full mesh's k-d tree for :meth:`Binding.between` (unbalanced: it serves one
    query, and builds 2x faster)."""
    return cKDTree(full, balanced_tree=False)


@dataclass(frozen=True)
class Binding:
    """How the full mesh and its proxy correspond at rest.

    Attributes
    ----------
    idx : (n,) int64
        The nearest proxy vertex of each full vertex (a full handle pins it).
    near : (n, k) int32
        The proxy vertices each full vertex follows, which the skinning blends
        ``x_v = sum_q a_vq (y_q + R_q (v - q))``: its home (the proxy vertex it was collapsed
        into) first, then those of the home's neighbours on the proxy that are among the
        full vertex's nearest, up to :data:`SKIN_NEIGHBOURS` (the nearest, where it has no
        home). Bound by distance alone, a full vertex of a thin part followed the other side
        of a narrow gap: on the 1.75M dragon a region 260 edges away on the surface, 7.8 %
        of the diagonal from where the exact solve put it.
    weights : (n, k) float32
        Their weights ``a_vq`` up to a factor per row (inverse squared distances; 0 in
        unused slots).
    full, proxy : (n, 3), (m, 3)
        The rest positions bound (the caller's arrays, not copied).
    near_full : (m,) int64
        The nearest full vertex of each proxy vertex (where the proxy reads r and handles;
        read by homes instead, the 1.75M dragon's proxy had 4,277 handle vertices instead of
        4,238 and its preview's p95 rose from 1.7 % to 3.8 % of the diagonal).
    covered : (n,) bool or None
        Which full vertices the proxy was made from (None: all); the others are
        :func:`specks`, which only follow their nearest proxy vertices.
    """

    idx: np.ndarray
    near: np.ndarray
    weights: np.ndarray
    full: np.ndarray
    proxy: np.ndarray
    near_full: np.ndarray
    covered: np.ndarray | None = None

    @classmethod
    def between(cls, full: np.ndarray, proxy: np.ndarray,
                full_tree: cKDTree | None = None, left_out: np.ndarray | None = None,
                home: np.ndarray | None = None,
                proxy_faces: np.ndarray | None = None,
                proxy_adjacency=None) -> Binding:
        """Bind ``full`` (n, 3) rest positions to ``proxy`` (m, 3) ones.

        ``full_tree``: :func:`full_tree_of` ``full``, when made beforehand; ``left_out``:
        the full vertices left out of the proxy, its :func:`specks`; ``home`` (with the
        proxy's faces): each full vertex's home (:func:`decimation`), -1 where it has none.
        Without homes every full vertex follows its nearest proxy vertices.

        Examples
        --------
        >>> import numpy as np
        >>> b = Binding.between(np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]]),
        ...                     np.array([[0.1, 0, 0], [2.1, 0, 0]]))
        >>> b.idx.tolist(), b.near_full.tolist(), b.near.shape
        ([0, 0, 1], [0, 2], (3, 2))
        """
        full = np.ascontiguousarray(full, dtype=np.float64)
        proxy = np.ascontiguousarray(proxy, dtype=np.float64)
        n, m = len(full), len(proxy)
        k = min(SKIN_NEIGHBOURS, m)
        homes = np.full(n, -1, dtype=np.int32) if home is None else np.asarray(home, np.int32)
        if home is None:
            ptr, nbr = np.zeros(m + 1, dtype=np.int64), np.zeros(0, dtype=np.int32)
        else:
            adj = (Mesh(proxy, proxy_faces).adjacency if proxy_adjacency is None
                   else proxy_adjacency.tocsr())
            ptr, nbr = adj.indptr.astype(np.int64), adj.indices.astype(np.int32)
        near = np.empty((n, k), dtype=np.int32)
        weights = np.empty((n, k), dtype=np.float32)
        idx = np.empty(n, dtype=np.int64)
        tree = cKDTree(proxy)
        c = min(_CANDIDATES if home is not None else k, m)
        # a full vertex on a proxy vertex follows that one alone (to float32's precision);
        # 1 / floor^2 stays finite
        size = max(float(np.linalg.norm(np.ptp(proxy, axis=0))),
                   float(np.linalg.norm(np.ptp(full, axis=0))) if n else 0.0)
        floor = max(1e-9 * size, 1e-150)
        for a in range(0, n, _QUERY_ROWS):  # the queries run on every core
            b = min(n, a + _QUERY_ROWS)
            dist, cand = tree.query(full[a:b], k=c, workers=-1)
            dist, cand = dist.reshape(b - a, c), cand.reshape(b - a, c).astype(np.int32)
            idx[a:b] = cand[:, 0]
            _pick(full[a:b], proxy, cand, dist, homes[a:b], ptr, nbr, floor, near[a:b],
                  weights[a:b])
        if full_tree is None:
            full_tree = full_tree_of(full)
        near_full = full_tree.query(proxy, k=1, workers=-1)[1].astype(np.int64)
        return cls(idx, near, weights, full, proxy, near_full,
                   None if left_out is None else ~left_out)

    @property
    def offsets(self) -> np.ndarray:
        """``v - q`` at rest for each full vertex v and its nearest proxy vertex q."""
        return self.full - self.proxy[self.idx]

    def skin(self, Y: np.ndarray, R: np.ndarray) -> np.ndarray:
        """Full positions from proxy positions ``Y`` (m, 3) and rotations ``R`` (m, 3, 3).

        Examples
        --------
        >>> import numpy as np
        >>> b = Binding.between(np.array([[0.0, 0, 0], [1, 0, 0]]), np.array([[0.0, 0, 0]]))
        >>> Rz = np.array([[[0.0, -1, 0], [1, 0, 0], [0, 0, 1]]])
        >>> b.skin(np.array([[5.0, 0, 0]]), Rz).tolist()
        [[5.0, 0.0, 0.0], [5.0, 1.0, 0.0]]
        """
        out = np.empty((len(self.idx), 3))
        _skin(np.ascontiguousarray(Y, dtype=np.float64), np.ascontiguousarray(R, np.float64),
              self.proxy, self.full, self.near, self.weights, out)
        return out


def proxy_rings(rings: np.ndarray, near_full: np.ndarray) -> np.ndarray:
    """The proxy's rigidity map: the full r where each proxy vertex is bound.

    The proxy counts these r in the full mesh's rings (its solver's ``ring_scale`` is
    ``h_full / h_proxy``), so that it is as stiff as the full mesh
    (:mod:`arapkit.arap.energies.rring`).

    Examples
    --------
    >>> import numpy as np
    >>> proxy_rings(np.array([1, 5, 9]), np.array([2, 0])).tolist()
    [9, 1]
    """
    return np.asarray(rings, dtype=np.int32)[near_full]
