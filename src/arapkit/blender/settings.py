"""The ARAP Deform panel's choices, read from the library (no second list of methods).

The methods are those the method registry offers to the ``"blender"`` door
(:mod:`arapkit.methods.registry`); whether the panel shows the rigidity controls is the
method's ``rigidity_map`` capability. The edge weights are :data:`WEIGHT_KINDS` with the
library's default first, and the tolerance is the paper's relative energy test with the
library's default.

Examples
--------
>>> [name for name, label, _ in method_items()]
['rring', 'spokes-and-rims', 'sr-arap', 'smooth-arap']
>>> takes_rigidity_map("sr-arap")
False
>>> weight_items()[0][0]
'cotan-clamped'
"""

from __future__ import annotations

from ..mesh.weights import DEFAULT_WEIGHTS, WEIGHT_KINDS
from ..methods.registry import method, methods

__all__ = ["DEFAULT_MAX_ITER", "DEFAULT_TOL", "method_items", "takes_rigidity_map",
           "weight_items"]

#: the paper's stopping test, as :class:`arapkit.Deformer`
DEFAULT_TOL = 1e-3
#: the iteration cap of :class:`arapkit.Deformer`
DEFAULT_MAX_ITER = 1000

_WEIGHT_HELP = {
    "cotan": "raw cotangent weights (paper-exact; obtuse triangles can make the shape drift)",
    "cotan-clamped": "cotangent weights, negative ones clamped (the library's default)",
    "cotan-clamped-each": "each cotangent clamped before they are summed",
    "uniform": "every edge weighs the same",
}


def method_items() -> list[tuple[str, str, str]]:
    """(name, label, description) of each method the registry offers to Blender, in its
    order: the items of the panel's Method menu."""
    out = []
    for m in methods("blender"):
        what = "paints r per vertex" if m.rigidity_map else "no rigidity map"
        out.append((m.name, m.label, f"{m.label} ({what})"))
    return out


def takes_rigidity_map(name: str) -> bool:
    """Whether method ``name`` reads r per vertex (the panel shows the rigidity controls)."""
    return method(name, "blender").rigidity_map


def weight_items() -> list[tuple[str, str, str]]:
    """(name, label, description) of the edge weightings, the library's default first."""
    kinds = [DEFAULT_WEIGHTS, *(k for k in WEIGHT_KINDS if k != DEFAULT_WEIGHTS)]
    return [(k, k, _WEIGHT_HELP.get(k, k)) for k in kinds]
