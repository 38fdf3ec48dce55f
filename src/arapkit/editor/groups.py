"""Painted vertex groups in the editor: rigid parts and shared-rotation groups.

:class:`PaintedGroups` is what the *Paint part* tool edits: one id per vertex (-1: none)
and a name and kind per group. Like the rigidity map it is never changed in place (every
edit makes a new one), so undo snapshots share it. The solver gets it as a
:class:`~arapkit.mesh.groups.VertexGroups` (:meth:`PaintedGroups.vertex_groups`).

Examples
--------
>>> g, k = PaintedGroups.empty(5).with_group(rigid=True)
>>> g = g.painted(np.array([1, 2]), k)
>>> g.vertex_groups().summary(), g.label(k)
('1 rigid part (2 vertices)', 'part 1 (rigid)')
"""

from __future__ import annotations

import dataclasses
import html
from typing import Any

import numpy as np

from arapkit.errors import InputError
from arapkit.mesh.groups import VertexGroups

__all__ = ["ERASE", "GROUP_COLORS", "PaintedGroups", "groups_legend_html"]

#: what the group selector shows for "paint no group" (the eraser)
ERASE = "(erase)"
#: colours of groups 1, 2, ... in the *Groups* view (cycled; ungrouped vertices are shaded)
GROUP_COLORS = ((31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40),
                (148, 103, 189), (140, 86, 75), (227, 119, 194), (188, 189, 34))


@dataclasses.dataclass(frozen=True, eq=False)
class PaintedGroups:
    """Vertex groups as painted: ``ids`` (n,) int64, -1 for none, and ``specs``, one
    ``(name, rigid)`` per group."""

    ids: np.ndarray
    specs: tuple[tuple[str, bool], ...] = ()

    @classmethod
    def empty(cls, n: int) -> PaintedGroups:
        """No groups on ``n`` vertices."""
        return cls(np.full(n, -1, dtype=np.int64))

    @classmethod
    def of(cls, groups: VertexGroups) -> PaintedGroups:
        """The groups of a file (e.g. ``arapkit edit --groups``) as painted groups."""
        return cls(groups.ids.copy(), tuple(zip(groups.names, map(bool, groups.rigid))))

    @property
    def n_groups(self) -> int:
        return len(self.specs)

    def label(self, g: int) -> str:
        """What the group selector shows for group ``g``."""
        name, rigid = self.specs[g]
        return f"{name} ({'rigid' if rigid else 'shared rotation'})"

    def index_of(self, label: str) -> int:
        """The group a selector label stands for (-1 for :data:`ERASE`)."""
        if label == ERASE:
            return -1
        for g in range(self.n_groups):
            if self.label(g) == label:
                return g
        raise InputError(f"no group {label!r:.60}")

    def with_group(self, rigid: bool, name: str | None = None) -> tuple[PaintedGroups, int]:
        """A new, empty group at the end; returns the groups and its index."""
        taken = {n for n, _ in self.specs}
        if name is None:
            word = "part" if rigid else "group"
            k = 1
            while f"{word} {k}" in taken:
                k += 1
            name = f"{word} {k}"
        elif not name.strip() or name in taken:
            raise InputError(f"new group: the name {name!r:.40} is empty or taken")
        new = dataclasses.replace(self, specs=(*self.specs, (name, bool(rigid))))
        return new, new.n_groups - 1

    def painted(self, idx: np.ndarray, g: int) -> PaintedGroups:
        """Vertices ``idx`` put in group ``g`` (-1: in none)."""
        if not -1 <= g < self.n_groups:
            raise InputError(f"paint part: no group {g}")
        ids = self.ids.copy()
        ids[np.asarray(idx, dtype=np.int64)] = g
        return dataclasses.replace(self, ids=ids)

    def without(self, g: int) -> PaintedGroups:
        """Group ``g`` removed (its vertices in none, the later groups renumbered)."""
        if not 0 <= g < self.n_groups:
            raise InputError(f"remove group: no group {g}")
        ids = self.ids.copy()
        ids[ids == g] = -1
        ids[ids > g] -= 1
        return PaintedGroups(ids, self.specs[:g] + self.specs[g + 1:])

    def vertex_groups(self) -> VertexGroups | None:
        """The groups for the solver (groups with no vertex left out); None when none."""
        sizes = np.bincount(self.ids[self.ids >= 0], minlength=self.n_groups)
        lists = [(name, np.flatnonzero(self.ids == g), rigid)
                 for g, (name, rigid) in enumerate(self.specs) if sizes[g]]
        if not lists:
            return None
        return VertexGroups.from_lists(lists, len(self.ids), "painted groups")

    def to_json(self) -> list[dict[str, Any]]:
        """The session's form: every group, empty ones too."""
        return [{"name": name, "rigid": rigid,
                 "indices": np.flatnonzero(self.ids == g).tolist()}
                for g, (name, rigid) in enumerate(self.specs)]

    @classmethod
    def from_json(cls, data: Any, n: int) -> PaintedGroups:
        """Read :meth:`to_json` back (checked: one-line errors naming the session)."""
        if not isinstance(data, list):
            raise InputError(f"session: 'groups' must be a list, got {type(data).__name__}")
        out = cls.empty(n)
        for i, item in enumerate(data, 1):
            ok = (isinstance(item, dict) and isinstance(item.get("name"), str)
                  and isinstance(item.get("rigid"), bool)
                  and isinstance(item.get("indices"), list)
                  and all(isinstance(v, int) and not isinstance(v, bool) and 0 <= v < n
                          for v in item["indices"]))
            if not ok:
                raise InputError(f"session: group {i} must have a name, rigid true/false and "
                                 f"indices in 0..{n - 1}")
            idx = np.asarray(item["indices"], dtype=np.int64)
            if (out.ids[idx] >= 0).any():
                raise InputError(f"session: group {i} ({item['name']!r:.40}) overlaps another")
            out, g = out.with_group(item["rigid"], item["name"])
            out = out.painted(idx, g)
        return out

    def colour_labels(self) -> np.ndarray:
        """(n,) colour bin per vertex for the *Groups* view: 0 none, 1.. a group's colour."""
        return np.where(self.ids >= 0, self.ids % len(GROUP_COLORS) + 1, 0)


def groups_legend_html(groups: PaintedGroups) -> str:
    """Legend of the *Groups* view: a swatch per group with its name and kind."""
    if not groups.n_groups:
        return ("<div style='font-size:0.8em'>no groups: choose the tool <i>Paint part</i> "
                "and press <i>New rigid part</i></div>")
    items = []
    for g in range(groups.n_groups):
        r, gg, b = GROUP_COLORS[g % len(GROUP_COLORS)]
        items.append(f'<span style="display:inline-block;width:0.9em;height:0.9em;'
                     f'background:rgb({r},{gg},{b});margin:0 3px 0 8px;'
                     f'vertical-align:middle"></span>{html.escape(groups.label(g))}')
    return "<div style='font-size:0.8em'>groups: " + "".join(items) + "</div>"
