"""Best-known optima of benchmark problems, the references of convergence plots.

For an ``(instance, cost)`` the reference ``f*`` is, in this order of preference:

1. **certified**: the chordal cost of the lowest-cost solution found, when the certificate of
   global optimality (:func:`manopt_lie.problems.certify.certify`, the smallest eigenvalue of
   ``S = Q − Λ``) proves it optimal; its precision is the certificate's proven bound
   ``gap ≥ f(x) − f*``, relative;
2. **published**: the catalogue's published optimum, precise to half a unit of its last
   printed digit (:func:`~manopt_lie.bench.record.published_precision`);
3. none: the plots then show the cost itself, never a suboptimality against a run's own value.

Certification needs the solution in this process (not for runs done on other workers or
resumed from a results store) and applies to the chordal cost only.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from .plots import Reference
from .record import Run, published_precision

TIGHT_TOL = 1e-9
"""The relative gap a certificate is first asked to prove."""
CERTIFIED_COST = "chordal"
"""The cost whose global optimum a certificate can prove."""


def _certified(spec: Any, x: Any) -> Reference | None:
    from manopt_lie.problems.certify import certify  # sparse eigen-machinery: loaded when used

    try:  # as tight a bound as the solution allows: ask for 1e-9 first, then the default 1e-6
        certificate = certify(spec, x, eigenvector=False, tol=TIGHT_TOL)
        if not certificate.optimal:
            certificate = certify(spec, x, eigenvector=False)
    except (TypeError, ValueError):  # a problem the certificate does not cover
        return None
    if not certificate.optimal:
        return None
    value = certificate.fun
    return Reference(value, max(certificate.gap / max(abs(value), 1e-300), 1e-16), "certified")


def references(
    runs: Sequence[Run], solutions: Mapping[tuple[str, str, str, str], Any], specs: Mapping[str, Any],
    *, certify: bool = True,
) -> dict[tuple[str, str], Reference]:  # fmt: skip
    """The best-known optimum of every ``(instance, cost)`` of ``runs`` that has one.

    Parameters
    ----------
    solutions : the solutions by :attr:`Run.task_key <manopt_lie.bench.record.Run.task_key>`
        (those this process has)
    specs : the problems by instance name (those this process has)
    certify : bool
        Try to certify the lowest-cost chordal solution.
    """
    out: dict[tuple[str, str], Reference] = {}
    groups: dict[tuple[str, str], list[Run]] = {}
    for run in runs:
        groups.setdefault(run.key, []).append(run)
    for (instance, cost), group in groups.items():
        found = None
        if certify and cost == CERTIFIED_COST and instance in specs:
            ranked = sorted((r for r in group if math.isfinite(r.fun) and r.task_key in solutions), key=lambda r: r.fun)
            if ranked:
                found = _certified(specs[instance], solutions[ranked[0].task_key])
        published = group[0].published
        if found is None and published is not None:
            _, half_unit = published_precision(published)
            found = Reference(published, half_unit / max(abs(published), 1e-300), "published")
        if found is not None:
            out[instance, cost] = found
    return out
