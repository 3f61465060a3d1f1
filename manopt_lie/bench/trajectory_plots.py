"""Trajectory figures: a graph's initialization beside its solution, and trajectory errors.

- :func:`trajectory`: positions (2-D; 3-D as a top and a side view), odometry and loop
  closures, optionally the ground truth with the position error coloured along the path,
  landmarks, and 95 % covariance ellipses.
- :func:`pose_errors`: an APE/RPE result (``manopt-lie eval``) — the estimate's path coloured
  by its error over the reference, and the error against time with its statistics.

Headless (``Figure``, never pyplot); saved in the format of the file's extension.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import EllipseCollection, LineCollection
from matplotlib.colors import Normalize
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from manopt_lie.problems.evaluation import umeyama

from .figures import save

MAX_LOOP_CLOSURES = 5000
"""Loop closures drawn at most (a fixed-seed subsample beyond), to keep huge graphs light."""
MAX_ELLIPSES = 300
"""Covariance ellipses drawn at most (evenly spaced beyond)."""
CHI2_95 = 5.991464547107979
"""The 95 % quantile of χ² with 2 degrees of freedom: the ellipse ``δᵀΣ⁻¹δ ≤ CHI2_95``."""
CMAP = "viridis"
AXES = "xyz"


def _as_positions(a: Any, what: str, shape: tuple[int, ...] | None = None) -> np.ndarray:
    out = np.asarray(a, dtype=float)
    if out.ndim != 2 or out.shape[1] not in (2, 3) or (shape is not None and out.shape != shape):
        want = f"{shape}" if shape is not None else "(n, 2) or (n, 3)"
        raise ValueError(f"{what} must have shape {want}, got {out.shape}")
    return out


def _check_edges(edges: Any, n: int) -> np.ndarray:
    edges = np.asarray(edges)
    if edges.size == 0:
        return np.zeros((0, 2), dtype=np.int64)
    if edges.ndim != 2 or edges.shape[1] != 2 or not np.issubdtype(edges.dtype, np.integer):
        raise ValueError(f"edges must be an integer array of shape (m, 2), got {edges.dtype} {edges.shape}")
    if edges.min() < 0 or edges.max() >= n:
        raise ValueError(f"edge indices must lie in [0, {n}), got [{edges.min()}, {edges.max()}]")
    return edges


def _covariances(c: Any, count: int, d: int, what: str) -> np.ndarray | None:
    if c is None:
        return None
    c = np.asarray(c, dtype=float)
    if c.shape != (count, d, d):
        raise ValueError(f"{what} must have shape ({count}, {d}, {d}), got {c.shape}")
    return c


def _to_truth(pos: np.ndarray, truth: np.ndarray | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(aligned positions, R, t)``: ``pos`` moved onto ``truth`` by the Umeyama SE(d) alignment."""
    d = pos.shape[1]
    if truth is None:
        return pos, np.eye(d), np.zeros(d)
    try:
        r, t, _ = umeyama(pos, truth)
    except ValueError:  # degenerate positions: compare them as they are
        return pos, np.eye(d), np.zeros(d)
    return pos @ r.T + t, r, t


def _ellipses(ax: Axes, centres: np.ndarray, cov: np.ndarray, colour: str) -> None:
    if len(centres) > MAX_ELLIPSES:
        keep = np.linspace(0, len(centres) - 1, MAX_ELLIPSES).round().astype(int)
        centres, cov = centres[keep], cov[keep]
    vals, vecs = np.linalg.eigh(0.5 * (cov + np.swapaxes(cov, 1, 2)))
    vals = np.maximum(vals, 0.0)
    k = 2.0 * np.sqrt(CHI2_95)
    angles = np.degrees(np.arctan2(vecs[:, 1, 1], vecs[:, 0, 1]))  # the major axis (largest eigenvalue)
    ax.add_collection(EllipseCollection(k * np.sqrt(vals[:, 1]), k * np.sqrt(vals[:, 0]), angles, units="xy",
                                        offsets=centres, offset_transform=ax.transData, facecolors="none",
                                        edgecolors=colour, linewidths=0.7, alpha=0.8))  # fmt: skip


def _panel(ax: Axes, view: tuple[int, int], pos: np.ndarray, odometry: np.ndarray, loops: np.ndarray, *,
           truth: np.ndarray | None, error: np.ndarray | None, norm: Normalize | None, landmarks: np.ndarray | None,
           truth_landmarks: np.ndarray | None, cov: np.ndarray | None, lcov: np.ndarray | None) -> Any:  # fmt: skip
    a, b = view
    p = pos[:, [a, b]]
    mappable = None
    if truth is not None:
        ax.plot(truth[:, a], truth[:, b], "--", color="0.55", lw=0.9, zorder=1)
    if len(loops):
        alpha, width = (0.85, 1.0) if len(loops) < 500 else (0.35, 0.5)
        ax.add_collection(LineCollection(p[loops], colors="tab:orange", linewidths=width, alpha=alpha, zorder=2))
    if error is not None and norm is not None:
        segments = LineCollection(p[odometry], cmap=CMAP, norm=norm, linewidths=1.6, zorder=3)
        segments.set_array(0.5 * (error[odometry[:, 0]] + error[odometry[:, 1]]))
        ax.add_collection(segments)
        mappable = segments
    else:
        ax.add_collection(LineCollection(p[odometry], colors="tab:blue", linewidths=1.1, zorder=3))
    if not len(odometry):
        ax.plot(p[:, 0], p[:, 1], ".", color="tab:blue", ms=2)
    if truth_landmarks is not None:
        ax.plot(truth_landmarks[:, a], truth_landmarks[:, b], "^", mfc="none", mec="0.45", ms=5, zorder=4)
    if landmarks is not None:
        ax.plot(landmarks[:, a], landmarks[:, b], "^", color="tab:green", ms=4, zorder=5)
    sub = np.ix_(range(len(pos)), [a, b], [a, b])
    if cov is not None:
        _ellipses(ax, p, cov[sub], "tab:purple")
    if lcov is not None and landmarks is not None:
        _ellipses(ax, landmarks[:, [a, b]], lcov[np.ix_(range(len(landmarks)), [a, b], [a, b])], "tab:green")
    ax.set_xlabel(f"{AXES[a]} [m]")
    ax.set_ylabel(f"{AXES[b]} [m]")
    ax.autoscale_view()
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.25)
    return mappable


def trajectory(
    positions_before: Any,
    positions_after: Any,
    edges: Any,
    path: Path | str,
    title: str = "",
    *,
    truth: Any = None,
    landmarks: Any = None,
    truth_landmarks: Any = None,
    covariances: Any = None,
    landmark_covariances: Any = None,
    labels: Sequence[str] = ("initialization", "solution"),
) -> Path:
    """A graph's positions before (an initialization) and after optimization, side by side.

    Odometry edges (``|i − j| = 1``) are drawn as the path, loop closures as orange lines (at
    most :data:`MAX_LOOP_CLOSURES`, a fixed-seed subsample beyond). 3-D positions get two rows
    of a top (x–y) and a side (x–z) view.

    Parameters
    ----------
    positions_before, positions_after : ``(n, 2)`` or ``(n, 3)``
    edges : int ``(m, 2)``
        Vertex indices joined by each measurement.
    path : the figure file (``.png``, ``.pdf``, ``.svg``)
    title : str
    truth : ``(n, d)``, optional
        Ground-truth positions, drawn dashed; both estimates are then moved onto it by the
        Umeyama SE(d) alignment (as an APE is) and coloured by their position error, on one
        colour scale.
    landmarks, truth_landmarks : ``(L, d)``, optional
        The solution's landmarks (filled markers) and their ground truth (hollow markers).
    covariances : ``(n, d, d)``, optional
        Position covariances of the solution's poses, in the world frame: 95 % ellipses
        (of their 2 × 2 blocks in each view), for at most :data:`MAX_ELLIPSES` poses.
    landmark_covariances : ``(L, d, d)``, optional
    labels : the two panels' names
    """
    before = _as_positions(positions_before, "positions_before")
    after = _as_positions(positions_after, "positions_after", before.shape)
    n, d = before.shape
    edges = _check_edges(edges, n)
    true = None if truth is None else _as_positions(truth, "truth", before.shape)
    marks = None if landmarks is None else _as_positions(landmarks, "landmarks")
    true_marks = None if truth_landmarks is None else _as_positions(truth_landmarks, "truth_landmarks")
    cov = _covariances(covariances, n, d, "covariances")
    lcov = None if marks is None else _covariances(landmark_covariances, len(marks), d, "landmark_covariances")
    is_odometry = np.abs(edges[:, 0] - edges[:, 1]) == 1
    odometry, loops = edges[is_odometry], edges[~is_odometry]
    n_loops = len(loops)
    if n_loops > MAX_LOOP_CLOSURES:
        keep = np.random.default_rng(0).choice(n_loops, MAX_LOOP_CLOSURES, replace=False)
        loops = loops[np.sort(keep)]
    before, _, _ = _to_truth(before, true)
    after, r, t = _to_truth(after, true)
    if true is not None:
        marks = None if marks is None else marks @ r.T + t
        cov = None if cov is None else r @ cov @ r.T
        lcov = None if lcov is None else r @ lcov @ r.T
    errors = None if true is None else [np.linalg.norm(p - true, axis=1) for p in (before, after)]
    norm = None if errors is None else Normalize(0.0, max(float(np.max(np.concatenate(errors))), 1e-12))
    views = [(0, 1)] if d == 2 else [(0, 1), (0, 2)]
    fig = Figure(figsize=(11.5, 5.6 if d == 2 else 9.8), layout="constrained")
    grid = fig.subplots(len(views), 2, squeeze=False)  # rows: views; columns: before, after
    mappable = None
    for row, view in enumerate(views):
        for col, (pos, label) in enumerate(zip((before, after), labels, strict=True)):
            ax = grid[row, col]
            m = _panel(ax, view, pos, odometry, loops, truth=true, error=None if errors is None else errors[col],
                       norm=norm, landmarks=marks if col else None, truth_landmarks=true_marks,
                       cov=cov if col else None, lcov=lcov if col else None)  # fmt: skip
            mappable = mappable or m
            name = "" if d == 2 else (" — top view" if view == (0, 1) else " — side view")
            ax.set_title(f"{label}{name}")
    if mappable is not None:
        fig.colorbar(mappable, ax=grid.ravel().tolist(), shrink=0.85, label="position error [m] (aligned to the truth)")
    path_colour = "tab:blue" if errors is None else mappable.cmap(0.5) if mappable is not None else "tab:blue"
    legend = [Line2D([], [], color=path_colour, lw=1.4, label="odometry path")]
    if n_loops:
        shown = f"{n_loops}" if n_loops <= MAX_LOOP_CLOSURES else f"{MAX_LOOP_CLOSURES} of {n_loops}"
        legend.append(Line2D([], [], color="tab:orange", lw=1.0, label=f"loop closures ({shown})"))
    if true is not None:
        legend.append(Line2D([], [], color="0.55", ls="--", lw=1.0, label="ground truth"))
    if marks is not None:
        legend.append(Line2D([], [], color="tab:green", marker="^", ls="none", label="landmarks"))
    if true_marks is not None:
        legend.append(Line2D([], [], color="0.45", marker="^", mfc="none", ls="none", label="true landmarks"))
    if cov is not None or lcov is not None:
        legend.append(Line2D([], [], color="tab:purple", marker="o", mfc="none", ls="none", label="95 % ellipses"))
    fig.legend(handles=legend, loc="outside lower center", ncol=len(legend), fontsize="small", frameon=False)
    fig.suptitle(title or "trajectory")
    return save(fig, path)


def pose_errors(
    reference: Any,
    estimate: Any,
    errors: Any,
    path: Path | str,
    *,
    title: str,
    unit: str,
    stats: dict[str, float],
    times: Any = None,
    at: Any = None,
) -> Path:
    """An APE/RPE figure: the reference path (dashed) and the aligned estimate coloured by
    the error (top view, x–y), and the error against time (or index) with its rmse, mean,
    median and ±std band.

    Parameters
    ----------
    reference, estimate : ``(n, d)`` associated positions (the estimate aligned)
    errors : ``(k,)``
    at : int ``(k,)``, optional
        The pose each error belongs to (default ``0..k-1``; an RPE's pair ends).
    times : ``(n,)``, optional
        Timestamps of the poses (default: the index).
    stats : the statistics (``rmse``, ``mean``, ``median``, ``std``…)
    """
    ref = _as_positions(reference, "reference")
    est = _as_positions(estimate, "estimate", ref.shape)
    e = np.asarray(errors, dtype=float).reshape(-1)
    at = np.arange(e.size) if at is None else np.asarray(at, dtype=int)
    if at.shape != e.shape or (at.size and (at.min() < 0 or at.max() >= len(ref))):
        raise ValueError(f"at must hold {e.size} pose indices in [0, {len(ref)})")
    x = np.arange(len(ref), dtype=float) if times is None else np.asarray(times, dtype=float) - float(times[0])
    fig = Figure(figsize=(12, 4.8), layout="constrained")
    ax_path, ax_err = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1, 1.25]})
    norm = Normalize(float(e.min()), max(float(e.max()), float(e.min()) + 1e-12))
    ax_path.plot(ref[:, 0], ref[:, 1], "--", color="0.5", lw=1.0, label="reference")
    ax_path.plot(est[:, 0], est[:, 1], "-", color="0.8", lw=0.8, zorder=1)
    points = ax_path.scatter(est[at, 0], est[at, 1], c=e, cmap=CMAP, norm=norm, s=9, zorder=2, label="estimate")
    fig.colorbar(points, ax=ax_path, label=f"error [{unit}]" if unit else "error")
    ax_path.set_xlabel("x [m]")
    ax_path.set_ylabel("y [m]")
    ax_path.set_aspect("equal", adjustable="datalim")
    ax_path.grid(True, alpha=0.25)
    ax_path.legend(fontsize="small")
    ax_err.plot(x[at], e, "-", color="tab:gray", lw=0.9, label="error")
    mean, std = stats["mean"], stats["std"]
    ax_err.axhspan(mean - std, mean + std, color="tab:blue", alpha=0.12, label="mean ± std")
    for key, colour, style in (("rmse", "tab:red", "-"), ("mean", "tab:blue", "-"), ("median", "tab:green", "--")):
        ax_err.axhline(stats[key], color=colour, ls=style, lw=1.2, label=f"{key} {stats[key]:.4g}")
    ax_err.set_xlabel("time [s]" if times is not None else "pose index")
    ax_err.set_ylabel(f"error [{unit}]" if unit else "error")
    ax_err.grid(True, alpha=0.3)
    ax_err.legend(fontsize="small", loc="upper left")
    fig.suptitle(title.replace("\n", " "))
    return save(fig, path)
