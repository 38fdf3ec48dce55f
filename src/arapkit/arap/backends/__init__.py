"""Backends of the local/global loop, behind one interface, chosen by device name.

A backend runs one problem's kernels (local step, right-hand side, global solve) on one
device: :class:`~arapkit.arap.backends.cpu.CPUBackend` (numba) on ``"cpu"``,
:class:`~arapkit.arap.backends.torch_backend.TorchBackend` (extra ``arapkit[torch]``) on
``"cuda"``, ``"cuda:N"`` and ``"torch-cpu"``. :func:`make_backend` is the one dispatch.

Examples
--------
>>> from arapkit.arap.problem import ARAPProblem
>>> from arapkit.mesh.shapes import bar
>>> make_backend(ARAPProblem.from_mesh(bar(), [0]), "cpu").name
'cpu'
"""

from __future__ import annotations

from importlib.util import find_spec
from typing import TYPE_CHECKING

from ...errors import InputError
from .cpu import CPUBackend

if TYPE_CHECKING:
    from ..problem import ARAPProblem

__all__ = ["DEVICES", "check_device", "make_backend"]

#: the devices a solve can run on ("auto": CUDA when torch sees a device, else "cpu")
DEVICES = ("cpu", "auto", "cuda", "cuda:N", "torch-cpu")


def check_device(device: str) -> str:
    """Resolve ``device`` to "cpu" (numba), "torch-cpu", "cuda" or "cuda:N" (torch backend).

    ``"auto"`` is CUDA when torch is installed and sees a device, else the numba CPU path.
    The torch devices need the extra ``arapkit[torch]``; without it (or without CUDA) the
    error names the remedy.

    Examples
    --------
    >>> check_device("CPU")
    'cpu'
    """
    dev = str(device).lower()
    if dev == "cpu":
        return "cpu"
    if dev == "auto":
        if find_spec("torch") is None:
            return "cpu"
        import torch

        return "cuda" if torch.cuda.is_available() else "cpu"
    if dev == "gpu":
        dev = "cuda"
    if dev in ("cuda", "torch-cpu") or dev.startswith("cuda:"):
        if find_spec("torch") is None:
            raise InputError(f"device='{device}' needs PyTorch: pip install 'arapkit[torch]' "
                             "(a CUDA build for a GPU), or use device='cpu'")
        from .torch_backend import resolve_device

        resolve_device("cpu" if dev == "torch-cpu" else dev)
        return dev
    raise InputError(f"unknown device '{device}' (use 'cpu', 'auto', 'cuda', 'cuda:N' or "
                     "'torch-cpu')")


def make_backend(problem: ARAPProblem, device: str = "cpu"):
    """The backend of ``problem`` on ``device`` (see :func:`check_device`), not yet bound.

    A planar problem (``problem.dim == 2``) runs on the planar CPU backend
    (:mod:`arapkit.arap.backends.planar`).
    """
    dev = check_device(device)
    if problem.dim == 2:
        if dev != "cpu":
            raise InputError(f"device='{device}': a planar (2D) solve runs on the CPU "
                             "(device='cpu'); it is small and fast there")
        from .planar import PlanarBackend

        return PlanarBackend(problem)
    if dev == "cpu":
        return CPUBackend(problem)
    from .torch_backend import TorchBackend

    return TorchBackend(problem, "cpu" if dev == "torch-cpu" else dev)
