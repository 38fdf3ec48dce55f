"""Painting vertex groups in the editor: the state, the worker, and a real browser.

The browser test drives Debian's ``chromium`` with Playwright as
``tests/test_editor_browser.py`` does (skipped with the reason without them): it presses
*New rigid part*, picks the tool *Paint part*, paints the bar's middle with a click and a
Shift+drag stroke, drags the free end's gizmo, and checks the painted part stayed rigid.
"""

from __future__ import annotations

import time

import numpy as np
import pytest
from test_editor_browser import _browser_or_skip, _browser_page, bar_app, wait_for

from arapkit.editor.geometry import CameraView
from arapkit.editor.groups import ERASE, PaintedGroups
from arapkit.editor.state import EditorState
from arapkit.errors import InputError
from arapkit.mesh.shapes import bar


def _stretch(mesh, X, members) -> float:
    E = mesh.edges[np.isin(mesh.edges, members).all(axis=1)]
    rest = np.linalg.norm(mesh.vertices[E[:, 0]] - mesh.vertices[E[:, 1]], axis=1)
    return float(np.abs(np.linalg.norm(X[E[:, 0]] - X[E[:, 1]], axis=1) / rest - 1).max())


def test_painted_groups_undo_sessions_and_names():
    st = EditorState(bar())
    g = st.new_group(rigid=True)
    assert st.paint_group(st.vertices[600], 0.5, g) > 0
    shared = st.new_group(rigid=False)
    st.paint_group(st.vertices[100], 0.3, shared)
    vg = st.groups.vertex_groups()
    assert vg.names == ("part 1", "group 1") and vg.rigid.tolist() == [True, False]
    assert st.groups.index_of(ERASE) == -1 and st.groups.index_of("part 1 (rigid)") == 0
    # a session keeps them; undo takes the last stroke back
    again = EditorState(bar())
    again.apply_dict(st.to_dict())
    assert np.array_equal(again.groups.ids, st.groups.ids)
    st.undo()
    assert (st.groups.ids == shared).sum() == 0
    st.remove_group(0)
    assert st.groups.n_groups == 1 and (st.groups.ids >= 0).sum() == 0
    with pytest.raises(InputError, match="overlaps another"):
        PaintedGroups.from_json([{"name": "a", "rigid": True, "indices": [0, 1]},
                                 {"name": "b", "rigid": True, "indices": [1]}], 3)


def test_browser_paint_a_part_and_drag(tmp_path):
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
            page.mouse.click(x, y)
            wait_for(lambda: (st.groups.ids >= 0).any(), 30, "the click to paint")
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
        served = app.served_vertices()
        assert np.abs(served[tip.vertices] - st.vertices[tip.vertices]).max() < 1e-4
        assert _stretch(st.mesh, st.vertices, part) < 1e-9  # the part moved rigidly
        assert np.abs(st.vertices[part] - st.mesh.vertices[part]).max() > 0.05  # it moved
        other = np.flatnonzero((st.mesh.vertices[:, 0] > 5.0) & (st.mesh.vertices[:, 0] < 6.5))
        assert _stretch(st.mesh, st.vertices, other) > 1e-4  # the rest bends
    finally:
        app.stop()
