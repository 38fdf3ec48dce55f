"""Make the 2D examples of ``examples/`` (run from the repository root): the puppet sprite
this project draws itself (:func:`arapkit.image.sprite.puppet_sprite`), so it carries the
project's licence (MIT).

* ``puppet.png``: the figure, 256 x 256, transparent around it (eyes are holes).

The pins files (``puppet-pins.json``, ``puppet-keys.json``) are written by hand.

Examples
--------
::

    python examples/make_sprite.py          # rewrites puppet.png in examples/
    python examples/make_sprite.py /tmp/x   # writes it into /tmp/x instead
"""

from __future__ import annotations

import sys
from pathlib import Path

from arapkit.image.sprite import puppet_sprite
from arapkit.image.warp import save_image

HERE = Path(__file__).resolve().parent

if __name__ == "__main__":
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else HERE
    out.mkdir(parents=True, exist_ok=True)
    save_image(out / "puppet.png", puppet_sprite(256))
    print(f"wrote {out / 'puppet.png'}")
