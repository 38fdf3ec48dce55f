"""Learn a per-vertex rigidity map r_k from a set of deforming shapes (Chen et al. 2017, 3.4).

For every vertex ``k``, ring size ``r`` in ``[r_min, r_max]`` and example ``m`` (every shape
but the reference)::

    E(k, r, m) = sum_{(i,j) in N(k,r)} w_ij |(p_i^m - p_j^m) - R_k (p_i^1 - p_j^1)|^2

with ``R_k`` the best rotation for that neighbourhood, example and ``r``. It is normalised by
``A(k, r)``, the summed mixed Voronoi areas (on the reference) of the vertices of ``N(k, r)``
(those at graph distance <= r from k), averaged over the examples into ``E_ARAP(k, r)``, and

    r_k = argmin_r  E_ARAP(k, r) + omega (r_max - r).

The neighbourhoods come from one breadth-first search to ``r_max``
(:func:`arapkit.arap.rings.build_neighbourhoods`): ``N(k, r)`` is the prefix of ``N(k, r_max)``
whose entries have layer <= r, so one pass over each neighbourhood accumulates the
covariance of every r. The compiled kernel fits the rotations with
:func:`arapkit.arap.rotations.rotation_from_covariance`, the deformation engine's own kernel.

The steps live in their own modules: the energy table (:mod:`arapkit.learn.energies`),
the choice of omega and r (:mod:`arapkit.learn.selection`) and learning from several
sequences (:mod:`arapkit.learn.sequences`); their names are importable from here too.

Examples
--------
>>> import numpy as np
>>> from arapkit.mesh.shapes import bar
>>> mesh = bar()
>>> moved = mesh.vertices @ np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]]).T  # a rigid turn
>>> res = learn_rings(mesh, [moved], r_max=4)
>>> int(res.rings.min()), res.energies.shape == (mesh.n_vertices, 4)
(4, True)
"""

from __future__ import annotations

import time
from collections.abc import Sequence

import numpy as np

from ..mesh.model import Mesh, as_mesh
from ..mesh.weights import DEFAULT_WEIGHTS, edge_weights
from .energies import (
    EXAMPLE_BYTES,
    as_examples,
    check_ring_range,
    energy_tables,
    identical_examples,
    ring_energies,
)
from .selection import (
    AUTO_FLOOR,
    PAPER_OMEGA,
    LearnedRings,
    auto_omega,
    choose_rings,
    resolve_omega,
    select_rings,
)
from .sequences import combine_energies, learn_rings_sequences

__all__ = [
    "AUTO_FLOOR",
    "EXAMPLE_BYTES",
    "PAPER_OMEGA",
    "LearnedRings",
    "auto_omega",
    "combine_energies",
    "learn_rings",
    "learn_rings_sequences",
    "ring_energies",
    "rings_figure",
    "select_rings",
]


def learn_rings(
    reference: Mesh,
    examples,
    r_min: int = 1,
    r_max: int = 6,
    omega: float | str = PAPER_OMEGA,
    weights: str = DEFAULT_WEIGHTS,
) -> LearnedRings:
    """Learn a per-vertex ring size from example shapes (Chen et al. 2017, sec. 3.4).

    Parameters
    ----------
    reference : Mesh
        The reference shape; the learned map is for its vertices.
    examples : (M, n, 3) array, or sequence of (n, 3) arrays or Meshes
        The other shapes (M >= 1), with the reference's vertex order.
    r_min, r_max : int
        Range of ring sizes (paper: 1 and 6).
    omega : float or "auto"
        Weight of the rigidity preference ``r_max - r``. The paper uses 0.3; ``"auto"`` takes
        the mean energy increment per added ring (:func:`auto_omega`).
    weights : str
        Edge weights (:func:`arapkit.mesh.weights.edge_weights`), cotangent as in the paper.

    Returns
    -------
    LearnedRings

    Raises
    ------
    InputError
        No examples, mismatched vertex counts or faces, bad r range or omega.

    Warns
    -----
    UserWarning
        When some examples are identical to the reference.

    Examples
    --------
    >>> import numpy as np
    >>> from arapkit.mesh.shapes import bar
    >>> mesh = bar()
    >>> res = learn_rings(mesh, [mesh.vertices * [1.0, 1.0, 1.3]], r_max=3, omega="auto")
    >>> res.omega_rule, sorted(res.histogram()) == [1, 2, 3]
    ('auto', True)
    """
    t0 = time.perf_counter()
    r_min, r_max = check_ring_range(r_min, r_max)
    resolve_omega(omega, np.zeros((1, 1)))  # reject a bad omega before the work
    reference = as_mesh(reference, "reference")
    P = as_examples(reference, examples)
    identical = identical_examples(reference, P)
    timings: dict = {}
    energies, areas, _ = energy_tables(reference, P, edge_weights(reference, weights), r_min,
                                       r_max, timings=timings)
    timings["total_s"] = time.perf_counter() - t0
    return choose_rings(energies, areas, omega, r_min, r_max, len(P), identical, timings)


def rings_figure(
    vertices: np.ndarray,
    faces: np.ndarray,
    rings: np.ndarray,
    r_min: int = 1,
    r_max: int = 6,
    title: str | None = None,
    views: Sequence[str] = ("front", "back"),
    up: str | None = None,
):
    """Figure of a shape coloured by ring size: :func:`arapkit.plots.figures.rings_figure`.

    The plotting stack is imported only when a figure is drawn: learning needs none.

    Examples
    --------
    >>> from arapkit.mesh.shapes import bar
    >>> m = bar()
    >>> len(rings_figure(m.vertices, m.faces, [3] * m.n_vertices).axes)  # 2 views + colour bar
    3
    """
    from ..plots.figures import rings_figure as _figure

    return _figure(vertices, faces, rings, r_min, r_max, title=title, views=views, up=up)
