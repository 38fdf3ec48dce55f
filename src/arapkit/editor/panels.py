"""The editor's side panel: its widgets, their callbacks, and keeping them in step.

:class:`Panels` is the part of :class:`arapkit.editor.app.EditorApp` that builds the
viser GUI (tools, handles, rigidity, view, solver, session), turns widget events into
edits of the :class:`~arapkit.editor.state.EditorState`, and shows the state back in the
widgets.  Every callback runs through :meth:`Panels.ui`: echoes of the page's own updates
are skipped and bad input becomes a notification, never an exception in viser's loop.
"""

from __future__ import annotations

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
from arapkit.editor.settings import SolverSettings, solver_choices
from arapkit.editor.state import EditorState
from arapkit.editor.tools import TOOLS, find_tool
from arapkit.errors import InputError

__all__ = ["MAX_R", "VIEWS", "Panels", "handle_controls", "next_step"]

VIEWS = ("Shaded", "Rigidity r", "Energy")
#: the largest r the sliders offer: the library's one rule for r
MAX_R = validate.MAX_RINGS
_FIRST_TOOL = "Select"
#: a handle name longer than this is cut short on the buttons that act on it
_SHOWN_NAME = 24
_ERROR_MARK = "⚠ "


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
    """
    movable = [h for h in state.handles if not h.frozen]
    fixed = len(state.handles) - len(movable)
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


def handle_controls(name: str | None) -> dict[str, str]:
    """Labels of the controls that act on one handle, naming it (``None``: no handle).

    Examples
    --------
    >>> handle_controls("tip")["remove"]
    'Remove tip'
    >>> handle_controls(None)["remove"]
    'Remove handle'
    """
    if name is None:
        return {"heading": "No handle yet.", "rename": "Rename", "frozen": "",
                "reset": "Reset pose", "remove": "Remove handle"}
    shown = name if len(name) <= _SHOWN_NAME else name[:_SHOWN_NAME - 1] + "…"
    return {"heading": f"Handle **{shown}** (yellow dots): the controls below act on it.",
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
        self.md_status = gui.add_markdown("Starting ...")
        self._status_ok = ""
        self.md_hint = gui.add_markdown(next_step(self.state))
        # at the top: the colour view's legend stays in sight without scrolling
        self.html_legend = gui.add_html("")
        self.md_mesh = gui.add_markdown("")
        self.md_settings = gui.add_markdown("")
        with gui.add_folder("Tools"):
            self.dd_tool = gui.add_dropdown("Tool", tuple(t.label for t in TOOLS),
                                            initial_value=_FIRST_TOOL)
            self.sl_radius = gui.add_slider("Radius (% size)", 0.5, 30.0, 0.5, 3.0)
            # the one promise every tool keeps; the rest is the chosen tool's own help line
            gui.add_markdown("Plain drag orbits the camera, scroll zooms.")
            self.md_tool_help = gui.add_markdown(find_tool(_FIRST_TOOL).help)
            self.md_selection = gui.add_markdown("Selected: **0** vertices")
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
            self.sl_global = gui.add_slider("Global r", 1, MAX_R, 1, 1, marks=marks)
            self.sl_paint = gui.add_slider("Paint r", 1, MAX_R, 1, 3, marks=marks)
            self.up_rings = gui.add_upload_button("Load rings file", icon=viser.Icon.UPLOAD)
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
                self.notify(event, "Cannot do that", str(exc), error=True)
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
        self.sl_global.on_update(ui(lambda e: self._set_global(self.sl_global.value)))
        self.dd_view.on_update(ui(lambda e: (self.rebuild_display(), self.show_settings())))
        self.cb_show_handles.on_update(ui(lambda e: self.draw_markers()))
        self.dd_up.on_update(ui(lambda e: self._up_chosen()))
        for w in (self.dd_method, self.dd_weights, self.nb_tol, self.nb_maxit, self.nb_budget,
                  self.cb_dynamics):
            w.on_update(ui(lambda e: self._apply_settings()))
        self.bt_solve.on_click(ui(lambda e: self.request_solve()))
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
        self.cb_dynamics.value = s.dynamics
        self.sync_handle_widgets()

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
        labels = handle_controls(self.active)
        self.md_active.content = labels["heading"]
        # the checkbox's label column is narrow: it names the handle in its tooltip
        self.bt_rename.label, self.cb_frozen.hint = labels["rename"], labels["frozen"] or None
        self.bt_reset.label, self.bt_remove.label = labels["reset"], labels["remove"]
        self.md_hint.content = next_step(self.state)

    def sync_history(self) -> None:
        """Enable undo / redo as far as there is something to undo / redo."""
        self.bt_undo.disabled = not self.state.can_undo
        self.bt_redo.disabled = not self.state.can_redo

    def after_edit(self, solve: bool = True) -> int | None:
        """Refresh everything after an edit of handles or rings (not a drag); returns the
        solve's number (None when none was asked for)."""
        self.quietly(self.sync_gui_from_state)
        # the solve first: it runs while the display is rebuilt (the r view of a
        # 1.75M-vertex mesh, 0.2 s), and its shape waits for the lock held here
        seq = self.request_solve() if solve else None
        self.redraw()
        return seq

    # ---------------------------------------------------------------- widget actions
    def _make_handle(self, frozen: bool = False) -> None:
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
        self.state.remove_handle(self.active)
        self.active = None
        self.after_edit()

    def _set_global(self, r: int) -> None:
        if np.all(self.state.rings == r):
            return
        self.state.set_global_rings(int(r))
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

    def _history(self, step: Callable[[], bool]) -> None:
        if step():
            self.after_edit()
