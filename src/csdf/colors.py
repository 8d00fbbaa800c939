"""Colours of shapes at points: the rule, and the small programs that evaluate it.

A shape's colours are its ``color``, ``material`` and ``color_field`` nodes
(:meth:`csdf.Shape.color`, :meth:`csdf.Shape.material`, :meth:`csdf.Shape.color_field`).
A leaf shape takes the colour of the innermost such node around it (outside every one it
is uncoloured and drawn in :data:`DEFAULT_COLOR`, or a caller's default). Through
operators (:mod:`csdf.shapes.colorrule`), an operator's children's colours are weighted
by how much each child's distance moves the operator's output (``|d out / d d_i|``):

* a union: the colour of the operand whose surface it is (the one with the smaller
  value);
* an intersection: likewise the operand with the larger value;
* a difference ``a - b``: ``a``'s colour on ``a``'s faces, ``b``'s on the faces that
  ``b`` cut (as OpenSCAD draws them);
* a smooth blend: the operands' colours mixed by the blend's weights (for the smooth
  union of two, Quilez's ``h``: half and half where their distances are equal); an
  exponential blend by its softmax weights;
* a ``color_field``: its red, green, blue (and alpha) expressions of the coordinates.

The rule is evaluated by programs compiled from the same expression DAG as the distance:
when every colour is a constant and no blend mixes two of them, one program whose value
is the index of the winning row of a palette; otherwise five channel programs ``r, g,
b, a, u``, the colour being ``(r, g, b, a) + u * default``. They travel in the shape's
compiled program (:attr:`csdf.Program.colors`, the colour section of the bytecode), so
a program read back from bytes or text keeps its colours; evaluating the distance never
runs them, so a coloured model's distance costs exactly what it costs uncoloured.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .errors import CsdfError

__all__ = ["DEFAULT_COLOR", "color_program", "colors_at", "colors_of", "has_colors",
           "scene_has_colors", "albedo_glsl"]

#: the colour of surfaces outside every ``color`` node (a light grey, opaque)
DEFAULT_COLOR = (0.8, 0.8, 0.8, 1.0)


def _section(model) -> tuple[Any, np.ndarray] | None:
    """The colour section ``(program, palette with NaN rows)`` of a shape's compiled
    program (compiled once, cached on the shape) or of a program; None without."""
    return getattr(model_program(model), "colors", None)


def has_colors(shape) -> bool:
    """True when ``shape`` (a shape, or a compiled program) has colours: a ``color`` or
    ``material`` node in its tree, so a colour section in its program."""
    return _section(shape) is not None


def color_program(shape) -> tuple[Any, np.ndarray | None]:
    """The colour section of the shape's compiled program (:attr:`csdf.Program.colors`):
    ``(program, palette)``, a :class:`csdf.Program` whose value at a point is the index
    (a whole number, as float) of the winning row of ``palette`` ``(K, 4)`` float64 RGBA
    in ``[0, 1]`` (uncoloured rows filled with :data:`DEFAULT_COLOR`); or, for colours
    that vary continuously (smooth blends of different colours, colour fields),
    ``(programs, None)`` with the five channel programs ``r, g, b, a, u`` (the colour is
    ``(r, g, b, a) + u * DEFAULT_COLOR``).

    Raises:
        CsdfError: not a shape or program, or one without colours.
    """
    section = _section(shape)
    if section is None:
        raise CsdfError("the shape has no colours (no color(), material() or "
                        "color_field() node)")
    cprog, palette = section
    if palette is None:
        return cprog, None
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
    elif section[1] is None:  # channel programs: (r, g, b, a) + u * default
        vals = [_run(p, pts, params, check_ranges) for p in section[0]]
        out = np.stack(vals[:4], axis=1) + vals[4][:, None] * base
        out = np.clip(out, 0.0, 1.0)
    else:
        prog, raw = section
        palette = np.where(np.isnan(raw), base, raw)
        idx = _run(prog, pts, params, check_ranges)
        ok = np.isfinite(idx)
        out = np.full((n, 4), np.nan)
        out[ok] = palette[np.clip(np.rint(idx[ok]).astype(np.int64), 0, len(palette) - 1)]
    out[np.isnan(pts).any(axis=1)] = np.nan
    return out.reshape(*batch, 4)


def _run(prog, pts: np.ndarray, params: dict | None, check_ranges: bool) -> np.ndarray:
    """A colour program's values ``(N,)`` at ``pts``, with the parameters it has."""
    params = {k: v for k, v in (params or {}).items() if k in prog.param_names}
    return prog(pts, params, check_ranges=check_ranges)


def colors_of(model: Any, points: Any, params: dict | None = None, *,
              check_ranges: bool = True, default: Any = None,
              instances: Any = None) -> np.ndarray:
    """:func:`colors_at` for a model a consumer was given: a :class:`csdf.Shape` or
    :class:`csdf.Program` as is, a :class:`csdf.Field` by its shape (else its
    program) with its parameter values (updated by ``params``), ``points`` ``(N, 3)``
    in the field's frame (mapped back by its pose); a :class:`csdf.Scene` with
    ``instances`` ``(N,)``, the instance id each point lies on (-1: none, NaN colour),
    each point in the colours of its instance's model (world points)."""
    if getattr(model, "__csdf_scene__", False):
        return _scene_colors(model, points, instances, check_ranges, default)
    if hasattr(model, "children") or hasattr(model, "colors"):
        return colors_at(model, points, params, check_ranges=check_ranges, default=default)
    src = getattr(model, "shape", None) or getattr(model, "program", None)
    merged = dict(getattr(model, "params", {}) or {})
    merged.update(params or {})
    pose = getattr(model, "pose", None)
    local = points if pose is None or pose.is_identity() else pose.apply_inverse(points)
    return colors_at(src, local, merged, check_ranges=check_ranges, default=default)


def scene_has_colors(scene: Any) -> bool:
    """True when some instance of a :class:`csdf.Scene` places a coloured model."""
    return any(has_colors(inst.model) for inst in scene)


def _scene_colors(scene: Any, points: Any, instances: Any, check_ranges: bool,
                  default: Any) -> np.ndarray:
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if instances is None:
        raise CsdfError("a scene's colours need the instance id of each point")
    ids = np.asarray(instances).reshape(-1)
    if ids.shape != (len(pts),):
        raise CsdfError(f"instances must give one id per point ({len(pts)}), got "
                        f"{ids.shape}")
    out = np.full((len(pts), 4), np.nan)
    for i in np.unique(ids[ids >= 0]):
        sel = ids == i
        out[sel] = colors_of(scene.field(int(i)), pts[sel], check_ranges=check_ranges,
                             default=default)
    return out


def albedo_glsl(shape, name: str = "sdf_albedo", declared: str = "",
                default: Any = None) -> str:
    """GLSL ``vec3 <name>(vec3 p)``: the shape's colour (RGB) at ``p`` by this module's
    rule, for a preview shader that already holds the geometry's snippet
    (:func:`csdf.to_glsl`; ``declared`` is that snippet, whose parameter uniforms are
    not declared again). Uncoloured surfaces, and a shape without colours, get
    ``default`` (RGB; :data:`DEFAULT_COLOR`). The colour program's GLSL is emitted as
    ``<name>_index`` (channel programs as ``<name>_r``, ``_g``, ``_b``, ``_u``).

    Raises:
        CsdfError: a shape the GLSL export refuses (a mesh call).
    """
    from .field import albedo_functions

    base = DEFAULT_COLOR if default is None else tuple(default)
    prog = model_program(shape)
    params, lines = albedo_functions(prog, name, base)
    have = {ln.strip() for ln in declared.splitlines() if ln.startswith("uniform ")}
    decl = [f"uniform float {ident}; // {comment}" for ident, comment in params]
    decl = [d for d in decl if d.strip() not in have]
    return "\n".join(decl + lines) + "\n"


def model_program(model) -> Any:
    """The compiled program of a shape (cached on it), or the program itself."""
    return model.compile() if hasattr(model, "children") else model
