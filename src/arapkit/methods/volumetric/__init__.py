"""Volumetric r-ring ARAP: the closed surface is filled with tetrahedra ("inner edges").

Surface ARAP only keeps the *skin* rigid: bent hard, the skin folds into the empty inside and
can pass through itself. Filling the shape with tetrahedra adds inner edges that resist this,
and the r-ring energy (Chen et al. 2017, eq. 1) is defined on any edge graph, so the same
solver runs on the volume.

Construction (see ``docs/volumetric.md``)
-----------------------------------------
1. :func:`tetrahedralise` seeds the inside with a jittered lattice (:func:`interior_lattice`)
   and fills the surface with fTetWild (``pytetwild``, MPL-2.0) *without* surface
   simplification or optimisation, so every input vertex is a vertex of the tet mesh at
   exactly its input position (checked: a vertex fTetWild did not keep is refused, never
   approximated). Tet vertices are renumbered so that the first ``n`` are the surface's
   vertices in their input order.
2. The ARAP edge graph is the tet edges plus the input surface edges (fTetWild may split a
   surface edge where it cuts; the original edge is kept too). It is passed to the solver as
   a :class:`~arapkit.mesh.model.Mesh` whose faces are all four faces of every tet plus the input
   triangles; that mesh has exactly this edge set.
3. Weights (:func:`volume_graph`): by default ``w_ij = sum_t vol_t / l_ij^2`` over the tets
   on the edge, a stiffness per unit volume; ``uniform`` and clamped tetrahedral cotangent
   weights are the alternatives. All are positive, so the rest shape is an exact minimum and
   the system is positive definite.
4. Per-vertex rigidity r is given on the surface (:func:`volume_rings`): each surface vertex's
   ring on the volume is the largest one that reaches only skin of its surface r-ring (r hops
   through the inside would span whole cross-sections); an interior vertex's ring is held to
   the surface ring of its nearest surface vertex (rest positions) the same way.

The result is the input surface: the same vertices (deformed, first ``n`` rows of the volume
solve), the same faces.

Modules: :mod:`~arapkit.methods.volumetric.mesher` (the mesher's driver and the lattice),
:mod:`~arapkit.methods.volumetric.tets` (checks, tet mesh, files),
:mod:`~arapkit.methods.volumetric.graph` (edge graph and weights) and
:mod:`~arapkit.methods.volumetric.deformer`.
"""

from ...mesh.quality import enclosed_volume as mesh_volume  # the name this package has always used
from .deformer import (  # registers Deformer(volumetric=True)
    VOLUME_SOLVE_DEFAULTS,
    VolumetricDeformer,
)
from .graph import (
    CLAMP_FRACTION,
    DEFAULT_VOLUME_WEIGHTS,
    VOLUME_WEIGHTS,
    extend_rings,
    nearest_surface_vertex,
    tet_cotangent_weights,
    tet_volume_weights,
    volume_graph,
    volume_rings,
)
from .mesher import (
    LATTICE_CLEARANCE,
    MAX_LATTICE_CELLS,
    MAX_LATTICE_POINTS,
    MESHER_HINT,
    find_mesher,
    have_mesher,
    interior_lattice,
    lattice_spacing,
    morton_codes,
    run_mesher,
)
from .tets import (
    COARSE_TARGET,
    DEFAULT_DENSITY,
    ENVELOPE,
    MIN_EDGE_OVER_ENVELOPE,
    VOLUME_FORMATS,
    TetMesh,
    check_closed,
    save_volume,
    tetrahedralise,
)

__all__ = [
    "CLAMP_FRACTION",
    "COARSE_TARGET",
    "DEFAULT_DENSITY",
    "DEFAULT_VOLUME_WEIGHTS",
    "ENVELOPE",
    "LATTICE_CLEARANCE",
    "MAX_LATTICE_CELLS",
    "MAX_LATTICE_POINTS",
    "MESHER_HINT",
    "MIN_EDGE_OVER_ENVELOPE",
    "TetMesh",
    "VOLUME_FORMATS",
    "VOLUME_WEIGHTS",
    "VOLUME_SOLVE_DEFAULTS",
    "VolumetricDeformer",
    "check_closed",
    "extend_rings",
    "find_mesher",
    "have_mesher",
    "interior_lattice",
    "lattice_spacing",
    "mesh_volume",
    "morton_codes",
    "nearest_surface_vertex",
    "run_mesher",
    "save_volume",
    "tet_cotangent_weights",
    "tet_volume_weights",
    "tetrahedralise",
    "volume_graph",
    "volume_rings",
]
