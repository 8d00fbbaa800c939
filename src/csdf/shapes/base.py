"""The :class:`Shape` node, argument coercion, exactness rules and the API registry.

A shape is a *call-level* tree: each node remembers the public function that made
it (``name``, ``args``, ``kwargs``) and its child shapes, so it can be printed back
as a model file, and it knows how to build its scalar expression at any coordinate
vector (``sdf(p)``). No backend knows what a box is: they all see the expression.

Exactness contract (hg_sdf's): every shape carries

* ``exactness``: ``'exact'`` (the Euclidean signed distance to its surface),
  ``'bound'`` (never overestimates the distance to its own zero set: the function is
  continuous with Lipschitz constant <= 1), or ``'neither'``;
* ``lipschitz``: an upper bound of ``|grad f|``. Where a deformation makes this depend
  on the region (twist, bend, taper), it holds inside the child's bounding box, and it
  is ``inf`` when no bound is known. Consumers divide step sizes by it.

Parameters in arguments: bounding boxes and Lipschitz bounds hold for every value
of a parameter in ``[lo, hi]`` when both are finite, otherwise at its default.

Sizes (radii, half-sizes, heights, thicknesses) are checked by :func:`size_arg`: a
negative size is a :class:`~csdf.errors.ShapeError`; for a parameter expression, when
its value at the parameters' defaults is negative. A zero size
is allowed where the formula stays finite: the shape is then degenerate (a point, a
segment, a flat sheet) and its field is still the distance to that set; where a size
divides (ellipsoid radii, pyramid base, round_cone height) it must be > 0.

Size limits while building (so that a small model text cannot take minutes and
gigabytes): :data:`MAX_EXPANSION` evaluations of shape nodes once the shape DAG is
unfolded (checked before anything is built), and :data:`MAX_EXPR_NODES` expression
nodes created while building (counted as they are made).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import CsdfError, ShapeError
from ..expr import Expr, Param, X, Y, Z, as_expr, describe_number, expr_params, node_budget
from ..interval import expr_range
from ..ops import numpy_impl
from ..vec import Vec
from .palette import COLOR_NODES

__all__ = [
    "Shape", "BuildContext", "REGISTRY", "ApiEntry", "register", "scalar_arg", "vector_arg",
    "int_arg", "size_arg", "size_vector", "check_size", "derive_exactness", "Bounds",
    "EXACTNESS", "MAX_EXPR_NODES", "MAX_EXPANSION", "walk_shapes",
]

#: The most expression nodes that building one shape may create (shared
#: subexpressions count once; nodes that already exist count not at all). It matches
#: the language's 10^6-instruction limit: every instruction is one node. Counted while
#: building (:meth:`Shape.build`), so an oversized model stops at this size instead of
#: being built whole and then measured.
MAX_EXPR_NODES = 1_000_000

#: The most shape-node evaluations a shape may need once its DAG is unfolded: a shape
#: used in two places is evaluated twice when the two places give it different
#: coordinates, so ``k`` nested levels of ``a | a.translate(v)`` need ``2**k``. Checked
#: in time linear in the number of distinct shape nodes before anything is built, so an
#: exponential model fails at once and in a few MB. Each evaluation makes at least one
#: expression node, usually several, so this is a looser limit than
#: :data:`MAX_EXPR_NODES` for every model with no exponential reuse. (The count
#: assumes every use of a shape has its own coordinates; a shape used twice at the same
#: coordinates within one operator is counted once.)
MAX_EXPANSION = 200_000

EXACTNESS = ("exact", "bound", "neither")
Bounds = "np.ndarray | None"  # (2, dim) array [lo, hi] or None when unbounded/unknown


@dataclass
class BuildContext:
    """State carried while building a shape's expression.

    Attributes:
        calls: primitive invocations seen: ``id(out) -> (name, out, inputs)``.
        memo: ``(id(shape), ids of p) -> Expr`` so a subtree evaluated twice at the same
            coordinates is built once.
    """

    calls: dict[int, tuple[str, Expr, tuple[Expr, ...]]] = field(default_factory=dict)
    memo: dict[tuple, Expr] = field(default_factory=dict)
    #: the evaluation of each shape node, by the ``memo`` key (the colour rule of
    #: :mod:`csdf.colors` walks them from :attr:`root`)
    frames: dict[tuple, Frame] = field(default_factory=dict)
    #: the evaluations under way, innermost last
    stack: list[Frame] = field(default_factory=list)
    #: the evaluation of the shape that was built
    root: Frame | None = None
    #: a colour node (``color``, ``material``, ``color_field``) was built
    colored: bool = False

    def color_rule(self):
        """The built shape's colour rule as expressions
        (:class:`csdf.shapes.colorrule.ColorRule`), or None without colour nodes."""
        from .colorrule import color_rule

        return color_rule(self.root) if self.colored and self.root is not None else None


@dataclass(eq=False)
class Frame:
    """One evaluation of a shape node while building: the node, the coordinates it was
    given, its output, and the evaluations its function made (its children at their
    coordinates, in call order, each once)."""

    shape: Shape
    p: tuple[Expr, ...]
    out: Expr | None = None
    children: list[Frame] = field(default_factory=list)


class Shape:
    """A signed distance field built from primitives and operators.

    Evaluate with ``shape(points)``; compile with ``shape.compile()``. Combine with
    ``|`` (union), ``&`` (intersection), ``-`` (difference) and ``~`` (complement);
    transform with the methods below (``translate``, ``rotate``, ``scale``, ...).

    Attributes:
        name: the public function or method that made this node.
        args, kwargs: its arguments as given (numbers, expressions, tuples, shapes).
        children: child shapes.
        dim: 3, or 2 for planar shapes (a 2D shape evaluated in 3D is its infinite prism).
        exactness: ``'exact' | 'bound' | 'neither'`` (see module docs).
        lipschitz: upper bound of the gradient norm (float, may be inf).
        bounds: ``(2, dim)`` array ``[min, max]`` of the zero set, or None if unbounded.
    """

    __slots__ = (
        "name", "args", "kwargs", "children", "dim", "exactness", "lipschitz", "bounds",
        "_fn", "_primitive", "_expr", "_program",
    )

    def __init__(
        self,
        name: str,
        fn: Callable[[Vec, BuildContext], Expr],
        *,
        dim: int,
        exactness: str,
        lipschitz: float,
        bounds: np.ndarray | None,
        args: tuple = (),
        kwargs: dict | None = None,
        children: tuple[Shape, ...] = (),
        primitive: tuple[Expr, ...] | None = None,
    ):
        if exactness not in EXACTNESS:
            raise ValueError(f"bad exactness {exactness!r}")
        self.name = name
        self.args = args
        self.kwargs = dict(kwargs or {})
        self.children = children
        self.dim = dim
        self.exactness = exactness
        self.lipschitz = float(lipschitz)
        self.bounds = None if bounds is None else np.asarray(bounds, dtype=np.float64)
        self._fn = fn
        self._primitive = primitive
        self._expr: Expr | None = None
        self._program = None

    # ------------------------------------------------------------------ expressions
    def sdf(self, p: Vec, ctx: BuildContext | None = None) -> Expr:
        """The signed distance expression at coordinates ``p`` (a Vec of dim >= self.dim)."""
        ctx = ctx or BuildContext()
        key = (id(self), tuple(id(c) for c in p.c[: self.dim]))
        parent = ctx.stack[-1] if ctx.stack else None
        hit = ctx.memo.get(key)
        if hit is not None:
            frame = ctx.frames.get(key)
            if parent is not None and frame is not None and \
                    all(c is not frame for c in parent.children):
                parent.children.append(frame)
            return hit
        q = Vec(p.c[: self.dim])
        frame = Frame(self, tuple(q.c))
        ctx.stack.append(frame)
        try:
            out = self._fn(q, ctx)
        finally:
            ctx.stack.pop()
        frame.out = out
        ctx.frames[key] = frame
        if parent is None:
            ctx.root = frame
        else:
            parent.children.append(frame)
        if self.name in COLOR_NODES:
            ctx.colored = True
        if self._primitive is not None and out.op not in ("x", "y", "z", "const", "param"):
            ctx.calls.setdefault(id(out), (self.name, out, tuple(q.c) + self._primitive))
        ctx.memo[key] = out
        return out

    def build(self) -> tuple[Expr, BuildContext]:
        """Build the expression at (x, y, z) (or (x, y)); returns it and the context.

        Raises:
            CsdfError: the shape needs more than :data:`MAX_EXPANSION` shape
                evaluations or creates more than :data:`MAX_EXPR_NODES` expression
                nodes ("the model expands to more than N expression nodes").
        """
        n = self.expansion()
        if n > MAX_EXPANSION:
            raise CsdfError(
                f"the model expands to more than {MAX_EXPANSION} shape evaluations once "
                f"its reused shapes are unfolded ({describe_number(n)}; each makes "
                f"expression nodes, at most {MAX_EXPR_NODES} are allowed): a shape reused "
                "at many different placements (for example nested unions of translated "
                "copies, each level doubling) multiplies its size; use "
                "repeat/repeat_polar/mirror or fewer levels"
            )
        ctx = BuildContext()
        p = Vec((X, Y, Z)[: self.dim])
        with node_budget(MAX_EXPR_NODES, "the model"):
            return self.sdf(p, ctx), ctx

    def expansion(self) -> int:
        """Number of shape-node evaluations building this shape needs at most: the size
        of the shape DAG unfolded into a tree, with a child given twice to one node
        counted once (see :data:`MAX_EXPANSION`). Linear time in the distinct nodes."""
        total: dict[int, int] = {}
        stack: list[tuple[Shape, bool]] = [(self, False)]
        while stack:
            node, done = stack.pop()
            if id(node) in total:
                continue
            kids = {id(c): c for c in node.children if isinstance(c, Shape)}
            if done:
                total[id(node)] = 1 + sum(total[k] for k in kids)
                continue
            stack.append((node, True))
            stack.extend((c, False) for k, c in kids.items() if k not in total)
        return total[id(self)]

    @property
    def expr(self) -> Expr:
        """The scalar expression of this shape over x, y, z (cached)."""
        if self._expr is None:
            self._expr = self.build()[0]
        return self._expr

    @property
    def params(self) -> list[Param]:
        """Parameters of this shape, sorted by name."""
        return expr_params(self.expr)

    # ------------------------------------------------------------------ compile / eval
    def compile(self):
        """Compile to a :class:`csdf.Program` (cached on the shape)."""
        if self._program is None:
            from ..compiler.tape import compile_shape

            self._program = compile_shape(self)
        return self._program

    def __call__(self, points, params: dict | None = None, **kw):
        """Signed distances at ``points`` ``(..., 3)``; see :meth:`csdf.Program.__call__`."""
        return self.compile()(points, params, **kw)

    def gradient(self, points, params: dict | None = None, **kw):
        """Spatial gradient ``(..., 3)``; see :meth:`csdf.Program.gradient`."""
        return self.compile().gradient(points, params, **kw)

    def value_and_grad(self, points, params: dict | None = None, **kw):
        """Values and gradients; see :meth:`csdf.Program.value_and_grad`."""
        return self.compile().value_and_grad(points, params, **kw)

    def param_jacobian(self, points, params: dict | None = None, **kw):
        """Derivatives by parameter ``(..., P)``; see :meth:`csdf.Program.param_jacobian`."""
        return self.compile().param_jacobian(points, params, **kw)

    def contains(self, points, params: dict | None = None, **kw):
        """Inside test (``f <= 0``); see :meth:`csdf.Program.contains`."""
        return self.compile().contains(points, params, **kw)

    # ------------------------------------------------------------------ operators
    # ``|`` (union), ``&`` (intersection), ``-`` (difference) and ``~`` (complement) are
    # attached by :mod:`csdf.shapes.csg`, which defines them (so this module does not
    # import it: no cycle).

    def __repr__(self) -> str:
        parts = [repr(a) for a in self.args]
        parts += [f"{k}={v!r}" for k, v in self.kwargs.items()]
        return f"<Shape {self.name}({', '.join(parts)}) dim={self.dim} {self.exactness}>"


# ---------------------------------------------------------------------- the registry
@dataclass(frozen=True)
class ApiEntry:
    """One public modelling function: a primitive, an operator or a shape method."""

    name: str
    kind: str  # 'primitive3d' | 'primitive2d' | 'operator' | 'method'
    fn: Callable[..., Shape]


REGISTRY: dict[str, ApiEntry] = {}


def walk_shapes(shape: Shape):
    """Every node of a shape tree once (a shared subtree once), parents before their
    children, children in order."""
    stack, seen = [shape], set()
    while stack:
        s = stack.pop()
        if id(s) in seen:
            continue
        seen.add(id(s))
        yield s
        stack.extend(reversed(s.children))


def register(kind: str, name: str | None = None):
    """Decorator adding a function to the public modelling API registry."""

    def deco(fn):
        key = name or fn.__name__
        REGISTRY[key] = ApiEntry(key, kind, fn)
        if kind == "method":
            setattr(Shape, key, fn)
        return fn

    return deco


# ---------------------------------------------------------------------- arguments
def scalar_arg(v: Any, what: str) -> Expr:
    """Coerce a number or parameter expression; raise ShapeError naming ``what``."""
    if isinstance(v, Expr):
        if any(n in (X, Y, Z) for n in _leaves(v)):
            raise ShapeError(f"{what} must not depend on x, y or z")
        if v.op == "const" and not math.isfinite(float(v.value)):  # type: ignore[arg-type]
            # a folded constant (the language's ``0/0``, ``1/0``)
            raise ShapeError(f"{what} must be finite, got {float(v.value)}")  # type: ignore[arg-type]
        return v
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
        raise ShapeError(f"{what} must be a number or a parameter, got {type(v).__name__}")
    f = _float(v, what)
    if not math.isfinite(f):
        raise ShapeError(f"{what} must be finite, got {describe_number(v)}")
    return as_expr(f)


def _float(v: Any, what: str) -> float:
    try:
        return float(v)
    except OverflowError:
        raise ShapeError(
            f"{what} is {describe_number(v)}, too large for a float64 number"
        ) from None


def _at_defaults(e: Expr) -> float:
    """Value of a parameter-only expression with every parameter at its default."""
    from ..expr import walk

    vals: dict[int, float] = {}
    with np.errstate(all="ignore"):
        for n in walk(e):
            if n.op == "const":
                vals[id(n)] = float(n.value)  # type: ignore[arg-type]
            elif n.op == "param":
                vals[id(n)] = float(n.value.default)  # type: ignore[union-attr]
            else:
                args = [np.float64(vals[id(a)]) for a in n.args]
                vals[id(n)] = float(numpy_impl(n.op)(*args))
    return vals[id(e)]


def size_arg(v: Any, what: str, *, positive: bool = False) -> Expr:
    """Coerce a size (radius, full or half size, height, thickness) like
    :func:`scalar_arg`, refusing negative values (``positive``: also zero).

    A constant is checked at once. A parameter expression is checked at the
    parameters' defaults (a default lies in its declared range, so a range that is
    wholly negative is refused too). A range that reaches below zero while the default
    is fine is accepted: interval arithmetic over several parameters overestimates
    (``(root - hub) * 0.3`` in the zoo gear), so it cannot prove the size negative.

    Raises:
        ShapeError: naming ``what`` and the offending value or range.
    """
    return check_size(scalar_arg(v, what), what, positive=positive)


def size_vector(
    v: Any, n: int, what: str, *, broadcast: bool = False, positive: bool = False
) -> tuple[Expr, ...]:
    """Coerce an ``n``-vector of sizes like :func:`vector_arg`, checking each component
    as :func:`size_arg` does (named ``what[i]``, or ``what`` for a broadcast scalar)."""
    comps = vector_arg(v, n, what, broadcast=broadcast)
    if broadcast and not isinstance(v, (tuple, list, np.ndarray)):
        check_size(comps[0], what, positive=positive)
        return comps
    return tuple(check_size(c, f"{what}[{i}]", positive=positive) for i, c in enumerate(comps))


def check_size(e: Expr, what: str, *, positive: bool = False) -> Expr:
    """Check a coerced size expression (see :func:`size_arg`); returns it."""
    need = "> 0" if positive else ">= 0"

    def bad(x: float) -> bool:
        return x < 0 or (positive and x == 0)

    if e.op == "const":
        x = float(e.value)  # type: ignore[arg-type]
        if bad(x):
            raise ShapeError(f"{what} must be {need}, got {x:g}")
        return e
    d = _at_defaults(e)
    if bad(d):
        raise ShapeError(f"{what} must be {need}, got {d:g} at the parameters' defaults")
    return e


def _leaves(e: Expr):
    from ..expr import walk

    return (n for n in walk(e) if not n.args)


def vector_arg(v: Any, n: int, what: str, *, broadcast: bool = False) -> tuple[Expr, ...]:
    """Coerce an ``n``-vector (tuple/list/array of numbers or parameters).

    With ``broadcast`` a scalar is repeated ``n`` times.
    """
    if isinstance(v, np.ndarray):
        v = v.tolist()
    if isinstance(v, (tuple, list)):
        if len(v) != n:
            raise ShapeError(f"{what} must have {n} components, got {len(v)}")
        return tuple(scalar_arg(c, f"{what}[{i}]") for i, c in enumerate(v))
    if broadcast:
        e = scalar_arg(v, what)
        return (e,) * n
    raise ShapeError(f"{what} must be a {n}-vector (tuple of {n} numbers), got {type(v).__name__}")


def int_arg(v: Any, what: str, lo: int = 1, hi: int = 10_000) -> int:
    """Coerce a constant integer within ``[lo, hi]`` (counts, sides, steps)."""
    if isinstance(v, Expr):
        if v.op != "const":
            raise ShapeError(f"{what} must be a constant integer, not a parameter expression")
        v = float(v.value)  # type: ignore[arg-type]
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
        raise ShapeError(f"{what} must be an integer, got {type(v).__name__}")
    if isinstance(v, (float, np.floating)):
        f = float(v)
        if not math.isfinite(f):
            raise ShapeError(f"{what} must be a finite integer in [{lo}, {hi}], got {f}")
        if f != math.floor(f):
            raise ShapeError(f"{what} must be an integer, got {f:g}")
        i = int(f)
    else:
        i = int(v)
    if not lo <= i <= hi:
        raise ShapeError(f"{what} must be in [{lo}, {hi}], got {describe_number(i)}")
    return i


def mag(e: Expr) -> float:
    """Largest magnitude of a parameter-only argument (see module docs)."""
    lo, hi = expr_range(e)
    return max(abs(lo), abs(hi))


def derive_exactness(
    children: Sequence[Shape], *, keeps_exact: bool, lipschitz: float, continuous: bool = True
) -> str:
    """Exactness label of an operator node from its children.

    * ``'exact'`` when the operator preserves exact distances and all children are exact;
    * ``'bound'`` when the result is continuous, no child is ``'neither'`` and the
      Lipschitz bound is <= 1 (a 1-Lipschitz function vanishing on its zero set never
      overestimates the distance to it);
    * ``'neither'`` otherwise.
    """
    if keeps_exact and all(c.exactness == "exact" for c in children):
        return "exact"
    if continuous and all(c.exactness != "neither" for c in children) and lipschitz <= 1 + 1e-12:
        return "bound"
    return "neither"


def require_dim(shapes: Sequence[Shape], what: str) -> int:
    """All shapes must share one dimension; return it."""
    for s in shapes:
        if not isinstance(s, Shape):
            raise ShapeError(f"{what} expects shapes, got {type(s).__name__}")
    dims = {s.dim for s in shapes}
    if len(dims) != 1:
        raise ShapeError(
            f"{what} mixes 2D and 3D shapes; extrude or revolve the 2D shape first"
        )
    return dims.pop()


def box_bounds(lo: Sequence[float], hi: Sequence[float]) -> np.ndarray:
    return np.array([lo, hi], dtype=np.float64)


def union_bounds(bs: Sequence[np.ndarray | None]) -> np.ndarray | None:
    if any(b is None for b in bs):
        return None
    arr = np.stack(bs)  # type: ignore[arg-type]
    return np.array([arr[:, 0].min(0), arr[:, 1].max(0)])


def intersect_bounds(bs: Sequence[np.ndarray | None]) -> np.ndarray | None:
    known = [b for b in bs if b is not None]
    if not known:
        return None
    arr = np.stack(known)
    return np.array([arr[:, 0].max(0), arr[:, 1].min(0)])


def radius_of(bounds: np.ndarray | None) -> float:
    """Largest distance from the origin to a point of ``bounds`` (inf if unbounded)."""
    if bounds is None:
        return math.inf
    return float(np.linalg.norm(np.maximum(np.abs(bounds[0]), np.abs(bounds[1]))))
