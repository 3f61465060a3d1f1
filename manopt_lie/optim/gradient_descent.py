"""Riemannian steepest descent with an Armijo or a strong-Wolfe line search."""

from __future__ import annotations

import math
from typing import Any

from .line_search import Backtracking, LineSearch, StrongWolfe, probe_decrease, select_line_search
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
    A non-finite cost at a trial point counts as ``+inf`` (the search backtracks);
    a non-finite gradient at the accepted point ends the run with
    ``Status.NON_FINITE`` at the previous one. The search accepts only strict
    decreases, so an unchanged cost ends the run with ``Status.LINE_SEARCH_FAILED``.
    An accepted step shorter than ``min_step`` is convergence (``Status.STEP_SIZE``)
    only if a fresh Armijo search along ``−g`` from a step of unit length finds no
    decrease above round-off, ``ROUNDOFF·max(s, |f|)`` (:func:`probe_decrease`); if
    it does, the steps were being cut back for another reason (e.g. trial points
    without a finite cost) and the run ends with ``Status.NO_PROGRESS``.

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
        x = x0
        f, g, g_norm = run.initial(x0)
        f_prev: float | None = None
        alpha: float | None = None
        status = Status.CALLBACK if run.record(x, f, g_norm) else run.stop_reason()
        while status is None:
            slope = -(g_norm * g_norm)  # (a product: ** raises OverflowError)
            ls = search(run.cost, run.grad, m, x, f, -g, g_norm, slope, f_prev=f_prev, alpha_prev=alpha)
            if not ls.success:
                status = Status.LINE_SEARCH_FAILED
                break
            g_new = run.grad(ls.x) if ls.grad is None else ls.grad
            g_new_norm = run.norm(ls.x, g_new)
            if not math.isfinite(g_new_norm):
                status = Status.NON_FINITE
                break
            f_prev, x, f, g, g_norm, alpha = f, ls.x, ls.fun, g_new, g_new_norm, ls.alpha
            stop = run.record(x, f, g_norm, ls.step, evaluations=ls.nfev)
            status = Status.CALLBACK if stop else run.stop_reason(f_prev)
            if status is Status.STEP_SIZE:  # converged only if nothing is left to gain along −g
                status = run.stall_status(probe_decrease(run.cost, m, x, f, g, g_norm), f)
        return run.result(x, status)
