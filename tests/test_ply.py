"""PLY files in and out: every property, type, encoding and polygon mix survives a read and a
write, and every malformed file is one line naming it.

Files are written by tests/ply_oracle.py (plain Python, record by record: independent of
arapkit's reader and writer) or by trimesh, read with :func:`arapkit.load_mesh`, written
back with ``save_mesh(..., like=mesh)`` and read again by the oracle.
"""

from __future__ import annotations

import gzip

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from ply_oracle import numpy_type, parse_ply, ply_bytes

from arapkit.errors import InputError
from arapkit.io import load_mesh, read_ply_vertex_properties, save_mesh
from arapkit.io.ply import read_ply

ENCODINGS = ["ascii", "binary_little_endian", "binary_big_endian"]
RNG = np.random.default_rng(7)
NV = 7
V = RNG.random((NV, 3)).astype(np.float32).astype(np.float64)
TRIS = [[0, 1, 2], [1, 3, 2], [2, 3, 4], [4, 5, 6]]
MIXED = [[0, 1, 2, 3], [1, 4, 5, 6, 2], [4, 6, 5], [0, 3, 6]]


def _values(ply_type: str, n: int, rng=RNG) -> np.ndarray:
    dt = numpy_type(ply_type)
    if dt.kind == "f":
        return (rng.standard_normal(n) * 100).astype(dt)
    info = np.iinfo(dt)
    # the extremes of the type too
    return np.r_[info.min, info.max, rng.integers(info.min, info.max, n - 2, endpoint=True,
                                                  dtype=dt)].astype(dt)[:n]


# every case: extra vertex properties, faces, face properties, header notes
CASES = {
    "custom": dict(vprops=[("rings", "int", np.arange(1, NV + 1)),
                           ("energy", "double", RNG.random(NV)),
                           *[(f"p_{t}", t, _values(t, NV)) for t in
                             ("char", "uchar", "short", "ushort", "int", "uint", "float",
                              "double", "int8", "uint16", "float32", "int64", "uint64",
                              "float16")]]),
    "colours_uchar": dict(vprops=[(c, "uchar", _values("uchar", NV))
                                  for c in ("red", "green", "blue", "alpha")]),
    "colours_float": dict(vprops=[(c, "float", RNG.random(NV).astype(np.float32))
                                  for c in ("red", "green", "blue")]),
    "normals": dict(vprops=[(c, "float", RNG.standard_normal(NV).astype(np.float32))
                            for c in ("nx", "ny", "nz")]),
    "uv_u_v": dict(vprops=[("u", "float", _values("float", NV)),
                           ("v", "float", _values("float", NV))]),
    "uv_s_t": dict(vprops=[("s", "float", _values("float", NV)),
                           ("t", "float", _values("float", NV))]),
    "uv_texture": dict(vprops=[("texture_u", "float", _values("float", NV)),
                               ("texture_v", "float", _values("float", NV))]),
    "face_properties": dict(fprops=[("part", "ushort", _values("ushort", 4)),
                                    ("quality", "double", RNG.random(4))]),
    "mixed_polygons": dict(faces=MIXED, fprops=[("label", "int", _values("int", 4))]),
    "mixed_ushort_lists": dict(faces=MIXED, count="ushort", index="uint"),
    "comments": dict(notes=["comment TextureFile tex.png", "obj_info scanned 2024",
                            "comment made by hand"]),
}


def _elements(case: dict, coord: str = "float"):
    vert = [(c, coord, V[:, j]) for j, c in enumerate("xyz")] + case.get("vprops", [])
    faces = case.get("faces", TRIS)
    ftype = ("list", case.get("count", "uchar"), case.get("index", "int"))
    face = [("vertex_indices", ftype, faces)] + case.get("fprops", [])
    return [("vertex", vert), ("face", face)]


def _check_attributes(mesh, case: dict, V_expected) -> None:
    a = mesh.attributes
    np.testing.assert_array_equal(mesh.vertices, V_expected)
    faces = case.get("faces", TRIS)
    assert [p.tolist() for p in a.polygons()] == faces
    vprops = case.get("vprops", [])
    assert list(a.vertex_properties) == [n for n, _, _ in vprops]
    for name, t, values in vprops:
        got = a.vertex_properties[name]
        assert got.dtype == numpy_type(t), (name, got.dtype)
        np.testing.assert_array_equal(got, np.asarray(values).astype(numpy_type(t)))
    fprops = case.get("fprops", [])
    assert list(a.face_properties) == [n for n, _, _ in fprops]
    for name, t, values in fprops:
        assert a.face_properties[name].dtype == numpy_type(t)
        np.testing.assert_array_equal(a.face_properties[name], values)


def _check_written(out, case: dict, V_written) -> None:
    """The written file, read by the oracle: everything of the source, in its types."""
    got = parse_ply(out.read_bytes())
    vert, face = got["elements"]["vertex"], got["elements"]["face"]
    np.testing.assert_array_equal(np.stack([vert[c] for c in "xyz"], axis=1), V_written)
    assert [got["types"]["vertex", c] for c in "xyz"] == ["double"] * 3
    for name, t, values in case.get("vprops", []):
        assert numpy_type(got["types"]["vertex", name]) == numpy_type(t)
        np.testing.assert_array_equal(np.asarray(vert[name], dtype=numpy_type(t)),
                                      np.asarray(values).astype(numpy_type(t)))
    assert face["vertex_indices"] == case.get("faces", TRIS)
    for name, t, values in case.get("fprops", []):
        assert numpy_type(got["types"]["face", name]) == numpy_type(t)
        np.testing.assert_array_equal(np.asarray(face[name], dtype=numpy_type(t)), values)
    assert got["notes"] == ["comment written by arapkit", *case.get("notes", [])]


@pytest.mark.parametrize("encoding", ENCODINGS)
@pytest.mark.parametrize("name", list(CASES))
def test_round_trip(tmp_path, name, encoding):
    case = CASES[name]
    src = tmp_path / "src.ply"
    src.write_bytes(ply_bytes(encoding, _elements(case), case.get("notes", ())))
    mesh = load_mesh(src)
    _check_attributes(mesh, case, V)
    assert not mesh.attributes.lost and mesh.attributes.comments == case.get("notes", [])
    moved = mesh.vertices + [0.25, -1.0, 1e-3]
    out = tmp_path / "out.ply"
    assert save_mesh(out, moved, like=mesh) == []
    _check_written(out, case, moved)
    _check_attributes(load_mesh(out), case, moved)  # and arapkit reads its own output


@pytest.mark.parametrize("encoding", ENCODINGS)
def test_gzip_round_trip_with_everything(tmp_path, encoding):
    case = {"vprops": CASES["custom"]["vprops"] + CASES["colours_uchar"]["vprops"],
            "faces": MIXED, "fprops": CASES["mixed_polygons"]["fprops"],
            "notes": CASES["comments"]["notes"]}
    src = tmp_path / "src.ply.gz"
    src.write_bytes(gzip.compress(ply_bytes(encoding, _elements(case, "double"),
                                            case["notes"])))
    mesh = load_mesh(src)
    _check_attributes(mesh, case, V)
    out = tmp_path / "out.ply.gz"
    assert save_mesh(out, mesh.vertices * 2, like=mesh) == []
    plain = tmp_path / "out.ply"
    plain.write_bytes(gzip.decompress(out.read_bytes()))
    _check_written(plain, case, V * 2)


def test_arapkit_writer_read_by_the_oracle(tmp_path):
    """save_mesh without ``like``: positions exact, energy as double, rings as int."""
    F = np.array(TRIS)
    energy, rings = RNG.random(NV), np.arange(NV) % 4 + 1
    save_mesh(tmp_path / "t.ply", V * 3, F, {"energy": energy, "rings": rings})
    got = parse_ply((tmp_path / "t.ply").read_bytes())
    vert = got["elements"]["vertex"]
    np.testing.assert_array_equal(np.stack([vert[c] for c in "xyz"], axis=1), V * 3)
    assert got["types"]["vertex", "energy"] == "double" and vert["energy"] == energy.tolist()
    assert got["types"]["vertex", "rings"] == "int" and vert["rings"] == rings.tolist()
    assert got["elements"]["face"]["vertex_indices"] == TRIS


@pytest.mark.parametrize("encoding", ["ascii", "binary"])
def test_trimesh_files_colours_normals_and_uv(tmp_path, encoding):
    """trimesh as a second writer: RGBA uchar colours, vertex normals, UVs as s and t."""
    trimesh = pytest.importorskip("trimesh")
    tm = trimesh.creation.icosphere(subdivisions=1)
    uv = RNG.random((len(tm.vertices), 2))
    tm.visual = trimesh.visual.TextureVisuals(uv=uv)
    src = tmp_path / "uv.ply"
    src.write_bytes(trimesh.exchange.ply.export_ply(tm, encoding=encoding, vertex_normal=True))
    p = load_mesh(src).attributes.vertex_properties
    # trimesh writes UVs as doubles, rounded to 8 decimals in ASCII files
    np.testing.assert_allclose(np.stack([p["s"], p["t"]], axis=1), uv,
                               rtol=0, atol=1e-8 if encoding == "ascii" else 0)
    np.testing.assert_allclose(np.stack([p["nx"], p["ny"], p["nz"]], axis=1),
                               tm.vertex_normals, atol=1e-6)
    tm = trimesh.creation.icosphere(subdivisions=1)
    rgba = RNG.integers(0, 256, (len(tm.vertices), 4), dtype=np.uint8)
    tm.visual.vertex_colors = rgba
    src.write_bytes(trimesh.exchange.ply.export_ply(tm, encoding=encoding))
    mesh = load_mesh(src)
    p = mesh.attributes.vertex_properties
    assert p["red"].dtype == np.uint8
    np.testing.assert_array_equal(np.stack([p[c] for c in ("red", "green", "blue", "alpha")],
                                           axis=1), rgba)
    np.testing.assert_array_equal(mesh.faces, tm.faces)
    out = tmp_path / "out.ply"
    save_mesh(out, mesh.vertices, like=mesh)
    vert = parse_ply(out.read_bytes())["elements"]["vertex"]
    np.testing.assert_array_equal(np.stack([vert[c] for c in ("red", "green", "blue", "alpha")],
                                           axis=1), rgba)


def test_lists_beyond_the_faces_are_read_past_and_reported_lost(tmp_path):
    """MeshLab's per-corner texcoord list, a vertex list and an edge element are not kept
    (and said so); everything after them in every record is still read right."""
    elements = [
        ("vertex", [*[(c, "float", V[:, j]) for j, c in enumerate("xyz")],
                    ("nbrs", ("list", "uchar", "int"), [[1] * (i % 3) for i in range(NV)]),
                    ("quality", "float", _values("float", NV))]),
        ("face", [("vertex_indices", ("list", "uchar", "int"), MIXED),
                  ("texcoord", ("list", "uchar", "float"), [[0.5] * (2 * len(f)) for f in MIXED]),
                  ("part", "short", [1, -2, 3, -4])]),
        ("edge", [("vertex1", "int", [0, 1]), ("vertex2", "int", [1, 2])]),
        ("material", []),
    ]
    for encoding in ENCODINGS:
        src = tmp_path / "l.ply"
        src.write_bytes(ply_bytes(encoding, elements))
        mesh = load_mesh(src)
        a = mesh.attributes
        assert [p.tolist() for p in a.polygons()] == MIXED
        np.testing.assert_array_equal(a.vertex_properties["quality"], elements[0][1][4][2])
        assert a.face_properties["part"].tolist() == [1, -2, 3, -4]
        assert a.lost == ["PLY element 'edge'", "PLY list property 'nbrs'",
                          "PLY face list property 'texcoord'"]
        warnings = save_mesh(tmp_path / "o.ply", mesh.vertices, like=mesh)
        assert [w.split(": ", 1)[1] for w in warnings] == [
            f"not kept from the input: {w}" for w in a.lost]


def test_large_mixed_binary_file_against_the_oracle(tmp_path):
    """20,000 faces of 3 to 8 corners, big endian: the compiled scan, face by face."""
    rng = np.random.default_rng(3)
    n = 500
    Vb = rng.random((n, 3))
    polys = [rng.choice(n, size=k, replace=False).tolist()
             for k in rng.integers(3, 9, 20_000)]
    label = rng.integers(-(2**31), 2**31 - 1, len(polys))
    src = tmp_path / "big.ply"
    src.write_bytes(ply_bytes("binary_big_endian", [
        ("vertex", [(c, "double", Vb[:, j]) for j, c in enumerate("xyz")]),
        ("face", [("vertex_indices", ("list", "int", "uint"), polys), ("label", "int", label)]),
    ]))
    ply = read_ply(src.read_bytes(), str(src))
    faces = ply.elements["face"].data["vertex_indices"]
    assert [p.tolist() for p in faces.split()] == polys
    np.testing.assert_array_equal(ply.elements["face"].data["label"], label)
    np.testing.assert_array_equal(np.stack([ply.elements["vertex"].data[c] for c in "xyz"], 1),
                                  Vb)


@pytest.mark.parametrize("layout", ["crlf", "blank_lines", "no_final_newline", "tabs"])
def test_ascii_layouts(tmp_path, layout):
    text = ply_bytes("ascii", _elements(CASES["mixed_polygons"]),
                     newline="\r\n" if layout == "crlf" else "\n")
    head, body = text.split(b"end_header\n", 1) if layout != "crlf" else (text, b"")
    if layout == "blank_lines":
        text = head + b"end_header\n\n" + body.replace(b"\n", b"\n\n")
    elif layout == "no_final_newline":
        text = text.rstrip(b"\n")
    elif layout == "tabs":
        text = head + b"end_header\n" + body.replace(b" ", b" \t ")
    (tmp_path / "a.ply").write_bytes(text)
    _check_attributes(load_mesh(tmp_path / "a.ply"), CASES["mixed_polygons"], V)


def test_binary_file_may_end_with_a_newline(tmp_path):
    data = ply_bytes("binary_little_endian", _elements(CASES["custom"]))
    (tmp_path / "n.ply").write_bytes(data + b"\r\n")
    _check_attributes(load_mesh(tmp_path / "n.ply"), CASES["custom"], V)


def test_read_ply_vertex_properties_of_a_mixed_binary_file(tmp_path):
    """(trimesh's reader gave up on these: rings maps in such files could not be read)"""
    case = CASES["mixed_polygons"] | {"vprops": [("rings", "uchar", np.arange(NV) % 5 + 1)]}
    (tmp_path / "r.ply").write_bytes(ply_bytes("binary_big_endian", _elements(case)))
    props = read_ply_vertex_properties(tmp_path / "r.ply")
    assert list(props) == ["x", "y", "z", "rings"]
    assert props["rings"].tolist() == (np.arange(NV) % 5 + 1).tolist()


# --------------------------------------------------------------------------- malformed

HEAD = (b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
        b"property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
        b"end_header\n")
BODY = b"0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"
BHEAD = HEAD.replace(b"ascii", b"binary_little_endian").replace(b"face 1", b"face 2")
BVERT = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], "<f4").tobytes()
TRI = np.array([3], "u1").tobytes() + np.array([0, 1, 2], "<i4").tobytes()
QUAD = np.array([4], "u1").tobytes() + np.array([0, 1, 2, 1], "<i4").tobytes()

MALFORMED = {
    "empty": (b"", "not a PLY file"),
    "not ply": (b"plx" + HEAD[3:] + BODY, "not a PLY file"),
    "no end_header": (HEAD.replace(b"end_header\n", b""), "no end_header line"),
    "bad format": (HEAD.replace(b"format ascii", b"format binary"), "PLY header line 2"),
    "unknown type": (HEAD.replace(b"float z", b"quad z") + BODY,
                     "line 6: unknown property type 'quad'"),
    "unknown list type": (HEAD.replace(b"uchar int", b"uchar long") + BODY,
                          "unknown property type 'long'"),
    "float list length": (HEAD.replace(b"uchar int", b"float int") + BODY,
                          "list length type 'float' is not an integer type"),
    "count not whole": (HEAD.replace(b"vertex 3", b"vertex 3.0") + BODY,
                        "element 'vertex' has count '3.0', not a whole number"),
    "negative count": (HEAD.replace(b"vertex 3", b"vertex -3") + BODY, "negative count"),
    "property first": (b"ply\nformat ascii 1.0\nproperty float x\n" + HEAD[17:] + BODY,
                       "a property before any element"),
    "twice the property": (HEAD.replace(b"float z", b"float y") + BODY,
                           "two properties 'y'"),
    "twice the element": (HEAD.replace(b"element face 1", b"element vertex 1") + BODY,
                          "declared twice"),
    "stray header line": (HEAD.replace(b"end_header", b"hello\nend_header") + BODY,
                          "unexpected 'hello'"),
    "truncated ascii": (HEAD + BODY[:12], "truncated"),
    "vertex count too high": (HEAD.replace(b"vertex 3", b"vertex 4") + BODY,
                              "line 13: vertex 3 has 4 numbers"),
    "vertex count too low": (HEAD.replace(b"vertex 3", b"vertex 2") + BODY,
                             "line 12: face 0 has 3 numbers"),
    "face count too low": (HEAD.replace(b"face 1", b"face 0") + BODY,
                           "line 13: data after the last element"),
    "list past its line": (HEAD + BODY.replace(b"3 0 1 2", b"4 0 1 2"),
                           "line 13: face 0: a list of 4 values runs past the end"),
    "list too short": (HEAD + BODY.replace(b"3 0 1 2", b"2 0 1 2"),
                       "line 13: face 0 has 4 numbers, the header's properties take 3"),
    "not a number": (HEAD + BODY.replace(b"1 0 0", b"1 0 zero"), "line 11: 'zero' is not"),
    "fraction index": (HEAD + BODY.replace(b"0 1 2", b"0 1 2.5"),
                       "line 13: face 0: vertex_indices 2.5 is not a whole number"),
    "length beyond uchar": (HEAD + BODY.replace(b"3 0 1 2", b"300 0 1 2"),
                            "the length of vertex_indices 300 is not a whole number in the "
                            "range of uint8"),
    "negative length": (HEAD + BODY.replace(b"3 0 1 2", b"-3 0 1 2"), "the length of"),
    "negative signed length": (HEAD.replace(b"list uchar", b"list char")
                               + BODY.replace(b"3 0 1 2", b"-3 0 1 2"),
                               "line 13: face 0: a negative list length (-3)"),
    "index out of range": (HEAD + BODY.replace(b"0 1 2", b"0 1 7"), "references vertex 7"),
    "no faces": (HEAD.split(b"element face")[0] + b"end_header\n" + BODY[:18], "no faces"),
    "empty face element": (HEAD.replace(b"face 1", b"face 0") + BODY[:18], "no faces"),
    "no x y z": (HEAD.replace(b"float z", b"float w") + BODY, "no x, y, z"),
    "binary truncated in the vertices": (BHEAD + BVERT[:20],
                                         "truncated: the header promises 3 vertex records"),
    "binary truncated in the faces": (BHEAD + BVERT + TRI + TRI[:-2],
                                      "truncated: face 1 of 2 runs past the end"),
    "binary list past the end": (BHEAD + BVERT + TRI + b"\xc8" + TRI[1:],
                                 "truncated: face 1 of 2 runs past the end"),
    "binary mixed truncated": (BHEAD + BVERT + QUAD + TRI[:-1],
                               "truncated: face 1 of 2 runs past the end"),
    "binary face count too low": (BHEAD.replace(b"face 2", b"face 1") + BVERT + TRI + TRI,
                                  "13 bytes after the last element"),
    "binary trailing garbage": (BHEAD + BVERT + TRI + TRI + b"junk", "4 bytes after the last"),
    "binary negative length": (BHEAD.replace(b"list uchar", b"list char") + BVERT + TRI
                               + b"\xfd" + TRI[1:], "face 1: a negative list length"),
    "binary huge count": (BHEAD.replace(b"face 2", b"face 99999999999") + BVERT + TRI,
                          "more than the rest of the file can hold"),
    "binary huge vertex count": (BHEAD.replace(b"vertex 3", b"vertex 99999999999") + BVERT,
                                 "truncated: the header promises 99999999999 vertex"),
}


@pytest.mark.parametrize("case", list(MALFORMED))
def test_malformed_files_are_one_line_naming_the_file(tmp_path, case):
    data, message = MALFORMED[case]
    path = tmp_path / "bad.ply"
    path.write_bytes(data)
    with pytest.raises(InputError) as err:
        load_mesh(path)
    text = str(err.value)
    assert "\n" not in text and message in text, text
    assert text.startswith(f"{path}: ") or text.startswith("bad.ply: "), text


def test_gzip_of_a_truncated_file(tmp_path):
    path = tmp_path / "bad.ply.gz"
    path.write_bytes(gzip.compress(HEAD + BODY[:12]))
    with pytest.raises(InputError, match=f"^{path}: truncated"):
        load_mesh(path)


# --------------------------------------------------------------------------- random files

SCALARS = ["char", "uchar", "short", "ushort", "int", "uint", "float", "double", "int64",
           "uint64", "float16"]


@st.composite
def random_ply(draw):
    """A PLY file's elements: random vertex and face properties, random polygons."""
    nv = draw(st.integers(3, 12))
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    names = draw(st.lists(st.from_regex(r"[a-z][a-z0-9_]{0,6}", fullmatch=True),
                          max_size=5, unique=True).filter(
        lambda ns: not {"x", "y", "z", "vertex_indices"} & set(ns)))
    vprops = [(n, draw(st.sampled_from(SCALARS)), None) for n in names]
    vprops = [(n, t, _values(t, nv, rng) if nv >= 2 else None) for n, t, _ in vprops]
    sizes = draw(st.lists(st.integers(3, 6), min_size=1, max_size=8))
    faces = [rng.choice(nv, size=min(k, nv), replace=False).tolist() for k in sizes]
    faces = [f for f in faces if len(f) >= 3] or [[0, 1, 2]]
    fnames = draw(st.lists(st.sampled_from(["part", "label", "q"]), max_size=2, unique=True))
    fprops = [(n, draw(st.sampled_from(SCALARS)), None) for n in fnames]
    fprops = [(n, t, _values(t, len(faces), rng) if len(faces) >= 2
               else _values(t, 2, rng)[:1]) for n, t, _ in fprops]
    count = draw(st.sampled_from(["uchar", "ushort", "int", "uint"]))
    index = draw(st.sampled_from(["int", "uint"]))
    coord = draw(st.sampled_from(["float", "double"]))
    Vr = rng.standard_normal((nv, 3)).astype(numpy_type(coord)).astype(np.float64)
    encoding = draw(st.sampled_from(ENCODINGS))
    return encoding, Vr, coord, vprops, faces, fprops, count, index


@settings(max_examples=80, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(spec=random_ply())
def test_random_property_sets_round_trip(tmp_path, spec):
    encoding, Vr, coord, vprops, faces, fprops, count, index = spec
    elements = [
        ("vertex", [(c, coord, Vr[:, j]) for j, c in enumerate("xyz")] + vprops),
        ("face", [("vertex_indices", ("list", count, index), faces)] + fprops),
    ]
    src = tmp_path / "r.ply"
    src.write_bytes(ply_bytes(encoding, elements, ["comment random"]))
    case = {"vprops": vprops, "faces": faces, "fprops": fprops, "notes": ["comment random"]}
    mesh = load_mesh(src)
    _check_attributes(mesh, case, Vr)
    out = tmp_path / "o.ply"
    assert save_mesh(out, mesh.vertices, like=mesh) == []
    _check_written(out, case, Vr)
