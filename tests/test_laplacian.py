"""Laplacian surface editing: operator rows, hard and soft constraints."""

from __future__ import annotations

import numpy as np
import pytest

from arapkit import LaplacianEditor, laplacian_edit
from arapkit.mesh.shapes import bar, bar_bend
from arapkit.mesh.weights import cotangent_weights, voronoi_areas
from arapkit.methods.laplacian import differential_operator


@pytest.fixture(scope="module")
def setup():
    m = bar(length=3.0, segments=(15, 2, 2))
    h, t = bar_bend(m, 60)
    return m, h, t


def test_uniform_rows_by_hand(setup):
    m, _, _ = setup
    L = differential_operator(m, "uniform")
    P = m.vertices
    for i in (0, 17, m.n_vertices - 1):
        nbrs = {j for e in m.edges.tolist() if i in e for j in e if j != i}
        expect = P[i] - P[sorted(nbrs)].mean(axis=0)
        assert np.allclose((L @ P)[i], expect)


def test_cotan_rows(setup):
    m, _, _ = setup
    L = differential_operator(m, "cotan")
    w = cotangent_weights(m)
    A = voronoi_areas(m)
    P = m.vertices
    i = 20
    acc = sum(w[e] * (P[i] - P[a + b - i]) for e, (a, b) in enumerate(m.edges.tolist())
              if i in (a, b))
    assert np.allclose((L @ P)[i], acc / A[i])


@pytest.mark.parametrize("weights", ["uniform", "cotan"])
def test_hard_constraints_solve_least_squares(setup, weights):
    m, h, t = setup
    q = laplacian_edit(m, h, t, weights=weights)
    assert np.array_equal(q[h], t)
    # independent: dense least squares over the free vertices
    L = differential_operator(m, weights).toarray()
    delta = L @ m.vertices
    free = np.setdiff1d(np.arange(m.n_vertices), h)
    rhs = delta - L[:, h] @ t
    ref = np.linalg.lstsq(L[:, free], rhs, rcond=None)[0]
    assert np.allclose(q[free], ref, atol=1e-8)


def test_soft_constraints_approach_hard(setup):
    m, h, t = setup
    hard = LaplacianEditor(m, h, "uniform").solve(t)
    errs = []
    for omega in (1.0, 10.0, 1000.0):
        q = LaplacianEditor(m, h, "uniform", omega=omega).solve(t)
        errs.append(np.abs(q[h] - t).max())
        # independent: stacked least squares [L; omega*C] q = [delta; omega*c]
        if omega == 10.0:
            L = differential_operator(m, "uniform").toarray()
            C = np.zeros((len(h), m.n_vertices))
            C[np.arange(len(h)), h] = omega
            A = np.vstack([L, C])
            b = np.vstack([L @ m.vertices, omega * t])
            assert np.allclose(q, np.linalg.lstsq(A, b, rcond=None)[0], atol=1e-8)
    assert errs[0] > errs[1] > errs[2] and errs[0] > 1e-3
    assert np.abs(q - hard).max() < 1e-3


def test_factor_reused_for_new_targets(setup):
    m, h, t = setup
    ed = LaplacianEditor(m, h, "cotan")
    f = ed._factor
    q1 = ed.solve(t)
    q2 = ed.solve(t + 1.0)
    assert ed._factor is f
    # translating every target translates the solution (the operator kills constants)
    assert np.allclose(q2, q1 + 1.0)
