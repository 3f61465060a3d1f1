"""Synthetic landmark worlds: a robot driving laps among landmarks it sees within its range.

The graph-SLAM example of the seed notes with a known truth: poses along a circle (2-D)
or a helix (3-D), expressed in the first pose's frame (``X₀ = I``), odometry between
consecutive poses, and relative-point observations ``z = X⁻¹ l + η`` of the landmarks
within ``sensor_range`` (the ``max_observations`` nearest), which close the loops. Noise model as for pose graphs
(:mod:`manopt_lie.problems.synthetic`): odometry ``Z = (X_i⁻¹X_j) ⊕ ε``,
``ε ~ N(0, diag(σ_t² I, σ_R² I))``; points ``η ~ N(0, σ_p² I)`` in the pose's frame; the
information matrices are the inverse covariances, so the cost is the exact negative
log-likelihood at the truth. Each observation is an outlier (a uniformly random point
within range) with probability ``outlier_rate``; odometry never is.
"""

from __future__ import annotations

import numbers
from typing import Any

import numpy as np

from manopt_lie import SE2, SE3, SO2, SO3

from ..landmarks import LandmarkGraph
from ..pose_graph import PoseGraph
from .base import (
    DEFAULT_ROTATION_NOISE,
    DEFAULT_TRANSLATION_NOISE,
    FloatArray,
    Instance,
    IntArray,
    _nonnegative,
    _positive,
    _probability,
    _size,
    _weights,
)

__all__ = ["landmark_world"]

DEFAULT_POINT_NOISE = 0.05  # metres


def _trajectory(n: int, d: int, laps: float, radius: float) -> tuple[Any, FloatArray]:
    """Poses along ``laps`` laps of a circle (2-D) or a helix climbing ``radius/2`` (3-D),
    each heading along the path."""
    psi = 2 * np.pi * laps * np.arange(n) / n
    xy = radius * np.stack([np.cos(psi), np.sin(psi)], axis=1)
    if d == 2:
        return SE2.from_rotation_translation(SO2.from_angle(psi + np.pi / 2), xy), xy
    z = 0.5 * radius * np.arange(n) / n
    positions = np.concatenate([xy, z[:, None]], axis=1)
    rotation = SO3.exp(np.stack([np.zeros(n), np.zeros(n), psi + np.pi / 2], axis=1))
    return SE3.from_rotation_translation(rotation, positions), positions


def _distances(positions: FloatArray, landmarks: FloatArray, min_range: float) -> FloatArray:
    """Pose–landmark distances, ``inf`` below the sensor's ``min_range``."""
    dist = np.linalg.norm(positions[:, None, :] - landmarks[None, :, :], axis=-1)
    return np.where(dist < min_range, np.inf, dist)


def _nearest(positions: FloatArray, landmarks: FloatArray, sensor_range: float, k: int, min_range: float) -> IntArray:
    """``(pose, landmark)`` pairs: the ``k`` nearest landmarks within range of each pose, computed
    in blocks of poses (memory: a block × landmarks distance matrix)."""
    pairs = []
    block = max(1, 2_000_000 // max(len(landmarks), 1))
    for start in range(0, len(positions), block):  # over blocks of poses, not poses
        p = positions[start : start + block]
        dist = _distances(p, landmarks, min_range)
        order = np.argsort(dist, axis=1)[:, :k]
        near = np.take_along_axis(dist, order, axis=1) <= sensor_range
        rows = np.nonzero(near)
        pairs.append(np.stack([rows[0] + start, order[rows]], axis=1))
    return np.concatenate(pairs).astype(np.int64)


def landmark_world(
    n_poses: int = 200,
    n_landmarks: int = 50,
    *,
    d: int = 2,
    laps: float = 2.0,
    radius: float = 10.0,
    sensor_range: float = 6.0,
    min_range: float = 0.0,
    max_observations: int = 10,
    translation_noise: float = DEFAULT_TRANSLATION_NOISE,
    rotation_noise: float = DEFAULT_ROTATION_NOISE,
    point_noise: float = DEFAULT_POINT_NOISE,
    outlier_rate: float = 0.0,
    prior: bool = False,
    seed: int = 0,
) -> Instance:
    """A landmark-SLAM instance with its ground truth (module doc).

    Parameters
    ----------
    n_poses, n_landmarks : int ≥ 2
    d : {2, 3}
    laps : float > 0
        How many times the robot goes round (revisits close the loops through landmarks).
    radius : float > 0
        Of the circle (2-D) or helix (3-D); landmarks are uniform in the annulus
        ``[radius/2, 3 radius/2]`` (3-D: times the helix's height range, widened by ``radius/4``).
    sensor_range : float > 0
        Landmarks no pose would see are moved within range of a random pose, and one that is
        among no pose's nearest ``max_observations`` is seen by its nearest pose: each is seen.
    min_range : float ≥ 0
        Landmarks nearer than this are not seen (a sensor's minimum range: a bearing to a point
        on the sensor has no meaning); below ``sensor_range / 2``.
    max_observations : int ≥ 1
        Per pose, at most this many (the nearest) landmarks are seen.
    translation_noise, rotation_noise, point_noise : float ≥ 0
    outlier_rate : float in [0, 1]
    prior : bool
        Add a prior on pose 0 (mean ``X₀ ⊕ ε``, ``ε`` drawn with the odometry's noise, and
        the odometry's information) instead of holding it fixed.
    seed : int

    Returns
    -------
    Instance
        ``graph`` a :class:`~manopt_lie.problems.LandmarkGraph` named
        ``"landmarks{d}d-{n_poses}x{n_landmarks}-seed{seed}"``; ``truth`` its
        :class:`~manopt_lie.manifolds.Values` (poses, landmarks); ``outliers`` a mask over the
        observations; ``backbone`` the odometry edges. Pose ids are ``0..n−1``, landmark ids
        start at the next power of ten (``1000`` for 200 poses).
    """
    params = dict(locals())
    n, count = _size("n_poses", n_poses), _size("n_landmarks", n_landmarks)
    if isinstance(d, bool) or not isinstance(d, numbers.Integral) or d not in (2, 3):
        raise ValueError(f"d must be 2 or 3, got {d!r}")
    laps, radius, reach = _positive("laps", laps), _positive("radius", radius), _positive("sensor_range", sensor_range)
    k = _size("max_observations", max_observations, 1)
    closest = _nonnegative("min_range", min_range)
    if closest >= 0.5 * reach:
        raise ValueError(f"min_range must be below half the sensor_range, got {min_range} and {sensor_range}")
    sigma_t = _nonnegative("translation_noise", translation_noise)
    sigma_r = _nonnegative("rotation_noise", rotation_noise)
    sigma_p, rate = _nonnegative("point_noise", point_noise), _probability("outlier_rate", outlier_rate)
    rng = np.random.default_rng(seed)
    group = SE2 if d == 2 else SE3

    truth, positions = _trajectory(n, d, laps, radius)
    angle = rng.uniform(0, 2 * np.pi, count)
    rho = radius * np.sqrt(rng.uniform(0.25, 2.25, count))  # uniform over the annulus' area
    points = np.stack([rho * np.cos(angle), rho * np.sin(angle)], axis=1)
    if d == 3:
        points = np.concatenate([points, rng.uniform(-0.25 * radius, 0.75 * radius, (count, 1))], axis=1)
    # The world in the first pose's frame: X₀ = I, so the initializations' gauge is the truth's.
    to_first = truth[0].inverse()
    truth, points = to_first @ truth, to_first.act(points)
    positions = truth.as_matrix()[:, :d, d]

    odometry = np.stack([np.arange(n - 1), np.arange(1, n)], axis=1)
    dim = group.dim
    sigma = np.repeat([sigma_t, sigma_r], [d, dim - d]).astype(np.float64)
    z = truth[odometry[:, 0]].between(truth[odometry[:, 1]]).rplus(rng.standard_normal((n - 1, dim)) * sigma)
    information = np.broadcast_to(np.diag(_weights(sigma)), (n - 1, dim, dim)).copy()

    # A landmark no pose sees would be undetermined: move it within range of a random pose.
    lonely = np.setdiff1d(np.arange(count), _nearest(positions, points, reach, k, closest)[:, 1])
    if lonely.size:
        offset_dir = rng.standard_normal((lonely.size, d))
        offset_dir *= (0.5 * reach / np.linalg.norm(offset_dir, axis=1))[:, None]
        points[lonely] = positions[rng.integers(0, n, lonely.size)] + offset_dir
    seen = _nearest(positions, points, reach, k, closest)
    lonely = np.setdiff1d(np.arange(count), seen[:, 1])  # within range but never among a pose's nearest k
    if lonely.size:
        nearest = np.argmin(_distances(positions, points[lonely], closest), axis=0)
        seen = np.concatenate([seen, np.stack([nearest, lonely], axis=1)])
        seen = seen[np.lexsort((seen[:, 1], seen[:, 0]))]
    if not len(seen):
        raise ValueError(f"no landmark within sensor_range={reach} of any pose: widen it")
    measured = truth[seen[:, 0]].inverse().act(points[seen[:, 1]]) + sigma_p * rng.standard_normal((len(seen), d))
    outliers = rng.random(len(seen)) < rate
    direction = rng.standard_normal((int(outliers.sum()), d))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    measured[outliers] = direction * reach * rng.uniform(0, 1, (len(direction), 1)) ** (1 / d)

    # The prior's mean is sampled from its own noise, like every other measurement.
    prior_mean = truth[:1].rplus(rng.standard_normal((1, dim)) * sigma) if prior else None
    offset = 10 ** len(str(n))
    poses = PoseGraph(group, odometry, z, information, name=f"landmarks{d}d-{n}x{count}-seed{seed}",
                      fixed=np.zeros(0 if prior else 1, dtype=np.int64))  # fmt: skip
    point_info = np.broadcast_to(np.eye(d) * _weights(np.array(sigma_p)), (len(seen), d, d)).copy()
    priors = np.zeros(1 if prior else 0, dtype=np.int64)
    graph = LandmarkGraph(
        poses, landmark_ids=offset + np.arange(count), observations=seen, points=measured,
        point_information=point_info, prior_poses=priors, prior_means=prior_mean,
        prior_information=information[:1] if prior else None, name=poses.name,
    )  # fmt: skip
    values = graph.manifold.values(poses=truth, landmarks=points)
    return Instance(graph, values, outliers, params, np.ones(n - 1, dtype=bool))  # type: ignore[arg-type]
