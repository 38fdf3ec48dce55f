"""A sparse Cholesky factor held by a child process, so that this process keeps running.

cholespy holds Python's GIL for the whole of a factorisation and of every solve (its
bindings release nothing). A factor built on a background thread therefore freezes every
other thread of the process: at 1.75M vertices the editor's page, its websocket and the
preview stood still for 19 s after each new handle or repainted r, and for 4 s at 437K.
:class:`ChildCholesky` runs the same cholespy in a child Python instead; this process only
waits on a pipe (which releases the GIL) while the child factorises or solves. Right-hand
sides and solutions pass through a shared file mapping (``/dev/shm`` where there is one),
two copies of ``n k`` doubles a solve (about 10 ms at 1.57M rows and 3 columns).

Whoever builds factors beside other work asks for this with :func:`factors_in_child`;
:class:`arapkit.arap.constraints.CholeskyFactor` then builds its factor here for a matrix
of at least ``min_rows`` rows (a child costs about 0.2 s to start). Everywhere else (a
one-shot solve, where nothing waits beside it) the factor stays in this process.

Examples
--------
>>> import numpy as np, scipy.sparse as sp
>>> A = sp.coo_matrix(np.array([[4.0, 1.0], [1.0, 3.0]]))
>>> f = ChildCholesky(2, A.row.astype(np.int32), A.col.astype(np.int32), A.data)
>>> X = np.empty((2, 1))
>>> f.solve(np.array([[1.0], [2.0]]), X)
>>> np.round(X.ravel(), 6).tolist()
[0.090909, 0.636364]
>>> f.close()
"""

from __future__ import annotations

import contextvars
import os
import shutil
import subprocess
import sys
import tempfile
import threading
import weakref
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np

__all__ = ["CHILD_MIN_ROWS", "ChildCholesky", "ChildUnavailable", "child_env",
           "factors_in_child", "wants_child"]

#: the fewest rows worth a child: below, a factorisation takes less than a child's start
CHILD_MIN_ROWS = 50_000

_min_rows: contextvars.ContextVar[int | None] = contextvars.ContextVar(
    "arapkit_child_factor_min_rows", default=None)


def child_env() -> dict[str, str]:
    """The environment for a child Python started with ``sys.executable``: this process's
    import path ahead of its own, so that the child imports the same NumPy, cholespy and
    fast-simplification.

    In an embedded interpreter they may not be in that Python's site-packages: Blender puts
    an extension's bundled wheels on ``sys.path`` at run time, and a child started without
    them failed to import and fell back to this process (holding the GIL for seconds).

    Examples
    --------
    >>> import sys
    >>> env = child_env()
    >>> all(p in env["PYTHONPATH"].split(os.pathsep) for p in sys.path if os.path.isdir(p))
    True
    """
    env = dict(os.environ)
    paths = [p for p in sys.path if p and os.path.isdir(p)]
    if env.get("PYTHONPATH"):
        paths.append(env["PYTHONPATH"])
    env["PYTHONPATH"] = os.pathsep.join(paths)
    return env


@contextmanager
def factors_in_child(min_rows: int | None = None) -> Iterator[None]:
    """Within this block (on this thread), factors of ``min_rows`` rows or more (default:
    :data:`CHILD_MIN_ROWS`) are built and solved in a child process (:class:`ChildCholesky`).

    Examples
    --------
    >>> with factors_in_child(10):
    ...     wants_child(10), wants_child(9)
    (True, False)
    >>> wants_child(10**9)
    False
    """
    token = _min_rows.set(int(CHILD_MIN_ROWS if min_rows is None else min_rows))
    try:
        yield
    finally:
        _min_rows.reset(token)


def wants_child(n_rows: int) -> bool:
    """Whether a factor of ``n_rows`` rows is to be built in a child here and now."""
    least = _min_rows.get()
    return least is not None and n_rows >= least


class ChildUnavailable(RuntimeError):
    """The child could not be started or ended before its factor was made (the caller
    factorises in this process instead)."""


# The child: numpy and cholespy only (starts in about 0.2 s). Its replies go to a copy of
# stdout taken first; C-level stdout then points at stderr, so CHOLMOD's warnings cannot
# corrupt the replies.
_CHILD = r"""
import os, sys
reply = os.fdopen(os.dup(1), "wb", buffering=0)
os.dup2(2, 1)
import numpy as np
from cholespy import CholeskySolverD, MatrixType
folder, n = sys.argv[1], int(sys.argv[2])
# mapped, not read: the pages in memory are the files' own (copy-on-write: writable, as
# cholespy's bindings ask, and never written)
row, col, data = (np.load(os.path.join(folder, k + ".npy"), mmap_mode="c")
                  for k in ("row", "col", "data"))
try:
    solver = CholeskySolverD(n, row, col, data, MatrixType.COO)
except ValueError:
    reply.write(b"notpd\n")
    sys.exit(0)
del row, col, data
try:  # CHOLMOD's workspace back to the system, as this process does after a factor
    import ctypes
    ctypes.CDLL(None).malloc_trim(0)
except (OSError, AttributeError):
    pass
reply.write(b"ready\n")
buf = None
for line in sys.stdin.buffer:
    word, *args = line.split()
    if word == b"map":
        buf = np.memmap(args[0].decode(), dtype=np.float64, mode="r+")
    elif word == b"solve":
        k = int(args[0])
        shape = (n,) if k == 0 else (n, k)
        size = n * max(k, 1)
        solver.solve(buf[:size].reshape(shape), buf[size:2 * size].reshape(shape))
    reply.write(b"ok\n")
"""


def _scratch_dir() -> str:
    """A private folder in memory where the system has one (``/dev/shm``), else in the
    temporary directory."""
    shm = "/dev/shm"
    base = shm if os.path.isdir(shm) and os.access(shm, os.W_OK) else None
    return tempfile.mkdtemp(prefix="arapkit-factor-", dir=base)


def _close(proc: subprocess.Popen, folder: str) -> None:
    """End the child (its stdin's end is its signal; one still factorising does not read
    it, and is killed) and remove its folder."""
    try:
        if proc.stdin is not None:
            proc.stdin.close()
        proc.wait(timeout=2)
    except (OSError, subprocess.TimeoutExpired):
        proc.kill()
    finally:
        if proc.stdout is not None:
            proc.stdout.close()
        shutil.rmtree(folder, ignore_errors=True)


class ChildCholesky:
    """cholespy's ``CholeskySolverD`` of a COO matrix, in a child process.

    Same constructor arguments (``MatrixType.COO``) and ``solve(B, X)`` as cholespy's;
    raises ``ValueError`` where the matrix is not positive definite, as cholespy does, and
    :class:`ChildUnavailable` where no child could make the factor. Solves are serialised
    (one child, one pipe). The child ends when this object is closed or collected, or when
    this process ends (its stdin closes).
    """

    def __init__(self, n: int, row: np.ndarray, col: np.ndarray, data: np.ndarray) -> None:
        self.n = int(n)
        self._lock = threading.Lock()
        folder = _scratch_dir()
        try:
            for key, a, dt in (("row", row, np.int32), ("col", col, np.int32),
                               ("data", data, np.float64)):
                # one converted copy at a time (176 MB in all for 1.57M rows)
                np.save(os.path.join(folder, key + ".npy"), np.ascontiguousarray(a, dtype=dt))
            proc = subprocess.Popen(
                [sys.executable, "-c", _CHILD, folder, str(self.n)],
                stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                env=child_env())
        except (OSError, TypeError, ValueError) as exc:  # TypeError: no sys.executable
            shutil.rmtree(folder, ignore_errors=True)
            raise ChildUnavailable(f"no child for the factor: {exc}") from None
        self._proc, self._folder = proc, folder
        self._finalizer = weakref.finalize(self, _close, proc, folder)
        word = self._read()  # the pipe's wait releases the GIL: this process runs on
        for key in ("row", "col", "data"):  # the child has read them
            try:
                os.remove(os.path.join(folder, key + ".npy"))
            except OSError:
                pass
        if word == b"notpd":
            self.close()
            raise ValueError("the matrix is not positive definite")
        if word != b"ready":
            self.close()
            raise ChildUnavailable("the factor's child process ended before its factor")
        self._buf: np.memmap | None = None
        self._cap = 0
        self._maps = 0

    def _read(self) -> bytes:
        line = self._proc.stdout.readline() if self._proc.stdout is not None else b""
        return line.strip()

    def _send(self, text: str) -> None:
        self._proc.stdin.write(text.encode() + b"\n")
        self._proc.stdin.flush()

    def _room(self, size: int) -> np.memmap:
        """The shared buffer, at least ``2 size`` doubles (a right-hand side, a solution)."""
        if self._buf is None or self._cap < size:
            self._maps += 1
            path = os.path.join(self._folder, f"rhs{self._maps}")
            buf = np.memmap(path, dtype=np.float64, mode="w+", shape=(2 * size,))
            self._send(f"map {path}")
            if self._read() != b"ok":
                raise RuntimeError("the factor's child process ended")
            self._buf, self._cap = buf, size
            try:  # both sides hold it mapped; where the system allows, the name can go
                os.remove(path)
            except OSError:
                pass
        return self._buf

    def solve(self, B: np.ndarray, X: np.ndarray) -> None:
        """Solve ``A X = B`` for (n,) or (n, k) C-contiguous float64 ``B`` into ``X``."""
        k = 0 if B.ndim == 1 else B.shape[1]
        size = self.n * max(k, 1)
        with self._lock:
            if self._proc.poll() is not None:
                raise RuntimeError("the factor's child process ended")
            buf = self._room(size)
            buf[:size] = B.reshape(-1)
            self._send(f"solve {k}")
            if self._read() != b"ok":
                raise RuntimeError("the factor's child process ended during a solve")
            np.copyto(X, buf[size:2 * size].reshape(X.shape))

    @property
    def pid(self) -> int:
        """The child's process id."""
        return self._proc.pid

    def close(self) -> None:
        """End the child now (else when this object is collected)."""
        self._buf = None
        self._finalizer()
