"""One element against a large batch: the forms that multiply by the single factor once.

``_matrix.product`` turns ``A_n @ B`` (one ``B``) into one BLAS product; ``rminus`` against a
single ``X`` goes through ``Log(X⁻¹Y) = Ad_{X⁻¹} Log(Y X⁻¹)``; one ``X`` moving many points is
``P Rᵀ``; SO(3) ``Log`` of a batch with a few angles beyond ~2π/3 selects Shepperd's column for
those alone. Each must give what the element-by-element computation gives: the same numbers up
to rounding (bit for bit for ``Log``), every branch included.
"""

from __future__ import annotations

import numpy as np
import pytest

from manopt_lie import SO3
from manopt_lie.lie import _matrix, _so3

from .helpers import GROUPS, cases, group_id, tangent

N = 2 * _matrix.ONE_PRODUCT


@pytest.mark.parametrize("d", [2, 3, 4])
def test_product_by_one_right_factor_is_the_batched_product(d, rng):
    a = rng.standard_normal((N, d, d))
    b = rng.standard_normal((d, d))
    expected = np.matmul(a, b)
    for right in (b, np.broadcast_to(b, (N, d, d))):  # alone, or broadcast as blockwise passes it
        out = _matrix.product(a, right)
        assert out.shape == expected.shape
        np.testing.assert_allclose(out, expected, rtol=0, atol=1e-14 * np.abs(expected).max())
    batch = rng.standard_normal((3, N // 3, d, d))  # several batch axes
    np.testing.assert_allclose(_matrix.product(batch, b), np.matmul(batch, b), rtol=0, atol=1e-13)
    few = a[: _matrix.ONE_PRODUCT - 1]  # below the threshold: NumPy's product itself
    np.testing.assert_array_equal(_matrix.product(few, b), np.matmul(few, b))
    both = rng.standard_normal((N, d, d))  # two batches: the batched product
    np.testing.assert_array_equal(_matrix.product(a, both), np.matmul(a, both))


def test_rotating_vectors_by_one_rotation_broadcast_wider_than_the_vectors(rng):
    """A rotation broadcast (zero strides) to more batch axes than the vectors have: the
    product must still broadcast to the rotation's batch, not to the vectors'."""
    r = _so3.exp(rng.standard_normal(3))
    v = rng.standard_normal((N, 3))
    wide = _matrix.rotate_vectors(np.broadcast_to(r, (3, N, 3, 3)), v)
    assert wide.shape == (3, N, 3)
    np.testing.assert_allclose(wide, np.broadcast_to(v @ r.T, (3, N, 3)), rtol=0, atol=1e-14)


@pytest.mark.parametrize("group, regime", cases(GROUPS))
def test_rminus_against_one_element_equals_each_element(group, regime, rng):
    """``Y ⊖ X`` for a batch ``Y`` and one ``X`` (with Jacobians) is the single-element result for
    each ``Yᵢ``, across the sampling regimes (identity, tiny, near π)."""
    y = group.exp(tangent(group, regime, (N,), rng))
    x = group.exp(tangent(group, regime, (), rng))
    tau, j_y, j_x = y.rminus(x, jac=True)
    assert tau.shape == (N, group.dim) and j_y.shape == j_x.shape == (N, group.dim, group.dim)
    for i in range(0, N, 7):
        one = y[i].rminus(x, jac=True)
        scale = max(1.0, np.abs(one[0]).max())
        if regime == "near_pi" and np.linalg.norm(one[0]) > 0:  # at π the two signs are both Logs
            if np.abs(tau[i] + one[0]).max() < np.abs(tau[i] - one[0]).max():
                continue
        np.testing.assert_allclose(tau[i], one[0], rtol=0, atol=1e-13 * scale, err_msg=group_id(group))
        for a, b in ((j_y[i], one[1]), (j_x[i], one[2])):
            np.testing.assert_allclose(a, b, rtol=0, atol=1e-9 * max(1.0, np.abs(b).max()), err_msg=group_id(group))


@pytest.mark.parametrize("group", [g for g in GROUPS if g.point_dim in (2, 3)], ids=group_id)
def test_one_element_acting_on_many_points_equals_each_action(group, rng):
    x = group.exp(tangent(group, "random", (), rng))
    for shape in ((N,), (4, N // 4)):
        p = rng.standard_normal(shape + (group.point_dim,))
        q = x.act(p)
        assert q.shape == p.shape
        flat, pts = q.reshape(-1, group.point_dim), p.reshape(-1, group.point_dim)
        for i in range(0, flat.shape[0], 11):
            np.testing.assert_allclose(flat[i], x.act(pts[i]), rtol=0, atol=1e-13 * max(1.0, np.abs(flat[i]).max()))
    xs = group.exp(tangent(group, "random", (N,), rng))  # many elements, one point: broadcast alike
    p1 = rng.standard_normal(group.point_dim)
    np.testing.assert_allclose(xs.act(p1), np.stack([xs[i].act(p1) for i in range(N)]), rtol=0, atol=1e-12)


def test_so3_log_of_a_mixed_batch_is_each_elements_log_bit_for_bit(rng):
    """Angles spread over [0, π]: most below 2π/3 (column w), some above (columns x, y, z), the
    identity and half-turns about the axes, in one batch and in a batch of two axes."""
    angles = np.concatenate([rng.uniform(0.0, np.pi, 200), [0.0, np.pi, np.pi, np.pi, 3.0, 1e-9]])
    axes = rng.standard_normal((angles.size, 3))
    axes[-5:-2] = np.eye(3)
    axes /= np.linalg.norm(axes, axis=-1, keepdims=True)
    r = _so3.exp(angles[:, None] * axes)
    batch = _so3.log(r)
    for i in range(angles.size):
        np.testing.assert_array_equal(batch[i], _so3.log(r[i]))  # the twin, which equals the kernel
    np.testing.assert_array_equal(_so3.log(r.reshape(2, -1, 3, 3)), batch.reshape(2, -1, 3))
    # The public Log (from_matrix rounds the matrices onto SO(3) first) agrees to rounding.
    np.testing.assert_allclose(SO3.from_matrix(r).log(), batch, rtol=0, atol=1e-14)
    q = _so3.to_quaternion(r)
    assert (q[:, 3] >= 0.0).all()
    np.testing.assert_allclose(np.linalg.norm(q, axis=-1), 1.0, rtol=0, atol=1e-15)
