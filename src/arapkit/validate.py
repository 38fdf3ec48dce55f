"""One rule per kind of user value: the checks shared by the API, the CLI and the editor.

Every function takes the value as the user gave it (a Python object, a numpy array, the
text of a command-line option or a parsed JSON value) and either returns it in canonical
form or raises :class:`arapkit.errors.InputError` with one line that names ``what`` (the
option, file or field at fault). No function here lets ``OverflowError``,
``RecursionError``, ``TypeError`` or a numpy exception escape, so a caller never needs a
second ``except`` clause. The rules are listed in ``docs/input-rules.md``.

Examples
--------
>>> integer("12", "--max-iter", lo=1)
12
>>> integer(10**30, "handle index", lo=0, hi=99)
Traceback (most recent call last):
...
arapkit.errors.InputError: handle index: must be at most 99, got 1e+30
>>> ring_sizes(3, 2).tolist()
[3, 3]
"""

from __future__ import annotations

import json
import math
import numbers
import os
import re
from collections.abc import Sequence
from typing import Any

import numpy as np

from .errors import InputError

__all__ = [
    "INPUT_CAP_VARIABLE",
    "MAX_INPUT_MB",
    "MAX_ITER_LIMIT",
    "MAX_JSON_DEPTH",
    "MAX_RINGS",
    "MAX_UPLOAD_MB",
    "check_finite_positions",
    "check_input_size",
    "handle_indices",
    "host",
    "input_cap_mb",
    "integer",
    "iteration_cap",
    "json_depth",
    "number",
    "parse_json",
    "point_positions",
    "port",
    "positions_of",
    "quaternion",
    "read_input",
    "real_array",
    "ring_size",
    "ring_sizes",
    "target_positions",
    "tolerance",
    "upload_mb",
    "vec3",
]

#: largest ring size r anywhere (API, CLI, rings files, editor); BFS layers are int8
MAX_RINGS = 100
#: deepest JSON nesting accepted in handle files and sessions (they need about 5)
MAX_JSON_DEPTH = 64
#: largest iteration cap: beyond it a solve would run for days, so it is a typo
MAX_ITER_LIMIT = 10**9
#: largest upload cap the editor accepts, in MiB (1 TiB: anything larger is a typo)
MAX_UPLOAD_MB = 2.0**20
#: largest handle, .sel/.def, rings, session or job file read, in MiB: a handle file with
#: explicit targets for every vertex of a 2-million-vertex mesh is about 150 MiB
MAX_INPUT_MB = 256.0
#: environment variable that replaces :data:`MAX_INPUT_MB` (a number of MiB)
INPUT_CAP_VARIABLE = "ARAPKIT_MAX_INPUT_MB"


def _show(value: Any) -> str:
    """A short, one-line rendering of a bad value (huge integers in e-notation)."""
    if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
        v = int(value)
        if abs(v) < 10**15:
            return str(v)
        try:
            return f"{float(v):.3g}"
        except OverflowError:  # beyond the double range: say how many digits
            return f"{'-' if v < 0 else ''}about 1e+{int(v.bit_length() * 0.30103)}"
    text = repr(value) if isinstance(value, str) else str(value)
    text = " ".join(text.split())
    return text if len(text) <= 60 else text[:57] + "..."


def integer(value: Any, what: str, *, lo: int | None = None, hi: int | None = None) -> int:
    """An integer within ``[lo, hi]``.

    Accepts Python and numpy integers, integral finite floats (``3.0``: JSON writers
    produce them) and decimal text (command-line options). Refuses booleans, fractions,
    NaN and infinity. Python integers have no size limit, so ``10**30`` is reported as out
    of range instead of overflowing a C integer.

    Examples
    --------
    >>> integer(3.0, "k"), integer(" 7 ", "k", lo=1)
    (3, 7)
    >>> integer(2.5, "--max-iter")
    Traceback (most recent call last):
    ...
    arapkit.errors.InputError: --max-iter: expected an integer, got 2.5
    """
    v: int
    if isinstance(value, (bool, np.bool_)):
        raise InputError(f"{what}: expected an integer, got {_show(value)}")
    if isinstance(value, (int, np.integer)):
        v = int(value)
    elif isinstance(value, str):
        text = value.strip()
        if not re.fullmatch(r"[+-]?\d+", text):
            raise InputError(f"{what}: expected an integer, got {_show(value)}")
        if len(text) > 4000:  # int() refuses such strings; say what the problem is
            raise InputError(f"{what}: {len(text)}-digit number is out of range")
        v = int(text)
    elif isinstance(value, (float, np.floating)):
        f = float(value)
        if not math.isfinite(f) or f != math.floor(f):
            raise InputError(f"{what}: expected an integer, got {_show(value)}")
        v = int(f)
    else:
        raise InputError(f"{what}: expected an integer, got {type(value).__name__}")
    if lo is not None and v < lo:
        raise InputError(f"{what}: must be at least {_show(lo)}, got {_show(v)}")
    if hi is not None and v > hi:
        raise InputError(f"{what}: must be at most {_show(hi)}, got {_show(v)}")
    return v


def number(
    value: Any,
    what: str,
    *,
    lo: float | None = None,
    hi: float | None = None,
    lo_open: bool = False,
) -> float:
    """A finite real number in ``[lo, hi]`` (``(lo, hi]`` with ``lo_open``).

    Accepts Python/numpy reals and decimal text; refuses booleans, complex numbers,
    strings that are not numbers, NaN and infinity.

    Examples
    --------
    >>> number("1e-3", "--tol", lo=0)
    0.001
    >>> number(float("nan"), "tol")
    Traceback (most recent call last):
    ...
    arapkit.errors.InputError: tol: expected a finite number, got nan
    """
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (numbers.Real, str)):
        raise InputError(f"{what}: expected a number, got {_show(value)}")
    try:
        f = float(value)
    except (ValueError, OverflowError):
        raise InputError(f"{what}: expected a number, got {_show(value)}") from None
    if not math.isfinite(f):
        raise InputError(f"{what}: expected a finite number, got {_show(value)}")
    too_low = lo is not None and (f <= lo if lo_open else f < lo)
    if too_low or (hi is not None and f > hi):
        if lo_open and hi is None:
            rule = f"must be greater than {lo:g}"
        elif hi is None:
            rule = f"must be at least {lo:g}"
        elif lo is None:
            rule = f"must be at most {hi:g}"
        else:
            rule = f"must be in {'(' if lo_open else '['}{lo:g}, {hi:g}]"
        raise InputError(f"{what}: {rule}, got {_show(value)}")
    return f


def tolerance(value: Any, what: str = "tol") -> float:
    """Convergence tolerance: a finite number >= 0 (0 runs until ``max_iter`` or round-off).

    Examples
    --------
    >>> tolerance(0), tolerance("1e-6")
    (0.0, 1e-06)
    """
    return number(value, what, lo=0.0)


def iteration_cap(value: Any, what: str = "max_iter") -> int:
    """Iteration cap: an integer in ``1..MAX_ITER_LIMIT``.

    Examples
    --------
    >>> iteration_cap(200)
    200
    """
    return integer(value, what, lo=1, hi=MAX_ITER_LIMIT)


def ring_size(value: Any, what: str = "r") -> int:
    """One ring size r: an integer in ``1..MAX_RINGS``.

    Examples
    --------
    >>> ring_size("4", "--rings")
    4
    """
    return integer(value, what, lo=1, hi=MAX_RINGS)


def real_array(values: Any, what: str, dtype: Any = np.float64) -> np.ndarray:
    """``values`` as a numeric array, refusing text, objects and complex numbers.

    With ``dtype=None`` the array keeps its own (bool, integer or float) dtype.

    ``np.asarray`` would turn ``["1", "2"]`` into strings, ``[1, None]`` into objects and
    drop the imaginary part of a complex number on conversion; all of them are refused.

    Examples
    --------
    >>> real_array([[1, 2]], "v").dtype.name
    'float64'
    >>> real_array([1j], "v")
    Traceback (most recent call last):
    ...
    arapkit.errors.InputError: v: expected real numbers, got complex128 values
    """
    try:
        arr = np.asarray(values)
    except (ValueError, TypeError, OverflowError, RecursionError) as exc:
        raise InputError(f"{what}: not a numeric array ({_show(exc)})") from None
    if arr.dtype.kind == "O" and arr.size:
        # Python ints beyond 64 bits, or mixed types, land here; astype would also turn
        # the text "1.5" into a number, so every element must be a real number itself
        if not all(isinstance(x, numbers.Real) and not isinstance(x, (bool, np.bool_))
                   for x in arr.flat):
            raise InputError(f"{what}: expected numbers, got mixed or non-numeric values")
        try:
            arr = arr.astype(np.float64)
        except (ValueError, TypeError, OverflowError):
            raise InputError(f"{what}: expected numbers, got mixed or non-numeric values") from None
    if arr.dtype.kind not in "biuf" and not (arr.dtype.kind == "O" and arr.size == 0):
        raise InputError(f"{what}: expected real numbers, got {arr.dtype} values")
    if dtype is None:
        return arr
    if arr.dtype.kind == "b" and np.dtype(dtype).kind != "b":
        raise InputError(f"{what}: expected numbers, got booleans")
    with np.errstate(over="ignore", invalid="ignore"):
        return arr.astype(dtype)


def check_finite_positions(P: np.ndarray, what: str) -> np.ndarray:
    """Refuse an (n, 3) array with a NaN or infinite coordinate, naming the first vertex.

    Examples
    --------
    >>> check_finite_positions(np.array([[0.0, 1, np.inf]]), "out.ply")
    Traceback (most recent call last):
    ...
    arapkit.errors.InputError: out.ply: vertex 0 has a non-finite coordinate (1 such vertices)
    """
    ok = np.isfinite(P).all(axis=-1) if P.ndim > 1 else np.isfinite(P)
    if not ok.all():
        bad = np.flatnonzero(~ok)
        raise InputError(
            f"{what}: vertex {bad[0]} has a non-finite coordinate ({len(bad)} such vertices)"
        )
    return P


def point_positions(values: Any, what: str, nouns: tuple[str, str] = ("point", "points"),
                    empty: str = "the point cloud is empty") -> np.ndarray:
    """(n, 3) finite float64 positions of a point set, or one line naming the point at fault.

    The one rule for a cloud's points, a fit's target points and a mesh's vertices
    (``nouns=("vertex", "vertices")``, ``empty`` its own message): text, objects, complex
    numbers and booleans are refused (numpy would parse strings and drop imaginary parts
    without a word), as are a wrong shape, no point at all and a non-finite coordinate.

    Examples
    --------
    >>> point_positions([[0, 0, 1]], "scan.npy").shape
    (1, 3)
    >>> point_positions([[0, 0, float("nan")]], "scan.npy")
    Traceback (most recent call last):
    ...
    arapkit.errors.InputError: scan.npy: point 0 has a non-finite coordinate [0.0, 0.0, nan]
    """
    one, many = nouns
    P = np.array(real_array(values, f"{what}: {many}"), dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 3:
        raise InputError(f"{what}: {many} must have shape (n, 3), got {P.shape}")
    if len(P) == 0:
        raise InputError(f"{what}: {empty}")
    bad = np.flatnonzero(~np.isfinite(P).all(axis=1))
    if len(bad):
        raise InputError(f"{what}: {one} {bad[0]} has a non-finite coordinate "
                         f"{P[bad[0]].tolist()}"
                         + (f" ({len(bad)} such {many})" if len(bad) > 1 else ""))
    return P


def _numbers(values: Any, count: int, what: str) -> np.ndarray:
    """``count`` finite numbers (JSON numbers: text is refused here)."""
    if any(isinstance(x, (str, bytes)) for x in values):
        raise InputError(f"{what}: expected {count} numbers, got text")
    return np.array([number(x, what) for x in values])


def vec3(value: Any, what: str) -> np.ndarray:
    """Three finite numbers.

    Examples
    --------
    >>> vec3([1, 2, 3], "position").tolist()
    [1.0, 2.0, 3.0]
    """
    if not isinstance(value, (list, tuple, np.ndarray)) or len(value) != 3:
        raise InputError(f"{what}: expected 3 numbers, got {_show(value)}")
    return _numbers(value, 3, what)


def quaternion(value: Any, what: str = "wxyz") -> np.ndarray:
    """A rotation quaternion ``(w, x, y, z)``: four finite numbers, not all zero; unit length.

    Normalising divides by the largest component first, so ``1e300`` components neither
    overflow nor make a zero norm.

    Examples
    --------
    >>> quaternion([2, 0, 0, 0]).tolist()
    [1.0, 0.0, 0.0, 0.0]
    >>> quaternion([0, 0, 0, 0])
    Traceback (most recent call last):
    ...
    arapkit.errors.InputError: wxyz: a rotation quaternion must not be zero
    """
    if not isinstance(value, (list, tuple, np.ndarray)) or len(value) != 4:
        raise InputError(f"{what}: expected 4 numbers (w, x, y, z), got {_show(value)}")
    q = _numbers(value, 4, what)
    m = np.abs(q).max()
    if m == 0:
        raise InputError(f"{what}: a rotation quaternion must not be zero")
    q = q / m
    return q / np.linalg.norm(q)


def ring_sizes(rings: Any, n_vertices: int, source: str = "rings") -> np.ndarray:
    """An int or per-vertex sequence of ring sizes as (n,) int32, each in ``1..MAX_RINGS``.

    ``source`` names the file or option in messages.

    Examples
    --------
    >>> ring_sizes([1, 2, 6], 3).tolist()
    [1, 2, 6]
    >>> ring_sizes([1, 10**29], 2, "r.txt")
    Traceback (most recent call last):
    ...
    arapkit.errors.InputError: r.txt: vertex 1 has r = 1e+29 (r must be 1..100)
    """
    if isinstance(rings, (str, bytes)):
        raise InputError(f"{source}: expected an integer or one per vertex, got {_show(rings)}")
    r = real_array(rings, source)
    if r.ndim == 0:
        r = np.full(n_vertices, r)
    if r.ndim != 1:
        raise InputError(f"{source}: expected one r per vertex (1-D), got shape {r.shape}")
    if r.shape != (n_vertices,):
        raise InputError(
            f"{source}: has {r.size} values but the mesh has {n_vertices} vertices"
        )
    bad = ~np.isfinite(r) | (r != np.round(r))
    if bad.any():
        i = int(np.argmax(bad))
        raise InputError(f"{source}: value {_show(r[i])} at vertex {i} is not an integer")
    out = (r < 1) | (r > MAX_RINGS)
    if out.any():
        i = int(np.argmax(out))
        shown = _show(int(r[i])) if abs(r[i]) < 1e300 else _show(float(r[i]))
        raise InputError(f"{source}: vertex {i} has r = {shown} (r must be 1..{MAX_RINGS})")
    return r.astype(np.int32)


def positions_of(value: Any) -> Any:
    """What stands for vertex positions: ``value.vertices`` when ``value`` carries them
    (an :class:`arapkit.Mesh`, a ``trimesh.Trimesh``, a solve's :class:`arapkit.Result`),
    else ``value`` itself, to be checked as an array.

    Examples
    --------
    >>> class Shape:
    ...     vertices = [[0.0, 1.0, 2.0]]
    >>> positions_of(Shape())
    [[0.0, 1.0, 2.0]]
    >>> positions_of([[3.0, 4.0, 5.0]])
    [[3.0, 4.0, 5.0]]
    """
    return value if isinstance(value, np.ndarray) else getattr(value, "vertices", value)


def handle_indices(handles: Any, n_vertices: int, source: str = "handles") -> np.ndarray:
    """Handle vertex indices as a 1-D int64 array: integers, unique, in ``0..n-1``.

    A boolean array of length ``n`` is a mask and selects its True vertices; booleans of
    any other length, 2-D shapes, fractions and text are refused. A handle set read by
    :func:`arapkit.load_handles` (anything with ``indices``) stands for its indices.

    Examples
    --------
    >>> handle_indices([3, 0], 5).tolist()
    [3, 0]
    >>> handle_indices(np.array([True, False, True]), 3).tolist()
    [0, 2]
    """
    if not isinstance(handles, np.ndarray):
        handles = getattr(handles, "indices", handles)
    if isinstance(handles, (str, bytes)):
        raise InputError(f"{source}: handle indices must be integers, got {_show(handles)}")
    h = real_array(handles, source, dtype=None)
    if h.dtype.kind == "b":
        if h.shape != (n_vertices,):
            raise InputError(
                f"{source}: a boolean handle mask needs one value per vertex "
                f"({n_vertices}), got shape {h.shape}"
            )
        h = np.flatnonzero(h)
    elif h.ndim != 1:
        raise InputError(f"{source}: handle indices must be a 1-D list, got shape {h.shape}")
    if len(h) == 0:
        raise InputError(f"{source}: no handle vertices given")
    if h.dtype.kind == "f":
        frac = ~np.isfinite(h) | (h != np.round(h))
        if frac.any():
            i = int(np.argmax(frac))
            raise InputError(f"{source}: handle {i} is {_show(h[i])}, not an integer")
    out = (h < 0) | (h >= n_vertices)
    if out.any():
        i = int(np.argmax(out))
        raise InputError(
            f"{source}: handle {i} is vertex {_show(int(h[i]) if abs(h[i]) < 1e300 else h[i])}, "
            f"out of range (mesh has {n_vertices} vertices)"
        )
    h = h.astype(np.int64)
    uniq, counts = np.unique(h, return_counts=True)
    if (counts > 1).any():
        raise InputError(f"{source}: vertex {uniq[counts > 1][0]} is listed twice as a handle")
    return h


def target_positions(handles: np.ndarray, targets: Any, name: str = "targets") -> np.ndarray:
    """Handle targets: real, shape ``(len(handles), 3)``, finite.

    Examples
    --------
    >>> target_positions(np.array([4]), [[0, 1, 2]]).tolist()
    [[0.0, 1.0, 2.0]]

    A handle set read by :func:`arapkit.load_handles` (anything with ``targets``) stands
    for its targets.
    """
    if not isinstance(targets, np.ndarray):
        targets = getattr(targets, "targets", targets)
    T = real_array(targets, name)
    if T.shape != (len(handles), 3):
        raise InputError(f"{name}: expected shape ({len(handles)}, 3), got {T.shape}")
    # one flat test first: the row-wise one costs 20 ms for a scan's 4 x 10^5 handle
    # vertices, on every preview frame of a drag
    if not np.isfinite(T).all():
        bad = np.flatnonzero(~np.isfinite(T).all(axis=1))
        raise InputError(f"{name}: handle {bad[0]} (vertex {handles[bad[0]]}) target is not finite")
    return T


def port(value: Any, what: str = "--port") -> int:
    """A TCP port number, 1..65535.

    Examples
    --------
    >>> port("8080")
    8080
    """
    return integer(value, what, lo=1, hi=65535)


def host(value: Any, what: str = "--host") -> str:
    """An address this machine can listen on (checked by binding a throwaway socket).

    Without this check a server that cannot bind may retry ports forever.

    Examples
    --------
    >>> host("127.0.0.1")
    '127.0.0.1'
    """
    import socket

    if not isinstance(value, str) or not value or "\0" in value:
        raise InputError(f"{what}: expected a host name or address, got {_show(value)}")
    try:
        infos = socket.getaddrinfo(value, 0, type=socket.SOCK_STREAM)
        family, _, _, _, addr = infos[0]
        with socket.socket(family, socket.SOCK_STREAM) as s:
            s.bind(addr)
    except (OSError, UnicodeError) as e:
        reason = getattr(e, "strerror", None) or str(e)
        raise InputError(f"{what}: cannot listen on {_show(value)} ({reason})") from None
    return value


def upload_mb(value: Any, what: str = "--max-upload-mb") -> float:
    """An upload size cap in MiB: finite, > 0, at most :data:`MAX_UPLOAD_MB`.

    Examples
    --------
    >>> upload_mb("0.5")
    0.5
    """
    return number(value, what, lo=0.0, hi=MAX_UPLOAD_MB, lo_open=True)


def input_cap_mb() -> float:
    """The size cap of :func:`read_input` in MiB: :data:`MAX_INPUT_MB`, or the value of
    the environment variable :data:`INPUT_CAP_VARIABLE` when it is set.

    Examples
    --------
    >>> input_cap_mb() == MAX_INPUT_MB or INPUT_CAP_VARIABLE in os.environ
    True
    """
    text = os.environ.get(INPUT_CAP_VARIABLE)
    if text is None:
        return MAX_INPUT_MB
    return number(text, INPUT_CAP_VARIABLE, lo=0.0, lo_open=True)


def read_input(path: str | os.PathLike, what: str = "input files") -> bytes:
    """The bytes of a small input file (handles, .sel/.def, rings, sessions, jobs), or a
    one-line error naming it.

    The size is checked before anything is read: these files are parsed into Python
    objects, which take several times the file's size, so a file beyond the cap
    (:func:`input_cap_mb`) is refused instead of exhausting memory.

    Parameters
    ----------
    path : path
    what : str
        The kind of file, for the message ("handle files" ...).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "h.json"
    >>> _ = p.write_text("[]")
    >>> read_input(p)
    b'[]'
    >>> read_input(p.with_name("none.json"))
    Traceback (most recent call last):
    ...
    arapkit.errors.InputError: ...none.json: file not found
    """
    try:
        with open(path, "rb") as f:
            check_input_size(os.fstat(f.fileno()).st_size, path, what)
            return f.read()
    except InputError:
        raise
    except FileNotFoundError:
        raise InputError(f"{path}: file not found") from None
    except IsADirectoryError:
        raise InputError(f"{path}: is a folder, expected a file") from None
    except ValueError:  # the OS refuses names with a NUL byte
        raise InputError(f"{str(path)!r}: not a usable file name (NUL byte)") from None
    except OSError as e:
        raise InputError(f"{path}: cannot read ({e.strerror or e})") from None


def check_input_size(size: int, path: str | os.PathLike, what: str = "input files") -> None:
    """Refuse ``size`` bytes of input file ``path`` when beyond :func:`input_cap_mb`.

    Examples
    --------
    >>> check_input_size(2**40, "h.json", "handle files")
    Traceback (most recent call last):
    ...
    arapkit.errors.InputError: h.json: 1.05e+06 MiB is more than the 256 MiB allowed for \
handle files (set ARAPKIT_MAX_INPUT_MB to raise the cap)
    """
    cap = input_cap_mb()
    if size > cap * 2**20:
        raise InputError(
            f"{path}: {size / 2**20:.3g} MiB is more than the {cap:g} MiB allowed "
            f"for {what} (set {INPUT_CAP_VARIABLE} to raise the cap)"
        )


#: bytes scanned at a time by :func:`json_depth`: its working arrays stay this small
_SCAN_CHUNK = 2**20


def json_depth(text: str | bytes) -> int:
    """Deepest bracket nesting of a JSON text, found without recursion.

    Strings are skipped, so brackets inside them do not count. The text is scanned in
    chunks of :data:`_SCAN_CHUNK` bytes, so the scan needs little memory beyond the text
    (a regular expression over the strings kept a backtracking record per character and
    took over 100 times the text's size on one long string).

    Examples
    --------
    >>> json_depth('[{"a": "[[["}, [1]]')
    2
    >>> json_depth(r'["\\\\", "\\"[[", [[]]]')
    3
    """
    data = text.encode("utf-8", "surrogatepass") if isinstance(text, str) else bytes(text)
    if b"\\" in data:
        # escapes, left to right as a JSON reader takes them: first every escaped
        # backslash, then every escaped quote; the quotes left open and close strings
        data = data.replace(b"\\\\", b"__").replace(b'\\"', b"__")
    inside, depth, deepest = 0, 0, 0
    for start in range(0, len(data), _SCAN_CHUNK):
        b = np.frombuffer(data, np.uint8, min(_SCAN_CHUNK, len(data) - start), start)
        # quote parity so far, counted in uint8 (wrapping keeps the parity)
        in_string = (np.cumsum(b == ord('"'), dtype=np.uint8) + inside) & 1
        inside = int(in_string[-1])
        opens = ((b == ord("[")) | (b == ord("{"))) & (in_string == 0)
        closes = ((b == ord("]")) | (b == ord("}"))) & (in_string == 0)
        step = opens.astype(np.int64) - closes
        level = np.cumsum(step[opens | closes]) + depth
        if len(level):
            deepest, depth = max(deepest, int(level.max())), int(level[-1])
    return deepest


def parse_json(text: str | bytes, source: str, limit: int = MAX_JSON_DEPTH) -> Any:
    """Parse JSON with a one-line error for bad syntax or nesting deeper than ``limit``.

    Examples
    --------
    >>> parse_json("[1, 2]", "h.json")
    [1, 2]
    >>> parse_json("[" * 100000 + "]" * 100000, "h.json")
    Traceback (most recent call last):
    ...
    arapkit.errors.InputError: h.json: JSON too deeply nested (100000 levels; at most 64)
    """
    depth = json_depth(text)  # on the bytes when given bytes: no second copy of the text
    if depth > limit:
        raise InputError(f"{source}: JSON too deeply nested ({depth} levels; at most {limit})")
    if isinstance(text, bytes):
        try:
            text = text.decode("utf-8")
        except UnicodeDecodeError:
            raise InputError(f"{source}: not a UTF-8 text file") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as e:
        where = f"line {e.lineno} column {e.colno}"
        raise InputError(f"{source}: not valid JSON ({e.msg} at {where})") from None
    except RecursionError:  # belt and braces: the depth scan should have caught it
        raise InputError(f"{source}: JSON too deeply nested") from None
    except ValueError as e:  # e.g. integers with more than 4300 digits
        raise InputError(f"{source}: not valid JSON ({_show(e)})") from None


def keys_of(d: Any, allowed: Sequence[str], what: str) -> dict:
    """``d`` if it is a dict whose keys are all in ``allowed``.

    Examples
    --------
    >>> keys_of({"a": 1}, ("a", "b"), "solver")
    {'a': 1}
    """
    if not isinstance(d, dict):
        raise InputError(f"{what}: expected an object, got {type(d).__name__}")
    unknown = sorted(str(k) for k in d if k not in allowed)
    if unknown:
        raise InputError(f"{what}: unknown key {_show(unknown[0])} (allowed: {', '.join(allowed)})")
    return d
