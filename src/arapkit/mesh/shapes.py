"""Built-in test shapes: the paper's box bar and its bending set-ups (Chen et al. Fig. 3, 8)."""

from __future__ import annotations

import numpy as np

from .model import Mesh

__all__ = ["bar", "bar_bend", "bar_two_materials"]


def bar(
    length: float = 7.0,
    width: float = 0.4,
    height: float = 0.4,
    segments: tuple[int, int, int] = (70, 4, 4),
) -> Mesh:
    """Closed box bar along +x, section centred on the x axis, split into square-ish cells.

    The default (70 x 4 x 4 cells) has 1,154 vertices, the size of the paper's bar.

    Parameters
    ----------
    length, width, height : float
        Extent along x, y, z.
    segments : (int, int, int)
        Cells along x, y, z (each >= 1).

    Examples
    --------
    >>> m = bar()
    >>> m.n_vertices, m.n_faces, m.n_components, len(m.boundary_loops)
    (1154, 2304, 1, 0)
    """
    nx, ny, nz = segments
    xs = np.linspace(0.0, length, nx + 1)
    ys = np.linspace(-width / 2, width / 2, ny + 1)
    zs = np.linspace(-height / 2, height / 2, nz + 1)
    gi, gj, gk = np.meshgrid(np.arange(nx + 1), np.arange(ny + 1), np.arange(nz + 1), indexing="ij")
    on_surface = (gi == 0) | (gi == nx) | (gj == 0) | (gj == ny) | (gk == 0) | (gk == nz)
    index = -np.ones(gi.shape, dtype=np.int64)
    index[on_surface] = np.arange(on_surface.sum())
    V = np.stack([xs[gi[on_surface]], ys[gj[on_surface]], zs[gk[on_surface]]], axis=1)
    faces = []
    centre = np.array([length / 2, 0.0, 0.0])
    for axis, n_axis in ((0, nx), (1, ny), (2, nz)):
        for side in (0, n_axis):
            sl = [slice(None)] * 3
            sl[axis] = side
            grid = index[tuple(sl)]
            a, b, c, d = grid[:-1, :-1], grid[1:, :-1], grid[1:, 1:], grid[:-1, 1:]
            quads = np.stack([a.ravel(), b.ravel(), c.ravel(), d.ravel()], axis=1)
            tris = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
            # orient every triangle outwards
            p0, p1, p2 = V[tris[:, 0]], V[tris[:, 1]], V[tris[:, 2]]
            normal = np.cross(p1 - p0, p2 - p0)
            inward = np.einsum("ij,ij->i", normal, (p0 + p1 + p2) / 3 - centre) < 0
            tris[inward] = tris[inward][:, [0, 2, 1]]
            faces.append(tris)
    return Mesh(V, np.concatenate(faces), name="bar")


def _end_caps(mesh: Mesh) -> tuple[np.ndarray, np.ndarray, float]:
    x = mesh.vertices[:, 0]
    lo, hi = x.min(), x.max()
    tol = 1e-9 * (hi - lo)  # relative: the caps are found at any scale
    return np.flatnonzero(x <= lo + tol), np.flatnonzero(x >= hi - tol), hi - lo


def bar_bend(mesh: Mesh, degrees: float = 180.0) -> tuple[np.ndarray, np.ndarray]:
    """Handles and targets that bend a bar along +x into a circular arc of ``degrees``.

    The end cap at the smallest x stays fixed; the cap at the largest x is moved rigidly to
    where it would be if the centre line were an arc of the same length bending towards +z.

    Returns
    -------
    handles : (h,) int
    targets : (h, 3) float

    Examples
    --------
    >>> h, t = bar_bend(bar(), 180)
    >>> len(h), bool(abs(t[:, 0].max()) < 1e-9)
    (50, True)
    """
    fixed, moved, length = _end_caps(mesh)
    theta = np.radians(degrees)
    x0 = mesh.vertices[:, 0].min()
    if abs(theta) < 1e-12:
        end = np.array([x0 + length, 0.0, 0.0])
    else:
        rho = length / theta
        end = np.array([x0 + rho * np.sin(theta), 0.0, rho * (1.0 - np.cos(theta))])
    c, s = np.cos(theta), np.sin(theta)
    R = np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])
    P = mesh.vertices
    moved_targets = (P[moved] - [x0 + length, 0.0, 0.0]) @ R.T + end
    handles = np.concatenate([fixed, moved])
    targets = np.concatenate([P[fixed], moved_targets])
    return handles, targets


def bar_two_materials(mesh: Mesh, soft: int = 2, hard: int = 6) -> np.ndarray:
    """Per-vertex r for the paper's Fig. 8: the middle third soft, the rest hard.

    Examples
    --------
    >>> r = bar_two_materials(bar())
    >>> sorted(set(r.tolist()))
    [2, 6]
    """
    x = mesh.vertices[:, 0]
    lo, hi = x.min(), x.max()
    middle = (x > lo + (hi - lo) / 3) & (x < lo + 2 * (hi - lo) / 3)
    return np.where(middle, soft, hard).astype(np.int32)
