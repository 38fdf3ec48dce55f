"""Nothing lost on the way out: UVs, normals, materials, polygons, colours, PLY properties.

Every file here is written by the test itself, so the expected arrays are known by
construction; the deformed positions are checked against the Python API.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from ply_oracle import parse_ply

from arapkit import Deformer, load_mesh
from arapkit.io import save_mesh
from arapkit.mesh.attributes import polygon_area_vectors

CUBE_V = np.array(
    [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]],
    dtype=float,
)
# six quads, outward orientation
CUBE_Q = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]]


def cube_corner_uv() -> list[list[int]]:
    """vt index (0-based) of every corner: vertices 0..5 have two vt each, 6 and 7 one
    -> 14 vt in all, with seams at vertices 0..5."""
    own: dict[int, list[int]] = {}
    nxt = 0
    for v in range(8):
        k = 2 if v < 6 else 1
        own[v] = list(range(nxt, nxt + k))
        nxt += k
    seen = dict.fromkeys(range(8), 0)
    out = []
    for q in CUBE_Q:
        row = []
        for v in q:
            row.append(own[v][seen[v] % len(own[v])])
            seen[v] += 1
        out.append(row)
    return out


UV = np.array([[i / 13.0, ((7 * i) % 13) / 13.0] for i in range(14)])
HEAD = ["mtllib cube.mtl", "o cube"]


def cube_obj_text() -> str:
    lines = ["# a textured cube", *HEAD]
    lines += [f"v {x:g} {y:g} {z:g}" for x, y, z in CUBE_V]
    lines += [f"vt {u!r} {v!r}" for u, v in UV.tolist()]
    lines += ["vn 0 0 -1", "vn 0 0 1", "vn 0 -1 0", "vn 1 0 0", "vn 0 1 0", "vn -1 0 0"]
    cuv = cube_corner_uv()
    for f, q in enumerate(CUBE_Q):
        if f == 0:
            lines += ["g bottom_sides", "usemtl red", "s off"]
        if f == 3:
            lines += ["g rest", "usemtl blue"]
        lines.append("f " + " ".join(f"{v + 1}/{t + 1}/{f + 1}" for v, t in
                                     zip(q, cuv[f], strict=True)))
    return "\n".join(lines) + "\n"


def arapkit(*args) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONWARNINGS": "ignore"}
    return subprocess.run([sys.executable, "-m", "arapkit.cli", *map(str, args)],
                          capture_output=True, text=True, env=env, timeout=600)


def parse_obj_for_test(path: Path) -> dict:
    """Independent minimal OBJ reader: lines by kind, corners as (v, vt, vn) 0-based."""
    out: dict = {"v": [], "vt": [], "vn": [], "f": [], "other": []}
    for line in path.read_text().splitlines():
        t = line.split()
        if not t or t[0].startswith("#"):
            continue
        if t[0] in ("v", "vt", "vn"):
            out[t[0]].append([float(x) for x in t[1:]])
        elif t[0] == "f":
            out["f"].append([tuple(int(p) - 1 if p else -1 for p in c.split("/"))
                             for c in t[1:]])
        else:
            out["other"].append(line.strip())
    return out


def handles_file(tmp_path: Path) -> Path:
    h = tmp_path / "h.json"
    h.write_text(json.dumps([
        {"name": "base", "indices": [0, 1, 2, 3]},
        {"name": "top", "indices": [6], "translate": [0.2, 0.1, 0.3]},
    ]))
    return h


def test_textured_obj_round_trip_through_cli(tmp_path):
    src = tmp_path / "cube.obj"
    src.write_text(cube_obj_text())
    out = tmp_path / "out.obj"
    proc = arapkit("deform", src, "-H", handles_file(tmp_path), "-o", out, "-q")
    assert proc.returncode == 0, proc.stderr
    assert "warning" not in proc.stderr  # OBJ -> OBJ loses nothing
    got = parse_obj_for_test(out)
    # same vt array, exactly
    np.testing.assert_array_equal(np.array(got["vt"]), UV)
    # same corner -> vertex and corner -> vt tables; quads stay quads
    assert [[c[0] for c in f] for f in got["f"]] == CUBE_Q
    assert [[c[1] for c in f] for f in got["f"]] == cube_corner_uv()
    assert [[c[2] for c in f] for f in got["f"]] == [[f] * 4 for f in range(6)]
    # mtllib / usemtl / g / o / s in their places
    kinds = [ln if ln[0] != "f" else "f" for ln in out.read_text().splitlines()
             if not ln.startswith(("v", "#"))]
    assert kinds == ["mtllib cube.mtl", "o cube", "g bottom_sides", "usemtl red", "s off",
                     "f", "f", "f", "g rest", "usemtl blue", "f", "f", "f"]
    # positions: the Python API's result on the same file
    mesh = load_mesh(src)
    ref = Deformer(mesh, [0, 1, 2, 3, 6]).solve(
        np.vstack([CUBE_V[:4], CUBE_V[6] + [0.2, 0.1, 0.3]])).vertices
    V = np.array(got["v"])
    np.testing.assert_allclose(V, ref, rtol=0, atol=1e-12)
    assert np.linalg.norm(V - CUBE_V, axis=1).max() > 0.1  # really deformed
    # normals: one per original vn (flat layout kept), recomputed from the deformed quads
    N = np.array(got["vn"])
    for f, q in enumerate(CUBE_Q):
        P = V[q]
        fan = sum(np.cross(P[t] - P[0], P[t + 1] - P[0]) for t in range(1, len(q) - 1))
        np.testing.assert_allclose(N[f], fan / np.linalg.norm(fan), atol=1e-12)


def test_obj_colours_and_degenerate_faces_written_back(tmp_path):
    src = tmp_path / "c.obj"
    src.write_text(
        "v 0 0 0 1 0 0\nv 1 0 0 0 1 0\nv 0 1 0 0 0 1\nv 1 1 0 0.5 0.25 0.125\n"
        "f 1 2 3\nf 2 4 3\nf 1 1 2\nf 2 4 3\n"  # a repeated-vertex face and a duplicate
    )
    mesh = load_mesh(src)
    assert mesh.n_faces == 2
    V = mesh.vertices + [0, 0, 1.5]
    out = tmp_path / "o.obj"
    assert save_mesh(out, V, like=mesh) == []
    got = parse_obj_for_test(out)
    np.testing.assert_array_equal(np.array(got["v"])[:, 3:],
                                  [[1, 0, 0], [0, 1, 0], [0, 0, 1], [0.5, 0.25, 0.125]])
    np.testing.assert_array_equal(np.array(got["v"])[:, :3], V)
    assert [[c[0] for c in f] for f in got["f"]] == [[0, 1, 2], [1, 3, 2], [0, 0, 1],
                                                      [1, 3, 2]]


PLY_HEAD = """ply
format ascii 1.0
comment colours, a float and an int property, one quad
element vertex 5
property float x
property float y
property float z
property uchar red
property uchar green
property uchar blue
property uchar alpha
property float quality
property int label
element face 3
property list uchar int vertex_indices
property ushort part
end_header
"""
PLY_V = [
    "0 0 0 255 0 0 255 0.5 7",
    "1 0 0 0 255 0 128 0.25 -3",
    "1 1 0 0 0 255 0 1.5 2",
    "0 1 0 10 20 30 40 2 1",
    "2 0.5 0 1 2 3 4 3.125 -70000",
]
PLY_F = ["4 0 1 2 3 11", "3 1 4 2 65535", "3 0 0 1 2"]


def test_ply_colours_and_properties_kept_exactly(tmp_path):
    src = tmp_path / "p.ply"
    src.write_text(PLY_HEAD + "\n".join(PLY_V + PLY_F) + "\n")
    out = tmp_path / "out.ply"
    h = tmp_path / "h.json"
    h.write_text(json.dumps([{"indices": [0, 3]}, {"indices": [4], "translate": [0, 0, 0.5]}]))
    proc = arapkit("deform", src, "-H", h, "-o", out, "-q")
    assert proc.returncode == 0, proc.stderr
    assert "warning" not in proc.stderr
    # the tests' own record-by-record reader (tests/ply_oracle.py) as the independent one
    ply = parse_ply(out.read_bytes())
    vert, face, types = ply["elements"]["vertex"], ply["elements"]["face"], ply["types"]
    names = list(vert)
    assert names[:9] == ["x", "y", "z", "red", "green", "blue", "alpha", "quality", "label"]
    assert [types["vertex", k] for k in ("red", "alpha", "quality", "label")] == [
        "uchar", "uchar", "float", "int"]
    cols = np.array([[float(t) for t in row.split()] for row in PLY_V])
    for j, name in enumerate(["red", "green", "blue", "alpha", "quality", "label"]):
        np.testing.assert_array_equal(vert[name], cols[:, 3 + j])
    assert {"energy", "rings"} <= set(names)  # arapkit's own per-vertex values stay
    polys = face["vertex_indices"]
    assert polys == [[0, 1, 2, 3], [1, 4, 2], [0, 0, 1]]  # the quad and the degenerate face
    np.testing.assert_array_equal(face["part"], [11, 65535, 2])
    assert types["face", "part"] == "ushort"
    V = np.stack([vert[c] for c in "xyz"], axis=1)
    np.testing.assert_allclose(V[[0, 3]], cols[[0, 3], :3], atol=1e-12)
    np.testing.assert_allclose(V[4], [2, 0.5, 0.5], atol=1e-12)
    # and arapkit reads its own output back with everything on it
    again = load_mesh(out)
    assert again.attributes.face_sizes.tolist() == [4, 3, 3]
    assert again.attributes.vertex_properties["label"].tolist() == [7, -3, 2, 1, -70000]


def test_warnings_where_the_format_has_no_place(tmp_path):
    src = tmp_path / "cube.obj"
    src.write_text(cube_obj_text())
    out = tmp_path / "out.off"
    proc = arapkit("deform", src, "-H", handles_file(tmp_path), "-o", out, "-q")
    assert proc.returncode == 0, proc.stderr
    warns = [ln for ln in proc.stderr.splitlines() if ln.startswith("arapkit: warning: ")]
    assert len(warns) == 3, proc.stderr
    joined = " ".join(warns)
    assert "texture coordinates (vt)" in joined and "normals (vn)" in joined
    assert "materials/groups (g, mtllib, o, s, usemtl)" in joined
    # OFF keeps the quads
    lines = out.read_text().splitlines()
    assert lines[1] == "8 6 0" and all(ln.startswith("4 ") for ln in lines[10:16])
    # STL additionally splits the polygons
    mesh = load_mesh(src)
    w = save_mesh(tmp_path / "o.stl", mesh.vertices, like=mesh)
    assert any("polygons were split" in x for x in w) and len(w) == 4


def test_normals_follow_the_area_weighted_rule():
    V = np.array([[0.0, 0, 0], [2, 0, 0], [0, 1, 0], [0, 0, 3]])
    sizes, corners = np.array([3, 3]), np.array([0, 1, 2, 0, 2, 3])
    A = polygon_area_vectors(V, sizes, corners)
    np.testing.assert_allclose(A, [[0, 0, 1.0], [1.5, 0, 0]])


def test_smooth_normals_are_area_weighted_vertex_normals(tmp_path):
    """One vn per vertex (f v//v): after a deformation each is the normalised sum of
    the cross products of the triangles around the vertex, computed here by loops."""
    n = 5
    x, y = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n))
    V = np.stack([x.ravel(), y.ravel(), np.zeros(n * n)], axis=1)
    F = []
    for i in range(n - 1):
        for j in range(n - 1):
            a, b, c, d = i * n + j, i * n + j + 1, (i + 1) * n + j, (i + 1) * n + j + 1
            F += [[a, b, d], [a, d, c]]
    lines = [f"v {p[0]!r} {p[1]!r} {p[2]!r}" for p in V.tolist()]
    lines += ["vn 0 0 1"] * len(V)
    lines += ["f " + " ".join(f"{v + 1}//{v + 1}" for v in f) for f in F]
    src = tmp_path / "g.obj"
    src.write_text("\n".join(lines) + "\n")
    mesh = load_mesh(src)
    bent = mesh.vertices + np.stack([np.zeros(n * n), np.zeros(n * n),
                                     0.3 * np.sin(3 * V[:, 0]) * V[:, 1] ** 2], axis=1)
    out = tmp_path / "o.obj"
    assert save_mesh(out, bent, like=mesh) == []
    got = parse_obj_for_test(out)
    N = np.array(got["vn"])
    expect = np.zeros_like(V)
    for f in F:
        P = bent[f]
        cr = np.cross(P[1] - P[0], P[2] - P[0])
        for v in f:
            expect[v] += cr
    expect /= np.linalg.norm(expect, axis=1, keepdims=True)
    np.testing.assert_allclose(N, expect, atol=1e-12)
    assert [[c[2] for c in f] for f in got["f"]] == F


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_editor_export_keeps_the_obj_attributes(tmp_path):
    """An OBJ opened in the editor exports the PLY as before plus an OBJ with its UVs."""
    import argparse

    pytest.importorskip("viser")
    from arapkit.cli.edit import build_state
    from arapkit.editor.app import EditorApp

    ns = argparse.Namespace(mesh=None, rings_file=None, rings=1, handles=None, session=None)
    app = EditorApp(build_state(ns), port=_free_port(), export_dir=tmp_path / "out")
    try:
        app.open_mesh_bytes("cube.obj", cube_obj_text().encode())
        paths = app.export()
        assert [p.name for p in paths] == ["cube-deformed.ply", "cube-rings.txt",
                                           "cube-deformed.obj"]
        got = parse_obj_for_test(paths[2])
        np.testing.assert_array_equal(np.array(got["vt"]), UV)
        assert [[c[1] for c in f] for f in got["f"]] == cube_corner_uv()
        assert "usemtl blue" in paths[2].read_text()
    finally:
        app.stop()


def test_colours_cross_formats(tmp_path):
    """PLY uchar colours -> OBJ floats (/255) -> PLY uchar again, unchanged."""
    src = tmp_path / "p.ply"
    src.write_text(PLY_HEAD + "\n".join(PLY_V + PLY_F) + "\n")
    mesh = load_mesh(src)
    obj = tmp_path / "p.obj"
    warn = save_mesh(obj, mesh.vertices, like=mesh)
    assert len(warn) == 2 and "quality, label" in warn[0] and "part" in warn[1]
    cols = np.array([[float(t) for t in row.split()][3:7] for row in PLY_V])
    got = np.array(parse_obj_for_test(obj)["v"])
    np.testing.assert_allclose(got[:, 3:], cols / 255.0, rtol=0, atol=1e-15)
    back = load_mesh(obj)
    ply = tmp_path / "q.ply"
    assert save_mesh(ply, back.vertices, like=back) == []
    got = parse_ply(ply.read_bytes())
    v = got["elements"]["vertex"]
    for j, c in enumerate(["red", "green", "blue", "alpha"]):
        assert got["types"]["vertex", c] == "uchar"
        np.testing.assert_array_equal(v[c], cols[:, j])


def test_binary_ply_with_mixed_polygons_reads_back(tmp_path):
    """Sizes 4, 5, 3 total 12 = 3 x 4: trimesh reads such a binary file as three quads
    without complaint; the loader must notice and read the real polygons."""
    V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0], [2, 1, 0.5],
                  [1.5, 2, 0], [3, 0, 0]], dtype=float)
    src = tmp_path / "m.obj"
    src.write_text("".join(f"v {x} {y} {z}\n" for x, y, z in V)
                   + "f 1 2 3 4\nf 2 5 6 7 3\nf 5 8 6\n")
    mesh = load_mesh(src)
    out = tmp_path / "m.ply"
    assert save_mesh(out, mesh.vertices, like=mesh) == []
    back = load_mesh(out)
    assert [p.tolist() for p in back.attributes.polygons()] == [
        [0, 1, 2, 3], [1, 4, 5, 6, 2], [4, 7, 5]]
    np.testing.assert_array_equal(back.vertices, V)
    np.testing.assert_array_equal(back.faces, mesh.faces)


def test_off_normals_recomputed_and_colours_kept(tmp_path):
    """CNOFF: x y z, then a normal, then a colour. The normal follows the deformed shape,
    the colour is copied, and an OBJ gets them as vn (one per vertex) and v colours."""
    src = tmp_path / "t.off"
    src.write_text("CNOFF\n4 2 0\n"
                   "0 0 0 0 0 1 255 0 0 255\n1 0 0 0 0 1 0 255 0 255\n"
                   "0 1 0 0 0 1 0 0 255 255\n1 1 0 0 0 1 9 9 9 255\n"
                   "3 0 1 2\n3 1 3 2\n")
    mesh = load_mesh(src)
    # rotate by 90 degrees about x: every normal becomes (0, -1, 0)
    R = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])
    V = mesh.vertices @ R.T
    out = tmp_path / "o.off"
    assert save_mesh(out, V, like=mesh) == []
    rows = np.array([[float(t) for t in ln.split()] for ln in out.read_text().splitlines()[2:6]])
    assert out.read_text().splitlines()[0] == "CNOFF"
    np.testing.assert_allclose(rows[:, :3], V, atol=0)
    np.testing.assert_allclose(rows[:, 3:6], [[0, -1, 0]] * 4, atol=1e-15)
    np.testing.assert_array_equal(rows[:, 6:], [[255, 0, 0, 255], [0, 255, 0, 255],
                                                [0, 0, 255, 255], [9, 9, 9, 255]])
    obj = tmp_path / "o.obj"
    assert save_mesh(obj, V, like=mesh) == []
    got = parse_obj_for_test(obj)
    np.testing.assert_allclose(np.array(got["vn"]), [[0, -1, 0]] * 4, atol=1e-15)
    np.testing.assert_allclose(np.array(got["v"])[:, 3:], rows[:, 6:] / 255.0)
    assert [[c[2] for c in f] for f in got["f"]] == [[0, 1, 2], [1, 3, 2]]
