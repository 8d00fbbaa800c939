"""Numba kernels of region-pruned evaluation: interval arithmetic, tape simplification
and lane evaluation of *register tapes*, compiled once for all programs.

A register tape (made by :mod:`csdf.backends.pruned` from a program at fixed parameter
values) is a run of rows of an ``(n, 5)`` int32 array ``code`` (``op, dst, a, b,
flags``, as the ``'interp'`` kernels read) and an ``(n,)`` float64 array ``imm``.
Registers 0-2 hold x, y, z; :data:`CONST` instructions load ``imm`` into their
register (parameters, constants and the parameter-only prefix become such loads);
every other opcode is an op of :mod:`csdf.ops` with the ``'interp'`` backend's
semantics (its own ``_exec`` and ``_tangent`` run here, so the values are bit-identical
to that backend's). A tape is ``(start, length, out, n_regs)``: its rows in a pool, the
register holding the result and the registers it uses.

:func:`simplify_tape` runs a tape's intervals over one box (the rules of
:mod:`csdf.interval`, written here for scalars; ``tests/test_pruned.py`` checks them
against that module), replaces each ``min``/``max`` whose operand intervals do not
overlap by the winner (only when the loser is never NaN there), drops ``abs`` of a
positive operand, turns ``step``/``sign`` of a known sign into constants, removes
dead instructions and reallocates registers (linear scan).
Inside the box the shortened tape computes the same float64 values, bit for bit, and
the same gradients. The level kernels run it for many tiles or cells at once, in
parallel; the lane kernels evaluate points with the tapes of their cells. The kernels
are serial (each does ``part`` of ``n_parts`` of a job) and release the GIL; the
callers run the parts on csdf's worker threads.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .interp_kernels import (
    ABS,
    ACOS,
    ADD,
    ASIN,
    ATAN,
    ATAN2,
    COS,
    DIV,
    EXP,
    FLOOR,
    LOG,
    MAX,
    MIN,
    MOD,
    MUL,
    NEG,
    SIGN,
    SIN,
    SQRT,
    SQUARE,
    STEP,
    SUB,
    TAN,
    _exec,
    _tangent,
)

#: the opcode of a register load of ``imm`` (0 is no op of csdf.ops)
CONST = 0

_OPTS = dict(nogil=True, cache=True, boundscheck=False, error_model="numpy")

# The 'interp' kernels' op code, inlined into the lane loops below: short tapes run on
# a few lanes (a tracer's points rarely share a cell), where the call into the op
# switch cost as much as the op (measured: 4.6 -> 2.6 ns per instruction on one lane,
# 205-instruction tape). The same code, so the values stay bit-identical.
_exec_inline = njit(inline="always", **_OPTS)(_exec.py_func)
_tangent_inline = njit(inline="always", **_OPTS)(_tangent.py_func)

_K = 2.0**-48
_TINY = 2.0**-1060
_INF = math.inf
_NAN = math.nan
_PI = math.pi
_TWO_PI = 2.0 * math.pi
_HALF_PI = 0.5 * math.pi
_MARGIN = 1e-12
_MOD_ERR = 2.0**-48
_MOD_SAFE = 1e300
#: a thread's part of a job is every ``n_parts``-th run of this many items
_BLOCK = 1


# ------------------------------------------------------------------ scalar helpers
@njit(**_OPTS)
def _mn(a, b):
    """np.minimum: NaN if either is NaN."""
    if a != a or b != b:
        return _NAN
    return a if a <= b else b


@njit(**_OPTS)
def _mx(a, b):
    """np.maximum: NaN if either is NaN."""
    if a != a or b != b:
        return _NAN
    return a if a >= b else b


@njit(**_OPTS)
def _fmn(a, b):
    """np.fmin: the other operand where one is NaN."""
    if a != a:
        return b
    if b != b:
        return a
    return a if a <= b else b


@njit(**_OPTS)
def _fmx(a, b):
    """np.fmax: the other operand where one is NaN."""
    if a != a:
        return b
    if b != b:
        return a
    return a if a >= b else b


@njit(**_OPTS)
def _widen(lo, hi):
    lo = lo * ((1.0 - _K) if lo > 0 else (1.0 + _K)) - _TINY
    hi = hi * ((1.0 + _K) if hi > 0 else (1.0 - _K)) + _TINY
    return lo, hi


@njit(**_OPTS)
def _hits(wlo, whi, phase, period):
    return np.floor((whi - phase) / period) >= np.ceil((wlo - phase) / period)


@njit(**_OPTS)
def _periodic(alo, ahi, is_sin):
    wlo = alo - (abs(alo) * _MARGIN + _MARGIN)
    whi = ahi + (abs(ahi) * _MARGIN + _MARGIN)
    if is_sin:
        has_max = _hits(wlo, whi, _HALF_PI, _TWO_PI)
        has_min = _hits(wlo, whi, -_HALF_PI, _TWO_PI)
        v_lo, v_hi = np.sin(alo), np.sin(ahi)
    else:
        has_max = _hits(wlo, whi, 0.0, _TWO_PI)
        has_min = _hits(wlo, whi, _PI, _TWO_PI)
        v_lo, v_hi = np.cos(alo), np.cos(ahi)
    lo = -1.0 if has_min else _mn(v_lo, v_hi)
    hi = 1.0 if has_max else _mx(v_lo, v_hi)
    return _widen(lo, hi)


@njit(**_OPTS)
def _corners_mul(alo, ahi, blo, bhi):
    c1, c2, c3, c4 = alo * blo, alo * bhi, ahi * blo, ahi * bhi
    lo = _fmn(_fmn(c1, c2), _fmn(c3, c4))
    hi = _fmx(_fmx(c1, c2), _fmx(c3, c4))
    if lo != lo and not (alo != alo or blo != blo):
        return 0.0, 0.0
    return lo, hi


@njit(**_OPTS)
def _corners_div(alo, ahi, blo, bhi):
    c1, c2, c3, c4 = alo / blo, alo / bhi, ahi / blo, ahi / bhi
    lo = _fmn(_fmn(c1, c2), _fmn(c3, c4))
    hi = _fmx(_fmx(c1, c2), _fmx(c3, c4))
    if lo != lo and not (alo != alo or blo != blo):
        lo, hi = 0.0, 0.0
    if blo <= 0.0 and bhi >= 0.0:
        return -_INF, _INF
    return lo, hi


@njit(**_OPTS)
def _atan2_rule(alo, ahi, blo, bhi):
    c1, c2 = np.arctan2(alo, blo), np.arctan2(alo, bhi)
    c3, c4 = np.arctan2(ahi, blo), np.arctan2(ahi, bhi)
    lo = _fmn(_fmn(c1, c2), _fmn(c3, c4))
    hi = _fmx(_fmx(c1, c2), _fmx(c3, c4))
    if not (blo > 0.0 or alo > 0.0 or ahi < 0.0):
        nan0 = np.arctan2(alo, blo) * 0.0
        lo, hi = nan0 - _PI, nan0 + _PI
    return _widen(lo, hi)


@njit(**_OPTS)
def _mod_rule(alo, ahi, blo, bhi):
    neg = bhi < 0.0
    a_lo, a_hi = (-ahi, -alo) if neg else (alo, ahi)
    b_lo, b_hi = (-bhi, -blo) if neg else (blo, bhi)
    a_mag = _mx(abs(a_lo), abs(a_hi))
    safe = (b_lo > 0.0) and (a_mag < _MOD_SAFE) and (b_hi < _MOD_SAFE) and (
        a_mag < _MOD_SAFE * b_lo)
    err = (a_mag + b_hi) * _MOD_ERR + _TINY
    q_lo, q_hi = np.floor(a_lo / b_lo), np.floor(a_hi / b_lo)
    single = (b_lo == b_hi) and (q_lo == q_hi)
    r_lo, r_hi = _widen(a_lo - b_lo * q_lo, a_hi - b_lo * q_hi)
    if safe:
        lo, hi = (r_lo, r_hi) if single else (-err, b_hi + err)
    else:
        lo, hi = -_INF, _INF
    if neg:
        return -hi, -lo
    return lo, hi


@njit(**_OPTS)
def _step_v(a):
    if a != a:
        return a
    return 1.0 if a >= 0 else 0.0


@njit(**_OPTS)
def _sign_v(a):
    if a != a:
        return a
    return 1.0 if a > 0 else (-1.0 if a < 0 else 0.0)


@njit(**_OPTS)
def interval(op, alo, ahi, blo, bhi, same):
    """The interval of ``op`` over operand intervals (``same``: both operands are one
    value, as :data:`csdf.interval.SAME_OPERAND_RULES`)."""
    if op == ADD:
        lo, hi = alo + blo, ahi + bhi
        return _fmn(lo, hi), _fmx(hi, lo)
    if op == SUB:
        if same:
            z = _NAN if alo != alo else 0.0
            return z, z
        lo, hi = alo - bhi, ahi - blo
        return _fmn(lo, hi), _fmx(hi, lo)
    if op == MUL or op == SQUARE:
        if same or op == SQUARE:
            lo = _mx(_mx(alo, -ahi), 0.0)
            hi = _mx(-alo, ahi)
            return lo * lo, hi * hi
        return _corners_mul(alo, ahi, blo, bhi)
    if op == MIN:
        if same:
            return alo, ahi
        return _mn(alo, blo), _mn(ahi, bhi)
    if op == MAX:
        if same:
            return alo, ahi
        return _mx(alo, blo), _mx(ahi, bhi)
    if op == NEG:
        return -ahi, -alo
    if op == ABS:
        return _mx(_mx(alo, -ahi), 0.0), _mx(-alo, ahi)
    if op == SQRT:
        return np.sqrt(_mn(_mx(alo, 0.0), ahi)), np.sqrt(ahi)
    if op == DIV:
        if same:
            one = _NAN if alo != alo else 1.0
            return one, one
        return _corners_div(alo, ahi, blo, bhi)
    if op == MOD:
        if same:
            z = _NAN if alo != alo else 0.0
            return z, z
        return _mod_rule(alo, ahi, blo, bhi)
    if op == FLOOR:
        return np.floor(alo), np.floor(ahi)
    if op == STEP:
        return _step_v(alo), _step_v(ahi)
    if op == SIGN:
        return _sign_v(alo), _sign_v(ahi)
    if op == SIN:
        return _periodic(alo, ahi, True)
    if op == COS:
        return _periodic(alo, ahi, False)
    if op == EXP:
        lo, hi = _widen(np.exp(alo), np.exp(ahi))
        return _mx(lo, 0.0), hi
    if op == LOG:
        return _widen(np.log(_mn(_mx(alo, 0.0), ahi)), np.log(ahi))
    if op == ATAN:
        return _widen(np.arctan(alo), np.arctan(ahi))
    if op == ASIN or op == ACOS:
        clo = _mn(_mx(alo, -1.0), ahi)
        chi = _mx(_mn(ahi, 1.0), alo)
        if op == ASIN:
            return _widen(np.arcsin(clo), np.arcsin(chi))
        lo, hi = _widen(np.arccos(chi), np.arccos(clo))
        return _mx(lo, 0.0), hi
    if op == TAN:
        wlo = alo - (abs(alo) * _MARGIN + _MARGIN)
        whi = ahi + (abs(ahi) * _MARGIN + _MARGIN)
        if _hits(wlo, whi, _HALF_PI, _PI):
            return -_INF, _INF
        return _widen(np.tan(alo), np.tan(ahi))
    if op == ATAN2:
        return _atan2_rule(alo, ahi, blo, bhi)
    return -_INF, _INF


@njit(**_OPTS)
def _has_inf(lo, hi):
    return lo == -_INF or hi == _INF


@njit(**_OPTS)
def _has_zero(lo, hi):
    return lo <= 0.0 <= hi


@njit(**_OPTS)
def makes_nan(op, alo, ahi, blo, bhi):
    """Can ``op`` give NaN for non-NaN operands in these intervals? (conservative, as
    :func:`csdf.compiler.simplify._makes_nan`)"""
    if op == SQRT or op == LOG:
        return alo < 0.0
    if op == ASIN or op == ACOS:
        return alo < -1.0 or ahi > 1.0
    if op == SIN or op == COS or op == TAN:
        return _has_inf(alo, ahi)
    if op == ADD:
        return (ahi == _INF and blo == -_INF) or (alo == -_INF and bhi == _INF)
    if op == SUB:
        return (ahi == _INF and bhi == _INF) or (alo == -_INF and blo == -_INF)
    if op == MUL:
        return (_has_zero(alo, ahi) and _has_inf(blo, bhi)) or (
            _has_zero(blo, bhi) and _has_inf(alo, ahi))
    if op == DIV:
        return (_has_zero(alo, ahi) and _has_zero(blo, bhi)) or (
            _has_inf(alo, ahi) and _has_inf(blo, bhi))
    if op == MOD:
        return _has_zero(blo, bhi) or _has_inf(alo, ahi) or _has_inf(blo, bhi)
    return False


# ------------------------------------------------------------------ simplification
@njit(**_OPTS)
def simplify_tape(code, imm, start, K, out_reg, n_regs, blo, bhi, ocode, oimm, ostart,
                  emit, fs, ws):
    """Shorten the tape ``code[start:start+K]`` for the box ``[blo, bhi]`` (``(3,)``).

    Writes the shortened tape to ``ocode[ostart:]``/``oimm[ostart:]`` (at most ``K``
    rows) when ``emit`` is 1, or 2 and the output's interval holds values of both signs
    (``< 0`` and ``>= 0``); otherwise (0) computes only the intervals.

    ``fs`` (``(3, C)`` float64) and ``ws`` (``(10, C)`` int64) are scratch, ``C >=
    max(3 + K, n_regs)``.

    Returns:
        ``(n, out, n_regs, lo, hi)``: rows written, output register and registers of
        the new tape, and the interval of the output over the box.
    """
    n_ids = 3 + K
    lo = fs[0]
    hi = fs[1]
    newimm = fs[2]
    alias = ws[0]
    sa = ws[1]
    sb = ws[2]
    newop = ws[3]
    cur = ws[4]
    last = ws[5]
    reg = ws[6]
    free = ws[7]
    nan = ws[8]
    live = ws[9]
    nan[:3] = 0
    for i in range(3):
        lo[i] = blo[i]
        hi[i] = bhi[i]
        alias[i] = i
        cur[i] = i
    for k in range(K):
        row = start + k
        op = code[row, 0]
        d = code[row, 1]
        me = 3 + k
        newop[k] = op
        newimm[k] = imm[row]
        alias[me] = me
        if op == CONST:
            v = imm[row]
            lo[me] = v
            hi[me] = v
            nan[me] = 1 if v != v else 0
            cur[d] = me
            sa[k] = -1
            sb[k] = -1
            continue
        binary = op >= 32
        A = cur[code[row, 2]]
        B = cur[code[row, 3]] if binary else A
        sa[k] = A
        sb[k] = B
        alo, ahi, blo_, bhi_ = lo[A], hi[A], lo[B], hi[B]
        rl, rh = interval(op, alo, ahi, blo_, bhi_, binary and A == B)
        nan_in = nan[A] != 0 or (binary and nan[B] != 0)
        res = me
        if op == MIN:
            if ahi < blo_ and nan[B] == 0:
                res = A
            elif bhi_ < alo and nan[A] == 0:
                res = B
        elif op == MAX:
            if alo > bhi_ and nan[B] == 0:
                res = A
            elif blo_ > ahi and nan[A] == 0:
                res = B
        elif op == ABS:
            if alo > 0.0:
                res = A
        elif (op == STEP or op == SIGN) and not nan_in:
            if alo > 0.0 or (op == STEP and alo >= 0.0):
                newop[k] = CONST
                newimm[k] = 1.0
            elif ahi < 0.0:
                newop[k] = CONST
                newimm[k] = 0.0 if op == STEP else -1.0
        if res == me:
            if newop[k] == CONST:
                lo[me] = newimm[k]
                hi[me] = newimm[k]
                nan[me] = 0
            else:
                lo[me] = rl
                hi[me] = rh
                nan[me] = 1 if (nan_in or rl != rl or makes_nan(op, alo, ahi, blo_, bhi_)) else 0
        alias[me] = res
        cur[d] = res
    out_id = cur[out_reg]
    if emit == 0 or (emit == 2 and (hi[out_id] < 0.0 or lo[out_id] >= 0.0)):
        return 0, out_reg, n_regs, lo[out_id], hi[out_id]
    # liveness and last uses, from the output back
    live[:n_ids] = 0
    last[:n_ids] = -1
    live[out_id] = 1
    for k in range(K - 1, -1, -1):
        me = 3 + k
        if live[me] == 0 or newop[k] == CONST:
            continue
        A = sa[k]
        live[A] = 1
        if last[A] < 0:
            last[A] = k
        if newop[k] >= 32:
            B = sb[k]
            live[B] = 1
            if last[B] < 0:
                last[B] = k
    # registers: linear scan, lowest free first (a small stack of free registers)
    for i in range(3):
        reg[i] = i
    n_free = 0
    n_next = 3
    n = 0
    for k in range(K):
        me = 3 + k
        if live[me] == 0:
            continue
        op = newop[k]
        ra = 0
        rb = 0
        if op != CONST:
            A = sa[k]
            ra = reg[A]
            binary = op >= 32
            if binary:
                rb = reg[sb[k]]
            if A >= 3 and last[A] == k and A != out_id:
                free[n_free] = ra
                n_free += 1
            if binary:
                B = sb[k]
                if B != A and B >= 3 and last[B] == k and B != out_id:
                    free[n_free] = rb
                    n_free += 1
        if n_free > 0:  # the register freed last (any free one keeps the count minimal)
            n_free -= 1
            r = free[n_free]
        else:
            r = n_next
            n_next += 1
        reg[me] = r
        row = ostart + n
        ocode[row, 0] = op
        ocode[row, 1] = r
        ocode[row, 2] = ra
        ocode[row, 3] = rb
        ocode[row, 4] = code[start + k, 4]
        oimm[row] = newimm[k]
        n += 1
    return n, reg[out_id], n_next, lo[out_id], hi[out_id]


@njit(**_OPTS)
def simplify_many(code, imm, t_start, t_len, t_out, t_regs, parent, blo, bhi, ocode, oimm,
                  ostart, emit, r_len, r_out, r_regs, r_lo, r_hi, part, n_parts):
    """:func:`simplify_tape` for many boxes: box ``i``
    (``blo[i]``, ``bhi[i]``, ``(M, 3)``) shortens tape ``parent[i]`` (tapes are
    ``t_start, t_len, t_out, t_regs`` rows of a pool ``code``/``imm``) into
    ``ocode[ostart[i]:]``; results go to ``r_len, r_out, r_regs`` and the output
    interval to ``r_lo, r_hi`` (all ``(M,)``). Only the boxes ``i = part (mod n_parts)`` are
    done (one part per thread)."""
    M = blo.shape[0]
    cap = 4
    for b0 in range(part * _BLOCK, M, n_parts * _BLOCK):
        for i in range(b0, min(b0 + _BLOCK, M)):
            cap = max(cap, 3 + t_len[parent[i]], t_regs[parent[i]])
    fs = np.empty((3, cap))
    ws = np.empty((10, cap), dtype=np.int64)
    for b0 in range(part * _BLOCK, M, n_parts * _BLOCK):
        for i in range(b0, min(b0 + _BLOCK, M)):
            p = parent[i]
            n, o, nr, lo, hi = simplify_tape(code, imm, t_start[p], t_len[p], t_out[p],
                                             t_regs[p], blo[i], bhi[i], ocode, oimm,
                                             ostart[i], emit, fs, ws)
            r_len[i] = n
            r_out[i] = o
            r_regs[i] = nr
            r_lo[i] = lo
            r_hi[i] = hi


# ------------------------------------------------------------------ lanes
@njit(**_OPTS)
def run_lanes(code, imm, start, K, R, B):
    """Run tape rows ``[start, start+K)`` over ``B`` lanes of the register file
    ``R`` (``(n_regs, B)``; rows 0-2 hold the lanes' x, y, z)."""
    for k in range(K):
        row = start + k
        op = code[row, 0]
        if op == CONST:
            v = imm[row]
            d = code[row, 1]
            for j in range(B):
                R[d, j] = v
        else:
            _exec_inline(op, R, code[row, 2], code[row, 3], R, code[row, 1], B)


@njit(**_OPTS)
def run_lanes_grad(code, imm, start, K, R, D, tmp, B):
    """Values and spatial tangents (``D``: ``(n_regs, 3, B)``, rows 0-2 seeded with the
    identity) of tape rows ``[start, start+K)`` over ``B`` lanes."""
    for k in range(K):
        row = start + k
        op = code[row, 0]
        d = code[row, 1]
        if op == CONST:
            v = imm[row]
            for j in range(B):
                R[d, j] = v
            for t in range(3):
                for j in range(B):
                    D[d, t, j] = 0.0
        else:
            a = code[row, 2]
            b = code[row, 3]
            _exec_inline(op, R, a, b, tmp, 0, B)
            _tangent_inline(op, code[row, 4], R, a, b, tmp, D, d, 0, 3, B)
            for j in range(B):
                R[d, j] = tmp[0, j]


# ------------------------------------------------------------------ rasters (2D)
@njit(**_OPTS)
def raster_level(code, imm, p_start, p_len, p_out, p_regs, tiles, parent, xs, ys, img,
                 as_bool, leaf, ocode, oimm, ostart, r_len, r_out, r_regs, split, part,
                 n_parts):
    """One level of a raster's quadtree (:func:`csdf.backends.pruned.raster_image`):
    tile ``i`` (``tiles[i] = (r0, r1, c0, c1)``, pixels ``xs[c0:c1]`` by ``ys[r0:r1]``)
    shortens tape ``parent[i]`` (tapes ``p_start, p_len, p_out, p_regs`` of
    ``code``/``imm``) for its box into ``ocode[ostart[i]:]`` (results ``r_len, r_out,
    r_regs``); then, with ``as_bool``, a tile whose interval has one sign is filled;
    else a tile of at most ``leaf x leaf`` pixels is evaluated into ``img`` (values,
    or ``value < 0`` when ``as_bool``); else ``split[i] = 1``. Only the tiles ``i =
    part (mod n_parts)`` are done (one part per thread)."""
    M = tiles.shape[0]
    cap = 4
    for b0 in range(part * _BLOCK, M, n_parts * _BLOCK):
        for i in range(b0, min(b0 + _BLOCK, M)):
            cap = max(cap, 3 + p_len[parent[i]], p_regs[parent[i]])
    fs = np.empty((3, cap))
    ws = np.empty((10, cap), dtype=np.int64)
    R = np.empty((cap, leaf * leaf))
    blo = np.zeros(3)
    bhi = np.zeros(3)
    for b0 in range(part * _BLOCK, M, n_parts * _BLOCK):
        for i in range(b0, min(b0 + _BLOCK, M)):
            r0, r1, c0, c1 = tiles[i, 0], tiles[i, 1], tiles[i, 2], tiles[i, 3]
            p = parent[i]
            blo[0] = xs[c0]
            blo[1] = ys[r1 - 1]
            bhi[0] = xs[c1 - 1]
            bhi[1] = ys[r0]
            n, o, nr, lo, hi = simplify_tape(code, imm, p_start[p], p_len[p], p_out[p],
                                             p_regs[p], blo, bhi, ocode, oimm, ostart[i],
                                             2 if as_bool else 1, fs, ws)
            r_len[i] = n
            r_out[i] = o
            r_regs[i] = nr
            split[i] = 0
            if as_bool and (hi < 0.0 or lo >= 0.0):
                inside = hi < 0.0
                for r in range(r0, r1):
                    for cc in range(c0, c1):
                        img[r, cc] = inside
            elif r1 - r0 <= leaf and c1 - c0 <= leaf:
                w = c1 - c0
                m = (r1 - r0) * w
                for j in range(m):
                    R[0, j] = xs[c0 + j % w]
                    R[1, j] = ys[r0 + j // w]
                    R[2, j] = 0.0
                run_lanes(ocode, oimm, ostart[i], n, R, m)
                for j in range(m):
                    v = R[o, j]
                    if as_bool:
                        img[r0 + j // w, c0 + j % w] = v < 0.0
                    else:
                        img[r0 + j // w, c0 + j % w] = v
            else:
                split[i] = 1


# ------------------------------------------------------------------ point queries
@njit(**_OPTS)
def eval_cells(code, imm, t_start, t_len, t_out, t_regs, cell_tape, order, bounds, pts,
               out, grad, want_grad, lanes, part, n_parts):
    """Evaluate points grouped by cell: the points ``order[bounds[c]:bounds[c+1]]`` of
    ``pts`` (``(N, 3)``) run tape ``cell_tape[c]``, ``lanes`` at a time, into ``out``
    (``(N,)``) and, when ``want_grad``, ``grad`` (``(N, 3)``). Only the cells ``c =
    part (mod n_parts)`` are done (one part per thread)."""
    C = cell_tape.shape[0]
    # one register file for this part's cells (allocating per cell costs more than
    # running a short tape on a few points)
    n_rows = 3
    for b0 in range(part * _BLOCK, C, n_parts * _BLOCK):
        for c in range(b0, min(b0 + _BLOCK, C)):
            if bounds[c + 1] > bounds[c]:
                n_rows = max(n_rows, t_regs[cell_tape[c]])
    R = np.empty((n_rows, lanes))
    D = np.empty((n_rows if want_grad else 1, 3, lanes))
    tmp = np.empty((1, lanes))
    for b0 in range(part * _BLOCK, C, n_parts * _BLOCK):
        for c in range(b0, min(b0 + _BLOCK, C)):
            t = cell_tape[c]
            s0 = bounds[c]
            s1 = bounds[c + 1]
            if s1 <= s0:
                continue
            o = t_out[t]
            for s in range(s0, s1, lanes):
                m = min(lanes, s1 - s)
                for j in range(m):
                    p = order[s + j]
                    R[0, j] = pts[p, 0]
                    R[1, j] = pts[p, 1]
                    R[2, j] = pts[p, 2]
                if want_grad:
                    for r in range(3):
                        for t3 in range(3):
                            for j in range(m):
                                D[r, t3, j] = 1.0 if r == t3 else 0.0
                    run_lanes_grad(code, imm, t_start[t], t_len[t], R, D, tmp, m)
                else:
                    run_lanes(code, imm, t_start[t], t_len[t], R, m)
                for j in range(m):
                    p = order[s + j]
                    v = R[o, j]
                    out[p] = v
                    if want_grad:
                        if v != v:
                            grad[p, 0] = np.nan
                            grad[p, 1] = np.nan
                            grad[p, 2] = np.nan
                        else:
                            grad[p, 0] = D[o, 0, j]
                            grad[p, 1] = D[o, 1, j]
                            grad[p, 2] = D[o, 2, j]


@njit(**_OPTS)
def compact_cells(ids, stamp, slot, epoch, occupied):
    """Number the distinct cells of ``ids`` (``(N,)``, -1 outside) in order of first
    appearance, touching only the cells that occur: ``stamp``/``slot`` (one entry per
    cell, kept between calls) mark cell ``c`` as seen in this call (``stamp[c] ==
    epoch``) with group ``slot[c]``. Writes the cells to ``occupied`` and each point's
    group (the number of cells for points outside) back into ``ids``; returns the
    number of cells."""
    k = 0
    for i in range(ids.shape[0]):
        c = ids[i]
        if c >= 0 and stamp[c] != epoch:
            stamp[c] = epoch
            slot[c] = k
            occupied[k] = c
            k += 1
    for i in range(ids.shape[0]):
        c = ids[i]
        ids[i] = slot[c] if c >= 0 else k
    return k


@njit(**_OPTS)
def point_cells(pts, lo, span, n, axes, upper, ids):
    """Cell ids (``(N,)``, linear over ``n`` cells per axis, the first axis slowest) of
    points ``(N, 3)`` in the box ``lo + [0, span]``; -1 outside it (and for NaN).
    ``upper``: a point on a face between cells goes to the lower cell."""
    for i in range(pts.shape[0]):
        cid = 0
        for ax in range(axes):
            u = (pts[i, ax] - lo[ax]) / span[ax]
            if not (u >= 0.0 and u <= 1.0):
                cid = -1
                break
            f = u * n
            c = np.ceil(f) - 1.0 if upper else np.floor(f)
            c = min(max(c, 0.0), n - 1.0)
            cid = cid * n + int(c)
        ids[i] = cid
