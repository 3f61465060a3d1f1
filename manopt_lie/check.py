"""Numerical checks of gradients, Hessians and retractions (after Manopt's
``checkgradient``, ``checkhessian`` and ``checkretraction``).

Each check follows the curve ``c(t) = R_x(t d)`` for the steps
``t = 10⁻⁸ … 10⁰`` (51 points, log-spaced), measures an error ``e(t)`` that
a correct implementation makes ``O(t^k)``, and fits the slope of ``log e``
against ``log t``:

* :func:`check_gradient`: ``e(t) = |f(c(t)) − f(x) − t⟨grad f(x), d⟩|``, slope 2;
* :func:`check_hessian`: ``e(t) = |f(c(t)) − f(x) − t⟨grad f(x), d⟩ − t²/2 ⟨Hess f(x)[d], d⟩|``, slope 3;
* :func:`check_retraction`: ``e(t) = dist(Exp_x(t d), R_x(t d))``, slope 3 (second order) or 2 (first order).

The slope is read off the straightest long stretch of the curve: at small
``t`` the error drowns in round-off, at large ``t`` higher-order terms bend
it. Errors below a noise floor are ignored; when all of them are, the model
is exact to machine precision (a quadratic cost with its exact Hessian, a
retraction that *is* the exponential) and the check passes with slope ``nan``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from .manifolds.base import Manifold, MissingOperationError, Point, Tangent
from .optim.problem import Problem

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = ["CheckReport", "check_gradient", "check_hessian", "check_retraction"]

FloatArray = NDArray[np.float64]
RngLike = np.random.Generator | int | None

_STEPS = np.logspace(-8.0, 0.0, 51)
_MIN_WINDOW = 8  # fewer consecutive points do not make a trustworthy slope
_FIT_TOL = 0.02  # max residual (log10 units, ≈5 %) under which a window counts as straight
_COST_NOISE = 1e-12  # relative round-off floor of cost differences: the most it is taken to be
_COST_NOISE_MIN = 4 * np.finfo(float).eps  # ... and the least
_NOISE_STEPS = 8  # the smallest steps, where the remainder of a cost check is round-off (see _cost_floor)
_POINT_NOISE = 1e-14  # relative round-off floor of distances between points
_TANGENT_TOL = 1e-8
_SYMMETRY_TOL = 1e-6
_RETRACTION_TOL = 1e-6
_FD_STEP = 1e-5  # central difference: O(h²) truncation, O(ε/h) round-off, both ≪ _RETRACTION_TOL


@dataclass(frozen=True)
class CheckReport:
    """The outcome of a derivative or retraction check.

    Attributes
    ----------
    name : str
        ``"gradient"``, ``"hessian"`` or ``"retraction"``.
    expected_slope : float
        The slope of ``log e(t)`` against ``log t`` for a correct implementation
        (for retractions, that of a second-order one; first order passes too).
    slope : float
        The fitted slope; ``nan`` when every error is at machine precision.
    passed : bool
        Whether the slope is at least ``expected_slope − tol`` (``2 − tol`` for
        retractions: first order suffices) and every condition in
        :attr:`details` holds. A steeper error only means that the next Taylor
        term happens to vanish along the direction.
    t, error : ndarray, shape (51,)
        The steps and the errors ``e(t)``.
    window : tuple of int
        The fitted stretch ``t[i:j]`` as ``(i, j)``; ``(0, 0)`` when nothing was fitted.
    details : dict of str to float
        Side conditions: ``tangent_error``, ``symmetry_error`` (relative),
        ``retraction_order``, ``second_order`` (1.0/0.0), ``zero_error``,
        ``derivative_error``.
    message : str
        What was found, in words.
    """

    name: str
    expected_slope: float
    slope: float
    passed: bool
    t: FloatArray
    error: FloatArray
    window: tuple[int, int]
    details: dict[str, float]
    message: str

    def __str__(self) -> str:
        verdict = "passed" if self.passed else "FAILED"
        facts = ", ".join(f"{k} = {v:.3g}" for k, v in self.details.items())
        return f"{self.name} check {verdict}: {self.message}" + (f" [{facts}]" if facts else "")

    def plot(self, ax: Axes | None = None) -> Figure:
        """Draw ``e(t)`` on log-log axes, the fitted stretch highlighted, with a
        reference line of the expected slope; return the figure.

        Parameters
        ----------
        ax : matplotlib Axes, optional
            Where to draw; a new figure by default.

        Raises
        ------
        ImportError
            If matplotlib is not installed.
        """
        try:
            import matplotlib.pyplot as plt
        except ImportError as exc:
            raise ImportError("CheckReport.plot needs matplotlib: pip install matplotlib") from exc
        if ax is None:
            _, ax = plt.subplots()
        shown = np.isfinite(self.error) & (self.error > 0)  # log axes cannot show zeros
        ax.loglog(self.t[shown], self.error[shown], ".", color="0.4", label="error")
        i, j = self.window
        if j > i:
            ax.loglog(self.t[i:j], self.error[i:j], "-", lw=3, alpha=0.6, label=f"fit: slope {self.slope:.2f}")
            anchor: int | None = (i + j - 1) // 2
        else:
            anchor = int(np.flatnonzero(shown)[-1]) if shown.any() else None
        if anchor is not None:
            ref = self.error[anchor] * (self.t / self.t[anchor]) ** self.expected_slope
            ax.loglog(self.t, ref, "--", color="k", lw=1, label=f"slope {self.expected_slope:g}")
        ax.set_xlabel("step t")
        ax.set_ylabel("error")
        ax.set_title(f"{self.name} check: {'passed' if self.passed else 'FAILED'}")
        ax.legend()
        return ax.figure.figure  # the root figure, also when ax is in a sub-figure


def _fit_slope(t: FloatArray, error: FloatArray, floor: float | FloatArray) -> tuple[float, tuple[int, int]]:
    """Slope of ``log e`` against ``log t`` on the straightest long stretch of valid points.

    Valid points have finite errors above ``floor``. Every stretch ``t[i:j]`` of
    at least ``_MIN_WINDOW`` consecutive valid points gets a least-squares line
    and is scored by its largest absolute residual. Among the stretches whose
    residual is within ``_FIT_TOL`` (or, if none is, the best-fitting one) the
    longest wins, then the better fit. ``(nan, (0, 0))`` if no stretch exists.
    """
    n = t.size
    valid = np.isfinite(error) & (error > floor)
    i, j = np.triu_indices(n + 1, k=_MIN_WINDOW)  # all windows [i, j) of length ≥ _MIN_WINDOW
    invalid_before = np.concatenate([[0], np.cumsum(~valid)])
    clean = invalid_before[j] == invalid_before[i]
    if not clean.any():
        return float("nan"), (0, 0)
    i, j = i[clean], j[clean]
    x, y = np.log10(t), np.log10(np.where(valid, error, 1.0))
    inside = (np.arange(n) >= i[:, None]) & (np.arange(n) < j[:, None])
    length = j - i
    dx = np.where(inside, x - (inside @ x / length)[:, None], 0.0)
    dy = np.where(inside, y - (inside @ y / length)[:, None], 0.0)
    slope = np.sum(dx * dy, axis=1) / np.sum(dx * dx, axis=1)
    residual = np.max(np.abs(dy - slope[:, None] * dx), axis=1)
    straight = residual <= max(_FIT_TOL, residual.min())
    longest = np.flatnonzero(straight & (length == length[straight].max()))
    w = longest[np.argmin(residual[longest])]
    return float(slope[w]), (int(i[w]), int(j[w]))


def _slope_text(slope: float, window: tuple[int, int]) -> str:
    if np.isnan(slope):
        return "errors at machine precision: the model is exact"
    i, j = window
    return f"the error has slope {slope:.2f} over t ∈ [{_STEPS[i]:.0e}, {_STEPS[j - 1]:.0e}] ({j - i} steps)"


def _inner(m: Manifold, x: Point, u: Tangent, v: Tangent) -> float:
    return float(np.sum(m.inner(x, u, v)))  # a batch of points is a product manifold


def _norm(m: Manifold, x: Point, v: Tangent) -> float:
    return float(np.sqrt(max(_inner(m, x, v, v), 0.0)))


def _start(m: Manifold, x: Point | None, d: Tangent | None, rng: RngLike) -> tuple[Point, Tangent, np.random.Generator]:
    """The base point and direction, random where not given."""
    gen = np.random.default_rng(rng)
    if x is None:
        x = m.random_point(gen)
    else:
        m.check_point(x, "x")
    if d is None:
        d = m.unit(x, m.random_tangent(x, gen))
    if _norm(m, x, d) == 0.0:
        raise ValueError("check: the direction must be a nonzero tangent vector")
    return x, d, gen


def _tangent_error(m: Manifold, x: Point, v: Tangent) -> float:
    """``‖proj_x(v) − v‖ / ‖v‖``: how far ``v`` is from the tangent space at ``x``."""
    gap = _norm(m, x, m.proj(x, m.to_ambient(x, v)) - v)
    return gap / max(_norm(m, x, v), np.finfo(float).tiny)


def _costs_along(problem: Problem, x: Point, d: Tangent) -> FloatArray:
    m = problem.manifold
    return np.array([problem.cost(m.retr(x, d * float(s))) for s in _STEPS])


def _cost_floor(error: FloatArray, *terms: Any) -> FloatArray:
    """The round-off level of the remainder ``error``, a sum of ``terms``, per step.

    Relative to ``s(t) = max(1, |terms|)``: ten times the round-off measured at
    the smallest steps, ``max e(t)/s(t)`` over ``t ≤ 10^{-6.9}`` (where a
    remainder of order two is ``≲ 10⁻¹⁴`` and of order three far less), kept
    within ``[4ε, 10⁻¹²]``. Where the measurement is larger the truncation
    is showing there (a wrong first-order term) and the bound ``10⁻¹²`` is used.
    """
    scale = np.maximum(1.0, np.max(np.abs(np.broadcast_arrays(*terms)), axis=0))
    with np.errstate(invalid="ignore"):
        measured = 10.0 * np.max(error[:_NOISE_STEPS] / scale[:_NOISE_STEPS])
    relative = np.clip(measured, _COST_NOISE_MIN, _COST_NOISE) if np.isfinite(measured) else _COST_NOISE
    return relative * scale


def _cost_report(
    name: str, expected: float, error: FloatArray, floor: FloatArray, details: dict[str, float], tol: float, what: str
) -> CheckReport:
    """The report of a Taylor-remainder check with side conditions ``details``."""
    slope, window = _fit_slope(_STEPS, error, floor)
    slope_ok = bool(np.isnan(slope) or slope >= expected - tol)
    tangent_ok = details["tangent_error"] <= _TANGENT_TOL
    symmetric = details.get("symmetry_error", 0.0) <= _SYMMETRY_TOL
    notes = [_slope_text(slope, window) + ("" if np.isnan(slope) else f" (expected {expected:g})")]
    if not slope_ok:
        notes.append(f"{what} is probably wrong")
    elif slope > expected + tol:
        notes.append("steeper than needed: the next term of the expansion nearly vanishes along d")
    if not tangent_ok:
        notes.append(f"{what} is not a tangent vector (relative error {details['tangent_error']:.1e})")
    if not symmetric:
        notes.append(f"{what} is not symmetric (relative error {details['symmetry_error']:.1e})")
    passed = slope_ok and tangent_ok and symmetric
    return CheckReport(name, expected, slope, passed, _STEPS.copy(), error, window, details, "; ".join(notes) + ".")


def check_gradient(
    problem: Problem, x: Point | None = None, d: Tangent | None = None, *, rng: RngLike = None, tol: float = 0.1
) -> CheckReport:
    """Check the Riemannian gradient against the cost along a retraction curve.

    With ``c(t) = R_x(t d)``, ``f(c(t)) = f(x) + t⟨grad f(x), d⟩_x + O(t²)`` for
    any retraction, so ``e(t) = |f(c(t)) − f(x) − t⟨grad f(x), d⟩_x|`` has slope 2
    in log-log scale; an error in the gradient leaves a first-order term
    (slope 1). Also checks that ``grad f(x)`` is tangent:
    ``‖proj_x(g) − g‖ ≤ 10⁻⁸‖g‖``.

    Parameters
    ----------
    problem : Problem
        With a gradient.
    x : point, optional
        Base point; ``manifold.random_point(rng)`` by default.
    d : tangent vector at ``x``, optional
        Direction; a random unit tangent by default.
    rng : Generator or int, optional
        Randomness (or its seed) for ``x`` and ``d``.
    tol : float
        Accepted shortfall of the fitted slope below 2.

    Returns
    -------
    CheckReport
        ``details``: ``tangent_error``.
    """
    m = problem.manifold
    x, d, _ = _start(m, x, d, rng)
    f0, g = problem.cost(x), problem.grad(x)
    linear = _STEPS * _inner(m, x, g, d)
    f = _costs_along(problem, x, d)
    error = np.abs(f - f0 - linear)
    details = {"tangent_error": _tangent_error(m, x, g)}
    return _cost_report("gradient", 2.0, error, _cost_floor(error, f, f0, linear), details, tol, "the gradient")


def check_hessian(
    problem: Problem, x: Point | None = None, d: Tangent | None = None, *, rng: RngLike = None, tol: float = 0.1
) -> CheckReport:
    """Check the Riemannian Hessian against the cost along a retraction curve.

    ``e(t) = |f(c(t)) − f(x) − t⟨grad f(x), d⟩ − t²/2 ⟨Hess f(x)[d], d⟩|`` with
    ``c(t) = R_x(t d)`` has slope 3 when the Hessian (and gradient) are right
    and the second-order model along ``c`` is exact to ``O(t³)``: for a
    second-order retraction, at a critical point, or — on Lie groups here —
    because ``ehess2rhess`` gives the Hessian of the pullback ``f∘R_x``.
    Also checks that ``Hess f(x)`` is symmetric,
    ``|⟨H d₁, d₂⟩ − ⟨d₁, H d₂⟩| ≤ 10⁻⁶ max(‖H d₁‖‖d₂‖, ‖d₁‖‖H d₂‖)`` for two
    random unit tangents, and that ``H d`` is tangent.

    Parameters and return as in :func:`check_gradient` (``tol``: accepted
    shortfall below 3); ``details``: ``tangent_error``, ``symmetry_error``.
    """
    m = problem.manifold
    x, d, gen = _start(m, x, d, rng)
    f0, g, h = problem.cost(x), problem.grad(x), problem.hess(x, d)
    linear = _STEPS * _inner(m, x, g, d)
    quadratic = _STEPS**2 / 2 * _inner(m, x, h, d)
    f = _costs_along(problem, x, d)
    error = np.abs(f - f0 - linear - quadratic)
    d1, d2 = (m.unit(x, m.random_tangent(x, gen)) for _ in range(2))
    h1, h2 = problem.hess(x, d1), problem.hess(x, d2)
    scale = max(_norm(m, x, h1) * _norm(m, x, d2), _norm(m, x, d1) * _norm(m, x, h2), np.finfo(float).tiny)
    details = {
        "tangent_error": _tangent_error(m, x, h),
        "symmetry_error": abs(_inner(m, x, h1, d2) - _inner(m, x, d1, h2)) / scale,
    }
    floor = _cost_floor(error, f, f0, linear, quadratic)
    return _cost_report("hessian", 3.0, error, floor, details, tol, "the Hessian")


def _as_array(p: Point) -> FloatArray:
    """A point's numbers as a flat array (group elements by their matrix, tuples concatenated)."""
    if isinstance(p, tuple):
        return np.concatenate([_as_array(q) for q in p])
    return np.asarray(p.as_matrix() if hasattr(p, "as_matrix") else p, dtype=np.float64).ravel()


def _gap(m: Manifold, p: Point, q: Point) -> float:
    """``dist(p, q)``, or the Euclidean distance of the point arrays if ``m`` has no ``dist``."""
    try:
        return float(np.sqrt(np.sum(np.square(m.dist(p, q)))))
    except MissingOperationError:
        return float(np.linalg.norm(_as_array(p) - _as_array(q)))


def _derivative_error(m: Manifold, x: Point, v: Tangent) -> float:
    """Relative error of the central difference of ``t ↦ R_x(t v)`` at 0 against ``v``.

    Array points are compared in the embedding, with ``to_ambient(x, v)``; other
    points (group elements, tuples) in tangent coordinates through ``log_x``
    (``D log_x(x) = id``), or in the embedding if ``m`` has no ``log``.
    """
    h = _FD_STEP
    plus, minus = m.retr(x, v * h), m.retr(x, v * -h)
    if not isinstance(x, np.ndarray):
        try:
            slope = (m.log(x, plus) - m.log(x, minus)) * (0.5 / h)
            return _norm(m, x, slope - v) / _norm(m, x, v)
        except MissingOperationError:
            pass
    ref = _as_array(m.to_ambient(x, v))
    gap = np.linalg.norm((_as_array(plus) - _as_array(minus)) * (0.5 / h) - ref)
    return float(gap / max(np.linalg.norm(ref), np.finfo(float).tiny))


def check_retraction(
    manifold: Manifold, x: Point | None = None, v: Tangent | None = None, *, rng: RngLike = None, tol: float = 0.1
) -> CheckReport:
    """Check the retraction against the exponential map.

    A retraction agrees with the exponential to order ``k`` when
    ``dist(Exp_x(t v), R_x(t v)) = O(t^{k+1})``: every retraction is of first
    order (slope 2), a second-order one gives slope 3. The distance is
    ``manifold.dist`` where implemented, else the Frobenius distance of the
    point arrays (group elements through ``as_matrix()``). Also checks the
    defining properties ``R_x(0) = x`` and ``d/dt R_x(t v)|₀ = v`` (by a central
    difference), each to a relative ``10⁻⁶``.

    The check passes when the slope is at least ``2 − tol`` and both
    properties hold. ``details``: ``retraction_order`` (slope − 1; ``inf``
    when ``R = Exp`` to machine precision), ``second_order`` (1.0 when the
    slope is at least ``3 − tol``), ``zero_error``, ``derivative_error``.

    Parameters
    ----------
    manifold : Manifold
        With ``exp``.
    x, v, rng, tol
        As in :func:`check_gradient`.
    """
    x, v, _ = _start(manifold, x, v, rng)
    scale = max(1.0, float(np.linalg.norm(_as_array(x))))
    error = np.array([_gap(manifold, manifold.exp(x, v * float(s)), manifold.retr(x, v * float(s))) for s in _STEPS])
    slope, window = _fit_slope(_STEPS, error, _POINT_NOISE * scale)
    exact = bool(np.isnan(slope))
    details = {
        "retraction_order": float("inf") if exact else slope - 1.0,
        "second_order": 1.0 if exact or slope >= 3.0 - tol else 0.0,
        "zero_error": _gap(manifold, manifold.retr(x, manifold.zero_vector(x)), x) / scale,
        "derivative_error": _derivative_error(manifold, x, v),
    }
    order_ok = exact or slope >= 2.0 - tol
    zero_ok = details["zero_error"] <= _RETRACTION_TOL
    derivative_ok = details["derivative_error"] <= _RETRACTION_TOL
    notes = [_slope_text(slope, window)]
    if not exact:
        order = "second" if details["second_order"] else "first" if order_ok else "less than first"
        notes.append(f"the retraction agrees with the exponential to {order} order")
    if not zero_ok:
        notes.append(f"R_x(0) ≠ x (relative error {details['zero_error']:.1e})")
    if not derivative_ok:
        notes.append(f"d/dt R_x(t v) at 0 ≠ v (relative error {details['derivative_error']:.1e})")
    passed = order_ok and zero_ok and derivative_ok
    message = "; ".join(notes) + "."
    return CheckReport("retraction", 3.0, slope, passed, _STEPS.copy(), error, window, details, message)
