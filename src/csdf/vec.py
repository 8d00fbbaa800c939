"""Small fixed-size vectors of expressions, used to write shape formulas compactly.

``Vec`` is immutable; arithmetic is element-wise with broadcasting of scalars.
It never reaches user code: shapes receive a ``Vec`` of coordinate expressions and
return a scalar :class:`~csdf.expr.Expr`.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

from .expr import Expr, Number, as_expr, make, maximum, minimum, sqrt

__all__ = ["Vec", "vec", "dot", "length", "length2"]

Scalar = Expr | Number


class Vec:
    """An n-vector of expressions (n = 2 or 3 in practice)."""

    __slots__ = ("c",)

    def __init__(self, comps: Iterable[Scalar]):
        self.c: tuple[Expr, ...] = tuple(as_expr(v) for v in comps)

    def __len__(self) -> int:
        return len(self.c)

    def __iter__(self):
        return iter(self.c)

    def __getitem__(self, i: int) -> Expr:
        return self.c[i]

    @property
    def x(self) -> Expr:
        return self.c[0]

    @property
    def y(self) -> Expr:
        return self.c[1]

    @property
    def z(self) -> Expr:
        return self.c[2]

    def _zip(self, o: Vec | Scalar | Sequence[Scalar], op: str) -> Vec:
        if isinstance(o, Vec):
            other = o.c
        elif isinstance(o, (tuple, list)):
            other = tuple(as_expr(v) for v in o)
        else:
            other = (as_expr(o),) * len(self.c)
        if len(other) != len(self.c):
            raise ValueError(f"vector sizes differ: {len(self.c)} and {len(other)}")
        return Vec(make(op, a, b) for a, b in zip(self.c, other))

    def _rzip(self, o: Scalar | Sequence[Scalar], op: str) -> Vec:
        if isinstance(o, (tuple, list)):
            other = tuple(as_expr(v) for v in o)
        else:
            other = (as_expr(o),) * len(self.c)
        return Vec(make(op, b, a) for a, b in zip(self.c, other))

    def __add__(self, o):
        return self._zip(o, "add")

    def __radd__(self, o):
        return self._rzip(o, "add")

    def __sub__(self, o):
        return self._zip(o, "sub")

    def __rsub__(self, o):
        return self._rzip(o, "sub")

    def __mul__(self, o):
        return self._zip(o, "mul")

    def __rmul__(self, o):
        return self._rzip(o, "mul")

    def __truediv__(self, o):
        return self._zip(o, "div")

    def __neg__(self) -> Vec:
        return Vec(-a for a in self.c)

    def abs(self) -> Vec:
        return Vec(abs(a) for a in self.c)

    def max(self, o) -> Vec:
        return self._zip(o, "max")

    def min(self, o) -> Vec:
        return self._zip(o, "min")

    def clamp(self, lo, hi) -> Vec:
        return self.max(lo).min(hi)

    def max_comp(self) -> Expr:
        return maximum(*self.c)

    def min_comp(self) -> Expr:
        return minimum(*self.c)

    def __repr__(self) -> str:
        return f"Vec({', '.join(map(repr, self.c))})"


def vec(*comps: Scalar) -> Vec:
    return Vec(comps)


def dot(a: Vec, b: Vec | Sequence[Scalar]) -> Expr:
    bb = b.c if isinstance(b, Vec) else tuple(as_expr(v) for v in b)
    if len(bb) != len(a.c):
        raise ValueError("dot of vectors of different sizes")
    total = a.c[0] * bb[0]
    for u, v in zip(a.c[1:], bb[1:]):
        total = total + u * v
    return total


def length2(a: Vec) -> Expr:
    total = make("square", a.c[0])
    for u in a.c[1:]:
        total = total + make("square", u)
    return total


def length(a: Vec) -> Expr:
    return sqrt(length2(a))
