"""The precomputed ARAP problem: edge graph, weights, energy structure, constraints, factor.

An :class:`ARAPProblem` is what libigl calls ``ARAPData`` after ``arap_precomputation``:
everything that does not change when only the handle *targets* change. It is immutable;
a new handle set or a new energy (e.g. a new rigidity map) gives a new problem that shares
the unchanged parts (:meth:`ARAPProblem.with_handles`, :meth:`ARAPProblem.with_energy`).

Internally the vertices are renumbered in a bandwidth-reducing order (reverse
Cuthill-McKee): consecutive vertices are then close on the surface, so a neighbourhood's
vertices lie near each other in memory and the per-thread scatter windows of the CPU
backend barely overlap. ``perm`` maps internal to caller numbering (new -> old) and
``iperm`` the other way; every array stored here is in internal numbering except the
handle list, which stays in the caller's.

The problem can be built from a triangle :class:`~arapkit.mesh.model.Mesh`
(:meth:`ARAPProblem.from_mesh`) or from a plain edge graph with per-edge weights
(:meth:`ARAPProblem.from_graph`), e.g. the edges of a tetrahedral mesh.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np

from ..errors import Advice, InputError
from ..mesh.weights import SOUND_WEIGHTS
from .constraints import (
    Elimination,
    Followers,
    anchor_components,
    check_handles,
    return_free_memory,
)
from .domains import domain_of
from .energies import energy_info, make_energy
from .graph import EdgeGraph, bandwidth_order, check_graph, unit_scale
from .rings import check_rings

if TYPE_CHECKING:
    from ..mesh.cloud import PointCloud
    from ..mesh.model import Mesh
    from .energies.base import NeighbourhoodEnergy

__all__ = ["ARAPProblem"]


@dataclass(frozen=True, eq=False)
class ARAPProblem:
    """Immutable precomputation of one ARAP problem (libigl's ``ARAPData``).

    Build with :meth:`from_mesh` or :meth:`from_graph`; do not call the constructor.

    Attributes
    ----------
    graph : EdgeGraph
        Rest shape and edges in internal numbering.
    perm, iperm : (n,) int64
        Internal -> caller and caller -> internal vertex numbers.
    w : (m,) float64
        Edge weights (by edge id).
    weights_kind : str or None
        Name of the weighting (None for caller-supplied weights).
    energy : NeighbourhoodEnergy
        The energy's precomputed structure (internal numbering).
    handles : (h,) int64
        Handle vertices, caller numbering.
    fixed_extra : (f,) int64
        Vertices of components without a handle, held at rest (caller numbering).
    notes : list of str
        What was done about the constraints.
    """

    graph: EdgeGraph
    perm: np.ndarray
    iperm: np.ndarray
    w: np.ndarray
    weights_kind: str | None
    energy: NeighbourhoodEnergy
    handles: np.ndarray
    fixed_extra: np.ndarray
    notes: list[str]
    free_components: str = "follow"
    caller_graph: EdgeGraph | None = field(default=None, repr=False)
    timings: dict[str, float] = field(default_factory=dict, repr=False)
    #: the power of two the positions are divided by inside (see :func:`unit_scale`)
    scale: float = 1.0
    #: 2 for a planar shape solved in its plane (2 x 2 rotations, ``(n, 2)`` positions and
    #: targets, :mod:`arapkit.arap.backends.planar`), else 3
    dim: int = 3

    # -- construction --------------------------------------------------------------
    @classmethod
    def from_mesh(cls, mesh: Mesh | PointCloud, handles, energy="rring",
                  weights: str | None = None, *, rings=1, free_components: str = "follow",
                  reorder: bool = True, dim: int = 3, **energy_options) -> ARAPProblem:
        """Precompute ARAP on a triangle mesh or a point cloud's graph.

        Parameters
        ----------
        mesh : Mesh or PointCloud
            The shape (its domain, :func:`arapkit.arap.domains.domain_of`, says how its
            edge graph and weights are made).
        handles : (h,) int
            Constrained vertices.
        energy : str
            A registered energy of the local/global solver
            (:func:`arapkit.arap.energies.energy_names`); one defined on triangles is
            refused on a point cloud.
        weights : str or (m,) array, optional
            Edge weighting: a kind of the shape's domain (default: the domain's own,
            ``cotan-clamped`` on a mesh and ``gaussian`` on a point cloud), or one weight
            per edge.
        rings : int or (n,) int
            r per vertex for ``energy="rring"``.
        free_components, reorder :
            As for :class:`arapkit.Deformer`.
        dim : {3, 2}
            2 solves a planar mesh (one z, or ``(n, 2)`` positions) in its plane: targets
            and results are ``(n, 2)``, rotations 2 x 2 (see :mod:`arapkit.mesh.planar`).
        **energy_options :
            Options of the energy (e.g. ``sr_alpha``).

        Examples
        --------
        >>> from arapkit.mesh.shapes import bar
        >>> p = ARAPProblem.from_mesh(bar(), [0, 1], rings=2)
        >>> p.n_vertices, p.energy.name
        (1154, 'rring')
        >>> from arapkit.mesh.cloud import PointCloud
        >>> ARAPProblem.from_mesh(PointCloud(bar().vertices), [0, 1]).weights_kind
        'gaussian'
        """
        from ..mesh.planar import PlanarInput

        t0 = time.perf_counter()
        if dim not in (2, 3):
            raise InputError(f"dim: expected 2 or 3, got {dim!r}")
        planar = PlanarInput.of_shape(mesh)  # a mesh, or a point cloud (never planar)
        shape = planar.mesh
        if dim == 2 and not planar.planar:
            raise InputError(f"{shape.name}: dim=2 needs a planar mesh (one z for every "
                             "vertex, or (n, 2) positions)")
        dom = domain_of(shape)
        w, kind = dom.edge_weights(shape, weights)
        return cls._build(dom.graph(shape), w, kind, handles, energy, rings,
                          free_components, reorder, energy_options, t0, dim)

    @classmethod
    def from_graph(cls, vertices, edges, weights, handles, *, rings=1, name: str = "graph",
                   free_components: str = "follow", reorder: bool = True) -> ARAPProblem:
        """Precompute r-ring ARAP on a plain edge graph (e.g. a tetrahedral mesh's edges).

        The energy is eq. (1) of Chen et al. 2017 on the given edges, which is defined on any
        edge graph: ``sum_k sum_{e in N(k, r_k)} w_e |e' - R_k e|^2``.

        Parameters
        ----------
        vertices : (n, 3) float
            Rest positions.
        edges : (m, 2) int
            Undirected edges, each once (no loops).
        weights : (m,) float
            Weight of each edge (positive weights keep the rest shape an energy minimum).
        handles : (h,) int
            Constrained vertices.
        rings : int or (n,) int
            r per vertex.
        name : str
            Used in error messages.
        free_components, reorder :
            As for :class:`arapkit.Deformer`.

        Examples
        --------
        >>> import numpy as np
        >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
        >>> E = np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]])
        >>> p = ARAPProblem.from_graph(V, E, np.ones(6), [0, 1, 2], name="tet")
        >>> p.n_vertices, len(p.w)
        (4, 6)
        """
        t0 = time.perf_counter()
        V, E, w = check_graph(vertices, edges, weights, name)
        return cls._build(EdgeGraph(V, E, name), w, None, handles, "rring", rings,
                          free_components, reorder, {}, t0)

    @classmethod
    def _build(cls, graph: EdgeGraph, w, kind, handles, energy, rings, free_components,
               reorder, energy_options, t0, dim: int = 3) -> ARAPProblem:
        n = graph.n_vertices
        # the problem lives in units of a power of two near the extent: exact, and every
        # tolerance inside becomes relative to the mesh's own size
        s = unit_scale(graph.vertices, graph.name)
        if s != 1.0:
            graph = graph.scaled(1.0 / s)
        perm = bandwidth_order(graph) if reorder and n > 1 else np.arange(n, dtype=np.int64)
        iperm = np.empty(n, dtype=np.int64)
        iperm[perm] = np.arange(n)
        # a planar solve keeps the triangles: its flip guard reads their orientation
        inner = graph.permuted(perm, iperm,
                               faces=dim == 2 or energy_info(energy).faces_needed(energy_options))
        setup_ms = 1e3 * (time.perf_counter() - t0)
        h, extra, notes = cls._constraints(graph, handles, free_components)
        rings = check_rings(rings, n)
        t1 = time.perf_counter()
        en = make_energy(energy, inner, w, kind, rings=rings, perm=perm, **energy_options)
        if not math.isfinite(en.rest_term * s * s):
            raise InputError(
                f"{graph.name}: coordinates too large for double precision (extent about "
                f"{s:.3g}: the deformation energy overflows); rescale the mesh"
            )
        p = cls(inner, perm, iperm, w, kind, en, h, extra, notes, free_components, graph,
                scale=s, dim=dim)
        p.timings["neighbourhood_ms"] = setup_ms + 1e3 * (time.perf_counter() - t1)
        return p

    @staticmethod
    def _constraints(graph: EdgeGraph, handles, policy: str):
        h = check_handles(graph, handles)
        extra, notes = anchor_components(graph, h, policy)
        return h, extra, notes

    def with_handles(self, handles, *, update_factor: bool = False) -> ARAPProblem:
        """The same problem with a new handle set (refactorises on first use).

        ``update_factor=True`` keeps this problem's factor instead and solves the new
        constrained set through a low-rank correction of it
        (:class:`arapkit.arap.pinupdate.UpdatedElimination`): adding or removing a few
        handles then costs a few solves, not a factorisation.
        """
        h, extra, notes = self._constraints(self.caller_graph, handles, self.free_components)
        new = replace(self, handles=h, fixed_extra=extra, notes=notes,
                      timings={k: v for k, v in self.timings.items()
                               if k != "factorisation_ms"})
        if update_factor and self.factorised:
            from .pinupdate import UpdatedElimination

            t0 = time.perf_counter()
            upd = UpdatedElimination.update(self.elimination, self.edges, self.energy.system_w,
                                            self.iperm[new.constrained], self.name)
            if upd is not None:
                new.__dict__["elimination"] = upd  # the cached property, filled
                new.timings["update_ms"] = 1e3 * (time.perf_counter() - t0)
        return new

    def with_dim(self, dim: int) -> ARAPProblem:
        """The same problem solved in ``dim`` dimensions (a planar problem in 3D, or back),
        sharing the factor: the Laplacian does not depend on the dimension.

        Examples
        --------
        >>> import numpy as np
        >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
        >>> p = ARAPProblem.from_mesh((V, [[0, 1, 2]]), [0], dim=2)
        >>> _ = p.elimination
        >>> q = p.with_dim(3)
        >>> q.dim, q.elimination is p.elimination
        (3, True)
        """
        if dim == self.dim:
            return self
        if dim == 2 and self.graph.faces is None:
            raise InputError(f"{self.name}: dim=2 needs the triangles of a planar mesh")
        new = replace(self, dim=dim)
        if self.factorised:
            new.__dict__["elimination"] = self.elimination
        return new

    def with_energy(self, energy: NeighbourhoodEnergy, build_ms: float = 0.0) -> ARAPProblem:
        """The same graph and handles with another energy (e.g. a new rigidity map)."""
        return replace(self, energy=energy, timings={"neighbourhood_ms": build_ms})

    def with_rings(self, rings) -> ARAPProblem:
        """The same r-ring problem with a new rigidity map (int or one r per vertex).

        Examples
        --------
        >>> from arapkit.mesh.shapes import bar
        >>> p = ARAPProblem.from_mesh(bar(), [0]).with_rings(3)
        >>> int(p.energy.rings.max())
        3
        """
        if not energy_info(self.energy.name).rigidity_map:
            raise InputError(f"energy '{self.energy.name}' has no rigidity map")
        t0 = time.perf_counter()
        r = check_rings(rings, self.n_vertices)
        # the energy's own options (a ring scale) hold for the new map too
        en = make_energy(self.energy.name, self.graph, self.w, self.weights_kind, rings=r,
                         perm=self.perm, **self.energy.options)
        return self.with_energy(en, 1e3 * (time.perf_counter() - t0))

    # -- derived data ------------------------------------------------------------------
    @property
    def n_vertices(self) -> int:
        """Number of vertices."""
        return self.graph.n_vertices

    @property
    def name(self) -> str:
        """The graph's name (for messages)."""
        return self.graph.name

    @property
    def vertices(self) -> np.ndarray:
        """Rest positions, internal numbering."""
        return self.graph.vertices

    @cached_property
    def edges(self) -> np.ndarray:
        """The pairs the energy's terms couple, internal numbering: the graph's edges, then
        any the energy adds past them (:attr:`NeighbourhoodEnergy.extra_edges`)."""
        extra = self.energy.extra_edges
        return self.graph.edges if extra is None else np.concatenate([self.graph.edges, extra])

    @cached_property
    def constrained(self) -> np.ndarray:
        """Handles then component anchors (caller numbering)."""
        return np.concatenate([self.handles, self.fixed_extra])

    @cached_property
    def followers(self) -> Followers:
        """Who follows whom in components without handles (caller numbering, found once)."""
        return Followers.of(self.caller_graph, self.fixed_extra)

    @cached_property
    def elimination(self) -> Elimination:
        """Free/constrained split with the factor of the reduced system (built on first use)."""
        t0 = time.perf_counter()
        remedy = (
            Advice(" (obtuse triangles give negative cotangent weights); use {weights}",
                   weights=SOUND_WEIGHTS)
            if (self.w < 0).any() else ""
        )
        el = Elimination.from_edges(self.n_vertices, self.edges, self.energy.system_w,
                                    self.iperm[self.constrained], self.name, remedy)
        return_free_memory()  # the factorisation's workspace and its matrices' copies
        self.timings["factorisation_ms"] = 1e3 * (time.perf_counter() - t0)
        return el

    @property
    def factorised(self) -> bool:
        """Whether the factor has been computed."""
        return "elimination" in self.__dict__

    def release_factor(self) -> None:
        """Let the factor go (it is rebuilt on next use), e.g. before a problem that
        replaces this one is built: the two need not be held at once (1.2 GiB at 1.75M
        vertices).

        Examples
        --------
        >>> from arapkit.mesh.shapes import bar
        >>> p = ARAPProblem.from_mesh(bar(), [0])
        >>> _ = p.elimination
        >>> p.release_factor()
        >>> p.factorised
        False
        """
        self.__dict__.pop("elimination", None)

    def constrained_targets(self, targets: np.ndarray) -> np.ndarray:
        """Positions of :attr:`constrained` for given handle targets (anchors at rest);
        ``(c, dim)``."""
        rest = self.caller_graph.vertices[self.fixed_extra]
        return np.concatenate([targets, rest[:, :self.dim]])

    @cached_property
    def rest_positions(self) -> np.ndarray:
        """Rest positions in the solve's ``dim`` columns (internal numbering)."""
        return np.ascontiguousarray(self.vertices[:, :self.dim])

    @cached_property
    def b_rest(self) -> np.ndarray:
        """``A P0``: the right-hand side for identity rotations (internal numbering)."""
        E, dw, P0 = self.edges, self.energy.system_w, self.vertices
        a, b = E[:, 0], E[:, 1]
        n = self.n_vertices
        out = np.zeros((n, 3))
        dP = dw[:, None] * (P0[a] - P0[b])
        for ax in range(3):
            out[:, ax] = np.bincount(a, dP[:, ax], n) - np.bincount(b, dP[:, ax], n)
        return out
