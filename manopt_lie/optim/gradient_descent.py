"""Riemannian steepest descent with an Armijo or a strong-Wolfe line search."""

from __future__ import annotations

from typing import Any

from .line_search import Backtracking, LineSearch, StrongWolfe, select_line_search
from .optimizer import Optimizer, Run, StoppingCriteria
from .result import OptimizeResult, Status


class GradientDescent(Optimizer):
    """``x_{k+1} = R_{x_k}(−α_k g_k)``, ``g_k = grad f(x_k)``, with ``α_k`` from a line search on
    ``φ(α) = f(R_{x_k}(−α g_k))``, ``φ'(0) = −‖g_k‖²``.

    Parameters
    ----------
    line_search : {"armijo", "wolfe"} or LineSearch
        ``"armijo"`` (default): :class:`~manopt_lie.optim.line_search.Backtracking` until
        ``φ(α) ≤ φ(0) + c₁ α φ'(0)``, from Manopt's adaptive first trial
        ``α = 2(f_{k−1} − f_k)/‖g_k‖²`` (at most 4 times the previous ``α``), backtracking to
        the minimizer of the quadratic interpolant. ``"wolfe"``:
        :class:`~manopt_lie.optim.line_search.StrongWolfe`, which also asks
        ``|φ'(α)| ≤ c₂ |φ'(0)|``; the gradient it evaluates at the accepted point is
        reused. An instance is used as given.
    sufficient_decrease : float
        ``c₁`` (both searches).
    contraction, max_backtracks
        The Armijo search's largest backtracking factor and its number of backtracks
        before it fails.
    curvature : float
        ``c₂`` of the strong Wolfe search (0.9: steepest descent needs no exact step).
    stopping, **fields
        A :class:`~manopt_lie.optim.StoppingCriteria`, or its fields as keywords.

    Notes
    -----
    Manopt looks ``optimism = 2`` times further than ``2(f_{k−1} − f_k)/‖g_k‖²``; here it is
    1: on the benchmark problems the doubled trial costs a second cost evaluation in most
    iterations for the same iteration count.
    """

    def __init__(
        self,
        *,
        line_search: str | LineSearch = "armijo",
        sufficient_decrease: float = 1e-4,
        contraction: float = 0.5,
        max_backtracks: int = 30,
        curvature: float = 0.9,
        stopping: StoppingCriteria | None = None,
        **fields: Any,
    ) -> None:
        super().__init__(stopping=stopping, **fields)
        self.line_search = select_line_search(
            line_search,
            lambda: Backtracking(sufficient_decrease, contraction, max_backtracks, optimism=1.0),
            lambda: StrongWolfe(sufficient_decrease, curvature),
            "GradientDescent",
        )

    def _solve(self, run: Run, x0: Any) -> OptimizeResult:
        m, search = run.manifold, self.line_search.search
        x, f = x0, run.cost(x0)
        g = run.grad(x)
        g_norm = run.norm(x, g)
        f_prev: float | None = None
        alpha: float | None = None
        status = Status.CALLBACK if run.record(x, f, g_norm) else run.stop_reason()
        while status is None:
            ls = search(run.cost, run.grad, m, x, f, -g, g_norm, -(g_norm**2), f_prev=f_prev, alpha_prev=alpha)
            if not ls.success:
                status = Status.LINE_SEARCH_FAILED
                break
            f_prev, x, f, alpha = f, ls.x, ls.fun, ls.alpha
            g = run.grad(x) if ls.grad is None else ls.grad
            g_norm = run.norm(x, g)
            stop = run.record(x, f, g_norm, ls.step, evaluations=ls.nfev)
            status = Status.CALLBACK if stop else run.stop_reason(f_prev)
        return run.result(x, status)
