"""``minimize(cost, x0, manifold=…, method=…)``: define a cost, get a result — SciPy's habit.

One call builds the :class:`~manopt_lie.optim.Problem` (CasADi derivatives for a
symbolic cost, or the derivatives given), picks the optimizer from the registry
:data:`~manopt_lie.optim.OPTIMIZERS` and runs it::

    import casadi as ca
    from manopt_lie import minimize
    from manopt_lie.manifolds import Sphere

    res = minimize(lambda x: ca.mtimes([x.T, A, x]), x0, manifold=Sphere(3))
    res.x, res.fun, res.success, res["message"]

The heavy modules (optimizers, CasADi) load on the first call, so ``import manopt_lie``
stays light.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from .lie import LieGroup

if TYPE_CHECKING:
    from .manifolds import Manifold
    from .optim import OptimizeResult, Problem

__all__ = ["minimize"]

_SCIPY_NAMES = {
    "maxiter": "max_iterations",
    "gtol": "grad_atol (with grad_rtol=0 for an absolute test only)",
    "ftol": "rel_cost_decrease",
    "xtol": "min_step",
    "disp": "minimize(..., verbosity=1 or 2)",
}
"""SciPy's option names and this library's (hints for an unknown option; no aliases)."""


def _infer_manifold(x0: Any) -> Manifold:
    from .manifolds import Euclidean, LieGroupManifold, Power

    if isinstance(x0, LieGroup):
        m = LieGroupManifold(type(x0))
        batch = x0.batch_shape
        return m if batch == () else Power(m, batch)
    a = np.asarray(x0, dtype=object) if isinstance(x0, tuple) else np.asarray(x0)
    if a.dtype.kind in "fiu" and a.ndim >= 1:
        return Euclidean(*a.shape)
    raise TypeError(f"minimize: give manifold= (cannot infer one from x0 of type {type(x0).__name__})")


def _symbolic_problem(manifold: Manifold, cost: Callable[..., Any]) -> Problem:
    """``problem_from_casadi(manifold, cost)``, a cost that is not symbolic named as such."""
    from .casadi import problem_from_casadi
    from .casadi._spaces import space_of

    try:
        space_of(manifold, "minimize")
    except TypeError as err:
        raise TypeError(f"{err}; on other manifolds pass the derivatives (egrad=, ehess= or rgrad=, rhess=)") from None
    try:
        return problem_from_casadi(manifold, cost)
    except (TypeError, AttributeError, RuntimeError, NotImplementedError) as err:
        raise TypeError(
            f"minimize: the cost is not symbolic: called on CasADi symbols (the point as {manifold!r} "
            f"gives it) it raised {type(err).__name__}: {err}. Write it with casadi operations (ca.mtimes, "
            "ca.sumsqr, ca.trace, …), or pass its derivatives (egrad=, and ehess= for a Hessian)"
        ) from err


def _least_squares(manifold: Manifold, residual: Callable[..., Any], x0: Any) -> tuple[Problem, Any, bool]:
    """The least-squares problem of ``residual`` and ``x0`` on it; ``True`` if a single point was
    wrapped as ``Power(M, 1)`` (the result is unwrapped again)."""
    from .casadi import least_squares_from_casadi
    from .manifolds import Power

    single = not isinstance(manifold, Power)
    power = manifold if isinstance(manifold, Power) else Power(manifold, 1)
    if single:
        x0 = x0.reshape((1,)) if isinstance(x0, LieGroup) else np.asarray(x0, dtype=np.float64)[None]
    n = power.shape[0]
    return least_squares_from_casadi(power, np.arange(n)[:, None], residual), x0, single


def _optimizer(entry: Any, options: Mapping[str, Any], verbosity: int) -> Any:
    """``entry.make(**options, verbosity=verbosity)``, an unknown option named with SciPy's spelling."""
    if "verbosity" in options:
        raise TypeError("minimize: give verbosity= as an argument, not in options")
    try:
        return entry.make(**options, verbosity=verbosity)
    except TypeError as err:
        hints = [f"{k!r} is {_SCIPY_NAMES[k]} here" for k in options if k in _SCIPY_NAMES]
        raise TypeError(f"minimize: {err}" + (f" ({'; '.join(hints)})" if hints else "")) from None


def minimize(
    cost: Callable[..., Any] | Problem | None,
    x0: Any,
    *,
    manifold: Manifold | None = None,
    method: str | None = None,
    egrad: Callable[..., Any] | None = None,
    ehess: Callable[..., Any] | None = None,
    rgrad: Callable[..., Any] | None = None,
    rhess: Callable[..., Any] | None = None,
    residual: Callable[..., Any] | None = None,
    options: Mapping[str, Any] | None = None,
    callback: Callable[..., Any] | None = None,
    verbosity: int = 0,
) -> OptimizeResult:
    """Minimize ``cost`` on ``manifold`` from ``x0``, as ``scipy.optimize.minimize`` does in Rⁿ.

    The problem is, in this order of precedence:

    * ``cost`` itself, if it is a :class:`~manopt_lie.optim.Problem` (a
      :class:`~manopt_lie.optim.LeastSquaresProblem` included);
    * ``½ Σ ‖residual(X)‖²`` if ``residual`` is given (``cost`` is then ``None``): a CasADi
      residual function, turned into a least-squares problem by
      :func:`~manopt_lie.casadi.least_squares_from_casadi` — of the point on a single
      ``LieGroupManifold(G)`` or ``Euclidean(d)``, of each point on a ``Power`` of one;
    * ``Problem(manifold, cost, egrad=…, ehess=…)`` (or ``rgrad``/``rhess``) when
      derivatives are given: ``cost`` is then a numeric function;
    * otherwise ``cost`` must be *symbolic* — a function of CasADi symbols shaped like the
      point (see :func:`~manopt_lie.casadi.problem_from_casadi`: an ``n×1`` column on
      ``Sphere(n)``, an ``n×p`` matrix on ``Stiefel(n, p)``, …) — and CasADi gives its
      exact gradient and Hessian.

    Parameters
    ----------
    cost : callable, Problem or None
        The cost.
    x0 : point
        The start, a point of ``manifold``.
    manifold : Manifold, optional
        Inferred from ``x0`` when omitted: ``Euclidean(*x0.shape)`` for an array,
        ``LieGroupManifold(G)`` (or a ``Power`` of it, for a batch) for a group element.
    method : str, optional
        A name of :data:`~manopt_lie.optim.OPTIMIZERS`: ``"tr"`` (the default, with the
        exact Hessian when the problem has one), ``"cg"``, ``"gd"``, and for least
        squares ``"lm"`` (the default there) and ``"gn"``.
    egrad, ehess, rgrad, rhess : callable, optional
        Derivatives of a numeric ``cost``, as for :class:`~manopt_lie.optim.Problem`.
    residual : callable, optional
        A CasADi residual function (for ``"lm"``/``"gn"``, or any method).
    options : mapping, optional
        The optimizer's options and the :class:`~manopt_lie.optim.StoppingCriteria`
        fields, e.g. ``{"max_iterations": 200, "grad_rtol": 0, "grad_atol": 1e-8}`` or
        ``{"stopping": StoppingCriteria(...)}``. SciPy's names are not aliases; an
        unknown one raises ``TypeError`` saying the name here (``maxiter`` is
        ``max_iterations``).
    callback : callable, optional
        ``callback(info)`` with an :class:`~manopt_lie.optim.IterationInfo` after each
        iteration; returning ``True`` or raising ``StopIteration`` stops the run cleanly
        (``Status.CALLBACK``).
    verbosity : {0, 1, 2}
        0 silent; 1 a line at the start and the result at the end; 2 also one row per
        iteration (iteration, cost, gradient norm, step, time), on stderr.

    Returns
    -------
    OptimizeResult
        ``res.x``, ``res.fun``, ``res.success``, ``res.status`` (a
        :class:`~manopt_lie.optim.Status`, an ``IntEnum``), ``res.message``, … — also as
        a mapping, ``res["x"]``.

    Raises
    ------
    ValueError
        For a least-squares method without a least-squares problem (naming the ways
        to give one), or an unknown method (listing the registered ones).
    TypeError
        For a cost that is not symbolic and has no derivatives, an unsupported
        manifold for CasADi derivatives, inconsistent arguments, or an unknown option.
    """
    from .optim import LeastSquaresProblem, Problem, get_optimizer

    given = {"egrad": egrad, "ehess": ehess, "rgrad": rgrad, "rhess": rhess}
    derivatives = {k: v for k, v in given.items() if v is not None}
    single = False
    if isinstance(cost, Problem):
        if derivatives or residual is not None:
            raise TypeError("minimize: cost is a Problem already; give no derivatives or residual with it")
        if manifold is not None and manifold is not cost.manifold:
            raise TypeError(f"minimize: cost is a Problem on {cost.manifold!r}; manifold={manifold!r} differs")
        problem = cost
    else:
        manifold = _infer_manifold(x0) if manifold is None else manifold
        if not isinstance(x0, LieGroup | tuple):
            x0 = np.asarray(x0, dtype=np.float64)
        if residual is not None:
            if cost is not None or derivatives:
                raise TypeError("minimize: with residual=, pass cost=None and no derivatives")
            problem, x0, single = _least_squares(manifold, residual, x0)
        elif cost is None:
            raise TypeError("minimize: give a cost (or residual=)")
        elif derivatives:
            problem = Problem(manifold, cost, **derivatives)
        else:
            problem = _symbolic_problem(manifold, cost)
    least_squares = isinstance(problem, LeastSquaresProblem)
    method = method or ("lm" if least_squares else "tr")
    entry = get_optimizer(method)
    if not entry.accepts_problem(problem):
        raise ValueError(
            f"minimize: method {method!r} ({entry.summary}) needs a {entry.accepts.__name__}: pass "
            "residual= (a CasADi residual function) or a LeastSquaresProblem as the cost, or choose "
            "a method for any smooth cost ('tr', 'cg', 'gd')"
        )
    optimizer = _optimizer(entry, dict(options or {}), verbosity)
    result = optimizer.solve(problem, x0, callback=callback)
    return dataclasses.replace(result, x=result.x[0]) if single else result
