"""Synthetic pose-graph and rotation-averaging instances with known ground truth.

Every generator is reproducible from ``seed`` (``np.random.default_rng(seed)``),
vectorized (10⁵ poses in a fraction of a second) and returns an :class:`Instance`:
the problem, the ground truth it was sampled from, the mask of corrupted edges
and the generator's arguments.

Noise model (poses)
    ``Z_e = (X_i⁻¹ X_j) ⊕ ε = X_i⁻¹ X_j Exp(ε)``, ``ε ~ N(0, Σ)`` in tangent
    coordinates ``(ρ, θ)`` (CONVENTIONS §2), ``Σ = diag(σ_t² I_d, σ_R² I_r)``.
    The information matrix is ``Ω = Σ⁻¹``, so the geodesic cost ``½ Σ rᵀΩr``,
    ``r = Log(Z⁻¹ X_i⁻¹ X_j) = −ε`` at the truth, is the exact negative
    log-likelihood. An exact component (``σ = 0``) gets the weight
    :data:`EXACT_WEIGHT` ``= 1`` instead of ``∞``: with noise-free measurements
    ``Ω = I``, and the truth is a zero-cost global optimum whatever the weights.
Outliers
    Each edge off the *backbone* (the odometry chain of a trajectory, the random
    Hamiltonian path of a rotation-averaging graph) is corrupted independently
    with probability ``outlier_rate``: its measurement is replaced by a uniformly
    random relative pose (Haar rotation; translation uniform in the box
    ``[−e, e]`` of every displacement within the scene, ``e`` the extent of the
    true positions per axis) while keeping the nominal information. The backbone
    is never corrupted, so the inlier graph stays connected and the truth stays
    identifiable (up to the global gauge).
Edges
    Edge ``(i, j)`` has ``i < j``. Trajectories number their poses along the
    trajectory: the first ``n − 1`` edges are the odometry ``(k, k+1)``, then the
    loop closures in lexicographic order, each candidate kept independently with
    probability ``loop_closure_probability``.

The random stream is consumed in a fixed order (truth, edges, noise, outlier mask,
outlier values), so a seed gives the same instance on every platform for a given
version of this module.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from math import prod
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from manopt_lie import SE2, SE3, SO2, SO3
from manopt_lie.lie.base import LieGroup

from . import evaluation
from .pose_graph import PoseGraph
from .rotation_averaging import RotationAveraging

__all__ = ["EXACT_WEIGHT", "Instance", "circle2d", "cube", "grid2d", "rotation_averaging", "sphere", "torus"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]
Orientation = Literal["path", "random"]

EXACT_WEIGHT = 1.0
"""Information weight of a noise-free component (``σ = 0``), and ``κ`` of noise-free rotation averaging."""

DEFAULT_TRANSLATION_NOISE = 0.05  # metres
DEFAULT_ROTATION_NOISE = 0.01  # radians


@dataclass(frozen=True, eq=False)
class Instance:
    """A synthetic problem with its ground truth.

    Attributes
    ----------
    graph : PoseGraph or RotationAveraging
        The problem; its measurements were sampled from ``truth``.
    truth : group element, batch ``(n,)``
        The ground-truth poses or rotations.
    outliers : bool ``(m,)``
        Edges whose measurement was replaced by a random one.
    params : dict
        The generator's arguments (including ``seed``).
    backbone : bool ``(m,)``
        Edges guaranteeing connectivity (odometry, or a Hamiltonian path), never outliers.
    """

    graph: PoseGraph | RotationAveraging
    truth: LieGroup
    outliers: BoolArray
    params: dict[str, Any]
    backbone: BoolArray

    @property
    def n(self) -> int:
        return self.graph.n

    @property
    def m(self) -> int:
        return self.graph.m

    def errors(self, estimate: LieGroup) -> evaluation.Errors:
        """Per-element rotation (rad) and translation errors of ``estimate`` after the
        best global alignment to :attr:`truth` (:func:`problems.evaluation.errors`)."""
        return evaluation.errors(estimate, self.truth)

    def __repr__(self) -> str:
        return f"Instance({self.graph!r}, outliers={int(self.outliers.sum())})"


# ---- argument checks ----------------------------------------------------------------


def _size(name: str, value: Any, minimum: int = 2) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise ValueError(f"{name} must be an integer ≥ {minimum}, got {value!r}")
    if value < minimum:
        raise ValueError(f"{name} must be ≥ {minimum}, got {value}")
    return int(value)


def _real(name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value):
        raise ValueError(f"{name} must be a finite real number, got {value!r}")
    return float(value)


def _probability(name: str, value: Any) -> float:
    p = _real(name, value)
    if not 0.0 <= p <= 1.0:
        raise ValueError(f"{name} must lie in [0, 1], got {value}")
    return p


def _nonnegative(name: str, value: Any) -> float:
    x = _real(name, value)
    if x < 0.0:
        raise ValueError(f"{name} must be ≥ 0, got {value}")
    return x


def _positive(name: str, value: Any) -> float:
    x = _real(name, value)
    if x <= 0.0:
        raise ValueError(f"{name} must be > 0, got {value}")
    return x


def _orientation(value: Any) -> Orientation:
    if value not in ("path", "random"):
        raise ValueError(f"orientation must be 'path' or 'random', got {value!r}")
    return value  # type: ignore[no-any-return]


def _check_noise(params: dict[str, Any]) -> None:
    _nonnegative("translation_noise", params["translation_noise"])
    _nonnegative("rotation_noise", params["rotation_noise"])
    _probability("outlier_rate", params["outlier_rate"])
    _probability("loop_closure_probability", params["loop_closure_probability"])


# ---- shared machinery ---------------------------------------------------------------


def _weights(sigma: FloatArray) -> FloatArray:
    """``1/σ²``, and :data:`EXACT_WEIGHT` where ``σ = 0``."""
    return np.where(sigma > 0, 1.0 / np.where(sigma > 0, sigma, 1.0) ** 2, EXACT_WEIGHT)


def _replace(measurements: LieGroup, mask: BoolArray, values: LieGroup) -> LieGroup:
    """``measurements`` with the entries under ``mask`` replaced, in order, by ``values``."""
    index = np.arange(len(mask))
    index[mask] = len(mask) + np.arange(int(mask.sum()))
    return type(measurements).concatenate([measurements, values])[index]


def _sorted_pairs(pairs: IntArray) -> IntArray:
    """Rows ``(min, max)``, in lexicographic order."""
    pairs = np.sort(pairs, axis=1)
    return pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]


def _trajectory_instance(
    group: type[LieGroup],
    rotations: LieGroup,
    positions: FloatArray,
    candidates: IntArray,
    rng: np.random.Generator,
    name: str,
    params: dict[str, Any],
) -> Instance:
    """Poses along a trajectory ``0, 1, …, n−1``: odometry ``(k, k+1)`` plus each loop-closure
    candidate kept with ``loop_closure_probability``; noise and outliers as in the module doc."""
    n, d = positions.shape
    truth = group.from_rotation_translation(rotations, positions)  # type: ignore[attr-defined]
    candidates = _sorted_pairs(candidates)
    closures = candidates[rng.random(len(candidates)) < params["loop_closure_probability"]]
    odometry = np.stack([np.arange(n - 1), np.arange(1, n)], axis=1)
    edges = np.concatenate([odometry, closures]).astype(np.int64)
    m, k = len(edges), group.dim
    backbone = np.arange(m) < n - 1

    sigma = np.repeat([params["translation_noise"], params["rotation_noise"]], [d, k - d]).astype(np.float64)
    measurements = truth[edges[:, 0]].between(truth[edges[:, 1]]).rplus(rng.standard_normal((m, k)) * sigma)

    outliers = ~backbone & (rng.random(m) < params["outlier_rate"])
    count = int(outliers.sum())
    extent = np.ptp(positions, axis=0)
    wild = group.from_rotation_translation(  # type: ignore[attr-defined]
        group.rotation_group.random(rng, (count,)),  # type: ignore[attr-defined]
        rng.uniform(-extent, extent, (count, d)),
    )
    measurements = _replace(measurements, outliers, wild)

    information = np.broadcast_to(np.diag(_weights(sigma)), (m, k, k)).copy()
    graph = PoseGraph(group, edges, measurements, information, name=name)
    return Instance(graph, truth, outliers, params, backbone)


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


# ---- rotation averaging ----------------------------------------------------------------


def _pair_index(i: IntArray, j: IntArray, n: int) -> IntArray:
    """The number of the pair ``(i, j)``, ``i < j``, among all such pairs in row-major order:
    row ``i`` starts at ``s(i) = i n − i(i+1)/2``."""
    return i * n - i * (i + 1) // 2 + j - i - 1


def _pairs_from_index(t: IntArray, n: int) -> IntArray:
    """The pairs ``(i, j)``, ``i < j``, numbered ``t`` by :func:`_pair_index`, shape ``(len(t), 2)``.

    ``i`` is the root of ``s(i) = t`` rounded down, corrected by one where floating point
    lands on the wrong side.
    """
    start = lambda i: _pair_index(i, i + 1, n)
    i = np.floor((2 * n - 1 - np.sqrt((2.0 * n - 1) ** 2 - 8.0 * t)) / 2).astype(np.int64)
    i = np.clip(i, 0, n - 2)
    i -= start(i) > t
    i += start(i + 1) <= t
    return np.stack([i, t - start(i) + i + 1], axis=1)


def rotation_averaging(
    n: int = 100,
    *,
    d: int = 3,
    edge_probability: float | None = None,
    degree: float | None = None,
    noise: float = 0.05,
    outlier_rate: float = 0.0,
    seed: int = 0,
) -> Instance:
    """Rotation averaging on a random connected graph with Haar-random true rotations in SO(d).

    The graph is an Erdős–Rényi ``G(n, p)`` united with a Hamiltonian path through a random
    permutation of the vertices (the backbone, which makes it connected):
    ``n − 1 ≤ m ≤ n(n−1)/2``. Measurements are ``R̃_e = (R_iᵀ R_j) Exp(ε)``,
    ``ε ~ N(0, noise² I)``, with ``κ_e = 1/noise²`` (:data:`EXACT_WEIGHT` if ``noise = 0``);
    each edge off the path is an outlier (a Haar-random rotation) with probability
    ``outlier_rate``.

    Parameters
    ----------
    n : int ≥ 2
    d : {2, 3}
    edge_probability : float in [0, 1], optional
        ``p``; give it or ``degree``, not both.
    degree : float ≥ 0, optional
        Expected degree of the Erdős–Rényi part, ``p = min(1, degree/(n − 1))``;
        default 10 when neither is given.
    noise : float ≥ 0
        Standard deviation (rad) of each tangent coordinate of ``ε``.
    outlier_rate : float in [0, 1]
    seed : int

    Returns
    -------
    Instance
        ``graph.name`` is ``"rotation-averaging-so{d}-n{n}-seed{seed}"``.
    """
    params = dict(locals())
    n = _size("n", n)
    if isinstance(d, bool) or not isinstance(d, numbers.Integral) or d not in (2, 3):
        raise ValueError(f"d must be 2 or 3, got {d!r}")
    if edge_probability is not None and degree is not None:
        raise ValueError("give edge_probability or degree, not both")
    if edge_probability is not None:
        p = _probability("edge_probability", edge_probability)
    else:
        p = min(1.0, _nonnegative("degree", 10.0 if degree is None else degree) / (n - 1))
    sigma = _nonnegative("noise", noise)
    _probability("outlier_rate", outlier_rate)
    group = SO2 if d == 2 else SO3
    rng = np.random.default_rng(seed)

    truth = group.random(rng, (n,))
    order = rng.permutation(n)
    path = _pair_index(np.minimum(order[:-1], order[1:]), np.maximum(order[:-1], order[1:]), n)
    total = n * (n - 1) // 2
    # The union with G(n, p), as sorted pair indices: edges in lexicographic order.
    index = np.union1d(path, rng.choice(total, rng.binomial(total, p), replace=False))
    edges = _pairs_from_index(index, n)
    backbone = np.isin(index, path)
    m = len(edges)

    measurements = truth[edges[:, 0]].between(truth[edges[:, 1]]).rplus(sigma * rng.standard_normal((m, group.dim)))
    outliers = ~backbone & (rng.random(m) < outlier_rate)
    measurements = _replace(measurements, outliers, group.random(rng, (int(outliers.sum()),)))
    kappa = np.full(m, _weights(np.array(sigma)))
    graph = RotationAveraging(group, edges, measurements, kappa, n=n, name=f"rotation-averaging-so{d}-n{n}-seed{seed}")
    return Instance(graph, truth, outliers, params, backbone)
