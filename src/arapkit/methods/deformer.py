"""r-ring ARAP deformation: local/global iterations with one reused Cholesky factor.

Energy (Chen et al. 2017, eq. 1)::

    E(p', R) = sum_k sum_{e=(i,j) in N(k, r_k)} w_e |(p'_i - p'_j) - R_k (p_i - p_j)|^2

Global step (derived from eq. 1 itself; the paper's eq. 5 has a stray factor 2). Setting
dE/dp'_i = 0 gives, with d_e the number of neighbourhoods that contain edge e,

    sum_{j~i} d_ij w_ij (p'_i - p'_j) = sum_k R_k c_ki,

i.e. ``A p' = b`` with ``A`` the Laplacian of the edge weights ``d_e w_e``. For r = 1,
d_e = 2 and this is Sorkine & Alexa's ``sum_j w_ij (p'_i - p'_j) =
sum_j w_ij / 2 (R_i + R_j)(p_i - p_j)`` times 2. Handles (and vertices of components without
a handle) are eliminated, so the reduced matrix is symmetric positive definite; it is
factorised once per handle set and reused for every iteration and every new set of targets.

Local step: ``R_k = argmax_R tr(R S_k)`` with ``S_k = sum_e w_e e_e e'_e^T`` (see
:mod:`arapkit.arap.rotations`). Each step minimises E exactly over its block of unknowns, so the
energy never increases.

Layout
------
:class:`Deformer` is the friendly wrapper over four parts, each replaceable on its own:
the immutable precomputed problem (:mod:`arapkit.arap.problem`), the energy's structure
(:mod:`arapkit.arap.energies.base` and one module per further energy), the backend with the compiled
kernels (:mod:`arapkit.arap.backends.cpu`) and the local/global loop (:mod:`arapkit.arap.loop`).
Constraints and the Cholesky factor are in :mod:`arapkit.arap.constraints`.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..arap.backends import DEVICES, check_device, make_backend  # noqa: F401 - DEVICES: what device= takes
from ..arap.constraints import CholeskyFactor, anchor_components, check_handles, check_targets
from ..arap.domains import domain_of
from ..arap.energies.rring import check_ring_scale
from ..arap.graph import bandwidth_order, unit_scale
from ..arap.loop import Result, local_global, start_energy, with_progress
from ..arap.problem import ARAPProblem
from ..arap.rings import Neighbourhoods, check_rings
from ..errors import Advice, InputError
from ..mesh.cloud import PointCloud
from ..mesh.model import Mesh
from ..mesh.planar import PlanarInput
from ..mesh.weights import SOUND_WEIGHTS
from ..validate import integer, iteration_cap, real_array, tolerance
from .dispatch import (
    INITS,
    MULTIRES_AUTO_VERTICES,
    check_domain,
    check_method,
    coarse_to_fine,
    refuse_acceleration,
    register_variant,
    variant,
)
from .grouping import backend_for, grouped_problem, refuse_groups, ungrouped
from .planar import PlanarSolver, in_plane, planar_start, planar_targets, rings_or_preset, solve_dim
from .registry import method

# the method choice moved to .dispatch; its names stay importable from here
__all__ = ["INITS", "MULTIRES_AUTO_VERTICES", "Deformer", "Result", "check_handles",
           "anchor_components", "CholeskyFactor", "bandwidth_order", "check_domain",
           "check_method", "coarse_to_fine", "register_variant", "unit_scale"]


def _rows(ptr: np.ndarray, order: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """CSR rows ``order`` of a structure with row pointer ``ptr``: (new ptr, entry ids)."""
    lens = np.diff(ptr)[order]
    new_ptr = np.zeros(len(order) + 1, dtype=np.int64)
    np.cumsum(lens, out=new_ptr[1:])
    idx = np.repeat(ptr[order] - new_ptr[:-1], lens) + np.arange(new_ptr[-1])
    return new_ptr, idx


def _check_outside_roi_is_held(mesh: Mesh, roi, handles) -> None:
    """CGAL keeps the vertices outside its ROI where they are: here they must be handles."""
    loose = np.ones(mesh.n_vertices, dtype=bool)
    loose[np.asarray(roi)] = False
    loose[np.asarray(handles, dtype=np.int64)] = False
    if loose.any():
        raise InputError(f"{mesh.name}: vertex {int(np.flatnonzero(loose)[0])} is outside "
                         "sr_roi but not a handle (hold every vertex outside the ROI)")


class Deformer:
    """ARAP deformer: r-ring rigidity (default) or another method on the same handles.

    Parameters
    ----------
    mesh : Mesh, PointCloud, Graph, a (vertices, faces) pair, a trimesh.Trimesh, or points
        The shape (:func:`arapkit.mesh.cloud.as_shape`): a triangle mesh (a pair may hold
        ``(n, 2)`` positions: a planar shape, solved in 2D), or a point cloud (an
        :class:`arapkit.PointCloud`, an ``(n, 3)`` array, an Open3D or trimesh point
        cloud) solved on its neighbourhood graph, or an :class:`arapkit.Graph` of your
        own edges. Methods defined on triangles refuse a point cloud (``docs/clouds.md``).
    handles : (h,) int, (n,) bool, or a HandleSet
        Vertices with positional constraints (a mask selects its True vertices; a
        :func:`arapkit.load_handles` set stands for its indices).
    rings : int, (n,) int or a preset name
        Neighbourhood size r per vertex (1 = standard ARAP; larger = stiffer). Only for
        ``energy="rring"``. A rigidity preset ("distort", "normal", "rigid") stands for its
        r (:data:`arapkit.methods.planar.PRESETS`).
    weights : str or (m,) array, optional
        Edge weights. On a mesh ``"cotan"``, ``"cotan-clamped"`` (the default),
        ``"cotan-clamped-each"`` or ``"uniform"`` (:mod:`arapkit.mesh.weights`); on a point
        cloud ``"gaussian"`` (the default), ``"uniform"`` or ``"laplacian"``
        (:mod:`arapkit.mesh.cloud_weights`); or one positive weight per edge. None: the
        shape's default (a :class:`arapkit.Graph`'s own weights where it has them).
    energy : {"rring", "spokes-and-rims", "sr-arap", "smooth-arap", "embedded"}
        The method (see ``docs/methods.md``): r-ring ARAP (Chen et al. 2017),
        spokes-and-rims ARAP (Chao et al. 2010), smooth-rotation ARAP (Levi & Gotsman
        2014), Smooth ARAP (Oehri et al. 2025: no spike under a single-vertex handle,
        ``docs/smooth-arap.md``) or embedded deformation (Sumner et al. 2007,
        :mod:`arapkit.methods.embedded`).
    sr_alpha : float, optional
        SR-ARAP's rotation-smoothness weight (default 0.02, CGAL's), scaled by the surface
        area as CGAL does.
    sr_roi : (k,) int, optional
        SR-ARAP only: pose CGAL's problem for a partial region of interest (its vertex ids,
        handles included; a ``.sel`` file's statuses 1 and 2). Vertices outside it must be
        handles (held at rest). Rotations are then coupled only within the ROI and its
        one-ring, as in CGAL's ``Surface_mesh_deformation``; without it every vertex's
        rotation is coupled to all its neighbours' (``docs/methods.md``).
    nodes : int, optional
        Embedded deformation's graph size (default 200, at most the vertex count).
    smooth_lambda : float, optional
        Smooth ARAP's weight of the Laplacian term, in [0, 1) (default 0.99, the paper's;
        0 is ARAP): see :mod:`arapkit.arap.energies.smooth_arap`.
    ring_scale : float
        r is counted in the rings of a mesh whose edges are ``ring_scale`` times this
        one's (default 1: this mesh's own). A decimated copy of a mesh, solved with the
        original's rigidity map and ``ring_scale = h_original / h_copy`` (mean edge
        lengths), is as stiff as the original: it searches ``max(1, rint(r s))`` rings,
        and where one of its rings is already stiffer than r rings of the original
        (``r s < 1``) it blends in a rotation per triangle
        (:mod:`arapkit.arap.energies.rring`). Coarse to fine sets it for its proxy.
        ``energy="rring"`` only; the CPU device only below 1.
    groups : VertexGroups or (n,) int, optional
        Vertex groups (:class:`arapkit.mesh.groups.VertexGroups`, e.g. from
        :func:`arapkit.io.load_groups`): **rigid parts**, whose vertices move by one rigid
        motion (solved exactly: a handle inside one moves the whole part), and
        **shared-rotation groups**, libigl's ``ARAPData.G`` (one rotation, free positions).
        A plain array is libigl's ``G``: one id per vertex, shared rotations, -1 for none.
        For the methods the registry says take them (``MethodInfo.groups``: r-ring and
        spokes-and-rims ARAP); they mix with a rigidity map and with handles. See
        ``docs/groups.md``.
    tol : float
        Stop when ``|E_{t-1} - E_t| / |E_{t-1}| < tol`` (the paper's test, gamma = 1e-3).
    max_iter : int
        Iteration cap.
    init : {"identity", "laplacian"}
        Start from identity rotations (the paper) or from Laplacian editing (the report).
    free_components : {"follow", "fix", "error"}
        What to do with connected components that hold no handle.
    accelerate : bool or None
        Anderson acceleration (Peng et al. 2018) of the local/global iteration with an
        energy safeguard: an accelerated iterate is kept only when it lowers the energy,
        otherwise the plain iterate is used, so the history stays monotone. None (the
        default) is the method's choice: off for a plain solve, so that iterations (and the
        paper's stopping test) mean plain local/global steps; on for coarse to fine
        (``multires``) and volumetric solves. See ``docs/benchmarks.md`` for when it pays.
        Not with ``energy="sr-arap"``.
    history : int
        Anderson history size m.
    reorder : bool
        Work internally in a bandwidth-reducing vertex order (results are returned in the
        mesh's order and agree with ``reorder=False`` to round-off).
    dim : {None, 2, 3}
        None: 2 for a planar shape with a method that runs in the plane, else 3
        (:func:`arapkit.methods.planar.solve_dim`, ``docs/2d.md``).
    flips : {"prevent", "allow"}
        2D: keep every triangle unfolded (:mod:`arapkit.arap.flips`), or plain ARAP.
    device : {"cpu", "auto", "cuda", "cuda:N", "torch-cpu"}
        Where to solve: "cpu" runs the numba kernels; "cuda" (and "torch-cpu", the same
        code on CPU tensors) the torch backend of :mod:`arapkit.arap.backends.torch_backend` (extra
        ``arapkit[torch]``; see ``docs/torch.md``); "auto" is "cuda" when torch sees a
        device, else "cpu".
    multires : bool or None
        Solve coarse to fine: a decimated proxy (about 20K vertices) previews and starts
        the full-resolution solve, which then converges by the same test (see
        :mod:`arapkit.methods.multires`). This returns a
        :class:`arapkit.methods.multires.MultiresDeformer` (same interface, plus
        ``preview``). None (the default): on for meshes of at least 100,000 vertices
        (:data:`MULTIRES_AUTO_VERTICES`) with a method that allows it; False: never.
    proxy_vertices : int, optional
        With coarse to fine: the proxy's size (default 20,000; a mesh of at most twice
        that is its own proxy).
    levels : sequence of int, optional
        With coarse to fine: the sizes of the intermediate meshes the exact solve passes
        through (default: none; see :class:`arapkit.methods.multires.MultiresDeformer`).
    volumetric : bool
        Fill the closed surface with tetrahedra and solve r-ring ARAP on the volume's edge
        graph (the course report's "inner edges"); the result is still the surface's. This
        returns a :class:`arapkit.methods.volumetric.VolumetricDeformer` (same interface; needs
        ``pip install 'arapkit[volume]'``). The surface ``weights`` do not apply.
    density : float, optional
        With ``volumetric=True``: spacing of the interior points in multiples of the
        surface's mean edge length, or of 1/40 of the bounding-box diagonal where that is
        larger (default :data:`arapkit.methods.volumetric.DEFAULT_DENSITY`).

    Examples
    --------
    >>> from arapkit.mesh.shapes import bar, bar_bend
    >>> mesh = bar()
    >>> h, t = bar_bend(mesh, 90)
    >>> res = Deformer(mesh, h, rings=2).solve(t)
    >>> bool(res.converged), bool(res.energy >= 0)
    (True, True)
    >>> fast = Deformer(mesh, h, rings=2, accelerate=True).solve(t, tol=1e-6)
    >>> bool(fast.energy <= res.energy)
    True

    A rigid part in the middle of the bar keeps its shape while the rest bends:

    >>> from arapkit.mesh.groups import VertexGroups
    >>> middle = np.flatnonzero(np.abs(mesh.vertices[:, 0] - 4) < 1)
    >>> part = VertexGroups.from_lists([("middle", middle, True)], mesh.n_vertices)
    >>> bent = Deformer(mesh, h, groups=part).solve(t).vertices
    >>> i, j = middle[0], middle[-1]
    >>> d0, d1 = (np.linalg.norm(X[i] - X[j]) for X in (mesh.vertices, bent))
    >>> bool(abs(d1 - d0) < 1e-9 * d0)
    True
    """

    def __new__(cls, mesh: Mesh | PointCloud, handles, rings=1, weights: str | None = None,
                *, volumetric: bool = False, density: float | None = None,
                multires: bool | None = None, proxy_vertices: int | None = None,
                levels=None, **options):
        shape = PlanarInput.of_shape(mesh)  # a mesh, or a point cloud (solved in 3D)
        mesh = shape.mesh
        check_domain(mesh, options.get("energy", "rring"), volumetric=volumetric,
                     init=options.get("init", "identity"))
        if not volumetric:
            if density is not None:
                raise InputError("density is an option of volumetric=True")
            if not in_plane(shape, multires, options) and coarse_to_fine(mesh, multires,
                                                                         options):
                if proxy_vertices is not None:
                    options["proxy_vertices"] = proxy_vertices
                if levels is not None:
                    options["levels"] = levels
                return variant("multires")(mesh, handles, rings, weights, **options)
            for name, value in (("proxy_vertices", proxy_vertices), ("levels", levels)):
                if value is not None:
                    raise InputError(f"{name} is an option of multires=True")
            obj = super().__new__(cls)
            # __init__ receives the caller's mesh again: a trimesh is converted once, here
            obj._checked_shape = shape
            return obj
        if multires:
            raise InputError("multires=True is for surfaces; volumetric=True solves the "
                             "volume directly")
        if options.get("groups") is not None:
            raise InputError("groups: vertex groups are for surface ARAP, not "
                             "volumetric=True (the volume's interior vertices have none)")
        energy = options.pop("energy", "rring")
        check_method(energy, options.pop("sr_alpha", None), options.pop("nodes", None),
                     options.pop("sr_roi", None), options.pop("smooth_lambda", None))
        if not method(energy).volumetric:
            raise InputError(f"volumetric=True runs r-ring ARAP; energy '{energy}' is for "
                             "surfaces")
        if density is not None:
            options["density"] = density
        return variant("volumetric")(mesh, handles, rings, **options)

    def __init__(
        self,
        mesh: Mesh | PointCloud,
        handles,
        rings=1,
        weights: str | None = None,
        *,
        volumetric: bool = False,
        density: float | None = None,
        multires: bool | None = None,
        proxy_vertices: int | None = None,
        levels=None,
        energy: str = "rring",
        sr_alpha: float | None = None,
        sr_roi=None,
        nodes: int | None = None,
        smooth_lambda: float | None = None,
        ring_scale: float = 1.0,
        groups=None,
        tol: float = 1e-3,
        max_iter: int = 1000,
        init: str = "identity",
        free_components: str = "follow",
        accelerate: bool | None = None,
        history: int = 5,
        reorder: bool = True,
        device: str = "cpu",
        dim: int | None = None,
        flips: str = "prevent",
    ) -> None:
        self.device = check_device(device)
        options = check_method(energy, sr_alpha, nodes, sr_roi, smooth_lambda)
        info = method(energy)
        rings = rings_or_preset(rings)
        self.ring_scale = check_ring_scale(ring_scale)
        if self.ring_scale != 1.0:
            if not info.rigidity_map:
                raise InputError(f"ring_scale: energy '{energy}' has no rigidity map")
            options["ring_scale"] = self.ring_scale
        shape = self.__dict__.pop("_checked_shape", None) or PlanarInput.of_shape(mesh)
        mesh = shape.mesh
        self.mesh = mesh
        #: the shape as given (2D or 3D) and the dimension it is solved in
        self.shape = shape
        self.dim = solve_dim(shape, dim, info.planar, energy)
        self._plane = PlanarSolver(shape, flips, self.device)
        self.energy = energy
        # None: the shape's domain's own (cotan-clamped on a mesh, gaussian on a cloud)
        self.weights_kind = domain_of(mesh).default_weights if weights is None else weights
        self.tol = tolerance(tol)
        self.max_iter = iteration_cap(max_iter)
        if init not in INITS:
            raise InputError(f"unknown init '{init}' (use {' or '.join(INITS)})")
        self.init = init
        # None: the method's choice, which for a plain solve is off
        self.accelerate = None if accelerate is None else bool(accelerate)
        if self.accelerate:
            refuse_acceleration(info, " (use accelerate=False)")
        self.history = integer(history, "history", lo=1, hi=1000)
        self.factorisations = 0
        self._laplacian_editor = None
        self.embedded = None
        if not info.local_global:
            from .embedded import EmbeddedDeformation

            if not np.all(np.asarray(rings) == 1):
                raise InputError(f"energy '{energy}' has no rigidity map (rings must be 1)")
            if groups is not None:
                refuse_groups(energy)
            self.groups = None
            self.embedded = EmbeddedDeformation(mesh, handles, options["nodes"])
            self.problem = None
            self._rings = np.ones(mesh.n_vertices, dtype=np.int32)
            self._weight_notes = []
            return
        #: the vertex groups in use (None: none)
        self.groups = None
        self.problem = ARAPProblem.from_mesh(
            mesh, handles, energy, weights, rings=rings, free_components=free_components,
            reorder=reorder, dim=self.dim, **options)
        if self.problem.weights_kind is not None:
            self.weights_kind = self.problem.weights_kind
        self._rings = self.problem.energy.rings[self.problem.iperm]
        if sr_roi is not None:
            _check_outside_roi_is_held(mesh, sr_roi, handles)
        if groups is not None:
            self.problem, self.groups = grouped_problem(self.problem, groups, energy,
                                                        self.device)
        self.backend = backend_for(self.problem, self.device)
        self._weight_notes = self._check_rest_is_minimum()

    # -- configuration (lazy refactorisation, as CGAL) -----------------------------
    def set_groups(self, groups) -> None:
        """Use other vertex groups (a :class:`~arapkit.mesh.groups.VertexGroups`, one
        shared-rotation id per vertex, or None for none); refactorises at the next solve.

        Examples
        --------
        >>> from arapkit.mesh.groups import VertexGroups
        >>> from arapkit.mesh.shapes import bar
        >>> m = bar()
        >>> d = Deformer(m, [0])
        >>> d.set_groups(VertexGroups.from_lists([("tip", [1, 2, 3], True)], m.n_vertices))
        >>> d.groups.names
        ('tip',)
        """
        if self.problem is None:
            if groups is not None:
                refuse_groups(self.energy)
            return
        p = self.problem
        plain, kept = ungrouped(p), None
        new = plain
        if groups is not None:  # checked first: a refusal keeps what is there
            new, kept = grouped_problem(plain, groups, self.energy, self.device)
        self.groups = kept
        p.release_factor()
        self.problem = new
        self.backend = backend_for(self.problem, self.device)

    def set_handles(self, handles, *, update_factor: bool | None = None) -> None:
        """Use a new handle set; the factorisation is redone at the next solve, or, with
        ``update_factor`` (None: in 2D), corrected (:mod:`arapkit.arap.pinupdate`)."""
        self._laplacian_editor = None
        if self.embedded is not None:
            from .embedded import EmbeddedDeformation

            self.embedded = EmbeddedDeformation(self.mesh, handles, len(self.embedded.nodes))
            return
        update = self.dim == 2 if update_factor is None else bool(update_factor)
        # checked first: a bad set keeps the factor
        new = self.problem.with_handles(handles, update_factor=update)
        if not new.factorised:
            self.problem.release_factor()  # not held beside the new one by whoever keeps this
        self.problem = new

    def set_rings(self, rings) -> None:
        """Use a new rigidity map (int or per-vertex); rebuilds neighbourhoods and the factor."""
        p = self.problem
        if not method(self.energy).rigidity_map:
            if not np.all(np.asarray(rings) == 1):
                raise InputError(f"energy '{self.energy}' has no rigidity map (rings must be 1)")
            return
        r = check_rings(rings_or_preset(rings), p.n_vertices)  # a bad map: the factor is kept
        p.release_factor()  # of no use to the new map, and as large as the one to come
        self.problem = p.with_rings(r)
        self.backend = backend_for(self.problem, self.device)
        self._rings = self.problem.energy.rings[self.problem.iperm]
        self._weight_notes = self._check_rest_is_minimum()

    def _check_rest_is_minimum(self) -> list[str]:
        """Say so when negative weights make the rest shape a non-minimum of eq. (1).

        With all weights >= 0 every rest covariance is positive semi-definite, its best
        rotation is the identity and the energy at rest is 0. Negative cotangent weights
        (raw ``weights="cotan"`` on obtuse triangles) can make the best-fit energy at rest
        negative: the shape then drifts even when every handle stays in place. Only then
        is there something worth telling the user.
        """
        if self.energy_is_sum_of_squares:
            return []
        d = self.problem.dim
        R = np.empty((self.problem.energy.n_owners, d, d))
        R_prev = np.tile(np.eye(d), (len(R), 1, 1))
        E_rest = self.backend.local(self.problem.rest_positions.copy(), R, R_prev)
        if E_rest >= -1e-9 * abs(self.backend.rest_term):
            return []
        bad = int(np.count_nonzero(np.abs(R - np.eye(d)).max(axis=(1, 2)) > 1e-6))
        return [Advice(
            f"{int((self.w < 0).sum())} edges have negative cotangent weights and the rest "
            f"shape is not an energy minimum ({bad} neighbourhoods prefer a rotation at rest): "
            "the shape drifts even where handles stay put and the energy can be negative; "
            "use {weights} (positive weights)", weights=SOUND_WEIGHTS,
        )]

    @property
    def energy_is_sum_of_squares(self) -> bool:
        """Whether every weight is >= 0, so that the energy is a sum of squares (E >= 0).

        False only for raw cotangent weights on meshes with obtuse triangles. Embedded
        deformation has no edge weights: its energy is a sum of squared residuals by
        construction.

        Examples
        --------
        >>> from arapkit.mesh.shapes import bar
        >>> Deformer(bar(), [0]).energy_is_sum_of_squares
        True
        """
        if self.problem is None:
            return True
        return bool((self.w >= 0).all())

    @property
    def notes(self) -> list[str]:
        """What the deformer did about the input: fixed components, problematic weights."""
        if self.problem is None:
            return []
        return list(self.problem.notes) + self._weight_notes

    @property
    def handles(self) -> np.ndarray:
        """Handle vertices."""
        return self.embedded.handles if self.problem is None else self.problem.handles

    def _local_global(self, what: str):
        if self.problem is None:
            raise InputError(f"{what}: energy '{self.energy}' is not a local/global method")
        return self.problem

    @property
    def w(self) -> np.ndarray:
        """Edge weights (by edge id of ``mesh.edges``)."""
        return self._local_global("edge weights").w

    @property
    def rings(self) -> np.ndarray:
        """r per vertex."""
        return self._rings

    @property
    def timings(self) -> dict[str, float]:
        """Precomputation times: neighbourhood_ms, factorisation_ms (once factorised)."""
        return self.embedded.timings if self.problem is None else self.problem.timings

    @property
    def neighbourhoods(self) -> Neighbourhoods:
        """The neighbourhoods in use, relabelled to the mesh's vertex numbering.

        No search is repeated: the solver's structure is permuted. Edge ids index
        ``mesh.edges``; Smooth ARAP's ids past them are its vertex pairs two rings apart.
        """
        p = self._local_global("neighbourhoods")
        nbh = p.energy.nbh
        eptr, eid = _rows(nbh.edge_ptr, p.iperm)
        dptr, did = _rows(nbh.disk_ptr, p.iperm)
        return Neighbourhoods(
            nbh.rings[p.iperm], eptr, nbh.edge_idx[eid], nbh.edge_layer[eid], dptr,
            p.perm[nbh.disk_idx[did]].astype(np.int32), nbh.disk_coef[did], nbh.edge_count,
        )

    def prepare(self) -> None:
        """Factorise now (otherwise the first :meth:`solve` does it); reused for all targets."""
        if self.problem is None:
            return
        if self.backend.problem is not self.problem or not self.problem.factorised:
            if self.backend.problem.energy is not self.problem.energy:
                self.backend = backend_for(self.problem, self.device)
            was = self.problem.factorised
            self.backend.bind(self.problem)
            if not was and self.problem.elimination.factor is not None:
                self.factorisations += 1

    def vertex_energy(self, P: np.ndarray, R: np.ndarray) -> np.ndarray:
        """Each neighbourhood's term of the energy for positions P and rotations R (mesh order).

        Examples
        --------
        >>> import numpy as np
        >>> from arapkit.mesh.shapes import bar
        >>> m = bar()
        >>> d = Deformer(m, [0])
        >>> R = np.tile(np.eye(3), (m.n_vertices, 1, 1))
        >>> float(d.vertex_energy(m.vertices, R).max())
        0.0
        """
        p = self._local_global("vertex_energy")
        P = np.asarray(P, dtype=np.float64)[:, :p.dim]
        Pi = np.ascontiguousarray(P[p.perm] / p.scale)
        Ri = np.ascontiguousarray(np.asarray(R, dtype=np.float64)[p.perm])
        return self.backend.vertex_energy(Pi, Ri)[p.iperm] * (p.scale * p.scale)

    def energy_of(self, P: np.ndarray, targets) -> float:
        """The energy of shape ``P`` with its handles moved to ``targets``, at the best
        rotations: what a :meth:`solve` started from ``P`` begins at (unless the targets
        are one rigid motion of the handles' rest positions: that solve starts from the
        motion of the rest shape instead).

        Examples
        --------
        >>> import numpy as np
        >>> from arapkit.mesh.shapes import bar
        >>> m = bar()
        >>> d = Deformer(m, [0, 1])
        >>> float(d.energy_of(m.vertices, m.vertices[[0, 1]]))
        0.0
        >>> float(d.energy_of(m.vertices, m.vertices[[0, 1]] + [[0, 0, 0], [0, 0, 1]])) > 0
        True
        """
        p = self._local_global("energy_of")
        d = p.dim
        T = check_targets(self.handles, targets) if d == 3 else \
            planar_targets(self.shape, self.handles, targets)[:, :2]
        P = planar_start(self.shape, np.asarray(P, dtype=np.float64)) if d == 2 else P
        self.prepare()
        s = p.scale
        R = np.empty((p.energy.n_owners, d, d))
        R_prev = np.empty_like(R) if p.energy.coupling is not None else np.empty((0, d, d))
        _, E = start_energy(p, self.backend, P, s, p.constrained_targets(T / s), R, R_prev)
        return float(E * s * s)

    def _initial_positions(self, targets: np.ndarray, init) -> np.ndarray | None:
        if init is not None and not isinstance(init, str):
            # a float64 array is not copied: the solve only reads it (a shape is 40 MB at
            # 1.75M vertices, and a coarse-to-fine caller holds its own through the solve)
            P = (init if isinstance(init, np.ndarray) and init.dtype == np.float64
                 else real_array(init, "init"))
            if targets.shape[1] == 2:  # a planar solve
                return planar_start(self.shape, P)
            if P.shape != self.mesh.vertices.shape or not np.isfinite(P).all():
                raise InputError(
                    f"init: expected finite positions of shape {self.mesh.vertices.shape}"
                )
            return P
        mode = self.init if init is None else init
        if mode not in INITS:
            raise InputError(f"unknown init '{mode}' (use {' or '.join(INITS)})")
        if mode == "identity":
            return None
        check_domain(self.mesh, init=mode)
        # embedded deformation has no problem: its constrained vertices are the handles
        p = self.problem
        if self._laplacian_editor is None:
            from .laplacian import LaplacianEditor

            self._laplacian_editor = LaplacianEditor(
                self.mesh, self.handles if p is None else p.constrained, "uniform")
        if p is not None and targets.shape[1] == 2:  # in the plane: lifted and back
            C = p.constrained_targets(targets)
            C = np.concatenate([C, np.full((len(C), 1), self.shape.z)], axis=1)
            return self._laplacian_editor.solve(C)[:, :2]
        return self._laplacian_editor.solve(targets if p is None else
                                            p.constrained_targets(targets))

    # -- the solve ----------------------------------------------------------------
    def solve(
        self,
        targets,
        init=None,
        tol: float | None = None,
        max_iter: int | None = None,
        callback: Callable[[int, float, np.ndarray], bool | None] | None = None,
        accelerate: bool | None = None,
        progress: Callable[[int, float], bool | None] | None = None,
        angles=None,
    ) -> Result:
        """Deform so that the handles reach ``targets``.

        Parameters
        ----------
        targets : (h, 3), (h, 2) in 2D, or a HandleSet
            Positions of the handles, in the order of ``handles`` (a
            :func:`arapkit.load_handles` set stands for its targets).
        init : None, "identity", "laplacian" or (n, 3) array ((n, 2) in 2D)
            Starting point; an array is a warm start (e.g. the previous result).
        tol, max_iter : optional overrides of the constructor's values.
        callback : callable(iteration, energy, vertices) -> bool, optional
            Called after every iteration; returning True stops the loop. ``vertices`` is
            a new copy of the shape each time (about 40 ms an iteration at 1.75M
            vertices).
        accelerate : optional override of the constructor's ``accelerate``.
        progress : callable(iteration, energy) -> bool, optional
            Called after every iteration (after ``callback``) without the shape: for a
            caller that reports progress or may interrupt the solve on a large mesh.
            Returning True stops the loop.
        angles : (h,) float, optional
            2D only: a turn per handle in radians (NaN: none), Photoshop's pin rotation.
            A turned pin holds its own rotation and its one-ring neighbours' at the
            angle, so its neighbourhood turns with it (:func:`pin_neighbourhoods`).

        Returns
        -------
        Result

        Examples
        --------
        >>> from arapkit.mesh.shapes import bar
        >>> m = bar(segments=(12, 2, 2))
        >>> left = np.flatnonzero(m.vertices[:, 0] == m.vertices[:, 0].min())
        >>> right = np.flatnonzero(m.vertices[:, 0] == m.vertices[:, 0].max())
        >>> d = Deformer(m, np.concatenate([left, right]))
        >>> T = m.vertices[d.handles] + [0.0, 0.0, 0.5] * np.isin(d.handles, right)[:, None]
        >>> seen = []
        >>> res = d.solve(T, progress=lambda it, E: seen.append(E) or it == 3)
        >>> res.iterations, len(seen), seen[-1] == res.energy
        (3, 3, True)
        """
        T = (check_targets(self.handles, targets) if self.dim == 3
             else planar_targets(self.shape, self.handles, targets))
        tol = self.tol if tol is None else tolerance(tol)
        max_iter = self.max_iter if max_iter is None else iteration_cap(max_iter)
        accelerate = bool(self.accelerate) if accelerate is None else bool(accelerate)
        if accelerate:
            refuse_acceleration(method(self.energy))
        if self.embedded is not None:
            # a start shape becomes node maps fitted to it (EmbeddedDeformation.fit_node_maps)
            return self.embedded.solve(T, init=self._initial_positions(T, init), tol=tol,
                                       max_iter=max_iter,
                                       callback=with_progress(callback, progress))
        self.prepare()
        start = self._initial_positions(T, init)
        loop = dict(tol=tol, max_iter=max_iter, callback=callback, accelerate=accelerate,
                    history=self.history, progress=progress)
        if self.dim == 2:
            return self._plane.solve(self.problem, self.backend, self.handles, T, start,
                                     angles, **loop)
        if angles is not None:
            raise InputError("angles: pin turns are for planar (2D) solves")
        return local_global(self.problem, self.backend, T, start, **loop)
