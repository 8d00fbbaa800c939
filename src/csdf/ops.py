"""The scalar operation set, and the one specification of every op that the expression
layer, the compiler and every evaluator follow.

Each op has a fixed opcode (part of the bytecode format, see ``docs/bytecode.md``),
an arity (1 or 2), and a Table-1 category of the paper (§4.3):

========  ===============================================================
category  ops
========  ===============================================================
add       ``add sub neg``
mul       ``mul square``
div       ``div mod``
call      ``sqrt sin cos tan asin acos atan atan2 exp log floor``
branch    ``min max abs step sign``
========  ===============================================================

For every op, :data:`OPS` gives in one record (:class:`OpInfo`):

value
    the NumPy function (:attr:`OpInfo.value`). Semantics follow IEEE double / float
    arithmetic as NumPy implements it. Special cases worth knowing:
    ``mod(a, b) = a - b*floor(a/b)`` (GLSL ``mod``, result has the sign of ``b``),
    ``step(a) = 1 if a >= 0 else 0``, ``sign(0) = 0``; every op propagates NaN (NaN in,
    NaN out; ``min``/``max`` too).
derivative
    the forward-mode rule (:class:`Derivative`), with its factors written once as
    formulas (:mod:`csdf.opformula`) from which the NumPy reference evaluates and the
    Numba code generator and GLSL export generate their code.
kink conventions
    what the derivative is where the op is not differentiable (:attr:`OpInfo.kink`):
    ``abs`` -> ``sign(a)`` (0 at 0); ``floor``/``step``/``sign`` -> 0 (structurally:
    no tangent at all, so 0 even where the operand's tangent is infinite or NaN);
    ``sqrt`` at 0 -> 0; ``atan2`` at the origin -> 0; ``min``/``max`` at ties -> the
    :ref:`tie rule <tie rule>` below.
interval rule
    :attr:`OpInfo.interval`, the op's rule in :data:`csdf.interval.RULES` (looked up on
    use: :mod:`csdf.interval` does not import this module, and this module imports it
    only when asked, so neither layer depends on the other at import time).

.. _tie rule:

Tie rule of ``min`` and ``max``
    The result takes operand ``a``'s derivative where ``a`` wins *or ties*, unless
    ``a`` is a constant slot of the program: then ties go to ``b``, whose one-sided
    derivative is the informative one (a box's face normal exactly on the surface:
    ``min(2, x)`` at ``x = 2`` has gradient ``(1, 0, 0)``). :func:`tie_strict` is that
    rule, :func:`tie_comparison` the comparison it gives; every evaluator takes it
    from there (the Numba interpreter through a flag bit the lowering sets from
    :func:`tie_strict`).

Where a value is NaN, its derivatives are NaN too (the evaluators enforce this at the
output). Where a derivative factor or an operand is infinite, a tangent component whose
seed is zero may come out 0 (evaluators that keep structural zeros per component: the
generated kernels, GLSL) or NaN (``0 * inf``: the NumPy reference, the interpreter);
elsewhere the evaluators agree to rounding. ``tests/test_ops.py`` checks every op on
every evaluator against this specification.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol, TypeVar

import numpy as np

from .opformula import Formula

__all__ = ["OpInfo", "Derivative", "OPS", "OPS_BY_CODE", "CATEGORIES", "numpy_impl",
           "interval_rule", "tie_strict", "tie_comparison", "tie_mask", "chain_tangent",
           "TangentAlgebra", "MESH_CODE", "ARG_CODE", "DATA_CODES"]

CATEGORIES = ("add", "mul", "div", "call", "branch")

T = TypeVar("T")


# ---------------------------------------------------------------------------- derivatives
@dataclass(frozen=True)
class Derivative:
    """The forward-mode rule of one op.

    ``kind``:

    ``'chain'``
        ``d(out) = outer * (ca * da + cb * db)``, where ``da``/``db`` are the operands'
        tangents and ``outer``, ``ca``, ``cb`` formulas over ``a``, ``b``, ``v`` (the
        result) and the ``let`` names (``None``: absent, i.e. ``outer = 1`` or the
        operand does not enter). The partial derivatives are ``d/da = outer * ca`` and
        ``d/db = outer * cb``. Evaluators compute this factored form, in this order,
        with :func:`chain_tangent` (a coefficient ``-X`` subtracts its term), so they
        all round alike; a structurally zero tangent contributes nothing (not
        ``0 * factor``, which would turn an infinite factor into NaN).
    ``'select'``
        ``min``/``max``: ``d(out) = da`` where ``a CMP b``, else ``db``, with ``CMP``
        from :func:`tie_comparison` (a selection, not ``mask * da + ...``).
    ``'zero'``
        ``floor``/``step``/``sign``: no tangent (structurally zero).
    """

    kind: str
    outer: Formula | None = None
    ca: Formula | None = None
    cb: Formula | None = None
    let: tuple[tuple[str, Formula], ...] = ()
    #: ``((operand 'a'|'b', negated, magnitude or None for 1), ...)``, from ca and cb
    terms: tuple[tuple[str, bool, Formula | None], ...] = field(default=(), compare=False)

    @property
    def formulas(self) -> tuple[Formula, ...]:
        """Every formula of the rule (``let`` first, then coefficients, then outer)."""
        fs = [f for _, f in self.let] + [m for _, _, m in self.terms if m is not None]
        return tuple(fs + ([self.outer] if self.outer is not None else []))


def _chain(*, outer: str | None = None, ca: str | None = None, cb: str | None = None,
           let: tuple[tuple[str, str], ...] = ()) -> Derivative:
    fa = Formula(ca) if ca is not None else None
    fb = Formula(cb) if cb is not None else None
    terms = tuple((which, *f.split_sign()) for which, f in (("a", fa), ("b", fb))
                  if f is not None)
    return Derivative("chain", Formula(outer) if outer is not None else None, fa, fb,
                      tuple((n, Formula(f)) for n, f in let), terms)


def _unary(factor: str) -> Derivative:
    """``d(op(a)) = factor * da``."""
    return _chain(outer=factor, ca="1")


_SELECT = Derivative("select")
_ZERO = Derivative("zero")


class TangentAlgebra(Protocol[T]):
    """The four tangent operations an evaluator supplies to :func:`chain_tangent`
    (a tangent is a backend value: an array, a variable name, a GLSL expression)."""

    def scale(self, f: Any, t: T) -> T: ...
    def add(self, u: T, v: T) -> T: ...
    def sub(self, u: T, v: T) -> T: ...
    def neg(self, t: T) -> T: ...


def chain_tangent(rule: Derivative, ta: T | None, tb: T | None,
                  coef: Callable[[Formula], Any], alg: TangentAlgebra[T]) -> T | None:
    """One tangent of a ``'chain'`` op: ``outer * (ca * ta + cb * tb)``.

    Args:
        rule: the op's :class:`Derivative` (kind ``'chain'``).
        ta, tb: the operands' tangents; ``None`` is structurally zero (and so is the
            result when both are, or the one that enters is).
        coef: the backend value of a formula (called only for the formulas needed;
            callers cache it and bind the ``let`` names first).
        alg: the backend's tangent operations.
    """
    acc = None
    for which, negated, mag in rule.terms:
        t = ta if which == "a" else tb
        if t is None:
            continue
        x = t if mag is None else alg.scale(coef(mag), t)
        if acc is None:
            acc = alg.neg(x) if negated else x
        else:
            acc = alg.sub(acc, x) if negated else alg.add(acc, x)
    if acc is not None and rule.outer is not None:
        acc = alg.scale(coef(rule.outer), acc)
    return acc


# ---------------------------------------------------------------------------- tie rule
def tie_strict(a_is_const: bool) -> bool:
    """The tie rule of ``min``/``max`` (see the module docs): True when ties go to
    ``b`` (the comparison that picks ``a`` is strict), i.e. when operand ``a`` is a
    constant slot of the program."""
    return bool(a_is_const)


def tie_comparison(op: str, a_is_const: bool) -> str:
    """The comparison ``CMP`` for which ``op`` (``'min'`` or ``'max'``) takes operand
    ``a``'s derivative where ``a CMP b`` (and ``b``'s elsewhere, NaN included):
    ``'<='``/``'<'`` for ``min``, ``'>='``/``'>'`` for ``max`` (strict per
    :func:`tie_strict`)."""
    strict = tie_strict(a_is_const)
    if op == "min":
        return "<" if strict else "<="
    if op == "max":
        return ">" if strict else ">="
    raise ValueError(f"the tie rule is for min and max, not {op!r}")


_NP_CMP: dict[str, Callable] = {"<": np.less, "<=": np.less_equal, ">": np.greater,
                                ">=": np.greater_equal}


def tie_mask(op: str, a, b, a_is_const: bool):
    """Where ``op`` takes ``a``'s derivative (NumPy bool array or scalar)."""
    return _NP_CMP[tie_comparison(op, a_is_const)](a, b)


# ---------------------------------------------------------------------------- values
def _step(a):
    return np.heaviside(a, 1.0).astype(np.result_type(a), copy=False)


def _mod(a, b):
    return a - b * np.floor(a / b)


@dataclass(frozen=True)
class OpInfo:
    """The specification of one scalar operation (see the module docs).

    Attributes:
        name, code, arity, category, commutative: identity and bytecode facts.
        value: the NumPy function computing the op element-wise.
        derivative: the forward-mode rule.
        kink: the derivative convention where the op is not differentiable ('' when
            it is differentiable wherever its value is finite).
    """

    name: str
    code: int
    arity: int
    category: str
    commutative: bool = False
    value: Callable | None = field(default=None, compare=False, repr=False)
    derivative: Derivative = field(default=_ZERO, compare=False, repr=False)
    kink: str = field(default="", compare=False, repr=False)

    @property
    def interval(self) -> Callable:
        """The op's interval rule, :data:`csdf.interval.RULES` ``[name]``: unary
        ``(alo, ahi) -> (lo, hi)``, binary ``(alo, ahi, blo, bhi) -> (lo, hi)``."""
        return interval_rule(self.name)

    def partials(self, a, b=None, v=None, *, a_is_const: bool = False,
                 dtype=np.float64) -> tuple[Any, Any]:
        """``(d out/da, d out/db)`` at ``a``, ``b`` with NumPy (``v``, the result, is
        computed when not given; ``d/db`` is 0 for unary ops). For ``min``/``max``
        these are the 0/1 weights of the tie rule; evaluators select rather than
        multiply (see :class:`Derivative`)."""
        dt = np.dtype(dtype)
        a = np.asarray(a, dt)
        b = None if b is None else np.asarray(b, dt)
        with np.errstate(all="ignore"):
            if v is None:
                v = self.value(a, b) if self.arity == 2 else self.value(a)
            rule = self.derivative
            zero = np.zeros(np.broadcast(a, a if b is None else b).shape, dt)
            if rule.kind == "zero":
                return zero, zero
            if rule.kind == "select":
                m = tie_mask(self.name, a, b, a_is_const)
                return zero + m, zero + ~m
            env: dict[str, Any] = {"a": a, "b": b, "v": v}
            for name, f in rule.let:
                env[name] = f.numpy(env, dt)
            out = []
            for c in (rule.ca, rule.cb):
                p = zero if c is None else zero + c.numpy(env, dt)
                if rule.outer is not None:
                    p = p * rule.outer.numpy(env, dt)
                out.append(p)
            return out[0], out[1]


def interval_rule(name: str) -> Callable:
    """The interval rule of op ``name``: :data:`csdf.interval.RULES` ``[name]``
    (:mod:`csdf.interval` is imported on this first use)."""
    from . import interval

    return interval.RULES[name]


# name, opcode, arity, category, value, derivative, kink convention
_TABLE: list[tuple[str, int, int, str, Callable, Derivative, str]] = [
    # unary
    ("neg", 1, 1, "add", np.negative, _chain(ca="-1"), ""),
    ("abs", 2, 1, "branch", np.abs, _unary("sign(a)"), "derivative sign(a): 0 at a = 0"),
    ("sqrt", 3, 1, "call", np.sqrt, _unary("pos_div(0.5, v)"),
     "derivative 0 at a = 0 (where it is infinite)"),
    ("square", 4, 1, "mul", np.square, _unary("2 * a"), ""),
    ("sin", 5, 1, "call", np.sin, _unary("cos(a)"), ""),
    ("cos", 6, 1, "call", np.cos, _unary("-sin(a)"), ""),
    ("tan", 7, 1, "call", np.tan, _unary("1 + v * v"), ""),
    ("asin", 8, 1, "call", np.arcsin, _unary("1 / sqrt(1 - a * a)"),
     "derivative inf at a = +-1"),
    ("acos", 9, 1, "call", np.arccos, _unary("-1 / sqrt(1 - a * a)"),
     "derivative -inf at a = +-1"),
    ("atan", 10, 1, "call", np.arctan, _unary("1 / (1 + a * a)"), ""),
    ("exp", 11, 1, "call", np.exp, _unary("v"), ""),
    ("log", 12, 1, "call", np.log, _unary("1 / a"), "derivative inf at a = 0"),
    ("floor", 13, 1, "call", np.floor, _ZERO, "derivative 0 (also at the jumps)"),
    ("step", 14, 1, "branch", _step, _ZERO, "derivative 0 (also at a = 0)"),
    ("sign", 15, 1, "branch", np.sign, _ZERO, "derivative 0 (also at a = 0)"),
    # binary
    ("add", 32, 2, "add", np.add, _chain(ca="1", cb="1"), ""),
    ("sub", 33, 2, "add", np.subtract, _chain(ca="1", cb="-1"), ""),
    ("mul", 34, 2, "mul", np.multiply, _chain(ca="b", cb="a"), ""),
    ("div", 35, 2, "div", np.divide, _chain(outer="1 / b", ca="1", cb="-v"), ""),
    ("min", 36, 2, "branch", np.minimum, _SELECT, "ties: the tie rule (tie_comparison)"),
    ("max", 37, 2, "branch", np.maximum, _SELECT, "ties: the tie rule (tie_comparison)"),
    ("atan2", 38, 2, "call", np.arctan2,
     _chain(ca="pos_div(b, r2)", cb="pos_div(-a, r2)", let=(("r2", "a * a + b * b"),)),
     "atan2(a=y, b=x); derivative 0 at the origin"),
    ("mod", 39, 2, "div", _mod, _chain(ca="1", cb="-floor(a / b)"),
     "derivative of a - b*floor(a/b) with floor's derivative 0 (also at the jumps)"),
]
_COMMUTATIVE = {"add", "mul", "min", "max"}

OPS: dict[str, OpInfo] = {
    name: OpInfo(name, code, arity, cat, name in _COMMUTATIVE, fn, deriv, kink)
    for name, code, arity, cat, fn, deriv, kink in _TABLE
}
OPS_BY_CODE: dict[int, OpInfo] = {info.code: info for info in OPS.values()}

# ------------------------------------------------------------------------- data calls
#: opcode of a mesh call: ``slot[dst] = d(slot[a], slot[b], slot[c])``, the exact signed
#: distance to the closed triangle mesh of the program's data block ``k``; it takes two
#: rows of the tape, ``(MESH_CODE, dst, a, b)`` then ``(ARG_CODE, dst, c, k)`` (see
#: ``docs/bytecode.md``). Not in :data:`OPS`: it is no scalar op of the expression
#: algebra (its value needs the data block), so the per-op tables do not list it.
#: Derivative: the chain rule through the mesh's unit gradient (the direction from the
#: nearest point). Interval: the value at the centre of the box of its three inputs,
#: plus or minus the box's half diagonal (the distance is 1-Lipschitz). Category: call.
MESH_CODE = 48
#: the second row of a mesh call: its third operand and its data block
ARG_CODE = 49
#: the data opcodes (rows that evaluators handle outside :data:`OPS`)
DATA_CODES = frozenset({MESH_CODE, ARG_CODE})


def numpy_impl(name: str) -> Callable:
    """Return the NumPy function computing op ``name`` element-wise."""
    fn = OPS[name].value
    assert fn is not None
    return fn
