"""Other ARAP methods on the seam: spokes-and-rims (libigl oracle), SR-ARAP (CGAL oracle),
the plain edge-graph problem, and the options' errors."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from cgal_oracle import build_driver, run_cgal
from conftest import data_path

from arapkit import Deformer, InputError, Mesh, load_mesh
from arapkit.arap.problem import ARAPProblem
from arapkit.arap.solve import arap_solve
from arapkit.mesh.shapes import bar, bar_bend
from arapkit.mesh.weights import corner_cotangents, edge_weights


def bend_cylinder(m: Mesh, degrees: float = 60.0):
    """Hold the bottom 5 % of the cylinder, turn and shift the top 5 %."""
    V = m.vertices
    lo, hi = V[:, 0].min(), V[:, 0].max()
    L = hi - lo
    bot = np.flatnonzero(V[:, 0] < lo + 0.05 * L)
    top = np.flatnonzero(V[:, 0] > hi - 0.05 * L)
    h = np.concatenate([bot, top])
    th = np.radians(degrees)
    Rm = np.array([[np.cos(th), 0, -np.sin(th)], [0, 1, 0], [np.sin(th), 0, np.cos(th)]])
    c = V[top].mean(axis=0)
    T = V[h].copy()
    T[len(bot):] = (V[top] - c) @ Rm.T + c + np.array([0.0, 0.0, 0.3 * L])
    return h, T


@pytest.fixture(scope="module")
def cylinder():
    m = load_mesh(data_path("meshes", "cylinder.off"))
    return m, *bend_cylinder(m)


def brute_spokes_rims_energy(m: Mesh, P, R) -> float:
    """Chao et al.'s energy, triangle by triangle with half cotangents (libigl's form)."""
    V, F = m.vertices, m.faces
    cots = corner_cotangents(V, F)
    E = 0.0
    for t, f in enumerate(F):
        for c in range(3):
            i, j = f[(c + 1) % 3], f[(c + 2) % 3]  # the edge facing corner c
            for k in f:
                d = (P[i] - P[j]) - R[k] @ (V[i] - V[j])
                E += 0.5 * cots[t, c] * d @ d
    return E


# ---------------------------------------------------------------- spokes and rims


def test_spokes_and_rims_matches_libigl(cylinder):
    igl = pytest.importorskip("igl", reason="libigl is the test oracle for spokes-and-rims")
    m, h, T = cylinder
    V, F = m.vertices, m.faces
    data = igl.ARAPData()
    data.energy = igl.ARAP_ENERGY_TYPE_SPOKES_AND_RIMS
    data.max_iter = 600
    igl.arap_precomputation(V, F.astype(np.int64), 3, h.astype(np.int32), data)
    U0 = V.copy()
    U0[h] = T
    U = igl.arap_solve(T, data, U0)
    res = Deformer(m, h, weights="cotan", energy="spokes-and-rims").solve(T, tol=1e-10,
                                                                          max_iter=3000)
    diag = m.bounding_box_diagonal
    assert res.converged
    assert np.abs(U - res.vertices).max() < 2e-3 * diag
    assert np.abs(res.vertices - V).max() > 0.2 * diag  # it really moved


def test_spokes_and_rims_energy_is_chao_and_descends(cylinder):
    m, h, T = cylinder
    res = Deformer(m, h, weights="cotan", energy="spokes-and-rims").solve(T, max_iter=12, tol=0)
    ref = brute_spokes_rims_energy(m, res.vertices, res.rotations)
    assert res.energy == pytest.approx(ref, rel=1e-9)
    assert res.vertex_energy.sum() == pytest.approx(ref, rel=1e-9)
    H = np.array(res.history)
    assert np.all(np.diff(H) <= 1e-12 * H[0]) and H[-1] < 0.5 * H[0]


@pytest.mark.parametrize("energy", ["rring", "spokes-and-rims"])
def test_descent_methods_never_rise_on_the_bar(energy):
    m = bar()
    h, t = bar_bend(m, 180)
    res = Deformer(m, h, energy=energy).solve(t, tol=1e-7, max_iter=120)
    H = np.array(res.history)
    assert len(H) > 10
    assert np.all(np.diff(H) <= 1e-10 * H[0]), np.diff(H).max()
    # with acceleration (safeguarded) the history stays monotone too
    fast = Deformer(m, h, energy=energy, accelerate=True).solve(t, tol=1e-7, max_iter=120)
    assert np.all(np.diff(fast.history) <= 1e-10 * H[0])


# ---------------------------------------------------------------- SR-ARAP


@pytest.fixture(scope="session")
def cgal_driver(tmp_path_factory) -> Path:
    driver = build_driver(tmp_path_factory.mktemp("cgal"))
    if isinstance(driver, str):
        pytest.skip(driver)
    return driver


@pytest.mark.parametrize("alpha", [0.02, 0.5])
def test_sr_arap_matches_cgal(cgal_driver, cylinder, tmp_path, alpha):
    m, h, T = cylinder
    # CGAL clamps negative cotangents to 0; on this mesh none is negative, so its weights
    # are exactly arapkit's "cotan"
    assert corner_cotangents(m.vertices, m.faces).min() >= 0
    U = run_cgal(cgal_driver, data_path("meshes", "cylinder.off"), h, T, "sre", alpha, tmp_path)
    res = Deformer(m, h, weights="cotan", energy="sr-arap", sr_alpha=alpha).solve(
        T, tol=1e-12, max_iter=20000)
    diag = m.bounding_box_diagonal
    assert res.converged
    assert np.abs(U - res.vertices).max() < 2e-3 * diag
    # and the smoothness term matters: plain ARAP is further away than the tolerance
    plain = Deformer(m, h, weights="cotan").solve(T, tol=1e-12, max_iter=5000)
    assert np.abs(plain.vertices - res.vertices).max() > 10 * np.abs(U - res.vertices).max()


def test_spokes_and_rims_matches_cgal(cgal_driver, cylinder, tmp_path):
    m, h, T = cylinder
    U = run_cgal(cgal_driver, data_path("meshes", "cylinder.off"), h, T, "rims", 0.0, tmp_path)
    res = Deformer(m, h, weights="cotan", energy="spokes-and-rims").solve(T, tol=1e-12,
                                                                          max_iter=5000)
    assert np.abs(U - res.vertices).max() < 2e-3 * m.bounding_box_diagonal


@pytest.fixture(scope="module")
def obtuse_partial_roi(tmp_path_factory):
    """A sheared, jittered bar (many obtuse corners, edges with both opposite angles obtuse)
    posed as a ``.sel`` would be: the left end outside the ROI (status 0), the right end the
    control vertices (status 2, turned 90 degrees and shifted), the rest the ROI (1)."""
    from arapkit.io import save_mesh

    b = bar(length=3.0, segments=(15, 3, 3))
    rng = np.random.default_rng(1)
    V = b.vertices.copy()
    V[:, 0] += 0.6 * V[:, 1] + 0.03 * rng.standard_normal(len(V))
    V[:, 1:] += 0.02 * rng.standard_normal((len(V), 2))
    m = Mesh(V, b.faces, name="obtuse bar")
    path = tmp_path_factory.mktemp("obtuse") / "obtuse.off"
    save_mesh(path, V, m.faces)
    x = b.vertices[:, 0]
    outside, control = np.flatnonzero(x < 0.5), np.flatnonzero(x > 2.8)
    th = np.radians(90)
    Q = np.array([[1, 0, 0], [0, np.cos(th), -np.sin(th)], [0, np.sin(th), np.cos(th)]])
    c = V[control].mean(axis=0)
    moved = (V[control] - c) @ Q.T + c + [0.3, 0.0, 0.5]
    roi = np.setdiff1d(np.arange(m.n_vertices), outside)
    return m, path, outside, control, moved, roi


# CGAL's problem in arapkit's terms, per CGAL tag: energy, weights, whether sr_roi is needed
CGAL_POSED = {"sre": ("sr-arap", "cotan-clamped-each", True),
              "arap": ("rring", "cotan-clamped-each", False),
              "rims": ("spokes-and-rims", "cotan", False)}


@pytest.mark.parametrize("tag", ["sre", "arap", "rims"])
def test_cgal_problem_on_obtuse_mesh_with_partial_roi(cgal_driver, obtuse_partial_roi,
                                                       tmp_path, tag):
    m, path, outside, control, moved, roi = obtuse_partial_roi
    cots = corner_cotangents(m.vertices, m.faces)
    assert (cots < 0).sum() > 200  # obtuse enough for the weightings to differ
    # CGAL solves the ROI only; arapkit holds the vertices outside it as handles at rest
    U = run_cgal(cgal_driver, path, control, moved, tag, 0.02, tmp_path, roi=roi,
                 iterations=20000, tol=1e-14)
    h = np.concatenate([outside, control])
    T = np.concatenate([m.vertices[outside], moved])
    energy, weights, needs_roi = CGAL_POSED[tag]
    opts = {"sr_roi": roi} if needs_roi else {}
    diag = m.bounding_box_diagonal
    res = Deformer(m, h, weights=weights, energy=energy, **opts).solve(T, tol=1e-13,
                                                                       max_iter=20000)
    assert res.converged
    # reached: 6e-11 (sre), 1.7e-7 (arap), 1e-7 (rims)
    assert np.abs(U - res.vertices).max() < 1e-5 * diag
    assert np.abs(U - m.vertices).max() > 0.1 * diag  # it really moved
    # the default weighting, posed without the ROI, is another problem: 1.5e-3 to 1e-2 away
    default = Deformer(m, h, energy=energy).solve(T, tol=1e-13, max_iter=20000)
    assert np.abs(U - default.vertices).max() > 1e-3 * diag
    if needs_roi:  # and CGAL's weights alone are not enough: 1.9e-3 away
        whole = Deformer(m, h, weights=weights, energy=energy).solve(T, tol=1e-13,
                                                                     max_iter=20000)
        assert np.abs(U - whole.vertices).max() > 1e-3 * diag


def test_sr_roi_coupling_is_cgals_region_of_solution():
    """Brute force: with sr_roi the coupling keeps (k, j) iff both lie in the ROI or on its
    one-ring, with CGAL's coefficient alpha A / (full degree of k)."""
    m = bar(length=2.0, segments=(8, 2, 2))
    x = m.vertices[:, 0]
    roi = np.flatnonzero(x > 1.0)
    h = np.flatnonzero((x <= 1.0) | (x > 1.9))
    d = Deformer(m, h, energy="sr-arap", sr_alpha=0.3, sr_roi=roi, reorder=False)
    indptr, indices, rc_w = d.problem.energy.coupling
    got = {(k, int(j)): rc_w[p] for k in range(m.n_vertices)
           for p, j in zip(range(indptr[k], indptr[k + 1]), indices[indptr[k]:indptr[k + 1]])}
    nbrs = [set() for _ in range(m.n_vertices)]
    for i, j in m.edges:
        nbrs[i].add(int(j))
        nbrs[j].add(int(i))
    solved = set(roi.tolist()).union(*(nbrs[v] for v in roi))
    V, F = m.vertices, m.faces
    area = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]),
                                axis=1).sum()
    area /= d.problem.scale ** 2  # the problem lives in units of its own size
    want = {(k, j): 0.3 * area / len(nbrs[k]) for k in range(m.n_vertices) for j in nbrs[k]
            if k in solved and j in solved}
    assert got.keys() == want.keys() and len(want) < 2 * len(m.edges)
    assert all(got[key] == pytest.approx(want[key], rel=1e-12) for key in want)


def test_sr_roi_errors():
    m = bar(length=2.0, segments=(8, 2, 2))
    x = m.vertices[:, 0]
    roi = np.flatnonzero(x > 1.0)
    h = np.flatnonzero((x <= 1.0) | (x > 1.9))
    with pytest.raises(InputError, match=r"vertex 9 is outside sr_roi but not a handle"):
        Deformer(m, h[h != 9], energy="sr-arap", sr_roi=roi)
    with pytest.raises(InputError, match=rf"sr_roi: vertex {m.n_vertices} is out of range"):
        Deformer(m, h, energy="sr-arap", sr_roi=[0, m.n_vertices])
    with pytest.raises(InputError, match="sr_roi must be a non-empty list of vertex ids"):
        Deformer(m, h, energy="sr-arap", sr_roi=[0.5])
    with pytest.raises(InputError, match="sr_roi is an option of energy 'sr-arap', not 'rring'"):
        Deformer(m, h, sr_roi=roi)


def test_sr_alpha_zero_is_spokes_arap():
    m = bar()
    h, t = bar_bend(m, 120)
    a = Deformer(m, h, energy="sr-arap", sr_alpha=0).solve(t, max_iter=30, tol=0)
    b = Deformer(m, h, rings=1).solve(t, max_iter=30, tol=0)
    assert np.abs(a.vertices - b.vertices).max() < 1e-12 * m.bounding_box_diagonal
    assert np.allclose(a.history, b.history, rtol=1e-12, atol=0)


def test_sr_energy_includes_rotation_term():
    m = bar()
    h, t = bar_bend(m, 120)
    res = Deformer(m, h, energy="sr-arap", sr_alpha=0.1).solve(t, tol=1e-10, max_iter=3000)
    # by hand: spokes ARAP of the result plus alpha A / deg_k sum_j |R_k - R_j|^2
    arap = Deformer(m, h, rings=1)
    E_arap = arap.vertex_energy(res.vertices, res.rotations).sum()
    V, F = m.vertices, m.faces
    area = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]),
                                axis=1).sum()
    deg = np.asarray(m.adjacency.sum(axis=1)).ravel()
    R = res.rotations
    i, j = m.edges[:, 0], m.edges[:, 1]
    d = ((R[i] - R[j]) ** 2).sum(axis=(1, 2))
    smooth = 0.1 * area * (d / deg[i] + d / deg[j]).sum()
    assert res.vertex_energy.sum() == pytest.approx(E_arap + smooth, rel=1e-6)
    # the reported energy pairs R_k with the neighbours' previous rotations: equal once
    # converged, up to what the slow Jacobi sweep leaves at tol = 1e-10
    assert res.energy == pytest.approx(E_arap + smooth, rel=1e-4)


# ---------------------------------------------------------------- the problem on a graph


def test_problem_from_graph_equals_mesh_solve():
    m = bar()
    h, t = bar_bend(m, 90)
    w = edge_weights(m)
    ref = Deformer(m, h, rings=2).solve(t, max_iter=15, tol=0)
    p = ARAPProblem.from_graph(m.vertices, m.edges, w, h, rings=2, name="bar graph")
    res = arap_solve(p, t, max_iter=15, tol=0)
    assert np.abs(res.vertices - ref.vertices).max() < 1e-12 * m.bounding_box_diagonal
    assert np.allclose(res.history, ref.history, rtol=1e-12, atol=0)


def test_problem_with_rings_equals_a_fresh_build():
    m = bar()
    h, t = bar_bend(m, 90)
    w = edge_weights(m)
    rings = np.where(m.vertices[:, 0] > 3.5, 1, 4)
    fresh = arap_solve(ARAPProblem.from_graph(m.vertices, m.edges, w, h, rings=rings), t,
                       max_iter=10, tol=0)
    p = ARAPProblem.from_graph(m.vertices, m.edges, w, h, rings=2)
    arap_solve(p, t, max_iter=2, tol=0)
    res = arap_solve(p.with_rings(rings), t, max_iter=10, tol=0)
    assert np.abs(res.vertices - fresh.vertices).max() < 1e-12 * m.bounding_box_diagonal
    with pytest.raises(InputError, match="vertex 0 has r = 0"):
        p.with_rings(np.zeros(m.n_vertices, int))


def test_problem_from_graph_tet_rigid():
    """A two-tet graph (no triangles) follows a rigid motion of three handles exactly."""
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]], dtype=float)
    E = np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3], [1, 4], [2, 4], [3, 4]])
    th = 0.7
    Q = np.array([[np.cos(th), -np.sin(th), 0], [np.sin(th), np.cos(th), 0], [0, 0, 1]])
    moved = V @ Q.T + [0.5, -2.0, 1.0]
    p = ARAPProblem.from_graph(V, E, np.ones(len(E)), [0, 1, 2], rings=2)
    res = arap_solve(p, moved[[0, 1, 2]], tol=1e-14, max_iter=500)
    assert np.abs(res.vertices - moved).max() < 1e-6
    assert np.abs(res.vertices - V).max() > 1.0  # it moved


def test_problem_from_graph_rejects_bad_graphs():
    V = np.eye(3)
    with pytest.raises(InputError, match="edge 1 .* loop or out of range"):
        ARAPProblem.from_graph(V, [[0, 1], [1, 1]], [1.0, 1.0], [0])
    with pytest.raises(InputError, match="listed twice"):
        ARAPProblem.from_graph(V, [[0, 1], [1, 0]], [1.0, 1.0], [0])
    with pytest.raises(InputError, match="2 finite numbers"):
        ARAPProblem.from_graph(V, [[0, 1], [1, 2]], [1.0, np.nan], [0])


# ---------------------------------------------------------------- options


def test_bad_method_options():
    m = bar()
    with pytest.raises(InputError, match="unknown energy 'nonsense'"):
        Deformer(m, [0], energy="nonsense")
    with pytest.raises(InputError, match="sr_alpha must be a finite number >= 0, got -1"):
        Deformer(m, [0], energy="sr-arap", sr_alpha=-1)
    with pytest.raises(InputError, match="sr_alpha is an option of energy 'sr-arap'"):
        Deformer(m, [0], sr_alpha=0.1)
    with pytest.raises(InputError, match="no rigidity map"):
        Deformer(m, [0], rings=2, energy="spokes-and-rims")
    with pytest.raises(InputError, match="descent methods; energy 'sr-arap' is not one"):
        Deformer(m, [0], energy="sr-arap", accelerate=True)


def cli(*args):
    return subprocess.run([sys.executable, "-m", "arapkit.cli", *map(str, args)],
                          capture_output=True, text=True, timeout=600,
                          env={**os.environ, "PYTHONWARNINGS": "ignore"})


@pytest.fixture(scope="module")
def bar_case(tmp_path_factory):
    import json

    from arapkit.io import save_mesh

    d = tmp_path_factory.mktemp("methods")
    m = bar()
    h, t = bar_bend(m, 90)
    save_mesh(d / "bar.off", m.vertices, m.faces)
    (d / "h.json").write_text(json.dumps([
        {"name": "all", "indices": h.tolist(), "targets": t.tolist()}]))
    return d, m, h, t


@pytest.mark.parametrize("argv, fragment", [
    (["--energy", "nonsense"], "unknown energy 'nonsense'"),
    (["--energy", "sr-arap", "--sr-alpha", "-0.5"], "sr_alpha must be a finite number >= 0"),
    (["--energy", "sr-arap", "--sr-alpha", "abc"], "sr_alpha must be a number"),
    (["--energy", "spokes-and-rims", "--rings", "3"], "no rigidity map"),
])
def test_cli_bad_method_exit_2(bar_case, argv, fragment):
    d, *_ = bar_case
    proc = cli("deform", d / "bar.off", "--handles", d / "h.json", "-o", d / "out.ply", *argv)
    assert proc.returncode == 2, proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.startswith("arapkit: error: ")]
    assert len(lines) == 1 and fragment in lines[0] and "Traceback" not in proc.stderr
    assert not (d / "out.ply").exists()


def test_cli_energy_option_runs_the_method(bar_case):
    d, m, h, t = bar_case
    proc = cli("deform", d / "bar.off", "--handles", d / "h.json", "-o", d / "sr.off",
               "--energy", "sr-arap", "--sr-alpha", "0.05", "--report", d / "sr.json", "-q")
    assert proc.returncode == 0, proc.stderr
    import json

    rep = json.loads((d / "sr.json").read_text())
    assert rep["method"] == {"energy": "sr-arap", "sr_alpha": 0.05}
    ref = Deformer(m, h, energy="sr-arap", sr_alpha=0.05).solve(t)
    got = load_mesh(d / "sr.off").vertices
    assert np.abs(got - ref.vertices).max() < 1e-6 * m.bounding_box_diagonal


def test_cli_offers_cgal_weights(bar_case):
    d, m, h, t = bar_case
    proc = cli("deform", d / "bar.off", "--handles", d / "h.json", "-o", d / "each.off",
               "--weights", "cotan-clamped-each", "-q")
    assert proc.returncode == 0, proc.stderr
    ref = Deformer(m, h, weights="cotan-clamped-each").solve(t)
    got = load_mesh(d / "each.off").vertices
    assert np.abs(got - ref.vertices).max() < 1e-6 * m.bounding_box_diagonal


# ---------------------------------------------------------------- embedded deformation


def test_embedded_meets_handles_descends_and_does_not_fold():
    from arapkit.mesh.quality import folded_edge_fraction

    m = bar()
    h, t = bar_bend(m, 90)
    res = Deformer(m, h, energy="embedded").solve(t, tol=1e-8, max_iter=100)
    diag = m.bounding_box_diagonal
    assert res.converged and np.isfinite(res.vertices).all()
    # soft constraints (weight 100, the paper's): met to a small residual, not exactly
    assert np.linalg.norm(res.vertices[h] - t, axis=1).max() < 5e-3 * diag
    H = np.array(res.history)
    assert len(H) >= 2 and np.all(np.diff(H) <= 0)
    assert folded_edge_fraction(m, res.vertices) == 0.0
    free = np.setdiff1d(np.arange(m.n_vertices), h)
    assert np.abs(res.vertices[free] - m.vertices[free]).max() > 0.2 * diag  # it bent
    assert res.vertex_energy.shape == (m.n_vertices,) and res.vertex_energy.min() >= 0


def test_embedded_rigid_motion_is_exact():
    m = bar(length=3.0, segments=(15, 2, 2))
    th = 0.8
    Q = np.array([[np.cos(th), -np.sin(th), 0], [np.sin(th), np.cos(th), 0], [0, 0, 1]])
    Vr = m.vertices @ Q.T + [1.0, 2.0, 3.0]
    x = m.vertices[:, 0]
    h = np.flatnonzero((x < 0.25) | (x > 2.75))
    res = Deformer(m, h, energy="embedded", nodes=40).solve(Vr[h], tol=1e-12, max_iter=100)
    assert np.abs(res.vertices - Vr).max() < 1e-9 * m.bounding_box_diagonal
    assert res.energy < 1e-16


def test_embedded_node_option_checked(bar_case):
    m = bar()
    with pytest.raises(InputError, match="nodes must be at least 2, got 0"):
        Deformer(m, [0], energy="embedded", nodes=0)
    with pytest.raises(InputError, match="nodes is an option of energy 'embedded'"):
        Deformer(m, [0], nodes=10)
    d, *_ = bar_case
    proc = cli("deform", d / "bar.off", "--handles", d / "h.json", "-o", d / "out.ply",
               "--energy", "embedded", "--nodes", "0")
    assert proc.returncode == 2
    lines = [ln for ln in proc.stderr.splitlines() if ln.startswith("arapkit: error: ")]
    assert len(lines) == 1 and "nodes must be at least 2" in lines[0]


@pytest.mark.parametrize("method", ["spokes-and-rims", "sr-arap", "embedded"])
def test_editor_worker_runs_each_method(method):
    from arapkit.editor.state import SolverSettings
    from arapkit.editor.worker import SolveRequest, SolveWorker

    m = bar()
    h, t = bar_bend(m, 60)
    updates = []
    w = SolveWorker(updates.append)
    w.start()
    try:
        settings = SolverSettings(method=method, tol=1e-9, max_iter=5000)
        w.submit(SolveRequest(m, h, t, np.full(m.n_vertices, 3), settings))
        assert w.wait_idle(120.0)
    finally:
        w.stop()
    last = updates[-1]
    assert last.final and last.error is None, last.error
    # the worker warm-starts from its last shape: compare converged solutions
    ref = Deformer(m, h, energy=method).solve(t, tol=1e-9, max_iter=5000)
    assert np.abs(last.vertices - ref.vertices).max() < 1e-4 * m.bounding_box_diagonal
    assert last.vertex_energy is not None and last.vertex_energy.shape == (m.n_vertices,)


def _rigid_bar_case():
    m = bar(length=3.0, segments=(15, 2, 2))
    th = 0.8
    Q = np.array([[np.cos(th), -np.sin(th), 0], [np.sin(th), np.cos(th), 0], [0, 0, 1]])
    x = m.vertices[:, 0]
    return m, np.flatnonzero((x < 0.25) | (x > 2.75)), m.vertices @ Q.T + [1.0, 2.0, 3.0], Q


def test_embedded_init_positions_are_honoured():
    m, h, Vr, Q = _rigid_bar_case()
    d = Deformer(m, h, energy="embedded", nodes=40)
    # the rest shape is the identity start: the same run as no init
    cold = d.solve(Vr[h], tol=1e-12, max_iter=100)
    rest = d.solve(Vr[h], init=m.vertices, tol=1e-12, max_iter=100)
    # (fitted to round-off: the 1e-12 stopping test may then end elsewhere)
    assert np.allclose(rest.history[:3], cold.history[:3], rtol=1e-9)
    assert np.abs(rest.vertices - cold.vertices).max() < 1e-9 * m.bounding_box_diagonal
    assert cold.iterations > 1 and cold.history[0] > 1e-3  # a rotation is nonlinear
    # the solution itself (a rigid image, representable exactly) as init: done at once
    warm = d.solve(Vr[h], init=Vr, tol=1e-12, max_iter=100)
    assert warm.history[0] < 1e-20  # from identity: cold.history[0] > 1e-3
    assert np.abs(warm.vertices - Vr).max() < 1e-9 * m.bounding_box_diagonal
    # the fitted maps are the rigid motion itself (not merely maps that skin to Vr)
    A = d.embedded.fit_node_maps(Vr)[:, :9].reshape(-1, 3, 3)
    assert np.abs(A - Q).max() < 1e-8


def test_embedded_warm_start_and_laplacian_init():
    from arapkit.methods.laplacian import LaplacianEditor

    m = bar()
    h, t = bar_bend(m, 90)
    d = Deformer(m, h, energy="embedded", nodes=60)
    cold = d.solve(t, tol=1e-8)
    warm = d.solve(t, init=cold.vertices, tol=1e-8)
    assert warm.history[0] < cold.history[0] / 2  # starts near the previous result
    diag = m.bounding_box_diagonal
    assert np.abs(warm.vertices - cold.vertices).max() < 1e-3 * diag
    lap = Deformer(m, h, energy="embedded", nodes=60, init="laplacian").solve(t, tol=1e-8)
    start = LaplacianEditor(m, h, "uniform").solve(t)
    explicit = d.solve(t, init=start, tol=1e-8)
    assert np.allclose(lap.history, explicit.history, rtol=1e-12)
    assert abs(lap.history[0] - cold.history[0]) > 1e-3 * cold.history[0]


def test_embedded_bad_init_is_one_line_error():
    m = bar()
    d = Deformer(m, [0, 1], energy="embedded", nodes=20)
    for bad in (np.zeros((3, 3)), np.full(m.vertices.shape, np.nan)):
        with pytest.raises(InputError, match=r"^init: expected finite positions") as e:
            d.solve(m.vertices[[0, 1]], init=bad)
        assert "\n" not in str(e.value)


def test_registry_capabilities_of_local_global_methods_are_their_energies():
    """Descent, acceleration and the rigidity map of a local/global method are facts of its
    energy: the registry takes them from the energy's registration."""
    from arapkit.arap.energies import energy_info, energy_names
    from arapkit.methods.registry import methods

    lg = [m for m in methods() if m.local_global]
    assert {m.name for m in lg} == set(energy_names())
    for m in lg:
        en = energy_info(m.name)
        assert m.descent == en.descent and m.accelerate == en.descent
        assert m.rigidity_map == en.rigidity_map
    assert not energy_info("sr-arap").descent  # the Jacobi coupling can raise the energy
