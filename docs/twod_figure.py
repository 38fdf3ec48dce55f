"""Make ``docs/2d-puppet.png``: the example sprite before and after ``arapkit warp`` with the
example pins (run from the repository root; needs ``arapkit[image]``).

Left: ``examples/puppet.png`` with its pins (orange); right: the warped picture with the
pins where they were dragged (the raised arm's pin also turned 30 degrees).

Examples
--------
::

    python docs/twod_figure.py
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from arapkit.image.pins import load_pins
from arapkit.image.warp import save_image, warp_image

ROOT = Path(__file__).resolve().parents[1]


def dots(img: np.ndarray, points: np.ndarray, r: float = 4.0) -> np.ndarray:
    """``img`` on white with an orange disc at each point."""
    a = img[..., 3:4] / 255.0
    out = (img[..., :3] * a + 255.0 * (1 - a)).astype(np.uint8)
    yy, xx = np.mgrid[:img.shape[0], :img.shape[1]]
    for x, y in points:
        out[np.hypot(xx + 0.5 - x, yy + 0.5 - y) <= r] = (255, 140, 0)
    return out


def main() -> None:
    from PIL import Image

    src = np.asarray(Image.open(ROOT / "examples" / "puppet.png").convert("RGBA"))
    pins = load_pins(ROOT / "examples" / "puppet-pins.json")
    res = warp_image(src, pins)
    gap = np.full((src.shape[0], 16, 3), 255, np.uint8)
    both = np.concatenate([dots(src, pins.at), gap, dots(res.image, pins.to)], axis=1)
    rgba = np.concatenate([both, np.full(both.shape[:2] + (1,), 255, np.uint8)], axis=2)
    save_image(ROOT / "docs" / "2d-puppet.png", rgba)
    print(f"wrote docs/2d-puppet.png ({res.folds} folds)")


if __name__ == "__main__":
    main()
