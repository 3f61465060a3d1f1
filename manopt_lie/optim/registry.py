"""The one registry of optimizers: short name → class, summary, the problems it accepts, defaults.

Command lines, benchmark harnesses and docs read :data:`OPTIMIZERS` instead of
keeping their own lists::

    entry = get_optimizer("lm")
    if entry.accepts_problem(problem):
        result = entry.make(StoppingCriteria(max_iterations=100)).solve(problem, x0)

A new optimizer is one module with its class and one :func:`register` call
(for the built-in ones, one line at the end of this module).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

from .conjugate_gradient import ConjugateGradient
from .dogleg import Dogleg
from .gradient_descent import GradientDescent
from .lbfgs import LBFGS
from .least_squares_problem import LeastSquaresProblem
from .nonlinear_least_squares import GaussNewton, LevenbergMarquardt
from .optimizer import Optimizer, StoppingCriteria
from .problem import Problem
from .trust_region import TrustRegion

__all__ = ["OPTIMIZERS", "OptimizerEntry", "UnknownOptimizerError", "get_optimizer", "register"]


class UnknownOptimizerError(ValueError):
    """No optimizer is registered under the name (the message lists the choices)."""


@dataclass(frozen=True, eq=False)
class OptimizerEntry:
    """One registered optimizer.

    Attributes
    ----------
    name : str
        The short name (``"lm"``), as a command line spells it.
    cls : type[Optimizer]
        The class :meth:`make` instantiates.
    summary : str
        One line saying what it is, e.g. ``"Levenberg-Marquardt, λ·I damping (GTSAM's update), sparse Cholesky"``.
    accepts : type[Problem]
        The problems it runs on: :class:`Problem` (any smooth problem with a
        gradient) or :class:`LeastSquaresProblem`.
    defaults : Mapping[str, Any]
        Constructor options beyond the stopping rule (read-only); :meth:`make`'s
        options override them.
    """

    name: str
    cls: type[Optimizer]
    summary: str
    accepts: type[Problem] = Problem
    defaults: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not (isinstance(self.name, str) and self.name and self.name == self.name.strip()):
            raise ValueError(f"OptimizerEntry: name must be a non-empty word, got {self.name!r}")
        if not (isinstance(self.cls, type) and issubclass(self.cls, Optimizer)):
            raise TypeError(f"OptimizerEntry {self.name!r}: cls must be an Optimizer subclass, got {self.cls!r}")
        if not (isinstance(self.accepts, type) and issubclass(self.accepts, Problem)):
            raise TypeError(f"OptimizerEntry {self.name!r}: accepts must be a Problem subclass, got {self.accepts!r}")
        if not isinstance(self.summary, str) or not self.summary or "\n" in self.summary:
            raise ValueError(f"OptimizerEntry {self.name!r}: summary must be one non-empty line")
        # A private copy behind a read-only view: entries are shared by every caller.
        object.__setattr__(self, "defaults", MappingProxyType(dict(self.defaults)))

    def make(self, stopping: StoppingCriteria | None = None, **options: Any) -> Optimizer:
        """``cls(stopping=stopping, **(defaults | options))``.

        ``options`` may also hold the stopping rule's fields when ``stopping`` is
        ``None``; an unknown option raises ``TypeError`` naming it.
        """
        return self.cls(stopping=stopping, **{**self.defaults, **options})

    def accepts_problem(self, problem: Problem) -> bool:
        """Whether this optimizer runs on ``problem`` (an instance of :attr:`accepts`)."""
        return isinstance(problem, self.accepts)


OPTIMIZERS: dict[str, OptimizerEntry] = {}
"""Every optimizer by its short name (``"gd"``, ``"cg"``, ``"lbfgs"``, ``"tr"``, ``"gn"``,
``"lm"``, ``"dogleg"``), filled by :func:`register`: what the command line, the benchmark
harness and :func:`~manopt_lie.minimize` choose from (``get_optimizer(name).make(stopping)``)."""


def register(entry: OptimizerEntry) -> None:
    """Add ``entry`` to :data:`OPTIMIZERS`, after building it once with its defaults.

    Raises
    ------
    ValueError
        If the name is taken.
    TypeError
        If its defaults are not options of its class.
    """
    if entry.name in OPTIMIZERS:
        raise ValueError(f"an optimizer named {entry.name!r} is already registered ({OPTIMIZERS[entry.name].cls})")
    entry.make()  # bad defaults fail here, not in the middle of a benchmark
    OPTIMIZERS[entry.name] = entry


def get_optimizer(name: str) -> OptimizerEntry:
    """The entry registered as ``name``.

    Raises
    ------
    UnknownOptimizerError (a ValueError)
        If there is none; the message lists the choices.
    """
    try:
        return OPTIMIZERS[name]
    except (KeyError, TypeError):
        raise UnknownOptimizerError(f"unknown optimizer {name!r}; choose from {', '.join(OPTIMIZERS)}") from None


for _entry in (
    OptimizerEntry("gd", GradientDescent, "Riemannian gradient descent, Armijo backtracking"),
    OptimizerEntry("cg", ConjugateGradient, "Riemannian nonlinear CG (Hager-Zhang), strong Wolfe"),
    OptimizerEntry("gn", GaussNewton, "Gauss-Newton with line search, sparse Cholesky", LeastSquaresProblem),
    OptimizerEntry(
        "lm", LevenbergMarquardt, "Levenberg-Marquardt, λ·I damping (GTSAM's update), sparse Cholesky",
        LeastSquaresProblem,
    ),
    OptimizerEntry("tr", TrustRegion, "Riemannian trust region, truncated CG"),
    OptimizerEntry("lbfgs", LBFGS, "Riemannian limited-memory BFGS, cautious updates, strong Wolfe"),
    OptimizerEntry("dogleg", Dogleg, "Powell's dogleg trust region, sparse Cholesky", LeastSquaresProblem),
):
    register(_entry)
del _entry
