"""The add-on's solver: one background thread, the newest handle pose wins, nothing queues.

Blender runs Python on its main thread, the one that draws the viewport: a solve there
freezes Blender for as long as it takes. So the add-on only reads the handle objects,
hands the targets to :meth:`LiveDeformer.request` and, from a timer, takes the newest shape
with :meth:`LiveDeformer.poll` to write into the shape key. Everything else runs here, on
one thread that owns the library objects: building the :class:`arapkit.Deformer` (with its
factorisation; coarse to fine from 100K vertices, as ``Deformer(..., multires=None)``
decides), and every solve. The compiled kernels release the GIL, so Blender's main thread
keeps running beside them.

Two kinds of request
--------------------
* **live** (a handle is being dragged): iterate warm-started from the last shape (with
  Anderson acceleration where the method takes it) and send a shape once
  :data:`FRAME_MS` has passed since the last one; stop as soon as a newer request waits.
  A large mesh iterates its proxy
  (:meth:`~arapkit.methods.multires.MultiresDeformer.preview`) and sends the skinned full
  shape.
* **exact**: ``deformer.solve(targets)`` from rest, the same computation as a script's
  ``Deformer(...).solve(targets)``, so the shape key does not depend on the path the drag
  took: what the Deform button, rendering and ``blender -b`` ask for.

When a drag stops, a plain mesh's live solve simply runs on to convergence, warm-started (as
the browser editor's does: it lands within the stopping test of the exact solve, without
starting over). A large mesh's preview is its proxy's, so there, once no newer request came
for :data:`SETTLE_S`, the exact solve follows (the editor's release).

Examples
--------
>>> from arapkit.mesh.shapes import bar, bar_bend
>>> mesh = bar(); h, t = bar_bend(mesh, 30)
>>> live = LiveDeformer(mesh, h, rings=2)
>>> live.request(t, exact=True)
1
>>> shape = live.wait(120.0)
>>> shape.exact, shape.converged, shape.error
(True, True, None)
>>> live.close()
"""

from __future__ import annotations

import dataclasses
import threading
import time
from typing import Any

import numpy as np

from ..errors import InputError, worded_for
from ..mesh.model import Mesh
from ..mesh.weights import DEFAULT_WEIGHTS
from ..methods.deformer import Deformer
from ..methods.multires import MultiresDeformer
from ..methods.registry import method as method_info

__all__ = ["FRAME_MS", "SETTLE_S", "LiveDeformer", "Shape"]

#: a live solve sends a shape when this long (ms) has passed since the last one: one
#: viewport frame at 60 Hz. Counted from the last shape sent, not from the start of a solve,
#: so that a new pose that follows a quiet frame shows after its first iteration (each pose
#: of a drag would otherwise pay a whole frame before it is seen).
FRAME_MS = 1000.0 / 60.0
#: a drag has stopped when no newer pose came for this long (s); then the exact solve runs
SETTLE_S = 0.25


@dataclasses.dataclass(frozen=True)
class Shape:
    """One shape for the shape key, or the message of a solve that failed.

    Attributes
    ----------
    seq : int
        The request it answers (:meth:`LiveDeformer.request`'s number).
    vertices : (n, 3) float64 or None
        The deformed positions; None when the solve failed (see :attr:`error`).
    exact : bool
        The exact solve (from rest), not a live one.
    converged : bool
    iterations : int
    energy : float
    elapsed_ms : float
        From the request to this shape.
    error : str or None
        A one-line message for Blender's report area.
    notes : tuple of str
        What the deformer said about the input, worded for the add-on's panel.
    """

    seq: int
    vertices: np.ndarray | None
    exact: bool
    converged: bool
    iterations: int
    energy: float
    elapsed_ms: float
    error: str | None = None
    notes: tuple[str, ...] = ()


@dataclasses.dataclass
class _Request:
    seq: int
    targets: np.ndarray
    exact: bool
    t0: float


class LiveDeformer:
    """A deformer on its own thread, for a caller that must never wait for a solve.

    Parameters
    ----------
    mesh : Mesh
        The rest mesh.
    handles : (h,) int
        Handle vertices.
    rings : int or (n,) int
        r per vertex (only read by a method with a rigidity map).
    method : str
        A method the registry offers to the ``"blender"`` door.
    weights, tol, max_iter, multires :
        As for :class:`arapkit.Deformer` (``multires=None``: coarse to fine from 100K
        vertices).
    frame_ms : float
        How often a live solve sends a shape.
    settle_s : float
        How long a drag on a large mesh must pause before the exact solve runs (None:
        never).
    """

    def __init__(self, mesh: Mesh, handles, rings=1, *, method: str = "rring",
                 weights: str = DEFAULT_WEIGHTS, tol: float = 1e-3, max_iter: int = 1000,
                 multires: bool | None = None, frame_ms: float = FRAME_MS,
                 settle_s: float | None = SETTLE_S) -> None:
        info = method_info(method, "blender")  # a one-line refusal for a method not offered
        self._options = dict(rings=rings if info.rigidity_map else 1, weights=weights,
                             energy=info.name, tol=tol, max_iter=max_iter, multires=multires)
        # a drag leaves the shape behind its handles; Anderson acceleration (safeguarded:
        # the energy still falls every step) catches up in fewer iterations where the
        # method takes it. The exact solve keeps the library's default, as a script has it.
        self._accelerate = info.accelerate
        self.mesh = mesh
        self.handles = np.asarray(handles, dtype=np.int64)
        self.frame_ms = float(frame_ms)
        self.settle_s = settle_s
        self._cond = threading.Condition()
        self._pending: _Request | None = None
        self._busy = False
        self._open = True
        self._seq = 0
        self._latest: Shape | None = None
        self._sent_at = -np.inf  # perf_counter() of the last shape sent
        self._taken = 0  # how many shapes had been sent when the caller last took one
        self._deformer: Any = None
        self._shape: np.ndarray | None = None  # the warm start of the next live solve
        #: what the thread is doing, for the panel ("preparing", "solving", "idle", ...)
        self.status = "preparing"
        #: shapes sent so far (a bench counts them)
        self.sent = 0
        self._thread = threading.Thread(target=self._run, name="arapkit-blender", daemon=True)
        self._thread.start()

    # ----------------------------------------------------------------- the caller's side
    def request(self, targets, exact: bool = False) -> int:
        """Solve for ``targets`` ((h, 3), the handles' order), replacing any waiting request.

        Returns the request's number, which the shapes that answer it carry.
        """
        T = np.array(targets, dtype=np.float64)
        with self._cond:
            self._seq += 1
            self._pending = _Request(self._seq, T, bool(exact), time.perf_counter())
            self._cond.notify_all()
            return self._seq

    def poll(self) -> Shape | None:
        """The newest shape not yet taken, or None (never waits: for Blender's timer)."""
        with self._cond:
            if self._latest is None or self._taken == self.sent:
                return None
            self._taken = self.sent  # shapes are counted: an id() could be reused
            return self._latest

    def wait(self, timeout: float | None = None) -> Shape | None:
        """Wait until no request is waiting or running; return the newest shape.

        For scripts and the command line (``blender -b``), where nothing else runs.
        """
        deadline = None if timeout is None else time.monotonic() + timeout
        with self._cond:
            while self._pending is not None or self._busy:
                left = None if deadline is None else deadline - time.monotonic()
                if left is not None and left <= 0:
                    break
                self._cond.wait(left)
            self._taken = self.sent
            return self._latest

    @property
    def busy(self) -> bool:
        """A request is waiting or being solved."""
        return self._pending is not None or self._busy

    @property
    def deformer(self) -> Any:
        """The library's deformer (None until the thread has built it)."""
        return self._deformer

    def close(self, timeout: float = 5.0) -> None:
        """Stop the thread (a running solve stops at its next iteration)."""
        with self._cond:
            self._open = False
            self._pending = None
            self._cond.notify_all()
        self._thread.join(timeout)

    # ------------------------------------------------------------------- the thread
    def _newer(self) -> bool:
        return self._pending is not None or not self._open

    def _publish(self, shape: Shape) -> None:
        with self._cond:
            self._latest = shape
            self._sent_at = time.perf_counter()
            self.sent += 1
            self._cond.notify_all()

    def _run(self) -> None:
        while True:
            with self._cond:
                while self._open and self._pending is None:
                    self._cond.wait()
                if not self._open:
                    return
                req, self._pending = self._pending, None
                self._busy = True
            try:
                self._serve(req)
            except Exception as exc:  # the thread lives on: the panel shows the message
                text = worded_for(exc.args[0], "blender") if exc.args else type(exc).__name__
                if not isinstance(exc, InputError):
                    text = f"internal error ({type(exc).__name__}): {text}"
                self.status = "error"
                self._publish(Shape(req.seq, None, req.exact, False, 0, float("nan"),
                                    _ms(req), error=str(text).splitlines()[0]))
            finally:
                with self._cond:
                    self._busy = False
                    self._cond.notify_all()

    def _build(self) -> Any:
        if self._deformer is None:
            self.status = "preparing"
            self._deformer = Deformer(self.mesh, self.handles, **self._options)
        return self._deformer

    def _serve(self, req: _Request) -> None:
        d = self._build()
        if req.exact:
            self._exact(d, req)
            return
        self.status = "solving"
        if isinstance(d, MultiresDeformer):
            converged = self._live_coarse(d, req)
        else:
            converged = self._live(d, req)
        if not converged or self.settle_s is None or not isinstance(d, MultiresDeformer):
            return  # a plain live solve that converged is the result
        with self._cond:  # the drag has stopped: the exact solve for the same targets
            self._cond.wait_for(self._newer, self.settle_s)
            if self._newer():
                return
        self._exact(d, req)

    def _exact(self, d: Any, req: _Request) -> None:
        self.status = "solving (exact)"
        res = d.solve(req.targets, progress=lambda it, E: self._newer())
        if self._newer() and not res.converged:
            return  # superseded: the newer request starts from the shape kept below
        V = np.asarray(res.vertices, dtype=np.float64)
        self._shape = V
        self.status = "idle"
        self._publish(Shape(req.seq, V, True, bool(res.converged), int(res.iterations),
                            float(res.energy), _ms(req),
                            notes=tuple(worded_for(n, "blender") for n in d.notes)))

    def _live(self, d: Deformer, req: _Request) -> bool:
        """Iterate from the last shape, sending one every frame; True if it converged."""
        frame = self.frame_ms / 1e3
        state = {"sent": False}

        def callback(iteration: int, energy: float, V: np.ndarray) -> bool:
            if time.perf_counter() >= self._sent_at + frame:
                self._shape = V
                self._publish(Shape(req.seq, V, False, False, iteration, energy, _ms(req)))
                state["sent"] = True
            # a newer pose stops this one, once it has shown something
            return state["sent"] and self._newer()

        res = d.solve(req.targets, init=self._shape, callback=callback,
                      accelerate=self._accelerate)
        V = np.asarray(res.vertices, dtype=np.float64)
        self._shape = V
        if not (self._newer() and state["sent"]):
            self._publish(Shape(req.seq, V, False, bool(res.converged), int(res.iterations),
                                float(res.energy), _ms(req)))
        return bool(res.converged) and not self._newer()

    def _live_coarse(self, d: MultiresDeformer, req: _Request) -> bool:
        """A large mesh: iterate the proxy a frame at a time, sending the skinned shape."""
        T = d.checked_targets(req.targets)
        frame = self.frame_ms / 1e3
        first = True
        while True:
            due = time.perf_counter() + frame
            p = d.preview(T, callback=lambda it, E, V, due=due, first=first:
                          time.perf_counter() >= due or (not first and self._newer()))
            self._shape = p.vertices
            self._publish(Shape(req.seq, p.vertices, False, bool(p.proxy.converged),
                                int(p.proxy.iterations), float(p.proxy.energy), _ms(req)))
            if first:  # the exact solve's factor, built beside the drag
                d.prepare(background=True)
                first = False
            if self._newer():
                return False
            if p.proxy.converged:
                return True


def _ms(req: _Request) -> float:
    return (time.perf_counter() - req.t0) * 1e3
