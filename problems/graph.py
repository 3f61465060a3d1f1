"""The base of measurement graphs: variables on one Lie group linked by relative measurements.

A graph has ``n`` vertices, each a variable ``X_i`` of a group ``G`` (poses in SE(d),
rotations in SO(d)), and ``m`` edges ``e = (i, j)``, each carrying a measurement
``Z_e ≈ X_i⁻¹ X_j`` and a weight. :class:`MeasurementGraph` owns everything the
kinds share, written once:

- validation of the edges, measurements, ids, estimates and gauge (:meth:`_validate`);
- the costs of CONVENTIONS §8 by name (:meth:`cost`, :meth:`problem`): **geodesic**
  ``½ Σ r_eᵀ Ω_e r_e`` with ``r_e = Log(Z_e⁻¹ X_i⁻¹ X_j)`` and **chordal**
  ``Σ ‖(X_j − X_i Z_e) W_e‖_F²`` on the top ``d`` rows of the matrices;
- initializations by name (:meth:`initialize`);
- what a command line or a benchmark needs to know without asking for the kind — the
  interface :class:`Graph`, which every kind implements (landmark graphs too):
  :attr:`kind`, :attr:`noun`, :attr:`dimension`, :meth:`positions` (what to plot)
  and :meth:`to_g2o` (what to write back).

A kind supplies its weights: :attr:`information` (``Ω_e``, ``(m, k, k)``, tangent order
``(ρ, θ)``) and :meth:`chordal_parameters` (SE-Sync's ``κ_e``, and ``τ_e`` when the group
has translations).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from manopt_lie.errors import ShapeError
from manopt_lie.lie._matrix import assemble
from manopt_lie.lie.base import LieGroup
from manopt_lie.manifolds import LieGroupManifold, Manifold, Power
from manopt_lie.optim import LeastSquaresProblem
from manopt_lie.optim.losses import RobustLoss

from . import costs, initialization

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


class Graph(ABC):
    """What a command line or a benchmark asks of any estimation problem built from
    measurements, whatever its kind (pose graph, rotation averaging, landmark SLAM…).

    Subclasses supply the class attributes :attr:`kind`, :attr:`noun`, :attr:`costs`,
    :attr:`initializations` and the methods below; the commands never branch on the kind.
    """

    kind: ClassVar[str]
    """The problem kind's name, as the command line and the catalogue spell it."""
    noun: ClassVar[str]
    """What the variables of the main block are, for messages (``"poses"``)."""
    costs: ClassVar[tuple[str, ...]]
    """The costs this kind offers; the first is the default."""
    initializations: ClassVar[tuple[str, ...]] = ("chordal", "odometry", "random", "file")
    """The names :meth:`initialize` takes."""

    name: str
    edges: IntArray
    """``(m, 2)`` vertex indices of the edges between the main block's variables (what a
    trajectory plot draws)."""

    @property
    @abstractmethod
    def n(self) -> int:
        """Number of variables of the main block (poses, rotations)."""

    @property
    @abstractmethod
    def m(self) -> int:
        """Number of measurements (of every kind)."""

    @property
    @abstractmethod
    def dimension(self) -> int:
        """The tangent dimension of all variables (the gauge included)."""

    @property
    @abstractmethod
    def manifold(self) -> Manifold:
        """Where the variables live."""

    def describe(self) -> str:
        """``"1045 poses, 1172 edges"``, for messages."""
        return f"{self.n} {self.noun}, {self.m} edges"

    def _cost_name(self, cost: str | None) -> str:
        if cost is None:
            return self.costs[0]
        if cost not in self.costs:
            raise ValueError(f"cost must be one of {self.costs}, got {cost!r}")
        return cost

    @abstractmethod
    def cost(self, x: Any, cost: str | None = None) -> float:
        """The value of ``cost`` (default: the first of :attr:`costs`) at ``x``."""

    @abstractmethod
    def problem(self, cost: str | None = None, *, robust: RobustLoss | str | None = None,
                repair_information: bool = False) -> LeastSquaresProblem:  # fmt: skip
        """The least-squares problem of ``cost``, its gauge fixed."""

    @abstractmethod
    def initialize(self, method: str = "chordal", *, seed: int | None = None) -> Any:
        """An initial estimate by name (one of :attr:`initializations`)."""

    @abstractmethod
    def positions(self, x: Any) -> FloatArray | None:
        """Positions ``(n, d)`` of the main block's variables to draw, or ``None``."""

    @abstractmethod
    def to_g2o(self, x: Any) -> tuple[Any, Any]:
        """The graph and the vertex estimates that represent the solution ``x`` in a g2o file."""

    def figure_layers(self, x: Any, covariances: Any = None) -> dict[str, Any]:
        """What a trajectory figure draws besides the main block's positions: for
        :func:`manopt_lie.bench.plots.trajectory`'s keywords (``covariances``: the poses'
        position covariances in the world frame, ``R Σ_ρρ Rᵀ``, from marginals in the right
        tangent — :func:`~manopt_lie.optim.marginal_covariances` over every variable)."""
        if covariances is None or self.positions(x) is None:
            return {}
        return {"covariances": _world_positions(self._poses_of(x), covariances.stacked()[: self.n])}

    def _poses_of(self, x: Any) -> LieGroup:
        return x  # type: ignore[no-any-return]

    @property
    def vertex_ids(self) -> IntArray:
        """The source's id of every variable, in the problem's global order (block after block)."""
        return self.ids  # type: ignore[attr-defined, no-any-return]

    def pose_graph(self) -> Any:
        """The pose graph within this problem (its poses and relative-pose edges).

        Raises
        ------
        ValueError
            If it has none.
        """
        raise ValueError(f"{self.name} is a {self.kind} problem, with no pose graph in it")


class MeasurementGraph(Graph):
    """Relative measurements ``Z_e ≈ X_i⁻¹ X_j`` between ``n`` variables of one group.

    Subclasses are frozen dataclasses with the fields ``group``, ``edges`` (vertex
    *indices* ``(m, 2)``), ``measurements`` (batch ``(m,)``), ``ids`` (the source's vertex
    ids, ``(n,)``), ``fixed`` (vertex indices held fixed by the source), ``name``, and
    :attr:`estimates` (vertex estimates from the source, or ``None``).
    """

    group: type[LieGroup]
    edges: IntArray
    measurements: LieGroup
    ids: IntArray
    fixed: IntArray
    name: str
    information: FloatArray
    """``Ω_e``, ``(m, k, k)`` with ``k = group.dim``, in tangent order ``(ρ, θ)`` (a field or a property)."""
    edge_lines: IntArray | None
    """The line of each edge in its source file, for messages, or ``None``."""

    # ---- what a kind supplies ---------------------------------------------------------

    @abstractmethod
    def chordal_parameters(self) -> tuple[FloatArray, FloatArray | None]:
        """SE-Sync's isotropic weights: ``κ_e`` ``(m,)`` and ``τ_e`` ``(m,)`` (``None`` without translations)."""

    @property
    @abstractmethod
    def estimates(self) -> Any:
        """Vertex estimates from the source (batch ``(n,)``), or ``None``."""

    # ---- validation -----------------------------------------------------------------

    def _validate(self, groups: tuple[type[LieGroup], ...], n: int | None, *, allow_empty: bool) -> int:
        """Check and normalize the shared fields (``ids`` may be ``None``: then ``0..n-1``); return ``n``."""
        name = self.name
        if self.group not in groups:
            names = " or ".join(g.__name__ for g in groups)
            raise TypeError(f"{type(self).__name__}: group must be {names}, got {self.group!r}")
        edges = np.asarray(self.edges)
        if edges.ndim != 2 or edges.shape[1] != 2 or not np.issubdtype(edges.dtype, np.integer):
            raise ShapeError(f"{name}: edges must be an integer array (m, 2), got {edges.shape} {edges.dtype}")
        if not (allow_empty or len(edges)):
            raise ShapeError(f"{name}: edges must be a non-empty integer array (m, 2), got {edges.shape}")
        m = len(edges)
        if not isinstance(self.measurements, self.group) or self.measurements.batch_shape != (m,):
            raise ShapeError(f"{name}: measurements must be {self.group.__name__} with batch shape ({m},)")
        if self.ids is None:
            if n is None:
                n = int(edges.max()) + 1 if m else 0
                if self.estimates is not None:
                    n = max(n, self.estimates.batch_shape[0])
            ids = np.arange(n, dtype=np.int64)
        else:
            ids = np.asarray(self.ids, dtype=np.int64)
            if ids.ndim != 1 or len(np.unique(ids)) != len(ids):
                raise ValueError(f"{name}: ids must be a 1-D array of distinct integers")
        n = len(ids)
        if m and (edges.min() < 0 or edges.max() >= n):
            raise ValueError(f"{name}: edge indices must lie in 0..{n - 1}")
        loops = np.flatnonzero(edges[:, 0] == edges[:, 1])
        if loops.size:
            raise ValueError(f"{name}: self-loop edges {loops[:10].tolist()}")
        estimates = self.estimates
        if estimates is not None and (not isinstance(estimates, self.group) or estimates.batch_shape != (n,)):
            raise ShapeError(f"{name}: estimates must be {self.group.__name__} with batch shape ({n},)")
        fixed = np.asarray(self.fixed, dtype=np.int64).reshape(-1)
        if fixed.size and (fixed.min() < 0 or fixed.max() >= n):
            raise ValueError(f"{name}: fixed vertex indices must lie in 0..{n - 1}")
        if self.edge_lines is not None:
            lines = np.asarray(self.edge_lines, dtype=np.int64)
            if lines.shape != (m,):
                raise ShapeError(f"{name}: edge_lines must have shape ({m},), got {lines.shape}")
            object.__setattr__(self, "edge_lines", lines)
        object.__setattr__(self, "edges", edges.astype(np.int64))
        object.__setattr__(self, "ids", ids)
        object.__setattr__(self, "fixed", fixed)
        return n

    # ---- sizes and names --------------------------------------------------------------

    @property
    def n(self) -> int:
        """Number of vertices."""
        return len(self.ids)

    @property
    def m(self) -> int:
        """Number of edges."""
        return len(self.edges)

    @property
    def d(self) -> int:
        """The dimension of the space the group acts on (2 or 3)."""
        return int(self.group.point_dim)  # type: ignore[attr-defined]

    @property
    def has_translations(self) -> bool:
        """Whether the group carries translations (SE(d)) or only rotations (SO(d))."""
        return bool(self.group.dim > self.d * (self.d - 1) // 2)

    @property
    def dimension(self) -> int:
        """The tangent dimension of the variables, ``n · dim G`` (the gauge included)."""
        return self.n * self.group.dim

    @property
    def anchor(self) -> int:
        """The vertex fixing the gauge: the first ``fixed`` one, else vertex 0."""
        return int(self.fixed[0]) if self.fixed.size else 0

    @property
    def manifold(self) -> Power:
        """``Power(G, n)`` with the group's retraction ``X ⊕ δ``."""
        return Power(LieGroupManifold(self.group), self.n)

    def edge_names(self, edges: Any) -> list[str]:
        """``"i→j"`` in the source's vertex ids, for messages, with the source file's line
        (``"i→j (line 12)"``) when the graph knows it (:attr:`edge_lines`)."""
        index = np.asarray(edges, dtype=np.int64).reshape(-1)
        ij = self.ids[self.edges[index]]
        lines = self.edge_lines
        if lines is None:
            return [f"{a}→{b}" for a, b in ij]
        return [f"{a}→{b} (line {line})" for (a, b), line in zip(ij, lines[index], strict=True)]

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.name!r}, {self.group.__name__}, n={self.n}, m={self.m})"

    # ---- costs and problems -----------------------------------------------------------

    def chordal_weights(self) -> FloatArray:
        """The diagonal of ``W_e`` per edge, ``(m, c)``: ``√κ`` on the ``d`` rotation columns
        and ``√τ`` on the translation column (if any).

        Raises
        ------
        IndefiniteInformationError
            Naming the edges where ``κ`` or ``τ`` is not positive.
        """
        kappa, tau = self.chordal_parameters()
        with np.errstate(invalid="ignore"):
            usable = np.isfinite(kappa) & (kappa > 0)
            if tau is not None:
                usable &= np.isfinite(tau) & (tau > 0)
        if not usable.all():
            bad = np.flatnonzero(~usable)
            more = f" and {bad.size - 10} more" if bad.size > 10 else ""
            raise costs.IndefiniteInformationError(
                f"{self.name}: the chordal cost needs finite κ, τ > 0 (SE-Sync's weights of the information "
                f"matrices); not so on {bad.size} edges: {', '.join(self.edge_names(bad[:10]))}{more}"
            )
        columns = [np.repeat(np.sqrt(kappa)[:, None], self.d, axis=1)]
        if tau is not None:
            columns.append(np.sqrt(tau)[:, None])
        return np.concatenate(columns, axis=1)

    def cost(self, x: LieGroup, cost: str | None = None) -> float:
        """The CONVENTIONS §8 value at ``x``: geodesic ``½ Σ rᵀΩr`` or chordal
        ``Σ ‖(X_j − X_i Z) W‖_F²`` (default: the first of :attr:`costs`)."""
        cost = self._cost_name(cost)
        self.manifold.check_point(x)
        if cost == "geodesic":
            return costs.geodesic_cost(x, self.edges, self.measurements, self.information)
        return costs.chordal_cost(x, self.edges, self.measurements, self.chordal_weights())

    def problem(
        self,
        cost: str | None = None,
        *,
        robust: RobustLoss | str | None = None,
        repair_information: bool = False,
    ) -> LeastSquaresProblem:
        """The least-squares problem on ``Power(G, n)`` with the :attr:`anchor` fixed.

        Parameters
        ----------
        cost : str, optional
            One of :attr:`costs` (default the first); the objective is exactly :meth:`cost`.
            The chordal problem without a robust loss carries its exact Riemannian
            Hessian (:class:`~manopt_lie.problems.costs.ChordalHessian`), so the trust
            region runs on the true model; every problem also offers Gauss-Newton.
        robust : RobustLoss or str, optional
            A robust loss on each edge's squared whitened residual, e.g. ``"huber:1.0"``.
        repair_information : bool
            The geodesic cost needs positive definite ``Ω``; by default edges that are
            not raise :class:`~manopt_lie.problems.costs.IndefiniteInformationError`
            naming them; ``True`` replaces them by the nearest positive definite matrix.
        """
        cost = self._cost_name(cost)
        if not self.m:
            raise ValueError(f"{self.name}: the graph has no edges, so there is nothing to optimize")
        fixed = np.array([self.anchor])
        if cost == "geodesic":
            sqrt_info = costs.information_sqrt(self.information, _EdgeNames(self), repair=repair_information)
            factor = costs.geodesic_factor(self.edges, self.measurements, sqrt_info, robust)
            return LeastSquaresProblem(self.manifold, [factor], fixed=fixed)
        weights = self.chordal_weights()
        factor = costs.chordal_factor(self.edges, self.measurements, weights, robust)
        hessian = None
        if robust is None:
            hessian = costs.ChordalHessian(self.manifold, self.edges, self.measurements, weights, fixed)
        return LeastSquaresProblem(self.manifold, [factor], fixed=fixed, hessian=hessian)

    # ---- initializations -----------------------------------------------------------

    def initialize(self, method: str = "chordal", *, seed: int | None = None) -> LieGroup:
        """An initial estimate by name: ``"chordal"`` (:meth:`chordal_initialization`),
        ``"odometry"`` (:meth:`odometry_initialization`), ``"random"``
        (:meth:`random_initialization` from ``seed``) or ``"file"`` (the source's
        :attr:`estimates`)."""
        if method == "chordal":
            return self.chordal_initialization()
        if method == "odometry":
            return self.odometry_initialization()
        if method == "random":
            return self.random_initialization(seed)
        if method == "file":
            if self.estimates is None:
                raise ValueError(f"{self.name} has no vertex estimates (no VERTEX lines): initialize otherwise")
            return self.estimates
        raise ValueError(f"initialization must be one of {self.initializations}, got {method!r}")

    def _in_source_frame(self, x: LieGroup) -> LieGroup:
        """Move the anchor to its estimate in the source (if the source had estimates)."""
        if self.estimates is None:
            return x
        return self.estimates[self.anchor] @ x[self.anchor].inverse() @ x  # type: ignore[no-any-return]

    def random_initialization(self, seed: int | np.random.Generator | None = None) -> LieGroup:
        """Haar-random rotations and, with translations, Gaussian translations of the scale of
        the graph (``σ = n^{1/d}`` times the median measured translation length), with the anchor
        at its source estimate — the start from which local solvers find spurious minima and
        certifiable ones must not."""
        rng = np.random.default_rng(seed)
        x = self.group.random(rng, (self.n,))
        if self.has_translations:
            z = self.measurements.as_matrix()
            length = float(np.median(np.linalg.norm(z[:, : self.d, self.d], axis=1))) if self.m else 1.0
            matrices = np.array(x.as_matrix())
            matrices[:, : self.d, self.d] = rng.standard_normal((self.n, self.d)) * (length * self.n ** (1 / self.d))
            x = self.group.from_matrix(matrices)
        x = x[self.anchor].inverse() @ x  # the anchor at the identity, then in the source's frame
        return self._in_source_frame(x)

    def odometry_initialization(self) -> LieGroup:
        """Measurements composed along a spanning tree from the anchor that prefers
        odometry edges ``(i, i+1)`` (:func:`~manopt_lie.problems.initialization.spanning_tree`)."""
        initialization.check_connected(self.n, self.edges, self.ids, self.anchor)
        x = initialization.spanning_tree(self.group, self.n, self.edges, self.measurements, self.anchor)
        return self._in_source_frame(x)

    def chordal_initialization(self) -> LieGroup:
        """Martinec–Pajdla / Carlone et al. (2015): rotations from the linear least squares
        relaxation of ``Σ κ‖R_j − R_i R̃‖²`` projected onto SO(d), then (with translations)
        translations from the linear least squares ``Σ τ‖t_j − t_i − R_i t̃‖²``. The
        magnitudes of SE-Sync's ``κ, τ`` are used, so that graphs with indefinite
        information matrices still initialize."""
        initialization.check_connected(self.n, self.edges, self.ids, self.anchor)
        kappa, tau = self.chordal_parameters()
        z, d = self.measurements.as_matrix(), self.d
        r = initialization.chordal_rotations(self.n, self.edges, z[:, :d, :d], _usable(kappa), self.anchor)
        if tau is None:
            return self._in_source_frame(self.group.from_matrix(r))
        t = initialization.chordal_translations(self.n, self.edges, r, z[:, :d, d], _usable(tau), self.anchor)
        return self._in_source_frame(self.group.from_matrix(assemble(r, t)))

    # ---- what commands show ------------------------------------------------------------

    def positions(self, x: LieGroup) -> FloatArray | None:
        """Vertex positions ``(n, d)`` to draw a trajectory; ``None`` for groups without translations."""
        if not self.has_translations:
            return None
        return np.asarray(x.as_matrix()[:, : self.d, self.d])


def _world_positions(poses: LieGroup, covariances: FloatArray) -> FloatArray:
    """``R Σ_ρρ Rᵀ``: the position block of right-tangent pose covariances in the world frame
    (``X Exp(τ)`` moves the position by ``R ρ`` to first order)."""
    m = poses.as_matrix()
    d = m.shape[-1] - 1
    r = m[:, :d, :d]
    return np.asarray(r @ covariances[:, :d, :d] @ np.swapaxes(r, 1, 2))


def _usable(weights: FloatArray) -> FloatArray:
    """``|w|`` clipped to ``10^±6`` times the median of the usable ones, with the weights of
    edges that have none (zero, ``nan``: singular information) replaced by that median: such
    edges still connect the graph, and extreme weights cannot make the linear systems of the
    initialization singular in floating point."""
    w = np.abs(weights)
    good = np.isfinite(w) & (w > 0)
    if good.all() and w.max() <= 1e6 * w.min():
        return w
    median = float(np.median(w[good])) if good.any() else 1.0
    return np.where(good, np.clip(w, 1e-6 * median, 1e6 * median), median)


class _EdgeNames:
    """Lazy ``names[e]`` → ``"i→j"`` in source ids, for error messages."""

    def __init__(self, graph: MeasurementGraph) -> None:
        self.graph = graph

    def __getitem__(self, e: int) -> str:
        return self.graph.edge_names([e])[0]
