"""Shape methods on parameters: fix some to values (``bind``) or give them other names
(``rename``), so that copies of one parametric model combine in one shape, each with
its own parameters (``chair.rename(prefix="left_") | chair.rename(prefix="right_")``).

Both keep the child's distance contract (exact, bound or neither), Lipschitz bound and
bounding box: they change which numbers the expression reads, not its geometry.
"""

from __future__ import annotations

import math
import numbers
from typing import Any

from ..errors import ParamError, ShapeError
from ..expr import Expr, Param, X, Y, Z, const, param, substitute
from ..vec import Vec
from .base import BuildContext, Shape, register

__all__ = ["bind", "rename"]


def _params_of(shape: Shape, what: str) -> dict[str, Param]:
    if not isinstance(shape, Shape):
        raise ShapeError(f"{what} is a shape method; got {type(shape).__name__}")
    return {p.name: p for p in shape.params}


def _unknown(what: str, names: list[str], known: dict[str, Param]) -> ParamError:
    have = ", ".join(sorted(known)) or "none"
    return ParamError(f"{what}: unknown parameter(s) {', '.join(map(repr, names))}; the "
                      f"shape's parameters: {have}")


def _rewritten(shape: Shape, name: str, swap: dict[str, Expr], args: tuple,
               kwargs: dict) -> Shape:
    """A node that evaluates ``shape`` with its parameter leaves replaced per ``swap``
    (parameter name -> expression). The child's expression is built once at (x, y, z)
    and its leaves substituted (parameters per ``swap``, coordinates by the caller's),
    so parameters that come with the caller's coordinates are left alone."""
    cache: dict[str, Any] = {}

    def fn(p: Vec, ctx: BuildContext) -> Expr:
        if "out" not in cache:
            inner = BuildContext()
            cache["out"] = shape.sdf(Vec((X, Y, Z)[: shape.dim]), inner)
            cache["calls"] = list(inner.calls.values())
        coords = {"x": 0, "y": 1, "z": 2}

        def leaf(n: Expr) -> Expr | None:
            if n.op in coords:
                return p.c[coords[n.op]]
            if n.op == "param":
                return swap.get(n.value.name)  # type: ignore[union-attr]
            return None

        calls = cache["calls"]
        roots = [cache["out"]] + [e for _, out, ins in calls for e in (out, *ins)]
        new = substitute(roots, leaf)
        k = 1
        for cname, _, ins in calls:  # the primitive calls, for the program's counts
            out, ins2 = new[k], tuple(new[k + 1:k + 1 + len(ins)])
            k += 1 + len(ins)
            if out.op not in ("x", "y", "z", "const", "param"):
                ctx.calls.setdefault(id(out), (cname, out, ins2))
        return new[0]

    return Shape(name, fn, dim=shape.dim, exactness=shape.exactness,
                 lipschitz=shape.lipschitz, bounds=shape.bounds, args=args, kwargs=kwargs,
                 children=(shape,))


@register("method")
def bind(shape: Shape, **values) -> Shape:
    """Fix parameters to values: ``chair.bind(seat_height=0.5)`` reads 0.5 where the
    chair read its parameter ``seat_height``, which is no longer a parameter of the
    result. Keeps the contract, Lipschitz bound and bounds.

    Raises:
        ParamError: a name the shape has no parameter for, a value that is not a finite
            number, or one outside the parameter's declared range.
    """
    known = _params_of(shape, "bind")
    if not values:
        raise ShapeError("bind: give at least one parameter value, as name=value")
    bad = [k for k in values if k not in known]
    if bad:
        raise _unknown("bind", bad, known)
    swap: dict[str, Expr] = {}
    for k, v in values.items():
        if isinstance(v, bool) or not isinstance(v, numbers.Real) or not math.isfinite(v):
            raise ParamError(f"bind: {k} must be a finite number, got {v!r}")
        p = known[k]
        if not p.lo <= v <= p.hi:
            raise ParamError(f"bind: {k} = {v:g} is outside its range [{p.lo:g}, {p.hi:g}]")
        swap[k] = const(float(v))
    return _rewritten(shape, "bind", swap, (), dict(values))


@register("method")
def rename(shape: Shape, prefix: str = "", suffix: str = "") -> Shape:
    """Give every parameter a new name, ``prefix + name + suffix``, keeping its default
    and range: ``chair.rename(prefix="left_")`` has ``left_seat_height``, ... so two
    copies of a model combine with parameters of their own. Keeps the contract,
    Lipschitz bound and bounds.

    Raises:
        ShapeError: prefix or suffix not a string, or both empty.
        ParamError: a new name that is not an identifier or is reserved.
    """
    known = _params_of(shape, "rename")
    if not isinstance(prefix, str) or not isinstance(suffix, str):
        raise ShapeError("rename: prefix and suffix must be strings")
    if not prefix and not suffix:
        raise ShapeError("rename: give a prefix or a suffix")
    swap: dict[str, Expr] = {}
    for k, p in known.items():
        try:
            swap[k] = param(prefix + k + suffix, p.default, p.lo, p.hi)
        except ParamError as exc:
            raise ParamError(f"rename: {exc}") from None
    kw = {k: v for k, v in (("prefix", prefix), ("suffix", suffix)) if v}
    return _rewritten(shape, "rename", swap, (), kw)


