"""Writing landmark graphs: parameters, pose and landmark vertices, edges, observations, priors.

The text is a fixed point of write ∘ read like a pose graph's (:mod:`._writer`). What g2o
has no field for is written in an equivalent form:

- 2-D sensor offsets (``EDGE_SE2_XY`` has none) are folded into the points: with
  ``S = (R_S, t_S)``, ``z' = S·z = R_S z + t_S`` and ``Ω' = R_S Ω R_Sᵀ`` give the same cost,
  since ``z − (X S)⁻¹ l = R_Sᵀ (z' − X⁻¹ l)`` (and ``offset_ids``, which 2-D files have no
  field for, are dropped);
- 3-D sensor offsets become ``PARAMS_SE3OFFSET`` lines: one per ``graph.offset_ids`` (the
  file's parameter ids, checked to name one offset each) or, without them, one per distinct
  offset; priors name a parameter holding the identity (one of those, or a new one).
"""

from __future__ import annotations

import io
from typing import Any

import numpy as np

from manopt_lie import SE3
from manopt_lie.errors import ShapeError
from manopt_lie.lie.base import LieGroup

from ..landmarks import LandmarkGraph
from ._assemble import is_identity
from ._format import check_finite, edge_lines, fix_line, lines, pose_fields, upper, vertex_lines
from ._records import LANDMARK, OBSERVATION, PARAM, PRIOR, TAG, FloatArray, IntArray

__all__ = ["landmark_text"]


def landmark_text(graph: LandmarkGraph, estimates: Any = None) -> str:
    """The g2o text of a landmark graph with ``estimates`` (:func:`~._writer.write`)."""
    name, group = graph.name, graph.group
    poses, landmarks = _estimates(graph, estimates)
    pose_ids: IntArray = graph.poses.ids
    landmark_ids: IntArray = graph.landmark_ids
    obs = graph.observations
    out = io.StringIO()
    obs_params = prior_param = None
    if group is SE3:
        obs_params, prior_param, table_ids, table = _parameters(graph)
        check_finite(table, f"{name}: non-finite sensor offsets of parameter ids", table_ids)
        lines(out, TAG[SE3, PARAM], table_ids[:, None], table)
    if poses is not None:
        vertex_lines(out, graph.poses, poses, "estimates['poses']")
    else:
        named = np.concatenate([graph.poses.edges.ravel(), obs[:, 0], graph.prior_poses])
        lonely = np.setdiff1d(np.arange(graph.n), named)
        if lonely.size:
            raise ValueError(f"{name}: poses {pose_ids[lonely[:10]].tolist()} have no measurement and no estimate; "
                             "g2o needs estimates to write them")  # fmt: skip
    if landmarks is not None:
        check_finite(landmarks, f"{name}: non-finite landmarks at vertex ids", landmark_ids)
        order = np.argsort(landmark_ids, kind="stable")
        lines(out, TAG[group, LANDMARK], landmark_ids[order, None], landmarks[order])
    else:
        unseen = np.setdiff1d(np.arange(graph.n_landmarks), obs[:, 1])
        if unseen.size:
            raise ValueError(f"{name}: landmarks {landmark_ids[unseen[:10]].tolist()} have no observation and no "
                             "estimate; g2o needs estimates to write them")  # fmt: skip
    fix_line(out, graph.poses)
    edge_lines(out, graph.poses)

    points, information = _points(graph)
    ids = np.stack([pose_ids[obs[:, 0]], landmark_ids[obs[:, 1]]], axis=1)
    vals = np.concatenate([points, upper(information)], axis=1)
    check_finite(vals, f"{name}: non-finite observations of (pose, landmark) ids", ids)
    if obs_params is not None:
        ids = np.concatenate([ids, obs_params[:, None]], axis=1)
    lines(out, TAG[group, OBSERVATION], ids, vals)

    p = len(graph.prior_poses)
    if p:
        prior_ids = pose_ids[graph.prior_poses][:, None]
        assert graph.prior_means is not None and graph.prior_information is not None  # LandmarkGraph checks
        vals = np.concatenate([pose_fields(graph.prior_means), upper(graph.prior_information)], axis=1)
        check_finite(vals, f"{name}: non-finite priors on pose ids", prior_ids[:, 0])
        if prior_param is not None:
            prior_ids = np.concatenate([prior_ids, np.full((p, 1), prior_param)], axis=1)
        lines(out, TAG[group, PRIOR], prior_ids, vals)
    return out.getvalue()


def _estimates(graph: LandmarkGraph, estimates: Any) -> tuple[LieGroup | None, FloatArray | None]:
    """The poses and landmarks to write: ``estimates`` (checked) or the graph's own."""
    if estimates is None:
        return graph.poses.poses, graph.landmarks
    try:
        poses, landmarks = estimates["poses"], estimates["landmarks"]
    except (KeyError, TypeError, IndexError):
        raise TypeError(
            f"{graph.name}: estimates of a landmark graph must be Values (poses, landmarks), "
            f"got {type(estimates).__name__}"
        ) from None
    landmarks = np.asarray(landmarks, dtype=np.float64)
    if landmarks.shape != (graph.n_landmarks, graph.d):
        raise ShapeError(f"{graph.name}: estimates['landmarks'] must have shape ({graph.n_landmarks}, {graph.d}), "
                         f"got {landmarks.shape}")  # fmt: skip
    return poses, landmarks


def _points(graph: LandmarkGraph) -> tuple[FloatArray, FloatArray]:
    """The points and their information as ``EDGE_SE2_XY`` / ``EDGE_SE3_TRACKXYZ`` take them:
    in 2-D with the sensor offsets folded in (module docstring)."""
    points, information = graph.points, graph.point_information
    offsets = graph.sensor_offsets
    if graph.group is SE3 or offsets is None:
        return points, information
    moved = np.flatnonzero(~is_identity(offsets))
    if not moved.size:
        return points, information
    m = offsets[moved].as_matrix()
    r, t = m[:, :2, :2], m[:, :2, 2]
    points, information = points.copy(), information.copy()
    with np.errstate(all="ignore"):  # huge values: check_finite names them
        points[moved] = np.einsum("kij,kj->ki", r, points[moved]) + t
        folded = r @ information[moved] @ np.swapaxes(r, 1, 2)
        information[moved] = 0.5 * (folded + np.swapaxes(folded, 1, 2))
    return points, information


def _parameters(graph: LandmarkGraph) -> tuple[IntArray, int | None, IntArray, FloatArray]:
    """3-D: the parameter id of each observation, that of the priors (``None`` without priors),
    and the table of parameters ``(ids (u,), fields x y z qx qy qz qw (u, 7))``."""
    k, name = len(graph.observations), graph.name
    identity = pose_fields(SE3.identity((1,)))
    offsets = graph.sensor_offsets
    fields = pose_fields(offsets) if offsets is not None and k else None
    if graph.offset_ids is not None:
        obs_params = graph.offset_ids
        table_ids, first, inverse = np.unique(obs_params, return_index=True, return_inverse=True)
        if fields is None:
            table = np.repeat(identity, len(table_ids), axis=0)
        else:
            table = fields[first]
            differ = np.flatnonzero((fields != table[inverse]).any(axis=1))
            if differ.size:
                row = int(differ[0])
                raise ValueError(
                    f"{name}: observation {graph.observation_names([row])[0]} has offset_id {obs_params[row]} with "
                    f"another sensor offset than observation {graph.observation_names([first[inverse[row]]])[0]}"
                )
    elif fields is None:
        obs_params = np.zeros(k, dtype=np.int64)
        table_ids, table = np.zeros(min(k, 1), dtype=np.int64), np.repeat(identity, min(k, 1), axis=0)
    else:
        table, inverse = np.unique(fields, axis=0, return_inverse=True)
        obs_params, table_ids = inverse.reshape(-1).astype(np.int64), np.arange(len(table), dtype=np.int64)
    prior_param = None
    if len(graph.prior_poses):
        same = np.flatnonzero((table == identity).all(axis=1))
        if same.size:
            prior_param = int(table_ids[same[0]])
        else:
            prior_param = int(np.setdiff1d(np.arange(len(table_ids) + 1), table_ids)[0])
            order = np.searchsorted(table_ids, prior_param)
            table_ids = np.insert(table_ids, order, prior_param)
            table = np.insert(table, order, identity[0], axis=0)
    return obs_params.astype(np.int64), prior_param, table_ids.astype(np.int64), table
