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
bounds it on a ball of radius ``r`` about ``c`` (:meth:`MeshDistance.interval`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..bvh import build_bvh
from ..errors import CsdfError

__all__ = ["MeshDistance", "LEAF_SIZE", "MAX_TRIANGLES"]

#: triangles per leaf of the hierarchy
LEAF_SIZE = 4
#: the most triangles a mesh may have
MAX_TRIANGLES = 5_000_000


class MeshDistance:
    """The exact signed distance field of a closed triangle mesh.

    Args:
        vertices: ``(Nv, 3)`` vertex positions (a :class:`trimesh.Trimesh` may be given
            instead, with ``faces`` None).
        faces: ``(Nt, 3)`` vertex indices of the triangles (either orientation, but the
            same for all: the mesh is turned outwards when its volume is negative).

    Attributes:
        vertices, faces: the mesh as used (faces oriented outwards).
        bounds: ``(2, 3)`` the mesh's box.
        volume: the enclosed volume.

    Raises:
        CsdfError: not ``(N, 3)`` arrays, non-finite vertices, indices out of range,
            more than :data:`MAX_TRIANGLES` triangles, or a mesh that is not closed or
            not consistently oriented (naming an offending edge).
    """

    def __init__(self, vertices: Any, faces: Any = None):
        if faces is None and hasattr(vertices, "vertices") and hasattr(vertices, "faces"):
            vertices, faces = vertices.vertices, vertices.faces
        V = np.ascontiguousarray(np.asarray(vertices, dtype=np.float64))
        try:
            T = np.asarray(faces)
        except (TypeError, ValueError):
            raise CsdfError("faces must be an (N, 3) array of vertex indices") from None
        if V.ndim != 2 or V.shape[1] != 3 or len(V) < 4:
            raise CsdfError(f"vertices must be an (N, 3) array of at least 4 points, got "
                            f"shape {V.shape}")
        if not np.all(np.isfinite(V)):
            raise CsdfError("vertices must be finite")
        if T.ndim != 2 or T.shape[1] != 3 or len(T) < 4 or not np.issubdtype(
                T.dtype, np.integer):
            raise CsdfError(f"faces must be an (N, 3) integer array of at least 4 "
                            f"triangles, got shape {T.shape} of {T.dtype}")
        if len(T) > MAX_TRIANGLES:
            raise CsdfError(f"the mesh has {len(T)} triangles; the limit is {MAX_TRIANGLES}")
        T = np.ascontiguousarray(T, dtype=np.int64)
        if T.min() < 0 or T.max() >= len(V):
            raise CsdfError(f"faces hold vertex indices outside 0..{len(V) - 1}")
        tri_edge = _check_closed(T)
        a, b, c = V[T[:, 0]], V[T[:, 1]], V[T[:, 2]]
        vol = float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)
        if vol < 0:  # turned inwards: flip every triangle (v0 v1 v2 -> v0 v2 v1)
            T = np.ascontiguousarray(T[:, [0, 2, 1]])
            tri_edge = np.ascontiguousarray(tri_edge[:, [2, 1, 0]])
            b, c = c, b
            vol = -vol
        self.vertices, self.faces, self.volume = V, T, vol
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
        self._data = (V, T, order, node_f, node_i, np.ascontiguousarray(fn), en,
                      np.ascontiguousarray(tri_edge), vn)
        self.bounds = np.array([V.min(axis=0), V.max(axis=0)])

    def __repr__(self) -> str:
        return f"MeshDistance({len(self.faces)} triangles, volume {self.volume:g})"

    def _run(self, points, want_grad: bool, want_closest: bool):
        from .mesh_kernels import signed_distance

        P = np.asarray(points, dtype=np.float64)
        if P.ndim != 2 or P.shape[1] != 3:
            raise CsdfError(f"points must be an (N, 3) array, got shape {P.shape}")
        if not np.all(np.isfinite(P)):
            raise CsdfError("points must be finite")
        P = np.ascontiguousarray(P)
        n = len(P)
        out = np.empty(n)
        grad = np.empty((n if want_grad else 0, 3))
        near = np.empty((n if want_closest else 0, 3))
        signed_distance(P, *self._data, out, grad, near, want_grad, want_closest)
        return out, grad, near

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

    def interval(self, lo, hi) -> tuple[float, float]:
        """Bounds of the signed distance over the box ``[lo, hi]`` (``(3,)`` each): the
        value at its centre plus or minus its half diagonal (the field is 1-Lipschitz)."""
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        c = 0.5 * (lo + hi)
        r = 0.5 * float(np.linalg.norm(hi - lo))
        v = float(self.value(c[None])[0])
        return v - r, v + r


def _check_closed(T: np.ndarray) -> np.ndarray:
    """``(Nt, 3)`` the undirected edge id of each triangle's edges ``v0v1, v1v2, v2v0``;
    raises unless every edge joins exactly two triangles, once in each direction."""
    d = T[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)  # directed edges, 3 per triangle
    und = np.sort(d, axis=1)
    keys, inv, counts = np.unique(und, axis=0, return_inverse=True, return_counts=True)
    bad = np.flatnonzero(counts != 2)
    if len(bad):
        e = keys[bad[0]]
        raise CsdfError(f"the mesh is not closed: edge ({e[0]}, {e[1]}) belongs to "
                        f"{counts[bad[0]]} triangle(s), not 2 ({len(bad)} such edges)")
    forward = d[:, 0] < d[:, 1]
    nfwd = np.bincount(inv.reshape(-1), weights=forward, minlength=len(keys))
    wrong = np.flatnonzero(nfwd != 1)
    if len(wrong):
        e = keys[wrong[0]]
        raise CsdfError(f"the mesh is not consistently oriented: both triangles at edge "
                        f"({e[0]}, {e[1]}) run it the same way ({len(wrong)} such edges)")
    return inv.reshape(-1, 3).astype(np.int64)
