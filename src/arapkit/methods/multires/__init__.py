"""Coarse-to-fine ARAP for large meshes: a decimated proxy previews and starts the exact solve.

At 0.4–2M vertices one local/global iteration costs 0.1–0.4 s on two cores and the
low-frequency part of a deformation needs hundreds of them from rest. The same energy on a
proxy of about 20K vertices (quadric decimation, ``fast-simplification``, MIT) costs a few
milliseconds per iteration and converges in tens, so:

* **preview** (:meth:`MultiresDeformer.preview`): iterate the proxy, warm-started from its
  last shape, and map it to the full mesh by rotation-aware skinning: every full vertex
  ``v`` follows the proxy vertex it was collapsed into and that one's nearest neighbours
  ``q`` (:class:`Binding`), ``x_v = sum_q a_vq (y_q + R_q (v - q))`` (inverse squared
  distance weights), with ``R_q`` the proxy's fitted rotation. A rigid motion of the
  handles gives a rigid proxy solution (every ``R_q`` that motion's rotation), so the
  preview is then exact;
* **solve** (:meth:`MultiresDeformer.solve`): solve the proxy from rest, skin it (through
  the intermediate meshes of ``levels=``, if any, each solved in its turn), and run the
  full-resolution local/global iteration (Anderson-accelerated) from there. Every step is
  deterministic (same targets, same start), so the editor's result on release and a
  script's ``Deformer(...).solve(targets)`` are the same computation.

The proxy poses the same problem at its own scale: its handles are the proxy vertices bound
to handle vertices, moved by the rigid motion fitted to each connected handle region
(:func:`arapkit.arap.constraints.rigid_motions`) (exact for the editor's rigid gizmo
moves). The proxy is as stiff as the full mesh: it reads the full mesh's r and counts it in
the full mesh's rings (``ring_scale = h_full / h_proxy``, ``h`` the mean edge length):
``max(1, rint(r s))`` rings of its own, and where even one of them is stiffer than the full
mesh's r-ring (r = 1 on a scan's 20K proxy) the one-ring energy is blended with a rotation
per triangle (:mod:`arapkit.arap.energies.rring`). With the plain one-ring the 20K proxy of
the 437K scan was several times stiffer than the scan, and its solution 1.7 % (p95) / 4.0 %
(max) of the diagonal from the scan's minimum. ``docs/interactive.md`` says when coarse to
fine is chosen and how to control it; ``docs/studies/interactive-at-scale.md`` has the
measurements behind each choice.

One module per concept:

* :mod:`.coarsening`: which coarse copy each kind of shape gets (a table by domain);
* :mod:`.decimator` (with :mod:`.decimation_child`): a mesh's proxy, made by quadric
  decimation in a child process, each full vertex's home on it, and a cache by content;
* :mod:`.subsampler`: a point cloud's proxy, a voxel-grid subsample of its points;
* :mod:`.binding`: how the full mesh follows a coarser one at rest, and the skinning kernels;
* :mod:`.handles`: the full handles on a coarser mesh (regions, fitted rigid motions);
* :mod:`.proxy`: the proxy's solvers, its solve from rest and the preview's warm start;
* :mod:`.parts`: the full mesh's parts the proxy does not solve;
* :mod:`.levels`: the exact solve's fine stages (the full problem, built lazily or beside
  the preview, and the intermediate meshes);
* :mod:`.coarse_to_fine`: :class:`MultiresDeformer`, what ``Deformer(..., multires=True)``
  returns (importing it registers it with :class:`arapkit.Deformer`).

Examples
--------
>>> from arapkit.mesh.shapes import bar, bar_bend
>>> mesh = bar(segments=(60, 8, 8))
>>> h, t = bar_bend(mesh, 60)
>>> d = MultiresDeformer(mesh, h, proxy_vertices=300)
>>> bool(d.solve(t).converged)
True
"""

from .binding import SKIN_NEIGHBOURS, Binding, full_tree_of, proxy_rings
from .coarse_to_fine import AUTO_MIN_VERTICES, MultiresDeformer, Preview
from .coarsening import Coarsening, coarsening_of
from .decimator import DEFAULT_PROXY_VERTICES, decimate, decimation, specks, start_decimation
from .handles import FIT_POINTS, coarse_handles
from .levels import LEVEL_TOL, PROXY_MAX_ITER, Level
from .proxy import LEAD_MAX, PROXY_TOL, STIFF_TOL
from .subsampler import subsample  # registers the point clouds' proxy

# the names the single module arapkit.methods.multires had (it was split into this package)
__all__ = ["AUTO_MIN_VERTICES", "DEFAULT_PROXY_VERTICES", "FIT_POINTS", "LEAD_MAX",
           "LEVEL_TOL", "PROXY_MAX_ITER", "PROXY_TOL", "SKIN_NEIGHBOURS", "STIFF_TOL",
           "Binding", "Coarsening", "Level", "MultiresDeformer", "Preview", "coarse_handles",
           "coarsening_of", "decimate", "decimation", "full_tree_of", "proxy_rings", "specks",
           "start_decimation", "subsample"]
