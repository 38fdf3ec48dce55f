"""The editor in 2D (issue 48, part 3): pins, drags, rigidity and exports on the server,
and pin, drag and export in real Chromium (skipped with the reason where Chromium or
Playwright is missing, as tests/test_editor_browser.py)."""

from __future__ import annotations

import json
import time

import numpy as np
import pytest

pytest.importorskip("viser", reason="the editor extra (viser) is not installed")
pytest.importorskip("pythoncdt", reason="the image extra is not installed")

from test_editor_browser import (  # noqa: E402
    CHROMIUM,
    CHROMIUM_ARGS,
    _non_background_fraction,
    free_port,
    wait_for,
)

from arapkit.editor.geometry import CameraView  # noqa: E402
from arapkit.editor.sprite import GIZMO, SpriteEditor  # noqa: E402
from arapkit.image.sprite import puppet_pins, puppet_sprite  # noqa: E402
from arapkit.mesh.shapes2d import strip  # noqa: E402


def test_server_pins_drag_turn_paint_export(tmp_path):
    ed = SpriteEditor(puppet_sprite(200), port=free_port(), export_dir=tmp_path)
    try:
        at = puppet_pins(200)
        for p in at:
            ed.add_pin(p)
        assert len(ed.pins) == len(at)
        before = ed.picture()
        ed.move_pin(0, at[0] + [25.0, -50.0], angle=0.4)
        assert np.abs(ed.vertices[ed.pins[0]] - (at[0] + [25.0, -50.0])).max() < 1.5
        assert ed.folds == 0 and np.abs(ed.picture().astype(int) - before).max() > 100
        ed.set_preset("rigid")
        assert (ed.rings == 4).all()
        ed.paint(at[5], 1, 20.0)
        assert 0 < (ed.rings == 1).sum() < ed.mesh.n_vertices
        png, obj, pins = ed.export("png"), ed.export("obj"), ed.export("pins")
        assert png.stat().st_size > 1000 and obj.read_text().count("\nf ") > 100
        saved = json.loads(pins.read_text())
        assert len(saved) == len(at) and saved[0]["angle"] == pytest.approx(
            np.degrees(0.4), abs=1e-3)
        ed.remove_pin()
        assert len(ed.pins) == len(at) - 1
    finally:
        ed.stop()


def test_a_planar_mesh_opens_in_2d(tmp_path):
    ed = SpriteEditor(strip(), port=free_port(), export_dir=tmp_path)
    try:
        ed.add_pin(ed.rest[0])
        ed.add_pin(ed.rest[-1])
        ed.move_pin(1, ed.rest[-1] + [-40.0, -120.0])
        assert ed.folds == 0 and np.abs(ed.vertices - ed.rest).max() > 50
    finally:
        ed.stop()


def test_browser_pin_drag_export(tmp_path):
    if not CHROMIUM.exists():
        pytest.skip("Debian chromium not installed at /usr/bin/chromium")
    sync_api = pytest.importorskip("playwright.sync_api",
                                   reason="playwright for Python is not installed")
    ed = SpriteEditor(puppet_sprite(256), port=free_port(), export_dir=tmp_path)
    try:
        with sync_api.sync_playwright() as p:
            browser = p.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS,
                                        headless=True)
            try:
                page = browser.new_page(viewport={"width": 1200, "height": 800})
                page.goto(ed.url.replace("0.0.0.0", "127.0.0.1"))
                page.wait_for_selector("canvas", timeout=30_000)
                wait_for(lambda: len(ed.server.get_clients()) == 1, 30, "the page")
                client = next(iter(ed.server.get_clients().values()))
                c = np.array([128.0, -128.0, 0.0])
                eye = c + [0.0, 0.0, 300.0]
                client.camera.position = tuple(eye)
                client.camera.look_at = tuple(c)
                wait_for(lambda: np.allclose(client.camera.position, eye, atol=1e-3), 30,
                         "the camera")
                canvas = page.locator("canvas").first
                box = canvas.bounding_box()
                scene = {"x": box["x"], "y": box["y"] + 160, "width": box["width"] - 360,
                         "height": box["height"] - 160}
                wait_for(lambda: _non_background_fraction(page.screenshot(clip=scene))
                         > 0.05, 30, "the picture to be drawn")
                cam = client.camera

                def screen(x, y, z=0.0):
                    view = CameraView(np.asarray(cam.position), np.asarray(cam.wxyz),
                                      float(cam.fov), float(cam.aspect))
                    uv, _ = view.project(np.array([[x, -y, z]]))
                    return box["x"] + uv[0, 0] * box["width"], box["y"] + uv[0, 1] * box["height"]

                # pin: a click on the belly
                page.mouse.click(*screen(128.0, 128.0))
                wait_for(lambda: len(ed.pins) == 1, 30, "the click to pin")
                ed.add_pin(puppet_pins(256)[2])  # a foot held too (from the server)
                v = ed.pins[0]
                start = ed.targets[0].copy()
                before = ed.picture()
                # drag: the gizmo's x arrow near its tip, to the right
                g = ed.targets[0]
                x, y = screen(g[0] + 0.8 * GIZMO * 256, g[1], 1.0)
                page.screenshot(path=str(tmp_path / "before-drag.png"))
                page.mouse.move(x, y)
                page.mouse.down()
                for k in range(1, 11):
                    page.mouse.move(x + 6 * k, y)
                    time.sleep(0.05)
                page.mouse.up()
                wait_for(lambda: ed.targets[0][0] > start[0] + 5, 30, "the drag")
                assert abs(ed.targets[0][1] - start[1]) < 3.0  # along the x arrow only
                wait_for(lambda: np.abs(ed.vertices[v] - ed.targets[0]).max() < 1.0, 30,
                         "the warp to follow")
                assert np.abs(ed.picture().astype(int) - before).max() > 100
                # export from the page's button
                page.get_by_role("button", name="Export PNG").click()
                wait_for(lambda: any(tmp_path.glob("*-warped.png")), 30, "the export")
                page.screenshot(path=str(tmp_path / "after.png"))
            finally:
                browser.close()
    finally:
        ed.stop()
