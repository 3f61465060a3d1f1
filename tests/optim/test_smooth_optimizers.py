"""Gradient descent, conjugate gradients and trust regions on problems with known optima."""

from __future__ import annotations

import numpy as np
import pytest

from manopt_lie import SO3, NonFiniteError, NotOnManifoldError, ShapeError
from manopt_lie.manifolds import LieGroupManifold, Power, Sphere, Stiefel
from manopt_lie.optim import (
    Backtracking,
    ConjugateGradient,
    GradientDescent,
    OptimizeResult,
    Problem,
    Status,
    StoppingCriteria,
    StrongWolfe,
    TrustRegion,
)

OPTIMIZERS = {
    "gd": lambda **kw: GradientDescent(**kw),
    "gd-adaptive": lambda **kw: GradientDescent(initial="adaptive", **kw),
    "gd-wolfe": lambda **kw: GradientDescent(line_search="wolfe", **kw),
    "cg-fr": lambda **kw: ConjugateGradient(beta="fletcher-reeves", **kw),
    "cg-pr": lambda **kw: ConjugateGradient(beta="polak-ribiere", **kw),
    "cg-hs": lambda **kw: ConjugateGradient(beta="hestenes-stiefel", **kw),
    "cg-hz": lambda **kw: ConjugateGradient(beta="hager-zhang", **kw),
    "cg-armijo": lambda **kw: ConjugateGradient(line_search="armijo", **kw),
    "tr": lambda **kw: TrustRegion(**kw),
}
optimizers = pytest.mark.parametrize("make", OPTIMIZERS.values(), ids=OPTIMIZERS.keys())


def _symmetric(rng, n):
    a = rng.standard_normal((n, n))
    return (a + a.T) / 2


def rayleigh(n=30, seed=0, hessian=True):
    """``min xᵀAx`` on the sphere: the smallest eigenvalue, at its eigenvector."""
    a = _symmetric(np.random.default_rng(seed), n)
    problem = Problem(
        Sphere(n), cost=lambda x: x @ a @ x, egrad=lambda x: 2 * a @ x,
        ehess=(lambda x, u: 2 * a @ u) if hessian else None,
    )  # fmt: skip
    w, v = np.linalg.eigh(a)
    return problem, w[0], v[:, 0]


def brockett(n=12, p=3, seed=0):
    """``min tr(XᵀAXN)`` on St(n, p), ``N = diag(p, …, 1)``: ``Σ N_ii λ_i`` at the eigenvectors."""
    a = _symmetric(np.random.default_rng(seed), n)
    big_n = np.diag(np.arange(p, 0, -1.0))
    problem = Problem(
        Stiefel(n, p), cost=lambda x: np.trace(x.T @ a @ x @ big_n),
        egrad=lambda x: 2 * a @ x @ big_n, ehess=lambda x, u: 2 * a @ u @ big_n,
    )  # fmt: skip
    return problem, float(np.sum(np.linalg.eigvalsh(a)[:p] * np.diag(big_n)))


def karcher(seed=0):
    """``½ Σ |Rᵢ ⊖ R|²`` for rotations ``R̄ Exp(±τₖ)``, symmetric about ``R̄``: the mean is ``R̄``."""
    rng = np.random.default_rng(seed)
    mean = SO3.random(rng)
    tau = 0.4 * rng.standard_normal((10, 3))
    samples = mean.rplus(np.concatenate([tau, -tau]))

    def residuals(r):
        return samples.rminus(r, jac=True)

    def grad(r):
        res, _, j_r = residuals(r)
        return np.einsum("kji,kj->i", j_r, res)  # Σ J_Rᵀ rᵢ

    problem = Problem(LieGroupManifold(SO3), cost=lambda r: 0.5 * np.sum(residuals(r)[0] ** 2), rgrad=grad)
    return problem, mean


@optimizers
def test_rayleigh_quotient_reaches_the_smallest_eigenvalue(make):
    problem, lam, v = rayleigh()
    res = make().solve(problem, problem.manifold.random_point(1))
    assert res.status is Status.GRADIENT_NORM and res.success
    assert res.grad_norm <= 1e-6 * res.history.grad_norm[0]
    assert res.fun == pytest.approx(lam, abs=1e-9)
    assert abs(res.x @ v) == pytest.approx(1.0, abs=1e-6)


@optimizers
def test_brockett_cost_reaches_the_eigenvector_optimum(make):
    problem, optimum = brockett()
    res = make(max_iterations=5000).solve(problem, problem.manifold.random_point(3))
    assert res.success, res
    assert res.fun == pytest.approx(optimum, rel=1e-9)


@optimizers
def test_karcher_mean_on_so3_is_recovered(make):
    problem, mean = karcher()
    res = make().solve(problem, SO3.identity())
    assert res.success, res
    assert res.x.dist(mean) < 1e-6


def test_trust_region_with_finite_difference_hessian():
    problem, lam, _ = rayleigh(hessian=False)
    res = TrustRegion().solve(problem, problem.manifold.random_point(2))
    assert res.success and res.nhev == 0
    assert res.fun == pytest.approx(lam, abs=1e-9)
    assert res.nit < 30  # superlinear, not gradient-descent-like


def test_trust_region_on_a_power_of_so3():
    """Independent Karcher-type costs on 500 rotations at once: ``½ Σ |Rₖ ⊖ Tₖ|²``."""
    manifold = Power(LieGroupManifold(SO3), 500)
    target = manifold.random_point(0)

    def cost(r):
        return 0.5 * np.sum(target.rminus(r) ** 2)

    def grad(r):
        res, _, j_r = target.rminus(r, jac=True)
        return np.einsum("...ji,...j->...i", j_r, res)

    res = TrustRegion().solve(Problem(manifold, cost=cost, rgrad=grad), manifold.random_point(1))
    assert res.success
    assert target.dist(res.x).max() < 1e-6


@pytest.mark.parametrize("key", ["gd", "gd-wolfe", "cg-pr", "cg-hz", "cg-armijo"])
@pytest.mark.parametrize("case", ["rayleigh", "brockett", "karcher"])
def test_line_search_descent_is_monotone(key, case):
    problem, x0 = _problem(case)
    res = OPTIMIZERS[key](max_iterations=200).solve(problem, x0)
    assert np.all(np.diff(res.history.cost) <= 0)


def test_trust_region_accepts_only_decreasing_steps():
    problem, _ = brockett(n=20, p=4, seed=2)
    res = TrustRegion().solve(problem, problem.manifold.random_point(5))
    accepted = res.history.extra["accepted"][1:] == 1.0
    steps = np.diff(res.history.cost)
    assert np.all(steps[accepted] <= 1e-12 * abs(res.fun)) and np.all(steps[~accepted] == 0)
    assert np.all(np.isnan(res.history.step[1:][~accepted]))


@optimizers
def test_result_bookkeeping(make):
    problem, _, _ = rayleigh()
    seen = []
    res = make(max_iterations=3, grad_rtol=0).solve(problem, problem.manifold.random_point(0), callback=seen.append)
    assert isinstance(res, OptimizeResult)
    assert res.status is Status.MAX_ITERATIONS and not res.success and res.nit == 3
    assert len(res.history) == 4 and len(seen) == 4 and [i.iteration for i in seen] == [0, 1, 2, 3]
    assert res.history.cost[-1] == res.fun and res.nfev >= 4 and res.ngev >= 4
    assert np.all(np.diff(res.history.time) >= 0)
    assert "iteration limit" in res.message and "f =" in str(res)


@optimizers
def test_other_stopping_reasons(make):
    problem, _, _ = rayleigh()
    x0 = problem.manifold.random_point(0)
    assert make().solve(problem, x0, callback=lambda info: info.iteration == 2).status is Status.CALLBACK
    assert make(max_time=0.0).solve(problem, x0).status is Status.MAX_TIME
    assert make(rel_cost_decrease=0.5).solve(problem, x0).status is Status.COST_DECREASE
    # Starting at a critical point stops at once.
    _, _, v = rayleigh()
    res = make().solve(problem, v)
    assert res.status is Status.GRADIENT_NORM and res.nit == 0


@optimizers
def test_bad_inputs_are_rejected(make):
    problem, _, _ = rayleigh(n=4)
    opt = make()
    with pytest.raises(NotOnManifoldError):
        opt.solve(problem, np.ones(4))
    with pytest.raises(ShapeError):
        opt.solve(problem, np.ones(3))
    with pytest.raises(NonFiniteError):
        opt.solve(problem, np.array([np.nan, 0, 0, 1.0]))
    with pytest.raises(NotImplementedError, match="gradient"):
        opt.solve(Problem(Sphere(4), cost=lambda x: x[0]), np.eye(4)[0])
    with pytest.raises(TypeError):
        opt.solve(lambda x: x, np.eye(4)[0])


def test_settings_are_validated():
    with pytest.raises(ValueError):
        StoppingCriteria(grad_rtol=-1)
    with pytest.raises(ValueError):
        ConjugateGradient(beta="dai-yuan")
    with pytest.raises(ValueError):
        TrustRegion(rho_prime=0.5)
    with pytest.raises(ValueError):
        GradientDescent(contraction=1.5)
    with pytest.raises(ValueError, match="line_search"):
        GradientDescent(line_search="newton")
    with pytest.raises(ValueError, match="initial"):
        GradientDescent(initial="newton")
    with pytest.raises(ValueError, match="initial"):
        Backtracking(initial="previous")


@pytest.mark.parametrize("case", ["rayleigh", "brockett"])
def test_barzilai_borwein_trials_cut_steepest_descent_iterations(case):
    """The secant step as first trial: the same optimum in a fraction of the iterations, each
    step still a decrease (the search stays monotone)."""
    problem, x0 = _problem(case)
    bb = GradientDescent(max_iterations=5000).solve(problem, x0)
    adaptive = GradientDescent(initial="adaptive", max_iterations=5000).solve(problem, x0)
    assert bb.success and bb.fun == pytest.approx(adaptive.fun, rel=1e-8, abs=1e-10)
    assert bb.nit < 0.6 * adaptive.nit
    assert np.all(np.diff(bb.history.cost) <= 0)


def test_hess_operator_is_hess_at_a_fixed_point():
    problem, _, _ = rayleigh(n=8)
    x = problem.manifold.random_point(0)
    apply = problem.hess_operator(x)
    for seed in range(3):
        v = problem.manifold.random_tangent(x, seed)
        np.testing.assert_array_equal(apply(v), problem.hess(x, v))
    lie, _ = karcher()
    with pytest.raises(NotImplementedError, match="ehess"):
        lie.hess_operator(SO3.identity())

    class Doubled(Problem):
        def hess(self, x, v):  # a subclass's own Hessian is what the operator applies
            return 2.0 * super().hess(x, v)

    doubled = Doubled(problem.manifold, problem._cost, egrad=problem._egrad, ehess=problem._ehess)
    np.testing.assert_allclose(doubled.hess_operator(x)(v), 2.0 * problem.hess(x, v))


def test_searches_start_from_an_optimizers_trial_and_newton_steps():
    problem, x = _problem("rayleigh")
    m, f0, g = problem.manifold, problem.cost(x), problem.grad(x)
    g_norm = float(m.norm(x, g))
    slope = -g_norm * g_norm
    first = []

    def cost(y):
        first.append(y)
        return problem.cost(y)

    for search in (Backtracking(), StrongWolfe()):
        first.clear()
        search.search(cost, problem.grad, m, x, f0, -g, g_norm, slope, alpha0=0.01 / g_norm)
        np.testing.assert_allclose(first[0], m.retr(x, -g * (0.01 / g_norm)))
    for search in (Backtracking(initial="newton"), StrongWolfe(initial="newton")):
        first.clear()
        search.search(cost, problem.grad, m, x, f0, -g * (0.5 / g_norm), 0.5, -0.5 * g_norm)
        np.testing.assert_allclose(first[0], m.retr(x, -g * (0.5 / g_norm)))  # α = 1
        first.clear()
        search.search(cost, problem.grad, m, x, f0, -g * (50 / g_norm), 50.0, -50 * g_norm)
        np.testing.assert_allclose(first[0], m.retr(x, -g * (np.pi / g_norm)))  # capped at typical_dist


def test_strong_wolfe_returns_the_transported_direction():
    problem, x = _problem("brockett")
    m, g = problem.manifold, problem.grad(x)
    g_norm = float(m.norm(x, g))
    res = StrongWolfe().search(problem.cost, problem.grad, m, x, problem.cost(x), -g, g_norm, -g_norm * g_norm)
    assert res.success and res.grad is not None
    np.testing.assert_allclose(res.transported, m.transp(x, res.x, -g), atol=1e-14)
    plain = Backtracking().search(problem.cost, problem.grad, m, x, problem.cost(x), -g, g_norm, -(g_norm**2))
    assert plain.transported is None


def test_hessian_products_reuse_the_euclidean_gradient():
    calls = []
    a = _symmetric(np.random.default_rng(0), 30)
    counted = Problem(
        Sphere(30), cost=lambda x: x @ a @ x, egrad=lambda x: calls.append(1) or 2 * a @ x,
        ehess=lambda x, u: 2 * a @ u,
    )  # fmt: skip
    res = TrustRegion().solve(counted, counted.manifold.random_point(1))
    assert res.success and res.nhev > 3 * res.ngev
    assert len(calls) == res.ngev  # one egrad per point, however many Hessian products


def _fused_rayleigh(n=30, seed=0, where="egrad"):
    """The Rayleigh quotient with ``cost`` returning ``(f, gradient)``, counting its calls."""
    a = _symmetric(np.random.default_rng(seed), n)
    calls = []

    def both(x):
        calls.append(1)
        ax = a @ x
        f = float(x @ ax)
        return (f, 2.0 * ax) if where == "egrad" else (f, 2.0 * (ax - f * x))

    return Problem(Sphere(n), cost=both, **{where: True}), calls, np.linalg.eigvalsh(a)[0]


@pytest.mark.parametrize("where", ["egrad", "rgrad"])
@pytest.mark.parametrize("key", ["gd", "cg-pr", "cg-hz", "tr"])
def test_a_cost_returning_its_gradient_is_called_once_per_point(key, where):
    """``egrad=True``/``rgrad=True`` (SciPy's ``jac=True``): the same optimum as separate
    callbacks, and the gradient at an accepted point reuses the call that gave its cost."""
    problem, calls, lam = _fused_rayleigh(where=where)
    x0 = problem.manifold.random_point(1)
    res = OPTIMIZERS[key]().solve(problem, x0)
    assert res.success and res.fun == pytest.approx(lam, abs=1e-9)
    separate, _, _ = rayleigh(hessian=False)
    twin = OPTIMIZERS[key]().solve(separate, x0)
    assert res.nit == twin.nit and res.fun == pytest.approx(twin.fun, rel=1e-12)  # the same iterates
    # Every accepted point's gradient comes with its cost: fewer calls than costs + gradients.
    assert len(calls) < res.nfev + res.ngev
    assert len(calls) <= res.nfev + (res.ngev - res.nit if key == "tr" else 1)


def test_a_cost_returning_its_gradient_is_checked():
    sphere = Sphere(3)
    with pytest.raises(TypeError, match=r"returns \(f, gradient\)"):
        Problem(sphere, cost=lambda x: 1.0, egrad=True).cost(np.array([1.0, 0.0, 0.0]))
    with pytest.raises(ValueError, match="either egrad"):
        Problem(sphere, cost=lambda x: (1.0, x), egrad=True, rgrad=True)
    with pytest.raises(ValueError, match="either egrad"):
        Problem(sphere, cost=lambda x: (1.0, x), egrad=True, rgrad=lambda x: x)
    with pytest.raises(TypeError, match="egrad must be callable or True"):
        Problem(sphere, cost=lambda x: 1.0, egrad=False)
    p = Problem(sphere, cost=lambda x: (float(x @ x), 2.0 * x), egrad=True)
    x = np.array([0.0, 1.0, 0.0])
    assert p.cost(x) == 1.0 and np.allclose(p.grad(x), 0.0)  # 2x projected on the tangent space
    x[...] = [1.0, 0.0, 0.0]  # mutated in place: a new point, evaluated anew
    assert np.allclose(p.grad(x), 0.0) and p.validate(x)[0] == 1.0


# ---- the strong Wolfe line search --------------------------------------------------


def _problem(case):
    """A problem of the three families and a start point far from its optimum."""
    if case == "rayleigh":
        problem, _, _ = rayleigh()
        return problem, problem.manifold.random_point(1)
    if case == "brockett":
        problem, _ = brockett()
        return problem, problem.manifold.random_point(3)
    problem, _ = karcher()
    return problem, SO3.identity()


def _array(x):
    return x.as_matrix() if hasattr(x, "as_matrix") else np.asarray(x)


def _derivative(problem, x, d, y, g):
    """``φ'(α) = ⟨grad f(y), T_{x→y}(d)⟩``, computed independently of the search."""
    m = problem.manifold
    return float(np.sum(m.inner(y, g, m.transp(x, y, d))))


@pytest.mark.parametrize("case", ["rayleigh", "brockett", "karcher"])
@pytest.mark.parametrize("curvature", [0.9, 0.1])
@pytest.mark.parametrize("scale", [1e-4, 1.0, 1e3], ids=["short", "unit", "long"])
@pytest.mark.parametrize("direction", ["gradient", "rotated"])
def test_strong_wolfe_step_satisfies_both_conditions(case, curvature, scale, direction):
    """From first trials far too short (bracketing), about right and far too long (zoom),
    along −grad and along another descent direction."""
    problem, x = _problem(case)
    m = problem.manifold
    g = problem.grad(x)
    d = -g if direction == "gradient" else -g + 0.9 * m.unit(x, m.random_tangent(x, 7)) * float(m.norm(x, g))
    d_norm, slope = float(np.sqrt(np.sum(m.inner(x, d, d)))), float(np.sum(m.inner(x, g, d)))
    assert slope < 0
    c1 = 1e-4
    ls = StrongWolfe(c1, curvature, initial="previous")  # first trial exactly `alpha_prev`
    f0 = problem.cost(x)
    res = ls.search(problem.cost, problem.grad, m, x, f0, d, d_norm, slope, alpha_prev=scale / d_norm)
    assert res.success and res.wolfe and res.alpha > 0
    assert res.step == pytest.approx(res.alpha * d_norm)
    y = m.retr(x, d * res.alpha)
    np.testing.assert_allclose(_array(res.x), _array(y), rtol=0, atol=1e-14)
    assert problem.cost(y) == res.fun
    assert res.fun <= f0 + c1 * res.alpha * slope  # sufficient decrease
    g_y = problem.grad(res.x)
    np.testing.assert_allclose(np.asarray(res.grad), np.asarray(g_y), rtol=1e-12, atol=1e-12)  # the point's gradient
    assert abs(_derivative(problem, x, d, res.x, g_y)) <= curvature * abs(slope)  # strong curvature condition
    assert res.ngev <= res.nfev <= 25


@pytest.mark.parametrize("key", ["gd-wolfe", "cg-fr", "cg-pr", "cg-hs", "cg-hz"])
@pytest.mark.parametrize("case", ["rayleigh", "brockett", "karcher"])
def test_wolfe_optimizers_converge_to_the_known_optimum(key, case):
    res = OPTIMIZERS[key](max_iterations=5000).solve(*_problem(case))
    assert res.status is Status.GRADIENT_NORM and res.grad_norm <= 1e-6 * res.history.grad_norm[0]
    if case == "rayleigh":
        assert res.fun == pytest.approx(rayleigh()[1], abs=1e-9)
    elif case == "brockett":
        assert res.fun == pytest.approx(brockett()[1], rel=1e-9)
    else:
        assert res.x.dist(karcher()[1]) < 1e-6


@pytest.mark.parametrize("key", ["gd-wolfe", "cg-pr", "cg-hz"])
def test_wolfe_optimizers_evaluate_each_gradient_once(key):
    """The gradient the search evaluated at the accepted point is reused, not recomputed."""
    a = _symmetric(np.random.default_rng(0), 30)
    seen = []

    def egrad(x):
        seen.append(x.tobytes())
        return 2 * a @ x

    problem = Problem(Sphere(30), cost=lambda x: x @ a @ x, egrad=egrad)
    res = OPTIMIZERS[key]().solve(problem, problem.manifold.random_point(1))
    assert res.success and res.ngev == len(seen) and len(set(seen)) == len(seen)
    assert res.ngev < res.nfev + 1  # no more gradients than points whose cost was needed


def test_strong_wolfe_reports_failure_without_decrease():
    """With the gradient's sign flipped, −grad climbs: no trial decreases the cost."""
    problem, _, _ = rayleigh()
    m = problem.manifold
    flipped = Problem(m, cost=problem.cost, rgrad=lambda x: -problem.grad(x))
    x0 = m.random_point(1)
    for opt in (GradientDescent(line_search="wolfe"), ConjugateGradient()):
        res = opt.solve(flipped, x0)
        assert res.status is Status.LINE_SEARCH_FAILED and not res.success
        assert res.nit == 0 and res.fun == problem.cost(x0) and res.x is x0


def test_strong_wolfe_falls_back_to_a_decreasing_point():
    """Out of evaluations before the curvature condition holds: the best point with
    sufficient decrease, flagged as not Wolfe."""
    problem, x = _problem("rayleigh")
    m = problem.manifold
    g = problem.grad(x)
    g_norm = float(m.norm(x, g))
    f0 = problem.cost(x)
    ls = StrongWolfe(curvature=0.1, max_evaluations=2, initial="previous")
    res = ls.search(problem.cost, problem.grad, m, x, f0, -g, g_norm, -(g_norm**2), alpha_prev=1e-6 / g_norm)
    assert res.success and not res.wolfe and res.nfev == 2
    assert res.fun <= f0 - 1e-4 * res.alpha * g_norm**2


@pytest.mark.parametrize(
    "settings",
    [
        {"sufficient_decrease": 0.5, "curvature": 0.5},  # c1 = c2
        {"sufficient_decrease": 0.6, "curvature": 0.1},  # c1 > c2
        {"sufficient_decrease": 0.0},
        {"sufficient_decrease": -1e-4},
        {"curvature": 0.0},
        {"curvature": -0.9},
        {"curvature": 1.0},
        {"max_evaluations": 0},
        {"initial": "bisection"},
        {"refine_tol": -1.0},
    ],
)
def test_strong_wolfe_rejects_bad_settings(settings):
    with pytest.raises(ValueError):
        StrongWolfe(**settings)
    optimizer_settings = {k: v for k, v in settings.items() if k in ("sufficient_decrease", "curvature")}
    if optimizer_settings:
        with pytest.raises(ValueError):
            GradientDescent(line_search="wolfe", **optimizer_settings)
        with pytest.raises(ValueError):
            ConjugateGradient(line_search="wolfe", **optimizer_settings)


def test_line_search_instances_are_used_as_given():
    wolfe = StrongWolfe(curvature=0.5)
    assert GradientDescent(line_search=wolfe).line_search is wolfe
    assert ConjugateGradient(line_search=Backtracking()).line_search == Backtracking()
    assert isinstance(ConjugateGradient().line_search, StrongWolfe)
    assert isinstance(GradientDescent().line_search, Backtracking)
    with pytest.raises(ValueError):
        Backtracking(optimism=0.0)
