"""Points grouped by the cell they fall in: one compiled counting sort, shared by the
pruned evaluator (points by octree cell) and detection's neighbour grid."""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["group_by_cell"]


@njit(nogil=True, cache=True, boundscheck=False, error_model="numpy")
def group_by_cell(cell: np.ndarray, n_cells: int) -> tuple[np.ndarray, np.ndarray]:
    """Counting sort of the cell indices ``cell`` ``(N,)`` (each in ``[0, n_cells)``):
    ``(order (N,), bounds (n_cells + 1,))`` with the points of cell ``c`` at
    ``order[bounds[c]:bounds[c+1]]``, in index order within a cell (what
    ``np.argsort(cell, kind='stable')`` gives)."""
    counts = np.zeros(n_cells + 1, dtype=np.int64)
    for i in range(cell.shape[0]):
        counts[cell[i] + 1] += 1
    for c in range(n_cells):
        counts[c + 1] += counts[c]
    pos = counts[:-1].copy()
    order = np.empty(cell.shape[0], dtype=np.int64)
    for i in range(cell.shape[0]):
        c = cell[i]
        order[pos[c]] = i
        pos[c] += 1
    return order, counts
