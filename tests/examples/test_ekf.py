"""The error-state EKF on SE(2) and SE(3) with known beacons (the seed notes' "EKF
map-based localization"), against the batch smoother on the same runs.

The robot moves by ``X_k = X_{k−1} ⊕ (u_k + w_k)``, ``w_k ~ N(0, Q)``, from
``X_0 ~ N(X̄_0, P_0)``, and every ``EVERY`` steps measures each beacon ``b`` in its frame,
``z = X⁻¹ b + v``, ``v ~ N(0, σ²I)``. The filter (:class:`~manopt_lie.problems.estimation.
ErrorStateEKF`) runs all Monte-Carlo runs at once, batched; its time loop is sequential.
The smoother is a ``LeastSquaresProblem`` over the poses only — a prior on ``X_0``,
odometry between-factors ``Z_k = Exp(u_k)`` with covariance ``Jr(u_k) Q Jr(u_k)ᵀ`` (the
covariance of ``Log(Z_k⁻¹ X_{k−1}⁻¹ X_k) = Log(Exp(u)⁻¹Exp(u + w)) ≈ Jr(u) w``) and
known-point factors — solved by LM, with marginals for its covariance.

Checked (fixed seeds): the smoother's position and rotation RMSE below the filter's; both
consistent — the filter's NEES against its ``P`` (per step, over runs: within
``χ²(N·n)/N`` at ≥ 98 % of the steps; overall), its NIS (innovations are white, so the
mean over corrections and runs is an exact test), the smoother's per-pose NEES against
its marginals and its joint NEES ``τᵀHτ ~ χ²(#coordinates)``; at the last step the filter
and the smoother estimate the same pose with the same covariance (equal for linear models);
and SE(3), 200 steps, runs in well under a second.
"""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass

import numpy as np
import pytest

from manopt_lie import SE2, SE3
from manopt_lie.factors import Covariance, Isotropic, between_factor, prior_factor
from manopt_lie.lie.calculus import integrate
from manopt_lie.lie.uncertainty import sample
from manopt_lie.manifolds import LieGroupManifold, Power
from manopt_lie.optim import LeastSquaresProblem, LevenbergMarquardt, marginal_covariances
from manopt_lie.problems.estimation import ErrorStateEKF, Motion, chi2_interval, known_point_factor, nees

STEPS, DT, EVERY, RUNS, SIGMA = 200, 0.1, 5, 40, 0.1
GROUPS = {2: SE2, 3: SE3}


@dataclass
class Scenario:
    group: type
    u: np.ndarray  # (STEPS, n) increments
    Q: np.ndarray  # (n, n)
    P0: np.ndarray  # (n, n)
    beacons: np.ndarray  # (B, d)
    seen: np.ndarray  # the steps with beacon measurements


def scenario(d: int) -> Scenario:
    k = np.arange(STEPS)
    if d == 2:  # 1 m/s on a circle of radius 10 m
        u = np.stack([np.full(STEPS, 1.0), 0 * k, np.full(STEPS, 0.1)], axis=1) * DT
        q, p0 = np.diag([0.02, 0.02, 0.005]) ** 2, np.diag([0.05, 0.05, 0.02]) ** 2
        beacons = np.array([[2.0, 1.0], [8.0, 12.0], [-5.0, 10.0], [5.0, 20.0], [-10.0, 5.0]])
    else:  # the same turn, rolling and pitching a little, climbing and sinking
        u = np.stack([np.full(STEPS, 1.0), 0 * k, 0.05 * np.sin(k / 20), 0.02 * np.cos(k / 15),
                      0.02 * np.sin(k / 10), np.full(STEPS, 0.1)], axis=1) * DT  # fmt: skip
        q, p0 = np.diag([0.02] * 3 + [0.005] * 3) ** 2, np.diag([0.05] * 3 + [0.02] * 3) ** 2
        beacons = np.array([[2.0, 1.0, 0.0], [8.0, 12.0, 2.0], [-5.0, 10.0, -1.0], [5.0, 20.0, 1.0], [-10.0, 5.0, 3.0]])
    return Scenario(GROUPS[d], u, q, p0, beacons, np.arange(EVERY, STEPS + 1, EVERY))


def simulate(s: Scenario, rng: np.random.Generator, runs: int):
    """The true trajectories ``(STEPS + 1, runs)`` and the beacons' measurements
    ``(len(seen), runs, B, d)``: all runs at once, integrated over batch axes."""
    g = s.group
    x0 = sample(g.identity(), s.P0, rng, (runs,))
    w = rng.multivariate_normal(np.zeros(g.dim), s.Q, (STEPS, runs))
    truth = integrate(x0, s.u[:, None, :] + w)
    visible = truth[s.seen].inverse().reshape((len(s.seen), runs, 1))
    z = visible.act(s.beacons) + SIGMA * rng.standard_normal((len(s.seen), runs, *s.beacons.shape))
    return truth, z


def ekf(s: Scenario, z: np.ndarray, runs: int | None):
    """The filter over every step (a Python loop over time, batched over runs): the
    estimates ``(STEPS + 1, *runs)``, covariances and the NIS of each correction."""
    motion = Motion.of(s.group, s.u, s.Q)  # every step's F, G Q Gᵀ in one batched call
    f = ErrorStateEKF(s.group.identity(() if runs is None else (runs,)), s.P0)
    xs, ps, nis = [f.x], [f.P], []
    measured = dict(zip(s.seen.tolist(), z, strict=True))
    r = SIGMA**2 * np.eye(s.beacons.shape[1])
    for k in range(STEPS):
        f = f.propagate(motion[k])
        if k + 1 in measured:
            f = f.correct_points(s.beacons, measured[k + 1], r)
            nis.append(f.nis)
        xs.append(f.x)
        ps.append(f.P)
    return s.group.stack(xs), np.stack(ps), np.array(nis)


def smoother(s: Scenario, z: np.ndarray, start):
    """LM over the poses only, from ``start``; the solution, its marginals and ``H``."""
    g, nb = s.group, len(s.beacons)
    jr = g.jr(s.u)
    odometry = np.stack([np.arange(STEPS), np.arange(1, STEPS + 1)], axis=1)
    factors = [
        prior_factor([0], g.identity(), Covariance(s.P0), name="prior"),
        between_factor(odometry, g.exp(s.u), Covariance(jr @ s.Q @ np.swapaxes(jr, 1, 2)), name="odometry"),
        known_point_factor(np.repeat(s.seen, nb), np.tile(s.beacons, (len(s.seen), 1)), z.reshape(-1, g.point_dim),
                           Isotropic(SIGMA, g.point_dim), name="beacons"),
    ]  # fmt: skip
    problem = LeastSquaresProblem(Power(LieGroupManifold(g), STEPS + 1), factors)
    result = LevenbergMarquardt().solve(problem, start)
    assert result.success, result.message
    return result.x, marginal_covariances(problem, result.x).stacked(), problem.linearize(result.x).hessian


def position_rmse(g, truth, estimate) -> float:
    d = g.point_dim
    err = truth.as_matrix()[..., :d, d] - estimate.as_matrix()[..., :d, d]
    return float(np.sqrt(np.mean(np.sum(err**2, axis=-1))))


def rotation_rmse(g, truth, estimate) -> float:
    return float(np.sqrt(np.mean(np.sum(truth.rminus(estimate)[..., g.point_dim :] ** 2, axis=-1))))


@functools.cache
def monte_carlo(d: int) -> dict:
    s = scenario(d)
    truth, z = simulate(s, np.random.default_rng(d), RUNS)
    xs, ps, nis = ekf(s, z, RUNS)
    out = {"scenario": s, "ekf_nees": nees(truth.rminus(xs), ps), "nis": nis}  # (STEPS + 1, RUNS)
    rows = []
    for i in range(RUNS):  # one smoothing problem per run
        x, cov, h = smoother(s, z[:, i], xs[:, i])
        tau = truth[:, i].rminus(x)
        rows.append((
            position_rmse(s.group, truth[:, i], xs[:, i]), position_rmse(s.group, truth[:, i], x),
            rotation_rmse(s.group, truth[:, i], xs[:, i]), rotation_rmse(s.group, truth[:, i], x),
            nees(tau, cov).mean(), float(tau.reshape(-1) @ (h @ tau.reshape(-1))),
            float(nees(x[-1].rminus(xs[-1, i]), ps[-1, i])),
            np.abs(np.linalg.eigvals(np.linalg.solve(ps[-1, i], cov[-1])).real - 1).max(),
        ))  # fmt: skip
    out.update(zip(("ekf_rmse", "smoother_rmse", "ekf_rot", "smoother_rot", "smoother_nees", "smoother_joint",
                    "last_gap", "last_cov"), np.array(rows).T, strict=True))  # fmt: skip
    return out


@pytest.mark.parametrize("d", [2, 3])
def test_the_smoother_beats_the_filter(d):
    mc = monte_carlo(d)
    assert mc["smoother_rmse"].mean() < 0.9 * mc["ekf_rmse"].mean(), (mc["smoother_rmse"].mean(), mc["ekf_rmse"].mean())
    assert mc["smoother_rot"].mean() < 0.9 * mc["ekf_rot"].mean(), (mc["smoother_rot"].mean(), mc["ekf_rot"].mean())


@pytest.mark.parametrize("d", [2, 3])
def test_the_filter_is_consistent(d):
    mc = monte_carlo(d)
    n, e = mc["scenario"].group.dim, mc["ekf_nees"]
    lo, hi = (v / RUNS for v in chi2_interval(RUNS * n))
    per_step = e.mean(axis=1)  # runs are independent: RUNS · mean ~ χ²(RUNS · n) at every step
    assert np.mean((lo < per_step) & (per_step < hi)) >= 0.98, per_step
    assert lo < e.mean() < hi, e.mean()  # steps are correlated: the interval of RUNS samples
    m = mc["nis"].size  # white innovations: every correction of every run independent
    lo, hi = chi2_interval(m * 5 * mc["scenario"].group.point_dim)
    assert lo < mc["nis"].sum() < hi, mc["nis"].mean()


@pytest.mark.parametrize("d", [2, 3])
def test_the_smoother_is_consistent(d):
    mc = monte_carlo(d)
    n = mc["scenario"].group.dim
    lo, hi = (v / RUNS for v in chi2_interval(RUNS * n))
    assert lo < mc["smoother_nees"].mean() < hi, mc["smoother_nees"].mean()
    dim = n * (STEPS + 1)
    lo, hi = (v / RUNS for v in chi2_interval(RUNS * dim))
    assert lo < mc["smoother_joint"].mean() < hi, mc["smoother_joint"].mean() / dim


@pytest.mark.parametrize("d", [2, 3])
def test_filter_and_smoother_agree_at_the_last_step(d):
    mc = monte_carlo(d)
    assert mc["last_gap"].max() < 0.05, mc["last_gap"].max()  # (x_s ⊖ x_f)ᵀ P⁻¹ (x_s ⊖ x_f): ≪ 1
    assert mc["last_cov"].max() < 0.1, mc["last_cov"].max()  # the eigenvalues of P⁻¹ Σ: within 10 % of 1


def test_an_se3_filter_over_200_steps_takes_well_under_a_second():
    s = scenario(3)
    _, z = simulate(s, np.random.default_rng(7), 1)
    start = time.perf_counter()
    xs, ps, _ = ekf(s, z[:, 0], None)
    elapsed = time.perf_counter() - start
    assert xs.batch_shape == (STEPS + 1,) and ps.shape == (STEPS + 1, 6, 6)
    assert elapsed < 0.5, elapsed
