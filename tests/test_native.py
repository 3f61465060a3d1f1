"""Native kernels: CasADi functions of one element compiled to C, cached on disk, run over
batches through ctypes — equal to CasADi's own evaluation, rebuilt when the cache is broken or
unusable, and absent (``None``) where no compiler is."""

from __future__ import annotations

import os

import casadi as ca
import numpy as np
import pytest

from manopt_lie import _kernels, _native
from manopt_lie.lie import SE2, SE3


def _function(name: str = "probe") -> ca.Function:
    x, p = ca.SX.sym("x", 3), ca.SX.sym("p", 2)
    second = ca.vertcat(ca.sumsqr(x), ca.if_else(x[0] > 0, x[1], x[2]))
    return ca.Function(name, [x, p], [ca.sin(x) * p[0] + p[1], second])


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """A fresh cache directory, nothing loaded yet."""
    monkeypatch.setenv("MANOPT_LIE_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(_native, "_LIBRARIES", {})
    return tmp_path / "cache"


def _run(native: _native.Native, x: np.ndarray, p: np.ndarray) -> list[np.ndarray]:
    m = len(x)
    outs = [np.empty((m, 3)), np.empty((m, 2))]
    native(m, [x, p], outs)
    return outs


def test_a_compiled_function_equals_casadi_and_is_cached(cache, monkeypatch):
    if not _native.enabled():
        assert os.environ.get("CI") != "true", "CI must build native kernels: no C compiler found"
        assert _native.compile_functions([_function()]) is None
        return
    native = _native.compile_functions([_function()])["probe"]
    rng = np.random.default_rng(0)
    x, p = rng.standard_normal((7, 3)), rng.standard_normal((7, 2))
    outs = _run(native, x, p)
    reference = _function().map(7)(x.T, p.T)
    np.testing.assert_array_equal(outs[0], np.asarray(reference[0]).T)
    np.testing.assert_array_equal(outs[1], np.asarray(reference[1]).T)
    shared = _run(native, x, np.ascontiguousarray(p[0]))  # a (nnz,) argument: one for every element
    np.testing.assert_array_equal(shared[0], np.sin(x) * p[0, 0] + p[0, 1])
    assert len(list(cache.glob("kernels-*.so"))) == 1
    # A second process (nothing loaded) finds the library in the cache: no compiler run.
    monkeypatch.setattr(_native, "_LIBRARIES", {})
    monkeypatch.setattr(_native, "_build", lambda source, target: pytest.fail("rebuilt a cached library"))
    np.testing.assert_array_equal(_run(_native.compile_functions([_function()])["probe"], x, p)[0], outs[0])


def test_bad_arrays_are_refused(cache):
    natives = _native.compile_functions([_function()])
    if natives is None:
        assert not _native.enabled()
        return
    native = natives["probe"]
    x, p = np.zeros((4, 3)), np.zeros((4, 2))
    for args, outs, what in [
        ([x, p[:3]], [np.empty((4, 3)), np.empty((4, 2))], r"\(3, 2\) .* is not \(4, 2\)"),
        ([x.astype(np.float32), p], [np.empty((4, 3)), np.empty((4, 2))], "float32"),
        ([np.asfortranarray(np.zeros((4, 3))).T.T[:, ::-1], p], [np.empty((4, 3)), np.empty((4, 2))], "argument"),
        ([x, p], [np.empty((4, 3)), np.empty((4, 3))], "result"),
        ([x, p], [np.empty((4, 3)), np.broadcast_to(np.empty(2), (4, 2))], "result"),  # read-only
    ]:
        with pytest.raises(ValueError, match=what):
            native(4, args, outs)


def test_read_only_and_viewed_arguments_are_read_where_they_are(cache):
    """Arguments are passed by address (the buffer protocol for writable arrays, NumPy's ctypes
    interface for read-only ones): the results do not depend on which, nor on an offset view."""
    natives = _native.compile_functions([_function()])
    if natives is None:
        return
    rng = np.random.default_rng(1)
    big = rng.standard_normal((9, 3))
    x, p = big[2:7], rng.standard_normal((5, 2))  # a view at an offset into its base
    writable = _run(natives["probe"], x, p)
    x_ro, p_ro = x.copy(), p.copy()
    x_ro.flags.writeable = p_ro.flags.writeable = False
    for a, b in zip(writable, _run(natives["probe"], x_ro, p_ro), strict=True):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(writable[0], np.sin(x) * p[:, :1] + p[:, 1:])
    # A constant argument pinned once (its address taken at pinning): the same results, and
    # still refused where its shape does not fit.
    pinned = _run(natives["probe"], x, _native.Pinned(p))
    for a, b in zip(writable, pinned, strict=True):
        np.testing.assert_array_equal(a, b)
    with pytest.raises(ValueError, match=r"\(4, 2\) \(pinned\) is not \(5, 2\)"):
        _run(natives["probe"], x, _native.Pinned(p[:4]))


def test_a_broken_cached_library_is_rebuilt(cache):
    if not _native.enabled():
        return
    # (a library this process has loaded is not overwritten here: its mapping would break)
    source = _native._source([_function("broken")])
    cache.mkdir(parents=True)
    (cache / _native.library_name(source)).write_bytes(b"not a shared library")
    native = _native.compile_functions([_function("broken")])["broken"]
    np.testing.assert_allclose(_run(native, np.ones((2, 3)), np.ones((2, 2)))[0], np.sin(1.0) + 1.0)


def test_an_unusable_cache_builds_in_a_private_directory(tmp_path, monkeypatch):
    if not _native.enabled():
        return
    blocked = tmp_path / "file"
    blocked.write_text("a file where the cache directory would be")
    monkeypatch.setenv("MANOPT_LIE_CACHE", str(blocked / "cache"))
    monkeypatch.setattr(_native, "_LIBRARIES", {})
    native = _native.compile_functions([_function("private")])["private"]
    np.testing.assert_allclose(_run(native, np.zeros((1, 3)), np.ones((1, 2)))[0], 1.0)


@pytest.mark.parametrize("setting", [("MANOPT_LIE_NATIVE", "0"), ("CC", "/nonexistent/cc")])
def test_no_native_code_where_it_is_switched_off_or_no_compiler_is(cache, monkeypatch, setting):
    monkeypatch.setenv(*setting)
    assert not _native.enabled()
    assert _native.compile_functions([_function()]) is None


@pytest.mark.parametrize("group", [SE2, SE3], ids=lambda g: g.__name__)
def test_the_groups_native_kernels(group):
    """Every kind of :data:`NATIVE_KINDS` for SE(2)/SE(3) where a compiler is; none for other groups."""
    kernels = [_kernels.native_kernel(group, kind) for kind in _kernels.NATIVE_KINDS]
    assert all(k is not None for k in kernels) == _native.enabled()
    assert _kernels.native_kernel(SE2.rotation_group, "rplus") is None


def test_a_compiler_command_with_arguments(cache, monkeypatch):
    """``$CC`` is split as a shell would (``ccache gcc``, ``env cc``)."""
    monkeypatch.setenv("CC", "env cc")
    if not _native.enabled():
        assert _native.compile_functions([_function("wrapped")]) is None
        return
    native = _native.compile_functions([_function("wrapped")])["wrapped"]
    np.testing.assert_allclose(_run(native, np.zeros((1, 3)), np.ones((1, 2)))[0], 1.0)


def test_threads_evaluate_a_between_factor_at_once():
    """The drivers keep their workspace on the stack and ctypes releases the GIL: factors
    evaluated from several threads at once give what one thread gives."""
    from concurrent.futures import ThreadPoolExecutor

    from manopt_lie.factors import between_factor

    rng = np.random.default_rng(3)
    m = 2000
    xi, xj, z = SE3.random(rng, (m,)), SE3.random(rng, (m,)), SE3.random(rng, (m,))
    factor = between_factor(np.c_[np.arange(m), np.arange(m, 2 * m)], z)
    r, (j_i, j_j) = factor.residual(xi, xj, jac=True)
    with ThreadPoolExecutor(4) as pool:
        results = list(pool.map(lambda _: factor.residual(xi, xj, jac=True), range(16)))
    for r_t, (j_i_t, j_j_t) in results:
        np.testing.assert_array_equal(r_t, r)
        np.testing.assert_array_equal(j_i_t, j_i)
        np.testing.assert_array_equal(j_j_t, j_j)


def test_no_home_directory_builds_in_a_private_directory(monkeypatch):
    def no_home(cls: type) -> None:
        raise RuntimeError("Could not determine home directory.")  # what Path.home raises

    monkeypatch.delenv("MANOPT_LIE_CACHE", raising=False)
    monkeypatch.delenv("XDG_CACHE_HOME", raising=False)
    monkeypatch.setattr(_native.Path, "home", classmethod(no_home))
    monkeypatch.setattr(_native, "_LIBRARIES", {})
    assert _native.cache_dir() is None
    if not _native.enabled():
        return
    native = _native.compile_functions([_function("homeless")])["homeless"]
    np.testing.assert_allclose(_run(native, np.zeros((1, 3)), np.ones((1, 2)))[0], 1.0)


def test_kernel_paths_by_name():
    assert _kernels.path_settings("arrays") == {"USE_NATIVE": False, "VM_EDGES": 0, "VM_POINTS": 0}
    assert _kernels.path_settings("native")["USE_NATIVE"] is True
    with pytest.raises(ValueError, match="kernel path"):
        _kernels.path_settings("gpu")
