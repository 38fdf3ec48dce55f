"""2D as a domain of :class:`arapkit.Deformer`: which dimension a solve runs in, planar
targets and pin turns, and the rigidity presets.

A shape whose vertices share one z (or that is given as ``(n, 2)`` positions) is solved in
its plane by default: 2 x 2 rotations (:mod:`arapkit.arap.backends.planar`) and a
flip-preventing line search on the global step (:mod:`arapkit.arap.flips`), so that no
triangle turns over. Which methods can is data on the registry (``MethodInfo.planar``).

Rigidity presets
----------------
Photoshop's Puppet Warp offers three modes; here they are values of r (rings per vertex):

======== ===== ==========================================================================
preset     r   what it does
======== ===== ==========================================================================
distort    1   Sorkine & Alexa's ARAP: each one-ring fits its own rotation (most give)
normal     2   rotations fitted over two rings: parts bend more smoothly, stretch less
rigid      4   four rings: thin parts bend as a whole, small features keep their shape
======== ===== ==========================================================================

r counts rings of the mesh, so a preset's stiffness is relative to the mesh's edge length;
the image mesher's default density (:mod:`arapkit.image.meshing`) is what they were
chosen on.

Examples
--------
>>> preset_rings("Rigid"), PRESETS["normal"]
(4, 2)
"""

from __future__ import annotations

import numpy as np

from ..arap.backends import make_backend
from ..arap.flips import FlipGuard
from ..arap.loop import Result, local_global
from ..errors import InputError
from ..mesh.planar import PlanarInput

__all__ = ["FLIPS", "PRESETS", "PlanarSolver", "check_flips", "in_plane", "pin_neighbourhoods",
           "planar_start", "planar_targets", "preset_rings", "rings_or_preset", "solve_dim"]

#: rigidity presets (Photoshop's Puppet Warp modes) as r
PRESETS = {"distort": 1, "normal": 2, "rigid": 4}
#: what a planar solve does about triangles that would turn over (the first is the default)
FLIPS = ("prevent", "allow")


def preset_rings(name: str) -> int:
    """r of a rigidity preset (:data:`PRESETS`, any case), or a one-line InputError.

    Examples
    --------
    >>> preset_rings("distort")
    1
    """
    r = PRESETS.get(str(name).strip().lower())
    if r is None:
        raise InputError(f"unknown rigidity preset '{name}' (use "
                         f"{', '.join(PRESETS)}, or a number of rings)")
    return r


def rings_or_preset(rings):
    """``rings`` with a preset name read as its r (anything else is left to check_rings).

    Examples
    --------
    >>> rings_or_preset("rigid"), rings_or_preset(3)
    (4, 3)
    """
    return preset_rings(rings) if isinstance(rings, str) else rings


def check_flips(value) -> str:
    """One of :data:`FLIPS`.

    Examples
    --------
    >>> check_flips("Allow")
    'allow'
    """
    v = str(value).strip().lower()
    if v not in FLIPS:
        raise InputError(f"unknown flips policy '{value}' (use {' or '.join(FLIPS)})")
    return v


def solve_dim(shape: PlanarInput, dim, planar_method: bool, method_name: str) -> int:
    """The dimension a Deformer solves ``shape`` in: ``dim`` when given (2 or 3), else 2 for
    a planar shape and a method that runs in the plane, else 3.

    Examples
    --------
    >>> import numpy as np
    >>> s = PlanarInput.of((np.array([[0, 0, 1], [1, 0, 1], [0, 1, 1]], float), [[0, 1, 2]]))
    >>> solve_dim(s, None, True, "rring"), solve_dim(s, 3, True, "rring")
    (2, 3)
    """
    if dim is None:
        return 2 if shape.planar and planar_method else 3
    if dim not in (2, 3) or isinstance(dim, bool):
        raise InputError(f"dim: expected 2, 3 or None, got {dim!r}")
    if dim == 2 and not shape.planar:
        raise InputError(f"{shape.mesh.name}: dim=2 needs a planar mesh (one z for every "
                         "vertex, or (n, 2) positions)")
    if dim == 2 and not planar_method:
        raise InputError(f"dim=2: energy '{method_name}' does not run in the plane")
    if dim == 3 and shape.given_dim == 2:
        raise InputError("dim=3: the shape was given as (n, 2) positions; give (n, 3) "
                         "positions to deform it in 3D")
    return dim


def in_plane(shape: PlanarInput, multires, options: dict) -> bool:
    """Whether ``Deformer(shape, ..., **options)`` solves in the plane (coarse to fine,
    a 3D variant, is then refused).

    Examples
    --------
    >>> s = PlanarInput.of((np.array([[0, 0], [1, 0], [0, 1]], float), [[0, 1, 2]]))
    >>> in_plane(s, None, {}), in_plane(s, None, {"energy": "embedded"})
    (True, False)
    """
    from .registry import method, method_names

    energy = options.get("energy", "rring")
    if energy not in method_names("library"):
        return False  # Deformer itself says which names there are
    plane = solve_dim(shape, options.get("dim"), method(energy).planar, energy) == 2
    if plane and multires:
        raise InputError("multires=True is for 3D surfaces; a planar shape is solved in 2D "
                         "(pass dim=3 to solve it in 3D)")
    return plane


def pin_neighbourhoods(problem, handles: np.ndarray, angles) -> tuple[np.ndarray, np.ndarray]:
    """The rotations a turned pin holds: its own and its one-ring neighbours' (internal
    numbering), each at the pin's angle. ``angles`` is one angle (radians) per handle,
    NaN for a pin without a turn. Where two turned pins share a neighbour, the later wins.

    Examples
    --------
    >>> from arapkit.arap.problem import ARAPProblem
    >>> V = np.array([[0, 0], [1, 0], [0, 1], [1, 1]], float)
    >>> p = ARAPProblem.from_mesh((V, [[0, 1, 2], [1, 3, 2]]), [0, 3], dim=2)
    >>> owners, a = pin_neighbourhoods(p, p.handles, [0.5, np.nan])
    >>> sorted(p.perm[owners].tolist()), a.tolist()
    ([0, 1, 2], [0.5, 0.5, 0.5])
    """
    a = np.asarray(angles, dtype=np.float64).reshape(-1)
    if a.shape != (len(handles),):
        raise InputError(f"angles: expected one angle per handle ({len(handles)}), "
                         f"got {a.size}")
    if np.isinf(a).any():
        raise InputError(f"angles: handle {int(np.flatnonzero(np.isinf(a))[0])} has an "
                         "infinite angle")
    turned = np.flatnonzero(~np.isnan(a))
    if not len(turned):
        return np.zeros(0, np.int64), np.zeros(0)
    E = problem.edges
    owners, values = [], []
    for i in turned:
        k = problem.iperm[handles[i]]
        ring = np.concatenate([[k], E[E[:, 0] == k, 1], E[E[:, 1] == k, 0]])
        owners.append(ring)
        values.append(np.full(len(ring), a[i]))
    return np.concatenate(owners).astype(np.int64), np.concatenate(values)


def planar_targets(shape: PlanarInput, handles: np.ndarray, targets) -> np.ndarray:
    """Checked targets of a planar solve: ``(h, 2)`` in the plane, or ``(h, 3)`` where 3D
    targets leave it (the caller then solves in 3D).

    Examples
    --------
    >>> s = PlanarInput.of((np.array([[0, 0], [1, 0], [0, 1]], float), [[0, 1, 2]]))
    >>> planar_targets(s, np.array([0]), [[2, 3]]).tolist()
    [[2.0, 3.0]]
    >>> planar_targets(s, np.array([0]), [[2, 3, 0]]).shape
    (1, 2)
    """
    from ..arap.constraints import check_targets
    from ..validate import real_array

    if not isinstance(targets, np.ndarray):
        targets = getattr(targets, "targets", targets)
    T = real_array(targets, "targets")
    h = len(handles)
    if T.ndim != 2 or len(T) != h or T.shape[1] not in (2, 3):
        raise InputError(f"targets: expected shape ({h}, 2) (or ({h}, 3) on the plane), "
                         f"got {T.shape}")
    if T.shape[1] == 2:
        T = np.concatenate([T, np.full((h, 1), shape.z)], axis=1)
    T = check_targets(handles, T)  # finiteness, with the handle named
    inside = shape.targets_in_plane(T)
    return T if inside is None else np.ascontiguousarray(inside)


def planar_start(shape: PlanarInput, P: np.ndarray) -> np.ndarray:
    """A start shape ``(n, 2)`` or ``(n, 3)`` (caller's numbering) as the plane's ``(n, 2)``.

    Examples
    --------
    >>> s = PlanarInput.of((np.array([[0, 0], [1, 0], [0, 1]], float), [[0, 1, 2]]))
    >>> planar_start(s, np.zeros((3, 3))).shape
    (3, 2)
    """
    n = shape.mesh.n_vertices
    if P.ndim != 2 or len(P) != n or P.shape[1] not in (2, 3) or not np.isfinite(P).all():
        raise InputError(f"init: expected finite positions of shape ({n}, 2) or ({n}, 3)")
    return np.ascontiguousarray(P[:, :2])


class PlanarSolver:
    """The planar side of a :class:`arapkit.Deformer`: a guarded 2D solve, or a 3D one on
    the same factor where the targets leave the plane.

    Parameters
    ----------
    shape : PlanarInput
    flips : {"prevent", "allow"}
        The flip guard's policy (:mod:`arapkit.arap.flips`).
    device : str
        For the 3D twin's backend.
    """

    def __init__(self, shape: PlanarInput, flips: str, device: str) -> None:
        self.shape = shape
        self.flips = check_flips(flips)
        self.device = device
        self._twin = None  # (2D problem, its 3D twin, the twin's backend)
        self._guard = None  # (problem, backend, its flip guard): built once, reused

    def solve(self, problem, backend, handles: np.ndarray, T: np.ndarray, start, angles,
              **loop) -> Result:
        """Solve for targets ``(h, 2)`` in the plane, or ``(h, 3)`` off it; results in the
        shape's own dimension. ``loop`` holds :func:`local_global`'s options."""
        if T.shape[1] == 3:
            if angles is not None:
                raise InputError("angles: pin turns are for targets in the plane")
            if self._twin is None or self._twin[0] is not problem:
                p3 = problem.with_dim(3)
                self._twin = (problem, p3, make_backend(p3, self.device).bind(p3))
            return local_global(self._twin[1], self._twin[2], T, start, **loop)
        backend.hold_rotations(*pin_neighbourhoods(problem, handles, angles)
                               if angles is not None else (None, None))
        if self._guard is None or self._guard[0] is not problem or self._guard[1] is not backend:
            self._guard = (problem, backend, FlipGuard(problem, backend,
                                                       prevent=self.flips == "prevent"))
        guard = self._guard[2]
        res = local_global(problem, backend, T, start, guard=guard, **loop)
        res.vertices = self.shape.to_caller(res.vertices)
        return res
