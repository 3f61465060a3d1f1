"""What every ``manopt-lie`` command shares: the argument parser's manners, the stopping-rule
flags (generated from :class:`~manopt_lie.optim.StoppingCriteria`, whose fields are defined
once), the progress display and file writing."""

from __future__ import annotations

import argparse
import dataclasses
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NoReturn

from manopt_lie.optim import StoppingCriteria

EXIT_USAGE = 2


class UsageError(ValueError):
    """A bad argument or input file: reported in one line, exit code 2."""


class Parser(argparse.ArgumentParser):
    """Usage errors in one line with exit code 2."""

    def error(self, message: str) -> NoReturn:
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
        group.add_argument(
            "--" + f.name.replace("_", "-"), dest=f.name, type=number(kind, positive=f.name in _POSITIVE),
            default=default, metavar="N" if kind is int else "X", help=f"{f.metadata['help']} (default: %(default)s)",
        )  # fmt: skip


def stopping(args: argparse.Namespace) -> StoppingCriteria:
    """The :class:`StoppingCriteria` given by the flags of :func:`add_stopping`."""
    return StoppingCriteria(**{f.name: getattr(args, f.name) for f in dataclasses.fields(StoppingCriteria)})


def add_output(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true", help="print one JSON document instead of the table")
    parser.add_argument("--quiet", action="store_true", help="no progress display")


def progress(quiet: bool) -> Any:
    """A rich progress display on stderr, or ``None`` when quiet or not a terminal."""
    if quiet or not sys.stderr.isatty():
        return None
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    return Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                    console=Console(stderr=True), transient=True)  # fmt: skip


def write_text(path: Path, text: str) -> None:
    """Write ``text`` to ``path``, creating its directory."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
