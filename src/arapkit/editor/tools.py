"""The editor's pointer tools: a registry of what a click and a Shift+drag do.

Each :class:`Tool` is one entry of :data:`TOOLS` with its name, the label of the tool
selector, a help line, and its handlers: what a click does to the :class:`EditorState`, and
whether Shift+drag draws a selection rectangle or paints a brush stroke.  The page looks the
chosen tool up here instead of comparing labels, so a new tool is one entry, and shows the
chosen tool's help line, which promises only what that tool does.

The selection tool draws a rectangle on Shift+drag as well as selecting on click: box
selection is what the default tool of Blender and MeshLab's selection tool do with a drag
(a plain drag orbits here, so the rectangle takes Shift).

:class:`PointerTools` is the part of :class:`arapkit.editor.app.EditorApp` that turns
scene events (clicks, rectangles, drags on the mesh) into those handlers.

Examples
--------
>>> from arapkit.mesh.shapes import bar
>>> st = EditorState(bar())
>>> pick = Pick(point=st.vertices[0], face=None, add=False, radius=0.05, r=3)
>>> find_tool("Select").click(st, pick) == len(st.selection) > 0
True
>>> find_tool("fill").click(st, pick), int(st.rings.max())
(1154, 3)
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from arapkit.editor.geometry import CameraView, nearest_corner, pick_point, raycast
from arapkit.editor.groups import GROUP_COLORS
from arapkit.editor.points import SPLAT_SIZE
from arapkit.editor.state import EditorState
from arapkit.editor.views import RING_COLORS, SHADED_COLOR, ring_labels
from arapkit.errors import InputError, worded_for

__all__ = ["TOOLS", "Pick", "PointerTools", "Tool", "find_tool"]


@dataclasses.dataclass(frozen=True)
class Pick:
    """Where a click hit the surface, and the panel's values that a tool reads.

    ``face`` is the face hit (``None``: the point alone), ``add`` is Shift held, ``radius``
    the brush radius in model units, ``r`` the panel's "Paint r" and ``group`` the group
    the *Paint part* tool paints (-1: the eraser).
    """

    point: np.ndarray
    face: int | None
    add: bool
    radius: float
    r: int
    group: int = -1


def _select(st: EditorState, pick: Pick) -> int:
    before = len(st.selection)
    st.select_near(pick.point, pick.radius, mode="add" if pick.add else "replace")
    return len(st.selection) - (before if pick.add else 0)


def _paint(st: EditorState, pick: Pick) -> int:
    return st.paint(pick.point, pick.radius, pick.r)


def _paint_part(st: EditorState, pick: Pick) -> int:
    return st.paint_group(pick.point, pick.radius, pick.group)


def _dab_r(st: EditorState, pick: Pick, record: bool) -> int:
    return st.paint(pick.point, pick.radius, pick.r, record=record)


def _dab_part(st: EditorState, pick: Pick, record: bool) -> int:
    return st.paint_group(pick.point, pick.radius, pick.group, record=record)


def _r_rgb(pick: Pick) -> tuple[int, int, int]:
    return RING_COLORS[ring_labels(np.array([pick.r]))[0]]


def _part_rgb(pick: Pick) -> tuple[int, int, int]:
    return SHADED_COLOR if pick.group < 0 else GROUP_COLORS[pick.group % len(GROUP_COLORS)]


def _fill(st: EditorState, pick: Pick) -> int:
    # the clicked face's nearest corner: the vertex the user sees under the pointer
    seed = (st.nearest_vertex(pick.point) if pick.face is None
            else nearest_corner(st.vertices, st.mesh.faces, pick.face, pick.point))
    return st.flood_fill(seed, pick.r)


@dataclasses.dataclass(frozen=True)
class Tool:
    """One pointer tool.

    Attributes
    ----------
    name : str
        Short key (``"brush"``).
    label : str
        What the tool selector shows.
    help : str
        One line for the panel: what the pointer does with this tool.
    click : callable(EditorState, Pick) -> int, or None
        What a click does; returns the vertices affected.  ``None``: clicks do nothing.
    paints : bool
        A click changes what is painted, r or the groups (one undo step; the page redraws
        and solves), not the selection.
    rectangle : bool
        Shift+drag draws a selection rectangle.
    brush : bool
        Shift+drag on the mesh paints a stroke (one undo step).
    aliases : tuple of str
        Former labels that :func:`find_tool` still accepts.
    dab : callable(EditorState, Pick, record) -> int, or None
        One dab of a brush stroke (``record``: the stroke's first, the undo step).
    stroke_rgb : callable(Pick) -> (r, g, b), or None
        The colour a stroke in progress is shown in.
    view : str or None
        The colour view the tool switches a shaded display to (what it paints).
    """

    name: str
    label: str
    help: str
    click: Callable[[EditorState, Pick], int] | None = None
    paints: bool = False
    rectangle: bool = False
    brush: bool = False
    aliases: tuple[str, ...] = ()
    dab: Callable[[EditorState, Pick, bool], int] | None = None
    stroke_rgb: Callable[[Pick], tuple[int, int, int]] | None = None
    view: str | None = None


#: every pointer tool, in the order of the tool selector
TOOLS: tuple[Tool, ...] = (
    Tool("navigate", "Navigate", "Drag orbits the camera; clicks do nothing."),
    Tool("select", "Select",
         "Click selects the vertices within the radius; Shift+click adds to the selection; "
         "Shift+drag a rectangle adds the vertices inside it that face you.",
         click=_select, rectangle=True, aliases=("Select: click", "Select: rectangle")),
    Tool("brush", "Paint brush",
         "Click or Shift+drag paints **Paint r** on the vertices within the radius.",
         click=_paint, paints=True, brush=True, dab=_dab_r, stroke_rgb=_r_rgb,
         view="Rigidity r"),
    Tool("fill", "Flood fill",
         "Click fills the connected region of equal r with **Paint r**.",
         click=_fill, paints=True, view="Rigidity r"),
    Tool("part", "Paint part",
         "Click or Shift+drag puts the vertices within the radius in the **Group** chosen "
         "in *Groups*; the group *(erase)* takes them out. A rigid part moves as one "
         "piece, a shared-rotation group turns as one.",
         click=_paint_part, paints=True, brush=True, dab=_dab_part, stroke_rgb=_part_rgb,
         view="Groups"),
)


def find_tool(key: str) -> Tool:
    """The tool of :data:`TOOLS` with this name or label.

    Examples
    --------
    >>> find_tool("Paint brush").name, find_tool("brush").label, find_tool("Select: click").name
    ('brush', 'Paint brush', 'select')
    """
    for t in TOOLS:
        if key in (t.name, t.label, *t.aliases):
            return t
    raise InputError(f"unknown tool {key!r:.40} (use one of {', '.join(t.label for t in TOOLS)})")


class PointerTools:
    """Scene events -> tool handlers; a part of :class:`arapkit.editor.app.EditorApp`.

    Uses the app's ``server``, ``state``, ``lock``, ``diag``, ``edge_length``, the panel
    widgets ``dd_tool``, ``md_tool_help``, ``sl_radius``, ``sl_paint``, and its methods
    ``mesh_nodes``, ``draw_markers``, ``show_points``, ``after_edit``, ``notify``,
    ``clear_error`` and ``ui``.
    """

    server: Any
    state: EditorState
    lock: Any
    diag: float
    edge_length: float
    dd_tool: Any
    md_tool_help: Any
    sl_radius: Any
    sl_paint: Any
    dd_view: Any
    quietly: Callable[[Callable[[], Any]], None]
    rebuild_display: Callable[[], None]
    show_settings: Callable[[], None]
    current_group: Callable[[], int]
    after_edit: Callable[..., int | None]
    draw_markers: Callable[[], None]
    mesh_nodes: Callable[[], list[Any]]
    notify: Callable[..., None]
    clear_error: Callable[[], None]
    show_points: Callable[..., None]
    ui: Callable[[Callable[[Any], None]], Callable[[Any], None]]

    def bind_tools(self) -> None:
        """Listen to clicks on the scene and to the tool selector."""
        self._stroke_open = False
        self._stroke: set[int] = set()
        self._last_stroke_draw = 0.0
        scene = self.server.scene
        scene.on_click()(self._on_click_replace)
        scene.on_click(modifier="shift")(self._on_click_add)
        self.dd_tool.on_update(self.ui(lambda event: self._on_tool_changed()))
        self._on_tool_changed()  # the first tool's rectangle and help, as for a chosen one

    @property
    def tool(self) -> Tool:
        """The tool chosen in the panel."""
        return find_tool(self.dd_tool.value)

    def apply_tool(self, tool: str, point: np.ndarray, face: int | None = None,
                   add: bool = False) -> int:
        """Apply a click tool (name or label) at a surface point; returns the vertices affected."""
        t = find_tool(tool)
        if t.click is None:
            return 0
        with self.lock:
            pick = self._pick(point, face, add)
            n = t.click(self.state, pick)
            if t.paints:
                self.after_edit()
            else:
                self.draw_markers()
            return n

    def bind_brush(self) -> None:
        """(Re)attach Shift+drag painting to the mesh nodes shown, when the tool paints."""
        brush = self.tool.brush
        for node in self.mesh_nodes():
            node.remove_drag_callback("all")
            if brush:
                node.on_drag("left", modifier="shift")(self._on_brush)

    # ---------------------------------------------------------------- events
    def _radius(self) -> float:
        return float(self.sl_radius.value) / 100.0 * self.diag

    def _pick(self, point: Any, face: int | None, add: bool) -> Pick:
        """A pick at ``point`` with the panel's radius, r and group."""
        return Pick(np.asarray(point, np.float64), face, add, self._radius(),
                    int(self.sl_paint.value), self.current_group())

    def _on_tool_changed(self) -> None:
        t = self.tool
        self.md_tool_help.content = t.help
        if t.view is not None and self.dd_view.value == "Shaded":
            # paint is invisible on the shaded model: show the colours of what the tool
            # paints (as Blender's weight paint mode shows the weights)
            self.quietly(lambda: setattr(self.dd_view, "value", t.view))
            self.rebuild_display()
            self.show_settings()
            self.md_tool_help.content = (t.help + f" The view switched to *{t.view}* to "
                                         "show what you paint.")
        scene = self.server.scene
        scene.remove_rect_select_callback("all")
        if t.rectangle:
            scene.on_rect_select(modifier="shift")(self._on_rect)
        self.bind_brush()

    def _on_click_replace(self, event: Any) -> None:
        self._on_click(event, add=False)

    def _on_click_add(self, event: Any) -> None:
        self._on_click(event, add=True)

    def _hit(self, origin: Any, direction: Any) -> tuple[int | None, np.ndarray] | None:
        st = self.state
        o, d = np.asarray(origin, np.float64), np.asarray(direction, np.float64)
        if st.mesh.faces is None:  # a point cloud: the splat under the pointer (no face)
            hit = pick_point(st.vertices, o, d, SPLAT_SIZE * self.edge_length)
            return None if hit is None else (None, hit[1])
        return raycast(st.vertices, np.asarray(st.mesh.faces), o, d)

    def _on_click(self, event: Any, add: bool) -> None:
        try:
            t = self.tool
            if t.click is None:
                return
            with self.lock:
                hit = self._hit(event.ray_origin, event.ray_direction)
                if hit is None:
                    return
                self.apply_tool(t.name, hit[1], face=hit[0], add=add)
                self.clear_error()
        except InputError as exc:
            self.notify(event, "Cannot do that",
                        worded_for(exc.args[0], "editor") if exc.args else str(exc), error=True)

    def _on_rect(self, event: Any) -> None:
        if not self.tool.rectangle:
            return
        cam = event.client.camera
        view = CameraView(np.asarray(cam.position), np.asarray(cam.wxyz), float(cam.fov),
                          float(cam.aspect))
        with self.lock:
            self.state.select_in_rect(view, event.screen_min, event.screen_max, mode="add")
            self.draw_markers()

    async def _on_brush(self, event: Any) -> None:
        # async: viser keeps start/update/end in order, so a stroke is one undo step.
        with self.lock:
            if not self.tool.brush:
                return
            st = self.state
            t = self.tool
            eye = np.asarray(event.client.camera.position, np.float64)
            hit = self._hit(eye, np.asarray(event.end_position) - eye)
            pick = self._pick(eye if hit is None else hit[1], None, False)
            if hit is not None:
                t.dab(st, pick, not self._stroke_open)
                self._stroke_open = True
                self._stroke.update(st.vertices_near(hit[1], self._radius()).tolist())
            if event.phase == "end":
                self._stroke_open = False
                self._stroke.clear()
                self.after_edit()
            elif time.perf_counter() - self._last_stroke_draw > 0.1 and self._stroke:
                self._draw_stroke(t.stroke_rgb(pick))

    def _draw_stroke(self, rgb: tuple[int, int, int]) -> None:
        """Show the stroke so far as dots in the colour it paints.

        Rebuilding the coloured meshes mid-stroke would remove the node being dragged,
        which ends the drag; they are rebuilt once, when the stroke ends.
        """
        idx = np.fromiter(self._stroke, dtype=np.int64)
        self.show_points("stroke", idx, rgb, 0.8 * self.edge_length)
        self._last_stroke_draw = time.perf_counter()
