"""A grid meshed in parts: the octree cut into cubes that are meshed one by one (on one
machine, or as tasks on a cluster: :mod:`csdf.distributed`) and stitched into the mesh
:func:`csdf.mesh` makes of the whole grid.

Why the parts agree with the whole:

* The octree keeps or drops a cell by its own box alone, so the bricks found below a
  cell (:func:`mesh_part` goes on from the plan's cells down to bricks) are the bricks
  the whole descent finds there.
* A triangle depends only on its voxel's 8 samples, and a vertex only on its grid edge
  (the samples at its ends, then a root search along it that looks at that edge alone:
  :class:`csdf.mesh.stream._Roots`). A part gives each vertex as its edge and its
  parameter ``t`` along it (:mod:`.part_kernels`), rebuilt with the mesher's own
  formula, and the vertices two parts share (on the faces between their cubes) are
  merged by edge, not by position.

So :class:`Stitcher` gives the same vertices and triangles as the one-machine mesh,
bit for bit, up to their order (:func:`canonical` puts both in one order); the mesh is
watertight where the whole one is. Marching cubes only: a dual-contouring vertex
depends on the voxels around it, across the parts' faces.

The plan (:func:`plan_parts`): the octree is descended to cells of
:func:`plan_level` voxels (a few thousand cells at any resolution), and the cubes to
mesh are chosen from the cells they hold, splitting the fullest cube until there are
``max_tasks``, so that the parts are of similar work whatever the surface's shape
(a uniform split leaves most cubes nearly empty and a few full). The workers go on
from the cells they are given, so the octree is descended once in all.
"""

from __future__ import annotations

import heapq
from dataclasses import dataclass, replace

import numpy as np

from ..errors import CsdfError
from ..field import Field
from . import part_kernels as PK
from .grid import BRICK, Grid, octree, top_size
from .kernels import fresh_array
from .stream import extract_mc

__all__ = ["Part", "PartTask", "plan_parts", "plan_level", "mesh_part", "Stitcher",
           "SharedVertices", "stitch", "canonical", "MAX_TASKS", "PLAN_CELLS",
           "default_max_tasks"]

#: the default most parts :func:`plan_parts` cuts a grid of up to 1024 voxels a side
#: into (Dask's guidance: tasks of a second or more; csdf's bricks of 8^3 voxels are far
#: too small to be tasks); finer grids get more in proportion to their surface, (side /
#: 1024)^2 times as many, so that a task's share of the surface stays the same
MAX_TASKS = 96
#: the plan's cells are the root cube's edge / PLAN_CELLS (at least 4 bricks): ~32^2 of
#: them across a surface, whatever the resolution
PLAN_CELLS = 32


@dataclass
class PartTask:
    """One part of a plan: a cube of the octree and the plan's cells inside it.

    Attributes:
        cell: ``(3,)`` int64, the cube's lower sample index.
        size: its edge in voxels (``BRICK`` times a power of two).
        cells: ``(k, 3)`` int64, the lower sample indices of the octree's cells of edge
            ``level`` inside the cube that may hold surface, sorted by x, y, z.
        level: their edge in voxels (at most ``size``).
    """

    cell: np.ndarray
    size: int
    cells: np.ndarray
    level: int

    @property
    def weight(self) -> int:
        """The work it holds, in plan cells."""
        return len(self.cells)


@dataclass
class Part:
    """The mesh of one cube, each vertex as its grid edge and its place along it.

    Attributes:
        grid: the whole grid.
        cell: ``(3,)`` int64, the cube's lower sample index; size: its edge (voxels).
        edges: ``(V,)`` uint32 (int64 for cubes over 512 voxels), each vertex's edge
            numbered inside the cube (:mod:`.part_kernels`); the vertices on the cube's
            faces (:meth:`shared`) may be held by a neighbouring part too.
        t: ``(V,)`` float64 in ``[0, 1]``, each vertex's parameter along its edge.
        faces: ``(F, 3)`` int32, indices into the part's vertices, counter-clockwise
            seen from outside; or, with ``escapes``, their uint16 codes
            (:meth:`encoded`).
        escapes: None, or ``(E,)`` int32, the indices the codes do not hold
            (:func:`csdf.mesh.part_kernels.encode_faces`).
    """

    grid: Grid
    cell: np.ndarray
    size: int
    edges: np.ndarray
    t: np.ndarray
    faces: np.ndarray
    escapes: np.ndarray | None = None

    def encoded(self) -> Part:
        """This part with its faces as 2-byte codes (:func:`~csdf.mesh.part_kernels.
        encode_faces`): what a task sends back, 6 bytes a face instead of 12."""
        if self.escapes is not None:
            return self
        codes, escapes = PK.encode_faces(self.faces)
        return replace(self, faces=codes, escapes=escapes)

    def face_indices(self) -> np.ndarray:
        """The faces ``(F, 3)`` int32 as vertex indices (decoded if they are codes)."""
        if self.escapes is None:
            return self.faces
        out = np.empty(self.faces.shape, dtype=np.int32)
        PK.decode_faces(self.faces, self.escapes, out)
        return out

    def shared(self) -> np.ndarray:
        """Bool ``(V,)``: the vertices on the cube's faces."""
        return PK.on_cube_faces(self.edges, self.size)

    def keys(self, mask: np.ndarray | None = None) -> np.ndarray:
        """Grid-wide edge numbers ``(V,)`` int64 of the vertices (those of ``mask`` only)
        (:func:`csdf.mesh.stream.edge_key`)."""
        mask = np.ones(len(self.edges), dtype=bool) if mask is None else mask
        return PK.global_keys(self.edges, self.cell, self.size, _dims(self.grid), mask)

    def vertices(self) -> np.ndarray:
        """Positions ``(V, 3)`` float64 (model units), as the whole-grid mesher makes
        them."""
        out = np.empty((len(self.edges), 3))
        PK.edge_points(self.edges, self.t, self.cell, self.size,
                       np.asarray(self.grid.origin, dtype=np.float64), float(self.grid.h),
                       out)
        return out


def _dims(grid: Grid) -> np.ndarray:
    return np.asarray(grid.dims, dtype=np.int64)


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


def plan_level(grid: Grid) -> int:
    """The edge (voxels) of the plan's cells: the root cube's edge / :data:`PLAN_CELLS`,
    at least ``4 BRICK``."""
    return max(4 * BRICK, top_size(grid) // PLAN_CELLS)


def plan_parts(fld: Field, grid: Grid, super_brick: int | None = None,
               max_tasks: int | None = None, task_surface: int = 0,
               min_tasks: int = 1) -> list[PartTask]:
    """The parts to mesh, the fullest first.

    Args:
        fld: the field (prepared for ``grid``: :func:`csdf.mesh.api.prepare_field`).
        grid: the sampling grid.
        super_brick: every part a cube of this edge in voxels (a power of two, at least
            ``BRICK``). Default: cubes of the octree of any size down to
            :func:`plan_level`, the fullest split first (into its 8 children that may
            hold surface) while there are at most ``max_tasks``.
        max_tasks: see ``super_brick``; default :func:`default_max_tasks`.
        task_surface, min_tasks: without ``super_brick``, at most one part per
            ``task_surface`` voxels of surface (estimated as the plan cells' count times
            their face area, ``level^2``: a voxel of surface is about 2 triangles), but
            at least ``min_tasks`` (0: no such bound): a small mesh is not cut into
            more parts than its work is worth.

    Returns:
        :class:`PartTask` s, by decreasing weight (then by x, y, z), so that a pool of
        workers given them in order finishes them at about the same time.

    Raises:
        CsdfError: a ``super_brick`` or ``max_tasks`` that is not a positive integer of
            the kind above.
    """
    top = top_size(grid)
    level = plan_level(grid)
    if super_brick is not None:
        size = _super_brick(super_brick, top)
        level = min(level, size)
        cells = _sorted(octree(grid, fld.intervals, None, stop=level))
        cubes = (cells // size) * size
        # (cells sorted by x, y, z are not grouped by cube: sorted by cube, then cell)
        order = np.lexsort((cells[:, 2], cells[:, 1], cells[:, 0], cubes[:, 2], cubes[:, 1],
                            cubes[:, 0]))
        cells, cubes = cells[order], cubes[order]
        first = np.ones(len(cubes), dtype=bool)
        first[1:] = np.any(cubes[1:] != cubes[:-1], axis=1)
        starts = np.flatnonzero(first)
        groups = np.split(cells, starts[1:]) if len(cells) else []
        tasks = [PartTask(cubes[s].copy(), size, g, level) for s, g in zip(starts, groups)]
    else:
        if max_tasks is None:
            max_tasks = default_max_tasks(grid)
        if isinstance(max_tasks, bool) or not isinstance(max_tasks, (int, np.integer)) \
                or max_tasks < 1:
            raise CsdfError(f"max_tasks must be a positive integer, got {max_tasks!r}")
        cells = _sorted(octree(grid, fld.intervals, None, stop=level))
        worth = -(-len(cells) * level**2 // int(task_surface)) if task_surface > 0 \
            else int(max_tasks)
        tasks = _split_fullest(cells, top, level, int(max_tasks), worth, int(min_tasks))
    tasks.sort(key=lambda p: (-p.weight, *p.cell.tolist()))
    return tasks


def _sorted(cells: np.ndarray) -> np.ndarray:
    """Cells ``(K, 3)`` sorted by x, y, z."""
    return cells[np.lexsort((cells[:, 2], cells[:, 1], cells[:, 0]))]


def _split_fullest(cells: np.ndarray, top: int, level: int, max_tasks: int,
                   worth: int | None = None, min_tasks: int = 1) -> list[PartTask]:
    """Cubes holding ``cells (K, 3)`` (edge ``level``): from the root cube (edge ``top``),
    the fullest cube split into its children that hold cells, as long as the count
    stays at most ``worth`` (default ``max_tasks``), or at most ``max_tasks`` while it
    is below ``min_tasks`` (a cube whose split would pass them, or of edge ``level``,
    is kept whole and the next fullest tried)."""
    worth = max_tasks if worth is None else min(worth, max_tasks)
    if not len(cells):
        return []
    root = PartTask(np.zeros(3, dtype=np.int64), top, cells, level)
    heap = [(_priority(root), 0, root)]
    done: list[PartTask] = []
    count = 1  # (a tie-breaker for the heap)
    while heap:
        cube = heapq.heappop(heap)[2]
        children = _children(cube) if cube.size > level else []
        now = len(done) + len(heap) + 1
        after = now - 1 + len(children)
        if not children or after > max_tasks or (after > worth and now >= min_tasks):
            done.append(cube)
            continue
        for c in children:
            heapq.heappush(heap, (_priority(c), count, c))
            count += 1
    return done


def _priority(cube: PartTask) -> int:
    """Heap order of :func:`_split_fullest`: the fullest first."""
    return -cube.weight


def _children(cube: PartTask) -> list[PartTask]:
    """The subcubes of ``cube`` that hold some of its cells (each keeps them sorted)."""
    half = cube.size // 2
    octant = ((cube.cells - cube.cell) // half) @ np.array([4, 2, 1])
    out = []
    for o in range(8):
        sel = cube.cells[octant == o]
        if len(sel):
            corner = cube.cell + half * np.array([(o >> 2) & 1, (o >> 1) & 1, o & 1])
            out.append(PartTask(corner, half, sel, cube.level))
    return out


def mesh_part(fld: Field, grid: Grid, task: PartTask) -> Part:
    """Marching cubes of one part of :func:`plan_parts`, on the whole grid's samples:
    the bricks below the task's cells (the octree goes on from them), meshed as
    :func:`csdf.mesh` meshes them, each vertex kept as its edge inside the cube and its
    ``t`` (a third of the bytes of a position), the faces as int32."""
    cell = np.asarray(task.cell, dtype=np.int64).reshape(3)
    size = int(task.size)
    bits, dtype = PK.edge_bits(size), PK.edge_dtype(size)

    def number(corner: np.ndarray, axis: np.ndarray, dims: np.ndarray) -> np.ndarray:
        out = np.empty(len(axis), dtype=dtype)
        PK.pack_edges(corner, axis, cell, bits, out)
        return out

    bricks = _sorted(octree(grid, fld.intervals, None,
                            start=(np.asarray(task.cells, dtype=np.int64), task.level)))
    t, faces, edges = extract_mc(grid, fld.value, fld.intervals, None,
                                 serial=fld.serial_values(), bricks=bricks,
                                 edge_keys=number, edge_t=True, face_dtype=np.int32)
    return Part(grid, cell, size, np.asarray(edges, dtype=dtype), np.ascontiguousarray(t),
                np.ascontiguousarray(faces))


class Stitcher:
    """Parts put together as they arrive, into one mesh (in any order of parts; the
    result is the same mesh up to order).

    Each vertex is numbered as it comes and written once (its position rebuilt from
    its edge and ``t``); a vertex on a cube's faces is looked up by its grid edge in a
    hash map of those (a few per cent of a large mesh), so a neighbour's copy is not
    repeated. One pass over each part's vertices and faces, in compiled code, into
    arrays that grow by doubling (their unused pages cost address space only).

    Args:
        grid: the whole grid.
        vertices, faces: the expected counts, to size the outputs (0: grown as needed).
    """

    def __init__(self, grid: Grid, vertices: int = 0, faces: int = 0) -> None:
        self.grid = grid
        self._dims = _dims(grid)
        self._origin = np.asarray(grid.origin, dtype=np.float64)
        self._verts = fresh_array((max(vertices, 1024), 3), np.float64)
        self._faces = fresh_array((max(faces, 1024), 3), np.int64)
        self._table = PK.new_table(1024)
        self._used = 0
        self.vertices = 0  # rows used
        self.faces = 0

    def add(self, part: Part) -> None:
        """Take one part."""
        self._verts = _room(self._verts, self.vertices, len(part.edges))
        self._faces = _room(self._faces, self.faces, len(part.faces))
        self._table, self._used, self.vertices, self.faces = PK.place_part(
            part.edges, part.t, part.faces, part.escapes, np.asarray(part.cell, dtype=np.int64),
            int(part.size), self._dims, self._origin, float(self.grid.h), self._table,
            self._used, self._verts, self.vertices, self._faces, self.faces)

    def result(self) -> tuple[np.ndarray, np.ndarray]:
        """The mesh ``(vertices (V, 3) float64, faces (F, 3) int64)`` (views of the
        outputs)."""
        return self._verts[:self.vertices], self._faces[:self.faces]


def _room(a: np.ndarray, used: int, more: int) -> np.ndarray:
    """``a`` with room for ``more`` rows after the first ``used`` (doubled, into fresh
    memory, when it has not)."""
    if used + more <= len(a):
        return a
    grown = fresh_array((max(used + more, 2 * len(a)),) + a.shape[1:], a.dtype)
    grown[:used] = a[:used]
    return grown


class SharedVertices:
    """The vertices that parts share, numbered once each: what a file of the whole
    mesh needs of them when the parts' own vertices are written by their workers.

    :meth:`add` takes one part's shared copies ``(keys, t)`` and gives their numbers
    (``0 .. count - 1``: a copy of an edge seen before gets that edge's number);
    :meth:`vertices` gives their positions in number order.

    Args:
        grid: the whole grid.
    """

    def __init__(self, grid: Grid) -> None:
        self.grid = grid
        self._table = PK.new_table(1024)
        self._used = 0
        self.count = 0
        self._keys: list[np.ndarray] = []
        self._t: list[np.ndarray] = []

    def add(self, keys: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Numbers ``(M,)`` int64 of shared copies ``keys (M,)`` int64 (grid-wide edges),
        ``t (M,)``."""
        keys = np.asarray(keys, dtype=np.int64)
        ids = np.empty(len(keys), dtype=np.int64)
        self._table, self._used, self.count, new = PK.merge_keys(
            keys, _dims(self.grid), self._table, self._used, self.count, ids)
        self._keys.append(keys[new])
        self._t.append(np.asarray(t, dtype=np.float64)[new])
        return ids

    def vertices(self) -> np.ndarray:
        """Positions ``(count, 3)`` float64 of the shared vertices, in number order."""
        out = np.empty((self.count, 3))
        if self.count:
            PK.key_points(np.concatenate(self._keys), np.concatenate(self._t),
                          _dims(self.grid), np.asarray(self.grid.origin, dtype=np.float64),
                          float(self.grid.h), out)
        return out


def stitch(parts: list[Part]) -> tuple[np.ndarray, np.ndarray]:
    """One mesh ``(vertices (V, 3), faces (F, 3) int64)`` of several parts of one grid
    (:class:`Stitcher`)."""
    if not parts:
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
    st = Stitcher(parts[0].grid, sum(len(p.edges) for p in parts),
                  sum(len(p.faces) for p in parts))
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
