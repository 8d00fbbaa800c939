"""Bounding volume hierarchies over boxes: :func:`build_bvh`, shared by the scene's
instance tree (:mod:`csdf.fieldset`) and the triangle tree of mesh distances
(:mod:`csdf.backends.meshdist`)."""

from __future__ import annotations

import numpy as np

from .errors import CsdfError

__all__ = ["build_bvh"]


def build_bvh(lo: np.ndarray, hi: np.ndarray, leaf_size: int = 2
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A bounding volume hierarchy over boxes ``[lo[k], hi[k]]`` (``(K, 3)`` each): split
    at the median of the box centres along the longest axis of their spread, down to
    ``leaf_size`` boxes per leaf (balanced, depth ``~log2(K / leaf_size) + 1``).

    Returns:
        ``(node_f (M, 6) [lo, hi], node_i (M, 2), order (K,))``: node 0 is the root;
        an inner node's ``node_i`` row holds its children, a leaf's ``(-1 - first,
        count)`` of the boxes ``order[first:first + count]``.
    """
    K = len(lo)
    if K == 0:
        raise CsdfError("a bounding volume hierarchy needs at least one box")
    centre = 0.5 * (lo + hi)
    order = np.arange(K)
    node_f: list[np.ndarray] = []
    node_i: list[list[int]] = []
    stack = [(0, K, -1, 0)]  # (first, end, parent, which child)
    while stack:
        a, b, parent, side = stack.pop()
        idx = order[a:b]
        me = len(node_f)
        node_f.append(np.concatenate([lo[idx].min(axis=0), hi[idx].max(axis=0)]))
        node_i.append([-1 - a, b - a])
        if parent >= 0:
            node_i[parent][side] = me
        if b - a <= leaf_size:
            continue
        c = centre[idx]
        ax = int(np.argmax(c.max(axis=0) - c.min(axis=0)))
        mid = (b - a) // 2
        part = np.argpartition(c[:, ax], mid)
        order[a:b] = idx[part]
        stack.append((a + mid, b, me, 1))
        stack.append((a, a + mid, me, 0))
    return (np.array(node_f, dtype=np.float64).reshape(-1, 6),
            np.array(node_i, dtype=np.int64).reshape(-1, 2), order.astype(np.int64))
