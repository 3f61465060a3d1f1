"""What the reader and the writer share: the layout of each g2o tag and :class:`ParseError`."""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from manopt_lie import SE2, SE3
from manopt_lie.lie.base import LieGroup

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


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
    """The layout of one tag: ``ids`` integer ids, ``pose`` numbers, ``info`` upper-triangle
    entries, ``fields`` their total (the tag excluded)."""

    group: type[LieGroup]
    ids: int
    pose: int
    info: int
    fields: int

    @property
    def is_edge(self) -> bool:
        return self.ids == 2


RECORDS = {
    "VERTEX_SE2": Record(SE2, 1, 3, 0, 4),
    "EDGE_SE2": Record(SE2, 2, 3, 6, 11),
    "VERTEX_SE3:QUAT": Record(SE3, 1, 7, 0, 8),
    "EDGE_SE3:QUAT": Record(SE3, 2, 7, 21, 30),
}
TAGS: dict[type[LieGroup], tuple[str, str]] = {
    SE2: ("VERTEX_SE2", "EDGE_SE2"),
    SE3: ("VERTEX_SE3:QUAT", "EDGE_SE3:QUAT"),
}


def dims(group: type[LieGroup]) -> str:
    """``"2-D"`` or ``"3-D"``, for messages."""
    return "2-D" if group is SE2 else "3-D"
