"""The Prospero challenge (issue 16): ``../shared/data/vm/prospero.vm`` rendered at
N x N over [-1, 1]^2, black where the value is negative (row 0 at y = +1).

Three ways, timed in the same run (seconds per frame, median of warm runs; the first
call separately; peak memory of NumPy's allocations by ``tracemalloc``):

* (a) ``csdf.raster``: the compiled quadtree of tiles, tapes shortened per tile
  (``csdf.backends.pruned.raster_image``); its first call is also measured in a fresh
  process (kernels loaded from the on-disk cache, the program converted);
* (a') the same algorithm in Python (``csdf.raster(..., backend='interp')``, programs
  shortened per tile by ``csdf.compiler.simplify``), the reference, one run;
* (b) csdf brute force: the whole program at every pixel on the ``interp`` backend
  (the ``fast`` backend would first compile a 6,000-line kernel for about 95 s);
* (b') with ``--fast``: the same on the ``fast`` backend (its first call compiles the
  per-program kernel, then cached on disk);
* (c) a whole-array NumPy evaluation of the ``.vm`` text, line by line, like the
  challenge's reference implementation (written here).

The images are compared pixel for pixel. Run: ``python benchmarks/bench_prospero.py
[--size 1024] [--runs 3] [--fast]``.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import machine_info, md_table  # noqa: E402

VM = Path(__file__).resolve().parents[2] / "shared" / "data" / "vm" / "prospero.vm"

#: published figures at 1024^2 as quoted in issue 16 (their hardware is not ours)
PUBLISHED = [
    ("Fidget JIT (interval arithmetic, tape simplification)", "6.3 ms", "as published"),
    ("C++ quadtree renderer, 8 threads", "1.96 ms", "as published"),
    ("C++ quadtree renderer, 1 thread", "8.69 ms", "as published"),
    ("MPR on a GPU", "3.9 ms", "as published"),
    ("28-line NumPy reference", "~15 s, ~60 GB", "as published"),
]


def numpy_reference(text: str, n: int) -> np.ndarray:
    """``(n, n)`` bool image by evaluating every line on whole arrays (float32). Each
    array is dropped after its last use (keeping them all, as the 28-line reference
    does, needs tens of GB at 1024^2)."""
    xs = np.linspace(-1.0, 1.0, n, dtype=np.float32)
    x = np.tile(xs, (n, 1))
    y = -np.tile(xs, (n, 1)).T
    lines = [ln.split() for ln in text.splitlines() if ln and not ln.startswith("#")]
    last_use = {a: i for i, (_, _, *args) in enumerate(lines) for a in args}
    v: dict[str, object] = {}
    ops = {"add": np.add, "sub": np.subtract, "mul": np.multiply, "max": np.maximum,
           "min": np.minimum, "neg": np.negative, "square": np.square, "sqrt": np.sqrt}
    for i, (name, op, *args) in enumerate(lines):
        if op == "var-x":
            v[name] = x
        elif op == "var-y":
            v[name] = y
        elif op == "const":
            v[name] = np.float32(args[0])
        else:
            v[name] = ops[op](*(v[a] for a in args))
            for a in set(args):
                if last_use[a] == i:
                    del v[a]
    return v[lines[-1][0]] < 0


def _timed(fn, runs: int) -> tuple[float, float, float, object]:
    """``(first call s, median warm s, peak MB, result)``; the peak comes from one more
    call under ``tracemalloc`` (which slows Python code, so it is not timed)."""
    t0 = time.perf_counter()
    out = fn()
    first = time.perf_counter() - t0
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    tracemalloc.start()
    fn()
    peak = tracemalloc.get_traced_memory()[1] / 2**20
    tracemalloc.stop()
    return first, statistics.median(times), peak, out


def _fresh_first_call(n: int) -> str:
    """Seconds of the first ``csdf.raster`` call (and of import + load + raster) in a
    new Python process."""
    import subprocess

    code = (
        "import resource, time; t0 = time.perf_counter(); import csdf; "
        f"p = csdf.load({str(VM)!r}); t1 = time.perf_counter(); "
        "base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024; "
        f"csdf.raster(p, {n}, {n}, ((-1, -1), (1, 1))); t2 = time.perf_counter(); "
        "peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024; "
        "print(f'{t2 - t1:.2f} s ({t2 - t0:.2f} s with import and load); peak resident "
        "memory {peak:.0f} MB, {base:.0f} MB before the call (Python, NumPy, csdf and the "
        "program; the call loads Numba and its cached kernels)')")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=600)
    return out.stdout.strip() or out.stderr.strip()[-200:]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--size", type=int, default=1024, help="image side in pixels")
    p.add_argument("--runs", type=int, default=3, help="warm runs per method (median)")
    p.add_argument("--fast", action="store_true",
                   help="also time brute force on the fast backend (a long first compile)")
    args = p.parse_args(argv)
    if not VM.is_file():
        print(f"{VM} not found (the shared data folder)", file=sys.stderr)
        return 1
    import csdf

    n = args.size
    text = VM.read_text()
    t0 = time.perf_counter()
    prog = csdf.io.loads_vm(text, str(VM)).compile()
    load = time.perf_counter() - t0
    box = ((-1.0, -1.0), (1.0, 1.0))
    xs = -1.0 + (np.arange(n) + 0.5) * (2.0 / n)
    gx, gy = np.meshgrid(xs, xs[::-1])
    pts = np.stack([gx.ravel(), gy.ravel()], axis=1)

    def brute():
        return prog(pts, backend="interp").reshape(n, n) < 0

    info = machine_info()
    print("\n".join(f"* {k}: {v}" for k, v in info.items()))
    print(f"* prospero.vm: {len(prog)} instructions after loading ({load:.2f} s)\n")
    a = _timed(lambda: csdf.raster(prog, n, n, box), max(args.runs, 7))
    a2 = _timed(lambda: csdf.raster(prog, n, n, box, backend="interp"), 1)
    fresh = _fresh_first_call(n)
    b = _timed(brute, args.runs)
    bf = _timed(lambda: prog(pts, backend="fast").reshape(n, n) < 0, args.runs) \
        if args.fast else None
    c = _timed(lambda: numpy_reference(text, n), args.runs)
    same = bool(np.array_equal(a[3], b[3])) and bool(np.array_equal(a2[3], b[3]))
    if bf is not None:
        same = same and bool(np.array_equal(bf[3], b[3]))
    ref_diff = int(np.count_nonzero(a[3] != c[3]))
    rows = [
        ["(a) csdf.raster, compiled pruned quadtree", f"{a[1] * 1e3:.0f}", f"{a[0]:.2f}",
         f"{a[2]:.0f}", "1.00x"],
        ["(a') the same quadtree in Python", f"{a2[1] * 1e3:.0f}", f"{a2[0]:.2f}",
         f"{a2[2]:.0f}", f"{a2[1] / a[1]:.2f}x"],
        ["(b) csdf brute force, interp", f"{b[1] * 1e3:.0f}", f"{b[0]:.2f}", f"{b[2]:.0f}",
         f"{b[1] / a[1]:.2f}x"],
    ] + ([["(b') csdf brute force, fast", f"{bf[1] * 1e3:.0f}", f"{bf[0]:.2f}",
           f"{bf[2]:.0f}", f"{bf[1] / a[1]:.2f}x"]] if bf is not None else []) + [
        ["(c) whole-array NumPy (float32)", f"{c[1] * 1e3:.0f}", f"{c[0]:.2f}",
         f"{c[2]:.0f}", f"{c[1] / a[1]:.2f}x"],
    ]
    print(f"### Prospero at {n}x{n}\n")
    print(md_table(["method", "ms per frame (median)", "first call s", "peak MB (tracemalloc)",
                    "time / (a)"], rows))
    print(f"\nFirst call of (a) in a fresh process (import, load, raster): {fresh}")
    print(f"\n(a), (a'), (b) (and (b')) pixel-identical: {same}; (a) against (c): "
          f"{ref_diff} pixels "
          "differ (float32 against float64, and (c) samples the pixel corners' grid "
          "np.linspace(-1, 1, n) like the reference, not the pixel centres)\n")
    print(md_table(["published", "time", "hardware"], [list(r) for r in PUBLISHED]))
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())
