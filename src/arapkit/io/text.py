"""Capped text input files read as tokens: the reading rules of ``.sel``, ``.def`` and
rigidity text files.

Examples
--------
>>> import tempfile, pathlib
>>> p = pathlib.Path(tempfile.mkdtemp()) / "r.txt"
>>> _ = p.write_text("# r per vertex\\n1\\n2 # a comment\\n")
>>> int_tokens(p, "value", "rings files")
[1, 2]
"""

from __future__ import annotations

import io
import re
from collections.abc import Iterator
from pathlib import Path

from ..errors import InputError
from ..validate import read_input

__all__ = ["int_tokens", "read_text", "text_tokens"]


_INTEGER = re.compile(r"[+-]?[0-9]+")


def text_tokens(path: Path, what: str) -> Iterator[tuple[int, str]]:
    """(line number, token) for the whitespace-separated tokens of a text file, skipping
    ``#`` comments; lines are read one at a time, so a long file is never split at once.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "a.def"
    >>> _ = p.write_text("1 0  # first row\\n2\\n")
    >>> list(text_tokens(p, ".def files"))
    [(1, '1'), (1, '0'), (2, '2')]
    """
    for number, line in enumerate(io.StringIO(read_text(path, what)), start=1):
        for token in line.split("#", 1)[0].split():
            yield number, token


def int_tokens(path: Path, what: str, kind: str, expected: int | None = None,
               allowed: range | None = None) -> list[int]:
    """The whitespace-separated integers of a text file (Python ints: no size limit).

    A token that is not an integer, or outside ``allowed``, is named with its line.
    With ``expected``, reading stops at the first token beyond that count. ``kind`` names
    the kind of file for the size cap's message.
    """
    out: list[int] = []
    for number, t in text_tokens(path, kind):
        # ASCII digits with one optional sign: "--1" and "²" pass str.isdigit but not int()
        if not _INTEGER.fullmatch(t) or len(t) > 4000:
            shown = t if len(t) <= 40 else t[:37] + "..."
            raise InputError(f"{path}:{number}: {what} {shown!r} is not an integer")
        value = int(t)
        if allowed is not None and value not in allowed:
            shown = t if len(t) <= 40 else t[:37] + "..."
            raise InputError(f"{path}:{number}: {what} {shown} is not one of "
                             f"{', '.join(map(str, allowed))}")
        out.append(value)
        if expected is not None and len(out) > expected:
            raise InputError(f"{path}:{number}: more than {expected} {what}s for a mesh of "
                             f"{expected} vertices")
    return out


def read_text(path: Path, what: str) -> str:
    """A capped text input file (:func:`arapkit.validate.read_input`), decoded.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "a.sel"
    >>> _ = p.write_bytes(b"\\xff\\xfe")
    >>> read_text(p, ".sel files")
    Traceback (most recent call last):
    ...
    arapkit.errors.InputError: ...a.sel: not a text file
    """
    try:
        return read_input(path, what).decode("utf-8")
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a text file") from None
