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
    "segment_distance", "regular_polygon2", "rhombus2", "edges_first",
]

SQRT3 = math.sqrt(3.0)


def box_distance(q: Vec) -> Expr:
    """Exact distance of an axis-aligned box given ``q = |p| - half_size`` (any dim)."""
    return length(q.max(0.0)) + minimum(q.max_comp(), 0.0)


#: how far below the distance to the nearest corner (a fraction of the outline's size)
#: the corner term of :func:`edges_first` is lowered, so that rounding alone never lets
#: it win against the edge lines (whose gradients are defined on the outline)
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
    return edges_first(lines, corner, abs(r1) + abs(r2) + abs(he))


def edges_first(lines: Expr, exact: Expr, size) -> Expr:
    """A convex outline's (or solid's) exact distance whose gradient is defined on it.

    ``lines`` is the largest signed distance to the supporting lines (planes) of its
    edges (faces): never above the exact distance ``exact``, equal to it inside, on the
    outline and beside an edge, and there its gradient is that edge's normal. ``exact``
    (a square root of a squared length times a sign, whose gradient is 0 / 0 on the
    outline: a sampled surface point had a zero gradient) is lowered by
    ``CORNER_SLACK * size`` so that it takes over only where a corner is nearest, never
    by rounding on the outline. The result is within that slack of the exact distance."""
    return maximum(lines, exact - CORNER_SLACK * size)


def hexagon2(p: Vec, apothem) -> Expr:
    """Exact regular hexagon with the given apothem, flat edges at ``y = +-apothem``
    (the edge lines first: :func:`edges_first`)."""
    kx, ky, kz = -math.sqrt(3.0) / 2.0, 0.5, 1.0 / math.sqrt(3.0)
    q = p.abs()
    m = 2.0 * minimum(kx * q.x + ky * q.y, 0.0)
    q = Vec((q.x - m * kx, q.y - m * ky))
    lim = kz * apothem
    lines = maximum(q.y, (SQRT3 / 2.0) * q.x + 0.5 * q.y) - apothem
    q = Vec((q.x - minimum(maximum(q.x, -lim), lim), q.y - apothem))
    return edges_first(lines, length(q) * sign(q.y), abs(apothem))


def equilateral_triangle2(p: Vec, circumradius) -> Expr:
    """Exact equilateral triangle, centroid at origin, a vertex on +y (the edge lines
    first: :func:`edges_first`)."""
    r = circumradius * (SQRT3 / 2.0)  # half side length
    lines = maximum(-p.y, (SQRT3 / 2.0) * abs(p.x) + 0.5 * p.y) - 0.5 * circumradius
    px = abs(p.x) - r
    py = p.y + r / SQRT3
    c = px + SQRT3 * py
    rx = (px - SQRT3 * py) * 0.5
    ry = (-SQRT3 * px - py) * 0.5
    px, py = select_ge(c, rx, px), select_ge(c, ry, py)
    px = px - minimum(maximum(px, -2.0 * r), 0.0)
    return edges_first(lines, -(length(Vec((px, py))) * sign(py)), abs(circumradius))


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
    or, given a list of loops, to their even-odd combination (holes).

    The unsigned distance is the smaller of the distance to the nearest vertex and the
    distances to the lines of the edges onto whose inside the point projects (the other
    edges' line distances are raised by the point's L1 distance to the edge's first
    vertex, at least its distance to that vertex; a constant as large as 1e30 instead
    left interval arithmetic unable to drop them, doubling the pruned tapes). Each edge
    line's distance is signed on the side that the crossing test counts a point on it
    on (``cross >= 0``; above a horizontal edge), so on an edge, where the distance is
    0, the gradient is the edge's outward normal (the square root of a squared distance
    has a 0 / 0 gradient there)."""
    loops = verts if isinstance(verts[0], list) else [verts]
    near2: Expr | None = None
    lines: Expr | None = None
    parity: Expr | float = 0.0
    edges = [(lp[i], lp[i - 1]) for lp in loops for i in range(len(lp))]
    for vi, vj in edges:
        e = vj - vi
        w = p - vi
        ee = length2(e)
        cross = e.y * w.x - e.x * w.y
        side = step(cross)  # the crossing test's side of the edge's line: 1 where >= 0
        if e.y.op == "const" and e.y.value == 0.0 and e.x.op == "const":
            # a horizontal edge is never crossed; a point on it is counted as if it
            # were above it (as the adjacent edges' ``p.y >= v.y`` place it)
            sigma = (2.0 * step(w.y) - 1.0) * (-1.0 if float(e.x.value) > 0 else 1.0)
        else:
            sigma = 2.0 * side - 1.0
        # >= 0 as written; the max keeps interval bounds >= 0 (its tie takes ``line``)
        line = maximum(sigma * cross / sqrt(ee), 0.0)
        t = dot(w, e) / ee
        off = 1.0 - step(t * (1.0 - t))  # 1 where the projection misses the edge
        line = line + off * (abs(w.x) + abs(w.y))
        v2 = length2(w)
        near2 = v2 if near2 is None else minimum(near2, v2)
        lines = line if lines is None else minimum(lines, line)
        c1 = step(p.y - vi.y)
        c2 = 1.0 - step(p.y - vj.y)
        c3 = 1.0 - side
        parity = parity + c1 * c2 * c3 + (1.0 - c1) * (1.0 - c2) * (1.0 - c3)
    s = 1.0 - 2.0 * mod(parity, 2.0)  # (-1)**crossings: -1 inside
    assert near2 is not None and lines is not None
    return s * minimum(lines, sqrt(near2))


def regular_polygon2(p: Vec, n: int, circumradius) -> Expr:
    """Exact regular ``n``-gon with a vertex on +y (the edge lines first:
    :func:`edges_first`)."""
    from ..expr import atan2, cos, sin

    an = math.pi / n
    ca, sa = math.cos(an), math.sin(an)
    bn = mod(atan2(p.x, p.y), 2.0 * an) - an
    rho = length(p)
    qx = rho * cos(bn) - circumradius * ca
    qy = rho * abs(sin(bn)) - circumradius * sa
    qy = qy + minimum(maximum(-qy, 0.0), circumradius * sa)
    # qx is the signed distance to the line of the edge of the point's sector, the
    # largest of all edge lines' for a regular polygon
    return edges_first(qx, length(Vec((qx, qy))) * sign(qx), abs(circumradius))


def rhombus2(p: Vec, hx, hy) -> Expr:
    """Exact rhombus with half-diagonals ``hx`` (along x) and ``hy`` (along y) (the edge
    lines first: :func:`edges_first`)."""
    q = p.abs()
    bb = hx * hx + hy * hy
    nd = (hx - 2.0 * q.x) * hx - (hy - 2.0 * q.y) * hy
    h = minimum(maximum(nd / bb, -1.0), 1.0)
    d = length(Vec((q.x - 0.5 * hx * (1.0 - h), q.y - 0.5 * hy * (1.0 + h))))
    edge = q.x * hy + q.y * hx - hx * hy
    return edges_first(edge / sqrt(bb), d * sign(edge), abs(hx) + abs(hy))
