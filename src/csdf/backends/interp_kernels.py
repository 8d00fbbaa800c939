"""Numba kernels of the ``'interp'`` backend: a block interpreter over the lowered tape.

Each kernel call evaluates points ``[start, stop)``. It keeps a per-call register file
``R`` of ``(n_rows, B)`` values (``B`` points per block) and, for derivatives, ``D`` of
``(n_rows, T, B)`` tangents. Every instruction is one tight loop over the block, which
LLVM vectorises; the opcode dispatch is paid once per block, not per point. Nothing of
size N is allocated: memory is the inputs, the outputs and a few kilobytes per thread.

Row layout (made by :mod:`csdf.backends.lowering`): rows 0-2 hold x, y, z of the block;
rows ``UNIFORM_BASE .. UNIFORM_BASE+U`` hold uniform values (parameters, constants and
the results of the parameter-only prefix, computed once per call); the rest are
registers.

Semantics are those of the op specification (:mod:`csdf.ops`): NaN propagation of
``min``/``max``, ``step(0) = 1``, ``mod`` as ``a - b*floor(a/b)``, and the derivative
rules. These kernels are compiled once for every program, so the rules are written out
here by hand, in the factored order of each :class:`csdf.ops.Derivative`; the tie rule
arrives as the flag :data:`~csdf.backends.lowering.FLAG_TIE_STRICT` (set by the lowering
from :func:`csdf.ops.tie_strict`). ``tests/test_ops.py`` checks every op, kinks and ties
included, against the specification, so values agree to rounding (the compiler may
contract multiply-adds).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .rows import FLAG_A_ZERO, FLAG_B_ZERO, FLAG_OUT_ZERO, FLAG_TIE_STRICT, UNIFORM_BASE

# opcodes (csdf.ops, checked by tests/test_ops.py); numba folds these module constants
# (and the imported ones) into the kernels
NEG, ABS, SQRT, SQUARE, SIN, COS, TAN, ASIN, ACOS, ATAN, EXP, LOG, FLOOR, STEP, SIGN = range(1, 16)
ADD, SUB, MUL, DIV, MIN, MAX, ATAN2, MOD = range(32, 40)

_OPTS = dict(nogil=True, cache=True, boundscheck=False, error_model="numpy")


@njit(**_OPTS)
def _load_block(R, pts, s, m, B):
    d = pts.shape[1]
    for j in range(m):
        R[0, j] = pts[s + j, 0]
        R[1, j] = pts[s + j, 1]
        R[2, j] = pts[s + j, 2] if d == 3 else 0.0
    for j in range(m, B):
        R[0, j] = 0.0
        R[1, j] = 0.0
        R[2, j] = 0.0


@njit(**_OPTS)
def _exec(op, R, ia, ib, O, io, B):
    """``O[io, :] = op(R[ia], R[ib])`` over one block (``O`` may be ``R``; rows may alias)."""
    if op == ADD:
        for j in range(B):
            O[io, j] = R[ia, j] + R[ib, j]
    elif op == SUB:
        for j in range(B):
            O[io, j] = R[ia, j] - R[ib, j]
    elif op == MUL:
        for j in range(B):
            O[io, j] = R[ia, j] * R[ib, j]
    elif op == SQUARE:
        for j in range(B):
            O[io, j] = R[ia, j] * R[ia, j]
    elif op == MIN:
        for j in range(B):
            a = R[ia, j]
            b = R[ib, j]
            r = a if a <= b else b
            O[io, j] = a + b if (a != a or b != b) else r
    elif op == MAX:
        for j in range(B):
            a = R[ia, j]
            b = R[ib, j]
            r = a if a >= b else b
            O[io, j] = a + b if (a != a or b != b) else r
    elif op == SQRT:
        for j in range(B):
            O[io, j] = np.sqrt(R[ia, j])
    elif op == ABS:
        for j in range(B):
            O[io, j] = abs(R[ia, j])
    elif op == NEG:
        for j in range(B):
            O[io, j] = -R[ia, j]
    elif op == DIV:
        for j in range(B):
            O[io, j] = R[ia, j] / R[ib, j]
    elif op == STEP:
        for j in range(B):
            a = R[ia, j]
            O[io, j] = a if a != a else (1.0 if a >= 0 else 0.0)
    elif op == SIGN:
        for j in range(B):
            a = R[ia, j]
            O[io, j] = a if a != a else (1.0 if a > 0 else (-1.0 if a < 0 else 0.0))
    elif op == FLOOR:
        for j in range(B):
            O[io, j] = np.floor(R[ia, j])
    elif op == MOD:
        for j in range(B):
            a = R[ia, j]
            b = R[ib, j]
            O[io, j] = a - b * np.floor(a / b)
    elif op == SIN:
        for j in range(B):
            O[io, j] = np.sin(R[ia, j])
    elif op == COS:
        for j in range(B):
            O[io, j] = np.cos(R[ia, j])
    elif op == ATAN2:
        for j in range(B):
            O[io, j] = np.arctan2(R[ia, j], R[ib, j])
    elif op == EXP:
        for j in range(B):
            O[io, j] = np.exp(R[ia, j])
    elif op == LOG:
        for j in range(B):
            O[io, j] = np.log(R[ia, j])
    elif op == TAN:
        for j in range(B):
            O[io, j] = np.tan(R[ia, j])
    elif op == ASIN:
        for j in range(B):
            O[io, j] = np.arcsin(R[ia, j])
    elif op == ACOS:
        for j in range(B):
            O[io, j] = np.arccos(R[ia, j])
    elif op == ATAN:
        for j in range(B):
            O[io, j] = np.arctan(R[ia, j])


@njit(**_OPTS)
def value_kernel(code, uvals, pts, out, start, stop, B, n_rows, out_row):
    """Distances of points ``[start, stop)`` into ``out``.

    Args:
        code: ``(K, 5)`` int32 lowered instructions (op, dst, a, b, flags).
        uvals: ``(U,)`` uniform row values (dtype of ``pts``).
        pts: ``(N, D)`` points; out: ``(N,)``.
    """
    R = np.zeros((n_rows, B), dtype=pts.dtype)
    for i in range(uvals.shape[0]):
        for j in range(B):
            R[UNIFORM_BASE + i, j] = uvals[i]
    K = code.shape[0]
    for s in range(start, stop, B):
        m = min(B, stop - s)
        _load_block(R, pts, s, m, B)
        for k in range(K):
            _exec(code[k, 0], R, code[k, 2], code[k, 3], R, code[k, 1], B)
        for j in range(m):
            out[s + j] = R[out_row, j]
        _nan_rows(R, out, s, m)


@njit(**_OPTS)
def _nan_rows(R, out, s, m):
    """NaN in, NaN out: a point with a NaN coordinate gets NaN (simplifications such as
    ``x * 0 -> 0`` could otherwise hide it)."""
    for j in range(m):
        if R[0, j] != R[0, j] or R[1, j] != R[1, j] or R[2, j] != R[2, j]:
            out[s + j] = np.nan


@njit(**_OPTS)
def _tangent(op, flags, R, ia, ib, V, D, d, t0, t1, B):
    """Tangents ``D[d, t0:t1]`` (columns ``t0 .. t1 - 1`` of ``T``, B points) of
    ``V[0] = op(R[ia], R[ib])`` from ``D[ia]``, ``D[ib]``; ``flags``:
    ``FLAG_B_ZERO``/``FLAG_A_ZERO``: ``b``'s/``a``'s tangent is zero, ``FLAG_OUT_ZERO``:
    the result's tangent is structurally zero, ``FLAG_TIE_STRICT``: ``min``/``max``
    take ``a``'s tangent only where ``a`` wins strictly. ``d`` may equal ``ia`` or
    ``ib``."""
    if flags & FLAG_OUT_ZERO:
        for t in range(t0, t1):
            for j in range(B):
                D[d, t, j] = 0.0
    elif op == ADD:
        if flags & FLAG_B_ZERO:
            for t in range(t0, t1):
                for j in range(B):
                    D[d, t, j] = D[ia, t, j]
        elif flags & FLAG_A_ZERO:
            for t in range(t0, t1):
                for j in range(B):
                    D[d, t, j] = D[ib, t, j]
        else:
            for t in range(t0, t1):
                for j in range(B):
                    D[d, t, j] = D[ia, t, j] + D[ib, t, j]
    elif op == SUB:
        if flags & FLAG_B_ZERO:
            for t in range(t0, t1):
                for j in range(B):
                    D[d, t, j] = D[ia, t, j]
        elif flags & FLAG_A_ZERO:
            for t in range(t0, t1):
                for j in range(B):
                    D[d, t, j] = -D[ib, t, j]
        else:
            for t in range(t0, t1):
                for j in range(B):
                    D[d, t, j] = D[ia, t, j] - D[ib, t, j]
    elif op == MUL:
        if flags & FLAG_B_ZERO:
            for t in range(t0, t1):
                for j in range(B):
                    D[d, t, j] = D[ia, t, j] * R[ib, j]
        elif flags & FLAG_A_ZERO:
            for t in range(t0, t1):
                for j in range(B):
                    D[d, t, j] = R[ia, j] * D[ib, t, j]
        else:
            for t in range(t0, t1):
                for j in range(B):
                    D[d, t, j] = D[ia, t, j] * R[ib, j] + R[ia, j] * D[ib, t, j]
    elif op == SQUARE:
        for t in range(t0, t1):
            for j in range(B):
                D[d, t, j] = 2.0 * R[ia, j] * D[ia, t, j]
    elif op == MIN or op == MAX:
        for j in range(B):
            a = R[ia, j]
            b = R[ib, j]
            if flags & FLAG_TIE_STRICT:  # (csdf.ops.tie_strict)
                pick_a = a < b if op == MIN else a > b
            else:
                pick_a = a <= b if op == MIN else a >= b
            if not pick_a:
                for t in range(t0, t1):
                    D[d, t, j] = D[ib, t, j]
            else:
                for t in range(t0, t1):
                    D[d, t, j] = D[ia, t, j]
    elif op == SQRT:
        for j in range(B):
            v = V[0, j]
            f = 0.5 / v if v > 0 else 0.0
            for t in range(t0, t1):
                D[d, t, j] = f * D[ia, t, j]
    elif op == ABS:
        for j in range(B):
            a = R[ia, j]
            f = 1.0 if a > 0 else (-1.0 if a < 0 else (0.0 if a == 0 else a))
            for t in range(t0, t1):
                D[d, t, j] = f * D[ia, t, j]
    elif op == NEG:
        for t in range(t0, t1):
            for j in range(B):
                D[d, t, j] = -D[ia, t, j]
    elif op == DIV:
        if flags & FLAG_B_ZERO:
            for j in range(B):
                f = 1.0 / R[ib, j]
                for t in range(t0, t1):
                    D[d, t, j] = f * D[ia, t, j]
        else:
            for j in range(B):
                f = 1.0 / R[ib, j]
                v = V[0, j]
                for t in range(t0, t1):
                    D[d, t, j] = f * (D[ia, t, j] - v * D[ib, t, j])
    elif op == STEP or op == SIGN or op == FLOOR:
        for t in range(t0, t1):
            for j in range(B):
                D[d, t, j] = 0.0
    elif op == MOD:
        if flags & FLAG_B_ZERO:
            for t in range(t0, t1):
                for j in range(B):
                    D[d, t, j] = D[ia, t, j]
        elif flags & FLAG_A_ZERO:
            for j in range(B):
                q = np.floor(R[ia, j] / R[ib, j])
                for t in range(t0, t1):
                    D[d, t, j] = -(q * D[ib, t, j])
        else:
            for j in range(B):
                q = np.floor(R[ia, j] / R[ib, j])
                for t in range(t0, t1):
                    D[d, t, j] = D[ia, t, j] - q * D[ib, t, j]
    elif op == ATAN2:
        for j in range(B):
            y = R[ia, j]
            x = R[ib, j]
            r2 = x * x + y * y
            fy = x / r2 if r2 > 0 else 0.0
            fx = -y / r2 if r2 > 0 else 0.0
            if flags & FLAG_B_ZERO:
                for t in range(t0, t1):
                    D[d, t, j] = fy * D[ia, t, j]
            elif flags & FLAG_A_ZERO:
                for t in range(t0, t1):
                    D[d, t, j] = fx * D[ib, t, j]
            else:
                for t in range(t0, t1):
                    D[d, t, j] = fy * D[ia, t, j] + fx * D[ib, t, j]
    else:
        for j in range(B):
            a = R[ia, j]
            v = V[0, j]
            if op == SIN:
                f = np.cos(a)
            elif op == COS:
                f = -np.sin(a)
            elif op == EXP:
                f = v
            elif op == LOG:
                f = 1.0 / a
            elif op == TAN:
                f = 1.0 + v * v
            elif op == ASIN:
                f = 1.0 / np.sqrt(1.0 - a * a)
            elif op == ACOS:
                f = -1.0 / np.sqrt(1.0 - a * a)
            else:  # ATAN
                f = 1.0 / (1.0 + a * a)
            for t in range(t0, t1):
                D[d, t, j] = f * D[ia, t, j]


@njit(**_OPTS)
def tangent_kernel(code, cols, uvals, utans, pts, out, grad, jac, start, stop, B, n_rows,
                   out_row, spatial, n_jac):
    """Values and forward-mode tangents of points ``[start, stop)``.

    Args:
        cols: ``(K, 4)`` per instruction the parameter tangent columns ``[lo, hi)`` it
            computes and ``[clo, chi)`` its destination held before, cleared outside
            ``[lo, hi)`` (:meth:`csdf.backends.lowering.Lowered.tangent_plan`: every
            row is zero outside its support); the spatial columns are always computed.
        utans: ``(U, T)`` tangents of the uniform rows.
        grad: ``(N, 3)`` written when ``spatial``; jac: ``(N, n_jac)``.
        spatial: whether tangents 0-2 are d/dx, d/dy, d/dz; the parameter tangents follow.
    """
    T = utans.shape[1]
    dt = pts.dtype
    R = np.zeros((n_rows, B), dtype=dt)
    D = np.zeros((n_rows, T, B), dtype=dt)
    tmp = np.zeros((1, B), dtype=dt)
    if spatial:
        for i in range(3):
            for j in range(B):
                D[i, i, j] = 1.0
    for i in range(uvals.shape[0]):
        for j in range(B):
            R[UNIFORM_BASE + i, j] = uvals[i]
        for t in range(T):
            for j in range(B):
                D[UNIFORM_BASE + i, t, j] = utans[i, t]
    K = code.shape[0]
    off = 3 if spatial else 0
    for s in range(start, stop, B):
        m = min(B, stop - s)
        _load_block(R, pts, s, m, B)
        for k in range(K):
            op = code[k, 0]
            d = code[k, 1]
            a = code[k, 2]
            b = code[k, 3]
            lo = cols[k, 0]
            hi = cols[k, 1]
            _exec(op, R, a, b, tmp, 0, B)
            if off > 0:
                _tangent(op, code[k, 4], R, a, b, tmp, D, d, 0, off, B)
            if lo < hi:
                _tangent(op, code[k, 4], R, a, b, tmp, D, d, lo, hi, B)
            # the destination's columns of its previous support outside the new one
            for t in range(cols[k, 2], min(cols[k, 3], lo)):
                for j in range(B):
                    D[d, t, j] = 0.0
            for t in range(max(cols[k, 2], hi), cols[k, 3]):
                for j in range(B):
                    D[d, t, j] = 0.0
            for j in range(B):
                R[d, j] = tmp[0, j]
        for j in range(m):
            out[s + j] = R[out_row, j]
        if spatial:
            for j in range(m):
                grad[s + j, 0] = D[out_row, 0, j]
                grad[s + j, 1] = D[out_row, 1, j]
                grad[s + j, 2] = D[out_row, 2, j]
        for c in range(n_jac):
            for j in range(m):
                jac[s + j, c] = D[out_row, off + c, j]
        for j in range(m):
            v = R[out_row, j]
            if R[0, j] != R[0, j] or R[1, j] != R[1, j] or R[2, j] != R[2, j] or v != v:
                out[s + j] = np.nan
                if spatial:
                    grad[s + j, 0] = np.nan
                    grad[s + j, 1] = np.nan
                    grad[s + j, 2] = np.nan
                for c in range(n_jac):
                    jac[s + j, c] = np.nan


@njit(**_OPTS)
def prefix_kernel(code, uvals, n_params, tangents, vals, tans):
    """Values and parameter tangents of the parameter-only prefix, for one parameter
    vector (the uniform rows of every kernel here).

    Args:
        code: ``(K, 5)`` int32 prefix instructions (op, dst, a, b, flags) on local rows:
            ``0 .. P-1`` the parameters, ``P .. U0-1`` the constants, ``U0 + k`` the
            result of instruction ``k`` (each its own row).
        uvals: ``(U0,)`` float64 parameter values, then the constants.
        n_params: ``P``.
        tangents: also the tangents (else ``tans`` is not written).
        vals: ``(K,)`` out: the results.
        tans: ``(K, P)`` out: their derivatives by the parameters.
    """
    n0 = uvals.shape[0]
    K = code.shape[0]
    R = np.empty((n0 + K, 1))
    for i in range(n0):
        R[i, 0] = uvals[i]
    T = n_params if tangents else 0
    D = np.zeros((n0 + K, max(T, 1), 1))
    for i in range(T):
        D[i, i, 0] = 1.0
    for k in range(K):
        op = code[k, 0]
        d = code[k, 1]
        _exec(op, R, code[k, 2], code[k, 3], R, d, 1)
        if tangents:
            _tangent(op, code[k, 4], R, code[k, 2], code[k, 3], R[d:d + 1], D, d, 0, T, 1)
    for k in range(K):
        vals[k] = R[n0 + k, 0]
        for t in range(T):
            tans[k, t] = D[n0 + k, t, 0]
