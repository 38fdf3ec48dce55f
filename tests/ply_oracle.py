"""An independent PLY writer and reader for the tests: plain Python, record by record.

Nothing here shares code with :mod:`arapkit.io.ply` or :mod:`arapkit.io.writers`: values
go through ``struct`` (binary) or ``repr`` (ASCII) one record at a time, so a test that
writes a file here and reads it with arapkit (or the other way round) checks arapkit
against a second implementation of the format. Slow: for test-sized files.

An element is ``(name, [(property, type, values), ...])``: ``type`` is a PLY type name
(``"uchar"``, ``"float"`` ...) for a scalar, with ``values`` one number per record, or
``("list", count_type, value_type)`` with ``values`` one sequence per record.
"""

from __future__ import annotations

import struct

import numpy as np

STRUCT = {"char": "b", "int8": "b", "uchar": "B", "uint8": "B", "short": "h", "int16": "h",
          "ushort": "H", "uint16": "H", "int": "i", "int32": "i", "uint": "I", "uint32": "I",
          "float": "f", "float32": "f", "double": "d", "float64": "d", "int64": "q",
          "uint64": "Q", "float16": "e"}
NUMPY = {"b": "i1", "B": "u1", "h": "i2", "H": "u2", "i": "i4", "I": "u4", "f": "f4",
         "d": "f8", "q": "i8", "Q": "u8", "e": "f2"}
ENDIAN = {"binary_little_endian": "<", "binary_big_endian": ">"}


def numpy_type(ply_type: str) -> np.dtype:
    """The NumPy type a PLY type name stands for."""
    return np.dtype(NUMPY[STRUCT[ply_type]])


def _text(value, ply_type: str) -> str:
    if STRUCT[ply_type] in "efd":
        # the shortest text that reads back as the same double (a float32 value is
        # exactly a double, so it reads back exactly too)
        return repr(float(value))
    return str(int(value))


def ply_bytes(encoding: str, elements, notes=(), newline: str = "\n") -> bytes:
    """A PLY file of ``elements``, with header lines ``notes`` (``comment ...``)."""
    head = ["ply", f"format {encoding} 1.0", *notes]
    for name, props in elements:
        count = len(props[0][2]) if props else 0
        head.append(f"element {name} {count}")
        for pname, ptype, _ in props:
            if isinstance(ptype, tuple):
                head.append(f"property list {ptype[1]} {ptype[2]} {pname}")
            else:
                head.append(f"property {ptype} {pname}")
    head.append("end_header")
    out = [(newline.join(head) + newline).encode("latin-1")]
    for _, props in elements:
        count = len(props[0][2]) if props else 0
        for i in range(count):
            if encoding == "ascii":
                toks = []
                for _, ptype, values in props:
                    if isinstance(ptype, tuple):
                        toks.append(str(len(values[i])))
                        toks += [_text(v, ptype[2]) for v in values[i]]
                    else:
                        toks.append(_text(values[i], ptype))
                out.append((" ".join(toks) + newline).encode())
                continue
            e = ENDIAN[encoding]
            for _, ptype, values in props:
                if isinstance(ptype, tuple):
                    vals = list(values[i])
                    out.append(struct.pack(e + STRUCT[ptype[1]], len(vals)))
                    out.append(struct.pack(e + STRUCT[ptype[2]] * len(vals), *vals))
                else:
                    out.append(struct.pack(e + STRUCT[ptype], values[i]))
    return b"".join(out)


def parse_ply(data: bytes) -> dict:
    """``{"format", "notes", "types", "elements"}`` of a PLY file, read record by record.

    ``elements`` maps each element to ``{property: list of values}`` (lists as lists);
    ``types`` maps ``(element, property)`` to the header's type (a tuple for lists).
    """
    end = data.index(b"end_header")
    body = data.index(b"\n", end) + 1
    lines = data[:end].decode("latin-1").split("\n")
    fmt = lines[1].split()[1]
    notes = [ln for ln in lines if ln.startswith(("comment", "obj_info"))]
    decl: list[tuple[str, int, list]] = []
    types = {}
    for ln in lines[2:]:
        w = ln.split()
        if w and w[0] == "element":
            decl.append((w[1], int(w[2]), []))
        elif w and w[0] == "property":
            t = ("list", w[2], w[3]) if w[1] == "list" else w[1]
            decl[-1][2].append((w[-1], t))
            types[decl[-1][0], w[-1]] = t
    elements = {name: {p: [] for p, _ in props} for name, _, props in decl}
    if fmt == "ascii":
        rows = iter(ln.split() for ln in data[body:].decode().splitlines() if ln.strip())
        for name, count, props in decl:
            for _ in range(count):
                toks = next(rows)
                k = 0
                for p, t in props:
                    if isinstance(t, tuple):
                        n = int(toks[k])
                        elements[name][p].append([float(x) for x in toks[k + 1 : k + 1 + n]])
                        k += 1 + n
                    else:
                        elements[name][p].append(float(toks[k]))
                        k += 1
                assert k == len(toks)
        return {"format": fmt, "notes": notes, "types": types, "elements": elements}
    e, pos = ENDIAN[fmt], body
    for name, count, props in decl:
        for _ in range(count):
            for p, t in props:
                if isinstance(t, tuple):
                    (n,) = struct.unpack_from(e + STRUCT[t[1]], data, pos)
                    pos += struct.calcsize(STRUCT[t[1]])
                    fmt_v = e + STRUCT[t[2]] * n
                    elements[name][p].append(list(struct.unpack_from(fmt_v, data, pos)))
                    pos += struct.calcsize(fmt_v)
                else:
                    (v,) = struct.unpack_from(e + STRUCT[t], data, pos)
                    elements[name][p].append(v)
                    pos += struct.calcsize(e + STRUCT[t])
    assert pos == len(data), (pos, len(data))
    return {"format": fmt, "notes": notes, "types": types, "elements": elements}
