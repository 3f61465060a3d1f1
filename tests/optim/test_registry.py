"""The registry of optimizers, and the table of docs/optimizers.md that must list it."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from manopt_lie import SE2
from manopt_lie.manifolds import Euclidean
from manopt_lie.optim import (
    OPTIMIZERS,
    ConjugateGradient,
    GradientDescent,
    LeastSquaresProblem,
    LevenbergMarquardt,
    OptimizerEntry,
    Problem,
    StoppingCriteria,
    TrustRegion,
    get_optimizer,
    register,
)
from manopt_lie.optim.registry import UnknownOptimizerError

from .helpers import pose_chain

DOCS = Path(__file__).resolve().parents[2] / "docs" / "optimizers.md"


def test_the_registered_optimizers():
    assert list(OPTIMIZERS) == ["gd", "cg", "gn", "lm", "tr", "lbfgs", "dogleg"]
    for name, entry in OPTIMIZERS.items():
        assert entry.name == name and get_optimizer(name) is entry
    assert get_optimizer("lm").summary == "Levenberg-Marquardt, λ·I damping (GTSAM's update), sparse Cholesky"
    assert {n for n, e in OPTIMIZERS.items() if e.accepts is LeastSquaresProblem} == {"gn", "lm", "dogleg"}


def test_make_and_accepts():
    lm = get_optimizer("lm")
    opt = lm.make(StoppingCriteria(max_iterations=9), initial_damping=1e-3)
    assert isinstance(opt, LevenbergMarquardt) and opt.stopping.max_iterations == 9 and opt.initial_damping == 1e-3
    assert get_optimizer("tr").make(max_iterations=4).stopping.max_iterations == 4
    with pytest.raises(TypeError, match="'initial_damping'"):
        get_optimizer("gn").make(initial_damping=1.0)
    lsq, _, _ = pose_chain(SE2, n=10, closures=3)
    smooth = Problem(Euclidean(2), cost=lambda x: x @ x, egrad=lambda x: 2 * x)
    assert all(e.accepts_problem(lsq) for e in OPTIMIZERS.values())
    assert [e.name for e in OPTIMIZERS.values() if e.accepts_problem(smooth)] == ["gd", "cg", "tr", "lbfgs"]
    assert get_optimizer("gd").make().solve(smooth, np.ones(2)).success


def test_defaults_are_overridden_by_options_and_read_only():
    entry = OptimizerEntry("cg-fr", ConjugateGradient, "CG, Fletcher-Reeves", defaults={"beta": "fletcher-reeves"})
    assert entry.make().beta == "fletcher-reeves" and entry.make(beta="polak-ribiere").beta == "polak-ribiere"
    with pytest.raises(TypeError):
        entry.defaults["beta"] = "x"  # type: ignore[index]


def test_register_and_errors():
    entry = OptimizerEntry(
        "tr-plain", TrustRegion, "Trust region, no preconditioner", defaults={"preconditioner": "identity"}
    )
    register(entry)
    try:
        assert get_optimizer("tr-plain") is entry and list(OPTIMIZERS)[-1] == "tr-plain"
        with pytest.raises(ValueError, match="already registered"):
            register(OptimizerEntry("tr-plain", GradientDescent, "again"))
    finally:
        del OPTIMIZERS["tr-plain"]
    with pytest.raises(TypeError):  # bad defaults fail at registration
        register(OptimizerEntry("gd-bad", GradientDescent, "bad", defaults={"damping": 1.0}))
    assert "gd-bad" not in OPTIMIZERS
    with pytest.raises(UnknownOptimizerError, match="unknown optimizer 'newton'; choose from gd, cg, gn, lm, tr"):
        get_optimizer("newton")
    assert issubclass(UnknownOptimizerError, ValueError)
    with pytest.raises(TypeError):
        OptimizerEntry("x", int, "not an optimizer")  # type: ignore[arg-type]
    with pytest.raises(ValueError):
        OptimizerEntry("x", GradientDescent, "two\nlines")


def _docs_table() -> dict[str, tuple[str, str, str]]:
    """Rows ``| `name` | `Class` | `Problem` | summary |`` of the table headed ``| name |``."""
    lines = DOCS.read_text().splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("| name | optimizer | problems | summary |"))
    rows = {}
    for line in lines[start + 2 :]:
        if not line.startswith("|"):
            break
        name, cls, accepts, summary = (re.sub(r"^`(.*)`$", r"\1", c.strip()) for c in line.strip("|").split("|"))
        rows[name] = (cls, accepts, summary)
    return rows


def test_docs_table_lists_the_registry():
    expected = {e.name: (e.cls.__name__, e.accepts.__name__, e.summary) for e in OPTIMIZERS.values()}
    assert list(_docs_table()) == list(expected)
    assert _docs_table() == expected
