"""problems.estimation: the error-state EKF's steps (against the Jacobians of the library,
central differences and the linear Kalman filter), the known-point factor, and the
consistency statistics."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from manopt_lie import SE2, SE3, Rn
from manopt_lie.errors import ShapeError
from manopt_lie.factors import Isotropic, prior_factor, relative_point_factor
from manopt_lie.manifolds import LieGroupManifold, Power
from manopt_lie.optim import LeastSquaresProblem
from manopt_lie.problems.estimation import (
    ErrorStateEKF,
    Motion,
    chi2_interval,
    known_point_factor,
    mean_nees_interval,
    nees,
    residual_chi2,
)

GROUPS = [SE2, SE3]


def spd(rng: np.random.Generator, n: int, batch: tuple[int, ...] = ()) -> np.ndarray:
    a = rng.standard_normal(batch + (n, n))
    return a @ np.swapaxes(a, -1, -2) / n + 0.1 * np.eye(n)


@pytest.mark.parametrize("group", GROUPS)
def test_prediction_uses_the_jacobians_of_rplus(group, rng):
    x, p = group.random(rng), spd(rng, group.dim)
    u, q = 0.3 * rng.standard_normal(group.dim), spd(rng, group.dim)
    f = ErrorStateEKF(x, p).predict(u, q)
    _, F, G = x.rplus(u, jac=True)
    assert np.allclose(f.x.as_matrix(), x.rplus(u).as_matrix())
    assert np.allclose(f.P, F @ p @ F.T + G @ q @ G.T)
    assert np.allclose(F, group.exp(u).inverse().adjoint()) and np.allclose(G, group.jr(u))
    assert f.nis is None


@pytest.mark.parametrize("group", GROUPS)
def test_motion_terms_batched_over_steps_equal_step_by_step(group, rng):
    u, q = 0.2 * rng.standard_normal((7, group.dim)), spd(rng, group.dim)
    motion = Motion.of(group, u, q)
    a = b = ErrorStateEKF(group.random(rng), spd(rng, group.dim))
    for k in range(7):
        a, b = a.predict(u[k], q), b.propagate(motion[k])
    assert np.allclose(a.x.as_matrix(), b.x.as_matrix()) and np.allclose(a.P, b.P)


@pytest.mark.parametrize("group", GROUPS)
def test_point_jacobian_against_differences_and_the_factor(group, rng):
    """H of correct_points: ∂(X⁻¹b)/∂X by central differences through X ⊕ δ, and the
    relative-point factor's own Jacobian."""
    d, n = group.point_dim, group.dim
    x, b = group.random(rng), rng.standard_normal((3, d))
    captured = {}

    class Spy(ErrorStateEKF):
        def correct(self, innovation, H, R):
            captured.update(y=innovation, H=H, R=R)
            return super().correct(innovation, H, R)

    z = rng.standard_normal((3, d))
    Spy(x, np.eye(n)).correct_points(b, z, 0.04 * np.eye(d))
    h = lambda X: X.inverse().act(b).reshape(-1)
    eps = 1e-6
    numeric = np.stack([(h(x.rplus(eps * e)) - h(x.rplus(-eps * e))) / (2 * eps) for e in np.eye(n)], axis=1)
    assert np.allclose(captured["H"], numeric, atol=1e-7)
    factor = relative_point_factor(np.c_[np.zeros(3, int), np.arange(3)], z)
    r, (j_x, _) = factor.residual(x.broadcast_to((3,)), b, jac=True)
    assert np.allclose(captured["H"], j_x.reshape(3 * d, n))
    assert np.allclose(captured["y"], -r.reshape(-1))
    assert np.allclose(captured["R"], 0.04 * np.eye(3 * d))


def test_correction_is_the_kalman_filter_on_a_vector_space(rng):
    """On Rⁿ (⊕ is +) the update is the linear one: the information form agrees."""
    group, n, m = Rn(4), 4, 3
    x, p = rng.standard_normal(n), spd(rng, n)
    H, R, z = rng.standard_normal((m, n)), spd(rng, m), rng.standard_normal(m)
    f = ErrorStateEKF(group(x), p).correct(z - H @ x, H, R)
    info = np.linalg.inv(p) + H.T @ np.linalg.solve(R, H)
    post = np.linalg.inv(info)
    mean = post @ (np.linalg.solve(p, x) + H.T @ np.linalg.solve(R, z))
    assert np.allclose(f.P, post) and np.allclose(f.x.data, mean)
    s = H @ p @ H.T + R
    assert np.isclose(f.nis, (z - H @ x) @ np.linalg.solve(s, z - H @ x))


@pytest.mark.parametrize("group", GROUPS)
def test_filters_batched_over_runs_equal_one_by_one(group, rng):
    d, n, N = group.point_dim, group.dim, 4
    x, p = group.random(rng, (N,)), spd(rng, n, (N,))
    b, z = rng.standard_normal((2, d)), rng.standard_normal((N, 2, d))
    u, q = 0.1 * rng.standard_normal((N, n)), spd(rng, n)
    batch = ErrorStateEKF(x, p).predict(u, q).correct_points(b, z, 0.1 * np.eye(d))
    for i in range(N):
        one = ErrorStateEKF(x[i], p[i]).predict(u[i], q).correct_points(b, z[i], 0.1 * np.eye(d))
        assert np.allclose(batch.x[i].as_matrix(), one.x.as_matrix()) and np.allclose(batch.P[i], one.P)
        assert np.isclose(batch.nis[i], one.nis)
    shared = ErrorStateEKF(group.identity(), np.eye(n)).correct_points(b, z, 0.1 * np.eye(d))
    assert shared.x.batch_shape == (N,) and shared.P.shape == (N, n, n)


def test_filter_refuses_bad_shapes(rng):
    with pytest.raises(ShapeError):
        ErrorStateEKF(SE2.identity(), np.eye(4))
    with pytest.raises(TypeError):
        ErrorStateEKF(np.eye(3), np.eye(3))
    f = ErrorStateEKF(SE2.identity(), np.eye(3))
    with pytest.raises(ShapeError):
        f.correct(np.zeros(2), np.zeros((2, 2)), np.eye(2))
    with pytest.raises(ShapeError):
        f.correct_points(np.zeros((2, 3)), np.zeros((2, 3)), np.eye(3))


@pytest.mark.parametrize("group", GROUPS)
def test_known_point_factor_is_the_relative_point_factor_with_the_point_given(group, rng):
    d, m = group.point_dim, 5
    poses, b, z = group.random(rng, (m,)), rng.standard_normal((m, d)), rng.standard_normal((m, d))
    noise = Isotropic(0.2, d)
    known = known_point_factor(np.arange(m), b, z, noise, blocks="poses")
    full = relative_point_factor(np.c_[np.arange(m), np.arange(m)], z, noise)
    r, (j,) = known.residual(poses, jac=True)
    r_full, (j_full, _) = full.residual(poses, b, jac=True)
    assert np.allclose(r, r_full) and np.allclose(j, j_full) and known.blocks == ("poses",)
    assert np.allclose(known.residual(poses), r)
    with pytest.raises(ShapeError):
        known_point_factor(np.arange(m), b[:2], z)


def test_nees_and_intervals(rng):
    e, c = rng.standard_normal((6, 3)), spd(rng, 3, (6,))
    assert np.allclose(nees(e, c), np.einsum("vi,vij,vj->v", e, np.linalg.inv(c), e))
    assert np.allclose(nees(e, c[0]), np.einsum("vi,ij,vj->v", e, np.linalg.inv(c[0]), e))
    with pytest.raises(ShapeError):
        nees(e, np.eye(2))
    lo, hi = chi2_interval(5)
    assert np.isclose(chi2.cdf(lo, 5), 0.001) and np.isclose(chi2.cdf(hi, 5), 0.999)
    lo, hi = mean_nees_interval(3, 40, probability=0.95)
    assert np.isclose(lo, chi2.ppf(0.025, 120) / 40) and np.isclose(hi, chi2.ppf(0.975, 120) / 40)
    with pytest.raises(ValueError):
        chi2_interval(0)


def test_residual_chi2_counts_the_free_coordinates(rng):
    """Two priors on each of 3 SE(2) poses, one held fixed: 18 entries − 6 free coordinates."""
    truth = SE2.random(rng, (3,))
    means = SE2.concatenate([truth.rplus(0.1 * rng.standard_normal((3, 3))) for _ in range(2)])
    factor = prior_factor(np.r_[0:3, 0:3], means, Isotropic(0.1, 3))
    problem = LeastSquaresProblem(Power(LieGroupManifold(SE2), 3), [factor], fixed=[0])
    value, dof = residual_chi2(problem, truth)
    assert dof == 12 and np.isclose(value, 2 * problem.cost(truth))
