"""A smooth cost on a manifold, with its derivatives: what an optimizer minimizes."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from ..manifolds.base import Manifold, Point, Tangent

__all__ = ["Problem"]


class Problem:
    """A smooth cost ``f : M → R`` on a manifold ``M``, with optional derivatives.

    Derivatives may be given in Riemannian form, or in Euclidean form for a
    smooth extension ``f̄`` of ``f`` to the embedding space, converted by the
    manifold (CONVENTIONS §6):

    * ``grad f(x) = rgrad(x)``, or ``egrad2rgrad(x, ∇f̄(x))`` with ``egrad(x) = ∇f̄(x)``;
    * ``Hess f(x)[v] = rhess(x, v)``, or
      ``ehess2rhess(x, ∇f̄(x), ∇²f̄(x)[u], v)`` with ``u = to_ambient(x, v)``
      and ``ehess(x, u) = ∇²f̄(x)[u]``.

    The callbacks are stored as given. The Euclidean gradient at the most recent
    point is remembered (keyed on the point's identity: optimizers never mutate
    points in place), so the many Hessian-vector products of a trust-region
    step evaluate ``egrad`` once.

    Parameters
    ----------
    manifold : Manifold
        The search space.
    cost : callable ``x ↦ f(x)``
        Returns a real number.
    egrad, rgrad : callable ``x ↦ gradient``, optional
        The Euclidean or the Riemannian gradient (at most one of them).
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

    __slots__ = ("_cost", "_egrad", "_egrad_cache", "_ehess", "_manifold", "_rgrad", "_rhess")

    def __init__(
        self,
        manifold: Manifold,
        cost: Callable[[Point], Any],
        *,
        egrad: Callable[[Point], Any] | None = None,
        rgrad: Callable[[Point], Tangent] | None = None,
        ehess: Callable[[Point, Any], Any] | None = None,
        rhess: Callable[[Point, Tangent], Tangent] | None = None,
    ) -> None:
        if not isinstance(manifold, Manifold):
            raise TypeError(f"Problem: manifold must be a Manifold, got {type(manifold).__name__}")
        for name, fn in {"cost": cost, "egrad": egrad, "rgrad": rgrad, "ehess": ehess, "rhess": rhess}.items():
            if not callable(fn) and (name == "cost" or fn is not None):
                raise TypeError(f"Problem: {name} must be callable, got {type(fn).__name__}")
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
        self._manifold = manifold
        self._cost = cost
        self._egrad, self._rgrad, self._ehess, self._rhess = egrad, rgrad, ehess, rhess
        self._egrad_cache: tuple[Point, Any] | None = None

    def _euclidean_gradient(self, x: Point) -> Any:
        assert self._egrad is not None
        if self._egrad_cache is None or self._egrad_cache[0] is not x:
            self._egrad_cache = (x, self._egrad(x))
        return self._egrad_cache[1]

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
