"""Lumped vertex masses of a surface: its area shared among the vertices, times a density.

A surface's mass is ``density * area``, the density in mass per unit area (kg/m^2 when the
mesh is in metres). The mass matrix of a dynamics solve (:mod:`arapkit.arap.dynamics`) is
lumped: one mass per vertex, a diagonal matrix, so it adds to the global step's diagonal
and the factor keeps its sparsity. Two ways to share a triangle's area:

* ``"voronoi"`` (the default): the mixed Voronoi area of Meyer, Desbrun, Schröder and Barr
  (2003), :func:`arapkit.mesh.weights.voronoi_areas`. libigl's ``massmatrix`` default
  (``MASSMATRIX_TYPE_VORONOI``) and the area the cotangent Laplacian is normalised by, so
  the masses and the ARAP energy's weights discretise the same surface measure.
* ``"barycentric"``: a third of each triangle to each corner (libigl's
  ``MASSMATRIX_TYPE_BARYCENTRIC``). Positive on any non-degenerate triangle.

Both sum to the surface area; on a mesh without obtuse triangles they differ vertex by
vertex only.

Examples
--------
>>> from arapkit import Mesh
>>> m = Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
>>> vertex_masses(m, density=2.0, kind="barycentric").round(6).tolist()
[0.333333, 0.333333, 0.333333]
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..validate import number
from .model import Mesh
from .weights import voronoi_areas

__all__ = ["MASS_KINDS", "check_density", "vertex_masses"]

#: the ways to lump a triangle's area onto its corners (the first is the default)
MASS_KINDS = ("voronoi", "barycentric")


def check_density(value, what: str = "density") -> float:
    """A surface density: a finite number > 0 (mass per unit area).

    Examples
    --------
    >>> check_density("2.5")
    2.5
    """
    return number(value, what, lo=0.0, lo_open=True)


def vertex_masses(mesh: Mesh, density: float = 1.0, kind: str = "voronoi") -> np.ndarray:
    """Each vertex's lumped mass, ``density`` times its share of the area.

    Parameters
    ----------
    mesh : Mesh
    density : float
        Mass per unit area (> 0).
    kind : {"voronoi", "barycentric"}
        How a triangle's area is shared among its corners (see the module docstring).

    Returns
    -------
    (n,) float64, 0 for a vertex that no triangle uses.

    Examples
    --------
    >>> from arapkit.mesh.shapes import bar
    >>> m = bar()
    >>> a, b = vertex_masses(m), vertex_masses(m, kind="barycentric")
    >>> bool(np.isclose(a.sum(), b.sum()))  # both: the surface area
    True
    """
    density = check_density(density)
    if kind not in MASS_KINDS:
        raise InputError(f"unknown mass '{kind}' (use {' or '.join(MASS_KINDS)})")
    if kind == "voronoi":
        area = voronoi_areas(mesh)
    else:
        V, F = mesh.vertices, mesh.faces
        tri = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]),
                                   axis=1)
        area = np.bincount(F.ravel(), np.repeat(tri / 3.0, 3), minlength=mesh.n_vertices)
    return density * area
