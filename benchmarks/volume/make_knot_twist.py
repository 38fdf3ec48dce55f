"""Write ``benchmarks/volume/knot1-twist.json``: one ring of knot1's tube turned, the rest fixed.

The ring is the tube at the top apex of ``../shared/data/meshes/knot1.off``: the vertices in a
sphere of radius 0.1 (1.5 tube radii; the tube radius is 0.068) about ``CENTRE``, the volume
centroid of the tube's cross-section there (found by averaging tet centroids in a thin slab
across the tube). It turns about ``AXIS``, the tube's local axis (the first principal axis
of the apex vertices), through ``CENTRE``. Every vertex farther than ``FREE`` from the ring
along the surface's edges (Dijkstra on edge lengths) is fixed, so only the tube on either
side of the apex, an outer arc with no other strand nearby, is free to deform.

Usage::

    python benchmarks/volume/make_knot_twist.py [DEGREES]      # default 135
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra

from arapkit import load_mesh
from arapkit.io import select_sphere

HERE = Path(__file__).resolve().parent
MESH = HERE.parents[2] / "shared" / "data" / "meshes" / "knot1.off"
CENTRE = [0.1374, 0.4302, 0.0633]
AXIS = [-0.9048, 0.0075, 0.4257]
RADIUS = 0.1
FREE = 0.3


def main(degrees: float = 135.0) -> None:
    m = load_mesh(MESH)
    V, E = m.vertices, m.edges
    ring = select_sphere(V, np.array(CENTRE), RADIUS)
    length = np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1)
    A = sp.coo_matrix((length, (E[:, 0], E[:, 1])), shape=(len(V), len(V))).tocsr()
    fixed = np.flatnonzero(dijkstra(A, directed=False, indices=ring, min_only=True) > FREE)
    comment = (
        f"knot1.off, a local twist of the tube: the ring of tube at the top apex (a sphere of "
        f"radius {RADIUS:g}, 1.5 tube radii, about the volume centroid of the tube's "
        f"cross-section there) turns {degrees:g} degrees about the tube's local axis (the "
        "first principal axis of the apex vertices) through that centroid. Every vertex "
        f"farther than {FREE:g} (edge-path distance on the surface) from the ring is fixed, so "
        "the free part is the tube on either side of the apex, an outer arc with no other "
        "strand nearby. No strand is driven through another. Made by make_knot_twist.py."
    )
    groups = [
        {"name": "rest of knot", "indices": [int(i) for i in fixed]},
        {"name": "apex ring", "sphere": {"center": CENTRE, "radius": RADIUS},
         "rotate": {"axis": AXIS, "degrees": degrees, "center": CENTRE}},
    ]
    text = ('{\n  "comment": ' + json.dumps(comment) + ',\n  "groups": [\n'
            + ",\n".join("    " + json.dumps(g) for g in groups) + "\n  ]\n}\n")
    (HERE / "knot1-twist.json").write_text(text)


if __name__ == "__main__":
    main(*(float(a) for a in sys.argv[1:2]))
