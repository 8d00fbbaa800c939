"""Tape simplification by interval arithmetic: a shorter program for one region.

Over one axis-aligned box (and parameter intervals), the interval of every instruction
(:mod:`csdf.interval`, the rules :func:`csdf.backends.interval_eval.evaluate_intervals`
uses) decides

* which ``min``/``max`` operand always wins (strictly, and only when the loser is never
  NaN there; ties are kept since the sign of a zero could differ): the other operand
  is dropped;
* which ``abs`` operands are positive (``abs`` is dropped);
* which ``step``/``sign`` operands have a known sign (they become constants).

The instructions no longer needed are removed and the registers reallocated
(:func:`csdf.compiler.regalloc.linear_scan`). Inside the box the result computes the
same float64 values as the original, bit for bit. A simplified program is a valid
:class:`~csdf.Program` like any other, so it can be simplified again for a sub-box
(meshers and tracers descend an octree this way, each child starting from its
parent's shortened tape).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ..errors import CsdfError
from ..interval import check_boxes, init_slots, param_bounds, run_tape, tape_steps
from ..layout import N_COORDS, SlotLayout
from ..ops import OPS_BY_CODE
from .binary import validate
from .calls import INSTR_REF, Call
from .program import Program
from .regalloc import linear_scan

__all__ = ["simplify"]

_OP_NAMES = {code: info.name for code, info in OPS_BY_CODE.items()}
_INF = math.inf

#: a value of the simplified tape: ("f", fixed slot of the original program),
#: ("c", index of a constant in the new pool) or ("i", index of a kept instruction)
Ref = tuple[str, int]


def _has_inf(lo: float, hi: float) -> bool:
    return lo == -_INF or hi == _INF


def _has_zero(lo: float, hi: float) -> bool:
    return lo <= 0.0 <= hi


def _makes_nan(name: str, a: tuple[float, float], b: tuple[float, float] | None) -> bool:
    """Can ``name`` give NaN for non-NaN operands in these intervals? (conservative)"""
    alo, ahi = a
    if name in ("sqrt", "log"):
        return alo < 0.0
    if name in ("asin", "acos"):
        return alo < -1.0 or ahi > 1.0
    if name in ("sin", "cos", "tan"):
        return _has_inf(alo, ahi)
    if b is None:
        return False
    blo, bhi = b
    if name == "add":
        return (ahi == _INF and blo == -_INF) or (alo == -_INF and bhi == _INF)
    if name == "sub":
        return (ahi == _INF and bhi == _INF) or (alo == -_INF and blo == -_INF)
    if name == "mul":
        return (_has_zero(alo, ahi) and _has_inf(blo, bhi)) or (
            _has_zero(blo, bhi) and _has_inf(alo, ahi))
    if name == "div":
        return (_has_zero(alo, ahi) and _has_zero(blo, bhi)) or (
            _has_inf(alo, ahi) and _has_inf(blo, bhi))
    if name == "mod":
        return _has_zero(blo, bhi) or _has_inf(alo, ahi) or _has_inf(blo, bhi)
    return False  # min max atan2


def _as_box(prog: Program, v: Any, what: str) -> np.ndarray:
    """One box corner as a ``(3,)`` (or ``(2,)`` for 2D) float64 array without NaN."""
    arr = np.asarray(v, dtype=np.float64).reshape(-1)
    if arr.shape[0] not in ((N_COORDS,) if prog.dim == 3 else (2, N_COORDS)):
        raise CsdfError(f"{what} must have shape (3,); got {np.shape(v)}")
    if np.isnan(arr).any():
        raise CsdfError(f"{what} contains NaN")
    return arr


def simplify(
    prog: Program,
    box_lo: Sequence[float] | np.ndarray,
    box_hi: Sequence[float] | np.ndarray,
    params: Mapping[str, float] | None = None,
    param_intervals: Mapping[str, tuple[float, float]] | None = None,
) -> Program:
    """A shorter program equal to ``prog`` inside one box (see the module docs).

    Args:
        prog: the :class:`csdf.Program` (a simplified one too).
        box_lo, box_hi: ``(3,)`` corners in model units (``(2,)`` for 2D programs), no
            NaN, ``box_lo <= box_hi``.
        params, param_intervals: as for
            :func:`csdf.backends.interval_eval.evaluate_intervals`: point values, and
            ``{name: (lo, hi)}`` ranges the result must hold for.

    Returns:
        A valid :class:`csdf.Program` with the same parameters, the constants of
        ``prog`` (plus any new ones, appended), dim, exactness, Lipschitz bound (inf if
        ``prog``'s is NaN) and bounds, whose float64 values at every point of the box,
        for every parameter value in its interval, are bit-identical to ``prog``'s (NaN
        where ``prog`` gives NaN). Outside the box it is a different function, so its
        exactness, Lipschitz and bounds metadata describe ``prog`` in the box only.
        Primitive ``calls`` whose instructions were removed are dropped. A program
        with mesh calls (data blocks) is returned as it is.

    Raises:
        CsdfError, ParamError: as for ``evaluate_intervals``; also a corner with NaN.
    """
    lo_arr = _as_box(prog, box_lo, "box_lo")
    hi_arr = _as_box(prog, box_hi, "box_hi")
    blo, bhi = check_boxes(prog.dim, lo_arr[None, :], hi_arr[None, :])
    plo, phi = param_bounds(prog, params, param_intervals)
    if prog.data:
        return prog
    sl, sh = init_slots(prog.layout, prog.consts, plo, phi)
    for k in range(N_COORDS):
        sl[k], sh[k] = blo[:, k], bhi[:, k]
    record: list[tuple[np.ndarray, np.ndarray]] = []
    run_tape(tape_steps(prog.code, _OP_NAMES), sl, sh, record)

    n_fixed = prog.n_fixed
    consts = [float(c) for c in prog.consts]
    const_bits = {np.float64(c).tobytes(): i for i, c in enumerate(consts)}
    fixed_nan = [False] * N_COORDS + [bool(np.isnan(v)) for v in plo]
    fixed_nan += [math.isnan(c) for c in consts]

    def const_ref(v: float) -> Ref:
        key = np.float64(v).tobytes()
        if key not in const_bits:
            const_bits[key] = len(consts)
            consts.append(v)
        ref = ("c", const_bits[key])
        may_nan[ref] = False
        interval[ref] = (v, v)
        return ref

    value: dict[int, Ref] = {}  # slot -> value currently held
    may_nan: dict[Ref, bool] = {}
    interval: dict[Ref, tuple[float, float]] = {}
    for s in range(n_fixed):
        value[s] = ("f", s)
        may_nan[("f", s)] = fixed_nan[s]
        interval[("f", s)] = (float(sl[s][0]), float(sh[s][0]))
    kept: list[tuple[int, Ref, Ref | None]] = []  # (opcode, a, b)
    origin: dict[int, int] = {}  # old instruction -> index in kept (if it stays)
    for k, (op, dst, a, b) in enumerate(prog.code.tolist()):
        info = OPS_BY_CODE[op]
        va = value[a]
        vb = value[b] if info.arity == 2 else None
        ia = interval[va]
        ib = interval[vb] if vb is not None else None
        res = (float(record[k][0][0]), float(record[k][1][0]))
        nan_in = may_nan[va] or (vb is not None and may_nan[vb])
        nan_out = nan_in or math.isnan(res[0]) or _makes_nan(info.name, ia, ib)
        new: Ref | None = None
        name = info.name
        if name == "min" and vb is not None:
            if ia[1] < ib[0] and not may_nan[vb]:  # type: ignore[index]
                new = va
            elif ib[1] < ia[0] and not may_nan[va]:  # type: ignore[index]
                new = vb
        elif name == "max" and vb is not None:
            if ia[0] > ib[1] and not may_nan[vb]:  # type: ignore[index]
                new = va
            elif ib[0] > ia[1] and not may_nan[va]:  # type: ignore[index]
                new = vb
        elif name == "abs" and ia[0] > 0.0:
            new = va
        elif name in ("step", "sign") and not nan_in:
            if ia[0] > 0.0 or (name == "step" and ia[0] >= 0.0):
                new = const_ref(1.0)
            elif ia[1] < 0.0:
                new = const_ref(0.0 if name == "step" else -1.0)
        if new is None:
            new = ("i", len(kept))
            origin[k] = len(kept)
            kept.append((op, va, vb))
            may_nan[new] = nan_out
            interval[new] = res
        value[dst] = new

    # liveness from the output back
    out_ref = value[prog.output]
    live = [False] * len(kept)
    if out_ref[0] == "i":
        live[out_ref[1]] = True
    for i in range(len(kept) - 1, -1, -1):
        if live[i]:
            for v in kept[i][1:]:
                if v is not None and v[0] == "i":
                    live[v[1]] = True
    order = [i for i in range(len(kept)) if live[i]]
    new_index = {i: j for j, i in enumerate(order)}  # kept instruction -> new position

    reads = [[new_index[v[1]] for v in kept[i][1:] if v is not None and v[0] == "i"]
             for i in order]
    live_out = [new_index[out_ref[1]]] if out_ref[0] == "i" else []
    regs, n_regs = linear_scan(reads, live_out)
    layout = SlotLayout(len(prog.params), len(consts), n_regs)

    def slot_of(v: Ref) -> int:
        kind, i = v
        if kind == "f":
            return i  # fixed slots keep their numbers (new constants are appended)
        if kind == "c":
            return layout.const(i)
        return layout.reg(regs[new_index[i]])

    code = np.zeros((len(order), 4), dtype=np.int64)
    for j, i in enumerate(order):
        op, va, vb = kept[i]
        code[j] = (op, layout.reg(regs[j]), slot_of(va), slot_of(vb) if vb is not None else 0)

    def remap(s: int) -> int | None:
        if not s & INSTR_REF:
            return s  # fixed slots keep their numbers (new constants are appended)
        i = origin.get(s & ~INSTR_REF)
        if i is None or i not in new_index:
            return None
        return INSTR_REF | new_index[i]

    calls = []
    for c in prog.calls:
        out = remap(INSTR_REF | c.out)
        inputs = [remap(s) for s in c.inputs]
        if out is None or any(s is None for s in inputs):
            continue
        calls.append(Call(c.name, out & ~INSTR_REF, tuple(s for s in inputs if s is not None)))
    result = Program(
        params=prog.params,
        consts=np.array(consts, dtype=np.float64),
        code=code,
        output=slot_of(out_ref),
        n_regs=n_regs,
        dim=prog.dim,
        exactness=prog.exactness,
        # a NaN bound (seen from twist/bend with rate 0 of unbounded shapes) is invalid
        # bytecode; inf claims nothing
        lipschitz=_INF if math.isnan(prog.lipschitz) else prog.lipschitz,
        calls=tuple(calls),
        bounds=prog.bounds,
    )
    validate(result)
    return result
