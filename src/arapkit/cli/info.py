"""``arapkit info``: what a mesh contains and what the deformer would do about its problems.

Examples
--------
::

    arapkit info cow.off
    arapkit info scan.ply --json
"""

from __future__ import annotations

import argparse
import json
from typing import Any

import numpy as np

from arapkit.cli.common import add_example_epilog, add_graph_options, graph_options
from arapkit.io import load_shape
from arapkit.io.clouds import cloud_formats_text
from arapkit.io.formats import readable_formats

__all__ = ["add_parser", "inspect_cloud", "inspect_mesh", "run"]

#: Triangles with a corner angle below this (degrees) count as near-degenerate.
NEEDLE_DEGREES = 1.0
#: ``info`` calls a mesh a soup from this many single-triangle components ...
SOUP_TRIANGLES = 1000
#: ... or this many coincident vertices (and at least 1 % of all vertices).
SOUP_COINCIDENT = 10


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``info``."""
    p = subparsers.add_parser(
        "info",
        help="describe a mesh and how the deformer would treat its problems",
        description="Print vertex/face counts, connected components, boundary loops, "
        "degenerate and non-manifold elements of MESH, its bounding box and a guess of its up "
        "axis (for writing handle files and reading figures), and what arapkit deform would "
        "do about each problem.",
        **add_example_epilog(
            ["arapkit info examples/cactus.off", "arapkit info scan.ply.gz --json",
             "arapkit info cloud.xyz --neighbours 16"]
        ),
    )
    p.add_argument("mesh", metavar="MESH",
                   help=f"mesh file ({readable_formats()}; may be .gz), or a point cloud "
                   f"({cloud_formats_text()}; docs/clouds.md)")
    p.add_argument("--json", action="store_true", help="print the facts as one JSON object")
    # the graph decides a cloud's components, which the advice is about: the same options
    # as deform's, so that what info reports is what deform will solve on
    add_graph_options(p)
    return p


def _min_angles_deg(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Smallest corner angle of each triangle, in degrees."""
    P = V[F]
    out = np.full(len(F), 180.0)
    for c in range(3):
        a = P[:, (c + 1) % 3] - P[:, c]
        b = P[:, (c + 2) % 3] - P[:, c]
        cosang = np.einsum("ij,ij->i", a, b) / np.maximum(
            np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1), 1e-300
        )
        out = np.minimum(out, np.degrees(np.arccos(np.clip(cosang, -1.0, 1.0))))
    return out


def inspect_mesh(mesh) -> dict[str, Any]:
    """Facts about ``mesh`` and the deformer's policy for each problem found.

    Returns
    -------
    dict with counts and an ``"advice"`` list of sentences.

    Examples
    --------
    >>> from arapkit.mesh.shapes import bar
    >>> facts = inspect_mesh(bar())
    >>> facts["components"], facts["boundary_loops"]
    (1, 0)
    """
    from arapkit.errors import InputError
    from arapkit.mesh.model import Mesh, check_number_range, scale_free_vertices
    from arapkit.mesh.orientation import bounding_box, guess_up
    from arapkit.mesh.weights import cotangent_weights
    from arapkit.mesh.welding import soup_facts

    box, up = bounding_box(mesh.vertices), guess_up(mesh.vertices)
    loops = mesh.boundary_loops
    labels = mesh.component_labels
    comp_sizes = np.bincount(labels, minlength=mesh.n_components)
    try:
        check_number_range(mesh.vertices, mesh.name)
        number_range, shape = None, mesh
    except InputError as exc:
        # angles and cotangents do not depend on the scale: measure them on a copy
        # rescaled to unit size, which cannot overflow
        number_range = str(exc)
        shape = Mesh(scale_free_vertices(mesh.vertices), mesh.faces, name=mesh.name)
    needles = int(np.count_nonzero(_min_angles_deg(shape.vertices, shape.faces) < NEEDLE_DEGREES))
    w = cotangent_weights(shape)
    negative = int(np.count_nonzero(w < 0))
    facts: dict[str, Any] = {
        "file": mesh.name,
        "vertices": mesh.n_vertices,
        "faces": mesh.n_faces,
        "edges": len(mesh.edges),
        "components": mesh.n_components,
        "largest_component_vertices": int(comp_sizes.max()),
        "boundary_loops": len(loops),
        "boundary_edges": int(np.count_nonzero(mesh.edge_face_counts == 1)),
        "nonmanifold_edges": mesh.n_nonmanifold_edges,
        "unreferenced_vertices": len(mesh.unreferenced),
        "degenerate_faces_dropped": sum(mesh.dropped_faces.values()),
        "needle_faces": needles,
        "negative_cotan_weights": negative,
        **soup_facts(mesh),
        "bounding_box_diagonal": mesh.bounding_box_diagonal,
        "bounding_box_min": box.min.tolist(),
        "bounding_box_max": box.max.tolist(),
        "extents": box.extents.tolist(),
        "up_axis_guess": up.axis,
        "up_axis_confidence": up.confidence,
        "up_axis_reason": up.reason,
        "repairs_on_load": list(mesh.notes),
        "number_range": number_range,
    }
    facts["advice"] = _advice(facts)
    return facts


def inspect_cloud(cloud) -> dict[str, Any]:
    """Facts about a point cloud (``docs/clouds.md``) and what the deformer does with it.

    Examples
    --------
    >>> import numpy as np
    >>> from arapkit.mesh.cloud import PointCloud
    >>> facts = inspect_cloud(PointCloud(np.random.default_rng(0).random((50, 3))))
    >>> facts["points"], facts["graph"], facts["components"]
    (50, 'kNN, k = 10', 1)
    """
    from arapkit.mesh.orientation import bounding_box, guess_up

    box, up = bounding_box(cloud.vertices), guess_up(cloud.vertices)
    sizes = np.bincount(cloud.component_labels, minlength=cloud.n_components)
    attrs = cloud.attributes
    props = sorted(attrs.vertex_properties) if attrs is not None else []
    facts: dict[str, Any] = {
        "file": cloud.name,
        "points": cloud.n_vertices,
        "graph": cloud.graph_description,
        "edges": len(cloud.edges),
        "mean_edge_length": cloud.mean_edge_length,
        "components": cloud.n_components,
        "largest_component_points": int(sizes.max()),
        "isolated_points": len(cloud.unreferenced),
        "normals": cloud.normals is not None,
        "colours": attrs is not None and attrs.colors() is not None,
        "properties": props,
        "bounding_box_diagonal": cloud.bounding_box_diagonal,
        "bounding_box_min": box.min.tolist(),
        "bounding_box_max": box.max.tolist(),
        "extents": box.extents.tolist(),
        "up_axis_guess": up.axis,
        "up_axis_confidence": up.confidence,
        "up_axis_reason": up.reason,
        "repairs_on_load": list(cloud.notes),
    }
    advice = [f"on load: {note}" for note in cloud.notes]
    advice.append("a point cloud: solved on its graph with gaussian weights; r-ring ARAP and "
                  "embedded deformation apply, the methods on triangles do not")
    if cloud.n_components > 1:
        advice.append(f"{cloud.n_components} connected parts of the graph: each part without "
                      "a handle moves rigidly with the nearest part that has handles (raise "
                      "--neighbours to join parts the graph leaves apart)")
    facts["advice"] = advice
    return facts


def _advice(f: dict[str, Any]) -> list[str]:
    out = []
    for note in f["repairs_on_load"]:
        out.append(f"on load: {note}")
    if f.get("number_range"):
        out.append(f"number range: {f['number_range']}")
    soup = f["triangle_components"] >= SOUP_TRIANGLES or (
        f["coincident_vertices"] >= max(SOUP_COINCIDENT, f["vertices"] // 100))
    if soup:
        out.append(
            f"looks like a triangle soup or an unwelded file ({f['triangle_components']} "
            f"single-triangle components, {f['coincident_vertices']} coincident vertices): "
            "use --weld to merge coincident vertices for the solve (the output keeps the "
            "input's vertices)"
        )
    if f["components"] > 1:
        out.append(
            f"{f['components']} connected components: each component without a handle moves "
            "rigidly with the nearest part that has handles"
        )
    if f["boundary_loops"]:
        out.append(
            f"{f['boundary_loops']} boundary loop(s): open boundaries are supported; boundary "
            "vertices are free unless a handle holds them"
        )
    if f["nonmanifold_edges"]:
        out.append(
            f"{f['nonmanifold_edges']} non-manifold edge(s): kept; their weights sum over all "
            "incident faces, so expect creases there"
        )
    if f["needle_faces"]:
        out.append(
            f"{f['needle_faces']} near-degenerate face(s) (an angle below {NEEDLE_DEGREES:g} "
            "degree): cotangents are capped; try --weights uniform if the result shows spikes"
        )
    if f["negative_cotan_weights"]:
        out.append(
            f"{f['negative_cotan_weights']} negative raw cotangent weight(s) (obtuse "
            "triangles): the default weights (cotan-clamped) raise them to a small positive "
            "floor; with --weights cotan (the paper's) the rest shape may drift and the "
            "system may not factorise"
        )
    if not out:
        out.append("no problems found: a closed, clean, single-component surface")
    return out


def run(args: argparse.Namespace) -> int:
    """Execute ``arapkit info``; returns the exit status."""
    # a file without faces is a point cloud, on the graph deform would build
    shape = load_shape(args.mesh, **graph_options(args))
    facts = inspect_mesh(shape) if shape.faces is not None else inspect_cloud(shape)
    facts["file"] = args.mesh
    if args.json:
        from arapkit.io import to_jsonable

        print(json.dumps(to_jsonable(facts), indent=2))
        return 0
    width = max(len(k) for k in facts)
    for key, value in facts.items():
        if key in ("advice", "repairs_on_load", "number_range"):
            continue
        if key == "up_axis_confidence":
            value = f"{value:.2f}  (0 = a coin toss, 1 = certain; see docs/figures.md)"
        elif isinstance(value, float):
            value = f"{value:.6g}"
        elif isinstance(value, list) and all(isinstance(x, float) for x in value):
            value = "[" + ", ".join(f"{x:.6g}" for x in value) + "]"
        print(f"{key.replace('_', ' ') + ':':<{width + 2}}{value}")
    print("what arapkit deform would do:")
    for line in facts["advice"]:
        print(f"  - {line}")
    return 0
