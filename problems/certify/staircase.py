"""The Riemannian staircase (Boumal 2015; SE-Sync, Rosen et al. IJRR 2019, Algorithm 1;
Shonan averaging, Dellaert et al. ECCV 2020, for rotations).

At rank ``p ≥ d`` the relaxation is ``min f(Y) = tr(Y Q Yᵀ)`` over ``Y ∈ St(p, d)ⁿ``
(blocks ``Y_i`` with orthonormal columns, translations eliminated: :mod:`.data`). Each
level runs :class:`~manopt_lie.optim.TrustRegion` with the exact Hessian (``∇f = 2YQ``,
``∇²f[V] = 2VQ``, turned Riemannian by ``Stiefel.egrad2rgrad/ehess2rhess``) and SE-Sync's
regularized Cholesky preconditioner ``(Q + λI)⁻¹``, then certifies the critical point
(:func:`~.certificate.certify_relaxation`). A certified ``Y`` solves the SDP relaxation;
otherwise ``λ_min(S) < 0`` and its eigenvector ``v`` gives the direction of negative
curvature ``Ẏ = e_{p+1} vᵀ`` at ``[Y; 0]`` on the next level, along which a backtracking
line search leaves the saddle. The final ``Y`` is rounded to rotations
(:func:`~.rounding.round_solution`), the translations are recovered, and the rounded
solution is certified on its own.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, replace
from enum import Enum
from typing import Any

import numpy as np
from numpy.typing import NDArray

from manopt_lie.lie.base import LieGroup
from manopt_lie.manifolds import Power, Stiefel
from manopt_lie.optim import IterationInfo, OptimizeResult, Problem, StoppingCriteria, TrustRegion

from ..graph import MeasurementGraph
from .certificate import DEFAULT_TOL, Certificate, certify_relaxation, margin, rotations_of, with_fun
from .data import Relaxation, relaxation, stacked
from .relaxed import escape_saddle, preconditioner, relaxation_problem
from .rounding import lift, round_solution

FloatArray = NDArray[np.float64]

logger = logging.getLogger("manopt_lie.problems.certify")

DEFAULT_STOPPING = StoppingCriteria(max_iterations=500, grad_rtol=1e-6, grad_atol=1e-9, rel_cost_decrease=1e-9)
"""The trust region at the levels ``p > d``: only as accurate as rounding needs (the point
at rank ``d`` is then polished); tighter when a certificate asks for it."""

GRAD_FLOOR = 1e-13
"""The polishing trust region at rank ``d`` stops at ``‖grad f‖ ≤ GRAD_FLOOR·‖Q‖·√(nd·p)``
(``‖Q‖`` the :attr:`Relaxation.scale`), a few hundred times the round-off of ``2YQ``: the
certificate needs accurate critical points (``λ_min`` of a point at distance ``δ`` from one
is ``−O(δ²)``), which the exact Hessian reaches in a few iterations, but not below round-off."""


def default_polish(rel: Relaxation, p: int) -> StoppingCriteria:
    """The rank-``d`` trust region's stopping rule (:data:`GRAD_FLOOR`)."""
    floor = GRAD_FLOOR * rel.scale * math.sqrt(rel.n * rel.d * p)
    return StoppingCriteria(max_iterations=200, grad_rtol=0.0, grad_atol=floor)


STALL_WINDOW = 10
STALL_DECREASE = 1e-2
"""A level ``p > d`` ends when ``STALL_WINDOW`` iterations lower the cost by less than this fraction."""

_REFINEMENTS = 1  # re-solves of one level, 100× tighter, when λ_min fails only by a hair
_IMPRECISE = 10.0  # λ_min ≥ −10η: maybe imprecision of the critical point, not a saddle


class StaircaseStatus(Enum):
    """Why :func:`staircase` stopped; only ``OPTIMAL`` carries a certificate."""

    OPTIMAL = "the rounded solution is certified globally optimal"
    RELAXATION_NOT_TIGHT = "the relaxation was solved (certified) but its rounded solution is not certified"
    MAX_RANK = "the maximum rank was reached without a certificate"
    MAX_TIME = "the time limit was reached without a certificate"
    ESCAPE_FAILED = "no decrease was found along the negative curvature direction"


@dataclass(frozen=True)
class Level:
    """One level of the staircase.

    Attributes
    ----------
    rank : int
        ``p``.
    result : OptimizeResult
        The trust region at rank ``p`` (iterations, time, history).
    polish : OptimizeResult or None
        The trust region at rank ``d`` from the rounded point (``p > d``; for ``p = d`` a
        re-solve with tighter tolerances, if one was needed).
    certificate_d : Certificate
        Of the rank-``d`` point (rounded and polished).
    certificate : Certificate
        Of the rank-``p`` point (the same as ``certificate_d`` for ``p = d``): its
        eigenvector is the escape direction.
    escape_step : float
        The step taken along it to the next level (``nan``: none).
    """

    rank: int
    result: OptimizeResult
    polish: OptimizeResult | None
    certificate_d: Certificate
    certificate: Certificate
    escape_step: float

    @property
    def iterations(self) -> int:
        """Trust-region iterations at this rank, the polish's included."""
        return self.result.nit + (self.polish.nit if self.polish is not None else 0)

    @property
    def time(self) -> float:
        """Trust-region time at both ranks (certificates excluded)."""
        return self.result.time + (self.polish.time if self.polish is not None else 0.0)


@dataclass(frozen=True)
class StaircaseResult:
    """What :func:`staircase` returns.

    Attributes
    ----------
    x : group element, batch ``(n,)``
        The rounded solution: SE(d) poses (translations recovered) or SO(d) rotations.
    fun : float
        Its chordal cost (CONVENTIONS §8, the graph's ``cost(x, "chordal")``).
    optimal : bool
        Whether :attr:`certificate` certifies ``x``.
    certificate : Certificate
        The certificate of ``x`` itself (rank ``d``).
    status : StaircaseStatus
    rank : int
        The rank ``p`` of the last level.
    y : ndarray ``(n, rank, d)``
        The last relaxation point; ``relaxation_value = f(y)``.
    lower_bound : float
        The best proven lower bound on the optimum ``f*`` (from the certificates of ``x``
        and of the last ``y``); ``suboptimality = fun − lower_bound ≥ fun − f*``.
    levels : tuple of Level
        Per level: the trust-region result (iterations, time, history) and the certificate.
    time : float
        Wall time in seconds, the initialization included (not :func:`relaxation`, when given).
    time_certificates : float
        The part spent in certificates.
    """

    x: LieGroup
    fun: float
    optimal: bool
    certificate: Certificate
    status: StaircaseStatus
    rank: int
    y: FloatArray
    relaxation_value: float
    lower_bound: float
    suboptimality: float
    levels: tuple[Level, ...]
    time: float
    time_certificates: float

    @property
    def iterations(self) -> int:
        """Trust-region iterations over all levels."""
        return sum(level.iterations for level in self.levels)

    def __str__(self) -> str:
        return (
            f"{self.status.value}: f = {self.fun:.10g}, f − f* ≤ {self.suboptimality:.3e}, rank {self.rank}, "
            f"{len(self.levels)} levels, {self.iterations} iterations, {self.time:.3g} s "
            f"({self.time_certificates:.3g} s certificates)"
        )


def _initial_point(graph: MeasurementGraph, x0: Any, p: int, rng: np.random.Generator) -> FloatArray:
    d = graph.d
    if x0 is None or (isinstance(x0, str) and x0 == "chordal"):
        return lift(rotations_of(graph, graph.chordal_initialization())[0], p)
    if isinstance(x0, str):
        if x0 != "random":
            raise ValueError(f"staircase: x0 must be None, 'chordal', 'random', a solution or blocks, got {x0!r}")
        if p == d:  # St(d, d) = O(d) has two components: start in SO(d), which rounding expects
            from manopt_lie.manifolds import SpecialOrthogonal

            return np.asarray(Power(SpecialOrthogonal(d), graph.n).random_point(rng))
        return np.asarray(Power(Stiefel(p, d), graph.n).random_point(rng))
    if isinstance(x0, np.ndarray) and x0.ndim == 3 and x0.shape[2] == d and x0.shape[1] > d:
        Power(Stiefel(x0.shape[1], d), graph.n).check_point(x0, "x0")
        return lift(np.asarray(x0, dtype=np.float64), max(p, x0.shape[1]))
    return lift(rotations_of(graph, x0)[0], p)


def _imprecise(cert: Certificate, y: FloatArray) -> bool:
    """Whether a refused certificate may only lack accuracy of the critical point ``Y``.

    At a point at distance ``δ`` from a certifiable one, the rows of ``Y`` are near null
    vectors of ``S`` (``SYᵀ = ½ grad fᵀ``) and ``λ_min = −O(δ²)`` belongs to them: the
    eigenvector lies in their span. A saddle's negative eigenvector is orthogonal to them
    (another eigenvalue of the symmetric ``S``). So: imprecise iff ``λ_min ≥ −10η`` or the
    eigenvector has more than half its norm in the span of the rows of ``Y``.
    """
    if cert.optimal or math.isnan(cert.lambda_min):
        return False
    if cert.lambda_min >= -_IMPRECISE * cert.eta:
        return True
    basis = np.linalg.qr(stacked(y))[0]
    return bool(np.linalg.norm(basis.T @ cert.eigenvector.reshape(-1)) > 0.5)


def _tighter(stop: StoppingCriteria) -> StoppingCriteria:
    return replace(stop, grad_rtol=stop.grad_rtol * 1e-2, grad_atol=stop.grad_atol * 1e-2)


def staircase(
    graph: MeasurementGraph,
    x0: Any = None,
    *,
    rank: int | None = None,
    max_rank: int | None = None,
    seed: int | None = None,
    tol: float = DEFAULT_TOL,
    atol: float | None = None,
    stopping: StoppingCriteria | None = None,
    polish: StoppingCriteria | None = None,
    max_time: float = math.inf,
    precondition: bool = True,
    data: Relaxation | None = None,
    trust_region: dict[str, Any] | None = None,
) -> StaircaseResult:
    """Certifiably optimal chordal pose-graph optimization (SE-Sync) or rotation averaging
    (Shonan) by the Riemannian staircase.

    Each level ``p``: the trust region on the rank-``p`` relaxation (``stopping``, and a
    level ``p > d`` ends on a stall: :data:`STALL_WINDOW`); for
    ``p > d`` the point is rounded to rotations and polished by the trust region at rank
    ``d`` (``polish``); the rank-``d`` point is certified. Certified: done. Otherwise the
    rank-``p`` point is certified too: certified, the relaxation is solved but not tight
    (its bound is reported); a ``λ_min`` within ``10η`` of passing re-solves the level with
    100× tighter gradient tolerances (once); else the staircase climbs to
    ``p + 1`` along the negative curvature direction (:func:`~.relaxed.escape_saddle`). The rank-``d``
    trust region stops itself (``Status.CALLBACK``) once its point is certified, or seen
    to be a saddle.

    Parameters
    ----------
    graph : PoseGraph or RotationAveraging
    x0 : None, "chordal", "random", solution or ndarray ``(n, q, d)``, optional
        Where to start: the chordal initialization (default), random rotations (rank
        ``d``; random Stiefel blocks at a higher rank) drawn from ``seed``, any solution
        (group element or arrays, as :func:`~.certificate.certify` takes), or Stiefel
        blocks of some rank ``q``.
    rank : int, optional
        The first level ``p`` (default ``d``; SE-Sync starts at 5).
    max_rank : int, optional
        The last level (default ``rank + 10``).
    seed : int, optional
        The random initialization's and the eigensolvers' seed.
    tol, atol : float
        The certificates' tolerances (:func:`~.certificate.certify`): ``optimal`` guarantees
        ``fun − f* ≤ tol·fun + atol``.
    stopping : StoppingCriteria, optional
        The trust region of the levels ``p > d`` (default :data:`DEFAULT_STOPPING`).
    polish : StoppingCriteria, optional
        The trust region at rank ``d`` (default :func:`default_polish`).
    max_time : float
        Seconds for the whole staircase.
    precondition : bool
        SE-Sync's regularized Cholesky preconditioner (default) or none (the trust region's
        steps are kept orthogonal to the gauge orbit either way: :func:`~.relaxed.preconditioner`).
    data : Relaxation, optional
        The graph's reduced data, if already built (:func:`~.data.relaxation`).
    trust_region : dict, optional
        :class:`~manopt_lie.optim.TrustRegion` options (default ``theta=0.5``, SE-Sync's;
        the preconditioner is :func:`~.relaxed.preconditioner`).

    Returns
    -------
    StaircaseResult
    """
    start = time.perf_counter()
    rel = relaxation(graph) if data is None else data
    d = graph.d
    p = d if rank is None else int(rank)
    max_rank = p + 10 if max_rank is None else int(max_rank)
    if not d <= p <= max_rank:
        raise ValueError(f"staircase: need d = {d} <= rank = {p} <= max_rank = {max_rank}")
    rng = np.random.default_rng(seed)
    y = _initial_point(graph, x0, p, rng)
    p = y.shape[1]
    level_stop = DEFAULT_STOPPING if stopping is None else stopping
    polish_stop = default_polish(rel, d) if polish is None else polish
    options = {"theta": 0.5, **(trust_region or {})}  # SE-Sync's: q-superlinear of order 1.5
    problems: dict[int, Problem] = {}
    cert_time = [0.0]

    def problem_at(rank: int) -> Problem:
        if rank not in problems:
            problems[rank] = relaxation_problem(rel, rank)
        return problems[rank]

    found: list[tuple[FloatArray, Certificate]] = []  # (point, certificate) the callback certified

    checked = [math.inf]  # the gradient norm at this run's last full certificate

    def certified(info: IterationInfo) -> bool:
        """Stop the rank-d trust region once its point is certified, or is clearly a saddle.

        Tried once ``‖grad‖ ≤ 10·√(η‖Q‖)`` (``λ_min ≈ −‖grad‖²/μ`` with ``μ ≤ ‖Q‖``): a
        factorization; when it refuses, the eigenpair too (once per hundredfold decrease of
        the gradient), and an eigenvector away from the rows of ``Y`` is a saddle's, which
        more accuracy would not change (:func:`_imprecise`).
        """
        eta = margin(rel, info.fun, info.fun, tol, atol)
        if info.grad_norm > 10.0 * math.sqrt(eta * rel.scale):
            return False
        y_ = np.asarray(info.x)
        cert = check(y_, quick=True)
        if not cert.optimal and info.grad_norm < 0.01 * checked[0]:
            checked[0] = info.grad_norm
            cert = check(y_, eigenvector=False)
            if _imprecise(cert, y_):
                return False
        elif not cert.optimal:
            return False
        found.append((np.array(y_), cert))
        return True

    costs: list[float] = []

    def stalled(info: IterationInfo) -> bool:
        """End a level ``p > d`` once :data:`STALL_WINDOW` iterations lowered the cost by less
        than :data:`STALL_DECREASE` of it: the rounded point is polished and certified then,
        rather than the relaxation crawling (measured: 20 s → 1.7 s on parking-garage's
        rotations from a spurious local minimum, where the rank-4 level crawls for 250
        iterations 10⁵× above the optimum while its rounding polishes to the optimum)."""
        costs.append(info.fun)
        if len(costs) <= STALL_WINDOW:
            return False
        before = costs[-STALL_WINDOW - 1]
        return before - info.fun < STALL_DECREASE * abs(before)

    def run(rank: int, y0: FloatArray, stop: StoppingCriteria) -> OptimizeResult:
        problem = problem_at(rank)
        tr = dict(options)
        tr.setdefault("preconditioner", preconditioner(rel, problem.manifold, regularized=precondition))  # type: ignore[arg-type]
        remaining = max(max_time - (time.perf_counter() - start), 0.0)
        solver = TrustRegion(stopping=replace(stop, max_time=min(stop.max_time, remaining)), **tr)
        checked[0] = math.inf
        costs.clear()
        return solver.solve(problem, y0, callback=certified if rank == d else stalled)

    def check(y_: FloatArray, **kw: Any) -> Certificate:
        cert = certify_relaxation(rel, y_, tol=tol, atol=atol, seed=seed, **kw)
        cert_time[0] += cert.time
        return cert

    def out_of_time() -> bool:
        return time.perf_counter() - start > max_time

    def certify_d(yd: FloatArray) -> Certificate:
        known = [c for x_, c in found if np.array_equal(x_, yd)]  # certified by the callback
        found.clear()
        return known[-1] if known else check(yd, eigenvector=False)

    levels: list[Level] = []
    status = StaircaseStatus.MAX_RANK
    while True:
        stop = level_stop if p > d else polish_stop
        for _ in range(_REFINEMENTS + 1):
            result = run(p, y, stop)
            y = np.asarray(result.x)
            polished: OptimizeResult | None = None
            if p == d:
                yd, stop_d = y, stop
            else:
                polished = run(d, lift(round_solution(y), d), polish_stop)
                yd, stop_d = np.asarray(polished.x), polish_stop
            cert_d = certify_d(yd)
            for _ in range(_REFINEMENTS):  # the rank-d point: as accurate as the certificate needs
                if not _imprecise(cert_d, yd) or out_of_time():
                    break
                stop_d = _tighter(stop_d)
                polished = run(d, yd, stop_d)
                yd = np.asarray(polished.x)
                cert_d = certify_d(yd)
            if p == d:
                y = yd
            cert_p = cert_d if p == d or cert_d.optimal else check(y, eigenvector=False)
            if cert_d.optimal or not _imprecise(cert_p, y) or out_of_time():
                break
            stop = _tighter(stop)
        logger.info("staircase rank %d: %s; rank %d: %s; rank %d: %s", p, result, d, cert_d, p, cert_p)
        levels.append(Level(p, result, polished, cert_d, cert_p, math.nan))
        if cert_d.optimal:
            status = StaircaseStatus.OPTIMAL
            break
        if cert_p.optimal:
            status = StaircaseStatus.RELAXATION_NOT_TIGHT
            break
        if out_of_time():
            status = StaircaseStatus.MAX_TIME
            break
        if p >= max_rank:
            break
        escaped = escape_saddle(rel, problem_at(p + 1), y, cert_p, max(result.grad_norm, 1e-12) * 10.0)
        if escaped is None:
            status = StaircaseStatus.ESCAPE_FAILED
            break
        y, step = escaped
        levels[-1] = replace(levels[-1], escape_step=step)
        p += 1
    rotations = round_solution(yd)
    x = rel.poses(rotations)
    fun = graph.cost(x, "chordal")
    if np.max(np.abs(rotations - yd)) <= 1e-13 and not math.isnan(cert_d.lambda_min):
        cert_x = with_fun(rel, cert_d, fun)  # the same rotations (up to the floor's round-off)
    else:
        cert_x = check(rotations, fun=fun)
    lower = max(cert_x.dual_bound, cert_p.dual_bound)
    if status is StaircaseStatus.OPTIMAL and not cert_x.optimal:
        status = StaircaseStatus.MAX_RANK  # cannot happen but by round-off in building x
    return StaircaseResult(
        x, fun, cert_x.optimal, cert_x, status, p, y, cert_p.fun, lower, fun - lower, tuple(levels),
        time.perf_counter() - start, cert_time[0],
    )  # fmt: skip
