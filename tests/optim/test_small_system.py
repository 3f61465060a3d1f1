"""The compiled Gauss-Newton, Levenberg-Marquardt and dogleg of small pose graphs
(``optim._small_system``) against the Python loops they mirror: the same statuses, counts,
histories and points, up to round-off; and the Python loop wherever the compiled one is out of
its scope or declines."""

from __future__ import annotations

import functools
import threading

import numpy as np
import pytest

from manopt_lie import SE2, SE3, _kernels
from manopt_lie.errors import NonFiniteError
from manopt_lie.factors import between_factor
from manopt_lie.factors.noise import Information, Isotropic
from manopt_lie.linalg import SingularSystemError
from manopt_lie.manifolds import LieGroupManifold, Power
from manopt_lie.optim import Dogleg, GaussNewton, LeastSquaresProblem, LevenbergMarquardt, Status, _small_system
from manopt_lie.optim.optimizer import Run
from manopt_lie.problems import g2o, synthetic

pytestmark = pytest.mark.skipif(_small_system._library() is None, reason="no C compiler: nothing compiled to test")


def pose_graph(group, n=9, closures=6, seed=0, noise="unit", spread=0.1, fixed=(0,), measurement_noise=0.05):
    """A random walk, odometry and loop closures measured with noise, the between factor with
    ``noise`` (``"unit"``, ``"isotropic"``: one σ for all, ``"per-edge"``: an ``Ω`` per edge), and a
    start ``spread`` away from the truth."""
    rng = np.random.default_rng(seed)
    poses = [group.identity()]
    for step in 0.5 * rng.standard_normal((n - 1, group.dim)):
        poses.append(poses[-1].rplus(step))
    truth = group.stack(poses)
    loops = rng.choice(n, size=(closures, 2))
    edges = np.concatenate([np.stack([np.arange(n - 1), np.arange(1, n)], 1), loops[loops[:, 0] != loops[:, 1]]])
    noise_draw = measurement_noise * rng.standard_normal((len(edges), group.dim))
    z = truth[edges[:, 0]].between(truth[edges[:, 1]]).rplus(noise_draw)
    model = {"unit": None, "isotropic": Isotropic(0.2, group.dim)}.get(noise)
    if noise == "per-edge":
        a = rng.standard_normal((len(edges), group.dim, group.dim))
        model = Information(a @ np.swapaxes(a, 1, 2) + group.dim * np.eye(group.dim))
    factor = between_factor(edges, z, model)
    problem = LeastSquaresProblem(Power(LieGroupManifold(group), n), [factor], fixed=list(fixed))
    start = spread * rng.standard_normal((n, group.dim))
    start[list(fixed)] = 0.0
    return problem, truth.rplus(start)


def python_loop(monkeypatch, optimizer, problem, x0):
    with monkeypatch.context() as m:
        m.setattr(_small_system, "solve", lambda *args: None)
        return optimizer.solve(problem, x0)


def compiled(optimizer, problem, x0):
    result = optimizer.solve(problem, x0)
    assert problem.structure is None, "the compiled loop should have run (the Python loop builds the structure)"
    return result


def assert_same_run(a, b):
    assert (a.status, a.nit, a.nfev, a.ngev) == (b.status, b.nit, b.nfev, b.ngev)
    ha, hb = a.history, b.history
    np.testing.assert_allclose(ha.cost, hb.cost, rtol=1e-9, atol=1e-12 * hb.cost[0])
    np.testing.assert_allclose(ha.grad_norm, hb.grad_norm, rtol=1e-6, atol=1e-9 * hb.grad_norm[0])
    np.testing.assert_allclose(ha.step, hb.step, rtol=1e-6, atol=1e-12)
    assert sorted(ha.extra) == sorted(hb.extra)
    for key, expected in hb.extra.items():  # damping, alpha, radius, shift and kind exact; rho to round-off
        # (a gain ratio near convergence divides two decreases a few digits above round-off)
        np.testing.assert_allclose(ha.extra[key], expected, rtol={"rho": 1e-4, "radius": 1e-6}.get(key, 0), atol=1e-9)
    np.testing.assert_allclose(a.x.as_matrix(), b.x.as_matrix(), atol=1e-9)
    assert a.fun == pytest.approx(b.fun, rel=1e-9, abs=1e-12)


METHODS = [GaussNewton, LevenbergMarquardt, Dogleg]


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize(
    ("group", "n", "noise"),
    [(SE3, 9, "unit"), (SE3, 12, "isotropic"), (SE3, 8, "per-edge"), (SE2, 30, "unit"), (SE2, 20, "per-edge"),
     (SE2, 128, "isotropic")],  # 384 unknowns: the largest the compiled loop takes
)
def test_converges_as_the_python_loop(monkeypatch, method, group, n, noise):
    optimizer = method()
    problem, x0 = pose_graph(group, n, noise=noise, seed=n)
    fast = compiled(optimizer, problem, x0)
    assert fast.status.converged and fast.nit >= 2
    assert_same_run(fast, python_loop(monkeypatch, optimizer, pose_graph(group, n, noise=noise, seed=n)[0], x0))


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize(
    ("group", "n", "closures", "fixed"),
    [(SE3, 10, 6, (3, 7)), (SE2, 5, 6, (0, 1, 2, 3, 4)), (SE2, 2, 0, (0,))],
    ids=["fixed-inside", "all-fixed", "two-poses"],
)
def test_fixed_poses_as_the_python_loop(monkeypatch, method, group, n, closures, fixed):
    make = functools.partial(pose_graph, group, n, closures=closures, seed=n, fixed=fixed)
    problem, x0 = make()
    fast = compiled(method(), problem, x0)
    assert np.array_equal(fast.x.as_matrix()[list(fixed)], x0.as_matrix()[list(fixed)])  # never moved
    assert_same_run(fast, python_loop(monkeypatch, method(), make()[0], x0))


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("side", [10, 16])  # 300 and 768 unknowns: H banded in the reverse Cuthill-McKee order
def test_a_banded_grid_as_the_python_loop(monkeypatch, method, side):
    graph = synthetic.grid2d(side, side, seed=side).graph
    x0 = graph.chordal_initialization()
    run = Run("", graph.problem("geodesic"), method().stopping.for_problem(graph.problem("geodesic")), None)
    plan = _small_system.plan(method(), run)
    assert plan is not None and plan.kd < 3 * side * 3  # a band of a few rows of the grid
    fast = compiled(method(), graph.problem("geodesic"), x0)
    assert_same_run(fast, python_loop(monkeypatch, method(), graph.problem("geodesic"), x0))


def assert_same_until_roundoff(a, b):
    """Runs to the end of what double precision resolves: the same until the decreases are
    round-off (where gain ratios are noise, and the runs part), then the same status and cost."""
    cost = b.history.cost
    resolved = int(np.argmax(np.abs(np.diff(cost)) < 1e-9 * cost[0])) + 1  # iterations with a real decrease
    assert a.status is b.status and a.status.converged
    np.testing.assert_allclose(a.history.cost[:resolved], cost[:resolved], rtol=1e-9)
    for key, expected in b.history.extra.items():
        np.testing.assert_allclose(a.history.extra[key][:resolved], expected[:resolved], rtol=1e-6, atol=1e-9)
    assert a.fun == pytest.approx(b.fun, rel=1e-12)


@pytest.mark.parametrize(
    ("optimizer", "group", "spread", "status"),
    [  # far from the optimum: rejected steps (LM, dogleg) or backtracking (GN)
        (LevenbergMarquardt(), SE3, 2.0, Status.COST_DECREASE),
        (LevenbergMarquardt(), SE2, 4.0, Status.COST_DECREASE),
        (LevenbergMarquardt(max_iterations=3), SE3, 2.0, Status.MAX_ITERATIONS),
        (LevenbergMarquardt(initial_damping=1.0, damping_factor=3.0), SE3, 2.0, Status.COST_DECREASE),
        (GaussNewton(), SE3, 2.0, Status.COST_DECREASE),
        (GaussNewton(), SE2, 4.0, Status.COST_DECREASE),
        (GaussNewton(max_backtracks=0, sufficient_decrease=0.5), SE3, 2.0, Status.LINE_SEARCH_FAILED),
        (Dogleg(), SE3, 2.0, Status.COST_DECREASE),
        (Dogleg(), SE2, 4.0, Status.COST_DECREASE),
        (Dogleg(initial_radius=1e-3), SE3, 2.0, Status.COST_DECREASE),  # the radius grows
    ],
    ids=lambda v: type(v).__name__ if isinstance(v, (GaussNewton, LevenbergMarquardt, Dogleg)) else None,
)
def test_every_branch_as_the_python_loop(monkeypatch, optimizer, group, spread, status):
    make = functools.partial(pose_graph, group, 10, closures=12, seed=2, spread=spread, measurement_noise=1.0)
    problem, x0 = make()
    fast = compiled(optimizer, problem, x0)
    assert fast.status is status
    assert_same_run(fast, python_loop(monkeypatch, optimizer, make()[0], x0))
    rho = fast.history.extra.get("rho")
    if rho is not None and status is Status.COST_DECREASE and group is SE2:
        assert (rho[1:] <= 0).any(), "the case was meant to reject steps"


@pytest.mark.parametrize(
    "optimizer",
    [
        GaussNewton(rel_cost_decrease=0.0, grad_rtol=0.0),  # to a collapse of the step
        LevenbergMarquardt(rel_cost_decrease=0.0, grad_rtol=0.0),
        LevenbergMarquardt(max_damping=1e-6, rel_cost_decrease=0.0, grad_rtol=0.0, grad_atol=0.0),  # the largest λ
        Dogleg(rel_cost_decrease=0.0, grad_rtol=0.0),  # the radius below min_step
    ],
    ids=["gn", "lm", "lm-largest-damping", "dogleg"],
)
def test_runs_to_the_end_as_the_python_loop(monkeypatch, optimizer):
    make = functools.partial(pose_graph, SE3, 10, closures=12, seed=3, spread=1.5, measurement_noise=0.3)
    problem, x0 = make()
    fast = compiled(optimizer, problem, x0)
    assert fast.status in (Status.STEP_SIZE, Status.GRADIENT_NORM)
    assert_same_until_roundoff(fast, python_loop(monkeypatch, optimizer, make()[0], x0))


@pytest.mark.parametrize("method", METHODS)
def test_no_iteration_returns_the_start(monkeypatch, method):
    problem, x0 = pose_graph(SE3, 6, seed=5)
    fast = compiled(method(max_iterations=0), problem, x0)
    assert fast.status is Status.MAX_ITERATIONS and fast.nit == 0 and fast.x is x0 and not fast.history.extra
    reference = python_loop(monkeypatch, method(max_iterations=0), pose_graph(SE3, 6, seed=5)[0], x0)
    assert (reference.nfev, reference.fun) == (fast.nfev, pytest.approx(fast.fun, rel=1e-12))


@pytest.mark.parametrize("method", [LevenbergMarquardt, Dogleg])
def test_the_gauge_free_graph_as_the_python_loop(monkeypatch, method):
    """No pose fixed: ``H`` is singular and only LM's damping (the dogleg's shift of its
    Gauss-Newton leg) makes the system definite; the gauge itself is then round-off amplified by
    ``1/λ``, so the runs agree on the cost and on the poses relative to each other."""
    make = functools.partial(pose_graph, SE2, 12, seed=4, fixed=())
    problem, x0 = make()
    fast = compiled(method(), problem, x0)
    reference = python_loop(monkeypatch, method(), make()[0], x0)
    assert (fast.status, fast.nit) == (reference.status, reference.nit)
    np.testing.assert_allclose(fast.history.cost, reference.history.cost, rtol=1e-9)
    relative = [r.x[0].between(r.x).as_matrix() for r in (fast, reference)]
    np.testing.assert_allclose(*relative, atol=1e-6)


def test_gauss_newton_on_a_singular_system_raises_as_the_python_loop():
    """Gauss-Newton does not damp: the compiled loop hands the run over, and the Python loop raises."""
    problem, x0 = pose_graph(SE2, 12, seed=4, fixed=())
    with pytest.raises(SingularSystemError):
        GaussNewton().solve(problem, x0)


def test_history_times_are_the_iterations_ends():
    problem, x0 = pose_graph(SE3, 9, seed=6, spread=0.5)
    result = compiled(LevenbergMarquardt(), problem, x0)
    times = result.history.time
    assert times[0] >= 0 and np.all(np.diff(times) >= 0) and times[-1] <= result.time


@pytest.mark.parametrize("method", METHODS)
def test_tiny_grid_as_the_python_loop(monkeypatch, dataset, method):
    graph = g2o.read(dataset("tinyGrid3D"))
    x0 = graph.chordal_initialization()
    fast = compiled(method(), graph.problem("geodesic"), x0)
    assert fast.nit == 4 and fast.fun == pytest.approx(9.31391, abs=1e-5)
    assert_same_run(fast, python_loop(monkeypatch, method(), graph.problem("geodesic"), x0))


@pytest.mark.parametrize("method", METHODS)
def test_threads_share_a_problem(method):
    problem, x0 = pose_graph(SE3, 9, seed=7, spread=0.5)
    expected = compiled(method(), problem, x0)
    results = [None] * 4

    def run(i):
        results[i] = method().solve(problem, x0)

    threads = [threading.Thread(target=run, args=(i,)) for i in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for r in results:
        np.testing.assert_array_equal(r.x.as_matrix(), expected.x.as_matrix())
        np.testing.assert_array_equal(r.history.cost, expected.history.cost)


@pytest.mark.parametrize(
    "case",
    ["callback", "verbosity", "robust", "diagonal damping", "pcg", "time limit", "too many iterations", "too large",
     "wide band", "no native kernels", "subclass"],
)
def test_the_python_loop_outside_the_scope(monkeypatch, capsys, case):
    """Each of these runs the Python loop, which builds the problem's structure."""
    n = {"too large": 129, "wide band": 70}.get(case, 9)  # 774 > MAX_UNKNOWNS; 420 > DENSE_UNKNOWNS, no band
    problem, x0 = pose_graph(SE3, n, closures=200 if case == "wide band" else 6, seed=8)
    options = {"callback": {}, "verbosity": {"verbosity": 1}, "diagonal damping": {"damping": "diagonal"},
               "pcg": {"linear_solver": "pcg"}, "time limit": {"max_time": 10.0},
               "too many iterations": {"max_iterations": _small_system.MAX_RECORDS + 1}}.get(case, {})  # fmt: skip
    calls = []
    if case == "robust":
        (factor,) = problem.factors
        robust = between_factor(factor.variables, SE3.identity((len(factor.variables),)), loss="huber:1.0")
        problem = LeastSquaresProblem(problem.manifold, [robust], fixed=[0])
    if case == "no native kernels":
        for name, value in _kernels.path_settings("machine").items():
            monkeypatch.setattr(_kernels, name, value)
    method = type("Subclass", (LevenbergMarquardt,), {}) if case == "subclass" else LevenbergMarquardt
    result = method(**options).solve(problem, x0, callback=calls.append if case == "callback" else None)
    assert problem.structure is not None and result.nit > 0
    assert case != "callback" or len(calls) == result.nit + 1


def test_a_non_finite_start_is_named_by_the_python_loop():
    problem, x0 = pose_graph(SE3, 6, seed=9)
    (factor,) = problem.factors
    z = SE3.identity((len(factor.variables),)).as_matrix().copy()
    z[2, 0, 3] = np.nan
    bad = LeastSquaresProblem(problem.manifold, [between_factor(factor.variables, SE3._wrap(z))], fixed=[0])
    with pytest.raises(NonFiniteError, match="edge 2"):
        LevenbergMarquardt().solve(bad, x0)


@pytest.mark.parametrize("method", METHODS)
def test_a_step_it_does_not_mirror_hands_the_run_to_the_python_loop(monkeypatch, method):
    """A step at or beyond the retraction's limit for its compiled kernel (here: any step) makes
    the compiled loop return unchanged, and the Python loop solves from the start."""
    problem, x0 = pose_graph(SE3, 9, seed=10)
    expected = python_loop(monkeypatch, method(), pose_graph(SE3, 9, seed=10)[0], x0)
    monkeypatch.setattr(_small_system, "HUGE", 0.0)
    result = method().solve(problem, x0)
    assert problem.structure is not None
    np.testing.assert_array_equal(result.x.as_matrix(), expected.x.as_matrix())
    assert (result.status, result.nit, result.nfev) == (expected.status, expected.nit, expected.nfev)
