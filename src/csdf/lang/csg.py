"""Reading OpenSCAD's ``.csg`` files (the evaluated node tree that ``openscad -o
model.csg model.scad`` writes) as csdf shapes, and ``.scad`` files through the
``openscad`` program.

The format: ``name(arg = value, ...)`` followed by ``;`` or a ``{ ... }`` block of
children; values are numbers (``inf``, ``-inf`` and ``nan`` included), ``true``,
``false``, ``undef``, strings and nested ``[ ... ]`` vectors; the top level is an
implicit group. A statement may carry a modifier: ``%`` (background) and ``*``
(disabled) are not part of the model, ``#`` (highlight) is, and ``!`` makes its
statement the whole model.

How the nodes become csdf shapes (``facets='ideal'``: true curves), with the distance
contract each keeps:

=======================================  ================================================
``group``, ``union``, ``render``,        the union of the children (exact where the
``color``                                children do not overlap; else a bound); a
                                         colour kept as :meth:`csdf.Shape.color`
``difference``, ``intersection``         csdf's ``-`` and ``&`` (a bound, as in csdf)
``multmatrix``                           :meth:`csdf.Shape.transform` of the matrix:
                                         **exact** for a rotation or reflection times a
                                         uniform scale, a **bound** otherwise (shear,
                                         non-uniform scale); on a 2D child its x-y part
``cube``, ``sphere``, ``cylinder``       ``box``, ``sphere``, ``cylinder`` /
                                         ``capped_cone`` / ``cone``: **exact**
``square``, ``circle``, ``polygon``      ``rectangle``, ``circle``, ``polygon`` (paths
                                         combined even-odd: holes): **exact**
``linear_extrude``                       ``extrude`` (**exact**); with ``twist`` or a
                                         ``scale``, ``twist`` / ``taper``
                                         (``facets='openscad'``: OpenSCAD's ruled
                                         surface, see below)
                                         (**neither**, with a Lipschitz bound)
``rotate_extrude`` (full turn)           ``revolve``: **exact**
``rotate_extrude`` (partial turn)        ``revolve(..., angle=)``: the sweep cut by the
                                         exact distance to its wedge, a **bound**
``resize``                               ``transform`` by the scale that takes the
                                         children's box (their hull's) to ``newsize``
                                         (``auto`` as OpenSCAD): a **bound** (exact
                                         when the scale is uniform)
``projection(cut = true)``               ``cross_section`` at z = 0: a **bound**
``offset(r = R)``                        the 2D child offset by ``R``: **exact** for
                                         ``R > 0`` on an exact child
``offset(delta = D)``                    the same (rounded where OpenSCAD mitres): a
                                         **bound**
``minkowski`` with a sphere or circle    the other child rounded by its radius (moved
                                         by its centre): **exact** on an exact child
``hull`` of two spheres                 their round cone: **exact** (two equal circles:
                                         a ``segment`` of that thickness, **exact**)
``hull`` of anything else                ``convex_polyhedron`` of points whose hull is
                                         the children's (2D: ``polygon`` of the hull,
                                         **exact** for that polygon): a **bound**, see
                                         below
``polyhedron`` when convex               ``convex_polyhedron`` of its points: a **bound**
                                         (exact inside and on the faces)
``polyhedron`` otherwise                 ``polyhedron`` (csdf.from_mesh): the exact
                                         distance to its closed surface, **exact**
=======================================  ================================================

A partial ``rotate_extrude`` in ``facets='openscad'`` mode is faceted as OpenSCAD does
(``int(k |angle| / 360)`` segments from +x, ``k`` the full turn's) where the faceted
full turn with that segment width has a whole number of segments, and read with the
true curve otherwise.

``facets='openscad'`` reproduces OpenSCAD 2021.01's faceting: ``sphere`` and
``cylinder`` become ``convex_polyhedron`` of exactly OpenSCAD's vertices (segments from
``$fn``, ``$fa``, ``$fs`` by :func:`fragments`; a sphere's rings by
:func:`sphere_points`), ``circle`` a ``polygon`` of OpenSCAD's vertices
(:func:`circle_points`), and a full ``rotate_extrude`` ``revolve(..., segments=n)``
turned so that its first section lies on -x as OpenSCAD's does (a **bound** with the
exact faceted zero set). A twisted or unevenly scaled ``linear_extrude`` whose child is
made of squares, circles and polygons (moved, united, cut, intersected) becomes
OpenSCAD's own surface: the outline (computed with shapely, the ``openscad`` extra) at
each of OpenSCAD's slices (:func:`helix_slices`, :func:`diagonal_slices`), neighbouring
slices joined by flat triangles split along each quad's shorter diagonal, as a
``polyhedron`` (**exact** for that surface); other children, or no shapely, keep the
smooth twist. Everything else reads as in ``'ideal'`` mode: ``offset(r)`` and
``minkowski`` with a sphere stay round.

``hull`` (both modes): the children are turned into points whose convex hull is theirs
(the exact vertices of cubes, squares, polygons, polyhedra and their transforms,
extrusions, unions, Minkowski sums and offsets by ``r``; curves faceted as OpenSCAD
does in ``'openscad'`` mode and with :data:`HULL_TOLERANCE` in ``'ideal'`` mode, the
hull then lying inside the true one by at most 0.2 % of each curve's radius). Children
with no such points (``difference``, ``intersection``, ``offset(delta)``, ...) are read
through their field: their parts' vertices that lie in the solid, and surface points
found on a grid of :data:`HULL_GRID` cells along their longest side, so the hull can
fall short by about one such cell where the cut makes a sharp edge.

Not yet read (a :class:`~csdf.errors.ModelError` naming the node, the file, line and
column): ``minkowski`` without a sphere or circle (outside a ``hull``),
``projection(cut = false)`` (the shadow:
its distance, the smallest value along each vertical line, has no closed form), and,
as in OpenSCAD's own CSG export, ``import``,
``surface``, ``text``, ``roof`` and ``fill`` (external data).

Limits: :data:`MAX_CSG_BYTES` of text, :data:`MAX_CSG_NODES` nodes.
"""

from __future__ import annotations

import math
import os
import shutil
import subprocess
import tempfile
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
from lark import Lark, Token, Transformer, UnexpectedInput, v_args
from lark.exceptions import VisitError

from ..errors import CsdfError, ModelError, ShapeError
from .source import check_source, read_source

__all__ = ["load_csg", "loads_csg", "load_scad", "MAX_CSG_BYTES", "MAX_CSG_NODES",
           "SCAD_TIMEOUT", "FACETS", "fragments", "circle_points", "sphere_points",
           "cylinder_points", "HULL_TOLERANCE", "HULL_GRID"]

#: largest ``.csg`` text read (bytes)
MAX_CSG_BYTES = 16 * 1024 * 1024
#: most nodes in one file
MAX_CSG_NODES = 20_000
#: seconds the ``openscad`` program may take to flatten a ``.scad`` file
SCAD_TIMEOUT = 120.0
#: the faceting modes
FACETS = ("ideal", "openscad")

_GRAMMAR = r"""
start: item*
?item: statement
     | ";"                                      -> empty
statement: [MODIFIER] NAME "(" [args] ")" body
body: ";"                                       -> leaf
     | "{" item* "}"                            -> block
     | statement                                -> single
args: arg ("," arg)*
arg: NAME "=" value                             -> named
   | value                                      -> positional
?value: NUMBER                                  -> number
      | NAME                                    -> word
      | STRING                                  -> string
      | "[" [value ("," value)*] "]"            -> vector
MODIFIER: /[%#!*]/
NAME: /\$?[A-Za-z_][A-Za-z0-9_]*/
NUMBER.2: /[-+]?((\d+\.?\d*|\.\d+)([eE][-+]?\d+)?|inf\b|nan\b)/
STRING: /"(\\.|[^"\\])*"/
COMMENT: /\/\/[^\n]*/ | /\/\*(.|\n)*?\*\//
%import common.WS
%ignore WS
%ignore COMMENT
"""


@lru_cache(maxsize=1)
def _parser() -> Lark:
    return Lark(_GRAMMAR, parser="lalr", propagate_positions=True, maybe_placeholders=True)


@dataclass
class _Node:
    name: str
    args: dict[str, Any]
    pos: list[Any]
    children: list[_Node] = field(default_factory=list)
    modifier: str | None = None
    line: int = 0
    column: int = 0


_UNDEF = object()


class _Build(Transformer):
    """Parse tree -> :class:`_Node` list."""

    def __init__(self, where):
        super().__init__()
        self.where = where
        self.count = 0

    def start(self, items):
        return [i for i in items if i is not None]

    def empty(self, _items):
        return None

    @v_args(meta=True)
    def statement(self, meta, items):
        mod, name, args, block = items
        self.count += 1
        if self.count > MAX_CSG_NODES:
            raise self.where(f"more than {MAX_CSG_NODES} nodes", meta.line, meta.column)
        named, pos = {}, []
        for kind, k, v in args or []:
            if kind == "named":
                named[k] = v
            else:
                pos.append(v)
        return _Node(str(name), named, pos, block or [], str(mod) if mod else None,
                     meta.line, meta.column)

    def block(self, items):
        return [i for i in items if i is not None]

    def leaf(self, _items):
        return []

    def single(self, items):
        return [i for i in items if i is not None]

    def args(self, items):
        return items

    def named(self, items):
        return ("named", str(items[0]), items[1])

    def positional(self, items):
        return ("positional", None, items[0])

    def number(self, items):
        return float(items[0])

    def word(self, items):
        w = str(items[0])
        return {"true": True, "false": False, "undef": _UNDEF}.get(w, ("word", w))

    def string(self, items):
        return bytes(str(items[0])[1:-1], "utf-8").decode("unicode_escape")

    def vector(self, items):
        return [i for i in items if i is not None] if items != [None] else []


def loads_csg(text: str, file: str = "<string>", facets: str = "ideal"):
    """The csdf shape of OpenSCAD ``.csg`` text (see the module documentation).

    Raises:
        ModelError: a syntax error, an unsupported node or bad arguments, with the file,
            line and column; an empty model.
    """
    if facets not in FACETS:
        raise CsdfError(f"facets must be one of {', '.join(map(repr, FACETS))}; "
                        f"got {facets!r}")
    check_source(text, file, MAX_CSG_BYTES, "OpenSCAD CSG text")
    lines = text.splitlines()

    def where(msg: str, line: int, col: int) -> ModelError:
        src = lines[line - 1] if 0 < line <= len(lines) else ""
        return ModelError(msg, file=file, line=line, column=col, source_line=src)

    try:
        tree = _parser().parse(text)
    except UnexpectedInput as exc:
        tok = getattr(exc, "token", None)
        what = f"unexpected {str(tok)!r}" if isinstance(tok, Token) else "unexpected input"
        raise where(f"CSG syntax: {what}", exc.line, exc.column) from None
    try:
        nodes = _Build(where).transform(tree)
    except VisitError as exc:
        if isinstance(exc.orig_exc, ModelError):
            raise exc.orig_exc from None
        raise
    roots = _roots(nodes)
    shape = _Converter(where, facets).group(roots, "the file")
    if shape is None:
        raise ModelError("the CSG file holds no geometry", file=file)
    return shape


def _roots(nodes: list[_Node]) -> list[_Node]:
    """The statements that make the model: the ``!`` one if any, else all but the
    background (``%``) and disabled (``*``) ones."""
    def find(ns):
        for n in ns:
            if n.modifier == "!":
                return n
            got = find(n.children)
            if got is not None:
                return got
        return None

    root = find(nodes)
    if root is not None:
        root.modifier = None
        return [root]
    return nodes


class _Converter:
    """:class:`_Node` trees -> csdf shapes (``facets`` ``'ideal'`` or ``'openscad'``)."""

    def __init__(self, where, facets: str = "ideal"):
        self.where = where
        self.faceted = facets == "openscad"

    # -- helpers ----------------------------------------------------------------------
    def err(self, n: _Node, msg: str) -> ModelError:
        return self.where(f"{n.name}: {msg}", n.line, n.column)

    def num(self, n: _Node, key: str, default: float | None = None, index: int | None = None,
            finite: bool = True) -> float:
        v = n.args.get(key, _UNDEF)
        if v is _UNDEF and index is not None and index < len(n.pos):
            v = n.pos[index]
        if v is _UNDEF or v is None:
            if default is None:
                raise self.err(n, f"missing {key}")
            return default
        if isinstance(v, bool) or not isinstance(v, float):
            raise self.err(n, f"{key} must be a number, got {_show(v)}")
        if finite and not math.isfinite(v):
            raise self.err(n, f"{key} must be finite, got {v}")
        return v

    def flag(self, n: _Node, key: str, default: bool = False) -> bool:
        v = n.args.get(key, default)
        if v is _UNDEF:
            return default
        if not isinstance(v, bool):
            raise self.err(n, f"{key} must be true or false, got {_show(v)}")
        return v

    def vec(self, n: _Node, key: str, size: int, default=None, index: int | None = None
            ) -> np.ndarray:
        v = n.args.get(key, _UNDEF)
        if v is _UNDEF and index is not None and index < len(n.pos):
            v = n.pos[index]
        if v is _UNDEF:
            if default is None:
                raise self.err(n, f"missing {key}")
            v = default
        if isinstance(v, float):
            v = [v] * size
        a = _array(v)
        if a is None or a.shape != (size,) or not np.all(np.isfinite(a)):
            raise self.err(n, f"{key} must be {size} finite numbers, got {_show(v)}")
        return a

    def positive(self, n: _Node, key: str, v: float) -> float:
        if not v > 0:
            raise self.err(n, f"{key} must be > 0, got {v}")
        return v

    # -- nodes ------------------------------------------------------------------------
    def group(self, children: list[_Node], what: str):
        shapes = [s for s in (self.node(c) for c in children
                              if c.modifier not in ("%", "*")) if s is not None]
        if not shapes:
            return None
        dims = {s.dim for s in shapes}
        if len(dims) > 1:
            c = children[0]
            raise self.where(f"{what} mixes 2D and 3D children (OpenSCAD ignores one kind; "
                             "csdf does not guess which)", c.line, c.column)
        from ..shapes.csg import union

        return shapes[0] if len(shapes) == 1 else union(*shapes)

    def node(self, n: _Node):
        fn = getattr(self, "n_" + n.name, None)
        if fn is None:
            if n.name in _EXTERNAL:
                raise self.err(n, f"not supported ({_EXTERNAL[n.name]})")
            raise self.err(n, "unknown node")
        try:
            return fn(n)
        except ShapeError as exc:  # a shape refused its arguments: say where
            raise self.err(n, str(exc)) from None

    def fragments(self, n: _Node, r: float) -> int:
        """OpenSCAD's number of segments of a circle of radius ``r`` from the node's
        ``$fn``, ``$fa``, ``$fs`` (:func:`fragments`)."""
        return fragments(r, self.num(n, "$fn", 0.0), self.num(n, "$fs", 2.0),
                         self.num(n, "$fa", 12.0))

    def n_group(self, n):
        return self.group(n.children, n.name)

    n_union = n_render = n_group

    def n_color(self, n):
        """The children's union with their colour kept (:meth:`csdf.Shape.color`):
        OpenSCAD writes ``color([r, g, b, a])``; other forms, and values outside
        ``[0, 1]`` (OpenSCAD's mark of an unknown colour name), add no colour."""
        from ..shapes.appearance import color_arg

        shape = self.group(n.children, n.name)
        raw = n.args.get("c", n.pos[0] if n.pos else _UNDEF)
        if shape is None or not isinstance(raw, list):
            return shape
        try:
            rgba = color_arg([float(v) for v in raw], "color")
        except (ShapeError, TypeError, ValueError):
            return shape  # OpenSCAD draws an unknown colour name its default way too
        return shape.color(rgba)

    def n_difference(self, n):
        kids = [s for s in (self.node(c) for c in n.children if c.modifier not in ("%", "*"))
                if s is not None]
        if not kids:
            return None
        first, rest = kids[0], kids[1:]
        if any(k.dim != first.dim for k in rest):
            raise self.err(n, "mixes 2D and 3D children")
        for k in rest:
            first = first - k
        return first

    def n_intersection(self, n):
        kids = [s for s in (self.node(c) for c in n.children if c.modifier not in ("%", "*"))
                if s is not None]
        if not kids:
            return None
        if any(k.dim != kids[0].dim for k in kids):
            raise self.err(n, "mixes 2D and 3D children")
        from ..shapes.csg import intersection

        return kids[0] if len(kids) == 1 else intersection(*kids)

    def n_multmatrix(self, n):
        child = self.group(n.children, n.name)
        if child is None:
            return None
        m = n.args.get("m", n.pos[0] if n.pos else _UNDEF)
        M = _array(m)
        if M is None or M.shape not in ((4, 4), (3, 4)) or not np.all(np.isfinite(M)):
            raise self.err(n, f"the matrix must be 4x4 finite numbers, got {_show(m)}")
        if M.shape == (4, 4) and not np.allclose(M[3], [0, 0, 0, 1]):
            raise self.err(n, "a projective matrix (last row not 0, 0, 0, 1) is not "
                              "supported")
        A, t = M[:3, :3], M[:3, 3]
        if child.dim == 2:
            if np.any(np.abs(A[2, :2]) > 1e-12) or np.any(np.abs(A[:2, 2]) > 1e-12):
                raise self.err(n, "turns a 2D child out of its plane")
            A, t = A[:2, :2], t[:2]
        if abs(np.linalg.det(A)) < 1e-12 * max(np.abs(A).max(), 1e-300) ** len(A):
            raise self.err(n, "the matrix is singular (a zero scale)")

        if np.array_equal(A, np.eye(len(A))):  # a plain move: readable as such
            return child.translate(t.tolist()) if np.any(t != 0) else child
        try:
            return child.transform(np.vstack([np.c_[A, t], [0.0] * len(A) + [1.0]]))
        except ShapeError as exc:
            raise self.err(n, str(exc)) from None

    def n_cube(self, n):
        from ..shapes.primitives3d import box

        return self.block(n, box, 3)

    def block(self, n, make, dim: int):
        """``cube`` or ``square``: ``make(size)`` centred, or with a corner at 0."""
        s = self.vec(n, "size", dim, default=[1.0] * dim, index=0)
        for i in range(dim):
            self.positive(n, f"size[{i}]", s[i])
        b = make(s.tolist())
        return b if self.flag(n, "center") else b.translate((s / 2).tolist())

    def n_sphere(self, n):
        from ..shapes.primitives3d import sphere

        r = self.positive(n, "r", self.num(n, "r", 1.0, index=0))
        if self.faceted:
            from ..shapes.convex import MAX_PLANES, convex_polyhedron

            k = self.fragments(n, r)
            if k * ((k + 1) // 2) > MAX_PLANES:
                raise self.err(n, f"{k} segments make more than {MAX_PLANES} faces, more "
                                  "than a convex_polyhedron holds (use facets='ideal')")
            return convex_polyhedron(sphere_points(r, k))
        return sphere(r)

    def cylinder_args(self, n) -> tuple[float, float, float]:
        """A ``cylinder`` node's ``(h, r1, r2)``, checked (``r`` gives both radii)."""
        h = self.positive(n, "h", self.num(n, "h", 1.0))
        r = self.num(n, "r", 1.0)
        r1, r2 = self.num(n, "r1", r), self.num(n, "r2", r)
        if r1 < 0 or r2 < 0 or not (r1 > 0 or r2 > 0):
            raise self.err(n, f"radii r1 = {r1}, r2 = {r2} must be >= 0 and not both 0")
        return h, r1, r2

    def n_cylinder(self, n):
        from ..shapes.primitives3d import capped_cone, cone, cylinder

        h, r1, r2 = self.cylinder_args(n)
        centre = self.flag(n, "center")
        if self.faceted:
            from ..shapes.convex import convex_polyhedron

            z0 = -h / 2 if centre else 0.0
            return convex_polyhedron(cylinder_points(r1, r2, z0, z0 + h,
                                                     self.fragments(n, max(r1, r2))))
        if r1 == r2:
            s = cylinder(r1, h)
            return s if centre else s.translate((0.0, 0.0, h / 2))
        if r2 == 0:
            s = cone(r1, h)
        elif r1 == 0:  # apex down: the cone reflected through z = h / 2
            s = cone(r2, h).transform([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, -1, h],
                                       [0, 0, 0, 1]])
        else:
            s = capped_cone(r1, r2, h)
        return s.translate((0.0, 0.0, -h / 2)) if centre else s

    def n_square(self, n):
        from ..shapes.primitives2d import rectangle

        return self.block(n, rectangle, 2)

    def n_circle(self, n):
        from ..shapes.primitives2d import circle

        r = self.positive(n, "r", self.num(n, "r", 1.0, index=0))
        if self.faceted:
            from ..shapes.primitives2d import polygon

            return polygon(circle_points(r, self.fragments(n, r)).tolist())
        return circle(r)

    def n_polygon(self, n):
        from ..shapes.primitives2d import polygon

        pts = _array(n.args.get("points", n.pos[0] if n.pos else _UNDEF))
        if pts is None or pts.ndim != 2 or pts.shape[1] < 2 or len(pts) < 3 \
                or not np.all(np.isfinite(pts)):
            raise self.err(n, "points must be at least 3 finite [x, y] pairs")
        pts = pts[:, :2]
        paths = n.args.get("paths", _UNDEF)
        if paths is _UNDEF or paths is None:
            loops = [list(range(len(pts)))]
        else:
            if not isinstance(paths, list) or not all(isinstance(p, list) for p in paths):
                raise self.err(n, f"paths must be a list of index lists, got {_show(paths)}")
            loops = []
            for k, p in enumerate(paths):
                idx = _array(p)
                if idx is None or idx.ndim != 1 or np.any(idx != np.round(idx)) or \
                        np.any(idx < 0) or np.any(idx >= len(pts)):
                    raise self.err(n, f"paths[{k}] must hold indices of points "
                                      f"(0..{len(pts) - 1})")
                if len(idx) >= 3:
                    loops.append([int(i) for i in idx])
            if not loops:
                return None
        if len(loops) == 1:
            return polygon(pts[loops[0]].tolist())
        return polygon(pts.tolist(), paths=loops)

    def n_linear_extrude(self, n):
        from ..shapes.primitives2d import extrude

        child = self.group(n.children, n.name)
        if child is None:
            return None
        if child.dim != 2:
            raise self.err(n, "needs 2D children")
        h = self.positive(n, "height", self.num(n, "height", 100.0))
        sc = n.args.get("scale", 1.0)
        sc_a = _array(sc)
        if sc_a is None or sc_a.size not in (1, 2) or not np.all(np.isfinite(sc_a)) or \
                np.any(sc_a < 0):
            raise self.err(n, f"scale must be a number or [sx, sy] >= 0, got {_show(sc)}")
        sc_a = np.broadcast_to(sc_a.reshape(-1), (2,))
        v = n.args.get("v", _UNDEF)
        if v is not _UNDEF and not np.allclose(_array(v), [0, 0, 1]):
            raise self.err(n, f"an extrusion direction v = {_show(v)} is not read yet")
        twist = self.num(n, "twist", 0.0)
        if not math.isfinite(twist):
            raise self.err(n, f"twist must be a number, got {twist:g}")
        if self.faceted and (twist != 0.0 or sc_a[0] != sc_a[1]):
            ruled = self.ruled_extrusion(n, h, sc_a, twist)
            if ruled is not None:
                return ruled
        s = extrude(child, h).translate((0.0, 0.0, h / 2))
        if twist != 0.0:
            # OpenSCAD turns clockwise (seen from +z) by `twist` degrees over the height
            s = s.twist(-math.radians(twist) / h)
        # then scales the turned section (an uneven scale does not commute with the turn)
        if sc_a[0] != sc_a[1]:  # x and y scaled apart from 1 at the bottom to sc at the top
            s = s.taper(((float(sc_a[0]) - 1.0) / h, (float(sc_a[1]) - 1.0) / h))
        elif sc_a[0] != 1.0:  # the section scaled from 1 at the bottom to sc at the top
            s = s.taper((float(sc_a[0]) - 1.0) / h)
        return s.translate((0.0, 0.0, -h / 2)) if self.flag(n, "center") else s

    # -- OpenSCAD's ruled extrusions (facets='openscad') ---------------------------------
    def ruled_extrusion(self, n: _Node, h: float, scale: np.ndarray, twist: float):
        """A twisted or non-uniformly scaled ``linear_extrude`` as OpenSCAD builds it:
        the outline copied to each slice (:func:`extrusion_levels`: turned by ``-twist
        t`` degrees, then scaled by ``1 + (scale - 1) t``) and neighbouring slices
        joined by flat triangles, each quad split along its shorter diagonal as
        OpenSCAD's export shows; the slice count by :meth:`extrude_slices`; a
        ``polyhedron`` of that surface (exact). None when the child's outline cannot be
        had (:meth:`extrusion_outline`), or the top is squashed flat in one axis only."""
        got = self.extrusion_outline(n)
        if got is None or (scale[0] == 0.0) != (scale[1] == 0.0):
            return None
        polys, rings = got
        import shapely

        slices = self.extrude_slices(n, h, scale, twist, np.concatenate(rings))
        z0 = -h / 2 if self.flag(n, "center") else 0.0
        apex = scale[0] == 0.0
        rots = twist * np.arange(slices + 1) / slices
        levels = extrusion_levels(np.concatenate(rings), h, scale, twist, slices, z0)
        if apex:  # a squashed top is one point
            levels = levels[:-1]
        size = sum(len(xy) for xy in rings)
        offsets = np.cumsum([0] + [len(xy) for xy in rings[:-1]])
        # per level, the first index of each ring
        base = [[i * size + int(o) for o in offsets] for i in range(len(levels))]
        V = levels.reshape(-1, 3)
        top = len(V)  # the apex's index
        if apex:
            V = np.concatenate([V, [[0.0, 0.0, z0 + h]]])
        faces: list[tuple[int, int, int]] = []
        for i in range(slices):
            split_first = math.sin(math.radians(rots[i] - rots[i + 1])) > 0.0
            for r, xy in enumerate(rings):
                k = len(xy)
                for j in range(k):
                    q = (j + 1) % k
                    p1, c1 = base[i][r] + j, base[i][r] + q
                    if apex and i == slices - 1:
                        faces.append((p1, c1, top))
                        continue
                    p2, c2 = base[i + 1][r] + j, base[i + 1][r] + q
                    # OpenSCAD splits each quad along its shorter diagonal (measured
                    # on its STL export; a tie by the direction of the twist)
                    d1 = float(((V[p1] - V[c2]) ** 2).sum())
                    d2 = float(((V[p2] - V[c1]) ** 2).sum())
                    if d1 < d2 or (d1 == d2 and not split_first):
                        faces += [(p1, c1, c2), (p1, c2, p2)]
                    else:
                        faces += [(p1, c1, p2), (c1, c2, p2)]
        index = {}  # a bottom vertex's index by its position
        for r, xy in enumerate(rings):
            for j, (x, y) in enumerate(xy.tolist()):
                index[(x, y)] = base[0][r] + j
        for p in polys:
            for tri in shapely.constrained_delaunay_triangles(p).geoms:
                c = np.asarray(tri.exterior.coords)[:3, :2]
                try:
                    ids = [index[(float(x), float(y))] for x, y in c.tolist()]
                except KeyError:
                    return None
                area = (c[1, 0] - c[0, 0]) * (c[2, 1] - c[0, 1]) - \
                    (c[1, 1] - c[0, 1]) * (c[2, 0] - c[0, 0])
                if area == 0.0:
                    continue
                a, b, d = ids if area > 0 else (ids[0], ids[2], ids[1])  # CCW
                faces.append((a, d, b))  # the bottom faces down
                if not apex:
                    off = base[slices][0]
                    faces.append((a + off, b + off, d + off))
        from ..shapes.polyhedron import polyhedron

        try:
            return polyhedron(V, np.array(faces, dtype=np.int64))
        except ShapeError as exc:
            raise self.err(n, f"OpenSCAD's extrusion surface: {exc}") from None

    def extrusion_outline(self, n: _Node) -> tuple[list, list[np.ndarray]] | None:
        """``(polygons, rings)`` of a ``linear_extrude``'s children: their outline as
        shapely polygons (outer rings counter-clockwise, holes clockwise) and each
        ring's vertices ``(k, 2)`` without the closing repeat; None when it cannot be
        had (a child other than squares, circles, polygons, their transforms and
        booleans; no shapely) or is empty."""
        try:
            import shapely
        except ImportError:
            return None
        geom = self.outline_group(n.children)
        if geom is None or geom.is_empty:
            return None
        polys = [shapely.geometry.polygon.orient(p, 1.0)
                 for p in getattr(geom, "geoms", [geom]) if not p.is_empty]
        rings: list[np.ndarray] = []
        for p in polys:
            for ring in [p.exterior, *p.interiors]:
                xy = np.asarray(ring.coords)[:-1, :2]
                if len(xy) >= 3:
                    rings.append(xy)
        return (polys, rings) if rings else None

    def extrude_slices(self, n: _Node, h: float, scale: np.ndarray, twist: float,
                       xy: np.ndarray) -> int:
        """The number of slices of a twisted or unevenly scaled ``linear_extrude`` in
        ``facets='openscad'`` mode, for its surface and for the points of a ``hull``
        or ``resize`` around it alike: the node's ``slices`` when given, else OpenSCAD
        2021.01's rule (:func:`helix_slices` for a twist, :func:`diagonal_slices` for
        an uneven scale alone), from the outline's vertices ``xy`` ``(N, 2)``.
        Raises a located error above 100000."""
        if "slices" in n.args:
            slices = max(int(self.num(n, "slices", 1.0)), 1)
        elif twist != 0.0:
            slices = helix_slices(float((xy ** 2).sum(axis=1).max()), h, twist,
                                  self.num(n, "$fn", 0.0), self.num(n, "$fs", 2.0),
                                  self.num(n, "$fa", 12.0))
        else:  # a non-uniform scale alone: OpenSCAD's "diagonal" slices
            delta2 = float((((1.0 - scale) * xy) ** 2).sum(axis=1).max())
            slices = diagonal_slices(delta2, h, self.num(n, "$fn", 0.0),
                                     self.num(n, "$fs", 2.0))
        if slices > 100_000:
            raise self.err(n, f"{slices} slices; at most 100000 are read")
        return slices

    def outline_group(self, children: list[_Node]):
        """The union of the children's outlines (a shapely geometry), or None."""
        import shapely

        parts = []
        for c in children:
            if c.modifier in ("%", "*"):
                continue
            g = self.outline(c)
            if g is None:
                return None
            parts.append(g)
        if not parts:
            return None
        return shapely.union_all(parts)

    def outline(self, n: _Node):
        """The outline of a 2D node as a shapely polygon (OpenSCAD's vertices: squares,
        faceted circles, polygons with even-odd paths, 2D transforms, unions,
        differences and intersections), or None for anything else."""
        import shapely
        from shapely import affinity

        name = n.name
        if name in ("group", "union", "render", "color"):
            return self.outline_group(n.children)
        if name in ("difference", "intersection"):
            kids = [c for c in n.children if c.modifier not in ("%", "*")]
            gs = [self.outline(c) for c in kids]
            if not gs or any(g is None for g in gs):
                return None
            if name == "intersection":
                return shapely.intersection_all(gs)
            return gs[0].difference(shapely.union_all(gs[1:])) if len(gs) > 1 else gs[0]
        if name == "multmatrix":
            g = self.outline_group(n.children)
            M = _array(n.args.get("m", n.pos[0] if n.pos else _UNDEF))
            if g is None or M is None or M.shape not in ((4, 4), (3, 4)):
                return None
            return affinity.affine_transform(g, [M[0, 0], M[0, 1], M[1, 0], M[1, 1],
                                                 M[0, 3], M[1, 3]])
        if name in ("square", "circle"):
            pts = self.points(n)
            return None if pts is None else shapely.Polygon(pts)
        if name == "polygon":
            pts = _array(n.args.get("points", n.pos[0] if n.pos else _UNDEF))
            if pts is None or pts.ndim != 2 or len(pts) < 3:
                return None
            pts = pts[:, :2]
            paths = n.args.get("paths", _UNDEF)
            loops = [list(range(len(pts)))] if paths in (_UNDEF, None) else paths
            area = None
            for loop in loops:
                idx = _array(loop)
                if idx is None or idx.ndim != 1 or len(idx) < 3:
                    continue
                ring = shapely.Polygon(pts[idx.astype(int)])
                if not ring.is_valid:
                    return None
                area = ring if area is None else area.symmetric_difference(ring)
            return area
        return None

    def n_rotate_extrude(self, n):
        from ..shapes.primitives2d import revolve

        child = self.group(n.children, n.name)
        if child is None:
            return None
        if child.dim != 2:
            raise self.err(n, "needs 2D children")
        angle = self.num(n, "angle", 360.0)
        if not math.isfinite(angle) or angle == 0.0:
            raise self.err(n, f"angle must be a non-zero number, got {angle:g}")
        partial = abs(angle) < 360.0
        b = child.bounds
        if b is not None and b[0, 0] < -1e-9 and b[1, 0] > 1e-9:
            raise self.err(n, "the 2D child crosses the axis (x < 0 and x > 0), which "
                              "OpenSCAD refuses too")
        if b is not None and b[1, 0] <= 1e-9:  # all on the negative side: mirror it
            child = child.transform([[-1, 0, 0], [0, 1, 0], [0, 0, 1]])
        sweep = math.radians(angle) if partial else None
        if not self.faceted:
            return revolve(child, angle=sweep)
        if b is None:
            raise self.err(n, "an unbounded 2D child cannot be faceted")
        pts = self.group_points(n)  # OpenSCAD counts the segments from the largest x
        xmax = float(np.abs(pts[:, 0]).max()) if pts is not None else float(
            np.abs(b[:, 0]).max())
        k = self.fragments(n, xmax)
        if partial:
            # OpenSCAD puts int(k |angle| / 360) segments (at least 1) on the sweep from
            # +x: the faceted turn of 360 k' / |angle| segments has them where that is
            # a whole number; otherwise the true curve is read
            k_part = max(int(k * abs(angle) / 360.0), 1)
            full = 360.0 * k_part / abs(angle)
            if abs(full - round(full)) < 1e-9 and round(full) >= 3:
                return revolve(child, segments=int(round(full)), angle=sweep)
            return revolve(child, angle=sweep)  # (no whole faceting fits: the curve)
        # OpenSCAD puts its first section on -x (then every 360 / k degrees)
        s = revolve(child, segments=max(k, 3))
        return s.transform([[-1, 0, 0, 0], [0, -1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]) \
            if k % 2 else s

    def n_offset(self, n):
        child = self.group(n.children, n.name)
        if child is None:
            return None
        if child.dim != 2:
            raise self.err(n, "needs 2D children")
        if "r" in n.args and n.args["r"] is not _UNDEF:
            d = self.num(n, "r")
        else:
            d = self.num(n, "delta", 0.0)
        if d == 0.0:
            return child
        return child.offset(d)

    def n_minkowski(self, n):
        kids = [c for c in n.children if c.modifier not in ("%", "*")]
        balls = [(i, _ball(c)) for i, c in enumerate(kids)]
        balls = [(i, b) for i, b in balls if b is not None]
        if len(kids) < 2:
            return self.group(kids, n.name)
        if len(balls) != 1 or len(kids) != 2:
            raise self.err(n, "only a shape with one sphere or circle is read yet (the "
                              "general sum needs csdf.from_mesh)")
        i, (radius, centre, dim) = balls[0]
        other = self.node(kids[1 - i])
        if other is None:
            return None
        if other.dim != dim:
            raise self.err(n, "mixes 2D and 3D children")
        if np.any(centre != 0):
            other = other.translate(centre.tolist())
        return other.round(radius)

    def n_hull(self, n):
        kids = [c for c in n.children if c.modifier not in ("%", "*")]
        if not kids:
            return None
        if not self.faceted:  # the closed forms of true spheres and circles
            balls = [_ball(c) for c in kids]
            if all(b is not None for b in balls):
                if len({b[2] for b in balls}) > 1:
                    raise self.err(n, "mixes 2D and 3D children")
                if len(kids) == 1:
                    return self.node(kids[0])
                if len(kids) == 2 and balls[0][2] == 3:
                    return _ball_hull(balls[0], balls[1])
                if len(kids) == 2 and balls[0][0] == balls[1][0]:
                    from ..shapes.primitives2d import segment

                    (r, a, _), (_, b, _) = balls
                    return segment(a.tolist(), b.tolist(), 2.0 * r)
        pts = self.points(n)
        if pts is None:
            return None
        return _hull_shape(pts)

    # -- points whose convex hull is a node's ---------------------------------------
    def points(self, n: _Node) -> np.ndarray | None:
        """``(N, dim)`` points whose convex hull is the node's (``facets='openscad'``:
        exactly OpenSCAD's faceted geometry; ``'ideal'``: curves faceted finely, within
        :data:`HULL_TOLERANCE` of their radius, inside); None for no geometry."""

        fn = getattr(self, "p_" + n.name, None)
        try:
            return fn(n) if fn is not None else self.sampled(n, None)
        except ShapeError as exc:
            raise self.err(n, str(exc)) from None

    def group_points(self, n: _Node, children: list[_Node] | None = None
                     ) -> np.ndarray | None:
        kids = [c for c in (n.children if children is None else children)
                if c.modifier not in ("%", "*")]
        got = [p for p in (self.points(c) for c in kids) if p is not None and len(p)]
        if not got:
            return None
        if len({p.shape[1] for p in got}) > 1:
            raise self.err(n, "mixes 2D and 3D children")
        return np.concatenate(got)

    p_group = p_union = p_render = p_color = p_hull = group_points

    def segments(self, n: _Node, r: float) -> int:
        """Segments of a circle of radius ``r``: OpenSCAD's, or the fine ideal ones."""
        return self.fragments(n, r) if self.faceted else _IDEAL_SEGMENTS

    def p_cube(self, n):
        s = self.vec(n, "size", 3, default=[1.0] * 3, index=0)
        for i in range(3):
            self.positive(n, f"size[{i}]", s[i])
        c = np.array(np.meshgrid([0, 1], [0, 1], [0, 1], indexing="ij")).reshape(3, -1).T
        return c * s - (s / 2 if self.flag(n, "center") else 0.0)

    def p_square(self, n):
        s = self.vec(n, "size", 2, default=[1.0] * 2, index=0)
        for i in range(2):
            self.positive(n, f"size[{i}]", s[i])
        c = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=float)
        return c * s - (s / 2 if self.flag(n, "center") else 0.0)

    def p_sphere(self, n):
        r = self.positive(n, "r", self.num(n, "r", 1.0, index=0))
        return sphere_points(r, self.segments(n, r))

    def p_circle(self, n):
        r = self.positive(n, "r", self.num(n, "r", 1.0, index=0))
        return circle_points(r, self.segments(n, r))

    def p_cylinder(self, n):
        h, r1, r2 = self.cylinder_args(n)
        z0 = -h / 2 if self.flag(n, "center") else 0.0
        return cylinder_points(r1, r2, z0, z0 + h, self.segments(n, max(r1, r2)))

    def p_polygon(self, n):
        pts = _array(n.args.get("points", n.pos[0] if n.pos else _UNDEF))
        if pts is None or pts.ndim != 2 or pts.shape[1] < 2 or not np.all(np.isfinite(pts)):
            raise self.err(n, "points must be finite [x, y] pairs")
        return pts[:, :2]

    def p_polyhedron(self, n):
        return self.polyhedron_data(n)[0]

    def p_multmatrix(self, n):
        pts = self.group_points(n)
        if pts is None:
            return None
        M = _array(n.args.get("m", n.pos[0] if n.pos else _UNDEF))
        if M is None or M.shape not in ((4, 4), (3, 4)) or not np.all(np.isfinite(M)):
            raise self.err(n, "the matrix must be 4x4 finite numbers")
        d = pts.shape[1]
        A, t = (M[:3, :3], M[:3, 3]) if d == 3 else (M[:2, :2], M[:2, 3])
        return pts @ A.T + t

    def p_linear_extrude(self, n):
        pts = self.group_points(n)
        if pts is None:
            return None
        if pts.shape[1] != 2:
            raise self.err(n, "needs 2D children")
        h = self.positive(n, "height", self.num(n, "height", 100.0))
        sc = _array(n.args.get("scale", 1.0))
        if sc is None or sc.size not in (1, 2) or not np.all(np.isfinite(sc)):
            raise self.err(n, "scale must be a number or [sx, sy]")
        sc = np.broadcast_to(sc.reshape(-1), (2,))
        v = n.args.get("v", _UNDEF)
        if v is not _UNDEF and not np.allclose(_array(v), [0, 0, 1]):
            raise self.err(n, f"an extrusion direction v = {_show(v)} is not read yet")
        twist = self.num(n, "twist", 0.0)
        z0 = -h / 2 if self.flag(n, "center") else 0.0
        if self.faceted and (twist != 0.0 or sc[0] != sc[1]):
            # OpenSCAD's slices, as its surface has them (ruled_extrusion): the exact
            # outline's vertices where it can be had
            got = self.extrusion_outline(n)
            if got is not None:
                pts = np.concatenate(got[1])
            layers = self.extrude_slices(n, h, sc, twist, pts)
        elif twist == 0.0:
            layers = 1
        else:  # a point turning by `step` degrees stays within the tolerance of its arc
            step = math.degrees(2.0 * math.acos(1.0 - HULL_TOLERANCE))
            layers = max(int(math.ceil(abs(twist) / step)), 1)
        return extrusion_levels(pts, h, sc, twist, layers, z0).reshape(-1, 3)

    def p_rotate_extrude(self, n):
        pts = self.group_points(n)
        if pts is None:
            return None
        if pts.shape[1] != 2:
            raise self.err(n, "needs 2D children")
        x = np.abs(pts[:, 0])
        angle = self.num(n, "angle", 360.0)
        k = self.segments(n, float(x.max()))
        if abs(angle) >= 360.0:
            # OpenSCAD's sections start on -x; ideal: any start, all on the circle
            a = math.pi + 2.0 * math.pi * np.arange(k) / k
        else:
            m = max(int(math.ceil(k * abs(angle) / 360.0)), 1)
            a = np.radians(self.num(n, "start", 0.0) + angle * np.arange(m + 1) / m)
        c, s_ = np.cos(a), np.sin(a)
        return np.column_stack([(x[:, None] * c).ravel(), (x[:, None] * s_).ravel(),
                                np.repeat(pts[:, 1], len(a))])

    def p_offset(self, n):
        pts = self.group_points(n)
        if pts is None:
            return None
        r = n.args.get("r", _UNDEF)
        if r is _UNDEF or r is None or not isinstance(r, float) or r < 0:
            return self.sampled(n, pts)
        if r == 0:
            return pts
        ring = circle_points(r, self.segments(n, r))
        return _minkowski_points(pts, ring)

    def p_minkowski(self, n):
        kids = [c for c in n.children if c.modifier not in ("%", "*")]
        sets = [p for p in (self.points(c) for c in kids) if p is not None and len(p)]
        if not sets:
            return None
        if len({p.shape[1] for p in sets}) > 1:
            raise self.err(n, "mixes 2D and 3D children")
        out = sets[0]
        for p in sets[1:]:  # hull(A + B) = hull(A) + hull(B)
            out = _minkowski_points(out, p)
        return out

    def p_difference(self, n):
        kids = [c for c in n.children if c.modifier not in ("%", "*")]
        return self.sampled(n, self.points(kids[0]) if kids else None)

    def p_intersection(self, n):
        kids = [c for c in n.children if c.modifier not in ("%", "*")]
        sets = [p for p in (self.points(c) for c in kids) if p is not None]
        return self.sampled(n, np.concatenate(sets) if sets and len(
            {p.shape[1] for p in sets}) == 1 else None)

    def sampled(self, n: _Node, candidates: np.ndarray | None) -> np.ndarray | None:
        """Points of a node read through its field: the ``candidates`` (exact vertices
        of its parts) that lie in the solid, and surface points found on a grid of
        :data:`HULL_GRID` cells along the longest side (projected onto the surface by
        the gradient). Hull error: about one cell at sharp edges made by the cut."""
        shape = self.node(n)
        if shape is None:
            return None
        if shape.bounds is None:
            raise self.err(n, "the hull of an unbounded child")
        return _surface_points(shape, candidates)

    def polyhedron_data(self, n: _Node) -> tuple[np.ndarray, list[list[int]]]:
        """``(points (N, 3), faces)`` of a ``polyhedron`` node, checked."""
        pts = _array(n.args.get("points", n.pos[0] if n.pos else _UNDEF))
        if pts is None or pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < 4 \
                or not np.all(np.isfinite(pts)):
            raise self.err(n, "points must be at least 4 finite [x, y, z] triples")
        faces = n.args.get("faces", n.args.get("triangles", _UNDEF))
        if not isinstance(faces, list) or not faces:
            raise self.err(n, f"faces must be a list of index lists, got {_show(faces)}")
        out = []
        for k, f in enumerate(faces):
            idx = _array(f)
            if idx is None or idx.ndim != 1 or len(idx) < 3 or np.any(idx != np.round(idx)) \
                    or np.any(idx < 0) or np.any(idx >= len(pts)):
                raise self.err(n, f"faces[{k}] must hold at least 3 indices of points "
                                  f"(0..{len(pts) - 1})")
            out.append([int(i) for i in idx])
        return pts, out

    def n_projection(self, n):
        from ..shapes.primitives2d import cross_section

        child = self.group(n.children, n.name)
        if child is None:
            return None
        if child.dim != 3:
            raise self.err(n, "needs 3D children")
        if self.flag(n, "cut"):
            return cross_section(child, 0.0)
        raise self.err(n, "cut = false (the solid's shadow) is not read: its distance "
                          "has no closed form (the smallest value along each vertical "
                          "line); cut = true reads as the section at z = 0")

    def n_polyhedron(self, n):
        from ..shapes.convex import convex_polyhedron
        from ..shapes.polyhedron import polyhedron

        pts, faces = self.polyhedron_data(n)
        used = pts[sorted({i for f in faces for i in f})]
        if _is_convex(used, pts, faces):
            return convex_polyhedron(used)
        try:
            return polyhedron(pts, faces)
        except ShapeError as exc:
            raise self.err(n, str(exc)) from None

    def n_resize(self, n):
        child = self.group(n.children, n.name)
        if child is None:
            return None
        d = child.dim
        new = self.vec(n, "newsize", 3, default=[0.0] * 3, index=0)
        raw = n.args.get("auto", False)
        flags = raw if isinstance(raw, list) else [raw] * 3
        if len(flags) != 3 or any(isinstance(v, (list, str)) or v is _UNDEF
                                  for v in flags):
            raise self.err(n, f"auto must be true, false or 3 of them, got {_show(raw)}")
        auto = [bool(v) for v in flags]
        pts = self.group_points(n)  # the children's box is their hull's
        if pts is None:
            return None
        size = np.zeros(3)
        size[:d] = pts.max(axis=0) - pts.min(axis=0)
        if np.any(new < 0) or not np.all(np.isfinite(new)):
            raise self.err(n, f"newsize must be 3 numbers >= 0, got {_show(new.tolist())}")
        scale = np.ones(3)
        for i in range(d):
            if new[i] > 0:
                if size[i] <= 0:
                    raise self.err(n, f"the children have no extent along axis {i}")
                scale[i] = new[i] / size[i]
        big = int(np.argmax(new[:d]))  # OpenSCAD's auto: the largest given size's factor
        for i in range(d):
            if new[i] == 0 and auto[i]:
                scale[i] = scale[big]
        return child.transform(np.diag(np.append(scale[:d], 1.0)).tolist())


#: ``facets='ideal'`` hulls: curved children are replaced by points on them whose hull
#: lies within this fraction of each curve's radius inside the true curve
HULL_TOLERANCE = 0.002
#: the segments of a circle for that: a sphere's points then lie at most
#: ``sqrt(2) pi / n`` radians from every point of it
_IDEAL_SEGMENTS = int(math.ceil(math.sqrt(2.0) * math.pi / math.acos(1.0 - HULL_TOLERANCE)))
#: cells along the longest side of the grid that samples children read through their
#: field (difference, intersection, offset by delta, ...) for a hull
HULL_GRID = 96
#: OpenSCAD's smallest radius that still makes a circle (GRID_FINE)
_GRID_FINE = 0.00000095367431640625


def fragments(r: float, fn: float = 0.0, fs: float = 2.0, fa: float = 12.0) -> int:
    """OpenSCAD 2021.01's number of segments of a circle of radius ``r`` (model units)
    from ``$fn`` (count), ``$fs`` (length) and ``$fa`` (degrees): ``$fn`` when it is
    > 0 (truncated, at least 3), else ``ceil(max(min(360 / $fa, 2 pi r / $fs), 5))``
    with ``$fa`` and ``$fs`` raised to 0.01; 3 below OpenSCAD's grid size."""
    if r < _GRID_FINE:
        return 3
    if fn > 0.0:
        return max(int(fn), 3) if math.isfinite(fn) else 3
    fs, fa = max(fs, 0.01), max(fa, 0.01)
    return int(math.ceil(max(min(360.0 / fa, r * 2.0 * math.pi / fs), 5.0)))


def _sin_cos_deg(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``sin`` and ``cos`` of angles in degrees, exact at multiples of 90 and 30 (so
    that a vertex on an axis has exact zeros)."""
    a = np.mod(np.asarray(a, dtype=np.float64), 360.0)
    r = np.radians(a)
    s, c = np.sin(r), np.cos(r)
    for deg, sv, cv in ((0, 0.0, 1.0), (30, 0.5, None), (60, None, 0.5), (90, 1.0, 0.0),
                        (120, None, -0.5), (150, 0.5, None), (180, 0.0, -1.0),
                        (210, -0.5, None), (240, None, -0.5), (270, -1.0, 0.0),
                        (300, None, 0.5), (330, -0.5, None)):
        hit = a == deg
        if sv is not None:
            s = np.where(hit, sv, s)
        if cv is not None:
            c = np.where(hit, cv, c)
    return s, c


def helix_slices(r2: float, h: float, twist: float, fn: float = 0.0, fs: float = 2.0,
                 fa: float = 12.0) -> int:
    """OpenSCAD 2021.01's number of slices of a twisted ``linear_extrude`` with no
    ``slices`` given: at least ``ceil(|twist| / 120)``; with ``$fn`` > 0,
    ``ceil(|twist| / 360 * $fn)``; else ``ceil(min(|twist| / $fa, L / $fs))`` with ``L``
    the length of the helix of the outline's farthest vertex (``r2``: its squared
    distance from the axis) over the height ``h``."""
    t = abs(twist)
    least = max(math.ceil(t / 120.0), 1)
    if math.sqrt(r2) < _GRID_FINE or not math.isfinite(fn):
        return least
    if fn > 0.0:
        return max(math.ceil(t / 360.0 * fn), least)
    fa_slices = t / max(fa, 0.01)
    fs_slices = math.sqrt(r2 * math.radians(t) ** 2 + h * h) / max(fs, 0.01)
    return max(math.ceil(min(fa_slices, fs_slices)), least)


def diagonal_slices(delta2: float, h: float, fn: float = 0.0, fs: float = 2.0) -> int:
    """OpenSCAD 2021.01's number of slices of a ``linear_extrude`` scaled unevenly and
    not twisted: ``$fn`` when > 0, else ``ceil(sqrt(delta2 + h^2) / $fs)``, ``delta2``
    the largest squared move of an outline vertex between bottom and top (at least 1)."""
    if math.sqrt(delta2) < _GRID_FINE or not math.isfinite(fn):
        return 1
    if fn > 0.0:
        return max(int(fn), 1)
    return max(math.ceil(math.sqrt(delta2 + h * h) / max(fs, 0.01)), 1)


def extrusion_levels(xy: np.ndarray, h: float, scale: np.ndarray, twist: float,
                     slices: int, z0: float = 0.0) -> np.ndarray:
    """The outline's vertices ``xy`` ``(N, 2)`` at each level of a ``linear_extrude``
    as OpenSCAD places them: ``(slices + 1, N, 3)``, level ``i`` (``t = i / slices``)
    at height ``z0 + h t``, turned by ``-twist t`` degrees (clockwise seen from +z),
    then scaled by ``1 + (scale - 1) t`` along x and y."""
    t = np.arange(slices + 1) / slices
    sn, cs = _sin_cos_deg(-(twist * np.arange(slices + 1) / slices))
    f = 1.0 + (np.asarray(scale, dtype=float)[None, :] - 1.0) * t[:, None]
    x = (xy[None, :, 0] * cs[:, None] - xy[None, :, 1] * sn[:, None]) * f[:, :1]
    y = (xy[None, :, 0] * sn[:, None] + xy[None, :, 1] * cs[:, None]) * f[:, 1:]
    z = np.broadcast_to((z0 + h * t)[:, None], x.shape)
    return np.stack([x, y, z], axis=-1)


def circle_points(r: float, k: int) -> np.ndarray:
    """OpenSCAD's ``k``-gon of a circle of radius ``r``: ``(k, 2)``, vertex ``i`` at
    ``360 i / k`` degrees (vertex 0 on +x)."""
    s, c = _sin_cos_deg(360.0 * np.arange(k) / k)
    return np.column_stack([r * c, r * s])


def sphere_points(r: float, k: int) -> np.ndarray:
    """OpenSCAD's faceted sphere of radius ``r`` with ``k`` segments: ``(k + 1) // 2``
    rings (``k``-gons, vertex 0 at angle 0) at the polar angles
    ``180 (i + 0.5) / rings`` degrees; ``(rings * k, 3)`` points."""
    rings = (k + 1) // 2
    s, c = _sin_cos_deg(180.0 * (np.arange(rings) + 0.5) / rings)
    ring = circle_points(1.0, k)
    return np.concatenate([np.column_stack([ring * (r * si), np.full(k, r * ci)])
                           for si, ci in zip(s, c)])


def cylinder_points(r1: float, r2: float, z1: float, z2: float, k: int) -> np.ndarray:
    """OpenSCAD's faceted cylinder or cone: a ``k``-gon of radius ``r1`` at ``z1`` and
    one of ``r2`` at ``z2`` (a radius 0 gives the apex point)."""
    out = []
    for r, z in ((r1, z1), (r2, z2)):
        ring = circle_points(r, k) if r > 0 else np.zeros((1, 2))
        out.append(np.column_stack([ring, np.full(len(ring), z)]))
    return np.concatenate(out)


def _minkowski_points(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Points whose hull is ``hull(a) + hull(b)``: the sums of the hull vertices."""
    a, b = _hull_reduce(a), _hull_reduce(b)
    return (a[:, None, :] + b[None, :, :]).reshape(-1, a.shape[1])


def _hull_reduce(p: np.ndarray) -> np.ndarray:
    """The hull's vertices of ``p`` (``p`` itself when it is flat or small)."""
    from scipy.spatial import ConvexHull, QhullError

    if len(p) <= p.shape[1] + 1:
        return p
    try:
        return p[ConvexHull(p).vertices]
    except (QhullError, ValueError):
        return p


def _hull_shape(points: np.ndarray):
    """The convex hull of ``(N, 3)`` points as a ``convex_polyhedron`` (of its vertices),
    or of ``(N, 2)`` points as a ``polygon``."""
    from ..shapes.convex import convex_polyhedron, hull_vertices_2d

    if points.shape[1] == 2:
        from ..shapes.primitives2d import polygon

        return polygon(hull_vertices_2d(points).tolist())
    return convex_polyhedron(_hull_reduce(np.unique(points, axis=0)))


def _surface_points(shape, candidates: np.ndarray | None) -> np.ndarray:
    """Points of ``shape``'s solid for its hull: the ``candidates`` with a field value
    <= 0 (to 1e-9 of the size), and surface points: grid samples (``HULL_GRID`` cells
    along the longest side of the bounds) within a cell of the surface, moved onto it
    by Newton steps along the gradient."""
    b = np.asarray(shape.bounds, dtype=np.float64)
    dim = b.shape[1]
    size = float((b[1] - b[0]).max())
    tol = 1e-9 * max(size, 1e-300)
    out = []
    if candidates is not None and len(candidates) and candidates.shape[1] == dim:
        v = np.asarray(shape(candidates), dtype=np.float64)
        out.append(candidates[v <= tol])
    h = size / HULL_GRID
    axes = [np.arange(lo - h, hi + 1.5 * h, h) for lo, hi in zip(b[0], b[1])]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, dim)
    v = np.asarray(shape(grid), dtype=np.float64)
    p = grid[np.abs(v) <= h]
    for _ in range(6):
        val, g = shape.value_and_grad(p)
        g = np.asarray(g, dtype=np.float64)[:, :dim]
        g2 = np.maximum((g * g).sum(axis=1), 1e-300)
        p = p - (np.asarray(val, dtype=np.float64) / g2)[:, None] * g
    val = np.asarray(shape(p), dtype=np.float64)
    out.append(p[np.abs(val) <= 1e-6 * size])
    pts = np.concatenate(out)
    if len(pts) < dim + 1:
        raise ShapeError("no surface found to take the hull of")
    return pts


def _is_convex(used: np.ndarray, pts: np.ndarray, faces: list[list[int]]) -> bool:
    """Whether a polyhedron's faces bound the convex hull of its points: every face's
    vertices on one hull plane, and the faces' enclosed volume the hull's."""
    from scipy.spatial import ConvexHull, QhullError

    try:
        hull = ConvexHull(used)
    except (QhullError, ValueError):
        return False
    scale = float(np.abs(used - used.mean(axis=0)).max())
    eq = hull.equations
    for f in faces:
        dist = pts[f] @ eq[:, :3].T + eq[:, 3]  # (face vertices, planes)
        if not np.any(np.all(np.abs(dist) <= 1e-9 * scale, axis=0)):
            return False
    o = used.mean(axis=0)
    vol = 0.0
    for f in faces:
        a = pts[f[0]] - o
        for i in range(1, len(f) - 1):
            vol += float(np.dot(a, np.cross(pts[f[i]] - o, pts[f[i + 1]] - o))) / 6.0
    return abs(abs(vol) - hull.volume) <= 1e-9 * max(hull.volume, 1e-300)


#: nodes that read external data
_EXTERNAL = {"import": "reads an external file", "surface": "reads a heightmap file",
             "text": "needs fonts", "roof": "a straight skeleton",
             "fill": "hole filling of an outline"}


def _ball(n: _Node) -> tuple[float, np.ndarray, int] | None:
    """``(radius, centre, dim)`` when ``n`` is a sphere or circle, possibly moved by
    pure translations (``multmatrix`` with an identity 3x3 part) and groups of one."""
    offset = np.zeros(3)
    while True:
        if n.name == "multmatrix":
            M = _array(n.args.get("m", n.pos[0] if n.pos else None))
            if M is None or M.shape not in ((4, 4), (3, 4)) or not np.allclose(
                    M[:3, :3], np.eye(3)):
                return None
            offset = offset + M[:3, 3]
        elif n.name not in ("group", "union", "render", "color"):
            break
        kids = [c for c in n.children if c.modifier not in ("%", "*")]
        if len(kids) != 1:
            return None
        n = kids[0]
    if n.name not in ("sphere", "circle"):
        return None
    r = n.args.get("r", n.pos[0] if n.pos else 1.0)
    if not isinstance(r, float) or not r > 0 or not math.isfinite(r):
        return None
    dim = 3 if n.name == "sphere" else 2
    if dim == 2 and offset[2] != 0:
        return None
    return r, offset[:dim], dim


def _ball_hull(a, b):
    """The convex hull of two spheres ``(radius, centre, 3)``."""
    (ra, ca, _), (rb, cb, _) = a, b
    from ..shapes.primitives3d import round_cone, sphere

    d = cb - ca
    L = float(np.linalg.norm(d))
    if L <= abs(ra - rb):  # one holds the other
        r, c = (ra, ca) if ra >= rb else (rb, cb)
        s = sphere(r)
        return s.translate(c.tolist()) if np.any(c != 0) else s
    # round_cone: r1 at z = 0, r2 at z = height; orient its +z along d
    return round_cone(ra, rb, L).orient((d / L).tolist()).translate(ca.tolist())


def _array(v) -> np.ndarray | None:
    if v is _UNDEF or isinstance(v, (bool, str, tuple)) or v is None:
        return None
    try:
        a = np.asarray(v, dtype=np.float64)
    except (TypeError, ValueError):
        return None
    return a


def _show(v) -> str:
    if v is _UNDEF:
        return "undef"
    if isinstance(v, tuple) and len(v) == 2 and v[0] == "word":
        return v[1]
    s = repr(v)
    return s if len(s) <= 60 else s[:57] + "..."


def load_csg(path: str | os.PathLike, facets: str = "ideal"):
    """The csdf shape of an OpenSCAD ``.csg`` file (see :func:`loads_csg`).

    Raises:
        ModelError: an unreadable file, a syntax error or an unsupported node, naming the
            file, line and column.
    """
    p = Path(path)
    text = read_source(p, MAX_CSG_BYTES)
    return loads_csg(text, str(p), facets)


def scad_to_csg_text(path: str | os.PathLike, timeout: float = SCAD_TIMEOUT) -> str:
    """Flatten a ``.scad`` file to ``.csg`` text with the ``openscad`` program.

    Raises:
        CsdfError: ``openscad`` not on PATH (with how to install it), a missing file, a
            failure (its message) or a run longer than ``timeout`` seconds.
    """
    p = Path(path)
    if not p.is_file():
        raise CsdfError(f"{p}: no such .scad file")
    exe = shutil.which("openscad")
    if exe is None:
        raise CsdfError(f"{p}: reading .scad needs the openscad program on PATH (Debian: "
                        "apt-get install openscad); or export a .csg from OpenSCAD "
                        "(File > Export > Export as CSG) and load that")
    with tempfile.TemporaryDirectory(prefix="csdf-scad-") as tmp:
        out = Path(tmp) / "model.csg"
        try:
            run = subprocess.run([exe, "-o", str(out), str(p.resolve())], cwd=str(p.parent),
                                 capture_output=True, text=True, timeout=timeout,
                                 stdin=subprocess.DEVNULL)
        except subprocess.TimeoutExpired:
            raise CsdfError(f"{p}: openscad took longer than {timeout:g} s") from None
        if run.returncode != 0 or not out.exists():
            msg = " ".join((run.stderr or run.stdout or "").strip().splitlines()[-3:])
            raise CsdfError(f"{p}: openscad failed (exit {run.returncode}): {msg}")
        return out.read_text(encoding="utf-8")


def load_scad(path: str | os.PathLike, facets: str = "ideal",
              timeout: float = SCAD_TIMEOUT):
    """The csdf shape of an OpenSCAD ``.scad`` file: flattened by the ``openscad``
    program (:func:`scad_to_csg_text`), then read as ``.csg`` (:func:`loads_csg`)."""
    return loads_csg(scad_to_csg_text(path, timeout), f"{path} (as CSG)", facets)

