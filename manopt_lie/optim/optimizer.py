"""The optimizer interface, shared stopping criteria and the bookkeeping of a run.

Every optimizer is configured in ``__init__`` and run by
``solve(problem, x0, callback=None) -> OptimizeResult``. Progress goes to the
``logging`` logger ``manopt_lie.optim`` (one DEBUG line per iteration, one INFO
line at the end), to a table on stderr when the optimizer was built with
``verbosity=1`` or ``2`` (:mod:`._verbosity`), and to the optional callback,
which receives an :class:`IterationInfo` after every iteration and stops the
run by returning ``True`` (or raising ``StopIteration``).

What every run shares (:class:`Run`): the callbacks' results are checked once,
at ``x₀`` (:meth:`Problem.validate`); a trial point whose cost is not finite
counts as ``+inf`` (rejected: a line search backtracks, a trust region
shrinks); a ``KeyboardInterrupt`` ends the run with ``Status.INTERRUPTED`` and
the last accepted point; tolerances on costs and gradients are measured in the
problem's own *cost scale* ``s`` (see :class:`StoppingCriteria`).
"""

from __future__ import annotations

import logging
import math
import time
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from dataclasses import fields as dataclass_fields
from typing import Any

import numpy as np

from ._values import safe_norm
from ._verbosity import Progress, check_verbosity
from .least_squares_problem import LeastSquaresProblem
from .line_search import LineSearch
from .problem import Problem
from .result import History, IterationInfo, OptimizeResult, Status

logger = logging.getLogger("manopt_lie.optim")

Callback = Callable[[IterationInfo], Any]

_EPS = float(np.finfo(float).eps)
ROUNDOFF = 1e3 * _EPS
"""Cost changes below ``ROUNDOFF·max(s, |f|)`` are round-off (:meth:`Run.roundoff`)."""
LEAST_SQUARES_REL_COST_DECREASE = 1e-5
"""``rel_cost_decrease`` left unset (``None``) on a :class:`LeastSquaresProblem`: GTSAM's
``relativeErrorTol``."""


@dataclass(frozen=True)
class StoppingCriteria:
    """When to stop (the first test that holds wins).

    Parameters
    ----------
    max_iterations, max_time
        Limits on iterations and on wall time (seconds).
    grad_rtol, grad_atol
        Stop once ``‖grad f(x)‖ ≤ max(grad_rtol·‖grad f(x₀)‖, grad_atol·s)``: by
        default a gradient a million times smaller than at the start (relative),
        or below ``1e-12·s`` (a floor, so that a start at a critical point stops at
        once), with ``s ≤ 1`` the cost scale below. For an absolute test as in
        SciPy's ``gtol`` or pymanopt's ``min_gradient_norm``, pass
        ``grad_rtol=0, grad_atol=tol`` (absolute for costs of order one or more).
    min_step
        Stop once a step has norm below this (rejected steps record ``nan``) — or,
        for the trust region, its radius. This stop is success
        (``Status.STEP_SIZE``) only where the optimizer's model predicts no
        decrease above round-off, ``ROUNDOFF·max(s, |f|)`` with ``ROUNDOFF = 10³·eps``;
        otherwise the run ends with ``Status.NO_PROGRESS``.
    rel_cost_decrease
        Stop once an accepted iteration decreases the cost by less than this
        fraction, ``(f_prev − f) ≤ rel_cost_decrease·max(s, |f_prev|)``
        (SE-Sync uses 1e-6 with ``s = 1``; GTSAM 1e-5); 0 disables the test.
        ``None`` (the default) lets the run decide (:meth:`for_problem`):
        ``1e-5`` (:data:`LEAST_SQUARES_REL_COST_DECREASE`, GTSAM's default) on a
        :class:`~manopt_lie.optim.LeastSquaresProblem` solved by a method with a
        curvature model (Gauss-Newton, Levenberg-Marquardt, the trust region), whose
        small decreases mean convergence; 0 (off) on other problems and for the
        first-order methods (steepest descent, CG), whose small decreases may only
        mean slow progress.

    Notes
    -----
    The *cost scale* ``s = min(1, max(|f(x₀)|, ‖grad f(x₀)‖·L))``, with ``L`` the
    manifold's ``typical_dist``, is the size of the cost at the start (or of its
    change over a typical distance, should ``f(x₀)`` be near 0), capped at 1.
    The absolute floors are multiplied by it, so they never exceed their values
    for a cost of order 1 (``grad_atol`` is then an absolute tolerance, as are
    the ``1`` of ``max(1, |f|)``), and they shrink with a cost of smaller
    magnitude: scaling a cost by 1e-300 scales every test with it, and its start
    does not look critical. A start at an exact critical point (``grad f(x₀) = 0``)
    still stops at once.

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
        default=1e-12,
        metadata={"help": "stop when the gradient norm falls below this times the cost scale (at most 1)"},
    )
    min_step: float = field(default=1e-12, metadata={"help": "stop when an accepted step is shorter than this"})
    rel_cost_decrease: float | None = field(
        default=None,
        metadata={
            "help": "stop when a step lowers the cost by less than this fraction (0: off; unset: 1e-5 on least squares)"
        },
    )

    def __post_init__(self) -> None:
        for name in ("grad_rtol", "grad_atol", "min_step", "rel_cost_decrease", "max_time"):
            value = getattr(self, name)
            if not (value is None and name == "rel_cost_decrease") and not value >= 0:
                raise ValueError(f"{name} must be non-negative, got {value!r}")
        if self.max_iterations < 0:
            raise ValueError(f"max_iterations must be non-negative, got {self.max_iterations}")

    def for_problem(self, problem: Problem, *, first_order: bool = False) -> StoppingCriteria:
        """This rule with ``rel_cost_decrease`` decided, if unset (``None``): ``1e-5`` on a
        :class:`~manopt_lie.optim.LeastSquaresProblem` unless ``first_order`` (the optimizer
        is steepest descent or CG: :attr:`Optimizer.first_order`), 0 otherwise; ``self`` if set."""
        if self.rel_cost_decrease is not None:
            return self
        on = isinstance(problem, LeastSquaresProblem) and not first_order
        return replace(self, rel_cost_decrease=LEAST_SQUARES_REL_COST_DECREASE if on else 0.0)


STOPPING_FIELDS: tuple[str, ...] = tuple(f.name for f in dataclass_fields(StoppingCriteria))


class Run:
    """The bookkeeping of one ``solve``: counted evaluations, history, stopping tests,
    logging, the callback and the cost scale.

    Attributes
    ----------
    scale : float
        The cost scale ``s`` (see :class:`StoppingCriteria`), set by the first record.
    grad_tol : float
        ``max(grad_rtol·‖g₀‖, grad_atol·s)``.
    rejected_nonfinite : int
        Trial points whose cost was not finite (counted as ``+inf``).

    ``stopping`` is used as given: :meth:`Optimizer.solve` passes the optimizer's rule
    decided for the problem (:meth:`StoppingCriteria.for_problem`). ``progress``
    prints the table of ``verbosity`` (:class:`~._verbosity.Progress`).
    """

    def __init__(
        self, name: str, problem: Problem, stopping: StoppingCriteria, callback: Callback | None,
        progress: Progress | None = None,
    ) -> None:  # fmt: skip
        self.name, self.problem, self.stopping, self.callback = name, problem, stopping, callback
        self.progress = progress
        self.manifold = problem.manifold
        self.nfev = self.ngev = self.nhev = 0
        self.start = time.perf_counter()
        self._records: list[tuple[float, float, float, float]] = []
        self._extra: dict[str, list[float]] = {}
        self._x: Any = None  # the last recorded point
        self.grad_tol = math.nan
        self.scale = 1.0
        self.rejected_nonfinite = 0

    # ---- counted evaluations ------------------------------------------------------

    def initial(self, x0: Any, *, hessian: bool = False) -> tuple[float, Any, float]:
        """``f(x₀)``, ``g₀ = grad f(x₀)`` and ``‖g₀‖``, every callback's result checked
        (:meth:`Problem.validate`; with ``hessian`` one Hessian product too, which
        ``nhev`` does not count: the optimizer does not use it).

        Raises
        ------
        ShapeError, NonFiniteError, TypeError
            If a callback returns the wrong shape, ``nan``/``inf`` or not real numbers at ``x₀``.
        """
        f, g = self.problem.validate(x0, hessian=hessian)
        self.nfev += 1  # the optimizer uses f(x₀) and g₀; the check's Hessian product is not counted
        self.ngev += 1
        return f, g, self.norm(x0, g)

    def cost(self, x: Any, evaluate: Callable[[Any], float] | None = None) -> float:
        """``f(x)`` at a trial point — by ``evaluate(x)`` if given (e.g.
        :meth:`~manopt_lie.optim.LeastSquaresProblem.trial_cost`), else ``problem.cost`` —;
        ``+inf`` if it is not finite (``nan``, ``±inf``), so that every acceptance test
        rejects the point."""
        self.nfev += 1
        f = (evaluate or self.problem.cost)(x)
        if math.isfinite(f):
            return f
        self.rejected_nonfinite += 1
        logger.debug("%s: the cost is %s at a trial point: rejected", self.name, f)
        return math.inf

    def grad(self, x: Any) -> Any:
        self.ngev += 1
        return self.problem.grad(x)

    def hess(self, x: Any, v: Any) -> Any:
        self.nhev += 1
        return self.problem.hess(x, v)

    def hess_operator(self, x: Any) -> Callable[[Any], Any]:
        """``v ↦ Hess f(x)[v]`` at a fixed ``x`` (:meth:`Problem.hess_operator`: what the
        point's memo lookups cost is paid once), counted like :meth:`hess`."""
        apply = self.problem.hess_operator(x)

        def counted(v: Any) -> Any:
            self.nhev += 1
            return apply(v)

        return counted

    def norm(self, x: Any, v: Any) -> float:
        """``‖v‖_x`` summed over any batch, safe from under- and overflow."""
        return safe_norm(self.manifold, x, v)

    def inner(self, x: Any, u: Any, v: Any) -> float:
        """``⟨u, v⟩_x`` summed over any batch (:meth:`~manopt_lie.manifolds.Manifold.total_inner`)."""
        return self.manifold.total_inner(x, u, v)

    def roundoff(self, f: float) -> float:
        """``ROUNDOFF·max(s, |f|)``: cost changes this small are indistinguishable from round-off."""
        return ROUNDOFF * max(self.scale, abs(f))

    def stall_status(self, predicted: float, f: float) -> Status:
        """The status of a step that collapsed at a point of cost ``f`` where the optimizer's
        model predicts the decrease ``predicted``: ``STEP_SIZE`` (converged to working
        precision) if that is round-off, else ``NO_PROGRESS`` (``nan`` included)."""
        return Status.STEP_SIZE if predicted <= self.roundoff(f) else Status.NO_PROGRESS

    # ---- iterations ---------------------------------------------------------------

    @property
    def nit(self) -> int:
        return max(len(self._records) - 1, 0)

    def elapsed(self) -> float:
        return time.perf_counter() - self.start

    def record(self, x: Any, f: float, grad_norm: float, step: float = math.nan, **extra: float) -> bool:
        """Record an iterate; ``True`` if the callback asks to stop (returns true or
        raises ``StopIteration``)."""
        return self.record_at(self.elapsed(), x, f, grad_norm, step, **extra)

    def record_at(self, now: float, x: Any, f: float, grad_norm: float, step: float = math.nan, **extra: float) -> bool:
        """:meth:`record` of an iterate that ended ``now`` seconds into the run (iterations run
        elsewhere, e.g. in compiled code, and recorded afterwards)."""
        if not self._records:
            self.scale = min(1.0, max(abs(f), grad_norm * self.manifold.typical_dist))
            self.grad_tol = max(self.stopping.grad_rtol * grad_norm, self.stopping.grad_atol * self.scale)
            if self.progress is not None:
                self.progress.start(self.problem, self.stopping, self.grad_tol)
        self._records.append((f, grad_norm, step, now))
        self._x = x
        for key, value in extra.items():
            column = self._extra.get(key)
            if column is None:  # a key first seen now: nan for the records before
                column = self._extra[key] = [math.nan] * (len(self._records) - 1)
            column.append(value)
        logger.debug("%s %4d  f = %.12g  |grad| = %.3e  step = %.3e", self.name, self.nit, f, grad_norm, step)
        if self.progress is not None:
            self.progress.row(self.nit, f, grad_norm, step, now)
        if self.callback is None:
            return False
        info = IterationInfo(self.nit, x, f, grad_norm, step, now, dict(extra))
        try:
            return bool(self.callback(info))
        except StopIteration:
            return True

    def stop_reason(self, f_prev: float | None = None) -> Status | None:
        """The stopping test after the latest record (``f_prev``: the cost before an accepted step).

        ``Status.STEP_SIZE`` here only says that the step was short; the optimizer
        decides with its model whether that is convergence (:meth:`stall_status`).
        """
        s = self.stopping
        f, grad_norm, step, now = self._records[-1]
        if grad_norm <= self.grad_tol:
            return Status.GRADIENT_NORM
        if self.nit > 0 and step < s.min_step:
            return Status.STEP_SIZE
        if f_prev is not None:
            rel = s.rel_cost_decrease
            assert rel is not None, "Run needs a decided rule (StoppingCriteria.for_problem)"
            if rel > 0 and f_prev - f <= rel * max(self.scale, abs(f_prev)):
                return Status.COST_DECREASE
        if self.nit >= s.max_iterations:
            return Status.MAX_ITERATIONS
        if now >= s.max_time:
            return Status.MAX_TIME
        return None

    def result(self, x: Any, status: Status) -> OptimizeResult:
        """The result at ``x``, the last recorded point (``nan`` cost and gradient norm
        if nothing was recorded: an interrupt during the evaluation at ``x₀``)."""
        records = np.array(self._records, dtype=np.float64).reshape(-1, 4)
        extra = {k: np.array(v + [math.nan] * (len(records) - len(v))) for k, v in self._extra.items()}
        history = History(records[:, 0], records[:, 1], records[:, 2], records[:, 3], extra)
        f, grad_norm = (records[-1, 0], records[-1, 1]) if len(records) else (math.nan, math.nan)
        res = OptimizeResult(
            x, float(f), float(grad_norm), self.nit, self.nfev, self.ngev, self.nhev,
            self.elapsed(), status, status.message, history,
        )  # fmt: skip
        logger.info("%s: %s", self.name, res)
        if self.progress is not None:
            self.progress.end(res)
        return res

    def interrupted(self, x0: Any) -> OptimizeResult:
        """The result after a ``KeyboardInterrupt``: the last recorded point (``x₀`` if none)."""
        return self.result(self._x if self._records else x0, Status.INTERRUPTED)


class Optimizer(ABC):
    """Base class: settings in ``__init__``, one ``solve`` for every problem."""

    def __init__(self, *, stopping: StoppingCriteria | None = None, verbosity: int = 0, **fields: Any) -> None:
        """Keep the stopping rule: ``stopping``, or ``StoppingCriteria(**fields)``; and the verbosity.

        Parameters
        ----------
        stopping : StoppingCriteria, optional
            The whole rule.
        verbosity : {0, 1, 2}
            What ``solve`` prints to stderr (pymanopt's habit): 0 nothing, 1 a line
            at the start and the result at the end, 2 also one table row per
            iteration — iteration, cost, gradient norm, step, time
            (:class:`~._verbosity.Progress`).
        **fields
            Or some of the rule's fields (``max_iterations=…``), the others at their defaults.

        Raises
        ------
        TypeError
            If both are given, ``stopping`` is not a ``StoppingCriteria``, or a
            keyword is not a field (naming it).
        ValueError
            If ``verbosity`` is not 0, 1 or 2.
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
        self.verbosity = check_verbosity(verbosity, name)

    @property
    def first_order(self) -> bool:
        """Whether the steps follow gradient directions with a line search (``GradientDescent``,
        ``ConjugateGradient``: optimizers with a :class:`~.line_search.LineSearch` as
        ``line_search``) rather than a model with curvature (Gauss-Newton,
        Levenberg-Marquardt, the trust region). A first-order run on a least-squares problem
        does not get the cost-decrease default (:meth:`StoppingCriteria.for_problem`)."""
        return isinstance(getattr(self, "line_search", None), LineSearch)

    def solve(self, problem: Problem, x0: Any, callback: Callback | None = None) -> OptimizeResult:
        """Minimize ``problem`` from ``x0``.

        ``callback(info)`` (an :class:`IterationInfo`) is called after every
        iteration, the initial point included; returning a true value or raising
        ``StopIteration`` ends the run cleanly with ``Status.CALLBACK``. The
        stopping rule is the optimizer's, decided for the problem
        (:meth:`StoppingCriteria.for_problem`: ``rel_cost_decrease`` unset is 1e-5
        on a least-squares problem, except for steepest descent and CG). The
        callbacks' results are checked once, at ``x0``. A ``KeyboardInterrupt``
        (Ctrl-C) during the run is not raised: ``solve`` returns the last accepted
        point with ``Status.INTERRUPTED`` (``converged`` false). Non-finite costs
        at trial points reject them; nothing raises ``FloatingPointError``, and
        NumPy's overflow/invalid/divide warnings are silenced for the run's duration
        (its callbacks' included): what they would flag is handled.

        Raises
        ------
        ValueError (a subclass)
            If ``x0`` is not a finite point of the problem's manifold
            (``NotOnManifoldError``, ``ShapeError``), if a callback returns the
            wrong shape at ``x0`` (``ShapeError``, naming it, with the expected
            and the actual shape), or if the cost or the gradient is not finite
            there (``NonFiniteError``).
        TypeError
            If ``problem`` is not a :class:`Problem`, or a callback returns
            something other than real numbers at ``x0``.
        NotImplementedError
            If the problem lacks a derivative the optimizer needs.
        """
        if not isinstance(problem, Problem):
            raise TypeError(f"{type(self).__name__}.solve: expected a Problem, got {type(problem).__name__}")
        problem.manifold.check_point(x0, "x0")
        if not problem.has_gradient:
            raise NotImplementedError(f"{type(self).__name__} needs a gradient: build the Problem with egrad or rgrad")
        name = type(self).__name__
        progress = Progress(name, self.verbosity) if self.verbosity else None
        stopping = self.stopping.for_problem(problem, first_order=self.first_order)
        run = Run(name, problem, stopping, callback, progress)
        try:
            # Non-finite values are handled (rejected, or reported by a status or an error),
            # so NumPy's warnings about producing them would only be noise.
            with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
                return self._solve(run, x0)
        except KeyboardInterrupt:
            return run.interrupted(x0)

    @abstractmethod
    def _solve(self, run: Run, x0: Any) -> OptimizeResult:
        """The iteration, recording through ``run``."""
