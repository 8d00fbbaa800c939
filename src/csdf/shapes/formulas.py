"""Distance formulas shared by several primitives (pure functions on expressions).

Formulas follow Inigo Quilez's catalogue of distance functions (as mathematics), written
here for z-up coordinates and branch-free evaluation: every ``if`` of the original
becomes :func:`~csdf.expr.select_ge` or a ``min``/``max``, with both branches finite.
"""

from __future__ import annotations

import math

from ..expr import Expr, maximum, minimum, mod, select_ge, sign, sqrt, step
from ..vec import Vec, dot, length, length2

__all__ = [
    "box_distance", "trapezoid2", "hexagon2", "equilateral_triangle2", "polygon2",
    "segment_distance", "regular_polygon2", "rhombus2",
]

SQRT3 = math.sqrt(3.0)


def box_distance(q: Vec) -> Expr:
    """Exact distance of an axis-aligned box given ``q = |p| - half_size`` (any dim)."""
    return length(q.max(0.0)) + minimum(q.max_comp(), 0.0)


#: how far below the distance to the nearest corner (a fraction of the trapezoid's
#: size) the corner term of :func:`trapezoid2` is lowered, so that rounding alone never
#: lets it win against the edge lines (whose gradients are defined on the outline)
CORNER_SLACK = 1e-14


def trapezoid2(q: Vec, r1, r2, he) -> Expr:
    """Exact isosceles trapezoid: half-width ``r1`` at ``y=-he``, ``r2`` at ``y=+he``.

    Inside, on the outline and beside an edge the distance is the largest signed
    distance to the three edge lines (a convex outline's exact distance there), whose
    gradient is that edge's normal. Only where a corner is nearest does the distance to
    the nearest point of the outline (a square root of a squared length) take over:
    that term's gradient is 0 / 0 on the outline itself (a sampled point on a cone's
    cap had a zero gradient), so it is lowered by ``CORNER_SLACK`` times the size to
    lose every tie to rounding."""
    qx = abs(q.x)
    qy = q.y
    k1 = Vec((r2, he))
    k2 = Vec((r2 - r1, 2.0 * he))
    p = Vec((qx, qy))
    ca = Vec((qx - minimum(qx, select_ge(qy, r2, r1)), abs(qy) - he))
    t = minimum(maximum(dot(k1 - p, k2) / length2(k2), 0.0), 1.0)
    cb = p - k1 + k2 * t
    inside = (1.0 - step(cb.x)) * (1.0 - step(ca.y))
    s = 1.0 - 2.0 * inside
    corner = s * sqrt(minimum(length2(ca), length2(cb)))
    side = ((qx - r1) * (2.0 * he) + (qy + he) * (r1 - r2)) / length(k2)
    lines = maximum(abs(qy) - he, side)
    slack = CORNER_SLACK * (abs(r1) + abs(r2) + abs(he))
    return maximum(lines, corner - slack)


def hexagon2(p: Vec, apothem) -> Expr:
    """Exact regular hexagon with the given apothem, flat edges at ``y = +-apothem``."""
    kx, ky, kz = -math.sqrt(3.0) / 2.0, 0.5, 1.0 / math.sqrt(3.0)
    q = p.abs()
    m = 2.0 * minimum(kx * q.x + ky * q.y, 0.0)
    q = Vec((q.x - m * kx, q.y - m * ky))
    lim = kz * apothem
    q = Vec((q.x - minimum(maximum(q.x, -lim), lim), q.y - apothem))
    return length(q) * sign(q.y)


def equilateral_triangle2(p: Vec, circumradius) -> Expr:
    """Exact equilateral triangle, centroid at origin, a vertex on +y."""
    r = circumradius * (SQRT3 / 2.0)  # half side length
    px = abs(p.x) - r
    py = p.y + r / SQRT3
    c = px + SQRT3 * py
    rx = (px - SQRT3 * py) * 0.5
    ry = (-SQRT3 * px - py) * 0.5
    px, py = select_ge(c, rx, px), select_ge(c, ry, py)
    px = px - minimum(maximum(px, -2.0 * r), 0.0)
    return -(length(Vec((px, py))) * sign(py))


def segment_distance(p: Vec, a: Vec, b: Vec) -> Expr:
    """Unsigned distance from ``p`` to the segment ``a -> b`` (any dim)."""
    pa = p - a
    ba = b - a
    denom = length2(ba)
    if denom.op == "const" and denom.value == 0.0:
        return length(pa)
    h = minimum(maximum(dot(pa, ba) / denom, 0.0), 1.0)
    return length(pa - ba * h)


def polygon2(p: Vec, verts: list[Vec] | list[list[Vec]]) -> Expr:
    """Exact signed distance to a simple polygon (either winding), crossing-number sign;
    or, given a list of loops, to their even-odd combination (holes)."""
    loops = verts if isinstance(verts[0], list) else [verts]
    d2 = length2(p - loops[0][0])
    parity: Expr | float = 0.0
    edges = [(lp[i], lp[i - 1]) for lp in loops for i in range(len(lp))]
    for vi, vj in edges:
        e = vj - vi
        w = p - vi
        t = minimum(maximum(dot(w, e) / length2(e), 0.0), 1.0)
        b = w - e * t
        d2 = minimum(d2, length2(b))
        c1 = step(p.y - vi.y)
        c2 = 1.0 - step(p.y - vj.y)
        c3 = 1.0 - step(e.y * w.x - e.x * w.y)
        parity = parity + c1 * c2 * c3 + (1.0 - c1) * (1.0 - c2) * (1.0 - c3)
    s = 1.0 - 2.0 * mod(parity, 2.0)  # (-1)**crossings: -1 inside
    return s * sqrt(d2)


def regular_polygon2(p: Vec, n: int, circumradius) -> Expr:
    """Exact regular ``n``-gon with a vertex on +y."""
    from ..expr import atan2, cos, sin

    an = math.pi / n
    ca, sa = math.cos(an), math.sin(an)
    bn = mod(atan2(p.x, p.y), 2.0 * an) - an
    rho = length(p)
    qx = rho * cos(bn) - circumradius * ca
    qy = rho * abs(sin(bn)) - circumradius * sa
    qy = qy + minimum(maximum(-qy, 0.0), circumradius * sa)
    return length(Vec((qx, qy))) * sign(qx)


def rhombus2(p: Vec, hx, hy) -> Expr:
    """Exact rhombus with half-diagonals ``hx`` (along x) and ``hy`` (along y)."""
    q = p.abs()
    bb = hx * hx + hy * hy
    nd = (hx - 2.0 * q.x) * hx - (hy - 2.0 * q.y) * hy
    h = minimum(maximum(nd / bb, -1.0), 1.0)
    d = length(Vec((q.x - 0.5 * hx * (1.0 - h), q.y - 0.5 * hy * (1.0 + h))))
    return d * sign(q.x * hy + q.y * hx - hx * hy)
