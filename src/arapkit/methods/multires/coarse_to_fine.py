"""The coarse-to-fine deformer: :class:`MultiresDeformer`, what ``Deformer(..., multires=True)``
returns (importing this module registers it with :class:`arapkit.Deformer`).

It previews on the proxy (:mod:`.proxy`) and skins the result onto the full mesh
(:mod:`.binding`); its exact solve starts the full mesh (:mod:`.levels`) from the skinned
proxy solution. The package's docstring (:mod:`arapkit.methods.multires`) says why.

Examples
--------
>>> from arapkit.mesh.shapes import bar, bar_bend
>>> mesh = bar(segments=(60, 8, 8))
>>> h, t = bar_bend(mesh, 60)
>>> d = MultiresDeformer(mesh, h, proxy_vertices=300)
>>> d.proxy_mesh.n_vertices < mesh.n_vertices
True
>>> res = d.solve(t)
>>> bool(res.converged), res.timings["proxy_iterations"] > 0
(True, True)
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass

import numpy as np

from ...arap.constraints import check_handles, check_targets
from ...arap.domains import domain_of
from ...arap.loop import Result
from ...arap.ringcost import check_ring_memory
from ...errors import InputError
from ...mesh.cloud import PointCloud, as_shape
from ...mesh.model import Mesh
from ...validate import ring_sizes
from ..deformer import Deformer
from ..dispatch import MULTIRES_AUTO_VERTICES, check_domain, register_variant
from ..registry import method
from .binding import Binding, full_tree_of, proxy_rings
from .coarsening import coarsening_of
from .decimator import DEFAULT_PROXY_VERTICES
from .handles import HandleMotions, coarse_handles
from .levels import PROXY_MAX_ITER, FineStages, Level, check_levels
from .parts import FreeParts
from .proxy import ProxyStage, same_targets

__all__ = ["AUTO_MIN_VERTICES", "MultiresDeformer", "Preview"]

#: ``Deformer(..., multires=None)`` (the default) turns coarse-to-fine on from this size
AUTO_MIN_VERTICES = MULTIRES_AUTO_VERTICES

_kernels_loaded = threading.Event()


def _load_kernels() -> None:
    """Load the compiled local/global kernels once per process, on a 50-vertex problem.

    Loading them from numba's cache takes about 0.4 s of a large mesh's opening: done while
    :func:`start_decimation`'s child works, it is off the path to the first preview.
    """
    if _kernels_loaded.is_set():
        return
    from ...mesh.shapes import bar, bar_bend

    m = bar(segments=(4, 2, 2))
    h, t = bar_bend(m, 30)
    # with a callback: the preview's solves watch every iteration
    Deformer(m, h, accelerate=True, free_components="follow", multires=False).solve(
        t, max_iter=2, callback=lambda *_: False)
    Binding.between(m.vertices, m.vertices[:8]).skin(m.vertices[:8], np.tile(np.eye(3), (8, 1, 1)))
    _kernels_loaded.set()


@dataclass
class Preview:
    """One preview: the proxy's shape and, mapped from it, the full mesh's.

    Attributes
    ----------
    vertices : (n, 3) or None
        The full mesh's preview (skinned; handles at their targets); None when not asked
        for (``preview(..., full=False)``).
    proxy : Result
        The proxy solve (its ``vertices`` are what the editor draws while dragging).
    """

    vertices: np.ndarray | None
    proxy: Result

class MultiresDeformer:
    """ARAP on a large mesh, coarse to fine: what ``Deformer(..., multires=True)`` returns.

    Same interface as :class:`arapkit.Deformer` (``solve``, ``set_handles``,
    ``set_rings``, ``prepare``, ``problem``, ``notes``), plus :meth:`preview`. ``solve``
    returns the full-resolution result, converged by the full mesh's own test, started from
    the skinned proxy solution.

    Parameters
    ----------
    mesh, handles, rings, weights :
        As for :class:`arapkit.Deformer`.
    proxy_vertices : int
        The proxy's size (default :data:`DEFAULT_PROXY_VERTICES`).
    levels : sequence of int, optional
        Sizes of the intermediate meshes the exact solve passes through between the proxy
        and the full mesh, coarse first (each a decimation of the full mesh, solved to
        :data:`LEVEL_TOL` from the coarser one's skinned solution). Default: none. With
        the stiffness-matched proxy a 100K level under the 437K scan cost 1.1 s of the
        release and saved 0.5-0.8 s of full iterations
        (``docs/studies/interactive-at-scale.md``). The preview does not use them.
    background : bool
        Build the full-resolution problem and its factor on a background thread (the
        editor: the proxy can preview at once); :meth:`solve` waits for it.
    **options
        :class:`arapkit.Deformer`'s other options, for the full-resolution solve.
        ``accelerate`` defaults to True here (Anderson acceleration on both levels).

    Attributes
    ----------
    proxy_mesh : Mesh
        The decimated proxy.
    proxy : Deformer
        The proxy's own solver (its handles are :meth:`proxy_targets`' rows).
    stage : ProxyStage
        The proxy's solvers and what the preview remembers between moves.
    binding : Binding
        How full and proxy vertices correspond at rest.
    levels : list of Level
        The intermediate meshes, built with the full problem (empty until then).
    edge_ratio : float
        ``h_full / h_proxy``, the mean edge lengths' ratio that scales r onto the proxy.
    lead : bool
        Whether a preview for new targets starts ahead along the drag (see
        :meth:`preview`). False by default: it pays where a preview gets a fixed number
        of iterations a move, not in the editor's 20 ms chunks
        (``docs/studies/interactive-at-scale.md``, fifteenth pass).

    Examples
    --------
    >>> import numpy as np
    >>> from arapkit.mesh.shapes import bar, bar_bend
    >>> mesh = bar(segments=(60, 8, 8))
    >>> h, t = bar_bend(mesh, 60)
    >>> d = MultiresDeformer(mesh, h, proxy_vertices=300)
    >>> p = d.preview(t)
    >>> p.vertices.shape == mesh.vertices.shape
    True
    """

    def __init__(self, mesh: Mesh | PointCloud, handles, rings=1, weights: str | None = None,
                 *, proxy_vertices: int = DEFAULT_PROXY_VERTICES, levels=None,
                 background: bool = False, **options) -> None:
        energy = options.get("energy", "rring")
        if not method(energy).multires:
            raise InputError(f"multires: energy '{energy}' cannot be solved coarse to fine "
                             "(use multires=False)")
        t0 = time.perf_counter()
        mesh = as_shape(mesh)
        check_domain(mesh, energy, init=options.get("init", "identity"))
        self._coarsening = coarsening_of(mesh)
        self.mesh = mesh
        self.energy = energy
        self.handles = check_handles(mesh, handles)
        self._rings = ring_sizes(rings, mesh.n_vertices)
        self._check_ring_memory(self._rings)
        self._weights = weights
        # acceleration is part of the machinery here: on unless asked off
        if options.get("accelerate") is None:
            options["accelerate"] = True
        self._options = options
        self.accelerate = bool(options["accelerate"])
        self.tol = self._options.get("tol", 1e-3)
        # what needs no proxy first: a child process may still be decimating
        _load_kernels()
        full = np.asarray(mesh.vertices, dtype=np.float64)
        tree = full_tree_of(full)
        _ = mesh.mean_edge_length
        left_out = self._coarsening.specks(mesh, proxy_vertices)
        self._index_handles()
        # needs no proxy: 0.5 s at 1.75M off the wait
        self._parts = FreeParts(mesh, self.handles, options.get("free_components", "follow"),
                                None if left_out is None else ~left_out)
        self.proxy_mesh, self._home = self._coarsening.make(mesh, proxy_vertices)
        level_sizes = check_levels(levels, mesh.n_vertices, self.proxy_mesh.n_vertices)
        self.binding = Binding.between(full, self.proxy_mesh.vertices, tree, left_out,
                                       self._home,
                                       proxy_adjacency=self.proxy_mesh.adjacency)
        self.edge_ratio = mesh.mean_edge_length / max(self.proxy_mesh.mean_edge_length, 1e-300)
        self._bind_handles()
        self.stage = ProxyStage(self.proxy_mesh, self._coarse_solver, self._proxy_handles,
                                self._proxy_rings(), self.edge_ratio)
        self._open_s = time.perf_counter() - t0
        self._checked: np.ndarray | None = None
        self._fine = FineStages(mesh, self.proxy_mesh, self._home, level_sizes, weights,
                                options, self._coarse_solver, self.handles, self._rings,
                                self._region)
        if background:
            self.prepare(background=True)

    def _check_ring_memory(self, rings: np.ndarray) -> None:
        """Refuse a rigidity map whose full-mesh rings would not fit in memory now: they
        are built at the exact solve, perhaps in the background, where a refusal would come
        late (:func:`arapkit.arap.ringcost.check_ring_memory`). One-rings are not
        estimated: they are the size of the mesh's own edges, and the estimate needs the
        edge list, which the open of a large mesh does not otherwise wait for."""
        if method(self.energy).rigidity_map and int(rings.max()) > 1:
            check_ring_memory(self.mesh.n_vertices, self.mesh.edges, rings, self.mesh.name)

    # -- the proxy -------------------------------------------------------------------
    @property
    def proxy(self) -> Deformer:
        """The proxy's own solver (the stiffness-matched one)."""
        return self.stage.solver

    @property
    def lead(self) -> bool:
        """Whether a preview for new targets starts ahead along the drag (see
        :meth:`preview`)."""
        return self.stage.lead

    @lead.setter
    def lead(self, on: bool) -> None:
        self.stage.lead = bool(on)

    def _coarse_solver(self, mesh: Mesh, handles: np.ndarray, rings: np.ndarray,
                       edge_ratio: float | None) -> Deformer:
        """A coarser mesh's solver: the full problem's method and weights, with r counted in
        the full mesh's rings (``edge_ratio``: ``h_full / h_coarse``; None: its own) where
        the method has a rigidity map, so that the coarse mesh is as stiff as the full one;
        its parts without a handle follow, whatever the full mesh does with its own."""
        scale = {}
        if edge_ratio is not None and method(self.energy).rigidity_map:
            scale["ring_scale"] = self._options.get("ring_scale", 1.0) * edge_ratio
        return Deformer(mesh, handles, rings, self._weights, energy=self.energy,
                        accelerate=True, free_components="follow", multires=False, **scale,
                        **{k: v for k, v in self._options.items()
                           if k in ("sr_alpha", "history")})

    # -- the full-resolution problem (levels.FineStages), built lazily or beside -------
    @property
    def levels(self) -> list[Level]:
        """The intermediate meshes, built with the full problem (empty until then)."""
        return self._fine.levels

    @property
    def full(self) -> Deformer:
        """The full-resolution :class:`arapkit.Deformer` (waits for a background build)."""
        return self._fine.full

    @property
    def full_ready(self) -> bool:
        """Whether the full-resolution factor is built (no wait in :meth:`solve`)."""
        return self._fine.ready

    def wait_ready(self, timeout: float) -> bool:
        """Wait up to ``timeout`` s for the full factor (built in the background if needed).

        Lets a caller stay responsive while a large factor is being built.
        """
        return self._fine.wait_ready(timeout)

    def prepare(self, background: bool = False) -> None:
        """Build the full-resolution factor now (or on a background thread, where safe)."""
        self._fine.prepare(background)

    # -- what the proxy sees ------------------------------------------------------------
    def _index_handles(self) -> None:
        """What the full mesh's handles need of the full mesh only: their regions, the
        points their motions are fitted to; the parts' rule is found again on first use."""
        self._motions = HandleMotions(self.mesh, self.handles)
        self._region = self._motions.region
        self._last_targets: tuple[np.ndarray, np.ndarray] | None = None
        self._parts: FreeParts | None = None

    def _bind_handles(self) -> None:
        """Proxy handles: proxy vertices bound to a handle, each with its handle region."""
        self._proxy_handles, self._proxy_region = coarse_handles(
            self.binding, self.handles, self._region, self.mesh.n_vertices)

    def _proxy_rings(self) -> np.ndarray:
        return proxy_rings(self._rings, self.binding.near_full)

    def proxy_targets(self, targets: np.ndarray) -> np.ndarray:
        """Targets of the proxy's handles: each handle region's fitted rigid motion.

        Examples
        --------
        >>> import numpy as np
        >>> from arapkit.mesh.shapes import bar, bar_bend
        >>> mesh = bar(segments=(60, 8, 8))
        >>> h, t = bar_bend(mesh, 0)
        >>> d = MultiresDeformer(mesh, h, proxy_vertices=300)
        >>> Q = d.proxy_mesh.vertices
        >>> bool(np.allclose(d.proxy_targets(t), Q[d.proxy.handles]))
        True
        """
        return self._proxy_targets(self.checked_targets(targets))

    def checked_targets(self, targets) -> np.ndarray:
        """``targets`` validated once, as a read-only array the methods here accept unchecked.

        A drag previews the same targets chunk after chunk; checking a scan's 4 x 10^5
        handle targets costs about 10 ms each time. Being read-only, the returned array
        cannot change between calls, so passing it back skips the check and the fit.

        Examples
        --------
        >>> from arapkit.mesh.shapes import bar, bar_bend
        >>> mesh = bar(segments=(60, 8, 8))
        >>> h, t = bar_bend(mesh, 30)
        >>> d = MultiresDeformer(mesh, h, proxy_vertices=300)
        >>> T = d.checked_targets(t)
        >>> T.flags.writeable, d.checked_targets(T) is T
        (False, True)
        """
        last = self._checked
        if last is not None and targets is last:
            return last
        T = check_targets(self.handles, targets)
        T.flags.writeable = False
        self._checked = T
        return T

    def _proxy_targets(self, T: np.ndarray) -> np.ndarray:
        # a drag sends the same targets chunk after chunk: fit them once
        last = self._last_targets
        if last is not None and same_targets(last[0], T):
            return last[1]
        out = self._motions.moved(T, self.proxy_mesh.vertices[self._proxy_handles],
                                  self._proxy_region)
        self._last_targets = (T if not T.flags.writeable else T.copy(), out)
        return out

    # -- configuration ------------------------------------------------------------------
    def set_handles(self, handles) -> None:
        """Use a new handle set: the proxy is refactorised now, the full mesh lazily."""
        self.handles = check_handles(self.mesh, handles)
        self._checked = None
        self._index_handles()
        self._fine.pose(self.handles, self._rings, self._region)
        self._bind_handles()
        self.stage.set_handles(self._proxy_handles)

    def set_rings(self, rings) -> None:
        """Use a new rigidity map: the proxy's is rebuilt now, the full mesh's lazily."""
        rings = ring_sizes(rings, self.mesh.n_vertices)
        self._check_ring_memory(rings)  # before anything changes: a refusal keeps the old map
        self._rings = rings
        self._fine.pose(self.handles, self._rings, self._region)
        self.stage.set_rings(self._proxy_rings())

    # -- the Deformer interface ---------------------------------------------------------
    @property
    def rings(self) -> np.ndarray:
        """r per vertex of the full mesh."""
        return self._rings

    @property
    def weights_kind(self) -> str | None:
        """The full problem's edge weighting (see :attr:`arapkit.Deformer.weights_kind`)."""
        if self._weights is not None:
            return self._weights if isinstance(self._weights, str) else None
        return domain_of(self.mesh).default_weights

    @property
    def problem(self):
        """The full-resolution ARAP problem (built on first use)."""
        return self.full.problem

    @property
    def energy_is_sum_of_squares(self) -> bool:
        """Whether the full problem's weights are all >= 0 (so E >= 0)."""
        return self.full.energy_is_sum_of_squares

    @property
    def notes(self) -> list[str]:
        """What was done about the input: the proxy, then the full problem's notes."""
        pm, full = self.proxy_mesh, self.full
        via = "".join(f", then a {lv.mesh.n_vertices}-vertex level" for lv in self.levels)
        return [f"coarse to fine: a {pm.n_vertices}-vertex proxy (opened in "
                f"{self._open_s:.1f} s){via} starts the full solve"] + full.notes

    @property
    def timings(self) -> dict[str, float]:
        """The full problem's precomputation times, plus ``proxy_open_s``."""
        return {**self.full.timings, "proxy_open_s": self._open_s}

    def vertex_energy(self, P: np.ndarray, R: np.ndarray) -> np.ndarray:
        """See :meth:`arapkit.Deformer.vertex_energy` (the full problem's)."""
        return self.full.vertex_energy(P, R)

    def energy_of(self, P: np.ndarray, targets) -> float:
        """See :meth:`arapkit.Deformer.energy_of` (the full problem's)."""
        return self.full.energy_of(P, targets)

    # -- solving ------------------------------------------------------------------------
    def preview(self, targets, max_iter: int | None = None, tol: float = 1e-4,
                callback=None, restart: bool = False, full: bool = True) -> Preview:
        """Iterate the proxy from its last shape and map it to the full mesh.

        Parameters
        ----------
        targets : (h, 3)
            The full handles' targets.
        max_iter : int, optional
            Proxy iterations at most (a frame's budget); default: to ``tol``.
        tol : float
            The proxy's stopping test.
        callback : callable(iteration, energy, proxy_vertices) -> bool, optional
            As for :meth:`arapkit.Deformer.solve`, on the proxy.
        restart : bool
            Start the proxy from rest instead of its last shape.
        full : bool
            Map the proxy to the full mesh (else ``Preview.vertices`` is None: a display
            that draws the proxy saves 3–80 ms a frame; :meth:`to_full` maps it later).

        Notes
        -----
        A drag's few iterations per move leave the shape behind its targets, by about as
        many moves as the slowest mode needs iterations. With :attr:`lead` set, where the
        targets changed along the last move's direction the proxy starts as far ahead as
        its shape moved over the last move: a steady drag then leaves no lag, only what
        changes in its speed. Bending a bar at 2.5 degrees a move with 3 iterations a
        move, the shape stays within 0.36 % of the diagonal of its own targets' solution
        instead of 6.4 %. In the editor it is off: there it made each iteration dearer
        (the rotations move more per step) and cost a quarter of the shapes sent, for a
        mid-drag figure within the bench's noise (``docs/studies/interactive-at-scale.md``).
        """
        T = self.checked_targets(targets)
        res = self.stage.preview(T, self._proxy_targets(T), callback, tol,
                                 max_iter or PROXY_MAX_ITER, restart)
        return Preview(self.to_full(res, T) if full else None, res)

    def to_full(self, proxy: Result, targets) -> np.ndarray:
        """The full mesh's shape from a proxy result: skinned, handles at ``targets``, and
        the parts without a handle placed by the exact solve's own rule."""
        X = self._onto_full(self.binding, proxy, self.checked_targets(targets))
        self._place_free_parts(X)
        return X

    def _place_free_parts(self, X: np.ndarray) -> None:
        """Place the parts the proxy does not solve as the full solve does (in place:
        :class:`FreeParts`). The full solve ignores the free parts in its start, so
        :meth:`fine_start` skips this."""
        if self._parts is None:  # found once per handle set
            self._parts = FreeParts(self.mesh, self.handles,
                                    self._options.get("free_components", "follow"),
                                    self.binding.covered)
        self._parts.apply(X)

    def _onto_full(self, binding: Binding, coarse: Result, T: np.ndarray) -> np.ndarray:
        X = binding.skin(coarse.vertices, coarse.rotations)
        X[self.handles] = T
        return X

    def coarse_start(self, targets, callback=None) -> tuple[np.ndarray, Result]:
        """The exact solve's first stage: the proxy solved from rest to :data:`PROXY_TOL`.

        Returns the proxy's solution skinned onto the full mesh (the editor shows it as the
        settled preview) and the proxy's result, which :meth:`fine_start` takes on from:
        ``solve(targets)`` is ``full.solve(targets, init=fine_start(targets, proxy)[0])``
        with ``proxy = coarse_start(targets)[1]``. ``callback`` is the proxy solve's (as
        for :meth:`preview`); a start it stopped early is not the solve's.
        """
        res = self.stage.from_rest(self._proxy_targets(self.checked_targets(targets)), callback)
        return self.to_full(res, targets), res

    def fine_start(self, targets, proxy: Result,
                   stop=None) -> tuple[np.ndarray | None, int]:
        """The full solve's start from the proxy's: through :attr:`levels`, then skinned.

        Each level starts from the coarser solution skinned onto it (handles at their
        region's fitted motion) and is solved to :data:`LEVEL_TOL`. Waits for the full
        problem (the levels are built with it). Without levels this is
        ``to_full(proxy, targets)``, :meth:`coarse_start`'s first value.

        Parameters
        ----------
        targets : (h, 3)
            The full handles' targets.
        proxy : Result
            The proxy's solution, :meth:`coarse_start`'s second value.
        stop : callable() -> bool, optional
            Asked after every level iteration; when it says True the start is abandoned
            (the editor: a newer request came) and None returned.

        Returns
        -------
        start : (n, 3) or None
        iterations : int
            The levels' iterations.
        """
        T = self.checked_targets(targets)
        coarse, binding, its = self._fine.climb(
            proxy, lambda Q, region: self._motions.moved(T, Q, region), stop)
        if coarse is None:
            return None, its
        return self._onto_full(self.binding if binding is None else binding, coarse, T), its

    def solve(self, targets, init=None, tol: float | None = None,
              max_iter: int | None = None, callback=None,
              accelerate: bool | None = None, progress=None) -> Result:
        """Deform so that the handles reach ``targets``; see :meth:`arapkit.Deformer.solve`.

        With ``init=None`` the full solve starts from the skinned proxy solution (coarse to
        fine); an array or ``"identity"``/``"laplacian"`` starts it there instead, as for
        :class:`arapkit.Deformer`. ``timings`` gains ``proxy_s``, ``proxy_iterations``,
        ``level_s`` and ``level_iterations``. ``callback`` and ``progress`` see the full
        solve's iterations (the proxy's are :meth:`coarse_start`'s).
        """
        t0 = time.perf_counter()
        proxy_its = level_its = 0
        t_proxy = t_levels = 0.0
        pres = None
        if init is None:
            pres = self.stage.from_rest(self._proxy_targets(self.checked_targets(targets)))
            proxy_its = pres.iterations
            t_proxy = time.perf_counter() - t0
        full = self.full  # built (or waited for) before the levels' clock starts
        if pres is not None:
            t1 = time.perf_counter()
            init, level_its = self.fine_start(targets, pres)
            t_levels = time.perf_counter() - t1
        res = full.solve(targets, init=init, tol=tol, max_iter=max_iter,
                         callback=callback, accelerate=accelerate, progress=progress)
        res.timings.update(proxy_s=t_proxy, proxy_iterations=proxy_its, level_s=t_levels,
                           level_iterations=level_its, total_s=time.perf_counter() - t0)
        return res


register_variant("multires", MultiresDeformer)
