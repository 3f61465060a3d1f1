"""The optimizer interface, shared stopping criteria and the bookkeeping of a run.

Every optimizer is configured in ``__init__`` and run by
``solve(problem, x0, callback=None) -> OptimizeResult``. Progress goes to the
``logging`` logger ``manopt_lie.optim`` (one DEBUG line per iteration, one INFO
line at the end) and to the optional callback, which receives an
:class:`IterationInfo` after every iteration and stops the run by returning
``True``.
"""

from __future__ import annotations

import logging
import math
import time
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, field
from dataclasses import fields as dataclass_fields
from typing import Any

import numpy as np

from .problem import Problem
from .result import History, IterationInfo, OptimizeResult, Status

logger = logging.getLogger("manopt_lie.optim")

Callback = Callable[[IterationInfo], Any]


@dataclass(frozen=True)
class StoppingCriteria:
    """When to stop (the first test that holds wins).

    Parameters
    ----------
    max_iterations, max_time
        Limits on iterations and on wall time (seconds).
    grad_rtol, grad_atol
        Stop once ``‖grad f(x)‖ ≤ max(grad_rtol·‖grad f(x₀)‖, grad_atol)``: by
        default a gradient a million times smaller than at the start (relative),
        or below 1e-12 (absolute, so that a start at a critical point stops at once).
    min_step
        Stop once an accepted step has norm below this (rejected steps record ``nan``).
    rel_cost_decrease
        Stop once an accepted iteration decreases the cost by less than this
        fraction, ``(f_prev − f) ≤ rel_cost_decrease·max(1, |f_prev|)``
        (SE-Sync uses 1e-6); 0 disables the test.

    Notes
    -----
    The fields are defined here only: every optimizer takes either a whole
    ``StoppingCriteria`` (``stopping=``) or these fields as keywords, and a
    command line can build its options from ``dataclasses.fields(StoppingCriteria)``,
    whose ``metadata["help"]`` is a one-line description.
    """

    max_iterations: int = field(default=1000, metadata={"help": "stop after this many iterations"})
    max_time: float = field(default=math.inf, metadata={"help": "stop after this many seconds of wall time"})
    grad_rtol: float = field(
        default=1e-6,
        metadata={"help": "stop when the gradient norm falls below this fraction of its value at the start"},
    )
    grad_atol: float = field(
        default=1e-12, metadata={"help": "stop when the gradient norm falls below this absolute value"}
    )
    min_step: float = field(default=1e-12, metadata={"help": "stop when an accepted step is shorter than this"})
    rel_cost_decrease: float = field(
        default=0.0,
        metadata={"help": "stop when a step lowers the cost by less than this fraction of it (0: never)"},
    )

    def __post_init__(self) -> None:
        for name in ("grad_rtol", "grad_atol", "min_step", "rel_cost_decrease", "max_time"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name} must be non-negative, got {getattr(self, name)!r}")
        if self.max_iterations < 0:
            raise ValueError(f"max_iterations must be non-negative, got {self.max_iterations}")


STOPPING_FIELDS: tuple[str, ...] = tuple(f.name for f in dataclass_fields(StoppingCriteria))


class Run:
    """The bookkeeping of one ``solve``: counted evaluations, history, stopping tests,
    logging and the callback."""

    def __init__(self, name: str, problem: Problem, stopping: StoppingCriteria, callback: Callback | None) -> None:
        self.name, self.problem, self.stopping, self.callback = name, problem, stopping, callback
        self.manifold = problem.manifold
        self.nfev = self.ngev = self.nhev = 0
        self.start = time.perf_counter()
        self._records: list[tuple[float, float, float, float]] = []
        self._extra: dict[str, list[float]] = {}
        self.grad_tol = math.nan

    # ---- counted evaluations ------------------------------------------------------

    def cost(self, x: Any) -> float:
        self.nfev += 1
        f = self.problem.cost(x)
        if not math.isfinite(f):
            raise FloatingPointError(f"{self.name}: the cost is {f} at an iterate")
        return f

    def grad(self, x: Any) -> Any:
        self.ngev += 1
        return self.problem.grad(x)

    def hess(self, x: Any, v: Any) -> Any:
        self.nhev += 1
        return self.problem.hess(x, v)

    def norm(self, x: Any, v: Any) -> float:
        return float(np.sqrt(np.sum(self.manifold.inner(x, v, v))))

    def inner(self, x: Any, u: Any, v: Any) -> float:
        return float(np.sum(self.manifold.inner(x, u, v)))

    # ---- iterations ---------------------------------------------------------------

    @property
    def nit(self) -> int:
        return len(self._records) - 1

    def elapsed(self) -> float:
        return time.perf_counter() - self.start

    def record(self, x: Any, f: float, grad_norm: float, step: float = math.nan, **extra: float) -> bool:
        """Record an iterate; ``True`` if the callback asks to stop."""
        if not self._records:
            self.grad_tol = max(self.stopping.grad_rtol * grad_norm, self.stopping.grad_atol)
        now = self.elapsed()
        self._records.append((f, grad_norm, step, now))
        for key, value in extra.items():
            self._extra.setdefault(key, [math.nan] * (len(self._records) - 1)).append(value)
        logger.debug("%s %4d  f = %.12g  |grad| = %.3e  step = %.3e", self.name, self.nit, f, grad_norm, step)
        if self.callback is None:
            return False
        info = IterationInfo(self.nit, x, f, grad_norm, step, now, dict(extra))
        return bool(self.callback(info))

    def stop_reason(self, f_prev: float | None = None) -> Status | None:
        """The stopping test after the latest record (``f_prev``: the cost before an accepted step)."""
        s = self.stopping
        f, grad_norm, step, now = self._records[-1]
        if grad_norm <= self.grad_tol:
            return Status.GRADIENT_NORM
        if self.nit > 0 and step < s.min_step:
            return Status.STEP_SIZE
        if f_prev is not None and s.rel_cost_decrease > 0 and f_prev - f <= s.rel_cost_decrease * max(1.0, abs(f_prev)):
            return Status.COST_DECREASE
        if self.nit >= s.max_iterations:
            return Status.MAX_ITERATIONS
        if now >= s.max_time:
            return Status.MAX_TIME
        return None

    def result(self, x: Any, status: Status) -> OptimizeResult:
        records = np.array(self._records, dtype=np.float64).reshape(-1, 4)
        extra = {k: np.array(v + [math.nan] * (len(records) - len(v))) for k, v in self._extra.items()}
        history = History(records[:, 0], records[:, 1], records[:, 2], records[:, 3], extra)
        f, grad_norm = records[-1, 0], records[-1, 1]
        res = OptimizeResult(
            x, float(f), float(grad_norm), self.nit, self.nfev, self.ngev, self.nhev,
            self.elapsed(), status, status.value, history,
        )  # fmt: skip
        logger.info("%s: %s", self.name, res)
        return res


class Optimizer(ABC):
    """Base class: settings in ``__init__``, one ``solve`` for every problem."""

    def __init__(self, *, stopping: StoppingCriteria | None = None, **fields: Any) -> None:
        """Keep the stopping rule: ``stopping``, or ``StoppingCriteria(**fields)``.

        Parameters
        ----------
        stopping : StoppingCriteria, optional
            The whole rule.
        **fields
            Or some of its fields (``max_iterations=…``), the others at their defaults.

        Raises
        ------
        TypeError
            If both are given, ``stopping`` is not a ``StoppingCriteria``, or a
            keyword is not a field (naming it).
        """
        name = type(self).__name__
        unknown = [k for k in fields if k not in STOPPING_FIELDS]
        if unknown:
            raise TypeError(
                f"{name}: unknown option{'s' if len(unknown) > 1 else ''} {', '.join(map(repr, unknown))}; "
                "besides its own options it takes stopping= or the StoppingCriteria fields "
                f"{', '.join(STOPPING_FIELDS)}"
            )
        if stopping is None:
            stopping = StoppingCriteria(**fields)
        elif fields:
            raise TypeError(f"{name}: pass either stopping= or its fields ({', '.join(fields)}), not both")
        elif not isinstance(stopping, StoppingCriteria):
            raise TypeError(f"{name}: stopping must be a StoppingCriteria, got {type(stopping).__name__}")
        self.stopping = stopping

    def solve(self, problem: Problem, x0: Any, callback: Callback | None = None) -> OptimizeResult:
        """Minimize ``problem`` from ``x0``.

        Raises
        ------
        ValueError (a subclass)
            If ``x0`` is not a finite point of the problem's manifold.
        NotImplementedError
            If the problem lacks a derivative the optimizer needs.
        """
        if not isinstance(problem, Problem):
            raise TypeError(f"{type(self).__name__}.solve: expected a Problem, got {type(problem).__name__}")
        problem.manifold.check_point(x0, "x0")
        if not problem.has_gradient:
            raise NotImplementedError(f"{type(self).__name__} needs a gradient: build the Problem with egrad or rgrad")
        return self._solve(Run(type(self).__name__, problem, self.stopping, callback), x0)

    @abstractmethod
    def _solve(self, run: Run, x0: Any) -> OptimizeResult:
        """The iteration, recording through ``run``."""
