"""The volumetric deformer: r-ring ARAP on the tet filling, the surface in and out.

:class:`VolumetricDeformer` is what ``Deformer(..., volumetric=True)`` returns (it registers
itself with :func:`arapkit.methods.deformer.register_variant`).
"""

from __future__ import annotations

import time

import numpy as np

from ...arap.constraints import check_handles
from ...arap.rings import check_rings
from ...errors import InputError
from ...mesh.model import Mesh, as_mesh
from ..deformer import Deformer, Result, register_variant
from .graph import DEFAULT_VOLUME_WEIGHTS, volume_graph, volume_rings
from .tets import DEFAULT_DENSITY, TetMesh, check_closed, save_volume, tetrahedralise

__all__ = ["VOLUME_SOLVE_DEFAULTS", "VolumetricDeformer"]

#: solver options a volumetric solve takes unless told otherwise: converged answers. At the
#: surface solver's tol 1e-3 slow volumes stop while still moving (docs/volumetric.md,
#: "Defaults": the elephant shows 0 self-intersecting faces at 1e-3, about 50 converged);
#: acceleration makes 1e-5 affordable (the cactus twist: 851 -> 72 iterations)
VOLUME_SOLVE_DEFAULTS = {"tol": 1e-5, "accelerate": True}


class VolumetricDeformer:
    """r-ring ARAP on the tetrahedral filling of a closed surface; returns the surface.

    Same interface as :class:`arapkit.Deformer` (``solve`` returns a
    :class:`~arapkit.methods.deformer.Result` whose ``vertices``, ``rotations`` and
    ``vertex_energy``
    are the surface's, first ``n`` rows), with the volume solved underneath.

    Parameters
    ----------
    mesh : Mesh
        Closed surface.
    handles : (h,) int
        Surface vertices with positional constraints.
    rings : int or (n,) int
        r per surface vertex, as for surface ARAP: on the volume it becomes the ring that
        reaches the same skin (:func:`~arapkit.methods.volumetric.graph.volume_rings`).
    density : float
        Interior lattice spacing (see :func:`tetrahedralise`).
    tet : TetMesh, optional
        A tetrahedralisation of ``mesh`` to reuse (from :func:`tetrahedralise`).
    **options
        ``tol``, ``max_iter``, ``init``, ``free_components``, ``accelerate``, ``history``,
        ``reorder``, ``device``: as for :class:`arapkit.Deformer`, except that ``tol`` and
        ``accelerate`` default to :data:`VOLUME_SOLVE_DEFAULTS` (1e-5, accelerated).

    Examples
    --------
    >>> from arapkit.mesh.shapes import bar, bar_bend
    >>> mesh = bar()
    >>> h, t = bar_bend(mesh, 90)
    >>> res = VolumetricDeformer(mesh, h, rings=1).solve(t)   # doctest: +SKIP
    >>> res.vertices.shape == mesh.vertices.shape             # doctest: +SKIP
    True
    """

    def __init__(self, mesh: Mesh, handles, rings=1, *, density: float = DEFAULT_DENSITY,
                 weights: str = DEFAULT_VOLUME_WEIGHTS, tet: TetMesh | None = None,
                 **options) -> None:
        self.mesh = mesh = as_mesh(mesh)
        handles = check_handles(mesh, handles)
        if tet is None:
            tet = tetrahedralise(mesh, density)  # refuses surfaces that bound no volume
        else:
            check_closed(mesh)
            if tet.n_surface != mesh.n_vertices or not np.array_equal(
                    tet.vertices[:tet.n_surface], mesh.vertices):
                raise InputError(
                    f"{mesh.name}: the given tet mesh was not made from this surface")
        self.tet = tet
        t0 = time.perf_counter()
        self.graph, self.w = volume_graph(mesh, tet, weights)
        self._rings = check_rings(rings, mesh.n_vertices)
        # a None (the Deformer's "method's choice") leaves the volume's default
        options = {**VOLUME_SOLVE_DEFAULTS,
                   **{k: v for k, v in options.items() if v is not None or k != "accelerate"}}
        self.accelerate = bool(options["accelerate"])
        # the volume's graph is solved as it is: no surface to decimate into a proxy
        self._inner = Deformer(self.graph, handles, volume_rings(rings, mesh, self.graph, tet),
                               weights=self.w, multires=False, **options)
        self._graph_ms = 1e3 * (time.perf_counter() - t0)
        self.handles = handles

    @property
    def n(self) -> int:
        """Number of surface vertices."""
        return self.mesh.n_vertices

    @property
    def rings(self) -> np.ndarray:
        """r per surface vertex, as given (the volume's rings are derived from it)."""
        return self._rings

    @property
    def problem(self):
        """The volume's ARAP problem, on the tet-edge graph (an ``ARAPProblem``)."""
        return self._inner.problem

    @property
    def energy_is_sum_of_squares(self) -> bool:
        """Whether every edge weight of the volume is >= 0 (so E >= 0)."""
        return self._inner.energy_is_sum_of_squares

    @property
    def notes(self) -> list[str]:
        """What was done about the input (the volume's size; fixed components)."""
        tm = self.tet
        return [
            f"filled with {len(tm.tets)} tetrahedra ({tm.n_vertices - tm.n_surface} interior "
            f"vertices) in {tm.seconds:.1f} s"
        ] + self._inner.notes

    def set_handles(self, handles) -> None:
        """Use a new handle set (surface vertices)."""
        self.handles = check_handles(self.mesh, handles)
        self._inner.set_handles(self.handles)

    def set_rings(self, rings) -> None:
        """Use a new rigidity map on the surface (extended inwards)."""
        self._inner.set_rings(volume_rings(rings, self.mesh, self.graph, self.tet))
        self._rings = check_rings(rings, self.n)

    def prepare(self) -> None:
        """Factorise now."""
        self._inner.prepare()

    def solve(self, targets, init=None, callback=None, **kwargs):
        """Deform so that the handles reach ``targets``; see :meth:`arapkit.Deformer.solve`.

        ``init`` may be an (n, 3) surface warm start (interior vertices then start at rest)
        or an (N, 3) volume one. ``callback`` sees the surface's vertices. The volume's
        deformed vertices are kept in :attr:`volume_vertices`.
        """
        n = self.n
        if init is not None and not isinstance(init, str):
            P = np.asarray(init, dtype=np.float64)
            if P.ndim == 2 and P.shape[0] == n and n != self.tet.n_vertices:
                P = np.concatenate([P, self.tet.vertices[n:]])
            init = P
        cb = None
        if callback is not None:
            def cb(it, E, P):
                return callback(it, E, P[:n])

        res = self._inner.solve(targets, init=init, callback=cb, **kwargs)
        self.volume_vertices = res.vertices

        def vertex_energy() -> np.ndarray:  # the volume's, computed on first access
            return res.vertex_energy[:n]

        timings = {"tetrahedralisation_ms": 1e3 * self.tet.seconds,
                   "graph_ms": self._graph_ms, **res.timings}
        return Result(res.vertices[:n], res.energy, res.history, res.iterations, res.converged,
                      res.rotations[:n], timings, vertex_energy)

    def save_volume(self, path) -> None:
        """Write the last solve's deformed tet mesh (or the rest one before any solve)."""
        P = getattr(self, "volume_vertices", self.tet.vertices)
        save_volume(path, P, self.tet.tets)


register_variant("volumetric", VolumetricDeformer)
