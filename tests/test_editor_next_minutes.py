"""The editor's next five minutes (issue 47): large r, rejected values, opening a mesh,
the Global r slider and undo, handle colours, what stays in view, and the smaller items.

Server-side tests drive the app as the page's callbacks do; browser tests use a real
headless Chromium (skipped with the reason when it or Playwright is missing, see
test_editor_browser). Meshes: the built-in bar, the examples' cactus and, where the data
is there, the cow of ../shared/data (skipped with the reason otherwise).
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from test_editor_browser import (
    _browser_or_skip,
    _browser_page,
    _camera_reported,
    bar_app,
    example_app,
    free_port,
    wait_for,
)
from test_editor_first_minutes import _click_button, _pixels

from arapkit.arap import ringcost
from arapkit.editor import panels
from arapkit.editor.app import EditorApp
from arapkit.editor.panels import HANDLE_COLOURS, handle_controls
from arapkit.editor.state import EditorState

ROOT = Path(__file__).resolve().parents[1]
COW = ROOT.parent / "shared" / "data" / "meshes" / "cow.off"
needs_cow = pytest.mark.skipif(not COW.exists(), reason=f"{COW} not found (../shared/data)")


def cow_app(tmp_path: Path) -> EditorApp:
    from arapkit import load_mesh

    return EditorApp(EditorState(load_mesh(COW)), port=free_port(), export_dir=tmp_path)


def event() -> SimpleNamespace:
    return SimpleNamespace(client=None)


def slide(app: EditorApp, values) -> None:
    """What viser sends for a drag of the Global r slider: every value it passes."""
    for v in values:
        with app.lock:
            app.quietly(lambda v=v: setattr(app.sl_global, "value", v))
        app.ui(lambda e, v=v: app._global_moved(v, e))(event())


# ------------------------------------------------------------------ large r (item 1)
def test_memory_refusal_in_the_editor_names_its_own_control(tmp_path, monkeypatch):
    monkeypatch.setenv(ringcost.RING_MEMORY_VARIABLE, "40")
    app = bar_app(tmp_path)
    st = app.state
    try:
        assert app.wait_idle(120)
        slide(app, [60])
        app.apply_pending_global()
        # refused before anything is built: r stays, the slider shows it again
        assert np.all(st.rings == 1) and app.sl_global.value == 1
        msg = app.md_status.content
        assert msg.startswith("⚠") and "r = 60 on 1,154 vertices needs about" in msg
        lo = int(msg.split("the largest r that fits is ")[1].split()[0])
        assert msg.endswith(f"(Global r {lo} in the Rigidity panel)")
        assert not st.can_undo  # the refused step left no undo step behind
        slide(app, [lo])
        app.apply_pending_global()
        assert np.all(st.rings == lo)
        assert app.wait_idle(120) and app.last_update.error is None
    finally:
        app.stop()


def test_a_long_build_shows_progress_and_can_be_cancelled(tmp_path, monkeypatch):
    from arapkit.arap import rings as rings_module

    app = bar_app(tmp_path)
    st = app.state
    seen = []
    app.sent_hooks.append(lambda u, t: seen.append(u))
    try:
        assert app.wait_idle(120)
        # from now on every build looks long: it runs in a thousand pieces and reports;
        # each piece is slowed down, so that the build takes a minute unless cancelled
        monkeypatch.setattr(ringcost, "SECONDS_PER_EDGE_ENTRY", 1.0)
        real = rings_module._fill

        def slow_fill(*args):
            time.sleep(0.05)
            return real(*args)

        monkeypatch.setattr(rings_module, "_fill", slow_fill)
        slide(app, [8])
        app.apply_pending_global()
        wait_for(lambda: any(u.building and 0 < u.building[0] < 1 for u in seen), 60,
                 "a build's progress")
        # the page stays live: its thread answers while the worker builds
        with app.lock:
            assert app.bt_cancel_build.visible
            assert 'role="progressbar"' in app.top.parts["progress"]
            assert "Building the r-rings for r = 8" in app.top.parts["progress"]
        app.ui(lambda e: app._cancel_build())(event())
        assert app.wait_idle(120)
        # back to the map being solved, as an undoable step; no error, no bar
        assert np.all(st.rings == 1) and np.all(app.worker.deformer.rings == 1)
        u = app.last_update
        assert u.final and u.error is None and u.building is None
        assert not app.bt_cancel_build.visible and app.top.parts["progress"] == ""
        assert st.undo() and np.all(st.rings == 8)
    finally:
        app.stop()


# ------------------------------------------------------------------ rejected values
def test_a_rejected_value_goes_back_to_the_last_accepted_one(tmp_path):
    app = bar_app(tmp_path)
    st = app.state
    try:
        assert app.wait_idle(120)
        slide(app, [5, 50, 500])  # typed "500": its first keystrokes were in range
        assert app.sl_global.value == 1 and app.md_status.content.startswith("⚠")
        assert "must be at most 100, got 500" in app.md_status.content
        time.sleep(panels.SLIDER_REST_S + 0.5)  # nothing typed before it is applied
        assert np.all(st.rings == 1) and not st.can_undo
        with app.lock:
            app.nb_tol.value = -1.0  # another field: the same rule
        assert app.nb_tol.value == st.settings.tol
    finally:
        app.stop()


# ------------------------------------------------------------------ the Global r slider
def test_a_slider_gesture_is_one_rebuild_and_one_undo_step(tmp_path):
    app = bar_app(tmp_path)
    st = app.state
    builds = []
    try:
        assert app.wait_idle(120)
        d = app.worker.deformer
        real = d.set_rings
        d.set_rings = lambda r: builds.append(int(np.max(r))) or real(r)
        slide(app, range(2, 18))  # 20 px of slider: 1 -> 17
        time.sleep(panels.SLIDER_REST_S + 0.5)
        assert app.wait_idle(120)
        assert np.all(st.rings == 17) and builds == [17]
        # a gesture that paused (or whose values came late) is applied in two pieces, and
        # is still one undo step
        slide(app, range(18, 24))
        time.sleep(panels.SLIDER_REST_S + 0.5)
        slide(app, range(24, 30))
        time.sleep(panels.SLIDER_REST_S + 0.5)
        assert app.wait_idle(120) and np.all(st.rings == 29)
        assert st.undo() and np.all(st.rings == 1) and not st.can_undo
    finally:
        app.stop()


def test_undo_brings_back_a_removed_fixed_handle_in_one_click(tmp_path):
    """Issue 47 needed 6 clicks, 3 of which changed nothing: each slider value was a step,
    and so was a gizmo grabbed and let go in place."""
    app = bar_app(tmp_path)
    st = app.state
    try:
        assert app.wait_idle(120)
        slide(app, range(2, 6))
        app.apply_pending_global()
        app.active = "fixed end"
        app.ui(lambda e: app._remove_handle())(event())
        assert all(not h.frozen for h in st.handles)
        tip = st.handle("free end")
        for phase in ("start", "end"):  # grabbed and let go without moving
            app.drag_handle("free end", tip.wxyz, tip.position, phase)
        app.ui(lambda e: app._history(st.undo))(event())  # one click: the handle is back
        assert any(h.name == "fixed end" and h.frozen for h in st.handles)
        app.ui(lambda e: app._history(st.undo))(event())  # one more: the slider's gesture
        assert np.all(st.rings == 1)
        assert not st.undo() and not st.can_undo
    finally:
        app.stop()


# ------------------------------------------------------------------ colours
def test_handle_colours_follow_one_rule_that_the_panel_names(tmp_path):
    app = bar_app(tmp_path)
    st = app.state
    try:
        assert app.wait_idle(120)
        x = st.vertices[:, 0]
        st.selection = np.flatnonzero(np.abs(x - 3.5) < 0.2)
        app.ui(lambda e: app._make_handle(frozen=True))(event())
        new = st.handles[-1].name

        def colour_of(name: str) -> tuple:
            idx = st.handle_indices()
            at = np.concatenate([np.full(len(h.vertices), h.name == name) for h in st.handles])
            cols = np.asarray(app._markers["handles"].colors)[at]
            assert len(np.unique(cols, axis=0)) == 1
            return tuple(int(c) for c in cols[0]) if len(idx) else ()

        # a new fixed handle is active and grey: light grey, never the movable yellow
        assert colour_of(new) == HANDLE_COLOURS[(True, True)][0]
        assert "(light grey dots)" in app.md_active.content
        assert colour_of("fixed end") == HANDLE_COLOURS[(True, False)][0]
        assert colour_of("free end") == HANDLE_COLOURS[(False, False)][0]  # orange
        app.ui(lambda e: app._select_handle("free end"))(event())
        assert colour_of("free end") == HANDLE_COLOURS[(False, True)][0]  # yellow
        assert "(yellow dots)" in app.md_active.content
        assert colour_of(new) == HANDLE_COLOURS[(True, False)][0]
        assert handle_controls("x", frozen=False)["heading"].count("yellow") == 1
    finally:
        app.stop()


# ------------------------------------------------------------------ smaller items
@needs_cow
def test_dots_are_sized_by_the_local_edge_length(tmp_path):
    app = cow_app(tmp_path)
    st = app.state
    try:
        head = st.vertices[np.argmax(st.vertices[:, 0])]
        st.select_near(head, 0.08 * app.diag, mode="replace")
        app.draw_markers()
        P = st.vertices[st.selection]
        gaps = np.linalg.norm(P[:, None] - P[None], axis=-1)
        np.fill_diagonal(gaps, np.inf)
        nearest = np.median(gaps.min(axis=1))
        size = app._markers["selection"].point_size
        # a dot's diameter below the typical distance to its neighbour: no overlap
        assert size < nearest, (size, nearest)
        assert size > 0.2 * nearest  # and still visible
    finally:
        app.stop()


def test_painting_in_the_shaded_view_shows_the_r_view(tmp_path):
    app = bar_app(tmp_path)
    try:
        assert app.dd_view.value == "Shaded"
        with app.lock:
            app.dd_tool.value = "Paint brush"
        assert app.dd_view.value == "Rigidity r" and app._groups
        assert "switched to *Rigidity r*" in app.md_tool_help.content
        assert "r:" in app.html_legend.content
    finally:
        app.stop()


def test_removing_the_only_fixed_handle_says_so(tmp_path):
    app = bar_app(tmp_path)
    st = app.state
    try:
        assert app.wait_idle(120)
        app.active = "fixed end"
        app.ui(lambda e: app._remove_handle())(event())
        assert app.wait_idle(120)
        assert "No fixed handle left" in app.md_status.content
        assert "pin a region" in app.md_hint.content
        app.ui(lambda e: app._history(st.undo))(event())
        assert app.wait_idle(120)
        assert "No fixed handle left" not in app.md_status.content
    finally:
        app.stop()


def test_next_hint_follows_the_selection_and_make_handle_says_what_to_do(tmp_path):
    app = bar_app(tmp_path)
    st = app.state
    try:
        assert app.wait_idle(120)
        st.select_near(st.vertices[600], 0.3, mode="replace")
        app.draw_markers()  # what a click's selection does
        assert "selected: press **Make handle from selection**" in app.md_hint.content
        st.clear_selection()
        app.ui(lambda e: app._make_handle())(event())
        assert "Make handle: nothing is selected. Select a region first" in \
            app.md_status.content
    finally:
        app.stop()


def test_reset_pose_is_enabled_only_where_it_does_something(tmp_path):
    app = example_app("cactus.off", tmp_path)
    st = app.state
    try:
        assert app.bt_reset.disabled and app.bt_remove.disabled and app.bt_rename.disabled
        st.select_near(st.vertices[0], 0.05 * app.diag)
        app.ui(lambda e: app._make_handle())(event())
        name = st.handles[-1].name
        assert app.bt_reset.disabled and not app.bt_remove.disabled  # at rest: nothing to do
        h = st.handle(name)
        app.drag_handle(name, h.wxyz, h.position + 0.1, "start")
        app.drag_handle(name, h.wxyz, h.position, "end")
        app.sync_handle_widgets()
        assert not app.bt_reset.disabled
        app.ui(lambda e: app._reset_pose())(event())
        assert app.bt_reset.disabled and st.handle(name).at_rest
    finally:
        app.stop()


def test_opening_a_mesh_without_work_to_lose_does_not_ask(tmp_path):
    app = example_app("cactus.off", tmp_path)
    try:
        assert not app.has_work()
        app.state.select_near(app.state.vertices[0], 0.05 * app.diag)
        app.ui(lambda e: app._make_handle())(event())
        assert app.has_work()
    finally:
        app.stop()


# ------------------------------------------------------------------ in a real browser
def _panel_box(page) -> dict:
    return page.locator(".mantine-ScrollArea-viewport").first.bounding_box()


def test_browser_status_and_legend_stay_in_view(tmp_path):
    sync_playwright = _browser_or_skip()
    app = bar_app(tmp_path)
    try:
        assert app.wait_idle(120)
        with _browser_page(sync_playwright, app) as (page, _):
            with app.lock:
                app.dd_view.value = "Rigidity r"
            legend = page.locator("#arapkit-top .legend")
            legend.wait_for(timeout=15_000)
            # at the bottom of the panel (Session), status, hint and legend are still there
            page.get_by_role("button", name="Export mesh + rings").scroll_into_view_if_needed()
            time.sleep(0.5)
            panel = _panel_box(page)
            for text in ("r-ring ARAP", "Next:"):
                box = page.locator("#arapkit-top").get_by_text(text).first.bounding_box()
                assert box is not None and panel["y"] - 1 <= box["y"]
                assert box["y"] + box["height"] <= panel["y"] + panel["height"]
            # the legend's first letter is inside the panel, not on its edge
            lbox = legend.bounding_box()
            assert lbox["x"] >= panel["x"] + 4, (lbox, panel)
            # nothing drawn over it: the block is on top where it stands
            x, y = lbox["x"] + 2, lbox["y"] + lbox["height"] / 2
            on_top = page.evaluate(
                "([x, y]) => !!document.elementFromPoint(x, y).closest('#arapkit-top')", [x, y])
            assert on_top
            page.screenshot(path=str(tmp_path / "scrolled.png"))
    finally:
        app.stop()


def test_browser_typed_500_and_abc_leave_the_last_accepted_r(tmp_path):
    sync_playwright = _browser_or_skip()
    app = bar_app(tmp_path)
    st = app.state
    try:
        assert app.wait_idle(120)
        with _browser_page(sync_playwright, app) as (page, _):
            box = page.locator(".mantine-NumberInput-input").nth(1)  # Radius, Global r, ...
            box.scroll_into_view_if_needed()
            box.click()
            box.fill("")
            box.type("500")
            wait_for(lambda: box.input_value() == "1", 15, "the field to show r = 1 again")
            page.get_by_text("must be at most 100, got 500").first.wait_for(timeout=15_000)
            page.keyboard.press("Tab")  # the blur that used to apply 100 silently
            time.sleep(panels.SLIDER_REST_S + 1.0)
            assert box.input_value() == "1" and np.all(st.rings == 1)
            box.click()
            box.fill("")
            box.type("abc")  # taken by no number box: it stays empty, and says why
            said = box.evaluate("e => getComputedStyle("
                                "e.closest('.mantine-NumberInput-root'), '::after').content")
            assert said == '"numbers only"'
            assert box.evaluate("e => getComputedStyle(e).outlineColor") == "rgb(250, 82, 82)"
            assert np.all(st.rings == 1)
            box.fill("7")  # and a number clears it
            assert box.evaluate("e => getComputedStyle("
                                "e.closest('.mantine-NumberInput-root'), '::after').content"
                                ) == "none"
    finally:
        app.stop()


def test_browser_open_mesh_asks_before_replacing_the_session(tmp_path):
    sync_playwright = _browser_or_skip()
    app = bar_app(tmp_path)  # two handles: something to lose
    cactus = ROOT / "examples" / "cactus.off"
    try:
        assert app.wait_idle(120)
        with _browser_page(sync_playwright, app) as (page, _):
            upload = page.locator("input[type=file]").last  # Open mesh, the last upload
            upload.set_input_files(str(cactus))
            page.get_by_text("Open cactus.off?").wait_for(timeout=30_000)
            assert app.state.n == 1154 and len(app.state.handles) == 2
            page.get_by_role("button", name="Keep bar").click()
            wait_for(lambda: page.get_by_text("Open cactus.off?").count() == 0, 15,
                     "the question to close")
            assert app.state.n == 1154 and len(app.state.handles) == 2
            upload.set_input_files([])  # the same file again must count as a new choice
            upload.set_input_files(str(cactus))
            page.get_by_role("button", name="Open cactus.off").click()
            wait_for(lambda: app.state.mesh.name == "cactus", 30, "the new mesh")
            assert app.state.handles == []
            # a refused upload: no "File uploaded successfully" before the refusal
            bad = tmp_path / "notes.txt"
            bad.write_text("hello")
            upload.set_input_files([])
            upload.set_input_files(str(bad))
            notes = page.locator(".mantine-Notification-root")
            notes.filter(has_text="not a mesh file").first.wait_for(timeout=30_000)
            assert notes.filter(has_text="File uploaded successfully").filter(
                visible=True).count() == 0
            assert app.state.mesh.name == "cactus"
    finally:
        app.stop()


@pytest.mark.parametrize("name", ["cow", "cactus.off"])
def test_browser_gizmo_arrows_stay_in_the_view_left_of_the_panel(tmp_path, name):
    """Handles at the model's ends (a long cow, a tall cactus: the top of its trunk), on
    the view the page opens with: every arrow tip is in the view, left of the panel."""
    sync_playwright = _browser_or_skip()
    if name == "cow" and not COW.exists():
        pytest.skip(f"{COW} not found (../shared/data)")
    app = cow_app(tmp_path) if name == "cow" else example_app(name, tmp_path)
    st = app.state
    try:
        assert app.wait_idle(120)
        V = st.vertices
        for k in (np.argmax(V[:, 0]), np.argmin(V[:, 0]), np.argmin(V[:, 1]),
                  np.argmax(V[:, 1])):
            st.select_near(V[k], 0.05 * app.diag, mode="replace")
            st.add_handle()
        app.after_edit()
        with _browser_page(sync_playwright, app) as (page, client):
            wait_for(lambda: _camera_reported(client), 30, "the browser's camera")
            start = app.server.initial_camera
            wait_for(lambda: np.allclose(client.camera.position, start.position, atol=1e-3)
                     and np.allclose(client.camera.look_at, start.look_at, atol=1e-3), 30,
                     "the page's camera to be the initial one")
            panel = page.locator(".mantine-ScrollArea-viewport").first.bounding_box()
            canvas = page.locator("canvas").first.bounding_box()
            for h in st.handles:
                s = app.gizmo_scale(h)
                tips = h.position + s * np.vstack([np.eye(3), -np.eye(3)])
                x, y = _pixels(page, client, tips)
                assert x.min() >= canvas["x"] and x.max() <= panel["x"], (h.name, x, panel)
                assert y.min() >= canvas["y"] and y.max() <= canvas["y"] + canvas["height"]
            page.screenshot(path=str(tmp_path / "gizmos.png"))
    finally:
        app.stop()


def test_browser_slider_drag_and_undo_click(tmp_path):
    """A real drag of the slider thumb: one rebuild, one undo step, undone in one click."""
    sync_playwright = _browser_or_skip()
    app = bar_app(tmp_path)
    st = app.state
    try:
        assert app.wait_idle(120)
        with _browser_page(sync_playwright, app) as (page, _):
            slider = page.locator(".mantine-Slider-root").nth(1)  # Radius, Global r, Paint r
            slider.scroll_into_view_if_needed()
            b = slider.bounding_box()
            x0, y0 = b["x"] + 2, b["y"] + b["height"] / 2
            page.mouse.move(x0, y0)
            page.mouse.down()
            for k in range(1, 11):
                page.mouse.move(x0 + 2 * k, y0)
                time.sleep(0.03)
            page.mouse.up()
            wait_for(lambda: np.any(st.rings > 1), 15, "the slider's r to be applied")
            assert app.wait_idle(120)
            r = int(st.rings[0])
            assert r > 1 and np.all(st.rings == r)
            _click_button(page, "Undo")
            wait_for(lambda: np.all(st.rings == 1), 15, "one Undo to bring r = 1 back")
            assert not st.can_undo
    finally:
        app.stop()


# ------------------------------------------------------------------ coarse to fine switch
def test_the_solver_panel_switches_coarse_to_fine(tmp_path, monkeypatch):
    """Auto / On / Off in the Solver panel is the session's ``solver.multires``, and the
    solve follows it: above the (patched) size Auto and On preview on a proxy, Off solves
    the full mesh; a session's value shows in the panel."""
    import arapkit.methods.dispatch as dispatch
    from arapkit.methods.multires import MultiresDeformer

    monkeypatch.setattr(dispatch, "MULTIRES_AUTO_VERTICES", 100)  # the bar counts as large
    app = bar_app(tmp_path)
    try:
        assert app.dd_multires.value == "Auto" and app.state.settings.multires is None
        assert app.wait_idle(120)
        assert isinstance(app.worker.deformer, MultiresDeformer)
        for label, want, cls in (("Off", False, False), ("On", True, True)):
            with app.lock:
                app.quietly(lambda label=label: setattr(app.dd_multires, "value", label))
            app.ui(lambda e: app._apply_settings())(event())
            assert app.wait_idle(120)
            assert app.state.settings.multires is want
            assert isinstance(app.worker.deformer, MultiresDeformer) is cls
        saved = app.state.to_dict()
        assert saved["solver"]["multires"] is True
        app.state.settings = dataclasses.replace(app.state.settings, multires=False)
        with app.lock:
            app.sync_gui_from_state()
        assert app.dd_multires.value == "Off"
    finally:
        app.stop()
