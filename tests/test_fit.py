"""Fitting a template to a scan (arapkit.fit, arapkit fit): accuracy against known answers,
the energy's decrease, landmarks, partial scans, bad input, attributes kept.

The known answers: a bar bent by arapkit's own ARAP solve (the target is sampled from it, so
every template vertex's true position is known), trimesh's own registration test pair with
its accuracy bars (closest points by trimesh as the oracle), and closest points checked
against libigl's point-mesh distance and a brute-force disk distance.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import data_path

import arapkit
from arapkit import InputError, Mesh
from arapkit.cli import main
from arapkit.io.landmarks import load_landmarks, parse_landmarks, save_landmarks
from arapkit.io.points import load_points
from arapkit.mesh.shapes import bar, bar_bend
from arapkit.methods.fit import FitTarget, Fitter, fit
from arapkit.methods.fit.align import similarity

ROOT = Path(__file__).resolve().parents[1]
TRIMESH = ROOT / "tests" / "data" / "trimesh_nricp"
EX = ROOT / "examples"


def sample_surface(V, F, n, rng, noise=0.0, missing=0.0, view=(0.0, 1.0, 0.0)):
    """``n`` points drawn by area on (V, F) with their triangles' normals, Gaussian noise
    of ``noise`` times the diagonal, less the fraction ``missing`` facing most away from a
    scanner looking along ``-view`` (a one-sided scan)."""
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    cross = np.cross(b - a, c - a)
    area = np.linalg.norm(cross, axis=1)
    f = rng.choice(len(F), size=n, p=area / area.sum())
    u, v = rng.random(n), rng.random(n)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    P = a[f] + u[:, None] * (b[f] - a[f]) + v[:, None] * (c[f] - a[f])
    N = cross[f] / area[f, None]
    P = P + rng.normal(0.0, noise * np.linalg.norm(np.ptp(V, axis=0)), P.shape)
    keep = np.sort(np.argsort(N @ np.asarray(view))[int(missing * n):])
    return P[keep], N[keep]


def rms(X, G):
    """RMS distance of X from G as a fraction of G's bounding-box diagonal."""
    return float(np.sqrt(((X - G) ** 2).sum(axis=1).mean()) / np.linalg.norm(np.ptp(G, axis=0)))


@pytest.fixture(scope="module")
def bent():
    """The bar, bent 90 degrees by arapkit itself (r = 1); its handles; a Fitter for it."""
    m = bar()
    h, t = bar_bend(m, 90)
    G = arapkit.Deformer(m, h, rings=1).solve(t).vertices
    return m, h, G, Fitter(m)


# -- accuracy against known answers ------------------------------------------------------


def test_recovers_a_known_deformation(bent):
    """The target is a cloud sampled from the bar bent by ARAP with its end caps as handles;
    with those handles as landmarks the true shape is the fit's energy minimum (up to the
    sampling), and the fit finds every vertex's true position to 0.1 % of the diagonal RMS
    (measured 0.004-0.024 % over four sampling seeds) where the bend moved them by 12 %."""
    m, h, G, fitter = bent
    P, N = sample_surface(G, m.faces, 6000, np.random.default_rng(1))
    res = fitter.fit(P, (h, G[h]), normals=N)
    assert rms(res.vertices, G) < 1e-3
    assert res.report.residual["max"] < 1e-3
    assert rms(m.vertices, G) > 0.1  # the bend is no small change


def test_fits_a_mesh_target(bent):
    """The same with the bent bar's triangles as the target."""
    m, h, G, fitter = bent
    res = fitter.fit(Mesh(G, m.faces), (h, G[h]))
    assert rms(res.vertices, G) < 2e-4
    assert res.report.target_kind == "mesh"


def test_partial_noisy_scan_stays_close(bent):
    """30 % of the scan missing (the side facing away from the scanner) and 0.2 % noise:
    within 0.55 % RMS of the true shape (measured 0.42 %; 0.66 % without the normal test,
    which keeps the hidden side off the far side's points)."""
    m, h, G, fitter = bent
    P, N = sample_surface(G, m.faces, 6000, np.random.default_rng(0), noise=0.002,
                          missing=0.3)
    res = fitter.fit(P, (h, G[h]), normals=N)
    assert rms(res.vertices, G) < 0.0055
    assert 0.6 < res.report.matched < 0.9


def test_parts_beyond_the_scans_border_are_not_pulled_onto_it(bent):
    """A scan of the bent bar without its last 2.5 units (rest x > 4.5): the hidden part
    follows the shape, within 0.5 % RMS (measured 0.13 %; 3.3 % when matches on the
    scan's border are not rejected: the hidden end is dragged onto the rim)."""
    from scipy.spatial import cKDTree

    m, h, G, fitter = bent
    P, N = sample_surface(G, m.faces, 6000, np.random.default_rng(0), noise=0.002)
    keep = m.vertices[cKDTree(G).query(P)[1], 0] < 4.5
    res = fitter.fit(P[keep], (h, G[h]), normals=N[keep])
    hidden = m.vertices[:, 0] > 4.5
    assert rms(res.vertices[hidden], G[hidden]) * np.linalg.norm(np.ptp(G[hidden], 0)) \
        / np.linalg.norm(np.ptp(G, 0)) < 0.005


def test_partial_scan_of_a_human_pose():
    """A real pose pair (anny frame 0 to frame 2, ground truth known): a one-sided scan with
    30 % missing and 0.2 % noise, 12 landmarks: within 0.41 % RMS of the true shape
    (measured 0.37 %; 0.44 % without the normal test; docs/benchmarks.md has the set)."""
    d = np.load(data_path("sequences/anny_makehuman_pose_seq.npz"))
    V, F = d["V"].astype(np.float64), d["F"]
    rng = np.random.default_rng(0)
    lm = np.linspace(0, len(V[0]) - 1, 12).astype(np.int64)
    P, N = sample_surface(V[2], F, len(V[0]), rng, noise=0.002, missing=0.3)
    res = fit(Mesh(V[0], F), P, (lm, V[2][lm]), normals=N)
    assert rms(res.vertices, V[2]) < 0.0041
    assert rms(V[0], V[2]) > 0.05


def test_trimesh_pair_meets_trimeshs_own_accuracy_bars():
    """trimesh's test_nricp asserts a mean closest-point distance below 1e-3 and a mean
    landmark error below 4e-4 for nricp_amberg with landmarks; the fit meets both (its
    closest points measured by trimesh, an independent oracle)."""
    trimesh = pytest.importorskip("trimesh")
    pytest.importorskip("rtree", reason="trimesh's closest_point needs rtree")
    ref = arapkit.load_mesh(TRIMESH / "reference.obj")
    tgt = arapkit.load_mesh(TRIMESH / "target.obj")
    pairs = np.array(json.loads((TRIMESH / "landmark_pairs.json").read_text()))
    # a clean mesh target: one more, softer stage (as trimesh's test tunes its steps)
    res = fit(ref, tgt, (pairs[:, 0], tgt.vertices[pairs[:, 1]]),
              schedule=(0.3, 0.1, 0.03, 0.01, 0.003, 0.001))
    assert res.report.scale_fitted  # the template is in other units: scale=None fits it
    d = trimesh.proximity.closest_point(trimesh.Trimesh(tgt.vertices, tgt.faces,
                                                        process=False), res.vertices)[1]
    assert d.mean() < 1e-3
    dl = np.linalg.norm(res.vertices[pairs[:, 0]] - tgt.vertices[pairs[:, 1]], axis=1)
    assert dl.mean() < 4e-4
    # the report's residuals are exact closest-point distances (libigl), which trimesh's
    # approximate query matches or overestimates (by 6e-7 at one vertex)
    igl = pytest.importorskip("igl")
    exact = np.sqrt(igl.point_mesh_squared_distance(res.vertices, tgt.vertices, tgt.faces)[0])
    assert np.allclose(res.residuals, exact, rtol=1e-7, atol=1e-10)
    assert (exact <= d + 1e-12).all()


def test_landmarks_are_met(bent):
    m, h, G, fitter = bent
    P, N = sample_surface(G, m.faces, 3000, np.random.default_rng(1))
    lm = [int(h[0]), int(h[-1]), 577]
    target = G[lm] + [0.0, 0.0, 0.01]  # slightly off the surface: still met exactly
    res = fitter.fit(P, {v: t for v, t in zip(lm, target)}, normals=N)
    assert np.abs(res.vertices[lm] - target).max() < 1e-9
    assert res.report.landmark_error < 1e-9


# -- the energy and the linear algebra ---------------------------------------------------


def test_energy_never_rises_within_a_stage(bent):
    """Every stage's energy sequence is non-increasing (each step minimises a majoriser of
    the stage's energy; Anderson steps are kept only when they lower it)."""
    m, h, G, fitter = bent
    P, N = sample_surface(G, m.faces, 6000, np.random.default_rng(2), noise=0.002,
                          missing=0.3)
    for accelerate in (True, False):
        res = Fitter(m, accelerate=accelerate).fit(P, (h[:25], G[h[:25]]), normals=N)
        stages = [s for s in res.report.stages if s.stiffness is not None]
        assert len(stages) == 5
        for s in stages:
            E = np.asarray(s.energy)
            assert len(E) >= 2
            assert (np.diff(E) <= 1e-12 * np.abs(E[:-1])).all(), (s.name, E)
        assert sum(len(s.energy) for s in stages) > 20


def test_first_stage_reuses_the_bends_matches_and_changes_nothing(bent, monkeypatch):
    """The first stage walks from the landmark bend's matches (searched at the same
    positions) instead of searching again: the fit is the same to the last bit as with
    the search, and it makes one k-d search fewer."""
    m, h, G, _ = bent
    rng = np.random.default_rng(11)
    P, N = sample_surface(G, m.faces, 3000, rng, noise=0.002, missing=0.3)
    lm = (h[::7], G[h[::7]])
    searches = []
    original = FitTarget.nearest

    def counted(self, X, k=1, distance_upper_bound=np.inf):
        if k > 1:
            searches.append(len(X))
        return original(self, X, k, distance_upper_bound)

    monkeypatch.setattr(FitTarget, "nearest", counted)
    reused = Fitter(m).fit(P, lm, normals=N)
    n_reused = len(searches)
    bend = Fitter._bend

    def forgetful(self, *args):  # the bend's vertices without its matches: a new search
        return bend(self, *args)[0], None

    monkeypatch.setattr(Fitter, "_bend", forgetful)
    searches.clear()
    searched = Fitter(m).fit(P, lm, normals=N)
    assert np.array_equal(reused.vertices, searched.vertices)
    assert len(searches) == n_reused + 1


def test_factors_are_kept_across_fits(bent):
    """One factorisation per stage on the first fit of a landmark set, none after."""
    m, h, G, _ = bent
    fitter = Fitter(m)
    P, N = sample_surface(G, m.faces, 3000, np.random.default_rng(3))
    first = fitter.fit(P, (h, G[h]), normals=N)
    second = fitter.fit(P + [0.0, 0.0, 0.01], (h, G[h] + [0.0, 0.0, 0.01]), normals=N)
    assert first.report.factorisations == len(fitter.schedule)
    assert second.report.factorisations == 0


def test_rigidity_map_changes_where_the_fit_bends(bent):
    """A per-vertex r: a stiff map keeps the template's shape where the scan asks for more."""
    m, h, G, _ = bent
    P, N = sample_surface(G, m.faces, 3000, np.random.default_rng(4))
    soft = fit(m, P, (h, G[h]), normals=N)
    r = np.full(m.n_vertices, 6)
    stiff = fit(m, P, (h, G[h]), rings=r, normals=N)
    assert not np.allclose(soft.vertices, stiff.vertices, atol=1e-4)
    with pytest.raises(InputError):
        fit(m, P, rings=np.ones(3, dtype=int), normals=N)


# -- closest points against oracles ------------------------------------------------------


def test_closest_points_on_a_mesh_match_libigl():
    igl = pytest.importorskip("igl")
    m = bar()
    rng = np.random.default_rng(5)
    Q = m.vertices[rng.integers(0, m.n_vertices, 500)] + rng.normal(0, 0.3, (500, 3))
    d2 = FitTarget.from_mesh(m).match(Q).d2
    ref = igl.point_mesh_squared_distance(Q, m.vertices, m.faces)[0]
    assert np.allclose(d2, ref, rtol=1e-9, atol=1e-12)


def test_closest_points_on_disks_match_brute_force():
    """A wavy sheet sampled with its normals; queries near it (as the fit's are)."""
    rng = np.random.default_rng(6)

    def sheet(xy):
        z = 0.3 * np.sin(xy[:, 0]) * np.cos(0.7 * xy[:, 1])
        n = np.stack([-0.3 * np.cos(xy[:, 0]) * np.cos(0.7 * xy[:, 1]),
                      0.21 * np.sin(xy[:, 0]) * np.sin(0.7 * xy[:, 1]), np.ones(len(xy))], 1)
        return np.column_stack([xy, z]), n / np.linalg.norm(n, axis=1, keepdims=True)

    P, N = sheet(rng.random((2000, 2)) * 6.0)
    t = FitTarget.from_points(P, N)
    Q, M = sheet(rng.random((500, 2)) * 5.0 + 0.5)
    Q = Q + M * rng.uniform(-0.3, 0.3, (500, 1))
    m = t.match(Q)
    d = Q[:, None, :] - t.points[None]
    h = (d * t.normals[None]).sum(axis=2)
    tang = d - h[..., None] * t.normals[None]
    tl = np.linalg.norm(tang, axis=2)
    over = np.maximum(tl - t.radius[None], 0.0)
    brute = (h * h + over * over).min(axis=1)
    # the distance found is to a real point of the disk union, so never below the true one;
    # the search (8 nearest centres, then a greedy walk) may stop in a local minimum of
    # the union: measured, 87 % exact, 99 % within 3 %
    assert (m.d2 >= brute - 1e-12).all()
    ratio = np.sqrt(m.d2 / brute)
    assert np.mean(ratio < 1 + 1e-9) > 0.8 and np.percentile(ratio, 99) < 1.05
    # the point reported is the one measured, and lies on the disk of the element reported
    assert np.allclose(((Q - m.point) ** 2).sum(axis=1), m.d2, rtol=1e-9, atol=1e-14)
    off = m.point - t.points[m.element]
    assert np.abs((off * t.normals[m.element]).sum(axis=1)).max() < 1e-12
    assert (np.linalg.norm(off, axis=1) <= t.radius[m.element] * (1 + 1e-12)).all()


@pytest.mark.parametrize("kind", ["points", "mesh"])
def test_the_walks_memory_changes_no_match(kind):
    """Queries that drift (steps of several sizes, as a fit's vertices do), matched from
    their last match with and without the walk's memory: the same elements and distances;
    and the memory skips most walks once the steps are small."""
    rng = np.random.default_rng(10)
    m = bar()
    P, N = sample_surface(m.vertices, m.faces, 3000, rng)
    t = FitTarget.from_points(P, N) if kind == "points" else FitTarget.from_mesh(m)
    X = m.vertices + rng.normal(0, 0.05, m.vertices.shape)
    first = t.match(X)
    memo = t.memo(len(X))
    t.match(X, first.element, search=False, memo=memo)
    prev_a = prev_b = first.element
    for step in (0.05, 0.01, 0.002, 0.0005, 0.0001, 0.02, 0.0):
        X = X + rng.normal(0, step, X.shape)
        a = t.match(X, prev_a, search=False)
        b = t.match(X, prev_b, search=False, memo=memo)
        assert (a.element == b.element).all(), step
        assert np.array_equal(a.d2, b.d2) and np.array_equal(a.point, b.point)
        assert np.array_equal(a.border, b.border)
        prev_a, prev_b = a.element, b.element
    # remembered as settled with a margin: most queries on the mesh; on the bar's flat
    # faces overlapping coplanar disks tie (no margin), so fewer there (measured 0.90, 0.23;
    # 0.999 on the curved scan of benchmark b)
    assert np.mean(memo.slack > 0) > (0.8 if kind == "mesh" else 0.15)


def test_a_moved_target_keeps_its_tree_and_matches_as_one_built_there():
    """``FitTarget.moved`` maps queries to the tree it has (built once per target): the
    matches equal those of a target built from the moved points."""
    rng = np.random.default_rng(8)
    m = bar()
    P, N = sample_surface(m.vertices, m.faces, 2000, rng)
    t = FitTarget.from_points(P, N)
    Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    Q *= np.sign(np.linalg.det(Q))
    s, tr = 2.5, np.array([0.3, -1.0, 2.0])
    inner = t.moved(s, Q, tr).moved(0.5, Q.T, -tr)  # twice: the frames compose
    assert inner.tree is t.tree
    s2, R2, t2 = s * 0.5, Q @ Q.T, s * Q @ -tr + tr
    P2 = (((P - tr) @ Q / s) + tr) @ Q.T / 0.5
    assert np.allclose(inner.points, P2) and np.allclose(s2 * P2 @ R2.T + t2, P)
    fresh = FitTarget.from_points(P2, N @ Q @ Q.T)
    X = P2[rng.integers(0, len(P2), 300)] + rng.normal(0, 0.1, (300, 3))
    a, b = inner.match(X), fresh.match(X)
    assert np.allclose(a.d2, b.d2, rtol=1e-9, atol=1e-14)
    d, i = inner.nearest(X, 1)
    brute = np.linalg.norm(X[:, None] - P2[None], axis=2)
    assert np.allclose(d, brute.min(axis=1)) and (i == brute.argmin(axis=1)).all()


def test_overlap_is_decided_as_by_counting_every_vertex():
    """The overlap test asks a stride of the vertices first; its decision is the count of
    all: a small cloud off the bar's end, placed where just enough (at least 1 % of the
    vertices) or just too few lie within reach, is fitted or refused as brute force says,
    and the message counts every vertex near it."""
    m = bar()
    V = m.vertices
    fitter = Fitter(m)
    need = max(3, 0.01 * len(V))
    corner = np.random.default_rng(9).random((8, 3)) * 1e-3
    seen = set()
    for gap in np.linspace(0.3, 0.7, 81):
        cloud = corner + [-gap, 0.0, 0.0]
        reach = 0.1 * max(np.linalg.norm(np.ptp(cloud, axis=0)),
                          np.linalg.norm(np.ptp(V, axis=0)))
        count = int((np.linalg.norm(V[:, None] - cloud[None], axis=2).min(axis=1)
                     <= reach).sum())
        if not need - 10 <= count < need + 10:
            continue
        refused = count < need
        seen.add(refused)
        target = FitTarget.from_points(cloud)
        if refused:
            with pytest.raises(InputError, match=f"only {count} of {len(V)} vertices"):
                fitter._check_overlap(target, (1.0, np.eye(3), np.zeros(3)))
        else:
            fitter._check_overlap(target, (1.0, np.eye(3), np.zeros(3)))
    assert seen == {True, False}


def test_similarity_recovers_a_known_transform():
    rng = np.random.default_rng(7)
    src = rng.random((20, 3))
    Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    Q *= np.sign(np.linalg.det(Q))
    s, R, t = similarity(src, 3.0 * src @ Q.T + [1.0, -2.0, 0.5])
    assert abs(s - 3.0) < 1e-12 and np.allclose(R, Q) and np.allclose(t, [1.0, -2.0, 0.5])
    s, R, t = similarity(src, src @ Q.T, scale=False)
    assert s == 1.0 and np.allclose(R, Q)


# -- bad input: library ----------------------------------------------------------------------


@pytest.mark.parametrize("target, match", [
    (np.array([[0.0, 0.0, np.nan], [1, 0, 0], [0, 1, 0], [1, 1, 0]]), "point 0 has a non-finite"),
    (np.zeros((0, 3)), "the point cloud is empty"),
    (np.zeros((5, 2)), r"shape \(n, 3\)"),
])
def test_bad_targets_are_refused(target, match):
    with pytest.raises(InputError, match=match):
        fit(bar(), target)


def test_landmark_out_of_range_and_no_overlap_are_refused(bent):
    m, h, G, fitter = bent
    with pytest.raises(InputError, match="landmark 0 is vertex 5000, out of range"):
        fitter.fit(G, {5000: [0.0, 0.0, 0.0]})
    with pytest.raises(InputError, match="no overlap"):
        fitter.fit(G + [100.0, 0.0, 0.0])
    with pytest.raises(InputError, match="no overlap"):  # landmarks that lead elsewhere
        fitter.fit(G, (h, G[h] + [100.0, 0.0, 0.0]))
    with pytest.raises(InputError, match="listed twice"):
        parse_landmarks([{"vertex": 1, "target": [0, 0, 0]}] * 2, 10)
    with pytest.raises(InputError, match="unknown key 'pos'"):
        parse_landmarks([{"vertex": 1, "pos": [0, 0, 0]}], 10)


# -- files and the command line --------------------------------------------------------------


def test_point_files_read(tmp_path):
    P = np.random.default_rng(8).random((10, 3))
    N = np.tile([0.0, 0.0, 1.0], (10, 1))
    np.save(tmp_path / "a.npy", np.hstack([P, N]))
    (tmp_path / "b.xyz").write_text("# a comment\n" + "\n".join(" ".join(map(str, p))
                                                                 for p in P))
    header = ["ply", "format ascii 1.0", "element vertex 10"]
    header += [f"property double {k}" for k in ("x", "y", "z", "nx", "ny", "nz")]
    (tmp_path / "c.ply").write_text("\n".join(header + ["end_header"]) + "\n" + "\n".join(
        " ".join(f"{float(c)!r}" for c in [*p, *n]) for p, n in zip(P, N)) + "\n")
    for name, has_normals in (("a.npy", True), ("b.xyz", False), ("c.ply", True)):
        Q, M = load_points(tmp_path / name)
        assert np.allclose(Q, P) and (M is not None) == has_normals
        if has_normals:
            assert np.allclose(M, N)
    (tmp_path / "bad.xyz").write_text("1 2 3\n4 5\n")
    with pytest.raises(InputError, match="line 2 has 2 numbers"):
        load_points(tmp_path / "bad.xyz")


def test_landmark_files_round_trip(tmp_path):
    save_landmarks(tmp_path / "lm.json", [3, 7], [[0.5, 0.0, 1.0], [1.0, 2.0, 3.0]])
    v, t = load_landmarks(tmp_path / "lm.json", 10)
    assert v.tolist() == [3, 7] and t.tolist() == [[0.5, 0.0, 1.0], [1.0, 2.0, 3.0]]


def test_cli_fits_the_example_with_defaults(tmp_path, capsys):
    out, rep, fig = tmp_path / "fitted.ply", tmp_path / "fit.json", tmp_path / "fit.png"
    code = main(["fit", str(EX / "finger.off"), str(EX / "finger-scan.xyz"), "-o", str(out),
                 "--landmarks", str(EX / "finger-landmarks.json"), "--report", str(rep),
                 "--figure", str(fig)])
    assert code == 0
    text = capsys.readouterr().out
    assert "fitted finger.off (802 vertices) to finger-scan.xyz" in text
    report = json.loads(rep.read_text())
    r = report["report"]
    # the 30 % of the finger the scan does not show is far from it: the mean stays low
    assert r["residual"]["mean"] < 0.01 and r["landmarks"] == 3 and r["iterations"] > 10
    assert set(r["residual"]) == {"mean", "p95", "max", "within_1pct"}
    assert r["time_s"] > 0 and r["stages"][-1]["stiffness"] == 0.003
    fitted = arapkit.load_mesh(out)
    assert fitted.n_vertices == 802 and np.array_equal(fitted.faces,
                                                       arapkit.load_mesh(EX / "finger.off").faces)
    assert fig.read_bytes()[:4] == b"\x89PNG"
    # against the truth: the finger bent 60 degrees by the script that made the scan
    import importlib.util

    spec = importlib.util.spec_from_file_location("make_examples", EX / "make_examples.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    V, F = mod.finger()
    truth = mod.finger_bend(V, 60)
    assert rms(fitted.vertices, truth) < 0.04 and rms(V, truth) > 0.15


def test_cli_rings_file(tmp_path):
    rings = tmp_path / "rings.txt"
    rings.write_text("\n".join(["3"] * 802))
    out = tmp_path / "fitted.off"
    assert main(["fit", str(EX / "finger.off"), str(EX / "finger-scan.xyz"), "-o", str(out),
                 "--rings-file", str(rings), "--report", "-", "-q"]) == 0
    assert out.exists()


def _bad_inputs(tmp_path: Path) -> dict[str, tuple[list[str], str]]:
    bad_nan = tmp_path / "nan.xyz"
    bad_nan.write_text("0 0 0\n1 0 nan\n0 1 0\n1 1 0\n")
    empty = tmp_path / "empty.xyz"
    empty.write_text("# nothing\n")
    empty_npy = tmp_path / "empty.npy"
    np.save(empty_npy, np.zeros((0, 3)))
    far = tmp_path / "far.xyz"
    np.savetxt(far, np.loadtxt(EX / "finger-scan.xyz")[:, :3] + [500.0, 0.0, 0.0])
    lm = tmp_path / "lm.json"
    lm.write_text('[{"vertex": 802, "target": [0, 0, 0]}]')
    scan = str(EX / "finger-scan.xyz")
    return {
        "nan": ([str(bad_nan)], "point 1 has a non-finite coordinate"),
        "empty": ([str(empty)], "the point cloud is empty"),
        "empty npy": ([str(empty_npy)], "the point cloud is empty"),
        "landmark": ([scan, "--landmarks", str(lm)], "landmark 0 is vertex 802, out of range"),
        "no overlap": ([str(far)], "no overlap"),
    }


@pytest.mark.parametrize("case", ["nan", "empty", "empty npy", "landmark", "no overlap"])
def test_cli_bad_input_one_line_exit_2_nothing_written(tmp_path, capsys, case):
    args, message = _bad_inputs(tmp_path)[case]
    outs = [tmp_path / "out.ply", tmp_path / "r.json", tmp_path / "f.png"]
    code = main(["fit", str(EX / "finger.off"), *args, "-o", str(outs[0]), "--report",
                 str(outs[1]), "--figure", str(outs[2])])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and err.startswith("arapkit: error: ") and message in err
    assert not any(p.exists() for p in outs)


def test_output_keeps_the_templates_attributes(tmp_path):
    """An OBJ template's UVs, material lines and vertex colours, and a PLY template's custom
    vertex property, are in the fitted file."""
    m = bar()
    uv = np.stack([m.vertices[:, 0] / 7.0, m.vertices[:, 1] + 0.5], axis=1)
    lines = ["mtllib bar.mtl"] + [f"v {x:.6f} {y:.6f} {z:.6f} 0.1 0.2 0.3"
                                  for x, y, z in m.vertices]
    lines += [f"vt {u:.6f} {v:.6f}" for u, v in uv] + ["usemtl skin"]
    lines += [f"f {a + 1}/{a + 1} {b + 1}/{b + 1} {c + 1}/{c + 1}" for a, b, c in m.faces]
    (tmp_path / "bar.obj").write_text("\n".join(lines) + "\n")
    np.save(tmp_path / "scan.npy", m.vertices * [1.0, 1.05, 1.0])
    out = tmp_path / "fitted.obj"
    assert main(["fit", str(tmp_path / "bar.obj"), str(tmp_path / "scan.npy"), "-o",
                 str(out), "-q"]) == 0
    text = out.read_text()
    vt_out = [[float(x) for x in ln.split()[1:]] for ln in text.splitlines()
              if ln.startswith("vt ")]
    assert np.allclose(vt_out, uv, atol=1e-6)
    assert "usemtl skin" in text and "mtllib bar.mtl" in text
    colours = [[float(x) for x in ln.split()[4:]] for ln in text.splitlines()
               if ln.startswith("v ")]
    assert np.allclose(colours, [[0.1, 0.2, 0.3]] * m.n_vertices)
    fitted = arapkit.load_mesh(out)
    assert fitted.n_vertices == m.n_vertices and not np.allclose(fitted.vertices, m.vertices)

    from arapkit.io import save_mesh

    save_mesh(tmp_path / "bar.ply", m.vertices, m.faces,
              vertex_properties={"label": np.arange(m.n_vertices, dtype=np.int32)})
    assert main(["fit", str(tmp_path / "bar.ply"), str(tmp_path / "scan.npy"), "-o",
                 str(tmp_path / "fitted.ply"), "-q"]) == 0
    from arapkit.io import read_ply_vertex_properties

    props = read_ply_vertex_properties(tmp_path / "fitted.ply")
    assert np.array_equal(props["label"], np.arange(m.n_vertices))
