"""The planar CPU backend: the loop's kernels in 2D, with 2 x 2 rotations in closed form.

The same operations as :class:`~arapkit.arap.backends.cpu.CPUBackend` (``local``, ``rhs``,
``solve``, ``scatter``, ``gather``, ``vertex_energy``), on ``(n, 2)`` positions: the energy's
structure is the 3D one of the planar rest shape (its coefficients' z is 0), the factor is
the same Laplacian, and only the local step differs (:mod:`arapkit.arap.rotations2d`). The
thread layout (chunks of equal work, private scatter windows) is the CPU backend's.

A pin may carry a turn (Photoshop's pin rotation): :meth:`PlanarBackend.hold_rotations`
holds the rotations of given owners at given angles instead of fitting them. The energy is
the same sum with those ``R_k`` fixed; the local step minimises it over the others and the
global step over the positions, so the loop is still a descent method.

Examples
--------
>>> import numpy as np
>>> from arapkit.arap.problem import ARAPProblem
>>> from arapkit.mesh.shapes import bar
>>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], float)
>>> p = ARAPProblem.from_mesh((V, [[0, 1, 2], [1, 3, 2]]), [0], dim=2)
>>> be = PlanarBackend(p)
>>> R = np.empty((4, 2, 2))
>>> abs(be.local(np.ascontiguousarray(p.vertices[:, :2]), R)) < 1e-12  # rest: no energy
True
"""

from __future__ import annotations

import numba as nb
import numpy as np

from ..problem import ARAPProblem
from ..rotations2d import fit_rotations_2d, rotation_2d
from .cpu import CPUBackend

__all__ = ["PlanarBackend"]

_NO_ROT2 = np.zeros((0, 2, 2))
_NO_HELD = np.zeros((0, 2))


@nb.njit(parallel=True, cache=True, nogil=True)
def local_step_2d(P, chunk_ptr, disk_ptr, disk_idx, coef, up_ptr, up_idx, up_w, R, buf,
                  win_lo, win_off, partial, rc_ptr, rc_idx, rc_w, R_prev, centres, held):
    """Fused 2D local step: covariances, rotations, scatter of the next right-hand side.

    As :func:`arapkit.arap.backends.cpu.local_step` with ``S_k`` 2 x 2 and ``R_k`` in
    closed form; ``held[k] = (cos, sin)`` holds owner k's rotation where it is not NaN
    (``held`` empty: none held). ``partial[c] = (sum tr(R_k S_k), quadratic term)``.
    """
    coupled = rc_ptr.shape[0] > 0
    n_held = held.shape[0]
    nv = P.shape[0]
    for c in nb.prange(chunk_ptr.shape[0] - 1):
        off = win_off[c] - win_lo[c]
        for q in range(win_off[c], win_off[c + 1]):
            buf[q, 0] = 0.0
            buf[q, 1] = 0.0
        quad = 0.0
        tr = 0.0
        for k in range(chunk_ptr[c], chunk_ptr[c + 1]):
            s00 = s01 = s10 = s11 = 0.0
            o = k if k < nv else centres[k - nv]
            px, py = P[o, 0], P[o, 1]
            for t in range(disk_ptr[k], disk_ptr[k + 1]):
                v = disk_idx[t]
                dx, dy = P[v, 0] - px, P[v, 1] - py
                c0, c1 = coef[t, 0], coef[t, 1]
                s00 += c0 * dx
                s01 += c0 * dy
                s10 += c1 * dx
                s11 += c1 * dy
            for t in range(up_ptr[min(k, nv)], up_ptr[min(k + 1, nv)]):
                j = up_idx[t]
                dx, dy = P[j, 0] - px, P[j, 1] - py
                quad += up_w[t] * (dx * dx + dy * dy)
            if coupled and k < rc_ptr.shape[0] - 1:
                for t in range(rc_ptr[k], rc_ptr[k + 1]):
                    j, cw = rc_idx[t], rc_w[t]
                    s00 += cw * R_prev[j, 0, 0]
                    s01 += cw * R_prev[j, 1, 0]
                    s10 += cw * R_prev[j, 0, 1]
                    s11 += cw * R_prev[j, 1, 1]
            if k < n_held and held[k, 0] == held[k, 0]:  # not NaN: held at its angle
                cs, sn = held[k, 0], held[k, 1]
            else:
                cs, sn = rotation_2d(s00, s01, s10, s11)
            R[k, 0, 0], R[k, 0, 1] = cs, -sn
            R[k, 1, 0], R[k, 1, 1] = sn, cs
            tr += cs * (s00 + s11) + sn * (s01 - s10)
            for t in range(disk_ptr[k], disk_ptr[k + 1]):
                q = off + disk_idx[t]
                c0, c1 = coef[t, 0], coef[t, 1]
                buf[q, 0] += cs * c0 - sn * c1
                buf[q, 1] += sn * c0 + cs * c1
        partial[c, 0] = tr
        partial[c, 1] = quad


#: below this many rotations the local step runs on one thread: a parallel region costs a
#: scheduler slice whenever another process holds a core, more than the work of a 10K-vertex
#: sprite (about 0.3 ms); above it the threads pay
SERIAL_BELOW = 50_000
local_step_2d_serial = nb.njit(cache=True, nogil=True)(local_step_2d.py_func)


@nb.njit(cache=True, nogil=True)
def gather_rhs_2d(buf, win_lo, win_off, chunk_ptr, cover_ptr, cover_idx, slot, fixed_rhs, rhs):
    """``rhs[slot[v]] = b_v - (A_fc C)_v`` for free v (the 2D form of the CPU backend's)."""
    nv = slot.shape[0]
    for c in range(chunk_ptr.shape[0] - 1):
        for v in range(chunk_ptr[c], min(chunk_ptr[c + 1], nv)):
            s = slot[v]
            if s < 0:
                continue
            b0 = -fixed_rhs[s, 0]
            b1 = -fixed_rhs[s, 1]
            for t in range(cover_ptr[c], cover_ptr[c + 1]):
                d = cover_idx[t]
                q = v - win_lo[d]
                if q >= 0 and q < win_off[d + 1] - win_off[d]:
                    q += win_off[d]
                    b0 += buf[q, 0]
                    b1 += buf[q, 1]
            rhs[s, 0] = b0
            rhs[s, 1] = b1


@nb.njit(cache=True, nogil=True)
def scatter_rows_2d(X, idx, P):
    """``P[idx[i]] = X[i]``."""
    for i in range(idx.shape[0]):
        v = idx[i]
        P[v, 0] = X[i, 0]
        P[v, 1] = X[i, 1]


@nb.njit(cache=True, nogil=True)
def gather_rows_2d(P, idx, scale, out):
    """``out[i] = P[idx[i]] * scale``."""
    for i in range(idx.shape[0]):
        v = idx[i]
        out[i, 0] = P[v, 0] * scale
        out[i, 1] = P[v, 1] * scale


@nb.njit(parallel=True, cache=True, nogil=True)
def neighbourhood_energies_2d(P, P0, edges, w, edge_ptr, edge_idx, entry_w, R, out):
    """Each neighbourhood's term, summed edge by edge (the weight of entry t is
    ``entry_w[t]``, or ``w[edge]`` when ``entry_w`` is empty)."""
    per_entry = entry_w.shape[0] > 0
    for k in nb.prange(out.shape[0]):
        acc = 0.0
        for t in range(edge_ptr[k], edge_ptr[k + 1]):
            e = edge_idx[t]
            we = entry_w[t] if per_entry else w[e]
            i, j = edges[e, 0], edges[e, 1]
            ex, ey = P0[i, 0] - P0[j, 0], P0[i, 1] - P0[j, 1]
            dx = (P[i, 0] - P[j, 0]) - (R[k, 0, 0] * ex + R[k, 0, 1] * ey)
            dy = (P[i, 1] - P[j, 1]) - (R[k, 1, 0] * ex + R[k, 1, 1] * ey)
            acc += we * (dx * dx + dy * dy)
        out[k] = acc


class PlanarBackend(CPUBackend):
    """The CPU backend's layout with 2D kernels, for a problem with ``dim == 2``.

    Positions are ``(n, 2)``, rotations ``(K, 2, 2)``; everything else as
    :class:`~arapkit.arap.backends.cpu.CPUBackend`.
    """

    name = "cpu"
    dim = 2

    def __init__(self, problem: ARAPProblem) -> None:
        super().__init__(problem)
        nbh = problem.energy.nbh
        # the rest shape is planar: the coefficients' z is 0 and is left out
        self.coef = np.ascontiguousarray(nbh.disk_coef[:, :2])
        self.buf = np.zeros((len(self.buf), 2))
        self.rest2 = np.ascontiguousarray(problem.vertices[:, :2])
        self.held = _NO_HELD
        # a rotation coupling's constant: |R_k - R_j|^2 = 2 d - 2 tr(R_k^T R_j) holds
        # 2 d = 6 per unit weight in the energy's (3D) rest term, 4 in the plane
        self.rest_term = en_rest = problem.energy.rest_term
        if len(self.rc_w):
            self.rest_term = en_rest - 2.0 * float(self.rc_w.sum())

    def hold_rotations(self, owners: np.ndarray | None, angles: np.ndarray | None) -> None:
        """Hold the rotations of ``owners`` (internal numbering) at ``angles`` (radians);
        None releases every held rotation."""
        if owners is None or not len(owners):
            self.held = _NO_HELD
            return
        K = self.problem.energy.n_owners
        held = np.full((K, 2), np.nan)
        a = np.asarray(angles, dtype=np.float64)
        held[owners, 0] = np.cos(a)
        held[owners, 1] = np.sin(a)
        self.held = held

    def local(self, P: np.ndarray, R: np.ndarray, R_prev: np.ndarray = _NO_ROT2) -> float:
        """Fit 2 x 2 rotations to P (in place in R), scatter the right-hand side; return
        E(P, R)."""
        nbh = self.problem.energy.nbh
        kernel = local_step_2d_serial if len(self.coef) and self.problem.energy.n_owners \
            < SERIAL_BELOW else local_step_2d
        kernel(P, self.chunk_ptr, nbh.disk_ptr, nbh.disk_idx, self.coef,
                      self.up_ptr, self.up_idx, self.up_w, R, self.buf,
                      self.win_lo, self.win_off, self.partial,
                      self.rc_ptr, self.rc_idx, self.rc_w, R_prev, self.centres, self.held)
        tr, quad = self.partial.sum(axis=0)
        E = float(quad + self.rest_term - 2.0 * tr)
        return max(E, 0.0) if self.nonneg else E

    def rhs(self, fixed_rhs: np.ndarray, rhs: np.ndarray) -> None:
        """Right-hand side of the free vertices from the last local step."""
        gather_rhs_2d(self.buf, self.win_lo, self.win_off, self.chunk_ptr, self.cover_ptr,
                      self.cover_idx, self.slot, fixed_rhs, rhs)

    @staticmethod
    def scatter(X: np.ndarray, idx: np.ndarray, P: np.ndarray) -> None:
        """``P[idx[i]] = X[i]``."""
        scatter_rows_2d(X, idx, P)

    @staticmethod
    def gather(P: np.ndarray, idx: np.ndarray, scale: float) -> np.ndarray:
        """``P[idx] * scale``, a new array."""
        out = np.empty((len(idx), 2))
        gather_rows_2d(P, idx, scale, out)
        return out

    def _neighbourhood_energies(self, P: np.ndarray, R: np.ndarray) -> np.ndarray:
        """Each owner's own term of the energy in the plane (see the CPU backend's)."""
        p = self.problem
        nbh = p.energy.nbh
        out = np.empty(p.energy.n_owners)
        neighbourhood_energies_2d(P, self.rest2, p.edges, p.w, nbh.edge_ptr, nbh.edge_idx,
                                  self.entry_w, R, out)
        return out

    def _extra_rotations(self, P: np.ndarray) -> np.ndarray:
        """The best 2 x 2 rotations of the owners past the vertices for positions P."""
        return fit_rotations_2d(self._owner_covariances(P, self.coef))
