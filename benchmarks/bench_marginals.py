"""Marginal covariances of all variables: ours against GTSAM's ``Marginals`` (not a timed test).

Run from the repository root::

    python benchmarks/bench_marginals.py                 # 2-D grid 10⁴ poses, cube 4913, poses+landmarks
    python benchmarks/bench_marginals.py --large         # also a 2-D grid of 10⁵ poses
    python benchmarks/bench_marginals.py --large-3d      # also cube(46): 97 336 SE(3) poses (minutes)
    python benchmarks/bench_marginals.py --repeat 5 --json out.json

Problems: ``grid2d(100, 100)`` (10⁴ SE(2) poses), ``cube(17)`` (4913 SE(3) poses),
``--large``: ``grid2d(316, 316)`` (99 856 poses), ``--large-3d``: ``cube(46)`` (97 336 SE(3)
poses; one round, GTSAM's per-key marginals timed on 1000 evenly spaced keys and scaled to
all of them: it needs tens of milliseconds per key there), each solved by Gauss-Newton from the
truth, anchor fixed; and a poses+landmarks :class:`~manopt_lie.manifolds.Blocks` problem
built here (the 10⁴-pose grid plus 2500 landmarks on a 2 m lattice, each pose observing
its four lattice neighbours as relative points), whose landmarks' marginals are wanted.

GTSAM gets the same problem at the same solution: the pose graphs as
``BetweenFactorPose2/3`` with the g2o information and a constrained prior on the anchor
(:mod:`manopt_lie.bench.peers`); the landmark problem as the ``GaussianFactorGraph`` of our
own whitened Jacobians (one ``JacobianFactor`` per edge; GTSAM's Python API has no
relative-point factor), so both invert the same ``H``. Timed:

- *linearization*: ours ``problem.linearize`` (residuals, Jacobians, ``H``), listed apart;
- *factorization*: ours :func:`~manopt_lie.linalg.cholesky_factor` of ``H``; GTSAM's
  ``Marginals(graph, values)`` (linearization and multifrontal Cholesky elimination into a
  Bayes tree);
- *marginals*: ours ``marginal_covariances(problem, x)`` minus the factorization (the
  Takahashi recursion and the reading of the blocks); GTSAM's ``marginalCovariance(key)``
  for every key (GTSAM has no batched call; a Python loop of one call per key);
- the ratios ours / GTSAM of the marginals and of the totals (ours: linearization,
  factorization and marginals; GTSAM's: ``Marginals()`` and the calls).

Times are medians of ``--repeat`` interleaved rounds (ours and GTSAM's in turn, so that
other load hits both alike); the load average is printed before and after. BLAS runs on
one thread (``OMP_NUM_THREADS`` etc. get defaults of 1): on this small shared machine a
threaded BLAS slows the recursion's small products down by large, erratic factors. GTSAM's
wheel is built without TBB (single-threaded). A second table compares our two methods
for a few variables (``method="selected"`` against ``"solve"``), which sets
``manopt_lie.optim.marginals.SOLVE_COLUMNS``.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

from manopt_lie import SE2  # noqa: E402
from manopt_lie.bench.report import write_json  # noqa: E402
from manopt_lie.bench.timing import interleaved, median_time  # noqa: E402
from manopt_lie.linalg import cholesky_factor  # noqa: E402
from manopt_lie.manifolds import Blocks, Euclidean, LieGroupManifold, Power  # noqa: E402
from manopt_lie.optim import Factor, GaussNewton, LeastSquaresProblem, marginal_covariances  # noqa: E402
from manopt_lie.problems import costs  # noqa: E402
from manopt_lie.problems.synthetic import cube, grid2d  # noqa: E402


def solved(problem: LeastSquaresProblem, x0: Any) -> Any:
    result = GaussNewton(grad_rtol=1e-10, max_iterations=20).solve(problem, x0)
    assert result.success, result.status
    return result.x


def pose_graph_case(name: str, inst: Any) -> dict[str, Any]:
    graph = inst.graph
    problem = graph.problem("geodesic")
    return {"name": name, "graph": graph, "problem": problem, "x": solved(problem, inst.truth), "variables": None}


def landmark_case(seed: int = 0) -> dict[str, Any]:
    """The 10⁴-pose grid with 2500 landmarks on a jittered 2 m lattice; every pose sees the
    four lattice points around it, measured as ``R⁻¹(l − t)`` with σ = 5 cm."""
    inst = grid2d(100, 100, seed=seed)
    graph, truth = inst.graph, inst.truth
    rng = np.random.default_rng(seed)
    side = 50
    lattice = np.stack(np.meshgrid(np.arange(side), np.arange(side), indexing="ij"), -1).reshape(-1, 2)
    points = 2.0 * lattice + 0.5 + 0.3 * rng.standard_normal(lattice.shape)
    t = truth.translation()
    cell = np.clip(np.floor((t - 0.5) / 2.0).astype(np.int64), 0, side - 2)
    corners = np.array([[0, 0], [1, 0], [0, 1], [1, 1]])
    pose_of = np.repeat(np.arange(graph.n), 4)
    point_of = ((cell[:, None, :] + corners) @ np.array([side, 1])).reshape(-1)
    rot = truth[pose_of].rotation().as_matrix()
    sigma = 0.05
    seen = np.einsum("eji,ej->ei", rot, points[point_of] - t[pose_of]) + sigma * rng.standard_normal((pose_of.size, 2))

    def relative_point(x: Any, landmark: Any, jac: bool = False) -> Any:
        r, tr = x.rotation().as_matrix(), x.translation()
        p = np.einsum("eji,ej->ei", r, landmark - tr)
        if not jac:
            return (p - seen) / sigma
        j_x = np.zeros((len(p), 2, 3))
        j_x[:, :, :2] = -np.eye(2)
        j_x[:, 0, 2], j_x[:, 1, 2] = p[:, 1], -p[:, 0]
        return (p - seen) / sigma, [j_x / sigma, np.swapaxes(r, 1, 2) / sigma]

    manifold = Blocks({"poses": Power(LieGroupManifold(SE2), graph.n), "landmarks": Power(Euclidean(2), side**2)})
    sqrt_info = costs.information_sqrt(graph.information)
    odometry = costs.geodesic_factor(graph.edges, graph.measurements, sqrt_info)
    factors = [
        Factor(odometry.variables, odometry.residual, name="between", blocks="poses"),
        Factor(np.c_[pose_of, point_of], relative_point, name="observation", blocks=("poses", "landmarks")),
    ]
    problem = LeastSquaresProblem(manifold, factors, fixed={"poses": [0]})
    x = solved(problem, manifold.values(poses=truth, landmarks=points))
    return {"name": "poses+landmarks 10⁴+2500", "graph": None, "problem": problem, "x": x, "variables": "landmarks",
            "factors": factors}  # fmt: skip


# ---- GTSAM --------------------------------------------------------------------------------


def gtsam_pose_graph(gtsam: Any, case: dict[str, Any]) -> tuple[Any, Any, list[int]]:
    from manopt_lie.bench.peers import gtsam_problem

    graph, values = gtsam_problem(gtsam, case["graph"], case["x"])
    return graph, values, [k for k in range(case["graph"].n) if k != case["graph"].anchor]


def gtsam_gaussian(gtsam: Any, case: dict[str, Any]) -> tuple[Any, Any, list[int]]:
    """Our whitened Jacobians as GTSAM ``JacobianFactor``\\ s (keys: global variable indices),
    the fixed variables' columns left out; the landmarks' keys."""
    problem, x = case["problem"], case["x"]
    fixed, dims = problem.fixed, problem.dims
    unit = {d: gtsam.noiseModel.Unit.Create(d) for d in (2, 3)}
    graph = gtsam.GaussianFactorGraph()
    for f in case["factors"]:
        ids = problem.manifold.offsets  # block offsets
        glob = np.stack([f.variables[:, s] + ids[b] for s, b in enumerate(f.blocks)], axis=1)
        pts = [x[b][f.variables[:, s]] for s, b in enumerate(f.blocks)]
        r, jacs = f.residual(*pts, jac=True)
        # One Python call per edge: GTSAM's API has no batched constructor (outside the timing).
        for e in range(len(r)):
            keep = [(int(glob[e, s]), jacs[s][e]) for s in range(glob.shape[1]) if not fixed[glob[e, s]]]
            args = [a for k, j in keep for a in (k, np.asfortranarray(j))]
            graph.add(gtsam.JacobianFactor(*args, -r[e], unit[r.shape[1]]))
    solution = gtsam.VectorValues()
    for k in np.flatnonzero(~fixed).tolist():
        solution.insert(k, np.zeros(int(dims[k])))
    start = problem.manifold.offsets["landmarks"]
    return graph, solution, list(range(start, start + problem.manifold.sizes[1]))


# ---- runs ---------------------------------------------------------------------------------


def run_case(case: dict[str, Any], repeat: int, gtsam: Any) -> dict[str, Any]:
    problem, x, variables = case["problem"], case["x"], case["variables"]
    repeat = case.get("repeat", repeat)
    # Our linearization, timed at fresh points 1e-9 away (the last one is remembered; the
    # one at x is made last, so that marginal_covariances below reuses it, as after a solve).
    zero = problem.manifold.zero_vector(x)
    nearby = [problem.manifold.retr(x, zero + 1e-9 * (i + 1)) for i in range(repeat)]
    lin = median_time(lambda: problem.linearize(nearby.pop()), repeat)[0]
    H = problem.linearize(x).hessian
    fns = [lambda: cholesky_factor(H), lambda: marginal_covariances(problem, x, variables)]
    if gtsam is not None:
        graph, values, keys = (gtsam_pose_graph if case["graph"] is not None else gtsam_gaussian)(gtsam, case)
        every = len(keys)
        if case.get("gtsam_sample"):  # evenly spaced keys; the time is scaled to all of them
            keys = keys[:: max(1, every // case["gtsam_sample"])]
        fns += [lambda: gtsam.Marginals(graph, values)]
        marginals = gtsam.Marginals(graph, values)
        fns += [lambda: [marginals.marginalCovariance(k) for k in keys]]
    out = interleaved(fns, repeat)
    failed = [o for o in out if isinstance(o, BaseException)]
    if failed:
        raise failed[0]
    (t_fac, _), (t_all, cov), *rest = out
    row = {"case": case["name"], "n": len(problem.dims), "variables": len(cov), "nnz_H": int(H.nnz),
           "linearize": lin, "ours_factor": t_fac, "ours_marginals": max(t_all - t_fac, 0.0), "ours_total": t_all,
           "method": cov.method, "backend": cov.backend}  # fmt: skip
    ours_total = lin + t_all
    if rest:
        (g_fac, _), (g_marg, theirs) = rest
        g_marg *= every / len(keys)
        order = [3, 4, 5, 0, 1, 2] if problem.dims[0] == 6 and case["graph"] is not None else None
        block = None if case["graph"] is not None else "landmarks"
        local = np.asarray(keys) - (0 if block is None else problem.manifold.offsets[block])
        ours = cov.stacked(block)[np.searchsorted(cov.indices(block), local)]
        ours = ours[:, order][:, :, order] if order else ours
        diff = float(np.abs(ours - np.stack(theirs)).max() / np.abs(ours).max())
        row.update(gtsam_factor=g_fac, gtsam_marginals=g_marg, gtsam_total=g_fac + g_marg,
                   ratio_marginals=row["ours_marginals"] / g_marg, ratio_total=ours_total / (g_fac + g_marg),
                   max_rel_diff=diff, gtsam_keys_timed=len(keys))  # fmt: skip
    return row


def few_variables(case: dict[str, Any], repeat: int, counts: tuple[int, ...] = (1, 4, 16, 64)) -> list[dict[str, Any]]:
    problem, x = case["problem"], case["x"]
    problem.linearize(x)
    rng = np.random.default_rng(1)
    rows = []
    for k in counts:
        chosen = rng.choice(np.flatnonzero(~problem.fixed), k, replace=False)
        (t_sel, _), (t_sol, _) = interleaved(
            [lambda: marginal_covariances(problem, x, chosen, method="selected"),
             lambda: marginal_covariances(problem, x, chosen, method="solve")], repeat)  # fmt: skip
        rows.append({"case": case["name"], "k": k, "columns": int(problem.dims[chosen].sum()), "selected": t_sel,
                     "solve": t_sol})  # fmt: skip
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--large", action="store_true", help="also a 2-D grid of 10⁵ poses")
    parser.add_argument("--large-3d", action="store_true",
                        help="also cube(46), 97 336 SE(3) poses: one round, GTSAM's marginals timed on 1000 keys "
                             "and scaled to all")  # fmt: skip
    parser.add_argument("--no-gtsam", action="store_true")
    parser.add_argument("--json", help="write the rows to this file")
    args = parser.parse_args()
    gtsam = None
    if not args.no_gtsam:
        try:
            import gtsam
        except ImportError:
            print("gtsam not installed: ours only")
    print(f"load average before: {os.getloadavg()}")
    cases = [pose_graph_case("grid2d 100x100", grid2d(100, 100, seed=0)),
             pose_graph_case("cube 17³", cube(17, seed=0)), landmark_case()]  # fmt: skip
    if args.large:
        cases.append(pose_graph_case("grid2d 316x316", grid2d(316, 316, seed=0)))
    if args.large_3d:
        cases.append({**pose_graph_case("cube 46³", cube(46, seed=0)), "repeat": 1, "gtsam_sample": 1000})
    rows = [run_case(case, args.repeat, gtsam) for case in cases]
    print(f"\nAll marginals, medians of {args.repeat} interleaved rounds (s); ratio = ours / GTSAM")
    head = ("case", "n", "k", "lin", "ours fac", "ours marg", "gtsam fac", "gtsam marg", "ratio marg", "ratio tot")
    print("{:26} {:>7} {:>7} {:>6} {:>9} {:>9} {:>10} {:>10} {:>10} {:>9}".format(*head))
    for r in rows:
        g = [r.get(k, float("nan")) for k in ("gtsam_factor", "gtsam_marginals", "ratio_marginals", "ratio_total")]
        print(f"{r['case']:26} {r['n']:7d} {r['variables']:7d} {r['linearize']:6.3f} {r['ours_factor']:9.3f} "
              f"{r['ours_marginals']:9.3f} {g[0]:10.3f} {g[1]:10.3f} {g[2]:10.2f} {g[3]:9.2f}")  # fmt: skip
    for r in rows:
        if "max_rel_diff" in r:
            sampled = f" (GTSAM's marginals timed on {r['gtsam_keys_timed']} keys, scaled)" * (
                r["gtsam_keys_timed"] < r["variables"]
            )
            print(f"  {r['case']}: max relative difference to GTSAM {r['max_rel_diff']:.1e}{sampled}")
    few = [row for case in cases[:2] for row in few_variables(case, args.repeat)]
    print("\nA few variables: method='selected' against 'solve' (s)")
    print("{:26} {:>5} {:>8} {:>9} {:>9}".format("case", "k", "columns", "selected", "solve"))
    for r in few:
        print(f"{r['case']:26} {r['k']:5d} {r['columns']:8d} {r['selected']:9.3f} {r['solve']:9.3f}")
    print(f"\nload average after: {os.getloadavg()}")
    if args.json:
        write_json(args.json, {"all": rows, "few": few, "repeat": args.repeat})


if __name__ == "__main__":
    main()
