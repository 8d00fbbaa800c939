"""Constructive solid geometry: union, intersection, difference, complement, with blends.

Blends (``blend=``, used when a blend radius ``k`` is given):

=============  ==================================================================  ==========
blend          formula of the union of distances ``d_i`` (``m = min d_i``)        contract
=============  ==================================================================  ==========
hard (k=None)  ``m``                                                               bound
``smooth``     ``m - k/4 * (sum_i h_i^2 - 1)``, ``h_i = max(k - (d_i - m), 0)/k``  bound*
``exponential``  ``m - k * log(sum_i exp(-(d_i - m)/k))``                          bound
``chamfer``    ``min(a, b, (a + b - k) / sqrt 2)``                                 neither, L=sqrt 2
``round``      ``max(k, min(a, b)) - |max((k - a, k - b), 0)|``                    neither, L=sqrt 2
``stairs``     ``min(a, b, (u + a + |mod(u - a + s, 2s) - s|)/2)``, ``u=b-k, s=k/n``  bound
``columns``    ``n`` round columns along the blend (hg_sdf's construction)         neither
=============  ==================================================================  ==========

``smooth`` is Inigo Quilez's quadratic polynomial smooth minimum for two operands and
its symmetric n-ary generalisation otherwise; its gradient is a convex combination of
the operands' gradients for up to three operands (Lipschitz <= 1); with ``n > 3``
operands the Lipschitz bound is ``n - 2``. Binary blends are folded over the operands.
Operands are put in a canonical order first, so the result (and the bytecode) does not
depend on the order in which they are given.

Intersection is the dual ``-union(-d_i)`` with the same blend; difference is
``intersection(a, ~b, ...)``. Union and intersection of exact distances are bounds
(exact outside a union, inside an intersection), as the paper's Fig. 9 shows.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from ..errors import ShapeError
from ..expr import Expr, exp, log, maximum, minimum, mod, select_ge, sqrt
from ..vec import Vec, length
from .base import (
    Shape,
    derive_exactness,
    int_arg,
    intersect_bounds,
    mag,
    register,
    require_dim,
    scalar_arg,
    union_bounds,
)

__all__ = ["union", "intersection", "difference", "complement", "BLENDS"]

BLENDS = ("smooth", "exponential", "chamfer", "round", "stairs", "columns")
SQRT_HALF = math.sqrt(0.5)


def _smooth(ds: list[Expr], k: Expr, n: int) -> Expr:
    m = minimum(*ds)
    total: Expr | float = 0.0
    for d in ds:
        h = maximum(k - (d - m), 0.0) / k
        total = total + h * h
    # every h <= 1 (d >= m), so total <= len(ds) and the cap changes no value; it keeps
    # interval arithmetic, which does not know d >= m, from making h huge on large boxes
    return m - k * 0.25 * (minimum(total, float(len(ds))) - 1.0)


def _exponential(ds: list[Expr], k: Expr, n: int) -> Expr:
    m = minimum(*ds)
    total: Expr | float = 0.0
    for d in ds:
        total = total + exp(-(d - m) / k)
    return m - k * log(minimum(total, float(len(ds))))  # each term <= 1: same cap


def _chamfer2(a: Expr, b: Expr, k: Expr, n: int) -> Expr:
    return minimum(a, b, (a + b - k) * SQRT_HALF)


def _round2(a: Expr, b: Expr, k: Expr, n: int) -> Expr:
    u = Vec((maximum(k - a, 0.0), maximum(k - b, 0.0)))
    return maximum(k, minimum(a, b)) - length(u)


def _stairs2(a: Expr, b: Expr, k: Expr, n: int) -> Expr:
    s = k / n
    u = b - k
    return minimum(a, b, 0.5 * (u + a + abs(mod(u - a + s, 2.0 * s) - s)))


def _columns2(a: Expr, b: Expr, k: Expr, n: int) -> Expr:
    sq2 = math.sqrt(2.0)
    cr = k * sq2 / ((n - 1) * 2 + sq2)
    px = (a + b) * SQRT_HALF
    py = (b - a) * SQRT_HALF
    px = px - sq2 / 2 * k + cr * sq2
    if n % 2 == 1:
        py = py + cr
    size = cr * 2.0
    py = mod(py + size * 0.5, size) - size * 0.5
    res = minimum(sqrt(px * px + py * py) - cr, px, a, b)
    both_near = maximum(a, b) - k  # < 0 when a < k and b < k
    return select_ge(both_near, minimum(a, b), res)


def _fold(fn2: Callable) -> Callable:
    def go(ds: list[Expr], k: Expr, n: int) -> Expr:
        acc = ds[0]
        for d in ds[1:]:
            acc = fn2(acc, d, k, n)
        return acc

    return go


_IMPL = {
    "smooth": _smooth,
    "exponential": _exponential,
    "chamfer": _fold(_chamfer2),
    "round": _fold(_round2),
    "stairs": _fold(_stairs2),
    "columns": _fold(_columns2),
}


def _blend_lipschitz(blend: str | None, n_ops: int) -> tuple[float, bool]:
    """(factor on the children's max Lipschitz, continuous?)"""
    if blend is None or blend in ("exponential", "stairs"):
        return 1.0, True
    if blend == "smooth":
        return float(max(1, n_ops - 2)), True
    if blend in ("chamfer", "round"):
        return math.sqrt(2.0), True
    return math.sqrt(2.0), False  # columns: discontinuous where the blend region ends


def _blend_reach(blend: str, k: float, n_ops: int) -> float:
    """How far a blended union can add material beyond the operands (for exact ones):
    the blend is only active where the smallest operand distance is below this."""
    if blend == "smooth":
        return k * max(n_ops - 1, 1) / 4.0
    if blend == "exponential":
        return k * math.log(n_ops)
    return k


def _parse_blend(blend, n) -> tuple[str, int]:
    if isinstance(blend, (tuple, list)) and len(blend) == 2:
        blend, n = blend
    if blend not in BLENDS:
        raise ShapeError(f"unknown blend {blend!r}; choose one of {', '.join(BLENDS)}")
    return blend, int_arg(n, f"{blend} blend: n", 1, 64)


def _combine(
    name: str, shapes: Sequence[Shape], k, blend, n, *, sign: float, args: tuple, kwargs: dict
) -> Shape:
    if len(shapes) < 1:
        raise ShapeError(f"{name} needs at least one shape")
    dim = require_dim(shapes, name)
    if k is None:
        mode, nn, ke = None, 0, None
    else:
        mode, nn = _parse_blend(blend, n)
        ke = scalar_arg(k, f"{name}: k")
        if ke.op == "const" and not float(ke.value) > 0:  # type: ignore[arg-type]
            raise ShapeError(f"{name}: blend radius k must be > 0, got {float(ke.value)}")

    def f(p: Vec, ctx) -> Expr:
        ds = [c.sdf(p, ctx) for c in shapes]
        if sign < 0:
            ds = [-d for d in ds]
        ds.sort(key=lambda e: e.key)
        if len(ds) == 1:
            out = ds[0]
        elif mode is None:
            out = minimum(*ds)
        else:
            out = _IMPL[mode](ds, ke, nn)
        return out if sign > 0 else -out

    factor, continuous = _blend_lipschitz(mode, len(shapes))
    lip = factor * max(s.lipschitz for s in shapes)
    bounds = union_bounds([s.bounds for s in shapes]) if sign > 0 else intersect_bounds(
        [s.bounds for s in shapes]
    )
    if sign > 0 and bounds is not None and mode is not None:
        bounds = bounds + np.array([[-1.0], [1.0]]) * _blend_reach(mode, mag(ke), len(shapes))
    return Shape(
        name, f, dim=dim, lipschitz=lip, bounds=bounds, args=args, kwargs=kwargs,
        children=tuple(shapes),
        exactness=derive_exactness(
            shapes, keeps_exact=len(shapes) == 1, lipschitz=lip, continuous=continuous
        ),
    )


def _kw(k, blend, n) -> dict:
    out = {}
    if k is not None:
        out["k"] = k
        if blend != "smooth":
            out["blend"] = blend
        if n != 4:
            out["n"] = n
    return out


@register("operator")
def union(*shapes: Shape, k=None, blend="smooth", n=4) -> Shape:
    """Union of shapes (``a | b``); with a blend radius ``k``, a blended union.

    Args:
        shapes: one or more shapes of the same dimension.
        k: blend radius (model units); None gives the hard union ``min``.
        blend: ``'smooth' | 'exponential' | 'chamfer' | 'round' | 'stairs' | 'columns'``
            (or ``('stairs', n)``); see the module table for each contract.
        n: number of steps / columns for ``stairs`` and ``columns``.

    Hard union: **bound** (exact outside when the operands are exact).
    """
    return _combine("union", shapes, k, blend, n, sign=1.0, args=shapes, kwargs=_kw(k, blend, n))


@register("operator")
def intersection(*shapes: Shape, k=None, blend="smooth", n=4) -> Shape:
    """Intersection of shapes (``a & b``), optionally blended (see :func:`union`).
    Hard intersection: **bound** (exact inside when the operands are exact)."""
    return _combine(
        "intersection", shapes, k, blend, n, sign=-1.0, args=shapes, kwargs=_kw(k, blend, n)
    )


@register("operator")
def difference(a: Shape, *others: Shape, k=None, blend="smooth", n=4) -> Shape:
    """``a`` minus the other shapes (``a - b``), optionally blended (see :func:`union`).
    **Bound**."""
    if not others:
        raise ShapeError("difference needs at least two shapes")
    require_dim([a, *others], "difference")
    negs = [complement(o) for o in others]
    s = _combine("difference", [a, *negs], k, blend, n, sign=-1.0, args=(a, *others),
                 kwargs=_kw(k, blend, n))
    s.children = (a, *others)
    if a.bounds is not None:
        s.bounds = a.bounds.copy()
    return s


@register("operator")
def complement(a: Shape) -> Shape:
    """Everything outside ``a`` (``~a``): ``-f``. Keeps exactness."""
    require_dim([a], "complement")
    return Shape(
        "complement", lambda p, ctx: -a.sdf(p, ctx), dim=a.dim, lipschitz=a.lipschitz,
        bounds=None, args=(a,), children=(a,), exactness=a.exactness,
    )


# the operator overloads of Shape (see Shape's docs): a | b, a & b, a - b, ~a
def _shape_or(self: Shape, other: Shape) -> Shape:
    """``a | b``: :func:`union` (sharp)."""
    return union(self, other)


def _shape_and(self: Shape, other: Shape) -> Shape:
    """``a & b``: :func:`intersection` (sharp)."""
    return intersection(self, other)


def _shape_sub(self: Shape, other: Shape) -> Shape:
    """``a - b``: :func:`difference` (sharp)."""
    return difference(self, other)


def _shape_invert(self: Shape) -> Shape:
    """``~a``: :func:`complement`."""
    return complement(self)


Shape.__or__ = _shape_or  # type: ignore[method-assign]
Shape.__and__ = _shape_and  # type: ignore[method-assign]
Shape.__sub__ = _shape_sub  # type: ignore[method-assign]
Shape.__invert__ = _shape_invert  # type: ignore[method-assign]
