"""The ``'fast'`` backend: a Numba kernel generated for each program structure.

The kernel (see :mod:`csdf.backends.codegen`) runs the whole tape as straight-line code
over a block of points, vectorised across points, on every core. It is compiled the
first time a program structure is evaluated in a mode and cached twice: in memory, and
on disk (the generated source and Numba's compiled code) in ``$CSDF_CACHE_DIR``
(default ``~/.cache/csdf/kernels``), so a second process starts warm. Programs that
differ only in constants or parameter values share a kernel.

Before a cached source file is imported it is compared byte for byte with the source
generated now; a file that differs is rewritten, so nothing but csdf's own generated
code is ever loaded.

Large results are written to recycled memory (:mod:`csdf.memory`), which spares
a loop of evaluations the page faults of fresh memory.
"""

from __future__ import annotations

import importlib.util
import os
import sys
import tempfile
import threading
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ..cache import memo
from ..memory import result_array
from ..parallel import MIN_PER_THREAD, run_parallel
from .codegen import BLOCK, generate, structure_key
from .lowering import lowered, numba_available

__all__ = ["evaluate", "bound_evaluator", "serial_values", "available", "is_ready", "cache_dir",
           "kernel_mode"]

_MEM: dict[str, object] = {}
_LOCK = threading.Lock()


def available() -> bool:
    return numba_available()


def cache_dir() -> Path:
    """Where generated kernels are cached (created on demand)."""
    env = os.environ.get("CSDF_CACHE_DIR")
    if env:
        base = Path(env)
    else:
        xdg = os.environ.get("XDG_CACHE_HOME")
        base = (Path(xdg) if xdg else Path.home() / ".cache") / "csdf" / "kernels"
    try:
        base.mkdir(parents=True, exist_ok=True)
        probe = base / ".write-test"
        probe.write_text("ok")
        probe.unlink()
        return base
    except OSError:
        fallback = Path(tempfile.gettempdir()) / f"csdf-kernels-{os.getuid()}"
        fallback.mkdir(parents=True, exist_ok=True)
        return fallback


def kernel_mode(mode: str) -> str:
    """The generated kernel that serves an evaluation mode (``'jac'`` uses ``'all'``)."""
    return {"value": "value", "grad": "grad", "jac": "all", "all": "all"}[mode]


def is_ready(prog, mode: str) -> bool:
    """True when the kernel for this program and mode is in memory or on disk."""
    low = lowered(prog)
    key = structure_key(low, kernel_mode(mode))
    if key in _MEM:
        return True
    return (cache_dir() / f"k_{key}.py").exists()


def _kernel(low, kmode: str):
    key = structure_key(low, kmode)
    k = _MEM.get(key)
    if k is not None:
        return k
    with _LOCK:
        k = _MEM.get(key)
        if k is not None:
            return k
        src = generate(low, kmode)
        path = cache_dir() / f"k_{key}.py"
        try:
            current = path.read_text() if path.exists() else None
        except OSError:
            current = None
        if current != src:
            fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".k_", suffix=".py")
            with os.fdopen(fd, "w") as f:
                f.write(src)
            os.replace(tmp, path)
        name = f"csdf_kernel_{key}"
        spec = importlib.util.spec_from_file_location(name, path)
        module = importlib.util.module_from_spec(spec)  # type: ignore[arg-type]
        sys.modules[name] = module
        spec.loader.exec_module(module)  # type: ignore[union-attr]
        k = module.kernel
        _MEM[key] = k
        return k


_EXTRA = np.array([0.0, 1.0, 2.0, 0.5, np.nan])


def _prepare(prog, pvals: np.ndarray, mode: str, dtype):
    """``(kernel, u, du, spatial, wrt, nan)`` for one program, parameter values and
    mode (``nan``: a parameter value is NaN).

    ``u`` (uniform values ``(U + 5,)``) and ``du`` (their parameter derivatives
    ``(U, P)``, or ``(1, 1)`` zeros) are kept for the last few parameter vectors per
    program and mode (a fit evaluates the same ones many times); the kernels only read
    them, and callers must not write to them."""
    low = lowered(prog)
    kmode = kernel_mode(mode)
    kernel = _kernel(low, kmode)
    spatial = kmode != "value"
    wrt = kmode == "all"
    key = (np.asarray(pvals, dtype=np.float64).tobytes(), kmode, np.dtype(dtype).str)
    u, du, nan = memo(low, "_fast_uniform", key, lambda: _uniform_rows(low, pvals, wrt,
                                                                        dtype), 16)
    return kernel, u, du, spatial, wrt, nan


def _uniform_rows(low, pvals: np.ndarray, wrt: bool, dtype
                  ) -> tuple[np.ndarray, np.ndarray, bool]:
    """The kernels' uniform inputs ``(u, du)`` (see :func:`_prepare`; not to be
    written) and whether a parameter value is NaN (:meth:`Lowered.uniform_rows`,
    without the copies and flags of :meth:`Lowered.uniform`: a fit asks for new ones
    at every step)."""
    uvals, drows = low.uniform_rows(pvals, wrt)
    f64 = np.dtype(dtype) == np.float64
    with np.errstate(over="ignore"):  # values beyond float32 range become inf
        u = np.concatenate([uvals, _EXTRA])
        u = u if f64 else u.astype(dtype)
        if drows is not None and drows.shape[1]:
            du = drows if f64 else drows.astype(dtype)
        else:
            du = np.zeros((1, 1), dtype)
    return u, du, bool(np.isnan(uvals[:low.n_params]).any())


def evaluate(prog, pts: np.ndarray, pvals: np.ndarray, mode: str) -> dict[str, np.ndarray]:
    """Same contract as :func:`csdf.backends.numpy_backend.evaluate`."""
    kernel, u, du, spatial, wrt, nan = _prepare(prog, pvals, mode, pts.dtype)
    return _run_kernel(kernel, u, du, spatial, wrt, nan, pts, len(prog.params), mode)


def _run_kernel(kernel, u: np.ndarray, du: np.ndarray, spatial: bool, wrt: bool, nan: bool,
                pts: np.ndarray, P: int, mode: str) -> dict[str, np.ndarray]:
    """The results of :func:`evaluate` from a prepared kernel and its uniform inputs
    (:func:`_prepare`) on points ``pts`` (N, 3), C-contiguous."""
    dtype = pts.dtype
    n = pts.shape[0]
    out = result_array((n,), dtype)  # (recycled memory for large results: csdf.memory)
    grad = result_array((n, 3), dtype) if spatial else np.empty((0, 3), dtype)
    jac = result_array((n, P), dtype) if wrt else np.empty((0, P), dtype)
    if n and n < 2 * MIN_PER_THREAD:  # one range (run_parallel's), on this thread
        kernel(pts, u, du, out, grad, jac, 0, n)
    else:
        run_parallel(lambda r: kernel(pts, u, du, out, grad, jac, r[0], r[1]), n, BLOCK)
    res = {"value": out}
    if mode in ("grad", "all"):
        res["grad"] = grad
    if mode in ("jac", "all"):
        res["jac"] = jac
    if nan:
        for arr in res.values():
            arr[:] = np.nan
    return res


def bound_evaluator(prog, mode: str) -> Callable[[np.ndarray, np.ndarray],
                                                 dict[str, np.ndarray]]:
    """``f(pts, pvals)`` giving what ``evaluate(prog, pts, pvals, mode)`` gives, to the
    bit, with the kernel looked up once and the uniform inputs of the last parameter
    vector kept: for a solver that evaluates one program many times on float64 points
    ``pts`` (N, 3), C-contiguous, with parameter vectors ``pvals`` (P,) float64 (a
    fit's steps, microseconds apart)."""
    low = lowered(prog)
    kmode = kernel_mode(mode)
    kernel = _kernel(low, kmode)
    spatial = kmode != "value"
    wrt = kmode == "all"
    P = len(prog.params)
    last: list = [None, None]

    def f(pts: np.ndarray, pvals: np.ndarray) -> dict[str, np.ndarray]:
        key = pvals.tobytes()
        if key != last[0]:
            last[1] = _uniform_rows(low, pvals, wrt, np.float64)
            last[0] = key
        u, du, nan = last[1]
        return _run_kernel(kernel, u, du, spatial, wrt, nan, pts, P, mode)

    return f


def serial_values(prog, pvals: np.ndarray) -> Callable[..., np.ndarray]:
    """Field values on the calling thread, bound to parameter values: the returned
    ``f(pts (M, 3) float64, C-contiguous, out=None) -> (M,) float64`` gives what
    ``evaluate(prog, pts, pvals, 'value')`` gives, with no per-call preparation and no
    thread hand-off, written into ``out (>= M,)`` when given. For callers that run many
    small evaluations on threads of their own (the streaming mesher)."""
    kernel, u, du, _, _, nan = _prepare(prog, pvals, "value", np.float64)
    empty2 = np.empty((0, 3))

    def f(pts: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        out = np.empty(pts.shape[0]) if out is None else out[:pts.shape[0]]
        if nan:
            out[:] = np.nan
        else:
            kernel(pts, u, du, out, empty2, empty2, 0, pts.shape[0])
        return out

    return f
