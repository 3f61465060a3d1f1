"""Figures of benchmark runs: convergence curves and Dolan–Moré performance profiles (the
trajectory figures are in :mod:`.trajectory_plots`, re-exported here).

Headless (``Figure`` and a backend canvas, never pyplot); the format follows the file's
extension (:mod:`.figures`).

Convergence is drawn against a **reference** ``f*`` only when one is known independently
of the runs — a published optimum or a certified one (:class:`Reference`): a run's own final
value is never its reference. Without one, the curves show the cost itself.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from .figures import FORMATS, PALETTE, color, figure_format, save
from .record import Run, best_costs, solved
from .trajectory_plots import MAX_LOOP_CLOSURES, pose_errors, trajectory

__all__ = ["FORMATS", "PALETTE", "MAX_LOOP_CLOSURES", "Reference", "color", "convergence", "convergence_plots",
           "figure_format", "performance_profile", "pose_errors", "profile", "save", "trajectory"]  # fmt: skip

FLOOR = 1e-16
"""Relative suboptimalities below a reference's precision (at least this) are drawn at it."""


@dataclass(frozen=True)
class Reference:
    """A best-known optimum ``f*`` of one ``(instance, cost)``.

    Attributes
    ----------
    value : float
    rtol : float
        Its relative precision: half a unit of the last printed digit of a published value,
        the certificate's ``gap/|f*|`` of a certified one.
    source : str
        ``"published"`` or ``"certified"``, for the legend.
    """

    value: float
    rtol: float
    source: str


def _symlog(ax: Axes, axis: str, values: Sequence[float]) -> None:
    """A log axis where the positive values span more than a factor of 20, linear near zero
    (so that iteration 0 and time 0 stay on it)."""
    positive = [v for v in values if v > 0 and math.isfinite(v)]
    if not positive or max(positive) / min(positive) < 20:
        return
    threshold = 10.0 ** math.floor(math.log10(min(positive)))
    getattr(ax, f"set_{axis}scale")("symlog", linthresh=threshold, linscale=0.3)
    getattr(ax, f"set_{axis}lim")(0.0, 1.3 * max(positive))


def _series(run: Run, values: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    its = np.arange(values.size, dtype=float)
    times = np.asarray(run.history_time, dtype=float) if len(run.history_time) == values.size else None
    return its, times


def _draw(ax_it: Axes, ax_t: Axes | None, run: Run, y: np.ndarray, end: float, label: str) -> None:
    c = color(run.optimizer)
    if y.size <= 1:  # the final value only (IPOPT): one marker
        ax_it.plot([run.nit], [end], "s", color=c, label=label)
        if ax_t is not None:
            ax_t.plot([run.time], [end], "s", color=c)
        return
    its, times = _series(run, y)
    ax_it.plot(its, y, "-", color=c, label=label)
    last = np.flatnonzero(np.isfinite(y))
    if last.size:
        ax_it.plot(its[last[-1]], y[last[-1]], "o", color=c)
    if ax_t is not None and times is not None:
        ax_t.plot(times, y, "-", color=c)
        if last.size:
            ax_t.plot(times[last[-1]], y[last[-1]], "o", color=c)


def _finish_axes(axes: Sequence[Axes], runs: Sequence[Run], *, log_y: bool) -> None:
    iterations = [float(max(len(r.history_cost) - 1, r.nit)) for r in runs]
    times = [t for r in runs for t in r.history_time[1:2]] + [r.time for r in runs]
    for ax, xlabel, values in zip(axes, ("iteration", "time [s]"), (iterations + [1.0], times), strict=False):
        ax.set_xlabel(xlabel)
        _symlog(ax, "x", values)
        if log_y:
            ax.set_yscale("log")
        else:
            ax.ticklabel_format(axis="y", useOffset=False)
        ax.grid(True, which="both", alpha=0.3)


def _costs(runs: Sequence[Run]) -> list[float]:
    return [f for r in runs for f in [*r.history_cost, r.fun] if math.isfinite(f)]


def _log_worthy(values: Sequence[float]) -> bool:
    return bool(values) and min(values) > 0 and max(values) / min(values) > 10


def convergence(runs: Sequence[Run], path: Path | str, *, reference: Reference | None = None) -> Path:
    r"""Convergence of the runs of one ``(instance, cost)``, against iterations and against time.

    - With a ``reference`` (a published or certified :math:`f_\star`): the relative
      suboptimality :math:`(f_k - f_\star)/|f_\star|` on a log axis; values below the
      reference's precision (:attr:`Reference.rtol`, at least :data:`FLOOR`) are drawn on
      that floor, shaded as "equal to f* within its precision".
    - Without one, several runs: the cost :math:`f_k` itself (log axis when it spans more than
      a decade), with the lowest final cost as a dotted line.
    - Without one, a single run: its cost and, when recorded, its gradient norm (log), both
      against iterations.

    Axes in iterations and seconds are logarithmic where the values span more than a factor
    of 20 (linear near zero, so the start stays on them). A run with a one-point history
    (IPOPT) is a marker at ``(nit, fun)`` and ``(time, fun)``.

    Raises
    ------
    ValueError
        If ``runs`` is empty or mixes several ``(instance, cost)``.
    """
    keys = {run.key for run in runs}
    if len(keys) != 1:
        raise ValueError(f"convergence needs runs of exactly one (instance, cost), got {sorted(keys)}")
    first = runs[0]
    fig = Figure(figsize=(12, 4.4), layout="constrained")
    ax_it, ax_right = fig.subplots(1, 2)
    single = reference is None and len(runs) == 1
    if reference is not None:
        floor = max(reference.rtol, FLOOR)
        scale = max(abs(reference.value), 1e-300)
        for run in runs:
            with np.errstate(invalid="ignore", over="ignore"):
                rel = (np.asarray(run.history_cost, dtype=float) - reference.value) / scale
                end = (run.fun - reference.value) / scale
            rel = np.where(np.isfinite(rel), np.maximum(rel, floor), np.nan)
            _draw(ax_it, ax_right, run, rel, max(end, floor) if math.isfinite(end) else math.nan, run.optimizer)
        for ax in (ax_it, ax_right):
            ax.axhspan(floor * 0.5, floor, color="0.85", zorder=0)
            ax.axhline(floor, color="0.5", lw=0.8, ls=":")
        ax_it.set_ylabel(r"$(f_k - f_\star)/|f_\star|$")
        ax_it.plot([], [], lw=6, color="0.85", label=f"= f* within its precision ({floor:.0e})")
        what = f"{reference.source} f* = {reference.value:.10g}"
        _finish_axes((ax_it, ax_right), runs, log_y=True)
    elif single:
        cost = np.asarray(first.history_cost, dtype=float)
        _draw(ax_it, None, first, cost, first.fun, "cost")
        ax_it.set_ylabel(f"{first.cost} cost")
        grad = np.asarray(first.history_grad_norm, dtype=float)
        if grad.size:
            ax_right.plot(np.arange(grad.size), grad, "-", color=color(first.optimizer))
            ax_right.set_ylabel("gradient norm")
            ax_right.set_yscale("log")
            ax_right.set_xlabel("iteration")
            _symlog(ax_right, "x", [float(grad.size), 1.0])
            ax_right.grid(True, which="both", alpha=0.3)
        else:
            times = np.asarray(first.history_time, dtype=float)
            if times.size == cost.size and cost.size:
                ax_right.plot(times, cost, "-", color=color(first.optimizer))
            ax_right.set_ylabel(f"{first.cost} cost")
            _finish_axes((ax_right, ax_right), [first], log_y=_log_worthy(_costs([first])))
            ax_right.set_xlabel("time [s]")
        _finish_axes((ax_it,), [first], log_y=_log_worthy(_costs([first])))
        what = f"{first.optimizer}: {first.nit} iterations, {first.time:.3g} s, final cost {first.fun:.10g}"
    else:
        finals = [r.fun for r in runs if math.isfinite(r.fun)]
        for run in runs:
            _draw(ax_it, ax_right, run, np.asarray(run.history_cost, dtype=float), run.fun, run.optimizer)
        if finals:
            for ax in (ax_it, ax_right):
                ax.axhline(min(finals), color="0.4", lw=0.8, ls=":")
            ax_it.plot([], [], color="0.4", lw=0.8, ls=":", label=f"lowest final cost {min(finals):.10g}")
        ax_it.set_ylabel(f"{first.cost} cost")
        what = "no published or certified f*: the cost itself"
        _finish_axes((ax_it, ax_right), runs, log_y=_log_worthy(_costs(runs)))
    if not single:
        ax_right.set_ylabel(ax_it.get_ylabel())
    if not single:
        fig.legend(*ax_it.get_legend_handles_labels(), loc="outside right upper", fontsize="small")
    fig.suptitle(f"{first.instance} — {first.cost} cost (n={first.n}, m={first.m}); {what}")
    return save(fig, path)


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "_", text).strip("_") or "unnamed"


def convergence_plots(
    runs: Sequence[Run], directory: Path | str, *, references: Mapping[tuple[str, str], Reference] | None = None,
    format: str = "png",
) -> list[Path]:  # fmt: skip
    """One :func:`convergence` figure per ``(instance, cost)``, named
    ``<instance>-<cost>-convergence.<format>`` in ``directory``, in order of first appearance;
    of several starts (seeds) only the first start's runs are drawn. ``references`` maps
    ``(instance, cost)`` to its best-known optimum."""
    groups: dict[tuple[str, str], list[Run]] = {}
    for run in runs:
        groups.setdefault(run.key, []).append(run)
    directory = Path(directory)
    paths = []
    for (inst, cost), group in groups.items():
        start = group[0].start
        chosen = [r for r in group if r.start == start]
        target = directory / f"{_slug(inst)}-{_slug(cost)}-convergence.{format}"
        paths.append(convergence(chosen, target, reference=(references or {}).get((inst, cost))))
    return paths


def profile(runs: Sequence[Run]) -> tuple[list[str], np.ndarray]:
    r"""Performance ratios of solve time (Dolan & Moré 2002), over the problems each solver attempted.

    A problem :math:`p` is an ``(instance, cost, start)``; for optimizer :math:`s`,
    :math:`t_{p,s}` is its run's ``time`` if it :func:`~manopt_lie.bench.record.solved` the
    problem (the fastest such run if repeated), :math:`r_{p,s} = t_{p,s} / \min_s t_{p,s}`.

    Returns
    -------
    names : list of str
        Optimizers, in order of first appearance.
    ratios : ndarray, shape (n_problems, n_optimizers)
        :math:`r_{p,s}`; ``inf`` where ``s`` attempted ``p`` and did not solve it, ``nan`` where
        it did not attempt it (a peer that does not apply): not a failure.
    """
    best = best_costs(list(runs))
    problems = list(dict.fromkeys(run.problem_key for run in runs))
    names = list(dict.fromkeys(run.optimizer for run in runs))
    t = np.full((len(problems), len(names)), np.nan)
    for run in runs:
        p, s = problems.index(run.problem_key), names.index(run.optimizer)
        time = run.time if run.key in best and solved(run, best[run.key]) else np.inf
        t[p, s] = time if np.isnan(t[p, s]) else min(t[p, s], time)
    with np.errstate(invalid="ignore", divide="ignore"):
        tmin = np.min(np.where(np.isnan(t), np.inf, t), axis=1, keepdims=True) if t.size else t
        # ties give 1 even at zero time; a problem nobody solved has a row of inf (and nan)
        ratios = np.where(t == tmin, 1.0, t / np.maximum(tmin, np.finfo(float).tiny))
    ratios[np.isinf(t)] = np.inf
    ratios[np.isnan(t)] = np.nan
    return names, ratios


def performance_profile(runs: Sequence[Run], path: Path | str) -> Path:
    r"""Plot :math:`\rho_s(\tau) = |\{p \in A_s : r_{p,s} \le \tau\}| / |A_s|` of :func:`profile`,
    :math:`A_s` the problems solver :math:`s` attempted (the legend says how many of all): a
    step function of :math:`\tau \in [1, 1.1\,\max r]` on a log2 axis."""
    if not runs:
        raise ValueError("performance_profile needs at least one run")
    names, ratios = profile(runs)
    finite = ratios[np.isfinite(ratios)]
    tau_max = max(1.1 * float(finite.max()) if finite.size else 1.0, 2.0)  # at least one octave
    taus = np.unique(np.concatenate([[1.0], finite, [tau_max]]))
    fig = Figure(figsize=(6.8, 4.6))
    ax = fig.subplots()
    total = ratios.shape[0]
    for s, name in enumerate(names):
        attempted = ~np.isnan(ratios[:, s])
        rho = (ratios[attempted, s, None] <= taus[None, :]).mean(axis=0)
        label = name if attempted.all() else f"{name} (attempted {attempted.sum()} of {total})"
        ax.step(taus, rho, where="post", color=color(name), label=label, ls="-" if attempted.all() else "--")
    ax.set_xscale("log", base=2)
    ax.set_xlim(1.0, tau_max)
    ax.set_ylim(-0.02, 1.02)
    ax.set_xlabel(r"$\tau$ (time / fastest solving time)")
    ax.set_ylabel(r"$\rho_s(\tau)$: fraction of attempted problems solved")
    ax.set_title(f"Performance profile of solve time ({total} problems)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize="small", loc="lower right")
    return save(fig, path)
