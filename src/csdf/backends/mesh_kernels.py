"""Numba kernels of the exact signed distance to a closed triangle mesh
(:mod:`csdf.backends.meshdist`).

For each query point: the nearest point of the mesh by a depth-first walk of a bounding
volume hierarchy over the triangles (nearer child first, subtrees pruned when their box
is no nearer than the best triangle so far), the nearest point on each triangle by its
Voronoi regions (vertex, edge or face: Ericson, *Real-Time Collision Detection*, 5.1.5),
and the sign by the angle-weighted pseudonormal of that feature (Baerentzen and Aanaes,
2005): the face normal, the sum of the two face normals at an edge, or the
angle-weighted sum at a vertex; ``(p - c) . n >= 0`` is outside. For a closed,
consistently oriented mesh this sign is exact wherever the nearest point is unique.

Data: ``V`` ``(Nv, 3)`` vertices, ``T`` ``(Nt, 3)`` int64 triangles, ``order``
``(Nt,)`` the triangles in leaf order, ``node_f`` ``(M, 6)`` node boxes, ``node_i``
``(M, 2)`` children or ``(-1 - first, count)`` for leaves (:func:`csdf.bvh.build_bvh`),
``fn`` ``(Nt, 3)`` face normals, ``en`` ``(Ne, 3)`` edge pseudonormals with
``tri_edge`` ``(Nt, 3)`` the edge ids of each triangle's edges ``v0v1, v1v2, v2v0``,
``vn`` ``(Nv, 3)`` vertex pseudonormals.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

_OPTS = dict(nogil=True, cache=True, boundscheck=False, error_model="numpy")
#: traversal stack depth (the tree is balanced: depth ~ log2(triangles / leaf) + 1)
STACK = 96

# nearest feature of a triangle: 0 the face, 1-3 edges v0v1, v1v2, v2v0, 4-6 vertices
FACE, EDGE01, EDGE12, EDGE20, VERT0, VERT1, VERT2 = 0, 1, 2, 3, 4, 5, 6


@njit(**_OPTS)
def _box_d2(p0, p1, p2, node_f, k):
    s = 0.0
    for ax in range(3):
        v = p0 if ax == 0 else (p1 if ax == 1 else p2)
        lo = node_f[k, ax]
        hi = node_f[k, 3 + ax]
        if v < lo:
            s += (lo - v) * (lo - v)
        elif v > hi:
            s += (v - hi) * (v - hi)
    return s


@njit(**_OPTS)
def closest_on_triangle(p0, p1, p2, a0, a1, a2, b0, b1, b2, c0, c1, c2):
    """``(x, y, z, feature)``: the point of triangle ``abc`` nearest to ``p`` and the
    feature it lies on (:data:`FACE`, an edge or a vertex)."""
    ab0, ab1, ab2 = b0 - a0, b1 - a1, b2 - a2
    ac0, ac1, ac2 = c0 - a0, c1 - a1, c2 - a2
    ap0, ap1, ap2 = p0 - a0, p1 - a1, p2 - a2
    d1 = ab0 * ap0 + ab1 * ap1 + ab2 * ap2
    d2 = ac0 * ap0 + ac1 * ap1 + ac2 * ap2
    if d1 <= 0.0 and d2 <= 0.0:
        return a0, a1, a2, VERT0
    bp0, bp1, bp2 = p0 - b0, p1 - b1, p2 - b2
    d3 = ab0 * bp0 + ab1 * bp1 + ab2 * bp2
    d4 = ac0 * bp0 + ac1 * bp1 + ac2 * bp2
    if d3 >= 0.0 and d4 <= d3:
        return b0, b1, b2, VERT1
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return a0 + v * ab0, a1 + v * ab1, a2 + v * ab2, EDGE01
    cp0, cp1, cp2 = p0 - c0, p1 - c1, p2 - c2
    d5 = ab0 * cp0 + ab1 * cp1 + ab2 * cp2
    d6 = ac0 * cp0 + ac1 * cp1 + ac2 * cp2
    if d6 >= 0.0 and d5 <= d6:
        return c0, c1, c2, VERT2
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        return a0 + w * ac0, a1 + w * ac1, a2 + w * ac2, EDGE20
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return b0 + w * (c0 - b0), b1 + w * (c1 - b1), b2 + w * (c2 - b2), EDGE12
    denom = 1.0 / (va + vb + vc)
    v = vb * denom
    w = vc * denom
    return (a0 + ab0 * v + ac0 * w, a1 + ab1 * v + ac1 * w, a2 + ab2 * v + ac2 * w, FACE)


@njit(**_OPTS)
def _nearest(p0, p1, p2, V, T, order, node_f, node_i, stack):
    """``(d2, x, y, z, triangle, feature)`` of the nearest mesh point to ``p``."""
    best = np.inf
    bx = by = bz = 0.0
    bt = -1
    bf = 0
    sp = 0
    stack[sp] = 0
    sp += 1
    while sp > 0:
        sp -= 1
        k = stack[sp]
        if _box_d2(p0, p1, p2, node_f, k) >= best:
            continue
        c0 = node_i[k, 0]
        if c0 < 0:  # a leaf
            first = -1 - c0
            for j in range(first, first + node_i[k, 1]):
                t = order[j]
                ia, ib, ic = T[t, 0], T[t, 1], T[t, 2]
                x, y, z, f = closest_on_triangle(
                    p0, p1, p2, V[ia, 0], V[ia, 1], V[ia, 2], V[ib, 0], V[ib, 1], V[ib, 2],
                    V[ic, 0], V[ic, 1], V[ic, 2])
                d2 = (p0 - x) * (p0 - x) + (p1 - y) * (p1 - y) + (p2 - z) * (p2 - z)
                if d2 < best:
                    best, bx, by, bz, bt, bf = d2, x, y, z, t, f
            continue
        c1 = node_i[k, 1]
        e0 = _box_d2(p0, p1, p2, node_f, c0)
        e1 = _box_d2(p0, p1, p2, node_f, c1)
        # push the farther child first: the nearer one is walked first
        if e0 <= e1:
            if e1 < best:
                stack[sp] = c1
                sp += 1
            if e0 < best:
                stack[sp] = c0
                sp += 1
        else:
            if e0 < best:
                stack[sp] = c0
                sp += 1
            if e1 < best:
                stack[sp] = c1
                sp += 1
    return best, bx, by, bz, bt, bf


@njit(**_OPTS)
def _pseudonormal(t, f, T, fn, en, tri_edge, vn):
    if f == FACE:
        return fn[t, 0], fn[t, 1], fn[t, 2]
    if f <= EDGE20:
        e = tri_edge[t, f - 1]
        return en[e, 0], en[e, 1], en[e, 2]
    v = T[t, f - VERT0]
    return vn[v, 0], vn[v, 1], vn[v, 2]


@njit(parallel=True, **_OPTS)
def signed_distance(P, V, T, order, node_f, node_i, fn, en, tri_edge, vn, out, grad,
                    closest, want_grad, want_closest):
    """Signed distances ``out`` ``(N,)`` of the points ``P`` ``(N, 3)``; with
    ``want_grad`` their gradients into ``grad`` ``(N, 3)`` (the face's normal where a
    face is nearest; else the unit direction from the nearest point, signed, and the
    feature's pseudonormal on the surface); with
    ``want_closest`` the nearest points into ``closest`` ``(N, 3)``."""
    n = P.shape[0]
    for i in prange(n):
        stack = np.empty(STACK, dtype=np.int64)
        p0, p1, p2 = P[i, 0], P[i, 1], P[i, 2]
        d2, x, y, z, t, f = _nearest(p0, p1, p2, V, T, order, node_f, node_i, stack)
        n0, n1, n2 = _pseudonormal(t, f, T, fn, en, tri_edge, vn)
        w0, w1, w2 = p0 - x, p1 - y, p2 - z
        s = 1.0 if w0 * n0 + w1 * n1 + w2 * n2 >= 0.0 else -1.0
        d = np.sqrt(d2)
        out[i] = s * d
        if want_grad:
            if f == FACE:
                # the signed distance is (p - c) . n wherever the face is nearest, so
                # its gradient is the face normal, on the surface too (where p - c is
                # rounding and its direction arbitrary)
                grad[i, 0] = n0
                grad[i, 1] = n1
                grad[i, 2] = n2
            elif d > 0.0:
                grad[i, 0] = s * w0 / d
                grad[i, 1] = s * w1 / d
                grad[i, 2] = s * w2 / d
            else:
                m = np.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
                grad[i, 0] = n0 / m
                grad[i, 1] = n1 / m
                grad[i, 2] = n2 / m
        if want_closest:
            closest[i, 0] = x
            closest[i, 1] = y
            closest[i, 2] = z
