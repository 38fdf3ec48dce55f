"""The graph ARAP loss (arapkit.torch.GraphARAPLoss) against independent computations.

The engine's own r-ring energy on the same graph (``ARAPProblem.from_graph`` and the numba
CPU backend), finite differences (``torch.autograd.gradcheck``), per-pose losses, Dynamic 3D
Gaussians' rigidity loss written out as in its public code, and an address-space limit
under which an n x n matrix cannot be allocated.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="PyTorch not installed (pip install 'arapkit[torch]')")

from arapkit.arap.backends.cpu import CPUBackend  # noqa: E402
from arapkit.arap.problem import ARAPProblem  # noqa: E402
from arapkit.errors import InputError  # noqa: E402
from arapkit.mesh.shapes import bar  # noqa: E402
from arapkit.torch import GraphARAPLoss, graph_arap_energy  # noqa: E402

F64 = torch.float64
ROOT = Path(__file__).resolve().parents[1]


def _cloud(n=300, seed=0):
    """Points on a noisy sheet (a surface-like cloud), and a smooth bend of it."""
    rng = np.random.default_rng(seed)
    P = np.column_stack([rng.random(n) * 2.0, rng.random(n), 0.05 * rng.standard_normal(n)])
    a = 0.6 * P[:, 0]
    X = np.column_stack([np.sin(a) / 0.6 + 0.2 * P[:, 2], 1.1 * P[:, 1],
                         (1 - np.cos(a)) / 0.6 + P[:, 2]])
    return P, X + 0.01 * rng.standard_normal(X.shape)


def _engine(P, edges, w, rings, X):
    """arapkit's engine: the r-ring energy on the graph at its optimal rotations, and them."""
    p = ARAPProblem.from_graph(P, edges, w, [0], rings=rings)
    be = CPUBackend(p)
    Pi = X[p.perm] / p.scale
    R = np.empty((len(P), 3, 3))
    be.local(Pi.copy(), R)
    return be.vertex_energy(Pi, R).sum() * p.scale ** 2, R[p.iperm]


def _mixed(P):
    return np.where(P[:, 0] > 1.0, 3, 1).astype(np.int32)


CONFIGS = [dict(), dict(backend="torch"), dict(rotations="differentiated")]


@pytest.mark.parametrize("rings", ["1", "3", "mixed"])
@pytest.mark.parametrize("cfg", CONFIGS, ids=["numba", "torch", "differentiated"])
def test_equals_the_engine_energy_on_a_knn_graph(rings, cfg):
    P, X = _cloud()
    r = _mixed(P) if rings == "mixed" else int(rings)
    loss = GraphARAPLoss(P, k=8, rings=r, **cfg)
    E = loss(torch.tensor(X)).item()
    ref, R = _engine(P, loss.edges, loss.edge_weights, r, X)
    assert ref > 1.0  # a real deformation, not round-off
    assert abs(E - ref) <= 1e-10 * ref
    assert loss.last_rotations.shape == R.shape
    assert torch.allclose(loss.last_rotations, torch.tensor(R), atol=1e-9)


def test_equals_the_engine_energy_on_given_edges():
    mesh = bar(segments=(6, 2, 2))
    P = mesh.vertices
    X = P * np.array([1.0, 1.3, 0.8]) + 0.02 * np.sin(7 * P[:, [1, 2, 0]])
    w = 0.5 + np.arange(len(mesh.edges)) % 3
    for r in (1, 3):
        ref, _ = _engine(P, mesh.edges, w, r, X)
        for backend in ("numba", "torch"):
            loss = GraphARAPLoss(P, edges=mesh.edges, weights=w, rings=r, backend=backend)
            assert abs(loss(torch.tensor(X)).item() - ref) <= 1e-10 * ref


def _gradcheck(loss, *inputs):
    return torch.autograd.gradcheck(lambda *a: loss(a[0], R=a[1] if len(a) > 1 else None),
                                    inputs, eps=1e-6, atol=1e-6, rtol=1e-5)


@pytest.mark.parametrize("cfg", [dict(), dict(backend="torch"), dict(rotations="differentiated"),
                                 dict(rings="mixed"), dict(rings=3, backend="torch"),
                                 dict(penalty="norm", rotations="differentiated",
                                      reduction="mean")],
                         ids=["detached-numba", "detached-torch", "differentiated", "mixed-r",
                              "r3-torch", "norm-differentiated"])
def test_gradient_matches_finite_differences(cfg):
    P, X = _cloud(40, seed=1)
    if cfg.get("rings") == "mixed":
        cfg = {**cfg, "rings": _mixed(P)}
    loss = GraphARAPLoss(P, k=6, **cfg)
    assert _gradcheck(loss, torch.tensor(X, requires_grad=True))


@pytest.mark.parametrize("backend", ["numba", "torch"])
def test_gradient_in_given_rotations_matches_finite_differences(backend):
    P, X = _cloud(30, seed=2)
    R = torch.linalg.qr(torch.randn(30, 3, 3, dtype=F64, generator=torch.Generator()
                                    .manual_seed(0)))[0]
    for penalty in ("squared", "norm"):
        loss = GraphARAPLoss(P, k=5, symmetric=False, penalty=penalty, backend=backend)
        assert _gradcheck(loss, torch.tensor(X, requires_grad=True), R.requires_grad_())


def test_detached_and_differentiated_rotations_give_one_gradient():
    """Envelope theorem: at the optimal rotations dE/dR = 0, so holding them fixed loses
    nothing in the first derivative; the two implementations agree too."""
    P, X = _cloud(200, seed=3)
    grads = []
    for cfg in CONFIGS:
        x = torch.tensor(X, requires_grad=True)
        GraphARAPLoss(P, k=8, rings=2, **cfg)(x).backward()
        grads.append(x.grad)
    scale = grads[0].abs().max()
    for g in grads[1:]:
        assert (g - grads[0]).abs().max() <= 1e-9 * scale


@pytest.mark.parametrize("backend", ["numba", "torch"])
def test_a_batch_equals_its_poses(backend):
    P, X = _cloud(150, seed=4)
    rng = np.random.default_rng(5)
    Xb = torch.tensor(np.stack([X, X * 1.1, X + 0.05 * rng.standard_normal(X.shape)]),
                      requires_grad=True)
    rest = torch.tensor(np.stack([P, P * 0.9, P + 0.01]))
    R = torch.linalg.qr(torch.tensor(rng.standard_normal((3, 150, 3, 3))))[0]
    R.requires_grad_()
    loss = GraphARAPLoss(P, k=7, rings=2, backend=backend)
    for kw in (dict(), dict(rest=rest), dict(R=R)):
        Eb = loss(Xb, **kw)
        gX, *gR = torch.autograd.grad(Eb.sum(), [Xb] + ([R] if "R" in kw else []))
        for b in range(3):
            x = Xb[b].detach().requires_grad_()
            one = {k: v[b] for k, v in kw.items()}
            if "R" in kw:
                one["R"] = R[b].detach().requires_grad_()
            e = loss(x, **one)
            g = torch.autograd.grad(e, [x] + ([one["R"]] if "R" in kw else []))
            assert torch.allclose(Eb[b], e, rtol=1e-13, atol=0)
            assert torch.allclose(gX[b], g[0], rtol=1e-12, atol=1e-14)
            if "R" in kw:
                assert torch.allclose(gR[0][b], g[1], rtol=1e-12, atol=1e-14)


# -- Dynamic 3D Gaussians (Luiten et al. 2024), written out as its public code computes it --


def _quat_to_matrix(q):
    """Unit quaternions (w, x, y, z) -> rotation matrices, as D3DGS's ``build_rotation``."""
    q = q / q.norm(dim=-1, keepdim=True)
    w, x, y, z = q.unbind(-1)
    return torch.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
                        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
                        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
                       -1).reshape(*q.shape[:-1], 3, 3)


def _quat_mult(a, b):
    w1, x1, y1, z1 = a.unbind(-1)
    w2, x2, y2, z2 = b.unbind(-1)
    return torch.stack([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
                        w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                        w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
                        w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2], -1)


def _d3dgs_rigidity(mu0, mu_prev, q_prev, mu, q, k=20):
    """``L_rigid`` of Dynamic 3D Gaussians' train.py: neighbours and weights at the first
    frame (brute force here: all pairwise distances), offsets compared in the previous
    frame's coordinates, ``sqrt(w |.|^2 + 1e-20)`` averaged over the n k pairs."""
    d2 = torch.cdist(mu0, mu0) ** 2
    d2.fill_diagonal_(float("inf"))
    sq, nbr = d2.topk(k, dim=1, largest=False)
    weight = torch.exp(-2000 * sq)
    prev_inv = q_prev * torch.tensor([1.0, -1, -1, -1], dtype=q.dtype)
    rot = _quat_to_matrix(_quat_mult(q / q.norm(dim=-1, keepdim=True), prev_inv))
    prev_offset = mu_prev[nbr] - mu_prev[:, None]
    curr_offset = mu[nbr] - mu[:, None]
    in_prev = (rot.transpose(2, 1)[:, None] @ curr_offset[..., None])[..., 0]
    return torch.sqrt(((in_prev - prev_offset) ** 2).sum(-1) * weight + 1e-20).mean()


@pytest.mark.parametrize("backend", ["numba", "torch"])
@pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
def test_dynamic_3d_gaussians_rigidity_loss(backend, dtype):
    g = torch.Generator().manual_seed(7)
    n = 400
    mu0 = 0.2 * torch.rand(n, 3, generator=g, dtype=F64)  # a 20 cm scene: w ~ 0.2
    mu_prev = mu0 + 0.003 * torch.randn(n, 3, generator=g, dtype=F64)
    q_prev = torch.nn.functional.normalize(torch.randn(n, 4, generator=g, dtype=F64), dim=-1)
    mu = (mu_prev + 0.004 * torch.randn(n, 3, generator=g, dtype=F64)).to(dtype)
    q = (q_prev + 0.1 * torch.randn(n, 4, generator=g, dtype=F64)).to(dtype)
    mu.requires_grad_()
    q.requires_grad_()
    ref = _d3dgs_rigidity(mu0.to(dtype), mu_prev.to(dtype), q_prev.to(dtype), mu, q)
    ref_grads = torch.autograd.grad(ref, [mu, q])

    loss = GraphARAPLoss(mu0, k=20, symmetric=False, weights=lambda d2: torch.exp(-2000 * d2),
                         penalty="norm", reduction="mean", backend=backend)
    R = _quat_to_matrix(q) @ _quat_to_matrix(q_prev.to(dtype)).transpose(-1, -2)
    got = loss(mu, rest=mu_prev, R=R)
    grads = torch.autograd.grad(got, [mu, q])
    tol = 1e-12 if dtype == torch.float64 else 2e-5
    assert ref.item() > 1e-3
    assert abs(got.item() - ref.item()) <= tol * ref.item()
    for a, b in zip(grads, ref_grads):
        assert torch.allclose(a, b, rtol=tol * 10, atol=tol * b.abs().max().item())


# -- memory: O(n k), never n x n ---------------------------------------------------------

_NO_DENSE = textwrap.dedent("""
    import resource, sys
    import torch
    from arapkit.torch import GraphARAPLoss
    n = int(sys.argv[1])
    P = torch.rand(n, 3, generator=torch.Generator().manual_seed(0))
    losses = [GraphARAPLoss(P, k=10), GraphARAPLoss(P, k=10, backend="torch"),
              GraphARAPLoss(P, k=10, rotations="differentiated")]
    X = (P * 1.05).requires_grad_()
    for loss in losses:  # once unlimited: compiled kernels, thread pools, allocator arenas
        loss(X).backward()
    vm = int(next(l for l in open("/proc/self/status") if l.startswith("VmSize")).split()[1])
    budget = int(sys.argv[2])
    resource.setrlimit(resource.RLIMIT_AS, (vm * 1024 + budget, vm * 1024 + budget))
    for loss in losses:
        X.grad = None
        loss(X).backward()
        assert torch.isfinite(X.grad).all()
    try:  # the control: under this limit an n x n float32 matrix cannot be allocated
        torch.empty(n, n)
    except (RuntimeError, MemoryError):
        print("dense refused")
    else:
        print("dense allocated")
""")


def test_memory_is_linear_no_n_by_n_matrix():
    """40K points (an n x n float32 matrix: 6.4 GB) under an address-space budget of 1 GB
    beyond what the process already mapped: every implementation runs forward and backward,
    and a dense n x n allocation is refused."""
    env = {"PYTHONPATH": str(ROOT / "src"), "PATH": "/usr/bin:/bin"}
    out = subprocess.run([sys.executable, "-c", _NO_DENSE, "40000", str(1 << 30)],
                         capture_output=True, text=True, env=env, timeout=900)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip() == "dense refused"


# -- bad input -----------------------------------------------------------------------------


def _one_line(match, make):
    with pytest.raises(InputError, match=match) as err:
        make()
    assert "\n" not in str(err.value)


def test_bad_input_is_one_line():
    P, X = _cloud(50)
    bad = P.copy()
    bad[7, 1] = np.nan
    _one_line("point 7 is not finite", lambda: GraphARAPLoss(bad, k=5))
    _one_line("k = 50 needs at least 51 points, got 50", lambda: GraphARAPLoss(P, k=50))
    _one_line("k must be a positive integer", lambda: GraphARAPLoss(P, k=0))
    _one_line(r"points must have shape \(n, 3\)", lambda: GraphARAPLoss(P[:, :2], k=5))
    _one_line(r"edge 1 \[1, 50\] is a loop or out of range \(50 vertices\)",
              lambda: GraphARAPLoss(P, edges=[[0, 1], [1, 50]]))
    _one_line("an edge is listed twice", lambda: GraphARAPLoss(P, edges=[[0, 1], [1, 0]]))
    _one_line("give k .* or edges, not both", lambda: GraphARAPLoss(P, k=5, edges=[[0, 1]]))
    _one_line(r"weight 3 is -1.0 \(weights must be finite and >= 0\)",
              lambda: GraphARAPLoss(P, edges=[[0, 1], [1, 2], [2, 3], [3, 4]],
                                    weights=[1, 1, 1, -1]))
    _one_line("unknown weights 'cotan'", lambda: GraphARAPLoss(P, k=5, weights="cotan"))
    _one_line("per-edge weights need edges=", lambda: GraphARAPLoss(P, k=5, weights=[1.0]))
    _one_line("rings > 1 need the symmetric kNN graph",
              lambda: GraphARAPLoss(P, k=5, symmetric=False, rings=2))
    _one_line(r"vertex 3 has r = 0 \(r must be 1..", lambda: GraphARAPLoss(
        P, k=5, rings=np.r_[1, 1, 1, 0, np.ones(46)]))
    _one_line("rotations must be 'detached' or 'differentiated'",
              lambda: GraphARAPLoss(P, k=5, rotations="svd"))
    loss = GraphARAPLoss(P, k=5)
    _one_line(r"X must have shape \(50, 3\) or \(B, 50, 3\), got \(49, 3\)",
              lambda: loss(torch.tensor(X[:49])))
    _one_line("X must be a torch.Tensor", lambda: loss(X))
    _one_line("X has dtype torch.int64", lambda: loss(torch.zeros(50, 3, dtype=torch.int64)))
    Xn = torch.tensor(X)
    Xn[11, 2] = float("inf")
    _one_line("X: point 11 is not finite", lambda: loss(Xn))
    _one_line("X: pose 1, point 11 is not finite",
              lambda: loss(torch.stack([torch.zeros_like(Xn), Xn])))
    _one_line(r"rest must have shape \(50, 3\)", lambda: loss(torch.tensor(X), rest=P[:3]))
    _one_line(r"R must have shape \(50, 3, 3\)",
              lambda: loss(torch.tensor(X), R=torch.eye(3, dtype=F64)))
    _one_line("penalty='norm' with fitted rotations needs rotations='differentiated'",
              lambda: GraphARAPLoss(P, k=5, penalty="norm")(torch.tensor(X)))
    _one_line("backend='numba' holds the fitted rotations fixed",
              lambda: GraphARAPLoss(P, k=5, backend="numba",
                                    rotations="differentiated")(torch.tensor(X)))


def test_a_copy_or_a_pickle_computes_the_same():
    import copy
    import pickle

    P, X = _cloud(80, seed=9)
    loss = GraphARAPLoss(P, k=6)
    x = torch.tensor(X)
    E = loss(x).item()  # fills the scratch buffer, which copies leave behind
    for other in (copy.deepcopy(loss), pickle.loads(pickle.dumps(loss))):
        assert other(x).item() == E


def test_one_shot_function_equals_the_module():
    P, X = _cloud(80, seed=8)
    x = torch.tensor(X)
    assert graph_arap_energy(x, P, k=6, rings=2).item() == \
        GraphARAPLoss(P, k=6, rings=2)(x).item()
