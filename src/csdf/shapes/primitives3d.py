"""3D primitives, centred at the origin, z up. Lengths in model units (metres in the zoo).

Each docstring states the distance contract: **exact** (Euclidean signed distance),
**bound** (never overestimates), or **neither**. Every argument may be a number or a
parameter expression (``csdf.param``).

Sizes (radii, sizes, heights, thicknesses, roundings) must be >= 0: a negative one is a
:class:`~csdf.errors.ShapeError` (for a parameter, when it is negative at the defaults;
see :func:`csdf.shapes.base.size_arg`). Zero is allowed and gives a degenerate shape
whose field is still the exact distance to it (``sphere(0)`` is the distance to a
point, ``rounded_box(s, 0)`` is ``box(s)``), except where a size divides: the
``ellipsoid`` radii, the ``pyramid`` base and the ``round_cone`` height must be > 0.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from ..errors import ShapeError
from ..expr import Expr, as_expr, maximum, minimum, select_ge, sign, sqrt
from ..interval import expr_range
from ..vec import Vec, dot, length, length2
from .base import (
    Shape,
    box_bounds,
    mag,
    register,
    scalar_arg,
    size_arg,
    size_vector,
    vector_arg,
)
from .formulas import (
    SQRT3,
    box_distance,
    edges_first,
    equilateral_triangle2,
    hexagon2,
    segment_distance,
    trapezoid2,
)

__all__ = [
    "sphere", "box", "rounded_box", "box_frame", "cylinder", "rounded_cylinder", "capsule",
    "cone", "capped_cone", "round_cone", "torus", "capped_torus", "link", "plane", "slab",
    "ellipsoid", "octahedron", "pyramid", "hex_prism", "tri_prism",
]


def primitive(
    name: str,
    fn: Callable[[Vec], Expr],
    *,
    args: tuple,
    prim_args: tuple[Expr, ...],
    exactness: str,
    bounds,
    dim: int = 3,
    lipschitz: float = 1.0,
) -> Shape:
    """Make a primitive node (a ``call`` at the primitive level of Table-1 counts)."""
    return Shape(
        name,
        lambda p, ctx: fn(p),
        dim=dim,
        exactness=exactness,
        lipschitz=lipschitz,
        bounds=bounds,
        args=args,
        primitive=prim_args,
    )


_vlen = length


def _cube(r: float) -> np.ndarray:
    return box_bounds([-r] * 3, [r] * 3)


def _lohi(e: Expr) -> tuple[float, float]:
    return expr_range(e)


@register("primitive3d")
def sphere(radius=1.0) -> Shape:
    """Sphere of ``radius``. **Exact.**"""
    r = size_arg(radius, "sphere: radius")
    return primitive(
        "sphere", lambda p: length(p) - r, args=(radius,), prim_args=(r,),
        exactness="exact", bounds=_cube(mag(r)),
    )


@register("primitive3d")
def box(size=1.0) -> Shape:
    """Axis-aligned box with full side lengths ``size`` (scalar or 3-vector). **Exact.**"""
    s = size_vector(size, 3, "box: size", broadcast=True)
    h = Vec(s) * 0.5
    m = [mag(c) / 2 for c in s]
    return primitive(
        "box", lambda p: box_distance(p.abs() - h), args=(size,), prim_args=s,
        exactness="exact", bounds=box_bounds([-v for v in m], m),
    )


@register("primitive3d")
def rounded_box(size=1.0, radius=0.1) -> Shape:
    """Box of outer full size ``size`` with edges rounded by ``radius``. **Exact.**"""
    s = size_vector(size, 3, "rounded_box: size", broadcast=True)
    r = size_arg(radius, "rounded_box: radius")
    h = Vec(s) * 0.5
    m = [mag(c) / 2 for c in s]
    return primitive(
        "rounded_box", lambda p: box_distance(p.abs() - h + r) - r, args=(size, radius),
        prim_args=(*s, r), exactness="exact", bounds=box_bounds([-v for v in m], m),
    )


@register("primitive3d")
def box_frame(size=1.0, thickness=0.1) -> Shape:
    """The 12 edges of a box of full size ``size`` as square bars of side ``thickness``,
    flush with the faces. **Exact.**"""
    s = size_vector(size, 3, "box_frame: size", broadcast=True)
    t = size_arg(thickness, "box_frame: thickness")
    h = Vec(s) * 0.5
    e = t * 0.5
    m = [mag(c) / 2 for c in s]

    def f(p: Vec) -> Expr:
        a = p.abs() - h
        q = (a + e).abs() - e
        outer = minimum(
            box_distance(Vec((a.x, q.y, q.z))),
            box_distance(Vec((q.x, a.y, q.z))),
            box_distance(Vec((q.x, q.y, a.z))),
        )
        # inside a bar the nearest boundary is an outer face or the hollow, which is
        # reached by moving two coordinates inward past the bar (exact in the corners)
        w = (a + t).max(0.0)
        depth = minimum(
            -a.max_comp(),
            sqrt(w.x * w.x + w.y * w.y), sqrt(w.y * w.y + w.z * w.z), sqrt(w.x * w.x + w.z * w.z),
        )
        return select_ge(outer, outer, -depth)

    return primitive(
        "box_frame", f, args=(size, thickness), prim_args=(*s, t), exactness="exact",
        bounds=box_bounds([-v for v in m], m),
    )


@register("primitive3d")
def cylinder(radius=0.5, height=1.0) -> Shape:
    """Capped cylinder around the z axis, ``z`` in ``[-height/2, height/2]``. **Exact.**"""
    r = size_arg(radius, "cylinder: radius")
    h = size_arg(height, "cylinder: height")
    R, H = mag(r), mag(h) / 2

    def f(p: Vec) -> Expr:
        return box_distance(Vec((length(Vec((p.x, p.y))) - r, abs(p.z) - h * 0.5)))

    return primitive(
        "cylinder", f, args=(radius, height), prim_args=(r, h), exactness="exact",
        bounds=box_bounds([-R, -R, -H], [R, R, H]),
    )


@register("primitive3d")
def rounded_cylinder(radius=0.5, height=1.0, rounding=0.1) -> Shape:
    """Cylinder (as :func:`cylinder`) whose two rims are rounded by ``rounding``. **Exact.**"""
    r = size_arg(radius, "rounded_cylinder: radius")
    h = size_arg(height, "rounded_cylinder: height")
    rr = size_arg(rounding, "rounded_cylinder: rounding")
    R, H = mag(r), mag(h) / 2

    def f(p: Vec) -> Expr:
        d = Vec((length(Vec((p.x, p.y))) - r + rr, abs(p.z) - h * 0.5 + rr))
        return box_distance(d) - rr

    return primitive(
        "rounded_cylinder", f, args=(radius, height, rounding), prim_args=(r, h, rr),
        exactness="exact", bounds=box_bounds([-R, -R, -H], [R, R, H]),
    )


@register("primitive3d")
def capsule(a=(0.0, 0.0, -0.5), b=(0.0, 0.0, 0.5), radius=0.25) -> Shape:
    """Points within ``radius`` of the segment ``a -> b``. **Exact.**"""
    av = vector_arg(a, 3, "capsule: a")
    bv = vector_arg(b, 3, "capsule: b")
    r = size_arg(radius, "capsule: radius")
    R = mag(r)
    ra = [expr_range(c) for c in av]
    rb = [expr_range(c) for c in bv]
    lo = [min(x[0], y[0]) - R for x, y in zip(ra, rb)]
    hi = [max(x[1], y[1]) + R for x, y in zip(ra, rb)]
    return primitive(
        "capsule", lambda p: segment_distance(p, Vec(av), Vec(bv)) - r, args=(a, b, radius),
        prim_args=(*av, *bv, r), exactness="exact", bounds=box_bounds(lo, hi),
    )


def _frustum(name: str, r1: Expr, r2: Expr, h: Expr, args: tuple) -> Shape:
    R = max(mag(r1), mag(r2))
    hl, hh = _lohi(h)

    def f(p: Vec) -> Expr:
        q = Vec((length(Vec((p.x, p.y))), p.z - h * 0.5))
        return trapezoid2(q, r1, r2, h * 0.5)

    return primitive(
        name, f, args=args, prim_args=(r1, r2, h), exactness="exact",
        bounds=box_bounds([-R, -R, min(0.0, hl)], [R, R, max(0.0, hh)]),
    )


@register("primitive3d")
def cone(radius=0.5, height=1.0) -> Shape:
    """Solid cone: base disk of ``radius`` at ``z=0``, apex at ``(0, 0, height)``. **Exact.**"""
    r = size_arg(radius, "cone: radius")
    h = size_arg(height, "cone: height")
    return _frustum("cone", r, as_expr(0.0), h, (radius, height))


@register("primitive3d")
def capped_cone(r1=0.5, r2=0.25, height=1.0) -> Shape:
    """Frustum: radius ``r1`` at ``z=0``, ``r2`` at ``z=height``. **Exact.**"""
    a = size_arg(r1, "capped_cone: r1")
    b = size_arg(r2, "capped_cone: r2")
    h = size_arg(height, "capped_cone: height")
    return _frustum("capped_cone", a, b, h, (r1, r2, height))


@register("primitive3d")
def round_cone(r1=0.5, r2=0.25, height=1.0) -> Shape:
    """Convex hull of a sphere ``r1`` at the origin and a sphere ``r2`` at
    ``(0, 0, height)``; requires ``r1, r2 >= 0`` and ``|r1 - r2| < height`` (so
    ``height > 0``). **Exact.**"""
    a = size_arg(r1, "round_cone: r1")
    b = size_arg(r2, "round_cone: r2")
    h = size_arg(height, "round_cone: height", positive=True)
    for v in (r1, r2, height):
        if isinstance(v, Expr):
            break
    else:
        if abs(float(r1) - float(r2)) >= float(height):
            raise ShapeError("round_cone: |r1 - r2| must be smaller than height")
    R = max(mag(a), mag(b))

    def f(p: Vec) -> Expr:
        q = Vec((length(Vec((p.x, p.y))), p.z))
        bb = (a - b) / h
        aa = sqrt(1.0 - bb * bb)
        k = dot(q, (-bb, aa))
        side = dot(q, (aa, bb)) - a
        top = length(Vec((q.x, q.y - h))) - b
        return select_ge(-k, length(q) - a, select_ge(k - aa * h, top, side))

    return primitive(
        "round_cone", f, args=(r1, r2, height), prim_args=(a, b, h), exactness="exact",
        bounds=box_bounds([-R, -R, -mag(a)], [R, R, mag(h) + mag(b)]),
    )


@register("primitive3d")
def torus(major=0.5, minor=0.15) -> Shape:
    """Torus around the z axis: tube of radius ``minor`` around a circle of radius
    ``major`` in the xy plane. **Exact.**"""
    R = size_arg(major, "torus: major")
    r = size_arg(minor, "torus: minor")
    e = mag(R) + mag(r)
    return primitive(
        "torus", lambda p: length(Vec((length(Vec((p.x, p.y))) - R, p.z))) - r,
        args=(major, minor), prim_args=(R, r), exactness="exact",
        bounds=box_bounds([-e, -e, -mag(r)], [e, e, mag(r)]),
    )


@register("primitive3d")
def capped_torus(major=0.5, minor=0.15, angle=math.pi / 2) -> Shape:
    """Arc of a torus (as :func:`torus`) whose centre circle spans azimuths within
    ``angle`` radians of the +y direction, with round end caps. **Exact.**"""
    R = size_arg(major, "capped_torus: major")
    r = size_arg(minor, "capped_torus: minor")
    a = scalar_arg(angle, "capped_torus: angle")
    from ..expr import cos, sin

    e = mag(R) + mag(r)

    def f(p: Vec) -> Expr:
        sx, cy = sin(a), cos(a)
        px = abs(p.x)
        k = select_ge(cy * px - sx * p.y, px * sx + p.y * cy, length(Vec((p.x, p.y))))
        d2 = maximum(length2(p) + R * R - 2.0 * R * k, 0.0)
        return sqrt(d2) - r

    return primitive(
        "capped_torus", f, args=(major, minor, angle), prim_args=(R, r, a), exactness="exact",
        bounds=box_bounds([-e, -e, -mag(r)], [e, e, mag(r)]),
    )


@register("primitive3d")
def link(length=1.0, major=0.3, minor=0.1) -> Shape:  # noqa: F811 (shadows vec.length)
    """Chain link in the xy plane: a tube of radius ``minor`` around two half circles of
    radius ``major`` centred at ``(0, +-length/2, 0)`` joined by straight parts. **Exact.**"""
    le = size_arg(length, "link: length")
    R = size_arg(major, "link: major")
    r = size_arg(minor, "link: minor")
    ex = mag(R) + mag(r)
    ey = mag(le) / 2 + ex

    def f(p: Vec) -> Expr:
        qy = maximum(abs(p.y) - le * 0.5, 0.0)
        return _vlen(Vec((_vlen(Vec((p.x, qy))) - R, p.z))) - r

    return primitive(
        "link", f, args=(length, major, minor), prim_args=(le, R, r), exactness="exact",
        bounds=box_bounds([-ex, -ey, -mag(r)], [ex, ey, mag(r)]),
    )


def _unit(n: tuple[Expr, ...], what: str) -> Vec:
    if all(c.op == "const" for c in n):
        v = np.array([float(c.value) for c in n])  # type: ignore[arg-type]
        norm = float(np.linalg.norm(v))
        if not norm > 0:
            raise ShapeError(f"{what} must not be the zero vector")
        return Vec(tuple(v / norm))
    nv = Vec(n)
    return nv / length(nv)


@register("primitive3d")
def plane(normal=(0.0, 0.0, 1.0), offset=0.0) -> Shape:
    """Half-space ``dot(p, n) <= offset`` with ``n = normal/|normal|``. **Exact.**"""
    n = _unit(vector_arg(normal, 3, "plane: normal"), "plane: normal")
    d = scalar_arg(offset, "plane: offset")
    return primitive(
        "plane", lambda p: dot(p, n) - d, args=(normal, offset), prim_args=(*n.c, d),
        exactness="exact", bounds=None,
    )


@register("primitive3d")
def slab(thickness=0.1, normal=(0.0, 0.0, 1.0)) -> Shape:
    """Slab ``|dot(p, n)| <= thickness/2`` between two parallel planes. **Exact.**"""
    t = size_arg(thickness, "slab: thickness")
    n = _unit(vector_arg(normal, 3, "slab: normal"), "slab: normal")
    return primitive(
        "slab", lambda p: abs(dot(p, n)) - t * 0.5, args=(thickness, normal),
        prim_args=(t, *n.c), exactness="exact", bounds=None,
    )


@register("primitive3d")
def ellipsoid(radii=(0.5, 0.3, 0.2)) -> Shape:
    """Ellipsoid with semi-axes ``radii`` (each > 0), as
    ``(|p / radii| - 1) * min(radii)``. **Bound** (exact on the surface and along the
    axes)."""
    r = size_vector(radii, 3, "ellipsoid: radii", broadcast=True, positive=True)
    rv = Vec(r)
    m = [mag(c) for c in r]
    return primitive(
        "ellipsoid", lambda p: (length(p / rv) - 1.0) * rv.min_comp(), args=(radii,),
        prim_args=r, exactness="bound", bounds=box_bounds([-v for v in m], m),
    )


@register("primitive3d")
def octahedron(size=0.5) -> Shape:
    """Regular octahedron ``|x| + |y| + |z| <= size`` (vertices at distance ``size``),
    as ``(|x| + |y| + |z| - size) / sqrt(3)``. **Bound** (exact near the faces)."""
    s = size_arg(size, "octahedron: size")
    return primitive(
        "octahedron", lambda p: (abs(p.x) + abs(p.y) + abs(p.z) - s) * (1.0 / SQRT3),
        args=(size,), prim_args=(s,), exactness="bound", bounds=_cube(mag(s)),
    )


@register("primitive3d")
def pyramid(height=1.0, base=1.0) -> Shape:
    """Square pyramid: base of side ``base`` (> 0) centred at ``z=0``, apex at
    ``(0, 0, height)`` (``height >= 0``; 0 gives the flat base square). **Exact.**"""
    h = size_arg(height, "pyramid: height")
    b = size_arg(base, "pyramid: base", positive=True)
    B = mag(b) / 2
    hl, hh = _lohi(h)

    def f(p: Vec) -> Expr:
        q = p / b
        hn = h / b
        m2 = hn * hn + 0.25
        ax, ay = abs(q.x), abs(q.y)
        px = maximum(ax, ay) - 0.5
        pz = minimum(ax, ay) - 0.5
        py = q.z
        qx = pz
        qy = hn * py - 0.5 * px
        qz = hn * px + 0.5 * py
        s = maximum(-qx, 0.0)
        t = minimum(maximum((qy - 0.5 * pz) / (m2 + 0.25), 0.0), 1.0)
        a = m2 * (qx + s) * (qx + s) + qy * qy
        c = m2 * (qx + 0.5 * t) * (qx + 0.5 * t) + (qy - m2 * t) * (qy - m2 * t)
        cond = minimum(qy, -qx * m2 - qy * 0.5)
        d2 = select_ge(-cond, minimum(a, c), 0.0)
        sides = sqrt(maximum((d2 + qz * qz) / m2, 0.0)) * sign(maximum(qz, -py))
        # the lateral formula ignores the base: below it the nearest point is on the base
        # square; inside, the base may be nearer than the sides
        under = length(Vec((Vec((ax, ay)) - 0.5).max(0.0).c + (q.z,)))
        exact = select_ge(q.z, maximum(sides, -q.z), under)
        # the base's and the four sides' planes first (a convex solid: see edges_first)
        planes = maximum(-q.z, (hn * maximum(ax, ay) + 0.5 * q.z - 0.5 * hn) / sqrt(m2))
        return edges_first(planes, exact, 1.0 + abs(hn)) * b

    return primitive(
        "pyramid", f, args=(height, base), prim_args=(h, b), exactness="exact",
        bounds=box_bounds([-B, -B, min(0.0, hl)], [B, B, max(0.0, hh)]),
    )


def _prism(d2: Expr, p: Vec, h: Expr) -> Expr:
    return box_distance(Vec((d2, abs(p.z) - h * 0.5)))


@register("primitive3d")
def hex_prism(radius=0.5, height=1.0) -> Shape:
    """Hexagonal prism: regular hexagon of circumradius ``radius`` with a vertex on +x,
    ``z`` in ``[-height/2, height/2]``. **Exact.**"""
    r = size_arg(radius, "hex_prism: radius")
    h = size_arg(height, "hex_prism: height")
    R, H = mag(r), mag(h) / 2
    return primitive(
        "hex_prism", lambda p: _prism(hexagon2(p, r * (SQRT3 / 2.0)), p, h),
        args=(radius, height), prim_args=(r, h), exactness="exact",
        bounds=box_bounds([-R, -R, -H], [R, R, H]),
    )


@register("primitive3d")
def tri_prism(radius=0.5, height=1.0) -> Shape:
    """Triangular prism: equilateral triangle of circumradius ``radius`` (centroid at the
    origin, a vertex on +y), ``z`` in ``[-height/2, height/2]``. **Exact.**"""
    r = size_arg(radius, "tri_prism: radius")
    h = size_arg(height, "tri_prism: height")
    R, H = mag(r), mag(h) / 2
    return primitive(
        "tri_prism", lambda p: _prism(equilateral_triangle2(p, r), p, h),
        args=(radius, height), prim_args=(r, h), exactness="exact",
        bounds=box_bounds([-R, -R, -H], [R, R, H]),
    )
