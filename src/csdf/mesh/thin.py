"""Parts and gaps thinner than a voxel: found with interval arithmetic between the samples.

A mesher on a grid of voxel edge ``h`` sees only the signs of its samples. A board
thinner than ``h`` that passes between two sample planes, the tip of a thin rod, or a
slot narrower than a voxel change no sample's sign, so marching cubes and dual
contouring lose them without a trace. :func:`thin_parts` finds them:

1. the octree's bricks (:func:`.grid.octree`) are sampled as the mesher samples them;
2. a voxel whose eight corners share a sign is a *candidate* when its interval over the
   voxel's box admits the other sign (for a distance or a distance bound, only voxels
   whose nearest corner is within ``L h sqrt(3) / 2`` of the zero set can: the others
   are skipped without intervals);
3. candidates are split into octants, level by level down to ``min_cell``, keeping the
   cells whose interval still admits the other sign: a cell whose interval has only the
   other sign counts whole, and at the last level a cell counts when its centre has the
   other sign. A candidate in which something was counted holds a part (or a gap) that
   the grid loses; the counted cells' volume estimates how much.

Intervals are conservative, so nothing that is there is missed above the resolution of
``min_cell``; what is reported is found at sample points, so nothing is invented.
The report also carries a Monte Carlo estimate of the field's volume on the grid (the
octree's wholly inside cells, plus stratified points in its bricks), which
:func:`csdf.mesh` compares with the mesh's volume, and the centres of the voxels that
hold lost parts, which it compares with the mesh's pieces. It uses the report to choose
its default resolution and to warn when an explicit one loses parts.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .cases import CORNERS
from .grid import BRICK, Grid, octree
from .reference import sample_bricks

__all__ = ["ThinReport", "ThinScan", "thin_parts", "LOST_FRACTION", "MAX_CELLS", "MC_POINTS"]

#: the share of the shape's volume in lost parts and gaps above which a grid is too
#: coarse (``csdf.mesh`` refines its default grid, or warns for an explicit one)
LOST_FRACTION = 0.002
#: cells refined at once at most; beyond, the deepest levels are estimated from centres
MAX_CELLS = 4_000_000
#: Monte Carlo points (over the octree's bricks) for the field's volume
MC_POINTS = 1 << 20
_BRICKS_PER_CHUNK = 2048  # bricks sampled at once (2048 * 729 samples, ~36 MB of points)
_CANDIDATES_PER_BLOCK = 1 << 17  # candidate voxels refined together


@dataclass(frozen=True)
class ThinReport:
    """What the grid loses between its samples (see the module docs).

    Attributes:
        h: the grid's voxel edge (model units).
        voxels: voxels whose corners share a sign although the other sign lies inside.
        lost_volume: estimated volume of inside parts between the samples (units^3).
        gap_volume: estimated volume of gaps (outside space) between the samples.
        volume: estimated volume of the shape inside the grid (units^3).
        where: ``(3,)`` centre of the voxel with the most lost volume, or None.
        min_cell: edge of the smallest cell examined (units).
        truncated: True when the cell budget cut the refinement short (the volumes are
            then estimated from cell centres at a coarser level).
        field_volume, field_volume_se: the volume of ``{f < 0}`` inside the grid box
            and its standard error (units^3): the octree's wholly inside cells plus a
            stratified Monte Carlo estimate over its bricks (a fixed seed).
        lost_parts: ``(M, 3)`` centres of the voxels that hold lost parts (not gaps).
    """

    h: float
    voxels: int
    lost_volume: float
    gap_volume: float
    volume: float
    where: np.ndarray | None
    min_cell: float
    truncated: bool = False
    field_volume: float = float("nan")
    field_volume_se: float = float("nan")
    lost_parts: np.ndarray | None = None

    @property
    def fraction(self) -> float:
        """Lost parts and gaps as a share of the shape's volume (0 when nothing)."""
        if self.voxels == 0:
            return 0.0
        return (self.lost_volume + self.gap_volume) / max(self.volume, self.h ** 3)

    def too_coarse(self, fraction: float = LOST_FRACTION) -> bool:
        """The grid loses more than ``fraction`` of the volume in thin parts or gaps."""
        return self.fraction > fraction


def thin_parts(grid: Grid, values: Callable, intervals: Callable,
               lipschitz: float | None = None, min_cell: float | None = None,
               max_cells: int = MAX_CELLS, mc_points: int = MC_POINTS) -> ThinReport:
    """Find the parts and gaps of a field that ``grid`` loses between its samples (on its
    own; :func:`csdf.mesh` runs the same check on the mesher's samples, through
    :class:`ThinScan`).

    Args:
        grid: the mesher's grid.
        values: ``(M, 3) -> (M,)`` field values (the mesher's evaluator).
        intervals: ``(lo (M, 3), hi (M, 3)) -> (flo (M,), fhi (M,))``, conservative.
        lipschitz: ``L`` when ``|f(x) - f(y)| <= L |x - y|`` (a distance, a bound, or a
            field whose gradient is bounded by ``L``); None to test every same-sign
            voxel with intervals.
        min_cell: the thinnest part or gap to find (model units; default ``h / 4``):
            cells are refined down to half of it.
        max_cells: the most cells refined at once (bounds time and memory).
        mc_points: Monte Carlo points for :attr:`ThinReport.field_volume` (0: none).

    Returns:
        A :class:`ThinReport`.
    """
    scan = ThinScan(grid, lipschitz)
    inside = [0.0]
    bricks = octree(grid, intervals, None, inside=inside)
    scan.octree(bricks, inside[0])
    for s in range(0, len(bricks), _BRICKS_PER_CHUNK):
        b = bricks[s:s + _BRICKS_PER_CHUNK]
        scan(b, sample_bricks(grid, b, values))
    return scan.report(values, intervals, min_cell, max_cells, mc_points)


class ThinScan:
    """The thin-part check in two steps: called with each chunk of bricks and their
    samples ``(C, B+1, B+1, B+1)`` (closed on the grid box), it keeps the candidate
    voxels (thread-safe: the streaming mesher calls it from its workers); then
    :meth:`report` refines them.

    Args:
        grid: the grid sampled.
        lipschitz: as for :func:`thin_parts`.
    """

    def __init__(self, grid: Grid, lipschitz: float | None = None) -> None:
        self.grid = grid
        self.h = float(grid.h)
        self.dims = np.asarray(grid.dims, dtype=np.int64)
        self.reach = None if lipschitz is None else \
            float(lipschitz) * self.h * math.sqrt(3.0) / 2.0
        self.bricks = np.zeros((0, 3), dtype=np.int64)
        self.inside_volume = 0.0  # of the octree's wholly inside cells
        self._lock = threading.Lock()
        self._ijk: list[np.ndarray] = []
        self._neg: list[np.ndarray] = []
        self._inside = 0  # inside samples the bricks own

    def octree(self, bricks: np.ndarray, inside_volume: float) -> None:
        """Record the octree's bricks ``(K, 3)`` and the volume of its inside cells."""
        self.bricks = bricks
        self.inside_volume = float(inside_volume)

    def __call__(self, chunk: np.ndarray, vals: np.ndarray) -> None:
        """Scan one chunk of bricks ``(C, 3)`` with samples ``vals (C, n, n, n)``."""
        tk = _kernels()
        if tk is not None:
            ijk, neg, n_in = tk.scan_bricks(
                np.ascontiguousarray(vals, dtype=np.float64), chunk, self.dims,
                math.inf if self.reach is None else self.reach, BRICK + 1)
        else:
            ijk, neg, n_in = _scan_numpy(vals, chunk, self.dims, self.reach)
        with self._lock:
            if len(ijk):
                self._ijk.append(ijk)
                self._neg.append(neg)
            self._inside += int(n_in)

    def report(self, values: Callable, intervals: Callable, min_cell: float | None = None,
               max_cells: int = MAX_CELLS, mc_points: int = MC_POINTS) -> ThinReport:
        """Refine the candidates (module docs) and report; ``values``/``intervals`` as
        for :func:`thin_parts`."""
        h = self.h
        if min_cell is None:
            min_cell = h / 4
        # cells down to half of min_cell: a part min_cell thick holds a whole one
        levels = max(0, math.ceil(math.log2(2.0 * h / min_cell) - 1e-9))
        volume = self.inside_volume + self._inside * h ** 3
        fvol, fse = _brick_volume(self.grid, self.bricks, values, mc_points)
        fvol = fvol + self.inside_volume if mc_points > 0 else math.nan
        fse = fse if mc_points > 0 else math.nan
        if not self._ijk:
            return ThinReport(h, 0, 0.0, 0.0, volume, None, min_cell,
                              field_volume=fvol, field_volume_se=fse)
        all_lo = self.grid.points(np.concatenate(self._ijk))
        all_neg = np.concatenate(self._neg)
        counted, found, truncated = _refine(all_lo, all_neg, h, values, intervals,
                                            self.reach, levels, max_cells)
        where = None
        if found.any():
            k = int(np.argmax(np.where(found, counted, -1.0)))
            where = all_lo[k] + h / 2.0
        return ThinReport(h, int(found.sum()), float(counted[all_neg].sum()),
                          float(counted[~all_neg].sum()), volume, where, min_cell,
                          truncated, fvol, fse, all_lo[found & all_neg] + h / 2.0)


def _scan_numpy(v: np.ndarray, b: np.ndarray, dims: np.ndarray, reach: float | None
                ) -> tuple[np.ndarray, np.ndarray, int]:
    """:func:`.thin_kernels.scan_bricks` in NumPy (without Numba)."""
    n = BRICK
    # each voxel's corner minimum and maximum
    mn = v[:, :n, :n, :n].copy()
    mx = mn.copy()
    for c in CORNERS[1:]:
        w = v[:, c[0]:c[0] + n, c[1]:c[1] + n, c[2]:c[2] + n]
        np.minimum(mn, w, out=mn)
        np.maximum(mx, w, out=mx)
    # per axis: voxels inside the grid, and off its boundary (where samples count as
    # outside); each brick owns the samples of its own voxels' lower corners
    ax = b[:, :, None] + np.arange(n)[None, None, :]  # (K, 3, B)
    ok = ax < dims[None, :, None]
    off = (ax >= 1) & (ax + 1 < dims[None, :, None])
    valid = ok[:, 0, :, None, None] & ok[:, 1, None, :, None] & ok[:, 2, None, None, :]
    interior = off[:, 0, :, None, None] & off[:, 1, None, :, None] & off[:, 2, None, None, :]
    n_in = int(np.count_nonzero((v[:, :n, :n, :n] < 0) & valid))
    out_c = interior & (mn > 0)
    in_c = interior & (mx < 0)
    if reach is not None:
        out_c &= mn < reach
        in_c &= -mx < reach
    ijk, neg = [np.zeros((0, 3), dtype=np.int64)], [np.zeros(0, dtype=bool)]
    for mask, is_neg in ((out_c, True), (in_c, False)):
        k, i, j, m = np.nonzero(mask)
        ijk.append(b[k] + np.stack([i, j, m], axis=1))
        neg.append(np.full(len(k), is_neg))
    return np.concatenate(ijk), np.concatenate(neg), n_in


def _refine(lo: np.ndarray, want_neg: np.ndarray, h: float, values: Callable,
            intervals: Callable, reach: float | None, levels: int, max_cells: int
            ) -> tuple[np.ndarray, np.ndarray, bool]:
    """Refine candidate voxels ``lo (C, 3)`` (lower corners, model units) looking for the
    sign ``want_neg (C,)`` (True: negative): ``(counted (C,) volume found, found (C,),
    truncated)``."""
    counted = np.zeros(len(lo))  # volume counted per candidate voxel
    found = np.zeros(len(lo), dtype=bool)
    truncated = False
    for a in range(0, len(lo), _CANDIDATES_PER_BLOCK):  # (bounds the octants' arrays)
        sl = slice(a, a + _CANDIDATES_PER_BLOCK)
        truncated |= _refine_block(lo[sl], want_neg[sl], np.arange(a, a + len(lo[sl])),
                                   counted, found, h, values, intervals, reach, levels,
                                   max_cells)
    return counted, found, truncated


def _refine_block(lo: np.ndarray, want_neg: np.ndarray, owner: np.ndarray,
                  counted: np.ndarray, found: np.ndarray, h: float, values: Callable,
                  intervals: Callable, reach: float | None, levels: int, max_cells: int
                  ) -> bool:
    """:func:`_refine` on one block of candidates (``owner``: their indices into
    ``counted``/``found``, updated in place); returns whether it was truncated."""
    size = h
    truncated = False
    # the candidates themselves: keep those whose interval admits the other sign
    keep, whole = _classify(intervals, lo, size, want_neg)
    np.add.at(counted, owner[whole], size ** 3)
    found[owner[whole]] = True
    lo, want_neg, owner = lo[keep], want_neg[keep], owner[keep]
    for level in range(1, levels + 1):
        if not len(lo):
            break
        last = level == levels
        if 8 * len(lo) > max_cells:
            last, truncated = True, True
        size /= 2.0
        lo = (lo[:, None, :] + CORNERS[None] * size).reshape(-1, 3)
        want_neg = np.repeat(want_neg, 8)
        owner = np.repeat(owner, 8)
        centre = values(lo + size / 2.0)
        hit = np.where(want_neg, centre < 0, centre > 0)
        found[owner[hit]] = True
        if reach is not None:
            # a cell whose centre is farther than L * half-diagonal from the zero set
            # has one sign: no interval needed
            near = np.abs(centre) < reach * size / h
            keep, whole = np.zeros(len(lo), dtype=bool), np.zeros(len(lo), dtype=bool)
            if near.any():
                keep[near], whole[near] = _classify(intervals, lo[near], size,
                                                    want_neg[near])
            whole |= hit & ~near  # the whole cell has the sign sought
        else:
            keep, whole = _classify(intervals, lo, size, want_neg)
        np.add.at(counted, owner[whole], size ** 3)
        found[owner[whole]] = True
        if last:
            np.add.at(counted, owner[keep & hit], size ** 3)
            break
        lo, want_neg, owner = lo[keep], want_neg[keep], owner[keep]
    return truncated


def _classify(intervals: Callable, lo: np.ndarray, size: float, want_neg: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
    """For cells ``lo (M, 3)`` of edge ``size``: ``(keep, whole)`` masks: the interval
    admits the sign sought but also the other (keep refining), or has only the sign
    sought (the whole cell counts)."""
    flo, fhi = intervals(lo, lo + size)
    whole = np.where(want_neg, fhi < 0, flo > 0)
    admits = np.where(want_neg, flo < 0, fhi > 0)
    return admits & ~whole, whole


def _brick_volume(grid: Grid, bricks: np.ndarray, values: Callable, n: int
                  ) -> tuple[float, float]:
    """Volume of ``{f < 0}`` inside the bricks ``(K, 3)`` (clipped to the grid box) and
    its standard error, by stratified Monte Carlo: the same number of points in every
    brick (seeded, so the same grid gives the same estimate)."""
    if not len(bricks) or n <= 0:
        return 0.0, 0.0
    rng = np.random.default_rng(0x5DF)
    per = max(8, n // len(bricks))
    side = BRICK * grid.h
    dims = np.asarray(grid.dims)
    total, var = 0.0, 0.0
    for s in range(0, len(bricks), max(1, (1 << 20) // per)):
        b = bricks[s:s + max(1, (1 << 20) // per)]
        u = rng.random((len(b), per, 3))
        ijk = b[:, None, :] + u * BRICK  # in voxel units
        inside_box = np.all(ijk < dims, axis=2)
        v = values(grid.points(ijk.reshape(-1, 3))).reshape(len(b), per)
        frac = ((v < 0) & inside_box).mean(axis=1)
        total += float(frac.sum()) * side ** 3
        var += float((frac * (1 - frac) / (per - 1)).sum()) * side ** 6
    return total, math.sqrt(var)


def _kernels():
    """The compiled steps (:mod:`.thin_kernels`), or None without Numba."""
    try:
        from . import thin_kernels
    except ImportError:  # pragma: no cover - Numba is a dependency
        return None
    return thin_kernels
