"""What ``verbosity=1`` and ``2`` print: pymanopt's habit, as plain text on stderr.

* ``verbosity=1``: one line when the run starts (the optimizer, the problem, the
  gradient tolerance and the iteration cap) and the result when it ends;
* ``verbosity=2``: also one row per iteration, the initial point being row 0::

      iter              cost      |grad|        step      time
         0   1.000000000e+01   2.000e+00           -    0.000s
         1   3.141592654e+00   1.234e-01   4.567e-01    0.002s

A rejected step (trust region, Levenberg-Marquardt) shows ``-`` as its step.
Lines are written to ``sys.stderr`` as it is at the time of writing (so test
harnesses that capture it see them) and flushed at once. Nothing here touches the
``logging`` output, which is independent.
"""

from __future__ import annotations

import math
import sys
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .optimizer import StoppingCriteria
    from .problem import Problem
    from .result import OptimizeResult

__all__ = ["Progress", "check_verbosity"]

VERBOSITIES = (0, 1, 2)
_HEADER = f"{'iter':>6}  {'cost':>16}  {'|grad|':>10}  {'step':>10}  {'time':>8}"


def check_verbosity(verbosity: Any, owner: str) -> int:
    """``verbosity`` as an int in :data:`VERBOSITIES`.

    Raises
    ------
    ValueError
        Naming the owner and the accepted values.
    """
    if isinstance(verbosity, bool) or verbosity not in VERBOSITIES:
        raise ValueError(f"{owner}: verbosity must be 0, 1 or 2, got {verbosity!r}")
    return int(verbosity)


def _number(value: float, fmt: str, width: int) -> str:
    return f"{value:{width}{fmt}}" if math.isfinite(value) else f"{'-' if math.isnan(value) else value:>{width}}"


class Progress:
    """The start line, the per-iteration rows (``verbosity=2``) and the end line of one run."""

    def __init__(self, name: str, verbosity: int) -> None:
        self.name, self.verbosity = name, verbosity

    @staticmethod
    def _write(line: str) -> None:
        stream = sys.stderr
        stream.write(line + "\n")
        stream.flush()

    def start(self, problem: Problem, stopping: StoppingCriteria, grad_tol: float) -> None:
        """``Optimizing Problem(Sphere(3), egrad) with TrustRegion: |grad| ≤ 1.0e-06, ≤ 1000 iterations``."""
        self._write(
            f"Optimizing {problem!r} with {self.name}: |grad| <= {grad_tol:.1e}, "
            f"at most {stopping.max_iterations} iterations"
        )
        if self.verbosity >= 2:
            self._write(_HEADER)

    def row(self, iteration: int, f: float, grad_norm: float, step: float, time: float) -> None:
        if self.verbosity >= 2:
            self._write(
                f"{iteration:>6}  {_number(f, '.9e', 16)}  {_number(grad_norm, '.3e', 10)}  "
                f"{_number(step, '.3e', 10)}  {time:>7.3f}s"
            )

    def end(self, result: OptimizeResult) -> None:
        self._write(f"{self.name}: {result}")
