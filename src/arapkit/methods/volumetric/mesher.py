"""The tetrahedral mesher's driver (fTetWild in a child process) and the interior lattice.

:func:`run_mesher` runs fTetWild (``pytetwild``, MPL-2.0) without surface simplification or
optimisation in a child process; :func:`interior_lattice` seeds the inside with a jittered
cubic lattice (see :mod:`arapkit.methods.volumetric`).
"""

from __future__ import annotations

import glob
import importlib
import importlib.machinery
import importlib.util
import os

import numpy as np

from ...errors import InputError
from ...mesh.model import Mesh

__all__ = ["LATTICE_CLEARANCE", "MAX_LATTICE_CELLS", "MAX_LATTICE_POINTS", "MESHER_HINT",
           "find_mesher", "have_mesher", "interior_lattice", "lattice_spacing", "morton_codes",
           "run_mesher"]

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


def find_mesher() -> str | None:
    """Path of fTetWild's compiled wrapper in the installed ``pytetwild``, or None.

    The wrapper is loaded by path in a child process (``_CHILD``): ``pytetwild`` 0.4.2
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
    return find_mesher() is not None


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


def run_mesher(name: str, V: np.ndarray, F: np.ndarray, ela: float, eps: float,
               threads: int) -> tuple[np.ndarray, np.ndarray, float]:
    """fTetWild without simplification or optimisation, in a child process.

    Returns the tet vertices, the tets and the CPU seconds the mesher's process used.

    Examples
    --------
    >>> V, T, cpu = run_mesher("cube", V, F, 0.1, 1e-3, 0)   # doctest: +SKIP
    """
    import io
    import subprocess
    import sys
    import tempfile

    so = find_mesher()
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
    cpu_seconds = _children_cpu() - before
    if proc.returncode != 0:
        why = (f"signal {-proc.returncode}" if proc.returncode < 0
               else (proc.stderr.decode(errors="replace").strip().splitlines() or ["?"])[-1])
        raise InputError(
            f"{name}: the tetrahedral mesher (fTetWild) failed on this surface ({why}); "
            "try another --interior-density, or deform without --volumetric"
        )
    out = np.load(io.BytesIO(proc.stdout))
    return out["V"], out["T"], cpu_seconds


# -- the interior lattice ------------------------------------------------------------


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
