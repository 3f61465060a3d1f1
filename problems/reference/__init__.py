"""Reference solutions: pose graphs and rotation averaging as CasADi NLPs solved by IPOPT.

An independent check of our Riemannian optimizers: the costs of CONVENTIONS §8 are
written a second time, symbolically, in ambient coordinates with the group constraints
as equalities, and handed to a general-purpose solver — IPOPT with MUMPS, as shipped in
CasADi's wheel — with the exact Hessian of the Lagrangian. Without bounds or
inequalities IPOPT has no barrier term: it takes Newton steps on the KKT system,
regularized when the reduced Hessian is not positive definite, with a filter line search.

Rotation parametrizations (translations are plain ``t ∈ Rᵈ``):

``"quaternion"``
    A unit quaternion ``q = (x, y, z, w)`` in 3-D, a unit complex number ``(cos θ, sin θ)``
    in 2-D, with the one constraint ``‖q‖² = 1``. Rotation matrices are the homogeneous
    quadratic ``R(q) = (w² − ‖v‖²)I + 2vvᵀ + 2w[v]×`` (linear ``[[c, −s], [s, c]]`` in
    2-D): the chordal cost stays quadratic in 2-D, quartic in 3-D. The geodesic residual
    comes from the product ``q_e = q̃* ⊗ q_i* ⊗ q_j`` as ``θ = 2 sign(w) atan2(‖v‖, |w|) v/‖v‖``
    (2-D: ``θ = atan2(Im z_e, Re z_e)``), which ignores the scale of ``q`` and the sign
    ambiguity ``q ~ −q``; translations go through ``R(q)``. ``4 + d`` (``2 + d``) variables
    and one constraint per pose.
``"matrix"``
    The ``d²`` entries of ``R`` with the ``d(d+1)/2`` constraints ``RᵀR = I`` (upper
    triangle): ``d² + d`` variables per pose, a KKT system about twice as large, but the
    chordal cost stays quadratic. ``det R = +1`` is not a constraint: ``O(d)`` has two
    components, ``x0`` lies on ``SO(d)`` and IPOPT's iterates, kept near feasibility by its
    filter, do not jump to the other one (whose nearest point is at Frobenius distance 2);
    should a rotation end with ``det R < 0`` anyway, the result is flagged as a failure.
    The geodesic residual uses ``a = vee(R − Rᵀ)/2``, ``c = (tr R − 1)/2`` and
    ``θ = atan2(‖a‖, c) a/‖a‖`` (2-D: ``θ = atan2(R₁₀ − R₀₁, R₀₀ + R₁₁)``).
``"auto"`` (default)
    ``"matrix"`` for a pose graph with a robust loss, else ``"quaternion"``. Measured
    (``docs/_casadi_reference.md``): without a robust loss both converge in the same number
    of iterations and the quaternions are 1.3–5x faster (a smaller KKT system); on robust
    pose graphs, which are non-convex far from the optimum, IPOPT failed on 4 of 18 3-D
    instances with quaternions (iteration limit, divergence) and none with matrices, and
    needed about half the iterations with matrices.

Every ``x/sin x``-like coefficient comes from :mod:`manopt_lie.lie._series` (the one source the
numpy kernels and the CasADi twins share): its Taylor series below a threshold and the closed
form, on a *safe* argument, above it (CasADi's ``if_else`` zeroes the unused branch, but a
``0·∞`` inside it would still poison reverse-mode derivatives), so the objective has finite
first and second derivatives at zero residual. Residual rotations by exactly ``π`` (the cut
locus, where ``Log`` itself is not differentiable) are not handled.

The gauge is fixed by removing the anchor (``graph.anchor``) from the variables, at its
value in ``x0``. The NLP is the same for every
:class:`~manopt_lie.problems.graph.MeasurementGraph`: translations appear exactly when the
graph's group has them (``graph.has_translations``).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal

import casadi as ca
import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from manopt_lie.casadi.lie import half_cot, jinv_coef
from manopt_lie.errors import ShapeError
from manopt_lie.lie._matrix import assemble
from manopt_lie.lie.base import LieGroup
from manopt_lie.optim.losses import RobustLoss, Trivial, parse_loss

from .. import costs
from ..graph import MeasurementGraph
from ..pose_graph import PoseGraph
from ..rotation_averaging import RotationAveraging
from .rotations import _cross, _rho, _Rotations, rotations

__all__ = ["KINDS", "PARAMETRIZATIONS", "ReferenceNLP", "ReferenceResult", "build_nlp", "reference_solve"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
Parametrization = Literal["auto", "quaternion", "matrix"]
PARAMETRIZATIONS = ("auto", "quaternion", "matrix")
"""How the NLP parametrizes rotations: unit quaternions, or matrices with ``RᵀR = I``
as constraints; ``"auto"`` chooses per problem."""
COSTS = ("chordal", "geodesic")
KINDS = (PoseGraph.kind, RotationAveraging.kind)
"""The problem kinds the reference solves (the measurement graphs of one group)."""

DEFAULT_IPOPT_OPTIONS: dict[str, Any] = {
    "hessian_approximation": "exact",
    "linear_solver": "mumps",
    "tol": 1e-10,
    "acceptable_tol": 1e-8,
    "max_iter": 1000,
    "print_level": 0,
    "sb": "yes",
}
"""IPOPT's settings unless ``options`` overrides them; ``tol`` bounds its scaled KKT error
(IPOPT scales the objective down when its gradient exceeds 100 at ``x0``)."""

SUCCESS = ("Solve_Succeeded", "Solved_To_Acceptable_Level")


@dataclass(frozen=True)
class ReferenceResult:
    """What :func:`reference_solve` returns.

    Attributes
    ----------
    x : group element, batch ``(n,)``
        IPOPT's solution projected exactly onto the group (nearest rotation / normalized
        quaternion); the anchor equals its value in ``x0``.
    fun : float
        Our cost at ``x``: ``spec.cost(x, cost)``, or ``spec.problem(cost, robust=…).cost(x)``
        ``= ½ Σ ρ(s_e)`` with a robust loss.
    objective : float
        IPOPT's objective at its own (unprojected) solution.
    status : str
        IPOPT's return status, e.g. ``"Solve_Succeeded"``.
    success : bool
        ``status`` is ``Solve_Succeeded`` or ``Solved_To_Acceptable_Level``, and (matrix
        parametrization) no rotation converged to a reflection.
    time : float
        Wall time of the IPOPT run (seconds), excluding :attr:`build_time`.
    iterations : int
        IPOPT's iteration count.
    build_time : float
        Building the symbolic NLP and IPOPT's derivative functions (seconds).
    constraint_violation : float
        ``max |g(v)|`` of the group constraints at IPOPT's solution.
    parametrization : str
        The rotation parametrization used, ``"quaternion"`` or ``"matrix"``.
    message : str
        Empty, or what made ``success`` false besides ``status``.
    """

    x: LieGroup
    fun: float
    objective: float
    status: str
    success: bool
    time: float
    iterations: int
    build_time: float
    constraint_violation: float
    parametrization: str
    message: str = ""


def _resolve(parametrization: str, spec: MeasurementGraph, loss: RobustLoss) -> str:
    """``"auto"`` → ``"matrix"`` for robust costs with translations, else ``"quaternion"`` (module doc)."""
    if parametrization not in PARAMETRIZATIONS:
        raise ValueError(f"reference_solve: parametrization must be one of {PARAMETRIZATIONS}, got {parametrization!r}")
    if parametrization == "auto":
        return "matrix" if spec.has_translations and not isinstance(loss, Trivial) else "quaternion"
    return parametrization


# ---- the symbolic NLP -----------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class ReferenceNLP:
    """The NLP ``min f(v) s.t. g(v) = 0`` of one instance, with its derivatives, before it is solved.

    ``v`` stacks ``size`` numbers per free pose (rotation parameters, then the translation),
    pose by pose; the anchor is a constant.

    Attributes
    ----------
    nlp : dict
        ``{"x": v, "f": f, "g": g}`` (CasADi ``MX``), the input of ``casadi.nlpsol``.
    options : dict
        ``casadi.nlpsol`` options supplying the assembled derivatives ``grad_f``, ``jac_g``
        and ``hess_lag`` (so CasADi differentiates one edge, not the whole graph).
    objective, constraints : casadi.Function
        ``v ↦ f(v)`` and ``v ↦ g(v)``.
    pack : callable
        Group element, batch ``(n,)`` ↦ ``v`` (the anchor is dropped).
    unpack : callable
        ``v`` ↦ ``(group element, number of reflections)``, projected onto the group.
    parametrization : str
        ``"quaternion"`` or ``"matrix"`` (``"auto"`` resolved).
    """

    nlp: dict[str, Any]
    options: dict[str, ca.Function]
    objective: ca.Function
    constraints: ca.Function
    pack: Callable[[LieGroup], FloatArray]
    unpack: Callable[[FloatArray], tuple[LieGroup, int]]
    parametrization: str


def _check(spec: Any, x0: Any, cost: str) -> None:
    if not isinstance(spec, MeasurementGraph):
        raise TypeError(f"reference_solve: spec must be a MeasurementGraph, got {type(spec).__name__}")
    if cost not in COSTS:
        raise ValueError(f"reference_solve: cost must be one of {COSTS}, got {cost!r}")
    if not isinstance(x0, spec.group):
        raise ValueError(
            f"reference_solve: x0 must be a {spec.group.__name__} element (batch ({spec.n},)), got {type(x0).__name__}"
        )
    if x0.batch_shape != (spec.n,):
        raise ShapeError(f"reference_solve: x0 must have batch shape ({spec.n},), got {x0.batch_shape}")


def _edge_data(spec: MeasurementGraph, cost: str, rot: _Rotations, loss: RobustLoss) -> FloatArray:
    """Per-edge numbers ``(m, k)``: ``R̃`` (column-major), the rotation's own parameters, then
    ``t̃`` (with translations) and the weights (``κ`` and ``τ`` for chordal, ``vec Ω`` for geodesic)."""
    d, z = spec.d, spec.measurements.as_matrix()
    parts = [np.swapaxes(z[:, :d, :d], 1, 2).reshape(spec.m, -1), rot.pack(z[:, :d, :d])]
    if spec.has_translations:
        parts.append(z[:, :d, d])
    if cost == "chordal":
        spec.chordal_weights()  # raises, naming the edges, unless κ, τ > 0
        kappa, tau = spec.chordal_parameters()
        parts += [kappa[:, None]] + ([] if tau is None else [tau[:, None]])
    else:
        bad = costs.indefinite_edges(spec.information)
        if bad.size and not isinstance(loss, Trivial):
            raise costs.IndefiniteInformationError(
                f"{spec.name}: a robust loss needs positive definite information matrices; "
                f"not so on edges {spec.edge_names(bad[:10])}"
            )
        parts.append(spec.information.reshape(spec.m, -1))
    return np.concatenate(parts, axis=1)


def _edge_function(spec: MeasurementGraph, cost: str, rot: _Rotations, loss: RobustLoss) -> ca.Function:
    """``(x_i, x_j, p_e) ↦ ½ ρ(s_e)`` for one edge (``ρ(s) = s`` without a robust loss)."""
    d, translations, k_tan = spec.d, spec.has_translations, spec.group.dim
    k = rot.size + (d if translations else 0)
    weights = (2 if translations else 1) if cost == "chordal" else k_tan * k_tan
    p = ca.SX.sym("p", d * d + rot.size + (d if translations else 0) + weights)
    xi, xj = ca.SX.sym("xi", k), ca.SX.sym("xj", k)
    z_rot = ca.reshape(p[: d * d], d, d)
    z_par = p[d * d : d * d + rot.size]
    rest = p[d * d + rot.size :]
    ri, rj = xi[: rot.size], xj[: rot.size]
    if cost == "chordal":
        mi, mj = rot.matrix(ri), rot.matrix(rj)
        s = 2.0 * rest[-weights] * ca.sumsqr(mj - mi @ z_rot)  # κ‖R_j − R_i R̃‖²
        if translations:
            z_t, tau = rest[:d], rest[d + 1]
            s += 2.0 * tau * ca.sumsqr(xj[rot.size :] - xi[rot.size :] - mi @ z_t)
    else:
        theta2, theta = rot.residual(ri, rj, z_par, z_rot)
        r = theta
        if translations:
            # t_e = R̃ᵀ (R_iᵀ (t_j − t_i) − t̃), ρ = V(θ)⁻¹ t_e (SE(2)) or Jl(θ)⁻¹ t_e (SE(3)).
            t = z_rot.T @ (rot.matrix(ri).T @ (xj[rot.size :] - xi[rot.size :]) - rest[:d])
            if d == 2:
                a, b = half_cot(theta2, theta), 0.5 * theta
                rho = ca.vertcat(a * t[0] + b * t[1], a * t[1] - b * t[0])
            else:
                wt = _cross(theta, t)
                rho = t - 0.5 * wt + jinv_coef(theta2) * _cross(theta, wt)
            r = ca.vertcat(rho, theta)
        omega = ca.reshape(rest[-weights:], k_tan, k_tan)
        s = r.T @ omega @ r
    return ca.Function("edge", [xi, xj, p], [0.5 * _rho(loss, s)])


def _scatter(rows: IntArray, cols: IntArray, src: IntArray, shape: tuple[int, int], n_src: int) -> tuple[Any, Any]:
    """The sparsity of the sum of entries ``src[t]`` placed at ``(rows[t], cols[t])`` and the 0/1
    matrix ``S`` with ``nonzeros = S @ entries`` (CasADi's column-major nonzero order)."""
    key = cols.astype(np.int64) * shape[0] + rows
    unique, nz = np.unique(key, return_inverse=True)
    sparsity = ca.Sparsity.triplet(shape[0], shape[1], (unique % shape[0]).tolist(), (unique // shape[0]).tolist())
    s = sp.csc_matrix((np.ones(len(src)), (nz.reshape(-1), src)), shape=(len(unique), n_src))
    s.sort_indices()
    pattern = ca.Sparsity(s.shape[0], s.shape[1], s.indptr.tolist(), s.indices.tolist())
    return sparsity, ca.DM(pattern, s.data)  # ca.DM(scipy matrix) is ~20x slower


def _triplets(matrix: Any) -> tuple[IntArray, IntArray]:
    """Row and column of each structural nonzero of an ``SX`` matrix, in ``nonzeros()`` order."""
    r, c = matrix.sparsity().get_triplet()
    return np.asarray(r, dtype=np.int64), np.asarray(c, dtype=np.int64)


def build_nlp(
    spec: MeasurementGraph,
    x0: LieGroup,
    *,
    cost: str = "chordal",
    robust: RobustLoss | str | None = None,
    parametrization: Parametrization = "auto",
) -> ReferenceNLP:
    """The symbolic NLP that :func:`reference_solve` solves (see there for the arguments).

    One edge's cost, gradient and Hessian (and one pose's constraints with theirs) are
    ``SX`` functions, differentiated once and ``map``-ped over the edges (poses) in an
    ``MX`` graph; the global gradient, Jacobian and upper triangle of the Hessian of the
    Lagrangian are their sums, ``S @ entries`` with constant 0/1 matrices ``S``. Building
    is linear in the size of the graph.
    """
    _check(spec, x0, cost)
    loss = parse_loss(robust)
    parametrization = _resolve(parametrization, spec, loss)  # type: ignore[assignment]
    rot = rotations(parametrization, spec.d)
    poses, anchor = spec.has_translations, spec.anchor
    d, n, m = spec.d, spec.n, spec.m
    k, c = rot.size + (d if poses else 0), rot.n_constraints
    nv, ng = k * (n - 1), c * (n - 1)

    def pack_all(x: LieGroup) -> FloatArray:
        mat = x.as_matrix()
        return np.concatenate([rot.pack(mat[:, :d, :d])] + ([mat[:, :d, d]] if poses else []), axis=1)  # (n, k)

    fixed, x0_matrix = pack_all(x0)[anchor], x0.as_matrix()[anchor]
    # Variable index of component a of pose p: k·col(p) + a, col skipping the anchor; -1 for the anchor.
    col = np.arange(n) - (np.arange(n) > anchor)
    col[anchor] = -1

    # One edge: f, ∇f and the nonzeros of ∇²f in (x_i, x_j), mapped over the edges.
    f_edge = _edge_function(spec, cost, rot, loss)
    xi, xj, p = (ca.SX.sym(name, *f_edge.sparsity_in(i).shape) for i, name in enumerate(("xi", "xj", "p")))
    w = ca.vertcat(xi, xj)
    fe = f_edge(xi, xj, p)
    hess_e = ca.triu(ca.hessian(fe, w)[0])
    he_rows, he_cols = _triplets(hess_e)
    grad_edge = ca.Function("grad_edge", [xi, xj, p], [ca.gradient(fe, w)]).map(m)
    hess_edge = ca.Function("hess_edge", [xi, xj, p], [hess_e.nz[:]]).map(m)
    f_edge = f_edge.map(m)

    # One pose: g, its Jacobian, and the nonzeros of ∇²(λᵀg), mapped over the free poses.
    r, lam = ca.SX.sym("r", k), ca.SX.sym("lam", c)
    gp = rot.constraints(r[: rot.size])
    jac_p, hess_p = ca.jacobian(gp, r), ca.triu(ca.hessian(ca.dot(lam, gp), r)[0])
    jp_rows, jp_cols = _triplets(jac_p)
    hp_rows, hp_cols = _triplets(hess_p)
    g_pose = ca.Function("g_pose", [r], [gp]).map(n - 1)
    jac_pose = ca.Function("jac_pose", [r], [jac_p.nz[:]]).map(n - 1)
    hess_pose = ca.Function("hess_pose", [r, lam], [hess_p.nz[:]]).map(n - 1)

    v = ca.MX.sym("v", nv)
    vm = ca.reshape(v, k, n - 1)
    x_all = ca.horzcat(vm[:, :anchor], ca.DM(fixed), vm[:, anchor:])
    args = (
        x_all[:, spec.edges[:, 0].tolist()],
        x_all[:, spec.edges[:, 1].tolist()],
        ca.DM(np.ascontiguousarray(_edge_data(spec, cost, rot, loss).T)),
    )
    f = ca.sum2(f_edge(*args))
    g = ca.vec(g_pose(vm))

    # Global index of each local variable of each edge: (m, 2k), -1 at the anchor.
    local = np.arange(2 * k)
    gidx = col[spec.edges[:, local // k]] * k + local % k
    gidx[col[spec.edges[:, local // k]] < 0] = -1
    e_index = np.arange(m)[:, None]

    ok = gidx >= 0
    grad_sp, grad_s = _scatter(
        gidx[ok], np.zeros(int(ok.sum()), np.int64), (e_index * 2 * k + local)[ok], (nv, 1), 2 * k * m
    )
    grad = ca.MX(grad_sp, ca.mtimes(grad_s, ca.vec(grad_edge(*args))))

    q = np.arange(n - 1)[:, None]
    jac_sp, jac_s = _scatter(
        (q * c + jp_rows).ravel(),
        (q * k + jp_cols).ravel(),
        np.arange((n - 1) * len(jp_rows)),
        (ng, nv),
        (n - 1) * len(jp_rows),
    )
    jac = ca.MX(jac_sp, ca.mtimes(jac_s, ca.vec(jac_pose(vm))))

    hi, hj = gidx[:, he_rows], gidx[:, he_cols]
    row_e, col_e = np.minimum(hi, hj), np.maximum(hi, hj)  # the upper triangle
    keep = (hi >= 0) & (hj >= 0)
    n_he = m * len(he_rows)
    src_e = (e_index * len(he_rows) + np.arange(len(he_rows)))[keep]
    row_p, col_p = (q * k + hp_rows).ravel(), (q * k + hp_cols).ravel()
    hess_sp, hess_s = _scatter(
        np.concatenate([row_e[keep], row_p]),
        np.concatenate([col_e[keep], col_p]),
        np.concatenate([src_e, n_he + np.arange(len(row_p))]),
        (nv, nv),
        n_he + len(row_p),
    )
    lam_f, lam_g, par = ca.MX.sym("lam_f"), ca.MX.sym("lam_g", ng), ca.MX.sym("p", 0, 1)
    entries = ca.vertcat(lam_f * ca.vec(hess_edge(*args)), ca.vec(hess_pose(vm, ca.reshape(lam_g, c, n - 1))))
    hess = ca.MX(hess_sp, ca.mtimes(hess_s, entries))

    def pack(x: LieGroup) -> FloatArray:
        return np.delete(pack_all(x), anchor, axis=0).reshape(-1)

    def unpack(values: FloatArray) -> tuple[LieGroup, int]:
        cols = np.insert(np.asarray(values, dtype=np.float64).reshape(n - 1, k), anchor, fixed, axis=0)
        r_mat, reflections = rot.unpack(cols[:, : rot.size])
        mats = assemble(r_mat, cols[:, rot.size :]) if poses else np.array(r_mat)
        mats[anchor] = x0_matrix  # exactly, not through the parametrization
        return spec.group.from_matrix(mats), reflections

    return ReferenceNLP(
        nlp={"x": v, "f": f, "g": g},
        options={
            "grad_f": ca.Function("grad_f", [v, par], [f, grad]),
            "jac_g": ca.Function("jac_g", [v, par], [g, jac]),
            "hess_lag": ca.Function("hess_lag", [v, par, lam_f, lam_g], [hess]),
        },
        objective=ca.Function("f", [v], [f]),
        constraints=ca.Function("g", [v], [g]),
        pack=pack,
        unpack=unpack,
        parametrization=parametrization,
    )


def reference_solve(
    spec: MeasurementGraph,
    x0: LieGroup,
    *,
    cost: str = "chordal",
    robust: RobustLoss | str | None = None,
    parametrization: Parametrization = "auto",
    options: dict[str, Any] | None = None,
) -> ReferenceResult:
    """Minimize a pose-graph or rotation-averaging cost with IPOPT, as a reference.

    Solves ``min_v ½ Σ_e ρ(s_e(v))  s.t.  g(v) = 0`` with ``v`` the poses' rotation
    parameters and translations (the anchor held at its value in ``x0``), ``g`` the
    group constraints (``‖q‖² = 1``, or ``RᵀR = I``) and, per edge,

    - chordal (SE-Sync): ``s_e = 2 (κ‖R_j − R_i R̃‖_F² + τ‖t_j − t_i − R_i t̃‖²)``
      (rotation averaging: ``s_e = 2κ‖R_j − R_i R̃‖_F²``), so that ``½ρ(s) = s/2`` is the
      chordal term of CONVENTIONS §8, as in :func:`problems.costs.chordal_factor`;
    - geodesic: ``s_e = r_eᵀ Ω_e r_e``, ``r_e = Log(Z_e⁻¹ X_i⁻¹ X_j) = (V(θ)⁻¹ t_e, θ)``
      exactly as in §3 (rotation averaging: ``s_e = κ θ²``).

    Parameters
    ----------
    spec : MeasurementGraph
        A pose graph or a rotation-averaging instance.
    x0 : group element, batch ``(n,)``
        The starting point (e.g. ``spec.chordal_initialization()``); also fixes the gauge.
    cost : {"chordal", "geodesic"}
    robust : RobustLoss or str, optional
        A loss ``ρ`` on each ``s_e`` (:func:`manopt_lie.optim.losses.parse_loss`).
    parametrization : {"auto", "quaternion", "matrix"}
        Unit quaternions (complex numbers in 2-D) with ``‖q‖² = 1``, or matrices with
        ``RᵀR = I``; ``"auto"`` takes matrices for robust pose graphs, quaternions
        otherwise (module doc).
    options : dict, optional
        IPOPT options overriding :data:`DEFAULT_IPOPT_OPTIONS` (IPOPT's names, e.g.
        ``{"tol": 1e-8, "max_iter": 100, "print_level": 5}``).

    Returns
    -------
    ReferenceResult

    Raises
    ------
    ValueError
        Unknown ``cost``, ``parametrization`` or loss; ``x0`` not of ``spec.group``
        (:class:`~manopt_lie.errors.ShapeError` for a wrong batch shape);
        :class:`~problems.costs.IndefiniteInformationError` for weights the cost cannot use.
    TypeError
        ``spec`` is not a :class:`~manopt_lie.problems.graph.MeasurementGraph`.
    """
    t0 = time.perf_counter()
    problem = build_nlp(spec, x0, cost=cost, robust=robust, parametrization=parametrization)
    ipopt = DEFAULT_IPOPT_OPTIONS | dict(options or {})
    solver = ca.nlpsol("reference", "ipopt", problem.nlp, problem.options | {"ipopt": ipopt, "print_time": False})
    build_time = time.perf_counter() - t0

    t0 = time.perf_counter()
    sol = solver(x0=problem.pack(x0), lbg=0.0, ubg=0.0)
    seconds = time.perf_counter() - t0
    stats = solver.stats()
    values = np.asarray(sol["x"], dtype=np.float64).reshape(-1)
    status = str(stats["return_status"])
    if np.all(np.isfinite(values)):
        x, reflections = problem.unpack(values)
        message = f"{reflections} rotations converged to reflections (det R < 0)" if reflections else ""
    else:  # nothing to project: hand back the start
        x, reflections, message = x0, 0, "IPOPT returned non-finite values; x is x0"
    fun = spec.cost(x, cost) if robust is None else spec.problem(cost, robust=robust).cost(x)
    g = np.asarray(sol["g"], dtype=np.float64)
    return ReferenceResult(
        x=x,
        fun=float(fun),
        objective=float(sol["f"]),
        status=status,
        success=status in SUCCESS and not message,
        time=seconds,
        iterations=int(stats["iter_count"]),
        build_time=build_time,
        constraint_violation=float(np.max(np.abs(g), initial=0.0)),
        parametrization=problem.parametrization,
        message=message,
    )
