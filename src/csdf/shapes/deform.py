"""Deformations and distance offsets: twist, bend, taper, elongate, round, shell, offset.

Non-isometric deformations cannot keep a distance (paper §3.3, Fig. 7): their results
are labelled **neither**, and their Lipschitz bound is computed from the child's
bounding box (it holds for points inside the deformed shape's bounding box; it is
``inf`` when the child is unbounded). Sphere tracing divides steps by it.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import ShapeError
from ..expr import Expr, cos, maximum, sin
from ..interval import expr_range
from ..vec import Vec
from .base import (
    Shape,
    box_bounds,
    mag,
    radius_of,
    register,
    scalar_arg,
    size_arg,
    size_vector,
)
from .domain import _check, _derived

__all__ = ["twist", "bend", "taper", "elongate", "round_", "shell", "offset"]


def _need3d(shape: Shape, what: str) -> None:
    _check(shape, what)
    if shape.dim != 3:
        raise ShapeError(f"{what} needs a 3D shape")


def _radial(b: np.ndarray | None) -> float:
    if b is None:
        return math.inf
    return float(np.hypot(max(abs(b[0, 0]), abs(b[1, 0])), max(abs(b[0, 1]), abs(b[1, 1]))))


def _stretch(rate: float, radius: float) -> float:
    """``1 + rate * radius``, with a zero rate giving 1 even for an unbounded child."""
    return 1.0 if rate == 0 else 1.0 + rate * radius


def _radial_bounds(b: np.ndarray | None) -> np.ndarray | None:
    if b is None:
        return None
    r = _radial(b)
    return box_bounds([-r, -r, b[0, 2]], [r, r, b[1, 2]])


@register("method")
def twist(shape: Shape, rate) -> Shape:
    """Twist about the z axis: the cross-section at height z turns by ``rate * z`` radians
    (``rate`` in radians per unit length). **Neither**; Lipschitz
    ``L * (1 + |rate| * rho)`` with ``rho`` the child's radius about z."""
    _need3d(shape, "twist")
    k = scalar_arg(rate, "twist: rate")

    def f(p: Vec, ctx) -> Expr:
        a = -k * p.z
        c, s = cos(a), sin(a)
        return shape.sdf(Vec((c * p.x - s * p.y, s * p.x + c * p.y, p.z)), ctx)

    lip = shape.lipschitz * _stretch(mag(k), _radial(shape.bounds))
    return _derived(shape, "twist", f, args=(rate,), keeps_exact=False, lipschitz=lip,
                    bounds=_radial_bounds(shape.bounds), neither=True)


@register("method")
def bend(shape: Shape, rate) -> Shape:
    """Bend in the xz plane: the point at abscissa x turns by ``rate * x`` radians about
    the y axis (``rate`` = curvature, 1/length). **Neither**; Lipschitz
    ``L * (1 + |rate| * R)`` with ``R`` the child's bounding radius."""
    _need3d(shape, "bend")
    k = scalar_arg(rate, "bend: rate")

    def f(p: Vec, ctx) -> Expr:
        a = k * p.x
        c, s = cos(a), sin(a)
        return shape.sdf(Vec((c * p.x + s * p.z, p.y, -s * p.x + c * p.z)), ctx)

    R = radius_of(shape.bounds)
    lip = shape.lipschitz * _stretch(mag(k), R)
    b = None if not math.isfinite(R) else box_bounds([-R] * 3, [R] * 3)
    return _derived(shape, "bend", f, args=(rate,), keeps_exact=False, lipschitz=lip,
                    bounds=b, neither=True)


@register("method")
def taper(shape: Shape, rate) -> Shape:
    """Taper along z: the cross-section at height z is scaled by ``s = 1 + rate * z``
    (clamped to >= 0.001), i.e. ``f(x/s, y/s, z)``; ``rate`` may also be a pair
    ``(rate_x, rate_y)`` scaling x and y apart (OpenSCAD's ``linear_extrude`` with
    ``scale = [sx, sy]``). **Neither**; Lipschitz bound from the smallest ``s`` over
    the child's z range."""
    _need3d(shape, "taper")
    pair = isinstance(rate, (tuple, list, np.ndarray))
    if pair:
        if len(rate) != 2:
            raise ShapeError(f"taper: rate must be a number or a pair (rate_x, rate_y), "
                             f"got {len(rate)} numbers")
        ks = [scalar_arg(r, f"taper: rate[{i}]") for i, r in enumerate(rate)]
    else:
        ks = [scalar_arg(rate, "taper: rate")] * 2

    def f(p: Vec, ctx) -> Expr:
        sx = maximum(1.0 + ks[0] * p.z, 0.001)
        sy = sx if not pair else maximum(1.0 + ks[1] * p.z, 0.001)
        return shape.sdf(Vec((p.x / sx, p.y / sy, p.z)), ctx)

    b = shape.bounds
    if b is None:
        lip, nb = math.inf, None
    else:
        ranges = [expr_range(k) for k in ks]
        ends = [1.0 + kk * z for lo_hi in ranges for kk in lo_hi for z in (b[0, 2], b[1, 2])]
        smin, smax = max(min(ends), 0.001), max(max(ends), 0.001)
        rho = _radial(b)
        kmax = max(mag(k) for k in ks)
        lip = shape.lipschitz * (max(1.0, 1.0 / smin) + kmax * rho / smin)
        r = rho * smax
        nb = box_bounds([-r, -r, b[0, 2]], [r, r, b[1, 2]])
    return _derived(shape, "taper", f, args=(tuple(rate) if pair else rate,),
                    keeps_exact=False, lipschitz=lip, bounds=nb, neither=True)


@register("method")
def elongate(shape: Shape, h) -> Shape:
    """Stretch the shape by inserting a slab of half-widths ``h`` (scalar or per axis,
    each >= 0) at the origin: ``f(p - clamp(p, -h, h))``. **Bound** (exact outside)."""
    _check(shape, "elongate")
    hv = size_vector(h, shape.dim, "elongate: h", broadcast=True)
    H = Vec(hv)

    def f(p: Vec, ctx) -> Expr:
        return shape.sdf(p - p.max(-H).min(H), ctx)

    b = shape.bounds
    if b is not None:
        m = np.array([mag(c) for c in hv])
        b = np.array([b[0] - m, b[1] + m])
    return _derived(shape, "elongate", f, args=(h,), keeps_exact=False, bounds=b)


def _grow(b: np.ndarray | None, d: float) -> np.ndarray | None:
    return None if b is None else np.array([b[0] - d, b[1] + d])


@register("method", name="round")
def round_(shape: Shape, radius) -> Shape:
    """Round the shape by growing it by ``radius`` (>= 0; use :meth:`offset` to shrink):
    ``f - radius``. **Bound** (exact outside when the child is exact)."""
    _check(shape, "round")
    r = size_arg(radius, "round: radius")
    return _derived(shape, "round", lambda p, ctx: shape.sdf(p, ctx) - r, args=(radius,),
                    keeps_exact=False, bounds=_grow(shape.bounds, mag(r)))


@register("method")
def offset(shape: Shape, d) -> Shape:
    """Grow (``d > 0``) or shrink (``d < 0``) the shape: ``f - d``. **Bound**."""
    _check(shape, "offset")
    e = scalar_arg(d, "offset: d")
    return _derived(shape, "offset", lambda p, ctx: shape.sdf(p, ctx) - e, args=(d,),
                    keeps_exact=False, bounds=_grow(shape.bounds, max(0.0, expr_range(e)[1])))


@register("method")
def shell(shape: Shape, thickness) -> Shape:
    """Hollow the shape into a shell of ``thickness`` (>= 0; 0 gives the surface itself)
    centred on its surface: ``|f| - thickness/2``. **Bound**."""
    _check(shape, "shell")
    t = size_arg(thickness, "shell: thickness")
    return _derived(
        shape, "shell", lambda p, ctx: abs(shape.sdf(p, ctx)) - t * 0.5, args=(thickness,),
        keeps_exact=False, bounds=_grow(shape.bounds, mag(t) / 2),
    )
