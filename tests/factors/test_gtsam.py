"""Optional peer: the factors' errors ``½‖Rr‖²`` equal GTSAM's ``factor.error(values)`` on the
same values (GTSAM's Pose3 tangent is rotation first, ``(ω, v)``: information matrices are
permuted; its bearing-range residual lists the bearing first)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from manopt_lie import SE2, SE3, SO3
from manopt_lie.factors import (
    Diagonal,
    Information,
    Isotropic,
    bearing_factor,
    between_factor,
    pose_range_factor,
    prior_factor,
    range_bearing_factor,
    range_factor,
    relative_point_factor,
)
from manopt_lie.optim import Factor

gtsam = pytest.importorskip("gtsam")
noise_model = gtsam.noiseModel

M = 8
ROTATION_FIRST = np.r_[3, 4, 5, 0, 1, 2]  # (ρ, θ) → GTSAM's (ω, v)


def pose3(x: SE3) -> Any:
    return gtsam.Pose3(np.array(x.as_matrix()))


def pose2(x: SE2) -> Any:
    m = x.as_matrix()
    return gtsam.Pose2(m[0, 2], m[1, 2], np.arctan2(m[1, 0], m[0, 0]))


def errors(factor: Factor, *points: Any) -> np.ndarray:
    r = factor.residual(*points)
    return 0.5 * np.einsum("ei,ei->e", r, r)


def peer_errors(make: Callable[[int], Any], *values: list[Any]) -> np.ndarray:
    out = []
    for e in range(M):
        v = gtsam.Values()
        for key, column in enumerate(values):
            v.insert(key, column[e])
        out.append(make(e).error(v))
    return np.array(out)


def spd(rng: np.random.Generator, k: int) -> np.ndarray:
    a = rng.standard_normal((M, k, k))
    return a @ np.swapaxes(a, 1, 2) + np.eye(k)


def test_between_and_prior_pose3(rng):
    xi, xj, z = SE3.random(rng, (M,)), SE3.random(rng, (M,)), SE3.random(rng, (M,))
    omega = spd(rng, 6)
    permuted = omega[:, ROTATION_FIRST][:, :, ROTATION_FIRST]
    ours = errors(between_factor(np.c_[np.arange(M), np.arange(M)], z, Information(omega)), xi, xj)
    theirs = peer_errors(
        lambda e: gtsam.BetweenFactorPose3(0, 1, pose3(z[e]), noise_model.Gaussian.Information(permuted[e])),
        [pose3(x) for x in xi],
        [pose3(x) for x in xj],
    )
    np.testing.assert_allclose(ours, theirs, rtol=1e-9)
    ours = errors(prior_factor(np.arange(M), z, Information(omega)), xi)
    theirs = peer_errors(
        lambda e: gtsam.PriorFactorPose3(0, pose3(z[e]), noise_model.Gaussian.Information(permuted[e])),
        [pose3(x) for x in xi],
    )
    np.testing.assert_allclose(ours, theirs, rtol=1e-9)


def test_between_pose2(rng):
    xi, xj, z = SE2.random(rng, (M,)), SE2.random(rng, (M,)), SE2.random(rng, (M,))
    omega = spd(rng, 3)  # Pose2's tangent is (x, y, θ), as here
    ours = errors(between_factor(np.c_[np.arange(M), np.arange(M)], z, Information(omega)), xi, xj)
    theirs = peer_errors(
        lambda e: gtsam.BetweenFactorPose2(0, 1, pose2(z[e]), noise_model.Gaussian.Information(omega[e])),
        [pose2(x) for x in xi],
        [pose2(x) for x in xj],
    )
    np.testing.assert_allclose(ours, theirs, rtol=1e-9)


def test_bearing_range_2d(rng):
    x, points = SE2.random(rng, (M,)), 3.0 * rng.standard_normal((M, 2))
    beta, rho = rng.uniform(-np.pi, np.pi, M), rng.uniform(1.0, 3.0, M)
    edges = np.c_[np.arange(M), np.arange(M)]
    poses, landmarks = [pose2(p) for p in x], list(points)
    ours = errors(range_bearing_factor(edges, rho, beta, Diagonal([0.3, 0.05])), x, points)
    theirs = peer_errors(
        lambda e: gtsam.BearingRangeFactor2D(
            0, 1, gtsam.Rot2(beta[e]), rho[e], noise_model.Diagonal.Sigmas([0.05, 0.3])
        ),
        poses,
        landmarks,
    )
    np.testing.assert_allclose(ours, theirs, rtol=1e-9)
    ours = errors(bearing_factor(edges, beta, Isotropic(0.05, 1)), x, points)
    theirs = peer_errors(
        lambda e: gtsam.BearingFactor2D(0, 1, gtsam.Rot2(beta[e]), noise_model.Isotropic.Sigma(1, 0.05)),
        poses,
        landmarks,
    )
    np.testing.assert_allclose(ours, theirs, rtol=1e-9)
    ours = errors(range_factor(edges, rho, Isotropic(0.3, 1)), x, points)
    theirs = peer_errors(
        lambda e: gtsam.RangeFactor2D(0, 1, rho[e], noise_model.Isotropic.Sigma(1, 0.3)), poses, landmarks
    )
    np.testing.assert_allclose(ours, theirs, rtol=1e-9)


def test_bearing_range_3d(rng):
    """The 3-D bearing residuals agree in norm with GTSAM's ``Unit3::localCoordinates`` (the bases
    of the tangent plane differ, which isotropic noise does not see)."""
    x, points = SE3.random(rng, (M,)), 3.0 * rng.standard_normal((M, 3))
    seen = x.inverse().act(points)
    z = SO3.exp(0.5 * rng.standard_normal((M, 3))).act(seen / np.linalg.norm(seen, axis=1, keepdims=True))
    rho = rng.uniform(1.0, 3.0, M)
    edges = np.c_[np.arange(M), np.arange(M)]
    poses, landmarks = [pose3(p) for p in x], list(points)
    ours = errors(range_bearing_factor(edges, rho, z, Diagonal([0.3, 0.05, 0.05])), x, points)
    theirs = peer_errors(
        lambda e: gtsam.BearingRangeFactor3D(
            0, 1, gtsam.Unit3(z[e]), rho[e], noise_model.Diagonal.Sigmas([0.05, 0.05, 0.3])
        ),
        poses,
        landmarks,
    )
    np.testing.assert_allclose(ours, theirs, rtol=1e-8)
    ours = errors(bearing_factor(edges, z, Isotropic(0.05, 2)), x, points)
    theirs = peer_errors(
        lambda e: gtsam.BearingFactor3D(0, 1, gtsam.Unit3(z[e]), noise_model.Isotropic.Sigma(2, 0.05)),
        poses,
        landmarks,
    )
    np.testing.assert_allclose(ours, theirs, rtol=1e-8)


def test_ranges_with_offsets_and_between_poses(rng):
    x, points, sensor = SE3.random(rng, (M,)), 3.0 * rng.standard_normal((M, 3)), SE3.random(rng, (M,))
    rho = rng.uniform(1.0, 3.0, M)
    edges = np.c_[np.arange(M), np.arange(M)]
    ours = errors(range_factor(edges, rho, Isotropic(0.3, 1), offset=sensor), x, points)
    theirs = peer_errors(
        lambda e: gtsam.RangeFactorWithTransform3D(0, 1, rho[e], noise_model.Isotropic.Sigma(1, 0.3), pose3(sensor[e])),
        [pose3(p) for p in x],
        list(points),
    )
    np.testing.assert_allclose(ours, theirs, rtol=1e-9)
    xj = SE3.random(rng, (M,))
    ours = errors(pose_range_factor(edges, rho, Isotropic(0.3, 1)), x, xj)
    theirs = peer_errors(
        lambda e: gtsam.RangeFactorPose3(0, 1, rho[e], noise_model.Isotropic.Sigma(1, 0.3)),
        [pose3(p) for p in x],
        [pose3(p) for p in xj],
    )
    np.testing.assert_allclose(ours, theirs, rtol=1e-9)


def test_relative_point_against_transform_to(rng):
    """GTSAM has no relative-point factor in Python; its ``Pose3.transformTo`` is the prediction."""
    x, points, sensor = SE3.random(rng, (M,)), rng.standard_normal((M, 3)), SE3.random(rng, (M,))
    factor = relative_point_factor(np.c_[np.arange(M), np.arange(M)], np.zeros((M, 3)), offset=sensor)
    predicted = np.array([pose3(x[e]).compose(pose3(sensor[e])).transformTo(points[e]) for e in range(M)])
    np.testing.assert_allclose(factor.residual(x, points), predicted, atol=1e-12)
