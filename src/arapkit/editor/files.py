"""The editor's files: uploads from the page (meshes, rings, sessions) and exports.

:class:`FileActions` is the part of :class:`arapkit.editor.app.EditorApp` that reads what
the page uploads and writes what it exports.  An upload never names a path on the server:
its bytes go through the library's readers in a private temporary file, its name only
picks the format, and the size cap holds while the parts arrive.  Exports and sessions go
to the folder chosen at start-up, under names made by :func:`safe_stem`.
"""

from __future__ import annotations

import re
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from arapkit import validate
from arapkit.editor.state import EditorState
from arapkit.errors import InputError
from arapkit.io.clouds import CLOUD_READ_FORMATS, is_cloud_file, shape_formats_text
from arapkit.io.formats import READ_FORMATS, is_readable_mesh

__all__ = ["MESH_SUFFIXES", "FileActions", "human_size", "printable", "safe_stem",
           "upload_suffix"]

#: what "Open mesh" takes: meshes and point clouds (the XYZ family and .npy)
MESH_SUFFIXES = tuple(dict.fromkeys("." + f for f in (*READ_FORMATS, *CLOUD_READ_FORMATS)))


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


def printable(name: Any) -> str:
    r"""A file name safe to show in a one-line message (control characters escaped).

    Examples
    --------
    >>> print(printable("a\nb.ply"))
    a\nb.ply
    """
    text = repr(str(name))[1:-1]
    return text if len(text) <= 80 else text[:77] + "..."


def human_size(n_bytes: float) -> str:
    """Human-readable size.

    Examples
    --------
    >>> human_size(1536), human_size(100)
    ('1.5 KB', '100 bytes')
    """
    for unit in ("bytes", "KB", "MB"):
        if n_bytes < 1024 or unit == "MB":
            return f"{n_bytes:.0f} {unit}" if unit == "bytes" else f"{n_bytes:.1f} {unit}"
        n_bytes /= 1024
    return f"{n_bytes:.1f} MB"




def upload_suffix(name: str) -> str:
    """The format suffix of an uploaded file's name, ``.gz`` kept with the one before it.

    Examples
    --------
    >>> upload_suffix("Bunny.PLY.gz"), upload_suffix("a.off")
    ('.ply.gz', '.off')
    """
    low = name.lower()
    if low.endswith(".gz"):
        return Path(low[:-3]).suffix + ".gz"
    return Path(low).suffix


class FileActions:
    """Uploads and exports; a part of :class:`arapkit.editor.app.EditorApp`.

    Uses the app's ``server``, ``state``, ``lock``, ``export_dir``, ``max_upload_bytes``,
    ``rejected_uploads``, ``vertex_energy``, the upload widgets and its methods
    ``install_mesh``, ``mesh_info``, ``after_edit``, ``notify`` and ``ui``.
    """

    server: Any
    state: EditorState
    lock: Any
    export_dir: Path
    max_upload_bytes: int
    rejected_uploads: list[str]
    vertex_energy: np.ndarray | None
    up_mesh: Any
    up_rings: Any
    up_groups: Any
    up_session: Any
    bt_save: Any
    bt_export: Any
    install_mesh: Callable[[], None]
    mesh_info: Callable[[], str]
    after_edit: Callable[..., int | None]
    notify: Callable[..., None]
    ui: Callable[[Callable[[Any], None]], Callable[[Any], None]]

    def bind_files(self) -> None:
        """Bind the upload and export widgets, and guard uploads while they arrive."""
        ui = self.ui
        self.up_rings.on_upload(ui(self._upload_rings))
        self.up_groups.on_upload(ui(self._upload_groups))
        self.bt_save.on_click(ui(self._save_session))
        self.up_session.on_upload(ui(self._upload_session))
        self.bt_export.on_click(ui(self._export))
        self.up_mesh.on_upload(ui(self._upload_mesh))
        self._upload_states: dict[str, Any] = {}
        self._guard_uploads()

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
        cap = human_size(self.max_upload_bytes)
        msg = (f"{printable(name)}: {human_size(size)} is over the {cap} "
               "upload limit (start the editor with a larger --max-upload-mb)")
        self.notify(type("Event", (), {"client": client})(), "Upload refused", msg, error=True)

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
            raise InputError(f"{printable(name)}: not a usable file name for {what} "
                             "(control characters or too long)")
        if len(data) > self.max_upload_bytes:
            cap = human_size(self.max_upload_bytes)
            raise InputError(
                f"{name}: {human_size(len(data))} is over the {cap} "
                f"limit for {what} (start the editor with a larger --max-upload-mb)"
            )
        if not data:
            raise InputError(f"{name}: the file is empty")

    def _via_tempfile(self, name: str, data: bytes, reader: Callable[[Path], Any]) -> Any:
        """Run a library reader on uploaded bytes; messages name the upload, not the temp."""
        with tempfile.TemporaryDirectory(prefix="arapkit-upload-") as tmp:
            path = Path(tmp) / ("upload" + upload_suffix(name))
            path.write_bytes(data)
            try:
                return reader(path)
            except InputError as exc:
                raise InputError(str(exc).replace(str(path), name)) from None
            except Exception as exc:  # a parser choking on garbage: still the file's fault
                raise InputError(f"{name}: cannot read ({type(exc).__name__}: {exc})") from None

    def read_mesh_bytes(self, name: str, data: bytes) -> Any:
        """The mesh or point cloud of an uploaded file (``name`` only picks the format), or
        a one-line refusal; nothing in the editor changes."""
        from arapkit.io import load_shape

        self._check_upload(name, data, "meshes")
        if not (is_readable_mesh(name) or is_cloud_file(name)):
            raise InputError(f"{name}: not a mesh file or point cloud (use "
                             f"{shape_formats_text()})")
        mesh = self._via_tempfile(name, data, load_shape)  # a file without faces: a cloud
        mesh.name = safe_stem(name)
        return mesh

    def replace_mesh(self, mesh: Any) -> None:
        """Start a new session on ``mesh`` (the old one's handles, r and undo are gone)."""
        with self.lock:
            self.state = EditorState(mesh)
            self.install_mesh()

    def open_mesh_bytes(self, name: str, data: bytes) -> None:
        """Replace the mesh by an uploaded file at once (the page asks first, see
        :meth:`has_work`)."""
        self.replace_mesh(self.read_mesh_bytes(name, data))

    def has_work(self) -> bool:
        """Whether opening another mesh would lose something: handles, or edits to undo."""
        st = self.state
        return bool(st.handles) or st.can_undo or bool((st.rings != 1).any())

    def load_rings_bytes(self, name: str, data: bytes) -> np.ndarray:
        """Use an uploaded rigidity map (text, .npy or PLY with ``rings``); undoable."""
        from arapkit.io import load_rings

        self._check_upload(name, data, "rings files")
        with self.lock:
            n = self.state.n
            rings = self._via_tempfile(name, data, lambda p: load_rings(p, n))
            self.state.load_rings(rings)
            self.after_edit()
            return rings

    def load_groups_bytes(self, name: str, data: bytes) -> Any:
        """Use an uploaded groups file (JSON, an id file or a PLY with ``part``/``group``)
        as the painted groups; undoable. Returns the groups read."""
        from arapkit.io import load_groups

        self._check_upload(name, data, "groups files")
        with self.lock:
            mesh = self.state.mesh
            welded = getattr(mesh, "welded_from", None)
            source = mesh if welded is None else welded.source
            groups = self._via_tempfile(
                name, data, lambda p: load_groups(p, source.vertices,
                                                  welded=None if welded is None else mesh))
            self.state.load_groups(groups)
            self.after_edit()
            return groups

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
            self.after_edit()

    def _upload_mesh(self, event: Any) -> None:
        f = self.up_mesh.value
        mesh = self.read_mesh_bytes(f.name, f.content)  # a bad file changes nothing
        client = getattr(event, "client", None)
        if client is None or not self.has_work():
            self.replace_mesh(mesh)
            self.notify(event, "Mesh loaded", self.mesh_info().replace("**", ""))
            return
        self._confirm_open(event, client, f.name, mesh)

    def _confirm_open(self, event: Any, client: Any, name: str, mesh: Any) -> None:
        """Ask before a new mesh replaces this one's handles, r and deformation (no undo
        crosses meshes, as in Blender or Photoshop opening a file)."""
        st = self.state
        what = [f"{len(st.handles)} handle(s)" if st.handles else "",
                "its r" if (st.rings != 1).any() else "",
                "its deformation and undo history" if st.can_undo else ""]
        lost = ", ".join(w for w in what if w)
        shown, current = printable(name), printable(st.mesh.name)
        modal = client.gui.add_modal(f"Open {shown}?")
        with modal:
            client.gui.add_markdown(
                f"This replaces **{current}** with {lost}. Undo cannot bring them back: "
                "*Save session* first to keep them.")
            b_open = client.gui.add_button(f"Open {shown}", color="red")
            b_keep = client.gui.add_button(f"Keep {current}")

        def open_it(_: Any) -> None:
            modal.close()
            self.replace_mesh(mesh)
            self.notify(event, "Mesh loaded", self.mesh_info().replace("**", ""))

        def keep(_: Any) -> None:
            modal.close()
            self.notify(event, "Not opened", f"{shown}: kept {current} as it was")

        b_open.on_click(self.ui(open_it))
        b_keep.on_click(self.ui(keep))

    def _upload_rings(self, event: Any) -> None:
        f = self.up_rings.value
        rings = self.load_rings_bytes(f.name, f.content)
        self.notify(event, "Rings loaded", f"{f.name}: r from {rings.min()} to {rings.max()}")

    def _upload_groups(self, event: Any) -> None:
        f = self.up_groups.value
        groups = self.load_groups_bytes(f.name, f.content)
        cloud = self.state.mesh.faces is None
        self.notify(event, "Groups loaded", f"{f.name}: {groups.summary(points=cloud)}")

    def _upload_session(self, event: Any) -> None:
        f = self.up_session.value
        self.load_session_bytes(f.name, f.content)
        self.notify(event, "Session loaded", f"{f.name}: {len(self.state.handles)} handles")

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
        """Write the deformed mesh (PLY with r and energy per vertex), the rings file and,
        when groups are painted, the groups file (``--groups`` reads it back).

        Everything the mesh's file carried comes along (``save_mesh(like=...)``); a mesh
        loaded from OBJ is also exported as OBJ, which keeps its UVs and materials.
        """
        from arapkit.io import save_mesh, save_rings

        with self.lock:
            out = self._ensure_export_dir()
            st = self.state
            stem = safe_stem(st.mesh.name)
            props: dict[str, np.ndarray] = {"rings": st.rings}
            if self.vertex_energy is not None:
                props["energy"] = self.vertex_energy
            mesh_path, rings_path = out / f"{stem}-deformed.ply", out / f"{stem}-rings.txt"
            save_mesh(mesh_path, st.vertices, vertex_properties=props, like=st.mesh)
            welded = getattr(st.mesh, "welded_from", None)
            source = welded.source if welded is not None else st.mesh
            # r per input vertex, like every file arapkit writes for a welded mesh
            rings = st.rings if welded is None else st.rings[welded.index]
            save_rings(rings_path, rings)
            paths = [mesh_path, rings_path]
            groups = st.groups.vertex_groups()
            if groups is not None:  # the painted parts, as a groups file of the input
                from arapkit.io import save_groups
                from arapkit.mesh.groups import VertexGroups

                if welded is not None:
                    groups = VertexGroups(groups.ids[welded.index], groups.names,
                                          groups.rigid, groups.source)
                paths.append(out / f"{stem}-groups.json")
                save_groups(paths[-1], groups)
            attrs = getattr(source, "attributes", None)
            if attrs is not None and attrs.source_format == "obj":
                obj_path = out / f"{stem}-deformed.obj"
                save_mesh(obj_path, st.vertices, like=st.mesh)
                paths.append(obj_path)
            return paths

    def _save_session(self, event: Any) -> None:
        path = self.save_session()
        self.notify(event, "Session saved", str(path))

    def _export(self, event: Any) -> None:
        paths = self.export()
        self.notify(event, "Exported", "  \n".join(str(p) for p in paths))
