"""Gauss-Newton and Levenberg-Marquardt with pluggable linear solvers: PCG against Cholesky,
reporting of inexact solves, directions that are not of descent, the protocol, the step's status."""

from __future__ import annotations

import numpy as np
import pytest

from manopt_lie import SE2, SE3
from manopt_lie.linalg import AutoSolver, CholeskySolver, LinearSolver, PCGSolver, get_linear_solver
from manopt_lie.optim import GaussNewton, LevenbergMarquardt, Status

from .helpers import pose_chain

LSQ = {"gn": GaussNewton, "lm": LevenbergMarquardt}
lsq = pytest.mark.parametrize("make", LSQ.values(), ids=LSQ.keys())


@lsq
@pytest.mark.parametrize("group", [SE2, SE3], ids=["SE2", "SE3"])
def test_pcg_reaches_the_cholesky_optimum(make, group):
    """A noisy chain with loop closures (optimum cost > 0): same optimum, cost to 1e-8 relative."""
    problem, _, x0 = pose_chain(group, n=60, closures=20, noise=0.05)
    direct = make(grad_rtol=1e-10).solve(problem, x0)
    iterative = make(grad_rtol=1e-10, linear_solver="pcg").solve(problem, x0)
    assert direct.success and iterative.success, (direct, iterative)
    assert direct.fun > 1e-3  # a real optimum, not an exact fit
    assert iterative.fun == pytest.approx(direct.fun, rel=1e-8)
    assert group.dist(iterative.x, direct.x).max() < 1e-5
    extra = iterative.history.extra
    assert np.all(extra["linear_iterations"][1:] >= 1) and np.all(extra["linear_converged"][1:] == 1.0)
    assert np.all(extra["linear_residual"][1:] <= 1e-6)
    assert "linear_iterations" not in direct.history.extra  # a direct solve has nothing to report


@lsq
def test_truncated_inner_solves_are_reported_and_still_descend(make):
    """Capped at 20 CG iterations (of 180 unknowns) no solve converges, every one is reported
    as such, and the truncated steps, still descent directions, reach the optimum."""
    problem, _, x0 = pose_chain(SE2, n=60, closures=20, noise=0.05)
    optimum = make(grad_rtol=1e-10, rel_cost_decrease=0).solve(problem, x0).fun
    res = make(grad_rtol=1e-8, rel_cost_decrease=0, linear_solver=PCGSolver(maxiter=20)).solve(problem, x0)
    extra = res.history.extra
    assert np.all(extra["linear_iterations"][1:] == 20)
    assert np.all(extra["linear_converged"][1:] == 0.0) and np.all(extra["linear_residual"][1:] > 1e-6)
    assert np.all(np.diff(res.history.cost) <= 0)
    assert res.success and res.fun == pytest.approx(optimum, rel=1e-8)
    capped = make(max_iterations=30, linear_solver=PCGSolver(maxiter=3)).solve(problem, x0)
    assert capped.status is Status.MAX_ITERATIONS and not capped.success  # slow, and says so


class _Uphill:
    """A broken solver: ``−H⁻¹b``, the opposite of a descent direction."""

    def __init__(self) -> None:
        self._cholesky = CholeskySolver()

    def bind(self, structure):
        return _Uphill()

    def __call__(self, H, b):
        return -self._cholesky(H, b)

    @property
    def stats(self):
        return {}


@lsq
def test_a_direction_that_is_not_of_descent_is_not_taken(make):
    problem, _, x0 = pose_chain(SE2, n=20, closures=5)
    assert isinstance(_Uphill(), LinearSolver)
    res = make(linear_solver=_Uphill()).solve(problem, x0)
    assert res.status is Status.LINEAR_SOLVER_FAILED and not res.success
    assert res.nit == 1 and res.x is x0 and res.fun == res.history.cost[0]
    assert np.isnan(res.history.step[1])


def test_failed_line_search_is_a_status_not_a_telemetry_flag():
    """The history's extras are numbers only; the reason to stop travels as a Status."""
    problem, _, x0 = pose_chain(SE2, n=20, closures=5)
    res = GaussNewton(max_backtracks=0, sufficient_decrease=0.999).solve(problem, x0)
    assert res.status is Status.LINE_SEARCH_FAILED and not res.success
    assert set(res.history.extra) == {"alpha"} and res.history.extra["alpha"][-1] == 0.0


def test_custom_solver_templates_are_bound_per_run():
    """Each run binds a fresh solver, so one optimizer can run inside another's callback."""
    bound = []

    class Counting(CholeskySolver):
        def bind(self, structure):
            bound.append(structure)
            return super().bind(structure)

    problem, _, x0 = pose_chain(SE3, n=30, closures=10, noise=0.05)
    other, _, y0 = pose_chain(SE2, n=25, closures=8, noise=0.05, seed=3)
    opt = LevenbergMarquardt(linear_solver=Counting("superlu"))
    alone = opt.solve(other, y0)
    inner = []

    def nested(info):
        if info.iteration == 1:
            inner.append(opt.solve(other, y0))

    outer = opt.solve(problem, x0, callback=nested)
    assert len(bound) == 3 and bound[0] is other.structure and bound[1] is problem.structure
    assert inner[0].fun == alone.fun and inner[0].nit == alone.nit
    assert outer.success and opt.linear_solver.n_analyses == 0  # the template itself never solves


def test_linear_solver_names_and_errors():
    assert isinstance(get_linear_solver(None), AutoSolver)
    assert isinstance(get_linear_solver("cholesky"), CholeskySolver)
    assert isinstance(get_linear_solver("pcg"), PCGSolver)
    template = PCGSolver(tol=1e-9)
    assert GaussNewton(linear_solver=template).linear_solver is template
    with pytest.raises(ValueError, match="unknown linear solver 'lu'; choose from auto, cholesky, pcg"):
        GaussNewton(linear_solver="lu")
    with pytest.raises(TypeError, match="bind"):
        LevenbergMarquardt(linear_solver=lambda H, b: b)
    with pytest.raises(TypeError, match=r"PCGSolver\(\)"):
        GaussNewton(linear_solver=PCGSolver)
    for bad in ({"tol": 0.0}, {"tol": 1.5}, {"maxiter": 0}, {"preconditioner": "ilu"}):
        with pytest.raises(ValueError):
            PCGSolver(**bad)


def test_the_default_solver_takes_pcg_where_the_factor_would_be_dense():
    """Rotation averaging on a random graph of 700 rotations (degree 8): the factor is predicted
    dense, so LM, GN and dogleg solve by PCG (its numbers in the history) and reach Cholesky's
    optimum; the trust region preconditions by the diagonal blocks instead of a factorization."""
    from manopt_lie.linalg import _cholmod
    from manopt_lie.optim import Dogleg, TrustRegion
    from manopt_lie.optim.preconditioners import _Auto, _BlockJacobi, bind_preconditioner
    from manopt_lie.problems.synthetic import rotation_averaging

    graph = rotation_averaging(700, degree=8, seed=0).graph
    x0 = graph.chordal_initialization()
    direct = LevenbergMarquardt(linear_solver="cholesky").solve(graph.problem("chordal"), x0)
    for make in (LevenbergMarquardt, GaussNewton, Dogleg):
        problem = graph.problem("chordal")
        res = make().solve(problem, x0)
        if not _cholmod.available():  # no prediction without CHOLMOD called directly
            assert "linear_iterations" not in res.history.extra
            continue
        assert res.success and res.fun == pytest.approx(direct.fun, rel=1e-9)
        assert np.all(res.history.extra["linear_iterations"][1:] >= 1)
        assert np.all(res.history.extra["linear_converged"][1:] == 1.0)
    problem = graph.problem("chordal")
    res = TrustRegion().solve(problem, x0)
    assert res.success and res.fun == pytest.approx(direct.fun, rel=1e-7)
    precon = bind_preconditioner("auto", problem)
    assert isinstance(precon, _Auto)
    precon(x0, np.zeros(problem.manifold.zero_vector(x0).shape))
    assert isinstance(precon._chosen, _BlockJacobi) or not _cholmod.available()
