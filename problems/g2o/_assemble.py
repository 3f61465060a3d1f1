"""The whole-file part of reading: ids resolved and checked, then a :class:`PoseGraph` or a
:class:`LandmarkGraph` built from the arrays of each tag (:mod:`._reader`).

Poses and landmarks share one id space. A kind of vertex is *defined* by its ``VERTEX``
lines, or, in a file with none of that kind, by the measurements naming it (an edges-only
file, as g2o's own tools write them). Every problem found — a duplicate id, an id used as a
pose and as a landmark, an edge, observation, prior or ``FIX`` naming an undefined vertex or
parameter, or a vertex of the wrong kind — is collected with its line, and the earliest is
raised.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from manopt_lie import SE2, SE3, SO2
from manopt_lie.lie.base import LieGroup

from ..landmarks import LandmarkGraph
from ..pose_graph import PoseGraph
from ._records import EDGE, LANDMARK, OBSERVATION, PARAM, POSE, PRIOR, RECORDS, TAG, FloatArray, IntArray, ParseError

if TYPE_CHECKING:
    from ._reader import Tag

__all__ = ["assemble", "elements", "is_identity"]

Problems = list[tuple[int, str]]


class _Defined(NamedTuple):
    """One kind of vertex (or the parameters): sorted distinct ids, the line defining each
    (its ``VERTEX`` line, or the first line naming it) and whether ``VERTEX`` lines did."""

    ids: IntArray
    lines: IntArray
    explicit: bool

    def line_of(self, ids: IntArray) -> IntArray:
        return self.lines[np.searchsorted(self.ids, ids)]


def _first(ids: IntArray, lines: IntArray) -> tuple[IntArray, IntArray, IntArray]:
    """Distinct ``ids`` (sorted), the earliest line of each, and the rows that repeat an id."""
    order = np.lexsort((lines, ids))
    ids_sorted = ids[order]
    head = np.ones(len(ids_sorted), dtype=bool)
    head[1:] = ids_sorted[1:] != ids_sorted[:-1]
    return ids_sorted[head], lines[order][head], order[~head]


def _duplicates(ids: IntArray, lines: IntArray, what: str, problems: Problems) -> _Defined:
    """Defined ids from their lines; the earliest repeated one is a problem."""
    unique, first, repeats = _first(ids, lines)
    if repeats.size:
        row = int(repeats[np.argmin(lines[repeats])])
        reason = f"duplicate {what} id {ids[row]} (first on line {first[np.searchsorted(unique, ids[row])]})"
        problems.append((int(lines[row]), reason))
    return _Defined(unique, first, True)


def _named(refs: list[tuple[IntArray, IntArray]]) -> _Defined:
    """Ids defined by the measurements naming them (first use)."""
    ids = np.concatenate([r[0] for r in refs]) if refs else np.zeros(0, np.int64)
    lines = np.concatenate([r[1] for r in refs]) if refs else np.zeros(0, np.int64)
    unique, first, _ = _first(ids, lines)
    return _Defined(unique, first, False)


def _clashes(poses: _Defined, landmarks: _Defined, problems: Problems) -> None:
    """Ids defined both as a pose and as a landmark: a problem on the line where the second use is."""
    both = np.intersect1d(poses.ids, landmarks.ids)
    if not both.size:
        return
    at_pose, at_landmark = poses.line_of(both), landmarks.line_of(both)
    later = np.maximum(at_pose, at_landmark)
    k = int(np.argmin(later))
    v, a, b = both[k], int(at_pose[k]), int(at_landmark[k])
    if a == b:
        reason = f"vertex id {v} is named as both the pose and the landmark of the observation"
    elif b > a:
        reason = f"vertex id {v} is used as a landmark here and as a pose on line {a} (one id space)"
    else:
        reason = f"vertex id {v} is used as a pose here and as a landmark on line {b} (one id space)"
    problems.append((max(a, b), reason))


def _refs(
    ids: IntArray, lines: IntArray, want: _Defined, other: _Defined | None,
    message: Callable[[int, int, int | None], str], problems: Problems,
) -> None:  # fmt: skip
    """References ``ids`` that ``want`` does not define: a problem at the earliest such line.
    ``message(row, id, line)`` words it, ``line`` the line defining it as the other kind (or ``None``)."""
    bad = np.flatnonzero(~np.isin(ids, want.ids))
    if not bad.size:
        return
    row = int(bad[np.argmin(lines[bad])])
    v = ids[row]
    there = None
    if other is not None and np.isin(v, other.ids):
        there = int(other.line_of(np.array([v]))[0])
    problems.append((int(lines[row]), message(row, int(v), there)))


def assemble(
    tags: dict[str, Tag], group: type[LieGroup], fix_ids: list[int], fix_lines: list[int], filename: str, name: str
) -> PoseGraph | LandmarkGraph:
    """Check what needs the whole file and build the graph (a :class:`LandmarkGraph` when the
    file has landmarks, observations or priors, else a :class:`PoseGraph`)."""
    v_ids, v_lines = tags[TAG[group, POSE]].ids_and_lines()
    e_ids, e_lines = tags[TAG[group, EDGE]].ids_and_lines()
    l_ids, l_lines = tags[TAG[group, LANDMARK]].ids_and_lines()
    o_ids, o_lines = tags[TAG[group, OBSERVATION]].ids_and_lines()
    p_ids, p_lines = tags[TAG[group, PRIOR]].ids_and_lines()
    landmark_file = bool(len(l_ids) or len(o_ids) or len(p_ids))
    if not (len(v_ids) or len(e_ids) or landmark_file):
        raise ParseError("no VERTEX or EDGE lines", filename, None)
    problems: Problems = []
    pose_tag, landmark_tag = TAG[group, POSE], TAG[group, LANDMARK]

    # ---- what is defined ----
    if len(v_ids):
        poses = _duplicates(v_ids[:, 0], v_lines, "vertex", problems)
    else:
        poses = _named([(e_ids[:, 0], e_lines), (e_ids[:, 1], e_lines), (o_ids[:, 0], o_lines), (p_ids[:, 0], p_lines)])
    if len(l_ids):
        landmarks = _duplicates(l_ids[:, 0], l_lines, "vertex", problems)
    else:
        landmarks = _named([(o_ids[:, 1], o_lines)])
    _clashes(poses, landmarks, problems)

    # ---- what is named ----
    if len(e_ids) and poses.explicit:
        known = np.isin(e_ids, poses.ids)
        missing = np.flatnonzero(~known.all(axis=1))
        if missing.size:
            row = int(missing[0])
            absent = e_ids[row][~known[row]][0]
            i, j = e_ids[row]
            where = landmarks.line_of(np.array([absent]))[0] if np.isin(absent, landmarks.ids) else None
            reason = (f"edge {i} → {j} names vertex {absent}, which has no VERTEX line" if where is None else
                      f"edge {i} → {j} names vertex {absent}, a landmark (line {where}), not a pose")  # fmt: skip
            problems.append((int(e_lines[row]), reason))

    def observation(row: int) -> str:
        return f"observation {o_ids[row, 0]} → {o_ids[row, 1]}"

    def wrong(kind: str, tag: str, what: Callable[[int], str]) -> Callable[[int, int, int | None], str]:
        def message(row: int, v: int, there: int | None) -> str:
            if there is None:
                return f"{what(row)} names {kind} {v}, which has no {tag} line"
            other = "landmark" if kind == "pose" else "pose"
            return f"{what(row)} names {kind} {v}, but {v} is a {other} (line {there})"

        return message

    def prior(row: int) -> str:
        return f"prior on {p_ids[row, 0]}"

    if poses.explicit:
        _refs(o_ids[:, 0], o_lines, poses, landmarks, wrong("pose", pose_tag, observation), problems)
        _refs(p_ids[:, 0], p_lines, poses, landmarks, wrong("pose", pose_tag, prior), problems)
    if landmarks.explicit:
        _refs(o_ids[:, 1], o_lines, landmarks, poses, wrong("landmark", landmark_tag, observation), problems)
    params = None
    if group is SE3:
        s_ids, s_lines = tags[TAG[SE3, PARAM]].ids_and_lines()
        params = _duplicates(s_ids[:, 0], s_lines, "parameter", problems)
        param_tag = TAG[SE3, PARAM]
        _refs(o_ids[:, 2], o_lines, params, None, wrong("parameter", param_tag, observation), problems)
        _refs(p_ids[:, 1], p_lines, params, None, wrong("parameter", param_tag, prior), problems)
    fixed_ids = np.array(fix_ids, dtype=np.int64)
    unknown = np.flatnonzero(~np.isin(fixed_ids, poses.ids))
    if unknown.size:
        v = fixed_ids[unknown[0]]
        reason = (f"FIX names landmark {v}: only poses can be fixed" if np.isin(v, landmarks.ids) else
                  f"FIX names vertex {v}, not defined")  # fmt: skip
        problems.append((fix_lines[int(unknown[0])], reason))
    if problems:
        lineno, reason = min(problems)
        raise ParseError(reason, filename, lineno)

    # ---- the graph ----
    pose_ids = poses.ids
    estimates = None
    if len(v_ids):
        v_vals = np.concatenate(tags[pose_tag].take_values())
        estimates = elements(group, v_vals[np.argsort(v_ids[:, 0], kind="stable")])
        del v_vals
    _, first_fix = np.unique(fixed_ids, return_index=True)
    measurements, information = _edges(group, tags[TAG[group, EDGE]])
    graph = PoseGraph(
        group=group,
        edges=np.searchsorted(pose_ids, e_ids),
        measurements=measurements,
        information=information,
        ids=pose_ids,
        poses=estimates,
        fixed=np.searchsorted(pose_ids, fixed_ids[np.sort(first_fix)]),
        name=name,
        edge_lines=e_lines,
    )
    if not landmark_file:
        return graph
    return _landmark_graph(graph, tags, landmarks.ids, params, filename, name)


def _landmark_graph(
    graph: PoseGraph, tags: dict[str, Tag], landmark_ids: IntArray, params: _Defined | None, filename: str, name: str
) -> LandmarkGraph:
    """The poses of ``graph`` with the file's landmarks, observations and priors."""
    group, d, dim = graph.group, graph.d, graph.group.dim
    l_ids, _ = tags[TAG[group, LANDMARK]].ids_and_lines()
    o_ids, o_lines = tags[TAG[group, OBSERVATION]].ids_and_lines()
    p_ids, p_lines = tags[TAG[group, PRIOR]].ids_and_lines()
    landmarks = None
    if len(l_ids):
        landmarks = np.concatenate(tags[TAG[group, LANDMARK]].take_values())[np.argsort(l_ids[:, 0], kind="stable")]
    o_vals = np.concatenate(tags[TAG[group, OBSERVATION]].take_values())
    p_vals = np.concatenate(tags[TAG[group, PRIOR]].take_values())
    means = elements(group, p_vals) if len(p_vals) else None
    prior_information = symmetric(p_vals[:, RECORDS[TAG[group, PRIOR]].pose :], dim)
    offsets = offset_ids = None
    if params is not None:  # 3-D: the offsets of the observations and the priors
        s_ids, _ = tags[TAG[SE3, PARAM]].ids_and_lines()
        s_vals = np.concatenate(tags[TAG[SE3, PARAM]].take_values())
        table = elements(SE3, s_vals[np.argsort(s_ids[:, 0], kind="stable")])
        offset_ids = o_ids[:, 2]
        used = np.searchsorted(params.ids, offset_ids)
        offsets = None if is_identity(table)[used].all() else table[used]
        if means is not None:
            means, prior_information = _fold(means, prior_information, table[np.searchsorted(params.ids, p_ids[:, 1])],
                                             p_lines, filename)  # fmt: skip
    return LandmarkGraph(
        graph,
        landmark_ids=landmark_ids,
        observations=np.stack([np.searchsorted(graph.ids, o_ids[:, 0]), np.searchsorted(landmark_ids, o_ids[:, 1])], 1),
        points=o_vals[:, :d],
        point_information=symmetric(o_vals[:, d:], d),
        landmarks=landmarks,
        sensor_offsets=offsets,
        offset_ids=offset_ids,
        prior_poses=np.searchsorted(graph.ids, p_ids[:, 0]),
        prior_means=means,
        prior_information=prior_information,
        name=name,
        observation_lines=o_lines,
        prior_lines=p_lines,
    )


def _fold(
    means: LieGroup, information: FloatArray, offsets: LieGroup, lines: IntArray, filename: str
) -> tuple[LieGroup, FloatArray]:
    """EDGE_SE3_PRIOR's ``X S ≈ Z`` as a prior on ``X``: ``Log(Z⁻¹ X S) = Ad_{S⁻¹} Log((Z S⁻¹)⁻¹ X)``, so
    the mean ``Z S⁻¹`` and the information ``Ad_{S⁻¹}ᵀ Ω Ad_{S⁻¹}`` give the same cost (identity
    offsets are left alone, bit for bit)."""
    moved = np.flatnonzero(~is_identity(offsets))
    if not moved.size:
        return means, information
    inverse = offsets[moved].inverse()
    with np.errstate(all="ignore"):
        folded = means[moved] @ inverse
        ad = inverse.adjoint()
        info = np.swapaxes(ad, 1, 2) @ information[moved] @ ad
        info = 0.5 * (info + np.swapaxes(info, 1, 2))  # symmetric to the bit, as the file will hold it
    finite = np.isfinite(folded.as_matrix()).all(axis=(1, 2)) & np.isfinite(info).all(axis=(1, 2))
    if not finite.all():
        row = int(moved[np.flatnonzero(~finite)[0]])
        raise ParseError("the prior moved by its parameter's offset is not finite", filename, int(lines[row]))
    pick = np.arange(len(information))
    pick[moved] = len(information) + np.arange(moved.size)
    information = information.copy()
    information[moved] = info
    return type(means).concatenate([means, folded])[pick], information


def is_identity(x: LieGroup) -> np.ndarray:
    """Which elements of a batch ``(r,)`` are exactly the identity."""
    m = x.as_matrix()
    return np.asarray((m == np.eye(m.shape[-1])).all(axis=(-2, -1)))


def symmetric(upper: FloatArray, k: int) -> FloatArray:
    """``(r, k, k)`` symmetric matrices from their upper triangles, row by row ``(r, k(k+1)/2)``."""
    out = np.empty((len(upper), k, k))
    rows, cols = np.triu_indices(k)
    out[:, rows, cols] = upper
    out[:, cols, rows] = upper
    return out


def _edges(group: type[LieGroup], tag: Tag) -> tuple[LieGroup, FloatArray]:
    """The measurements and information matrices, built chunk by chunk (each chunk's
    numbers are dropped once used, so the numbers and the result never coexist whole)."""
    chunks = tag.take_values()
    m, k, p = sum(len(c) for c in chunks), group.dim, tag.record.pose
    upper = np.triu_indices(k)
    information = np.empty((m, k, k))
    parts = []
    at = 0
    while chunks:
        vals = chunks.pop(0)
        block = information[at : at + len(vals)]
        block[:, upper[0], upper[1]] = vals[:, p:]
        block[:, upper[1], upper[0]] = vals[:, p:]
        parts.append(elements(group, vals))
        at += len(vals)
        del vals
    measurements = parts[0] if len(parts) == 1 else group.concatenate(parts)
    return measurements, information


def elements(group: type[LieGroup], vals: FloatArray) -> LieGroup:
    """Group elements from the pose fields ``x y θ`` or ``x y z qx qy qz qw`` (leading columns of ``vals``)."""
    if group is SE2:
        return SE2.from_rotation_translation(SO2.from_angle(vals[:, 2]), vals[:, :2])
    # The norm was checked against quaternion_tol already.
    return SE3.from_translation_quaternion(vals[:, :3], vals[:, 3:7], normalize=True)
