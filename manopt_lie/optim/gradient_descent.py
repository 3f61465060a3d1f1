"""Riemannian steepest descent with an Armijo or a strong-Wolfe line search."""

from __future__ import annotations

import math
from typing import Any

from .line_search import Backtracking, LineSearch, StrongWolfe, probe_decrease, select_line_search
from .optimizer import Optimizer, Run, StoppingCriteria
from .result import OptimizeResult, Status

INITIAL_STEPS = ("barzilai-borwein", "adaptive")


class GradientDescent(Optimizer):
    """``x_{k+1} = R_{x_k}(−α_k g_k)``, ``g_k = grad f(x_k)``, with ``α_k`` from a line search on
    ``φ(α) = f(R_{x_k}(−α g_k))``, ``φ'(0) = −‖g_k‖²``.

    Parameters
    ----------
    line_search : {"armijo", "wolfe"} or LineSearch
        ``"armijo"`` (default): :class:`~manopt_lie.optim.line_search.Backtracking` until
        ``φ(α) ≤ φ(0) + c₁ α φ'(0)``, backtracking to the minimizer of the quadratic
        interpolant. ``"wolfe"``: :class:`~manopt_lie.optim.line_search.StrongWolfe`, which
        also asks ``|φ'(α)| ≤ c₂ |φ'(0)|``; the gradient it evaluates at the accepted point is
        reused. An instance is used as given.
    initial : {"barzilai-borwein", "adaptive"}
        The first trial ``α`` of each search. ``"barzilai-borwein"`` (default): the
        Riemannian Barzilai–Borwein steps (Iannazzo and Porcelli 2018), alternately
        ``α¹ = ⟨s, s⟩/⟨s, y⟩`` and ``α² = ⟨s, y⟩/⟨y, y⟩`` (Dai and Fletcher's ABB) from the last
        step ``s = T(−α_{k−1} g_{k−1})`` and ``y = g_k − T(g_{k−1})``, ``T = T_{x_{k−1}→x_k}``: the
        inverse of a secant estimate of the curvature along the last step. Where
        ``⟨s, y⟩ ≤ 0`` (no positive curvature seen), and at the first iteration, it is
        ``"adaptive"``: Manopt's ``α = 2(f_{k−1} − f_k)/‖g_k‖²`` (at most 4 times the previous
        ``α``; a step of unit length at the first iteration). The search stays monotone (the
        trial is only its start), so every accepted step decreases the cost.
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
    1: on the benchmark problems the doubled trial cost a second cost evaluation in most
    iterations for the same iteration count. The Barzilai–Borwein trial cut the iterations
    to the gradient test 4× on a Rayleigh quotient on S⁹⁹⁹ and from more than 10 000 to
    about 1 100 on a Brockett cost on St(1000, 5) (docs/optimizers.md, Benchmarks).
    """

    def __init__(
        self,
        *,
        line_search: str | LineSearch = "armijo",
        initial: str = "barzilai-borwein",
        sufficient_decrease: float = 1e-4,
        contraction: float = 0.5,
        max_backtracks: int = 30,
        curvature: float = 0.9,
        stopping: StoppingCriteria | None = None,
        **fields: Any,
    ) -> None:
        super().__init__(stopping=stopping, **fields)
        if initial not in INITIAL_STEPS:
            raise ValueError(f"GradientDescent: initial must be one of {INITIAL_STEPS}, got {initial!r}")
        self.initial = initial
        self.line_search = select_line_search(
            line_search,
            lambda: Backtracking(sufficient_decrease, contraction, max_backtracks, optimism=1.0),
            lambda: StrongWolfe(sufficient_decrease, curvature),
            "GradientDescent",
        )

    @staticmethod
    def _barzilai_borwein(run: Run, x: Any, s: Any, y: Any, long: bool) -> float | None:
        """``⟨s, s⟩/⟨s, y⟩`` (``long``) or ``⟨s, y⟩/⟨y, y⟩``, from norms so that neither square
        under- nor overflows; ``None`` without positive curvature."""
        sy = run.inner(x, s, y)
        if not (sy > 0 and math.isfinite(sy)):
            return None
        a = run.norm(x, s) if long else run.norm(x, y)
        alpha = a * (a / sy) if long else sy / a / a
        return alpha if 0 < alpha < math.inf else None

    def _solve(self, run: Run, x0: Any) -> OptimizeResult:
        m, search = run.manifold, self.line_search.search
        bb = self.initial == "barzilai-borwein"
        x = x0
        f, g, g_norm = run.initial(x0)
        f_prev: float | None = None
        alpha: float | None = None
        alpha0: float | None = None
        status = Status.CALLBACK if run.record(x, f, g_norm) else run.stop_reason()
        while status is None:
            slope = -(g_norm * g_norm)  # (a product: ** raises OverflowError)
            ls = search(run.cost, run.grad, m, x, f, -g, g_norm, slope, f_prev=f_prev, alpha_prev=alpha, alpha0=alpha0)
            if not ls.success:
                status = Status.LINE_SEARCH_FAILED
                break
            g_new = run.grad(ls.x) if ls.grad is None else ls.grad
            g_new_norm = run.norm(ls.x, g_new)
            if not math.isfinite(g_new_norm):
                status = Status.NON_FINITE
                break
            if bb:  # s = T(−α g), y = g_new − T(g): one transport
                tg = m.transp(x, ls.x, g)
                alpha0 = self._barzilai_borwein(run, ls.x, tg * -ls.alpha, g_new - tg, run.nit % 2 == 0)
            f_prev, x, f, g, g_norm, alpha = f, ls.x, ls.fun, g_new, g_new_norm, ls.alpha
            stop = run.record(x, f, g_norm, ls.step, evaluations=ls.nfev)
            status = Status.CALLBACK if stop else run.stop_reason(f_prev)
            if status is Status.STEP_SIZE:  # converged only if nothing is left to gain along −g
                status = run.stall_status(probe_decrease(run.cost, m, x, f, g, g_norm), f)
        return run.result(x, status)
