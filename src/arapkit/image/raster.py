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


@nb.njit(cache=True, inline="always", fastmath=True)
def _sample(src, u, v):
    # bilinear, pixel centres at half integers, clamped at the borders
    H, W = src.shape[0], src.shape[1]
    fx = min(max(u - 0.5, 0.0), W - 1.0)
    fy = min(max(v - 0.5, 0.0), H - 1.0)
    x0, y0 = int(fx), int(fy)
    x1, y1 = min(x0 + 1, W - 1), min(y0 + 1, H - 1)
    ax, ay = fx - x0, fy - y0
    w00, w01 = (1.0 - ax) * (1.0 - ay), ax * (1.0 - ay)
    w10, w11 = (1.0 - ax) * ay, ax * ay
    p, q, r, t = src[y0, x0], src[y0, x1], src[y1, x0], src[y1, x1]
    return (w00 * p[0] + w01 * q[0] + w10 * r[0] + w11 * t[0],
            w00 * p[1] + w01 * q[1] + w10 * r[1] + w11 * t[1],
            w00 * p[2] + w01 * q[2] + w10 * r[2] + w11 * t[2],
            w00 * p[3] + w01 * q[3] + w10 * r[3] + w11 * t[3])


@nb.njit(cache=True, inline="always")
def _top_left(ax, ay, bx, by):
    # the edge a -> b owns the pixel centres on it when it is a top or a left edge of a
    # counter-clockwise triangle (y down)
    dx, dy = bx - ax, by - ay
    return (dy == 0.0 and dx > 0.0) or dy < 0.0


@nb.njit(cache=True, nogil=True)
def _draw(acc, src, X, U, F, order, outline):
    H, W = acc.shape[0], acc.shape[1]
    for q in range(order.shape[0]):
        t = order[q]
        i0, i1, i2 = F[t, 0], F[t, 1], F[t, 2]
        x0, y0, x1, y1, x2, y2 = X[i0, 0], X[i0, 1], X[i1, 0], X[i1, 1], X[i2, 0], X[i2, 1]
        area = (x1 - x0) * (y2 - y0) - (y1 - y0) * (x2 - x0)
        if area == 0.0 or not math.isfinite(area):
            continue
        o0, o1, o2 = outline[t, 1], outline[t, 2], outline[t, 0]
        if area < 0.0:  # clockwise on screen: walk it the other way
            i1, i2 = i2, i1
            x1, y1, x2, y2 = x2, y2, x1, y1
            area = -area
            o1, o2 = o2, o1
        pad = 1.0 if (o0 or o1 or o2) else 0.0
        lo_x = max(0, int(math.floor(min(x0, x1, x2) - pad)))
        hi_x = min(W - 1, int(math.ceil(max(x0, x1, x2) + pad)))
        lo_y = max(0, int(math.floor(min(y0, y1, y2) - pad)))
        hi_y = min(H - 1, int(math.ceil(max(y0, y1, y2) + pad)))
        if lo_x > hi_x or lo_y > hi_y:
            continue
        # edge functions w_c (twice the sub-triangle areas) are affine in the pixel centre:
        # w_c = a_c x + b_c y + c_c, stepped by a_c along a row
        a0, b0 = -(y2 - y1), x2 - x1
        a1, b1 = -(y0 - y2), x0 - x2
        a2, b2 = -(y1 - y0), x1 - x0
        c0 = -(a0 * x1 + b0 * y1)
        c1 = -(a1 * x2 + b1 * y2)
        c2 = -(a2 * x0 + b2 * y0)
        inv0 = 1.0 / math.hypot(a0, b0) if o0 else 0.0
        inv1 = 1.0 / math.hypot(a1, b1) if o1 else 0.0
        inv2 = 1.0 / math.hypot(a2, b2) if o2 else 0.0
        tl0, tl1, tl2 = _top_left(x1, y1, x2, y2), _top_left(x2, y2, x0, y0), \
            _top_left(x0, y0, x1, y1)
        ia = 1.0 / area
        # the rest position is affine in the pixel centre too
        u0, v0 = U[i0, 0], U[i0, 1]
        du1, dv1 = U[i1, 0] - u0, U[i1, 1] - v0
        du2, dv2 = U[i2, 0] - u0, U[i2, 1] - v0
        for py in range(lo_y, hi_y + 1):
            cy = py + 0.5
            cx = lo_x + 0.5
            w0 = a0 * cx + b0 * cy + c0
            w1 = a1 * cx + b1 * cy + c1
            w2 = a2 * cx + b2 * cy + c2
            for px in range(lo_x, hi_x + 1):
                cov = 1.0
                ok = True
                if o0:
                    d = w0 * inv0
                    if d < 0.5:
                        cov *= max(0.0, d + 0.5)
                elif w0 < 0.0 or (w0 == 0.0 and not tl0):
                    ok = False
                if o1:
                    d = w1 * inv1
                    if d < 0.5:
                        cov *= max(0.0, d + 0.5)
                elif w1 < 0.0 or (w1 == 0.0 and not tl1):
                    ok = False
                if o2:
                    d = w2 * inv2
                    if d < 0.5:
                        cov *= max(0.0, d + 0.5)
                elif w2 < 0.0 or (w2 == 0.0 and not tl2):
                    ok = False
                if ok and cov > 0.0:
                    l1, l2 = w1 * ia, w2 * ia  # barycentric weights of corners 1 and 2
                    r, g, b, al = _sample(src, u0 + l1 * du1 + l2 * du2,
                                          v0 + l1 * dv1 + l2 * dv2)
                    a = al * cov
                    keep = 1.0 - a
                    px_ = acc[py, px]
                    px_[0] = r * cov + keep * px_[0]
                    px_[1] = g * cov + keep * px_[1]
                    px_[2] = b * cov + keep * px_[2]
                    px_[3] = a + keep * px_[3]
                w0 += a0
                w1 += a1
                w2 += a2


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
    """``(H, W, 4)`` float32 premultiplied RGBA in [0, 1] of a uint8 RGBA picture (what
    :func:`rasterise` samples; a caller that draws many frames converts once)."""
    s = src.astype(np.float32) / np.float32(255.0)
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
    acc = np.zeros((H, W, 4), dtype=np.float32)
    if background is not None:
        bg = np.asarray(background, dtype=np.float32) / np.float32(255.0)
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
