"""Rings counted on a finer mesh (``Deformer(..., ring_scale=s)``): the blended energy.

Below one ring (``r s < 1``) the r-ring energy of a coarse mesh is blended with a rotation
per triangle (:mod:`arapkit.arap.energies.rring`). Everything here is checked against
independent computations: the energy summed term by term over independently searched
neighbourhoods and triangles, rotations by NumPy's SVD, the gradient edge by edge, and a
fine mesh's own solution.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import independent_ring_edges
from scipy.spatial import cKDTree

from arapkit import Deformer, InputError
from arapkit.mesh.shapes import bar, bar_bend, bar_two_materials
from arapkit.mesh.weights import edge_weights


def svd_rotation(S: np.ndarray) -> np.ndarray:
    """argmax_R tr(R S) over rotations, by NumPy's SVD."""
    U, _, Vt = np.linalg.svd(S)
    if np.linalg.det(Vt.T @ U.T) < 0:
        U[:, 2] *= -1
    return Vt.T @ U.T


def face_shares(mesh, w: np.ndarray) -> dict[tuple[int, tuple[int, int]], float]:
    """w_te: each face's share of its edges' weights, by the clamped cotangent of the face's
    angle opposite the edge (evenly where all of the edge's are 0), triangle by triangle."""
    V = mesh.vertices
    idx = {tuple(e): i for i, e in enumerate(mesh.edges.tolist())}
    cot: dict[tuple[int, tuple[int, int]], float] = {}
    for t, f in enumerate(mesh.faces.tolist()):
        for c in range(3):
            o, i, j = f[c], f[(c + 1) % 3], f[(c + 2) % 3]
            a, b = V[i] - V[o], V[j] - V[o]
            cot[t, tuple(sorted((i, j)))] = max(a @ b / np.linalg.norm(np.cross(a, b)), 0.0)
    total: dict[tuple[int, int], float] = {}
    count: dict[tuple[int, int], int] = {}
    for (_, e), c in cot.items():
        total[e] = total.get(e, 0.0) + c
        count[e] = count.get(e, 0) + 1
    return {(t, e): w[idx[e]] * (c / total[e] if total[e] > 0 else 1.0 / count[e])
            for (t, e), c in cot.items()}


def brute_blended(mesh, w, rings, s, P, fit_to=None):
    """The blended energy at P, summed term by term, with every rotation the best fit to
    ``fit_to`` (default P).

    Returns (energy, the vertices' rotations, the gradient for the rotations held fixed).
    """
    P0 = mesh.vertices
    Q = P if fit_to is None else fit_to
    idx = {tuple(e): i for i, e in enumerate(mesh.edges.tolist())}
    reach = np.asarray(rings, float) * s
    a = np.minimum(1.0, reach**2)
    searched = np.maximum(1, np.rint(reach)).astype(int)
    groups = []
    for k in range(mesh.n_vertices):
        pairs = sorted(independent_ring_edges(mesh, k, int(searched[k])))
        groups.append((pairs, [a[k] * w[idx[p]] for p in pairs]))
    shares = face_shares(mesh, w)
    for t, f in enumerate(mesh.faces.tolist()):
        membrane = 1.0 - a[f].mean()
        pairs = [tuple(sorted((f[c], f[(c + 1) % 3]))) for c in range(3)]
        groups.append((pairs, [2 * membrane * shares[t, p] for p in pairs]))
    energy, G = 0.0, np.zeros_like(P)
    R = np.empty((len(groups), 3, 3))
    for g, (pairs, coef) in enumerate(groups):
        R[g] = svd_rotation(sum(c * np.outer(P0[i] - P0[j], Q[i] - Q[j])
                                for (i, j), c in zip(pairs, coef)))
        for (i, j), c in zip(pairs, coef):
            d = (P[i] - P[j]) - R[g] @ (P0[i] - P0[j])
            energy += c * d @ d
            G[i] += 2 * c * d
            G[j] -= 2 * c * d
    return energy, R[:mesh.n_vertices], G


@pytest.fixture(scope="module")
def small_bar():
    m = bar(length=3.0, segments=(15, 2, 2))
    h, t = bar_bend(m, 120)
    return m, h, t


@pytest.mark.parametrize("scale", [0.3, 0.7])
def test_the_blended_energy_is_its_definition(small_bar, scale):
    # a mixed map: r = 1 blends everywhere at 0.3, r = 3 searches one ring at 0.3 (reach
    # 0.9) and three at 0.7 (reach 2.1, no blend)
    m, h, t = small_bar
    rings = bar_two_materials(m, 1, 3)
    res = Deformer(m, h, rings=rings, ring_scale=scale).solve(t, max_iter=6, tol=0)
    E, R, _ = brute_blended(m, edge_weights(m), rings, scale, res.vertices)
    assert res.energy == pytest.approx(E, rel=1e-9)
    assert res.vertex_energy.sum() == pytest.approx(E, rel=1e-9)
    np.testing.assert_allclose(res.rotations, R, atol=1e-8)
    # a plain r-ring energy is something else: the blend really is in use
    plain = Deformer(m, h, rings=rings).solve(t, max_iter=6, tol=0)
    assert abs(plain.energy - res.energy) > 0.05 * res.energy


def test_the_global_step_zeroes_the_blended_gradient(small_bar):
    m, h, t = small_bar
    w = edge_weights(m)
    rings = np.ones(m.n_vertices, int)
    d = Deformer(m, h, ring_scale=0.4)
    Pa = d.solve(t, max_iter=2, tol=0).vertices
    Ea, _, Ga = brute_blended(m, w, rings, 0.4, Pa)
    # one more iteration from Pa: its local step fits Pa's rotations (the triangles' too),
    # its global step minimises the energy for them exactly
    Pb = d.solve(t, init=Pa, max_iter=1, tol=0).vertices
    Eb, _, Gb = brute_blended(m, w, rings, 0.4, Pb, fit_to=Pa)
    free = np.setdiff1d(np.arange(m.n_vertices), h)
    assert np.abs(Gb[free]).max() < 1e-9 * np.abs(Ga[free]).max()
    assert Eb < Ea


def test_the_blended_energy_never_increases():
    m = bar()
    h, t = bar_bend(m, 150)
    for accelerate in (False, True):  # the safeguard keeps Anderson's history monotone too
        res = Deformer(m, h, ring_scale=0.3, accelerate=accelerate).solve(t, tol=1e-6,
                                                                          max_iter=200)
        H = np.array(res.history)
        assert len(H) > 50 and H[-1] < 0.02 * H[0]
        assert np.all(np.diff(H) <= 1e-10 * H[0]), np.diff(H).max()


def test_a_scale_with_every_reach_at_one_ring_or_more_is_the_rounded_map():
    # reach 4 x 0.5 = 2 everywhere: the neighbourhoods of r = 2, nothing blended
    m = bar()
    h, t = bar_bend(m, 90)
    a = Deformer(m, h, rings=4, ring_scale=0.5)
    b = Deformer(m, h, rings=2)
    assert a.problem.energy.n_owners == m.n_vertices
    np.testing.assert_array_equal(a.solve(t).vertices, b.solve(t).vertices)
    assert a.rings.max() == 4  # the map as given


def test_a_coarse_mesh_with_the_fine_meshs_rings_solves_like_the_fine_mesh():
    # the same bar at a third of the resolution: its one-ring is three of the fine bar's,
    # and without the scale it is much stiffer than the fine bar at r = 1
    fine = bar(length=7.0, segments=(84, 6, 6))
    coarse = bar(length=7.0, segments=(28, 2, 2))
    hf, tf = bar_bend(fine, 90)
    hc, tc = bar_bend(coarse, 90)
    goal = Deformer(fine, hf, accelerate=True).solve(tf, tol=1e-9, max_iter=5000)
    at = cKDTree(fine.vertices).query(coarse.vertices)[1]  # the coarse grid's points
    diag = fine.bounding_box_diagonal

    def error(scale: float) -> float:
        res = Deformer(coarse, hc, accelerate=True, ring_scale=scale).solve(
            tc, tol=1e-9, max_iter=5000)
        assert res.converged
        return float(np.linalg.norm(res.vertices - goal.vertices[at], axis=1).max() / diag)

    matched, plain = error(1 / 3), error(1.0)
    assert matched < 3e-4 < plain  # measured: 2.1e-4 against 9.3e-4
    assert matched < plain / 3


def test_rigidity_map_changes_keep_the_scale(small_bar):
    m, h, t = small_bar
    d = Deformer(m, h, ring_scale=0.3)
    r = bar_two_materials(m, 1, 2)
    d.set_rings(r)
    fresh = Deformer(m, h, rings=r, ring_scale=0.3)
    assert d.problem.energy.options == {"ring_scale": 0.3}
    np.testing.assert_array_equal(d.solve(t).vertices, fresh.solve(t).vertices)


@pytest.mark.parametrize("value", [0, -1, float("nan"), float("inf"), "x"])
def test_bad_ring_scales_are_refused_in_one_line(value):
    m = bar()
    with pytest.raises(InputError, match="ring_scale: ") as e:
        Deformer(m, [0], ring_scale=value)
    assert "\n" not in str(e.value)


def test_a_ring_scale_needs_a_rigidity_map():
    m = bar()
    with pytest.raises(InputError, match="ring_scale: energy 'spokes-and-rims' has no"):
        Deformer(m, [0], energy="spokes-and-rims", ring_scale=0.5)


def test_the_torch_backend_refuses_a_blended_energy():
    pytest.importorskip("torch", reason="the torch backend is the arapkit[torch] extra")
    m = bar()
    with pytest.raises(InputError, match="use device='cpu'"):
        Deformer(m, [0], ring_scale=0.5, device="torch-cpu")
