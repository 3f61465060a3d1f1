"""Least squares over variables of several kinds (:class:`Blocks`): poses and landmarks,
solved by every least-squares-capable optimizer to the known optimum."""

from __future__ import annotations

import numpy as np
import pytest

from manopt_lie import SE2, Rn
from manopt_lie.check import check_gradient
from manopt_lie.manifolds import Blocks, Euclidean, LieGroupManifold, Power, Values
from manopt_lie.optim import Factor, GaussNewton, LeastSquaresProblem, LevenbergMarquardt, TrustRegion


def landmark_world(rng: np.random.Generator, n: int = 10, landmarks: int = 6, euclidean: bool = True):
    """A planar chain of poses with odometry and exact relative-point observations of
    landmarks: the truth is a zero-cost optimum."""
    truth = SE2.exp(np.c_[np.arange(n) * 1.0, np.zeros(n), 0.3 * rng.standard_normal(n)])
    points = rng.uniform(-2, 10, (landmarks, 2))
    pose_of, point_of = np.repeat(np.arange(n), 3), rng.integers(0, landmarks, 3 * n)
    r, t = truth[pose_of].rotation().as_matrix(), truth[pose_of].translation()
    seen = np.einsum("eji,ej->ei", r, points[point_of] - t)  # R⁻¹(l − t)
    odometry = np.c_[np.arange(n - 1), np.arange(1, n)]
    z = truth[odometry[:, 0]].between(truth[odometry[:, 1]])

    def between(xi, xj, jac=False):
        y, j_i, j_j = xi.between(xj, jac=True)
        e, j_e, _ = y.rminus(z, jac=True)
        return (e, [j_e @ j_i, j_e @ j_j]) if jac else e

    def relative_point(x, landmark, jac=False):
        landmark = landmark.data if isinstance(landmark, Rn(2)) else landmark
        rot, trans = x.rotation().as_matrix(), x.translation()
        p = np.einsum("eji,ej->ei", rot, landmark - trans)
        if not jac:
            return p - seen
        j_x = np.zeros((len(p), 2, 3))
        j_x[:, :, :2] = -np.eye(2)
        j_x[:, 0, 2], j_x[:, 1, 2] = p[:, 1], -p[:, 0]
        return p - seen, [j_x, np.swapaxes(rot, 1, 2)]

    point_manifold = Euclidean(2) if euclidean else LieGroupManifold(Rn(2))
    manifold = Blocks({"poses": Power(LieGroupManifold(SE2), n), "landmarks": Power(point_manifold, landmarks)})
    factors = [
        Factor(odometry, between, name="odometry", blocks="poses"),
        Factor(np.c_[pose_of, point_of], relative_point, name="observations", blocks=("poses", "landmarks")),
    ]
    noisy_poses = SE2.concatenate([truth[:1], truth[1:].rplus(0.1 * rng.standard_normal((n - 1, 3)))])
    noisy_points = points + 0.3 * rng.standard_normal(points.shape)
    x0 = manifold.values(poses=noisy_poses, landmarks=noisy_points if euclidean else Rn(2)(noisy_points))
    return manifold, factors, x0, truth, points


@pytest.mark.parametrize("optimizer", [GaussNewton, LevenbergMarquardt, TrustRegion])
@pytest.mark.parametrize("euclidean", [True, False])
def test_poses_and_landmarks_reach_the_truth(rng, optimizer, euclidean):
    manifold, factors, x0, truth, points = landmark_world(rng, euclidean=euclidean)
    problem = LeastSquaresProblem(manifold, factors, fixed={"poses": [0]})
    result = optimizer(grad_rtol=1e-10, rel_cost_decrease=0).solve(problem, x0)
    assert result.success and result.fun < 1e-20
    found = result.x["landmarks"]
    found = found if euclidean else found.data
    assert np.abs(found - points).max() < 1e-6
    assert np.abs(result.x["poses"].rminus(truth)).max() < 1e-6
    assert isinstance(result.x, Values) and result.x.names == ("poses", "landmarks")


def test_the_gradient_and_the_layout(rng):
    manifold, factors, x0, _, _ = landmark_world(rng)
    problem = LeastSquaresProblem(manifold, factors)  # nothing fixed: the gradient is the whole derivative
    assert check_gradient(problem, x0, rng=rng).passed
    g = problem.grad(x0)
    assert g.shape == (manifold.size,) == (10 * 3 + 6 * 2,)
    poses, landmarks = manifold.split(g)
    assert poses.shape == (10, 3) and landmarks.shape == (6, 2)
    np.testing.assert_array_equal(manifold.join([poses, landmarks]), g)
    assert problem.dims.tolist() == [3] * 10 + [2] * 6
    fixed = LeastSquaresProblem(manifold, factors, fixed={"landmarks": [1, 2]}).fixed
    assert np.flatnonzero(fixed).tolist() == [11, 12]


def test_values_by_name():
    x = Values(("a", "b"), (np.zeros(2), np.ones(3)))
    assert x["b"] is x[1] and dict(x.items())["a"] is x[0]
    y = x.replace(b=np.full(3, 2.0))
    assert y["b"][0] == 2.0 and x["b"][0] == 1.0
    with pytest.raises(KeyError, match="no block named 'c'"):
        x["c"]


def test_errors_name_the_block(rng):
    manifold, factors, _, _, _ = landmark_world(rng)
    odometry, observations = factors
    with pytest.raises(ValueError, match="say which block"):
        LeastSquaresProblem(manifold, [Factor(odometry.variables, odometry.residual)])
    with pytest.raises(ValueError, match="unknown blocks"):
        LeastSquaresProblem(manifold, [Factor(odometry.variables, odometry.residual, blocks="calibration")])
    far = observations.variables.copy()
    far[4, 1] = 6
    with pytest.raises(ValueError, match=r"outside block .landmarks. 0\.\.5"):
        LeastSquaresProblem(manifold, [Factor(far, observations.residual, blocks=observations.blocks)])
    with pytest.raises(ValueError, match="fixed: unknown block"):
        LeastSquaresProblem(manifold, factors, fixed={"cameras": [0]})
    with pytest.raises(ValueError, match="2 blocks for 1 slots"):
        Factor([0, 1], odometry.residual, blocks=("poses", "poses"))
    with pytest.raises(TypeError, match="vector tangents"):
        Blocks({"x": Power(Euclidean(2, 2), 3)})
