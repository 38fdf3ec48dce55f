"""Figures: meshes shaded by energy or rigidity, energy curves (needs ``arapkit[plots]``).

The figures live in :mod:`arapkit.plots.figures`; importing this package loads no plotting
library, so ``arapkit.plots.colors`` (shared with the editor) stays light. The figure
functions are reached here lazily, for code written against the old ``arapkit.plots.figures``.
"""

from __future__ import annotations

import importlib
from typing import Any


def __getattr__(name: str) -> Any:
    if name.startswith("__"):
        raise AttributeError(name)
    figures = importlib.import_module(f"{__name__}.figures")
    try:
        return getattr(figures, name)
    except AttributeError:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
