"""Initial estimates from relative measurements ``Z_e ≈ X_i⁻¹ X_j``: spanning-tree
(odometry) composition and the chordal relaxation (Martinec–Pajdla 2007;
Carlone et al. 2015), vectorized and sparse.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.sparse.csgraph import breadth_first_order, connected_components, minimum_spanning_tree

from manopt_lie.lie._matrix import project_rotation
from manopt_lie.lie.base import LieGroup
from manopt_lie.linalg import CholeskySolver

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


class DisconnectedGraphError(ValueError):
    """Some vertices cannot be reached from the anchor through the edges."""


def _adjacency(n: int, edges: IntArray, weights: Any = 1.0) -> sp.csr_matrix:
    w = np.broadcast_to(np.asarray(weights, dtype=np.float64), (len(edges),))
    return sp.csr_matrix((w, (edges[:, 0], edges[:, 1])), shape=(n, n))


def check_connected(n: int, edges: IntArray, ids: IntArray | None = None, anchor: int = 0) -> None:
    """Raise :class:`DisconnectedGraphError` naming the vertices unreachable from ``anchor``."""
    _, labels = connected_components(_adjacency(n, edges), directed=False)
    unreachable = np.flatnonzero(labels != labels[anchor])
    if unreachable.size:
        names = (ids if ids is not None else np.arange(n))[unreachable]
        more = f" and {unreachable.size - 20} more" if unreachable.size > 20 else ""
        raise DisconnectedGraphError(
            f"the graph is disconnected: {unreachable.size} vertices cannot be reached from vertex "
            f"{(ids if ids is not None else np.arange(n))[anchor]}: {names[:20].tolist()}{more}"
        )


def spanning_tree(group: type[LieGroup], n: int, edges: IntArray, measurements: LieGroup, anchor: int = 0) -> LieGroup:
    """Poses ``X`` with ``X_anchor = I`` composed along a spanning tree that prefers
    odometry edges ``(i, i+1)`` (so it is the odometry chain where there is one,
    bridged by other edges where it breaks).

    The tree is composed by pointer doubling: ``⌈log₂ depth⌉`` batched compositions
    ``A_v ← A_{p(v)} A_v``, ``p(v) ← p(p(v))`` turn parent-relative poses into
    anchor-relative ones, with no per-vertex loop.
    """
    check_connected(n, edges, anchor=anchor)
    odometry = np.abs(edges[:, 0] - edges[:, 1]) == 1
    # Odometry edges weigh 1, others 2: the minimum spanning tree keeps the chain.
    tree = minimum_spanning_tree(_adjacency(n, edges, np.where(odometry, 1.0, 2.0)))
    order, parent = breadth_first_order(tree, anchor, directed=False, return_predecessors=True)
    child = order[1:]
    parent = parent[child]
    # The measurement of each tree edge: Z_e as stored when e = (parent, child), Z_e⁻¹ when reversed.
    codes = edges[:, 0] * n + edges[:, 1]
    sort = np.argsort(codes, kind="stable")

    def find(a: IntArray, b: IntArray) -> IntArray:
        pos = np.minimum(np.searchsorted(codes[sort], a * n + b), len(codes) - 1)
        return np.where(codes[sort][pos] == a * n + b, sort[pos], -1)

    forward, backward = find(parent, child), find(child, parent)
    rel = measurements[np.where(forward >= 0, forward, backward)].as_matrix()
    rel_inv = measurements[np.where(forward >= 0, forward, backward)].inverse().as_matrix()
    # acc_v = X_{up(v)}⁻¹ X_v; pointer doubling until every up(v) is the anchor.
    up = np.arange(n)
    up[child] = parent
    acc = np.array(group.identity((n,)).as_matrix())
    acc[child] = np.where((forward >= 0)[:, None, None], rel, rel_inv)
    while np.any(up != anchor):
        acc = acc[up] @ acc
        up = up[up]
    return group.from_matrix(acc, project=True)


def _solve_columns(h: sp.csc_matrix, b: FloatArray) -> FloatArray:
    """``H⁻¹ B`` column by column with one sparse factorization (zero columns stay zero)."""
    solver = CholeskySolver()
    solver.analyze(h)
    solver.factorize(h)
    out = np.zeros_like(b)
    for k in range(b.shape[1]):  # d ≤ 3 right-hand sides
        if np.any(b[:, k]):
            out[:, k] = solver.solve(b[:, k])
    return out


def _free(n: int, block: int, anchor: int) -> IntArray:
    keep = np.ones(n * block, dtype=bool)
    keep[anchor * block : (anchor + 1) * block] = False
    return np.flatnonzero(keep)


def chordal_rotations(n: int, edges: IntArray, rotations: FloatArray, kappa: FloatArray, anchor: int = 0) -> FloatArray:
    """Rotations minimizing the relaxed ``Σ κ_e ‖R_j − R_i R̃_e‖_F²`` over all ``d × d``
    matrices with ``R_anchor = I``, projected onto SO(d).

    Row by row the cost is ``Σ κ ‖y_j − R̃ᵀ y_i‖²`` in ``Y = [R_1ᵀ; …; R_nᵀ]``, so all
    ``d`` columns of ``Y`` share the normal matrix ``N`` (blocks ``κI`` on the
    diagonal, ``−κR̃`` at ``(i, j)``, ``−κR̃ᵀ`` at ``(j, i)``): one factorization.
    """
    check_connected(n, edges, anchor=anchor)
    d = rotations.shape[-1]
    i, j = edges[:, 0], edges[:, 1]
    k = kappa[:, None, None]
    eye = np.broadcast_to(np.eye(d), rotations.shape)
    blocks = [(i, i, k * eye), (j, j, k * eye), (i, j, -k * rotations), (j, i, -k * np.swapaxes(rotations, 1, 2))]
    a = np.arange(d)
    shape = rotations.shape
    rows = np.concatenate([np.broadcast_to(r[:, None, None] * d + a[:, None], shape).ravel() for r, _, _ in blocks])
    cols = np.concatenate([np.broadcast_to(c[:, None, None] * d + a, shape).ravel() for _, c, _ in blocks])
    normal = sp.csc_matrix((np.concatenate([v.ravel() for _, _, v in blocks]), (rows, cols)), shape=(n * d, n * d))
    free, fixed = _free(n, d, anchor), np.arange(anchor * d, (anchor + 1) * d)
    y = np.zeros((n * d, d))
    y[fixed] = np.eye(d)
    y[free] = _solve_columns(normal[free][:, free].tocsc(), -(normal[free][:, fixed] @ np.eye(d)))
    return project_rotation(np.swapaxes(y.reshape(n, d, d), 1, 2))


def chordal_translations(
    n: int, edges: IntArray, rotations: FloatArray, translations: FloatArray, tau: FloatArray, anchor: int = 0
) -> FloatArray:
    """Translations minimizing ``Σ τ_e ‖t_j − t_i − R_i t̃_e‖²`` for fixed rotations,
    with ``t_anchor = 0``: a weighted graph Laplacian solve with ``d`` right-hand sides."""
    i, j = edges[:, 0], edges[:, 1]
    lap = sp.csc_matrix(
        (np.concatenate([tau, tau, -tau, -tau]), (np.concatenate([i, j, i, j]), np.concatenate([i, j, j, i]))),
        shape=(n, n),
    )
    rt = tau[:, None] * np.einsum("eab,eb->ea", rotations[i], translations)  # τ R_i t̃
    rhs = np.zeros((n, translations.shape[1]))
    np.add.at(rhs, j, rt)
    np.add.at(rhs, i, -rt)
    free = _free(n, 1, anchor)
    t = np.zeros_like(rhs)
    t[free] = _solve_columns(lap[free][:, free].tocsc(), rhs[free])
    return t
