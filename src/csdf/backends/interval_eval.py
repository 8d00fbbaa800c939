"""Conservative interval evaluation of compiled programs over many boxes at once.

:func:`evaluate_intervals` runs the tape of a :class:`csdf.Program` once over ``M``
axis-aligned boxes, with every slot holding an interval ``[lo, hi]`` per box (two
``(M,)`` float64 arrays, processed in chunks of :data:`CHUNK` boxes like the reference
evaluator in ``numpy_backend``). The result bounds the distance at every point of each
box, for every parameter value in its interval. Meshing relies on it to skip empty
space: ``out_lo > 0`` means the whole box is outside, ``out_hi < 0`` inside.

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
    are ignored (every op propagates NaN, so such a point gives NaN at the output, which
    ``contains`` treats as outside). The interval ``(nan, nan)`` is *empty*: the slot is
    NaN at every point of the box (e.g. ``sqrt`` of ``[-2, -1]``, a NaN constant or
    parameter). An interval never has exactly one NaN endpoint. Some rules cannot
    always tell that a result is empty and return a (valid) non-empty interval instead.
    By default an empty *output* is reported as ``(-inf, inf)`` ("nothing known"); pass
    ``empty_as_nan=True`` to get ``(nan, nan)``. A box with a NaN bound, or a NaN
    parameter value, is empty (the evaluator gives NaN there too).

:func:`simplify` uses the same rules on one box to shorten a program for that region:
``min``/``max`` whose operand intervals do not overlap keep only the winning operand,
``abs`` of a positive operand is dropped, and ``step``/``sign`` of an operand of known
sign become constants.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from ..errors import CsdfError, ParamError
from ..ops import OPS_BY_CODE, numpy_impl

__all__ = ["evaluate_intervals", "simplify", "CHUNK"]

#: boxes per chunk (bounds memory: about ``2 * n_slots`` arrays of this length)
CHUNK = 1 << 15

Arr = np.ndarray
Pair = tuple[Arr, Arr]

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


def _monotone(name: str):
    """Rule for a nondecreasing op evaluated exactly like the point evaluator does."""
    fn = numpy_impl(name)

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
    "floor": _monotone("floor"),
    "step": _monotone("step"),
    "sign": _monotone("sign"),
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
# rules for op(a, a) that know both operands are equal
_SAME: dict[str, Callable[[Arr, Arr], Pair]] = {
    "sub": _same_sub,
    "mul": _square,
    "div": _same_div,
    "mod": _same_sub,  # a - a*floor(1) = 0 (or NaN for 0 and infinite a)
    "min": _identity,
    "max": _identity,
}


# ------------------------------------------------------------------------- the tape
def _rules(prog) -> list[tuple[Callable, int, int, int, bool]]:
    """Per instruction ``(rule, dst, a, b, binary)``; ``rule`` takes 2 or 4 arrays."""
    out = []
    for op, dst, a, b in prog.code.tolist():
        info = OPS_BY_CODE[op]
        if info.arity == 1:
            out.append((_UNARY[info.name], dst, a, b, False))
        elif a == b and info.name in _SAME:
            out.append((_SAME[info.name], dst, a, b, False))
        else:
            out.append((_BINARY[info.name], dst, a, b, True))
    return out


def _run(
    rules: list[tuple[Callable, int, int, int, bool]],
    lo: list,
    hi: list,
    record: list | None = None,
) -> None:
    """Run the tape in place over the slot intervals ``lo``/``hi`` (lists of arrays).

    Args:
        rules: from :func:`_rules`.
        lo, hi: per slot an ``(m,)`` or ``(1,)`` array (registers may be None).
        record: if given, each instruction's result ``(lo, hi)`` is appended to it.
    """
    with np.errstate(all="ignore"):
        for rule, dst, a, b, binary in rules:
            if binary:
                r = rule(lo[a], hi[a], lo[b], hi[b])
            else:
                r = rule(lo[a], hi[a])
            lo[dst], hi[dst] = r
            if record is not None:
                record.append(r)


def _check_boxes(prog, lo: Any, hi: Any) -> Pair:
    """Validate boxes; returns ``(M, 3)`` float64 ``lo, hi`` (z = [0, 0] for 2D input)."""
    try:
        blo = np.asarray(lo, dtype=np.float64)
        bhi = np.asarray(hi, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise CsdfError(f"box bounds must be real arrays of shape (M, 3): {exc}") from None
    ok_last = (3,) if prog.dim == 3 else (2, 3)
    for name, arr in (("lo", blo), ("hi", bhi)):
        if arr.ndim != 2 or arr.shape[1] not in ok_last:
            want = "(M, 3)" if prog.dim == 3 else "(M, 2) or (M, 3)"
            raise CsdfError(f"box {name} must have shape {want}; got shape {arr.shape}")
    if blo.shape != bhi.shape:
        raise CsdfError(f"box lo and hi shapes differ: {blo.shape} vs {bhi.shape}")
    bad = blo > bhi
    if bad.any():
        i, j = np.argwhere(bad)[0]
        raise CsdfError(
            f"box {i}: lo[{j}] = {blo[i, j]!r} > hi[{j}] = {bhi[i, j]!r} (need lo <= hi)"
        )
    if blo.shape[1] == 2:
        z = np.zeros((blo.shape[0], 1))
        blo, bhi = np.hstack([blo, z]), np.hstack([bhi, z])
    return blo, bhi


def _param_bounds(
    prog, params: Mapping[str, float] | None, param_intervals: Mapping[str, Any] | None
) -> Pair:
    """Parameter intervals ``(P,)`` lo and hi: points at their values unless given."""
    pv = prog.param_values(params)
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


def _init_slots(prog, plo: Arr, phi: Arr) -> tuple[list, list]:
    """Slot lists with parameters and constants as ``(1,)`` intervals; x, y, z unset."""
    n = prog.n_slots
    lo: list = [None] * n
    hi: list = [None] * n
    P = len(prog.params)
    for i in range(P):
        lo[3 + i], hi[3 + i] = plo[i:i + 1], phi[i:i + 1]
    consts = prog.consts.astype(np.float64)
    for i in range(len(consts)):
        lo[3 + P + i] = hi[3 + P + i] = consts[i:i + 1]
    return lo, hi


def evaluate_intervals(
    prog,
    lo: Any,
    hi: Any,
    params: Mapping[str, float] | None = None,
    param_intervals: Mapping[str, tuple[float, float]] | None = None,
    *,
    empty_as_nan: bool = False,
) -> Pair:
    """Bounds of a program's value over many axis-aligned boxes.

    Args:
        prog: the :class:`csdf.Program`.
        lo, hi: ``(M, 3)`` box corners (``(M, 2)`` also accepted for 2D programs), any
            real dtype; ``lo <= hi`` elementwise; infinite bounds are allowed.
        params: ``{name: value}`` parameter values (others take their defaults); each
            is a point interval.
        param_intervals: ``{name: (lo, hi)}``: these parameters range over ``[lo, hi]``.
        empty_as_nan: report a box where the value is NaN everywhere as ``(nan, nan)``
            instead of ``(-inf, inf)`` (see the module docs).

    Returns:
        ``(out_lo, out_hi)``, two ``(M,)`` float64 arrays with
        ``out_lo <= f(p) <= out_hi`` for every point ``p`` of each box and every
        parameter value in its interval at which ``f(p)`` is not NaN.

    Raises:
        CsdfError: badly shaped boxes or ``lo > hi``.
        ParamError: an unknown parameter name (the message lists the known ones), a
            non-numeric value, a bad interval, or a name given both ways.
    """
    blo, bhi = _check_boxes(prog, lo, hi)
    plo, phi = _param_bounds(prog, params, param_intervals)
    rules = _rules(prog)
    m_all = blo.shape[0]
    out_lo = np.empty(m_all)
    out_hi = np.empty(m_all)
    slots_lo, slots_hi = _init_slots(prog, plo, phi)
    for start in range(0, m_all, CHUNK):
        stop = min(m_all, start + CHUNK)
        sl, sh = list(slots_lo), list(slots_hi)
        for k in range(3):
            sl[k] = np.ascontiguousarray(blo[start:stop, k])
            sh[k] = np.ascontiguousarray(bhi[start:stop, k])
        _run(rules, sl, sh)
        out_lo[start:stop] = sl[prog.output]
        out_hi[start:stop] = sh[prog.output]
    bad = np.isnan(blo).any(axis=1) | np.isnan(bhi).any(axis=1)
    if np.isnan(plo).any():
        bad[:] = True
    out_lo[bad] = _NAN
    out_hi[bad] = _NAN
    if not empty_as_nan:
        empty = np.isnan(out_lo)
        out_lo[empty] = -_INF
        out_hi[empty] = _INF
    return out_lo, out_hi


# ------------------------------------------------------------------------- simplify
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


def _as_box(prog, v: Any, what: str) -> Arr:
    arr = np.asarray(v, dtype=np.float64).reshape(-1)
    if arr.shape[0] not in ((3,) if prog.dim == 3 else (2, 3)):
        raise CsdfError(f"{what} must have shape (3,); got {np.shape(v)}")
    if np.isnan(arr).any():
        raise CsdfError(f"{what} contains NaN")
    return arr


def simplify(
    prog,
    box_lo: Sequence[float] | Arr,
    box_hi: Sequence[float] | Arr,
    params: Mapping[str, float] | None = None,
    param_intervals: Mapping[str, tuple[float, float]] | None = None,
):
    """A shorter program equal to ``prog`` inside one box.

    Interval bounds of every instruction over the box decide which ``min``/``max``
    operand always wins (strictly, and only when the loser is never NaN there; ties
    are kept since the sign of a zero could differ), which ``abs`` operands are
    positive and which ``step``/``sign`` operands have a known sign; the unused
    instructions are removed and registers reallocated.

    Args:
        prog: the :class:`csdf.Program`.
        box_lo, box_hi: ``(3,)`` corners (``(2,)`` for 2D programs), no NaN.
        params, param_intervals: as for :func:`evaluate_intervals`.

    Returns:
        A valid :class:`csdf.Program` with the same parameters, the constants of
        ``prog`` (plus any new ones, appended), dim, exactness and Lipschitz bound
        (inf if ``prog``'s is NaN),
        whose float64 values at every point of the box, for every parameter value in
        its interval, are bit-identical to ``prog``'s (NaN where ``prog`` gives NaN).
        Outside the box it is a different function, so its exactness and Lipschitz
        metadata describe ``prog`` in the box only. Primitive ``calls`` whose
        instructions were removed are dropped.

    Raises:
        CsdfError, ParamError: as for :func:`evaluate_intervals`.
    """
    from ..compiler.binary import validate
    from ..compiler.program import INSTR_REF, Call, Program

    lo_arr = _as_box(prog, box_lo, "box_lo")
    hi_arr = _as_box(prog, box_hi, "box_hi")
    blo, bhi = _check_boxes(prog, lo_arr[None, :], hi_arr[None, :])
    plo, phi = _param_bounds(prog, params, param_intervals)
    sl, sh = _init_slots(prog, plo, phi)
    for k in range(3):
        sl[k], sh[k] = blo[:, k], bhi[:, k]
    record: list[Pair] = []
    _run(_rules(prog), sl, sh, record)

    n_fixed = prog.n_fixed
    consts = [float(c) for c in prog.consts]
    const_bits = {np.float64(c).tobytes(): i for i, c in enumerate(consts)}
    # a value is ('f', fixed slot), ('c', new const index) or ('i', kept instruction)
    fixed_nan = [False, False, False] + [bool(np.isnan(v)) for v in plo]
    fixed_nan += [math.isnan(c) for c in consts]

    def const_ref(v: float) -> tuple[str, int]:
        key = np.float64(v).tobytes()
        if key not in const_bits:
            const_bits[key] = len(consts)
            consts.append(v)
        ref = ("c", const_bits[key])
        may_nan[ref] = False
        interval[ref] = (v, v)
        return ref

    value: dict[int, tuple[str, int]] = {}  # slot -> value currently held
    may_nan: dict[tuple[str, int], bool] = {}
    interval: dict[tuple[str, int], tuple[float, float]] = {}
    for s in range(n_fixed):
        value[s] = ("f", s)
        may_nan[("f", s)] = fixed_nan[s]
        interval[("f", s)] = (float(sl[s][0]), float(sh[s][0]))
    kept: list[tuple[int, tuple[str, int], tuple[str, int] | None]] = []  # (op, a, b)
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
        new: tuple[str, int] | None = None
        name = info.name
        if name == "min" and vb is not None:
            if ia[1] < ib[0] and not may_nan[vb]:
                new = va
            elif ib[1] < ia[0] and not may_nan[va]:
                new = vb
        elif name == "max" and vb is not None:
            if ia[0] > ib[1] and not may_nan[vb]:
                new = va
            elif ib[0] > ia[1] and not may_nan[va]:
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
    last_use: dict[int, int] = {}
    for j, i in enumerate(order):
        for v in kept[i][1:]:
            if v is not None and v[0] == "i":
                last_use[v[1]] = j
    if out_ref[0] == "i":
        last_use[out_ref[1]] = len(order)

    new_fixed = 3 + len(prog.params) + len(consts)
    reg: dict[int, int] = {}
    free: list[int] = []
    n_regs = 0

    def slot_of(v: tuple[str, int]) -> int:
        kind, i = v
        if kind == "f":
            return i
        if kind == "c":
            return 3 + len(prog.params) + i
        return new_fixed + reg[i]

    code = np.zeros((len(order), 4), dtype=np.int64)
    new_index: dict[int, int] = {}
    for j, i in enumerate(order):
        op, va, vb = kept[i]
        sa = slot_of(va)
        sb = slot_of(vb) if vb is not None else 0
        for v in {v for v in (va, vb) if v is not None and v[0] == "i"}:
            if last_use[v[1]] == j:
                heapq.heappush(free, reg[v[1]])
        if free:
            r = heapq.heappop(free)
        else:
            r = n_regs
            n_regs += 1
        reg[i] = r
        code[j] = (op, new_fixed + r, sa, sb)
        new_index[i] = j
    output = slot_of(out_ref)

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
        output=output,
        n_regs=n_regs,
        dim=prog.dim,
        exactness=prog.exactness,
        # a NaN bound (seen from twist/bend with rate 0 of unbounded shapes) is invalid
        # bytecode; inf claims nothing
        lipschitz=_INF if math.isnan(prog.lipschitz) else prog.lipschitz,
        calls=tuple(calls),
    )
    validate(result)
    return result
