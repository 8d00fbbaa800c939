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

Beside coal and python-fcl (when importable; a line says when one is not): each scene
taken apart into the libraries' collision objects (``fcl_baseline.py``: boxes, spheres,
cylinders, capsules as shapes; csdf's rounded boxes as coal boxes swept by a sphere, as
meshes for python-fcl; anything else as a mesh: a table says which), queried one sphere
at a time from Python with the first spheres of the same set: (a) one distance call of
the sphere against one object (median per call), (b) a collide and a distance query
against the whole scene through a ``DynamicAABBTreeCollisionManager`` (median of runs,
per sphere), (c) those as M spheres/s beside csdf's (csdf answers 1,000,000 spheres a
call on all cores; the libraries one a call on one), and whether the answers agree with
csdf's: the fraction of equal collide verdicts, the distance differences of the spheres
clear of the scene (where csdf flags its value exact, and everywhere), and those of the
least of the one-object distances of the first 200 spheres (the narrow phase alone:
coal's broad-phase distance keeps the last pair's distance, not the least; see
``fcl_baseline.py`` for this and the other API differences).

Run: ``python benchmarks/bench_scene.py [--runs 3] [--esdf-voxels 0.05,0.02,0.01]
[--baselines coal,fcl] [--baseline-spheres 10000] [--quick]``; ``--quick`` is a smoke
run (100,000 spheres, 200 latency calls, one run, the 5 cm ESDF, 200 baseline spheres),
whose figures are not for the results file.
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
from fcl_baseline import (  # noqa: E402
    BASELINES,
    LIBRARIES,
    describe,
    is_exact,
    load_library,
    scene_parts,
)

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


def _measure(scene, c: np.ndarray, r: np.ndarray, runs: int, calls: int = 2000):
    """Seconds of ``collide`` and ``sphere_distance`` on all spheres (medians), and per
    call of the first 100 (medians over ``calls`` calls)."""
    def margin(c, r):
        return scene.sphere_distance(c, r, max_distance=MARGIN)

    scene.collide(c[:10], r[:10])  # builds the hierarchy, loads the kernels
    fns = (scene.collide, margin, scene.sphere_distance)
    total = [_median(lambda f=f: f(c, r), runs) for f in fns]
    sc, sr = c[:100], r[:100]
    lat = []
    for fn in fns:
        times = []
        for _ in range(calls):
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


def _model_rows(scene, parts: list, libs: list[str]) -> list[list[str]]:
    """One row per model of the scene: its csdf primitives and what each library gets
    (parts of the first instance of each model)."""
    rows = []
    seen: set[int] = set()
    for inst in scene:
        if id(inst.model) in seen:
            continue
        seen.add(id(inst.model))
        mine = [p for i, p in parts if i == inst.id]
        label = inst.source.get("zoo") or f"clutter {inst.model.name}"
        rows.append([label, str(len(inst.model.compile().calls)),
                     *[describe(mine, lib) for lib in libs]])
    return rows


def _baseline(lib: str, scene, parts: list, c: np.ndarray, r: float, runs: int,
              brute: int = 200, seed: int = 0) -> dict:
    """One library against one scene, with the spheres ``c`` of radius ``r``: build
    seconds, per-pair distance call times (medians by kind of object), seconds per
    sphere of broad-phase collide and distance (medians of runs), and the agreement
    with csdf's answers: of the broad phase's answers, and of the smallest of the
    one-object distances of the first ``brute`` spheres (no broad phase)."""
    t0 = time.perf_counter()
    bl = BASELINES[lib]([p for _, p in parts], r)
    build = time.perf_counter() - t0
    rng = np.random.default_rng(seed)
    objs = rng.integers(len(parts), size=len(c))
    for i in range(min(50, len(c))):  # warm up (lazy initialisation, caches)
        bl.pair_distance(c[i], int(objs[i]))
    pair: dict[str, list[float]] = {}
    for i, k in enumerate(objs):
        dt, _ = bl.pair_distance(c[i], int(k))
        kind = "shape" if is_exact(parts[k][1], lib) else "mesh"
        pair.setdefault(kind, []).append(dt)
    t_col = _median(lambda: bl.collide(c), runs) / len(c)
    t_dist = _median(lambda: bl.distance(c), runs) / len(c)
    hit, dist = bl.collide(c), bl.distance(c)
    m = min(brute, len(c))
    least = np.array([min(bl.pair_distance(c[i], k)[1] for k in range(len(parts)))
                      for i in range(m)])
    # csdf's answers for the same spheres
    want = scene.collide(c, r)
    q = scene.query(c)
    ref = q.distance - r
    exact_ids = {i for i, _ in parts} - {i for i, p in parts if not is_exact(p, lib)}
    clear = (ref > 0) & (dist > 0)
    diff = np.abs(dist - ref)[clear]
    flagged = (q.exact & np.isin(q.instance, list(exact_ids)))[clear]
    clear_m = (ref[:m] > 0) & (least > 0)
    diff_m = np.abs(least - ref[:m])[clear_m]
    return {"build": build, "pair": {k: statistics.median(v) for k, v in pair.items()},
            "collide": t_col, "distance": t_dist, "agree": float(np.mean(hit == want)),
            "hits": (int(want.sum()), int(hit.sum()), int(np.sum(hit != want))),
            "diff_exact": float(diff[flagged].max()) if flagged.any() else float("nan"),
            "n_exact": int(flagged.sum()), "diff_all": float(diff.max()) if diff.size
            else float("nan"), "far_off": float(np.mean(diff > 1e-3)) if diff.size else 0.0,
            "n_clear": int(clear.sum()),
            "diff_least": float(diff_m.max()) if diff_m.size else float("nan"),
            "n_least": int(clear_m.sum())}


def _baseline_tables(runs: list[tuple], libs: list[str], repeats: int) -> None:
    """Print the baselines' tables: what each library gets, timings beside csdf's, and
    agreement. ``runs``: ``(n, count, scene, spheres, radius, csdf collide seconds per
    sphere, csdf distance seconds per sphere)`` per scene."""
    n0, _, scene0, *_ = runs[0]
    parts_of = {n: scene_parts(scene) for n, _, scene, *_ in runs}
    print()
    print(md_table(["model (one room)", "csdf primitives", *[f"{lib} objects" for lib in libs]],
                   _model_rows(scene0, parts_of[n0], libs)))
    trows, arows = [], []
    for n, count, scene, c, r, csdf_col, csdf_dist in runs:
        parts = parts_of[n]
        for lib in libs:
            res = _baseline(lib, scene, parts, c, r, repeats)
            pair = ", ".join(f"{v * 1e6:.1f} ({k})" for k, v in sorted(res["pair"].items(),
                                                                     reverse=True))
            name = f"{count} ({len(parts)} objects)"
            trows.append([name, lib, f"{res['build']:.2f}", pair,
                          f"{res['collide'] * 1e6:.1f}", f"{1e-6 / res['collide']:.3f}",
                          f"{1e-6 / csdf_col:.2f}", f"{res['distance'] * 1e6:.1f}",
                          f"{1e-6 / res['distance']:.3f}", f"{1e-6 / csdf_dist:.2f}"])
            want, got, differ = res["hits"]
            ex = (f"{res['diff_exact'] * 1e3:.2g} mm ({res['n_exact']})" if res["n_exact"]
                  else "- (0)")
            arows.append([name, lib, f"{len(c)}", f"{res['agree']:.4f}",
                          f"{want} / {got} ({differ} differ)", ex,
                          f"{res['diff_all'] * 1e3:.2g} mm ({res['n_clear']})",
                          f"{res['far_off']:.3f}",
                          f"{res['diff_least'] * 1e3:.2g} mm ({res['n_least']})"])
    print()
    print(md_table(["scene (primitives)", "library", "build s",
                    "one distance call, us (object kind)", "collide: us per sphere",
                    "M spheres/s", "csdf M spheres/s", "distance: us per sphere",
                    "M spheres/s", "csdf M spheres/s"], trows))
    print()
    print(md_table(["scene (primitives)", "library", "spheres",
                    "collide verdicts agree", "colliding: csdf / library",
                    "largest distance difference where csdf is exact (spheres)",
                    "largest distance difference, all clear spheres (spheres)",
                    "fraction differing by > 1 mm",
                    "largest difference of the least one-object distance (spheres)"], arows))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--esdf-voxels", default="0.05,0.02,0.01",
                   help="voxel sizes of the ESDF in metres ('' to skip)")
    p.add_argument("--baselines", default=",".join(LIBRARIES),
                   help="libraries to compare with: coal, fcl ('' to skip)")
    p.add_argument("--baseline-spheres", type=int, default=10_000,
                   help="spheres (the first of each scene's set) the libraries answer")
    p.add_argument("--quick", action="store_true",
                   help="a smoke run: fewer spheres, calls and runs, the 5 cm ESDF only")
    args = p.parse_args(argv)
    n_spheres, calls, runs, esdf = 1_000_000, 2000, args.runs, args.esdf_voxels
    n_base = args.baseline_spheres
    if args.quick:
        n_spheres, calls, runs, esdf, n_base = 100_000, 200, 1, "0.05", min(n_base, 200)
    import csdf  # noqa: F401

    libs, extra = [], {}
    for name in [v.strip() for v in args.baselines.split(",") if v.strip()]:
        if name not in BASELINES:
            p.error(f"--baselines: unknown library {name!r} (known: {', '.join(LIBRARIES)})")
        mod, version = load_library(name)
        extra[name] = version
        if mod is None:
            print(f"{name} is {version}: its comparison is skipped")
        else:
            libs.append(name)
    print("\n".join(f"* {k}: {v}" for k, v in machine_info(extra).items()))
    rng = np.random.default_rng(1)
    rows = []
    base = None
    scenes = {}
    queries = []
    for n in (20, 200, 1000):
        scene, count, box = make_scene(n)
        scenes[n] = (scene, box)
        c = rng.uniform(box[0], box[1], (n_spheres, 3))
        r = np.full(len(c), 0.05)
        total, lat = _measure(scene, c, r, runs, calls)
        if base is None:
            base = total
        hit = float(np.mean(scene.collide(c, r)))
        row = [f"{count} ({len(scene)} instances)", f"{hit:.3f}"]
        for t, t0, call in zip(total, base, lat):
            row += [f"{len(c) / t / 1e6:.2f}", f"{call * 1e6:.1f}", f"{t / t0:.2f}x"]
        rows.append(row)
        queries.append((n, count, scene, c[:n_base].copy(), float(r[0]),
                        total[0] / len(c), total[2] / len(c)))
    print()
    head = ["scene (primitives)", "fraction colliding"]
    for what in ("collide", f"clearance, margin {MARGIN} m", "clearance"):
        head += [f"{what}: M spheres/s", "us per 100-sphere call", "cost / 20"]
    print(md_table(head, rows))
    if libs and n_base > 0:
        _baseline_tables(queries, libs, runs)
    voxels = [float(v) for v in esdf.split(",") if v.strip()]
    if voxels:
        scene, box = scenes[20]
        q = rng.uniform(box[0] + 0.1, box[1] - 0.1, (200_000, 3))
        want = scene.query(q)
        t_csdf = _median(lambda: scene.distance(q), runs)
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
                                                               mode="nearest"), runs)
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
