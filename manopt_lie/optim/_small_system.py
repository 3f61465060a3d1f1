"""Gauss-Newton, Levenberg-Marquardt and the dogleg on a small pose graph, every iteration in
compiled code (``small_system.c``).

On a system of a few dozen unknowns a Python iteration is almost all calls — validation,
bookkeeping, a dozen NumPy calls of a few microseconds each — and GTSAM's whole solve of a 9-pose
graph takes 0.4 ms. A pose graph whose one factor is the library's between factor on SE(2) or
SE(3) with native kernels, of at most :data:`DENSE_UNKNOWNS` unknowns (:data:`MAX_UNKNOWNS`
where its ``H`` is banded), is therefore solved by ``small_system.c``: the iterations of
:class:`GaussNewton`, :class:`LevenbergMarquardt` or :class:`Dogleg` — the same steps,
acceptance and updates, the same stopping rule and collapse test — on an ``H`` factored by
LAPACK's Cholesky, dense or banded (SciPy's), calling the factor's compiled kernels and the
compiled retraction through their addresses. Its history is recorded into the run afterwards,
with the times at which the iterations ended.

The iterates are those of the Python loop up to round-off (sums in another order); one check is
left out: a solve is checked on its right-hand side (finite, ``‖(H + μI)δ + g‖ ≤ rtol·‖g‖``,
``−gᵀδ > 0``) but not on a random probe as well. Anything the compiled loop does not mirror — a
start that is not finite (whose error the Python loop words), Gauss-Newton's singular system
(which the Python loop raises), a step of a size the retraction computes by other kernels, a
kernel that fails — makes it return before it changes anything, and the Python loop runs
instead; so does any problem or setting outside its scope (:func:`plan`).
"""

from __future__ import annotations

import ctypes
import functools
import math
from typing import TYPE_CHECKING, Any

import numpy as np
import scipy.sparse
from numpy.typing import NDArray
from scipy.sparse.csgraph import reverse_cuthill_mckee

from .. import _kernels, _native
from ..lie import SE2, SE3
from ..lie._series import HUGE
from ..linalg import AutoSolver, CholeskySolver
from ..manifolds import LieGroupManifold, Power
from .least_squares_problem import LeastSquaresProblem
from .losses import Trivial
from .optimizer import ROUNDOFF, Run
from .result import OptimizeResult, Status

if TYPE_CHECKING:
    from .nonlinear_least_squares import NonlinearLeastSquares

DENSE_UNKNOWNS = 384
"""The largest system the compiled loop factors dense (64 SE(3) or 128 SE(2) poses): LAPACK's dense
Cholesky (0.13 ms at 162 unknowns, 0.74 ms at 384 here) stays faster than the sparse Python loop's
set-up and iterations up to about this size (LM against GTSAM's, cold, with a dense ``H``:
``cube(3)``, 162 unknowns, 1.18 compiled against 3.41 sparse; ``grid2d(10, 10)``, 300: 1.21
against 1.63; ``cube(4)``, 384: 2.09 against 2.10; ``grid2d(12, 12)``, 432: 1.61 against 1.22)."""

MAX_UNKNOWNS = 768
"""The largest system the compiled loop takes at all, where its ``H`` is banded (:func:`_banded_order`):
``H`` is stored dense, so beyond this its memory costs more than the band saves (banded, against
the sparse Python loop, LM over GTSAM's: ``grid2d(16, 16)``, 768 unknowns, 0.33 against 0.76;
``smallGrid3D``, 750, 0.75 against 0.83; ``cube(5)``, 750, 1.19 against 1.51; but
``grid2d(22, 22)``, 1452, 0.92 against 0.55 and ``cube(6)``, 1296, 2.79 against 1.15)."""

BANDED_FROM = 128
"""Systems above this many unknowns are ordered for a band (:func:`_banded_order`); below, the
ordering costs more than a dense factorization."""

MAX_RECORDS = 10_000
"""The most iterations (``max_iterations``) the compiled loop runs: it cannot be interrupted (a
``KeyboardInterrupt`` waits for it), so a run allowed more takes the Python loop."""

GAUSS_NEWTON, LEVENBERG_MARQUARDT, DOGLEG = 0, 1, 2
"""The methods' codes in ``small_system.c`` (an optimizer class's ``_compiled_as``)."""

EXTRAS = (("alpha",), ("damping", "rho"), ("radius", "gauss_newton_shift", "dogleg", "rho"))
"""``history.extra`` of each method, by code, as the Python loops record them."""

_c_double, _c_long, _c_void = ctypes.c_double, ctypes.c_longlong, ctypes.c_void_p
_DEFAULT_RTOL = CholeskySolver().rtol  # what the automatic choice checks a dense solve to


def _fields(kind: Any, names: str) -> list[tuple[str, Any]]:
    return [(name, kind) for name in names.split()]


class _Problem(ctypes.Structure):
    """``nls_problem`` of ``small_system.c``, field for field."""

    _fields_ = [
        *_fields(_c_long, "n m s2 k"),
        *_fields(_c_void, "edges fixed z sqrt_info"),
        *_fields(_c_long, "sqrt_info_stride"),
        *_fields(_c_void, "between log rplus potrf potrs pbtrf pbtrs position"),
        *_fields(_c_long, "kd"),
        *_fields(_c_double, "rtol grad_rtol grad_atol min_step rel_decrease typical_dist roundoff huge"),
        *_fields(_c_long, "max_iterations method max_backtracks"),
        *_fields(_c_double, "c1 lam0 lam_max kappa radius0"),
        *_fields(_c_void, "x history"),
        *_fields(_c_long, "records nfev ngev rejected moved"),
        *_fields(ctypes.c_int, "status"),
    ]


@functools.cache
def _lapack() -> list[int]:
    """The addresses of LAPACK's ``dpotrf``, ``dpotrs``, ``dpbtrf`` and ``dpbtrs`` as SciPy ships
    them (the capsules of :mod:`scipy.linalg.cython_lapack`): the dense Cholesky routines the Python
    loop's dense solves call, and their banded twins."""
    from scipy.linalg import cython_lapack

    # Prototypes of our own: setting restype on ctypes.pythonapi's functions would change them for everyone.
    name = ctypes.PYFUNCTYPE(ctypes.c_char_p, ctypes.py_object)(("PyCapsule_GetName", ctypes.pythonapi))
    pointer = ctypes.PYFUNCTYPE(ctypes.c_void_p, ctypes.py_object, ctypes.c_char_p)(
        ("PyCapsule_GetPointer", ctypes.pythonapi)
    )
    capsules = [cython_lapack.__pyx_capi__[routine] for routine in ("dpotrf", "dpotrs", "dpbtrf", "dpbtrs")]  # type: ignore[attr-defined]
    return [int(pointer(capsule, name(capsule))) for capsule in capsules]


@functools.cache
def _library() -> Any:
    """``small_system.c`` compiled (once per machine, like the kernels), or ``None``."""
    prototypes = {"small_system": (ctypes.c_int, [ctypes.POINTER(_Problem)])}
    return _native.load_source(__package__, "small_system.c", prototypes)


def _settings(optimizer: Any, method: int) -> tuple[int, float, float, float, float, float] | None:
    """The method's settings as the struct takes them (``max_backtracks, c1, λ₀, λ_max, κ, Δ₀``),
    or ``None`` where the compiled loop does not mirror them (Marquardt's damping)."""
    if method == GAUSS_NEWTON:
        return optimizer.max_backtracks, optimizer.sufficient_decrease, 0.0, 0.0, 0.0, 0.0
    if method == LEVENBERG_MARQUARDT:
        if optimizer.damping != "identity":
            return None
        return 0, 0.0, optimizer.initial_damping, optimizer.max_damping, optimizer.damping_factor, 0.0
    radius = optimizer.initial_radius
    return 0, 0.0, 0.0, 0.0, 0.0, math.nan if radius is None else radius


def _banded_order(edges: NDArray[np.int64], n: int, k: int) -> tuple[NDArray[np.int64], int]:
    """Each pose's position in an order that keeps ``H`` banded — reverse Cuthill-McKee on the
    poses' graph — and ``H``'s half bandwidth in it, in unknowns; the poses' own order and a dense
    ``H`` (``N − 1``) where a band would not save at least half of the factorization's work."""
    N = n * k
    position = np.arange(n, dtype=np.int64)
    if N > BANDED_FROM:
        # The poses' graph, both directions, as CSR arrays made here (SciPy's COO route and its own
        # symmetrization took 0.2 ms on 27 poses, 25 times the ordering itself).
        rows, cols = np.concatenate([edges[:, 0], edges[:, 1]]), np.concatenate([edges[:, 1], edges[:, 0]])
        by_row = np.lexsort((cols, rows))  # rows sorted within (RCM breaks ties by the order stored)
        indptr = np.concatenate([[0], np.cumsum(np.bincount(rows, minlength=n))])
        graph = scipy.sparse.csr_matrix((np.ones(len(rows)), cols[by_row], indptr), shape=(n, n))
        position[reverse_cuthill_mckee(graph, symmetric_mode=True)] = np.arange(n)
        kd = (int(np.abs(position[edges[:, 0]] - position[edges[:, 1]]).max()) + 1) * k - 1
        if 2 * kd * kd < N * N / 3:  # the band's N·kd² against the dense N³/3, halved at least
            return position, kd
        position = np.arange(n, dtype=np.int64)
    return position, N - 1


def _rtol(optimizer: NonlinearLeastSquares) -> float | None:
    """The relative residual the dense solves are checked to, if the optimizer's linear solver is
    the one a small system gets: the automatic choice, or a Cholesky solver that may go dense."""
    solver = optimizer.linear_solver
    if type(solver) is AutoSolver:
        return _DEFAULT_RTOL
    if type(solver) is CholeskySolver and solver.backend in ("auto", "dense"):
        return solver.rtol
    return None


def plan(optimizer: NonlinearLeastSquares, run: Run) -> _Problem | None:
    """The compiled loop's problem for this run, or ``None`` if the run is outside its scope:
    :class:`GaussNewton`, :class:`LevenbergMarquardt` (damping ``s·I``) or :class:`Dogleg` with
    the default linear solver; one between factor of SE(2)/SE(3) with native kernels, no robust
    loss, ``Power(G, n)``, ``2 ≤ n``, at most :data:`DENSE_UNKNOWNS` unknowns (:data:`MAX_UNKNOWNS`
    where ``H`` is banded); no callback, no progress table, no time limit, at most
    :data:`MAX_RECORDS` iterations."""
    problem, stopping = run.problem, run.stopping
    method = vars(type(optimizer)).get("_compiled_as")  # the class's own: a subclass may change a step
    if method is None or not isinstance(problem, LeastSquaresProblem) or len(problem.factors) != 1:
        return None
    if run.callback is not None or run.progress is not None or stopping.max_time != math.inf:
        return None
    rtol, settings = _rtol(optimizer), _settings(optimizer, method)
    if rtol is None or settings is None or stopping.max_iterations > MAX_RECORDS:
        return None
    manifold = problem.manifold
    if not isinstance(manifold, Power) or not isinstance(manifold.manifold, LieGroupManifold) or manifold.shape[1:]:
        return None
    group, n = manifold.manifold.group, manifold.shape[0]
    (factor,) = problem.factors
    spec = getattr(factor.residual, "native_between", None)
    if spec is None or spec.group is not group or manifold.manifold.geometry != "group" or n < 2:
        return None
    if group not in (SE2, SE3) or n * group.dim > MAX_UNKNOWNS or type(factor.robust_loss) is not Trivial:
        return None
    whitened = spec.sqrt_information is not None
    kinds = [("whitened " if whitened else "") + kind for kind in ("between", "log")] + ["rplus"]
    kernels = [k for k in (_kernels.native_kernel(group, kind) for kind in kinds) if k is not None]
    if len(kernels) != len(kinds) or _library() is None:
        return None
    edges = np.ascontiguousarray(factor.variables, dtype=np.int64)
    fixed = np.ascontiguousarray(problem.fixed, dtype=np.uint8)
    sqrt_info = spec.sqrt_information
    max_backtracks, c1, lam0, lam_max, kappa, radius0 = settings
    position, kd = _banded_order(edges, n, group.dim)
    if kd == n * group.dim - 1 and n * group.dim > DENSE_UNKNOWNS:  # no narrow band: the sparse Python loop
        return None
    c = _Problem(
        n, len(edges), spec.z_inv.shape[1], group.dim,
        edges.ctypes.data, fixed.ctypes.data, spec.z_inv.address, sqrt_info.address if whitened else None,
        (0 if len(sqrt_info.shape) == 1 else sqrt_info.shape[1]) if whitened else 0,
        *[k.address for k in kernels], *_lapack(), position.ctypes.data, kd,
        rtol, stopping.grad_rtol, stopping.grad_atol, stopping.min_step, stopping.rel_cost_decrease or 0.0,
        manifold.typical_dist, ROUNDOFF, HUGE,
        stopping.max_iterations, method, max_backtracks, c1, lam0, lam_max, kappa, radius0,
    )  # fmt: skip
    c._keep = (edges, fixed, position)  # the arrays the pointers point into, alive as long as the struct
    return c


def solve(optimizer: NonlinearLeastSquares, run: Run, x0: Any) -> OptimizeResult | None:
    """The run by the compiled loop, or ``None`` (nothing recorded) if the Python loop must do it."""
    c = plan(optimizer, run)
    if c is None:
        return None
    x = np.array(x0.as_matrix(), dtype=np.float64, order="C")  # a copy: the compiled loop moves it
    history = np.empty((c.max_iterations + 1, 8))
    c.x, c.history = x.ctypes.data, history.ctypes.data
    entered = run.elapsed()  # the compiled loop's times count from its entry
    status = _library().small_system(ctypes.byref(c))
    if status < 0:  # outside what it mirrors: the Python loop, from the start
        return None
    x_final = type(x0)._wrap(x) if c.moved else x0
    names = EXTRAS[c.method]
    for i, (f, grad_norm, step, at, *extra) in enumerate(history[: c.records].tolist()):
        run.record_at(entered + at, x_final, f, grad_norm, step, **(dict(zip(names, extra, strict=False)) if i else {}))
    run.nfev, run.ngev, run.rejected_nonfinite = c.nfev, c.ngev, c.rejected
    return run.result(x_final, Status(status))
