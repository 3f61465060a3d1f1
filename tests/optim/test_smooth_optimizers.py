"""Gradient descent, conjugate gradients and trust regions on problems with known optima."""

from __future__ import annotations

import numpy as np
import pytest

from manopt_lie import SO3, NonFiniteError, NotOnManifoldError, ShapeError
from manopt_lie.manifolds import LieGroupManifold, Power, Sphere, Stiefel
from manopt_lie.optim import (
    ConjugateGradient,
    GradientDescent,
    OptimizeResult,
    Problem,
    Status,
    StoppingCriteria,
    TrustRegion,
)

OPTIMIZERS = {
    "gd": lambda **kw: GradientDescent(**kw),
    "cg-fr": lambda **kw: ConjugateGradient(beta="fletcher-reeves", **kw),
    "cg-pr": lambda **kw: ConjugateGradient(**kw),
    "cg-hs": lambda **kw: ConjugateGradient(beta="hestenes-stiefel", **kw),
    "cg-hz": lambda **kw: ConjugateGradient(beta="hager-zhang", **kw),
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


@pytest.mark.parametrize("make", [OPTIMIZERS["gd"], OPTIMIZERS["cg-pr"]], ids=["gd", "cg"])
def test_armijo_descent_is_monotone(make):
    problem, _ = brockett()
    res = make(max_iterations=200).solve(problem, problem.manifold.random_point(4))
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
