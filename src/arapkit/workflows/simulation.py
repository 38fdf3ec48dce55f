"""One simulation from files: what ``arapkit simulate`` runs, as a library function.

:class:`SimulationJob` names the files and parameters; :func:`run_simulation` reads the
mesh, the handles (optional) and the rigidity map, builds the
:class:`~arapkit.methods.dynamics.Simulator` and runs it. Handles of a handle file that
move (a group with ``translate`` / ``rotate``) go from rest to their pose during the first
``ramp`` seconds, each group by one rigid motion (:func:`arapkit.methods.keyframes.ramp`),
and stay there; fixed groups stay pinned. Gravity defaults to 9.81 m/s^2 down the mesh's
guessed up axis (:func:`arapkit.mesh.orientation.guess_up`, as the figures' "up").

Examples
--------
>>> import tempfile, pathlib
>>> from arapkit.io import save_mesh
>>> from arapkit.mesh.shapes import bar
>>> d = pathlib.Path(tempfile.mkdtemp())
>>> _ = save_mesh(d / "bar.off", bar().vertices, bar().faces)
>>> out = run_simulation(SimulationJob(mesh=str(d / "bar.off"), frames=3))
>>> out.trajectory.vertices.shape, out.gravity.tolist(), out.gravity_reason[:17]
((3, 1154, 3), [0.0, 0.0, -9.81], 'down the guessed ')
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import InputError
from ..methods.dynamics import Simulator, Trajectory, ramp
from ..validate import vec3

__all__ = ["STANDARD_GRAVITY", "SimulationJob", "SimulationResult", "default_gravity",
           "run_simulation"]

#: m/s^2
STANDARD_GRAVITY = 9.81


def _simulator_defaults() -> dict[str, Any]:
    """The :class:`Simulator`'s own defaults (one copy of the values)."""
    params = inspect.signature(Simulator.__init__).parameters
    names = ("rings", "weights", "energy", "dt", "stiffness", "density", "damping", "mass",
             "tol", "max_iter", "accelerate")
    return {name: params[name].default for name in names}


_SIM = _simulator_defaults()


@dataclass
class SimulationJob:
    """Parameters of one simulation, as ``arapkit simulate`` takes them.

    Attributes
    ----------
    mesh : str
    handles : str or None
        A handle file (``.json`` groups or ``.sel``); None: a free body.
    transform : str or None
        ``.def`` matrix for a ``.sel`` file.
    frames : int
        Frames written, the rest shape first.
    ramp : float
        Seconds over which moved handle groups reach their pose.
    gravity : (3,) or None
        m/s^2; None: :func:`default_gravity`.
    groups : str or None
        A groups file (rigid parts and shared-rotation groups, docs/groups.md, read by
        :func:`arapkit.io.load_groups` as ``arapkit deform --groups``); None: none.
    rings, rings_file, weights, energy, dt, stiffness, density, damping, mass, tol,
    max_iter, accelerate :
        As for :class:`~arapkit.methods.dynamics.Simulator` (``rings_file`` as for
        ``arapkit deform``).
    """

    mesh: str
    handles: str | None = None
    transform: str | None = None
    frames: int = 120
    ramp: float = 1.0
    gravity: Any = None
    rings: int = _SIM["rings"]
    rings_file: str | None = None
    weights: str = _SIM["weights"]
    energy: str = _SIM["energy"]
    dt: float = _SIM["dt"]
    stiffness: float = _SIM["stiffness"]
    density: float = _SIM["density"]
    damping: float = _SIM["damping"]
    mass: str = _SIM["mass"]
    tol: float = _SIM["tol"]
    max_iter: int = _SIM["max_iter"]
    accelerate: bool = _SIM["accelerate"]
    groups: str | None = None


@dataclass
class SimulationResult:
    """A simulation's inputs as read and its trajectory."""

    mesh: Any
    handles: Any
    trajectory: Trajectory
    gravity: np.ndarray
    gravity_reason: str
    notes: list[str] = field(default_factory=list)
    #: the vertex groups simulated with (None for none)
    groups: Any = None


def default_gravity(vertices: np.ndarray) -> tuple[np.ndarray, str]:
    """9.81 m/s^2 down the guessed up axis, and why that axis.

    Examples
    --------
    >>> from arapkit.mesh.shapes import bar
    >>> g, why = default_gravity(bar().vertices)
    >>> g.tolist()
    [0.0, 0.0, -9.81]
    """
    from ..mesh.orientation import guess_up

    up = guess_up(vertices)
    g = np.zeros(3)
    g["xyz".index(up.axis[1])] = -STANDARD_GRAVITY if up.axis[0] == "+" else STANDARD_GRAVITY
    return g, f"down the guessed up axis {up.axis} ({up.reason})"


def run_simulation(job: SimulationJob, note: Callable[[str], None] | None = None,
                   callback: Callable[[int, Any], bool | None] | None = None
                   ) -> SimulationResult:
    """Read the job's files, simulate, return the trajectory (nothing is written).

    Parameters
    ----------
    job : SimulationJob
    note : callable(str), optional
        Called with each note about the input, prefixed with the mesh file name.
    callback : callable(frame, Step) -> bool, optional
        Called after each step (:meth:`Simulator.run`); True stops.

    Raises
    ------
    InputError
        Any bad input, in one line naming the file or parameter.
    """
    from ..io import load_groups, load_handles, load_mesh, load_rings

    notes: list[str] = []

    def tell(msg: str) -> None:
        notes.append(msg)
        if note is not None:
            note(f"{job.mesh}: {msg}")

    mesh = load_mesh(job.mesh)
    for msg in mesh.notes:
        tell(msg)
    hs = None
    if job.handles is not None:
        hs = load_handles(job.handles, mesh.vertices, job.transform)
    elif job.transform is not None:
        raise InputError(f"{job.transform}: a .def transform needs a .sel handle file")
    rings = load_rings(job.rings_file, mesh.n_vertices) if job.rings_file else job.rings
    groups = None if job.groups is None else load_groups(job.groups, mesh.vertices)
    if job.gravity is None:
        g, why = default_gravity(mesh.vertices)
    else:
        g, why = vec3(list(job.gravity), "gravity"), "as given"
    sim = Simulator(mesh, None if hs is None else hs.indices, rings, job.weights,
                    energy=job.energy, dt=job.dt, stiffness=job.stiffness,
                    density=job.density, damping=job.damping, gravity=g, mass=job.mass,
                    tol=job.tol, max_iter=job.max_iter, accelerate=job.accelerate,
                    groups=groups)
    targets = None
    if hs is not None and not np.array_equal(hs.targets, mesh.vertices[hs.indices]):
        sizes = np.cumsum([0] + [len(gr.indices) for gr in hs.groups])
        groups = [np.arange(a, b) for a, b in zip(sizes[:-1], sizes[1:])]
        targets = ramp(mesh.vertices[hs.indices], hs.targets, job.ramp, groups)
    traj = sim.run(job.frames, targets, callback=callback)
    return SimulationResult(mesh, hs, traj, g, why, notes, sim.groups)
