"""A grid meshed in parts: the octree cut into super-bricks that are meshed one by one
(on one machine, or as tasks on a cluster: :mod:`csdf.distributed`) and stitched into
the mesh :func:`csdf.mesh` makes of the whole grid.

Why the parts agree with the whole:

* The octree keeps or drops a cell by its own box alone, so the bricks found below a
  super-brick (:func:`mesh_part` goes on from it down to bricks) are the bricks the
  whole descent finds there.
* A triangle depends only on its voxel's 8 samples, and a vertex only on its grid edge
  (the samples at its ends, then a root search along it that looks at that edge alone:
  :class:`csdf.mesh.stream._Roots`). Every vertex carries its edge's number
  (:func:`csdf.mesh.stream.edge_key`), so the vertices two parts share on the face
  between them are merged by number, not by position.

So :func:`stitch` gives the same vertices and triangles as the one-machine mesh,
bit for bit, up to their order (:func:`canonical` puts both in one order); the mesh is
watertight where the whole one is. Marching cubes only: a dual-contouring vertex
depends on the voxels around it, across the parts' faces.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import CsdfError
from ..field import Field
from .grid import BRICK, Grid, octree, top_size
from .stream import extract_mc

__all__ = ["Part", "plan_parts", "mesh_part", "shared_edges", "Stitcher", "stitch", "canonical",
           "MAX_TASKS", "MIN_SUPER_BRICK", "default_max_tasks"]

#: the default most parts :func:`plan_parts` cuts a grid of up to 1024 voxels a side
#: into (Dask's guidance: tasks of a second or more; csdf's bricks of 8^3 voxels are far
#: too small to be tasks); finer grids get more in proportion to their surface, (side /
#: 1024)^2 times as many, so that a task's share of the surface stays the same
MAX_TASKS = 96
#: the smallest super-brick :func:`plan_parts` chooses by itself (voxels)
MIN_SUPER_BRICK = 64


@dataclass
class Part:
    """The mesh of one super-brick: its own vertices first, then the shared ones.

    Attributes:
        cell: ``(3,)`` int64, the super-brick's lower sample index.
        size: its edge in voxels.
        vertices: ``(V, 3)`` float64, model units: rows ``[0, n_own)`` are the part's
            own (no other part holds them), rows ``[n_own, V)`` lie on the
            super-brick's faces and a neighbouring part may hold them too.
        faces: ``(F, 3)`` int64 (or int32), indices into ``vertices``,
            counter-clockwise seen from outside.
        n_own: the number of own vertices.
        keys: ``(V - n_own,)`` int64, the grid edge of each shared vertex
            (:func:`csdf.mesh.stream.edge_key`), by which parts are stitched.
    """

    cell: np.ndarray
    size: int
    vertices: np.ndarray
    faces: np.ndarray
    n_own: int
    keys: np.ndarray


def _super_brick(size: object, top: int) -> int:
    """A user's super-brick edge, checked: ``BRICK`` times a power of two (at most the
    root cell's edge ``top``)."""
    if isinstance(size, bool) or not isinstance(size, (int, np.integer)) or size < BRICK \
            or int(size) & (int(size) - 1):
        raise CsdfError(f"super_brick must be a power of two of at least {BRICK} (voxels "
                        f"along each side of a task's cube), got {size!r}")
    return min(int(size), top)


def default_max_tasks(grid: Grid) -> int:
    """:data:`MAX_TASKS` times ``max(1, (longest side / 1024)^2)``, rounded."""
    return int(round(MAX_TASKS * max(1.0, (max(grid.dims) / 1024.0) ** 2)))


def plan_parts(fld: Field, grid: Grid, super_brick: int | None = None,
               max_tasks: int | None = None) -> tuple[np.ndarray, int]:
    """The super-bricks to mesh: ``(cells (K, 3) int64, size)``, the lower sample indices
    of the octree cells of edge ``size`` voxels that may hold surface, sorted by x, y, z.

    Args:
        fld: the field (prepared for ``grid``: :func:`csdf.mesh.api.prepare_field`).
        grid: the sampling grid.
        super_brick: the cells' edge in voxels (a power of two, at least ``BRICK``).
            Default: the finest octree level (at most down to :data:`MIN_SUPER_BRICK`)
            whose surviving cells are at most ``max_tasks``.
        max_tasks: see ``super_brick``; default :func:`default_max_tasks`.

    Raises:
        CsdfError: a ``super_brick`` or ``max_tasks`` that is not a positive integer of
            the kind above.
    """
    top = top_size(grid)
    if super_brick is not None:
        size = _super_brick(super_brick, top)
        cells = octree(grid, fld.intervals, None, stop=size)
    else:
        if max_tasks is None:
            max_tasks = default_max_tasks(grid)
        if isinstance(max_tasks, bool) or not isinstance(max_tasks, (int, np.integer)) \
                or max_tasks < 1:
            raise CsdfError(f"max_tasks must be a positive integer, got {max_tasks!r}")
        size = top
        cells = octree(grid, fld.intervals, None, stop=size)
        while size > max(MIN_SUPER_BRICK, BRICK) and len(cells):
            finer = octree(grid, fld.intervals, None, stop=size // 2, start=(cells, size))
            if len(finer) > max_tasks:
                break
            cells, size = finer, size // 2
    cells = cells[np.lexsort((cells[:, 2], cells[:, 1], cells[:, 0]))]
    return cells, size


def mesh_part(fld: Field, grid: Grid, cell: np.ndarray, size: int) -> Part:
    """Marching cubes of the super-brick at ``cell (3,)`` of edge ``size`` voxels (one of
    :func:`plan_parts`'s), on the whole grid's samples and numbering."""
    cell = np.asarray(cell, dtype=np.int64).reshape(3)
    bricks = octree(grid, fld.intervals, None, start=(cell[None], size))
    bricks = bricks[np.lexsort((bricks[:, 2], bricks[:, 1], bricks[:, 0]))]
    verts, faces, keys = extract_mc(grid, fld.value, fld.intervals, None,
                                    serial=fld.serial_values(), bricks=bricks,
                                    edge_keys=True)
    shared = shared_edges(keys, grid, size)
    order = np.argsort(shared, kind="stable")  # own vertices first, each in its order
    rank = np.empty(len(order), dtype=np.int64)
    rank[order] = np.arange(len(order))
    n_own = int(len(shared) - shared.sum())
    return Part(cell, int(size), np.ascontiguousarray(np.asarray(verts)[order]),
                rank[np.asarray(faces)] if len(faces) else np.zeros((0, 3), np.int64),
                n_own, keys[order[n_own:]])


def shared_edges(keys: np.ndarray, grid: Grid, size: int) -> np.ndarray:
    """Bool ``(V,)``: which grid edges ``keys (V,)`` lie on the faces between
    super-bricks of edge ``size`` voxels (in a plane ``i = m size`` across their axis)."""
    keys = np.asarray(keys, dtype=np.int64)
    axis = keys % 3
    rest = keys // 3
    nz1, ny1 = grid.dims[2] + 1, grid.dims[1] + 1
    k = rest % nz1
    rest //= nz1
    j = rest % ny1
    i = rest // ny1
    on = np.zeros(len(keys), dtype=bool)
    for d, c in enumerate((i, j, k)):
        on |= (axis != d) & (c % size == 0)
    return on


class Stitcher:
    """Parts put together as they arrive (in any order of parts; the result is the same
    mesh up to order).

    Each part's own vertices are numbered as they come and handed to
    ``write_vertices``; its faces go to ``write_faces`` with each shared vertex as a
    placeholder ``-1 - c`` (``c``: the running count of shared copies). Only the shared
    copies (a few per cent of a large mesh) are kept: :meth:`shared` merges them by grid
    edge, and :meth:`resolve` replaces the placeholders. Without writers the arrays are
    kept, and :meth:`result` gives the mesh.

    Args:
        write_vertices: ``(n, 3) float64 -> None``, or None to keep them.
        write_faces: ``(m, 3) int64 -> None``, or None to keep them.
    """

    def __init__(self, write_vertices=None, write_faces=None) -> None:
        self._verts: list[np.ndarray] = []
        self._faces: list[np.ndarray] = []
        self._write_v = write_vertices or self._verts.append
        self._write_f = write_faces or self._faces.append
        self._keys: list[np.ndarray] = []
        self._copies: list[np.ndarray] = []
        self.own = 0  # own vertices so far
        self.copies = 0  # shared copies so far
        self.faces = 0

    def add(self, part: Part) -> None:
        """Take one part."""
        verts = np.asarray(part.vertices, dtype=np.float64)
        n_own = int(part.n_own)
        f = np.asarray(part.faces, dtype=np.int64)
        self._write_v(verts[:n_own])
        self._write_f(np.where(f < n_own, f + self.own, -1 - (self.copies + f - n_own)))
        if len(verts) > n_own:
            self._keys.append(np.asarray(part.keys, dtype=np.int64))
            self._copies.append(verts[n_own:])
        self.own += n_own
        self.copies += len(verts) - n_own
        self.faces += len(f)

    def shared(self) -> tuple[np.ndarray, np.ndarray]:
        """``(vertices (S, 3), ids (C,))``: the shared vertices merged by grid edge (the
        first copy kept; all are equal), numbered after the own ones, and the number of
        each copy's vertex."""
        if not self._keys:
            return np.zeros((0, 3)), np.zeros(0, dtype=np.int64)
        keys = np.concatenate(self._keys)
        _, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
        return np.concatenate(self._copies)[first], self.own + inverse.reshape(-1)

    @staticmethod
    def resolve(faces: np.ndarray, ids: np.ndarray) -> np.ndarray:
        """``faces (m, 3)`` with every placeholder ``-1 - c`` replaced by ``ids[c]``
        (in place when it is a writable array)."""
        neg = faces < 0
        faces[neg] = ids[-1 - faces[neg]]
        return faces

    def result(self) -> tuple[np.ndarray, np.ndarray]:
        """The mesh ``(vertices (V, 3), faces (F, 3) int64)`` of the kept arrays."""
        shared, ids = self.shared()
        verts = np.concatenate(self._verts + [shared]) if self._verts else shared
        faces = np.concatenate(self._faces) if self._faces else \
            np.zeros((0, 3), dtype=np.int64)
        return verts, self.resolve(faces, ids)


def stitch(parts: list[Part]) -> tuple[np.ndarray, np.ndarray]:
    """One mesh ``(vertices (V, 3), faces (F, 3) int64)`` of several parts: the parts'
    own vertices in order, then the shared ones merged by grid edge
    (:class:`Stitcher`)."""
    st = Stitcher()
    for p in parts:
        st.add(p)
    return st.result()


def canonical(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A mesh in a canonical order, to compare two meshes made in different orders:
    vertices ``(V, 3)`` sorted by x, y, z; each face rotated to start at its smallest
    index (its winding kept); faces sorted. Unreferenced vertices are kept."""
    v = np.asarray(vertices)
    f = np.asarray(faces, dtype=np.int64)
    order = np.lexsort((v[:, 2], v[:, 1], v[:, 0]))
    rank = np.empty(len(v), dtype=np.int64)
    rank[order] = np.arange(len(v))
    f = rank[f] if len(f) else f.reshape(0, 3)
    shift = np.argmin(f, axis=1) if len(f) else np.zeros(0, dtype=np.int64)
    rows = np.arange(len(f))[:, None]
    f = f[rows, (shift[:, None] + np.arange(3)[None, :]) % 3]
    f = f[np.lexsort((f[:, 2], f[:, 1], f[:, 0]))] if len(f) else f
    return v[order], f
