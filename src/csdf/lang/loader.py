"""Loading ``.csdf`` model files: parse with Lark, then evaluate the tree safely.

Names are lexically scoped: a name means the nearest binding before it (a ``def``'s
argument inside its body, then a ``param``/``let``/``def`` above), else the built-in of
that name, so a model may name things after built-ins (``let slab = ...``) without
losing the built-in where it is not shadowed; see :meth:`_Loader.lookup`. Keywords are
reserved by the grammar.

Safety: nothing from a model file is ever passed to Python's ``eval``/``exec``, imported
or looked up as an attribute. Names resolve only to the model's own ``param``/``let``/
``def`` bindings, the registered modelling API (:data:`csdf.shapes.REGISTRY`) and a
fixed table of math functions and constants; ``.name(...)`` resolves only to
registered shape methods. Strings are short tokens (axis and blend names). Sizes are
limited (file bytes, nesting depth, calls, instructions), so a hostile file fails with a
:class:`~csdf.errors.ModelError` instead of exhausting the machine.
"""

from __future__ import annotations

import difflib
import inspect
import math
import os
import re
import sys
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

from lark import Lark, Token, Tree
from lark.exceptions import UnexpectedCharacters, UnexpectedEOF, UnexpectedInput, UnexpectedToken

from .. import expr as E
from ..errors import CsdfError, ModelError
from ..expr import Expr
from ..shapes.base import REGISTRY, Shape
from .source import check_source, read_source

__all__ = ["load", "loads", "parser", "MAX_FILE_BYTES", "MAX_DEPTH", "MAX_CALLS",
           "MAX_INSTRUCTIONS"]

MAX_FILE_BYTES = 1_000_000
MAX_DEPTH = 200  # nesting of expressions
MAX_CALLS = 100_000  # builtin and def calls while evaluating
MAX_CALL_DEPTH = 64  # nested def calls
MAX_INSTRUCTIONS = 1_000_000  # compiled size of the exported shape

_GRAMMAR = (Path(__file__).parent / "grammar.lark").read_text()


@lru_cache(maxsize=1)
def parser() -> Lark:
    """The LALR parser of the language's grammar (``grammar.lark``), built once; its
    trees carry source positions (``meta.start_pos``, ``meta.end_pos``: character
    offsets), which :func:`csdf.zoo.load` uses to set parameter defaults in a
    model's text."""
    return Lark(_GRAMMAR, parser="lalr", propagate_positions=True, maybe_placeholders=True)


MATH: dict[str, Any] = {
    "sqrt": E.sqrt, "square": E.square, "sin": E.sin, "cos": E.cos, "tan": E.tan,
    "asin": E.asin, "acos": E.acos, "atan": E.atan, "atan2": E.atan2, "exp": E.exp,
    "log": E.log, "floor": E.floor, "step": E.step, "sign": E.sign, "mod": E.mod,
    "abs": lambda a: E.make("abs", a), "min": E.minimum, "max": E.maximum, "clamp": E.clamp,
    "neg": lambda a: E.make("neg", a), "add": lambda a, b: E.make("add", a, b),
    "sub": lambda a, b: E.make("sub", a, b), "mul": lambda a, b: E.make("mul", a, b),
    "div": lambda a, b: E.make("div", a, b),
}
CONSTANTS: dict[str, float] = {"pi": math.pi, "tau": 2 * math.pi, "inf": math.inf}
#: the coordinates, named only inside the arguments of these calls
_COORDS = {"x": E.X, "y": E.Y, "z": E.Z}
_COORD_CALLS = ("field", "remap", "color_field")
KEYWORDS = ("param", "let", "def", "export", "in")


@dataclass
class _Func:
    """A ``def``: its body sees its arguments and the bindings made before it
    (``seq``: the number of top-level bindings when it was defined)."""

    name: str
    args: list[str]
    body: Tree
    line: int
    seq: int = 0


@dataclass
class _Global:
    """A top-level binding: its definition order, value and line."""

    seq: int
    value: Any
    line: int


class _Builtin:
    """Marker: a name resolved to the built-in of that name."""


class _Unknown:
    """Marker: a name bound to nothing."""


_BUILTIN = _Builtin()
_UNKNOWN = _Unknown()


def _is_num(v: Any) -> bool:
    return isinstance(v, (int, float, Expr)) and not isinstance(v, bool)


def _is_vec(v: Any) -> bool:
    """A tuple of numbers (arithmetic applies element-wise to these, not to nested ones)."""
    return isinstance(v, tuple) and all(_is_num(x) for x in v)


def _kind(v: Any) -> str:
    if _is_num(v):
        return "a number"
    if isinstance(v, Shape):
        return f"a {v.dim}D shape"
    if isinstance(v, tuple):
        return f"a {len(v)}-vector"
    if isinstance(v, list):
        return "a list"
    if isinstance(v, str):
        return "a string"
    if isinstance(v, _Func):
        return f"the function {v.name!r}"
    return type(v).__name__


class _Loader:
    def __init__(self, text: str, file: str):
        self.text = text
        self.file = file
        self.lines = _lines(text)
        self.globals: dict[str, _Global] = {}  # top-level bindings, in order
        self.locals: dict[str, Any] = {}  # the arguments of the def being evaluated
        self.coords = 0  # > 0 inside field(...) / .remap(...): x, y, z are coordinates
        self.limit = sys.maxsize  # globals with seq < limit are "before" this point
        self.func_line = 0  # the line of the def being evaluated (0 at top level)
        self.params: dict[str, Expr] = {}
        self.calls = 0
        self.call_stack: list[str] = []
        self.export: Shape | None = None

    # ------------------------------------------------------------------ errors
    def error(self, msg: str, node: Tree | Token | None, hint: str = "", width: int = 0):
        line = col = 0
        if isinstance(node, Token):
            line, col = node.line or 0, node.column or 0
            width = width or len(str(node))
        elif isinstance(node, Tree) and not node.meta.empty:
            line, col = node.meta.line, node.meta.column
            if not width and node.meta.end_line == line:
                width = node.meta.end_column - col
        src = self.lines[line - 1] if 0 < line <= len(self.lines) else ""
        return ModelError(msg, file=self.file, line=line, column=col, hint=hint,
                          source_line=src, width=width or 1)

    def known_names(self) -> list[str]:
        return sorted(set(self.locals) | set(self.globals) | set(REGISTRY) | set(MATH)
                      | set(CONSTANTS))

    # ------------------------------------------------------------------ names
    def lookup(self, name: str) -> tuple[Any, int]:
        """What ``name`` means here, and the line that bound it (0 for a built-in).

        Lexical scope, nearest first: the arguments of the ``def`` being evaluated; the
        top-level bindings made before this point (before the ``def`` statement, inside
        a function body); the built-in of that name (:data:`_BUILTIN`); and, inside a
        function body only, a top-level binding made after the ``def`` (so functions can
        be written in any order; a built-in of the same name takes precedence there).
        :data:`_UNKNOWN` when none applies.
        """
        if name in self.locals:
            return self.locals[name], self.func_line
        g = self.globals.get(name)
        if g is not None and g.seq < self.limit:
            return g.value, g.line
        if name in REGISTRY or name in MATH or name in CONSTANTS:
            return _BUILTIN, 0
        if g is not None:
            return g.value, g.line
        return _UNKNOWN, 0

    def suggest(self, name: str, pool: list[str]) -> str:
        close = difflib.get_close_matches(name, pool, n=3, cutoff=0.6)
        return f"did you mean {', '.join(repr(c) for c in close)}?" if close else ""

    # ------------------------------------------------------------------ statements
    def run(self, tree: Tree) -> Shape:
        last = None
        for st in tree.children:
            last = st
            getattr(self, "st_" + st.data)(st)
        if self.export is None:
            node = last if last is not None else None
            raise self.error("missing 'export' statement", node,
                             hint="end the model with: export <shape>")
        return self.export

    def _bind(self, name_tok: Token, value: Any, what: str) -> None:
        """Bind a top-level name (once). A name may equal a built-in's: it shadows the
        built-in from here on (``what``: the kind of binding, for messages)."""
        name = str(name_tok)
        if name in self.globals:
            prev = self.globals[name].line
            raise self.error(f"{name!r} is already defined", name_tok,
                             hint=f"each name can be defined once (it was on line {prev})")
        self.globals[name] = _Global(len(self.globals), value, name_tok.line or 0)

    def st_param_stmt(self, st: Tree) -> None:
        name, default, lo, hi = st.children
        d = self.number_value(self.eval(default), default, "a parameter default")
        lo_v = None if lo is None else self.number_value(self.eval(lo), lo, "a bound")
        hi_v = None if hi is None else self.number_value(self.eval(hi), hi, "a bound")
        try:
            p = E.param(str(name), d, lo_v, hi_v)
        except CsdfError as exc:
            node = default if lo is None or "range" not in str(exc) else st
            raise self.error(str(exc), node if "default" in str(exc) else st) from None
        self._bind(name, p, "parameter")
        self.params[str(name)] = p

    def number_value(self, v: Any, node, what: str) -> float:
        if isinstance(v, Expr):
            if v.op == "const":
                return float(v.value)  # type: ignore[arg-type]
            raise self.error(f"{what} must be a constant number", node)
        if _is_num(v):
            return float(v)
        raise self.error(f"{what} must be a number, got {_kind(v)}", node)

    def st_let_stmt(self, st: Tree) -> None:
        name, value = st.children
        self._bind(name, self.eval(value), "variable")

    def st_def_stmt(self, st: Tree) -> None:
        name, *rest = st.children
        body = rest[-1]
        args = [str(a) for a in rest[:-1] if a is not None]
        if len(set(args)) != len(args):
            raise self.error(f"function {str(name)!r} repeats an argument name", name)
        f = _Func(str(name), args, body, name.line or 0, seq=len(self.globals))
        self._bind(name, f, "function")

    def st_export_stmt(self, st: Tree) -> None:
        if self.export is not None:
            raise self.error("a model has exactly one 'export'; this is a second one", st)
        v = self.eval(st.children[0])
        if not isinstance(v, Shape):
            raise self.error(f"export needs a shape, got {_kind(v)}", st.children[0])
        self.export = v

    # ------------------------------------------------------------------ expressions
    def eval(self, node, depth: int = 0) -> Any:
        if depth > MAX_DEPTH:
            raise self.error(f"expression nested deeper than {MAX_DEPTH} levels", node)
        if isinstance(node, Token):  # pragma: no cover - all atoms are wrapped in trees
            raise self.error("unexpected token", node)
        method = getattr(self, "ex_" + node.data, None)
        if method is None:  # pragma: no cover
            raise self.error(f"unsupported construct {node.data!r}", node)
        return method(node, depth + 1)

    def ex_number(self, node: Tree, depth: int) -> Any:
        tok = str(node.children[0])
        if "." in tok or "e" in tok or "E" in tok:
            v = float(tok)
            if not math.isfinite(v):
                raise self.error(f"number {tok} is out of range", node)
            return v
        if len(tok) > 15:
            raise self.error(f"integer {tok[:20]}... is too long", node)
        return int(tok)

    def ex_string(self, node: Tree, depth: int) -> str:
        return str(node.children[0])[1:-1]

    def ex_name(self, node: Tree, depth: int) -> Any:
        tok = node.children[0]
        name = str(tok)
        if self.coords and name in _COORDS:
            return _COORDS[name]
        v, _ = self.lookup(name)
        if v is _BUILTIN:
            if name in CONSTANTS:
                return CONSTANTS[name]
            raise self.error(f"{name!r} is a function; call it: {name}(...)", tok)
        if v is _UNKNOWN:
            raise self.error(f"unknown name {name!r}", tok,
                             hint=self.suggest(name, self.known_names()))
        if isinstance(v, _Func):
            raise self.error(f"{name!r} is a function; call it: {name}(...)", tok)
        return v

    def ex_tuple(self, node: Tree, depth: int) -> tuple:
        items = [self.eval(c, depth) for c in node.children if c is not None]
        for c, v in zip(node.children, items):
            if not (_is_num(v) or isinstance(v, (tuple, list))):
                raise self.error(f"a vector holds numbers (or vectors), got {_kind(v)}", c)
        return tuple(items)

    def ex_list(self, node: Tree, depth: int) -> list:
        return [self.eval(c, depth) for c in node.children if c is not None]

    def _arith(self, node: Tree, depth: int, op: str) -> Any:
        a = self.eval(node.children[0], depth)
        b = self.eval(node.children[1], depth)
        if isinstance(a, Shape) and isinstance(b, Shape):
            if op == "sub":
                return self._api(node, "difference", REGISTRY["difference"].fn, [a, b], {})
            raise self.error(f"shapes combine with | & - ~, not {_SYMBOL[op]}", node,
                             hint="use | for union, & for intersection, - for difference")
        if _is_num(a) and _is_num(b):
            return E.make(op, a, b)
        if _is_vec(a) and _is_vec(b) and op in ("add", "sub"):
            if len(a) != len(b):
                raise self.error(f"vectors of sizes {len(a)} and {len(b)} cannot be added",
                                 node)
            return tuple(E.make(op, x, y) for x, y in zip(a, b))
        if op in ("mul", "div") and _is_vec(a) and _is_num(b):
            return tuple(E.make(op, x, b) for x in a)
        if op == "mul" and _is_num(a) and _is_vec(b):
            return tuple(E.make(op, a, y) for y in b)
        raise self.error(f"cannot apply {_SYMBOL[op]} to {_kind(a)} and {_kind(b)}", node)

    def ex_add(self, node, depth):
        return self._arith(node, depth, "add")

    def ex_sub(self, node, depth):
        return self._arith(node, depth, "sub")

    def ex_mul(self, node, depth):
        return self._arith(node, depth, "mul")

    def ex_div(self, node, depth):
        return self._arith(node, depth, "div")

    def ex_neg(self, node, depth):
        a = self.eval(node.children[0], depth)
        if _is_num(a):
            return -a if isinstance(a, (int, float)) else E.make("neg", a)
        if _is_vec(a):
            return tuple(E.make("neg", x) for x in a)
        raise self.error(f"cannot negate {_kind(a)}", node,
                         hint="use ~ for the complement of a shape")

    def ex_pos(self, node, depth):
        a = self.eval(node.children[0], depth)
        if not (_is_num(a) or isinstance(a, tuple)):
            raise self.error(f"unary + needs a number, got {_kind(a)}", node)
        return a

    def _shapes2(self, node, depth, fname: str) -> Shape:
        a = self.eval(node.children[0], depth)
        b = self.eval(node.children[1], depth)
        for c, v in zip(node.children, (a, b)):
            if not isinstance(v, Shape):
                sym = "|" if fname == "union" else "&"
                raise self.error(f"{sym} combines shapes, got {_kind(v)}", c)
        return self._api(node, fname, REGISTRY[fname].fn, [a, b], {})

    def ex_union_op(self, node, depth):
        return self._shapes2(node, depth, "union")

    def ex_intersection_op(self, node, depth):
        return self._shapes2(node, depth, "intersection")

    def ex_complement_op(self, node, depth):
        a = self.eval(node.children[0], depth)
        if not isinstance(a, Shape):
            raise self.error(f"~ needs a shape, got {_kind(a)}", node)
        return self._api(node, "complement", REGISTRY["complement"].fn, [a], {})

    def _args(self, node: Tree | None, depth: int) -> tuple[list, dict]:
        pos: list = []
        kw: dict = {}
        if node is None:
            return pos, kw
        for a in node.children:
            if a is None:
                continue
            if isinstance(a, Tree) and a.data == "kwarg":
                key = str(a.children[0])
                if key in kw:
                    raise self.error(f"argument {key!r} given twice", a.children[0])
                kw[key] = self.eval(a.children[1], depth)
            else:
                if kw:
                    raise self.error("positional argument after a keyword argument", a)
                pos.append(self.eval(a, depth))
        return pos, kw

    def _coord_args(self, node: Tree | None, depth: int) -> tuple[list, dict]:
        """The arguments of ``field(...)`` or ``.remap(...)``: ``x``, ``y``, ``z`` are
        the coordinates there (and only there)."""
        self.coords += 1
        try:
            return self._args(node, depth)
        finally:
            self.coords -= 1

    def ex_call(self, node: Tree, depth: int) -> Any:
        name_tok, argnode = node.children
        name = str(name_tok)
        f, line = self.lookup(name)
        if name in _COORD_CALLS and f is _BUILTIN:
            pos, kw = self._coord_args(argnode, depth)
        else:
            pos, kw = self._args(argnode, depth)
        if isinstance(f, _Func):
            return self._call_def(node, f, pos, kw, depth)
        if f is _UNKNOWN:
            raise self.error(f"unknown function {name!r}", name_tok,
                             hint=self.suggest(name, self.known_names()))
        if f is not _BUILTIN:
            hint = ""
            if name in REGISTRY or name in MATH:
                hint = (f"{name!r} bound on line {line} hides the built-in {name}() here; "
                        "rename it to call the built-in")
            raise self.error(f"{name!r} is {_kind(f)}, not a function", name_tok, hint=hint)
        if name in REGISTRY:
            entry = REGISTRY[name]
            if entry.kind == "method":
                raise self.error(f"{name!r} is a shape method; write shape.{name}(...)",
                                 name_tok)
            return self._api(node, name, entry.fn, pos, kw)
        if name in MATH:
            return self._math(node, name, pos, kw)
        raise self.error(f"unknown function {name!r}", name_tok,
                         hint=self.suggest(name, self.known_names()))

    def ex_method(self, node: Tree, depth: int) -> Any:
        target, name_tok, argnode = node.children
        obj = self.eval(target, depth)
        name = str(name_tok)
        methods = sorted(k for k, e in REGISTRY.items() if e.kind == "method")
        if name not in methods:
            raise self.error(f"unknown method {name!r}", name_tok,
                             hint=self.suggest(name, methods) or f"methods: {', '.join(methods)}")
        if not isinstance(obj, Shape):
            raise self.error(f".{name}() applies to shapes, not to {_kind(obj)}", node)
        if name in _COORD_CALLS:
            pos, kw = self._coord_args(argnode, depth)
        else:
            pos, kw = self._args(argnode, depth)
        return self._api(node, name, REGISTRY[name].fn, [obj, *pos], kw)

    def _count(self, node) -> None:
        self.calls += 1
        if self.calls > MAX_CALLS:
            raise self.error(f"the model makes more than {MAX_CALLS} calls", node)

    def _api(self, node: Tree, name: str, fn, pos: list, kw: dict) -> Any:
        self._count(node)
        try:
            inspect.signature(fn).bind(*pos, **kw)
        except TypeError as exc:
            sig = str(inspect.signature(fn)).replace("shape: Shape, ", "").replace("'", "")
            raise self.error(f"wrong arguments for {name}: {exc}", node,
                             hint=f"{name}{sig}") from None
        try:
            return fn(*pos, **kw)
        except (CsdfError, TypeError, ValueError) as exc:
            raise self.error(str(exc), node) from None

    def _math(self, node: Tree, name: str, pos: list, kw: dict) -> Any:
        self._count(node)
        if kw:
            raise self.error(f"{name}() takes no keyword arguments", node)
        for v in pos:
            if not _is_num(v):
                raise self.error(f"{name}() needs numbers, got {_kind(v)}", node)
        fn = MATH[name]
        try:
            if name in ("min", "max"):
                if len(pos) < 2:
                    raise TypeError(f"{name}() needs at least two numbers")
                return fn(*pos)
            inspect.signature(fn).bind(*pos)
            return fn(*pos)
        except TypeError as exc:
            raise self.error(f"wrong arguments for {name}: {exc}", node) from None

    def _call_def(self, node: Tree, f: _Func, pos: list, kw: dict, depth: int) -> Any:
        self._count(node)
        if f.name in self.call_stack:
            raise self.error(f"function {f.name!r} calls itself (recursion is not allowed)",
                             node)
        if len(self.call_stack) >= MAX_CALL_DEPTH:
            raise self.error(f"functions nested deeper than {MAX_CALL_DEPTH} calls", node)
        bound: dict[str, Any] = {}
        if len(pos) > len(f.args):
            raise self.error(f"{f.name}() takes {len(f.args)} argument(s), got {len(pos)}",
                             node, hint=f"def {f.name}({', '.join(f.args)}) on line {f.line}")
        for a, v in zip(f.args, pos):
            bound[a] = v
        for k, v in kw.items():
            if k not in f.args or k in bound:
                raise self.error(f"{f.name}() got an unexpected or repeated argument {k!r}",
                                 node, hint=f"def {f.name}({', '.join(f.args)})")
            bound[k] = v
        missing = [a for a in f.args if a not in bound]
        if missing:
            raise self.error(f"{f.name}() is missing argument(s) {', '.join(missing)}", node,
                             hint=f"def {f.name}({', '.join(f.args)}) on line {f.line}")
        saved = self.locals, self.limit, self.func_line
        self.locals, self.limit, self.func_line = bound, f.seq, f.line
        self.call_stack.append(f.name)
        try:
            return self.eval(f.body, depth)
        finally:
            self.call_stack.pop()
            self.locals, self.limit, self.func_line = saved


_SYMBOL = {"add": "+", "sub": "-", "mul": "*", "div": "/"}


def loads(text: str, file: str = "<string>") -> Shape:
    """Load a model from ``.csdf`` text.

    Returns:
        The exported :class:`csdf.Shape` (its parameters are ``shape.params``).

    Raises:
        ModelError: with file, line, column, a caret under the offending text and a hint.
    """
    check_source(text, file, MAX_FILE_BYTES, "model text")
    loader = _Loader(text, file)
    try:
        tree = parser().parse(text)
    except UnexpectedInput as exc:
        raise _syntax_error(exc, loader) from None
    except RecursionError:  # pragma: no cover - the LALR parser is not recursive
        raise ModelError("model nested too deeply", file=file) from None
    try:
        shape = loader.run(tree)
    except RecursionError:
        raise ModelError("model nested too deeply", file=file) from None
    try:
        n = len(shape.compile())
    except RecursionError:
        raise ModelError("model nested too deeply to compile", file=file) from None
    except CsdfError as exc:
        raise ModelError(str(exc), file=file) from None
    if n > MAX_INSTRUCTIONS:
        raise ModelError(f"model compiles to {n} instructions; the limit is {MAX_INSTRUCTIONS}",
                         file=file)
    return shape


_CLOSER = {"(": ")", "[": "]"}
_STRING_AT = re.compile(r"\"[A-Za-z0-9_+\-]{0,16}\"|'[A-Za-z0-9_+\-]{0,16}'")


def _open_brackets(text: str, end: int) -> list[tuple[str, int, int]]:
    """The brackets still open at character offset ``end``, outermost first, as
    ``(bracket, line, column)`` (1-based). Comments and strings are skipped; a closing
    bracket closes the innermost open one (a mismatch is the parser's error)."""
    stack: list[tuple[str, int, int]] = []
    line, line_start, i = 1, 0, 0
    end = min(end, len(text))
    while i < end:
        ch = text[i]
        if ch == "\n":
            line, line_start = line + 1, i + 1
        elif ch == "#":
            j = text.find("\n", i)
            i = end if j < 0 else j
            continue
        elif ch in "\"'":
            m = _STRING_AT.match(text, i)
            if m is not None:
                i = m.end()
                continue
        elif ch in _CLOSER:
            stack.append((ch, line, i - line_start + 1))
        elif ch in ")]" and stack:
            stack.pop()
        i += 1
    return stack


def _bracket_error(exc: UnexpectedInput, loader: _Loader) -> ModelError | None:
    """Python's report for a bracket problem, or None: ``'(' was never closed`` at the
    opening bracket when the model ends, or a keyword (which cannot stand inside
    brackets) follows, while it is open; ``closing bracket ']' does not match opening
    bracket '('`` at a closing bracket of the other kind."""
    text = loader.text
    if isinstance(exc, UnexpectedEOF):
        tok = None
    elif isinstance(exc, UnexpectedToken):
        tok = exc.token
    else:
        return None
    at_end = tok is None or tok.type == "$END"
    end = len(text) if at_end or tok.start_pos is None else tok.start_pos
    stack = _open_brackets(text, end)
    if not stack:
        return None
    ch, line, col = stack[-1]
    src = loader.lines[line - 1] if 0 < line <= len(loader.lines) else ""
    if at_end or str(tok) in KEYWORDS:
        where = "the end of the model" if at_end else f"{str(tok)!r} on line {tok.line}"
        return ModelError(f"{ch!r} was never closed", file=loader.file, line=line,
                          column=col, source_line=src,
                          hint=f"add the matching {_CLOSER[ch]!r} before {where}")
    if str(tok) in (")", "]") and str(tok) != _CLOSER[ch]:
        tline = tok.line or 0
        tsrc = loader.lines[tline - 1] if 0 < tline <= len(loader.lines) else ""
        return ModelError(f"closing bracket {str(tok)!r} does not match opening bracket "
                          f"{ch!r} on line {line}", file=loader.file, line=tline,
                          column=tok.column or 0, source_line=tsrc,
                          hint=f"the {ch!r} at {line}:{col} needs {_CLOSER[ch]!r}")
    return None


def _lines(text: str) -> list[str]:
    """The model's lines as the parser numbers them: split at ``\n`` only (``splitlines``
    also splits at ``\r``, ``\x0c``, ``\u2028``, ..., which the parser counts as spaces
    or comment text), without the empty piece after a final newline."""
    lines = text.split("\n")
    if len(lines) > 1 and lines[-1] == "":
        lines.pop()
    return lines


def _syntax_error(exc: UnexpectedInput, loader: _Loader) -> ModelError:
    bracket = _bracket_error(exc, loader)
    if bracket is not None:
        return bracket
    line = getattr(exc, "line", 0) or 0
    col = getattr(exc, "column", 0) or 0
    if isinstance(exc, UnexpectedCharacters):
        ch = loader.text[exc.pos_in_stream] if exc.pos_in_stream < len(loader.text) else ""
        msg = f"unexpected character {ch!r}"
        hint = ""
        if ch in "\"'":
            hint = "strings are short names such as 'x' or \"xy\" (letters, digits, _ + -)"
    elif isinstance(exc, UnexpectedEOF):
        lines = loader.lines or [""]
        line, col = len(lines), len(lines[-1]) + 1
        msg = "unexpected end of the model"
        hint = "an expression or statement is incomplete"
    elif isinstance(exc, UnexpectedToken):
        tok = exc.token
        if tok.type == "$END":
            lines = loader.lines or [""]
            line, col = len(lines), len(lines[-1]) + 1
            msg = "unexpected end of the model"
        else:
            msg = f"unexpected {str(tok)!r}"
            if str(tok) in KEYWORDS:
                msg += " (a keyword cannot be used as a name)"
        expected = sorted(_pretty(t) for t in exc.expected)[:8]
        hint = f"expected one of: {', '.join(expected)}" if expected else ""
    else:  # pragma: no cover
        msg, hint = "syntax error", ""
    src = loader.lines[line - 1] if 0 < line <= len(loader.lines) else ""
    return ModelError(msg, file=loader.file, line=line, column=col, hint=hint,
                      source_line=src)


_TOKEN_NAMES = {
    "LPAR": "(", "RPAR": ")", "LSQB": "[", "RSQB": "]", "COMMA": ",", "EQUAL": "=",
    "VBAR": "|", "AMPERSAND": "&", "PLUS": "+", "MINUS": "-", "STAR": "*", "SLASH": "/",
    "TILDE": "~", "DOT": ".", "NAME": "a name", "NUMBER": "a number", "STRING": "a string",
}


def _pretty(t: str) -> str:
    if t in _TOKEN_NAMES:
        return _TOKEN_NAMES[t]
    return t.lower().strip("_") if t.isupper() else t


def load(path: str | os.PathLike) -> Shape:
    """Load a ``.csdf`` model file (see :func:`loads`); a ``.vm`` file (Fidget's text
    format) is read by :func:`csdf.lang.vm.load_vm`, an OpenSCAD ``.csg`` file by
    :func:`csdf.lang.csg.load_csg` and a ``.scad`` file (through the ``openscad``
    program) by :func:`csdf.lang.csg.load_scad`."""
    p = Path(path)
    if p.suffix.lower() == ".vm":
        from .vm import load_vm

        return load_vm(p)
    if p.suffix.lower() == ".csg":
        from .csg import load_csg

        return load_csg(p)
    if p.suffix.lower() == ".scad":
        from .csg import load_scad

        return load_scad(p)
    text = read_source(p, MAX_FILE_BYTES, "model")
    return loads(text, file=str(p))


