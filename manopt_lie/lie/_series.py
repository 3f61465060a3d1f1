"""Scalar coefficient functions of the rotation angle, stable at and near 0: the one source.

Every ``0/0``-at-zero coefficient of the Lie-group formulas is *data*, a
:class:`Coefficient`: a threshold on the angle ``θ``, the Taylor coefficients
``c_j`` of its series in ``t = θ²``, and its closed form, written once against a
small :class:`Backend` namespace (``sin``, ``cos``, ``sqrt``, ``atan``,
``atan2``, ``fmax``, ``where``, ``sinh``, ``cosh``, ``exp``). One evaluator, :func:`evaluate`, serves every
backend::

    f(t) = Σ_j c_j t^j           where t < threshold²   (Horner)
           closed(θ)             elsewhere, the closed form seeing θ = 1 in the series branch

selecting on the *squared* angle, so that the closed form never sees a small
argument: no branch divides by zero, and on a symbolic backend (CasADi,
``manopt_lie.casadi.lie``) derivatives of every order are finite at ``t = 0``.
The NumPy backend :data:`NUMPY` serves the array kernels through the functions
of ``θ`` below (:func:`sinc`, …). Both backends pick the same branch for the
same angle: for ``θ ≥ 0`` in binary floating point, ``fl(θ²) < fl(thr²)`` exactly
when ``θ < thr`` (because ``√fl(x²) = x``). Every closed form is even in ``θ``,
so the angle may carry a sign.

Each threshold balances the closed form's cancellation against the series'
truncation: against exact references the largest relative error is below
1e-13 for every function and angle in ``[0, 2π)``.

Two more evaluators serve speed, with the values of :func:`evaluate` bit for bit: :func:`patched`
(NumPy arrays: the closed form everywhere, the series only on the subset of small angles, if any)
and :func:`value` (one angle as a Python float, for the single-element path of ``_one``, on the
backend :data:`FLOAT` of NumPy's own ufuncs). Closed forms use products, never ``x**k``: NumPy's
vectorized ``pow`` and the C library's round differently, products round alike everywhere.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from math import factorial
from typing import Any, NamedTuple

import numpy as np

from ._checks import FloatArray

__all__ = [
    "Backend",
    "Coefficient",
    "NUMPY",
    "FLOAT",
    "HUGE",
    "COEFFICIENTS",
    "horner",
    "evaluate",
    "patched",
    "value",
    "bind",
    "atan2_ratio",
    "atan2_ratio_float",
    "sinc",
    "cosc",
    "sinc3",
    "jinv_coef",
    "q_coef2",
    "q_coef3",
    "half_cot",
    "sinc_half",
    "atan_ratio",
    "sim3_moments",
    "sim3_coefficients",
    "sim3_inverse_coefficients",
]


class Backend(NamedTuple):
    """The elementary functions a closed form may use; ``where(cond, a, b)`` selects elementwise."""

    sin: Callable[[Any], Any]
    cos: Callable[[Any], Any]
    sqrt: Callable[[Any], Any]
    atan: Callable[[Any], Any]
    atan2: Callable[[Any, Any], Any]
    fmax: Callable[[Any, Any], Any]
    where: Callable[[Any, Any, Any], Any]
    sinh: Callable[[Any], Any]
    cosh: Callable[[Any], Any]
    exp: Callable[[Any], Any]


NUMPY = Backend(np.sin, np.cos, np.sqrt, np.arctan, np.arctan2, np.fmax, np.where, np.sinh, np.cosh, np.exp)


def _as_float(ufunc: np.ufunc) -> Callable[..., float]:
    """``ufunc`` on Python floats, returning a Python float: NumPy's loop, hence its rounding."""
    return lambda *x: float(ufunc(*x))


# One angle as Python floats: NumPy's ufuncs (the same loops, so the same roundings, as on arrays),
# ``math.sqrt`` (correctly rounded, as ``np.sqrt``) and a plain conditional for ``where``.
FLOAT = Backend(
    _as_float(np.sin),
    _as_float(np.cos),
    math.sqrt,
    _as_float(np.arctan),
    _as_float(np.arctan2),
    _as_float(np.fmax),
    lambda c, a, b: a if c else b,
    _as_float(np.sinh),
    _as_float(np.cosh),
    _as_float(np.exp),
)

# Angles beyond HUGE are routed to scale-safe forms (``_so3.scale_safe``): otherwise the closed
# forms' powers θ³…θ⁵, the discarded series' powers of θ² and ``|θ|²`` itself overflow (from
# θ ≈ 1e25 on) and turn into nan. Such angles have no physical meaning (the ulp of 1e20 is 16384 rad).
HUGE = 1e20
HUGE2 = HUGE * HUGE


def _square(x: Any) -> Any:
    return x * x


@dataclass(frozen=True)
class Coefficient:
    """A coefficient function ``f(θ)``, even in ``θ``, as data.

    Attributes
    ----------
    name : str
        The public name (``"sinc"``), shared by the NumPy and CasADi functions.
    formula : str
        The closed form, for documentation.
    threshold : float
        The series is used for ``|θ| < threshold``, i.e. ``t = θ² < threshold²``.
    series : tuple of float
        ``c_0, c_1, …``: ``f = Σ_j c_j t^j`` near 0 (at least two terms).
    closed : callable
        ``closed(backend, θ)``, the closed form, evaluated only away from 0.
    """

    name: str
    formula: str
    threshold: float
    series: tuple[float, ...]
    closed: Callable[[Backend, Any], Any] = field(repr=False)
    threshold2: float = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if len(self.series) < 2:
            raise ValueError(f"{self.name}: a series needs at least two coefficients")
        object.__setattr__(self, "threshold2", self.threshold * self.threshold)


def horner(t: Any, coefficients: tuple[float, ...]) -> Any:
    """``Σ_k c_k t^k`` by Horner's rule (``t`` an array or a CasADi matrix; two or more coefficients).

    Updates in place where the type allows (NumPy arrays: no temporaries); ``out`` is always new.
    """
    out = coefficients[-1] * t
    out += coefficients[-2]
    for c in coefficients[-3::-1]:
        out *= t
        out += c
    return out


def evaluate(coef: Coefficient, t: Any, theta: Any = None, backend: Backend = NUMPY) -> Any:
    """``coef`` at ``t = θ²``: its series where ``t < threshold²``, else its closed form.

    Parameters
    ----------
    coef
        The coefficient.
    t
        The squared angle ``θ² ≥ 0``.
    theta
        The angle itself (either sign), passed to the closed form; by default ``√t``.
    backend
        :data:`NUMPY` or a symbolic backend (``manopt_lie.casadi.lie.CASADI``).
    """
    small = t < coef.threshold2
    safe = backend.sqrt(backend.where(small, 1.0, t)) if theta is None else backend.where(small, 1.0, theta)
    return backend.where(small, horner(t, coef.series), coef.closed(backend, safe))


def patched(coef: Coefficient, t: FloatArray, theta: FloatArray) -> FloatArray:
    """:func:`evaluate` on NumPy arrays, faster: the closed form on every angle, the series only where
    ``t < threshold²`` (those angles see ``θ = 1`` in the closed form) — if there are any, and on that
    subset alone if it is a small part (gathering and scattering cost more than Horner's rule)."""
    small = t < coef.threshold2
    count = np.count_nonzero(small)
    if not count:
        return coef.closed(NUMPY, theta)
    closed = coef.closed(NUMPY, np.where(small, 1.0, theta))
    if 8 * count > small.size:
        return np.where(small, horner(t, coef.series), closed)
    out = np.asarray(closed)
    out[small] = horner(t[small], coef.series)
    return out


def value(coef: Coefficient, t: float, theta: float) -> float:
    """:func:`evaluate` at one angle, on Python floats: the series if ``t < threshold²``, else the closed
    form at ``θ`` (on :data:`FLOAT`)."""
    return horner(t, coef.series) if t < coef.threshold2 else coef.closed(FLOAT, theta)


def bind(coef: Coefficient, backend: Backend) -> Callable[..., Any]:
    """``f(t, theta=None)``: ``coef`` as a function of ``t = θ²`` on ``backend``, named and documented."""

    def f(t: Any, theta: Any = None) -> Any:
        return evaluate(coef, t, theta, backend)

    f.__name__ = f.__qualname__ = coef.name
    f.__doc__ = f"""``{coef.formula}``, as a function of ``t = θ²``.

    ``Σ_j c_j t^j`` ({len(coef.series)} terms) where ``t < {coef.threshold:g}²``, else the closed form at
    ``θ`` (by default ``√t``; pass ``theta``, of either sign, to skip the square root), which sees
    ``θ = 1`` in the series branch: values and derivatives of every order are finite at ``t = 0``.
    """
    return f


def _taylor(term: Callable[[int], float], n: int = 6) -> tuple[float, ...]:
    return tuple(term(j) for j in range(n))


# Bernoulli numbers B₂, B₄, …, B₁₂ for the series of x·cot(x).
_BERNOULLI = (1 / 6, -1 / 30, 1 / 42, -1 / 30, 5 / 66, -691 / 2730)
_COT_SERIES = _taylor(lambda j: (-1) ** j * _BERNOULLI[j] / factorial(2 * j + 2))

SINC = Coefficient(
    "sinc", "sin θ / θ", 0.3, _taylor(lambda j: (-1) ** j / factorial(2 * j + 1)), lambda b, x: b.sin(x) / x
)
COSC = Coefficient(
    "cosc",
    "(1 − cos θ) / θ², as 2 sin²(θ/2) / θ² (no cancellation)",
    0.3,
    _taylor(lambda j: (-1) ** j / factorial(2 * j + 2)),
    lambda b, x: 2.0 * _square(b.sin(0.5 * x) / x),
)
SINC3 = Coefficient(
    "sinc3",
    "(θ − sin θ) / θ³",
    0.5,
    _taylor(lambda j: (-1) ** j / factorial(2 * j + 3)),
    lambda b, x: (x - b.sin(x)) / (x * x * x),
)
JINV_COEF = Coefficient(
    "jinv_coef",
    "1/θ² − (1 + cos θ)/(2θ sin θ) = 1/θ² − cot(θ/2)/(2θ), the [θ]×² coefficient of Jr(θ)⁻¹; finite on [0, 2π)",
    0.3,
    _COT_SERIES,
    lambda b, x: 1.0 / (x * x) - b.cos(0.5 * x) / (2.0 * x * b.sin(0.5 * x)),
)
Q_COEF2 = Coefficient(
    "q_coef2",
    "(θ² + 2 cos θ − 2) / (2θ⁴), c₂ of Barfoot's Q(ρ, θ)",
    0.7,
    _taylor(lambda j: (-1) ** j / factorial(2 * j + 4)),
    lambda b, x: (x * x + 2.0 * b.cos(x) - 2.0) / (2.0 * _square(x * x)),
)
Q_COEF3 = Coefficient(
    "q_coef3",
    "(2θ − 3 sin θ + θ cos θ) / (2θ⁵), c₃ of Barfoot's Q(ρ, θ)",
    0.7,
    _taylor(lambda j: (-1) ** j * (j + 1) / factorial(2 * j + 5)),
    lambda b, x: (2.0 * x - 3.0 * b.sin(x) + x * b.cos(x)) / (2.0 * _square(x * x) * x),
)
HALF_COT = Coefficient(
    "half_cot",
    "(θ/2) cot(θ/2) = 1 − θ² jinv_coef(θ), the diagonal of SE(2)'s V(θ)⁻¹; finite on [0, 2π), 0 at π",
    0.3,
    (1.0, *(-c for c in _COT_SERIES)),
    lambda b, x: 0.5 * x * b.cos(0.5 * x) / b.sin(0.5 * x),
)
SINC_HALF = Coefficient(
    "sinc_half",
    "sin(θ/2) / θ = ½ sinc(θ/2), the half-angle coefficient of SO(3) Exp",
    1e-4,  # no cancellation: the series is needed only at 0 (and for symbolic derivatives)
    _taylor(lambda j: (-1) ** j / (factorial(2 * j + 1) * 2 ** (2 * j + 1)), 3),
    lambda b, x: b.sin(0.5 * x) / x,
)
COS_HALF = Coefficient(
    "cos_half",
    "cos(θ/2) as a function of θ² (symbolic SO(3) Exp; in NumPy plain cos(θ/2) is exact)",
    1e-4,
    _taylor(lambda j: (-1) ** j / (factorial(2 * j) * 4**j), 3),
    lambda b, x: b.cos(0.5 * x),
)
ATAN_RATIO = Coefficient(
    "atan_ratio",
    "atan(x) / x, of t = x²; atan2(s, c)/s = atan_ratio(s/c)/c for c > 0 (see atan2_ratio)",
    1e-3,  # no cancellation: three terms reach 1e-19 below the threshold
    _taylor(lambda j: (-1) ** j / (2 * j + 1), 3),
    lambda b, x: b.atan(x) / x,
)

# The even parts of the moments ∫₀¹ sᵏ e^{sσ} ds of Sim(3) (shifted to s = ½ + x, y = σ/2):
# ∫_{−½}^{½} xᵏ e^{2xy} dx = y^(k mod 2) · emomentₖ(y), each even in y.
EMOMENT0 = Coefficient(
    "emoment0",
    "sinh y / y = ∫ e^{2xy} dx over [−½, ½]",
    1e-4,  # no cancellation
    _taylor(lambda j: 1.0 / factorial(2 * j + 1), 3),
    lambda b, x: b.sinh(x) / x,
)
EMOMENT1 = Coefficient(
    "emoment1",
    "(y cosh y − sinh y) / (2y³) = (1/y) ∫ x e^{2xy} dx over [−½, ½]",
    0.5,
    _taylor(lambda j: (j + 1) / factorial(2 * j + 3), 8),
    lambda b, x: (x * b.cosh(x) - b.sinh(x)) / (2.0 * (x * x * x)),
)
EMOMENT2 = Coefficient(
    "emoment2",
    "(y² sinh y − 2y cosh y + 2 sinh y) / (4y³) = ∫ x² e^{2xy} dx over [−½, ½]",
    1.0,
    _taylor(lambda j: 1.0 / (4 * (2 * j + 3) * factorial(2 * j)), 10),
    lambda b, x: ((x * x + 2.0) * b.sinh(x) - 2.0 * x * b.cosh(x)) / (4.0 * (x * x * x)),
)

COEFFICIENTS: tuple[Coefficient, ...] = (
    SINC,
    COSC,
    SINC3,
    JINV_COEF,
    Q_COEF2,
    Q_COEF3,
    HALF_COT,
    SINC_HALF,
    COS_HALF,
    ATAN_RATIO,
    EMOMENT0,
    EMOMENT1,
    EMOMENT2,
)

# Below this |(σ, θ)|² the Sim(3) coefficients b, c take their second-order Taylor polynomials
# (error O(r³) < 1e-18); above it their closed forms, free of cancellation, are exact to ~1e-15.
SIM3_ORIGIN2 = 1e-12


def sim3_moments(sigma: Any, backend: Backend = NUMPY) -> tuple[Any, Any, Any, Any]:
    """``(e^σ, μ₀, μ₁, μ₂)`` with ``μₖ = ∫₀¹ sᵏ e^{sσ} ds`` (see :func:`sim3_coefficients`)."""
    y = 0.5 * sigma
    y2 = y * y
    m0, m1, m2 = (evaluate(c, y2, y, backend) for c in (EMOMENT0, EMOMENT1, EMOMENT2))
    e = backend.exp(y)
    es = e * e
    mu0 = e * m0
    mu1 = e * (0.5 * m0 + y * m1)
    mu2 = e * (0.25 * m0 + y * m1 + m2)
    # For σ < −1 the shifted form cancels (its terms are ~1/|σ|, μ₂ ~ 2/|σ|³): integrate by parts.
    neg = sigma < -1.0
    sd = backend.where(neg, sigma, -1.0)
    ed = backend.exp(sd)
    mu1_d = (1.0 + ed * (sd - 1.0)) / (sd * sd)
    mu1 = backend.where(neg, mu1_d, mu1)
    mu2 = backend.where(neg, (ed - 2.0 * mu1_d) / sd, mu2)
    return es, mu0, mu1, mu2


def sim3_coefficients(sigma: Any, t: Any, backend: Backend = NUMPY) -> tuple[Any, Any, Any]:
    """``(a, b, c)`` of ``W(σ, θ) = ∫₀¹ e^{sσ} Exp(sθ) ds = a I + b θ^ + c θ^²`` (Sim(3) ``Exp``), ``t = |θ|²``.

    With the moments ``μₖ = ∫₀¹ sᵏ e^{sσ} ds`` (from :data:`EMOMENT0` … at ``y = σ/2``:
    ``μ₀ = eʸ m₀``, ``μ₁ = eʸ(m₀/2 + y m₁)``, ``μ₂ = eʸ(m₀/4 + y m₁ + m₂)``; for σ < −1, where
    these cancel, ``μ₁ = (1 + e^σ(σ − 1))/σ²`` and ``μ₂ = (e^σ − 2μ₁)/σ``) and
    ``w₁ = σ²/(σ² + t)``, ``w₂ = t/(σ² + t)``::

        a = μ₀ = (e^σ − 1)/σ
        b = w₁ μ₁ + w₂ e^σ (cosc θ − σ sinc3 θ)
        c = w₁ μ₂/2 + w₂ e^σ (sinc3 θ − σ q_coef2 θ)

    (``b = Im φ(σ + iθ)/θ``, ``c = (φ(σ) − Re φ(σ + iθ))/θ²`` for ``φ(z) = (e^z − 1)/z``, written
    without the cancellations of the textbook form). At σ = 0 they are SO(3)'s ``Jl``
    coefficients. Below :data:`SIM3_ORIGIN2` the Taylor polynomials
    ``b = ½ + σ/3 + σ²/8 − t/24``, ``c = 1/6 + σ/8 + σ²/20 − t/120``.
    """
    es, mu0, mu1, mu2 = sim3_moments(sigma, backend)
    cc, s3, q2 = (evaluate(c, t, None, backend) for c in (COSC, SINC3, Q_COEF2))
    s2 = sigma * sigma
    r2 = s2 + t
    origin = r2 < SIM3_ORIGIN2
    den = backend.where(origin, 1.0, r2)
    w1, w2 = s2 / den, t / den
    b = w1 * mu1 + w2 * es * (cc - sigma * s3)
    c = 0.5 * w1 * mu2 + w2 * es * (s3 - sigma * q2)
    b = backend.where(origin, 0.5 + sigma * (1.0 / 3.0 + sigma / 8.0) - t / 24.0, b)
    c = backend.where(origin, 1.0 / 6.0 + sigma * (1.0 / 8.0 + sigma / 20.0) - t / 120.0, c)
    return mu0, b, c


def sim3_inverse_coefficients(a: Any, b: Any, c: Any, t: Any) -> tuple[Any, Any, Any]:
    """``(α, β, γ)`` with ``(a I + b θ^ + c θ^²)⁻¹ = α I + β θ^ + γ θ^²`` (``θ^³ = −t θ^``).

    Scaled by ``a`` first (``b' = b/a``, ``c' = c/a``, so nothing overflows for large σ):
    ``d = 1 − t c'``, ``Δ = d² + t b'²``, ``α = 1/a``, ``β = −b'/(aΔ)``,
    ``γ = (b'² − c' d)/(aΔ)``. Δ > 0 except where ``W`` is singular (σ = 0, θ = 2πk, k ≠ 0).
    """
    bp, cp = b / a, c / a
    d = 1.0 - t * cp
    delta = a * (d * d + t * bp * bp)
    return 1.0 / a, -bp / delta, (bp * bp - cp * d) / delta


def atan2_ratio(s2: Any, c: Any, backend: Backend = NUMPY) -> Any:
    """``atan2(s, c) / s`` with ``s = √s2 ≥ 0``, any sign of ``c``.

    Where ``c > 0`` and ``x² = s2/c² < threshold²`` of :data:`ATAN_RATIO` (tested as
    ``s2 < threshold²·c·|c|``), the series ``atan_ratio(x)/c = (1 − x²/3 + x⁴/5)/c``;
    elsewhere ``atan2(s, c)/s`` with ``s ≥ 1e-150``. With ``a = sin θ·u`` and
    ``c ∝ cos θ`` (a quaternion's ``(v, w)``, or the skew part and ``(tr R − 1)/2``
    of a rotation matrix), ``ratio·a`` is the rotation vector (up to the factor 2
    for quaternions).
    """
    small = s2 < ATAN_RATIO.threshold2 * c * abs(c)
    cs = backend.where(small, c, 1.0)
    series = horner(s2 / (cs * cs), ATAN_RATIO.series) / cs
    s = backend.sqrt(backend.where(small, 1.0, backend.fmax(s2, 1e-300)))
    return backend.where(small, series, backend.atan2(s, c) / s)


def atan2_ratio_float(s2: float, c: float) -> float:
    """:func:`atan2_ratio` on Python floats (one branch evaluated, the same roundings)."""
    if s2 < ATAN_RATIO.threshold2 * c * abs(c):
        return horner(s2 / (c * c), ATAN_RATIO.series) / c
    s = math.sqrt(s2 if s2 >= 1e-300 else 1e-300)
    return FLOAT.atan2(s, c) / s


# ---- the NumPy functions of the angle θ (either sign) that the kernels call ----------------
# ``t`` is the squared angle where the caller has it (``|w|²`` summed by components), else ``θ²``.


def sinc(theta: FloatArray, t: FloatArray | None = None) -> FloatArray:
    """``sin θ / θ``."""
    return patched(SINC, theta * theta if t is None else t, theta)


def cosc(theta: FloatArray, t: FloatArray | None = None) -> FloatArray:
    """``(1 − cos θ) / θ²``, written ``2 sin²(θ/2) / θ²`` to avoid cancellation."""
    return patched(COSC, theta * theta if t is None else t, theta)


def sinc3(theta: FloatArray, t: FloatArray | None = None) -> FloatArray:
    """``(θ − sin θ) / θ³``."""
    return patched(SINC3, theta * theta if t is None else t, theta)


def jinv_coef(theta: FloatArray, t: FloatArray | None = None) -> FloatArray:
    """``1/θ² − (1 + cos θ)/(2θ sin θ) = 1/θ² − cot(θ/2)/(2θ)``.

    The coefficient of ``[θ]×²`` in ``Jr(θ)⁻¹``; finite up to (excluding) ``2π``
    and exact at ``π``, being written with ``cot(θ/2)``.
    """
    return patched(JINV_COEF, theta * theta if t is None else t, theta)


def q_coef2(theta: FloatArray, t: FloatArray | None = None) -> FloatArray:
    """``(θ² + 2 cos θ − 2) / (2θ⁴)`` of Barfoot's ``Q(ρ, θ)``."""
    return patched(Q_COEF2, theta * theta if t is None else t, theta)


def q_coef3(theta: FloatArray, t: FloatArray | None = None) -> FloatArray:
    """``(2θ − 3 sin θ + θ cos θ) / (2θ⁵)`` of Barfoot's ``Q(ρ, θ)``."""
    return patched(Q_COEF3, theta * theta if t is None else t, theta)


def half_cot(theta: FloatArray, t: FloatArray | None = None) -> FloatArray:
    """``(θ/2) cot(θ/2) = 1 − θ² jinv_coef(θ)``, the diagonal of SE(2)'s ``V(θ)⁻¹``.

    Accurate relative to its value everywhere on ``(−2π, 2π)``, including its zero at ``±π``.
    """
    return patched(HALF_COT, theta * theta if t is None else t, theta)


def sinc_half(theta: FloatArray, t: FloatArray | None = None) -> FloatArray:
    """``sin(θ/2) / θ``."""
    return patched(SINC_HALF, theta * theta if t is None else t, theta)


def atan_ratio(x: FloatArray) -> FloatArray:
    """``atan(x) / x``."""
    return evaluate(ATAN_RATIO, x * x, x)
