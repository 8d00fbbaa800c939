"""Convex polyhedra: the intersection of half-spaces ``n_i . p <= d_i``.

:func:`convex_polyhedron` takes the half-spaces as planes, or points whose convex hull
it is (computed with Qhull through ``scipy.spatial.ConvexHull``, coplanar facets
merged into one plane). Its field is ``max_i (n_i . p - d_i)`` with unit normals,
built as a balanced tree of ``max`` (depth ``log2`` of the number of planes):

* **inside** it is the exact signed distance (the nearest boundary point of a convex
  body from inside lies on the nearest facet plane);
* **outside** it is a lower bound of the distance (every half-space holds the body,
  so the distance to each plane is at most the distance to the body); it equals the
  distance where the nearest point is inside a facet, and underestimates near edges and
  vertices.

So the contract is **bound** (Lipschitz 1), with the exact zero set. The planes are
fixed numbers: a hull is computed when the shape is made, so points and planes cannot be
parameters.

Helpers for the readers of other formats: :func:`hull_planes` (points -> planes) and
:func:`hull_vertices_2d` (the convex hull of 2D points, counter-clockwise).
"""

from __future__ import annotations

import numpy as np

from ..errors import ShapeError
from ..expr import Expr, maximum
from ..vec import Vec
from .base import Shape, box_bounds, register
from .primitives3d import primitive

__all__ = ["convex_polyhedron", "hull_planes", "hull_vertices_2d", "MAX_HULL_POINTS",
           "MAX_PLANES"]

#: most points a hull is computed of
MAX_HULL_POINTS = 1_000_000
#: most planes of one convex polyhedron (each plane is about 7 instructions)
MAX_PLANES = 20_000

#: the default: a regular tetrahedron inscribed in the cube [-0.5, 0.5]^3
_TETRA = ((0.5, 0.5, 0.5), (0.5, -0.5, -0.5), (-0.5, 0.5, -0.5), (-0.5, -0.5, 0.5))


def _numbers(v, what: str, width: int) -> np.ndarray:
    """``(K, width)`` float64 array of constant numbers (``Expr`` constants allowed)."""
    def num(c, where: str) -> float:
        if isinstance(c, Expr):
            if c.op != "const":
                raise ShapeError(f"{where} must be a number: the hull is computed when the "
                                 "shape is made, so parameters cannot be used here")
            c = c.value
        if isinstance(c, bool) or not isinstance(c, (int, float, np.integer, np.floating)):
            raise ShapeError(f"{where} must be a number, got {type(c).__name__}")
        f = float(c)
        if not np.isfinite(f):
            raise ShapeError(f"{where} must be finite, got {f}")
        return f

    if isinstance(v, np.ndarray) and v.dtype.kind in "fiu":
        a = np.asarray(v, dtype=np.float64)
        if a.ndim != 2 or a.shape[1] != width:
            raise ShapeError(f"{what} must be a list of {width}-vectors, got an array of "
                             f"shape {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ShapeError(f"{what} must be finite numbers")
        return a
    if not isinstance(v, (list, tuple, np.ndarray)):
        raise ShapeError(f"{what} must be a list of {width}-vectors, got {type(v).__name__}")
    rows = []
    for i, row in enumerate(v):
        if not isinstance(row, (list, tuple, np.ndarray)) or len(row) != width:
            raise ShapeError(f"{what}[{i}] must be a {width}-vector")
        rows.append([num(c, f"{what}[{i}][{j}]") for j, c in enumerate(row)])
    return np.array(rows, dtype=np.float64).reshape(-1, width)


def _scale(a: np.ndarray) -> float:
    return float(max(np.abs(a).max(initial=0.0), 1e-300))


def _snap(normals: np.ndarray) -> np.ndarray:
    """Unit normals with components below 1e-14 set to exact zeros (an axis-aligned
    face then reads ``x - d``, not ``x + 1e-17 y - d``)."""
    n = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    n = np.where(np.abs(n) < 1e-14, 0.0, n)
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def _merge(normals: np.ndarray, offsets: np.ndarray, scale: float) -> np.ndarray:
    """Indices of the planes kept when planes equal to 1e-9 (normals; offsets relative
    to ``scale``) are merged (coplanar facets of a triangulated hull)."""
    from scipy.spatial import cKDTree

    key = np.column_stack([normals, offsets / scale])
    drop = np.zeros(len(key), dtype=bool)
    for i, j in cKDTree(key).query_pairs(1e-9, output_type="ndarray"):
        drop[max(i, j)] = True
    return np.flatnonzero(~drop)


def hull_planes(points, what: str = "convex hull") -> tuple[np.ndarray, np.ndarray]:
    """The facet planes of the convex hull of 3D points.

    Args:
        points: ``(N, 3)`` points (N >= 4, not all in one plane).
        what: the name used in error messages.

    Returns:
        ``(planes, vertices)``: ``planes`` ``(K, 4)`` rows ``(nx, ny, nz, d)`` with unit
        outward normals, the hull being ``n . p <= d`` for every row (coplanar facets
        merged; ``d`` is the largest ``n . v`` over the hull's vertices, so every vertex
        is inside); ``vertices`` ``(V, 3)`` the hull's vertices.

    Raises:
        ShapeError: fewer than 4 points, too many, non-finite, or all (nearly) in one
            plane or on one line.
    """
    from scipy.spatial import ConvexHull, QhullError

    p = _numbers(points, what, 3)
    if len(p) < 4:
        raise ShapeError(f"{what} needs at least 4 points, got {len(p)}")
    if len(p) > MAX_HULL_POINTS:
        raise ShapeError(f"{what} has {len(p)} points; at most {MAX_HULL_POINTS} are "
                         "allowed")
    p = np.unique(p, axis=0)
    scale = _scale(p - p.mean(axis=0))
    try:
        hull = ConvexHull(p)
    except (QhullError, ValueError):
        raise ShapeError(f"{what}: the points are all in one plane or on one line (a "
                         "flat hull has no inside)") from None
    verts = p[hull.vertices]
    if hull.volume <= 1e-12 * scale**3:
        raise ShapeError(f"{what}: the points are all in one plane or on one line (a "
                         "flat hull has no inside)")
    n = _snap(hull.equations[:, :3])
    d = (n @ verts.T).max(axis=1)  # supporting planes through the hull's vertices
    keep = _merge(n, d, scale)
    return np.column_stack([n[keep], d[keep]]), verts


def hull_vertices_2d(points) -> np.ndarray:
    """The convex hull of 2D points: its vertices ``(V, 2)`` counter-clockwise.

    Raises:
        ShapeError: fewer than 3 points, or all on one line.
    """
    from scipy.spatial import ConvexHull, QhullError

    p = np.unique(_numbers(points, "2D hull points", 2), axis=0)
    if len(p) < 3:
        raise ShapeError(f"a 2D hull needs at least 3 distinct points, got {len(p)}")
    try:
        hull = ConvexHull(p)
    except (QhullError, ValueError):
        raise ShapeError("the 2D hull's points are all on one line (it has no "
                         "inside)") from None
    if hull.volume <= 1e-12 * _scale(p - p.mean(axis=0)) ** 2:
        raise ShapeError("the 2D hull's points are all on one line (it has no inside)")
    return p[hull.vertices]  # Qhull gives 2D hull vertices counter-clockwise


def _planes_vertices(planes: np.ndarray) -> np.ndarray:
    """Vertices of the bounded intersection of half-spaces ``n . p <= d``."""
    from scipy.optimize import linprog
    from scipy.spatial import HalfspaceIntersection, QhullError

    n, d = planes[:, :3], planes[:, 3]
    # the Chebyshev centre: the deepest interior point (n are unit vectors)
    res = linprog(np.array([0.0, 0.0, 0.0, -1.0]), A_ub=np.column_stack([n, np.ones(len(n))]),
                  b_ub=d, bounds=[(None, None)] * 3 + [(0.0, None)], method="highs")
    if res.status == 3:
        raise ShapeError("convex_polyhedron: the planes do not bound a finite region")
    if res.status != 0 or not res.x[3] > 1e-12 * _scale(d):
        raise ShapeError("convex_polyhedron: the planes enclose no volume (empty or "
                         "flat intersection)")
    try:
        hs = HalfspaceIntersection(np.column_stack([n, -d]), res.x[:3])
    except (QhullError, ValueError):
        raise ShapeError("convex_polyhedron: the planes do not bound a finite "
                         "region") from None
    v = hs.intersections
    if not np.all(np.isfinite(v)) or np.abs(v).max() > 1e12 * max(_scale(d), 1.0):
        raise ShapeError("convex_polyhedron: the planes do not bound a finite region")
    return v


def _plane_expr(p: Vec, row: np.ndarray) -> Expr:
    """``n . p - d`` with zero components left out."""
    terms: list[Expr] = []
    for c, x in zip(row[:3].tolist(), p.c):
        if c == 1.0:
            terms.append(x)
        elif c == -1.0:
            terms.append(-x)
        elif c != 0.0:
            terms.append(x * c)
    e = terms[0]
    for t in terms[1:]:
        e = e + t
    return e - float(row[3]) if row[3] != 0.0 else e


@register("primitive3d")
def convex_polyhedron(points=None, planes=None) -> Shape:
    """Convex polyhedron: the convex hull of ``points`` ``(N, 3)`` (N >= 4, not flat;
    coplanar facets merged), or the intersection of the half-spaces ``planes`` ``(K, 4)``,
    each row ``(nx, ny, nz, d)`` meaning ``n . p <= d`` (normals need not be unit; the
    intersection must be bounded and not flat). Neither: a regular tetrahedron in the
    cube ``[-0.5, 0.5]^3``. Field ``max_i (n_i . p - d_i)`` over unit normals:
    **bound** (exact inside and where the nearest point lies inside a face; below the
    distance near edges and vertices outside); Lipschitz 1. Numbers only, no parameters.

    Raises:
        ShapeError: both or bad arguments, a flat or unbounded solid, more than
            :data:`MAX_PLANES` planes.
    """
    if points is not None and planes is not None:
        raise ShapeError("convex_polyhedron: give points or planes, not both")
    if planes is None:
        pts = _numbers(_TETRA if points is None else points, "convex_polyhedron: points", 3)
        rows, verts = hull_planes(pts, "convex_polyhedron: points")
        args: tuple = (pts.tolist(),)
        kwargs: dict = {}
    else:
        raw = _numbers(planes, "convex_polyhedron: planes", 4)
        if len(raw) < 4:
            raise ShapeError(f"convex_polyhedron: at least 4 planes bound a solid, got "
                             f"{len(raw)}")
        norm = np.linalg.norm(raw[:, :3], axis=1)
        if not np.all(norm > 0):
            i = int(np.argmin(norm))
            raise ShapeError(f"convex_polyhedron: planes[{i}] has a zero normal")
        unit = raw / norm[:, None]
        n = _snap(unit[:, :3])
        rows = np.column_stack([n, unit[:, 3]])
        rows = rows[_merge(n, rows[:, 3], _scale(rows[:, 3]))]
        verts = _planes_vertices(rows)
        args, kwargs = (), {"planes": raw.tolist()}
    if len(rows) > MAX_PLANES:
        raise ShapeError(f"convex_polyhedron has {len(rows)} planes; at most {MAX_PLANES} "
                         "are allowed")
    lo, hi = verts.min(axis=0), verts.max(axis=0)

    def f(p: Vec) -> Expr:
        return maximum(*[_plane_expr(p, r) for r in rows])

    shape = primitive("convex_polyhedron", f, args=args, prim_args=(), exactness="bound",
                      bounds=box_bounds(lo.tolist(), hi.tolist()))
    shape.kwargs = kwargs
    return shape
