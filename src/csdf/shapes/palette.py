"""Named materials and the colour a ``color`` or ``material`` node gives (kept apart from
:mod:`csdf.shapes.appearance`, which makes those nodes, so that building a shape's
expression can read them without importing it)."""

from __future__ import annotations

from typing import Any

from ..expr import Expr, as_expr, clamp

__all__ = ["MATERIALS", "COLOR_NODES", "node_color", "node_roughness", "field_channels"]

#: the shape nodes that give their subtree a colour (its geometry is the child's)
COLOR_NODES = frozenset({"color", "material", "color_field"})

#: named materials: ``name -> (rgb, roughness)`` (roughness in [0, 1], 1 matte)
MATERIALS: dict[str, tuple[tuple[float, float, float], float]] = {
    "wood": ((0.62, 0.42, 0.24), 0.8),
    "dark_wood": ((0.45, 0.29, 0.16), 0.75),
    "steel": ((0.62, 0.64, 0.67), 0.35),
    "brass": ((0.72, 0.55, 0.24), 0.3),
    "rubber": ((0.12, 0.12, 0.13), 0.9),
    "paint": ((0.92, 0.90, 0.85), 0.5),
    "concrete": ((0.55, 0.55, 0.52), 0.95),
}


def node_color(node: Any) -> tuple[float, ...] | None:
    """The colour a ``color`` or ``material`` node gives (None for other nodes, and
    for a ``color_field``, whose colour varies: its channels are ``node.args[0]``)."""
    if node.name == "color":
        return tuple(node.args[0])
    if node.name == "material":
        given = node.kwargs.get("color")
        return tuple(given) if given is not None else MATERIALS[node.args[0]][0]
    return None


def node_roughness(node: Any) -> float | None:
    """The roughness a ``material`` node gives (None for other nodes)."""
    if node.name != "material":
        return None
    r = node.kwargs.get("roughness")
    if r is not None:
        return float(r)
    known = MATERIALS.get(node.args[0])
    return known[1] if known else 0.5


def field_channels(node: Any) -> tuple[Expr, Expr, Expr, Expr]:
    """The ``(r, g, b, a)`` expressions in x, y, z of a ``color_field`` node, each
    clamped to ``[0, 1]`` (alpha 1 when not given)."""
    chans = tuple(node.args[0]) + ((as_expr(1.0),) if len(node.args[0]) == 3 else ())
    return tuple(clamp(c, 0.0, 1.0) for c in chans)  # type: ignore[return-value]
