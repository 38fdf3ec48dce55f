"""Vertex groups on a :class:`~arapkit.methods.deformer.Deformer`: which methods, shapes and
devices take them, the grouped problem, and its backend.

Shared-rotation groups (libigl's ``ARAPData.G``) and rigid parts are solved by
:mod:`arapkit.arap.grouped`; this module is the door's side of it: the one-line refusals,
and the backend wrapped where the problem has groups.

Examples
--------
>>> from arapkit.arap.problem import ARAPProblem
>>> from arapkit.mesh.groups import VertexGroups
>>> from arapkit.mesh.shapes import bar
>>> m = bar()
>>> p = ARAPProblem.from_mesh(m, [0], "rring", "cotan-clamped")
>>> g = VertexGroups.from_lists([("tip", [1, 2, 3], True)], m.n_vertices)
>>> grouped, kept = grouped_problem(p, g, "rring", "cpu")
>>> kept.names
('tip',)
"""

from __future__ import annotations

from ..arap.backends import make_backend
from ..arap.grouped import GroupedBackend, GroupedProblem, as_groups, with_groups
from ..arap.problem import ARAPProblem
from ..errors import InputError
from ..mesh.groups import VertexGroups
from .registry import method, methods

__all__ = ["backend_for", "grouped_problem", "refuse_groups", "ungrouped"]


def refuse_groups(energy: str) -> None:
    """Raise the one-line refusal for a method that takes no vertex groups."""
    takes = ", ".join(m.name for m in methods("library") if m.groups)
    raise InputError(f"groups: energy '{energy}' takes no vertex groups (these methods do: "
                     f"{takes})")


def grouped_problem(problem: ARAPProblem, groups, energy: str,
                    device: str) -> tuple[ARAPProblem, VertexGroups | None]:
    """``problem`` with ``groups`` (checked against the method, the dimension and the
    device), and the groups it kept (None where they change nothing)."""
    if not method(energy).groups:
        refuse_groups(energy)
    if problem.dim == 2:  # a part's fit and a pooled rotation are 3 x 3
        raise InputError("groups: vertex groups are solved in 3D; a planar shape takes none "
                         "(pass dim=3 to solve it in 3D)")
    g = as_groups(groups, problem.n_vertices)
    if g.rigid.any() and device != "cpu":
        raise InputError(f"{g.source}: rigid parts solve on device='cpu' (their merged "
                         "system is factorised there)")
    grouped = with_groups(problem, g)
    return grouped, (g if grouped is not problem else None)


def ungrouped(problem: ARAPProblem) -> ARAPProblem:
    """``problem`` without its groups (itself where it has none)."""
    return problem.without_groups() if isinstance(problem, GroupedProblem) else problem


def backend_for(problem: ARAPProblem, device: str):
    """The backend of ``problem`` on ``device``, wrapped where the problem has groups."""
    inner = make_backend(problem, device)
    return GroupedBackend(inner, problem) if isinstance(problem, GroupedProblem) else inner
