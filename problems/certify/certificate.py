"""The certificate of global optimality of the chordal cost: the smallest eigenvalue of
``S = Q − Λ(Y)`` (Rosen et al., IJRR 2019, Theorem 7; Boumal, Voroninski, Bandeira 2016).

For the relaxation ``min tr(Q Z)`` over ``Z ⪰ 0`` with identity ``d × d`` diagonal blocks
(an SDP whose value is at most the optimum ``f*`` over SO(d)ⁿ), every block-diagonal
symmetric ``Λ`` with ``Q − Λ ⪰ −ηI`` gives the dual bound ``f* ≥ tr(Λ) − η·nd``
(``tr Z = nd``). At a point ``Y`` (rotations, or a rank-``p`` relaxation point) SE-Sync's
multipliers ``Λ_i = Sym((QYᵀ)_i Y_i)`` have ``tr Λ = f(Y)``, the chordal cost with the
optimal translations, so for a solution ``x`` with those rotations

    f(x) − f*  ≤  gap = (f(x) − f(Y)) + η·nd        whenever  S + ηI ≻ 0,

``f(x) − f(Y) ≥ 0`` being what the translations of ``x`` lose against the optimal ones.
:func:`certify` asks for the ``η`` that makes ``gap`` the allowed ``tol·|f(x)| + atol`` and
*proves* ``S + ηI ≻ 0`` by a sparse Cholesky factorization (SE-Sync's ``fast_verification``):
``optimal=True`` never rests on an eigenvalue estimate. When the factorization fails, the
smallest eigenpair is computed (:mod:`.eigen`) for the report and for leaving the saddle.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from manopt_lie import SO2, SO3
from manopt_lie.errors import NonFiniteError, ShapeError
from manopt_lie.lie.base import LieGroup

from ..graph import MeasurementGraph
from .data import Relaxation, relaxation, stacked
from .eigen import bracket, lanczos_min, ritz_min

FloatArray = NDArray[np.float64]

DEFAULT_TOL = 1e-6
"""Default relative tolerance: ``optimal`` means ``f(x) − f* ≤ 1e-6·f(x) + atol``."""

EIG_FLOOR = 1e-13
"""The smallest margin ``η`` a factorization is asked to prove, relative to
:attr:`~.data.Relaxation.scale` (about 500 ulps: above the backward error of a sparse
Cholesky factorization and the rounding of ``Λ``)."""

ATOL_FACTOR = 2.0
"""The default ``atol = ATOL_FACTOR · n·d · EIG_FLOOR · scale``: the resolution of the test,
what lets a solution of cost ``f* = 0`` (noise-free measurements) be certified at all."""

_HEADROOM = 0.999  # η leaves 0.1 % of the allowed gap for restating a certificate (with_fun)


@dataclass(frozen=True)
class Certificate:
    """The outcome of :func:`certify` at a point ``x`` (or a relaxation point ``Y``).

    Attributes
    ----------
    optimal : bool
        ``S + ηI ≻ 0`` was proven by a factorization and ``gap ≤ tol·|fun| + atol``:
        then ``f(x) − f* ≤ gap``.
    fun : float
        ``f(x)``, the chordal cost (CONVENTIONS §8) of the point.
    lambda_min : float
        An estimate of the smallest eigenvalue of ``S = Q − Λ``: a Ritz value (an upper
        bound on it) of Lanczos or inverse iteration; ``nan`` when not computed.
    lambda_lower : float
        A proven lower bound on it: ``−η`` when ``S + ηI ≻ 0`` was shown, else the bracket's
        ``−hi`` (or ``S ⪰ −Λ``'s).
    eta : float
        The margin asked for.
    tol, atol : float
        The tolerances: ``optimal`` needs ``gap ≤ tol·|fun| + atol``.
    dual_bound : float
        A proven lower bound on the optimum ``f*``: ``tr(Λ) + n·d·lambda_lower``.
    gap : float
        ``fun − dual_bound``, a proven upper bound on ``f(x) − f*``.
    eigenvector : ndarray ``(n, d)``
        A unit eigenvector of ``lambda_min`` in blocks ``v_i``: when ``lambda_min < 0`` the
        direction of negative curvature that leaves a saddle (zeros when not computed).
    rank : int
        ``p`` of the certified point (``d`` for poses or rotations).
    factorizations : int
        Sparse factorizations spent.
    time : float
        Wall time in seconds.
    message : str
        What was found, in words.
    """

    optimal: bool
    fun: float
    lambda_min: float
    lambda_lower: float
    eta: float
    tol: float
    atol: float
    dual_bound: float
    gap: float
    eigenvector: FloatArray
    rank: int
    factorizations: int
    time: float
    message: str

    @property
    def relative_gap(self) -> float:
        """``gap / |fun|`` (``inf`` at ``fun = 0`` with a positive gap)."""
        if self.fun == 0.0:
            return 0.0 if self.gap <= 0.0 else math.inf
        return self.gap / abs(self.fun)

    def __str__(self) -> str:
        verdict = "optimal" if self.optimal else "NOT certified"
        return (
            f"{verdict}: f = {self.fun:.10g}, f − f* ≤ {self.gap:.3e} ({self.relative_gap:.2e} relative), "
            f"λ_min(S) ≈ {self.lambda_min:.3e} (proven ≥ {self.lambda_lower:.3e}, asked ≥ {-self.eta:.3e})"
        )


def default_atol(rel: Relaxation) -> float:
    """``ATOL_FACTOR · n·d · EIG_FLOOR · scale``."""
    return ATOL_FACTOR * rel.n * rel.d * EIG_FLOOR * rel.scale


def margin(rel: Relaxation, f_x: float, f_y: float, tol: float, atol: float | None = None) -> float:
    """``η = (tol·|f_x| + atol − (f_x − f_y)) / nd`` (less 0.1 % of headroom for
    :func:`with_fun`), at least ``EIG_FLOOR·scale``: the margin whose proof makes the gap
    bound ``(f_x − f_y) + η·nd`` the allowed one."""
    atol = default_atol(rel) if atol is None else atol
    budget = tol * abs(f_x) + atol - max(f_x - f_y, 0.0)
    return max(_HEADROOM * budget / (rel.n * rel.d), EIG_FLOOR * rel.scale)


def with_fun(rel: Relaxation, cert: Certificate, fun: float) -> Certificate:
    """``cert`` (of ``Y``) restated for a point ``x`` with the same rotations up to round-off
    far below the floor, whose cost is ``fun``: the same proven bound on ``λ_min``, the gap
    ``fun − dual_bound`` and the same acceptance rule."""
    gap = fun - cert.dual_bound
    proven = cert.lambda_lower >= -cert.eta
    return replace(cert, fun=fun, gap=gap, optimal=proven and gap <= cert.tol * abs(fun) + cert.atol)


def certify_relaxation(
    rel: Relaxation,
    y: FloatArray,
    *,
    fun: float | None = None,
    tol: float = DEFAULT_TOL,
    atol: float | None = None,
    seed: int | None = 0,
    eigenvector: bool = True,
    quick: bool = False,
) -> Certificate:
    """The certificate of a rank-``p`` point ``Y`` (``(n, p, d)``, orthonormal columns per block).

    Parameters
    ----------
    rel : Relaxation
        The graph's reduced data (:func:`~.data.relaxation`).
    y : ndarray ``(n, p, d)``
    fun : float, optional
        ``f(x)`` of the point being certified when it is not ``f(Y)`` (a pose estimate whose
        translations are not the optimal ones for its rotations).
    tol, atol : float
        ``optimal`` needs ``f(x) − f* ≤ gap ≤ tol·|f(x)| + atol`` (``atol`` default
        :func:`default_atol`).
    seed : int, optional
        Seeds the eigensolvers' start vectors.
    eigenvector : bool
        Whether to estimate ``λ_min`` and its eigenvector when the point is certified (one
        step of block inverse iteration from the rows of ``Y`` and a random vector, a
        Ritz value); a refused point always gets them unless ``quick``.
    quick : bool
        Only the factorization test: a refused point gets ``lambda_min = nan``, a zero
        eigenvector and the bound ``S ⪰ −Λ`` (what a stopping test needs).
    """
    start = time.perf_counter()
    n, p, d = y.shape
    nd = n * d
    atol = default_atol(rel) if atol is None else float(atol)
    yt = stacked(y)
    lam = rel.lambda_blocks(y, rel.q(yt))
    f_y = rel.cost(y)  # = tr Λ up to the rounding of Λ, which EIG_FLOOR covers
    f_x = f_y if fun is None else float(fun)
    lost = max(f_x - f_y, 0.0)  # what the point's translations lose against the optimal ones
    allowed = tol * abs(f_x) + atol
    eta = margin(rel, f_x, f_y, tol, atol)
    floor = EIG_FLOOR * rel.scale
    rng = np.random.default_rng(seed)
    count = 1
    theta, v = math.nan, np.zeros(nd)
    if rel.factor_certificate(lam, eta):
        lower = -eta
        if eigenvector:
            theta, v = ritz_min(rel, lam, np.concatenate([yt, rng.standard_normal((nd, 1))], axis=1), steps=1)
    elif quick:
        lower = -max(float(np.max(np.linalg.eigvalsh(lam)[:, -1])), 0.0)  # S ⪰ −Λ
    else:
        hi, spent = bracket(rel, lam, eta, floor)
        count += spent
        lower = -hi
        theta, v = lanczos_min(rel, lam, hi, rng.standard_normal(nd))
    dual = f_y + nd * lower
    gap = f_x - dual
    optimal = lower >= -eta and gap <= allowed
    if optimal:
        message = f"certified: S + ηI ≻ 0 with η = {eta:.3e}, so f − f* ≤ {gap:.3e}"
    elif lost > allowed:
        message = (
            f"not certified: the translations lose {lost:.3e} against the optimal ones for these rotations, "
            f"more than tol·|f| + atol = {allowed:.3e}"
        )
    elif lower >= -eta:
        message = f"S + ηI ≻ 0, but the gap bound {gap:.3e} exceeds tol·|f| + atol = {allowed:.3e} (the resolution)"
    elif math.isnan(theta):
        message = "not certified: the factorization test failed (λ_min not computed)"
    else:
        message = f"not certified: λ_min(S) ≈ {theta:.3e} < −η = {-eta:.3e} (a saddle or a spurious local minimum)"
    return Certificate(
        optimal, f_x, theta, lower, eta, tol, atol, dual, gap, v.reshape(n, d), p, count,
        time.perf_counter() - start, message,
    )  # fmt: skip


def rotations_of(graph: MeasurementGraph, x: Any) -> tuple[FloatArray, FloatArray | None]:
    """The rotations ``(n, d, d)`` and translations ``(n, d)`` (or ``None``) of a solution.

    ``x`` may be the graph's group element (SE(d) or SO(d), batch ``(n,)``), an SO(d)
    element for a pose graph (the translations are then the optimal ones), or arrays:
    homogeneous matrices ``(n, d+1, d+1)``, top rows ``[R t]`` ``(n, d, d+1)``, rotations
    ``(n, d, d)``, or a pair ``(R, t)``. Rotations are validated (and re-orthonormalized) by
    ``SO(d).from_matrix``; translations are ignored for rotation averaging.

    Raises
    ------
    ShapeError, NonFiniteError, NotInGroupError
    """
    n, d = graph.n, graph.d
    if isinstance(x, LieGroup):
        if x.batch_shape != (n,):
            raise ShapeError(f"{graph.name}: x must have batch shape ({n},), got {x.batch_shape}")
        m = np.asarray(x.as_matrix())
    elif isinstance(x, tuple) and len(x) == 2:
        r, t = (np.asarray(a, dtype=np.float64) for a in x)
        if r.shape != (n, d, d) or t.shape != (n, d):
            raise ShapeError(
                f"{graph.name}: (R, t) must have shapes ({n}, {d}, {d}) and ({n}, {d}), got {r.shape} and {t.shape}"
            )
        m = np.concatenate([r, t[:, :, None]], axis=2)
    else:
        m = np.asarray(x, dtype=np.float64)
    if m.shape not in ((n, d + 1, d + 1), (n, d, d + 1), (n, d, d)):
        raise ShapeError(
            f"{graph.name}: x must hold {n} poses or rotations as ({n}, {d + 1}, {d + 1}), ({n}, {d}, {d + 1}) "
            f"or ({n}, {d}, {d}) matrices, got {m.shape}"
        )
    if not np.all(np.isfinite(m)):
        raise NonFiniteError(f"{graph.name}: x holds non-finite values")
    rotations = np.asarray((SO2 if d == 2 else SO3).from_matrix(m[:, :d, :d]).as_matrix())
    translations = m[:, :d, d] if m.shape[2] == d + 1 and graph.has_translations else None
    return rotations, translations


def certify(
    graph: MeasurementGraph,
    x: Any,
    *,
    tol: float = DEFAULT_TOL,
    atol: float | None = None,
    data: Relaxation | None = None,
    eigenvector: bool = True,
    seed: int | None = 0,
) -> Certificate:
    """Certify — or refuse — the global optimality of a solution of ``graph``'s chordal cost.

    Parameters
    ----------
    graph : PoseGraph or RotationAveraging
        Its chordal cost (CONVENTIONS §8) ``Σ κ‖R_j − R_i R̃‖² + τ‖t_j − t_i − R_i t̃‖²`` with
        SE-Sync's weights (``Σ κ‖R_j − R_i R̃‖²`` for rotations).
    x : group element or arrays
        The solution, from any solver (see :func:`rotations_of` for the forms accepted).
        Given translations enter through ``f(x)``; without them the optimal ones for the
        rotations are meant.
    tol : float
        Relative tolerance: ``optimal=True`` guarantees ``f(x) − f* ≤ tol·f(x) + atol``.
    atol : float, optional
        Absolute tolerance, default :func:`default_atol` (``2·n·d·10⁻¹³·‖Q‖``, the test's
        resolution).
    data : Relaxation, optional
        The graph's reduced data, to reuse across calls (built here when not given).
    eigenvector : bool
        Whether a certified point also gets its ``λ_min`` estimate and eigenvector.
    seed : int, optional
        Seeds the eigensolvers.

    Returns
    -------
    Certificate

    Raises
    ------
    ValueError
        For a negative tolerance, and (subclasses) for ``x`` of the wrong shape, not
        finite or not rotations, or a graph whose chordal weights are not positive.
    """
    if not (tol >= 0 and (atol is None or atol >= 0)):
        raise ValueError(f"certify: tol and atol must be non-negative, got tol={tol!r}, atol={atol!r}")
    rel = relaxation(graph) if data is None else data
    rotations, translations = rotations_of(graph, x)
    fun = None if translations is None else graph.cost(_poses(graph, rotations, translations), "chordal")
    return certify_relaxation(rel, rotations, fun=fun, tol=tol, atol=atol, seed=seed, eigenvector=eigenvector)


def _poses(graph: MeasurementGraph, rotations: FloatArray, translations: FloatArray) -> LieGroup:
    d = graph.d
    m = np.zeros((graph.n, d + 1, d + 1))
    m[:, :d, :d], m[:, :d, d], m[:, d, d] = rotations, translations, 1.0
    return graph.group.from_matrix(m)
