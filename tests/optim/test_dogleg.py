"""Powell's dogleg: the step's geometry, known optima, cheap rejections, singular systems."""

from __future__ import annotations

import numpy as np
import pytest

from manopt_lie import SE2, SE3
from manopt_lie.linalg import CholeskySolver
from manopt_lie.manifolds import Euclidean, Power
from manopt_lie.optim import (
    OPTIMIZERS,
    Dogleg,
    Factor,
    GaussNewton,
    LeastSquaresProblem,
    Problem,
    Status,
    get_optimizer,
)
from manopt_lie.optim.dogleg import CAUCHY, DOGLEG, GAUSS_NEWTON, dogleg_step
from manopt_lie.problems import synthetic

from .helpers import between, pose_chain


def test_dogleg_step_geometry(rng):
    g = rng.standard_normal(6)
    a = -0.3 * g  # a Cauchy step along −g
    b = a + rng.standard_normal(6)  # a Gauss-Newton step
    step, kind = dogleg_step(b, a, g, 1.01 * np.linalg.norm(b))
    assert kind == GAUSS_NEWTON and step is b
    radius = 0.5 * np.linalg.norm(a)
    step, kind = dogleg_step(b, a, g, radius)
    assert kind == CAUCHY and np.linalg.norm(step) == pytest.approx(radius)
    np.testing.assert_allclose(step / np.linalg.norm(step), -g / np.linalg.norm(g))
    radius = 0.5 * (np.linalg.norm(a) + np.linalg.norm(b))
    step, kind = dogleg_step(b, a, g, radius)
    assert kind == DOGLEG and np.linalg.norm(step) == pytest.approx(radius, rel=1e-12)
    tau = (step - a) @ (b - a) / ((b - a) @ (b - a))
    assert 0 < tau < 1
    np.testing.assert_allclose(step, a + tau * (b - a), atol=1e-12)  # on the second leg
    step, kind = dogleg_step(None, a, g, 10 * np.linalg.norm(a))  # no Gauss-Newton leg: the Cauchy point
    assert kind == CAUCHY and step is a
    step, kind = dogleg_step(None, None, g, 2.0)  # a model flat along g: steepest descent of length Δ
    assert kind == CAUCHY and np.linalg.norm(step) == pytest.approx(2.0)


@pytest.mark.parametrize("group", [SE2, SE3], ids=["SE2", "SE3"])
def test_consistent_pose_graph_is_solved_exactly(group):
    problem, truth, x0 = pose_chain(group)
    res = Dogleg(grad_rtol=1e-14, rel_cost_decrease=0).solve(problem, x0)
    assert res.success, res
    assert res.fun < 1e-18 and truth.dist(res.x).max() < 1e-8
    np.testing.assert_array_equal(res.x[0].as_matrix(), truth[0].as_matrix())
    assert set(res.history.extra["dogleg"][1:]) == {GAUSS_NEWTON}  # near the optimum: Gauss-Newton steps


def test_noisy_graph_reaches_the_gauss_newton_optimum():
    graph = synthetic.grid2d(8, 8, loop_closure_probability=0.5, seed=3).graph
    problem, x0 = graph.problem("geodesic"), graph.odometry_initialization()
    reference = GaussNewton(grad_rtol=1e-12, rel_cost_decrease=0).solve(problem, x0)
    res = Dogleg(grad_rtol=1e-12, rel_cost_decrease=0).solve(problem, x0)
    assert res.success and res.fun == pytest.approx(reference.fun, rel=1e-10)


def rosenbrock():
    def residual(p, jac):
        x, y = p[:, 0], p[:, 1]
        r = np.stack([10 * (y - x**2), 1 - x], axis=-1)
        if not jac:
            return r
        j = np.zeros((len(x), 2, 2))
        j[:, 0, 0], j[:, 0, 1], j[:, 1, 0] = -20 * x, 10.0, -1.0
        return r, [j]

    return LeastSquaresProblem(Power(Euclidean(2), 1), [Factor(np.zeros((1, 1), dtype=int), residual)])


class CountingCholesky(CholeskySolver):
    """A Cholesky template whose bound solvers count their factorizations in ``calls``."""

    def __init__(self, calls):
        super().__init__()
        self.calls = calls

    def bind(self, structure):
        return CountingCholesky(self.calls)

    def factorize(self, H):
        self.calls.append(1)
        super().factorize(H)


def test_rosenbrock_and_rejections_reuse_the_factorization():
    calls: list[int] = []
    res = Dogleg(grad_rtol=1e-12, rel_cost_decrease=0, linear_solver=CountingCholesky(calls)).solve(
        rosenbrock(), np.array([[-1.2, 1.0]])
    )
    assert res.success, res
    np.testing.assert_allclose(res.x, [[1.0, 1.0]], atol=1e-8)
    accepted = int(np.sum(~np.isnan(res.history.step[1:])))
    assert accepted < res.nit  # Rosenbrock's valley rejects some steps…
    # …which cost no factorization: one per linearization stepped from (x₀ and each accepted
    # point but the last, where the run stopped).
    assert len(calls) == accepted
    radius, rho = res.history.extra["radius"], res.history.extra["rho"]
    shrunk = np.flatnonzero(rho[1:-1] < 0.25) + 1
    assert np.all(radius[shrunk + 1] < radius[shrunk])  # a poor ratio shrinks the region


def test_a_singular_system_gets_a_shifted_gauss_newton_leg():
    problem, _, x0 = pose_chain(SE3, n=10, closures=3)
    free = LeastSquaresProblem(problem.manifold, problem.factors)  # no gauge fixed: H is singular
    res = Dogleg(grad_rtol=1e-10, rel_cost_decrease=0).solve(free, x0)
    assert res.success and res.fun < 1e-16, res
    assert np.nanmax(res.history.extra["gauss_newton_shift"]) > 0


def test_a_collapsing_radius_is_no_progress_not_success():
    problem, _, x0 = pose_chain(SE2, n=10, closures=3)
    (factor,) = problem.factors
    residual = factor.residual

    def flipped(xi, xj, jac):
        if not jac:
            return residual(xi, xj, jac)
        r, js = residual(xi, xj, jac)
        return r, [-j for j in js]  # a model pointing uphill: every step fails

    bad = LeastSquaresProblem(problem.manifold, [Factor(factor.variables, flipped)], fixed=[0])
    res = Dogleg().solve(bad, x0)
    assert res.status is Status.NO_PROGRESS and not res.success
    assert res.history.extra["radius"][-1] < 1e-10


def test_options_and_the_registry():
    with pytest.raises(ValueError, match="initial_radius"):
        Dogleg(initial_radius=0.0)
    entry = get_optimizer("dogleg")
    assert entry.cls is Dogleg and entry.accepts is LeastSquaresProblem and OPTIMIZERS["dogleg"] is entry
    problem, truth, x0 = pose_chain(SE2, n=12, closures=4)
    res = entry.make(initial_radius=0.01, grad_rtol=1e-12, rel_cost_decrease=0).solve(problem, x0)
    assert res.success and truth.dist(res.x).max() < 1e-8
    assert res.history.extra["radius"][1] == 0.01
    with pytest.raises(TypeError, match="LeastSquaresProblem"):
        Dogleg().solve(Problem(Euclidean(2), cost=lambda x: x @ x, egrad=lambda x: 2 * x), np.ones(2))


def test_the_helpers_between_factor_is_used_as_given():
    # The same problem through a hand-written factor and through the helpers' one.
    problem, _, x0 = pose_chain(SE2, n=6, closures=2)
    (factor,) = problem.factors
    again = LeastSquaresProblem(problem.manifold, [Factor(factor.variables, factor.residual)], fixed=[0])
    a = Dogleg(grad_rtol=1e-12).solve(problem, x0)
    b = Dogleg(grad_rtol=1e-12).solve(again, x0)
    assert a.nit == b.nit and a.fun == b.fun
    assert callable(between(SE2.identity((1,))))
