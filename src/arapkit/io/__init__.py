"""Files <-> objects: mesh readers and writers, handle and rigidity files, safe output.

The public names of every io module are available here (``from arapkit.io import
save_mesh``); the old paths ``arapkit.fileio``, ``arapkit.handles`` and
``arapkit.meshwriters`` point at this package for one release.

Modules
-------
formats   the readable, writable and figure formats (one list each)
readers   :func:`load_mesh`, :func:`read_ply_vertex_properties`
clouds    :func:`load_points` (files without faces), :func:`load_shape` (mesh or cloud)
cloud_writer  :func:`save_points` (a cloud with its normals, colours and properties)
ply       the PLY format read whole (:func:`read_ply`: every element, property and list)
writers   :func:`save_mesh` (plain, or with everything the source carried)
atomic    atomic output, output-path checks, strict JSON
arrays    :func:`load_numpy` for user-given ``.npy`` / ``.npz`` files
handles   handle JSON files; :func:`load_handles` also reads ``.sel`` + ``.def``
seldef    the benchmark ``.sel`` / ``.def`` files
rigidity  per-vertex rigidity maps (text, ``.npy``, PLY)
text      capped text files read as tokens

The vertex selections and handle records (:func:`select_box`, :class:`HandleSet` ...)
live in :mod:`arapkit.mesh.selection` and are re-exported here, as the old
``arapkit.handles`` had them.

Examples
--------
>>> from arapkit.io import load_mesh, save_mesh, select_box
>>> save_mesh.__module__
'arapkit.io.writers'
"""

from ..mesh.selection import (
    HandleGroup,
    HandleSet,
    rotation_matrix,
    select_box,
    select_nearest,
    select_sphere,
)
from .arrays import load_numpy
from .atomic import atomic_open, atomic_write, check_output_path, to_jsonable, write_json
from .cloud_writer import CLOUD_WRITE_FORMATS, save_points
from .clouds import CLOUD_READ_FORMATS, load_points, load_shape
from .formats import (
    FIGURE_FORMATS,
    MESH_FORMATS,
    READ_FORMATS,
    check_figure_format,
    is_readable_mesh,
    mesh_format,
    readable_formats,
)
from .groups import groups_to_json, load_groups, parse_groups, save_groups
from .handles import (
    COMMENT_KEY,
    GROUP_KEYS,
    MOTION_KEYS,
    SELECTION_KEYS,
    handles_to_json,
    load_handles,
    parse_handles,
    save_handles,
)
from .ply import PlyFile, read_ply
from .readers import load_mesh, read_ply_vertex_properties
from .rigidity import load_rings, save_rings
from .seldef import load_def, load_sel, save_def, save_sel
from .text import int_tokens, read_text, text_tokens
from .writers import ply_property_column, save_mesh, write_with_attributes

__all__ = [
    "CLOUD_READ_FORMATS",
    "CLOUD_WRITE_FORMATS",
    "COMMENT_KEY",
    "FIGURE_FORMATS",
    "GROUP_KEYS",
    "HandleGroup",
    "HandleSet",
    "MESH_FORMATS",
    "MOTION_KEYS",
    "PlyFile",
    "READ_FORMATS",
    "SELECTION_KEYS",
    "atomic_open",
    "atomic_write",
    "check_figure_format",
    "check_output_path",
    "groups_to_json",
    "handles_to_json",
    "int_tokens",
    "is_readable_mesh",
    "load_def",
    "load_groups",
    "load_handles",
    "load_mesh",
    "load_numpy",
    "load_points",
    "load_rings",
    "load_sel",
    "load_shape",
    "mesh_format",
    "parse_groups",
    "parse_handles",
    "ply_property_column",
    "read_ply",
    "read_ply_vertex_properties",
    "read_text",
    "readable_formats",
    "rotation_matrix",
    "save_def",
    "save_groups",
    "save_handles",
    "save_mesh",
    "save_points",
    "save_rings",
    "save_sel",
    "select_box",
    "select_nearest",
    "select_sphere",
    "text_tokens",
    "to_jsonable",
    "write_json",
    "write_with_attributes",
]
