"""Quadric decimation with each input vertex's home: runs in this process or as a script.

:mod:`arapkit.methods.multires` calls :func:`simplify` here, or runs this file as a script
in a child Python (arrays in and out through the pipes as ``.npy``): it imports NumPy and
``fast-simplification`` only, so that child starts in about 0.2 s, without arapkit.

Examples
--------
>>> from arapkit.mesh.shapes import bar
>>> m = bar(segments=(60, 8, 8))
>>> U, G, home = simplify(m.vertices.astype(np.float32), m.faces.astype(np.int64), 600)
>>> bool(len(home) == m.n_vertices and home.max() == len(U) - 1)
True
"""

from __future__ import annotations

import io
import sys

import numpy as np


def homes(n: int, faces: np.ndarray, collapses: np.ndarray,
          out_faces: np.ndarray) -> np.ndarray:
    """The output vertex each of the ``n`` input vertices was collapsed into (-1: none).

    fast-simplification records ``collapses[i] = [i0, i1]``: vertex ``i1`` merged into
    ``i0``. Following them gives each vertex its representative; the output keeps, in input
    order, the representatives that a face still uses (its ``compact_mesh``), so the
    output index is that one's rank among them. A vertex whose representative lost all its
    faces (a part collapsed away), or that no face used, has no home. The reading is
    checked: the input's surviving faces, renumbered so, must be ``out_faces`` exactly;
    where they are not (another version of the library), no vertex has a home.
    """
    rep = np.arange(n, dtype=np.int64)
    rep[collapses[:, 1]] = collapses[:, 0]
    while True:  # pointer jumping: each pass halves every chain
        nxt = rep[rep]
        if np.array_equal(nxt, rep):
            break
        rep = nxt
    RF = rep[faces]
    kept = (RF[:, 0] != RF[:, 1]) & (RF[:, 1] != RF[:, 2]) & (RF[:, 0] != RF[:, 2])
    alive = np.zeros(n, dtype=bool)
    alive[RF[kept].ravel()] = True
    rank = np.cumsum(alive) - 1
    if not np.array_equal(rank[RF[kept]], out_faces):
        return np.full(n, -1, dtype=np.int32)
    return np.where(alive[rep], rank[rep], -1).astype(np.int32)


def simplify(V: np.ndarray, F: np.ndarray,
             target_faces: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """fast-simplification to ``target_faces`` faces: its vertices, faces and :func:`homes`."""
    import fast_simplification

    U, G, collapses = fast_simplification.simplify(V, F, target_count=target_faces,
                                                   return_collapses=True)
    G = np.asarray(G)
    return np.asarray(U), G, homes(len(V), F, np.asarray(collapses, dtype=np.int64), G)


def _main() -> None:
    from numpy.lib import format as npf

    # numpy's .npy reader and writer need a seekable file: the pipes are read whole
    src = io.BytesIO(sys.stdin.buffer.read())
    V, F = npf.read_array(src), npf.read_array(src)
    out = io.BytesIO()
    for a in simplify(V, F, int(sys.argv[1])):
        npf.write_array(out, a, allow_pickle=False)
    sys.stdout.buffer.write(out.getvalue())


if __name__ == "__main__":
    _main()
