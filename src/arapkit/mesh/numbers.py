"""The number range and scale rules every shape obeys: coordinates whose squares stay normal
doubles, an overflow-free extent and bounding-box diagonal, and unit-scale copies.

Examples
--------
>>> import numpy as np
>>> bounding_box_diagonal(np.array([[0.0, 0, 0], [3, 4, 0]]))
5.0
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError

__all__ = [
    "COORDINATE_RANGE",
    "bounding_box_diagonal",
    "check_number_range",
    "extent",
    "kernel_input",
    "normalised",
    "scale_free_vertices",
]

#: Coordinates (and the mesh's extent) inside ``[1/COORDINATE_RANGE, COORDINATE_RANGE]``
#: keep every squared length and area of the solver a normal double.
COORDINATE_RANGE = 1e150


def kernel_input(a, dtype) -> np.ndarray:
    """``a`` as a C-contiguous, read-only array of ``dtype`` (copied only where it must be).

    numba compiles one version of a kernel per argument type, and a read-only array is
    another type than a writable one: a mesh's own arrays are read-only, shapes the solver
    sends are not. Passing every input this way keeps one compiled version, which can then
    be loaded before it is needed.

    Examples
    --------
    >>> kernel_input([[0, 1, 2]], np.int64).flags.writeable
    False
    """
    out = np.ascontiguousarray(a, dtype=dtype).view()
    out.flags.writeable = False
    return out


def check_number_range(vertices: np.ndarray, name: str = "mesh") -> None:
    """Refuse coordinates whose squares would overflow or underflow a double.

    Loading and validation work at any finite scale (they normalise first), but the
    solver squares lengths: a coordinate beyond ``COORDINATE_RANGE`` (1e150) in size, or
    a mesh smaller than its inverse, is outside the numbers it can represent.

    Raises
    ------
    InputError
        Naming ``name``, the size found and the range.

    Examples
    --------
    >>> check_number_range(np.array([[0.0, 0, 0], [1e200, 0, 0]]), "big.off")
    Traceback (most recent call last):
    ...
    arapkit.errors.InputError: big.off: coordinates reach 1e+200, beyond the number range ...
    """
    V = np.asarray(vertices, dtype=np.float64)
    big = float(np.max(np.abs(V))) if V.size else 0.0
    size = float(np.max(extent(V))) if V.size else 0.0
    lo, hi = 1.0 / COORDINATE_RANGE, COORDINATE_RANGE
    rng = f"(sizes from {lo:.0e} to {hi:.0e}; squared lengths overflow above about 1e154)"
    if big > hi:
        raise InputError(
            f"{name}: coordinates reach {big:.3g}, beyond the number range arapkit "
            f"computes in {rng}; rescale the mesh"
        )
    if 0 < size < lo:
        raise InputError(
            f"{name}: the mesh is only {size:.3g} across, below the number range arapkit "
            f"computes in {rng}; rescale the mesh"
        )


def extent(vertices: np.ndarray) -> np.ndarray:
    """Per-axis extent (max - min) computed without overflow (ptp of ±1e308 is inf).

    Examples
    --------
    >>> extent(np.array([[-1e308, 0, 0], [1e307, 1, 0]])).tolist()
    [1.1e+308, 1.0, 0.0]
    """
    V = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    if len(V) == 0:
        return np.zeros(3)
    hi, lo = V.max(axis=0), V.min(axis=0)
    return 2.0 * (0.5 * hi - 0.5 * lo)


def scale_free_vertices(vertices: np.ndarray) -> np.ndarray:
    """The vertices moved and rescaled by powers of two to about unit size.

    Angles, cotangents and relative tolerances are the same as the input's, and no
    squared quantity over- or underflows, whatever the input's units.

    Examples
    --------
    >>> scale_free_vertices(np.array([[0.0, 0, 0], [3e200, 0, 0]])).tolist()
    [[0.0, 0.0, 0.0], [0.9798151324726952, 0.0, 0.0]]
    """
    return normalised(np.asarray(vertices, dtype=np.float64))[0]


def bounding_box_diagonal(vertices: np.ndarray) -> float:
    """Length of the bounding-box diagonal (a shape's scale), computed without overflow.

    The one definition of "the diagonal": :attr:`Mesh.bounding_box_diagonal`, weld
    tolerances, step tolerances and augmentation radii all use it.

    Examples
    --------
    >>> bounding_box_diagonal(np.array([[0.0, 0, 0], [3, 4, 0]]))
    5.0
    >>> bounding_box_diagonal(np.array([[0.0, 0, 0], [3e300, 4e300, 0]]))
    5e+300
    """
    W, factor = normalised(np.asarray(vertices, dtype=np.float64).reshape(-1, 3))
    return float(np.linalg.norm(np.ptp(W, axis=0))) * factor if len(W) else 0.0


def normalised(V: np.ndarray) -> tuple[np.ndarray, float]:
    """Coordinates rescaled by powers of two (exact) to about unit size, and the factor.

    The translation to the minimum corner keeps far-from-origin meshes accurate; all
    squared quantities of the result lie near 1, so no tolerance over- or underflows.
    """
    big = float(np.max(np.abs(V))) if V.size else 0.0
    if big == 0.0:
        return np.zeros_like(V), 1.0
    e1 = np.frexp(big)[1]
    W = np.ldexp(V, -e1)
    W = W - W.min(axis=0)
    ext = float(np.max(W))
    if ext == 0.0:
        return W, 1.0
    e2 = np.frexp(ext)[1]
    return np.ldexp(W, -e2), float(np.ldexp(1.0, e1 + e2))

