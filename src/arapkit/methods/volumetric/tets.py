"""The tet mesh of a closed surface: checks, :func:`tetrahedralise`, :func:`save_volume`.

The first ``n`` vertices of a :class:`TetMesh` are the surface's, at exactly their input
positions (see :mod:`arapkit.methods.volumetric`).
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass

import numpy as np

from ...errors import InputError
from ...mesh.model import Mesh
from ...mesh.quality import enclosed_volume as mesh_volume
from .mesher import (
    MAX_LATTICE_POINTS,
    MESHER_HINT,
    have_mesher,
    interior_lattice,
    lattice_spacing,
    morton_codes,
    run_mesher,
)

__all__ = ["COARSE_TARGET", "DEFAULT_DENSITY", "ENVELOPE", "MIN_EDGE_OVER_ENVELOPE",
           "VOLUME_FORMATS", "TetMesh", "check_closed", "save_volume", "tetrahedralise"]

#: spacing of the interior lattice, in multiples of the surface's mean edge length (or of
#: 1/40 of the bounding-box diagonal where that is larger; see lattice_spacing)
DEFAULT_DENSITY = 1.0
#: fTetWild's envelope, relative to the bounding-box diagonal (fTetWild's own default). The
#: surface is inserted without simplification and every input vertex is kept exactly whatever
#: the envelope, but where fTetWild cannot insert a triangle exactly it accepts one within the
#: envelope: at 3e-2 the hand's tets held 0.24 % more volume than its surface, at 1e-3
#: 0.006 %, in the same time
ENVELOPE = 1e-3
#: file formats of :func:`save_volume` (meshio's names)
VOLUME_FORMATS = {".vtu": "vtu", ".msh": "gmsh", ".vtk": "vtk", ".mesh": "medit"}
#: the mesher's target edge length is at least this many envelopes (see tetrahedralise)
MIN_EDGE_OVER_ENVELOPE = 4.0
#: and at least this fraction of the bounding-box diagonal (see tetrahedralise)
COARSE_TARGET = 0.12


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
    if not have_mesher():
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
    TV, TT, cpu_seconds = run_mesher(mesh.name, np.concatenate([V[used], seeds]), faces,
                                     ela, ENVELOPE, threads)
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
    tm.cpu_seconds = cpu_seconds
    return tm


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
