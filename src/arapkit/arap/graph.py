"""The solver's edge graph: rest positions and undirected edges, and their units and order.

:class:`EdgeGraph` is what every energy, backend and constraint of :mod:`arapkit.arap` reads:
a triangle mesh's edges (:meth:`EdgeGraph.from_mesh`) or any graph, e.g. a tetrahedral mesh's
edges, a point cloud's neighbourhood graph (:meth:`EdgeGraph.from_cloud`).
:func:`unit_scale` picks the power of two the solver divides positions by, and
:func:`bandwidth_order` the vertex order it works in.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from ..errors import InputError
from ..mesh.topology import EdgeTopology

if TYPE_CHECKING:
    from ..mesh.cloud import PointCloud
    from ..mesh.model import Mesh

__all__ = ["EdgeGraph", "bandwidth_order", "check_graph", "unit_scale"]


@dataclass(frozen=True, eq=False)
class EdgeGraph(EdgeTopology):
    """Rest positions and an undirected edge list (optionally with the triangles they bound).

    Parameters
    ----------
    vertices : (n, 3) float64
    edges : (m, 2) int64
        Each undirected edge once; edge ids are row numbers.
    name : str
        Used in error messages.
    faces : (f, 3) int64, optional
        Triangles, for energies defined on triangles (spokes-and-rims, SR-ARAP's area).
    face_edges : (f, 3) int64, optional
        Edge id of ``(F[f, c], F[f, c + 1])``; required with ``faces``.
    known_components : (count, labels), optional
        The connected components when already known (they are then not searched again).

    Examples
    --------
    >>> import numpy as np
    >>> g = EdgeGraph(np.eye(3), np.array([[0, 1], [1, 2]]))
    >>> g.n_vertices, g.n_components
    (3, 1)
    """

    vertices: np.ndarray
    edges: np.ndarray
    name: str = "graph"
    faces: np.ndarray | None = None
    face_edges: np.ndarray | None = None
    known_components: tuple[int, np.ndarray] | None = field(default=None, repr=False)

    @classmethod
    def from_mesh(cls, mesh: Mesh) -> EdgeGraph:
        """The edge graph of a triangle mesh (its edges keep their ids)."""
        # the mesh has already labelled its components: do not search again
        return cls(mesh.vertices, mesh.edges, mesh.name, mesh.faces, mesh.face_edges,
                   (mesh.n_components, mesh.component_labels))

    @classmethod
    def from_cloud(cls, cloud: PointCloud) -> EdgeGraph:
        """The neighbourhood graph of a point cloud (or a given graph), without triangles."""
        return cls(cloud.vertices, cloud.edges, cloud.name, None, None,
                   (cloud.n_components, cloud.component_labels))

    @property
    def n_components(self) -> int:
        """Number of connected components (an isolated vertex is its own)."""
        if self.known_components is None:
            return super().n_components
        return int(self.known_components[0])

    @property
    def component_labels(self) -> np.ndarray:
        """Connected-component label of each vertex."""
        if self.known_components is None:
            return super().component_labels
        return self.known_components[1]

    @property
    def n_vertices(self) -> int:
        """Number of vertices."""
        return len(self.vertices)

    def scaled(self, factor: float) -> EdgeGraph:
        """The same graph with every position multiplied by ``factor`` (components kept)."""
        return EdgeGraph(self.vertices * factor, self.edges, self.name, self.faces,
                         self.face_edges, (self.n_components, self.component_labels))

    def permuted(self, perm: np.ndarray, iperm: np.ndarray, faces: bool = True) -> EdgeGraph:
        """The same graph with vertex ``perm[i]`` renamed ``i`` (edge and face ids kept).

        ``faces=False`` leaves the triangles out, for a user that needs only the edges
        (an energy without triangle terms: the faces are 80 MB at 1.75M vertices).
        """
        keep = faces and self.faces is not None
        return EdgeGraph(
            np.ascontiguousarray(self.vertices[perm]),
            iperm[self.edges],
            self.name,
            iperm[self.faces] if keep else None,
            self.face_edges if keep else None,
            (self.n_components, self.component_labels[perm]),
        )


def unit_scale(vertices: np.ndarray, name: str) -> float:
    """The power of two ``s`` with ``extent / s`` in [0.5, 1): the solver works in ``V / s``.

    Dividing by a power of two is exact, so a mesh scaled by ``2**k`` gives bit-identical
    iterations; any other scale changes nothing beyond round-off. Every tolerance inside
    the solve (convergence floor, cotangent caps) is then relative to the mesh's own size,
    and squared lengths neither overflow nor underflow for extents anywhere in the double
    range.

    Examples
    --------
    >>> import numpy as np
    >>> unit_scale(np.array([[0.0, 0, 0], [3, 0, 0]]), "m")
    4.0
    """
    V = np.asarray(vertices, dtype=np.float64)
    if len(V) < 2:
        return 1.0
    with np.errstate(over="ignore", invalid="ignore"):
        extent = float(np.max(V.max(axis=0) - V.min(axis=0)))
    if not math.isfinite(extent):
        raise InputError(
            f"{name}: coordinates span more than double precision can hold "
            f"(from {V.min():.3g} to {V.max():.3g}); rescale the mesh"
        )
    if extent == 0:
        return 1.0
    return math.ldexp(1.0, math.frexp(extent)[1])


def bandwidth_order(mesh: Mesh | EdgeGraph) -> np.ndarray:
    """Reverse Cuthill-McKee order of the vertices (new -> old).

    Examples
    --------
    >>> from arapkit.mesh.shapes import bar
    >>> m = bar()
    >>> sorted(bandwidth_order(m).tolist()) == list(range(m.n_vertices))
    True
    """
    from scipy.sparse.csgraph import reverse_cuthill_mckee

    return reverse_cuthill_mckee(mesh.adjacency.tocsr(), symmetric_mode=True).astype(np.int64)


def check_graph(vertices, edges, weights, name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions (n, 3), edges (m, 2) and one weight per edge, or a one-line InputError.

    Edges must be integers in range, without loops or repeats; every number finite.

    Examples
    --------
    >>> V, E, w = check_graph(np.eye(3), [[0, 1], [1, 2]], [1, 1], "g")
    >>> E.dtype, w.tolist()
    (dtype('int64'), [1.0, 1.0])
    """
    V = np.ascontiguousarray(vertices, dtype=np.float64)
    if V.ndim != 2 or V.shape[1] != 3:
        raise InputError(f"{name}: vertices must have shape (n, 3), got {V.shape}")
    if not np.isfinite(V).all():
        bad = int(np.flatnonzero(~np.isfinite(V).all(axis=1))[0])
        raise InputError(f"{name}: vertex {bad} has a non-finite coordinate")
    E = np.asarray(edges)
    if E.ndim != 2 or E.shape[1] != 2 or not np.issubdtype(E.dtype, np.integer):
        raise InputError(f"{name}: edges must be an (m, 2) integer array, got {E.shape} {E.dtype}")
    E = E.astype(np.int64)
    bad = np.flatnonzero((E < 0).any(axis=1) | (E >= len(V)).any(axis=1) | (E[:, 0] == E[:, 1]))
    if len(bad):
        raise InputError(f"{name}: edge {bad[0]} {E[bad[0]].tolist()} is a loop or out of range "
                         f"({len(V)} vertices)")
    key = np.minimum(E[:, 0], E[:, 1]) * len(V) + np.maximum(E[:, 0], E[:, 1])
    if len(np.unique(key)) != len(key):
        raise InputError(f"{name}: an edge is listed twice")
    w = np.ascontiguousarray(weights, dtype=np.float64)
    if w.shape != (len(E),) or not np.isfinite(w).all():
        raise InputError(f"{name}: weights must be {len(E)} finite numbers, one per edge")
    return V, E, w
