"""The nearest of a sensor's rays to a direction: which scan point lies on the ray
through a model's surface sample (is that sample seen, hidden, or seen through?).

A scan from one viewpoint is a bundle of rays within a cone. :class:`RayIndex` grids
their gnomonic projection about the cone's axis (straight lines stay straight; lengths
stretch by at most ``sec^2`` of the angle from the axis), so a query reads only the few
cells that can hold a ray within the tolerance, in compiled code
(:func:`.kernels.ray_nearest`). It answers what a :class:`scipy.spatial.cKDTree` of the
unit directions answers with ``k=1`` and ``distance_upper_bound=tol`` (the nearest ray
by chord distance, strictly within ``tol``; of equally near rays, the lowest index), at
a fraction of the time: detection asks for about half a million directions a scene.
Bundles wider than :data:`MAX_ANGLE` about their mean direction (a panorama), or finer
than :data:`MAX_CELLS` cells, fall back to the KD-tree.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..cellsort import group_by_cell
from .kernels import ray_nearest, ray_nearest_point

__all__ = ["RayIndex", "MAX_ANGLE", "MAX_CELLS"]

#: the widest bundle gridded: every ray and tolerance within this angle (radians) of
#: the axis (beyond it the projection stretches lengths more than ~33 times)
MAX_ANGLE = math.radians(80.0)
#: the most grid cells (beyond: the KD-tree)
MAX_CELLS = 1 << 22


class RayIndex:
    """The unit ray directions ``dirs`` ``(N, 3)`` of a scan, for nearest-ray queries
    within the chord distance ``tol`` (radians, about an angle). ``tree``: a
    :class:`scipy.spatial.cKDTree` of ``dirs`` the caller already has, for the
    fallback (else one is built when needed)."""

    def __init__(self, dirs: np.ndarray, tol: float, tree: Any = None):
        self.dirs = np.ascontiguousarray(dirs, dtype=np.float64)
        self.tol = float(tol)
        self._tree = tree
        self._grid: tuple | None = None
        n = len(self.dirs)
        mean = self.dirs.sum(axis=0) if n else np.zeros(3)
        norm = float(np.linalg.norm(mean))
        if n == 0 or norm <= 1e-9 * n or not math.isfinite(self.tol) or self.tol <= 0.0:
            self._fallback()
            return
        c = mean / norm
        a = 2.0 * math.asin(min(1.0, 0.5 * self.tol))
        cq = self.dirs @ c
        widest = math.acos(max(-1.0, min(1.0, float(cq.min()))))
        if widest + 2.0 * a + 1e-6 >= MAX_ANGLE:
            self._fallback()
            return
        # an orthonormal frame (e0, e1, c)
        e0 = np.cross(c, np.eye(3)[int(np.argmin(np.abs(c)))])
        e0 /= np.linalg.norm(e0)
        e1 = np.cross(c, e0)
        G = np.ascontiguousarray(np.stack([(self.dirs @ e0) / cq, (self.dirs @ e1) / cq],
                                          axis=1))
        h = a  # a cell as wide as the search square at the axis
        lo = G.min(axis=0) - h
        n0, n1 = (int(k) for k in np.floor((G.max(axis=0) + h - lo) / h) + 1)
        if n0 * n1 > MAX_CELLS:
            self._fallback()
            return
        # each ray's cell, as the queries compute it (row-major), grouped by cell
        cell = (np.clip(np.floor((G[:, 0] - lo[0]) / h).astype(np.int64), 0, n0 - 1) * n1
                + np.clip(np.floor((G[:, 1] - lo[1]) / h).astype(np.int64), 0, n1 - 1))
        order, start = group_by_cell(cell, n0 * n1)
        # queries farther from the axis than the widest ray and an arc of the
        # tolerance are within it of no ray (a little more is read: it is checked)
        cos_far = math.cos(widest + a + 1e-6)
        self._grid = (order, start, c, e0, e1, float(lo[0]), float(lo[1]), h, n0, n1,
                      cos_far)
        self._widest = widest

    def _fallback(self) -> None:
        if self._tree is None:
            from scipy.spatial import cKDTree

            self._tree = cKDTree(self.dirs)

    @property
    def gridded(self) -> bool:
        """True when queries use the grid (False: the KD-tree fallback)."""
        return self._grid is not None

    def nearest(self, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For unit directions ``Q`` ``(M, 3)``: ``(chord distance (M,), ray index
        (M,))`` of the nearest ray strictly within ``tol``; ``inf`` and ``N`` (the
        number of rays) where there is none, as :meth:`scipy.spatial.cKDTree.query`
        gives them."""
        Q = np.ascontiguousarray(Q, dtype=np.float64).reshape(-1, 3)
        if self._grid is None:
            return self._tree.query(Q, k=1, distance_upper_bound=self.tol)
        order, start, c, e0, e1, lo0, lo1, h, n0, n1, cos_far = self._grid
        j, d2 = ray_nearest(Q, self.dirs, order, start, c, e0, e1, lo0, lo1, h, n0, n1,
                            self.tol, cos_far)
        none = j < 0
        j[none] = len(self.dirs)
        return np.sqrt(d2), j

    def nearest_point(self, X: np.ndarray, P: np.ndarray, origin: np.ndarray,
                      radius: float, tree) -> tuple[np.ndarray, np.ndarray]:
        """For points ``X`` ``(M, 3)``: ``(distance (M,), index (M,))`` of the nearest
        of the scan points ``P`` ``(N, 3)`` (whose rays from ``origin`` ``(3,)`` these
        are) strictly within ``radius`` (scene units), ``inf`` and ``N`` where there is
        none: what ``tree.query(X, k=1, distance_upper_bound=radius)`` gives
        (``tree``, a :class:`scipy.spatial.cKDTree` of ``P``, answers the points this
        grid cannot: all of them when it is not :attr:`gridded`, and those within
        ``radius`` of the origin or whose rays leave the gridded cone)."""
        X = np.ascontiguousarray(X, dtype=np.float64).reshape(-1, 3)
        if self._grid is None:
            return tree.query(X, k=1, distance_upper_bound=radius)
        order, start, c, e0, e1, lo0, lo1, h, n0, n1, _ = self._grid
        j, d2 = ray_nearest_point(X, np.asarray(origin, dtype=np.float64), P, order, start,
                                  c, e0, e1, lo0, lo1, h, n0, n1, float(radius),
                                  self._widest, MAX_ANGLE)
        d = np.sqrt(d2)
        ask = np.flatnonzero(j == -2)
        if len(ask):
            d[ask], j[ask] = tree.query(X[ask], k=1, distance_upper_bound=radius)
        j[j < 0] = len(P)
        return d, j
