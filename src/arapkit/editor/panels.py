"""The editor's side panel: its widgets, their callbacks, and keeping them in step.

:class:`Panels` is the part of :class:`arapkit.editor.app.EditorApp` that builds the
viser GUI (tools, handles, rigidity, view, solver, session), turns widget events into
edits of the :class:`~arapkit.editor.state.EditorState`, and shows the state back in the
widgets.  Every callback runs through :meth:`Panels.ui`: echoes of the page's own updates
are skipped and bad input becomes a notification, never an exception in viser's loop.
"""

from __future__ import annotations

import threading
import time
import traceback
import types
import zipfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import viser

from arapkit import validate
from arapkit.arap.domains import domain_of
from arapkit.editor.files import MESH_SUFFIXES
from arapkit.editor.geometry import UP_AXES
from arapkit.editor.groups import ERASE
from arapkit.editor.settings import (
    MULTIRES_CHOICES,
    SolverSettings,
    multires_label,
    solver_choices,
)
from arapkit.editor.state import EditorState
from arapkit.editor.tools import TOOLS, find_tool
from arapkit.editor.topbar import TopBlock
from arapkit.errors import InputError, worded_for
from arapkit.mesh.cloud import counted, element_nouns, is_cloud

__all__ = ["MAX_R", "VIEWS", "Panels", "handle_controls", "next_step", "selected_text"]

VIEWS = ("Shaded", "Rigidity r", "Energy", "Groups")
#: the largest r the sliders offer: the library's one rule for r
MAX_R = validate.MAX_RINGS
_FIRST_TOOL = "Select"
#: a handle name longer than this is cut short on the buttons that act on it
_SHOWN_NAME = 24
_ERROR_MARK = "⚠ "
#: a Global r gesture is applied once the slider has rested this long (viser sends every
#: value the slider passes, and nothing at the release): one rebuild and one undo step
SLIDER_REST_S = 0.6
#: a Global r applied within this many seconds of the last one, with nothing changed in
#: between, joins its undo step: a gesture that paused (or whose values arrived late on a
#: busy machine) is still undone in one click
GESTURE_S = 3.0
#: the dot colours of handles: movable orange, fixed grey, the active one (the one the
#: Handles panel acts on) brighter: yellow when movable, light grey when fixed
HANDLE_COLOURS = {(False, False): ((255, 140, 0), "orange"),
                  (False, True): ((255, 235, 0), "yellow"),
                  (True, False): ((110, 110, 135), "grey"),
                  (True, True): ((200, 200, 220), "light grey")}


@contextmanager
def _icon_archive_opened_once() -> Iterator[None]:
    """Let viser read every button icon from one opening of its icon archive.

    viser opens its 25,000-entry ``tabler-icons.zip`` afresh for each icon (about 90 ms a
    time on two cores: half a second of the editor's start for the panel's six icons).
    Where viser's layout differs from the one expected, nothing is changed.
    """
    try:
        from viser import _icons
    except ImportError:  # pragma: no cover - another viser layout
        yield
        return
    if getattr(_icons, "zipfile", None) is not zipfile:  # pragma: no cover - idem
        yield
        return
    opened: dict[str, zipfile.ZipFile] = {}

    class _Kept:
        """One archive, not closed at the end of each ``with`` block."""

        def __init__(self, path: Any) -> None:
            key = str(path)
            if key not in opened:
                opened[key] = zipfile.ZipFile(path)
            self._zip = opened[key]

        def __enter__(self) -> zipfile.ZipFile:
            return self._zip

        def __exit__(self, *exc: object) -> None:
            return None

    _icons.zipfile = types.SimpleNamespace(ZipFile=_Kept)
    try:
        yield
    finally:
        _icons.zipfile = zipfile
        for z in opened.values():
            z.close()


def selected_text(n: int, shape: Any) -> str:
    """The selection's line under the tools: its count, in points for a point cloud.

    Examples
    --------
    >>> from arapkit.mesh.shapes import bar
    >>> selected_text(3, bar())
    'Selected: **3** vertices'
    """
    one, many = element_nouns(is_cloud(shape))
    return f"Selected: **{n}** {one if n == 1 else many}"


def next_step(state: EditorState) -> str:
    """The hint at the top of the panel: what to do next with these handles.

    A drag needs a handle to move and one that holds: with only movable handles the
    whole model follows the drag rigidly, which looks like nothing happens.

    Examples
    --------
    >>> from arapkit.mesh.shapes import bar
    >>> st = EditorState(bar())
    >>> "select a region" in next_step(st)
    True
    >>> _ = st.add_handle(np.arange(10))
    >>> "Make fixed handle" in next_step(st)
    True
    >>> _ = st.add_handle(np.arange(1100, 1154), frozen=True)
    >>> next_step(st).startswith("**Next:** drag")
    True
    >>> _ = st.select_near(st.vertices[500], 0.1)
    >>> "selected: press **Make handle from selection**" in next_step(st)
    True
    """
    movable = [h for h in state.handles if not h.frozen]
    fixed = len(state.handles) - len(movable)
    if len(state.selection):
        what = ("press **Make fixed handle from selection** to pin it" if not fixed
                else "press **Make handle from selection** to move it")
        other = ("(or **Make handle from selection** to move it)" if not fixed
                 else "(or **Make fixed handle from selection** to pin it)")
        return (f"**Next:** {counted(len(state.selection), state.mesh)} selected: {what} "
                f"{other}.")
    if not state.handles:
        return ("**Next:** select a region (tool *Select*: click, or Shift+drag a "
                "rectangle), then **Make handle** to move it or **Make fixed handle** to "
                "pin it.")
    if not fixed:
        return ("**Next:** pin a region: select it and press **Make fixed handle** (or "
                "tick *Frozen* on a handle). With nothing fixed, a drag moves the whole "
                "model rigidly.")
    if not movable:
        return ("**Next:** select the part to move and press **Make handle**, then drag "
                "its gizmo.")
    return ("**Next:** drag a gizmo (arrows move, rings turn) to deform; *Undo* is in "
            "*Session*.")


def handle_controls(name: str | None, frozen: bool = False) -> dict[str, str]:
    """Labels of the controls that act on one handle, naming it (``None``: no handle), and
    the colour of its dots.

    Examples
    --------
    >>> handle_controls("tip")["remove"]
    'Remove tip'
    >>> handle_controls(None)["remove"]
    'Remove handle'
    >>> "(light grey dots)" in handle_controls("feet", frozen=True)["heading"]
    True
    """
    if name is None:
        return {"heading": "No handle yet.", "rename": "Rename", "frozen": "",
                "reset": "Reset pose", "remove": "Remove handle"}
    shown = name if len(name) <= _SHOWN_NAME else name[:_SHOWN_NAME - 1] + "…"
    colour = HANDLE_COLOURS[(bool(frozen), True)][1]
    return {"heading": f"Handle **{shown}** ({colour} dots): the controls below act on it.",
            "rename": f"Rename {shown}", "frozen": f"Hold {shown} where it is",
            "reset": f"Reset pose of {shown}", "remove": f"Remove {shown}"}


class Panels:
    """Widgets and their callbacks; a part of :class:`arapkit.editor.app.EditorApp`.

    Uses the app's ``server``, ``state``, ``lock``, ``active``, ``export_dir``,
    ``vertex_energy``, ``up_reason`` and its methods ``request_solve``, ``redraw``,
    ``rebuild_display``, ``draw_markers``, ``aim_cameras``, ``status``.
    """

    server: Any
    state: EditorState
    lock: Any
    active: str | None
    export_dir: Path
    vertex_energy: np.ndarray | None
    up_reason: str
    request_solve: Callable[[], int | None]
    solved_rings: Callable[[], np.ndarray | None]
    edit_note: str
    redraw: Callable[[], None]
    rebuild_display: Callable[[], None]
    draw_markers: Callable[[], None]
    aim_cameras: Callable[[], None]
    status: Callable[[str], None]

    def build_panels(self) -> None:
        """Create every widget and bind the panel's own callbacks."""
        with _icon_archive_opened_once():
            self._build_panels()

    def _build_panels(self) -> None:
        self._quiet = False
        gui = self.server.gui
        # status, hint, legend and a build's progress: one block that stays in view
        self.top = TopBlock(gui, "Starting ...", next_step(self.state))
        self.md_status, self.md_hint, self.html_legend = (self.top.status, self.top.hint,
                                                          self.top.legend)
        self._status_ok = ""
        self.md_mesh = gui.add_markdown("")
        self.md_settings = gui.add_markdown("")
        with gui.add_folder("Tools"):
            self.dd_tool = gui.add_dropdown("Tool", tuple(t.label for t in TOOLS),
                                            initial_value=_FIRST_TOOL)
            self.sl_radius = gui.add_slider("Radius (% size)", 0.5, 30.0, 0.5, 3.0)
            # the one promise every tool keeps; the rest is the chosen tool's own help line
            gui.add_markdown("Plain drag orbits the camera, scroll zooms.")
            self.md_tool_help = gui.add_markdown(find_tool(_FIRST_TOOL).help)
            self.md_selection = gui.add_markdown(selected_text(0, self.state.mesh))
            self.bt_make = gui.add_button("Make handle from selection", icon=viser.Icon.PLUS)
            self.bt_make_fixed = gui.add_button("Make fixed handle from selection",
                                                icon=viser.Icon.PIN)
            self.bt_clear_sel = gui.add_button("Clear selection")
        with gui.add_folder("Handles"):
            self.dd_handle = gui.add_dropdown("Handle", ("(none)",))
            self.md_active = gui.add_markdown(handle_controls(None)["heading"])
            self.tx_name = gui.add_text("Name", "")
            self.bt_rename = gui.add_button("Rename")
            self.cb_frozen = gui.add_checkbox("Frozen (fixed)", False)
            self.bt_reset = gui.add_button("Reset pose")
            self.bt_remove = gui.add_button("Remove handle", color="red")
        with gui.add_folder("Rigidity"):
            marks = tuple(r for r in (1, 3, 10, 30, MAX_R) if r <= MAX_R)
            rule = f"a whole number from 1 to {MAX_R}"
            self.sl_global = gui.add_slider(
                "Global r", 1, MAX_R, 1, 1, marks=marks,
                hint=f"r of every vertex: {rule}; applied when the slider rests")
            self.md_global = gui.add_markdown(
                f"*Global r*: {rule}, applied when the slider rests (one undo step); a "
                "large r costs memory and time, estimated first.")
            self.bt_cancel_build = gui.add_button("Cancel the r-ring build", color="red",
                                                  visible=False)
            self.sl_paint = gui.add_slider("Paint r", 1, MAX_R, 1, 3, marks=marks,
                                           hint=f"r the brush and the fill paint: {rule}")
            self.up_rings = gui.add_upload_button("Load rings file", icon=viser.Icon.UPLOAD)
        with gui.add_folder("Groups"):
            gui.add_markdown("Rigid parts move as one piece; a shared-rotation group turns "
                             "as one (libigl's G). Paint them with the tool *Paint part*.")
            self.dd_group = gui.add_dropdown("Group", (ERASE,), initial_value=ERASE)
            self.bt_new_part = gui.add_button("New rigid part", icon=viser.Icon.PLUS)
            self.bt_new_shared = gui.add_button("New shared-rotation group")
            self.bt_remove_group = gui.add_button("Remove group", color="red")
            self.up_groups = gui.add_upload_button("Load groups file", icon=viser.Icon.UPLOAD)
        with gui.add_folder("View"):
            self.dd_view = gui.add_dropdown("Colour", VIEWS, initial_value="Shaded")
            self.dd_up = gui.add_dropdown("Up axis", tuple(UP_AXES), initial_value="+z")
            self.cb_show_handles = gui.add_checkbox("Highlight handles", True)
        with gui.add_folder("Solver"):
            self._build_solver_panel(gui)
        with gui.add_folder("Session"):
            self.bt_undo = gui.add_button("Undo", icon=viser.Icon.ARROW_BACK_UP)
            self.bt_redo = gui.add_button("Redo", icon=viser.Icon.ARROW_FORWARD_UP)
            self.bt_save = gui.add_button("Save session")
            self.up_session = gui.add_upload_button("Load session", mime_type=".json")
            self.bt_export = gui.add_button("Export mesh + rings", icon=viser.Icon.DOWNLOAD)
            self.up_mesh = gui.add_upload_button(
                "Open mesh", mime_type=",".join(MESH_SUFFIXES) + ",.gz", icon=viser.Icon.UPLOAD)
            gui.add_markdown(f"Exports and sessions go to `{self.export_dir}`.")
        self._bind_panel_events()

    def _build_solver_panel(self, gui: Any) -> None:
        s = self.state.settings
        self.dd_method = gui.add_dropdown("Method", tuple(c.label for c in solver_choices()))
        # the loaded shape's weightings (a point cloud has its own)
        self.dd_weights = gui.add_dropdown("Weights", domain_of(self.state.mesh).weight_kinds,
                                           initial_value=s.weights)
        self.nb_tol = gui.add_number("Tolerance", s.tol, min=1e-9, max=0.5, step=1e-6)
        self.nb_maxit = gui.add_number("Max iterations", s.max_iter, min=1, max=100000, step=1)
        self.nb_budget = gui.add_number("Live budget (ms)", s.live_budget_ms, min=1.0,
                                        max=5000.0, step=1.0)
        self.dd_multires = gui.add_dropdown(
            "Coarse to fine", tuple(MULTIRES_CHOICES), initial_value=multires_label(s.multires),
            hint="Auto: from 100,000 vertices a decimated proxy previews the drag and starts "
                 "the exact solve (docs/interactive.md); On or Off forces it")
        self.cb_dynamics = gui.add_checkbox(
            "Secondary motion", s.dynamics,
            hint="Drags move an elastic body that lags behind the handles and settles "
                 "(ARAP dynamics) instead of jumping to the static shape")
        self.bt_solve = gui.add_button("Solve again")

    # ---------------------------------------------------------------- callback plumbing
    def ui(self, fn: Callable[[Any], None]) -> Callable[[Any], None]:
        """Wrap a GUI callback: skip echoes of our own updates, report bad input."""

        def wrapped(event: Any) -> None:
            if self._quiet:
                return
            try:
                with self.lock:
                    fn(event)
                    self.clear_error()
            except InputError as exc:
                # a rejected value must not stay in its field (a later blur would send
                # the clamped value): every widget shows the state again
                self.quietly(self.sync_gui_from_state)
                self.notify(event, "Cannot do that", worded_for(exc.args[0], "editor")
                            if exc.args else str(exc), error=True)
            except Exception as exc:  # a bug, not the user's fault: say so in the page too
                traceback.print_exc()
                self.notify(event, "Internal error",
                            f"{type(exc).__name__}: {exc} (please report this)", error=True)

        return wrapped

    def notify(self, event: Any, title: str, body: str, error: bool = False) -> None:
        """A notification for the event's page (all pages when it has none)."""
        client = getattr(event, "client", None)
        targets = [client] if client is not None else list(self.server.get_clients().values())
        for c in targets:
            c.add_notification(title, body, auto_close_seconds=8.0,
                               color="red" if error else "green")
        if error:
            self.md_status.content = f"{_ERROR_MARK}{body}"

    def clear_error(self) -> None:
        """An action succeeded: an error line left in the status gives way to the last news."""
        if self.md_status.content.startswith(_ERROR_MARK):
            self.md_status.content = self._status_ok

    def quietly(self, fn: Callable[[], None]) -> None:
        """Run ``fn`` with the widget callbacks muted (setting values, not user actions)."""
        # Assigning a widget value runs its callbacks; these are not user actions.
        old, self._quiet = self._quiet, True
        try:
            fn()
        finally:
            self._quiet = old

    def _bind_panel_events(self) -> None:
        ui = self.ui
        self.bt_make.on_click(ui(lambda e: self._make_handle()))
        self.bt_make_fixed.on_click(ui(lambda e: self._make_handle(frozen=True)))
        self.bt_clear_sel.on_click(ui(lambda e: self._clear_selection()))
        self.dd_handle.on_update(ui(lambda e: self._select_handle(self.dd_handle.value)))
        self.bt_rename.on_click(ui(lambda e: self._rename()))
        self.cb_frozen.on_update(ui(lambda e: self._freeze(self.cb_frozen.value)))
        self.bt_reset.on_click(ui(lambda e: self._reset_pose()))
        self.bt_remove.on_click(ui(lambda e: self._remove_handle()))
        self._global_timer: threading.Timer | None = None
        self._global_pending: tuple[int, Any] | None = None
        self.sl_global.on_update(ui(lambda e: self._global_moved(self.sl_global.value, e)))
        self.bt_cancel_build.on_click(ui(lambda e: self._cancel_build()))
        self.dd_view.on_update(ui(lambda e: (self.rebuild_display(), self.show_settings())))
        self.cb_show_handles.on_update(ui(lambda e: self.draw_markers()))
        self.dd_up.on_update(ui(lambda e: self._up_chosen()))
        for w in (self.dd_method, self.dd_weights, self.nb_tol, self.nb_maxit, self.nb_budget,
                  self.dd_multires, self.cb_dynamics):
            w.on_update(ui(lambda e: self._apply_settings()))
        self.bt_solve.on_click(ui(lambda e: self.request_solve()))
        self.bt_new_part.on_click(ui(lambda e: self._new_group(rigid=True)))
        self.bt_new_shared.on_click(ui(lambda e: self._new_group(rigid=False)))
        self.bt_remove_group.on_click(ui(lambda e: self._remove_group()))
        self.bt_undo.on_click(ui(lambda e: self._history(self.state.undo)))
        self.bt_redo.on_click(ui(lambda e: self._history(self.state.redo)))

    # ---------------------------------------------------------------- state -> widgets
    def show_settings(self) -> None:
        """One line in the panel: what the page shows and how it solves, at a glance."""
        if not hasattr(self, "md_settings"):
            return
        s = self.state.settings
        why = f" ({self.up_reason})" if self.up_reason else ""
        self.md_settings.content = (
            f"View **{self.dd_view.value}**, up **{self.dd_up.value}**{why} · "
            f"method **{s.label}** · weights **{s.weights}**"
            + (" · **secondary motion**" if s.dynamics else "")
        )

    def sync_gui_from_state(self) -> None:
        """Show the state's global r, solver settings and handles in the widgets."""
        st = self.state
        values, counts = np.unique(st.rings, return_counts=True)
        self.sl_global.value = int(min(values[np.argmax(counts)], MAX_R))
        s = st.settings
        # what the loaded shape takes: a point cloud has fewer methods and its own weights
        self.dd_method.options = tuple(c.label for c in solver_choices(st.mesh.faces is not None))
        self.dd_weights.options = domain_of(st.mesh).weight_kinds
        self.dd_method.value = s.label
        self.dd_weights.value = s.weights
        self.nb_tol.value, self.nb_maxit.value = s.tol, s.max_iter
        self.nb_budget.value = s.live_budget_ms
        self.dd_multires.value = multires_label(s.multires)
        self.cb_dynamics.value = s.dynamics
        self.sync_handle_widgets()
        self.sync_group_widgets()

    def sync_group_widgets(self, choose: int | None = None) -> None:
        """Show the painted groups in the group selector (keeping the chosen one, or
        choosing group ``choose``)."""
        g = self.state.groups
        labels = (ERASE, *(g.label(k) for k in range(g.n_groups)))
        keep = self.dd_group.value if self.dd_group.value in labels else ERASE
        self.dd_group.options = labels
        self.dd_group.value = labels[choose + 1] if choose is not None else keep

    def current_group(self) -> int:
        """The group the *Paint part* tool paints (-1: the eraser)."""
        return self.state.groups.index_of(self.dd_group.value)

    def sync_handle_widgets(self) -> None:
        """Show the active handle (the last one when it is gone) in the handle widgets."""
        names = [h.name for h in self.state.handles]
        if self.active not in names:
            self.active = names[-1] if names else None
        self.dd_handle.options = tuple(names) or ("(none)",)
        self.dd_handle.value = self.active or "(none)"
        h = self.state.handle(self.active) if self.active else None
        self.tx_name.value = h.name if h else ""
        self.cb_frozen.value = bool(h and h.frozen)
        labels = handle_controls(self.active, bool(h and h.frozen))
        self.md_active.content = labels["heading"]
        # the checkbox's label column is narrow: it names the handle in its tooltip
        self.bt_rename.label, self.cb_frozen.hint = labels["rename"], labels["frozen"] or None
        self.bt_reset.label, self.bt_remove.label = labels["reset"], labels["remove"]
        # what acts on a handle is disabled without one; Reset pose also where it would
        # do nothing (a fixed handle, or one at its rest pose)
        for w in (self.tx_name, self.bt_rename, self.cb_frozen, self.bt_remove):
            w.disabled = h is None
        self.bt_reset.disabled = h is None or h.frozen or h.at_rest
        self.md_hint.content = next_step(self.state)

    def sync_history(self) -> None:
        """Enable undo / redo as far as there is something to undo / redo."""
        self.bt_undo.disabled = not self.state.can_undo
        self.bt_redo.disabled = not self.state.can_redo

    def after_edit(self, solve: bool = True,
                   revert: Callable[[], bool] | None = None) -> int | None:
        """Refresh everything after an edit of handles or rings (not a drag); returns the
        solve's number (None when none was asked for).

        A new rigidity map is estimated first: one whose r-rings would not fit in memory
        is taken back (``revert``, by default the edit's undo step) and refused in one
        line that names the largest r that fits.
        """
        self.edit_note = ""
        self.check_rings_fit(self.state.undo if revert is None else revert)
        self.quietly(self.sync_gui_from_state)
        # the solve first: it runs while the display is rebuilt (the r view of a
        # 1.75M-vertex mesh, 0.2 s), and its shape waits for the lock held here
        seq = self.request_solve() if solve else None
        self.redraw()
        return seq

    # ---------------------------------------------------------------- widget actions
    def _make_handle(self, frozen: bool = False) -> None:
        if not len(self.state.selection):
            what = "Make fixed handle" if frozen else "Make handle"
            raise InputError(f"{what}: nothing is selected. Select a region first: tool "
                             "Select, then click on the model or Shift+drag a rectangle")
        h = self.state.add_handle(frozen=frozen)
        self.active = h.name
        self.after_edit()

    def _clear_selection(self) -> None:
        self.state.clear_selection()
        self.draw_markers()

    def _select_handle(self, name: str) -> None:
        if name == "(none)":
            return
        self.active = name
        self.quietly(self.sync_handle_widgets)
        self.draw_markers()

    def _rename(self) -> None:
        if self.active is None:
            raise InputError("rename: no handle selected")
        self.state.rename_handle(self.active, self.tx_name.value)
        self.active = self.tx_name.value.strip()
        self.after_edit(solve=False)

    def _freeze(self, frozen: bool) -> None:
        if self.active is None:
            return
        self.state.set_frozen(self.active, frozen)
        self.after_edit(solve=False)

    def _reset_pose(self) -> None:
        if self.active is None:
            return
        h = self.state.handle(self.active)
        if self.state.move_handle(h.name, (1.0, 0.0, 0.0, 0.0), h.pivot):
            self.after_edit()

    def _remove_handle(self) -> None:
        if self.active is None:
            raise InputError("remove: no handle selected")
        was_fixed = self.state.handle(self.active).frozen
        self.state.remove_handle(self.active)
        self.active = None
        self.after_edit()
        st = self.state
        if was_fixed and st.handles and not any(h.frozen for h in st.handles):
            # the solve then moves the model rigidly with the movable handles: say why
            self.notify(None, "No fixed handle left",
                        "Nothing holds the model now: it follows the movable handles "
                        "rigidly. Undo brings the fixed handle back, or pin a region.")
            self.edit_note = ("_No fixed handle left: the model follows the movable "
                              "handles rigidly (Undo brings it back)._")

    def _global_moved(self, value: Any, event: Any = None) -> None:
        """The Global r slider moved: checked now, applied once it rests."""
        if self._global_timer is not None:
            self._global_timer.cancel()
        self._global_pending = None
        # a bad value goes back at once, with what was typed before it ("5", "50", "500")
        r = validate.ring_size(value, "Global r")
        self._global_pending = (r, event)
        self._global_timer = threading.Timer(SLIDER_REST_S, self._global_rested)
        self._global_timer.daemon = True
        self._global_timer.start()

    def _global_rested(self) -> None:
        with self.lock:
            pending, self._global_pending = self._global_pending, None
        if pending is not None:
            r, event = pending
            self.ui(lambda e: self._set_global(r))(event)

    def apply_pending_global(self) -> None:
        """Apply a Global r still waiting for the slider to rest (tests, shutdown)."""
        if self._global_timer is not None:
            self._global_timer.cancel()
        self._global_rested()

    def _set_global(self, r: int) -> None:
        st = self.state
        if np.all(st.rings == r):
            return
        last = getattr(self, "_last_global", None)
        joins = (last is not None and last[1] is st.rings
                 and time.monotonic() - last[0] < GESTURE_S)
        before = st.rings
        st.set_global_rings(int(r), record=not joins)
        self._last_global = (time.monotonic(), st.rings)
        # a refusal takes back this piece only: the gesture's step keeps its start
        self.after_edit(revert=(lambda: setattr(st, "rings", before) or True) if joins
                        else None)

    def _cancel_build(self) -> None:
        """Stop a long r-ring build: the rigidity map goes back to the one being solved."""
        rings = self.solved_rings()
        if rings is not None and not np.array_equal(rings, self.state.rings):
            self.state.restore_rings(rings)
        self.after_edit()

    def _apply_settings(self) -> None:
        label = self.dd_method.value
        choice = next((c for c in solver_choices(self.state.mesh.faces is not None)
                       if c.label == label), None)
        old = self.state.settings
        # the page's values pass the same rules as a session's (a client can send anything)
        s = SolverSettings.from_dict({
            **old.to_dict(),
            "method": label if choice is None else choice.method,
            "volumetric": choice is not None and choice.volumetric,
            "weights": self.dd_weights.value,
            "tol": self.nb_tol.value,
            "max_iter": self.nb_maxit.value,
            "live_budget_ms": self.nb_budget.value,
            "multires": MULTIRES_CHOICES.get(self.dd_multires.value, old.multires),
            "dynamics": bool(self.cb_dynamics.value),
        })
        self.state.settings = s
        if (s.method, s.volumetric) != (old.method, old.volumetric):
            self.vertex_energy = None  # another method's energy: not shown as this one's
        self.show_settings()
        self.request_solve()

    def _up_chosen(self) -> None:
        """The user picked an up axis in the panel: it holds until the next mesh loads."""
        self.up_reason = "chosen in the panel"
        self.aim_cameras()

    def _new_group(self, rigid: bool) -> None:
        g = self.state.new_group(rigid)
        self.quietly(lambda: self.sync_group_widgets(choose=g))
        self.sync_history()

    def _remove_group(self) -> None:
        g = self.current_group()
        if g < 0:
            raise InputError("remove group: choose a group first")
        self.state.remove_group(g)
        self.after_edit()

    def _history(self, step: Callable[[], bool]) -> None:
        st = self.state
        if step():
            self.after_edit(revert=st.redo if step == st.undo else st.undo)

    def check_rings_fit(self, revert: Callable[[], bool]) -> None:
        """Refuse a rigidity map whose r-rings would not fit (estimated, as the library
        does before building), after taking the edit back with ``revert``."""
        from arapkit.arap.ringcost import check_ring_memory

        st = self.state
        if st.rings is getattr(self, "_rings_checked", None):
            return
        s = st.settings
        if s.info.rigidity_map and not s.volumetric:  # a volume's map is the library's
            try:
                check_ring_memory(st.n, st.mesh.edges, st.rings, st.mesh.name)
            except InputError:
                revert()
                self._rings_checked = st.rings
                self.quietly(self.sync_gui_from_state)
                self.redraw()  # the colours of the map taken back
                raise
        self._rings_checked = st.rings
