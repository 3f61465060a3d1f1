"""What every ``manopt-lie`` command shares: the argument parser's manners, the exit codes,
the stopping-rule flags (generated from :class:`~manopt_lie.optim.StoppingCriteria`, whose
fields are defined once), the progress display, JSON and file writing."""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NoReturn

from manopt_lie.atomic import atomic_write, check_writable
from manopt_lie.bench.figures import figure_format
from manopt_lie.bench.report import json_safe, json_text  # noqa: F401  (re-exported for the commands)
from manopt_lie.optim import StoppingCriteria

EXIT_OK = 0
EXIT_NOT_CONVERGED = 1
EXIT_USAGE = 2
EXIT_INTERRUPTED = 130
EXIT_BROKEN_PIPE = 141

EXIT_CODES = f"""exit codes:
  {EXIT_OK}    success: solve converged; bench and demo ran every run; eval computed the errors
  {EXIT_NOT_CONVERGED}    solve ran but did not converge, or a run failed
  {EXIT_USAGE}    bad arguments or input (one line on stderr, or a JSON error with --json)
  {EXIT_INTERRUPTED}  interrupted (Ctrl-C): nothing is written (bench --store keeps the runs it finished)
  {EXIT_BROKEN_PIPE}  the reader of the output went away (as for any Unix tool killed by SIGPIPE)"""


class UsageError(ValueError):
    """A bad argument or input file: reported in one line, exit code 2."""


class Parser(argparse.ArgumentParser):
    """Usage errors in one line with exit code 2 (a JSON error on stdout when ``--json`` is
    among the arguments); the exit codes in every ``--help``."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("epilog", EXIT_CODES)
        kwargs.setdefault("formatter_class", argparse.RawDescriptionHelpFormatter)
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> NoReturn:
        if "--json" in sys.argv[1:]:
            print_json({"error": f"{message}", "exit_code": EXIT_USAGE})
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message} (see --help)\n")


def csv(choices: Sequence[str]) -> Any:
    """An argument type: a comma-separated, non-empty list of ``choices``."""

    def parse(text: str) -> list[str]:
        names = [t.strip() for t in text.split(",") if t.strip()]
        if bad := [n for n in names if n not in choices]:
            raise argparse.ArgumentTypeError(f"unknown {', '.join(bad)}; choose from {','.join(choices)}")
        if not names:
            raise argparse.ArgumentTypeError("empty list")
        return names

    return parse


def number(kind: type, *, positive: bool) -> Any:
    """An argument type: an ``int`` or ``float``, positive or non-negative."""

    def parse(text: str) -> Any:
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
        if not (value > 0 if positive else value >= 0):
            raise argparse.ArgumentTypeError(f"must be {'positive' if positive else 'non-negative'}, got {text}")
        return value

    return parse


_POSITIVE = {"max_iterations", "max_time"}


def add_stopping(parser: argparse.ArgumentParser, **defaults: Any) -> None:
    """One flag per field of :class:`StoppingCriteria` (``--max-iterations``, ``--grad-rtol``, …),
    its help text from the field's metadata; ``defaults`` overrides the dataclass's."""
    group = parser.add_argument_group("stopping rule (shared by every optimizer; the first test that holds wins)")
    for f in dataclasses.fields(StoppingCriteria):
        default = defaults.get(f.name, f.default)
        kind = int if isinstance(f.default, int) else float
        shown = "set by the optimizer" if default is None else "%(default)s"
        group.add_argument(
            "--" + f.name.replace("_", "-"), dest=f.name, type=number(kind, positive=f.name in _POSITIVE),
            default=default, metavar="N" if kind is int else "X", help=f"{f.metadata['help']} (default: {shown})",
        )  # fmt: skip


def stopping(args: argparse.Namespace) -> StoppingCriteria:
    """The :class:`StoppingCriteria` given by the flags of :func:`add_stopping`."""
    return StoppingCriteria(**{f.name: getattr(args, f.name) for f in dataclasses.fields(StoppingCriteria)})


def add_output(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true", help="print one JSON document instead of the table")
    parser.add_argument("--quiet", action="store_true", help="no progress display")


def progress(quiet: bool) -> Any:
    """A rich progress display on stderr, or ``None`` when quiet or not a terminal (then
    :class:`Lines` says what happens)."""
    if quiet or not sys.stderr.isatty():
        return None
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    return Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                    console=Console(stderr=True), transient=True)  # fmt: skip


class Lines:
    """Progress as plain lines on stderr, for logs (stderr not a terminal): one line per
    finished run, but at most one every ``interval`` seconds (the count says how far it got),
    and always the last one and every failed one; ``preamble`` comes with the first::

        manopt-lie bench: 12 runs of 3 instances in this process
        manopt-lie bench: [1/12] cube-8 · chordal · gn: cost 400.6794 in 0.046 s (gradient norm)
    """

    def __init__(self, command: str, total: int, *, interval: float = 1.0, stream: Any = None,
                 preamble: str | None = None) -> None:  # fmt: skip
        self.command, self.total, self.interval = command, total, interval
        self.stream = stream if stream is not None else sys.stderr
        self.preamble = preamble  # said with the first finished run: a usage error stays one line
        self.done = 0
        self.last = -math.inf

    def say(self, text: str) -> None:
        print(f"manopt-lie {self.command}: {text}", file=self.stream, flush=True)
        self.last = time.monotonic()

    def finished(self, label: str, text: str, *, important: bool = False) -> None:
        """One more run finished."""
        self.done += 1
        if self.preamble is not None:
            self.say(self.preamble)
            self.preamble = None
        now = time.monotonic()
        if important or self.done == self.total or now - self.last >= self.interval:
            self.say(f"[{self.done}/{self.total}] {label}: {text}")


def seeds(text: str) -> list[int]:
    """An argument type: seeds as ``0-9``, ``0,3,7`` or a mix (``0-4,10``)."""
    out: list[int] = []
    for part in (p.strip() for p in text.split(",")):
        lo, dash, hi = part.partition("-")
        try:
            first, last = int(lo), int(hi) if dash else int(lo)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not seeds: {text!r} (e.g. 0-9 or 0,3,7)") from None
        if first < 0 or last < first:
            raise argparse.ArgumentTypeError(f"not a range of non-negative seeds: {part!r}")
        out += [k for k in range(first, last + 1) if k not in out]
    return out


def figure_path(path: Path | None, what: str, *, inputs: Sequence[Path] = ()) -> Path | None:
    """:func:`output_path` for a figure, whose extension must name its format (``.png``,
    ``.pdf`` or ``.svg``): checked before any work."""
    if path is not None:
        if path.is_dir():
            raise UsageError(f"{what} {path} is a directory")
        try:
            figure_format(path)
        except ValueError as error:
            raise UsageError(f"{what}: {error}") from None
    return output_path(path, what, inputs=inputs)


def print_json(document: Any) -> None:
    print(json_text(document), flush=True)


def output_path(path: Path | None, what: str, *, inputs: Sequence[Path] = (), force: bool = False) -> Path | None:
    """Check an output path before any work: writable (:func:`~manopt_lie.atomic.check_writable`)
    and — unless ``force`` — not one of the ``inputs`` (the same file by any name)."""
    if path is None:
        return None
    for source in inputs:
        if path.exists() and source.exists() and os.path.samefile(path, source) and not force:
            raise UsageError(f"{what} {path} is the input file; pass --force to overwrite it")
    return check_writable(path, what)


def write_text(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically, creating its directory."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(path, newline="\n") as f:
        f.write(text)
