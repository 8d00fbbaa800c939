"""Scalar helpers for generated kernels (:mod:`csdf.backends.codegen`).

Each selection lives in its own small function instead of an inline ``a if c else b``:
Numba gives every inline conditional its own basic blocks, and a kernel with thousands of
them compiles slowly (and can exhaust Numba's recursion limit); LLVM inlines these calls
afterwards and turns them into vector selects. Semantics match :mod:`csdf.ops` and the
NumPy reference (NaN-propagating ``min``/``max``, ``step(0) = 1``, ``sign(0) = 0``).
"""

from __future__ import annotations

from numba import njit

_OPTS = dict(nogil=True, cache=True, error_model="numpy")


@njit(**_OPTS)
def min_(a, b):
    """``min`` that returns NaN when either operand is NaN (ties pick ``a``)."""
    m = a if a <= b else b
    return m if a == a else a


@njit(**_OPTS)
def max_(a, b):
    """``max`` that returns NaN when either operand is NaN (ties pick ``a``)."""
    m = a if a >= b else b
    return m if a == a else a


@njit(**_OPTS)
def sel_(c, a, b):
    """``a`` where ``c`` else ``b``."""
    return a if c else b


@njit(**_OPTS)
def step_(a, one, zero):
    """1 where ``a >= 0``, 0 where ``a < 0``, NaN for NaN."""
    return one if a >= 0 else (zero if a < 0 else a)


@njit(**_OPTS)
def sign_(a, one, zero):
    """-1, 0 or 1; NaN for NaN."""
    return one if a > 0 else (-one if a < 0 else a * zero)


@njit(**_OPTS)
def safe_div_(a, b, zero):
    """``a / b`` where ``b > 0``, else 0 (derivative factors at kinks)."""
    return a / b if b > 0 else zero
