"""Closed triangle meshes as exact distance fields: :func:`polyhedron` and
:func:`from_mesh`.

The field is the exact signed distance to the mesh's surface (negative inside): the
nearest point over all triangles, found through a bounding volume hierarchy, signed by
the angle-weighted pseudonormal of the nearest feature (exact for a closed,
consistently oriented mesh, also inside thin and non-convex parts). Contract: **exact**,
Lipschitz 1. The gradient is the unit vector from the nearest point (exact wherever that
point is unique).

In a program the whole mesh is one call (:data:`csdf.ops.MESH_CODE`) that reads the
mesh as a data block of the bytecode (format version 3), not one instruction per face.
The CPU evaluators run it (``'numpy'``, whose mesh op is a multithreaded Numba query;
intervals too, so meshing and pruning work); the Numba tape evaluators, GLSL, C and
``.vm`` export refuse it with a message that says so.

The mesh is checked when the shape is made: closed (every edge joins two triangles),
consistently oriented (turned outwards when its volume is negative), finite, at most
:data:`csdf.meshdata.MAX_TRIANGLES` triangles. Points and faces are numbers, not
parameters; the shape is posed, scaled and combined like any other.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from ..errors import CsdfError, ShapeError
from ..expr import Expr, mesh_call
from ..meshdata import MeshData
from ..vec import Vec
from .base import Shape, box_bounds, register
from .primitives3d import primitive

__all__ = ["polyhedron", "from_mesh", "triangulate_faces"]


def _points(points: Any) -> np.ndarray:
    try:
        p = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError):
        p = None
    if p is None or p.ndim != 2 or p.shape[1] != 3:
        raise ShapeError("polyhedron: points must be a list of 3-vectors (numbers)")
    if not np.all(np.isfinite(p)):
        raise ShapeError("polyhedron: points must be finite numbers")
    return p


def _ear_clip(poly: np.ndarray, idx: list[int]) -> list[list[int]]:
    """Triangles of a simple polygon ``poly`` ``(n, 2)`` (counter-clockwise) by ear
    clipping, as indices into ``idx``."""
    order = list(range(len(idx)))
    tris: list[list[int]] = []

    def cross(o, a, b) -> float:
        return float((a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]))

    guard = 0
    while len(order) > 3 and guard < 10 * len(idx) ** 2:
        guard += 1
        n = len(order)
        for j in range(n):
            i0, i1, i2 = order[j - 1], order[j], order[(j + 1) % n]
            a, b, c = poly[i0], poly[i1], poly[i2]
            if cross(a, b, c) <= 0:
                continue  # reflex or flat corner: no ear
            if any(cross(a, b, poly[k]) >= 0 and cross(b, c, poly[k]) >= 0
                   and cross(c, a, poly[k]) >= 0 for k in order if k not in (i0, i1, i2)):
                continue
            tris.append([idx[i0], idx[i1], idx[i2]])
            order.pop(j)
            break
        else:
            raise ShapeError("polyhedron: a face is not a simple polygon (it crosses "
                             "itself); triangulate it")
    tris.append([idx[k] for k in order])
    return tris


def triangulate_faces(points: np.ndarray, faces: Any) -> np.ndarray:
    """``(Nt, 3)`` int64 triangles of polygon faces (lists of at least 3 vertex indices,
    each planar and simple; convex ones fanned, others ear-clipped in their plane), in
    each face's own winding.

    Raises:
        ShapeError: a face with fewer than 3 vertices, an index out of range, a face
            with no area, or one that crosses itself.
    """
    if isinstance(faces, np.ndarray) and faces.ndim == 2 and faces.shape[1] == 3:
        rows: list = faces.tolist()
    elif isinstance(faces, (list, tuple, np.ndarray)):
        rows = list(faces)
    else:
        raise ShapeError("polyhedron: faces must be a list of vertex index lists")
    n = len(points)
    tris: list[list[int]] = []
    for i, f in enumerate(rows):
        try:
            idx = [int(v) for v in f]
            if any(float(v) != int(v) for v in f):
                raise ValueError
        except (TypeError, ValueError):
            raise ShapeError(f"polyhedron: faces[{i}] must be a list of vertex "
                             "indices") from None
        if len(idx) < 3:
            raise ShapeError(f"polyhedron: faces[{i}] has {len(idx)} vertices; a face "
                             "needs 3 or more")
        if min(idx) < 0 or max(idx) >= n:
            raise ShapeError(f"polyhedron: faces[{i}] holds a vertex index outside "
                             f"0..{n - 1}")
        if len(idx) == 3:
            tris.append(idx)
            continue
        P = points[idx]
        normal = np.zeros(3)  # Newell's normal of the polygon
        for k in range(len(idx)):
            a, b = P[k], P[(k + 1) % len(idx)]
            normal += np.array([(a[1] - b[1]) * (a[2] + b[2]), (a[2] - b[2]) * (a[0] + b[0]),
                                (a[0] - b[0]) * (a[1] + b[1])])
        norm = float(np.linalg.norm(normal))
        if not norm > 0:
            raise ShapeError(f"polyhedron: faces[{i}] has no area")
        w = normal / norm
        u = np.cross(w, [1.0, 0.0, 0.0] if abs(w[0]) < 0.9 else [0.0, 1.0, 0.0])
        u /= np.linalg.norm(u)
        v = np.cross(w, u)
        q = np.column_stack([(P - P[0]) @ u, (P - P[0]) @ v])  # counter-clockwise
        tris.extend(_ear_clip(q, idx))
    return np.array(tris, dtype=np.int64).reshape(-1, 3)


def _mesh_shape(data: MeshData, points: Any, faces: Any) -> Shape:
    def f(p: Vec) -> Expr:
        x, y, z = p.c
        return mesh_call(data, x, y, z)

    lo, hi = data.bounds
    shape = primitive("polyhedron", f, args=(), prim_args=(), exactness="exact",
                      bounds=box_bounds(lo.tolist(), hi.tolist()))
    shape.kwargs = {"points": points, "faces": faces}  # (printed back as given)
    return shape


@register("primitive3d")
def polyhedron(points=None, faces=None) -> Shape:
    """A closed polyhedron: ``points`` ``(N, 3)`` and ``faces``, lists of vertex indices
    (triangles, or planar simple polygons, which are triangulated), all wound one way
    (either way: the solid is turned outwards). Neither: a regular tetrahedron in the
    cube ``[-0.5, 0.5]^3``. Field: the exact signed distance to the surface, through a
    bounding volume hierarchy (one mesh call in the bytecode; see
    :mod:`csdf.shapes.polyhedron`): **exact**, Lipschitz 1. Numbers only, no parameters.

    Raises:
        ShapeError: bad points or faces, or a surface that is not closed and
            consistently oriented (the message names an offending edge), or more than
            :data:`csdf.meshdata.MAX_TRIANGLES` triangles.
    """
    if points is None and faces is None:
        points = [[0.5, 0.5, 0.5], [0.5, -0.5, -0.5], [-0.5, 0.5, -0.5], [-0.5, -0.5, 0.5]]
        faces = [[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]]
    if points is None or faces is None:
        raise ShapeError("polyhedron needs both points and faces")
    P = _points(points)
    T = triangulate_faces(P, faces)
    try:
        data = MeshData(P, T)
    except CsdfError as exc:
        raise ShapeError(f"polyhedron: {exc}") from None
    rows = T if len(T) == len(faces) else [[int(v) for v in f] for f in faces]
    return _mesh_shape(data, P, rows)


def from_mesh(mesh: Any, faces: Any = None) -> Shape:
    """The exact signed distance field of a closed triangle mesh, as a shape.

    Args:
        mesh: a :class:`trimesh.Trimesh` (or anything with ``.vertices`` and
            ``.faces``), a :class:`csdf.meshdata.MeshData`, ``(N, 3)`` vertices (with
            ``faces``), or the path of a mesh file trimesh reads (``.stl``, ``.ply``,
            ``.obj``, ``.off``, ``.glb``; a scene's geometries are concatenated).
        faces: ``(Nt, 3)`` triangles when ``mesh`` is vertices.

    Returns:
        A ``polyhedron`` shape (see :func:`polyhedron`): **exact**, Lipschitz 1, bounds
        the mesh's box; in a ``.csdf`` model it is written as
        ``polyhedron(points=..., faces=...)``.

    Raises:
        CsdfError: an unreadable file, or a mesh that is not closed and consistently
            oriented (the message names an offending edge), or too large.
    """
    if isinstance(mesh, (str, os.PathLike)):
        import trimesh

        path = os.fspath(mesh)
        if not os.path.isfile(path):
            raise CsdfError(f"from_mesh: no mesh file {path!r}")
        try:
            loaded = trimesh.load(path, force="mesh", process=True)
        except Exception as exc:  # trimesh raises many kinds for a bad file
            raise CsdfError(f"from_mesh: cannot read {path!r} as a mesh: {exc}") from None
        if not hasattr(loaded, "faces") or len(loaded.faces) == 0:
            raise CsdfError(f"from_mesh: {path!r} holds no triangles")
        mesh = loaded
    if isinstance(mesh, MeshData) and faces is None:
        data = mesh
    else:
        try:
            data = MeshData(mesh, faces)
        except CsdfError as exc:
            raise CsdfError(f"from_mesh: {exc}") from None
    return _mesh_shape(data, data.vertices, data.faces)
