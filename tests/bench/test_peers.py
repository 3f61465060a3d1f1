"""The peer adapters (``benchmarks.peers``): registry, cost agreement, solutions.

GTSAM and pymanopt are optional extras (``pip install gtsam pymanopt``). The tests
that run them use ``pytest.importorskip`` and are skipped when the library is
missing — also on CI (``$CI`` set), deliberately: unlike the benchmark datasets,
the peers are not required by the project. Everything else here (the registry,
the unavailable-library errors, the vectorized chordal derivatives handed to
pymanopt) runs without them.
"""

from __future__ import annotations

import sys

import numpy as np
import pytest

from manopt_lie import SE2, SE3
from manopt_lie.bench import peers
from manopt_lie.optim import LevenbergMarquardt, TrustRegion
from manopt_lie.problems import synthetic

NOISE = {"translation_noise": 0.2, "rotation_noise": 0.1}


@pytest.fixture(scope="module")
def graphs():
    """A small noisy SE(2) and SE(3) pose graph."""
    return {
        SE2: synthetic.grid2d(5, 6, loop_closure_probability=0.5, seed=1, **NOISE).graph,
        SE3: synthetic.cube(3, loop_closure_probability=0.5, seed=2, **NOISE).graph,
    }


@pytest.fixture(scope="module")
def rotations():
    return {d: synthetic.rotation_averaging(40, d=d, noise=0.1, seed=3 + d).graph for d in (2, 3)}


# ---- registry ----------------------------------------------------------------------------


def test_registry_and_applies():
    assert set(peers.PEERS) == {"gtsam-lm", "gtsam-dogleg", "pymanopt-tr"}
    for name in ("gtsam-lm", "gtsam-dogleg"):
        assert peers.applies(name, "pose-graph", "geodesic")
        assert not peers.applies(name, "pose-graph", "chordal")
        assert not peers.applies(name, "rotation-averaging", "geodesic")
    assert peers.applies("pymanopt-tr", "rotation-averaging", "chordal")
    assert not peers.applies("pymanopt-tr", "rotation-averaging", "geodesic")
    assert not peers.applies("pymanopt-tr", "pose-graph", "chordal")


def test_unknown_peer_is_a_value_error(graphs):
    for call in (
        lambda: peers.applies("ceres", "pose-graph", "geodesic"),
        lambda: peers.available("ceres"),
        lambda: peers.solve("ceres", graphs[SE2], graphs[SE2].chordal_initialization()),
    ):
        with pytest.raises(ValueError, match="unknown peer 'ceres'"):
            call()


def test_peer_on_the_wrong_problem_is_a_value_error(graphs, rotations):
    with pytest.raises(ValueError, match="pose-graph"):
        peers.solve("gtsam-lm", rotations[3], rotations[3].chordal_initialization())
    with pytest.raises(ValueError, match="rotation-averaging"):
        peers.solve("pymanopt-tr", graphs[SE3], graphs[SE3].chordal_initialization())


@pytest.mark.parametrize(("name", "module"), [("gtsam-lm", "gtsam"), ("pymanopt-tr", "pymanopt")])
def test_missing_library_raises_peer_unavailable(monkeypatch, graphs, rotations, name, module):
    monkeypatch.setitem(sys.modules, module, None)  # makes `import module` fail
    assert not peers.available(name)
    spec = graphs[SE2] if module == "gtsam" else rotations[2]
    with pytest.raises(peers.PeerUnavailableError, match=f"pip install {module}") as info:
        peers.solve(name, spec, spec.chordal_initialization())
    assert isinstance(info.value, ImportError)


# ---- the chordal rotation-averaging functions given to pymanopt (plain NumPy) --------------


@pytest.mark.parametrize("d", [2, 3])
def test_chordal_cost_and_derivatives(rotations, rng, d):
    spec = rotations[d]
    cost, egrad, ehess = peers._chordal_rotations(spec)
    x = spec.group.random(rng, (spec.n,))
    r = x.as_matrix()
    assert cost(r) == pytest.approx(spec.cost(x, "chordal"), rel=1e-12)
    # f is quadratic in the matrix entries: central differences are exact up to round-off.
    u, v = rng.standard_normal((2, spec.n, d, d))
    t = 1e-3
    slope = (cost(r + t * u) - cost(r - t * u)) / (2 * t)
    assert slope == pytest.approx(np.sum(egrad(r) * u), rel=1e-8)
    curvature = (np.sum(egrad(r + t * v) * u) - np.sum(egrad(r - t * v) * u)) / (2 * t)
    assert curvature == pytest.approx(np.sum(ehess(r, v) * u), rel=1e-8)
    assert np.sum(ehess(r, v) * u) == pytest.approx(np.sum(ehess(r, u) * v), rel=1e-10)  # symmetric


# ---- GTSAM -------------------------------------------------------------------------------


@pytest.mark.parametrize("group", [SE2, SE3])
def test_gtsam_error_is_our_geodesic_cost(graphs, rng, group):
    gtsam = pytest.importorskip("gtsam")
    graph = graphs[group]
    for x in (group.random(rng, (graph.n,)), graph.chordal_initialization()):
        factors, values = peers.gtsam_problem(gtsam, graph, x)  # the anchor prior sits at x: it adds 0
        assert factors.size() == graph.m + 1
        assert factors.error(values) == pytest.approx(graph.cost(x, "geodesic"), rel=1e-9)
        back = peers.from_gtsam(gtsam, group, values)
        np.testing.assert_allclose(back.as_matrix(), x.as_matrix(), atol=1e-12)


@pytest.mark.parametrize("name", ["gtsam-lm", "gtsam-dogleg"])
@pytest.mark.parametrize("group", [SE2, SE3])
def test_gtsam_reaches_our_optimum_and_matches_optimize(graphs, group, name):
    gtsam = pytest.importorskip("gtsam")
    graph = graphs[group]
    x0 = graph.chordal_initialization()
    run = peers.solve(name, graph, x0)
    ours = LevenbergMarquardt(grad_rtol=1e-10, rel_cost_decrease=1e-14).solve(graph.problem("geodesic"), x0)
    assert run.status == "converged" and run.converged
    assert graph.cost(run.x, "geodesic") == pytest.approx(ours.fun, rel=1e-6)
    assert len(run.history_cost) == len(run.history_time) == run.nit + 1
    assert run.history_cost[0] == pytest.approx(graph.cost(x0, "geodesic"), rel=1e-9)
    assert run.history_cost[-1] == pytest.approx(graph.cost(run.x, "geodesic"), rel=1e-9)
    assert np.all(np.diff(run.history_time) >= 0) and run.time >= run.history_time[-1]
    # The hand-stepped loop stops where GTSAM's optimize() does.
    factors, values = peers.gtsam_problem(gtsam, graph, x0)
    if name == "gtsam-lm":
        optimizer = gtsam.LevenbergMarquardtOptimizer(factors, values, gtsam.LevenbergMarquardtParams())
    else:
        optimizer = gtsam.DoglegOptimizer(factors, values, gtsam.DoglegParams())
    optimizer.optimize()
    assert run.nit == optimizer.iterations()
    assert run.history_cost[-1] == pytest.approx(optimizer.error(), rel=1e-12)


def test_gtsam_iteration_cap(graphs):
    pytest.importorskip("gtsam")
    graph = graphs[SE3]
    run = peers.solve("gtsam-lm", graph, graph.chordal_initialization(), max_iterations=1, rel_cost_decrease=1e-15)
    assert (run.nit, run.status, run.converged, len(run.history_cost)) == (1, "max_iterations", False, 2)


# ---- pymanopt ----------------------------------------------------------------------------


@pytest.mark.parametrize("d", [2, 3])
def test_pymanopt_reaches_our_optimum(rotations, d):
    pytest.importorskip("pymanopt")
    spec = rotations[d]
    x0 = spec.chordal_initialization()
    run = peers.solve("pymanopt-tr", spec, x0)
    ours = TrustRegion(grad_rtol=1e-10).solve(spec.problem("chordal"), x0)
    assert run.status == "converged" and run.converged
    assert isinstance(run.x, spec.group) and run.x.batch_shape == (spec.n,)
    assert spec.cost(run.x, "chordal") == pytest.approx(ours.fun, rel=1e-6)
    assert len(run.history_cost) == len(run.history_time) == run.nit + 1
    assert run.history_cost[0] == pytest.approx(spec.cost(x0, "chordal"), rel=1e-12)
    assert run.history_cost[-1] == pytest.approx(spec.cost(run.x, "chordal"), rel=1e-9)
    # TR accepts only decreasing steps (up to its ρ regularization, ~1e3 ε |f|)
    assert np.all(np.diff(run.history_cost) <= 1e-10 * run.history_cost[0])
    assert np.all(np.diff(run.history_time) >= 0) and run.time >= run.history_time[-1]


def test_pymanopt_iteration_cap(rotations):
    pytest.importorskip("pymanopt")
    spec = rotations[3]
    run = peers.solve("pymanopt-tr", spec, spec.chordal_initialization(), max_iterations=2, grad_rtol=1e-15)
    assert (run.nit, run.status, run.converged, len(run.history_cost)) == (2, "max_iterations", False, 3)
