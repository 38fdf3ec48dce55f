"""The ``arapkit`` command line.

Subcommands live in their own modules, each exposing ``add_parser(subparsers)`` and
``run(args) -> int``; :data:`COMMANDS` lists them.

Exit status: 0 success, 2 bad input (one line on stderr, ``arapkit: error: ...``),
1 internal error (with a traceback, since it is a bug), 130 interrupted.

Examples
--------
>>> from arapkit.cli import main
>>> main(["--version"])  # doctest: +SKIP
arapkit 0.1.0
0
"""

from __future__ import annotations

import argparse
import difflib
import importlib
import os
import sys
import traceback
from collections.abc import Sequence

from arapkit import __version__
from arapkit.errors import InputError
from arapkit.workflows.jobs import error_message

__all__ = ["COMMANDS", "build_parser", "main"]

#: (subcommand, module): each module exposes ``add_parser(subparsers)`` and ``run(args)``.
COMMANDS: list[tuple[str, str]] = [
    ("deform", "arapkit.cli.deform"),
    ("compare", "arapkit.cli.compare"),
    ("demo", "arapkit.cli.demo"),
    ("info", "arapkit.cli.info"),
    ("learn", "arapkit.cli.learn"),
    ("edit", "arapkit.cli.edit"),
    ("batch", "arapkit.cli.batch"),
    ("simulate", "arapkit.cli.simulate"),
    ("warp", "arapkit.cli.warp"),
    ("fit", "arapkit.cli.fit"),
]

_EPILOG = """examples (from a clone of the repository, which ships examples/):
  arapkit demo --out demo-output
  arapkit info examples/cactus.off
  arapkit deform examples/cactus.off --handles examples/cactus.json --dry-run --figure groups.png
  arapkit deform examples/cactus.off -H examples/cactus.json -r 4 -o bent.ply --figure bent.png
  arapkit deform examples/bar.off --handles examples/bar.sel --transform examples/bar.def -o out.off
"""


#: options people bring from other tools, and this command line's name for them
_ALIASES = {"--method": "--energy", "--iterations": "--max-iter", "--iters": "--max-iter",
            "--out": "--output", "--ring": "--rings", "--weight": "--weights"}


class _Parser(argparse.ArgumentParser):
    """argparse with one-line usage errors, like every other error of the command line."""

    def error(self, message: str):  # type: ignore[override]
        # the top level's own name already opens the line: "arapkit: error: ..."
        where = "" if self.prog == "arapkit" else f"{self.prog}: "
        self.exit(2, f"arapkit: error: {where}{' '.join(message.split())} "
                     f"(see {self.prog} --help)\n")

    def unrecognized(self, extra: list[str]) -> None:
        """Refuse arguments this (sub)command does not take, naming the likely intended one.

        Examples
        --------
        >>> build_parser().commands["deform"].suggestion("--method")
        '--energy'
        >>> build_parser().commands["deform"].suggestion("--max-iters=5")
        '--max-iter'
        """
        hints = [(o.split("=")[0], self.suggestion(o)) for o in extra if o.startswith("--")]
        hints = [(o, h) for o, h in hints if h]
        hint = ("" if not hints else f"; did you mean {hints[0][1]}?" if len(hints) == 1
                else "; did you mean " + ", ".join(f"{h} for {o}" for o, h in hints) + "?")
        self.error(f"unrecognized arguments: {' '.join(extra)}{hint}")

    def suggestion(self, option: str) -> str | None:
        """The option of this parser that ``option`` most likely meant, or None."""
        name = option.split("=")[0]
        known = [o for o in self._option_string_actions if o.startswith("--")]
        if _ALIASES.get(name) in known:
            return _ALIASES[name]
        close = difflib.get_close_matches(name, known, n=1, cutoff=0.75)
        return close[0] if close else None


def build_parser() -> argparse.ArgumentParser:
    """The top-level parser with one subparser per available command.

    Examples
    --------
    >>> p = build_parser()
    >>> p.parse_args(["info", "x.off"]).command
    'info'
    """
    parser = _Parser(
        prog="arapkit",
        description="As-rigid-as-possible surface deformation with controllable rigidity "
        "(r-ring ARAP, Chen et al. 2017).",
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"arapkit {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    #: each subcommand's own parser, which reports arguments it does not take
    parser.commands = {}
    for name, module in COMMANDS:
        mod = importlib.import_module(module)
        sp = mod.add_parser(sub)
        sp.set_defaults(_run=mod.run, command=name)
        parser.commands[name] = sp
    return parser


def _fail(message: str, code: int) -> int:
    # one line: a message may carry file content with newlines, which would break that
    print(f"arapkit: error: {' '.join(str(message).split())}", file=sys.stderr)
    return code


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status.

    Parameters
    ----------
    argv : list of str, optional
        Arguments without the program name (default ``sys.argv[1:]``).

    Examples
    --------
    >>> main(["info", "/no/such/mesh.off"])  # doctest: +SKIP
    arapkit: error: /no/such/mesh.off: file not found
    2
    """
    parser = build_parser()
    try:
        args, extra = parser.parse_known_args(argv)
        if extra:  # argparse would blame the top level; the subcommand knows its options
            parser.commands.get(getattr(args, "command", None), parser).unrecognized(extra)
    except SystemExit as e:  # argparse: --help/--version (0) or a usage error (2)
        return int(e.code or 0)
    # the report records the command as typed, also when main() is called in-process
    args._argv = list(sys.argv[1:] if argv is None else argv)
    if getattr(args, "_run", None) is None:
        parser.print_help(sys.stderr)
        return 2
    try:
        return int(args._run(args) or 0)
    except (InputError, FileNotFoundError, IsADirectoryError, PermissionError) as e:
        return _fail(error_message(e), 2)
    except KeyboardInterrupt:
        print("arapkit: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # stdout closed early (e.g. piped into head): not an error worth a traceback;
        # point stdout at /dev/null so the interpreter's final flush does not complain
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 0
    except Exception as e:
        traceback.print_exc()
        return _fail(error_message(e), 1)
