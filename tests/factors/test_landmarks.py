"""Pose–point factors in 2-D and 3-D: relative point (with sensor offsets), range, bearing,
range-bearing, pose–pose range — values, right Jacobians against central differences, angle
wrapping, and the near-degenerate cases."""

from __future__ import annotations

import numpy as np
import pytest

from manopt_lie import SE2, SE3, SO3, Rn
from manopt_lie.errors import ShapeError
from manopt_lie.factors import (
    Diagonal,
    Information,
    Isotropic,
    bearing_factor,
    pose_range_factor,
    range_bearing_factor,
    range_factor,
    relative_point_factor,
)
from manopt_lie.lie import LieGroup

from .helpers import assert_jacobians

POSES = {2: SE2, 3: SE3}
M = 16
EDGES = np.c_[np.arange(M), np.arange(M)]


def scene(rng: np.random.Generator, d: int, offset: str) -> tuple[LieGroup, np.ndarray, LieGroup | None, np.ndarray]:
    """Poses, points at least 0.5 away from their sensors, the offsets, and the points in the sensor frames."""
    group = POSES[d]
    x = group.random(rng, (M,))
    sensor = {"none": None, "per edge": group.random(rng, (M,)), "shared": group.random(rng)}[offset]
    frame = x if sensor is None else x @ sensor.broadcast_to((M,))
    seen = rng.uniform(0.5, 3.0, (M, 1)) * rng.standard_normal((M, d))
    seen = seen / np.linalg.norm(seen, axis=1, keepdims=True) * rng.uniform(0.5, 3.0, (M, 1))
    return x, frame.act(seen), sensor, seen


def bearing_of(p: np.ndarray) -> np.ndarray:
    return np.arctan2(p[:, 1], p[:, 0]) if p.shape[1] == 2 else p / np.linalg.norm(p, axis=1, keepdims=True)


def perturbed_bearing(rng: np.random.Generator, p: np.ndarray, angle: float = 0.3) -> np.ndarray:
    """Measured bearings ``angle``-ish away from the true ones (clear of the wrap and the antipode)."""
    if p.shape[1] == 2:
        return bearing_of(p) + rng.uniform(-angle, angle, len(p))
    return SO3.exp(angle * rng.standard_normal((len(p), 3)) / np.sqrt(3)).act(bearing_of(p))


def angle_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=1), np.einsum("ei,ei->e", a, b))


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("offset", ["none", "per edge", "shared"])
@pytest.mark.parametrize("rn", [False, True], ids=["euclidean", "rn"])
def test_relative_point(rng, d, offset, rn):
    x, points, sensor, seen = scene(rng, d, offset)
    z = seen + 0.1 * rng.standard_normal(seen.shape)
    factor = relative_point_factor(EDGES, z, Information(np.eye(d) * 4.0), offset=sensor)
    landmark = Rn(d)(points) if rn else points
    frame = x if sensor is None else x @ sensor.broadcast_to((M,))
    np.testing.assert_allclose(factor.residual(x, landmark), 2.0 * (frame.inverse().act(points) - z), atol=1e-12)
    assert_jacobians(factor, [x, landmark])


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("offset", ["none", "per edge"])
def test_range(rng, d, offset):
    x, points, sensor, seen = scene(rng, d, offset)
    rho = np.linalg.norm(seen, axis=1) + 0.1 * rng.standard_normal(M)
    factor = range_factor(EDGES, rho, Isotropic(0.5, 1), offset=sensor)
    np.testing.assert_allclose(factor.residual(x, points)[:, 0], 2.0 * (np.linalg.norm(seen, axis=1) - rho))
    assert_jacobians(factor, [x, points])
    if sensor is None:  # turning the sensor does not change the distance
        _, (j_x, _) = factor.residual(x, points, jac=True)
        assert np.abs(j_x[:, :, d:]).max() < 1e-14


@pytest.mark.parametrize("d", [2, 3])
def test_pose_range(rng, d):
    group = POSES[d]
    xi, xj = group.random(rng, (M,)), group.random(rng, (M,))
    rho = np.linalg.norm(xj.translation() - xi.translation(), axis=1) + 0.1
    factor = pose_range_factor(EDGES, rho)
    np.testing.assert_allclose(factor.residual(xi, xj)[:, 0], -0.1, atol=1e-12)
    assert_jacobians(factor, [xi, xj])
    r, (j_i, j_j) = pose_range_factor(EDGES, rho).residual(xi, xi, jac=True)
    np.testing.assert_array_equal(r[:, 0], -rho)  # coincident positions: −ρ, zero derivative
    assert not j_i.any() and not j_j.any()


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("offset", ["none", "per edge"])
def test_bearing(rng, d, offset):
    x, points, sensor, seen = scene(rng, d, offset)
    measured = perturbed_bearing(rng, seen)
    factor = bearing_factor(EDGES, measured, offset=sensor)
    r = factor.residual(x, points)
    if d == 2:
        expected = np.angle(np.exp(1j * (bearing_of(seen) - measured)))
        np.testing.assert_allclose(r[:, 0], expected, atol=1e-12)
    else:  # the norm of the residual is the angle between the directions
        assert r.shape == (M, 2)
        np.testing.assert_allclose(np.linalg.norm(r, axis=1), angle_between(seen, measured), atol=1e-12)
    assert_jacobians(factor, [x, points])


@pytest.mark.parametrize("d", [2, 3])
def test_range_bearing(rng, d):
    x, points, sensor, seen = scene(rng, d, "per edge")
    rho, beta = np.linalg.norm(seen, axis=1) + 0.05, perturbed_bearing(rng, seen)
    sigmas = [0.1] + [0.01] * (d - 1)
    factor = range_bearing_factor(EDGES, rho, beta, Diagonal(sigmas), offset=sensor)
    r = factor.residual(x, points)
    assert r.shape == (M, d)
    np.testing.assert_allclose(r[:, 0], -0.5, atol=1e-12)
    bearing = bearing_factor(EDGES, beta, offset=sensor).residual(x, points)
    np.testing.assert_allclose(r[:, 1:], bearing / 0.01, atol=1e-10)
    assert_jacobians(factor, [x, points])


def test_bearing_3d_close_to_the_measured_direction(rng):
    """Around ``p̂ = z`` (the series branch below 1e-3 rad and the closed form above it)."""
    x, points, _, seen = scene(rng, 3, "none")
    axis = np.cross(seen, rng.standard_normal((M, 3)))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    for angle in (0.5, 1.1e-3, 0.9e-3, 1e-6, 0.0):
        factor = bearing_factor(EDGES, SO3.exp(angle * axis).act(seen))
        np.testing.assert_allclose(np.linalg.norm(factor.residual(x, points), axis=1), angle, atol=1e-14)
        assert_jacobians(factor, [x, points], h=1e-7)


def test_bearing_3d_behind_the_sensor(rng):
    """At and near the antipode of the measured direction: ``‖r‖ = angle → π``, finite; no false minimum."""
    x, points, _, seen = scene(rng, 3, "none")
    axis = np.cross(seen, rng.standard_normal((M, 3)))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    for gap in (0.1, 1e-3, 1e-9, 0.0):
        factor = bearing_factor(EDGES, -SO3.exp(gap * axis).act(seen))
        r, jacobians = factor.residual(x, points, jac=True)
        np.testing.assert_allclose(np.linalg.norm(r, axis=1), np.pi - gap, atol=1e-12)
        assert np.isfinite(r).all() and all(np.isfinite(j).all() for j in jacobians)
        if gap >= 1e-3:
            assert_jacobians(factor, [x, points], h=1e-8)
    # Exactly behind: the direction of r is undefined, r = (π, 0).
    r = bearing_factor([[0, 0]], [[0.0, 0.0, -1.0]]).residual(SE3.identity((1,)), [[0.0, 0.0, 2.0]])
    np.testing.assert_array_equal(r, [[np.pi, 0.0]])


def test_angles_wrap_to_minus_pi_pi(rng):
    x = SE2.identity((4,))
    points = np.array([[-1.0, 0.0], [-1.0, -0.0], [-1.0, 1e-9], [-1.0, -1e-9]])
    r = bearing_factor(np.c_[np.arange(4), np.arange(4)], np.zeros(4)).residual(x, points)[:, 0]
    np.testing.assert_allclose(r, [np.pi, np.pi, np.pi - 1e-9, -np.pi + 1e-9], rtol=0, atol=1e-15)
    assert r[0] == r[1] == np.pi  # π, never −π
    # A measured bearing near −π and a predicted one near +π are 0.2 apart, not 2π − 0.2.
    near = bearing_factor([[0, 0]], [-np.pi + 0.1]).residual(
        SE2.identity((1,)), [[np.cos(np.pi - 0.1), np.sin(np.pi - 0.1)]]
    )
    np.testing.assert_allclose(near, [[-0.2]], atol=1e-12)
    # Random angles: the residual is the wrapped difference, in (−π, π].
    beta = rng.uniform(-20, 20, 200)
    p = rng.standard_normal((200, 2))
    r = bearing_factor(np.zeros((200, 2), dtype=int), beta).residual(SE2.identity((200,)), p)[:, 0]
    np.testing.assert_allclose(np.exp(1j * r), np.exp(1j * (np.arctan2(p[:, 1], p[:, 0]) - beta)), atol=1e-12)
    assert ((r > -np.pi) & (r <= np.pi)).all()


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("offset", ["none", "per edge"])
def test_point_at_the_sensor(rng, d, offset):
    """A point on (or within ``min_range`` of) the sensor: finite residuals, the bearing of the
    sensor's x axis at ``p = 0`` (of ``p`` itself within ``min_range``), zero bearing Jacobians,
    a range of ``−ρ`` with a zero derivative at ``p = 0``; just outside, exact Jacobians."""
    x, _, sensor, seen = scene(rng, d, offset)
    frame = x if sensor is None else x @ sensor.broadcast_to((M,))
    beta, rho = perturbed_bearing(rng, seen), np.full(M, 2.0)
    factors = [bearing_factor(EDGES, beta, offset=sensor), range_bearing_factor(EDGES, rho, beta, offset=sensor),
               range_factor(EDGES, rho, offset=sensor)]  # fmt: skip
    on_sensor = frame.translation().copy()  # p = 0 without an offset, |p| ~ 1e-16 with one
    x_axis = np.eye(d)[:1].repeat(M, axis=0)
    for factor in factors:
        r, jacobians = factor.residual(x, on_sensor, jac=True)
        assert np.isfinite(r).all() and all(np.isfinite(j).all() for j in jacobians)
        ranges = 1 if factor.name != "bearing" else 0  # the range row, first
        assert not any(j[:, ranges:].any() for j in jacobians)  # bearings: zero within min_range
        if sensor is None:  # p = 0 exactly: the range's derivative is zero too
            assert not any(j.any() for j in jacobians)
        if factor.name == "range":
            np.testing.assert_allclose(r[:, 0], -rho, atol=1e-12)
        elif sensor is None:  # p = 0: as if the point were straight ahead
            ahead = bearing_factor(EDGES, beta).residual(x, frame.act(x_axis))
            np.testing.assert_allclose(r[:, -ahead.shape[1] :], ahead, atol=1e-12)
    direction = rng.standard_normal((M, d))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    for distance, zero in ((1e-10, True), (1e-4, False)):
        near = frame.act(distance * direction)
        beta = perturbed_bearing(rng, distance * direction)
        for factor in (
            bearing_factor(EDGES, beta, offset=sensor),
            range_bearing_factor(EDGES, rho, beta, offset=sensor),
        ):
            r, jacobians = factor.residual(x, near, jac=True)
            assert np.isfinite(r).all() and all(np.isfinite(j).all() for j in jacobians)
            if zero:
                bearing_rows = [j[:, -1 if d == 2 else -2 :, :] for j in jacobians]
                assert not any(b.any() for b in bearing_rows)
            else:
                assert_jacobians(factor, [x, near], h=1e-8)
    # A larger min_range switches the bearing Jacobians off further out.
    far = frame.act(0.5 * direction)
    _, jacobians = bearing_factor(EDGES, perturbed_bearing(rng, direction), offset=sensor, min_range=1.0).residual(
        x, far, jac=True
    )
    assert not any(j.any() for j in jacobians)


def test_bad_input(rng):
    x = SE3.random(rng, (M,))
    with pytest.raises(ShapeError, match=r"measured must be points of shape \(m, 2\) or \(m, 3\)"):
        relative_point_factor(EDGES, np.zeros((M, 4)))
    with pytest.raises(ShapeError, match=r"measured points must have shape \(16, 3\)"):
        relative_point_factor(EDGES, np.zeros((M + 1, 3)))
    with pytest.raises(ValueError, match="non-finite ranges at edge 3"):
        range_factor(EDGES, np.r_[np.ones(3), np.nan, np.ones(M - 4)])
    with pytest.raises(ValueError, match="zero bearing direction at edge 2"):
        bearing_factor(EDGES, np.r_[np.ones((2, 3)), np.zeros((1, 3)), np.ones((M - 3, 3))])
    with pytest.raises(ShapeError, match=r"angles \(m,\) or directions \(m, 3\)"):
        bearing_factor(EDGES, np.ones((M, 2)))
    with pytest.raises(ValueError, match="min_range must be finite and non-negative"):
        bearing_factor(EDGES, np.ones(M), min_range=-1.0)
    with pytest.raises(TypeError, match="the offset must be a SE2 element"):
        relative_point_factor(EDGES, np.zeros((M, 2)), offset=SE3.random(rng))
    factor = relative_point_factor(EDGES, np.zeros((M, 3)))
    with pytest.raises(TypeError, match="expected SE3 poses"):
        factor.residual(SE2.random(rng, (M,)), np.zeros((M, 3)))
    with pytest.raises(ShapeError, match=r"expected points of shape \(m, 3\)"):
        factor.residual(x, np.zeros((M, 2)))
    with pytest.raises(TypeError, match="expected points in R"):
        factor.residual(x, x)
    with pytest.raises(TypeError, match="expected SE2 or SE3 poses in the first slot"):
        range_factor(EDGES, np.ones(M)).residual(np.zeros((M, 3)), np.zeros((M, 3)))
