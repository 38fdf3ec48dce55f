"""Smooth ARAP (issue 49, section 3): the energy against a brute-force evaluation, its
gradient against finite differences, descent, the fixed global matrix, and the spike a
single-vertex drag pulls (``tests/spike_cases.py``).

The oracle builds the energy from its definition with libigl's cotangent matrix and Voronoi
mass matrix (``weights="cotan"``, libigl's weights) and NumPy, and fits the rotations from
the cross-covariance derived on paper:

    E = (1 - lam) sum_k sum_{j~k} w_kj |e'_kj - R_k e_kj|^2
        + lam A sum_k |(L P')_k - R_k (L P)_k|^2 / M_k,
    S_k = (1 - lam) sum_j w_kj e_kj e'_kj^T + lam A / M_k (L P)_k (L P')_k^T.
"""

from __future__ import annotations

import sys
from functools import cache
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from arapkit import Deformer, Mesh
from arapkit.arap.energies.smooth_arap import check_smooth_lambda, neighbour_pairs
from arapkit.arap.problem import ARAPProblem
from arapkit.arap.rotations import fit_rotations
from arapkit.errors import InputError
from arapkit.mesh.shapes import bar

sys.path.insert(0, str(Path(__file__).parent))
from spike_cases import bar_case, bumpy_sphere, cases, sphere_case, spike  # noqa: E402

igl = pytest.importorskip("igl", reason="libigl is the test oracle (arapkit[test])")

LAM = 0.9  # not the default: a test of the default would not see lam and 1 - lam swapped


@cache
def _small_sphere() -> Mesh:
    return bumpy_sphere(subdivisions=2)


class Oracle:
    """The energy of a mesh from its definition (libigl's L and M, dense NumPy sums)."""

    def __init__(self, mesh: Mesh, lam: float) -> None:
        V, F = mesh.vertices, mesh.faces.astype(np.int64)
        C = sp.csr_matrix(igl.cotmatrix(V, F))
        self.L = -C  # (L P)_k = sum_j w_kj (p_k - p_j)
        self.M = igl.massmatrix(V, F, igl.MASSMATRIX_TYPE_VORONOI).diagonal()
        self.A = float(self.M.sum())
        W = sp.triu(C, k=1).tocoo()
        self.a, self.b, self.w = W.row, W.col, W.data
        self.V, self.lam = V, lam
        self.delta = self.L @ V

    def energy(self, P: np.ndarray, R: np.ndarray) -> float:
        """E(P, R), every term as written."""
        V, a, b, w = self.V, self.a, self.b, self.w
        arap = 0.0
        for k, j in ((a, b), (b, a)):  # each edge is a spoke of both its ends
            d = (P[k] - P[j]) - np.einsum("kab,kb->ka", R[k], V[k] - V[j])
            arap += float((w * (d * d).sum(axis=1)).sum())
        r = self.L @ P - np.einsum("kab,kb->ka", R, self.delta)
        smooth = float(((r * r).sum(axis=1) / self.M).sum()) * self.A
        return (1 - self.lam) * arap + self.lam * smooth

    def best_rotations(self, P: np.ndarray) -> np.ndarray:
        """argmax_R tr(R S_k), S_k the cross-covariance of both terms."""
        V, a, b, w = self.V, self.a, self.b, self.w
        S = np.zeros((len(V), 3, 3))
        for k, j in ((a, b), (b, a)):
            e, e2 = V[k] - V[j], P[k] - P[j]
            np.add.at(S, k, (1 - self.lam) * w[:, None, None] * e[:, :, None] * e2[:, None, :])
        c = self.lam * self.A / self.M
        S += c[:, None, None] * self.delta[:, :, None] * (self.L @ P)[:, None, :]
        return fit_rotations(S)

    def reduced(self, P: np.ndarray) -> float:
        """min_R E(P, R)."""
        return self.energy(P, self.best_rotations(P))


def _bent(mesh: Mesh, seed: int = 0) -> np.ndarray:
    """A smooth, large deformation of the rest shape plus noise."""
    rng = np.random.default_rng(seed)
    V = mesh.vertices
    a = 0.8 * V[:, 0:1]
    P = np.hstack([V[:, :1] * np.cos(a) - V[:, 2:3] * np.sin(a), V[:, 1:2] * 1.1,
                   V[:, :1] * np.sin(a) + V[:, 2:3] * np.cos(a)])
    return P + 0.02 * rng.standard_normal(V.shape)


def _random_rotations(n: int, seed: int = 1) -> np.ndarray:
    return fit_rotations(np.random.default_rng(seed).standard_normal((n, 3, 3)))


def _system(p: ARAPProblem):
    """The engine's global matrix Q and right-hand side b(R) in the caller's numbering."""
    n = p.n_vertices
    E, dw = p.edges, p.energy.system_w
    a, b = E[:, 0], E[:, 1]
    Q = sp.coo_matrix((np.concatenate([-dw, -dw, dw, dw]),
                       (np.concatenate([a, b, a, b]), np.concatenate([b, a, a, b]))), (n, n))
    Q = sp.csr_matrix(Q)[p.iperm][:, p.iperm]
    nbh = p.energy.nbh
    k = np.repeat(np.arange(n), np.diff(nbh.disk_ptr))

    def rhs(R: np.ndarray) -> np.ndarray:
        Ri = R[p.perm]  # internal numbering
        out = np.zeros((n, 3))
        np.add.at(out, nbh.disk_idx, np.einsum("kab,kb->ka", Ri[k], nbh.disk_coef))
        return out[p.iperm]

    return Q, rhs


# ------------------------------------------------------------------- the energy itself


def test_energy_matches_brute_force():
    """Each vertex's term summed, at any P and R, is E from its definition."""
    m = _small_sphere()
    o = Oracle(m, LAM)
    d = Deformer(m, [0], weights="cotan", energy="smooth-arap", smooth_lambda=LAM)
    P, R = _bent(m), _random_rotations(m.n_vertices)
    want = o.energy(P, R)
    assert d.vertex_energy(P, R).sum() == pytest.approx(want, rel=1e-9)
    assert want > 1.0  # not a trivially small case


def test_local_step_fits_both_terms():
    """The engine's energy at its best rotations is the oracle's minimum over R, and no
    small turn of the oracle's rotations lowers E (the cross-covariance is the right one)."""
    m = _small_sphere()
    o = Oracle(m, LAM)
    d = Deformer(m, [0], weights="cotan", energy="smooth-arap", smooth_lambda=LAM)
    P = _bent(m)
    R = o.best_rotations(P)
    E0 = o.energy(P, R)
    assert d.energy_of(P, P[[0]]) == pytest.approx(E0, rel=1e-9)
    rng = np.random.default_rng(2)
    for _ in range(5):
        turn = fit_rotations(np.eye(3) + 1e-3 * rng.standard_normal((m.n_vertices, 3, 3)))
        assert o.energy(P, turn @ R) > E0
    # fitting the edges alone (the ARAP covariance) is not the minimiser of this energy
    edges_only = Oracle(m, LAM)
    edges_only.lam = 0.0
    assert o.energy(P, edges_only.best_rotations(P)) > E0 * (1 + 1e-6)


def test_gradient_matches_finite_differences():
    """dE/dP = 2 (Q P - b(R)) with the engine's Q and b, at fixed R and at the best R
    (the reduced energy, whose gradient the global step sets to zero)."""
    m = _small_sphere()
    o = Oracle(m, LAM)
    p = ARAPProblem.from_mesh(m, [0], "smooth-arap", "cotan", smooth_lambda=LAM)
    Q, rhs = _system(p)
    # the engine works in positions / scale: its weights (Q) are unitless, its right-hand
    # side's coefficients are lengths in those units
    P, R = _bent(m), _random_rotations(m.n_vertices)
    D = np.random.default_rng(3).standard_normal(P.shape)
    h = 1e-6
    fd = (o.energy(P + h * D, R) - o.energy(P - h * D, R)) / (2 * h)
    grad = 2 * (Q @ P - p.scale * rhs(R))
    assert float((grad * D).sum()) == pytest.approx(fd, rel=1e-6)
    R_best = o.best_rotations(P)
    fd = (o.reduced(P + h * D) - o.reduced(P - h * D)) / (2 * h)
    grad = 2 * (Q @ P - p.scale * rhs(R_best))
    assert float((grad * D).sum()) == pytest.approx(fd, rel=1e-5)


def test_global_matrix_is_the_bilaplacian_blend_and_factorised_once():
    """Q = (1 - lam) L_D + lam A L^T M^-1 L (L_D: spokes ARAP's, twice L), factorised once
    for every set of targets."""
    m = _small_sphere()
    o = Oracle(m, LAM)
    p = ARAPProblem.from_mesh(m, [0], "smooth-arap", "cotan", smooth_lambda=LAM)
    Q, _ = _system(p)
    want = (1 - LAM) * 2 * o.L + LAM * o.A * (o.L.T @ sp.diags(1 / o.M) @ o.L)
    # unitless (A / M_k and the cotangents are), so the engine's units do not enter
    err = abs(Q - want).max()
    assert err <= 1e-10 * abs(want).max()
    d = Deformer(m, np.arange(5), weights="cotan", energy="smooth-arap")
    T = m.vertices[:5]
    for shift in (0.1, 0.3):
        d.solve(T + shift)
    assert d.factorisations == 1


# ------------------------------------------------------------------------ the solve


def test_every_iteration_lowers_the_brute_force_energy():
    """On the bar's drag, every iterate's energy (the oracle's, at its best rotations)
    falls, and agrees with the solver's history; the handles are met exactly."""
    c = bar_case()
    m = c.mesh
    o = Oracle(m, LAM)
    seen = []
    d = Deformer(m, c.handles, weights="cotan", energy="smooth-arap", smooth_lambda=LAM)
    res = d.solve(c.targets, max_iter=40,
                  callback=lambda it, E, V: seen.append((E, o.reduced(V))) and None)
    E_solver, E_oracle = np.array(seen).T
    assert np.allclose(E_solver, E_oracle, rtol=1e-8)
    assert (np.diff(E_oracle) < 0).all()
    assert np.abs(res.vertices[c.handles] - c.targets).max() == 0.0


@pytest.mark.parametrize("accelerate", [False, True])
def test_history_is_monotone_and_converges(accelerate):
    """Default weights, default lam: the history never rises, with or without Anderson."""
    c = sphere_case()
    res = Deformer(c.mesh, c.handles, energy="smooth-arap").solve(c.targets,
                                                                  accelerate=accelerate)
    H = np.array(res.history)
    assert res.converged and (np.diff(H) <= 0).all() and H[-1] < 0.2 * H[0]


def test_lambda_zero_is_rring_arap():
    m = bar(segments=(12, 2, 2))
    h = np.flatnonzero(m.vertices[:, 0] == 0)
    h = np.append(h, np.argmax(m.vertices[:, 0]))
    T = m.vertices[h] + [0, 0, 0.4] * (np.arange(len(h)) == len(h) - 1)[:, None]
    for rings in (1, 2):
        a = Deformer(m, h, rings=rings).solve(T, tol=1e-8)
        b = Deformer(m, h, rings=rings, energy="smooth-arap", smooth_lambda=0).solve(T, tol=1e-8)
        assert np.abs(a.vertices - b.vertices).max() < 1e-9
        assert b.energy == pytest.approx(a.energy, rel=1e-9)


def test_rigidity_map_adds_the_rring_term():
    """With r per vertex, E = (1 - lam) E_r-ring + lam E_Laplacian, term by term; a
    larger r is stiffer; a new map keeps the energy and lam."""
    m = _small_sphere()
    o = Oracle(m, LAM)
    rings = np.where(m.vertices[:, 2] > 0, 2, 1)
    P, R = _bent(m), _random_rotations(m.n_vertices)
    smooth = Deformer(m, [0], rings, "cotan", energy="smooth-arap", smooth_lambda=LAM)
    rring = Deformer(m, [0], rings, "cotan")
    o_lap = o.energy(P, R) - (1 - LAM) * Deformer(m, [0], 1, "cotan").vertex_energy(P, R).sum()
    want = (1 - LAM) * rring.vertex_energy(P, R).sum() + o_lap
    assert smooth.vertex_energy(P, R).sum() == pytest.approx(want, rel=1e-9)
    smooth.set_rings(3)
    assert smooth.problem.energy.name == "smooth-arap"
    assert smooth.problem.energy.options == {"smooth_lambda": LAM}
    # stiffer: the same drag moves the far side less
    c = bar_case()
    moved = []
    for r in (1, 4):
        V = Deformer(c.mesh, c.handles, r, energy="smooth-arap").solve(c.targets).vertices
        moved.append(np.linalg.norm(V - c.mesh.vertices, axis=1).mean())
    assert moved[1] != pytest.approx(moved[0], rel=1e-3)


def test_scale_invariant():
    """lam means the same at any units: the result scales with the mesh."""
    c = sphere_case()
    fixed = {"tol": 1e-12, "max_iter": 60}  # the same iterations: round-off apart
    a = Deformer(c.mesh, c.handles, energy="smooth-arap").solve(c.targets, **fixed)
    big = Mesh(c.mesh.vertices * 3.0, c.mesh.faces)
    b = Deformer(big, c.handles, energy="smooth-arap").solve(c.targets * 3.0, **fixed)
    assert np.abs(b.vertices / 3.0 - a.vertices).max() < 1e-9
    assert b.energy == pytest.approx(9 * a.energy, rel=1e-9)


# ------------------------------------------------------------------------ the spike


@pytest.mark.parametrize("case", cases(), ids=lambda c: c.name)
def test_spike_is_five_times_smaller_than_arap(case):
    """One vertex dragged by 20 % of the diagonal: ARAP pulls a spike, Smooth ARAP at
    least 5x less (docs/benchmarks.md has the table), handles met exactly, E falling."""
    m = case.mesh
    out = {}
    for energy in ("rring", "smooth-arap"):
        res = Deformer(m, case.handles, energy=energy).solve(case.targets)
        assert np.abs(res.vertices[case.handles] - case.targets).max() == 0.0
        assert (np.diff(res.history) <= 0).all()
        out[energy] = spike(m, res.vertices, case.vertex)
    assert out["rring"] > 0.5  # ARAP does pull one
    assert out["smooth-arap"] * 5 <= out["rring"], out


def test_bar_and_sphere_cases_are_present():
    assert {"bar", "bumpy sphere"} <= {c.name for c in cases()}


# ------------------------------------------------------------------- inputs and doors


def test_bad_lambda_is_one_line():
    for bad in (1, 1.5, -0.1, "x", float("nan")):
        with pytest.raises(InputError) as e:
            check_smooth_lambda(bad)
        assert "smooth_lambda" in str(e.value) and "\n" not in str(e.value)
    with pytest.raises(InputError, match="option of energy 'smooth-arap'"):
        Deformer(bar(), [0], smooth_lambda=0.5)
    with pytest.raises(InputError, match="ring_scale"):
        Deformer(bar(), [0], energy="smooth-arap", ring_scale=0.5)
    with pytest.raises(InputError, match="coarse to fine"):
        Deformer(bar(), [0], energy="smooth-arap", multires=True)


def test_vertex_on_no_triangle_stays_finite():
    m = bar(segments=(6, 2, 2))
    V = np.vstack([m.vertices, [[10.0, 10.0, 10.0]]])
    lone = Mesh(V, m.faces)
    h = np.flatnonzero(V[:, 0] == 0)
    T = V[h] + 0.1
    res = Deformer(lone, h, energy="smooth-arap").solve(T)
    assert np.isfinite(res.vertices).all() and np.isfinite(res.energy)


def test_neighbour_pairs_lists_each_pair_once():
    ptr = np.array([0, 4, 4, 6])
    a, b = neighbour_pairs(ptr, np.arange(6))
    assert sorted(zip(a.tolist(), b.tolist(), strict=True)) == [
        (0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3), (4, 5)]


def test_torch_layer_forward_and_gradient():
    """ARAPLayer (the registry offers it the torch door) solves as the Deformer does, and
    its implicit gradient matches central differences of converged solves."""
    torch = pytest.importorskip("torch", reason="PyTorch not installed")
    from arapkit.torch import ARAPLayer

    c = sphere_case()
    steps = {"tol": 0.0, "max_iter": 60}  # the same 60 iterations: round-off apart
    want = Deformer(c.mesh, c.handles, energy="smooth-arap").solve(c.targets, **steps)
    layer = ARAPLayer(c.mesh, c.handles, energy="smooth-arap", dtype=torch.float64, **steps)
    got = layer(torch.tensor(c.targets)).detach().numpy()
    assert np.abs(got - want.vertices).max() < 1e-9 * c.mesh.bounding_box_diagonal

    # few free vertices: Smooth ARAP converges slowly (docs/smooth-arap.md), and the
    # finite differences need converged solves
    mesh = bumpy_sphere(subdivisions=1)
    z = mesh.vertices[:, 2]
    h = np.append(np.flatnonzero(z < 0.2), np.argmax(z))
    t = mesh.vertices[h].copy()
    t[-1] += [0.1, 0.0, 0.3]
    layer = ARAPLayer(mesh, h, energy="smooth-arap", dtype=torch.float64, tol=0.0,
                      xtol=1e-13, max_iter=20_000)
    rng = np.random.default_rng(4)
    w = torch.tensor(rng.standard_normal((mesh.n_vertices, 3)))
    T = torch.tensor(t, requires_grad=True)
    (layer(T) * w).sum().backward()
    assert layer.last_info["converged"]
    D = rng.standard_normal(t.shape)
    eps = 1e-5
    f = [float((layer(torch.tensor(t + s * D)) * w).sum()) for s in (eps, -eps)]
    fd = (f[0] - f[1]) / (2 * eps)
    assert float((T.grad.numpy() * D).sum()) == pytest.approx(fd, rel=1e-4)
