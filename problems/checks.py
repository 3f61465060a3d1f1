"""Checks of a measurement graph for what makes optimization fail or mislead: :func:`lint`.

Information matrices that are not symmetric positive definite or whose eigenvalues
overflow double precision, duplicate edges, vertices without edges and vertices not
connected to the anchor. Nothing is raised: the :class:`LintReport` lists what was found.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
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
    overflow : int array ``(o,)``
        Edges whose information matrix has eigenvalues beyond the double range
        (``|λ| > 1.8e308``; found with each matrix scaled by its largest entry) or
        non-finite entries: no cost can use them (their terms overflow).
    overflow_ids : int array ``(o, 2)``
        Their vertex ids.
    renormalized : int or None
        Quaternions the g2o reader normalized (norm off by more than 1e-12, within its
        ``quaternion_tol``): a note, not a problem (:attr:`ok` ignores it). Known only
        for a report of a file (:func:`manopt_lie.problems.g2o.lint` given a path or a
        file object); ``None`` for a report of a graph, which does not keep it.
    quaternion_error : float or None
        The largest ``| ‖q‖ − 1 |`` among the file's quaternions (0 for 2-D files);
        ``None`` as :attr:`renormalized`.
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
    overflow: IntArray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    overflow_ids: IntArray = field(default_factory=lambda: np.zeros((0, 2), dtype=np.int64))
    renormalized: int | None = None
    quaternion_error: float | None = None

    @property
    def connected(self) -> bool:
        """Whether every vertex is connected to the anchor."""
        return not self.unreachable.size

    @property
    def ok(self) -> bool:
        """``True`` when no problem was found (duplicates included; normalized quaternions
        are not a problem)."""
        found = self.indefinite.size or self.asymmetric.size or self.duplicates.size or self.isolated.size
        return not (found or self.overflow.size) and self.connected

    def __str__(self) -> str:
        head = f"{self.name}: {self.n} vertices, {self.m} edges"
        note = ""
        if self.renormalized:
            what = _count(self.renormalized, "quaternion", "quaternions")
            note = f"  note: {what} normalized (| ‖q‖ − 1 | up to {self.quaternion_error:.2g})"
        if self.ok:
            return f"{head}: ok" + (f"\n{note}" if note else "")
        lines = [head]
        if self.overflow.size:
            what = _count(self.overflow.size, "information matrix", "information matrices")
            names = (f"{i}→{j}" for i, j in self.overflow_ids)
            lines.append(f"  {what} beyond double precision (eigenvalues overflow): {_some(names)}")
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
        if note:
            lines.append(note)
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

    Finds information matrices that are not symmetric positive definite or whose
    eigenvalues overflow (:func:`eigenvalues`), duplicate edges, vertices without edges
    and vertices not connected to the anchor vertex (vertex 0 unless ``FIX`` says
    otherwise). Nothing is raised; see :attr:`LintReport.ok` and ``str(report)``. What
    only a file shows (normalized quaternions) is reported by
    :func:`manopt_lie.problems.g2o.lint` of the file.
    """
    ids: IntArray = graph.ids  # type: ignore[assignment]
    n, m, edges = graph.n, graph.m, graph.edges
    info = np.asarray(graph.information, dtype=np.float64)

    lam, asymmetric, overflow = eigenvalues(info)
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
        overflow=overflow,
        overflow_ids=ids[edges[overflow]].reshape(-1, 2),
    )


def eigenvalues(info: FloatArray) -> tuple[FloatArray, IntArray, IntArray]:
    """Smallest eigenvalues of the symmetric parts of ``(m, k, k)`` matrices, without overflow.

    Each matrix is divided by its largest absolute entry before one batched ``eigvalsh``
    (so the decomposition sees entries in ``[-1, 1]`` whatever the file held), and the
    eigenvalues are scaled back; where that overflows the double range, or a matrix has
    non-finite entries, the edge is listed in ``overflow``. Never raises.

    Returns
    -------
    lam : ``(m,)``
        The smallest eigenvalues (``-inf`` where it overflows, ``nan`` for non-finite
        matrices); ``lam > 0`` exactly for the positive definite ones.
    asymmetric : int array
        Matrices not symmetric to ``1e-12`` relative to their largest entry.
    overflow : int array
        Matrices with an eigenvalue beyond the double range or a non-finite entry.
    """
    m = len(info)
    if not m:
        empty = np.zeros(0, dtype=np.int64)
        return np.zeros(0), empty, empty
    finite: NDArray[np.bool_] = np.asarray(np.isfinite(info).all(axis=(1, 2)))
    clean = np.where(finite[:, None, None], info, 0.0)  # non-finite matrices: nan eigenvalues below
    scale = np.abs(clean).max(axis=(1, 2))
    scale[scale == 0.0] = 1.0  # a zero matrix: its eigenvalues are 0 anyway
    unit = clean / scale[:, None, None]
    asymmetric = np.flatnonzero(np.abs(unit - np.swapaxes(unit, 1, 2)).max(axis=(1, 2)) > 1e-12)
    sym = 0.5 * (unit + np.swapaxes(unit, 1, 2))
    try:
        lam_unit = np.linalg.eigvalsh(sym)
    except np.linalg.LinAlgError:  # pragma: no cover  # entries in [-1, 1]: never seen; one by one then
        lam_unit = np.stack([_eigvalsh_or_nan(a) for a in sym])
    with np.errstate(over="ignore", under="ignore", invalid="ignore"):
        lam_all = lam_unit * scale[:, None]
    usable = finite & np.isfinite(lam_unit).all(axis=1)
    overflow = np.flatnonzero(~(usable & np.isfinite(lam_all).all(axis=1)))
    # Definiteness is read on the scaled matrix: an underflow of λ·scale to 0 does not count.
    smallest = np.where(lam_unit[:, 0] > 0.0, np.maximum(lam_all[:, 0], 5e-324), lam_all[:, 0])
    lam = np.asarray(np.where(usable, smallest, np.nan), dtype=np.float64)
    return lam, asymmetric, overflow


def _eigvalsh_or_nan(a: FloatArray) -> FloatArray:  # pragma: no cover  # see eigenvalues
    try:
        return np.asarray(np.linalg.eigvalsh(a), dtype=np.float64)
    except np.linalg.LinAlgError:
        return np.full(len(a), np.nan)
