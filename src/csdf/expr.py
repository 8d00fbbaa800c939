"""Scalar expressions: a hash-consed DAG over x, y, z, constants and named parameters.

Every node is created through :func:`make`, which

* folds constants (all-constant arguments are evaluated right away in float64),
* applies a few algebraic identities that hold for all finite values (``a + 0 -> a``,
  ``a * 1 -> a``, ``a * 0 -> 0``, ``0 - a -> -a``, ``-(-a) -> a``, ``|(-a)| -> |a|``,
  ``min(a, a) -> a`` ...); with infinities or NaN inside an expression, or for the sign
  of zero, they can differ from step-by-step IEEE evaluation (NaN *points* still give
  NaN: the evaluators check for them),
* orders the arguments of commutative ops canonically, and
* interns the node, so structurally equal expressions are the *same* Python object.

Because of interning, common subexpressions are shared automatically and ``is``
is structural equality. Each node also has a deterministic 64-bit structural key
(:attr:`Expr.key`, independent of Python's hash seed) used for canonical ordering.
"""

from __future__ import annotations

import hashlib
import math
import re
import struct
import threading
import weakref
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from .errors import CsdfError, ParamError
from .ops import OPS, numpy_impl

__all__ = [
    "Expr", "Param", "param", "const", "as_expr", "make", "X", "Y", "Z", "Number",
    "sqrt", "square", "sin", "cos", "tan", "asin", "acos", "atan", "atan2", "exp", "log",
    "floor", "step", "sign", "minimum", "maximum", "mod", "clamp", "mix", "select_ge",
    "walk", "expr_params", "is_const", "const_value", "to_float", "describe_number",
    "NodeBudget", "node_budget", "substitute", "mesh_call", "DATA_OPS",
]

#: expression ops that hold a data block in ``value`` (not scalar ops of :data:`OPS`):
#: ``'mesh'``, the signed distance to a :class:`csdf.meshdata.MeshData` at its three
#: arguments
DATA_OPS = frozenset({"mesh"})

Number = int | float
_NAME_RE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
RESERVED_PARAM_NAMES = frozenset({"points", "params", "backend", "dtype", "level",
                                  "check_ranges", "range_hint"})


@dataclass(frozen=True)
class Param:
    """A named shape parameter.

    Attributes:
        name: identifier (letters, digits, underscore; not starting with a digit).
        default: value used when none is given at evaluation time.
        lo, hi: inclusive bounds (``-inf`` / ``inf`` when unbounded). Bounds are used by
            fitting and by user interfaces; evaluation accepts any value.
    """

    name: str
    default: float
    lo: float = -math.inf
    hi: float = math.inf

    def __repr__(self) -> str:
        rng = ""
        if math.isfinite(self.lo) or math.isfinite(self.hi):
            rng = f" in [{self.lo:g}, {self.hi:g}]"
        return f"Param({self.name} = {self.default:g}{rng})"


class Expr:
    """One node of the expression DAG. Create nodes with :func:`make` or operators.

    Attributes:
        op: ``'x' | 'y' | 'z' | 'const' | 'param'`` or an op name from :data:`csdf.ops.OPS`.
        args: child expressions (empty for leaves).
        value: the float of a ``'const'`` node, the :class:`Param` of a ``'param'`` node,
            the :class:`csdf.meshdata.MeshData` of a ``'mesh'`` node.
        key: deterministic 64-bit structural hash.
    """

    __slots__ = ("op", "args", "value", "key", "__weakref__")

    op: str
    args: tuple[Expr, ...]
    value: object
    key: int

    def __init__(self) -> None:  # pragma: no cover - use make()
        raise TypeError("create expressions with csdf.expr.make() or the operators")

    # -- arithmetic -------------------------------------------------------------------
    def __add__(self, o: Expr | Number) -> Expr:
        return make("add", self, as_expr(o))

    def __radd__(self, o: Expr | Number) -> Expr:
        return make("add", as_expr(o), self)

    def __sub__(self, o: Expr | Number) -> Expr:
        return make("sub", self, as_expr(o))

    def __rsub__(self, o: Expr | Number) -> Expr:
        return make("sub", as_expr(o), self)

    def __mul__(self, o: Expr | Number) -> Expr:
        return make("mul", self, as_expr(o))

    def __rmul__(self, o: Expr | Number) -> Expr:
        return make("mul", as_expr(o), self)

    def __truediv__(self, o: Expr | Number) -> Expr:
        return make("div", self, as_expr(o))

    def __rtruediv__(self, o: Expr | Number) -> Expr:
        return make("div", as_expr(o), self)

    def __neg__(self) -> Expr:
        return make("neg", self)

    def __pos__(self) -> Expr:
        return self

    def __abs__(self) -> Expr:
        return make("abs", self)

    def __pow__(self, k: int) -> Expr:
        if k == 2:
            return make("square", self)
        if k == 1:
            return self
        if k == 0.5:
            return make("sqrt", self)
        raise TypeError("only e**2, e**1 and e**0.5 are supported; use exp/log otherwise")

    def __bool__(self) -> bool:
        raise TypeError(
            "an expression has no truth value (it may depend on x, y, z or parameters); "
            "use csdf.expr.minimum/maximum/select_ge instead of if/else"
        )

    def __float__(self) -> float:
        if self.op == "const":
            return float(self.value)  # type: ignore[arg-type]
        if self.op == "param":
            return float(self.value.default)  # type: ignore[union-attr]
        raise TypeError(f"expression {self!r} depends on x, y or z; it has no single value")

    # -- parameter-like access (only meaningful for 'param' nodes) ----------------------
    @property
    def name(self) -> str:
        if self.op != "param":
            raise AttributeError("only parameter expressions have a name")
        return self.value.name  # type: ignore[union-attr]

    def __repr__(self) -> str:
        return to_infix(self)

    def __reduce__(self):  # pickling rebuilds through make() so interning holds
        if self.op == "const":
            return (const, (self.value,))
        if self.op == "param":
            p = self.value
            return (param, (p.name, p.default, p.lo, p.hi))  # type: ignore[union-attr]
        if self.op in ("x", "y", "z"):
            return (_leaf, (self.op,))
        if self.op in DATA_OPS:
            return (mesh_call, (self.value, *self.args))
        return (make, (self.op, *self.args))


_INTERN: weakref.WeakValueDictionary[tuple, Expr] = weakref.WeakValueDictionary()


class NodeBudget:
    """A limit on the number of expression nodes created in one thread while it is
    active (see :func:`node_budget`).

    Only nodes that did not exist yet count (interning finds the others), so the count
    is the growth of the DAG: what building costs in time and memory.

    Attributes:
        limit: the most nodes that may be created.
        count: nodes created so far.
        what: how the error names the thing being built (``'the model'``).
    """

    __slots__ = ("limit", "count", "what")

    def __init__(self, limit: int, what: str = "the model"):
        self.limit = int(limit)
        self.count = 0
        self.what = what

    def charge(self) -> None:
        """Count one new node.

        Raises:
            CsdfError: more than :attr:`limit` nodes were created.
        """
        self.count += 1
        if self.count > self.limit:
            raise CsdfError(
                f"{self.what} expands to more than {self.limit} expression nodes; "
                "a shape reused at many different placements (for example nested "
                "unions of translated copies, each level doubling) multiplies its "
                "size; use repeat/repeat_polar/mirror or fewer levels"
            )


class _Active(threading.local):
    budget: NodeBudget | None = None


_ACTIVE = _Active()


class node_budget:  # noqa: N801 (used as a context manager, like a function)
    """Context manager: count the expression nodes created in this thread against
    ``limit`` (an error is raised when it is exceeded). When a budget is already active
    in this thread, the outer one keeps counting and ``limit`` is ignored.

    Example::

        with node_budget(1_000_000):
            e = shape.sdf(p)
    """

    def __init__(self, limit: int, what: str = "the model"):
        self._new = NodeBudget(limit, what)
        self._owner = False

    def __enter__(self) -> NodeBudget:
        if _ACTIVE.budget is not None:
            return _ACTIVE.budget
        _ACTIVE.budget = self._new
        self._owner = True
        return self._new

    def __exit__(self, *exc: object) -> None:
        if self._owner:
            _ACTIVE.budget = None
            self._owner = False


def _float_bits(v: float) -> bytes:
    return struct.pack("<d", v)


def _structural_key(op: str, args: tuple[Expr, ...], value: object) -> int:
    h = hashlib.blake2b(digest_size=8)
    h.update(op.encode())
    for a in args:
        h.update(a.key.to_bytes(8, "little"))
    if op == "const":
        h.update(_float_bits(value))  # type: ignore[arg-type]
    elif op == "param":
        p: Param = value  # type: ignore[assignment]
        h.update(p.name.encode())
        h.update(_float_bits(p.default) + _float_bits(p.lo) + _float_bits(p.hi))
    elif op in DATA_OPS:
        h.update(value.digest.encode())  # type: ignore[attr-defined]
    return int.from_bytes(h.digest(), "little")


def _intern(op: str, args: tuple[Expr, ...], value: object = None) -> Expr:
    if op == "const":
        ident = (op, _float_bits(value))  # type: ignore[arg-type]
    elif op == "param":
        ident = (op, value)
    elif op in DATA_OPS:
        ident = (op, tuple(id(a) for a in args), value.digest)  # type: ignore[attr-defined]
    else:
        ident = (op, tuple(id(a) for a in args))
    node = _INTERN.get(ident)
    if node is not None:
        return node
    budget = _ACTIVE.budget
    if budget is not None:
        budget.charge()
    node = object.__new__(Expr)
    node.op = op
    node.args = args
    node.value = value
    node.key = _structural_key(op, args, value)
    _INTERN[ident] = node
    return node


def _leaf(op: str) -> Expr:
    return _intern(op, ())


X = _leaf("x")
Y = _leaf("y")
Z = _leaf("z")
# keep the coordinate leaves alive forever
_KEEP = (X, Y, Z)


def describe_number(v: object) -> str:
    """Short text of a number for error messages (a huge integer as ``10**400``)."""
    if isinstance(v, (int, np.integer)) and not isinstance(v, bool):
        i = int(v)
        if abs(i) >= 10**20:
            digits = len(str(abs(i))) if abs(i).bit_length() < 10_000 else None
            if digits is None:
                return f"{'-' if i < 0 else ''}2**{abs(i).bit_length() - 1} or more"
            if abs(i) == 10 ** (digits - 1):
                return f"{'-' if i < 0 else ''}10**{digits - 1}"
            return f"{'-' if i < 0 else ''}an integer of {digits} digits"
        return str(i)
    try:
        return f"{float(v):g}"  # type: ignore[arg-type]
    except (TypeError, ValueError, OverflowError):
        return type(v).__name__


def to_float(v: object, what: str, error: type[CsdfError] = CsdfError) -> float:
    """``float(v)`` for a real number (Python or NumPy, not bool), raising ``error``
    naming ``what`` and the value when it is not a number or too large for float64
    (``10**400``). NaN and infinities pass: callers decide about them."""
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
        if not (isinstance(v, np.ndarray) and v.shape == () and v.dtype.kind in "iuf"):
            raise error(f"{what} must be a number, got {type(v).__name__}")
    try:
        return float(v)  # type: ignore[arg-type]
    except OverflowError:
        raise error(
            f"{what} is {describe_number(v)}, too large for a float64 number "
            "(at most about 1.8e308)"
        ) from None


def const(v: Number) -> Expr:
    """A constant node (float64).

    Raises:
        CsdfError: ``v`` is an integer too large for float64.
    """
    try:
        f = float(v)
    except OverflowError:
        raise CsdfError(
            f"the constant {describe_number(v)} is too large for a float64 number"
        ) from None
    return _intern("const", (), f)


def param(name: str, default: Number, lo: Number | None = None, hi: Number | None = None) -> Expr:
    """A named parameter usable wherever a number is (radius, size, angle, ...).

    Args:
        name: identifier, unique within a shape (same name must mean same declaration).
        default: value used when evaluation does not give one.
        lo, hi: optional inclusive bounds; ``default`` must lie within them.

    Returns:
        An :class:`Expr` of op ``'param'``; its :class:`Param` is ``expr.value``.

    Raises:
        ParamError: bad name, non-finite default, or default outside ``[lo, hi]``.
    """
    if not isinstance(name, str) or not _NAME_RE.fullmatch(name):
        raise ParamError(f"parameter name {name!r} is not an identifier ([A-Za-z_][A-Za-z0-9_]*)")
    if name in RESERVED_PARAM_NAMES:
        raise ParamError(f"parameter name {name!r} is reserved; pick another name")
    if len(name) > 255:
        raise ParamError(f"parameter name is longer than 255 characters: {name[:20]}...")
    d = _finite(default, f"default of parameter {name!r}")
    lo_f = -math.inf if lo is None else _number(lo, f"lower bound of parameter {name!r}")
    hi_f = math.inf if hi is None else _number(hi, f"upper bound of parameter {name!r}")
    if math.isnan(lo_f) or math.isnan(hi_f) or lo_f > hi_f:
        raise ParamError(f"parameter {name!r}: bounds [{lo_f:g}, {hi_f:g}] are not a range")
    if not lo_f <= d <= hi_f:
        raise ParamError(
            f"parameter {name!r}: default {d:g} is outside its range [{lo_f:g}, {hi_f:g}]"
        )
    return _intern("param", (), Param(name, d, lo_f, hi_f))


def _number(v: object, what: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
        raise ParamError(f"{what} must be a number, got {type(v).__name__}")
    return to_float(v, what, ParamError)


def _finite(v: object, what: str) -> float:
    f = _number(v, what)
    if not math.isfinite(f):
        raise ParamError(f"{what} must be finite, got {f}")
    return f


def as_expr(v: Expr | Number) -> Expr:
    """Convert a number (or 0-d NumPy value) to a constant node; pass expressions through."""
    if isinstance(v, Expr):
        return v
    if isinstance(v, bool):
        raise TypeError("a boolean is not a number here")
    if isinstance(v, (int, float, np.integer, np.floating)):
        return const(to_float(v, "a number in an expression"))
    if isinstance(v, np.ndarray) and v.shape == ():
        return const(to_float(v, "a number in an expression"))
    raise TypeError(f"expected a number or expression, got {type(v).__name__}")


def is_const(e: Expr, v: float | None = None) -> bool:
    """True when ``e`` is a constant (equal to ``v`` when given)."""
    return e.op == "const" and (v is None or e.value == v)


def const_value(e: Expr) -> float | None:
    """The float of a constant node, else None."""
    return float(e.value) if e.op == "const" else None  # type: ignore[arg-type]


def _fold(op: str, vals: list[float]) -> Expr:
    with np.errstate(all="ignore"):
        out = numpy_impl(op)(*[np.float64(v) for v in vals])
    return const(float(out))


def make(op: str, *args: Expr) -> Expr:
    """Create (or find) the node ``op(*args)`` with folding and simplification."""
    info = OPS.get(op)
    if info is None:
        raise ValueError(f"unknown op {op!r}")
    if len(args) != info.arity:
        raise ValueError(f"op {op} takes {info.arity} argument(s), got {len(args)}")
    args = tuple(as_expr(a) for a in args)
    if all(a.op == "const" for a in args):
        return _fold(op, [a.value for a in args])  # type: ignore[misc]
    a = args[0]
    if info.arity == 1:
        if op == "neg" and a.op == "neg":
            return a.args[0]
        if op in ("abs", "square") and a.op == "neg":
            return make(op, a.args[0])
        if op == "abs" and a.op in ("abs", "sqrt", "square", "exp"):
            return a
        if op == "square" and a.op == "abs":
            return make("square", a.args[0])
    else:
        b = args[1]
        if op == "add":
            if is_const(b, 0.0):
                return a
            if is_const(a, 0.0):
                return b
        elif op == "sub":
            if is_const(b, 0.0):
                return a
            if is_const(a, 0.0):
                return make("neg", b)
        elif op == "mul":
            if is_const(b, 1.0):
                return a
            if is_const(a, 1.0):
                return b
            if is_const(b, -1.0):
                return make("neg", a)
            if is_const(a, -1.0):
                return make("neg", b)
            if is_const(a, 0.0) or is_const(b, 0.0):
                # NaN points/parameters are handled by the evaluators (NaN in, NaN out)
                return const(0.0)
            if a is b:
                return make("square", a)
        elif op == "div":
            if is_const(b, 1.0):
                return a
        elif op in ("min", "max") and a is b:
            return a
        if info.commutative and b.key < a.key:
            args = (b, a)
    return _intern(op, args)


def mesh_call(data, ax: Expr | Number, ay: Expr | Number, az: Expr | Number) -> Expr:
    """The node ``mesh(ax, ay, az)``: the exact signed distance to the closed triangle
    mesh ``data`` (a :class:`csdf.meshdata.MeshData`) at the point ``(ax, ay, az)``
    (model units). It is never folded (its value needs the mesh's hierarchy, built by
    the evaluators); the compiler gives it one call in the tape with the mesh as a data
    block."""
    if not hasattr(data, "digest") or not hasattr(data, "faces"):
        raise TypeError(f"a mesh call needs a MeshData, got {type(data).__name__}")
    return _intern("mesh", (as_expr(ax), as_expr(ay), as_expr(az)), data)


# ----------------------------------------------------------------------------- helpers
def sqrt(a: Expr | Number) -> Expr:
    return make("sqrt", a)


def square(a: Expr | Number) -> Expr:
    return make("square", a)


def sin(a: Expr | Number) -> Expr:
    return make("sin", a)


def cos(a: Expr | Number) -> Expr:
    return make("cos", a)


def tan(a: Expr | Number) -> Expr:
    return make("tan", a)


def asin(a: Expr | Number) -> Expr:
    return make("asin", a)


def acos(a: Expr | Number) -> Expr:
    return make("acos", a)


def atan(a: Expr | Number) -> Expr:
    return make("atan", a)


def atan2(y: Expr | Number, x: Expr | Number) -> Expr:
    return make("atan2", y, x)


def exp(a: Expr | Number) -> Expr:
    return make("exp", a)


def log(a: Expr | Number) -> Expr:
    return make("log", a)


def floor(a: Expr | Number) -> Expr:
    return make("floor", a)


def step(a: Expr | Number) -> Expr:
    """1 where ``a >= 0``, else 0."""
    return make("step", a)


def sign(a: Expr | Number) -> Expr:
    return make("sign", a)


def mod(a: Expr | Number, b: Expr | Number) -> Expr:
    """Floored modulo ``a - b*floor(a/b)`` (GLSL ``mod``)."""
    return make("mod", a, b)


def minimum(*xs: Expr | Number) -> Expr:
    """Minimum of two or more values (balanced tree, canonical order)."""
    return _reduce("min", xs)


def maximum(*xs: Expr | Number) -> Expr:
    """Maximum of two or more values (balanced tree, canonical order)."""
    return _reduce("max", xs)


def _reduce(op: str, xs: Iterable[Expr | Number]) -> Expr:
    items = sorted((as_expr(x) for x in xs), key=lambda e: e.key)
    if not items:
        raise ValueError(f"{op} of nothing")
    while len(items) > 1:
        nxt = [make(op, items[i], items[i + 1]) for i in range(0, len(items) - 1, 2)]
        if len(items) % 2:
            nxt.append(items[-1])
        items = nxt
    return items[0]


def clamp(a: Expr | Number, lo: Expr | Number, hi: Expr | Number) -> Expr:
    return make("min", make("max", a, lo), hi)


def mix(a: Expr | Number, b: Expr | Number, t: Expr | Number) -> Expr:
    """``a + (b - a) * t``."""
    a = as_expr(a)
    return a + (as_expr(b) - a) * t


def select_ge(c: Expr | Number, a: Expr | Number, b: Expr | Number) -> Expr:
    """``a`` where ``c >= 0`` else ``b``, as ``b + step(c)*(a - b)``.

    Both branches are computed, so both must be finite wherever the result is used.
    """
    b = as_expr(b)
    return b + step(c) * (as_expr(a) - b)


# --------------------------------------------------------------------------- traversal
def walk(root: Expr) -> Iterator[Expr]:
    """Yield every node reachable from ``root`` once, children before parents."""
    seen: set[int] = set()
    stack: list[tuple[Expr, bool]] = [(root, False)]
    while stack:
        node, expanded = stack.pop()
        if id(node) in seen:
            continue
        if expanded:
            seen.add(id(node))
            yield node
            continue
        stack.append((node, True))
        for a in reversed(node.args):
            if id(a) not in seen:
                stack.append((a, False))


def substitute(roots: Sequence[Expr], leaf: Callable[[Expr], Expr | None]) -> list[Expr]:
    """``roots`` rebuilt with each leaf (``x``, ``y``, ``z``, ``const`` or ``param``
    node) replaced by ``leaf(node)`` where that is not None; shared nodes stay shared
    (also between the roots) and rebuilt nodes are folded and simplified as by
    :func:`make`. Linear in the number of distinct nodes."""
    new: dict[int, Expr] = {}
    for root in roots:
        for n in walk(root):
            if id(n) in new:
                continue
            if not n.args:
                r = leaf(n)
                new[id(n)] = n if r is None else r
                continue
            args = tuple(new[id(a)] for a in n.args)
            same = all(a is b for a, b in zip(args, n.args))
            if same:
                new[id(n)] = n
            elif n.op in DATA_OPS:
                new[id(n)] = mesh_call(n.value, *args)
            else:
                new[id(n)] = make(n.op, *args)
    return [new[id(r)] for r in roots]


def expr_params(root: Expr) -> list[Param]:
    """Parameters used by ``root``, sorted by name.

    Raises:
        ParamError: one name declared with two different defaults or ranges.
    """
    found: dict[str, Param] = {}
    for n in walk(root):
        if n.op == "param":
            p: Param = n.value  # type: ignore[assignment]
            old = found.get(p.name)
            if old is not None and old != p:
                raise ParamError(
                    f"parameter {p.name!r} is declared twice with different values: "
                    f"{old!r} and {p!r}"
                )
            found[p.name] = p
    return [found[k] for k in sorted(found)]


_INFIX = {"add": "+", "sub": "-", "mul": "*", "div": "/"}


def to_infix(root: Expr, max_nodes: int = 200) -> str:
    """Readable infix text of an expression (shared subexpressions are repeated)."""
    count = 0

    def go(e: Expr) -> str:
        nonlocal count
        count += 1
        if count > max_nodes:
            return "..."
        if e.op in ("x", "y", "z"):
            return e.op
        if e.op == "const":
            return repr(e.value)
        if e.op == "param":
            return e.value.name  # type: ignore[union-attr]
        if e.op in _INFIX:
            return f"({go(e.args[0])} {_INFIX[e.op]} {go(e.args[1])})"
        if e.op == "neg":
            return f"-{go(e.args[0])}"
        if e.op in DATA_OPS:
            return f"mesh#{e.value.digest}({', '.join(go(a) for a in e.args)})"  # type: ignore[attr-defined]
        return f"{e.op}({', '.join(go(a) for a in e.args)})"

    return go(root)
