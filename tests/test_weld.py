"""Triangle soups and unwelded files: weld for the solve, answer in the input's vertices."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import data_path

from arapkit import Deformer, InputError, Mesh, load_mesh
from arapkit.io import read_ply_vertex_properties, save_mesh
from arapkit.mesh.welding import soup_facts, to_source, weld, weld_handles, weld_values


def arapkit(*args) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONWARNINGS": "ignore"}
    return subprocess.run([sys.executable, "-m", "arapkit.cli", *map(str, args)],
                          capture_output=True, text=True, env=env, timeout=600)


def explode(mesh: Mesh) -> Mesh:
    """Every face with its own three corners, in face order (a triangle soup)."""
    F = mesh.faces
    return Mesh(mesh.vertices[F.ravel()], np.arange(F.size).reshape(-1, 3), name="soup")


def square_soup(scale: float = 1.0) -> Mesh:
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]) * scale
    return Mesh(V, [[0, 1, 2], [3, 4, 5]], name="sq")


def test_weld_map_by_hand():
    w = weld(square_soup())
    assert w.n_vertices == 4 and w.n_faces == 2 and w.n_components == 1
    # first-occurrence order: input vertex 3 is a copy of 1, 5 of 2
    assert w.welded_from.index.tolist() == [0, 1, 2, 1, 3, 2]
    assert w.faces.tolist() == [[0, 1, 2], [1, 3, 2]]
    assert to_source(w, np.arange(4) * 10).tolist() == [0, 10, 20, 10, 30, 20]
    assert weld_values(w, np.array([1, 2, 3, 5, 1, 1])).tolist() == [1, 5, 3, 1]


@pytest.mark.parametrize("scale", [1e-200, 1e-150, 1e-3, 1.0, 1e150, 1e200])
def test_tolerance_is_relative_to_the_diagonal(scale):
    soup = square_soup(scale)
    V = np.array(soup.vertices)
    diag = np.sqrt(2) * scale
    V[3] += [0, 0, 0.5e-7 * diag]  # inside the default 1e-7 of the diagonal
    V[5] += [0, 0, 3e-7 * diag]  # outside it
    m = Mesh(V, soup.faces)
    assert weld(m).welded_from.index.tolist() == [0, 1, 2, 1, 3, 4]
    assert weld(m, 0).n_vertices == 6  # exact duplicates only
    assert weld(m, 1e-6).n_vertices == 4


def test_bad_tolerance_refused():
    with pytest.raises(InputError, match="sq: weld tolerance"):
        weld(square_soup(), -1)


def test_handles_on_copies():
    w = weld(square_soup())
    idx, tgt = weld_handles(w, np.array([1, 3, 4]), np.array([[2.0, 0, 0], [2, 0, 0], [1, 1, 1]]))
    assert idx.tolist() == [1, 3] and tgt.tolist() == [[2, 0, 0], [1, 1, 1]]
    with pytest.raises(InputError, match=r"h.json: input vertices 1 and 3 were welded into one"):
        weld_handles(w, np.array([1, 3]), np.array([[2.0, 0, 0], [3, 0, 0]]), what="h.json")


def test_save_like_welded_writes_input_vertices(tmp_path):
    soup = square_soup()
    w = weld(soup)
    moved = w.vertices + [[0, 0, 0], [0, 0, 1], [0, 0, 2], [0, 0, 3]]
    out = tmp_path / "o.ply"
    save_mesh(out, moved, vertex_properties={"rings": np.array([1, 2, 3, 4])}, like=w)
    p = read_ply_vertex_properties(out)
    assert p["z"].tolist() == [0, 1, 2, 1, 3, 2]
    assert p["rings"].tolist() == [1, 2, 3, 2, 4, 3]


@pytest.fixture(scope="module")
def cow_soup(tmp_path_factory):
    cow = load_mesh(data_path("meshes", "cow.off"))
    d = tmp_path_factory.mktemp("soup")
    soup = explode(cow)
    path = d / "cow-soup.off"
    save_mesh(path, soup.vertices, soup.faces)
    V = cow.vertices
    lo, hi = V.min(axis=0), V.max(axis=0)
    x0 = lo[0] + 0.15 * (hi[0] - lo[0])
    x1 = hi[0] - 0.15 * (hi[0] - lo[0])
    handles = [
        {"name": "back", "box": {"min": (lo - 1).tolist(), "max": [x0, hi[1] + 1, hi[2] + 1]}},
        {"name": "front", "box": {"min": [x1, lo[1] - 1, lo[2] - 1], "max": (hi + 1).tolist()},
         "translate": [0.0, 0.1 * float(hi[1] - lo[1]), 0.0]},
    ]
    h = d / "h.json"
    h.write_text(json.dumps(handles))
    return cow, soup, path, h, d


def test_soup_deform_with_weld_matches_the_welded_mesh(cow_soup):
    cow, soup, path, h, d = cow_soup
    out_soup, out_cow = d / "soup-out.ply", d / "cow-out.ply"
    p1 = arapkit("deform", path, "-H", h, "--weld", "-o", out_soup, "-q", "--tol", "1e-6")
    assert p1.returncode == 0, p1.stderr
    p2 = arapkit("deform", data_path("meshes", "cow.off"), "-H", h, "-o", out_cow, "-q",
                 "--tol", "1e-6")
    assert p2.returncode == 0, p2.stderr
    a, b = read_ply_vertex_properties(out_soup), read_ply_vertex_properties(out_cow)
    Vs = np.stack([a["x"], a["y"], a["z"]], axis=1)
    Vc = np.stack([b["x"], b["y"], b["z"]], axis=1)
    # the input's vertex count and order: soup vertex k is cow vertex faces.ravel()[k]
    assert len(Vs) == soup.n_vertices == 3 * cow.n_faces
    assert np.abs(Vc - cow.vertices).max() > 0.005 * cow.bounding_box_diagonal
    np.testing.assert_allclose(Vs, Vc[cow.faces.ravel()], rtol=0,
                               atol=1e-8 * cow.bounding_box_diagonal)
    np.testing.assert_allclose(a["energy"], b["energy"][cow.faces.ravel()], rtol=1e-6,
                               atol=1e-12)


def test_info_suggests_weld_on_a_soup(cow_soup):
    cow, soup, path, h, d = cow_soup
    p = arapkit("info", path)
    assert p.returncode == 0, p.stderr
    assert "--weld" in p.stdout and "triangle soup" in p.stdout
    facts = json.loads(arapkit("info", path, "--json").stdout)
    assert facts["triangle_components"] == cow.n_faces
    # cow.off itself has one exactly repeated position (vertices 44 and 2903)
    distinct = len(np.unique(cow.vertices, axis=0))
    assert facts["coincident_vertices"] == soup.n_vertices - distinct
    clean = arapkit("info", data_path("meshes", "cow.off"))
    assert "--weld" not in clean.stdout
    assert soup_facts(cow) == {"triangle_components": 0,
                               "coincident_vertices": cow.n_vertices - distinct}


def test_index_handle_on_one_copy_moves_all_copies(tmp_path):
    soup = square_soup()
    path = tmp_path / "sq.obj"
    save_mesh(path, soup.vertices, soup.faces)
    h = tmp_path / "h.json"
    h.write_text(json.dumps([{"indices": [0]}, {"indices": [2]},
                             {"indices": [3], "translate": [0, 0, 0.5]}]))
    out = tmp_path / "o.obj"
    p = arapkit("deform", path, "-H", h, "--weld", "-o", out, "-q")
    assert p.returncode == 0, p.stderr
    V = np.array([[float(t) for t in ln.split()[1:]] for ln in out.read_text().splitlines()
                  if ln.startswith("v ")])
    assert len(V) == 6
    np.testing.assert_allclose(V[[1, 3]], [[1, 0, 0.5], [1, 0, 0.5]], atol=1e-12)
    # the same solve through the library on the welded mesh
    w = weld(load_mesh(path))
    ref = Deformer(w, [0, 1, 2]).solve([[0, 0, 0], [1, 0, 0.5], [0, 1, 0]]).vertices
    np.testing.assert_allclose(V, ref[w.welded_from.index], atol=1e-12)


def test_conflicting_targets_refused_on_cli(tmp_path):
    soup = square_soup()
    path = tmp_path / "sq.off"
    save_mesh(path, soup.vertices, soup.faces)
    h = tmp_path / "h.json"
    h.write_text(json.dumps([{"indices": [1]}, {"indices": [3], "translate": [0, 0, 1]}]))
    p = arapkit("deform", path, "-H", h, "--weld", "-o", tmp_path / "o.ply")
    assert p.returncode == 2
    assert "input vertices" in p.stderr and "welded into one" in p.stderr
    assert "Traceback" not in p.stderr
    assert not (tmp_path / "o.ply").exists()


def test_weld_option_value_checked(tmp_path):
    p = arapkit("deform", Path("x.off"), "-H", "h.json", "--weld", "nan", "-o",
                tmp_path / "o.ply")
    assert p.returncode == 2 and "--weld" in p.stderr


def test_learn_with_weld_writes_the_input_vertices(tmp_path):
    """learn on two soups with --weld equals learn on the welded meshes, per soup vertex."""
    from arapkit.mesh.shapes import bar

    mesh = bar(segments=(20, 2, 2))
    # a hinge: the far half turned by 30 degrees about the middle (soft joint, rigid rest)
    posed = mesh.vertices.copy()
    mid, a = posed[:, 0].max() / 2, np.radians(30)
    R = np.array([[np.cos(a), 0, -np.sin(a)], [0, 1, 0], [np.sin(a), 0, np.cos(a)]])
    far = posed[:, 0] > mid
    posed[far] = (posed[far] - [mid, 0, 0]) @ R.T + [mid, 0, 0]
    soup = explode(mesh)
    F = mesh.faces.ravel()
    ref_s, pose_s = tmp_path / "ref-soup.off", tmp_path / "pose-soup.off"
    save_mesh(ref_s, mesh.vertices[F], soup.faces)
    save_mesh(pose_s, posed[F], soup.faces)
    ref_m, pose_m = tmp_path / "ref.off", tmp_path / "pose.off"
    save_mesh(ref_m, mesh.vertices, mesh.faces)
    save_mesh(pose_m, posed, mesh.faces)
    out_s, out_m = tmp_path / "soup-r.txt", tmp_path / "mesh-r.txt"
    common = ["--r-max", "3", "--omega", "0.02", "-q"]
    p1 = arapkit("learn", ref_s, pose_s, "--weld", "-o", out_s, "--ply", tmp_path / "s.ply",
                 *common)
    assert p1.returncode == 0, p1.stderr
    p2 = arapkit("learn", ref_m, pose_m, "-o", out_m, *common)
    assert p2.returncode == 0, p2.stderr
    rs, rm = np.loadtxt(out_s, dtype=int), np.loadtxt(out_m, dtype=int)
    assert len(rs) == soup.n_vertices and len(set(rm.tolist())) > 1
    np.testing.assert_array_equal(rs, rm[F])
    assert read_ply_vertex_properties(tmp_path / "s.ply")["rings"].tolist() == rs.tolist()


def test_editor_state_with_weld_and_its_session(tmp_path):
    import argparse

    from arapkit.cli.edit import build_state
    from arapkit.editor.state import EditorState

    soup = square_soup()
    path = tmp_path / "sq.off"
    save_mesh(path, soup.vertices, soup.faces)
    h = tmp_path / "h.json"
    h.write_text(json.dumps([{"name": "a", "indices": [0]},
                             {"name": "b", "indices": [3, 4], "translate": [0, 0, 1]}]))
    r = tmp_path / "r.txt"
    r.write_text("1\n1\n1\n4\n2\n1\n")
    ns = argparse.Namespace(mesh=str(path), rings_file=str(r), rings=1, handles=str(h),
                            session=None, weld=1e-7)
    st = build_state(ns)
    assert st.n == 4
    assert [(x.name, x.vertices.tolist()) for x in st.handles] == [("a", [0]), ("b", [1, 3])]
    assert st.rings.tolist() == [1, 4, 1, 2]  # the largest r of the copies
    session = tmp_path / "s.json"
    st.save_session(session)
    again = EditorState.from_session(session)
    assert again.n == 4 and again.mesh.welded_from.index.tolist() == [0, 1, 2, 1, 3, 2]


ROOT = Path(__file__).resolve().parents[1]


def _cli_vertices(path: Path) -> np.ndarray:
    p = read_ply_vertex_properties(path)
    return np.stack([p["x"], p["y"], p["z"]], axis=1)


def test_geometric_selectors_act_on_the_welded_mesh(tmp_path):
    """``nearest`` on a soup with --weld picks k positions, not k copies of one position.

    The reference is the welded mesh saved as a file and deformed without --weld: its
    handle file names the same ``nearest`` and ``box`` selections and the explicit vertex
    translated into its own numbering.
    """
    soup = explode(load_mesh(ROOT / "examples" / "cactus.off"))
    w = weld(soup)
    soup_path, welded_path = tmp_path / "soup.ply", tmp_path / "welded.ply"
    save_mesh(soup_path, soup.vertices, soup.faces)
    save_mesh(welded_path, w.vertices, w.faces)
    assert np.array_equal(load_mesh(welded_path).vertices, w.vertices)
    lo, hi = w.vertices.min(axis=0), w.vertices.max(axis=0)
    tip = w.vertices[np.argmax(w.vertices[:, 0])]  # the right arm's outermost point
    # an explicit input vertex: a soup corner whose welded vertex is on the left arm
    left = int(np.flatnonzero(soup.vertices[:, 0] < lo[0] + 0.1 * (hi[0] - lo[0]))[-1])
    groups = [
        {"name": "pot", "box": {"min": (lo - 1).tolist(),
                                "max": [hi[0] + 1, lo[1] + 0.1 * (hi[1] - lo[1]), hi[2] + 1]}},
        {"name": "hand", "nearest": {"point": tip.tolist(), "k": 5},
         "rotate": {"axis": [0, 0, 1], "degrees": -30, "center": [0, float(tip[1]), 0]}},
        {"name": "left", "indices": [left], "translate": [0, 0, 0.2]},
    ]
    h_soup, h_welded = tmp_path / "h-soup.json", tmp_path / "h-welded.json"
    h_soup.write_text(json.dumps(groups))
    groups[2]["indices"] = [int(w.welded_from.index[left])]
    h_welded.write_text(json.dumps(groups))
    outs = tmp_path / "soup-out.ply", tmp_path / "welded-out.ply"
    for mesh, h, out, weld_opt in ((soup_path, h_soup, outs[0], ["--weld"]),
                                   (welded_path, h_welded, outs[1], [])):
        p = arapkit("deform", mesh, "-H", h, *weld_opt, "-o", out, "-q", "--tol", "1e-8")
        assert p.returncode == 0, p.stderr
    got, ref = _cli_vertices(outs[0]), _cli_vertices(outs[1])
    diag = w.bounding_box_diagonal
    assert np.abs(ref - w.vertices).max() > 0.01 * diag  # the arm did move
    np.testing.assert_allclose(got, ref[w.welded_from.index], rtol=0, atol=1e-10 * diag)
    # the explicit input vertex went where its group sent it, with all its copies
    copies = np.flatnonzero(w.welded_from.index == w.welded_from.index[left])
    assert len(copies) > 1
    np.testing.assert_allclose(got[copies], soup.vertices[copies] + [0, 0, 0.2],
                               rtol=0, atol=1e-10 * diag)


def test_welded_handle_resolution_by_hand():
    """Selections on the welded square (4 positions), vertex numbers on the soup (6)."""
    from arapkit.io import parse_handles

    soup = square_soup()
    w = weld(soup)
    V = soup.vertices
    # nearest to (1, 0.1): welded 1 at (1, 0) and then welded 3 at (1, 1) -- on the soup
    # the two copies of (1, 0) would be the 2 nearest
    hs = parse_handles([{"nearest": {"point": [1, 0.1, 0], "k": 2}, "translate": [0, 0, 1]},
                        {"indices": [0]}], V, welded=w)
    assert [g.indices.tolist() for g in hs.groups] == [[1, 3], [0]]
    assert hs.targets.tolist() == [[1, 0, 1], [1, 1, 1], [0, 0, 0]]
    # different copies of one position in two indices groups: one handle, the first group's
    hs = parse_handles([{"indices": [1]}, {"indices": [3, 4]}], V, welded=w)
    assert [g.indices.tolist() for g in hs.groups] == [[1], [3]]
    # a geometric group selecting a welded vertex already held is an overlap, as unwelded
    with pytest.raises(InputError, match=r"h.json: handle group 2: overlaps group 'a'.*welded "
                                         r"vertex 1"):
        parse_handles([{"name": "a", "indices": [3]},
                       {"sphere": {"center": [1, 0, 0], "radius": 0.1}}], V, "h.json", welded=w)
    # vertex numbers are the input's: 5 exists on the soup, not on the welded square
    assert parse_handles([{"indices": [5]}], V, welded=w).indices.tolist() == [2]
    with pytest.raises(InputError, match=r"vertex index 6 out of range \(mesh has 6 vertices"):
        parse_handles([{"indices": [6]}], V, welded=w)
    with pytest.raises(InputError, match="input vertices 1 and 3 were welded into one"):
        parse_handles([{"indices": [1]}, {"indices": [3], "translate": [0, 0, 1]}], V,
                      welded=w)


def test_editor_and_batch_jobs_select_on_the_welded_mesh(tmp_path):
    """The editor's --handles and a batch job's inline handles resolve like deform."""
    import argparse

    from arapkit.cli.edit import build_state
    from arapkit.workflows.jobs import DeformJob, load_job_inputs

    soup = square_soup()
    path = tmp_path / "sq.off"
    save_mesh(path, soup.vertices, soup.faces)
    groups = [{"name": "a", "indices": [5]},
              {"name": "b", "nearest": {"point": [1, 0.1, 0], "k": 2}, "translate": [0, 0, 1]}]
    h = tmp_path / "h.json"
    h.write_text(json.dumps(groups))
    ns = argparse.Namespace(mesh=str(path), rings_file=None, rings=1, handles=str(h),
                            session=None, weld=1e-7)
    st = build_state(ns)
    assert [(x.name, x.vertices.tolist()) for x in st.handles] == [("a", [2]), ("b", [1, 3])]
    inputs = load_job_inputs(DeformJob(mesh=str(path), handles=groups, weld=1e-7))
    assert inputs.handles.indices.tolist() == [2, 1, 3]
    assert inputs.handles.targets.tolist() == [[0, 1, 0], [1, 0, 1], [1, 1, 1]]
