"""ARAP dynamics with rigid parts and shared-rotation groups (issue 49, section 2: "per-vertex
r and rigid parts"): closed forms of implicit Euler, conservation laws, the ungrouped
simulation, and the doors.

Each test was seen to fail with the feature it covers broken (see the report of the
change that added it).
"""

from __future__ import annotations

import contextlib
import io
import json
import os

import numpy as np
import pytest

from arapkit import InputError, cli
from arapkit.mesh.groups import VertexGroups
from arapkit.mesh.mass import vertex_masses
from arapkit.mesh.shapes import bar
from arapkit.methods.dynamics import Keyframes, Simulator, simulate

G = np.array([0.0, 0.0, -9.81])


@pytest.fixture(scope="module")
def beam():
    """A 3 m bar, pinned at its left end, with a rigid part in its middle."""
    m = bar(length=3.0, segments=(30, 2, 2))
    V = m.vertices
    left = np.flatnonzero(V[:, 0] == 0)
    mid = np.flatnonzero(np.abs(V[:, 0] - 1.8) < 0.45)
    return m, left, mid, VertexGroups.from_lists([("middle", mid, True)], m.n_vertices)


def inner_edges(m, part):
    E = m.edges
    return E[np.isin(E, part).all(axis=1)]


def lengths(X, E):
    return np.linalg.norm(X[E[:, 0]] - X[E[:, 1]], axis=1)


def momentum(masses, v):
    return (masses[:, None] * v).sum(axis=0)


# --------------------------------------------------------------------- rigidity


def test_edge_lengths_inside_a_rigid_part_are_kept_at_every_frame(beam):
    m, left, mid, g = beam
    E = inner_edges(m, mid)
    L0 = lengths(m.vertices, E)
    tr = simulate(m, 21, dt=1 / 30, handles=left, gravity=G, groups=g, stiffness=2e3)
    assert tr.converged.all()
    stretch = max(np.abs(lengths(X, E) - L0).max() for X in tr.vertices)
    assert stretch < 1e-9
    # the same body without the part bends there (the test can fail)
    plain = simulate(m, 21, dt=1 / 30, handles=left, gravity=G, stiffness=2e3)
    assert max(np.abs(lengths(X, E) - L0).max() for X in plain.vertices) > 1e-4
    assert tr.parameters["groups"] == f"1 rigid part ({len(mid)} vertices)"


def test_anderson_extrapolates_the_parts_rotations_and_phi_never_rises(beam):
    """The accelerated iterate holds the parts' rotations: it takes far fewer iterations
    than the plain one for the same steps, and the step's objective still never rises."""
    m, left, mid, g = beam
    opts = dict(dt=1 / 30, handles=left, gravity=G, groups=g, stiffness=2e3, tol=1e-8)
    fast = Simulator(m, accelerate=True, **opts)
    slow = Simulator(m, accelerate=False, **opts)
    its = np.zeros((2, 8))
    for k in range(8):
        a, b = fast.step(), slow.step()
        its[:, k] = a.iterations, b.iterations
        assert a.converged and b.converged
        h = np.array(a.history)
        assert np.all(np.diff(h) <= 1e-12 * abs(h[0]))
        assert np.abs(a.positions - b.positions).max() < 1e-4 * m.bounding_box_diagonal
    assert its[0].sum() < 0.4 * its[1].sum()


# ----------------------------------------------------------------- closed forms


@pytest.mark.parametrize("whole", [True, False])
def test_a_free_rigid_part_falls_as_implicit_euler_says(beam, whole):
    """Implicit Euler's fall after n steps is g h^2 n (n + 1) / 2, for every vertex of a
    body that is one rigid part, or has one."""
    m, _, mid, g = beam
    if whole:
        g = VertexGroups.from_lists([("all", np.arange(m.n_vertices), True)], m.n_vertices)
    h, n = 0.05, 20
    tr = simulate(m, n + 1, dt=h, gravity=G, damping=0.0, groups=g)
    k = np.arange(n + 1)
    drop = tr.vertices - m.vertices[None]
    # a translation: no strain, no turn (round-off, grown by the steps through v)
    assert np.abs(drop - drop.mean(axis=1, keepdims=True)).max() < 1e-10 * m.bounding_box_diagonal
    fall = G * h * h * (k * (k + 1) / 2)[:, None]
    # round-off of the solves, grown by the steps (the ungrouped body's is the same size)
    assert np.abs(drop.mean(axis=1) - fall).max() < 1e-9 * np.abs(fall).max()
    assert np.all(tr.iterations == 1)  # started at the inertial prediction: exact


def test_a_rigid_part_with_no_forces_stays_at_rest(beam):
    m, left, mid, g = beam
    for handles in (None, left):
        tr = simulate(m, 31, dt=1 / 60, handles=handles, damping=0.0, groups=g)
        # round-off only, as the ungrouped body's (test_dynamics.py)
        assert np.abs(tr.vertices - m.vertices).max() < 1e-9 * m.bounding_box_diagonal
        assert np.abs(tr.kinetic).max() < 1e-12 and np.abs(tr.elastic).max() < 1e-12


def test_with_damping_the_total_energy_decreases(beam):
    """Kinetic + elastic + potential, each computed here from the frames (the elastic one
    by the ungrouped body's energy: a part changes what shapes are reached, not E)."""
    m, left, mid, g = beam
    sim = Simulator(m, left, dt=1 / 30, gravity=G, damping=2.0, groups=g, stiffness=2e3)
    tr = sim.run(31)
    plain = Simulator(m, left, dt=1 / 30, stiffness=2e3)
    M = vertex_masses(m)
    V = tr.vertices
    vel = np.diff(V, axis=0) * 30
    kin = np.concatenate([[0.0], 0.5 * (M[:, None] * vel ** 2).sum(axis=(1, 2))])
    pot = -(M[None, :] * (V @ G)).sum(axis=1)
    ela = np.array([plain.system.elastic_energy(X) for X in V])
    total = kin + pot + ela
    assert np.allclose(total, tr.energy + pot[0], rtol=0, atol=1e-8 * abs(total).max())
    assert total[-1] < total[1] < total[0]
    assert np.all(np.diff(total) <= 1e-9 * abs(total).max())


@pytest.mark.parametrize("whole", [True, False])
def test_a_thrown_body_keeps_its_linear_momentum(beam, whole):
    """Without gravity, damping or handles, the forces on the body sum to zero, so
    implicit Euler keeps sum_v m_v v_v exactly (not the angular momentum: it damps
    spin); a part turns about its centre of mass, so the iterations keep it too."""
    m, _, mid, g = beam
    if whole:
        g = VertexGroups.from_lists([("all", np.arange(m.n_vertices), True)], m.n_vertices)
    sim = Simulator(m, dt=1 / 30, damping=0.0, groups=g, stiffness=2e3)
    M = sim.masses
    c = (M[:, None] * m.vertices).sum(0) / M.sum()
    w = np.array([0.3, 2.0, 1.0])  # a spin, and a throw
    v0 = np.cross(w, m.vertices - c) + [1.0, 0.0, 3.0]
    sim.reset(velocities=v0)
    p0 = momentum(M, v0)
    E = inner_edges(m, mid)
    for _ in range(15):
        s = sim.step()
        assert s.converged and s.iterations > 1
        assert np.abs(momentum(M, s.velocities) - p0).max() < 1e-11 * np.abs(p0).max()
    assert np.abs(lengths(sim.positions, E) - lengths(m.vertices, E)).max() < 1e-9


def weighted_kabsch(A, B, w):
    """The rotation R minimising sum_v w_v |R A_v - B_v|^2 (A, B centred as wanted)."""
    U, _, Vt = np.linalg.svd((w[:, None] * A).T @ B)
    d = np.sign(np.linalg.det(Vt.T @ U.T))
    return Vt.T @ np.diag([1.0, 1.0, d]) @ U.T


@pytest.mark.parametrize("pivot", [False, True])
def test_a_rigid_bodys_step_is_the_mass_weighted_fit_of_the_inertial_prediction(beam, pivot):
    """A body that is one rigid part has no strain, so implicit Euler's step minimises
    sum_v m_v |R a_v + t - y_v|^2 alone: free, the mass-weighted Procrustes fit of the
    prediction y about its centre of mass; held by one vertex p (a pendulum), the fit of
    y - p about p. Computed here by an SVD, step by step."""
    m, *_ = beam
    V = m.vertices
    g = VertexGroups.from_lists([("all", np.arange(m.n_vertices), True)], m.n_vertices)
    h = 1 / 30
    pin = np.array([int(np.argmin(V[:, 0]))]) if pivot else None
    sim = Simulator(m, pin, dt=h, gravity=G, damping=0.0, groups=g, tol=1e-12)
    M = sim.masses
    c = (M[:, None] * V).sum(0) / M.sum()
    sim.reset(velocities=np.cross([0.5, 1.0, 2.0], V - c) + [0.0, 1.0, 0.0])
    for _ in range(10):
        x, v = sim.positions.copy(), sim.velocities.copy()
        y = x + h * v + h * h * G
        if pivot:
            p = V[pin[0]]
            R = weighted_kabsch(V - p, y - p, M)
            expect = (V - p) @ R.T + p
        else:
            yc = (M[:, None] * y).sum(0) / M.sum()
            R = weighted_kabsch(V - c, y - yc, M)
            expect = (V - c) @ R.T + yc
        s = sim.step()
        assert np.abs(s.positions - expect).max() < 1e-9 * m.bounding_box_diagonal


@pytest.mark.parametrize("rigid", [False, True])
def test_groups_of_one_vertex_each_are_the_ungrouped_simulation(beam, rigid):
    m, left, _, _ = beam
    n = m.n_vertices
    g = VertexGroups.from_ids(np.arange(n), n, rigid=rigid)
    # the same iterations: a fixed count, no extrapolation (whose choices round-off may
    # flip)
    opts = dict(dt=1 / 30, handles=left, gravity=G, stiffness=2e3, tol=0.0, max_iter=150,
                accelerate=False)
    a = simulate(m, 11, groups=g, **opts)
    b = simulate(m, 11, **opts)
    assert np.abs(a.vertices - b.vertices).max() < 1e-10


def test_shared_rotation_groups_fit_one_rotation_in_the_local_step(beam):
    """A shared-rotation group is libigl's G: one rotation for its members, the
    positions free (unlike a part, it stretches); the body is stiffer there."""
    m, left, mid, _ = beam
    g = VertexGroups.from_lists([("middle", mid, False)], m.n_vertices)
    opts = dict(dt=1 / 30, handles=left, gravity=G, stiffness=2e3)
    sim = Simulator(m, groups=g, **opts)
    s = sim.step()
    assert np.abs(s.rotations[mid] - s.rotations[mid[0]]).max() < 1e-15
    tr = simulate(m, 21, groups=g, **opts)
    plain = simulate(m, 21, **opts)
    E = inner_edges(m, mid)
    st = np.abs(lengths(tr.vertices[-1], E) - lengths(m.vertices, E)).max()
    sp = np.abs(lengths(plain.vertices[-1], E) - lengths(m.vertices, E)).max()
    assert 1e-6 < st < sp


@pytest.mark.parametrize("energy", ["rring", "spokes-and-rims"])
def test_touching_parts_mix_with_per_vertex_r_and_phi_never_rises(beam, energy):
    """Two parts joined by edges (fitted one after the other) beside a stiffer r = 3 end:
    both stay rigid and each step's objective falls at every iteration."""
    m, left, _, _ = beam
    V = m.vertices
    a = np.flatnonzero((V[:, 0] > 1.0) & (V[:, 0] < 1.55))
    b = np.flatnonzero((V[:, 0] > 1.55) & (V[:, 0] < 2.2))
    g = VertexGroups.from_lists([("a", a, True), ("b", b, True)], m.n_vertices)
    rings = np.where(V[:, 0] > 2.2, 3, 1) if energy == "rring" else 1
    sim = Simulator(m, left, rings, energy=energy, dt=1 / 30, gravity=G, groups=g,
                    stiffness=2e3)
    assert sim.system.parts.layout.colour.tolist() == [0, 1]
    for _ in range(12):
        s = sim.step()
        h = np.array(s.history)
        assert s.converged and np.all(np.diff(h) <= 1e-12 * abs(h[0]))
        for part in (a, b):
            E = inner_edges(m, part)
            assert np.abs(lengths(s.positions, E) - lengths(V, E)).max() < 1e-9
    assert np.abs(sim.positions - V).max() > 0.05


# --------------------------------------------------------------------- handles


def test_a_handle_inside_a_rigid_part_moves_the_whole_part(beam):
    m, left, _, _ = beam
    V = m.vertices
    tip = np.flatnonzero(V[:, 0] > 2.55)  # the right end, held by its end cap
    cap = np.flatnonzero(V[:, 0] == V[:, 0].max())
    g = VertexGroups.from_lists([("tip", tip, True)], m.n_vertices)
    handles = np.concatenate([left, cap])
    up = V[handles].copy()
    up[len(left):] += [0.0, 0.0, 0.6]
    keys = Keyframes([0.0, 0.5], [V[handles], up])
    tr = simulate(m, 31, dt=1 / 30, handles=handles, targets=keys, groups=g, stiffness=2e3)
    for k in range(len(tr.times)):
        lift = keys(tr.times[k])[len(left):] - V[cap]
        assert np.abs(tr.vertices[k][tip] - V[tip] - lift[0]).max() < 1e-9


def test_one_handle_in_a_part_makes_it_swing_about_it(beam):
    m, left, mid, g = beam
    h = np.concatenate([left, mid[:1]])
    tr = simulate(m, 16, dt=1 / 30, handles=h, gravity=G, groups=g, stiffness=2e3)
    E = inner_edges(m, mid)
    for X in tr.vertices:
        assert np.abs(lengths(X, E) - lengths(m.vertices, E)).max() < 1e-9
        assert np.abs(X[mid[0]] - m.vertices[mid[0]]).max() < 1e-12


def test_handles_no_rigid_motion_meets_name_the_part(beam):
    m, left, _, _ = beam
    V = m.vertices
    cap = np.flatnonzero(V[:, 0] == V[:, 0].max())
    g = VertexGroups.from_lists([("right end", np.flatnonzero(V[:, 0] > 2.55), True)],
                                m.n_vertices, source="parts.json")
    sim = Simulator(m, cap, groups=g)
    stretched = V[cap] * [1.0, 2.0, 2.0]
    with pytest.raises(InputError) as e:
        sim.step(stretched)
    msg = str(e.value)
    assert "\n" not in msg and "parts.json: rigid part 'right end'" in msg
    assert "no rigid motion meets its" in msg


def test_bad_groups_are_one_line_errors(beam):
    m, *_ = beam
    with pytest.raises(InputError) as e:
        Simulator(m, groups=np.zeros(m.n_vertices + 1, int))
    assert "\n" not in str(e.value) and str(m.n_vertices) in str(e.value)


# ------------------------------------------------------------------------ doors


def run_cli(*args, cwd):
    """The command line in-process in ``cwd``: (status, stdout, stderr)."""
    out, err = io.StringIO(), io.StringIO()
    here = os.getcwd()
    os.chdir(cwd)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            rc = cli.main([str(a) for a in args])
    finally:
        os.chdir(here)
    return rc, out.getvalue(), err.getvalue()


def test_cli_simulate_groups_keeps_the_part_rigid(tmp_path):
    from arapkit.io import save_mesh

    m = bar(length=3.0, segments=(30, 2, 2))
    save_mesh(tmp_path / "bar.off", m.vertices, m.faces)
    (tmp_path / "parts.json").write_text(json.dumps(
        [{"name": "middle", "box": {"min": [1.4, -1, -1], "max": [2.2, 1, 1]}, "rigid": True}]))
    (tmp_path / "pins.json").write_text(json.dumps(
        [{"name": "left", "box": {"min": [-0.1, -1, -1], "max": [0.01, 1, 1]}}]))
    r = run_cli("simulate", "bar.off", "--handles", "pins.json", "--groups", "parts.json",
                "--frames", "8", "--stiffness", "2000", "-o", "out.npz", cwd=tmp_path)
    assert r[0] == 0, r[2]
    assert "groups: 1 rigid part" in r[1]
    with np.load(tmp_path / "out.npz") as z:
        V = z["V"]
    part = np.flatnonzero((m.vertices[:, 0] >= 1.4) & (m.vertices[:, 0] <= 2.2))
    E = inner_edges(m, part)
    assert np.abs(V[-1] - m.vertices).max() > 1e-3  # it moved
    assert max(np.abs(lengths(X, E) - lengths(m.vertices, E)).max() for X in V) < 1e-9
    # a groups file that is not there: one line, exit 2
    r = run_cli("simulate", "bar.off", "--groups", "nope.json", "--frames", "2", "-o",
                "x.npz", cwd=tmp_path)
    assert r[0] == 2 and r[2].count("\n") == 1 and "nope.json" in r[2]


def test_the_editors_secondary_motion_takes_the_painted_parts():
    from arapkit.editor.motion import SecondaryMotion
    from arapkit.editor.settings import SolverSettings
    from arapkit.editor.worker import SolveRequest

    m = bar(length=3.0, segments=(30, 2, 2))
    V = m.vertices
    left = np.flatnonzero(V[:, 0] == 0)
    mid = np.flatnonzero(np.abs(V[:, 0] - 1.8) < 0.45)
    g = VertexGroups.from_lists([("middle", mid, True)], m.n_vertices, "painted groups")
    req = SolveRequest(m, left, V[left] + [0.0, 0.0, 0.3], np.ones(m.n_vertices, int),
                       SolverSettings(dynamics=True), groups=g)
    body = SecondaryMotion()
    sim = body.simulator_for(req, V)
    assert sim.groups is g
    s = sim.step(req.targets)
    E = inner_edges(m, mid)
    assert np.abs(lengths(s.positions, E) - lengths(V, E)).max() < 1e-9
    # the same painting keeps the body; another one makes a new body
    assert body.simulator_for(req, s.positions) is sim
    req.groups = None
    assert body.simulator_for(req, s.positions).groups is None
