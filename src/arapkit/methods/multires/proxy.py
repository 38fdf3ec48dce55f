"""The proxy's stage: its solvers, its solve from rest, and the preview's warm start.

The proxy poses the full mesh's problem at its own scale and is as stiff as the full mesh:
it reads the full mesh's r and counts it in the full mesh's rings (``ring_scale = h_full /
h_proxy``), and where even one of its own rings is stiffer than the full mesh's r-ring the
one-ring energy is blended with a rotation per triangle
(:mod:`arapkit.arap.energies.rring`). That blended proxy is soft against bending and slow to
converge from rest, so a plain one-ring proxy (:attr:`ProxyStage.stiff`) leads: the solve
from rest goes through it (:data:`STIFF_TOL`), and a preview follows new targets on it first.

Examples
--------
>>> from arapkit.mesh.shapes import bar, bar_bend
>>> from arapkit.methods.multires import MultiresDeformer
>>> mesh = bar(segments=(60, 8, 8))
>>> h, t = bar_bend(mesh, 60)
>>> stage = MultiresDeformer(mesh, h, proxy_vertices=300).stage
>>> stage.solver.mesh.n_vertices < mesh.n_vertices, stage.shape is None
(True, True)
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ...arap.energies.rring import ring_blend
from ...arap.loop import Result
from ...mesh.model import Mesh
from ..deformer import Deformer
from .levels import PROXY_MAX_ITER, CoarseSolver, repose

__all__ = ["LEAD_MAX", "PROXY_TOL", "STIFF_TOL", "ProxyStage", "same_targets"]

#: the proxy's own stopping test in :meth:`MultiresDeformer.solve`: tighter than the full
#: solve's, since its iterations are cheap. The stiffness-matched proxy is slow to converge
#: (its bending is soft): at 1e-5 the 437K scan's release took 4.6 s instead of 2.6 s, for
#: an exact result 0.37 % (p95) of the diagonal from the minimum instead of 0.56 %
PROXY_TOL = 1e-4
#: the stiffness-matched proxy is soft against bending: solved from rest it settled in a
#: kinked minimum (2.5 % of the diagonal from the full one at its worst vertex, where the
#: same energy continued from the stiff one-ring's solution is 1.3 % away), so it starts
#: from the plain one-ring proxy's solution, solved to this
STIFF_TOL = 1e-4
#: how far ahead a preview's start runs, in moves as long as the last one (a drag move
#: the editor dropped makes the next one twice as long)
LEAD_MAX = 2.0


def same_targets(a: np.ndarray | None, b: np.ndarray) -> bool:
    """Whether ``a`` holds the targets ``b``: the same array (a drag passes one read-only
    array chunk after chunk, and comparing a scan's 10^5 targets costs about a millisecond)
    or an equal one (a pose submitted again).

    Examples
    --------
    >>> T = np.zeros((2, 3))
    >>> same_targets(T, T), same_targets(T.copy(), T), same_targets(None, T)
    (True, True, False)
    >>> same_targets(np.zeros((3, 3)), T)
    False
    """
    return a is not None and (a is b or np.array_equal(a, b))


class ProxyStage:
    """The proxy's solvers and what the preview remembers between moves.

    Parameters
    ----------
    mesh : Mesh
        The proxy mesh.
    coarse_solver : callable
        Makes a coarser mesh's solver (:data:`~arapkit.methods.multires.levels.CoarseSolver`).
    handles, rings : (k,) int, (m,) int
        The proxy's handles and r (the full mesh's r where each proxy vertex is bound).
    edge_ratio : float
        ``h_full / h_proxy``.

    Attributes
    ----------
    solver : Deformer
        The stiffness-matched proxy.
    stiff : Deformer or None
        The plain one-ring proxy that leads it (None where the proxy is not blended).
    shape : (m, 3) or None
        The proxy's last preview shape (None: the next preview starts from rest).
    moves : tuple or None
        The last two moves a preview saw: their proxy targets, and the shape the older
        one ended at (see :meth:`lead_start`).
    stiff_done_for : (h, 3) or None
        The full targets the plain proxy has converged for (forgotten with the handles
        or r).
    lead : bool
        See :attr:`MultiresDeformer.lead`.
    """

    def __init__(self, mesh: Mesh, coarse_solver: CoarseSolver, handles: np.ndarray,
                 rings: np.ndarray, edge_ratio: float) -> None:
        self.mesh = mesh
        self._coarse_solver = coarse_solver
        self.solver = coarse_solver(mesh, handles, rings, edge_ratio)
        self.solver.prepare()
        self.stiff: Deformer | None = None
        self._pose_stiff()
        self.shape: np.ndarray | None = None
        self.lead = False
        self.moves: tuple[np.ndarray | None, np.ndarray, np.ndarray | None] | None = None
        self.stiff_done_for: np.ndarray | None = None

    def _pose_stiff(self) -> None:
        """Give the plain one-ring proxy, which the matched proxy's solve from rest starts
        from, the proxy's handles and rings (none where the proxy is not blended)."""
        p = self.solver
        searched, share = ring_blend(p.rings, p.ring_scale)
        if not (share < 1.0).any():
            self.stiff = None
            return
        if self.stiff is None:
            self.stiff = self._coarse_solver(self.mesh, p.handles, searched, None)
        repose(self.stiff, p.handles, searched)

    def set_handles(self, handles: np.ndarray) -> None:
        """New handles: both proxies refactorised now; the next preview starts from rest."""
        self.solver.set_handles(handles)
        self.solver.prepare()
        self._pose_stiff()
        self.shape = None
        self.moves = self.stiff_done_for = None

    def set_rings(self, rings: np.ndarray) -> None:
        """A new rigidity map: both proxies rebuilt now."""
        self.solver.set_rings(rings)
        self.solver.prepare()
        self._pose_stiff()
        self.moves = self.stiff_done_for = None

    def preview(self, T: np.ndarray, PT: np.ndarray, callback, tol: float, max_iter: int,
                restart: bool) -> Result:
        """The proxy for the full targets ``T`` (its own targets ``PT``), from its last
        shape (or from rest); see :meth:`MultiresDeformer.preview`."""
        if restart or self.shape is None:
            self.moves = None
            res = self.from_rest(PT, callback, tol, max_iter)
        else:
            self.lead_start(PT)
            res = self.onwards(T, PT, callback, tol, max_iter)
        self.shape = res.vertices
        if self.moves is None:
            self.moves = (None, PT, None)
        return res

    def lead_start(self, PT: np.ndarray) -> None:
        """Where ``PT`` are new proxy targets, note the move and start the preview ahead.

        The start is ``Y + s (Y - Y_prev)``: ``Y`` the shape the last move ended at,
        ``Y_prev`` the one before, ``s`` the new move's length along the last one's (the
        projection of the targets' change on theirs, in ``[0, 2]``: up to 2 because a
        move the editor dropped makes the next one twice as long; a reversed or sideways
        move starts where the shape is). It runs ahead only where that lowers the
        energy for the new targets (:meth:`~arapkit.Deformer.energy_of` on the solver that
        takes the move: two local steps): a drag that bends the shape gains, while a
        shape that does not follow a move linearly (a small handle pulling a thin spike)
        would be thrown past where it goes.
        """
        moves = self.moves
        if moves is None:
            return
        older, last, shape = moves
        if same_targets(last, PT):
            return
        Y = self.shape
        self.moves = (last, PT, Y)
        if not self.lead or older is None or shape is None:
            return
        step, prior = (PT - last).ravel(), (last - older).ravel()
        norm = float(prior @ prior)
        s = min(max(float(step @ prior) / norm, 0.0), LEAD_MAX) if norm > 0.0 else 0.0
        if s > 0.0:
            ahead = Y + s * (Y - shape)
            # a new move starts on the plain one-ring proxy where there is one
            solver = self.stiff if self.stiff is not None else self.solver
            if solver.energy_of(ahead, PT) < solver.energy_of(Y, PT):
                self.shape = ahead

    def onwards(self, T: np.ndarray, PT: np.ndarray, callback: Callable | None, tol: float,
                max_iter: int) -> Result:
        """The proxy from its last shape, for a preview. Where it is blended, new targets
        are first followed by the plain one-ring proxy, whose iterations cost half as much
        and spread a move faster (halfway through the bench's drag at 437K its shape was
        4.3 % (p95) of the diagonal from the exact solve for its targets, the blended
        proxy's 6.8 %); once that has converged, the blended proxy takes over from there."""
        start = self.shape
        # equal targets in a new array (a pose submitted again) go on with the blended proxy
        if self.stiff is not None and not same_targets(self.stiff_done_for, T):
            stiff = self.stiff.solve(PT, init=start, tol=tol, max_iter=max_iter,
                                     callback=callback)
            if not stiff.converged:
                return stiff
            self.stiff_done_for, start = T, stiff.vertices
        return self.solver.solve(PT, init=start, tol=tol, max_iter=max_iter,
                                 callback=callback)

    def from_rest(self, PT: np.ndarray, callback: Callable | None = None,
                  tol: float = PROXY_TOL, max_iter: int = PROXY_MAX_ITER) -> Result:
        """The proxy solved from rest: through the plain one-ring proxy where it is
        blended (:data:`STIFF_TOL`); ``iterations`` counts both. A first stage that ends
        unconverged (stopped by ``callback``, or at ``max_iter``) is returned as it is."""
        start, before = "identity", 0
        if self.stiff is not None:
            stiff = self.stiff.solve(PT, init="identity", tol=STIFF_TOL, max_iter=max_iter,
                                     callback=callback)
            if not stiff.converged:
                return stiff
            start, before = stiff.vertices, stiff.iterations
        res = self.solver.solve(PT, init=start, tol=tol, max_iter=max_iter,
                                callback=callback)
        res.iterations += before
        return res
