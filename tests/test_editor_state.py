"""Editor logic without a browser: selection, handles, paint, flood fill, undo, sessions.

Expected counts are derived independently from the bar's grid layout (70 x 4 x 4 cells,
spacing 0.1 along x, section 0.4 x 0.4): 25 vertices on an end cap, 16 on every other
cross-section ring.
"""

from __future__ import annotations

import argparse
import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from arapkit.editor.geometry import CameraView, raycast
from arapkit.editor.state import EditorState, Handle
from arapkit.editor.views import face_groups, ring_labels
from arapkit.editor.worker import SolveRequest, SolveWorker
from arapkit.errors import InputError
from arapkit.mesh.shapes import bar

CAP, RING = 25, 16  # vertices per end cap / per inner cross-section of the default bar


@pytest.fixture(scope="module")
def mesh():
    return bar()


@pytest.fixture()
def st(mesh):
    return EditorState(mesh)


def columns_below(x: float) -> int:
    """Vertices of the bar with x < ``x`` (x a multiple of 0.1 within the bar)."""
    cols = int(round(x / 0.1))
    return CAP + (cols - 1) * RING


def wxyz_of(rot: Rotation) -> np.ndarray:
    x, y, z, w = rot.as_quat()
    return np.array([w, x, y, z])


# ------------------------------------------------------------------ selection


def test_select_near_matches_brute_force_count(st):
    V = st.mesh.vertices
    p, r = np.array([3.5, 0.0, 0.2]), 0.25
    expected = np.flatnonzero(np.linalg.norm(V - p, axis=1) <= r)
    sel = st.select_near(p, r, mode="replace")
    assert sel.tolist() == expected.tolist()
    assert 10 < len(sel) < 60
    # add elsewhere, then remove the first patch again
    q = np.array([1.0, 0.0, -0.2])
    n_q = int(np.sum(np.linalg.norm(V - q, axis=1) <= r))
    assert len(st.select_near(q, r, mode="add")) == len(expected) + n_q
    assert len(st.select_near(p, r, mode="remove")) == n_q


def test_select_near_tiny_radius_picks_nearest(st):
    sel = st.select_near(np.array([7.01, 0.2, 0.2]), 1e-6, mode="replace")
    assert len(sel) == 1 and np.allclose(st.vertices[sel[0]], [7.0, 0.2, 0.2])


def _front_camera(x: float) -> CameraView:
    # Looks along +y from y = -12; image x = world x, image y (down) = world -z.
    R = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])
    return CameraView(np.array([x, -12.0, 0.0]), wxyz_of(Rotation.from_matrix(R)), 1.2, 1.5)


def test_select_in_rect_front_face_only(st):
    V = st.mesh.vertices
    cam = _front_camera(3.55)  # no grid column sits exactly on the screen centre line
    sel = st.select_in_rect(cam, (0.0, 0.0), (1.0, 1.0), mode="replace")
    front = np.flatnonzero(np.isclose(V[:, 1], -0.2))
    assert len(front) == 71 * 5
    assert sel.tolist() == front.tolist()
    left = st.select_in_rect(cam, (0.0, 0.0), (0.5, 1.0), mode="replace")
    assert len(left) == 36 * 5  # columns x = 0.0 ... 3.5
    assert np.all(V[left, 0] < 3.55)


def test_camera_ray_hits_projected_point(st):
    cam = _front_camera(2.0)
    target = np.array([4.0, -0.2, 0.1])
    uv, depth = cam.project(target[None])
    assert depth[0] == pytest.approx(11.8)
    o, d = cam.ray(uv[0])
    hit = raycast(st.vertices, np.asarray(st.mesh.faces), o, d)
    assert hit is not None
    assert np.allclose(hit[1], target, atol=1e-9)
    assert raycast(st.vertices, np.asarray(st.mesh.faces), o, -d) is None


def _raycast_by_arrays(V, F, o, d):
    """Oracle: Moller-Trumbore over all faces at once with NumPy arrays."""
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    e1, e2 = b - a, c - a
    p = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, p)
    ok = np.abs(det) > 1e-12 * np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1) * \
        np.linalg.norm(d)
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = o - a
    u = np.einsum("ij,ij->i", s, p) * inv
    q = np.cross(s, e1)
    v = (q @ d) * inv
    t = np.einsum("ij,ij->i", e2, q) * inv
    hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
    if not hit.any():
        return None
    f = int(np.flatnonzero(hit)[np.argmin(t[hit])])
    return f, o + t[f] * d


def test_pointer_kernels_are_compiled_once_for_read_only_and_writable_inputs():
    """A mesh's arrays are read-only, a solved shape's are not: both reach one compiled
    version, the one the editor loads in the background at start."""
    from arapkit.editor.app import load_pointer_kernels
    from arapkit.editor.geometry import _nearest_hit
    from arapkit.editor.views import _face_labels, _one_group
    from arapkit.mesh.selection import _reach, connected_region
    from arapkit.mesh.shapes import bar

    load_pointer_kernels()
    m = bar(segments=(8, 2, 2))
    V = np.array(m.vertices)  # writable, like the shapes the solver sends
    assert not m.vertices.flags.writeable and V.flags.writeable
    for P in (V, m.vertices):
        assert raycast(P, m.faces, np.array([3.0, 0.05, 5.0]), np.array([0.0, 0.0, -1.0]))
        face_groups(m.faces, (P[:, 0] > 3).astype(np.int64), 2)
        connected_region(m.faces, P[:, 0] > 3, int(np.argmax(P[:, 0])))
    for kernel in (_nearest_hit, _face_labels, _one_group, _reach):
        assert len(kernel.signatures) == 1, kernel


def test_raycast_matches_the_array_version_on_random_rays():
    from arapkit.mesh.shapes import bar

    m = bar(segments=(30, 6, 6))
    V, F = m.vertices, m.faces
    rng = np.random.default_rng(7)
    hits = 0
    for _ in range(200):
        o = rng.uniform(-2, 9, 3)
        d = rng.uniform(V.min(0), V.max(0)) - o
        want, got = _raycast_by_arrays(V, F, o, d), raycast(V, F, o, d)
        if want is None:
            assert got is None
            continue
        hits += 1
        assert got[0] == want[0] and np.allclose(got[1], want[1], rtol=0, atol=1e-12)
    assert hits > 100


# ------------------------------------------------------------------ handles


def test_handle_targets_follow_gizmo_pose(st):
    V = st.mesh.vertices
    cap = np.flatnonzero(np.isclose(V[:, 0], 7.0))
    h = st.add_handle(cap)
    assert h.name == "handle-1" and len(h.vertices) == CAP
    assert np.allclose(h.position, [7.0, 0.0, 0.0])
    rot = Rotation.from_euler("y", -90, degrees=True)
    st.move_handle(h.name, wxyz=wxyz_of(rot), position=[3.0, 0.0, 4.0])
    idx, tgt = st.constraints()
    expected = rot.apply(V[cap] - [7.0, 0, 0]) + [3.0, 0.0, 4.0]
    assert idx.tolist() == cap.tolist()
    assert np.allclose(tgt, expected)
    # the cap normal (+x) is turned to +z
    assert np.allclose(rot.apply([1.0, 0, 0]), [0, 0, 1], atol=1e-12)


def test_new_handle_takes_vertices_from_older_one(st):
    V = st.mesh.vertices
    a = st.add_handle(np.flatnonzero(V[:, 0] <= 0.15), name="left")  # x = 0, 0.1
    assert len(a.vertices) == CAP + RING
    b = st.add_handle(np.flatnonzero(np.isclose(V[:, 0], 0.1)), name="ring")
    assert len(st.handle("left").vertices) == CAP
    assert len(b.vertices) == RING
    assert len(np.unique(st.handle_indices())) == CAP + RING
    with pytest.raises(InputError, match="taken"):
        st.add_handle([5], name="ring")
    with pytest.raises(InputError, match="no vertices"):
        st.add_handle()


def test_rename_freeze_remove(st):
    h = st.add_handle([0, 1, 2])
    st.add_handle([3], name="other")
    st.rename_handle(h.name, "base")
    assert [x.name for x in st.handles] == ["base", "other"]
    with pytest.raises(InputError, match="taken"):
        st.rename_handle("base", "other")
    st.set_frozen("base", True)
    before = st.handle("base").targets().copy()
    assert st.move_handle("base", position=[9.0, 9, 9]) is False
    assert np.array_equal(st.handle("base").targets(), before)
    st.remove_handle("other")
    assert [x.name for x in st.handles] == ["base"]
    assert st.handle_indices().tolist() == [0, 1, 2]


# ------------------------------------------------------------------ rigidity


def test_paint_counts_vertices_in_brush(st):
    V = st.mesh.vertices
    p, r = np.array([2.0, 0.2, 0.0]), 0.3
    expected = int(np.sum(np.linalg.norm(V - p, axis=1) <= r))
    assert st.paint(p, r, 4) == expected
    assert int(np.sum(st.rings == 4)) == expected
    assert st.paint(p, r, 4) == 0  # nothing changes: no undo step either
    assert st.undo() and not st.can_undo  # exactly one step was recorded


def test_flood_fill_stops_at_change_of_r(st):
    V = st.mesh.vertices
    x = V[:, 0]
    band = (x > 2.0 - 1e-9) & (x < 3.0 + 1e-9)  # columns 2.0 ... 3.0
    st.load_rings(np.where(band, 4, 1))
    # left of the band: every vertex with x < 2
    assert st.flood_fill(0, 2) == columns_below(2.0) == 329
    assert np.array_equal(st.rings == 2, x < 2.0 - 1e-9)
    # the band itself: 11 inner rings
    seed = int(np.flatnonzero(np.isclose(x, 2.5))[0])
    assert st.flood_fill(seed, 5) == 11 * RING
    # right of the band stays untouched: x = 3.1 ... 6.9 rings plus the end cap
    assert int(np.sum(st.rings == 1)) == 39 * RING + CAP
    region = st.fill_region(int(np.argmax(x)))
    assert len(region) == 39 * RING + CAP


def test_connected_region_matches_a_breadth_first_search_over_edges():
    """Oracle: scipy's BFS over the mesh's edges with both ends in the mask, on a mesh of
    two parts whose mask has holes (faces with a masked-out corner still join the rest)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import breadth_first_order

    from arapkit import Mesh
    from arapkit.mesh.selection import connected_region
    from arapkit.mesh.shapes import bar

    one = bar(segments=(20, 4, 4))
    V = np.concatenate([one.vertices, one.vertices + [0.0, 5.0, 0.0]])
    F = np.concatenate([one.faces, one.faces + one.n_vertices])
    mesh = Mesh(V, F)
    rng = np.random.default_rng(3)
    mask = (V[:, 0] < 1.2) | (V[:, 0] > 1.6) | (rng.random(len(V)) < 0.3)
    e = mesh.edges[mask[mesh.edges[:, 0]] & mask[mesh.edges[:, 1]]]
    g = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(len(V), len(V))).tocsr()
    sizes = set()
    for seed in rng.choice(np.flatnonzero(mask), 12, replace=False):
        want = np.sort(breadth_first_order(g, seed, directed=False, return_predecessors=False))
        got = connected_region(mesh.faces, mask, int(seed))
        assert np.array_equal(got, want)
        sizes.add(len(got))
    assert len(sizes) > 1  # the seeds fell in different regions
    assert connected_region(mesh.faces, mask, int(np.flatnonzero(~mask)[0])).size == 0


def test_set_global_rings_and_bad_rings(st):
    st.set_global_rings(3)
    assert np.all(st.rings == 3)
    with pytest.raises(InputError, match="1154"):
        st.load_rings(np.ones(5, int))
    with pytest.raises(InputError, match=r"r = 0 \(r must be 1\.\.100\)"):
        st.load_rings(np.zeros(st.n, int))


# ------------------------------------------------------------------ undo / redo


def test_undo_redo_handles_and_paint(st):
    h = st.add_handle([0, 1, 2])  # step 1
    st.move_handle(h.name, position=[1.0, 2.0, 3.0])  # step 2
    n_painted = st.paint(np.array([5.0, 0, 0]), 0.3, 6)  # step 3
    assert n_painted > 0
    assert st.undo()  # paint gone
    assert np.all(st.rings == 1)
    assert np.allclose(st.handle(h.name).position, [1.0, 2.0, 3.0])
    assert st.undo()  # move gone
    assert np.allclose(st.handle(h.name).position, st.mesh.vertices[[0, 1, 2]].mean(0))
    assert st.undo()  # handle gone
    assert st.handles == [] and not st.undo()
    assert st.redo() and st.redo() and st.redo()
    assert np.allclose(st.handle(h.name).position, [1.0, 2.0, 3.0])
    assert int(np.sum(st.rings == 6)) == n_painted
    assert not st.redo()
    st.undo()
    st.set_global_rings(2)  # a new edit drops the redo list
    assert not st.can_redo


def test_drag_is_one_undo_step(st):
    h = st.add_handle([10, 11])
    start = h.position.copy()
    st.checkpoint()  # gizmo drag start
    for k in range(5):
        st.move_handle(h.name, position=start + [0.1 * k, 0, 0], record=False)
    st.undo()
    assert np.allclose(st.handle(h.name).position, start)


# ------------------------------------------------------------------ sessions


def test_session_round_trip(st, tmp_path):
    from arapkit.io import save_mesh

    mesh_file = tmp_path / "bar.off"
    save_mesh(mesh_file, st.mesh.vertices, st.mesh.faces)
    st.mesh_path = str(mesh_file)
    a = st.add_handle(np.arange(25), name="base", frozen=True)
    b = st.add_handle(np.arange(1129, 1154), name="tip")
    rot = Rotation.from_euler("z", 30, degrees=True)
    st.move_handle("tip", wxyz=wxyz_of(rot), position=b.position + [0, 1, 0])
    st.paint(np.array([3.5, 0, 0]), 0.4, 5)
    st.settings.tol, st.settings.method = 1e-5, "laplacian"
    path = st.save_session(tmp_path / "s.json")
    d = json.loads(path.read_text())
    assert d["mesh"] == str(mesh_file) and len(d["rings"]) == st.n
    assert np.allclose(d["targets"], st.constraints()[1])

    st2 = EditorState.from_session(path)
    assert [h.name for h in st2.handles] == ["base", "tip"]
    assert st2.handle("base").frozen and not st2.handle("tip").frozen
    assert np.array_equal(st2.handle_indices(), st.handle_indices())
    assert np.allclose(st2.constraints()[1], st.constraints()[1])
    assert np.array_equal(st2.rings, st.rings)
    assert st2.settings == st.settings
    assert a.name == "base"


def test_old_session_method_names_load_and_save_as_the_one_name(st, tmp_path):
    """Sessions of arapkit 0.1 say "arap" or "volumetric": read as r-ring ARAP, written new."""
    from arapkit.editor.settings import SolverSettings
    from arapkit.methods.registry import method

    st.add_handle(np.arange(25), name="base", frozen=True)
    for old, volumetric in (("arap", False), ("volumetric", True)):
        d = json.loads(json.dumps(st.to_dict()))
        d["solver"] = {"method": old, "weights": "cotan", "tol": 1e-4, "max_iter": 50,
                       "live_max_iter": 8, "live_budget_ms": 60.0}  # no "volumetric" key then
        path = tmp_path / f"{old}.json"
        path.write_text(json.dumps(d))
        st2 = EditorState(st.mesh)
        st2.apply_dict(EditorState.read_session(path))
        s = st2.settings
        assert (s.method, s.volumetric) == ("rring", volumetric)
        assert method(s.method).rigidity_map and s.tol == 1e-4 and s.max_iter == 50
        saved = json.loads(st2.save_session(tmp_path / f"{old}-new.json").read_text())["solver"]
        assert saved["method"] == "rring" and saved["volumetric"] is volumetric
        assert SolverSettings.from_dict(saved) == s
    # volumetric is offered only where the registry says the method has a volumetric form
    with pytest.raises(InputError, match="no volumetric form"):
        SolverSettings.from_dict({"method": "laplacian", "volumetric": True})
    with pytest.raises(InputError, match="volumetric must be true or false"):
        SolverSettings.from_dict({"volumetric": "yes"})


def test_session_for_another_mesh_is_refused(st, tmp_path):
    d = st.to_dict()
    d["n_vertices"] = 10
    with pytest.raises(InputError, match="10 vertices"):
        st.apply_dict(d)
    with pytest.raises(InputError, match="not an arapkit editor session"):
        st.apply_dict({"format": "x"})
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(InputError, match="cannot read session"):
        EditorState.read_session(bad)


def test_handle_from_dict_with_targets_only():
    h = Handle.from_dict({"name": "t", "vertices": [0, 1], "targets": [[0, 0, 1], [0, 0, 3]]}, 5)
    assert np.allclose(h.position, [0, 0, 2]) and np.allclose(h.targets()[:, 2], [1, 3])


# ------------------------------------------------------------------ views, CLI state


def test_face_groups_cover_every_face_once(st):
    r = np.ones(st.n, int)
    r[:100] = 3
    r[100:120] = 9
    groups = face_groups(st.mesh.faces, ring_labels(r), 6)
    assert sum(len(g.faces) for g in groups) == st.mesh.n_faces
    assert {g.label for g in groups} == {0, 2, 5}
    flab = ring_labels(r)[st.mesh.faces].max(axis=1)
    for g in groups:
        # oracle: np.unique's sorted vertices and inverse numbering of the group's faces
        mine = st.mesh.faces[flab == g.label]
        vidx, local = np.unique(mine, return_inverse=True)
        assert np.array_equal(g.vertices, vidx)
        assert np.array_equal(g.faces, local.reshape(-1, 3))
        assert np.array_equal(g.vertices[g.faces], mine)


def test_cli_state_reads_handles_and_rings(tmp_path):
    from arapkit.cli.edit import build_state
    from arapkit.io import save_rings

    hfile = tmp_path / "h.json"
    hfile.write_text(json.dumps([
        {"name": "left", "box": {"min": [-1, -1, -1], "max": [0.05, 1, 1]}},
        {"name": "right", "box": {"min": [6.95, -1, -1], "max": [8, 1, 1]},
         "translate": [0, 0, 1]},
    ]))
    rfile = tmp_path / "r.txt"
    save_rings(rfile, np.full(1154, 2))
    ns = argparse.Namespace(mesh=None, rings_file=str(rfile), rings=1, handles=str(hfile),
                            session=None)
    st = build_state(ns)
    # the built-in handles are replaced by the file's groups (same vertices)
    assert [h.name for h in st.handles] == ["left", "right"]
    assert st.handle("left").frozen and not st.handle("right").frozen
    assert np.allclose(st.handle("right").position, [7.0, 0, 1.0])
    assert np.all(st.rings == 2) and not st.can_undo


# ------------------------------------------------------------------ solver thread


def test_worker_newer_request_supersedes_older(mesh):
    from arapkit.editor.state import SolverSettings

    st = EditorState(mesh)
    x = mesh.vertices[:, 0]
    st.add_handle(np.flatnonzero(x < 1e-9), frozen=True)
    tip = st.add_handle(np.flatnonzero(x > 7 - 1e-9))
    updates = []
    w = SolveWorker(updates.append)
    w.start()
    try:
        seqs, start = [], tip.position.copy()
        for k in range(1, 9):
            st.move_handle(tip.name, position=start + [0, 0, 0.1 * k], record=False)
            idx, tgt = st.constraints()
            seqs.append(w.submit(SolveRequest(mesh, idx, tgt, st.rings, SolverSettings())))
        assert w.wait_idle(120)
    finally:
        w.stop()
    solved = {u.seq for u in updates}
    assert seqs[-1] in solved
    assert len(solved) < len(seqs) and w.dropped >= 1  # intermediate moves were dropped
    last = updates[-1]
    assert last.final and last.seq == seqs[-1] and last.converged and last.error is None
    assert np.isfinite(last.energy) and last.energy > 0
    moved = last.vertices[tip.vertices] - mesh.vertices[tip.vertices]
    assert np.allclose(moved, [0.0, 0.0, 0.8], atol=1e-9)


# ------------------------------------------------------------------ first minutes


def test_tool_help_promises_only_what_the_tool_does():
    from arapkit.editor.tools import TOOLS, find_tool

    for t in TOOLS:
        assert ("Shift+drag" in t.help) == (t.rectangle or t.brush), t.label
        # a painting tool names what it paints: the panel's Paint r, or its Group
        names_paint = "Paint r" in t.help or "**Group**" in t.help
        assert ("rectangle" in t.help) == t.rectangle and names_paint == t.paints
    # the page starts with the selection tool, which draws the rectangle the CLI promises
    assert find_tool("Select").rectangle and find_tool("Select: click") is find_tool("select")


def test_next_step_follows_the_handles(st):
    from arapkit.editor.panels import handle_controls, next_step

    assert "select a region" in next_step(st)
    h = st.add_handle(np.arange(CAP))
    assert "Make fixed handle" in next_step(st)
    st.set_frozen(h.name, True)
    assert "Make handle" in next_step(st) and "Make fixed" not in next_step(st)
    st.add_handle(np.arange(st.n - CAP, st.n))
    assert next_step(st).startswith("**Next:** drag a gizmo")
    labels = handle_controls(h.name)
    assert h.name in labels["heading"] and labels["remove"] == f"Remove {h.name}"
    assert handle_controls("x" * 80)["remove"].endswith("…")


def test_energy_scale_has_a_floor_relative_to_the_mesh():
    from arapkit.editor.views import energy_floor, energy_legend_html, energy_scale

    unit = 0.3  # rest term per vertex
    noise = np.full(100, 4e-10)  # round-off of a shape at rest
    vmax = energy_scale(noise, energy_floor(unit))
    assert vmax == pytest.approx(1e-6 * unit)
    assert "0 everywhere" in energy_legend_html(vmax, floor=energy_floor(unit), top=4e-10)
    bent = np.linspace(0, 1e-2 * unit, 100)  # a real deformation keeps its own scale
    assert energy_scale(bent, energy_floor(unit)) == pytest.approx(np.percentile(bent, 99))
