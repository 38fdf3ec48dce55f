"""Welding: solve on a triangle soup's shared vertices, answer in the input's own vertices.

A triangle soup (every face with its own three corners) or a file saved with split
vertices (per-face normals or UV seams exported as duplicated positions) falls apart
into thousands of components: each would be moved rigidly by its handles or held
fixed. :func:`weld` merges vertices closer than ``tol`` times the bounding-box diagonal
into one; the welded mesh remembers the map (``mesh.welded_from``), so results can be
written back to the input's vertices -- same count, same order -- with
:func:`to_source` or :func:`arapkit.io.writers.save_mesh` ``(..., like=welded)``.

Examples
--------
>>> import numpy as np
>>> from arapkit import Mesh
>>> soup = Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]],
...             [[0, 1, 2], [3, 4, 5]])
>>> w = weld(soup)
>>> w.n_vertices, soup.n_components, w.n_components
(4, 2, 1)
>>> w.welded_from.index.tolist()
[0, 1, 2, 1, 3, 2]
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from .model import Mesh, bounding_box_diagonal, scale_free_vertices
from .selection import HandleGroup, HandleSet

__all__ = ["WELD_TOL", "WeldMap", "soup_facts", "to_source", "weld", "weld_frame",
           "weld_handle_set", "weld_handles", "weld_values"]

#: Default weld distance, relative to the bounding-box diagonal. Far above the rounding
#: of coordinates written with 6+ significant digits (1e-7 of the diagonal is well
#: under a float32 ULP at the mesh's scale times a few), far below any real feature.
WELD_TOL = 1e-7


@dataclass(frozen=True)
class WeldMap:
    """How a welded mesh relates to the mesh it was made from.

    Attributes
    ----------
    source : Mesh
        The input mesh (with its file attributes).
    index : (n_source,) int64
        Welded vertex of every input vertex.
    tol : float
        Weld distance relative to the bounding-box diagonal.
    distance : float
        The absolute weld distance used (``tol`` times the diagonal).
    representative : (n_welded,) int64
        The first input vertex of every welded vertex (whose position it has).
    """

    source: Mesh
    index: np.ndarray
    tol: float
    distance: float
    representative: np.ndarray


def _clusters(V: np.ndarray, dist: float) -> np.ndarray:
    """Label of every vertex, equal for vertices chained by gaps <= ``dist``; labels in
    order of first appearance, so the welded order follows the input order."""
    if dist > 0:
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import connected_components
        from scipy.spatial import cKDTree

        pairs = cKDTree(V).query_pairs(dist, output_type="ndarray")
        n = len(V)
        g = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
        _, lab = connected_components(g, directed=False)
    else:
        _, lab = np.unique(V, axis=0, return_inverse=True)
        lab = lab.reshape(-1)
    # renumber by first occurrence
    _, first = np.unique(lab, return_index=True)
    order = np.argsort(first)
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    return rank[lab]


def _relative_clusters(V: np.ndarray, tol: float) -> np.ndarray:
    """:func:`_clusters` with a distance of ``tol`` times the bounding-box diagonal,
    found on coordinates rescaled to unit size (distances of a mesh at 1e200 or 1e-200
    would over- or underflow in the k-d tree)."""
    W = scale_free_vertices(V)
    return _clusters(W, tol * bounding_box_diagonal(W))


def weld(mesh: Mesh, tol: float | None = None) -> Mesh:
    """Merge vertices of ``mesh`` closer than ``tol`` times its bounding-box diagonal.

    Parameters
    ----------
    mesh : Mesh
    tol : float, optional
        Relative weld distance (default :data:`WELD_TOL` = 1e-7); 0 merges only exact
        duplicates. Vertices are merged transitively (a chain of close pairs becomes
        one vertex).

    Returns
    -------
    Mesh
        The welded mesh: each merged vertex sits at its first copy's position, faces that
        collapse are dropped (with a note), and ``welded.welded_from`` is a
        :class:`WeldMap` back to ``mesh``.

    Examples
    --------
    >>> from arapkit import Mesh
    >>> m = Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1e-9]], [[0, 1, 2], [3, 1, 2]])
    >>> weld(m).n_vertices
    3
    """
    tol = WELD_TOL if tol is None else float(tol)
    if not np.isfinite(tol) or tol < 0:
        raise InputError(f"{mesh.name}: weld tolerance must be a number >= 0, got {tol}")
    dist = tol * mesh.bounding_box_diagonal
    lab = _relative_clusters(mesh.vertices, tol)
    n_w = int(lab.max()) + 1
    first = np.full(n_w, len(lab), dtype=np.int64)
    np.minimum.at(first, lab, np.arange(len(lab)))
    welded = Mesh(mesh.vertices[first], lab[mesh.faces], name=mesh.name)
    welded.notes.insert(
        0,
        f"welded {mesh.n_vertices} vertices into {n_w} (distance <= {tol:g} of the "
        f"bounding-box diagonal); results are written to the input's {mesh.n_vertices}",
    )
    welded.welded_from = WeldMap(mesh, lab.astype(np.int64), tol, dist, first)
    return welded


def _map(mesh: Mesh) -> WeldMap:
    wf = getattr(mesh, "welded_from", None)
    if wf is None:
        raise ValueError(f"{mesh.name} is not a welded mesh "
                         "(make it with arapkit.mesh.welding.weld)")
    return wf


def to_source(mesh: Mesh, values: np.ndarray) -> np.ndarray:
    """Per-vertex ``values`` of a welded mesh, given to every input vertex (input order).

    A mesh that was not welded gets ``values`` back unchanged.

    Examples
    --------
    >>> from arapkit import Mesh
    >>> w = weld(Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 0, 0]], [[0, 1, 2], [3, 2, 0]]))
    >>> to_source(w, np.array([10, 11, 12])).tolist()
    [10, 11, 12, 11]
    """
    wf = getattr(mesh, "welded_from", None)
    return np.asarray(values) if wf is None else np.asarray(values)[wf.index]


def weld_values(mesh: Mesh, values: np.ndarray, reduce=np.maximum) -> np.ndarray:
    """Per-input-vertex ``values`` reduced onto the welded vertices (default: the largest).

    Used for per-vertex rigidity maps given on the input: a merged vertex takes the
    stiffest r of its copies.

    Examples
    --------
    >>> from arapkit import Mesh
    >>> w = weld(Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 0, 0]], [[0, 1, 2], [3, 2, 0]]))
    >>> weld_values(w, np.array([1, 2, 3, 6])).tolist()
    [1, 6, 3]
    """
    wf = _map(mesh)
    values = np.asarray(values)
    if len(values) != len(wf.index):
        raise InputError(
            f"{mesh.name}: {len(values)} values for {len(wf.index)} input vertices"
        )
    out = values[np.unique(wf.index, return_index=True)[1]].copy()
    reduce.at(out, wf.index, values)
    return out


def weld_handles(
    mesh: Mesh, indices: np.ndarray, targets: np.ndarray, what: str = "handles"
) -> tuple[np.ndarray, np.ndarray]:
    """Handle vertices given on the input, as welded vertices with one target each.

    Copies of one position selected together become one constrained vertex (their
    targets, equal up to the weld distance, are averaged). Copies sent to targets
    further apart than that cannot be one vertex: an :class:`InputError` says which.

    Parameters
    ----------
    mesh : Mesh
        A mesh made by :func:`weld`.
    indices : (k,) int
        Input vertex indices.
    targets : (k, 3) float
    what : str
        Names the handle source in messages (e.g. the handle file).

    Examples
    --------
    >>> from arapkit import Mesh
    >>> w = weld(Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 0, 0]], [[0, 1, 2], [3, 2, 0]]))
    >>> i, t = weld_handles(w, np.array([1, 3]), np.array([[2.0, 0, 0], [2, 0, 0]]))
    >>> i.tolist(), t.tolist()
    ([1], [[2.0, 0.0, 0.0]])
    """
    wf = _map(mesh)
    indices = np.asarray(indices, dtype=np.int64)
    targets = np.asarray(targets, dtype=np.float64).reshape(-1, 3)
    w = wf.index[indices]
    uniq, inv = np.unique(w, return_inverse=True)
    inv = inv.reshape(-1)
    mean = np.zeros((len(uniq), 3))
    np.add.at(mean, inv, targets)
    mean /= np.bincount(inv, minlength=len(uniq))[:, None]
    gap = np.linalg.norm(targets - mean[inv], axis=1)
    # rigid motions keep the copies' distance (<= the weld distance); allow scaling by 2
    limit = 4.0 * wf.distance + 1e-12 * mesh.bounding_box_diagonal
    if np.any(gap > limit):
        k = int(np.argmax(gap))
        others = indices[(inv == inv[k]) & (np.arange(len(inv)) != k)]
        raise InputError(
            f"{what}: input vertices {int(indices[k])} and {int(others[0])} were welded into "
            f"one vertex but have targets {2 * gap[k]:.3g} apart; give them the same target "
            "or weld with a smaller tolerance"
        )
    return uniq.astype(np.int64), mean


def weld_handle_set(mesh: Mesh, handle_set: HandleSet) -> HandleSet:
    """A :class:`~arapkit.mesh.selection.HandleSet` read on the input, on the welded vertices.

    For sets resolved by input vertex (``.sel`` statuses, explicit indices). A handle file
    with ``box``, ``sphere`` or ``nearest`` groups should be read with
    ``load_handles(path, vertices, welded=mesh)`` instead, so that those select welded
    vertices (``nearest`` on the input would count copies of one position).

    Each group is mapped with :func:`weld_handles`; a welded vertex claimed by several
    groups (through different copies) stays in the first, and copies with targets too
    far apart are refused.

    Examples
    --------
    >>> from arapkit import Mesh
    >>> from arapkit.io import parse_handles
    >>> m = Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 0, 0]], [[0, 1, 2], [3, 2, 0]])
    >>> hs = parse_handles([{"indices": [0]}, {"indices": [1, 3], "translate": [0, 0, 1]}],
    ...                    m.vertices)
    >>> weld_handle_set(weld(m), hs).indices.tolist()
    [0, 1]
    """
    weld_handles(mesh, handle_set.indices, handle_set.targets, what=handle_set.source)
    seen: set[int] = set()
    groups = []
    for g in handle_set.groups:
        idx, tgt = weld_handles(mesh, g.indices, g.targets, what=handle_set.source)
        keep = np.array([int(i) not in seen for i in idx], dtype=bool)
        seen.update(int(i) for i in idx)
        if keep.any():
            groups.append(HandleGroup(g.name, idx[keep], tgt[keep], g.kind))
    return HandleSet(groups, source=handle_set.source)


def weld_frame(mesh: Mesh, vertices: np.ndarray) -> np.ndarray:
    """Positions of another pose of the input (same vertices), on the welded vertices.

    Examples
    --------
    >>> from arapkit import Mesh
    >>> w = weld(Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 0, 0]], [[0, 1, 2], [3, 2, 0]]))
    >>> weld_frame(w, np.arange(12.0).reshape(4, 3))[:, 0].tolist()
    [0.0, 3.0, 6.0]
    """
    return np.asarray(vertices)[_map(mesh).representative]


def soup_facts(mesh: Mesh) -> dict[str, int]:
    """How soup-like a mesh is: small components and coincident vertices.

    Returns
    -------
    dict with ``triangle_components`` (components of exactly 3 vertices) and
    ``coincident_vertices`` (vertices that :func:`weld` with the default tolerance
    would merge away).

    Examples
    --------
    >>> from arapkit import Mesh
    >>> soup_facts(Mesh(np.eye(3), [[0, 1, 2]]))
    {'triangle_components': 1, 'coincident_vertices': 0}
    """
    sizes = np.bincount(mesh.component_labels)
    lab = _relative_clusters(mesh.vertices, WELD_TOL)
    return {
        "triangle_components": int(np.count_nonzero(sizes == 3)),
        "coincident_vertices": int(mesh.n_vertices - (lab.max() + 1)),
    }
