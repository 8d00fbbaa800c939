"""The steps of dual contouring that both meshers share: the normals at the edge roots
(:func:`edge_normals`), the compiled QEF vertices and edge quads (:func:`dc_solve`), and
the compiled projection of the vertices and split of the quads (:func:`dc_finish`).

The NumPy reference mesher (:mod:`.reference`) runs these after its own edge roots with
``compiled=True`` and has NumPy versions of the last two (its oracle); the streaming
mesher (:mod:`.stream`) runs them after its stream. The compiled kernels are in
:mod:`.dc_kernels` (Numba, imported when called).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from .cases import COMPONENT_TABLE, EDGE_ORIGIN, MAX_COMPONENTS
from .grid import Grid

__all__ = ["edge_normals", "dc_solve", "dc_finish", "PROJECT_STEPS", "SPLIT_MIN", "TIE"]

#: Newton steps projecting the dual-contouring vertices onto the zero set
PROJECT_STEPS = 3
SPLIT_MIN = 65536  # active voxels worth solving on several threads

# a quad's diagonals tie (flat faces: both midpoints on the surface up to rounding) when
# their |f| differ by less than this many voxels: take 0-2, whatever the rounding
TIE = 1e-9


def edge_normals(grid: Grid, roots: np.ndarray, uaxis: np.ndarray, gradients: Callable,
                 on_box: np.ndarray) -> np.ndarray:
    """Unit normals ``(E, 3)`` at the edge roots ``(E, 3)`` (edge axes ``uaxis (E,)``)."""
    # normals from both sides of the surface along each edge: exactly on a kink (a box
    # face, f = 0 where max/min tie) a gradient is a one-sided choice and can vanish
    step = np.eye(3)[uaxis] * (1e-4 * grid.h)
    normals = gradients(np.concatenate([roots - step, roots + step]))
    normals = normals[: len(roots)] + normals[len(roots):]
    nlen = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = np.where(nlen > 0, normals / np.maximum(nlen, 1e-300), 0.0)
    # box-clipped edges: their normal is the box face normal (the box closes the surface)
    if on_box.any():
        lo_b = grid.origin
        hi_b = grid.origin + grid.h * np.array(grid.dims)
        rp = roots[on_box]
        d = np.stack([lo_b - rp, rp - hi_b], axis=1).reshape(len(rp), 6)
        face = np.argmax(d, axis=1)
        nb = np.zeros((len(rp), 3))
        nb[np.arange(len(rp)), face % 3] = np.where(face < 3, -1.0, 1.0)
        normals[on_box] = np.where((np.max(d, axis=1) > -grid.h)[:, None], nb, normals[on_box])
    return normals


def dc_solve(grid: Grid, vox: np.ndarray, vcase: np.ndarray, inv: np.ndarray,
             roots: np.ndarray, normals: np.ndarray, uaxis: np.ndarray,
             threads: int = 1) -> tuple:
    """Compiled QEF vertices ``(V, 3)`` and edge quads ``(E, 4)`` with their found-corner
    masks ``(E,)`` (:func:`.dc_kernels.dc_vertices_range`; arguments as there). With
    ``threads > 1`` (and at least ``SPLIT_MIN`` voxels) the voxels are split into that
    many ranges solved side by side (the same results)."""
    from . import dc_kernels as D

    args = (np.asarray(vox, dtype=np.int64), np.asarray(vcase, dtype=np.int64),
            np.asarray(inv, dtype=np.int64), roots, normals,
            np.asarray(uaxis, dtype=np.int64), COMPONENT_TABLE.astype(np.int64),
            EDGE_ORIGIN.astype(np.int64), np.asarray(grid.origin, dtype=np.float64),
            float(grid.h))
    rank, n_comp, n_pairs = D.dc_case_tables(args[6], MAX_COMPONENTS)
    case = args[1]
    vstart = np.concatenate([[0], np.cumsum(n_comp[case])])  # first vertex of each voxel
    pstart = np.concatenate([[0], np.cumsum(n_pairs[case])])  # first pair of each voxel
    verts = np.empty((int(vstart[-1]), 3))
    quads = np.full((len(roots), 4), -1, dtype=np.int64)
    if threads <= 1 or len(vox) < SPLIT_MIN:
        threads = 1
    cuts = np.linspace(0, len(vox), threads + 1).astype(np.int64)
    ranges = [(int(a0), int(a1), int(pstart[a0]), int(vstart[a0]), *args, rank, n_comp,
               verts, quads) for a0, a1 in zip(cuts[:-1], cuts[1:])]
    if threads == 1:
        D.dc_vertices_range(*ranges[0])
    else:
        from ..parallel import executor

        pool = executor("csdf-dc", threads)
        for job in [pool.submit(D.dc_vertices_range, *r) for r in ranges]:
            job.result()
    return verts, quads, D.dc_found(quads)


def dc_finish(grid: Grid, verts: np.ndarray, quads: np.ndarray, found: np.ndarray,
              f0: np.ndarray, values: Callable, gradients_values: Callable,
              block: int = 1 << 18) -> tuple[np.ndarray, np.ndarray]:
    """Vertices ``(V, 3)`` projected to the surface and the split, wound triangles
    ``(F, 3)`` of the complete quads; the field is evaluated ``block`` points at a time
    (the result does not depend on it)."""
    from . import dc_kernels as D

    for s in range(0, len(verts), block):
        v = verts[s:s + block]
        for _ in range(PROJECT_STEPS):  # (reference._project's steps, compiled)
            f, g = gradients_values(v)
            D.newton_step(v, np.asarray(f, dtype=np.float64), np.asarray(g, dtype=np.float64),
                          float(grid.h))
    quads = D.dc_quads(quads, found, f0)
    fm = np.empty(2 * len(quads))
    n = len(quads)
    for s in range(0, n, block):
        q = quads[s:s + block]
        f = np.asarray(values(D.dc_midpoints(q, verts)), dtype=np.float64)
        fm[s:s + len(q)] = f[:len(q)]
        fm[n + s:n + s + len(q)] = f[len(q):]
    return verts, D.dc_split(quads, fm, TIE * grid.h)
