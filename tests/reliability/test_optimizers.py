"""Reliability regressions for the optimizers (issue 13): no false success, no traceback,
no stale cache, no race.

Each test names the audit's defect it covers:

1. an infinite gradient norm made the tolerance infinite (success at iteration 0);
2. a gradient of the wrong shape was accepted;
3. a collapsing step (a sign-flipped gradient) was reported as convergence;
4. a cost scaled by 1e-300 "succeeded" at x0 (an absolute gradient floor);
5. a nan/inf cost at a trial point raised ``FloatingPointError``;
6. Ctrl-C gave a traceback and no result;
7. one ``LeastSquaresProblem`` shared by threads gave wrong results;
8. the gradient caches keyed on the point's identity, so a point mutated in place was stale.
"""

from __future__ import annotations

import re
import threading
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest

from manopt_lie import SE2, SE3, SO3
from manopt_lie.errors import NonFiniteError, ShapeError
from manopt_lie.manifolds import LieGroupManifold, Sphere
from manopt_lie.optim import (
    OPTIMIZERS,
    Factor,
    GaussNewton,
    GradientDescent,
    LeastSquaresProblem,
    LevenbergMarquardt,
    Problem,
    Status,
    TrustRegion,
)
from tests.optim.helpers import pose_chain

# Every registered optimizer: the smooth ones on smooth problems, the least-squares ones
# (and the trust region, which runs on both) on least-squares problems.
SMOOTH = {name: e.cls for name, e in OPTIMIZERS.items() if e.accepts is Problem}
LEAST_SQUARES = {n: e.cls for n, e in OPTIMIZERS.items() if e.accepts is LeastSquaresProblem} | {"tr": TrustRegion}
smooth = pytest.mark.parametrize("make", SMOOTH.values(), ids=SMOOTH.keys())
least_squares = pytest.mark.parametrize("make", LEAST_SQUARES.values(), ids=LEAST_SQUARES.keys())
ALL = [*(pytest.param("smooth", m, id=k) for k, m in SMOOTH.items()),
       *(pytest.param("lsq", m, id=f"lsq-{k}") for k, m in LEAST_SQUARES.items())]  # fmt: skip
every_optimizer = pytest.mark.parametrize(("kind", "make"), ALL)

A = np.diag(np.arange(1.0, 11.0))
X0 = np.ones(10) / np.sqrt(10)  # not an eigenvector: f(X0) = 5.5, λ_min = 1


def rayleigh(scale=1.0, flip=1.0, *, cost=None, egrad=None, hessian=False):
    """``scale·xᵀAx`` on S⁹, optionally with a gradient of the wrong sign or other callbacks."""
    return Problem(
        Sphere(10),
        cost=cost or (lambda x: scale * (x @ A @ x)),
        egrad=egrad or (lambda x: flip * scale * 2.0 * (A @ x)),
        ehess=(lambda x, u: flip * scale * 2.0 * (A @ u)) if hessian else None,
    )


def chain(wrap=None, *, group=SE2, n=30, closures=10, noise=0.05, seed=0):
    """A pose chain with loop closures (factor arrays, pose 0 fixed), its residual wrapped
    by ``wrap(residual) -> residual`` to inject a defect; the problem, the truth and x0."""
    problem, truth, x0 = pose_chain(group, n=n, closures=closures, seed=seed, noise=noise)
    if wrap is None:
        return problem, truth, x0
    factor = problem.factors[0]
    wrapped = Factor(factor.variables, wrap(factor.residual), name="between")
    return LeastSquaresProblem(problem.manifold, [wrapped], fixed=[0]), truth, x0


def scaled(residual, scale=1.0, flip=1.0):
    def wrapped(xi, xj, jac):
        if not jac:
            return scale * residual(xi, xj, jac)
        r, jacobians = residual(xi, xj, jac)
        return scale * r, [flip * scale * j for j in jacobians]

    return wrapped


def problem_and_start(kind, **kw):
    if kind == "smooth":
        return rayleigh(**kw), X0
    problem, _, x0 = chain(lambda r: scaled(r, **kw) if kw else r)
    return problem, x0


def optimum(kind):
    if kind == "smooth":
        return 1.0
    problem, _, x0 = chain()
    return GaussNewton(grad_rtol=1e-12, rel_cost_decrease=0).solve(problem, x0).fun


# ---- 1. an infinite gradient is never convergence --------------------------------------


@smooth
@pytest.mark.parametrize("bad", [np.inf, -np.inf, np.nan])
def test_1_infinite_gradient_at_x0_is_an_error_not_success_at_iteration_0(make, bad):
    problem = rayleigh(egrad=lambda x: np.full(10, bad))
    with pytest.raises(NonFiniteError, match="egrad"):
        make().solve(problem, X0)


@every_optimizer
def test_1_infinite_cost_at_x0_is_an_error_not_success(kind, make):
    if kind == "smooth":
        problem, x0 = rayleigh(cost=lambda x: np.inf), X0
    else:

        def infinite(residual):
            def wrapped(xi, xj, jac):
                out = residual(xi, xj, jac)
                return (np.full_like(out[0], np.inf), out[1]) if jac else np.full_like(out, np.inf)

            return wrapped

        problem, _, x0 = chain(infinite)
    with pytest.raises(NonFiniteError, match="x0"):
        make().solve(problem, x0)


def test_1_a_non_finite_residual_at_x0_names_the_factor_and_the_edge():
    def poisoned(residual):
        def wrapped(xi, xj, jac):
            r, jacobians = residual(xi, xj, True)
            r = r.copy()
            r[7] = np.nan
            return (r, jacobians) if jac else r

        return wrapped

    problem, _, x0 = chain(poisoned)
    for make in (GaussNewton, LevenbergMarquardt, TrustRegion):
        with pytest.raises(NonFiniteError, match=r"'between'.*edge 7"):
            make().solve(problem, x0)


def test_1_a_nan_jacobian_at_x0_is_called_non_finite_not_a_singular_system():
    """Audit: a nan Jacobian was reported as a singular system, with "fix the gauge" advice."""

    def nan_jacobian(residual):
        def wrapped(xi, xj, jac):
            if not jac:
                return residual(xi, xj, jac)
            r, (ji, jj) = residual(xi, xj, True)
            ji = ji.copy()
            ji[3, 0, 0] = np.nan
            return r, [ji, jj]

        return wrapped

    problem, _, x0 = chain(nan_jacobian)
    for make in LEAST_SQUARES.values():
        with pytest.raises(NonFiniteError, match="Jacobian") as error:
            make().solve(problem, x0)
        assert "gauge" not in str(error.value) and "singular" not in str(error.value).lower()


@every_optimizer
def test_1_a_gradient_turning_infinite_mid_run_never_reports_success(kind, make):
    """From the 4th gradient on, every gradient is infinite: the run must end on the last
    point with finite values, not converge (and not return ``fun = inf``)."""
    calls = [0]
    if kind == "smooth":

        def egrad(x):
            calls[0] += 1
            return np.full(10, np.inf) if calls[0] > 3 else 2.0 * (A @ x)

        problem, x0 = rayleigh(egrad=egrad), X0
    else:

        def infinite_later(residual):
            def wrapped(xi, xj, jac):
                if not jac:
                    return residual(xi, xj, jac)
                calls[0] += 1
                r, jacobians = residual(xi, xj, jac)
                return r, [np.full_like(j, np.inf) if calls[0] > 3 else j for j in jacobians]

            return wrapped

        problem, _, x0 = chain(infinite_later)
    res = make(max_iterations=200).solve(problem, x0)
    assert not res.success and res.status is not Status.GRADIENT_NORM
    assert np.isfinite(res.fun) and np.isfinite(res.grad_norm) and res.fun == pytest.approx(problem.cost(res.x))


# ---- 2. callbacks of the wrong shape ---------------------------------------------------


@smooth
def test_2_egrad_of_the_wrong_shape_is_a_shape_error_naming_it(make):
    """``egrad`` returning (3, 3) on Sphere(3) used to be projected by broadcasting and "succeed"."""
    problem = Problem(Sphere(3), cost=lambda x: x @ x, egrad=lambda x: np.eye(3))
    with pytest.raises(ShapeError, match=r"egrad returned shape \(3, 3\).*shape \(3,\)"):
        make().solve(problem, np.array([1.0, 0.0, 0.0]))


@smooth
def test_2_a_scalar_egrad_that_would_broadcast_is_refused(make):
    problem = Problem(Sphere(3), cost=lambda x: x[0], egrad=lambda x: 0.0)  # looks critical once broadcast
    with pytest.raises(ShapeError, match=r"egrad returned shape \(\)"):
        make().solve(problem, np.array([0.0, 1.0, 0.0]))


@smooth
def test_2_rgrad_of_the_wrong_shape_on_a_lie_group_is_a_shape_error(make):
    problem = Problem(LieGroupManifold(SO3), cost=lambda R: 0.0, rgrad=lambda R: np.zeros((3, 3)))
    with pytest.raises(ShapeError, match=r"rgrad returned shape \(3, 3\).*shape \(3,\)"):
        make().solve(problem, SO3.identity())


def test_2_a_lie_group_egrad_must_have_the_matrix_shape():
    problem = Problem(LieGroupManifold(SO3), cost=lambda R: 0.0, egrad=lambda R: np.zeros(3))
    with pytest.raises(ShapeError, match=r"egrad returned shape \(3,\).*\(3, 3\)"):
        GradientDescent().solve(problem, SO3.identity())


@pytest.mark.parametrize("which", ["ehess", "rhess"])
def test_2_hessians_of_the_wrong_shape_are_shape_errors_for_the_trust_region(which):
    def wrong(x, u):
        return np.zeros((10, 10))

    if which == "ehess":
        problem = Problem(Sphere(10), cost=lambda x: x @ A @ x, egrad=lambda x: 2 * A @ x, ehess=wrong)
    else:
        problem = Problem(Sphere(10), cost=lambda x: x @ A @ x, egrad=lambda x: 2 * A @ x, rhess=wrong)
    with pytest.raises(ShapeError, match=rf"{which} returned shape \(10, 10\)"):
        TrustRegion().solve(problem, X0)


@smooth
@pytest.mark.parametrize(
    ("cost", "error", "pattern"),
    [(lambda x: x, ShapeError, r"cost returned shape \(10,\)"),
     (lambda x: np.array([x @ A @ x]), ShapeError, r"cost returned shape \(1,\)"),
     (lambda x: complex(x @ A @ x), TypeError, "real number"),
     (lambda x: np.nan, NonFiniteError, "cost at x0 is nan")],
)  # fmt: skip
def test_2_a_cost_must_be_a_finite_real_scalar(make, cost, error, pattern):
    with pytest.raises(error, match=pattern):
        make().solve(rayleigh(cost=cost), X0)


@pytest.mark.parametrize("linearized", [False, True])
def test_2_a_factor_with_residuals_of_the_wrong_shape_is_named(linearized):
    def flat(residual):
        def wrapped(xi, xj, jac):
            out = residual(xi, xj, jac)
            if not jac:
                return out.ravel() if not linearized else out
            r, jacobians = out
            return (r.ravel(), jacobians) if linearized else (r, jacobians)

        return wrapped

    problem, _, x0 = chain(flat)
    m = problem.factors[0].variables.shape[0]
    if linearized:
        with pytest.raises(ShapeError, match=rf"between: residual\(jac=True\) returned residuals of shape \({3 * m},"):
            GaussNewton().solve(problem, x0)
    else:  # x0 passes (it is linearized); the first trial cost does not
        with pytest.raises(ShapeError, match=rf"residual\(jac=False\) .* shape \({3 * m},\); expected .* \({m}, 3\)"):
            GradientDescent().solve(problem, x0)


# ---- 3. a collapsing step is no convergence --------------------------------------------


@every_optimizer
def test_3_a_sign_flipped_gradient_is_never_success(kind, make):
    problem, x0 = problem_and_start(kind, flip=-1.0)
    f0 = problem.cost(x0)
    res = make().solve(problem, x0)
    assert not res.success, res
    assert res.status in (Status.NO_PROGRESS, Status.LINE_SEARCH_FAILED)
    assert res.fun == pytest.approx(f0, rel=1e-12)  # it made no progress, and says so


@pytest.mark.parametrize("kind", ["smooth", "lsq"])
def test_3_the_trust_region_collapsing_on_a_flipped_gradient_is_no_progress(kind):
    problem, x0 = problem_and_start(kind, flip=-1.0)
    res = TrustRegion().solve(problem, x0)
    assert res.status is Status.NO_PROGRESS and not res.status.converged
    assert res.history.extra["radius"][-1] < 1e-12 or res.history.step[-1] < 1e-12


def test_3_levenberg_marquardt_with_flipped_jacobians_is_no_progress():
    problem, _, x0 = chain(lambda r: scaled(r, flip=-1.0))
    res = LevenbergMarquardt().solve(problem, x0)
    assert res.status is Status.NO_PROGRESS and res.history.extra["damping"][-1] > 1e29  # λ of the last try


@pytest.mark.parametrize("make", [GaussNewton, LevenbergMarquardt, TrustRegion], ids=["gn", "lm", "tr"])
@pytest.mark.parametrize(("group", "noise"), [(SE2, 0.0), (SE2, 0.05), (SE3, 0.05)], ids=["se2-exact", "se2", "se3"])
def test_3_genuine_convergence_at_round_off_is_still_success(make, group, noise):
    """With no gradient tolerance the run can only end when the step collapses at round-off:
    there the model predicts nothing left to gain, so it is convergence (``STEP_SIZE``)."""
    problem, _, x0 = chain(group=group, noise=noise, n=40, closures=15)
    reference = GaussNewton(grad_rtol=1e-10, rel_cost_decrease=0).solve(problem, x0)
    res = make(grad_rtol=0.0, grad_atol=0.0, rel_cost_decrease=0, max_iterations=500).solve(problem, x0)
    assert res.status is Status.STEP_SIZE and res.success, res
    assert res.fun == pytest.approx(reference.fun, rel=1e-9, abs=1e-20)


@pytest.mark.parametrize("hessian", [True, False], ids=["ehess", "finite-differences"])
def test_3_trust_region_at_round_off_on_an_embedded_manifold_is_success(hessian):
    problem = rayleigh(hessian=hessian)
    res = TrustRegion(grad_rtol=0.0, grad_atol=0.0).solve(problem, X0)
    assert res.status is Status.STEP_SIZE and res.fun == pytest.approx(1.0, abs=1e-14)


# ---- 4. the gradient floor follows the cost's scale ------------------------------------


@smooth
@pytest.mark.parametrize("scale", [1e-300, 1e-150, 1e-20])
def test_4_a_cost_scaled_by_1e_300_does_not_succeed_at_x0(make, scale):
    """‖grad f(x₀)‖ ≈ 1e-300 is far below an absolute floor of 1e-12; the floor is
    ``grad_atol·s`` with ``s = min(1, max(|f(x₀)|, ‖g₀‖·L))``, so the run goes on and solves it."""
    res = make().solve(rayleigh(scale=scale), X0)
    assert res.nit > 0
    assert res.success and res.fun == pytest.approx(scale, rel=1e-9)


@least_squares
def test_4_least_squares_scaled_to_1e_300_solve_like_the_original(make):
    original = make().solve(*chain()[::2])
    problem, _, x0 = chain(lambda r: scaled(r, scale=1e-150))
    res = make().solve(problem, x0)
    assert res.nit > 0 and res.success, res
    assert res.fun == pytest.approx(1e-300 * original.fun, rel=1e-9)


@smooth
@pytest.mark.parametrize("scale", [1.0, 1e-300])
def test_4_a_start_at_a_critical_point_still_stops_at_once(make, scale):
    e1 = np.eye(10)[0]
    res = make().solve(rayleigh(scale=scale), e1)
    assert res.status is Status.GRADIENT_NORM and res.nit == 0


def test_4_a_constant_offset_does_not_loosen_the_floor():
    """The floor is capped at grad_atol (s ≤ 1): a cost of 1e12 + xᵀAx is not 'critical' at x0."""
    res = GradientDescent().solve(rayleigh(cost=lambda x: 1e12 + x @ A @ x), X0)
    assert res.nit > 0


# ---- 5. non-finite costs at trial points -----------------------------------------------


def every_third(bad):
    """A counter that makes every third evaluation after the first return ``bad``."""
    calls = [0]

    def hit():
        calls[0] += 1
        return calls[0] > 1 and calls[0] % 3 == 0

    return hit


@every_optimizer
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_5_nan_or_inf_costs_at_trial_points_are_rejected_not_raised(kind, make, bad):
    hit = every_third(bad)
    if kind == "smooth":
        problem, x0 = rayleigh(cost=lambda x: bad if hit() else x @ A @ x), X0
    else:

        def poisoned(residual):
            def wrapped(xi, xj, jac):
                out = residual(xi, xj, jac)
                return out if jac or not hit() else np.full_like(out, bad)

            return wrapped

        problem, _, x0 = chain(poisoned)
    res = make(rel_cost_decrease=0).solve(problem, x0)  # used to raise FloatingPointError
    assert res.success, res
    assert res.fun == pytest.approx(optimum(kind), rel=1e-9)


def test_5_a_nan_region_beyond_the_first_trial_makes_the_searches_backtrack():
    """The cost is nan wherever x₀ is left by more than 0.3: every optimizer stays inside."""
    problem = rayleigh(cost=lambda x: np.nan if np.linalg.norm(x - X0) > 0.3 else x @ A @ x)
    for make in SMOOTH.values():
        res = make(max_iterations=50).solve(problem, X0)
        assert np.isfinite(res.fun) and np.linalg.norm(res.x - X0) <= 0.3 and res.fun < 5.5


# ---- 6. Ctrl-C returns the last point --------------------------------------------------


def interrupting(kind, where, after):
    """A problem whose cost or gradient (or, for "callback", nothing) raises
    KeyboardInterrupt at its ``after``-th call."""
    calls = [0]

    def tick():
        calls[0] += 1
        if calls[0] == after:
            raise KeyboardInterrupt

    if kind == "smooth":

        def cost(x):
            if where == "cost":
                tick()
            return x @ A @ x

        def egrad(x):
            if where == "gradient":
                tick()
            return 2.0 * (A @ x)

        return rayleigh(cost=cost, egrad=egrad), X0

    def ticking(residual):
        # "cost": every evaluation (a trial's may come with Jacobians, kept for the
        # linearization); "gradient": those with Jacobians.
        def wrapped(xi, xj, jac):
            if where == "cost" or jac:
                tick()
            return residual(xi, xj, jac)

        return wrapped

    problem, _, x0 = chain(ticking if where != "callback" else None)
    return problem, x0


@every_optimizer
@pytest.mark.parametrize("where", ["cost", "gradient", "callback"])
def test_6_keyboard_interrupt_returns_the_last_point_with_status_interrupted(kind, make, where):
    problem, x0 = interrupting(kind, where, after=3)
    seen = []

    def callback(info):
        seen.append(info.iteration)
        if where == "callback" and info.iteration == 2:
            raise KeyboardInterrupt

    res = make(grad_rtol=1e-14).solve(problem, x0, callback=callback)
    assert res.status is Status.INTERRUPTED and not res.success
    assert "interrupt" in res.message.lower()
    assert res.nit == seen[-1] and len(res.history) == res.nit + 1
    assert res.fun == res.history.cost[-1] == pytest.approx(problem.cost(res.x), rel=1e-14)
    if where == "callback":
        assert res.nit == 2


@every_optimizer
def test_6_an_interrupt_during_the_first_evaluation_returns_x0(kind, make):
    problem, x0 = interrupting(kind, "cost" if kind == "smooth" else "gradient", after=1)
    res = make().solve(problem, x0)
    assert res.status is Status.INTERRUPTED and res.x is x0 and np.isnan(res.fun)
    assert res.nit == 0 and len(res.history) == 0


@every_optimizer
def test_6_a_callback_raising_stop_iteration_stops_cleanly(kind, make):
    problem, x0 = problem_and_start(kind)

    def callback(info):
        if info.iteration == 2:
            raise StopIteration

    res = make(grad_rtol=1e-14).solve(problem, x0, callback=callback)
    assert res.status is Status.CALLBACK and res.nit == 2 and not res.success


# ---- 7. threads ------------------------------------------------------------------------


def _same(a, b):
    x_a = a.x.data if hasattr(a.x, "data") and not isinstance(a.x, np.ndarray) else a.x
    x_b = b.x.data if hasattr(b.x, "data") and not isinstance(b.x, np.ndarray) else b.x
    return np.array_equal(x_a, x_b) and a.fun == b.fun and a.nit == b.nit and a.status is b.status


def _in_threads(solve, k=8):
    barrier = threading.Barrier(k)

    def run(_):
        barrier.wait()  # all at once
        return solve()

    with ThreadPoolExecutor(k) as pool:
        return list(pool.map(run, range(k)))


@least_squares
def test_7_one_least_squares_problem_shared_by_8_threads_gives_the_serial_result(make):
    problem, _, x0 = chain(group=SE3, n=200, closures=60, noise=0.02)
    serial = make().solve(problem, x0)
    results = _in_threads(lambda: make().solve(problem, x0))
    assert sum(not _same(r, serial) for r in results) == 0


def test_7_one_optimizer_and_one_smooth_problem_shared_by_8_threads():
    problem = rayleigh(hessian=True)  # the egrad memo serves the Hessian products
    opt = TrustRegion()
    serial = opt.solve(problem, X0)
    assert all(_same(r, serial) for r in _in_threads(lambda: opt.solve(problem, X0)))


# ---- 8. caches key on values -----------------------------------------------------------


def test_8_the_egrad_memo_sees_a_point_mutated_in_place():
    calls = []

    def egrad(x):
        calls.append(x.copy())
        return 2.0 * (A @ x)

    problem = rayleigh(egrad=egrad, hessian=True)
    x = X0.copy()
    v = problem.manifold.random_tangent(x, 0)
    g0 = problem.grad(x)
    problem.hess(x, v)
    assert len(calls) == 1  # the memo works
    x[:] = np.eye(10)[3]  # the same array, a new point
    np.testing.assert_allclose(problem.grad(x), Sphere(10).proj(x, 2.0 * (A @ x)), atol=1e-15)
    assert len(calls) == 2 and not np.allclose(problem.grad(x), g0)


def test_8_the_linearization_memo_sees_a_point_mutated_in_place():
    problem, truth, x0 = chain()
    x = SE2.from_matrix(x0.as_matrix())
    lin0 = problem.linearize(x)
    assert problem.linearize(x) is lin0  # remembered
    x.data.flags.writeable = True
    x.data[...] = truth.as_matrix()  # the same element, mutated
    lin1 = problem.linearize(x)
    assert lin1 is not lin0 and lin1.cost == pytest.approx(problem.cost(truth))


# ---- the statuses ----------------------------------------------------------------------


def test_every_status_says_correctly_whether_it_converged():
    converged = {Status.GRADIENT_NORM, Status.COST_DECREASE, Status.STEP_SIZE, Status.CERTIFIED}
    for status in Status:
        assert status.converged is (status in converged), status


def test_the_status_table_in_the_docs_lists_exactly_the_enum():
    text = (Path(__file__).resolve().parents[2] / "docs" / "optimizers.md").read_text()
    rows = re.findall(r"^\| `([A-Z_]+)` \| (yes|no) \|", text, re.M)
    assert [name for name, _ in rows] == [s.name for s in Status]
    assert all((flag == "yes") is Status[name].converged for name, flag in rows)
