"""The file formats arapkit reads and writes: one list each, read by the readers, the writers,
the CLI's help and every message that names them; and the check a loader that dispatches on
the suffix makes first (:func:`existing_file`).

Examples
--------
>>> readable_formats()
'OFF, OBJ, PLY, STL'
>>> mesh_format("out.OFF.gz")
('off', True)
"""

from __future__ import annotations

import os
from pathlib import Path

from ..errors import InputError

__all__ = [
    "FIGURE_FORMATS",
    "MESH_FORMATS",
    "READ_FORMATS",
    "check_figure_format",
    "existing_file",
    "is_readable_mesh",
    "mesh_format",
    "readable_formats",
]

#: Input mesh formats, by extension (a ``.gz`` suffix may follow any of them).
READ_FORMATS = ("off", "obj", "ply", "stl")
#: Output mesh formats, by extension (a ``.gz`` suffix may follow any of them).
MESH_FORMATS = ("ply", "obj", "off", "stl", "glb")
#: Figure formats every figure writer accepts (matplotlib writes them all).
FIGURE_FORMATS = ("png", "pdf", "svg", "jpg", "jpeg")


def readable_formats(last: str = ", ") -> str:
    """The readable mesh formats for people: ``OFF, OBJ, PLY, STL`` (``last`` joins the
    final two, e.g. ``" or "``).

    Examples
    --------
    >>> readable_formats(" or ")
    'OFF, OBJ, PLY or STL'
    """
    names = [f.upper() for f in READ_FORMATS]
    return ", ".join(names[:-1]) + last + names[-1]


def is_readable_mesh(name: str | os.PathLike) -> bool:
    """Whether a file name has a readable mesh extension (optionally followed by ``.gz``).

    Examples
    --------
    >>> is_readable_mesh("bunny.PLY.gz"), is_readable_mesh("notes.txt")
    (True, False)
    """
    low = Path(name).name.lower().removesuffix(".gz")
    return low.rsplit(".", 1)[-1] in READ_FORMATS if "." in low else False


def check_figure_format(path: str | os.PathLike) -> str:
    """The figure format named by ``path``'s extension, or a one-line error.

    Examples
    --------
    >>> check_figure_format("fig.PDF")
    'pdf'
    """
    fmt = Path(path).suffix.lower().lstrip(".")
    if fmt not in FIGURE_FORMATS:
        raise InputError(f"{path}: unsupported figure format '.{fmt}' (use "
                         + ", ".join("." + f for f in FIGURE_FORMATS[:-1])
                         + f" or .{FIGURE_FORMATS[-1]})")
    return fmt


def mesh_format(path: str | os.PathLike) -> tuple[str, bool]:
    """Output mesh format named by a file's extension, and whether it ends in ``.gz``.

    Examples
    --------
    >>> mesh_format("out.OFF.gz")
    ('off', True)
    """
    name = Path(path).name.lower()
    gz = name.endswith(".gz")
    if gz:
        name = name[:-3]
    ext = name.rsplit(".", 1)[-1] if "." in name else ""
    if ext not in MESH_FORMATS:
        shown = f"'.{ext}'" if ext else "no extension"
        raise InputError(
            f"{path}: unsupported mesh format {shown} (use one of: "
            + ", ".join("." + f for f in MESH_FORMATS)
            + ")"
        )
    return ext, gz


def existing_file(path: str | os.PathLike) -> Path:
    """``path`` as a :class:`~pathlib.Path`, refused in one line when its name holds a NUL
    byte or nothing is there (what loaders that dispatch on the suffix check first).

    Examples
    --------
    >>> existing_file("/no/such/r.txt")
    Traceback (most recent call last):
    ...
    arapkit.errors.InputError: /no/such/r.txt: file not found
    """
    if "\0" in str(path):
        raise InputError(f"{str(path)!r}: not a usable file name (NUL byte)")
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: file not found")
    return path
