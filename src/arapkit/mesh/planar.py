"""Planar shapes: meshes whose vertices lie in one plane ``z = const``, and 2D input.

2D is a domain of its own in arapkit (issue 48): a planar shape is deformed with 2 x 2
rotations in its plane (:mod:`arapkit.arap.backends.planar`), where a 3D solve may turn a
neighbourhood over (a half turn about an in-plane axis is a rotation in 3D and a reflection
in the plane) and fold the shape. This module holds what the doors share about planar
input: recognising it, lifting ``(n, 2)`` positions into a :class:`~arapkit.mesh.model.Mesh`
(z = 0) and returning results in the caller's own dimension, and the triangles' orientation.

Examples
--------
>>> import numpy as np
>>> V = np.array([[0, 0], [1, 0], [0, 1]], float)
>>> shape = PlanarInput.of((V, [[0, 1, 2]]))
>>> shape.mesh.vertices[:, 2].tolist(), shape.given_dim
([0.0, 0.0, 0.0], 2)
>>> shape.to_caller(np.array([[1.0, 2.0]])).tolist()
[[1.0, 2.0]]
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..validate import real_array
from .model import Mesh, as_mesh, faces_of

__all__ = ["PLANAR_TOL", "PlanarInput", "is_planar", "signed_areas"]

#: largest spread of z, relative to the extent, that still counts as one plane ``z = const``
#: (a mesh written by a 2D tool has exactly one z; text formats keep it to the digit)
PLANAR_TOL = 1e-12


def is_planar(vertices: np.ndarray) -> bool:
    """Whether every vertex has the same z, to :data:`PLANAR_TOL` of the extent.

    Examples
    --------
    >>> is_planar(np.array([[0, 0, 2.0], [1, 0, 2.0], [0, 1, 2.0]]))
    True
    >>> is_planar(np.eye(3))
    False
    """
    V = np.asarray(vertices, dtype=np.float64)
    if V.ndim != 2 or V.shape[1] == 2:
        return V.ndim == 2
    if len(V) == 0:
        return False
    ext = float(np.max(V.max(axis=0) - V.min(axis=0)))
    z = V[:, 2]
    return bool(z.max() - z.min() <= PLANAR_TOL * ext)


def signed_areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Twice the signed area of each triangle in the xy plane (counter-clockwise > 0).

    Examples
    --------
    >>> signed_areas(np.array([[0, 0], [1, 0], [0, 1]], float), np.array([[0, 1, 2], [0, 2, 1]]))
    array([ 1., -1.])
    """
    P = np.asarray(vertices, dtype=np.float64)
    a, b, c = P[faces[:, 0]], P[faces[:, 1]], P[faces[:, 2]]
    return ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1])
            - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))


@dataclass(frozen=True)
class PlanarInput:
    """A shape given in 2D or 3D, as the mesh the solver reads and the caller's format.

    Attributes
    ----------
    mesh : Mesh
        The shape with 3D positions (z = 0 for 2D input).
    given_dim : int
        2 when the caller gave ``(n, 2)`` positions, else 3.
    planar : bool
        The positions lie in one plane ``z = const``.
    z : float
        That plane's z (0 for 2D input; meaningful only when ``planar``).
    """

    mesh: Mesh
    given_dim: int
    planar: bool
    z: float

    @classmethod
    def of(cls, value, what: str = "mesh") -> PlanarInput:
        """Read a Mesh, a ``(vertices, faces)`` pair with ``(n, 2)`` or ``(n, 3)`` positions,
        or a mesh object of another library (see :func:`arapkit.mesh.model.as_mesh`)."""
        if isinstance(value, Mesh):
            return cls._of_mesh(value, 3)
        V = None
        if isinstance(value, (tuple, list)) and len(value) == 2:
            V, F = value
        elif getattr(value, "vertices", None) is not None and faces_of(value) is not None:
            V, F = value.vertices, faces_of(value)
        if V is not None:
            A = real_array(V, f"{what}: vertices")
            if A.ndim == 2 and A.shape[1] == 2:
                lifted = np.concatenate([A.astype(np.float64), np.zeros((len(A), 1))], axis=1)
                return cls(Mesh(lifted, np.asarray(F) if not isinstance(F, list) else F,
                                name=what), 2, True, 0.0)
        return cls._of_mesh(as_mesh(value, what), 3)

    @classmethod
    def of_shape(cls, value, what: str = "mesh") -> PlanarInput:
        """As :meth:`of`, and a point cloud or graph too (anything
        :func:`~arapkit.mesh.cloud.as_shape` reads as one): ``mesh`` is then the cloud,
        never planar (it has no triangles for the plane's flip guard, so it is solved in
        3D).

        Examples
        --------
        >>> s = PlanarInput.of_shape(np.eye(3))
        >>> type(s.mesh).__name__, s.planar, s.given_dim
        ('PointCloud', False, 3)
        """
        from .cloud import PointCloud, as_shape

        if isinstance(value, (Mesh, tuple, list)) or faces_of(value) is not None:
            return cls.of(value, what)
        shape = as_shape(value, what)
        if isinstance(shape, PointCloud):
            return cls(shape, 3, False, 0.0)  # type: ignore[arg-type]
        return cls.of(shape, what)

    @classmethod
    def _of_mesh(cls, mesh: Mesh, given_dim: int) -> PlanarInput:
        planar = is_planar(mesh.vertices)
        return cls(mesh, given_dim, planar, float(mesh.vertices[0, 2]) if planar else 0.0)

    def targets_in_plane(self, targets: np.ndarray, name: str = "targets") -> np.ndarray | None:
        """``(h, 2)`` in-plane targets, or None when ``(h, 3)`` targets leave the plane.

        Targets are given in the caller's dimension; 3D targets of a planar mesh count as
        in the plane when their z is the plane's to :data:`PLANAR_TOL` of the extent.
        """
        T = np.asarray(targets, dtype=np.float64)
        if T.ndim != 2 or T.shape[1] not in (2, 3):
            raise InputError(f"{name}: expected shape (h, 2) or (h, 3), got {T.shape}")
        if T.shape[1] == 2:
            return T
        if len(T) and np.abs(T[:, 2] - self.z).max() > PLANAR_TOL * self.extent:
            return None
        return T[:, :2]

    @property
    def extent(self) -> float:
        """The largest side of the bounding box (found once: every frame of a drag asks)."""
        if "_extent" not in self.__dict__:
            V = self.mesh.vertices
            object.__setattr__(self, "_extent",
                               max(float(np.max(V.max(axis=0) - V.min(axis=0))), 1e-300))
        return self.__dict__["_extent"]

    def to_caller(self, P: np.ndarray) -> np.ndarray:
        """``(n, 2)`` solver positions in the caller's dimension (z of the plane added)."""
        if self.given_dim == 2 or P.shape[1] == 3:
            return P
        return np.concatenate([P, np.full((len(P), 1), self.z)], axis=1)
