"""g2o files: :func:`read`, :func:`write`, :func:`lint` — pose graphs, landmarks and priors.

Supported lines (fields separated by whitespace, one record per line)::

    VERTEX_SE2         id x y θ
    EDGE_SE2           i j x y θ  I11 I12 I13 I22 I23 I33
    VERTEX_XY          id x y                                 (2-D landmark)
    EDGE_SE2_XY        i l x y  I11 I12 I22                   (landmark l seen from pose i)
    EDGE_PRIOR_SE2     i x y θ  I11 I12 I13 I22 I23 I33       (prior on pose i)
    VERTEX_SE3:QUAT    id x y z qx qy qz qw
    EDGE_SE3:QUAT      i j x y z qx qy qz qw  I11 I12 … I16 I22 … I66
    VERTEX_TRACKXYZ    id x y z                               (3-D landmark)
    PARAMS_SE3OFFSET   p x y z qx qy qz qw                    (sensor offset p)
    EDGE_SE3_TRACKXYZ  i l p x y z  I11 I12 I13 I22 I23 I33   (l seen from pose i's sensor p)
    EDGE_SE3_PRIOR     i p x y z qx qy qz qw  I11 … I66       (prior on pose i's sensor p)
    FIX                id [id …]

An edge ``i j`` carries the measured relative pose ``X_i⁻¹ X_j`` and the upper
triangle, row by row, of its information matrix in g2o's tangent order
``(ρ, θ)``, translation first (CONVENTIONS §2). Quaternions are Hamilton,
scalar last. An observation carries the landmark's point in the frame of the pose's
sensor, ``z ≈ (X_i S_p)⁻¹ l`` (``S_p`` the ``PARAMS_SE3OFFSET`` of id ``p``; the identity
in 2-D), and a ``d × d`` information matrix; a prior, the pose's measured value
(``EDGE_SE3_PRIOR``: of ``X_i S_p``) and its information in ``(ρ, θ)`` order. These are
the field orders of g2o's own readers (``types/slam2d``, ``types/slam3d``). ``#`` starts a
comment that runs to the end of the line; blank lines are skipped. Files are UTF-8 (a
byte order mark at the start is dropped); lines end with ``\\n``, ``\\r\\n`` or ``\\r``.

Poses and landmarks share one id space. A file with landmark, observation or prior
lines is read as a :class:`~manopt_lie.problems.LandmarkGraph`, any other as a
:class:`~manopt_lie.problems.PoseGraph`. Parameters may be defined anywhere in the file
(g2o wants them before their edges; :func:`write` puts them first); one that no line
names is dropped. As in g2o, an observation or a prior naming a parameter that no
``PARAMS_SE3OFFSET`` line defines is an error, id 0 included: g2o has no implicit identity
offset. A prior's offset is folded into it: ``Log(Z⁻¹ X S) = Ad_{S⁻¹} Log((Z S⁻¹)⁻¹ X)``, so
the prior on ``X`` with mean ``Z S⁻¹`` and information ``Ad_{S⁻¹}ᵀ Ω Ad_{S⁻¹}`` has the
same cost (identity offsets leave the prior untouched, bit for bit); written back, it
names an identity parameter.

The reader is strict: any other tag (``EDGE_SE2_XY_CALIB``, ``PARAMS_SE2OFFSET``, …), a
wrong number of fields, a field that is not a number (or, for ids, not an integer), a
number that is not finite as a double (``nan``, ``inf``, ``1e400``), a quaternion whose
norm is not 1 within ``quaternion_tol``, 2-D and 3-D records in one file, duplicate vertex
or parameter ids, an id that is a pose and a landmark, self-loops, edges, observations,
priors or ``FIX`` lines naming a vertex (of their kind) or a parameter that the file does
not define, ``FIX`` on a landmark, and lines that are not text (a NUL character, bytes that
are not UTF-8: a binary file) raise :class:`ParseError` with the file name and the earliest
offending line. A file without ``VERTEX`` lines of a kind (pose or landmark) takes those
vertices from the lines naming them, as edges-only pose graphs do. Quaternions within
``quaternion_tol`` (default 1e-4: any unit quaternion printed with 4 or more decimals) are
normalized. Information matrices that are not positive definite are accepted (real data
has them); :func:`lint` reports them, with matrices whose eigenvalues overflow double
precision, duplicate edges and observations, vertices without measurements, vertices not
connected to the anchor, landmarks seen fewer than twice or out of view and, for a file,
the quaternions that were normalized.

The reader streams: it reads the file in blocks of lines, converts each block with
one NumPy call per tag, and stops at the first bad line (a binary file is refused
without reading the rest of it); its memory stays near the size of the graph's
arrays.

:func:`write` puts out ``repr``-exact numbers and the original ids, such that
``write ∘ read ∘ write = write`` (the text is a fixed point) and translations, points
and information matrices read back bit for bit.
"""

from __future__ import annotations

import dataclasses

from .. import checks
from ..checks import LintReport
from ..graph import Graph, MeasurementGraph
from ..landmarks import LandmarkGraph
from ..pose_graph import PoseGraph
from ._reader import QUATERNION_TOL, Stats, parse
from ._records import ParseError
from ._source import PathOrFile, open_source, string_chunks
from ._writer import dumps, write

__all__ = ["ParseError", "LintReport", "QUATERNION_TOL", "read", "loads", "write", "dumps", "lint"]


def read(
    path_or_file: PathOrFile, *, name: str | None = None, quaternion_tol: float = QUATERNION_TOL
) -> PoseGraph | LandmarkGraph:
    """Read a g2o file: a pose graph, or a landmark graph (the module docstring has the lines).

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
    PoseGraph or LandmarkGraph
        A :class:`PoseGraph` for a file of pose lines only. Vertices are renumbered
        ``0..n-1`` in increasing id order; ``graph.ids`` keeps the file's ids.
        ``graph.poses`` holds the ``VERTEX`` estimates, or is ``None`` for a file with
        edges only (its vertex ids are then those the edges name). ``graph.fixed`` lists
        the ``FIX``-ed vertices in file order; ``graph.edge_lines`` the line of each edge
        (messages about an edge name it).

        A :class:`LandmarkGraph` for a file with landmark, observation or prior lines: its
        ``.poses`` is the pose graph above (the pose vertices and the pose–pose edges);
        ``landmark_ids`` the landmarks' ids in increasing order and ``landmarks`` their
        estimates (``None`` without landmark ``VERTEX`` lines); ``observations`` the
        ``(pose, landmark)`` indices, ``points`` and ``point_information`` in file order,
        with ``offset_ids`` (3-D: the parameter ids) and ``sensor_offsets`` (``None`` when
        all of them are the identity); the priors (offsets folded in, see the module
        docstring); ``observation_lines`` and ``prior_lines``.

    Raises
    ------
    ParseError
        On the earliest malformed line (see the module docstring), with ``filename``
        and ``lineno``.
    """
    return _read(path_or_file, name, quaternion_tol)[0]


def loads(text: str, *, name: str = "<string>", quaternion_tol: float = QUATERNION_TOL) -> PoseGraph | LandmarkGraph:
    """:func:`read` from a string; ``name`` is the graph's name and the file name in errors."""
    return parse(string_chunks(text, name), name, name, quaternion_tol)[0]


def _read(path_or_file: PathOrFile, name: str | None, quaternion_tol: float) -> tuple[PoseGraph | LandmarkGraph, Stats]:
    filename, default, chunks = open_source(path_or_file)
    return parse(chunks(), filename, name if name is not None else default, quaternion_tol)


def lint(
    graph_or_file: MeasurementGraph | LandmarkGraph | PathOrFile, *, quaternion_tol: float = QUATERNION_TOL
) -> LintReport:
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
    if isinstance(graph_or_file, Graph):
        return checks.lint(graph_or_file)
    graph, stats = _read(graph_or_file, None, quaternion_tol)
    return dataclasses.replace(
        checks.lint(graph), renormalized=stats.renormalized, quaternion_error=stats.quaternion_error
    )
