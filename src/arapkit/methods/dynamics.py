"""ARAP dynamics: a body whose elastic energy is ARAP's, stepped in time by implicit Euler.

:class:`Simulator` is the stateful solver (positions, velocities, time; the factor reused
for every step of one length) and :func:`simulate` the one-shot call, as
:class:`~arapkit.methods.laplacian.LaplacianEditor` / ``laplacian_edit``. Each step
minimises implicit Euler's objective by local/global iterations on the ARAP engine
(:mod:`arapkit.arap.dynamics`, which derives it) until its relative decrease is below
``tol``.

Units are physical, the mesh's coordinates being metres: ``stiffness`` in N/m (the ARAP
energy is a length squared), ``density`` in kg/m^2 (a surface's mass is density times
area, lumped on the vertices: :func:`arapkit.mesh.mass.vertex_masses`), ``damping`` a
mass-damping rate in 1/s (Rayleigh's ``a M``: a body moving freely slows by
``1 / (1 + a dt)`` each step), ``gravity`` an acceleration in m/s^2 and ``forces`` per
vertex in N. The stiffness does not depend on ``dt``: halving the step does not make the
body stiffer (libigl's does: its stiffness is ``ym / dt^2``; :meth:`Simulator.like_libigl`
reproduces it).

Handles are vertices whose positions are given at every step: pinned (``targets=None``
keeps them where they are), or moved over time by a callable ``t -> (h, 3)`` such as
:class:`Keyframes` or :func:`ramp`.

``groups`` (as for :class:`~arapkit.methods.deformer.Deformer`, docs/groups.md) makes rigid
parts, which move by one rigid motion at every step (a handle inside one carries it), and
shared-rotation groups, whose members' neighbourhoods share one rotation.

Examples
--------
>>> import numpy as np
>>> from arapkit.mesh.shapes import bar
>>> m = bar()
>>> left = np.flatnonzero(m.vertices[:, 0] == 0)            # pin the left end
>>> traj = simulate(m, frames=31, dt=1 / 30, handles=left, gravity=[0, 0, -9.81])
>>> traj.vertices.shape, round(float(traj.times[-1]), 6)
((31, 1154, 3), 1.0)
>>> bool(traj.vertices[-1][:, 2].min() < -0.2)             # the free end sags
True
>>> from arapkit.mesh.groups import VertexGroups
>>> tip = np.flatnonzero(m.vertices[:, 0] > 6)               # the last metre: rigid
>>> g = VertexGroups.from_lists([("tip", tip, True)], m.n_vertices)
>>> traj = simulate(m, 11, dt=1 / 30, handles=left, gravity=[0, 0, -9.81], groups=g)
>>> d = traj.vertices[-1][tip] - traj.vertices[-1][tip[0]]
>>> bool(np.allclose(np.linalg.norm(d, axis=1),
...                  np.linalg.norm(m.vertices[tip] - m.vertices[tip[0]], axis=1), atol=1e-9))
True
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..arap.dynamics import LIBIGL_ENERGY_SCALE, STARTS, ImplicitEuler, Step, check_dt
from ..arap.problem import ARAPProblem
from ..errors import InputError
from ..mesh.mass import vertex_masses
from ..mesh.model import Mesh, as_mesh
from ..mesh.weights import DEFAULT_WEIGHTS
from ..validate import (
    integer,
    iteration_cap,
    number,
    real_array,
    target_positions,
    tolerance,
    vec3,
)
from .grouping import grouped_problem
from .keyframes import Keyframes, ramp

__all__ = ["DEFAULT_DAMPING", "DEFAULT_DT", "DEFAULT_STIFFNESS", "DEFAULT_TOL", "Keyframes",
           "Simulator", "Trajectory", "ramp", "simulate"]

#: 60 steps a second, a display's frame rate
DEFAULT_DT = 1.0 / 60.0
#: N/m: examples/bar.off (7 m long, 0.4 m square section, 1 kg/m^2) pinned at one end
#: bends visibly under gravity, swings once and settles (docs/dynamics.md)
DEFAULT_STIFFNESS = 3.0e4
#: 1/s: a free body's speed falls to 1/e in half a second; wobbles settle in a few seconds
DEFAULT_DAMPING = 2.0
#: the relative decrease of a step's objective that ends the step (docs/dynamics.md has the
#: measurement it was chosen from)
DEFAULT_TOL = 1e-6
#: frames x vertices a trajectory may hold in memory (24 bytes each: 2.4 GB)
MAX_FRAME_VERTICES = 100_000_000


@dataclass
class Trajectory:
    """The frames of a simulation.

    Attributes
    ----------
    vertices : (frames, n, 3)
        The shape at each frame; frame 0 is the start.
    faces : (m, 3)
    times : (frames,)
        Seconds.
    handles : (h,) int
    iterations : (frames - 1,) int
        Local/global iterations of each step.
    converged : (frames - 1,) bool
        Whether each step met ``tol`` (rather than ``max_iter``).
    kinetic, elastic, potential : (frames,)
        Kinetic energy, ``stiffness * E``, and the potential of gravity relative to frame
        0 (J).
    seconds : float
        Wall time.
    """

    vertices: np.ndarray
    faces: np.ndarray
    times: np.ndarray
    handles: np.ndarray
    iterations: np.ndarray
    converged: np.ndarray
    kinetic: np.ndarray
    elastic: np.ndarray
    potential: np.ndarray
    seconds: float = 0.0
    parameters: dict[str, Any] = field(default_factory=dict)

    @property
    def energy(self) -> np.ndarray:
        """Total mechanical energy per frame (J)."""
        return self.kinetic + self.elastic + self.potential


def _targets_at(targets, t: float, n_handles: int, current: np.ndarray) -> np.ndarray:
    """The handles' positions at time ``t`` from what the caller gave."""
    if targets is None:
        return current
    T = targets(t) if callable(targets) else targets
    return target_positions(np.empty(n_handles), T, "targets")


class Simulator:
    """ARAP dynamics of one mesh: implicit Euler steps, the factor reused (see the module).

    Parameters
    ----------
    mesh : Mesh, a (vertices, faces) pair, or a trimesh.Trimesh
    handles : (h,) int, (n,) bool, a HandleSet, or None
        Vertices whose positions are given at every step; None or empty: a free body.
    rings : int or (n,) int
        r per vertex (``energy="rring"``): larger is stiffer there.
    weights : str
        Edge weights (:mod:`arapkit.mesh.weights`).
    energy : str
        A registered descent energy (``"rring"``, ``"spokes-and-rims"``).
    dt : float
        Step length in seconds (default 1/60).
    stiffness : float
        N/m (default :data:`DEFAULT_STIFFNESS`).
    density : float
        kg/m^2 (default 1).
    damping : float
        Mass-damping rate in 1/s (default :data:`DEFAULT_DAMPING`; 0: none but implicit
        Euler's own).
    gravity : (3,) float
        Acceleration in m/s^2 (default none).
    mass : {"voronoi", "barycentric"}
        How the area is lumped on the vertices (:mod:`arapkit.mesh.mass`).
    tol, max_iter : float, int
        A step ends when its objective's relative decrease is below ``tol`` or after
        ``max_iter`` iterations (``tol=0``: always ``max_iter``, as libigl, even at rest).
    start : {"inertial", "previous"}
        Where each step's iterations start (see :mod:`arapkit.arap.dynamics`).
    accelerate : bool
        Anderson acceleration of each step's iterations, with the energy safeguard (the
        step's objective still never rises); default on (docs/dynamics.md measures it).
    groups : VertexGroups or (n,) int, optional
        Rigid parts and shared-rotation groups, as for
        :class:`~arapkit.methods.deformer.Deformer` (e.g. :func:`arapkit.io.load_groups`;
        an id array is libigl's ``G``, shared rotations). A part's vertices keep their
        distances at every step; a part with handles that no rigid motion meets is
        refused, naming it.

    Examples
    --------
    >>> import numpy as np
    >>> from arapkit.mesh.shapes import bar
    >>> m = bar()
    >>> sim = Simulator(m, np.flatnonzero(m.vertices[:, 0] == 0), gravity=[0, 0, -9.81])
    >>> s = sim.step()
    >>> s.converged, bool(np.all(np.diff(s.history) <= 0)), round(sim.time, 6)
    (True, True, 0.016667)
    """

    def __init__(self, mesh: Mesh, handles=None, rings=1, weights: str = DEFAULT_WEIGHTS, *,
                 energy: str = "rring", dt: float = DEFAULT_DT,
                 stiffness: float = DEFAULT_STIFFNESS, density: float = 1.0,
                 damping: float = DEFAULT_DAMPING, gravity=(0.0, 0.0, 0.0),
                 mass: str = "voronoi", tol: float = DEFAULT_TOL, max_iter: int = 1000,
                 start: str = "inertial", accelerate: bool = True, groups=None) -> None:
        self.mesh = mesh = as_mesh(mesh)
        n = mesh.n_vertices
        h = _handle_array(handles, n, mesh.name)
        self.masses = vertex_masses(mesh, density, mass)
        self.density, self.mass_kind = float(density), mass
        self.gravity = vec3(gravity, "gravity")
        self.tol, self.max_iter = tolerance(tol), iteration_cap(max_iter)
        if start not in STARTS:
            raise InputError(f"unknown start '{start}' (use {' or '.join(STARTS)})")
        self.start = start
        self.accelerate = bool(accelerate)
        # the static problem's handle set is not used (the system holds only `h`); one
        # vertex stands in when there is none, as the problem needs one
        self.problem = ARAPProblem.from_mesh(mesh, h if len(h) else [0], energy, weights,
                                             rings=rings)
        #: the vertex groups in use (None: none)
        self.groups = None
        if groups is not None:
            self.problem, self.groups = grouped_problem(self.problem, groups, energy, "cpu")
        self.system = ImplicitEuler(self.problem, self.masses, stiffness, check_dt(dt),
                                    damping, handles=h)
        self.positions = mesh.vertices.copy()
        self.velocities = np.zeros_like(self.positions)
        # the time is t0 + steps * dt, not a running sum: 30 steps of 1/30 s end at 1.0
        self._t0, self.steps = 0.0, 0

    @classmethod
    def like_libigl(cls, mesh: Mesh, handles, dt: float, ym: float = 1.0,
                    energy: str = "spokes-and-rims", max_iter: int = 10) -> Simulator:
        """libigl's ``arap_solve`` with ``with_dynamics``: same steps, to round-off.

        libigl's ``ARAPData`` with ``with_dynamics = true``, ``h = dt``, ``ym``,
        ``max_iter`` and ``energy`` (``ARAP_ENERGY_TYPE_SPOKES_AND_RIMS``, its default on
        3-D triangle meshes, or ``"rring"`` for ``ARAP_ENERGY_TYPE_SPOKES``): raw cotangent
        weights, Voronoi masses of density 1, stiffness ``ym / dt^2`` in libigl's energy
        scale (:data:`~arapkit.arap.dynamics.LIBIGL_ENERGY_SCALE`), no damping, a fixed
        ``max_iter`` iterations started from the last positions. Its ``f_ext`` is a force:
        pass it as ``forces`` to :meth:`step`.

        Examples
        --------
        >>> import numpy as np
        >>> from arapkit.mesh.shapes import bar
        >>> m = bar()
        >>> sim = Simulator.like_libigl(m, np.flatnonzero(m.vertices[:, 0] == 0), 1 / 30)
        >>> sim.step().iterations, round(sim.stiffness, 9)  # ym / dt^2 / 6
        (10, 150.0)
        """
        if energy not in LIBIGL_ENERGY_SCALE:
            raise InputError(f"like_libigl: energy '{energy}' has no libigl counterpart "
                             f"(use {' or '.join(LIBIGL_ENERGY_SCALE)})")
        dt = check_dt(dt)
        stiffness = number(ym, "ym", lo=0.0, lo_open=True) * LIBIGL_ENERGY_SCALE[energy] / dt**2
        return cls(mesh, handles, 1, "cotan", energy=energy, dt=dt, stiffness=stiffness,
                   density=1.0, damping=0.0, mass="voronoi", tol=0.0,
                   max_iter=max_iter, start="previous", accelerate=False)

    # -- parameters ----------------------------------------------------------------
    @property
    def handles(self) -> np.ndarray:
        """The handle vertices."""
        return self.system.handles

    @property
    def dt(self) -> float:
        """Step length (s); setting it refactorises."""
        return self.system.dt

    @dt.setter
    def dt(self, value: float) -> None:
        self._rebuild(dt=check_dt(value))

    @property
    def stiffness(self) -> float:
        """N/m; setting it refactorises."""
        return self.system.stiffness

    @stiffness.setter
    def stiffness(self, value: float) -> None:
        self._rebuild(stiffness=value)

    @property
    def damping(self) -> float:
        """Mass-damping rate (1/s); setting it refactorises."""
        return self.system.damping

    @damping.setter
    def damping(self, value: float) -> None:
        self._rebuild(damping=value)

    @property
    def time(self) -> float:
        """Seconds since the start."""
        return self._t0 + self.steps * self.dt

    def _rebuild(self, **changes: Any) -> None:
        self._t0, self.steps = self.time, 0  # a new dt counts from now
        s = self.system
        kw = {"stiffness": s.stiffness, "dt": s.dt, "damping": s.damping, **changes}
        self.system = ImplicitEuler(self.problem, self.masses, kw["stiffness"], kw["dt"],
                                    kw["damping"], handles=kw.get("handles", s.handles))

    def set_handles(self, handles) -> None:
        """Use another handle set (refactorises; positions and velocities are kept)."""
        self._rebuild(handles=_handle_array(handles, self.mesh.n_vertices, self.mesh.name))

    def set_rings(self, rings) -> None:
        """Use another rigidity map (refactorises)."""
        self.problem = self.problem.with_rings(rings)
        self._rebuild()

    def reset(self, positions=None, velocities=None, time: float = 0.0) -> None:
        """Start again from ``positions`` (default rest) and ``velocities`` (default 0)."""
        n = self.mesh.n_vertices
        self.positions = (self.mesh.vertices.copy() if positions is None
                          else _field(positions, n, "positions"))
        self.velocities = (np.zeros((n, 3)) if velocities is None
                           else _field(velocities, n, "velocities"))
        self._t0, self.steps = number(time, "time"), 0

    # -- stepping --------------------------------------------------------------------
    def step(self, targets=None, forces=None) -> Step:
        """Advance by ``dt``; the handles end at ``targets`` (default: where they are).

        Parameters
        ----------
        targets : (h, 3), optional
            The handles' positions at the end of the step.
        forces : (n, 3), optional
            Forces per vertex (N) during the step, beside gravity.
        """
        T = _targets_at(targets, self.time + self.dt, len(self.handles),
                        self.positions[self.handles])
        f = None if forces is None else _field(forces, self.mesh.n_vertices, "forces")
        s = self.system.step(self.positions, self.velocities, T, accel=self.gravity,
                             forces=f, tol=self.tol, max_iter=self.max_iter,
                             start=self.start, accelerate=self.accelerate)
        self.positions, self.velocities = s.positions, s.velocities
        self.steps += 1
        return s

    def energies(self) -> dict[str, float]:
        """Kinetic, elastic and gravitational energy now (J; gravity's relative to the
        origin)."""
        kin = 0.5 * float(np.sum(self.masses[:, None] * self.velocities ** 2))
        pot = -float(np.sum(self.masses * (self.positions @ self.gravity)))
        return {"kinetic": kin, "elastic": self.system.elastic_energy(self.positions),
                "potential": pot}

    def run(self, frames: int, targets=None, forces=None,
            callback: Callable[[int, Step], bool | None] | None = None) -> Trajectory:
        """Simulate ``frames - 1`` steps; frame 0 is the state now.

        Parameters
        ----------
        frames : int
            Frames to return, the current state first (>= 1).
        targets : None, (h, 3) or callable(t) -> (h, 3)
            Handle positions: pinned where they are, held at one pose, or moved over time
            (:class:`Keyframes`, :func:`ramp`).
        forces : None, (n, 3) or callable(t) -> (n, 3)
        callback : callable(frame, Step) -> bool, optional
            Called after each step; True stops (the trajectory ends there).
        """
        frames = integer(frames, "frames", lo=1)
        n = self.mesh.n_vertices
        if frames * n > MAX_FRAME_VERTICES:
            raise InputError(f"frames: {frames} frames of {n} vertices would take "
                             f"{frames * n * 24 / 2**30:.1f} GiB (keep frames x vertices "
                             f"under {MAX_FRAME_VERTICES:.0e}; step with Simulator.step to "
                             "keep only what you need)")
        t0 = time.perf_counter()
        pinned = self.positions[self.handles].copy()
        V = np.empty((frames, n, 3))
        times = np.empty(frames)
        its = np.zeros(frames - 1, dtype=np.int64)
        conv = np.zeros(frames - 1, dtype=bool)
        kin, ela, pot = (np.zeros(frames) for _ in range(3))
        e = self.energies()
        pot0 = e["potential"]
        V[0], times[0], kin[0], ela[0] = self.positions, self.time, e["kinetic"], e["elastic"]
        last = frames
        for k in range(1, frames):
            T = pinned if targets is None else targets
            f = forces(self.time + self.dt) if callable(forces) else forces
            s = self.step(T, f)
            V[k], times[k], its[k - 1], conv[k - 1] = s.positions, self.time, s.iterations, \
                s.converged
            kin[k] = 0.5 * float(np.sum(self.masses[:, None] * s.velocities ** 2))
            ela[k] = s.elastic
            pot[k] = -float(np.sum(self.masses * (s.positions @ self.gravity))) - pot0
            if callback is not None and callback(k, s):
                last = k + 1
                break
        return Trajectory(V[:last], self.mesh.faces, times[:last], self.handles.copy(),
                          its[:last - 1], conv[:last - 1], kin[:last], ela[:last],
                          pot[:last], time.perf_counter() - t0, self.parameters())

    def parameters(self) -> dict[str, Any]:
        """What a report records of this simulator."""
        return {"dt": self.dt, "stiffness": self.stiffness, "density": self.density,
                "damping": self.damping, "gravity": self.gravity.tolist(),
                "mass": self.mass_kind, "energy": self.problem.energy.name,
                "weights": self.problem.weights_kind, "tol": self.tol,
                "max_iter": self.max_iter, "start": self.start,
                "accelerate": self.accelerate,
                "groups": None if self.groups is None else self.groups.summary()}


def simulate(mesh: Mesh, frames: int, dt: float = DEFAULT_DT, handles=None, targets=None,
             forces=None, **options: Any) -> Trajectory:
    """Simulate ``mesh`` from rest for ``frames`` frames (one-shot :class:`Simulator`).

    Parameters
    ----------
    mesh, handles, dt :
        As for :class:`Simulator`.
    frames : int
        Frames to return, the rest shape first (so ``frames - 1`` steps).
    targets, forces :
        As for :meth:`Simulator.run`.
    **options :
        Any other keyword of :class:`Simulator` (``rings``, ``stiffness``, ``gravity`` ...).

    Examples
    --------
    >>> from arapkit.mesh.shapes import bar
    >>> t = simulate(bar(), 11, dt=0.1, gravity=[0, 0, -9.81], damping=0)  # a free fall
    >>> round(float(t.vertices[-1, :, 2].mean() - t.vertices[0, :, 2].mean()), 6)
    -5.3955
    """
    sim = Simulator(mesh, handles, dt=dt, **options)
    return sim.run(frames, targets, forces)


def _handle_array(handles, n: int, name: str) -> np.ndarray:
    """Handle vertices (possibly none) as int64."""
    from ..validate import handle_indices

    if handles is None:
        return np.zeros(0, dtype=np.int64)
    if not isinstance(handles, np.ndarray):
        handles = getattr(handles, "indices", handles)
    if np.size(handles) == 0:
        return np.zeros(0, dtype=np.int64)
    return handle_indices(handles, n, name)


def _field(values, n: int, what: str) -> np.ndarray:
    """An (n, 3) array of finite numbers, or a one-line error naming the first bad vertex."""
    from ..validate import check_finite_positions

    A = real_array(values, what)
    if A.shape != (n, 3):
        raise InputError(f"{what}: expected shape ({n}, 3), got {A.shape}")
    return check_finite_positions(A, what)
