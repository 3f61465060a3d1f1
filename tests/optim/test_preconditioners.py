"""The trust region's preconditioner option: names, callables, errors, per-run state."""

from __future__ import annotations

import numpy as np
import pytest

from manopt_lie import SE2, SE3
from manopt_lie.manifolds import Sphere
from manopt_lie.optim import PRECONDITIONERS, LeastSquaresProblem, LevenbergMarquardt, Problem, Status, TrustRegion
from manopt_lie.optim.trust_region import default_max_radius
from manopt_lie.problems.synthetic.landmarks import landmark_world

from .helpers import pose_chain


@pytest.mark.parametrize("preconditioner", ["auto", "gauss-newton", "block-jacobi", "identity"])
def test_every_named_preconditioner_reaches_the_optimum(preconditioner):
    problem, _, x0 = pose_chain(SE3, n=40, closures=15, noise=0.05)
    reference = TrustRegion(grad_rtol=1e-10, rel_cost_decrease=0).solve(problem, x0)
    res = TrustRegion(grad_rtol=1e-10, rel_cost_decrease=0, preconditioner=preconditioner, max_iterations=3000)
    res = res.solve(problem, x0)
    assert res.status is Status.GRADIENT_NORM, res
    assert res.fun == pytest.approx(reference.fun, rel=1e-9)


def test_a_better_preconditioner_needs_fewer_inner_iterations():
    problem, _, x0 = pose_chain(SE2, n=60, closures=20, noise=0.05)
    inner = {
        name: TrustRegion(preconditioner=name).solve(problem, x0).history.extra["inner_iterations"][1:].sum()
        for name in ("gauss-newton", "block-jacobi", "identity")
    }
    assert inner["gauss-newton"] < inner["block-jacobi"] < inner["identity"]
    # Gauss-Newton model + its own inverse as preconditioner: tCG is exact in one step.
    auto = TrustRegion().solve(problem, x0).history.extra["inner_iterations"][1:]
    assert np.all(auto == 1)


def test_the_default_radius_is_in_the_units_of_the_gauss_newton_norm():
    """With a preconditioner built from ``G = JᵀWJ`` the region's norm is in √cost units: the
    default ``Δ̄`` is at least ``√(2 f(x₀))``, which no Gauss-Newton step exceeds; without one it
    stays ``typical_dist``, as does a zero or non-finite cost."""
    assert default_max_radius(80.0, 1.8e8, True) == pytest.approx(np.sqrt(3.6e8))
    assert default_max_radius(80.0, 10.0, True) == 80.0
    assert default_max_radius(80.0, 1.8e8, False) == 80.0
    assert default_max_radius(80.0, 0.0, True) == default_max_radius(80.0, np.inf, True) == 80.0
    problem, _, x0 = pose_chain(SE2, n=20, closures=5, noise=0.05)
    lin = problem.linearize(x0)
    gauss_newton = -np.linalg.solve(lin.hessian.toarray(), lin.grad.reshape(-1))
    assert -lin.grad.reshape(-1) @ gauss_newton <= 2 * lin.cost  # ‖η‖²_G = 2(m(0) − m(η)) ≤ 2f


def test_far_from_the_solution_the_gauss_newton_norm_needs_few_steps():
    """A landmark world started far from its optimum in distance (landmarks from the chordal
    poses): the first Gauss-Newton step is 16 typical distances long in the norm of ``G``. With the
    radius of that norm the trust region takes as few steps as Levenberg-Marquardt's (20 with
    a distance-sized ``Δ̄``), to the same optimum."""
    world = landmark_world(200, 50, seed=0).graph
    problem, x0 = world.problem("geodesic"), world.initialize("chordal", seed=0)
    lm = LevenbergMarquardt().solve(problem, x0)
    tr = TrustRegion().solve(problem, x0)
    assert tr.status.converged and tr.nit <= lm.nit + 3, (tr.nit, lm.nit)
    assert tr.fun == pytest.approx(lm.fun, rel=1e-6)
    capped = TrustRegion(max_radius=problem.manifold.typical_dist).solve(problem, x0)
    assert capped.nit >= 3 * tr.nit  # the old default: every early step on a boundary of distance size


def test_callables_are_used_as_given():
    problem, _, x0 = pose_chain(SE2, n=20, closures=5, noise=0.05)
    seen = []

    def scaled(x, r):
        seen.append(x)
        return 0.5 * r

    res = TrustRegion(preconditioner=scaled).solve(problem, x0)
    assert res.success and seen and seen[0] is x0


def test_names_that_need_least_squares_refuse_a_plain_problem():
    a = np.diag([3.0, 1.0, 2.0])
    plain = Problem(Sphere(3), cost=lambda x: x @ a @ x, egrad=lambda x: 2 * a @ x, ehess=lambda x, u: 2 * a @ u)
    x0 = np.ones(3) / np.sqrt(3)
    for name in ("gauss-newton", "block-jacobi"):
        with pytest.raises(ValueError, match=f"preconditioner='{name}'.*LeastSquaresProblem.*Problem"):
            TrustRegion(preconditioner=name).solve(plain, x0)
    for name in ("auto", "identity"):
        assert TrustRegion(preconditioner=name).solve(plain, x0).fun == pytest.approx(1.0)


def test_bad_preconditioners():
    assert PRECONDITIONERS == ("auto", "gauss-newton", "block-jacobi", "identity")
    with pytest.raises(ValueError, match="unknown preconditioner 'ilu'; choose from auto, gauss-newton"):
        TrustRegion(preconditioner="ilu")
    with pytest.raises(TypeError, match="callable"):
        TrustRegion(preconditioner=None)  # type: ignore[arg-type]


def test_no_preconditioner_state_in_the_problem_or_the_optimizer():
    """Runs nest (one inside another's callback) and give the results of separate runs."""
    assert not hasattr(LeastSquaresProblem, "preconditioner")
    problem, _, x0 = pose_chain(SE3, n=30, closures=10, noise=0.05)
    other, _, y0 = pose_chain(SE3, n=30, closures=10, noise=0.05, seed=5)
    opt = TrustRegion()
    alone = [opt.solve(problem, x0), opt.solve(other, y0)]
    inner = []

    def nested(info):
        if info.iteration in (1, 2):
            inner.append(opt.solve(other, y0))

    outer = opt.solve(problem, x0, callback=nested)
    assert outer.fun == alone[0].fun and outer.nit == alone[0].nit
    assert [r.fun for r in inner] == [alone[1].fun] * 2
    assert vars(opt).keys() == vars(TrustRegion()).keys()  # nothing added by the runs
