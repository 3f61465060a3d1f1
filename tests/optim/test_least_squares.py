"""Least squares: Gauss-Newton, Levenberg-Marquardt and the trust region's Gauss-Newton model
on problems with known minimizers."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from manopt_lie import SE2, SE3, SO3
from manopt_lie.check import check_gradient
from manopt_lie.errors import ShapeError
from manopt_lie.linalg import BlockStructure, SingularSystemError
from manopt_lie.manifolds import Euclidean, LieGroupManifold, Power, Sphere
from manopt_lie.optim import (
    ConjugateGradient,
    Dogleg,
    Factor,
    GaussNewton,
    LeastSquaresProblem,
    LevenbergMarquardt,
    Linearization,
    Problem,
    SideBySide,
    Status,
    TrustRegion,
)
from manopt_lie.optim.losses import L1, Cauchy, GemanMcClure, Huber, TruncatedL2, parse_loss

from .helpers import between, pose_chain

SOLVERS = {"gn": GaussNewton, "lm": LevenbergMarquardt, "tr": TrustRegion, "dogleg": Dogleg}
solvers = pytest.mark.parametrize("make", SOLVERS.values(), ids=SOLVERS.keys())


@solvers
@pytest.mark.parametrize("group", [SE2, SE3], ids=["SE2", "SE3"])
def test_consistent_pose_graph_is_solved_exactly(make, group):
    problem, truth, x0 = pose_chain(group)
    res = make(rel_cost_decrease=0).solve(problem, x0)  # the gradient defaults: 10⁶ times smaller
    assert res.status is Status.GRADIENT_NORM and res.grad_norm <= 1e-6 * res.history.grad_norm[0]
    res = make(grad_rtol=1e-14, rel_cost_decrease=0).solve(problem, x0)
    assert res.success, res
    assert res.fun < 1e-18
    assert truth.dist(res.x).max() < 1e-8
    np.testing.assert_array_equal(res.x[0].as_matrix(), truth[0].as_matrix())  # the anchor never moves


def rosenbrock():
    """Rosenbrock as least squares: ``r = (10(y − x²), 1 − x)``, minimizer (1, 1)."""

    def residual(p, jac):
        x, y = p[:, 0], p[:, 1]
        r = np.stack([10 * (y - x**2), 1 - x], axis=-1)
        if not jac:
            return r
        j = np.zeros((len(x), 2, 2))
        j[:, 0, 0], j[:, 0, 1], j[:, 1, 0] = -20 * x, 10.0, -1.0
        return r, [j]

    return LeastSquaresProblem(Power(Euclidean(2), 1), [Factor(np.zeros((1, 1), dtype=int), residual)])


@solvers
def test_rosenbrock_minimizer(make):
    res = make(grad_rtol=1e-12, rel_cost_decrease=0).solve(rosenbrock(), np.array([[-1.2, 1.0]]))
    assert res.success, res
    np.testing.assert_allclose(res.x, [[1.0, 1.0]], atol=1e-8)


def robust_rotation_averaging(loss, seed=0):
    """Measurements of one rotation ``R*``: 70 % exact, 30 % arbitrary outliers."""
    rng = np.random.default_rng(seed)
    truth = SO3.random(rng)
    m = 50
    measurements = SO3.concatenate([truth.broadcast_to((35,)), SO3.random(rng, (m - 35,))])

    def residual(r, jac):
        if not jac:
            return measurements.rminus(r)
        tau, _, j_r = measurements.rminus(r, jac=True)
        return tau, [j_r]

    factor = Factor(np.zeros((m, 1), dtype=int), residual, loss=loss)
    return LeastSquaresProblem(Power(LieGroupManifold(SO3), 1), [factor]), truth, truth.rplus([[0.1, -0.1, 0.05]])


@solvers
@pytest.mark.parametrize(
    "loss, tol", [(TruncatedL2(0.3), 1e-9), (GemanMcClure(0.1), 1e-3), (Cauchy(0.05), 1e-2), (Huber(0.01), 2e-2)],
    ids=["truncated", "geman-mcclure", "cauchy", "huber"],
)  # fmt: skip
def test_robust_losses_reject_outliers(make, loss, tol):
    problem, truth, x0 = robust_rotation_averaging(loss)
    res = make(max_iterations=500).solve(problem, x0)
    assert res.success, res
    assert truth.dist(res.x)[0] < tol
    plain, _, _ = robust_rotation_averaging(None)
    assert truth.dist(GaussNewton().solve(plain, x0).x)[0] > 0.1  # what the outliers do unchecked


def test_gradient_of_a_robust_problem_checks_out():
    problem, _, x0 = robust_rotation_averaging(Cauchy(0.5))
    assert check_gradient(problem, x0, rng=0).passed


def test_missing_gauge_is_a_clear_error():
    problem, _, x0 = pose_chain(SE3, n=10, closures=3)
    free = LeastSquaresProblem(problem.manifold, problem.factors)
    with pytest.raises(SingularSystemError, match="gauge"):
        GaussNewton().solve(free, x0)


def test_levenberg_marquardt_history_and_damping():
    problem, _, x0 = pose_chain(SE2, n=20, closures=5)
    res = LevenbergMarquardt().solve(problem, x0)
    assert res.status is Status.GRADIENT_NORM
    damping = res.history.extra["damping"][1:]
    assert np.all(damping > 0) and len(damping) == res.nit
    assert damping[0] == 1e-8  # λ₀
    accepted = ~np.isnan(res.history.step[1:])
    # Divided by 10 after a success, multiplied by ν ≥ 10 after a failure.
    ratio = damping[1:] / damping[:-1]
    np.testing.assert_allclose(ratio[accepted[:-1]], np.maximum(0.1, 1e-15 / damping[:-1][accepted[:-1]]))
    assert np.all(ratio[~accepted[:-1]] >= 10)


@pytest.mark.parametrize("damping", ["identity", "diagonal"])
def test_levenberg_marquardt_dampings_reach_the_optimum(damping):
    problem, _, x0 = pose_chain(SE3, noise=0.01)
    reference = GaussNewton(grad_rtol=1e-12, rel_cost_decrease=0).solve(problem, x0)
    res = LevenbergMarquardt(damping=damping, grad_rtol=1e-12, rel_cost_decrease=0).solve(problem, x0)
    assert res.success and res.fun == pytest.approx(reference.fun, rel=1e-10)
    with pytest.raises(ValueError, match="damping"):
        LevenbergMarquardt(damping="marquardt")
    with pytest.raises(ValueError, match="damping_factor"):
        LevenbergMarquardt(damping_factor=1.0)


def test_levenberg_marquardt_damps_a_singular_system_away():
    """Without a gauge ``H`` is singular: Gauss-Newton refuses it (above), LM raises ``λ``
    until the damped system solves and still reaches a minimizer."""
    problem, _, x0 = pose_chain(SE3, n=10, closures=3)
    free = LeastSquaresProblem(problem.manifold, problem.factors)
    res = LevenbergMarquardt(grad_rtol=1e-10, rel_cost_decrease=0).solve(free, x0)
    assert res.success and res.fun < 1e-16


def test_levenberg_marquardt_leaves_the_linearization_unchanged():
    """The damping goes onto ``H``'s diagonal in place and comes off again, bitwise."""
    problem, _, x0 = pose_chain(SE2, n=15, closures=4)
    hessian = problem.linearize(x0).hessian  # the run reuses this (remembered) linearization
    before = hessian.data.copy()
    res = LevenbergMarquardt(max_iterations=1).solve(problem, x0)
    assert res.nit == 1
    np.testing.assert_array_equal(hessian.data, before)


def test_problem_validation():
    manifold = Power(LieGroupManifold(SE2), 3)
    with pytest.raises(ValueError, match="outside"):
        LeastSquaresProblem(manifold, [Factor(np.array([[0, 3]]), between(SE2.identity((1,))))])
    with pytest.raises(ValueError):
        LeastSquaresProblem(manifold, [])
    with pytest.raises(TypeError):
        LeastSquaresProblem(Sphere(3), [Factor(np.array([[0]]), lambda x, jac: x)])
    with pytest.raises(ValueError):
        Factor(np.zeros((0, 2), dtype=int), between(SE2.identity((1,))))
    with pytest.raises(TypeError, match="LeastSquaresProblem"):
        GaussNewton().solve(Problem(Euclidean(2), cost=lambda x: 0.0, egrad=lambda x: x), np.zeros(2))


def test_parse_loss():
    assert parse_loss("huber:2") == Huber(2.0)
    assert parse_loss("cauchy") == Cauchy(1.0)
    assert parse_loss(None).rho(np.array(4.0)) == 4.0
    with pytest.raises(ValueError, match="unknown"):
        parse_loss("tukey:1")
    with pytest.raises(ValueError):
        parse_loss("huber:-1")


@pytest.mark.parametrize("loss", [Huber(0.7), Cauchy(0.7), GemanMcClure(0.7), TruncatedL2(0.7), L1(0.7)], ids=repr)
def test_loss_weights_are_derivatives(loss):
    s = np.linspace(0.01, 3.0, 50)
    s = s[np.abs(s - 0.49) > 1e-3]  # TruncatedL2 has a kink at c²
    h = 1e-6
    np.testing.assert_allclose((loss.rho(s + h) - loss.rho(s - h)) / (2 * h), loss.weight(s), atol=1e-6)
    np.testing.assert_allclose(loss.rho(np.array([1e-8])), 1e-8, rtol=1e-6)  # ρ(s) ≈ s near 0


def _counting(problem):
    """The problem with its one factor's residual calls counted, by ``jac``."""
    calls = {True: 0, False: 0}
    (factor,) = problem.factors

    def residual(xi, xj, jac=False):
        calls[jac] += 1
        return factor.residual(xi, xj, jac)

    counted = Factor(factor.variables, residual, name=factor.name)
    return LeastSquaresProblem(problem.manifold, [counted], fixed=np.flatnonzero(problem.fixed)), calls


def test_trial_cost_keeps_the_jacobians_for_the_linearization_at_that_point():
    problem, _, x0 = pose_chain(SE3, n=12, closures=4, noise=0.01)
    counted, calls = _counting(problem)
    f = counted.trial_cost(x0)
    assert calls == {True: 1, False: 0} and f == pytest.approx(problem.cost(x0), rel=1e-14)
    assert counted.kept_at(x0)
    lin, fresh = counted.linearize(x0), problem.linearize(x0)
    assert calls == {True: 1, False: 0} and not counted.kept_at(x0)  # used once, not evaluated again
    assert lin.cost == fresh.cost
    np.testing.assert_array_equal(lin.grad, fresh.grad)
    np.testing.assert_array_equal(lin.hessian.toarray(), fresh.hessian.toarray())
    # Kept at another point (a copy of its value: moving x afterwards does not fool it).
    x1 = x0.rplus(1e-3 * np.ones((12, 6)))
    counted.trial_cost(x1)
    assert not counted.kept_at(x0)
    counted.linearize(x0.rplus(np.zeros((12, 6))))  # x0's value: remembered, nothing evaluated
    assert calls == {True: 2, False: 0}
    counted.linearize(x1.rplus(1e-3 * np.ones((12, 6))))  # elsewhere: evaluated, the kept trial dropped
    assert calls == {True: 3, False: 0} and not counted.kept_at(x1)


@pytest.mark.parametrize("make", [LevenbergMarquardt, GaussNewton, Dogleg])
def test_accepted_trials_are_evaluated_once(make):
    """From a good start every trial is accepted: one residual evaluation per iteration
    (the trial's, with Jacobians, reused by the linearization there), none without Jacobians."""
    problem, _, x0 = pose_chain(SE3, n=30, closures=8, noise=0.01)
    counted, calls = _counting(problem)
    res = make(rel_cost_decrease=1e-12, grad_rtol=1e-12).solve(counted, x0)
    accepted = int(np.sum(~np.isnan(res.history.step[1:])))
    assert accepted == res.nit > 0
    assert calls[False] == 0 and calls[True] == 1 + res.nit  # x₀'s linearization, then the trials
    assert res.nfev == 1 + res.nit
    reference = make(rel_cost_decrease=1e-12, grad_rtol=1e-12).solve(problem, x0)
    assert res.fun == reference.fun and res.nit == reference.nit


def test_a_rejected_trial_keeps_no_jacobians_for_the_next():
    """Trial i keeps its Jacobians iff trial i−1 was accepted (the first always): after a
    rejection they would likely be wasted."""
    problem, _, x0 = pose_chain(SE2, n=20, closures=6)
    far = x0.rplus(3.0 * np.random.default_rng(2).standard_normal((20, 3)))  # a poor start: 4 rejections
    counted, calls = _counting(problem)
    res = LevenbergMarquardt(max_iterations=60).solve(counted, far)
    accepted = ~np.isnan(res.history.step[1:])
    keep = np.concatenate([[True], accepted[:-1]])
    assert (~accepted).sum() > 0
    assert calls[False] == int((~keep).sum())
    assert calls[True] == 1 + int(keep.sum()) + int((accepted & ~keep).sum())


@pytest.mark.parametrize("make", [LevenbergMarquardt, Dogleg])
def test_a_rejected_trial_does_not_stay_kept(make, monkeypatch):
    """The Jacobians a rejected trial kept are dropped at once: they would otherwise stay
    resident through the next damped factorization, the peak of a large solve."""
    problem, _, x0 = pose_chain(SE2, n=20, closures=6)
    far = x0.rplus(3.0 * np.random.default_rng(2).standard_normal((20, 3)))
    counted, _ = _counting(problem)
    trials = []
    keep = LeastSquaresProblem.trial_cost

    def recording(self, x):
        trials.append(x)
        return keep(self, x)

    monkeypatch.setattr(LeastSquaresProblem, "trial_cost", recording)
    rejected = []

    def callback(info):
        if info.iteration > 0 and np.isnan(info.step) and trials:
            rejected.append(counted.kept_at(trials[-1]))

    make(max_iterations=60).solve(counted, far, callback=callback)
    assert rejected and not any(rejected)
    counted.trial_cost(x0)
    counted.discard_trial()
    assert not counted.kept_at(x0)


def _counting_hessians(monkeypatch):
    """The number of ``H`` assemblies (``BlockStructure._hessian`` calls: the problem's unchecked
    assembly), as a one-entry list."""
    count, assemble = [0], BlockStructure._hessian

    def counted(self, *args, **kw):
        count[0] += 1
        return assemble(self, *args, **kw)

    monkeypatch.setattr(BlockStructure, "_hessian", counted)
    return count


@pytest.mark.parametrize("make", [LevenbergMarquardt, GaussNewton, Dogleg])
def test_the_last_point_of_a_run_assembles_no_hessian(make, monkeypatch):
    """``H`` is assembled where a step is computed from it: one per iteration, none at the
    point where the run stops, which still reports its gradient norm."""
    problem, _, x0 = pose_chain(SE3, n=30, closures=8, noise=0.01)
    count = _counting_hessians(monkeypatch)
    res = make().solve(problem, x0)
    assert res.status is Status.COST_DECREASE and res.nit > 0
    assert count[0] == res.nit
    lin = problem.linearize(res.x)  # remembered: its H is assembled on demand, once
    assert res.grad_norm == pytest.approx(float(np.linalg.norm(lin.grad)), rel=1e-12)
    h = lin.hessian
    assert count[0] == res.nit + 1 and lin.hessian is h


def test_a_deferred_hessian_is_the_normal_equations_and_checks_its_jacobians(monkeypatch):
    problem, _, x0 = pose_chain(SE3, n=12, closures=4, noise=0.01)
    evaluation = problem._evaluate(x0)
    lin = problem.linearize(x0)
    h, g = problem.structure.normal_equations(evaluation[2], evaluation[1])  # the reference, not counted
    problem._local.linearization = None  # linearize again, the assemblies counted
    count = _counting_hessians(monkeypatch)
    lin = problem.linearize(x0)
    assert count[0] == 0 and "not assembled" in repr(lin)
    fixed_diagonal = np.repeat(problem.fixed, problem.dims).astype(float)
    h = problem.structure.add_diagonal(h, fixed_diagonal)  # 1 on the gauge's fixed pose
    np.testing.assert_allclose(lin.grad.reshape(-1), g, rtol=0, atol=1e-13 * np.abs(g).max())
    assert lin.is_finite() and count[0] == 0  # the Jacobians checked, H still deferred
    np.testing.assert_array_equal(lin.hessian.toarray(), h.toarray())
    assert count[0] == 1 and "not assembled" not in repr(lin)
    jacobians = [np.array(evaluation[2][0])]
    jacobians[0][3, 0, 0] = np.inf
    deferred = Linearization(lin.cost, lin.grad, lambda: h, lin.residuals, lin.weights, jacobians=jacobians)
    assert not deferred.is_finite()


def test_a_recycled_hessian_is_assembled_over_the_old_one():
    """``new.recycle(old)``: the new ``H`` is written into the old one's arrays (the same
    values as a fresh assembly), and the old linearization gives up its ``H``."""
    problem, _, x0 = pose_chain(SE3, n=12, closures=4, noise=0.01)
    old = problem.linearize(x0)
    h_old = old.hessian
    data = h_old.data
    x1 = problem.manifold.retr(x0, 1e-2 * np.ones_like(old.grad))
    fresh = problem.linearize(x1).hessian.toarray()
    problem.linearize(x0)  # a new point, then x1 again: a new linearization, H deferred
    new = problem.linearize(x1)
    new.recycle(old)
    assert "recycled" in repr(old)
    with pytest.raises(RuntimeError, match="recycled"):
        old.hessian  # noqa: B018
    assert new.hessian is h_old and new.hessian.data is data
    np.testing.assert_array_equal(new.hessian.toarray(), fresh)
    # No-ops: an assembled H stays; an old H never assembled, or given up, gives nothing.
    new.recycle(problem.linearize(x0))
    assert new.hessian is h_old
    deferred = problem.linearize(problem.manifold.retr(x1, 1e-2 * np.ones_like(old.grad)))
    deferred.recycle(old)
    assert deferred.hessian is not h_old


def test_an_accepted_step_recycles_the_hessian(monkeypatch):
    """LM, GN and the dogleg assemble each iteration's ``H`` over the last one: one ``H`` of
    the problem is alive at a time (a 10⁵-pose grid: 23 MB less at the solve's peak)."""
    outs, assemble = [], BlockStructure._hessian

    def recording(self, blocks, weights, out=None):
        h = assemble(self, blocks, weights, out)
        outs.append((out, h.data.__array_interface__["data"][0]))
        return h

    monkeypatch.setattr(BlockStructure, "_hessian", recording)
    for make in (LevenbergMarquardt, GaussNewton, Dogleg):
        problem, _, x0 = pose_chain(SE3, n=30, closures=8, noise=0.05)
        outs.clear()
        res = make().solve(problem, x0)
        assert res.status is Status.COST_DECREASE and res.nit >= 2
        assert outs[0][0] is None and all(out is not None for out, _ in outs[1:])
        assert len({address for _, address in outs}) == 1


def test_gradient_solvers_on_least_squares_assemble_no_hessian(monkeypatch):
    """Smooth solvers ask a least-squares problem for gradients only: no ``H`` is assembled."""
    problem, _, x0 = pose_chain(SE2, n=20, closures=6, noise=0.01)
    count = _counting_hessians(monkeypatch)
    res = ConjugateGradient(max_iterations=30).solve(problem, x0)
    assert res.nit > 0 and count[0] == 0


def test_side_by_side_jacobians_are_read_whole_and_agree_with_a_list():
    """A factor with fresh Jacobians returned as a SideBySide is read as its one block — the
    fixed variable's columns are zeroed in that very array — and as a plain list concatenated:
    the same linearization either way."""
    problem, _, x0 = pose_chain(SE3, n=10, closures=3, noise=0.01)
    (factor,) = problem.factors
    blocks = []

    def joined(xi, xj, jac=False):
        if not jac:
            return factor.residual(xi, xj)
        r, (j_i, j_j) = factor.residual(xi, xj, jac=True)
        blocks.append(np.concatenate([j_i, j_j], axis=-1))
        return r, SideBySide(blocks[-1], (6, 6))

    def listed(xi, xj, jac=False):
        out = joined(xi, xj, jac)
        return out if not jac else (out[0], list(out[1]))

    fixed = np.flatnonzero(problem.fixed)
    lins = [LeastSquaresProblem(problem.manifold, [Factor(factor.variables, residual, fresh_jacobians=True)],
                                fixed=fixed).linearize(x0) for residual in (joined, listed)]  # fmt: skip
    np.testing.assert_array_equal(lins[0].grad, lins[1].grad)
    np.testing.assert_array_equal(lins[0].hessian.toarray(), lins[1].hessian.toarray())
    first = np.flatnonzero(factor.variables[:, 0] == fixed[0])  # edges leaving the fixed pose
    assert first.size and not blocks[0][first, :, :6].any()  # zeroed in the factor's own block
    assert blocks[1][first, :, :6].any()  # the list's slices were concatenated, not written into
    block = SideBySide(np.zeros((4, 6, 9)), (6, 3))
    assert [j.shape for j in block] == [(4, 6, 6), (4, 6, 3)] and np.shares_memory(block[1], block.block)
    with pytest.raises(ValueError, match="SideBySide"):
        SideBySide(np.zeros((4, 6, 9)), (6, 6))


def test_small_problems_store_their_normal_equations_dense():
    """Up to DENSE_MAX unknowns the structure stores every entry of H (H.data the matrix), and
    the solution is the same as through the sparse pattern."""
    from manopt_lie.linalg import DENSE_MAX

    small, _, x0 = pose_chain(SE3, n=DENSE_MAX // 6, closures=3, noise=0.01)
    large, _, y0 = pose_chain(SE3, n=DENSE_MAX // 6 + 1, closures=3, noise=0.01)
    lin = small.linearize(x0)
    large.linearize(y0)
    assert small.structure.dense and not large.structure.dense
    n = small.structure.n
    np.testing.assert_array_equal(lin.hessian.data.reshape(n, n).T, lin.hessian.toarray())
    v = small.factors[0].variables
    _, jacobians = small.factors[0].residual(x0[v[:, 0]], x0[v[:, 1]], jac=True)
    block = np.concatenate(jacobians, axis=-1)
    block[:, :, :6][small.fixed[v[:, 0]]] = 0.0  # the fixed pose's columns dropped…
    block[:, :, 6:][small.fixed[v[:, 1]]] = 0.0
    expected = BlockStructure(small.dims, [(v, 6)]).hessian([block]).toarray()
    expected[np.diag_indices(n)] += np.repeat(small.fixed, 6)  # …and 1s on its diagonal
    np.testing.assert_allclose(lin.hessian.toarray(), expected, rtol=0, atol=1e-12 * np.abs(expected).max())
    for problem, x in ((small, x0), (large, y0)):  # H v: through the dense matrix, or the sparse one
        linear = problem.linearize(x)
        u = np.random.default_rng(1).standard_normal(problem.structure.n)
        hv = linear.hessian.toarray() @ u
        np.testing.assert_allclose(linear.hessian_product(u), hv, rtol=0, atol=1e-13 * np.abs(hv).max())
    res = LevenbergMarquardt().solve(small, x0)
    assert res.success


def test_a_declared_residual_dim_is_checked():
    """``residual_dim`` is a positive integer or ``None``; residuals of another length are a
    ShapeError naming the factor, at the first evaluation."""
    edges = np.array([[0, 1]])
    for bad in (0, -3, 2.5, True, "3"):
        with pytest.raises(ValueError, match="between: residual_dim"):
            Factor(edges, lambda xi, xj, jac: None, name="between", residual_dim=bad)
    problem, _, x0 = pose_chain(SE2, n=60, closures=10)
    f = problem.factors[0]
    declared = LeastSquaresProblem(problem.manifold, [replace(f, residual_dim=4)], fixed=[0])
    with pytest.raises(ShapeError, match=r"between: .*expected \(m, k\) = \(\d+, 4\)"):
        declared.linearize(x0)


@pytest.mark.parametrize("n", [12, 200], ids=["dense", "sparse"])
def test_declared_residual_dims_build_the_structure_before_the_first_residuals(monkeypatch, n):
    """Declared lengths: the structure is started before any residual is evaluated, and it is the
    structure (the pooled object itself) and the linearization of the same factors undeclared."""
    from manopt_lie.linalg import clear_caches

    problem, _, x0 = pose_chain(SE3, n=n, closures=n // 4, noise=0.01)
    undeclared = problem.factors[0]
    events: list[str] = []
    started = BlockStructure._shared_later.__func__

    def spy_start(cls, *args):
        events.append("structure")
        return started(cls, *args)

    def spy_residual(*args, jac):
        events.append("residual")
        return undeclared.residual(*args, jac=jac)

    monkeypatch.setattr(BlockStructure, "_shared_later", classmethod(spy_start))
    clear_caches()
    declared = replace(undeclared, residual=spy_residual, residual_dim=6)
    first = LeastSquaresProblem(problem.manifold, [declared], fixed=[0])
    lin = first.linearize(x0)
    assert events == ["structure", "residual"]
    again = problem.linearize(x0)  # undeclared: built after its residuals, here from the pool
    assert problem.structure is first.structure
    np.testing.assert_array_equal(lin.hessian.toarray(), again.hessian.toarray())
    np.testing.assert_array_equal(lin.grad, again.grad)
    clear_caches()


def test_an_edge_on_one_variable_twice_is_refused_alike_declared_or_not():
    problem, _, x0 = pose_chain(SE2, n=200, closures=5)
    f = problem.factors[0]
    edges = f.variables.copy()
    edges[7] = [5, 5]
    messages = []
    for r in (None, 3):
        bad = LeastSquaresProblem(problem.manifold, [replace(f, variables=edges, residual_dim=r)], fixed=[0])
        with pytest.raises(ValueError, match="factor 0, edge 7: touches variable 5 in two slots") as err:
            bad.linearize(x0)
        messages.append(str(err.value))
    assert messages[0] == messages[1]
