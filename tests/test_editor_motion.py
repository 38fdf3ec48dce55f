"""The editor's secondary motion (ARAP dynamics while dragging): server side and in Chromium.

The browser test needs Debian's ``chromium`` at /usr/bin/chromium and Playwright for
Python (no browser download); without them it is skipped with the reason.
"""

from __future__ import annotations

import argparse
import contextlib
import socket
import time
from pathlib import Path

import numpy as np
import pytest

from arapkit import Deformer
from arapkit.cli.edit import build_state
from arapkit.editor.app import EditorApp
from arapkit.editor.geometry import CameraView
from arapkit.editor.motion import editor_stiffness
from arapkit.editor.settings import SolverSettings
from arapkit.errors import InputError

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


def test_a_drag_with_secondary_motion_lags_swings_and_settles(tmp_path):
    """Ticked, a drag steps an elastic body: shapes keep coming after the release (it
    swings), the middle of the bar passes the static shape and comes back, and the last
    update is final with the bar settled at the static shape for the handles."""
    app = bar_app(tmp_path / "out")
    try:
        assert app.wait_idle(120)
        with app.lock:
            app.cb_dynamics.value = True  # what the page's checkbox sends
        assert app.state.settings.dynamics and "secondary motion" in app.md_settings.content
        assert app.wait_idle(120)
        seen = []
        app.sent_hooks.append(lambda u, sent: seen.append(u))
        st = app.state
        tip = st.handle("free end")
        start = tip.position.copy()
        release = None
        for k, phase in enumerate(["start", "update", "update", "update", "end"]):
            seq = app.drag_handle("free end", (1, 0, 0, 0), start + [0, 0, 0.5 * k], phase)
            release = seq if seq is not None else release
            time.sleep(1 / 30)
        assert app.wait_idle(120)
        last = seen[-1]
        assert last.final and last.converged and last.error is None
        assert "secondary motion" in last.notes[0]
        after = [u for u in seen if u.seq == release]
        assert len(after) > 5  # it kept moving after the last move of the drag
        idx, tgt = st.constraints()
        static = Deformer(st.mesh, idx).solve(tgt, tol=1e-8).vertices
        diag = st.mesh.bounding_box_diagonal
        assert np.abs(last.vertices - static).max() < 0.01 * diag
        mid = np.abs(st.mesh.vertices[:, 0] - 3.5) < 0.3
        z = np.array([u.vertices[mid, 2].mean() for u in seen]) - static[mid, 2].mean()
        assert z.min() < -0.05 and z.max() > 0.02  # behind, then past the static shape
        # unticked, the next drag is the static solve again
        with app.lock:
            app.cb_dynamics.value = False
        app.drag_handle("free end", (1, 0, 0, 0), start, "start")
        app.drag_handle("free end", (1, 0, 0, 0), start + [0, 0, 0.2], "end")
        assert app.wait_idle(120)
        assert not app.last_update.notes or "secondary" not in app.last_update.notes[0]
    finally:
        app.stop()


def test_secondary_motion_refuses_what_it_cannot_run():
    from arapkit.editor.motion import SecondaryMotion
    from arapkit.editor.worker import SolveRequest
    from arapkit.mesh.shapes import bar

    m = bar()
    req = SolveRequest(m, np.array([0]), m.vertices[[0]], np.ones(m.n_vertices, int),
                       SolverSettings(method="sr-arap", dynamics=True))
    with pytest.raises(InputError, match="secondary motion runs a local/global descent"):
        SecondaryMotion().simulator_for(req, m.vertices)
    with pytest.raises(InputError, match="session solver: stiffness: must be greater"):
        SolverSettings.from_dict({"dynamics": True, "stiffness": 0})
    assert SolverSettings.from_dict({"dynamics": True}).dynamics
    assert editor_stiffness(m) == pytest.approx(3e4)


# ------------------------------------------------------------------ real browser


def _chromium_or_skip():
    if not CHROMIUM.exists():
        pytest.skip("Debian chromium not installed at /usr/bin/chromium "
                    "(apt-get install chromium; .ci/run does this)")
    sync_api = pytest.importorskip("playwright.sync_api",
                                   reason="playwright for Python is not installed")
    return sync_api.sync_playwright


@contextlib.contextmanager
def page_on(sync_playwright, app: EditorApp):
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


def test_browser_toggle_gives_secondary_motion(tmp_path):
    """In Chromium: tick *Secondary motion* in the solver panel, drag the free end's gizmo;
    the server runs the dynamics and shapes keep arriving after the mouse is released."""
    sync_playwright = _chromium_or_skip()
    app = bar_app(tmp_path / "out")
    try:
        assert app.wait_idle(120)
        st = app.state
        tip = st.handle("free end")
        with page_on(sync_playwright, app) as (page, client):
            box = page.get_by_label("Secondary motion")
            box.scroll_into_view_if_needed()
            box.check()
            wait_for(lambda: st.settings.dynamics, 30, "the checkbox to reach the server")
            assert app.wait_idle(60)
            seen = []
            app.sent_hooks.append(lambda u, sent: seen.append((time.monotonic(), u)))
            g = tip.position.copy()
            eye = g + np.array([0.0, -4.0, 1.0])
            client.camera.position = tuple(eye)
            client.camera.look_at = tuple(g)
            wait_for(lambda: np.allclose(client.camera.look_at, g, atol=1e-3)
                     and np.allclose(client.camera.position, eye, atol=1e-3), 30,
                     "the camera to move")
            canvas = page.locator("canvas").first
            cbox = canvas.bounding_box()
            cam = client.camera
            view = CameraView(np.asarray(cam.position), np.asarray(cam.wxyz),
                              float(cam.fov), float(cam.aspect))
            arrow = g + 0.85 * app.gizmo_scale(tip) * np.array([0.0, 0.0, 1.0])
            uv, _ = view.project(arrow[None])
            x = cbox["x"] + uv[0, 0] * cbox["width"]
            y = cbox["y"] + uv[0, 1] * cbox["height"]
            page.mouse.move(x, y)
            page.mouse.down()
            for k in range(1, 11):
                page.mouse.move(x, y - 20 * k)
                time.sleep(0.03)
            page.mouse.up()
            released = time.monotonic()
            wait_for(lambda: st.handle("free end").position[2] > g[2] + 0.1, 30,
                     "the gizmo drag to reach the server")
            assert app.wait_idle(120)
            page.screenshot(path=str(tmp_path / "after.png"))
        last = seen[-1][1]
        # the body moved on after the drag: many shapes answer the last gizmo message (it
        # takes about a second of the body's time to settle, 30 steps, whatever the load;
        # three quiet steps end it)
        after = [u for t, u in seen if u.seq == last.seq]
        assert len(after) >= 8, (len(after), seen[-1][0] - released)
        assert last.final and last.error is None and "secondary motion" in last.notes[0]
        assert np.abs(app.served_vertices() - st.vertices).max() < 1e-5
    finally:
        app.stop()


def test_browser_secondary_motion_keeps_a_painted_part_rigid(tmp_path):
    """In Chromium: a rigid part painted in the bar's middle (the *Groups* panel's state),
    *Secondary motion* ticked, the free end dragged: every shape the body sends keeps the
    part's edge lengths (the painted groups reach the body as they reach the static
    solve)."""
    sync_playwright = _chromium_or_skip()
    app = bar_app(tmp_path / "out")
    try:
        assert app.wait_idle(120)
        st = app.state
        with app.lock:
            g = st.new_group(rigid=True)
            st.paint_group(st.vertices[int(np.argmin(np.abs(st.vertices[:, 0] - 3.5)))],
                           0.6, g)
        part = np.flatnonzero(st.groups.ids == g)
        assert len(part) > 20
        E = st.mesh.edges[np.isin(st.mesh.edges, part).all(axis=1)]
        rest = np.linalg.norm(st.vertices[E[:, 0]] - st.vertices[E[:, 1]], axis=1)
        tip = st.handle("free end")
        with page_on(sync_playwright, app) as (page, client):
            box = page.get_by_label("Secondary motion")
            box.scroll_into_view_if_needed()
            box.check()
            wait_for(lambda: st.settings.dynamics, 30, "the checkbox to reach the server")
            assert app.wait_idle(60)
            seen = []
            app.sent_hooks.append(lambda u, sent: seen.append(u))
            gz = tip.position.copy()
            eye = gz + np.array([0.0, -4.0, 1.0])
            client.camera.position = tuple(eye)
            client.camera.look_at = tuple(gz)
            wait_for(lambda: np.allclose(client.camera.look_at, gz, atol=1e-3)
                     and np.allclose(client.camera.position, eye, atol=1e-3), 30,
                     "the camera to move")
            canvas = page.locator("canvas").first
            cbox = canvas.bounding_box()
            cam = client.camera
            view = CameraView(np.asarray(cam.position), np.asarray(cam.wxyz),
                              float(cam.fov), float(cam.aspect))
            arrow = gz + 0.85 * app.gizmo_scale(tip) * np.array([0.0, 0.0, 1.0])
            uv, _ = view.project(arrow[None])
            x = cbox["x"] + uv[0, 0] * cbox["width"]
            y = cbox["y"] + uv[0, 1] * cbox["height"]
            page.mouse.move(x, y)
            page.mouse.down()
            for k in range(1, 11):
                page.mouse.move(x, y - 20 * k)
                time.sleep(0.03)
            page.mouse.up()
            wait_for(lambda: st.handle("free end").position[2] > gz[2] + 0.1, 30,
                     "the gizmo drag to reach the server")
            assert app.wait_idle(120)
        shapes = [u.vertices for u in seen if u.vertices is not None and u.error is None]
        assert len(shapes) >= 8 and seen[-1].final
        assert "secondary motion" in seen[-1].notes[0]
        moved = np.abs(shapes[-1][part] - st.mesh.vertices[part]).max()
        assert moved > 1e-3  # the part moved with the body
        for V in shapes:
            L = np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1)
            assert np.abs(L - rest).max() < 1e-9
    finally:
        app.stop()
