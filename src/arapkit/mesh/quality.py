"""Shape-quality measures of a deformation: folded edges and volume change.

* **Folded edges**: interior edges whose signed dihedral angle changes by more than a
  threshold (default 60 degrees) between rest and deformed shape. A smooth bend turns
  each dihedral angle by a few degrees; a fold or a crease turns it by tens.
* **Volume change**: relative change of the enclosed (signed) volume, meaningful for
  closed meshes only (``nan`` when the mesh has boundary edges).

Self-intersecting faces are not counted: none of arapkit's dependencies counts them
(trimesh needs an optional collision library for that).
"""

from __future__ import annotations

import numpy as np

from .model import Mesh

__all__ = ["FOLD_DEGREES", "dihedral_angles", "enclosed_volume", "folded_edge_fraction",
           "volume", "volume_change"]

#: dihedral change above which an edge counts as folded
FOLD_DEGREES = 60.0


def _interior_edge_faces(mesh: Mesh) -> tuple[np.ndarray, np.ndarray]:
    """Edges with exactly two faces and those faces (e, 2)."""
    FE = mesh.face_edges.ravel()
    faces = np.repeat(np.arange(mesh.n_faces), 3)
    order = np.argsort(FE, kind="stable")
    FE, faces = FE[order], faces[order]
    counts = np.bincount(FE, minlength=len(mesh.edges))
    two = np.flatnonzero(counts == 2)
    start = np.concatenate([[0], np.cumsum(counts)[:-1]])[two]
    return two, np.stack([faces[start], faces[start + 1]], axis=1)


def dihedral_angles(mesh: Mesh, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Signed dihedral angle (radians) of each interior edge for positions P.

    Returns the edge ids and the angles (0 for a flat pair of faces).

    Examples
    --------
    >>> import numpy as np
    >>> m = Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], [[0, 1, 2], [2, 1, 3]])
    >>> e, a = dihedral_angles(m, m.vertices)
    >>> e.tolist(), np.round(a, 12).tolist()
    ([2], [0.0])
    """
    e, ef = _interior_edge_faces(mesh)
    F = mesh.faces
    n = np.cross(P[F[:, 1]] - P[F[:, 0]], P[F[:, 2]] - P[F[:, 0]])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    n1, n2 = n[ef[:, 0]], n[ef[:, 1]]
    E = mesh.edges[e]
    d = P[E[:, 1]] - P[E[:, 0]]
    d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-300)
    s = np.einsum("ij,ij->i", np.cross(n1, n2), d)
    c = np.einsum("ij,ij->i", n1, n2)
    return e, np.arctan2(s, c)


def folded_edge_fraction(mesh: Mesh, P: np.ndarray, degrees: float = FOLD_DEGREES) -> float:
    """Fraction of interior edges whose dihedral angle changed by more than ``degrees``.

    Examples
    --------
    >>> import numpy as np
    >>> m = Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], [[0, 1, 2], [2, 1, 3]])
    >>> P = m.vertices.copy(); P[3] = [0.5, 0.5, 1.0]   # fold the second triangle up
    >>> folded_edge_fraction(m, P)
    1.0
    """
    _, a0 = dihedral_angles(mesh, mesh.vertices)
    _, a1 = dihedral_angles(mesh, np.asarray(P, dtype=np.float64))
    if len(a0) == 0:
        return 0.0
    change = np.abs(np.angle(np.exp(1j * (a1 - a0))))
    return float(np.mean(change > np.radians(degrees)))


def enclosed_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Signed volume enclosed by a closed, consistently oriented triangle mesh.

    Divergence theorem: the sum over faces of ``a . (b x c) / 6``.

    Examples
    --------
    >>> from arapkit.mesh.shapes import bar
    >>> m = bar(5.0, 1.0, 1.0, (10, 2, 2))
    >>> round(enclosed_volume(m.vertices, m.faces), 9)
    5.0
    """
    a, b, c = (vertices[faces[:, i]] for i in range(3))
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def volume(mesh: Mesh, P: np.ndarray) -> float:
    """Signed volume enclosed by the faces at positions P (divergence theorem)."""
    return enclosed_volume(P, mesh.faces)


def volume_change(mesh: Mesh, P: np.ndarray) -> float:
    """``(vol(P) - vol(rest)) / |vol(rest)|`` for a closed mesh, ``nan`` otherwise.

    Examples
    --------
    >>> from arapkit.mesh.shapes import bar
    >>> m = bar()
    >>> round(volume_change(m, 2.0 * m.vertices), 9)
    7.0
    """
    if (mesh.edge_face_counts != 2).any():
        return float("nan")
    v0 = volume(mesh, mesh.vertices)
    if v0 == 0:
        return float("nan")
    return (volume(mesh, np.asarray(P, dtype=np.float64)) - v0) / abs(v0)
