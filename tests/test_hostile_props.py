"""Property-based hostile input: generated junk never breaks the promise.

For the command line (run in-process through :func:`arapkit.cli.main`): exit status 0 or 2;
on 2 exactly one stderr line ``arapkit: error: ...`` and no traceback; inputs unchanged;
an output, when written, has only finite coordinates. For the Python API and the editor
state: :class:`InputError` or a valid result, never another exception, and a refused
session changes nothing.

The example counts are small so that the whole file runs in well under a minute.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import tempfile
from pathlib import Path
from unittest import mock

import numpy as np
import pytest

hypothesis = pytest.importorskip("hypothesis", reason="hypothesis is in the 'test' extra")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402
from hypothesis.extra import numpy as hnp  # noqa: E402

from arapkit import Deformer, Mesh, cli  # noqa: E402
from arapkit.editor.state import EditorState  # noqa: E402
from arapkit.errors import InputError  # noqa: E402
from arapkit.io import read_ply_vertex_properties, save_mesh  # noqa: E402

SETTINGS = settings(max_examples=150, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.too_slow,
                                           HealthCheck.function_scoped_fixture])


def grid(n: int = 6) -> Mesh:
    """An n x n triangulated grid in the unit square, slightly bent so it is 3-D."""
    x, y = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n))
    V = np.stack([x.ravel(), y.ravel(), 0.1 * np.sin(3 * x.ravel())], axis=1)
    q = np.arange(n * n).reshape(n, n)[:-1, :-1].ravel()
    F = np.concatenate([np.stack([q, q + 1, q + n], 1), np.stack([q + 1, q + n + 1, q + n], 1)])
    return Mesh(V, F, name="grid")


MESH = grid()
N = MESH.n_vertices

# --------------------------------------------------------------------------- strategies

huge_ints = st.sampled_from([10**23, -(10**30), 2**63, 2**64 + 1, 10**400, -1, 0, N, N - 1])
numbers = (st.integers(-5, 2 * N) | huge_ints
           | st.floats(allow_nan=True, allow_infinity=True)
           | st.sampled_from([1e308, -1e308, 5e-324, 0.5, 2.5]))
scalars = st.none() | st.booleans() | numbers | st.text(max_size=6)
json_values = st.recursive(
    scalars,
    lambda c: st.lists(c, max_size=4) | st.dictionaries(st.text(max_size=6), c, max_size=3),
    max_leaves=12,
)
vec3s = st.lists(numbers, min_size=3, max_size=3) | json_values
GROUP_KEYS = ["name", "indices", "box", "sphere", "nearest", "fixed", "translate", "rotate",
              "targets"]


@st.composite
def handle_groups(draw) -> dict:
    """A group that is often nearly valid: real keys, junk or plausible values."""
    g: dict = {}
    sel = draw(st.sampled_from(["indices", "box", "sphere", "nearest", None]))
    if sel == "indices":
        g["indices"] = draw(st.lists(numbers, min_size=1, max_size=4) | json_values)
    elif sel == "box":
        g["box"] = draw(st.fixed_dictionaries({"min": vec3s, "max": vec3s}) | json_values)
    elif sel == "sphere":
        g["sphere"] = draw(st.fixed_dictionaries({"center": vec3s, "radius": numbers}))
    elif sel == "nearest":
        g["nearest"] = draw(st.fixed_dictionaries({"point": vec3s, "k": numbers}))
    motion = draw(st.sampled_from(["translate", "rotate", "targets", "fixed", None]))
    if motion == "translate":
        g["translate"] = draw(vec3s)
    elif motion == "rotate":
        g["rotate"] = draw(st.fixed_dictionaries(
            {"axis": vec3s, "degrees": numbers}, optional={"center": vec3s}))
    elif motion == "targets":
        g["targets"] = draw(st.lists(vec3s, max_size=3) | json_values)
    elif motion == "fixed":
        g["fixed"] = draw(st.booleans() | json_values)
    for k in draw(st.lists(st.sampled_from(GROUP_KEYS + ["bogus"]), max_size=2)):
        g[k] = draw(json_values)
    return g


handle_files = (st.lists(handle_groups(), min_size=1, max_size=3)
                | st.builds(lambda gs: {"groups": gs}, st.lists(handle_groups(), max_size=2))
                | json_values)

# --------------------------------------------------------------------------- CLI harness


def run_cli(folder: Path, args: list) -> tuple[int, str]:
    """Run the command line in-process; assert the promise; return (status, stderr)."""
    before = {p: p.read_bytes() for p in folder.iterdir() if p.is_file()}
    err, out = io.StringIO(), io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
        rc = cli.main([str(a) for a in args])
    text = err.getvalue()
    assert "Traceback" not in text, text
    assert rc in (0, 2), (rc, text)
    if rc == 2:
        lines = text.splitlines()
        assert len(lines) == 1 and lines[0].startswith("arapkit: error: "), text
    for p, data in before.items():
        assert p.read_bytes() == data, f"{p.name} changed"
    return rc, text


def assert_output_finite(path: Path) -> None:
    if path.exists():
        p = read_ply_vertex_properties(path)
        assert np.isfinite(np.stack([p["x"], p["y"], p["z"]])).all()


@pytest.fixture(scope="module")
def folder():
    with tempfile.TemporaryDirectory() as d:
        save_mesh(Path(d) / "grid.off", MESH.vertices, MESH.faces)
        (Path(d) / "h.json").write_text(json.dumps(
            [{"indices": [0, 1]}, {"indices": [N - 1], "translate": [0, 0, 0.3]}]))
        yield Path(d)


def _fresh(folder: Path) -> None:
    for name in ("out.ply", "x.json", "r.txt", "r.npy", "m.off", "m.obj", "m.ply"):
        (folder / name).unlink(missing_ok=True)


# --------------------------------------------------------------------------- properties


@SETTINGS
@given(spec=handle_files)
def test_cli_handle_files(folder, spec):
    _fresh(folder)
    (folder / "x.json").write_text(json.dumps(spec))
    rc, _ = run_cli(folder, ["deform", folder / "grid.off", "--handles", folder / "x.json",
                             "-o", folder / "out.ply", "--max-iter", 5, "-q"])
    assert_output_finite(folder / "out.ply")


ring_tokens = st.lists(
    st.integers(-3, 120).map(str) | huge_ints.map(str)
    | st.sampled_from(["2.5", "nan", "x", "#c", "", "1e3", "+4", "--1"]),
    min_size=0, max_size=N + 2)
ring_arrays = hnp.arrays(
    dtype=st.sampled_from([np.int8, np.int64, np.uint64, np.float32, np.float64, np.bool_,
                           np.complex64]),
    shape=st.sampled_from([(N,), (N, 1), (N + 1,), (), (0,)]),
    elements=None)


@SETTINGS
@given(tokens=ring_tokens, arr=ring_arrays, as_npy=st.booleans())
def test_cli_rings_files(folder, tokens, arr, as_npy):
    _fresh(folder)
    if as_npy:
        rings = folder / "r.npy"
        np.save(rings, arr)
    else:
        rings = folder / "r.txt"
        rings.write_text("\n".join(tokens))
    rc, _ = run_cli(folder, ["deform", folder / "grid.off", "--handles", folder / "h.json",
                             "--rings-file", rings, "-o", folder / "out.ply", "--max-iter", 3,
                             "-q"])
    assert_output_finite(folder / "out.ply")


option_text = (st.text(max_size=8) | numbers.map(str)
               | st.sampled_from(["nan", "inf", "-inf", "1e400", "0x10", "1_000", " 3 "]))


@settings(max_examples=60, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(opt=st.sampled_from(["--tol", "--max-iter", "--rings"]), value=option_text)
def test_cli_deform_option_values(folder, opt, value):
    # the mesh is missing: a good value ends in "file not found" (after the checks)
    rc, err = run_cli(folder, ["deform", folder / "missing.off", "--handles",
                               folder / "h.json", "-o", folder / "out.ply", f"{opt}={value}"])
    assert rc == 2


@settings(max_examples=40, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(opt=st.sampled_from(["--port", "--max-upload-mb", "--rings"]), value=option_text)
def test_cli_edit_option_values(folder, opt, value):
    # a value that passes reaches the editor, which is replaced here by a refusal
    with mock.patch("arapkit.editor.app.EditorApp", side_effect=InputError("would start")):
        rc, err = run_cli(folder, ["edit", f"{opt}={value}"])
    assert rc == 2


mesh_lines = st.lists(
    st.lists(st.sampled_from(["v", "f", "OFF", "3", "0", "1", "2", "-1", "1e23", "nan",
                              "0.5", "x", "//", "1/1", "-4", "100000000000000000000000"]),
             min_size=0, max_size=5).map(" ".join),
    min_size=0, max_size=12)


@SETTINGS
@given(lines=mesh_lines, ext=st.sampled_from(["off", "obj", "ply"]), header=st.booleans())
def test_cli_malformed_mesh_texts(folder, lines, ext, header):
    _fresh(folder)
    text = "\n".join(lines)
    if header and ext == "off":
        text = "OFF\n" + text
    if header and ext == "ply":
        text = ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
                "end_header\n" + text)
    path = folder / f"m.{ext}"
    path.write_text(text + "\n")
    run_cli(folder, ["info", path])


@SETTINGS
@given(data=st.binary(max_size=200), ext=st.sampled_from(["off", "obj", "ply", "stl"]))
def test_cli_binary_junk_meshes(folder, data, ext):
    _fresh(folder)
    path = folder / f"m.{ext}"
    path.write_bytes(data)
    run_cli(folder, ["info", path])


# --------------------------------------------------------------------------- API


@SETTINGS
@given(handles=(st.lists(numbers, max_size=4) | json_values
                | hnp.arrays(st.sampled_from([np.bool_, np.int64, np.float64]),
                             st.sampled_from([(N,), (2, 2), (3,)]))),
       targets=json_values | hnp.arrays(np.float64, st.sampled_from([(1, 3), (2, 3), (3,)])),
       tol=numbers | st.text(max_size=4), max_iter=numbers | st.text(max_size=4))
def test_api_deformer_inputs(handles, targets, tol, max_iter):
    try:
        d = Deformer(MESH, handles)
        res = d.solve(targets, tol=tol, max_iter=max_iter)
    except InputError as e:
        assert "\n" not in str(e)
        return
    assert np.isfinite(res.vertices).all() and math.isfinite(res.energy)


@SETTINGS
@given(V=json_values | hnp.arrays(st.sampled_from([np.float64, np.complex128, np.int64,
                                                    np.object_, np.str_]),
                                   st.sampled_from([(3, 3), (4, 3), (3,), (3, 2)])),
       F=json_values | hnp.arrays(st.sampled_from([np.int64, np.float64, np.bool_]),
                                  st.sampled_from([(1, 3), (3,), (2, 4)])))
def test_api_mesh_inputs(V, F):
    try:
        m = Mesh(V, F)
    except InputError as e:
        assert "\n" not in str(e)
        return
    assert np.isfinite(m.vertices).all() and m.faces.max() < m.n_vertices


# --------------------------------------------------------------------------- sessions

_STATE = EditorState(MESH)
_STATE.add_handle([0, 1], name="base", frozen=True)
_STATE.add_handle([N - 1], name="tip")
GOOD = json.loads(json.dumps(_STATE.to_dict()))
SESSION_PATHS = [
    ("format",), ("n_vertices",), ("handles",), ("rings",), ("solver",),
    ("handles", 0), ("handles", 1, "wxyz"), ("handles", 1, "position"),
    ("handles", 1, "anchor"), ("handles", 0, "vertices"), ("handles", 1, "name"),
    ("handles", 1, "frozen"), ("solver", "tol"), ("solver", "max_iter"),
    ("solver", "weights"), ("solver", "method"), ("solver", "live_budget_ms"),
    ("rings", 0),
]


@SETTINGS
@given(path=st.sampled_from(SESSION_PATHS), value=json_values | vec3s,
       extra=st.sampled_from([None, ("handles", 1, "wxyz"), ("solver", "tol")]),
       extra_value=json_values)
def test_sessions_refused_or_valid(path, value, extra, extra_value):
    d = json.loads(json.dumps(GOOD))
    for p, v in ((path, value), (extra, extra_value)):
        if p is None:
            continue
        node = d
        for key in p[:-1]:
            ok = isinstance(node, dict) and key in node or (
                isinstance(node, list) and isinstance(key, int) and key < len(node))
            node = node[key] if ok else None
        if isinstance(node, dict) or (isinstance(node, list) and isinstance(p[-1], int)
                                      and p[-1] < len(node)):
            node[p[-1]] = v  # (a path the first mutation removed is left alone)
    st_ = EditorState(MESH)
    st_.apply_dict(json.loads(json.dumps(GOOD)), record=False)
    before = json.dumps(st_.to_dict())
    try:
        st_.apply_dict(d)
    except InputError as e:
        assert "\n" not in str(e)
        assert json.dumps(st_.to_dict()) == before
        return
    idx, tgt = st_.constraints()
    assert np.isfinite(tgt).all()
    assert st_.rings.min() >= 1 and st_.rings.max() <= 100
    assert st_.settings.tol >= 0 and st_.settings.max_iter >= 1
