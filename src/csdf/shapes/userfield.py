"""Fields written as math: :func:`field` (an expression in x, y, z), the first-order
distance of the paper's Eq. 11 (:func:`normalized`: ``f / |grad f|``), a user's own
domain map (:func:`remap`), and catalogue entries written that way (:func:`gyroid`,
:func:`superquadric`, :func:`tanglecube`).

In Python the coordinates are ``csdf.x``, ``csdf.y``, ``csdf.z`` (expressions with the
usual operators and the math functions of :mod:`csdf.expr`), or a function of three
arguments is called with them::

    ball = csdf.field(csdf.sqrt(csdf.x**2 + csdf.y**2 + csdf.z**2) - 1, exact=True)
    blob = csdf.field(lambda x, y, z: x * x + y * y + z * z - 1).normalized()

In a ``.csdf`` model the names ``x``, ``y`` and ``z`` mean the coordinates inside the
arguments of ``field(...)`` and ``.remap(...)`` only (elsewhere they are unknown names,
so no other argument can depend on the position)::

    param r = 1 in [0.5, 2]
    export field(sqrt(x * x + y * y + z * z) - r, exact = 1)

**Contracts.** A field is ``'neither'`` unless its author vouches: ``exact=True`` (the
exact distance), or ``lipschitz=L`` (``|grad f| <= L``; a ``'bound'`` when ``L <= 1``,
since then ``f`` never overestimates the distance). Without a declared bound its
Lipschitz bound is found by interval arithmetic of its symbolic gradient over its
``bounds`` (:func:`interval_lipschitz`; ``inf`` without bounds), so that sphere tracing
steps safely. :func:`normalized` and :func:`remap` are ``'neither'`` with an unknown
bound.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..errors import ShapeError
from ..expr import Expr, X, Y, Z, as_expr, cos, maximum, minimum, select_ge, sin, sqrt, walk
from ..exprgrad import gradient
from ..interval import expr_box_ranges
from ..vec import Vec
from .base import Shape, register
from .exprfield import expr_dim, expr_shape, substitute

__all__ = ["field", "normalized", "remap", "gyroid", "superquadric", "tanglecube",
           "interval_lipschitz", "interval_bounds", "GRAD_FLOOR", "LIPSCHITZ_CELLS",
           "BOUNDS_SEARCH"]

#: ``normalized`` divides by ``max(|grad f|, GRAD_FLOOR)`` (where the gradient
#: vanishes the result is ``f / GRAD_FLOOR``: large, with the sign of ``f``)
GRAD_FLOOR = 1e-12


#: the bounds box is cut into this many cells a side for :func:`interval_lipschitz`
LIPSCHITZ_CELLS = 8


def interval_lipschitz(e: Expr, bounds: np.ndarray, cells: int = LIPSCHITZ_CELLS
                       ) -> float:
    """An upper bound of ``|grad e|`` over the box ``bounds`` (``(2, dim)``): the
    gradient built symbolically (:func:`csdf.exprgrad.gradient`) and bounded by
    interval arithmetic on each of ``cells ** dim`` cells of the box (parameters over
    their ranges); ``inf`` where an interval is unbounded or unknown. A bound over the
    box only, which is where meshing and ray casting evaluate a field."""
    b = np.asarray(bounds, dtype=np.float64)
    dim = b.shape[1]
    g = gradient(e, (X, Y, Z)[:dim])
    edges = [np.linspace(b[0, i], b[1, i], cells + 1) for i in range(dim)]
    idx = np.stack(np.meshgrid(*[np.arange(cells)] * dim, indexing="ij"), -1).reshape(-1, dim)
    lo = np.stack([edges[i][idx[:, i]] for i in range(dim)], axis=1)
    hi = np.stack([edges[i][idx[:, i] + 1] for i in range(dim)], axis=1)
    sq = np.zeros(len(lo))
    for glo, ghi in expr_box_ranges(g, lo, hi):
        with np.errstate(invalid="ignore", over="ignore"):
            m = np.maximum(np.abs(glo), np.abs(ghi))
            if np.any(np.isnan(m)):
                return math.inf
            sq += m * m
    return float(np.sqrt(sq.max()))


#: the box (model units, +- this a side) searched for a field's surface when no bounds
#: are given, and the search's subdivision: levels per round, rounds, most cells kept
BOUNDS_SEARCH = 1000.0
BOUNDS_LEVELS = 5
BOUNDS_ROUNDS = 8
BOUNDS_CELLS = 4096


def interval_bounds(e: Expr, dim: int, extent: float = BOUNDS_SEARCH) -> np.ndarray | None:
    """A box holding the zero set of ``e`` (``(2, dim)``), found by interval arithmetic:
    the cube ``+-extent`` is cut into cells, those whose interval excludes 0 are
    dropped, the rest cut again (:data:`BOUNDS_LEVELS` levels), and the search repeats
    in the box of the cells kept until it stops shrinking. Conservative (intervals
    bound the values). None when the surface reaches the search box (unbounded, like a
    gyroid or a plane), when there is none, or when it is spread over more than
    :data:`BOUNDS_CELLS` cells at the first level."""
    lo, hi = np.full(dim, -float(extent)), np.full(dim, float(extent))
    corners = np.array(np.meshgrid(*[[0.0, 1.0]] * dim, indexing="ij")).reshape(dim, -1).T
    for rnd in range(BOUNDS_ROUNDS):
        clo, chi = lo[None], hi[None]
        for _ in range(BOUNDS_LEVELS):
            half = 0.5 * (chi - clo)
            nlo = (clo[:, None, :] + corners[None] * half[:, None, :]).reshape(-1, dim)
            nhi = nlo + np.repeat(half, len(corners), axis=0)
            flo, fhi = expr_box_ranges([e], nlo, nhi)[0]
            keep = ~((flo > 0) | (fhi < 0))  # may hold the surface (NaN: unknown, kept)
            if not keep.any():
                return None
            clo, chi = nlo[keep], nhi[keep]
            if len(clo) > BOUNDS_CELLS:
                if rnd == 0:
                    return None
                break
        new_lo, new_hi = clo.min(axis=0), chi.max(axis=0)
        if rnd == 0 and (np.any(new_lo <= lo) or np.any(new_hi >= hi)):
            return None  # reaches the search box: unbounded as far as we can tell
        if np.allclose(new_lo, lo) and np.allclose(new_hi, hi):
            break
        lo, hi = new_lo, new_hi
    return np.array([lo, hi])


def _coords_expr(expr: Any, what: str) -> Expr:
    if isinstance(expr, Shape):
        raise ShapeError(f"{what}: the field must be an expression in x, y, z, not a "
                         "shape")
    if callable(expr) and not isinstance(expr, Expr):
        try:
            expr = expr(X, Y, Z)
        except TypeError as exc:
            raise ShapeError(f"{what}: a function of the field must take (x, y, z): "
                             f"{exc}") from None
    if isinstance(expr, bool) or not isinstance(expr, (Expr, int, float, np.integer,
                                                       np.floating)):
        raise ShapeError(f"{what}: the field must be an expression in x, y, z (or a "
                         f"function of them), got {type(expr).__name__}")
    e = as_expr(expr)
    if e.op == "const" and not math.isfinite(float(e.value)):  # type: ignore[arg-type]
        raise ShapeError(f"{what}: the field is a non-finite constant")
    return e


def _bounds_arg(bounds: Any, dim: int, what: str) -> np.ndarray | None:
    if bounds is None:
        return None
    try:
        b = np.asarray(bounds, dtype=np.float64)
    except (TypeError, ValueError):
        raise ShapeError(f"{what}: bounds must be numbers ((lo...), (hi...))") from None
    if b.shape != (2, dim) or not np.all(np.isfinite(b)) or not np.all(b[0] < b[1]):
        raise ShapeError(f"{what}: bounds must be ((lo...), (hi...)) with {dim} finite "
                         f"values each and lo < hi, got {bounds!r}")
    return b


@register("primitive3d")
def field(expr=None, exact=False, lipschitz=None, bounds=None, normalize=False) -> Shape:
    """The field given by ``expr``, an expression in ``x``, ``y``, ``z`` (a 2D field
    when it does not use ``z``), or a function ``f(x, y, z)`` returning one; parameters
    (``csdf.param``) may appear in it.

    Args:
        expr: the field (default: the unit sphere ``sqrt(x^2 + y^2 + z^2) - 1``).
        exact: the author vouches that it is the exact signed distance.
        lipschitz: the author's bound of ``|grad f|`` (``'bound'`` contract when
            ``<= 1``, else ``'neither'``); default unknown (``inf``).
        bounds: ``((lo...), (hi...))`` a box holding the surface; None: found by
            interval arithmetic (:func:`interval_bounds`), or unknown when the surface
            is unbounded (meshing and rendering then ask for ``bounds=``).
        normalize: return :func:`normalized` of the field (Eq. 11: ``f / |grad f|``).

    **Neither** unless declared (see the module documentation).
    """
    e = _coords_expr(sqrt(X * X + Y * Y + Z * Z) - 1.0 if expr is None else expr, "field")
    dim = expr_dim(e)
    if isinstance(exact, bool):
        ex = exact
    elif isinstance(exact, (int, float)) and exact in (0, 1):
        ex = bool(exact)  # (the language has no booleans: 0 or 1)
    else:
        raise ShapeError(f"field: exact must be true or false (1 or 0), got {exact!r}")
    b = _bounds_arg(bounds, dim, "field")
    given = b is not None
    if b is None:
        b = interval_bounds(e, dim)
    if lipschitz is None:
        lip, label = (1.0, "exact") if ex else (math.inf, "neither")
        if not ex and b is not None:  # the bound over the box, by intervals
            lip = interval_lipschitz(e, b)
    else:
        if isinstance(lipschitz, bool) or not isinstance(lipschitz, (int, float)) or \
                not lipschitz > 0 or math.isnan(lipschitz):
            raise ShapeError(f"field: lipschitz must be a positive number, got {lipschitz!r}")
        lip = float(lipschitz)
        label = "exact" if ex else ("bound" if lip <= 1.0 else "neither")
    kwargs: dict = {}
    if exact:
        kwargs["exact"] = 1
    if lipschitz is not None:
        kwargs["lipschitz"] = lip
    if given:
        kwargs["bounds"] = [list(map(float, b[0])), list(map(float, b[1]))]
    out = expr_shape(e, dim=dim, name="field", args=(e,), kwargs=kwargs, exactness=label,
                     lipschitz=lip, bounds=b)
    if isinstance(normalize, bool) or normalize in (0, 1):
        return normalized(out) if normalize else out
    raise ShapeError(f"field: normalize must be true or false (1 or 0), got {normalize!r}")


@register("method")
def normalized(shape: Shape, far=None) -> Shape:
    """The first-order distance of the paper's Eq. 11: ``f / |grad f|``, with the
    gradient built from the same expression (forward mode, :func:`csdf.exprgrad.
    gradient`), so it is exact on the surface wherever ``grad f != 0`` and its error
    grows with the distance as the curvature of the level sets dictates. Where the
    gradient vanishes it divides by :data:`GRAD_FLOOR` instead.

    ``far``: a shape holding this one (a bounding sphere or box); outside it (where
    its field is >= 0) its value is used instead, as the paper suggests: far from the
    surface Eq. 11 is unreliable, and the distance to a shape around the object is a
    lower bound of the distance to the object. **Neither**."""
    if not isinstance(shape, Shape):
        raise ShapeError(f"normalized is a shape method; got {type(shape).__name__}")
    if far is not None and (not isinstance(far, Shape) or far.dim != shape.dim):
        raise ShapeError(f"normalized: far must be a {shape.dim}D shape around this one")
    e = shape.expr
    g = gradient(e, (X, Y, Z)[: shape.dim])
    norm = sqrt(sum((c * c for c in g[1:]), g[0] * g[0]))
    out = e / maximum(norm, GRAD_FLOOR)

    def fn(p: Vec, ctx) -> Expr:
        v = substitute(out, p.c)
        if far is None:
            return v
        fv = far.sdf(p, ctx)
        return select_ge(fv, fv, v)

    bounds = shape.bounds if far is None else far.bounds
    return Shape("normalized", fn, dim=shape.dim, exactness="neither", lipschitz=math.inf,
                 bounds=bounds, args=(), kwargs={} if far is None else {"far": far},
                 children=(shape,) if far is None else (shape, far))


@register("method")
def remap(shape: Shape, x=None, y=None, z=None) -> Shape:
    """The shape evaluated at new coordinates: ``f(X(p), Y(p), Z(p))`` with the given
    expressions in ``x``, ``y``, ``z`` (those not given stay as they are): a user's own
    twist, shear or warp. **Neither**; Lipschitz bound unknown (``inf``); bounds
    unknown (pass ``bounds=`` to consumers, or intersect with a bounded shape)."""
    if not isinstance(shape, Shape):
        raise ShapeError(f"remap is a shape method; got {type(shape).__name__}")
    given = {"x": x, "y": y, "z": z}
    maps = []
    kwargs = {}
    for i, (name, v) in enumerate(given.items()):
        if i >= shape.dim:
            if v is not None:
                raise ShapeError(f"remap: a {shape.dim}D shape has no {name}")
            continue
        if v is None:
            maps.append((X, Y, Z)[i])
            continue
        e = _coords_expr(v, f"remap {name}")
        maps.append(e)
        kwargs[name] = e
    if not kwargs:
        return shape
    uses_z = any(n is Z for m in maps for n in walk(m))
    if shape.dim == 2 and uses_z:
        raise ShapeError("remap: a 2D shape's new coordinates may not use z")

    def fn(p: Vec, ctx) -> Expr:
        q = [substitute(m, p.c) for m in maps]
        return shape.sdf(Vec(tuple(q)), ctx)

    return Shape("remap", fn, dim=shape.dim, exactness="neither", lipschitz=math.inf,
                 bounds=None, kwargs=kwargs, children=(shape,))


def _catalogue(name: str, e: Expr, args: tuple, lipschitz: float, bounds, label: str
               ) -> Shape:
    if math.isinf(lipschitz) and bounds is not None:
        lipschitz = interval_lipschitz(e, bounds)
    return expr_shape(e, dim=3, name=name, args=args, exactness=label, lipschitz=lipschitz,
                      bounds=bounds)


@register("primitive3d")
def gyroid(period=1.0, thickness=0.1) -> Shape:
    """The gyroid sheet ``|sin(kx) cos(ky) + sin(ky) cos(kz) + sin(kz) cos(kx)| / k -
    thickness / 2`` with ``k = 2 pi / period`` (a triply periodic minimal surface
    thickened to a wall; unbounded: intersect it with a box). **Neither**; Lipschitz
    bound ``2 sqrt(3)`` (each partial derivative of the sum over ``k`` is at most 2 in
    magnitude)."""
    from .base import size_arg

    per = size_arg(period, "gyroid: period")
    t = size_arg(thickness, "gyroid: thickness")
    k = 2.0 * math.pi / per
    s = sin(k * X) * cos(k * Y) + sin(k * Y) * cos(k * Z) + sin(k * Z) * cos(k * X)
    e = abs(s) / k - t * 0.5
    return _catalogue("gyroid", e, (period, thickness), 2.0 * math.sqrt(3.0), None,
                      "neither")


@register("primitive3d")
def superquadric(radii=(0.5, 0.5, 0.5), e1=1.0, e2=1.0) -> Shape:
    """The superquadric (superellipsoid) with semi-axes ``radii`` and shape exponents
    ``e1`` (north-south) and ``e2`` (east-west): the inside-outside function of Barr
    ``F = ((|x/a|^(2/e2) + |y/b|^(2/e2))^(e2/e1) + |z/c|^(2/e1))``, as the field
    ``(F^(e1/2) - 1) * min(a, b, c)`` (zero on the surface, negative inside; the
    radial scaling makes it exact on the axes of a sphere). Exponents in ``[0.1, 4]``.
    **Neither**."""
    from .base import size_arg, size_vector

    r = size_vector(radii, 3, "superquadric: radii", broadcast=True)
    a1 = size_arg(e1, "superquadric: e1")
    a2 = size_arg(e2, "superquadric: e2")
    for v, nm in ((a1, "e1"), (a2, "e2")):
        if v.op == "const" and not 0.1 <= float(v.value) <= 4.0:  # type: ignore[arg-type]
            raise ShapeError(f"superquadric: {nm} must be in [0.1, 4], got {float(v.value)}")

    def pw(base: Expr, p: Expr) -> Expr:  # base >= 0: base ** p, 0 at 0
        from ..expr import exp, log

        return exp(p * log(maximum(base, 1e-300)))

    from ..expr import make

    ax, ay, az = (make("abs", c) for c in (X / r[0], Y / r[1], Z / r[2]))
    f = pw(pw(ax, 2.0 / a2) + pw(ay, 2.0 / a2), a2 / a1) + pw(az, 2.0 / a1)
    e = (pw(f, a1 * 0.5) - 1.0) * minimum(minimum(r[0], r[1]), r[2])
    m = [abs(float(c.value)) if c.op == "const" else math.inf for c in r]  # type: ignore[arg-type]
    b = None if not all(math.isfinite(v) for v in m) else np.array([[-m[0], -m[1], -m[2]],
                                                                    [m[0], m[1], m[2]]])
    return _catalogue("superquadric", e, (radii, e1, e2), math.inf, b, "neither")


@register("primitive3d")
def tanglecube(scale=1.0) -> Shape:
    """The tangle cube ``x^4 - 5x^2 + y^4 - 5y^2 + z^4 - 5z^2 + 11.8 = 0`` in units of
    ``scale`` (a genus-5 algebraic surface, a classic implicit test), as the
    polynomial times ``scale / 12`` (its gradient is about 12 on the surface at scale 1,
    so the field is of the order of a distance there; it is not one). **Neither**."""
    from .base import size_arg

    s = size_arg(scale, "tanglecube: scale")
    u, v, w = X / s, Y / s, Z / s
    u2, v2, w2 = u * u, v * v, w * w
    e = (u2 * u2 - 5.0 * u2 + v2 * v2 - 5.0 * v2 + w2 * w2 - 5.0 * w2 + 11.8) * (s / 12.0)
    lim = 3.0 * (float(s.value) if s.op == "const" else math.inf)  # type: ignore[arg-type]
    b = None if not math.isfinite(lim) else np.array([[-lim] * 3, [lim] * 3])
    return _catalogue("tanglecube", e, (scale,), math.inf, b, "neither")
