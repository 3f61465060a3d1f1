"""The certificate of global optimality of the chordal cost: the smallest eigenvalue of
``S = Q − Λ(Y)`` (Rosen et al., IJRR 2019, Theorem 7; Boumal, Voroninski, Bandeira 2016).

For the relaxation ``min tr(Q Z)`` over ``Z ⪰ 0`` with identity ``d × d`` diagonal blocks
(an SDP whose value ``f_SDP`` is at most the optimum ``f*`` over SO(d)ⁿ), every
block-diagonal symmetric ``Λ`` with ``Q − Λ ⪰ −ηI`` gives the dual bound
``f* ≥ f_SDP ≥ tr(Λ) − η n d``. At a point ``Y`` (rotations ``R``, or a rank-``p``
relaxation point) SE-Sync's multipliers ``Λ_i = Sym((QYᵀ)_i Y_i)`` have ``tr Λ = f(Y)``,
the chordal cost with optimal translations, so

    f(x) − f*  ≤  gap = (f(x) − f(Y)) + η n d        whenever  S + ηI ≻ 0,

where ``f(x) − f(Y) ≥ 0`` is what the translations of ``x`` lose against the optimal ones.
:func:`certify` chooses the ``η`` that makes ``gap = tol·f(x)`` (plus a floor
``n d · EIG_FLOOR · scale`` set by the precision of a factorization) and *proves*
``S + ηI ≻ 0`` by a sparse Cholesky factorization (as SE-Sync's ``fast_verification``):
``optimal=True`` is never claimed from an eigenvalue estimate. When the factorization
fails, the smallest eigenpair is computed for the report and for escaping the saddle:
a log-bisection of factorizations brackets ``λ_min`` between ``−lo`` and ``−hi``
(``S ⪰ −Λ`` gives the first ``hi``), then shift-and-invert Lanczos (ARPACK) at ``−hi``
converges in a few solves because the wanted eigenvalue is the one nearest the shift.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse.linalg as spla
from numpy.typing import NDArray

from manopt_lie.errors import ShapeError
from manopt_lie.lie.base import LieGroup

from ..graph import MeasurementGraph
from .data import Relaxation, relaxation, stacked

FloatArray = NDArray[np.float64]

DEFAULT_TOL = 1e-6
"""Default relative tolerance: ``optimal`` means ``f(x) − f* ≤ 1e-6·f(x)`` (plus the floor)."""

EIG_FLOOR = 1e-12
"""The smallest eigenvalue margin a factorization is asked to prove, relative to
:attr:`Relaxation.scale` (a few hundred times the backward error of a Cholesky factorization)."""

_BRACKET_RATIO = 8.0  # bisect λ_min's bracket [−hi, −lo] until hi/lo ≤ this


@dataclass(frozen=True)
class Certificate:
    """The outcome of :func:`certify` at a point ``x`` (or a relaxation point ``Y``).

    Attributes
    ----------
    optimal : bool
        ``S + ηI ≻ 0`` was proven by a factorization and ``f(x) − f(Y) ≤ tol·f(x)``:
        then ``f(x) − f* ≤ gap ≤ tol·f(x) + n·d·EIG_FLOOR·scale``.
    fun : float
        ``f(x)``, the chordal cost (CONVENTIONS §8) of the point.
    lambda_min : float
        An estimate of the smallest eigenvalue of ``S = Q − Λ``: a Ritz value (an upper
        bound) from a Lanczos or inverse iteration.
    lambda_lower : float
        A proven lower bound on it (``−η`` when optimal; ``−hi`` of the bracket otherwise).
    eta : float
        The margin asked for: optimal iff ``S + ηI ≻ 0`` (and the translation test).
    tol : float
        The relative tolerance on ``f(x) − f*``.
    dual_bound : float
        A proven lower bound on the optimum: ``tr(Λ) + n·d·lambda_lower``.
    gap : float
        ``fun − dual_bound``, a proven upper bound on ``f(x) − f*``.
    eigenvector : ndarray ``(n, d)``
        A unit eigenvector of ``lambda_min``, in blocks (the direction of negative
        curvature that leaves a saddle when ``lambda_min < 0``).
    rank : int
        ``p`` of the certified point (``d`` for poses or rotations).
    factorizations : int
        Sparse factorizations spent; ``time`` their wall time in seconds, with the rest.
    message : str
        What was found, in words.
    """

    optimal: bool
    fun: float
    lambda_min: float
    lambda_lower: float
    eta: float
    tol: float
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


def _s_times(rel: Relaxation, lam: FloatArray, vt: FloatArray) -> FloatArray:
    """``S V = Q V − Λ V`` for ``V`` of shape ``(nd, k)``."""
    n, d = rel.n, rel.d
    lv = (lam @ vt.reshape(n, d, -1)).reshape(n * d, -1)
    return rel.q(vt) - lv


def _ritz_min(rel: Relaxation, lam: FloatArray, start: FloatArray, steps: int) -> tuple[float, FloatArray]:
    """The smallest Ritz pair of ``S`` on ``(S + shift I)⁻ᵏ · start``: block inverse iteration
    with the current (positive definite) certificate factorization."""
    x = np.linalg.qr(start)[0]
    for _ in range(steps):
        x = np.linalg.qr(rel.solve_certificate(x))[0]
    sx = _s_times(rel, lam, x)
    h = x.T @ sx
    w, u = np.linalg.eigh(0.5 * (h + h.T))
    v = x @ u[:, 0]
    return float(w[0]), v / np.linalg.norm(v)


def _lanczos_min(rel: Relaxation, lam: FloatArray, shift: float, v0: FloatArray) -> tuple[float, FloatArray]:
    """The eigenpair of ``S`` nearest ``−shift`` (the smallest one: ``S + shift·I ≻ 0``) by
    ARPACK in shift-and-invert mode, with the current certificate factorization."""
    size = rel.n * rel.d

    def s_op(v: FloatArray) -> FloatArray:
        return _s_times(rel, lam, v.reshape(size, 1)).ravel()

    def inv_op(v: FloatArray) -> FloatArray:
        return rel.solve_certificate(v.reshape(size, 1)).ravel()

    a = spla.LinearOperator((size, size), matvec=s_op, dtype=np.float64)
    op = spla.LinearOperator((size, size), matvec=inv_op, dtype=np.float64)
    try:
        w, u = spla.eigsh(a, k=1, sigma=-shift, which="LM", OPinv=op, v0=v0, tol=1e-8, maxiter=200)
        v = u[:, 0] / np.linalg.norm(u[:, 0])
    except spla.ArpackNoConvergence as err:  # keep the best Ritz vector it had
        if not err.eigenvectors.size:
            return _ritz_min(rel, lam, v0.reshape(size, 1), 4)
        v = err.eigenvectors[:, 0] / np.linalg.norm(err.eigenvectors[:, 0])
    theta = float(v @ s_op(v))  # the Rayleigh quotient with the exact S
    del w
    return theta, v


def margin(rel: Relaxation, f_x: float, f_y: float, tol: float) -> float:
    """``η``: the eigenvalue margin that makes the gap bound ``(f_x − f_y) + η·nd`` equal
    ``tol·|f_x|``, plus the floor ``EIG_FLOOR·scale``."""
    lost = max(f_x - f_y, 0.0)
    return max(tol * abs(f_x) - lost, 0.0) / (rel.n * rel.d) + EIG_FLOOR * rel.scale


def certify_relaxation(
    rel: Relaxation,
    y: FloatArray,
    *,
    fun: float | None = None,
    tol: float = DEFAULT_TOL,
    seed: int | None = 0,
    eigenvector: bool = True,
    quick: bool = False,
) -> Certificate:
    """The certificate of a rank-``p`` point ``Y`` (``(n, p, d)``, orthonormal columns per block).

    Parameters
    ----------
    rel : Relaxation
        The graph's reduced data (:func:`~manopt_lie.problems.certify.data.relaxation`).
    y : ndarray ``(n, p, d)``
    fun : float, optional
        ``f(x)`` of the point being certified when it is not ``f(Y)`` (a pose estimate
        whose translations are not the optimal ones for its rotations).
    tol : float
        Relative tolerance on ``f(x) − f*``.
    seed : int, optional
        Seeds the start vectors of the eigensolvers.
    eigenvector : bool
        Whether to estimate ``λ_min`` and its eigenvector when the point is certified
        (two block inverse iterations); when it is not, they are computed unless ``quick``.
    quick : bool
        Only the factorization test: a refused point gets ``lambda_min = nan``, a zero
        eigenvector and the trivial bound ``S ⪰ −Λ`` (what a stopping test needs).
    """
    start = time.perf_counter()
    n, p, d = y.shape
    nd = n * d
    yt = stacked(y)
    qyt = rel.q(yt)
    f_y = rel.cost(y)  # = tr Λ up to the rounding of Λ, which EIG_FLOOR covers
    f_x = f_y if fun is None else float(fun)
    lam = rel.lambda_blocks(y, qyt)
    floor = EIG_FLOOR * rel.scale
    lost = max(f_x - f_y, 0.0)  # what the point's translations lose against the optimal ones
    eta = margin(rel, f_x, f_y, tol)
    rng = np.random.default_rng(seed)
    count = 1
    if rel.factor_certificate(lam, eta):
        lower = -eta
        optimal = lost <= tol * abs(f_x)
        if eigenvector:
            probe = np.concatenate([yt, rng.standard_normal((nd, 2))], axis=1)
            theta, v = _ritz_min(rel, lam, probe, 2)
        else:
            theta, v = math.nan, np.zeros(nd)
    else:
        optimal = False
        # S ⪰ −Λ (Q ⪰ 0): S + hi·I ≻ 0 for hi above the largest eigenvalue of the blocks.
        lo = eta
        hi = max(float(np.max(np.linalg.eigvalsh(lam)[:, -1])), 0.0) * (1.0 + 1e-6) + 2.0 * floor
        if quick:
            return Certificate(
                False, f_x, math.nan, -hi, eta, tol, f_y - nd * hi, f_x - f_y + nd * hi, np.zeros((n, d)), p, count,
                time.perf_counter() - start, "not certified (the factorization test failed; λ_min not computed)",
            )  # fmt: skip
        last_ok = False
        while hi > _BRACKET_RATIO * lo:
            mid = math.sqrt(lo * hi)
            count += 1
            last_ok = rel.factor_certificate(lam, mid)
            lo, hi = (lo, mid) if last_ok else (mid, hi)
        if not last_ok:
            count += 1
            if not rel.factor_certificate(lam, hi):  # only by round-off at the Gershgorin-like bound
                hi *= 2.0
                count += 1
                rel.factor_certificate(lam, hi)
        lower = -hi
        theta, v = _lanczos_min(rel, lam, hi, rng.standard_normal(nd))
    dual = f_y + nd * lower
    gap = f_x - dual
    if optimal:
        message = f"certified: S + ηI ≻ 0 with η = {eta:.3e}, so f − f* ≤ {gap:.3e}"
    elif lost > tol * abs(f_x) and lower >= -eta:
        message = f"the translations are suboptimal by {lost:.3e} for their rotations (more than tol·f)"
    else:
        message = f"λ_min(S) ≈ {theta:.3e} < −η = {-eta:.3e}: not certified (a saddle or a local minimum)"
    return Certificate(
        optimal, f_x, theta, lower, eta, tol, dual, gap, v.reshape(n, d), p, count, time.perf_counter() - start,
        message,
    )  # fmt: skip


def rotations_of(graph: MeasurementGraph, x: Any) -> tuple[FloatArray, FloatArray | None]:
    """The rotations ``(n, d, d)`` and translations ``(n, d)`` (or ``None``) of a solution.

    ``x`` may be the graph's group element (SE(d) or SO(d), batch ``(n,)``), an SO(d)
    element for a pose graph (then the translations are the optimal ones), or plain
    arrays: homogeneous matrices ``(n, d+1, d+1)``, top rows ``[R t]`` ``(n, d, d+1)``,
    rotations ``(n, d, d)``, or a pair ``(R, t)``. Rotations are validated (and
    re-orthonormalized) by ``SO(d).from_matrix``.
    """
    n, d = graph.n, graph.d
    if isinstance(x, LieGroup):
        if x.batch_shape != (n,):
            raise ShapeError(f"{graph.name}: x must have batch shape ({n},), got {x.batch_shape}")
        m = np.asarray(x.as_matrix())
    elif isinstance(x, tuple) and len(x) == 2:
        r, t = (np.asarray(a, dtype=np.float64) for a in x)
        if r.shape != (n, d, d) or t.shape != (n, d):
            raise ShapeError(f"{graph.name}: (R, t) must have shapes ({n}, {d}, {d}) and ({n}, {d}), got {r.shape}, {t.shape}")
        m = np.concatenate([r, t[:, :, None]], axis=2)
    else:
        m = np.asarray(x, dtype=np.float64)
    if m.shape not in ((n, d + 1, d + 1), (n, d, d + 1), (n, d, d)):
        raise ShapeError(
            f"{graph.name}: x must hold {n} poses or rotations as ({n}, {d + 1}, {d + 1}), ({n}, {d}, {d + 1}) "
            f"or ({n}, {d}, {d}) matrices, got {m.shape}"
        )
    if not np.all(np.isfinite(m)):
        from manopt_lie.errors import NonFiniteError

        raise NonFiniteError(f"{graph.name}: x holds non-finite values")
    group = _rotation_group(d)
    rotations = np.asarray(group.from_matrix(m[:, :d, :d]).as_matrix())
    translations = m[:, :d, d] if m.shape[2] == d + 1 else None
    if not graph.has_translations:
        translations = None
    return rotations, translations


def _rotation_group(d: int) -> Any:
    from manopt_lie import SO2, SO3

    return SO2 if d == 2 else SO3


def certify(
    graph: MeasurementGraph,
    x: Any,
    *,
    tol: float = DEFAULT_TOL,
    data: Relaxation | None = None,
    eigenvector: bool = True,
    seed: int | None = 0,
) -> Certificate:
    """Certify (or refuse) the global optimality of a solution of ``graph``'s chordal cost.

    Parameters
    ----------
    graph : PoseGraph or RotationAveraging
        Its chordal cost (CONVENTIONS §8) ``Σ κ‖R_j − R_i R̃‖² + τ‖t_j − t_i − R_i t̃‖²``.
    x : group element or arrays
        The solution, from any solver: see :func:`rotations_of` for the forms accepted.
        Translations, when given, enter through ``f(x)``; without them the optimal ones
        for the rotations are meant.
    tol : float
        Relative tolerance: ``optimal=True`` guarantees ``f(x) − f* ≤ tol·f(x) + n·d·EIG_FLOOR·scale``.
    data : Relaxation, optional
        The graph's reduced data, to reuse across calls (built when not given).
    eigenvector, seed
        See :func:`certify_relaxation`.

    Returns
    -------
    Certificate
    """
    if not tol >= 0:
        raise ValueError(f"certify: tol must be non-negative, got {tol!r}")
    rel = relaxation(graph) if data is None else data
    rotations, translations = rotations_of(graph, x)
    fun = None
    if translations is not None:
        fun = graph.cost(_poses(graph, rotations, translations), "chordal")
    return certify_relaxation(rel, rotations, fun=fun, tol=tol, seed=seed, eigenvector=eigenvector)


def _poses(graph: MeasurementGraph, rotations: FloatArray, translations: FloatArray) -> LieGroup:
    d = graph.d
    m = np.zeros((graph.n, d + 1, d + 1))
    m[:, :d, :d], m[:, :d, d], m[:, d, d] = rotations, translations, 1.0
    return graph.group.from_matrix(m)
