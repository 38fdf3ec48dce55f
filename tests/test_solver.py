"""r-ring ARAP solver (issue 2): libigl agreement, monotone energy, optimality, trends."""

from __future__ import annotations

import os
import platform
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from conftest import data_path, independent_ring_edges

from arapkit import Deformer, InputError, Mesh, load_mesh
from arapkit.mesh.shapes import bar, bar_bend, bar_two_materials
from arapkit.mesh.weights import edge_weights

SRC = str(Path(__file__).resolve().parents[1] / "src")


def brute_energy(mesh, w, rings, P, R):
    """Eq. (1) summed edge by edge over independently searched neighbourhoods."""
    E = 0.0
    idx = {tuple(e): i for i, e in enumerate(mesh.edges.tolist())}
    P0 = mesh.vertices
    for k in range(mesh.n_vertices):
        for i, j in independent_ring_edges(mesh, k, int(rings[k])):
            d = (P[i] - P[j]) - R[k] @ (P0[i] - P0[j])
            E += w[idx[(i, j)]] * d @ d
    return E


def brute_gradient(mesh, w, rings, P, R):
    """dE/dp'_i of eq. (1) for fixed rotations, edge by edge."""
    G = np.zeros_like(P)
    idx = {tuple(e): i for i, e in enumerate(mesh.edges.tolist())}
    P0 = mesh.vertices
    for k in range(mesh.n_vertices):
        for i, j in independent_ring_edges(mesh, k, int(rings[k])):
            d = (P[i] - P[j]) - R[k] @ (P0[i] - P0[j])
            G[i] += 2 * w[idx[(i, j)]] * d
            G[j] -= 2 * w[idx[(i, j)]] * d
    return G


def svd_rotations(mesh, w, rings, P):
    """Best-fit rotations by numpy SVD over independently searched neighbourhoods."""
    idx = {tuple(e): i for i, e in enumerate(mesh.edges.tolist())}
    P0 = mesh.vertices
    R = np.empty((mesh.n_vertices, 3, 3))
    for k in range(mesh.n_vertices):
        S = np.zeros((3, 3))
        for i, j in independent_ring_edges(mesh, k, int(rings[k])):
            S += w[idx[(i, j)]] * np.outer(P0[i] - P0[j], P[i] - P[j])
        U, _, Vt = np.linalg.svd(S)
        if np.linalg.det(Vt.T @ U.T) < 0:
            U[:, 2] *= -1
        R[k] = Vt.T @ U.T
    return R


@pytest.fixture(scope="module")
def small_bar():
    m = bar(length=3.0, segments=(15, 2, 2))
    h, t = bar_bend(m, 120)
    return m, h, t


def test_r1_matches_libigl():
    igl = pytest.importorskip("igl", reason="libigl is the test oracle for r = 1")
    m = load_mesh(data_path("meshes", "elephant.off"))
    V, F = m.vertices, m.faces
    order = np.argsort(V[:, 1])
    k = len(V) // 20
    h = np.concatenate([order[:k], order[-k:]])
    t = V[h].copy()
    t[k:] += np.array([0.3, 0.0, 0.1]) * m.bounding_box_diagonal
    for iters in (1, 10):
        data = igl.ARAPData()
        data.energy = igl.ARAP_ENERGY_TYPE_SPOKES
        data.max_iter = iters
        igl.arap_precomputation(V, F.astype(np.int64), 3, h.astype(np.int32), data)
        U = igl.arap_solve(t, data, V.copy())
        res = Deformer(m, h, rings=1).solve(t, init=V.copy(), max_iter=iters, tol=0.0)
        assert res.iterations == iters
        assert np.abs(U - res.vertices).max() < 1e-3 * m.bounding_box_diagonal
        assert np.abs(U - V).max() > 0.1 * m.bounding_box_diagonal  # it really moved


@pytest.mark.parametrize("rings", [1, 2, 3, 6, "mixed"])
def test_energy_never_increases(rings):
    m = bar()
    h, t = bar_bend(m, 180)
    r = bar_two_materials(m, 1, 4) if rings == "mixed" else rings
    res = Deformer(m, h, rings=r).solve(t, tol=1e-6, max_iter=150)
    H = np.array(res.history)
    assert len(H) > 10
    assert np.all(np.diff(H) <= 1e-10 * H[0]), np.diff(H).max()
    assert H[-1] < 0.5 * H[0]


@pytest.mark.parametrize("r", [1, 3])
def test_global_step_zeroes_gradient(small_bar, r):
    m, h, t = small_bar
    w = edge_weights(m)
    rings = np.full(m.n_vertices, r)
    d = Deformer(m, h, rings=r)
    Pa = d.solve(t, max_iter=2, tol=0).vertices  # some deformed, not converged shape
    Ra = svd_rotations(m, w, rings, Pa)
    # warm start: one local step on Pa (= Ra), then one global step
    Pb = d.solve(t, init=Pa, max_iter=1, tol=0).vertices
    G = brute_gradient(m, w, rings, Pb, Ra)
    free = np.setdiff1d(np.arange(m.n_vertices), h)
    G0 = brute_gradient(m, w, rings, Pa, Ra)
    assert np.abs(G[free]).max() < 1e-9 * np.abs(G0[free]).max()
    # and the energy at the solution is lower than at Pa for the same rotations
    assert brute_energy(m, w, rings, Pb, Ra) < brute_energy(m, w, rings, Pa, Ra)


@pytest.mark.parametrize("r", [1, 2])
def test_reported_energy_is_eq1(small_bar, r):
    m, h, t = small_bar
    res = Deformer(m, h, rings=r).solve(t, max_iter=5, tol=0)
    w = edge_weights(m)
    rings = np.full(m.n_vertices, r)
    ref = brute_energy(m, w, rings, res.vertices, res.rotations)
    assert res.energy == res.history[-1] == pytest.approx(ref, rel=1e-9)
    assert res.vertex_energy.sum() == pytest.approx(ref, rel=1e-12)
    # rotations are the best fit: they agree with numpy's SVD
    assert np.allclose(res.rotations, svd_rotations(m, w, rings, res.vertices), atol=1e-8)


@pytest.mark.parametrize("r", [1, 2])
def test_energy_of_is_eq1_at_the_best_rotations_with_the_handles_moved(small_bar, r):
    """``energy_of``: eq. (1) edge by edge, at numpy's SVD rotations, of the shape with its
    handles put at their targets."""
    m, h, t = small_bar
    d = Deformer(m, h, rings=r)
    P = m.vertices + 0.05 * np.random.default_rng(0).standard_normal(m.vertices.shape)
    Q = P.copy()
    Q[h] = t
    w = edge_weights(m)
    rings = np.full(m.n_vertices, r)
    ref = brute_energy(m, w, rings, Q, svd_rotations(m, w, rings, Q))
    assert d.energy_of(P, t) == pytest.approx(ref, rel=1e-9)
    assert d.energy_of(Q, t) == d.energy_of(P, t)


@pytest.mark.parametrize("r", [1, 3])
def test_rigid_motion_of_handles(r):
    m = bar(length=3.0, segments=(15, 2, 2))
    rng = np.random.default_rng(1)
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    ang = np.radians(50)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    Q = np.eye(3) + np.sin(ang) * K + (1 - np.cos(ang)) * K @ K
    shift = np.array([0.3, -1.0, 2.0])
    x = m.vertices[:, 0]
    h = np.flatnonzero((x < 0.25) | (x > 2.75))
    V_rigid = m.vertices @ Q.T + shift
    res = Deformer(m, h, rings=r).solve(V_rigid[h], tol=1e-12, max_iter=2000)
    assert np.abs(res.vertices - V_rigid).max() < 1e-6 * m.bounding_box_diagonal
    assert res.energy < 1e-10
    assert res.converged


@pytest.mark.parametrize("r", [1, 3])
def test_rigid_motion_converges_at_once_from_any_warm_start(r):
    """A rigid motion of every handle has energy 0: reached in a step, called converged."""
    from pathlib import Path

    from scipy.spatial.transform import Rotation

    m = load_mesh(Path(__file__).resolve().parents[1] / "examples" / "cactus.off")
    V, y = m.vertices, m.vertices[:, 1]
    h = np.flatnonzero((y < np.quantile(y, 0.05)) | (y > np.quantile(y, 0.95)))
    d = Deformer(m, h, rings=r)
    bent_t = V[h] + np.where(y[h, None] > 5, [1.5, 0.0, 0.0], 0.0)
    bent = d.solve(bent_t, max_iter=30).vertices
    Q1 = Rotation.from_rotvec([0.3, -0.2, 0.5]).as_matrix()
    Q2 = Rotation.from_rotvec([-0.1, 0.4, 0.2]).as_matrix()
    moved = V @ Q1.T + [1.5, -2.0, 0.7]
    for init in (None, V, bent, moved):
        for Q, shift in ((Q1, [1.5, -2.0, 0.7]), (Q1, [1.6, -2.0, 0.7]), (Q2, [-1, 3, 0.2])):
            res = d.solve(V[h] @ Q.T + shift, init=init)
            assert res.converged and res.iterations <= 3, (res.iterations, res.history[-3:])
            assert np.abs(res.vertices - (V @ Q.T + shift)).max() < 1e-9 * m.bounding_box_diagonal


def test_energy_at_round_off_is_converged():
    """A translation of two handles (no rigid start: collinear) is exact after one step.

    Its energy is then round-off of either sign, which the relative decrease cannot judge.
    """
    m = load_mesh(data_path("meshes", "bunny00.off"))
    V = m.vertices
    d = Deformer(m, [0, len(V) // 2])
    rng = np.random.default_rng(0)
    its = [d.solve(V[d.handles] + rng.normal(size=3) * m.bounding_box_diagonal).iterations
           for _ in range(8)]
    assert its == [1] * 8


def test_iterations_fall_as_r_grows():
    """Paper, Table 1 and Fig. 5: the bar bent 180 degrees converges faster for larger r."""
    m = bar()
    h, t = bar_bend(m, 180)
    its = [Deformer(m, h, rings=r, weights="cotan").solve(t).iterations for r in (1, 2, 4, 6, 10)]
    assert all(a > b for a, b in zip(its, its[1:])), its


def test_warm_start_and_result_fields():
    m = bar()
    h, t = bar_bend(m, 90)
    d = Deformer(m, h, rings=2)
    res = d.solve(t)
    f0 = d.timings["factorisation_ms"]
    assert res.vertices.shape == (1154, 3) and res.rotations.shape == (1154, 3, 3)
    assert res.vertex_energy.shape == (1154,) and res.vertex_energy.min() >= 0
    assert res.energy == pytest.approx(res.vertex_energy.sum())
    assert set(res.timings) >= {"neighbourhood_ms", "factorisation_ms", "global_ms_per_iter",
                                "local_ms_per_iter", "iterations", "total_s"}
    # same targets again from the result: already converged, stops at once
    again = d.solve(t, init=res.vertices)
    assert again.iterations <= 2 and again.converged
    # a small further drag, warm-started, takes fewer iterations than from scratch
    h2, t2 = bar_bend(m, 100)
    warm = d.solve(t2, init=res.vertices)
    cold = d.solve(t2)
    assert warm.iterations < cold.iterations
    assert d.timings["factorisation_ms"] == f0  # targets changed, no refactorisation


def test_laplacian_init_starts_lower():
    m = bar()
    h, t = bar_bend(m, 180)
    d = Deformer(m, h, rings=1)
    a = d.solve(t, init="identity", max_iter=1, tol=0)
    b = d.solve(t, init="laplacian", max_iter=1, tol=0)
    assert b.history[0] < a.history[0]


def test_callback_stops():
    m = bar()
    h, t = bar_bend(m, 180)
    seen = []
    res = Deformer(m, h).solve(t, callback=lambda i, e, P: seen.append(e) or i >= 3)
    assert res.iterations == 3 and len(seen) == 3 and not res.converged
    assert seen == res.history


@pytest.mark.parametrize("energy", ["rring", "embedded"])
def test_progress_sees_each_energy_and_stops_without_copying_the_shape(energy, monkeypatch):
    # progress(iteration, energy): the same energies as the history, the same solve as
    # without it (bitwise), True ends it; the r-ring loop never gathers the shape for it
    from arapkit.arap.backends.cpu import CPUBackend

    m = bar()
    h, t = bar_bend(m, 120)
    d = Deformer(m, h, energy=energy)
    plain = d.solve(t, max_iter=30)
    if energy == "rring":
        def refuse(*_):
            raise AssertionError("the shape was gathered for progress alone")

        monkeypatch.setattr(CPUBackend, "gather", staticmethod(refuse))
    seen = []
    res = d.solve(t, max_iter=30, progress=lambda i, e: seen.append((i, e)) and False)
    assert seen == list(enumerate(res.history, start=1))
    assert res.history == plain.history
    np.testing.assert_array_equal(res.vertices, plain.vertices)
    cut = d.solve(t, progress=lambda i, e: i >= 3)
    assert cut.iterations == 3 and not cut.converged and cut.history == plain.history[:3]
    monkeypatch.undo()
    # with a callback too: the callback first, and its stop ends the solve before progress
    calls = []
    both = d.solve(t, callback=lambda i, e, P: calls.append(("cb", i)) or i >= 2,
                   progress=lambda i, e: calls.append(("progress", i)) and False)
    assert both.iterations == 2
    assert calls == [("cb", 1), ("progress", 1), ("cb", 2)]


@pytest.mark.parametrize("device", ["cpu", "torch-cpu"])
def test_callback_sees_each_iterations_positions_in_the_callers_units(device):
    # a mesh far from unit size (the solver works in units of a power of two) and in the
    # caller's vertex order: the last positions seen are the result's, bitwise, and every
    # call gets its own array
    if device == "torch-cpu":
        pytest.importorskip("torch", reason="the torch extra is not installed")
    m0 = bar()
    m = Mesh(m0.vertices * 37.0 + 5.0, m0.faces)
    h, t = bar_bend(m, 90)
    seen = []
    res = Deformer(m, h, device=device).solve(
        t, max_iter=4, tol=0, callback=lambda i, e, P: seen.append(P) and False)
    assert len(seen) == 4 and len({id(P) for P in seen}) == 4
    assert not np.array_equal(seen[0], seen[-1])
    np.testing.assert_array_equal(seen[-1], res.vertices)


def test_component_without_handle():
    a = bar(length=2.0, segments=(10, 2, 2))
    V = np.vstack([a.vertices, a.vertices + [0, 5, 0]])
    F = np.vstack([a.faces, a.faces + a.n_vertices])
    m = Mesh(V, F, name="two")
    h, t = bar_bend(a, 90)
    d = Deformer(m, h, free_components="fix")
    assert any("without a handle" in n and f"vertex {a.n_vertices}" in n for n in d.notes)
    res = d.solve(t)
    assert np.array_equal(res.vertices[a.n_vertices:], V[a.n_vertices:])
    with pytest.raises(InputError, match=f"1 connected component.*vertex {a.n_vertices}"):
        Deformer(m, h, free_components="error")
    # the default: the free bar moves rigidly with its neighbours; same solve otherwise
    f = Deformer(m, h)
    assert any("move rigidly with the nearest part" in n for n in f.notes)
    follow = f.solve(t)
    n = a.n_vertices
    assert follow.history == res.history
    np.testing.assert_array_equal(follow.vertices[:n], res.vertices[:n])
    B0, B1 = V[n:], follow.vertices[n:]
    D0 = np.linalg.norm(B0[:, None] - B0[None], axis=2)
    D1 = np.linalg.norm(B1[:, None] - B1[None], axis=2)
    assert np.abs(D1 - D0).max() < 1e-9  # rigid
    assert np.abs(B1 - B0).max() > 0.1  # and moved with the bent bar
    # its rotation is the one reported for every vertex of it
    R = follow.rotations[n:]
    assert np.abs(R - R[0]).max() < 1e-12
    np.testing.assert_allclose((B0 - B0.mean(0)) @ R[0].T, B1 - B1.mean(0), atol=1e-9)


def test_bad_handles_and_targets():
    m = bar()
    with pytest.raises(InputError, match="handle 1 is vertex 5000, out of range"):
        Deformer(m, [0, 5000])
    with pytest.raises(InputError, match="vertex 3 is listed twice"):
        Deformer(m, [3, 3])
    with pytest.raises(InputError, match="no handle"):
        Deformer(m, [])
    d = Deformer(m, [0, 1])
    with pytest.raises(InputError, match=r"expected shape \(2, 3\)"):
        d.solve(np.zeros((3, 3)))
    with pytest.raises(InputError, match="handle 1 .*vertex 1.* not finite"):
        d.solve([[0, 0, 0], [np.nan, 0, 0]])
    with pytest.raises(InputError, match="unknown init"):
        Deformer(m, [0], init="zero")


def test_obtuse_real_mesh_factorises_and_clamp_keeps_rest():
    m = load_mesh(data_path("meshes", "hand.off"))
    h = np.arange(0, m.n_vertices, 50)
    assert (edge_weights(m, "cotan") < 0).any()
    res = Deformer(m, h, weights="cotan-clamped").solve(m.vertices[h])
    assert np.abs(res.vertices - m.vertices).max() < 1e-10 * m.bounding_box_diagonal
    d = Deformer(m, h, weights="cotan")
    res = d.solve(m.vertices[h], max_iter=3)
    assert np.isfinite(res.vertices).all()
    # the drift is real (rest is not a minimum) and the deformer says so
    assert res.energy < 0 and np.abs(res.vertices - m.vertices).max() > 1e-3
    assert any("not an energy minimum" in n and "cotan-clamped" in n for n in d.notes)
    assert not Deformer(m, h, weights="cotan-clamped").notes


def test_indefinite_system_names_remedy():
    import scipy.sparse as sp

    from arapkit.methods.deformer import CholeskyFactor

    with pytest.raises(InputError, match="not positive definite.*cotan-clamped"):
        CholeskyFactor(sp.csr_matrix(np.array([[1.0, 2.0], [2.0, 1.0]])), "m.off",
                       "; use weights='cotan-clamped'")


def test_bar_r1_bends_smoothly():
    """Rotations along the bar's bottom centre line turn steadily from 0 to 180 degrees.

    Guards the rank-one tie-break of the rotation kernel: an arbitrary pick among equally
    good rotations makes r = 1 kink at a few cross-sections instead of bending evenly.
    """
    m = bar()
    h, t = bar_bend(m, 180)
    res = Deformer(m, h, rings=1, weights="cotan").solve(t)
    V = m.vertices
    line = np.flatnonzero((np.abs(V[:, 1]) < 1e-9) & (np.abs(V[:, 2] + 0.2) < 1e-9))
    line = line[np.argsort(V[line, 0])]
    R = res.rotations[line]
    theta = np.degrees(np.arctan2(R[:, 2, 0], R[:, 0, 0]))
    assert np.all(np.diff(theta) > 0), np.diff(theta).min()
    assert theta[0] < 5 and theta[-1] > 175
    assert np.abs(R[:, 1, 1] - 1).max() < 1e-6  # every turn is about the y axis


def test_local_step_in_blocks_matches_whole_array_definitions():
    # the fused local step works through each chunk in blocks of _BLOCK vertices; on two
    # threads a 30K-vertex bar has chunks of several blocks and a short last one
    import numba

    from arapkit.arap.backends.cpu import _BLOCK, CPUBackend
    from arapkit.arap.problem import ARAPProblem

    m = bar(length=20.0, segments=(500, 12, 12))
    h, t = bar_bend(m, 60)
    p = ARAPProblem.from_mesh(m, h)
    threads = numba.get_num_threads()
    numba.set_num_threads(min(2, threads))
    try:
        be = CPUBackend(p).bind(p)
    finally:
        numba.set_num_threads(threads)
    sizes = np.diff(be.chunk_ptr)
    assert sizes.max() > 2 * _BLOCK and (sizes % _BLOCK).any()
    rng = np.random.default_rng(0)
    n = p.n_vertices
    P = p.vertices + 0.05 * rng.standard_normal((n, 3))
    R = np.empty((n, 3, 3))
    E = be.local(P, R)
    rhs = np.empty((len(p.elimination.free), 3))
    be.rhs(np.zeros_like(rhs), rhs)
    # covariances S_k = sum_v c_kv (p_v - p_k)^T and rotations by NumPy's SVD
    nbh = p.energy.nbh
    k = np.repeat(np.arange(n), np.diff(nbh.disk_ptr))
    S = np.einsum("ta,tb->tab", nbh.disk_coef, P[nbh.disk_idx] - P[k])
    S = np.stack([np.bincount(k, S[:, a, b], n) for a in range(3) for b in range(3)],
                 axis=1).reshape(n, 3, 3)
    U, _, Vt = np.linalg.svd(S)
    flip = np.linalg.det(np.swapaxes(Vt, 1, 2) @ np.swapaxes(U, 1, 2)) < 0
    U[flip, :, 2] *= -1
    R_ref = np.swapaxes(Vt, 1, 2) @ np.swapaxes(U, 1, 2)
    np.testing.assert_allclose(R, R_ref, atol=1e-9)
    # the energy against the edge-by-edge sum, the right-hand side b_v = sum_k R_k c_kv
    assert E == pytest.approx(be.vertex_energy(P, R_ref).sum(), rel=1e-9)
    b = np.einsum("tab,tb->ta", R_ref[k], nbh.disk_coef)
    b = np.stack([np.bincount(nbh.disk_idx, b[:, a], n) for a in range(3)], axis=1)
    np.testing.assert_allclose(rhs, b[p.elimination.free], atol=1e-9 * np.abs(b).max())


@pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="malloc_trim is glibc's")
def test_return_free_memory_hands_freed_heap_pages_back():
    # glibc keeps freed arrays below its (raised) mmap threshold in its heap; the call
    # after a factorisation must give them back. A fresh interpreter: a clean heap.
    code = textwrap.dedent("""
        import numpy as np
        from arapkit.arap.constraints import return_free_memory
        def rss():
            with open("/proc/self/statm") as f:
                return int(f.read().split()[1]) * 4096 / 2**20
        big = np.ones(30 * 2**17)      # freeing 30 MiB raises the threshold above 4 MiB
        del big
        keep, pins = [], []
        for _ in range(60):            # 60 x 4 MiB from the heap, each pinned by 128 KiB
            keep.append(np.ones(2**19))
            pins.append(np.ones(2**14))
        del keep
        before = rss()
        return_free_memory()
        print(before - rss())
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, env={**os.environ, "PYTHONPATH": SRC})
    assert float(out.stdout) > 150  # MiB of the 240 freed


def test_only_triangle_energies_keep_the_permuted_triangles():
    # an r-ring problem reads edges only: its internal graph drops the faces (80 MB at
    # 1.75M vertices); spokes-and-rims and SR-ARAP keep them, renumbered
    from arapkit.arap.problem import ARAPProblem

    m = bar(length=3.0, segments=(15, 2, 2))
    h, _ = bar_bend(m, 90)
    assert ARAPProblem.from_mesh(m, h).graph.faces is None
    for energy in ("spokes-and-rims", "sr-arap"):
        p = ARAPProblem.from_mesh(m, h, energy=energy)
        np.testing.assert_array_equal(p.perm[p.graph.faces], m.faces)
        np.testing.assert_array_equal(p.graph.face_edges, m.face_edges)


def test_many_followers_each_take_their_anchors_kabsch_motion():
    """A scan's floating specks: every component without a handle is placed by the best
    rigid motion of its own anchors (checked one by one against scipy's Kabsch), rotations
    included, and the compiled pass leaves every other vertex alone."""
    from scipy.spatial.transform import Rotation

    from arapkit.arap.constraints import Followers

    a = bar(length=2.0, segments=(10, 2, 2))
    rng = np.random.default_rng(3)
    k = 60
    centres = a.vertices[rng.integers(0, a.n_vertices, k)] + rng.normal(0, 0.05, (k, 3))
    specks = (centres[:, None] + rng.normal(0, 0.02, (k, 3, 3))).reshape(-1, 3)
    V = np.vstack([a.vertices, specks])
    F = np.vstack([a.faces, a.n_vertices + np.arange(3 * k).reshape(-1, 3)])
    m = Mesh(V, F, name="specks")
    free = np.arange(a.n_vertices, len(V))
    f = Followers.of(m, free)
    P = V.copy()
    x = V[: a.n_vertices, 0]  # a smooth bend of the bar: each speck's anchors disagree a bit
    P[: a.n_vertices, 1] += 0.3 * x**2
    P[: a.n_vertices, 2] += 0.1 * np.sin(3 * x)
    R = np.tile(np.eye(3), (len(V), 1, 1))
    before = P[: a.n_vertices].copy()
    f.apply(P, R)
    assert np.array_equal(P[: a.n_vertices], before)
    assert int(f.group.max()) + 1 == k
    for g in range(k):
        anchors = f.anchors[f.anchor_group == g]
        src, dst = V[anchors], P[anchors]
        rot = Rotation.align_vectors(dst - dst.mean(0), src - src.mean(0))[0].as_matrix()
        mine = f.vertices[f.group == g]
        want = (V[mine] - src.mean(0)) @ rot.T + dst.mean(0)
        assert np.abs(P[mine] - want).max() < 1e-9, g
        assert np.abs(R[mine] - rot).max() < 1e-9, g


def test_followers_bind_each_part_to_its_nearest_anchors_by_brute_force():
    """Who follows whom, against brute-force distances: each free part of two or more
    vertices (parts of several sizes, their vertices scattered through the numbering)
    follows the nearest anchored vertex of each of its vertices and the ``k`` nearest its
    centroid; single free vertices follow nothing."""
    from arapkit.arap.constraints import Followers

    a = bar(length=2.0, segments=(6, 2, 2))
    b = bar(length=0.5, segments=(2, 1, 1))
    rng = np.random.default_rng(5)
    parts_v = [a.vertices, b.vertices + [0.3, 0.6, 0.1]]
    parts_f = [a.faces, b.faces]
    for _ in range(30):  # single triangles about the bar
        parts_v.append(a.vertices[rng.integers(a.n_vertices)] + rng.normal(0, 0.1, (3, 3)))
        parts_f.append(np.array([[0, 1, 2]]))
    parts_v.append(rng.normal(0, 0.5, (4, 3)))  # isolated vertices: in no face
    offsets = np.cumsum([0] + [len(v) for v in parts_v])
    V = np.vstack(parts_v)
    F = np.vstack([f + o for f, o in zip(parts_f, offsets)])
    perm = rng.permutation(len(V))  # the parts' vertices scattered through the numbering
    where = np.empty_like(perm)
    where[perm] = np.arange(len(V))
    m = Mesh(V[perm], where[F], name="parts")
    anchored = np.sort(where[: a.n_vertices])
    free = np.setdiff1d(np.arange(len(V)), anchored)
    k = 8
    f = Followers.of(m, free, k=k)
    labels = m.component_labels
    followed = 0
    for c in np.unique(labels[free]):
        mine = np.flatnonzero(labels == c)
        got = f.vertices[f.group == f.group[np.flatnonzero(f.vertices == mine[0])]] \
            if mine[0] in f.vertices else np.zeros(0, int)
        if len(mine) < 2:
            assert len(got) == 0
            continue
        followed += 1
        assert np.array_equal(got, mine)
        g = f.group[np.flatnonzero(f.vertices == mine[0])[0]]
        d = np.linalg.norm(m.vertices[mine][:, None] - m.vertices[anchored][None], axis=2)
        dc = np.linalg.norm(m.vertices[anchored] - m.vertices[mine].mean(0), axis=1)
        want = np.union1d(anchored[d.argmin(1)], anchored[np.argsort(dc)[:k]])
        assert np.array_equal(f.anchors[f.anchor_group == g], want), c
    assert followed == 31 and int(f.group.max()) + 1 == followed
