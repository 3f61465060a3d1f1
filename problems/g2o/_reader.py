"""Reading g2o files: chunks of lines → arrays per tag (the format: the package docstring).

The lines come in chunks (:mod:`._source`). A chunk is checked and converted in bulk: one
pass over its lines sorts the fields by tag (plain Python, the only per-line work), then
one NumPy conversion per tag turns them into ids and numbers, which are checked with
array operations (finite, no self-loops, unit quaternions). Only when something is wrong
is the chunk re-read line by line, to report the earliest bad line with the reason. So
reading stops at the first bad line, and memory stays near the size of the arrays kept
per tag (ids, numbers, line numbers). What needs the whole file — duplicate ids, edges,
observations, priors and ``FIX`` lines naming undefined vertices or parameters — is checked
at the end by :mod:`._assemble`, which builds the graph, again reporting the earliest
offending line.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from manopt_lie.lie.base import LieGroup

from ..landmarks import LandmarkGraph
from ..pose_graph import PoseGraph
from ._assemble import assemble
from ._records import DIMENSION_TAGS, RECORDS, FloatArray, IntArray, ParseError, Record, dims
from ._source import Chunks

__all__ = ["QUATERNION_TOL", "RENORMALIZED", "Stats", "Tag", "parse"]

QUATERNION_TOL = 1e-4
"""Default largest ``| ‖q‖ − 1 |`` accepted (and normalized away) by :func:`parse`.

Quaternions printed with ``d`` decimals carry rounding errors ``|δ_i| ≤ ½·10⁻ᵈ``, which move
the norm by ``|Σ q_i δ_i| ≤ ‖q‖₁·½·10⁻ᵈ < 10⁻ᵈ`` (``‖q‖₁ ≤ 2``, with equality only for
``|q_i| = ½``, which print exactly). So ``1e-4`` accepts every unit quaternion printed with
4 or more decimals, and leaves a margin of 50 over real files, whose quaternions were not
quite unit before printing either (SE-Sync's ``cubicle.g2o``, 6 decimals: up to 1.9e-6;
``sphere2500.g2o``: 7.8e-7). A wrong digit in the first four decimals, or a quaternion that
is no rotation at all, stays an error. Normalizing loses nothing the printing had not lost.
"""

RENORMALIZED = 1e-12
"""Quaternions whose norm is off by more than this are counted by :class:`Stats`
(``write`` puts out norms within an ulp or two of 1)."""


class Stats(NamedTuple):
    """What the reader saw that the graph does not keep (for :func:`lint` of a file)."""

    renormalized: int
    """Quaternions whose norm was off by more than :data:`RENORMALIZED` (normalized)."""
    quaternion_error: float
    """The largest ``| ‖q‖ − 1 |`` in the file (0 for 2-D files)."""


class Tag:
    """The lines of one tag: the fields of the current chunk (strings, flat), then the
    converted arrays of every chunk so far."""

    __slots__ = ("id_text", "ids", "linenos", "lines", "record", "split", "tag", "val_text", "vals", "width")

    def __init__(self, tag: str, record: Record) -> None:
        self.record, self.tag = record, tag
        self.width, self.split = record.fields + 1, record.ids + 1  # with the tag; ids end at split
        self.id_text: list[str] = []
        self.val_text: list[str] = []
        self.lines: list[int] = []
        self.ids: list[IntArray] = []
        self.vals: list[FloatArray] = []
        self.linenos: list[IntArray] = []

    def clear(self) -> None:
        self.id_text, self.val_text, self.lines = [], [], []

    def ids_and_lines(self) -> tuple[IntArray, IntArray]:
        """Ids ``(r, ids)`` and line numbers ``(r,)`` of every chunk."""
        if not self.ids:
            return np.zeros((0, self.record.ids), np.int64), np.zeros(0, np.int64)
        return np.concatenate(self.ids), np.concatenate(self.linenos)

    def take_values(self) -> list[FloatArray]:
        """The numbers ``(r, pose + info)`` of each chunk (at least one), handed over: the tag drops them."""
        r = self.record
        chunks, self.vals = self.vals or [np.zeros((0, r.pose + r.info))], []
        return chunks


def quaternion_norms(q: FloatArray) -> FloatArray:
    """``‖q‖`` of ``(r, 4)`` rows without overflow or underflow (huge entries give huge norms)."""
    return np.hypot(np.hypot(q[:, 0], q[:, 1]), np.hypot(q[:, 2], q[:, 3]))


class _Parser:
    """The state of one read: the file's dimension, each tag's arrays, the ``FIX`` ids."""

    def __init__(self, filename: str, quaternion_tol: float) -> None:
        self.filename, self.quaternion_tol = filename, quaternion_tol
        self.group: type[LieGroup] | None = None
        self.first = (0, "")  # line and tag of the first record, for the 2-D/3-D message
        self.tags: dict[str, Tag] = {}  # every tag of the file's dimension, once known
        self.fix_ids: list[int] = []
        self.fix_lines: list[int] = []
        self.renormalized, self.quaternion_error = 0, 0.0

    def error(self, reason: str, lineno: int | None) -> ParseError:
        return ParseError(reason, self.filename, lineno)

    # ---- one chunk -------------------------------------------------------------------

    def feed(self, start: int, lines: list[str]) -> None:
        """Take the chunk ``lines`` (numbered from ``start``), or raise at its earliest bad line."""
        state = (self.group, self.first)
        tags = self.tags
        for offset, line in enumerate(lines):
            if "#" in line:
                line = line[: line.index("#")]
            parts = line.split()
            if not parts:
                continue
            slot = tags.get(parts[0])
            if slot is not None and len(parts) == slot.width:
                slot.id_text += parts[1 : slot.split]
                slot.val_text += parts[slot.split :]
                slot.lines.append(start + offset)
                continue
            try:
                self._record(parts, start + offset, keep=True)
            except ParseError:
                self._recheck(start, lines[:offset], state)  # an earlier line may be worse
                raise
            tags = self.tags
        for slot in tags.values():
            if slot.lines and not self._convert(slot):
                self._recheck(start, lines, state)
                raise AssertionError("the line-by-line check accepted what the bulk check refused")  # pragma: no cover
        for slot in tags.values():
            slot.clear()

    def _record(self, parts: list[str], lineno: int, *, keep: bool) -> Record | None:
        """Check a line's tag and field count (``FIX``: its ids); the first record fixes the
        dimension. With ``keep``, a record's fields go to its tag, ``FIX`` ids are kept."""
        tag = parts[0]
        record = RECORDS.get(tag)
        if record is None:
            if tag != "FIX":
                raise self.error(f"unknown tag {tag!r} (supported: {', '.join(RECORDS)}, FIX)", lineno)
            if len(parts) == 1:
                raise self.error("FIX needs at least 1 vertex id", lineno)
            for text in parts[1:]:  # FIX lines are few: plain Python
                try:
                    np.int64(int(text))  # out of range: OverflowError
                except (ValueError, OverflowError):
                    raise self.error(f"FIX field {text!r} is not an integer id", lineno) from None
            if keep:
                self.fix_ids += map(int, parts[1:])
                self.fix_lines += [lineno] * (len(parts) - 1)
            return None
        if len(parts) - 1 != record.fields:
            raise self.error(f"{tag} needs {record.fields} fields, got {len(parts) - 1}", lineno)
        if self.group is None:
            self.group, self.first = record.group, (lineno, tag)
            if keep:
                self.tags = {t: Tag(t, RECORDS[t]) for t in DIMENSION_TAGS[record.group]}
        elif record.group is not self.group:
            first_line, first_tag = self.first
            reason = f"{tag} in a file of {dims(self.group)} records (line {first_line} is {first_tag})"
            raise self.error(reason, lineno)
        if keep:
            slot = self.tags[tag]
            slot.id_text += parts[1 : slot.split]
            slot.val_text += parts[slot.split :]
            slot.lines.append(lineno)
        return record

    def _convert(self, slot: Tag) -> bool:
        """Convert the chunk's fields of a tag (one NumPy call for the ids, one for the numbers)
        and check them; ``False`` if anything is wrong (the caller finds the line)."""
        record = slot.record
        try:
            ids = np.array(slot.id_text, dtype=np.int64).reshape(-1, record.ids)
            vals = np.array(slot.val_text, dtype=np.float64).reshape(len(ids), -1)
        except (ValueError, OverflowError):
            return False
        if not np.isfinite(vals).all() or (record.is_edge and (ids[:, 0] == ids[:, 1]).any()):
            return False
        if record.quaternion:
            deviation = np.abs(quaternion_norms(vals[:, 3:7]) - 1.0)
            if not (deviation <= self.quaternion_tol).all():
                return False
            self.renormalized += int(np.count_nonzero(deviation > RENORMALIZED))
            self.quaternion_error = max(self.quaternion_error, float(deviation.max()))
        slot.ids.append(ids)
        slot.vals.append(vals)
        slot.linenos.append(np.array(slot.lines, dtype=np.int64))
        return True

    def _recheck(self, start: int, lines: list[str], state: tuple[type[LieGroup] | None, tuple[int, str]]) -> None:
        """Check ``lines`` one by one from the chunk's starting ``state``; raise at the first bad one."""
        saved = (self.group, self.first)
        self.group, self.first = state
        try:
            for offset, line in enumerate(lines):
                parts = line.partition("#")[0].split()
                if parts:
                    record = self._record(parts, start + offset, keep=False)
                    if record is not None:
                        self._values(parts[0], record, parts[1:], start + offset)
        finally:
            self.group, self.first = saved

    def _values(self, tag: str, record: Record, fields: list[str], lineno: int) -> None:
        """Check the fields of one record; raise naming the first bad one."""
        vals: list[float] = []  # ids included
        for col, text in enumerate(fields):
            try:
                value = np.array(text, dtype=np.int64 if col < record.ids else np.float64)
            except OverflowError:
                raise self.error(f"{tag} field {col + 1} is {text!r}, out of the 64-bit id range", lineno) from None
            except ValueError:
                what = "an integer id" if col < record.ids else "a number"
                raise self.error(f"{tag} field {col + 1} is {text!r}, not {what}", lineno) from None
            if not np.isfinite(value):
                raise self.error(f"{tag} field {col + 1} is {text!r}, not a finite number", lineno)
            vals.append(value.item())
        if record.is_edge and vals[0] == vals[1]:
            raise self.error(f"self-loop edge {vals[0]} → {vals[1]}", lineno)
        if record.quaternion:
            norm = float(quaternion_norms(np.array([vals[record.ids + 3 : record.ids + 7]]))[0])
            if not abs(norm - 1.0) <= self.quaternion_tol:
                tol = self.quaternion_tol
                reason = f"{record.noun} quaternion norm {norm!r} is not 1 within quaternion_tol={tol:g}"
                raise self.error(reason, lineno)


def parse(chunks: Chunks, filename: str, name: str, quaternion_tol: float) -> tuple[PoseGraph | LandmarkGraph, Stats]:
    """The graph of a g2o source given as chunks of lines, and what :func:`lint` wants to know."""
    if not 0.0 <= quaternion_tol < 1.0:  # below 1, accepted norms are in (0, 2): normalizing is safe
        raise ValueError(f"quaternion_tol must be in [0, 1), got {quaternion_tol!r}")
    parser = _Parser(filename, quaternion_tol)
    try:
        for start, lines in chunks:
            parser.feed(start, lines)
    finally:
        close = getattr(chunks, "close", None)
        if close is not None:
            close()  # a bad line stops the reading: the file is closed now, not when the error is
    if parser.group is None:
        raise parser.error("no VERTEX or EDGE lines", None)
    graph = assemble(parser.tags, parser.group, parser.fix_ids, parser.fix_lines, parser.filename, name)
    return graph, Stats(parser.renormalized, parser.quaternion_error)
