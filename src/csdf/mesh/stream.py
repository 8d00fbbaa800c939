"""Streaming sparse marching cubes: the fast path of :func:`csdf.mesh` (``method='mc'``;
``method='dc'``: :func:`extract_dc`, the same stream feeding compiled dual contouring).

Same grid, octree and results as :func:`csdf.mesh.reference.extract` (watertight,
2-manifold, consistently wound, vertices on the zero set to ``1e-6`` voxel), but the
bookkeeping is compiled (:mod:`.kernels`) and runs chunk by chunk over the octree's
bricks (sorted by x, y, z): evaluate the chunk's samples, run marching cubes on it (new
vertices are the chunk's new crossed edges; an edge on a brick face that a neighbouring
brick made first is found in a hash map keyed by the edge), take the new edges' roots a
few search steps forward, and append vertices and faces. The few roots still unfinished
(kinks, flat spots) are finished together at the end. Working memory is a few chunks
(a few MB each), the hash map of crossed edges on brick faces and the output; no
``(A, 12)`` arrays and no global sort.

With the fast backend the stages run side by side: worker threads sample the chunks
ahead and search the roots of the chunks behind while one thread runs the kernel, the
only stage that must go in order (its hash map and vertex numbering). The kernel finds
a brick's crossed voxels from bit masks of its inside samples, one 9-bit mask per
column of samples, so empty columns cost a few instructions.

Measured at 512^3 on the CSG example (2 cores, ``benchmarks/bench_mesh.py``): the
kernel thread is the critical path (~0.15 s of ~0.21 s), then the octree (~0.02 s);
sampling (~0.1 s) and the root search (~0.05 s) run beside it.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor

import numpy as np

from ..parallel import N_THREADS, executor
from . import dual
from . import kernels as K
from .cases import COMPONENT_TABLE, EDGE_AXIS, EDGE_ORIGIN, TRI_TABLE
from .grid import BRICK, Grid, octree

__all__ = ["extract_mc", "extract_dc", "edge_key", "CHUNK_SAMPLES"]

CHUNK_SAMPLES = 1 << 18  # samples evaluated per call of the field (~6 MB of points)
ITERATIONS = 40  # root search steps at most
FIRST_ITERATIONS = 4  # steps per chunk; the few edges left go on together at the end
LOOKAHEAD = 2  # chunks sampled ahead of the marching-cubes kernel
# worker threads sampling and searching roots beside the thread running the kernel: one
# core fewer than there are, so that thread, the critical path, keeps a core (measured at
# 512^3 on 2 cores: 0.21-0.23 s with one worker, 0.26-0.36 s with two)
WORKERS = max(1, N_THREADS - 1)
_LOCAL = threading.local()  # per worker thread: its sample points buffer
assert 3 * BRICK * (2 * BRICK - 1) <= K._STRIDE, "hash slots need room for a brick's edges"
_N_TRI = (TRI_TABLE[:, :, 0] >= 0).sum(axis=1).astype(np.int64)
_TRI = TRI_TABLE.astype(np.int64)
_COMP = COMPONENT_TABLE.astype(np.int64)


def extract_mc(
    grid: Grid,
    values: Callable[[np.ndarray], np.ndarray],
    intervals: Callable,
    progress: Callable | None = None,
    tol: float = 1e-6,
    chunk_samples: int = CHUNK_SAMPLES,
    serial: Callable | None = None,
    scan: Callable | None = None,
    bricks: np.ndarray | None = None,
    edge_keys: bool | Callable = False,
    edge_t: bool = False,
    face_dtype: type = np.int64,
) -> tuple[np.ndarray, ...]:
    """Marching cubes of the zero set on ``grid``, streamed over the octree's bricks.

    Args:
        values: ``(M, 3) float64 -> (M,)`` field values (one backend for the whole mesh,
            so a sample shared by two bricks gets the same value in both).
        intervals: ``(lo (M, 3), hi (M, 3)) -> (flo (M,), fhi (M,))``, conservative.
        progress: optional ``callback(stage: str, done: int, total: int)``.
        tol: root tolerance on ``|f|`` in voxels.
        chunk_samples: samples per field evaluation (memory / call-overhead trade-off).
        serial: optional single-threaded ``values`` (same results), which lets the
            stages run side by side on worker threads (see :func:`_stream`).
        scan: optional ``callback(bricks (C, 3), values (C, n, n, n))`` called with each
            chunk's samples (on a worker thread; it must not keep ``values``), and
            first ``scan.octree(bricks (K, 3), inside_volume)`` when it has that
            attribute: how the thin-part check (:mod:`.thin`) shares the mesher's work.
        bricks: the lower corners ``(K, 3)`` of the bricks to mesh, sorted by x, y, z
            (default: the octree's; a subset meshes part of the grid, see
            :mod:`.parts`).
        edge_keys: also return each vertex's grid edge (:func:`edge_key`), or numbered
            by ``edge_keys(corner (E, 3) int64, axis (E,) int64, dims (3,)) -> (E,)``
            (:mod:`.parts` numbers them inside a part's cube).
        edge_t: give each vertex as its parameter ``t`` in ``[0, 1]`` along its grid edge
            instead of its position (the position is
            :func:`csdf.mesh.kernels.edge_coord` of the edge and ``t``): a third of the
            bytes, for meshes made in parts (:mod:`.parts`).
        face_dtype: the faces' integer type (int32 for a part, whose vertices are far
            fewer than 2^31).

    Returns:
        ``vertices (V, 3)`` float64 (``t (V,)`` float64 with ``edge_t``) and ``faces (F,
        3)`` int64 (what ``trimesh`` keeps, so it makes no copy), counter-clockwise seen
        from outside; with ``edge_keys``, then ``keys (V,)``.
    """
    if bricks is None:
        bricks = _sorted_bricks(grid, intervals, progress, scan)
    if len(bricks) == 0:
        empty = (np.zeros(0 if edge_t else (0, 3)), np.zeros((0, 3), dtype=face_dtype))
        return (*empty, np.zeros(0, dtype=np.int64)) if edge_keys else empty
    dims = np.array(grid.dims, dtype=np.int64)
    # initial sizes from the brick count, grown on demand: ~2 faces and ~1 vertex per
    # surface voxel, ~B^2 surface voxels per brick. The outputs get twice that: pages
    # never written cost address space, not memory, and a growth would copy everything
    est_faces = int(len(bricks) * 4.0 * BRICK * BRICK) + 1024
    out = [K.fresh_array((est_faces, 3), face_dtype), 0]  # faces, rows used
    keys: list[np.ndarray] = []
    number = edge_keys if callable(edge_keys) else edge_key

    def kernel(chunk, vals, table, n_used, n_verts, ebuf):
        table, n_used, out[0], out[1], *ebuf, n_new = K.mc_chunk(
            chunk, vals, dims, EDGE_ORIGIN, EDGE_AXIS, _TRI, _N_TRI, table, n_used,
            out[0], out[1], n_verts, *ebuf)
        if edge_keys:  # (the new edges are vertices n_verts, n_verts + 1, ...)
            keys.append(number(ebuf[0][:n_new], ebuf[1][:n_new], dims))
        return table, n_used, ebuf, n_new

    verts = _stream(grid, bricks, values, progress, tol, chunk_samples, kernel,
                    est_faces // 2, serial, scan, edge_t)
    if edge_keys:
        return verts, out[0][:out[1]], np.concatenate(keys)
    return verts, out[0][:out[1]]


def edge_key(corner: np.ndarray, axis: np.ndarray, dims: np.ndarray) -> np.ndarray:
    """A grid edge's number ``(E,)`` int64, the same wherever it is meshed: from its lower
    sample ``corner (E, 3)`` and ``axis (E,)`` on a grid of ``dims`` voxels,
    ``((i (ny + 1) + j) (nz + 1) + k) 3 + axis``."""
    c = corner.astype(np.int64)
    return ((c[:, 0] * (int(dims[1]) + 1) + c[:, 1]) * (int(dims[2]) + 1) + c[:, 2]) * 3 \
        + axis.astype(np.int64)


def extract_dc(
    grid: Grid,
    values: Callable[[np.ndarray], np.ndarray],
    gradients: Callable[[np.ndarray], np.ndarray],
    intervals: Callable,
    progress: Callable | None = None,
    tol: float = 1e-6,
    chunk_samples: int = CHUNK_SAMPLES,
    serial: Callable | None = None,
    values_and_gradients: Callable | None = None,
    scan: Callable | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Manifold dual contouring of the zero set on ``grid``, streamed like
    :func:`extract_mc` and compiled (:mod:`.dc_kernels`): the same mesh as
    ``extract(..., method='dc')`` up to the order of vertices and faces.

    The stream records the active voxels (corner, case) and the vertex id of each of
    their crossed edges (the roots, numbered as :func:`extract_mc` numbers them); then the
    normals at the roots (exact gradients, in blocks), the QEF vertices and the quads.

    Args:
        values: ``(M, 3) -> (M,)`` field values; gradients: ``(M, 3) -> (M, 3)``.
        intervals, progress, tol, chunk_samples, serial: as for :func:`extract_mc`.
        values_and_gradients: optional ``(M, 3) -> ((M,), (M, 3))`` in one pass (for the
            projection of the vertices; else ``values`` and ``gradients``).
        scan: as for :func:`extract_mc`.

    Returns:
        ``vertices (V, 3)`` float64 and ``faces (F, 3)`` int64, counter-clockwise seen
        from outside.
    """
    from . import dc_kernels as D

    bricks = _sorted_bricks(grid, intervals, progress, scan)
    if len(bricks) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
    dims = np.array(grid.dims, dtype=np.int64)
    est = int(len(bricks) * 2.0 * BRICK * BRICK) + 1024  # ~active voxels
    st = {"vox": np.empty((est, 3), dtype=np.int64), "vcase": np.empty(est, dtype=np.int64),
          "n_vox": 0, "pairs": np.empty(4 * est, dtype=np.int64), "n_pairs": 0,
          "f0": np.empty(est), "axis": np.empty(est, dtype=np.int8),
          "on_box": np.empty(est, dtype=np.uint8)}

    def kernel(chunk, vals, table, n_used, n_verts, ebuf):
        (table, n_used, *ebuf, n_new, st["vox"], st["vcase"], st["n_vox"], st["pairs"],
         st["n_pairs"]) = D.dc_chunk(
            chunk, vals, dims, EDGE_ORIGIN, EDGE_AXIS, _COMP, table, n_used, n_verts,
            *ebuf, st["vox"], st["vcase"], st["n_vox"], st["pairs"], st["n_pairs"])
        need = n_verts + n_new
        for k in ("f0", "axis", "on_box"):
            if need > len(st[k]):
                grown = np.empty(max(need, 2 * len(st[k])), dtype=st[k].dtype)
                grown[:n_verts] = st[k][:n_verts]
                st[k] = grown
        st["f0"][n_verts:need] = ebuf[2][:n_new]
        st["axis"][n_verts:need] = ebuf[1][:n_new]
        D.edge_flags(ebuf[0][:n_new], ebuf[1][:n_new], dims, st["on_box"][n_verts:need])
        return table, n_used, ebuf, n_new

    roots = _stream(grid, bricks, values, progress, tol, chunk_samples, kernel, est,
                    serial, scan)
    n_e = len(roots)
    uaxis = st["axis"][:n_e].astype(np.int64)
    on_box = st["on_box"][:n_e].astype(bool)
    normals = np.empty((n_e, 3))
    block = max(1, chunk_samples)
    for s in range(0, n_e, block):
        sl = slice(s, s + block)
        normals[sl] = dual.edge_normals(grid, roots[sl], uaxis[sl], gradients, on_box[sl])

    def gradients_values(p):
        if values_and_gradients is not None:
            return values_and_gradients(p)
        return values(p), gradients(p)

    n_vox, n_pairs = st.pop("n_vox"), st.pop("n_pairs")
    verts, quads, found = dual.dc_solve(grid, st.pop("vox")[:n_vox], st.pop("vcase")[:n_vox],
                                        st.pop("pairs")[:n_pairs], roots, normals, uaxis,
                                        threads=N_THREADS if serial is not None else 1)
    del normals, roots, on_box  # (the working arrays go before the faces are made)
    return dual.dc_finish(grid, verts, quads, found, st["f0"][:n_e], values, gradients_values)


def _sorted_bricks(grid: Grid, intervals: Callable, progress: Callable | None,
                   scan: Callable | None = None) -> np.ndarray:
    """The octree's bricks ``(K, 3)``, sorted by x, y, z (a deterministic, local sweep);
    ``scan.octree`` (when there is one) is told them and the volume of the cells dropped
    as wholly inside."""
    inside = [0.0]
    bricks = octree(grid, intervals, (lambda s, n: progress("octree", s, n)) if progress
                    else None, inside=inside)
    bricks = bricks[np.lexsort((bricks[:, 2], bricks[:, 1], bricks[:, 0]))]
    if hasattr(scan, "octree"):
        scan.octree(bricks, inside[0])
    return bricks


def _stream(grid: Grid, bricks: np.ndarray, values: Callable, progress: Callable | None,
            tol: float, chunk_samples: int, kernel: Callable, est_verts: int,
            serial: Callable | None = None, scan: Callable | None = None,
            edge_t: bool = False) -> np.ndarray:
    """Stream over ``bricks (K, 3)`` chunk by chunk: evaluate the samples, run ``kernel``
    (``(chunk, vals, table, n_used, n_verts, ebuf) -> (table, n_used, ebuf, n_new)``, which
    numbers the chunk's new crossed edges from ``n_verts`` in the edge hash map ``table``
    and writes them to the edge buffers ``ebuf``), search the new edges' roots; returns
    the roots ``(V, 3)`` (vertex ``i`` on crossed edge ``i``).

    With ``serial`` (a single-threaded ``values``, see
    :func:`csdf.backends.fast.serial_values`) the stages overlap on a pool of
    :data:`WORKERS` threads: chunks ahead are sampled, and the roots of chunks behind
    searched, while this thread runs ``kernel`` (the one stage that must go in order).
    The result is the same, vertex for vertex, as without ``serial``. With ``edge_t``
    the result is each root's parameter ``t (V,)`` along its edge instead."""
    dims = np.array(grid.dims, dtype=np.int64)
    origin = np.asarray(grid.origin, dtype=np.float64)
    h = float(grid.h)
    per_chunk = max(1, chunk_samples // (BRICK + 1) ** 3)
    box = (origin, origin + h * dims)
    # ~2 B of a brick's crossed edges on its faces: the hash map's keys (at most half full)
    table = K.new_hash(len(bricks) * 4 * BRICK + 1024)
    n_used = 0  # occupied slots of the hash map
    verts = K.fresh_array((est_verts,) if edge_t else (est_verts, 3), np.float64)
    n_verts = 0
    stragglers: list[_Roots] = []
    cap = per_chunk * 2 * BRICK * BRICK  # edge buffers, grown on demand

    def new_ebuf():
        return (np.empty((cap, 3), dtype=np.int64), np.empty(cap, dtype=np.int64),
                np.empty(cap), np.empty(cap))

    def search(ebuf, n_new, out, base, f):
        """Roots of the new edges ``ebuf[:n_new]``, written to ``out``; the pending ones
        (vertex ids from ``base``) or None."""
        e_c, e_a, e_f0, e_f1 = (a[:n_new] for a in ebuf)
        on = K.edges_on_box(e_c, e_a, dims)
        roots = _Roots(e_c, e_a, e_f0, e_f1, origin, h, tol * h, box,
                       clip=on if on.any() else None)
        roots.run(f, FIRST_ITERATIONS)
        roots.points(out)  # (or their t, for edge_t)
        return roots.pending(base) if len(roots.idx) else None

    # with ``serial`` a pool of workers runs the sampling and the searches; without it,
    # each job runs on this thread when it is submitted (the same loop, in sequence)
    pool = _pool() if serial is not None and N_THREADS > 1 else _Inline()
    f = serial if serial is not None else values
    starts = range(0, len(bricks), per_chunk)
    ebuf = new_ebuf()
    ahead = {}  # chunk start -> future of its samples
    searches = []  # futures of the root searches (-> pending roots or None)
    spare_vals: list | None = [] if serial is not None else None  # buffers done with
    spare_ebuf: list = []  # edge buffers whose search is done

    def sample(k):
        if k < len(bricks) and k not in ahead:
            ahead[k] = pool.submit(_samples, bricks[k:k + per_chunk], f, origin, h, dims,
                                   spare_vals, scan)

    def search_owning(ebuf, n_new, out, base):
        rest = search(ebuf, n_new, out, base, f)
        spare_ebuf.append(ebuf)
        return rest

    try:
        for k in starts[:LOOKAHEAD]:
            sample(k)
        for s in starts:
            chunk = bricks[s:s + per_chunk]
            vals = ahead.pop(s).result()
            sample(s + LOOKAHEAD * per_chunk)
            table, n_used, ebuf, n_new = kernel(chunk, vals, table, n_used, n_verts, ebuf)
            if spare_vals is not None:
                spare_vals.append(vals.base)  # (the buffer vals is a view of)
            del vals
            if n_verts + n_new > len(verts):  # (searches still running write to verts)
                stragglers += [r for r in (j.result() for j in searches) if r is not None]
                searches = []
                verts = _room(verts, n_verts, n_new)
            searches.append(pool.submit(search_owning, ebuf, n_new,
                                        verts[n_verts:n_verts + n_new], n_verts))
            # (the search owns the old buffers until it is done)
            ebuf = spare_ebuf.pop() if spare_ebuf else new_ebuf()
            n_verts += n_new
            if progress:
                progress("samples", s + len(chunk), len(bricks))
    except BaseException:
        # stopped (KeyboardInterrupt, or a signal the caller turned into one) or
        # failed: drop the jobs not yet started, so the workers stop with this thread
        for job in (*ahead.values(), *searches):
            job.cancel()
        raise
    stragglers += [r for r in (j.result() for j in searches) if r is not None]
    if stragglers:  # the few slow roots (kinks, flat spots) of all chunks together
        rest = _Roots.concat(stragglers)
        rest.run(values, ITERATIONS)
        verts[rest.vid] = rest.points(np.empty(verts[:len(rest.vid)].shape))
    if progress:
        progress("roots", n_verts, n_verts)
    return verts[:n_verts]


def _room(verts: np.ndarray, n_verts: int, n_new: int) -> np.ndarray:
    """``verts`` with room for ``n_new`` rows after the first ``n_verts`` (grown by
    doubling, into fresh memory)."""
    if n_verts + n_new <= len(verts):
        return verts
    grown = K.fresh_array((max(n_verts + n_new, 2 * len(verts)),) + verts.shape[1:],
                          np.float64)
    grown[:n_verts] = verts[:n_verts]
    return grown


def _pool() -> ThreadPoolExecutor:
    """The mesher's worker threads."""
    return executor("csdf-mesh", WORKERS)


class _Inline:
    """An executor that runs each job on the calling thread when it is submitted."""

    @staticmethod
    def submit(fn: Callable, *args) -> Future:
        done: Future = Future()
        done.set_result(fn(*args))
        return done


def _samples(chunk: np.ndarray, values: Callable, origin: np.ndarray, h: float,
             dims: np.ndarray, spare: list | None = None,
             scan: Callable | None = None) -> np.ndarray:
    """Field values ``(C, n, n, n)`` at the samples of bricks ``chunk (C, 3)``, closed on
    the grid box (``n = BRICK + 1``).

    With ``spare`` (a list of free value buffers, see :func:`_stream`; ``values`` then
    takes ``out=``) the values go into a buffer taken from it and the points into this
    thread's own buffer, so a long stream does not keep faulting in fresh memory."""
    n = BRICK + 1
    m = len(chunk) * n**3
    if spare is None:
        pts = K.brick_points(chunk, origin, h, BRICK)
        vals = np.asarray(values(pts), dtype=np.float64)
    else:
        pts = getattr(_LOCAL, "pts", None)
        if pts is None or len(pts) < m:
            pts = _LOCAL.pts = np.empty((m, 3))
        K.brick_points_into(chunk, origin, h, BRICK, pts)
        buf = spare.pop() if spare else None
        if buf is None or len(buf) < m:
            buf = np.empty(m)
        vals = values(pts[:m], out=buf)
        assert vals.base is buf  # (so the kernel's caller can give buf back)
    vals = vals.reshape(len(chunk), n, n, n)
    K.close_on_box(chunk, vals, dims, h)
    if scan is not None:
        scan(chunk, vals)
    return vals


class _Roots:
    """The bracketed root search on a set of edges (state as in :func:`.kernels.root_start`),
    run a few steps at a time.

    Attributes:
        e_c ``(E, 3)`` int64, e_a ``(E,)``: the edges; t, a, b, fa, fb, side ``(E,)``: the
        search state; idx: the edges still pending; it: steps done; vid ``(E,)``: the
        edges' vertex ids (for the stragglers); box: the grid box ``(lo, hi)``; clip:
        bool ``(E,)``, the edges on the box, whose field is closed on it (None: none).
        Each edge's search depends on that edge alone, not on the others searched with
        it, so the roots do not depend on how the bricks are split into chunks or tasks.
    """

    def __init__(self, e_c, e_a, f0, f1, origin, h, tol, box, it=0, state=None, idx=None,
                 vid=None, clip=None):
        self.e_c, self.e_a, self.origin, self.h, self.tol, self.box = e_c, e_a, origin, h, tol, box
        self.clip = clip
        self.state = K.root_start(f0, f1) if state is None else state
        self.idx = np.arange(len(e_a), dtype=np.int64) if idx is None else idx
        self.it = it
        self.vid = vid

    def run(self, values: Callable, until: int) -> None:
        """Search steps until ``until`` steps are done or no edge is pending."""
        while self.it < until and len(self.idx):
            t = self.state[0]
            p = K.root_points(self.idx, self.e_c, self.e_a, t, self.origin, self.h)
            ft = np.asarray(values(p), dtype=np.float64)
            if self.clip is not None:
                on = self.clip[self.idx]
                if on.any():
                    f_on = ft[on]
                    K.clip_to_box(p[on], f_on, self.box[0], self.box[1], self.h)
                    ft[on] = f_on
            self.idx = K.root_update(self.idx, ft, *self.state, self.tol, self.it)
            self.it += 1

    def points(self, out: np.ndarray) -> np.ndarray:
        """The current points ``(E, 3)``, written into ``out``; with ``out (E,)``, their
        parameters ``t`` along the edges."""
        if out.ndim == 1:
            out[:] = self.state[0]
        else:
            K.all_points(None, self.e_c, self.e_a, self.state[0], self.origin, self.h, out)
        return out

    def pending(self, vert_base: int) -> _Roots:
        """The pending edges alone (vertex ids from ``vert_base``)."""
        i = self.idx
        state = tuple(x[i] for x in self.state)
        return _Roots(self.e_c[i], self.e_a[i], None, None, self.origin, self.h, self.tol,
                      self.box, self.it, state, None, vert_base + i,
                      None if self.clip is None else self.clip[i])

    @staticmethod
    def concat(parts: list[_Roots]) -> _Roots:
        """One search over the pending edges of several (all after the same steps; each
        edge on the grid box still sees the field closed on it)."""
        p0 = parts[0]
        clip = None
        if any(p.clip is not None for p in parts):
            clip = np.concatenate([np.zeros(len(p.e_a), dtype=bool) if p.clip is None
                                   else p.clip for p in parts])
        state = tuple(np.concatenate([p.state[k] for p in parts]) for k in range(6))
        return _Roots(np.concatenate([p.e_c for p in parts]),
                      np.concatenate([p.e_a for p in parts]), None, None, p0.origin, p0.h,
                      p0.tol, p0.box, p0.it, state, None,
                      np.concatenate([p.vid for p in parts]), clip)
