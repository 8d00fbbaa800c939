"""Spheres holding the surface of a triangle mesh: how a robot's mesh collision
geometry enters csdf until meshes can be read as exact shapes.

The cover is built so that **every point of the surface lies inside a sphere**:

1. The surface is sampled on a barycentric grid of every triangle, fine enough that
   each surface point is within ``eps`` of a sample (the largest side of a grid cell).
2. Candidate centres are the points of a grid (pitch ``spacing / 2``) inside the mesh
   (generalised winding number > 1/2, exact for closed meshes); a candidate's radius
   is its distance to the samples plus ``spacing / 2``, so a sphere reaches at most
   about ``spacing / 2`` beyond the surface.
3. A greedy set cover picks candidates until every sample lies at least ``eps``
   inside a chosen sphere; a sample no candidate holds so gets a sphere of its own
   (radius ``spacing / 2``). With ``eps < spacing / 2`` the cover of the samples
   implies the cover of the surface.

The spheres are a bound of the mesh's geometry, never less: the clearance a robot's
spheres report is at most the clearance of its surface.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import CsdfError

__all__ = ["surface_samples", "winding_number", "sphere_set", "MAX_SAMPLES"]

#: the most surface samples a cover is built from (the grid is coarsened to fit)
MAX_SAMPLES = 40_000
#: the most candidate centres considered
MAX_CANDIDATES = 3_000


def surface_samples(vertices: np.ndarray, faces: np.ndarray, step: float
                    ) -> tuple[np.ndarray, float]:
    """Points on every triangle on a barycentric grid of ``m = ceil(longest side /
    step)`` cells a side: ``(points (P, 3), eps)`` where every point of the surface is
    within ``eps`` (the longest side of any grid cell) of a point."""
    tri = vertices[faces]  # (F, 3, 3)
    side = np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2).max(axis=1)
    m = np.maximum(1, np.ceil(side / step)).astype(int)
    out, eps = [], 0.0
    for mm in np.unique(m):
        sel = tri[m == mm]
        i, j = np.meshgrid(np.arange(mm + 1), np.arange(mm + 1), indexing="ij")
        keep = i + j <= mm
        u, v = i[keep] / mm, j[keep] / mm
        w = 1.0 - u - v
        pts = (u[None, :, None] * sel[:, None, 0] + v[None, :, None] * sel[:, None, 1]
               + w[None, :, None] * sel[:, None, 2])
        out.append(pts.reshape(-1, 3))
        eps = max(eps, float(side[m == mm].max()) / mm)
    return np.unique(np.concatenate(out), axis=0), eps


def winding_number(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray
                   ) -> np.ndarray:
    """``(N,)`` generalised winding numbers of a triangle mesh at points: the sum of
    the triangles' signed solid angles over 4 pi (1 inside a closed, outward-oriented
    mesh, 0 outside; Van Oosterom and Strackee's formula)."""
    tri = vertices[faces]  # (F, 3, 3)
    out = np.zeros(len(points))
    for s in range(0, len(points), 256):
        p = points[s:s + 256]
        a = tri[None, :, 0] - p[:, None]
        b = tri[None, :, 1] - p[:, None]
        c = tri[None, :, 2] - p[:, None]
        la, lb, lc = (np.linalg.norm(x, axis=2) for x in (a, b, c))
        det = np.einsum("nfi,nfi->nf", a, np.cross(b, c))
        den = (la * lb * lc + np.einsum("nfi,nfi->nf", a, b) * lc
               + np.einsum("nfi,nfi->nf", b, c) * la + np.einsum("nfi,nfi->nf", c, a) * lb)
        out[s:s + 256] = np.arctan2(det, den).sum(axis=1) / (2 * np.pi)
    return out


def sphere_set(vertices, faces, spacing: float | None = None
               ) -> tuple[np.ndarray, np.ndarray]:
    """Spheres holding the surface of a triangle mesh (see the module docs):
    ``(centres (S, 3), radii (S,))`` in the mesh's frame.

    Args:
        vertices: ``(V, 3)``; faces: ``(F, 3)`` vertex indices.
        spacing: the grid pitch of candidate centres times 2, and about how far a
            sphere may reach beyond the surface (default: a tenth of the mesh's
            largest extent).

    Raises:
        CsdfError: an empty or malformed mesh.
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3 or not len(f):
        raise CsdfError("a mesh needs vertices (V, 3) and faces (F, 3)")
    if f.min() < 0 or f.max() >= len(v) or not np.isfinite(v).all():
        raise CsdfError("mesh faces must index its finite vertices")
    extent = float((v.max(axis=0) - v.min(axis=0)).max())
    h = float(spacing) if spacing else extent / 10
    if not h > 0:
        raise CsdfError("a mesh cover needs a positive spacing (a degenerate mesh?)")
    step = h / 4
    area = float(np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]),
                                axis=1).sum() / 2)
    if area / (step * step) > MAX_SAMPLES:  # coarser samples, looser spheres
        step = math.sqrt(area / MAX_SAMPLES)
        h = max(h, 4 * step)
    samples, eps = surface_samples(v, f, step)
    bloat = max(h / 2, 2 * eps)
    from scipy.spatial import cKDTree

    tree = cKDTree(samples)
    lo, hi = v.min(axis=0), v.max(axis=0)
    pitch = h / 2
    while True:
        axes = [np.arange(lo[k] + pitch / 2, hi[k], pitch) for k in range(3)]
        n = math.prod(max(1, len(a)) for a in axes)
        if n <= 4 * MAX_CANDIDATES:
            break
        pitch *= 1.25
    axes = [a if len(a) else np.array([(lo[k] + hi[k]) / 2]) for k, a in enumerate(axes)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    inside = grid[np.abs(winding_number(grid, v, f)) > 0.5]
    if len(inside) > MAX_CANDIDATES:
        inside = inside[np.linspace(0, len(inside) - 1, MAX_CANDIDATES).astype(int)]
    cand_r = tree.query(inside)[0] + bloat if len(inside) else np.zeros(0)
    # which samples each candidate holds with eps to spare
    holds = [np.array(tree.query_ball_point(c, r - eps), dtype=np.int64)
             for c, r in zip(inside, cand_r)]
    covered = np.zeros(len(samples), bool)
    chosen: list[int] = []
    gain = np.array([len(x) for x in holds], dtype=np.int64)
    while len(gain) and gain.max() > 0:
        k = int(np.argmax(gain))
        chosen.append(k)
        covered[holds[k]] = True
        gain[k] = 0
        # refresh the gains lazily: only candidates that could still be the best
        for j in np.argsort(-gain):
            if gain[j] == 0:
                break
            gain[j] = int((~covered[holds[j]]).sum())
            if gain[j] >= gain.max():
                break
    centres = [inside[k] for k in chosen]
    radii = [cand_r[k] for k in chosen]
    rest = samples[~covered]
    if len(rest):  # thin parts no inner candidate holds: spheres on the samples
        sub = cKDTree(rest)
        left = np.ones(len(rest), bool)
        for i in range(len(rest)):
            if left[i]:
                left[sub.query_ball_point(rest[i], bloat - eps)] = False
                centres.append(rest[i])
                radii.append(bloat)
    return np.array(centres, dtype=np.float64).reshape(-1, 3), np.array(radii)
