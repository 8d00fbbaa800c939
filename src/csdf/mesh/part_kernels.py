"""Compiled (Numba) cores of :mod:`.parts`: a part's vertices as grid edges numbered
inside its cube, and the hash map that merges the vertices two parts share.

A part's vertex is ``(edge, t)``: ``edge`` its grid edge inside the part's cube of
edge ``s`` voxels, the bits ``i | j | k | axis`` (``b = s.bit_length()`` bits for each of
the lower sample's indices ``0 .. s`` from the cube's lower corner, 2 for the axis: 32
bits up to ``s = 512``), and ``t`` its parameter along the edge. Its position is the
mesher's own :func:`.kernels.edge_coord`, so a vertex rebuilt here equals the one the
whole-grid mesher makes, bit for bit. The grid-wide number of an edge (a key) is
:func:`csdf.mesh.stream.edge_key`'s.

The vertices that parts share (on their cubes' faces, which are bricks' faces) are
merged in the mesher's own hash map of brick-face edges (:func:`.kernels.new_hash`,
keyed by :func:`.kernels.face_key`), kept at most half full.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from . import kernels as K
from .grid import BRICK
from .kernels import edge_coord

__all__ = ["edge_bits", "edge_dtype", "pack_edges", "on_cube_faces", "edge_points",
           "global_keys", "key_points", "new_table", "place_part", "merge_keys", "file_part",
           "encode_faces", "decode_faces", "ESCAPE"]

@njit(cache=True, nogil=True, inline="always")
def edge_bits(size: int) -> int:
    """Bits per index of an edge number inside a cube of edge ``size`` voxels (those of
    ``size`` itself)."""
    b = 0
    while (1 << b) <= size:
        b += 1
    return b


def edge_dtype(size: int) -> type:
    """The integer type of edge numbers inside a cube of edge ``size``: uint32 up to
    512 voxels, else int64."""
    return np.uint32 if 3 * int(size).bit_length() + 2 <= 32 else np.int64


@njit(cache=True, nogil=True)
def pack_edges(corner: np.ndarray, axis: np.ndarray, cell: np.ndarray, bits: int,
               out: np.ndarray) -> None:
    """Edge numbers ``out (E,)`` inside the cube at ``cell (3,)`` of the edges with lower
    samples ``corner (E, 3)`` (grid indices) and ``axis (E,)``."""
    for r in range(axis.shape[0]):
        out[r] = ((((corner[r, 0] - cell[0]) << bits | (corner[r, 1] - cell[1])) << bits
                   | (corner[r, 2] - cell[2])) << 2) | axis[r]


@njit(cache=True, nogil=True, inline="always")
def _decode(e: int, bits: int) -> tuple:
    """``(i, j, k, axis)`` inside the cube of an edge number ``e``."""
    m = (1 << bits) - 1
    return (e >> (2 + 2 * bits)) & m, (e >> (2 + bits)) & m, (e >> 2) & m, e & 3


@njit(cache=True, nogil=True, inline="always")
def _on_faces(i: int, j: int, k: int, axis: int, size: int) -> bool:
    """Whether an edge lies on the cube's faces (in a face plane it does not cross),
    where a neighbouring part may hold it too."""
    return ((axis != 0 and (i == 0 or i == size)) or (axis != 1 and (j == 0 or j == size))
            or (axis != 2 and (k == 0 or k == size)))


@njit(cache=True, nogil=True, inline="always")
def _key(i: int, j: int, k: int, axis: int, ny1: int, nz1: int) -> int:
    """The grid-wide number of the edge at grid indices ``(i, j, k)``."""
    return ((i * ny1 + j) * nz1 + k) * 3 + axis


@njit(cache=True, nogil=True, inline="always")
def _from_key(key: int, ny1: int, nz1: int) -> tuple:
    """``(i, j, k, axis)`` of a grid-wide edge number (:func:`_key`)."""
    rest = key // 3
    k = rest % nz1
    rest //= nz1
    return rest // ny1, rest % ny1, k, key % 3


@njit(cache=True, nogil=True)
def on_cube_faces(edges: np.ndarray, size: int) -> np.ndarray:
    """Bool ``(V,)``: which of a part's edges ``(V,)`` lie on its cube's faces."""
    bits = edge_bits(size)
    out = np.empty(edges.shape[0], dtype=np.bool_)
    for r in range(edges.shape[0]):
        i, j, k, axis = _decode(np.int64(edges[r]), bits)
        out[r] = _on_faces(i, j, k, axis, size)
    return out


@njit(cache=True, nogil=True, inline="always")
def _point(out: np.ndarray, row: int, i: int, j: int, k: int, axis: int, t: float,
           origin: np.ndarray, h: float) -> None:
    """``out[row]``: the vertex at ``t`` on the edge at grid indices ``(i, j, k)``,
    ``axis`` (:func:`.kernels.edge_coord`)."""
    out[row, 0] = edge_coord(origin[0], i, 1 if axis == 0 else 0, h, t)
    out[row, 1] = edge_coord(origin[1], j, 1 if axis == 1 else 0, h, t)
    out[row, 2] = edge_coord(origin[2], k, 1 if axis == 2 else 0, h, t)


@njit(cache=True, nogil=True)
def edge_points(edges: np.ndarray, t: np.ndarray, cell: np.ndarray, size: int,
                origin: np.ndarray, h: float, out: np.ndarray) -> None:
    """Positions ``out (V, 3)`` (model units) of a part's vertices ``(edges (V,), t
    (V,))`` (its cube at ``cell (3,)``, edge ``size``)."""
    bits = edge_bits(size)
    for r in range(edges.shape[0]):
        i, j, k, axis = _decode(np.int64(edges[r]), bits)
        _point(out, r, cell[0] + i, cell[1] + j, cell[2] + k, axis, t[r], origin, h)


@njit(cache=True, nogil=True)
def key_points(keys: np.ndarray, t: np.ndarray, dims: np.ndarray, origin: np.ndarray,
               h: float, out: np.ndarray) -> None:
    """Positions ``out (V, 3)`` of vertices given by grid-wide edge numbers ``keys (V,)``
    (on a grid of ``dims`` voxels) and ``t (V,)``."""
    ny1 = dims[1] + 1
    nz1 = dims[2] + 1
    for r in range(keys.shape[0]):
        i, j, k, axis = _from_key(keys[r], ny1, nz1)
        _point(out, r, i, j, k, axis, t[r], origin, h)


@njit(cache=True, nogil=True)
def global_keys(edges: np.ndarray, cell: np.ndarray, size: int, dims: np.ndarray,
                mask: np.ndarray) -> np.ndarray:
    """Grid-wide numbers ``(M,)`` int64 of the edges ``edges[mask]`` of a part."""
    bits = edge_bits(size)
    ny1 = dims[1] + 1
    nz1 = dims[2] + 1
    out = np.empty(int(mask.sum()), dtype=np.int64)
    m = 0
    for r in range(edges.shape[0]):
        if mask[r]:
            i, j, k, axis = _decode(np.int64(edges[r]), bits)
            out[m] = _key(cell[0] + i, cell[1] + j, cell[2] + k, axis, ny1, nz1)
            m += 1
    return out


def new_table(capacity: int) -> np.ndarray:
    """An empty hash map of shared edges with room for ``capacity`` (the mesher's own,
    :func:`.kernels.new_hash`)."""
    return K.new_hash(2 * capacity)


@njit(cache=True, nogil=True, inline="always")
def _hash_key(i: int, j: int, k: int, axis: int, nby: int, nbz: int) -> int:
    """The hash key of an edge on a brick's face at grid indices ``(i, j, k)``: the
    mesher's own (:func:`.kernels.face_key`, from the brick holding its lower end), so
    the vertices on a brick's faces sit side by side in the table as they do there."""
    b = BRICK
    return K.face_key((i // b) * b, (j // b) * b, (k // b) * b, i % b, j % b, k % b, axis,
                      b, nby, nbz)


@njit(cache=True, nogil=True)
def _with_room(table: np.ndarray, keys: int) -> np.ndarray:
    """``table``, grown until ``keys`` keys leave it at most half full."""
    while 2 * keys > table.shape[0]:
        table = K._rehash(table)
    return table


@njit(cache=True, nogil=True, inline="always")
def _id_of(table: np.ndarray, key: int, new_id: int) -> int:
    """The value of ``key``, or ``new_id`` stored as its value when it is new (the
    caller keeps the table at most half full)."""
    s = K._slot(table, key)
    if table[s, 0] == key:
        return table[s, 1]
    table[s, 0] = key
    table[s, 1] = new_id
    return new_id


#: the face code that stands for "the index is the next of the escapes"
ESCAPE = 65535


@njit(cache=True, nogil=True)
def encode_faces(faces: np.ndarray) -> tuple:
    """A part's faces ``(F, 3)`` (vertex indices) as ``(codes (F, 3) uint16, escapes (E,)
    int32)``: half the bytes.

    The mesher numbers a vertex when a face first uses it, so a face's indices lie at or
    below ``front + 3``, ``front`` the largest index of the faces before it, and most
    lie just below (91 % within 127, 99.9 % within 65,534 on a part of the 1024^3 CSG
    mesh). Each index is stored as ``front + 3 - index``, or as :data:`ESCAPE` with the
    index itself next in ``escapes`` (:func:`_decoded` reads them back)."""
    codes = np.empty(faces.shape, dtype=np.uint16)
    n = 0
    front = -1
    for q in range(faces.shape[0]):  # (the codes, and how many escape)
        top = front
        for c in range(3):
            x = np.int64(faces[q, c])
            e = front + 3 - x
            if 0 <= e < ESCAPE:
                codes[q, c] = e
            else:
                codes[q, c] = ESCAPE
                n += 1
            top = max(top, x)
        front = top
    escapes = np.empty(n, dtype=np.int32)
    m = 0
    for q in range(faces.shape[0] if n else 0):  # (the escapes, in order)
        for c in range(3):
            if codes[q, c] == ESCAPE:
                escapes[m] = faces[q, c]
                m += 1
    return codes, escapes


@njit(cache=True, nogil=True, inline="always")
def _decoded(code: int, front: int, escapes: np.ndarray, n: int) -> tuple:
    """``(index, escapes used)`` of one code of :func:`encode_faces`."""
    if code == ESCAPE:
        return escapes[n], n + 1
    return front + 3 - code, n


@njit(cache=True, nogil=True)
def decode_faces(codes: np.ndarray, escapes: np.ndarray, out: np.ndarray, start: int = 0,
                 ids: np.ndarray | None = None) -> None:
    """The faces of :func:`encode_faces`'s ``codes (F, 3)`` and ``escapes``, written to
    ``out[start:start + F]``: the indices, or ``ids[index]`` with ``ids``."""
    n = 0
    front = -1
    for q in range(codes.shape[0]):
        top = front
        for c in range(3):
            x, n = _decoded(codes[q, c], front, escapes, n)
            if ids is None:
                out[start + q, c] = x
            else:
                out[start + q, c] = ids[x]
            top = max(top, x)
        front = top


@njit(cache=True, nogil=True)
def place_part(edges, t, faces, escapes, cell, size, dims, origin, h, table, n_used, verts,
               n_verts, out_faces, n_faces):
    """Put one part into the whole mesh: each vertex numbered as it comes (a vertex on
    the cube's faces that an earlier part brought is found in ``table`` by its edge and
    not repeated), its position written to ``verts[n_verts:]``, the faces renumbered
    into ``out_faces[n_faces:]``.

    Args:
        edges ``(V,)``, t ``(V,)``: the part's vertices (cube at ``cell (3,)``, edge
        ``size``); faces ``(F, 3)``: its faces, int32 vertex indices, or uint16 codes
        of :func:`encode_faces` with their ``escapes`` (E,) (None: indices); dims
        ``(3,)``, origin ``(3,)``, h: the grid.
        table, n_used: the hash map of shared edges (grid-wide edge -> vertex id) and its
        keys; verts ``(Vcap, 3)`` float64 with ``n_verts`` rows used and out_faces
        ``(Fcap, 3)`` int64 with ``n_faces``: the outputs, with room for the part.

    Returns:
        ``(table, n_used, n_verts, n_faces)`` (the table possibly grown).
    """
    bits = edge_bits(size)
    nby = dims[1] // BRICK + 2  # (bricks per axis, as the mesher counts them)
    nbz = dims[2] // BRICK + 2
    # room for every shared vertex first: a table grown (reassigned) inside the loop
    # below made it 2.5x slower (measured on the 1024^3 CSG mesh)
    table = _with_room(table, n_used + int(on_cube_faces(edges, size).sum()))
    ids = np.empty(edges.shape[0], dtype=np.int64)
    for r in range(edges.shape[0]):
        i, j, k, axis = _decode(np.int64(edges[r]), bits)
        if _on_faces(i, j, k, axis, size):
            vid = _id_of(table, _hash_key(cell[0] + i, cell[1] + j, cell[2] + k, axis, nby,
                                          nbz), n_verts)
            ids[r] = vid
            if vid != n_verts:  # (an earlier part's copy, the same vertex)
                continue
            n_used += 1
        ids[r] = n_verts
        _point(verts, n_verts, cell[0] + i, cell[1] + j, cell[2] + k, axis, t[r], origin, h)
        n_verts += 1
    if escapes is None:
        for q in range(faces.shape[0]):
            out_faces[n_faces + q, 0] = ids[faces[q, 0]]
            out_faces[n_faces + q, 1] = ids[faces[q, 1]]
            out_faces[n_faces + q, 2] = ids[faces[q, 2]]
    else:
        decode_faces(faces, escapes, out_faces, n_faces, ids)
    return table, n_used, n_verts, n_faces + faces.shape[0]


@njit(cache=True, nogil=True)
def merge_keys(keys, dims, table, n_used, n_next, ids):
    """Number edges on the faces between parts, given by their grid-wide numbers ``keys
    (M,)`` (a grid of ``dims`` voxels): an edge seen before keeps its number, a new one
    gets the next (from ``n_next``); the numbers go to ``ids (M,)``.

    Returns:
        ``(table, n_used, n_next, new)``: ``new (M,)`` bool, which keys were new (the
        table possibly grown).
    """
    ny1 = dims[1] + 1
    nz1 = dims[2] + 1
    nby = dims[1] // BRICK + 2
    nbz = dims[2] // BRICK + 2
    new = np.zeros(keys.shape[0], dtype=np.bool_)
    table = _with_room(table, n_used + keys.shape[0])
    for r in range(keys.shape[0]):
        i, j, k, axis = _from_key(keys[r], ny1, nz1)
        vid = _id_of(table, _hash_key(i, j, k, axis, nby, nbz), n_next)
        ids[r] = vid
        if vid == n_next:
            new[r] = True
            n_used += 1
            n_next += 1
    return table, n_used, n_next, new


@njit(cache=True, nogil=True)
def file_part(edges, t, faces, cell, size, origin, h, own_base, shared_ids, verts, out_faces):
    """A part's records in a file of the whole mesh whose vertices it does not hold: its
    own vertices (not on the cube's faces) numbered ``own_base, own_base + 1, ...`` in
    order, their positions written to ``verts (n_own, 3)`` float64; its shared ones
    numbered ``shared_ids (S,)`` in order (merged by the client); its faces in those
    numbers written to ``out_faces (F, 3)`` int32."""
    bits = edge_bits(size)
    ids = np.empty(edges.shape[0], dtype=np.int64)
    w = 0
    m = 0
    for r in range(edges.shape[0]):
        i, j, k, axis = _decode(np.int64(edges[r]), bits)
        if _on_faces(i, j, k, axis, size):
            ids[r] = shared_ids[m]
            m += 1
        else:
            ids[r] = own_base + w
            _point(verts, w, cell[0] + i, cell[1] + j, cell[2] + k, axis, t[r], origin, h)
            w += 1
    for q in range(faces.shape[0]):
        out_faces[q, 0] = ids[faces[q, 0]]
        out_faces[q, 1] = ids[faces[q, 1]]
        out_faces[q, 2] = ids[faces[q, 2]]
