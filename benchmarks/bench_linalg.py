"""Normal-equation assembly and sparse SPD solvers on pose-graph-like problems, in one process.

Run from the repository root::

    python benchmarks/bench_linalg.py              # both tables
    python benchmarks/bench_linalg.py --repeat 3 --no-large

Problems are grids of poses (2-D with 3-dim tangents, 3-D with 6-dim ones)
visited by a serpentine odometry chain, plus loop closures between a random
fraction of the remaining grid neighbours, plus a prior on pose 0 (the gauge).

Table 1 times ``BlockStructure.normal_equations`` (per iteration) against
SciPy's sparse product ``Jᵀ(WJ)``. Table 2 times every available solver:
``analyze`` once per pattern, then ``factorize+solve`` per iteration, with
the ratio of the latter to SciPy's SuperLU called as ``splu(H).solve(g)``
(its default COLAMD ordering recomputed every time) in the same process.
Optional candidates (``qdldl``, ``cholespy``, ``pypardiso``) appear when
importable.

Every library runs on one thread unless the environment says otherwise
(``OMP_NUM_THREADS`` etc. are only given defaults): on a small shared
machine, threaded BLAS calls inside SuperLU or CHOLMOD slow down by large,
erratic factors whenever another process holds the cores.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402
import scipy.sparse.linalg as spla  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from manopt_lie.bench.timing import median_time  # noqa: E402
from manopt_lie.linalg import BlockStructure, CholeskySolver  # noqa: E402


def median_ms(f: Callable[[], Any], repeat: int) -> float:
    """Median wall time of ``repeat`` calls in milliseconds, after one warm-up call."""
    return 1e3 * median_time(f, repeat, warmup=1)[0]


def grid_pose_graph(shape: tuple[int, ...], closure_rate: float, rng: np.random.Generator) -> np.ndarray:
    """Edges ``(m, 2)``: a serpentine odometry chain through a grid plus random neighbour closures."""
    n = int(np.prod(shape))
    coords = np.stack(np.unravel_index(np.arange(n), shape), axis=1)
    # Reverse every other line of each axis so that consecutive chain poses are grid neighbours.
    for ax in range(1, len(shape)):
        flip = np.ravel_multi_index(coords[:, :ax].T, shape[:ax]) % 2 == 1
        coords[flip, ax] = shape[ax] - 1 - coords[flip, ax]
    node = np.empty(shape, dtype=np.intp)
    node[tuple(coords.T)] = np.arange(n)
    chain = np.stack([np.arange(n - 1), np.arange(1, n)], axis=1)
    lines = [np.moveaxis(node, ax, 0) for ax in range(len(shape))]
    pairs = np.concatenate([np.stack([a[:-1].ravel(), a[1:].ravel()], axis=1) for a in lines])
    pairs = pairs[np.abs(pairs[:, 0] - pairs[:, 1]) > 1]
    return np.concatenate([chain, pairs[rng.random(len(pairs)) < closure_rate]])


def pose_graph_problem(shape: tuple[int, ...], d: int, rng: np.random.Generator, closure_rate: float) -> dict:
    """Structure, Jacobian blocks ``[−R | I + noise]``, residuals and weights of a grid pose graph."""
    edges = grid_pose_graph(shape, closure_rate, rng)
    m, n_poses = len(edges), int(np.prod(shape))
    R, _ = np.linalg.qr(rng.standard_normal((m, d, d)))
    between = np.concatenate([-R, np.eye(d) + 0.1 * rng.standard_normal((m, d, d))], axis=2)
    return {
        "structure": BlockStructure(np.full(n_poses, d), [(np.zeros((1, 1), dtype=int), d), (edges, d)]),
        "blocks": [10.0 * np.eye(d)[None], between],
        "residuals": [np.zeros((1, d)), rng.standard_normal((m, d))],
        "weights": [np.ones(1), rng.uniform(0.5, 2.0, m)],
        "edges": m,
    }


# name -> (grid shape, tangent dimension, fraction of grid neighbours closed as loops)
PROBLEMS = {
    "2-D 50×50, d=3": ((50, 50), 3, 0.3),
    "2-D 100×100, d=3": ((100, 100), 3, 0.3),
    "3-D 14×14×14, d=6": ((14, 14, 14), 6, 0.3),
}
LARGE = {
    "3-D 22×22×22, d=6": ((22, 22, 22), 6, 0.5),  # ≈ 2·10⁴ edges
    "3-D 37×37×37, d=6": ((37, 37, 37), 6, 0.5),  # ≈ 10⁵ edges
}


def assembly_table(problems: dict, repeat: int, rng: np.random.Generator) -> None:
    print("Assembly of H = JᵀWJ, g = JᵀWr per iteration (ratio = ours / SciPy Jᵀ(WJ); lower is better)")
    header = ("problem", "edges", "n", "nnz(H)", "build", "normal_eq", "jacobian", "ratio")
    print("{:22} {:>7} {:>7} {:>9} {:>8} {:>10} {:>9} {:>6}".format(*header))
    for name, (shape, d, rate) in problems.items():
        start = time.perf_counter()
        p = pose_graph_problem(shape, d, rng, rate)
        S = p["structure"]
        build = 1e3 * (time.perf_counter() - start)
        args = (p["blocks"], p["residuals"], p["weights"])
        ours = median_ms(lambda: S.normal_equations(*args), repeat)
        jac = median_ms(lambda: S.jacobian(p["blocks"]), repeat)
        J = S.jacobian(p["blocks"])
        w = np.concatenate([np.repeat(wk, bk.shape[1]) for wk, bk in zip(p["weights"], p["blocks"], strict=True)])
        scipy_ms = median_ms(lambda: (J.T @ sp.diags(w) @ J).tocsc(), repeat)
        print(
            f"{name:22} {p['edges']:7d} {S.n:7d} {S.nnz:9d} {build:7.0f}ms {ours:8.1f}ms {jac:7.1f}ms"
            f" {ours / scipy_ms:6.2f}"
        )


def lower_triangle(H: sp.csc_matrix) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """CSC ``indptr``, ``indices`` of ``tril(H)`` and the positions of its entries in ``H.data``."""
    cols = np.repeat(np.arange(H.shape[0]), np.diff(H.indptr))
    keep = H.indices >= cols
    indptr = np.concatenate(([0], np.cumsum(np.bincount(cols[keep], minlength=H.shape[0])))).astype(np.int32)
    return indptr, H.indices[keep].astype(np.int32), np.flatnonzero(keep)


def solver_candidates() -> dict[str, tuple[Callable[[sp.csc_matrix], Any], Callable[[Any, sp.csc_matrix, Any], Any]]]:
    """``name -> (analyze(H) -> state, factorize_solve(state, H, g) -> x)``."""

    def ours(backend: str) -> tuple[Callable, Callable]:
        def analyze(H: sp.csc_matrix) -> CholeskySolver:
            solver = CholeskySolver(backend)
            solver.analyze(H)
            return solver

        return analyze, lambda s, H, g: (s.factorize(H), s.solve(g))[1]

    cands: dict[str, tuple[Callable, Callable]] = {
        "SuperLU splu (COLAMD)": (lambda H: None, lambda s, H, g: spla.splu(H).solve(g)),
        "SuperLU splu (MMD_ATA)": (
            lambda H: None,
            lambda s, H, g: spla.splu(
                H, permc_spec="MMD_ATA", diag_pivot_thresh=0.0, options={"SymmetricMode": True}
            ).solve(g),
        ),
    }
    for backend in CholeskySolver.available_backends()[::-1]:
        if backend != "dense":  # LAPACK on the dense matrix: for ≤ 128 unknowns, not these systems
            cands[f"CholeskySolver[{backend}]"] = ours(backend)
    try:
        import cholespy

        def cholespy_solve(lower: tuple, H: sp.csc_matrix, g: np.ndarray) -> np.ndarray:
            indptr, indices, pos = lower
            f = cholespy.CholeskySolverD(H.shape[0], indptr, indices, H.data[pos], cholespy.MatrixType.CSC)
            x = np.zeros_like(g)
            f.solve(g, x)
            return x

        cands["cholespy (CHOLMOD, no reuse)"] = (lower_triangle, cholespy_solve)
    except ImportError:
        pass
    try:
        from pypardiso.pardiso_wrapper import PyPardisoSolver

        def pardiso_analyze(H: sp.csc_matrix) -> tuple:
            # The lower triangle in CSC is, by symmetry, the upper triangle in CSR.
            indptr, indices, pos = lower_triangle(H)
            solver = PyPardisoSolver(mtype=2)  # real SPD
            solver.set_phase(11)
            solver._call_pardiso(sp.csr_matrix((H.data[pos], indices, indptr), shape=H.shape), np.zeros(H.shape[0]))
            return solver, indptr, indices, pos

        def pardiso_solve(state: tuple, H: sp.csc_matrix, g: np.ndarray) -> np.ndarray:
            solver, indptr, indices, pos = state
            solver.set_phase(23)
            return solver._call_pardiso(sp.csr_matrix((H.data[pos], indices, indptr), shape=H.shape), g)

        cands["pypardiso (MKL)"] = (pardiso_analyze, pardiso_solve)
    except ImportError:
        pass
    return cands


def solver_table(problems: dict, repeat: int, rng: np.random.Generator) -> None:
    print("\nSolvers: analyze once, factorize+solve per iteration (ratio = factorize+solve / SuperLU COLAMD)")
    cands = solver_candidates()
    for name, (shape, d, rate) in problems.items():
        p = pose_graph_problem(shape, d, rng, rate)
        H, g = p["structure"].normal_equations(p["blocks"], p["residuals"], p["weights"])
        print(f"-- {name}: n = {H.shape[0]}, nnz(H) = {H.nnz}")
        print(f"   {'candidate':30} {'analyze':>10} {'fact+solve':>11} {'ratio':>6} {'residual':>9}")
        baseline = None
        for cname, (analyze, solve) in cands.items():
            start = time.perf_counter()
            state = analyze(H)
            t_analyze = 1e3 * (time.perf_counter() - start)
            t_solve = median_ms(lambda: solve(state, H, g), repeat)
            x = solve(state, H, g)
            baseline = baseline or t_solve
            res = np.linalg.norm(H @ x - g) / np.linalg.norm(g)
            print(f"   {cname:30} {t_analyze:8.1f}ms {t_solve:9.1f}ms {t_solve / baseline:6.2f} {res:9.1e}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeat", type=int, default=5, help="timed runs per measurement (median)")
    parser.add_argument("--no-large", action="store_true", help="skip the 2·10⁴- and 10⁵-edge assembly cases")
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    assembly_table(PROBLEMS if args.no_large else {**PROBLEMS, **LARGE}, args.repeat, rng)
    solver_table(PROBLEMS, args.repeat, rng)


if __name__ == "__main__":
    main()
