"""CPU backend of the local/global solver: compiled kernels and their thread layout.

A backend turns an :class:`~arapkit.arap.problem.ARAPProblem` into the four operations the
loop (:mod:`arapkit.arap.loop`) needs, all in internal vertex numbering:

* ``local(P, R, R_prev) -> E``: fit the rotations to P (into R), scatter the next
  right-hand side and return the energy at (P, R);
* ``rhs(fixed_rhs, out)``: the reduced right-hand side from the last local step;
* ``solve(rhs, out)``: the global step with the problem's factor;
* ``scatter(X, idx, P)``, ``gather(P, idx, scale)`` and ``vertex_energy(P, R)``.

This one runs numba kernels on CPU threads; another device (e.g. torch/CUDA) is one more
module with the same methods.

Layout: the vertices are split into chunks of equal work, one parallel region per local
step. Each chunk scatters its share of the right-hand side into a private window of a
buffer (no races); with the problem's bandwidth-reducing order the windows barely overlap,
and a serial pass sums the windows that cover each vertex.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from ..problem import ARAPProblem
from ..rotations import fit_rotation_range, fit_rotations

__all__ = ["CPUBackend"]

_NO_INT = np.zeros(0, dtype=np.int64)
_NO_INT32 = np.zeros(0, dtype=np.int32)
_NO_FLOAT = np.zeros(0)
_NO_ROT = np.zeros((0, 3, 3))


# -- compiled kernels ---------------------------------------------------------------


#: vertices whose covariances and rotations a chunk holds at once: two blocks of 36 KiB
#: stay in cache, where one (n, 3, 3) array of covariances was 126 MB at 1.75M vertices
_BLOCK = 512


@nb.njit(parallel=True, cache=True, nogil=True)
def local_step(P, chunk_ptr, disk_ptr, disk_idx, disk_coef, up_ptr, up_idx, up_w, R, buf,
               win_lo, win_off, partial, rc_ptr, rc_idx, rc_w, R_prev, centres):
    """Fused local step: covariances, rotations and the scatter of the next right-hand side.

    Per chunk of consecutive k (one parallel region per iteration: on a shared machine
    every extra region is a chance to wait for a descheduled thread), block by block of
    :data:`_BLOCK` vertices:

    1. ``S_k = sum_v c_kv (p'_v - p'_k)^T``. Subtracting p'_k is exact (the c_kv of a
       neighbourhood sum to zero) and keeps the sums well conditioned far from the origin.
       The upper Laplacian row of k adds its share of ``sum_e d_e w_e |e'|^2`` while those
       vertices are in cache.
    2. ``R_k`` for the block at once (the vectorised kernel of :mod:`arapkit.arap.rotations`).
    3. ``tr(R_k S_k)`` and ``b_v += R_k c_kv``. Scattering from k needs no transposed copy
       of the coefficients; each chunk adds into its own window
       ``[win_lo[c], win_lo[c] + len)`` of ``buf`` (no races), and with a bandwidth-reducing
       vertex order the windows barely overlap.

    The covariances live only in the block's scratch: the per-vertex arithmetic and the
    order of the chunk's sums are those of a whole-chunk pass, so the result is the same
    to the bit. ``partial[c] = (sum tr(R_k S_k), quadratic term)`` for chunk c.

    A rotation coupling (SR-ARAP) adds ``sum_j rc_w R_prev[j]^T`` to ``S_k``; energies
    without one pass an empty ``rc_ptr`` and skip it. An owner past the vertices
    (``k >= n``: a triangle's rotation) is centred on ``centres[k - n]`` and has no row of
    the Laplacian.
    """
    coupled = rc_ptr.shape[0] > 0
    nv = P.shape[0]
    for c in nb.prange(chunk_ptr.shape[0] - 1):
        S = np.empty((_BLOCK, 3, 3))
        Rb = np.empty((_BLOCK, 3, 3))
        off = win_off[c] - win_lo[c]
        for q in range(win_off[c], win_off[c + 1]):
            buf[q, 0] = 0.0
            buf[q, 1] = 0.0
            buf[q, 2] = 0.0
        quad = 0.0
        tr = 0.0
        for b0 in range(chunk_ptr[c], chunk_ptr[c + 1], _BLOCK):
            b1 = min(b0 + _BLOCK, chunk_ptr[c + 1])
            for k in range(b0, b1):
                s00 = s01 = s02 = s10 = s11 = s12 = s20 = s21 = s22 = 0.0
                o = k if k < nv else centres[k - nv]
                px, py, pz = P[o, 0], P[o, 1], P[o, 2]
                for t in range(disk_ptr[k], disk_ptr[k + 1]):
                    v = disk_idx[t]
                    dx, dy, dz = P[v, 0] - px, P[v, 1] - py, P[v, 2] - pz
                    c0, c1, c2 = disk_coef[t, 0], disk_coef[t, 1], disk_coef[t, 2]
                    s00 += c0 * dx
                    s01 += c0 * dy
                    s02 += c0 * dz
                    s10 += c1 * dx
                    s11 += c1 * dy
                    s12 += c1 * dz
                    s20 += c2 * dx
                    s21 += c2 * dy
                    s22 += c2 * dz
                for t in range(up_ptr[min(k, nv)], up_ptr[min(k + 1, nv)]):
                    j = up_idx[t]
                    dx, dy, dz = P[j, 0] - px, P[j, 1] - py, P[j, 2] - pz
                    quad += up_w[t] * (dx * dx + dy * dy + dz * dz)
                i = k - b0
                S[i, 0, 0], S[i, 0, 1], S[i, 0, 2] = s00, s01, s02
                S[i, 1, 0], S[i, 1, 1], S[i, 1, 2] = s10, s11, s12
                S[i, 2, 0], S[i, 2, 1], S[i, 2, 2] = s20, s21, s22
            if coupled:
                # a separate pass: inside the loop above it slows the uncoupled energies
                for k in range(b0, b1):
                    for t in range(rc_ptr[k], rc_ptr[k + 1]):
                        j, cw = rc_idx[t], rc_w[t]
                        for a in range(3):
                            for b in range(3):
                                S[k - b0, a, b] += cw * R_prev[j, b, a]
            fit_rotation_range(S, Rb, 0, b1 - b0)
            for k in range(b0, b1):
                i = k - b0
                r00, r01, r02 = Rb[i, 0, 0], Rb[i, 0, 1], Rb[i, 0, 2]
                r10, r11, r12 = Rb[i, 1, 0], Rb[i, 1, 1], Rb[i, 1, 2]
                r20, r21, r22 = Rb[i, 2, 0], Rb[i, 2, 1], Rb[i, 2, 2]
                R[k, 0, 0], R[k, 0, 1], R[k, 0, 2] = r00, r01, r02
                R[k, 1, 0], R[k, 1, 1], R[k, 1, 2] = r10, r11, r12
                R[k, 2, 0], R[k, 2, 1], R[k, 2, 2] = r20, r21, r22
                for a in range(3):
                    tr += (Rb[i, a, 0] * S[i, 0, a] + Rb[i, a, 1] * S[i, 1, a]
                           + Rb[i, a, 2] * S[i, 2, a])
                for t in range(disk_ptr[k], disk_ptr[k + 1]):
                    q = off + disk_idx[t]
                    c0, c1, c2 = disk_coef[t, 0], disk_coef[t, 1], disk_coef[t, 2]
                    buf[q, 0] += r00 * c0 + r01 * c1 + r02 * c2
                    buf[q, 1] += r10 * c0 + r11 * c1 + r12 * c2
                    buf[q, 2] += r20 * c0 + r21 * c1 + r22 * c2
        partial[c, 0] = tr
        partial[c, 1] = quad


# Serial on purpose: these are light O(n) passes, and on a shared machine a parallel region
# costs a scheduler time slice whenever another process holds one of the cores.
@nb.njit(cache=True, nogil=True)
def gather_rhs(buf, win_lo, win_off, chunk_ptr, cover_ptr, cover_idx, slot, fixed_rhs, rhs):
    """``rhs[slot[v]] = b_v - (A_fc C)_v`` for free v, summing the windows that cover v.

    The chunks' owner ranges run over the vertices first: the vertices of chunk c are its
    range's part below n (owners past the vertices have no right-hand side of their own).
    """
    nv = slot.shape[0]
    for c in range(chunk_ptr.shape[0] - 1):
        for v in range(chunk_ptr[c], min(chunk_ptr[c + 1], nv)):
            s = slot[v]
            if s < 0:
                continue
            b0 = -fixed_rhs[s, 0]
            b1 = -fixed_rhs[s, 1]
            b2 = -fixed_rhs[s, 2]
            for t in range(cover_ptr[c], cover_ptr[c + 1]):
                d = cover_idx[t]
                q = v - win_lo[d]
                if q >= 0 and q < win_off[d + 1] - win_off[d]:
                    q += win_off[d]
                    b0 += buf[q, 0]
                    b1 += buf[q, 1]
                    b2 += buf[q, 2]
            rhs[s, 0] = b0
            rhs[s, 1] = b1
            rhs[s, 2] = b2


@nb.njit(cache=True, nogil=True)
def scatter_rows(X, idx, P):
    """``P[idx[i]] = X[i]``."""
    for i in range(idx.shape[0]):
        v = idx[i]
        P[v, 0] = X[i, 0]
        P[v, 1] = X[i, 1]
        P[v, 2] = X[i, 2]


@nb.njit(cache=True, nogil=True)
def gather_rows(P, idx, scale, out):
    """``out[i] = P[idx[i]] * scale``."""
    for i in range(idx.shape[0]):
        v = idx[i]
        out[i, 0] = P[v, 0] * scale
        out[i, 1] = P[v, 1] * scale
        out[i, 2] = P[v, 2] * scale


@nb.njit(cache=True, nogil=True)
def _windows(chunk_ptr, disk_ptr, disk_idx):
    """Smallest index range each chunk's disks touch."""
    n_chunks = chunk_ptr.shape[0] - 1
    lo = np.empty(n_chunks, dtype=np.int64)
    hi = np.empty(n_chunks, dtype=np.int64)
    for c in range(n_chunks):
        a, b = 1 << 62, -1
        for t in range(disk_ptr[chunk_ptr[c]], disk_ptr[chunk_ptr[c + 1]]):
            v = disk_idx[t]
            a = min(a, v)
            b = max(b, v)
        lo[c], hi[c] = (a, b + 1) if b >= 0 else (chunk_ptr[c], chunk_ptr[c])
    return lo, hi


@nb.njit(parallel=True, cache=True, nogil=True)
def neighbourhood_energies(P, P0, edges, w, edge_ptr, edge_idx, entry_w, R, out):
    """Each neighbourhood's term, summed edge by edge (no cancellation).

    The weight of entry t is ``entry_w[t]``, or ``w[edge]`` when ``entry_w`` is empty.
    """
    per_entry = entry_w.shape[0] > 0
    for k in nb.prange(out.shape[0]):
        acc = 0.0
        for t in range(edge_ptr[k], edge_ptr[k + 1]):
            e = edge_idx[t]
            we = entry_w[t] if per_entry else w[e]
            i, j = edges[e, 0], edges[e, 1]
            for a in range(3):
                d = (P[i, a] - P[j, a]) - (
                    R[k, a, 0] * (P0[i, 0] - P0[j, 0])
                    + R[k, a, 1] * (P0[i, 1] - P0[j, 1])
                    + R[k, a, 2] * (P0[i, 2] - P0[j, 2])
                )
                acc += we * d * d
        out[k] = acc




# -- the backend --------------------------------------------------------------------


class CPUBackend:
    """Kernels and thread layout for one problem's energy (see the module docstring).

    The layout depends only on the energy (not on the handles), so a new handle set keeps
    the backend; :meth:`bind` points it at the new problem's elimination.

    Examples
    --------
    >>> import numpy as np
    >>> from arapkit.mesh.shapes import bar
    >>> p = ARAPProblem.from_mesh(bar(), [0])
    >>> be = CPUBackend(p)
    >>> R = np.empty((p.n_vertices, 3, 3))
    >>> abs(be.local(p.vertices.copy(), R)) < 1e-12  # rest shape: zero energy
    True
    """

    name = "cpu"
    #: the positions' columns (the planar backend's are 2)
    dim = 3

    def __init__(self, problem: ARAPProblem) -> None:
        self.problem = problem
        en = problem.energy
        nbh = en.nbh
        n = problem.n_vertices
        E = problem.edges
        # upper rows of the Laplacian of D_e, for the quadratic term of the energy
        a, b = E.min(axis=1), E.max(axis=1)
        order = np.argsort(a, kind="stable")
        self.up_ptr = np.zeros(n + 1, dtype=np.int64)
        np.cumsum(np.bincount(a, minlength=n), out=self.up_ptr[1:])
        self.up_idx = b[order].astype(np.int32)
        self.up_w = en.system_w[order]
        if en.coupling is not None:
            self.rc_ptr, self.rc_idx, self.rc_w = en.coupling
        else:
            self.rc_ptr, self.rc_idx, self.rc_w = _NO_INT, _NO_INT, _NO_FLOAT
        self.entry_w = _NO_FLOAT if en.entry_w is None else en.entry_w
        self.centres = _NO_INT32 if en.centres is None else en.centres
        self.rest_term = en.rest_term
        self.nonneg = bool((problem.w >= 0).all())
        self._make_chunks(nbh, en.n_owners)
        self.slot = _NO_INT
        self._all: tuple[np.ndarray, np.ndarray] | None = None  # for vertex_rhs

    def bind(self, problem: ARAPProblem, elimination=None) -> CPUBackend:
        """Use ``problem`` (same energy, possibly other handles); factorises if needed.

        ``elimination`` (an :class:`~arapkit.arap.constraints.Elimination` of another
        system on the same vertices, e.g. a dynamics step's, :mod:`arapkit.arap.dynamics`)
        sets the free/constrained split of :meth:`rhs` instead of the problem's own, which
        is then not factorised.
        """
        assert problem.energy is self.problem.energy
        self.problem = problem
        self.slot = (problem.elimination if elimination is None else elimination).slot
        return self

    def _make_chunks(self, nbh, n: int) -> None:
        """Split the ``n`` owners k into chunks of equal work and give each a private
        scatter window."""
        threads = nb.get_num_threads()
        work = np.diff(nbh.disk_ptr) + 16  # + the rotation fit
        cum = np.concatenate([[0], np.cumsum(work)])
        n_chunks = max(1, min(8 * threads, n // 256))
        while True:
            cuts = np.searchsorted(cum, np.linspace(0, cum[-1], n_chunks + 1))
            cuts[0], cuts[-1] = 0, n
            chunk_ptr = np.unique(cuts).astype(np.int64)
            lo, hi = _windows(chunk_ptr, nbh.disk_ptr, nbh.disk_idx)
            total = int((hi - lo).sum())
            # a poor vertex order makes windows span the mesh: fewer chunks bound the memory
            if total <= 3 * n or n_chunks <= threads:
                break
            n_chunks = max(threads, n_chunks // 2)
        win_off = np.zeros(len(lo) + 1, dtype=np.int64)
        np.cumsum(hi - lo, out=win_off[1:])
        cover = [np.flatnonzero((lo < chunk_ptr[c + 1]) & (hi > chunk_ptr[c]))
                 for c in range(len(lo))]
        self.chunk_ptr = chunk_ptr
        self.win_lo = lo
        self.win_off = win_off
        self.cover_ptr = np.concatenate([[0], np.cumsum([len(x) for x in cover])]).astype(
            np.int64)
        self.cover_idx = np.concatenate(cover).astype(np.int64)
        self.buf = np.zeros((total, 3))
        self.partial = np.zeros((len(lo), 2))

    def local(self, P: np.ndarray, R: np.ndarray, R_prev: np.ndarray = _NO_ROT) -> float:
        """Fit rotations to P (in place in R), scatter the right-hand side; return E(P, R).

        ``R_prev`` (the last rotations) is read only by energies with a rotation coupling.
        """
        nbh = self.problem.energy.nbh
        local_step(P, self.chunk_ptr, nbh.disk_ptr, nbh.disk_idx, nbh.disk_coef,
                   self.up_ptr, self.up_idx, self.up_w, R, self.buf,
                   self.win_lo, self.win_off, self.partial,
                   self.rc_ptr, self.rc_idx, self.rc_w, R_prev, self.centres)
        tr, quad = self.partial.sum(axis=0)
        E = float(quad + self.rest_term - 2.0 * tr)
        # with weights >= 0, E is a sum of squares: a negative value is the round-off of
        # the expanded form, and the user must never be shown one
        return max(E, 0.0) if self.nonneg else E

    def rhs(self, fixed_rhs: np.ndarray, rhs: np.ndarray, slot: np.ndarray | None = None) -> None:
        """Right-hand side of the free vertices from the last local step.

        ``slot`` (each vertex's row, -1 for a constrained one) replaces the bound problem's
        split, for a caller that solves a system of its own with the same rotations (the
        template fit of :mod:`arapkit.methods.fit`, whose matrix adds its data term).
        """
        gather_rhs(self.buf, self.win_lo, self.win_off, self.chunk_ptr, self.cover_ptr,
                   self.cover_idx, self.slot if slot is None else slot, fixed_rhs, rhs)

    def terms(self) -> tuple[float, float]:
        """``(sum_k tr(R_k S_k), sum_e D_e |e'|^2)`` of the last local step: the energy is
        ``quad + rest_term - 2 tr``, and with a global scale s of the rest shape
        ``quad + s^2 rest_term - 2 s tr``."""
        tr, quad = self.partial.sum(axis=0)
        return float(tr), float(quad)

    def solve(self, rhs: np.ndarray, out: np.ndarray) -> np.ndarray:
        """Global step: ``A_ff^{-1} rhs``."""
        return self.problem.elimination.solve(rhs, out)

    def vertex_rhs(self, out: np.ndarray) -> np.ndarray:
        """``b_v = sum_k R_k c_kv`` of every vertex from the last local step, into ``out``
        (n, 3): rigid parts (:mod:`arapkit.arap.parts`) read their vertices' share."""
        n = len(out)
        if self._all is None or len(self._all[0]) != n:
            self._all = (np.arange(n, dtype=np.int64), np.zeros((n, 3)))
        gather_rhs(self.buf, self.win_lo, self.win_off, self.chunk_ptr, self.cover_ptr,
                   self.cover_idx, self._all[0], self._all[1], out)
        return out

    @staticmethod
    def scatter(X: np.ndarray, idx: np.ndarray, P: np.ndarray) -> None:
        """``P[idx[i]] = X[i]``."""
        scatter_rows(X, idx, P)

    @staticmethod
    def gather(P: np.ndarray, idx: np.ndarray, scale: float) -> np.ndarray:
        """``P[idx] * scale``, a new array, in one pass: NumPy's index-then-multiply took
        18 ms at 437K against 1.7 ms, on every iteration a callback watches (0.5 s of the
        editor's release)."""
        out = np.empty((len(idx), 3))
        gather_rows(P, idx, scale, out)
        return out

    def vertex_energy(self, P: np.ndarray, R: np.ndarray) -> np.ndarray:
        """Each vertex's term of the energy (internal numbering).

        With a rotation coupling, vertex k's term includes ``sum_j c_kj |R_k - R_j|^2``.
        An owner past the vertices (a triangle) shares its term evenly among the vertices
        it touches; given the vertices' rotations only, its own are fitted to P.
        """
        p = self.problem
        nbh = p.energy.nbh
        n, K = len(P), p.energy.n_owners
        if len(R) < K:
            R = np.concatenate([R, self._extra_rotations(P)])
        out = self._neighbourhood_energies(P, R)
        if len(self.rc_ptr):
            k = np.repeat(np.arange(n), np.diff(self.rc_ptr))
            d = ((R[k] - R[self.rc_idx]) ** 2).sum(axis=(1, 2))
            out[:n] += np.bincount(k, self.rc_w * d, n)
        if K > n:
            sizes = np.diff(nbh.disk_ptr[n:])
            share = np.repeat(out[n:] / np.maximum(sizes, 1), sizes)
            out = out[:n] + np.bincount(nbh.disk_idx[nbh.disk_ptr[n]:], share, n)
        return out

    def _neighbourhood_energies(self, P: np.ndarray, R: np.ndarray) -> np.ndarray:
        """Each owner's own term of the energy (before couplings and sharing)."""
        p = self.problem
        nbh = p.energy.nbh
        out = np.empty(p.energy.n_owners)
        neighbourhood_energies(P, p.vertices, p.edges, p.w, nbh.edge_ptr, nbh.edge_idx,
                               self.entry_w, R, out)
        return out

    def _extra_rotations(self, P: np.ndarray) -> np.ndarray:
        """The best rotations of the owners past the vertices for positions P."""
        return fit_rotations(self._owner_covariances(P, self.problem.energy.nbh.disk_coef))

    def _owner_covariances(self, P: np.ndarray, coef: np.ndarray) -> np.ndarray:
        """The covariance of each owner past the vertices (a triangle) for positions P."""
        nbh = self.problem.energy.nbh
        n = len(P)
        lo = nbh.disk_ptr[n]
        sizes = np.diff(nbh.disk_ptr[n:])
        owner = np.repeat(np.arange(len(sizes)), sizes)
        d = P[nbh.disk_idx[lo:]] - P[self.centres[owner]]
        dim = P.shape[1]
        S = np.zeros((len(sizes), dim, dim))
        np.add.at(S, owner, coef[lo:, :, None] * d[:, None, :])
        return S
