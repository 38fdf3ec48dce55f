"""Point cloud files: every readable format, every per-point value written back, bad files
in one line, and mesh loading unchanged (arapkit.io.clouds, arapkit.io.cloud_writer).

Oracles: files written here by hand (text) or byte by byte (binary PLY), the rotations a
solve reports applied to the normals by hand, and load_mesh for files with faces.
"""

from __future__ import annotations

import gzip
from pathlib import Path

import numpy as np
import pytest

import arapkit
from arapkit import Deformer, InputError, PointCloud, load_points, save_mesh, save_points
from arapkit.io import load_mesh, load_shape, read_ply
from arapkit.mesh.model import Mesh

RNG = np.random.default_rng(0)
N_PTS = 60
P = RNG.random((N_PTS, 3)) * [3, 1, 1]
NRM = RNG.normal(size=(N_PTS, 3))
NRM /= np.linalg.norm(NRM, axis=1)[:, None]
RGB = RNG.integers(0, 256, (N_PTS, 3)).astype(np.uint8)
CONF = RNG.random(N_PTS).astype(np.float32)
LABEL = RNG.integers(-5, 5, N_PTS).astype(np.int16)


def _ply_binary(path: Path, faces: bool = False) -> None:
    """A binary PLY point cloud written byte by byte: float positions and normals, uchar
    colours, two custom properties, and (``faces``) an empty face element."""
    dt = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("nx", "<f4"), ("ny", "<f4"),
                   ("nz", "<f4"), ("red", "u1"), ("green", "u1"), ("blue", "u1"),
                   ("confidence", "<f4"), ("label", "<i2")])
    rec = np.empty(N_PTS, dtype=dt)
    for i, c in enumerate("xyz"):
        rec[c] = P[:, i]
    for i, c in enumerate(("nx", "ny", "nz")):
        rec[c] = NRM[:, i]
    for i, c in enumerate(("red", "green", "blue")):
        rec[c] = RGB[:, i]
    rec["confidence"], rec["label"] = CONF, LABEL
    head = ["ply", "format binary_little_endian 1.0", "comment scanner X", f"element vertex "
            f"{N_PTS}"] + [f"property {t} {n}" for n, t in (
                ("x", "float"), ("y", "float"), ("z", "float"), ("nx", "float"), ("ny", "float"),
                ("nz", "float"), ("red", "uchar"), ("green", "uchar"), ("blue", "uchar"),
                ("confidence", "float"), ("label", "short"))]
    if faces:
        head += ["element face 0", "property list uchar int vertex_indices"]
    path.write_bytes(("\n".join(head + ["end_header"]) + "\n").encode() + rec.tobytes())


def _rows(A: np.ndarray) -> str:
    return "\n".join(" ".join(repr(float(x)) for x in row) for row in A) + "\n"


@pytest.fixture()
def files(tmp_path) -> dict[str, Path]:
    out = {}
    out["ply"] = tmp_path / "scan.ply"
    _ply_binary(out["ply"])
    out["ply-empty-faces"] = tmp_path / "scan_f.ply"
    _ply_binary(out["ply-empty-faces"], faces=True)
    out["obj"] = tmp_path / "scan.obj"
    out["obj"].write_text("o scan\n" + "".join(
        f"v {x!r} {y!r} {z!r} {r / 255!r} {g / 255!r} {b / 255!r}\n"
        for (x, y, z), (r, g, b) in zip(P.tolist(), RGB.tolist(), strict=True)))
    out["off"] = tmp_path / "scan.off"
    out["off"].write_text(f"NOFF\n{N_PTS} 0 0\n" + _rows(np.hstack([P, NRM])))
    out["xyz"] = tmp_path / "scan.xyz"
    out["xyz"].write_text(_rows(np.hstack([P, CONF[:, None]])))
    out["xyzn"] = tmp_path / "scan.xyzn"
    out["xyzn"].write_text(_rows(np.hstack([P, NRM])))
    out["xyzrgb"] = tmp_path / "scan.xyzrgb"
    out["xyzrgb"].write_text(_rows(np.hstack([P, RGB])))
    out["npy"] = tmp_path / "scan.npy"
    np.save(out["npy"], P)
    out["xyz.gz"] = tmp_path / "scan.xyz.gz"
    out["xyz.gz"].write_bytes(gzip.compress(_rows(P).encode()))
    return out


WHAT = {  # format: (normals, colours, custom properties)
    "ply": (True, True, {"confidence", "label"}),
    "ply-empty-faces": (True, True, {"confidence", "label"}),
    "obj": (False, True, set()),
    "off": (True, False, set()),
    "xyz": (False, False, set()),
    "xyzn": (True, False, set()),
    "xyzrgb": (False, True, set()),
    "npy": (False, False, set()),
    "xyz.gz": (False, False, set()),
}


@pytest.mark.parametrize("fmt", list(WHAT))
def test_every_format_loads_as_a_cloud_with_its_attributes(files, fmt):
    c = load_points(files[fmt])
    assert isinstance(c, PointCloud) and c.n_vertices == N_PTS
    tol = 1e-7 if fmt.startswith("ply") else 0.0  # float32 positions in the PLY
    assert np.abs(c.points - P).max() <= tol * 3
    normals, colours, props = WHAT[fmt]
    assert (c.normals is not None) == normals
    if normals:
        assert np.abs(c.normals - NRM).max() <= 1e-7
    rgb = c.attributes.colors()
    assert (rgb is not None) == colours
    if colours:
        assert np.abs(rgb[:, :3] - RGB / 255.0).max() < 1e-12
    assert props <= set(c.attributes.vertex_properties)
    if fmt == "xyz":  # the fourth column kept verbatim
        assert np.array_equal(c.attributes.vertex_extra[:, 0], CONF.astype(np.float64))
    # load_shape reads it as a cloud too, and the doors' arrays are the points
    assert isinstance(load_shape(files[fmt]), PointCloud)


def test_load_shape_is_load_mesh_for_files_with_faces(tmp_path):
    for name in ("bar.off", "cactus.off", "finger.off"):
        a, b = load_shape(Path("examples") / name), load_mesh(Path("examples") / name)
        assert isinstance(a, Mesh) and np.array_equal(a.vertices, b.vertices)
        assert np.array_equal(a.faces, b.faces) and a.notes == b.notes
    # load_points reads a mesh file's vertices, and says the faces were not used
    c = load_points("examples/bar.off")
    assert isinstance(c, PointCloud) and "face(s) were not used" in c.notes[0]
    with pytest.raises(InputError, match="sets a point cloud's graph; this file is a "
                       "triangle mesh"):
        load_shape("examples/bar.off", neighbours=6)


def test_a_mesh_loader_still_refuses_a_file_without_faces(files):
    """load_mesh keeps its own words for a faceless file (mesh loading is unchanged)."""
    with pytest.raises(InputError, match="no faces"):
        load_mesh(files["ply"])
    with pytest.raises(InputError, match="no faces: the file has no 'f' lines"):
        load_mesh(files["obj"])


@pytest.mark.parametrize("src", ["ply", "xyzn", "off"])
def test_writing_back_keeps_every_value_and_turns_the_normals(files, tmp_path, src):
    c = load_points(files[src])
    h = np.flatnonzero(c.points[:, 0] < 0.5)
    t = np.flatnonzero(c.points[:, 0] > 2.5)
    T = np.vstack([c.points[h], c.points[t] + [0, 0, 0.8]])
    res = Deformer(c, np.concatenate([h, t]), rings=2).solve(T)
    out = tmp_path / f"out.{'ply' if src == 'ply' else src}"
    assert save_mesh(out, res, like=c, vertex_properties={"energy": res.vertex_energy}
                     if src == "ply" else None) == []
    back = load_points(out)
    assert np.abs(back.points - res.vertices).max() < 1e-12
    turned = np.einsum("nij,nj->ni", res.rotations, c.normals)
    assert np.abs(back.normals - turned).max() < 1e-6  # float32 normals in the PLY
    assert np.abs(back.normals - c.normals).max() > 0.05  # they did turn
    if src == "ply":
        ply = read_ply(out.read_bytes(), str(out))
        v = ply.elements["vertex"].data
        assert list(ply.elements) == ["vertex"]  # no face element
        assert ply.comments[1] == "comment scanner X"
        assert v["nx"].dtype == np.float32 and v["label"].dtype == np.int16
        assert np.array_equal(v["label"], LABEL) and np.array_equal(v["confidence"], CONF)
        assert np.array_equal(np.stack([v["red"], v["green"], v["blue"]], 1), RGB)
        assert np.allclose(v["energy"], res.vertex_energy)


def test_positions_alone_turn_the_normals_by_fitted_rotations(files, tmp_path):
    """Without a solve's rotations, each normal turns by the rotation fitted to its point's
    neighbourhood: a rigid motion of the points turns them exactly."""
    from scipy.spatial.transform import Rotation

    c = load_points(files["xyzn"])
    R = Rotation.from_rotvec([0.3, -1.2, 0.5]).as_matrix()
    assert save_mesh(tmp_path / "o.xyzn", c.points @ R.T + 2.0, like=c) == []
    assert np.abs(load_points(tmp_path / "o.xyzn").normals - NRM @ R.T).max() < 1e-12


def test_formats_without_room_say_what_they_drop(files, tmp_path):
    c = load_points(files["ply"])
    warn = save_points(tmp_path / "o.xyz", c)
    assert any("normals were not written" in w for w in warn)
    assert any("PLY vertex properties were not written" in w for w in warn)
    assert save_points(tmp_path / "o.xyzrgb", c) == [
        "o.xyzrgb: XYZRGB cannot carry them: normals were not written",
        "o.xyzrgb: XYZRGB cannot carry them: PLY vertex properties were not written"]
    back = load_points(tmp_path / "o.xyzrgb")
    assert np.abs(back.attributes.colors() - RGB / 255.0).max() < 1e-12
    with pytest.raises(InputError, match="unsupported point cloud format '.stl'"):
        save_points(tmp_path / "o.stl", c)
    with pytest.raises(InputError, match="this point cloud has no normals"):
        save_points(tmp_path / "o.xyzn", load_points(files["xyz"]))
    assert not (tmp_path / "o.xyzn").exists() and not (tmp_path / "o.stl").exists()


def test_a_cloud_from_an_array_saves_as_plain_points(tmp_path):
    c = PointCloud(P)
    assert save_points(tmp_path / "p.npy", c) == []
    assert np.array_equal(np.load(tmp_path / "p.npy"), P)
    assert save_mesh(tmp_path / "p.ply", c) == []  # save_mesh(path, cloud) writes a cloud
    assert np.array_equal(load_points(tmp_path / "p.ply").points, P)


@pytest.mark.parametrize("name, content, message", [
    ("e.xyz", "", "the point cloud is empty"),
    ("b.xyz", "0 0 0\n1 x 0\n", "line 2: malformed number"),
    ("s.xyzn", "0 0 0 0 0 1\n1 0 0 0\n", r"line 2 has 4 numbers: a row of .xyzn needs 6"),
    ("n.xyz", "0 0 0\nnan 0 0\n", "point 1 has a non-finite coordinate"),
    ("short.xyz", "0 0\n", "a row of .xyz needs 3"),
    ("o.off", "OFF\n3 0 0\n0 0 0\n1 0 0\n", "truncated"),
    ("z.off", "OFF\n0 0 0\n", "the point cloud is empty"),
    ("v.obj", "o nothing\n", "no vertices"),
    ("p.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float a\nend_header\n1\n",
     "PLY vertices have no x, y, z properties"),
    ("t.ply", "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
              "property float z\nend_header\n0 0 0\n", "ply"),
    ("u.csv", "0 0 0\n", "unsupported point cloud format '.csv'"),
])
def test_bad_files_are_refused_in_one_line(tmp_path, name, content, message):
    p = tmp_path / name
    p.write_text(content)
    with pytest.raises(InputError, match=message) as e:
        load_points(p)
    msg = str(e.value)
    assert "\n" not in msg and str(p) in msg or p.name in msg


@pytest.mark.parametrize("array, message", [
    (np.zeros((4, 2)), r"must have shape \(n, 3\), or \(n, 6\) with normals, got \(4, 2\)"),
    (np.array(["a", "b", "c"] * 2).reshape(2, 3), "must hold numbers"),
    (np.zeros((0, 3)), "the point cloud is empty"),
])
def test_bad_arrays_are_refused_in_one_line(tmp_path, array, message):
    np.save(tmp_path / "a.npy", array)
    with pytest.raises(InputError, match=message):
        load_points(tmp_path / "a.npy")


def test_missing_files_and_folders_are_refused_in_one_line(tmp_path):
    with pytest.raises(InputError, match="no such file"):
        load_points(tmp_path / "gone.ply")
    with pytest.raises(InputError, match="is a folder"):
        load_points(tmp_path)
    with pytest.raises(InputError, match="no such file"):
        load_points(tmp_path / "gone.npy")


def test_the_graph_options_reach_the_cloud(files):
    assert load_points(files["xyz"], neighbours=4).neighbours == 4
    c = load_points(files["xyz"], radius=0.5)
    assert c.radius == 0.5 and c.neighbours is None
    assert arapkit.load_points is load_points


def test_the_fits_formats_load_through_the_one_loader(tmp_path):
    """What the template fit's first reader took (``.npy`` (n, 6), ``.xyz`` / ``.txt`` /
    ``.pts`` rows ``x y z nx ny nz``) loads here, normals included; a ``.xyz`` whose last
    three columns are not unit vectors (colours) keeps them verbatim instead; and
    ``arapkit.io.points`` (kept for one release) and the fit's target read the same."""
    from arapkit.io.points import load_points as legacy_points
    from arapkit.workflows.fitting import load_target

    rng = np.random.default_rng(46)
    P = rng.random((30, 3))
    N = rng.normal(size=(30, 3))
    N /= np.linalg.norm(N, axis=1)[:, None]
    np.save(tmp_path / "a.npy", np.hstack([P, N]))
    for ext in ("xyz", "txt", "pts"):
        np.savetxt(tmp_path / f"b.{ext}", np.round(np.hstack([P, N]), 4), fmt="%.4f")
    for name in ("a.npy", "b.xyz", "b.txt", "b.pts"):
        c = load_points(tmp_path / name)
        tol = 0 if name.endswith("npy") else 1e-4
        assert np.abs(c.points - P).max() <= tol and c.normals is not None, name
        assert np.abs(c.normals - N).max() <= 2 * tol + 1e-12, name
        Q, M = legacy_points(tmp_path / name)
        assert np.array_equal(Q, c.points) and np.array_equal(M, c.normals)
        t = load_target(tmp_path / name)
        assert t.kind == "points" and np.array_equal(t.points, c.points) and t.oriented
    rgb = np.hstack([P, rng.integers(0, 256, (30, 3))])
    np.savetxt(tmp_path / "c.xyz", rgb, fmt="%.6g")
    c = load_points(tmp_path / "c.xyz")
    assert c.normals is None and np.array_equal(c.attributes.vertex_extra, rgb[:, 3:])
    # x y z nx ny nz rows are written back so, the normals turned with the shape
    c = load_points(tmp_path / "b.xyz")
    Rz = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    assert save_points(tmp_path / "out.xyz", c.points @ Rz.T, like=c) == []
    back = np.loadtxt(tmp_path / "out.xyz")
    assert back.shape == (30, 6) and np.allclose(back[:, 3:], c.normals @ Rz.T, atol=1e-9)
