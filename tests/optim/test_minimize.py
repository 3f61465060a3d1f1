"""``manopt_lie.minimize``: symbolic costs on any manifold, every method of the registry,
least squares from residuals, numeric costs with derivatives, options, callbacks, errors."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

import manopt_lie
from manopt_lie import SE2, SO3, minimize
from manopt_lie.casadi import SymSE2, SymSO3
from manopt_lie.manifolds import Euclidean, Grassmann, LieGroupManifold, Power, Sphere
from manopt_lie.optim import OPTIMIZERS, LeastSquaresProblem, Problem, Status, StoppingCriteria, UnknownOptimizerError

A = np.diag([3.0, 1.0, 2.0])
X0 = np.ones(3) / np.sqrt(3)


def rayleigh(x):
    return ca.mtimes([x.T, A, x])


def rosenbrock(p):
    return ca.vertcat(10 * (p[1] - p[0] ** 2), 1 - p[0])


def test_the_public_spelling():
    assert manopt_lie.minimize is minimize and "minimize" in manopt_lie.__all__


@pytest.mark.parametrize("method", ["tr", "cg", "gd"])
def test_every_smooth_method_on_a_symbolic_cost(method):
    res = minimize(rayleigh, X0, manifold=Sphere(3), method=method)
    assert res.success and res.fun == pytest.approx(1.0, abs=1e-10)
    assert abs(res.x[1]) == pytest.approx(1.0, abs=1e-5)
    assert (res.nhev > 0) is (method == "tr")  # the exact Hessian, from CasADi


@pytest.mark.parametrize("method", ["lm", "gn", "tr", "cg"])
def test_least_squares_from_a_residual(method):
    res = minimize(None, np.array([-1.2, 1.0]), residual=rosenbrock, method=method, options={"max_iterations": 5000})
    assert res.success, res
    np.testing.assert_allclose(res.x, [1.0, 1.0], atol=2e-3)
    assert res.x.shape == (2,)  # the single point, not a Power of one


def test_every_registered_method_runs():
    for name, entry in OPTIMIZERS.items():
        if entry.accepts is LeastSquaresProblem:
            res = minimize(None, np.array([-1.2, 1.0]), residual=rosenbrock, method=name)
        else:
            res = minimize(rayleigh, X0, manifold=Sphere(3), method=name)
        assert res.success, (name, res)


def test_least_squares_defaults_to_lm_and_its_cost_decrease_rule():
    res = minimize(None, np.array([-1.2, 1.0]), residual=rosenbrock)
    assert res.success
    # GTSAM's 1e-5 rule, on by default here (without a gradient test, which LM may meet first).
    res = minimize(None, np.array([-1.2, 1.0]), residual=rosenbrock, options={"grad_rtol": 0, "grad_atol": 0})
    assert res.success and res.status is Status.COST_DECREASE
    options = {"rel_cost_decrease": 0, "grad_rtol": 1e-12}
    tight = minimize(None, np.array([-1.2, 1.0]), residual=rosenbrock, options=options)
    assert tight.status is Status.GRADIENT_NORM
    np.testing.assert_allclose(tight.x, [1.0, 1.0], atol=1e-8)


def test_least_squares_on_a_lie_group_and_a_given_problem(rng):
    truth = SE2.exp([1.0, -0.5, 0.7])
    landmarks = rng.uniform(-5.0, 5.0, (6, 2))
    local = truth.inverse().act(landmarks)

    def residual(x):  # all landmarks, in the robot frame
        return ca.vertcat(
            *[SymSE2.act(SymSE2.inverse(x), ca.DM(p)) - ca.DM(q) for p, q in zip(landmarks, local, strict=True)]
        )

    res = minimize(None, SE2.identity(), residual=residual, options={"rel_cost_decrease": 0})
    assert res.success and isinstance(res.x, SE2) and res.x.batch_shape == () and truth.dist(res.x) < 1e-6
    from manopt_lie.casadi import least_squares_from_casadi

    problem = least_squares_from_casadi(Power(LieGroupManifold(SE2), 1), [0], residual)
    res = minimize(problem, SE2.identity((1,)), method="gn")
    assert res.success and truth.dist(res.x[0]) < 1e-6


def test_manifolds_inferred_from_x0():
    res = minimize(lambda x: ca.sumsqr(x - 2.0), np.zeros(3))  # Euclidean(3)
    np.testing.assert_allclose(res.x, 2.0, atol=1e-10)
    target = SO3.exp([0.1, 0.2, 0.3])
    res = minimize(lambda r: ca.sumsqr(SymSO3.rminus(r, target.as_matrix())), SO3.identity())
    assert res.success and res.x.dist(target) < 1e-8
    batch = SO3.identity((4,))
    res = minimize(lambda r: ca.sumsqr(SymSO3.rminus(r, target.as_matrix())), batch)  # Power(SO3, 4), per element
    assert res.success and target.dist(res.x).max() < 1e-8
    with pytest.raises(TypeError, match="give manifold="):
        minimize(lambda x: x, (np.zeros(3), np.zeros(2)))


def test_a_numeric_cost_with_derivatives_and_a_grassmannian(rng):
    res = minimize(lambda x: x @ A @ x, X0, manifold=Sphere(3), egrad=lambda x: 2 * A @ x)
    assert res.success and res.fun == pytest.approx(1.0)
    b = rng.standard_normal((8, 8))
    s = b + b.T
    res = minimize(
        lambda x: ca.trace(ca.mtimes([x.T, s, x])), Grassmann(8, 2).random_point(rng), manifold=Grassmann(8, 2)
    )
    assert res.fun == pytest.approx(np.linalg.eigvalsh(s)[:2].sum(), abs=1e-9)


def test_options_callback_and_verbosity(capsys):
    res = minimize(rayleigh, X0, manifold=Sphere(3), method="cg", options={"max_iterations": 2})
    assert res.status is Status.MAX_ITERATIONS and res.nit == 2
    res = minimize(rayleigh, X0, manifold=Sphere(3), options={"stopping": StoppingCriteria(grad_rtol=1e-12)})
    assert res.grad_norm <= 1e-12 * res.history.grad_norm[0]
    res = minimize(rayleigh, X0, manifold=Sphere(3), callback=lambda info: info.iteration == 1)
    assert res.status is Status.CALLBACK and res.nit == 1

    def stop(info):
        raise StopIteration

    assert minimize(rayleigh, X0, manifold=Sphere(3), callback=stop).status is Status.CALLBACK
    capsys.readouterr()
    res = minimize(rayleigh, X0, manifold=Sphere(3), verbosity=2)
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith("Optimizing") and len(err) == res.nit + 4


def test_clear_errors():
    with pytest.raises(ValueError, match=r"'lm' .* needs a LeastSquaresProblem: pass residual="):
        minimize(rayleigh, X0, manifold=Sphere(3), method="lm")
    with pytest.raises(UnknownOptimizerError, match="choose from gd, cg, gn, lm, tr"):
        minimize(rayleigh, X0, manifold=Sphere(3), method="bfgs")
    with pytest.raises(TypeError, match=r"not symbolic: .* AttributeError: 'SX' object has no attribute 'as_matrix'"):
        minimize(lambda r: float(np.trace(r.as_matrix())), SO3.identity())
    with pytest.raises(TypeError, match=r"unknown option 'maxiter'.*'maxiter' is max_iterations here"):
        minimize(rayleigh, X0, manifold=Sphere(3), options={"maxiter": 3})
    with pytest.raises(TypeError, match="verbosity= as an argument"):
        minimize(rayleigh, X0, manifold=Sphere(3), options={"verbosity": 1})
    with pytest.raises(TypeError, match="cost=None"):
        minimize(rayleigh, X0, residual=rosenbrock)
    with pytest.raises(TypeError, match="Problem already"):
        minimize(Problem(Sphere(3), lambda x: 0.0, egrad=lambda x: 0 * x), X0, egrad=lambda x: x)
    with pytest.raises(TypeError, match="pass the derivatives"):
        minimize(rayleigh, (X0,), manifold=Power(Power(Sphere(3), 2), 2))
    with pytest.raises(TypeError, match="tangent coordinates"):
        minimize(None, X0, manifold=Sphere(3), residual=lambda x: x)
    with pytest.raises(ValueError, match="scalar"):
        minimize(lambda x: x, np.zeros(3), manifold=Euclidean(3))
