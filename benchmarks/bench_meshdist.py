"""Exact signed distance to a triangle mesh (issue 20, the core of ``from_mesh``):
:class:`csdf.backends.meshdist.MeshDistance` against ``trimesh.proximity.
signed_distance`` and (the ``bench`` extra) Open3D's ``RaycastingScene.
compute_signed_distance``, on the same meshes and points in the same run.

The ``csdf.from_mesh`` rows run the same query as a shape's compiled program (one mesh
call, the mesh a data block of the bytecode), through ``Program.__call__``.

Meshes: a torus of 10,000 triangles (``trimesh.creation.torus``, major 1, minor 0.3)
and the zoo chair meshed by ``csdf.mesh`` at resolution 64 (about 10,600 triangles).
Points: 10^6 uniform in the mesh's box padded by 10 % a side (seeded). trimesh is timed
on 10^4 of them (it takes minutes for 10^6) and its time scaled by 100, said so in its
row. Each timing is the median of ``--repeat`` runs after one warm-up call; the
agreement columns compare the distances with csdf's on the points each method ran.

Run: ``python benchmarks/bench_meshdist.py [--points 1000000] [--repeat 3]``.
"""

from __future__ import annotations

import argparse
import platform

import numpy as np
import trimesh
from common import median_time

import csdf
from csdf.backends.meshdist import MeshDistance


def _time(fn, repeat: int) -> tuple[float, object]:
    return median_time(fn, repeat)


def meshes() -> list[tuple[str, trimesh.Trimesh]]:
    torus = trimesh.creation.torus(1.0, 0.3, major_sections=100, minor_sections=50)
    m = csdf.mesh(csdf.zoo.load("chair"), resolution=64, progress=False)
    chair = trimesh.Trimesh(m.vertices, m.faces, process=False)
    return [("torus", torus), ("chair (csdf.mesh, r = 64)", chair)]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--points", type=int, default=1_000_000)
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args()
    try:
        import open3d as o3d
    except ImportError:
        o3d = None
    print(f"machine: {platform.processor() or platform.machine()}, "
          f"{csdf.parallel.N_THREADS} threads; {a.points} points; median of {a.repeat}")
    print("| mesh | triangles | method | s for the points | vs csdf | max abs diff vs csdf |")
    print("|---|---|---|---|---|---|")
    for name, m in meshes():
        lo, hi = m.bounds
        pad = 0.1 * (hi - lo)
        P = np.random.default_rng(0).uniform(lo - pad, hi + pad, (a.points, 3))
        md = MeshDistance(m)
        t_c, d_c = _time(lambda md=md, P=P: md.value(P), a.repeat)
        nt = len(m.faces)
        print(f"| {name} | {nt} | csdf MeshDistance | {t_c:.3f} | 1.00 | 0 |")
        # the same query as a shape: one mesh call of a compiled program
        prog = csdf.from_mesh(m).compile()
        t_p, d_p = _time(lambda prog=prog, P=P: prog(P), a.repeat)
        diff = float(np.abs(d_p - d_c).max())
        print(f"| {name} | {nt} | csdf.from_mesh program, values | {t_p:.3f} | "
              f"{t_p / t_c:.2f} | {diff:.2e} |")
        t_g, _ = _time(lambda prog=prog, P=P: prog.value_and_grad(P), a.repeat)
        print(f"| {name} | {nt} | csdf.from_mesh program, values and gradients | "
              f"{t_g:.3f} | {t_g / t_c:.2f} | - |")
        if o3d is not None:
            scene = o3d.t.geometry.RaycastingScene()
            scene.add_triangles(o3d.core.Tensor(np.asarray(m.vertices, np.float32)),
                                o3d.core.Tensor(np.asarray(m.faces, np.uint32)))
            q = o3d.core.Tensor(P.astype(np.float32))
            t_o, d_o = _time(lambda s=scene, q=q: s.compute_signed_distance(q).numpy(),
                             a.repeat)
            diff = float(np.abs(d_o.astype(float) - d_c).max())
            print(f"| {name} | {nt} | Open3D RaycastingScene (float32) | {t_o:.3f} | "
                  f"{t_o / t_c:.2f} | {diff:.2e} |")
        k = min(10_000, a.points)
        t_t, d_t = _time(lambda m=m, P=P, k=k: trimesh.proximity.signed_distance(m, P[:k]),
                         1)
        # trimesh's sign convention is the opposite (positive inside)
        diff = float(np.abs(-np.asarray(d_t) - d_c[:k]).max())
        scaled = t_t * a.points / k
        print(f"| {name} | {nt} | trimesh.proximity.signed_distance ({k} points, time "
              f"x{a.points // k}) | {scaled:.1f} | {scaled / t_c:.0f} | {diff:.2e} |")


if __name__ == "__main__":
    main()
