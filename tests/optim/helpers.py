"""Pose chains with loop closures, built from factor arrays, for the least-squares tests."""

from __future__ import annotations

import numpy as np

from manopt_lie.manifolds import LieGroupManifold, Power
from manopt_lie.optim import Factor, LeastSquaresProblem


def between(z):
    """The residual ``(Xᵢ⁻¹Xⱼ) ⊖ Z`` of relative-pose measurements ``Z`` and its Jacobians."""

    def residual(xi, xj, jac):
        if not jac:
            return xi.between(xj).rminus(z)
        e, j_i, j_j = xi.between(xj, jac=True)
        r, j_e, _ = e.rminus(z, jac=True)
        return r, [j_e @ j_i, j_e @ j_j]

    return residual


def pose_chain(group, n=40, closures=15, seed=0, noise=0.0):
    """A random-walk trajectory, odometry and loop-closure measurements (exact, or perturbed
    by ``Exp(noise·randn)`` so that the optimum has a positive cost), the problem with pose 0
    fixed, the truth and a perturbed start."""
    rng = np.random.default_rng(seed)
    steps = 0.3 * rng.standard_normal((n - 1, group.dim))
    poses = [group.identity()]
    for s in steps:
        poses.append(poses[-1].rplus(s))
    truth = group.stack(poses)
    odometry = np.stack([np.arange(n - 1), np.arange(1, n)], axis=1)
    loops = rng.choice(n, size=(closures, 2))
    loops = loops[loops[:, 0] != loops[:, 1]]
    edges = np.concatenate([odometry, loops])
    z = truth[edges[:, 0]].between(truth[edges[:, 1]])
    if noise:
        z = z.rplus(noise * np.random.default_rng(seed + 1).standard_normal((len(edges), group.dim)))
    problem = LeastSquaresProblem(
        Power(LieGroupManifold(group), n), [Factor(edges, between(z), name="between")], fixed=[0]
    )
    perturbation = 0.1 * rng.standard_normal((n, group.dim))
    perturbation[0] = 0.0
    return problem, truth, truth.rplus(perturbation)
