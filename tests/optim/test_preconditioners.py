"""The trust region's preconditioner option: names, callables, errors, per-run state."""

from __future__ import annotations

import numpy as np
import pytest

from manopt_lie import SE2, SE3
from manopt_lie.manifolds import Sphere
from manopt_lie.optim import PRECONDITIONERS, LeastSquaresProblem, Problem, Status, TrustRegion

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
