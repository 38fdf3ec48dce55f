"""The core install is MIT-clean: no GPL, AGPL or LGPL licence anywhere in the tree of
packages that ``pip install arapkit`` brings, read from the installed metadata.

The tree starts at arapkit's ``Requires-Dist`` lines without an ``extra ==`` marker and
follows every package's own requirements that apply here (no extra; platform markers
evaluated), through :mod:`importlib.metadata`. A licence is read from
``License-Expression`` (PEP 639, authoritative when present), else the ``License ::``
classifiers, else the ``License`` field; a package whose licence cannot be read fails the
test unless :data:`UNREADABLE_OK` names it with the reason.
"""

from __future__ import annotations

import email.message
import json
import re
from importlib import metadata
from pathlib import Path

import pytest

requirements = pytest.importorskip("packaging.requirements")
utils = pytest.importorskip("packaging.utils")

ROOT = Path(__file__).resolve().parents[1]

#: packages whose metadata states no licence, each with where its licence was checked by
#: hand. Empty today: every package of the core's tree states its licence.
UNREADABLE_OK: dict[str, str] = {}

COPYLEFT = re.compile(r"\b(A|L)?GPL|GNU (LESSER |LIBRARY |AFFERO )?GENERAL PUBLIC", re.I)


def copyleft(expression: str | None, classifiers: list[str], text: str | None) -> str | None:
    """The copyleft licence that metadata states, "" when it states none it can be read
    from, or None when the licence is permissive.

    Examples
    --------
    >>> copyleft("GPL-3.0-or-later", [], None), copyleft("MIT OR GPL-2.0", [], None)
    ('GPL-3.0-or-later', None)
    """
    if expression:
        # an SPDX expression is copyleft when every alternative of an OR is
        alternatives = re.split(r"\s+OR\s+", expression.strip("() "))
        return expression if all(COPYLEFT.search(a) for a in alternatives) else None
    named = [c for c in classifiers if c.startswith("License ::")
             and c.strip() != "License :: OSI Approved"]
    if named:
        return next((c for c in named if COPYLEFT.search(c)), None)
    text = (text or "").strip()
    if not text or text.upper() == "UNKNOWN":
        return ""
    # a short field names the licence, a long one is its text: its title says which
    return text if COPYLEFT.search(text[:300]) else None


def core_requirements() -> tuple[list[str], str]:
    """arapkit's requirement lines and where they were read.

    The installed arapkit's metadata, unless it is an editable install of another
    checkout (a worktree running its tests with ``PYTHONPATH=src`` against a shared
    environment): then this checkout's own ``pyproject.toml`` declares the core.
    """
    try:
        dist = metadata.distribution("arapkit")
        url = json.loads(dist.read_text("direct_url.json") or "{}").get("url", "")
    except metadata.PackageNotFoundError:
        dist, url = None, ""
    if dist is not None and (not url or url == ROOT.as_uri()):
        return list(dist.requires or []), "the installed arapkit's Requires-Dist"
    tomllib = pytest.importorskip("tomllib")  # Python 3.11+
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    where = f"{ROOT / 'pyproject.toml'} (arapkit installed from {url or 'nowhere'})"
    return list(project["dependencies"]), where


def applies(line: str) -> requirements.Requirement | None:
    """The requirement of ``line`` when it applies to the core here (no extra)."""
    req = requirements.Requirement(line)
    if req.marker is not None and not req.marker.evaluate({"extra": ""}):
        return None
    return req


def licence_problems(lines: list[str]) -> tuple[list[str], dict[str, str]]:
    """Every problem in the tree of ``lines``, and the licence read for each package."""
    problems, seen = [], {}
    queue = [(req, "arapkit") for req in filter(None, map(applies, lines))]
    while queue:
        req, parent = queue.pop(0)
        name = utils.canonicalize_name(req.name)
        if name in seen:
            continue
        try:
            dist = metadata.distribution(req.name)
        except metadata.PackageNotFoundError:
            seen[name] = "not installed"
            problems.append(f"{req.name} (required by {parent}) is not installed: its "
                            "licence cannot be read")
            continue
        meta = dist.metadata
        expression = meta.get("License-Expression")
        classifiers = meta.get_all("Classifier") or []
        found = copyleft(expression, classifiers, meta.get("License"))
        seen[name] = (expression or "; ".join(c for c in classifiers if "License" in c)
                      or (meta.get("License") or "")[:60])
        if found is None:
            pass
        elif found == "" and name not in UNREADABLE_OK:
            problems.append(f"{req.name} (required by {parent}): no licence in its metadata")
        elif found:
            problems.append(f"{req.name} (required by {parent}) is {found[:80]!r}")
        queue += [(r, req.name) for r in filter(None, map(applies, dist.requires or []))]
    return problems, seen


def test_core_dependency_tree_has_no_gpl_agpl_or_lgpl_licence():
    lines, source = core_requirements()
    problems, seen = licence_problems(lines)
    assert {"numpy", "scipy", "numba", "llvmlite", "trimesh"} <= set(seen), seen
    assert not problems, (
        f"core dependencies from {source}: " + "; ".join(problems)
        + " (a copyleft package belongs behind an opt-in extra with its licence stated; "
        "if pyproject.toml no longer lists it, reinstall: pip install -e .)"
    )


@pytest.mark.parametrize(("expression", "classifiers", "text", "expected"), [
    ("GPL-3.0-or-later", [], None, "GPL-3.0-or-later"),
    ("LGPL-2.1-only", [], None, "LGPL-2.1-only"),
    ("AGPL-3.0-only", [], None, "AGPL-3.0-only"),
    ("MIT OR GPL-2.0-or-later", [], None, None),
    ("BSD-3-Clause AND MIT", ["License :: OSI Approved :: GNU General Public License v3"],
     None, None),
    (None, ["License :: OSI Approved :: GNU General Public License v3 or later (GPLv3+)"],
     None, "License :: OSI Approved :: GNU General Public License v3 or later (GPLv3+)"),
    (None, ["License :: OSI Approved :: GNU Lesser General Public License v3 (LGPLv3)"],
     None, "License :: OSI Approved :: GNU Lesser General Public License v3 (LGPLv3)"),
    (None, ["License :: OSI Approved :: BSD License"], "see GPL notes of bundled libs", None),
    (None, [], "GNU GENERAL PUBLIC LICENSE\n Version 3, 29 June 2007 ...",
     "GNU GENERAL PUBLIC LICENSE\n Version 3, 29 June 2007 ..."),
    (None, [], "MIT", None),
    (None, ["License :: OSI Approved"], "UNKNOWN", ""),
    (None, [], None, ""),
])
def test_licence_reading(expression, classifiers, text, expected):
    assert copyleft(expression, classifiers, text) == expected


def test_a_gpl_package_in_the_tree_is_named(monkeypatch):
    """plyfile (GPL-3.0-or-later) as a core dependency fails the check, by name."""
    real = metadata.distribution

    class Fake:
        metadata = email.message.Message()
        metadata["License-Expression"] = "GPL-3.0-or-later"
        requires = ["numpy>=2.0"]

    monkeypatch.setattr(metadata, "distribution",
                        lambda name: Fake() if name == "plyfile" else real(name))
    problems, _ = licence_problems(["numpy>=1.24", "plyfile>=1.0", "pytest; extra == 'test'"])
    assert problems == ["plyfile (required by arapkit) is 'GPL-3.0-or-later'"]
