"""Rigid parts: vertices that move by one rigid motion, solved exactly in reduced coordinates.

A part ``P`` with centre vertex ``c`` (rest position ``v_c``) has its vertices at

    x_v = R_P a_v + t_P,    a_v = v_v - v_c,

so every edge inside it keeps its length and ``t_P`` is where its centre goes. The energy is
the method's own (any energy of :mod:`arapkit.arap.energies` with one rotation per vertex),
restricted to such shapes. Written out,

    E = sum_e D_e |x_i - x_j|^2 - 2 sum_v b_v . x_v + const,   b_v = sum_k R_k c_kv,

and the loop minimises it block by block, each block exactly, so it never rises:

* **local step**: the vertex rotations ``R_k`` as usual, then each part's ``R_P`` with its
  translation held: edges inside the part are constant, so ``E = const - 2 tr(R_P M_P)``
  with

      M_P = sum_{v in P} a_v b_v^T + sum_{e = (i in P, j not in P)} D_e a_i (x_j - t_P)^T,

  a Procrustes problem (:func:`~arapkit.arap.rotations.fit_rotations`). The block also
  holds the rotations ``R_k`` of the energy's neighbourhoods that lie inside the part: their
  terms vanish at ``R_k = R_P`` whatever ``R_P`` is, so they leave ``M_P`` (their share,
  ``Q_k R_k^T`` with ``Q_k = sum_v a_v c_kv^T``, is taken out) and follow the part. Held at
  their old values instead they would pull the part back to its last rotation, and a part
  would turn a little each iteration. Parts joined by an edge are fitted one after the other
  (a greedy colouring), the others together;
* **global step**: ``x = B y + z``, with ``y`` the free vertices and each free part's
  centre (``t_P``), ``B`` copying a centre to its part, and ``z`` the parts' offsets
  ``R_P a_v`` and the constrained positions. The minimiser solves
  ``(B^T A B) y = B^T (b - A z)``: ``B^T A B`` is the Laplacian of the mesh with each part
  merged into one vertex (edges inside a part drop out). It does not depend on the
  rotations, so it is factorised once per handle set and reused for every target, as the
  plain problem's.

A system with a diagonal term ``sum_v d_v |x_v|^2`` beside the edges (implicit Euler's masses,
:mod:`arapkit.arap.dynamics`) passes ``diag``: it is summed into each merged row like the
edges, adds ``-sum_{v in P} d_v a_v t_P^T`` to ``M_P``, and a free part then turns about its
centre of ``d`` (``ref``) rather than its centre vertex: the block stays exact, and the turn
keeps ``sum_v d_v x_v``, so a step's linear momentum is that of the global step's solution.

Handles inside a part hold it (:func:`hold_parts`): three or more not on one line fix it
(their best rigid fit places it: a set of handles no rigid motion meets is refused, naming
the part); handles on one line make it a hinge about that line (its rotation about the line
is fitted); one handle makes a pivot (its rotation about the handle is fitted). Held parts'
vertices are constrained vertices of the elimination.

Examples
--------
>>> from arapkit.arap.problem import ARAPProblem
>>> from arapkit.mesh.shapes import bar
>>> p = ARAPProblem.from_mesh(bar(segments=(8, 2, 2)), [0])
>>> part = np.full(p.n_vertices, -1); part[p.iperm[40:60]] = 0
>>> lay = PartLayout.build(p.graph, part, ("middle",))
>>> lay.n_parts, int(lay.sizes[0]), lay.colour.tolist()
(1, 20, [0])
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING

import numba as nb
import numpy as np
import scipy.sparse as sp

from ..errors import InputError
from .constraints import Elimination, rigid_motions
from .rotations import fit_rotation_range

if TYPE_CHECKING:
    from .graph import EdgeGraph

__all__ = ["FIXED", "FREE", "HINGE", "KINDS", "PART_TOL", "PIVOT", "PartHolds", "PartLayout",
           "PartSystem", "hold_parts", "nearest_rotations"]

#: how a part is held: by nothing, one handle, handles on a line, or three or more
FREE, PIVOT, HINGE, FIXED = 0, 1, 2, 3
KINDS = ("free", "pivot", "hinge", "fixed")
#: the largest distance, relative to the bounding-box diagonal, by which the best rigid
#: motion of a part may miss its handles (a float32 gizmo's rotation misses by about 1e-7)
PART_TOL = 1e-6


@dataclass(frozen=True, eq=False)
class PartLayout:
    """The parts in the solver's numbering, independent of the handles.

    Attributes
    ----------
    part : (n,) int64
        Each vertex's part, -1 for none.
    names : tuple of str
        The parts' names.
    ptr, verts : CSR
        Each part's vertices, ascending.
    cross_part, cross_i, cross_j : (c,) int64
        Every edge leaving a part, once per part it leaves: ``cross_i`` in
        ``cross_part``, ``cross_j`` outside it.
    cross_edge : (c,) int64
        That edge's id (its weight ``D_e`` is the energy's: a new rigidity map changes it).
    colour : (P,) int64
        Parts joined by an edge have different colours (fitted one after the other).
    """

    part: np.ndarray
    names: tuple[str, ...]
    ptr: np.ndarray
    verts: np.ndarray
    cross_part: np.ndarray
    cross_i: np.ndarray
    cross_j: np.ndarray
    cross_edge: np.ndarray
    colour: np.ndarray

    @classmethod
    def build(cls, graph: EdgeGraph, part: np.ndarray, names: tuple[str, ...]) -> PartLayout:
        """The layout of ``part`` (one id per vertex of ``graph``, -1 for none)."""
        part = np.asarray(part, dtype=np.int64)
        k = len(names)
        verts = np.flatnonzero(part >= 0)
        verts = verts[np.argsort(part[verts], kind="stable")]
        ptr = np.zeros(k + 1, dtype=np.int64)
        np.cumsum(np.bincount(part[verts], minlength=k), out=ptr[1:])
        E = graph.edges
        pa, pb = part[E[:, 0]], part[E[:, 1]]
        leave = pa != pb
        out_a = leave & (pa >= 0)  # the edge leaves a's part
        out_b = leave & (pb >= 0)
        cross_part = np.concatenate([pa[out_a], pb[out_b]])
        cross_i = np.concatenate([E[out_a, 0], E[out_b, 1]]).astype(np.int64)
        cross_j = np.concatenate([E[out_a, 1], E[out_b, 0]]).astype(np.int64)
        cross_edge = np.concatenate([np.flatnonzero(out_a), np.flatnonzero(out_b)])
        colour = _greedy_colours(k, pa[out_a & out_b], pb[out_a & out_b])
        return cls(part, tuple(names), ptr, verts.astype(np.int64), cross_part, cross_i,
                   cross_j, cross_edge.astype(np.int64), colour)

    @property
    def n_parts(self) -> int:
        """How many parts there are."""
        return len(self.names)

    @property
    def sizes(self) -> np.ndarray:
        """(P,) vertices per part."""
        return np.diff(self.ptr)

    @cached_property
    def vert_part(self) -> np.ndarray:
        """The part of each entry of :attr:`verts`."""
        return np.repeat(np.arange(self.n_parts, dtype=np.int64), self.sizes)


@nb.njit(cache=True, nogil=True)
def _place(P, R, slots, vert_part, verts, a, centre):  # pragma: no cover - compiled
    """``P[verts[s]] = R[p] a[s] + P[centre[p]]`` for each slot ``s`` (part ``p``): one
    pass, where NumPy's ``R[vert_part]`` alone is 9 doubles a vertex. A part's centre has
    ``a = 0``, so writing it keeps its value for the part's later vertices."""
    for i in range(slots.shape[0]):
        s = slots[i]
        p = vert_part[s]
        c = centre[p]
        cx, cy, cz = P[c, 0], P[c, 1], P[c, 2]
        v = verts[s]
        for r in range(3):
            P[v, r] = R[p, r, 0] * a[s, 0] + R[p, r, 1] * a[s, 1] + R[p, r, 2] * a[s, 2] + (
                cx if r == 0 else cy if r == 1 else cz)


def _greedy_colours(k: int, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Colours of ``k`` parts such that parts joined by an edge (a[i], b[i]) differ."""
    colour = np.full(k, -1, dtype=np.int64)
    if not len(a):
        colour[:] = 0
        return colour
    pairs = np.unique(np.stack([np.concatenate([a, b]), np.concatenate([b, a])], 1), axis=0)
    nbr_ptr = np.searchsorted(pairs[:, 0], np.arange(k + 1))
    for p in range(k):  # parts are few: a loop over them, not over vertices
        taken = set(colour[pairs[nbr_ptr[p]:nbr_ptr[p + 1], 1]].tolist())
        c = 0
        while c in taken:
            c += 1
        colour[p] = c
    return colour


@dataclass(frozen=True, eq=False)
class PartHolds:
    """What the constrained vertices make of each part (depends on the handle set).

    Attributes
    ----------
    kind : (P,) int8
        :data:`FREE`, :data:`PIVOT`, :data:`HINGE` or :data:`FIXED`.
    centre : (P,) int64
        The vertex a part turns about: its first vertex when free, its first handle
        otherwise.
    axis_end : (P,) int64
        A hinge's handle farthest from its centre (-1 for the other kinds).
    handles : list of (h_p,) int64
        Each part's constrained vertices (solver numbering).
    """

    kind: np.ndarray
    centre: np.ndarray
    axis_end: np.ndarray
    handles: list[np.ndarray]

    @property
    def held(self) -> np.ndarray:
        """(P,) bool: the parts with a constrained vertex."""
        return self.kind != FREE


def hold_parts(layout: PartLayout, constrained: np.ndarray, rest: np.ndarray) -> PartHolds:
    """How the constrained vertices (solver numbering) hold each part of ``layout``.

    Examples
    --------
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0]], float)
    >>> class G: edges = np.array([[0, 1], [1, 2], [0, 3]])
    >>> lay = PartLayout.build(G, np.zeros(4, np.int64), ("all",))
    >>> [KINDS[hold_parts(lay, np.array(c), V).kind[0]] for c in ([], [1], [0, 2], [0, 2, 3])]
    ['free', 'pivot', 'hinge', 'fixed']
    """
    k = layout.n_parts
    is_cons = np.zeros(len(layout.part), dtype=bool)
    is_cons[np.asarray(constrained, dtype=np.int64)] = True
    kind = np.zeros(k, dtype=np.int8)
    centre = layout.verts[layout.ptr[:-1]].copy()
    axis_end = np.full(k, -1, dtype=np.int64)
    handles = []
    size = float(np.ptp(rest, axis=0).max()) if len(rest) else 1.0
    for p in range(k):
        vs = layout.verts[layout.ptr[p]:layout.ptr[p + 1]]
        h = vs[is_cons[vs]]
        handles.append(h)
        if not len(h):
            continue
        centre[p] = h[0]
        X = rest[h] - rest[h[0]]
        reach = np.linalg.norm(X, axis=1)
        if len(h) == 1 or reach.max() <= 1e-12 * max(size, 1e-300):
            kind[p] = PIVOT
            continue
        sv = np.linalg.svd(X - X.mean(axis=0), compute_uv=False)
        if sv[1] <= 1e-6 * sv[0]:  # on one line: the rotation about it is free
            kind[p] = HINGE
            axis_end[p] = h[int(np.argmax(reach))]
        else:
            kind[p] = FIXED
    return PartHolds(kind, centre, axis_end, handles)


@dataclass(frozen=True, eq=False)
class PartSystem:
    """The reduced system of one handle set, and the part steps of the loop.

    Attributes
    ----------
    layout : PartLayout
    holds : PartHolds
    elimination : Elimination
        Free rows: the free vertices outside parts and the free parts' centres; the
        constrained vertices: the handles and anchors outside parts, then every vertex of a
        held part. The free parts' other vertices are in neither (they follow their centre).
    a : (v,) float
        ``a_v = v_v - v_centre`` for every part vertex (in ``layout.verts`` order).
    gather : (f, n) CSR
        ``B^T``: sums a vertex's row into its free row (a part's into its centre's).
    A_z : (n, z) CSR
        The columns of the global matrix of the vertices ``z`` lives on (``z_cols``).
    z_cols : (z,) int64
        The free parts' non-centre vertices, then the constrained vertices.
    n_followers : int
        How many of ``z_cols`` are free parts' non-centre vertices.
    cross_w : (c,) float
        ``D_e`` of the layout's crossing edges, for this energy.
    ref : (P, 3) float or None
        The point each part turns about in the local step, relative to its centre in rest
        coordinates (None: the centre itself; with ``diag``, a free part's centre of
        ``diag``).
    diag_moment : (P, 3) float or None
        ``sum_{v in P} d_v (a_v - ref_P)``: the diagonal term's share of ``M_P`` is minus
        its product with the turning point (None without ``diag``).
    interior : (owners, parts, Q) or None
        The energy's neighbourhoods that lie inside one part, that part, and ``Q_k``
        (None when not given the neighbourhoods).
    """

    layout: PartLayout
    holds: PartHolds
    elimination: Elimination
    a: np.ndarray
    gather: sp.csr_matrix
    A_z: sp.csr_matrix
    z_cols: np.ndarray
    n_followers: int
    cross_w: np.ndarray
    ref: np.ndarray | None = None
    diag_moment: np.ndarray | None = None
    interior: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    @classmethod
    def build(cls, layout: PartLayout, graph: EdgeGraph, system_w: np.ndarray,
              constrained: np.ndarray, name: str, remedy="",
              diag: np.ndarray | None = None, nbh=None) -> PartSystem:
        """Factorise the merged system for ``constrained`` (handles and anchors outside
        parts and inside them, solver numbering); ``diag`` (n,), solver numbering, adds
        ``sum_v d_v |x_v|^2`` to the energy (a mass term, see the module); ``nbh`` (the
        energy's :class:`~arapkit.arap.rings.Neighbourhoods`) lets the part fit hold the
        rotations of the neighbourhoods inside a part."""
        n = graph.n_vertices
        rest = graph.vertices
        holds = hold_parts(layout, constrained, rest)
        vp = layout.vert_part
        free_part = holds.kind[vp] == FREE
        held_verts = layout.verts[~free_part]
        is_cons = np.zeros(n, dtype=bool)
        is_cons[np.asarray(constrained, dtype=np.int64)] = True
        is_cons[layout.part >= 0] = False  # part handles are held through their part
        cons = np.concatenate([np.flatnonzero(is_cons), held_verts]).astype(np.int64)
        centre_of = holds.centre[vp]
        followers = layout.verts[free_part & (layout.verts != centre_of)]
        node = np.arange(n, dtype=np.int64)
        node[layout.verts[free_part]] = centre_of[free_part]
        E = graph.edges
        ends = node[E]
        keep = ends[:, 0] != ends[:, 1]
        # followers are listed as constrained for the split (they are no unknowns) and
        # then dropped: no edge reaches them any more, so their columns are empty
        d = None if diag is None else np.asarray(diag, dtype=np.float64)
        el = Elimination.from_edges(n, ends[keep], system_w[keep],
                                    np.concatenate([cons, followers]), name, remedy,
                                    # a merged row holds its part's whole diagonal
                                    diag=None if d is None else np.bincount(node, d, n))
        el = Elimination(el.free, cons, el.slot, el.A_fc[:, :len(cons)].tocsr(), el.factor)
        rows = el.slot[node]
        mine = rows >= 0
        gather = sp.csr_matrix((np.ones(int(mine.sum())), (rows[mine], np.flatnonzero(mine))),
                               shape=(len(el.free), n))
        a, b = E[:, 0], E[:, 1]
        L = sp.csc_matrix((np.concatenate([-system_w, -system_w, system_w, system_w]),
                           (np.concatenate([a, b, a, b]), np.concatenate([b, a, a, b]))),
                          shape=(n, n))
        if d is not None:
            L = (L + sp.diags(d)).tocsc()
        z_cols = np.concatenate([followers, cons]).astype(np.int64)
        A_z = L[:, z_cols].tocsr()
        a_v = rest[layout.verts] - rest[centre_of]
        ref = dm = None
        if d is not None:
            k = layout.n_parts
            dv = d[layout.verts]
            d_p = np.bincount(vp, dv, k)
            first = np.stack([np.bincount(vp, dv * a_v[:, c], k) for c in range(3)], axis=1)
            ref = np.zeros((k, 3))
            turn = (holds.kind == FREE) & (d_p > 0)  # held parts turn about their handles
            ref[turn] = first[turn] / d_p[turn, None]
            dm = first - d_p[:, None] * ref
        return cls(layout, holds, el, a_v, gather, A_z, z_cols, len(followers),
                   system_w[layout.cross_edge], ref, dm,
                   None if nbh is None else _interior(layout, nbh, a_v))

    # -- the parts' motions ------------------------------------------------------------
    def place(self, P: np.ndarray, R: np.ndarray, slots: np.ndarray | None = None) -> None:
        """Put the vertices of the moving parts (all but the fixed ones; or the entries
        ``slots`` of ``layout.verts``) at ``R_P a_v + P[centre]``, in place."""
        sel = self._moving_slots if slots is None else slots
        _place(P, np.ascontiguousarray(R), sel, self.layout.vert_part, self.layout.verts,
               self.a, self.holds.centre)

    @cached_property
    def _moving_slots(self) -> np.ndarray:
        """The entries of ``layout.verts`` in moving parts."""
        return np.flatnonzero(self.holds.kind[self.layout.vert_part] != FIXED)

    def extrapolated(self, A: np.ndarray, plain: np.ndarray) -> np.ndarray:
        """The parts' rotations of an extrapolated iterate (Anderson's): the rotation
        nearest ``A`` (k, 3, 3) for a free part, ``plain``'s (the plain step's) for a held
        one, whose rotation its handles constrain (a hinge turns about its line only).

        Examples
        --------
        >>> from arapkit.arap.problem import ARAPProblem
        >>> from arapkit.mesh.shapes import bar
        >>> p = ARAPProblem.from_mesh(bar(segments=(8, 2, 2)), [0])
        >>> part = np.full(p.n_vertices, -1); part[p.iperm[40:60]] = 0
        >>> ps = PartSystem.build(PartLayout.build(p.graph, part, ("m",)), p.graph,
        ...                       p.energy.system_w, p.iperm[[0]], "bar")
        >>> R = ps.extrapolated(np.array([[[1.1, 0.1, 0], [-0.1, 0.9, 0], [0, 0, 1.0]]]),
        ...                     np.eye(3)[None])
        >>> round(float(np.linalg.det(R[0])), 12), bool(np.allclose(R[0] @ R[0].T, np.eye(3)))
        (1.0, True)
        """
        out = nearest_rotations(np.ascontiguousarray(A))
        held = self.holds.kind != FREE
        out[held] = plain[held]
        return out

    def sync(self, P: np.ndarray) -> np.ndarray:
        """The parts' rotations fitted to ``P`` (a start shape), with ``P`` made rigid on
        them: free parts by their best rigid fit, held ones about their centre."""
        lay, hold = self.layout, self.holds
        R, t = rigid_motions(self.a, P[lay.verts], lay.vert_part, lay.n_parts)
        free = np.flatnonzero(hold.kind == FREE)
        P[hold.centre[free]] = t[free]
        self.place(P, R)
        return R

    def moments(self, P: np.ndarray, b: np.ndarray, own: np.ndarray | None = None,
                R: np.ndarray | None = None) -> np.ndarray:
        """``M_P`` of every part at positions ``P`` and vertex right-hand sides ``b``;
        ``own`` (:meth:`own_moments`, which does not move with ``P``) when known. With a
        turning point (:attr:`ref`), the parts' rotations ``R`` place it and ``a_v`` is
        taken from it."""
        lay = self.layout
        k = lay.n_parts
        M = self.own_moments(b) if own is None else own.copy()
        g = self._turning_points(P, R)
        d = P[lay.cross_j] - g[lay.cross_part]
        a = self.a[self._cross_slot]
        if self.ref is not None:
            a = a - self.ref[lay.cross_part]
        ac = a * self.cross_w[:, None]
        for r in range(3):
            for c in range(3):
                M[:, r, c] += np.bincount(lay.cross_part, ac[:, r] * d[:, c], k)
        if self.diag_moment is not None:
            M -= self.diag_moment[:, :, None] * g[:, None, :]
        return M

    def _turning_points(self, P: np.ndarray, R: np.ndarray | None) -> np.ndarray:
        """(P, 3) where each part's turning point is: its centre, or ``ref`` placed."""
        t = P[self.holds.centre]
        return t if self.ref is None else t + np.einsum("pab,pb->pa", R, self.ref)

    def own_moments(self, b: np.ndarray) -> np.ndarray:
        """``sum_{v in P} (a_v - ref_P) b_v^T`` of every part: ``M_P`` less its crossing
        edges and diagonal term."""
        lay = self.layout
        k = lay.n_parts
        bv = b[lay.verts]
        M = np.empty((k, 3, 3))
        for r in range(3):
            for c in range(3):
                M[:, r, c] = np.bincount(lay.vert_part, self.a[:, r] * bv[:, c], k)
        if self.ref is not None:
            bsum = np.stack([np.bincount(lay.vert_part, bv[:, c], k) for c in range(3)], 1)
            M -= self.ref[:, :, None] * bsum[:, None, :]
        return M

    @cached_property
    def _cross_slot(self) -> np.ndarray:
        """Where each crossing edge's inner vertex is in ``layout.verts``."""
        lay = self.layout
        slot = np.full(len(lay.part), -1, dtype=np.int64)
        slot[lay.verts] = np.arange(len(lay.verts))
        return slot[lay.cross_i]

    @cached_property
    def _colours(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """The moving parts colour by colour, each with its entries of ``layout.verts``."""
        lay = self.layout
        moving = self.holds.kind != FIXED
        out = []
        for c in np.unique(lay.colour[moving]):
            parts = np.flatnonzero(moving & (lay.colour == c))
            out.append((parts, np.flatnonzero(np.isin(lay.vert_part, parts))))
        return out

    def fit(self, P: np.ndarray, b: np.ndarray, R: np.ndarray,
            R_own: np.ndarray | None = None) -> float:
        """The local step of the parts: each moving part's best rotation with its turning
        point held (its centre, or :attr:`ref`), colour by colour (``P`` and ``R`` updated
        in place). Returns the energy's change, ``-2 sum_P tr((R_new - R_old) M_P)`` (not
        positive, up to round-off). ``R_own`` (the energy's rotations from the local step)
        lets the neighbourhoods inside a part turn with it (see the module); those
        rotations are set to their part's."""
        hold = self.holds
        dE = 0.0
        own = self.own_moments(b) if self._colours else None
        inside = self.interior if R_own is not None else None
        if own is not None and inside is not None and len(inside[0]):
            ks, kp, Q = inside
            QR = Q @ R_own[ks].transpose(0, 2, 1)
            for r in range(3):
                for c in range(3):
                    own[:, r, c] -= np.bincount(kp, QR[:, r, c], self.layout.n_parts)
        for parts, slots in self._colours:
            M = self.moments(P, b, own, R)[parts]
            old = R[parts]
            new = np.empty_like(M)
            # serial: a few matrices, where a parallel region would cost a time slice
            fit_rotation_range(np.ascontiguousarray(M), new, 0, len(M))
            hinge = hold.kind[parts] == HINGE
            if hinge.any():
                new[hinge] = self._hinge(P, parts[hinge], old[hinge], M[hinge])
            # the exact block minimiser: taken even when round-off makes it look a hair
            # worse (refusing it would stall the positions at sqrt(eps))
            gain = np.einsum("pab,pba->p", new, M) - np.einsum("pab,pba->p", old, M)
            R[parts] = new
            dE -= 2.0 * float(gain.sum())
            if self.ref is not None:  # the turning point stays: the centre moves
                c = hold.centre[parts]
                P[c] += np.einsum("pab,pb->pa", old - new, self.ref[parts])
            self.place(P, R, slots)
        if inside is not None:
            R_own[inside[0]] = R[inside[1]]
        return dE

    def _hinge(self, P: np.ndarray, parts: np.ndarray, old: np.ndarray,
               M: np.ndarray) -> np.ndarray:
        """Best rotations ``Q(theta) R_old`` about each hinge's (target) axis: with
        ``N = R_old M``, ``tr(Q N)`` peaks at ``theta = atan2(tr(K N), tr N - n.N n)``."""
        hold = self.holds
        axis = P[hold.axis_end[parts]] - P[hold.centre[parts]]
        n = axis / np.linalg.norm(axis, axis=1, keepdims=True)
        N = old @ M
        K = np.zeros((len(parts), 3, 3))
        K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -n[:, 2], n[:, 1], -n[:, 0]
        K[:, 1, 0], K[:, 2, 0], K[:, 2, 1] = n[:, 2], -n[:, 1], n[:, 0]
        nNn = np.einsum("pa,pab,pb->p", n, N, n)
        theta = np.arctan2(np.einsum("pab,pba->p", K, N), np.trace(N, axis1=1, axis2=2) - nNn)
        c, s = np.cos(theta)[:, None, None], np.sin(theta)[:, None, None]
        Q = c * np.eye(3) + s * K + (1 - c) * n[:, :, None] * n[:, None, :]
        return Q @ old

    # -- the global step's right-hand side -------------------------------------------------
    def rhs(self, b: np.ndarray, P: np.ndarray, R: np.ndarray, out: np.ndarray) -> None:
        """``B^T (b - A z)``: ``z`` the free parts' offsets ``R_P a_v`` and the constrained
        positions (read from ``P``)."""
        lay = self.layout
        z = np.empty((len(self.z_cols), 3))
        nf = self.n_followers
        if nf:
            sel = self._follower_slots
            vp = lay.vert_part[sel]
            z[:nf] = np.einsum("vab,vb->va", R[vp], self.a[sel])
        z[nf:] = P[self.z_cols[nf:]]
        out[:] = self.gather @ (b - self.A_z @ z)

    @cached_property
    def _follower_slots(self) -> np.ndarray:
        """Where the followers (``z_cols[:n_followers]``) are in ``layout.verts``."""
        lay = self.layout
        slot = np.full(len(lay.part), -1, dtype=np.int64)
        slot[lay.verts] = np.arange(len(lay.verts))
        return slot[self.z_cols[:self.n_followers]]

    def rest_rhs(self, b_rest: np.ndarray) -> np.ndarray:
        """The reduced right-hand side at identity rotations, less the constrained
        vertices' share (the loop subtracts ``A_fc C``), as an (n, 3) array whose free
        rows hold it."""
        nf = self.n_followers
        z = self.a[self._follower_slots] if nf else np.zeros((0, 3))
        r = self.gather @ (b_rest - self.A_z[:, :nf] @ z)
        out = np.zeros_like(b_rest)
        out[self.elimination.free] = r
        return out

    # -- the held parts' placement ---------------------------------------------------------
    def constrained_positions(self, rest: np.ndarray, known: np.ndarray, diag: float,
                              source: str) -> np.ndarray:
        """Positions of ``elimination.constrained``: the vertices outside parts read from
        ``known`` (solver numbering; only their rows and the parts' handles' are read), the
        held parts' placed by :meth:`held_positions`."""
        cons = self.elimination.constrained
        outside = int(np.count_nonzero(self.layout.part[cons] < 0))
        C = np.empty((len(cons), 3))
        C[:outside] = known[cons[:outside]]
        C[outside:] = self.held_positions(rest, known, diag, source)
        return C

    def held_positions(self, rest: np.ndarray, known: np.ndarray, diag: float,
                       source: str) -> np.ndarray:
        """Where the held parts' vertices start: fixed parts by the best rigid fit to their
        handles, hinges turned as that fit, pivots translated. ``known`` holds the
        constrained vertices' positions (solver numbering; other rows unread).

        Raises a one-line InputError naming the part when no rigid motion meets its
        handles to within :data:`PART_TOL` of the diagonal ``diag``.
        """
        lay, hold = self.layout, self.holds
        out = []
        for p in np.flatnonzero(hold.held):
            h = hold.handles[p]
            X, Y = rest[h], known[h]
            R, t = rigid_motions(X, Y, np.zeros(len(h), dtype=np.int64), 1)
            R, t = R[0], t[0]
            misfit = float(np.linalg.norm(X @ R.T + t - Y, axis=1).max())
            if not misfit <= PART_TOL * diag:  # also NaN
                raise InputError(
                    f"{source}: rigid part {lay.names[p]!r}: no rigid motion meets its "
                    f"{len(h)} handle vertices (the best misses by {misfit:.3g}, "
                    f"{misfit / diag:.2g} of the diagonal); move its handles as one, or "
                    "take them out of the part")
            if hold.kind[p] == PIVOT:
                R = np.eye(3)
            vs = lay.verts[lay.ptr[p]:lay.ptr[p + 1]]
            c = hold.centre[p]
            out.append((rest[vs] - rest[c]) @ R.T + known[c])
        return np.concatenate(out) if out else np.zeros((0, 3))



def _interior(layout: PartLayout, nbh, a: np.ndarray) -> tuple[np.ndarray, ...]:
    """The owners whose neighbourhood (every vertex its right-hand side touches) lies in one
    part, that part, and ``Q_k = sum_v a_v c_kv^T`` (``a`` in ``layout.verts`` order)."""
    ptr, idx, coef = nbh.disk_ptr, nbh.disk_idx, nbh.disk_coef
    sizes = np.diff(ptr)
    has = np.flatnonzero(sizes > 0)
    pv = layout.part[idx]
    if not len(has):
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3, 3))
    lo, hi = np.minimum.reduceat(pv, ptr[has]), np.maximum.reduceat(pv, ptr[has])
    inner = (lo == hi) & (lo >= 0)
    owners, parts = has[inner].astype(np.int64), lo[inner].astype(np.int64)
    mine = np.repeat(np.isin(np.arange(len(sizes)), owners), sizes)
    local = np.repeat(np.arange(len(owners)), sizes[owners])
    slot = np.full(len(layout.part), -1, dtype=np.int64)
    slot[layout.verts] = np.arange(len(layout.verts))
    av, cv = a[slot[idx[mine]]], coef[mine]
    Q = np.empty((len(owners), 3, 3))
    for r in range(3):
        for c in range(3):
            Q[:, r, c] = np.bincount(local, av[:, r] * cv[:, c], len(owners))
    return owners, parts, Q


def nearest_rotations(A: np.ndarray) -> np.ndarray:
    """(k, 3, 3) the rotation nearest each of ``A`` (k, 3, 3) in the Frobenius norm: the
    one maximising ``tr(R^T A) = tr(R A^T)`` (an extrapolated rotation made one again).

    Examples
    --------
    >>> R = nearest_rotations(np.array([[[1.1, 0.1, 0], [-0.1, 0.9, 0], [0, 0, 1]]]))
    >>> bool(np.allclose(R[0] @ R[0].T, np.eye(3))), round(float(np.linalg.det(R[0])), 12)
    (True, 1.0)
    """
    out = np.empty_like(A)
    fit_rotation_range(np.ascontiguousarray(A.transpose(0, 2, 1)), out, 0, len(A))
    return out
