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
the winning entry of a palette. Both travel in the shape's compiled program
(:attr:`csdf.Program.colors`, the colour section of the bytecode), so a program read
back from bytes or text keeps its colours; evaluating the distance never runs the
colour program, so a coloured model's distance costs exactly what it costs
uncoloured.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .errors import CsdfError

__all__ = ["DEFAULT_COLOR", "color_program", "colors_at", "colors_of", "has_colors",
           "albedo_glsl"]

#: the colour of surfaces outside every ``color`` node (a light grey, opaque)
DEFAULT_COLOR = (0.8, 0.8, 0.8, 1.0)


def _section(model) -> tuple[Any, np.ndarray] | None:
    """The colour section ``(program, palette with NaN rows)`` of a shape's compiled
    program (compiled once, cached on the shape) or of a program; None without."""
    prog = model.compile() if hasattr(model, "children") else model
    return getattr(prog, "colors", None)


def has_colors(shape) -> bool:
    """True when ``shape`` (a shape, or a compiled program) has colours: a ``color`` or
    ``material`` node in its tree, so a colour section in its program."""
    return _section(shape) is not None


def color_program(shape) -> tuple[Any, np.ndarray]:
    """``(program, palette)``: the colour section of the shape's compiled program
    (:attr:`csdf.Program.colors`): a :class:`csdf.Program` whose value at a point is
    the index (a whole number, as float) of the winning row of ``palette`` ``(K, 4)``
    float64 RGBA in ``[0, 1]`` (the nearest-coloured-surface rule of this module; NaN
    rows: uncoloured parts, drawn in :data:`DEFAULT_COLOR`).

    Raises:
        CsdfError: not a shape or program, or one without colours.
    """
    section = _section(shape)
    if section is None:
        raise CsdfError("the shape has no colours (no color() or material() node)")
    cprog, palette = section
    return cprog, np.where(np.isnan(palette), np.array(DEFAULT_COLOR), palette)


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
    section = _section(shape)
    if section is None:
        out = np.tile(base, (n, 1))
    else:
        prog, raw = section
        palette = np.where(np.isnan(raw), base, raw)
        params = {k: v for k, v in (params or {}).items() if k in prog.param_names}
        idx = prog(pts, params, check_ranges=check_ranges)
        ok = np.isfinite(idx)
        out = np.full((n, 4), np.nan)
        out[ok] = palette[np.clip(np.rint(idx[ok]).astype(np.int64), 0, len(palette) - 1)]
    out[np.isnan(pts).any(axis=1)] = np.nan
    return out.reshape(*batch, 4)


def colors_of(model: Any, points: Any, params: dict | None = None, *,
              check_ranges: bool = True, default: Any = None) -> np.ndarray:
    """:func:`colors_at` for a model a consumer was given: a :class:`csdf.Shape` or
    :class:`csdf.Program` as is, a :class:`csdf.Field` by its shape (else its
    program) with its parameter values (updated by ``params``), ``points`` ``(N, 3)``
    in the field's frame (mapped back by its pose)."""
    if hasattr(model, "children") or hasattr(model, "colors"):
        return colors_at(model, points, params, check_ranges=check_ranges, default=default)
    src = getattr(model, "shape", None) or getattr(model, "program", None)
    merged = dict(getattr(model, "params", {}) or {})
    merged.update(params or {})
    pose = getattr(model, "pose", None)
    local = points if pose is None or pose.is_identity() else pose.apply_inverse(points)
    return colors_at(src, local, merged, check_ranges=check_ranges, default=default)


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
    section = _section(shape)
    if section is None:
        return f"vec3 {name}(vec3 p) {{\n    return {vec3(base)};\n}}\n"
    prog, raw = section
    palette = np.where(np.isnan(raw), np.array((tuple(base) + (1.0,))[:4]), raw)
    have = {ln.strip() for ln in declared.splitlines() if ln.startswith("uniform ")}
    src = [ln for ln in to_glsl(prog, f"{name}_index", gradient=False).splitlines()
           if not (ln.startswith("uniform ") and ln.strip() in have)]
    body = [f"vec3 {name}(vec3 p) {{", f"    float k = {name}_index(p);"]
    for k in range(len(palette) - 1):
        body.append(f"    if (k < {k}.5) return {vec3(palette[k])};")
    body += [f"    return {vec3(palette[-1])};", "}"]
    return "\n".join(src + body) + "\n"

