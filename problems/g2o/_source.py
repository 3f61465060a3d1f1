"""The lines of a g2o source, in chunks: paths, binary and text streams, strings.

A source is read in blocks of :data:`BLOCK` bytes (or characters), never whole, and cut
into chunks of complete lines, each numbered from 1 for the file. Whatever the source:

- a UTF-8 byte order mark at the start is dropped;
- ``\\n``, ``\\r\\n`` and ``\\r`` (old Mac) all end a line (Python's universal newlines);
- a line with a NUL character or, from bytes, bytes that are not UTF-8 is a
  :class:`ParseError` naming that line, raised as soon as its block is read (the lines
  before it are handed out first, so an earlier bad line is still reported first), so a
  binary file is rejected without reading the rest of it.
"""

from __future__ import annotations

import codecs
import os
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import IO

from ._records import ParseError

__all__ = ["BLOCK", "PathOrFile", "Chunks", "open_source", "string_chunks"]

PathOrFile = str | os.PathLike[str] | IO[str] | IO[bytes]
Chunks = Iterator[tuple[int, list[str]]]
"""``(number of the first line, lines)``, the lines without their ends."""

BLOCK = 1 << 20
"""Bytes (or characters) read at a time: a few thousand lines."""

_BINARY = "; is it a binary file?"


class _Bad(str):
    """A marker in a stream of text pieces: the line in progress here is not text (the reason)."""

    __slots__ = ()


def open_source(path_or_file: PathOrFile) -> tuple[str, str, Callable[[], Chunks]]:
    """The file name for messages, the default graph name and a function that reads the chunks
    (opening a path only when called, and closing it when the chunks end)."""
    if isinstance(path_or_file, str | os.PathLike):
        filename = os.fspath(path_or_file)

        def from_path() -> Chunks:
            with open(filename, "rb") as f:
                yield from _lines(_decoded(f.read, b""), filename)

        return filename, Path(filename).stem, from_path
    has_name = hasattr(path_or_file, "name")
    filename = str(getattr(path_or_file, "name", "<stream>"))
    default = Path(filename).stem if has_name else "g2o"

    def from_stream() -> Chunks:
        try:
            first = path_or_file.read(BLOCK)
        except UnicodeDecodeError as e:  # a text stream that cannot decode its first block
            first = _Bad(_undecodable(e))
        if isinstance(first, bytes):
            pieces = _decoded(path_or_file.read, first)  # type: ignore[arg-type]
        else:
            pieces = _text(path_or_file, first)  # type: ignore[arg-type]
        yield from _lines(pieces, filename)

    return filename, default, from_stream


def string_chunks(text: str, filename: str) -> Chunks:
    """The chunks of a string (:func:`loads`), cut in blocks without copying it whole."""
    return _lines((text[i : i + BLOCK] for i in range(0, len(text), BLOCK)), filename)


def _decoded(read: Callable[[int], bytes], first: bytes) -> Iterator[str]:
    """UTF-8 text pieces of a byte stream (``first``: bytes already read); at the first
    undecodable byte, the valid text before it and then a :class:`_Bad`."""
    offset = 0  # bytes decoded so far, for the message
    tail = b""  # an incomplete UTF-8 sequence at the end of the last block
    raw = first if first else read(BLOCK)
    while True:
        final = not raw
        data = tail + raw if tail else raw
        try:
            text, used = codecs.utf_8_decode(data, "strict", final)
        except UnicodeDecodeError as e:
            yield data[: e.start].decode("utf-8")
            yield _Bad(f"not UTF-8 text (byte 0x{data[e.start]:02x} at offset {offset + e.start}){_BINARY}")
            return
        yield text
        if final:
            return
        offset += used
        tail = data[used:]
        raw = read(BLOCK)


def _text(stream: IO[str], first: str) -> Iterator[str]:
    """The pieces of a text stream; a decoding error of the stream becomes a :class:`_Bad`
    (the stream decodes blocks, so the bad line is this one or one of the next few)."""
    piece = first
    while piece and not isinstance(piece, _Bad):
        yield piece
        try:
            piece = stream.read(BLOCK)
        except UnicodeDecodeError as e:
            piece = _Bad(_undecodable(e))
    if piece:
        yield piece


def _undecodable(e: UnicodeDecodeError) -> str:
    return f"the text stream cannot decode this line or one of the next ({e.reason}){_BINARY}"


def _lines(pieces: Iterator[str], filename: str) -> Chunks:
    """Chunks of complete lines from text pieces cut anywhere (see the module docstring)."""
    lineno = 1  # the number of the line in progress
    pending: list[str] = []  # the pieces of the line in progress
    skip_lf = False  # the last piece ended with "\r": a "\n" starting the next one is its "\r\n"
    start = True
    for piece in pieces:
        if isinstance(piece, _Bad):
            raise ParseError(str(piece), filename, lineno)
        if not piece:
            continue
        if start:
            start = False
            if piece.startswith("\ufeff"):
                piece = piece[1:]
        if skip_lf:
            skip_lf = False
            if piece.startswith("\n"):
                piece = piece[1:]
        nul = piece.find("\0")
        if nul >= 0:
            piece = piece[:nul]
        cut = max(piece.rfind("\n"), piece.rfind("\r")) + 1  # after the last line end
        if cut:
            skip_lf = cut == len(piece) and piece[-1] == "\r"
            text = "".join(pending) + piece[:cut] if pending else piece[:cut]
            pending = []
            if "\r" in text:
                text = text.replace("\r\n", "\n").replace("\r", "\n")
            lines = text.split("\n")
            lines.pop()  # the empty string after the last line end
            yield lineno, lines
            lineno += len(lines)
        if cut < len(piece):
            pending.append(piece[cut:])
        if nul >= 0:
            raise ParseError(f"a NUL character in the line{_BINARY}", filename, lineno)
    if pending:
        yield lineno, ["".join(pending)]
