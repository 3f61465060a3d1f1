"""What an optimizer returns: a status, the solution, counters and the history.

:class:`OptimizeResult` reads like SciPy's: attributes (``res.x``, ``res.fun``,
``res.success``, ``res.status``, ``res.message``) and, equally, a read-only
mapping (``res["x"]``, ``res.keys()``, ``dict(res)``). :class:`Status` is an
``IntEnum``: a name for people (``status.name``, ``Status.GRADIENT_NORM``), a
stable integer code for programs and files (``int(status)``, JSON), and a
sentence (``status.message``).
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from enum import IntEnum
from typing import Any

import numpy as np
from numpy.typing import NDArray


class Status(IntEnum):
    """Why an optimizer stopped; :attr:`converged` says whether that is success.

    The integer codes are stable (they are written to files and compared as
    ints, ``status == 1``); new statuses get new codes. Codes 1–3 are the three
    convergence tests, successes like ``CERTIFIED`` (12). ``STEP_SIZE`` is issued only where it
    is earned: the step (the trust region, Levenberg-Marquardt's damping)
    collapsed at a point where the optimizer's model predicts no decrease the
    cost can resolve; a collapse where the model still promises one — the cost
    and its derivatives disagree, e.g. a wrong gradient — is ``NO_PROGRESS``.

    No code is 0, so every status is truthy (``step.status or …`` stays safe).
    ``CERTIFIED`` (a success) is issued by solvers that prove global optimality (the
    certifiable staircase of :mod:`manopt_lie.problems.certify`).
    """

    GRADIENT_NORM = 1
    COST_DECREASE = 2
    STEP_SIZE = 3
    MAX_ITERATIONS = 4
    MAX_TIME = 5
    LINE_SEARCH_FAILED = 6
    LINEAR_SOLVER_FAILED = 7
    CALLBACK = 8
    NO_PROGRESS = 9
    NON_FINITE = 10
    INTERRUPTED = 11
    CERTIFIED = 12

    @property
    def converged(self) -> bool:
        """Whether the stop is a convergence test (gradient, cost decrease or step size)."""
        return self in _CONVERGED

    @property
    def message(self) -> str:
        """The status in words (what ``OptimizeResult.message`` says)."""
        return _MESSAGES[self]

    def __str__(self) -> str:  # the name, not the bare integer IntEnum would print
        return f"Status.{self.name}"

    def __format__(self, spec: str) -> str:
        return str(self) if not spec else format(int(self), spec)


_CONVERGED = frozenset({Status.GRADIENT_NORM, Status.COST_DECREASE, Status.STEP_SIZE, Status.CERTIFIED})
_MESSAGES = {
    Status.GRADIENT_NORM: "the gradient norm fell below the tolerance",
    Status.COST_DECREASE: "the relative cost decrease fell below the tolerance",
    Status.STEP_SIZE: "the step fell below the tolerance where no further decrease is resolvable",
    Status.MAX_ITERATIONS: "the iteration limit was reached",
    Status.MAX_TIME: "the time limit was reached",
    Status.LINE_SEARCH_FAILED: "the line search found no decrease",
    Status.LINEAR_SOLVER_FAILED: "the linear solver gave no descent direction",
    Status.CALLBACK: "the callback asked to stop",
    Status.NO_PROGRESS: "the step collapsed although the model predicts a decrease (are the derivatives right?)",
    Status.NON_FINITE: "the gradient was not finite at a new point; the run stopped at the last finite one",
    Status.INTERRUPTED: "interrupted (KeyboardInterrupt); the last accepted point is returned",
    Status.CERTIFIED: "the solution is certified globally optimal",
}


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


_KEYS = ("x", "fun", "grad_norm", "nit", "nfev", "ngev", "nhev", "time", "status", "message", "history", "success")


@dataclass(frozen=True)
class OptimizeResult(Mapping[str, Any]):
    """The result of ``Optimizer.solve`` (names as in ``scipy.optimize``), also a read-only mapping.

    Attributes
    ----------
    x : the final point.
    fun : its cost.
    grad_norm : the Riemannian gradient norm there.
    nit : iterations performed.
    nfev, ngev, nhev : cost, gradient and Hessian-vector evaluations.
    time : wall time in seconds.
    status : :class:`Status`, an ``IntEnum``: ``status is Status.GRADIENT_NORM``,
        ``int(status)`` its stable code, ``status.name`` its name.
    message : the status in words.
    history : :class:`History`, ``nit + 1`` records.
    success : ``status.converged`` (a property).

    Every attribute is also an item, ``res["x"]``; ``res.keys()`` lists them in the
    order above, ``dict(res)`` copies them (as ``scipy.optimize.OptimizeResult``, a
    ``dict``, allows). A result is immutable.
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
        """Whether the run stopped on a convergence test (``status.converged``), as SciPy's ``success``."""
        return self.status.converged

    # ---- the mapping ------------------------------------------------------------------

    def __getitem__(self, key: str) -> Any:
        if key not in _KEYS:
            raise KeyError(f"{key!r}; an OptimizeResult has the keys {', '.join(_KEYS)}")
        return getattr(self, key)

    def __iter__(self) -> Iterator[str]:
        return iter(_KEYS)

    def __len__(self) -> int:
        return len(_KEYS)

    def __contains__(self, key: object) -> bool:
        return key in _KEYS

    def __str__(self) -> str:
        return (
            f"{self.message}: f = {self.fun:.10g}, |grad| = {self.grad_norm:.3e} after {self.nit} iterations "
            f"({self.nfev} costs, {self.ngev} gradients, {self.nhev} Hessian products) in {self.time:.3g} s"
        )
