"""Test-only oracle: libigl's tetrahedral ARAP (per-tet rotations, cotangent weights).

An independent reference for what the ARAP energy itself does on a tet mesh; used by
``tests/test_volume.py`` and ``benchmarks/bench_volume.py --libigl``.
"""

from __future__ import annotations

import numpy as np


def libigl_tet_arap(tm, handles, targets, iterations: int) -> np.ndarray:
    """libigl's ARAP on the tets of ``tm`` (an ``arapkit.methods.volumetric.TetMesh``); surface
    rows.

    Examples
    --------
    >>> from arapkit.methods.volumetric import TetMesh
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    >>> tm = TetMesh(V, np.array([[0, 1, 2, 3]]), 4)
    >>> U = libigl_tet_arap(tm, np.array([0, 1, 2]), V[:3] + 1.0, 100)
    >>> bool(np.abs(U - (V + 1.0)).max() < 1e-6)    # all handles translated: all moves
    True
    """
    import igl

    data = igl.ARAPData()
    data.max_iter = iterations
    igl.arap_precomputation(tm.vertices, tm.tets.astype(np.int64), 3,
                            np.asarray(handles, dtype=np.int32), data)
    return igl.arap_solve(targets, data, tm.vertices.copy())[: tm.n_surface]
