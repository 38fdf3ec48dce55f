"""The layout bar's rules that no linter checks: one concept per module, well under 700 lines.

``lint-imports`` (in ``make test``) keeps imports downward and free of circles; this keeps
every source module of the package under :data:`MAX_LINES`, so a monolith is caught when it
grows, not a release later (``methods/multires.py`` reached 1,373 lines before it was split).
"""

from __future__ import annotations

from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src" / "arapkit"
#: a module at this size holds more than one concept (docs/architecture.md)
MAX_LINES = 700


def _modules() -> list[Path]:
    return sorted(p for p in SRC.rglob("*.py") if "__pycache__" not in p.parts)


def test_the_package_has_modules():
    assert len(_modules()) > 50  # the walk finds the package (a wrong SRC would pass below)


@pytest.mark.parametrize("path", _modules(), ids=lambda p: str(p.relative_to(SRC)))
def test_no_source_module_reaches_700_lines(path):
    lines = path.read_text(encoding="utf-8").count("\n")
    assert lines < MAX_LINES, (
        f"{path.relative_to(SRC)} has {lines} lines: split it by concept "
        "(docs/architecture.md)")
