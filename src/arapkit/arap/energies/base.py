"""Energies of the local/global solver: one precomputed neighbourhood structure each.

Every local/global energy here has the form

    E(p', R) = sum_k sum_{e in N(k)} w_ke |(p'_i - p'_j) - R_k (p_i - p_j)|^2  [+ C(R)]

with a neighbourhood ``N(k)`` of edges for every vertex k and a weight ``w_ke`` for each
(k, e) pair. From that alone follow (see :mod:`arapkit.methods.deformer` for the derivation):

* the covariances ``S_k = sum_v c_kv p'_v^T`` and the right-hand side
  ``b_v = sum_k R_k c_kv``, with ``c_kv = sum_{e in N(k), e touches v} s_ev w_ke e_e``;
* the global matrix, the Laplacian of the edge weights ``D_e = sum_k w_ke``;
* the value ``sum_e D_e |e'|^2 + sum_e D_e |e|^2 - 2 sum_k tr(R_k S_k)``.

An energy is therefore data (:class:`NeighbourhoodEnergy`), not code: a backend runs the
same kernels for all of them. ``C(R)`` is an optional coupling between neighbouring
rotations, ``sum_k sum_j c_kj |R_k - R_j|_F^2`` (SR-ARAP), which adds ``c_kj R_j^T`` to
``S_k`` (with the neighbours' previous rotations) and a constant to the value.

Energies: ``rring`` (Chen et al. 2017, here), ``spokes-and-rims``
(:mod:`arapkit.arap.energies.spokes_rims`), ``sr-arap`` (:mod:`arapkit.arap.energies.sr_arap`).
Embedded deformation
(:mod:`arapkit.methods.embedded`) is not a local/global ARAP energy and has its own solver.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numba as nb
import numpy as np

from ...errors import InputError
from ..rings import Neighbourhoods, neighbourhoods_from_arrays

if TYPE_CHECKING:
    from ..problem import EdgeGraph

__all__ = ["CAPABILITIES", "ENERGIES", "INTERFACES", "LOCAL_GLOBAL", "VOLUMETRIC_INTERFACES",
           "Capabilities", "NeighbourhoodEnergy", "make_energy", "offered_by",
           "rring_energy"]

#: the ways to run a method: :class:`arapkit.Deformer`, ``arapkit deform``,
#: ``arapkit compare``, ``arapkit batch``, the editor's solver and
#: :class:`arapkit.torch.ARAPLayer`
INTERFACES = ("library", "deform", "compare", "batch", "editor", "torch")
#: the interfaces that offer volumetric ARAP (r-ring ARAP on the tetrahedralised inside)
VOLUMETRIC_INTERFACES = ("library", "deform", "compare", "editor")


@dataclass(frozen=True)
class Capabilities:
    """What one method can do and where it is offered; the interfaces read this table.

    Attributes
    ----------
    local_global : bool
        Solved by the local/global loop (:mod:`arapkit.arap.loop`); else it has its own solver.
    rigidity_map : bool
        Takes a per-vertex ring size r (``rings`` other than 1).
    accelerate : bool
        A descent method, so Anderson acceleration with its energy safeguard applies.
    volumetric : bool
        Also runs on the tetrahedralised inside (``volumetric=True``).
    handle_tol : float
        How far a handle may end from its target, relative to the bounding-box diagonal:
        0 for hard constraints (met to round-off), the soft constraints' residual bound
        otherwise.
    interfaces : tuple of str
        The :data:`INTERFACES` that offer the method.

    Examples
    --------
    >>> CAPABILITIES["rring"].rigidity_map, "torch" in CAPABILITIES["embedded"].interfaces
    (True, False)
    """

    local_global: bool
    rigidity_map: bool = False
    accelerate: bool = False
    volumetric: bool = False
    handle_tol: float = 0.0
    interfaces: tuple[str, ...] = INTERFACES


#: every method of ``Deformer(..., energy=...)`` and ``arapkit deform --energy``, the
#: default first. ``compare`` runs the paper's comparison set (no spokes-and-rims); the
#: torch layer needs a local/global method whose single step has a fixed point (not
#: SR-ARAP's Jacobi coupling). Embedded deformation's constraints are soft (weight 100):
#: the 2 % bound is the one its tests hold on every mesh (docs/methods.md).
CAPABILITIES: dict[str, Capabilities] = {
    "rring": Capabilities(local_global=True, rigidity_map=True, accelerate=True,
                          volumetric=True),
    "spokes-and-rims": Capabilities(
        local_global=True, accelerate=True,
        interfaces=tuple(i for i in INTERFACES if i != "compare")),
    "sr-arap": Capabilities(local_global=True,
                            interfaces=tuple(i for i in INTERFACES if i != "torch")),
    "embedded": Capabilities(local_global=False, handle_tol=2e-2,
                             interfaces=tuple(i for i in INTERFACES if i != "torch")),
}
#: every method of ``Deformer(..., energy=...)`` and ``arapkit deform --energy``
ENERGIES = tuple(CAPABILITIES)
#: those solved by the local/global loop
LOCAL_GLOBAL = tuple(name for name, c in CAPABILITIES.items() if c.local_global)


def offered_by(interface: str) -> tuple[str, ...]:
    """The methods an interface offers, in :data:`ENERGIES` order.

    Examples
    --------
    >>> offered_by("torch")
    ('rring', 'spokes-and-rims')
    """
    return tuple(name for name, c in CAPABILITIES.items() if interface in c.interfaces)


@dataclass(frozen=True, eq=False)
class NeighbourhoodEnergy:
    """Precomputed structure of one local/global energy (internal vertex numbering).

    Attributes
    ----------
    name : str
    nbh : Neighbourhoods
        ``N(k)`` as edge lists (``edge_ptr``, ``edge_idx``) and as disks with the
        coefficients ``c_kv`` (``disk_ptr``, ``disk_idx``, ``disk_coef``).
    entry_w : (nnz,) float64 or None
        ``w_ke`` for each entry of ``edge_idx``; None means ``w_ke = w_e`` (r-ring).
    system_w : (m,) float64
        ``D_e = sum_k w_ke``, the global step's Laplacian weights.
    rest_term : float
        ``sum_e D_e |e|^2`` plus the coupling's constant.
    coupling : (ptr, idx, coef) or None
        ``c_kj`` of the rotation coupling in CSR form.
    descent : bool
        Whether each step minimises the energy exactly (the energy then never rises).
    options : dict
        The energy's parameters, for reports.
    """

    name: str
    nbh: Neighbourhoods
    entry_w: np.ndarray | None
    system_w: np.ndarray
    rest_term: float
    coupling: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
    descent: bool = True
    options: dict[str, Any] = field(default_factory=dict)

    @property
    def rings(self) -> np.ndarray:
        """r per vertex (internal numbering); 1 for the non-r-ring energies."""
        return self.nbh.rings


@nb.njit(parallel=True, cache=True)
def _weighted_edge_norms(P, edges, dw):
    total = 0.0
    for e in nb.prange(edges.shape[0]):
        i, j = edges[e, 0], edges[e, 1]
        dx, dy, dz = P[i, 0] - P[j, 0], P[i, 1] - P[j, 1], P[i, 2] - P[j, 2]
        total += dw[e] * (dx * dx + dy * dy + dz * dz)
    return total


def rest_term(graph: EdgeGraph, system_w: np.ndarray) -> float:
    """``sum_e D_e |e|^2`` at rest."""
    return float(_weighted_edge_norms(graph.vertices, graph.edges, system_w))


def rring_energy(graph: EdgeGraph, w: np.ndarray, rings) -> NeighbourhoodEnergy:
    """r-ring ARAP (Chen et al. 2017, eq. 1): ``N(k, r_k)``, ``w_ke = w_e``.

    ``rings`` is in the graph's numbering (already checked).
    """
    nbh = neighbourhoods_from_arrays(graph.n_vertices, graph.edges, graph.vertices, w, rings,
                                     transpose=False)
    dw = nbh.edge_count * w
    return NeighbourhoodEnergy("rring", nbh, None, dw, rest_term(graph, dw))


def energy_from_entries(name: str, graph: EdgeGraph, k: np.ndarray, e: np.ndarray,
                        w_ke: np.ndarray, **kw) -> NeighbourhoodEnergy:
    """Build an energy from its (k, e, w_ke) triplets (repeated pairs are summed).

    Examples
    --------
    >>> import numpy as np
    >>> from arapkit.arap.problem import EdgeGraph
    >>> g = EdgeGraph(np.eye(3), np.array([[0, 1], [1, 2]]))
    >>> en = energy_from_entries("demo", g, np.array([0, 1, 1]), np.array([0, 0, 1]),
    ...                          np.ones(3))
    >>> en.system_w.tolist(), en.nbh.sizes.tolist()
    ([2.0, 1.0], [1, 2, 0])
    """
    n, E, P = graph.n_vertices, graph.edges, graph.vertices
    m = len(E)
    key, inv = np.unique(k.astype(np.int64) * m + e, return_inverse=True)
    wk = np.bincount(inv.ravel(), w_ke, len(key))
    kk, ee = key // m, key % m
    edge_ptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(kk, minlength=n), out=edge_ptr[1:])
    # disks: each entry touches both ends of its edge with opposite signs
    d = wk[:, None] * (P[E[ee, 0]] - P[E[ee, 1]])
    dk = np.concatenate([kk, kk])
    dv = np.concatenate([E[ee, 0], E[ee, 1]])
    dkey, dinv = np.unique(dk * n + dv, return_inverse=True)
    dinv = dinv.ravel()
    coef = np.stack([np.bincount(dinv, np.concatenate([d[:, a], -d[:, a]]), len(dkey))
                     for a in range(3)], axis=1)
    disk_ptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(dkey // n, minlength=n), out=disk_ptr[1:])
    system_w = np.bincount(ee, wk, m)
    nbh = Neighbourhoods(
        rings=np.ones(n, dtype=np.int32), edge_ptr=edge_ptr, edge_idx=ee.astype(np.int32),
        edge_layer=np.ones(len(ee), dtype=np.int8), disk_ptr=disk_ptr,
        disk_idx=(dkey % n).astype(np.int32), disk_coef=np.ascontiguousarray(coef),
        vdisk_ptr=None, vdisk_k=None, vdisk_coef=None,
        edge_count=np.bincount(ee, minlength=m),
    )
    return NeighbourhoodEnergy(name, nbh, wk, system_w, rest_term(graph, system_w), **kw)


def make_energy(name: str, graph: EdgeGraph, w: np.ndarray, weights_kind: str | None, *,
                rings=1, perm: np.ndarray | None = None, **options) -> NeighbourhoodEnergy:
    """Build the named local/global energy on ``graph`` (internal numbering).

    ``rings`` is a checked int32 array (:func:`arapkit.arap.rings.check_rings`) in the caller's
    numbering; ``perm`` (internal -> caller) maps it.
    """
    if name not in LOCAL_GLOBAL:
        raise InputError(f"unknown energy '{name}' (use one of {', '.join(ENERGIES)})")
    if name == "rring":
        if options:
            raise InputError(f"energy 'rring' takes no option {sorted(options)[0]!r}")
        r = np.asarray(rings, dtype=np.int32)
        return rring_energy(graph, w, r if perm is None else r[perm])
    if not np.all(np.asarray(rings) == 1):
        raise InputError(f"energy '{name}' has no rigidity map (rings must be 1)")
    if graph.faces is None:
        raise InputError(f"{graph.name}: energy '{name}' needs a triangle mesh")
    if name == "spokes-and-rims":
        from .spokes_rims import spokes_and_rims_energy

        if options:
            raise InputError(f"energy 'spokes-and-rims' takes no option {sorted(options)[0]!r}")
        return spokes_and_rims_energy(graph, w, weights_kind)
    from .sr_arap import check_roi, sr_arap_energy

    if options.get("roi") is not None:
        roi = check_roi(options["roi"], graph.n_vertices)
        options["roi"] = roi if perm is None else roi[perm]
    return sr_arap_energy(graph, w, **options)
