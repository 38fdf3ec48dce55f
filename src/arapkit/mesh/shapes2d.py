"""Built-in planar shapes: a strip (the 2D box bar) and its ends, for tests and benchmarks.

Examples
--------
>>> m = strip()
>>> m.n_vertices, m.n_faces, float(m.vertices[:, 2].max())
(451, 800, 0.0)
"""

from __future__ import annotations

import numpy as np

from .model import Mesh

__all__ = ["strip", "strip_ends"]


def strip(length: float = 4.0, width: float = 1.0,
          segments: tuple[int, int] = (40, 10)) -> Mesh:
    """A rectangle ``[0, length] x [-width/2, width/2]`` in the plane z = 0, each cell split
    along alternating diagonals (no preferred direction), counter-clockwise triangles.

    Examples
    --------
    >>> strip(segments=(2, 1)).faces.tolist()
    [[0, 1, 4], [0, 4, 3], [1, 2, 4], [2, 5, 4]]
    """
    nx, ny = segments
    xs = np.linspace(0.0, length, nx + 1)
    ys = np.linspace(-width / 2, width / 2, ny + 1)
    X, Y = np.meshgrid(xs, ys)
    V = np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], axis=1)
    F = []
    for j in range(ny):
        for i in range(nx):
            a = j * (nx + 1) + i
            b, c, d = a + 1, a + nx + 2, a + nx + 1
            F += [[a, b, c], [a, c, d]] if (i + j) % 2 == 0 else [[a, b, d], [b, c, d]]
    return Mesh(V, np.array(F), name="strip")


def strip_ends(mesh: Mesh, cells: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """The vertices of the first and last ``cells`` columns of a :func:`strip`.

    Examples
    --------
    >>> left, right = strip_ends(strip(segments=(4, 1)))
    >>> left.tolist(), right.tolist()
    ([0, 1, 5, 6], [3, 4, 8, 9])
    """
    x = mesh.vertices[:, 0]
    xs = np.unique(x)
    return (np.flatnonzero(x <= xs[cells] + 1e-12),
            np.flatnonzero(x >= xs[-1 - cells] - 1e-12))
