"""Conservative interval ranges of parameter-only expressions.

Shapes use this to size their bounding boxes and Lipschitz bounds when an argument
depends on parameters: a parameter ranges over ``[lo, hi]`` when both bounds are
finite, otherwise it is taken at its default (documented on :class:`csdf.Shape`).
The result always contains every value the expression can take under that rule.
"""

from __future__ import annotations

import math

from .expr import Expr, walk

__all__ = ["expr_range", "magnitude"]

Interval = tuple[float, float]
_FULL: Interval = (-math.inf, math.inf)


def _mul(a: Interval, b: Interval) -> Interval:
    prods = [a[0] * b[0], a[0] * b[1], a[1] * b[0], a[1] * b[1]]
    if any(math.isnan(p) for p in prods):
        return _FULL
    return (min(prods), max(prods))


def _monotone(f, a: Interval) -> Interval:
    try:
        return (f(a[0]), f(a[1]))
    except (ValueError, OverflowError):
        return _FULL


def _exp(v: float) -> float:
    try:
        return math.exp(v)
    except OverflowError:
        return math.inf


def _sign(v: float) -> float:
    return 0.0 if v == 0 else math.copysign(1.0, v)


def _op_range(op: str, a: Interval, b: Interval | None) -> Interval:
    if op == "add":
        return (a[0] + b[0], a[1] + b[1])  # type: ignore[index]
    if op == "sub":
        return (a[0] - b[1], a[1] - b[0])  # type: ignore[index]
    if op == "mul":
        return _mul(a, b)  # type: ignore[arg-type]
    if op == "div":
        if b[0] <= 0.0 <= b[1]:  # type: ignore[index]
            return _FULL
        return _mul(a, (1.0 / b[1], 1.0 / b[0]))  # type: ignore[index]
    if op == "neg":
        return (-a[1], -a[0])
    if op == "abs":
        if a[0] >= 0:
            return a
        if a[1] <= 0:
            return (-a[1], -a[0])
        return (0.0, max(-a[0], a[1]))
    if op == "square":
        lo, hi = _op_range("abs", a, None)
        return (lo * lo, hi * hi)
    if op == "sqrt":
        return (math.sqrt(max(a[0], 0.0)), math.sqrt(max(a[1], 0.0)))
    if op in ("sin", "cos"):
        return (-1.0, 1.0)
    if op == "asin":
        return _monotone(math.asin, (max(a[0], -1.0), min(a[1], 1.0)))
    if op == "acos":
        lo, hi = max(a[0], -1.0), min(a[1], 1.0)
        return (math.acos(hi), math.acos(lo)) if lo <= hi else _FULL
    if op == "atan":
        return _monotone(math.atan, a)
    if op == "atan2":
        return (-math.pi, math.pi)
    if op == "exp":
        return (_exp(a[0]), _exp(a[1]))
    if op == "log":
        lo = math.log(a[0]) if a[0] > 0 else -math.inf
        return (lo, math.log(a[1]) if a[1] > 0 else -math.inf)
    if op == "floor":
        return _monotone(math.floor, a) if all(map(math.isfinite, a)) else a
    if op == "step":
        return (0.0 if a[0] < 0 else 1.0, 0.0 if a[1] < 0 else 1.0)
    if op == "sign":
        return (_sign(a[0]), _sign(a[1]))
    if op == "min":
        return (min(a[0], b[0]), min(a[1], b[1]))  # type: ignore[index]
    if op == "max":
        return (max(a[0], b[0]), max(a[1], b[1]))  # type: ignore[index]
    if op == "mod":
        m = max(abs(b[0]), abs(b[1]))  # type: ignore[index]
        big = max(abs(a[0]), abs(a[1]))
        lo_b = min(abs(b[0]), abs(b[1]))  # type: ignore[index]
        # a - b*floor(a/b) stays within |b| only while a/b is exact enough (and finite)
        if b[0] <= 0.0 <= b[1] or not math.isfinite(big) or big > lo_b * 2.0**50:  # type: ignore[index]
            return _FULL
        return (-m, m)
    return _FULL  # tan and anything unbounded


def expr_range(root: Expr) -> Interval:
    """Interval containing every value of a parameter-only expression.

    Args:
        root: expression over constants and parameters (x, y, z give the full line).

    Returns:
        ``(lo, hi)``; ``(-inf, inf)`` when nothing better is known.
    """
    ranges: dict[int, Interval] = {}
    for n in walk(root):
        if n.op == "const":
            v = float(n.value)  # type: ignore[arg-type]
            r = (v, v)
        elif n.op == "param":
            p = n.value
            if math.isfinite(p.lo) and math.isfinite(p.hi):  # type: ignore[union-attr]
                r = (p.lo, p.hi)  # type: ignore[union-attr]
            else:
                r = (p.default, p.default)  # type: ignore[union-attr]
        elif n.op in ("x", "y", "z"):
            r = _FULL
        else:
            a = ranges[id(n.args[0])]
            b = ranges[id(n.args[1])] if len(n.args) > 1 else None
            r = _op_range(n.op, a, b)
            if math.isnan(r[0]) or math.isnan(r[1]):
                r = _FULL
        ranges[id(n)] = r
    return ranges[id(root)]


def magnitude(root: Expr) -> float:
    """Largest absolute value a parameter-only expression can take (may be inf)."""
    lo, hi = expr_range(root)
    return max(abs(lo), abs(hi))
