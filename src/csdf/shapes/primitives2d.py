"""2D primitives in the xy plane, and the sweeps that make solids of them.

A 2D shape evaluated at 3D points ignores z (it is its infinite prism along z, which
keeps its exactness). :func:`extrude` and :func:`revolve` turn it into a bounded solid.

Sizes must be >= 0 (a negative one is a :class:`~csdf.errors.ShapeError`, as for the
3D primitives); zero gives a degenerate shape whose field is still the exact distance to
it (``circle(0)`` is the distance to the origin, ``segment`` with thickness 0 the distance
to the segment), except the ``ellipse`` radii, which divide and must be > 0.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import ShapeError
from ..expr import Expr
from ..interval import expr_range
from ..vec import Vec, length
from .base import (
    Shape,
    box_bounds,
    derive_exactness,
    int_arg,
    mag,
    register,
    scalar_arg,
    size_arg,
    size_vector,
    vector_arg,
)
from .formulas import (
    box_distance,
    equilateral_triangle2,
    hexagon2,
    polygon2,
    regular_polygon2,
    rhombus2,
    segment_distance,
    trapezoid2,
)
from .primitives3d import primitive

__all__ = [
    "circle", "rectangle", "rounded_rectangle", "regular_polygon", "polygon", "triangle",
    "hexagon", "ring", "segment", "trapezoid", "rhombus", "ellipse", "equilateral_triangle",
    "extrude", "revolve", "cross_section",
]


def _square(r: float) -> np.ndarray:
    return box_bounds([-r, -r], [r, r])


def _prim2(name, fn, args, prim_args, bounds, exactness="exact") -> Shape:
    return primitive(
        name, fn, args=args, prim_args=prim_args, exactness=exactness, bounds=bounds, dim=2
    )


@register("primitive2d")
def circle(radius=0.5) -> Shape:
    """Disk of ``radius``. **Exact.**"""
    r = size_arg(radius, "circle: radius")
    return _prim2("circle", lambda p: length(p) - r, (radius,), (r,), _square(mag(r)))


@register("primitive2d")
def rectangle(size=1.0) -> Shape:
    """Axis-aligned rectangle with full side lengths ``size`` (scalar or 2-vector). **Exact.**"""
    s = size_vector(size, 2, "rectangle: size", broadcast=True)
    h = Vec(s) * 0.5
    m = [mag(c) / 2 for c in s]
    return _prim2(
        "rectangle", lambda p: box_distance(p.abs() - h), (size,), s,
        box_bounds([-m[0], -m[1]], m),
    )


@register("primitive2d")
def rounded_rectangle(size=1.0, radius=0.1) -> Shape:
    """Rectangle of outer full size ``size`` with corners rounded by ``radius``. **Exact.**"""
    s = size_vector(size, 2, "rounded_rectangle: size", broadcast=True)
    r = size_arg(radius, "rounded_rectangle: radius")
    h = Vec(s) * 0.5
    m = [mag(c) / 2 for c in s]
    return _prim2(
        "rounded_rectangle", lambda p: box_distance(p.abs() - h + r) - r, (size, radius),
        (*s, r), box_bounds([-m[0], -m[1]], m),
    )


@register("primitive2d")
def regular_polygon(n=5, radius=0.5) -> Shape:
    """Regular ``n``-gon (``n`` a constant integer >= 3) of circumradius ``radius`` with a
    vertex on +y. **Exact.**"""
    k = int_arg(n, "regular_polygon: n", 3, 1000)
    r = size_arg(radius, "regular_polygon: radius")
    return _prim2(
        "regular_polygon", lambda p: regular_polygon2(p, k, r), (n, radius), (r,),
        _square(mag(r)),
    )


def _vertices(vertices, what: str) -> list[tuple[Expr, Expr]]:
    if isinstance(vertices, np.ndarray):
        vertices = vertices.tolist()
    if not isinstance(vertices, (list, tuple)) or len(vertices) < 3:
        raise ShapeError(f"{what} needs a list of at least 3 (x, y) vertices")
    if len(vertices) > 1000:
        raise ShapeError(f"{what} has {len(vertices)} vertices; at most 1000 are allowed")
    vs = [vector_arg(v, 2, f"{what}[{i}]") for i, v in enumerate(vertices)]
    for i in range(len(vs)):
        a, b = vs[i], vs[i - 1]
        if all(c.op == "const" for c in a + b) and all(
            float(u.value) == float(w.value) for u, w in zip(a, b)  # type: ignore[arg-type]
        ):
            raise ShapeError(f"{what}: vertices {i - 1 if i else len(vs) - 1} and {i} coincide")
    return vs


def _poly_bounds(vs) -> np.ndarray:
    rx = [expr_range(v[0]) for v in vs]
    ry = [expr_range(v[1]) for v in vs]
    return box_bounds([min(r[0] for r in rx), min(r[0] for r in ry)],
                      [max(r[1] for r in rx), max(r[1] for r in ry)])


@register("primitive2d")
def polygon(vertices=((0.0, 0.5), (-0.5, -0.5), (0.5, -0.5)), paths=None) -> Shape:
    """Simple polygon with ``vertices`` ``(K, 2)`` in either winding. **Exact.**

    With ``paths`` (a list of index lists into ``vertices``, each a closed loop of at
    least 3), the region is the loops combined even-odd (OpenSCAD's ``polygon``: an inner
    loop is a hole): the distance to the nearest edge of any loop, negative where a ray
    crosses the loops an odd number of times. **Exact.**"""
    if paths is None:
        vs = _vertices(vertices, "polygon: vertices")
        return _prim2(
            "polygon", lambda p: polygon2(p, [Vec(v) for v in vs]), (vertices,),
            tuple(c for v in vs for c in v), _poly_bounds(vs),
        )
    if isinstance(vertices, np.ndarray):
        vertices = vertices.tolist()
    if isinstance(paths, np.ndarray):
        paths = paths.tolist()
    if not isinstance(paths, (list, tuple)) or not paths:
        raise ShapeError("polygon: paths must be a list of index lists")
    if not isinstance(vertices, (list, tuple)):
        raise ShapeError("polygon: vertices must be a list of (x, y) vertices")
    loops = []
    for k, path in enumerate(paths):
        if not isinstance(path, (list, tuple)) or not all(
                isinstance(i, (int, float)) and float(i) == int(i) and 0 <= i < len(vertices)
                for i in path):
            raise ShapeError(f"polygon: paths[{k}] must hold indices of vertices "
                             f"(0..{len(vertices) - 1})")
        loops.append(_vertices([vertices[int(i)] for i in path], f"polygon: paths[{k}]"))
    if sum(len(lp) for lp in loops) > 1000:
        raise ShapeError("polygon: the paths have more than 1000 vertices in all")
    every = [v for lp in loops for v in lp]
    return _prim2(
        "polygon", lambda p: polygon2(p, [[Vec(v) for v in lp] for lp in loops]),
        (vertices, [[int(i) for i in path] for path in paths]),
        tuple(c for v in every for c in v), _poly_bounds(every),
    )


@register("primitive2d")
def triangle(a=(0.0, 0.5), b=(-0.5, -0.5), c=(0.5, -0.5)) -> Shape:
    """Triangle with corners ``a``, ``b``, ``c`` (2-vectors). **Exact.**"""
    vs = _vertices([a, b, c], "triangle")
    return _prim2(
        "triangle", lambda p: polygon2(p, [Vec(v) for v in vs]), (a, b, c),
        tuple(x for v in vs for x in v), _poly_bounds(vs),
    )


@register("primitive2d")
def equilateral_triangle(radius=0.5) -> Shape:
    """Equilateral triangle of circumradius ``radius``, centroid at the origin, a vertex
    on +y. **Exact.**"""
    r = size_arg(radius, "equilateral_triangle: radius")
    return _prim2(
        "equilateral_triangle", lambda p: equilateral_triangle2(p, r), (radius,), (r,),
        _square(mag(r)),
    )


@register("primitive2d")
def hexagon(radius=0.5) -> Shape:
    """Regular hexagon of circumradius ``radius`` with a vertex on +x. **Exact.**"""
    r = size_arg(radius, "hexagon: radius")
    return _prim2(
        "hexagon", lambda p: hexagon2(p, r * (math.sqrt(3.0) / 2.0)), (radius,), (r,),
        _square(mag(r)),
    )


@register("primitive2d")
def ring(radius=0.5, thickness=0.1) -> Shape:
    """Annulus ``| |p| - radius | <= thickness/2``. **Exact.**"""
    r = size_arg(radius, "ring: radius")
    t = size_arg(thickness, "ring: thickness")
    return _prim2(
        "ring", lambda p: abs(length(p) - r) - t * 0.5, (radius, thickness), (r, t),
        _square(mag(r) + mag(t) / 2),
    )


@register("primitive2d")
def segment(a=(-0.5, 0.0), b=(0.5, 0.0), thickness=0.0) -> Shape:
    """Points within ``thickness/2`` of the segment ``a -> b`` (a stadium); with
    thickness 0 the unsigned distance to the segment. **Exact.**"""
    av = vector_arg(a, 2, "segment: a")
    bv = vector_arg(b, 2, "segment: b")
    t = size_arg(thickness, "segment: thickness")
    e = mag(t) / 2
    bb = _poly_bounds([av, bv, av])
    return _prim2(
        "segment", lambda p: segment_distance(p, Vec(av), Vec(bv)) - t * 0.5,
        (a, b, thickness), (*av, *bv, t), bb + np.array([[-e, -e], [e, e]]),
    )


@register("primitive2d")
def trapezoid(r1=0.5, r2=0.25, height=1.0) -> Shape:
    """Isosceles trapezoid, centred: half-width ``r1`` at ``y=-height/2`` and ``r2`` at
    ``y=+height/2``. **Exact.**"""
    a = size_arg(r1, "trapezoid: r1")
    b = size_arg(r2, "trapezoid: r2")
    h = size_arg(height, "trapezoid: height")
    w, hh = max(mag(a), mag(b)), mag(h) / 2
    return _prim2(
        "trapezoid", lambda p: trapezoid2(p, a, b, h * 0.5), (r1, r2, height), (a, b, h),
        box_bounds([-w, -hh], [w, hh]),
    )


@register("primitive2d")
def rhombus(size=(1.0, 0.6)) -> Shape:
    """Rhombus with full diagonals ``size = (sx, sy)`` along x and y. **Exact.**"""
    s = size_vector(size, 2, "rhombus: size", broadcast=True)
    m = [mag(c) / 2 for c in s]
    return _prim2(
        "rhombus", lambda p: rhombus2(p, s[0] * 0.5, s[1] * 0.5), (size,), s,
        box_bounds([-m[0], -m[1]], m),
    )


@register("primitive2d")
def ellipse(radii=(0.5, 0.3)) -> Shape:
    """Ellipse with semi-axes ``radii`` (each > 0) as ``(|p / radii| - 1) * min(radii)``.
    **Bound.**"""
    r = size_vector(radii, 2, "ellipse: radii", broadcast=True, positive=True)
    rv = Vec(r)
    m = [mag(c) for c in r]
    return _prim2(
        "ellipse", lambda p: (length(p / rv) - 1.0) * rv.min_comp(), (radii,), r,
        box_bounds([-m[0], -m[1]], m), exactness="bound",
    )


# ------------------------------------------------------------------------- sweeps
def _require2d(shape, what: str) -> None:
    if not isinstance(shape, Shape):
        raise ShapeError(f"{what} expects a 2D shape, got {type(shape).__name__}")
    if shape.dim != 2:
        raise ShapeError(f"{what} expects a 2D shape (circle, polygon, ...), got a 3D shape")


@register("operator")
def extrude(shape, height=1.0) -> Shape:
    """Extrude a 2D shape along z to ``z`` in ``[-height/2, height/2]``.
    **Exact** when the 2D shape is exact; Lipschitz ``max(L2d, 1)``."""
    _require2d(shape, "extrude")
    h = size_arg(height, "extrude: height")

    def f(p: Vec, ctx) -> Expr:
        d = shape.sdf(Vec((p.x, p.y)), ctx)
        return box_distance(Vec((d, abs(p.z) - h * 0.5)))

    lip = max(shape.lipschitz, 1.0)
    b = shape.bounds
    H = mag(h) / 2
    bounds = None if b is None else box_bounds([b[0, 0], b[0, 1], -H], [b[1, 0], b[1, 1], H])
    return Shape(
        "extrude", f, dim=3, lipschitz=lip, bounds=bounds, args=(shape, height),
        children=(shape,),
        exactness=derive_exactness([shape], keeps_exact=True, lipschitz=lip),
    )


@register("operator")
def revolve(shape, offset=0.0, segments=0, angle=None) -> Shape:
    """Revolve a 2D shape around the z axis: its x becomes the distance from the axis
    minus ``offset`` and its y becomes z. **Exact** when the 2D shape is exact and lies
    in ``x >= -offset``.

    With ``segments = n >= 3`` (a constant integer) the sweep is faceted as CAD tools
    do: ``n`` copies of the section at the angles ``360 k / n`` degrees (the first on
    +x) joined by flat faces, that is the distance from the axis replaced by the
    regular ``n``-gon's gauge ``r cos(d) / cos(pi / n)`` (``d`` the angle from the
    middle of the nearest segment), times ``cos(pi / n)``: a **bound** (exact zero set,
    Lipschitz that of the section) when the section lies in ``x >= -offset``.

    With ``angle`` (radians, a constant with ``0 < |angle| < 2 pi``; None for a full
    turn) only the part swept from +x by that angle is kept (counter-clockwise seen
    from +z; clockwise for a negative angle): the sweep intersected with the exact
    distance to that wedge of the plane, a **bound** (the intersection of two fields
    underestimates outside, near the cut faces' edges)."""
    _require2d(shape, "revolve")
    o = scalar_arg(offset, "revolve: offset")
    n = 0 if isinstance(segments, (int, np.integer)) and not isinstance(segments, bool) \
        and segments == 0 else int_arg(segments, "revolve: segments", 3, 10_000)
    half = math.pi / n if n else 0.0
    cos_half = math.cos(half)
    sweep = None if angle is None else _sweep_angle(angle)

    def radial(p: Vec) -> Expr:
        r = length(Vec((p.x, p.y)))
        if not n:
            return r
        from ..expr import atan2, cos, mod

        d = mod(atan2(p.y, p.x), 2.0 * half) - half  # angle from the segment's middle
        return r * cos(d) * (1.0 / cos_half)

    def f(p: Vec, ctx) -> Expr:
        d = shape.sdf(Vec((radial(p) - o, p.z)), ctx)
        d = d * cos_half if n else d
        if sweep is None:
            return d
        from ..expr import maximum

        return maximum(d, _wedge_distance(p.x, p.y, sweep))

    b = shape.bounds
    if b is None:
        bounds = None
    else:
        R = max(abs(b[0, 0]), abs(b[1, 0])) + mag(o)
        bounds = box_bounds([-R, -R, b[0, 1]], [R, R, b[1, 1]])
    keeps = not n and sweep is None
    lip = shape.lipschitz if sweep is None else max(shape.lipschitz, 1.0)
    kwargs: dict = {"segments": n} if n else {}
    if sweep is not None:
        kwargs["angle"] = angle
    return Shape(
        "revolve", f, dim=3, lipschitz=lip, bounds=bounds,
        args=(shape, offset), kwargs=kwargs or None, children=(shape,),
        exactness=derive_exactness([shape], keeps_exact=keeps, lipschitz=lip),
    )


def _sweep_angle(angle) -> float:
    """A partial turn's angle (radians), checked: a constant, ``0 < |angle| < 2 pi``."""
    if isinstance(angle, Expr):
        if angle.op != "const":
            raise ShapeError("revolve: angle must be a number (the wedge is fixed)")
        angle = angle.value
    if isinstance(angle, bool) or not isinstance(angle, (int, float, np.integer,
                                                         np.floating)):
        raise ShapeError(f"revolve: angle must be a number, got {type(angle).__name__}")
    a = float(angle)
    if not (0.0 < abs(a) < 2.0 * math.pi):
        raise ShapeError(f"revolve: angle must be within (-2 pi, 2 pi) and not 0 "
                         f"(radians; None for a full turn), got {a:g}")
    return a


def _wedge_distance(x: Expr, y: Expr, angle: float) -> Expr:
    """The exact signed distance in the plane to the wedge swept from +x by ``angle``
    (radians; clockwise when negative): the distance to the nearer of its two boundary
    rays, negative inside."""
    from ..expr import maximum, minimum, select_ge, sqrt

    a = abs(angle)
    yy = y if angle > 0 else -y
    c, s = math.cos(a), math.sin(a)
    r2 = x * x + yy * yy

    def ray(t: Expr) -> Expr:  # distance to the ray along a unit u with t = p . u
        tp = maximum(t, 0.0)
        return sqrt(maximum(r2 - tp * tp, 0.0))

    d = minimum(ray(x), ray(x * c + yy * s))
    s1, s2 = yy, x * s - yy * c  # >= 0: on the inner side of the first / last ray
    inside = minimum(s1, s2) if a <= math.pi else maximum(s1, s2)
    return select_ge(inside, -d, d)


@register("operator")
def cross_section(shape, z=0.0) -> Shape:
    """The 2D section of a 3D shape by the plane ``z = z`` (a constant or parameter): the
    field ``f(x, y, z)`` as a field of the plane. Its zero set is the section's
    outline; as a distance in the plane it is a **bound** when ``shape`` is exact or a
    bound (the distance in space to the surface is at most the distance in the plane
    to the section's outline), else neither. OpenSCAD's ``projection(cut = true)``."""
    from .base import require_dim

    if require_dim([shape], "cross_section") != 3:
        raise ShapeError("cross_section: needs a 3D shape")
    zz = scalar_arg(z, "cross_section: z")

    def f(p: Vec, ctx) -> Expr:
        return shape.sdf(Vec((p.x, p.y, zz)), ctx)

    b = shape.bounds
    bounds = None if b is None else np.array([b[0, :2], b[1, :2]])
    return Shape(
        "cross_section", f, dim=2, lipschitz=shape.lipschitz, bounds=bounds,
        args=(shape,), kwargs={"z": z} if not (isinstance(z, (int, float)) and z == 0)
        else None, children=(shape,),
        exactness=derive_exactness([shape], keeps_exact=False,
                                   lipschitz=shape.lipschitz),
    )
