"""Learning per-vertex rigidity from deforming shapes (paper sec. 3.4): arapkit.learn.fit + CLI."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import bfs_distances, data_path

from arapkit import InputError, Mesh, learn_rings
from arapkit.cli import main
from arapkit.learn.fit import AUTO_FLOOR, auto_omega, ring_energies, select_rings
from arapkit.mesh.weights import DEFAULT_WEIGHTS, edge_weights, voronoi_areas

JOINT, HALF = 4.0, 0.6  # the limb bends over x in [JOINT - HALF, JOINT + HALF]


# -- a synthetic limb ----------------------------------------------------------------------


def tube(length: float = 8.0, radius: float = 0.5, around: int = 16, along: int = 41):
    """Open tube along x; every other ring is turned half a step (near-equilateral faces)."""
    rings = []
    for a, x in enumerate(np.linspace(0.0, length, along)):
        phi = 2 * np.pi * (np.arange(around) + 0.5 * (a % 2)) / around
        rings.append(np.stack([np.full(around, x), radius * np.cos(phi),
                               radius * np.sin(phi)], axis=1))
    faces = []
    for a in range(along - 1):
        for i in range(around):
            p, q = a * around + i, a * around + (i + 1) % around
            p2, q2 = p + around, q + around
            faces += [[p, q, p2], [q, q2, p2]] if a % 2 == 0 else [[p, q2, p2], [p, q, q2]]
    return np.concatenate(rings), np.array(faces)


def bend(V: np.ndarray, degrees: float) -> np.ndarray:
    """Turn the x > JOINT segment rigidly about the z axis through the joint; the angle
    blends smoothly (smoothstep) across the joint region, so both segments stay rigid."""
    s = np.clip((V[:, 0] - (JOINT - HALF)) / (2 * HALF), 0.0, 1.0)
    theta = np.radians(degrees) * s * s * (3 - 2 * s)
    c, sn = np.cos(theta), np.sin(theta)
    x, y = V[:, 0] - JOINT, V[:, 1]
    return np.stack([JOINT + c * x - sn * y, sn * x + c * y, V[:, 2]], axis=1)


@pytest.fixture(scope="module")
def limb():
    V, F = tube()
    return Mesh(V, F, name="limb"), [bend(V, d) for d in (20, 40, 60, 80)]


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return Q * np.sign(np.linalg.det(Q))


# -- independent reference computation ------------------------------------------------------


def brute_force(mesh: Mesh, example: np.ndarray, k: int, r: int,
                weights: str = DEFAULT_WEIGHTS) -> tuple[float, float, float]:
    """E(k, r, m) straight from the definition, A(k, r), and the energy's scale."""
    dist = bfs_distances(mesh, k)
    far = 1 << 30
    E, w = mesh.edges, edge_weights(mesh, weights)
    sel = np.array([min(dist.get(i, far), dist.get(j, far)) <= r - 1 for i, j in E.tolist()])
    e1 = mesh.vertices[E[sel, 0]] - mesh.vertices[E[sel, 1]]
    em = example[E[sel, 0]] - example[E[sel, 1]]
    ws = w[sel]
    U, _, Vt = np.linalg.svd((ws[:, None] * e1).T @ em)
    Rk = Vt.T @ U.T
    if np.linalg.det(Rk) < 0:
        U[:, 2] *= -1
        Rk = Vt.T @ U.T
    energy = float(np.sum(ws * np.sum((em - e1 @ Rk.T) ** 2, axis=1)))
    area = float(sum(a for v, a in enumerate(voronoi_areas(mesh)) if dist.get(v, far) <= r))
    scale = float(np.sum(np.abs(ws) * (np.sum(e1**2, 1) + np.sum(em**2, 1))))
    return energy, area, scale


def check_against_brute_force(mesh: Mesh, examples: np.ndarray, ks: list[int],
                              weights: str = DEFAULT_WEIGHTS) -> None:
    mean, areas, raw = ring_energies(mesh, examples, 1, 6, weights=weights, per_example=True)
    assert raw is not None and raw.shape == (mesh.n_vertices, 6, len(examples))
    for k in ks:
        for r in range(1, 7):
            for m, ex in enumerate(examples):
                energy, area, scale = brute_force(mesh, ex, k, r, weights)
                assert raw[k, r - 1, m] == pytest.approx(energy, abs=1e-10 * scale), (k, r, m)
                assert areas[k, r - 1] == pytest.approx(area, rel=1e-12)
            assert mean[k, r - 1] == pytest.approx(np.mean(raw[k, r - 1]) / areas[k, r - 1],
                                                   rel=1e-12, abs=1e-300)


# -- (d) the kernel against the definition ----------------------------------------------------


def test_energies_match_brute_force_on_limb(limb):
    mesh, frames = limb
    rng = np.random.default_rng(1)
    # noise makes every rotation fit non-trivial; a rigid turn adds a global rotation
    examples = np.stack([frames[1] + 0.02 * rng.normal(size=frames[1].shape),
                         frames[3] @ random_rotation(rng).T + [1.0, -2.0, 0.5]])
    ends = int(np.argmax(mesh.vertices[:, 0]))  # on the boundary loop: truncated rings
    check_against_brute_force(mesh, examples, [0, ends, 330, 345])


@pytest.mark.parametrize("weights", ["cotan", DEFAULT_WEIGHTS])
def test_energies_match_brute_force_on_panda(weights):
    """A real skinned mesh with many obtuse triangles (negative raw cotangent weights)."""
    data = np.load(data_path("sequences", "panda_walk_seq.npz"))
    V, F = data["V"], data["F"]
    mesh = Mesh(V[0], F)
    # raw cotan: the case where E may be negative; the default has positive weights only
    assert (edge_weights(mesh, weights) < 0).any() == (weights == "cotan")
    check_against_brute_force(mesh, V[[7, 30]], [0, 123, 600], weights)


def test_example_batches_give_the_same_table(limb, monkeypatch):
    import arapkit.learn.energies as learn

    mesh, frames = limb
    whole = ring_energies(mesh, frames, 2, 5, per_example=True)
    monkeypatch.setattr(learn, "EXAMPLE_BYTES", 32 * len(mesh.edges) * 3)  # 3 per batch
    split = ring_energies(mesh, frames, 2, 5, per_example=True)
    for a, b in zip(whole, split, strict=True):
        assert np.allclose(a, b, rtol=1e-13, atol=1e-15)


# -- (a) the synthetic limb -----------------------------------------------------------------


@pytest.mark.parametrize("omega", ["auto", 0.02])
def test_limb_rigid_segments_and_soft_joint(limb, omega):
    mesh, frames = limb
    res = learn_rings(mesh, frames, omega=omega)
    x = mesh.vertices[:, 0]
    edge = 0.2  # the tube's spacing along x
    reach = HALF + 6 * edge  # beyond it, N(k, 6) lies inside one rigid segment
    rigid = np.abs(x - JOINT) > reach + 1e-9
    joint = np.abs(x - JOINT) <= 0.3
    assert rigid.sum() > 300 and joint.sum() >= 48
    assert (res.rings[rigid] == 6).all()
    assert (res.rings[joint] < 6).all()
    assert res.rings[joint].mean() <= 2.0
    assert res.energies.shape == (mesh.n_vertices, 6) and res.n_examples == 4


def test_limb_paper_omega_is_all_rigid(limb):
    """The normalised energies of a smooth bend are small: the paper's 0.3 keeps r_max."""
    mesh, frames = limb
    res = learn_rings(mesh, frames)
    assert res.omega == 0.3 and res.omega_rule == "given"
    assert (res.rings == 6).all()
    assert 0.001 < auto_omega(res.energies) < 0.05


# -- (c) rigid motions ---------------------------------------------------------------------


@pytest.mark.parametrize("omega", [0.3, "auto", 1e-9])
def test_rigid_motions_give_r_max(limb, omega):
    mesh, _ = limb
    rng = np.random.default_rng(5)
    frames = [mesh.vertices @ random_rotation(rng).T + rng.normal(size=3) * 10 for _ in range(3)]
    res = learn_rings(mesh, frames, r_min=2, r_max=5, omega=omega)
    assert (res.rings == 5).all()
    assert np.abs(res.energies).max() < 1e-10
    if omega == "auto":
        assert res.omega == AUTO_FLOOR


# -- (b) the panda walk ----------------------------------------------------------------------


def panda_regions(V: np.ndarray) -> dict[str, np.ndarray]:
    """Body parts of the panda's reference pose, from coordinates (z up, head towards -y).

    head: the 17% of the body length at the -y end. Lower legs: everything below a quarter
    of the height (only the legs reach down there). Shoulders and hips: the band between
    30% and 60% of the height above the four feet, i.e. where the legs meet the trunk; a
    foot is the mean (x, y) of the vertices below 10% of the height in one quadrant.
    """
    x, y, z = V.T
    h = (z - z.min()) / np.ptp(z)
    head = y < y.min() + 0.17 * np.ptp(y)
    low = h < 0.1
    feet = np.array([[x[s].mean(), y[s].mean()]
                     for s in (low & (x < 0) & (y < 0), low & (x >= 0) & (y < 0),
                               low & (x < 0) & (y >= 0), low & (x >= 0) & (y >= 0))])
    to_foot = np.min(np.hypot(x[:, None] - feet[:, 0], y[:, None] - feet[:, 1]), axis=1)
    radius = 0.1 * np.ptp(y)
    return {"head": head, "lower legs": h < 0.25,
            "shoulders and hips": (h >= 0.3) & (h < 0.6) & (to_foot < radius)}


def test_panda_head_and_lower_legs_stiffer_than_shoulders_and_hips():
    data = np.load(data_path("sequences", "panda_walk_seq.npz"))
    V, F = data["V"], data["F"]
    mesh = Mesh(V[0], F)
    res = learn_rings(mesh, V[1:], omega=0.02)
    counts = res.histogram()
    assert all(c >= 50 for c in counts.values()), counts  # r spreads over 1..6
    parts = panda_regions(V[0])
    mean = {name: res.rings[sel].mean() for name, sel in parts.items()}
    assert all(sel.sum() >= 50 for sel in parts.values())
    assert mean["head"] > mean["shoulders and hips"] + 1.5, mean
    assert mean["lower legs"] > mean["shoulders and hips"] + 0.5, mean
    # the observation: the paper's omega leaves nearly every vertex at r_max
    assert res.with_omega(0.3).histogram()[6] >= 890
    auto = res.with_omega("auto")
    assert 0.01 < auto.omega < 0.04 and auto.omega_rule == "auto"
    assert auto.rings[parts["head"]].mean() > auto.rings[parts["shoulders and hips"]].mean()


# -- omega and selection ---------------------------------------------------------------------


def test_select_rings_prefers_rigid_on_ties_and_follows_omega():
    E = np.array([[0.0, 0.1, 0.3], [0.0, 0.0, 0.0], [-1.0, 0.0, 0.0]])
    assert select_rings(E, 0.0, 1, 3).tolist() == [1, 3, 1]
    assert select_rings(E, 0.15, 1, 3).tolist() == [2, 3, 1]
    assert select_rings(E, 1.0, 1, 3).tolist() == [3, 3, 3]
    assert auto_omega(np.zeros((4, 3))) == AUTO_FLOOR
    assert auto_omega(np.zeros((4, 1))) == AUTO_FLOOR


# -- (e) bad inputs --------------------------------------------------------------------------


def test_bad_inputs(limb):
    mesh, frames = limb
    with pytest.raises(InputError, match="at least one example"):
        learn_rings(mesh, [])
    with pytest.raises(InputError, match="example 1 has 10 vertices, the reference 656"):
        learn_rings(mesh, [frames[0], frames[0][:10]])
    other = Mesh(frames[0], mesh.faces[:, [0, 2, 1]], name="flipped")
    with pytest.raises(InputError, match="flipped.*different faces"):
        learn_rings(mesh, [other])
    with pytest.raises(InputError, match="r_max .2. must be >= r_min .3."):
        learn_rings(mesh, frames, r_min=3, r_max=2)
    with pytest.raises(InputError, match="omega must be"):
        learn_rings(mesh, frames, omega=-1)
    with pytest.raises(InputError, match="omega must be"):
        learn_rings(mesh, frames, omega="often")
    with pytest.raises(InputError, match="non-finite"):
        learn_rings(mesh, [np.full_like(frames[0], np.nan)])
    with pytest.warns(UserWarning, match="1 of 2 examples are identical to the reference"):
        res = learn_rings(mesh, [mesh.vertices, frames[2]])
    assert res.identical == [0]


# -- command line ------------------------------------------------------------------------------


def write_off(path, V, F) -> None:
    lines = ["OFF", f"{len(V)} {len(F)} 0"]
    lines += [" ".join(repr(float(c)) for c in v) for v in V]
    lines += ["3 " + " ".join(str(int(i)) for i in f) for f in F]
    path.write_text("\n".join(lines) + "\n")


@pytest.fixture
def limb_files(tmp_path, limb):
    mesh, frames = limb
    folder = tmp_path / "poses"
    folder.mkdir()
    for i, V in enumerate([mesh.vertices, *frames]):
        write_off(folder / f"pose_{i}.off", V, mesh.faces)
    return folder


def test_cli_folder_writes_rings_ply_and_figure(tmp_path, limb, limb_files, capsys):
    from arapkit.io import load_rings, read_ply_vertex_properties

    mesh, frames = limb
    out, ply, fig = tmp_path / "r.txt", tmp_path / "r.ply", tmp_path / "r.png"
    assert main(["learn", str(limb_files), "-o", str(out), "--ply", str(ply),
                 "--figure", str(fig), "--energies", str(tmp_path / "e.npy")]) == 0
    expected = learn_rings(mesh, frames, omega="auto")
    assert load_rings(out, mesh.n_vertices).tolist() == expected.rings.tolist()
    assert read_ply_vertex_properties(ply)["rings"].tolist() == expected.rings.tolist()
    assert fig.read_bytes()[:4] == b"\x89PNG"
    assert np.allclose(np.load(tmp_path / "e.npy"), expected.energies)
    stdout = capsys.readouterr().out
    assert f"omega = {expected.omega:.4g} (auto)" in stdout and "4 examples" in stdout


def test_cli_glob_reference_and_paper_omega(tmp_path, limb, limb_files, capsys):
    mesh, frames = limb
    out = tmp_path / "r.txt"
    assert main(["learn", str(limb_files / "pose_*.off"), "-o", str(out), "--reference", "2",
                 "--omega", "0.3", "--r-max", "4", "--quiet"]) == 0
    assert out.read_text().split() == ["4"] * mesh.n_vertices
    assert "pose_2.off" in capsys.readouterr().out


def test_cli_npz_and_identical_frame_warning(tmp_path, limb, capsys):
    mesh, frames = limb
    npz = tmp_path / "seq.npz"
    np.savez(npz, V=np.stack([mesh.vertices, frames[0], mesh.vertices]), F=mesh.faces)
    assert main(["learn", str(npz), "-o", str(tmp_path / "r.txt")]) == 0
    err = capsys.readouterr().err
    assert "warning: seq.npz[2] is identical to the reference" in err


@pytest.mark.parametrize(
    "case, message",
    [
        ("one frame", "at least two frames"),
        ("vertex count", "pose_1.off: has 640 vertices but the reference pose_0.off has 656"),
        ("faces", "pose_1.off: faces differ from the reference"),
        ("reference", "--reference 7 is out of range: there are 2 frames"),
        ("glob", "no files match"),
        ("npz keys", "expected arrays 'V'"),
        ("npz and mesh", "give .npz files alone"),
        ("ply output", "use --ply"),
    ],
)
def test_cli_bad_inputs(tmp_path, limb, capsys, case, message):
    mesh, frames = limb
    V, F = mesh.vertices, mesh.faces
    write_off(tmp_path / "pose_0.off", V, F)
    args = [str(tmp_path / "pose_0.off"), str(tmp_path / "pose_1.off")]
    extra: list[str] = []
    out = str(tmp_path / "r.txt")
    if case == "one frame":
        args = args[:1]
    elif case == "vertex count":
        keep = F.max(axis=1) < 640  # drop the last ring of vertices and its faces
        write_off(tmp_path / "pose_1.off", frames[0][:640], F[keep])
    elif case == "faces":
        write_off(tmp_path / "pose_1.off", frames[0], F[:, [0, 2, 1]])
    else:
        write_off(tmp_path / "pose_1.off", frames[0], F)
    if case == "reference":
        extra = ["--reference", "7"]
    elif case == "glob":
        args = [str(tmp_path / "nothing_*.off")]
    elif case == "npz keys":
        np.savez(tmp_path / "bad.npz", X=V)
        args = [str(tmp_path / "bad.npz")]
    elif case == "npz and mesh":
        np.savez(tmp_path / "seq.npz", V=np.stack([V, V]), F=F)
        args = [str(tmp_path / "seq.npz"), args[0]]
    elif case == "ply output":
        out = str(tmp_path / "r.ply")
    assert main(["learn", *args, "-o", out, *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1, err
