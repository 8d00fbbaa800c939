"""A shape whose field is a given expression in x, y (and z): the generic "field from an
expression", for models that arrive as formulas rather than as primitives and operators
(Fidget's ``.vm`` files, :mod:`csdf.lang.vm`; later user-written fields).

Nothing is known about such a field unless the caller says so: by default its distance
contract is ``'neither'``, its Lipschitz bound ``inf`` (no bound known: consumers that
need one fall back to their own step rules) and its bounds ``None`` (unknown).

Internal API (used by :mod:`csdf.lang.vm`; meant to carry a future public
``csdf.field(expr)``):

* :func:`expr_dim` -- 2 when an expression uses only x and y, else 3;
* :func:`substitute` -- the expression with x, y, z replaced by other expressions,
  keeping the DAG's sharing (iterative: no recursion limit on deep DAGs);
* :func:`expr_shape` -- the :class:`~csdf.shapes.base.Shape` of an expression.

The shape evaluates the expression at its coordinates: at the plain ``(x, y, z)`` it is
the expression itself (no copy), under a transform (``shape.translate(...)``) the
expression with the coordinates substituted, so every operator and method of shapes
works on it, and it compiles, evaluates on every backend and gets intervals and
gradients like any other shape.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ..errors import ShapeError
from ..expr import Expr, X, Y, Z, walk
from ..expr import substitute as substitute_leaves
from ..vec import Vec
from .base import EXACTNESS, BuildContext, Shape

__all__ = ["expr_dim", "substitute", "expr_shape"]

_COORDS = (X, Y, Z)


def expr_dim(e: Expr) -> int:
    """3 when ``e`` depends on z, else 2 (an expression in x and y alone, or in
    neither, is a 2D field)."""
    return 3 if any(n is Z for n in walk(e)) else 2


def substitute(e: Expr, coords: Sequence[Expr]) -> Expr:
    """``e`` with ``x, y, z`` replaced by ``coords[0], coords[1], coords[2]`` (fewer
    coordinates leave the remaining ones as they are), by :func:`csdf.expr.substitute`:
    shared subexpressions stay shared and rebuilt nodes go through
    :func:`csdf.expr.make` (folding, interning, the active node budget)."""
    subs = {id(c): v for c, v in zip(_COORDS, coords)}
    if all(subs[id(c)] is c for c in _COORDS[: len(coords)]):
        return e
    return substitute_leaves([e], lambda n: subs.get(id(n)))[0]


def expr_shape(
    e: Expr,
    *,
    dim: int | None = None,
    name: str = "expr_field",
    args: tuple = (),
    kwargs: dict | None = None,
    exactness: str = "neither",
    lipschitz: float = math.inf,
    bounds: np.ndarray | None = None,
) -> Shape:
    """The shape whose field is ``e``, an expression in x, y (and z).

    Args:
        e: the field; parameters (:func:`csdf.param`) may appear in it.
        dim: 2 or 3; None takes :func:`expr_dim`. A 2D field may not use z.
        name, args, kwargs: how the shape names itself (``repr``, error messages); it
            is not in the modelling registry, so :func:`csdf.dumps` cannot print it as
            a ``.csdf`` call.
        exactness: the distance contract the caller can vouch for (``'neither'``
            unless known).
        lipschitz: a known bound of ``|grad e|``, else ``inf`` (unknown).
        bounds: ``(2, dim)`` ``[lo, hi]`` box containing the zero set, or None
            (unknown or unbounded).

    Raises:
        ShapeError: ``e`` is not an expression, ``dim`` is not 2 or 3 or too small for
            ``e``, a bad exactness label, a negative or NaN Lipschitz bound, or bounds
            of the wrong shape.
    """
    if not isinstance(e, Expr):
        raise ShapeError(f"{name}: the field must be an expression, got {type(e).__name__}")
    need = expr_dim(e)
    if dim is None:
        dim = need
    if dim not in (2, 3):
        raise ShapeError(f"{name}: dim must be 2 or 3, got {dim!r}")
    if dim < need:
        raise ShapeError(f"{name}: a 2D field may not use z")
    if exactness not in EXACTNESS:
        raise ShapeError(f"{name}: exactness must be one of {EXACTNESS}, got {exactness!r}")
    lip = float(lipschitz)
    if not lip >= 0:
        raise ShapeError(f"{name}: lipschitz must be a non-negative number, got {lip}")
    box = None
    if bounds is not None:
        box = np.array(bounds, dtype=np.float64)
        if box.shape != (2, dim):
            raise ShapeError(f"{name}: bounds must have shape (2, {dim}), got {box.shape}")

    def fn(p: Vec, ctx: BuildContext) -> Expr:
        return substitute(e, p.c)

    return Shape(name, fn, dim=dim, exactness=exactness, lipschitz=lip, bounds=box,
                 args=args, kwargs=kwargs)
