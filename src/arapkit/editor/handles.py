"""A handle of the editor: vertices moved together by one gizmo, and its session form.

A handle stores the positions of its vertices when it was created (``anchor``) and a gizmo
pose (rotation ``wxyz`` + ``position``, the gizmo starts at the anchor centroid).  Its
targets are ``R(wxyz) @ (anchor - pivot) + position``.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from arapkit import validate
from arapkit.editor.geometry import quat_to_matrix
from arapkit.errors import InputError

__all__ = ["Handle"]


@dataclasses.dataclass
class Handle:
    """One handle region: vertices moved together by one gizmo.

    Examples
    --------
    >>> h = Handle.create("tip", np.array([0, 1]), np.array([[0.0, 0, 0], [2.0, 0, 0]]))
    >>> h.position.tolist()
    [1.0, 0.0, 0.0]
    >>> h.targets().tolist()
    [[0.0, 0.0, 0.0], [2.0, 0.0, 0.0]]
    """

    name: str
    vertices: np.ndarray  # (k,) int64 vertex indices
    anchor: np.ndarray  # (k, 3) positions when the handle was made
    wxyz: np.ndarray  # gizmo rotation
    position: np.ndarray  # gizmo position; starts at the anchor centroid
    frozen: bool = False
    #: the last (wxyz, position, anchor, targets): every drag move asks for every handle's
    #: targets, and on a scan a fixed base holds 10^5 vertices
    _last: tuple | None = dataclasses.field(default=None, repr=False, compare=False)

    @classmethod
    def create(cls, name: str, vertices: np.ndarray, anchor: np.ndarray) -> Handle:
        """A handle whose gizmo sits at the centroid of ``anchor`` with no rotation."""
        anchor = np.array(anchor, dtype=np.float64).reshape(-1, 3)
        return cls(
            name=name,
            vertices=np.array(vertices, dtype=np.int64).reshape(-1),
            anchor=anchor,
            wxyz=np.array([1.0, 0.0, 0.0, 0.0]),
            position=anchor.mean(axis=0),
        )

    @property
    def pivot(self) -> np.ndarray:
        """Centre of rotation: the anchor centroid."""
        return self.anchor.mean(axis=0)

    @property
    def at_rest(self) -> bool:
        """The gizmo is where the handle was made: no rotation, at the anchor centroid.

        Examples
        --------
        >>> h = Handle.create("tip", np.array([0]), np.zeros((1, 3)))
        >>> h.at_rest
        True
        """
        return bool(np.allclose(self.wxyz, [1.0, 0.0, 0.0, 0.0], rtol=0, atol=1e-12)
                    and np.array_equal(self.position, self.pivot))

    def same_as(self, other: Handle) -> bool:
        """Whether ``other`` is this handle unchanged (name, vertices, pose, anchor, frozen)."""
        return (self.name == other.name and self.frozen == other.frozen
                and all(a is b or np.array_equal(a, b) for a, b in (
                    (self.vertices, other.vertices), (self.anchor, other.anchor),
                    (self.wxyz, other.wxyz), (self.position, other.position))))

    def targets(self) -> np.ndarray:
        """Target positions of the handle vertices for the current gizmo pose."""
        last = self._last
        pose = (self.wxyz.tobytes(), self.position.tobytes())
        # arrays are replaced, never mutated: the same objects mean the same targets
        if last is not None and last[0] == pose and last[1] is self.anchor:
            return last[2]
        R = quat_to_matrix(self.wxyz)
        # einsum, not BLAS: a tall (n, 3) @ (3, 3) product in threaded OpenBLAS took 10x
        # longer while the solver thread kept the other core busy (every drag move)
        out = np.einsum("vj,ij->vi", self.anchor - self.pivot, R) + self.position
        out.flags.writeable = False
        self._last = (pose, self.anchor, out)
        return out

    def copy(self) -> Handle:
        # Arrays are replaced, never mutated, so sharing them is safe.
        return dataclasses.replace(self)

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "vertices": self.vertices.tolist(),
            "frozen": self.frozen,
            "anchor": self.anchor.tolist(),
            "wxyz": self.wxyz.tolist(),
            "position": self.position.tolist(),
            "targets": self.targets().tolist(),
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any], n_vertices: int) -> Handle:
        """Inverse of :meth:`to_dict`; a handle given only by targets gets them as anchor.

        Every field is checked with the rules of :mod:`arapkit.validate`; a bad one raises
        :class:`InputError` naming the handle and the field.
        """
        if not isinstance(d, dict):
            raise InputError(f"session handle: expected an object, got {type(d).__name__}")
        name = d.get("name", "handle")
        if not isinstance(name, str) or not name or "\0" in name:
            raise InputError(f"session handle: 'name' must be a non-empty string, got {name!r:.40}")
        where = f"session handle {name!r}"
        if "vertices" not in d:
            raise InputError(f"{where}: no 'vertices'")
        idx = validate.handle_indices(d["vertices"], n_vertices, f"{where}: 'vertices'")
        key = "anchor" if "anchor" in d else "targets"
        if key not in d:
            raise InputError(f"{where}: needs 'anchor' or 'targets'")
        anchor = validate.real_array(d[key], f"{where}: {key!r}")
        if anchor.shape != (idx.size, 3):
            raise InputError(f"{where}: expected {idx.size} {key} rows of 3, got {anchor.shape}")
        validate.check_finite_positions(anchor, f"{where}: {key!r}")
        h = cls.create(name, idx, anchor)
        if "wxyz" in d or "position" in d:
            h.wxyz = validate.quaternion(d.get("wxyz", [1, 0, 0, 0]), f"{where}: 'wxyz'")
            h.position = validate.vec3(d.get("position", h.position.tolist()),
                                       f"{where}: 'position'")
        frozen = d.get("frozen", False)
        if not isinstance(frozen, bool):
            raise InputError(f"{where}: 'frozen' must be true or false, got {frozen!r:.40}")
        h.frozen = frozen
        with np.errstate(over="ignore", invalid="ignore"):
            finite = np.isfinite(h.targets()).all()
        if not finite:
            raise InputError(f"{where}: its targets are beyond double precision (too large)")
        return h
