"""What a shape is: the triangle mesh model, its edge graph, weights, welding and quality.

Examples
--------
>>> from arapkit.mesh.model import Mesh
>>> Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]]).n_vertices
3
"""

from .model import COORDINATE_RANGE, Mesh, check_number_range, load_mesh, scale_free_vertices

__all__ = ["COORDINATE_RANGE", "Mesh", "check_number_range", "load_mesh", "scale_free_vertices"]
