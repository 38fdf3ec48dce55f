"""Test-only oracle: faces of a triangle mesh that intersect a face they share no vertex with.

Broad phase: axis-aligned bounding boxes of all faces, overlapping pairs found with a
k-d tree on the box centres. Narrow phase: libigl's exact-predicate-free Guigue-Devillers
test ``igl.tri_tri_intersection_test_3d``, one pair at a time (brute force, but only on
candidate pairs). Faces that share a vertex touch by construction and are not compared.
"""

from __future__ import annotations

import numpy as np


def self_intersecting_faces(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Indices of the faces that intersect a non-adjacent face (libigl narrow phase).

    Examples
    --------
    >>> import numpy as np
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0],
    ...               [0.2, 0.2, -1], [0.2, 0.2, 1], [0.3, 0.9, 0.0]])
    >>> self_intersecting_faces(V, np.array([[0, 1, 2], [3, 4, 5]])).tolist()
    [0, 1]
    """
    import igl
    from scipy.spatial import cKDTree

    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    P = V[F]  # (m, 3, 3)
    lo, hi = P.min(axis=1), P.max(axis=1)
    centre, half = (lo + hi) / 2, (hi - lo) / 2
    reach = 2 * float(np.linalg.norm(half, axis=1).max())
    pairs = cKDTree(centre).query_pairs(reach, output_type="ndarray")
    if len(pairs) == 0:
        return np.empty(0, dtype=np.int64)
    a, b = pairs[:, 0], pairs[:, 1]
    overlap = np.all(np.abs(centre[a] - centre[b]) <= half[a] + half[b], axis=1)
    share = (F[a][:, :, None] == F[b][:, None, :]).any(axis=(1, 2))
    a, b = a[overlap & ~share], b[overlap & ~share]
    hit = np.zeros(len(F), dtype=bool)
    for i, j in zip(a.tolist(), b.tolist()):
        if hit[i] and hit[j]:
            continue
        p, q = P[i], P[j]
        if igl.tri_tri_intersection_test_3d(p[0:1], p[1:2], p[2:3], q[0:1], q[1:2], q[2:3])[0]:
            hit[i] = hit[j] = True
    return np.flatnonzero(hit)
