"""``dumps``: print any shape built with the Python API as ``.csdf`` text.

The text loads back (:func:`csdf.loads`) to the same expression, hence identical
bytecode: floats are printed with ``repr`` (exact), parameter expressions are printed
fully parenthesised with the op names the language knows, every shape node is printed as
the call that made it, and a shape used more than once is bound once with ``let``.

Names: ``let`` names are fresh (never a parameter's or a built-in's name). A parameter
may be named like a built-in (``param box = ...``); it then shadows the built-in after
its ``param`` statement, so each call of a shadowed built-in (and ``inf``, in ranges and
arguments) goes through a small ``def`` printed before the parameters, whose body still
sees the built-in (the language's scoping is lexical).
"""

from __future__ import annotations

import math
from collections import Counter

import numpy as np

from ..errors import CsdfError
from ..expr import Expr
from ..shapes.base import REGISTRY, Shape
from .loader import CONSTANTS, KEYWORDS, MATH

__all__ = ["dumps"]

_INFIX = {"add": "+", "sub": "-", "mul": "*", "div": "/"}
#: calls whose arguments may use the coordinates x, y, z (see csdf.lang.loader)
_COORD_CALLS = ("field",)
_INFIX_CSG = {"union": "|", "intersection": "&", "difference": "-"}


_BUILTINS = frozenset(REGISTRY) | frozenset(MATH) | frozenset(CONSTANTS)


class _Printer:
    """Prints one shape; ``param_names``: the names its ``param`` statements bind."""

    def __init__(self, root: Shape, param_names: set[str]):
        self.uses: Counter[int] = Counter()
        self._count(root, set())
        self.names: dict[int, str] = {}
        self.lets: list[str] = []
        self.shadowed = param_names & _BUILTINS
        self.taken = set(param_names) | _BUILTINS | set(KEYWORDS)
        self.wrappers: dict[tuple, str] = {}  # (builtin, n positional, keywords) -> def
        self.defs: list[str] = []

    # -------------------------------------------------------------- names
    def fresh(self, prefix: str) -> str:
        """A name bound nowhere else in the printed model."""
        i = 1
        while f"{prefix}{i}" in self.taken:
            i += 1
        name = f"{prefix}{i}"
        self.taken.add(name)
        return name

    def call(self, name: str, pos: list[str], kw: list[tuple[str, str]]) -> str:
        """The text of a call of the built-in ``name`` with printed arguments: direct,
        or through a wrapper ``def`` (printed before the parameters) when a parameter
        shadows ``name``."""
        if name in self.shadowed and name in _COORD_CALLS:
            # its arguments may use x, y, z, which mean the coordinates only inside its
            # parentheses: the wrapper holds the whole call, arguments and all
            w = self.fresh(f"builtin_{name}_")
            parts = pos + [f"{k}={v}" for k, v in kw]
            self.defs.append(f"def {w}() = {name}({', '.join(parts)})")
            return f"{w}()"
        if name in self.shadowed:
            key = (name, len(pos), tuple(k for k, _ in kw))
            a = [f"a{i + 1}" for i in range(len(pos))]
            b = [f"b{i + 1}" for i in range(len(kw))]
            w = self.wrappers.get(key)
            if w is None:
                w = self.fresh(f"builtin_{name}_")
                inner = a + [f"{k}={v}" for (k, _), v in zip(kw, b)]
                self.defs.append(f"def {w}({', '.join(a + b)}) = {name}({', '.join(inner)})")
                self.wrappers[key] = w
            name, kw = w, [(bk, v) for bk, (_, v) in zip(b, kw)]
        parts = pos + [f"{k}={v}" for k, v in kw]
        return f"{name}({', '.join(parts)})"

    def inf(self) -> str:
        """The constant ``inf``, or a call of ``def builtin_inf_N() = inf`` when a
        parameter is named ``inf``."""
        if "inf" not in self.shadowed:
            return "inf"
        w = self.wrappers.get(("inf",))
        if w is None:
            w = self.fresh("builtin_inf_")
            self.defs.append(f"def {w}() = inf")
            self.wrappers[("inf",)] = w
        return f"{w}()"

    def num(self, v: float) -> str:
        """A float, exactly (``repr``); negative numbers parenthesised."""
        if math.isinf(v):
            return self.inf() if v > 0 else f"(-{self.inf()})"
        if math.isnan(v):
            raise CsdfError("a NaN number cannot be written in a model")
        r = repr(float(v))
        return f"({r})" if r.startswith("-") else r

    def expr(self, e: Expr) -> str:
        """A parameter expression (or a field's, in x, y, z), fully parenthesised."""
        if e.op == "const":
            return self.num(float(e.value))  # type: ignore[arg-type]
        if e.op == "param":
            return e.value.name  # type: ignore[union-attr]
        if e.op in ("x", "y", "z"):
            return e.op  # (only a field's or a remap's arguments hold coordinates)
        if e.op in _INFIX:
            return f"({self.expr(e.args[0])} {_INFIX[e.op]} {self.expr(e.args[1])})"
        if e.op == "neg":
            return f"(-{self.expr(e.args[0])})"
        return self.call(e.op, [self.expr(a) for a in e.args], [])

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
            return self.expr(v)
        if isinstance(v, bool):
            raise CsdfError("booleans cannot be written in a model")
        if isinstance(v, (int, np.integer)):
            return str(int(v))
        if isinstance(v, (float, np.floating)):
            return self.num(float(v))
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
            name = self.fresh("s")
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
        return self.call(s.name, [self.value(a) for a in args],
                         [(k, self.value(v)) for k, v in kw.items()])


def _all_params(shape: Shape) -> list:
    """Parameters used anywhere in the call tree (also those a simplification removed
    from the expression, e.g. ``0 * r``), sorted by name."""
    from ..expr import expr_params
    from ..shapes.base import walk_shapes

    exprs = []
    for s in walk_shapes(shape):
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
    params = _all_params(shape)
    for p in params:
        if p.name in KEYWORDS:
            raise CsdfError(f"parameter name {p.name!r} is a keyword of the .csdf language; "
                            "it cannot be written in a model")
    pr = _Printer(shape, {p.name for p in params})
    body = pr.shape(shape)
    decls = []
    for p in params:
        rng = ""
        if not (math.isinf(p.lo) and math.isinf(p.hi)):
            rng = f" in [{pr.num(p.lo)}, {pr.num(p.hi)}]"
        decls.append(f"param {p.name} = {pr.num(p.default)}{rng}")
    lines = ["# written by csdf.dumps", *pr.defs, *decls, *pr.lets, f"export {body}"]
    return "\n".join(lines) + "\n"

