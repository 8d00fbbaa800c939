"""csdf.distributed on a local Dask cluster (issue 22), against one machine in the same run.

1. A mesh at ``--resolution`` (default 1024) by ``csdf.distributed.mesh`` on a
   ``--workers``-process ``LocalCluster`` (``csdf.distributed.connect``: one thread
   each) against ``csdf.mesh`` in this process (``check_thin=False``, the same grid),
   in memory to in memory, and
2. file to file: ``csdf.mesh`` then ``csdf.io.meshstream.write_whole`` (binary PLY,
   float64 vertices) against ``csdf.distributed.mesh(out=...)`` (the workers write
   their parts into the same layout; no process holds the whole mesh). The same file
   both ways: ``csdf.io.write_mesh`` goes through trimesh, which writes float32
   vertices, a different and smaller file.

   After a warm-up at 128 (kernels loaded on every worker) and an untimed round at the
   resolution (each worker's field for that grid made and kept, as this process keeps
   its compiled kernels), ``--repeat`` rounds of the four runs one after the other;
   a round counts only if other processes on the machine used under 5 % of a core
   during each of its runs (measured from the CPU times of the machine and of this
   process tree). Medians, the overheads, the tasks, how the mesh was put together
   (``metadata['csdf']['assembled']``: ``shared``, the workers wrote it into shared
   memory), whether the meshes and the file equal the one-process mesh (canonical
   order), the load average and the rounds kept and dropped.
3. A mesh at ``--big`` (default 2048) streamed to a PLY on a fresh cluster: wall time,
   file size and each worker's peak resident memory (``ru_maxrss``, whole process life).
4. ``fit_many`` on ``--scans`` scans against a loop of ``csdf.fit``: seconds and whether
   the results agree.

Models: the demo's CSG part (sphere & box minus three cylinders: 105 instructions, a
cheap field, so the mesh's size, not the field, sets the cost: the hard case for
shipping results) and the zoo chair (a heavier field).

Run: ``python benchmarks/bench_distributed.py [--workers 2] [--resolution 1024]
[--big 2048] [--scans 200] [--repeat 5] [--wait-load 1]`` (needs the ``dask`` extra).
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
import psutil
import trimesh

import csdf
import csdf.distributed as cd
from csdf.io.meshstream import write_whole
from csdf.mesh.parts import canonical


def _reset_peak() -> None:
    """Reset this process's peak resident memory to its current one (Linux
    ``/proc/self/clear_refs``; ``ru_maxrss`` would include what a forked process
    inherited)."""
    with open("/proc/self/clear_refs", "w") as fh:
        fh.write("5")


def _peak_rss_mb(field: str = "VmHWM") -> float:
    """This process's peak resident memory since :func:`_reset_peak` (MB); with
    ``field='VmRSS'`` its current one."""
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith(field + ":"):
                return float(line.split()[1]) / 1024.0
    return float("nan")


#: a timed run counts only if other processes used less than this share of a core
OTHERS = 0.05


def models() -> list[tuple[str, object]]:
    c = csdf.cylinder(0.5, 3.0)
    part = (csdf.sphere(1.0) & csdf.box(1.5)) - c - c.orient("x") - c.orient("y")
    return [("CSG part", part), ("zoo chair", csdf.zoo.load("chair")),
            ("zoo gear", csdf.zoo.load("gear"))]


def _equal(a, b) -> bool:
    """Whether two meshes are the same up to order (:func:`canonical`)."""
    ca, cb = canonical(a.vertices, a.faces), canonical(b.vertices, b.faces)
    return ca[0].shape == cb[0].shape and np.array_equal(ca[0], cb[0]) and \
        np.array_equal(ca[1], cb[1])


def _write_whole(m, path: Path):
    """``m`` written as :func:`csdf.distributed.mesh` writes a PLY."""
    return write_whole(path, m.vertices, m.faces)


def _load() -> str:
    """The 1-minute load average now."""
    return f"{os.getloadavg()[0]:.2f}"


def _busy() -> float:
    """CPU seconds the whole machine's processes have used (interrupts left out: the
    loopback network between the client and its workers is handled there)."""
    t = psutil.cpu_times()
    return t.user + t.system + t.nice


def _ours() -> float:
    """CPU seconds of this process and its children (the cluster's workers)."""
    total = 0.0
    me = psutil.Process()
    for p in [me, *me.children(recursive=True)]:
        try:
            c = p.cpu_times()
        except psutil.Error:
            continue
        total += c.user + c.system
    return total


def _timed(fn) -> tuple[float, bool, object]:
    """``(wall seconds, quiet, result)`` of ``fn()``: quiet when other processes used
    less than :data:`OTHERS` of a core meanwhile (give or take 3 clock ticks of 10 ms,
    the resolution of the CPU times)."""
    b0, o0, t0 = _busy(), _ours(), time.perf_counter()
    out = fn()
    dt = time.perf_counter() - t0
    return dt, (_busy() - b0) - (_ours() - o0) < OTHERS * dt + 0.03, out


def _wait_load(limit: float, most: float = 900.0) -> None:
    """Wait (at most ``most`` seconds) until the 1-minute load average is below
    ``limit``."""
    t0 = time.time()
    while os.getloadavg()[0] >= limit and time.time() - t0 < most:
        time.sleep(10)


def bench_mesh(client, res: int, repeat: int, wait_load: float | None,
               only: list[str] | None = None) -> None:
    print(f"\n## Mesh at {res}^3: csdf.distributed.mesh vs csdf.mesh\n")
    print("In memory: `csdf.mesh` vs `csdf.distributed.mesh`. To file: `csdf.mesh` + "
          "`csdf.io.meshstream.write_whole` vs `csdf.distributed.mesh(out=...)`, the same "
          "binary PLY (float64 vertices). Medians of "
          f"{repeat} rounds of the four, one after the other, after an untimed round; a "
          f"round is kept only if other processes used under {OTHERS:.0%} of a core during "
          "each of its runs (the last column: the 1-minute load average when the model's "
          "runs began, rounds kept and dropped).\n")
    print("| model | triangles | csdf.mesh s | distributed s | overhead | mesh + write PLY s | "
          "distributed out= PLY s | overhead | tasks | largest cube | assembled | "
          "equal (memory, file) | load; rounds kept / dropped |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name, shape in models():
        if only and not any(o in name for o in only):
            continue
        csdf.mesh(shape, resolution=128, progress=False, check_thin=False)  # warm-up
        cd.mesh(shape, resolution=128, client=client, progress=False)
        with tempfile.TemporaryDirectory(dir=".") as tmp:
            one, out = Path(tmp) / "one.ply", Path(tmp) / "m.ply"
            runs = {
                "one": lambda s=shape: csdf.mesh(s, resolution=res, progress=False,
                                                 check_thin=False),
                "dist": lambda s=shape: cd.mesh(s, resolution=res, client=client,
                                                progress=False),
                "file_one": lambda s=shape, p=one: _write_whole(csdf.mesh(
                    s, resolution=res, progress=False, check_thin=False), p),
                "file_dist": lambda s=shape, p=out: cd.mesh(
                    s, resolution=res, client=client, progress=False, out=p),
            }
            for fn in runs.values():  # (each worker's field for this grid made and kept)
                fn()
            if wait_load is not None:
                _wait_load(wait_load)
            load0 = _load()
            kept: dict[str, list[float]] = {k: [] for k in runs}
            dropped = 0
            while len(kept["one"]) < repeat and dropped < 4 * repeat:
                got = {}
                for k, fn in runs.items():
                    dt, quiet, result = _timed(fn)
                    got[k] = (dt, quiet)
                    if k in ("one", "dist"):
                        last = result  # (the in-memory meshes, compared below)
                        if k == "one":
                            whole = result
                    del result
                if all(q for _, q in got.values()):
                    for k, (dt, _) in got.items():
                        kept[k].append(dt)
                else:
                    dropped += 1
            n_kept = len(kept["one"])
            if not n_kept:  # (never quiet: the last round, said so)
                kept = {k: [got[k][0]] for k in runs}
            med = {k: statistics.median(v) for k, v in kept.items()}
            equal = _equal(whole, last)
            assembled = last.metadata["csdf"]["assembled"]
            del last
            mf = runs["file_dist"]()
            equal_file = _equal(whole, trimesh.load(out, process=False))
        print(f"| {name} | {mf.faces:,} | {med['one']:.2f} | {med['dist']:.2f} | "
              f"{(med['dist'] / med['one'] - 1) * 100:+.0f} % | {med['file_one']:.2f} | "
              f"{med['file_dist']:.2f} | {(med['file_dist'] / med['file_one'] - 1) * 100:+.0f} % "
              f"| {mf.tasks} | {mf.super_brick} | {assembled} | {equal}, {equal_file} | "
              f"{load0}; {n_kept} / {dropped}{'' if n_kept else ' (none quiet: the last)'} |",
              flush=True)
        del whole


def bench_big(workers: int, res: int) -> None:
    name, shape = models()[0]
    client = cd.connect(workers=workers)
    try:
        cd.mesh(shape, resolution=128, client=client, progress=False)  # load the kernels
        client.run(_reset_peak)
        _reset_peak()
        before = _peak_rss_mb("VmRSS")
        with tempfile.TemporaryDirectory(dir=".") as tmp:
            t0 = time.perf_counter()
            mf = cd.mesh(shape, resolution=res, client=client, progress=False,
                         out=Path(tmp) / "big.ply")
            dt = time.perf_counter() - t0
            size = mf.path.stat().st_size
        peaks = client.run(_peak_rss_mb)
    finally:
        cd.disconnect(client)
    print(f"\n## Mesh at {res}^3 streamed to disk ({name}, {workers} workers)\n")
    print("| triangles | vertices | file | s | tasks | largest cube | worker peak RSS | "
          "client peak RSS (before the job) |")
    print("|---|---|---|---|---|---|---|---|")
    print(f"| {mf.faces:,} | {mf.vertices:,} | {size / 2**30:.2f} GiB | {dt:.1f} | "
          f"{mf.tasks} | {mf.super_brick} | "
          f"{' / '.join(f'{v / 1024:.2f} GiB' for v in peaks.values())} | "
          f"{_peak_rss_mb() / 1024:.2f} GiB ({before / 1024:.2f} GiB) |", flush=True)


def bench_fit(client, n: int) -> None:
    shape = csdf.zoo.load("stool")
    rng = np.random.default_rng(0)
    clouds = []
    for i in range(n):
        p, _ = csdf.sample_surface(shape, 1000, seed=i)
        a = rng.normal(size=3) * 0.15
        R = csdf.Pose.from_rotvec(a).rotation
        clouds.append(p @ R.T + rng.normal(size=3) * 0.05 + rng.normal(0, 0.002, p.shape))
    kw = {"estimate": "pose"}
    csdf.fit(shape, clouds[0], **kw)
    cd.fit_many(shape, clouds[:4], client=client, **kw)
    t0 = time.perf_counter()
    loop = [csdf.fit(shape, c, **kw) for c in clouds]
    t_loop = time.perf_counter() - t0
    t0 = time.perf_counter()
    many = cd.fit_many(shape, clouds, client=client, **kw)
    t_many = time.perf_counter() - t0
    same = all(np.array_equal(a.rotation, b.rotation) and
               np.array_equal(a.translation, b.translation) for a, b in zip(loop, many))
    ok = sum(bool(r.success) for r in many)
    print(f"\n## fit_many on {n} scans vs a loop of csdf.fit\n")
    print("| scans | loop s | fit_many s | speed-up | identical results | successes |")
    print("|---|---|---|---|---|---|")
    print(f"| {n} | {t_loop:.1f} | {t_many:.1f} | {t_loop / t_many:.2f}x | {same} | "
          f"{ok}/{n} |", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--resolution", type=int, default=1024)
    ap.add_argument("--big", type=int, default=2048, help="0 skips the out-of-core run")
    ap.add_argument("--scans", type=int, default=200, help="0 skips fit_many")
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--models", default=None, help="only the models whose names hold one "
                    "of these comma-separated words")
    ap.add_argument("--wait-load", type=float, default=None, help="before each model's "
                    "timed runs, wait (up to 15 min) until the 1-minute load average is "
                    "below this")
    a = ap.parse_args()
    print(f"machine: {platform.processor() or platform.machine()}, "
          f"{csdf.parallel.N_THREADS} cores; {a.workers} worker processes x 1 thread")
    if a.big:  # first, so that no earlier job's memory is in the client's figure
        if a.wait_load is not None:
            _wait_load(a.wait_load)
        print(f"(1-minute load average before: {_load()})")
        bench_big(a.workers, a.big)
    client = cd.connect(workers=a.workers)  # (each worker gets its share of the cores)
    try:
        bench_mesh(client, a.resolution, a.repeat, a.wait_load,
                   a.models.split(",") if a.models else None)
        if a.scans:
            if a.wait_load is not None:
                _wait_load(a.wait_load)
            print(f"\n(1-minute load average before: {_load()})")
            bench_fit(client, a.scans)
    finally:
        cd.disconnect(client)


if __name__ == "__main__":
    main()
