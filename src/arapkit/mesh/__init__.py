"""What a shape is: the triangle mesh model, point clouds and graphs, edge graphs, weights,
welding and quality.

Files are read and written by :mod:`arapkit.io` (one layer up). ``from arapkit.mesh import
load_mesh`` still works for one release, with a :class:`DeprecationWarning`.

Examples
--------
>>> from arapkit.mesh import Mesh
>>> Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]]).n_vertices
3
"""

import importlib
import warnings
from typing import Any

from .cloud import Graph, PointCloud, as_shape
from .model import (
    COORDINATE_RANGE,
    EdgeTopology,
    Mesh,
    bounding_box_diagonal,
    check_number_range,
    scale_free_vertices,
)
from .welding import weld

__all__ = ["COORDINATE_RANGE", "EdgeTopology", "Graph", "Mesh", "PointCloud", "as_shape",
           "bounding_box_diagonal", "check_number_range", "scale_free_vertices", "weld"]

#: names the flat ``arapkit.mesh`` module had that now live in a higher layer
_MOVED_UP = {"load_mesh": "arapkit.io.readers"}


def __getattr__(name: str) -> Any:
    # fetched at call time: importing arapkit.io here would be an upward import
    if name in _MOVED_UP:
        new = _MOVED_UP[name]
        warnings.warn(f"arapkit.mesh.{name} moved to {new}.{name}; the old path goes in the "
                      "next release", DeprecationWarning, stacklevel=2)
        return getattr(importlib.import_module(new), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
