"""Riemannian optimizers on three problems with known optima, against pymanopt.

Run from the repository root::

    python benchmarks/bench_optimizers.py                 # full sizes
    python benchmarks/bench_optimizers.py --quick         # small sizes, one repeat (smoke run)
    python benchmarks/bench_optimizers.py --json out.json
    python benchmarks/bench_optimizers.py --problems rayleigh --optimizers cg,lbfgs --no-casadi

Problems (each from one fixed starting point, shared by every optimizer):

* **karcher**: ``½ Σᵢ |Rᵢ ⊖ R|²`` over 10⁵ rotations ``R̄ Exp(±τₖ)`` on
  ``LieGroupManifold(SO3)``; symmetric about ``R̄``, so the optimum is
  ``½ Σ |τᵢ|²`` at ``R̄``. Gradient ``−Σ rᵢ``, ``rᵢ = Rᵢ ⊖ R`` (which equals
  ``Σ J_Rᵀ rᵢ``, since ``Jl(r)⁻ᵀ r = r``: no Jacobians needed), so a gradient costs
  one cost; no Hessian (the trust region differentiates the gradient numerically).
* **rayleigh**: ``xᵀAx`` on ``Sphere(1000)`` (S⁹⁹⁹), ``A`` random symmetric;
  optimum ``λ_min(A)``.
* **brockett**: ``tr(XᵀAXN)`` on ``Stiefel(1000, 5)``, ``N = diag(5, …, 1)``;
  optimum ``Σ N_ii λ_i`` (ascending eigenvalues).

Every run stops on the same test: the Riemannian gradient norm at most
``1e-6 × ‖grad f(x₀)‖`` (``grad_rtol=1e-6, grad_atol=0``; pymanopt gets
``min_gradient_norm = 1e-6 × ‖grad f(x₀)‖`` in its own metric, which on SO(3)
is the Frobenius norm of the skew matrix, √2 times ours, so the relative test
is the same), or the shared iteration and time caps. The time is the median of
``--repeat`` runs; ``grad_norm`` is always measured in our metric, at the final
point, so both libraries' columns compare.

On Rayleigh and Brockett both libraries evaluate the same NumPy expressions,
written so that no ``n×n`` temporary is formed (``2.0 * (A @ x)``, not
``2 * A @ x = (2A) @ x``).

Both libraries also share ``min_step = 1e-12`` (pymanopt's ``min_step_size``);
pymanopt's cap on cost evaluations is lifted, since ours has none.

pymanopt (numpy backend, hand-written derivatives) runs in the same process
when it is installed; otherwise its rows are skipped with a note. Its
optimizers: ``SteepestDescent``, ``ConjugateGradient(beta_rule="PolakRibiere")``
(ours is set to PR+ as well) and ``TrustRegions``, with default line searches
and radii (ours: Armijo for steepest descent, strong Wolfe for CG). On SO(3) it
uses the polar retraction and a plain-NumPy residual ``Log(RᵀRᵢ)``, with the same
gradient ``−Σ rᵢ``, and its trust region gets the same finite-difference Hessian
as ours (pymanopt's numpy backend has none built in). The last table gives the
cost of one evaluation in each library, to tell the optimizers' overhead from
that of the cost functions.

Our problems return the cost and its gradient from one callable (``Problem(…, egrad=True)``
or ``rgrad=True``, SciPy's ``jac=True``), as a user whose cost shares work with its
gradient writes them — the residuals of Karcher, the product ``AX`` of Rayleigh and
Brockett — so the gradient at an accepted point comes with its cost; pymanopt has no such
form and evaluates them apart.

Each run also times the problem's own callbacks (cost, gradient, Hessian products: the
same NumPy code in both libraries); the rest of its time, per iteration, is the optimizer's
*overhead* (retractions, projections, transports, bookkeeping). Our L-BFGS (``lbfgs``, no
pymanopt counterpart) is compared with our CG and pymanopt's in its own table.

**A tiny problem** (``--no-tiny`` skips it): chordal rotation averaging relaxed to
``St(3, 3)²⁰`` (20 rotations, 60 edges, ``Σ ‖Y_j − Y_i R̃_ij‖²_F``, exact Hessian), solved by
both trust regions, where the overhead per iteration is all there is to measure (what a
certification staircase on tens of rotations pays).

**CasADi-derived twins** (``--no-casadi`` skips them): each problem is also built by
``problem_from_casadi`` from its cost alone — the Karcher residual ``½‖Log(RᵀRᵢ)‖²``
as one mapped edge per sample (exact Hessian blocks, so the trust region needs no
finite differences; compiled with ``jit=True`` when ``gcc`` is on the PATH, ``--no-jit``
to interpret), ``xᵀAx`` on the sphere and ``tr(XᵀAXN)`` on the Stiefel manifold as one
expression in ``MX`` symbols (Euclidean gradient and Hessian-vector products, converted
by the manifold; not compiled: the dense ``A`` would be written into the C code).
Our optimizers run on both; the table "CasADi-derived / hand-written" gives the ratio
of times per iteration (goal ≤ 1.5).
"""

from __future__ import annotations

import argparse
import copy
import math
import os
import platform
import shutil
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial, wraps
from typing import Any

import casadi as ca
import numpy as np

from manopt_lie import SO3
from manopt_lie.bench.report import write_json
from manopt_lie.bench.timing import interleaved, median_time
from manopt_lie.casadi import SymSO3, problem_from_casadi
from manopt_lie.manifolds import LieGroupManifold, Power, Sphere, Stiefel
from manopt_lie.optim import ConjugateGradient, GradientDescent, OptimizeResult, Problem, TrustRegion

try:
    from manopt_lie.optim import LBFGS
except ImportError:  # an older manopt_lie (a "before" measurement): its rows are skipped
    LBFGS = None

JIT = shutil.which("gcc") is not None  # the Karcher twin compiled (main() may turn it off)
GRAD_RTOL = 1e-6
MIN_STEP = 1e-12
FD_STEP = 2.0**-14  # the finite-difference step of our TrustRegion, reused for pymanopt's Karcher Hessian

OURS: dict[str, Callable[..., Any]] = {
    "gd": GradientDescent,
    "cg": partial(ConjugateGradient, beta="polak-ribiere"),  # the same rule as pymanopt's below
    "tr": TrustRegion,
    **({"lbfgs": LBFGS} if LBFGS is not None else {}),
}
PYMANOPT = ("gd", "cg", "tr")  # the methods with a pymanopt counterpart


class Clock:
    """Seconds spent in a problem's own callbacks, to tell them from the optimizer's overhead."""

    def __init__(self) -> None:
        self.seconds = 0.0

    def __call__(self, fn: Callable[..., Any]) -> Callable[..., Any]:
        @wraps(fn)  # the signature, which pymanopt's decorators read
        def timed(*args: Any) -> Any:
            start = time.perf_counter()
            try:
                return fn(*args)
            finally:
                self.seconds += time.perf_counter() - start

        return timed


# ---- the problems -----------------------------------------------------------------


Counts = dict[str, int]
"""Evaluation counters of a pymanopt problem (``nfev``, ``ngev``, ``nhev``): pymanopt's own
``cost_evaluations`` counts iterations for its line-search methods."""


@dataclass
class Case:
    """One problem: our formulation, its start, its known optimum and a pymanopt twin."""

    name: str
    title: str
    problem: Problem
    x0: Any
    optimum: float
    make_pymanopt: Callable[[Any, Counts], tuple[Any, Any]]  # (pymanopt module, counters) ↦ (problem, x0)
    from_pymanopt: Callable[[Any], Any]  # a pymanopt point ↦ ours
    make_casadi: Callable[[], Problem]  # the same cost through problem_from_casadi
    clock: Clock  # times the callbacks of ``problem``


def _symmetric(rng: np.random.Generator, n: int) -> np.ndarray:
    a = rng.standard_normal((n, n))
    return (a + a.T) / 2


def _skew(w: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def karcher_case(n: int, rng: np.random.Generator) -> Case:
    mean = SO3.random(rng)
    tau = 0.3 * rng.standard_normal((n // 2, 3))
    tau = np.concatenate([tau, -tau])  # symmetric about the mean: R̄ is the Karcher mean
    samples = mean.rplus(tau)
    assert np.linalg.norm(tau, axis=-1).max() < np.pi  # so that Log(R̄ᵀRᵢ) = τᵢ exactly

    def cost_and_grad(r: SO3) -> tuple[float, np.ndarray]:
        # Σ J_Rᵀ rᵢ with J_R = −Jl(rᵢ)⁻¹ (CONVENTIONS §4) is −Σ rᵢ, since Jl(r)⁻ᵀ r = Jr(r)⁻¹ r = r:
        # no Jacobians needed, and the residuals serve both halves.
        res = samples.rminus(r)
        return 0.5 * float(np.sum(res**2)), -np.sum(res, axis=0)

    x0 = mean.rplus(np.array([0.6, -0.5, 0.4]))
    clock = Clock()
    problem = Problem(LieGroupManifold(SO3), cost=clock(cost_and_grad), rgrad=True)
    mats = samples.as_matrix()

    def make_pymanopt(pymanopt: Any, counts: Counts) -> tuple[Any, Any]:
        # pymanopt's SO(3): points are matrices, tangent vectors skew matrices Ω (the
        # direction R·Ω) with ⟨Ω₁, Ω₂⟩ = tr(Ω₁ᵀΩ₂) = 2 ω₁ᵀω₂. The residuals are written in
        # plain NumPy (rotation-matrix log through atan2), as a pymanopt user would.
        manifold = pymanopt.manifolds.SpecialOrthogonalGroup(3, retraction="polar")

        def residuals(r: np.ndarray) -> np.ndarray:
            m = np.matmul(r.T, mats)  # Rᵀ Rᵢ
            w = 0.5 * np.stack([m[:, 2, 1] - m[:, 1, 2], m[:, 0, 2] - m[:, 2, 0], m[:, 1, 0] - m[:, 0, 1]], -1)
            s = np.linalg.norm(w, axis=-1)
            angle = np.arctan2(s, 0.5 * (np.trace(m, axis1=1, axis2=2) - 1.0))
            return w * np.where(s > 1e-12, angle / np.where(s > 1e-12, s, 1.0), 1.0)[:, None]

        clock = Clock()

        @clock
        def rgrad_skew(r: np.ndarray) -> np.ndarray:
            counts["ngev"] += 1
            # d/dt ½|Log(Exp(−tω)RᵀRᵢ)|² = −rᵢᵀ Jl(rᵢ)⁻¹ ω = −rᵢᵀω, so the coordinate
            # gradient is −Σ rᵢ; halve it for the Frobenius metric of skew matrices.
            return _skew(-0.5 * residuals(r).sum(axis=0))

        @pymanopt.function.numpy(manifold)
        @clock
        def p_cost(r: np.ndarray) -> float:
            counts["nfev"] += 1
            return 0.5 * float(np.sum(residuals(r) ** 2))

        cache: dict[bytes, np.ndarray] = {}

        def cached_grad(r: np.ndarray) -> np.ndarray:
            # One entry: the trust region's Hessian products reuse the gradient at r,
            # as ours do.
            key = r.tobytes()
            if key not in cache:
                cache.clear()
                cache[key] = rgrad_skew(r)
            return cache[key]

        @pymanopt.function.numpy(manifold)
        def p_grad(r: np.ndarray) -> np.ndarray:
            return cached_grad(r)

        @pymanopt.function.numpy(manifold)
        def p_hess(r: np.ndarray, omega: np.ndarray) -> np.ndarray:
            # The difference quotient of the gradient along the retraction, as our
            # TrustRegion does without a Hessian.
            norm = manifold.norm(r, omega)
            if norm == 0.0:
                return np.zeros((3, 3))
            t = FD_STEP / norm
            return (rgrad_skew(manifold.retraction(r, t * omega)) - cached_grad(r)) / t

        p = pymanopt.Problem(manifold, p_cost, riemannian_gradient=p_grad, riemannian_hessian=p_hess)
        counts["clock"] = clock
        return p, x0.as_matrix().copy()

    def make_casadi() -> Problem:
        return problem_from_casadi(
            LieGroupManifold(SO3), lambda r, ri: 0.5 * ca.sumsqr(SymSO3.rminus(ri, r)),
            variables=np.zeros((len(mats), 1), dtype=np.int64), data=(mats,), jit=JIT,
        )  # fmt: skip

    return Case(
        "karcher", f"Karcher mean, SO(3), {n:,} rotations", problem, x0, 0.5 * float(np.sum(tau**2)),
        make_pymanopt, lambda r: SO3.from_matrix(r), make_casadi, clock,
    )  # fmt: skip


def rayleigh_case(n: int, rng: np.random.Generator) -> Case:
    a = _symmetric(rng, n)
    clock = Clock()

    def cost_and_egrad(x: np.ndarray) -> tuple[float, np.ndarray]:
        ax = a @ x  # one product for both halves
        return float(x @ ax), 2.0 * ax

    problem = Problem(Sphere(n), cost=clock(cost_and_egrad), egrad=True, ehess=clock(lambda x, u: 2.0 * (a @ u)))
    x0 = problem.manifold.random_point(rng)

    def make_pymanopt(pymanopt: Any, counts: Counts) -> tuple[Any, Any]:
        manifold, clock = pymanopt.manifolds.Sphere(n), Clock()

        @pymanopt.function.numpy(manifold)
        @clock
        def cost(x: np.ndarray) -> float:
            counts["nfev"] += 1
            return float(x @ a @ x)

        @pymanopt.function.numpy(manifold)
        @clock
        def egrad(x: np.ndarray) -> np.ndarray:
            counts["ngev"] += 1
            return 2.0 * (a @ x)

        @pymanopt.function.numpy(manifold)
        @clock
        def ehess(x: np.ndarray, u: np.ndarray) -> np.ndarray:
            counts["nhev"] += 1
            return 2.0 * (a @ u)

        counts["clock"] = clock
        return pymanopt.Problem(manifold, cost, euclidean_gradient=egrad, euclidean_hessian=ehess), x0.copy()

    return Case(
        "rayleigh", f"Rayleigh quotient, S^{n - 1}", problem, x0, float(np.linalg.eigvalsh(a)[0]),
        make_pymanopt, lambda x: x, lambda: problem_from_casadi(Sphere(n), lambda x: ca.mtimes([x.T, a, x])), clock,
    )  # fmt: skip


def brockett_case(n: int, p: int, rng: np.random.Generator) -> Case:
    a = _symmetric(rng, n)
    big_n = np.diag(np.arange(p, 0, -1.0))
    n2 = 2.0 * big_n
    clock = Clock()

    def cost_and_egrad(x: np.ndarray) -> tuple[float, np.ndarray]:
        axn = (a @ x) @ big_n  # one product for both halves: f = tr(Xᵀ(AXN)), ∇f̄ = 2AXN
        return float(np.sum(x * axn)), 2.0 * axn

    problem = Problem(Stiefel(n, p), cost=clock(cost_and_egrad), egrad=True, ehess=clock(lambda x, u: (a @ u) @ n2))
    x0 = problem.manifold.random_point(rng)
    optimum = float(np.sum(np.linalg.eigvalsh(a)[:p] * np.diag(big_n)))

    def make_pymanopt(pymanopt: Any, counts: Counts) -> tuple[Any, Any]:
        manifold, clock = pymanopt.manifolds.Stiefel(n, p), Clock()

        @pymanopt.function.numpy(manifold)
        @clock
        def cost(x: np.ndarray) -> float:
            counts["nfev"] += 1
            return float(np.trace(x.T @ a @ x @ big_n))

        @pymanopt.function.numpy(manifold)
        @clock
        def egrad(x: np.ndarray) -> np.ndarray:
            counts["ngev"] += 1
            return (a @ x) @ n2

        @pymanopt.function.numpy(manifold)
        @clock
        def ehess(x: np.ndarray, u: np.ndarray) -> np.ndarray:
            counts["nhev"] += 1
            return (a @ u) @ n2

        counts["clock"] = clock
        return pymanopt.Problem(manifold, cost, euclidean_gradient=egrad, euclidean_hessian=ehess), x0.copy()

    def make_casadi() -> Problem:
        return problem_from_casadi(Stiefel(n, p), lambda x: ca.trace(ca.mtimes([x.T, a, x, big_n])))

    return Case(
        "brockett", f"Brockett, St({n}, {p})", problem, x0, optimum, make_pymanopt, lambda x: x, make_casadi, clock
    )


def tiny_case(n: int, rng: np.random.Generator) -> tuple[Problem, np.ndarray, Clock, Callable[..., Any]]:
    """Chordal rotation averaging ``Σ_ij ‖Y_j − Y_i R̃_ij‖²_F`` over ``Y ∈ St(3, 3)ⁿ`` (a ring and
    ``2n`` random chords, noise 0.05 rad), exact Hessian; our problem, its start near the truth,
    its clock, and ``(pymanopt, clock, counts) ↦ (pymanopt problem, x0)``."""
    ring = np.stack([np.arange(n), (np.arange(n) + 1) % n], 1)
    chords = rng.integers(0, n, (2 * n, 2))
    edges = np.concatenate([ring, chords[chords[:, 0] != chords[:, 1]]])
    i, j = edges.T
    truth = SO3.random(rng, (n,)).as_matrix()
    meas = np.swapaxes(truth[i], 1, 2) @ truth[j] @ SO3.exp(0.05 * rng.standard_normal((len(i), 3))).as_matrix()
    meas_t = np.swapaxes(meas, 1, 2)

    def cost(y: np.ndarray) -> float:
        r = y[j] - y[i] @ meas
        return float(np.sum(r * r))

    def egrad(y: np.ndarray) -> np.ndarray:  # linear in y, so also the Hessian applied to a direction
        r = 2.0 * (y[j] - y[i] @ meas)
        g = np.zeros_like(y)
        np.add.at(g, j, r)
        np.add.at(g, i, -(r @ meas_t))
        return g

    x0 = np.linalg.qr(truth + 0.3 * rng.standard_normal(truth.shape))[0]
    clock = Clock()
    problem = Problem(Power(Stiefel(3, 3), n), cost=clock(cost), egrad=clock(egrad), ehess=clock(lambda y, u: egrad(u)))

    def make_pymanopt(pymanopt: Any, clock: Clock, counts: Counts) -> tuple[Any, Any]:
        manifold = pymanopt.manifolds.Stiefel(3, 3, k=n)

        def ehess(y: np.ndarray, u: np.ndarray) -> np.ndarray:
            counts["nhev"] += 1  # pymanopt reports no inner iterations: count the products
            return egrad(u)

        p_cost = pymanopt.function.numpy(manifold)(clock(cost))
        p_grad = pymanopt.function.numpy(manifold)(clock(egrad))
        p_hess = pymanopt.function.numpy(manifold)(clock(ehess))
        return pymanopt.Problem(manifold, p_cost, euclidean_gradient=p_grad, euclidean_hessian=p_hess), x0.copy()

    return problem, x0, clock, make_pymanopt


def tiny_rows(pymanopt: Any, repeat: int, rng: np.random.Generator) -> list[dict[str, Any]]:
    """Both trust regions on :func:`tiny_case` (20 rotations): time per iteration and the
    optimizer's overhead per *step* (outer iteration or Hessian product, i.e. inner iteration)."""
    problem, x0, clock, make_pymanopt = tiny_case(20, rng)
    g0 = float(np.linalg.norm(problem.grad(x0)))
    ours = TrustRegion(grad_rtol=1e-8, grad_atol=0.0, max_iterations=500)

    def run_ours() -> Any:
        clock.seconds = 0.0
        return ours.solve(problem, x0), clock.seconds

    jobs, names = [run_ours], ["manopt_lie"]
    if pymanopt is not None:
        p_clock, counts = Clock(), {"nhev": 0}
        p_problem, p_x0 = make_pymanopt(pymanopt, p_clock, counts)
        opt = pymanopt.optimizers.TrustRegions(
            max_iterations=500, min_gradient_norm=1e-8 * g0, verbosity=0, log_verbosity=0
        )

        def run_theirs() -> Any:
            p_clock.seconds, counts["nhev"] = 0.0, 0
            return opt.run(p_problem, initial_point=p_x0), p_clock.seconds, counts["nhev"]

        jobs.append(run_theirs)
        names.append("pymanopt")
    rows = []
    for name, outcome in zip(names, interleaved(jobs, repeat), strict=True):
        if isinstance(outcome, BaseException):
            rows.append({"library": name, "status": f"error: {outcome}"[:120]})
            continue
        seconds, out = outcome
        if name == "manopt_lie":
            res, callbacks = out
            nit, nhev, fun = res.nit, res.nhev, res.fun
        else:
            res, callbacks, nhev = out
            nit, fun = res.iterations, problem.cost(res.point)
        steps = max(nit + nhev, 1)
        rows.append({
            "library": name, "nit": nit, "nhev": nhev, "time_ms": 1e3 * seconds, "callbacks_ms": 1e3 * callbacks,
            "ms_per_iteration": 1e3 * seconds / max(nit, 1),
            "overhead_us_per_step": 1e6 * max(seconds - callbacks, 0.0) / steps, "fun": fun,
        })  # fmt: skip
    return rows


# ---- running ----------------------------------------------------------------------


@dataclass
class Timed:
    """A run to time repeatedly, and how to turn its median time and last result into a row."""

    run: Callable[[], Any]
    row: Callable[[float, Any], dict[str, Any]]


def time_interleaved(jobs: list[Timed], repeat: int) -> list[dict[str, Any]]:
    """:func:`~manopt_lie.bench.timing.interleaved` over the jobs, each outcome turned into its row
    (a job that raised, or whose row raises, is reported, not fatal)."""
    rows = []
    for job, outcome in zip(jobs, interleaved([job.run for job in jobs], repeat), strict=True):
        try:
            if isinstance(outcome, BaseException):
                raise outcome
            rows.append(job.row(*outcome))
        except Exception as exc:
            rows.append({"status": f"error: {type(exc).__name__}: {exc}"[:120]})
    return rows


def warmed(problem: Problem, x0: Any) -> Problem:
    """``problem`` after one cost, gradient and Hessian product at ``x0``: CasADi builds each
    function on first use, which belongs to the build time, not to the first timed run."""
    problem.cost(x0)
    problem.hess(x0, problem.grad(x0))
    return problem


def our_grad_norm(case: Case, x: Any) -> float:
    m = case.problem.manifold
    g = case.problem.grad(x)
    return float(np.sqrt(np.sum(m.inner(x, g, g))))


def split(seconds: float, callbacks: float | None, nit: int) -> dict[str, Any]:
    """The time in the problem's callbacks (s) and the rest per iteration (ms): the optimizer's overhead."""
    if callbacks is None:
        return {}
    return {"callbacks_s": callbacks, "overhead_ms_per_it": 1e3 * max(seconds - callbacks, 0.0) / max(nit, 1)}


def ours_job(case: Case, key: str, args: argparse.Namespace, problem: Problem | None = None) -> Timed:
    clock = case.clock if problem is None else None  # the CasADi twins' callbacks are not timed
    problem = case.problem if problem is None else problem
    opt = OURS[key](
        max_iterations=args.max_iterations, max_time=args.max_time,
        grad_rtol=GRAD_RTOL, grad_atol=0.0, min_step=MIN_STEP,
    )  # fmt: skip

    def run() -> tuple[OptimizeResult, float | None]:
        if clock is not None:
            clock.seconds = 0.0
        res = opt.solve(problem, case.x0)
        return res, None if clock is None else clock.seconds

    def row(seconds: float, out: tuple[OptimizeResult, float | None]) -> dict[str, Any]:
        res, callbacks = out
        return {
            "nit": res.nit, "nfev": res.nfev, "ngev": res.ngev, "nhev": res.nhev, "time_s": seconds,
            **split(seconds, callbacks, res.nit),
            "fun": res.fun, "optimum": case.optimum, "gap": res.fun - case.optimum,
            "grad_norm": res.grad_norm, "grad_tol": GRAD_RTOL * res.history.grad_norm[0],
            "status": res.status.name.lower(),
        }  # fmt: skip

    return Timed(run, row)


def _pymanopt_status(text: str) -> str:
    for needle, label in (
        ("grad norm", "gradient_norm"), ("max iterations", "max_iterations"), ("max time", "max_time"),
        ("step_size", "step_size"), ("cost evals", "max_cost_evaluations"),
    ):  # fmt: skip
        if needle in text:
            return label
    return text


def pymanopt_job(pymanopt: Any, case: Case, key: str, args: argparse.Namespace) -> Timed:
    counts = {"nfev": 0, "ngev": 0, "nhev": 0}
    problem, x0 = case.make_pymanopt(pymanopt, counts)
    g0 = problem.manifold.norm(x0, problem.riemannian_gradient(x0))
    settings = {
        "max_iterations": args.max_iterations, "max_time": args.max_time,
        "min_gradient_norm": GRAD_RTOL * g0, "min_step_size": MIN_STEP,
        "max_cost_evaluations": 10**12, "verbosity": 0, "log_verbosity": 0,
    }  # fmt: skip
    opts = pymanopt.optimizers
    opt = {
        "gd": lambda: opts.SteepestDescent(**settings),
        "cg": lambda: opts.ConjugateGradient(beta_rule="PolakRibiere", **settings),
        "tr": lambda: opts.TrustRegions(**settings),
    }[key]()

    clock = counts.pop("clock")

    def run() -> Any:
        counts.update(nfev=0, ngev=0, nhev=0)
        clock.seconds = 0.0
        res = opt.run(problem, initial_point=x0)
        return res, dict(counts), clock.seconds

    def row(seconds: float, out: Any) -> dict[str, Any]:
        res, evaluations, callbacks = out
        x = case.from_pymanopt(res.point)
        # Steps taken: pymanopt's CG counts the initial point as iteration 1; its steepest
        # descent tests the gradient *before* each step, so it takes one step past the test.
        nit = res.iterations - (1 if key == "cg" else 0)
        fun = case.problem.cost(x)
        return {
            "nit": nit, **evaluations, "time_s": seconds, **split(seconds, callbacks, nit), "fun": fun,
            "optimum": case.optimum, "gap": fun - case.optimum, "grad_norm": our_grad_norm(case, x),
            "status": _pymanopt_status(res.stopping_criterion),
        }  # fmt: skip

    return Timed(run, row)


def run_case(
    case: Case, key: str, pymanopt: Any, args: argparse.Namespace, symbolic: Problem | None
) -> list[dict[str, Any]]:
    """Rows for our optimizer ``key`` on ``case``, on its CasADi twin ``symbolic`` and, when
    available, pymanopt's."""
    jobs, libraries = [ours_job(case, key, args)], ["manopt_lie"]
    if symbolic is not None:
        jobs.append(ours_job(case, key, args, symbolic))
        libraries.append("manopt_lie+casadi")
    failed: dict[str, Any] | None = None
    if pymanopt is not None and key in PYMANOPT:
        try:
            jobs.append(pymanopt_job(pymanopt, case, key, args))
            libraries.append("pymanopt")
        except Exception as exc:  # setting pymanopt up failed: report it
            failed = {"library": "pymanopt", "status": f"error: {type(exc).__name__}: {exc}"[:120]}
    rows = [
        {"problem": case.name, "optimizer": key, "library": lib, **row}
        for lib, row in zip(libraries, time_interleaved(jobs, args.repeat), strict=True)
    ]
    if failed is not None:
        rows.append({"problem": case.name, "optimizer": key, **failed})
    return rows


def evaluation_costs(case: Case, pymanopt: Any, repeat: int, symbolic: Problem | None) -> dict[str, Any]:
    """Milliseconds per cost and per gradient evaluation at ``x0`` (what an iteration is made of)."""
    row: dict[str, Any] = {"problem": case.name}
    m = case.problem.manifold
    points = [case.x0, m.retr(case.x0, 1e-3 * m.random_tangent(case.x0, 0))]
    for label, problem in (("ours", case.problem), ("casadi", symbolic)):
        if problem is not None:
            # Two points in turn: Problem (and the CasADi evaluators) remember the last point's
            # gradient, and a cost returning its gradient its cost too.
            turn = iter(range(10**9))
            cost = lambda p=problem: p.cost(copy.copy(points[next(turn) % 2]))
            row[f"{label}_cost_ms"] = 1e3 * median_time(cost, repeat)[0]
            grad = lambda p=problem: p.grad(copy.copy(points[next(turn) % 2]))
            row[f"{label}_grad_ms"] = 1e3 * median_time(grad, repeat)[0]
    if pymanopt is None:
        return row

    def fresh() -> tuple[Any, Any]:  # a new problem: the Karcher twin caches its last gradient
        return case.make_pymanopt(pymanopt, {"nfev": 0, "ngev": 0, "nhev": 0})

    try:
        problem, x0 = fresh()
        build = median_time(fresh, repeat)[0]
        row["pymanopt_cost_ms"] = 1e3 * median_time(lambda: problem.cost(x0), repeat)[0]
        with_build = median_time(lambda: fresh()[0].riemannian_gradient(x0), repeat)[0]
        row["pymanopt_grad_ms"] = 1e3 * max(with_build - build, 0.0)
    except Exception:  # shown as missing columns
        pass
    return row


# ---- output -----------------------------------------------------------------------


def _cell(value: Any, fmt: str) -> str:
    if value is None:
        return ""
    if isinstance(value, float) and math.isnan(value):
        return "nan"
    return format(value, fmt)


def print_table(title: str, rows: list[dict[str, Any]], fmt: dict[str, str]) -> None:
    keys = list(dict.fromkeys(k for row in rows for k in row))
    cells = [[_cell(row.get(k), fmt.get(k, "")) for k in keys] for row in rows]
    try:
        from rich.console import Console
        from rich.table import Table

        if not sys.stdout.isatty():  # a file or a pipe: plain columns, none cut to a terminal's width
            raise ImportError
    except ImportError:
        widths = [max(len(k), *(len(c[i]) for c in cells)) for i, k in enumerate(keys)]
        print(f"\n{title}")
        print("  ".join(k.rjust(w) for k, w in zip(keys, widths, strict=True)))
        for c in cells:
            print("  ".join(v.rjust(w) for v, w in zip(c, widths, strict=True)))
        return
    table = Table(title=title)
    for key in keys:
        table.add_column(key, justify="right")
    for c in cells:
        table.add_row(*c)
    Console().print(table)


def _import_pymanopt() -> tuple[Any, str]:
    """pymanopt and a note on it, or ``None`` and why not (missing or broken: its rows are skipped)."""
    try:
        import pymanopt
        import pymanopt.manifolds
        import pymanopt.optimizers
    except Exception as exc:
        return None, f"pymanopt not available ({type(exc).__name__}: {exc}); its rows are skipped"
    return pymanopt, f"pymanopt {pymanopt.__version__} (numpy backend)"


def _load() -> str:
    """The 1-minute load average (other processes on a small machine skew wall times)."""
    try:
        return f"{os.getloadavg()[0]:.2f}"
    except OSError:
        return "n/a"


def _evaluations(row: dict[str, Any]) -> str:
    """``costs+gradients`` (``+Hessian products`` if any) of a run row."""
    return f"{row['nfev']}+{row['ngev']}" + (f"+{row['nhev']}" if row.get("nhev") else "")


def _lbfgs_row(problem: str, rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """L-BFGS against our CG and pymanopt's on ``problem``, from the run rows (none if a run is missing)."""
    by = {(r["optimizer"], r.get("library")): r for r in rows if r["problem"] == problem and "time_s" in r}
    ours, cg, theirs = by.get(("lbfgs", "manopt_lie")), by.get(("cg", "manopt_lie")), by.get(("cg", "pymanopt"))
    if ours is None or cg is None:
        return []
    row = {
        "problem": problem, "lbfgs_s": ours["time_s"], "cg_s": cg["time_s"], "lbfgs_nit": ours["nit"],
        "cg_nit": cg["nit"], "lbfgs_evals": _evaluations(ours), "cg_evals": _evaluations(cg),
        "lbfgs_gap": f"{ours['gap']:.1e}", "cg_gap": f"{cg['gap']:.1e}", "lbfgs/cg": ours["time_s"] / cg["time_s"],
    }  # fmt: skip
    if theirs is not None:
        row |= {"pymanopt_cg_s": theirs["time_s"], "lbfgs/pymanopt_cg": ours["time_s"] / theirs["time_s"]}
    return [row]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="small sizes and one repeat (a smoke run)")
    parser.add_argument("--repeat", type=int, default=None, help="timed runs per case, median reported (default 3)")
    parser.add_argument("--max-iterations", type=int, default=10_000, help="iteration cap, both libraries")
    parser.add_argument("--max-time", type=float, default=120.0, help="seconds per run, both libraries")
    parser.add_argument("--no-pymanopt", action="store_true", help="skip pymanopt even if installed")
    parser.add_argument("--no-casadi", action="store_true", help="skip the CasADi-derived twins")
    parser.add_argument("--no-jit", action="store_true", help="interpret the Karcher twin instead of compiling it")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--problems", default="karcher,rayleigh,brockett", help="comma-separated subset")
    parser.add_argument("--optimizers", default=",".join(OURS), help=f"comma-separated subset of {','.join(OURS)}")
    parser.add_argument("--no-tiny", action="store_true", help="skip the trust regions on 20 rotations")
    parser.add_argument("--json", metavar="PATH", help="also write the results as JSON")
    args = parser.parse_args(argv)
    if args.repeat is None:
        args.repeat = 1 if args.quick else 3
    global JIT
    JIT = JIT and not args.no_jit
    n_rot, n = (10_000, 200) if args.quick else (100_000, 1000)

    pymanopt, note = (None, "pymanopt skipped (--no-pymanopt)") if args.no_pymanopt else _import_pymanopt()

    start_load = _load()
    rng = np.random.default_rng(args.seed)
    cases = [karcher_case(n_rot, rng), rayleigh_case(n, rng), brockett_case(n, 5, rng)]  # (draws in this order)
    cases = [c for c in cases if c.name in args.problems.split(",")]
    keys = [k for k in OURS if k in args.optimizers.split(",")]
    print(f"manopt_lie optimizers vs {note}; median of {args.repeat}; stop at |grad| <= {GRAD_RTOL:g}·|grad(x0)|,")
    print(f"max {args.max_iterations} iterations, max {args.max_time:g} s; "
          f"{platform.python_implementation()} {platform.python_version()}, numpy {np.__version__}, "
          f"{os.cpu_count()} cores, load average {_load()} at the start")  # fmt: skip
    for case in cases:
        print(f"  {case.name}: {case.title}, optimum {case.optimum:.12g}")

    symbolic: dict[str, Problem | None] = {}
    builds: list[dict[str, Any]] = []
    for case in cases:
        symbolic[case.name] = None
        if not args.no_casadi:
            seconds, symbolic[case.name] = median_time(lambda c=case: warmed(c.make_casadi(), c.x0), 1)
            builds.append({"problem": case.name, "build_s": seconds})
    rows: list[dict[str, Any]] = []
    ratios: list[dict[str, Any]] = []
    twins: list[dict[str, Any]] = []
    lbfgs: list[dict[str, Any]] = []
    for case in cases:
        for key in keys:
            runs = run_case(case, key, pymanopt, args, symbolic[case.name])
            rows.extend(runs)
            by = {r.get("library"): r for r in runs if "time_s" in r}
            hand, sym = by.get("manopt_lie"), by.get("manopt_lie+casadi")
            if hand is not None and sym is not None:
                twins.append({
                    "problem": case.name, "optimizer": key, "hand_s": hand["time_s"], "casadi_s": sym["time_s"],
                    "hand_nit": hand["nit"], "casadi_nit": sym["nit"],
                    "per_iteration_ratio": (sym["time_s"] / max(sym["nit"], 1))
                    / (hand["time_s"] / max(hand["nit"], 1)),
                })  # fmt: skip
            pair = [by[lib] for lib in ("manopt_lie", "pymanopt") if lib in by]
            if len(pair) == 2:
                ours, theirs = pair
                ratios.append({
                    "problem": case.name, "optimizer": key,
                    "ours_s": ours["time_s"], "pymanopt_s": theirs["time_s"],
                    "ours_nit": ours["nit"], "pymanopt_nit": theirs["nit"],
                    "ours_evals": _evaluations(ours), "pymanopt_evals": _evaluations(theirs),
                    "ours_overhead_ms/it": ours.get("overhead_ms_per_it"),
                    "pymanopt_overhead_ms/it": theirs.get("overhead_ms_per_it"),
                    "ratio": ours["time_s"] / theirs["time_s"],
                    "per_iteration_ratio": (ours["time_s"] / max(ours["nit"], 1))
                    / (theirs["time_s"] / max(theirs["nit"], 1)),
                })  # fmt: skip
        lbfgs.extend(_lbfgs_row(case.name, rows))
    tiny = [] if args.no_tiny else tiny_rows(pymanopt, max(10, 5 * args.repeat), np.random.default_rng(args.seed))
    evals = [evaluation_costs(case, pymanopt, max(3, args.repeat), symbolic[case.name]) for case in cases]

    fmt = {
        "time_s": ".3f", "callbacks_s": ".3f", "overhead_ms_per_it": ".3f", "fun": ".10g", "optimum": ".10g",
        "gap": ".1e", "grad_norm": ".1e", "grad_tol": ".1e",
    }  # fmt: skip
    print_table("Runs (grad_norm in manopt_lie's metric at the final point)", rows, fmt)
    if ratios:
        rfmt = {
            "ours_s": ".3f", "pymanopt_s": ".3f", "ours_overhead_ms/it": ".3f", "pymanopt_overhead_ms/it": ".3f",
            "ratio": ".2f", "per_iteration_ratio": ".2f",
        }  # fmt: skip
        print_table("Time ratio ours / pymanopt (goal <= 0.2)", ratios, rfmt)
    if lbfgs:
        lfmt = {"lbfgs_s": ".3f", "cg_s": ".3f", "pymanopt_cg_s": ".3f", "lbfgs/cg": ".2f", "lbfgs/pymanopt_cg": ".2f"}
        print_table("L-BFGS against CG (ours, and pymanopt's PR CG): time, iterations, costs+gradients", lbfgs, lfmt)
    if tiny:
        print_table(
            "Trust regions on 20 rotations (St(3,3)^20, exact Hessian): overhead per step = (time − callbacks) / "
            "(iterations + Hessian products)", tiny,
            {"time_ms": ".2f", "callbacks_ms": ".2f", "ms_per_iteration": ".3f", "overhead_us_per_step": ".1f",
             "fun": ".10g"},
        )  # fmt: skip
    if twins:
        tfmt = {"hand_s": ".3f", "casadi_s": ".3f", "per_iteration_ratio": ".2f"}
        print_table("CasADi-derived / hand-written, same optimizer (goal: per-iteration ratio <= 1.5)", twins, tfmt)
        print_table(f"Building the CasADi twins (s; Karcher jit={JIT})", builds, {"build_s": ".2f"})
    if evals:
        print_table("Evaluation costs at x0 (ms)", evals, {k: ".2f" for k in evals[0] if k != "problem"})
    print(f"\nload average {_load()} at the end")
    if pymanopt is None:
        print(f"\nNote: {note}. Install it (pip install pymanopt) to compare.")
    if args.json:
        out = {
            "settings": {
                "quick": args.quick, "repeat": args.repeat, "grad_rtol": GRAD_RTOL, "min_step": MIN_STEP, "jit": JIT,
                "max_iterations": args.max_iterations, "max_time": args.max_time, "seed": args.seed,
                "pymanopt": note, "python": platform.python_version(), "numpy": np.__version__,
                "machine": platform.machine(), "cores": os.cpu_count(), "load_start": start_load,
                "load_end": _load(),
            },
            "problems": [{"name": c.name, "title": c.title, "optimum": c.optimum} for c in cases],
            "runs": rows, "ratios": ratios, "lbfgs": lbfgs, "tiny": tiny, "casadi": twins, "casadi_build": builds,
            "evaluations": evals,
        }  # fmt: skip
        write_json(args.json, out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
