"""2D as a domain (issue 48, part 1): the planar solver against libigl, brute force and the
3D solver; pin turns, presets, (n, 2) input, pins added and removed on the existing factor."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import independent_ring_edges

from arapkit import Deformer, InputError, Mesh
from arapkit.arap.rotations2d import fit_rotations_2d, rigid_motion_2d
from arapkit.mesh.shapes2d import strip, strip_ends
from arapkit.mesh.weights import edge_weights
from arapkit.methods.planar import PRESETS


def brute_energy_2d(mesh, w, rings, P, R):
    """Eq. (1) in the plane, edge by edge over independently searched neighbourhoods."""
    idx = {tuple(e): i for i, e in enumerate(mesh.edges.tolist())}
    P0 = mesh.vertices[:, :2]
    E = 0.0
    for k in range(mesh.n_vertices):
        for i, j in independent_ring_edges(mesh, k, int(rings[k])):
            d = (P[i] - P[j]) - R[k] @ (P0[i] - P0[j])
            E += w[idx[(i, j)]] * d @ d
    return E


def brute_gradient_2d(mesh, w, rings, P, R):
    """dE/dp'_i of eq. (1) in the plane for fixed rotations."""
    idx = {tuple(e): i for i, e in enumerate(mesh.edges.tolist())}
    P0 = mesh.vertices[:, :2]
    G = np.zeros_like(P)
    for k in range(mesh.n_vertices):
        for i, j in independent_ring_edges(mesh, k, int(rings[k])):
            d = (P[i] - P[j]) - R[k] @ (P0[i] - P0[j])
            G[i] += 2 * w[idx[(i, j)]] * d
            G[j] -= 2 * w[idx[(i, j)]] * d
    return G


def bend(mesh, dx=-1.0, dy=2.0):
    """Left end held, right end moved by (dx, dy): a bend that plain ARAP solves fold-free."""
    left, right = strip_ends(mesh)
    h = np.concatenate([left, right])
    T = mesh.vertices[h, :2].copy()
    T[len(left):] += [dx, dy]
    return h, T


@pytest.fixture(scope="module")
def small():
    return strip(segments=(12, 4))


def test_closed_form_rotation_is_the_best_proper_rotation():
    rng = np.random.default_rng(0)
    S = rng.normal(size=(500, 2, 2))
    S[:5] *= 1e-200  # tiny and huge scales: hypot keeps the unit vector
    S[5:10] *= 1e200
    R = fit_rotations_2d(S)
    assert np.allclose(R @ np.swapaxes(R, 1, 2), np.eye(2), atol=1e-14)
    assert np.allclose(np.linalg.det(R), 1.0)
    # brute force: tr(R(t) S) over a fine circle of angles, refined around the best
    t = np.linspace(-np.pi, np.pi, 20001)
    for k in range(10, 60):
        s = S[k]
        tr = np.cos(t) * (s[0, 0] + s[1, 1]) + np.sin(t) * (s[0, 1] - s[1, 0])
        best = tr.max()
        got = np.trace(R[k] @ s)
        assert got >= best - 1e-9 * np.abs(s).max()
    # SVD with the reflection fix (Sorkine & Alexa) agrees
    for s, r in zip(S[10:60], R[10:60]):
        U, _, Vt = np.linalg.svd(s)
        D = np.diag([1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
        assert np.allclose(Vt.T @ D @ U.T, r, atol=1e-10)
    assert np.array_equal(fit_rotations_2d(np.zeros((1, 2, 2)))[0], np.eye(2))


def test_rigid_motion_2d_recovers_a_motion():
    rng = np.random.default_rng(1)
    X = rng.normal(size=(7, 2))
    t = 2.1
    Q = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
    R, c = rigid_motion_2d(X, X @ Q.T + [3, -1])
    assert np.allclose(R, Q) and np.allclose(c, [3, -1])


def test_r1_matches_libigl_2d_to_1e6_of_the_diagonal(small):
    """libigl's dim=2 ARAP (spokes, raw cotangents) and ours at convergence, flip guard on."""
    igl = pytest.importorskip("igl", reason="libigl is the test oracle for 2D ARAP")
    m = strip(segments=(40, 10))
    V2 = np.ascontiguousarray(m.vertices[:, :2])
    h, T = bend(m)
    data = igl.ARAPData()
    data.energy = igl.ARAP_ENERGY_TYPE_SPOKES
    data.max_iter = 2000
    igl.arap_precomputation(V2, m.faces.astype(np.int64), 2, h.astype(np.int32), data)
    U = igl.arap_solve(T, data, V2.copy())
    res = Deformer((V2, m.faces), h, weights="cotan").solve(T, tol=1e-12, max_iter=3000)
    diag = np.linalg.norm(np.ptp(V2, axis=0))
    assert res.vertices.shape == V2.shape and res.folds == 0
    assert np.abs(U - res.vertices).max() < 1e-6 * diag
    assert np.abs(U - V2).max() > 0.3 * diag  # it really moved
    # and iteration by iteration with the guard off (libigl snaps the pins as we do)
    for iters in (1, 4):
        data.max_iter = iters
        U = igl.arap_solve(T, data, V2.copy())
        r = Deformer((V2, m.faces), h, weights="cotan", flips="allow").solve(
            T, init=V2.copy(), max_iter=iters, tol=0)
        assert np.abs(U - r.vertices).max() < 1e-12 * diag


@pytest.mark.parametrize("energy, rings, weights", [
    ("rring", 1, "cotan-clamped"), ("rring", 3, "uniform"), ("rring", "mixed", "cotan"),
    ("spokes-and-rims", 1, "cotan-clamped"), ("sr-arap", 1, "cotan-clamped")])
def test_planar_solve_equals_the_3d_solve_without_folds(small, energy, rings, weights):
    """Where the 3D solve keeps the shape flat and unfolded, the 2D solve is the same."""
    h, T = bend(small, -0.3, 0.8)
    r = np.where(small.vertices[:, 0] < 1.5, 1, 3) if rings == "mixed" else rings
    kw = dict(rings=r, weights=weights, energy=energy, tol=1e-10, max_iter=3000)
    # the guard off: the same iterates as 3D (the guard would keep the pins from snapping
    # where that alone folds a triangle, a different path to the same minimum)
    two = Deformer(small, h, flips="allow", **kw)
    three = Deformer(small, h, dim=3, **kw)
    assert two.dim == 2 and three.dim == 3
    a = two.solve(T)
    b = three.solve(np.c_[T, np.zeros(len(T))])
    assert a.folds == 0 and a.rotations.shape == (small.n_vertices, 2, 2)
    assert np.abs(a.vertices[:, 2]).max() == 0.0
    assert np.abs(a.vertices - b.vertices).max() < 1e-9
    assert a.energy == pytest.approx(b.energy, rel=1e-9)
    guarded = Deformer(small, h, **kw).solve(T)  # and the guarded path's minimum
    assert np.abs(guarded.vertices - b.vertices).max() < 1e-4


@pytest.mark.parametrize("r", [1, 2])
def test_reported_energy_is_eq1_and_global_step_zeroes_gradient(small, r):
    h, T = bend(small)
    w = edge_weights(small)
    rings = np.full(small.n_vertices, r)
    d = Deformer(small, h, rings=r, flips="allow")
    res = d.solve(T, max_iter=3, tol=0)
    P = res.vertices[:, :2]
    assert res.energy == pytest.approx(brute_energy_2d(small, w, rings, P, res.rotations),
                                       rel=1e-9)
    assert res.vertex_energy.sum() == pytest.approx(res.energy, rel=1e-9)
    # one more iteration from P: the local step gives R(P), the global step zeroes dE/dp'
    Ra = d.solve(T, init=P, max_iter=1, tol=0)
    free = np.setdiff1d(np.arange(small.n_vertices), h)
    R0 = fit_rotations_2d(np.stack([sum(
        np.outer(small.vertices[i, :2] - small.vertices[j, :2], P[i] - P[j])
        * w[{tuple(e): q for q, e in enumerate(small.edges.tolist())}[(i, j)]]
        for i, j in independent_ring_edges(small, k, r)) for k in range(small.n_vertices)]))
    G = brute_gradient_2d(small, w, rings, Ra.vertices[:, :2], R0)
    G0 = brute_gradient_2d(small, w, rings, P, R0)
    assert np.abs(G[free]).max() < 1e-9 * np.abs(G0[free]).max()


def test_energy_never_increases_with_the_flip_guard():
    m = strip()
    left, right = strip_ends(m)
    h = np.concatenate([left, right])
    T = m.vertices[h, :2].copy()
    T[len(left):, 0] -= 3.5  # a hard push: the guard is busy
    for accelerate in (False, True):
        res = Deformer(m, h, accelerate=accelerate).solve(T, tol=1e-7, max_iter=400)
        # the pins travel first (snapped at once they would fold the end's triangles):
        # from their landing on, one problem, and its energy never rises
        H = np.array(res.history)[res.timings["pins_landed_at"]:]
        assert res.folds == 0 and len(H) > 20
        assert np.all(np.diff(H) <= 1e-10 * H[0]), np.diff(H).max()


def test_a_turned_pin_turns_its_neighbourhood():
    """One pin with an angle and nothing else: the minimum is the rest shape turned by that
    angle about the pin (energy 0), which the held rotations must reach."""
    m = strip(segments=(16, 4))
    pin = int(np.argmin(np.linalg.norm(m.vertices[:, :2] - [2.0, 0.0], axis=1)))
    d = Deformer(m, [pin])
    c = m.vertices[pin, :2]
    for theta in (0.4, -1.2):
        res = d.solve([c], angles=[theta], tol=1e-12, max_iter=5000)
        Q = np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
        want = (m.vertices[:, :2] - c) @ Q.T + c
        # to the energy's round-off floor (1024 ulps of the rest term): ~1e-6 in position
        assert res.converged and res.energy < 1e-10
        assert np.abs(res.vertices[:, :2] - want).max() < 2e-5
    untouched = d.solve([c], tol=1e-12)  # no angle: nothing turns
    assert np.abs(untouched.vertices - m.vertices).max() < 1e-12
    with pytest.raises(InputError, match="one angle per handle"):
        d.solve([c], angles=[0.1, 0.2])


def test_presets_are_values_of_r(small):
    h, _ = bend(small)
    for name, r in PRESETS.items():
        assert np.all(Deformer(small, h, rings=name.upper()).rings == r)
    with pytest.raises(InputError, match="unknown rigidity preset 'stiff'"):
        Deformer(small, h, rings="stiff")


def test_input_dimensions_and_targets_off_the_plane():
    m = strip(segments=(8, 2))
    V2, F = m.vertices[:, :2], m.faces
    h, T = bend(m, -0.2, 0.5)
    # (n, 2) in, (n, 2) out
    r2 = Deformer((V2, F), h).solve(T)
    assert r2.vertices.shape == (m.n_vertices, 2)
    # a plane at z = 5: (n, 3) out on that plane, targets (h, 2) or (h, 3) alike
    lifted = Mesh(np.c_[V2, np.full(len(V2), 5.0)], F)
    d = Deformer(lifted, h)
    a, b = d.solve(T), d.solve(np.c_[T, np.full(len(T), 5.0)])
    assert np.array_equal(a.vertices, b.vertices) and np.all(a.vertices[:, 2] == 5.0)
    assert np.abs(a.vertices[:, :2] - r2.vertices).max() < 1e-12
    # targets that leave the plane: the same factor, solved in 3D
    up = np.c_[T, np.full(len(T), 5.0)]
    up[len(h) // 2:, 2] += 1.0
    f0 = d.factorisations
    r3 = d.solve(up)
    assert r3.folds is None and r3.rotations.shape[1:] == (3, 3)
    assert np.ptp(r3.vertices[:, 2]) > 0.5 and d.factorisations == f0
    with pytest.raises(InputError, match="dim=2 needs a planar mesh"):
        Deformer(Mesh(np.c_[V2, np.arange(len(V2)) * 0.01], F), h, dim=2)
    with pytest.raises(InputError, match=r"targets: expected shape \(\d+, 2\)"):
        Deformer((V2, F), h).solve(T[:-1])


def test_pins_added_and_removed_without_refactorising():
    """A pin set changed through the bordered solve gives the refactorised answer."""
    m = strip(segments=(30, 8))
    left, right = strip_ends(m)
    mid = int(np.argmin(np.linalg.norm(m.vertices[:, :2] - [2.0, 0.3], axis=1)))
    d = Deformer(m, np.concatenate([left, right]), flips="allow")
    d.prepare()
    f0 = d.factorisations
    V = m.vertices[:, :2]
    for handles in (np.concatenate([left, right, [mid]]),     # one pin added
                    np.concatenate([left, [mid]]),            # one end let go
                    np.concatenate([left[:2], right, [mid]])):  # pins of an end removed
        d.set_handles(handles)
        T = V[handles] + np.where(np.isin(handles, right)[:, None], [-0.3, 0.6], 0.0)
        T[handles == mid] += [0.1, -0.2]
        got = d.solve(T, tol=0, max_iter=30)
        want = Deformer(m, handles, flips="allow").solve(T, tol=0, max_iter=30)
        assert np.abs(got.vertices - want.vertices).max() < 1e-10
        assert np.abs(got.vertices[handles, :2] - T).max() < 1e-12
    assert d.factorisations == f0  # never refactorised
    assert "update_ms" in d.problem.timings
