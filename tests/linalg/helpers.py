"""Random factor graphs and a naive dense reference for the sparse linear algebra tests."""

from __future__ import annotations

import threading
from collections.abc import Callable

import numpy as np

from manopt_lie.linalg import BlockStructure


def random_factor_graph(rng: np.random.Generator, n_vars: int = 9) -> tuple[np.ndarray, list[tuple[np.ndarray, int]]]:
    """Variables of dimension 3 and 6, and factor types of arity 1 and 2.

    Slots are typed (a 3-dim slot only takes 3-dim variables); the binary
    factors repeat some pairs of variables, in both orders.
    """
    dims = np.where(np.arange(n_vars) % 3 == 2, 6, 3)
    small, large = np.flatnonzero(dims == 3), np.flatnonzero(dims == 6)

    def pairs(a: np.ndarray, b: np.ndarray, m: int) -> np.ndarray:
        out = np.stack([rng.choice(a, m), rng.choice(b, m)], axis=1)
        out = out[out[:, 0] != out[:, 1]]
        return np.concatenate([out, out[:2], out[:1, ::-1]])  # repeated edges, one reversed

    factors = [
        (rng.choice(small, 4)[:, None], 3),  # unary prior on 3-dim variables (with repeats)
        (rng.choice(large, 2)[:, None], 6),  # unary prior on 6-dim variables
        (pairs(small, small, 8), 3),  # binary, same dims
        (np.stack([rng.choice(small, 5), rng.choice(large, 5)], axis=1), 4),  # binary, mixed dims
        (pairs(large, large, 3), 6),
    ]
    return dims, factors


def random_values(
    rng: np.random.Generator, dims: np.ndarray, factors: list[tuple[np.ndarray, int]]
) -> tuple[list[np.ndarray], list[np.ndarray], list[np.ndarray]]:
    """Random Jacobian blocks, residuals and positive weights for ``factors``."""
    blocks = [rng.standard_normal((len(ids), r, int(dims[ids[0]].sum()))) for ids, r in factors]
    residuals = [rng.standard_normal((len(ids), r)) for ids, r in factors]
    weights = [rng.uniform(0.1, 2.0, len(ids)) for ids, _ in factors]
    return blocks, residuals, weights


def dense_jacobian(dims: np.ndarray, factors: list[tuple[np.ndarray, int]], blocks: list[np.ndarray]) -> np.ndarray:
    """``J`` built edge by edge, the obvious way."""
    offsets = np.concatenate([[0], np.cumsum(dims)])
    rows = []
    for (ids, r), A in zip(factors, blocks, strict=True):
        for e in range(len(ids)):
            row, col = np.zeros((r, offsets[-1])), 0
            for v in ids[e]:
                row[:, offsets[v] : offsets[v + 1]] += A[e][:, col : col + dims[v]]
                col += dims[v]
            rows.append(row)
    return np.vstack(rows)


def dense_normal_equations(
    dims: np.ndarray,
    factors: list[tuple[np.ndarray, int]],
    blocks: list[np.ndarray],
    residuals: list[np.ndarray],
    weights: list[np.ndarray] | None,
) -> tuple[np.ndarray, np.ndarray]:
    """``JᵀWJ`` and ``JᵀWr`` with dense matrices."""
    J = dense_jacobian(dims, factors, blocks)
    r = np.concatenate([res.ravel() for res in residuals])
    if weights is None:
        w = np.ones(len(r))
    else:
        w = np.concatenate([np.repeat(wk, res.shape[1]) for wk, res in zip(weights, residuals, strict=True)])
    return J.T @ (w[:, None] * J), J.T @ (w * r)


def pose_graph(
    rng: np.random.Generator, n_poses: int = 40, d: int = 3, anchor: bool = True
) -> tuple[BlockStructure, list[np.ndarray], list[np.ndarray]]:
    """A ring of poses with chords and, if ``anchor``, a prior on pose 0.

    Edge ``(i, j)`` has the block ``[−Q_j Q_iᵀ | I]`` for random orthogonal
    ``Q``: like a pose graph's, ``H`` is singular along the gauge
    ``x_i = Q_i c`` unless anchored.
    """
    ring = np.stack([np.arange(n_poses), (np.arange(n_poses) + 1) % n_poses], axis=1)
    chords = np.stack([np.arange(0, n_poses, 4), (np.arange(0, n_poses, 4) + n_poses // 2) % n_poses], axis=1)
    edges = np.concatenate([ring, chords])
    Q, _ = np.linalg.qr(rng.standard_normal((n_poses, d, d)))
    R = Q[edges[:, 1]] @ np.swapaxes(Q[edges[:, 0]], 1, 2)
    factors: list[tuple[np.ndarray, int]] = [(edges, d)]
    blocks = [np.concatenate([-R, np.broadcast_to(np.eye(d), R.shape)], axis=2)]
    residuals = [rng.standard_normal((len(edges), d))]
    if anchor:
        factors.append((np.zeros((1, 1), dtype=int), d))
        blocks.append(np.eye(d)[None])
        residuals.append(np.zeros((1, d)))
    return BlockStructure(np.full(n_poses, d), factors), blocks, residuals


def structure_arrays(S: BlockStructure) -> list[np.ndarray]:
    """Every index array of a structure: offsets, block pattern, ``H``'s pattern and diagonal
    positions, and each factor's scatters into ``H.data`` and ``g``."""
    scatters = [a for h, g in zip(S._hess_scatter, S._grad_scatter, strict=True) for a in (h.whole, g)]
    return [S.offsets, *S.block_pattern, S.indptr, S.indices, S.diagonal_positions, *scatters]


def assert_same_structure(S: BlockStructure, T: BlockStructure) -> None:
    """The same index arrays, entry for entry and dtype for dtype."""
    for a, b in zip(structure_arrays(S), structure_arrays(T), strict=True):
        assert a.dtype == b.dtype
        np.testing.assert_array_equal(a, b)
    assert S.nnz == T.nnz and S.n == T.n


def in_threads(run: Callable[[int], None], count: int) -> None:
    """``run(i)`` on ``count`` threads at once, ``i = 0 … count − 1``, all joined."""
    threads = [threading.Thread(target=run, args=(i,)) for i in range(count)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
