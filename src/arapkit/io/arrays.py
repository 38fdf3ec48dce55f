"""Reading numpy array files (``.npy``, ``.npz``) given by users, safely.

Examples
--------
>>> import tempfile, pathlib, numpy as np
>>> p = pathlib.Path(tempfile.mkdtemp()) / "a.npy"
>>> np.save(p, np.arange(3))
>>> load_numpy(p).tolist()
[0, 1, 2]
"""

from __future__ import annotations

import contextlib
import os
import zipfile
import zlib
from collections.abc import Sequence

import numpy as np

from ..errors import InputError

__all__ = ["load_numpy"]


#: what np.load raises on a damaged or foreign file: a file that starts like a zip archive
#: (every .npz) and then holds garbage fails inside zipfile or zlib, not in numpy
_NUMPY_ERRORS = (ValueError, OSError, EOFError, KeyError, zipfile.BadZipFile, zlib.error)


def load_numpy(
    path: str | os.PathLike, names: Sequence[str] | None = None
) -> np.ndarray | dict[str, np.ndarray]:
    """Read a ``.npy`` array, or the arrays ``names`` of a ``.npz`` archive, from user input.

    Every way a damaged file fails becomes one :class:`InputError` line naming the file;
    pickled objects are never loaded.

    Parameters
    ----------
    path : path
    names : sequence of str, optional
        For a ``.npz`` archive: the arrays to read (all must be present). Without it the
        file must be a single ``.npy`` array.

    Returns
    -------
    ndarray, or dict of name -> ndarray when ``names`` is given.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "a.npz"
    >>> np.savez(p, V=np.zeros((2, 3)))
    >>> load_numpy(p, ["V"])["V"].shape
    (2, 3)
    >>> _ = p.write_bytes(b"PK\\x03\\x04garbage")
    >>> load_numpy(p, ["V"])
    Traceback (most recent call last):
    ...
    arapkit.errors.InputError: ...a.npz: not a readable .npz file (BadZipFile: File is not a \
zip file)
    """
    kind = ".npy" if names is None else ".npz"
    try:
        with contextlib.ExitStack() as stack:
            data = np.load(path, allow_pickle=False)
            if isinstance(data, np.lib.npyio.NpzFile):
                stack.enter_context(data)
                if names is None:
                    raise InputError(f"{path}: a .npz archive, expected a single .npy array")
                missing = [n for n in names if n not in data.files]
                if missing:
                    raise InputError(f"{path}: expected arrays {', '.join(map(repr, names))}, "
                                     f"found {', '.join(data.files) or 'none'}")
                return {n: np.asarray(data[n]) for n in names}
            if names is not None or not isinstance(data, np.ndarray):
                raise InputError(f"{path}: not a .npz archive (a single array)")
            return data
    except FileNotFoundError:
        raise InputError(f"{path}: file not found") from None
    except _NUMPY_ERRORS as e:
        raise InputError(f"{path}: not a readable {kind} file ({type(e).__name__}: {e})") from None
