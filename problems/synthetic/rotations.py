"""Synthetic rotation averaging on random graphs (the noise model: :mod:`manopt_lie.problems.synthetic`)."""

from __future__ import annotations

import numbers

import numpy as np

from manopt_lie import SO2, SO3

from ..rotation_averaging import RotationAveraging
from .base import Instance, IntArray, _nonnegative, _probability, _replace, _size, _weights

# ---- rotation averaging ----------------------------------------------------------------


def _pair_index(i: IntArray, j: IntArray, n: int) -> IntArray:
    """The number of the pair ``(i, j)``, ``i < j``, among all such pairs in row-major order:
    row ``i`` starts at ``s(i) = i n − i(i+1)/2``."""
    return i * n - i * (i + 1) // 2 + j - i - 1


def _pairs_from_index(t: IntArray, n: int) -> IntArray:
    """The pairs ``(i, j)``, ``i < j``, numbered ``t`` by :func:`_pair_index`, shape ``(len(t), 2)``.

    ``i`` is the root of ``s(i) = t`` rounded down, corrected by one where floating point
    lands on the wrong side.
    """
    start = lambda i: _pair_index(i, i + 1, n)
    i = np.floor((2 * n - 1 - np.sqrt((2.0 * n - 1) ** 2 - 8.0 * t)) / 2).astype(np.int64)
    i = np.clip(i, 0, n - 2)
    i -= start(i) > t
    i += start(i + 1) <= t
    return np.stack([i, t - start(i) + i + 1], axis=1)


def rotation_averaging(
    n: int = 100,
    *,
    d: int = 3,
    edge_probability: float | None = None,
    degree: float | None = None,
    noise: float = 0.05,
    outlier_rate: float = 0.0,
    seed: int = 0,
) -> Instance:
    """Rotation averaging on a random connected graph with Haar-random true rotations in SO(d).

    The graph is an Erdős–Rényi ``G(n, p)`` united with a Hamiltonian path through a random
    permutation of the vertices (the backbone, which makes it connected):
    ``n − 1 ≤ m ≤ n(n−1)/2``. Measurements are ``R̃_e = (R_iᵀ R_j) Exp(ε)``,
    ``ε ~ N(0, noise² I)``, with ``κ_e = 1/noise²`` (:data:`EXACT_WEIGHT` if ``noise = 0``);
    each edge off the path is an outlier (a Haar-random rotation) with probability
    ``outlier_rate``.

    Parameters
    ----------
    n : int ≥ 2
    d : {2, 3}
    edge_probability : float in [0, 1], optional
        ``p``; give it or ``degree``, not both.
    degree : float ≥ 0, optional
        Expected degree of the Erdős–Rényi part, ``p = min(1, degree/(n − 1))``;
        default 10 when neither is given.
    noise : float ≥ 0
        Standard deviation (rad) of each tangent coordinate of ``ε``.
    outlier_rate : float in [0, 1]
    seed : int

    Returns
    -------
    Instance
        ``graph.name`` is ``"rotation-averaging-so{d}-n{n}-seed{seed}"``.
    """
    params = dict(locals())
    n = _size("n", n)
    if isinstance(d, bool) or not isinstance(d, numbers.Integral) or d not in (2, 3):
        raise ValueError(f"d must be 2 or 3, got {d!r}")
    if edge_probability is not None and degree is not None:
        raise ValueError("give edge_probability or degree, not both")
    if edge_probability is not None:
        p = _probability("edge_probability", edge_probability)
    else:
        p = min(1.0, _nonnegative("degree", 10.0 if degree is None else degree) / (n - 1))
    sigma = _nonnegative("noise", noise)
    _probability("outlier_rate", outlier_rate)
    group = SO2 if d == 2 else SO3
    rng = np.random.default_rng(seed)

    truth = group.random(rng, (n,))
    order = rng.permutation(n)
    path = _pair_index(np.minimum(order[:-1], order[1:]), np.maximum(order[:-1], order[1:]), n)
    total = n * (n - 1) // 2
    # The union with G(n, p), as sorted pair indices: edges in lexicographic order.
    index = np.union1d(path, rng.choice(total, rng.binomial(total, p), replace=False))
    edges = _pairs_from_index(index, n)
    backbone = np.isin(index, path)
    m = len(edges)

    measurements = truth[edges[:, 0]].between(truth[edges[:, 1]]).rplus(sigma * rng.standard_normal((m, group.dim)))
    outliers = ~backbone & (rng.random(m) < outlier_rate)
    measurements = _replace(measurements, outliers, group.random(rng, (int(outliers.sum()),)))
    kappa = np.full(m, _weights(np.array(sigma)))
    graph = RotationAveraging(group, edges, measurements, kappa, n=n, name=f"rotation-averaging-so{d}-n{n}-seed{seed}")
    return Instance(graph, truth, outliers, params, backbone)
