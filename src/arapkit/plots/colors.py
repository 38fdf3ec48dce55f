"""The colours arapkit uses for rigidity r and for energy, in figures and in the editor.

One map per quantity everywhere, so a picture from ``learn``, ``deform``, ``demo`` and the
editor reads the same: r from 1 (blue, soft) to 6 and above (red, rigid); energy from pale
yellow (low: the shape stays readable, unlike a map that starts at black) to dark red.

Examples
--------
>>> ring_rgb([1, 6, 9]).tolist()
[[45, 85, 230], [220, 35, 35], [220, 35, 35]]
"""

from __future__ import annotations

import numpy as np

__all__ = ["ENERGY_CMAP", "RING_COLORS", "ring_rgb"]

#: r = 1 ... 6; larger r uses the last colour.  Blue (soft) to red (rigid).
RING_COLORS: tuple[tuple[int, int, int], ...] = (
    (45, 85, 230),
    (0, 170, 225),
    (40, 180, 90),
    (235, 200, 40),
    (245, 130, 30),
    (220, 35, 35),
)

#: matplotlib colour map for energies: light at 0, so low-energy regions keep their shading.
ENERGY_CMAP = "YlOrRd"


def ring_rgb(rings) -> np.ndarray:
    """RGB (0..255) of each r: r = 1 ... 6 from :data:`RING_COLORS`, r > 6 as r = 6."""
    r = np.clip(np.asarray(rings, dtype=np.int64), 1, len(RING_COLORS))
    return np.asarray(RING_COLORS, dtype=np.int64)[r - 1]
