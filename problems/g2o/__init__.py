"""g2o pose-graph files: :func:`read`, :func:`write`, :func:`lint`.

Supported lines (fields separated by whitespace, one record per line)::

    VERTEX_SE2       id x y θ
    EDGE_SE2         i j x y θ  I11 I12 I13 I22 I23 I33
    VERTEX_SE3:QUAT  id x y z qx qy qz qw
    EDGE_SE3:QUAT    i j x y z qx qy qz qw  I11 I12 … I16 I22 … I66
    FIX              id [id …]

An edge ``i j`` carries the measured relative pose ``X_i⁻¹ X_j`` and the upper
triangle, row by row, of its information matrix in g2o's tangent order
``(ρ, θ)``, translation first (CONVENTIONS §2). Quaternions are Hamilton,
scalar last. ``#`` starts a comment that runs to the end of the line; blank
lines are skipped. Files are UTF-8 (a byte order mark at the start is dropped);
lines end with ``\\n``, ``\\r\\n`` or ``\\r``.

The reader is strict: any other tag (``VERTEX_XY``, ``PARAMS_SE3OFFSET``, …),
a wrong number of fields, a field that is not a number (or, for ids, not an
integer), a number that is not finite as a double (``nan``, ``inf``, ``1e400``),
a quaternion whose norm is not 1 within ``quaternion_tol``, 2-D and 3-D records
in one file, duplicate vertex ids, self-loops, edges or ``FIX`` lines naming a
vertex that the file does not define, and lines that are not text (a NUL
character, bytes that are not UTF-8: a binary file) raise :class:`ParseError`
with the file name and the earliest offending line. Quaternions within
``quaternion_tol`` (default 1e-4: any unit quaternion printed with 4 or more
decimals) are normalized. Information matrices that are not positive definite
are accepted (real data has them); :func:`lint` reports them, with matrices
whose eigenvalues overflow double precision, duplicate edges, vertices without
edges, vertices not connected to the anchor and, for a file, the quaternions
that were normalized.

The reader streams: it reads the file in blocks of lines, converts each block with
one NumPy call per tag, and stops at the first bad line (a binary file is refused
without reading the rest of it); its memory stays near the size of the graph's
arrays.

:func:`write` puts out ``repr``-exact numbers and the original ids, such that
``write ∘ read ∘ write = write`` (the text is a fixed point) and translations
and information matrices read back bit for bit.
"""

from __future__ import annotations

import dataclasses

from .. import checks
from ..checks import LintReport
from ..graph import MeasurementGraph
from ..pose_graph import PoseGraph
from ._reader import QUATERNION_TOL, Stats, parse
from ._records import ParseError
from ._source import PathOrFile, open_source, string_chunks
from ._writer import dumps, write

__all__ = ["ParseError", "LintReport", "QUATERNION_TOL", "read", "loads", "write", "dumps", "lint"]


def read(path_or_file: PathOrFile, *, name: str | None = None, quaternion_tol: float = QUATERNION_TOL) -> PoseGraph:
    """Read a g2o pose graph (see the module docstring for the accepted lines).

    Parameters
    ----------
    path_or_file : path, or text or binary file object
        Read in blocks, never whole.
    name : str, optional
        The graph's name; default the file's stem (``"intel"``).
    quaternion_tol : float in [0, 1)
        Largest accepted ``| ‖q‖ − 1 |``; accepted quaternions are normalized. The
        default, :data:`QUATERNION_TOL` ``= 1e-4``, accepts unit quaternions printed with
        4 or more decimals (rounding moves the norm by less than ``10⁻ᵈ`` for ``d``
        decimals) and refuses a wrong digit before that.

    Returns
    -------
    PoseGraph
        Vertices are renumbered ``0..n-1`` in increasing id order; ``graph.ids`` keeps
        the file's ids. ``graph.poses`` holds the ``VERTEX`` estimates, or is ``None``
        for a file with edges only (its vertex ids are then those the edges name).
        ``graph.fixed`` lists the ``FIX``-ed vertices in file order;
        ``graph.edge_lines`` the line of each edge (messages about an edge name it).

    Raises
    ------
    ParseError
        On the earliest malformed line (see the module docstring), with ``filename``
        and ``lineno``.
    """
    return _read(path_or_file, name, quaternion_tol)[0]


def loads(text: str, *, name: str = "<string>", quaternion_tol: float = QUATERNION_TOL) -> PoseGraph:
    """:func:`read` from a string; ``name`` is the graph's name and the file name in errors."""
    return parse(string_chunks(text, name), name, name, quaternion_tol)[0]


def _read(path_or_file: PathOrFile, name: str | None, quaternion_tol: float) -> tuple[PoseGraph, Stats]:
    filename, default, chunks = open_source(path_or_file)
    return parse(chunks(), filename, name if name is not None else default, quaternion_tol)


def lint(graph_or_file: MeasurementGraph | PathOrFile, *, quaternion_tol: float = QUATERNION_TOL) -> LintReport:
    """:func:`manopt_lie.problems.checks.lint` of a graph, or of a g2o file read with :func:`read`.

    Given a file (a path or a file object), the report also says how many quaternions
    the reader normalized (:attr:`LintReport.renormalized`: their norm was off by more
    than 1e-12, but within ``quaternion_tol``) and the largest ``| ‖q‖ − 1 |``
    (:attr:`LintReport.quaternion_error`). Given a graph, it cannot know them: both
    are ``None``.

    Raises
    ------
    ParseError
        If the file cannot be read (nothing else: a graph read is always linted).
    """
    if isinstance(graph_or_file, MeasurementGraph):
        return checks.lint(graph_or_file)
    graph, stats = _read(graph_or_file, None, quaternion_tol)
    return dataclasses.replace(
        checks.lint(graph), renormalized=stats.renormalized, quaternion_error=stats.quaternion_error
    )
