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
4. Per-vertex rigidity r given on the surface extends inwards: each interior vertex takes the
   r of its nearest surface vertex (rest positions).

The result is the input surface: the same vertices (deformed, first ``n`` rows of the volume
solve), the same faces.
"""

from __future__ import annotations

import glob
import importlib
import importlib.machinery
import importlib.util
import os
import time
from dataclasses import dataclass

import numpy as np

from ..arap.rings import check_rings
from ..errors import InputError
from ..mesh.model import Mesh
from ..mesh.quality import enclosed_volume as mesh_volume  # the name this module has always used
from .deformer import Deformer, Result, check_handles

__all__ = [
    "DEFAULT_DENSITY",
    "DEFAULT_VOLUME_WEIGHTS",
    "MESHER_HINT",
    "TetMesh",
    "VOLUME_FORMATS",
    "VOLUME_WEIGHTS",
    "VolumetricDeformer",
    "check_closed",
    "have_mesher",
    "interior_lattice",
    "lattice_spacing",
    "mesh_volume",
    "morton_codes",
    "save_volume",
    "tet_cotangent_weights",
    "tet_volume_weights",
    "tetrahedralise",
    "volume_graph",
]

#: spacing of the interior lattice, in multiples of the surface's mean edge length (or of
#: 1/40 of the bounding-box diagonal where that is larger; see lattice_spacing)
DEFAULT_DENSITY = 1.0
#: weights below this fraction of the mean absolute weight are raised to it
CLAMP_FRACTION = 1e-3
#: fTetWild's envelope, relative to the bounding-box diagonal (fTetWild's own default). The
#: surface is inserted without simplification and every input vertex is kept exactly whatever
#: the envelope, but where fTetWild cannot insert a triangle exactly it accepts one within the
#: envelope: at 3e-2 the hand's tets held 0.24 % more volume than its surface, at 1e-3
#: 0.006 %, in the same time
ENVELOPE = 1e-3
#: positive weightings of the volume's edge graph (see :func:`volume_graph`)
VOLUME_WEIGHTS = ("uniform", "tet-volume", "tet-cotan-clamped")
#: a stiffness per unit volume, so the sparse interior counts as much as the densely
#: tessellated skin (uniform weights make the skin the stiffer, the finer it is); it kept
#: more volume than uniform on the twists and strained bends of docs/benchmarks.md
#: ("Volumetric"), in fewer iterations. Cotangent weights suffer from unoptimised slivers
DEFAULT_VOLUME_WEIGHTS = "tet-volume"
_TET_EDGES = ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3))
#: file formats of :func:`save_volume` (meshio's names)
VOLUME_FORMATS = {".vtu": "vtu", ".msh": "gmsh", ".vtk": "vtk", ".mesh": "medit"}
#: the mesher's target edge length is at least this many envelopes (see tetrahedralise)
MIN_EDGE_OVER_ENVELOPE = 4.0
#: and at least this fraction of the bounding-box diagonal (see tetrahedralise)
COARSE_TARGET = 0.12
#: at density 1 the interior lattice is never finer than the bounding-box diagonal over
#: this (20 kept less volume on the hand and elephant, 60 cost up to 3.5x per iteration for the
#: same results; docs/benchmarks.md, "Volumetric")
MAX_LATTICE_CELLS = 40
#: a finer lattice is refused (memory and time grow with its cube; density 1 seeds at most
#: 41^3, about 7e4)
MAX_LATTICE_POINTS = 5e6
#: lattice points are kept this many spacings away from the surface (closer ones would make
#: flat tets against it)
LATTICE_CLEARANCE = 0.5
MESHER_HINT = (
    "volumetric ARAP needs the optional tetrahedral mesher: pip install 'arapkit[volume]' "
    "(installs pytetwild)"
)


# -- the mesher ---------------------------------------------------------------------


def _ftetwild() -> str | None:
    """Path of fTetWild's compiled wrapper in the installed ``pytetwild``, or None.

    The wrapper is loaded by path in a child process (:data:`_CHILD`): ``pytetwild`` 0.4.2
    imports PyVista (a VTK stack) on package import only to register an accessor, without
    declaring it, and fTetWild can crash (segmentation fault) on some inputs, which must
    not take the caller down. ``find_spec`` locates the package without importing it.
    """
    spec = importlib.util.find_spec("pytetwild")
    if spec is None or not spec.submodule_search_locations:
        return None
    for folder in spec.submodule_search_locations:
        for f in sorted(glob.glob(os.path.join(folder, "PyfTetWildWrapper*"))):
            if f.endswith(tuple(importlib.machinery.EXTENSION_SUFFIXES)):
                return f
    return None


def have_mesher() -> bool:
    """Whether the optional tetrahedral mesher (``pytetwild``) is installed.

    Examples
    --------
    >>> isinstance(have_mesher(), bool)
    True
    """
    return _ftetwild() is not None


# The mesher's process: arrays in and out as .npz on stdin/stdout, fTetWild's own output off.
_CHILD = r"""
import importlib.machinery, importlib.util, io, os, sys
import numpy as np
so = sys.argv[1]
name = "pytetwild.PyfTetWildWrapper"
loader = importlib.machinery.ExtensionFileLoader(name, so)
W = importlib.util.module_from_spec(importlib.util.spec_from_file_location(name, so,
                                                                           loader=loader))
loader.exec_module(W)
a = np.load(io.BytesIO(sys.stdin.buffer.read()))
out = os.dup(1)
os.dup2(os.open(os.devnull, os.O_WRONLY), 1)
V, T = W.tetrahedralize_mesh(
    a["V"], a["F"], False, True, 0.05, float(a["ela"]), float(a["eps"]), 10.0, False,
    int(a["threads"]), 80, 6, True, False, False,
    np.empty((0, 3)), np.empty((0, 4), dtype=np.int32), np.empty(0))
buf = io.BytesIO()
np.savez(buf, V=np.asarray(V, dtype=np.float64), T=np.asarray(T, dtype=np.int64))
os.fdopen(out, "wb").write(buf.getvalue())
"""


def _children_cpu() -> float:
    """CPU seconds used by finished child processes (0 where the platform does not say)."""
    try:
        import resource

        ru = resource.getrusage(resource.RUSAGE_CHILDREN)
        return ru.ru_utime + ru.ru_stime
    except (ImportError, OSError):
        return 0.0


def _run_ftetwild(name: str, V: np.ndarray, F: np.ndarray, ela: float, eps: float,
                  threads: int) -> tuple[np.ndarray, np.ndarray]:
    """fTetWild without simplification or optimisation, in a child process."""
    import io
    import subprocess
    import sys
    import tempfile

    so = _ftetwild()
    if so is None:
        raise InputError(MESHER_HINT)
    buf = io.BytesIO()
    np.savez(buf, V=np.ascontiguousarray(V, dtype=np.float64),
             F=np.ascontiguousarray(F, dtype=np.uint32), ela=ela, eps=eps, threads=threads)
    before = _children_cpu()
    # fTetWild writes a debug file (__tracked_surface.stl) into its working folder
    with tempfile.TemporaryDirectory(prefix="arapkit-tetwild-") as scratch:
        proc = subprocess.run([sys.executable, "-c", _CHILD, so], input=buf.getvalue(),
                              capture_output=True, check=False, cwd=scratch)
    _run_ftetwild.cpu_seconds = _children_cpu() - before
    if proc.returncode != 0:
        why = (f"signal {-proc.returncode}" if proc.returncode < 0
               else (proc.stderr.decode(errors="replace").strip().splitlines() or ["?"])[-1])
        raise InputError(
            f"{name}: the tetrahedral mesher (fTetWild) failed on this surface ({why}); "
            "try another --interior-density, or deform without --volumetric"
        )
    out = np.load(io.BytesIO(proc.stdout))
    return out["V"], out["T"]


# -- checks and the tet mesh ------------------------------------------------------------


def check_closed(mesh: Mesh) -> None:
    """Refuse surfaces that do not bound a volume, with one line naming the problem.

    Examples
    --------
    >>> from arapkit import Mesh
    >>> try:
    ...     check_closed(Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], name="tri"))
    ... except InputError as e:
    ...     print(str(e)[:60])
    tri: volumetric ARAP needs a closed surface, but it has 1 bo
    """
    loops = mesh.boundary_loops
    if loops:
        n_edges = int(np.count_nonzero(mesh.edge_face_counts == 1))
        raise InputError(
            f"{mesh.name}: volumetric ARAP needs a closed surface, but it has {len(loops)} "
            f"boundary loop(s) ({n_edges} boundary edges); close the holes or deform "
            "without --volumetric"
        )
    if mesh.n_nonmanifold_edges:
        raise InputError(
            f"{mesh.name}: volumetric ARAP needs a watertight surface, but "
            f"{mesh.n_nonmanifold_edges} edge(s) have more than two faces; repair the mesh "
            "or deform without --volumetric"
        )
    bad = _misoriented_edge(mesh.faces)
    if bad is not None:
        raise InputError(
            f"{mesh.name}: volumetric ARAP needs consistently oriented faces, but the two "
            f"faces on edge {bad[0]}-{bad[1]} both run it in the same direction; orient the "
            "faces consistently (e.g. trimesh.repair.fix_winding) or deform without "
            "--volumetric"
        )


def _misoriented_edge(faces: np.ndarray) -> tuple[int, int] | None:
    """An edge that two faces traverse in the same direction, or None.

    On a closed, consistently oriented surface every directed edge occurs exactly once.

    Examples
    --------
    >>> import numpy as np
    >>> tet = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    >>> flipped = tet.copy()
    >>> flipped[3] = [1, 3, 2]
    >>> _misoriented_edge(tet) is None, _misoriented_edge(flipped)
    (True, (1, 3))
    """
    F = np.asarray(faces, dtype=np.int64)
    directed = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    uniq, counts = np.unique(directed, axis=0, return_counts=True)
    if (counts == 1).all():
        return None
    i, j = uniq[np.argmax(counts > 1)]
    return (int(min(i, j)), int(max(i, j)))


@dataclass
class TetMesh:
    """A tetrahedral mesh whose first ``n_surface`` vertices are a surface's vertices.

    Attributes
    ----------
    vertices : (N, 3) rest positions; rows ``[0, n_surface)`` equal the surface's vertices.
    tets : (T, 4) vertex indices, positively oriented.
    n_surface : number of surface vertices (the first rows).
    seconds : wall time the mesher took.
    cpu_seconds : CPU time the mesher's process used (all its threads).
    """

    vertices: np.ndarray
    tets: np.ndarray
    n_surface: int
    seconds: float = 0.0
    cpu_seconds: float = 0.0

    @property
    def n_vertices(self) -> int:
        """Number of vertices, surface and interior."""
        return len(self.vertices)

    def volumes(self, P: np.ndarray | None = None) -> np.ndarray:
        """Signed volume of every tet (at rest, or at positions ``P``)."""
        P = self.vertices if P is None else P
        a, b, c, d = (P[self.tets[:, i]] for i in range(4))
        return np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a) / 6.0


def tetrahedralise(mesh: Mesh, density: float = DEFAULT_DENSITY, threads: int = 0) -> TetMesh:
    """Fill a closed surface with tetrahedra, keeping every surface vertex exactly.

    Parameters
    ----------
    mesh : Mesh
        Closed (watertight) surface.
    density : float
        Spacing of the interior lattice in multiples of the surface's mean edge length, or
        of 1/40 of the bounding-box diagonal where that is larger (:func:`lattice_spacing`).
    threads : int
        Mesher threads (0 = all cores).

    Returns
    -------
    TetMesh

    Examples
    --------
    >>> from arapkit.mesh.shapes import bar
    >>> tm = tetrahedralise(bar(), density=2.0)      # doctest: +SKIP
    >>> bool((tm.vertices[:tm.n_surface] == bar().vertices).all())   # doctest: +SKIP
    True
    """
    check_closed(mesh)  # a surface that bounds no volume is refused with or without the mesher
    if _ftetwild() is None:
        raise InputError(MESHER_HINT)
    density = float(density)
    if not (np.isfinite(density) and density > 0):
        raise InputError(f"interior density must be a positive number, got {density!r}")
    V, E = mesh.vertices, mesh.edges
    mean_edge = float(np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1).mean())
    t0 = time.perf_counter()
    used = np.unique(mesh.faces)  # unreferenced vertices are no part of the volume
    remap = np.full(mesh.n_vertices, -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    diag = mesh.bounding_box_diagonal
    spacing = lattice_spacing(mean_edge, diag, density)
    # counted, not built: the lattice's axes at a tiny spacing would not fit in memory
    cells = float(np.prod(np.floor(np.ptp(V, axis=0) / spacing) + 1))
    if cells > MAX_LATTICE_POINTS:
        raise InputError(
            f"{mesh.name}: interior density {density:g} would seed {cells:.3g} lattice points "
            f"(at most {MAX_LATTICE_POINTS:.0e}); use a larger --interior-density"
        )
    seeds = interior_lattice(mesh, spacing)
    # The interior points come from the lattice. fTetWild's target edge length only places
    # its own background grid when it does not optimise, so it is kept coarse (a finer grid
    # mixed in with the lattice made the thick bar's bend lose 1.5 % instead of 1 %); and it
    # crashed (segmentation fault) when that target came within about 3x of its envelope
    ela = max(spacing, COARSE_TARGET * diag, MIN_EDGE_OVER_ENVELOPE * ENVELOPE * diag)
    faces = remap[mesh.faces]
    if mesh_volume(V, mesh.faces) < 0:  # inward-facing: fTetWild keeps what the faces enclose
        faces = faces[:, ::-1]
    # fTetWild's surface tree (an AABB tree over the faces in the order given) is only as
    # good as that order: bunny00's own face order made one of its passes take 25 s of the
    # 28; in Morton order the whole mesher takes 2.5 s, with the same tets
    faces = faces[np.argsort(morton_codes(V[mesh.faces].mean(axis=1)), kind="stable")]
    TV, TT = _run_ftetwild(mesh.name, np.concatenate([V[used], seeds]), faces, ela,
                           ENVELOPE, threads)
    seconds = time.perf_counter() - t0
    TV = np.asarray(TV, dtype=np.float64)
    TT = np.asarray(TT, dtype=np.int64)
    if len(TT) == 0:
        raise InputError(f"{mesh.name}: the tetrahedral mesher found no inside to fill")
    # lattice points outside the surface are in no tet: drop them
    kept = np.unique(TT)
    if len(kept) < len(TV):
        renum = np.full(len(TV), -1, dtype=np.int64)
        renum[kept] = np.arange(len(kept))
        TV, TT = TV[kept], renum[TT]
    tm = _renumber(mesh, used, TV, TT, seconds)
    tm.cpu_seconds = getattr(_run_ftetwild, "cpu_seconds", 0.0)
    return tm


def morton_codes(points: np.ndarray, bits: int = 10) -> np.ndarray:
    """Z-order (Morton) code of every point on a ``2**bits`` grid over their bounding box.

    Sorting by it puts points that are close in space close in the order.

    Examples
    --------
    >>> import numpy as np
    >>> morton_codes(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 1.0]]), bits=1).tolist()
    [0, 1, 2, 7]
    """
    P = np.asarray(points, dtype=np.float64)
    lo, span = P.min(axis=0), np.ptp(P, axis=0)
    q = (np.divide(P - lo, span, out=np.zeros_like(P), where=span > 0)
         * (2**bits - 1)).round().astype(np.uint64)
    code = np.zeros(len(P), dtype=np.uint64)
    for b in range(bits):
        for k in range(3):
            code |= ((q[:, k] >> np.uint64(b)) & np.uint64(1)) << np.uint64(3 * b + k)
    return code


def lattice_spacing(mean_edge: float, diagonal: float, density: float) -> float:
    """Spacing of the interior lattice: ``density`` x max(mean edge, diagonal / 40).

    The diagonal bound keeps the volume's size in check on finely tessellated surfaces
    (bunny00's mean edge is 1/200 of its diagonal); ``density`` scales the spacing in both
    regimes, so it is always a working knob (0.5: about 8x the interior points).

    Examples
    --------
    >>> lattice_spacing(0.1, 1.0, 1.0), lattice_spacing(0.001, 1.0, 1.0)
    (0.1, 0.025)
    >>> lattice_spacing(0.001, 1.0, 0.5)
    0.0125
    """
    return density * max(mean_edge, diagonal / MAX_LATTICE_CELLS)


def interior_lattice(mesh: Mesh, spacing: float, seed: int = 0) -> np.ndarray:
    """Seed points for the inside: a jittered cubic lattice, away from the surface.

    fTetWild keeps every input point in its Delaunay mesh, and without its optimisation adds
    almost none of its own, so these points *are* the interior (the report's "inner edges"
    then run between them and the surface instead of straight across the inside). Points
    closer than ``LATTICE_CLEARANCE * spacing`` to the surface (to within about 5 %: the
    surface is sampled at a quarter of that) are left out; points outside
    the surface are left in and end in no tet (the mesher's inside test, a winding number,
    is better than any we would add). The jitter (±5 % of the spacing, fixed seed) breaks
    the co-planarities between a lattice and a grid-like surface (the bars) that crashed
    fTetWild.

    Examples
    --------
    >>> from arapkit.mesh.shapes import bar
    >>> P = interior_lattice(bar(1.0, 1.0, 1.0, (4, 4, 4)), 0.25)  # the unit cube
    >>> len(P), bool((abs(P - [0.5, 0, 0]) < 0.3).all())         # 3 x 3 x 3 inside
    (27, True)
    """
    from scipy.spatial import cKDTree

    V = mesh.vertices
    lo, hi = V.min(axis=0), V.max(axis=0)
    axes = [np.arange(a + ((b - a) % spacing) / 2, b, spacing) for a, b in zip(lo, hi)]
    G = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    G += np.random.default_rng(seed).uniform(-0.05 * spacing, 0.05 * spacing, G.shape)
    clearance = LATTICE_CLEARANCE * spacing
    dist, _ = cKDTree(_surface_samples(mesh, clearance / 2)).query(
        G, distance_upper_bound=clearance)
    return G[np.isinf(dist)]


def _surface_samples(mesh: Mesh, step: float) -> np.ndarray:
    """Points on every face, no farther than about ``step`` from any point of the surface."""
    V, F = mesh.vertices, mesh.faces
    P = V[F]  # (m, 3, 3)
    longest = np.linalg.norm(P - np.roll(P, 1, axis=1), axis=2).max(axis=1)
    k = np.maximum(1, np.ceil(longest / step)).astype(np.int64)
    out = [V]
    for kk in np.unique(k):
        i, j = np.mgrid[0:kk + 1, 0:kk + 1]
        keep = i + j <= kk
        a, b = i[keep] / kk, j[keep] / kk  # barycentric grid of the triangle
        T = P[k == kk]
        out.append((T[:, None, 0] * (1 - a - b)[:, None] + T[:, None, 1] * a[:, None]
                    + T[:, None, 2] * b[:, None]).reshape(-1, 3))
    return np.concatenate(out)


def _renumber(mesh: Mesh, used: np.ndarray, TV: np.ndarray, TT: np.ndarray,
              seconds: float) -> TetMesh:
    """Put the surface's vertices first, in input order; refuse if one was not kept."""
    from scipy.spatial import cKDTree

    dist, idx = cKDTree(TV).query(mesh.vertices[used])
    lost = np.flatnonzero(dist != 0.0)
    if len(lost):
        v = used[lost[0]]
        raise InputError(
            f"{mesh.name}: the tetrahedral mesher moved vertex {v} (by {dist[lost[0]]:.3g}; "
            f"{len(lost)} vertices); is the surface self-intersecting or are vertices "
            "duplicated? Repair it or deform without --volumetric"
        )
    n = mesh.n_vertices
    new_of_old = np.full(len(TV), -1, dtype=np.int64)
    new_of_old[idx] = used
    interior = np.flatnonzero(new_of_old < 0)
    new_of_old[interior] = n + np.arange(len(interior))
    P = np.empty((n + len(interior), 3))
    P[:n] = mesh.vertices  # unreferenced surface vertices included, at rest
    P[new_of_old] = TV
    T = new_of_old[TT]
    tm = TetMesh(P, T, n, seconds)
    neg = tm.volumes() < 0
    T[neg] = T[neg][:, [1, 0, 2, 3]]  # fTetWild's orientation is the opposite of ours
    return tm


# -- the edge graph and its weights -------------------------------------------------------


def tet_cotangent_weights(V: np.ndarray, T: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Tetrahedral cotangent weight of every edge: ``-sum_t vol_t grad(phi_i) . grad(phi_j)``.

    This is the linear finite-element stiffness of the tet mesh and equals
    ``(1/6) sum_t l_kl cot theta_kl`` (theta_kl the dihedral angle at the opposite edge).
    Edges in no tet get 0; tet edges missing from ``edges`` are left out.

    Examples
    --------
    >>> import numpy as np
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    >>> E = np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]])
    >>> np.round(tet_cotangent_weights(V, np.array([[0, 1, 2, 3]]), E), 6).tolist()
    [0.166667, 0.166667, 0.166667, 0.0, 0.0, 0.0]
    """
    a = V[T[:, 0]]
    D = np.stack([V[T[:, 1]] - a, V[T[:, 2]] - a, V[T[:, 3]] - a], axis=1)  # (t, 3, 3)
    det = np.linalg.det(D)
    vol = np.abs(det) / 6.0
    ok = vol > 0
    G = np.zeros((len(T), 4, 3))
    # x = a + D^T (phi_1, phi_2, phi_3): the gradients are the rows of D^-T; phi_0 = 1 - sum
    G[ok, 1:] = np.linalg.inv(D[ok]).transpose(0, 2, 1)
    G[:, 0] = -G[:, 1:].sum(axis=1)
    pos = _tet_edge_positions(len(V), T, edges).ravel()
    val = np.stack([-vol * np.einsum("ij,ij->i", G[:, i], G[:, j]) for i, j in _TET_EDGES],
                   axis=1).ravel()
    return np.bincount(pos[pos >= 0], val[pos >= 0], minlength=len(edges))


def tet_volume_weights(V: np.ndarray, T: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Volume weight of every edge: ``sum_t vol_t / l_ij^2`` over the tets on edge ij.

    Positive by construction and as a spring's stiffness in a volume (``vol / l^2``
    has the cotangent weights' unit, length); a sliver tet adds almost nothing, where
    its cotangent weights would be huge or negative. Edges in no tet get 0; tet edges
    missing from ``edges`` (sorted rows, i < j) are left out.

    Examples
    --------
    >>> import numpy as np
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    >>> E = np.array([[0, 1], [1, 2]])
    >>> np.round(tet_volume_weights(V, np.array([[0, 1, 2, 3]]), E), 6).tolist()
    [0.166667, 0.083333]
    """
    a = V[T[:, 0]]
    vol = np.abs(np.einsum("ij,ij->i", np.cross(V[T[:, 1]] - a, V[T[:, 2]] - a),
                           V[T[:, 3]] - a)) / 6.0
    pos = _tet_edge_positions(len(V), T, edges).ravel()
    l2 = np.sum((V[edges[:, 0]] - V[edges[:, 1]]) ** 2, axis=1)
    w = np.bincount(pos[pos >= 0], np.repeat(vol, 6)[pos >= 0], minlength=len(edges))
    return w / l2


def _tet_edge_positions(n: int, T: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """(t, 6) index into ``edges`` (sorted, i < j) of the six edges of every tet; -1: absent."""
    keys = edges[:, 0].astype(np.int64) * n + edges[:, 1]
    k = np.stack([np.minimum(T[:, i], T[:, j]) * n + np.maximum(T[:, i], T[:, j])
                  for i, j in _TET_EDGES], axis=1)
    pos = np.minimum(np.searchsorted(keys, k), len(keys) - 1)
    return np.where(keys[pos] == k, pos, -1)




def volume_graph(surface: Mesh, tm: TetMesh,
                 weights: str = DEFAULT_VOLUME_WEIGHTS) -> tuple[Mesh, np.ndarray]:
    """The solver's view of the volume: a Mesh with the ARAP edge graph, and its weights.

    Returns
    -------
    graph : Mesh
        Vertices ``tm.vertices``; faces: the four faces of every tet and the surface's
        triangles, so its edges are the tet edges plus the surface edges.
    weights : (len(graph.edges),) float
        All > 0: ``"tet-volume"`` (:func:`tet_volume_weights`), ``"tet-cotan-clamped"``
        (:func:`tet_cotangent_weights` raised to ``CLAMP_FRACTION`` times their mean
        absolute value) or ``"uniform"``. Surface edges that are no tet edge (fTetWild split
        them) get the median tet-edge weight.
    """
    if weights not in VOLUME_WEIGHTS:
        raise InputError(f"unknown volume weights '{weights}' (choose one of "
                         f"{', '.join(VOLUME_WEIGHTS)})")
    T = tm.tets
    tri = np.concatenate([T[:, [0, 1, 2]], T[:, [0, 1, 3]], T[:, [0, 2, 3]], T[:, [1, 2, 3]],
                          surface.faces])
    graph = Mesh(tm.vertices, tri, name=surface.name)
    in_tet = np.zeros(len(graph.edges), dtype=bool)
    in_tet[_tet_edge_positions(tm.n_vertices, T, graph.edges).ravel()] = True  # all found
    if weights == "uniform":
        return graph, np.ones(len(graph.edges))
    if weights == "tet-volume":
        w = tet_volume_weights(tm.vertices, T, graph.edges)
    else:
        w = tet_cotangent_weights(tm.vertices, T, graph.edges)
    floor = CLAMP_FRACTION * max(float(np.mean(np.abs(w[in_tet]))), 1e-300)
    w = np.maximum(w, floor)
    w[~in_tet] = float(np.median(w[in_tet]))
    return graph, w


def extend_rings(rings, tm: TetMesh) -> np.ndarray:
    """Per-vertex r for every tet vertex: interior vertices take their nearest surface vertex's.

    Examples
    --------
    >>> import numpy as np
    >>> tm = TetMesh(np.array([[0, 0, 0], [1, 0, 0], [0.9, 0, 0.0]]), np.zeros((0, 4), int), 2)
    >>> extend_rings([1, 3], tm).tolist()
    [1, 3, 3]
    """
    from scipy.spatial import cKDTree

    n = tm.n_surface
    r = check_rings(rings, n)
    if tm.n_vertices == n:
        return r
    _, near = cKDTree(tm.vertices[:n]).query(tm.vertices[n:])
    return np.concatenate([r, r[near]])


def save_volume(path, vertices: np.ndarray, tets: np.ndarray) -> None:
    """Write a tet mesh (``.vtu``, ``.msh``, ... anything meshio writes), atomically.

    Examples
    --------
    >>> save_volume("out.vtu", tm.vertices, tm.tets)     # doctest: +SKIP
    """
    try:
        import meshio
    except ImportError:
        raise InputError(
            f"{path}: saving the volume needs meshio: pip install 'arapkit[volume]'"
        ) from None
    import contextlib
    import tempfile

    path = os.fspath(path)
    ext = os.path.splitext(path)[1].lower()
    fmt = VOLUME_FORMATS.get(ext)
    if fmt is None:
        raise InputError(f"{path}: unsupported volume format (use {', '.join(VOLUME_FORMATS)})")
    folder = os.path.dirname(path) or "."
    if not os.path.isdir(folder):
        raise InputError(f"{path}: folder {folder!r} does not exist")
    m = meshio.Mesh(np.asarray(vertices, dtype=np.float64),
                    [("tetra", np.asarray(tets, dtype=np.int64))])
    # meshio's XML writers want a file name: write beside the target, then move it over
    fd, tmp = tempfile.mkstemp(prefix=f".{os.path.basename(path)}.", suffix=ext, dir=folder)
    os.close(fd)
    try:
        meshio.write(tmp, m, file_format=fmt)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


# -- the deformer ---------------------------------------------------------------------------


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
        r per surface vertex; interior vertices take their nearest surface vertex's.
    density : float
        Interior lattice spacing (see :func:`tetrahedralise`).
    tet : TetMesh, optional
        A tetrahedralisation of ``mesh`` to reuse (from :func:`tetrahedralise`).
    **options
        ``tol``, ``max_iter``, ``init``, ``free_components``, ``accelerate``, ``history``,
        ``reorder``, ``device``: as for :class:`arapkit.Deformer`.

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
        self.mesh = mesh
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
        self._inner = Deformer(self.graph, handles, extend_rings(rings, tet),
                               weights=self.w, **options)
        self._graph_ms = 1e3 * (time.perf_counter() - t0)
        self.handles = handles

    @property
    def n(self) -> int:
        """Number of surface vertices."""
        return self.mesh.n_vertices

    @property
    def rings(self) -> np.ndarray:
        """r per surface vertex."""
        return self._inner.rings[: self.n]

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
        self._inner.set_rings(extend_rings(rings, self.tet))

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
        inner_ve = res._vertex_energy

        def vertex_energy() -> np.ndarray:
            ve = inner_ve() if callable(inner_ve) else inner_ve
            return ve[:n]

        timings = {"tetrahedralisation_ms": 1e3 * self.tet.seconds,
                   "graph_ms": self._graph_ms, **res.timings}
        return Result(res.vertices[:n], res.energy, res.history, res.iterations, res.converged,
                      res.rotations[:n], timings, vertex_energy)

    def save_volume(self, path) -> None:
        """Write the last solve's deformed tet mesh (or the rest one before any solve)."""
        P = getattr(self, "volume_vertices", self.tet.vertices)
        save_volume(path, P, self.tet.tets)
