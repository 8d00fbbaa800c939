"""Compiled (Numba) cores of the sparse marching-cubes mesher (see :mod:`.stream`).

Everything here works on one *chunk* of bricks at a time (a brick is ``B^3`` voxels,
``(B+1)^3`` samples, lower sample corner ``brick (3,)``), so memory stays bounded by the
chunk plus the outputs:

* :func:`brick_points`: the sample coordinates of a chunk's bricks;
* :func:`close_on_box`: samples on the grid's outer faces count as outside;
* :func:`mc_chunk`: marching cubes over the chunk's voxels. Each crossed grid edge gets
  one vertex id: edges inside a brick are unique to it (a per-brick scratch table),
  edges on a brick's faces may be shared with a neighbouring brick and are looked up in
  an open-addressing hash map keyed by the edge (the brick holding its lower end and
  its index there), so no global sort or ``unique`` is needed and shared edges give
  the same vertex (watertight);
* :func:`root_points`, :func:`root_update`, :func:`clip_to_box`: the bracketed
  Illinois / bisection root search on each new edge (the same iteration as
  :func:`csdf.mesh.reference._refine_roots`), driven from Python because the field is
  evaluated by the program's own backend.

* :func:`fresh_array`: the big outputs on memory maps of their own.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..memory import map_array, private_map

__all__ = [
    "all_points", "edge_coord", "brick_points", "brick_points_into", "close_on_box",
    "mc_chunk", "new_hash",
    "root_points", "root_start", "root_update", "clip_to_box", "edges_on_box", "fresh_array",
    "neg_columns", "column_crossed", "voxel_case", "lowest_bit", "face_index", "face_key",
]

_EMPTY = -1
# Hash keys of edges on brick faces: (brick index << _LOCAL_BITS) | face_index(...), the
# brick being the one that holds the edge's lower end, numbered x-major like the sweep
# (bricks sorted by x, y, z). The slot is brick index * _STRIDE + face index, modulo
# the table: a brick's face edges sit side by side, and the sweep's working set (the
# brick and its +x, +y, +z neighbours) is three regions that advance through the table
# in step with it, instead of random lines (measured at 1024^3: a scattering hash made
# the kernel ~6x slower than at 512^3 for 4x the work, cache and TLB misses)
_LOCAL_BITS = 12  # room for the face index (3 B (2B - 1) <= 4096: B <= 26)
_LOCAL_MASK = (1 << _LOCAL_BITS) - 1
_STRIDE = 361  # >= 3 B (2B - 1) for B = 8; odd, so it does not alias power-of-two grids


def new_hash(capacity: int) -> np.ndarray:
    """An empty edge hash map ``(H, 2)`` int64: rows ``(key, vertex id)``, key -1 = empty
    (key and value side by side: one cache line per probe); ``H`` is the power of two at
    or above ``capacity``."""
    h = 1 << max(10, int(capacity - 1).bit_length())
    table = fresh_array((h, 2), np.int64, huge=True)
    table[:, 0] = _EMPTY
    return table


def fresh_array(shape: tuple[int, ...], dtype, huge: bool = False) -> np.ndarray:
    """``np.empty(shape, dtype)``; a large array gets its own private anonymous memory
    map, advised to use transparent huge pages when ``huge`` (``MADV_HUGEPAGE``, where
    the OS has it).

    Why a map of its own: pages never written cost address space only, so generous
    capacities (the faces, the vertices) are cheap and never copied. Why huge pages only
    on request: 2 MB pages make the first writes ~5x cheaper and random access (the edge
    hash map) cheaper still, when the OS has free huge pages; when it has to compact
    memory first a fault can stall for a long time (measured on the benchmark VM: the
    512^3 mesh took 0.44-0.61 s with every output on huge pages, 0.25-0.37 s with only
    the hash map on them, in that state). NumPy itself advises huge pages for every
    array of 4 MB or more.
    """
    dtype = np.dtype(dtype)
    nbytes = int(np.prod(shape)) * dtype.itemsize
    if nbytes < (4 << 20):
        return np.empty(shape, dtype)
    return map_array(private_map(nbytes, huge), shape, dtype)


@njit(cache=True, nogil=True, inline="always")
def _slot(table: np.ndarray, key: np.int64) -> int:
    """Row of ``key`` in the table, or the empty row where it would go (linear probing)."""
    mask = table.shape[0] - 1
    s = ((key >> _LOCAL_BITS) * _STRIDE + (key & _LOCAL_MASK)) & mask
    while table[s, 0] != key and table[s, 0] != _EMPTY:
        s = (s + 1) & mask
    return s


@njit(cache=True, nogil=True)
def _rehash(table: np.ndarray) -> np.ndarray:
    out = np.empty((table.shape[0] * 2, 2), dtype=np.int64)
    out[:, 0] = _EMPTY
    for i in range(table.shape[0]):
        if table[i, 0] != _EMPTY:
            s = _slot(out, table[i, 0])
            out[s, 0] = table[i, 0]
            out[s, 1] = table[i, 1]
    return out


@njit(cache=True, nogil=True)
def brick_points(bricks: np.ndarray, origin: np.ndarray, h: float, B: int) -> np.ndarray:
    """Sample coordinates ``(C * (B+1)^3, 3)`` float64 of bricks ``(C, 3)`` (lower sample
    corners); sample ``(i, j, k)`` of brick ``b`` is row ``((b n + i) n + j) n + k``,
    ``n = B + 1``, at ``origin + (brick + (i, j, k)) * h``."""
    n = B + 1
    out = np.empty((bricks.shape[0] * n * n * n, 3))
    brick_points_into(bricks, origin, h, B, out)
    return out


@njit(cache=True, nogil=True)
def brick_points_into(bricks: np.ndarray, origin: np.ndarray, h: float, B: int,
                      out: np.ndarray) -> None:
    """:func:`brick_points` written into the first rows of ``out``."""
    n = B + 1
    r = 0
    for b in range(bricks.shape[0]):
        for i in range(n):
            x = origin[0] + (bricks[b, 0] + i) * h
            for j in range(n):
                y = origin[1] + (bricks[b, 1] + j) * h
                for k in range(n):
                    out[r, 0] = x
                    out[r, 1] = y
                    out[r, 2] = origin[2] + (bricks[b, 2] + k) * h
                    r += 1


@njit(cache=True, nogil=True)
def close_on_box(bricks: np.ndarray, vals: np.ndarray, dims: np.ndarray, h: float) -> None:
    """In place: samples on the grid's outer faces get ``max(f, h)`` (outside), which
    closes the surface on the grid box. ``vals (C, n, n, n)``."""
    n = vals.shape[1]
    for b in range(bricks.shape[0]):
        if (bricks[b, 0] > 0 and bricks[b, 1] > 0 and bricks[b, 2] > 0
                and bricks[b, 0] + n - 1 < dims[0] and bricks[b, 1] + n - 1 < dims[1]
                and bricks[b, 2] + n - 1 < dims[2]):
            continue  # no sample on the box
        for i in range(n):
            gi = bricks[b, 0] + i
            for j in range(n):
                gj = bricks[b, 1] + j
                for k in range(n):
                    gk = bricks[b, 2] + k
                    if (gi <= 0 or gj <= 0 or gk <= 0 or gi >= dims[0] or gj >= dims[1]
                            or gk >= dims[2]):
                        if vals[b, i, j, k] < h:
                            vals[b, i, j, k] = h


@njit(cache=True, nogil=True)
def _grow2(a: np.ndarray, need: int) -> np.ndarray:
    if need <= a.shape[0]:
        return a
    cap = max(need, 2 * a.shape[0])
    out = np.empty((cap, a.shape[1]), dtype=a.dtype)
    out[: a.shape[0]] = a
    return out


@njit(cache=True, nogil=True)
def _grow1(a: np.ndarray, need: int) -> np.ndarray:
    if need <= a.shape[0]:
        return a
    out = np.empty(max(need, 2 * a.shape[0]), dtype=a.dtype)
    out[: a.shape[0]] = a
    return out


@njit(cache=True, nogil=True, inline="always")
def neg_columns(vals: np.ndarray, b: int, masks: np.ndarray) -> None:
    """``masks[x, y]``: bit ``z`` set where sample ``(x, y, z)`` of brick ``b`` is inside
    (``f < 0``); ``vals (C, n, n, n)``, ``masks (n, n)`` int64."""
    n = vals.shape[1]
    for x in range(n):
        for y in range(n):
            m = 0
            for z in range(n):
                if vals[b, x, y, z] < 0:
                    m |= 1 << z
            masks[x, y] = m


@njit(cache=True, nogil=True, inline="always")
def column_crossed(m0: int, m1: int, m2: int, m3: int, B: int) -> int:
    """Bit ``z`` set where voxel ``z`` of a column (corner masks ``m0..m3`` of its four
    sample columns, :func:`neg_columns`) has corners both inside and outside."""
    a = m0 & m1 & m2 & m3
    o = m0 | m1 | m2 | m3
    return ((o | (o >> 1)) & ~(a & (a >> 1))) & ((1 << B) - 1)


@njit(cache=True, nogil=True, inline="always")
def voxel_case(m0: int, m1: int, m2: int, m3: int, z: int) -> int:
    """The corner pattern of voxel ``z`` of a column (bit ``c`` = corner ``c`` inside,
    corner ``c`` at ``(c & 1, c >> 1 & 1, c >> 2 & 1)``)."""
    return (((m0 >> z) & 1) | (((m1 >> z) & 1) << 1) | (((m2 >> z) & 1) << 2)
            | (((m3 >> z) & 1) << 3) | (((m0 >> z) & 2) << 3) | (((m1 >> z) & 2) << 4)
            | (((m2 >> z) & 2) << 5) | (((m3 >> z) & 2) << 6))


@njit(cache=True, nogil=True, inline="always")
def lowest_bit(m: int) -> int:
    """Index of the lowest set bit of ``m > 0``."""
    z = 0
    while not (m >> z) & 1:
        z += 1
    return z


@njit(cache=True, nogil=True, inline="always")
def face_key(bx: int, by: int, bz: int, lx: int, ly: int, lz: int, a: int, B: int,
             nby: int, nbz: int) -> int:
    """Hash key of the edge at local sample ``(lx, ly, lz)``, axis ``a``, of the brick at
    lower sample corner ``(bx, by, bz)``: the brick holding the edge's lower end (x-major
    index over ``nby, nbz`` bricks per y, z) and the edge's :func:`face_index` there; -1
    for an edge inside the brick (no other brick has it). The one numbering of shared
    edges for marching cubes and dual contouring."""
    if not ((a != 0 and (lx == 0 or lx == B)) or (a != 1 and (ly == 0 or ly == B))
            or (a != 2 and (lz == 0 or lz == B))):
        return -1
    qx, rx = divmod(bx + lx, B)
    qy, ry = divmod(by + ly, B)
    qz, rz = divmod(bz + lz, B)
    return (((qx * nby + qy) * nbz + qz) << _LOCAL_BITS) | face_index(rx, ry, rz, a, B)


@njit(cache=True, nogil=True, inline="always")
def face_index(rx: int, ry: int, rz: int, a: int, B: int) -> int:
    """Index ``0 .. 3 B (2B - 1) - 1`` of an edge on a brick's lower faces: axis ``a``,
    lower end at local sample ``r`` (``r[a] < B``, the other two ``< B`` and one of them
    0). Compact, so a brick's face edges sit side by side in the hash map."""
    if a == 0:
        ra, ru, rv = rx, ry, rz
    elif a == 1:
        ra, ru, rv = ry, rx, rz
    else:
        ra, ru, rv = rz, rx, ry
    return (a * B + ra) * (2 * B - 1) + (ru if rv == 0 else B - 1 + rv)


@njit(cache=True, nogil=True)
def _mc_brick(b, bricks, vals, ny1, nz1, edge_origin, edge_axis, tri_table, n_tri, table,
              n_used, faces, n_faces, vert_base, stamp, slot_vid, e_corner, e_axis,
              e_f0, e_f1, n_new, masks):
    """Marching cubes in brick ``b`` of :func:`mc_chunk` (arrays with room for it; kept
    apart so that no array is reassigned inside its loops). Returns the new
    ``(n_faces, n_new, n_used)``."""
    n = vals.shape[1]
    B = n - 1
    nby = (ny1 - 1) // B + 2  # bricks per axis, with room for the upper faces
    nbz = (nz1 - 1) // B + 2
    bx, by, bz = bricks[b, 0], bricks[b, 1], bricks[b, 2]
    neg_columns(vals, b, masks)
    for x in range(B):
        for y in range(B):
            m0 = masks[x, y]
            m1 = masks[x + 1, y]
            m2 = masks[x, y + 1]
            m3 = masks[x + 1, y + 1]
            crossed = column_crossed(m0, m1, m2, m3, B)
            while crossed:
                z = lowest_bit(crossed)
                crossed &= crossed - 1
                case = voxel_case(m0, m1, m2, m3, z)
                for t in range(n_tri[case]):
                    for q in range(3):
                        e = tri_table[case, t, q]
                        a = edge_axis[e]
                        lx = x + edge_origin[e, 0]
                        ly = y + edge_origin[e, 1]
                        lz = z + edge_origin[e, 2]
                        s = ((a * n + lx) * n + ly) * n + lz
                        if stamp[s] != b:
                            stamp[s] = b
                            key = face_key(bx, by, bz, lx, ly, lz, a, B, nby, nbz)
                            on_face = key >= 0
                            vid = -1
                            hs = 0
                            if on_face:
                                hs = _slot(table, key)
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
                        faces[n_faces, q] = slot_vid[s]
                    n_faces += 1
    return n_faces, n_new, n_used


@njit(cache=True, nogil=True)
def mc_chunk(bricks, vals, dims, edge_origin, edge_axis, tri_table, n_tri, table,
             n_used, faces, n_faces, vert_base, e_corner, e_axis, e_f0, e_f1):
    """Marching cubes over one chunk of bricks.

    Args:
        bricks: ``(C, 3)`` int64 lower sample corners; vals: ``(C, n, n, n)`` float64 field
            values at their samples (``n = B + 1``), already closed on the grid box.
        dims: ``(3,)`` int64 voxels per axis; edge_origin ``(12, 3)``, edge_axis ``(12,)``,
            tri_table ``(256, T, 3)``, n_tri ``(256,)``: the case table (:mod:`.cases`).
        table: the edge hash map (global edge index -> vertex id, :func:`new_hash`),
            kept across chunks, with ``n_used`` occupied slots; faces ``(Fcap, 3)`` int64 with
            ``n_faces`` used rows.
        vert_base: vertex id of this chunk's first new edge.
        e_corner ``(Ecap, 3)`` int64, e_axis ``(Ecap,)`` int64, e_f0, e_f1 ``(Ecap,)``:
            buffers for the new edges (reused from chunk to chunk: fresh memory is slow).

    Returns:
        ``(table, n_used, faces, n_faces, e_corner, e_axis, e_f0, e_f1, E)``: the
        (possibly grown) tables and buffers; the buffers' first ``E`` rows are the
        chunk's new edges (lower sample index, axis, field values at both ends) in
        vertex-id order.
    """
    n = vals.shape[1]
    B = n - 1
    ny1 = dims[1] + 1
    nz1 = dims[2] + 1
    n_slots = 3 * n * n * n
    stamp = np.full(n_slots, -1, dtype=np.int64)
    slot_vid = np.zeros(n_slots, dtype=np.int32)
    masks = np.empty((n, n), dtype=np.int64)
    n_new = 0
    max_tris = tri_table.shape[1]
    for b in range(bricks.shape[0]):
        # room for this brick: every face edge may be new in the hash, every voxel may
        # emit the most triangles
        while 2 * (n_used + n_slots) > table.shape[0]:
            table = _rehash(table)
        faces = _grow2(faces, n_faces + B * B * B * max_tris)
        if n_new + n_slots > e_axis.shape[0]:  # (grown here, not in the inner loop)
            e_corner = _grow2(e_corner, n_new + n_slots)
            e_axis = _grow1(e_axis, n_new + n_slots)
            e_f0 = _grow1(e_f0, n_new + n_slots)
            e_f1 = _grow1(e_f1, n_new + n_slots)
        n_faces, n_new, n_used = _mc_brick(
            b, bricks, vals, ny1, nz1, edge_origin, edge_axis, tri_table, n_tri, table,
            n_used, faces, n_faces, vert_base, stamp, slot_vid, e_corner, e_axis,
            e_f0, e_f1, n_new, masks)
    return table, n_used, faces, n_faces, e_corner, e_axis, e_f0, e_f1, n_new


@njit(cache=True, nogil=True)
def edges_on_box(e_corner: np.ndarray, e_axis: np.ndarray, dims: np.ndarray) -> np.ndarray:
    """Boolean ``(E,)``: which edges ``(E, 3)``/``(E,)`` touch the grid's outer faces."""
    out = np.zeros(e_corner.shape[0], dtype=np.bool_)
    for r in range(e_corner.shape[0]):
        for d in range(3):
            c = e_corner[r, d]
            if c <= 0 or c >= dims[d] or (e_axis[r] == d and c + 1 >= dims[d]):
                out[r] = True
                break
    return out


@njit(cache=True, nogil=True, inline="always")
def edge_coord(o: float, c: int, step: int, h: float, t: float) -> float:
    """One coordinate of the vertex at parameter ``t`` along a grid edge: ``p0 + t (p1 -
    p0)`` with ``p0 = o + c h``, ``p1 = o + (c + step) h`` (``o``: the grid origin's
    coordinate, ``c``: the edge's lower sample index, ``step``: 1 along the edge's axis,
    else 0). The mesher's one formula, so that a vertex rebuilt elsewhere from its edge
    and ``t`` (:mod:`.parts`) is the same float64, bit for bit."""
    p0 = o + c * h
    p1 = o + (c + step) * h
    return p0 + t * (p1 - p0)


@njit(cache=True, nogil=True)
def root_points(idx, e_corner, e_axis, t, origin, h) -> np.ndarray:
    """Points ``(m, 3)`` at parameter ``t[e]`` along edges ``e = idx[r]``:
    ``p0 + t (p1 - p0)`` with ``p0 = origin + c h``, ``p1 = origin + (c + step) h``."""
    out = np.empty((idx.shape[0], 3))
    all_points(idx, e_corner, e_axis, t, origin, h, out)
    return out


@njit(cache=True, nogil=True)
def all_points(idx, e_corner, e_axis, t, origin, h, out) -> None:
    """:func:`root_points` written into ``out (m, 3)``; ``idx`` None: every edge."""
    m = e_axis.shape[0] if idx is None else idx.shape[0]
    for r in range(m):
        e = r if idx is None else idx[r]
        for d in range(3):
            out[r, d] = edge_coord(origin[d], e_corner[e, d], 1 if e_axis[e] == d else 0,
                                   h, t[e])


@njit(cache=True, nogil=True)
def clip_to_box(p: np.ndarray, f: np.ndarray, lo: np.ndarray, hi: np.ndarray, h: float) -> None:
    """In place ``f = max(f, 2 box(p) + h)``: the field closed on the grid box, which
    agrees with :func:`close_on_box` at the samples (see ``reference._clip_box``)."""
    for r in range(p.shape[0]):
        m = -np.inf
        for d in range(3):
            m = max(m, lo[d] - p[r, d], p[r, d] - hi[d])
        box = 2.0 * m + h
        if box > f[r]:
            f[r] = box


@njit(cache=True, nogil=True)
def _sign(v: float) -> int:
    return 1 if v > 0 else (-1 if v < 0 else 0)


@njit(cache=True, nogil=True)
def root_start(f0: np.ndarray, f1: np.ndarray) -> tuple:
    """Initial state of the root search on ``E`` edges: ``(t, a, b, fa, fb, side)``."""
    m = f0.shape[0]
    t = np.empty(m)
    a = np.zeros(m)
    b = np.ones(m)
    fa = f0.copy()
    fb = f1.copy()
    side = np.zeros(m, dtype=np.int8)
    for i in range(m):
        v = fa[i] / (fa[i] - fb[i])
        if not np.isfinite(v):
            v = 0.5
        t[i] = min(max(v, 0.0), 1.0)
    return t, a, b, fa, fb, side


@njit(cache=True, nogil=True)
def root_update(idx, ft, t, a, b, fa, fb, side, tol, it) -> np.ndarray:
    """One step of the bracketed root search on the pending edges ``idx`` given the
    field ``ft`` at their current points; returns the edges still pending.

    Regula falsi with the Illinois modification and a bisection step every third
    iteration, always bracketed in ``[a, b]`` (the iteration of ``reference._refine_roots``).
    """
    keep = np.empty(idx.shape[0], dtype=idx.dtype)
    n = 0
    for r in range(idx.shape[0]):
        e = idx[r]
        f = ft[r]
        if abs(f) <= tol:
            continue
        ti = t[e]
        left = _sign(f) == _sign(fa[e])  # the root lies in (t, b)
        if left:
            if side[e] == 1:
                fb[e] *= 0.5
            a[e] = ti
            fa[e] = f
            side[e] = 1
        else:
            if side[e] == -1:
                fa[e] *= 0.5
            b[e] = ti
            fb[e] = f
            side[e] = -1
        tn = a[e] + fa[e] * (b[e] - a[e]) / (fa[e] - fb[e])
        if not np.isfinite(tn) or tn <= a[e] or tn >= b[e] or it % 3 == 2:
            tn = 0.5 * (a[e] + b[e])
        t[e] = tn
        keep[n] = e
        n += 1
    return keep[:n]
