"""The PLY format read whole: header, elements, scalar and list properties, every encoding.

:func:`read_ply` turns the bytes of a PLY file (ASCII, binary little or big endian) into a
:class:`PlyFile`: every element with every property in its file type, the lists of every
record with their own lengths (triangles and quads mixed, in binary files too), and the
header's ``comment`` and ``obj_info`` lines. Anything malformed -- a bad header, an unknown
type, a file shorter than its header's counts, a list that runs past the end, data left
over after the last element, a value that does not fit its type -- is one
:class:`~arapkit.errors.InputError` line naming the file (and the line, for ASCII).

Binary elements of fixed-size records (and lists that all have the first record's length)
are one ``np.frombuffer``; lists of varying length are walked by a compiled scan. ASCII
numbers are parsed by NumPy in one call per element (integers alone, which is 7x faster,
when every property of the element is an integer).

Examples
--------
>>> data = (b"ply\\nformat ascii 1.0\\ncomment made by hand\\nelement vertex 4\\n"
...         b"property float x\\nproperty float y\\nproperty float z\\nproperty uchar red\\n"
...         b"element face 2\\nproperty list uchar int vertex_indices\\nend_header\\n"
...         b"0 0 0 255\\n1 0 0 0\\n1 1 0 7\\n0 1 0 9\\n4 0 1 2 3\\n3 0 2 3\\n")
>>> ply = read_ply(data, "quad.ply")
>>> ply.elements["vertex"].data["red"].tolist(), ply.comments
([255, 0, 7, 9], ['comment made by hand'])
>>> faces = ply.elements["face"].data["vertex_indices"]
>>> faces.sizes.tolist(), faces.values.tolist()
([4, 3], [0, 1, 2, 3, 0, 2, 3])
"""

from __future__ import annotations

import re
import warnings
from dataclasses import dataclass, field

import numba as nb
import numpy as np

from ..errors import InputError

__all__ = ["PLY_TYPES", "PlyElement", "PlyFile", "PlyList", "PlyProperty", "ply_property_column",
           "read_ply"]

#: PLY type names -> NumPy type codes: the standard names, their sized aliases, and the
#: 64-bit and half types that trimesh reads and writes
PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
    "int64": "i8", "uint64": "u8", "float16": "f2",
}
_ENCODINGS = {"ascii": "", "binary_little_endian": "<", "binary_big_endian": ">"}
# the header ends at a line of its own that reads end_header
_END_HEADER = re.compile(rb"^end_header[ \t]*\r?$", re.MULTILINE)
_TOKEN = re.compile(rb"[^\x00-\x20]+")


@dataclass
class PlyProperty:
    """One property of an element: a scalar, or a list with the type of its length.

    Examples
    --------
    >>> PlyProperty("vertex_indices", np.dtype("i4"), np.dtype("u1")).is_list
    True
    """

    name: str
    dtype: np.dtype
    count_dtype: np.dtype | None = None

    @property
    def is_list(self) -> bool:
        """Whether every record holds a list of values here."""
        return self.count_dtype is not None


@dataclass
class PlyList:
    """A list property: the length of every record's list, and all values in file order.

    Examples
    --------
    >>> lst = PlyList(np.array([3, 1]), np.array([5, 6, 7, 8]))
    >>> [v.tolist() for v in lst.split()]
    [[5, 6, 7], [8]]
    """

    sizes: np.ndarray
    values: np.ndarray

    def split(self) -> list[np.ndarray]:
        """The lists one by one."""
        return np.split(self.values, np.cumsum(self.sizes)[:-1])


@dataclass
class PlyElement:
    """An element (``vertex``, ``face`` ...): its record count, properties and data.

    ``data`` maps every property name to an array of its values (in the property's type,
    native byte order) or, for a list property, a :class:`PlyList`.
    """

    name: str
    count: int
    properties: list[PlyProperty] = field(default_factory=list)
    data: dict[str, np.ndarray | PlyList] = field(default_factory=dict)


@dataclass
class PlyFile:
    """A whole PLY file: the encoding, the elements in file order, the header notes.

    ``comments`` and ``obj_info`` are the header lines of that keyword, verbatim and in
    file order; ``header_notes`` has both kinds together, in the order of the header.
    """

    encoding: str
    elements: dict[str, PlyElement]
    header_notes: list[str] = field(default_factory=list)

    @property
    def comments(self) -> list[str]:
        """The ``comment`` lines of the header."""
        return [n for n in self.header_notes if n.split(None, 1)[0] == "comment"]

    @property
    def obj_info(self) -> list[str]:
        """The ``obj_info`` lines of the header."""
        return [n for n in self.header_notes if n.split(None, 1)[0] == "obj_info"]


def read_ply(data: bytes, path: str) -> PlyFile:
    """Every element of the PLY file whose bytes are ``data`` (``path`` names it in errors).

    Parameters
    ----------
    data : bytes
        The whole file (already gunzipped).
    path : str
        The file's name, for the messages.

    Returns
    -------
    PlyFile

    Raises
    ------
    InputError
        The header or the data is malformed (one line naming ``path``).

    Examples
    --------
    >>> import numpy as np
    >>> head = (b"ply\\nformat binary_big_endian 1.0\\nelement vertex 2\\n"
    ...         b"property double x\\nproperty int rings\\nend_header\\n")
    >>> rec = np.array([(0.5, 3), (1.5, 7)], dtype=[("x", ">f8"), ("rings", ">i4")])
    >>> read_ply(head + rec.tobytes(), "v.ply").elements["vertex"].data["rings"].tolist()
    [3, 7]
    """
    ply, body, first_line = _parse_header(data, path)
    if ply.encoding == "ascii":
        _read_ascii(data, body, first_line, ply, path)
    else:
        _read_binary(data, body, _ENCODINGS[ply.encoding], ply, path)
    return ply


# --------------------------------------------------------------------------- header


def _parse_header(data: bytes, path: str) -> tuple[PlyFile, int, int]:
    """The header as a :class:`PlyFile` without data, where the data starts, and its line."""
    if not data.startswith(b"ply"):
        raise InputError(f"{path}: not a PLY file (it does not start with 'ply')")
    end = _END_HEADER.search(data)
    if end is None:
        raise InputError(f"{path}: PLY header has no end_header line")
    body = end.end() + (data[end.end() : end.end() + 1] == b"\n")
    # latin-1 maps bytes to characters one to one: comments are written back byte for byte
    lines = [ln.rstrip("\r") for ln in data[: end.start()].decode("latin-1").split("\n")]
    lines = lines[:-1]  # the text before end_header ends with its newline
    if lines[0].strip() != "ply":
        raise InputError(f"{path}: not a PLY file (the first line is not 'ply')")
    fmt = lines[1].split() if len(lines) > 1 else []
    if len(fmt) < 2 or fmt[0] != "format" or fmt[1] not in _ENCODINGS:
        raise InputError(
            f"{path}: PLY header line 2: expected 'format ascii|binary_little_endian|"
            f"binary_big_endian 1.0', found {lines[1].strip() if len(lines) > 1 else ''!r}"
        )
    ply = PlyFile(fmt[1], {})
    element: PlyElement | None = None
    for no, line in enumerate(lines[2:], 3):
        words = line.split()
        if not words:
            continue
        where = f"{path}: PLY header line {no}"
        if words[0] in ("comment", "obj_info"):
            ply.header_notes.append(line.rstrip("\r\n"))
        elif words[0] == "element":
            element = _element(words, where, path)
            if element.name in ply.elements:
                raise InputError(f"{where}: element {element.name!r} declared twice")
            ply.elements[element.name] = element
        elif words[0] == "property":
            if element is None:
                raise InputError(f"{where}: a property before any element")
            prop = _property(words, where)
            if any(p.name == prop.name for p in element.properties):
                raise InputError(
                    f"{where}: element {element.name!r} has two properties {prop.name!r}"
                )
            element.properties.append(prop)
        else:
            raise InputError(f"{where}: unexpected {line.strip()!r}")
    return ply, body, len(lines) + 2


def _element(words: list[str], where: str, path: str) -> PlyElement:
    if len(words) != 3:
        raise InputError(f"{where}: expected 'element <name> <count>'")
    try:
        count = int(words[2])
    except ValueError:
        # (the header line's number is in `where`; this wording is older than it)
        raise InputError(
            f"{path}: PLY header: element {words[1]!r} has count {words[2]!r}, "
            "not a whole number"
        ) from None
    if count < 0:
        raise InputError(f"{where}: element {words[1]!r} has a negative count ({count})")
    return PlyElement(words[1], count)


def _type(name: str, where: str) -> np.dtype:
    if name not in PLY_TYPES:
        raise InputError(f"{where}: unknown property type {name!r}")
    return np.dtype(PLY_TYPES[name])


def _property(words: list[str], where: str) -> PlyProperty:
    if len(words) == 3:
        return PlyProperty(words[2], _type(words[1], where))
    if len(words) == 5 and words[1] == "list":
        count = _type(words[2], where)
        if count.kind not in "iu" or count.itemsize > 4:
            raise InputError(f"{where}: list length type {words[2]!r} is not an integer type")
        return PlyProperty(words[4], _type(words[3], where), count)
    raise InputError(
        f"{where}: expected 'property <type> <name>' or 'property list <type> <type> <name>'"
    )


# --------------------------------------------------------------------------- values


def _typed(values: np.ndarray, dtype: np.dtype) -> tuple[np.ndarray, int]:
    """``values`` in ``dtype``, and the first value that an integer type cannot hold (or -1).

    An integer type takes only whole numbers in its range (ASCII files are parsed as
    float64 or int64 first).
    """
    if dtype.kind not in "iu":
        with np.errstate(over="ignore"):  # beyond a float32: inf, as a binary file can hold
            return values.astype(dtype), -1
    with np.errstate(invalid="ignore", over="ignore"):
        out = values.astype(dtype)
        bad = np.flatnonzero(out != values)
    return out, int(bad[0]) if len(bad) else -1


# --------------------------------------------------------------------------- binary


def _native(values: np.ndarray, dtype: np.dtype) -> np.ndarray:
    """A copy of file values in native byte order (any bit pattern: a signalling NaN too)."""
    with np.errstate(all="ignore"):
        return values.astype(dtype)


def _read_binary(data: bytes, pos: int, endian: str, ply: PlyFile, path: str) -> None:
    buf = np.frombuffer(data, dtype=np.uint8)
    for el in ply.elements.values():
        if not el.properties:
            continue
        if any(p.is_list for p in el.properties):
            pos = _binary_lists(data, buf, pos, endian, el, path)
            continue
        rec_dt = np.dtype([(p.name, p.dtype.newbyteorder(endian)) for p in el.properties])
        if pos + el.count * rec_dt.itemsize > len(data):
            have = (len(data) - pos) // max(rec_dt.itemsize, 1)
            raise InputError(f"{path}: truncated: the header promises {el.count} "
                             f"{el.name} records, the file holds {have}")
        rec = np.frombuffer(data, dtype=rec_dt, count=el.count, offset=pos)
        el.data = {p.name: _native(rec[p.name], p.dtype) for p in el.properties}
        pos += el.count * rec_dt.itemsize
    if data[pos:].strip(b" \t\r\n\0"):
        raise InputError(f"{path}: {len(data) - pos} bytes after the last element: the "
                         "header's counts do not match the data")


def _binary_lists(data: bytes, buf: np.ndarray, pos: int, endian: str, el: PlyElement,
                  path: str) -> int:
    """Read element ``el`` (which has list properties) at ``pos``; return where it ends.

    Records whose lists all have the first record's lengths are one ``frombuffer``;
    otherwise a compiled scan finds where every property of every record starts.
    """
    props = el.properties
    uniform = _uniform_records(data, buf, pos, endian, el)
    if uniform is not None:
        return uniform
    layout = np.array([[int(p.is_list), p.dtype.itemsize,
                        p.count_dtype.itemsize if p.is_list else 0,
                        int(p.is_list and p.count_dtype.kind == "i")] for p in props],
                      dtype=np.int64)
    # a record takes at least its scalars and list lengths: a header count that cannot
    # fit in the file is refused before anything of its size is allocated
    if el.count * int(np.where(layout[:, 0] == 1, layout[:, 2], layout[:, 1]).sum()) \
            > len(data) - pos:
        raise InputError(f"{path}: truncated: the header promises {el.count} {el.name} "
                         "records, more than the rest of the file can hold")
    starts, sizes, end, status, bad = _scan_records(buf, pos, el.count, layout,
                                                    endian == ">")
    if status == 1:
        raise InputError(f"{path}: truncated: {el.name} {bad} of {el.count} runs past the "
                         "end of the file (a list length or the header's count is wrong)")
    if status == 2:
        raise InputError(f"{path}: {el.name} {bad}: a negative list length")
    for j, p in enumerate(props):
        file_dt = p.dtype.newbyteorder(endian)
        if p.is_list:
            n = sizes[:, j]
            raw = _gather(buf, starts[:, j] + layout[j, 2], n * layout[j, 1])
            el.data[p.name] = PlyList(n, _native(raw.view(file_dt), p.dtype))
        else:
            raw = _gather(buf, starts[:, j], np.full(el.count, layout[j, 1]))
            el.data[p.name] = _native(raw.view(file_dt), p.dtype)
    return end


def _uniform_records(data: bytes, buf: np.ndarray, pos: int, endian: str,
                     el: PlyElement) -> int | None:
    """Read ``el`` as records of one size (every list as long as the first record's).

    Returns where the element ends, or None (nothing read) when the records differ.
    """
    if el.count == 0:
        return _empty(el, pos)
    fields: list[tuple] = []
    width: dict[int, int] = {}
    at = pos
    for j, p in enumerate(el.properties):
        if not p.is_list:
            fields.append((f"s{j}", p.dtype.newbyteorder(endian)))
            at += p.dtype.itemsize
            continue
        cdt = p.count_dtype.newbyteorder(endian)
        if at + cdt.itemsize > len(data):
            return None
        k = width[j] = int(np.frombuffer(data, dtype=cdt, count=1, offset=at)[0])
        if k < 0:
            return None
        fields += [(f"n{j}", cdt), (f"v{j}", p.dtype.newbyteorder(endian), (k,))]
        at += cdt.itemsize + k * p.dtype.itemsize
        if at > len(data):  # (the scan says where)
            return None
    rec_dt = np.dtype(fields)
    if pos + el.count * rec_dt.itemsize > len(data):
        return None
    rec = np.frombuffer(data, dtype=rec_dt, count=el.count, offset=pos)
    if any(np.any(rec[f"n{j}"] != k) for j, k in width.items()):
        return None
    for j, p in enumerate(el.properties):
        if p.is_list:
            el.data[p.name] = PlyList(np.full(el.count, width[j], dtype=np.int64),
                                      _native(rec[f"v{j}"].reshape(-1), p.dtype))
        else:
            el.data[p.name] = _native(rec[f"s{j}"], p.dtype)
    return pos + el.count * rec_dt.itemsize


def _empty(el: PlyElement, pos: int) -> int:
    el.data = {p.name: (PlyList(np.zeros(0, np.int64), np.zeros(0, p.dtype)) if p.is_list
                        else np.zeros(0, p.dtype)) for p in el.properties}
    return pos


@nb.njit(cache=True, nogil=True)
def _scan_records(buf, pos, count, layout, big):  # pragma: no cover - compiled
    """Where every property of every record starts, and every list's length.

    ``layout[j]`` is (is list, value size, length size, length signed). Returns
    (starts, sizes, end, status, record): status 0 read, 1 past the end, 2 negative length.
    """
    nprop = layout.shape[0]
    starts = np.zeros((count, nprop), dtype=np.int64)
    sizes = np.zeros((count, nprop), dtype=np.int64)
    n = buf.shape[0]
    for i in range(count):
        for j in range(nprop):
            starts[i, j] = pos
            if layout[j, 0] == 0:
                pos += layout[j, 1]
                continue
            width = layout[j, 2]
            if pos + width > n:
                return starts, sizes, pos, 1, i
            k = np.int64(0)
            for b in range(width):
                byte = np.int64(buf[pos + (width - 1 - b if big else b)])
                k |= byte << (8 * b)
            if layout[j, 3] == 1 and k >= (np.int64(1) << (8 * width - 1)):
                k -= np.int64(1) << (8 * width)
            if k < 0:
                return starts, sizes, pos, 2, i
            sizes[i, j] = k
            pos += width + k * layout[j, 1]
            if pos > n:
                return starts, sizes, pos, 1, i
        if pos > n:
            return starts, sizes, pos, 1, i
    return starts, sizes, pos, 0, count


@nb.njit(cache=True, nogil=True)
def _gather(buf, starts, lengths):  # pragma: no cover - compiled
    """The bytes ``buf[starts[i] : starts[i] + lengths[i]]`` of every i, one after another."""
    out = np.empty(lengths.sum(), dtype=np.uint8)
    o = 0
    for i in range(starts.shape[0]):
        s = starts[i]
        for b in range(lengths[i]):
            out[o + b] = buf[s + b]
        o += lengths[i]
    return out


# --------------------------------------------------------------------------- ASCII


def _read_ascii(data: bytes, pos: int, first_line: int, ply: PlyFile, path: str) -> None:
    """Read every element of an ASCII body: one record per line (blank lines skipped)."""
    body = data[pos:]
    b = np.frombuffer(body, dtype=np.uint8)
    line_start = np.concatenate([[0], np.flatnonzero(b == 10) + 1])
    line_end = np.append(line_start[1:], len(b))
    space = b <= 32  # spaces, tabs, carriage returns, newlines (and other control bytes)
    word = ~space
    word[1:] &= space[:-1]
    token_at = np.flatnonzero(word)  # where every token starts
    first_token = np.searchsorted(token_at, line_start)
    tokens = np.diff(np.append(first_token, len(token_at)))
    lines = np.flatnonzero(tokens)  # the non-blank lines
    done = 0
    for el in ply.elements.values():
        if not el.properties:
            continue
        rows = lines[done : done + el.count]
        if len(rows) < el.count:
            raise InputError(f"{path}: truncated: the header promises {el.count} "
                             f"{el.name} records, the file has {len(rows)} more lines")
        done += el.count
        if el.count == 0:
            _empty(el, 0)
            continue

        def where(i: int, rows=rows) -> str:
            return f"{path}: line {first_line + int(rows[i])}"

        lo, hi = line_start[rows[0]], line_end[rows[-1]]
        integral = all(p.dtype.kind in "iu" for p in el.properties)
        nums = _numbers(body[lo:hi], int(tokens[rows].sum()), integral)
        if nums is None:
            for i, r in enumerate(rows):
                for tok in body[line_start[r] : line_end[r]].split():
                    try:
                        float(tok)
                    except ValueError:
                        raise InputError(f"{where(i)}: {tok.decode('latin-1')!r} is not a "
                                         "number") from None
            raise InputError(f"{where(0)}: malformed numbers in {el.name} records")
        base = int(first_token[rows[0]])

        def token(g: int, base=base) -> bytes:
            return _TOKEN.match(body, int(token_at[base + g])).group()

        _ascii_element(nums, tokens[rows], el, where, token)
    if done < len(lines):
        raise InputError(f"{path}: line {first_line + int(lines[done])}: data after the last "
                         "element (the header's counts do not match the data)")


def _numbers(text: bytes, expected: int, integral: bool) -> np.ndarray | None:
    """The ``expected`` numbers of ``text`` (int64 when ``integral`` allows), or None."""
    for dtype in ((np.int64, np.float64) if integral else (np.float64,)):
        with warnings.catch_warnings():
            # NumPy < 2.3 warns and stops at a malformed token, later ones raise
            warnings.simplefilter("ignore", DeprecationWarning)
            try:
                out = np.fromstring(text, dtype=dtype, sep=" ")
            except ValueError:
                continue
        info = np.iinfo(np.int64)
        # an integer beyond int64 saturates: read it as a float, then refused by its type
        if len(out) == expected and not (dtype is np.int64 and len(out) and (
                out.max() == info.max or out.min() == info.min)):
            return out
    return None


def _exact_ints(tokens: list[bytes], dtype: np.dtype) -> tuple[np.ndarray, int]:
    """64-bit integers from their text (a double cannot hold them all), and the first bad."""
    out = np.zeros(len(tokens), dtype=dtype)
    info = np.iinfo(dtype)
    for i, tok in enumerate(tokens):
        try:
            v = int(tok)
        except ValueError:
            f = float(tok)
            v = int(f) if f.is_integer() else None
        if v is None or not info.min <= v <= info.max:
            return out, i
        out[i] = v
    return out, -1


def _ascii_element(nums: np.ndarray, t: np.ndarray, el: PlyElement, where, token) -> None:
    """Split the numbers of ``el``'s records (``t[i]`` on record i) into its properties.

    ``where(i)`` is the file and line of record i and ``token(g)`` the text of the
    element's number g, for the messages and for 64-bit integers.
    """
    name, n = el.name, el.count

    def typed(at: np.ndarray, dtype: np.dtype, what: str, record_of=lambda m: m):
        """The numbers ``at`` in ``dtype`` (64-bit integers from their text)."""
        if dtype.kind in "iu" and dtype.itemsize == 8:
            out, bad = _exact_ints([token(g) for g in at.tolist()], dtype)
            shown = token(int(at[bad])).decode("latin-1") if bad >= 0 else ""
        else:
            out, bad = _typed(nums[at], dtype)
            shown = repr(nums[at[bad]].item()) if bad >= 0 else ""
        if bad >= 0:
            i = int(record_of(bad))
            raise InputError(f"{where(i)}: {name} {i}: {what} {shown} is not a whole number "
                             f"in the range of {dtype.name}")
        return out

    def count_error(i: int, what: str) -> InputError:
        return InputError(f"{where(i)}: {name} {i} has {t[i]} numbers, {what}")

    start = np.concatenate([[0], np.cumsum(t)[:-1]])  # each record's first number
    if not any(p.is_list for p in el.properties):
        width = len(el.properties)
        bad = np.flatnonzero(t != width)
        if len(bad):
            raise count_error(int(bad[0]), f"the header's properties take {width}")
        for j, p in enumerate(el.properties):
            el.data[p.name] = typed(np.arange(j, n * width, width), p.dtype, p.name)
        return
    off = np.zeros(n, dtype=np.int64)
    for p in el.properties:
        short = np.flatnonzero(off >= t)
        if len(short):
            raise count_error(int(short[0]), "too few for the header's properties")
        if not p.is_list:
            el.data[p.name] = typed(start + off, p.dtype, p.name)
            off += 1
            continue
        k = typed(start + off, p.count_dtype, f"the length of {p.name}").astype(np.int64)
        off += 1
        negative = np.flatnonzero(k < 0)
        if len(negative):
            i = int(negative[0])
            raise InputError(f"{where(i)}: {name} {i}: a negative list length ({k[i]})")
        over = np.flatnonzero(off + k > t)
        if len(over):
            i = int(over[0])
            raise InputError(f"{where(i)}: {name} {i}: a list of {k[i]} values runs past "
                             "the end of its line")
        ends = np.cumsum(k)
        at = np.repeat(start + off - (ends - k), k) + np.arange(int(ends[-1]))
        el.data[p.name] = PlyList(k, typed(at, p.dtype, p.name, lambda m, e=ends: (
            np.searchsorted(e, m, side="right"))))
        off += k
    bad = np.flatnonzero(off != t)
    if len(bad):
        i = int(bad[0])
        raise count_error(i, f"the header's properties take {off[i]}")


def ply_property_column(name: str, values, n: int) -> np.ndarray:
    """A vertex property as PLY can hold it: n values, int32 for integers, else double.

    Examples
    --------
    >>> ply_property_column("rings", [1, 2], 2).dtype.name
    'int32'
    """
    arr = np.asarray(values)
    if arr.shape != (n,):
        raise ValueError(f"vertex property {name!r} has shape {arr.shape}, expected ({n},)")
    if not name.isidentifier():
        raise ValueError(f"vertex property name {name!r} is not a plain identifier")
    # PLY has no 64-bit integers: integers as int32, everything else as double
    return arr.astype(np.int32 if arr.dtype.kind in "iub" else np.float64)
