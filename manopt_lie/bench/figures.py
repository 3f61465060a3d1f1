"""What every figure shares: the file formats, atomic saving, the optimizers' colours.

Headless: figures are built on ``Figure`` and written through a backend's canvas, never
through pyplot. The format follows the file's extension (:data:`FORMATS`); commands check
it with :func:`figure_format` before any work (this module imports Matplotlib only to save).
"""

from __future__ import annotations

import zlib
from pathlib import Path
from typing import TYPE_CHECKING

from manopt_lie.atomic import atomic_write

if TYPE_CHECKING:
    from matplotlib.figure import Figure

FORMATS = ("png", "pdf", "svg")
"""The figure formats, by file extension."""

PALETTE: dict[str, str] = {
    "lm": "tab:blue", "gtsam-lm": "tab:orange", "gn": "tab:green", "tr": "tab:red",
    "pymanopt-tr": "tab:purple", "gtsam-dogleg": "tab:brown", "cg": "tab:olive",
    "gd": "tab:gray", "ipopt": "black", "lbfgs": "tab:pink", "dogleg": "tab:cyan", "staircase": "gold",
}  # fmt: skip
"""Matplotlib colours of the optimizers and peers, by name, so every figure of a report
draws each one alike; other names hash into a fallback list (:func:`color`)."""
_FALLBACK = ["navy", "teal", "maroon", "darkkhaki", "indigo", "sienna", "darkslategray", "orchid"]


def color(optimizer: str) -> str:
    """The colour of ``optimizer``, the same in every figure (unknown names hash into tab10)."""
    return PALETTE.get(optimizer, _FALLBACK[zlib.crc32(optimizer.encode()) % len(_FALLBACK)])


def figure_format(path: Path | str) -> str:
    """The format of a figure file from its extension (``"png"``, ``"pdf"``, ``"svg"``).

    Raises
    ------
    ValueError
        For any other extension, naming the ones there are.
    """
    suffix = Path(path).suffix.lower().lstrip(".")
    if suffix not in FORMATS:
        given = f"'.{suffix}'" if suffix else "no extension"
        raise ValueError(f"{path}: a figure needs the extension .png, .pdf or .svg (got {given})")
    return suffix


def save(fig: Figure, path: Path | str) -> Path:
    """Write ``fig`` to ``path`` in the format of its extension (:func:`figure_format`; dpi
    120 for PNG, tight box), atomically (:func:`manopt_lie.atomic.atomic_write`), parents
    created; then free it."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # Matplotlib loads with the first figure

    path = Path(path)
    fmt = figure_format(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    FigureCanvasAgg(fig)  # a canvas without pyplot; savefig switches to the PDF/SVG backend itself
    metadata = {"Software": None} if fmt == "png" else {"Creator": None} if fmt == "pdf" else {"Date": None}
    with atomic_write(path, "wb") as f:
        fig.savefig(f, dpi=120, bbox_inches="tight", format=fmt, metadata=metadata)
    fig.clear()
    return path
