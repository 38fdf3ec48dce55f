"""A point cloud in the editor's scene: one node of round splats, coloured per point.

A mesh is drawn as triangles, split into one node per colour in the r and energy views
(:func:`arapkit.editor.views.face_groups`). A point cloud has no triangles: it is one
viser point cloud in every view, its splats shaded like small spheres, coloured per
point (the file's own colours in the shaded view where it has them). :class:`CloudNode`
answers what the editor asks of its mesh node (``vertices``, ``visible``, ``remove``), so
the drag, the proxy preview and the exports treat both alike.

viser's point clouds take no pointer events of their own: a click picks the point under
the pointer through the scene's click ray (:func:`arapkit.editor.geometry.pick_point`),
and the brush paints click by click (a Shift+drag stroke is a mesh's).

Examples
--------
>>> import numpy as np
>>> splat_colors(np.array([0, 2]), [(1, 2, 3), (4, 5, 6), (7, 8, 9)]).tolist()
[[1, 2, 3], [7, 8, 9]]
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

__all__ = ["SPLAT_SIZE", "CloudNode", "cloud_colors", "splat_colors"]

#: a splat's diameter in mean edge lengths of the cloud's graph: neighbouring splats
#: overlap, so a dense cloud reads as a surface
SPLAT_SIZE = 1.0


def splat_colors(labels: np.ndarray, colors: Sequence[Sequence[int]]) -> np.ndarray:
    """(n, 3) uint8 colours: ``colors[label]`` for each point."""
    return np.asarray(colors, dtype=np.uint8)[np.asarray(labels, dtype=np.int64)]


def cloud_colors(cloud: Any, uniform: Sequence[int]) -> np.ndarray:
    """The shaded view's colours: the cloud's own (its file's), else ``uniform`` for all.

    Examples
    --------
    >>> from arapkit.mesh.cloud import PointCloud
    >>> cloud_colors(PointCloud(np.eye(3)), (9, 9, 9)).tolist()
    [[9, 9, 9], [9, 9, 9], [9, 9, 9]]
    """
    attrs = getattr(cloud, "attributes", None)
    rgb = None if attrs is None else attrs.colors()
    if rgb is None:
        return np.tile(np.asarray(uniform, dtype=np.uint8), (cloud.n_vertices, 1))
    return np.clip(np.round(np.asarray(rgb)[:, :3] * 255.0), 0, 255).astype(np.uint8)


class CloudNode:
    """The scene node of a point cloud (what the editor keeps as its mesh node).

    Parameters
    ----------
    scene : viser scene API
    name : str
        The node's path (a new node of the same name replaces it).
    points : (n, 3) float32
        Positions, relative to the mesh frame.
    colors : (n, 3) uint8 or (3,)
    size : float
        Splat diameter in model units.
    visible : bool
    """

    def __init__(self, scene: Any, name: str, points: np.ndarray, colors: Any, size: float,
                 visible: bool = True) -> None:
        self._scene, self._name, self._size = scene, name, float(size)
        self._colors = np.asarray(colors, dtype=np.uint8)
        self.node = self._make(points, visible)

    def _make(self, points: np.ndarray, visible: bool) -> Any:
        colors = self._colors
        if colors.ndim == 2 and len(colors) != len(points):  # a proxy of another size
            colors = colors[0] if len(colors) else np.array([190, 195, 205], np.uint8)
        return self._scene.add_point_cloud(
            self._name, np.asarray(points, np.float32), colors, point_size=self._size,
            point_shape="circle", point_shading="gradient", precision="float32",
            visible=visible)

    @property
    def vertices(self) -> np.ndarray:
        """The positions drawn (float32, relative to the mesh frame)."""
        return np.asarray(self.node.points)

    @vertices.setter
    def vertices(self, points: np.ndarray) -> None:
        if len(points) != len(self.node.points):  # a new size: a new node (same name)
            self.node = self._make(points, self.node.visible)
        else:
            self.node.points = np.asarray(points, np.float32)

    @property
    def colors(self) -> np.ndarray:
        """Per-point colours (uint8)."""
        return np.asarray(self.node.colors)

    @colors.setter
    def colors(self, colors: Any) -> None:
        self._colors = np.asarray(colors, dtype=np.uint8)
        self.node.colors = self._colors

    @property
    def visible(self) -> bool:
        return bool(self.node.visible)

    @visible.setter
    def visible(self, on: bool) -> None:
        self.node.visible = bool(on)

    def remove(self) -> None:
        self.node.remove()

    # a point cloud takes no drag of its own (see the module docstring)
    def remove_drag_callback(self, which: str = "all") -> None:
        """Nothing to remove: no drag was attached."""

    def on_drag(self, *args: Any, **kwargs: Any):
        """The brush's Shift+drag is a mesh's: on a cloud each click paints."""
        return lambda fn: fn
