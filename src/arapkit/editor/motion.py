"""Secondary motion in the editor: a drag moves an elastic body that lags and settles.

With the solver panel's *Secondary motion* ticked (:attr:`SolverSettings.dynamics
<arapkit.editor.settings.SolverSettings>`), the solve thread does not solve for the static
shape: it steps an ARAP body in time (:class:`arapkit.methods.dynamics.Simulator`, no
gravity) whose handles follow the gizmos. Each drag move is one request; the body's state
(positions, velocities) carries from one request to the next, so a fast drag leaves the
free parts behind and a stop lets them swing through and settle. Steps are
:data:`EDITOR_DT` long and paced to the clock (a step that takes longer plays in slow
motion); every step's shape is sent. The request ends, with a final update, once the body
has settled: every vertex slower than :data:`SETTLED_SPEED` mesh diagonals per second for
three steps in a row, or after :data:`MAX_SECONDS` of simulated time. Painted rigid parts
and shared-rotation groups go to the body as they go to the static solve (for the methods
that take them): a rigid part swings as one piece.

Units: the editor cannot know what a mesh's unit is, so the stiffness defaults to
:func:`editor_stiffness`, the library's default scaled so that a mesh of any size wobbles
on the time scale of examples/bar.off at the default (a body's time scale grows with its
size over the square root of the stiffness). A session may set ``stiffness`` (N/m) and
``damping`` (1/s) itself.

Examples
--------
>>> from arapkit.mesh.shapes import bar
>>> round(editor_stiffness(bar()) / DEFAULT_STIFFNESS, 3)  # the bar is the reference
1.0
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np

from arapkit.errors import InputError
from arapkit.methods.dynamics import DEFAULT_STIFFNESS, Simulator

__all__ = ["EDITOR_DT", "MAX_SECONDS", "MAX_VERTICES", "SETTLED_SPEED", "SecondaryMotion",
           "editor_stiffness"]

#: the editor's step: 30 shapes a second
EDITOR_DT = 1.0 / 30.0
#: mesh diagonals per second below which a vertex counts as at rest
SETTLED_SPEED = 1e-4
#: a request's simulated time at most (a body that never settles still ends)
MAX_SECONDS = 20.0
#: the largest mesh secondary motion runs on (a step factorises and iterates the full mesh)
MAX_VERTICES = 100_000
#: the bounding-box diagonal of examples/bar.off (7 x 0.4 x 0.4), the stiffness's reference
REFERENCE_DIAGONAL = float(np.sqrt(7.0**2 + 2 * 0.4**2))


def editor_stiffness(mesh: Any) -> float:
    """The default stiffness on ``mesh``: the library's, scaled by the square of the mesh's
    size relative to examples/bar.off, so that its motion has the bar's time scale.

    A body scaled by ``s`` (masses by ``s^2``, forces of the same strain by ``s``) at the
    same stiffness moves ``s`` times slower; ``s^2`` times the stiffness gives its time
    back.
    """
    return DEFAULT_STIFFNESS * (float(mesh.bounding_box_diagonal) / REFERENCE_DIAGONAL) ** 2


def _energy_of(settings: Any) -> str:
    """The elastic energy a method of the panel gives the body, or a one-line refusal."""
    from arapkit.arap.energies import energy_info

    info = settings.info
    if settings.volumetric or not info.local_global or not energy_info(info.name).descent:
        raise InputError(f"secondary motion runs a local/global descent method (r-ring ARAP, "
                         f"spokes-and-rims) on the surface, not {settings.label}")
    return info.name


class SecondaryMotion:
    """The body the drags move: a :class:`Simulator` kept while the set-up stays."""

    def __init__(self) -> None:
        self.sim: Simulator | None = None
        self._key: tuple = ()
        #: the last shape this body produced (the worker's warm start while it is current)
        self.last: np.ndarray | None = None

    def simulator_for(self, req: Any, start: np.ndarray) -> Simulator:
        """The body for ``req``, rebuilt when the mesh, handles, r or parameters change;
        restarted at rest speed from ``start`` when the shape shown is not its own."""
        s = req.settings
        mesh = req.mesh
        if mesh.n_vertices > MAX_VERTICES:
            raise InputError(f"secondary motion runs on meshes of up to {MAX_VERTICES:,} "
                             f"vertices (this one has {mesh.n_vertices:,}); untick it")
        energy = _energy_of(s)
        rings = req.rings if s.info.rigidity_map else 1
        # as the static solve: the painting is read by the methods that take groups
        groups = req.groups if s.info.groups else None
        stiffness = editor_stiffness(mesh) if s.stiffness is None else s.stiffness
        key = (id(mesh), np.asarray(req.handles).tobytes(), np.asarray(rings).tobytes(),
               s.weights, energy, stiffness, s.damping, _groups_key(groups))
        if self.sim is None or key != self._key:
            self.sim = Simulator(mesh, req.handles, rings, s.weights, energy=energy,
                                 dt=EDITOR_DT, stiffness=stiffness, damping=s.damping,
                                 groups=groups)
            self._key = key
            self.last = None
        if start is not self.last:  # an undo, a static solve, another mesh: start there
            self.sim.reset(positions=start)
        return self.sim

    def run(self, req: Any, start: np.ndarray, emit: Callable[..., None],
            superseded: Callable[[], bool], keep: Callable[[np.ndarray], None]) -> None:
        """Step towards ``req``'s targets until settled or superseded, sending each shape.

        ``emit(V, energy, iterations, converged, final, **extra)`` sends a shape,
        ``superseded()`` says a newer request waits (the body then carries on with it) and
        ``keep(V)`` records the worker's warm start.
        """
        t0 = time.perf_counter()
        sim = self.simulator_for(req, start)
        setup_ms = 1e3 * (time.perf_counter() - t0)
        diag = float(req.mesh.bounding_box_diagonal)
        slow = SETTLED_SPEED * diag
        targets = np.asarray(req.targets, dtype=np.float64)
        quiet = 0
        t_start = time.perf_counter()
        steps = 0
        while True:
            step = sim.step(targets)
            steps += 1
            V = step.positions
            self.last = V
            keep(V)
            speed = float(np.sqrt((step.velocities ** 2).sum(axis=1).max()))
            quiet = quiet + 1 if speed < slow else 0
            final = quiet >= 3 or steps * sim.dt >= MAX_SECONDS
            emit(V, step.elastic, step.iterations, final, final,
                 setup_ms=setup_ms if steps == 1 else 0.0,
                 notes=(f"secondary motion: stiffness {sim.stiffness:.3g} N/m, damping "
                        f"{sim.damping:g}/s, {steps} steps of {sim.dt:.3g} s",) if final
                 else ())
            if final or superseded():
                return
            # paced to the clock: a step is dt of the body's time
            wait = t_start + steps * sim.dt - time.perf_counter()
            if wait > 0:
                time.sleep(wait)
            if superseded():
                return


def _groups_key(groups: Any) -> tuple:
    """What of the groups (a VertexGroups or None) makes another body."""
    if groups is None:
        return ()
    return (groups.names, np.asarray(groups.rigid).tobytes(), np.asarray(groups.ids).tobytes())
