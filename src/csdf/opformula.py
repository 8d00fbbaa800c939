"""The little formula language of the op specification (:mod:`csdf.ops`).

A derivative factor such as ``1 / sqrt(1 - a * a)`` is written once, as text, in the op
table; every evaluator turns it into its own code from that one definition: the NumPy
reference evaluates it on arrays (:meth:`Formula.numpy`), the generated Numba kernels
and the GLSL export render it as source text (:meth:`Formula.render`).

Syntax: a Python expression over

* the names ``a``, ``b`` (the operands), ``v`` (the op's result) and names bound by the
  rule's ``let`` clauses;
* numeric literals (``0.5``, ``1``, ``2``);
* unary ``-``, binary ``+ - * /`` (usual precedence, left to right);
* the functions ``sin cos sqrt floor sign`` (as NumPy defines them) and
  ``pos_div(n, d)`` = ``n / d`` where ``d > 0``, else 0 (also where ``d`` is NaN): the
  guarded quotient that gives the kink conventions (``sqrt`` at 0, ``atan2`` at the
  origin).

Rendering keeps the evaluation order of the text exactly (a right operand of equal
precedence stays parenthesised), so every target rounds as the NumPy reference does.
"""

from __future__ import annotations

import ast
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["Formula", "FUNCTIONS", "Target"]

#: the functions a formula may call, with their arities
FUNCTIONS: dict[str, int] = {"sin": 1, "cos": 1, "sqrt": 1, "floor": 1, "sign": 1,
                             "pos_div": 2}

_BINOPS: dict[type, tuple[str, int]] = {
    ast.Add: ("+", 1), ast.Sub: ("-", 1), ast.Mult: ("*", 2), ast.Div: ("/", 2),
}
_UNARY_PREC = 3
_ATOM_PREC = 4


def _pos_div(n, d):
    """``n / d`` where ``d > 0``, else 0 (NumPy; keeps the dtype of ``n / d``; the
    callers of :meth:`Formula.numpy` silence NumPy's floating-point warnings)."""
    return np.where(d > 0, n / d, 0)


_NUMPY_FUNCS: dict[str, Callable] = {
    "sin": np.sin, "cos": np.cos, "sqrt": np.sqrt, "floor": np.floor, "sign": np.sign,
    "pos_div": _pos_div,
}
_NUMPY_BINOPS: dict[type, Callable] = {
    ast.Add: np.add, ast.Sub: np.subtract, ast.Mult: np.multiply, ast.Div: np.divide,
}


@dataclass(frozen=True)
class Target:
    """How one evaluator writes formulas as source text.

    Attributes:
        name: ``name(n) -> text`` for a variable (``a``, ``b``, ``v``, a ``let`` name).
        literal: ``literal(x) -> text`` for a number (an atom, e.g. ``1.0`` or ``k1``).
        calls: function name -> ``str.format`` template over the rendered arguments
            ``{0}``, ``{1}`` (e.g. ``'np.sin({0})'``). Arguments are rendered as atoms
            (parenthesised unless they are a name, literal or call) when
            ``atom_args`` names the function, else at the lowest precedence.
        atom_args: functions whose template needs atomic arguments (such as GLSL's
            ``({1} > 0.0 ? {0} / {1} : 0.0)``).
    """

    name: Callable[[str], str]
    literal: Callable[[float], str]
    calls: Mapping[str, str]
    atom_args: frozenset[str] = field(default_factory=frozenset)


class Formula:
    """One parsed formula (see the module docs). Immutable; compare by text."""

    __slots__ = ("text", "_tree", "_np")

    def __init__(self, text: str):
        self.text = text
        tree = ast.parse(text, mode="eval").body
        _check(tree, text)
        self._tree = tree
        self._np = _numpy_closure(tree)

    def __repr__(self) -> str:
        return f"Formula({self.text!r})"

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Formula) and other.text == self.text

    def __hash__(self) -> int:
        return hash(self.text)

    @property
    def names(self) -> frozenset[str]:
        """The variables the formula reads."""
        return frozenset(n.id for n in ast.walk(self._tree) if isinstance(n, ast.Name)
                         and n.id not in FUNCTIONS)

    @property
    def is_name(self) -> bool:
        """True when the formula is a bare variable (``v``, ``b``)."""
        return isinstance(self._tree, ast.Name)

    @property
    def is_one(self) -> bool:
        """True when the formula is the literal 1."""
        return isinstance(self._tree, ast.Constant) and self._tree.value == 1

    def split_sign(self) -> tuple[bool, Formula | None]:
        """``(negated, magnitude)``: a formula ``-X`` gives ``(True, X)``, others
        ``(False, self)``; a magnitude of 1 is ``None`` (``'1'`` -> ``(False, None)``,
        ``'-1'`` -> ``(True, None)``). Tangent algebra uses it to subtract a term
        instead of multiplying by a negated coefficient."""
        t = self._tree
        if isinstance(t, ast.UnaryOp) and isinstance(t.op, ast.USub):
            inner = Formula(ast.unparse(t.operand))
            return True, (None if inner.is_one else inner)
        return False, (None if self.is_one else self)

    def numpy(self, env: Mapping[str, Any], dtype: np.dtype) -> Any:
        """The formula's value with NumPy on the arrays or scalars of ``env``
        (``{'a': ..., 'b': ..., 'v': ..., <let names>: ...}``), literals in ``dtype``.
        Division by zero and the like follow IEEE; call it under
        ``np.errstate(all='ignore')`` to silence NumPy's warnings."""
        return self._np(env, dtype)

    def evaluate(self, env: Mapping[str, Any], functions: Mapping[str, Callable]) -> Any:
        """The formula's value with the names bound by ``env`` and the functions
        (``sin``, ``sqrt``, ``pos_div``, ...) by ``functions``; ``+ - * /`` and unary
        ``-`` are Python's operators on the values (so any type with arithmetic works:
        floats, arrays, expressions)."""
        return _evaluate(self._tree, env, functions)

    def render(self, target: Target, *, atom: bool = False) -> str:
        """The formula as source text for ``target`` (evaluation order preserved);
        ``atom``: parenthesised unless it is a name, literal or call, so that it can
        be an operand of any operator."""
        return _render(self._tree, target, _ATOM_PREC if atom else 0)


def _check(node: ast.AST, text: str) -> None:
    """Reject anything outside the formula language."""
    if isinstance(node, ast.BinOp) and type(node.op) in _BINOPS:
        _check(node.left, text)
        _check(node.right, text)
    elif isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
        _check(node.operand, text)
    elif isinstance(node, ast.Constant) and type(node.value) in (int, float):
        pass
    elif isinstance(node, ast.Name) and node.id not in FUNCTIONS:
        pass
    elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
          and node.func.id in FUNCTIONS and not node.keywords
          and len(node.args) == FUNCTIONS[node.func.id]):
        for arg in node.args:
            _check(arg, text)
    else:
        raise ValueError(f"formula {text!r}: {ast.unparse(node)!r} is outside the language")


def _evaluate(node: ast.AST, env: Mapping[str, Any], functions: Mapping[str, Callable]
              ) -> Any:
    if isinstance(node, ast.Constant):
        return float(node.value)
    if isinstance(node, ast.Name):
        return env[node.id]
    if isinstance(node, ast.UnaryOp):
        return -_evaluate(node.operand, env, functions)
    if isinstance(node, ast.BinOp):
        a = _evaluate(node.left, env, functions)
        b = _evaluate(node.right, env, functions)
        op = type(node.op)
        if op is ast.Add:
            return a + b
        if op is ast.Sub:
            return a - b
        if op is ast.Mult:
            return a * b
        return a / b
    assert isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
    return functions[node.func.id](*(_evaluate(x, env, functions) for x in node.args))


def _numpy_closure(node: ast.AST) -> Callable[[Mapping[str, Any], np.dtype], Any]:
    """A function ``(env, dtype) -> value`` evaluating ``node`` with NumPy."""
    if isinstance(node, ast.BinOp):
        fn = _NUMPY_BINOPS[type(node.op)]
        left, right = _numpy_closure(node.left), _numpy_closure(node.right)
        return lambda env, dt: fn(left(env, dt), right(env, dt))
    if isinstance(node, ast.UnaryOp):
        inner = _numpy_closure(node.operand)
        return lambda env, dt: np.negative(inner(env, dt))
    if isinstance(node, ast.Constant):
        value = float(node.value)
        return lambda env, dt: dt.type(value)
    if isinstance(node, ast.Name):
        key = node.id
        return lambda env, dt: env[key]
    assert isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
    fn = _NUMPY_FUNCS[node.func.id]
    args = [_numpy_closure(a) for a in node.args]
    if len(args) == 1:
        (only,) = args
        return lambda env, dt: fn(only(env, dt))
    return lambda env, dt: fn(*(a(env, dt) for a in args))


def _prec(node: ast.AST) -> int:
    if isinstance(node, ast.BinOp):
        return _BINOPS[type(node.op)][1]
    if isinstance(node, ast.UnaryOp):
        return _UNARY_PREC
    return _ATOM_PREC


def _render(node: ast.AST, t: Target, min_prec: int) -> str:
    """Text of ``node``, parenthesised when its precedence is below ``min_prec``."""
    p = _prec(node)
    if isinstance(node, ast.BinOp):
        sym, _ = _BINOPS[type(node.op)]
        s = f"{_render(node.left, t, p)} {sym} {_render(node.right, t, p + 1)}"
    elif isinstance(node, ast.UnaryOp):
        s = f"-{_render(node.operand, t, _UNARY_PREC + 1)}"  # never "--a" (GLSL decrement)
    elif isinstance(node, ast.Constant):
        s = t.literal(float(node.value))
    elif isinstance(node, ast.Name):
        s = t.name(node.id)
    else:
        assert isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
        fname = node.func.id
        arg_prec = _ATOM_PREC if fname in t.atom_args else 0
        s = t.calls[fname].format(*(_render(a, t, arg_prec) for a in node.args))
    return f"({s})" if p < min_prec else s
