"""A closed triangle mesh as a data block of a program: :class:`MeshData`.

``csdf.from_mesh`` / ``polyhedron`` shapes hold one: the checked mesh (closed and
consistently oriented, turned outwards), with a content digest that names it in
expression keys and bytecode. The distance queries themselves (a bounding volume
hierarchy, Numba kernels) are :class:`csdf.backends.meshdist.MeshDistance`, built from
this once per process and mesh.

The checks are here, at the bottom layer, so that a shape is refused when it is made,
not when it is first evaluated.
"""

from __future__ import annotations

import hashlib
from typing import Any

import numpy as np

from .errors import CsdfError

__all__ = ["MeshData", "MAX_TRIANGLES", "check_closed"]

#: the most triangles a mesh may have
MAX_TRIANGLES = 5_000_000


class MeshData:
    """A closed, consistently oriented triangle mesh, checked and turned outwards.

    Args:
        vertices: ``(Nv, 3)`` vertex positions (model units); a
            :class:`trimesh.Trimesh` (or anything with ``.vertices`` and ``.faces``)
            may be given instead, with ``faces`` None.
        faces: ``(Nt, 3)`` vertex indices of the triangles, all in one orientation
            (the mesh is turned outwards when its volume is negative).

    Attributes:
        vertices: ``(Nv, 3)`` float64, read-only.
        faces: ``(Nt, 3)`` int64, read-only, oriented outwards.
        tri_edge: ``(Nt, 3)`` int64 undirected edge id of each triangle's edges
            ``v0v1, v1v2, v2v0``.
        volume: the enclosed volume (model units cubed).
        bounds: ``(2, 3)`` the mesh's box.
        digest: 16 hex digits naming the content (vertices and oriented faces).

    Two ``MeshData`` are equal when their content is; they pickle as their arrays.

    Raises:
        CsdfError: not ``(N, 3)`` arrays, non-finite vertices, indices out of range,
            more than :data:`MAX_TRIANGLES` triangles, or a mesh that is not closed or
            not consistently oriented (naming an offending edge).
    """

    __slots__ = ("vertices", "faces", "tri_edge", "volume", "bounds", "digest",
                 "__weakref__")

    def __init__(self, vertices: Any, faces: Any = None):
        if faces is None and hasattr(vertices, "vertices") and hasattr(vertices, "faces"):
            vertices, faces = vertices.vertices, vertices.faces
        try:
            V = np.ascontiguousarray(np.asarray(vertices, dtype=np.float64))
        except (TypeError, ValueError):
            raise CsdfError("vertices must be an (N, 3) array of numbers") from None
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
        tri_edge = check_closed(T)
        a, b, c = V[T[:, 0]], V[T[:, 1]], V[T[:, 2]]
        vol = float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)
        if vol < 0:  # turned inwards: flip every triangle (v0 v1 v2 -> v0 v2 v1)
            T = np.ascontiguousarray(T[:, [0, 2, 1]])
            tri_edge = np.ascontiguousarray(tri_edge[:, [2, 1, 0]])
            vol = -vol
        if not vol > 0:
            raise CsdfError("the mesh encloses no volume")
        for arr in (V, T, tri_edge):
            arr.setflags(write=False)
        self.vertices, self.faces, self.tri_edge, self.volume = V, T, tri_edge, vol
        self.bounds = np.array([V.min(axis=0), V.max(axis=0)])
        self.bounds.setflags(write=False)
        h = hashlib.blake2b(digest_size=8)
        h.update(np.asarray(V.shape, "<i8").tobytes() + V.astype("<f8").tobytes())
        h.update(T.astype("<i8").tobytes())
        self.digest = h.hexdigest()

    def __repr__(self) -> str:
        return (f"MeshData({len(self.vertices)} vertices, {len(self.faces)} triangles, "
                f"volume {self.volume:g}, {self.digest})")

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, MeshData):
            return NotImplemented
        return self.digest == other.digest and np.array_equal(
            self.vertices, other.vertices) and np.array_equal(self.faces, other.faces)

    def __hash__(self) -> int:
        return hash(self.digest)

    def __reduce__(self):
        return (MeshData, (np.array(self.vertices), np.array(self.faces)))

    @property
    def nbytes(self) -> int:
        """Size of the block in bytecode: ``24`` bytes a vertex, ``12`` a triangle."""
        return 24 * len(self.vertices) + 12 * len(self.faces)


def check_closed(T: np.ndarray) -> np.ndarray:
    """``(Nt, 3)`` the undirected edge id of each triangle's edges ``v0v1, v1v2, v2v0``.

    Raises:
        CsdfError: unless every edge joins exactly two triangles, once in each
            direction (closed and consistently oriented), naming an offending edge.
    """
    d = T[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)  # directed edges, 3 per triangle
    if np.any(d[:, 0] == d[:, 1]):
        k = int(np.flatnonzero(d[:, 0] == d[:, 1])[0]) // 3
        raise CsdfError(f"triangle {k} repeats a vertex (a degenerate face)")
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
    return np.ascontiguousarray(inv.reshape(-1, 3).astype(np.int64))
