"""The reduced problem data of the chordal cost, built once per graph (SE-Sync's
"simplified" formulation; Rosen, Carlone, Bandeira, Leonard, IJRR 2019, §4).

The chordal cost of a graph (CONVENTIONS §8) is the quadratic form
``f(X) = tr(X M Xᵀ)`` of the stacked top rows ``X = [X_1 … X_n]``, ``X_i = [R_i t_i]``
(:func:`~manopt_lie.problems.costs.chordal_quadratic_form`). Ordered as translations
(the :attr:`~manopt_lie.problems.graph.MeasurementGraph.anchor`'s left out: the gauge)
then rotations,

    M = [[A, B],       A = L(W^τ) (the anchored translational Laplacian),
         [Bᵀ, C]],     C = L(G^ρ) + Σ̃ (the connection Laplacian and the translation terms),

and the translations ``T = −A⁻¹ B Rᵀ`` that are optimal for given rotations eliminate
into the *reduced* data matrix (SE-Sync's ``Q = L(G^ρ) + Σ̃ − Ṽᵀ L(W^τ)⁺ Ṽ``, eq. 20)

    Q = C − Bᵀ A⁻¹ B,     f(R) = min_t f(R, t) = tr(R Q Rᵀ),

dense in general, so it is never formed: a product ``Q V`` is two sparse products and
one solve with the (once factored) ``A``. Rotation averaging has no translations and
``Q = C`` is the connection Laplacian itself.

Everything the certificate and the staircase factor — the certificate matrix
``S + ηI`` and the preconditioner ``Q + λI`` — is factored through the *full* sparse
``M`` with a block-diagonal change on the rotation block: by the Schur complement,

    [[A, B], [Bᵀ, C − Λ + ηI]] ≻ 0   ⇔   Q − Λ + ηI ≻ 0      (A ≻ 0),

and its solves with ``[0; V]`` return ``(Q − Λ + ηI)⁻¹ V`` in the rotation block. One
symbolic analysis serves every factorization.

Variables of the rank-``p`` relaxation are arrays ``Y`` of shape ``(n, p, d)``, ``Y_i``
with orthonormal columns (``Power(Stiefel(p, d), n)``); the matrix ``Yᵀ`` of SE-Sync
(``nd × p``) is :func:`stacked` ``(Y)``, row ``i·d + a`` holding column ``a`` of ``Y_i``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from manopt_lie.lie.base import LieGroup

from ..costs import chordal_quadratic_form
from ..graph import MeasurementGraph
from ..initialization import check_connected
from ._factor import SymmetricFactor

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

PRECONDITIONER_CONDITION = 1e6
"""SE-Sync's bound on the condition number of the regularized preconditioner ``Q + λI``."""


def stacked(y: FloatArray) -> FloatArray:
    """``Yᵀ`` (``nd × p``) of blocks ``Y_i`` (``(n, p, d)``): row ``i·d + a`` is column ``a`` of ``Y_i``."""
    n, p, d = y.shape
    return np.ascontiguousarray(y.transpose(0, 2, 1)).reshape(n * d, p)


def unstacked(yt: FloatArray, n: int) -> FloatArray:
    """The inverse of :func:`stacked`: ``(nd, p)`` → ``(n, p, d)``."""
    p = yt.shape[1]
    return yt.reshape(n, -1, p).transpose(0, 2, 1)


@dataclass(eq=False)
class Relaxation:
    """The reduced data of one graph's chordal cost (see the module docstring).

    Build it with :func:`relaxation`; it holds sparse matrices and factorizations only
    (``O(m)`` memory), no dense ``Q``. The factorizations are state (the last certificate
    matrix factored, the preconditioner built on first use): share one ``Relaxation``
    across calls, not across threads.

    Attributes
    ----------
    graph : MeasurementGraph
    n, d : int
        Vertices and the dimension of their rotations.
    n_translations : int
        ``n − 1`` for pose graphs (the anchor's translation is fixed), 0 for rotations.
    M : scipy.sparse.csc_matrix
        The full anchored data matrix, translations first, with the rotation block's
        ``d × d`` diagonal blocks stored in full (zeros included): the one pattern of
        every factorization.
    scale : float
        The largest diagonal entry of ``M``: the scale of ``Q`` and of ``S = Q − Λ``.
    """

    graph: MeasurementGraph
    n: int
    d: int
    n_translations: int
    M: sp.csc_matrix
    scale: float
    _A: SymmetricFactor | None
    _B: sp.csr_matrix | None
    _Bt: sp.csr_matrix | None
    _C: sp.csr_matrix
    _block_pos: IntArray  # positions in M.data of the rotation diagonal blocks, (n, d, d) order
    _diag_pos: IntArray  # positions in M.data of the rotation block's diagonal
    _factor: SymmetricFactor
    _edges: IntArray  # (m, 2)
    _kappa: FloatArray  # (m,)
    _tau: FloatArray | None  # (m,)
    _rot: FloatArray  # R̃_e, (m, d, d)
    _trans: FloatArray | None  # t̃_e, (m, d)
    _precond: SymmetricFactor | None = None

    @property
    def has_translations(self) -> bool:
        """Whether the problem has translations (a pose graph) rather than rotations only."""
        return self.n_translations > 0

    # ---- the quadratic form -----------------------------------------------------------

    def q(self, vt: FloatArray) -> FloatArray:
        """``Q V`` for ``V`` of shape ``(nd,)`` or ``(nd, k)``: ``C V − Bᵀ A⁻¹ (B V)``."""
        out = self._C @ vt
        if self._A is not None:
            assert self._B is not None and self._Bt is not None
            out -= self._Bt @ self._A.solve(self._B @ vt)
        return np.asarray(out)

    def cost(self, y: FloatArray) -> float:
        """``f(Y) = tr(Y Q Yᵀ)`` for blocks ``Y`` of shape ``(n, p, d)``: the chordal cost
        with the translations ``T`` that are optimal for ``Y`` (for ``p = d`` and rotations,
        the graph's chordal cost at the poses :meth:`poses` builds).

        It is summed edge by edge, ``Σ κ‖Y_j − Y_i R̃‖² + τ‖T_j − T_i − Y_i t̃‖²``, a sum of
        squares accurate to a few ulps of ``f``: ``tr(Y Q Yᵀ)`` cancels terms of the size of
        ``‖Q‖·nd``, which would hide the decrease of the last trust-region steps.
        """
        i, j = self._edges[:, 0], self._edges[:, 1]
        r = y[j] - y[i] @ self._rot
        f = float(np.einsum("e,epd,epd->", self._kappa, r, r))
        if self._tau is not None and self._trans is not None:
            t = self.translations(stacked(y))
            e = t[j] - t[i] - np.einsum("epd,ed->ep", y[i], self._trans)
            f += float(np.einsum("e,ep,ep->", self._tau, e, e))
        return f

    def lambda_blocks(self, y: FloatArray, qyt: FloatArray | None = None) -> FloatArray:
        """SE-Sync's Lagrange multipliers ``Λ_i = Sym((Q Yᵀ)_i Y_i)``, ``(n, d, d)``
        (``(Q Yᵀ)_i`` the ``d × p`` block row ``i``); ``Σ tr Λ_i = f(Y)``. At a first-order
        critical point ``(Q − Λ) Yᵀ = ½ grad f(Y)ᵀ = 0``."""
        if qyt is None:
            qyt = self.q(stacked(y))
        g = qyt.reshape(self.n, self.d, -1)  # (Q Yᵀ)_i, d × p
        lam = g @ y
        return 0.5 * (lam + lam.transpose(0, 2, 1))

    def certificate_values(self, lam: FloatArray, shift: float) -> FloatArray:
        """The values (in :attr:`M`'s pattern) of ``[[A, B], [Bᵀ, C − Λ + shift·I]]``, whose
        Schur complement is ``S + shift·I`` with ``S = Q − Λ``."""
        values = self.M.data.copy()
        values[self._block_pos] -= lam.reshape(-1)
        values[self._diag_pos] += shift
        return values

    def factor_certificate(self, lam: FloatArray, shift: float) -> bool:
        """Factor ``S + shift·I`` (through the full matrix); ``True`` iff it is positive definite."""
        return self._factor.factorize(self.certificate_values(lam, shift))

    def solve_certificate(self, vt: FloatArray) -> FloatArray:
        """``(S + shift·I)⁻¹ V`` with the last positive definite :meth:`factor_certificate`."""
        return self._solve_rotation_block(self._factor, vt)

    def _solve_rotation_block(self, factor: SymmetricFactor, vt: FloatArray) -> FloatArray:
        nt = self.n_translations
        if not nt:
            return factor.solve(vt)
        rhs = np.zeros((nt + vt.shape[0],) + vt.shape[1:])
        rhs[nt:] = vt
        return factor.solve(rhs)[nt:]

    def precondition(self, vt: FloatArray) -> FloatArray:
        """``(Q + λI)⁻¹ V`` with SE-Sync's regularization ``λ = ‖M‖/(10⁶ − 1)`` (a Gershgorin
        bound for ``‖M‖``): the regularized Cholesky preconditioner, factored on first use."""
        if self._precond is None:
            factor = SymmetricFactor(self.M, self._factor.backend)
            gershgorin = float(np.max(np.asarray(abs(self.M).sum(axis=0)).ravel()))
            values = self.M.data.copy()
            values[self._diag_pos] += gershgorin / (PRECONDITIONER_CONDITION - 1.0)
            if not factor.factorize(values):
                raise ArithmeticError(f"{self.graph.name}: the regularized data matrix is not positive definite")
            self._precond = factor
        return self._solve_rotation_block(self._precond, vt)

    # ---- from the relaxation back to the graph's variables ---------------------------

    def translations(self, rt: FloatArray) -> FloatArray:
        """The translations ``(n, k)`` optimal for the stacked rotations ``Rᵀ`` (``(nd, k)``):
        ``T = −A⁻¹ B Rᵀ``, with the anchor's at 0 (zeros for rotation averaging)."""
        graph, out = self.graph, np.zeros((self.n, rt.shape[1]))
        if self._A is not None:
            assert self._B is not None
            free = np.delete(np.arange(self.n), graph.anchor)
            out[free] = -self._A.solve(np.asarray(self._B @ rt))
        return out

    def poses(self, rotations: FloatArray) -> LieGroup:
        """The graph's group element (batch ``(n,)``) of the rotations ``(n, d, d)`` with their
        optimal translations, moved so that the anchor sits where the source had it (at the
        identity when the source had no estimates)."""
        graph, d = self.graph, self.d
        if self.has_translations:
            m = np.zeros((self.n, d + 1, d + 1))
            m[:, :d, :d] = rotations
            m[:, :d, d] = self.translations(stacked(rotations))
            m[:, d, d] = 1.0
        else:
            m = rotations
        x = graph.group.from_matrix(m)  # validated (rotations within 1e-6 or an error) and polished
        anchor = graph.anchor
        frame = x[anchor].inverse() if graph.estimates is None else graph.estimates[anchor] @ x[anchor].inverse()
        return frame @ x  # type: ignore[no-any-return]


def _positions(csc: sp.csc_matrix, rows: IntArray, cols: IntArray) -> IntArray:
    """Indices into ``csc.data`` of the entries ``(rows, cols)``, which the pattern must hold."""
    n = csc.shape[0]
    keys = np.repeat(np.arange(n, dtype=np.int64), np.diff(csc.indptr)) * n + csc.indices
    want = cols.astype(np.int64) * n + rows
    pos = np.searchsorted(keys, want)
    assert np.array_equal(keys[np.minimum(pos, keys.size - 1)], want), "pattern misses an entry"
    return pos


def relaxation(graph: MeasurementGraph, *, backend: str = "auto") -> Relaxation:
    """Build the reduced problem data of ``graph``'s chordal cost, once.

    Parameters
    ----------
    graph : PoseGraph or RotationAveraging
    backend : {"auto", "cholmod", "superlu"}
        The sparse factorization (:class:`~manopt_lie.problems.certify._factor.SymmetricFactor`).

    Raises
    ------
    IndefiniteInformationError
        Naming the edges whose SE-Sync weights ``κ, τ`` are not positive.
    DisconnectedGraphError
        If some vertices cannot be reached from the anchor.
    """
    if not graph.m:
        raise ValueError(f"{graph.name}: the graph has no edges, so there is nothing to certify")
    weights = graph.chordal_weights()
    n, d, anchor = graph.n, graph.d, graph.anchor
    check_connected(n, graph.edges, graph.ids, anchor)
    c = weights.shape[1]
    full = chordal_quadratic_form(n, graph.edges, graph.measurements, weights).tocoo()
    rot = (np.arange(n)[:, None] * c + np.arange(d)).ravel()
    trans = np.delete(np.arange(n) * c + d, anchor) if c > d else np.zeros(0, dtype=np.int64)
    nt = trans.size
    new_index = np.full(n * c, -1, dtype=np.int64)
    new_index[np.concatenate([trans, rot])] = np.arange(nt + n * d)
    keep = (new_index[full.row] >= 0) & (new_index[full.col] >= 0)
    # The rotation block's d × d diagonal blocks, stored in full so that Λ fits the pattern.
    a, b = np.meshgrid(np.arange(d), np.arange(d), indexing="ij")
    block_rows = (nt + np.arange(n)[:, None, None] * d + a).ravel()
    block_cols = (nt + np.arange(n)[:, None, None] * d + b).ravel()
    size = nt + n * d
    M = sp.csc_matrix(
        (
            np.concatenate([full.data[keep], np.zeros(block_rows.size), np.zeros(size)]),
            (
                np.concatenate([new_index[full.row[keep]], block_rows, np.arange(size)]),
                np.concatenate([new_index[full.col[keep]], block_cols, np.arange(size)]),
            ),
        ),
        shape=(size, size),
    )
    M.sum_duplicates()
    M.sort_indices()
    block_pos = _positions(M, block_rows, block_cols)
    diag = nt + np.arange(n * d)
    diag_pos = _positions(M, diag, diag)
    C = M[nt:, nt:].tocsr()
    A = B = Bt = None
    if nt:
        a_mat = M[:nt, :nt].tocsc()
        A = SymmetricFactor(a_mat, backend)
        if not A.factorize(a_mat.data):
            raise ArithmeticError(f"{graph.name}: the translational Laplacian is not positive definite")
        B = M[:nt, nt:].tocsr()
        Bt = B.T.tocsr()
    factor = SymmetricFactor(M, backend)
    scale = float(np.max(M.diagonal()))
    z = np.asarray(graph.measurements.as_matrix())
    w2 = weights**2
    tau: FloatArray | None = w2[:, d] if nt else None
    measured_t: FloatArray | None = z[:, :d, d].copy() if nt else None
    return Relaxation(
        graph, n, d, nt, M, scale, A, B, Bt, C, block_pos, diag_pos, factor, graph.edges, w2[:, 0], tau,
        z[:, :d, :d].copy(), measured_t,
    )  # fmt: skip
