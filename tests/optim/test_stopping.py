"""StoppingCriteria: passed whole or as keywords, defined once, described for a command line."""

from __future__ import annotations

import dataclasses

import pytest

from manopt_lie.optim import (
    ConjugateGradient,
    GaussNewton,
    GradientDescent,
    LevenbergMarquardt,
    StoppingCriteria,
    TrustRegion,
)

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
