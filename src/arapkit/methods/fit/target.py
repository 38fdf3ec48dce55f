"""The surface a template is fitted to: a triangle mesh, or a point cloud read as oriented disks.

:class:`FitTarget` holds what the fit's correspondence step needs, built once per target:
the surface elements (a mesh's triangles, or one disk per cloud point), their neighbour graph
for the greedy walk, a k-d tree of their centres for the global search, their normals and
which of them lie on the surface's border. :meth:`FitTarget.match` returns every query's
closest point (:mod:`arapkit.methods.fit.closest`).

A cloud's normals come with it (a scanner's, or a PLY's ``nx ny nz``) or are estimated by
principal components of each point's neighbours; estimated normals have no orientation, so
the normal test of the fit then compares lines, not directions. A disk's radius is the
distance to the point's 6th nearest neighbour: at uniform density that leaves about
``exp(-6)``, 0.25 %, of the surface uncovered.

Examples
--------
>>> import numpy as np
>>> t = FitTarget.from_any(np.random.default_rng(0).random((200, 3)) * [1, 1, 0])
>>> t.kind, t.oriented, t.n_points
('points', False, 200)
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from ...errors import InputError
from ...mesh.model import Mesh, faces_of
from ...validate import point_positions, real_array
from .closest import PARALLEL_QUERIES, boundary_points, match_disks, match_triangles

__all__ = ["FitTarget", "Matches", "WalkMemo", "as_points"]

#: neighbours of a cloud point: for its normal, its disk's radius and the walk's graph
NORMAL_NEIGHBOURS = 10
RADIUS_NEIGHBOUR = 6
WALK_NEIGHBOURS = 8
BORDER_NEIGHBOURS = 16
#: a cloud point whose neighbours leave an angular gap wider than this is on its border
BORDER_GAP = np.deg2rad(135.0)
#: k-d tree candidates per query, and the most moves of the walk that follows
START_CANDIDATES = 8
MAX_WALK = 64


class Matches(NamedTuple):
    """Closest points of a set of queries (one row per query).

    Attributes
    ----------
    point : (n, 3) the closest point on the target surface.
    element : (n,) the triangle or disk it lies on.
    d2 : (n,) squared distance.
    border : (n,) bool, the closest point is on the surface's border.
    normal : (n, 3) the target's unit normal there.
    """

    point: np.ndarray
    element: np.ndarray
    d2: np.ndarray
    border: np.ndarray
    normal: np.ndarray


class WalkMemo(NamedTuple):
    """What the closest-point walk remembers of each query between calls, so that a query
    that has hardly moved skips a walk that would stay where it is (see
    :func:`arapkit.methods.fit.closest.match_disks`). Make it with :meth:`FitTarget.memo`
    and pass it to every :meth:`FitTarget.match` of the same queries.

    Attributes
    ----------
    anchor : (n, 3) where each query last settled.
    slack : (n,) how much farther than its element every neighbour was there.
    owner : (n,) that element (-1: nothing remembered).
    """

    anchor: np.ndarray
    slack: np.ndarray
    owner: np.ndarray


def as_points(values, what: str) -> np.ndarray:
    """``values`` as finite (n, 3) float64 positions, or a one-line InputError naming the
    first bad row.

    Examples
    --------
    >>> as_points([[0, 0, float("nan")]], "scan.npy")
    Traceback (most recent call last):
    ...
    arapkit.errors.InputError: scan.npy: point 0 has a non-finite coordinate [0.0, 0.0, nan]
    """
    return point_positions(values, what)


def _csr(rows: np.ndarray, cols: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The graph of the pairs ``(rows, cols)`` as CSR (sorted, no duplicates, no loops)."""
    keep = rows != cols
    # scipy's counting sort: six times faster than a lexsort of the pairs (13,750 points)
    A = sp.csr_matrix((np.ones(int(keep.sum()), dtype=np.int32), (rows[keep], cols[keep])),
                      shape=(n, n))
    A.sum_duplicates()
    return A.indptr.astype(np.int64), A.indices.astype(np.int64)


def _unit(N: np.ndarray) -> np.ndarray:
    length = np.linalg.norm(N, axis=1, keepdims=True)
    return N / np.where(length > 0, length, 1.0)


@dataclass(frozen=True, eq=False)
class FitTarget:
    """A target surface prepared for closest-point queries (build with :meth:`from_any`).

    Attributes
    ----------
    kind : {"mesh", "points"}
    points : (m, 3) the mesh's vertices or the cloud's points.
    faces : (f, 3) int or None.
    normals : (e, 3) unit normal of each element (triangle or point).
    oriented : bool, whether the normals have a consistent direction.
    radius : (m,) each disk's radius (clouds; empty for meshes).
    nbr_ptr, nbr_idx : the elements' neighbour graph (CSR).
    border : (m,) bool, boundary vertices (mesh) or border points (cloud).
    border_edge : (f, 3) bool, boundary edges ab, ac, bc of each face (meshes).
    tree : k-d tree of the element centres, built once per target (see ``frame``).
    name : str, for messages.
    frame : (scale, R, t) or None, where the tree is: a point x of this target is
        ``scale R x + t`` in the tree's coordinates (None: the same coordinates).
    """

    kind: str
    points: np.ndarray
    faces: np.ndarray | None
    normals: np.ndarray
    oriented: bool
    radius: np.ndarray
    nbr_ptr: np.ndarray
    nbr_idx: np.ndarray
    border: np.ndarray
    border_edge: np.ndarray
    tree: cKDTree
    name: str = "target"
    frame: tuple[float, np.ndarray, np.ndarray] | None = None

    # -- construction --------------------------------------------------------------
    @classmethod
    def from_any(cls, target, normals=None, name: str = "target") -> FitTarget:
        """A mesh (:class:`~arapkit.Mesh`, ``trimesh.Trimesh``, a (vertices, faces) pair), a
        point cloud (an (n, 3) array, an :class:`arapkit.PointCloud` with its normals, or
        an object with ``vertices`` and no faces such as ``trimesh.PointCloud``), with
        optional per-point ``normals`` for a cloud."""
        if isinstance(target, FitTarget):
            return target
        name = getattr(target, "name", None) or name
        if isinstance(target, Mesh):
            return cls.from_mesh(target)
        if isinstance(target, (tuple, list)) and len(target) == 2 and np.ndim(target[1]) == 2:
            return cls.from_mesh(Mesh(target[0], target[1], name=name))
        F = faces_of(target)
        V = getattr(target, "vertices", None)
        if V is not None and F is not None and np.size(F):
            return cls.from_mesh(Mesh(np.asarray(V), np.asarray(F), name=name))
        if V is not None:
            if normals is None:  # trimesh's vertex_normals, an arapkit.PointCloud's normals
                vn = getattr(target, "vertex_normals", None)
                if vn is None:
                    vn = getattr(target, "normals", None)
                normals = vn if vn is not None and np.shape(vn) == np.shape(V) else None
            return cls.from_points(V, normals, name)
        if isinstance(target, (str, bytes)):
            raise InputError(f"{name}: expected a mesh, a point cloud or an (n, 3) array, "
                             "got a str (load a file with arapkit.load_mesh or "
                             "arapkit.load_points)")
        return cls.from_points(target, normals, name)

    @classmethod
    def from_mesh(cls, mesh: Mesh) -> FitTarget:
        """The triangles of ``mesh`` (vertices referenced by no face are left out)."""
        V, F = np.ascontiguousarray(mesh.vertices), np.ascontiguousarray(mesh.faces)
        if len(F) == 0:
            raise InputError(f"{mesh.name}: the target mesh has no faces")
        cross = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
        # edges ab, ac, bc of each face: an edge of one face only is a border
        ends = np.sort(np.stack([F[:, [0, 1]], F[:, [0, 2]], F[:, [1, 2]]], axis=1), axis=2)
        key = ends[..., 0].astype(np.int64) * len(V) + ends[..., 1]
        _, inv, count = np.unique(key.ravel(), return_inverse=True, return_counts=True)
        border_edge = (count[inv] == 1).reshape(-1, 3)
        border = np.zeros(len(V), dtype=bool)
        border[ends[border_edge].ravel()] = True
        # faces sharing a vertex are neighbours of the walk
        fid = np.repeat(np.arange(len(F)), 3)
        vf_order = np.argsort(F.ravel(), kind="stable")
        vf_ptr = np.zeros(len(V) + 1, dtype=np.int64)
        np.cumsum(np.bincount(F.ravel(), minlength=len(V)), out=vf_ptr[1:])
        vf = fid[vf_order]
        deg = np.diff(vf_ptr)[F.ravel()]
        rows = np.repeat(fid, deg)
        starts = vf_ptr[F.ravel()]
        cols = vf[np.repeat(starts, deg) + _ranges(deg)]
        ptr, idx = _csr(rows, cols, len(F))
        centres = V[F].mean(axis=1)
        return cls("mesh", V, F, _unit(cross), True, np.zeros(0), ptr, idx, border,
                   border_edge, cKDTree(centres), mesh.name)

    @classmethod
    def from_points(cls, points, normals=None, name: str = "target") -> FitTarget:
        """A cloud of (n, 3) ``points`` with optional (n, 3) ``normals``."""
        P = as_points(points, name)
        if len(P) < 4:
            raise InputError(f"{name}: a point cloud needs at least 4 points, got {len(P)}")
        tree = cKDTree(P)
        k = min(len(P), max(NORMAL_NEIGHBOURS, RADIUS_NEIGHBOUR, WALK_NEIGHBOURS,
                                    BORDER_NEIGHBOURS) + 1)
        dist, knn = tree.query(P, k=k, workers=_workers(len(P)))
        oriented = normals is not None
        if oriented:
            N = np.array(real_array(normals, f"{name}: normals"), dtype=np.float64)
            if N.shape != P.shape:
                raise InputError(f"{name}: {len(N)} normals for {len(P)} points "
                                 f"(shape {N.shape})")
            length = np.linalg.norm(N, axis=1)
            bad = np.flatnonzero(~(np.isfinite(length) & (length > 0)))
            if len(bad):
                raise InputError(f"{name}: normal {bad[0]} is zero or not finite "
                                 f"{N[bad[0]].tolist()}")
            N = N / length[:, None]
        else:
            N = _pca_normals(P, knn[:, : min(k, NORMAL_NEIGHBOURS + 1)])
        radius = dist[:, min(k - 1, RADIUS_NEIGHBOUR)]
        if not (radius > 0).any():
            raise InputError(f"{name}: all points coincide")
        # duplicates would give a disk of radius 0: give them the smallest real one
        radius = np.maximum(radius, radius[radius > 0].min())
        w = knn[:, 1: min(k, WALK_NEIGHBOURS + 1)]
        rows = np.repeat(np.arange(len(P)), w.shape[1])
        # symmetrised, so the walk can go back where a one-way neighbour led
        ptr, idx = _csr(np.concatenate([rows, w.ravel()]), np.concatenate([w.ravel(), rows]),
                        len(P))
        border = boundary_points(P, N, knn[:, 1:].astype(np.int64), BORDER_GAP)
        return cls("points", P, None, N, oriented, radius, ptr, idx, border,
                   np.zeros((0, 3), dtype=bool), tree, name)

    # -- queries --------------------------------------------------------------------
    @property
    def n_points(self) -> int:
        """Number of vertices (mesh) or points (cloud)."""
        return len(self.points)

    @property
    def diagonal(self) -> float:
        """The diagonal of the points' bounding box."""
        return float(np.linalg.norm(self.points.max(axis=0) - self.points.min(axis=0)))

    def nearest(self, X: np.ndarray, k: int = 1,
                distance_upper_bound: float = np.inf) -> tuple[np.ndarray, np.ndarray]:
        """The ``k`` element centres nearest each row of ``X`` (the k-d tree's query, in this
        target's coordinates): distances (inf beyond the bound) and element indices."""
        X = np.asarray(X, dtype=np.float64)
        scale = 1.0
        if self.frame is not None:
            scale, R, t = self.frame
            X = scale * X @ R.T + t
        d, i = self.tree.query(X, k=k, distance_upper_bound=distance_upper_bound * scale,
                               workers=_workers(len(X)))
        return d / scale, i

    @staticmethod
    def memo(n: int) -> WalkMemo:
        """An empty :class:`WalkMemo` for ``n`` queries."""
        return WalkMemo(np.zeros((n, 3)), np.zeros(n), np.full(n, -1, dtype=np.int64))

    def match(self, X: np.ndarray, prev: np.ndarray | None = None, *,
              search: bool = True, memo: WalkMemo | None = None) -> Matches:
        """Closest points of the rows of ``X`` on the surface.

        ``prev`` (one element per row, -1 for none) is always a candidate, so no row gets a
        farther point than its last match; ``search`` adds a k-d tree search (without it
        only the walk from ``prev`` runs). ``memo`` (:meth:`memo`, kept by the caller
        across calls for the same queries) skips the walks that would not move: the same
        matches, faster.
        """
        X = np.ascontiguousarray(X, dtype=np.float64)
        n = len(X)
        prev = np.full(n, -1, np.int64) if prev is None else np.ascontiguousarray(prev, np.int64)
        if search or (prev < 0).any():
            k = min(START_CANDIDATES, self.tree.n)
            start = self.nearest(X, k)[1].reshape(n, k).astype(np.int64)
        else:
            start = np.zeros((n, 0), dtype=np.int64)
        if memo is None or len(memo.owner) != n:
            memo = self.memo(n)
        q = np.empty((n, 3))
        elem = np.empty(n, dtype=np.int64)
        d2 = np.empty(n)
        border = np.empty(n, dtype=bool)
        if self.kind == "mesh":
            match_triangles(X, self.points, self.faces, self.nbr_ptr, self.nbr_idx, start,
                            prev, self.border_edge, self.border, MAX_WALK, q, elem, d2, border,
                            *memo)
        else:
            match_disks(X, self.points, self.normals, self.radius, self.nbr_ptr, self.nbr_idx,
                        start, prev, self.border, MAX_WALK, q, elem, d2, border, *memo)
        return Matches(q, elem, d2, border, self.normals[elem])

    def moved(self, scale: float, R: np.ndarray, t: np.ndarray) -> FitTarget:
        """The target mapped by ``x -> R^T (x - t) / scale``, the inverse of the similarity
        ``x -> scale R x + t`` (into a template's frame)."""
        P = np.ascontiguousarray((self.points - t) @ R / scale)
        N = np.ascontiguousarray(self.normals @ R)
        # the tree stays where it is: queries are mapped to it (see ``frame``)
        s0, R0, t0 = (1.0, np.eye(3), np.zeros(3)) if self.frame is None else self.frame
        frame = (s0 * scale, R0 @ R, s0 * R0 @ t + t0)
        return replace(self, points=P, normals=N, radius=self.radius / scale, frame=frame)


def _workers(n: int) -> int:
    """Threads for a k-d tree query of ``n`` points: as the matching kernels (a thread's
    start costs what it saves below :data:`PARALLEL_QUERIES` on a shared machine)."""
    return -1 if n >= PARALLEL_QUERIES else 1


def _ranges(counts: np.ndarray) -> np.ndarray:
    """``[0..c0-1, 0..c1-1, ...]`` for the given counts."""
    ends = np.cumsum(counts)
    return np.arange(ends[-1] if len(ends) else 0) - np.repeat(ends - counts, counts)


def _pca_normals(P: np.ndarray, knn: np.ndarray) -> np.ndarray:
    """Unit normals (unoriented): the least principal axis of each point's neighbours."""
    nb = P[knn]
    d = nb - nb.mean(axis=1, keepdims=True)
    C = np.einsum("nki,nkj->nij", d, d)
    return np.linalg.eigh(C)[1][:, :, 0]
