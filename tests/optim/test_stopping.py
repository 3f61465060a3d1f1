"""StoppingCriteria: passed whole or as keywords, defined once, described for a command line."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from manopt_lie.manifolds import Euclidean
from manopt_lie.optim import (
    ConjugateGradient,
    GaussNewton,
    GradientDescent,
    LevenbergMarquardt,
    Problem,
    Status,
    StoppingCriteria,
    TrustRegion,
)
from manopt_lie.optim.optimizer import Run

CLASSES = [GradientDescent, ConjugateGradient, TrustRegion, GaussNewton, LevenbergMarquardt]
classes = pytest.mark.parametrize("cls", CLASSES, ids=lambda c: c.__name__)


@classes
def test_whole_or_by_fields(cls):
    rule = StoppingCriteria(max_iterations=7, grad_rtol=1e-9, rel_cost_decrease=1e-5)
    assert cls(stopping=rule).stopping is rule
    assert cls(max_iterations=7, grad_rtol=1e-9, rel_cost_decrease=1e-5).stopping == rule
    assert cls().stopping == StoppingCriteria()


@classes
def test_bad_combinations_are_type_errors(cls):
    with pytest.raises(TypeError, match="not both"):
        cls(stopping=StoppingCriteria(), max_iterations=3)
    with pytest.raises(TypeError, match="'max_iters'"):
        cls(max_iters=3)
    with pytest.raises(TypeError, match="StoppingCriteria"):
        cls(stopping={"max_iterations": 3})
    with pytest.raises(ValueError):
        cls(grad_atol=-1.0)  # the dataclass validates its fields


def test_existing_spelling_keeps_working():
    opt = GaussNewton(max_iterations=5, rel_cost_decrease=1e-5)
    assert opt.stopping == StoppingCriteria(max_iterations=5, rel_cost_decrease=1e-5)


def test_every_field_has_one_line_help():
    fields = dataclasses.fields(StoppingCriteria)
    assert [f.name for f in fields] == [
        "max_iterations", "max_time", "grad_rtol", "grad_atol", "min_step", "rel_cost_decrease",
    ]  # fmt: skip
    for f in fields:
        text = f.metadata["help"]
        assert isinstance(text, str) and 10 < len(text) < 100 and "\n" not in text and "§" not in text


def test_record_at_keeps_the_given_times_and_fills_late_extras_with_nan():
    """``Run.record_at``: the history holds the times it is given (iterations recorded after they
    ran), the first record sets the cost scale as ``record`` does, and an extra first seen later
    is ``nan`` for the records before it."""
    problem = Problem(Euclidean(2), lambda x: float(x @ x), egrad=lambda x: 2 * x)
    run = Run("test", problem, StoppingCriteria().for_problem(problem), None)
    assert not run.record_at(0.25, np.zeros(2), 0.01, 1e-3)
    assert not run.record_at(0.75, np.zeros(2), 0.005, 1e-4, 0.1, rho=0.9)
    result = run.result(np.zeros(2), Status.MAX_ITERATIONS)
    np.testing.assert_array_equal(result.history.time, [0.25, 0.75])
    assert run.scale == max(0.01, 1e-3 * problem.manifold.typical_dist)
    rho = result.history.extra["rho"]
    assert math.isnan(rho[0]) and rho[1] == 0.9
