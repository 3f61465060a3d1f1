"""Stateless line searches along a retraction curve: Armijo backtracking and strong Wolfe.

Along a descent direction ``η`` at ``x`` both study ``φ(α) = f(R_x(α η))``, with
``φ'(0) = ⟨grad f(x), η⟩ < 0`` and, away from 0, the Riemannian surrogate

    φ'(α) ≈ ⟨grad f(y), T_{x→y}(η)⟩,    y = R_x(α η),

``T`` the manifold's vector transport. It is exact on Lie groups (``T`` is the
identity on coordinates and ``d/dα X Exp(ατ) = X Exp(ατ) τ^``) and off by a
positive factor on the sphere, so its sign, which steers the search, is right.

Everything a search needs from earlier iterations (the previous cost and step)
is passed in, so one search never leaks into the next.

Both accept only a strict decrease, ``φ(α) < φ(0)``, besides the
sufficient-decrease test (which, once ``c₁αφ'(0)`` is below the round-off of
``φ(0)``, an unchanged cost would pass). A trial point whose cost is ``+inf``
(what :class:`~manopt_lie.optim.optimizer.Run` makes of a ``nan`` or infinite
cost) fails every test, so the searches backtrack from it; the strong Wolfe
search treats a trial with a non-finite gradient alike.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from ..manifolds.base import Manifold

__all__ = [
    "Backtracking",
    "LineSearch",
    "LineSearchResult",
    "StrongWolfe",
    "armijo",
    "initial_step",
    "newton_step",
    "probe_decrease",
    "select_line_search",
]

_EPS = float(np.finfo(float).eps)


@dataclass(frozen=True)
class LineSearchResult:
    """``x = R_{x₀}(α η)`` with ``alpha = α``; ``step`` is ``α‖η‖``.

    ``nfev`` and ``ngev`` count the search's cost and gradient evaluations.
    ``grad`` is ``grad f(x)`` when the search evaluated it there (strong Wolfe), for the
    optimizer to reuse; ``None`` otherwise. ``wolfe`` says whether ``x`` satisfies the
    strong Wolfe conditions: a strong Wolfe search that runs out of evaluations falls
    back to its best point with sufficient decrease. ``success`` is ``False`` only when
    no trial decreased the cost enough; ``x`` is then ``x₀``. ``transported`` is
    ``T_{x₀→x}(η)`` when the search computed it for ``φ'(α)`` (with ``grad``), so that
    conjugate gradients and L-BFGS need not transport ``η`` again; ``None`` otherwise.
    """

    x: Any
    fun: float
    alpha: float
    step: float
    nfev: int
    success: bool
    grad: Any = None
    ngev: int = 0
    wolfe: bool = False
    transported: Any = None


def initial_step(
    f0: float,
    f_prev: float | None,
    slope: float,
    d_norm: float,
    max_step: float,
    *,
    optimism: float = 1.0,
    alpha_prev: float | None = None,
    growth: float = math.inf,
) -> float:
    """Manopt's adaptive first trial ``α``, capped.

    ``optimism · 2(f_prev − f₀)/|φ'(0)|``: ``2(f_prev − f₀)/|φ'(0)|`` minimizes the quadratic
    with ``φ(0) = f₀`` and slope ``φ'(0)`` whose decrease repeats the last one
    (Nocedal–Wright eq. 3.60); Manopt looks ``optimism = 2`` times further. At most
    ``growth·alpha_prev`` (the previous accepted ``α``: after a large decrease the rule
    overshoots by orders of magnitude) and ``max_step/‖η‖``. Without a previous cost, or
    if the guess is below round-off, a unit-length step ``1/‖η‖``.
    """
    alpha = optimism * 2.0 * (f_prev - f0) / -slope if f_prev is not None and slope < 0 else math.nan
    if alpha_prev is not None and alpha_prev > 0:
        alpha = min(alpha, growth * alpha_prev)
    if not (alpha * d_norm > _EPS):  # also nan
        alpha = 1.0 / d_norm
    return min(alpha, max_step / d_norm)


def newton_step(d_norm: float, max_step: float) -> float:
    """``α = 1``, at most ``max_step/‖η‖``: the first trial along a quasi-Newton direction."""
    return min(1.0, max_step / d_norm)


def armijo(
    cost: Callable[[Any], float],
    manifold: Manifold,
    x0: Any,
    f0: float,
    d: Any,
    d_norm: float,
    slope: float,
    alpha: float,
    *,
    sufficient_decrease: float = 1e-4,
    contraction: float = 0.5,
    max_backtracks: int = 30,
    interpolate: bool = False,
) -> LineSearchResult:
    """Backtrack from ``alpha`` until ``f(R_x(α d)) ≤ f₀ + c·α·slope`` (Armijo) and ``< f₀``.

    The strict decrease matters once ``c·α·slope`` is below the round-off of ``f₀``:
    a step that leaves the cost unchanged is no progress, whatever its length.

    ``slope = ⟨grad f(x₀), d⟩ < 0`` is the directional derivative and ``d_norm = ‖d‖``. Each
    failed trial multiplies ``α`` by ``contraction`` or, with ``interpolate``, moves it to the
    minimizer of the quadratic through ``φ(0), φ'(0), φ(α)`` kept in
    ``[min(0.1, contraction)·α, contraction·α]`` (Nocedal–Wright §3.5). Fails
    (``success=False``, returning ``x₀``) when ``max_backtracks`` contractions
    find no sufficient decrease.
    """
    low = min(0.1, contraction)
    for k in range(max_backtracks + 1):
        y = manifold.retr(x0, d * alpha)
        f = cost(y)
        if f <= f0 + sufficient_decrease * alpha * slope and f < f0:
            return LineSearchResult(y, f, alpha, alpha * d_norm, k + 1, True)
        curvature = f - f0 - slope * alpha  # > 0 after the failed test, unless in round-off
        if interpolate and 0 < curvature < math.inf:
            q = -slope * alpha * alpha / (2.0 * curvature)
            alpha = min(max(q, low * alpha), contraction * alpha)
        elif interpolate and curvature <= 0:
            alpha *= low
        else:  # f = inf (not finite) says nothing about the curvature: contract
            alpha *= contraction
    return LineSearchResult(x0, f0, 0.0, 0.0, max_backtracks + 1, False)


def probe_decrease(cost: Callable[[Any], float], manifold: Manifold, x: Any, f: float, g: Any, g_norm: float) -> float:
    """The decrease ``f − f(y)`` that a fresh Armijo search along ``−g`` finds from a step
    of unit length (at most ``typical_dist``), 0 if it finds none.

    What steepest descent and conjugate gradients, which have no model of the cost,
    use to judge a step that collapsed: a decrease above round-off means the
    collapse was not convergence.
    """
    slope = -(g_norm * g_norm)
    alpha = initial_step(f, None, slope, g_norm, manifold.typical_dist)
    ls = armijo(cost, manifold, x, f, -g, g_norm, slope, alpha, interpolate=True)
    return f - ls.fun if ls.success else 0.0


class LineSearch(ABC):
    """What :class:`GradientDescent` and :class:`ConjugateGradient` call: a stateless search
    along ``α ↦ R_{x₀}(α d)``."""

    @abstractmethod
    def search(
        self,
        cost: Callable[[Any], float],
        grad: Callable[[Any], Any],
        manifold: Manifold,
        x0: Any,
        f0: float,
        d: Any,
        d_norm: float,
        slope: float,
        *,
        f_prev: float | None = None,
        alpha_prev: float | None = None,
        alpha0: float | None = None,
    ) -> LineSearchResult:
        """Search from ``x₀`` (cost ``f₀``) along ``d`` (``d_norm = ‖d‖``,
        ``slope = ⟨grad f(x₀), d⟩ < 0``).

        ``cost`` and ``grad`` are the optimizer's (counted) evaluations; ``f_prev`` and
        ``alpha_prev`` are the previous iterate's cost and accepted ``α`` (``None`` at the
        first iteration), for the first trial. ``alpha0``, if given, is the optimizer's own
        first trial (e.g. a Barzilai–Borwein step), used instead of the search's rule (still
        at most ``typical_dist/‖η‖``).
        """


@dataclass(frozen=True)
class Backtracking(LineSearch):
    """Armijo backtracking (:func:`armijo`) from Manopt's adaptive first trial (:func:`initial_step`).

    Parameters
    ----------
    sufficient_decrease : float
        ``c₁`` in ``φ(α) ≤ φ(0) + c₁ α φ'(0)``, in ``(0, 1)``.
    contraction : float
        The largest backtracking factor, in ``(0, 1)``.
    max_backtracks : int
        Contractions before the search fails.
    optimism : float
        How much further than the quadratic model's step the first trial looks (Manopt: 2).
    growth : float
        The first trial is at most ``growth`` times the previous accepted ``α``.
    interpolate : bool
        Backtrack to the quadratic interpolant's minimizer (``True``) or by ``contraction``.
    initial : {"quadratic", "newton"}
        The first trial: :func:`initial_step` (``optimism``, ``growth``), or ``"newton"``:
        ``α = 1`` (at most ``typical_dist/‖η‖``), the step of a quasi-Newton direction
        (:class:`~manopt_lie.optim.LBFGS`), which carries its own scale.
    """

    sufficient_decrease: float = 1e-4
    contraction: float = 0.5
    max_backtracks: int = 30
    optimism: float = 2.0
    growth: float = 4.0
    interpolate: bool = True
    initial: str = "quadratic"

    def __post_init__(self) -> None:
        if not (0 < self.sufficient_decrease < 1 and 0 < self.contraction < 1):
            raise ValueError("line search: need 0 < sufficient_decrease < 1 and 0 < contraction < 1")
        if not (self.optimism > 0 and self.growth > 0 and self.max_backtracks >= 0):
            raise ValueError("line search: need optimism > 0, growth > 0 and max_backtracks >= 0")
        if self.initial not in ("quadratic", "newton"):
            raise ValueError(f"line search: initial must be 'quadratic' or 'newton', got {self.initial!r}")

    def search(
        self,
        cost: Callable[[Any], float],
        grad: Callable[[Any], Any],
        manifold: Manifold,
        x0: Any,
        f0: float,
        d: Any,
        d_norm: float,
        slope: float,
        *,
        f_prev: float | None = None,
        alpha_prev: float | None = None,
        alpha0: float | None = None,
    ) -> LineSearchResult:
        """Armijo backtracking along ``R_{x₀}(α d)`` (``grad`` is not used)."""
        if alpha0 is not None:
            alpha = min(alpha0, manifold.typical_dist / d_norm)
        elif self.initial == "newton":
            alpha = newton_step(d_norm, manifold.typical_dist)
        else:
            alpha = initial_step(
                f0, f_prev, slope, d_norm, manifold.typical_dist,
                optimism=self.optimism, alpha_prev=alpha_prev, growth=self.growth,
            )  # fmt: skip
        return armijo(
            cost, manifold, x0, f0, d, d_norm, slope, alpha,
            sufficient_decrease=self.sufficient_decrease, contraction=self.contraction,
            max_backtracks=self.max_backtracks, interpolate=self.interpolate,
        )  # fmt: skip


# ---- strong Wolfe -----------------------------------------------------------------


def _cubic_min(a: float, fa: float, da: float, b: float, fb: float, db: float) -> float:
    """The minimizer of the cubic through ``(a, fa, da)`` and ``(b, fb, db)`` (Nocedal–Wright
    eq. 3.59); ``nan`` if it has none."""
    d1 = da + db - 3.0 * (fa - fb) / (a - b)
    disc = d1 * d1 - da * db
    if not disc >= 0:
        return math.nan
    d2 = math.copysign(math.sqrt(disc), b - a)
    den = db - da + 2.0 * d2
    return b - (b - a) * (db + d2 - d1) / den if den != 0 else math.nan


def _quadratic_min(a: float, fa: float, da: float, b: float, fb: float) -> float:
    """The minimizer of the quadratic through ``(a, fa, da)`` and ``(b, fb)``; ``nan`` unless convex."""
    h = b - a
    curv = fb - fa - da * h
    return a - da * h * h / (2.0 * curv) if curv > 0 else math.nan


class _Trial(NamedTuple):
    """A trial step: ``φ(α)``, ``φ'(α)`` (``nan`` until evaluated), the point, its gradient
    and ``T_{x₀→y}(η)``."""

    alpha: float
    f: float
    df: float = math.nan
    y: Any = None
    g: Any = None
    td: Any = None


@dataclass(frozen=True)
class StrongWolfe(LineSearch):
    """A step satisfying the strong Wolfe conditions

        φ(α) ≤ φ(0) + c₁ α φ'(0),      |φ'(α)| ≤ c₂ |φ'(0)|,

    by bracketing and zoom (Nocedal & Wright, Algorithms 3.5 and 3.6).

    *Bracketing*: trials grow from the first one, by cubic extrapolation kept within
    2–5 times the last step, until one breaks the sufficient decrease, stops decreasing
    or has ``φ' ≥ 0``. *Zoom*: the bracket shrinks to the minimizer of the cubic
    through its ends (``φ'`` known at both) or of the quadratic through
    ``φ(lo), φ'(lo), φ(hi)``, kept 10% of the bracket away from its ends. The gradient
    is evaluated only at trials with sufficient decrease that improve on the best one,
    and returned with the accepted point.

    *First trial*: ``initial="quadratic"`` is :func:`initial_step` (capped at ``growth``
    times the previous ``α``); ``initial="previous"`` is the previous accepted ``α``
    (for conjugate gradients, whose steps vary slowly). Both are ``1/‖η‖`` at the first
    iteration and at most ``typical_dist/‖η‖`` (later trials may go further).
    ``initial="newton"`` is ``α = 1`` (:func:`newton_step`; L-BFGS, whose direction
    carries its scale), also capped at ``typical_dist/‖η‖``. With a
    finite ``refine_tol``, a first trial ``α₀`` with sufficient decrease is first refined
    to the minimizer ``α_q`` of the quadratic through ``φ(0), φ'(0), φ(α₀)`` (one more
    cost, no gradient) unless ``|α_q − α₀| ≤ refine_tol·α₀``: a nearly exact step at one
    cost and one gradient in most conjugate-gradient iterations.

    Parameters
    ----------
    sufficient_decrease, curvature : float
        ``c₁`` and ``c₂``, ``0 < c₁ < c₂ < 1``. ``c₂ = 0.9`` suits steepest descent
        (a loose step), ``c₂ = 0.1`` conjugate gradients (a nearly exact one).
    max_evaluations : int
        Cost evaluations before giving up; the search then returns its best point with
        sufficient decrease (``wolfe=False``), or fails if there is none.
    initial : {"quadratic", "previous", "newton"}
        The first trial, see above.
    optimism, growth : float
        The factor on the quadratic first trial and its cap relative to the previous ``α``.
    refine_tol : float
        The refinement of the first trial, see above (``inf``: off).
    """

    sufficient_decrease: float = 1e-4
    curvature: float = 0.9
    max_evaluations: int = 25
    initial: str = "quadratic"
    optimism: float = 1.0
    growth: float = 4.0
    refine_tol: float = math.inf

    def __post_init__(self) -> None:
        c1, c2 = self.sufficient_decrease, self.curvature
        if not (0 < c1 < c2 < 1):
            raise ValueError(f"strong Wolfe: need 0 < sufficient_decrease < curvature < 1, got c1={c1!r}, c2={c2!r}")
        if not (self.max_evaluations >= 1 and self.optimism > 0 and self.growth > 0 and self.refine_tol >= 0):
            raise ValueError("strong Wolfe: need max_evaluations >= 1, optimism > 0, growth > 0 and refine_tol >= 0")
        if self.initial not in ("quadratic", "previous", "newton"):
            raise ValueError(f"strong Wolfe: initial must be 'quadratic', 'previous' or 'newton', got {self.initial!r}")

    def _first_trial(
        self, f0: float, f_prev: float | None, slope: float, d_norm: float, max_step: float, alpha_prev: float | None
    ) -> float:
        if self.initial == "newton":
            return newton_step(d_norm, max_step)
        if self.initial == "previous":
            alpha = alpha_prev if alpha_prev is not None and alpha_prev * d_norm > _EPS else 1.0 / d_norm
            return min(alpha, max_step / d_norm)
        return initial_step(
            f0, f_prev, slope, d_norm, max_step, optimism=self.optimism, alpha_prev=alpha_prev, growth=self.growth
        )

    def search(
        self,
        cost: Callable[[Any], float],
        grad: Callable[[Any], Any],
        manifold: Manifold,
        x0: Any,
        f0: float,
        d: Any,
        d_norm: float,
        slope: float,
        *,
        f_prev: float | None = None,
        alpha_prev: float | None = None,
        alpha0: float | None = None,
    ) -> LineSearchResult:
        """Bracketing and zoom along ``R_{x₀}(α d)``; see the class docstring."""
        c1, c2 = self.sufficient_decrease, self.curvature
        nfev = ngev = 0

        def value(alpha: float) -> _Trial:
            nonlocal nfev
            nfev += 1
            y = manifold.retr(x0, d * alpha)
            return _Trial(alpha, cost(y), math.nan, y)

        def with_derivative(t: _Trial) -> _Trial:
            """``t`` with ``φ'(α)``; a non-finite gradient makes it a failed trial (``f = inf``, ``df = nan``)."""
            nonlocal ngev
            ngev += 1
            g = grad(t.y)
            td = manifold.transp(x0, t.y, d)
            df = manifold.total_inner(t.y, g, td)
            if not math.isfinite(df):
                return _Trial(t.alpha, math.inf, math.nan, t.y, None)
            return _Trial(t.alpha, t.f, df, t.y, g, td)

        def done(t: _Trial, wolfe: bool) -> LineSearchResult:
            if t.alpha == 0.0:
                return LineSearchResult(x0, f0, 0.0, 0.0, nfev, False, None, ngev, False)
            return LineSearchResult(t.y, t.f, t.alpha, t.alpha * d_norm, nfev, True, t.g, ngev, wolfe, t.td)

        def decreases(t: _Trial) -> bool:
            return t.f <= f0 + c1 * t.alpha * slope and t.f < f0

        def curvature_ok(t: _Trial) -> bool:
            return abs(t.df) <= -c2 * slope

        prev = _Trial(0.0, f0, slope)
        if alpha0 is None:
            t = value(self._first_trial(f0, f_prev, slope, d_norm, manifold.typical_dist, alpha_prev))
        else:
            t = value(min(alpha0, manifold.typical_dist / d_norm))
        if math.isfinite(self.refine_tol) and decreases(t) and t.f < f0:
            a = t.alpha
            q = _quadratic_min(0.0, f0, slope, a, t.f)  # nan if concave: look further
            if not abs(q - a) <= self.refine_tol * a:
                r = value(4.0 * a if math.isnan(q) else min(max(q, 0.1 * a), 4.0 * a))
                t = r if decreases(r) and r.f < t.f else t
        # Bracketing (Algorithm 3.5): until [lo, hi] holds a Wolfe point.
        while True:
            if not decreases(t) or (prev.alpha > 0 and t.f >= prev.f):
                lo, hi = prev, t
                break
            t = with_derivative(t)
            if math.isnan(t.df):  # no usable gradient there
                lo, hi = prev, t
                break
            if curvature_ok(t):
                return done(t, True)
            if t.df >= 0:
                lo, hi = t, prev
                break
            if nfev >= self.max_evaluations:
                return done(t, False)  # sufficient decrease, but no Wolfe point (yet)
            width = t.alpha - prev.alpha
            ext = _cubic_min(prev.alpha, prev.f, prev.df, t.alpha, t.f, t.df)
            ext = t.alpha + 4.0 * width if math.isnan(ext) else min(max(ext, t.alpha + width), t.alpha + 4.0 * width)
            prev, t = t, value(ext)
        # Zoom (Algorithm 3.6): lo has sufficient decrease, the lowest cost so far and a known
        # φ'(lo), with φ'(lo)·(hi − lo) < 0.
        while nfev < self.max_evaluations:
            a, b = lo.alpha, hi.alpha
            if math.isnan(hi.df):
                alpha = _quadratic_min(a, lo.f, lo.df, b, hi.f)
            else:
                alpha = _cubic_min(a, lo.f, lo.df, b, hi.f, hi.df)
            margin = 0.1 * abs(b - a)
            alpha = 0.5 * (a + b) if math.isnan(alpha) else min(max(alpha, min(a, b) + margin), max(a, b) - margin)
            if alpha in (a, b):  # the bracket is below round-off
                break
            t = value(alpha)
            if not decreases(t) or t.f >= lo.f:
                hi = t
                continue
            t = with_derivative(t)
            if math.isnan(t.df):
                hi = t
                continue
            if curvature_ok(t):
                return done(t, True)
            if t.df * (b - a) >= 0:
                hi = lo
            lo = t
        return done(lo, False)


def select_line_search(
    kind: str | LineSearch, armijo: Callable[[], LineSearch], wolfe: Callable[[], LineSearch], owner: str
) -> LineSearch:
    """The search an optimizer's ``line_search=`` setting names: ``"armijo"`` or ``"wolfe"``, built
    by the matching callable with the optimizer's settings (validated then), or an instance."""
    if isinstance(kind, LineSearch):
        return kind
    if kind == "armijo":
        return armijo()
    if kind == "wolfe":
        return wolfe()
    raise ValueError(f"{owner}: line_search must be 'armijo', 'wolfe' or a LineSearch instance, got {kind!r}")
