"""The volume's edge graph for the solver and its weights, and r extended inwards.

The ARAP edge graph is the tet edges plus the input surface edges; every weighting here is
positive, so the rest shape is an exact minimum (see :mod:`arapkit.methods.volumetric`).
"""

from __future__ import annotations

import numpy as np

from ...arap.rings import check_rings, neighbourhoods_from_arrays
from ...errors import InputError
from ...mesh.model import Mesh
from .tets import TetMesh

__all__ = ["CLAMP_FRACTION", "DEFAULT_VOLUME_WEIGHTS", "VOLUME_WEIGHTS", "extend_rings",
           "nearest_surface_vertex", "tet_cotangent_weights", "tet_volume_weights",
           "volume_graph", "volume_rings"]

#: weights below this fraction of the mean absolute weight are raised to it
CLAMP_FRACTION = 1e-3
#: positive weightings of the volume's edge graph (see :func:`volume_graph`)
VOLUME_WEIGHTS = ("uniform", "tet-volume", "tet-cotan-clamped")
#: a stiffness per unit volume, so the sparse interior counts as much as the densely
#: tessellated skin (uniform weights make the skin the stiffer, the finer it is); it kept
#: more volume than uniform on the twists and strained bends of docs/benchmarks.md
#: ("Volumetric"), in fewer iterations. Cotangent weights suffer from unoptimised slivers
DEFAULT_VOLUME_WEIGHTS = "tet-volume"
_TET_EDGES = ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3))


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


def nearest_surface_vertex(tm: TetMesh) -> np.ndarray:
    """For every tet vertex, the surface vertex nearest to it at rest (itself on the surface).

    Examples
    --------
    >>> import numpy as np
    >>> tm = TetMesh(np.array([[0, 0, 0], [1, 0, 0], [0.9, 0, 0.0]]), np.zeros((0, 4), int), 2)
    >>> nearest_surface_vertex(tm).tolist()
    [0, 1, 1]
    """
    from scipy.spatial import cKDTree

    n = tm.n_surface
    if tm.n_vertices == n:
        return np.arange(n)
    _, near = cKDTree(tm.vertices[:n]).query(tm.vertices[n:])
    return np.concatenate([np.arange(n), near])


def extend_rings(rings, tm: TetMesh) -> np.ndarray:
    """Per-vertex r for every tet vertex: interior vertices take their nearest surface vertex's.

    Examples
    --------
    >>> import numpy as np
    >>> tm = TetMesh(np.array([[0, 0, 0], [1, 0, 0], [0.9, 0, 0.0]]), np.zeros((0, 4), int), 2)
    >>> extend_rings([1, 3], tm).tolist()
    [1, 3, 3]
    """
    return check_rings(rings, tm.n_surface)[nearest_surface_vertex(tm)]


def volume_rings(rings, surface: Mesh, graph: Mesh, tm: TetMesh) -> np.ndarray:
    """Per-vertex r on the volume's edge graph that couples the skin the surface's r-ring does.

    The paper's ``N(k, r)`` on the surface fits one rotation to the skin within r edges of
    k. On the volume's graph, r edges from k through the interior reach skin much farther
    along the surface (across a limb, whose far side is half a perimeter away on the
    surface and a few tet edges away through it), so the same r is a far stiffer
    neighbourhood: one rotation over a whole cross-section, which a twist or a bend can only
    satisfy by thinning the limb. Here a surface vertex k gets the largest ``r' <= r_k``
    whose volume ring reaches only surface vertices of its surface ring ``N(k, r_k)``
    (at least 1: the tet spokes). An interior vertex i takes the r' of its nearest surface
    vertex s, held to the same rule: lowered until its volume ring reaches only skin of
    ``N(s, r_s)``. Taking s's r' unchecked gave the inside of a limb rings over its whole
    cross-section (on the thick bar at r = 3, 99 of 207 interior vertices), the over-stiff
    core the rule exists to avoid.

    Parameters
    ----------
    rings : int or (n,) int
        r per surface vertex.
    surface : Mesh
        The closed surface (its vertices are the first ``n`` of ``graph``).
    graph : Mesh
        The volume's edge graph (:func:`volume_graph`).
    tm : TetMesh
        The tetrahedralisation ``graph`` was made from.

    Examples
    --------
    >>> import numpy as np
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0], [0.2, 0.2, 0.2]])
    >>> F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    >>> T = np.array([[0, 1, 2, 4], [0, 1, 3, 4], [0, 2, 3, 4], [1, 2, 3, 4]])
    >>> s, tm = Mesh(V[:4], F), TetMesh(V, T, 4)
    >>> volume_rings(2, s, volume_graph(s, tm)[0], tm).tolist()
    [2, 2, 2, 2, 2]
    """
    n = tm.n_surface
    r = check_rings(rings, n)
    N = graph.n_vertices
    out = np.ones(N, dtype=np.int32)
    if r.max() > 1:
        near = nearest_surface_vertex(tm)
        cap = r[near]
        k, v = _disks(surface, r)
        allowed = np.unique(k * N + v)  # (surface vertex s, skin of N(s, r_s))
        for j in range(2, int(r.max()) + 1):  # the volume ring of k grows with j
            rj = np.where(cap >= j, j, 1).astype(np.int32)
            k, v = _disks(graph, rj)
            skin = v < n
            k, v = k[skin], v[skin]
            beyond = np.unique(k[~np.isin(near[k] * N + v, allowed)])
            ok = cap >= j
            ok[beyond] = False
            out[ok] = j
        # and never above the r' of the skin it lies under: deep inside a thick part a ring
        # reaches less skin, so the check alone would make the core stiffer than its skin
        out[n:] = np.minimum(out[n:], out[near[n:]])
    return out


def _disks(mesh: Mesh, rings: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(owner k, vertex v) pairs: v is within ``rings[k]`` edges of k."""
    E = mesh.edges
    nbh = neighbourhoods_from_arrays(mesh.n_vertices, E, mesh.vertices, np.ones(len(E)), rings,
                                     name=mesh.name)
    owner = np.repeat(np.arange(mesh.n_vertices, dtype=np.int64), np.diff(nbh.disk_ptr))
    return owner, nbh.disk_idx.astype(np.int64)
