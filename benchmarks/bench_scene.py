"""Scene queries (issue 17, the part that exists): sphere queries against scenes of
20, 200 and 1,000 primitives (rooms of zoo furniture plus random clutter, 20
primitives a room), beside a dense ESDF made with
``scipy.ndimage.distance_transform_edt`` (of one room).

For each scene: throughput of ``collide``, of ``sphere_distance`` with a margin of 10 cm
(``max_distance``: a planner's cost ignores farther obstacles) and without one
(1,000,000 spheres of radius 5 cm spread over the scene's box, median of runs), the
latency of a call of 100 spheres (median of 2,000 calls), and the per-query cost
against the smallest scene.
For the ESDF (voxel sizes 1, 2 and 5 cm over the same box): the time to build it from
csdf occupancy, its memory, the time of trilinear queries
(``scipy.ndimage.map_coordinates``) and the largest error against csdf's exact
distance, and the scene's own size in bytes (its programs and instance records).

Run: ``python benchmarks/bench_scene.py [--runs 3] [--esdf-voxels 0.05,0.02,0.01]``.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import machine_info, md_table  # noqa: E402

FURNITURE = [("table", (0.0, 0.0, 0.0), 0.0), ("chair", (0.0, -0.7, 0.0), 0.0),
             ("chair", (0.0, 0.7, 0.0), np.pi), ("stool", (1.2, 0.8, 0.0), 0.0),
             ("bookshelf", (-1.6, 0.0, 0.0), np.pi / 2), ("lamp", (1.4, -1.2, 0.0), 0.0)]
#: one room: 4 x 4 m, 2.5 m high
ROOM = np.array([4.0, 4.0, 2.5])
#: primitives per room (furniture, then clutter up to this)
PER_ROOM = 20
#: the planner's margin of the capped clearance query (m)
MARGIN = 0.1


def make_scene(n_primitives: int, seed: int = 0):
    """Rooms of ``ROOM`` size side by side, each with zoo furniture (as many pieces as
    fit in ``PER_ROOM`` primitives) and random spheres and boxes up to ``PER_ROOM``: the
    density stays the same as the scene grows. Returns ``(scene, primitives, box)``."""
    import csdf

    rng = np.random.default_rng(seed)
    scene = csdf.Scene()
    rooms = max(1, round(n_primitives / PER_ROOM))
    side = int(np.ceil(np.sqrt(rooms)))
    ball, crate = csdf.sphere(1.0), csdf.box(1.0)
    count = 0
    for r in range(rooms):
        origin = np.array([r % side, r // side, 0]) * ROOM
        centre = origin + ROOM * [0.5, 0.5, 0]
        here = 0
        for name, at, yaw in FURNITURE:
            prims = len(csdf.zoo.load(name).compile().calls)
            if here + prims > PER_ROOM:
                continue
            scene.add(name, pose=csdf.Pose.from_rotvec([0, 0, yaw], centre + at))
            here += prims
        while here < PER_ROOM:
            at = origin + rng.uniform([0.1, 0.1, 0.0], ROOM - 0.1)
            if here % 2:
                scene.add(ball, pose=csdf.Pose(translation=at), scale=rng.uniform(0.03, 0.1))
            else:
                scene.add(crate, pose=csdf.Pose.from_rotvec(rng.normal(size=3), at),
                          scale=rng.uniform(0.05, 0.2))
            here += 1
        count += here
    box = np.array([[0.0, 0.0, 0.0], [side * ROOM[0], side * ROOM[1], ROOM[2]]])
    return scene, count, box


def _median(fn, runs: int) -> float:
    fn()
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def _measure(scene, c: np.ndarray, r: np.ndarray, runs: int):
    """Seconds of ``collide`` and ``sphere_distance`` on all spheres (medians), and per
    call of the first 100 (medians over 2,000 calls)."""
    def margin(c, r):
        return scene.sphere_distance(c, r, max_distance=MARGIN)

    scene.collide(c[:10], r[:10])  # builds the hierarchy, loads the kernels
    fns = (scene.collide, margin, scene.sphere_distance)
    total = [_median(lambda f=f: f(c, r), runs) for f in fns]
    sc, sr = c[:100], r[:100]
    lat = []
    for fn in fns:
        times = []
        for _ in range(2000):
            t0 = time.perf_counter()
            fn(sc, sr)
            times.append(time.perf_counter() - t0)
        lat.append(statistics.median(times))
    return total, lat


def _esdf(scene, box: np.ndarray, h: float):
    """A signed ESDF on voxel centres of size ``h`` over ``box``: occupancy from the
    scene, distance transforms outside and inside. Returns (grid, origin, seconds)."""
    from scipy.ndimage import distance_transform_edt

    t0 = time.perf_counter()
    dims = np.ceil((box[1] - box[0]) / h).astype(int)
    axes = [box[0, i] + (np.arange(dims[i]) + 0.5) * h for i in range(3)]
    occ = np.empty(tuple(dims), bool)
    gx, gy = np.meshgrid(axes[0], axes[1], indexing="ij")
    for k, z in enumerate(axes[2]):
        pts = np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, z)], axis=1)
        occ[:, :, k] = scene.collide(pts, 0.0).reshape(gx.shape)  # distance < 0
    out = distance_transform_edt(~occ, sampling=h)
    inside = distance_transform_edt(occ, sampling=h)
    grid = np.where(occ, -inside, out).astype(np.float32)
    return grid, box[0] + 0.5 * h, time.perf_counter() - t0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--esdf-voxels", default="0.05,0.02,0.01",
                   help="voxel sizes of the ESDF in metres ('' to skip)")
    args = p.parse_args(argv)
    import csdf  # noqa: F401

    print("\n".join(f"* {k}: {v}" for k, v in machine_info().items()))
    rng = np.random.default_rng(1)
    rows = []
    base = None
    scenes = {}
    for n in (20, 200, 1000):
        scene, count, box = make_scene(n)
        scenes[n] = (scene, box)
        c = rng.uniform(box[0], box[1], (1_000_000, 3))
        r = np.full(len(c), 0.05)
        total, lat = _measure(scene, c, r, args.runs)
        if base is None:
            base = total
        hit = float(np.mean(scene.collide(c, r)))
        row = [f"{count} ({len(scene)} instances)", f"{hit:.3f}"]
        for t, t0, call in zip(total, base, lat):
            row += [f"{len(c) / t / 1e6:.2f}", f"{call * 1e6:.1f}", f"{t / t0:.2f}x"]
        rows.append(row)
    print()
    head = ["scene (primitives)", "fraction colliding"]
    for what in ("collide", f"clearance, margin {MARGIN} m", "clearance"):
        head += [f"{what}: M spheres/s", "us per 100-sphere call", "cost / 20"]
    print(md_table(head, rows))
    voxels = [float(v) for v in args.esdf_voxels.split(",") if v.strip()]
    if voxels:
        scene, box = scenes[20]
        q = rng.uniform(box[0] + 0.1, box[1] - 0.1, (200_000, 3))
        want = scene.query(q)
        t_csdf = _median(lambda: scene.distance(q), args.runs)
        size = sum(len(inst.model.compile().to_bytes()) if hasattr(inst.model, "compile")
                   else len(inst.model.to_bytes()) for inst in
                   {id(i.model): i for i in scene}.values()) + 19 * 8 * len(scene)
        erows = [["csdf scene (one room, 20 primitives)", "-", f"{size / 1e3:.1f} kB",
                  f"{t_csdf / len(q) * 1e9:.0f}", "0 (exact where flagged)"]]
        from scipy.ndimage import map_coordinates

        for h in voxels:
            grid, origin, build = _esdf(scene, box, h)
            idx = ((q - origin) / h).T
            t_q = _median(lambda g=grid, i=idx: map_coordinates(g, i, order=1,
                                                               mode="nearest"), args.runs)
            got = map_coordinates(grid, idx, order=1, mode="nearest")
            err = np.abs(got - want.distance)[want.exact]
            erows.append([f"ESDF {h * 100:g} cm ({grid.size / 1e6:.1f} M voxels)",
                          f"{build:.1f}", f"{grid.nbytes / 1e6:.1f} MB",
                          f"{t_q / len(q) * 1e9:.0f}",
                          f"{err.max() * 100:.2f} cm (median {np.median(err) * 100:.2f})"])
        print()
        print(md_table(["representation", "build s", "memory", "query ns/point",
                        "max |error| against csdf"], erows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
