"""Puppet warping an image: mesh its shape, pin it, deform in 2D, draw it again.

:class:`ImageWarp` holds what does not change between frames (the picture, its mesh with a
vertex at every pin, the planar :class:`arapkit.Deformer` and its factor); each
:meth:`ImageWarp.frame` solves warm from the last frame and rasterises
(:mod:`arapkit.image.raster`). :func:`warp_image` is the one-shot call behind
``arapkit warp``; :func:`render_keyframes` renders an animation.

Examples
--------
>>> import numpy as np
>>> img = np.zeros((64, 96, 4), np.uint8); img[16:48, 8:88] = [200, 60, 40, 255]
>>> pins = [{"at": [12, 32], "to": [12, 32]}, {"at": [84, 32], "to": [84, 12]}]
>>> out = warp_image(img, pins)
>>> out.image.shape, out.folds
((64, 96, 4), 0)
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError, require_extra
from ..io.atomic import atomic_open
from ..mesh.model import Mesh
from ..methods.deformer import Deformer
from .meshing import mesh_mask, shape_mask
from .pins import Keyframes, Pins, parse_pins
from .raster import boundary_edges, premultiplied, rasterise

__all__ = ["ImageWarp", "WarpResult", "read_image", "render_keyframes", "save_animation",
           "save_image", "warp_image"]

#: how many local/global iterations a frame may take (warm from the frame before)
FRAME_ITERATIONS = 200


def read_image(path_or_array, name: str | None = None) -> tuple[np.ndarray, str]:
    """An image as ``(H, W, 4)`` uint8 RGBA and its name (a file through Pillow, or an
    array ``(H, W)``, ``(H, W, 3)`` or ``(H, W, 4)`` of uint8)."""
    if isinstance(path_or_array, np.ndarray):
        a = path_or_array
        label = name or "image"
        if a.dtype != np.uint8 or a.ndim not in (2, 3) or (a.ndim == 3 and a.shape[2] not in
                                                           (3, 4)):
            raise InputError(f"{label}: expected a uint8 array (H, W), (H, W, 3) or "
                             f"(H, W, 4), got {a.dtype} {a.shape}")
        if a.ndim == 2:
            a = np.repeat(a[..., None], 3, axis=2)
        if a.shape[2] == 3:
            a = np.concatenate([a, np.full(a.shape[:2] + (1,), 255, np.uint8)], axis=2)
        return np.ascontiguousarray(a), label
    require_extra(["PIL"], "image", "reading an image")
    from PIL import Image, UnidentifiedImageError

    p = Path(path_or_array)
    label = name or str(p)
    try:
        with Image.open(p) as im:
            if im.width * im.height > 64_000_000:
                raise InputError(f"{label}: {im.width} x {im.height} pixels; at most 64 "
                                 "megapixels")
            rgba = np.asarray(im.convert("RGBA"))
    except FileNotFoundError:
        raise InputError(f"{label}: no such file") from None
    except (UnidentifiedImageError, OSError, ValueError) as e:
        raise InputError(f"{label}: not an image Pillow can read ({e})") from None
    return np.ascontiguousarray(rgba), label


def save_image(path, rgba: np.ndarray) -> None:
    """Write an RGBA image (PNG, or what the suffix says) atomically."""
    from PIL import Image

    p = Path(path)
    fmt = {".png": "PNG", ".jpg": "JPEG", ".jpeg": "JPEG", ".webp": "WEBP", ".bmp": "BMP",
           ".tif": "TIFF", ".tiff": "TIFF"}.get(p.suffix.lower())
    if fmt is None:
        raise InputError(f"{p}: unknown image format '{p.suffix}' (use .png)")
    im = Image.fromarray(rgba, "RGBA")
    if fmt in ("JPEG", "BMP"):
        im = im.convert("RGB")
    with atomic_open(p, "wb") as f:
        im.save(f, format=fmt)


@dataclass
class WarpResult:
    """A warped frame.

    Attributes
    ----------
    image : (H, W, 4) uint8
    vertices : (n, 2) the deformed mesh's vertices (pixels)
    folds : int
        Triangles turned over (0 unless the pins admit no fold-free map).
    mesh : Mesh
        The rest mesh (its pins are vertices ``0 .. p-1``).
    """

    image: np.ndarray
    vertices: np.ndarray
    folds: int
    mesh: Mesh


class ImageWarp:
    """A picture meshed and pinned, ready to warp frame after frame.

    Parameters
    ----------
    image : path or (H, W[, 3|4]) uint8 array
    at : (p, 2) float
        The pins' places on the picture (pixels); each becomes a mesh vertex.
    spacing : float, optional
        Mesh edge length in pixels (the density; default the shape's size over 40).
    rigidity : int or str
        r, or a preset ("distort", "normal", "rigid"; :data:`arapkit.methods.planar.PRESETS`).
    key : (3,) int, optional
        Mesh every pixel away from this colour (default: alpha, or the top-left colour for
        an image without transparency).
    alpha_threshold : int
        Pixels with alpha above this are the shape.

    Examples
    --------
    >>> img = np.zeros((40, 40, 4), np.uint8); img[5:35, 5:35] = 255
    >>> w = ImageWarp(img, [[10, 20], [30, 20]])
    >>> r = w.frame([[10, 20], [30, 20]])   # pins at rest: the picture itself
    >>> bool((r.image == img).all())
    True
    """

    def __init__(self, image, at, *, spacing: float | None = None, rigidity="normal",
                 key=None, alpha_threshold: int = 0, name: str | None = None) -> None:
        self.rgba, self.name = read_image(image, name)
        at = np.asarray(at, dtype=np.float64).reshape(-1, 2)
        if not len(at):
            raise InputError(f"{self.name}: no pins (put at least one)")
        H, W = self.rgba.shape[:2]
        out = np.flatnonzero((at[:, 0] < 0) | (at[:, 0] > W) | (at[:, 1] < 0) | (at[:, 1] > H))
        if len(out):
            i = int(out[0])
            raise InputError(f"pin {i} at ({at[i, 0]:g}, {at[i, 1]:g}) is outside the "
                             f"{W} x {H} image {self.name}")
        keyed = key is not None or not (self.rgba[..., 3] < 255).any()
        mask = shape_mask(self.rgba, alpha_threshold=alpha_threshold, key=key,
                          name=self.name)
        self.background = None
        if keyed:
            k = self.rgba[0, 0, :3] if key is None else np.asarray(key, np.uint8)
            self.background = np.r_[k, 255].astype(np.uint8)
            self.rgba = self.rgba.copy()
            self.rgba[~mask, 3] = 0  # the key is background, not part of the shape
        self.mesh = mesh_mask(mask, spacing, pins=at, name=self.name)
        self.at = at
        self.rest = self.mesh.vertices[:, :2]
        self.outline = boundary_edges(self.mesh.faces)
        self.deformer = Deformer(self.mesh, np.arange(len(at)), rings=rigidity)
        self.vertices = self.rest.copy()
        self._depth_owner = None
        self._source = None

    @property
    def pins(self) -> np.ndarray:
        """The pins' vertices (``0 .. p-1``)."""
        return self.deformer.handles

    def vertex_depths(self, pin_depth) -> np.ndarray | None:
        """Each vertex's depth: that of the pin nearest along the mesh (None when all are
        equal)."""
        d = np.asarray(pin_depth, dtype=np.float64)
        if not len(d) or np.all(d == d[0]):
            return None
        if self._depth_owner is None:
            from scipy.sparse.csgraph import dijkstra

            m = self.mesh
            E = m.edges
            w = np.linalg.norm(m.vertices[E[:, 0]] - m.vertices[E[:, 1]], axis=1)
            from scipy.sparse import coo_matrix

            G = coo_matrix((w, (E[:, 0], E[:, 1])), shape=(m.n_vertices,) * 2)
            _, _, src = dijkstra(G, directed=False, indices=np.arange(len(self.at)),
                                 min_only=True, return_predecessors=True)
            self._depth_owner = np.where(src < 0, 0, src)
        return d[self._depth_owner]

    def frame(self, to, angles=None, depth=None, *, max_iter: int = FRAME_ITERATIONS,
              tol: float = 1e-4) -> WarpResult:
        """Solve for the pins at ``to`` (warm from the last frame) and draw the picture.

        ``angles`` (radians in the image frame, NaN: none) turn pins; ``depth`` (one per
        pin) orders overlapping parts.
        """
        to = np.asarray(to, dtype=np.float64).reshape(-1, 2)
        res = self.deformer.solve(to, init=self.vertices, angles=angles, tol=tol,
                                  max_iter=max_iter)
        self.vertices = np.ascontiguousarray(res.vertices[:, :2])
        return WarpResult(self.render(self.vertices, depth), self.vertices, res.folds,
                          self.mesh)

    def render(self, vertices: np.ndarray, depth=None) -> np.ndarray:
        """The picture drawn on the mesh deformed to ``vertices``."""
        vd = None if depth is None else self.vertex_depths(depth)
        tri = None if vd is None else vd[self.mesh.faces].mean(axis=1)
        if self._source is None:
            self._source = premultiplied(self.rgba)
        return rasterise(self._source, self.rest, vertices, self.mesh.faces, depth=tri,
                         background=self.background, outline=self.outline)

    def save_mesh(self, path) -> None:
        """The warped mesh (z = 0) with the rest positions as UVs (v up, in [0, 1]), OBJ."""
        H, W = self.rgba.shape[:2]
        F = self.mesh.faces + 1
        lines = ["# arapkit warp: the warped mesh (pixels, y down), UVs = rest / image size"]
        lines += [f"v {x:.6f} {y:.6f} 0" for x, y in self.vertices]
        lines += [f"vt {x / W:.6f} {1.0 - y / H:.6f}" for x, y in self.rest]
        lines += [f"f {a}/{a} {b}/{b} {c}/{c}" for a, b, c in F]
        with atomic_open(Path(path), "w") as f:
            f.write("\n".join(lines) + "\n")


def warp_image(image, pins, *, spacing: float | None = None, rigidity="normal",
               key=None, alpha_threshold: int = 0) -> WarpResult:
    """Warp ``image`` by ``pins`` (a :class:`Pins`, or the decoded JSON of a pins file).

    See :class:`ImageWarp` for the options; the result's ``image`` has the input's size.
    """
    p = pins if isinstance(pins, Pins) else parse_pins(pins)
    w = ImageWarp(image, p.at, spacing=spacing, rigidity=rigidity, key=key,
                  alpha_threshold=alpha_threshold)
    return w.frame(p.to, p.turned, p.depth, max_iter=1000)


def render_keyframes(warp: ImageWarp, keys: Keyframes, progress=None) -> list[np.ndarray]:
    """Every frame of ``keys`` drawn, each solve warm from the last."""
    frames = []
    for i, p in enumerate(keys.frames()):
        frames.append(warp.frame(p.to, p.turned, p.depth).image)
        if progress is not None:
            progress(i)
    return frames


def save_animation(path, frames: list[np.ndarray], fps: float) -> list[Path]:
    """Write frames as a GIF (``.gif``), an APNG (``.png``) or PNG files in a folder
    (any other path, created); atomically. Returns the files written."""
    from PIL import Image

    p = Path(path)
    ms = int(round(1000.0 / fps))
    if p.suffix.lower() in (".gif", ".png", ".apng"):
        ims = [Image.fromarray(f, "RGBA") for f in frames]
        fmt = "GIF" if p.suffix.lower() == ".gif" else "PNG"
        extra = {"disposal": 2} if fmt == "GIF" else {}
        with atomic_open(p, "wb") as f:
            ims[0].save(f, format=fmt, save_all=True, append_images=ims[1:], duration=ms,
                        loop=0, **extra)
        return [p]
    p.mkdir(parents=True, exist_ok=True)
    out = []
    for i, fr in enumerate(frames):
        q = p / f"frame_{i:04d}.png"
        save_image(q, fr)
        out.append(q)
    return out
