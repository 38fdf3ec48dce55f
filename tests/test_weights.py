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


def test_bar_weights_positive():
    # a box of right isosceles triangles: every cotangent is 0 or 1
    w = edge_weights(bar(), "cotan")
    assert set(np.round(w, 12).tolist()) <= {0.0, 0.5, 1.0}
