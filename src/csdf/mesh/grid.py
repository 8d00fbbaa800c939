"""The voxel grid both meshers work on, and the octree that prunes it.

Grid: ``dims = (nx, ny, nz)`` voxels of edge ``h`` from ``origin``; sample ``(i, j, k)``
is the point ``origin + h * (i, j, k)``.

Octree: cubic cells of ``BRICK * 2^L`` voxels are tested with interval arithmetic over
their boxes; a cell whose interval excludes 0 holds no surface and is dropped (intervals
are conservative, so this is safe for fields that are not distances: twist, bend,
non-uniform scale). Survivors split until they are bricks of ``BRICK^3`` voxels. Cells
touching the grid box are kept while their interval reaches below 0, since the surface
is closed on the box.

Used by the NumPy reference mesher (:mod:`.reference`) and the compiled streaming mesher
(:mod:`.stream`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .cases import CORNERS

__all__ = ["Grid", "octree", "top_size", "BRICK"]

#: edge of an octree leaf (a brick), in voxels
BRICK = 8


@dataclass(frozen=True)
class Grid:
    """A voxel grid: ``dims`` voxels of edge ``h`` starting at ``origin`` (model units)."""

    origin: np.ndarray  # (3,)
    h: float
    dims: tuple[int, int, int]

    def points(self, ijk: np.ndarray) -> np.ndarray:
        """Sample coordinates ``(M, 3)`` of integer sample indices ``ijk (M, 3)``."""
        return self.origin + ijk * self.h


def octree(grid: Grid, intervals: Callable, progress: Callable | None,
           inside: list[float] | None = None, *, stop: int = BRICK,
           start: tuple[np.ndarray, int] | None = None) -> np.ndarray:
    """Lower corners ``(K, 3)`` (sample indices) of the bricks that may hold surface.

    ``intervals``: ``(lo (M, 3), hi (M, 3)) -> (flo (M,), fhi (M,))``, conservative
    bounds of the field over boxes; ``progress``: optional ``callback(size, kept)`` after
    each level (cell edge in voxels, cells kept); ``inside``: optional one-element list
    to which the volume (model units^3) of the cells dropped as wholly inside is
    added.

    ``stop``: the cell edge (voxels, ``BRICK`` times a power of two) at which to stop:
    the cells kept at that level are returned (:func:`cells_at`). ``start``: ``(cells
    (K, 3), size)``, cells kept at level ``size`` by an earlier call (with ``stop=size``),
    to go on from: their subcells are tested down to ``stop``. A cell is kept or dropped
    by its own box alone, so the bricks found below a super-cell are the bricks a whole
    descent finds there (what :mod:`csdf.mesh.parts` relies on)."""
    dims = np.array(grid.dims)
    if start is None:
        size = top_size(grid)
        cells = np.zeros((1, 3), dtype=np.int64)
    else:
        cells, size = np.asarray(start[0], dtype=np.int64).reshape(-1, 3), int(start[1])
        if size == stop or len(cells) == 0:
            return cells
        cells, size = _split(cells, size, dims)
    while True:
        lo_idx = cells
        hi_idx = np.minimum(cells + size, dims)
        lo, hi = intervals(grid.points(lo_idx), grid.points(hi_idx))
        touches = np.any(lo_idx == 0, axis=1) | np.any(hi_idx >= dims, axis=1)
        in_grid = np.all(lo_idx < dims, axis=1)
        keep = (lo <= 0) & ((hi >= 0) | touches) & in_grid
        if inside is not None:
            full = ~keep & (hi < 0) & in_grid
            inside[0] += float(np.prod(hi_idx[full] - lo_idx[full], axis=1).sum()) * grid.h**3
        cells = cells[keep]
        if progress:
            progress(size, len(cells))
        if size <= stop or len(cells) == 0:
            return cells
        cells, size = _split(cells, size, dims)


def top_size(grid: Grid) -> int:
    """The edge (voxels) of the octree's root cell: ``BRICK`` times the smallest power
    of two that covers the grid's longest side."""
    size = BRICK
    while size < max(grid.dims):
        size *= 2
    return size


def _split(cells: np.ndarray, size: int, dims: np.ndarray) -> tuple[np.ndarray, int]:
    """The 8 subcells of each cell (those starting inside the grid), and their edge."""
    size //= 2
    offs = CORNERS * size
    cells = (cells[:, None, :] + offs[None, :, :]).reshape(-1, 3)
    return cells[np.all(cells < dims, axis=1)], size
