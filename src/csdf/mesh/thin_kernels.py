"""The compiled step of the thin-part check (:mod:`.thin`): one pass over the bricks'
voxels that finds the candidates (corners of one sign, near the zero set) and counts the
inside samples. Same results as :func:`.thin._scan_numpy`, without its ``(K, B, B, B)``
temporaries."""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["scan_bricks"]


@njit(cache=True, nogil=True)
def scan_bricks(v, bricks, dims, reach, n):  # pragma: no cover - compiled
    """One pass over the voxels of bricks ``(K, 3)`` with samples ``v (K, n, n, n)``,
    closed on the grid box as the mesher samples them (:func:`.kernels.close_on_box`:
    samples on the grid's boundary are outside, at least ``h``).

    Returns:
        ``(ijk (C, 3), neg (C,), inside)``: the candidate voxels (interior ones whose
        corners share a sign, with the corner nearest the zero set within ``reach`` of
        it), whether the sign sought inside them is negative, and the number of inside
        samples the bricks own (their voxels' lower corners inside the grid).
    """
    k = bricks.shape[0]
    m = n - 1
    ijk = np.empty((k * m * m * m, 3), dtype=np.int64)
    neg = np.empty(k * m * m * m, dtype=np.bool_)
    c = 0
    inside = 0
    for b in range(k):
        for i in range(m):
            gi = bricks[b, 0] + i
            for j in range(m):
                gj = bricks[b, 1] + j
                for l in range(m):
                    gl = bricks[b, 2] + l
                    if gi >= dims[0] or gj >= dims[1] or gl >= dims[2]:
                        continue
                    lo = np.inf
                    hi = -np.inf
                    for di in range(2):
                        for dj in range(2):
                            for dl in range(2):
                                x = v[b, i + di, j + dj, l + dl]
                                lo = min(lo, x)
                                hi = max(hi, x)
                    if v[b, i, j, l] < 0:  # (boundary samples are outside)
                        inside += 1
                    if not (gi >= 1 and gj >= 1 and gl >= 1 and gi + 1 < dims[0]
                            and gj + 1 < dims[1] and gl + 1 < dims[2]):
                        continue
                    if lo > 0 and lo < reach:
                        ijk[c, 0], ijk[c, 1], ijk[c, 2] = gi, gj, gl
                        neg[c] = True
                        c += 1
                    elif hi < 0 and -hi < reach:
                        ijk[c, 0], ijk[c, 1], ijk[c, 2] = gi, gj, gl
                        neg[c] = False
                        c += 1
    return ijk[:c], neg[:c], inside
