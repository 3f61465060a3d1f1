"""How fast a small pose graph's Levenberg-Marquardt can be in Python: a bare loop on our kernels.

Run from the repository root (GTSAM for its column)::

    python benchmarks/bench_floor.py                         # tinyGrid3D, 300 rounds
    python benchmarks/bench_floor.py --dataset smallGrid3D --repeat 50 --json out.json

The *bare* solver takes the iterations of ``LevenbergMarquardt()`` — ``(H + λI)δ = −g`` with
``λ₀ = 1e-8``, ``λ ÷ 10`` on a decrease, GTSAM's stopping rule; on a failure ``× 10`` where ours
multiplies by a doubling ``ν``, and ``I`` where ours damps ``s·I`` with the cost scale ``s ≤ 1``
(equal on tinyGrid3D: ``s = 1``, no failure) — on the
same native residual kernels and retraction, with ``H = JᵀJ`` from one dense Jacobian and
LAPACK's Cholesky, and nothing else: no validation of the start, no history, no check of the
factorization or of the solution, no robust loss, one factor type. It is not a solver to use;
it bounds from below what any Python loop over these kernels costs, so it tells how much of
the library's time on a small system its machinery takes and whether a goal is within reach of
trimming at all. (It told that one was not: ``LevenbergMarquardt`` now runs a small pose graph's
iterations in compiled code, :mod:`manopt_lie.optim._small_system`, so ``ours`` measures that loop
against the Python floor.) ``bare``, ``ours`` (``LevenbergMarquardt(rel_cost_decrease=1e-5)``, the pools
of structures and analyses emptied before each run) and GTSAM's LM run in alternation from the chordal
initialization, each problem built before its clock; the table gives the medians, the ratios
to GTSAM and the final costs (all three agree).
"""

from __future__ import annotations

import argparse
import statistics
import time
from typing import Any

import numpy as np
from scipy.linalg import lapack

from manopt_lie.bench import peers
from manopt_lie.bench.report import write_json
from manopt_lie.linalg import clear_caches
from manopt_lie.optim import LeastSquaresProblem, LevenbergMarquardt
from manopt_lie.problems import PoseGraph, catalogue, g2o

RULE = 1e-5  # GTSAM's relativeErrorTol, ours rel_cost_decrease


def bare_lm(problem: LeastSquaresProblem, x: Any, max_iterations: int = 100) -> tuple[Any, float, int]:
    """Levenberg-Marquardt as ``LevenbergMarquardt()`` steps, stripped to the arithmetic: the final
    point, its cost ``½‖r‖²`` and the accepted steps. One factor type of arity 2, ``n ≤ a few
    hundred`` unknowns (``J`` is dense); fixed variables get a unit diagonal and no step."""
    (factor,) = problem.factors
    ids, d = factor.variables, int(problem.dims[0])
    n = d * len(problem.dims)
    # Entry (row, column) of J for each entry of every edge's [J_i | J_j] block.
    columns = np.concatenate([d * ids[:, s, None] + np.arange(d) for s in range(2)], axis=1)  # (m, 2d)
    rows = np.arange(ids.shape[0] * d).reshape(-1, d)
    position = (rows[:, :, None] * n + columns[:, None, :]).reshape(-1)
    fixed = np.flatnonzero(np.repeat(problem.fixed, d))
    diagonal = np.arange(n) * (n + 1)
    jacobian, hessian, gradient = np.zeros((rows.size, n)), np.empty((n, n)), np.empty(n)

    def linearize(point: Any) -> float:
        r, blocks = factor.residual(point[ids[:, 0]], point[ids[:, 1]], jac=True)
        jacobian.fill(0.0)
        jacobian.put(position, np.concatenate(blocks, axis=-1))
        jacobian[:, fixed] = 0.0
        np.matmul(jacobian.T, jacobian, out=hessian)
        np.matmul(jacobian.T, r.reshape(-1), out=gradient)
        hessian.flat[diagonal[fixed]] += 1.0
        return 0.5 * float(np.dot(r.reshape(-1), r.reshape(-1)))

    def cost(point: Any) -> float:
        r = factor.residual(point[ids[:, 0]], point[ids[:, 1]]).reshape(-1)
        return 0.5 * float(np.dot(r, r))

    f, lam, accepted = linearize(x), 1e-8, 0
    while accepted < max_iterations:
        damped = hessian.copy()
        damped.flat[diagonal] += lam
        factor_l, info = lapack.dpotrf(damped, lower=1, overwrite_a=1)
        if info:
            lam *= 10.0
            continue
        delta, _ = lapack.dpotrs(factor_l, -gradient, lower=1)
        predicted = -float(gradient @ delta) - 0.5 * float(delta @ (hessian @ delta))
        trial = problem.manifold.retr(x, delta.reshape(-1, d))
        if (f - cost(trial)) / predicted > 0:
            x, previous, lam, accepted = trial, f, max(lam / 10.0, 1e-15), accepted + 1
            f = linearize(x)
            if previous - f < RULE * previous:
                break
        else:
            lam *= 10.0
    return x, f, accepted


def compare(graph: PoseGraph, repeat: int) -> list[dict[str, Any]]:
    """The solvers in alternation, ``repeat`` rounds after two warm-up rounds: per solver the median
    time of its solve alone (the problem is built before the clock), the iterations and the final
    geodesic cost."""
    x0 = graph.chordal_initialization()

    def bare() -> tuple[Any, Any]:
        problem = graph.problem("geodesic")
        return lambda: bare_lm(problem, x0), lambda out: (out[2], out[0])

    def ours() -> tuple[Any, Any]:
        problem, solver = graph.problem("geodesic"), LevenbergMarquardt(rel_cost_decrease=RULE)
        clear_caches()  # each run pays its own analysis, as GTSAM its ordering
        return lambda: solver.solve(problem, x0), lambda out: (out.nit, out.x)

    solvers = {"bare": bare, "ours": ours}
    if peers.available("gtsam-lm"):
        import gtsam

        params = gtsam.LevenbergMarquardtParams()
        params.setRelativeErrorTol(RULE)

        def gtsam_lm() -> tuple[Any, Any]:
            built = peers.gtsam_problem(gtsam, graph, x0)

            def solve() -> Any:  # the optimizer's construction too: it evaluates the start, as ours does
                optimizer = gtsam.LevenbergMarquardtOptimizer(*built, params)
                return optimizer, optimizer.optimize()

            return solve, lambda out: (out[0].iterations(), peers.from_gtsam(gtsam, graph.group, out[1]))

        solvers["gtsam"] = gtsam_lm
    times: dict[str, list[float]] = {name: [] for name in solvers}
    last: dict[str, tuple[int, Any]] = {}
    for round_ in range(repeat + 2):
        for name, make in solvers.items():
            solve, read = make()
            start = time.perf_counter()
            out = solve()
            seconds = time.perf_counter() - start
            if round_ >= 2:
                times[name].append(seconds)
            last[name] = read(out)
    reference = statistics.median(times["gtsam"]) if "gtsam" in times else None
    return [
        {"solver": name, "dataset": graph.name, "time": statistics.median(times[name]),
         "ratio": None if reference is None else statistics.median(times[name]) / reference,
         "iterations": last[name][0], "cost": graph.cost(last[name][1], "geodesic")}
        for name in solvers
    ]  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--dataset", default="tinyGrid3D", help="a dataset of the data directory (default tinyGrid3D)")
    parser.add_argument("--repeat", type=int, default=300, help="rounds, medians taken (default 300)")
    parser.add_argument("--json", metavar="PATH", help="also write the rows as JSON")
    args = parser.parse_args(argv)
    rows = compare(g2o.read(catalogue.default_data_dir() / f"{args.dataset}.g2o"), args.repeat)
    print(f"{'solver':6s} {'ms':>8s} {'/ GTSAM':>8s} {'iterations':>10s} {'final cost':>14s}")
    for row in rows:
        ratio = "—" if row["ratio"] is None else f"{row['ratio']:.2f}"
        print(f"{row['solver']:6s} {1e3 * row['time']:8.3f} {ratio:>8s} {row['iterations']:10d} {row['cost']:14.6f}")
    if args.json:
        write_json(args.json, rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
