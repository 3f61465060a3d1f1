"""CasADi functions of one element compiled to native code and run over whole batches.

CasADi writes C for a function (``casadi.CodeGenerator``); next to it goes a *driver* per
function that loops over the batch, pointing each argument and result at element ``e``
(``base + e·stride``; a stride of 0 shares one argument among all elements). The system's C
compiler (``$CC``, else ``cc``) builds one shared library per set of functions, kept in a cache
directory under the hash of its source (``$MANOPT_LIE_CACHE``, else ``$XDG_CACHE_HOME`` or
``~/.cache``, then ``manopt_lie/native``), so it is compiled once per machine (~0.3 s) and loaded
in a millisecond afterwards. A driver is called through :mod:`ctypes`, which releases the GIL.
:func:`load` builds any C source the same way (``optim/small_system.c``, which calls the drivers
through their addresses, :attr:`Native.address`).

No compiler, a failed build or ``MANOPT_LIE_NATIVE=0``: :func:`compile_functions` returns
``None`` and the callers keep their other paths.
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import os
import platform
import shlex
import shutil
import subprocess
import sys
import tempfile
import threading
from collections.abc import Mapping, Sequence
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["Native", "Pinned", "address", "compile_functions", "enabled", "declare", "load", "load_source"]

FloatArray = NDArray[np.float64]
FLAGS = ("-O2", "-fPIC", "-shared", "-pthread", "-ffp-contract=off")
"""Compiler flags: no fused multiply-adds, so the machine code rounds as CasADi's virtual machine
does; POSIX threads (``linalg/patterns.c`` starts one)."""

_LOCK = threading.Lock()
_LIBRARIES: dict[str, Any] = {}  # library file name → the loaded library (None: it cannot be built)


def compiler() -> list[str]:
    """The C compiler's command: ``$CC`` (split as a shell would, e.g. ``ccache gcc``), else ``cc``."""
    return shlex.split(os.environ.get("CC") or "cc")


def enabled() -> bool:
    """Whether native kernels may be built here: ``MANOPT_LIE_NATIVE`` is not ``0`` and a C compiler is found."""
    command = compiler()
    return os.environ.get("MANOPT_LIE_NATIVE", "1") != "0" and bool(command) and shutil.which(command[0]) is not None


def cache_dir() -> Path | None:
    """Where compiled libraries are kept (``None``: no home directory to keep them in)."""
    root = os.environ.get("MANOPT_LIE_CACHE")
    if root:
        return Path(root)
    try:
        base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    except (RuntimeError, KeyError):  # no home directory (``Path.home`` finds none)
        return None
    return base / "manopt_lie" / "native"


_FLOAT64 = np.dtype(np.float64)


def address(a: np.ndarray) -> int:
    """The address of ``a``'s first element: through the buffer protocol when ``a`` is writable and
    not empty (0.35 µs), else NumPy's ctypes interface (1.1 µs: it builds an object per call).
    A kernel's call takes the address of each of its 4–6 arrays, its own work a few µs."""
    if a.flags.writeable and a.nbytes:
        return ctypes.addressof(ctypes.c_char.from_buffer(a.data))
    return int(a.ctypes.data)


class Pinned:
    """A constant argument of many calls (a factor's measurements): made C-contiguous float64 and
    its address taken once, then passed to :meth:`Native.__call__` in place of the array, which it
    keeps alive. Looking up an address costs a call 0.5–1 µs per argument; a constant's need not
    be looked up again."""

    __slots__ = ("address", "array", "shape")

    def __init__(self, a: FloatArray) -> None:
        self.array = np.ascontiguousarray(a, dtype=np.float64)
        self.shape = self.array.shape
        self.address = int(self.array.ctypes.data)


class Native:
    """The batch driver of one compiled function: ``native(m, args, outs)`` evaluates elements
    ``0 … m−1``; each argument is ``(m, nnz)`` (row ``e`` for element ``e``) or ``(nnz,)``
    (shared), each result ``(m, nnz)``, all C-contiguous float64 (checked)."""

    def __init__(self, driver: Any, sizes_in: Sequence[int], sizes_out: Sequence[int]) -> None:
        self._driver = driver
        self._sizes_in, self._sizes_out = tuple(sizes_in), tuple(sizes_out)
        # The pointer and stride arrays' types, and the results' strides, made once (read-only in C).
        self._pointers_in, self._pointers_out = ctypes.c_void_p * len(sizes_in), ctypes.c_void_p * len(sizes_out)
        self._strides_in = ctypes.c_longlong * len(sizes_in)
        self._strides_out = (ctypes.c_longlong * len(sizes_out))(*sizes_out)

    @functools.cached_property
    def address(self) -> int:
        """The batch driver's address, for compiled code that calls it (``int name_batch(long long m,
        const double** arg, const long long* arg_stride, double** res, const long long* res_stride)``)."""
        return int(ctypes.cast(self._driver, ctypes.c_void_p).value or 0)

    def __call__(self, m: int, args: Sequence[FloatArray | Pinned], outs: Sequence[FloatArray]) -> None:
        pointers, strides = [], []
        for a, size in zip(args, self._sizes_in, strict=True):
            shared = len(a.shape) == 1
            fits = a.shape == ((size,) if shared else (m, size))
            if isinstance(a, Pinned):  # made float64 and C-contiguous when pinned
                what: object = "pinned"
                at = a.address
            else:
                what, fits = a.dtype, fits and a.dtype is _FLOAT64 and a.flags.c_contiguous
                at = address(a) if fits else 0
            if not fits:
                raise ValueError(f"native kernel: an argument of shape {a.shape} ({what}) is not ({m}, {size})")
            pointers.append(at)
            strides.append(0 if shared else size)
        results = []
        for o, size in zip(outs, self._sizes_out, strict=True):
            if o.dtype is not _FLOAT64 or not o.flags.c_contiguous or o.shape != (m, size) or not o.flags.writeable:
                raise ValueError(f"native kernel: a result of shape {o.shape} ({o.dtype}) is not ({m}, {size})")
            results.append(address(o))
        status = self._driver(
            ctypes.c_longlong(m), self._pointers_in(*pointers), self._strides_in(*strides),
            self._pointers_out(*results), self._strides_out,
        )  # fmt: skip
        if status:
            raise RuntimeError(f"native kernel: the compiled function failed on an element (status {status})")


def _driver(name: str, n_in: int, n_out: int, sz_iw: int, sz_w: int) -> str:
    """C: ``name_batch(m, arg, arg_stride, res, res_stride)`` over ``m`` elements."""
    return f"""
CASADI_SYMBOL_EXPORT int {name}_batch(long long m, const casadi_real** arg, const long long* arg_stride,
                                      casadi_real** res, const long long* res_stride) {{
  const casadi_real* a[{n_in}]; casadi_real* r[{n_out}];
  casadi_int iw[{sz_iw + 1}]; casadi_real w[{sz_w + 1}];
  long long e; int i;
  for (e = 0; e < m; ++e) {{
    for (i = 0; i < {n_in}; ++i) a[i] = arg[i] + e * arg_stride[i];
    for (i = 0; i < {n_out}; ++i) r[i] = res[i] + e * res_stride[i];
    if ({name}(a, r, iw, w, 0)) return 1;
  }}
  return 0;
}}
"""


def _source(functions: Sequence[Any]) -> str:
    import casadi as ca

    generator = ca.CodeGenerator("manopt_lie_native", {"with_header": False, "casadi_int": "long long int"})
    for f in functions:
        generator.add(f)
    drivers = [_driver(f.name(), f.n_in(), f.n_out(), f.sz_iw(), f.sz_w()) for f in functions]
    return generator.dump() + "".join(drivers)


def _build(source: str, target: Path) -> None:
    """Compile ``source`` into ``target`` (written next to it, then renamed into place: never half-written)."""
    target.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
    with tempfile.TemporaryDirectory(dir=target.parent) as work:
        c_file, library = Path(work) / "kernels.c", Path(work) / target.name
        c_file.write_text(source)
        subprocess.run([*compiler(), *FLAGS, "-o", str(library), str(c_file), "-lm"], check=True, capture_output=True)
        os.replace(library, target)


def library_name(source: str) -> str:
    """The file name of the library of ``source``: the hash of the source, the flags, the compiler
    and the machine (a cache shared by different machines keeps one library for each)."""
    key = chr(0).join([*FLAGS, *compiler(), sys.platform, platform.machine(), source])
    return f"kernels-{hashlib.sha256(key.encode()).hexdigest()[:24]}.so"


def load(source: str) -> Any:
    """The library of the C ``source`` (a :class:`ctypes.CDLL`): from the cache, else built into it
    (or, when the cache cannot be used, into a private directory); ``None`` if it cannot be built."""
    key = library_name(source)
    with _LOCK:
        if key not in _LIBRARIES:
            _LIBRARIES[key] = None
            for directory in dict.fromkeys((cache_dir(), None)):  # the cache, then a private directory
                try:
                    target = (directory or Path(tempfile.mkdtemp(prefix="manopt_lie-"))) / key
                    if not target.exists():
                        _build(source, target)
                    try:
                        _LIBRARIES[key] = ctypes.CDLL(str(target))
                    except OSError:  # a broken file in the cache: built anew
                        _build(source, target)
                        _LIBRARIES[key] = ctypes.CDLL(str(target))
                    break
                except (OSError, subprocess.CalledProcessError):
                    continue
        return _LIBRARIES[key]


def load_source(
    package: str, name: str | Sequence[str], signatures: Mapping[str, tuple[Any, Sequence[Any]]]
) -> Any:
    """The C file ``name`` of ``package`` (or several, compiled together as one) compiled and loaded
    (:func:`load`), its functions given these prototypes ``{function: (restype, argtypes)}``;
    ``None`` where native code is not :func:`enabled` or cannot be built."""
    if not enabled():
        return None
    names = [name] if isinstance(name, str) else list(name)
    library = load("\n".join(resources.files(package).joinpath(n).read_text() for n in names))
    if library is not None:
        declare(library, signatures)
    return library


def declare(library: Any, signatures: Mapping[str, tuple[Any, Sequence[Any]]]) -> None:
    """Give ``library``'s functions these prototypes ``{function: (restype, argtypes)}`` (an
    ``AttributeError`` where one is missing)."""
    for function, (restype, argtypes) in signatures.items():
        getattr(library, function).restype, getattr(library, function).argtypes = restype, argtypes


def compile_functions(functions: Sequence[Any]) -> dict[str, Native] | None:
    """The functions (CasADi ``Function``\\ s of one element, dense inputs and outputs) compiled
    into one library, by name; ``None`` when native code cannot be built here."""
    if not enabled():
        return None
    library = load(_source(functions))
    if library is None:
        return None
    natives = {}
    for f in functions:
        driver = getattr(library, f"{f.name()}_batch")
        driver.restype = ctypes.c_int
        sizes_in = [f.nnz_in(i) for i in range(f.n_in())]
        sizes_out = [f.nnz_out(i) for i in range(f.n_out())]
        natives[f.name()] = Native(driver, sizes_in, sizes_out)
    return natives
