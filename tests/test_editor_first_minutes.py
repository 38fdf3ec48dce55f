"""A newcomer's first minutes in the editor, in a real headless Chromium.

Each test is one step where a new user tripped: the rectangle promised by the default
tool, the hint that a fixed handle is needed, a rigid drag reported as converged, the
handle the controls act on named on them, and the energy legend of a shape at rest.
Skipped with the reason when Chromium or Playwright is missing (see test_editor_browser).
"""

from __future__ import annotations

import time

import numpy as np
from test_editor_browser import (
    CameraView,
    _browser_or_skip,
    _browser_page,
    _camera_reported,
    example_app,
    wait_for,
)

from arapkit.editor.tools import find_tool


def _pixels(page, client, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Page coordinates (x, y) of world points as the browser's camera shows them."""
    cam = client.camera
    view = CameraView(np.asarray(cam.position), np.asarray(cam.wxyz), float(cam.fov),
                      float(cam.aspect))
    box = page.locator("canvas").first.bounding_box()
    uv, _ = view.project(np.atleast_2d(points))
    return box["x"] + uv[:, 0] * box["width"], box["y"] + uv[:, 1] * box["height"]


def _shift_drag(page, x0: float, y0: float, x1: float, y1: float) -> None:
    page.keyboard.down("Shift")
    page.mouse.move(x0, y0)
    page.mouse.down()
    page.mouse.move(x1, y1, steps=12)
    page.mouse.up()
    page.keyboard.up("Shift")


def _pot_and_top(app) -> tuple[np.ndarray, np.ndarray]:
    """The cactus's pot (bottom 12 %) and the tip of its trunk (top 4 %)."""
    y = app.state.vertices[:, 1]
    lo, hi = y.min(), y.max()
    return (np.flatnonzero(y < lo + 0.12 * (hi - lo)),
            np.flatnonzero(y > hi - 0.04 * (hi - lo)))


def _panel_text(page) -> str:
    return page.inner_text("body")


def _click_button(page, name: str) -> None:
    page.get_by_role("button", name=name, exact=True).click()


def _drag_gizmo_sideways(page, client, app, name: str) -> np.ndarray:
    """Look at handle ``name`` from the front and drag its gizmo's x arrow to the right."""
    h = app.state.handle(name)
    g = h.position.copy()
    eye = g + np.array([0.0, 0.0, 0.6 * app.diag])
    client.camera.position = tuple(eye)
    client.camera.look_at = tuple(g)
    wait_for(lambda: np.allclose(client.camera.look_at, g, atol=1e-3)
             and np.allclose(client.camera.position, eye, atol=1e-3), 30, "the camera to move")
    time.sleep(0.5)
    # the arrow beyond the rotation rings, which cross the axes at about 0.65 of its length
    x, y = _pixels(page, client, g + 0.85 * app.gizmo_scale(h) * np.array([1.0, 0.0, 0.0]))
    page.mouse.move(float(x[0]), float(y[0]))
    page.mouse.down()
    for k in range(1, 11):
        page.mouse.move(float(x[0]) + 8 * k, float(y[0]))
        time.sleep(0.05)
    page.mouse.up()
    wait_for(lambda: app.state.handle(name).position[0] > g[0] + 1e-3 * app.diag, 30,
             "the gizmo drag to reach the server")
    return g


def test_browser_default_tool_draws_the_rectangle_it_promises(tmp_path):
    """Shift+drag with the tool the page starts with selects; the help names only that."""
    sync_playwright = _browser_or_skip()
    app = example_app("cactus.off", tmp_path)
    try:
        assert app.wait_idle(120)
        pot, _ = _pot_and_top(app)
        with _browser_page(sync_playwright, app) as (page, client):
            wait_for(lambda: _camera_reported(client), 30, "the browser to report its camera")
            start = app.server.initial_camera
            # position and look-at arrive in separate messages: wait for both
            wait_for(lambda: np.allclose(client.camera.position, start.position, atol=1e-3)
                     and np.allclose(client.camera.look_at, start.look_at, atol=1e-3), 30,
                     "the page's camera to be the initial one")
            text = _panel_text(page)
            assert find_tool(app.dd_tool.value).help in text
            assert "brush stroke" not in text  # not promised by the selection tool
            # framed: the model spans most of the view's height or width
            x, y = _pixels(page, client, app.state.vertices)
            box = page.locator("canvas").first.bounding_box()
            fill = max((y.max() - y.min()) / box["height"], (x.max() - x.min()) / box["width"])
            assert 0.5 < fill < 0.9, fill
            cam_before = np.asarray(client.camera.position).copy()
            xs, ys = _pixels(page, client, app.state.vertices[pot])
            _shift_drag(page, xs.min() - 15, ys.min() - 5, xs.max() + 15, ys.max() + 15)
            wait_for(lambda: len(app.state.selection) > 0, 15, "the rectangle to select")
            # the pot and the trunk's foot in front of it, not the camera
            y_sel = app.state.vertices[app.state.selection, 1]
            span, bottom = np.ptp(app.state.vertices[:, 1]), app.state.vertices[:, 1].min()
            assert len(y_sel) > 50 and y_sel.max() < bottom + 0.5 * span
            assert np.allclose(client.camera.position, cam_before, atol=1e-6)
    finally:
        app.stop()


def test_browser_hint_asks_for_a_fixed_handle(tmp_path):
    sync_playwright = _browser_or_skip()
    app = example_app("cactus.off", tmp_path)
    st = app.state
    try:
        assert app.wait_idle(120)
        pot, top = _pot_and_top(app)
        with _browser_page(sync_playwright, app) as (page, _):
            st.select_near(st.vertices[top].mean(axis=0), 0.05 * app.diag)
            _click_button(page, "Make handle from selection")
            wait_for(lambda: len(st.handles) == 1, 15, "the handle")
            page.get_by_text("pin a region").wait_for(timeout=15_000)
            st.select_near(st.vertices[pot].mean(axis=0), 0.1 * app.diag)
            _click_button(page, "Make fixed handle from selection")
            wait_for(lambda: len(st.handles) == 2, 15, "the fixed handle")
            assert st.handles[-1].frozen
            page.get_by_text("drag a gizmo").wait_for(timeout=15_000)
            assert "pin a region" not in _panel_text(page)
    finally:
        app.stop()


def test_browser_rigid_drag_converges(tmp_path):
    """One handle, nothing fixed: the model follows rigidly, and that is convergence."""
    sync_playwright = _browser_or_skip()
    app = example_app("cactus.off", tmp_path)
    st = app.state
    try:
        assert app.wait_idle(120)
        _, top = _pot_and_top(app)
        st.select_near(st.vertices[top].mean(axis=0), 0.05 * app.diag)
        with _browser_page(sync_playwright, app) as (page, client):
            _click_button(page, "Make handle from selection")
            wait_for(lambda: len(st.handles) == 1, 15, "the handle")
            assert app.wait_idle(60)
            rest = app.served_vertices().copy()
            name = st.handles[0].name
            _drag_gizmo_sideways(page, client, app, name)
            assert app.wait_idle(60)
            u = app.last_update
            assert u.final and u.converged and u.iterations <= 3, (u.iterations, u.energy)
            page.get_by_text("converged").first.wait_for(timeout=15_000)
            assert "max iterations" not in _panel_text(page)
            shift = app.served_vertices() - rest
            assert np.abs(shift - shift.mean(axis=0)).max() < 1e-4 * app.diag  # rigid
    finally:
        app.stop()


def test_browser_controls_name_the_handle_they_act_on(tmp_path):
    sync_playwright = _browser_or_skip()
    app = example_app("cactus.off", tmp_path)
    st = app.state
    try:
        assert app.wait_idle(120)
        pot, top = _pot_and_top(app)
        with _browser_page(sync_playwright, app) as (page, _):
            st.select_near(st.vertices[pot].mean(axis=0), 0.1 * app.diag)
            _click_button(page, "Make handle from selection")
            st.select_near(st.vertices[top].mean(axis=0), 0.05 * app.diag)
            _click_button(page, "Make handle from selection")
            wait_for(lambda: len(st.handles) == 2, 15, "two handles")
            newest = st.handles[-1].name
            page.get_by_role("button", name=f"Remove {newest}").wait_for(timeout=15_000)
            page.get_by_role("button", name=f"Reset pose of {newest}").wait_for(timeout=5_000)
            # a failed "Make handle" leaves an error line ...
            _click_button(page, "Make handle from selection")
            page.get_by_text("nothing is selected").first.wait_for(timeout=15_000)
            assert app.md_status.content.startswith("⚠")
            # ... which the next action that works clears; the controls still name the handle
            _click_button(page, "Clear selection")
            wait_for(lambda: not app.md_status.content.startswith("⚠"), 15,
                     "the error line to clear")
            page.get_by_role("button", name=f"Remove {newest}").wait_for(timeout=5_000)
            # Frozen acts on the handle named there
            page.get_by_role("checkbox").first.check()
            wait_for(lambda: st.handle(newest).frozen, 15, "the named handle to freeze")
            assert not st.handles[0].frozen
    finally:
        app.stop()


def test_browser_energy_legend_reads_zero_at_rest(tmp_path):
    sync_playwright = _browser_or_skip()
    app = example_app("cactus.off", tmp_path)
    st = app.state
    try:
        assert app.wait_idle(120)
        pot, top = _pot_and_top(app)
        st.add_handle(pot, frozen=True)
        st.add_handle(top)
        app.after_edit()
        assert app.wait_idle(60)
        with _browser_page(sync_playwright, app) as (page, _):
            app.dd_view.value = "Energy"  # what choosing it in the page does
            legend = page.get_by_text("vertex energy")
            legend.wait_for(timeout=15_000)
            assert "0 everywhere" in legend.inner_text()
            box = legend.bounding_box()
            assert box is not None and 0 <= box["y"] and box["y"] + box["height"] <= 800
            # one colour: no shaded node, one node for the lowest energy bin
            assert len(app.mesh_nodes()) == 1 and app.mesh_node is None
    finally:
        app.stop()


def test_r_sliders_follow_the_library_and_gizmos_fit_their_handle(tmp_path):
    from arapkit.editor.app import GIZMO_MAX, GIZMO_MIN
    from arapkit.validate import MAX_RINGS

    app = example_app("cactus.off", tmp_path)
    st = app.state
    try:
        assert app.sl_global.max == app.sl_paint.max == MAX_RINGS
        pot, top = _pot_and_top(app)
        small = st.add_handle(top[:4])
        big = st.add_handle(pot)
        for h in (small, big):
            radius = np.linalg.norm(h.anchor - h.pivot, axis=1).max()
            scale = app.gizmo_scale(h)
            assert GIZMO_MIN * app.diag <= scale <= GIZMO_MAX * app.diag
            # reaches past its handle, within the size that keeps it in the view
            assert scale >= min(4 * radius, GIZMO_MAX * app.diag)
        assert app.gizmo_scale(small) < app.gizmo_scale(big)
    finally:
        app.stop()
