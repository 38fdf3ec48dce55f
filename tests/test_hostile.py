"""Hostile input: every entry point refuses cleanly and nothing non-finite reaches a file.

One test per example of the hostile-input report (command line, Python API, editor state),
each asserting the promise: the command line exits 2 with exactly one stderr line naming
the file or option at fault, no traceback, no output written and the inputs unchanged;
the API raises :class:`InputError` (never another exception, never a NaN result).
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np
import pytest

from arapkit import Deformer, Mesh, cli, validate
from arapkit.editor.state import EditorState, Handle, SolverSettings
from arapkit.editor.worker import SolveRequest, SolveWorker
from arapkit.errors import InputError
from arapkit.io import check_output_path, load_handles, load_rings, save_mesh
from arapkit.mesh.shapes import bar, bar_bend

# ----------------------------------------------------------------------------- helpers


@pytest.fixture(scope="module")
def mesh() -> Mesh:
    return bar()


@pytest.fixture
def files(tmp_path, mesh):
    """bar.off, a good handle file (left cap fixed, right cap lifted) and its caps."""
    save_mesh(tmp_path / "bar.off", mesh.vertices, mesh.faces)
    x = mesh.vertices[:, 0]
    base = np.flatnonzero(x <= x.min() + 1e-9).tolist()
    tip = np.flatnonzero(x >= x.max() - 1e-9).tolist()
    (tmp_path / "h.json").write_text(json.dumps(
        [{"name": "base", "indices": base}, {"name": "tip", "indices": tip,
                                             "translate": [0, 0, 1]}]))
    return tmp_path, base, tip


def cli_refuses(capsys, tmp_path: Path, *args) -> str:
    """Run the command line in-process; assert the promise; return the error line."""
    before = {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    rc = cli.main([str(a) for a in args])
    out, err = capsys.readouterr()
    assert rc == 2, (rc, err)
    assert "Traceback" not in err, err
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("arapkit: error: "), err
    after = {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    assert after == before, "an input changed or an output appeared"
    return lines[0]


# ------------------------------------------------------------------ numbers beyond C integers


def test_handle_index_beyond_c_integer_names_file(capsys, files):
    tmp, base, _ = files
    (tmp / "big.json").write_text(json.dumps([{"indices": [10**30]}]))
    line = cli_refuses(capsys, tmp, "deform", tmp / "bar.off", "--handles", tmp / "big.json",
                       "-o", tmp / "o.ply")
    assert "big.json" in line and "1e+30 out of range (mesh has 1154 vertices)" in line


def test_rings_file_r_beyond_c_integer_names_file(capsys, files, mesh):
    tmp, _, _ = files
    (tmp / "r.txt").write_text("\n".join(["1"] * (mesh.n_vertices - 1) + ["1" + "0" * 29]))
    line = cli_refuses(capsys, tmp, "deform", tmp / "bar.off", "--handles", tmp / "h.json",
                       "--rings-file", tmp / "r.txt", "-o", tmp / "o.ply")
    assert f"{tmp / 'r.txt'}: vertex 1153 has r = 1e+29 (r must be 1..100)" in line


def test_overlarge_r_in_rings_file_names_file(capsys, files, mesh):
    tmp, _, _ = files
    np.save(tmp / "r.npy", np.r_[np.ones(mesh.n_vertices - 1, int), 1000])
    line = cli_refuses(capsys, tmp, "deform", tmp / "bar.off", "--handles", tmp / "h.json",
                       "--rings-file", tmp / "r.npy", "-o", tmp / "o.ply")
    assert f"{tmp / 'r.npy'}: vertex 1153 has r = 1000" in line


def test_rings_from_api_and_cli_share_one_rule(mesh):
    # the CLI caps --rings at 100; the API, rings files and the editor say the same
    for bad in (101, 10**18):
        with pytest.raises(InputError, match=r"r must be 1\.\.100"):
            Deformer(mesh, [0], rings=bad)
        with pytest.raises(InputError, match=r"r must be 1\.\.100"):
            EditorState(mesh).load_rings(np.full(mesh.n_vertices, bad))
    assert cli.main(["deform", "m.off", "-H", "h.json", "-o", "o.ply", "--rings", "101"]) == 2


# ------------------------------------------------------------------ non-finite never written


@pytest.mark.parametrize("motion", [
    {"translate": [1e308, 0, 0]},
    {"translate": [0, -1e308, 1e308]},
    "targets",
])
def test_huge_targets_stop_the_solve_and_write_nothing(capsys, files, motion):
    tmp, base, tip = files
    if motion == "targets":
        motion = {"targets": [[1e308, 0, 0]] * len(tip)}
    (tmp / "far.json").write_text(json.dumps([{"indices": base}, {"indices": tip, **motion}]))
    line = cli_refuses(capsys, tmp, "deform", tmp / "bar.off", "--handles", tmp / "far.json",
                       "-o", tmp / "o.ply", "--report", tmp / "r.json")
    # the handle file put the target there: it is named, with the group and vertex, not the mesh
    assert f"far.json: handle group 2: target of vertex {tip[0]} reaches 1e+308" in line
    assert "bar.off" not in line


def test_huge_def_transform_names_the_def_file(capsys, files, mesh):
    from arapkit.io import save_def, save_sel

    tmp, base, tip = files
    save_sel(tmp / "a.sel", mesh.n_vertices, base, tip)
    M = np.eye(4)
    M[0, 3] = 1e300
    save_def(tmp / "far.def", M)
    line = cli_refuses(capsys, tmp, "deform", tmp / "bar.off", "--handles", tmp / "a.sel",
                       "--transform", tmp / "far.def", "-o", tmp / "o.ply")
    assert f"far.def: handle group 2 ('handle'): target of vertex {tip[0]} reaches 1e+300" in line
    # an overflowing matrix product (inf targets) is caught by the same rule
    M[0, 0] = 1e308
    save_def(tmp / "far.def", M)
    line = cli_refuses(capsys, tmp, "deform", tmp / "bar.off", "--handles", tmp / "a.sel",
                       "--transform", tmp / "far.def", "-o", tmp / "o.ply")
    assert "far.def: handle group 2 ('handle'): target of vertex" in line and "inf" in line


def test_target_reach_is_the_mesh_number_range(tmp_path, mesh):
    from arapkit.mesh.model import COORDINATE_RANGE

    x = mesh.vertices[:, 0]
    base = np.flatnonzero(x <= x.min() + 1e-9).tolist()
    tip = np.flatnonzero(x >= x.max() - 1e-9).tolist()
    p = tmp_path / "h.json"
    # at the limit the targets load and the solve stays finite: the rule refuses nothing
    # the solver can do (the bar is 7 units long, so the limit is 1e150 itself)
    p.write_text(json.dumps([{"indices": base},
                             {"indices": tip, "translate": [COORDINATE_RANGE, 0, 0]}]))
    hs = load_handles(p, mesh.vertices)
    res = Deformer(mesh, hs.indices).solve(hs.targets, max_iter=3)
    assert np.isfinite(res.vertices).all()
    p.write_text(json.dumps([{"indices": base},
                             {"indices": tip, "translate": [2 * COORDINATE_RANGE, 0, 0]}]))
    with pytest.raises(InputError, match=rf"h.json: handle group 2: target of vertex {tip[0]} "
                                         r"reaches 2e\+150"):
        load_handles(p, mesh.vertices)
    # a tiny mesh: the limit is 1e150 of its extents (0.07 units long: 7e148)
    small = mesh.vertices * 0.01
    p.write_text(json.dumps([{"indices": base}, {"indices": tip, "translate": [1e149, 0, 0]}]))
    with pytest.raises(InputError, match=r"at most 7e\+148"):
        load_handles(p, small)


def test_api_huge_targets_raise_not_nan(mesh):
    h, t = bar_bend(mesh, 90)
    d = Deformer(mesh, h)
    far = t.copy()
    far[-1] = [1e308, 1e308, 0]
    with pytest.raises(InputError, match="non-finite values at iteration 1: targets too large"):
        d.solve(far)
    with pytest.raises(InputError, match="non-finite"):
        Deformer(mesh, h, accelerate=True).solve(far)
    with pytest.raises(InputError, match="non-finite"):
        d.solve(far, init="laplacian")
    # the deformer still works afterwards
    assert np.isfinite(d.solve(t).vertices).all()


def test_save_mesh_refuses_non_finite(tmp_path):
    V = np.eye(3)
    V[1, 2] = np.nan
    with pytest.raises(InputError, match="vertex 1 has a non-finite coordinate"):
        save_mesh(tmp_path / "o.ply", V, np.array([[0, 1, 2]]))
    assert not list(tmp_path.iterdir())


# ------------------------------------------------------------------ JSON nesting


def test_deeply_nested_handle_file(capsys, files):
    tmp, _, _ = files
    (tmp / "deep.json").write_text("[" * 100_000 + "]" * 100_000)
    line = cli_refuses(capsys, tmp, "deform", tmp / "bar.off", "--handles", tmp / "deep.json",
                       "-o", tmp / "o.ply")
    assert "deep.json: JSON too deeply nested (100000 levels; at most 64)" in line


def test_json_depth_ignores_brackets_in_strings():
    assert validate.json_depth('{"a": "[[[[{{{{", "b": [[1]]}') == 3
    assert validate.parse_json('{"a": "' + "[" * 1000 + '"}', "x") == {"a": "[" * 1000}


# ------------------------------------------------------------------ rings files


def test_rings_ply_without_rings_property(capsys, files):
    # an ASCII PLY (trimesh hands those over as a dict of columns, not a record array)
    tmp, _, _ = files
    (tmp / "r.ply").write_text(
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
        "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
        "end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")
    line = cli_refuses(capsys, tmp, "deform", tmp / "bar.off", "--handles", tmp / "h.json",
                       "--rings-file", tmp / "r.ply", "-o", tmp / "o.ply")
    assert f"{tmp / 'r.ply'}: no vertex property 'rings' (found: x, y, z)" in line


def test_rings_from_ascii_ply_property(tmp_path):
    (tmp_path / "r.ply").write_text(
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
        "property float z\nproperty int rings\nend_header\n0 0 0 2\n1 0 0 5\n0 1 0 1\n")
    assert load_rings(tmp_path / "r.ply", 3).tolist() == [2, 5, 1]


# ------------------------------------------------------------------ learn


def test_learn_single_frame_names_npz(capsys, files, mesh):
    tmp, _, _ = files
    np.savez(tmp / "one.npz", V=mesh.vertices[None], F=mesh.faces)
    line = cli_refuses(capsys, tmp, "learn", tmp / "one.npz", "-o", tmp / "r.txt")
    assert f"{tmp / 'one.npz'}: holds 1 frame(s)" in line


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_learn_non_finite_frame_names_npz(capsys, files, mesh, bad):
    tmp, _, _ = files
    V = np.stack([mesh.vertices] * 3)
    V[2, 7, 1] = bad
    np.savez(tmp / "seq.npz", V=V, F=mesh.faces)
    line = cli_refuses(capsys, tmp, "learn", tmp / "seq.npz", "-o", tmp / "r.txt")
    assert f"{tmp / 'seq.npz'}: frame 2 has a non-finite coordinate at vertex 7" in line


# ------------------------------------------------------------------ option values


@pytest.mark.parametrize("args, fragment", [
    (["--tol", "nan"], "--tol: expected a finite number, got 'nan'"),
    (["--tol", "-1"], "--tol: must be at least 0"),
    (["--max-iter", "2.5"], "--max-iter: expected an integer, got '2.5'"),
    (["--max-iter", "0"], "--max-iter: must be at least 1, got 0"),
    (["--max-iter", "1" + "0" * 30], "--max-iter: must be at most 1000000000, got 1e+30"),
    (["--rings", "1" + "0" * 30], "--rings/-r: must be at most 100, got 1e+30"),
    (["--rings", "x"], "--rings/-r: expected an integer, got 'x'"),
])
def test_bad_option_values_one_line(capsys, files, args, fragment):
    tmp, _, _ = files
    line = cli_refuses(capsys, tmp, "deform", tmp / "bar.off", "--handles", tmp / "h.json",
                       "-o", tmp / "o.ply", *args)
    assert fragment in line


@pytest.mark.parametrize("args, fragment", [
    (["--port", "70000"], "--port: must be at most 65535, got 70000"),
    (["--port", "-1"], "--port: must be at least 1"),
    (["--max-upload-mb", "nan"], "--max-upload-mb: expected a finite number, got 'nan'"),
    (["--max-upload-mb", "0"], "--max-upload-mb: must be in (0, 1.04858e+06]"),
    (["--rings", "1000000"], "--rings/-r: must be at most 100"),
])
def test_edit_options_refused_before_starting(capsys, tmp_path, args, fragment, monkeypatch):
    import arapkit.editor.app as app_mod

    def never(*a, **k):
        raise AssertionError("the editor started")

    monkeypatch.setattr(app_mod, "EditorApp", never)
    line = cli_refuses(capsys, tmp_path, "edit", *args)
    assert fragment in line


def test_edit_unbindable_host_refused_not_hanging(capsys, tmp_path):
    line = cli_refuses(capsys, tmp_path, "edit", "--host", "999.1.1.1", "--port", "18123")
    assert "--host: cannot listen on '999.1.1.1'" in line


def test_editor_app_validates_port_and_cap_before_starting():
    import arapkit.editor.app as app_mod

    st = EditorState(bar())
    for kw in ({"port": 70000}, {"port": True}, {"max_upload_mb": float("nan")}):
        with pytest.raises(InputError):
            app_mod.EditorApp(st, **kw)


def test_edit_host_warning_on_stderr_and_url_served(capsys, monkeypatch):
    import socket

    import arapkit.editor.app as app_mod

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    monkeypatch.setattr(app_mod.EditorApp, "serve_forever", lambda self: self.stop())
    assert cli.main(["edit", "--host", "0.0.0.0", "--port", str(port)]) == 0
    out, err = capsys.readouterr()
    assert "warning: serving on 0.0.0.0" in err and "warning" not in out
    assert f"arapkit editor: http://0.0.0.0:{port} " in out


# ------------------------------------------------------------------ outputs


def test_output_in_proc_names_the_output(capsys, files):
    tmp, _, _ = files
    line = cli_refuses(capsys, tmp, "deform", tmp / "bar.off", "--handles", tmp / "h.json",
                       "-o", "/proc/o.ply")
    assert "/proc/o.ply: cannot write the output" in line and ".tmp" not in line


@pytest.mark.parametrize("which", ["-o", "--report", "--figure"])
def test_unwritable_output_found_before_loading(capsys, files, locked, which):
    tmp, _, _ = files
    outs = {"-o": tmp / "o.ply", "--report": tmp / "r.json", "--figure": tmp / "f.png"}
    name = {"-o": "o.ply", "--report": "r.json", "--figure": "f.png"}[which]
    outs[which] = locked / name
    args = [a for k, v in outs.items() for a in (k, v)]
    # the mesh does not exist: an error about the output proves it came first
    line = cli_refuses(capsys, tmp, "deform", tmp / "missing.off", "--handles", tmp / "h.json",
                       *args)
    assert f"{locked / name}: cannot write the" in line and "Operation not permitted" in line
    assert ".tmp" not in line and ".probe" not in line
    assert not (tmp / "o.ply").exists()


def test_unwritable_outputs_of_learn_and_demo(capsys, files, locked):
    tmp, _, _ = files
    line = cli_refuses(capsys, tmp, "learn", tmp / "missing.npz", "-o", locked / "r.txt")
    assert f"{locked / 'r.txt'}: cannot write the output" in line
    line = cli_refuses(capsys, tmp, "learn", tmp / "missing.npz", "-o", tmp / "r.txt",
                       "--figure", locked / "f.png")
    assert f"{locked / 'f.png'}: cannot write the figure" in line
    line = cli_refuses(capsys, tmp, "demo", "--out", locked, "--quiet")
    assert f"{locked / 'demo-report.json'}: cannot write the demo output" in line


def test_check_output_path_leaves_nothing_behind(tmp_path):
    check_output_path(tmp_path / "o.ply")
    assert list(tmp_path.iterdir()) == []
    (tmp_path / "o.ply").write_bytes(b"old")
    check_output_path(tmp_path / "o.ply")
    assert (tmp_path / "o.ply").read_bytes() == b"old" and len(list(tmp_path.iterdir())) == 1


# ------------------------------------------------------------------ Python API


def test_mesh_faces_flattened_or_wrong_types(mesh):
    V, F = mesh.vertices, mesh.faces
    with pytest.raises(InputError, match=r"faces must be an \(m, 3\) array"):
        Mesh(V, F.ravel())
    with pytest.raises(InputError, match="vertices: expected real numbers, got <U"):
        Mesh(V.astype(str), F)
    with pytest.raises(InputError, match="vertices: expected real numbers, got complex128"):
        Mesh(V + 1j, F)
    with pytest.raises(InputError, match="non-numeric"):
        Mesh([[0, 0, 0], [1, 0, None], [0, 1, 0]], [[0, 1, 2]])
    with pytest.raises(InputError, match="expected real numbers"):
        Mesh([[0, 0, 0], [1, 0, "0"], [0, 1, 0]], [[0, 1, 2]])
    with pytest.raises(InputError, match="face 0 references vertex 1e\\+23"):
        Mesh(V, [[0, 1, 10**23]])
    with pytest.raises(InputError, match="faces must be an \\(m, 3\\) array or a list of polygons"):
        Mesh(V, 5)


def test_boolean_mask_is_a_mask(mesh):
    h, t = bar_bend(mesh, 60)
    mask = np.zeros(mesh.n_vertices, bool)
    mask[h] = True
    order = np.sort(h)
    d = Deformer(mesh, mask)
    assert d.handles.tolist() == order.tolist()
    by_index = Deformer(mesh, order).solve(t[np.argsort(h)])
    np.testing.assert_array_equal(d.solve(t[np.argsort(h)]).vertices, by_index.vertices)
    with pytest.raises(InputError, match="boolean handle mask needs one value per vertex"):
        Deformer(mesh, np.array([True, False]))


@pytest.mark.parametrize("handles, fragment", [
    (np.array([[0, 1], [2, 3]]), r"1-D list, got shape \(2, 2\)"),
    ([0.5, 3], "handle 0 is 0.5, not an integer"),
    (["0", "1"], "expected real numbers"),
    ("01", "must be integers"),
    ([10**30], "out of range"),
    ([1 + 2j], "complex"),
    ([], "no handle vertices"),
    ([3, 3], "listed twice"),
])
def test_bad_handle_arrays(mesh, handles, fragment):
    with pytest.raises(InputError, match=fragment):
        Deformer(mesh, handles)


@pytest.mark.parametrize("kw, fragment", [
    ({"tol": float("nan")}, "tol: expected a finite number"),
    ({"tol": -1}, "tol: must be at least 0"),
    ({"max_iter": 0}, "max_iter: must be at least 1"),
    ({"max_iter": -1}, "max_iter: must be at least 1"),
    ({"max_iter": 2.5}, "max_iter: expected an integer, got 2.5"),
    ({"max_iter": True}, "max_iter: expected an integer"),
    ({"tol": "1e-3"}, None),  # text that is a number is fine, as on the command line
])
def test_solve_options(mesh, kw, fragment):
    h, t = bar_bend(mesh, 30)
    d = Deformer(mesh, h)
    if fragment is None:
        assert d.solve(t, **kw).converged
        return
    with pytest.raises(InputError, match=fragment):
        d.solve(t, **kw)
    with pytest.raises(InputError, match=fragment):
        Deformer(mesh, h, **kw)


def test_targets_and_init_types(mesh):
    h, t = bar_bend(mesh, 30)
    d = Deformer(mesh, h)
    with pytest.raises(InputError, match="complex"):
        d.solve(t + 1j)
    with pytest.raises(InputError, match="expected real numbers"):
        d.solve(t.astype(str))
    with pytest.raises(InputError, match="init: expected real numbers"):
        d.solve(t, init=mesh.vertices.astype(str))


def test_coordinates_too_large_for_energy_blame_the_range(mesh):
    # at 1e150 the mesh deforms (see test_scale_invariance); targets 1e10 times further
    # out overflow the energy: the message is about the number range, not obtuse triangles
    big = Mesh(mesh.vertices * 1e150, mesh.faces)
    h, _ = bar_bend(mesh, 30)
    with pytest.raises(InputError) as e:
        Deformer(big, h).solve(big.vertices[h] * 1e10)
    msg = str(e.value)
    assert "double precision" in msg and "obtuse" not in msg


def test_unit_scale_refuses_spans_beyond_double():
    from arapkit.methods.deformer import unit_scale

    assert unit_scale(np.array([[0.0, 0, 0], [3e-200, 0, 0]]), "m") == 2.0 ** -662
    with pytest.raises(InputError, match="span more than double precision"):
        unit_scale(np.array([[-1e308, 0, 0], [1e308, 0, 0]]), "m")


def test_validate_integers_never_overflow():
    for v in (10**30, -(10**400), "9" * 5000):
        with pytest.raises(InputError):
            validate.integer(v, "x", lo=0, hi=10)
    assert validate.integer(np.int64(5), "x") == 5
    with pytest.raises(InputError, match="expected an integer, got True"):
        validate.integer(True, "x")


def test_quaternion_rules():
    with pytest.raises(InputError, match="must not be zero"):
        validate.quaternion([0, 0, 0, 0])
    q = validate.quaternion([1e300, 1e300, 0, 0])
    assert np.allclose(q, [math.sqrt(0.5), math.sqrt(0.5), 0, 0])
    for bad in ([1, 0, 0], [np.nan, 0, 0, 1], "wxyz", [1, 0, 0, "0"]):
        with pytest.raises(InputError):
            validate.quaternion(bad)


# ------------------------------------------------------------------ editor state


def good_session(st: EditorState) -> dict:
    d = st.to_dict()
    return json.loads(json.dumps(d))


@pytest.fixture
def st() -> EditorState:
    ns = argparse.Namespace(mesh=None, rings_file=None, rings=1, handles=None, session=None)
    from arapkit.cli.edit import build_state

    return build_state(ns)


def _mutations(d: dict) -> list[tuple[str, dict, str]]:
    """(label, bad session, message fragment) for each class of the report."""
    out = []

    def mut(label, fragment, fn):
        e = json.loads(json.dumps(d))
        fn(e)
        out.append((label, e, fragment))

    mut("zero quaternion", "must not be zero", lambda e: e["handles"][1].update(wxyz=[0, 0, 0, 0]))
    mut("NaN position", "finite", lambda e: e["handles"][1].update(position=[float("nan"), 0, 0]))
    mut("1e308 anchor", "beyond double precision",
        lambda e: e["handles"][1].update(anchor=[[1e308, 0, 0]] * len(e["handles"][1]["vertices"])))
    mut("NaN anchor", "non-finite",
        lambda e: e["handles"][0]["anchor"][0].__setitem__(0, float("nan")))
    mut("tol -1", "tol: must be at least 0", lambda e: e["solver"].update(tol=-1))
    mut("weights bogus", "weights 'bogus'", lambda e: e["solver"].update(weights="bogus"))
    mut("max_iter 2.5", "max_iter: expected an integer", lambda e: e["solver"].update(max_iter=2.5))
    mut("unknown solver key", "unknown key", lambda e: e["solver"].update(speed=9))
    mut("solver a list", "expected an object", lambda e: e.update(solver=[1]))
    mut("r 10^6", "r must be 1..100", lambda e: e.update(rings=[10**6] * len(e["rings"])))
    mut("r 10^30", "r must be 1..100", lambda e: e.update(rings=[10**30] * len(e["rings"])))
    mut("rings a string", "rings", lambda e: e.update(rings="lots"))
    mut("handles 5", "'handles' must be a list, got int", lambda e: e.update(handles=5))
    mut("handle a string", "expected an object", lambda e: e.update(handles=["x"]))
    mut("vertices strings", "expected real numbers",
        lambda e: e["handles"][0].update(vertices=["a"]))
    mut("vertices nested", "1-D list", lambda e: e["handles"][0].update(vertices=[[0, 1]]))
    mut("vertices huge", "out of range", lambda e: e["handles"][0].update(vertices=[10**30]))
    mut("name a number", "'name' must be a non-empty string",
        lambda e: e["handles"][0].update(name=7))
    mut("frozen a string", "'frozen' must be true or false",
        lambda e: e["handles"][0].update(frozen="no"))
    mut("n_vertices a string", "made for a mesh of", lambda e: e.update(n_vertices="1154"))
    mut("wxyz three", "expected 4 numbers", lambda e: e["handles"][1].update(wxyz=[1, 0, 0]))
    return out


def test_bad_sessions_change_nothing(st):
    d = good_session(st)
    before = json.dumps(st.to_dict())
    for label, bad, fragment in _mutations(d):
        with pytest.raises(InputError, match=fragment.replace("(", r"\(").replace(")", r"\)")):
            st.apply_dict(bad)
        assert json.dumps(st.to_dict()) == before, label
    st.apply_dict(d)  # the untouched session still loads
    assert json.dumps(st.to_dict()) == before


def test_session_uploads_through_the_app(tmp_path, st):
    """The page's upload path: bad sessions, deep nesting, NUL names and big r files."""
    from arapkit.editor.app import EditorApp
    from tests.test_editor_browser import free_port

    app = EditorApp(st, port=free_port(), export_dir=tmp_path, max_upload_mb=1.0)
    try:
        assert app.wait_idle(120)
        before = json.dumps(app.state.to_dict())
        d = good_session(app.state)
        cases = [(label, json.dumps(b).encode()) for label, b, _ in _mutations(d)]
        cases.append(("deep", b"[" * 100_000 + b"]" * 100_000))
        cases.append(("deep object", b'{"a":' * 50_000 + b"1" + b"}" * 50_000))
        cases.append(("not json", b"\xff\xfe"))
        cases.append(("list", b"[1, 2]"))
        for label, data in cases:
            with pytest.raises(InputError):
                app.load_session_bytes(f"{label}.json", data)
            assert json.dumps(app.state.to_dict()) == before, label
        with pytest.raises(InputError, match="not a usable file name"):
            app.load_rings_bytes("r\x00.txt", b"1\n")
        with pytest.raises(InputError, match=r"r must be 1\.\.100"):
            app.load_rings_bytes("r.txt", ("\n".join(["1000000000000000000"] * st.n)).encode())
        with pytest.raises(InputError, match="over the 1.0 MB limit"):
            app.load_rings_bytes("r.txt", b"1\n" * 600_000)
        assert json.dumps(app.state.to_dict()) == before
        # the solver panel's values pass the same rules (a client can send any number)
        settings = app.state.settings
        for widget, bad in ((app.nb_tol, float("nan")), (app.nb_maxit, -3),
                            (app.nb_tol, -1.0), (app.nb_budget, float("inf"))):
            old = widget.value
            widget.value = bad  # runs the page's callback, which reports and changes nothing
            assert app.state.settings == settings
            assert app.md_status.content.startswith("⚠")
            app.quietly(lambda w=widget, v=old: setattr(w, "value", v))
    finally:
        app.stop()


def test_move_handle_refuses_bad_pose(st):
    name = st.handles[1].name
    before = st.handles[1].targets().copy()
    for kw in ({"wxyz": [0, 0, 0, 0]}, {"position": [np.nan, 0, 0]}, {"position": [1, 2]}):
        with pytest.raises(InputError):
            st.move_handle(name, **kw)
        np.testing.assert_array_equal(st.handles[1].targets(), before)
    assert not st.can_undo  # nothing was recorded


def test_handle_from_dict_accepts_its_own_output(st):
    h = st.handles[1]
    h2 = Handle.from_dict(json.loads(json.dumps(h.to_dict())), st.n)
    np.testing.assert_allclose(h2.targets(), h.targets())
    assert SolverSettings.from_dict(SolverSettings().to_dict()) == SolverSettings()


def test_worker_never_warm_starts_from_non_finite(st):
    updates = []
    w = SolveWorker(updates.append)
    w.reset_shape(np.full((st.n, 3), np.nan), st.mesh)
    assert w._shape is None
    idx, tgt = st.constraints()
    req = SolveRequest(st.mesh, idx, tgt, st.rings, st.settings,
                       init=np.full((st.n, 3), np.inf))
    assert np.isfinite(w._start_shape(req)).all()
    w._keep(req, np.full((st.n, 3), np.nan))
    assert w._shape is None
    w.start()
    try:
        far = tgt.copy()
        far[-1] = 1e308
        w.submit(SolveRequest(st.mesh, idx, far, st.rings, st.settings))
        assert w.wait_idle(120)
        assert updates[-1].error and "double precision" in updates[-1].error
        assert w._shape is None or np.isfinite(w._shape).all()
        w.submit(SolveRequest(st.mesh, idx, tgt, st.rings, st.settings))
        assert w.wait_idle(120)
        assert updates[-1].error is None and np.isfinite(updates[-1].vertices).all()
    finally:
        w.stop()


def test_load_handles_huge_numbers(tmp_path, mesh):
    p = tmp_path / "h.json"
    for spec, fragment in [
        ([{"indices": [0], "translate": [10**400, 0, 0]}], "3 finite numbers"),
        ([{"nearest": {"point": [0, 0, 0], "k": 10**30}}], "'k' must be an integer"),
        ([{"sphere": {"center": [0, 0, 0], "radius": 10**400}}], "positive number"),
        ([{"indices": [0], "rotate": {"axis": [1e300, 1e300, 0], "degrees": 10}}], None),
    ]:
        p.write_text(json.dumps(spec))
        if fragment is None:
            assert np.isfinite(load_handles(p, mesh.vertices).targets).all()
        else:
            with pytest.raises(InputError, match=fragment):
                load_handles(p, mesh.vertices)


def test_sel_status_other_than_0_1_2_is_refused(tmp_path, mesh):
    from arapkit.io import load_sel

    p = tmp_path / "a.sel"
    statuses = ["0"] + ["1"] * (mesh.n_vertices - 2) + ["2"]
    p.write_text("\n".join(statuses))
    assert load_sel(p, mesh.vertices).indices.tolist() == [0, mesh.n_vertices - 1]
    # any code other than 0, 1, 2 is refused with its line (a comment line counts as one)
    for bad, shown in (("7", "7"), ("-1", "-1"), ("1" + "0" * 30, "1" + "0" * 30)):
        lines = ["# statuses"] + statuses[:]
        lines[5] = bad
        p.write_text("\n".join(lines))
        with pytest.raises(InputError) as e:
            load_sel(p, mesh.vertices)
        assert str(e.value) == f"{p}:6: status {shown} is not one of 0, 1, 2"


def test_file_names_with_nul_bytes(mesh):
    for call in (lambda: load_handles("a\0b.json", mesh.vertices),
                 lambda: load_rings("r\0.txt", mesh.n_vertices),
                 lambda: EditorState.read_session("s\0.json")):
        with pytest.raises(InputError) as e:
            call()
        assert "\0" not in str(e.value) and "\\x00" in str(e.value)


@pytest.mark.parametrize("token", ["--1", "+-2", "\u00b2", "\u0663", "1_000"])
def test_rings_tokens_that_fool_isdigit(tmp_path, token):
    p = tmp_path / "r.txt"
    p.write_text(f"1\n{token}\n1\n", encoding="utf-8")
    with pytest.raises(InputError, match="is not an integer"):
        load_rings(p, 3)


# ------------------------------------------------------------------ damaged and huge input files


@pytest.mark.parametrize("garbage", [b"PK\x03\x04" + b"\x00garbage" * 20, b"PK\x03\x04"])
def test_corrupt_npz_and_npy_are_one_line(capsys, files, mesh, garbage):
    # zip's signature, then garbage: np.load hands the file to zipfile, which raises
    # BadZipFile (not a ValueError); learn reported it as an internal error, exit 1
    tmp, _, _ = files
    (tmp / "seq.npz").write_bytes(garbage)
    line = cli_refuses(capsys, tmp, "learn", tmp / "seq.npz", "-o", tmp / "r.txt")
    assert line.startswith(f"arapkit: error: {tmp / 'seq.npz'}: not a readable .npz file (")
    # a rings .npy that starts like an archive, through the same loader
    (tmp / "r.npy").write_bytes(garbage)
    line = cli_refuses(capsys, tmp, "deform", tmp / "bar.off", "--handles", tmp / "h.json",
                       "--rings-file", tmp / "r.npy", "-o", tmp / "o.ply")
    assert line.startswith(f"arapkit: error: {tmp / 'r.npy'}: not a readable .npy file (")


def test_npz_member_damaged_after_a_good_directory(capsys, files, mesh):
    # a real archive whose compressed member is overwritten: the directory reads, the
    # member does not (zlib.error)
    tmp, _, _ = files
    p = tmp / "seq.npz"
    np.savez_compressed(p, V=np.stack([mesh.vertices] * 3), F=mesh.faces)
    raw = bytearray(p.read_bytes())
    raw[200:2000] = b"\xff" * 1800
    p.write_bytes(bytes(raw))
    line = cli_refuses(capsys, tmp, "learn", p, "-o", tmp / "r.txt")
    assert line.startswith(f"arapkit: error: {p}: not a readable .npz file (")


def test_input_files_over_the_cap_are_refused_in_one_line(capsys, files, mesh, monkeypatch):
    from arapkit.io import save_def, save_sel
    from arapkit.workflows.batch import load_jobs

    tmp, base, tip = files
    save_sel(tmp / "a.sel", mesh.n_vertices, base, tip)
    save_def(tmp / "a.def", np.eye(4))
    (tmp / "r.txt").write_text("1\n" * mesh.n_vertices)
    sel = ["--handles", tmp / "a.sel", "--transform", tmp / "a.def"]
    for at_fault, kind, args in [
        ("h.json", "handle files", ["--handles", tmp / "h.json"]),
        ("a.sel", ".sel files", sel),
        ("a.def", ".def files", sel),
        ("r.txt", "rings files", ["--handles", tmp / "h.json", "--rings-file", tmp / "r.txt"]),
    ]:
        size = (tmp / at_fault).stat().st_size
        cap = (size - 1) / 2**20  # one byte short; the other inputs here are smaller
        monkeypatch.setenv(validate.INPUT_CAP_VARIABLE, repr(cap))
        line = cli_refuses(capsys, tmp, "deform", tmp / "bar.off", *args, "-o", tmp / "o.ply")
        assert line == (f"arapkit: error: {tmp / at_fault}: {size / 2**20:.3g} MiB is more "
                        f"than the {cap:g} MiB allowed for {kind} "
                        "(set ARAPKIT_MAX_INPUT_MB to raise the cap)")
    monkeypatch.setenv(validate.INPUT_CAP_VARIABLE, "0.001")
    for reader, what in [(lambda p: EditorState.read_session(p), "sessions"),
                         (lambda p: load_jobs(p), "job files")]:
        with pytest.raises(InputError, match=f"MiB allowed for {what}"):
            reader(tmp / "r.txt")
    # the default cap and a bad override
    monkeypatch.delenv(validate.INPUT_CAP_VARIABLE)
    assert validate.input_cap_mb() == validate.MAX_INPUT_MB == 256
    monkeypatch.setenv(validate.INPUT_CAP_VARIABLE, "lots")
    with pytest.raises(InputError, match="ARAPKIT_MAX_INPUT_MB: expected a number"):
        load_handles(tmp / "h.json", mesh.vertices)


_PEAK = """
import json, sys, tracemalloc
import numpy as np
from arapkit.errors import InputError
from arapkit.io import load_handles
tracemalloc.start()
try:
    load_handles(sys.argv[1], np.eye(3))
except InputError as e:
    assert len(str(e)) < 400, len(str(e))
print(tracemalloc.get_traced_memory()[1])
"""


@pytest.mark.parametrize("case", ["name", "duplicate name", "escapes"])
def test_long_strings_in_handle_files_take_a_small_multiple_of_the_file(tmp_path, case):
    # a 20 MB group name drove the peak to 100 times the file's size (the string scan of
    # the nesting check); messages that quote the name must not copy it either
    import subprocess
    import sys

    long = "x" * 20_000_000 if case != "escapes" else "\\\\\"" * 4_000_000
    groups = [{"name": long, "indices": [0]}]
    if case == "duplicate name":
        groups.append({"name": long, "indices": [1]})
    p = tmp_path / "h.json"
    p.write_text(json.dumps(groups))
    size = p.stat().st_size
    env = {"PYTHONPATH": str(Path(__file__).resolve().parents[1] / "src")}
    out = subprocess.run([sys.executable, "-c", _PEAK, str(p)], capture_output=True, text=True,
                         env=env, check=True)
    peak = int(out.stdout)
    assert peak < 4 * size, (peak / size, size)
