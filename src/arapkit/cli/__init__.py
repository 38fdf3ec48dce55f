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
]

_EPILOG = """examples (from a clone of the repository, which ships examples/):
  arapkit demo --out demo-output
  arapkit info examples/cactus.off
  arapkit deform examples/cactus.off --handles examples/cactus.json --dry-run --figure groups.png
  arapkit deform examples/cactus.off -H examples/cactus.json -r 4 -o bent.ply --figure bent.png
  arapkit deform examples/bar.off --handles examples/bar.sel --transform examples/bar.def -o out.off
"""


class _Parser(argparse.ArgumentParser):
    """argparse with one-line usage errors, like every other error of the command line."""

    def error(self, message: str):  # type: ignore[override]
        self.exit(2, f"arapkit: error: {self.prog}: {' '.join(message.split())} "
                     f"(see {self.prog} --help)\n")


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
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, module in COMMANDS:
        mod = importlib.import_module(module)
        sp = mod.add_parser(sub)
        sp.set_defaults(_run=mod.run, command=name)
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
        args = parser.parse_args(argv)
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
