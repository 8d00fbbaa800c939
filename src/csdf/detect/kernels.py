"""Compiled (Numba) core of detection: connected components of a masked neighbour graph
by union-find, visiting only the masked points' own edges."""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["component_roots"]


@njit(cache=True, nogil=True)
def _find(parent: np.ndarray, i: int) -> int:
    root = i
    while parent[root] != root:
        root = parent[root]
    while parent[i] != root:  # path compression
        nxt = parent[i]
        parent[i] = root
        i = nxt
    return root


@njit(cache=True, nogil=True)
def component_roots(sel: np.ndarray, nbr: np.ndarray, linked: np.ndarray,
                    mask: np.ndarray) -> np.ndarray:
    """For the masked points ``sel`` ``(M,)`` (indices where ``mask`` ``(N,)`` is
    true), the representative point of each one's connected component ``(M,)``, where
    ``i`` and ``j = nbr[i, c]`` are joined when ``linked[i, c]`` and both are masked
    (``nbr``, ``linked`` ``(N, k)``; the graph is taken as undirected). Equal
    representatives mean the same component."""
    n = mask.shape[0]
    parent = np.arange(n)
    k = nbr.shape[1]
    for a in range(sel.shape[0]):
        i = sel[a]
        for c in range(k):
            if not linked[i, c]:
                continue
            j = nbr[i, c]
            if not mask[j]:
                continue
            ri = _find(parent, i)
            rj = _find(parent, j)
            if ri != rj:
                if ri < rj:
                    parent[rj] = ri
                else:
                    parent[ri] = rj
    out = np.empty(sel.shape[0], dtype=np.int64)
    for a in range(sel.shape[0]):
        out[a] = _find(parent, sel[a])
    return out
