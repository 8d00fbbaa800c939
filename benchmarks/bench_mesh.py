"""Meshing benchmark for csdf: ``csdf.mesh`` against dense evaluation + scikit-image
marching cubes, on the README's CSG example.

Run from the repository root::

    .venv/bin/python benchmarks/bench_mesh.py            # full run: 256, 512 (+ 1024 for csdf)
    .venv/bin/python benchmarks/bench_mesh.py --quick --output /tmp/mesh_quick.md   # 128, 256

Every timed call runs in its own fresh subprocess (this file with ``--child csdf|dense|plain``,
started from a small ``/bin/sh``), so each run's peak memory is its own: the child warms
up (meshes once at resolution 32, which loads or compiles the Numba kernels), resets its
peak-RSS counter, times one call and reports its wall time, peak memory (VmHWM after the
call minus VmRSS just before it), face count and watertightness as one JSON line.

The parent prints each run as it finishes, then the tables and a "targets" section, and
writes everything (with the exact command line and the machine) to a Markdown file
(``benchmarks/MESH_RESULTS.md`` by default). See ``benchmarks/README.md``.
"""

from __future__ import annotations

import argparse
import gc
import json
import math
import os
import resource
import shlex
import statistics
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import loadavg, machine_info, md_table, read_text, run_child  # noqa: E402

HERE = Path(__file__).resolve().parent
METHODS = ("mc", "dc")
WARMUP_RESOLUTION = 32

# targets (see README.md)
TARGET_SPEEDUP = 10.0  # dense+MC time / csdf time at 512^3
TARGET_MEMORY = 0.1  # csdf peak memory / dense+MC peak memory at 512^3
TARGET_SCALING = 4.5  # time(2N) / time(N), csdf, 256 -> 512 and 512 -> 1024

BASELINES = ("dense", "plain")
LABELS = {"dense": "dense + skimage MC", "plain": "plain dense + skimage MC"}

SHAPE_DESC = ("`(sphere(1.0) & box(1.5)) - c - c.orient('x') - c.orient('y')`, "
              "c = cylinder(0.5, 3.0)")
MB = 1e6  # memory is reported in MB = 10^6 bytes
NOTES = """## Notes: where the time and memory go (csdf mc, 512^3)

Profiled during development on this machine (fresh process, warm kernels, load ~1;
cProfile and per-kernel thread CPU time), not part of the timed runs above:

* **Work.** The interval octree keeps 29,198 bricks of 8^3 voxels, and every one of them
  holds surface (the pruning is already tight), so csdf scans 14.9 M voxels and evaluates
  21.3 M samples (9^3 per brick), against 138.2 M voxels and 139.0 M samples for the dense
  baseline: 9.2x fewer voxels and 6.5x fewer samples.
* **Time** (~0.22 s first call; measured with per-stage timers and the main thread's
  waits): the stages overlap. One thread runs the compiled marching-cubes kernel, the
  only stage that must go in chunk order (~0.15 s: ~0.13 s of compute, the rest first
  writes to the 89 MB face array), and waits ~0.015 s in all for samples; one worker
  thread evaluates the chunks' samples ahead of it (21 M samples, ~0.12 s) and searches
  the roots of the chunks behind it (~0.05 s: the linear guess, then secant / Illinois
  steps until |f| <= 1e-6 voxel; scikit-image only interpolates linearly). Before the
  stream the octree takes ~0.025 s. The kernel skips a brick's empty voxel columns with
  bit masks of inside samples (one 9-bit mask per sample column), and the edge hash map
  places a brick's face edges side by side and neighbouring bricks near each other, so
  its working set moves through the table with the sweep (a scattering hash made 1024^3
  ~6x slower than 512^3). On this VM the first write to fresh memory costs ~2 us per
  4 KB page; huge pages make it ~5x cheaper but stalled calls for 0.2-0.6 s when the
  OS had to compact memory first, so only the hash map asks for them.
* **Memory.** Against the slab-streamed dense baseline the memory target cannot be met
  while the peak includes the returned mesh: `trimesh.Trimesh` stores float64 vertices
  and int64 faces (24 bytes per vertex and per face), 134 MB at 512^3 = 0.174x that
  baseline's peak on its own. Everything else csdf holds at its peak (edge hash map, a
  few chunks of samples and edges) is the *working* column: ~34 MB = ~0.04x. Against the
  plain dense pipeline (one array of all samples) csdf's whole peak is 0.025x.
* **dc** (extra rows) streams over the same bricks (`extract_dc`): a compiled kernel
  records the active voxels and their edges' vertices, the QEF of each voxel is solved
  in compiled code (3x3 symmetric Jacobi eigensolver, the same pseudo-inverse rule as the
  NumPy reference mesher `reference.py`, which stays the fallback; the voxels split into one range
  per core), and quads are assembled by scatter; the vertices are projected onto the
  surface by compiled Newton steps (one value+gradient evaluation each); the edge
  normals still run as NumPy in blocks.
"""
MEMORY_GUARD = 0.85  # skip a run projected to need more than this share of MemAvailable


# ---------------------------------------------------------------------------- the workload
def build_shape():
    """The README's CSG example (no parameters)."""
    import csdf

    c = csdf.cylinder(0.5, 3.0)
    return (csdf.sphere(1.0) & csdf.box(1.5)) - c - c.orient("x") - c.orient("y")


def dense_grid(bounds, resolution: int) -> tuple[np.ndarray, float, tuple[int, ...]]:
    """``(origin, h, dims)`` of csdf.mesh's grid without its jitter.

    ``h`` = longest side of ``bounds`` / ``resolution``, ``origin = bounds[0] - 2 h``,
    ``dims = ceil(extent / h) + 5`` voxels per axis (``dims + 1`` samples).
    """
    b = np.asarray(bounds, dtype=np.float64).reshape(2, 3)
    extent = b[1] - b[0]
    h = float(extent.max()) / resolution
    origin = b[0] - 2.0 * h
    dims = tuple(int(math.ceil(e / h)) + 5 for e in extent)
    return origin, h, dims


def dense_mesh(shape, resolution: int, plain: bool = False
               ) -> tuple[np.ndarray, np.ndarray, dict[str, float]]:
    """The baseline: evaluate every sample of the grid, then scikit-image marching cubes.

    The field is evaluated x-slab by x-slab (``(ny * nz, 3)`` float64 points, one buffer
    reused) with ``prog(points, backend='fast')`` into a float32 ``(nx, ny, nz)`` volume;
    ``skimage.measure.marching_cubes(vol, 0.0, spacing=(h, h, h))`` then meshes it and the
    vertices are moved to model coordinates. Returns ``(verts, faces, seconds by stage)``.

    ``plain``: the textbook way instead: every sample's coordinates in one ``(M, 3)``
    float64 array (``np.meshgrid``), one ``prog(points, backend='fast')`` call, the float64
    values reshaped into the volume.
    """
    from skimage.measure import marching_cubes

    t0 = time.perf_counter()
    prog = shape.compile()  # cached on the shape (compiled during the warm-up)
    origin, h, dims = dense_grid(shape.bounds, resolution)
    nx, ny, nz = (d + 1 for d in dims)
    if plain:
        axes = [origin[d] + h * np.arange(n) for d, n in enumerate((nx, ny, nz))]
        pts = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        vol = prog(pts, backend="fast").reshape(nx, ny, nz)
    else:
        vol = np.empty((nx, ny, nz), dtype=np.float32)
        pts = np.empty((ny * nz, 3), dtype=np.float64)
        pts[:, 1] = np.repeat(origin[1] + h * np.arange(ny), nz)
        pts[:, 2] = np.tile(origin[2] + h * np.arange(nz), ny)
        for i in range(nx):
            pts[:, 0] = origin[0] + h * i
            vol[i] = prog(pts, backend="fast").reshape(ny, nz)
    del pts
    t1 = time.perf_counter()
    verts, faces, _normals, _values = marching_cubes(vol, 0.0, spacing=(h, h, h))
    del vol, _normals, _values
    verts = verts + origin
    t2 = time.perf_counter()
    return verts, faces, {"eval": t1 - t0, "mc": t2 - t1}


# ---------------------------------------------------------------------------- children
def _status_kib(name: str) -> int:
    """A ``/proc/self/status`` field in KiB (``VmRSS``: now, ``VmHWM``: peak); -1 if none."""
    for line in read_text("/proc/self/status").splitlines():
        if line.startswith(name + ":"):
            return int(line.split()[1])
    return -1


def _reset_peak_rss() -> bool:
    """Reset this process's VmHWM to its current RSS (Linux >= 4.0: ``clear_refs`` = 5)."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
    except OSError:
        return False
    return _status_kib("VmHWM") <= _status_kib("VmRSS") + 64


def _snapshot(tag: str) -> dict[str, int]:
    return {f"rss_{tag}_kib": _status_kib("VmRSS"), f"hwm_{tag}_kib": _status_kib("VmHWM"),
            f"maxrss_{tag}_kib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss}


def _measure(fn) -> tuple[object, dict]:
    """Run ``fn()`` once: wall seconds and RSS snapshots around it."""
    gc.collect()
    rec: dict = {"hwm_reset": _reset_peak_rss(), "load1": os.getloadavg()[0]}
    rec |= _snapshot("before")
    t0 = time.perf_counter()
    out = fn()
    rec["seconds"] = time.perf_counter() - t0
    rec |= _snapshot("after")
    return out, rec


def child_csdf(resolution: int, method: str) -> dict:
    """Fresh process: warm up, then time one ``csdf.mesh`` call."""
    import csdf

    shape = build_shape()
    t0 = time.perf_counter()
    # the mesher itself; the thin-part check's cost is measured by bench_thin.py
    csdf.mesh(shape, resolution=WARMUP_RESOLUTION, method=method, progress=False,
              check_thin=False)
    warmup = time.perf_counter() - t0
    m, rec = _measure(lambda: csdf.mesh(shape, resolution=resolution, method=method,
                                        progress=False, check_thin=False))
    meta = m.metadata["csdf"]
    rec.update(
        warmup=warmup, mesher_seconds=meta["seconds"], dims=list(meta["dims"]),
        voxel_size=meta["voxel_size"], faces=len(m.faces), vertices=len(m.vertices),
        output_bytes=int(m.vertices.nbytes + m.faces.nbytes),
        watertight=bool(m.is_watertight),
    )
    return rec


def child_dense(resolution: int, plain: bool = False) -> dict:
    """Fresh process: warm up, then time one dense evaluation + marching cubes."""
    import trimesh

    shape = build_shape()
    t0 = time.perf_counter()
    dense_mesh(shape, WARMUP_RESOLUTION, plain)
    warmup = time.perf_counter() - t0
    (verts, faces, stages), rec = _measure(lambda: dense_mesh(shape, resolution, plain))
    _, h, dims = dense_grid(shape.bounds, resolution)
    m = trimesh.Trimesh(vertices=verts, faces=faces, process=False, validate=False)
    rec.update(
        warmup=warmup, eval_seconds=stages["eval"], mc_seconds=stages["mc"], dims=list(dims),
        voxel_size=h, faces=len(faces), vertices=len(verts), watertight=bool(m.is_watertight),
    )
    return rec


def peak_mb(r: dict) -> float:
    """Peak memory of the call: VmHWM after it - VmRSS just before it, in MB."""
    return max(0, r["hwm_after_kib"] - r["rss_before_kib"]) * 1024 / MB


def maxrss_mb(r: dict) -> float:
    """Cross-check: ``ru_maxrss`` after the call - VmRSS before it, in MB."""
    return max(0, r["maxrss_after_kib"] - r["rss_before_kib"]) * 1024 / MB


# ---------------------------------------------------------------------------- machine info
def _version(module: str) -> str:
    try:
        return __import__(module).__version__
    except Exception as exc:
        return f"unavailable ({type(exc).__name__})"


# ---------------------------------------------------------------------------- formatting
def fmt_s(t: float | None) -> str:
    if t is None:
        return "-"
    if t < 1.0:
        return f"{t * 1e3:.0f} ms"
    return f"{t:.2f} s"


def fmt_mb(x: float | None) -> str:
    return "-" if x is None else f"{x:,.0f} MB"


def fmt_x(x: float | None, digits: int = 2) -> str:
    return "-" if x is None else f"{x:.{digits}f}x"


def status(ok: bool | None) -> str:
    return "n/a" if ok is None else ("PASS" if ok else "FAIL")


def log(msg: str) -> None:
    print(msg, flush=True)


# ---------------------------------------------------------------------------- main run
@dataclass
class Config:
    resolutions: list[int]  # compared with the dense baseline
    scaling_resolution: int | None  # csdf only (1024), or None
    dense_at_scaling: bool  # --with-dense-1024
    plain: bool  # also the plain dense baseline (not --no-plain)
    methods: list[str]
    runs_small: int  # runs at resolutions <= 256
    runs_large: int  # runs at resolutions > 256
    memory_guard: bool
    output: Path
    command: str

    def runs(self, n: int) -> int:
        return self.runs_small if n <= 256 else self.runs_large

    @property
    def csdf_resolutions(self) -> list[int]:
        extra = [self.scaling_resolution] if self.scaling_resolution else []
        return sorted(set(self.resolutions + extra))


@dataclass
class Series:
    """The runs of one (kind, method, resolution): kind 'csdf', 'dense' or 'plain'."""

    kind: str
    method: str
    resolution: int
    records: list[dict] = field(default_factory=list)
    errors: list[str] = field(default_factory=list)
    skipped: str = ""  # why the runs were not started (memory guard)

    @property
    def label(self) -> str:
        return f"csdf {self.method}" if self.kind == "csdf" else LABELS[self.kind]

    def med(self, fn) -> float | None:
        vals = [fn(r) for r in self.records]
        return statistics.median(vals) if vals else None

    @property
    def time(self) -> float | None:
        return self.med(lambda r: r["seconds"])

    @property
    def peak(self) -> float | None:
        return self.med(peak_mb)

    @property
    def output(self) -> float | None:
        """The output mesh's size (trimesh's float64 vertices + int64 faces), MB."""
        vals = [r["output_bytes"] / MB for r in self.records if "output_bytes" in r]
        return statistics.median(vals) if vals else None


def run_series(cfg: Config) -> dict[tuple[str, str, int], Series]:
    """Every run, each in a fresh child; the runs of one resolution are interleaved
    (csdf methods, then dense, repeated), so slow drift in machine load hits all alike."""
    series: dict[tuple[str, str, int], Series] = {}
    for n in cfg.csdf_resolutions:
        kinds = [("csdf", m) for m in cfg.methods]
        if n in cfg.resolutions or (n == cfg.scaling_resolution and cfg.dense_at_scaling):
            kinds.append(("dense", "mc"))
        if n in cfg.resolutions and cfg.plain:
            kinds.append(("plain", "mc"))
        runs = cfg.runs(n)
        log(f"\n== resolution {n} ({runs} run{'s' if runs > 1 else ''} each, fresh "
            "subprocesses) ==")
        for kind, method in kinds:
            s = series[(kind, method, n)] = Series(kind, method, n)
            need = projected_mb(series, kind, method, n)
            avail = mem_available_mb()
            if cfg.memory_guard and need is not None and avail is not None \
                    and need > MEMORY_GUARD * avail:
                s.skipped = (f"skipped: projected memory {fmt_mb(need)} > {MEMORY_GUARD:.0%} "
                             f"of the available {fmt_mb(avail)} (--no-memory-guard runs it)")
                log(f"  {s.label:20s} {s.skipped}")
        for i in range(runs):
            for kind, method in kinds:
                s = series[(kind, method, n)]
                if s.skipped:
                    continue
                args = ["--child", kind, "--resolution", str(n), "--method", method]
                timeout = 3600.0 if n >= 1024 else 1800.0
                rec, wall, err = run_child(__file__, args, timeout, via_shell=True)
                if rec is None:
                    s.errors.append(err)
                    log(f"  {s.label:20s} run {i + 1}: ERROR {err}")
                    continue
                rec["process_wall"] = wall
                s.records.append(rec)
                extra = (f"eval {fmt_s(rec['eval_seconds'])} + MC {fmt_s(rec['mc_seconds'])}"
                         if kind != "csdf" else f"mesher {fmt_s(rec['mesher_seconds'])}")
                log(f"  {s.label:20s} run {i + 1}: {fmt_s(rec['seconds']):>9s} ({extra}), "
                    f"peak {fmt_mb(peak_mb(rec))}, {rec['faces']:,} faces, watertight "
                    f"{rec['watertight']}, load {rec['load1']:.2f}")
    return series


def mem_available_mb() -> float | None:
    for line in read_text("/proc/meminfo").splitlines():
        if line.startswith("MemAvailable:"):
            return int(line.split()[1]) * 1024 / MB
    return None


def projected_mb(series: dict, kind: str, method: str, n: int) -> float | None:
    """Projected RSS (MB) of a child at resolution ``n``: its RSS before the call plus the
    peak of the largest smaller resolution grown by the observed growth per doubling
    (at least 4x, as for a surface; 8x per doubling before two resolutions are known)."""
    done = sorted((r, s) for (k, m, r), s in series.items()
                  if k == kind and m == method and r < n and s.peak is not None)
    if not done:
        return None
    n1, s1 = done[-1]
    growth = 8.0
    if len(done) >= 2:
        n0, s0 = done[-2]
        if s0.peak:
            growth = max(4.0, (s1.peak / s0.peak) ** (1.0 / math.log2(n1 / n0)))
    rss = statistics.median(r["rss_before_kib"] for r in s1.records) * 1024 / MB
    return rss + s1.peak * growth ** math.log2(n / n1)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--quick", action="store_true",
                   help="smoke test: resolutions 128 and 256, no 1024, 1 run each")
    p.add_argument("--methods", nargs="+", choices=METHODS, default=list(METHODS),
                   help="csdf meshing methods (default: mc dc; targets use mc)")
    p.add_argument("--with-dense-1024", action="store_true",
                   help="also run the dense baseline at 1024^3 (~4.3 GB volume)")
    p.add_argument("--runs-small", type=int,
                   help="runs per measurement at resolutions <= 256 (default 3; 1 with --quick)")
    p.add_argument("--runs-large", type=int, default=2,
                   help="runs per measurement at resolutions > 256 (default 2)")
    p.add_argument("--no-memory-guard", action="store_true",
                   help="run a measurement even when its projected memory exceeds "
                   f"{MEMORY_GUARD * 100:.0f}%% of MemAvailable")  # %% for argparse
    p.add_argument("--output", type=Path, default=HERE / "MESH_RESULTS.md",
                   help="Markdown results file (default benchmarks/MESH_RESULTS.md)")
    p.add_argument("--no-plain", action="store_true",
                   help="skip the second baseline (all samples in one array)")
    p.add_argument("--child", choices=("csdf", "dense", "plain"), help=argparse.SUPPRESS)
    p.add_argument("--resolution", type=int, default=WARMUP_RESOLUTION, help=argparse.SUPPRESS)
    p.add_argument("--method", choices=METHODS, default="mc", help=argparse.SUPPRESS)
    a = p.parse_args(argv)

    if a.child == "csdf":
        print(json.dumps(child_csdf(a.resolution, a.method)))
        return 0
    if a.child in ("dense", "plain"):
        print(json.dumps(child_dense(a.resolution, a.child == "plain")))
        return 0

    runs_small = a.runs_small if a.runs_small is not None else (1 if a.quick else 3)
    if runs_small < 1 or a.runs_large < 1:
        p.error("--runs-small and --runs-large must be positive")
    if a.quick and a.with_dense_1024:
        p.error("--with-dense-1024 has no effect with --quick (no 1024 run)")
    python = sys.executable
    if Path(python).is_relative_to(Path.cwd()):
        python = os.path.relpath(python)
    script = sys.argv[0] if argv is None else "benchmarks/bench_mesh.py"
    env = "".join(f"{k}={shlex.quote(os.environ[k])} " for k in ("PYTHONPATH", "NUMBA_NUM_THREADS")
                  if os.environ.get(k))
    cfg = Config(
        resolutions=[128, 256] if a.quick else [256, 512],
        scaling_resolution=None if a.quick else 1024,
        dense_at_scaling=a.with_dense_1024,
        plain=not a.no_plain,
        methods=list(dict.fromkeys(a.methods)),
        runs_small=runs_small,
        runs_large=a.runs_large,
        memory_guard=not a.no_memory_guard,
        output=a.output,
        command=env + shlex.join([python, script, *(sys.argv[1:] if argv is None else argv)]),
    )
    return run(cfg)


def run(cfg: Config) -> int:
    t_start = time.perf_counter()
    info = machine_info({"scikit-image": _version("skimage"), "trimesh": _version("trimesh")})
    log("csdf meshing benchmark\n" + "\n".join(f"  {k}: {v}" for k, v in info.items()))
    series = run_series(cfg)
    elapsed = time.perf_counter() - t_start
    md = report(cfg, info, series, elapsed)
    cfg.output.parent.mkdir(parents=True, exist_ok=True)
    cfg.output.write_text(md)
    log("\n" + md)
    log(f"written to {cfg.output}")
    return 0


# ---------------------------------------------------------------------------- report
def report(cfg: Config, info: dict, series: dict, elapsed: float) -> str:
    shape = build_shape()
    bounds = np.asarray(shape.bounds, dtype=np.float64)
    primary = "mc" if "mc" in cfg.methods else cfg.methods[0]
    L: list[str] = ["# csdf meshing benchmark\n"]
    L.append(f"Command: `{cfg.command}`  \nTotal benchmark time: {elapsed:.0f} s\n")
    L.append("## Machine\n")
    L.append(md_table(["", ""], [[k, v] for k, v in info.items()]
                      + [["load average at end", loadavg()]]) + "\n")

    L.append("## Setup\n")
    box = ", ".join(f"{lo:g}..{hi:g}" for lo, hi in zip(bounds[0], bounds[1]))
    runs_text = ", ".join(f"{n}: {cfg.runs(n)}" for n in cfg.csdf_resolutions)
    L.append(
        f"Shape: {SHAPE_DESC} (the README example without its parameter), bounds "
        f"`shape.bounds` = [{box}] (x, y, z).\n\n"
        f"* **csdf**: `csdf.mesh(shape, resolution=N, method=..., progress=False, "
        f"check_thin=False)` (sparse "
        f"octree pruned by interval arithmetic, fast backend; `mc` is the compiled "
        f"marching cubes streamed over the octree's bricks, `src/csdf/mesh/stream.py`, "
        f"`dc` the dual contouring streamed the same way, with compiled QEF solves); its "
        f"grid has h = longest side / N, origin = bounds[0] - h (2 + jitter) and "
        f"ceil(extent / h) + 5 voxels per axis. The call's time includes building the "
        f"`trimesh.Trimesh`.\n"
        f"* **dense + skimage MC** (baseline): the same grid without the jitter (origin = "
        f"bounds[0] - 2h, the same voxel counts, i.e. voxels + 1 samples per axis); "
        f"`prog(points, backend='fast')` over every sample, x-slab by x-slab ((ny nz, 3) "
        f"float64 points) into a float32 volume, then "
        f"`skimage.measure.marching_cubes(vol, 0.0, spacing=(h, h, h))` (single-threaded) "
        f"and a shift of the vertices to model coordinates. *eval* and *MC* are the two "
        f"parts of its time.\n"
        f"* **plain dense + skimage MC** (second baseline, the textbook pipeline): the same "
        f"grid, but every sample's coordinates in one (M, 3) float64 array (`np.meshgrid`), "
        f"one `prog(points, backend='fast')` call, and its float64 values as the volume; "
        f"then the same marching cubes.\n"
        f"* Each run is a **fresh subprocess** (`bench_mesh.py --child csdf|dense|plain`, started "
        f"from a small `/bin/sh`): it builds the shape, **warms up** with the same pipeline "
        f"at resolution {WARMUP_RESOLUTION} (loads / JIT-compiles the Numba kernels, imports "
        f"scikit-image), runs `gc.collect()`, resets its peak RSS (`/proc/self/clear_refs` "
        f"= 5), then times one call (warm). **Time** = wall time of that call; **peak "
        f"memory** = VmHWM after the call - VmRSS just before it (MB = 10^6 bytes): "
        f"everything the call allocated at its peak, output mesh included. The face "
        f"count and `is_watertight` (trimesh) are taken after the measurement.\n"
        f"* Runs per measurement (resolution: runs): {runs_text}; the tables give the "
        f"**median** over the runs (every run is under *Raw samples*). The runs of one "
        f"resolution are interleaved (csdf methods, then dense, repeated).\n"
        f"* Targets use method `{primary}`; other methods are extra rows.\n"
        f"* Memory guard{'' if cfg.memory_guard else ' (off in this run)'}: a measurement "
        f"whose projected memory (the previous resolution's peak grown by the observed "
        f"growth per doubling, at least 4x) exceeds {MEMORY_GUARD:.0%} of MemAvailable is "
        f"skipped, not run into the OOM killer.\n")

    L.append("## Results\n")
    rows = []
    for (kind, _method, n), s in series.items():
        r0 = s.records[0] if s.records else None
        if r0 is None:
            rows.append([str(n), s.label, "-", "0", "-", "-", "-", "-", "-", "-",
                         s.skipped or "; ".join(s.errors)])
            continue
        peaks = [peak_mb(r) for r in s.records]
        parts = (f"eval {fmt_s(s.med(lambda r: r['eval_seconds']))} + MC "
                 f"{fmt_s(s.med(lambda r: r['mc_seconds']))}" if kind != "csdf"
                 else f"mesher {fmt_s(s.med(lambda r: r['mesher_seconds']))}")
        wt = {r["watertight"] for r in s.records}
        notes = []
        if s.errors:
            notes.append(f"{len(s.errors)} failed: {s.errors[0]}")
        if not all(r["hwm_reset"] for r in s.records):
            notes.append("peak RSS not reset: memory may be an upper bound")
        rows.append([
            str(n), s.label, "x".join(map(str, r0["dims"])), str(len(s.records)),
            fmt_s(s.time), parts, fmt_mb(s.peak),
            f"{min(peaks):,.0f}-{max(peaks):,.0f}" if len(peaks) > 1 else "-",
            f"{r0['faces']:,}", "yes" if wt == {True} else ("no" if wt == {False} else "mixed"),
            "; ".join(notes),
        ])
    L.append(md_table(["N", "pipeline", "voxels", "runs", "time (median)", "parts (median)",
                       "peak memory (median)", "peak range (MB)", "faces", "watertight",
                       "notes"], rows) + "\n")

    # csdf vs dense
    L.append("## csdf vs dense + marching cubes\n")
    L.append("Speedup = baseline time / csdf time; memory ratio = csdf peak / baseline "
             "peak (medians).\n")
    rows = []
    compare: dict[tuple[str, str, int], tuple[float | None, float | None]] = {}
    for base in BASELINES:
        for n in cfg.csdf_resolutions:
            d = series.get((base, "mc", n))
            if d is None:
                continue
            for m in cfg.methods:
                c = series.get(("csdf", m, n))
                if c is None:
                    continue
                sp = d.time / c.time if c.time and d.time else None
                mr = c.peak / d.peak if c.peak is not None and d.peak else None
                compare[(base, m, n)] = (sp, mr)
                work = (c.peak - c.output if c.peak is not None and c.output is not None
                        else None)
                rows.append([str(n), f"csdf {m}", LABELS[base], fmt_s(c.time),
                             fmt_s(d.time), fmt_x(sp, 2), fmt_mb(c.peak), fmt_mb(d.peak),
                             fmt_x(mr, 3), fmt_mb(c.output),
                             fmt_x(c.output / d.peak if c.output and d.peak else None, 3),
                             fmt_mb(work),
                             fmt_x(work / d.peak if work and d.peak else None, 3)])
    L.append("*output*: the returned mesh alone (trimesh keeps float64 vertices and int64 "
             "faces: 24 bytes per vertex and per face), part of csdf's peak; *working*: "
             "csdf peak - output, everything else the call held at its peak. Both are "
             "shown as a share of the baseline's peak.\n")
    L.append(md_table(["N", "csdf", "baseline", "csdf time", "baseline time", "speedup",
                       "csdf peak", "baseline peak", "memory ratio", "output",
                       "output / baseline peak", "working", "working / baseline peak"],
                      rows) + "\n")

    # scaling
    L.append("## Scaling\n")
    L.append("time(2N) / time(N) (medians; 4x = linear in the surface voxels' count, the "
             "best a surface mesher can do as N doubles; 8x = linear in the volume).\n")
    rows = []
    scaling: dict[tuple[str, int], float | None] = {}
    res = cfg.csdf_resolutions
    pipelines = [("csdf", m) for m in cfg.methods] + [(b, "mc") for b in BASELINES]
    for kind, m in pipelines:
        cells = []
        for n in res:
            s = series.get((kind, m, n))
            cells.append(fmt_s(s.time if s else None))
        for n1, n2 in zip(res, res[1:]):
            s1, s2 = series.get((kind, m, n1)), series.get((kind, m, n2))
            ratio = s2.time / s1.time if s1 and s2 and s1.time and s2.time else None
            if kind == "csdf":
                scaling[(m, n2)] = ratio
            cells.append(fmt_x(ratio, 2))
        if kind != "csdf" and not any(series.get((kind, m, n)) for n in res):
            continue
        rows.append([f"csdf {m}" if kind == "csdf" else LABELS[kind], *cells])
    head = ["pipeline", *(f"time {n}" for n in res),
            *(f"{n2}/{n1}" for n1, n2 in zip(res, res[1:]))]
    L.append(md_table(head, rows) + "\n")

    # targets
    L.append("## Targets\n")
    big = max(cfg.resolutions)
    if big != 512:
        L.append(f"(This run's largest compared resolution is {big}, not 512, and its "
                 f"scaling steps are not 256 -> 512 -> 1024: the rows below are computed "
                 f"at the resolutions of this run and are indicative only.)\n")
    rows = []
    for m in [primary, *(x for x in cfg.methods if x != primary)]:
        tag = "" if m == primary else " (extra)"
        for base in BASELINES:
            c, d = series.get(("csdf", m, big)), series.get((base, "mc", big))
            if d is None or not d.records:
                continue
            sp, mr = compare.get((base, m, big), (None, None))
            vs = "dense+MC" if base == "dense" else "plain dense+MC"
            detail = (f"{sp:.2f}x ({fmt_s(d.time)} / {fmt_s(c.time)})"
                      if sp is not None and c else "not measured")
            rows.append([f"{big}^3, {m}{tag}: csdf >= {TARGET_SPEEDUP:g}x faster than {vs}",
                         detail, status(None if sp is None else sp >= TARGET_SPEEDUP)])
            detail = (f"{mr:.3f} ({fmt_mb(c.peak)} / {fmt_mb(d.peak)})"
                      if mr is not None and c else "not measured")
            rows.append([f"{big}^3, {m}{tag}: csdf peak memory <= {TARGET_MEMORY:g} x {vs}",
                         detail, status(None if mr is None else mr <= TARGET_MEMORY)])
            if c and c.output and d.peak and c.peak is not None:
                rows.append([f"({big}^3, {m}{tag}: the output mesh alone vs {vs} peak; "
                             f"working memory vs {vs} peak)",
                             f"{c.output / d.peak:.3f} ({fmt_mb(c.output)}); "
                             f"{(c.peak - c.output) / d.peak:.3f} "
                             f"({fmt_mb(c.peak - c.output)})", "info"])
        for n1, n2 in zip(res, res[1:]):
            ratio = scaling.get((m, n2))
            rows.append([f"{m}{tag}: time({n2}) / time({n1}) <= {TARGET_SCALING:g}",
                         fmt_x(ratio, 2) if ratio is not None else "not measured",
                         status(None if ratio is None else ratio <= TARGET_SCALING)])
    L.append(md_table(["target", "measured", "result"], rows) + "\n")

    L.append(NOTES)

    # raw samples
    L.append("## Raw samples\n")
    L.append("<details><summary>every run</summary>\n")
    L.append("*time*: the timed call; *parts*: mesher's own `seconds` (csdf) or eval + MC "
             "(dense); *RSS before*: the child's VmRSS just before the call (after the "
             "warm-up); *ru_maxrss peak*: `ru_maxrss` after the call - RSS before "
             "(cross-check of VmHWM); *load*: 1-minute load average seen by the child just "
             "before the call; *process*: the child's whole wall time (start-up, warm-up, "
             "call, watertight check).\n")
    rows = []
    for (kind, _method, n), s in series.items():
        for i, r in enumerate(s.records):
            parts = (f"{r['eval_seconds']:.3f} + {r['mc_seconds']:.3f}" if kind != "csdf"
                     else f"{r['mesher_seconds']:.3f}")
            rows.append([str(n), s.label, str(i + 1), f"{r['seconds']:.3f}", parts,
                         f"{peak_mb(r):,.0f}", f"{maxrss_mb(r):,.0f}",
                         f"{r['rss_before_kib'] * 1024 / MB:,.0f}", f"{r['warmup']:.2f}",
                         f"{r['load1']:.2f}", f"{r['process_wall']:.1f}"])
        for err in s.errors:
            rows.append([str(n), s.label, "failed", "-", "-", "-", "-", "-", "-", "-", err])
    L.append(md_table(["N", "pipeline", "run", "time (s)", "parts (s)", "peak (MB)",
                       "ru_maxrss peak (MB)", "RSS before (MB)", "warm-up (s)", "load",
                       "process (s)"], rows))
    L.append("\n</details>\n")
    return "\n".join(L)


if __name__ == "__main__":
    sys.exit(main())
