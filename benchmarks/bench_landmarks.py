"""Landmark SLAM against GTSAM: Levenberg-Marquardt, then the marginals of every landmark.

A synthetic world (:func:`manopt_lie.problems.synthetic.landmark_world`: laps among
landmarks, the truth in the first pose's frame) is measured by odometry and by range and
bearing to the landmarks in view — GTSAM's built-in ``BearingRangeFactor2D/3D`` and our
:func:`manopt_lie.factors.range_bearing_factor` model the same measurement. Both start from
the same values — ``--starts odometry``: the odometry composed, far from the optimum (over
thousands of poses both libraries may stop in different local minima); ``near-truth``: the
true poses perturbed, in the optimum's basin — each landmark placed from its first
observation, and stop by GTSAM's rule (relative cost decrease below 1e-5). Times are medians of interleaved
runs of the optimization only (building the factor graph is excluded on both sides; our
first linearization and symbolic analysis are inside the solve). Final costs are compared
with our cost function evaluated at both solutions, marginals by GTSAM's ``Marginals`` on
its solution against :func:`manopt_lie.optim.marginal_covariances` on ours.

    python benchmarks/bench_landmarks.py              # 2-D 10,000 poses / 2,000 landmarks; 3-D 5,000 / 1,000
    python benchmarks/bench_landmarks.py --quick      # a fifth of that
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

import numpy as np

from manopt_lie import SE2, SE3
from manopt_lie.bench.report import write_json
from manopt_lie.bench.timing import interleaved
from manopt_lie.factors import Diagonal, Information, between_factor, range_bearing_factor
from manopt_lie.manifolds import Blocks
from manopt_lie.optim import LeastSquaresProblem, LevenbergMarquardt, marginal_covariances
from manopt_lie.problems import synthetic

SIGMA_RANGE, SIGMA_BEARING = 0.05, 0.01
RULE = 1e-5  # GTSAM's relativeErrorTol, ours by default on least squares


def world(d: int, n: int, landmarks: int, seed: int = 0) -> dict[str, Any]:
    """The synthetic world measured by range and bearing (the truth, odometry, observations)."""
    laps, radius = (4, 0.01 * n) if d == 2 else (3, 0.02 * n)
    inst = synthetic.landmark_world(n, landmarks, d=d, laps=laps, radius=radius, sensor_range=0.25 * radius,
                                    min_range=0.05 * radius, max_observations=5, seed=seed)  # fmt: skip
    graph, rng = inst.graph, np.random.default_rng(seed + 1)
    poses, points = inst.truth["poses"], inst.truth["landmarks"]
    obs = graph.observations
    p = poses[obs[:, 0]].inverse().act(points[obs[:, 1]])
    ranges = np.linalg.norm(p, axis=1) + SIGMA_RANGE * rng.standard_normal(len(p))
    if d == 2:
        bearings = np.arctan2(p[:, 1], p[:, 0]) + SIGMA_BEARING * rng.standard_normal(len(p))
    else:
        noisy = p / np.linalg.norm(p, axis=1, keepdims=True) + SIGMA_BEARING * rng.standard_normal(p.shape)
        bearings = noisy / np.linalg.norm(noisy, axis=1, keepdims=True)
    return {"d": d, "graph": graph, "ranges": ranges, "bearings": bearings, "truth": inst.truth}


def ours(w: dict[str, Any]) -> tuple[LeastSquaresProblem, Any]:
    """Our problem on Blocks(poses, landmarks) and the initial values."""
    graph, d = w["graph"], w["d"]
    pg = graph.poses
    manifold = graph.manifold  # poses retracted as GTSAM's: (R Exp(θ), t + Rρ)
    sigmas = [SIGMA_RANGE, SIGMA_BEARING] + ([SIGMA_BEARING] if d == 3 else [])
    factors = [
        between_factor(pg.edges, pg.measurements, Information(pg.information), name="odometry", blocks="poses"),
        range_bearing_factor(graph.observations, w["ranges"], w["bearings"], Diagonal(sigmas),
                             name="range-bearing", blocks=("poses", "landmarks")),
    ]  # fmt: skip
    problem = LeastSquaresProblem(manifold, factors, fixed={"poses": [0]})
    return problem, start(w, manifold, pg.odometry_initialization())


def start(w: dict[str, Any], manifold: Blocks, poses0: Any) -> Any:
    """Initial values: ``poses0``, and each landmark placed from its first observation."""
    graph, d = w["graph"], w["d"]
    seen = poses0[graph.observations[:, 0]]
    direction = (np.stack([np.cos(w["bearings"]), np.sin(w["bearings"])], axis=1) if d == 2 else w["bearings"])
    world_points = seen.act(w["ranges"][:, None] * direction)
    landmarks0 = np.zeros((graph.n_landmarks, d))
    landmarks0[graph.observations[::-1, 1]] = world_points[::-1]  # the first observation of each
    return manifold.values(poses=poses0, landmarks=landmarks0)


def near_truth(w: dict[str, Any], manifold: Blocks, seed: int = 7) -> Any:
    """A start in the optimum's basin: the true poses (the first kept) perturbed by
    ``Exp(σ·randn)``, σ = 0.1 in position and 0.02 rad in rotation, landmarks from their first
    observation."""
    truth = w["truth"]["poses"]
    d = w["d"]
    sigma = np.r_[[0.1] * d, [0.02] * (truth.dim - d)]
    noise = sigma * np.random.default_rng(seed).standard_normal((len(truth), truth.dim))
    noise[0] = 0.0
    return start(w, manifold, truth.rplus(noise))


def gtsam_problem(gtsam: Any, w: dict[str, Any], x0: Any) -> tuple[Any, Any, list[int]]:
    """GTSAM's factor graph of the same measurements, its initial values, the landmark keys."""
    graph, d = w["graph"], w["d"]
    pg = graph.poses
    factors, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    order = np.arange(3) if d == 2 else np.r_[3:6, 0:3]  # GTSAM's Pose3 tangent is (ω, v)
    info = pg.information[:, order][:, :, order]
    z = pg.measurements.as_matrix()
    gaussian = gtsam.noiseModel.Gaussian.Information
    if d == 2:
        def pose(m: np.ndarray) -> Any:
            return gtsam.Pose2(m[0, 2], m[1, 2], math.atan2(m[1, 0], m[0, 0]))

        measured = [pose(m) for m in z]
        between, point = gtsam.BetweenFactorPose2, gtsam.Point2
        bearing_range = gtsam.BearingRangeFactor2D
        noise = gtsam.noiseModel.Diagonal.Sigmas(np.array([SIGMA_BEARING, SIGMA_RANGE]))
        bearings = [gtsam.Rot2(b) for b in w["bearings"]]
    else:
        measured = [gtsam.Pose3(m) for m in z]
        between, pose, point = gtsam.BetweenFactorPose3, gtsam.Pose3, gtsam.Point3
        bearing_range = gtsam.BearingRangeFactor3D
        noise = gtsam.noiseModel.Diagonal.Sigmas(np.array([SIGMA_BEARING, SIGMA_BEARING, SIGMA_RANGE]))
        bearings = [gtsam.Unit3(b) for b in w["bearings"]]
    for (i, j), zij, omega in zip(pg.edges.tolist(), measured, info, strict=True):
        factors.add(between(i, j, zij, gaussian(omega)))
    keys = [gtsam.symbol("l", a) for a in range(graph.n_landmarks)]
    for (i, a), b, r in zip(graph.observations.tolist(), bearings, w["ranges"].tolist(), strict=True):
        factors.add(bearing_range(i, keys[a], b, r, noise))
    poses0 = x0["poses"].as_matrix()
    factors.add(gtsam.NonlinearEqualityPose2(0, pose(poses0[0])) if d == 2 else
                gtsam.NonlinearEqualityPose3(0, pose(poses0[0])))  # fmt: skip
    for i, m in enumerate(poses0):
        values.insert(i, pose(m))
    for key, p in zip(keys, x0["landmarks"], strict=True):
        values.insert(key, point(*p))
    return factors, values, keys


def from_gtsam(gtsam: Any, w: dict[str, Any], values: Any, manifold: Blocks) -> Any:
    """GTSAM's solution as our values (poses of keys 0..n−1, landmarks in key order)."""
    u = gtsam.utilities
    if w["d"] == 2:
        xyt = u.extractPose2(values)
        c, s = np.cos(xyt[:, 2]), np.sin(xyt[:, 2])
        m = np.zeros((len(xyt), 3, 3))
        m[:, 0, 0], m[:, 0, 1], m[:, 1, 0], m[:, 1, 1] = c, -s, s, c
        m[:, :2, 2], m[:, 2, 2] = xyt[:, :2], 1.0
        return manifold.values(poses=SE2.from_matrix(m), landmarks=u.extractPoint2(values))
    a = u.extractPose3(values)  # (n, 12): R row by row, then t
    m = np.zeros((len(a), 4, 4))
    m[:, :3, :3], m[:, :3, 3], m[:, 3, 3] = a[:, :9].reshape(-1, 3, 3), a[:, 9:], 1.0
    return manifold.values(poses=SE3.from_matrix(m, project=True), landmarks=u.extractPoint3(values))


def bench(d: int, n: int, landmarks: int, repeat: int, marginals: bool, begin: str) -> dict[str, Any]:
    import gtsam

    w = world(d, n, landmarks)
    problem, x0 = ours(w)
    if begin == "near-truth":
        x0 = near_truth(w, problem.manifold)
    factors, values, keys = gtsam_problem(gtsam, w, x0)
    params = gtsam.LevenbergMarquardtParams()
    params.setRelativeErrorTol(RULE)
    params.setMaxIterations(100)
    outcomes = interleaved(
        [lambda: LevenbergMarquardt().solve(problem, x0),
         lambda: gtsam.LevenbergMarquardtOptimizer(factors, values, params).optimize()], repeat,
    )  # fmt: skip
    (t_ours, res), (t_gtsam, sol) = outcomes  # type: ignore[misc]
    x_gtsam = from_gtsam(gtsam, w, sol, problem.manifold)  # type: ignore[arg-type]
    f_ours, f_gtsam = res.fun, problem.cost(x_gtsam)
    row: dict[str, Any] = {
        "d": d, "start": begin, "poses": n, "landmarks": landmarks, "observations": len(w["graph"].observations),
        "ours_s": t_ours, "gtsam_s": t_gtsam, "ratio": t_ours / t_gtsam, "ours_nit": res.nit,
        "ours_status": res.status.name.lower(), "cost_ours": f_ours, "cost_gtsam_in_ours": f_gtsam,
        "cost_gtsam_own": factors.error(sol), "rel_cost_gap": (f_ours - f_gtsam) / abs(f_gtsam),
    }  # fmt: skip
    if marginals:
        def gtsam_marginals() -> Any:
            m = gtsam.Marginals(factors, sol)
            return [m.marginalCovariance(k) for k in keys]

        (t_mo, cov), (t_mg, gcov) = interleaved(  # type: ignore[misc]
            [lambda: marginal_covariances(problem, res.x, variables="landmarks"), gtsam_marginals], repeat
        )
        ours_cov = cov.stacked("landmarks")
        rel = max(float(np.abs(a - b).max() / np.abs(b).max()) for a, b in zip(ours_cov, gcov, strict=True))
        row |= {"marginals_ours_s": t_mo, "marginals_gtsam_s": t_mg, "marginals_ratio": t_mo / t_mg,
                "marginals_max_rel_difference": rel}  # fmt: skip
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--quick", action="store_true", help="a fifth of the sizes")
    parser.add_argument("--no-marginals", action="store_true")
    parser.add_argument("--starts", nargs="+", default=["odometry", "near-truth"], choices=["odometry", "near-truth"],
                        help="composed odometry (far: both libraries may stop in different local minima) and/or "
                        "the true poses perturbed (in the optimum's basin)")
    parser.add_argument("--json", type=Path, help="write the rows as JSON")
    args = parser.parse_args()
    scale = 5 if args.quick else 1
    rows = [bench(d, n // scale, count // scale, args.repeat, not args.no_marginals, begin)
            for begin in args.starts for d, n, count in ((2, 10_000, 2_000), (3, 5_000, 1_000))]  # fmt: skip
    print("| world | start | poses | landmarks | observations | ours (s) | GTSAM (s) | ratio | iterations | "
          "cost gap | marginals ours (s) | GTSAM (s) | ratio |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        marg = (f"{r['marginals_ours_s']:.3f} | {r['marginals_gtsam_s']:.3f} | {r['marginals_ratio']:.2f}"
                if "marginals_ratio" in r else "— | — | —")  # fmt: skip
        print(f"| {r['d']}-D | {r['start']} | {r['poses']} | {r['landmarks']} | {r['observations']} | "
              f"{r['ours_s']:.3f} | {r['gtsam_s']:.3f} | {r['ratio']:.2f} | {r['ours_nit']} | "
              f"{r['rel_cost_gap']:+.1e} | {marg} |")

    if args.json:
        write_json(args.json, rows)


if __name__ == "__main__":
    main()
