"""A smooth cost on a manifold, with its derivatives: what an optimizer minimizes."""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from typing import Any

import numpy as np

from ..errors import NonFiniteError, ShapeError
from ..manifolds.base import Manifold, Point, Tangent
from ._values import check_result, same_point, snapshot, structure

__all__ = ["Problem"]


def checked_cost(value: Any, owner: str) -> float:
    """``value`` as a float if it is a finite real scalar (the cost at ``x₀``).

    Raises
    ------
    ShapeError
        If it is an array of any shape but ``()``.
    TypeError
        If it is complex or not a number.
    NonFiniteError
        If it is ``nan`` or ``±inf``.
    """
    if np.ndim(value) != 0:
        raise ShapeError(f"{owner}: cost returned shape {np.shape(value)} at x0; a cost is a real scalar, shape ()")
    kind = np.asarray(value).dtype
    if kind.kind not in "fiub":  # float, int, unsigned, bool
        raise TypeError(f"{owner}: cost returned a {type(value).__name__} ({kind}) at x0; it must be a real number")
    f = float(value)
    if not math.isfinite(f):
        raise NonFiniteError(f"{owner}: the cost at x0 is {f}; an optimizer needs a finite cost at its start")
    return f


class _CostAndGradient:
    """``cost(x)`` and ``grad(x)`` from one callable ``x ↦ (f(x), gradient)``: each call
    remembers both halves at its point (per thread, keyed on the point's value), so the
    gradient at a point whose cost was just evaluated — an accepted step — costs nothing."""

    __slots__ = ("_both", "_local")

    def __init__(self, both: Callable[[Point], Any]) -> None:
        self._both = both
        self._local = threading.local()

    def _at(self, x: Point) -> tuple[Any, Any]:
        memo: tuple[Any, Any, Any] | None = getattr(self._local, "memo", None)
        if memo is not None and same_point(memo[0], x):
            return memo[1], memo[2]
        out = self._both(x)
        if not (isinstance(out, tuple) and len(out) == 2):
            raise TypeError(
                f"Problem: with egrad=True or rgrad=True the cost returns (f, gradient); got {type(out).__name__}"
            )
        self._local.memo = (snapshot(x), *out)
        return out

    def cost(self, x: Point) -> Any:
        return self._at(x)[0]

    def grad(self, x: Point) -> Any:
        return self._at(x)[1]


class Problem:
    """A smooth cost ``f : M → R`` on a manifold ``M``, with optional derivatives.

    Derivatives may be given in Riemannian form, or in Euclidean form for a
    smooth extension ``f̄`` of ``f`` to the embedding space, converted by the
    manifold (CONVENTIONS §6):

    * ``grad f(x) = rgrad(x)``, or ``egrad2rgrad(x, ∇f̄(x))`` with ``egrad(x) = ∇f̄(x)``;
    * ``Hess f(x)[v] = rhess(x, v)``, or
      ``ehess2rhess(x, ∇f̄(x), ∇²f̄(x)[u], v)`` with ``u = to_ambient(x, v)``
      and ``ehess(x, u) = ∇²f̄(x)[u]``.

    ``egrad=True`` or ``rgrad=True`` (SciPy's ``jac=True``) says that ``cost`` returns
    the pair ``(f(x), gradient)``: costs that share their work with their gradient
    (residuals, a matrix product) then evaluate both in one call, and the gradient at a
    point whose cost was just evaluated — every accepted step of a line search or a
    trust region — is the remembered one (per thread, keyed on the point's value).

    The callbacks are stored as given. The Euclidean gradient at the most recent
    point is remembered, so the many Hessian-vector products of a trust-region
    step evaluate ``egrad`` once. The memo is keyed on the point's *value* (a
    private copy compared with ``np.array_equal``, so a point mutated in place is
    a new point) and kept per thread, so one problem may be solved from several
    threads at once (given callbacks that are themselves thread-safe).
    :meth:`validate` checks every callback's result once, at ``x₀``.

    Parameters
    ----------
    manifold : Manifold
        The search space.
    cost : callable ``x ↦ f(x)``
        Returns a real number (with ``egrad=True`` or ``rgrad=True``: ``(f(x), gradient)``).
    egrad, rgrad : callable ``x ↦ gradient`` or True, optional
        The Euclidean or the Riemannian gradient (at most one of them); ``True``: the
        second value of ``cost``.
    ehess, rhess : callable ``(x, u) ↦ Hessian-vector product``, optional
        The Euclidean Hessian applied to an ambient direction ``u`` (needs
        ``egrad``), or the Riemannian Hessian applied to a tangent ``v`` (needs
        a gradient). At most one of them.

    Raises
    ------
    ValueError
        If both forms of a derivative are given, if ``ehess`` comes without
        ``egrad``, or if ``rhess`` comes without a gradient.
    TypeError
        If a callback is not callable.
    """

    __slots__ = ("_cost", "_egrad", "_ehess", "_local", "_manifold", "_rgrad", "_rhess")

    def __init__(
        self,
        manifold: Manifold,
        cost: Callable[[Point], Any],
        *,
        egrad: Callable[[Point], Any] | bool | None = None,
        rgrad: Callable[[Point], Tangent] | bool | None = None,
        ehess: Callable[[Point, Any], Any] | None = None,
        rhess: Callable[[Point, Tangent], Tangent] | None = None,
    ) -> None:
        if not isinstance(manifold, Manifold):
            raise TypeError(f"Problem: manifold must be a Manifold, got {type(manifold).__name__}")
        fused = egrad is True or rgrad is True
        for name, fn in {"cost": cost, "egrad": egrad, "rgrad": rgrad, "ehess": ehess, "rhess": rhess}.items():
            if not callable(fn) and (name == "cost" or (fn is not None and fn is not True)):
                also = " or True" if name in ("egrad", "rgrad") else ""
                raise TypeError(f"Problem: {name} must be callable{also}, got {type(fn).__name__}")
        if egrad is not None and rgrad is not None:
            raise ValueError("Problem: pass either egrad (Euclidean) or rgrad (Riemannian), not both")
        if ehess is not None and rhess is not None:
            raise ValueError("Problem: pass either ehess (Euclidean) or rhess (Riemannian), not both")
        if ehess is not None and egrad is None:
            raise ValueError(
                "Problem: ehess needs egrad (ehess2rhess uses the Euclidean gradient); "
                "with rgrad, pass the Riemannian Hessian as rhess"
            )
        if rhess is not None and rgrad is None and egrad is None:
            raise ValueError("Problem: a Hessian needs a gradient; pass egrad or rgrad too")
        if fused:  # cost returns (f, gradient): both halves from one call
            both = _CostAndGradient(cost)
            cost = both.cost
            egrad, rgrad = (both.grad, None) if egrad is True else (None, both.grad)
        self._manifold = manifold
        self._cost = cost
        assert not isinstance(egrad, bool) and not isinstance(rgrad, bool)  # True replaced above, False refused
        self._egrad, self._rgrad, self._ehess, self._rhess = egrad, rgrad, ehess, rhess
        self._local = threading.local()  # per-thread memo of the last Euclidean gradient

    def _euclidean_gradient(self, x: Point) -> Any:
        assert self._egrad is not None
        memo: tuple[Any, Any] | None = getattr(self._local, "egrad", None)
        if memo is not None and same_point(memo[0], x):
            return memo[1]
        value = self._egrad(x)
        self._local.egrad = (snapshot(x), value)
        return value

    def __repr__(self) -> str:
        given = [n for n in ("egrad", "rgrad", "ehess", "rhess") if getattr(self, "_" + n) is not None]
        return f"Problem({self._manifold!r}{''.join(', ' + n for n in given)})"

    @property
    def manifold(self) -> Manifold:
        """The search space."""
        return self._manifold

    @property
    def has_gradient(self) -> bool:
        """Whether :meth:`grad` is available (``egrad`` or ``rgrad`` was given)."""
        return self._egrad is not None or self._rgrad is not None

    @property
    def has_hessian(self) -> bool:
        """Whether :meth:`hess` is available (``ehess`` or ``rhess`` was given)."""
        return self._ehess is not None or self._rhess is not None

    def cost(self, x: Point) -> float:
        """``f(x)``."""
        return float(self._cost(x))

    def validate(self, x: Point, *, hessian: bool = False) -> tuple[float, Tangent]:
        """``f(x)`` and ``grad f(x)``, every callback's result checked: what an optimizer
        evaluates at ``x₀``, once per run (the hot path checks nothing).

        The cost must be a finite real scalar; ``egrad`` must return an array of
        the ambient shape (that of ``to_ambient(x, v)``: ``x``'s own for an embedded
        manifold, the matrix for a Lie group), ``rgrad`` a tangent vector (that of
        ``zero_vector(x)``), all finite. With ``hessian=True`` (and a Hessian) it also
        applies the Hessian to ``grad f(x)`` and checks ``ehess`` (ambient) or
        ``rhess`` (tangent) likewise.

        Returns
        -------
        f : float
        grad : tangent vector

        Raises
        ------
        ShapeError
            Naming the callback, the expected and the actual shape.
        NonFiniteError
            If a result holds ``nan`` or ``inf``.
        TypeError
            If a result is complex or not a number.
        NotImplementedError
            If the problem has no gradient.
        """
        m, owner = self._manifold, type(self).__name__
        f = checked_cost(self._cost(x), owner)
        zero = m.zero_vector(x)
        tangent, tangent_what = structure(zero), f"a tangent vector of {m!r} at x0"
        ambient = structure(m.to_ambient(x, zero))
        ambient_what = f"the ambient (embedding-space) vector of {m!r} at x0"
        if self._egrad is not None:
            check_result(owner, "egrad", self._euclidean_gradient(x), ambient, ambient_what)
        g = self.grad(x)
        check_result(owner, "rgrad" if self._rgrad is not None else "egrad2rgrad(egrad)", g, tangent, tangent_what)
        if hessian and self._ehess is not None:
            u = m.to_ambient(x, g)
            h = self._ehess(x, u)
            check_result(owner, "ehess", h, ambient, ambient_what)
            h = m.ehess2rhess(x, self._euclidean_gradient(x), h, g)
            check_result(owner, "ehess2rhess(ehess)", h, tangent, tangent_what)
        elif hessian and self._rhess is not None:
            check_result(owner, "rhess", self._rhess(x, g), tangent, tangent_what)
        return f, g

    def grad(self, x: Point) -> Tangent:
        """The Riemannian gradient ``grad f(x)``, a tangent vector at ``x``.

        Raises
        ------
        NotImplementedError
            If the problem was built without ``egrad`` or ``rgrad``.
        """
        if self._rgrad is not None:
            return self._rgrad(x)
        if self._egrad is not None:
            return self._manifold.egrad2rgrad(x, self._euclidean_gradient(x))
        raise NotImplementedError("Problem.grad: build the Problem with egrad=... or rgrad=...")

    def hess_operator(self, x: Point) -> Callable[[Tangent], Tangent]:
        """``v ↦ Hess f(x)[v]`` at a fixed ``x``, for the many products of one trust-region
        step: the Euclidean gradient at ``x`` (and the manifold's conversion) is looked up
        once, not at every product. The products are those of :meth:`hess` (a subclass
        overriding :meth:`hess` gets its own method called).

        Raises
        ------
        NotImplementedError
            If the problem was built without ``ehess`` or ``rhess``.
        """
        if type(self).hess is not Problem.hess:
            return lambda v: self.hess(x, v)
        rhess = self._rhess
        if rhess is not None:
            return lambda v: rhess(x, v)
        ehess = self._ehess
        if ehess is None or self._egrad is None:
            raise NotImplementedError("Problem.hess: build the Problem with ehess=... (and egrad) or rhess=...")
        m, egrad = self._manifold, self._euclidean_gradient(x)
        return lambda v: m.ehess2rhess(x, egrad, ehess(x, m.to_ambient(x, v)), v)

    def hess(self, x: Point, v: Tangent) -> Tangent:
        """The Riemannian Hessian applied to ``v``: ``Hess f(x)[v]``, a tangent vector at ``x``.

        Raises
        ------
        NotImplementedError
            If the problem was built without ``ehess`` or ``rhess``.
        """
        if self._rhess is not None:
            return self._rhess(x, v)
        if self._ehess is not None and self._egrad is not None:
            m = self._manifold
            return m.ehess2rhess(x, self._euclidean_gradient(x), self._ehess(x, m.to_ambient(x, v)), v)
        raise NotImplementedError("Problem.hess: build the Problem with ehess=... (and egrad) or rhess=...")
