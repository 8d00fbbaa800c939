"""Hypothesis strategies for csdf, reusable by any test module.

* :func:`param_sets` / :func:`positive_param_sets`: 0-3 named parameters
  (``csdf.param``), each name declared once per example.
* :func:`expr_dags`: random expression DAGs over x, y, z, constants and parameters
  using every op of :data:`csdf.ops.OPS`, with shared subexpressions.
* :func:`shapes`: random shapes built through the public modelling API (primitives,
  CSG with and without blends, domain operations, deformations, 2D sweeps), with
  parameters sometimes in place of numbers.
* :func:`random_csg_tree`: a random union / intersection / difference tree of leaf
  labels (``csdf.infer``'s tree form), from a NumPy generator.
* :func:`points` and :func:`param_values`: evaluation inputs, including the special
  values (signed zeros, huge numbers, infinities, NaN).

Import with ``from . import strategies`` (tests as a package) or ``import strategies``.
"""

from __future__ import annotations

import math

import numpy as np
from hypothesis import reject
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

import csdf
from csdf.expr import Expr, X, Y, Z, const, make, param
from csdf.ops import OPS

__all__ = [
    "UNARY_OPS", "BINARY_OPS", "ALL_OPS", "SPECIAL_FLOATS", "PARAM_NAMES", "constants",
    "param_sets", "positive_param_sets", "expr_dags", "shapes", "shapes_2d", "points",
    "param_values", "random_csg_tree",
]

UNARY_OPS = tuple(sorted(name for name, info in OPS.items() if info.arity == 1))
BINARY_OPS = tuple(sorted(name for name, info in OPS.items() if info.arity == 2))
ALL_OPS = UNARY_OPS + BINARY_OPS

MAX_F = 1.7976931348623157e308
#: finite values that tend to break things: signed zeros, subnormals, huge numbers,
#: exact and inexact fractions, multiples of pi near the poles of tan.
SPECIAL_FLOATS = (
    0.0, -0.0, 1.0, -1.0, 0.5, -0.5, 2.0, -2.0, 3.0, 0.1, -0.1, 1e-300, -1e-300, 5e-324,
    -5e-324, 2.2250738585072014e-308, 1e16, -1e16, 1e300, -1e300, MAX_F, -MAX_F,
    math.pi, -math.pi, math.pi / 2, -math.pi / 2, 1e-8, 7.0,
)
NONFINITE = (math.inf, -math.inf, math.nan)

PARAM_NAMES = ("a", "b", "r", "k_1", "Radius", "_t", "p0", "height")


# ------------------------------------------------------------------------- numbers
def constants(*, allow_nonfinite: bool = True) -> st.SearchStrategy[float]:
    """Constants: small integers, ordinary floats, the special values above, and (when
    ``allow_nonfinite``) infinities and NaN."""
    parts = [
        st.integers(-10, 10).map(float),
        st.floats(-1e3, 1e3, allow_nan=False),
        st.sampled_from(SPECIAL_FLOATS),
        st.floats(allow_nan=False, allow_infinity=False),
    ]
    if allow_nonfinite:
        parts.append(st.sampled_from(NONFINITE))
    return st.one_of(*parts)


@st.composite
def _one_param(draw, name: str, lo_default: float, hi_default: float) -> Expr:
    d = draw(st.floats(lo_default, hi_default, allow_nan=False))
    kind = draw(st.sampled_from(("free", "bounded", "lo", "hi", "tight")))
    if kind == "free":
        return param(name, d)
    if kind == "tight":
        return param(name, d, d, d)
    below = draw(st.floats(0.0, 10.0))
    above = draw(st.floats(0.0, 10.0))
    lo = d - below if kind in ("bounded", "lo") else None
    hi = d + above if kind in ("bounded", "hi") else None
    # d - below may round above d for huge d; clamp so the declaration stays valid
    lo = None if lo is None else min(lo, d)
    hi = None if hi is None else max(hi, d)
    return param(name, d, lo, hi)


@st.composite
def param_sets(draw, max_params: int = 3) -> list[Expr]:
    """0..max_params parameters with distinct names and any finite defaults."""
    names = draw(st.lists(st.sampled_from(PARAM_NAMES), max_size=max_params, unique=True))
    return [draw(_one_param(n, -5.0, 5.0)) for n in names]


@st.composite
def positive_param_sets(draw, max_params: int = 3) -> list[Expr]:
    """Parameters usable as sizes: defaults in [0.2, 1.5], ranges (if any) positive."""
    names = draw(st.lists(st.sampled_from(PARAM_NAMES), max_size=max_params, unique=True))
    out = []
    for n in names:
        d = draw(st.floats(0.2, 1.5))
        if draw(st.booleans()):
            out.append(param(n, d, d * 0.5, d * 2.0))
        else:
            out.append(param(n, d))
    return out


# ------------------------------------------------------------------------- expressions
@st.composite
def expr_dags(
    draw,
    max_depth: int = 6,
    max_params: int = 3,
    ops: tuple[str, ...] = ALL_OPS,
    allow_nonfinite: bool = True,
) -> Expr:
    """A random expression DAG (already folded and interned by ``make``).

    Subexpressions built earlier in the same example are reused now and then, so the
    result is a DAG with sharing, not only a tree.
    """
    params = draw(param_sets(max_params))
    leaf_kinds = ["x", "y", "z", "const"] + (["param"] * 2 if params else [])
    pool: list[Expr] = []

    def leaf() -> Expr:
        kind = draw(st.sampled_from(leaf_kinds))
        if kind == "x":
            return X
        if kind == "y":
            return Y
        if kind == "z":
            return Z
        if kind == "const":
            return const(draw(constants(allow_nonfinite=allow_nonfinite)))
        return draw(st.sampled_from(params))

    def node(depth: int) -> Expr:
        choice = draw(st.integers(0, 9))
        if pool and choice == 0:
            return draw(st.sampled_from(pool))
        if depth <= 0 or choice <= 2:
            return leaf()
        op = draw(st.sampled_from(ops))
        args = [node(depth - 1) for _ in range(OPS[op].arity)]
        e = make(op, *args)
        pool.append(e)
        return e

    depth = draw(st.integers(1, max_depth))
    return node(depth)


# ------------------------------------------------------------------------- shapes
BLENDS = ("smooth", "exponential", "chamfer", "round", "stairs", "columns")


class _Draw:
    """Helpers drawing shape arguments: numbers, or parameters in their place."""

    def __init__(self, draw, params: list[Expr]):
        self.draw = draw
        self.params = params

    def pos(self, lo: float = 0.2, hi: float = 1.5):
        """A positive size: a number or a (positive) parameter expression."""
        d = self.draw
        if self.params and d(st.integers(0, 2)) == 0:
            p = d(st.sampled_from(self.params))
            return p if d(st.booleans()) else p * d(st.floats(0.2, 1.0))
        return d(st.floats(lo, hi))

    def small(self):
        """A small positive value (blend radii, roundings, thicknesses)."""
        return self.pos(0.02, 0.3)

    def signed(self, lo: float = -1.0, hi: float = 1.0):
        """Any value (offsets, angles): a number or a parameter expression."""
        d = self.draw
        if self.params and d(st.integers(0, 2)) == 0:
            p = d(st.sampled_from(self.params))
            return d(st.sampled_from((p, -p, p - 1.0, p * 0.5)))
        return d(st.one_of(st.floats(lo, hi), st.sampled_from((0.0, -0.0, lo, hi))))

    def vec(self, n: int, signed: bool = True):
        return tuple(self.signed() if signed else self.pos() for _ in range(n))

    def blend_kwargs(self) -> dict:
        d = self.draw
        if d(st.booleans()):
            return {}
        kw: dict = {"k": self.small()}
        if d(st.booleans()):
            kw["blend"] = d(st.sampled_from(BLENDS))
            if kw["blend"] in ("stairs", "columns") and d(st.booleans()):
                kw["n"] = d(st.integers(1, 6))
        return kw


def _primitive_3d(a: _Draw):
    d = a.draw
    name = d(st.sampled_from((
        "sphere", "box", "rounded_box", "box_frame", "cylinder", "rounded_cylinder",
        "capsule", "cone", "capped_cone", "round_cone", "torus", "capped_torus", "link",
        "plane", "slab", "ellipsoid", "octahedron", "pyramid", "hex_prism", "tri_prism",
    )))
    if name == "sphere":
        return csdf.sphere(a.pos())
    if name == "box":
        return csdf.box(a.pos() if d(st.booleans()) else a.vec(3, signed=False))
    if name == "rounded_box":
        return csdf.rounded_box(a.vec(3, signed=False), a.small())
    if name == "box_frame":
        return csdf.box_frame(a.pos(), a.small())
    if name == "cylinder":
        return csdf.cylinder(a.pos(), a.pos())
    if name == "rounded_cylinder":
        return csdf.rounded_cylinder(a.pos(), a.pos(), a.small())
    if name == "capsule":
        return csdf.capsule(a.vec(3), a.vec(3), a.small())
    if name == "cone":
        return csdf.cone(a.pos(), a.pos())
    if name == "capped_cone":
        return csdf.capped_cone(a.pos(), a.pos(), a.pos())
    if name == "round_cone":
        return csdf.round_cone(a.small(), a.small(), a.pos(0.7, 1.5))
    if name == "torus":
        return csdf.torus(a.pos(), a.small())
    if name == "capped_torus":
        return csdf.capped_torus(a.pos(), a.small(), a.signed(0.1, 3.0))
    if name == "link":
        return csdf.link(a.pos(), a.pos(), a.small())
    if name == "plane":
        return csdf.plane(d(st.sampled_from(((0.0, 0.0, 1.0), (1.0, 2.0, -0.5)))), a.signed())
    if name == "slab":
        return csdf.slab(a.small(), d(st.sampled_from(((0.0, 1.0, 0.0), (1.0, 1.0, 1.0)))))
    if name == "ellipsoid":
        return csdf.ellipsoid(a.vec(3, signed=False))
    if name == "octahedron":
        return csdf.octahedron(a.pos())
    if name == "pyramid":
        return csdf.pyramid(a.pos(), a.pos())
    if name == "hex_prism":
        return csdf.hex_prism(a.pos(), a.pos())
    return csdf.tri_prism(a.pos(), a.pos())


def _primitive_2d(a: _Draw):
    d = a.draw
    name = d(st.sampled_from((
        "circle", "rectangle", "rounded_rectangle", "regular_polygon", "polygon", "triangle",
        "equilateral_triangle", "hexagon", "ring", "segment", "trapezoid", "rhombus",
        "ellipse",
    )))
    if name == "circle":
        return csdf.circle(a.pos())
    if name == "rectangle":
        return csdf.rectangle(a.pos() if d(st.booleans()) else a.vec(2, signed=False))
    if name == "rounded_rectangle":
        return csdf.rounded_rectangle(a.vec(2, signed=False), a.small())
    if name == "regular_polygon":
        return csdf.regular_polygon(d(st.integers(3, 9)), a.pos())
    if name == "polygon":
        s = a.pos()
        return csdf.polygon(((0.0, s), (-0.5, -0.5), (0.6, -0.4), (0.3, 0.2)))
    if name == "triangle":
        return csdf.triangle((0.0, a.pos()), (-0.5, -0.5), (0.5, -0.4))
    if name == "equilateral_triangle":
        return csdf.equilateral_triangle(a.pos())
    if name == "hexagon":
        return csdf.hexagon(a.pos())
    if name == "ring":
        return csdf.ring(a.pos(), a.small())
    if name == "segment":
        return csdf.segment(a.vec(2), a.vec(2), a.small())
    if name == "trapezoid":
        return csdf.trapezoid(a.pos(), a.pos(), a.pos())
    if name == "rhombus":
        return csdf.rhombus(a.vec(2, signed=False))
    return csdf.ellipse(a.vec(2, signed=False))


def _combine(a: _Draw, children: list):
    d = a.draw
    kind = d(st.sampled_from(("union", "intersection", "difference", "or", "and", "sub")))
    if kind == "or":
        return children[0] | children[1]
    if kind == "and":
        return children[0] & children[1]
    if kind == "sub":
        return children[0] - children[1]
    fn = {"union": csdf.union, "intersection": csdf.intersection,
          "difference": csdf.difference}[kind]
    return fn(*children, **a.blend_kwargs())


def _transform(a: _Draw, s, dim: int):
    d = a.draw
    names = ["translate", "rotate", "scale", "scale_vec", "mirror", "repeat",
             "repeat_mirrored", "repeat_polar", "elongate", "round", "shell", "offset",
             "complement"]
    if dim == 3:
        names += ["twist", "bend", "taper", "orient", "rotate_matrix"]
    name = d(st.sampled_from(names))
    axes = "xyz"[:dim]
    if name == "translate":
        return s.translate(a.vec(dim))
    if name == "rotate":
        if dim == 2:
            return s.rotate(a.signed(-3.2, 3.2))
        axis = d(st.sampled_from(("x", "y", "z", "-y", (1.0, 2.0, 3.0))))
        return s.rotate(a.signed(-3.2, 3.2), axis=axis)
    if name == "rotate_matrix":
        c, sn = math.cos(0.7), math.sin(0.7)
        return s.rotate([[c, -sn, 0.0], [sn, c, 0.0], [0.0, 0.0, 1.0]])
    if name == "scale":
        return s.scale(a.pos(0.3, 2.0))
    if name == "scale_vec":
        return s.scale(a.vec(dim, signed=False))
    if name == "mirror":
        return s.mirror(d(st.sampled_from([axes[0], axes[-1], axes])))
    if name in ("repeat", "repeat_mirrored"):
        spacing = a.pos(0.5, 3.0) if d(st.booleans()) else tuple(
            d(st.sampled_from((0.0, 1.5, 2.5))) for _ in range(dim))
        count = d(st.one_of(st.none(), st.integers(1, 5)))
        return getattr(s, name)(spacing, count)
    if name == "repeat_polar":
        if dim == 2:
            return s.repeat_polar(d(st.integers(1, 8)))
        return s.repeat_polar(d(st.integers(1, 8)), axis=d(st.sampled_from("xyz")))
    if name == "elongate":
        return s.elongate(a.small() if d(st.booleans()) else a.vec(dim, signed=False))
    if name == "round":
        return s.round(a.small())
    if name == "shell":
        return s.shell(a.small())
    if name == "offset":
        return s.offset(a.signed(-0.2, 0.2))
    if name == "complement":
        return ~s
    if name == "twist":
        return s.twist(a.signed(-2.0, 2.0))
    if name == "bend":
        return s.bend(a.signed(-1.0, 1.0))
    if name == "taper":
        return s.taper(a.signed(-0.5, 0.5))
    return s.orient(d(st.sampled_from(("x", "-z", (1.0, 1.0, 0.0)))))


def _shape_tree(a: _Draw, depth: int, dim: int):
    d = a.draw
    choice = d(st.integers(0, 5)) if depth > 0 else 0
    if choice == 0:
        if dim == 3 and d(st.integers(0, 3)) == 0:
            flat = _shape_tree(a, max(depth - 1, 0), 2)
            if d(st.booleans()):
                return csdf.extrude(flat, a.pos())
            return csdf.revolve(flat, a.signed(0.0, 1.0))
        return _primitive_3d(a) if dim == 3 else _primitive_2d(a)
    if choice <= 2:
        n = d(st.integers(2, 3))
        return _combine(a, [_shape_tree(a, depth - 1, dim) for _ in range(n)])
    return _transform(a, _shape_tree(a, depth - 1, dim), dim)


@st.composite
def shapes(draw, max_depth: int = 3, max_params: int = 3, dim: int = 3):
    """A random shape of dimension ``dim`` from the public modelling API."""
    a = _Draw(draw, draw(positive_param_sets(max_params)))
    try:
        return _shape_tree(a, draw(st.integers(0, max_depth)), dim)
    except csdf.ShapeError:  # an argument combination the API rejects: try another one
        reject()


def shapes_2d(max_depth: int = 2, max_params: int = 3):
    """A random planar shape (compiles to a 2D program)."""
    return shapes(max_depth=max_depth, max_params=max_params, dim=2)


# ------------------------------------------------------------------------- inputs
POINT_SPECIALS = (0.0, -0.0, 1.0, -1.0, 0.5, 1e-300, 1e300, -1e300, math.inf, -math.inf,
                  math.nan)


def points(
    dim: int = 3, min_n: int = 1, max_n: int = 12, allow_nonfinite: bool = True
) -> st.SearchStrategy[np.ndarray]:
    """``(N, dim)`` float64 points, mostly in [-3, 3], sometimes special values."""
    specials = POINT_SPECIALS if allow_nonfinite else POINT_SPECIALS[:8]
    elems = st.one_of(st.floats(-3.0, 3.0), st.sampled_from(specials))
    return arrays(np.float64, st.tuples(st.integers(min_n, max_n), st.just(dim)), elements=elems)


@st.composite
def param_values(draw, params, allow_nan: bool = True) -> dict[str, float]:
    """Values for some of ``params`` (a list of :class:`csdf.Param`): the default, a value
    in range, an arbitrary finite value or (rarely) a special one; others left out."""
    out: dict[str, float] = {}
    for p in params:
        kind = draw(st.integers(0, 9))
        if kind <= 2:
            continue
        if kind <= 4:
            out[p.name] = p.default
        elif kind <= 6 and math.isfinite(p.lo) and math.isfinite(p.hi):
            out[p.name] = draw(st.floats(p.lo, p.hi))
        elif kind <= 8:
            out[p.name] = draw(st.floats(-10.0, 10.0))
        else:
            specials = (0.0, -0.0, 1e300, math.inf, -math.inf)
            out[p.name] = draw(st.sampled_from(specials + ((math.nan,) if allow_nan else ())))
    return out


def random_csg_tree(rng: np.random.Generator, labels: list[int]):
    """A random binary CSG tree over the leaf ``labels`` (each once, in order), in
    ``csdf.infer``'s form: an int leaf or ``(op, left, right)`` with ``op`` one of
    union, intersection, difference."""
    if len(labels) == 1:
        return int(labels[0])
    k = int(rng.integers(1, len(labels)))
    op = ("union", "intersection", "difference")[int(rng.integers(3))]
    return (op, random_csg_tree(rng, labels[:k]), random_csg_tree(rng, labels[k:]))
