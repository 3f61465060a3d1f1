"""What an optimizer returns: a status, the solution, counters and the history."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum
from typing import Any

import numpy as np
from numpy.typing import NDArray


class Status(Enum):
    """Why an optimizer stopped; :attr:`converged` says whether that is success.

    Only the three convergence tests are success. ``STEP_SIZE`` is issued only
    where it is earned: the step (the trust region, Levenberg-Marquardt's
    damping) collapsed at a point where the optimizer's model predicts no
    decrease the cost can resolve; a collapse where the model still promises
    one — the cost and its derivatives disagree, e.g. a wrong gradient — is
    ``NO_PROGRESS``.
    """

    GRADIENT_NORM = "the gradient norm fell below the tolerance"
    COST_DECREASE = "the relative cost decrease fell below the tolerance"
    STEP_SIZE = "the step fell below the tolerance where no further decrease is resolvable"
    MAX_ITERATIONS = "the iteration limit was reached"
    MAX_TIME = "the time limit was reached"
    LINE_SEARCH_FAILED = "the line search found no decrease"
    LINEAR_SOLVER_FAILED = "the linear solver gave no descent direction"
    CALLBACK = "the callback asked to stop"
    NO_PROGRESS = "the step collapsed although the model predicts a decrease (are the derivatives right?)"
    NON_FINITE = "the gradient was not finite at a new point; the run stopped at the last finite one"
    INTERRUPTED = "interrupted (KeyboardInterrupt); the last accepted point is returned"

    @property
    def converged(self) -> bool:
        """Whether the stop is a convergence test (gradient, cost decrease or step size)."""
        return self in _CONVERGED


_CONVERGED = frozenset({Status.GRADIENT_NORM, Status.COST_DECREASE, Status.STEP_SIZE})


@dataclass(frozen=True)
class History:
    """Per-iteration records, index 0 being the initial point.

    ``extra`` holds optimizer-specific series (e.g. the trust-region radius).
    """

    cost: NDArray[np.float64]
    grad_norm: NDArray[np.float64]
    step: NDArray[np.float64]
    time: NDArray[np.float64]
    extra: dict[str, NDArray[np.float64]] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.cost)


@dataclass(frozen=True)
class IterationInfo:
    """What a callback sees after each iteration (``iteration = 0``: the initial point)."""

    iteration: int
    x: Any
    fun: float
    grad_norm: float
    step: float
    time: float
    extra: dict[str, float]


@dataclass(frozen=True)
class OptimizeResult:
    """The result of ``Optimizer.solve`` (names as in ``scipy.optimize``).

    Attributes
    ----------
    x : the final point.
    fun : its cost.
    grad_norm : the Riemannian gradient norm there.
    nit : iterations performed.
    nfev, ngev, nhev : cost, gradient and Hessian-vector evaluations.
    time : wall time in seconds.
    status : :class:`Status`; ``message`` says it in words.
    history : :class:`History`, ``nit + 1`` records.
    """

    x: Any
    fun: float
    grad_norm: float
    nit: int
    nfev: int
    ngev: int
    nhev: int
    time: float
    status: Status
    message: str
    history: History

    @property
    def success(self) -> bool:
        return self.status.converged

    def __str__(self) -> str:
        return (
            f"{self.message}: f = {self.fun:.10g}, |grad| = {self.grad_norm:.3e} after {self.nit} iterations "
            f"({self.nfev} costs, {self.ngev} gradients, {self.nhev} Hessian products) in {self.time:.3g} s"
        )
