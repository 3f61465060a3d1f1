"""CHOLMOD 3.0's C interface as :mod:`ctypes` sees it: its constants, the leading fields of its
structs, the prototypes :mod:`~manopt_lie.linalg._cholmod` calls, and where CVXOPT's copies of
its libraries (CHOLMOD, AMD) are loaded from. The layout is checked at first use
(``_cholmod._works``)."""

from __future__ import annotations

import ctypes
import ctypes.util
import os
from collections.abc import Mapping, Sequence
from ctypes import POINTER, c_double, c_int, c_size_t, c_void_p
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .._native import declare

# CHOLMOD's constants (cholmod_core.h, cholmod_cholesky.h).
_INT, _PATTERN, _REAL, _DOUBLE = 0, 0, 1, 0
_NATURAL, _GIVEN, _AMD = 0, 1, 2
_SIMPLICIAL, _SUPERNODAL = 0, 2  # Common.supernodal
_NOT_POSDEF = 1
_SOLVE_A = 0
_COMMON_BYTES = 1 << 16
"""Room for a ``cholmod_common`` (CHOLMOD 3.0's is a few kB): only its leading fields are read."""


class _Method(ctypes.Structure):
    _fields_ = [("lnz", c_double), ("fl", c_double), ("prune_dense", c_double), ("prune_dense2", c_double),
                ("nd_oksep", c_double), ("other_1", c_double * 4), ("nd_small", c_size_t), ("other_2", c_size_t * 4),
                ("aggressive", c_int), ("order_for_lu", c_int), ("nd_compress", c_int), ("nd_camd", c_int),
                ("nd_components", c_int), ("ordering", c_int), ("other_3", c_size_t * 4)]  # fmt: skip


class _Common(ctypes.Structure):
    """The leading fields of CHOLMOD 3.0's ``cholmod_common``, up to ``status``."""

    _fields_ = [("dbound", c_double), ("grow0", c_double), ("grow1", c_double), ("grow2", c_size_t),
                ("maxrank", c_size_t), ("supernodal_switch", c_double), ("supernodal", c_int),
                ("final_asis", c_int), ("final_super", c_int), ("final_ll", c_int), ("final_pack", c_int),
                ("final_monotonic", c_int), ("final_resymbol", c_int), ("zrelax", c_double * 3),
                ("nrelax", c_size_t * 3), ("prefer_zomplex", c_int), ("prefer_upper", c_int),
                ("quick_return_if_not_posdef", c_int), ("prefer_binary", c_int), ("print", c_int),
                ("precise", c_int), ("try_catch", c_int), ("error_handler", c_void_p), ("nmethods", c_int),
                ("current", c_int), ("selected", c_int), ("method", _Method * 10), ("postorder", c_int),
                ("default_nesdis", c_int), ("metis_memory", c_double), ("metis_dswitch", c_double),
                ("metis_nswitch", c_size_t), ("nrow", c_size_t), ("mark", ctypes.c_int64), ("iworksize", c_size_t),
                ("xworksize", c_size_t), ("Flag", c_void_p), ("Head", c_void_p), ("Xwork", c_void_p),
                ("Iwork", c_void_p), ("itype", c_int), ("dtype", c_int), ("no_workspace_reallocate", c_int),
                ("status", c_int)]  # fmt: skip


# What cholmod_start writes (cholmod_defaults): read back at the offsets above, they confirm the layout.
_DEFAULTS = {"grow0": 1.2, "grow1": 1.2, "grow2": 5, "maxrank": 8, "supernodal_switch": 40.0, "supernodal": 1,
             "final_asis": 1, "final_super": 1, "final_ll": 0, "final_pack": 1, "prefer_upper": 1, "print": 3,
             "nmethods": 0, "postorder": 1, "metis_nswitch": 3000, "itype": _INT, "dtype": _DOUBLE,
             "status": 0}  # fmt: skip


class _Sparse(ctypes.Structure):
    _fields_ = [("nrow", c_size_t), ("ncol", c_size_t), ("nzmax", c_size_t), ("p", c_void_p), ("i", c_void_p),
                ("nz", c_void_p), ("x", c_void_p), ("z", c_void_p), ("stype", c_int), ("itype", c_int),
                ("xtype", c_int), ("dtype", c_int), ("sorted", c_int), ("packed", c_int)]  # fmt: skip


class _Dense(ctypes.Structure):
    _fields_ = [("nrow", c_size_t), ("ncol", c_size_t), ("nzmax", c_size_t), ("d", c_size_t), ("x", c_void_p),
                ("z", c_void_p), ("xtype", c_int), ("dtype", c_int)]  # fmt: skip


class _Factor(ctypes.Structure):
    _fields_ = [("n", c_size_t), ("minor", c_size_t), ("Perm", c_void_p), ("ColCount", c_void_p),
                ("IPerm", c_void_p), ("nzmax", c_size_t), ("p", c_void_p), ("i", c_void_p), ("x", c_void_p),
                ("z", c_void_p), ("nz", c_void_p), ("next", c_void_p), ("prev", c_void_p), ("nsuper", c_size_t),
                ("ssize", c_size_t), ("xsize", c_size_t), ("maxcsize", c_size_t), ("maxesize", c_size_t),
                ("super", c_void_p), ("pi", c_void_p), ("px", c_void_p), ("s", c_void_p), ("ordering", c_int),
                ("is_ll", c_int), ("is_super", c_int), ("is_monotonic", c_int), ("itype", c_int),
                ("xtype", c_int), ("dtype", c_int)]  # fmt: skip


_SIGNATURES: dict[str, tuple[Any, list[Any]]] = {
    "cholmod_version": (c_int, [c_void_p]),
    "cholmod_start": (c_int, [c_void_p]),
    "cholmod_finish": (c_int, [c_void_p]),
    "cholmod_analyze_p": (POINTER(_Factor), [c_void_p, c_void_p, c_void_p, c_size_t, c_void_p]),
    "cholmod_factorize": (c_int, [c_void_p, c_void_p, c_void_p]),
    "cholmod_solve": (POINTER(_Dense), [c_int, c_void_p, c_void_p, c_void_p]),
    "cholmod_free_dense": (c_int, [c_void_p, c_void_p]),
    "cholmod_free_factor": (c_int, [c_void_p, c_void_p]),
    "cholmod_copy_factor": (POINTER(_Factor), [c_void_p, c_void_p]),
    "cholmod_factor_to_sparse": (POINTER(_Sparse), [c_void_p, c_void_p]),
    "cholmod_free_sparse": (c_int, [c_void_p, c_void_p]),
    "cholmod_allocate_factor": (c_void_p, [c_size_t, c_void_p]),
    "cholmod_malloc": (c_void_p, [c_size_t, c_size_t, c_void_p]),
}


def _array(address: int | None, dtype: type, size: int) -> NDArray[Any]:
    """A NumPy view of ``size`` items at ``address`` (owned by CHOLMOD: copy what must outlive it)."""
    if size == 0:
        return np.empty(0, dtype=dtype)
    if not address:
        raise RuntimeError("CHOLMOD returned no array where it should hold one")
    # A buffer of bytes at the address, read as dtype: 2 µs a call, against 4 through a typed pointer.
    item = np.dtype(dtype)
    return np.frombuffer(memoryview((ctypes.c_char * (size * item.itemsize)).from_address(address)), dtype=item)


def loaded_library(name: str) -> str | None:
    """The path of the library ``name`` (``"cholmod"``, ``"amd"``) CVXOPT loaded (Linux: from the
    process's memory map), else the system's."""
    try:
        with open("/proc/self/maps") as maps:
            for line in maps:
                path = line.split()[-1]
                if os.path.basename(path).startswith(f"lib{name}"):
                    return path
    except OSError:
        pass
    return ctypes.util.find_library(name)


def cvxopt_library(name: str, signatures: Mapping[str, tuple[Any, Sequence[Any]]]) -> Any | None:
    """The library ``name`` CVXOPT loaded (see :func:`loaded_library`), its functions given these
    prototypes ``{function: (restype, argtypes)}``; ``None`` where it or one of them is missing."""
    path = loaded_library(name)
    try:
        lib = ctypes.CDLL(path) if path else None
        if lib is None:
            return None
        declare(lib, signatures)
    except (OSError, AttributeError):
        return None
    return lib
