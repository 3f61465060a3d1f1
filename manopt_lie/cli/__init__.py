"""The ``manopt-lie`` command line (also ``python -m manopt_lie``): the top floor.

- ``manopt-lie demo``: a synthetic 3-D pose graph and a rotation-averaging instance,
  each solved by every optimizer (:mod:`.bench`).
- ``manopt-lie solve FILE.g2o``: solve one file, write the result as g2o (:mod:`.solve`).
- ``manopt-lie bench``: a suite of catalogue instances × optimizers, optional peers and
  the IPOPT reference (:mod:`.bench`).

Bad arguments and bad input files end with a one-line ``manopt-lie <command>: error: …``
on stderr and exit code 2.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

from . import _common, bench, solve

__all__ = ["build_parser", "main"]


def build_parser() -> _common.Parser:
    from .. import __version__

    parser = _common.Parser(
        prog="manopt-lie",
        description="Optimization on manifolds and Lie groups: pose graphs, rotation averaging and optimizer "
        "benchmarks.",
    )
    parser.add_argument("--version", action="version", version=f"manopt-lie {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="{demo,solve,bench}",
                                     parser_class=_common.Parser)  # fmt: skip
    bench.add_parsers(commands)
    solve.add_parser(commands)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; return the exit code (0, or 2 for bad arguments or input)."""
    args = build_parser().parse_args(argv)
    try:
        args.run(args)
    except (ValueError, OSError, ImportError) as error:  # bad input: files, arguments, missing extras
        message = " ".join(str(error).split())
        print(f"manopt-lie {args.command}: error: {message}", file=sys.stderr)
        return _common.EXIT_USAGE
    return 0
