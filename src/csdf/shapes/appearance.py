"""Appearance kept on shapes: :meth:`Shape.color` and :meth:`Shape.material`.

A colour is metadata of the shape tree: the node keeps the child's geometry unchanged
(the same expression, so the same tape, exactness, Lipschitz bound and bounds) and
records the colour (a material: a name, its colour and a roughness), which readers of
other formats keep (OpenSCAD's ``color()``) and the ``.csdf`` printer writes back.
:func:`colors` lists the colours of a tree; :mod:`csdf.colors` evaluates them at points
(the nearest coloured surface), for meshes, renders, scans and the editor's preview.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..errors import ShapeError
from ..expr import Expr, X, Y, Z, walk
from .base import Shape, register, walk_shapes
from .palette import MATERIALS, node_color, node_roughness

__all__ = ["color", "material", "color_field", "colors", "color_arg", "MATERIALS",
           "node_color", "node_roughness"]



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
    ``[0, 1]``. The geometry is the child's, unchanged (same tape, contract and
    bounds); the colour is kept on the tree (:func:`colors`)."""
    if not isinstance(shape, Shape):
        raise ShapeError(f"color is a shape method; got {type(shape).__name__}")
    c = color_arg(rgb)
    return Shape("color", lambda p, ctx: shape.sdf(p, ctx), dim=shape.dim,
                 exactness=shape.exactness, lipschitz=shape.lipschitz, bounds=shape.bounds,
                 args=(c,), children=(shape,))


@register("method")
def material(shape: Shape, name, color=None, roughness=None) -> Shape:
    """The same shape with a named material: its colour (``color``, else the named
    material's from :data:`MATERIALS`) and its ``roughness`` in ``[0, 1]`` (1 matte;
    else the named material's, else 0.5). A ``color`` node (:func:`color`) with the
    name and roughness kept: the geometry is the child's, unchanged.

    Raises:
        ShapeError: a name that is not an identifier, an unknown name without a
            ``color``, a bad colour or roughness.
    """
    if not isinstance(shape, Shape):
        raise ShapeError(f"material is a shape method; got {type(shape).__name__}")
    if not isinstance(name, str) or not name.isidentifier():
        raise ShapeError(f"material: name must be an identifier, got {name!r}")
    known = MATERIALS.get(name)
    if color is None and known is None:
        raise ShapeError(f"material {name!r} is not one of {', '.join(sorted(MATERIALS))}; "
                         "give its color=(r, g, b)")
    c = color_arg(known[0] if color is None else color, "material: color")
    r = roughness if roughness is not None else (known[1] if known else 0.5)
    if isinstance(r, bool) or not isinstance(r, (int, float, np.integer, np.floating)) \
            or not 0.0 <= float(r) <= 1.0:
        raise ShapeError(f"material: roughness must be a number in [0, 1], got {r!r}")
    kwargs: dict = {}
    if color is not None:
        kwargs["color"] = c
    if roughness is not None:
        kwargs["roughness"] = float(r)
    return Shape("material", lambda p, ctx: shape.sdf(p, ctx), dim=shape.dim,
                 exactness=shape.exactness, lipschitz=shape.lipschitz, bounds=shape.bounds,
                 args=(name,), kwargs=kwargs or None, children=(shape,))


@register("method")
def color_field(shape: Shape, rgb) -> Shape:
    """The same shape with a procedural colour: ``rgb`` is 3 or 4 expressions in the
    shape's coordinates ``x``, ``y``, ``z`` (red, green, blue[, alpha]; numbers work
    too, parameters may appear), or a function ``f(x, y, z)`` returning them; each is
    clamped to ``[0, 1]`` where it is evaluated. Surfaces inside the node without a
    colour of their own take it; the coordinates are those the node is given (they
    move with the shape). The geometry is the child's, unchanged.

    Raises:
        ShapeError: not 3 or 4 expressions, or one that is a shape or a non-finite
            number.
    """
    from .userfield import _coords_expr

    if not isinstance(shape, Shape):
        raise ShapeError(f"color_field is a shape method; got {type(shape).__name__}")
    if callable(rgb) and not isinstance(rgb, Expr):
        try:
            rgb = rgb(X, Y, Z)
        except TypeError as exc:
            raise ShapeError(f"color_field: a function of the colour must take (x, y, z): "
                             f"{exc}") from None
    if isinstance(rgb, (str, bytes, Expr)) or not isinstance(rgb, (tuple, list)) or \
            len(rgb) not in (3, 4):
        raise ShapeError("color_field: rgb must be 3 or 4 expressions in x, y, z (red, "
                         f"green, blue[, alpha]), got {type(rgb).__name__}"
                         + (f" of {len(rgb)}" if isinstance(rgb, (tuple, list)) else ""))
    names = ("red", "green", "blue", "alpha")
    channels = tuple(_coords_expr(v, f"color_field {names[i]}") for i, v in enumerate(rgb))
    if shape.dim == 2 and any(n.op == "z" for e in channels for n in walk(e)):
        raise ShapeError("color_field: a 2D shape's colour may not use z")
    return Shape("color_field", lambda p, ctx: shape.sdf(p, ctx), dim=shape.dim,
                 exactness=shape.exactness, lipschitz=shape.lipschitz, bounds=shape.bounds,
                 args=(channels,), children=(shape,))


def colors(shape: Shape) -> list[tuple[Shape, tuple[float, ...]]]:
    """Every ``color`` and ``material`` node of a shape tree with its colour, outermost
    first."""
    return [(s, c) for s in walk_shapes(shape) if (c := node_color(s)) is not None]
