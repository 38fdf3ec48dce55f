"""The editor end to end: a real viser server, and (when available) a real headless browser.

The browser test needs Debian's ``chromium`` at /usr/bin/chromium and Playwright for
Python (no browser download); ``.ci/run`` installs both.  Without them it is skipped with
the reason.  The server-side test runs everywhere.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import socket
import time
from pathlib import Path

import numpy as np
import pytest

from arapkit.cli.edit import build_state
from arapkit.editor.app import EditorApp
from arapkit.editor.geometry import CameraView

CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def bar_app(export_dir: Path) -> EditorApp:
    """The editor on the built-in bar: left end frozen, right end ("free end") draggable."""
    ns = argparse.Namespace(mesh=None, rings_file=None, rings=1, handles=None, session=None)
    return EditorApp(build_state(ns), port=free_port(), export_dir=export_dir)


def wait_for(cond, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not cond():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.05)


# ------------------------------------------------------------------ server side only


def test_a_colour_view_sends_each_shape_once(tmp_path):
    """In the r view the shaded mesh has no node: a new shape goes to the colour groups
    only (sending a hidden shaded mesh too doubled every shape, and viser kept its copies),
    what the page shows is the new shape, and going back to the shaded view sends it
    there."""
    app = bar_app(tmp_path / "out")
    try:
        assert app.wait_idle(120)
        st = app.state
        tip = st.handle("free end")
        shaded = app.mesh_node
        with app.lock:
            app.dd_view.value = "Rigidity r"
        assert app.wait_idle(120) and app._groups
        # the node is removed from the scene, not hidden: viser holds no copy of it
        assert app.mesh_node is None
        with pytest.raises(RuntimeError, match="removed"):
            shaded.vertices = shaded.vertices + 1.0  # a removed node takes no shape
        before = app.served_vertices()
        start = tip.position.copy()
        for k, phase in enumerate(["start", "end"]):
            app.drag_handle("free end", (1, 0, 0, 0), start + [0, 0, 0.3 * k], phase)
        assert app.wait_idle(120)
        assert app.mesh_node is None
        shown = app.served_vertices()
        assert np.abs(shown - st.vertices).max() < 1e-5  # float32 on the wire
        assert np.abs(shown[tip.vertices] - before[tip.vertices]).max() > 0.29
        with app.lock:
            app.dd_view.value = "Shaded"
        assert app.wait_idle(120) and not app._groups
        assert np.abs(app.served_vertices() - st.vertices).max() < 1e-5
    finally:
        app.stop()


def test_a_far_placed_mesh_keeps_its_detail_in_the_scene(tmp_path):
    """A georeferenced scan (coordinates near 5e6) in float32 world coordinates would be
    drawn in 0.5 m steps; the mesh and its dots are sent relative to the mesh's centre,
    under frames placed there, and keep float32's precision at the mesh's own size."""
    from arapkit import Mesh
    from arapkit.editor.state import EditorState
    from arapkit.mesh.shapes import bar

    shift = np.array([5e5, 5e6, 100.0])
    m = bar()
    st = EditorState(Mesh(m.vertices + shift, m.faces))
    x = m.vertices[:, 0]
    st.add_handle(np.flatnonzero(x == x.min()), name="fixed end", frozen=True)
    tip = st.add_handle(np.flatnonzero(x == x.max()), name="free end")
    app = EditorApp(st, port=free_port(), export_dir=tmp_path / "out")
    try:
        assert app.wait_idle(120)
        rest = st.mesh.vertices
        centre = (rest.min(axis=0) + rest.max(axis=0)) / 2
        assert all(np.array_equal(f.position, centre) for f in app._frames)
        start = tip.position.copy()
        for k, phase in enumerate(["start", "end"]):
            app.drag_handle("free end", (1, 0, 0, 0), start + [0, 0, 0.3 * k], phase)
        assert app.wait_idle(120)
        assert np.abs(st.handle("free end").position - start - [0, 0, 0.3]).max() < 1e-9
        # world float32 would be off by up to 0.25 here; the bar is 7 long
        assert np.abs(app.served_vertices() - st.vertices).max() < 1e-5
        dots = app._markers["handles"].points
        idx = np.concatenate([h.vertices for h in st.handles])
        assert np.abs(np.asarray(dots, np.float64) + centre - st.vertices[idx]).max() < 1e-5
    finally:
        app.stop()


def test_server_drag_paint_export_session(tmp_path):
    app = bar_app(tmp_path / "out")
    try:
        assert app.url.startswith("http://127.0.0.1:")
        assert app.wait_idle(120)
        st = app.state
        tip = st.handle("free end")
        rest = app.served_vertices()[tip.vertices].copy()
        start = tip.position.copy()
        for k, phase in enumerate(["start", "update", "update", "end"]):
            app.drag_handle("free end", (1, 0, 0, 0), start + [0, 0, 0.3 * k], phase)
        assert app.wait_idle(120)
        served = app.served_vertices()[tip.vertices]
        assert np.allclose(served - rest, [0, 0, 0.9], atol=1e-5)  # float32 on the wire
        u = app.last_update
        assert u.final and u.converged and np.isfinite(u.energy) and u.energy > 0
        assert st.can_undo  # the whole drag is one step
        st.undo()
        assert np.allclose(st.handle("free end").position, start)

        # paint bucket from the page's tool entry point: the whole bar is one r region
        n = app.apply_tool("Flood fill", st.mesh.vertices[600], face=None)
        assert n == st.n and np.all(st.rings == 3)

        paths = app.export()
        assert [p.name for p in paths] == ["bar-deformed.ply", "bar-rings.txt"]
        assert all(p.parent == (tmp_path / "out").resolve() and p.exists() for p in paths)
        session = app.save_session()
        assert session.name == "bar-session.json" and (tmp_path / "out" / "bar-rest.ply").exists()
    finally:
        app.stop()


def test_an_edit_is_solved_while_the_r_view_is_rebuilt(tmp_path, monkeypatch):
    """after_edit asks for the solve before it rebuilds the display (a 1.75M-vertex r view
    takes 0.2 s), returns its number, and that solve is the one shown with the new r."""
    app = bar_app(tmp_path / "out")
    try:
        assert app.wait_idle(120)
        st = app.state
        with app.lock:
            app.dd_view.value = "Rigidity r"
        events = []
        submit, redraw = app.worker.submit, app.redraw
        monkeypatch.setattr(app.worker, "submit",
                            lambda req: events.append(("solve", submit(req))) or events[-1][1])
        monkeypatch.setattr(app, "redraw", lambda: (events.append(("redraw", None)), redraw()))
        with app.lock:
            st.paint(st.mesh.vertices[600], 0.5, 4)
            seq = app.after_edit()
        assert events == [("solve", seq), ("redraw", None)]
        assert app.wait_idle(120) and app.last_update.seq == seq and app.last_update.final
        painted = np.flatnonzero(st.rings == 4)
        assert len(painted) > 0 and len(app._groups) == 2  # r = 1 and r = 4 drawn apart
        assert app.after_edit(solve=False) is None
    finally:
        app.stop()


TETRA_OFF = b"OFF\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n"


def test_uploads_are_checked(tmp_path):
    from arapkit.errors import InputError

    app = bar_app(tmp_path / "out")
    try:
        app.max_upload_bytes = 1000
        with pytest.raises(InputError, match=r"big\.off: 2.0 KB is over the 1000 bytes limit"):
            app.open_mesh_bytes("big.off", b"OFF\n" + b"0" * 2044)
        app.max_upload_bytes = 2**20
        with pytest.raises(InputError, match=r"^notes\.txt: not a mesh file"):
            app.open_mesh_bytes("notes.txt", b"hello")
        with pytest.raises(InputError, match=r"^garbage\.off: ") as err:
            app.open_mesh_bytes("garbage.off", b"OFF\n3 1 0\n0 0 0\n1 0 0\n")
        assert "arapkit-upload" not in str(err.value)  # names the upload, not the temp file
        assert app.state.n == 1154  # a bad file leaves the editor as it was

        with pytest.raises(InputError, match="1154"):
            app.load_rings_bytes("r.txt", b"1\n2\n")
        rings = app.load_rings_bytes("r.txt", ("3\n" * 1154).encode())
        assert np.all(rings == 3) and np.all(app.state.rings == 3)

        session = app.state.to_dict()
        app.state.undo()  # back to r = 1; the session brings r = 3 back
        app.load_session_bytes("s.json", json.dumps(session).encode())
        assert np.all(app.state.rings == 3)
        with pytest.raises(InputError, match="arapkit edit --session"):
            app.load_session_bytes("s.json", json.dumps({**session, "n_vertices": 4}).encode())

        app.open_mesh_bytes("../../tetra.off", TETRA_OFF)
        assert app.state.n == 4 and app.state.handles == []
        assert app.state.mesh.name == "tetra"
        assert "No handles yet" in app.md_status.content
        assert app.export()[0] == (tmp_path / "out" / "tetra-deformed.ply").resolve()
    finally:
        app.stop()


# ------------------------------------------------------------------ real browser


def _browser_or_skip():
    if not CHROMIUM.exists():
        pytest.skip("Debian chromium not installed at /usr/bin/chromium "
                    "(apt-get install chromium; .ci/run does this)")
    sync_api = pytest.importorskip("playwright.sync_api",
                                   reason="playwright for Python is not installed")
    return sync_api.sync_playwright


def _non_background_fraction(png: bytes) -> float:
    from matplotlib.image import imread

    img = imread(io.BytesIO(png), format="png")[..., :3]
    background = img[2, 2]
    return float(np.mean(np.abs(img - background).sum(axis=-1) > 0.1))


@contextlib.contextmanager
def _browser_page(sync_playwright, app: EditorApp):
    """Chromium showing the editor: yields (page, the server's handle on that client)."""
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS,
                                    headless=True)
        try:
            page = browser.new_page(viewport={"width": 1200, "height": 800})
            page.goto(app.url)
            page.wait_for_selector("canvas", timeout=30_000)
            wait_for(lambda: len(app.server.get_clients()) == 1, 30, "the page to connect")
            yield page, next(iter(app.server.get_clients().values()))
        finally:
            browser.close()


def test_browser_drag_deforms_mesh(tmp_path):
    sync_playwright = _browser_or_skip()
    app = bar_app(tmp_path / "out")
    try:
        assert app.wait_idle(120)
        st = app.state
        tip = st.handle("free end")
        before = app.served_vertices()[tip.vertices].copy()
        with _browser_page(sync_playwright, app) as (page, client):
            # Look at the free end from the front so its gizmo is easy to reach.
            g = tip.position.copy()
            eye = g + np.array([0.0, -4.0, 1.0])
            # position first: moving the camera drags its look-at point along.
            client.camera.position = tuple(eye)
            client.camera.look_at = tuple(g)
            wait_for(lambda: np.allclose(client.camera.look_at, g, atol=1e-3)
                     and np.allclose(client.camera.position, eye, atol=1e-3), 30,
                     "the camera to move")
            canvas = page.locator("canvas").first
            box = canvas.bounding_box()
            # The scene area: left of the GUI panel, below the notifications.
            scene = {"x": box["x"], "y": box["y"] + 160, "width": box["width"] - 360,
                     "height": box["height"] - 160}
            wait_for(lambda: _non_background_fraction(page.screenshot(clip=scene)) > 0.05,
                     30, "the mesh to be drawn (canvas stays blank)")
            page.screenshot(path=str(tmp_path / "before.png"))

            # Grab the gizmo's z arrow halfway along and drag it upwards.
            cam = client.camera
            view = CameraView(np.asarray(cam.position), np.asarray(cam.wxyz),
                              float(cam.fov), float(cam.aspect))
            # beyond the rotation rings, which cross the axes at about 0.65 of the arrow
            arrow = g + 0.85 * app.gizmo_scale(tip) * np.array([0.0, 0.0, 1.0])
            uv, _ = view.project(arrow[None])
            x = box["x"] + uv[0, 0] * box["width"]
            y = box["y"] + uv[0, 1] * box["height"]
            page.mouse.move(x, y)
            page.mouse.down()
            for k in range(1, 11):
                page.mouse.move(x, y - 10 * k)
                time.sleep(0.05)
            page.mouse.up()
            wait_for(lambda: st.handle("free end").position[2] > g[2] + 0.1, 30,
                     "the gizmo drag to reach the server")
            assert app.wait_idle(60)
            time.sleep(1.0)
            page.screenshot(path=str(tmp_path / "after.png"))
        moved = st.handle("free end").position - g
        served = app.served_vertices()[tip.vertices]
        # the served tip follows the gizmo (mostly upwards), the energy is finite
        assert moved[2] > 0.1
        assert np.allclose(served - before, moved, atol=1e-4)
        u = app.last_update
        assert u.error is None and np.isfinite(u.energy) and u.energy > 0
        assert st.can_undo
    finally:
        app.stop()


# ------------------------------------------------------------------ up axis on load

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def example_app(name: str, export_dir: Path, up: str | None = None) -> EditorApp:
    ns = argparse.Namespace(mesh=str(EXAMPLES / name), rings_file=None, rings=1, handles=None,
                            session=None)
    return EditorApp(build_state(ns), port=free_port(), export_dir=export_dir, up=up)


@pytest.mark.parametrize(("name", "up"), [("cactus.off", "+y"), ("finger.off", "+z")])
def test_up_axis_guessed_on_load_and_shown(tmp_path, name, up):
    app = example_app(name, tmp_path)
    try:
        assert app.dd_up.value == up
        assert f"up **{up}** (guessed" in app.md_settings.content
        assert "method **r-ring ARAP**" in app.md_settings.content
        assert f"weights **{app.state.settings.weights}**" in app.md_settings.content
        # the camera starts above the centre along +up, so the model is seen upright
        u = np.array(dict(zip(("+x", "+y", "+z"), np.eye(3), strict=True))[up])
        eye = np.asarray(app.server.initial_camera.position)
        look = np.asarray(app.server.initial_camera.look_at)
        assert (eye - look) @ u > 0
        # switching to a y-up mesh from the page guesses again
        app.open_mesh_bytes("cactus.off", (EXAMPLES / "cactus.off").read_bytes())
        assert app.dd_up.value == "+y"
    finally:
        app.stop()


def test_up_axis_override_holds(tmp_path):
    app = example_app("cactus.off", tmp_path, up="-y")
    try:
        assert app.dd_up.value == "-y" and "set with --up" in app.md_settings.content
    finally:
        app.stop()


def _camera_reported(client) -> bool:
    try:
        return client.camera.update_timestamp > 0
    except AssertionError:  # viser asserts until the browser has sent its camera once
        return False


@pytest.mark.parametrize(("name", "up"), [("cactus.off", (0, 1, 0)), ("finger.off", (0, 0, 1))])
def test_browser_opens_mesh_right_way_up(tmp_path, name, up):
    """The page's own camera (reported back by the browser) has the guessed up direction."""
    sync_playwright = _browser_or_skip()
    app = example_app(name, tmp_path)
    try:
        with _browser_page(sync_playwright, app) as (_, client):
            wait_for(lambda: _camera_reported(client), 30, "the browser to report its camera")
            wait_for(lambda: np.allclose(client.camera.up_direction, up, atol=1e-3), 10,
                     f"the page's camera up direction to become {up}")

            def looks_down_from_above() -> bool:
                cam = client.camera
                return (np.asarray(cam.position) - np.asarray(cam.look_at)) @ up > 0

            # the browser reports position and look-at in separate messages: one CI run
            # saw the new look-at with the page's initial position (3, 3, 3)
            wait_for(looks_down_from_above, 10, "the camera to sit above what it looks at")
    finally:
        app.stop()


# ------------------------------------------------------------------ painting a rigid part


def _stretch(mesh, X, members) -> float:
    """The largest relative change of an edge length inside ``members``."""
    E = mesh.edges[np.isin(mesh.edges, members).all(axis=1)]
    rest = np.linalg.norm(mesh.vertices[E[:, 0]] - mesh.vertices[E[:, 1]], axis=1)
    return float(np.abs(np.linalg.norm(X[E[:, 0]] - X[E[:, 1]], axis=1) / rest - 1).max())


def test_browser_paint_a_part_and_drag(tmp_path):
    """Press *New rigid part*, pick the tool *Paint part*, paint the bar's middle with a
    click and a Shift+drag stroke, drag the free end's gizmo: the part stays rigid, the
    rest bends, and the export writes the part as a groups file."""
    sync_playwright = _browser_or_skip()
    app = bar_app(tmp_path / "out")
    try:
        assert app.wait_idle(120)
        st = app.state
        with _browser_page(sync_playwright, app) as (page, client):
            page.get_by_role("button", name="New rigid part").first.click()
            wait_for(lambda: st.groups.n_groups == 1, 20, "the new part")
            page.get_by_label("Tool", exact=True).last.click()
            page.get_by_role("option", name="Paint part").click()
            wait_for(lambda: app.dd_tool.value == "Paint part", 20, "the tool")
            wait_for(lambda: app.dd_view.value == "Groups", 20, "the groups view")
            mid = st.vertices.mean(axis=0)
            eye = mid + np.array([0.0, -9.0, 2.0])
            client.camera.position = tuple(eye)
            client.camera.look_at = tuple(mid)
            wait_for(lambda: np.allclose(client.camera.look_at, mid, atol=1e-3)
                     and np.allclose(client.camera.position, eye, atol=1e-3), 30, "camera")
            cam = client.camera
            view = CameraView(np.asarray(cam.position), np.asarray(cam.wxyz), float(cam.fov),
                              float(cam.aspect))
            box = page.locator("canvas").first.bounding_box()

            def screen(p):
                uv, _ = view.project(np.asarray(p, float)[None])
                return box["x"] + uv[0, 0] * box["width"], box["y"] + uv[0, 1] * box["height"]

            x, y = screen([3.0, -0.2, 0.0])  # the bar's front face
            # the tool's click listener reaches the page a moment after the tool is chosen
            # (a click before it is not a paint stroke): click again as a user would
            for _ in range(6):
                page.mouse.click(x, y)
                try:
                    wait_for(lambda: (st.groups.ids >= 0).any(), 5, "the click to paint")
                    break
                except AssertionError:
                    continue
            wait_for(lambda: (st.groups.ids >= 0).any(), 5, "the click to paint")
            clicked = int((st.groups.ids >= 0).sum())
            x2, y2 = screen([4.5, -0.2, 0.0])
            page.keyboard.down("Shift")
            page.mouse.move(x, y)
            page.mouse.down()
            for k in range(1, 11):
                page.mouse.move(x + (x2 - x) * k / 10, y + (y2 - y) * k / 10)
                time.sleep(0.05)
            page.mouse.up()
            page.keyboard.up("Shift")
            wait_for(lambda: (st.groups.ids >= 0).sum() > clicked, 30, "the stroke")
            assert app.wait_idle(60)
            part = np.flatnonzero(st.groups.ids == 0)
            xs = st.mesh.vertices[part, 0]
            assert xs.min() < 3.2 and xs.max() > 4.2  # from the click to the stroke's end
            # drag the free end up with its gizmo (its z arrow, as a user grabs it)
            tip = st.handle("free end")
            g = tip.position.copy()
            eye = g + np.array([0.0, -4.0, 1.0])
            client.camera.position = tuple(eye)
            client.camera.look_at = tuple(g)
            wait_for(lambda: np.allclose(client.camera.look_at, g, atol=1e-3)
                     and np.allclose(client.camera.position, eye, atol=1e-3), 30, "camera")
            cam = client.camera
            view = CameraView(np.asarray(cam.position), np.asarray(cam.wxyz), float(cam.fov),
                              float(cam.aspect))
            gx, gy = screen(g + 0.85 * app.gizmo_scale(tip) * np.array([0.0, 0.0, 1.0]))
            # the page makes the gizmos anew after an edit (the stroke): a person's next
            # drag comes later than a script's, so give the new gizmo time to arrive
            time.sleep(2.0)
            page.mouse.move(gx, gy)
            page.mouse.down()
            for k in range(1, 16):
                page.mouse.move(gx, gy - 12 * k)
                time.sleep(0.05)
            page.mouse.up()
            wait_for(lambda: st.handle("free end").position[2] > g[2] + 0.3, 30,
                     "the gizmo drag to reach the server")
            assert app.wait_idle(120)
            page.screenshot(path=str(tmp_path / "painted-part-dragged.png"))
        u = app.last_update
        assert u.error is None and u.final and np.isfinite(u.energy)
        exported = app.export()  # the painted part comes out as a groups file
        from arapkit import load_groups

        assert exported[-1].name == "bar-groups.json"
        assert np.array_equal(load_groups(exported[-1], st.mesh).members(0), part)
        served = app.served_vertices()
        assert np.abs(served[tip.vertices] - st.vertices[tip.vertices]).max() < 1e-4
        assert _stretch(st.mesh, st.vertices, part) < 1e-9  # the part moved rigidly
        assert np.abs(st.vertices[part] - st.mesh.vertices[part]).max() > 0.05  # it moved
        other = np.flatnonzero((st.mesh.vertices[:, 0] > 5.0) & (st.mesh.vertices[:, 0] < 6.5))
        assert _stretch(st.mesh, st.vertices, other) > 1e-4  # the rest bends
    finally:
        app.stop()
