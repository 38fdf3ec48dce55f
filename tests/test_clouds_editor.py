"""The editor on a point cloud: splats in every view, picking by the click ray, the flood
fill along the graph, the drag (plain and coarse to fine), exports with the points'
attributes, and a real Chromium opening a cloud, picking and dragging it.

Oracles: the library's own solve (Deformer, MultiresDeformer) of the same state, the
point nearest the click ray found by brute force, the file read back.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import pytest
from test_editor_browser import (
    _browser_or_skip,
    _browser_page,
    _non_background_fraction,
    free_port,
    wait_for,
)

from arapkit import Deformer, load_points
from arapkit.cli.edit import build_state
from arapkit.editor.app import EditorApp
from arapkit.editor.geometry import CameraView, pick_point
from arapkit.editor.points import CloudNode
from arapkit.editor.state import EditorState

ROOT = Path(__file__).resolve().parents[1]
CLOUD = ROOT / "examples" / "cactus-points.ply"


def cloud_app(export_dir: Path, handles: bool = True) -> EditorApp:
    """The editor opened on the example cloud as ``arapkit edit`` opens it."""
    ns = argparse.Namespace(mesh=str(CLOUD), rings_file=None, rings=1, session=None,
                            handles=str(ROOT / "examples" / "cactus.json") if handles else None)
    return EditorApp(build_state(ns), port=free_port(), export_dir=export_dir)


def test_pick_point_is_the_nearest_point_along_the_ray_within_the_radius():
    rng = np.random.default_rng(0)
    P = rng.random((4000, 3))
    for _ in range(20):
        o = rng.random(3) * 4 - 1.5
        d = rng.normal(size=3)
        r = 0.05
        hit = pick_point(P, o, d, r)
        u = d / np.linalg.norm(d)
        t = (P - o) @ u
        dist = np.linalg.norm(P - o - t[:, None] * u, axis=1)
        ok = np.flatnonzero((t > 0) & (dist <= r))
        if len(ok) == 0:
            assert hit is None
        else:
            assert hit[0] == ok[np.argmin(t[ok])]


def test_a_cloud_is_drawn_as_splats_and_dragged_as_the_library_solves(tmp_path):
    app = cloud_app(tmp_path / "out")
    try:
        assert app.wait_idle(120)
        st = app.state
        assert isinstance(app.mesh_node, CloudNode) and app._groups == []
        assert "2,000 points, a point cloud (kNN, k = 10)" in app.mesh_info()
        # the shaded view shows the file's own colours
        src = st.mesh.attributes.vertex_properties
        assert np.array_equal(app.mesh_node.colors[:, 0], src["red"])
        # only the methods that apply, and the cloud's weights
        assert app.dd_method.options == ("r-ring ARAP", "embedded deformation")
        assert app.dd_weights.options == ("gaussian", "uniform", "laplacian")
        movable = [h for h in st.handles if not h.frozen]
        h = movable[0]
        start = h.position.copy()
        for k, phase in enumerate(["start", "update", "end"]):
            app.drag_handle(h.name, (1, 0, 0, 0), start + [0.0, 0.5 * k, 0.0], phase)
        assert app.wait_idle(120)
        hidx, targets = st.constraints()
        # the editor warm-starts each solve from the drag's last shape: the library's solve
        # from rest to the same stopping test lies within 1 % of the diagonal (0.2 %
        # measured), at an energy as low to 5 %; handles exact
        d = Deformer(st.mesh, hidx, tol=st.settings.tol, max_iter=st.settings.max_iter)
        want = d.solve(targets)
        diag = st.mesh.bounding_box_diagonal
        assert np.abs(st.vertices - want.vertices).max() < 0.01 * diag
        assert d.energy_of(st.vertices, targets) < 1.05 * want.energy
        assert np.abs(st.vertices[hidx] - targets).max() < 1e-12 * diag
        assert np.abs(st.vertices - st.mesh.points).max() > 0.02 * diag
        assert np.abs(app.served_vertices() - st.vertices).max() < 1e-5
        # the r view colours the same node per point
        with app.lock:
            app.dd_view.value = "Rigidity r"
        assert app.wait_idle(60) and isinstance(app.mesh_node, CloudNode) and not app._groups
        # exports keep the points' properties, normals turned
        mesh_path = app.export()[0]
        out = load_points(mesh_path)
        assert np.abs(out.points - st.vertices).max() < 1e-12
        assert "part" in out.attributes.vertex_properties and out.normals is not None
    finally:
        app.stop()


def test_clicks_pick_points_and_the_fill_follows_the_graph(tmp_path):
    app = cloud_app(tmp_path / "out", handles=False)
    try:
        assert app.wait_idle(120)
        st = app.state
        P = st.vertices
        front = int(np.argmax(P[:, 2] - 10 * np.abs(P[:, 1] - 6) - 10 * np.abs(P[:, 0])))
        hit = app._hit(P[front] + [0, 0, 5.0], [0, 0, -1.0])
        assert hit is not None and hit[0] is None
        assert np.linalg.norm(hit[1] - P[front]) <= app.edge_length
        # paint the pot r = 4, then fill the plant r = 2 from one of its points: the fill
        # stops at the pot (the graph's region of equal r)
        pot = np.flatnonzero(P[:, 1] < 2.1)
        st.rings[pot] = 4
        n = app.apply_tool("fill", P[front], face=None)
        assert n == st.n - len(pot) and (st.rings[pot] == 4).all()
        assert (np.delete(st.rings, pot) == app.sl_paint.value).all()
    finally:
        app.stop()


def test_a_large_cloud_previews_on_its_subsample_and_releases_the_exact_solve(tmp_path):
    """Coarse to fine in the editor: the drag draws the proxy's splats, the release the
    library's coarse-to-fine solve."""
    from arapkit import PointCloud
    from arapkit.mesh.shapes import bar
    from arapkit.methods.multires import MultiresDeformer

    m = bar(segments=(120, 10, 10))
    st = EditorState(PointCloud(m.vertices, name="bar points"))
    x = m.vertices[:, 0]
    st.add_handle(np.flatnonzero(x == x.min()), name="fixed end", frozen=True)
    tip = st.add_handle(np.flatnonzero(x == x.max()), name="free end")
    st.settings.multires = True
    app = EditorApp(st, port=free_port(), export_dir=tmp_path / "out")
    shown = []
    app.sent_hooks.append(lambda u, t: shown.append(u))
    try:
        assert app.wait_idle(120)
        start = tip.position.copy()
        for k, phase in enumerate(["start", "update", "update", "end"]):
            app.drag_handle("free end", (1, 0, 0, 0), start + [0, 0, 0.6 * k], phase)
        assert app.wait_idle(180)
        assert any(u.proxy_vertices is not None for u in shown)
        assert isinstance(app.proxy_node, CloudNode)
        hidx, targets = st.constraints()
        want = MultiresDeformer(st.mesh, hidx, tol=st.settings.tol,
                                max_iter=st.settings.max_iter).solve(targets)
        assert np.abs(st.vertices - want.vertices).max() < 1e-9 * st.mesh.bounding_box_diagonal
        assert not app.proxy_node.visible and app.mesh_node.visible
    finally:
        app.stop()


def test_browser_opens_a_cloud_picks_a_point_and_drags_it(tmp_path):
    sync_playwright = _browser_or_skip()
    app = cloud_app(tmp_path / "out")
    try:
        assert app.wait_idle(120)
        st = app.state
        h = next(h for h in st.handles if not h.frozen)
        before = app.served_vertices()[h.vertices].copy()
        with _browser_page(sync_playwright, app) as (page, client):
            centre = st.mesh.points.mean(axis=0) + app._origin * 0
            eye = centre + np.array([0.0, 0.0, 30.0])
            client.camera.position = tuple(eye)
            client.camera.look_at = tuple(centre)
            client.camera.up_direction = (0.0, 1.0, 0.0)
            wait_for(lambda: np.allclose(client.camera.look_at, centre, atol=1e-3)
                     and np.allclose(client.camera.position, eye, atol=1e-3), 30,
                     "the camera to move")
            canvas = page.locator("canvas").first
            box = canvas.bounding_box()
            scene = {"x": box["x"], "y": box["y"] + 160, "width": box["width"] - 360,
                     "height": box["height"] - 160}
            wait_for(lambda: _non_background_fraction(page.screenshot(clip=scene)) > 0.02,
                     30, "the splats to be drawn (canvas stays blank)")
            page.screenshot(path=str(tmp_path / "cloud.png"))
            cam = client.camera
            view = CameraView(np.asarray(cam.position), np.asarray(cam.wxyz),
                              float(cam.fov), float(cam.aspect))

            def screen(p):
                uv, _ = view.project(np.asarray(p, np.float64)[None])
                return box["x"] + uv[0, 0] * box["width"], box["y"] + uv[0, 1] * box["height"]

            # pick: the Select tool, a click on the trunk's front selects the points there
            with app.lock:
                app.dd_tool.value = "Select"
            P = st.vertices
            trunk = np.flatnonzero((np.abs(P[:, 0]) < 0.4) & (np.abs(P[:, 1] - 5.0) < 0.4))
            front = trunk[np.argmax(P[trunk, 2])]
            page.mouse.click(*screen(P[front]))
            wait_for(lambda: len(st.selection) > 0, 30, "the click to select points")
            near = np.linalg.norm(P[st.selection] - P[front], axis=1)
            assert near.max() < app._radius() + 2 * app.edge_length
            assert P[st.selection, 2].mean() > 0  # the front of the trunk, not its back

            # drag: the moving handle's gizmo, its y arrow pulled up the screen
            g = h.position.copy()
            arrow = g + 0.85 * app.gizmo_scale(h) * np.array([0.0, 1.0, 0.0])
            x, y = screen(arrow)
            page.mouse.move(x, y)
            page.mouse.down()
            for k in range(1, 11):
                page.mouse.move(x, y - 8 * k)
                time.sleep(0.05)
            page.mouse.up()
            wait_for(lambda: st.handle(h.name).position[1] > g[1] + 0.1, 30,
                     "the gizmo drag to reach the server")
            assert app.wait_idle(60)
            time.sleep(1.0)
            page.screenshot(path=str(tmp_path / "dragged.png"))
        moved = st.handle(h.name).position - g
        served = app.served_vertices()[h.vertices]
        assert moved[1] > 0.1
        assert np.allclose(served - before, moved, atol=1e-4)
        assert app.last_update.error is None and np.isfinite(app.last_update.energy)
    finally:
        app.stop()


@pytest.mark.parametrize("name", ["cactus-points.ply"])
def test_uploading_a_cloud_file_opens_it(tmp_path, name):
    app = cloud_app(tmp_path / "out", handles=False)
    try:
        assert app.wait_idle(120)
        data = (ROOT / "examples" / "cactus.off").read_bytes()
        app.open_mesh_bytes("cactus.off", data)  # a mesh again: triangles, mesh methods
        assert app.wait_idle(120) and app.state.mesh.faces is not None
        assert "SR-ARAP" in app.dd_method.options
        app.open_mesh_bytes(name, (ROOT / "examples" / name).read_bytes())
        assert app.wait_idle(120) and app.state.mesh.faces is None
        assert isinstance(app.mesh_node, CloudNode)
        assert app.dd_weights.value == "gaussian"
    finally:
        app.stop()


def test_edit_opens_a_cloud_on_the_graph_asked_for_and_its_session_keeps_it(tmp_path):
    """``arapkit edit cloud --neighbours K`` (or ``--radius``) solves on that graph, the
    saved session records it and reopening builds the same graph (its edges compared with
    the library's cloud on the same option); a session's bad graph and a graph option
    beside ``--session`` are refused in one line."""
    from arapkit import InputError

    for opts in ({"neighbours": 6, "radius": None}, {"neighbours": None, "radius": 0.08}):
        ns = argparse.Namespace(mesh=str(CLOUD), rings_file=None, rings=1, session=None,
                                handles=None, **opts)
        st = build_state(ns)
        lib = load_points(CLOUD, **{k: v for k, v in opts.items() if v is not None})
        assert np.array_equal(st.mesh.edges, lib.edges)
        path = st.save_session(tmp_path / "s.json")
        back = EditorState.from_session(path)
        assert np.array_equal(back.mesh.edges, lib.edges)
        assert len(lib.edges) != len(load_points(CLOUD).edges)  # not the default graph
    d = EditorState.read_session(path)
    d["graph"] = {"k": 3}
    import json

    (tmp_path / "bad.json").write_text(json.dumps(d))
    with pytest.raises(InputError, match="bad.json: 'graph' must hold 'neighbours' or "
                       "'radius', got \\['k'\\]"):
        EditorState.from_session(tmp_path / "bad.json")
    ns = argparse.Namespace(mesh=None, rings_file=None, rings=1, session=str(path),
                            handles=None, neighbours=8, radius=None)
    with pytest.raises(InputError, match="a session keeps the graph it was made with"):
        build_state(ns)


def test_arapkit_edit_opens_a_cloud_from_the_command_line(capsys, monkeypatch):
    """The command line's own door (``run``, not only ``build_state``): a file without
    faces opens in the 3D editor on the graph asked for (it was read as a mesh for the
    2D check and refused)."""
    import socket

    import arapkit.editor.app as app_mod
    from arapkit.cli import main

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    served = []

    def serve(self):
        served.append(self.state)
        self.stop()

    monkeypatch.setattr(app_mod.EditorApp, "serve_forever", serve)
    assert main(["edit", str(CLOUD), "-k", "6", "--port", str(port)]) == 0, \
        capsys.readouterr().err
    assert "(point cloud cactus-points.ply, 2000 points; " in capsys.readouterr().out
    (st,) = served
    assert st.mesh.faces is None and st.n == 2000
    assert np.array_equal(st.mesh.edges, load_points(CLOUD, neighbours=6).edges)
