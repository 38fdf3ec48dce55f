"""ARAP dynamics (issue 49, section 2): physics against closed forms, libigl, brute force.

Each test was seen to fail with the feature it covers broken (see the report of the
change that added it).
"""

from __future__ import annotations

import numpy as np
import pytest
from igl_dynamics_oracle import LibiglArapDynamics

from arapkit import Deformer, InputError
from arapkit.arap.dynamics import LIBIGL_ENERGY_SCALE
from arapkit.mesh.mass import vertex_masses
from arapkit.mesh.shapes import bar, bar_two_materials
from arapkit.methods.dynamics import Keyframes, Simulator, simulate

G = np.array([0.0, 0.0, -9.81])


@pytest.fixture(scope="module")
def beam():
    """The bar, pinned at its left end (a cantilever)."""
    m = bar()
    return m, np.flatnonzero(m.vertices[:, 0] == 0)


@pytest.fixture(scope="module")
def small():
    """A shorter bar for the brute-force checks."""
    m = bar(length=2.0, segments=(10, 2, 2))
    return m, np.flatnonzero(m.vertices[:, 0] == 0)


# ---------------------------------------------------------------- closed forms


def test_a_free_body_falls_as_g_t2_over_2_to_first_order():
    """Implicit Euler's fall after n steps is g h^2 n (n + 1) / 2 = g (t^2 + h t) / 2: the
    error against g t^2 / 2 is g h t / 2, halved with the step; the body stays rigid."""
    m = bar()
    errors = []
    for h in (0.1, 0.05, 0.025):
        n = round(1.0 / h)
        tr = simulate(m, n + 1, dt=h, gravity=G, damping=0.0)
        drop = tr.vertices[-1] - m.vertices
        assert np.abs(drop - drop.mean(axis=0)).max() < 1e-9  # a translation: no strain
        fall = drop[:, 2].mean()
        assert fall == pytest.approx(-9.81 * (1.0 + h) / 2, rel=1e-9)  # round-off of the solve
        errors.append(abs(fall + 9.81 / 2))
        assert np.all(tr.iterations == 1)  # started at the inertial prediction: exact
    assert errors[0] / errors[1] == pytest.approx(2.0, rel=1e-6)
    assert errors[1] / errors[2] == pytest.approx(2.0, rel=1e-6)


@pytest.mark.parametrize("pinned", [False, True])
def test_a_rest_shape_without_forces_stays_at_rest(beam, pinned):
    m, left = beam
    tr = simulate(m, 101, dt=1 / 60, handles=left if pinned else None, damping=0.0)
    # round-off only: the global matrix's condition (~1e5) times eps, over 100 steps
    assert np.abs(tr.vertices - m.vertices).max() < 1e-8 * m.bounding_box_diagonal
    assert np.abs(tr.kinetic).max() < 1e-12 and np.abs(tr.elastic).max() < 1e-12


def test_mass_damping_slows_a_free_body_by_1_over_1_plus_a_h():
    """With no other force, v_{n+1} = v_n / (1 + a h): the kinetic energy falls by its
    square each step; without damping it stays."""
    m = bar()
    h, a = 0.02, 3.0
    for damping, factor in ((a, (1 + a * h) ** -2), (0.0, 1.0)):
        sim = Simulator(m, dt=h, damping=damping)
        sim.reset(velocities=np.tile([1.0, 2.0, 0.5], (m.n_vertices, 1)))
        tr = sim.run(11)
        ratios = tr.kinetic[1:] / tr.kinetic[:-1]
        assert np.allclose(ratios, factor, rtol=1e-10), ratios


def test_with_damping_the_energy_decreases(beam):
    """The cantilever released under gravity: its total energy (kinetic + elastic +
    gravity's potential) never rises from step to step, and damping takes more of it."""
    m, left = beam
    runs = {a: simulate(m, 61, dt=1 / 60, handles=left, gravity=G, damping=a)
            for a in (0.0, 2.0)}
    E = runs[2.0].energy
    assert np.all(np.diff(E) <= 1e-9 * np.abs(E).max()), np.diff(E).max()
    assert E[-1] < runs[0.0].energy[-1] - 0.05 * abs(runs[0.0].energy[-1])
    # it really moved: the free end swung down
    assert runs[2.0].vertices[:, :, 2].min() < -1.0


# ---------------------------------------------------------------- the step itself


def test_the_step_objective_never_rises_within_a_step(beam):
    """Every iteration of every step lowers the step's objective, with a per-vertex r map,
    moving handles, and with and without acceleration."""
    m, left = beam
    right = np.flatnonzero(m.vertices[:, 0] == m.vertices[:, 0].max())
    h = np.concatenate([left, right])
    rest = m.vertices[h]
    up = rest + [0.0, 0.0, 2.0] * np.isin(h, right)[:, None]
    keys = Keyframes([0.0, 0.2], [rest, up])
    for acc in (False, True):
        sim = Simulator(m, h, bar_two_materials(m, 1, 4), gravity=G, accelerate=acc,
                        tol=1e-8)
        rises, steps = 0, 0
        for _ in range(20):
            s = sim.step(keys(sim.time + sim.dt))
            H = np.array(s.history)
            rises += int((np.diff(H) > 1e-12 * np.abs(H).max()).sum())
            steps += len(H) > 2
            assert s.converged
            assert np.abs(s.positions[h] - keys(sim.time)).max() < 1e-12  # handles met
        assert rises == 0 and steps > 10


def test_a_converged_step_is_an_implicit_euler_step(small):
    """At the end of a step, dPhi/dx = 0 for the free vertices, Phi(x) = (1 + a h)/(2 h^2)
    |x - y|_M^2 + k E(x) with E at its best rotations: checked by central differences of
    Phi, E from the static deformer (an independent evaluation of the energy)."""
    m, left = small
    h, k, a = 0.05, 2e4, 1.5
    sim = Simulator(m, left, dt=h, stiffness=k, damping=a, gravity=G, tol=1e-14,
                    max_iter=5000)
    for _ in range(3):
        sim.step()
    x0, v0 = sim.positions.copy(), sim.velocities.copy()
    s = sim.step()
    x1 = s.positions
    assert s.converged
    M = vertex_masses(m)
    y = x0 + (h * v0 + h * h * G) / (1 + a * h)
    d = Deformer(m, left)

    def phi(x):
        return ((1 + a * h) / (2 * h * h) * np.sum(M[:, None] * (x - y) ** 2)
                + k * d.energy_of(x, x[left]))

    assert phi(x1) == pytest.approx(s.history[-1], rel=1e-9)  # the objective reported
    rng = np.random.default_rng(0)
    free = np.setdiff1d(np.arange(m.n_vertices), left)
    eps = 1e-4
    inertial = (1 + a * h) / h ** 2 * M[:, None] * (x1 - y)  # what the elastic force balances
    scale = np.linalg.norm(inertial[free])
    for _ in range(4):
        D = np.zeros_like(x1)
        D[free] = rng.normal(size=(len(free), 3))
        D /= np.linalg.norm(D)
        slope = (phi(x1 + eps * D) - phi(x1 - eps * D)) / (2 * eps)
        assert abs(slope) < 1e-3 * scale, (slope, scale)
    # the check can fail: at the inertial prediction (the step's start) Phi is not flat
    D = np.zeros_like(x1)
    D[free] = x1[free] - y[free]
    D /= np.linalg.norm(D)
    assert abs((phi(y + eps * D) - phi(y - eps * D)) / (2 * eps)) > 0.1 * scale


def test_a_larger_r_is_stiffer_and_stiffness_does_not_depend_on_h(beam):
    m, left = beam
    sag = {}
    for r in (1, 3):
        for fps in (30, 60, 120):
            tr = simulate(m, fps + 1, dt=1 / fps, handles=left, gravity=G, rings=r)
            sag[r, fps] = tr.vertices[-1]
    diag = m.bounding_box_diagonal
    assert sag[3, 60][:, 2].min() > sag[1, 60][:, 2].min() + 0.2  # r = 3 sags less
    for r in (1, 3):  # halving the step changes the pose at 1 s by < 1 % of the diagonal
        for a, b in ((30, 60), (60, 120)):
            assert np.abs(sag[r, a] - sag[r, b]).max() < 0.01 * diag


def test_libigls_pose_at_1_s_changes_with_the_step(beam):
    """libigl's stiffness is ym / h^2: the same run with half the step is a body four times
    softer. Its pose at 1 s moves by several per cent of the diagonal (measured: 9.0 % from
    1/30 to 1/60 s, docs/benchmarks.md); arapkit's reproduction of it does the same."""
    igl = pytest.importorskip("igl", reason="libigl is the test oracle for its dynamics")
    m, left = beam
    V, F = m.vertices, m.faces.astype(np.int64)
    ym = 50.0
    poses = {}
    for fps in (30, 60):
        data = igl.ARAPData()
        data.energy = igl.ARAP_ENERGY_TYPE_SPOKES_AND_RIMS
        data.with_dynamics, data.h, data.ym, data.max_iter = True, 1 / fps, ym, 10
        igl.arap_precomputation(V, F, 3, left.astype(np.int32), data)
        data.f_ext = vertex_masses(m)[:, None] * G
        U = V.copy()
        for _ in range(fps):
            U = igl.arap_solve(V[left], data, U)
        poses[fps] = U
        sim = Simulator.like_libigl(m, left, 1 / fps, ym=ym)
        for _ in range(fps):
            sim.step(forces=sim.masses[:, None] * G)
        assert np.abs(sim.positions - U).max() < 1e-5 * m.bounding_box_diagonal
    assert np.abs(poses[30] - poses[60]).max() > 0.05 * m.bounding_box_diagonal


# ---------------------------------------------------------------- libigl compatibility


@pytest.mark.parametrize(("energy", "theirs"), [("spokes-and-rims", "spokes-and-rims"),
                                                ("rring", "spokes")])
def test_like_libigl_reproduces_arap_solve_with_dynamics(beam, energy, theirs):
    """Against libigl's update formulas (tests/igl_dynamics_oracle.py) with its double
    precision rotation fit: 1e-8 of the diagonal over 30 steps, a force, and a handle that
    moves. Against its compiled arap_solve (float32 rotations): to their round-off, and
    the transcription with the float32 fit is closer to it still (it is libigl's code)."""
    igl = pytest.importorskip("igl", reason="libigl is the test oracle for its dynamics")
    m, left = beam
    V, F = m.vertices, m.faces
    right = np.flatnonzero(V[:, 0] == V[:, 0].max())
    b = np.concatenate([left, right])
    h, ym = 1 / 30, 50.0
    ours = Simulator.like_libigl(m, b, h, ym=ym, energy=energy)
    assert ours.stiffness == pytest.approx(ym * LIBIGL_ENERGY_SCALE[energy] / h ** 2)
    double = LibiglArapDynamics(V, F, b, h, ym, theirs)
    single = LibiglArapDynamics(V, F, b, h, ym, theirs)
    data = igl.ARAPData()
    data.energy = (igl.ARAP_ENERGY_TYPE_SPOKES_AND_RIMS if theirs == "spokes-and-rims"
                   else igl.ARAP_ENERGY_TYPE_SPOKES)
    data.with_dynamics, data.h, data.ym, data.max_iter = True, h, ym, 10
    igl.arap_precomputation(V, F.astype(np.int64), 3, b.astype(np.int32), data)
    f = double.M.diagonal()[:, None] * G
    data.f_ext = single.f_ext = double.f_ext = f
    A, B, U = V.copy(), V.copy(), V.copy()
    diag = m.bounding_box_diagonal
    worst = {"double": 0.0, "single": 0.0, "binary": 0.0}
    for k in range(30):
        bc = V[b].copy()
        bc[len(left):, 2] += 0.05 * min(k + 1, 10)  # the right end rises, then holds
        A = double.solve(bc, A, single_precision=False)
        B = single.solve(bc, B, single_precision=True)
        U = igl.arap_solve(bc, data, U)
        s = ours.step(bc, forces=f)
        assert s.iterations == 10
        worst["double"] = max(worst["double"], np.abs(s.positions - A).max() / diag)
        worst["single"] = max(worst["single"], np.abs(B - U).max() / diag)
        worst["binary"] = max(worst["binary"], np.abs(s.positions - U).max() / diag)
    assert np.abs(U - V).max() > 0.05 * diag  # it really moved
    assert worst["double"] < 1e-8, worst
    assert worst["binary"] < 2e-6, worst  # float32 rotations (measured 4.5e-7)
    assert worst["single"] < 0.5 * worst["binary"], worst


def test_voronoi_masses_are_libigls_and_both_kinds_sum_to_the_area(beam):
    igl = pytest.importorskip("igl", reason="libigl's massmatrix is the oracle")
    m, _ = beam
    M = igl.massmatrix(m.vertices, m.faces.astype(np.int64), igl.MASSMATRIX_TYPE_VORONOI)
    assert np.abs(vertex_masses(m, 2.5) - 2.5 * M.diagonal()).max() < 1e-14
    area = 2 * (7 * 0.4) * 2 + 2 * 0.4 * 0.4
    for kind in ("voronoi", "barycentric"):
        assert vertex_masses(m, 3.0, kind).sum() == pytest.approx(3.0 * area, rel=1e-12)


# ---------------------------------------------------------------- handles over time


def test_keyframed_handles_are_met_and_the_body_lags(beam):
    """The right end is keyed up by 2 m in 0.1 s: at every frame the handles are at the
    keyed positions; the middle of the bar lags behind the static shape for the final
    handles when they stop, swings past it, and settles there."""
    m, left = beam
    right = np.flatnonzero(m.vertices[:, 0] == m.vertices[:, 0].max())
    h = np.concatenate([left, right])
    rest = m.vertices[h]
    up = rest + [0.0, 0.0, 2.0] * np.isin(h, right)[:, None]
    keys = Keyframes([0.0, 0.1], [rest, up])
    tr = simulate(m, 121, dt=1 / 60, handles=h, targets=keys, damping=4.0)
    for k, t in enumerate(tr.times):
        assert np.abs(tr.vertices[k][h] - keys(t)).max() < 1e-12
    static = Deformer(m, h).solve(up, tol=1e-8).vertices
    mid = np.abs(m.vertices[:, 0] - 3.5) < 0.3
    z = tr.vertices[:, mid, 2].mean(axis=1) - static[mid, 2].mean()
    assert z[6] < -0.04  # behind when the handles stop (t = 0.1 s; measured -0.058 m)
    assert z.max() > 0.05  # swings through (measured +0.13 m)
    assert np.abs(tr.vertices[-1] - static).max() < 1e-3 * m.bounding_box_diagonal


def test_pinned_handles_stay_and_a_pose_array_holds(beam):
    m, left = beam
    sim = Simulator(m, left, gravity=G)
    tr = sim.run(11)
    assert np.abs(tr.vertices[:, left] - m.vertices[left]).max() == 0.0
    pose = m.vertices[left] + [0.0, 0.0, 0.1]
    tr = sim.run(3, targets=pose)
    assert np.abs(tr.vertices[1:, left] - pose).max() < 1e-12


# ---------------------------------------------------------------- bad input


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"dt": 0.0}, "dt: must be greater than 0"),
    ({"dt": -1.0}, "dt: must be greater than 0"),
    ({"gravity": [0, float("nan"), 0]}, "gravity: expected a finite number"),
    ({"stiffness": 0}, "stiffness: must be greater than 0"),
    ({"damping": -1}, "damping: must be at least 0"),
    ({"density": float("inf")}, "density: expected a finite number"),
    ({"mass": "lumped"}, "unknown mass 'lumped'"),
    ({"energy": "sr-arap"}, "not a descent energy"),
    ({"handles": [5000]}, "out of range"),
])
def test_bad_parameters_are_one_line_errors(kwargs, match):
    with pytest.raises(InputError, match=match) as e:
        Simulator(bar(), **kwargs)
    assert "\n" not in str(e.value)


def test_bad_run_input_is_one_line(beam):
    m, left = beam
    sim = Simulator(m, left)
    with pytest.raises(InputError, match="frames: must be at least 1"):
        sim.run(0)
    with pytest.raises(InputError, match=r"targets: expected shape \(\d+, 3\)"):
        sim.step(np.zeros((2, 3)))
    with pytest.raises(InputError, match="forces: vertex 3 has a non-finite"):
        f = np.zeros((m.n_vertices, 3))
        f[3, 0] = np.nan
        sim.step(forces=f)
    with pytest.raises(InputError, match="frames: 10000000 frames"):
        sim.run(10_000_000)
    with pytest.raises(InputError, match="keyframe times: must be finite and strictly"):
        Keyframes([0.0, 0.0], np.zeros((2, 1, 3)))
