"""The NumPy reference mesher: sparse surface extraction on a voxel grid, octree pruning
by interval arithmetic, then marching cubes or manifold dual contouring on the active
voxels only, in NumPy array code.

It is the oracle the compiled streaming mesher (:mod:`csdf.mesh.stream`,
:mod:`csdf.mesh.kernels`, :mod:`csdf.mesh.dc_kernels`) is tested equal to (same octree,
case table, root search and vertex placement), and the mesher :func:`csdf.mesh` uses
when the field has no compiled evaluator (Numba missing, or another backend chosen).

The grid and the octree are in :mod:`.grid`; the dual-contouring steps shared with the
streaming mesher in :mod:`.dual`. The mesher works in three stages:

1. **Octree** (:func:`.grid.octree`): bricks of ``BRICK^3`` voxels that may hold
   surface.
2. **Samples.** The field is evaluated at each surviving brick's ``(BRICK+1)^3``
   samples. Samples on the outer faces of the grid count as outside, so the surface is
   always closed (the shape is clipped to the grid box).
3. **Extraction.** A voxel is active when its corners disagree. Each crossed grid edge
   gets one root, found on the exact field by bracketed secant steps (so vertices lie on
   the zero set), identified by a global edge key, so the same edge gives the same
   vertex in every brick and the mesh is watertight. Marching cubes emits the table's
   triangles; dual contouring places one vertex per surface component of each active
   voxel by minimising the quadric error of the component's edge roots and exact
   normals (keeping sharp edges and corners), and emits one quad per crossed edge.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from .cases import COMPONENT_TABLE, CORNERS, EDGE_AXIS, EDGE_ORIGIN, MAX_COMPONENTS, TRI_TABLE
from .dual import PROJECT_STEPS, TIE, dc_finish, dc_solve, edge_normals
from .grid import BRICK, Grid, octree

__all__ = ["extract", "sample_bricks"]


def sample_bricks(grid: Grid, bricks: np.ndarray, values: Callable) -> np.ndarray:
    """Field values ``(K, B+1, B+1, B+1)`` (x fastest last) at the bricks' samples."""
    n = BRICK + 1
    g = np.arange(n)
    local = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    out = np.empty((len(bricks), n, n, n), dtype=np.float64)
    dims = np.array(grid.dims)
    step = max(1, 2_000_000 // len(local))
    for s in range(0, len(bricks), step):
        b = bricks[s:s + step]
        ijk = (b[:, None, :] + local[None, :, :]).reshape(-1, 3)
        v = values(grid.points(ijk))
        boundary = np.any(ijk <= 0, axis=1) | np.any(ijk >= dims, axis=1)
        v = np.where(boundary, np.maximum(v, grid.h), v)  # outside on the grid box
        out[s:s + step] = v.reshape(len(b), n, n, n)
    return out


def _edge_key(cx, cy, cz, axis, dims) -> np.ndarray:
    nx, ny = dims[0] + 1, dims[1] + 1
    return ((cz * ny + cy) * nx + cx) * 3 + axis


def _refine_roots(p0, p1, f0, f1, values: Callable, tol: float, iters: int = 40) -> np.ndarray:
    """Points on segments ``p0 -> p1`` where the field crosses 0.

    Regula falsi with the Illinois modification, a bisection step every third
    iteration (so a kinked or flat field still converges), always bracketed so a root
    never leaves its edge. Each iteration evaluates only the edges with ``|f| > tol``.
    """
    n = len(p0)
    a = np.zeros(n)
    b = np.ones(n)
    fa, fb = f0.astype(np.float64).copy(), f1.astype(np.float64).copy()
    d = p1 - p0
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.clip(fa / (fa - fb), 0.0, 1.0)
    t = np.where(np.isfinite(t), t, 0.5)
    side = np.zeros(n, dtype=np.int8)
    idx = np.arange(n)
    for it in range(iters):
        if len(idx) == 0:
            break
        ti = t[idx]
        ft = values(p0[idx] + ti[:, None] * d[idx])
        done = np.abs(ft) <= tol
        ai, bi, fai, fbi, si = a[idx], b[idx], fa[idx], fb[idx], side[idx]
        left = (np.sign(ft) == np.sign(fai)) & ~done  # the root lies in (t, b)
        right = ~left & ~done
        fbi = np.where(left & (si == 1), fbi * 0.5, fbi)  # Illinois
        fai = np.where(right & (si == -1), fai * 0.5, fai)
        ai = np.where(left, ti, ai)
        fai = np.where(left, ft, fai)
        bi = np.where(right, ti, bi)
        fbi = np.where(right, ft, fbi)
        si = np.where(left, 1, np.where(right, -1, 0)).astype(np.int8)
        with np.errstate(divide="ignore", invalid="ignore"):
            tn = ai + fai * (bi - ai) / (fai - fbi)
        bisect = ~np.isfinite(tn) | (tn <= ai) | (tn >= bi) | (it % 3 == 2)
        tn = np.where(bisect, 0.5 * (ai + bi), tn)
        a[idx], b[idx], fa[idx], fb[idx], side[idx] = ai, bi, fai, fbi, si
        t[idx] = np.where(done, ti, tn)
        idx = idx[~done]
    return p0 + t[:, None] * d


def extract(
    grid: Grid,
    values: Callable[[np.ndarray], np.ndarray],
    gradients: Callable[[np.ndarray], np.ndarray],
    intervals: Callable,
    method: str = "mc",
    progress: Callable | None = None,
    compiled: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """Extract the zero set on ``grid``.

    Args:
        values: ``(M, 3) -> (M,)`` field values; gradients: ``(M, 3) -> (M, 3)``.
        intervals: ``(lo (M, 3), hi (M, 3)) -> (flo (M,), fhi (M,))``, conservative.
        method: ``'mc'`` (marching cubes) or ``'dc'`` (manifold dual contouring).
        progress: optional ``callback(stage: str, done: int, total: int)``.
        compiled: dual contouring's per-cell work in the compiled kernels of
            :mod:`.dc_kernels` (needs Numba; the same mesh as the NumPy code).

    Returns:
        ``vertices (V, 3)`` float64 and ``faces (F, 3)`` int64, counter-clockwise seen
        from outside.
    """
    dims = np.array(grid.dims, dtype=np.int64)
    bricks = octree(grid, intervals, (lambda s, n: progress("octree", s, n)) if progress
                    else None)
    if len(bricks) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
    vals = sample_bricks(grid, bricks, values)
    if progress:
        progress("samples", len(bricks), len(bricks))
    B = BRICK
    inside = (vals < 0).view(np.uint8)
    case = np.zeros((len(bricks), B, B, B), dtype=np.uint8)
    for c, (dx, dy, dz) in enumerate(CORNERS.tolist()):
        case |= inside[:, dx:dx + B, dy:dy + B, dz:dz + B] << np.uint8(c)
    del inside
    kb, vi, vj, vk = np.nonzero((case != 0) & (case != 255))
    vox = bricks[kb] + np.stack([vi, vj, vk], axis=1)  # (A, 3) voxel index (lower corner)
    vcase = case[kb, vi, vj, vk].astype(np.intp)
    del case
    # crossed edges of every active voxel
    comp = COMPONENT_TABLE[vcase]  # (A, 12)
    av, ae = np.nonzero(comp >= 0)
    corner = vox[av] + EDGE_ORIGIN[ae]
    axis = EDGE_AXIS[ae]
    keys = _edge_key(corner[:, 0], corner[:, 1], corner[:, 2], axis, dims)
    ukeys, first, inv = np.unique(keys, return_index=True, return_inverse=True)
    # endpoints and values of each unique crossed edge, from the brick samples
    e_av, e_ae = av[first], ae[first]
    loc = np.stack([vi, vj, vk], axis=1)[e_av] + EDGE_ORIGIN[e_ae]
    step = np.eye(3, dtype=np.int64)[EDGE_AXIS[e_ae]]
    kk = kb[e_av]
    f0 = vals[kk, loc[:, 0], loc[:, 1], loc[:, 2]]
    l1 = loc + step
    f1 = vals[kk, l1[:, 0], l1[:, 1], l1[:, 2]]
    c0 = bricks[kk] + loc
    p0, p1 = grid.points(c0), grid.points(c0 + step)
    on_box = np.any((c0 <= 0) | (c0 + step <= 0) | (c0 >= dims) | (c0 + step >= dims), axis=1)
    roots = _refine_roots(p0, p1, f0, f1, _clip_box(values, grid, on_box), tol=1e-6 * grid.h)
    if progress:
        progress("roots", len(ukeys), len(ukeys))
    if method == "mc":
        tri = TRI_TABLE[vcase]  # (A, T, 3) local edges
        # map (active voxel, local edge) -> unique edge id
        lut = np.full((len(vox), 12), -1, dtype=np.int32)
        lut[av, ae] = inv
        a_idx, t_idx = np.nonzero(tri[:, :, 0] >= 0)
        faces = lut[a_idx[:, None], tri[a_idx, t_idx]].astype(np.int64)
        return roots, faces
    return _dual_contour(grid, vox, vcase, av, ae, inv, roots, f0, axis[first], ukeys, dims,
                         gradients, on_box, values, compiled)


def _clip_box(values: Callable, grid: Grid, on_box: np.ndarray) -> Callable:
    """The field used for roots when the surface is closed on the grid box:
    ``max(f, 2 * box + h)``, which is ``-h`` one sample inside the box and ``+h`` on it
    (agreeing with the forced sample values) and, being negative inside, changes no sign
    and no zero crossing of ``f`` elsewhere."""
    if not on_box.any():
        return values
    lo = grid.origin
    hi = grid.origin + grid.h * np.array(grid.dims)

    def clipped(p: np.ndarray) -> np.ndarray:
        box = 2.0 * np.max(np.maximum(lo - p, p - hi), axis=1) + grid.h
        return np.maximum(values(p), box)

    return clipped


def _project(verts: np.ndarray, fg: Callable, h: float, steps: int = PROJECT_STEPS
             ) -> np.ndarray:
    """Newton steps ``v -= f grad f / |grad f|^2`` towards the zero set, each limited to
    half a voxel; vertices already on it (sharp edges and corners) stay put."""
    for _ in range(steps):
        f, g = fg(verts)
        gg = np.sum(g * g, axis=1)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            step = np.where(gg > 0, f / gg, 0.0)[:, None] * g
            n = np.linalg.norm(step, axis=1, keepdims=True)
            step = np.where(n > 0.5 * h, step * (0.5 * h / np.maximum(n, 1e-300)), step)
        verts = verts - np.nan_to_num(step)
    return verts


def _dual_contour(grid, vox, vcase, av, ae, inv, roots, f0, uaxis, ukeys, dims, gradients,
                  on_box, values, compiled=False):
    def gradients_values(p):
        return values(p), gradients(p)

    normals = edge_normals(grid, roots, uaxis, gradients, on_box)
    if compiled:
        return _dual_contour_compiled(grid, vox, vcase, inv, roots, normals, f0, uaxis,
                                      values, gradients_values)
    # one vertex per (active voxel, component)
    comp = COMPONENT_TABLE[vcase]  # (A, 12)
    vert_of = comp[av, ae]  # component of each (voxel, edge) pair
    vid_key = av * MAX_COMPONENTS + vert_of
    uv, vinv = np.unique(vid_key, return_inverse=True)
    n_v = len(uv)
    p = roots[inv]
    n = normals[inv]
    # quadric error per vertex: A = sum n n^T, b = sum n (n . p), mass point
    A = np.zeros((n_v, 3, 3))
    bvec = np.zeros((n_v, 3))
    mass = np.zeros((n_v, 3))
    cnt = np.zeros(n_v)
    np.add.at(A, vinv, n[:, :, None] * n[:, None, :])
    np.add.at(bvec, vinv, n * np.sum(n * p, axis=1, keepdims=True))
    np.add.at(mass, vinv, p)
    np.add.at(cnt, vinv, 1.0)
    mass /= cnt[:, None]
    U, S, Vt = np.linalg.svd(A)
    smax = S[:, :1]
    Sinv = np.where(S > 0.05 * np.maximum(smax, 1e-300), 1.0 / np.where(S > 0, S, 1), 0.0)
    rhs = bvec - np.einsum("vij,vj->vi", A, mass)
    x = mass + np.einsum("vji,vj,vkj,vk->vi", Vt, Sinv, U, rhs)  # pinv(A) = V S+ U^T
    # keep each vertex within half a voxel of its voxel (limits fold-overs while letting
    # a feature line that clips a voxel's corner keep its vertex on the feature)
    owner = vox[uv // MAX_COMPONENTS]
    lo = grid.points(owner) - 0.5 * grid.h
    hi = grid.points(owner + 1) + 0.5 * grid.h
    verts = np.clip(x, lo, hi)
    verts = _project(verts, gradients_values, grid.h)
    # one quad per crossed edge: the 4 voxels around it, each with its component vertex
    pair_key = av * 12 + ae
    order = np.argsort(pair_key)
    sorted_keys = pair_key[order]
    sorted_vid = vinv[order]
    nx1, ny1 = dims[0] + 1, dims[1] + 1
    axis = uaxis
    cx = (ukeys // 3) % nx1
    cy = (ukeys // 3 // nx1) % ny1
    cz = ukeys // 3 // nx1 // ny1
    corner = np.stack([cx, cy, cz], axis=1)
    # linear voxel index of active voxels, for lookup
    vox_lin = (vox[:, 2] * dims[1] + vox[:, 1]) * dims[0] + vox[:, 0]
    lin_order = np.argsort(vox_lin)
    lin_sorted = vox_lin[lin_order]
    quads = np.zeros((len(ukeys), 4), dtype=np.int64)
    ok = np.ones(len(ukeys), dtype=bool)
    for q, (du, dv) in enumerate(((0, 0), (1, 0), (1, 1), (0, 1))):
        u_ax = (axis + 1) % 3
        v_ax = (axis + 2) % 3
        vv = corner.copy()
        vv[np.arange(len(vv)), u_ax] -= du
        vv[np.arange(len(vv)), v_ax] -= dv
        valid = np.all((vv >= 0) & (vv < dims), axis=1)
        lin = (vv[:, 2] * dims[1] + vv[:, 1]) * dims[0] + vv[:, 0]
        pos = np.clip(np.searchsorted(lin_sorted, lin), 0, len(lin_sorted) - 1)
        found = valid & (lin_sorted[pos] == lin)
        a_idx = lin_order[pos]
        # local edge of this voxel that is the shared edge: origin offset = corner - voxel
        off = corner - vv
        local = _local_edge(off, axis)
        pk = a_idx * 12 + local
        ppos = np.clip(np.searchsorted(sorted_keys, pk), 0, len(sorted_keys) - 1)
        found &= sorted_keys[ppos] == pk
        quads[:, q] = sorted_vid[ppos]
        ok &= found
    quads = quads[ok]
    flip = f0[ok] >= 0  # lower endpoint outside: normal points towards -axis
    quads[flip] = quads[flip][:, ::-1]
    # split along the diagonal whose midpoint is nearer the surface: along a sharp edge
    # that is the edge itself, so the two triangles do not cut the corner off
    m02 = 0.5 * (verts[quads[:, 0]] + verts[quads[:, 2]])
    m13 = 0.5 * (verts[quads[:, 1]] + verts[quads[:, 3]])
    fm = np.abs(values(np.concatenate([m02, m13])))
    use02 = fm[: len(quads)] <= fm[len(quads):] + TIE * grid.h
    t1 = np.where(use02[:, None], quads[:, [0, 1, 2]], quads[:, [0, 1, 3]])
    t2 = np.where(use02[:, None], quads[:, [0, 2, 3]], quads[:, [1, 2, 3]])
    faces = np.concatenate([t1, t2])
    return verts, faces


def _dual_contour_compiled(grid, vox, vcase, inv, roots, normals, f0, uaxis, values,
                           gradients_values):
    """:func:`_dual_contour` after the normals, with its per-cell work compiled
    (:mod:`.dc_kernels`): the same vertices, quads and triangles."""
    verts, quads, found = dc_solve(grid, vox, vcase, inv, roots, normals, uaxis)
    return dc_finish(grid, verts, quads, found, f0, values, gradients_values)


_LOCAL = {}
for _e in range(12):
    _LOCAL[(tuple(EDGE_ORIGIN[_e].tolist()), int(EDGE_AXIS[_e]))] = _e


def _local_edge(off: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Local edge index from the edge's origin offset within the voxel and its axis."""
    code = (off[:, 0] * 4 + off[:, 1] * 2 + off[:, 2]) * 3 + axis
    table = np.full(8 * 3, -1, dtype=np.int64)
    for (o, a), e in _LOCAL.items():
        table[(o[0] * 4 + o[1] * 2 + o[2]) * 3 + a] = e
    return table[code]
