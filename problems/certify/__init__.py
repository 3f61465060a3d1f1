"""Certifiably correct chordal pose-graph optimization and rotation averaging (SE-Sync; Shonan).

- :func:`certify` — the certificate of global optimality of *any* solution (ours, GTSAM's,
  g2o's…) of a graph's chordal cost: the smallest eigenvalue of ``S = Q − Λ(x)``, proven
  non-negative up to a margin by a sparse factorization, and the bound ``f(x) − f* ≤ gap``.
- :func:`staircase` — the Riemannian staircase from any initialization, random included:
  the rank-``p`` relaxation on ``St(p, d)ⁿ`` by the trust region with the exact Hessian,
  certificates, escapes from saddles, rounding, recovered translations.
- :func:`relaxation` — the reduced problem data, built once per graph and shared by both.

See ``docs/certifiable.md``.
"""

from .certificate import DEFAULT_TOL, EIG_FLOOR, Certificate, certify, certify_relaxation, rotations_of
from .data import Relaxation, relaxation
from .relaxed import escape_saddle, horizontal, preconditioner, relaxation_problem
from .rounding import lift, round_solution
from .staircase import Level, StaircaseResult, StaircaseStatus, staircase

__all__ = [
    "DEFAULT_TOL",
    "EIG_FLOOR",
    "Certificate",
    "Level",
    "Relaxation",
    "StaircaseResult",
    "StaircaseStatus",
    "certify",
    "certify_relaxation",
    "escape_saddle",
    "horizontal",
    "preconditioner",
    "lift",
    "relaxation",
    "relaxation_problem",
    "rotations_of",
    "round_solution",
    "staircase",
]
