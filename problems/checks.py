"""Checks of a measurement graph for what makes optimization fail or mislead: :func:`lint`.

Information matrices that are not symmetric positive definite, duplicate edges,
vertices without edges and vertices not connected to the anchor. Nothing is
raised: the :class:`LintReport` lists what was found.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

__all__ = ["LintReport", "lint"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


@dataclass(frozen=True, eq=False)
class LintReport:
    """Problems found in a pose graph by :func:`lint`.

    Attributes
    ----------
    name : str
    n, m : int
        Numbers of vertices and edges.
    indefinite : int array ``(k,)``
        Edges whose information matrix (its symmetric part) is not positive definite.
    indefinite_ids : int array ``(k, 2)``
        Their vertex ids ``(i, j)`` as in the source.
    min_eigenvalues : ``(k,)``
        Their smallest eigenvalue.
    asymmetric : int array
        Edges whose information matrix is not symmetric (to ``1e-12`` relative).
    duplicates : int array ``(d,)``
        Edges joining the same two vertices (either way) as an earlier edge.
    duplicate_ids : int array ``(d, 2)``
        Their vertex ids.
    isolated : int array
        Ids of vertices with no edge.
    anchor : int
        Id of the vertex connectivity is checked from (the graph's ``anchor``).
    unreachable : int array
        Ids of vertices not connected to the anchor.
    """

    name: str
    n: int
    m: int
    indefinite: IntArray
    indefinite_ids: IntArray
    min_eigenvalues: FloatArray
    asymmetric: IntArray
    duplicates: IntArray
    duplicate_ids: IntArray
    isolated: IntArray
    anchor: int
    unreachable: IntArray

    @property
    def connected(self) -> bool:
        """Whether every vertex is connected to the anchor."""
        return not self.unreachable.size

    @property
    def ok(self) -> bool:
        """``True`` when nothing at all was found (duplicates included)."""
        return not (self.indefinite.size or self.asymmetric.size or self.duplicates.size or self.isolated.size) and (
            self.connected
        )

    def __str__(self) -> str:
        head = f"{self.name}: {self.n} vertices, {self.m} edges"
        if self.ok:
            return f"{head}: ok"
        lines = [head]
        if self.indefinite.size:
            items = [
                f"{i}→{j} (λmin {lam:.3g})"
                for (i, j), lam in zip(self.indefinite_ids, self.min_eigenvalues, strict=True)
            ]
            what = _count(self.indefinite.size, "information matrix", "information matrices")
            lines.append(f"  {what} not positive definite: {_some(items)}")
        if self.asymmetric.size:
            what = _count(self.asymmetric.size, "information matrix", "information matrices")
            lines.append(f"  {what} not symmetric: edges {_some(self.asymmetric)}")
        if self.duplicates.size:
            what = _count(self.duplicates.size, "duplicate edge", "duplicate edges")
            lines.append(f"  {what}: {_some(f'{i}→{j}' for i, j in self.duplicate_ids)}")
        if self.isolated.size:
            lines.append(f"  {_count(self.isolated.size, 'vertex', 'vertices')} without edges: {_some(self.isolated)}")
        if self.unreachable.size:
            what = _count(self.unreachable.size, "vertex", "vertices")
            lines.append(f"  not connected: {what} unreachable from vertex {self.anchor}: {_some(self.unreachable)}")
        return "\n".join(lines)


def _count(k: int, singular: str, plural: str) -> str:
    return f"{k} {singular if k == 1 else plural}"


def _some(items: Iterable[Any], k: int = 10) -> str:
    """The first ``k`` items, comma-separated, and how many more there are."""
    texts = [str(i) for i in items]
    more = f", … ({len(texts) - k} more)" if len(texts) > k else ""
    return ", ".join(texts[:k]) + more


def lint(graph: Any) -> LintReport:
    """Check a measurement graph (:class:`~manopt_lie.problems.graph.MeasurementGraph`) for common problems.

    Finds information matrices that are not symmetric positive definite (one batched
    ``eigvalsh`` over the ``(m, k, k)`` stack), duplicate edges, vertices without edges
    and vertices not connected to the anchor vertex (vertex 0 unless ``FIX`` says
    otherwise). Nothing is raised; see :attr:`LintReport.ok` and ``str(report)``.
    """
    ids: IntArray = graph.ids  # type: ignore[assignment]
    n, m, edges, info = graph.n, graph.m, graph.edges, graph.information

    scale = np.abs(info).max(axis=(1, 2)) if m else np.zeros(0)
    asymmetric = np.flatnonzero(np.abs(info - np.swapaxes(info, 1, 2)).max(axis=(1, 2), initial=0.0) > 1e-12 * scale)
    lam = np.linalg.eigvalsh(0.5 * (info + np.swapaxes(info, 1, 2)))[:, 0] if m else np.zeros(0)
    indefinite = np.flatnonzero(~(lam > 0.0))

    pairs = np.sort(edges, axis=1)
    _, first = np.unique(pairs, axis=0, return_index=True)
    duplicates = np.setdiff1d(np.arange(m), first)

    degree = np.bincount(edges.ravel(), minlength=n)
    isolated = ids[degree == 0]
    unreachable = np.zeros(0, dtype=np.int64)
    if n:
        adjacency = coo_matrix((np.ones(m), (edges[:, 0], edges[:, 1])), shape=(n, n))
        _, labels = connected_components(adjacency, directed=False)
        unreachable = ids[labels != labels[graph.anchor]]
    return LintReport(
        name=graph.name,
        n=n,
        m=m,
        indefinite=indefinite,
        indefinite_ids=ids[edges[indefinite]].reshape(-1, 2),
        min_eigenvalues=np.asarray(lam[indefinite], dtype=np.float64),
        asymmetric=asymmetric,
        duplicates=duplicates,
        duplicate_ids=ids[edges[duplicates]].reshape(-1, 2),
        isolated=isolated,
        anchor=int(ids[graph.anchor]) if n else 0,
        unreachable=unreachable,
    )
