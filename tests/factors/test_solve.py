"""End to end: poses and landmarks on :class:`Blocks`, 2-D and 3-D, with between, prior,
relative-point, range-bearing (and range, bearing, rotation, pose-range) factors; Gauss-Newton
and Levenberg-Marquardt reach the truth from a perturbed start on noise-free data."""

from __future__ import annotations

import numpy as np
import pytest

from manopt_lie import SE2, SE3, SO2, SO3, Rn
from manopt_lie.check import check_gradient
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
    rotation_factor,
)
from manopt_lie.manifolds import Blocks, Euclidean, LieGroupManifold, Power
from manopt_lie.optim import GaussNewton, LeastSquaresProblem, LevenbergMarquardt

POSES = {2: SE2, 3: SE3}
ROTATIONS = {2: SO2, 3: SO3}


def world(rng: np.random.Generator, d: int, *, rn: bool = False, n: int = 8, landmarks: int = 6, seen: int = 3):
    """A lap of ``n`` poses among ``landmarks`` points, every factor type built from the truth."""
    group = POSES[d]
    k = group.dim
    tau = np.zeros((n, k))
    angle = np.linspace(0, 1.5 * np.pi, n)
    tau[:, 0], tau[:, 1] = 4 * np.cos(angle), 4 * np.sin(angle)
    tau[:, d:] = 0.3 * rng.standard_normal((n, k - d))
    truth = group.exp(tau)
    points = rng.uniform(-5, 5, (landmarks, d))
    pose_of = np.repeat(np.arange(n), seen)
    point_of = np.concatenate([rng.choice(landmarks, seen, replace=False) for _ in range(n)])
    obs = np.c_[pose_of, point_of]
    sensor = group.exp(0.2 * rng.standard_normal(k))  # one shared offset
    p = (truth[pose_of] @ sensor.broadcast_to((len(obs),))).inverse().act(points[point_of])
    bearings = np.arctan2(p[:, 1], p[:, 0]) if d == 2 else 2.0 * p  # un-normalized directions are fine
    odometry = np.c_[np.arange(n - 1), np.arange(1, n)]
    loops = np.array([[0, n - 1], [1, n - 2]])
    omega = np.eye(k) * np.r_[np.full(d, 10.0), np.full(k - d, 100.0)]
    pl = ("poses", "landmarks")
    factors = [
        prior_factor([0], truth[0], Information(omega), name="prior", blocks="poses"),
        between_factor(
            odometry,
            truth[odometry[:, 0]].between(truth[odometry[:, 1]]),
            Information(omega),
            name="odometry",
            blocks="poses",
        ),
        rotation_factor(
            loops,
            truth[loops[:, 0]].rotation().between(truth[loops[:, 1]].rotation()),
            Isotropic(0.05, k - d),
            name="loop rotations",
            blocks="poses",
        ),
        pose_range_factor(
            loops,
            np.linalg.norm(truth[loops[:, 1]].translation() - truth[loops[:, 0]].translation(), axis=1),
            name="loop ranges",
            blocks="poses",
        ),
        relative_point_factor(obs[::2], p[::2], Isotropic(0.1, d), offset=sensor, name="points", blocks=pl),
        range_bearing_factor(
            obs[1::2],
            np.linalg.norm(p[1::2], axis=1),
            bearings[1::2],
            Diagonal([0.1] + [0.01] * (d - 1)),
            offset=sensor,
            name="range-bearing",
            blocks=pl,
        ),
        range_factor(obs, np.linalg.norm(p, axis=1), Isotropic(0.2, 1), offset=sensor, name="ranges", blocks=pl),
        bearing_factor(
            obs, bearings, Isotropic(0.02, d - 1), offset=sensor, name="bearings", blocks=pl, loss="huber:1.0"
        ),
    ]
    point_manifold = LieGroupManifold(Rn(d)) if rn else Euclidean(d)
    manifold = Blocks({"poses": Power(LieGroupManifold(group), n), "landmarks": Power(point_manifold, landmarks)})
    noisy_poses = truth.rplus(np.c_[0.1 * rng.standard_normal((n, d)), 0.05 * rng.standard_normal((n, k - d))])
    noisy_points = points + 0.2 * rng.standard_normal(points.shape)
    x0 = manifold.values(poses=noisy_poses, landmarks=Rn(d)(noisy_points) if rn else noisy_points)
    return manifold, factors, x0, truth, points


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("optimizer", [GaussNewton, LevenbergMarquardt])
@pytest.mark.parametrize("rn", [False, True], ids=["euclidean", "rn"])
def test_reach_the_truth(rng, d, optimizer, rn):
    manifold, factors, x0, truth, points = world(rng, d, rn=rn)
    problem = LeastSquaresProblem(manifold, factors)  # the prior fixes the gauge
    assert problem.cost(x0) > 1.0
    result = optimizer(grad_rtol=1e-12, rel_cost_decrease=0).solve(problem, x0)
    assert result.success and result.fun < 1e-18, (result.message, result.fun)
    found = result.x["landmarks"].data if rn else result.x["landmarks"]
    assert np.abs(found - points).max() < 1e-7
    assert np.abs(result.x["poses"].rminus(truth)).max() < 1e-7


@pytest.mark.parametrize("d", [2, 3])
def test_the_gradient_of_the_whole_problem(rng, d):
    manifold, factors, x0, _, _ = world(rng, d)
    assert check_gradient(LeastSquaresProblem(manifold, factors), x0, rng=rng).passed


def test_a_pose_graph_on_power(rng):
    """Without blocks: a ``Power(SE3, n)`` pose graph of between factors, odometry and loops, one
    pose fixed."""
    n = 10
    truth = SE3.random(rng, (n,))
    edges = np.r_[np.c_[np.arange(n - 1), np.arange(1, n)], [[0, 5], [2, 9], [3, 7]]]
    factor = between_factor(edges, truth[edges[:, 0]].between(truth[edges[:, 1]]), Isotropic(0.1, 6))
    problem = LeastSquaresProblem(Power(LieGroupManifold(SE3), n), [factor], fixed=[0])
    x0 = SE3.concatenate([truth[:1], truth[1:].rplus(0.2 * rng.standard_normal((n - 1, 6)))])
    result = GaussNewton(grad_rtol=1e-12).solve(problem, x0)
    assert result.success and np.abs(result.x.rminus(truth)).max() < 1e-8
