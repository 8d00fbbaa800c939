"""csdf's one interval arithmetic: a rule per op, a tape runner, and parameter ranges.

Every op of :mod:`csdf.ops` has a rule in :data:`RULES` that maps operand intervals to
a result interval: unary ``rule(alo, ahi) -> (lo, hi)``, binary
``rule(alo, ahi, blo, bhi) -> (lo, hi)``. Endpoints are float64 arrays of one shape
(``(m,)``, or ``(1,)`` broadcast against ``(m,)``), so one call bounds ``m`` intervals.
Three users share the rules:

* :func:`csdf.backends.interval_eval.evaluate_intervals` runs a program's tape over
  many boxes (:func:`tape_steps`, :func:`init_slots`, :func:`run_tape`);
* :func:`csdf.compiler.simplify.simplify` runs it over one box and records every
  instruction's interval;
* :func:`expr_range` and :func:`magnitude` bound parameter-only expressions (shapes
  size their bounding boxes and Lipschitz bounds with them), on length-1 arrays.

What is bounded
    The values the float64 reference evaluator (``backend='numpy'``) computes. ``+``,
    ``-``, ``*``, ``/``, ``sqrt``, ``square``, ``floor``, ``min``, ``max``, ``abs``,
    ``neg``, ``step``, ``sign`` and ``mod`` inside one period are bounded *exactly* as
    the evaluator rounds: IEEE rounding to nearest is monotone, so the endpoint formula
    rounded once bounds every rounded point value. Library functions (``sin cos tan asin
    acos atan atan2 exp log``) are not correctly rounded, so their endpoints are widened
    outward by 16 ulps (relative) plus ``2**-1060`` (absolute). Intervals are closed sets
    of the extended reals: ``-inf`` and ``inf`` are values like any other, and a box may
    have infinite bounds. Signed zeros are not tracked: an interval containing 0 may
    produce either zero.

NaN convention
    An interval bounds the *non-NaN* values of its slot; points where the slot is NaN
    are ignored (every op propagates NaN, so such a point gives NaN at the output). The
    interval ``(nan, nan)`` is *empty*: the slot is NaN at every point of the box (e.g.
    ``sqrt`` of ``[-2, -1]``, a NaN constant or parameter). An interval never has
    exactly one NaN endpoint. Some rules cannot always tell that a result is empty and
    return a (valid) non-empty interval instead.

This module is low in the layering: it imports only NumPy, :mod:`csdf.errors` and
:mod:`csdf.layout` (not :mod:`csdf.ops` nor :mod:`csdf.expr`, which may refer to it).
A tape is given as raw ``(K, 4)`` code plus an opcode-to-name map, and expressions are
read through their ``op``/``args``/``value`` attributes.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any, Protocol

import numpy as np

from .errors import CsdfError, ParamError
from .layout import N_COORDS, SlotLayout

__all__ = [
    "RULES", "SAME_OPERAND_RULES", "Interval", "Step", "expr_range", "expr_box_ranges",
    "magnitude",
    "tape_steps", "run_tape", "init_slots", "check_boxes", "param_bounds",
]

Arr = np.ndarray
Pair = tuple[Arr, Arr]
#: ``(lo, hi)`` of one scalar interval
Interval = tuple[float, float]
#: one instruction ready to run: ``(rule, dst, a, b, binary)`` (see :func:`tape_steps`)
Step = tuple[Callable[..., Pair], int, Any, int, Any]

_K = 2.0**-48  # 16 ulps: relative widening of library-function endpoints
_TINY = 2.0**-1060  # absolute widening (absorbs subnormal results)
_INF = math.inf
_NAN = math.nan
_PI = math.pi
_TWO_PI = 2.0 * math.pi
_HALF_PI = 0.5 * math.pi
# extremum/pole detection widens the argument by this much (relative and absolute):
# far more than the rounding of the period arithmetic, far less than a period unless
# |x| > ~1e11 (then sin/cos give [-1, 1] and tan the full line, which is still valid)
_MARGIN = 1e-12
# mod: relative size of the rounding error of a - b*floor(a/b) (a few units of 2**-53)
_MOD_ERR = 2.0**-48
_MOD_SAFE = 1e300  # below this no quotient or product in mod overflows
_FULL: Interval = (-_INF, _INF)


# ------------------------------------------------------------------------- helpers
def _widen(lo: Arr, hi: Arr) -> Pair:
    """Widen ``[lo, hi]`` outward by 16 ulps and ``2**-1060``; infinities and NaN stay.

    Args:
        lo, hi: ``(m,)`` (or broadcastable) endpoint arrays.

    Returns:
        ``(lo', hi')`` with ``lo' <= lo`` and ``hi' >= hi``.
    """
    lo = lo * np.where(lo > 0, 1.0 - _K, 1.0 + _K) - _TINY
    hi = hi * np.where(hi > 0, 1.0 + _K, 1.0 - _K) + _TINY
    return lo, hi


def _margin(lo: Arr, hi: Arr) -> Pair:
    """``[lo, hi]`` widened by the relative and absolute :data:`_MARGIN`."""
    return lo - (np.abs(lo) * _MARGIN + _MARGIN), hi + (np.abs(hi) * _MARGIN + _MARGIN)


def _hits(wlo: Arr, whi: Arr, phase: float, period: float) -> Arr:
    """Boolean ``(m,)``: does ``[wlo, whi]`` contain a point ``phase + k*period``?

    True for infinite bounds; False for NaN (empty) intervals.
    """
    return np.floor((whi - phase) / period) >= np.ceil((wlo - phase) / period)


def _const_unless_empty(x: Arr, value: float) -> Arr:
    """``value`` where ``x`` is not NaN, NaN where it is (keeps empty intervals empty)."""
    return np.where(np.isnan(x), _NAN, value)


# ------------------------------------------------------------------------- unary rules
# Each rule maps operand intervals (alo, ahi) (and (blo, bhi) for binary ops), arrays of
# shape (m,) or (1,), to the result interval. Operands are valid intervals: lo <= hi, or
# (nan, nan) for empty.


def _neg(alo: Arr, ahi: Arr) -> Pair:
    return -ahi, -alo


def _abs(alo: Arr, ahi: Arr) -> Pair:
    # max(lo, -hi) is lo when lo >= 0, -hi when hi <= 0, negative when 0 is inside
    return np.maximum(np.maximum(alo, -ahi), 0.0), np.maximum(-alo, ahi)


def _square(alo: Arr, ahi: Arr) -> Pair:
    lo, hi = _abs(alo, ahi)
    return lo * lo, hi * hi


def _sqrt(alo: Arr, ahi: Arr) -> Pair:
    # negative part clipped; entirely negative -> sqrt of a negative number -> (nan, nan)
    return np.sqrt(np.minimum(np.maximum(alo, 0.0), ahi)), np.sqrt(ahi)


def _log(alo: Arr, ahi: Arr) -> Pair:
    return _widen(np.log(np.minimum(np.maximum(alo, 0.0), ahi)), np.log(ahi))


def _exp(alo: Arr, ahi: Arr) -> Pair:
    lo, hi = _widen(np.exp(alo), np.exp(ahi))
    return np.maximum(lo, 0.0), hi


def _atan(alo: Arr, ahi: Arr) -> Pair:
    return _widen(np.arctan(alo), np.arctan(ahi))


def _clip_unit(alo: Arr, ahi: Arr) -> Pair:
    """Intersect with the domain [-1, 1]; both ends land outside it when disjoint."""
    return np.minimum(np.maximum(alo, -1.0), ahi), np.maximum(np.minimum(ahi, 1.0), alo)


def _asin(alo: Arr, ahi: Arr) -> Pair:
    lo, hi = _clip_unit(alo, ahi)
    return _widen(np.arcsin(lo), np.arcsin(hi))


def _acos(alo: Arr, ahi: Arr) -> Pair:
    lo, hi = _clip_unit(alo, ahi)
    out_lo, out_hi = _widen(np.arccos(hi), np.arccos(lo))
    return np.maximum(out_lo, 0.0), out_hi


def _periodic(fn: Callable[[Arr], Arr], at_max: float, at_min: float):
    """Rule for sin/cos: maxima at ``at_max + 2k pi``, minima at ``at_min + 2k pi``."""

    def rule(alo: Arr, ahi: Arr) -> Pair:
        wlo, whi = _margin(alo, ahi)
        has_max = _hits(wlo, whi, at_max, _TWO_PI)
        has_min = _hits(wlo, whi, at_min, _TWO_PI)
        v_lo, v_hi = fn(alo), fn(ahi)
        lo = np.where(has_min, -1.0, np.minimum(v_lo, v_hi))
        hi = np.where(has_max, 1.0, np.maximum(v_lo, v_hi))
        return _widen(lo, hi)

    return rule


def _tan(alo: Arr, ahi: Arr) -> Pair:
    wlo, whi = _margin(alo, ahi)
    pole = _hits(wlo, whi, _HALF_PI, _PI)
    lo, hi = _widen(np.tan(alo), np.tan(ahi))
    return np.where(pole, -_INF, lo), np.where(pole, _INF, hi)


def _step_fn(a: Arr) -> Arr:
    """``step`` as the evaluator computes it: 1 where ``a >= 0``, 0 below, NaN for NaN."""
    return np.heaviside(a, 1.0)


def _monotone(fn: Callable[[Arr], Arr]):
    """Rule for a nondecreasing op evaluated exactly like the point evaluator does."""

    def rule(alo: Arr, ahi: Arr) -> Pair:
        return fn(alo), fn(ahi)

    return rule


# ------------------------------------------------------------------------- binary rules
def _add(alo: Arr, ahi: Arr, blo: Arr, bhi: Arr) -> Pair:
    lo, hi = alo + blo, ahi + bhi
    # lo is NaN only for -inf + inf, when one operand is [inf, inf]: every non-NaN sum is
    # inf = hi (and symmetrically for hi); both NaN only when every sum is NaN
    return np.fmin(lo, hi), np.fmax(hi, lo)


def _sub(alo: Arr, ahi: Arr, blo: Arr, bhi: Arr) -> Pair:
    lo, hi = alo - bhi, ahi - blo
    return np.fmin(lo, hi), np.fmax(hi, lo)  # same argument as in _add


def _corners(
    fn: Callable[[Arr, Arr], Arr], alo: Arr, ahi: Arr, blo: Arr, bhi: Arr
) -> Pair:
    """Min and max of ``fn`` over the four corners, ignoring NaN corners (NaN if all)."""
    c1, c2, c3, c4 = fn(alo, blo), fn(alo, bhi), fn(ahi, blo), fn(ahi, bhi)
    return (np.fmin(np.fmin(c1, c2), np.fmin(c3, c4)),
            np.fmax(np.fmax(c1, c2), np.fmax(c3, c4)))


def _zero_if_all_nan(lo: Arr, hi: Arr, alo: Arr, blo: Arr) -> Pair:
    """Where every corner was NaN but the operands are not empty, the result is [0, 0]."""
    if np.isnan(lo).any():
        fix = np.isnan(lo) & ~(np.isnan(alo) | np.isnan(blo))
        lo, hi = np.where(fix, 0.0, lo), np.where(fix, 0.0, hi)
    return lo, hi


def _mul(alo: Arr, ahi: Arr, blo: Arr, bhi: Arr) -> Pair:
    # A NaN corner is 0 * inf; the values near it lie between 0 and an infinity that a
    # neighbouring corner supplies, and 0 is supplied by a neighbouring corner too
    # unless all four corners are 0 * inf: [0, 0] times an interval with two infinite
    # ends, whose finite values give 0.
    lo, hi = _corners(np.multiply, alo, ahi, blo, bhi)
    return _zero_if_all_nan(lo, hi, alo, blo)


def _div(alo: Arr, ahi: Arr, blo: Arr, bhi: Arr) -> Pair:
    # a/b is monotone in each argument while b keeps its sign. A NaN corner is inf/inf;
    # the values near it (0 .. inf) are covered by the other corners unless all four
    # are inf/inf: b = [inf, inf] (or [-inf, -inf]) and a = [-inf, inf], whose finite
    # values give 0.
    lo, hi = _zero_if_all_nan(*_corners(np.divide, alo, ahi, blo, bhi), alo, blo)
    zero = (blo <= 0.0) & (bhi >= 0.0)  # either signed zero may occur: anything goes
    return np.where(zero, -_INF, lo), np.where(zero, _INF, hi)


def _min(alo: Arr, ahi: Arr, blo: Arr, bhi: Arr) -> Pair:
    return np.minimum(alo, blo), np.minimum(ahi, bhi)


def _max(alo: Arr, ahi: Arr, blo: Arr, bhi: Arr) -> Pair:
    return np.maximum(alo, blo), np.maximum(ahi, bhi)


def _atan2(alo: Arr, ahi: Arr, blo: Arr, bhi: Arr) -> Pair:
    """atan2(y = a, x = b).

    Away from the origin and the branch cut (y = 0, x < 0) atan2 is continuous with no
    critical point and monotone along every box edge, so the corners bound it; that is
    the case when x > 0, y > 0 or y < 0 throughout the box (infinite ends included:
    IEEE atan2 of infinities is monotone along the edges too). Otherwise [-pi, pi].
    """
    lo, hi = _corners(np.arctan2, alo, ahi, blo, bhi)
    ok = (blo > 0.0) | (alo > 0.0) | (ahi < 0.0)
    nan0 = np.arctan2(alo, blo) * 0.0  # NaN exactly for empty operands
    lo = np.where(ok, lo, nan0 - _PI)
    hi = np.where(ok, hi, nan0 + _PI)
    return _widen(lo, hi)


def _mod(alo: Arr, ahi: Arr, blo: Arr, bhi: Arr) -> Pair:
    """mod(a, b) = a - b*floor(a/b) (GLSL; the sign of b).

    b < 0 is reduced to b > 0 by the exact identity mod(a, b) = -mod(-a, -b). For b > 0:
    when b is one value and a's interval lies in one period (the same floor(a/b) at both
    ends, as rounded), the result is the exact shifted range. Otherwise the result is
    [0, b] widened by the rounding error of the formula, ``2**-48 * (|a| + b)``: the
    floored quotient may be off by one when a/b rounds to an integer, and
    b*floor(a/b) loses low bits when |a/b| is large. An interval of b containing 0, or
    operands so large that a/b or b*floor(a/b) may overflow (the result can then be
    +-inf), give (-inf, inf).
    """
    neg = bhi < 0.0
    a_lo, a_hi = np.where(neg, -ahi, alo), np.where(neg, -alo, ahi)
    b_lo, b_hi = np.where(neg, -bhi, blo), np.where(neg, -blo, bhi)
    a_mag = np.maximum(np.abs(a_lo), np.abs(a_hi))
    safe = (b_lo > 0.0) & (a_mag < _MOD_SAFE) & (b_hi < _MOD_SAFE) & (
        a_mag < _MOD_SAFE * b_lo)
    err = (a_mag + b_hi) * _MOD_ERR + _TINY
    q_lo, q_hi = np.floor(a_lo / b_lo), np.floor(a_hi / b_lo)
    single = (b_lo == b_hi) & (q_lo == q_hi)
    r_lo, r_hi = _widen(a_lo - b_lo * q_lo, a_hi - b_lo * q_hi)
    lo = np.where(safe, np.where(single, r_lo, -err), -_INF)
    hi = np.where(safe, np.where(single, r_hi, b_hi + err), _INF)
    return np.where(neg, -hi, lo), np.where(neg, -lo, hi)


# --- both operands the same slot (same value at every point)
def _same_sub(alo: Arr, ahi: Arr) -> Pair:
    z = _const_unless_empty(alo, 0.0)  # a - a is 0 (or NaN for infinite a)
    return z, z


def _same_div(alo: Arr, ahi: Arr) -> Pair:
    one = _const_unless_empty(alo, 1.0)  # a / a is 1 (or NaN for 0 and infinite a)
    return one, one


def _identity(alo: Arr, ahi: Arr) -> Pair:
    return alo, ahi


_UNARY: dict[str, Callable[[Arr, Arr], Pair]] = {
    "neg": _neg,
    "abs": _abs,
    "sqrt": _sqrt,
    "square": _square,
    "sin": _periodic(np.sin, _HALF_PI, -_HALF_PI),
    "cos": _periodic(np.cos, 0.0, _PI),
    "tan": _tan,
    "asin": _asin,
    "acos": _acos,
    "atan": _atan,
    "exp": _exp,
    "log": _log,
    "floor": _monotone(np.floor),
    "step": _monotone(_step_fn),
    "sign": _monotone(np.sign),
}
_BINARY: dict[str, Callable[[Arr, Arr, Arr, Arr], Pair]] = {
    "add": _add,
    "sub": _sub,
    "mul": _mul,
    "div": _div,
    "min": _min,
    "max": _max,
    "atan2": _atan2,
    "mod": _mod,
}

#: op name -> interval rule: unary ``(alo, ahi) -> (lo, hi)``, binary
#: ``(alo, ahi, blo, bhi) -> (lo, hi)``; endpoints are float64 arrays of one shape
RULES: dict[str, Callable[..., Pair]] = {**_UNARY, **_BINARY}

#: rules for ``op(a, a)`` (both operands the same slot), ``(alo, ahi) -> (lo, hi)``:
#: tighter than the general rule because the two operands are equal at every point
SAME_OPERAND_RULES: dict[str, Callable[[Arr, Arr], Pair]] = {
    "sub": _same_sub,
    "mul": _square,
    "div": _same_div,
    "mod": _same_sub,  # a - a*floor(1) = 0 (or NaN for 0 and infinite a)
    "min": _identity,
    "max": _identity,
}


# ------------------------------------------------------------------------- tapes
#: opcodes of a mesh call's two rows (the values of :data:`csdf.ops.MESH_CODE` and
#: ``ARG_CODE``; this module does not import the op table)
_MESH, _ARG = 48, 49


def _keep(lo, hi):
    return lo, hi


def tape_steps(code: np.ndarray, op_names: Mapping[int, str],
               mesh_rule: Callable[..., Pair] | None = None) -> list[Step]:
    """The rule of every instruction of a tape, ready for :func:`run_tape`.

    Args:
        code: ``(K, 4)`` integer instructions ``(opcode, dst, a, b)`` (see
            ``docs/bytecode.md``).
        op_names: opcode -> op name (e.g. ``{c: i.name for c, i in OPS_BY_CODE.items()}``).
        mesh_rule: the interval rule of mesh calls, ``rule(block, alo, ahi, blo, bhi,
            clo, chi) -> (lo, hi)`` (given by the evaluator that holds the meshes);
            None: a tape with mesh calls is refused.

    Returns:
        Per instruction ``(rule, dst, a, b, binary)``: ``rule`` takes four arrays when
        ``binary`` is True, else two (a unary op, or a binary op whose operands are the
        same slot, with its rule from :data:`SAME_OPERAND_RULES`); a mesh call's first
        row has ``binary == 'mesh'``, ``a`` its three operand slots and ``b`` its data
        block, its second row the rule that keeps the destination (``binary ==
        'keep'``).

    Raises:
        CsdfError: a mesh call and no ``mesh_rule``.
    """
    out: list[Step] = []
    rows = np.asarray(code).reshape(-1, 4).tolist()
    for k, (op, dst, a, b) in enumerate(rows):
        if op == _MESH:
            if mesh_rule is None:
                raise CsdfError("this interval evaluation cannot run a mesh call "
                                "(csdf.from_mesh); use csdf.backends.interval_eval")
            out.append((mesh_rule, dst, (a, b, rows[k + 1][2]), rows[k + 1][3], "mesh"))
            continue
        if op == _ARG:
            out.append((_keep, dst, dst, 0, "keep"))
            continue
        name = op_names[op]
        if name in _UNARY:
            out.append((_UNARY[name], dst, a, b, False))
        elif a == b and name in SAME_OPERAND_RULES:
            out.append((SAME_OPERAND_RULES[name], dst, a, b, False))
        else:
            out.append((_BINARY[name], dst, a, b, True))
    return out


def run_tape(
    steps: Sequence[Step],
    lo: list,
    hi: list,
    record: list[Pair] | None = None,
) -> None:
    """Run a tape in place over slot intervals.

    Args:
        steps: from :func:`tape_steps`.
        lo, hi: per slot an ``(m,)`` or ``(1,)`` float64 array of interval ends (from
            :func:`init_slots`, with the coordinate slots set; registers may be None
            until written). Each instruction overwrites its destination slot.
        record: if given, each instruction's result ``(lo, hi)`` is appended to it.
    """
    with np.errstate(all="ignore"):
        for rule, dst, a, b, binary in steps:
            if binary == "mesh":
                r = rule(b, lo[a[0]], hi[a[0]], lo[a[1]], hi[a[1]], lo[a[2]], hi[a[2]])
            elif binary == "keep":
                r = (lo[dst], hi[dst])
            elif binary:
                r = rule(lo[a], hi[a], lo[b], hi[b])
            else:
                r = rule(lo[a], hi[a])
            lo[dst], hi[dst] = r
            if record is not None:
                record.append(r)


def init_slots(layout: SlotLayout, consts: np.ndarray, plo: Arr, phi: Arr) -> tuple[list, list]:
    """Slot interval lists for one program: parameters and constants as ``(1,)`` arrays.

    Args:
        layout: the program's slot layout.
        consts: ``(C,)`` constant pool.
        plo, phi: ``(P,)`` parameter interval ends (from :func:`param_bounds`).

    Returns:
        ``(lo, hi)``: lists of ``layout.n_slots`` entries; the coordinate slots and the
        registers are None (the caller sets the coordinates).
    """
    n = layout.n_slots
    lo: list = [None] * n
    hi: list = [None] * n
    for i in range(layout.n_params):
        s = layout.param(i)
        lo[s], hi[s] = plo[i:i + 1], phi[i:i + 1]
    values = np.asarray(consts, dtype=np.float64)
    for j in range(layout.n_consts):
        s = layout.const(j)
        lo[s] = hi[s] = values[j:j + 1]
    return lo, hi


def check_boxes(dim: int, lo: Any, hi: Any) -> Pair:
    """Validate axis-aligned boxes for a ``dim``-dimensional program.

    Args:
        dim: 3, or 2 (then ``(M, 2)`` boxes are accepted too).
        lo, hi: ``(M, 3)`` (or ``(M, 2)``) corners, any real dtype, ``lo <= hi``.

    Returns:
        ``(M, 3)`` float64 ``lo, hi`` (z = [0, 0] for 2D input). NaN bounds pass.

    Raises:
        CsdfError: not real arrays, a bad shape, different shapes, or ``lo > hi``.
    """
    try:
        blo = np.asarray(lo, dtype=np.float64)
        bhi = np.asarray(hi, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise CsdfError(f"box bounds must be real arrays of shape (M, 3): {exc}") from None
    ok_last = (N_COORDS,) if dim == 3 else (2, N_COORDS)
    for name, arr in (("lo", blo), ("hi", bhi)):
        if arr.ndim != 2 or arr.shape[1] not in ok_last:
            want = "(M, 3)" if dim == 3 else "(M, 2) or (M, 3)"
            raise CsdfError(f"box {name} must have shape {want}; got shape {arr.shape}")
    if blo.shape != bhi.shape:
        raise CsdfError(f"box lo and hi shapes differ: {blo.shape} vs {bhi.shape}")
    bad = blo > bhi
    if bad.any():
        i, j = np.argwhere(bad)[0]
        raise CsdfError(
            f"box {i}: lo[{j}] = {float(blo[i, j])!r} > hi[{j}] = {float(bhi[i, j])!r} "
            "(need lo <= hi)"
        )
    if blo.shape[1] == 2:
        z = np.zeros((blo.shape[0], 1))
        blo, bhi = np.hstack([blo, z]), np.hstack([bhi, z])
    return blo, bhi


def param_bounds(
    prog: Any,
    params: Mapping[str, float] | None,
    param_intervals: Mapping[str, Any] | None,
) -> Pair:
    """Parameter intervals of a program: each is its value (a point) unless given.

    Args:
        prog: the program (anything with ``param_values(params, check_ranges=)`` and
            ``param_names``, as :class:`csdf.Program` has). Values outside their
            declared ranges are not refused here: interval arithmetic holds for any
            value (the evaluation API and :class:`csdf.field.Field` check ranges).
        params: ``{name: value}`` point values (others take their defaults).
        param_intervals: ``{name: (lo, hi)}`` ranges.

    Returns:
        ``(plo, phi)``, two ``(P,)`` float64 arrays in the program's parameter order.

    Raises:
        ParamError: an unknown name (the message lists the known ones), a non-numeric
            value, an interval that is not a pair with ``lo <= hi``, or a name given
            both as a value and as an interval.
    """
    pv = prog.param_values(params, check_ranges=False)
    plo, phi = pv.copy(), pv.copy()
    given = dict(param_intervals or {})
    twice = set(given) & set(params or {})
    if twice:
        raise ParamError(f"parameter(s) {sorted(twice)} given both as values and intervals")
    index = {name: i for i, name in enumerate(prog.param_names)}
    for name, rng in given.items():
        i = index.get(name)
        if i is None:
            known = ", ".join(prog.param_names) or "none"
            raise ParamError(f"unknown parameter {name!r}; this shape's parameters: {known}")
        try:
            a, b = (float(v) for v in rng)
        except (TypeError, ValueError):
            raise ParamError(
                f"interval of parameter {name!r} must be a pair (lo, hi) of numbers, "
                f"got {rng!r}"
            ) from None
        if not a <= b:  # also catches NaN
            raise ParamError(f"interval of parameter {name!r} is not lo <= hi: ({a}, {b})")
        plo[i], phi[i] = a, b
    return plo, phi


# ------------------------------------------------------------------------- expressions
class _Node(Protocol):
    """What :func:`expr_range` reads of a :class:`csdf.expr.Expr` node."""

    op: str
    args: tuple[Any, ...]
    value: object


def _postorder(root: _Node) -> list[_Node]:
    """Every node reachable from ``root`` once, children before parents."""
    seen: set[int] = set()
    out: list[_Node] = []
    stack: list[tuple[_Node, bool]] = [(root, False)]
    while stack:
        node, expanded = stack.pop()
        if id(node) in seen:
            continue
        if expanded:
            seen.add(id(node))
            out.append(node)
            continue
        stack.append((node, True))
        for a in reversed(node.args):
            if id(a) not in seen:
                stack.append((a, False))
    return out


def expr_range(root: _Node) -> Interval:
    """Interval containing every value of a parameter-only expression.

    A parameter ranges over ``[lo, hi]`` when both bounds are finite, otherwise it is
    taken at its default (the rule documented on :class:`csdf.Shape`). The ranges come
    from :data:`RULES` on length-1 arrays, so they bound the values the evaluators
    compute.

    Args:
        root: a :class:`csdf.expr.Expr` over constants and parameters (x, y, z range
            over the whole line).

    Returns:
        ``(lo, hi)``; ``(-inf, inf)`` when nothing better is known (also when the
        expression is NaN for every parameter value).
    """
    inf = np.array([_INF])
    coords = {c: (-inf, inf) for c in ("x", "y", "z")}
    lo_a, hi_a = _ranges([root], coords, 1)[0]
    lo, hi = float(lo_a[0]), float(hi_a[0])
    if math.isnan(lo) or math.isnan(hi):
        return _FULL
    return (lo, hi)


def expr_box_ranges(roots: Sequence[_Node], lo: Arr, hi: Arr) -> list[Pair]:
    """Intervals of expressions in x, y, z over ``M`` boxes at once: for each root, two
    ``(M,)`` arrays bounding its values over the box ``[lo[m], hi[m]]`` (``(M, 3)``
    each; a 2D box ``(M, 2)`` leaves z over the whole line), parameters over their
    ranges as in :func:`expr_range`. NaN bounds mean nothing is known there (an
    expression NaN over the whole box)."""
    lo = np.asarray(lo, dtype=np.float64)
    hi = np.asarray(hi, dtype=np.float64)
    m = len(lo)
    full = (np.full(m, -_INF), np.full(m, _INF))
    coords = {c: ((lo[:, i].copy(), hi[:, i].copy()) if i < lo.shape[1] else full)
              for i, c in enumerate(("x", "y", "z"))}
    return _ranges(list(roots), coords, m)


def _ranges(roots: list[_Node], coords: dict[str, Pair], m: int) -> list[Pair]:
    ranges: dict[int, Pair] = {}
    for root in roots:
        for n in _postorder(root):
            if id(n) in ranges:
                continue
            if n.op == "const":
                v = np.full(m, float(n.value))  # type: ignore[arg-type]
                r = (v, v)
            elif n.op == "param":
                p: Any = n.value
                if math.isfinite(p.lo) and math.isfinite(p.hi):
                    r = (np.full(m, float(p.lo)), np.full(m, float(p.hi)))
                else:
                    d = np.full(m, float(p.default))
                    r = (d, d)
            elif n.op in ("x", "y", "z"):
                r = coords[n.op]
            else:
                a = ranges[id(n.args[0])]
                with np.errstate(all="ignore"):
                    if n.op in _UNARY:
                        r = _UNARY[n.op](*a)
                    elif n.args[1] is n.args[0] and n.op in SAME_OPERAND_RULES:
                        r = SAME_OPERAND_RULES[n.op](*a)
                    else:
                        r = _BINARY[n.op](*a, *ranges[id(n.args[1])])
            ranges[id(n)] = r
    return [ranges[id(r)] for r in roots]


def magnitude(root: _Node) -> float:
    """Largest absolute value a parameter-only expression can take (may be inf)."""
    lo, hi = expr_range(root)
    return max(abs(lo), abs(hi))
