"""Figures for benchmark runs: convergence curves, Dolan–Moré performance profiles
and pose-graph trajectories. Headless: figures are built on ``Figure`` with the
Agg canvas, never through pyplot, and only ever written to PNG files."""

from __future__ import annotations

import re
import zlib
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from mpl_toolkits.mplot3d.art3d import Line3DCollection

from manopt_lie.atomic import atomic_write
from manopt_lie.bench.record import Run, best_costs, solved

FLOOR = 1e-16
"""Relative suboptimalities are clipped to this floor so that a log axis shows zeros."""
MAX_LOOP_CLOSURES = 5000
"""Loop closures drawn at most (a fixed-seed subsample beyond), to keep huge graphs light."""

PALETTE: dict[str, str] = {
    "lm": "tab:blue", "gtsam-lm": "tab:orange", "gn": "tab:green", "tr": "tab:red",
    "pymanopt-tr": "tab:purple", "gtsam-dogleg": "tab:brown", "cg": "tab:olive",
    "gd": "tab:gray", "ipopt": "black",
}  # fmt: skip
_FALLBACK = ["tab:pink", "tab:cyan", "tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown"]


def color(optimizer: str) -> str:
    """The colour of ``optimizer``, the same in every figure (unknown names hash into tab10)."""
    return PALETTE.get(optimizer, _FALLBACK[zlib.crc32(optimizer.encode()) % len(_FALLBACK)])


def save(fig: Figure, path: Path | str) -> Path:
    """Write ``fig`` to ``path`` as PNG (parents created, dpi 120, tight box; atomically:
    :func:`manopt_lie.atomic.atomic_write`), then free it."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    FigureCanvasAgg(fig)  # attach the Agg canvas: no pyplot, no global figure registry
    with atomic_write(path, "wb") as f:
        fig.savefig(f, dpi=120, bbox_inches="tight", format="png")
    fig.clear()
    return path


def _suboptimality(f: np.ndarray, f_best: float) -> np.ndarray:
    """``max((f − f_best)/max(|f_best|, 1e-12), FLOOR)``, non-finite entries as NaN (gaps in lines)."""
    with np.errstate(invalid="ignore", over="ignore"):
        rel = (np.asarray(f, dtype=float) - f_best) / max(abs(f_best), 1e-12)
    return np.where(np.isfinite(rel), np.maximum(rel, FLOOR), np.nan)


def _draw_run(ax_it: Axes, ax_t: Axes, run: Run, f_best: float) -> None:
    c = color(run.optimizer)
    sub = _suboptimality(np.asarray(run.history_cost, dtype=float), f_best)
    if sub.size <= 1:  # final cost only (IPOPT): a single marker
        end = _suboptimality(np.array([run.fun]), f_best)
        ax_it.plot([run.nit], end, "s", color=c, label=run.optimizer)
        ax_t.plot([run.time], end, "s", color=c)
        return
    its = np.arange(sub.size)
    ax_it.plot(its, sub, "-", color=c, label=run.optimizer)
    last = np.flatnonzero(np.isfinite(sub))
    if last.size:
        ax_it.plot(its[last[-1]], sub[last[-1]], "o", color=c)
    if len(run.history_time) == sub.size:
        times = np.asarray(run.history_time, dtype=float)
        ax_t.plot(times, sub, "-", color=c)
        if last.size:
            ax_t.plot(times[last[-1]], sub[last[-1]], "o", color=c)


def convergence(runs: Sequence[Run], path: Path | str) -> Path:
    r"""Relative suboptimality against iterations and time for runs of one ``(instance, cost)``.

    Plots :math:`(f_k - f_\star)/\max(|f_\star|, 10^{-12})` on a log axis, clipped to
    :data:`FLOOR`, where :math:`f_\star` is the best final cost of ``runs``
    (:func:`~benchmarks.record.best_costs`); one line per optimizer, the last point
    marked; a run with a single-point history is a marker at ``(nit, fun)``, ``(time, fun)``.

    Raises
    ------
    ValueError
        If ``runs`` is empty or mixes several ``(instance, cost)``.
    """
    keys = {run.key for run in runs}
    if len(keys) != 1:
        raise ValueError(f"convergence needs runs of exactly one (instance, cost), got {sorted(keys)}")
    (key,) = keys
    f_best = best_costs(list(runs)).get(key)
    if f_best is None:  # no finite final cost: fall back on the histories
        finite = [f for run in runs for f in run.history_cost if np.isfinite(f)]
        f_best = min(finite, default=0.0)
    fig = Figure(figsize=(11, 4.2))
    ax_it, ax_t = fig.subplots(1, 2, sharey=True)
    for run in runs:
        _draw_run(ax_it, ax_t, run, f_best)
    for ax, xlabel in ((ax_it, "iteration"), (ax_t, "time [s]")):
        ax.set_yscale("log")
        ax.set_xlabel(xlabel)
        ax.grid(True, which="both", alpha=0.3)
    ax_it.set_ylabel(r"$(f_k - f_\star)/|f_\star|$")
    ax_it.legend(fontsize="small")
    first = runs[0]
    fig.suptitle(f"{first.instance} — {first.cost} cost (n={first.n}, m={first.m})")
    return save(fig, path)


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "_", text).strip("_") or "unnamed"


def convergence_plots(runs: Sequence[Run], directory: Path | str) -> list[Path]:
    """One :func:`convergence` figure per ``(instance, cost)``, named
    ``<instance>-<cost>-convergence.png`` in ``directory``, in order of first appearance."""
    groups: dict[tuple[str, str], list[Run]] = {}
    for run in runs:
        groups.setdefault(run.key, []).append(run)
    directory = Path(directory)
    return [
        convergence(group, directory / f"{_slug(inst)}-{_slug(cost)}-convergence.png")
        for (inst, cost), group in groups.items()
    ]


def profile(runs: Sequence[Run]) -> tuple[list[str], np.ndarray]:
    r"""Performance ratios of solve time (Dolan & Moré 2002).

    For problem :math:`p = (\text{instance}, \text{cost})` and optimizer :math:`s`,
    :math:`t_{p,s}` is the run's ``time`` if it :func:`~benchmarks.record.solved` the
    problem, else :math:`\infty` (also when missing; the fastest solving run if
    repeated), and :math:`r_{p,s} = t_{p,s} / \min_s t_{p,s}`.

    Returns
    -------
    names : list of str
        Optimizers, in order of first appearance.
    ratios : ndarray, shape (n_problems, n_optimizers)
        :math:`r_{p,s}`, problems in order of first appearance; ``inf`` when unsolved.
    """
    best = best_costs(list(runs))
    problems = list(dict.fromkeys(run.key for run in runs))
    names = list(dict.fromkeys(run.optimizer for run in runs))
    t = np.full((len(problems), len(names)), np.inf)
    for run in runs:
        p, s = problems.index(run.key), names.index(run.optimizer)
        if run.key in best and solved(run, best[run.key]):
            t[p, s] = min(t[p, s], run.time)
    tmin = t.min(axis=1, keepdims=True) if t.size else t
    with np.errstate(invalid="ignore", divide="ignore"):
        # ties give 1 even at zero time; a problem nobody solved has an all-inf row
        ratios = np.where(t == tmin, 1.0, t / np.maximum(tmin, np.finfo(float).tiny))
    ratios[~np.isfinite(t)] = np.inf
    return names, ratios


def performance_profile(runs: Sequence[Run], path: Path | str) -> Path:
    r"""Plot :math:`\rho_s(\tau) = |\{p : r_{p,s} \le \tau\}| / n_p` of :func:`profile`,
    a step function of :math:`\tau \in [1, 1.1\,\max r]` on a log2 axis."""
    if not runs:
        raise ValueError("performance_profile needs at least one run")
    names, ratios = profile(runs)
    finite = ratios[np.isfinite(ratios)]
    tau_max = max(1.1 * float(finite.max()) if finite.size else 1.0, 2.0)  # at least one octave
    taus = np.unique(np.concatenate([[1.0], finite, [tau_max]]))
    fig = Figure(figsize=(6.5, 4.5))
    ax = fig.subplots()
    for s, name in enumerate(names):
        rho = (ratios[:, s, None] <= taus[None, :]).mean(axis=0)
        ax.step(taus, rho, where="post", color=color(name), label=name)
    ax.set_xscale("log", base=2)
    ax.set_xlim(1.0, tau_max)
    ax.set_ylim(-0.02, 1.02)
    ax.set_xlabel(r"$\tau$ (time / fastest solving time)")
    ax.set_ylabel(r"$\rho_s(\tau)$: fraction of problems solved")
    ax.set_title(f"Performance profile of solve time ({ratios.shape[0]} problems)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize="small", loc="lower right")
    return save(fig, path)


def _check_trajectory(before: np.ndarray, after: np.ndarray, edges: np.ndarray) -> None:
    if before.ndim != 2 or before.shape[1] not in (2, 3) or after.shape != before.shape:
        raise ValueError(f"positions must both have shape (n, 2) or (n, 3), got {before.shape} and {after.shape}")
    if edges.ndim != 2 or edges.shape[1] != 2 or (edges.size and not np.issubdtype(edges.dtype, np.integer)):
        raise ValueError(f"edges must be an integer array of shape (m, 2), got {edges.dtype} {edges.shape}")
    if edges.size and (edges.min() < 0 or edges.max() >= before.shape[0]):
        raise ValueError(f"edge indices must lie in [0, {before.shape[0]}), got [{edges.min()}, {edges.max()}]")


def _draw_graph(ax: Axes, pos: np.ndarray, odometry: np.ndarray, loops: np.ndarray, title: str) -> None:
    three = pos.shape[1] == 3
    Collection = Line3DCollection if three else LineCollection
    ax.add_collection(Collection(pos[loops], colors="tab:orange", linewidths=0.3, alpha=0.35))
    ax.add_collection(Collection(pos[odometry], colors="tab:blue", linewidths=0.9))
    ax.set_title(title)
    if not three:
        ax.autoscale_view()
        ax.set_aspect("equal", adjustable="datalim")
        return
    ax.set_box_aspect((1, 1, 1))  # type: ignore[arg-type]
    finite = pos[np.isfinite(pos).all(axis=1)]
    if finite.size:  # 3-D axes do not autoscale on collections: set a cube around the points
        lo, hi = finite.min(axis=0), finite.max(axis=0)
        centre, half = (lo + hi) / 2, max(float((hi - lo).max()) / 2, 1e-9)
        ax.set_xlim(centre[0] - half, centre[0] + half)
        ax.set_ylim(centre[1] - half, centre[1] + half)
        ax.set_zlim(centre[2] - half, centre[2] + half)  # type: ignore[attr-defined]


def trajectory(
    positions_before: np.ndarray, positions_after: np.ndarray, edges: np.ndarray, path: Path | str, title: str = ""
) -> Path:
    """Pose-graph positions before and after optimization, side by side.

    Odometry edges (``|i − j| = 1``) are dark lines, loop closures thin light ones
    (at most :data:`MAX_LOOP_CLOSURES`, a fixed-seed subsample beyond).

    Parameters
    ----------
    positions_before, positions_after : ndarray, shape (n, 2) or (n, 3)
    edges : ndarray of int, shape (m, 2)
        Vertex indices (rows of the position arrays) joined by each measurement.
    """
    before, after = np.asarray(positions_before, dtype=float), np.asarray(positions_after, dtype=float)
    edges = np.asarray(edges)
    if edges.size == 0:
        edges = edges.reshape(0, 2).astype(int)
    _check_trajectory(before, after, edges)
    is_odometry = np.abs(edges[:, 0] - edges[:, 1]) == 1
    odometry, loops = edges[is_odometry], edges[~is_odometry]
    if len(loops) > MAX_LOOP_CLOSURES:
        keep = np.random.default_rng(0).choice(len(loops), MAX_LOOP_CLOSURES, replace=False)
        loops = loops[np.sort(keep)]
    three = before.shape[1] == 3
    fig = Figure(figsize=(11, 5.2))
    for k, (pos, label) in enumerate(((before, "before"), (after, "after"))):
        ax = fig.add_subplot(1, 2, k + 1, projection="3d" if three else None)
        _draw_graph(ax, pos, odometry, loops, label)
    if title:
        fig.suptitle(title)
    return save(fig, path)
