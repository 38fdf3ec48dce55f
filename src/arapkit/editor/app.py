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
import signal
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import viser

from arapkit import validate
from arapkit.editor.files import MESH_SUFFIXES, FileActions, safe_stem
from arapkit.editor.geometry import UP_AXES, framing_distance, pick_point, raycast
from arapkit.editor.groups import GROUP_COLORS, groups_legend_html
from arapkit.editor.panels import (
    HANDLE_COLOURS,
    MAX_R,
    VIEWS,
    Panels,
    next_step,
    selected_text,
)
from arapkit.editor.points import SPLAT_SIZE, CloudNode, cloud_colors, splat_colors
from arapkit.editor.state import EditorState
from arapkit.editor.tools import TOOLS, PointerTools
from arapkit.editor.views import (
    RING_COLORS,
    SHADED_COLOR,
    energy_colors,
    energy_floor,
    energy_labels,
    energy_legend_html,
    energy_scale,
    face_groups,
    ring_labels,
    rings_legend_html,
)
from arapkit.editor.worker import SolveRequest, SolveUpdate, SolveWorker
from arapkit.errors import InputError
from arapkit.mesh.cloud import element_nouns
from arapkit.mesh.selection import connected_region

# the names this module held before its parts moved out (MESH_SUFFIXES, safe_stem: files;
# UP_AXES: geometry; MAX_R, VIEWS: panels; TOOLS: tools)
__all__ = ["MAX_R", "MESH_SUFFIXES", "TOOLS", "UP_AXES", "VIEWS", "EditorApp", "safe_stem"]

#: how much of the view the model fills when a mesh is opened
FRAME_FILL = 0.65
#: a gizmo's size in radii of its handle (see EditorApp.gizmo_scale)
GIZMO_PER_RADIUS = 6.0
#: a gizmo's size within these fractions of the mesh's bounding-box diagonal: framed at
#: FRAME_FILL left of the panel, a tall model (the cactus, seen from a little above) has
#: about 0.13 of its diagonal to spare above its top, so an arrow from a handle there stays
#: in view (at 0.3 it left the view, or reached under the panel)
GIZMO_MIN, GIZMO_MAX = 0.05, 0.12
#: the share of the page's width that the panel covers (320 px of a 1200 px window): the
#: camera aims so that the model is centred in the rest
PANEL_SHARE = 0.28
#: a dot's diameter in local edge lengths (the median length of the edges at the dotted
#: vertices): neighbouring dots then never overlap, on a coarse mesh as on a fine one
DOT_PER_EDGE = 0.45
SELECT_RGB = (230, 30, 200)


def load_pointer_kernels() -> None:
    """Compile, or load from numba's cache, the kernels of a click (picking), the paint
    bucket and the r view, so that the first of each does not wait for them (0.6–0.9 s
    each on a fresh install, 0.2 s from the cache). The editor runs this in the background
    at start; their inputs are read-only arrays (``kernel_input``), one compiled type.

    Examples
    --------
    >>> load_pointer_kernels()
    """
    V = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    F = np.array([[0, 1, 2]])
    raycast(V, F, np.array([0.2, 0.2, 1.0]), np.array([0.0, 0.0, -1.0]))
    pick_point(V, np.array([0.2, 0.2, 1.0]), np.array([0.0, 0.0, -1.0]), 0.1)
    face_groups(F, np.zeros(3, dtype=np.int64), 1)
    connected_region(F, np.ones(3, dtype=bool), 0)
    connected_region(F[:, :2], np.ones(3, dtype=bool), 0)  # a point cloud's edges


def _vertex_spacing(mesh: Any) -> np.ndarray:
    """Each vertex's mean incident edge length (the mean edge length where it has none)."""
    E = np.asarray(mesh.edges)
    V = np.asarray(mesh.vertices, dtype=np.float64)
    n = len(V)
    length = np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1)
    total = np.bincount(E.ravel(), np.repeat(length, 2), n)
    count = np.bincount(E.ravel(), minlength=n)
    fallback = float(length.mean()) if len(length) else 1.0
    return np.where(count > 0, total / np.maximum(count, 1), fallback)


def _raise_keyboard_interrupt(signum: int, frame: Any) -> None:
    raise KeyboardInterrupt


class EditorApp(Panels, PointerTools, FileActions):
    """A running editor: viser server, GUI, scene and solver thread.

    Its parts live beside it: the side panel (:class:`~arapkit.editor.panels.Panels`),
    the pointer tools (:class:`~arapkit.editor.tools.PointerTools`) and uploads / exports
    (:class:`~arapkit.editor.files.FileActions`); this class holds the lifecycle, the
    scene (mesh, colours, markers, gizmos) and the plumbing to the solver thread.

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
        #: per-vertex energy of the last solve that had one (the energy view, exports)
        self.vertex_energy: np.ndarray | None = None
        #: the scale of the loaded mesh (bounding-box diagonal) and its mean edge length
        self.diag, self.edge_length = 1.0, 1.0
        #: a colour view's nodes, each with the mesh vertices it draws (an index array)
        self._groups: list[tuple[np.ndarray, Any]] = []
        self._gizmos: list[Any] = []
        self._gizmo_serial = 0
        self._markers: dict[str, Any] = {}
        #: the mesh's box centre: the mesh and its dots are sent relative to it, under
        #: frames placed there (float32 keeps 0.5 m at 5e6: a georeferenced scan drawn in
        #: world coordinates would show in steps; the browser composes the frame's float64
        #: offset with the camera's before its float32 upload, so nothing is lost)
        self._origin = np.zeros(3)
        self._frames: list[Any] = []
        #: the shaded mesh; None in a colour view (viser keeps three copies of a node's
        #: vertices and two of its faces, 0.15 GiB at 1.75M vertices, hidden or not)
        self.mesh_node: Any = None
        #: a large mesh's proxy, shown instead of the mesh while a drag is previewed
        self.proxy_node: Any = None
        self._proxy_of: Any = None
        #: called as hook(update, perf_counter_when_sent) after each shape is handed to viser
        self.sent_hooks: list[Callable[[SolveUpdate, float], None]] = []
        #: a note about the last edit, kept in the status line until the next edit
        self.edit_note = ""
        self.vertex_spacing = np.ones(0)
        #: names of uploads dropped while arriving because they were over the cap
        self.rejected_uploads: list[str] = []
        self.build_panels()
        self.bind_files()
        self.bind_tools()
        self.worker.start()
        self.install_mesh()
        threading.Thread(target=load_pointer_kernels, name="arapkit-pointer-kernels",
                         daemon=True).start()

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
        """The vertex positions last sent to the page: the shaded mesh node's, or in a
        colour view its groups' (a vertex in no face, drawn by none, is given where the
        state has it)."""
        if self.mesh_node is not None:
            return np.asarray(self.mesh_node.vertices, dtype=np.float64) + self._origin
        out = np.array(self.state.vertices, dtype=np.float64)
        for idx, node in self._groups:
            out[idx] = np.asarray(node.vertices, dtype=np.float64) + self._origin
        return out

    def local32(self, V: np.ndarray) -> np.ndarray:
        """World positions as the scene holds them: float32, relative to the mesh's centre."""
        return (np.asarray(V, dtype=np.float64) - self._origin).astype(np.float32)

    def _place_frames(self, origin: np.ndarray) -> None:
        """Put the frames that hold the mesh and its dots at ``origin`` (world)."""
        self._origin = np.asarray(origin, dtype=np.float64)
        if not self._frames:
            self._frames = [self.server.scene.add_frame(name, show_axes=False)
                            for name in ("/mesh", "/markers")]
        for frame in self._frames:
            frame.position = tuple(self._origin)

    # ================================================================ scene set-up
    def install_mesh(self) -> None:
        """(Re)create every scene node for ``self.state`` (start-up, new mesh, session)."""
        with self.lock:
            st = self.state
            self.worker.expect(st.mesh, st.settings)
            V = st.vertices
            lo, hi = V.min(axis=0), V.max(axis=0)
            self.diag = st.mesh.bounding_box_diagonal or 1.0
            self.edge_length = st.mesh.mean_edge_length
            self.vertex_spacing = _vertex_spacing(st.mesh)
            self.worker.reset_shape(V, st.mesh)
            self.vertex_energy = None
            self.last_update = None
            self._place_frames((lo + hi) / 2)
            if self.mesh_node is not None:
                self.mesh_node.remove()
            if self.proxy_node is not None:
                self.proxy_node.remove()
            # a large mesh's preview draws this node (hidden until then; its faces are set
            # when the proxy is known); a point cloud's preview is splats
            if st.mesh.faces is None:
                self.proxy_node = CloudNode(self.server.scene, "/mesh/preview",
                                            self.local32(V[:3]), SHADED_COLOR,
                                            SPLAT_SIZE * self.edge_length, visible=False)
            else:
                self.proxy_node = self.server.scene.add_mesh_simple(
                    "/mesh/preview", self.local32(V[:3]), np.array([[0, 1, 2]], np.uint32),
                    color=SHADED_COLOR, side="double", visible=False)
            self._proxy_of = None
            self.mesh_node = None  # made by rebuild_display (below), in the shaded view only
            self.quietly(self._choose_up)
            self.aim_cameras()
            self.active = st.handles[-1].name if st.handles else None
            self.quietly(self.sync_gui_from_state)
            self.redraw()
            self.md_mesh.content = self.mesh_info()
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

    def aim_cameras(self) -> None:
        """Look at the mesh from the front, slightly above, for the chosen up axis."""
        from arapkit.mesh.orientation import view_frame

        up_name = self.dd_up.value
        up = np.array(UP_AXES[up_name], dtype=np.float64)
        # the figures' front: along the thinner horizontal axis (row 2 points at the viewer)
        front = view_frame(self.state.vertices, "front", up_name)[0][2]
        front = front - (front @ up) * up
        front /= np.linalg.norm(front)
        centre = self._origin
        toward_eye = 0.9 * front + 0.55 * up + 0.15 * np.cross(up, front)
        toward_eye /= np.linalg.norm(toward_eye)
        # the scene left of the GUI panel is about 840 x 800 pixels in a 1200 x 800 window
        dist = framing_distance(self.state.vertices, centre, toward_eye, up,
                                self.server.initial_camera.fov, 1.05, FRAME_FILL)
        eye = centre + dist * toward_eye
        # Aim right of the centre by the panel's share of the view, so that the model is
        # centred in the part of the page the panel leaves (its gizmos then fit there too)
        right = np.cross(centre - eye, up)
        half_width = dist * np.tan(self.server.initial_camera.fov / 2) * 1.5  # radians
        shift = PANEL_SHARE * half_width * right / np.linalg.norm(right)
        centre, eye = centre + shift, eye + shift
        self.server.scene.set_up_direction(up_name)
        self.server.initial_camera.position = tuple(eye)
        self.server.initial_camera.look_at = tuple(centre)
        for client in self.server.get_clients().values():
            # position before look-at: moving the camera drags its look-at point along.
            client.camera.up_direction = tuple(up)
            client.camera.position = tuple(eye)
            client.camera.look_at = tuple(centre)
        self.show_settings()

    def mesh_info(self) -> str:
        """The panel's line about the loaded mesh (name, size, loader notes)."""
        m = self.state.mesh
        notes = "; ".join(getattr(m, "notes", [])[:3])
        cloud = m.faces is None
        size = f"a point cloud ({m.graph_description})" if cloud else f"{m.n_faces:,} faces"
        return (f"**{m.name}**: {m.n_vertices:,} {element_nouns(cloud)[1]}, {size}"
                + (f"  \n_{notes}_" if notes else ""))

    def redraw(self) -> None:
        """Everything that depends on handles/rings/view, not just on vertex positions."""
        self.rebuild_display()
        self.draw_markers()
        self._sync_gizmos()
        self.sync_history()

    # ---------------------------------------------------------------- mesh display
    def rebuild_display(self) -> None:
        """Show the mesh in the chosen view: shaded, or split into one node per colour.

        The view not shown has no node: a hidden node costs viser's copies all the same.
        """
        for _, node in self._groups:
            node.remove()
        self._groups = []
        st = self.state
        V32 = self.local32(st.vertices)
        view = self.dd_view.value
        labels, colors, legend = None, (), ""
        if view == "Rigidity r":
            labels, colors, legend = ring_labels(st.rings), RING_COLORS, rings_legend_html()
        elif view == "Groups":
            labels, colors = st.groups.colour_labels(), (SHADED_COLOR, *GROUP_COLORS)
            legend = groups_legend_html(st.groups)
        elif view == "Energy":
            if self.vertex_energy is None:
                legend = "<i>energy appears after an r-ring ARAP solve</i>"
            else:
                # Round-off energies (an undeformed mesh) all get the lowest colour.
                unit = self.last_update.energy_unit if self.last_update else float("nan")
                floor = energy_floor(unit)
                vmax = energy_scale(self.vertex_energy, floor)
                colors = tuple(energy_colors())
                labels = energy_labels(self.vertex_energy, vmax, len(colors))
                legend = energy_legend_html(vmax, len(colors), floor,
                                            float(np.nanmax(self.vertex_energy, initial=0.0)))
        if st.mesh.faces is None:  # a point cloud: one node of splats in every view
            self._show_cloud(V32, labels, colors)
        elif labels is None:
            if self.mesh_node is None:
                self.mesh_node = self.server.scene.add_mesh_simple(
                    "/mesh/shaded", V32, np.asarray(st.mesh.faces, np.uint32),
                    color=SHADED_COLOR, side="double")
            else:
                self.mesh_node.vertices = V32
                self.mesh_node.visible = True
        else:
            if self.mesh_node is not None:
                self.mesh_node.remove()
                self.mesh_node = None
            for g in face_groups(st.mesh.faces, labels, len(colors)):
                node = self.server.scene.add_mesh_simple(
                    f"/mesh/group{g.label}", V32[g.vertices], g.faces,
                    color=colors[g.label], side="double",
                )
                # the group's faces are not kept: the node has them (0.05 GiB at 1.75M)
                self._groups.append((g.vertices, node))
        self.html_legend.content = legend
        self.bind_brush()

    def _show_cloud(self, V32: np.ndarray, labels: np.ndarray | None, colors: Any) -> None:
        """Draw a point cloud: the file's colours (or one colour), or the view's."""
        rgb = (cloud_colors(self.state.mesh, SHADED_COLOR) if labels is None
               else splat_colors(labels, colors))
        if self.mesh_node is None:
            self.mesh_node = CloudNode(self.server.scene, "/mesh/points", V32, rgb,
                                       SPLAT_SIZE * self.edge_length)
        else:
            self.mesh_node.vertices = V32
            self.mesh_node.colors = rgb
            self.mesh_node.visible = True

    def _refresh_vertices(self, V: np.ndarray) -> None:
        """Send new positions only (a drag): the colour split stays as it is."""
        V32 = self.local32(V)
        if self.mesh_node is not None:
            self.mesh_node.vertices = V32
        # a colour view's groups only: the shaded node is made again, with the shape of
        # then, when the view is left
        for idx, node in self._groups:
            node.vertices = V32[idx]
        self._refresh_markers(V32)

    def _refresh_markers(self, V32: np.ndarray) -> None:
        """Move the handle and selection dots to ``V32`` (float32 positions)."""
        for key, idx in (("handles", self.state.handle_indices()),
                         ("selection", self.state.selection)):
            node = self._markers.get(key)
            if node is not None and len(idx):
                node.points = V32[idx]

    def _show_proxy(self, proxy_mesh: Any, P: np.ndarray) -> None:
        """Draw a large mesh's preview as its proxy (0.24 MB a frame, not 5-21 MB).

        The full mesh is hidden meanwhile and sent once, when the exact shape arrives.
        """
        P32 = self.local32(P)
        node = self.proxy_node
        node.vertices = P32
        if self._proxy_of is not proxy_mesh:
            if proxy_mesh.faces is not None:  # a point cloud's proxy has its points only
                node.faces = np.asarray(proxy_mesh.faces, np.uint32)
            self._proxy_of = proxy_mesh
        node.visible = True
        # the dots too: moving them would send 10^4-10^5 points a frame on a scan (more
        # than the proxy), and left in place they mark where the handle no longer is
        for hidden in self.mesh_nodes() + list(self._markers.values()):
            hidden.visible = False

    def _hide_proxy(self) -> None:
        if self.proxy_node is None or not self.proxy_node.visible:
            return
        self.proxy_node.visible = False
        for node in list(self._markers.values()) + self.mesh_nodes():
            node.visible = True

    def mesh_nodes(self) -> list[Any]:
        """The scene nodes that show the mesh: the shaded one, or one per colour of a view."""
        shown = [self.mesh_node] if self.mesh_node is not None else []  # none before start-up
        return shown + [n for _, n in self._groups]

    def show_points(self, key: str, idx: np.ndarray, colors: Any, size: float) -> None:
        """Show the vertices ``idx`` as round dots, as the marker layer ``key``."""
        self._markers[key] = self.server.scene.add_point_cloud(
            f"/markers/{key}", self.local32(self.state.vertices[idx]),
            np.asarray(colors, np.uint8), point_size=size, point_shape="circle",
            precision="float32",
        )

    def draw_markers(self) -> None:
        """Redraw the handle and selection dots, and the selection count."""
        st = self.state
        for node in self._markers.values():
            node.remove()
        self._markers = {}
        idx = st.handle_indices()
        if len(idx) and self.cb_show_handles.value:
            cols = np.concatenate([
                np.tile(HANDLE_COLOURS[(bool(h.frozen), h.name == self.active)][0],
                        (len(h.vertices), 1))
                for h in st.handles
            ])
            self.show_points("handles", idx, cols, self.dot_size(idx))
        if len(st.selection):
            self.show_points("selection", st.selection, SELECT_RGB,
                             self.dot_size(st.selection))
        self.md_selection.content = selected_text(len(st.selection), st.mesh)
        # the hint follows the selection at once ("press Make handle ...")
        self.md_hint.content = next_step(st)

    def dot_size(self, idx: np.ndarray) -> float:
        """Diameter of the dots drawn on the vertices ``idx``: a share of their local edge
        length, so that neighbouring dots do not overlap (a coarse mesh's mean edge is
        several times the edge of its finely cut parts)."""
        spacing = self.vertex_spacing[idx]
        return float(DOT_PER_EDGE * np.median(spacing)) if len(spacing) else 0.0

    def _sync_gizmos(self) -> None:
        for g in self._gizmos:
            g.remove()
        self._gizmos = []
        for h in self.state.handles:
            if not h.frozen:
                self._gizmos.append(self._make_gizmo(h.name, h.wxyz, h.position,
                                                     self.gizmo_scale(h)))

    def gizmo_scale(self, handle: Any) -> float:
        """Size of a handle's gizmo: a few times the handle's radius, within mesh bounds.

        The gizmo is drawn over the mesh: its rings then circle a small handle's dots
        instead of hiding them, and a large handle gets a gizmo that reaches past it.
        """
        radius = float(np.linalg.norm(handle.anchor - handle.pivot, axis=1).max())
        return float(np.clip(GIZMO_PER_RADIUS * radius, GIZMO_MIN * self.diag,
                             GIZMO_MAX * self.diag))

    def _make_gizmo(self, name: str, wxyz: np.ndarray, position: np.ndarray,
                    scale: float) -> Any:
        # Fresh node names: a late message for a removed gizmo can never hit a new one.
        self._gizmo_serial += 1
        tc = self.server.scene.add_transform_controls(
            f"/gizmos/g{self._gizmo_serial}", scale=scale, line_width=3.0,
            depth_test=False, wxyz=tuple(wxyz), position=tuple(position),
            # no plane squares: drawn over everything at the centre, they hid the handle
            disable_sliders=True,
        )

        # async: viser then runs start/update/end in order on its event loop.
        async def on_update(event: Any) -> None:
            self.drag_handle(name, tc.wxyz, tc.position, event.phase)

        tc.on_update(on_update)
        return tc

    # ================================================================ solving
    def request_solve(self, live: bool = False) -> int | None:
        """Send the current handles/targets/rings to the solver thread (latest wins).

        ``live``: a drag in progress, for which a large mesh's preview is enough.
        """
        with self.lock:
            st = self.state
            idx, tgt = st.constraints()
            if len(idx) == 0:
                self.status("No handles yet: see **Next** below.")
                return None
            if self._status_ok.startswith("No handles yet"):  # not once a handle is made
                self.status(f"**{st.settings.label}** · solving ...")
            req = SolveRequest(st.mesh, idx, tgt, st.rings, dataclasses.replace(st.settings),
                               live=live, groups=st.groups.vertex_groups())
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
            # The end of a drag repeats the last pose: let the running solve finish, unless
            # it is a large mesh's preview, whose release still needs the exact solve.
            release = phase == "end"
            seq = (None if same and release and not self.worker.previewing
                   else self.request_solve(live=not release))
            if phase != "update":
                if self.active != name:
                    self.active = name
                    self.quietly(self.sync_handle_widgets)
                    self.draw_markers()
                self.sync_history()
            return seq

    def _on_solve_update(self, u: SolveUpdate) -> None:
        """Worker thread: show a new shape (drops results for a mesh no longer loaded)."""
        with self.lock:
            if u.mesh is not self.state.mesh:
                return
            if u.vertices is not None:
                self.state.vertices = np.asarray(u.vertices, dtype=np.float64)
            self.last_update = u
            if u.vertex_energy is not None:
                self.vertex_energy = u.vertex_energy
            if u.proxy_vertices is not None:
                self._show_proxy(u.proxy_mesh, u.proxy_vertices)
            # an update with neither shape is an exact solve's progress: what is shown stays
            elif u.vertices is not None or u.final:
                self._hide_proxy()
                if u.final and self.dd_view.value == "Energy" and u.vertex_energy is not None:
                    self.rebuild_display()
                self._refresh_vertices(self.state.vertices)
            sent = time.perf_counter()
            self._status_from(u)
        for hook in self.sent_hooks:
            hook(u, sent)

    def _status_from(self, u: SolveUpdate) -> None:
        method = self.state.settings.label
        if u.building is not None:
            fraction, seconds, cost = u.building
            r = self.state.rings
            shown = f"r = {int(r.max())}" if r.min() == r.max() else f"r up to {int(r.max())}"
            left = max(0.0, seconds * (1.0 - fraction))
            self.top.progress(fraction, f"Building the r-rings for {shown} ({cost}): "
                              f"**{100 * fraction:.0f} %**, about {left:.0f} s left. "
                              "*Cancel* is under *Global r*.")
            self.bt_cancel_build.visible = fraction < 1.0
            return
        self.top.progress(None)
        self.bt_cancel_build.visible = False
        if u.error:
            self.status(f"**{method}**: {u.error}")
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
        edit = f"  \n{self.edit_note}" if self.edit_note else ""
        self.status(
            f"**{method}** · iterations **{u.iterations}** · energy **{energy}** · {phase}  \n"
            f"{shown}{total}{notes}{edit}"
        )

    def solved_rings(self) -> np.ndarray | None:
        """r per vertex of the deformer being solved (before a build in progress), if any."""
        d = self.worker.deformer
        return None if d is None else np.asarray(d.rings)

    def status(self, text: str) -> None:
        """Set the status line at the top of the panel (what an error line gives way to)."""
        self._status_ok = text
        self.md_status.content = text

