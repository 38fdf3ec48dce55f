"""arapkit's rasteriser: a warped triangle mesh drawn from its source image.

Each triangle of the deformed mesh is scanned over the output pixels its box covers; a pixel
centre inside it (barycentric coordinates from edge functions; on a shared edge the top-left
rule draws it once) takes the source colour at the same barycentric point of the rest
triangle, sampled bilinearly (premultiplied alpha, so that colour does not bleed from
transparent pixels). Edges on the mesh's outline are anti-aliased: a pixel within half a
pixel of one is covered in proportion to its signed distance (``clamp(d + 1/2, 0, 1)``).
Triangles are drawn back to front (their depth) and composited with "over", so where parts
overlap the nearer one is in front. Nothing is re-triangulated: the mesh is the one that was
deformed (unlike scikit-image's ``PiecewiseAffineTransform``, which triangulates its control
points afresh).

Examples
--------
>>> import numpy as np
>>> src = np.zeros((8, 8, 4), np.uint8); src[..., 0] = 200; src[..., 3] = 255
>>> V = np.array([[0, 0], [8, 0], [8, 8], [0, 8]], float)
>>> F = np.array([[0, 1, 2], [0, 2, 3]])
>>> out = rasterise(src, V, V, F)
>>> bool((out == src).all())  # at rest, the picture itself
True
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

__all__ = ["boundary_edges", "premultiplied", "rasterise", "triangle_depths"]


@nb.njit(cache=True, inline="always")
def _sample(src, u, v, out):
    # bilinear, pixel centres at half integers, clamped at the borders
    H, W = src.shape[0], src.shape[1]
    fx = min(max(u - 0.5, 0.0), W - 1.0)
    fy = min(max(v - 0.5, 0.0), H - 1.0)
    x0, y0 = int(fx), int(fy)
    x1, y1 = min(x0 + 1, W - 1), min(y0 + 1, H - 1)
    ax, ay = fx - x0, fy - y0
    for c in range(4):
        top = src[y0, x0, c] * (1.0 - ax) + src[y0, x1, c] * ax
        bot = src[y1, x0, c] * (1.0 - ax) + src[y1, x1, c] * ax
        out[c] = top * (1.0 - ay) + bot * ay


@nb.njit(cache=True, inline="always")
def _top_left(ax, ay, bx, by):
    # the edge a -> b owns the pixel centres on it when it is a top or a left edge of a
    # counter-clockwise triangle (y down)
    dx, dy = bx - ax, by - ay
    return (dy == 0.0 and dx > 0.0) or dy < 0.0


@nb.njit(cache=True, nogil=True)
def _draw(acc, src, X, U, F, order, outline):
    H, W = acc.shape[0], acc.shape[1]
    s = np.empty(4)
    for q in range(order.shape[0]):
        t = order[q]
        i0, i1, i2 = F[t, 0], F[t, 1], F[t, 2]
        x0, y0, x1, y1, x2, y2 = X[i0, 0], X[i0, 1], X[i1, 0], X[i1, 1], X[i2, 0], X[i2, 1]
        area = (x1 - x0) * (y2 - y0) - (y1 - y0) * (x2 - x0)
        if area == 0.0 or not math.isfinite(area):
            continue
        if area < 0.0:  # clockwise on screen: walk it the other way
            i1, i2 = i2, i1
            x1, y1, x2, y2 = x2, y2, x1, y1
            area = -area
        # outline flags of the edges opposite corners 0, 1, 2 (as ordered now)
        o0 = outline[t, 1]
        o1 = outline[t, 2] if F[t, 1] == i1 else outline[t, 0]
        o2 = outline[t, 0] if F[t, 1] == i1 else outline[t, 2]
        pad = 1.0 if (o0 or o1 or o2) else 0.0
        lo_x = max(0, int(math.floor(min(x0, x1, x2) - pad)))
        hi_x = min(W - 1, int(math.ceil(max(x0, x1, x2) + pad)))
        lo_y = max(0, int(math.floor(min(y0, y1, y2) - pad)))
        hi_y = min(H - 1, int(math.ceil(max(y0, y1, y2) + pad)))
        l0 = math.hypot(x2 - x1, y2 - y1)
        l1 = math.hypot(x0 - x2, y0 - y2)
        l2 = math.hypot(x1 - x0, y1 - y0)
        tl0, tl1, tl2 = _top_left(x1, y1, x2, y2), _top_left(x2, y2, x0, y0), \
            _top_left(x0, y0, x1, y1)
        for py in range(lo_y, hi_y + 1):
            cy = py + 0.5
            for px in range(lo_x, hi_x + 1):
                cx = px + 0.5
                # twice the areas of the sub-triangles: barycentric weights times 2A
                w0 = (x2 - x1) * (cy - y1) - (y2 - y1) * (cx - x1)
                w1 = (x0 - x2) * (cy - y2) - (y0 - y2) * (cx - x2)
                w2 = (x1 - x0) * (cy - y0) - (y1 - y0) * (cx - x0)
                cov = 1.0
                ok = True
                for w, o, ln, tl in ((w0, o0, l0, tl0), (w1, o1, l1, tl1), (w2, o2, l2, tl2)):
                    if o:
                        d = w / ln  # signed distance to the outline edge, in pixels
                        if d < 0.5:
                            cov *= max(0.0, d + 0.5)
                    elif w < 0.0 or (w == 0.0 and not tl):
                        ok = False
                if not ok or cov <= 0.0:
                    continue
                b0, b1, b2 = w0 / area, w1 / area, w2 / area
                u = b0 * U[i0, 0] + b1 * U[i1, 0] + b2 * U[i2, 0]
                v = b0 * U[i0, 1] + b1 * U[i1, 1] + b2 * U[i2, 1]
                _sample(src, u, v, s)
                a = s[3] * cov
                keep = 1.0 - a
                for c in range(3):
                    acc[py, px, c] = s[c] * cov + keep * acc[py, px, c]
                acc[py, px, 3] = a + keep * acc[py, px, 3]


def boundary_edges(F: np.ndarray) -> np.ndarray:
    """``(m, 3)`` bool: whether face t's edge ``(F[t, c], F[t, c + 1])`` is on the outline
    (in no other triangle).

    Examples
    --------
    >>> boundary_edges(np.array([[0, 1, 2], [0, 2, 3]])).tolist()
    [[True, True, False], [False, True, True]]
    """
    a = F
    b = np.roll(F, -1, axis=1)
    key = np.minimum(a, b) * (int(F.max()) + 1) + np.maximum(a, b)
    _, inv, cnt = np.unique(key.ravel(), return_inverse=True, return_counts=True)
    return (cnt[inv] == 1).reshape(F.shape)


def triangle_depths(F: np.ndarray, vertex_depth: np.ndarray | None) -> np.ndarray:
    """Each triangle's depth: the mean of its corners' (0 everywhere without depths)."""
    if vertex_depth is None:
        return np.zeros(len(F))
    return np.asarray(vertex_depth, dtype=np.float64)[F].mean(axis=1)


@nb.njit(cache=True, nogil=True)
def _finish(acc, out):
    # premultiplied float -> straight uint8; a pixel whose alpha rounds to 0 has no colour
    for y in range(acc.shape[0]):
        for x in range(acc.shape[1]):
            a = acc[y, x, 3]
            if a * 255.0 < 0.5:
                for c in range(4):
                    out[y, x, c] = 0
                continue
            for c in range(3):
                v = acc[y, x, c] / a * 255.0 + 0.5
                out[y, x, c] = 255 if v >= 255.0 else (0 if v <= 0.0 else int(v))
            v = a * 255.0 + 0.5
            out[y, x, 3] = 255 if v >= 255.0 else int(v)


def premultiplied(src: np.ndarray) -> np.ndarray:
    """``(H, W, 4)`` float64 premultiplied RGBA in [0, 1] of a uint8 RGBA picture (what
    :func:`rasterise` samples; a caller that draws many frames converts once)."""
    s = src.astype(np.float64) / 255.0
    s[..., :3] *= s[..., 3:4]
    return s


def rasterise(src: np.ndarray, rest: np.ndarray, deformed: np.ndarray, faces: np.ndarray,
              *, depth: np.ndarray | None = None, size: tuple[int, int] | None = None,
              background=None, outline: np.ndarray | None = None) -> np.ndarray:
    """Draw the deformed mesh with the colours of ``src`` at the rest positions.

    Parameters
    ----------
    src : (H, W, 4) uint8, or its :func:`premultiplied` float form
        The source picture, RGBA (straight alpha).
    rest, deformed : (n, 2) float
        Vertex positions in the source and in the output, in pixels (x right, y down).
    faces : (m, 3) int
    depth : (m,) float, optional
        Triangle depths: larger is nearer, drawn later (in front).
    size : (H, W), optional
        The output's size (default the source's).
    background : (3,) or (4,) uint8, optional
        What shows where no triangle is (default transparent).
    outline : (m, 3) bool, optional
        :func:`boundary_edges` of ``faces``, when already known.

    Returns
    -------
    (H, W, 4) uint8, straight alpha.
    """
    H, W = (src.shape[0], src.shape[1]) if size is None else size
    s = premultiplied(src) if src.dtype == np.uint8 else src
    acc = np.zeros((H, W, 4), dtype=np.float64)
    if background is not None:
        bg = np.asarray(background, dtype=np.float64) / 255.0
        a = bg[3] if len(bg) == 4 else 1.0
        acc[..., :3] = bg[:3] * a
        acc[..., 3] = a
    F = np.ascontiguousarray(faces, dtype=np.int64)
    order = np.argsort(triangle_depths(F, None) if depth is None else depth, kind="stable")
    out_edges = boundary_edges(F) if outline is None else outline
    _draw(acc, s, np.ascontiguousarray(deformed[:, :2], dtype=np.float64),
          np.ascontiguousarray(rest[:, :2], dtype=np.float64), F, order.astype(np.int64),
          np.ascontiguousarray(out_edges))
    out = np.empty((H, W, 4), dtype=np.uint8)
    _finish(acc, out)
    return out
