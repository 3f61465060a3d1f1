"""Riemannian steepest descent with a backtracking Armijo line search."""

from __future__ import annotations

from typing import Any

from .line_search import Backtracking
from .optimizer import Optimizer, Run
from .result import OptimizeResult, Status


class GradientDescent(Optimizer):
    """``x_{k+1} = R_{x_k}(−α_k grad f(x_k))`` with ``α_k`` from a backtracking Armijo
    search whose first trial is Manopt's adaptive guess ``2(f_{k−1} − f_k)/‖grad f(x_k)‖²``.

    Parameters
    ----------
    sufficient_decrease, contraction, max_backtracks
        The Armijo constant ``c`` in ``f(x⁺) ≤ f(x) − c α ‖g‖²``, the backtracking
        factor and the number of contractions before the search fails.
    **stopping
        See :class:`~manopt_lie.optim.optimizer.StoppingCriteria`.
    """

    def __init__(
        self,
        *,
        sufficient_decrease: float = 1e-4,
        contraction: float = 0.5,
        max_backtracks: int = 30,
        **stopping: Any,
    ) -> None:
        super().__init__(**stopping)
        self.line_search = Backtracking(sufficient_decrease, contraction, max_backtracks)

    def _solve(self, run: Run, x0: Any) -> OptimizeResult:
        m = run.manifold
        x, f = x0, run.cost(x0)
        g = run.grad(x)
        g_norm = run.norm(x, g)
        f_prev: float | None = None
        status = Status.CALLBACK if run.record(x, f, g_norm) else run.stop_reason()
        while status is None:
            ls = self.line_search.search(run.cost, m, x, f, f_prev, -g, g_norm, -(g_norm**2))
            if not ls.success:
                status = Status.LINE_SEARCH_FAILED
                break
            f_prev, x, f = f, ls.x, ls.fun
            g = run.grad(x)
            g_norm = run.norm(x, g)
            stop = run.record(x, f, g_norm, ls.step, backtracks=ls.nfev - 1)
            status = Status.CALLBACK if stop else run.stop_reason(f_prev)
        return run.result(x, status)
