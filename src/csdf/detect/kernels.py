"""Compiled (Numba) core of detection: connected components of a masked neighbour graph
by union-find, visiting only the masked points' own edges; the distances of points to
surface hypotheses (:mod:`.surfaces`' table) with their inlier tests and counts; the
k nearest neighbours of every point on a grid of cells; the nearest of a sensor's rays
to a direction (:class:`.rays.RayIndex`)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["component_roots", "largest_component", "best_counts", "linked_graph", "grow_inliers",
           "seeded_components", "surface_values", "inlier_counts", "knn_cells", "within_ball",
           "bounds", "ray_nearest", "ray_nearest_point", "pca_normals",
           "PLANE", "SPHERE", "CYLINDER", "CONE", "TORUS"]


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


# ------------------------------------------------------------------ surface distances
#: the surface kinds' numbers in the kernels (the order of ``surfaces.KINDS``)
PLANE, SPHERE, CYLINDER, CONE, TORUS = 0, 1, 2, 3, 4


@njit(cache=True, nogil=True, inline="always")
def _surface_point(kind: int, h: np.ndarray, ct: float, st: float, px: float, py: float,
                   pz: float) -> tuple[float, float, float, float]:
    """Signed distance of point ``(px, py, pz)`` to surface hypothesis ``h`` (a row of
    the table in :mod:`.surfaces`) and the unit surface normal ``(ux, uy, uz)`` at its
    nearest point; ``ct``, ``st``: cosine and sine of a cone's half angle."""
    if kind == PLANE:
        return px * h[0] + py * h[1] + pz * h[2] - h[3], h[0], h[1], h[2]
    vx, vy, vz = px - h[0], py - h[1], pz - h[2]
    if kind == SPHERE:
        r = math.sqrt(vx * vx + vy * vy + vz * vz)
        m = max(r, 1e-300)
        return r - h[3], vx / m, vy / m, vz / m
    ax, ay, az = h[3], h[4], h[5]
    hh = vx * ax + vy * ay + vz * az
    wx, wy, wz = vx - hh * ax, vy - hh * ay, vz - hh * az
    rho = math.sqrt(wx * wx + wy * wy + wz * wz)
    m = max(rho, 1e-300)
    wx, wy, wz = wx / m, wy / m, wz / m
    if kind == CYLINDER:
        return rho - h[6], wx, wy, wz
    if kind == CONE:
        d = rho * ct - hh * st
        if rho * st + hh * ct < 0.0:  # the nearest point of the nappe is the apex
            d = math.sqrt(rho * rho + hh * hh)
        return d, ct * wx - st * ax, ct * wy - st * ay, ct * wz - st * az
    e = rho - h[6]  # torus
    tx, ty, tz = e * wx + hh * ax, e * wy + hh * ay, e * wz + hh * az
    tl = math.sqrt(tx * tx + ty * ty + tz * tz)
    m = max(tl, 1e-300)
    return tl - h[7], tx / m, ty / m, tz / m


@njit(cache=True, nogil=True)
def _angles(kind: int, H: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cosines and sines ``(M,)`` of the cones' half angles (zeros for other kinds)."""
    ct = np.zeros(H.shape[0])
    st = np.zeros(H.shape[0])
    if kind == CONE:
        for i in range(H.shape[0]):
            ct[i] = math.cos(H[i, 6])
            st[i] = math.sin(H[i, 6])
    return ct, st


@njit(cache=True, nogil=True)
def surface_values(kind: int, H: np.ndarray, P: np.ndarray, N: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Signed distances ``(M, S)`` of points to hypotheses ``H`` ``(M, W)`` and the
    ``|cos|`` of the angle between each point's normal and the surface normal at its
    nearest point ``(M, S)``. ``P``, ``N``: ``(1, S, 3)`` points shared by every
    hypothesis or ``(M, S, 3)`` each one's own; ``N`` may have no rows (then the
    cosines are zeros)."""
    M, S = H.shape[0], P.shape[1]
    ct, st = _angles(kind, H)
    d = np.empty((M, S))
    c = np.zeros((M, S))
    own = P.shape[0] > 1
    normals = N.shape[0] > 0
    for i in range(M):
        pi = i if own else 0
        for j in range(S):
            dd, ux, uy, uz = _surface_point(kind, H[i], ct[i], st[i], P[pi, j, 0],
                                            P[pi, j, 1], P[pi, j, 2])
            d[i, j] = dd
            if normals:
                c[i, j] = abs(ux * N[pi, j, 0] + uy * N[pi, j, 1] + uz * N[pi, j, 2])
    return d, c


@njit(cache=True, nogil=True, inline="always")
def _is_inlier(kind: int, h: np.ndarray, ct: float, st: float, P: np.ndarray, N: np.ndarray,
               j: int, eps: float, cos_tol: float) -> bool:
    """Whether point ``j`` of ``P`` (unit normal ``N[j]``) lies within ``eps`` of
    hypothesis ``h`` with its normal agreeing to ``|cos| >= cos_tol``."""
    dd, ux, uy, uz = _surface_point(kind, h, ct, st, P[j, 0], P[j, 1], P[j, 2])
    return abs(dd) <= eps and abs(ux * N[j, 0] + uy * N[j, 1] + uz * N[j, 2]) >= cos_tol


@njit(cache=True, nogil=True)
def inlier_counts(kind: int, H: np.ndarray, P: np.ndarray, N: np.ndarray, eps: float,
                  cos_tol: float) -> np.ndarray:
    """``(M,)`` how many points ``P`` ``(S, 3)`` (unit normals ``N`` ``(S, 3)``) lie
    within ``eps`` of each hypothesis ``H`` ``(M, W)`` with normals agreeing to
    ``|cos| >= cos_tol``."""
    M = H.shape[0]
    ct, st = _angles(kind, H)
    out = np.zeros(M, dtype=np.int64)
    for i in range(M):
        n = 0
        for j in range(P.shape[0]):
            if _is_inlier(kind, H[i], ct[i], st[i], P, N, j, eps, cos_tol):
                n += 1
        out[i] = n
    return out


@njit(cache=True, nogil=True)
def inlier_mask(kind: int, h: np.ndarray, P: np.ndarray, N: np.ndarray, idx: np.ndarray,
                eps: float, cos_tol: float) -> np.ndarray:
    """``(K,)`` which of the points ``idx`` ``(K,)`` of ``P`` (unit normals ``N``) lie
    within ``eps`` of hypothesis ``h`` of ``kind`` with normals agreeing to
    ``|cos| >= cos_tol``."""
    ct = math.cos(h[6]) if kind == CONE else 0.0
    st = math.sin(h[6]) if kind == CONE else 0.0
    out = np.zeros(idx.shape[0], dtype=np.bool_)
    for a in range(idx.shape[0]):
        out[a] = _is_inlier(kind, h, ct, st, P, N, idx[a], eps, cos_tol)
    return out


@njit(cache=True, nogil=True)
def best_counts(kind: np.ndarray, H: np.ndarray, P: np.ndarray, N: np.ndarray, eps: float,
                cos_tol: float, first: int, k: int, z: float
                ) -> tuple[np.ndarray, np.ndarray]:
    """Inlier counts on growing prefixes (Schnabel et al.'s scoring on subsets): every
    hypothesis, row ``i`` of ``H`` ``(T, 8)`` (its kind's row, padded) of kind
    ``kind[i]``, is counted on the first ``first`` points of ``P``, ``N`` ``(S, 3)``,
    the survivors on twice as many, and so on up to all ``S``; after each step a
    hypothesis is dropped when ``count + z sqrt(count)`` is below ``c - z sqrt(c)``,
    ``c`` the ``k``-th largest count among the survivors (when more than ``k``
    survive). Returns the counts ``(T,)`` (over the points each was counted on) and
    which survived ``(T,)``."""
    T = H.shape[0]
    S = P.shape[0]
    counts = np.zeros(T, dtype=np.int64)
    alive = np.ones(T, dtype=np.bool_)
    ct = np.zeros(T)
    st = np.zeros(T)
    for i in range(T):
        if kind[i] == CONE:
            ct[i] = math.cos(H[i, 6])
            st[i] = math.sin(H[i, 6])
    a, b = 0, min(first, S)
    while a < S:
        for i in range(T):
            if alive[i]:
                n = 0
                for j in range(a, b):
                    if _is_inlier(kind[i], H[i], ct[i], st[i], P, N, j, eps, cos_tol):
                        n += 1
                counts[i] += n
        if b >= S:
            break
        live = np.flatnonzero(alive)
        if live.shape[0] > k:
            c = np.sort(counts[live])[live.shape[0] - k]
            floor = c - z * math.sqrt(c)
            for i in live:
                if counts[i] + z * math.sqrt(counts[i]) < floor:
                    alive[i] = False
        a, b = b, min(2 * b, S)
    return counts, alive


@njit(cache=True, nogil=True)
def largest_component(sel: np.ndarray, nbr: np.ndarray, linked: np.ndarray,
                      mask: np.ndarray) -> np.ndarray:
    """The points of the largest connected component (sorted indices) of the masked
    points ``sel`` (as :func:`component_roots`; a tie goes to the component holding the
    lowest point)."""
    roots = component_roots(sel, nbr, linked, mask)
    size = np.zeros(mask.shape[0], dtype=np.int64)
    best, best_n = -1, 0
    for a in range(roots.shape[0]):
        r = roots[a]
        size[r] += 1
    for a in range(roots.shape[0]):
        r = roots[a]
        if size[r] > best_n or (size[r] == best_n and r < best):
            best, best_n = r, size[r]
    out = np.empty(best_n, dtype=np.int64)
    k = 0
    for a in range(roots.shape[0]):
        if roots[a] == best:
            out[k] = sel[a]
            k += 1
    return out


@njit(cache=True, nogil=True)
def scatter(P: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The centroid ``(3,)`` and the scatter matrix ``(3, 3)`` (the sum of the outer
    products of the offsets from it) of the points ``idx`` ``(K,)`` of ``P``
    ``(N, 3)``, without gathering them."""
    c = np.zeros(3)
    for a in range(idx.shape[0]):
        for u in range(3):
            c[u] += P[idx[a], u]
    c /= max(idx.shape[0], 1)
    S = np.zeros((3, 3))
    for a in range(idx.shape[0]):
        j = idx[a]
        dx, dy, dz = P[j, 0] - c[0], P[j, 1] - c[1], P[j, 2] - c[2]
        S[0, 0] += dx * dx
        S[0, 1] += dx * dy
        S[0, 2] += dx * dz
        S[1, 1] += dy * dy
        S[1, 2] += dy * dz
        S[2, 2] += dz * dz
    S[1, 0], S[2, 0], S[2, 1] = S[0, 1], S[0, 2], S[1, 2]
    return c, S


@njit(cache=True, nogil=True)
def in_box_and_slab(Q: np.ndarray, lo: np.ndarray, hi: np.ndarray, nrm: np.ndarray,
                    off: float, width: float) -> np.ndarray:
    """``(M, 3)`` the points of ``Q`` ``(K, 3)`` inside the box ``lo``, ``hi`` ``(3,)``
    and within ``width`` of the plane ``nrm . p = off``, in order."""
    out = np.empty_like(Q)
    m = 0
    for a in range(Q.shape[0]):
        x, y, z = Q[a, 0], Q[a, 1], Q[a, 2]
        if (lo[0] <= x <= hi[0] and lo[1] <= y <= hi[1] and lo[2] <= z <= hi[2]
                and abs(nrm[0] * x + nrm[1] * y + nrm[2] * z - off) <= width):
            out[m, 0], out[m, 1], out[m, 2] = x, y, z
            m += 1
    return out[:m].copy()


@njit(cache=True, nogil=True)
def any_within(A: np.ndarray, B: np.ndarray, r: float) -> bool:
    """Whether a point of ``A`` ``(Ka, 3)`` lies nearer than ``r`` (``> 0``) to a
    point of ``B`` ``(Kb, 3)``: ``B`` binned in cells of side ``r`` (sorted by cell),
    each point of ``A`` compared with those in the 3 x 3 x 3 cells around its own."""
    if A.shape[0] == 0 or B.shape[0] == 0:
        return False
    lo, hi = bounds(B)
    nx = int((hi[0] - lo[0]) // r) + 1
    ny = int((hi[1] - lo[1]) // r) + 1
    nz = int((hi[2] - lo[2]) // r) + 1
    keys = np.empty(B.shape[0], dtype=np.int64)
    for j in range(B.shape[0]):
        keys[j] = (min(int((B[j, 0] - lo[0]) // r), nx - 1) + nx * (
            min(int((B[j, 1] - lo[1]) // r), ny - 1)
            + ny * min(int((B[j, 2] - lo[2]) // r), nz - 1)))
    order = np.argsort(keys)
    skeys = keys[order]
    r2 = r * r
    for i in range(A.shape[0]):
        ix = int(math.floor((A[i, 0] - lo[0]) / r))
        iy = int(math.floor((A[i, 1] - lo[1]) / r))
        iz = int(math.floor((A[i, 2] - lo[2]) / r))
        if ix < -1 or iy < -1 or iz < -1 or ix > nx or iy > ny or iz > nz:
            continue  # no cell of B within one cell
        for z in range(max(iz - 1, 0), min(iz + 1, nz - 1) + 1):
            for y in range(max(iy - 1, 0), min(iy + 1, ny - 1) + 1):
                for x in range(max(ix - 1, 0), min(ix + 1, nx - 1) + 1):
                    key = x + nx * (y + ny * z)
                    e = np.searchsorted(skeys, key)
                    while e < skeys.shape[0] and skeys[e] == key:
                        j = order[e]
                        dx = A[i, 0] - B[j, 0]
                        dy = A[i, 1] - B[j, 1]
                        dz = A[i, 2] - B[j, 2]
                        if dx * dx + dy * dy + dz * dz < r2:
                            return True
                        e += 1
    return False


# ------------------------------------------------------------------ nearest neighbours
@njit(cache=True, nogil=True)
def cell_keys(P: np.ndarray, lo: np.ndarray, h: float, dims: np.ndarray) -> np.ndarray:
    """``(N,)`` the key ``ix + nx (iy + ny iz)`` of each point's cell of side ``h`` from
    ``lo`` ``(3,)`` (``dims`` ``(3,)`` = ``(nx, ny, nz)`` cells a side; indices clamped
    to them): ``(P - lo) // h`` in one pass."""
    out = np.empty(P.shape[0], dtype=np.int64)
    nx, ny, nz = dims[0], dims[1], dims[2]
    for i in range(P.shape[0]):
        ix = min(int((P[i, 0] - lo[0]) // h), nx - 1)
        iy = min(int((P[i, 1] - lo[1]) // h), ny - 1)
        iz = min(int((P[i, 2] - lo[2]) // h), nz - 1)
        out[i] = ix + nx * (iy + ny * iz)
    return out


@njit(cache=True, nogil=True, inline="always")
def _keep_nearest(bd: np.ndarray, bi: np.ndarray, m: int, k: int, d2: float, b: int
                  ) -> int:
    """Put candidate ``b`` at squared distance ``d2`` into the ascending lists ``bd``
    (squared distances) and ``bi`` (labels) of the ``m`` nearest so far (at most
    ``k``; the farthest drops out when full); returns their new count. Of equally near
    candidates the earlier one stays first."""
    s = m if m < k else k - 1
    while s > 0 and bd[s - 1] > d2:
        bd[s] = bd[s - 1]
        bi[s] = bi[s - 1]
        s -= 1
    bd[s] = d2
    bi[s] = b
    return m + 1 if m < k else m


@njit(cache=True, nogil=True, inline="always")
def _scan_run(S: np.ndarray, b0: int, b1: int, px: float, py: float, pz: float, skip: int,
              k: int, bd: np.ndarray, bi: np.ndarray, m: int, worst: float
              ) -> tuple[int, float]:
    """Rows ``b0 .. b1 - 1`` of ``S`` (one run of cells) as candidates for the nearest
    of ``(px, py, pz)``, row ``skip`` left out, kept by :func:`_keep_nearest` when nearer
    than ``worst`` (squared); returns the new count and ``worst`` (the ``k``-th
    distance once ``k`` are kept)."""
    for b in range(b0, b1):
        dx = S[b, 0] - px
        dy = S[b, 1] - py
        dz = S[b, 2] - pz
        d2 = dx * dx + dy * dy + dz * dz
        if d2 >= worst or b == skip:
            continue
        m = _keep_nearest(bd, bi, m, k, d2, b)
        if m == k:
            worst = bd[k - 1]
    return m, worst


@njit(cache=True, nogil=True, inline="always")
def _search_cube(S: np.ndarray, first: np.ndarray, nx: int, ny: int, nz: int, ix: int,
                 iy: int, iz: int, R: int, px: float, py: float, pz: float, skip: int,
                 k: int, bd: np.ndarray, bi: np.ndarray) -> int:
    """The nearest of ``(px, py, pz)`` (at most ``k``; row ``skip`` left out) among
    the points of the cells within ``R`` of cell ``(ix, iy, iz)`` of the grid of
    :func:`knn_cells`, into ``bd`` and ``bi`` (ascending); returns how many."""
    m, worst = 0, np.inf
    x0, x1 = max(ix - R, 0), min(ix + R, nx - 1)
    for z in range(max(iz - R, 0), min(iz + R, nz - 1) + 1):
        for y in range(max(iy - R, 0), min(iy + R, ny - 1) + 1):
            base = nx * (y + ny * z)
            m, worst = _scan_run(S, first[base + x0], first[base + x1 + 1], px, py, pz,
                                 skip, k, bd, bi, m, worst)
    return m


@njit(cache=True, nogil=True)
def knn_cells(S: np.ndarray, order: np.ndarray, first: np.ndarray, cstart: np.ndarray,
              ckey: np.ndarray, dims: np.ndarray, origin: np.ndarray, h: float, k: int,
              c0: int, c1: int, out_d: np.ndarray, out_i: np.ndarray,
              exact: np.ndarray) -> None:
    """The ``k`` nearest neighbours (self excluded) of the points of occupied grid
    cells ``c0 .. c1 - 1``, searched in the 3 x 3 x 3 block of cells around each.

    ``S`` ``(N, 3)`` the points sorted by the key ``ix + nx (iy + ny iz)`` of their
    cell (cells of side ``h`` from ``origin`` ``(3,)``; ``dims`` ``(3,)`` =
    ``(nx, ny, nz)``), ``order`` ``(N,)`` their indices in the cloud; ``first``
    ``(nx ny nz + 1,)`` where each cell's run of ``S`` begins (every cell, empty ones
    too); ``cstart`` ``(C + 1,)`` and ``ckey`` ``(C,)`` where each occupied cell's run
    begins and its key. Writes, at each point's own row (its index in the cloud), the
    distances ``out_d`` and indices ``out_i`` ``(N, k)`` of its neighbours (nearest
    first) and ``exact`` ``(N,)``: whether its ``k``-th neighbour lies within ``h``
    (only then is the block sure to hold the true neighbours; the others need another
    search). The block's nine rows of three cells are each one run of ``S``; a point
    searches its own row first and then skips every row, and every cell at either end
    of a row, that lies no nearer than its ``k``-th neighbour so far (the answer is
    the same, found on fewer candidates)."""
    nx, ny, nz = dims[0], dims[1], dims[2]
    bd = np.empty(k)
    bi = np.empty(k, dtype=np.int64)
    h2 = h * h
    slack = 1e-9 * h  # cell boundaries as computed may be off by rounding
    for c in range(c0, c1):
        key = ckey[c]
        ix = key % nx
        iy = (key // nx) % ny
        iz = key // (nx * ny)
        bx = origin[0] + ix * h  # the cell's lower corner
        by = origin[1] + iy * h
        bz = origin[2] + iz * h
        last = np.inf  # the k-th distance (squared) of the cell's previous point
        for a in range(cstart[c], cstart[c + 1]):
            # first within a radius a quarter beyond the previous point's k-th
            # neighbour (neighbours in one cell have alike ones): far fewer candidates
            # enter the sorted list; when fewer than k lie within it, again unbounded
            m = _block_search(S, first, a, ix, iy, iz, nx, ny, nz, bx, by, bz, h, slack,
                              1.5625 * last, k, bd, bi)
            if m < k and last < np.inf:
                m = _block_search(S, first, a, ix, iy, iz, nx, ny, nz, bx, by, bz, h,
                                  slack, np.inf, k, bd, bi)
            last = bd[k - 1] if m == k else np.inf
            i = order[a]
            for q in range(m):
                out_d[i, q] = math.sqrt(bd[q])
                out_i[i, q] = order[bi[q]]
            exact[i] = m == k and bd[k - 1] <= h2


@njit(cache=True, nogil=True)
def knn_block(S: np.ndarray, order: np.ndarray, first: np.ndarray, skey: np.ndarray,
              dims: np.ndarray, origin: np.ndarray, h: float, k: int, rows: np.ndarray,
              R: int, out_d: np.ndarray, out_i: np.ndarray, exact: np.ndarray) -> None:
    """The ``k`` nearest neighbours (self excluded) of the points at rows ``rows`` of
    ``S`` (the grid of :func:`knn_cells`; ``skey`` ``(N,)`` each row's cell key),
    searched in the ``(2 R + 1)^3`` cells around each point's own, which hold every
    point within ``R h`` of it. Writes, at each point's own row, ``out_d``, ``out_i``
    and ``exact`` (whether its ``k``-th neighbour lies within ``R h``) as
    :func:`knn_cells` does."""
    nx, ny, nz = dims[0], dims[1], dims[2]
    bd = np.empty(k)
    bi = np.empty(k, dtype=np.int64)
    reach = R * h - 1e-9 * h  # cell boundaries as computed may be off by rounding
    for r in range(rows.shape[0]):
        a = rows[r]
        key = skey[a]
        ix = key % nx
        iy = (key // nx) % ny
        iz = key // (nx * ny)
        m = _search_cube(S, first, nx, ny, nz, ix, iy, iz, R, S[a, 0], S[a, 1], S[a, 2], a,
                         k, bd, bi)
        i = order[a]
        for q in range(m):
            out_d[i, q] = math.sqrt(bd[q])
            out_i[i, q] = order[bi[q]]
        exact[i] = m == k and bd[k - 1] <= reach * reach


@njit(cache=True, nogil=True)
def grid_knn(Q: np.ndarray, S: np.ndarray, ids: np.ndarray, first: np.ndarray,
             dims: np.ndarray, origin: np.ndarray, h: float, k: int) -> np.ndarray:
    """``(M, k)`` the ``k`` nearest of the points ``S`` ``(K, 3)`` (sorted by their
    cells of side ``h`` from ``origin``, ``dims`` cells a side, key ``ix + nx (iy + ny
    iz)``; ``first`` where each cell's run begins) to each query point ``Q`` ``(M, 3)``
    (inside the grid's box), as the labels ``ids`` ``(K,)`` of those points, nearest
    first (a point at distance 0 included): searched in the block of cells ``R`` around
    the query's own, ``R`` growing from 1 until the ``k``-th lies within ``R h`` (then
    no point outside the block is nearer). ``k <= K``."""
    nx, ny, nz = dims[0], dims[1], dims[2]
    out = np.empty((Q.shape[0], k), dtype=np.int64)
    bd = np.empty(k)
    bi = np.empty(k, dtype=np.int64)
    big = max(nx, ny, nz)
    for q in range(Q.shape[0]):
        px, py, pz = Q[q, 0], Q[q, 1], Q[q, 2]
        ix = min(max(int((px - origin[0]) // h), 0), nx - 1)
        iy = min(max(int((py - origin[1]) // h), 0), ny - 1)
        iz = min(max(int((pz - origin[2]) // h), 0), nz - 1)
        R = 1
        while True:
            m = _search_cube(S, first, nx, ny, nz, ix, iy, iz, R, px, py, pz, -1, k, bd, bi)
            reach = (R - 1e-9) * h  # (cell boundaries as computed may be off by rounding)
            if (m == k and bd[k - 1] <= reach * reach) or R > big:
                break
            R += 1
        for c in range(m):
            out[q, c] = ids[bi[c]]
        for c in range(m, k):  # (only when the grid holds fewer than k points)
            out[q, c] = ids[bi[0]]
    return out


#: the rows ``(dy, dz)`` of a 3 x 3 x 3 block of cells, the middle one first
_ROW_Y = np.array([0, -1, 1, 0, 0, -1, 1, -1, 1], dtype=np.int64)
_ROW_Z = np.array([0, 0, 0, -1, 1, -1, -1, 1, 1], dtype=np.int64)


@njit(cache=True, nogil=True, inline="always")
def _block_search(S: np.ndarray, first: np.ndarray, a: int, ix: int, iy: int, iz: int,
                  nx: int, ny: int, nz: int, bx: float, by: float, bz: float, h: float,
                  slack: float, bound: float, k: int, bd: np.ndarray, bi: np.ndarray
                  ) -> int:
    """The nearest neighbours of point ``a`` of ``S`` (in cell ``(ix, iy, iz)`` whose
    lower corner is ``(bx, by, bz)``) among the points of its 3 x 3 x 3 block of cells
    closer than ``sqrt(bound)``: the first ``m <= k`` of ``bd`` (squared distances,
    ascending) and ``bi`` (rows of ``S``); returns ``m``. Rows of cells, and cells at
    either end of a row, that lie no nearer than the ``k``-th distance so far are
    skipped."""
    px, py, pz = S[a, 0], S[a, 1], S[a, 2]
    # each side's gap: the least distance to the neighbouring cell that way
    gxl = max(px - bx - slack, 0.0)
    gxh = max(bx + h - px - slack, 0.0)
    gyl = max(py - by - slack, 0.0)
    gyh = max(by + h - py - slack, 0.0)
    gzl = max(pz - bz - slack, 0.0)
    gzh = max(bz + h - pz - slack, 0.0)
    m = 0
    worst = bound  # the k-th distance so far (squared), or the bound
    for r in range(9):
        y = iy + _ROW_Y[r]
        z = iz + _ROW_Z[r]
        if y < 0 or y >= ny or z < 0 or z >= nz:
            continue
        g = 0.0
        if _ROW_Y[r] < 0:
            g += gyl * gyl
        elif _ROW_Y[r] > 0:
            g += gyh * gyh
        if _ROW_Z[r] < 0:
            g += gzl * gzl
        elif _ROW_Z[r] > 0:
            g += gzh * gzh
        if g >= worst:
            continue
        x0 = ix - 1 if ix > 0 and g + gxl * gxl < worst else ix
        x1 = ix + 1 if ix < nx - 1 and g + gxh * gxh < worst else ix
        base = nx * (y + ny * z)
        m, worst = _scan_run(S, first[base + x0], first[base + x1 + 1], px, py, pz, a, k,
                             bd, bi, m, worst)
    return m


@njit(cache=True, nogil=True, inline="always")
def _spread_bits(x: int) -> int:
    """The low 21 bits of ``x`` spread out to every third bit (bit ``b`` to ``3 b``)."""
    x &= 0x1FFFFF
    x = (x | (x << 32)) & 0x1F00000000FFFF
    x = (x | (x << 16)) & 0x1F0000FF0000FF
    x = (x | (x << 8)) & 0x100F00F00F00F00F
    x = (x | (x << 4)) & 0x10C30C30C30C30C3
    x = (x | (x << 2)) & 0x1249249249249249
    return x


@njit(cache=True, nogil=True)
def morton_keys(P: np.ndarray, lo: np.ndarray, scale: float) -> np.ndarray:
    """``(N,)`` the Morton (Z-order) key of each point of ``P`` ``(N, 3)``: its cell
    ``floor((p - lo) * scale)`` on a ``2^21`` grid per axis (clamped), the three cell
    indices' bits interleaved (x lowest). Sorting by the keys puts near points near."""
    out = np.empty(P.shape[0], dtype=np.int64)
    top = (1 << 21) - 1
    for i in range(P.shape[0]):
        key = 0
        for c in range(3):
            v = (P[i, c] - lo[c]) * scale
            k = 0 if not v > 0.0 else (top if v >= top else int(v))
            key |= _spread_bits(k) << c
        out[i] = key
    return out


@njit(cache=True, nogil=True)
def bounds(P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The least and greatest coordinates ``(3,)`` each of the points ``P`` ``(N, 3)``
    (``N >= 1``): ``P.min(axis=0)`` and ``P.max(axis=0)`` in one pass (NumPy reduces
    the short rows of an ``(N, 3)`` array slowly)."""
    lo = P[0].copy()
    hi = P[0].copy()
    for i in range(1, P.shape[0]):
        for c in range(3):
            v = P[i, c]
            if v < lo[c]:
                lo[c] = v
            elif v > hi[c]:
                hi[c] = v
    return lo, hi


@njit(cache=True, nogil=True)
def within_ball(P: np.ndarray, idx: np.ndarray, c: np.ndarray, r: float) -> np.ndarray:
    """``(K,)`` which of the points ``idx`` ``(K,)`` of ``P`` ``(N, 3)`` lie within
    distance ``r`` of ``c`` ``(3,)``."""
    out = np.zeros(idx.shape[0], dtype=np.bool_)
    r2 = r * r
    for a in range(idx.shape[0]):
        j = idx[a]
        dx, dy, dz = P[j, 0] - c[0], P[j, 1] - c[1], P[j, 2] - c[2]
        out[a] = dx * dx + dy * dy + dz * dz <= r2
    return out


@njit(cache=True, nogil=True)
def ball_in_frame(P: np.ndarray, idx: np.ndarray, c: np.ndarray, r: float, R: np.ndarray,
                  t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The positions ``(M,)`` (ascending) in ``idx`` ``(K,)`` of the points of ``P``
    ``(N, 3)`` within distance ``r`` of ``c`` ``(3,)``, and those points in the frame
    of the pose ``p = R q + t``: ``q = (p - t) R`` ``(M, 3)``, C-contiguous (what
    :func:`within_ball`, a gather and a matrix product give, in one pass)."""
    pos = np.empty(idx.shape[0], dtype=np.int64)
    q = np.empty((idx.shape[0], 3))
    r2 = r * r
    m = 0
    for a in range(idx.shape[0]):
        j = idx[a]
        dx, dy, dz = P[j, 0] - c[0], P[j, 1] - c[1], P[j, 2] - c[2]
        if dx * dx + dy * dy + dz * dz <= r2:
            x, y, z = P[j, 0] - t[0], P[j, 1] - t[1], P[j, 2] - t[2]
            for col in range(3):
                q[m, col] = x * R[0, col] + y * R[1, col] + z * R[2, col]
            pos[m] = a
            m += 1
    return pos[:m].copy(), q[:m].copy()


@njit(cache=True, nogil=True)
def close_agreeing(d: np.ndarray, gq: np.ndarray, R: np.ndarray, N: np.ndarray,
                   rows: np.ndarray, limit: float, cos_tol: float
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Of the points with signed distances ``d`` ``(M,)`` and gradients ``gq``
    ``(M, 3)`` in a solid's frame (rotation ``R``: scene = ``R`` times frame), whose
    normals are the rows ``rows`` ``(M,)`` of ``N`` ``(N, 3)``: which lie within
    ``limit`` of the surface with normals within ``cos_tol`` (a cosine, either sign) of
    its gradient (their positions ``(K,)``, ascending) and their unsigned distances
    ``(K,)``."""
    pos = np.empty(d.shape[0], dtype=np.int64)
    dist = np.empty(d.shape[0])
    m = 0
    for a in range(d.shape[0]):
        ad = abs(d[a])
        if not ad <= limit:
            continue
        g0 = R[0, 0] * gq[a, 0] + R[0, 1] * gq[a, 1] + R[0, 2] * gq[a, 2]
        g1 = R[1, 0] * gq[a, 0] + R[1, 1] * gq[a, 1] + R[1, 2] * gq[a, 2]
        g2 = R[2, 0] * gq[a, 0] + R[2, 1] * gq[a, 1] + R[2, 2] * gq[a, 2]
        gn = max(math.sqrt(g0 * g0 + g1 * g1 + g2 * g2), 1e-300)
        j = rows[a]
        if abs(g0 * N[j, 0] + g1 * N[j, 1] + g2 * N[j, 2]) / gn >= cos_tol:
            pos[m] = a
            dist[m] = ad
            m += 1
    return pos[:m].copy(), dist[:m].copy()


#: a set of ``m`` points grown from a cloud of ``N`` is sorted when ``m`` times this
#: is at most ``N``, else collected in order by one pass over the cloud's states
#: (cheaper than sorting a large set)
SORT_COST = 16
#: the states of points while a set grows (:func:`_spread`)
UNTESTED, IN, OUT, REACHED, PASS = 0, 1, 2, 3, 4


@njit(cache=True, nogil=True)
def _spread(state: np.ndarray, seeds: np.ndarray, start: np.ndarray, adj: np.ndarray,
            kind: int, h: np.ndarray, P: np.ndarray, N: np.ndarray, eps: float,
            cos_tol: float) -> np.ndarray:
    """The points a set grows to from ``seeds`` over the graph of :func:`linked_graph`
    (``start``, ``adj``), sorted. ``state`` ``(N,)`` holds each point's state: ``IN``
    and ``OUT`` are known, an ``UNTESTED`` point is tested against hypothesis ``h`` when
    first met (within ``eps``, normals agreeing to ``cos_tol``), and a ``PASS`` seed is
    grown from without being in the set. The seeds are met first, then the neighbours
    of each point that joined, in turn."""
    ct = math.cos(h[6]) if kind == CONE else 0.0
    st = math.sin(h[6]) if kind == CONE else 0.0
    queue = np.empty(state.shape[0], dtype=np.int64)
    m, q = 0, 0
    src, e, stop = seeds, 0, seeds.shape[0]  # the points met next: src[e:stop]
    while True:
        if e == stop:
            if q == m:
                break
            i = queue[q]
            q += 1
            src, e, stop = adj, start[i], start[i + 1]
            continue
        j = src[e]
        e += 1
        s = state[j]
        if s == UNTESTED:
            s = IN if _is_inlier(kind, h, ct, st, P, N, j, eps, cos_tol) else OUT
        if s == IN or s == PASS:
            state[j] = REACHED if s == IN else OUT
            queue[m] = j
            m += 1
        elif s == OUT:
            state[j] = OUT
    k = 0
    for a in range(m):
        if state[queue[a]] == REACHED:
            k += 1
    out = np.empty(k, dtype=np.int64)
    if k * SORT_COST <= state.shape[0]:  # few: sorted
        k = 0
        for a in range(m):
            if state[queue[a]] == REACHED:
                out[k] = queue[a]
                k += 1
        return np.sort(out)
    k = 0  # many: in order by one pass over the states (no sort)
    for i in range(state.shape[0]):
        if state[i] == REACHED:
            out[k] = i
            k += 1
    return out


@njit(cache=True, nogil=True)
def seeded_components(good: np.ndarray, seeds: np.ndarray, start: np.ndarray,
                      adj: np.ndarray) -> np.ndarray:
    """The points ``good`` ``(G,)`` in the connected components of ``good`` and
    ``seeds`` ``(S,)`` together that hold a seed (sorted indices), in the graph of
    :func:`linked_graph` (``start``, ``adj``), found by growing from the seeds."""
    state = np.full(start.shape[0] - 1, OUT, dtype=np.int8)
    for a in range(seeds.shape[0]):
        state[seeds[a]] = PASS
    for a in range(good.shape[0]):
        state[good[a]] = IN
    return _spread(state, seeds, start, adj, PLANE, np.zeros(4), np.zeros((1, 3)),
                   np.zeros((1, 3)), 0.0, 0.0)


@njit(cache=True, nogil=True)
def linked_graph(nbr: np.ndarray, linked: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The undirected graph of the linked neighbour edges (``nbr``, ``linked``
    ``(N, k)``, as in :func:`component_roots`) in compressed rows: ``start`` ``(N + 1,)``
    and ``adj`` ``(E,)``, the neighbours of point ``i`` being
    ``adj[start[i]:start[i + 1]]``, each once (an edge found from both ends, as most
    k-nearest-neighbour edges are, is listed once: on a 40k-point scan, searches over
    the graph meet 44 % fewer entries)."""
    n, k = nbr.shape
    deg = np.zeros(n + 1, dtype=np.int64)
    for i in range(n):
        for c in range(k):
            if linked[i, c]:
                deg[i + 1] += 1
                deg[nbr[i, c] + 1] += 1
    start = np.cumsum(deg)
    fill = start[:-1].copy()
    adj = np.empty(start[n], dtype=np.int64)
    for i in range(n):
        for c in range(k):
            if linked[i, c]:
                j = nbr[i, c]
                adj[fill[i]] = j
                fill[i] += 1
                adj[fill[j]] = i
                fill[j] += 1
    # each row's repeats dropped (in place, first listing kept), rows packed
    seen = np.full(n, -1, dtype=np.int64)
    out = np.zeros(n + 1, dtype=np.int64)
    w = 0
    for i in range(n):
        for e in range(start[i], start[i + 1]):
            j = adj[e]
            if seen[j] != i:
                seen[j] = i
                adj[w] = j
                w += 1
        out[i + 1] = w
    return out, adj[:w].copy()


@njit(cache=True, nogil=True)
def grow_inliers(kind: int, h: np.ndarray, P: np.ndarray, N: np.ndarray, free: np.ndarray,
                 seeds: np.ndarray, eps: float, cos_tol: float, start: np.ndarray,
                 adj: np.ndarray) -> np.ndarray:
    """The free inliers of hypothesis ``h`` (within ``eps``, normals agreeing to
    ``cos_tol``) connected to the free inlier points among ``seeds`` in the graph of
    :func:`linked_graph` (sorted indices): the connected components of the inliers that
    hold a seed, found by growing from the seeds, so that only those components' points
    and their neighbours are evaluated."""
    state = np.full(P.shape[0], OUT, dtype=np.int8)
    for i in range(P.shape[0]):
        if free[i]:
            state[i] = UNTESTED
    return _spread(state, seeds, start, adj, kind, h, P, N, eps, cos_tol)


@njit(cache=True, nogil=True, inline="always")
def _square(q0: float, q1: float, q2: float, cq: float, th: float, a: float,
            e0: np.ndarray, e1: np.ndarray) -> tuple[float, float, float]:
    """The gnomonic projection ``(u, v)`` of the unit direction ``q`` (``cq``: its
    cosine to the axis) and the half-width ``r`` of the square holding every direction
    within the arc ``a`` of it, ``th`` being the largest angle from the axis along such
    an arc (lengths stretch by at most ``sec^2 th``)."""
    ce = math.cos(th)
    r = a / (ce * ce) * (1.0 + 1e-9) + 1e-15
    return ((q0 * e0[0] + q1 * e0[1] + q2 * e0[2]) / cq,
            (q0 * e1[0] + q1 * e1[1] + q2 * e1[2]) / cq, r)


@njit(cache=True, nogil=True, inline="always")
def _nearest_in_square(x0: float, x1: float, x2: float, A: np.ndarray, order: np.ndarray,
                       start: np.ndarray, u: float, v: float, r: float, lo0: float,
                       lo1: float, h: float, n0: int, n1: int, limit: float
                       ) -> tuple[int, float]:
    """The row of ``A`` ``(N, 3)`` nearest to ``(x0, x1, x2)`` among those in the grid
    cells (``order``, ``start``: :func:`csdf.cellsort.group_by_cell`) of the square of
    half-width ``r`` about ``(u, v)``, when its squared distance is below ``limit``:
    ``(row or -1, squared distance)``; of equally near rows, the lowest."""
    a0 = max(int(math.floor((u - r - lo0) / h)), 0)
    a1 = min(int(math.floor((u + r - lo0) / h)), n0 - 1)
    b0 = max(int(math.floor((v - r - lo1) / h)), 0)
    b1 = min(int(math.floor((v + r - lo1) / h)), n1 - 1)
    k = -1
    dmin = limit
    for ga in range(a0, a1 + 1):
        for gb in range(b0, b1 + 1):
            cc = ga * n1 + gb
            for s in range(start[cc], start[cc + 1]):
                j = order[s]
                d0 = x0 - A[j, 0]
                d1 = x1 - A[j, 1]
                d2 = x2 - A[j, 2]
                dd = d0 * d0 + d1 * d1 + d2 * d2
                if dd < dmin or (dd == dmin and k >= 0 and j < k):
                    dmin = dd
                    k = j
    return k, dmin


@njit(cache=True, nogil=True)
def ray_nearest(Q: np.ndarray, D: np.ndarray, order: np.ndarray, start: np.ndarray,
                c: np.ndarray, e0: np.ndarray, e1: np.ndarray, lo0: float, lo1: float,
                h: float, n0: int, n1: int, tol: float, cos_far: float
                ) -> tuple[np.ndarray, np.ndarray]:
    """For each unit direction ``Q[i]`` ``(M, 3)``, the ray of ``D`` ``(N, 3)`` nearest
    to it (chord distance) when nearer than ``tol``: ``(index (M,), -1 for none;
    squared distance (M,))``. The rays are gridded in the gnomonic projection about
    the axis ``c`` (``u = D.e0 / D.c``, ``v = D.e1 / D.c``; :class:`.rays.RayIndex`). A chord
    below ``tol`` is an arc below ``a = 2 asin(tol / 2)``; along it the angle from
    ``c`` stays below ``theta_q + a``, where the projection stretches lengths by at
    most ``sec^2``, so every ray within ``tol`` lies within ``a sec^2(theta_q + a)``
    of the query's projection, and only the cells of that square are read. Queries
    farther than ``cos_far`` (a cosine) from the axis are answered by the caller."""
    m = Q.shape[0]
    best = np.full(m, -1, dtype=np.int64)
    bd = np.full(m, np.inf)
    tol2 = tol * tol
    a = 2.0 * math.asin(min(1.0, 0.5 * tol))
    for i in range(m):
        q0, q1, q2 = Q[i, 0], Q[i, 1], Q[i, 2]
        cq = q0 * c[0] + q1 * c[1] + q2 * c[2]
        if cq < cos_far:
            continue
        u, v, r = _square(q0, q1, q2, cq, math.acos(min(1.0, cq)) + a, a, e0, e1)
        k, dmin = _nearest_in_square(q0, q1, q2, D, order, start, u, v, r, lo0, lo1, h,
                                     n0, n1, tol2)
        if k >= 0:
            best[i] = k
            bd[i] = dmin
    return best, bd


@njit(cache=True, nogil=True)
def ray_nearest_point(X: np.ndarray, o: np.ndarray, P: np.ndarray, order: np.ndarray,
                      start: np.ndarray, c: np.ndarray, e0: np.ndarray, e1: np.ndarray,
                      lo0: float, lo1: float, h: float, n0: int, n1: int, radius: float,
                      widest: float, far: float) -> tuple[np.ndarray, np.ndarray]:
    """For each point ``X[i]`` ``(M, 3)``, the scan point of ``P`` ``(N, 3)`` (seen
    from ``o``, gridded by their rays as in :func:`ray_nearest`) nearest to it when
    nearer than ``radius``: ``(index (M,), -1 for none, -2 where the caller must look
    itself; squared distance (M,))``. A point within ``radius`` of ``X[i]``, at range
    ``rho`` from ``o``, lies on a ray within ``a = asin(radius / rho)`` of ``X[i]``'s,
    so only those rays' cells are read (``widest``: the largest angle of a ray from the
    axis; ``far``: the largest angle the grid's stretch bound is used at)."""
    m = X.shape[0]
    best = np.full(m, -1, dtype=np.int64)
    bd = np.full(m, np.inf)
    r2 = radius * radius
    for i in range(m):
        x0, x1, x2 = X[i, 0], X[i, 1], X[i, 2]
        v0, v1, v2 = x0 - o[0], x1 - o[1], x2 - o[2]
        rho = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
        if rho <= radius * (1.0 + 1e-6):
            best[i] = -2
            continue
        a = math.asin(radius / rho) * (1.0 + 1e-9) + 1e-15
        q0, q1, q2 = v0 / rho, v1 / rho, v2 / rho
        cq = q0 * c[0] + q1 * c[1] + q2 * c[2]
        thq = math.acos(max(-1.0, min(1.0, cq)))
        if thq - a > widest + 1e-9:
            continue  # no ray comes that close
        th = thq + a
        if th >= far:
            best[i] = -2
            continue
        u, v, r = _square(q0, q1, q2, cq, th, a, e0, e1)
        k, dmin = _nearest_in_square(x0, x1, x2, P, order, start, u, v, r, lo0, lo1, h,
                                     n0, n1, r2)
        if k >= 0:
            best[i] = k
            bd[i] = dmin
    return best, bd


@njit(cache=True, nogil=True)
def pca_normals(P: np.ndarray, nbr: np.ndarray, start: int, stop: int,
                normals: np.ndarray, least: np.ndarray, ok: np.ndarray) -> None:
    """For each point ``i`` in ``[start, stop)``: the least eigenvalue ``least[i]`` and
    its unit eigenvector ``normals[i]`` of the covariance of its neighbours
    ``P[nbr[i]]`` (``P`` ``(N, 3)``, ``nbr`` ``(N, k)``; divided by ``k``; squared
    scene units), in closed form.

    The eigenvalue is the least root of the characteristic cubic (its trigonometric
    solution); the eigenvector is the longest cross product of two rows of the
    covariance less that root, which spans the null space when the root is simple; the
    eigenvalue is then refined as the vector's Rayleigh quotient. ``ok[i]`` is False
    where that longest cross product, about ``(l1 - l0) (l2 - l0)`` for eigenvalues
    ``l0 <= l1 <= l2``, is no longer than ``1e-4`` times the squared trace: the two
    least eigenvalues nearly equal (neighbours along a line, or all at one point), the
    axis ill-defined, and the caller decides it otherwise (``normals[i]`` and
    ``least[i]`` left unset)."""
    k = nbr.shape[1]
    for i in range(start, stop):
        mx = 0.0
        my = 0.0
        mz = 0.0
        for c in range(k):
            j = nbr[i, c]
            mx += P[j, 0]
            my += P[j, 1]
            mz += P[j, 2]
        mx /= k
        my /= k
        mz /= k
        a00 = 0.0
        a01 = 0.0
        a02 = 0.0
        a11 = 0.0
        a12 = 0.0
        a22 = 0.0
        for c in range(k):
            j = nbr[i, c]
            dx = P[j, 0] - mx
            dy = P[j, 1] - my
            dz = P[j, 2] - mz
            a00 += dx * dx
            a01 += dx * dy
            a02 += dx * dz
            a11 += dy * dy
            a12 += dy * dz
            a22 += dz * dz
        a00 /= k
        a01 /= k
        a02 /= k
        a11 /= k
        a12 /= k
        a22 /= k
        tr = a00 + a11 + a22
        q = tr / 3.0
        p1 = a01 * a01 + a02 * a02 + a12 * a12
        d0 = a00 - q
        d1 = a11 - q
        d2 = a22 - q
        p = math.sqrt(max((d0 * d0 + d1 * d1 + d2 * d2 + 2.0 * p1) / 6.0, 0.0))
        if p > 0.0:
            det = (d0 * (d1 * d2 - a12 * a12) - a01 * (a01 * d2 - a12 * a02)
                   + a02 * (a01 * a12 - d1 * a02)) / (p * p * p)
            phi = math.acos(min(max(det / 2.0, -1.0), 1.0)) / 3.0
            lam = q + 2.0 * p * math.cos(phi + 2.0 * math.pi / 3.0)
        else:
            lam = q
        b00 = a00 - lam
        b11 = a11 - lam
        b22 = a22 - lam
        # rows (b00, a01, a02), (a01, b11, a12), (a02, a12, b22); their cross products
        x0 = a01 * a12 - a02 * b11
        y0 = a02 * a01 - b00 * a12
        z0 = b00 * b11 - a01 * a01
        x1 = a01 * b22 - a02 * a12
        y1 = a02 * a02 - b00 * b22
        z1 = b00 * a12 - a01 * a02
        x2 = b11 * b22 - a12 * a12
        y2 = a12 * a02 - a01 * b22
        z2 = a01 * a12 - b11 * a02
        n0 = x0 * x0 + y0 * y0 + z0 * z0
        n1 = x1 * x1 + y1 * y1 + z1 * z1
        n2 = x2 * x2 + y2 * y2 + z2 * z2
        if n1 > n0 and n1 >= n2:
            x0, y0, z0, n0 = x1, y1, z1, n1
        elif n2 > n0:
            x0, y0, z0, n0 = x2, y2, z2, n2
        if not (tr > 0.0 and n0 > (1e-4 * tr * tr) ** 2):
            ok[i] = False
            continue
        s = 1.0 / math.sqrt(n0)
        x0 *= s
        y0 *= s
        z0 *= s
        normals[i, 0] = x0
        normals[i, 1] = y0
        normals[i, 2] = z0
        least[i] = (a00 * x0 * x0 + a11 * y0 * y0 + a22 * z0 * z0
                    + 2.0 * (a01 * x0 * y0 + a02 * x0 * z0 + a12 * y0 * z0))
        ok[i] = True
