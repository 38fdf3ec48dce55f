"""Every example in README.md runs as written, so the README cannot rot.

What is run (keep to these rules when you add an example):

1. Every ```python block runs, in README order, in one shared namespace (as one interpreter
   session), with the working directory set to a scratch folder holding a copy of
   ``examples/`` and nothing beside it, as a fresh clone has. Relative paths such as
   ``examples/cactus.off`` therefore work, ``../shared/data`` (the project's test data,
   which a clone lacks) does not, and outputs land in the scratch folder, never in the
   repository.
2. In every other fenced block, except ```text and ```json, each line that starts with
   ``arapkit `` is run by bash in the same scratch folder, in README order (a line may use
   an earlier line's output), with ``arapkit`` being this checkout's command line. It must
   exit with status 0. Write usage synopses with placeholders (MESH, FILE ...) in ```text
   blocks.
3. ``arapkit edit`` starts a server that never exits: its lines are parsed by the real
   parser and the editor state is built (mesh, rings and handles loaded and checked), but
   nothing is served.
4. Markers, in a comment: ``# needs arapkit[torch]`` skips it when torch is not installed
   (CI installs it); ``# not run`` on a line never runs it (say why after it). No example
   may name ``../shared``: a reader's clone has nothing beside it.
   A line that pipes into a program that is not installed (``jq``) is skipped.
5. ``<!-- same-as: PATH -->`` right before a ```json block: the block must equal the
   repository file PATH, compared as parsed JSON.
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
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
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
    """('python' | 'shell', README line, code) in README order, per the module's rules."""
    out = []
    for b in fenced_blocks(text):
        if b.lang == "python":
            out.append(("python", b.line, b.text))
        elif b.lang not in ("text", "json"):
            for k, line in enumerate(b.lines):
                if line.strip().startswith("arapkit "):
                    out.append(("shell", b.line + k, line.strip()))
    return out


@pytest.fixture(scope="module")
def scratch(tmp_path_factory):
    """A folder with a copy of examples/ and nothing beside it, and an ``arapkit`` on PATH."""
    work = tmp_path_factory.mktemp("readme") / "repo"
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
    found = examples(README.read_text())
    kinds = [k for k, _, _ in found]
    # the README has library examples and command-line examples; if the parser found
    # none, the test below would pass vacuously
    assert kinds.count("python") >= 3 and kinds.count("shell") >= 10
    assert not any("armadillo" in code for _, _, code in found)
    # the project's test data is not in a clone: an example using it fails for a reader
    # (and is not skipped here: the scratch folder has nothing beside it either)
    at_fault = [f"README.md:{line}" for _, line, code in found if "../shared" in code]
    assert not at_fault, f"examples reading ../shared: {at_fault}"


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


def test_readme_examples_run(scratch, monkeypatch):
    work, bin_dir = scratch
    monkeypatch.chdir(work)
    before = _repo_files()
    namespace: dict = {"__name__": "__readme__"}
    ran, skipped = 0, []
    for kind, line, code in examples(README.read_text()):
        where = f"README.md:{line}"
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
    assert ran >= 10
    # outputs went to the scratch folder, not into the repository
    assert _repo_files() == before
    if skipped:
        print("skipped:\n  " + "\n  ".join(skipped))


def test_json_blocks_match_their_files():
    blocks = [b for b in fenced_blocks(README.read_text()) if b.same_as]
    assert blocks, "README should show at least one shipped handle file"
    for b in blocks:
        assert json.loads(b.text) == json.loads((ROOT / b.same_as).read_text()), (
            f"README.md:{b.line} differs from {b.same_as}"
        )


def test_shipped_handle_files_resolve():
    """Every handle file in examples/ selects something on the mesh its comment names."""
    from arapkit import load_handles, load_mesh

    files = sorted((ROOT / "examples").rglob("*.json"))
    assert len(files) >= 5
    for f in files:
        comment = json.loads(f.read_text()).get("comment", "")
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
