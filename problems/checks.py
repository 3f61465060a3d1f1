"""Checks of a measurement graph for what makes optimization fail or mislead: :func:`lint`.

Information matrices that are not symmetric positive definite or whose eigenvalues
overflow double precision, duplicate edges, vertices without edges and vertices not
connected to the anchor. For landmark graphs also: the same for the observations' and the
priors' information, duplicate observations, landmarks seen once or never, and landmarks
out of every pose's view. Nothing is raised: the :class:`LintReport` lists what was found.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from .graph import MeasurementGraph

if TYPE_CHECKING:
    from .landmarks import LandmarkGraph

__all__ = ["LintReport", "lint"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


def _ids() -> IntArray:
    """An empty list of indices or ids (a field's default)."""
    return np.zeros(0, dtype=np.int64)


def _pairs() -> IntArray:
    """An empty list of id pairs (a field's default)."""
    return np.zeros((0, 2), dtype=np.int64)


def _values() -> FloatArray:
    """An empty list of eigenvalues (a field's default)."""
    return np.zeros(0)


@dataclass(frozen=True, eq=False)
class LintReport:
    """Problems found in a pose graph by :func:`lint`.

    Attributes
    ----------
    name : str
    n, m : int
        Numbers of vertices and edges.
    indefinite : int array ``(k,)``
        Edges whose information matrix (its symmetric part) is not positive definite.
    indefinite_ids : int array ``(k, 2)``
        Their vertex ids ``(i, j)`` as in the source.
    min_eigenvalues : ``(k,)``
        Their smallest eigenvalue.
    asymmetric : int array
        Edges whose information matrix is not symmetric (to ``1e-12`` relative).
    duplicates : int array ``(d,)``
        Edges joining the same two vertices (either way) as an earlier edge.
    duplicate_ids : int array ``(d, 2)``
        Their vertex ids.
    isolated : int array
        Ids of vertices with no edge.
    anchor : int
        Id of the vertex connectivity is checked from (the graph's ``anchor``).
    unreachable : int array
        Ids of vertices not connected to the anchor.
    overflow : int array ``(o,)``
        Edges whose information matrix has eigenvalues beyond the double range
        (``|λ| > 1.8e308``; found with each matrix scaled by its largest entry) or
        non-finite entries: no cost can use them (their terms overflow).
    overflow_ids : int array ``(o, 2)``
        Their vertex ids.
    renormalized : int or None
        Quaternions the g2o reader normalized (norm off by more than 1e-12, within its
        ``quaternion_tol``): a note, not a problem (:attr:`ok` ignores it). Known only
        for a report of a file (:func:`manopt_lie.problems.g2o.lint` given a path or a
        file object); ``None`` for a report of a graph, which does not keep it.
    quaternion_error : float or None
        The largest ``| ‖q‖ − 1 |`` among the file's quaternions (0 for 2-D files);
        ``None`` as :attr:`renormalized`.

    For a :class:`~manopt_lie.problems.LandmarkGraph` (the fields below are empty for pose
    graphs), ``n`` counts the poses and ``m`` the relative-pose edges, and the pose-graph
    fields above are those of :attr:`LandmarkGraph.poses`, except :attr:`isolated` (poses
    without any measurement: edge, observation or prior) and :attr:`unreachable` (pose and
    landmark ids not connected, through edges, observations and priors, to what fixes the
    gauge: the ``FIX``-ed poses, the priors, or else the anchor pose).

    Attributes
    ----------
    n_landmarks : int or None
        Number of landmarks; ``None`` for a pose graph.
    n_observations, n_priors : int
    unseen : int array
        Ids of landmarks no observation sees (nothing determines them).
    seen_once : int array
        Ids of landmarks seen by exactly one observation (with :attr:`unseen`: the
        landmarks seen fewer than twice). One relative point with full-rank information
        fixes a landmark in principle, but nothing checks it: an outlier goes unnoticed.
    out_of_view : int array
        Ids of landmarks whose estimate is farther than :attr:`view_range` from every pose
        estimate: no pose could have seen them where they are. Checked only when the graph
        has estimates of the poses and the landmarks, and observations.
    view_range : float or None
        The largest range an observation measured from its pose, ``max ‖z_o‖ + ‖t_{S_o}‖``
        (the point's distance from the sensor plus the sensor's from the pose, so that every
        observed landmark is within it of its pose if the estimates fit the measurements);
        ``None`` when :attr:`out_of_view` was not checked.
    duplicate_observations : int array ``(k,)``
        Observations of the same landmark from the same pose (and, in 3-D, with the same
        sensor offset id) as an earlier one.
    duplicate_observation_ids : int array ``(k, 2)``
        Their ``(pose id, landmark id)``.
    indefinite_observations, asymmetric_observations, overflow_observations : int arrays
        Observations whose information matrix is not positive definite, not symmetric, or
        beyond double precision (as for edges).
    indefinite_observation_ids, overflow_observation_ids : int arrays ``(k, 2)``
        Their ``(pose id, landmark id)``.
    observation_min_eigenvalues : ``(k,)``
        The smallest eigenvalue of each indefinite one.
    indefinite_priors, asymmetric_priors, overflow_priors : int arrays
        The same for the priors' information matrices.
    indefinite_prior_ids, overflow_prior_ids : int arrays
        The ids of their poses.
    prior_min_eigenvalues : ``(k,)``
    """

    name: str
    n: int
    m: int
    indefinite: IntArray
    indefinite_ids: IntArray
    min_eigenvalues: FloatArray
    asymmetric: IntArray
    duplicates: IntArray
    duplicate_ids: IntArray
    isolated: IntArray
    anchor: int
    unreachable: IntArray
    overflow: IntArray = field(default_factory=_ids)
    overflow_ids: IntArray = field(default_factory=_pairs)
    renormalized: int | None = None
    quaternion_error: float | None = None
    n_landmarks: int | None = None
    n_observations: int = 0
    n_priors: int = 0
    unseen: IntArray = field(default_factory=_ids)
    seen_once: IntArray = field(default_factory=_ids)
    out_of_view: IntArray = field(default_factory=_ids)
    view_range: float | None = None
    duplicate_observations: IntArray = field(default_factory=_ids)
    duplicate_observation_ids: IntArray = field(default_factory=_pairs)
    indefinite_observations: IntArray = field(default_factory=_ids)
    indefinite_observation_ids: IntArray = field(default_factory=_pairs)
    observation_min_eigenvalues: FloatArray = field(default_factory=_values)
    asymmetric_observations: IntArray = field(default_factory=_ids)
    overflow_observations: IntArray = field(default_factory=_ids)
    overflow_observation_ids: IntArray = field(default_factory=_pairs)
    indefinite_priors: IntArray = field(default_factory=_ids)
    indefinite_prior_ids: IntArray = field(default_factory=_ids)
    prior_min_eigenvalues: FloatArray = field(default_factory=_values)
    asymmetric_priors: IntArray = field(default_factory=_ids)
    overflow_priors: IntArray = field(default_factory=_ids)
    overflow_prior_ids: IntArray = field(default_factory=_ids)

    @property
    def connected(self) -> bool:
        """Whether every vertex is connected to the anchor."""
        return not self.unreachable.size

    @property
    def ok(self) -> bool:
        """``True`` when no problem was found (duplicates and, for landmark graphs, landmarks
        seen fewer than twice or out of view included; normalized quaternions are not a
        problem)."""
        found = self.indefinite.size or self.asymmetric.size or self.duplicates.size or self.isolated.size
        landmarks = (
            self.unseen, self.seen_once, self.out_of_view, self.duplicate_observations, self.indefinite_observations,
            self.asymmetric_observations, self.overflow_observations, self.indefinite_priors, self.asymmetric_priors,
            self.overflow_priors,
        )  # fmt: skip
        return not (found or self.overflow.size or any(a.size for a in landmarks)) and self.connected

    def __str__(self) -> str:
        landmark = self.n_landmarks is not None
        if landmark:
            counts = [(self.n, "pose", "poses"), (self.n_landmarks or 0, "landmark", "landmarks"),
                      (self.m, "edge", "edges"), (self.n_observations, "observation", "observations"),
                      (self.n_priors, "prior", "priors")]  # fmt: skip
            head = f"{self.name}: " + ", ".join(_count(*c) for c in counts)
        else:
            head = f"{self.name}: {self.n} vertices, {self.m} edges"
        note = ""
        if self.renormalized:
            what = _count(self.renormalized, "quaternion", "quaternions")
            note = f"  note: {what} normalized (| ‖q‖ − 1 | up to {self.quaternion_error:.2g})"
        if self.ok:
            return f"{head}: ok" + (f"\n{note}" if note else "")
        lines = [head]
        edges = [f"{i}→{j}" for i, j in self.overflow_ids], [f"{i}→{j}" for i, j in self.indefinite_ids]
        _information(lines, "", edges, self.min_eigenvalues, self.asymmetric, "edges")
        observations = ([f"{i}→{j}" for i, j in self.overflow_observation_ids],
                        [f"{i}→{j}" for i, j in self.indefinite_observation_ids])  # fmt: skip
        _information(lines, "observation ", observations, self.observation_min_eigenvalues,
                     self.asymmetric_observations, "observations")  # fmt: skip
        priors = [f"on {i}" for i in self.overflow_prior_ids], [f"on {i}" for i in self.indefinite_prior_ids]
        _information(lines, "prior ", priors, self.prior_min_eigenvalues, self.asymmetric_priors, "priors")
        if self.duplicates.size:
            what = _count(self.duplicates.size, "duplicate edge", "duplicate edges")
            lines.append(f"  {what}: {_some(f'{i}→{j}' for i, j in self.duplicate_ids)}")
        if self.duplicate_observations.size:
            what = _count(self.duplicate_observations.size, "duplicate observation", "duplicate observations")
            lines.append(f"  {what}: {_some(f'{i}→{j}' for i, j in self.duplicate_observation_ids)}")
        if self.unseen.size:
            lines.append(f"  {_count(self.unseen.size, 'landmark', 'landmarks')} never seen: {_some(self.unseen)}")
        if self.seen_once.size:
            what = _count(self.seen_once.size, "landmark", "landmarks")
            lines.append(f"  {what} seen only once (fewer than twice): {_some(self.seen_once)}")
        if self.out_of_view.size:
            what = _count(self.out_of_view.size, "landmark", "landmarks")
            lines.append(f"  {what} out of view (farther than the largest measured range, {self.view_range:.3g}, "
                         f"from every pose): {_some(self.out_of_view)}")  # fmt: skip
        if self.isolated.size:
            if landmark:
                what = _count(self.isolated.size, "pose", "poses")
                lines.append(f"  {what} without measurements: {_some(self.isolated)}")
            else:
                what = _count(self.isolated.size, "vertex", "vertices")
                lines.append(f"  {what} without edges: {_some(self.isolated)}")
        if self.unreachable.size:
            what = _count(self.unreachable.size, "vertex", "vertices")
            source = (f"what fixes the gauge (FIX-ed poses, priors, else pose {self.anchor})" if landmark else
                      f"vertex {self.anchor}")  # fmt: skip
            lines.append(f"  not connected: {what} unreachable from {source}: {_some(self.unreachable)}")
        if note:
            lines.append(note)
        return "\n".join(lines)


def _information(
    lines: list[str], kind: str, names: tuple[list[str], list[str]], lam: FloatArray, asymmetric: IntArray, noun: str
) -> None:
    """The lines on ``kind`` information matrices: overflowing, indefinite (``names``: of
    those two), asymmetric (their indices, as ``noun``)."""
    overflow, indefinite = names
    if overflow:
        what = _count(len(overflow), f"{kind}information matrix", f"{kind}information matrices")
        lines.append(f"  {what} beyond double precision (eigenvalues overflow): {_some(overflow)}")
    if indefinite:
        items = [f"{name} (λmin {value:.3g})" for name, value in zip(indefinite, lam, strict=True)]
        what = _count(len(indefinite), f"{kind}information matrix", f"{kind}information matrices")
        lines.append(f"  {what} not positive definite: {_some(items)}")
    if asymmetric.size:
        what = _count(asymmetric.size, f"{kind}information matrix", f"{kind}information matrices")
        lines.append(f"  {what} not symmetric: {noun} {_some(asymmetric)}")


def _count(k: int, singular: str, plural: str) -> str:
    return f"{k} {singular if k == 1 else plural}"


def _some(items: Iterable[Any], k: int = 10) -> str:
    """The first ``k`` items, comma-separated, and how many more there are."""
    texts = [str(i) for i in items]
    more = f", … ({len(texts) - k} more)" if len(texts) > k else ""
    return ", ".join(texts[:k]) + more


def lint(graph: Any) -> LintReport:
    """Check a measurement graph (:class:`~manopt_lie.problems.graph.MeasurementGraph`) for common problems.

    Finds information matrices that are not symmetric positive definite or whose
    eigenvalues overflow (:func:`eigenvalues`), duplicate edges, vertices without edges
    and vertices not connected to the anchor vertex (vertex 0 unless ``FIX`` says
    otherwise). Nothing is raised; see :attr:`LintReport.ok` and ``str(report)``. What
    only a file shows (normalized quaternions) is reported by
    :func:`manopt_lie.problems.g2o.lint` of the file.

    A :class:`~manopt_lie.problems.LandmarkGraph` is checked as its pose graph, and for the
    problems of its landmarks, observations and priors (:class:`LintReport` lists them):
    landmarks seen fewer than twice, never seen, or out of every pose's view (farther from
    every pose estimate than the largest measured range), duplicate observations, and
    information matrices of observations and priors as for edges.
    """
    if not isinstance(graph, MeasurementGraph):  # poses and landmarks: more than one kind of variable
        return _lint_landmarks(graph)
    ids: IntArray = graph.ids  # type: ignore[assignment]
    n, m, edges = graph.n, graph.m, graph.edges
    info = np.asarray(graph.information, dtype=np.float64)

    lam, asymmetric, overflow = eigenvalues(info)
    indefinite = np.flatnonzero(~(lam > 0.0))

    pairs = np.sort(edges, axis=1)
    _, first = np.unique(pairs, axis=0, return_index=True)
    duplicates = np.setdiff1d(np.arange(m), first)

    degree = np.bincount(edges.ravel(), minlength=n)
    isolated = ids[degree == 0]
    unreachable = np.zeros(0, dtype=np.int64)
    if n:
        adjacency = coo_matrix((np.ones(m), (edges[:, 0], edges[:, 1])), shape=(n, n))
        _, labels = connected_components(adjacency, directed=False)
        unreachable = ids[labels != labels[graph.anchor]]
    return LintReport(
        name=graph.name,
        n=n,
        m=m,
        indefinite=indefinite,
        indefinite_ids=ids[edges[indefinite]].reshape(-1, 2),
        min_eigenvalues=np.asarray(lam[indefinite], dtype=np.float64),
        asymmetric=asymmetric,
        duplicates=duplicates,
        duplicate_ids=ids[edges[duplicates]].reshape(-1, 2),
        isolated=isolated,
        anchor=int(ids[graph.anchor]) if n else 0,
        unreachable=unreachable,
        overflow=overflow,
        overflow_ids=ids[edges[overflow]].reshape(-1, 2),
    )


def _lint_landmarks(graph: LandmarkGraph) -> LintReport:
    """:func:`lint` of a landmark graph (see :class:`LintReport`)."""
    base, poses = lint(graph.poses), graph.poses
    n, count = graph.n, graph.n_landmarks
    pose_ids, landmark_ids = poses.ids, graph.landmark_ids
    obs, priors = graph.observations, graph.prior_poses
    k, p = len(obs), len(priors)

    degree = np.bincount(poses.edges.ravel(), minlength=n) + np.bincount(obs[:, 0], minlength=n)
    isolated = pose_ids[degree + np.bincount(priors, minlength=n) == 0]
    # Poses, landmarks and (with priors) the world as one graph; what is linked to the gauge is determined.
    world = n + count
    rows = np.concatenate([poses.edges[:, 0], obs[:, 0], priors])
    cols = np.concatenate([poses.edges[:, 1], n + obs[:, 1], np.full(p, world)])
    _, labels = connected_components(coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(world + 1, world + 1)),
                                     directed=False)  # fmt: skip
    fixed = np.concatenate([graph.gauge if n else np.zeros(0, np.int64), [world] if p else []]).astype(np.int64)
    linked = np.isin(labels[:world], labels[fixed])
    unreachable = np.sort(np.concatenate([pose_ids, landmark_ids])[~linked])

    seen = np.bincount(obs[:, 1], minlength=count)
    sensor = np.zeros(k, dtype=np.int64) if graph.offset_ids is None else graph.offset_ids
    _, first = np.unique(np.stack([obs[:, 0], obs[:, 1], sensor], axis=1), axis=0, return_index=True)
    duplicates = np.setdiff1d(np.arange(k), first)
    names = np.stack([pose_ids[obs[:, 0]], landmark_ids[obs[:, 1]]], axis=1)

    lam_o, asymmetric_o, overflow_o = eigenvalues(graph.point_information)
    indefinite_o = np.flatnonzero(~(lam_o > 0.0))
    assert graph.prior_information is not None  # LandmarkGraph sets it
    lam_p, asymmetric_p, overflow_p = eigenvalues(graph.prior_information)
    indefinite_p = np.flatnonzero(~(lam_p > 0.0))
    view_range, out_of_view = _view(graph)
    return replace(
        base,
        isolated=isolated,
        unreachable=unreachable,
        n_landmarks=count,
        n_observations=k,
        n_priors=p,
        unseen=landmark_ids[seen == 0],
        seen_once=landmark_ids[seen == 1],
        out_of_view=out_of_view,
        view_range=view_range,
        duplicate_observations=duplicates,
        duplicate_observation_ids=names[duplicates].reshape(-1, 2),
        indefinite_observations=indefinite_o,
        indefinite_observation_ids=names[indefinite_o].reshape(-1, 2),
        observation_min_eigenvalues=np.asarray(lam_o[indefinite_o], dtype=np.float64),
        asymmetric_observations=asymmetric_o,
        overflow_observations=overflow_o,
        overflow_observation_ids=names[overflow_o].reshape(-1, 2),
        indefinite_priors=indefinite_p,
        indefinite_prior_ids=pose_ids[priors[indefinite_p]],
        prior_min_eigenvalues=np.asarray(lam_p[indefinite_p], dtype=np.float64),
        asymmetric_priors=asymmetric_p,
        overflow_priors=overflow_p,
        overflow_prior_ids=pose_ids[priors[overflow_p]],
    )


def _view(graph: LandmarkGraph) -> tuple[float | None, IntArray]:
    """The largest measured range and the ids of the landmarks whose estimate is farther than it
    from every pose estimate (``None`` and none without estimates or observations)."""
    estimates, landmarks, d = graph.poses.poses, graph.landmarks, graph.d
    if estimates is None or landmarks is None or not len(graph.observations) or not graph.n:
        return None, np.zeros(0, dtype=np.int64)
    reach = _norms(graph.points)
    if graph.sensor_offsets is not None:
        with np.errstate(over="ignore"):  # huge offsets: an infinite range, so every landmark is in view
            reach = reach + _norms(graph.sensor_offsets.as_matrix()[:, :d, d])
    view = float(reach.max())
    positions = estimates.as_matrix()[:, :d, d]
    try:
        distance, _ = cKDTree(positions).query(landmarks, k=1)
    except (ValueError, OverflowError):  # pragma: no cover  # finite inputs: never seen
        return None, np.zeros(0, dtype=np.int64)
    with np.errstate(over="ignore"):
        out = np.asarray(distance) > view * (1.0 + 1e-9)
    return view, graph.landmark_ids[out]


def _norms(v: FloatArray) -> FloatArray:
    """Euclidean norms of ``(r, 2)`` or ``(r, 3)`` rows without overflow (``hypot``)."""
    out = np.hypot(v[:, 0], v[:, 1])
    return np.hypot(out, v[:, 2]) if v.shape[1] == 3 else out


def eigenvalues(info: FloatArray) -> tuple[FloatArray, IntArray, IntArray]:
    """Smallest eigenvalues of the symmetric parts of ``(m, k, k)`` matrices, without overflow.

    Each matrix is divided by its largest absolute entry before one batched ``eigvalsh``
    (so the decomposition sees entries in ``[-1, 1]`` whatever the file held), and the
    eigenvalues are scaled back; where that overflows the double range, or a matrix has
    non-finite entries, the edge is listed in ``overflow``. Never raises.

    Returns
    -------
    lam : ``(m,)``
        The smallest eigenvalues (``-inf`` where it overflows, ``nan`` for non-finite
        matrices); ``lam > 0`` exactly for the positive definite ones.
    asymmetric : int array
        Matrices not symmetric to ``1e-12`` relative to their largest entry.
    overflow : int array
        Matrices with an eigenvalue beyond the double range or a non-finite entry.
    """
    m = len(info)
    if not m:
        empty = np.zeros(0, dtype=np.int64)
        return np.zeros(0), empty, empty
    finite: NDArray[np.bool_] = np.asarray(np.isfinite(info).all(axis=(1, 2)))
    clean = np.where(finite[:, None, None], info, 0.0)  # non-finite matrices: nan eigenvalues below
    scale = np.abs(clean).max(axis=(1, 2))
    scale[scale == 0.0] = 1.0  # a zero matrix: its eigenvalues are 0 anyway
    unit = clean / scale[:, None, None]
    asymmetric = np.flatnonzero(np.abs(unit - np.swapaxes(unit, 1, 2)).max(axis=(1, 2)) > 1e-12)
    sym = 0.5 * (unit + np.swapaxes(unit, 1, 2))
    try:
        lam_unit = np.linalg.eigvalsh(sym)
    except np.linalg.LinAlgError:  # pragma: no cover  # entries in [-1, 1]: never seen; one by one then
        lam_unit = np.stack([_eigvalsh_or_nan(a) for a in sym])
    with np.errstate(over="ignore", under="ignore", invalid="ignore"):
        lam_all = lam_unit * scale[:, None]
    usable = finite & np.isfinite(lam_unit).all(axis=1)
    overflow = np.flatnonzero(~(usable & np.isfinite(lam_all).all(axis=1)))
    # Definiteness is read on the scaled matrix: an underflow of λ·scale to 0 does not count.
    smallest = np.where(lam_unit[:, 0] > 0.0, np.maximum(lam_all[:, 0], 5e-324), lam_all[:, 0])
    lam = np.asarray(np.where(usable, smallest, np.nan), dtype=np.float64)
    return lam, asymmetric, overflow


def _eigvalsh_or_nan(a: FloatArray) -> FloatArray:  # pragma: no cover  # see eigenvalues
    try:
        return np.asarray(np.linalg.eigvalsh(a), dtype=np.float64)
    except np.linalg.LinAlgError:
        return np.full(len(a), np.nan)
