"""The smallest eigenpair of the certificate matrix ``S = Q − Λ``, with the factorizations
of ``S + σI`` that :class:`~.data.Relaxation` provides.

``S`` is the Schur complement of a sparse matrix (``Q`` is dense for pose graphs), so
products ``Sv`` cost a solve and solves with ``S + σI`` one factorization of the full sparse
matrix: both Krylov methods below work with the *inverse*, where the wanted eigenvalue is
the extreme one.

- :func:`bracket`: factorizations decide ``S + σI ≻ 0`` exactly (up to backward error), so a
  bisection on ``log σ`` brackets ``λ_min ∈ (−hi, −lo]`` within a factor
  :data:`BRACKET_RATIO`; ``S ⪰ −Λ`` (``Q ⪰ 0``) gives the first ``hi`` without one.
- :func:`lanczos_min`: ARPACK's Lanczos in shift-and-invert mode at ``σ = −hi``: the
  eigenvalue of ``(S + hi·I)⁻¹`` of largest magnitude is ``1/(λ_min + hi)``, and the bracket
  keeps it away from the others' ``1/(λ + hi) ≤ 1/(hi − lo)``-ish (measured: 10–30 solves).
  SE-Sync's LOBPCG on ``S`` itself, or Lanczos on ``S − λ_max I``, converge in hundreds of
  products for the clustered spectra of pose graphs, each product a solve here.
- :func:`ritz_min`: block inverse iteration from the rows of ``Y`` (the near null vectors
  of ``S`` at a critical point) for the estimate reported with a certificate (one step:
  the factorization is what the proof needs, the estimate should not cost another).
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse.linalg as spla
from numpy.typing import NDArray

from .data import Relaxation

FloatArray = NDArray[np.float64]

BRACKET_RATIO = 8.0
""":func:`bracket` bisects until ``hi/lo ≤`` this."""


def s_times(rel: Relaxation, lam: FloatArray, vt: FloatArray) -> FloatArray:
    """``S V = Q V − Λ V`` for ``V`` of shape ``(nd, k)`` and blocks ``Λ`` ``(n, d, d)``."""
    n, d = rel.n, rel.d
    return rel.q(vt) - (lam @ vt.reshape(n, d, -1)).reshape(n * d, -1)


def bracket(rel: Relaxation, lam: FloatArray, lo: float, floor: float) -> tuple[float, int]:
    """``hi`` with ``S + hi·I ≻ 0`` proven (the certificate factorization left at ``hi``), given
    that ``S + lo·I`` is not; returns ``(hi, factorizations)``.

    The start ``hi = max(λ_max(Λ_i), 0)`` (+ round-off) is safe because ``S = Q − Λ ⪰ −Λ``.
    """
    hi = max(float(np.max(np.linalg.eigvalsh(lam)[:, -1])), 0.0) * (1.0 + 1e-6) + 2.0 * floor
    count, last_ok = 0, False
    while hi > BRACKET_RATIO * lo:
        mid = math.sqrt(lo * hi)
        count += 1
        last_ok = rel.factor_certificate(lam, mid)
        lo, hi = (lo, mid) if last_ok else (mid, hi)
    while not last_ok:  # the factorization must end at hi (only round-off can refuse it)
        count += 1
        last_ok = rel.factor_certificate(lam, hi)
        if not last_ok:
            hi *= 2.0
    return hi, count


def ritz_min(rel: Relaxation, lam: FloatArray, start: FloatArray, steps: int = 2) -> tuple[float, FloatArray]:
    """The smallest Ritz pair of ``S`` on ``(S + σI)⁻ᵏ·start`` (``k = steps``, the last positive
    definite certificate factorization): block inverse iteration; the Ritz value is an upper
    bound on ``λ_min``."""
    x = np.linalg.qr(start)[0]
    for _ in range(steps):
        x = np.linalg.qr(rel.solve_certificate(x))[0]
    h = x.T @ s_times(rel, lam, x)
    w, u = np.linalg.eigh(0.5 * (h + h.T))
    v = x @ u[:, 0]
    return float(w[0]), v / np.linalg.norm(v)


def lanczos_min(rel: Relaxation, lam: FloatArray, shift: float, v0: FloatArray) -> tuple[float, FloatArray]:
    """The eigenpair of ``S`` nearest ``−shift`` — the smallest, as ``S + shift·I ≻ 0`` — by ARPACK in
    shift-and-invert mode with the current certificate factorization. Returns the Rayleigh
    quotient (with the exact ``S``) and the unit vector."""
    size = rel.n * rel.d

    def s_op(v: FloatArray) -> FloatArray:
        return s_times(rel, lam, v.reshape(size, 1)).ravel()

    def inv_op(v: FloatArray) -> FloatArray:
        return rel.solve_certificate(v.reshape(size, 1)).ravel()

    a = spla.LinearOperator((size, size), matvec=s_op, dtype=np.float64)
    op = spla.LinearOperator((size, size), matvec=inv_op, dtype=np.float64)
    try:
        _, u = spla.eigsh(a, k=1, sigma=-shift, which="LM", OPinv=op, v0=v0, tol=1e-8, maxiter=300)
        v = u[:, 0]
    except spla.ArpackNoConvergence as err:  # keep the best Ritz vector it had
        if not err.eigenvectors.size:
            return ritz_min(rel, lam, v0.reshape(size, 1), 8)
        v = err.eigenvectors[:, 0]
    v = v / np.linalg.norm(v)
    return float(v @ s_op(v)), v
