"""Adapters running optional peer libraries on our problems, for the benchmarks.

Each peer starts from our ``x0``, minimizes the same cost as ours (``docs/conventions.md``)
and returns a :class:`PeerRun` holding our group elements, so that every final
cost can be evaluated with our definition:

- ``gtsam-lm``, ``gtsam-dogleg`` (pose graphs, geodesic cost): GTSAM's
  ``LevenbergMarquardtOptimizer`` / ``DoglegOptimizer`` with default parameters
  (except ``relativeErrorTol`` and ``maxIterations``) on ``BetweenFactorPose2/3``
  with the g2o information ``Ω`` — whose factor-graph error is exactly
  ``½ Σ rᵀΩr``, ``r = Log(Z⁻¹X_i⁻¹X_j)`` — the anchor held by a constrained prior.
  Stopping: GTSAM's own rule (relative or absolute decrease of the error, see
  ``gtsam.checkConvergence``); ``grad_rtol`` does not apply. GTSAM has no time cap:
  ``max_time`` is tested here after each iteration.
- ``pymanopt-tr`` (rotation averaging, chordal cost): pymanopt's ``TrustRegions``
  on ``SpecialOrthogonalGroup(d, k=n)`` (its default QR retraction) with the exact Hessian of
  ``Σ κ‖R_j − R_i R̃‖_F²``. No rotation is fixed: the cost is invariant under a
  global rotation and the trust region copes with that flat direction. Stopping:
  ``‖grad f‖ ≤ grad_rtol ‖grad f(x₀)‖``; ``rel_cost_decrease`` does not apply.

The peers are optional extras (``pip install gtsam pymanopt``): this module imports
them only inside the functions that run them.
"""

from __future__ import annotations

import importlib
import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from manopt_lie import SE2, SE3, SO2, SO3
from manopt_lie.lie.base import LieGroup
from manopt_lie.problems import costs
from manopt_lie.problems.graph import MeasurementGraph
from manopt_lie.problems.pose_graph import PoseGraph
from manopt_lie.problems.rotation_averaging import RotationAveraging


@dataclass(frozen=True)
class Peer:
    """A peer solver: the library it needs and the one ``(kind, cost)`` it solves."""

    name: str
    summary: str
    module: str
    kind: str
    cost: str


PEERS: dict[str, Peer] = {
    peer.name: peer
    for peer in (
        Peer("gtsam-lm", "GTSAM LevenbergMarquardtOptimizer on BetweenFactorPose2/3 (geodesic pose-graph cost)",
             "gtsam", PoseGraph.kind, "geodesic"),
        Peer("gtsam-dogleg", "GTSAM DoglegOptimizer on BetweenFactorPose2/3 (geodesic pose-graph cost)",
             "gtsam", PoseGraph.kind, "geodesic"),
        Peer("pymanopt-tr", "pymanopt TrustRegions on SpecialOrthogonalGroup^n, exact Hessian (chordal rotation "
             "averaging)", "pymanopt", RotationAveraging.kind, "chordal"),
    )
}  # fmt: skip


class PeerUnavailableError(ImportError):
    """A peer library is not installed."""


@dataclass(frozen=True)
class PeerRun:
    """The outcome of one peer run.

    Attributes
    ----------
    x : group element, batch ``(n,)``
        The final poses (SE2/SE3) or rotations (SO2/SO3), in our types.
    nit : int
        Iterations (outer iterations, rejected steps included).
    time : float
        Seconds spent optimizing (building the peer's problem excluded).
    status : str
        ``"converged"``, ``"max_iterations"``, ``"max_time"`` or ``"diverged"`` (the
        snake_case of :mod:`manopt_lie.bench.record`).
    converged : bool
        Whether the peer's own convergence test was met.
    history_cost, history_time : list of float
        The peer's objective at the start and after each iteration (``nit + 1``
        values), and the seconds since the start at which each was reached.
    """

    x: Any
    nit: int
    time: float
    status: str
    converged: bool
    history_cost: list[float]
    history_time: list[float]


def _peer(name: str) -> Peer:
    if name not in PEERS:
        raise ValueError(f"unknown peer {name!r}; choose from {', '.join(PEERS)}")
    return PEERS[name]


def _import(name: str) -> Any:
    module = _peer(name).module
    try:
        return importlib.import_module(module)
    except ImportError as exc:
        raise PeerUnavailableError(
            f"peer {name!r} needs the optional package {module!r}: pip install {module}"
        ) from exc


def available(name: str) -> bool:
    """Whether the library behind peer ``name`` can be imported."""
    try:
        _import(name)
    except PeerUnavailableError:
        return False
    return True


def applies(name: str, kind: str, cost: str) -> bool:
    """Whether peer ``name`` solves problems of ``kind`` (a graph's ``kind``) with ``cost``."""
    peer = _peer(name)
    return (peer.kind, peer.cost) == (kind, cost)


def solve(
    name: str,
    spec: MeasurementGraph,
    x0: LieGroup,
    *,
    max_iterations: int = 100,
    rel_cost_decrease: float = 1e-5,
    grad_rtol: float = 1e-6,
    max_time: float = math.inf,
) -> PeerRun:
    """Run peer ``name`` on ``spec`` from ``x0`` (see the module doc for each peer's cost and rule).

    Raises
    ------
    ValueError
        An unknown peer, or a problem kind it does not solve.
    PeerUnavailableError
        The peer's library is not installed.
    """
    peer = _peer(name)
    if spec.kind != peer.kind:
        raise ValueError(f"peer {name!r} solves {peer.kind}/{peer.cost} problems, not {spec.kind}")
    run = _RUNS[peer.module]
    return run(name, spec, x0, max_iterations=max_iterations, rel_cost_decrease=rel_cost_decrease,
               grad_rtol=grad_rtol, max_time=max_time)  # fmt: skip


# ---- GTSAM ------------------------------------------------------------------------------

# Our tangent order is (ρ, θ); GTSAM's Pose3 tangent is (ω, v), its Pose2 tangent (x, y, θ).
_GTSAM_ORDER: dict[type[LieGroup], np.ndarray] = {SE2: np.arange(3), SE3: np.r_[3:6, 0:3]}


def _gtsam_poses(gtsam: Any, x: LieGroup) -> list[Any]:
    m = x.as_matrix()
    if type(x) is SE3:
        return [gtsam.Pose3(p) for p in m]
    xyt = np.stack([m[:, 0, 2], m[:, 1, 2], np.arctan2(m[:, 1, 0], m[:, 0, 0])], axis=1)
    return [gtsam.Pose2(*p) for p in xyt.tolist()]


def gtsam_problem(gtsam: Any, graph: PoseGraph, x0: LieGroup) -> tuple[Any, Any]:
    """The factor graph whose error is ``graph.cost(x, "geodesic")`` (plus a constrained prior
    holding the anchor at ``x0``) and the initial values, keys ``0..n-1``."""
    bad = costs.indefinite_edges(graph.information)
    if bad.size:
        raise costs.IndefiniteInformationError(
            f"{graph.name}: GTSAM needs positive definite information matrices; not so on {graph.edge_names(bad[:10])}"
        )
    order = _GTSAM_ORDER[graph.group]
    information = graph.information[:, order][:, :, order]
    between = gtsam.BetweenFactorPose3 if graph.group is SE3 else gtsam.BetweenFactorPose2
    prior = gtsam.PriorFactorPose3 if graph.group is SE3 else gtsam.PriorFactorPose2
    gaussian = gtsam.noiseModel.Gaussian.Information
    # One Python call per factor and per pose: GTSAM's API has no batched constructor. This
    # happens before the timed region.
    factors = gtsam.NonlinearFactorGraph()
    measured = _gtsam_poses(gtsam, graph.measurements)
    for (i, j), z, omega in zip(graph.edges.tolist(), measured, information, strict=True):
        factors.add(between(i, j, z, gaussian(omega)))
    poses = _gtsam_poses(gtsam, x0)
    factors.add(prior(graph.anchor, poses[graph.anchor], gtsam.noiseModel.Constrained.All(graph.group.dim)))
    values = gtsam.Values()
    for key, pose in enumerate(poses):
        values.insert(key, pose)
    return factors, values


def from_gtsam(gtsam: Any, group: type[LieGroup], values: Any) -> LieGroup:
    """Poses of keys ``0..n-1`` (``Values`` iterate in key order) as our group, projected."""
    if group is SE3:
        a = gtsam.utilities.extractPose3(values)  # (n, 12): R row by row, then t
        return SE3.from_rotation_translation(SO3.from_matrix(a[:, :9].reshape(-1, 3, 3), project=True), a[:, 9:])
    a = gtsam.utilities.extractPose2(values)  # (n, 3): x, y, θ
    return SE2.from_rotation_translation(SO2.from_angle(a[:, 2]), a[:, :2])


def _gtsam(
    name: str, graph: PoseGraph, x0: LieGroup, *, max_iterations: int, rel_cost_decrease: float, max_time: float,
    **_: Any,
) -> PeerRun:
    gtsam = _import(name)
    factors, values = gtsam_problem(gtsam, graph, x0)
    lm = name == "gtsam-lm"
    params = gtsam.LevenbergMarquardtParams() if lm else gtsam.DoglegParams()
    params.setRelativeErrorTol(rel_cost_decrease)
    params.setMaxIterations(max_iterations)
    make = gtsam.LevenbergMarquardtOptimizer if lm else gtsam.DoglegOptimizer

    # NonlinearOptimizer::defaultOptimize, stepped by hand to time each iteration; with
    # max_time = inf it stops where optimize() would.
    start = time.perf_counter()
    optimizer = make(factors, values, params)
    new = optimizer.error()
    history_cost, history_time = [new], [time.perf_counter() - start]
    converged = new <= params.getErrorTol()
    status = "converged" if converged else "max_iterations"
    while not converged and optimizer.iterations() < max_iterations:
        current = new
        optimizer.iterate()
        new = optimizer.error()
        history_cost.append(new)
        history_time.append(time.perf_counter() - start)
        converged = gtsam.checkConvergence(params, current, new)
        if converged:
            status = "converged"
        elif not math.isfinite(current):
            status = "diverged"
            break
        elif history_time[-1] >= max_time:
            status = "max_time"
            break
    seconds = time.perf_counter() - start
    x = from_gtsam(gtsam, graph.group, optimizer.values())
    return PeerRun(x, int(optimizer.iterations()), seconds, status, bool(converged), history_cost, history_time)


# ---- pymanopt ---------------------------------------------------------------------------


def _chordal_rotations(spec: MeasurementGraph) -> tuple[Any, Any, Any]:
    """``(cost, egrad, ehess)`` of ``f(R) = Σ κ‖R_j − R_i R̃‖_F² = tr(X Q Xᵀ)`` on stacked rotations
    ``(n, d, d)``, ``Q`` the connection Laplacian (:func:`~manopt_lie.problems.costs.chordal_quadratic_form`):
    ``∇f = 2XQ``, and ``f`` is quadratic, so ``∇²f[U] = 2UQ``."""
    q = costs.chordal_quadratic_form(spec.n, spec.edges, spec.measurements, spec.chordal_weights())

    def egrad(r: np.ndarray) -> np.ndarray:
        return costs.quadratic_form_gradient(q, r)

    def cost(r: np.ndarray) -> float:
        return 0.5 * float(np.sum(r * egrad(r)))

    def ehess(r: np.ndarray, u: np.ndarray) -> np.ndarray:
        return egrad(u)

    return cost, egrad, ehess


def _pymanopt_tr(
    name: str, spec: MeasurementGraph, x0: LieGroup, *, max_iterations: int, grad_rtol: float, max_time: float,
    **_: Any,
) -> PeerRun:
    pymanopt = _import(name)
    cost, egrad, ehess = _chordal_rotations(spec)
    manifold = pymanopt.manifolds.SpecialOrthogonalGroup(spec.d, k=spec.n)
    r0 = np.array(x0.as_matrix(), dtype=np.float64)
    g0 = float(manifold.norm(r0, manifold.euclidean_to_riemannian_gradient(r0, egrad(r0))))

    # pymanopt 2.2's TrustRegions logs nothing (log_verbosity is ignored), so the history is
    # recorded here: it evaluates the gradient at x₀ and after each accepted step, each time
    # right after the cost at the same point, and tests its stopping rule once per iteration.
    # The cache also spares the Euclidean gradient that pymanopt would recompute for every
    # Hessian-vector product.
    last: dict[str, Any] = {"point": None, "cost": math.nan, "grad_point": None, "grad": None}
    history_cost: list[float] = []
    history_time: list[float] = []
    start = 0.0

    @pymanopt.function.numpy(manifold)
    def p_cost(r: np.ndarray) -> float:
        last["point"], last["cost"] = r, cost(r)
        return float(last["cost"])

    @pymanopt.function.numpy(manifold)
    def p_grad(r: np.ndarray) -> np.ndarray:
        last["current"] = last["cost"] if r is last["point"] else cost(r)
        last["grad_point"], last["grad"] = r, egrad(r)
        if not history_cost:
            history_cost.append(last["current"])
            history_time.append(time.perf_counter() - start)
        return manifold.euclidean_to_riemannian_gradient(r, last["grad"])

    @pymanopt.function.numpy(manifold)
    def p_hess(r: np.ndarray, omega: np.ndarray) -> np.ndarray:
        g = last["grad"] if r is last["grad_point"] else egrad(r)
        return manifold.euclidean_to_riemannian_hessian(r, g, ehess(r, r @ omega), omega)

    base: Any = pymanopt.optimizers.TrustRegions

    class TrustRegions(base):
        def _check_stopping_criterion(self, **kwargs: Any) -> Any:
            history_cost.append(last["current"])
            history_time.append(time.perf_counter() - start)
            return super()._check_stopping_criterion(**kwargs)

    problem = pymanopt.Problem(manifold, p_cost, riemannian_gradient=p_grad, riemannian_hessian=p_hess)
    optimizer = TrustRegions(
        max_iterations=max_iterations, min_gradient_norm=grad_rtol * g0, max_time=max_time, verbosity=0
    )
    start = time.perf_counter()
    result = optimizer.run(problem, initial_point=r0)
    seconds = time.perf_counter() - start
    labels = {"grad norm": "converged", "max iterations": "max_iterations", "max time": "max_time"}
    status = next(
        (label for key, label in labels.items() if key in result.stopping_criterion), result.stopping_criterion
    )
    x = spec.group.from_matrix(result.point, project=True)
    return PeerRun(x, int(result.iterations), seconds, status, status == "converged", history_cost, history_time)


_RUNS: dict[str, Any] = {"gtsam": _gtsam, "pymanopt": _pymanopt_tr}
