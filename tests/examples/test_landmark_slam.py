"""Graph-based landmark SLAM (the seed notes' "Graph-SLAM: least squares on manifold"), in
2-D and 3-D, with known truth: poses, landmarks, odometry and relative-point observations
(``LandmarkGraph``), and a range-bearing variant assembled from the factor library on
``Blocks``; solved by Levenberg-Marquardt from the odometry.

Checked over Monte-Carlo runs (one simulated world per seed, fixed seeds):

- the chi-square at the optimum, ``Σ rᵀΩr = 2f ~ χ²(dof)``, ``dof = #residual entries −
  #free tangent coordinates``: its sum over runs within the 0.1 %–99.9 % quantiles of
  ``χ²(Σ dof)``, and at most one run outside its own;
- the marginals against the actual errors ``e_v = truth ⊖ estimate`` (right tangent of the
  estimate): the joint NEES ``τᵀHτ ~ χ²(#free)`` (exact to first order), averaged over the
  independent runs, within ``χ²(runs·#free)/runs``; the mean per-variable NEES (poses,
  landmarks) within ``χ²(runs·d)/runs`` — runs counted, not variables, since the
  variables of one run share their measurements (see docs/landmarks.md).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import pytest

from manopt_lie.factors import Diagonal, Information, between_factor, range_bearing_factor
from manopt_lie.optim import LeastSquaresProblem, LevenbergMarquardt, marginal_covariances
from manopt_lie.problems import synthetic
from manopt_lie.problems.estimation import chi2_interval, mean_nees_interval, nees, residual_chi2

N_POSES, N_LANDMARKS = 50, 15
RUNS = {2: 40, 3: 30}
SIGMA_RANGE, SIGMA_BEARING = 0.05, 0.01  # m, rad


@dataclass
class Runs:
    chi2: np.ndarray  # (runs,) Σ rᵀΩr at the optimum
    dof: np.ndarray  # (runs,)
    joint: np.ndarray  # (runs,) τᵀHτ over every free variable
    free: int  # free tangent coordinates
    poses: np.ndarray  # (runs,) mean NEES of the free poses
    landmarks: np.ndarray  # (runs,) mean NEES of the landmarks
    d: int
    pose_dim: int


def world(d: int, seed: int) -> synthetic.Instance:
    return synthetic.landmark_world(N_POSES, N_LANDMARKS, d=d, sensor_range=6.0 if d == 2 else 8.0, seed=seed)


def range_bearing_problem(inst: synthetic.Instance, rng: np.random.Generator):
    """The world's odometry and observed pairs, measured as range and bearing instead: ranges
    ``‖p‖ + n_ρ``; bearings (2-D) ``∠p + n_β``, (3-D) the direction turned by ``n_β`` about an
    axis ⟂ to it; on ``Blocks(poses, landmarks)``. Returns the problem and a start (poses by
    odometry, each landmark at the mean of the points its measurements put it at)."""
    graph, truth = inst.graph, inst.truth
    d, obs = graph.d, graph.observations
    p = truth["poses"][obs[:, 0]].inverse().act(truth["landmarks"][obs[:, 1]])
    rho = np.linalg.norm(p, axis=1) + SIGMA_RANGE * rng.standard_normal(len(p))
    if d == 2:
        bearing = np.arctan2(p[:, 1], p[:, 0]) + SIGMA_BEARING * rng.standard_normal(len(p))
        direction = np.stack([np.cos(bearing), np.sin(bearing)], axis=1)
    else:
        unit = p / np.linalg.norm(p, axis=1, keepdims=True)
        tangent = rng.standard_normal(p.shape)
        tangent -= np.sum(tangent * unit, axis=1, keepdims=True) * unit
        angle = SIGMA_BEARING * np.linalg.norm(tangent, axis=1, keepdims=True)
        axis = tangent / np.linalg.norm(tangent, axis=1, keepdims=True)
        bearing = direction = np.cos(angle) * unit + np.sin(angle) * axis  # exactly an angle |n_β| from p̂
    pg = graph.poses
    factors = [
        between_factor(pg.edges, pg.measurements, Information(pg.information), name="odometry", blocks="poses"),
        range_bearing_factor(obs, rho, bearing, Diagonal([SIGMA_RANGE] + [SIGMA_BEARING] * (d - 1)),
                             name="range-bearing", blocks=("poses", "landmarks")),
    ]  # fmt: skip
    problem = LeastSquaresProblem(graph.manifold, factors, fixed={"poses": [0]})
    poses = graph.poses.initialize("odometry")
    seen = poses[obs[:, 0]].act(rho[:, None] * direction)
    total = np.zeros((graph.n_landmarks, d))
    np.add.at(total, obs[:, 1], seen)
    landmarks = total / np.bincount(obs[:, 1], minlength=graph.n_landmarks)[:, None]
    return problem, graph.values(poses, landmarks)


@functools.cache
def monte_carlo(d: int, kind: str) -> Runs:
    rows = []
    for seed in range(RUNS[d]):
        inst = world(d, seed)
        if kind == "relative point":
            problem, start = inst.graph.problem(), inst.graph.initialize("odometry")
        else:
            problem, start = range_bearing_problem(inst, np.random.default_rng(1000 + seed))
        result = LevenbergMarquardt().solve(problem, start)
        assert result.success, result.message
        x, truth = result.x, inst.truth
        value, dof = residual_chi2(problem, x)
        cov = marginal_covariances(problem, x)
        free = cov.indices("poses")
        e_poses = truth["poses"][free].rminus(x["poses"][free])  # truth ⊖ estimate, right tangent
        e_landmarks = truth["landmarks"] - x["landmarks"]
        tau = problem.manifold.join([truth["poses"].rminus(x["poses"]), e_landmarks])
        joint = float(tau @ (problem.linearize(x).hessian @ tau))  # τᵀ Σ⁻¹ τ with Σ = H⁻¹
        rows.append((value, dof, joint, nees(e_poses, cov.stacked("poses")).mean(),
                     nees(e_landmarks, cov.stacked("landmarks")).mean()))  # fmt: skip
    a = np.array(rows)
    n_free = int(np.sum(problem.dims[~problem.fixed]))
    return Runs(a[:, 0], a[:, 1].astype(int), a[:, 2], n_free, a[:, 3], a[:, 4], d, problem.manifold.block_dims[0])


CASES = [(2, "relative point"), (3, "relative point"), (2, "range-bearing"), (3, "range-bearing")]


@pytest.mark.parametrize(("d", "kind"), CASES)
def test_chi_square_at_the_optimum_matches_its_degrees_of_freedom(d, kind):
    runs = monte_carlo(d, kind)
    lo, hi = chi2_interval(runs.dof.sum())
    assert lo < runs.chi2.sum() < hi, (runs.chi2.sum() / runs.dof.sum(), lo / runs.dof.sum(), hi / runs.dof.sum())
    bounds = np.array([chi2_interval(k) for k in runs.dof])
    outside = (runs.chi2 < bounds[:, 0]) | (runs.chi2 > bounds[:, 1])
    assert outside.sum() <= 1, runs.chi2[outside] / runs.dof[outside]


@pytest.mark.parametrize(("d", "kind"), CASES)
def test_joint_nees_matches_the_free_dimension(d, kind):
    runs = monte_carlo(d, kind)
    lo, hi = mean_nees_interval(runs.free, len(runs.joint))
    assert lo < runs.joint.mean() < hi, (runs.joint.mean(), lo, hi, runs.free)


@pytest.mark.parametrize(("d", "kind"), CASES)
def test_marginals_are_consistent_with_the_errors(d, kind):
    runs = monte_carlo(d, kind)
    for mean, dim in ((runs.poses.mean(), runs.pose_dim), (runs.landmarks.mean(), runs.d)):
        lo, hi = mean_nees_interval(dim, len(runs.poses))
        assert lo < mean < hi, (mean, dim, lo, hi)
