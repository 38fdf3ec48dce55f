"""Shared-rotation groups (libigl's ``ARAPData.G``): one rotation for several neighbourhoods.

A group ``g`` of vertices uses one rotation ``R_g`` for all its members' neighbourhoods:

    E = sum_k sum_{e in N(k)} w_ke |e'_e - R_{g(k)} e_e|^2

(``g(k) = k`` outside any group). Since the energy is a sum over the entries (k, e), this
is the same energy as one neighbourhood per group holding every member's entries, and the
best ``R_g`` maximises ``tr(R_g sum_{k in g} S_k)``: libigl sums the members' covariances
the same way (its ``G_sum`` applied to ``CSM``). So the group is *pooled*: its first member
(in the solver's order) owns the union of the members' entries (a repeated (k, e) pair
summed), the other members own none, and every backend runs unchanged. The global matrix
is untouched (``D_e = sum_k w_ke`` keeps its value), so the factor is the ungrouped one.

What the pooling hides is put back by :class:`~arapkit.arap.grouped.GroupedBackend`: the
members' rotations (copies of the group's) and each member's own term of the energy
(:func:`owner_terms`).

Examples
--------
>>> from arapkit.arap.problem import ARAPProblem
>>> from arapkit.mesh.shapes import bar
>>> p = ARAPProblem.from_mesh(bar(segments=(6, 2, 2)), [0])
>>> g = np.full(p.n_vertices, -1); g[:10] = 0            # ten vertices share a rotation
>>> pooled = pool_rotations(p.energy, p.graph, p.w, g)
>>> int((pooled.nbh.sizes > 0).sum()) == p.n_vertices - 9, bool(
...     np.allclose(pooled.system_w, p.energy.system_w))
(True, True)
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from ..errors import InputError
from .energies.base import owner_rows
from .rings import Neighbourhoods

if TYPE_CHECKING:
    from .energies.base import NeighbourhoodEnergy
    from .graph import EdgeGraph

__all__ = ["entries", "owner_terms", "pool_rotations", "representatives"]


def representatives(group: np.ndarray) -> np.ndarray:
    """(n,) the owner whose rotation each vertex uses: the smallest vertex of its group,
    itself outside any group (``group`` is -1 there).

    Examples
    --------
    >>> representatives(np.array([-1, 1, 0, 1, 0])).tolist()
    [0, 1, 2, 1, 2]
    """
    group = np.asarray(group, dtype=np.int64)
    rep = np.arange(len(group), dtype=np.int64)
    inside = np.flatnonzero(group >= 0)
    if len(inside):
        k = int(group.max()) + 1
        first = np.full(k, len(group), dtype=np.int64)
        np.minimum.at(first, group[inside], inside)
        rep[inside] = first[group[inside]]
    return rep


def entries(energy: NeighbourhoodEnergy, w: np.ndarray) -> tuple[np.ndarray, ...]:
    """The energy's (k, e, w_ke) triplets, one per entry of its neighbourhoods."""
    nbh = energy.nbh
    k = np.repeat(np.arange(energy.n_owners, dtype=np.int64), np.diff(nbh.edge_ptr))
    e = nbh.edge_idx.astype(np.int64)
    wk = w[e] if energy.entry_w is None else energy.entry_w
    return k, e, np.asarray(wk, dtype=np.float64)


def pool_rotations(energy: NeighbourhoodEnergy, graph: EdgeGraph, w: np.ndarray,
                   group: np.ndarray, what: str = "groups") -> NeighbourhoodEnergy:
    """``energy`` with each group's neighbourhoods pooled into its first member's.

    Parameters
    ----------
    energy : NeighbourhoodEnergy
        One rotation per vertex, no rotation coupling.
    graph : EdgeGraph
        The graph the energy was built on (same numbering as ``group``).
    w : (m,) float
        Edge weights (an r-ring energy's entries weigh ``w_e``).
    group : (n,) int
        The shared-rotation group of each vertex, -1 for none.
    what : str
        Named in messages.

    Returns
    -------
    NeighbourhoodEnergy
        Same name, options, global weights and rest term; rows of non-first members empty.
    """
    n = graph.n_vertices
    if energy.n_owners != n:
        raise InputError(f"{what}: shared rotations need one rotation per vertex (this "
                         "energy has rotations of triangles too: a ring scale below 1)")
    if energy.coupling is not None:
        raise InputError(f"{what}: energy '{energy.name}' couples neighbouring rotations; "
                         "shared rotations are for the uncoupled energies")
    rep = representatives(group)
    k, e, wk = entries(energy, w)
    edge_ptr, ee, wkk, disk_ptr, disk_idx, coef = owner_rows(graph.vertices, graph.edges, n,
                                                            rep[k], e, wk)
    nbh = Neighbourhoods(
        rings=energy.nbh.rings, edge_ptr=edge_ptr, edge_idx=ee,
        # a pooled neighbourhood has no BFS layers of its own
        edge_layer=np.ones(len(ee), dtype=np.int8), disk_ptr=disk_ptr, disk_idx=disk_idx,
        disk_coef=coef, edge_count=np.bincount(ee, minlength=len(graph.edges)),
    )
    return replace(energy, nbh=nbh, entry_w=wkk)


def owner_terms(energy: NeighbourhoodEnergy, graph: EdgeGraph, w: np.ndarray, P: np.ndarray,
                R: np.ndarray, block: int = 1 << 20) -> np.ndarray:
    """Each owner's term ``sum_{e in N(k)} w_ke |e'_e - R_k e_e|^2`` of an (unpooled)
    energy, summed entry by entry (no cancellation), in blocks of ``block`` entries.

    Examples
    --------
    >>> from arapkit.arap.problem import ARAPProblem
    >>> from arapkit.mesh.shapes import bar
    >>> p = ARAPProblem.from_mesh(bar(segments=(6, 2, 2)), [0])
    >>> R = np.tile(np.eye(3), (p.n_vertices, 1, 1))
    >>> float(owner_terms(p.energy, p.graph, p.w, p.vertices * 1.5, R).sum()) > 0
    True
    """
    k, e, wk = entries(energy, w)
    E, P0 = graph.edges, graph.vertices
    out = np.zeros(energy.n_owners)
    for lo in range(0, len(k), block):
        s = slice(lo, lo + block)
        i, j = E[e[s], 0], E[e[s], 1]
        d = (P[i] - P[j]) - np.einsum("kab,kb->ka", R[k[s]], P0[i] - P0[j])
        out += np.bincount(k[s], wk[s] * np.einsum("ka,ka->k", d, d), len(out))
    return out
