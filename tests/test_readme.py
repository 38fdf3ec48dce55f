"""Every example in README.md and in the docs pages of :data:`PAGES` runs as written.

So the README and the user pages cannot rot. Each page is run on its own, as a reader who
opens only that page would run it (keep to these rules when you add an example):

1. Every ```python block of a page runs, in page order, in one namespace per page (as one
   interpreter session), with the working directory set to a scratch folder of its own
   holding a copy of ``examples/`` and nothing beside it, as a fresh clone has. Relative
   paths such as ``examples/cactus.off`` therefore work, ``../shared/data`` (the project's
   test data, which a clone lacks) does not, and outputs land in the scratch folder, never
   in the repository. A block indented under a list item is dedented first.
2. In every other fenced block, except ```text and ```json, each line that starts with
   ``arapkit `` is run by bash in the same scratch folder, in page order (a line may use
   an earlier line of the same page's output), with ``arapkit`` being this checkout's
   command line. It must exit with status 0. Write usage synopses with placeholders
   (MESH, FILE ...) in ```text blocks.
3. ``arapkit edit`` starts a server that never exits: its lines are parsed by the real
   parser and the editor state is built (mesh, rings and handles loaded and checked), but
   nothing is served.
4. Markers, in a comment: ``# needs arapkit[torch]`` skips it when torch is not installed
   (CI installs it); ``# not run`` on a line never runs it (say why after it). No example
   may name ``../shared``: a reader's clone has nothing beside it.
   A line that pipes into a program that is not installed (``jq``) is skipped.
5. ``<!-- same-as: PATH -->`` right before a ```json block: the block must equal the
   repository file PATH, compared as parsed JSON.
6. A docs page with blocks these rules would run is in :data:`PAGES`, or in
   :data:`NOT_RUN_PAGES` with the reason its examples cannot run in a clone (placeholders
   for the reader's own files, a cluster's address). A new page with examples must choose.
"""

from __future__ import annotations

import importlib.util
import json
import os
import re
import shlex
import shutil
import subprocess
import sys
import textwrap
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
#: the pages whose examples are run, each on its own (the README first)
PAGES = ("README.md", "docs/solver.md", "docs/handles.md", "docs/cli.md", "docs/learning.md",
         "docs/editor.md", "docs/torch.md", "docs/volumetric.md", "docs/interactive.md",
         "docs/dynamics.md", "docs/smooth-arap.md", "docs/2d.md",
         "docs/groups.md", "docs/fit.md", "docs/clouds.md")
#: docs pages with blocks that look runnable but are not, and why
NOT_RUN_PAGES = {
    "docs/api-contract.md": "a signature sheet (names and defaults, not a program)",
    "docs/batch.md": "job files, meshes and cluster addresses of the reader's own",
    "docs/io.md": "the reader's own textured.obj and handles",
    "docs/methods.md": "an edge graph of the reader's own, and a usage synopsis",
}
#: optional extras: a block or line with the marker skips when the module is missing
NEEDS_EXTRA = {"# needs arapkit[torch]": ("torch", "torch"),
               "# needs arapkit[volume]": ("pytetwild", "volume")}
NOT_RUN = "# not run"
_FENCE = re.compile(r"^(\s*)```(\S*)\s*$")
_SAME_AS = re.compile(r"<!--\s*same-as:\s*(\S+)\s*-->")


@dataclass
class Block:
    lang: str
    line: int  # 1-based line number of the first line inside the fence
    lines: list[str]
    same_as: str | None = None

    @property
    def text(self) -> str:
        return "\n".join(self.lines) + "\n"


def fenced_blocks(text: str) -> list[Block]:
    """Fenced code blocks of a Markdown text, with their language and position."""
    blocks, current, previous = [], None, ""
    for number, line in enumerate(text.splitlines(), start=1):
        m = _FENCE.match(line)
        if current is None and m:
            same = _SAME_AS.search(previous)
            current = Block(m.group(2).lower(), number + 1, [], same.group(1) if same else None)
        elif current is not None and m and not m.group(2):
            blocks.append(current)
            current = None
        elif current is not None:
            current.lines.append(line)
        if line.strip():
            previous = line
    return blocks


def examples(text: str) -> list[tuple[str, int, str]]:
    """('python' | 'shell', page line, code) in page order, per the module's rules."""
    out = []
    for b in fenced_blocks(text):
        if b.lang == "python":
            out.append(("python", b.line, textwrap.dedent(b.text)))
        elif b.lang not in ("text", "json"):
            for k, line in enumerate(b.lines):
                if line.strip().startswith("arapkit "):
                    out.append(("shell", b.line + k, line.strip()))
    return out


@pytest.fixture
def scratch(tmp_path_factory):
    """A folder with a copy of examples/ and nothing beside it, and an ``arapkit`` on PATH."""
    work = tmp_path_factory.mktemp("page") / "repo"
    shutil.copytree(ROOT / "examples", work / "examples")
    assert [p.name for p in work.parent.iterdir()] == ["repo"]
    bin_dir = tmp_path_factory.mktemp("bin")  # elsewhere: ../bin would be beside the copy
    shim = bin_dir / "arapkit"
    shim.write_text(f'#!/bin/sh\nexec "{sys.executable}" -m arapkit.cli "$@"\n')
    shim.chmod(0o755)
    return work, bin_dir


def _skip_reason(code: str) -> str | None:
    for marker, (module, extra) in NEEDS_EXTRA.items():
        if marker in code and importlib.util.find_spec(module) is None:
            return f"needs {module} (pip install 'arapkit[{extra}]'), which is not installed"
    if NOT_RUN in code:
        return "marked '# not run'"
    if "|" in code:
        for part in code.split("|")[1:]:
            words = shlex.split(part, comments=True)
            if words and shutil.which(words[0]) is None:
                return f"pipes into {words[0]}, which is not installed"
    return None


def _run_edit(line: str) -> None:
    from arapkit.cli import build_parser
    from arapkit.cli.edit import build_state

    argv = shlex.split(line, comments=True)[1:]
    args = build_parser().parse_args(argv)
    build_state(args)


def _run_shell(line: str, work: Path, bin_dir: Path) -> None:
    env = dict(os.environ)
    env["PATH"] = f"{bin_dir}{os.pathsep}{env.get('PATH', '')}"
    env["PYTHONPATH"] = os.pathsep.join(
        p for p in (str(ROOT / "src"), env.get("PYTHONPATH", "")) if p
    )
    proc = subprocess.run(["bash", "-o", "pipefail", "-c", line], cwd=work, env=env,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, (
        f"exit {proc.returncode}\nstdout: {proc.stdout[-2000:]}\nstderr: {proc.stderr[-2000:]}"
    )


def _repo_files() -> set[str]:
    """The repository's top-level files and everything in examples/ and docs/."""
    top = {p.name for p in ROOT.iterdir() if p.is_file()}
    for sub in ("examples", "docs"):
        top |= {str(p.relative_to(ROOT)) for p in (ROOT / sub).rglob("*")
                if p.is_file() and "__pycache__" not in p.parts}
    return top


def test_rules_find_the_examples():
    found = {page: examples((ROOT / page).read_text()) for page in PAGES}
    kinds = [k for page in PAGES for k, _, _ in found[page]]
    # the pages hold library and command-line examples; if the parser found none, the
    # test below would pass vacuously. The README's front door has one of each.
    assert kinds.count("python") >= 8 and kinds.count("shell") >= 15
    assert {k for k, _, _ in found["README.md"]} == {"python", "shell"}
    assert all(found[page] for page in PAGES), "a page in PAGES with no example"
    everything = [(page, line, code) for page in PAGES for _, line, code in found[page]]
    assert not any("armadillo" in code for _, _, code in everything)
    # the project's test data is not in a clone: an example using it fails for a reader
    # (and is not skipped here: the scratch folder has nothing beside it either)
    at_fault = [f"{page}:{line}" for page, line, code in everything if "../shared" in code]
    assert not at_fault, f"examples reading ../shared: {at_fault}"


def test_every_page_with_examples_is_run_or_says_why_not():
    pages = {str(p.relative_to(ROOT)) for p in (ROOT / "docs").rglob("*.md")}
    with_examples = {p for p in pages if examples((ROOT / p).read_text())}
    unlisted = with_examples - set(PAGES) - set(NOT_RUN_PAGES)
    assert not unlisted, f"pages with examples that nothing runs: {sorted(unlisted)}"
    assert set(NOT_RUN_PAGES) <= with_examples, "a page in NOT_RUN_PAGES has no examples"
    assert all((ROOT / p).is_file() for p in PAGES)


def test_rules_on_a_small_text():
    text = (
        "```text\narapkit deform MESH -o OUT\n```\n"
        "```sh\nmake demo\narapkit info a.off   # comment\n```\n"
        "<!-- same-as: x.json -->\n```json\n[]\n```\n"
        "```python\nx = 1\n```\n"
        "```\narapkit demo\n```\n"
    )
    assert examples(text) == [
        ("shell", 6, "arapkit info a.off   # comment"),
        ("python", 13, "x = 1\n"),
        ("shell", 16, "arapkit demo"),
    ]
    assert [b.same_as for b in fenced_blocks(text)] == [None, None, "x.json", None, None]


@pytest.mark.parametrize("page", PAGES)
def test_page_examples_run(page, scratch, monkeypatch):
    work, bin_dir = scratch
    monkeypatch.chdir(work)
    before = _repo_files()
    namespace: dict = {"__name__": "__readme__"}
    ran, skipped = 0, []
    for kind, line, code in examples((ROOT / page).read_text()):
        where = f"{page}:{line}"
        reason = _skip_reason(code)
        if reason:
            skipped.append(f"{where}: {reason}")
            continue
        try:
            if kind == "python":
                exec(compile(code, where, "exec"), namespace)  # noqa: S102 - the README's own code
            elif code.split()[:2] == ["arapkit", "edit"]:
                _run_edit(code)
            else:
                _run_shell(code, work, bin_dir)
        except Exception as e:  # report which example broke, then the error
            raise AssertionError(f"{where}: {code.strip()[:200]!r} failed: {e}") from e
        ran += 1
    # every page runs something unless its examples need a missing extra (a page may also
    # hold '# not run' signatures beside them)
    assert ran >= 1 or (any("needs " in s for s in skipped)
                        and all("needs " in s or "not run" in s for s in skipped))
    # outputs went to the scratch folder, not into the repository
    assert _repo_files() == before
    if skipped:
        print("skipped:\n  " + "\n  ".join(skipped))


def test_json_blocks_match_their_files():
    blocks = [(page, b) for page in PAGES for b in fenced_blocks((ROOT / page).read_text())
              if b.same_as]
    assert blocks, "the pages should show at least one shipped handle file"
    for page, b in blocks:
        assert json.loads(b.text) == json.loads((ROOT / b.same_as).read_text()), (
            f"{page}:{b.line} differs from {b.same_as}"
        )


def test_shipped_handle_files_resolve():
    """Every handle file in examples/ selects something on the mesh its comment names."""
    from arapkit import load_handles, load_mesh

    # landmark files (arapkit fit) are not handle files
    files = sorted(f for f in (ROOT / "examples").rglob("*.json")
                   if not f.name.endswith("-landmarks.json"))
    assert len(files) >= 5
    for f in files:
        data = json.loads(f.read_text())
        if (isinstance(data, list) and data and "at" in data[0]) or "keyframes" in data:
            continue  # the pins and keyframes of arapkit warp (docs/2d.md), not handles
        comment = data.get("comment", "")
        meshes = re.findall(r"examples/(\w+\.off)", comment)
        assert meshes, f"{f.name}: its comment should name the mesh it is for"
        mesh = load_mesh(ROOT / "examples" / meshes[0])
        if f.name.endswith("-groups.json"):  # vertex groups (docs/groups.md), not handles
            from arapkit import load_groups

            g = load_groups(f, mesh)
            assert g.n_groups >= 1 and (g.sizes > 0).all()
            continue
        hs = load_handles(f, mesh.vertices)
        assert len(hs.groups) >= 2 and all(len(g.indices) for g in hs.groups)
