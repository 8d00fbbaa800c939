"""Rendering benchmark for csdf: sphere-traced 512x512 images, and surface sampling.

Run from the repository root::

    .venv/bin/python benchmarks/bench_render.py                      # the benchmark
    .venv/bin/python benchmarks/bench_render.py --figure docs/render.png   # + README image
    .venv/bin/python benchmarks/bench_render.py --figure docs/render.png --no-bench

Measured (each: one warm-up run, then the median of 5 timed runs, fast backend):

* ``csdf.render`` of the CSG example and of the 20-primitive model (``union20`` of
  ``bench_eval.py``) at 512x512, Lambert shading, and with soft shadows + ambient
  occlusion;
* ``csdf.scan`` of the CSG example at 512x512;
* ``csdf.sample_surface`` of 10^5 points on the CSG example, when the library has it.

It also counts field evaluations per pixel with and without over-relaxation. Results are
printed as a table and written with the command line to ``benchmarks/RENDER_RESULTS.md``
(``--out``). Target: <= 0.5 s per 512x512 render on a 2-core machine.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import os
import platform
import shlex
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from bench_eval import MODEL_DESC, build_model  # noqa: E402

SIZE = 512
RUNS = 5
TARGET_S = 0.5
SAMPLES = 100_000


def _camera(shape, size: int = SIZE):
    """A camera looking at the shape's bounding-box centre from the (+x, -y, +z) octant,
    40-degree view, the box's bounding sphere just filling the view."""
    from csdf.render import auto_camera

    return auto_camera(shape, size, size, fov=40.0)


def _time(fn: Callable[[], object], runs: int = RUNS) -> tuple[float, list[float], object]:
    """Median wall time of ``runs`` calls after one warm-up call; returns the last result."""
    out = fn()
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), times, out


def _fmt(s: float) -> str:
    return f"{s * 1e3:.0f} ms" if s < 10 else f"{s:.1f} s"


def figure(path: Path) -> None:
    """Render the CSG example at 640x480 with soft shadows and ambient occlusion."""
    import csdf
    from csdf.render import Camera, render

    c = csdf.cylinder(0.5, 3.0)
    shape = (csdf.sphere(1.0) & csdf.box(1.5)) - c - c.orient("x") - c.orient("y")
    cam = Camera.look_at((2.3, -2.9, 2.0), (0.0, 0.0, -0.05), fov=32.0, width=640, height=480)
    r = render(shape, cam, 640, 480, shadows=True, ao=True)
    r.save(path)
    print(f"wrote {path} ({r.stats['seconds']:.2f} s)")


def run_benchmark() -> tuple[list[dict], list[str]]:
    """Run every measurement; returns (rows, notes)."""
    import csdf
    from csdf.render import Field, render, sphere_trace
    from csdf.scan import scan

    rows: list[dict] = []
    notes: list[str] = []
    for name in ("csg", "union20"):
        shape = build_model(name)
        cam = _camera(shape)
        for label, kw in (("Lambert", {}), ("shadows + AO", {"shadows": True, "ao": True})):
            med, times, r = _time(lambda s=shape, c=cam, k=kw: render(s, c, SIZE, SIZE, **k))
            rows.append({
                "task": f"render {SIZE}x{SIZE}, {label}", "model": name, "median": med,
                "times": times, "target": TARGET_S if not kw else None,
                "detail": f"{r.mask.mean():.0%} pixels hit; "
                          f"{r.stats['evaluations'] / SIZE**2:.1f} field evaluations / pixel "
                          f"(tracing + normals); slowest ray {r.stats['iterations']} "
                          "iterations",
            })
            print(f"{name:8s} render {label:13s} {_fmt(med):>8s}  {rows[-1]['detail']}",
                  flush=True)
        # over-relaxation: field evaluations with and without it (tracing only)
        fld = Field(shape)
        dirs = cam.pixel_directions() @ cam.R.T
        ev = {om: sphere_trace(fld, cam.t, dirs, omega=om).evaluations for om in (1.6, 1.0)}
        notes.append(f"{name}: sphere tracing takes {ev[1.6] / SIZE**2:.2f} field evaluations "
                     f"per pixel with over-relaxation (omega = 1.6) and {ev[1.0] / SIZE**2:.2f} "
                     f"without ({(ev[1.6] / ev[1.0] - 1) * 100:+.1f} %).")

    shape = build_model("csg")
    cam = _camera(shape)
    med, times, (pts, _) = _time(lambda: scan(shape, cam, SIZE, SIZE, noise=0.001,
                                              outliers=0.01, seed=0))
    rows.append({"task": f"scan {SIZE}x{SIZE} (noise, outliers)", "model": "csg",
                 "median": med, "times": times, "target": None,
                 "detail": f"{len(pts):,} points"})
    print(f"csg      scan                 {_fmt(med):>8s}  {rows[-1]['detail']}", flush=True)

    sample = getattr(csdf, "sample_surface", None)
    if sample is None:
        notes.append("csdf.sample_surface is not available in this version: row skipped.")
    else:
        med, times, (pts, _) = _time(lambda: sample(shape, SAMPLES, seed=0))
        rows.append({"task": f"sample_surface 10^{int(np.log10(SAMPLES))} points",
                     "model": "csg", "median": med, "times": times, "target": None,
                     "detail": f"{len(pts):,} points"})
        print(f"csg      sample_surface       {_fmt(med):>8s}", flush=True)
    return rows, notes


def _machine() -> list[tuple[str, str]]:
    import numba

    import csdf

    try:
        git = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=HERE, text=True,
                             capture_output=True, check=False).stdout.strip() or "?"
    except OSError:
        git = "?"
    cpu = platform.processor() or "?"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return [
        ("date", _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d %H:%M:%S UTC")),
        ("CPU", cpu),
        ("cores", f"{os.cpu_count()} logical, {len(os.sched_getaffinity(0))} usable"),
        ("Python", platform.python_version()),
        ("NumPy / Numba", f"{np.__version__} / {numba.__version__} "
                          f"(NUMBA_NUM_THREADS = {numba.config.NUMBA_NUM_THREADS})"),
        ("csdf", f"{csdf.__version__} (git {git})"),
        ("load average at the end", " ".join(f"{x:.2f}" for x in os.getloadavg())
         + " (1, 5, 15 min; other processes make timings noisy)"),
    ]


def write_results(path: Path, rows: list[dict], notes: list[str], command: str,
                  seconds: float) -> None:
    from csdf.io import atomic_path

    lines = [
        "# csdf rendering benchmark", "",
        f"Command: `{command}`  ", f"Total benchmark time: {seconds:.0f} s", "",
        "## Machine", "", "|  |  |", "|---|---|",
        *[f"| {k} | {v} |" for k, v in _machine()], "",
        "## Models", "", "| model | definition |", "|---|---|",
        *[f"| {m} | {MODEL_DESC[m]} |" for m in ("csg", "union20")], "",
        "Camera: 40-degree vertical field of view, looking at the bounding-box centre from "
        "the (+x, -y, +z) octant, the box's bounding sphere just filling the view. Fast "
        "(Numba) backend; default parameter values.", "",
        "## Results", "",
        f"Median wall time of {RUNS} runs after one warm-up run.", "",
        "| task | model | median | runs | target | details |", "|---|---|---|---|---|---|",
    ]
    for r in rows:
        target = "-" if r["target"] is None else (
            f"<= {r['target']} s: {'met' if r['median'] <= r['target'] else 'MISSED'}")
        runs = ", ".join(_fmt(t) for t in r["times"])
        lines.append(f"| {r['task']} | {r['model']} | {_fmt(r['median'])} | {runs} | "
                     f"{target} | {r['detail']} |")
    lines += ["", "## Notes", "", *[f"* {n}" for n in notes], ""]
    with atomic_path(path) as tmp:
        tmp.write_text("\n".join(lines))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=HERE / "RENDER_RESULTS.md",
                    help="Markdown results file (default benchmarks/RENDER_RESULTS.md)")
    ap.add_argument("--figure", type=Path, default=None,
                    help="also render the README picture (CSG example, 640x480, shadows "
                         "and AO) to this PNG, e.g. docs/render.png")
    ap.add_argument("--no-bench", action="store_true", help="only make the figure")
    args = ap.parse_args(argv)
    command = "python " + " ".join(shlex.quote(a) for a in [
        os.path.relpath(__file__, Path.cwd()), *(sys.argv[1:] if argv is None else argv)])
    if args.figure is not None:
        figure(args.figure)
    if args.no_bench:
        return 0
    t0 = time.perf_counter()
    rows, notes = run_benchmark()
    seconds = time.perf_counter() - t0
    print()
    print(f"{'task':38s} {'model':8s} {'median':>9s}  target")
    for r in rows:
        target = "" if r["target"] is None else (
            f"<= {r['target']} s " + ("met" if r["median"] <= r["target"] else "MISSED"))
        print(f"{r['task']:38s} {r['model']:8s} {_fmt(r['median']):>9s}  {target}")
    for n in notes:
        print("note:", n)
    write_results(args.out, rows, notes, command, seconds)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
