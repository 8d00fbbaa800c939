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
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .cases import CORNERS
from .grid import BRICK, Grid, octree
from .reference import sample_bricks

__all__ = ["ThinReport", "thin_parts", "LOST_FRACTION", "MAX_CELLS", "MC_POINTS"]

#: the share of the shape's volume in lost parts and gaps above which a grid is too
#: coarse (``csdf.mesh`` refines its default grid, or warns for an explicit one)
LOST_FRACTION = 0.002
#: cells refined at once at most; beyond, the deepest levels are estimated from centres
MAX_CELLS = 4_000_000
#: Monte Carlo points (over the octree's bricks) for the field's volume
MC_POINTS = 1 << 20
_BRICKS_PER_CHUNK = 2048  # bricks sampled at once (2048 * 729 samples, ~36 MB of points)


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
    """Find the parts and gaps of a field that ``grid`` loses between its samples.

    Args:
        grid: the mesher's grid.
        values: ``(M, 3) -> (M,)`` field values (the mesher's evaluator).
        intervals: ``(lo (M, 3), hi (M, 3)) -> (flo (M,), fhi (M,))``, conservative.
        lipschitz: ``L`` when the field is a distance or a distance bound scaled by
            ``L`` (``|f(x) - f(y)| <= L |x - y|``); None for any other field (every
            same-sign voxel is then tested with intervals).
        min_cell: the smallest cell edge to refine to (model units; default ``h / 8``).
        max_cells: the most cells refined at once (bounds time and memory).
        mc_points: Monte Carlo points for :attr:`ThinReport.field_volume`.

    Returns:
        A :class:`ThinReport`.
    """
    h = float(grid.h)
    if min_cell is None:
        min_cell = h / 8
    levels = max(0, math.ceil(math.log2(h / min_cell) - 1e-9)) if min_cell < h else 0
    inside = [0.0]
    bricks = octree(grid, intervals, None, inside=inside)
    volume = inside[0]
    fvol, fse = _brick_volume(grid, bricks, values, mc_points)
    fvol += inside[0]
    dims = np.array(grid.dims)
    reach = None if lipschitz is None else float(lipschitz) * h * math.sqrt(3.0) / 2.0
    cand_lo, cand_neg = [], []
    n = BRICK
    for s in range(0, len(bricks), _BRICKS_PER_CHUNK):
        b = bricks[s:s + _BRICKS_PER_CHUNK]
        v = sample_bricks(grid, b, values)  # (K, B+1, B+1, B+1), x first
        # each voxel's corner minimum and maximum
        mn = v[:, :n, :n, :n].copy()
        mx = mn.copy()
        for c in CORNERS[1:]:
            w = v[:, c[0]:c[0] + n, c[1]:c[1] + n, c[2]:c[2] + n]
            np.minimum(mn, w, out=mn)
            np.maximum(mx, w, out=mx)
        # per axis: voxels inside the grid, and off its boundary (where samples count
        # as outside); each brick owns the samples of its own voxels' lower corners
        ax = b[:, :, None] + np.arange(n)[None, None, :]  # (K, 3, B)
        ok = ax < dims[None, :, None]
        off = (ax >= 1) & (ax + 1 < dims[None, :, None])
        valid = ok[:, 0, :, None, None] & ok[:, 1, None, :, None] & ok[:, 2, None, None, :]
        interior = (off[:, 0, :, None, None] & off[:, 1, None, :, None]
                    & off[:, 2, None, None, :])
        volume += float(np.count_nonzero((v[:, :n, :n, :n] < 0) & valid)) * h ** 3
        out_c = interior & (mn > 0)
        in_c = interior & (mx < 0)
        if reach is not None:
            out_c &= mn < reach
            in_c &= -mx < reach
        for mask, is_neg in ((out_c, True), (in_c, False)):
            k, i, j, m = np.nonzero(mask)
            if len(k):
                cand_lo.append(b[k] + np.stack([i, j, m], axis=1))
                cand_neg.append(np.full(len(k), is_neg))
    if not cand_lo:
        return ThinReport(h, 0, 0.0, 0.0, volume, None, min_cell,
                          field_volume=fvol, field_volume_se=fse)
    lo = grid.points(np.concatenate(cand_lo))
    want_neg = np.concatenate(cand_neg)
    owner = np.arange(len(lo))
    n_cand = len(lo)
    counted = np.zeros(n_cand)  # volume counted per candidate voxel
    found = np.zeros(n_cand, dtype=bool)
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
            part = keep & hit
            np.add.at(counted, owner[part], size ** 3)
            break
        lo, want_neg, owner = lo[keep], want_neg[keep], owner[keep]
    all_lo = grid.points(np.concatenate(cand_lo))
    all_neg = np.concatenate(cand_neg)
    lost = float(counted[all_neg].sum())
    gap = float(counted[~all_neg].sum())
    where = None
    if found.any():
        k = int(np.argmax(np.where(found, counted, -1.0)))
        where = all_lo[k] + h / 2.0
    parts = all_lo[found & all_neg] + h / 2.0
    return ThinReport(h, int(found.sum()), lost, gap, volume, where, min_cell, truncated,
                      fvol, fse, parts)


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
