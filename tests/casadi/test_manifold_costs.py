"""Symbolic costs on every manifold: closed-form optima, derivative checks (slopes 2 and 3),
agreement with hand-written derivatives, products, powers, least squares and bad input."""

from __future__ import annotations

import shutil

import casadi as ca
import numpy as np
import pytest

from manopt_lie import SO3, Rn, ShapeError
from manopt_lie.casadi import SymbolicTerm, SymSO3, least_squares_from_casadi, problem_from_casadi
from manopt_lie.check import check_gradient, check_hessian
from manopt_lie.manifolds import (
    Euclidean,
    Grassmann,
    LieGroupManifold,
    Power,
    Product,
    SpecialOrthogonal,
    Sphere,
    Stiefel,
)
from manopt_lie.optim import LeastSquaresProblem, LevenbergMarquardt, Problem, Status, TrustRegion


def symmetric(rng, n):
    b = rng.standard_normal((n, n))
    return (b + b.T) / 2


def assert_checks(problem, x=None, seeds=(0, 1)):
    """The Taylor remainders of the gradient and the Hessian have slopes 2 and 3 (or are exact)."""
    for seed in seeds:
        g, h = check_gradient(problem, x, rng=seed), check_hessian(problem, x, rng=seed)
        assert g.passed, g
        assert h.passed, h
        assert np.isnan(g.slope) or g.slope > 1.9
        assert np.isnan(h.slope) or h.slope > 2.9


def solve(problem, x0, **stopping):
    res = TrustRegion(**{"grad_rtol": 1e-10, **stopping}).solve(problem, x0)
    assert res.success, res
    assert res.nhev > 0  # the exact Hessian was used
    return res


# ---- closed-form optima ------------------------------------------------------------------


def test_rayleigh_quotient_on_the_sphere(rng):
    n = 8
    a = symmetric(rng, n)
    problem = problem_from_casadi(Sphere(n), lambda x: ca.mtimes([x.T, a, x]))
    assert "egrad" in repr(problem) and "ehess" in repr(problem)
    assert_checks(problem)
    res = solve(problem, Sphere(n).random_point(rng))
    lam, vec = np.linalg.eigh(a)
    assert res.fun == pytest.approx(lam[0], abs=1e-12)
    assert abs(res.x @ vec[:, 0]) == pytest.approx(1.0, abs=1e-8)


def test_gradient_and_hessian_are_the_hand_written_ones(rng):
    """``egrad = 2Ax`` and ``ehess = 2Au`` exactly, so the Riemannian ones are the manifold's."""
    n = 6
    a = symmetric(rng, n)
    m = Sphere(n)
    problem = problem_from_casadi(m, lambda x: ca.mtimes([x.T, a, x]))
    hand = Problem(m, lambda x: x @ a @ x, egrad=lambda x: 2 * a @ x, ehess=lambda x, u: 2 * a @ u)
    x = m.random_point(rng)
    v = m.random_tangent(x, rng)
    assert problem.cost(x) == pytest.approx(hand.cost(x), rel=1e-14)
    np.testing.assert_allclose(problem.grad(x), hand.grad(x), atol=1e-13)
    np.testing.assert_allclose(problem.hess(x, v), hand.hess(x, v), atol=1e-13)


@pytest.mark.parametrize("retraction", ["qr", "polar"])
def test_brockett_on_the_stiefel_manifold(rng, retraction):
    n, p = 7, 3
    a = symmetric(rng, n)
    big_n = np.diag(np.arange(p, 0, -1.0))
    m = Stiefel(n, p, retraction=retraction)
    problem = problem_from_casadi(m, lambda x: ca.trace(ca.mtimes([x.T, a, x, big_n])))
    if retraction == "polar":  # second order: the model along the retraction is exact to O(t³)
        assert_checks(problem)
    else:
        assert check_gradient(problem, rng=0).passed
    res = solve(problem, m.random_point(rng))
    lam, vec = np.linalg.eigh(a)
    assert res.fun == pytest.approx(np.sum(lam[:p] * np.diag(big_n)), abs=1e-10)
    np.testing.assert_allclose(np.abs(np.sum(res.x * vec[:, :p], axis=0)), 1.0, atol=1e-6)  # ordered eigenvectors


@pytest.mark.parametrize("retraction", ["qr", "polar"])
def test_trace_on_the_grassmannian_is_the_sum_of_the_smallest_eigenvalues(rng, retraction):
    n, p = 9, 3
    a = symmetric(rng, n)
    m = Grassmann(n, p, retraction=retraction)
    problem = problem_from_casadi(m, lambda x: ca.trace(ca.mtimes([x.T, a, x])))
    assert_checks(problem)  # an invariant cost: both retractions are second order for it
    res = solve(problem, m.random_point(rng))
    lam, vec = np.linalg.eigh(a)
    assert res.fun == pytest.approx(lam[:p].sum(), abs=1e-10)
    assert m.dist(res.x, vec[:, :p]) < 1e-7  # the invariant subspace, whatever its basis


@pytest.mark.parametrize("n", [2, 3, 4])
def test_procrustes_on_special_orthogonal_is_the_svd_solution(rng, n):
    """``min ‖RA − B‖_F²`` over SO(n): ``R = U diag(1, …, 1, det(UVᵀ)) Vᵀ`` for ``BAᵀ = U S Vᵀ``."""
    a = rng.standard_normal((n, 10))
    b = SpecialOrthogonal(n).random_point(rng) @ a + 0.1 * rng.standard_normal((n, 10))
    m = SpecialOrthogonal(n)
    problem = problem_from_casadi(m, lambda r: ca.sumsqr(ca.mtimes(r, a) - b))
    assert_checks(problem)
    res = solve(problem, m.random_point(rng))
    u, _, vt = np.linalg.svd(b @ a.T)
    d = np.ones(n)
    d[-1] = np.sign(np.linalg.det(u @ vt))
    best = u @ np.diag(d) @ vt
    np.testing.assert_allclose(res.x, best, atol=1e-8)
    assert res.fun == pytest.approx(np.sum((best @ a - b) ** 2), rel=1e-12)


def test_euclidean_vectors_and_matrices(rng):
    q = symmetric(rng, 4) + 5 * np.eye(4)
    b = rng.standard_normal(4)
    vec = problem_from_casadi(Euclidean(4), lambda x: 0.5 * ca.mtimes([x.T, q, x]) - ca.dot(b, x))
    assert_checks(vec)
    np.testing.assert_allclose(solve(vec, np.zeros(4)).x, np.linalg.solve(q, b), atol=1e-10)
    a, c = rng.standard_normal((6, 3)), rng.standard_normal((6, 2))
    mat = problem_from_casadi(Euclidean(3, 2), lambda x: ca.sumsqr(ca.mtimes(a, x) - c))
    assert_checks(mat)
    np.testing.assert_allclose(solve(mat, np.zeros((3, 2))).x, np.linalg.lstsq(a, c, rcond=None)[0], atol=1e-9)


def test_rn_group_points_are_columns(rng):
    m = LieGroupManifold(Rn(3))
    problem = problem_from_casadi(m, lambda x: ca.sumsqr(x - np.array([1.0, 2.0, 3.0])) + ca.sumsqr(x) ** 2 / 100)
    assert_checks(problem)
    res = solve(problem, Rn(3).identity())
    assert isinstance(res.x, Rn(3)) and problem.grad(res.x).shape == (3,)


def test_a_product_gets_one_argument_per_factor(rng):
    """``f(x, R, t) = xᵀAx + ½‖Log(R̃ᵀR)‖² + ‖t − c‖² + coupling`` with a known optimum, and a
    coupled cost whose Hessian has cross terms between the factors."""
    a = symmetric(rng, 3)
    target, c = SO3.random(rng), rng.standard_normal(2)
    m = Product(Sphere(3), LieGroupManifold(SO3), Euclidean(2))
    z = target.as_matrix()

    def cost(x, r, t):
        return ca.mtimes([x.T, a, x]) + 0.5 * ca.sumsqr(SymSO3.rminus(r, z)) + ca.sumsqr(t - c)

    problem = problem_from_casadi(m, cost)
    x0 = (Sphere(3).random_point(rng), target.rplus(0.3 * rng.standard_normal(3)), np.zeros(2))
    assert_checks(problem, x0)
    res = solve(problem, x0)
    assert res.fun == pytest.approx(np.linalg.eigvalsh(a)[0], abs=1e-10)
    assert res.x[1].dist(target) < 1e-8
    np.testing.assert_allclose(res.x[2], c, atol=1e-10)
    v = rng.standard_normal(3)
    coupled = problem_from_casadi(
        Product(Sphere(3), Euclidean(1)), lambda x, s: ca.sumsqr(s * x - v)
    )  # optimum s·x = v: f = 0 at s = ±|v|
    assert_checks(coupled, (np.ones(3) / np.sqrt(3), np.array([0.5])))
    res = solve(coupled, (np.ones(3) / np.sqrt(3), np.array([0.5])))
    assert res.fun < 1e-18 and abs(res.x[1][0]) == pytest.approx(np.linalg.norm(v))


def test_power_of_spheres_per_point_and_over_edges(rng):
    """Per point (the mapped path, with data rows), and over pairs of points (edges)."""
    k = 50
    a = rng.standard_normal((k, 3))
    m = Power(Sphere(3), k)
    per_point = problem_from_casadi(m, lambda x, ai: ca.dot(x, ai), data=(a,))
    x0 = m.random_point(rng)
    assert per_point.cost(x0) == pytest.approx(np.sum(x0 * a), rel=1e-13)
    np.testing.assert_allclose(per_point.grad(x0), a - np.sum(a * x0, axis=1, keepdims=True) * x0, atol=1e-13)
    res = solve(per_point, x0)
    assert res.fun == pytest.approx(-np.linalg.norm(a, axis=1).sum(), rel=1e-12)
    edges = np.c_[np.arange(k - 1), np.arange(1, k)]
    chain = problem_from_casadi(m, [SymbolicTerm(edges, lambda x, y: -ca.dot(x, y), name="align")])
    assert_checks(chain, x0)
    res = solve(chain, x0)
    assert res.fun == pytest.approx(-(k - 1), abs=1e-9)  # all points equal


def test_a_function_of_all_points_at_once_agrees_with_the_edges(rng):
    k = 5
    m = Power(Sphere(3), k)
    edges = np.c_[np.arange(k - 1), np.arange(1, k)]
    term = lambda x, y: ca.sumsqr(x - y) ** 2
    by_edges = problem_from_casadi(m, term, variables=edges)
    whole = problem_from_casadi(m, lambda *xs: sum(term(xs[i], xs[j]) for i, j in edges), variables=[range(k)])
    x = m.random_point(rng)
    v = m.random_tangent(x, rng)
    assert by_edges.cost(x) == pytest.approx(whole.cost(x), rel=1e-13)
    np.testing.assert_allclose(by_edges.grad(x), whole.grad(x), atol=1e-12)
    np.testing.assert_allclose(by_edges.hess(x, v), whole.hess(x, v), atol=1e-12)


@pytest.mark.parametrize("symbols", ["SX", "MX"])
def test_scalar_and_matrix_symbols_agree(rng, symbols):
    n, p = 60, 2  # 120 entries: above the automatic switch to MX
    a = symmetric(rng, n)
    m = Stiefel(n, p)
    problem = problem_from_casadi(m, lambda x: ca.trace(ca.mtimes([x.T, a, x])), symbols=symbols)
    x = m.random_point(rng)
    v = m.random_tangent(x, rng)
    np.testing.assert_allclose(problem.grad(x), m.proj(x, 2 * a @ x), atol=1e-11)
    np.testing.assert_allclose(problem.hess(x, v), m.ehess2rhess(x, 2 * a @ x, 2 * a @ v, v), atol=1e-11)
    with pytest.raises(ValueError, match="symbols"):
        problem_from_casadi(m, lambda x: ca.trace(x), symbols="XX")


@pytest.mark.skipif(shutil.which("gcc") is None, reason="jit=True compiles with gcc")
def test_jit_on_an_embedded_manifold(rng):
    a = symmetric(rng, 4)
    plain = problem_from_casadi(Sphere(4), lambda x: ca.mtimes([x.T, a, x]))
    jitted = problem_from_casadi(Sphere(4), lambda x: ca.mtimes([x.T, a, x]), jit=True)
    x = Sphere(4).random_point(rng)
    np.testing.assert_allclose(jitted.grad(x), plain.grad(x), atol=1e-14)


# ---- least squares on Euclidean points ---------------------------------------------------


def test_least_squares_on_euclidean_points(rng):
    """Rosenbrock as residuals on ``Power(Euclidean(2), 1)``: the Jacobian is the hand-written
    one, LM finds (1, 1); a data fit over many points is one mapped call."""

    def rosenbrock(p):
        return ca.vertcat(10 * (p[1] - p[0] ** 2), 1 - p[0])

    m = Power(Euclidean(2), 1)
    problem = least_squares_from_casadi(m, [0], rosenbrock, exact_hessian=True)
    assert isinstance(problem, LeastSquaresProblem)
    x0 = np.array([[-1.2, 1.0]])
    lin = problem.linearize(x0)
    j = np.array([[-20 * -1.2, 10.0], [-1.0, 0.0]])
    r = np.array([10 * (1.0 - 1.44), 2.2])
    np.testing.assert_allclose(lin.grad, (j.T @ r)[None], atol=1e-12)
    assert check_hessian(problem, x0, rng=0).passed
    res = LevenbergMarquardt(grad_rtol=1e-12, rel_cost_decrease=0).solve(problem, x0)
    assert res.status is Status.GRADIENT_NORM
    np.testing.assert_allclose(res.x, [[1.0, 1.0]], atol=1e-8)
    points = rng.standard_normal((40, 2))
    fit = least_squares_from_casadi(Power(Euclidean(2), 40), np.arange(40), lambda x, q: x - q, data=(points,))
    res = LevenbergMarquardt().solve(fit, np.zeros((40, 2)))  # one (lightly damped) step: |grad| 10⁶ smaller
    assert res.success and res.nit == 1 and res.fun < 1e-9


# ---- bad input ----------------------------------------------------------------------------


def test_bad_costs_and_points_on_embedded_manifolds(rng):
    sphere = problem_from_casadi(Sphere(3), lambda x: ca.sumsqr(x))
    with pytest.raises(ShapeError, match=r"expected an array of shape \(3,\)"):
        sphere.cost(np.ones(4))
    with pytest.raises(ValueError, match="scalar"):
        problem_from_casadi(Sphere(3), lambda x: x)
    with pytest.raises(ValueError, match="no variables"):
        problem_from_casadi(Product(Sphere(3), Euclidean(1)), lambda x, s: s, variables=[[0]])
    with pytest.raises(TypeError, match="one cost function of all factors"):
        problem_from_casadi(Product(Sphere(3), Euclidean(1)), [SymbolicTerm([0], lambda x: 1.0)])
    with pytest.raises(TypeError, match="MX expression"):
        problem_from_casadi(Sphere(3), lambda x: ca.MX.sym("y") * 0 + 1.0 + 0 * ca.MX(1))
    prod = problem_from_casadi(Product(Sphere(3), Euclidean(1)), lambda x, s: ca.sumsqr(s * x))
    with pytest.raises(ShapeError, match="tuple of 2 parts"):
        prod.cost(np.ones(3))
