"""Point clouds and graphs: shapes without triangles, deformed on a neighbourhood graph.

r-ring ARAP (Chen et al. 2017, eq. 1) needs edges, not triangles. A :class:`PointCloud`
is a set of points (with normals and any other per-point values its file carried) and
the graph the solver runs on: its symmetrised k-nearest-neighbour graph by default, the
pairs within a radius, or, for a :class:`Graph`, the edges (and weights) the caller gives.
:func:`as_shape` is what the doors that take a mesh *or* a cloud call (a triangle mesh
stays a :class:`~arapkit.mesh.model.Mesh`).

A cloud answers the questions the solver, the handles and the figures ask of a mesh
(``vertices``, ``edges``, ``n_vertices``, components, ``mean_edge_length``, the bounding
box) and says it has no triangles (``faces`` is None): methods that need them
(spokes-and-rims, SR-ARAP, Laplacian editing, volumetric ARAP) refuse it in one line.

Examples
--------
>>> import numpy as np
>>> c = PointCloud(np.random.default_rng(0).random((50, 3)), name="c")
>>> c.n_vertices, c.neighbours, bool(len(c.edges) >= 50 * 10 // 2), c.faces is None
(50, 10, True, True)
>>> g = Graph([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1], [1, 2]], weights=[1.0, 2.0])
>>> g.edges.tolist(), g.weights.tolist()
([[0, 1], [1, 2]], [1.0, 2.0])
"""

from __future__ import annotations

import hashlib
import os
from functools import cached_property

import numpy as np

from ..errors import InputError
from ..validate import integer, number, point_positions, real_array
from .attributes import MeshAttributes
from .model import Mesh, as_mesh, faces_of
from .neighbours import DEFAULT_NEIGHBOURS, MAX_NEIGHBOURS, check_edges, knn_edges, radius_edges
from .numbers import bounding_box_diagonal, check_number_range
from .topology import EdgeTopology

__all__ = ["Graph", "PointCloud", "as_shape", "counted", "element_nouns", "is_cloud"]


def _normals(values, n: int, name: str) -> np.ndarray | None:
    if values is None:
        return None
    N = np.array(real_array(values, f"{name}: normals"), dtype=np.float64)
    if N.shape != (n, 3):
        raise InputError(f"{name}: normals must have shape ({n}, 3), got {N.shape}")
    bad = np.flatnonzero(~np.isfinite(N).all(axis=1))
    if len(bad):
        raise InputError(f"{name}: the normal of point {bad[0]} is not finite")
    return N


class PointCloud(EdgeTopology):
    """Points, their per-point values, and the neighbourhood graph ARAP runs on.

    Parameters
    ----------
    points : (n, 3) array_like of float
        Positions; finite. Their order is kept (handles and rigidity maps index it).
    normals : (n, 3) array_like, optional
        Per-point normals. A solve's rotations turn them
        (:func:`arapkit.io.writers.save_mesh` with ``like=cloud``).
    name : str
        Used in messages (usually the file name).
    attributes : MeshAttributes, optional
        What the source file carried besides positions (set by
        :func:`arapkit.io.clouds.load_points`), written back by ``save_mesh(..., like=cloud)``.
    neighbours : int, optional
        k of the symmetrised k-nearest-neighbour graph (default
        :data:`~arapkit.mesh.neighbours.DEFAULT_NEIGHBOURS`, 10).
    radius : float, optional
        Link every pair of points closer than this instead (not with ``neighbours``).

    Attributes
    ----------
    points, vertices : (n, 3) float64, read-only
        The positions (two names for one array: what a mesh calls its vertices).
    edges : (m, 2) int64
        The graph, each undirected edge once (built on first use).
    faces : None
        A point cloud has no triangles.
    notes : list of str
        What was done about the input.

    Examples
    --------
    >>> import numpy as np
    >>> c = PointCloud([[0, 0, 0], [1, 0, 0], [5, 0, 0], [6, 0, 0]], neighbours=1)
    >>> c.edges.tolist(), c.n_components  # two pairs, 4 apart
    ([[0, 1], [2, 3]], 2)
    >>> PointCloud(c.points, radius=4.5).n_components
    1
    """

    #: a point cloud has no triangles (a :class:`~arapkit.mesh.model.Mesh` has)
    faces = None
    n_faces = 0
    welded_from = None
    boundary_loops: list = []
    dropped_faces: dict = {}

    def __init__(self, points, normals=None, *, name: str = "cloud",
                 attributes: MeshAttributes | None = None, neighbours: int | None = None,
                 radius: float | None = None) -> None:
        self.name = str(name)
        self.notes: list[str] = []
        self.attributes = attributes
        self.points = point_positions(points, self.name)
        self.points.setflags(write=False)
        self.normals = _normals(normals, len(self.points), self.name)
        if self.normals is not None:
            self.normals.setflags(write=False)
        if neighbours is not None and radius is not None:
            raise InputError(f"{self.name}: give neighbours or radius, not both")
        self.radius = None if radius is None else number(radius, "radius", lo=0.0,
                                                         lo_open=True)
        self.neighbours = (None if self.radius is not None else
                           integer(DEFAULT_NEIGHBOURS if neighbours is None else neighbours,
                                   "neighbours", lo=1, hi=MAX_NEIGHBOURS))
        #: explicit per-edge weights (a :class:`Graph`'s), else None
        self.weights: np.ndarray | None = None

    # -- what a mesh has too ---------------------------------------------------------
    @property
    def vertices(self) -> np.ndarray:
        """The points (what the solver, the handles and the figures call vertices)."""
        return self.points

    @property
    def n_vertices(self) -> int:
        """Number of points."""
        return len(self.points)

    @property
    def n_points(self) -> int:
        """Number of points."""
        return len(self.points)

    @cached_property
    def edges(self) -> np.ndarray:
        """The neighbourhood graph's edges ``(i, j)``, ``i < j``, sorted (built once)."""
        if self.radius is not None:
            E = radius_edges(self.points, self.radius)
        else:
            E = knn_edges(self.points, self.neighbours)
        E.setflags(write=False)
        return E

    @property
    def graph_description(self) -> str:
        """How the graph was made, for reports: ``"kNN, k = 10"``, ``"radius 0.5"``."""
        if self.radius is not None:
            return f"radius {self.radius:g}"
        return f"kNN, k = {self.neighbours}"

    @property
    def unreferenced(self) -> np.ndarray:
        """Points without an edge (their own components)."""
        used = np.zeros(self.n_vertices, dtype=bool)
        used[self.edges.ravel()] = True
        return np.flatnonzero(~used)

    @cached_property
    def mean_edge_length(self) -> float:
        """Mean length of the graph's edges: the cloud's resolution (0 without edges).

        Examples
        --------
        >>> PointCloud([[0, 0, 0], [2, 0, 0]]).mean_edge_length
        2.0
        """
        E = self.edges
        if len(E) == 0:
            return 0.0
        return float(np.linalg.norm(self.points[E[:, 0]] - self.points[E[:, 1]], axis=1).mean())

    @cached_property
    def bounding_box_diagonal(self) -> float:
        """Length of the bounding-box diagonal (the cloud's scale)."""
        return bounding_box_diagonal(self.points)

    @cached_property
    def content_hash(self) -> str:
        """SHA-1 (hex) of the points and the graph's definition: a key for what depends
        on the cloud's content only (its proxy)."""
        h = hashlib.sha1()
        h.update(np.ascontiguousarray(self.points, dtype=np.float64).tobytes())
        h.update(self.graph_description.encode())
        return h.hexdigest()

    def check_number_range(self) -> None:
        """:func:`~arapkit.mesh.numbers.check_number_range` on the points."""
        check_number_range(self.points, self.name)

    def with_points(self, points, name: str | None = None) -> PointCloud:
        """A cloud of other positions with this one's graph rule (not its attributes).

        Examples
        --------
        >>> c = PointCloud(np.eye(3), neighbours=1)
        >>> c.with_points(2 * np.eye(3)).neighbours
        1
        """
        return PointCloud(points, name=self.name if name is None else name,
                          neighbours=self.neighbours, radius=self.radius)

    def __repr__(self) -> str:
        return f"PointCloud({self.name!r}, {self.n_vertices} points, {self.graph_description})"


class Graph(PointCloud):
    """An edge graph given by the caller: points, edges and optional weights.

    The r-ring energy is defined on any edge graph (Chen et al. 2017, eq. 1): a
    deformation graph, a skeleton with its points, a mesh's edges with weights of your
    own. ``Deformer(Graph(points, edges, weights), handles, rings=...)`` solves it like a
    mesh (potpourri3d's and libigl's style: data in, solver object out).

    Parameters
    ----------
    points : (n, 3) array_like of float
    edges : (m, 2) array_like of int
        Undirected edges, each once, no loops; edge ids are row numbers (the order and
        the weights' alignment are kept).
    weights : (m,) array_like of float, optional
        Positive weight of each edge; without it the solver weights the edges as a point
        cloud's (a Gaussian of the length, :mod:`arapkit.mesh.cloud_weights`).
    name : str
    normals : (n, 3) array_like, optional

    Examples
    --------
    >>> import numpy as np
    >>> from arapkit import Deformer
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
    >>> E = [[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]]
    >>> res = Deformer(Graph(V, E), [0, 1, 2]).solve(V[:3] + 1.0)  # the tet follows rigidly
    >>> bool(np.allclose(res.vertices, V + 1.0))
    True
    """

    def __init__(self, points, edges, weights=None, *, name: str = "graph",
                 normals=None, attributes: MeshAttributes | None = None) -> None:
        super().__init__(points, normals, name=name, attributes=attributes)
        self.neighbours = None
        E = check_edges(edges, self.n_vertices, self.name)
        E.setflags(write=False)
        self.__dict__["edges"] = E  # the cached property's slot: given, not built
        if weights is not None:
            from .weights import given_weights

            self.weights = given_weights(self, weights)
            self.weights.setflags(write=False)

    @property
    def graph_description(self) -> str:
        """``"given edges"`` (and ``", given weights"``)."""
        return "given edges" + (", given weights" if self.weights is not None else "")

    @cached_property
    def content_hash(self) -> str:
        """SHA-1 of the points and the edges."""
        h = hashlib.sha1()
        h.update(np.ascontiguousarray(self.points, dtype=np.float64).tobytes())
        h.update(np.ascontiguousarray(self.edges, dtype=np.int64).tobytes())
        return h.hexdigest()

    def __repr__(self) -> str:
        return f"Graph({self.name!r}, {self.n_vertices} points, {len(self.edges)} edges)"


def is_cloud(shape) -> bool:
    """Whether ``shape`` is a point cloud or graph (no triangles).

    Examples
    --------
    >>> is_cloud(PointCloud(np.eye(3))), is_cloud(Mesh(np.eye(3), [[0, 1, 2]]))
    (True, False)
    """
    return isinstance(shape, PointCloud)


def counted(n: int, shape=None, *, points: bool | None = None) -> str:
    """``n`` of a shape's elements in words: points for a cloud (``shape`` a cloud, or
    ``points=True``), vertices for a mesh; what messages print, so that a cloud's user
    reads of points.

    Examples
    --------
    >>> counted(1, PointCloud(np.eye(3))), counted(4, Mesh(np.eye(3), [[0, 1, 2]]))
    ('1 point', '4 vertices')
    """
    one, many = element_nouns(is_cloud(shape) if points is None else points)
    return f"{n} {one if n == 1 else many}"


def element_nouns(points: bool) -> tuple[str, str]:
    """``("point", "points")`` for a point cloud, ``("vertex", "vertices")`` for a mesh:
    the words every message counting a shape's elements uses (:func:`counted`).

    Examples
    --------
    >>> element_nouns(True), element_nouns(False)
    (('point', 'points'), ('vertex', 'vertices'))
    """
    return ("point", "points") if points else ("vertex", "vertices")


def as_shape(value, what: str = "mesh") -> Mesh | PointCloud:
    """``value`` as what arapkit deforms: a :class:`Mesh` (anything with triangles, as
    :func:`~arapkit.mesh.model.as_mesh` takes it) or a :class:`PointCloud`.

    A point cloud is a :class:`PointCloud` itself, an ``(n, 3)`` array, or another
    library's point cloud: anything with ``points`` (Open3D's ``PointCloud``) or
    ``vertices`` and no faces (``trimesh.PointCloud``).

    Examples
    --------
    >>> as_shape(np.eye(3))
    PointCloud('mesh', 3 points, kNN, k = 10)
    >>> as_shape((np.eye(3), [[0, 1, 2]]))
    Mesh('mesh', 3 vertices, 1 faces)
    >>> class Open3DLike:
    ...     points = np.eye(3)
    >>> as_shape(Open3DLike(), "scan").n_vertices
    3
    """
    if isinstance(value, (Mesh, PointCloud)):
        return value
    if isinstance(value, np.ndarray) and value.ndim == 2:
        return PointCloud(value, name=what)
    if not isinstance(value, (tuple, list, str, os.PathLike)) and faces_of(value) is None:
        pts = getattr(value, "points", None)
        if pts is None:
            pts = getattr(value, "vertices", None)
        if pts is not None:
            normals = getattr(value, "normals", None)
            try:
                has = normals is not None and len(normals) == len(pts)
            except TypeError:
                has = False
            return PointCloud(np.asarray(pts), np.asarray(normals) if has else None,
                              name=what)
    return as_mesh(value, what)
