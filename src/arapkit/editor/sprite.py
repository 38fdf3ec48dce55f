"""The editor in 2D: puppet-warp a sprite (or a planar mesh) in the browser.

``arapkit edit sprite.png`` (or a mesh whose z is constant) opens this view instead of the
3D editor: the picture, warped live, seen from above.

* **Pin** tool: a click on the picture puts a pin on the nearest mesh vertex (a pin is
  added to the factor, not refactorised: :mod:`arapkit.arap.pinupdate`); each pin has a
  gizmo: drag it to move the pin, turn its ring to rotate the pin's neighbourhood
  (Photoshop's pin rotation); **Remove last pin** takes one away.
* **Rigidity**: a preset (distort, normal, rigid: :data:`arapkit.methods.planar.PRESETS`)
  for the whole shape, or the **Paint r** tool: a click paints r within the brush radius.
* **Export**: the warped picture (PNG), the warped mesh (OBJ with the rest positions as
  UVs) and the pins (the JSON of ``arapkit warp --pins``), into the export folder.

Scene coordinates are the picture's pixels with y up (``(x, -y, 0)``), so the picture
reads upright from the default camera above it.

Examples
--------
>>> import numpy as np
>>> from arapkit.image.sprite import puppet_sprite
>>> ed = SpriteEditor(puppet_sprite(96), port=8125)  # doctest: +SKIP
>>> ed.add_pin([48.0, 48.0]); ed.move_pin(0, [50.0, 40.0])  # doctest: +SKIP
>>> ed.stop()  # doctest: +SKIP
"""

from __future__ import annotations

import json
import threading
from pathlib import Path

import numpy as np
import viser

from arapkit import validate
from arapkit.errors import InputError
from arapkit.image.meshing import mesh_mask, shape_mask
from arapkit.image.raster import boundary_edges, premultiplied, rasterise
from arapkit.image.warp import read_image, save_image
from arapkit.io.atomic import atomic_open
from arapkit.methods.deformer import Deformer
from arapkit.methods.planar import PRESETS, preset_rings

__all__ = ["TOOLS_2D", "SpriteEditor", "planar_mesh_picture"]

#: the pointer tools of the 2D view
TOOLS_2D = ("Pin", "Paint r")
#: the margin shown around the picture, relative to its longer side
MARGIN = 0.25
#: a pin gizmo's size, relative to the picture's longer side
GIZMO = 0.1
#: local/global iterations a pin move may take before the picture is sent
EDIT_ITERATIONS = 60


def planar_mesh_picture(mesh, size: int = 768) -> tuple[np.ndarray, np.ndarray]:
    """A planar mesh as a picture to warp: a checkerboard on its triangles, and its vertices
    in that picture's pixels (y down).

    Examples
    --------
    >>> from arapkit.mesh.shapes2d import strip
    >>> img, P = planar_mesh_picture(strip(), 200)
    >>> img.shape[1], round(float(P[:, 0].max() - P[:, 0].min()))
    (200, 180)
    """
    V = mesh.vertices[:, :2]
    lo, hi = V.min(axis=0), V.max(axis=0)
    s = 0.9 * size / float(max(hi - lo))
    P = (V - lo) * s
    P[:, 1] = (hi[1] - lo[1]) * s - P[:, 1]  # y down
    P += 0.05 * size
    H = int(np.ceil((hi[1] - lo[1]) * s + 0.1 * size))
    yy, xx = np.mgrid[:H, :size]
    checker = ((xx // 24 + yy // 24) % 2).astype(np.uint8)
    src = np.zeros((H, size, 4), np.uint8)
    src[..., :3] = np.where(checker[..., None], [90, 140, 210], [235, 240, 250])
    src[..., 3] = 255
    cover = rasterise(src, P, P, mesh.faces)
    return cover, P


class SpriteEditor:
    """The 2D editor on a viser server.

    Parameters
    ----------
    source : path, (H, W[, 3|4]) uint8 array, or a planar Mesh
        A picture (meshed from its alpha or its background colour) or a planar mesh.
    spacing : float, optional
        Mesh edge length in pixels for a picture (the density).
    host, port, export_dir :
        As for :class:`arapkit.editor.app.EditorApp`.
    """

    def __init__(self, source, *, spacing: float | None = None, host: str = "127.0.0.1",
                 port: int = 8080, export_dir: str | Path = "arapkit-edits",
                 verbose: bool = False) -> None:
        port = validate.port(port, "port")
        host = validate.host(host, "host")
        from arapkit.mesh.model import Mesh

        if isinstance(source, Mesh):
            # the mesh in the picture's pixels, so that one frame serves both
            self.rgba, rest = planar_mesh_picture(source)
            self.name = source.name
            self.mesh = Mesh(np.c_[rest, np.zeros(len(rest))], source.faces, name=source.name)
            self.rest = rest
        else:
            self.rgba, self.name = read_image(source)
            self.mesh = mesh_mask(shape_mask(self.rgba, name=self.name), spacing,
                                  name=self.name)
            self.rest = self.mesh.vertices[:, :2].copy()
        self.export_dir = Path(export_dir).expanduser().resolve()
        self.lock = threading.RLock()
        self.pins: list[int] = []          # vertex of each pin
        self.targets: list[np.ndarray] = []
        self.angles: list[float] = []      # radians in the picture's frame (NaN: none)
        self.rings = np.full(self.mesh.n_vertices, PRESETS["normal"], dtype=np.int64)
        self.vertices = self.rest.copy()
        self.folds = 0
        self._deformer = None
        self._source = premultiplied(self.rgba)
        self._outline = boundary_edges(self.mesh.faces)
        self.server = viser.ViserServer(host=host, port=port, label="arapkit 2D editor",
                                        verbose=verbose)
        H, W = self.rgba.shape[:2]
        self.size = (W, H)
        #: the view shows a margin around the picture, where warped parts may go
        self.margin = m = int(MARGIN * max(W, H))
        self.server.scene.set_up_direction("+y")
        # viser lays an image's first row at the plane's -y edge: rows are sent bottom up
        self.image_node = self.server.scene.add_image(
            "/picture", self.view()[::-1].copy(), render_width=W + 2 * m,
            render_height=H + 2 * m, format="png", position=(W / 2, -H / 2, 0.0))
        self._gizmos: list = []
        self._build_gui()
        self.server.on_client_connect(self._look_from_above)
        self.server.scene.on_click()(self._on_click)

    # -- the page -------------------------------------------------------------------
    def _build_gui(self) -> None:
        gui = self.server.gui
        gui.add_markdown("**2D puppet warp**: click the picture to pin it, drag or turn a "
                         "pin's gizmo; paint r with the Paint r tool.")
        self.tool = gui.add_dropdown("Tool", TOOLS_2D, initial_value="Pin")
        self.preset = gui.add_dropdown("Rigidity preset", tuple(PRESETS),
                                       initial_value="normal")
        self.paint_r = gui.add_slider("Paint r", min=1, max=8, step=1, initial_value=4)
        self.brush = gui.add_slider("Brush radius (px)", min=2, max=200, step=1,
                                    initial_value=30)
        self.status = gui.add_markdown(self._status())
        remove = gui.add_button("Remove last pin")
        png = gui.add_button("Export PNG")
        obj = gui.add_button("Export mesh")
        pins = gui.add_button("Export pins")
        self.preset.on_update(lambda _: self.set_preset(self.preset.value))
        remove.on_click(lambda _: self.remove_pin())
        png.on_click(lambda _: self.export("png"))
        obj.on_click(lambda _: self.export("obj"))
        pins.on_click(lambda _: self.export("pins"))

    def _status(self) -> str:
        return (f"{self.mesh.n_vertices} vertices, {len(self.pins)} pins, folds: "
                f"{self.folds}")

    def _look_from_above(self, client) -> None:
        W, H = self.size
        c = np.array([W / 2, -H / 2, 0.0])
        client.camera.position = tuple(c + [0.0, 0.0, 1.2 * max(W, H)])
        client.camera.look_at = tuple(c)

    @property
    def url(self) -> str:
        """The address served."""
        return f"http://{self.server.get_host() or '0.0.0.0'}:{self.server.get_port()}"

    def stop(self) -> None:
        """Stop the server."""
        self.server.stop()

    # -- pins -------------------------------------------------------------------------
    def _on_click(self, event) -> None:
        o, d = np.asarray(event.ray_origin), np.asarray(event.ray_direction)
        if o is None or d is None or abs(d[2]) < 1e-12:
            return
        t = -o[2] / d[2]
        x, y = o[0] + t * d[0], -(o[1] + t * d[1])
        if self.tool.value == "Pin":
            self.add_pin([x, y])
        else:
            self.paint([x, y], int(self.paint_r.value), float(self.brush.value))

    def add_pin(self, at) -> int:
        """Pin the vertex nearest ``at`` (pixels, y down) where the picture is now; return
        the pin's number."""
        p = np.asarray(at, dtype=np.float64)
        with self.lock:
            v = int(np.argmin(np.linalg.norm(self.vertices - p, axis=1)))
            if v in self.pins:
                return self.pins.index(v)
            self.pins.append(v)
            self.targets.append(self.vertices[v].copy())
            self.angles.append(np.nan)
            self._pins_changed()
            self._add_gizmo(len(self.pins) - 1)
            return len(self.pins) - 1

    def remove_pin(self, i: int | None = None) -> None:
        """Remove pin ``i`` (default the last)."""
        with self.lock:
            if not self.pins:
                return
            i = len(self.pins) - 1 if i is None else int(i)
            for lst in (self.pins, self.targets, self.angles):
                lst.pop(i)
            for g in self._gizmos:
                g.remove()
            self._gizmos = []
            for k in range(len(self.pins)):
                self._add_gizmo(k)
            self._pins_changed()

    def move_pin(self, i: int, to, angle: float | None = None) -> None:
        """Move pin ``i`` to ``to`` (pixels, y down), turned by ``angle`` (radians on screen,
        counter-clockwise), and warp."""
        with self.lock:
            self.targets[i] = np.asarray(to, dtype=np.float64)
            if angle is not None:
                self.angles[i] = -float(angle)  # y down: counter-clockwise is negative
            self.solve()

    def _add_gizmo(self, i: int) -> None:
        x, y = self.targets[i]
        W, H = self.size
        g = self.server.scene.add_transform_controls(
            f"/pins/{i}", scale=GIZMO * max(W, H), active_axes=(True, True, False),
            disable_sliders=True, position=(x, -y, 1.0))

        @g.on_update
        def _(_event, i=i, g=g) -> None:
            w, x_, y_, z_ = g.wxyz
            turn = 2.0 * np.arctan2(z_, w)  # about +z (screen counter-clockwise)
            self.move_pin(i, [g.position[0], -g.position[1]],
                          turn if abs(turn) > 1e-9 else None)

        self._gizmos.append(g)

    def _pins_changed(self) -> None:
        if self._deformer is None and self.pins:
            self._deformer = Deformer(self.mesh, np.array(self.pins), rings=self.rings)
        elif self._deformer is not None and self.pins:
            self._deformer.set_handles(np.array(self.pins))  # updated, not refactorised
        self.solve()

    # -- rigidity ---------------------------------------------------------------------
    def set_preset(self, name: str) -> None:
        """Use a preset's r everywhere."""
        with self.lock:
            self.rings[:] = preset_rings(name)
            self._rings_changed()

    def paint(self, at, r: int, radius: float) -> None:
        """Paint ``r`` on the vertices within ``radius`` pixels of ``at`` (rest picture)."""
        with self.lock:
            near = np.linalg.norm(self.rest - np.asarray(at, float), axis=1) <= radius
            if near.any():
                self.rings[near] = int(r)
                self._rings_changed()

    def _rings_changed(self) -> None:
        if self._deformer is not None:
            self._deformer.set_rings(self.rings)
            self.solve()

    # -- solving and drawing ---------------------------------------------------------
    def solve(self) -> None:
        """Warp for the pins as they are and send the picture."""
        with self.lock:
            if self.pins and self._deformer is not None:
                T = np.array(self.targets)
                a = np.array(self.angles)
                res = self._deformer.solve(T, init=self.vertices, max_iter=EDIT_ITERATIONS,
                                           angles=None if np.isnan(a).all() else a)
                self.vertices = np.ascontiguousarray(res.vertices[:, :2])
                self.folds = res.folds
            self.image_node.image = self.view()[::-1].copy()
            self.status.content = self._status()

    def picture(self) -> np.ndarray:
        """The warped picture as it is now (the input's size: what is exported)."""
        return rasterise(self._source, self.rest, self.vertices, self.mesh.faces,
                         outline=self._outline)

    def view(self) -> np.ndarray:
        """The warped picture with the view's margin on every side (what the page shows)."""
        W, H = self.size
        m = self.margin
        return rasterise(self._source, self.rest, self.vertices + m, self.mesh.faces,
                         size=(H + 2 * m, W + 2 * m), outline=self._outline)

    # -- exports -----------------------------------------------------------------------
    def export(self, what: str) -> Path:
        """Write the warped picture ("png"), mesh ("obj") or pins ("pins") to the export
        folder; return the file."""
        self.export_dir.mkdir(parents=True, exist_ok=True)
        stem = Path(self.name).stem or "sprite"
        with self.lock:
            if what == "png":
                out = self.export_dir / f"{stem}-warped.png"
                save_image(out, self.picture())
            elif what == "obj":
                out = self.export_dir / f"{stem}-warped.obj"
                W, H = self.size
                lines = [f"v {x:.6f} {y:.6f} 0" for x, y in self.vertices]
                lines += [f"vt {x / W:.6f} {1.0 - y / H:.6f}" for x, y in self.rest]
                lines += [f"f {a}/{a} {b}/{b} {c}/{c}" for a, b, c in self.mesh.faces + 1]
                with atomic_open(out, "w") as f:
                    f.write("\n".join(lines) + "\n")
            elif what == "pins":
                out = self.export_dir / f"{stem}-pins.json"
                pins = []
                for v, t, a in zip(self.pins, self.targets, self.angles):
                    pin = {"at": self.rest[v].round(3).tolist(), "to": t.round(3).tolist()}
                    if not np.isnan(a):
                        pin["angle"] = round(-float(np.degrees(a)), 3)
                    pins.append(pin)
                with atomic_open(out, "w") as f:
                    f.write(json.dumps(pins, indent=1) + "\n")
            else:
                raise InputError(f"unknown export '{what}' (use png, obj or pins)")
        return out
