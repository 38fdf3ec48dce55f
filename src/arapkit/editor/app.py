"""The browser editor: a viser page over :class:`EditorState` and :class:`SolveWorker`.

Interaction model
-----------------
* Plain drags orbit the camera.  A plain click applies the current tool at the clicked
  point (select / paint / flood fill); Shift+click adds to the selection; Shift+drag
  draws a rectangle (rectangle tool) or paints a stroke (brush tool).
* Every handle that is not frozen has a transform gizmo; dragging it moves the handle
  targets, and the solver thread deforms the mesh live.
* Exports and saved sessions are written to the folder chosen at start-up; the page
  never names a path.

Examples
--------
>>> from arapkit.mesh.shapes import bar
>>> from arapkit.editor.state import EditorState
>>> app = EditorApp(EditorState(bar()), port=8123)  # doctest: +SKIP
>>> print(app.url)  # doctest: +SKIP
http://127.0.0.1:8123
>>> app.stop()  # doctest: +SKIP
"""

from __future__ import annotations

import dataclasses
import re
import signal
import tempfile
import threading
import time
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import viser

from arapkit import validate
from arapkit.editor.state import METHODS as PANEL_METHODS
from arapkit.editor.state import CameraView, EditorState, SolverSettings, raycast
from arapkit.editor.views import (
    RING_COLORS,
    SHADED_COLOR,
    energy_colors,
    energy_labels,
    energy_legend_html,
    energy_scale,
    face_groups,
    ring_labels,
    rings_legend_html,
)
from arapkit.editor.worker import SolveRequest, SolveUpdate, SolveWorker
from arapkit.errors import InputError
from arapkit.io.formats import READ_FORMATS, is_readable_mesh, readable_formats
from arapkit.mesh.model import bounding_box_diagonal

TOOLS = ("Navigate", "Select: click", "Select: rectangle", "Paint brush", "Flood fill")
VIEWS = ("Shaded", "Rigidity r", "Energy")
_METHOD_LABELS = {"arap": "r-ring ARAP", "laplacian": "Laplacian editing",
                  "spokes-and-rims": "spokes-and-rims ARAP", "sr-arap": "SR-ARAP",
                  "embedded": "embedded deformation", "volumetric": "volumetric ARAP"}
#: dropdown label -> solver method, for every method of the solver panel
METHODS = {_METHOD_LABELS.get(m, m): m for m in PANEL_METHODS}
UP_AXES = {"+z": (0, 0, 1), "+y": (0, 1, 0), "+x": (1, 0, 0),
           "-z": (0, 0, -1), "-y": (0, -1, 0), "-x": (-1, 0, 0)}
MESH_SUFFIXES = tuple("." + f for f in READ_FORMATS)
MAX_R = 10
HANDLE_RGB, FROZEN_RGB, ACTIVE_RGB, SELECT_RGB = (255, 140, 0), (110, 110, 135), (255, 235, 0), (
    230, 30, 200)


def safe_stem(name: str, default: str = "mesh") -> str:
    """A file stem made only of ``[A-Za-z0-9_-]``: a name can never become a path.

    Examples
    --------
    >>> safe_stem("../../etc/passwd.off"), safe_stem("My bunny.ply.gz"), safe_stem("..")
    ('passwd', 'My_bunny', 'mesh')
    """
    base = re.split(r"[\\/]", str(name))[-1]
    base = base.split(".")[0]
    base = re.sub(r"[^A-Za-z0-9_-]+", "_", base).strip("_")[:48]
    return base or default


def _raise_keyboard_interrupt(signum: int, frame: Any) -> None:
    raise KeyboardInterrupt


def _printable(name: Any) -> str:
    """A file name safe to show in a one-line message (control characters escaped)."""
    text = repr(str(name))[1:-1]
    return text if len(text) <= 80 else text[:77] + "..."


def _size(n_bytes: float) -> str:
    """Human-readable size: ``_size(1536) == '1.5 KB'``."""
    for unit in ("bytes", "KB", "MB"):
        if n_bytes < 1024 or unit == "MB":
            return f"{n_bytes:.0f} {unit}" if unit == "bytes" else f"{n_bytes:.1f} {unit}"
        n_bytes /= 1024
    return f"{n_bytes:.1f} MB"


class EditorApp:
    """A running editor: viser server, GUI, scene and solver thread.

    Parameters
    ----------
    state : EditorState
        Mesh, handles and rigidity to start from.
    host, port : where to serve (``127.0.0.1`` unless asked otherwise).
    export_dir : folder for exports and saved sessions (created on first use).
    max_upload_mb : size cap for meshes, rings and sessions uploaded from the page.
    verbose : let viser print its banner.
    up : signed axis ('+y', '-z', ...) shown up; default: :func:`arapkit.guess_up` of each
        mesh loaded (the same guess as ``arapkit info`` and the figures).
    """

    def __init__(
        self,
        state: EditorState,
        *,
        host: str = "127.0.0.1",
        port: int = 8080,
        export_dir: str | Path = "arapkit-edits",
        max_upload_mb: float = 64.0,
        verbose: bool = False,
        up: str | None = None,
    ) -> None:
        if up is not None and up not in UP_AXES:
            raise InputError(f"up axis {up!r}: expected one of {', '.join(UP_AXES)}")
        # checked before anything starts: a bad port must not leave a thread running
        port = validate.port(port, "port")
        host = validate.host(host, "host")
        max_upload_mb = validate.upload_mb(max_upload_mb, "max_upload_mb")
        self.state = state
        self._up_override = up
        self.up_reason = ""
        self.export_dir = Path(export_dir).expanduser().resolve()
        self.max_upload_bytes = int(max_upload_mb * 2**20)
        self.lock = threading.RLock()
        self.server = viser.ViserServer(host=host, port=port, label="arapkit editor",
                                        verbose=verbose)
        self.worker = SolveWorker(self._on_solve_update)
        self.last_update: SolveUpdate | None = None
        self.active: str | None = None
        self._quiet = False
        self._stroke_open = False
        self._stroke: set[int] = set()
        self._last_stroke_draw = 0.0
        self._vertex_energy: np.ndarray | None = None
        self._groups: list[tuple[Any, Any]] = []
        self._gizmos: list[Any] = []
        self._gizmo_serial = 0
        self._markers: dict[str, Any] = {}
        self.mesh_node: Any = None
        #: called as hook(update, perf_counter_when_sent) after each shape is handed to viser
        self.sent_hooks: list[Callable[[SolveUpdate, float], None]] = []
        #: names of uploads dropped while arriving because they were over the cap
        self.rejected_uploads: list[str] = []
        self._upload_states: dict[str, Any] = {}
        self._build_gui()
        self._guard_uploads()
        self._bind_scene_events()
        self.worker.start()
        self._install_mesh()

    # ================================================================ lifecycle
    @property
    def url(self) -> str:
        """The address served, as bound (``0.0.0.0`` means every interface)."""
        host = self.server.get_host() or "0.0.0.0"
        shown = f"[{host}]" if ":" in host else host
        return f"http://{shown}:{self.server.get_port()}"

    def stop(self) -> None:
        """Stop the solver thread and the server."""
        self.worker.stop()
        self.server.stop()

    def serve_forever(self) -> None:
        """Block until Ctrl-C (or SIGTERM), then shut down."""
        if threading.current_thread() is threading.main_thread():
            # A service manager stops us with SIGTERM: shut down as for Ctrl-C.
            signal.signal(signal.SIGTERM, _raise_keyboard_interrupt)
        try:
            while True:
                time.sleep(3600)
        except KeyboardInterrupt:
            pass
        finally:
            self.stop()

    def wait_idle(self, timeout: float = 30.0) -> bool:
        """Wait until the solver has nothing pending (tests and benchmarks)."""
        return self.worker.wait_idle(timeout)

    def served_vertices(self) -> np.ndarray:
        """The vertex positions last sent to the page (shaded mesh node)."""
        return np.asarray(self.mesh_node.vertices, dtype=np.float64)

    # ================================================================ scene set-up
    def _install_mesh(self) -> None:
        """(Re)create every scene node for ``self.state`` (start-up, new mesh, session)."""
        with self.lock:
            st = self.state
            V = st.vertices
            lo, hi = V.min(axis=0), V.max(axis=0)
            self._diag = bounding_box_diagonal(V) or 1.0
            e = np.asarray(st.mesh.edges)
            self._edge_len = float(np.linalg.norm(V[e[:, 0]] - V[e[:, 1]], axis=1).mean())
            self.worker.reset_shape(V, st.mesh)
            self._vertex_energy = None
            self.last_update = None
            if self.mesh_node is not None:
                self.mesh_node.remove()
            self.mesh_node = self.server.scene.add_mesh_simple(
                "/mesh/shaded", V.astype(np.float32), np.asarray(st.mesh.faces, np.uint32),
                color=SHADED_COLOR, side="double",
            )
            self._centre = (lo + hi) / 2
            self._quietly(self._choose_up)
            self._aim_cameras()
            self.active = st.handles[-1].name if st.handles else None
            self._quietly(self._sync_gui_from_state)
            self._redraw()
            self.md_mesh.content = self._mesh_info()
        self.request_solve()

    def _choose_up(self) -> None:
        """Set the up axis of a newly loaded mesh: the override, else the shared guess."""
        from arapkit.mesh.orientation import guess_up

        if self._up_override is not None:
            self.dd_up.value = self._up_override
            self.up_reason = "set with --up"
        else:
            g = guess_up(self.state.vertices)
            self.dd_up.value = g.axis
            self.up_reason = f"guessed, confidence {g.confidence:.2f}"

    def _aim_cameras(self) -> None:
        """Look at the mesh from the front, slightly above, for the chosen up axis."""
        from arapkit.mesh.orientation import view_frame

        up_name = self.dd_up.value
        up = np.array(UP_AXES[up_name], dtype=np.float64)
        # the figures' front: along the thinner horizontal axis (row 2 points at the viewer)
        front = view_frame(self.state.vertices, "front", up_name)[0][2]
        front = front - (front @ up) * up
        front /= np.linalg.norm(front)
        centre = self._centre
        eye = centre + self._diag * (0.9 * front + 0.55 * up + 0.15 * np.cross(up, front))
        # Aim a little right of the centre so the GUI panel (right side) hides less.
        right = np.cross(centre - eye, up)
        shift = 0.12 * self._diag * right / np.linalg.norm(right)
        centre, eye = centre + shift, eye + shift
        self.server.scene.set_up_direction(up_name)
        self.server.initial_camera.position = tuple(eye)
        self.server.initial_camera.look_at = tuple(centre)
        for client in self.server.get_clients().values():
            # position before look-at: moving the camera drags its look-at point along.
            client.camera.up_direction = tuple(up)
            client.camera.position = tuple(eye)
            client.camera.look_at = tuple(centre)
        self._show_settings()

    def _show_settings(self) -> None:
        """One line in the panel: what the page shows and how it solves, at a glance."""
        if not hasattr(self, "md_settings"):
            return
        s = self.state.settings
        method = next((k for k, v in METHODS.items() if v == s.method), s.method)
        why = f" ({self.up_reason})" if self.up_reason else ""
        self.md_settings.content = (
            f"View **{self.dd_view.value}**, up **{self.dd_up.value}**{why} · "
            f"method **{method}** · weights **{s.weights}**"
        )

    def _mesh_info(self) -> str:
        m = self.state.mesh
        notes = "; ".join(getattr(m, "notes", [])[:3])
        return (f"**{m.name}**: {m.n_vertices:,} vertices, {m.n_faces:,} faces"
                + (f"  \n_{notes}_" if notes else ""))

    def _redraw(self) -> None:
        """Everything that depends on handles/rings/view, not just on vertex positions."""
        self._rebuild_display()
        self._draw_markers()
        self._sync_gizmos()
        self._sync_history()

    # ---------------------------------------------------------------- mesh display
    def _rebuild_display(self) -> None:
        for _, node in self._groups:
            node.remove()
        self._groups = []
        st = self.state
        V32 = st.vertices.astype(np.float32)
        view = self.dd_view.value
        labels, colors, legend = None, (), ""
        if view == "Rigidity r":
            labels, colors, legend = ring_labels(st.rings), RING_COLORS, rings_legend_html()
        elif view == "Energy":
            if self._vertex_energy is None:
                legend = "<i>energy appears after an r-ring ARAP solve</i>"
            else:
                # Round-off energies (an undeformed mesh) all get the lowest colour.
                vmax = max(energy_scale(self._vertex_energy), 1e-12 * self._diag**2)
                colors = tuple(energy_colors())
                labels = energy_labels(self._vertex_energy, vmax, len(colors))
                legend = energy_legend_html(vmax)
        if labels is None:
            self.mesh_node.vertices = V32
            self.mesh_node.visible = True
        else:
            self.mesh_node.visible = False
            for g in face_groups(st.mesh.faces, labels, len(colors)):
                node = self.server.scene.add_mesh_simple(
                    f"/mesh/group{g.label}", V32[g.vertices], g.faces.astype(np.uint32),
                    color=colors[g.label], side="double",
                )
                self._groups.append((g, node))
        self.html_legend.content = legend
        self._bind_brush()

    def _refresh_vertices(self, V: np.ndarray) -> None:
        """Send new positions only (a drag): the colour split stays as it is."""
        V32 = V.astype(np.float32)
        # The shaded node is what tests read back, so it is always kept current.
        self.mesh_node.vertices = V32
        for g, node in self._groups:
            node.vertices = V32[g.vertices]
        for key, idx in (("handles", self.state.handle_indices()),
                         ("selection", self.state.selection)):
            node = self._markers.get(key)
            if node is not None and len(idx):
                node.points = V32[idx]

    def _draw_markers(self) -> None:
        st = self.state
        for node in self._markers.values():
            node.remove()
        self._markers = {}
        size = 0.6 * self._edge_len
        idx = st.handle_indices()
        if len(idx) and self.cb_show_handles.value:
            cols = np.concatenate([
                np.tile(ACTIVE_RGB if h.name == self.active else
                        FROZEN_RGB if h.frozen else HANDLE_RGB, (len(h.vertices), 1))
                for h in st.handles
            ]).astype(np.uint8)
            self._markers["handles"] = self.server.scene.add_point_cloud(
                "/markers/handles", st.vertices[idx].astype(np.float32), cols,
                point_size=size, point_shape="circle", precision="float32",
            )
        if len(st.selection):
            self._markers["selection"] = self.server.scene.add_point_cloud(
                "/markers/selection", st.vertices[st.selection].astype(np.float32),
                np.array(SELECT_RGB, np.uint8), point_size=size * 1.2, point_shape="circle",
                precision="float32",
            )
        self.md_selection.content = f"Selected: **{len(st.selection)}** vertices"

    def _sync_gizmos(self) -> None:
        for g in self._gizmos:
            g.remove()
        self._gizmos = []
        for h in self.state.handles:
            if not h.frozen:
                self._gizmos.append(self._make_gizmo(h.name, h.wxyz, h.position))

    def _make_gizmo(self, name: str, wxyz: np.ndarray, position: np.ndarray) -> Any:
        # Fresh node names: a late message for a removed gizmo can never hit a new one.
        self._gizmo_serial += 1
        tc = self.server.scene.add_transform_controls(
            f"/gizmos/g{self._gizmo_serial}", scale=0.12 * self._diag, line_width=3.0,
            depth_test=False, wxyz=tuple(wxyz), position=tuple(position),
        )

        # async: viser then runs start/update/end in order on its event loop.
        async def on_update(event: Any) -> None:
            self.drag_handle(name, tc.wxyz, tc.position, event.phase)

        tc.on_update(on_update)
        return tc

    # ================================================================ solving
    def request_solve(self) -> int | None:
        """Send the current handles/targets/rings to the solver thread (latest wins)."""
        with self.lock:
            st = self.state
            idx, tgt = st.constraints()
            if len(idx) == 0:
                self._status("No handles yet: select vertices (click or Shift+drag a "
                             "rectangle) and press **Make handle from selection**.")
                return None
            req = SolveRequest(st.mesh, idx, tgt, st.rings, dataclasses.replace(st.settings))
            return self.worker.submit(req)

    def drag_handle(
        self, name: str, wxyz: Any, position: Any, phase: str = "update"
    ) -> int | None:
        """Move handle ``name``'s gizmo (what a gizmo drag does); returns the solve number.

        ``phase`` ``"start"`` records an undo step, so one drag is undone at once.
        """
        with self.lock:
            try:
                h = self.state.handle(name)
            except KeyError:
                return None
            same = np.allclose(h.wxyz, wxyz) and np.allclose(h.position, position)
            if not self.state.move_handle(name, wxyz, position, record=phase == "start"):
                return None
            # The end of a drag repeats the last pose: let the running solve finish.
            seq = None if same and phase == "end" else self.request_solve()
            if phase != "update":
                if self.active != name:
                    self.active = name
                    self._quietly(self._sync_handle_widgets)
                    self._draw_markers()
                self._sync_history()
            return seq

    def _on_solve_update(self, u: SolveUpdate) -> None:
        """Worker thread: show a new shape (drops results for a mesh no longer loaded)."""
        with self.lock:
            if u.mesh is not self.state.mesh:
                return
            self.state.vertices = np.asarray(u.vertices, dtype=np.float64)
            self.last_update = u
            if u.vertex_energy is not None:
                self._vertex_energy = u.vertex_energy
            if u.final and self.dd_view.value == "Energy" and u.vertex_energy is not None:
                self._rebuild_display()
                self._refresh_vertices(self.state.vertices)
            else:
                self._refresh_vertices(self.state.vertices)
            sent = time.perf_counter()
            self._status_from(u)
        for hook in self.sent_hooks:
            hook(u, sent)

    def _status_from(self, u: SolveUpdate) -> None:
        method = "Laplacian editing" if self.state.settings.method == "laplacian" else (
            "r-ring ARAP")
        if u.error:
            self._status(f"**{method}**: {u.error}")
            return
        energy = "n/a" if not np.isfinite(u.energy) else f"{u.energy:.5g}"
        phase = ("converged" if u.converged else "stopped at max iterations" if u.final
                 else "iterating ...")
        setup = f" (setup {u.setup_ms:.0f} ms)" if u.setup_ms >= 1 else ""
        first = u.latency_ms if not u.final else next(
            (ms for seq, ms in reversed(self.worker.latencies) if seq == u.seq), u.latency_ms)
        shown = f"first shape **{first:.0f} ms** after the move{setup}"
        total = f" · final after {u.latency_ms:.0f} ms" if u.final else ""
        notes = "".join(f"  \n_{n}_" for n in u.notes)
        self._status(
            f"**{method}** · iterations **{u.iterations}** · energy **{energy}** · {phase}  \n"
            f"{shown}{total}{notes}"
        )

    def _status(self, text: str) -> None:
        self.md_status.content = text

    # ================================================================ GUI
    def _build_gui(self) -> None:
        gui = self.server.gui
        self.md_status = gui.add_markdown("Starting ...")
        self.md_mesh = gui.add_markdown("")
        self.md_settings = gui.add_markdown("")
        with gui.add_folder("Tools"):
            self.dd_tool = gui.add_dropdown("Tool", TOOLS, initial_value="Select: click")
            self.sl_radius = gui.add_slider("Radius (% size)", 0.5, 30.0, 0.5, 3.0)
            gui.add_markdown("Click on the mesh to use the tool (Shift+click adds to the "
                             "selection). Shift+drag: rectangle / brush stroke. Plain drag "
                             "orbits.")
            self.md_selection = gui.add_markdown("Selected: **0** vertices")
            self.bt_make = gui.add_button("Make handle from selection", icon=viser.Icon.PLUS)
            self.bt_clear_sel = gui.add_button("Clear selection")
        with gui.add_folder("Handles"):
            self.dd_handle = gui.add_dropdown("Handle", ("(none)",))
            self.tx_name = gui.add_text("Name", "")
            self.bt_rename = gui.add_button("Rename")
            self.cb_frozen = gui.add_checkbox("Frozen (fixed)", False)
            self.bt_reset = gui.add_button("Reset pose")
            self.bt_remove = gui.add_button("Remove handle", color="red")
        with gui.add_folder("Rigidity"):
            self.sl_global = gui.add_slider("Global r", 1, MAX_R, 1, 1)
            self.sl_paint = gui.add_slider("Paint r", 1, MAX_R, 1, 3)
            self.up_rings = gui.add_upload_button("Load rings file", icon=viser.Icon.UPLOAD)
        with gui.add_folder("View"):
            self.dd_view = gui.add_dropdown("Colour", VIEWS, initial_value="Shaded")
            self.dd_up = gui.add_dropdown("Up axis", tuple(UP_AXES), initial_value="+z")
            self.cb_show_handles = gui.add_checkbox("Highlight handles", True)
            self.html_legend = gui.add_html("")
        with gui.add_folder("Solver"):
            from arapkit.mesh.weights import WEIGHT_KINDS

            s = self.state.settings
            self.dd_method = gui.add_dropdown("Method", tuple(METHODS))
            self.dd_weights = gui.add_dropdown("Weights", WEIGHT_KINDS, initial_value=s.weights)
            self.nb_tol = gui.add_number("Tolerance", s.tol, min=1e-9, max=0.5, step=1e-6)
            self.nb_maxit = gui.add_number("Max iterations", s.max_iter, min=1, max=100000,
                                           step=1)
            self.nb_budget = gui.add_number("Live budget (ms)", s.live_budget_ms, min=1.0,
                                            max=5000.0, step=1.0)
            self.bt_solve = gui.add_button("Solve again")
        with gui.add_folder("Session"):
            self.bt_undo = gui.add_button("Undo", icon=viser.Icon.ARROW_BACK_UP)
            self.bt_redo = gui.add_button("Redo", icon=viser.Icon.ARROW_FORWARD_UP)
            self.bt_save = gui.add_button("Save session")
            self.up_session = gui.add_upload_button("Load session", mime_type=".json")
            self.bt_export = gui.add_button("Export mesh + rings", icon=viser.Icon.DOWNLOAD)
            self.up_mesh = gui.add_upload_button(
                "Open mesh", mime_type=",".join(MESH_SUFFIXES) + ",.gz", icon=viser.Icon.UPLOAD)
            gui.add_markdown(f"Exports and sessions go to `{self.export_dir}`.")
        self._bind_gui_events()

    def _ui(self, fn: Callable[[Any], None]) -> Callable[[Any], None]:
        """Wrap a GUI callback: skip echoes of our own updates, report bad input."""

        def wrapped(event: Any) -> None:
            if self._quiet:
                return
            try:
                with self.lock:
                    fn(event)
            except InputError as exc:
                self._notify(event, "Cannot do that", str(exc), error=True)
            except Exception as exc:  # a bug, not the user's fault: say so in the page too
                traceback.print_exc()
                self._notify(event, "Internal error",
                             f"{type(exc).__name__}: {exc} (please report this)", error=True)

        return wrapped

    def _notify(self, event: Any, title: str, body: str, error: bool = False) -> None:
        client = getattr(event, "client", None)
        targets = [client] if client is not None else list(self.server.get_clients().values())
        for c in targets:
            c.add_notification(title, body, auto_close_seconds=8.0,
                               color="red" if error else "green")
        if error:
            self._status(f"⚠ {body}")

    def _quietly(self, fn: Callable[[], None]) -> None:
        # Assigning a widget value runs its callbacks; these are not user actions.
        old, self._quiet = self._quiet, True
        try:
            fn()
        finally:
            self._quiet = old

    def _bind_gui_events(self) -> None:  # noqa: C901 - one small closure per widget
        ui = self._ui
        self.dd_tool.on_update(ui(lambda e: self._on_tool()))
        self.bt_make.on_click(ui(lambda e: self._make_handle()))
        self.bt_clear_sel.on_click(ui(lambda e: self._clear_selection()))
        self.dd_handle.on_update(ui(lambda e: self._select_handle(self.dd_handle.value)))
        self.bt_rename.on_click(ui(lambda e: self._rename()))
        self.cb_frozen.on_update(ui(lambda e: self._freeze(self.cb_frozen.value)))
        self.bt_reset.on_click(ui(lambda e: self._reset_pose()))
        self.bt_remove.on_click(ui(lambda e: self._remove_handle()))
        self.sl_global.on_update(ui(lambda e: self._set_global(self.sl_global.value)))
        self.up_rings.on_upload(ui(self._upload_rings))
        self.dd_view.on_update(ui(lambda e: (self._rebuild_display(), self._show_settings())))
        self.cb_show_handles.on_update(ui(lambda e: self._draw_markers()))
        self.dd_up.on_update(ui(lambda e: self._up_chosen()))
        for w in (self.dd_method, self.dd_weights, self.nb_tol, self.nb_maxit, self.nb_budget):
            w.on_update(ui(lambda e: self._apply_settings()))
        self.bt_solve.on_click(ui(lambda e: self.request_solve()))
        self.bt_undo.on_click(ui(lambda e: self._history(self.state.undo)))
        self.bt_redo.on_click(ui(lambda e: self._history(self.state.redo)))
        self.bt_save.on_click(ui(self._save_session))
        self.up_session.on_upload(ui(self._upload_session))
        self.bt_export.on_click(ui(self._export))
        self.up_mesh.on_upload(ui(self._upload_mesh))

    def _sync_gui_from_state(self) -> None:
        st = self.state
        values, counts = np.unique(st.rings, return_counts=True)
        self.sl_global.value = int(min(values[np.argmax(counts)], MAX_R))
        s = st.settings
        self.dd_method.value = next(k for k, v in METHODS.items() if v == s.method)
        self.dd_weights.value = s.weights
        self.nb_tol.value, self.nb_maxit.value = s.tol, s.max_iter
        self.nb_budget.value = s.live_budget_ms
        self._sync_handle_widgets()

    def _sync_handle_widgets(self) -> None:
        names = [h.name for h in self.state.handles]
        if self.active not in names:
            self.active = names[-1] if names else None
        self.dd_handle.options = tuple(names) or ("(none)",)
        self.dd_handle.value = self.active or "(none)"
        h = self.state.handle(self.active) if self.active else None
        self.tx_name.value = h.name if h else ""
        self.cb_frozen.value = bool(h and h.frozen)

    def _sync_history(self) -> None:
        self.bt_undo.disabled = not self.state.can_undo
        self.bt_redo.disabled = not self.state.can_redo

    def _after_edit(self, solve: bool = True) -> None:
        """Refresh everything after an edit of handles or rings (not a drag)."""
        self._quietly(self._sync_gui_from_state)
        self._redraw()
        if solve:
            self.request_solve()

    # ---------------------------------------------------------------- GUI actions
    def _radius(self) -> float:
        return float(self.sl_radius.value) / 100.0 * self._diag

    def _on_tool(self) -> None:
        tool = self.dd_tool.value
        scene = self.server.scene
        scene.remove_rect_select_callback("all")
        if tool == "Select: rectangle":
            scene.on_rect_select(modifier="shift")(self._on_rect)
        self._bind_brush()

    def _make_handle(self) -> None:
        h = self.state.add_handle()
        self.active = h.name
        self._after_edit()

    def _clear_selection(self) -> None:
        self.state.clear_selection()
        self._draw_markers()

    def _select_handle(self, name: str) -> None:
        if name == "(none)":
            return
        self.active = name
        self._quietly(self._sync_handle_widgets)
        self._draw_markers()

    def _rename(self) -> None:
        if self.active is None:
            raise InputError("rename: no handle selected")
        self.state.rename_handle(self.active, self.tx_name.value)
        self.active = self.tx_name.value.strip()
        self._after_edit(solve=False)

    def _freeze(self, frozen: bool) -> None:
        if self.active is None:
            return
        self.state.set_frozen(self.active, frozen)
        self._after_edit(solve=False)

    def _reset_pose(self) -> None:
        if self.active is None:
            return
        h = self.state.handle(self.active)
        if self.state.move_handle(h.name, (1.0, 0.0, 0.0, 0.0), h.pivot):
            self._after_edit()

    def _remove_handle(self) -> None:
        if self.active is None:
            raise InputError("remove: no handle selected")
        self.state.remove_handle(self.active)
        self.active = None
        self._after_edit()

    def _set_global(self, r: int) -> None:
        if np.all(self.state.rings == r):
            return
        self.state.set_global_rings(int(r))
        self._after_edit()

    def _apply_settings(self) -> None:
        # the page's values pass the same rules as a session's (a client can send anything)
        s = SolverSettings.from_dict({
            **self.state.settings.to_dict(),
            "method": METHODS.get(self.dd_method.value, self.dd_method.value),
            "weights": self.dd_weights.value,
            "tol": self.nb_tol.value,
            "max_iter": self.nb_maxit.value,
            "live_budget_ms": self.nb_budget.value,
        })
        self.state.settings = s
        if s.method == "laplacian":
            self._vertex_energy = None
        self._show_settings()
        self.request_solve()

    def _up_chosen(self) -> None:
        """The user picked an up axis in the panel: it holds until the next mesh loads."""
        self.up_reason = "chosen in the panel"
        self._aim_cameras()

    def _history(self, step: Callable[[], bool]) -> None:
        if step():
            self._after_edit()

    # ---------------------------------------------------------------- pointer tools
    def _bind_scene_events(self) -> None:
        scene = self.server.scene
        scene.on_click()(self._on_click_replace)
        scene.on_click(modifier="shift")(self._on_click_add)

    def _on_click_replace(self, event: Any) -> None:
        self._on_click(event, add=False)

    def _on_click_add(self, event: Any) -> None:
        self._on_click(event, add=True)

    def _hit(self, origin: Any, direction: Any) -> tuple[int, np.ndarray] | None:
        st = self.state
        return raycast(st.vertices, np.asarray(st.mesh.faces), np.asarray(origin, np.float64),
                       np.asarray(direction, np.float64))

    def _on_click(self, event: Any, add: bool) -> None:
        tool = self.dd_tool.value
        if tool == "Navigate":
            return
        try:
            with self.lock:
                hit = self._hit(event.ray_origin, event.ray_direction)
                if hit is None:
                    return
                self.apply_tool(tool, hit[1], face=hit[0], add=add)
        except InputError as exc:
            self._notify(event, "Cannot do that", str(exc), error=True)

    def apply_tool(self, tool: str, point: np.ndarray, face: int | None = None,
                   add: bool = False) -> int:
        """Apply a click tool at a surface point; returns the vertices affected."""
        with self.lock:
            st = self.state
            if tool.startswith("Select"):
                before = len(st.selection)
                st.select_near(point, self._radius(), mode="add" if add else "replace")
                self._draw_markers()
                return len(st.selection) - (before if add else 0)
            if tool == "Paint brush":
                n = st.paint(point, self._radius(), int(self.sl_paint.value))
            elif tool == "Flood fill":
                corners = st.mesh.faces[face] if face is not None else None
                seed = (st.nearest_vertex(point) if corners is None else int(corners[np.argmin(
                    np.linalg.norm(st.vertices[corners] - point, axis=1))]))
                n = st.flood_fill(seed, int(self.sl_paint.value))
            else:
                return 0
            self._after_edit()
            return n

    def _on_rect(self, event: Any) -> None:
        if self.dd_tool.value != "Select: rectangle":
            return
        cam = event.client.camera
        view = CameraView(np.asarray(cam.position), np.asarray(cam.wxyz), float(cam.fov),
                          float(cam.aspect))
        with self.lock:
            self.state.select_in_rect(view, event.screen_min, event.screen_max, mode="add")
            self._draw_markers()

    def _bind_brush(self) -> None:
        nodes = [self.mesh_node] + [n for _, n in self._groups]
        for node in nodes:
            node.remove_drag_callback("all")
            if self.dd_tool.value == "Paint brush":
                node.on_drag("left", modifier="shift")(self._on_brush)

    async def _on_brush(self, event: Any) -> None:
        # async: viser keeps start/update/end in order, so a stroke is one undo step.
        with self.lock:
            if self.dd_tool.value != "Paint brush":
                return
            st = self.state
            eye = np.asarray(event.client.camera.position, np.float64)
            hit = self._hit(eye, np.asarray(event.end_position) - eye)
            r = int(self.sl_paint.value)
            if hit is not None:
                st.paint(hit[1], self._radius(), r, record=not self._stroke_open)
                self._stroke_open = True
                self._stroke.update(st.vertices_near(hit[1], self._radius()).tolist())
            if event.phase == "end":
                self._stroke_open = False
                self._stroke.clear()
                self._after_edit()
            elif time.perf_counter() - self._last_stroke_draw > 0.1 and self._stroke:
                self._draw_stroke(r)

    def _draw_stroke(self, r: int) -> None:
        """Show the stroke so far as dots in the colour of r.

        Rebuilding the coloured meshes mid-stroke would remove the node being dragged,
        which ends the drag; they are rebuilt once, when the stroke ends.
        """
        idx = np.fromiter(self._stroke, dtype=np.int64)
        self._markers["stroke"] = self.server.scene.add_point_cloud(
            "/markers/stroke", self.state.vertices[idx].astype(np.float32),
            np.array(RING_COLORS[ring_labels(np.array([r]))[0]], np.uint8),
            point_size=0.8 * self._edge_len, point_shape="circle", precision="float32",
        )
        self._last_stroke_draw = time.perf_counter()

    # ---------------------------------------------------------------- files
    def _guard_uploads(self) -> None:
        """Enforce the upload cap while the parts arrive, not after the whole file did.

        viser buffers every part of an upload and calls ``on_upload`` only at the end, with
        no public hook before that. Its websocket layer runs every registered handler for a
        message in order, after its own, so these handlers see each transfer start and each
        part right after viser buffered it: a transfer that declares more than the cap is
        dropped at its start message, and one that sends more than it declared (or than
        the cap) is dropped at the part that crosses it. Dropping means removing viser's
        buffer entry; viser then ignores the transfer's later parts. What remains: one
        websocket message (viser caps them at 50 MiB) is read into memory before any
        handler sees it. (Uses viser internals: ``scene._websock_interface`` and the GUI's
        ``_current_file_upload_states``.)
        """
        from viser import _messages

        ws = getattr(self.server.scene, "_websock_interface", None)
        states = getattr(self.server.gui, "_current_file_upload_states", None)
        if ws is None or states is None:  # another viser: the cap after upload still holds
            return
        self._upload_states = states
        ws.register_handler(_messages.FileTransferStartUpload, self._on_upload_start)
        ws.register_handler(_messages.FileTransferPart, self._on_upload_part)

    def _drop_upload(self, client_id: Any, transfer: str, name: Any, size: float) -> None:
        self._upload_states.pop(transfer, None)
        self.rejected_uploads.append(str(name))
        client = self.server.get_clients().get(client_id)
        msg = (f"{_printable(name)}: {_size(size)} is over the {_size(self.max_upload_bytes)} "
               "upload limit (start the editor with a larger --max-upload-mb)")
        self._notify(type("Event", (), {"client": client})(), "Upload refused", msg, error=True)

    def _on_upload_start(self, client_id: Any, message: Any) -> None:
        if message.transfer_uuid in self._upload_states:
            size = message.size_bytes
            if not isinstance(size, int) or size > self.max_upload_bytes or size < 0:
                self._drop_upload(client_id, message.transfer_uuid, message.filename,
                                  size if isinstance(size, (int, float)) else float("nan"))

    def _on_upload_part(self, client_id: Any, message: Any) -> None:
        state = self._upload_states.get(message.transfer_uuid)
        if state is None:
            return
        got = state["transferred_bytes"]
        if got > self.max_upload_bytes or got > state["total_bytes"]:
            self._drop_upload(client_id, message.transfer_uuid, state["filename"], got)

    def _check_upload(self, name: str, data: bytes, what: str) -> None:
        if not isinstance(name, str) or any(ord(c) < 32 for c in name) or len(name) > 255:
            raise InputError(f"{_printable(name)}: not a usable file name for {what} "
                             "(control characters or too long)")
        if len(data) > self.max_upload_bytes:
            raise InputError(
                f"{name}: {_size(len(data))} is over the {_size(self.max_upload_bytes)} "
                f"limit for {what} (start the editor with a larger --max-upload-mb)"
            )
        if not data:
            raise InputError(f"{name}: the file is empty")

    @staticmethod
    def _suffix(name: str) -> str:
        low = name.lower()
        if low.endswith(".gz"):
            return Path(low[:-3]).suffix + ".gz"
        return Path(low).suffix

    def _via_tempfile(self, name: str, data: bytes, reader: Callable[[Path], Any]) -> Any:
        """Run a library reader on uploaded bytes; messages name the upload, not the temp."""
        with tempfile.TemporaryDirectory(prefix="arapkit-upload-") as tmp:
            path = Path(tmp) / ("upload" + self._suffix(name))
            path.write_bytes(data)
            try:
                return reader(path)
            except InputError as exc:
                raise InputError(str(exc).replace(str(path), name)) from None
            except Exception as exc:  # a parser choking on garbage: still the file's fault
                raise InputError(f"{name}: cannot read ({type(exc).__name__}: {exc})") from None

    def open_mesh_bytes(self, name: str, data: bytes) -> None:
        """Replace the mesh by an uploaded file (``name`` only picks the format)."""
        from arapkit import load_mesh

        self._check_upload(name, data, "meshes")
        if not is_readable_mesh(name):
            raise InputError(f"{name}: not a mesh file (use {readable_formats(' or ')})")
        mesh = self._via_tempfile(name, data, load_mesh)
        mesh.name = safe_stem(name)
        with self.lock:
            self.state = EditorState(mesh)
            self._install_mesh()

    def load_rings_bytes(self, name: str, data: bytes) -> np.ndarray:
        """Use an uploaded rigidity map (text, .npy or PLY with ``rings``); undoable."""
        from arapkit.io import load_rings

        self._check_upload(name, data, "rings files")
        with self.lock:
            n = self.state.n
            rings = self._via_tempfile(name, data, lambda p: load_rings(p, n))
            self.state.load_rings(rings)
            self._after_edit()
            return rings

    def load_session_bytes(self, name: str, data: bytes) -> None:
        """Apply an uploaded session to the loaded mesh (never opens a path it names)."""
        self._check_upload(name, data, "sessions")
        d = validate.parse_json(data, name)
        if not isinstance(d, dict):
            raise InputError(f"{name}: a session must be a JSON object")
        with self.lock:
            try:
                self.state.apply_dict(d)
            except InputError as exc:
                raise InputError(
                    f"{name}: {exc}. A session for another mesh is opened with "
                    "`arapkit edit --session FILE`") from None
            self._after_edit()

    def _upload_mesh(self, event: Any) -> None:
        f = self.up_mesh.value
        self.open_mesh_bytes(f.name, f.content)
        self._notify(event, "Mesh loaded", self._mesh_info().replace("**", ""))

    def _upload_rings(self, event: Any) -> None:
        f = self.up_rings.value
        rings = self.load_rings_bytes(f.name, f.content)
        self._notify(event, "Rings loaded", f"{f.name}: r from {rings.min()} to {rings.max()}")

    def _upload_session(self, event: Any) -> None:
        f = self.up_session.value
        self.load_session_bytes(f.name, f.content)
        self._notify(event, "Session loaded", f"{f.name}: {len(self.state.handles)} handles")

    def _ensure_export_dir(self) -> Path:
        try:
            self.export_dir.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            msg = f"{self.export_dir}: cannot create the export folder ({exc})"
            raise InputError(msg) from None
        return self.export_dir

    def save_session(self) -> Path:
        """Write ``<mesh>-session.json`` into the export folder and return its path.

        A mesh that came from an upload has no file of its own, so its rest shape is
        saved next to the session first and the session names that file.
        """
        from arapkit.io import save_mesh

        with self.lock:
            out = self._ensure_export_dir()
            st = self.state
            stem = safe_stem(st.mesh.name)
            if st.mesh_path is None:
                rest = out / f"{stem}-rest.ply"
                save_mesh(rest, st.mesh.vertices, like=st.mesh)
                st.mesh_path = str(rest)
            return st.save_session(out / f"{stem}-session.json")

    def export(self) -> list[Path]:
        """Write the deformed mesh (PLY with r and energy per vertex) and the rings file.

        Everything the mesh's file carried comes along (``save_mesh(like=...)``); a mesh
        loaded from OBJ is also exported as OBJ, which keeps its UVs and materials.
        """
        from arapkit.io import save_mesh, save_rings

        with self.lock:
            out = self._ensure_export_dir()
            st = self.state
            stem = safe_stem(st.mesh.name)
            props: dict[str, np.ndarray] = {"rings": st.rings}
            if self._vertex_energy is not None:
                props["energy"] = self._vertex_energy
            mesh_path, rings_path = out / f"{stem}-deformed.ply", out / f"{stem}-rings.txt"
            save_mesh(mesh_path, st.vertices, vertex_properties=props, like=st.mesh)
            welded = getattr(st.mesh, "welded_from", None)
            source = welded.source if welded is not None else st.mesh
            # r per input vertex, like every file arapkit writes for a welded mesh
            rings = st.rings if welded is None else st.rings[welded.index]
            save_rings(rings_path, rings)
            paths = [mesh_path, rings_path]
            attrs = getattr(source, "attributes", None)
            if attrs is not None and attrs.source_format == "obj":
                obj_path = out / f"{stem}-deformed.obj"
                save_mesh(obj_path, st.vertices, like=st.mesh)
                paths.append(obj_path)
            return paths

    def _save_session(self, event: Any) -> None:
        path = self.save_session()
        self._notify(event, "Session saved", str(path))

    def _export(self, event: Any) -> None:
        paths = self.export()
        self._notify(event, "Exported", "  \n".join(str(p) for p in paths))
