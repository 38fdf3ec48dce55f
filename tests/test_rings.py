"""r-ring neighbourhoods N(k, r), counted by hand on small regular meshes."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import independent_ring_edges

from arapkit import InputError, Mesh
from arapkit.arap.rings import build_neighbourhoods, check_rings
from arapkit.mesh.shapes import bar
from arapkit.mesh.weights import edge_weights


def lattice(n: int = 9) -> Mesh:
    """n x n grid, every quad split along the same diagonal: a triangular lattice."""
    ij = np.array([(i, j) for i in range(n) for j in range(n)], dtype=float)
    V = np.c_[ij + 0.5 * ij[:, [1]] * [1, 0], np.zeros(len(ij))]
    F = []
    for i in range(n - 1):
        for j in range(n - 1):
            a, b, c, d = i * n + j, (i + 1) * n + j, (i + 1) * n + j + 1, i * n + j + 1
            F += [[a, b, c], [a, c, d]]
    return Mesh(V, F, name="lattice")


def test_hand_counted_sizes_on_lattice():
    m = lattice(9)
    centre = 4 * 9 + 4
    assert m.adjacency[centre].nnz == 6
    sizes = {}
    for r in (1, 2, 3):
        nb = build_neighbourhoods(m, edge_weights(m, "uniform"), r)
        sizes[r] = len(nb.edges_of(centre))
    # r=1: the 6 spokes.
    # r=2: 6 spokes + 6 rim edges of the hexagon + 6 neighbours x 3 outward edges = 30.
    # r=3: the radius-2 hexagon (19 vertices) holds 42 edges (30 above + 12 on its rim),
    #      plus the edges leaving it: 6 corners x 3 + 6 side vertices x 2 = 30 -> 72.
    assert sizes == {1: 6, 2: 30, 3: 72}


def test_tetrahedron():
    V = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]
    m = Mesh(V, [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    nb1 = build_neighbourhoods(m, edge_weights(m), 1)
    nb2 = build_neighbourhoods(m, edge_weights(m), 2)
    assert nb1.sizes.tolist() == [3, 3, 3, 3]
    assert nb2.sizes.tolist() == [6, 6, 6, 6]
    assert nb1.edge_count.tolist() == [2] * 6  # each spoke belongs to its two ends
    assert nb2.edge_count.tolist() == [4] * 6


@pytest.mark.parametrize("r", [1, 2, 4])
def test_matches_independent_bfs_on_bar(r):
    m = bar(segments=(12, 2, 2))
    nb = build_neighbourhoods(m, edge_weights(m), r)
    for k in (0, 7, m.n_vertices // 2, m.n_vertices - 1):
        got = {tuple(e) for e in m.edges[nb.edges_of(k)].tolist()}
        assert got == independent_ring_edges(m, k, r)
        # layers: prefixes give the smaller rings
        for rr in range(1, r + 1):
            sub = {tuple(e) for e in m.edges[nb.edges_of(k, rr)].tolist()}
            assert sub == independent_ring_edges(m, k, rr)


def test_mixed_rings_and_coefficients():
    m = bar(segments=(10, 2, 2))
    rings = np.where(m.vertices[:, 0] > 3.5, 3, 1)
    w = edge_weights(m)
    nb = build_neighbourhoods(m, w, rings)
    assert nb.rings.tolist() == rings.tolist()
    P = m.vertices
    # c_kv definition: S_k = sum_e w e e^T must equal sum_v c_kv p_v^T
    for k in (0, m.n_vertices - 1):
        ids = nb.edges_of(k)
        e = P[m.edges[ids, 0]] - P[m.edges[ids, 1]]
        S_ref = (w[ids, None, None] * e[:, :, None] * e[:, None, :]).sum(0)
        s = slice(nb.disk_ptr[k], nb.disk_ptr[k + 1])
        S = nb.disk_coef[s].T @ P[nb.disk_idx[s]]
        assert np.allclose(S, S_ref, atol=1e-12)


def test_bad_rings():
    with pytest.raises(InputError, match="has 3 values but the mesh has 4"):
        check_rings([1, 2, 3], 4)
    with pytest.raises(InputError, match="vertex 1 has r = 0"):
        check_rings([1, 0, 2], 3)
    with pytest.raises(InputError, match="not an integer"):
        check_rings([1, 1.5, 2], 3)
