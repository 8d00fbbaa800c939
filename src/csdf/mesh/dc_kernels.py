"""Compiled (Numba) cores of manifold dual contouring (``method='dc'`` with the fast backend).

The same computation as :func:`csdf.mesh.reference._dual_contour` (tested equal to it), on
the arrays that :func:`csdf.mesh.reference.extract` builds, without its ``(pairs, ...)``
temporaries, ``ufunc.at``, batched SVD or sorted searches:

* :func:`dc_vertices_range`: one vertex per surface component of each active voxel (ids in
  (voxel, component) order, as ``np.unique`` gives them), its quadric accumulated in the
  same order as ``np.add.at``, minimised by the pseudo-inverse of the 3x3 normal matrix
  (a symmetric positive semi-definite matrix, so its SVD is its eigendecomposition, found
  by cyclic Jacobi rotations) with the same relative cut-off ``0.05`` of the largest
  singular value around the component's mass point, then clamped to half a voxel around
  its voxel; and for every crossed edge the quad of the four vertices around it, found
  by scattering each (voxel, edge) pair into its slot of the edge's quad (no search);
* :func:`dc_quads`, :func:`dc_midpoints`: the complete quads, wound by the edge's sign,
  and the midpoints of both diagonals (where the field is evaluated);
* :func:`dc_split`: each quad split along the diagonal whose midpoint is nearer the
  surface (first triangles, then second triangles, as the NumPy path orders them).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from . import kernels as K

__all__ = [
    "dc_chunk", "dc_vertices_range", "dc_case_tables", "dc_found", "dc_quads",
    "dc_midpoints", "dc_split", "edge_flags", "sym_eig3", "newton_step", "has_short_edge",
]

_CUT = 0.05  # singular values below this fraction of the largest are dropped (as NumPy)


@njit(cache=True, nogil=True)
def sym_eig3(a: np.ndarray, v: np.ndarray) -> None:
    """In place: eigendecomposition of the symmetric ``a (3, 3)`` by cyclic Jacobi
    rotations. On return ``a``'s diagonal holds the eigenvalues and ``v (3, 3)``'s
    columns the orthonormal eigenvectors (``a_in = v diag(a) v^T``)."""
    for i in range(3):
        for j in range(3):
            v[i, j] = 1.0 if i == j else 0.0
    for _ in range(60):
        off = a[0, 1] * a[0, 1] + a[0, 2] * a[0, 2] + a[1, 2] * a[1, 2]
        diag = a[0, 0] * a[0, 0] + a[1, 1] * a[1, 1] + a[2, 2] * a[2, 2]
        if off == 0.0 or off <= 1e-36 * diag:
            return
        for p, q in ((0, 1), (0, 2), (1, 2)):
            apq = a[p, q]
            if apq == 0.0:
                continue
            theta = (a[q, q] - a[p, p]) / (2.0 * apq)
            if abs(theta) > 1e150:
                t = 0.5 / theta
            else:
                t = 1.0 / (abs(theta) + np.sqrt(theta * theta + 1.0))
                if theta < 0.0:
                    t = -t
            c = 1.0 / np.sqrt(t * t + 1.0)
            s = t * c
            for k in range(3):  # a <- a P (columns p, q)
                akp = a[k, p]
                akq = a[k, q]
                a[k, p] = c * akp - s * akq
                a[k, q] = s * akp + c * akq
            for k in range(3):  # a <- P^T a (rows p, q)
                apk = a[p, k]
                aqk = a[q, k]
                a[p, k] = c * apk - s * aqk
                a[q, k] = s * apk + c * aqk
            for k in range(3):  # v <- v P
                vkp = v[k, p]
                vkq = v[k, q]
                v[k, p] = c * vkp - s * vkq
                v[k, q] = s * vkp + c * vkq


@njit(cache=True, nogil=True)
def dc_case_tables(comp_table, max_components):
    """``(rank (256, K), n_comp (256,), n_pairs (256,))``: for each case the vertex of
    each surface component among the case's components (ascending), the number of
    components and the number of crossed edges."""
    rank = np.full((256, max_components), -1, dtype=np.int64)
    n_comp = np.zeros(256, dtype=np.int64)
    n_pairs = np.zeros(256, dtype=np.int64)
    for c in range(256):
        for k in range(max_components):
            for e in range(12):
                if comp_table[c, e] == k:
                    rank[c, k] = n_comp[c]
                    n_comp[c] += 1
                    break
        for e in range(12):
            if comp_table[c, e] >= 0:
                n_pairs[c] += 1
    return rank, n_comp, n_pairs


@njit(cache=True, nogil=True)
def dc_found(quads):
    """Bit mask ``(E,)`` int8 of the quad corners found (``quads (E, 4) >= 0``)."""
    found = np.zeros(quads.shape[0], dtype=np.int8)
    for u in range(quads.shape[0]):
        m = 0
        for q in range(4):
            if quads[u, q] >= 0:
                m |= 1 << q
        found[u] = m
    return found


@njit(cache=True, nogil=True)
def dc_vertices_range(a0, a1, p0, base0, vox, vcase, inv, roots, normals, uaxis,
                      comp_table, edge_origin, origin, h, rank, n_comp, verts, quads):
    """Dual-contouring vertices and the quad corners of the voxels ``[a0, a1)``, whose
    pairs start at ``p0`` and vertices at ``base0`` (the counts over the voxels before
    ``a0``): writes their rows of ``verts`` and their corners of ``quads``. Each (edge,
    corner) slot belongs to one voxel, so disjoint ranges can run on separate threads.

    A voxel's pairs are consecutive, so each voxel's quadrics are summed (in the pairs'
    order, as ``np.add.at`` sums them) and solved before the next voxel's.

    Args:
        vox: ``(A, 3)`` int64 active voxels (lower sample corner); vcase ``(A,)`` their
            marching-cubes cases.
        inv: ``(P,)`` unique edge of each (voxel, crossed local edge) pair, the pairs in
            (voxel, local edge) order (``np.nonzero(COMPONENT_TABLE[vcase] >= 0)``).
        roots, normals: ``(E, 3)`` float64 root and unit normal of each unique edge;
            uaxis ``(E,)`` its axis.
        comp_table: ``(256, 12)`` component of each crossed edge (-1: not crossed);
            edge_origin ``(12, 3)``: lower corner of each local edge.
        origin ``(3,)``, h: the grid; rank, n_comp: :func:`dc_case_tables`.
        verts: ``(V, 3)`` float64, written: the clamped QEF vertices in (voxel,
            component) order.
        quads: ``(E, 4)`` int64, -1 where no voxel has written: for each edge the
            vertex of the voxel at each corner of its quad (``(du, dv) = (0, 0), (1, 0),
            (1, 1), (0, 1)`` voxels below it along the axes after its own).
    """
    max_components = rank.shape[1]
    A = np.zeros((max_components, 6))  # xx, xy, xz, yy, yz, zz
    bvec = np.zeros((max_components, 3))
    mass = np.zeros((max_components, 3))
    cnt = np.zeros(max_components)
    m = np.empty((3, 3))
    vec = np.empty((3, 3))
    rhs = np.empty(3)
    ms = np.empty(3)
    p = p0
    base = base0
    for a in range(a0, a1):
        c = vcase[a]
        A[:] = 0.0
        bvec[:] = 0.0
        mass[:] = 0.0
        cnt[:] = 0.0
        for e in range(12):
            k = comp_table[c, e]
            if k < 0:
                continue
            r = rank[c, k]
            u = inv[p]
            p += 1
            nx, ny, nz = normals[u, 0], normals[u, 1], normals[u, 2]
            px, py, pz = roots[u, 0], roots[u, 1], roots[u, 2]
            A[r, 0] += nx * nx
            A[r, 1] += nx * ny
            A[r, 2] += nx * nz
            A[r, 3] += ny * ny
            A[r, 4] += ny * nz
            A[r, 5] += nz * nz
            d = nx * px + ny * py + nz * pz
            bvec[r, 0] += nx * d
            bvec[r, 1] += ny * d
            bvec[r, 2] += nz * d
            mass[r, 0] += px
            mass[r, 1] += py
            mass[r, 2] += pz
            cnt[r] += 1.0
            ax = uaxis[u]
            du = edge_origin[e, (ax + 1) % 3]
            dv = edge_origin[e, (ax + 2) % 3]
            q = (0 if dv == 0 else 3) if du == 0 else (1 if dv == 0 else 2)
            quads[u, q] = base + r
        for r in range(n_comp[c]):
            v = base + r
            for i in range(3):
                ms[i] = mass[r, i] / cnt[r]
            m[0, 0], m[0, 1], m[0, 2] = A[r, 0], A[r, 1], A[r, 2]
            m[1, 0], m[1, 1], m[1, 2] = A[r, 1], A[r, 3], A[r, 4]
            m[2, 0], m[2, 1], m[2, 2] = A[r, 2], A[r, 4], A[r, 5]
            for i in range(3):
                rhs[i] = bvec[r, i] - (m[i, 0] * ms[0] + m[i, 1] * ms[1] + m[i, 2] * ms[2])
            sym_eig3(m, vec)
            smax = max(abs(m[0, 0]), abs(m[1, 1]), abs(m[2, 2]))
            cut = _CUT * max(smax, 1e-300)
            x0, x1, x2 = ms[0], ms[1], ms[2]
            for j in range(3):
                s = abs(m[j, j])
                if s > cut and s > 0.0:
                    w = (vec[0, j] * rhs[0] + vec[1, j] * rhs[1] + vec[2, j] * rhs[2]) / s
                    x0 += vec[0, j] * w
                    x1 += vec[1, j] * w
                    x2 += vec[2, j] * w
            # keep the vertex within half a voxel of its voxel
            for i, xi in enumerate((x0, x1, x2)):
                lo = (origin[i] + vox[a, i] * h) - 0.5 * h
                hi = (origin[i] + (vox[a, i] + 1) * h) + 0.5 * h
                verts[v, i] = min(max(xi, lo), hi)
        base += n_comp[c]


@njit(cache=True, nogil=True)
def dc_quads(quads, found, f0):
    """The complete quads ``(Q, 4)`` of ``quads (E, 4)`` (all four corners found:
    ``found (E,) == 15``), reversed where the edge's lower end is outside
    (``f0 (E,) >= 0``)."""
    n = 0
    for u in range(quads.shape[0]):
        if found[u] == 15:
            n += 1
    out = np.empty((n, 4), dtype=np.int64)
    r = 0
    for u in range(quads.shape[0]):
        if found[u] != 15:
            continue
        for q in range(4):
            out[r, q] = quads[u, 3 - q] if f0[u] >= 0 else quads[u, q]
        r += 1
    return out


@njit(cache=True, nogil=True)
def dc_midpoints(quads, verts):
    """Midpoints ``(2 m, 3)`` of the diagonals 0-2 (first ``m`` rows) and 1-3 of quads
    ``(m, 4)`` with vertices ``verts (V, 3)``."""
    m = quads.shape[0]
    mid = np.empty((2 * m, 3))
    for r in range(m):
        for i in range(3):
            mid[r, i] = 0.5 * (verts[quads[r, 0], i] + verts[quads[r, 2], i])
            mid[m + r, i] = 0.5 * (verts[quads[r, 1], i] + verts[quads[r, 3], i])
    return mid


@njit(cache=True, nogil=True)
def dc_split(quads, fm, tie):
    """Triangles ``(2 Q, 3)`` of quads ``(Q, 4)``: along diagonal 0-2 where
    ``|f(mid02)| <= |f(mid13)| + tie`` (``fm (2 Q,)``), else 1-3; first triangles, then
    second."""
    n = quads.shape[0]
    faces = np.empty((2 * n, 3), dtype=np.int64)
    for r in range(n):
        q0, q1, q2, q3 = quads[r, 0], quads[r, 1], quads[r, 2], quads[r, 3]
        if abs(fm[r]) <= abs(fm[n + r]) + tie:
            faces[r, 0], faces[r, 1], faces[r, 2] = q0, q1, q2
            faces[n + r, 0], faces[n + r, 1], faces[n + r, 2] = q0, q2, q3
        else:
            faces[r, 0], faces[r, 1], faces[r, 2] = q0, q1, q3
            faces[n + r, 0], faces[n + r, 1], faces[n + r, 2] = q1, q2, q3
    return faces


@njit(cache=True, nogil=True)
def _dc_brick(b, bricks, vals, nby, nbz, edge_origin, edge_axis, comp_table, table, n_used,
              vert_base, stamp, slot_vid, e_corner, e_axis, e_f0, e_f1, n_new, vox, vcase,
              n_vox, pairs, n_pairs, masks):
    """The active voxels of brick ``b`` of :func:`dc_chunk` (arrays with room for them).
    Crossed edges get vertex ids exactly as :func:`csdf.mesh.kernels.mc_chunk` gives them
    (per-brick scratch slots, the hash map for edges on brick faces). Returns the new
    ``(n_new, n_used, n_vox, n_pairs)``."""
    n = vals.shape[1]
    B = n - 1
    bx, by, bz = bricks[b, 0], bricks[b, 1], bricks[b, 2]
    K.neg_columns(vals, b, masks)
    for x in range(B):
        for y in range(B):
            m0 = masks[x, y]
            m1 = masks[x + 1, y]
            m2 = masks[x, y + 1]
            m3 = masks[x + 1, y + 1]
            crossed = K.column_crossed(m0, m1, m2, m3, B)
            while crossed:
                z = K.lowest_bit(crossed)
                crossed &= crossed - 1
                case = K.voxel_case(m0, m1, m2, m3, z)
                vox[n_vox, 0] = bricks[b, 0] + x
                vox[n_vox, 1] = bricks[b, 1] + y
                vox[n_vox, 2] = bricks[b, 2] + z
                vcase[n_vox] = case
                n_vox += 1
                for e in range(12):
                    if comp_table[case, e] < 0:
                        continue
                    # the vertex id of the edge, as kernels._mc_brick numbers it: the
                    # key is the shared scalar helper; the table and buffer updates stay
                    # inline in both (a Numba helper taking these arrays made the
                    # marching-cubes kernel 2.5-8x slower, measured)
                    a = edge_axis[e]
                    lx = x + edge_origin[e, 0]
                    ly = y + edge_origin[e, 1]
                    lz = z + edge_origin[e, 2]
                    s = ((a * n + lx) * n + ly) * n + lz
                    if stamp[s] != b:
                        stamp[s] = b
                        key = K.face_key(bx, by, bz, lx, ly, lz, a, B, nby, nbz)
                        on_face = key >= 0
                        vid = -1
                        hs = 0
                        if on_face:
                            hs = K._slot(table, key)
                            if table[hs, 0] == key:
                                vid = table[hs, 1]
                            else:
                                table[hs, 0] = key
                                n_used += 1
                        if vid < 0:
                            vid = vert_base + n_new
                            if on_face:
                                table[hs, 1] = vid
                            e_corner[n_new, 0] = bx + lx
                            e_corner[n_new, 1] = by + ly
                            e_corner[n_new, 2] = bz + lz
                            e_axis[n_new] = a
                            e_f0[n_new] = vals[b, lx, ly, lz]
                            e_f1[n_new] = vals[b, lx + (a == 0), ly + (a == 1),
                                               lz + (a == 2)]
                            n_new += 1
                        slot_vid[s] = vid
                    pairs[n_pairs] = slot_vid[s]
                    n_pairs += 1
    return n_new, n_used, n_vox, n_pairs


@njit(cache=True, nogil=True)
def dc_chunk(bricks, vals, dims, edge_origin, edge_axis, comp_table, table, n_used,
             vert_base, e_corner, e_axis, e_f0, e_f1, vox, vcase, n_vox, pairs, n_pairs):
    """The active voxels of one chunk of bricks and their crossed edges' vertex ids.

    Args:
        bricks, vals, dims, edge_origin, edge_axis, table, n_used, vert_base, e_corner,
            e_axis, e_f0, e_f1: as for :func:`csdf.mesh.kernels.mc_chunk` (the same edge
            numbering); comp_table ``(256, 12)``: component of each crossed edge.
        vox ``(Acap, 3)`` int64, vcase ``(Acap,)`` int64 with ``n_vox`` rows used: active
            voxels (lower sample corner) and their cases; pairs ``(Pcap,)`` int64 with
            ``n_pairs`` used: the vertex id of each (active voxel, crossed local edge), in
            (voxel, local edge) order.

    Returns:
        ``(table, n_used, e_corner, e_axis, e_f0, e_f1, E, vox, vcase, n_vox, pairs,
        n_pairs)``: the (possibly grown) arrays; the edge buffers' first ``E`` rows are
        the chunk's new edges, in vertex-id order.
    """
    n = vals.shape[1]
    B = n - 1
    nby = dims[1] // B + 2  # bricks per axis, with room for the upper faces
    nbz = dims[2] // B + 2
    n_slots = 3 * n * n * n
    stamp = np.full(n_slots, -1, dtype=np.int64)
    slot_vid = np.zeros(n_slots, dtype=np.int32)
    masks = np.empty((n, n), dtype=np.int64)
    n_new = 0
    for b in range(bricks.shape[0]):
        while 2 * (n_used + n_slots) > table.shape[0]:
            table = K._rehash(table)
        vox = K._grow2(vox, n_vox + B * B * B)
        vcase = K._grow1(vcase, n_vox + B * B * B)
        pairs = K._grow1(pairs, n_pairs + 12 * B * B * B)
        if n_new + n_slots > e_axis.shape[0]:
            e_corner = K._grow2(e_corner, n_new + n_slots)
            e_axis = K._grow1(e_axis, n_new + n_slots)
            e_f0 = K._grow1(e_f0, n_new + n_slots)
            e_f1 = K._grow1(e_f1, n_new + n_slots)
        n_new, n_used, n_vox, n_pairs = _dc_brick(
            b, bricks, vals, nby, nbz, edge_origin, edge_axis, comp_table, table, n_used,
            vert_base, stamp, slot_vid, e_corner, e_axis, e_f0, e_f1, n_new, vox, vcase,
            n_vox, pairs, n_pairs, masks)
    return (table, n_used, e_corner, e_axis, e_f0, e_f1, n_new, vox, vcase, n_vox, pairs,
            n_pairs)


@njit(cache=True, nogil=True)
def edge_flags(e_corner, e_axis, dims, on_box):
    """In place ``on_box (E,)``: 1 where edge ``(E, 3)``/``(E,)`` touches the grid's outer
    faces (an end on or beyond them), else 0."""
    for r in range(e_corner.shape[0]):
        flag = 0
        for d in range(3):
            c = e_corner[r, d]
            c1 = c + (1 if e_axis[r] == d else 0)
            if c <= 0 or c1 <= 0 or c >= dims[d] or c1 >= dims[d]:
                flag = 1
        on_box[r] = flag


@njit(cache=True, nogil=True)
def newton_step(verts, f, g, h):
    """In place, one step ``v -= f grad f / |grad f|^2`` towards the zero set, limited to
    half a voxel; a non-finite component of the step counts as 0 (the arithmetic and
    its order are those of :func:`csdf.mesh.reference._project`). ``verts, g (V, 3)``,
    ``f (V,)``."""
    for r in range(verts.shape[0]):
        g0, g1, g2 = g[r, 0], g[r, 1], g[r, 2]
        gg = g0 * g0 + g1 * g1 + g2 * g2
        k = f[r] / gg if gg > 0 else 0.0
        s0, s1, s2 = k * g0, k * g1, k * g2
        n = np.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
        if n > 0.5 * h:
            c = 0.5 * h / max(n, 1e-300)
            s0, s1, s2 = s0 * c, s1 * c, s2 * c
        verts[r, 0] -= _finite(s0)
        verts[r, 1] -= _finite(s1)
        verts[r, 2] -= _finite(s2)


@njit(cache=True, nogil=True, inline="always")
def _finite(x):
    """``np.nan_to_num`` of a scalar."""
    if np.isnan(x):
        return 0.0
    if np.isinf(x):
        return 1.7976931348623157e308 if x > 0 else -1.7976931348623157e308
    return x


@njit(cache=True, nogil=True)
def has_short_edge(verts, faces, min2):
    """True when some triangle edge of ``faces (F, 3)`` over ``verts (V, 3)`` has squared
    length below ``min2`` (one pass, no temporaries; see
    :func:`csdf.mesh.api.separate_close_vertices`)."""
    for r in range(faces.shape[0]):
        for k in range(3):
            a = faces[r, k]
            b = faces[r, (k + 1) % 3]
            d0 = verts[a, 0] - verts[b, 0]
            d1 = verts[a, 1] - verts[b, 1]
            d2 = verts[a, 2] - verts[b, 2]
            if d0 * d0 + d1 * d1 + d2 * d2 < min2:
                return True
    return False
