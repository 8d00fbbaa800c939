"""``dumps``: print any shape built with the Python API as ``.csdf`` text.

The text loads back (:func:`csdf.loads`) to the same expression, hence identical
bytecode: floats are printed with ``repr`` (exact), parameter expressions are printed
fully parenthesised with the op names the language knows, every shape node is printed as
the call that made it, and a shape used more than once is bound once with ``let``.
"""

from __future__ import annotations

import math
from collections import Counter

import numpy as np

from ..errors import CsdfError
from ..expr import Expr
from ..shapes.base import REGISTRY, Shape

__all__ = ["dumps"]

_INFIX = {"add": "+", "sub": "-", "mul": "*", "div": "/"}
_INFIX_CSG = {"union": "|", "intersection": "&", "difference": "-"}


def _num(v: float) -> str:
    if math.isinf(v):
        return "inf" if v > 0 else "(-inf)"
    if math.isnan(v):
        raise CsdfError("a NaN number cannot be written in a model")
    r = repr(float(v))
    return f"({r})" if r.startswith("-") else r


def _expr(e: Expr) -> str:
    if e.op == "const":
        return _num(float(e.value))  # type: ignore[arg-type]
    if e.op == "param":
        return e.value.name  # type: ignore[union-attr]
    if e.op in ("x", "y", "z"):
        raise CsdfError("a shape argument depends on x, y or z; it cannot be printed")
    if e.op in _INFIX:
        return f"({_expr(e.args[0])} {_INFIX[e.op]} {_expr(e.args[1])})"
    if e.op == "neg":
        return f"(-{_expr(e.args[0])})"
    return f"{e.op}({', '.join(_expr(a) for a in e.args)})"


class _Printer:
    def __init__(self, root: Shape):
        self.uses: Counter[int] = Counter()
        self._count(root, set())
        self.names: dict[int, str] = {}
        self.lets: list[str] = []

    def _count(self, s: Shape, seen: set[int]) -> None:
        stack = [s]
        while stack:
            node = stack.pop()
            self.uses[id(node)] += 1
            if id(node) in seen:
                continue
            seen.add(id(node))
            stack.extend(node.children)

    def value(self, v) -> str:
        if isinstance(v, Shape):
            return self.shape(v)
        if isinstance(v, Expr):
            return _expr(v)
        if isinstance(v, bool):
            raise CsdfError("booleans cannot be written in a model")
        if isinstance(v, (int, np.integer)):
            return str(int(v))
        if isinstance(v, (float, np.floating)):
            return _num(float(v))
        if isinstance(v, str):
            return f'"{v}"'
        if isinstance(v, np.ndarray):
            v = v.tolist()
        if isinstance(v, tuple):
            inner = ", ".join(self.value(x) for x in v)
            return f"({inner},)" if len(v) == 1 else f"({inner})"
        if isinstance(v, list):
            return f"[{', '.join(self.value(x) for x in v)}]"
        raise CsdfError(f"cannot write a {type(v).__name__} in a model")

    def shape(self, s: Shape) -> str:
        name = self.names.get(id(s))
        if name is not None:
            return name
        text = self._call(s)
        if self.uses[id(s)] > 1:
            name = f"s{len(self.names) + 1}"
            self.names[id(s)] = name
            self.lets.append(f"let {name} = {text}")
            return name
        return text

    def _call(self, s: Shape) -> str:
        entry = REGISTRY.get(s.name)
        if entry is None:
            raise CsdfError(f"shape node {s.name!r} is not part of the modelling API")
        args = list(s.args)
        kw = dict(s.kwargs)
        if entry.kind == "method":
            target = s.children[0]
            parts = [self.value(a) for a in args] + [f"{k}={self.value(v)}" for k, v in kw.items()]
            return f"{self.shape(target)}.{s.name}({', '.join(parts)})"
        if s.name in _INFIX_CSG and len(args) == 2 and not kw:
            return f"({self.value(args[0])} {_INFIX_CSG[s.name]} {self.value(args[1])})"
        if s.name == "complement" and not kw:
            return f"(~{self.value(args[0])})"
        parts = [self.value(a) for a in args] + [f"{k}={self.value(v)}" for k, v in kw.items()]
        return f"{s.name}({', '.join(parts)})"


def _all_params(shape: Shape) -> list:
    """Parameters used anywhere in the call tree (also those a simplification removed
    from the expression, e.g. ``0 * r``), sorted by name."""
    from ..expr import expr_params

    exprs = []
    stack, seen = [shape], set()
    while stack:
        s = stack.pop()
        if id(s) in seen:
            continue
        seen.add(id(s))
        stack.extend(s.children)
        vals = list(s.args) + list(s.kwargs.values())
        while vals:
            v = vals.pop()
            if isinstance(v, Expr):
                exprs.append(v)
            elif isinstance(v, (tuple, list)):
                vals.extend(v)
    found = {p.name: p for e in exprs for p in expr_params(e)}
    for p in shape.params:
        found[p.name] = p
    return [found[k] for k in sorted(found)]


def dumps(shape: Shape) -> str:
    """``.csdf`` text of a shape; :func:`csdf.loads` of it compiles to identical bytecode.

    Raises:
        CsdfError: the shape holds something the language cannot express.
    """
    if not isinstance(shape, Shape):
        raise CsdfError(f"dumps expects a Shape, got {type(shape).__name__}")
    lines = ["# written by csdf.dumps"]
    for p in _all_params(shape):
        rng = ""
        if not (math.isinf(p.lo) and math.isinf(p.hi)):
            rng = f" in [{_num(p.lo)}, {_num(p.hi)}]"
        lines.append(f"param {p.name} = {_num(p.default)}{rng}")
    pr = _Printer(shape)
    body = pr.shape(shape)
    lines += pr.lets
    lines.append(f"export {body}")
    return "\n".join(lines) + "\n"

