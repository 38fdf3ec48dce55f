"""Background solver thread for the editor: latest request wins, nothing queues.

The UI thread only builds a :class:`SolveRequest` (handles, targets, rings, settings) and
hands it to :meth:`SolveWorker.submit`.  The worker thread owns the library objects
(:class:`arapkit.Deformer` / :class:`arapkit.LaplacianEditor`), refactorises only when the
handle set, the rigidity map, the weights or the mesh change, and warm-starts every solve
from the last shape it produced.

Supersede rule
--------------
There is one slot for a pending request.  A newer request replaces an older pending one
(dropped, never solved).  A running solve first finishes its *live* chunk (at most
``live_max_iter`` iterations or ``live_budget_ms`` after the request was made) and sends
that shape; from then on it keeps iterating towards convergence but stops at the next
iteration as soon as a newer request is waiting.  So a drag shows a fresh shape after a
bounded delay, and iterations run to convergence once the user stops moving.

Large meshes
------------
When the deformer is coarse to fine (:class:`arapkit.methods.multires.MultiresDeformer`,
chosen by ``Deformer`` from 100K vertices), a *live* request (a drag in progress) iterates
only the proxy, in chunks of one frame (:data:`PREVIEW_FRAME_MS`), and each update carries
the proxy's shape for display (``proxy_mesh``/``proxy_vertices``) beside the skinned full
one. Any other request (the drag's release, a new handle, a repainted r) first previews
the same way, then runs ``deformer.solve(targets)``: the exact result, the same computation
as a script's ``Deformer(...).solve(targets)``.

Secondary motion
----------------
With ``settings.dynamics`` the request is not solved for the static shape: the elastic
body of :mod:`arapkit.editor.motion` steps towards the targets, sending every step's
shape, until it settles or a newer drag move arrives (the body then carries on with it).

Examples
--------
>>> from arapkit.mesh.shapes import bar, bar_bend
>>> from arapkit.editor.settings import SolverSettings
>>> mesh = bar(); h, t = bar_bend(mesh, 30)
>>> updates = []
>>> w = SolveWorker(updates.append); w.start()
>>> seq = w.submit(SolveRequest(mesh, h, t, np.ones(mesh.n_vertices, int), SolverSettings()))
>>> w.wait_idle(60.0)
True
>>> updates[-1].final and updates[-1].seq == seq
True
>>> w.stop()
"""

from __future__ import annotations

import dataclasses
import threading
import time
import traceback
from collections import deque
from collections.abc import Callable
from typing import Any

import numpy as np

from arapkit.arap.domains import domain_of
from arapkit.arap.rings import BuildCancelled, ring_progress
from arapkit.editor.motion import SecondaryMotion
from arapkit.editor.settings import SolverSettings
from arapkit.errors import worded_for
from arapkit.mesh.weights import DEFAULT_WEIGHTS, WEIGHT_KINDS
from arapkit.methods.deformer import coarse_to_fine
from arapkit.methods.multires import DEFAULT_PROXY_VERTICES, MultiresDeformer, coarsening_of

LAPLACIAN_WEIGHTS = WEIGHT_KINDS
#: one preview chunk: proxy iterations run for about this long before a shape is sent;
#: with the chunk's start-up and the skinning, about 30 shapes a second
#: (the proxy keeps iterating between drag moves)
PREVIEW_FRAME_MS = 20.0

#: seconds between the progress reports (iterations and energy, no shape) of a large mesh's
#: exact solve after a release
PROGRESS_EVERY_S = 1.0
#: seconds between the progress reports of a long r-ring build, and the shortest build
#: (estimated) that reports: the page shows a bar and a Cancel button
BUILD_PROGRESS_EVERY_S = 0.25
BUILD_PROGRESS_FROM_S = 1.0


@dataclasses.dataclass
class SolveRequest:
    """Everything one solve needs; built on the UI thread, read-only afterwards."""

    mesh: Any
    handles: np.ndarray
    targets: np.ndarray
    rings: np.ndarray
    settings: SolverSettings
    init: np.ndarray | None = None  # start shape; default: the worker's last shape
    #: a drag in progress: a large mesh's proxy preview is enough (the release is not live)
    live: bool = False
    #: painted rigid parts and shared-rotation groups (a VertexGroups; None for none), read
    #: by the methods that take them (the registry's ``MethodInfo.groups``)
    groups: Any = None
    t_submit: float = dataclasses.field(default_factory=time.perf_counter)
    seq: int = 0


@dataclasses.dataclass
class SolveUpdate:
    """One shape sent to the display.

    ``final`` marks the last update of a request (a request stopped early for a newer
    one sends no final update).  ``latency_ms`` is measured from the request to the
    moment this update is handed to the publisher.
    """

    seq: int
    mesh: Any
    #: the full mesh's shape; None for a large mesh's preview before it settles (the
    #: display then draws ``proxy_vertices``) and for the progress of its exact solve
    #: (neither shape: the display keeps what it shows and updates its status line)
    vertices: np.ndarray | None
    energy: float
    iterations: int
    converged: bool
    final: bool
    latency_ms: float
    vertex_energy: np.ndarray | None = None
    error: str | None = None
    setup_ms: float = 0.0
    #: what the deformer says about the input, worded for the editor (e.g. raw cotangent drift)
    notes: tuple[str, ...] = ()
    #: the energy's unit per vertex, ``sum_e D_e |e|^2 / n`` at rest (nan: not known)
    energy_unit: float = float("nan")
    #: a large mesh's preview: the proxy mesh and its shape (what the display draws while
    #: dragging); None for a full-resolution shape
    proxy_mesh: Any = None
    proxy_vertices: np.ndarray | None = None
    #: a long r-ring build in progress: (fraction done, estimated seconds, what it costs);
    #: such an update has no shape and is not final
    building: tuple[float, float, str] | None = None


def _coarse_to_fine(mesh: Any, s: SolverSettings, groups: Any = None) -> bool:
    """Whether ``mesh`` is solved coarse to fine with these settings (by size unless they
    say; never a volume, whose tet graph has no surface to decimate, nor with groups,
    which have no proxy)."""
    return not s.volumetric and coarse_to_fine(mesh, s.multires,
                                               {"energy": s.method, "groups": groups})


def _groups_for(req: SolveRequest) -> Any:
    """The request's groups where its method reads them (surface methods with the
    registry's ``groups`` capability), else None: as a painted r is for one without a
    rigidity map, the painting is kept and ignored."""
    s = req.settings
    return req.groups if s.info.groups and not s.volumetric else None


def _build(req: SolveRequest, rings: Any, s: SolverSettings) -> Any:
    """The deformer the settings ask for: coarse to fine, volumetric or plain."""
    from arapkit import Deformer

    # a weighting the shape does not take (a mesh's kind on a point cloud, from a session
    # or the defaults) gives way to the shape's own: the panel offers the shape's kinds
    weights = s.weights if s.weights in domain_of(req.mesh).weight_kinds else None
    groups = _groups_for(req)
    if _coarse_to_fine(req.mesh, s, groups):
        # the proxy previews at once; the full factor is built in the background once the
        # first preview is out (started earlier, it competes with that preview)
        return MultiresDeformer(req.mesh, req.handles, rings, weights, energy=s.method,
                                tol=s.tol, max_iter=s.max_iter)
    # chosen above: not again by size
    return Deformer(req.mesh, req.handles, rings=rings, energy=s.method, weights=weights,
                    tol=s.tol, max_iter=s.max_iter, multires=False,
                    **({"volumetric": True} if s.volumetric else {}),
                    **({} if groups is None else {"groups": groups}))


class _Engine:
    """Library solver objects for the current configuration, rebuilt only when needed."""

    def __init__(self) -> None:
        self.mesh: Any = None
        self.deformer: Any = None
        self.laplacian: Any = None
        self._key: tuple = ()
        self._lap_key: tuple = ()

    def deformer_for(self, req: SolveRequest) -> Any:
        """The :class:`arapkit.Deformer` for ``req``, rebuilt only when the set-up changed."""
        s = req.settings
        info = s.info
        # only a method with a rigidity map reads the painted one; the others ignore it
        rings = req.rings if info.rigidity_map else 1
        # a volumetric deformer tetrahedralises once per mesh: kept while handles and r change;
        # a large mesh with groups is solved at full resolution, without them coarse to fine
        groups = _groups_for(req)
        key = (id(req.mesh), s.weights, s.method, s.volumetric, s.multires,
               _coarse_to_fine(req.mesh, s, groups))
        if self.deformer is None or self._key != key:
            self.deformer = _build(req, rings, s)
            self._key = key
            self.mesh = req.mesh
            return self.deformer
        d = self.deformer
        if info.rigidity_map and not np.array_equal(d.rings, req.rings):
            d.set_rings(req.rings)
        if not np.array_equal(d.handles, req.handles):
            d.set_handles(req.handles)
        if not _same_groups(getattr(d, "groups", None), groups):
            d.set_groups(groups)
        return d

    def laplacian_editor(self, req: SolveRequest) -> Any:
        from arapkit import LaplacianEditor

        w = req.settings.weights if req.settings.weights in LAPLACIAN_WEIGHTS else DEFAULT_WEIGHTS
        key = (id(req.mesh), w, req.handles.tobytes())
        if self.laplacian is None or key != self._lap_key:
            self.laplacian = LaplacianEditor(req.mesh, req.handles, weights=w)
            self._lap_key = key
        return self.laplacian


class SolveWorker:
    """Runs solves on a daemon thread and reports shapes through ``publish``.

    Parameters
    ----------
    publish : callable(SolveUpdate)
        Called on the worker thread; must not block for long (it delays the next solve).
    publish_interval_s : float
        Minimum time between intermediate updates after the live one.
    """

    def __init__(
        self, publish: Callable[[SolveUpdate], None], publish_interval_s: float = 0.15
    ) -> None:
        self._publish = publish
        self._interval = publish_interval_s
        self._cond = threading.Condition()
        self._pending: SolveRequest | None = None
        self._busy = False
        self._running = False
        self._seq = 0
        self._engine = _Engine()
        #: the elastic body of secondary motion (settings.dynamics), kept between drags
        self._motion = SecondaryMotion()
        self._shape: np.ndarray | None = None
        self._shape_mesh: Any = None
        self._thread: threading.Thread | None = None
        #: (seq, ms from request to first shape handed to publish), most recent last.
        self.latencies: deque[tuple[int, float]] = deque(maxlen=1000)
        self.dropped = 0
        self._last_error: str | None = None
        #: the last shape sent is a large mesh's proxy preview: a drag's release must
        #: still be solved exactly, even at the same pose
        self.previewing = False

    # ---------------------------------------------------------------- control
    def start(self) -> None:
        self._running = True
        self._thread = threading.Thread(target=self._loop, name="arapkit-solver", daemon=True)
        self._thread.start()

    def stop(self, timeout: float = 5.0) -> None:
        with self._cond:
            self._running = False
            self._pending = None
            self._cond.notify_all()
        if self._thread is not None:
            self._thread.join(timeout)

    def submit(self, req: SolveRequest) -> int:
        """Queue ``req`` in place of any pending one; returns its sequence number."""
        with self._cond:
            self._seq += 1
            req.seq = self._seq
            if self._pending is not None:
                self.dropped += 1
            self._pending = req
            self._cond.notify_all()
            return req.seq

    def expect(self, mesh: Any, settings: SolverSettings) -> None:
        """A mesh is about to be solved: start what takes long and needs only the mesh.

        A large mesh's proxy is decimated in a child process meanwhile (seconds that would
        otherwise hold this process's GIL while the page is being set up).
        """
        try:
            if _coarse_to_fine(mesh, settings):
                coarsening_of(mesh).start(mesh, DEFAULT_PROXY_VERTICES)
        except Exception:  # an early start only: the solve itself reports any problem
            pass

    def reset_shape(self, vertices: np.ndarray | None, mesh: Any = None) -> None:
        """Set the warm start for the next solve (e.g. after loading another mesh)."""
        V = None if vertices is None else np.array(vertices, dtype=np.float64)
        with self._cond:
            self._shape = V if V is None or np.isfinite(V).all() else None
            self._shape_mesh = mesh

    def wait_idle(self, timeout: float = 30.0) -> bool:
        """Block until no request is pending or running; ``False`` on timeout."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while self._pending is not None or self._busy:
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._cond.wait(left)
        return True

    @property
    def has_newer(self) -> bool:
        return self._pending is not None

    @property
    def deformer(self) -> Any:
        """The library solver of the current set-up (a :class:`arapkit.Deformer` or a
        :class:`~arapkit.methods.multires.MultiresDeformer`; None before the first solve):
        what a bench or a test asks whether its full factor is built."""
        return self._engine.deformer

    # ---------------------------------------------------------------- thread
    def _loop(self) -> None:
        while True:
            with self._cond:
                while self._running and self._pending is None:
                    self._cond.wait()
                if not self._running:
                    return
                req, self._pending = self._pending, None
                self._busy = True
            try:
                self._solve(req)
            except Exception as exc:  # keep the thread alive: report and wait for the next
                text = worded_for(exc.args[0], "editor") if exc.args else str(exc)
                msg = text.splitlines()[0] if text else type(exc).__name__
                # A bug repeats on every drag: print its traceback once, not 20 times a second.
                if not _is_input_error(exc) and msg != self._last_error:
                    traceback.print_exc()
                self._last_error = msg
                self._emit(req, self._start_shape(req), np.nan, 0, False, True, error=msg)
            finally:
                with self._cond:
                    self._busy = False
                    self._cond.notify_all()

    def _start_shape(self, req: SolveRequest) -> np.ndarray:
        # a non-finite shape is never a start: it would poison every later solve
        if req.init is not None:
            init = np.asarray(req.init, dtype=np.float64)
            if init.shape == req.mesh.vertices.shape and np.isfinite(init).all():
                return init
        if self._shape is not None and self._shape_mesh is req.mesh:
            return self._shape
        return np.asarray(req.mesh.vertices, dtype=np.float64)

    def _emit(
        self, req: SolveRequest, V: np.ndarray, energy: float, iters: int, converged: bool,
        final: bool, **extra: Any,
    ) -> None:
        latency = (time.perf_counter() - req.t_submit) * 1e3
        self._publish(
            SolveUpdate(req.seq, req.mesh, V, float(energy), iters, converged, final, latency,
                        **extra)
        )

    def _solve(self, req: SolveRequest) -> None:
        if len(req.handles) == 0:
            self._emit(req, self._start_shape(req), np.nan, 0, False, True,
                       error="no handles: select vertices and make a handle")
            return
        t0 = time.perf_counter()
        one_shot = _ONE_SHOT.get(req.settings.method)
        if req.settings.dynamics:
            self._solve_motion(req)
        elif one_shot is not None:
            one_shot(self, req, t0)
        else:
            self._solve_iterative(req, t0)

    def _solve_motion(self, req: SolveRequest) -> None:
        """Secondary motion: step the elastic body towards the targets until it settles or
        a newer drag move arrives (:mod:`arapkit.editor.motion`)."""
        first = [True]

        def emit(V: np.ndarray, energy: float, iters: int, converged: bool, final: bool,
                 **extra: Any) -> None:
            self._emit(req, V, energy, iters, converged, final, **extra)
            if first[0]:
                self._record_latency(req)
                first[0] = False

        self._motion.run(req, self._start_shape(req), emit, lambda: self.has_newer,
                         lambda V: self._keep(req, V))

    def _solve_laplacian(self, req: SolveRequest, t0: float) -> None:
        ed = self._engine.laplacian_editor(req)
        setup = (time.perf_counter() - t0) * 1e3
        V = np.asarray(ed.solve(req.targets), dtype=np.float64)
        if not np.isfinite(V).all():
            from arapkit.errors import InputError

            raise InputError("targets too large for double precision: the solve produced "
                             "non-finite positions")
        self._keep(req, V)
        self._emit(req, V, np.nan, 1, True, True, setup_ms=setup)
        self._record_latency(req)

    def _build_progress(self, req: SolveRequest) -> Callable[[float, Any], bool]:
        """The ring build's progress callback: reports a long build now and then, and
        cancels it as soon as a newer request waits (a new r, an undo, Cancel)."""
        last = [-1.0]

        def report(fraction: float, cost: Any) -> bool:
            if self.has_newer:
                return True
            now = time.perf_counter()
            if cost.seconds >= BUILD_PROGRESS_FROM_S and (
                    now - last[0] >= BUILD_PROGRESS_EVERY_S or fraction >= 1.0):
                last[0] = now
                self._emit(req, None, np.nan, 0, False, False,
                           building=(fraction, cost.seconds, cost.describe()))
            return False

        return report

    def _solve_iterative(self, req: SolveRequest, t0: float) -> None:
        s = req.settings
        try:
            # a large r's rings take seconds to minutes: built here, off the page's
            # thread, with progress, and given up for a newer request
            with ring_progress(self._build_progress(req)):
                d = self._engine.deformer_for(req)
        except BuildCancelled:
            return  # the newer request runs next, from the deformer as it was
        setup = (time.perf_counter() - t0) * 1e3
        if isinstance(d, MultiresDeformer):
            self._solve_coarse_to_fine(req, d, setup)
            return
        init = self._start_shape(req)
        live = {"sent": False, "last": 0.0, "count": 0}

        def callback(iteration: int, energy: float, vertices: np.ndarray) -> bool:
            live["count"] += 1
            now = time.perf_counter()
            if not live["sent"]:
                over_budget = (now - req.t_submit) * 1e3 >= s.live_budget_ms
                if live["count"] >= s.live_max_iter or over_budget:
                    self._emit(req, np.array(vertices), energy, live["count"], False, False,
                               setup_ms=setup)
                    self._record_latency(req)
                    live["sent"], live["last"] = True, time.perf_counter()
                return False
            # After the live update: stop for a newer drag, else report now and then.
            if self.has_newer:
                return True
            if now - live["last"] >= self._interval:
                self._emit(req, np.array(vertices), energy, live["count"], False, False)
                live["last"] = time.perf_counter()
            return False

        res = d.solve(req.targets, init=init, tol=s.tol, max_iter=s.max_iter, callback=callback)
        V = np.asarray(res.vertices, dtype=np.float64)
        self._keep(req, V)
        if self.has_newer and not res.converged and live["sent"]:
            # Superseded: the newer request starts from V and will be shown in a moment;
            # sending V now would only delay it.
            return
        self._emit_result(req, d, res, V, setup)
        if not live["sent"]:
            self._record_latency(req)

    def _solve_coarse_to_fine(self, req: SolveRequest, d: MultiresDeformer,
                              setup: float) -> None:
        """A large mesh: proxy previews, then (unless the request is live) the exact solve."""
        self.previewing = True
        init = proxy = None
        if not req.live and d.full_ready:
            # the exact solve starts from the proxy solved from rest: shown as the settled
            # preview, it replaces iterating the last drag shape to convergence first
            # (0.3-0.5 s of a release at 437K)
            started = self._coarse_preview(req, d, setup)
            if started is None:
                return
            init, proxy = started
        elif not self._preview(req, d, setup) or req.live:
            return
        last = [time.perf_counter()]

        def progress(iteration: int, energy: float) -> bool:
            if self.has_newer:
                return True
            now = time.perf_counter()
            if now - last[0] >= PROGRESS_EVERY_S:
                # the count and the energy only, the settled preview staying on screen: a
                # full shape (5-21 MB) looks no different from it, and having one to send
                # costs a copy of every vertex each iteration (40 ms of 0.5 s at 1.75M)
                self._emit(req, None, energy, iteration, False, False)
                last[0] = time.perf_counter()
            return False

        while not d.wait_ready(0.05):  # the full factor: stay open to a newer request
            if self.has_newer:
                return
        if proxy is not None and d.levels:
            # on through the intermediate levels to solve()'s own start; without one the
            # settled preview is that start already (skinning it again costs tens of ms
            # at 1.75M)
            init, _ = d.fine_start(req.targets, proxy, stop=lambda: self.has_newer)
            if init is None:
                return
        res = d.solve(req.targets, init=init, progress=progress)
        V = np.asarray(res.vertices, dtype=np.float64)
        if self.has_newer and not res.converged:
            return
        self._keep(req, V)
        self.previewing = False
        self._emit_result(req, d, res, V, setup)

    def _coarse_preview(self, req: SolveRequest, d: MultiresDeformer,
                        setup: float) -> tuple[np.ndarray, Any] | None:
        """Send the exact solve's first stage (the proxy from rest, skinned) as the settled
        preview; return it and the proxy's result (None when a newer request cut it short)."""
        init, pres = d.coarse_start(req.targets, callback=lambda *_: self.has_newer)
        if self.has_newer:
            return None
        self._keep(req, init)
        self._emit(req, init, pres.energy, pres.iterations, True, False, setup_ms=setup,
                   proxy_mesh=d.proxy_mesh, proxy_vertices=pres.vertices)
        self._record_latency(req)
        return init, pres

    def _preview(self, req: SolveRequest, d: MultiresDeformer, setup: float) -> bool:
        """Iterate the proxy a frame at a time, sending each shape; False if superseded."""
        count = 0
        T = d.checked_targets(req.targets)  # once, not on every frame
        while True:
            chunk_end = time.perf_counter() + PREVIEW_FRAME_MS / 1e3
            first = count == 0

            def frame(iteration: int, energy: float, vertices: np.ndarray,
                      chunk_end: float = chunk_end, first: bool = first) -> bool:
                # a request's first shape is always sent: a fast drag still sees motion
                return (self.has_newer and not first) or time.perf_counter() >= chunk_end

            # the display draws the proxy: the full mesh is mapped only once it settles
            p = d.preview(T, callback=frame, full=False)
            count += p.proxy.iterations
            done = bool(p.proxy.converged)
            # sent even when a newer move cut the chunk short: the proxy's shape costs
            # 0.24 MB and a millisecond, and a drag stays smooth between moves
            V = d.to_full(p.proxy, T) if done and not self.has_newer else None
            if V is not None:
                self._keep(req, V)
            self._emit(req, V, p.proxy.energy, count, done, done and req.live,
                       setup_ms=setup if first else 0.0,
                       proxy_mesh=d.proxy_mesh, proxy_vertices=p.proxy.vertices)
            if first:
                self._record_latency(req)
                d.prepare(background=True)
            if self.has_newer:
                return False
            if done:
                return True

    def _emit_result(self, req: SolveRequest, d: Any, res: Any, V: np.ndarray,
                     setup: float) -> None:
        """Send a deformer's final result with its energy colours, notes and energy unit."""
        self._emit(
            req, V, res.energy, res.iterations, bool(res.converged), True,
            vertex_energy=np.asarray(res.vertex_energy), setup_ms=setup,
            notes=tuple(worded_for(n, "editor") for n in d.notes), energy_unit=_energy_unit(d),
        )

    def _record_latency(self, req: SolveRequest) -> None:
        """Note the time from ``req`` to its first shape handed to the publisher."""
        self.latencies.append((req.seq, (time.perf_counter() - req.t_submit) * 1e3))

    def _keep(self, req: SolveRequest, V: np.ndarray) -> None:
        if np.isfinite(V).all():  # the solver refuses non-finite results; never keep one
            self._shape, self._shape_mesh = V, req.mesh


#: methods that :class:`arapkit.Deformer` does not run, with the one linear solve that does
_ONE_SHOT: dict[str, Callable[[SolveWorker, SolveRequest, float], None]] = {
    "laplacian": SolveWorker._solve_laplacian,
}


def _same_groups(a: Any, b: Any) -> bool:
    """Whether two VertexGroups (or None) are the same groups."""
    if a is None or b is None:
        return a is b
    return (a.names == b.names and np.array_equal(a.rigid, b.rigid)
            and np.array_equal(a.ids, b.ids))


def _energy_unit(deformer: Any) -> float:
    """The rest term of the deformer's energy per vertex, in the caller's units."""
    p = deformer.problem
    if p is None:  # not a local/global method
        return float("nan")
    return float(p.energy.rest_term * p.scale**2 / p.n_vertices)


def _is_input_error(exc: BaseException) -> bool:
    from arapkit.errors import InputError

    return isinstance(exc, InputError)
