"""The precomputation's compiled kernels against independent definitions.

Cotangents from the angles themselves; the vertex adjacency, a mesh's unique edges and
its adjacency matrix from NumPy's and SciPy's sorts. No oracle library needed (the libigl
comparisons are in ``test_weights.py``).
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from arapkit import Mesh
from arapkit.arap.rings import vertex_adjacency
from arapkit.mesh.weights import COT_CAP, corner_cotangents


def _cot_by_angles(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """cot of each corner from its angle (arccos of the normalised dot product)."""
    out = np.empty(F.shape)
    for f, face in enumerate(F):
        for c in range(3):
            o, i, j = V[face[c]], V[face[(c + 1) % 3]], V[face[(c + 2) % 3]]
            a, b = (i - o) / np.linalg.norm(i - o), (j - o) / np.linalg.norm(j - o)
            out[f, c] = 1.0 / np.tan(np.arccos(np.clip(a @ b, -1.0, 1.0)))
    return out


@pytest.mark.parametrize("scale", [1e-200, 1e-160, 1.0, 1e150, 1e200])
def test_corner_cotangents_against_angles_at_every_scale(scale):
    # well-shaped random triangles: cot from the angle agrees to round-off, and the
    # power-of-two rescaling keeps the result the same far from 1
    rng = np.random.default_rng(3)
    V = rng.standard_normal((60, 3))
    F = np.array([rng.choice(60, 3, replace=False) for _ in range(80)])
    ref = _cot_by_angles(V, F)
    keep = np.abs(ref).max(axis=1) < 50  # leave out needles, where arccos loses digits
    got = corner_cotangents(V * scale, F)
    assert keep.sum() > 60
    np.testing.assert_allclose(got[keep], ref[keep], rtol=1e-9, atol=1e-9)


def test_corner_cotangents_degenerate_corners():
    V = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0], [np.nan, 0, 0]])
    got = corner_cotangents(V, np.array([[0, 1, 2], [0, 0, 3], [0, 1, 4]]))
    # collinear: the 180-degree corner is -cap, the two zero-angle corners +cap
    assert got[0].tolist() == [COT_CAP, -COT_CAP, COT_CAP]
    # a repeated vertex: 0/0 at its corners is 0; the third corner has a zero angle
    assert got[1].tolist() == [0.0, 0.0, COT_CAP]
    assert np.isnan(got[2]).all()  # NaN in, NaN out (the loaders refuse it earlier)


def _adjacency_by_sort(n: int, E: np.ndarray):
    """The definition: entries i -> j then j -> i, stably sorted by (vertex, neighbour)."""
    src = np.concatenate([E[:, 0], E[:, 1]])
    dst = np.concatenate([E[:, 1], E[:, 0]])
    eid = np.concatenate([np.arange(len(E)), np.arange(len(E))])
    order = np.lexsort((dst, src))
    ptr = np.concatenate([[0], np.cumsum(np.bincount(src, minlength=n))])
    return ptr, dst[order], eid[order]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_vertex_adjacency_is_the_stable_sort(seed):
    # repeated edges (ties keep the input order), isolated vertices, and one vertex of
    # valence > 32 (the rows that are merge-sorted rather than insertion-sorted)
    rng = np.random.default_rng(seed)
    E = rng.integers(0, 40, (400, 2))
    E[:60, 0] = 7
    E = np.concatenate([E, E[:25]])
    n = 45
    got = vertex_adjacency(n, E)
    want = _adjacency_by_sort(n, E)
    assert np.diff(got[0])[7] > 32
    for g, w in zip(got, want, strict=True):
        np.testing.assert_array_equal(g, w)
    assert got[1].dtype == np.int32 and got[2].dtype == np.int32


@pytest.mark.parametrize("seed", [0, 1])
def test_mesh_edges_are_the_unique_sorted_keys(seed):
    # faces over a few vertices share many edges; a vertex of high valence takes the
    # merge-sorted bucket
    rng = np.random.default_rng(seed)
    n = 30
    F = np.array([rng.choice(n, 3, replace=False) for _ in range(300)])
    F[:40, 0] = 5
    m = Mesh(rng.standard_normal((n, 3)), F)
    he = np.concatenate([m.faces[:, [0, 1]], m.faces[:, [1, 2]], m.faces[:, [2, 0]]])
    keys = he.min(axis=1) * n + he.max(axis=1)
    ukeys, inverse = np.unique(keys, return_inverse=True)
    np.testing.assert_array_equal(m.edges, np.stack([ukeys // n, ukeys % n], axis=1))
    np.testing.assert_array_equal(m.face_edges, inverse.reshape(3, -1).T)
    A = sp.coo_matrix((np.ones(len(m.edges)), tuple(m.edges.T)), shape=(n, n))
    want = (A + A.T).tocsr()
    got = m.adjacency
    assert got.has_sorted_indices
    np.testing.assert_array_equal(got.indptr, want.indptr)
    np.testing.assert_array_equal(got.indices, want.indices)
    np.testing.assert_array_equal(got.data, want.data)


@pytest.mark.parametrize("seed", [0, 1])
def test_mean_edge_length_is_the_mean_over_half_edges(seed):
    # every face's three edges, a shared edge once per face, a zero-length edge included
    rng = np.random.default_rng(seed)
    n = 40
    F = np.array([rng.choice(n, 3, replace=False) for _ in range(200)])
    F[:10] = F[10]
    V = rng.standard_normal((n, 3)) * [1.0, 10.0, 0.1]
    V[F[20, 1]] = V[F[20, 0]]  # a zero-length edge
    m = Mesh(V, F)
    F = m.faces  # as the mesh keeps them
    he = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    want = np.linalg.norm(V[he[:, 1]] - V[he[:, 0]], axis=1).mean()
    assert m.mean_edge_length == pytest.approx(want, rel=1e-13)
