"""The fit's linear algebra: one symbolic analysis, a numeric factor per stage
(arapkit.methods.fit.ldl, .system), checked against scipy's sparse LU solve.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as sla

from arapkit import InputError
from arapkit.arap.problem import ARAPProblem
from arapkit.mesh.shapes import bar
from arapkit.methods.fit.ldl import SharedPattern
from arapkit.methods.fit.system import StageSystems


def laplacian(n_side=9, seed=0):
    """A grid graph's Laplacian with random positive weights (singular: constant kernel)."""
    rng = np.random.default_rng(seed)
    idx = np.arange(n_side * n_side).reshape(n_side, n_side)
    e = np.concatenate([np.stack([idx[:, :-1].ravel(), idx[:, 1:].ravel()], 1),
                        np.stack([idx[:-1].ravel(), idx[1:].ravel()], 1)])
    w = rng.uniform(0.5, 2.0, len(e))
    n = n_side * n_side
    W = sp.coo_matrix((w, (e[:, 0], e[:, 1])), shape=(n, n))
    W = W + W.T
    return sp.csr_matrix(sp.diags(np.asarray(W.sum(axis=1)).ravel()) - W)


@pytest.mark.parametrize("columns", [1, 2, 3, 4, 7])
def test_factors_of_one_pattern_solve_like_lu(columns):
    """Every diagonal, in any order, after the first analysis: the solve of each matches
    scipy's LU of the same matrix; the off-diagonal entries are the pattern's."""
    L = laplacian()
    n = L.shape[0]
    rng = np.random.default_rng(1)
    shared = SharedPattern(L, "grid")
    B = rng.normal(size=(n, columns))
    factors = []
    for k in range(4):
        diag = L.diagonal() + rng.uniform(0.0, 10.0 ** (k - 2), n) + 1e-9
        factors.append((shared.factor(diag), diag))
    for f, diag in factors:  # the earlier factors are kept intact by later refactorisations
        A = sp.csc_matrix(L - sp.diags(L.diagonal()) + sp.diags(diag))
        ref = sla.splu(A).solve(B)
        X = f.solve(B)
        assert X.shape == B.shape
        assert np.allclose(X, ref, rtol=1e-9, atol=1e-12 * np.abs(ref).max())
    x1 = factors[0][0].solve(B[:, 0])  # a vector in, a vector out
    assert x1.shape == (n,) and np.allclose(x1, factors[0][0].solve(B[:, :1])[:, 0])


def test_a_matrix_that_is_not_positive_definite_is_refused():
    L = laplacian()
    shared = SharedPattern(L, "grid: fit system")
    with pytest.raises(InputError, match="grid: fit system: the system matrix is not "
                                         "positive definite"):
        shared.factor(L.diagonal())  # the Laplacian itself: singular
    with pytest.raises(InputError, match="not positive definite"):
        shared.factor(L.diagonal() - 1.0)  # indefinite: a negative pivot, no exception
    f = shared.factor(L.diagonal() + 1.0)  # and the next one is made afresh
    assert np.all(np.isfinite(f.solve(np.ones((L.shape[0], 3)))))


def test_stage_systems_solve_each_stage_and_keep_its_factor():
    """The fit's stage matrix ``L_ff + diag(w) + delta I`` with landmarks eliminated, two
    stages and back: solutions equal a direct solve; a stage factorises once."""
    p = ARAPProblem.from_mesh(bar(), [0], rings=1)
    E, D, n = p.edges, p.energy.system_w, p.n_vertices
    A = sp.coo_matrix((np.concatenate([-D, -D]), (np.concatenate([E[:, 0], E[:, 1]]),
                                                   np.concatenate([E[:, 1], E[:, 0]]))),
                      shape=(n, n)).tocsr()
    L = sp.csr_matrix(sp.diags(-np.asarray(A.sum(axis=1)).ravel()) + A)
    landmarks = np.array([3, 40, 77])
    s = StageSystems(L, landmarks, "bar", delta=1e-6)
    rng = np.random.default_rng(2)
    rhs = rng.normal(size=(len(s.free), 3))
    w = rng.uniform(0.1, 1.0, len(s.free))
    for key, scale in ((0.3, 1.0), (0.1, 9.0), (0.3, 1.0)):
        x = s.solve(key, w * scale, rhs)
        M = sp.csc_matrix(L[s.free][:, s.free] + sp.diags(w * scale + 1e-6))
        assert np.allclose(x, sla.splu(M).solve(rhs), rtol=1e-9, atol=1e-12)
    assert s.factorisations == 2
