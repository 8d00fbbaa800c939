"""Region-pruned evaluation: register tapes shortened per tile or cell, compiled once.

A program at fixed parameter values becomes a :class:`RegTape` (parameters, constants
and the parameter-only prefix become register loads, every other instruction gets its
own register). :mod:`csdf.backends.tape_kernels` shortens such a tape for a box (the
``min``/``max`` that interval arithmetic decides keep only their winner; dead
instructions go; registers are reallocated) and evaluates points with the short tapes,
in kernels compiled once for all programs (no per-program compilation, so a
7,000-instruction program costs nothing to start).

Two users:

* :func:`raster_image`, the engine of :func:`csdf.raster`: a quadtree of tiles, each
  level shortening every tile's parent tape for the tile (in parallel), filling tiles
  whose interval has one sign and evaluating the leaves' pixels with their own tapes;
* :class:`CellTapes`, point queries grouped into spatial cells: an octree (a quadtree
  for 2D) of cells over a box, whose tapes are built on demand (each from its
  parent's) and kept, so repeated queries near the same places (a mesher's bricks
  and root searches, a tracer's rays) pay for each cell once. Boxes get intervals from
  the smallest cell that holds them.

Values are bit-identical to the ``'interp'`` backend's (the same op kernels run on the
same inputs), gradients equal to its gradients.
"""

from __future__ import annotations

import threading

import numpy as np

from ..cache import memo
from ..cellsort import group_by_cell
from ..layout import N_COORDS
from ..ops import OPS_BY_CODE, tie_strict
from ..parallel import N_THREADS, executor
from .lowering import FLAG_A_ZERO, FLAG_B_ZERO, FLAG_OUT_ZERO, FLAG_TIE_STRICT, lowered

__all__ = ["RegTape", "reg_tape", "TapePool", "CellTapes", "raster_image", "cell_tapes"]

_kernels = None
#: below this many items a kernel runs on the calling thread alone
_SERIAL_BELOW = 8


def _k():
    global _kernels
    if _kernels is None:
        from . import tape_kernels

        _kernels = tape_kernels
    return _kernels


def _parallel(kernel: str, n_items: int, *args) -> None:
    """Run ``kernel(*args, part, n_parts)`` of :mod:`.tape_kernels` over ``n_items``
    items: one part per core on the shared worker threads (the kernels release the
    GIL), or on this thread alone for small jobs. (Not Numba's ``prange``: its OpenMP
    threads spin after each call and would starve the other evaluators' threads.)"""
    fn = getattr(_k(), kernel)
    n = max(1, min(N_THREADS, n_items // _SERIAL_BELOW))
    if n == 1:
        fn(*args, 0, 1)
    else:
        list(executor().map(lambda c: fn(*args, c, n), range(n)))


class RegTape:
    """A program at fixed parameter values as a register tape (see the module docs).

    Attributes:
        code: ``(n, 5)`` int32 rows ``(op, dst, a, b, flags)``; imm: ``(n,)`` float64.
        out: the register of the result; n_regs: registers used (at least 3).
    """

    def __init__(self, prog, pvals: np.ndarray):
        lay = prog.layout
        low = lowered(prog)
        n_prefix = low.n_prefix
        # the interpreter's own compiled prefix rules, so the tape agrees with it bit
        # for bit (NumPy's arctan2 differs from libm's in the last bit now and then)
        pre_vals, _ = low.prefix(np.asarray(pvals, dtype=np.float64), tangents=False)
        rows: list[list[int]] = []
        imms: list[float] = []
        zero: list[bool] = [False] * N_COORDS  # structurally zero spatial tangent, by reg
        loc: dict[int, int] = {i: i for i in range(N_COORDS)}

        def load(v: float) -> int:
            r = len(zero)
            rows.append([0, r, 0, 0, FLAG_OUT_ZERO])
            imms.append(float(v))
            zero.append(True)
            return r

        def reg_of(slot: int) -> int:
            r = loc.get(slot)
            if r is None:  # a parameter or constant, loaded on first use
                if lay.is_const(slot):
                    r = load(prog.consts[slot - lay.const_base])
                else:
                    r = load(pvals[slot - lay.param_base])
                loc[slot] = r
            return r

        code = prog.code.tolist()
        for k, (op, dst, a, b) in enumerate(code):
            if k < n_prefix:
                loc[dst] = load(pre_vals[k])
                continue
            info = OPS_BY_CODE[op]
            binary = info.arity == 2
            ra = reg_of(a)
            rb = reg_of(b) if binary else 0
            za = zero[ra]
            zb = zero[rb] if binary else True
            zd = (za and zb) or info.derivative.kind == "zero"
            flags = ((FLAG_B_ZERO if (binary and zb) else 0) | (FLAG_A_ZERO if za else 0)
                     | (FLAG_OUT_ZERO if zd else 0)
                     | (FLAG_TIE_STRICT if tie_strict(lay.is_const(a)) else 0))
            r = len(zero)
            rows.append([op, r, ra, rb, flags])
            imms.append(0.0)
            zero.append(zd)
            loc[dst] = r
        self.out = reg_of(prog.output)
        self.code = np.array(rows, dtype=np.int32).reshape(-1, 5)
        self.imm = np.array(imms, dtype=np.float64)
        self.n_regs = max(len(zero), N_COORDS)
        self.dim = prog.dim


def reg_tape(prog, pvals: np.ndarray) -> RegTape:
    """The :class:`RegTape` of a program at these parameter values (cached on the
    program, a few per program)."""
    return memo(prog, "_reg_tapes", np.asarray(pvals, np.float64).tobytes(),
                lambda: RegTape(prog, pvals), 4)


class TapePool:
    """Tapes in one pool of rows: tape ``t`` is rows ``start[t] : start[t] + length[t]``
    of ``code``/``imm`` with output register ``out[t]`` and ``regs[t]`` registers."""

    def __init__(self, code: np.ndarray, imm: np.ndarray, out: int, n_regs: int):
        self.code = code
        self.imm = imm
        self.n_rows = len(code)
        self.start = np.zeros(1, np.int64)
        self.length = np.array([len(code)], np.int64)
        self.out = np.array([out], np.int64)
        self.regs = np.array([n_regs], np.int64)

    @property
    def n_tapes(self) -> int:
        return len(self.start)

    def shorten(self, parent: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                emit: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Shorten tape ``parent[i]`` for box ``[lo[i], hi[i]]`` (``(M, 3)``), in parallel.

        Returns:
            ``(tapes, flo, fhi)``: the new tapes' indices (``(M,)``; with
            ``emit=False`` no tape is made and ``tapes`` is ``parent``) and the
            intervals of the output over the boxes.
        """
        M = len(parent)
        flo = np.empty(M)
        fhi = np.empty(M)
        r_len = np.empty(M, np.int64)
        r_out = np.empty(M, np.int64)
        r_regs = np.empty(M, np.int64)
        if M == 0:
            return parent.copy(), flo, fhi
        need = self.length[parent]
        ostart = self.n_rows + np.concatenate([[0], np.cumsum(need)[:-1]])
        if emit:
            self._room(int(self.n_rows + need.sum()))
        _parallel("simplify_many", M, self.code, self.imm, self.start, self.length,
                    self.out, self.regs, parent, np.ascontiguousarray(lo, np.float64),
                    np.ascontiguousarray(hi, np.float64), self.code, self.imm, ostart,
                    int(emit), r_len, r_out, r_regs, flo, fhi)
        if not emit:
            return parent.copy(), flo, fhi
        # pack the new tapes' rows (each was given room for its parent's length)
        new_start = self.n_rows + np.concatenate([[0], np.cumsum(r_len)[:-1]])
        used = int(r_len.sum())
        if used:
            src = np.repeat(ostart - new_start, r_len) + np.arange(self.n_rows,
                                                                    self.n_rows + used)
            dst = slice(self.n_rows, self.n_rows + used)
            self.code[dst] = self.code[src]
            self.imm[dst] = self.imm[src]
        first = self.n_tapes
        self.start = np.concatenate([self.start, new_start])
        self.length = np.concatenate([self.length, r_len])
        self.out = np.concatenate([self.out, r_out])
        self.regs = np.concatenate([self.regs, r_regs])
        self.n_rows += used
        return np.arange(first, first + M), flo, fhi

    def _room(self, rows: int) -> None:
        if rows <= len(self.code):
            return
        size = max(rows, 2 * len(self.code))
        code = np.empty((size, 5), np.int32)
        imm = np.empty(size)
        code[:self.n_rows] = self.code[:self.n_rows]
        imm[:self.n_rows] = self.imm[:self.n_rows]
        self.code, self.imm = code, imm


# ------------------------------------------------------------------ rasters
def raster_image(prog, pvals: np.ndarray, xs: np.ndarray, ys: np.ndarray, values: bool,
                 leaf: int = 16) -> tuple[np.ndarray, dict]:
    """The image of a 2D program at pixel centres ``xs`` (``(W,)``, by column) and
    ``ys`` (``(H,)``, by row, decreasing).

    A quadtree of tiles, level by level (:func:`.tape_kernels.raster_level`): each
    tile shortens its parent's tape for its box; with ``values=False`` tiles whose
    interval has one sign are filled; tiles of at most ``leaf x leaf`` pixels are
    evaluated with their own tapes; the others split in four.

    Returns:
        ``(image, stats)``: ``(H, W)`` float64 values, or bool ``value < 0``; stats
        ``{'levels', 'tiles', 'work'}`` (tiles shortened, and the sum of their parents'
        tape lengths).
    """
    tape = reg_tape(prog, pvals)
    H, W = len(ys), len(xs)
    img = np.empty((H, W), dtype=np.float64 if values else bool)
    xs = np.ascontiguousarray(xs, np.float64)
    ys = np.ascontiguousarray(ys, np.float64)
    code, imm = tape.code, tape.imm
    p_start = np.zeros(1, np.int64)
    p_len = np.array([len(code)], np.int64)
    p_out = np.array([tape.out], np.int64)
    p_regs = np.array([tape.n_regs], np.int64)
    tiles = np.array([[0, H, 0, W]], np.int64)
    parent = np.zeros(1, np.int64)
    stats = {"levels": 0, "tiles": 0, "work": 0}
    while len(tiles):
        M = len(tiles)
        need = p_len[parent]
        ostart = np.concatenate([[0], np.cumsum(need)[:-1]]).astype(np.int64)
        total = max(int(need.sum()), 1)
        ocode = np.empty((total, 5), np.int32)
        oimm = np.empty(total)
        r_len, r_out, r_regs = (np.empty(M, np.int64) for _ in range(3))
        split = np.empty(M, np.int8)
        _parallel("raster_level", M, code, imm, p_start, p_len, p_out, p_regs, tiles,
                    parent, xs, ys, img, not values, int(leaf), ocode, oimm, ostart, r_len,
                    r_out, r_regs, split)
        stats["levels"] += 1
        stats["tiles"] += M
        stats["work"] += int(need.sum())
        code, imm = ocode, oimm
        p_start, p_len, p_out, p_regs = ostart, r_len, r_out, r_regs
        go = split.astype(bool)
        tiles, parent = _split(tiles[go], np.flatnonzero(go))
    return img, stats


def _split(tiles: np.ndarray, parent: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each tile ``(r0, r1, c0, c1)`` into (up to) four quadrants, which inherit their
    parent's tape."""
    r0, r1, c0, c1 = tiles.T
    rm, cm = (r0 + r1 + 1) // 2, (c0 + c1 + 1) // 2
    kids = np.stack([
        np.stack([r0, rm, c0, cm], 1), np.stack([r0, rm, cm, c1], 1),
        np.stack([rm, r1, c0, cm], 1), np.stack([rm, r1, cm, c1], 1)], axis=1)
    kids = kids.reshape(-1, 4)
    par = np.repeat(parent, 4)
    ok = (kids[:, 0] < kids[:, 1]) & (kids[:, 2] < kids[:, 3])
    return kids[ok], par[ok]


# ------------------------------------------------------------------ point queries
class CellTapes:
    """Tapes of the cells of an octree (quadtree in 2D) over a box, built on demand.

    Args:
        prog: the program; pvals: ``(P,)`` float64 parameter values (no NaN).
        box: ``(2, 3)`` ``[lo, hi]`` of the region (points outside it run the whole
            tape, which is valid everywhere).
        depth: the finest level: ``2**depth`` cells per axis.
    """

    def __init__(self, prog, pvals: np.ndarray, box: np.ndarray, depth: int):
        self.tape = reg_tape(prog, pvals)
        self.pool = TapePool(self.tape.code, self.tape.imm, self.tape.out, self.tape.n_regs)
        self.dim = prog.dim
        box = np.array(box, dtype=np.float64).reshape(2, -1)
        if box.shape[1] == 2:
            box = np.hstack([box, np.zeros((2, 1))])
        self.lo = box[0]
        self.span = np.maximum(box[1] - box[0], 1e-300)
        self.depth = int(depth)
        self.axes = 3 if self.dim == 3 else 2
        self.tables = [np.full((1 << l) ** self.axes, -1, np.int64)
                       for l in range(self.depth + 1)]
        self.lock = threading.Lock()
        n_cells = len(self.tables[self.depth])
        self.stamp = np.zeros(n_cells, np.int32)  # scratch of evaluate's cell numbering
        self.slot = np.zeros(n_cells, np.int32)
        self.epoch = 0
        #: cells proved empty are kept one level finer than the tapes (``2**(depth +
        #: 1)`` per axis) once :meth:`track_empty` is called, else at the tapes' level
        self.empty_depth = self.depth
        #: ``(n_empty_cells,)`` uint8 at ``empty_depth``: 1 where the cell's interval
        #: proves the field positive (filled in as cells are built; 0: not, or unknown)
        self.empty = np.zeros(n_cells, np.uint8)
        # level 0: the root tape shortened for the whole box
        self.tables[0][0] = -1
        self.tables[0][0] = self._root()

    def _root(self) -> int:
        pad = 1e-7 * self.span
        lo, hi = self.lo - pad, self.lo + self.span + pad
        if self.axes == 2:
            lo[2] = hi[2] = 0.0
        t, flo, _ = self.pool.shorten(np.zeros(1, np.int64), lo[None], hi[None])
        self._mark_empty(0, np.zeros(1, np.int64), flo)
        return int(t[0])

    # cell ids at level l: linear index over (i, j[, k]) with 2**l per axis
    def _ijk(self, level: int, ids: np.ndarray) -> np.ndarray:
        n = 1 << level
        out = np.empty((len(ids), 3), np.int64)
        rest = ids.copy()
        for ax in range(self.axes - 1, -1, -1):
            out[:, ax] = rest % n
            rest //= n
        if self.axes == 2:
            out[:, 2] = 0
        return out

    def _box_lo(self, level: int, ids: np.ndarray) -> np.ndarray:
        ijk = self._ijk(level, ids)
        lo = self.lo + ijk * (self.span / (1 << level))
        if self.axes == 2:
            lo[:, 2] = 0.0
        return lo

    def _box_hi(self, level: int, ids: np.ndarray) -> np.ndarray:
        ijk = self._ijk(level, ids) + 1
        hi = self.lo + ijk * (self.span / (1 << level))
        top = ijk == (1 << level)
        hi[top] = np.broadcast_to(self.lo + self.span, hi.shape)[top]
        if self.axes == 2:
            hi[:, 2] = 0.0
        return hi

    def _parent_ids(self, level: int, ids: np.ndarray) -> np.ndarray:
        ijk = self._ijk(level, ids) // 2
        n = 1 << (level - 1)
        out = np.zeros(len(ids), np.int64)
        for ax in range(self.axes):
            out = out * n + ijk[:, ax]
        return out

    def tapes(self, level: int, ids: np.ndarray) -> np.ndarray:
        """The tapes of cells ``ids`` (``(M,)`` int64) at ``level``, built if missing."""
        with self.lock:
            return self._tapes(level, ids)

    def _tapes(self, level: int, ids: np.ndarray) -> np.ndarray:
        table = self.tables[level]
        missing = np.unique(ids[table[ids] < 0])
        if len(missing):
            par = self._tapes(level - 1, self._parent_ids(level, missing))
            # each cell's tape holds on its box grown by a hair, so that a point put
            # in it by rounding (or on its faces) is inside
            pad = 1e-7 * self.span / (1 << level)
            lo, hi = self._box_lo(level, missing) - pad, self._box_hi(level, missing) + pad
            if self.axes == 2:
                lo[:, 2] = hi[:, 2] = 0.0
            t, flo, _ = self.pool.shorten(par, lo, hi)
            table[missing] = t
            self._mark_empty(level, missing, flo)
            if level == self.depth < self.empty_depth:
                self._mark_children(missing, t, flo)
        return table[ids]

    def track_empty(self) -> np.ndarray:
        """Keep the cells proved empty one level finer than the tapes (each cell built
        from now on also bounds its children: intervals only, no tapes); returns the
        flags (see :attr:`empty`). Limited to ``2**21`` flags (depth 6 in 3D)."""
        with self.lock:
            fine = self.depth + 1
            if self.empty_depth < fine and (1 << fine) ** self.axes <= 1 << 21:
                old = self.empty.reshape((1 << self.depth,) * self.axes)
                for ax in range(self.axes):
                    old = np.repeat(old, 2, axis=ax)
                self.empty = np.ascontiguousarray(old).reshape(-1)
                self.empty_depth = fine
            return self.empty

    def _mark_children(self, ids: np.ndarray, tapes: np.ndarray, flo: np.ndarray) -> None:
        """Bound the children of the new finest cells ``ids`` (tapes ``tapes``) that
        are not proved empty themselves, and flag the empty ones."""
        keep = ~(flo > 0)
        ids, tapes = ids[keep], tapes[keep]
        if not len(ids):
            return
        k = 1 << self.axes
        ijk = self._ijk(self.depth, ids)[:, :self.axes] * 2
        offs = np.array([[(c >> (self.axes - 1 - ax)) & 1 for ax in range(self.axes)]
                         for c in range(k)])
        kid = (ijk[:, None, :] + offs[None]).reshape(-1, self.axes)
        n = 1 << (self.depth + 1)
        kid_ids = np.zeros(len(kid), np.int64)
        for ax in range(self.axes):
            kid_ids = kid_ids * n + kid[:, ax]
        level = self.depth + 1
        pad = 1e-7 * self.span / (1 << level)
        lo, hi = self._box_lo(level, kid_ids) - pad, self._box_hi(level, kid_ids) + pad
        if self.axes == 2:
            lo[:, 2] = hi[:, 2] = 0.0
        _, klo, _ = self.pool.shorten(np.repeat(tapes, k), lo, hi, emit=False)
        self.empty[kid_ids[klo > 0]] = 1

    def _mark_empty(self, level: int, ids: np.ndarray, flo: np.ndarray) -> None:
        """Flag the finest cells under cells ``ids`` of ``level`` whose interval lower
        bound ``flo`` is positive (no surface and no inside there)."""
        ids = ids[flo > 0]
        if not len(ids):
            return
        m = self.empty_depth - level
        if m == 0:
            self.empty[ids] = 1
            return
        n = 1 << self.empty_depth
        grid = self.empty.reshape((n,) * self.axes)
        w = 1 << m
        for ijk in self._ijk(level, ids)[:, :self.axes] * w:
            grid[tuple(slice(int(a), int(a) + w) for a in ijk)] = 1

    def cells_of(self, pts: np.ndarray, level: int,
                 upper: bool = False) -> np.ndarray:
        """Cell ids ``(N,)`` at ``level`` of points ``(N, 3)``, -1 for points outside
        the box. ``upper``: a point on a face between cells goes to the lower cell
        (for the upper corners of boxes)."""
        ids = np.empty(len(pts), np.int64)
        _k().point_cells(np.ascontiguousarray(pts, np.float64), self.lo, self.span,
                         1 << level, self.axes, upper, ids)
        return ids

    def evaluate(self, pts: np.ndarray, grad: bool = False):
        """Values ``(N,)`` (and gradients ``(N, 3)`` when ``grad``) at ``pts``
        (``(N, 3)`` float64 C-contiguous; 2D programs read x, y)."""
        K = _k()
        N = len(pts)
        group = self.cells_of(pts, self.depth)
        occupied = np.empty(min(N, len(self.tables[self.depth])), np.int64)
        with self.lock:  # number the occupied cells in O(N), then their tapes
            self.epoch += 1
            if self.epoch >= np.iinfo(np.int32).max:
                self.stamp[:] = 0
                self.epoch = 1
            k = K.compact_cells(group, self.stamp, self.slot, self.epoch, occupied)
            cell_tape = np.empty(k + 1, np.int64)
            cell_tape[:k] = self._tapes(self.depth, occupied[:k])
        cell_tape[k] = 0  # points outside the region: the whole tape
        order, bounds = group_by_cell(group, k + 1)
        out = np.empty(N)
        g = np.empty((N, 3)) if grad else np.empty((1, 3))
        pool = self.pool
        _parallel("eval_cells", len(cell_tape), pool.code, pool.imm, pool.start,
                  pool.length, pool.out, pool.regs, cell_tape, order, bounds, pts, out, g,
                  grad, 64)
        bad = np.isnan(pts).any(axis=1)
        if bad.any():
            out[bad] = np.nan
            if grad:
                g[bad] = np.nan
        return (out, g) if grad else out

    def intervals(self, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Bounds ``(M,)`` of the values over boxes ``[lo, hi]`` (``(M, 3)``), each from
        the tape of the smallest cell that holds the box (the whole tape for boxes not
        inside the region)."""
        M = len(lo)
        tape = np.zeros(M, np.int64)
        done = np.zeros(M, bool)
        for level in range(self.depth, -1, -1):
            a = self.cells_of(lo, level)
            b = self.cells_of(hi, level, upper=True)
            here = ~done & (a >= 0) & (a == b)
            if here.any():
                tape[here] = self.tapes(level, a[here])
                done |= here
        _, flo, fhi = self.pool.shorten(tape, lo, hi, emit=False)
        return flo, fhi


def cell_tapes(prog, pvals: np.ndarray, box: np.ndarray, depth: int | None = None) -> CellTapes:
    """The (cached on the program) :class:`CellTapes` of a program at these parameter
    values over this box; ``depth`` default: 5 in 3D (32 cells per axis), 8 in 2D."""
    if depth is None:
        depth = 5 if prog.dim == 3 else 8
    key = (np.asarray(pvals, np.float64).tobytes(), np.asarray(box, np.float64).tobytes(),
           depth)
    return memo(prog, "_cell_tapes", key, lambda: CellTapes(prog, pvals, box, depth), 9)

