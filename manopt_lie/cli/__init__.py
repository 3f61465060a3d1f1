"""The ``manopt-lie`` command line (also ``python -m manopt_lie``): the top floor.

- ``manopt-lie demo``: a synthetic 3-D pose graph and a rotation-averaging instance,
  each solved by every optimizer (:mod:`.bench`).
- ``manopt-lie solve FILE.g2o``: solve one file, write the result as g2o (:mod:`.solve`).
- ``manopt-lie bench``: a suite of catalogue instances × optimizers, optional peers and
  the IPOPT reference (:mod:`.bench`).
- ``manopt-lie eval ape|rpe REF EST``: trajectory errors as evo computes them (:mod:`.eval`).

Exit codes (in every ``--help``): 0 success, 1 not converged (or a run failed), 2 bad
arguments or input — one line ``manopt-lie <command>: error: …`` on stderr, and with
``--json`` a JSON ``{"error": …}`` on stdout —, 130 interrupted (nothing written), 141
when the reader of the output went away.
"""

from __future__ import annotations

import errno
import os
import sys
from collections.abc import Sequence

from . import _common, bench, eval, solve

__all__ = ["build_parser", "main"]


def build_parser() -> _common.Parser:
    """The ``manopt-lie`` argument parser with its subcommands (demo, solve, bench, eval)."""
    from .. import __version__

    parser = _common.Parser(
        prog="manopt-lie",
        description="Optimization on manifolds and Lie groups: pose graphs, rotation averaging and optimizer "
        "benchmarks.",
    )
    parser.add_argument("--version", action="version", version=f"manopt-lie {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="{demo,solve,bench,eval}",
                                     parser_class=_common.Parser)  # fmt: skip
    bench.add_parsers(commands)
    solve.add_parser(commands)
    eval.add_parser(commands)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; return the exit code (see the module doc)."""
    try:
        args = build_parser().parse_args(argv)
    except KeyboardInterrupt:
        print("manopt-lie: interrupted", file=sys.stderr)
        return _common.EXIT_INTERRUPTED
    try:
        return int(args.run(args))
    except KeyboardInterrupt:
        print(f"manopt-lie {args.command}: interrupted", file=sys.stderr)
        return _common.EXIT_INTERRUPTED
    except BrokenPipeError:
        # The reader left (``| head``): say nothing, and keep Python from complaining at exit.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return _common.EXIT_BROKEN_PIPE
    except MemoryError:
        return _fail(args, "out of memory", _common.EXIT_NOT_CONVERGED)
    except OSError as error:
        # A file that could not be written whole (full disk, file-size limit) is a failure of the
        # run, not of its input; the atomic writes left the previous file in place.
        code = _common.EXIT_NOT_CONVERGED if error.errno in _WRITE_ERRORS else _common.EXIT_USAGE
        return _fail(args, " ".join(str(error).split()), code)
    except (ValueError, ImportError) as error:  # bad input: files, arguments, missing extras
        return _fail(args, " ".join(str(error).split()), _common.EXIT_USAGE)


_WRITE_ERRORS = {errno.EFBIG, errno.ENOSPC, errno.EDQUOT, errno.EIO}


def _fail(args: object, message: str, code: int) -> int:
    command = getattr(args, "command", "")
    print(f"manopt-lie {command}: error: {message}", file=sys.stderr)
    if getattr(args, "json", False):
        _common.print_json({"error": message, "exit_code": code})
    return code
