"""The exact solve's fine stages: the full-resolution problem, built when first needed or
beside the preview, and the intermediate meshes (levels) between the proxy and it.

:class:`FineStages` holds them for one version of the handles and r: every change of
either (:meth:`FineStages.pose`) makes the built problem stale, and the next
:attr:`FineStages.full` (or a background build, :meth:`FineStages.prepare`) builds it
again. :meth:`FineStages.climb` takes the proxy's solution up through the levels, each
started from the coarser one's skinned solution and solved to :data:`LEVEL_TOL`.

Examples
--------
>>> from arapkit.mesh.shapes import bar, bar_bend
>>> from arapkit.methods.multires import MultiresDeformer
>>> mesh = bar(segments=(60, 8, 8))
>>> h, t = bar_bend(mesh, 30)
>>> d = MultiresDeformer(mesh, h, proxy_vertices=300)
>>> d.full_ready, d.full.mesh is mesh, d.full_ready
(False, True, True)
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from concurrent.futures import TimeoutError as FutureTimeout
from dataclasses import dataclass

import numba
import numpy as np

from ...arap.childfactor import factors_in_child
from ...arap.loop import Result
from ...errors import InputError
from ...mesh.model import Mesh
from ...validate import integer
from ..deformer import Deformer
from .binding import Binding, full_tree_of, proxy_rings
from .coarsening import coarsening_of
from .handles import coarse_handles

__all__ = ["LEVEL_TOL", "PROXY_MAX_ITER", "FineStages", "Level", "can_overlap", "repose"]

#: an intermediate mesh's stopping test: its iterations cost a quarter of the full mesh's
LEVEL_TOL = 1e-4
#: iterations at most of a coarser mesh's solve (the proxy's, a level's)
PROXY_MAX_ITER = 2000

#: makes a coarser mesh's solver: ``(mesh, handles, rings, edge_ratio) -> Deformer``
CoarseSolver = Callable[[Mesh, np.ndarray, np.ndarray, "float | None"], Deformer]


def can_overlap() -> bool:
    """Whether numba's parallel kernels may run on two threads at once.

    Its ``workqueue`` layer (where neither OpenMP nor TBB is found) is not thread-safe:
    there the full problem is built when first needed instead of beside the preview.

    Examples
    --------
    >>> can_overlap() in (True, False)
    True
    """
    try:
        return numba.threading_layer() != "workqueue"
    except ValueError:  # no parallel kernel has run yet: unknown, so no
        return False


def repose(solver: Deformer, handles: np.ndarray, rings: np.ndarray) -> None:
    """Give ``solver`` these handles and r where they changed, and factorise it.

    Examples
    --------
    >>> from arapkit.mesh.shapes import bar, bar_bend
    >>> m = bar()
    >>> h, _ = bar_bend(m, 30)
    >>> d = Deformer(m, h)
    >>> repose(d, h[:10], d.rings); d.handles.tolist() == h[:10].tolist()
    True
    """
    if not np.array_equal(solver.handles, handles):
        solver.set_handles(handles)
    if not np.array_equal(solver.rings, rings):
        solver.set_rings(rings)
    solver.prepare()


@dataclass
class Level:
    """An intermediate mesh of the exact solve, between the proxy and the full mesh.

    Attributes
    ----------
    mesh : Mesh
        A decimation of the full mesh.
    up : Binding
        This mesh (as "full") against the next coarser one (the proxy for the first level):
        how a coarser solution is skinned onto it.
    full : Binding
        The full mesh against this one: where its handles and r come from, and how its
        solution is skinned onto the full mesh (the last level).
    edge_ratio : float
        ``h_full / h_level``, as :attr:`MultiresDeformer.edge_ratio`.
    solver : Deformer or None
        Its own solver, for the current handles and r (built with the full problem).
    handles, region : (k,) int64
        Its handle vertices and the full handle region each follows.
    """

    mesh: Mesh
    up: Binding
    full: Binding
    edge_ratio: float
    solver: Deformer | None = None
    handles: np.ndarray | None = None
    region: np.ndarray | None = None


def check_levels(levels, n_vertices: int, proxy_vertices: int) -> list[int]:
    """The intermediate meshes' sizes, checked: increasing, between the proxy's size
    (``proxy_vertices``: its real vertex count) and half the mesh's.

    Examples
    --------
    >>> check_levels([1000, 3000], 10_000, 500)
    [1000, 3000]
    >>> check_levels([3000, 1000], 10_000, 500)
    Traceback (most recent call last):
    ...
    arapkit.errors.InputError: levels: 1000 vertices is not between the coarser mesh ...
    """
    if levels is None:
        return []
    try:
        sizes = [integer(k, "levels", lo=1) for k in levels]
    except TypeError:
        raise InputError(f"levels must be a sequence of vertex counts, got {levels!r}") \
            from None
    lo, n = proxy_vertices, n_vertices
    for k in sizes:
        if not lo < k <= n // 2:
            raise InputError(
                f"levels: {k} vertices is not between the coarser mesh ({lo}) and half "
                f"the mesh ({n // 2}); give increasing sizes in that range")
        lo = k
    return sizes


class FineStages:
    """The full-resolution :class:`~arapkit.Deformer` and the levels, for the current
    handles and r; built lazily, or on a background thread with the large factors in a
    child process.

    Parameters
    ----------
    mesh : Mesh
        The full mesh.
    proxy_mesh, home :
        The proxy and each full vertex's home on it (:func:`decimation`).
    level_sizes : list of int
        :func:`check_levels`' sizes.
    weights, options :
        The full problem's weights and :class:`~arapkit.Deformer` options.
    coarse_solver : callable
        Makes a level's solver (the proxy's method and weights, r scaled).
    handles, rings, region :
        The full mesh's handles, r and each handle's region (:class:`HandleMotions`).

    Attributes
    ----------
    levels : list of Level
        Built with the full problem (empty until then).
    pending : Future or None
        The background build, if one was started.
    """

    def __init__(self, mesh: Mesh, proxy_mesh: Mesh, home: np.ndarray,
                 level_sizes: list[int], weights, options: dict,
                 coarse_solver: CoarseSolver, handles: np.ndarray, rings: np.ndarray,
                 region: np.ndarray) -> None:
        self.mesh = mesh
        self._coarsening = coarsening_of(mesh)
        self._proxy_mesh, self._home = proxy_mesh, home
        self._level_sizes = level_sizes
        self._weights, self._options = weights, options
        self._coarse_solver = coarse_solver
        self.levels: list[Level] = []
        self._full: Deformer | None = None
        self._pose = (handles, rings, region)
        # the handles and r change a version; the full problem records the one it was built
        # for (comparing 10^6-entry arrays on every access cost milliseconds)
        self._version = 0
        self._built = -1
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="arapkit-full")
        self.pending: Future | None = None
        self._pending_version = -1

    def pose(self, handles: np.ndarray, rings: np.ndarray, region: np.ndarray) -> None:
        """New handles or r: what is built goes stale (built again when next asked for)."""
        self._pose = (handles, rings, region)
        self._version += 1

    def _make_levels(self) -> None:
        """Decimate and bind the intermediate meshes (once: they depend on the mesh only)."""
        coarsen = self._coarsening
        for size in self._level_sizes:  # in a child process: the GIL stays free
            coarsen.start(self.mesh, size)
        full = np.asarray(self.mesh.vertices, dtype=np.float64)
        tree = full_tree_of(full) if self._level_sizes else None
        coarser, coarser_home = self._proxy_mesh, self._home
        for size in self._level_sizes:
            m, home = coarsen.make(self.mesh, size)
            down = Binding.between(full, m.vertices, tree, coarsen.specks(self.mesh, size),
                                   home, proxy_adjacency=m.adjacency)
            # a level vertex's home on the coarser mesh: that of the full vertex it reads
            up_home = coarser_home[down.near_full]
            self.levels.append(Level(
                m, Binding.between(m.vertices, coarser.vertices, home=up_home,
                                   proxy_adjacency=coarser.adjacency),
                down, self.mesh.mean_edge_length / max(m.mean_edge_length, 1e-300)))
            coarser, coarser_home = m, home

    def _pose_level(self, level: Level, handles: np.ndarray, region: np.ndarray,
                    rings: np.ndarray) -> None:
        """Give ``level`` the full mesh's handles and r, and factorise its solver."""
        lh, lr = coarse_handles(level.full, handles, region, self.mesh.n_vertices)
        lrings = proxy_rings(rings, level.full.near_full)
        if level.solver is None:
            level.solver = self._coarse_solver(level.mesh, lh, lrings, level.edge_ratio)
        repose(level.solver, lh, lrings)
        level.handles, level.region = lh, lr

    def _build(self) -> Deformer:
        version, (handles, rings, region) = self._version, self._pose
        if len(self.levels) < len(self._level_sizes):
            self._make_levels()
        for level in self.levels:
            self._pose_level(level, handles, region, rings)
        if self._full is None:
            self._full = Deformer(self.mesh, handles, rings, self._weights, multires=False,
                                  **self._options)
        repose(self._full, handles, rings)
        self._built = version
        return self._full

    def _build_beside(self) -> Deformer:
        """:meth:`_build` on the background thread, its large factors made and solved in
        a child process: cholespy holds the GIL throughout, and a factor built here froze
        every other thread (the editor's page and preview: 19 s at 1.75M vertices)."""
        with factors_in_child():
            return self._build()

    def _stale(self) -> bool:
        return self._full is None or self._built != self._version

    @property
    def full(self) -> Deformer:
        """The full-resolution :class:`arapkit.Deformer` (waits for a background build)."""
        if self.pending is not None:
            self.pending.result()
            self.pending = None
        if self._stale():
            self._build()
        return self._full

    @property
    def ready(self) -> bool:
        """Whether the full-resolution factor is built (no wait for :attr:`full`)."""
        return (self.pending is None or self.pending.done()) and not self._stale()

    def wait_ready(self, timeout: float) -> bool:
        """Wait up to ``timeout`` s for the full factor (built in the background if needed)."""
        if self.ready:
            return True
        # a finished build may be for handles or r changed since: then build again
        if self.pending is None or self.pending.done():
            self._pending_version = self._version
            self.pending = self._pool.submit(self._build_beside)
        try:
            self.pending.result(timeout)
        except FutureTimeout:
            return False
        return self.ready

    def prepare(self, background: bool = False) -> None:
        """Build the full-resolution factor now (or on a background thread, where safe)."""
        if background:
            # once per version of the handles and r: a caller may ask on every request
            if can_overlap() and self._stale() and not (
                    self.pending is not None and not self.pending.done()
                    and self._pending_version == self._version):
                self._pending_version = self._version
                self.pending = self._pool.submit(self._build_beside)
        else:
            _ = self.full

    def climb(self, proxy: Result, moved: Callable[[np.ndarray, np.ndarray], np.ndarray],
              stop: Callable[[], bool] | None = None
              ) -> tuple[Result | None, Binding | None, int]:
        """The proxy's solution taken up through the levels.

        Each level starts from the coarser solution skinned onto it, its handles at
        ``moved(rest_points, region)`` (their regions' fitted motions), and is solved to
        :data:`LEVEL_TOL`. Waits for the full problem (the levels are built with it).

        Returns
        -------
        coarse : Result or None
            The finest level's solution (``proxy`` without levels); None where ``stop``
            said True after a level iteration (a newer request came).
        binding : Binding or None
            The last level's binding to the full mesh; None without levels.
        iterations : int
            The levels' iterations.
        """
        _ = self.full
        coarse, its = proxy, 0
        for level in self.levels:
            X = level.up.skin(coarse.vertices, coarse.rotations)
            LT = moved(level.mesh.vertices[level.handles], level.region)
            coarse = level.solver.solve(LT, init=X, tol=LEVEL_TOL, max_iter=PROXY_MAX_ITER,
                                        callback=None if stop is None else (lambda *_: stop()))
            its += coarse.iterations
            if stop is not None and not coarse.converged and stop():
                return None, None, its
        return coarse, (self.levels[-1].full if self.levels else None), its
