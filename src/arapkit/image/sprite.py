"""A puppet sprite arapkit draws itself: the picture of the examples, tests and benchmarks.

A gingerbread figure (head, body, two arms, two legs) with a hole for each eye, buttons and
a scarf, anti-aliased (4 x 4 samples a pixel), transparent around it; its pins are put on
the hands, feet, head and belly (:func:`puppet_pins`).

Examples
--------
>>> img = puppet_sprite(128)
>>> img.shape, int(img[64, 64, 3]), int(img[2, 2, 3])
((128, 128, 4), 255, 0)
"""

from __future__ import annotations

import numpy as np

__all__ = ["puppet_pins", "puppet_sprite"]

_BODY = (176, 108, 60)
_SCARF = (200, 40, 50)
_BUTTON = (250, 240, 220)


def _shapes(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Coverage of the figure, the scarf and the buttons on unit coordinates."""
    head = np.hypot(x - 0.5, y - 0.2) < 0.13
    body = ((x - 0.5) / 0.17) ** 2 + ((y - 0.5) / 0.21) ** 2 < 1
    arms = (np.abs(y - 0.4 - 0.25 * np.abs(x - 0.5) ** 1.5) < 0.055) & (np.abs(x - 0.5) < 0.44)
    hands = (np.hypot(x - 0.07, y - 0.45) < 0.065) | (np.hypot(x - 0.93, y - 0.45) < 0.065)
    legs = ((np.abs(x - 0.5 - 0.45 * (y - 0.62)) < 0.065) | (np.abs(x - 0.5 + 0.45 * (y - 0.62))
                                                           < 0.065)) & (y > 0.6) & (y < 0.9)
    feet = (np.hypot(x - 0.36, y - 0.9) < 0.07) | (np.hypot(x - 0.64, y - 0.9) < 0.07)
    eyes = (np.hypot(x - 0.45, y - 0.18) < 0.025) | (np.hypot(x - 0.55, y - 0.18) < 0.025)
    figure = (head | body | arms | hands | legs | feet) & ~eyes
    scarf = figure & (np.abs(y - 0.32) < 0.03) & (np.abs(x - 0.5) < 0.16)
    buttons = figure & ((np.hypot(x - 0.5, y - 0.45) < 0.025)
                        | (np.hypot(x - 0.5, y - 0.55) < 0.025))
    return figure, scarf, buttons


def puppet_sprite(size: int = 256) -> np.ndarray:
    """The figure on a transparent ``size x size`` RGBA canvas (uint8, straight alpha)."""
    s = 4
    n = size * s
    c = (np.arange(n) + 0.5) / n
    x, y = np.meshgrid(c, c)
    figure, scarf, buttons = _shapes(x, y)
    rgb = np.zeros((n, n, 3))
    rgb[figure] = _BODY
    rgb[scarf] = _SCARF
    rgb[buttons] = _BUTTON
    # a little shading, so that a warp shows in the picture as well as in the outline
    rgb *= (0.85 + 0.15 * np.cos(6 * np.pi * x) * np.cos(6 * np.pi * y))[..., None]
    a = figure.astype(np.float64)
    prem = rgb * a[..., None]

    def box(v: np.ndarray) -> np.ndarray:  # the mean of each pixel's s x s samples
        return v.reshape(size, s, size, s, *v.shape[2:]).mean(axis=(1, 3))

    A = box(a)
    C = box(prem) / np.maximum(A, 1e-12)[..., None]
    out = np.concatenate([C, 255.0 * A[..., None]], axis=-1)
    out[A == 0] = 0
    return np.clip(np.rint(out), 0, 255).astype(np.uint8)


def puppet_pins(size: int = 256) -> np.ndarray:
    """``(6, 2)`` pixel places of the figure's pins: hands, feet, head, belly.

    Examples
    --------
    >>> puppet_pins(100).round(1).tolist()[0]
    [7.0, 45.0]
    """
    return np.array([[0.07, 0.45], [0.93, 0.45], [0.36, 0.9], [0.64, 0.9], [0.5, 0.2],
                     [0.5, 0.5]]) * size
