"""Landmark SLAM: poses linked by relative-pose edges, landmarks seen from the poses, priors.

The graph-based SLAM of the seed notes: ``n`` poses ``X_i ∈ SE(d)`` and ``L`` landmarks
``l_a ∈ Rᵈ``, with three kinds of measurements, each a factor type of one vectorized
residual (:mod:`manopt_lie.factors`):

- **relative poses** ``Z_e ≈ X_i⁻¹ X_j`` (odometry, loop closures) with information ``Ω_e``
  — the edges of :attr:`LandmarkGraph.poses`, a :class:`~manopt_lie.problems.PoseGraph`;
- **relative points** ``z_o ≈ (X_i S_o)⁻¹ l_a``: landmark ``a`` seen in the frame of the
  sensor ``S_o`` mounted on pose ``i`` (g2o's ``EDGE_SE2_XY`` and, with g2o's
  ``PARAMS_SE3OFFSET``, ``EDGE_SE3_TRACKXYZ``), information ``Ω_o`` (``d × d``);
- **priors** ``X_i ≈ X̄_p`` on single poses (``EDGE_PRIOR_SE2``, ``EDGE_SE3_PRIOR``),
  residual ``Log(X̄_p⁻¹ X_i)``, information ``Ω_p``.

The cost (``"geodesic"``) is ``½ Σ rᵀΩr`` over all of them, the negative log-likelihood
under Gaussian noise in the right tangent. The variables are
``Blocks({"poses": Power(SE(d), n), "landmarks": Power(Euclidean(d), L)})``; a point is a
:class:`~manopt_lie.manifolds.Values` ``(poses, landmarks)``. The gauge: the ``FIX``-ed poses
if any; else, without priors, the anchor pose; with priors, nothing (they fix it).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from manopt_lie.errors import ShapeError
from manopt_lie.factors import Gaussian, between_factor, prior_factor, relative_point_factor
from manopt_lie.lie.base import LieGroup
from manopt_lie.manifolds import Blocks, Euclidean, LieGroupManifold, Power, Values
from manopt_lie.optim import LeastSquaresProblem
from manopt_lie.optim.losses import RobustLoss

from . import costs
from .costs import InformationMatrixError
from .graph import Graph, _world_positions
from .pose_graph import PoseGraph

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

__all__ = ["LandmarkGraph"]


def _ints(a: Any, shape: tuple[int, ...], what: str, name: str) -> IntArray:
    out = np.asarray(a)
    if out.shape != shape or (out.size and not np.issubdtype(out.dtype, np.integer)):
        raise ShapeError(f"{name}: {what} must be an integer array of shape {shape}, got {out.shape} {out.dtype}")
    return out.astype(np.int64)


def _floats(a: Any, shape: tuple[int, ...], what: str, name: str) -> FloatArray:
    out = np.asarray(a, dtype=np.float64)
    if out.shape != shape:
        raise ShapeError(f"{name}: {what} must have shape {shape}, got {out.shape}")
    if not np.isfinite(out).all():
        bad = np.flatnonzero(~np.isfinite(out.reshape(len(out), -1)).all(axis=1))
        raise InformationMatrixError(f"{name}: non-finite {what} on rows {bad[:10].tolist()}")
    return out


@dataclass(frozen=True, eq=False, repr=False)
class LandmarkGraph(Graph):
    """Poses, landmarks, relative-pose edges, landmark observations and pose priors.

    Parameters
    ----------
    poses : PoseGraph
        The pose variables (ids, ``FIX``, estimates) and the relative-pose edges
        (possibly none).
    landmark_ids : int array ``(L,)``
        The landmarks' ids in the source (distinct, and distinct from the pose ids).
    observations : int array ``(k, 2)``
        ``(pose index, landmark index)`` of each observation.
    points : ``(k, d)``
        The measured landmark in the sensor frame, ``z_o ≈ (X_i S_o)⁻¹ l_a``.
    point_information : ``(k, d, d)``
    landmarks : ``(L, d)``, optional
        Landmark estimates from the source.
    sensor_offsets : SE(d) element, batch ``(k,)``, optional
        The sensor's pose ``S_o`` on the robot per observation (default the identity).
    offset_ids : int array ``(k,)``, optional
        g2o parameter ids of the offsets (kept for writing).
    prior_poses : int array ``(p,)``
        Pose indices with a prior.
    prior_means : SE(d) element, batch ``(p,)``, optional
    prior_information : ``(p, k, k)``
        In tangent order ``(ρ, θ)``.
    name : str
    observation_lines, prior_lines : int arrays, optional
        Source file lines, for messages.
    """

    kind: ClassVar[str] = "landmark-slam"
    noun: ClassVar[str] = "poses"
    costs: ClassVar[tuple[str, ...]] = ("geodesic",)

    poses: PoseGraph
    landmark_ids: IntArray
    observations: IntArray
    points: FloatArray
    point_information: FloatArray
    landmarks: FloatArray | None = None
    sensor_offsets: LieGroup | None = None
    offset_ids: IntArray | None = None
    prior_poses: IntArray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    prior_means: LieGroup | None = None
    prior_information: FloatArray | None = None
    name: str = "landmark graph"
    observation_lines: IntArray | None = None
    prior_lines: IntArray | None = None

    def __post_init__(self) -> None:
        name, graph = self.name, self.poses
        if not isinstance(graph, PoseGraph):
            raise TypeError(f"{name}: poses must be a PoseGraph, got {type(graph).__name__}")
        d, dim = graph.d, graph.group.dim
        ids = np.asarray(self.landmark_ids, dtype=np.int64).reshape(-1)
        if len(np.unique(ids)) != len(ids):
            raise ValueError(f"{name}: landmark ids must be distinct")
        shared = np.intersect1d(ids, graph.ids)
        if shared.size:
            raise ValueError(f"{name}: ids {shared[:10].tolist()} name both a pose and a landmark")
        n_landmarks = len(ids)
        obs = np.asarray(self.observations)
        k = len(obs) if obs.ndim == 2 else -1
        obs = _ints(obs, (k, 2), "observations", name)
        if k and ((obs[:, 0] < 0) | (obs[:, 0] >= graph.n) | (obs[:, 1] < 0) | (obs[:, 1] >= n_landmarks)).any():
            raise ValueError(
                f"{name}: observations must index poses 0..{graph.n - 1} and landmarks 0..{n_landmarks - 1}"
            )
        object.__setattr__(self, "landmark_ids", ids)
        object.__setattr__(self, "observations", obs)
        object.__setattr__(self, "points", _floats(self.points, (k, d), "points", name))
        object.__setattr__(
            self, "point_information", _floats(self.point_information, (k, d, d), "point information", name)
        )
        if self.landmarks is not None:
            object.__setattr__(self, "landmarks", _floats(self.landmarks, (n_landmarks, d), "landmarks", name))
        if self.sensor_offsets is not None and (
            not isinstance(self.sensor_offsets, graph.group) or self.sensor_offsets.batch_shape != (k,)
        ):
            raise ShapeError(f"{name}: sensor_offsets must be {graph.group.__name__} with batch shape ({k},)")
        if self.offset_ids is not None:
            object.__setattr__(self, "offset_ids", _ints(self.offset_ids, (k,), "offset_ids", name))
        priors = np.asarray(self.prior_poses, dtype=np.int64).reshape(-1)
        p = len(priors)
        if p and (priors.min() < 0 or priors.max() >= graph.n):
            raise ValueError(f"{name}: prior_poses must index poses 0..{graph.n - 1}")
        if p and (
            self.prior_means is None or not isinstance(self.prior_means, graph.group)
            or self.prior_means.batch_shape != (p,)
        ):  # fmt: skip
            raise ShapeError(f"{name}: prior_means must be {graph.group.__name__} with batch shape ({p},)")
        info = np.zeros((0, dim, dim)) if self.prior_information is None and not p else self.prior_information
        object.__setattr__(self, "prior_poses", priors)
        object.__setattr__(self, "prior_information", _floats(info, (p, dim, dim), "prior information", name))
        for what, size in (("observation_lines", k), ("prior_lines", p)):
            lines = getattr(self, what)
            if lines is not None:
                object.__setattr__(self, what, _ints(lines, (size,), what, name))

    # ---- sizes ---------------------------------------------------------------------------

    @property
    def edges(self) -> IntArray:  # type: ignore[override]
        """The relative-pose edges ``(m_pose, 2)``."""
        return self.poses.edges

    @property
    def n(self) -> int:
        """Number of poses."""
        return self.poses.n

    @property
    def n_landmarks(self) -> int:
        """Number of landmarks."""
        return len(self.landmark_ids)

    @property
    def m(self) -> int:
        """Number of measurements: relative poses, observations and priors."""
        return self.poses.m + len(self.observations) + len(self.prior_poses)

    @property
    def d(self) -> int:
        """The dimension of the world, 2 or 3 (of the poses and landmarks)."""
        return self.poses.d

    @property
    def group(self) -> type[LieGroup]:
        """The group of the poses, ``SE2`` or ``SE3``."""
        return self.poses.group

    @property
    def dimension(self) -> int:
        return self.n * self.group.dim + self.n_landmarks * self.d

    @property
    def manifold(self) -> Blocks:
        """``Blocks(poses=Power(SE(d), n), landmarks=Power(Euclidean(d), L))`` (without the
        landmarks block when there are none: a pose graph with priors). The poses retract
        by ``(R Exp(θ), t + Rρ)`` (``geometry="decoupled"``, GTSAM's Pose retraction): the
        same tangent coordinates and Jacobians as ``X Exp(τ)``, but long steps from a poor
        start (odometry composed over thousands of poses) move positions along straight
        lines; with ``X Exp(τ)`` LM needed over 1000 iterations on a 5000-pose 3-D world
        that it now solves in 33 (``benchmarks/bench_landmarks.py``)."""
        blocks = {"poses": Power(LieGroupManifold(self.group, geometry="decoupled"), self.n)}
        if self.n_landmarks:
            blocks["landmarks"] = Power(Euclidean(self.d), self.n_landmarks)
        return Blocks(blocks)

    @property
    def vertex_ids(self) -> IntArray:
        """Pose ids, then landmark ids (the order of the variables)."""
        return np.concatenate([self.poses.ids, self.landmark_ids])

    def describe(self) -> str:
        def count(k: int, what: str) -> str:
            return f"{k} {what if k == 1 else what + 's'}"

        return (
            f"{count(self.n, 'pose')}, {count(self.n_landmarks, 'landmark')}; "
            f"{count(self.poses.m, 'relative pose')}, {count(len(self.observations), 'observation')}, "
            f"{count(len(self.prior_poses), 'prior')}"
        )

    def __repr__(self) -> str:
        return (
            f"LandmarkGraph({self.name!r}, {self.group.__name__}, n={self.n}, landmarks={self.n_landmarks}, "
            f"observations={len(self.observations)}, priors={len(self.prior_poses)})"
        )

    def values(self, poses: LieGroup, landmarks: Any) -> Values:
        """A point of :attr:`manifold` from poses ``(n,)`` and landmarks ``(L, d)``."""
        if not self.n_landmarks:
            return self.manifold.values(poses=poses)
        return self.manifold.values(poses=poses, landmarks=np.asarray(landmarks, dtype=np.float64))

    @property
    def estimates(self) -> Values | None:
        """The source's estimates of every variable, if it had them all."""
        if self.poses.poses is None or (self.landmarks is None and self.n_landmarks):
            return None
        return self.values(self.poses.poses, self.landmarks)

    # ---- what commands show ------------------------------------------------------------

    def positions(self, x: Values) -> FloatArray:
        """The poses' positions ``(n, d)``."""
        return np.asarray(x["poses"].as_matrix()[:, : self.d, self.d])

    def landmark_positions(self, x: Values) -> FloatArray:
        """The landmarks ``(L, d)`` of ``x``."""
        return np.asarray(x["landmarks"]) if self.n_landmarks else np.zeros((0, self.d))

    def _poses_of(self, x: Values) -> LieGroup:
        return x["poses"]  # type: ignore[no-any-return]

    def figure_layers(self, x: Values, covariances: Any = None) -> dict[str, Any]:
        """The landmarks and, with marginals, the 95 % ellipses of poses and landmarks."""
        layers: dict[str, Any] = {"landmarks": self.landmark_positions(x)}
        if covariances is not None:
            layers["covariances"] = _world_positions(x["poses"], covariances.stacked("poses"))
            if self.n_landmarks:
                layers["landmark_covariances"] = covariances.stacked("landmarks")
        return layers

    def to_g2o(self, x: Values) -> tuple[LandmarkGraph, Values]:
        """This graph with the estimates ``x`` (every vertex is written back)."""
        return self, x

    def pose_graph(self) -> PoseGraph:
        """:attr:`poses`: the poses and the relative-pose edges, without the landmarks."""
        return self.poses

    # ---- costs and problems --------------------------------------------------------

    def observation_names(self, observations: Any) -> list[str]:
        """``"pose 3 → landmark 1007 (line 12)"`` for messages."""
        index = np.asarray(observations, dtype=np.int64).reshape(-1)
        pose, point = self.poses.ids[self.observations[index, 0]], self.landmark_ids[self.observations[index, 1]]
        lines = [""] * len(index) if self.observation_lines is None else [
            f" (line {line})" for line in self.observation_lines[index]
        ]  # fmt: skip
        return [f"pose {a} → landmark {b}{where}" for a, b, where in zip(pose, point, lines, strict=True)]

    def prior_names(self, priors: Any) -> list[str]:
        """``"prior on pose 3 (line 12)"`` for messages, one per index of ``priors``."""
        index = np.asarray(priors, dtype=np.int64).reshape(-1)
        lines = [""] * len(index) if self.prior_lines is None else [f" (line {ln})" for ln in self.prior_lines[index]]
        ids = self.poses.ids[self.prior_poses[index]]
        return [f"prior on pose {a}{where}" for a, where in zip(ids, lines, strict=True)]

    def problem(
        self,
        cost: str | None = None,
        *,
        robust: RobustLoss | str | None = None,
        repair_information: bool = False,
    ) -> LeastSquaresProblem:
        """The least-squares problem on :attr:`manifold`: relative poses
        (:func:`~manopt_lie.factors.between_factor`), observations
        (:func:`~manopt_lie.factors.relative_point_factor`, with the sensor offsets) and
        priors (:func:`~manopt_lie.factors.prior_factor`), each whitened by its information
        (refused, naming the measurement, unless positive definite — or repaired with
        ``repair_information=True``); ``robust`` applies to every factor. The gauge is fixed
        as the module doc says."""
        self._cost_name(cost)
        if not self.m:
            raise ValueError(f"{self.name}: the graph has no measurements, so there is nothing to optimize")
        factors = []
        graph = self.poses
        if graph.m:
            root = costs.information_sqrt(graph.information, _Names(graph.edge_names), repair=repair_information)
            factors.append(between_factor(graph.edges, graph.measurements, Gaussian(root), loss=robust,
                                          name="relative poses", blocks="poses"))  # fmt: skip
        if len(self.observations):
            root = costs.information_sqrt(self.point_information, _Names(self.observation_names),
                                          repair=repair_information)  # fmt: skip
            factors.append(relative_point_factor(self.observations, self.points, Gaussian(root),
                                                 offset=self.sensor_offsets, loss=robust, name="observations",
                                                 blocks=("poses", "landmarks")))  # fmt: skip
        if len(self.prior_poses):
            assert self.prior_means is not None and self.prior_information is not None  # checked on construction
            root = costs.information_sqrt(self.prior_information, _Names(self.prior_names), repair=repair_information)
            factors.append(prior_factor(self.prior_poses, self.prior_means, Gaussian(root), loss=robust,
                                        name="priors", blocks="poses"))  # fmt: skip
        return LeastSquaresProblem(self.manifold, factors, fixed={"poses": self.gauge})

    @property
    def gauge(self) -> IntArray:
        """The poses held fixed: the ``FIX``-ed ones; else, without priors, the anchor; else none."""
        if self.poses.fixed.size:
            return self.poses.fixed
        return np.zeros(0, dtype=np.int64) if len(self.prior_poses) else np.array([self.poses.anchor])

    def cost(self, x: Values, cost: str | None = None) -> float:
        """``½ Σ rᵀΩr`` over every measurement at ``x`` (the value :meth:`problem` minimizes)."""
        self.manifold.check_point(x)
        return self.problem(cost).cost(x)

    # ---- initializations -----------------------------------------------------------

    def initialize(self, method: str = "chordal", *, seed: int | None = None) -> Values:
        """Poses by ``method`` on the pose subgraph (:meth:`PoseGraph.initialize`; moved onto
        the first prior when there are priors and the source had no poses), then each
        landmark by :meth:`triangulate`. ``"file"`` takes the source's estimates (landmarks
        it lacks are triangulated)."""
        if method == "file" and self.poses.poses is not None and self.landmarks is not None:
            return self.values(self.poses.poses, self.landmarks)
        poses = self.poses.initialize(method, seed=seed)
        if len(self.prior_poses) and self.poses.poses is None:
            i = self.prior_poses[0]
            poses = self.prior_means[0] @ poses[i].inverse() @ poses  # type: ignore[index]
        landmarks = self.landmarks if method == "file" and self.landmarks is not None else self.triangulate(poses)
        return self.values(poses, landmarks)

    def sensors(self, poses: LieGroup) -> LieGroup:
        """``X_i S_o``: the sensor's pose of every observation ``(k,)``."""
        x = poses[self.observations[:, 0]]
        return x if self.sensor_offsets is None else x @ self.sensor_offsets

    def triangulate(self, poses: LieGroup) -> FloatArray:
        """The landmarks minimizing the observations' cost for fixed ``poses``, in closed form:
        with ``(R_o, t_o) = X_i S_o``, ``‖(X_i S_o)⁻¹ l − z_o‖²_{Ω_o} = ‖l − (t_o + R_o z_o)‖²_{W_o}``,
        ``W_o = R_o Ω_o R_oᵀ``, so ``l_a = (Σ_o W_o)⁻¹ Σ_o W_o (t_o + R_o z_o)`` over the
        observations of ``a``. A landmark whose summed ``W`` is singular (seen once with a
        rank-deficient information) takes its first observation's point.

        Raises
        ------
        ValueError
            Naming the landmarks that no observation sees (nothing determines them).
        """
        d, obs = self.d, self.observations
        seen = np.bincount(obs[:, 1], minlength=self.n_landmarks) if len(obs) else np.zeros(self.n_landmarks, int)
        if not seen.all():
            lonely = self.landmark_ids[seen == 0]
            raise ValueError(f"{self.name}: landmarks {lonely[:10].tolist()} are never observed")
        m = self.sensors(poses).as_matrix()
        r, t = m[:, :d, :d], m[:, :d, d]
        world = t + np.einsum("oij,oj->oi", r, self.points)
        sym = 0.5 * (self.point_information + np.swapaxes(self.point_information, 1, 2))
        w = r @ sym @ np.swapaxes(r, 1, 2)
        a, b = np.zeros((self.n_landmarks, d, d)), np.zeros((self.n_landmarks, d))
        np.add.at(a, obs[:, 1], w)
        np.add.at(b, obs[:, 1], np.einsum("oij,oj->oi", w, world))
        first = np.zeros((self.n_landmarks, d))
        first[obs[::-1, 1]] = world[::-1]  # the first observation of each landmark wins
        eig = np.linalg.eigvalsh(a)
        ok = eig[:, 0] > 1e-12 * np.maximum(np.abs(eig[:, -1]), np.finfo(float).tiny)
        out = first.copy()
        out[ok] = np.linalg.solve(a[ok], b[ok][:, :, None])[:, :, 0]
        return out


class _Names:
    """Lazy ``names[e]`` from a function of indices, for error messages."""

    def __init__(self, names: Any) -> None:
        self.names = names

    def __getitem__(self, e: int) -> str:
        return str(self.names([e])[0])
