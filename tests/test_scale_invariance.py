"""Units never matter: the same mesh at 1e-150 ... 1e150 deforms to the same shape, scaled.

The solver works in the mesh's own unit (a power of two near its extent, an exact
scaling), cotangents are computed from scale-free corner vectors and handle selection
tolerances are relative, so the iteration count is the same at every scale and the
shape agrees to round-off. Scales whose energy would overflow are refused with a message
about the number range.
"""

from __future__ import annotations

import numpy as np
import pytest

from arapkit import Deformer, Mesh
from arapkit.errors import InputError
from arapkit.mesh.shapes import bar, bar_bend
from arapkit.mesh.weights import edge_weights

SCALES = [
    1e-150, 1e-100, 2.0**-400, 1e-50, 1e-10, 1.0, 1e10, 1e50, 1e100, 1e150, 2.0**-250, 2.0**400,
]


@pytest.fixture(scope="module")
def reference():
    m = bar()
    h, t = bar_bend(m, 90)
    res = Deformer(m, h, rings=2, weights="cotan").solve(t)
    return m, h, t, res


@pytest.mark.parametrize("weights", ["cotan", "cotan-clamped", "uniform"])
@pytest.mark.parametrize("scale", SCALES)
def test_same_shape_and_iterations_at_every_scale(reference, scale, weights):
    m, h, t, _ = reference
    ref = Deformer(m, h, rings=2, weights=weights).solve(t)
    ms = Mesh(m.vertices * scale, m.faces)
    # selection is relative too: the bend's caps are the same vertices at every scale
    hs, ts = bar_bend(ms, 90)
    assert hs.tolist() == h.tolist()
    res = Deformer(ms, hs, rings=2, weights=weights).solve(ts)
    assert res.iterations == ref.iterations
    assert res.converged
    np.testing.assert_allclose(res.vertices / scale, ref.vertices, rtol=0, atol=1e-9)
    assert res.energy / scale**2 == pytest.approx(ref.energy, rel=1e-8)
    assert np.isfinite(res.vertex_energy).all()


@pytest.mark.parametrize("k", [-250, -60, 60, 400])
def test_power_of_two_scales_are_bit_identical(reference, k):
    m, h, t, ref = reference
    s = 2.0**k
    res = Deformer(Mesh(m.vertices * s, m.faces), h, rings=2, weights="cotan").solve(t * s)
    np.testing.assert_array_equal(res.vertices / s, ref.vertices)
    assert res.history == [e * s * s for e in ref.history]


@pytest.mark.parametrize("scale", [1e-150, 1e-100, 1e100, 1e150, 1e200])
def test_cotangent_weights_are_scale_free(scale):
    # cotangents from power-of-two-normalised corner vectors: no overflow, no underflow.
    # (compared on the weights alone, so Mesh's loader threshold does not matter: the
    # mesh is built at scale 1 and its vertices replaced)
    m = bar()
    ref = edge_weights(m, "cotan")
    ms = Mesh(m.vertices, m.faces)
    V = m.vertices * scale
    V.setflags(write=False)
    ms.vertices = V
    np.testing.assert_allclose(edge_weights(ms, "cotan"), ref, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("scale", [1e155, 1e200, 1e300])
def test_too_large_is_refused_by_number_range(scale):
    m = bar()
    h, t = bar_bend(m, 90)
    V = m.vertices * scale
    ms = Mesh(m.vertices, m.faces)  # see above: bypass Mesh's loader threshold
    V.setflags(write=False)
    ms.vertices = V
    with pytest.raises(InputError) as e:
        Deformer(ms, h, rings=2).solve(t * scale)
    msg = str(e.value)
    assert "double precision" in msg and "degenerate" not in msg and "obtuse" not in msg


@pytest.mark.parametrize("scale", [1e-12, 1.0, 1e12])
def test_editor_picking_at_any_scale(scale):
    from arapkit.editor.state import raycast

    V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]) * scale
    hit = raycast(V, np.array([[0, 1, 2]]), np.array([0.2, 0.2, 1.0]) * scale,
                  np.array([0.0, 0, -1]))
    assert hit is not None and hit[0] == 0
    np.testing.assert_allclose(hit[1], np.array([0.2, 0.2, 0]) * scale, atol=1e-12 * scale)
