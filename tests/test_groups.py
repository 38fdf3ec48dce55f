"""Vertex groups: shared rotations (libigl's G) and rigid parts, through the library.

Oracles: libigl's ``arap_solve`` with ``G`` (and its algorithm replayed in double,
``tests/igl_arap_oracle.py``), a brute-force minimisation over the parts' reduced
coordinates (L-BFGS on the energy with best rotations), edge lengths, finite differences.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from arapkit import Deformer, VertexGroups, load_groups
from arapkit.errors import InputError
from arapkit.io import load_handles, load_mesh, parse_groups, save_groups, save_mesh
from arapkit.mesh.shapes import bar, bar_bend

ROOT = Path(__file__).resolve().parents[1]
CACTUS = ROOT / "examples" / "cactus.off"
CACTUS_HANDLES = ROOT / "examples" / "cactus.json"
CACTUS_GROUPS = ROOT / "examples" / "cactus-groups.json"
#: rigid parts keep their edges to this, relative to each edge's rest length
RIGID_TOL = 1e-9


def _stretch(mesh, X, members) -> float:
    """The largest relative change of an edge length inside ``members``."""
    E = mesh.edges[np.isin(mesh.edges, members).all(axis=1)]
    assert len(E)
    rest = np.linalg.norm(mesh.vertices[E[:, 0]] - mesh.vertices[E[:, 1]], axis=1)
    now = np.linalg.norm(X[E[:, 0]] - X[E[:, 1]], axis=1)
    return float((np.abs(now - rest) / rest).max())


def _monotone(history, rel: float = 1e-10) -> bool:
    H = np.asarray(history)
    return bool(np.all(np.diff(H) <= rel * H[0]))


@pytest.fixture(scope="module")
def cactus():
    m = load_mesh(CACTUS)
    hs = load_handles(CACTUS_HANDLES, m.vertices)
    return m, hs


@pytest.fixture(scope="module")
def small_bar():
    m = bar(length=4.0, segments=(10, 2, 2))
    h, t = bar_bend(m, 90)
    x = m.vertices[:, 0]
    A = np.flatnonzero((x > 1.2) & (x < 2.0))
    B = np.flatnonzero((x > 2.0) & (x < 2.8))
    return m, h, t, A, B


# ------------------------------------------------------------------ shared rotations


@pytest.mark.parametrize("iterations", [1, 10])
def test_shared_rotations_are_libigls_G(cactus, iterations):
    """arapkit with groups = libigl's algorithm with G (double) to round-off; libigl's
    binary itself is that algorithm with single-precision rotations."""
    igl = pytest.importorskip("igl", reason="libigl is the test oracle for groups")
    from igl_arap_oracle import igl_arap_groups

    m, hs = cactus
    V, F, n = m.vertices, m.faces, m.n_vertices
    h, t = hs.indices, hs.targets
    ids = np.full(n, -1)
    ids[V[:, 0] < -1.5] = 0  # the left arm
    ids[(V[:, 1] > 3) & (V[:, 1] < 6) & (np.abs(V[:, 0]) < 1.5)] = 1  # a stretch of trunk
    G = np.arange(n)  # libigl's G: every vertex in a group, the ungrouped alone
    for g in (0, 1):
        G[ids == g] = np.flatnonzero(ids == g)[0]
    d = igl.ARAPData()
    d.energy = igl.ARAP_ENERGY_TYPE_SPOKES
    d.max_iter = iterations
    d.G = G
    igl.arap_precomputation(V, F.astype(np.int64), 3, h.astype(np.int32), d)
    U = igl.arap_solve(t, d, V.copy())
    diag = m.bounding_box_diagonal
    # the replica is libigl's algorithm: in single precision it is libigl's binary
    assert np.abs(igl_arap_groups(V, F, h, t, G, iterations, True) - U).max() < 1e-12 * diag
    exact = igl_arap_groups(V, F, h, t, G, iterations, False)
    res = Deformer(m, h, weights="cotan", groups=ids).solve(t, init=V, max_iter=iterations,
                                                            tol=0)
    assert res.iterations == iterations
    assert np.abs(res.vertices - exact).max() < 1e-9 * diag
    # and libigl's binary, with its float32 rotations: measured 2.0e-6 and 5.1e-6
    assert np.abs(res.vertices - U).max() < 1e-5 * diag
    # the groups changed the result (else the test could not fail)
    plain = Deformer(m, h, weights="cotan").solve(t, init=V, max_iter=iterations, tol=0)
    assert np.abs(plain.vertices - exact).max() > 1e-4 * diag


def test_libigl_G_counts_from_0_or_1_alike(cactus):
    """libigl documents G as 1..k but counts from 0; both give the same groups here, as
    they solve the same in libigl (an empty group 0 changes nothing)."""
    m, hs = cactus
    G = np.arange(m.n_vertices)
    arm = np.flatnonzero(m.vertices[:, 0] < -1.5)
    G[arm] = arm[0]
    a = Deformer(m, hs.indices, groups=G).solve(hs.targets, max_iter=5, tol=0).vertices
    b = Deformer(m, hs.indices, groups=G + 1).solve(hs.targets, max_iter=5, tol=0).vertices
    c = Deformer(m, hs.indices, groups=np.where(np.isin(np.arange(m.n_vertices), arm), 0, -1)
                 ).solve(hs.targets, max_iter=5, tol=0).vertices
    assert np.array_equal(a, b) and np.abs(a - c).max() < 1e-12


def test_shared_group_shares_one_rotation_and_descends(small_bar):
    m, h, t, A, B = small_bar
    g = VertexGroups.from_lists([("A", A, False)], m.n_vertices)
    res = Deformer(m, h, rings=2, groups=g).solve(t, tol=1e-8, max_iter=400)
    R = res.rotations[A]
    assert np.abs(R - R[0]).max() < 1e-12
    assert _monotone(res.history)
    # each member's own term, with the group's rotation, sums to the energy
    assert res.vertex_energy.sum() == pytest.approx(res.energy, rel=1e-9)
    assert _stretch(m, res.vertices, A) > 1e-4  # a shared rotation still stretches


# ------------------------------------------------------------------ rigid parts


@pytest.mark.parametrize("energy, rings", [("rring", 1), ("rring", "mixed"),
                                           ("spokes-and-rims", 1)])
def test_rigid_parts_stay_rigid_and_the_energy_falls(small_bar, energy, rings):
    m, h, t, A, B = small_bar
    r = np.where(m.vertices[:, 0] > 2.5, 3, 1) if rings == "mixed" else rings
    g = VertexGroups.from_lists([("A", A, True), ("B", B, True)], m.n_vertices)  # touching
    res = Deformer(m, h, rings=r, energy=energy, groups=g).solve(t, tol=1e-8, max_iter=2000)
    assert res.converged and _monotone(res.history)
    assert _stretch(m, res.vertices, A) < RIGID_TOL and _stretch(m, res.vertices, B) < RIGID_TOL
    assert np.abs(res.vertices[h] - t).max() < 1e-12
    plain = Deformer(m, h, rings=r, energy=energy).solve(t)
    assert _stretch(m, plain.vertices, A) > 1e-3  # without the parts they bend
    fast = Deformer(m, h, rings=r, energy=energy, groups=g, accelerate=True).solve(
        t, tol=1e-8, max_iter=2000)
    assert _monotone(fast.history) and _stretch(m, fast.vertices, A) < RIGID_TOL
    assert fast.energy == pytest.approx(res.energy, rel=1e-5)


def test_rigid_part_is_the_constrained_minimum(small_bar):
    """The solve reaches the minimum of the energy over shapes whose part moves rigidly:
    an independent L-BFGS over the reduced coordinates (free vertices, the part's
    rotation vector and translation) finds the same energy and shape."""
    so = pytest.importorskip("scipy.optimize")
    from scipy.spatial.transform import Rotation

    from arapkit.arap.backends.cpu import CPUBackend
    from arapkit.arap.problem import ARAPProblem

    m, h, t, A, _ = small_bar
    V, n = m.vertices, m.n_vertices
    g = VertexGroups.from_lists([("A", A, True)], n)
    res = Deformer(m, h, groups=g).solve(t, tol=1e-12, max_iter=20000, accelerate=True)
    p0 = ARAPProblem.from_mesh(m, h, reorder=False)  # the plain energy, mesh numbering
    be = CPUBackend(p0).bind(p0)
    s = p0.scale
    E, w = p0.edges, p0.energy.system_w
    R, b = np.empty((n, 3, 3)), np.empty((n, 3))
    free = np.setdiff1d(np.arange(n), np.concatenate([h, A]))
    a = (V[A] - V[A[0]]) / s

    def shape(z):
        X = V / s
        X[h] = t / s
        X[free] = z[:-6].reshape(-1, 3)
        X[A] = a @ Rotation.from_rotvec(z[-6:-3]).as_matrix().T + z[-3:]
        return X

    def f(z):
        X = shape(z)
        energy = be.local(X, R)
        be.vertex_rhs(b)
        AX = np.zeros_like(X)  # A X, the Laplacian of D_e
        d = w[:, None] * (X[E[:, 0]] - X[E[:, 1]])
        np.add.at(AX, E[:, 0], d)
        np.add.at(AX, E[:, 1], -d)
        grad = 2 * (AX - b)  # dE/dX at the best rotations (envelope theorem)
        gz = np.concatenate([grad[free].ravel(), np.zeros(3), grad[A].sum(axis=0)])
        for i in range(3):  # the rotation vector by central differences
            dz = np.zeros_like(z)
            dz[-6 + i] = 1e-6
            gz[-6 + i] = (be.local(shape(z + dz), R) - be.local(shape(z - dz), R)) / 2e-6
        return energy, gz

    z0 = np.concatenate([V[free].ravel() / s, np.zeros(3), V[A[0]] / s])
    opt = so.minimize(f, z0, jac=True, method="L-BFGS-B",
                      options={"maxiter": 20000, "ftol": 1e-15, "gtol": 1e-11})
    assert opt.fun * s * s == pytest.approx(res.energy, rel=1e-9)
    assert np.abs(shape(opt.x) * s - res.vertices).max() < 1e-5 * m.bounding_box_diagonal


@pytest.mark.parametrize("kind", ["pivot", "hinge", "fixed"])
def test_a_handle_inside_a_part_moves_the_whole_part(small_bar, kind):
    from arapkit.arap.parts import KINDS

    m, h, t, A, _ = small_bar
    V = m.vertices
    line = A[(np.abs(V[A, 0] - V[A[0], 0]) < 1e-9) & (np.abs(V[A, 2] - V[A[0], 2]) < 1e-9)]
    inner = {"pivot": A[:1], "hinge": line[:2], "fixed": A[:6]}[kind]
    assert kind != "fixed" or np.linalg.matrix_rank(V[inner] - V[inner].mean(0)) >= 2
    hh = np.concatenate([h, inner])
    tt = np.concatenate([t, V[inner] + [0.0, 0.3, 0.1]])  # translated together: rigid
    g = VertexGroups.from_lists([("A", A, True)], m.n_vertices)
    d = Deformer(m, hh, groups=g)
    res = d.solve(tt, tol=1e-9, max_iter=3000)
    assert KINDS[d.problem.part_system.holds.kind[0]] == kind
    assert _monotone(res.history) and _stretch(m, res.vertices, A) < RIGID_TOL
    assert np.abs(res.vertices[hh] - tt).max() < 1e-9 * m.bounding_box_diagonal
    if kind == "fixed":  # fixed by its handles: the part is their translation
        assert np.abs(res.vertices[A] - (V[A] + [0.0, 0.3, 0.1])).max() < 1e-12


def test_handles_no_rigid_motion_meets_name_the_part(small_bar):
    m, h, t, A, _ = small_bar
    V = m.vertices
    hh = np.concatenate([h, A[:2]])
    tt = np.concatenate([t, V[A[:2]] + [[0, 0, 0], [0, 0.5, 0]]])  # pulled apart
    g = VertexGroups.from_lists([("wing", A, True)], m.n_vertices, source="g.json")
    with pytest.raises(InputError) as exc:
        Deformer(m, hh, groups=g).solve(tt)
    msg = str(exc.value)
    assert "\n" not in msg and "rigid part 'wing'" in msg and msg.startswith("g.json: ")


def test_groups_follow_set_handles_set_rings_and_warm_starts(small_bar):
    m, h, t, A, B = small_bar
    g = VertexGroups.from_lists([("A", A, True), ("B", B, False)], m.n_vertices)
    d = Deformer(m, h, groups=g)
    first = d.solve(t)
    d.set_rings(2)
    d.set_handles(h)
    again = d.solve(t, init=first.vertices, tol=1e-9)
    assert _stretch(m, again.vertices, A) < RIGID_TOL and _monotone(again.history)
    assert d.groups is g and int(d.rings.max()) == 2
    ref = Deformer(m, h, rings=2, groups=g).solve(t, tol=1e-9)
    assert np.abs(again.vertices - ref.vertices).max() < 1e-4 * m.bounding_box_diagonal
    d.set_groups(None)
    assert d.groups is None and _stretch(m, d.solve(t).vertices, A) > 1e-3


def test_new_targets_reuse_the_merged_factor_and_large_meshes_solve_in_full(small_bar):
    from types import SimpleNamespace

    from arapkit.methods.deformer import MULTIRES_AUTO_VERTICES, coarse_to_fine

    m, h, t, A, _ = small_bar
    d = Deformer(m, h, groups=VertexGroups.from_lists([("A", A, True)], m.n_vertices))
    for k in range(3):
        res = d.solve(t + [0.0, 0.0, 0.1 * k])
        assert _stretch(m, res.vertices, A) < RIGID_TOL
    assert d.factorisations == 1
    big = SimpleNamespace(n_vertices=MULTIRES_AUTO_VERTICES)
    assert coarse_to_fine(big, None, {}) and not coarse_to_fine(big, None, {"groups": [0]})


def test_methods_without_groups_refuse_them(small_bar):
    from arapkit.methods.registry import methods

    m, h, t, A, _ = small_bar
    g = VertexGroups.from_lists([("A", A, True)], m.n_vertices)
    for info in methods("library"):
        if info.groups:
            continue
        with pytest.raises(InputError, match="takes no vertex groups"):
            Deformer(m, h, energy=info.name, groups=g)
    with pytest.raises(InputError, match="full resolution"):
        Deformer(m, h, groups=g, multires=True)


# ------------------------------------------------------------------ files


def test_groups_file_selectors_and_round_trip(tmp_path, cactus):
    m, _ = cactus
    g = load_groups(CACTUS_GROUPS, m)
    assert g.names == ("left arm", "right arm") and g.rigid.tolist() == [True, False]
    assert (m.vertices[g.members(0), 0] < -1.3).all()
    save_groups(tmp_path / "g.json", g)
    back = load_groups(tmp_path / "g.json", m)
    assert back.names == g.names and np.array_equal(back.ids, g.ids)
    # id files: libigl's G (shared rotations), and PLY properties of both kinds
    np.save(tmp_path / "g.npy", np.where(g.ids == 1, 5, -1))
    ids = load_groups(tmp_path / "g.npy", m)
    assert ids.rigid.tolist() == [False] and np.array_equal(ids.ids >= 0, g.ids == 1)
    (tmp_path / "g.txt").write_text("\n".join(map(str, g.ids)) + "\n")
    assert np.array_equal(load_groups(tmp_path / "g.txt", m).ids, g.ids)
    save_mesh(tmp_path / "m.ply", m.vertices, m.faces,
              vertex_properties={"part": np.where(g.ids == 0, 0, -1).astype(np.int32),
                                 "group": np.where(g.ids == 1, 0, -1).astype(np.int32)})
    ply = load_groups(tmp_path / "m.ply", m)
    assert ply.rigid.tolist() == [True, False] and np.array_equal(ply.ids, g.ids)


@pytest.mark.parametrize("entries, fragment", [
    ([{"name": "a", "indices": [0], "rigid": "yes"}], "group 1 ('a'): 'rigid' must be true"),
    ([{"name": "a", "indices": [0]}, {"name": "b", "indices": [0, 1]}],
     "group 2 ('b'): overlaps group 'a'"),
    ([{"name": "a", "box": {"min": [9, 9, 9], "max": [10, 10, 10]}}],
     "group 1 ('a'): box selects no vertices"),
    ([{"name": "a", "indices": [0], "translate": [1, 0, 0]}], "unknown key 'translate'"),
    ([{"name": "a"}], "needs exactly one selection"),
    ([{"name": "a", "indices": [99999]}], "vertex index 99999 out of range"),
    ({"groups": []}, "no groups"),
])
def test_groups_file_errors_name_the_file_and_entry(tmp_path, entries, fragment):
    m = bar()
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(entries))
    with pytest.raises(InputError) as exc:
        load_groups(path, m)
    msg = str(exc.value)
    assert msg.startswith(f"{path}: ") and fragment in msg and "\n" not in msg


def test_id_file_errors(tmp_path):
    m = bar()
    (tmp_path / "short.txt").write_text("0\n1\n")
    with pytest.raises(InputError, match=r"short.txt: 2 group ids for a mesh of 1154"):
        load_groups(tmp_path / "short.txt", m)
    (tmp_path / "neg.txt").write_text("\n".join(["-2"] + ["0"] * (m.n_vertices - 1)))
    with pytest.raises(InputError, match=r"neg.txt: vertex 0 has group id -2"):
        load_groups(tmp_path / "neg.txt", m)
    save_mesh(tmp_path / "m.ply", m.vertices, m.faces)
    with pytest.raises(InputError, match=r"m.ply: no vertex property 'group' or 'part'"):
        load_groups(tmp_path / "m.ply", m)


def test_parse_groups_on_a_welded_soup():
    from arapkit import Mesh
    from arapkit.mesh.welding import weld

    soup = Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]],
                [[0, 1, 2], [3, 4, 5]])
    w = weld(soup)
    g = parse_groups([{"indices": [1, 4]}], soup.vertices, welded=w)
    assert g.ids.tolist() == [-1, 0, -1, 0]
    with pytest.raises(InputError, match="copies of one welded vertex"):
        parse_groups([{"indices": [1]}, {"indices": [3]}], soup.vertices, welded=w)


# ------------------------------------------------------------------ the PyTorch layer


@pytest.mark.parametrize("case", ["shared", "free part", "pivot", "fixed"])
def test_layer_with_groups_matches_the_deformer_and_finite_differences(small_bar, case):
    torch = pytest.importorskip("torch", reason="PyTorch not installed")
    from arapkit.torch import ARAPLayer

    m, h, t, A, B = small_bar
    V, n = m.vertices, m.n_vertices
    inner = {"pivot": A[:1], "fixed": A[:6]}.get(case, A[:0])
    hh = np.concatenate([h, inner])
    tt = np.concatenate([t, V[inner] + [0.0, 0.3, 0.1]])
    g = VertexGroups.from_lists([("A", A, case != "shared"), ("B", B, False)], n)
    # converged tightly: the finite differences see the solution, not the stopping test
    layer = ARAPLayer(m, hh, dtype=torch.float64, groups=g, tol=0, max_iter=2500,
                      xtol=1e-13)
    T = torch.tensor(tt, requires_grad=True)
    X = layer(T)
    ref = Deformer(m, hh, groups=g).solve(tt, tol=0, max_iter=2500, accelerate=True)
    assert np.abs(X.detach().numpy() - ref.vertices).max() < 1e-6 * m.bounding_box_diagonal
    w = torch.randn(n, 3, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
    (X * w).sum().backward()
    eps = 1e-5
    for i, a in ((len(h) - 1, 2), (3, 1)):
        Tp, Tm = tt.copy(), tt.copy()
        Tp[i, a] += eps
        Tm[i, a] -= eps
        fd = ((layer(torch.tensor(Tp)) - layer(torch.tensor(Tm))) * w).sum().item() / (2 * eps)
        assert T.grad[i, a].item() == pytest.approx(fd, rel=1e-5, abs=1e-7)


def test_layer_refuses_rigid_parts_off_the_cpu(small_bar):
    torch = pytest.importorskip("torch", reason="PyTorch not installed")
    from arapkit.torch import ARAPLayer

    m, h, _, A, _ = small_bar
    g = VertexGroups.from_lists([("A", A, True)], m.n_vertices)
    with pytest.raises(InputError, match="device='cpu'"):
        ARAPLayer(m, h, groups=g, device="cuda:0", dtype=torch.float64)


# ------------------------------------------------------------------ the command line


def test_cli_rigid_arm_and_its_refusals(tmp_path, capsys, cactus):
    from arapkit.cli import main

    m, _ = cactus
    out, rep = tmp_path / "arm.ply", tmp_path / "arm.json"
    code = main(["deform", str(CACTUS), "--handles", str(CACTUS_HANDLES), "--groups",
                 str(CACTUS_GROUPS), "-o", str(out), "--report", str(rep), "-q"])
    assert code == 0, capsys.readouterr().err
    from arapkit.io import read_ply_vertex_properties

    p = read_ply_vertex_properties(out)
    X = np.stack([p["x"], p["y"], p["z"]], axis=1)
    g = load_groups(CACTUS_GROUPS, m)
    assert _stretch(m, X, g.members(0)) < RIGID_TOL
    report = json.loads(rep.read_text())
    assert report["vertex_groups"]["groups"][0] == {"name": "left arm", "count": 440,
                                                    "rigid": True}
    # a hand that no rigid motion of the arm meets: one line naming the part, exit 2
    bad = tmp_path / "torn.json"
    hands = json.loads(CACTUS_HANDLES.read_text())
    hands["groups"].append({"name": "elbow", "box": {"min": [-4.5, 5, -2], "max": [-3, 6, 2]},
                            "translate": [0, 0, 1]})
    bad.write_text(json.dumps(hands))
    capsys.readouterr()
    code = main(["deform", str(CACTUS), "--handles", str(bad), "--groups", str(CACTUS_GROUPS),
                 "-o", str(tmp_path / "x.ply"), "-q"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1, err
    assert "rigid part 'left arm'" in err and str(CACTUS_GROUPS) in err
    # a groups file error names the file and the entry
    broken = tmp_path / "broken.json"
    broken.write_text(json.dumps([{"name": "arm", "sphere": {"center": [0, 0, 0]}}]))
    code = main(["deform", str(CACTUS), "--handles", str(CACTUS_HANDLES), "--groups",
                 str(broken), "-o", str(tmp_path / "y.ply"), "-q"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and err.endswith(f"{broken}: group 1 ('arm'): 'sphere' needs 'radius'")
    assert not (tmp_path / "x.ply").exists() and not (tmp_path / "y.ply").exists()
    # a method without groups refuses them before reading anything
    code = main(["deform", str(CACTUS), "--handles", str(CACTUS_HANDLES), "--groups",
                 str(CACTUS_GROUPS), "--energy", "sr-arap", "-o", str(tmp_path / "z.ply")])
    assert code == 2 and "takes no vertex groups" in capsys.readouterr().err


def test_cli_dry_run_lists_the_groups(capsys):
    from arapkit.cli import main

    code = main(["deform", str(CACTUS), "--handles", str(CACTUS_HANDLES), "--groups",
                 str(CACTUS_GROUPS), "--dry-run"])
    out = capsys.readouterr().out
    assert code == 0 and "left arm: 440 vertices, rigid part" in out
    assert "right arm: 368 vertices, shared rotation" in out


def _bone_case():
    """The 7 m bar bent by 90 degrees with its middle 2 m a rigid bone."""
    from scipy.spatial.transform import Rotation

    m = bar()
    V, x = m.vertices, m.vertices[:, 0]
    lo, hi = np.flatnonzero(x < 0.3), np.flatnonzero(x > x.max() - 0.3)
    R = Rotation.from_euler("z", 90, degrees=True).as_matrix()
    t = np.r_[V[lo], (V[hi] - V[hi].mean(0)) @ R.T + [0.6 * x.max(), 0.4 * x.max(), 0]]
    bone = np.flatnonzero(np.abs(x - 3.5) < 1.0)
    return m, np.r_[lo, hi], t, bone


def test_anderson_extrapolates_the_parts_rotations_with_the_positions():
    """With a rigid bone, Anderson acceleration extrapolates the parts' rotations beside the
    positions: it needs well under half the plain iterations (positions alone: 219
    against 238), the energy never rises and the end is the tightly converged solve's."""
    m, h, t, bone = _bone_case()
    g = VertexGroups.from_lists([("bone", bone, True)], m.n_vertices)
    plain = Deformer(m, h, groups=g).solve(t, max_iter=5000)
    fast = Deformer(m, h, groups=g, accelerate=True).solve(t, max_iter=5000)
    ref = Deformer(m, h, groups=g).solve(t, tol=1e-10, max_iter=50000)
    assert plain.converged and fast.converged and ref.converged
    assert fast.iterations <= 0.5 * plain.iterations
    assert _monotone(fast.history) and _stretch(m, fast.vertices, bone) < RIGID_TOL
    assert np.abs(fast.vertices[h] - t).max() < 1e-12
    # the default stop (tol 1e-3) of the accelerated solve is nearer the minimum than the
    # plain one's (measured: 5 % above it against 11 %)
    assert ref.energy <= fast.energy <= plain.energy
    assert fast.energy - ref.energy < 0.6 * (plain.energy - ref.energy)
    # a solve from rest starts from rest also after another solve on the same deformer
    # (its parts are not placed with the last solve's rotations): the same iterates
    d = Deformer(m, h, groups=g, accelerate=True)
    d.solve(t[::-1].copy(), max_iter=30)
    again = d.solve(t, max_iter=5000)
    assert again.iterations == fast.iterations
    assert np.abs(again.vertices - fast.vertices).max() < 1e-12 * m.bounding_box_diagonal


@pytest.mark.parametrize("kind", ["pivot", "hinge"])
def test_accelerated_held_parts_turn_only_as_their_handles_allow(small_bar, kind):
    """A pivot's or a hinge's extrapolated rotation keeps its handles where they are
    (a held part takes the plain step's rotation): the accelerated solve reaches the plain
    solve's minimum with the handles exact."""
    m, h, t, A, _ = small_bar
    V = m.vertices
    line = A[(np.abs(V[A, 0] - V[A[0], 0]) < 1e-9) & (np.abs(V[A, 2] - V[A[0], 2]) < 1e-9)]
    inner = {"pivot": A[:1], "hinge": line[:2]}[kind]
    hh = np.concatenate([h, inner])
    tt = np.concatenate([t, V[inner] + [0.0, 0.3, 0.1]])
    g = VertexGroups.from_lists([("A", A, True)], m.n_vertices)
    ref = Deformer(m, hh, groups=g).solve(tt, tol=1e-12, max_iter=50000)
    fast = Deformer(m, hh, groups=g, accelerate=True).solve(tt, tol=1e-12, max_iter=50000)
    assert fast.converged and _monotone(fast.history)
    assert fast.iterations < ref.iterations
    assert np.abs(fast.vertices[hh] - tt).max() < 1e-9 * m.bounding_box_diagonal
    assert _stretch(m, fast.vertices, A) < RIGID_TOL
    assert fast.energy == pytest.approx(ref.energy, rel=1e-8)


def test_an_extrapolated_rotation_is_a_rotation_and_held_parts_keep_the_plain_one(small_bar):
    """``PartSystem.extrapolated``: a free part gets the rotation nearest the extrapolated
    matrix (its polar factor, computed here by SVD), a hinge-held one the plain step's."""
    from arapkit.arap.parts import FREE, HINGE

    m, h, t, A, B = small_bar
    V = m.vertices
    line = A[(np.abs(V[A, 0] - V[A[0], 0]) < 1e-9) & (np.abs(V[A, 2] - V[A[0], 2]) < 1e-9)]
    hh = np.concatenate([h, line[:2]])
    g = VertexGroups.from_lists([("A", A, True), ("B", B, True)], m.n_vertices)
    ps = Deformer(m, hh, groups=g).problem.part_system
    assert sorted(ps.holds.kind.tolist()) == [FREE, HINGE]
    rng = np.random.default_rng(3)
    Aex = np.eye(3) + 0.3 * rng.normal(size=(2, 3, 3))
    plain = np.stack([np.eye(3), np.eye(3)[[1, 0, 2]] * [[1], [-1], [1]]])
    out = ps.extrapolated(Aex, plain)
    for k in range(2):
        if ps.holds.kind[k] == HINGE:
            assert np.array_equal(out[k], plain[k])
        else:
            U, _, Wt = np.linalg.svd(Aex[k])
            D = np.diag([1, 1, np.sign(np.linalg.det(U @ Wt))])
            assert np.abs(out[k] - U @ D @ Wt).max() < 1e-12
