"""Reading Fidget's ``.vm`` text format: one expression node per line.

The format (Matt Keeter's Fidget, ``Context::from_text``)::

    # a comment line
    NAME OPCODE ARG...

``NAME`` is any token without whitespace (Fidget writes ``_1f``-style hex ids), each
``ARG`` the name of a node defined on an earlier line, except for ``const``, whose one
argument is a number. Blank lines and lines starting with ``#`` are skipped. The *last*
node is the field. Stricter than Fidget's reader: a name may be defined only once, and
a line must have exactly its opcode's number of arguments. A file using ``var-z`` is a
3D field, else a 2D one.

Opcodes (:data:`OPCODES`) and how csdf builds them (``a``, ``b`` the arguments):

==================================  ==================================================
``var-x var-y var-z``               the coordinates
``const``                           a float64 constant (decimal, ``inf``, ``nan``)
``neg abs sqrt square``             the csdf op of that name
``sin cos tan asin acos atan exp``  likewise
``ln``                              ``log``
``recip``                           ``1 / a``
``floor``                           ``floor``
``ceil``                            ``-floor(-a)``
``round``                           half away from zero (Rust's ``f64::round``):
                                    ``sign(a) * (t + step(|a| - t - 0.5))``,
                                    ``t = floor(|a|)``
``add sub mul div min max``         the csdf op of that name
``atan2``                           ``atan2(a, b)`` = ``atan2(y, x)``
``mod``                             Euclidean remainder (Rust's ``rem_euclid``, in
                                    ``[0, |b|)``): ``mod(a, abs(b))``
``compare``                         ``-1, 0, 1`` as ``a <, =, > b``: ``sign(a - b)``
``and``                             ``a`` if ``a == 0`` else ``b``: ``nz(a) * b``
``or``                              ``a`` if ``a != 0`` else ``b``:
                                    ``a + (1 - nz(a)) * b``
``not``                             ``1`` if ``a == 0`` else ``0``: ``1 - nz(a)``
==================================  ==================================================

with ``nz(a) = sign(|a|)`` (1 where ``a != 0``, 0 where ``a == 0``). The rewritten
opcodes agree with Fidget's definitions for finite operands, up to rounding for ``mod``
(a floored division, not an exact remainder); they differ where Fidget's ignore an
infinite or NaN operand (``compare(inf, inf)`` is NaN here, 0 in Fidget; ``and`` and
``or`` with an infinite unused operand give NaN; ``round(inf)`` is NaN). Every other
token in the opcode position is an error.

The loaded field is a :class:`~csdf.Shape` built through :mod:`csdf.expr` (so the
file's shared nodes stay shared: a node used many times is compiled once) by
:func:`csdf.shapes.exprfield.expr_shape`: its distance contract is ``'neither'``, its
Lipschitz bound ``inf`` and its bounds ``None``, because a ``.vm`` file states nothing
about them.

Limits: :data:`MAX_VM_BYTES` bytes of text, :data:`MAX_VM_NODES` nodes, and the
shapes layer's :data:`~csdf.shapes.base.MAX_EXPR_NODES` expression nodes. Every problem
is a :class:`~csdf.errors.ModelError` naming ``file:line:column`` with the line and a
caret.
"""

from __future__ import annotations

import difflib
import os
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from .. import expr as E
from ..errors import CsdfError, ModelError
from ..expr import Expr
from ..shapes.base import MAX_EXPR_NODES, Shape
from ..shapes.exprfield import expr_shape
from .source import check_source, read_source

__all__ = ["load_vm", "loads_vm", "OPCODES", "VmOp", "MAX_VM_BYTES", "MAX_VM_NODES"]

#: the largest ``.vm`` text accepted, in bytes (Prospero is about 150 kB)
MAX_VM_BYTES = 64 * 1024 * 1024
#: the most nodes (non-comment lines) a ``.vm`` file may have (Prospero has 7,866)
MAX_VM_NODES = 1_000_000


def _nz(a: Expr) -> Expr:
    """1 where ``a != 0``, 0 where ``a == 0`` (NaN stays NaN)."""
    return E.sign(abs(a))


def _round(a: Expr) -> Expr:
    u = abs(a)
    t = E.floor(u)
    return E.sign(a) * (t + E.step((u - t) - 0.5))


@dataclass(frozen=True)
class VmOp:
    """One opcode of the ``.vm`` format: its number of node arguments and how csdf
    builds it from the arguments' expressions."""

    name: str
    arity: int
    build: Callable[..., Expr]


_TABLE: list[tuple[str, int, Callable[..., Expr]]] = [
    ("neg", 1, lambda a: -a),
    ("abs", 1, lambda a: abs(a)),
    ("recip", 1, lambda a: 1.0 / a),
    ("sqrt", 1, E.sqrt),
    ("square", 1, E.square),
    ("floor", 1, E.floor),
    ("ceil", 1, lambda a: -E.floor(-a)),
    ("round", 1, _round),
    ("sin", 1, E.sin),
    ("cos", 1, E.cos),
    ("tan", 1, E.tan),
    ("asin", 1, E.asin),
    ("acos", 1, E.acos),
    ("atan", 1, E.atan),
    ("exp", 1, E.exp),
    ("ln", 1, E.log),
    ("not", 1, lambda a: 1.0 - _nz(a)),
    ("add", 2, lambda a, b: a + b),
    ("sub", 2, lambda a, b: a - b),
    ("mul", 2, lambda a, b: a * b),
    ("div", 2, lambda a, b: a / b),
    ("min", 2, lambda a, b: E.make("min", a, b)),
    ("max", 2, lambda a, b: E.make("max", a, b)),
    ("atan2", 2, E.atan2),
    ("mod", 2, lambda a, b: E.mod(a, abs(b))),
    ("compare", 2, lambda a, b: E.sign(a - b)),
    ("and", 2, lambda a, b: _nz(a) * b),
    ("or", 2, lambda a, b: a + (1.0 - _nz(a)) * b),
]

#: every opcode of the format with node arguments (``var-x``, ``var-y``, ``var-z`` and
#: ``const`` are the leaves)
OPCODES: dict[str, VmOp] = {n: VmOp(n, k, f) for n, k, f in _TABLE}
_LEAVES = {"var-x": E.X, "var-y": E.Y, "var-z": E.Z}
_KNOWN = sorted([*OPCODES, *_LEAVES, "const"])

# a number as Rust's f64 parser reads it (no underscores, no hex), or inf/nan words
_NUMBER = re.compile(
    r"[+-]?(?:(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?|inf|infinity|nan)", re.IGNORECASE)
_TOKEN = re.compile(r"\S+")


class _Lines:
    """The text's lines and the error maker for them."""

    def __init__(self, text: str, file: str):
        self.file = file
        self.lines = text.split("\n")

    def error(self, msg: str, line: int = 0, col: int = 0, width: int = 1,
              hint: str = "") -> ModelError:
        src = self.lines[line - 1].rstrip("\r") if 0 < line <= len(self.lines) else ""
        return ModelError(msg, file=self.file, line=line, column=col, width=width,
                          hint=hint, source_line=src)


def _node(op: str, args: list[tuple[str, int]], nodes: dict[str, tuple[Expr, int]],
          src: _Lines, ln: int) -> Expr:
    """The expression of one node (its opcode and argument count already checked)."""
    if op == "const":
        tok, col = args[0]
        if not _NUMBER.fullmatch(tok):
            raise src.error(f"const expects a number, got {tok!r}", ln, col, len(tok))
        return E.const(float(tok))
    if op in _LEAVES:
        return _LEAVES[op]
    vals = []
    for tok, col in args:
        hit = nodes.get(tok)
        if hit is None:
            raise src.error(f"undefined node {tok!r}", ln, col, len(tok),
                            hint="an argument names a node defined on an earlier line")
        vals.append(hit[0])
    return OPCODES[op].build(*vals)


def _parse(src: _Lines) -> tuple[Expr, bool, int]:
    """``(last node, whether var-z appears, node count)``."""
    nodes: dict[str, tuple[Expr, int]] = {}
    last: Expr | None = None
    uses_z = False
    count = 0
    for ln, raw in enumerate(src.lines, 1):
        toks = [(m.group(), m.start() + 1) for m in _TOKEN.finditer(raw)]
        if not toks or toks[0][0].startswith("#"):
            continue
        count += 1
        if count > MAX_VM_NODES:
            raise src.error(f"the file has more than {MAX_VM_NODES} nodes (the limit)",
                            ln, 1)
        name, ncol = toks[0]
        if len(toks) < 2:
            raise src.error(f"node {name!r} has no opcode", ln, ncol + len(name),
                            hint="a line is: NAME OPCODE ARGS...")
        op, ocol = toks[1]
        args = toks[2:]
        prev = nodes.get(name)
        if prev is not None:
            raise src.error(f"node {name!r} is defined twice", ln, ncol, len(name),
                            hint=f"first defined on line {prev[1]}")
        if op in _LEAVES or op == "const":
            want = 1 if op == "const" else 0
        elif op in OPCODES:
            want = OPCODES[op].arity
        else:
            close = difflib.get_close_matches(op, _KNOWN, n=3)
            hint = (f"did you mean {' or '.join(repr(c) for c in close)}? " if close else "")
            raise src.error(f"unknown opcode {op!r}", ln, ocol, len(op),
                            hint=hint + "known opcodes: " + " ".join(_KNOWN))
        if len(args) != want:
            what = "a number" if op == "const" else f"{want} argument(s)"
            at = args[want] if len(args) > want else (op, ocol)
            col = at[1] if len(args) > want else ocol + len(op)
            raise src.error(f"{op} takes {what}, got {len(args)} argument(s)", ln, col,
                            len(at[0]) if len(args) > want else 1)
        try:
            e = _node(op, args, nodes, src, ln)
        except ModelError:
            raise
        except CsdfError as exc:  # the expression-node budget
            raise src.error(str(exc), ln, ocol, len(op)) from None
        uses_z = uses_z or op == "var-z"
        nodes[name] = (e, ln)
        last = e
    if last is None:
        raise src.error("the file has no nodes (only comments and blank lines)",
                        hint="a line is: NAME OPCODE ARGS...; the last node is the field")
    return last, uses_z, count


def loads_vm(text: str, name: str = "<string>") -> Shape:
    """Load a field from ``.vm`` text (see the module docs).

    Args:
        text: the file's text.
        name: the file name for error messages and the shape's ``args``.

    Returns:
        A 2D :class:`~csdf.Shape` (3D when ``var-z`` appears) whose field is the last
        node; exactness ``'neither'``, Lipschitz bound ``inf``, bounds ``None``. It is
        compiled here (the program is cached on the shape).

    Raises:
        ModelError: naming ``file:line:column`` for an unknown opcode, a wrong number
            of arguments, an undefined or twice-defined name, a bad number, an empty
            file, or a limit exceeded (:data:`MAX_VM_BYTES`, :data:`MAX_VM_NODES`,
            :data:`~csdf.shapes.base.MAX_EXPR_NODES`, the compiler's slot limit).
    """
    check_source(text, name, MAX_VM_BYTES, ".vm text")
    src = _Lines(text, name)
    with E.node_budget(MAX_EXPR_NODES, "the .vm file"):
        root, uses_z, count = _parse(src)
    shape = expr_shape(root, dim=3 if uses_z else 2, name="load_vm", args=(name,))
    try:
        shape.compile()
    except CsdfError as exc:
        raise ModelError(f"{count} nodes do not compile: {exc}", file=name) from None
    return shape


def load_vm(path: str | os.PathLike) -> Shape:
    """Load a Fidget ``.vm`` file (see :func:`loads_vm`; UTF-8 or ASCII text)."""
    p = Path(path)
    text = read_source(p, MAX_VM_BYTES)
    return loads_vm(text, name=str(p))
