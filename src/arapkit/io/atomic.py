"""Writing outputs safely: atomic file replacement, output-path checks and strict JSON.

Every writer of arapkit goes through :func:`atomic_open`: it writes a temporary file in the
destination folder and then ``os.replace``-s it over the target, so a crash or Ctrl-C never
leaves a half-written output (and an existing file is either untouched or fully replaced).

Examples
--------
>>> import tempfile, pathlib
>>> p = pathlib.Path(tempfile.mkdtemp()) / "r.json"
>>> write_json(p, {"ok": True}); p.read_text()
'{\\n  "ok": true\\n}\\n'
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import tempfile
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import IO, Any

import numpy as np

from ..errors import InputError

__all__ = [
    "atomic_open",
    "atomic_write",
    "check_output_path",
    "to_jsonable",
    "write_json",
]


@contextlib.contextmanager
def atomic_open(path: str | os.PathLike, mode: str = "wb") -> Iterator[IO]:
    """Open a temporary file next to ``path``; on success move it over ``path``.

    On any exception the temporary file is removed and ``path`` is left as it was.

    Parameters
    ----------
    path : path
        Final destination; its folder must exist.
    mode : {"wb", "w"}
        Binary or text (UTF-8) mode.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "a.txt"
    >>> with atomic_open(p, "w") as f:
    ...     _ = f.write("hello")
    >>> p.read_text()
    'hello'
    """
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise InputError(f"{path}: folder {str(folder)!r} does not exist")
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=folder)
    except OSError as e:  # name the user's file, not the temporary one
        raise InputError(f"{path}: cannot write ({e.strerror or e})") from None
    try:
        kwargs = {"encoding": "utf-8", "newline": "\n"} if "b" not in mode else {}
        with os.fdopen(fd, mode, **kwargs) as f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        # mkstemp creates 0600 files; give outputs the usual umask-based permissions
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        try:
            os.replace(tmp, path)
        except OSError as e:
            raise InputError(f"{path}: cannot write ({e.strerror or e})") from None
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def atomic_write(path: str | os.PathLike, data: bytes | str) -> None:
    """Write ``data`` (bytes, or text as UTF-8) to ``path`` atomically.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "a.bin"
    >>> atomic_write(p, b"xy"); p.read_bytes()
    b'xy'
    """
    with atomic_open(path, "wb") as f:
        f.write(data.encode("utf-8") if isinstance(data, str) else data)


def check_output_path(
    path: str | os.PathLike,
    inputs: Sequence[str | os.PathLike | None] = (),
    force: bool = False,
    what: str = "output",
) -> Path:
    """Check that ``path`` can be written, before any expensive work is done.

    Raises :class:`InputError` when the folder is missing, the path is a folder, or the
    path is one of ``inputs`` (unless ``force``).

    Examples
    --------
    >>> check_output_path("/no/such/out.ply")
    Traceback (most recent call last):
    ...
    arapkit.errors.InputError: /no/such/out.ply: output folder '/no/such' does not exist
    """
    p = Path(path)
    folder = p.parent if str(p.parent) else Path(".")
    if not folder.is_dir():
        raise InputError(f"{p}: {what} folder {str(folder)!r} does not exist")
    if p.is_dir():
        raise InputError(f"{p}: is a folder; give a file name for the {what}")
    if not force and p.exists():
        for inp in inputs:
            if inp is not None and Path(inp).exists() and os.path.samefile(p, inp):
                raise InputError(f"{p}: {what} would overwrite an input file (use --force)")
    _probe_writable(p, folder, what)
    return p


def _probe_writable(p: Path, folder: Path, what: str) -> None:
    """Create and remove a scratch file next to ``p``: the only test that also sees
    read-only mounts, immutable folders and root's limits (``os.access`` does not)."""
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".probe", dir=folder)
    except OSError as e:
        raise InputError(
            f"{p}: cannot write the {what} in folder {str(folder)!r} ({e.strerror or e})"
        ) from None
    os.close(fd)
    with contextlib.suppress(OSError):
        os.unlink(tmp)
    if p.exists():
        try:  # opening for update changes neither content nor times
            with open(p, "r+b"):
                pass
        except OSError as e:
            raise InputError(f"{p}: cannot overwrite the {what} ({e.strerror or e})") from None


def to_jsonable(obj: Any) -> Any:
    """Convert numpy scalars/arrays, paths and non-finite floats into plain JSON values.

    Non-finite floats become ``None`` so that the output is strict JSON.

    Examples
    --------
    >>> import numpy as np
    >>> to_jsonable({"a": np.arange(2), "b": float("nan"), "c": np.float32(1.5)})
    {'a': [0, 1], 'b': None, 'c': 1.5}
    """
    if isinstance(obj, Mapping):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, (np.bool_, bool)):
        return bool(obj)
    if isinstance(obj, (np.integer, int)):
        return int(obj)
    if isinstance(obj, (np.floating, float)):
        v = float(obj)
        return v if math.isfinite(v) else None
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    return obj


def write_json(path: str | os.PathLike, obj: Any, indent: int = 2) -> None:
    """Write ``obj`` as strict JSON, atomically (numpy values are converted).

    Examples
    --------
    >>> import tempfile, pathlib, numpy as np
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "r.json"
    >>> write_json(p, {"iterations": np.int64(3)}); p.read_text()
    '{\\n  "iterations": 3\\n}\\n'
    """
    text = json.dumps(to_jsonable(obj), indent=indent, allow_nan=False) + "\n"
    atomic_write(path, text)
