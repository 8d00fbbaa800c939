"""Symbolic derivatives of expressions: :func:`gradient`.

Forward mode over the DAG, children before parents (:func:`csdf.expr.walk`), with every
op's rule from its specification (:data:`csdf.ops.OPS`): the same factored form
``outer * (ca * da + cb * db)`` (:func:`csdf.ops.chain_tangent`) that the evaluators
run, with the coefficient formulas evaluated on expressions
(:meth:`csdf.opformula.Formula.evaluate`), so the derivative expression means what the
evaluators compute, and a structurally zero tangent stays absent (``None``). ``min`` and
``max`` select the winner's tangent with the tie rule (:func:`csdf.ops.tie_comparison`)
as a step function; ``floor``, ``step`` and ``sign`` have none. Shared subexpressions stay
shared: each node's tangent is built once.

The result is an expression like any other: it compiles, evaluates on every backend and
has intervals (``csdf.Shape.normalized`` is ``f / |grad f|`` built from it, and the
Lipschitz bound of a user's field comes from the intervals of its gradient).
"""

from __future__ import annotations

from collections.abc import Sequence

from .errors import CsdfError
from .expr import Expr, X, Y, Z, as_expr, cos, floor, sign, sin, sqrt, step, walk
from .ops import OPS, chain_tangent, tie_comparison

__all__ = ["gradient", "partials"]

Tangent = tuple  # one expression (or None) per variable


def _pos_div(n: Expr, d: Expr) -> Expr:
    """``n / d`` where ``d > 0``, else 0, as an expression: the quotient is taken with
    a denominator of 1 where ``d <= 0`` (so no infinity or NaN is made there)."""
    gt = 1.0 - step(-d)  # 1 where d > 0 (step(0) = 1)
    return n * gt / (d + (1.0 - gt) * (1.0 + abs(d)))


_FUNCS = {"sin": sin, "cos": cos, "sqrt": sqrt, "floor": floor, "sign": sign,
          "pos_div": _pos_div}


class _Alg:
    """Tangent algebra on tuples of expressions (``None`` entries: structurally 0)."""

    def scale(self, f, t):
        return tuple(None if c is None else f * c for c in t)

    def add(self, u, v):
        return tuple(b if a is None else (a if b is None else a + b) for a, b in zip(u, v))

    def sub(self, u, v):
        return tuple((None if b is None else -b) if a is None else (a if b is None else a - b)
                     for a, b in zip(u, v))

    def neg(self, t):
        return tuple(None if c is None else -c for c in t)


def gradient(e: Expr, wrt: Sequence[Expr] = (X, Y, Z)) -> tuple[Expr, ...]:
    """The partial derivatives of ``e`` with respect to the leaves ``wrt`` (the
    coordinates by default; parameters work too), as expressions (the constant 0 where
    ``e`` does not depend on one)."""
    return _derivatives(as_expr(e), wrt, walk(as_expr(e)))


def partials(e: Expr, nodes: Sequence[Expr]) -> tuple[Expr, ...]:
    """The partial derivatives of ``e`` with respect to its subexpressions ``nodes``,
    each held as an independent variable (what lies below them is not looked at): for
    ``e = min(a, b)`` with ``nodes = (a, b)``, the steps that select the winner; for a
    smooth blend of ``a`` and ``b``, its blend weights. The constant 0 where ``e`` does
    not reach a node. The nodes must not lie below one another."""
    e = as_expr(e)
    stop = {id(n) for n in nodes}
    return _derivatives(e, nodes, _walk_until(e, stop))


def _walk_until(root: Expr, stop: set[int]) -> list[Expr]:
    """The nodes reachable from ``root`` without passing below a node of ``stop``,
    children before parents."""
    seen: set[int] = set()
    out: list[Expr] = []
    stack: list[tuple[Expr, bool]] = [(root, False)]
    while stack:
        node, expanded = stack.pop()
        if id(node) in seen:
            continue
        if expanded or id(node) in stop:
            seen.add(id(node))
            out.append(node)
            continue
        stack.append((node, True))
        for a in reversed(node.args):
            if id(a) not in seen:
                stack.append((a, False))
    return out


def _derivatives(e: Expr, wrt: Sequence[Expr], order) -> tuple[Expr, ...]:
    k = len(wrt)
    seeds = {id(w): i for i, w in enumerate(wrt)}
    alg = _Alg()
    tan: dict[int, Tangent | None] = {}
    for node in order:
        if not node.args or id(node) in seeds:
            i = seeds.get(id(node))
            tan[id(node)] = None if i is None else tuple(
                as_expr(1.0) if j == i else None for j in range(k))
            continue
        a = node.args[0]
        b = node.args[1] if len(node.args) > 1 else None
        ta, tb = tan[id(a)], (tan[id(b)] if b is not None else None)
        if ta is None and tb is None and len(node.args) <= 2:
            tan[id(node)] = None
            continue
        if node.op not in OPS:
            raise CsdfError(f"the derivative of a {node.op!r} call (a mesh) cannot be "
                            "written as an expression; evaluate its gradient instead")
        rule = OPS[node.op].derivative
        if rule.kind == "zero":
            tan[id(node)] = None
        elif rule.kind == "select":
            cmp = tie_comparison(node.op, a.op == "const")
            d = {"<=": b - a, "<": a - b, ">=": a - b, ">": b - a}[cmp]
            w = step(d) if cmp in ("<=", ">=") else 1.0 - step(d)  # 1 where a wins
            zero = (None,) * k
            tan[id(node)] = alg.add(alg.scale(w, ta or zero), alg.scale(1.0 - w, tb or zero))
        else:
            env = {"a": a, "b": b, "v": node}
            for name, f in rule.let:
                env[name] = f.evaluate(env, _FUNCS)
            tan[id(node)] = chain_tangent(
                rule, ta, tb, lambda f, env=env: f.evaluate(env, _FUNCS), alg)
    t = tan[id(e)]
    zero = as_expr(0.0)
    return tuple(zero for _ in range(k)) if t is None else tuple(
        zero if c is None else c for c in t)
