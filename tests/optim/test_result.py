"""The result is SciPy-like: attributes and a mapping, success, an integer status code with a
name and a message; the stopping rule's least-squares default; verbosity; callbacks."""

from __future__ import annotations

import dataclasses
import json
import pickle

import numpy as np
import pytest

from manopt_lie import SE2
from manopt_lie.manifolds import LieGroupManifold, Power, Sphere
from manopt_lie.optim import (
    ConjugateGradient,
    Factor,
    GaussNewton,
    GradientDescent,
    LeastSquaresProblem,
    LevenbergMarquardt,
    Problem,
    Status,
    StoppingCriteria,
    TrustRegion,
)

A = np.diag(np.arange(1.0, 11.0))
X0 = np.ones(10) / np.sqrt(10)


def rayleigh():
    return Problem(Sphere(10), cost=lambda x: x @ A @ x, egrad=lambda x: 2 * A @ x, ehess=lambda x, u: 2 * A @ u)


# ---- the status -------------------------------------------------------------------------------

CODES = {
    "GRADIENT_NORM": 1, "COST_DECREASE": 2, "STEP_SIZE": 3, "MAX_ITERATIONS": 4, "MAX_TIME": 5,
    "LINE_SEARCH_FAILED": 6, "LINEAR_SOLVER_FAILED": 7, "CALLBACK": 8, "NO_PROGRESS": 9, "NON_FINITE": 10,
    "INTERRUPTED": 11, "CERTIFIED": 12,
}  # fmt: skip


def test_status_codes_are_stable_integers():
    """Files and other programs keep the codes: they never change, none is 0 (every status is truthy)."""
    assert {s.name: int(s) for s in Status} == CODES
    assert Status.GRADIENT_NORM == 1 and Status(4) is Status.MAX_ITERATIONS and all(Status)
    successes = [Status.GRADIENT_NORM, Status.COST_DECREASE, Status.STEP_SIZE, Status.CERTIFIED]
    assert [s for s in Status if s.converged] == successes
    assert json.dumps({"status": Status.CALLBACK}) == '{"status": 8}'
    assert str(Status.STEP_SIZE) == "Status.STEP_SIZE" and f"{Status.STEP_SIZE}" == "Status.STEP_SIZE"
    assert f"{Status.STEP_SIZE:d}" == "3" and Status.NO_PROGRESS.name.lower() == "no_progress"
    assert "iteration limit" in Status.MAX_ITERATIONS.message
    assert pickle.loads(pickle.dumps(Status.NON_FINITE)) is Status.NON_FINITE


# ---- the result -------------------------------------------------------------------------------


def test_the_result_is_also_a_mapping():
    res = TrustRegion().solve(rayleigh(), X0)
    keys = ["x", "fun", "grad_norm", "nit", "nfev", "ngev", "nhev", "time", "status", "message", "history", "success"]
    assert list(res.keys()) == keys and list(res) == keys and len(res) == len(keys)
    assert res["x"] is res.x and res["fun"] == res.fun and res["success"] is res.success is True
    assert res["status"] is res.status is Status.GRADIENT_NORM and res["status"] == 1
    assert res["message"] == Status.GRADIENT_NORM.message
    assert "nit" in res and "jac" not in res and res.get("jac") is None
    with pytest.raises(KeyError, match="keys x, fun"):
        res["jac"]
    copy = dict(res)
    assert copy["nit"] == res.nit and set(copy) == set(keys)
    assert dict(res.items())["fun"] == res.fun
    with pytest.raises(dataclasses.FrozenInstanceError):
        res.fun = 0.0  # type: ignore[misc]
    assert "the gradient norm fell below" in str(res)


def test_json_of_a_result():
    res = GradientDescent(max_iterations=3).solve(rayleigh(), X0)
    doc = {k: v for k, v in res.items() if k not in ("x", "history")}
    assert json.loads(json.dumps(doc))["status"] == int(Status.MAX_ITERATIONS)


# ---- run control -----------------------------------------------------------------------------


@pytest.mark.parametrize("cls", [GradientDescent, ConjugateGradient, TrustRegion])
@pytest.mark.parametrize("how", ["true", "stop-iteration"])
def test_a_callback_stops_cleanly(cls, how):
    seen = []

    def callback(info):
        seen.append(info.iteration)
        if info.iteration == 2:
            if how == "true":
                return True
            raise StopIteration

    res = cls().solve(rayleigh(), X0, callback=callback)
    assert res.status is Status.CALLBACK and not res.success
    assert seen == [0, 1, 2] and res.nit == 2 and len(res.history) == 3


def test_verbosity_prints_a_table_to_stderr(capsys):
    TrustRegion().solve(rayleigh(), X0)
    assert capsys.readouterr().err == ""
    TrustRegion(verbosity=1).solve(rayleigh(), X0)
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 2 and lines[0].startswith("Optimizing Problem(Sphere(10), egrad, ehess) with TrustRegion")
    assert lines[1].startswith("TrustRegion: the gradient norm fell below the tolerance")
    res = TrustRegion(verbosity=2).solve(rayleigh(), X0)
    out = capsys.readouterr()
    lines = out.err.splitlines()
    assert out.out == "" and len(lines) == res.nit + 4
    assert lines[1].split() == ["iter", "cost", "|grad|", "step", "time"]
    first, last = lines[2].split(), lines[-2].split()
    assert first[0] == "0" and float(first[1]) == pytest.approx(res.history.cost[0]) and first[3] == "-"
    assert int(last[0]) == res.nit and float(last[2]) == pytest.approx(res.grad_norm, rel=1e-3)
    assert last[4].endswith("s")
    for bad in (3, -1, True, "2"):
        with pytest.raises(ValueError, match="verbosity must be 0, 1 or 2"):
            GradientDescent(verbosity=bad)


# ---- the least-squares default of the cost-decrease rule ---------------------------------------


def pose_chain(n=12):
    rng = np.random.default_rng(3)
    truth = SE2.exp(np.cumsum(0.3 * rng.standard_normal((n, 3)), axis=0))
    edges = np.r_[np.c_[np.arange(n - 1), np.arange(1, n)], [[0, 6], [3, 10]]]
    z = truth[edges[:, 0]].between(truth[edges[:, 1]]).rplus(0.05 * rng.standard_normal((len(edges), 3)))

    def between(xi, xj, jac):
        if not jac:
            return xi.between(xj).rminus(z)
        e, j_i, j_j = xi.between(xj, jac=True)
        r, j_e, _ = e.rminus(z, jac=True)
        return r, [j_e @ j_i, j_e @ j_j]

    problem = LeastSquaresProblem(Power(LieGroupManifold(SE2), n), [Factor(edges, between)], fixed=[0])
    return problem, truth.rplus(0.1 * rng.standard_normal((n, 3)) * (np.arange(n) > 0)[:, None])


def test_the_cost_decrease_rule_is_on_by_default_for_least_squares_only():
    problem, x0 = pose_chain()
    assert StoppingCriteria().rel_cost_decrease is None
    assert StoppingCriteria().for_problem(problem).rel_cost_decrease == 1e-5
    assert StoppingCriteria().for_problem(rayleigh()).rel_cost_decrease == 0.0
    rule = StoppingCriteria(rel_cost_decrease=1e-9)
    assert rule.for_problem(problem) is rule  # set: kept as given
    for cls in (GaussNewton, LevenbergMarquardt, TrustRegion):
        default = cls(grad_rtol=1e-14).solve(problem, x0)
        off = cls(grad_rtol=1e-14, rel_cost_decrease=0).solve(problem, x0)
        assert default.status is Status.COST_DECREASE and default.success, (cls, default)
        assert off.status in (Status.GRADIENT_NORM, Status.STEP_SIZE) and off.nit >= default.nit
        assert default.fun - off.fun <= 1e-5 * off.fun  # what the rule promises, at least
    with pytest.raises(ValueError, match="rel_cost_decrease"):
        StoppingCriteria(rel_cost_decrease=-1.0)
