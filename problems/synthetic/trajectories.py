"""Synthetic SE(2)/SE(3) trajectories with loop closures: SE-Sync's cube, planar grids,
a sphere, a torus and circles (the noise model: :mod:`manopt_lie.problems.synthetic`)."""

from __future__ import annotations

from math import prod
from typing import Any

import numpy as np

from manopt_lie import SE2, SE3, SO2, SO3
from manopt_lie.lie.base import LieGroup

from .base import (
    DEFAULT_ROTATION_NOISE,
    DEFAULT_TRANSLATION_NOISE,
    FloatArray,
    Instance,
    IntArray,
    Orientation,
    _check_noise,
    _orientation,
    _positive,
    _size,
    _trajectory_instance,
)


def _frames(heading: FloatArray, normal: FloatArray) -> SO3:
    """Rotations ``[x, z × x, z]`` with ``x`` the heading and ``z`` the (orthogonal) normal, ``(n, 3)`` each."""
    return SO3.from_matrix(np.stack([heading, np.cross(normal, heading), normal], axis=-1))


# ---- grids ----------------------------------------------------------------------------

# The rotation whose x axis points along +e_0, −e_0, +e_1, −e_1, (+e_2, −e_2): yaw by 0, π,
# ±π/2, then pitch by ∓π/2, with exact entries so that noise-free odometry is exact.
_HEADINGS = {
    2: np.array([[[1, 0], [0, 1]], [[-1, 0], [0, -1]], [[0, -1], [1, 0]], [[0, 1], [-1, 0]]], dtype=np.float64),
    3: np.array(
        [
            [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
            [[-1, 0, 0], [0, -1, 0], [0, 0, 1]],
            [[0, -1, 0], [1, 0, 0], [0, 0, 1]],
            [[0, 1, 0], [-1, 0, 0], [0, 0, 1]],
            [[0, 0, -1], [0, 1, 0], [1, 0, 0]],
            [[0, 0, 1], [0, 1, 0], [-1, 0, 0]],
        ],
        dtype=np.float64,
    ),
}


def _snake(shape: tuple[int, ...]) -> IntArray:
    """Integer coordinates ``(n, len(shape))`` of the boustrophedon path through a grid.

    Axis 0 runs fastest. Coordinate ``a`` of the ``k``-th pose is ``c = ⌊k / s_<a⌋ mod s_a``
    (``s_<a`` the product of the sizes of the faster axes), mirrored to ``s_a − 1 − c`` when
    ``⌊k / s_≤a⌋`` is odd: every line and every layer is run in the opposite direction to the
    previous one, so consecutive poses are grid neighbours.
    """
    k = np.arange(prod(shape))
    coords = np.empty((len(k), len(shape)), dtype=np.int64)
    stride = 1
    for axis, size in enumerate(shape):  # over the (2 or 3) axes, not the poses
        c = (k // stride) % size
        coords[:, axis] = np.where((k // (stride * size)) % 2 == 1, size - 1 - c, c)
        stride *= size
    return coords


def _grid_instance(
    shape: tuple[int, ...], group: type[LieGroup], rng: np.random.Generator, name: str, params: dict[str, Any]
) -> Instance:
    coords = _snake(shape)
    n, d = coords.shape
    rotation_group = group.rotation_group  # type: ignore[attr-defined]
    if params["orientation"] == "random":
        rotations = rotation_group.random(rng, (n,))
    else:  # look along the step to the next pose; the last pose keeps the last heading
        steps = np.diff(coords, axis=0)
        steps = np.concatenate([steps, steps[-1:]])
        axis = np.argmax(np.abs(steps), axis=1)
        code = 2 * axis + (steps[np.arange(n), axis] < 0)
        rotations = rotation_group.from_matrix(_HEADINGS[d][code])
    # Every pair of grid neighbours that is not consecutive on the path is a candidate.
    index = np.empty(shape, dtype=np.int64)
    index[tuple(coords.T)] = np.arange(n)
    pairs = []
    for axis in range(d):
        lines = np.moveaxis(index, axis, 0)
        pairs.append(np.stack([lines[:-1].ravel(), lines[1:].ravel()], axis=1))
    neighbours = np.sort(np.concatenate(pairs), axis=1)
    candidates = neighbours[neighbours[:, 1] - neighbours[:, 0] != 1]
    return _trajectory_instance(group, rotations, coords.astype(np.float64), candidates, rng, name, params)


def cube(
    side: int = 10,
    *,
    loop_closure_probability: float = 0.1,
    translation_noise: float = DEFAULT_TRANSLATION_NOISE,
    rotation_noise: float = DEFAULT_ROTATION_NOISE,
    outlier_rate: float = 0.0,
    orientation: Orientation = "path",
    seed: int = 0,
) -> Instance:
    """SE-Sync's cube: ``n = side³`` SE(3) poses on the unit grid ``{0, …, side−1}³``.

    The robot visits the grid along a boustrophedon (snake) path — rows along x,
    the rows of a layer along y, layers along z, each run in the opposite
    direction to the previous one — with odometry between consecutive poses.
    Loop closures join grid neighbours that are not consecutive on the path, each
    kept with ``loop_closure_probability``: ``m = n − 1 + B(3 side²(side−1) − n + 1, p)``.

    Parameters
    ----------
    side : int ≥ 2
    loop_closure_probability : float in [0, 1]
    translation_noise, rotation_noise : float ≥ 0
        ``σ_t`` (m) and ``σ_R`` (rad) of the tangent noise (module doc).
    outlier_rate : float in [0, 1]
        Probability that a loop closure is replaced by a random relative pose.
    orientation : {"path", "random"}
        ``"path"`` (default): each pose's x axis points to the next pose, z up when
        moving horizontally (relative rotations are multiples of 90°, as for a robot
        following the path). ``"random"``: Haar-random orientations.
    seed : int

    Returns
    -------
    Instance
        ``graph.name`` is ``"cube-{side}-seed{seed}"``.
    """
    params = dict(locals())
    side = _size("side", side)
    _check_noise(params)
    _orientation(orientation)
    return _grid_instance((side,) * 3, SE3, np.random.default_rng(seed), f"cube-{side}-seed{seed}", params)


def grid2d(
    rows: int = 20,
    cols: int = 20,
    *,
    loop_closure_probability: float = 0.1,
    translation_noise: float = DEFAULT_TRANSLATION_NOISE,
    rotation_noise: float = DEFAULT_ROTATION_NOISE,
    outlier_rate: float = 0.0,
    orientation: Orientation = "path",
    seed: int = 0,
) -> Instance:
    """The planar cube: ``n = rows·cols`` SE(2) poses on the unit grid, visited row by row
    along a snake path (x = column, y = row).

    Loop closures join grid neighbours that are not consecutive on the path, each kept
    with ``loop_closure_probability``: ``m = n − 1 + B(rows(cols−1) + cols(rows−1) − n + 1, p)``.
    Other parameters as in :func:`cube`; ``graph.name`` is ``"grid2d-{rows}x{cols}-seed{seed}"``.
    """
    params = dict(locals())
    rows, cols = _size("rows", rows), _size("cols", cols)
    _check_noise(params)
    _orientation(orientation)
    return _grid_instance((cols, rows), SE2, np.random.default_rng(seed), f"grid2d-{rows}x{cols}-seed{seed}", params)


# ---- trajectories on surfaces ----------------------------------------------------------


def sphere(
    n_rings: int = 50,
    poses_per_ring: int = 50,
    radius: float = 10.0,
    *,
    loop_closure_probability: float = 1.0,
    translation_noise: float = DEFAULT_TRANSLATION_NOISE,
    rotation_noise: float = DEFAULT_ROTATION_NOISE,
    outlier_rate: float = 0.0,
    seed: int = 0,
) -> Instance:
    """A sphere2500-like SE(3) trajectory spiralling up a sphere, ``n = n_rings·poses_per_ring``.

    Pose ``i`` (``P = poses_per_ring``) sits at azimuth ``ψ = 2πi/P`` and polar angle
    ``φ = π(i/P + 1)/(n_rings + 1)`` measured from the south pole,
    ``p_i = r (sin φ cos ψ, sin φ sin ψ, −cos φ)``: one ring per lap, climbing
    continuously. Its x axis is tangent to the ring, ``(−sin ψ, cos ψ, 0)``, its z axis
    the outward normal. Odometry joins consecutive poses; loop closures join each pose
    to the corresponding pose of the previous ring, ``(i − P, i)``, each kept with
    ``loop_closure_probability``: ``m = n − 1 + B(n − P, p)`` (sphere2500: 50 × 50,
    m = 4949). ``graph.name`` is ``"sphere-{n_rings}x{poses_per_ring}-seed{seed}"``.
    """
    params = dict(locals())
    rings, per = _size("n_rings", n_rings), _size("poses_per_ring", poses_per_ring)
    radius = _positive("radius", radius)
    _check_noise(params)
    rng = np.random.default_rng(seed)
    i = np.arange(rings * per)
    psi, phi = 2 * np.pi * i / per, np.pi * (i / per + 1) / (rings + 1)
    normal = np.stack([np.sin(phi) * np.cos(psi), np.sin(phi) * np.sin(psi), -np.cos(phi)], axis=1)
    heading = np.stack([-np.sin(psi), np.cos(psi), np.zeros_like(psi)], axis=1)
    closures = np.stack([i[:-per], i[per:]], axis=1)
    name = f"sphere-{rings}x{per}-seed{seed}"
    return _trajectory_instance(SE3, _frames(heading, normal), radius * normal, closures, rng, name, params)


def torus(
    n_laps: int = 10,
    poses_per_lap: int = 100,
    major_radius: float = 10.0,
    minor_radius: float = 3.0,
    *,
    loop_closure_probability: float = 1.0,
    translation_noise: float = DEFAULT_TRANSLATION_NOISE,
    rotation_noise: float = DEFAULT_ROTATION_NOISE,
    outlier_rate: float = 0.0,
    seed: int = 0,
) -> Instance:
    """An SE(3) trajectory winding around a torus, ``n = n_laps·poses_per_lap``, laps side by side.

    Pose ``i`` (``P = poses_per_lap``) has angle ``u = 2πi/P`` around the axis and
    ``v = 2πi/n`` around the tube, ``p_i = ((R + r cos v) cos u, (R + r cos v) sin u, r sin v)``:
    each lap goes once around the axis while the tube angle advances by ``2π/n_laps``, so
    after the last lap the trajectory is back at its start. The x axis is ``(−sin u, cos u, 0)``
    (along the laps), the z axis the outward normal of the torus. Loop closures join each
    pose to the same ``u`` on the next lap, the last lap to the first,
    ``(i, (i + P) mod n)``, each kept with ``loop_closure_probability``:
    ``m = n − 1 + B(n, p)``. Needs ``n_laps ≥ 3`` and ``minor_radius < major_radius``.
    ``graph.name`` is ``"torus-{n_laps}x{poses_per_lap}-seed{seed}"``.
    """
    params = dict(locals())
    laps, per = _size("n_laps", n_laps, 3), _size("poses_per_lap", poses_per_lap)
    big, small = _positive("major_radius", major_radius), _positive("minor_radius", minor_radius)
    if small >= big:
        raise ValueError(f"minor_radius must be < major_radius, got {minor_radius} ≥ {major_radius}")
    _check_noise(params)
    rng = np.random.default_rng(seed)
    n = laps * per
    i = np.arange(n)
    u, v = 2 * np.pi * i / per, 2 * np.pi * i / n
    normal = np.stack([np.cos(v) * np.cos(u), np.cos(v) * np.sin(u), np.sin(v)], axis=1)
    heading = np.stack([-np.sin(u), np.cos(u), np.zeros_like(u)], axis=1)
    centre = big * np.stack([np.cos(u), np.sin(u), np.zeros_like(u)], axis=1)
    closures = np.stack([i, (i + per) % n], axis=1)
    name = f"torus-{laps}x{per}-seed{seed}"
    return _trajectory_instance(SE3, _frames(heading, normal), centre + small * normal, closures, rng, name, params)


def circle2d(
    n_laps: int = 5,
    poses_per_lap: int = 100,
    radius: float = 10.0,
    *,
    loop_closure_probability: float = 1.0,
    translation_noise: float = DEFAULT_TRANSLATION_NOISE,
    rotation_noise: float = DEFAULT_ROTATION_NOISE,
    outlier_rate: float = 0.0,
    seed: int = 0,
) -> Instance:
    """A planar SE(2) trajectory driving ``n_laps`` times counter-clockwise around a circle,
    ``n = n_laps·poses_per_lap``.

    Pose ``i`` (``P = poses_per_lap``) has angle ``ψ = 2πi/P`` and distance
    ``r(1 + 0.1 i/P)`` from the origin (each lap 10 % of ``r`` wider, so revisited places
    are near, not identical), heading ``ψ + π/2``. Loop closures join each pose to the
    same ``ψ`` on the previous lap, ``(i − P, i)``, each kept with
    ``loop_closure_probability``: ``m = n − 1 + B(n − P, p)``.
    ``graph.name`` is ``"circle2d-{n_laps}x{poses_per_lap}-seed{seed}"``.
    """
    params = dict(locals())
    laps, per = _size("n_laps", n_laps), _size("poses_per_lap", poses_per_lap)
    radius = _positive("radius", radius)
    _check_noise(params)
    rng = np.random.default_rng(seed)
    i = np.arange(laps * per)
    psi = 2 * np.pi * i / per
    positions = (radius * (1 + 0.1 * i / per))[:, None] * np.stack([np.cos(psi), np.sin(psi)], axis=1)
    closures = np.stack([i[:-per], i[per:]], axis=1)
    name = f"circle2d-{laps}x{per}-seed{seed}"
    return _trajectory_instance(SE2, SO2.from_angle(psi + np.pi / 2), positions, closures, rng, name, params)
