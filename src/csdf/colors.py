"""Colours of shapes at points: the rule, and the small program that evaluates it.

A shape's colours are its ``color`` nodes (:meth:`csdf.Shape.color`). At a point the
colour is that of the **nearest coloured surface**: among the ``color`` nodes, and the
leaf shapes outside any ``color`` node (which take :data:`DEFAULT_COLOR`), the one whose
field has the smallest absolute value there (innermost first on ties). On the surface of
a model this gives, through CSG:

* a union: the colour of the operand whose surface it is (the one with the smaller
  value, which is 0 there);
* an intersection: likewise the operand with the larger value (0 there, the other's
  negative value is farther from 0 unless both surfaces meet);
* a difference ``a - b``: ``a``'s colour on ``a``'s faces, ``b``'s on the faces that
  ``b`` cut (as OpenSCAD draws them);
* a smooth blend: the colour of the nearer operand, switching in the blend's middle.

The rule is evaluated by a second program compiled from the same expression DAG (the
distances of the coloured nodes, shared with the geometry): its value is the index of
the winning entry of a palette. The geometry's own program is untouched, so evaluating
a coloured model's distance costs exactly what it costs uncoloured.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .compiler.tape import compile_expr
from .errors import CsdfError
from .expr import Expr, const, minimum, step

__all__ = ["DEFAULT_COLOR", "color_program", "colors_at", "has_colors", "albedo_glsl"]

#: the colour of surfaces outside every ``color`` node (a light grey, opaque)
DEFAULT_COLOR = (0.8, 0.8, 0.8, 1.0)


def _entries(shape) -> list[tuple[tuple[float, ...] | None, Expr]]:
    _, ctx = shape.build()
    return list(ctx.colored)


def has_colors(shape) -> bool:
    """True when ``shape`` is a shape whose tree holds a ``color`` node (False for
    anything else, such as a compiled program)."""
    from .shapes.base import walk_shapes

    if not hasattr(shape, "children"):
        return False
    return any(s.name in ("color", "material") for s in walk_shapes(shape))


def color_program(shape) -> tuple[Any, np.ndarray]:
    """``(program, palette)``: a :class:`csdf.Program` whose value at a point is the
    index (a whole number, as float) of the winning entry of ``palette`` ``(K, 4)``
    float64 RGBA in ``[0, 1]`` (the nearest-coloured-surface rule of this module).
    Cached on the shape.

    Raises:
        CsdfError: the shape is not a :class:`csdf.Shape`.
    """
    if not hasattr(shape, "build") or not hasattr(shape, "children"):
        raise CsdfError(f"colours need a Shape, got {type(shape).__name__}")

    def make():
        entries = _entries(shape)
        palette = np.array([DEFAULT_COLOR if c is None else
                            (tuple(c) + (1.0,))[:4] for c, _ in entries], dtype=np.float64)
        best = abs(entries[0][1])
        index: Expr = const(0.0)
        for k, (_, d) in enumerate(entries[1:], start=1):
            a = abs(d)
            nearer = 1.0 - step(a - best)  # 1 where this entry is strictly nearer
            index = index + nearer * (float(k) - index)
            best = minimum(best, a)
        prog = compile_expr(index, dim=shape.dim, exactness="neither")
        _ENTRY_KINDS[id(shape)] = (shape, entries)
        return prog, palette

    hit = _CACHE.get(id(shape))
    if hit is not None and hit[0] is shape:
        return hit[1]
    if len(_CACHE) >= 16:
        old = next(iter(_CACHE))
        _CACHE.pop(old)
        _ENTRY_KINDS.pop(old, None)
    got = make()
    _CACHE[id(shape)] = (shape, got)
    return got


#: the colour programs of recent shapes (shapes have no attribute dictionary)
_CACHE: dict[int, tuple[Any, tuple[Any, np.ndarray]]] = {}
_ENTRY_KINDS: dict[int, tuple[Any, list]] = {}


def _entries_cached(shape) -> list:
    hit = _ENTRY_KINDS.get(id(shape))
    if hit is None or hit[0] is not shape:
        return _entries(shape)
    return hit[1]


def colors_at(shape, points: Any, params: dict | None = None, *,
              check_ranges: bool = True, default: Any = None) -> np.ndarray:
    """``(N, 4)`` float64 RGBA in ``[0, 1]``: the shape's colour at each point
    ``(N, dim)`` (model units; the nearest-coloured-surface rule of this module);
    NaN rows at points with a NaN coordinate. A shape without ``color`` nodes is
    :data:`DEFAULT_COLOR` everywhere; ``default`` (RGBA) replaces that colour.

    Raises:
        CsdfError: not a shape, or bad points or parameters (as for evaluation).
    """
    from .points import as_points

    pts, batch, _ = as_points(points, getattr(shape, "dim", 3))
    n = pts.shape[0]
    base = np.array(DEFAULT_COLOR if default is None else default, dtype=np.float64)
    if not has_colors(shape):
        out = np.tile(base, (n, 1))
    else:
        prog, palette = color_program(shape)
        if default is not None:
            palette = palette.copy()
            palette[[c is None for c, _ in _entries_cached(shape)]] = base
        params = {k: v for k, v in (params or {}).items() if k in prog.param_names}
        idx = prog(pts, params, check_ranges=check_ranges)
        ok = np.isfinite(idx)
        out = np.full((n, 4), np.nan)
        out[ok] = palette[np.clip(np.rint(idx[ok]).astype(np.int64), 0, len(palette) - 1)]
    out[np.isnan(pts).any(axis=1)] = np.nan
    return out.reshape(*batch, 4)


def albedo_glsl(shape, name: str = "sdf_albedo", declared: str = "",
                default: Any = None) -> str:
    """GLSL ``vec3 <name>(vec3 p)``: the shape's colour (RGB) at ``p`` by this module's
    rule, for a preview shader that already holds the geometry's snippet
    (:func:`csdf.to_glsl`; ``declared`` is that snippet, whose parameter uniforms are
    not declared again). Uncoloured surfaces, and a shape without colours, get
    ``default`` (RGB; :data:`DEFAULT_COLOR`). The colour program's GLSL is emitted as
    ``<name>_index``.

    Raises:
        CsdfError: a shape the GLSL export refuses (a mesh call).
    """
    from .field import glsl_float, to_glsl

    def vec3(c) -> str:
        return "vec3(" + ", ".join(glsl_float(float(v)) for v in c[:3]) + ")"

    base = DEFAULT_COLOR if default is None else tuple(default)
    if not has_colors(shape):
        return f"vec3 {name}(vec3 p) {{\n    return {vec3(base)};\n}}\n"
    prog, palette = color_program(shape)
    palette = palette.copy()
    palette[[c is None for c, _ in _entries_cached(shape)]] = (tuple(base) + (1.0,))[:4]
    have = {ln.strip() for ln in declared.splitlines() if ln.startswith("uniform ")}
    src = [ln for ln in to_glsl(prog, f"{name}_index", gradient=False).splitlines()
           if not (ln.startswith("uniform ") and ln.strip() in have)]
    body = [f"vec3 {name}(vec3 p) {{", f"    float k = {name}_index(p);"]
    for k in range(len(palette) - 1):
        body.append(f"    if (k < {k}.5) return {vec3(palette[k])};")
    body += [f"    return {vec3(palette[-1])};", "}"]
    return "\n".join(src + body) + "\n"
