"""The PyTorch layer, loss and backend against the numba solver and finite differences."""

from __future__ import annotations

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="PyTorch not installed (pip install 'arapkit[torch]')")

from arapkit import Deformer  # noqa: E402
from arapkit.arap.backends.cpu import CPUBackend  # noqa: E402
from arapkit.arap.backends.torch_backend import fit_rotations  # noqa: E402
from arapkit.arap.problem import ARAPProblem  # noqa: E402
from arapkit.errors import InputError  # noqa: E402
from arapkit.mesh.shapes import bar, bar_bend  # noqa: E402
from arapkit.torch import ARAPLayer, arap_energy  # noqa: E402

F64 = torch.float64


@pytest.fixture(scope="module")
def small():
    """A short bar (58 vertices) bent by 60 degrees: both caps are handles."""
    mesh = bar(length=2.0, segments=(6, 2, 2))
    h, t = bar_bend(mesh, 60)
    return mesh, h, t


def _diag(mesh) -> float:
    return float(np.linalg.norm(mesh.vertices.max(0) - mesh.vertices.min(0)))


@pytest.mark.parametrize("rings", [1, 2])
def test_forward_equals_deformer(rings):
    mesh = bar(segments=(20, 3, 3))
    h, t = bar_bend(mesh, 90)
    ref = Deformer(mesh, h, rings=rings).solve(t, tol=1e-12, max_iter=20000)
    layer = ARAPLayer(mesh, h, rings=rings, dtype=F64, tol=1e-12, max_iter=20000)
    X = layer(torch.tensor(t))
    assert X.shape == (mesh.n_vertices, 3) and X.dtype == F64
    assert layer.last_info["converged"] and ref.converged
    assert np.abs(X.numpy() - ref.vertices).max() <= 1e-6 * _diag(mesh)
    # the handles are exactly where they were sent
    assert np.array_equal(X.numpy()[h], t)


def test_batch_equals_single_solves(small):
    mesh, h, t = small
    rng = np.random.default_rng(1)
    T = np.stack([t + 0.1 * rng.standard_normal(t.shape) for _ in range(4)])
    layer = ARAPLayer(mesh, h, rings=2, dtype=F64, tol=0.0, xtol=1e-13, max_iter=20000)
    Xb = layer(torch.tensor(T))
    assert Xb.shape == (4, mesh.n_vertices, 3)
    for b in range(4):
        Xs = layer(torch.tensor(T[b]))
        assert torch.allclose(Xb[b], Xs, rtol=0, atol=1e-9 * _diag(mesh))


def _cactus_poses():
    """examples/cactus.off with the arms of examples/cactus.json turned by 1 %, 30 %, 100 %
    and 250 % of the file's angles: poses that converge in very different numbers of
    iterations."""
    from pathlib import Path

    from arapkit import load_mesh
    from arapkit.io import parse_handles

    examples = Path(__file__).resolve().parents[1] / "examples"
    mesh = load_mesh(examples / "cactus.off")
    spec = json.loads((examples / "cactus.json").read_text())
    T = []
    for f in (0.01, 0.3, 1.0, 2.5):
        for g in spec["groups"][1:]:
            g["rotate"]["degrees"] *= f
        hs = parse_handles(spec, mesh.vertices)
        for g in spec["groups"][1:]:
            g["rotate"]["degrees"] /= f
        T.append(hs.targets)
    return mesh, hs.indices, np.stack(T)


@pytest.mark.parametrize("tol", [1e-3, 1e-10])
def test_batch_poses_stop_on_their_own(tol):
    """Each pose of a batch stops at its own test: its answer and iteration count are
    those of its single solve, however long its batch-mates run."""
    mesh, h, T = _cactus_poses()
    layer = ARAPLayer(mesh, h, dtype=F64, tol=tol, max_iter=20000)
    Xb = layer(torch.tensor(T))
    info = layer.last_info
    its = []
    for b in range(len(T)):
        Xs = layer(torch.tensor(T[b]))
        assert torch.allclose(Xb[b], Xs, rtol=0, atol=1e-9 * _diag(mesh))
        assert layer.last_info["converged"] and bool(info["pose_converged"][b])
        assert int(info["pose_iterations"][b]) == layer.last_info["iterations"]
        its.append(layer.last_info["iterations"])
        assert torch.allclose(info["energy"][b], layer.last_info["energy"][0], rtol=1e-12)
    assert len(set(its)) == len(its) and info["iterations"] == max(its)


def test_gradient_of_frozen_poses(small):
    """Gradients of a batch whose poses stopped at different iterations: each equals the
    gradient of its single solve, taken at the iterate where that pose stopped."""
    mesh, h, _ = small
    T = np.stack([bar_bend(mesh, a)[1] for a in (2, 60, 150)])
    rng = np.random.default_rng(7)
    c = torch.tensor(rng.standard_normal((3, mesh.n_vertices, 3)))
    layer = ARAPLayer(mesh, h, dtype=F64, tol=1e-6, max_iter=20000)
    Tb = torch.tensor(T, requires_grad=True)
    (layer(Tb) * c).sum().backward()
    info = layer.last_info
    its = []
    for b in range(3):
        Ts = torch.tensor(T[b], requires_grad=True)
        (layer(Ts) * c[b]).sum().backward()
        assert torch.allclose(Tb.grad[b], Ts.grad, rtol=0, atol=1e-12 * Ts.grad.abs().max())
        its.append(layer.last_info["iterations"])
    assert len(set(its)) == 3 and info["pose_iterations"].tolist() == its


def _directional_check(layer, t, c, rng, eps=1e-5, n_dirs=2):
    T = torch.tensor(t, requires_grad=True)
    (layer(T) * c).sum().backward()
    g = T.grad.numpy()
    for _ in range(n_dirs):
        D = rng.standard_normal(t.shape)

        def f(s, D=D):
            return float((layer(torch.tensor(t + s * D)) * c).sum())

        fd = (f(eps) - f(-eps)) / (2 * eps)
        an = float((g * D).sum())
        assert abs(an - fd) <= 1e-4 * abs(fd), (an, fd)


@pytest.mark.parametrize("rings", [1, 3])
def test_gradient_matches_finite_differences(small, rings):
    """Implicit differentiation vs central differences of fully converged solves."""
    mesh, h, t = small
    rng = np.random.default_rng(rings)
    c = torch.tensor(rng.standard_normal((mesh.n_vertices, 3)))
    layer = ARAPLayer(mesh, h, rings=rings, dtype=F64, tol=0.0, xtol=1e-13, max_iter=20000)
    _directional_check(layer, t, c, rng)
    assert layer.last_info["converged"]


def test_gradient_of_a_batch_is_per_pose(small):
    mesh, h, t = small
    rng = np.random.default_rng(5)
    layer = ARAPLayer(mesh, h, dtype=F64, tol=0.0, xtol=1e-12, max_iter=20000)
    T = torch.tensor(np.stack([t, t + 0.05 * rng.standard_normal(t.shape)]), requires_grad=True)
    c = torch.tensor(rng.standard_normal((2, mesh.n_vertices, 3)))
    (layer(T) * c).sum().backward()
    for b in range(2):
        Tb = torch.tensor(T.detach().numpy()[b], requires_grad=True)
        (layer(Tb) * c[b]).sum().backward()
        assert torch.allclose(T.grad[b], Tb.grad, rtol=1e-7, atol=1e-9)


def test_rotation_derivative_matches_finite_differences():
    """The closed-form polar derivative, including a covariance with repeated singular values
    (where the autograd of the SVD divides by zero)."""
    rng = np.random.default_rng(0)
    S = rng.standard_normal((5, 3, 3))
    S[0] = np.diag([2.0, 1.0, 1.0]) @ _rot(0.3)  # repeated singular values
    S[1] = -S[1] if np.linalg.det(S[1]) > 0 else S[1]  # a reflection is fixed
    St = torch.tensor(S, requires_grad=True)
    G = torch.tensor(rng.standard_normal((5, 3, 3)))
    (fit_rotations(St) * G).sum().backward()
    D = rng.standard_normal(S.shape)
    eps = 1e-6

    def f(s):
        return float((fit_rotations(torch.tensor(S + s * D)) * G).sum(dim=(1, 2)).sum())

    fd = (f(eps) - f(-eps)) / (2 * eps)
    assert abs(float((St.grad.numpy() * D).sum()) - fd) <= 1e-6 * abs(fd)
    R = fit_rotations(torch.tensor(S)).numpy()
    assert np.allclose(np.linalg.det(R), 1.0)
    assert np.allclose(R @ R.transpose(0, 2, 1), np.eye(3))


def _rot(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


@pytest.mark.parametrize("rings", [1, 3])
def test_arap_energy_value_and_gradient(small, rings):
    mesh, h, t = small
    p = ARAPProblem.from_mesh(mesh, h, rings=rings)
    rest = torch.tensor(mesh.vertices)
    # zero at rest and at any rigid motion of it; positive otherwise
    assert float(arap_energy(rest, p).detach()) <= 1e-24
    moved = rest @ torch.tensor(_rot(0.7)).T + torch.tensor([1.0, -2.0, 3.0])
    assert float(arap_energy(moved, p)) <= 1e-20
    rng = np.random.default_rng(rings)
    X0 = mesh.vertices + 0.05 * rng.standard_normal(mesh.vertices.shape)
    X = torch.tensor(X0, requires_grad=True)
    E = arap_energy(X, p)
    assert float(E.detach()) > 0
    # the same value as the numba kernels' local step (their own rotations, expanded form);
    # the backend works in the problem's unit p.scale, so positions and energy are converted
    R = np.empty((mesh.n_vertices, 3, 3))
    E_numba = CPUBackend(p).local(np.ascontiguousarray(X0[p.perm] / p.scale), R) * p.scale**2
    assert np.isclose(float(E.detach()), E_numba, rtol=1e-9)
    E.backward()
    D = rng.standard_normal(X0.shape)
    eps = 1e-6
    fd = (float(arap_energy(torch.tensor(X0 + eps * D), p))
          - float(arap_energy(torch.tensor(X0 - eps * D), p))) / (2 * eps)
    assert abs(float((X.grad.numpy() * D).sum()) - fd) <= 1e-4 * abs(fd)
    # batched: one value per pose
    Eb = arap_energy(torch.stack([rest, X.detach()]), p)
    assert Eb.shape == (2,) and float(Eb[0]) <= 1e-24 and torch.isclose(Eb[1], E.detach())


@pytest.mark.parametrize("kw", [{"rings": 2}, {"rings": 1, "accelerate": True},
                                {"energy": "sr-arap"}])
def test_deformer_torch_backend_equals_numba(kw):
    if kw.get("energy") == "sr-arap":  # a rotation coupling, where the energy module exists
        pytest.importorskip("arapkit.arap.energies.sr_arap",
                            reason="energy 'sr-arap' not in this build")
    mesh = bar(segments=(20, 3, 3))
    h, t = bar_bend(mesh, 90)
    ref = Deformer(mesh, h, **kw).solve(t, max_iter=50)
    dev = Deformer(mesh, h, device="torch-cpu", **kw)
    assert dev.device == "torch-cpu" and dev.backend.name == "torch"
    res = dev.solve(t, max_iter=50)
    assert res.iterations == ref.iterations
    assert np.abs(res.vertices - ref.vertices).max() <= 1e-9 * _diag(mesh)
    assert np.allclose(res.history, ref.history, rtol=1e-9)
    assert np.allclose(res.vertex_energy, ref.vertex_energy, rtol=1e-8, atol=1e-14)


def test_bad_inputs_are_one_line_errors(small):
    mesh, h, t = small
    layer = ARAPLayer(mesh, h, dtype=F64)
    with pytest.raises(InputError, match=rf"targets: expected shape \({len(h)}, 3\)"):
        layer(torch.zeros(len(h) + 1, 3, dtype=F64))
    with pytest.raises(InputError, match="dtype torch.float32 does not match"):
        layer(torch.tensor(t, dtype=torch.float32))
    with pytest.raises(InputError, match="expected a torch.Tensor"):
        layer(t)
    bad = torch.tensor(t)
    bad[3, 1] = float("nan")
    with pytest.raises(InputError, match=f"handle 3 \\(vertex {h[3]}\\) target is not finite"):
        layer(bad)
    with pytest.raises(InputError, match="dtype torch.int64 is not supported"):
        ARAPLayer(mesh, h, dtype=torch.int64)
    with pytest.raises(InputError, match="expected positions of shape"):
        arap_energy(torch.zeros(3, 3, dtype=F64), layer)
    if not torch.cuda.is_available():
        for make in (lambda: ARAPLayer(mesh, h, device="cuda"),
                     lambda: Deformer(mesh, h, device="cuda")):
            with pytest.raises(InputError, match="no CUDA device.*CUDA build of torch.*"
                                                 "device='cpu'") as err:
                make()
            assert "\n" not in str(err.value)
        assert Deformer(mesh, h, device="auto").device == "cpu"
    with pytest.raises(InputError, match="only 'cpu' and 'cuda'"):
        ARAPLayer(mesh, h, device="meta")


def test_cpu_rotation_kernel_equals_the_cuda_path():
    """On CPU the forward uses the numba kernel; CUDA runs the batched SVD: same rotations."""
    from arapkit.arap.backends.torch_backend import _svd_rotation, best_rotations

    rng = np.random.default_rng(3)
    S = torch.tensor(rng.standard_normal((500, 3, 3)))
    R_svd = _svd_rotation(S)[0]
    assert torch.allclose(best_rotations(S), R_svd, atol=1e-10)
    assert torch.allclose(best_rotations(S.float()), R_svd.float(), atol=1e-5)
