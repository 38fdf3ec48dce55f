"""Screenshots of the editor's first five minutes: docs/editor-1-start.png ... -5-energy.png.

Run from the repository root with headless Chromium and Playwright installed (as for
tests/test_editor_browser.py): ``PYTHONPATH=src python docs/editor_screenshots.py``.
It walks the "first five minutes" of ``docs/editor.md`` on examples/cactus.off with the
browser tests' helpers and saves each step at 3/4 size in 128 colours (about 50 KB each).
"""

from __future__ import annotations

import io
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from PIL import Image

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))  # the tests' helpers

from playwright.sync_api import sync_playwright  # noqa: E402
from test_editor_browser import _browser_page, example_app, wait_for  # noqa: E402
from test_editor_first_minutes import (  # noqa: E402
    _click_button,
    _pixels,
    _pot_and_top,
    _shift_drag,
)

OUT = Path(__file__).resolve().parent


def shot(page, name: str) -> None:
    time.sleep(1.0)
    img = Image.open(io.BytesIO(page.screenshot())).convert("RGB")
    img = img.resize((img.width * 3 // 4, img.height * 3 // 4), Image.LANCZOS)
    img.quantize(colors=128, method=Image.Quantize.MEDIANCUT).save(
        OUT / f"editor-{name}.png", optimize=True)


def drag_arrow(page, client, app, name: str, pixels: int) -> None:
    """Drag the x arrow of handle ``name``'s gizmo to the right, seen from the front."""
    h = app.state.handle(name)
    g = h.position.copy()
    client.camera.position = tuple(g + np.array([0.0, -0.3, 1.1]) * app.diag)
    client.camera.look_at = tuple(g - np.array([0.0, 0.35, 0.0]) * app.diag)
    time.sleep(1.0)
    x, y = _pixels(page, client, g + 0.85 * app.gizmo_scale(h) * np.array([1.0, 0, 0]))
    page.mouse.move(float(x[0]), float(y[0]))
    page.mouse.down()
    for k in range(1, 21):
        page.mouse.move(float(x[0]) + pixels * k / 20, float(y[0]))
        time.sleep(0.05)
    page.mouse.up()


def main() -> None:
    app = example_app("cactus.off", Path(tempfile.mkdtemp()))
    st = app.state
    try:
        assert app.wait_idle(120)
        with _browser_page(sync_playwright, app) as (page, client):
            time.sleep(1.5)
            close = page.locator(".mantine-Notification-root button")
            if close.count():  # "software WebGL" notice of a headless browser
                close.first.click()
            start = app.server.initial_camera
            wait_for(lambda: np.allclose(client.camera.position, start.position, atol=1e-3)
                     and np.allclose(client.camera.look_at, start.look_at, atol=1e-3), 30,
                     "the page's camera")
            shot(page, "1-start")
            pot, top = _pot_and_top(app)
            xs, ys = _pixels(page, client, st.vertices[pot])
            _shift_drag(page, xs.min() - 15, ys.min() - 5, xs.max() + 15, ys.max() + 15)
            wait_for(lambda: len(st.selection) > 0, 15, "the rectangle")
            shot(page, "2-rectangle")
            _click_button(page, "Make fixed handle from selection")
            wait_for(lambda: len(st.handles) == 1, 15, "the fixed handle")
            x, y = _pixels(page, client, st.vertices[top].mean(axis=0))
            page.mouse.click(float(x[0]), float(y[0]))
            wait_for(lambda: len(st.selection) > 0, 15, "the click")
            _click_button(page, "Make handle from selection")
            wait_for(lambda: len(st.handles) == 2, 15, "the handle")
            assert app.wait_idle(60)
            shot(page, "3-handles")
            drag_arrow(page, client, app, st.handles[-1].name, 120)
            assert app.wait_idle(60)
            shot(page, "4-bend")
            app.dd_view.value = "Energy"
            shot(page, "5-energy")
    finally:
        app.stop()


if __name__ == "__main__":
    main()
