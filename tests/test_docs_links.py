"""Every relative link of the README and the docs pages leads somewhere.

A section that moves (the README's reference sections went to ``docs/``, the coarse-to-fine
study to ``docs/studies/``) leaves links behind; this finds them. A link is checked when it
is relative (not ``http:``, ``https:``, ``mailto:``): its file must exist in the repository,
and its ``#anchor``, if any, must be a heading of that file, by GitHub's rule for heading
anchors. Links inside fenced code blocks are text, not links, and are not checked.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md")),
         *sorted((ROOT / "examples").glob("*.md"))]
_LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")
_FENCE = re.compile(r"^\s*```")


def slug(heading: str) -> str:
    """GitHub's anchor for a heading: lower case, punctuation dropped, spaces to hyphens.

    >>> slug("Browser editor (issue 5)")
    'browser-editor-issue-5'
    >>> slug("Botsch–Sorkine / CGAL benchmark files (`.sel` + `.def`)")
    'botschsorkine--cgal-benchmark-files-sel--def'
    """
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


def anchors(path: Path) -> set[str]:
    """The heading anchors of a Markdown file (a repeated heading gets -1, -2 ...)."""
    seen: dict[str, int] = {}
    out = set()
    in_code = False
    for line in path.read_text().splitlines():
        if _FENCE.match(line):
            in_code = not in_code
            continue
        m = re.match(r"#{1,6}\s+(.*?)\s*#*\s*$", line)
        if m and not in_code:
            base = slug(m.group(1))
            n = seen.get(base, 0)
            seen[base] = n + 1
            out.add(base if n == 0 else f"{base}-{n}")
    return out


def links(path: Path) -> list[tuple[int, str]]:
    """(line, target) of every relative link outside fenced code blocks."""
    out, in_code = [], False
    for number, line in enumerate(path.read_text().splitlines(), start=1):
        if _FENCE.match(line):
            in_code = not in_code
            continue
        if in_code:
            continue
        for target in _LINK.findall(line):
            if not re.match(r"[a-z]+:", target):
                out.append((number, target))
    return out


def broken(path: Path) -> list[str]:
    """The links of ``path`` whose file or anchor does not exist, as 'file:line: target'."""
    bad = []
    for number, target in links(path):
        file_part, _, anchor = target.partition("#")
        dest = path if not file_part else (path.parent / file_part).resolve()
        where = f"{path.relative_to(ROOT)}:{number}: {target}"
        if not dest.exists():
            bad.append(where)
        elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
            bad.append(where + " (no such heading)")
    return bad


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_resolve(page):
    assert not broken(page)


def test_the_check_finds_a_broken_link(tmp_path, monkeypatch):
    """A moved file and a moved section are both reported (the check can fail)."""
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    (tmp_path / "a.md").write_text("# Title\n\n## Moved away\n")
    page = tmp_path / "b.md"
    page.write_text("[ok](a.md#moved-away) [gone](c.md) [section](a.md#not-here)\n"
                    "```\n[in code](nowhere.md)\n```\n[web](https://example.org)\n")
    assert broken(page) == ["b.md:1: c.md", "b.md:1: a.md#not-here (no such heading)"]


def test_the_readme_lists_every_user_page():
    """The README's contents list links every page of docs/ (a new page gets a line)."""
    readme = (ROOT / "README.md").read_text()
    listed = {t.partition("#")[0] for _, t in links(ROOT / "README.md")}
    pages = {f"docs/{p.name}" for p in (ROOT / "docs").glob("*.md")}
    assert pages <= listed, f"not in the README's contents: {sorted(pages - listed)}"
    assert "docs/studies/interactive-at-scale.md" in readme
