"""PyTorch layer and losses: differentiable r-ring ARAP on CPU or CUDA tensors.

Needs the optional extra ``pip install 'arapkit[torch]'``.

* :class:`ARAPLayer`: ``X = layer(targets)`` solves ARAP for handle targets ``(h, 3)`` or a
  batch ``(B, h, 3)``; a batch is solved together (all ``3B`` right-hand sides in one
  triangular solve per iteration). Its backward is implicit differentiation at the
  converged solution, not unrolled iterations (:mod:`arapkit.torch.layer`).
* :func:`arap_energy`: eq. 1 of Chen et al. 2017 with optimal rotations, differentiable in
  the positions: the drop-in "ARAP loss" on a mesh (:mod:`arapkit.torch.energy`).
* :class:`GraphARAPLoss` and :func:`graph_arap_energy`: the ARAP loss on a point set with a
  kNN or given graph, r-rings and per-point r, batched, in O(n k) memory, with rotations
  detached or differentiated (:mod:`arapkit.torch.graph_loss`).

What is differentiated: the handle *targets* (the layer) or the positions (the energies).
Held fixed: the rest shape, the edge weights, the rigidity map r, the handle set and the
anchors of handle-free components (which stay at rest).

Details and examples: ``docs/torch.md``.
"""

from __future__ import annotations

from .energy import arap_energy
from .graph_loss import GraphARAPLoss, graph_arap_energy
from .layer import ARAPLayer

__all__ = ["ARAPLayer", "GraphARAPLoss", "arap_energy", "graph_arap_energy"]
