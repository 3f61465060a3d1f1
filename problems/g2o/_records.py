"""What the reader and the writer share: the layout of each g2o tag and :class:`ParseError`."""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from manopt_lie import SE2, SE3
from manopt_lie.lie.base import LieGroup

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

# What a record is (``Record.kind``).
POSE, EDGE, LANDMARK, OBSERVATION, PARAM, PRIOR = "pose", "edge", "landmark", "observation", "param", "prior"


class ParseError(ValueError):
    """A malformed g2o line, as ``"intel.g2o:123: EDGE_SE2 needs 11 fields, got 9"``.

    Attributes
    ----------
    filename : str
        The file (or the ``name`` given to :func:`loads`).
    lineno : int or None
        1-based line number; ``None`` for a problem with the file as a whole.
    reason : str
        The message without the location.
    """

    def __init__(self, reason: str, filename: str, lineno: int | None) -> None:
        self.reason = reason
        self.filename = filename
        self.lineno = lineno
        where = f"{filename}:{lineno}" if lineno is not None else filename
        super().__init__(f"{where}: {reason}")

    def __reduce__(self) -> tuple[Any, ...]:
        return (type(self), (self.reason, self.filename, self.lineno))


class Record(NamedTuple):
    """The layout of one tag: ``ids`` integer ids (vertex and parameter ids), ``pose``
    numbers (a pose, a point or an offset), ``info`` upper-triangle entries, ``fields``
    their total (the tag excluded); ``kind`` what the line is (:data:`POSE`, …)."""

    group: type[LieGroup]
    kind: str
    ids: int
    pose: int
    info: int
    fields: int

    @property
    def is_edge(self) -> bool:
        """A relative pose between two poses (self-loops are refused)."""
        return self.kind == EDGE

    @property
    def quaternion(self) -> bool:
        """Whether the numbers hold ``x y z qx qy qz qw`` (the quaternion checked and normalized)."""
        return self.pose == 7

    @property
    def noun(self) -> str:
        """What messages call the line's element (``"vertex quaternion norm …"``)."""
        return {POSE: "vertex", EDGE: "edge", PARAM: "parameter", PRIOR: "prior"}.get(self.kind, self.kind)


RECORDS = {
    "VERTEX_SE2": Record(SE2, POSE, 1, 3, 0, 4),
    "EDGE_SE2": Record(SE2, EDGE, 2, 3, 6, 11),
    "VERTEX_XY": Record(SE2, LANDMARK, 1, 2, 0, 3),
    "EDGE_SE2_XY": Record(SE2, OBSERVATION, 2, 2, 3, 7),
    "EDGE_PRIOR_SE2": Record(SE2, PRIOR, 1, 3, 6, 10),
    "VERTEX_SE3:QUAT": Record(SE3, POSE, 1, 7, 0, 8),
    "EDGE_SE3:QUAT": Record(SE3, EDGE, 2, 7, 21, 30),
    "VERTEX_TRACKXYZ": Record(SE3, LANDMARK, 1, 3, 0, 4),
    "EDGE_SE3_TRACKXYZ": Record(SE3, OBSERVATION, 3, 3, 6, 12),  # pose, landmark, parameter
    "PARAMS_SE3OFFSET": Record(SE3, PARAM, 1, 7, 0, 8),
    "EDGE_SE3_PRIOR": Record(SE3, PRIOR, 2, 7, 21, 30),  # pose, parameter
}
TAG: dict[tuple[type[LieGroup], str], str] = {(r.group, r.kind): tag for tag, r in RECORDS.items()}
"""The tag of each ``(group, kind)``."""
TAGS: dict[type[LieGroup], tuple[str, str]] = {g: (TAG[g, POSE], TAG[g, EDGE]) for g in (SE2, SE3)}
"""The pose vertex and edge tags of each group."""
DIMENSION_TAGS: dict[type[LieGroup], tuple[str, ...]] = {
    g: tuple(tag for tag, r in RECORDS.items() if r.group is g) for g in (SE2, SE3)
}


def dims(group: type[LieGroup]) -> str:
    """``"2-D"`` or ``"3-D"``, for messages."""
    return "2-D" if group is SE2 else "3-D"
