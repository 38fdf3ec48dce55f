"""Positional constraints and the sparse Cholesky factor behind every solver.

Both ARAP (:mod:`arapkit.arap.problem`) and Laplacian editing (:mod:`arapkit.methods.laplacian`)
solve
``A x = b`` for the free vertices of a symmetric positive (semi-)definite ``A`` with some
vertices held at given positions. This module holds what they share:

* :func:`check_handles` / :func:`check_targets`: validation with one-line errors;
* :func:`anchor_components`: vertices of connected components without a handle, which
  must be held too (otherwise the component can translate freely and ``A`` is singular);
* :class:`Elimination`: the split into free and constrained vertices, the reduced matrix
  ``A_ff`` (factorised once) and the coupling ``A_fc`` that moves the constrained values to
  the right-hand side, ``A_ff x_f = b_f - A_fc x_c``;
* :class:`CholeskyFactor`: CHOLMOD (via cholespy) with its C-level chatter silenced, in a
  child process where one was asked for (:func:`arapkit.arap.childfactor.factors_in_child`).

Anything with ``name``, ``n_vertices``, ``n_components`` and ``component_labels`` (a
:class:`~arapkit.mesh.model.Mesh` or an :class:`~arapkit.arap.graph.EdgeGraph`) can be
constrained.
"""

from __future__ import annotations

import os
import sys
from contextlib import contextmanager
from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING

import numba as nb
import numpy as np
import scipy.sparse as sp

from ..errors import Advice, InputError
from ..validate import handle_indices, target_positions
from .childfactor import ChildCholesky, ChildUnavailable, wants_child
from .rotations import fit_rotations

if TYPE_CHECKING:
    from ..mesh.model import Mesh
    from .graph import EdgeGraph

__all__ = [
    "CholeskyFactor",
    "Elimination",
    "anchor_components",
    "check_handles",
    "check_targets",
    "quiet_c_output",
    "return_free_memory",
    "rigid_motion",
]


def check_handles(mesh: Mesh | EdgeGraph, handles) -> np.ndarray:
    """Validate handle vertex indices (integers, unique, in range) and return them as int64.

    A boolean array of one value per vertex is read as a mask. The rule is
    :func:`arapkit.validate.handle_indices`.

    Examples
    --------
    >>> from arapkit.mesh.shapes import bar
    >>> check_handles(bar(), [0, 5]).tolist()
    [0, 5]
    """
    return handle_indices(handles, mesh.n_vertices, mesh.name)


def check_targets(handles: np.ndarray, targets, name: str = "targets") -> np.ndarray:
    """Validate handle targets: real, shape (len(handles), 3), finite."""
    return target_positions(handles, targets, name)


#: what to do with a connected component that holds no handle (the first is the default)
FREE_COMPONENT_POLICIES = ("follow", "fix", "error")


def anchor_components(mesh: Mesh | EdgeGraph, handles: np.ndarray, policy: str = "follow"):
    """Vertices that must be held fixed because their component has no handle.

    Without a handle such a component can translate freely and the system is singular, so
    its vertices are taken out of the solve. Its energy is 0 under any rigid motion, so
    every rigid placement is an equally good minimiser; the policy picks one.

    Parameters
    ----------
    policy : {"follow", "fix", "error"}
        ``"follow"`` (default) moves each such component afterwards by the rigid motion of
        the nearest part that has handles (:func:`follow_rigidly`: a character's eyes and
        teeth stay in its head); ``"fix"`` keeps them at rest; ``"error"`` refuses.

    Returns
    -------
    fixed : (f,) int64
        Vertices to hold at their rest positions.
    notes : list of str
        What was done, naming the components.

    Examples
    --------
    >>> from arapkit.mesh.shapes import bar
    >>> anchor_components(bar(), [0])[0].size
    0
    """
    labels = mesh.component_labels
    anchored = np.zeros(mesh.n_components, dtype=bool)
    anchored[labels[handles]] = True
    if anchored.all():
        return np.empty(0, dtype=np.int64), []
    missing = np.flatnonzero(~anchored)
    sizes = np.bincount(labels, minlength=mesh.n_components)[missing]
    firsts = [int(np.flatnonzero(labels == c)[0]) for c in missing[:3]]
    single = int((sizes == 1).sum())
    desc = (
        f"{len(missing)} connected component(s) without a handle ("
        + ", ".join(f"{s} vertices incl. vertex {f}" for s, f in zip(sizes[:3], firsts))
        + (", ..." if len(missing) > 3 else "")
        + (f"; {single} of them isolated vertices" if single else "")
        + ")"
    )
    if policy == "error":
        raise InputError(f"{mesh.name}: {desc}; add a handle there or use free_components='fix'")
    if policy not in FREE_COMPONENT_POLICIES:
        raise InputError(f"unknown free_components policy '{policy}' (use "
                         f"{', '.join(repr(p) for p in FREE_COMPONENT_POLICIES)})")
    fixed = np.flatnonzero(~anchored[labels]).astype(np.int64)
    what = ("move rigidly with the nearest part that has handles (isolated vertices stay at "
            "rest)" if policy == "follow" else "are held fixed at rest")
    return fixed, [f"{desc} {what}"]


def follow_rigidly(mesh: Mesh | EdgeGraph, free: np.ndarray, deformed: np.ndarray,
                   rotations: np.ndarray | None = None, k: int = 32) -> None:
    """Move each component of ``free`` by the rigid motion of its nearest anchored vertices.

    For a component C without handles, the anchored vertices nearest to C at rest (the
    nearest one of each vertex of C, and the ``k`` nearest its centroid) are fitted by the
    best rigid motion rest -> ``deformed`` (Kabsch), which is then applied to C in place;
    ``rotations`` of C's vertices are set to it. Single vertices stay where they are. C's
    own energy is 0 before and after, so the solution stays a minimiser. A solver that does
    this after every solve keeps the :class:`Followers` binding instead.

    Examples
    --------
    >>> import numpy as np
    >>> from arapkit import Mesh
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 2], [1, 0, 2], [0, 1, 2]], float)
    >>> m = Mesh(V, [[0, 1, 2], [3, 4, 5]])
    >>> P = V.copy(); P[:3] += [5, 0, 0]           # the handled triangle moved by +5 x
    >>> follow_rigidly(m, np.array([3, 4, 5]), P)
    >>> (np.round(P[3:] - V[3:], 9) + 0.0).tolist()
    [[5.0, 0.0, 0.0], [5.0, 0.0, 0.0], [5.0, 0.0, 0.0]]
    """
    Followers.of(mesh, free, k).apply(deformed, rotations)


@dataclass(frozen=True)
class Followers:
    """The rest-time half of :func:`follow_rigidly`: who follows whom, found once.

    Attributes
    ----------
    vertices : (m,) int
        The vertices of the free components of two or more vertices.
    group : (m,) int
        Their component, numbered ``0..G-1``.
    anchors, anchor_group : (a,) int
        The anchored vertices each component follows, and that component.
    rest : (n, 3)
        The rest positions.
    """

    vertices: np.ndarray
    group: np.ndarray
    anchors: np.ndarray
    anchor_group: np.ndarray
    rest: np.ndarray

    @classmethod
    def of(cls, mesh: Mesh | EdgeGraph, free: np.ndarray, k: int = 32) -> Followers:
        """Bind each free component of ``mesh`` to its nearest anchored vertices at rest.

        Examples
        --------
        >>> import numpy as np
        >>> from arapkit import Mesh
        >>> V = np.eye(3).tolist() + (np.eye(3) + [0, 0, 2]).tolist()
        >>> f = Followers.of(Mesh(np.array(V), [[0, 1, 2], [3, 4, 5]]), np.array([3, 4, 5]))
        >>> f.vertices.tolist(), sorted(set(f.anchors.tolist()))
        ([3, 4, 5], [0, 1, 2])
        """
        from scipy.spatial import cKDTree

        V = np.asarray(mesh.vertices)
        labels = mesh.component_labels
        is_free = np.zeros(len(V), dtype=bool)
        is_free[free] = True
        anchored = np.flatnonzero(~is_free)
        # the free components of two or more vertices, each one's vertices in index order
        sizes = np.bincount(labels, minlength=mesh.n_components)
        follows = is_free & (sizes[labels] >= 2)
        if not len(anchored) or not follows.any():
            none = np.zeros(0, np.int64)
            return cls(none, none, none, none, V)
        vs, group = _by_part(labels, follows)
        n_groups = int(group[-1]) + 1
        # all at once (a scan's specks are 10^4 parts): each vertex's nearest anchored
        # vertex, and the k nearest each part's centroid
        # a tree for one batch of queries: neither balanced nor compacted builds 1.5x faster
        tree = cKDTree(V[anchored], balanced_tree=False, compact_nodes=False)
        near = tree.query(V[vs], k=1, workers=-1)[1]
        counts = np.bincount(group, minlength=n_groups)
        centres = np.stack([np.bincount(group, V[vs, a], n_groups) for a in range(3)], 1)
        kk = min(k, len(anchored))
        centre = tree.query(centres / counts[:, None], k=kk, workers=-1)[1].reshape(-1, kk)
        # each part's anchors, once each and in index order: the sorted distinct keys
        # (by a sort: NumPy's hashing np.unique took 0.3 s on a scan's 6 x 10^5)
        key = np.sort(np.concatenate([group * len(anchored) + near,
                                      np.repeat(np.arange(n_groups), kk) * len(anchored)
                                      + centre.ravel()]))
        key = key[np.concatenate([[True], key[1:] != key[:-1]])]
        return cls(vs, group, anchored[key % len(anchored)], key // len(anchored), V)

    @classmethod
    def on_own_anchors(cls, mesh: Mesh | EdgeGraph, follows: np.ndarray,
                       anchors: np.ndarray) -> Followers:
        """Each part's vertices in the (n,) bool ``follows`` follow the rigid fit to that
        part's own ``anchors`` (vertex indices); parts without an anchor are left out.

        Examples
        --------
        >>> import numpy as np
        >>> from arapkit import Mesh
        >>> V = np.eye(3).tolist() + (np.eye(3) + [0, 0, 2]).tolist()
        >>> m = Mesh(np.array(V), [[0, 1, 2], [3, 4, 5]])
        >>> f = Followers.on_own_anchors(m, np.array([0, 1, 1, 0, 1, 1], bool), np.array([0]))
        >>> f.vertices.tolist(), f.anchors.tolist()
        ([1, 2], [0])
        """
        labels = mesh.component_labels
        anchored = np.zeros(mesh.n_components, dtype=bool)
        anchored[labels[anchors]] = True
        vs, group = _by_part(labels, follows & anchored[labels])
        parts = labels[vs][np.flatnonzero(np.diff(group, prepend=-1))]  # ascending
        anchors = np.asarray(anchors, dtype=np.int64)[np.isin(labels[anchors], parts)]
        return cls(vs, group, anchors, np.searchsorted(parts, labels[anchors]).astype(np.int64),
                   np.asarray(mesh.vertices))

    @cached_property
    def _rest_anchors(self) -> np.ndarray:
        return np.ascontiguousarray(self.rest[self.anchors])

    def apply(self, deformed: np.ndarray, rotations: np.ndarray | None = None) -> None:
        """Move the followers by their anchors' fitted rigid motions (in place)."""
        if not len(self.vertices):
            return
        n = int(self.group[-1]) + 1  # numbered in order, the last is the largest
        R, t = rigid_motions(self._rest_anchors, deformed[self.anchors], self.anchor_group, n)
        # one pass: NumPy's R[group] alone is 9 doubles a follower (a scan's specks: 60K)
        _place(R, t, self.group, self.vertices, self.rest, deformed,
               _NO_ROTATIONS if rotations is None else rotations)


def _by_part(labels: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The vertices in ``mask`` sorted by part (in index order within one), and each one's
    part numbered ``0..G-1`` in that order: :class:`Followers`' numbering."""
    vs = np.flatnonzero(mask)
    vs = vs[np.argsort(labels[vs], kind="stable")].astype(np.int64)
    lab = labels[vs]
    group = np.zeros(len(vs), dtype=np.int64)
    group[1:] = np.cumsum(lab[1:] != lab[:-1])
    return vs, group


_NO_ROTATIONS = np.zeros((0, 3, 3))


@nb.njit(cache=True, nogil=True)
def _place(R, t, group, vertices, rest, deformed, rotations):  # pragma: no cover - compiled
    """``deformed[v] = R[g] rest[v] + t[g]`` (and ``rotations[v] = R[g]``) per follower."""
    keep = rotations.shape[0] > 0
    for i in range(vertices.shape[0]):
        v, g = vertices[i], group[i]
        for a in range(3):
            deformed[v, a] = (R[g, a, 0] * rest[v, 0] + R[g, a, 1] * rest[v, 1]
                              + R[g, a, 2] * rest[v, 2] + t[g, a])
            if keep:
                for b in range(3):
                    rotations[v, a, b] = R[g, a, b]


def rigid_motions(src: np.ndarray, dst: np.ndarray, group: np.ndarray,
                  n_groups: int) -> tuple[np.ndarray, np.ndarray]:
    """Per group, the rigid motion best mapping its points ``src`` onto ``dst`` (Kabsch).

    Returns ``(R, t)``, (G, 3, 3) and (G, 3), each ``det R = +1`` minimising
    ``sum |src @ R.T + t - dst|^2`` over the group's points (a group without points gets
    the identity). The sums are one compiled pass over the points, around each group's
    means, and the rotations are the local step's
    (:func:`~arapkit.arap.rotations.fit_rotations`): a scan's 2 x 10^4 floating specks,
    each following its anchors after every solve, took 77 ms a preview frame with
    bincounts and a batched SVD.

    Examples
    --------
    >>> import numpy as np
    >>> src = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    >>> R, t = rigid_motions(np.vstack([src, src]), np.vstack([src + 1, src[:, [1, 0, 2]]]),
    ...                      np.array([0, 0, 0, 1, 1, 1]), 2)
    >>> t[0].tolist(), (np.round(np.linalg.det(R), 12) + 0.0).tolist()
    ([1.0, 1.0, 1.0], [1.0, 1.0])
    """
    src = np.ascontiguousarray(src, dtype=np.float64)
    dst = np.ascontiguousarray(dst, dtype=np.float64)
    ms = np.zeros((n_groups, 3))
    md = np.zeros((n_groups, 3))
    H = np.zeros((n_groups, 3, 3))
    _group_moments(src, dst, np.ascontiguousarray(group, dtype=np.int64), ms, md, H)
    R = fit_rotations(H, H)  # maximises tr(R H), H = sum (s - ms)(d - md)^T
    return R, md - np.einsum("gij,gj->gi", R, ms)


@nb.njit(cache=True, nogil=True)
def _group_moments(src, dst, group, ms, md, H):  # pragma: no cover - compiled
    """Each group's means of ``src`` and ``dst`` and ``sum (s - ms)(d - md)^T``."""
    count = np.zeros(ms.shape[0])
    for i in range(group.shape[0]):
        g = group[i]
        count[g] += 1.0
        for a in range(3):
            ms[g, a] += src[i, a]
            md[g, a] += dst[i, a]
    for g in range(ms.shape[0]):
        c = max(count[g], 1.0)
        for a in range(3):
            ms[g, a] /= c
            md[g, a] /= c
    # centred before the products: far from the origin (a georeferenced scan) the
    # uncentred sums would cancel to noise
    for i in range(group.shape[0]):
        g = group[i]
        for a in range(3):
            s = src[i, a] - ms[g, a]
            for b in range(3):
                H[g, a, b] += s * (dst[i, b] - md[g, b])


def rigid_motion(src: np.ndarray, dst: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rigid motion that best maps points ``src`` onto ``dst`` (Kabsch).

    Returns ``(R, t)`` with ``det R = +1`` minimising ``sum |src @ R.T + t - dst|^2``.

    Examples
    --------
    >>> import numpy as np
    >>> src = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    >>> R, t = rigid_motion(src, src[:, [1, 0, 2]] * [-1, 1, 1] + 2.0)  # a quarter turn
    >>> (np.round(R, 12) + 0.0).tolist(), t.tolist()
    ([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]], [2.0, 2.0, 2.0])
    """
    R, t = rigid_motions(src, dst, np.zeros(len(src), dtype=np.int64), 1)
    return R[0], t[0]


def _flush_c_stdio() -> None:
    """Flush the C library's stdio buffers (CHOLMOD's printf output sits there)."""
    try:
        import ctypes

        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError):  # no libc symbols on this platform: nothing to flush
        pass


def return_free_memory() -> None:
    """Hand the C heap's free pages back to the system (glibc's ``malloc_trim``).

    glibc keeps what a large build frees (a factorisation's workspace, the matrices it was
    assembled from) in its heaps for reuse, and raises its ``mmap`` threshold as it goes,
    so that later arrays of up to 32 MiB come from those heaps as well: at 1.75M vertices
    the editor's resident memory grew 0.7 GiB above what it had alive. Dask's workers trim
    the same way. Elsewhere (no glibc) this does nothing. It takes a few milliseconds and
    is called after each factorisation (:attr:`ARAPProblem.elimination
    <arapkit.arap.problem.ARAPProblem.elimination>`).

    Examples
    --------
    >>> import numpy as np
    >>> blocks = [np.ones(2**16) for _ in range(8)]
    >>> del blocks
    >>> return_free_memory()  # the freed blocks' pages go back to the system
    """
    global _TRIM
    if _TRIM is None:
        try:
            import ctypes

            _TRIM = ctypes.CDLL(None).malloc_trim  # the C library this process runs on
        except (OSError, AttributeError):
            _TRIM = False
    if _TRIM:
        _TRIM(0)


_TRIM = None


@contextmanager
def quiet_c_output():
    """Silence C-level stdout and stderr: CHOLMOD prints a warning before cholespy raises.

    stdout must carry results only (the command line pipes it), so the warning is flushed
    into /dev/null before the streams are restored.

    Examples
    --------
    >>> with quiet_c_output():
    ...     pass  # C code called here prints nothing
    """
    sys.stdout.flush()
    sys.stderr.flush()
    try:
        saved = [os.dup(1), os.dup(2)]
    except OSError:
        yield
        return
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 1)
            os.dup2(null.fileno(), 2)
            try:
                yield
            finally:
                _flush_c_stdio()
    finally:
        for fd, target in zip(saved, (1, 2)):
            os.dup2(fd, target)
            os.close(fd)


class CholeskyFactor:
    """Sparse Cholesky factor (CHOLMOD via cholespy) of a symmetric positive definite matrix.

    Examples
    --------
    >>> import numpy as np, scipy.sparse as sp
    >>> f = CholeskyFactor(sp.csr_matrix(np.array([[4.0, 1.0], [1.0, 3.0]])), "demo")
    >>> np.round(f.solve(np.array([[1.0], [2.0]])).ravel(), 6).tolist()
    [0.090909, 0.636364]
    """

    def __init__(self, A: sp.spmatrix, what: str, remedy: str | Advice = "") -> None:
        from cholespy import CholeskySolverD, MatrixType

        A = sp.coo_matrix(A)
        self.n = A.shape[0]
        try:
            self._solver = None
            if wants_child(self.n):  # built beside other work: the GIL stays free
                try:  # converted there, one array at a time
                    self._solver = ChildCholesky(self.n, A.row, A.col, A.data)
                except ChildUnavailable:
                    pass  # the same factor, made here
            if self._solver is None:
                with quiet_c_output():
                    self._solver = CholeskySolverD(
                        self.n, A.row.astype(np.int32), A.col.astype(np.int32),
                        A.data.astype(np.float64), MatrixType.COO)
        except ValueError:
            msg = f"{what}: the system matrix is not positive definite"
            raise InputError(
                remedy.after(msg) if isinstance(remedy, Advice) else msg + remedy
            ) from None

    def solve(self, B: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Solve ``A X = B`` for a (n,) or (n, k) right-hand side (into ``out`` if given)."""
        B = np.ascontiguousarray(B, dtype=np.float64)
        X = np.empty_like(B) if out is None else out
        self._solver.solve(B, X)
        return X


@dataclass(frozen=True)
class Elimination:
    """Free/constrained split of ``A x = b`` with ``A_ff`` factorised once.

    Attributes
    ----------
    free, constrained : (f,), (c,) int64
        Vertex ids (in the numbering of the matrix).
    slot : (n,) int64
        Row of each vertex in the reduced system, -1 for constrained vertices.
    A_fc : (f, c) CSR
        Coupling block: the reduced right-hand side is ``b_f - A_fc x_c``.
    factor : CholeskyFactor or None
        Factor of ``A_ff`` (None when every vertex is constrained).

    Examples
    --------
    >>> import numpy as np
    >>> el = Elimination.from_edges(3, np.array([[0, 1], [1, 2]]), np.ones(2), [0, 2], "chain")
    >>> x = el.solve(-el.A_fc @ np.array([[0.0], [2.0]]))  # the middle of 0 and 2
    >>> el.free.tolist(), np.round(x, 12).ravel().tolist()
    ([1], [1.0])
    """

    free: np.ndarray
    constrained: np.ndarray
    slot: np.ndarray
    A_fc: sp.csr_matrix
    factor: CholeskyFactor | None

    @staticmethod
    def _split(n: int, constrained) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        cons = np.asarray(constrained, dtype=np.int64)
        is_free = np.ones(n, dtype=bool)
        is_free[cons] = False
        free = np.flatnonzero(is_free)
        slot = np.full(n, -1, dtype=np.int64)
        slot[free] = np.arange(len(free))
        return free, cons, slot

    @classmethod
    def from_edges(cls, n: int, edges: np.ndarray, weights: np.ndarray, constrained,
                   what: str, remedy: str = "", diag: np.ndarray | None = None
                   ) -> Elimination:
        """Eliminate from the graph Laplacian ``sum_e w_e (e_i - e_j)(e_i - e_j)^T``, plus
        ``diag`` (n,) on its diagonal where given (a mass term: it couples no two vertices,
        so only the free rows' entries matter).

        The reduced blocks are assembled straight from the edge list (no full n x n matrix).
        """
        free, cons, slot = cls._split(n, constrained)
        cslot = np.full(n, -1, dtype=np.int64)
        cslot[cons] = np.arange(len(cons))
        a, b, w = edges[:, 0], edges[:, 1], weights
        sa, sb = slot[a], slot[b]
        nf, nc = len(free), len(cons)
        ff = (sa >= 0) & (sb >= 0)
        d_ff = (np.bincount(sa[sa >= 0], w[sa >= 0], nf)
                + np.bincount(sb[sb >= 0], w[sb >= 0], nf))
        if diag is not None:
            # (without edges, bincount's sum is an int array)
            d_ff = d_ff + np.asarray(diag, dtype=np.float64)[free]
        fc = (sa >= 0) & (sb < 0)
        cf = (sa < 0) & (sb >= 0)
        A_fc = sp.csr_matrix(
            (np.concatenate([-w[fc], -w[cf]]),
             (np.concatenate([sa[fc], sb[cf]]), np.concatenate([cslot[b[fc]], cslot[a[cf]]]))),
            shape=(nf, nc),
        )
        factor = None
        if nf:
            A = sp.coo_matrix(
                (np.concatenate([-w[ff], -w[ff], d_ff]),
                 (np.concatenate([sa[ff], sb[ff], np.arange(nf)]),
                  np.concatenate([sb[ff], sa[ff], np.arange(nf)]))),
                shape=(nf, nf),
            )
            factor = CholeskyFactor(A, what, remedy)
        return cls(free, cons, slot, A_fc, factor)

    @classmethod
    def from_matrix(cls, A: sp.spmatrix, constrained, what: str, remedy: str = "") -> Elimination:
        """Eliminate from an assembled symmetric matrix (e.g. the normal equations)."""
        A = sp.csr_matrix(A)
        free, cons, slot = cls._split(A.shape[0], constrained)
        Af = A[free]
        factor = CholeskyFactor(Af[:, free], what, remedy) if len(free) else None
        return cls(free, cons, slot, Af[:, cons].tocsr(), factor)

    def solve(self, rhs: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """``A_ff^{-1} rhs`` for a reduced right-hand side (f,) or (f, k)."""
        if self.factor is None:
            return np.empty_like(rhs) if out is None else out
        return self.factor.solve(rhs, out)
