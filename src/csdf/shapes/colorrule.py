"""The colour rule: a shape's colour at a point, as expressions built from the
evaluations of its nodes (:class:`csdf.shapes.base.Frame`, recorded while the shape's
distance is built, so the colour shares the distance's subexpressions).

Walking the evaluations from the root:

* a leaf shape takes the colour of the innermost ``color``, ``material`` or
  ``color_field`` node around it; outside every such node it is *uncoloured* (drawn in
  :data:`csdf.colors.DEFAULT_COLOR`, or the caller's default);
* a ``color`` or ``material`` node gives its colour to the leaves inside it that have
  none of their own; a ``color_field`` node its channels, evaluated at the coordinates
  the node is given (so the pattern moves with the shape);
* an operator that evaluated one child has that child's colour;
* an operator that evaluated several mixes their colours with the weights
  ``|d out / d d_i|`` (normalised), the partial derivatives of its output with respect
  to each child's distance (:func:`csdf.exprgrad.partials`). For hard union,
  intersection and difference these are the steps that select the winning operand: the
  colour of the operand whose surface it is. For smooth blends they are the blend's own
  weights: the quadratic smooth union of two operands mixes the colours by Quilez's
  ``h``, half and half where the operands' distances are equal, and an exponential
  blend by its softmax weights.

The result is either a palette index (when every colour is a constant and no blend mixes
two different ones: the compact form) or five channel expressions ``r, g, b, a, u``:
the colour is ``(r, g, b, a) + u * default`` (``u`` the weight of uncoloured surfaces).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..expr import Expr, X, Y, Z, as_expr, maximum, minimum, step, substitute
from .palette import COLOR_NODES, field_channels, node_color

__all__ = ["ColorRule", "color_rule"]

#: the operators whose several children meet in a hard min/max (no blend radius):
#: their colour is the winner's, so a palette index can carry it
_SELECTORS = frozenset({"union", "intersection", "difference"})
_CHANNELS = 5  # r, g, b, a, u


@dataclass(frozen=True)
class ColorRule:
    """The colour rule of a shape as expressions in x, y, z (and parameters).

    Attributes:
        index: the palette row at a point (a whole number as float), or None when the
            colour is given by ``channels``.
        palette: ``(K, 4)`` float64 RGBA in [0, 1], NaN rows for uncoloured surfaces
            (with ``index``), else None.
        channels: ``(r, g, b, a, u)`` expressions (without ``index``), else None.
    """

    index: Expr | None
    palette: np.ndarray | None
    channels: tuple[Expr, ...] | None


@dataclass
class _Col:
    key: int | None  # the palette row when the colour is that constant
    index: Expr | None  # the palette row as an expression, when piecewise constant
    ch: tuple[Expr, ...]  # r, g, b, a, u


class _Builder:
    def __init__(self) -> None:
        self.rows: dict[tuple | None, int] = {}
        self.memo: dict[tuple[int, int], _Col] = {}
        self.consts: dict[tuple | None, _Col] = {}

    def constant(self, rgba: tuple[float, ...] | None) -> _Col:
        key = None if rgba is None else (tuple(float(v) for v in rgba) + (1.0,))[:4]
        col = self.consts.get(key)
        if col is None:
            row = self.rows.setdefault(key, len(self.rows))
            vals = (0.0, 0.0, 0.0, 0.0, 1.0) if key is None else key + (0.0,)
            col = _Col(row, as_expr(float(row)), tuple(as_expr(v) for v in vals))
            self.consts[key] = col
        return col

    def color(self, frame: Any, inherited: _Col | None) -> _Col:
        """The colour of an evaluation; ``inherited``: its innermost enclosing colour
        node's (None: uncoloured)."""
        memo_key = (id(frame), id(inherited))
        hit = self.memo.get(memo_key)
        if hit is not None:
            return hit
        shape = frame.shape
        if shape.name in COLOR_NODES:
            inherited = self._node_color(frame)
        kids = frame.children
        if not kids:
            out = self.constant(None) if inherited is None else inherited
        elif len(kids) == 1:
            out = self.color(kids[0], inherited)
        else:
            out = self._combine(frame, [self.color(k, inherited) for k in kids])
        self.memo[memo_key] = out
        return out

    def _node_color(self, frame: Any) -> _Col:
        shape = frame.shape
        rgba = node_color(shape)
        if rgba is not None:
            return self.constant(rgba)
        coords = {id(c): v for c, v in zip((X, Y, Z), frame.p)}
        chans = substitute(list(field_channels(shape)), lambda n: coords.get(id(n)))
        return _Col(None, None, tuple(chans) + (as_expr(0.0),))

    def _combine(self, frame: Any, cols: list[_Col]) -> _Col:
        if cols[0].key is not None and all(c.key == cols[0].key for c in cols):
            return cols[0]
        outs = [k.out for k in frame.children]
        chains = _chains(frame.children)
        if not all(chains):
            return _nearest(outs, cols)  # a bare coordinate or constant: no partials
        from ..exprgrad import partials

        flat = [n for chain in chains for n in chain]
        ws = iter(partials(frame.out, flat))
        weights = []
        for chain in chains:
            w: Expr | float = 0.0
            for _ in chain:
                w = w + abs(next(ws))
            weights.append(as_expr(w))
        hard = frame.shape.name in _SELECTORS and frame.shape.kwargs.get("k") is None
        if hard:  # the weights are 0 or 1, one of them 1
            index = None
            if all(c.index is not None for c in cols):
                index = _dot(weights, [c.index for c in cols])
            ch = tuple(_dot(weights, [c.ch[j] for c in cols]) for j in range(_CHANNELS))
            return _Col(None, index, ch)
        # (the weights of a blend sum to about 1; the floor keeps 0/0 out, in float32 too)
        total = maximum(_dot(weights, [as_expr(1.0)] * len(cols)), 1e-9)
        ch = tuple(_ratio(_dot(weights, [c.ch[j] for c in cols]), total)
                   for j in range(_CHANNELS))
        return _Col(None, None, ch)


def _chains(kids: list[Any], depth: int = 8) -> list[list[Expr]]:
    """Per child evaluation, the outputs that stand for its distance in its parent's
    output: its own, and those of the single children below it (a complement's ``-b``
    may fold away with the parent's negation, leaving ``b``), each node with one child
    only, bare coordinates and constants left out."""
    seen: set[int] = set()
    chains = []
    for k in kids:
        chain = []
        f = k
        for _ in range(depth):
            if f.out.args and id(f.out) not in seen:
                seen.add(id(f.out))
                chain.append(f.out)
            if len(f.children) != 1:
                break
            f = f.children[0]
        chains.append(chain)
    return chains


def _ratio(num: Expr, den: Expr) -> Expr:
    return num if num.op == "const" and float(num.value) == 0.0 else num / den  # type: ignore[arg-type]


def _dot(weights: list[Expr], values: list[Expr]) -> Expr:
    acc: Expr | float = 0.0
    for w, v in zip(weights, values):
        if w.op == "const" and float(w.value) == 0.0:  # type: ignore[arg-type]
            continue
        acc = acc + w * v
    return as_expr(acc)


def _nearest(outs: list[Expr], cols: list[_Col]) -> _Col:
    """The colour of the child with the smallest ``|d|`` (the first on ties)."""
    best = abs(outs[0])
    index = cols[0].index
    ch = list(cols[0].ch)
    for d, c in zip(outs[1:], cols[1:]):
        a = abs(d)
        nearer = 1.0 - step(a - best)  # 1 where this child is strictly nearer
        if index is not None and c.index is not None:
            index = index + nearer * (c.index - index)
        else:
            index = None
        ch = [v + nearer * (cv - v) for v, cv in zip(ch, c.ch)]
        best = minimum(best, a)
    return _Col(None, index, tuple(ch))


def color_rule(root: Any) -> ColorRule:
    """The colour rule of the shape whose evaluation is ``root`` (see the module
    documentation)."""
    b = _Builder()
    col = b.color(root, None)
    if col.index is not None:
        palette = np.full((len(b.rows), 4), np.nan)
        for key, row in b.rows.items():
            if key is not None:
                palette[row] = key
        return ColorRule(col.index, palette, None)
    return ColorRule(None, None, col.ch)
