"""Gaussians on groups: propagation, sampling, tangent-space mean/covariance, frame changes."""

from __future__ import annotations

import numpy as np
import pytest

from manopt_lie import (
    SE3,
    SO3,
    IndefiniteMatrixError,
    ShapeError,
    left_to_right_covariance,
    mean_and_covariance,
    propagate_covariance,
    right_to_left_covariance,
    sample,
)

from .helpers import GROUPS, assert_same, group_id


def _spd(rng, n, scale):
    a = rng.standard_normal((n, n))
    return scale * (a @ a.T / n + 0.1 * np.eye(n))


def test_propagate_covariance_batched(rng):
    j = rng.standard_normal((4, 1, 3, 6))
    p = np.stack([_spd(rng, 6, 1.0) for _ in range(5)])
    out = propagate_covariance(j, p)
    assert out.shape == (4, 5, 3, 3)
    np.testing.assert_allclose(out[2, 3], j[2, 0] @ p[3] @ j[2, 0].T, atol=1e-12)
    with pytest.raises(ShapeError):
        propagate_covariance(j, np.eye(5))
    with pytest.raises(ShapeError):
        propagate_covariance(np.ones(3), np.eye(3))


@pytest.mark.parametrize("group", GROUPS, ids=group_id)
def test_sample_mean_covariance_recover_the_gaussian(group, rng):
    mean = group.random(rng)
    cov = _spd(rng, group.dim, 0.01)
    xs = sample(mean, cov, rng, size=(20000,))
    assert xs.batch_shape == (20000,)
    est_mean, est_cov = mean_and_covariance(xs)
    assert np.abs(est_mean.rminus(mean)).max() < 5 * np.sqrt(cov.diagonal().max() / 20000)
    np.testing.assert_allclose(est_cov, cov, atol=0.05 * np.abs(cov).max())


def test_mean_of_a_batch_along_another_axis(rng):
    means = SO3.random(rng, (3,))
    cov = 1e-3 * np.eye(3)
    xs = sample(means[:, None].broadcast_to((3, 4000)), cov, rng)  # samples along axis 1
    m, p = mean_and_covariance(xs, axis=1)
    assert m.batch_shape == (3,) and p.shape == (3, 3, 3)
    assert m.dist(means).max() < 5e-3
    np.testing.assert_allclose(p, np.broadcast_to(cov, p.shape), atol=2e-4)
    with pytest.raises(ShapeError):
        mean_and_covariance(xs, axis=2)
    with pytest.raises(ValueError):
        mean_and_covariance(xs[:1], ddof=1)


def test_mean_of_exact_points_is_exact():
    """Samples symmetric about X̄ in the tangent space: the mean is X̄ to machine precision."""
    center = SE3.exp([0.3, -0.2, 1.0, 0.4, -1.2, 0.7])
    taus = 0.3 * np.vstack([np.eye(6), -np.eye(6)])
    m, p = mean_and_covariance(center.rplus(taus))
    assert_same(m, center, tol=1e-12)
    np.testing.assert_allclose(p, 0.09 / 6 * np.eye(6), atol=1e-12)


def test_frame_conversion_round_trip_and_meaning(rng):
    """A right-perturbed Gaussian with ``P`` is the left-perturbed one with ``Ad P Adᵀ``."""
    x = SE3.random(rng)
    p_right = _spd(rng, 6, 0.01)
    p_left = right_to_left_covariance(x, p_right)
    np.testing.assert_allclose(left_to_right_covariance(x, p_left), p_right, atol=1e-12)
    tau_left = rng.multivariate_normal(np.zeros(6), p_left, size=20000)
    xs = x.lplus(tau_left)
    # Their right-perturbation covariance about x is the converted one.
    est = np.cov(xs.rminus(x).T, bias=True)
    np.testing.assert_allclose(est, p_right, atol=0.05 * np.abs(p_right).max())


def test_first_order_propagation_through_compose(rng):
    """``Z = X·Y``: cov(Z) ≈ J_X P_X J_Xᵀ + J_Y P_Y J_Yᵀ for small covariances."""
    x, y = SE3.random(rng), SE3.random(rng)
    p_x, p_y = _spd(rng, 6, 1e-5), _spd(rng, 6, 1e-5)
    z, j_x, j_y = x.compose(y, jac=True)
    predicted = propagate_covariance(j_x, p_x) + propagate_covariance(j_y, p_y)
    xs, ys = sample(x, p_x, rng, (40000,)), sample(y, p_y, rng, (40000,))
    empirical = np.cov((xs @ ys).rminus(z).T, bias=True)
    np.testing.assert_allclose(empirical, predicted, atol=0.05 * np.abs(predicted).max())


def test_indefinite_covariance_is_rejected(rng):
    with pytest.raises(IndefiniteMatrixError):
        sample(SO3.identity(), np.diag([1.0, -1.0, 1.0]), rng)
    with pytest.raises(IndefiniteMatrixError):
        sample(SO3.identity(), np.triu(np.ones((3, 3))), rng)
    # Semidefinite is fine: a rotation about z only.
    xs = sample(SO3.identity(), np.diag([0.0, 0.0, 0.1]), rng, (100,))
    np.testing.assert_allclose(xs.log()[:, :2], 0.0, atol=1e-15)
