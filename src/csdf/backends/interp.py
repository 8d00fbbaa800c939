"""The ``'interp'`` backend: the tape interpreted by Numba kernels over blocks of points
(``interp_kernels.py``), multithreaded. The kernels are compiled once (cached on disk),
so a new program costs no compilation; ``'fast'`` is quicker per point."""

from __future__ import annotations

import numpy as np

from ..parallel import run_parallel
from .lowering import lowered, numba_available

__all__ = ["evaluate", "available", "warm"]

_kernels = None


def available() -> bool:
    return numba_available()


def _k():
    global _kernels
    if _kernels is None:
        from . import interp_kernels

        _kernels = interp_kernels
    return _kernels


def warm() -> bool:
    """True once the kernels module has been loaded in this process."""
    return _kernels is not None


def _block_size(n_rows: int, T: int, itemsize: int, budget: int = 32 * 1024,
                most: int = 256) -> int:
    """Points per block: the most, a power of two from 16 to ``most``, whose registers
    and ``T`` tangents fit ``budget`` bytes (16 at least; the default keeps one block's
    register file in L1). Each point is computed alike whatever the block."""
    per_point = n_rows * (1 + T) * itemsize
    B = 16
    while B < most and (2 * B) * per_point <= budget:
        B *= 2
    return B


#: the most memory (bytes) one block's registers and tangents take in the derivative
#: kernel: with each instruction's tangents on its own parameters' columns only
#: (:meth:`csdf.backends.lowering.Lowered.tangent_plan`) an instruction touches a few
#: of them, and longer blocks pay the dispatch less often (a three-leaf refinement's
#: Jacobian, 103 rows and 23 parameters: 64 points a block, 1.4x the speed of 16)
TANGENT_BLOCK_BYTES = 2 << 20
#: the most points a block of the derivative kernel holds
TANGENT_BLOCK_MOST = 128


def evaluate(prog, pts: np.ndarray, pvals: np.ndarray, mode: str) -> dict[str, np.ndarray]:
    """Same contract as :func:`csdf.backends.numpy_backend.evaluate`."""
    K = _k()
    low = lowered(prog)
    dtype = pts.dtype
    n = pts.shape[0]
    P = len(prog.params)
    spatial = mode in ("grad", "all")
    wrt_params = mode in ("jac", "all")
    T = (3 if spatial else 0) + (P if wrt_params else 0)
    res: dict[str, np.ndarray] = {"value": np.empty(n, dtype)}
    uvals, utans, zero_uniform = low.uniform(pvals, dtype, spatial, wrt_params)
    if mode == "value":
        B = _block_size(low.n_rows, 0, dtype.itemsize)

        def job(r):
            K.value_kernel(low.code, uvals, pts, res["value"], r[0], r[1], B, low.n_rows,
                           low.out_row)
    else:
        grad = np.empty((n, 3), dtype) if spatial else np.empty((0, 3), dtype)
        jac = np.empty((n, P), dtype) if wrt_params else np.empty((0, 0), dtype)
        if spatial:
            res["grad"] = grad
        if wrt_params:
            res["jac"] = jac
        B = _block_size(low.n_rows, T, dtype.itemsize, TANGENT_BLOCK_BYTES,
                        TANGENT_BLOCK_MOST)
        n_jac = P if wrt_params else 0
        if T == 0:  # no parameters: the Jacobian is empty
            utans = np.zeros((utans.shape[0], 0), dtype)
        # each instruction's tangents on the parameter columns it may touch
        code, cols = low.tangent_plan(utans, zero_uniform, 3 if spatial else 0)

        def job(r):
            K.tangent_kernel(code, cols, uvals, utans, pts, res["value"], grad, jac, r[0],
                             r[1], B, low.n_rows, low.out_row, spatial, n_jac)

    run_parallel(job, n, B)
    if np.isnan(pvals).any():  # NaN points are handled inside the kernels
        for arr in res.values():
            arr[:] = np.nan
    return res
