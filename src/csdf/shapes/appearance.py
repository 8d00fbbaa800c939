"""Appearance kept on shapes: :meth:`Shape.color`.

A colour is metadata of the shape tree: the node keeps the child's geometry unchanged
(the same expression, so the same bytecode, exactness, Lipschitz bound and bounds) and
records the colour, which readers of other formats keep (OpenSCAD's ``color()``) and the
``.csdf`` printer writes back. :func:`colors` lists the colours of a tree.

Not yet: colour through CSG at evaluation time (the nearest operand's colour as a second
output of the program), coloured renders and meshes (issue 24).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..errors import ShapeError
from .base import Shape, register, walk_shapes

__all__ = ["color", "colors", "color_arg"]


def color_arg(rgb: Any, what: str = "color") -> tuple[float, ...]:
    """``(r, g, b)`` or ``(r, g, b, a)`` floats in ``[0, 1]``, checked.

    Raises:
        ShapeError: not 3 or 4 numbers, or one outside ``[0, 1]`` or not finite.
    """
    if isinstance(rgb, (str, bytes)) or not isinstance(rgb, (tuple, list, np.ndarray)):
        raise ShapeError(f"{what} must be 3 or 4 numbers in [0, 1] (red, green, blue[, "
                         f"alpha]), got {type(rgb).__name__}")
    vals = []
    for i, v in enumerate(rgb):
        if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
            raise ShapeError(f"{what}[{i}] must be a number, got {type(v).__name__}")
        f = float(v)
        if not math.isfinite(f) or not 0.0 <= f <= 1.0:
            raise ShapeError(f"{what}[{i}] = {f:g} is outside [0, 1]")
        vals.append(f)
    if len(vals) not in (3, 4):
        raise ShapeError(f"{what} must be 3 or 4 numbers (red, green, blue[, alpha]), got "
                         f"{len(vals)}")
    return tuple(vals)


@register("method")
def color(shape: Shape, rgb) -> Shape:
    """The same shape with a colour: ``rgb`` is ``(r, g, b)`` or ``(r, g, b, a)`` in
    ``[0, 1]``. The geometry is the child's, unchanged (same bytecode, contract and
    bounds); the colour is kept on the tree (:func:`colors`)."""
    if not isinstance(shape, Shape):
        raise ShapeError(f"color is a shape method; got {type(shape).__name__}")
    c = color_arg(rgb)
    return Shape("color", lambda p, ctx: shape.sdf(p, ctx), dim=shape.dim,
                 exactness=shape.exactness, lipschitz=shape.lipschitz, bounds=shape.bounds,
                 args=(c,), children=(shape,))


def colors(shape: Shape) -> list[tuple[Shape, tuple[float, ...]]]:
    """Every ``color`` node of a shape tree with its colour, outermost first."""
    return [(s, tuple(s.args[0])) for s in walk_shapes(shape) if s.name == "color"]
