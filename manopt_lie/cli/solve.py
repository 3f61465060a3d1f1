"""``manopt-lie solve FILE.g2o``: read a g2o file as a problem of a chosen kind, initialize,
solve with one optimizer, write the solution as g2o, plot, print a summary or JSON.

The command knows problems only through the
:class:`~manopt_lie.problems.graph.Graph` interface and the kinds registry
(:mod:`manopt_lie.problems.kinds`), and optimizers through the registry
(:data:`manopt_lie.optim.OPTIMIZERS`).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import numpy as np

from manopt_lie.bench.record import status_words
from manopt_lie.optim import OPTIMIZERS, Status, get_optimizer, marginal_covariances
from manopt_lie.problems import KINDS, g2o
from manopt_lie.problems.graph import Graph
from manopt_lie.problems.kinds import convert
from manopt_lie.problems.pose_graph import PoseGraph
from manopt_lie.problems.rotation_averaging import RotationAveraging
from manopt_lie.problems.solvers import GRAPH_SOLVERS

from . import _common

CERTIFIABLE = (PoseGraph.kind, RotationAveraging.kind)
"""The kinds :func:`manopt_lie.problems.certify.certify` applies to (their chordal cost)."""
COSTS = tuple(dict.fromkeys(c for kind in KINDS.values() for c in kind.graph.costs))


def add_parser(commands: Any) -> None:
    solve = commands.add_parser(
        "solve", help="solve a g2o file",
        description="Solve a g2o pose graph (or the rotation averaging of its rotations) and write the result.",
    )  # fmt: skip
    solve.add_argument("file", type=Path, metavar="FILE.g2o")
    solve.add_argument("--problem", choices=tuple(KINDS),
                       help="; ".join(f"{k.name}: {k.summary}" for k in KINDS.values())
                       + " (default: what the file holds)")
    solve.add_argument("--cost", choices=COSTS,
                       help="geodesic: ½Σ rᵀΩr with r = Log(Z⁻¹Xᵢ⁻¹Xⱼ), GTSAM's error; chordal: SE-Sync's "
                       "Frobenius-norm cost (default: geodesic for pose graphs, chordal for rotations)")
    optimizers = "; ".join(f"{e.name}: {e.summary}" for e in (*OPTIMIZERS.values(), *GRAPH_SOLVERS.values()))
    solve.add_argument("--optimizer", choices=(*OPTIMIZERS, *GRAPH_SOLVERS), default="tr",
                       help=f"{optimizers} (default: %(default)s)")
    solve.add_argument("--init", choices=Graph.initializations, default="chordal",
                       help="initial guess: chordal relaxation, odometry (spanning tree), random (Haar rotations, "
                       "random translations; see --seed), or file (the file's VERTEX poses) (default: %(default)s)")
    solve.add_argument("--seed", type=int, default=0, help="seed of --init random (default: %(default)s)")
    solve.add_argument("--robust", metavar="LOSS:SCALE", help="robust loss, e.g. huber:1.0, cauchy:0.5")
    solve.add_argument("--out", type=Path, metavar="RESULT.g2o",
                       help="write the solution as g2o (atomically; never over the input without --force; "
                       "rotation averaging keeps the file's translations)")
    solve.add_argument("--force", action="store_true", help="allow --out to overwrite the input file")
    solve.add_argument("--certify", action="store_true",
                       help="certify the solution's global optimality for the chordal (SE-Sync) cost: the "
                       "smallest eigenvalue of the dual certificate and a bound on f(x) − f* (pose graphs and "
                       "rotation averaging)")
    solve.add_argument("--covariances", type=Path, metavar="COV.json",
                       help="write the marginal covariance of every vertex at the solution, as JSON "
                       "{vertex id: d×d matrix}: right (local) perturbation X ⊕ τ, translation first "
                       "(x, y, θ / x, y, z, θx, θy, θz), the fixed vertices (the gauge) as zeros")
    solve.add_argument("--plot", type=Path, metavar="FIG.png|pdf|svg",
                       help="trajectories before/after (poses; landmarks, and 95%% covariance ellipses with "
                       "--covariances) or convergence (rotations); png, pdf or svg by the extension")
    solve.add_argument("--quaternion-tol", type=_common.number(float, positive=True), default=None, metavar="X",
                       help="accept (and normalize) quaternions whose norm is within X of 1 "
                       "(default: the reader's, see manopt_lie.problems.g2o.read)")
    _common.add_stopping(solve, max_time=600.0)
    _common.add_output(solve)
    solve.set_defaults(run=run)  # fmt: skip


def run(args: argparse.Namespace) -> int:
    if args.file.is_dir():
        raise _common.UsageError(f"{args.file} is a directory, not a g2o file")
    if not args.file.is_file():
        raise _common.UsageError(f"no such file: {args.file}")
    _common.output_path(args.out, "--out", inputs=[args.file], force=args.force)
    _common.figure_path(args.plot, "--plot", inputs=[args.file])
    _common.output_path(args.covariances, "--covariances", inputs=[args.file])
    if args.certify and args.problem is not None and args.problem not in CERTIFIABLE:
        raise _common.UsageError(f"--certify: certificates exist for {', '.join(CERTIFIABLE)} problems")
    tol = {} if args.quaternion_tol is None else {"quaternion_tol": args.quaternion_tol}
    graph = convert(g2o.read(args.file, **tol), args.problem)
    solver = GRAPH_SOLVERS.get(args.optimizer)
    cost = args.cost or (solver.costs[0] if solver is not None else graph.costs[0])
    if cost not in graph.costs:
        raise _common.UsageError(f"--cost {cost}: a {graph.kind} problem offers {', '.join(graph.costs)}")
    if solver is not None and not solver.applies(graph.kind, cost):
        raise _common.UsageError(f"--optimizer {solver.name} solves {', '.join(solver.kinds)} problems with the "
                                 f"{', '.join(solver.costs)} cost, not a {graph.kind} problem with the {cost} cost")
    start = time.perf_counter()
    if args.certify and graph.kind not in CERTIFIABLE:
        raise _common.UsageError(f"--certify: {graph.name} is a {graph.kind} problem; certificates exist for "
                                 f"{', '.join(CERTIFIABLE)} problems")  # fmt: skip
    x0 = graph.initialize(args.init, seed=args.seed)
    init_time = time.perf_counter() - start
    problem = graph.problem(cost, robust=args.robust)
    progress = _common.progress(args.quiet)
    if solver is not None:
        if args.robust:
            raise _common.UsageError(f"--optimizer {solver.name} solves the plain chordal cost: no --robust")
        result = solver.solve(graph, x0, _common.stopping(args))
    elif progress is None:
        result = _optimizer(args.optimizer, problem, args).solve(problem, x0)
    else:
        with progress:
            bar = progress.add_task(f"{args.optimizer} on {args.file.name}", total=args.max_iterations)

            def show(info: Any) -> None:
                progress.update(bar, completed=info.iteration, description=f"{args.optimizer}: cost {info.fun:.6g}")

            result = _optimizer(args.optimizer, problem, args).solve(problem, x0, callback=show)
    if result.status is Status.INTERRUPTED:
        raise KeyboardInterrupt  # nothing is written; main reports it and exits 130
    summary = {
        "file": str(args.file), "problem": graph.kind, "cost": cost, "optimizer": args.optimizer,
        "robust": args.robust, "n": graph.n, "m": graph.m, "initial_fun": problem.cost(x0), "fun": result.fun,
        "nit": result.nit, "time": result.time, "init_time": init_time, "status": result.status.name.lower(),
        "converged": result.status.converged, "grad_norm": result.grad_norm, "message": result.message,
        "written": [],
    }  # fmt: skip
    if args.out is not None:
        _common.write_text(args.out, g2o.dumps(*graph.to_g2o(result.x)))
        summary["written"].append(str(args.out))
    if args.certify:
        summary["certificate"] = _certificate(graph, result.x)
    marginals = None
    if args.covariances is not None:
        marginals = marginal_covariances(problem, result.x, variables=np.arange(len(graph.vertex_ids)))
        document = {str(i): marginals[v].tolist() for v, i in enumerate(graph.vertex_ids.tolist())}
        _common.write_text(args.covariances, _common.json_text(document, indent=1))
        summary["written"].append(str(args.covariances))
    if args.plot is not None:
        _plot(args, graph, x0, result, summary, marginals)
        summary["written"].append(str(args.plot))
    code = _common.EXIT_OK if result.status.converged else _common.EXIT_NOT_CONVERGED
    if args.json:
        _common.print_json(summary)
        return code
    print(
        f"{args.file.name}: {graph.describe()}; "
        f"{cost} cost {summary['initial_fun']:.8g} → {result.fun:.8g} by {args.optimizer} in {result.nit} "
        f"iterations, {result.time:.3f} s (+ {init_time:.3f} s {args.init} initialization)\n"
        f"status: {status_words(summary['status'])} ({result.message}); ‖grad‖ = {result.grad_norm:.3g}"
    )
    if args.certify:
        c = summary["certificate"]
        verdict = "globally optimal" if c["optimal"] else "NOT certified optimal"
        print(f"certificate: {verdict} for the chordal cost {c['fun']:.8g}: λ_min(S) ≈ {c['lambda_min']:.3g}, "
              f"f − f* ≤ {c['gap_bound']:.3g} (rank {c['rank']}, {c['time']:.3f} s); {c['message']}")  # fmt: skip
    for path in summary["written"]:
        print(f"wrote {path}")
    return code


def _optimizer(name: str, problem: Any, args: argparse.Namespace) -> Any:
    entry = get_optimizer(name)
    if not entry.accepts_problem(problem):
        raise _common.UsageError(f"--optimizer {entry.name} needs a {entry.accepts.__name__}")
    return entry.make(_common.stopping(args))


def _certificate(graph: Graph, x: Any) -> dict[str, Any]:
    """:func:`manopt_lie.problems.certify.certify` of ``x`` as JSON-ready numbers."""
    from manopt_lie.problems.certify import certify

    c = certify(graph, x)
    return {
        "optimal": bool(c.optimal), "fun": c.fun, "lambda_min": c.lambda_min, "lambda_lower": c.lambda_lower,
        "gap_bound": c.gap, "dual_bound": c.dual_bound, "relative_gap": c.relative_gap, "tol": c.tol,
        "rank": c.rank, "time": c.time, "message": c.message,
    }  # fmt: skip


def _plot(args: argparse.Namespace, graph: Graph, x0: Any, result: Any, summary: dict[str, Any],
          marginals: Any) -> None:  # fmt: skip
    """Trajectories before and after where the variables have positions (with the graph's
    extra layers: landmarks, covariance ellipses when computed), else the convergence."""
    from manopt_lie.bench import plots
    from manopt_lie.bench.record import Run

    before, after = graph.positions(x0), graph.positions(result.x)
    if before is not None and after is not None:
        title = f"{args.file.name}: {args.init} initialization → {args.optimizer} ({summary['cost']})"
        labels = (f"{args.init} initialization", f"{args.optimizer} solution")
        plots.trajectory(before, after, graph.edges, args.plot, title, labels=labels,
                         **graph.figure_layers(result.x, marginals))  # fmt: skip
        return
    run = Run(args.file.stem, graph.kind, summary["cost"], args.optimizer, graph.n, graph.m, result.nit,
              result.time, summary["init_time"], result.fun, summary["status"], summary["converged"],
              result.grad_norm, history_cost=result.history.cost.tolist(),
              history_time=result.history.time.tolist(),
              history_grad_norm=result.history.grad_norm.tolist())  # fmt: skip
    plots.convergence([run], args.plot)
