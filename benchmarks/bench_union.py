"""Meshing and rendering a union of many primitives (issue 16): cost per output element
of a union of 1,000 random primitives against a union of 20, with and without pruned
evaluation, timed in the same run.

The unions: spheres, boxes and tori at random places in a cube whose side grows with
the cube root of the count (so the density of primitives, and the surface per
primitive, stay about the same). Meshing: marching cubes at a fixed voxel size, so the
1,000-primitive mesh has ~50x the triangles; cost per triangle. Rendering: a 320x240
sphere-traced image of the whole union; cost per pixel on the object.

For each union: the median of warm runs (the program compiled beforehand; pruned
evaluation keeps its cell tapes between calls, so warm runs reuse them), and the
first run (which builds them). Without pruning the 1,000-primitive union runs on the
``interp`` backend (``auto`` does not compile per-program kernels for programs this
long), the 20-primitive union on the compiled ``fast`` backend. The pruned and
unpruned meshes are compared vertex by vertex (as sets: the unpruned one comes from
the reference mesher). Run: ``python benchmarks/bench_union.py [--runs 3]``.
"""

from __future__ import annotations

import argparse
import importlib
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import machine_info, md_table  # noqa: E402


def union(n: int, seed: int = 0):
    """A union of ``n`` random primitives (:func:`csdf.zoo.clutter`)."""
    import csdf

    return csdf.zoo.clutter(n, seed)


def _time(fn, runs: int):
    t0 = time.perf_counter()
    out = fn()
    first = time.perf_counter() - t0
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return first, statistics.median(times), out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--voxel", type=float, default=0.05, help="voxel size (model units)")
    args = p.parse_args(argv)
    import csdf
    F = importlib.import_module("csdf.field")  # (csdf.field is the user-field function)

    print("\n".join(f"* {k}: {v}" for k, v in machine_info().items()))
    rows = []
    per = {}
    meshes = {}
    renders = {}
    for n in (20, 1000):
        prog = union(n).compile()
        b = prog.bounds
        side = float(np.max(b[1] - b[0]))
        cam = csdf.Camera.look_at(eye=(b[1] + side * 0.9), target=(b[0] + b[1]) / 2,
                                  width=320, height=240)
        for prune in (True, False):
            if n == 20 and not prune:
                continue  # short programs are never pruned
            F.PRUNE_MIN_INSTRUCTIONS = 1500 if prune else 10**9
            prog.__dict__.pop("_cell_tapes", None)
            fm, tm, m = _time(lambda p=prog: csdf.mesh(p, voxel_size=args.voxel,
                                                       check_thin=False), args.runs)
            prog.__dict__.pop("_cell_tapes", None)
            fr, tr, r = _time(lambda p=prog, c=cam: csdf.render(p, c), args.runs)
            hit = int(np.count_nonzero(np.isfinite(r.depth)))
            meshes[(n, prune)] = m
            renders[(n, prune)] = r
            key = (n, prune)
            per[key] = (tm / len(m.faces), tr / max(hit, 1))
            how = ("pruned" if prune else "not pruned") if n > 20 else "compiled (short)"
            rows.append([f"{n} ({len(prog)} instr.)", how,
                         f"{len(m.faces):,}", f"{tm:.2f}", f"{fm:.2f}",
                         f"{per[key][0] * 1e6:.2f}", f"{tr:.2f}", f"{fr:.2f}",
                         f"{per[key][1] * 1e6:.2f}"])
    F.PRUNE_MIN_INSTRUCTIONS = 1500
    print()
    print(md_table(["union of", "evaluation", "triangles", "mesh s (median)", "first s",
                    "us/triangle", "render s (median)", "first s", "us/pixel hit"], rows))
    base = per[(20, True)]
    for prune in (True, False):
        q = per[(1000, prune)]
        print(f"\n1,000 against 20 ({'pruned' if prune else 'not pruned'}): "
              f"{q[0] / base[0]:.1f}x per triangle, {q[1] / base[1]:.1f}x per pixel")
    a = np.unique(np.round(meshes[(1000, True)].vertices, 9), axis=0)
    z = np.unique(np.round(meshes[(1000, False)].vertices, 9), axis=0)
    same = a.shape == z.shape and bool(np.allclose(a, z, atol=1e-8))
    print(f"pruned and unpruned meshes of the 1,000-primitive union have the same "
          f"vertices: {same}")
    a, z = renders[(1000, True)], renders[(1000, False)]
    both = a.mask & z.mask
    print(f"pruned and unpruned images: {int(np.count_nonzero(a.mask != z.mask))} of "
          f"{a.mask.size} pixels differ in coverage (rays grazing slivers thinner than the "
          f"hit tolerance, sampled differently where the pruned tracer skips empty cells), "
          f"{int(np.count_nonzero((a.color != z.color).any(axis=-1)))} in colour; depth "
          f"where both hit: max difference {np.abs(a.depth[both] - z.depth[both]).max():.1e}"
          f" (median {np.median(np.abs(a.depth[both] - z.depth[both])):.1e})")
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())
