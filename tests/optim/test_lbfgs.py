"""Riemannian L-BFGS: known optima on the sphere, the Stiefel manifold, SO(3) and Rⁿ, its
registry entry, and the reliability battery every optimizer passes (no false success, non-finite
values, interrupts, threads)."""

from __future__ import annotations

import math
import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from manopt_lie import SO3
from manopt_lie.manifolds import Euclidean, LieGroupManifold, Power, Product, ProductVector, Sphere
from manopt_lie.optim import (
    LBFGS,
    OPTIMIZERS,
    Backtracking,
    ConjugateGradient,
    Problem,
    Status,
    StrongWolfe,
    get_optimizer,
)

from .test_smooth_optimizers import brockett, karcher, rayleigh

SEARCHES = {"wolfe": {}, "armijo": {"line_search": "armijo"}}
searches = pytest.mark.parametrize("settings", SEARCHES.values(), ids=SEARCHES.keys())


def rosenbrock(a=1.0, b=100.0):
    """``(a − x)² + b(y − x²)²`` on R²: the minimum 0 at ``(a, a²)``, down a curved valley."""

    def cost(p):
        return (a - p[0]) ** 2 + b * (p[1] - p[0] ** 2) ** 2

    def egrad(p):
        return np.array([-2 * (a - p[0]) - 4 * b * p[0] * (p[1] - p[0] ** 2), 2 * b * (p[1] - p[0] ** 2)])

    return Problem(Euclidean(2), cost=cost, egrad=egrad)


# ---- known optima -----------------------------------------------------------------------


@searches
def test_rayleigh_quotient_reaches_the_smallest_eigenvalue(settings):
    problem, lam, v = rayleigh(n=50)
    res = LBFGS(**settings).solve(problem, problem.manifold.random_point(1))
    assert res.status is Status.GRADIENT_NORM and res.success, res
    assert res.grad_norm <= 1e-6 * res.history.grad_norm[0]
    assert res.fun == pytest.approx(lam, abs=1e-9)
    assert abs(res.x @ v) == pytest.approx(1.0, abs=1e-6)


@searches
def test_brockett_cost_reaches_the_eigenvector_optimum(settings):
    problem, optimum = brockett(n=20, p=4, seed=1)
    res = LBFGS(max_iterations=5000, **settings).solve(problem, problem.manifold.random_point(3))
    assert res.success, res
    assert res.fun == pytest.approx(optimum, rel=1e-9)


@searches
def test_karcher_mean_on_so3_is_recovered(settings):
    problem, mean = karcher()
    res = LBFGS(**settings).solve(problem, SO3.identity())
    assert res.success, res
    assert res.x.dist(mean) < 1e-6


@searches
def test_rosenbrock_valley_on_euclidean_space(settings):
    res = LBFGS(grad_rtol=1e-10, max_iterations=500, **settings).solve(rosenbrock(), np.array([-1.2, 1.0]))
    assert res.success, res
    np.testing.assert_allclose(res.x, [1.0, 1.0], atol=1e-6)
    assert res.fun < 1e-12
    assert res.nit < 60  # quasi-Newton: a steepest descent needs thousands here


def test_independent_karcher_costs_on_a_power_of_so3():
    manifold = Power(LieGroupManifold(SO3), 200)
    target = manifold.random_point(0)
    problem = Problem(
        manifold, cost=lambda r: 0.5 * np.sum(target.rminus(r) ** 2), rgrad=lambda r: -target.rminus(r)
    )  # ∂/∂τ ½|T ⊖ R Exp(τ)|² at 0 is −Jr⁻ᵀ(r) r = −r
    start = target.rplus(0.3 * np.random.default_rng(1).standard_normal((200, 3)))
    res = LBFGS().solve(problem, start)
    assert res.success and target.dist(res.x).max() < 1e-6


def test_a_product_manifold_with_product_vectors():
    """``xᵀAx + ‖y − c‖²`` on S² × R²: the two optima at once."""
    a = np.diag([3.0, 1.0, 2.0])
    c = np.array([0.5, -2.0])
    manifold = Product(Sphere(3), Euclidean(2))
    problem = Problem(
        manifold, cost=lambda x: x[0] @ a @ x[0] + np.sum((x[1] - c) ** 2),
        egrad=lambda x: (2 * a @ x[0], 2 * (x[1] - c)),
    )  # fmt: skip
    res = LBFGS().solve(problem, (np.ones(3) / np.sqrt(3), np.zeros(2)))
    assert res.success and res.fun == pytest.approx(1.0, abs=1e-10)
    np.testing.assert_allclose(res.x[1], c, atol=1e-6)
    assert isinstance(problem.grad(res.x), ProductVector)


# ---- L-BFGS against CG, and its own mechanics ---------------------------------------------


def test_fewer_evaluations_than_conjugate_gradients_on_the_rayleigh_quotient():
    problem, lam, _ = rayleigh(n=200, seed=3)
    x0 = problem.manifold.random_point(0)
    quasi_newton = LBFGS().solve(problem, x0)
    cg = ConjugateGradient().solve(problem, x0)
    assert quasi_newton.success and cg.success
    assert quasi_newton.fun == pytest.approx(lam, abs=1e-9)
    assert quasi_newton.nfev + quasi_newton.ngev < cg.nfev + cg.ngev


def test_the_memory_is_bounded_and_the_descent_monotone():
    problem, _, _ = rayleigh(n=60, seed=2)
    res = LBFGS(memory=3).solve(problem, problem.manifold.random_point(2))
    memory = res.history.extra["memory"]
    assert res.success and np.nanmax(memory) == 3 and np.isnan(memory[0])
    assert np.all(np.diff(res.history.cost) <= 0)
    assert np.all(res.history.extra["evaluations"][1:] >= 1)


def test_each_gradient_is_evaluated_once_with_the_wolfe_search():
    problem, _, _ = rayleigh(n=40)
    res = LBFGS().solve(problem, problem.manifold.random_point(1))
    assert res.success
    assert res.ngev <= res.nfev + 1  # the search's gradient at the accepted point is reused, never recomputed


def test_a_zero_cautious_constant_and_a_line_search_instance():
    problem, lam, _ = rayleigh(n=30)
    x0 = problem.manifold.random_point(4)
    for opt in (LBFGS(cautious=0.0), LBFGS(line_search=StrongWolfe(curvature=0.5, initial="newton"))):
        res = opt.solve(problem, x0)
        assert res.success and res.fun == pytest.approx(lam, abs=1e-9)
    search = Backtracking(initial="newton")
    assert LBFGS(line_search=search).line_search is search


@pytest.mark.parametrize(
    "settings",
    [{"memory": 0}, {"memory": 2.5}, {"memory": True}, {"cautious": -1.0}, {"line_search": "newton"},
     {"curvature": 1e-5}, {"line_search": "armijo", "contraction": 1.5}, {"damping": 1.0}],
)  # fmt: skip
def test_bad_settings_are_rejected(settings):
    with pytest.raises((ValueError, TypeError)):
        LBFGS(**settings)


def test_the_registry_entry():
    entry = get_optimizer("lbfgs")
    assert entry is OPTIMIZERS["lbfgs"] and entry.cls is LBFGS and entry.accepts is Problem
    assert entry.summary == "Riemannian limited-memory BFGS, cautious updates, strong Wolfe"
    opt = entry.make(max_iterations=7, memory=4)
    assert isinstance(opt, LBFGS) and opt.stopping.max_iterations == 7 and opt.memory == 4
    assert opt.first_order  # a line-search method: no cost-decrease default on least squares
    problem, lam, _ = rayleigh(n=20)
    assert entry.make().solve(problem, problem.manifold.random_point(0)).fun == pytest.approx(lam, abs=1e-9)


# ---- reliability: what every optimizer guarantees ----------------------------------------

A = np.diag(np.arange(1.0, 11.0))
X0 = np.ones(10) / np.sqrt(10)


def diagonal(scale=1.0, flip=1.0, cost=None, egrad=None):
    """``scale·xᵀAx`` on S⁹ (optimum ``scale`` at e₁), optionally with a flipped gradient."""
    cost = cost or (lambda x: scale * (x @ A @ x))
    return Problem(Sphere(10), cost=cost, egrad=egrad or (lambda x: flip * scale * 2.0 * (A @ x)))


def test_a_sign_flipped_gradient_is_never_success():
    problem = diagonal(flip=-1.0)
    res = LBFGS().solve(problem, X0)
    assert not res.success and res.status in (Status.NO_PROGRESS, Status.LINE_SEARCH_FAILED)
    assert res.fun == pytest.approx(problem.cost(X0), rel=1e-12)


def test_a_gradient_turning_infinite_mid_run_is_never_success():
    """The strong Wolfe search rejects trials without a finite gradient, so the run ends on the
    last finite point (a failed search, or ``NON_FINITE``), never converged."""
    calls = [0]

    def egrad(x):
        calls[0] += 1
        return np.full(10, np.inf) if calls[0] > 3 else 2.0 * (A @ x)

    problem = diagonal(egrad=egrad)
    res = LBFGS().solve(problem, X0)
    assert res.status in (Status.NON_FINITE, Status.LINE_SEARCH_FAILED) and not res.success
    assert np.isfinite(res.fun) and res.fun == pytest.approx(problem.cost(res.x))


@pytest.mark.parametrize("scale", [1e-300, 1e-150, 1e300])
def test_scaled_costs_solve_like_the_original(scale):
    res = LBFGS().solve(diagonal(scale=scale), X0)
    assert res.nit > 0 and res.success, res
    assert res.fun == pytest.approx(scale, rel=1e-9)


@pytest.mark.parametrize("scale", [1.0, 1e-300])
def test_a_start_at_a_critical_point_stops_at_once(scale):
    res = LBFGS().solve(diagonal(scale=scale), np.eye(10)[0])
    assert res.status is Status.GRADIENT_NORM and res.nit == 0


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_costs_at_trial_points_are_rejected(bad):
    calls = [0]

    def cost(x):
        calls[0] += 1
        return bad if calls[0] > 1 and calls[0] % 3 == 0 else x @ A @ x

    res = LBFGS().solve(diagonal(cost=cost), X0)
    assert res.success and res.fun == pytest.approx(1.0, rel=1e-9)


def test_a_nan_region_keeps_the_search_inside():
    problem = diagonal(cost=lambda x: np.nan if np.linalg.norm(x - X0) > 0.3 else x @ A @ x)
    res = LBFGS(max_iterations=50).solve(problem, X0)
    assert np.isfinite(res.fun) and np.linalg.norm(res.x - X0) <= 0.3 and res.fun < 5.5


@pytest.mark.parametrize("where", ["cost", "gradient", "callback"])
def test_keyboard_interrupt_returns_the_last_point(where):
    calls = [0]

    def tick(kind):
        calls[0] += kind == where
        if calls[0] == 3 and kind == where:
            raise KeyboardInterrupt

    def cost(x):
        tick("cost")
        return x @ A @ x

    def egrad(x):
        tick("gradient")
        return 2.0 * (A @ x)

    seen = []

    def callback(info):
        seen.append(info.iteration)
        tick("callback")

    res = LBFGS(grad_rtol=1e-14).solve(diagonal(cost=cost, egrad=egrad), X0, callback=callback)
    assert res.status is Status.INTERRUPTED and not res.success
    assert res.nit == seen[-1] and len(res.history) == res.nit + 1
    assert res.fun == res.history.cost[-1]


def test_a_callback_stops_cleanly():
    res = LBFGS(grad_rtol=1e-14).solve(diagonal(), X0, callback=lambda info: info.iteration == 2)
    assert res.status is Status.CALLBACK and res.nit == 2 and not res.success


def test_one_optimizer_and_one_problem_shared_by_8_threads():
    problem, opt = diagonal(), LBFGS()
    serial = opt.solve(problem, X0)
    barrier = threading.Barrier(8)

    def run(_):
        barrier.wait()
        return opt.solve(problem, X0)

    with ThreadPoolExecutor(8) as pool:
        results = list(pool.map(run, range(8)))
    assert all(np.array_equal(r.x, serial.x) and r.nit == serial.nit and r.fun == serial.fun for r in results)


def test_round_off_convergence_without_a_gradient_tolerance_is_honest():
    """With no gradient test the run ends when steps collapse: success only at round-off."""
    res = LBFGS(grad_rtol=0.0, grad_atol=0.0, max_iterations=500).solve(diagonal(), X0)
    assert res.status in (Status.STEP_SIZE, Status.LINE_SEARCH_FAILED, Status.GRADIENT_NORM)
    assert res.fun == pytest.approx(1.0, abs=1e-14)
    assert math.isfinite(res.grad_norm)
