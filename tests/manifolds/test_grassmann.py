"""Grassmann(n, p): subspaces, not bases — retractions, principal angles, exp/log, Hessians,
batches and the derivative checkers."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg
from hypothesis import given
from hypothesis import strategies as st

from manopt_lie import NotOnManifoldError
from manopt_lie.check import check_gradient, check_hessian, check_retraction
from manopt_lie.manifolds import Grassmann, Power
from manopt_lie.optim import ConjugateGradient, Problem, TrustRegion

seeds = given(seed=st.integers(0, 2**32 - 1))
SIZES = [(5, 1), (6, 2), (7, 3), (4, 4)]


def same_subspace(x, y, tol=1e-10):
    return np.abs(x @ x.T - y @ y.T).max() < tol


def test_dimension_and_representation():
    m = Grassmann(7, 3)
    assert m.dim == 12 and m.point_shape == (7, 3) and m.typical_dist == pytest.approx(np.sqrt(3) * np.pi / 2)
    assert Grassmann(4, 4).dim == 0
    assert repr(Grassmann(5, 2, retraction="polar")) == "Grassmann(5, 2, retraction='polar')"
    for bad in (lambda: Grassmann(2, 3), lambda: Grassmann(3, 0), lambda: Grassmann(3, 2, retraction="cayley")):
        with pytest.raises(ValueError):
            bad()
    with pytest.raises(NotOnManifoldError, match="XᵀX = I"):
        m.check_point(np.ones((7, 3)))


@pytest.mark.parametrize(("n", "p"), SIZES)
@seeds
def test_both_retractions_give_the_same_subspace(n, p, seed):
    rng = np.random.default_rng(seed)
    qr, polar = Grassmann(n, p), Grassmann(n, p, retraction="polar")
    x = qr.random_point(rng)
    v = qr.random_tangent(x, rng)
    assert np.abs(x.T @ v).max() < 1e-12  # horizontal
    a, b = qr.retr(x, 0.7 * v), polar.retr(x, 0.7 * v)
    qr.check_point(a)
    polar.check_point(b)
    assert same_subspace(a, b)
    assert qr.dist(a, b) < 1e-7


@pytest.mark.parametrize(("n", "p"), SIZES[:3])
@seeds
def test_principal_angles_agree_with_scipy_and_with_exp(n, p, seed):
    rng = np.random.default_rng(seed)
    m = Grassmann(n, p)
    x, y = m.random_point(rng), m.random_point(rng)
    angles = scipy.linalg.subspace_angles(x, y)
    assert m.dist(x, y) == pytest.approx(np.linalg.norm(angles), rel=1e-9, abs=1e-12)
    # Exp along a tangent of norm below π/2 moves the subspace by exactly that distance, and log undoes it.
    v = 1.2 * m.random_tangent(x, rng)
    z = m.exp(x, v)
    m.check_point(z)
    assert m.dist(x, z) == pytest.approx(1.2, rel=1e-10)
    np.testing.assert_allclose(m.log(x, z), v, atol=1e-10)
    np.testing.assert_allclose(m.log(x, z @ np.linalg.qr(rng.standard_normal((p, p)))[0]), v, atol=1e-10)


def test_distance_keeps_small_and_right_angles_accurate():
    m = Grassmann(3, 1)
    x = np.array([[1.0], [0.0], [0.0]])
    for t in (1e-9, 1e-4, 0.5, np.pi / 2):
        y = np.array([[np.cos(t)], [np.sin(t)], [0.0]])
        assert m.dist(x, y) == pytest.approx(t, rel=1e-12)
        assert m.dist(x, -y) == pytest.approx(t, rel=1e-12)  # −y spans the same line


@pytest.mark.parametrize("retraction", ["qr", "polar"])
def test_retractions_are_second_order_and_costs_are_invariant(rng, retraction):
    """Against ``exp``: slope 3; ``tr(XᵀAX)`` has one value per subspace; the derivative checks pass."""
    m = Grassmann(8, 3, retraction=retraction)
    report = check_retraction(m, rng=0)
    assert report.passed and report.details["second_order"] == 1.0
    b = rng.standard_normal((8, 8))
    a = b + b.T
    problem = Problem(m, lambda x: np.trace(x.T @ a @ x), egrad=lambda x: 2 * a @ x, ehess=lambda x, u: 2 * a @ u)
    x = m.random_point(rng)
    q = np.linalg.qr(rng.standard_normal((3, 3)))[0]
    assert problem.cost(x @ q) == pytest.approx(problem.cost(x), rel=1e-12)
    for seed in range(3):
        assert check_gradient(problem, rng=seed).passed
        assert check_hessian(problem, rng=seed).passed


def test_trust_region_and_cg_find_the_invariant_subspace(rng):
    b = rng.standard_normal((30, 30))
    a = b + b.T
    m = Grassmann(30, 4)
    problem = Problem(m, lambda x: np.trace(x.T @ a @ x), egrad=lambda x: 2 * a @ x, ehess=lambda x, u: 2 * a @ u)
    lam, vec = np.linalg.eigh(a)
    x0 = m.random_point(rng)
    # CG's line search sees cost changes down to round-off, |g|² ≈ eps·|f|·λ: |g| ≈ 3e-7 here.
    for optimizer in (TrustRegion(grad_rtol=1e-10), ConjugateGradient(grad_rtol=1e-7)):
        res = optimizer.solve(problem, x0)
        assert res.success, res
        assert res.fun == pytest.approx(lam[:4].sum(), abs=1e-9)
        assert m.dist(res.x, vec[:, :4]) < 1e-6


def test_a_power_of_grassmannians_is_one_batched_call(rng):
    m = Power(Grassmann(5, 2, retraction="polar"), 6)
    x = m.random_point(rng)
    assert x.shape == (6, 5, 2)
    v = m.random_tangent(x, rng)
    y = m.retr(x, v)
    m.check_point(y)
    base = m.manifold
    for i in range(6):
        np.testing.assert_allclose(y[i], base.retr(x[i], v[i]), atol=1e-14)
        assert m.manifold.dist(x[i], y[i]) == pytest.approx(base.dist(x[i], y[i]), rel=1e-12)
    np.testing.assert_allclose(m.dist(x, y), np.linalg.norm(base.dist(x, y)), rtol=1e-12)
    w = m.transp(x, y, v)
    np.testing.assert_allclose(np.swapaxes(y, -1, -2) @ w, 0.0, atol=1e-12)
