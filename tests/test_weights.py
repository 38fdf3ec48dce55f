"""Edge weights and Voronoi areas against libigl (test-only oracle) and hand values."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import data_path

from arapkit import InputError, Mesh, load_mesh
from arapkit.mesh.shapes import bar
from arapkit.mesh.weights import edge_weights, voronoi_areas

igl = pytest.importorskip("igl", reason="libigl is the test oracle for weights")


@pytest.mark.parametrize("name", ["cow.off", "plane.off"])
def test_cotan_matches_libigl(name):
    m = load_mesh(data_path("meshes", name))
    L = igl.cotmatrix(m.vertices, m.faces).tocsr()
    E = m.edges
    ref = np.asarray(L[E[:, 0], E[:, 1]]).ravel()
    assert np.allclose(edge_weights(m, "cotan"), ref, rtol=1e-10, atol=1e-12)


def test_voronoi_matches_libigl():
    m = load_mesh(data_path("meshes", "elephant.off"))
    M = igl.massmatrix(m.vertices, m.faces, igl.MASSMATRIX_TYPE_VORONOI)
    assert np.allclose(voronoi_areas(m), M.diagonal(), rtol=1e-10)


def test_hand_values_right_triangle():
    m = Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    # angles: 90 at 0, 45 at 1 and 2 -> cot 0, 1, 1; edge (1,2) faces the right angle
    w = dict(zip(map(tuple, m.edges.tolist()), edge_weights(m, "cotan")))
    assert w[(1, 2)] == pytest.approx(0.0, abs=1e-15)
    assert w[(0, 1)] == pytest.approx(0.5) and w[(0, 2)] == pytest.approx(0.5)
    # right triangle: circumcentre on the hypotenuse; areas 1/4, 1/8, 1/8 (Meyer's mixed rule)
    assert np.allclose(voronoi_areas(m), [0.25, 0.125, 0.125])


def test_obtuse_clamped_and_uniform():
    V = [[0, 0, 0], [2, 0, 0], [1, 0.1, 0], [1, -0.1, 0]]
    m = Mesh(V, [[0, 1, 2], [1, 0, 3]])
    w = dict(zip(map(tuple, m.edges.tolist()), edge_weights(m, "cotan")))
    assert w[(0, 1)] < 0  # two very obtuse angles face the shared edge
    wc = edge_weights(m, "cotan-clamped")
    assert (wc > 0).all()
    assert (edge_weights(m, "uniform") == 1).all()
    with pytest.raises(InputError, match="unknown weights 'cot'"):
        edge_weights(m, "cot")


def brute_clamped_each(V, F) -> dict:
    """Per corner: the angle by arccos, max(cot, 0) / 2 added to the edge it faces."""
    w = {}
    for f in F:
        for c in range(3):
            k, i, j = f[c], f[(c + 1) % 3], f[(c + 2) % 3]
            a, b = V[i] - V[k], V[j] - V[k]
            angle = np.arccos(a @ b / np.linalg.norm(a) / np.linalg.norm(b))
            key = (min(i, j), max(i, j))
            w[key] = w.get(key, 0.0) + 0.5 * max(1.0 / np.tan(angle), 0.0)
    return w


def test_cotan_clamped_each_brute_force():
    # a jittered, sheared open grid: obtuse corners, edges facing two obtuse angles, boundary
    rng = np.random.default_rng(3)
    g = np.stack(np.meshgrid(np.arange(6.0), np.arange(5.0), indexing="ij"), -1).reshape(-1, 2)
    V = np.column_stack([g[:, 0] + 0.9 * g[:, 1], g[:, 1], 0.2 * rng.standard_normal(len(g))])
    V[:, :2] += 0.15 * rng.standard_normal((len(g), 2))
    idx = np.arange(30).reshape(6, 5)
    lo, hi = idx[:-1, :-1].ravel(), idx[1:, 1:].ravel()
    F = np.concatenate([np.column_stack([lo, idx[1:, :-1].ravel(), hi]),
                        np.column_stack([lo, hi, idx[:-1, 1:].ravel()])])
    m = Mesh(V, F)
    ref = brute_clamped_each(m.vertices, m.faces)
    got = edge_weights(m, "cotan-clamped-each")
    want = np.array([ref[tuple(e)] for e in m.edges.tolist()])
    assert np.allclose(got, want, rtol=1e-12, atol=1e-14)
    raw = edge_weights(m, "cotan")
    both_obtuse = want == 0
    assert both_obtuse.sum() >= 2 and (raw < 0).sum() > both_obtuse.sum()
    # it differs from clamping the sum: cotan-clamped keeps a mixed edge's negative part
    assert np.abs(edge_weights(m, "cotan-clamped") - want).max() > 1e-2


def test_bar_weights_positive():
    # a box of right isosceles triangles: every cotangent is 0 or 1
    w = edge_weights(bar(), "cotan")
    assert set(np.round(w, 12).tolist()) <= {0.0, 0.5, 1.0}
