"""Errors against ground truth: trajectory metrics as evo computes them, and per-edge residuals.

Trajectory metrics (Sturm et al., IROS 2012; Zhang & Scaramuzza, IROS 2018; evo):

- **alignment** (:func:`umeyama`, :func:`align_poses`): the similarity ``y ≈ s R x + t`` that
  minimizes ``Σ ‖y_i − (s R x_i + t)‖²`` over the positions, in closed form (Umeyama,
  PAMI 1991): with the centred point sets and ``Σ_xy = (1/n) Σ (y_i − ȳ)(x_i − x̄)ᵀ = U D Vᵀ``,
  ``R = U S Vᵀ`` (``S = diag(1, …, 1, det(U)det(V))``), ``s = tr(D S)/σ_x²`` (``1`` for SE(d))
  and ``t = ȳ − s R x̄``. The estimate's poses become ``(R R_i, s R t_i + t)``.
- **APE** (:func:`ape`): per pose ``E_i = P_i⁻¹ Q_i`` (estimate ``P``, reference ``Q``).
- **RPE** (:func:`rpe`): per pair ``(i, j)``, ``E_ij = (Q_i⁻¹ Q_j)⁻¹ (P_i⁻¹ P_j)``; pairs
  ``(0, Δ), (Δ, 2Δ), …``, or every ``(i, i + Δ)`` with ``all_pairs``.
- the **pose relation** turns ``E`` into a number (:data:`RELATIONS`, evo's ``-r`` names):
  ``trans_part`` ``‖t(E)‖`` (metres; the default), ``angle_rad``/``angle_deg`` the angle of
  ``R(E)``, ``rot_part`` ``‖R(E) − I‖_F``, ``full`` ``‖E − I‖_F``;
- **statistics** (:class:`Stats`): rmse, mean, median, std (population), min, max, sse.
- **association** (:func:`associate`): timestamps matched as evo does, each stamp of the
  shorter trajectory to the nearest one of the other within ``max_diff`` (0.01 s).

Everything is vectorized over the poses and works in 2-D (SE(2)) and 3-D (SE(3)).

For graphs, :func:`align` and :func:`errors` compare an estimate with the truth up to the
gauge ``X_i ↦ G X_i``: for poses ``G`` is the Umeyama SE(d) alignment of the positions (the
APE's), for rotations the Procrustes solution ``R = proj_SO(Σ R_i R̂_iᵀ)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from manopt_lie.errors import ShapeError
from manopt_lie.lie._matrix import project_rotation
from manopt_lie.lie.base import LieGroup

from . import costs

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

RELATIONS: dict[str, tuple[str, str]] = {
    "trans_part": ("translation part", "m"),
    "angle_deg": ("rotation angle in degrees", "deg"),
    "angle_rad": ("rotation angle in radians", "rad"),
    "rot_part": ("rotation part", ""),
    "full": ("full transformation", ""),
}
"""Pose relations by evo's ``-r`` name: ``(what evo's title calls it, unit)``."""

MAX_DIFF = 0.01
"""Default largest timestamp difference (seconds) of an association, evo's ``--t_max_diff``."""


@dataclass(frozen=True)
class Stats:
    """Summary of non-negative errors, with evo's names (``std`` is the population deviation)."""

    rmse: float
    mean: float
    median: float
    std: float
    min: float
    max: float
    sse: float

    @classmethod
    def of(cls, e: Any) -> Stats:
        """The statistics of the errors ``e`` (a non-empty 1-D array)."""
        e = np.asarray(e, dtype=np.float64).reshape(-1)
        if not e.size:
            raise ValueError("no errors to summarize")
        sse = float(np.sum(e**2))
        return cls(float(np.sqrt(sse / e.size)), float(np.mean(e)), float(np.median(e)), float(np.std(e)),
                   float(np.min(e)), float(np.max(e)), sse)  # fmt: skip

    @property
    def rms(self) -> float:
        """:attr:`rmse` (the name :func:`errors` callers use)."""
        return self.rmse

    def to_json(self) -> dict[str, float]:
        return {k: getattr(self, k) for k in ("rmse", "mean", "median", "std", "min", "max", "sse")}


# ---- alignment ---------------------------------------------------------------------------


def umeyama(x: Any, y: Any, *, with_scale: bool = False) -> tuple[FloatArray, FloatArray, float]:
    """The similarity ``y ≈ s R x + t`` of least squares (Umeyama 1991, eqs. 34–43; see the module doc).

    Parameters
    ----------
    x, y : ``(n, d)``
        Corresponding points (rows).
    with_scale : bool
        Fit ``s`` (Sim(d)); else ``s = 1`` (SE(d)).

    Returns
    -------
    R : ``(d, d)`` rotation
    t : ``(d,)``
    s : float

    Raises
    ------
    ValueError
        For mismatched shapes, or points whose cross-covariance has rank below ``d − 1``
        (all on one line in 3-D, or all equal): the rotation is then not determined.
    """
    x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    if x.ndim != 2 or x.shape != y.shape or x.shape[0] < 1:
        raise ShapeError(f"umeyama: need two point sets of one shape (n, d), got {x.shape} and {y.shape}")
    n, d = x.shape
    mean_x, mean_y = x.mean(axis=0), y.mean(axis=0)
    xc, yc = x - mean_x, y - mean_y
    sigma_x = float(np.sum(xc**2)) / n
    u, singular, vt = np.linalg.svd(yc.T @ xc / n)
    if np.count_nonzero(singular > d * np.finfo(float).eps * max(singular[0], np.finfo(float).tiny)) < d - 1:
        raise ValueError("umeyama: the points are degenerate (collinear or coincident); the alignment is not defined")
    sign = np.ones(d)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        sign[-1] = -1.0  # a proper rotation, not a reflection
    r = (u * sign) @ vt
    s = float(np.sum(singular * sign) / sigma_x) if with_scale else 1.0
    return r, mean_y - s * r @ mean_x, s


def _rigid_inverse(t: FloatArray) -> FloatArray:
    d = t.shape[-1] - 1
    out = np.zeros_like(t)
    rt = np.swapaxes(t[..., :d, :d], -1, -2)
    out[..., :d, :d] = rt
    out[..., :d, d] = -np.einsum("...ij,...j->...i", rt, t[..., :d, d])
    out[..., d, d] = 1.0
    return out


def _matrices(x: LieGroup | Any) -> FloatArray:
    m = np.asarray(x.as_matrix() if hasattr(x, "as_matrix") else x, dtype=np.float64)
    if m.ndim != 3 or m.shape[1] != m.shape[2] or m.shape[1] not in (3, 4):
        raise ShapeError(f"need a batch (n,) of SE(2) or SE(3) poses (n, 3, 3) or (n, 4, 4), got {m.shape}")
    return m


@dataclass(frozen=True)
class Alignment:
    """What was applied to the estimate: ``P_i ↦ (R R_i, s R t_i + t)``.

    ``method`` is ``"none"``, ``"se"`` (SE(d) Umeyama), ``"sim"`` (Sim(d) Umeyama),
    ``"scale"`` (the Sim(d) scale only) or ``"origin"`` (the first poses made equal).
    """

    method: str
    rotation: FloatArray
    translation: FloatArray
    scale: float

    @property
    def matrix(self) -> FloatArray:
        """``[[s R, t], [0, 1]]``."""
        d = len(self.translation)
        m = np.eye(d + 1)
        m[:d, :d], m[:d, d] = self.scale * self.rotation, self.translation
        return m

    def apply(self, poses: FloatArray) -> FloatArray:
        d = len(self.translation)
        out = np.array(poses, dtype=np.float64)
        out[:, :d, :d] = self.rotation @ poses[:, :d, :d]
        out[:, :d, d] = self.scale * poses[:, :d, d] @ self.rotation.T + self.translation
        return out

    def describe(self, d: int = 3) -> str:
        return {"none": "not aligned", "se": f"with SE({d}) Umeyama alignment",
                "sim": f"with Sim({d}) Umeyama alignment", "scale": "scale corrected",
                "origin": "with origin alignment"}[self.method]  # fmt: skip


def align_poses(
    reference: Any, estimate: Any, *, align: bool = False, correct_scale: bool = False, align_origin: bool = False
) -> tuple[FloatArray, Alignment]:
    """The estimate's poses ``(n, d+1, d+1)`` aligned to the reference's, as ``evo_ape`` does:
    ``align`` fits SE(d) (``-a``), with ``correct_scale`` Sim(d) (``-as``); ``correct_scale``
    alone fits and applies only the scale (``-s``); ``align_origin`` moves the first estimated
    pose onto the first reference pose (``--align_origin``)."""
    ref, est = _matrices(reference), _matrices(estimate)
    if ref.shape != est.shape:
        raise ShapeError(f"align_poses: reference {ref.shape} and estimate {est.shape} differ (associate them first)")
    d = ref.shape[-1] - 1
    if align_origin and (align or correct_scale):
        raise ValueError("align_origin cannot be combined with align or correct_scale")
    if align_origin:
        g = ref[0] @ _rigid_inverse(est[0])
        alignment = Alignment("origin", g[:d, :d], g[:d, d], 1.0)
    elif align or correct_scale:
        r, t, s = umeyama(est[:, :d, d], ref[:, :d, d], with_scale=correct_scale)
        if align:
            alignment = Alignment("sim" if correct_scale else "se", r, t, s)
        else:
            alignment = Alignment("scale", np.eye(d), np.zeros(d), s)
    else:
        alignment = Alignment("none", np.eye(d), np.zeros(d), 1.0)
    return alignment.apply(est), alignment


# ---- APE, RPE ----------------------------------------------------------------------------


def _angle(r: FloatArray) -> FloatArray:
    """Rotation angles in ``[0, π]`` of rotation matrices ``(k, d, d)``, accurate everywhere
    (``atan2`` of the sine and cosine parts)."""
    if r.shape[-1] == 2:
        return np.abs(np.arctan2(r[:, 1, 0] - r[:, 0, 1], r[:, 0, 0] + r[:, 1, 1]))
    skew = np.stack([r[:, 2, 1] - r[:, 1, 2], r[:, 0, 2] - r[:, 2, 0], r[:, 1, 0] - r[:, 0, 1]], axis=1)
    return np.arctan2(0.5 * np.linalg.norm(skew, axis=1), 0.5 * (np.trace(r, axis1=1, axis2=2) - 1.0))


def relation_errors(e: FloatArray, relation: str = "trans_part") -> FloatArray:
    """The numbers of the pose relation ``relation`` (:data:`RELATIONS`) of error poses ``E`` ``(k, d+1, d+1)``."""
    if relation not in RELATIONS:
        raise ValueError(f"pose relation must be one of {tuple(RELATIONS)}, got {relation!r}")
    d = e.shape[-1] - 1
    if relation == "trans_part":
        return np.linalg.norm(e[:, :d, d], axis=1)
    if relation == "rot_part":
        return np.linalg.norm(e[:, :d, :d] - np.eye(d), axis=(1, 2))
    if relation == "full":
        return np.linalg.norm(e - np.eye(d + 1), axis=(1, 2))
    angle = _angle(e[:, :d, :d])
    return np.degrees(angle) if relation == "angle_deg" else angle


@dataclass(frozen=True)
class PoseError:
    """The result of :func:`ape` or :func:`rpe`.

    Attributes
    ----------
    metric : ``"ape"`` or ``"rpe"``
    relation : a key of :data:`RELATIONS`
    errors : ``(k,)`` one per pose (APE) or pair (RPE)
    stats : Stats
    alignment : Alignment
    pairs : ``(k, 2)`` int, the RPE's index pairs (``None`` for APE)
    delta : the RPE's Δ in frames (``None`` for APE)
    all_pairs : bool
    """

    metric: str
    relation: str
    errors: FloatArray
    stats: Stats
    alignment: Alignment
    d: int
    pairs: IntArray | None = None
    delta: int | None = None
    all_pairs: bool = False

    @property
    def unit(self) -> str:
        return RELATIONS[self.relation][1]

    @property
    def title(self) -> str:
        """evo's title: ``"APE w.r.t. translation part (m)\\n(with SE(3) Umeyama alignment)"``."""
        what, unit = RELATIONS[self.relation]
        head = f"{self.metric.upper()} w.r.t. {what}" + (f" ({unit})" if unit else "")
        if self.metric == "rpe":
            head += f"\nfor delta = {self.delta} (frames) using {'all' if self.all_pairs else 'consecutive'} pairs"
        return f"{head}\n({self.alignment.describe(self.d)})"

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "metric": self.metric, "pose_relation": self.relation, "unit": self.unit, **self.stats.to_json(),
            "count": int(self.errors.size), "alignment": self.alignment.method, "scale": self.alignment.scale,
            "alignment_matrix": self.alignment.matrix.tolist(),
        }  # fmt: skip
        if self.metric == "rpe":
            out |= {"delta": self.delta, "delta_unit": "frames", "all_pairs": self.all_pairs}
        return out


def ape(
    reference: Any, estimate: Any, *, relation: str = "trans_part", align: bool = False, correct_scale: bool = False,
    align_origin: bool = False,
) -> PoseError:  # fmt: skip
    """The absolute pose error of associated poses (batches ``(n,)`` of SE(d), or matrices
    ``(n, d+1, d+1)``), after the alignment of :func:`align_poses`; ``E_i = P_i⁻¹ Q_i``."""
    ref = _matrices(reference)
    est, alignment = align_poses(ref, estimate, align=align, correct_scale=correct_scale, align_origin=align_origin)
    e = _rigid_inverse(est) @ ref
    errors = relation_errors(e, relation)
    return PoseError("ape", relation, errors, Stats.of(errors), alignment, ref.shape[-1] - 1)


def rpe_pairs(n: int, delta: int = 1, *, all_pairs: bool = False) -> IntArray:
    """evo's index pairs for a Δ in frames: ``(0, Δ), (Δ, 2Δ), …`` or, with ``all_pairs``,
    every ``(i, i + Δ)``. An empty result raises ``ValueError``."""
    if delta < 1:
        raise ValueError(f"delta must be a positive number of frames, got {delta}")
    if all_pairs:
        first = np.arange(max(n - delta, 0))
        pairs = np.stack([first, first + delta], axis=1)
    else:
        ids = np.arange(0, n, delta)
        pairs = np.stack([ids[:-1], ids[1:]], axis=1)
    if not len(pairs):
        raise ValueError(f"delta = {delta} (frames) gives no pairs among {n} poses: try a smaller delta")
    return pairs.astype(np.int64)


def rpe(
    reference: Any, estimate: Any, *, delta: int = 1, all_pairs: bool = False, relation: str = "trans_part",
    align: bool = False, correct_scale: bool = False, align_origin: bool = False,
) -> PoseError:  # fmt: skip
    """The relative pose error of associated poses over :func:`rpe_pairs`, after the alignment
    of :func:`align_poses` (only a scale changes it); ``E_ij = (Q_i⁻¹ Q_j)⁻¹ (P_i⁻¹ P_j)``."""
    ref = _matrices(reference)
    est, alignment = align_poses(ref, estimate, align=align, correct_scale=correct_scale, align_origin=align_origin)
    pairs = rpe_pairs(len(ref), delta, all_pairs=all_pairs)
    i, j = pairs[:, 0], pairs[:, 1]
    q_rel = _rigid_inverse(ref[i]) @ ref[j]
    p_rel = _rigid_inverse(est[i]) @ est[j]
    errors = relation_errors(_rigid_inverse(q_rel) @ p_rel, relation)
    return PoseError("rpe", relation, errors, Stats.of(errors), alignment, ref.shape[-1] - 1, pairs, delta, all_pairs)


# ---- association -------------------------------------------------------------------------


def _match(short: FloatArray, long: FloatArray, max_diff: float) -> tuple[IntArray, IntArray]:
    """evo's ``matching_time_indices``: each stamp of ``short`` to the nearest of ``long``
    within ``max_diff`` (binary search on sorted stamps, else a linear search)."""
    if not len(long) or not len(short):
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    if not np.all(np.diff(long) >= 0):
        best = np.empty(len(short), np.int64)
        step = max(1, 4_000_000 // len(long))  # bounded memory for the |short| × |long| differences
        for k in range(0, len(short), step):
            best[k : k + step] = np.argmin(np.abs(long[None, :] - short[k : k + step, None]), axis=1)
        keep = np.abs(long[best] - short) <= max_diff
        return np.flatnonzero(keep), best[keep]
    inside = (short >= long[0] - max_diff) & (short <= long[-1] + max_diff)
    j = np.minimum(np.searchsorted(long, short, side="right"), len(long) - 1)
    upper = long[j] - short
    lower = np.where(j > 0, short - long[np.maximum(j - 1, 0)], np.inf)
    take_upper = (upper <= max_diff) & (upper < lower)
    take_lower = ~take_upper & (lower <= max_diff) & (lower <= upper)
    keep = inside & (take_upper | take_lower)
    return np.flatnonzero(keep), np.where(take_upper, j, j - 1)[keep].astype(np.int64)


def associate(
    reference_stamps: Any, estimate_stamps: Any, *, max_diff: float = MAX_DIFF, offset: float = 0.0
) -> tuple[IntArray, IntArray]:
    """Indices ``(i_ref, i_est)`` of the poses matched by timestamp, as evo's
    ``associate_trajectories``: every stamp of the trajectory with fewer poses (the estimate on
    a tie) goes to the nearest stamp of the other within ``max_diff`` seconds; ``offset`` is
    added to the estimate's stamps.

    Raises
    ------
    ValueError
        When no stamps match.
    """
    ref = np.asarray(reference_stamps, dtype=np.float64).reshape(-1)
    est = np.asarray(estimate_stamps, dtype=np.float64).reshape(-1)
    if max_diff < 0:
        raise ValueError(f"max_diff must be non-negative, got {max_diff}")
    if len(est) > len(ref):
        i_ref, i_est = _match(ref, est + offset, max_diff)
    else:
        i_est, i_ref = _match(est, ref - offset, max_diff)
    if not len(i_ref):
        raise ValueError(
            f"no matching timestamps between the reference and the estimate with a largest difference of "
            f"{max_diff} s and an offset of {offset} s"
        )
    return i_ref, i_est


# ---- graphs against ground truth ----------------------------------------------------------


@dataclass(frozen=True)
class Errors:
    """Per-element errors after alignment: rotation angles (radians) and, for poses,
    translation distances."""

    rotation: FloatArray
    translation: FloatArray | None

    @property
    def rotation_stats(self) -> Stats:
        return Stats.of(self.rotation)

    @property
    def translation_stats(self) -> Stats | None:
        return None if self.translation is None else Stats.of(self.translation)


def _rotation_part(x: LieGroup) -> FloatArray:
    d = x.point_dim  # type: ignore[attr-defined]
    return x.as_matrix()[..., :d, :d]


def align(estimate: LieGroup, truth: LieGroup) -> LieGroup:
    """``G · estimate`` for the global motion ``G`` closest to ``truth``: the Umeyama SE(d)
    alignment of the positions for poses, the rotations' Procrustes solution otherwise."""
    if type(estimate) is not type(truth) or estimate.batch_shape != truth.batch_shape or len(estimate.batch_shape) != 1:
        raise ShapeError(f"align: need two batches (n,) of one group, got {estimate!r} and {truth!r}")
    d = estimate.point_dim  # type: ignore[attr-defined]
    m_est, m_true = estimate.as_matrix(), truth.as_matrix()
    g = np.eye(m_est.shape[-1])
    if g.shape[0] > d and len(m_est) >= 2:
        try:
            g[:d, :d], g[:d, d], _ = umeyama(m_est[:, :d, d], m_true[:, :d, d])
            return type(estimate).from_matrix(g) @ estimate
        except ValueError:  # degenerate positions: fall back on the rotations
            pass
    g[:d, :d] = project_rotation(np.einsum("nij,nkj->ik", _rotation_part(truth), _rotation_part(estimate)))
    if g.shape[0] > d:
        g[:d, d] = np.mean(m_true[:, :d, d] - m_est[:, :d, d] @ g[:d, :d].T, axis=0)
    return type(estimate).from_matrix(g) @ estimate


def errors(estimate: LieGroup, truth: LieGroup) -> Errors:
    """Rotation angles ``|Log(R_iᵀ R̂_i)|`` and translation distances ``‖t̂_i − t_i‖`` after
    :func:`align` (for poses, the translation errors are the APE's)."""
    aligned = align(estimate, truth)
    angle = _angle(np.einsum("nji,njk->nik", _rotation_part(truth), _rotation_part(aligned)))
    d = estimate.point_dim  # type: ignore[attr-defined]
    translation = None
    if aligned.as_matrix().shape[-1] > d:
        translation = np.linalg.norm(aligned.as_matrix()[:, :d, d] - truth.as_matrix()[:, :d, d], axis=1)
    return Errors(angle, translation)


def edge_residuals(graph: Any, x: LieGroup) -> dict[str, Any]:
    """Per-edge whitened residual norms ``‖Lᵀr_e‖`` of a measurement graph at ``x``
    (geodesic residuals ``r_e = Log(Z_e⁻¹X_i⁻¹X_j)``, ``Ω_e = L Lᵀ`` its
    ``information``), with summary statistics and the ``chi2`` value ``Σ rᵀΩr`` —
    large entries point at outliers."""
    r = costs.geodesic_residuals(x, graph.edges, graph.measurements)
    chi2 = np.einsum("ei,eij,ej->e", r, graph.information, r)
    norms = np.sqrt(np.maximum(chi2, 0.0))
    return {"norms": norms, "stats": Stats.of(norms), "chi2": float(np.sum(chi2))}
