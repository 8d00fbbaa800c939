"""The exact signed distance to a closed triangle mesh: :class:`MeshDistance`.

A mesh is checked once (every edge shared by exactly two triangles, each direction of
it used once: closed and consistently oriented; turned outwards when its volume is
negative), its triangles indexed by a bounding volume hierarchy
(:func:`csdf.bvh.build_bvh`, :data:`LEAF_SIZE` triangles a leaf) and its sign data
precomputed: face normals, edge pseudonormals (the sum of the two unit face normals at
an edge) and angle-weighted vertex pseudonormals. Queries run the Numba kernels of
:mod:`csdf.backends.mesh_kernels` on all cores.

The distance is exact (the nearest point over all triangles, to rounding), the sign
exact for a closed oriented mesh (also inside thin and non-convex parts: it depends on
the nearest feature only), the gradient the unit vector from the nearest point (exact
wherever that point is unique), and the function is 1-Lipschitz, so ``value(c) +- r``
bounds it on a ball of radius ``r`` about ``c`` (:meth:`MeshDistance.intervals`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..bvh import build_bvh
from ..errors import CsdfError
from ..meshdata import MAX_TRIANGLES, MeshData

__all__ = ["MeshDistance", "LEAF_SIZE", "MAX_TRIANGLES", "for_data"]

#: triangles per leaf of the hierarchy
LEAF_SIZE = 4


class MeshDistance:
    """The exact signed distance field of a closed triangle mesh.

    Args:
        vertices: ``(Nv, 3)`` vertex positions, or a :class:`csdf.meshdata.MeshData`,
            or a :class:`trimesh.Trimesh` (``faces`` None for either).
        faces: ``(Nt, 3)`` vertex indices of the triangles (either orientation, but the
            same for all: the mesh is turned outwards when its volume is negative).

    Attributes:
        data: the checked mesh (:class:`csdf.meshdata.MeshData`).
        vertices, faces: the mesh as used (faces oriented outwards).
        bounds: ``(2, 3)`` the mesh's box.
        volume: the enclosed volume.

    Raises:
        CsdfError: the checks of :class:`csdf.meshdata.MeshData` (shapes, finite
            values, index range, size limit, closed and consistently oriented).
    """

    def __init__(self, vertices: Any, faces: Any = None):
        data = vertices if isinstance(vertices, MeshData) and faces is None else \
            MeshData(vertices, faces)
        self.data = data
        V, T, tri_edge = data.vertices, data.faces, data.tri_edge
        self.vertices, self.faces, self.volume = V, T, data.volume
        a, b, c = V[T[:, 0]], V[T[:, 1]], V[T[:, 2]]
        cr = np.cross(b - a, c - a)
        area2 = np.linalg.norm(cr, axis=1)
        fn = cr / np.maximum(area2, 1e-300)[:, None]
        en = np.zeros((int(tri_edge.max()) + 1, 3))
        np.add.at(en, tri_edge.reshape(-1), np.repeat(fn, 3, axis=0))
        vn = np.zeros_like(V)
        for k, (p, q, r) in enumerate(((a, b, c), (b, c, a), (c, a, b))):
            u, w = q - p, r - p
            cosang = np.einsum("ij,ij->i", u, w) / np.maximum(
                np.linalg.norm(u, axis=1) * np.linalg.norm(w, axis=1), 1e-300)
            np.add.at(vn, T[:, k], fn * np.arccos(np.clip(cosang, -1.0, 1.0))[:, None])
        lo = np.minimum(np.minimum(a, b), c)
        hi = np.maximum(np.maximum(a, b), c)
        node_f, node_i, order = build_bvh(lo, hi, LEAF_SIZE)
        self._data = (np.array(V), np.array(T), order, node_f, node_i,
                      np.ascontiguousarray(fn), en, np.array(tri_edge), vn)
        self.bounds = np.array(data.bounds)

    def __repr__(self) -> str:
        return f"MeshDistance({len(self.faces)} triangles, volume {self.volume:g})"

    def _query(self, P: np.ndarray, want_grad: bool, want_closest: bool):
        """``(values, gradients, nearest points)`` of finite, C-contiguous ``(N, 3)``
        float64 points (empty ``(0, 3)`` arrays for what is not wanted)."""
        from .mesh_kernels import signed_distance

        n = len(P)
        out = np.empty(n)
        grad = np.empty((n if want_grad else 0, 3))
        near = np.empty((n if want_closest else 0, 3))
        signed_distance(P, *self._data, out, grad, near, want_grad, want_closest)
        return out, grad, near

    def _run(self, points, want_grad: bool, want_closest: bool):
        P = np.asarray(points, dtype=np.float64)
        if P.ndim != 2 or P.shape[1] != 3:
            raise CsdfError(f"points must be an (N, 3) array, got shape {P.shape}")
        if not np.all(np.isfinite(P)):
            raise CsdfError("points must be finite")
        return self._query(np.ascontiguousarray(P), want_grad, want_closest)

    def field(self, p0: np.ndarray, p1: np.ndarray, p2: np.ndarray,
              want_grad: bool) -> tuple[np.ndarray, np.ndarray]:
        """The field as an op of a program: ``(values (N,), gradients (N, 3) or (0, 3))``
        float64 at the points ``(p0, p1, p2)`` (three ``(N,)`` arrays, any real dtype, or
        scalars broadcast to the others). A point with a NaN coordinate gives NaN, and
        NaN gradients; an infinite coordinate gives ``+inf`` with the gradient of the
        direction it runs off to (the mesh is bounded)."""
        P = np.empty((max(np.size(p0), np.size(p1), np.size(p2)), 3))
        P[:, 0], P[:, 1], P[:, 2] = p0, p1, p2
        ok = np.isfinite(P).all(axis=1)
        if ok.all():
            return self._query(P, want_grad, False)[:2]
        o, g, _ = self._query(np.ascontiguousarray(P[ok]), want_grad, False)
        nan = np.isnan(P).any(axis=1)
        far = ~ok & ~nan
        out = np.where(far, np.inf, np.nan)
        out[ok] = o
        grad = np.empty((len(P) if want_grad else 0, 3))
        if want_grad:
            grad[ok] = g
            with np.errstate(invalid="ignore"):
                d = np.where(np.isinf(P), np.sign(P), 0.0)[far]
                grad[far] = d / np.linalg.norm(d, axis=1, keepdims=True)
            grad[nan] = np.nan
        return out, grad

    def value(self, points) -> np.ndarray:
        """``(N,)`` signed distances of ``points`` ``(N, 3)`` (negative inside)."""
        return self._run(points, False, False)[0]

    def value_and_grad(self, points) -> tuple[np.ndarray, np.ndarray]:
        """``((N,), (N, 3))``: signed distances and unit gradients."""
        d, g, _ = self._run(points, True, False)
        return d, g

    def closest(self, points) -> tuple[np.ndarray, np.ndarray]:
        """``((N,), (N, 3))``: signed distances and the nearest mesh points."""
        d, _, c = self._run(points, False, True)
        return d, c

    def intervals(self, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Bounds ``((M,), (M,))`` of the signed distance over boxes ``[lo, hi]`` (``(M,
        3)`` each): the value at each box's centre plus or minus its half diagonal (the
        field is 1-Lipschitz), widened by rounding, then clipped below by the distance
        from the box to the mesh's box (no point outside that box is nearer) and by
        minus the mesh's half diagonal (no point is deeper). A box with an infinite
        side gets those two lower bounds and ``+inf``; one with a NaN bound is empty
        (NaN, NaN)."""
        lo3 = np.asarray(lo, dtype=np.float64).reshape(-1, 3)
        hi3 = np.asarray(hi, dtype=np.float64).reshape(-1, 3)
        mlo, mhi = self.bounds
        gap = np.maximum(np.maximum(mlo - hi3, lo3 - mhi), 0.0)
        apart = np.linalg.norm(gap, axis=1)  # > 0: the box misses the mesh's box
        deep = -0.5 * float(np.linalg.norm(mhi - mlo))
        out_lo = np.where(apart > 0, apart, deep)
        out_hi = np.full(len(lo3), np.inf)
        with np.errstate(invalid="ignore", over="ignore"):
            fin = np.isfinite(lo3).all(axis=1) & np.isfinite(hi3).all(axis=1)
        if fin.any():
            c = 0.5 * (lo3[fin] + hi3[fin])
            r = 0.5 * np.linalg.norm(hi3[fin] - lo3[fin], axis=1)
            v, _ = self.field(c[:, 0], c[:, 1], c[:, 2], False)
            slack = 1e-12 * (np.abs(v) + r + np.abs(c).max(axis=1)) + 1e-300
            out_lo[fin] = np.maximum(out_lo[fin], v - r - slack)
            out_hi[fin] = v + r + slack
        empty = np.isnan(lo3).any(axis=1) | np.isnan(hi3).any(axis=1)
        out_lo[empty] = np.nan
        out_hi[empty] = np.nan
        return out_lo, out_hi

    def interval(self, lo, hi) -> tuple[float, float]:
        """Bounds of the signed distance over the box ``[lo, hi]`` (``(3,)`` each), as
        :meth:`intervals` gives them."""
        out_lo, out_hi = self.intervals(lo, hi)
        return float(out_lo[0]), float(out_hi[0])

_BY_DIGEST: dict[str, MeshDistance] = {}


def for_data(data: MeshData) -> MeshDistance:
    """The :class:`MeshDistance` of a program's mesh block, built once per process and
    mesh (kept by content digest; the 16 most recent)."""
    md = _BY_DIGEST.get(data.digest)
    if md is None or md.data != data:
        if len(_BY_DIGEST) >= 16:
            _BY_DIGEST.pop(next(iter(_BY_DIGEST)))
        md = _BY_DIGEST[data.digest] = MeshDistance(data)
    return md
