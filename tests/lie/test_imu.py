"""IMU preintegration on SE₂(3) (docs/imu_preintegration.md): the time shift, the noise Jacobian, Monte-Carlo."""

from __future__ import annotations

import numpy as np

from manopt_lie import SE23, SO3

from .helpers import assert_same, numerical_jacobian

DT = 0.01


def _increment(w: np.ndarray, a: np.ndarray) -> tuple[SE23, np.ndarray]:
    rot = SO3.exp(w * DT)
    u = SE23.from_parts(rot, 0.5 * a * DT**2, a * DT)
    rt = np.swapaxes(rot.as_matrix(), -1, -2)
    g = np.zeros(w.shape[:-1] + (9, 6))
    g[..., 0:3, 3:6] = 0.5 * DT**2 * rt
    g[..., 3:6, 3:6] = DT * rt
    g[..., 6:9, 0:3] = SO3.jr(w * DT) * DT
    return u, g


def _shift(x: SE23) -> SE23:
    return SE23.from_parts(x.rotation(), x.position() + DT * x.velocity(), x.velocity())


_A = np.eye(9)
_A[0:3, 3:6] = DT * np.eye(3)


def test_time_shift_is_an_automorphism_with_tangent_map_A(rng):
    x, y = SE23.random(rng, (10,)), SE23.random(rng, (10,))
    assert_same(_shift(x @ y), _shift(x) @ _shift(y))
    delta = 1e-3 * rng.standard_normal((10, 9))
    assert_same(_shift(x.rplus(delta)), _shift(x).rplus(delta @ _A.T), tol=1e-13)


def test_noise_jacobian_against_finite_differences(rng):
    w, a = rng.standard_normal(3), rng.standard_normal(3)
    _, g = _increment(w, a)
    fd = numerical_jacobian(lambda n: _increment(w + n[..., :3], a + n[..., 3:])[0], [np.zeros(6)], 0)
    np.testing.assert_allclose(g, fd, atol=1e-9)


def test_preintegrated_covariance_against_monte_carlo():
    rng = np.random.default_rng(11)
    n, samples = 80, 3000
    t = DT * np.arange(n)
    omega = np.stack([0.4 * np.sin(2 * t), 0.1 + 0 * t, 0.8 * np.cos(t)], axis=-1)
    accel = np.stack([0.5 + 0 * t, np.sin(t), 9.81 + 0 * t], axis=-1)
    q = np.diag([2e-3**2] * 3 + [2e-2**2] * 3) / DT
    x, p = SE23.identity(), np.zeros((9, 9))
    for k in range(n):
        u, g = _increment(omega[k], accel[k])
        f = u.inverse().adjoint() @ _A
        x, p = _shift(x) @ u, f @ p @ f.T + g @ q @ g.T
    noise = rng.multivariate_normal(np.zeros(6), q, size=(n, samples))
    xs = SE23.identity((samples,))
    for k in range(n):
        xs = _shift(xs) @ _increment(omega[k] + noise[k, :, :3], accel[k] + noise[k, :, 3:])[0]
    d = xs.rminus(x)
    maha = np.einsum("ni,ij,nj->n", d, np.linalg.inv(p), d).mean()
    assert abs(maha - 9) < 5 * np.sqrt(18 / samples)
    sample_cov = d.T @ d / samples
    sd = np.sqrt((np.outer(np.diag(p), np.diag(p)) + p**2) / samples)
    assert (np.abs(sample_cov - p) < 5 * sd).all()
