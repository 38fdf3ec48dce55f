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

from arapkit.cli.common import add_example_epilog
from arapkit.io import load_mesh
from arapkit.io.formats import readable_formats

__all__ = ["add_parser", "inspect_mesh", "run"]

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
            ["arapkit info examples/cactus.off", "arapkit info scan.ply.gz --json"]
        ),
    )
    p.add_argument("mesh", metavar="MESH", help=f"mesh file ({readable_formats()}; may be .gz)")
    p.add_argument("--json", action="store_true", help="print the facts as one JSON object")
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
    facts = inspect_mesh(load_mesh(args.mesh))
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
