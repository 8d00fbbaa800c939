"""Evaluation benchmark for csdf: the ``fast`` (Numba) backend against the NumPy reference.

Run from the repository root::

    .venv/bin/python benchmarks/bench_eval.py            # full run (10^6 and 10^7 points)
    .venv/bin/python benchmarks/bench_eval.py --quick    # smoke test (10^5 and 10^6 points)

It prints each measurement as it goes, then the result tables and a "targets" section,
and writes everything (with the exact command line) to a Markdown file
(``benchmarks/RESULTS.md`` by default). See ``benchmarks/README.md`` for what is measured
and how to read it.

The same file is also the script run in fresh subprocesses for the start-up and
peak-memory measurements (``--child startup|memory``, not meant to be used by hand).
``csdf`` is imported lazily, inside functions, so that a child process can time
``import csdf`` itself.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shlex
import statistics
import sys
import time
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import (  # noqa: E402
    loadavg,
    machine_info,
    md_table,
    read_text,
    run_child,
    thread_scaling,
)

HERE = Path(__file__).resolve().parent
MODELS = ("sphere", "csg", "union20")
MODES = ("value", "grad", "jac")
MODE_LABEL = {"value": "value", "grad": "value+grad", "jac": "value+grad+jac"}
BACKENDS = ("fast", "numpy", "numpy-whole")
# "numpy-whole" is the same reference evaluator run with one chunk = all points: a full
# (N,) array per instruction, the textbook NumPy evaluator the issue describes (and what
# fogleman/sdf does). Its derivative modes are not run at >= 10^7 points: a full (N, T)
# array per register would take several GiB.
WHOLE = "numpy-whole"
_KERNEL_MODE = {"value": "value", "grad": "grad", "jac": "all"}

# targets (see README.md)
TARGET_SPEEDUP = 30.0  # fast / numpy, csg and union20
TARGET_COPY_RATIO = 2.0  # sphere value-only eval time / pts.copy() time
TARGET_GRAD_RATIO = 3.0  # value+grad time / value time
TARGET_MEMORY_RATIO = 1.5  # (input + eval RSS increase) / (input + output bytes)
TARGET_WARM_START = 0.5  # seconds, first fast call in a fresh process, cache warm

POINT_SEED = 12345  # seed of the benchmark points (the union20 layout uses seed 0)
BOX_PAD = 0.1  # points are uniform in the model's bounding box grown by 10% per side


# ---------------------------------------------------------------------------- models
def build_model(name: str):
    """The benchmark shape ``name`` (a ``csdf.Shape``); each has at least one parameter."""
    import csdf

    if name == "sphere":
        return csdf.sphere(csdf.param("r", 1.0, 0.5, 1.5))
    if name == "csg":
        r = csdf.param("r", 1.0, 0.5, 1.5)
        c = csdf.cylinder(0.5, 3.0)
        return (csdf.sphere(r) & csdf.box(1.5)) - c - c.orient("x") - c.orient("y")
    if name == "union20":
        return _union20(csdf)
    raise ValueError(f"unknown model {name!r}; known: {', '.join(MODELS)}")


UNION20_SMOOTH_STEPS = (1, 5, 9, 13, 17)  # fold steps (1..19) that use csdf.union(k=0.1)


def _union20(csdf):
    """20 primitives at seeded random positions, folded left to right.

    Primitive ``i`` (0..19): a sphere when ``i`` is even, a box when odd; centre uniform
    in [-2, 2]^3 and size ``s`` uniform in [0.2, 0.6] (sphere radius ``s``; box half
    side ``s``, i.e. ``csdf.box(2 * s)``), drawn in that order from
    ``np.random.default_rng(0)``. Parameters: the radius of sphere 0 (``r0``) and the
    full side of box 1 (``b1``). Fold step ``i`` (1..19) combines the accumulated shape
    with primitive ``i``: ``csdf.union(acc, s, k=0.1)`` for the 5 steps in
    ``UNION20_SMOOTH_STEPS``, ``acc | s`` otherwise.
    """
    rng = np.random.default_rng(0)
    acc = None
    for i in range(20):
        centre = tuple(float(v) for v in rng.uniform(-2.0, 2.0, 3))
        s = float(rng.uniform(0.2, 0.6))
        if i % 2 == 0:
            size = csdf.param("r0", s, 0.1, 0.8) if i == 0 else s
            prim = csdf.sphere(size)
        else:
            size = csdf.param("b1", 2 * s, 0.2, 1.6) if i == 1 else 2 * s
            prim = csdf.box(size)
        prim = prim.translate(centre)
        if acc is None:
            acc = prim
        elif i in UNION20_SMOOTH_STEPS:
            acc = csdf.union(acc, prim, k=0.1)
        else:
            acc = acc | prim
    return acc


MODEL_DESC = {
    "sphere": "`sphere(r)`, r = param('r', 1.0, 0.5, 1.5)",
    "csg": "`(sphere(r) & box(1.5)) - c - c.orient('x') - c.orient('y')`, "
    "c = cylinder(0.5, 3.0), r = param('r', 1.0, 0.5, 1.5)",
    "union20": "10 spheres + 10 boxes, translated, seeded (rng 0); 5 of 19 unions smooth "
    "(k = 0.1); params r0 (sphere 0 radius), b1 (box 1 size)",
}


def model_box(shape) -> tuple[np.ndarray, np.ndarray]:
    """The shape's bounding box grown by ``BOX_PAD`` of its extent on each side."""
    b = np.asarray(shape.bounds, dtype=np.float64)
    lo, hi = b[0], b[1]
    pad = BOX_PAD * (hi - lo)
    return lo - pad, hi + pad


def unit_points(n: int, seed: int = POINT_SEED) -> np.ndarray:
    """``(n, 3)`` float64 uniform in [0, 1)^3."""
    return np.random.default_rng(seed).random((n, 3))


def scale_points(u: np.ndarray, lo: np.ndarray, hi: np.ndarray, *, inplace=False) -> np.ndarray:
    pts = u if inplace else u.copy()
    pts *= hi - lo
    pts += lo
    return pts


# ---------------------------------------------------------------------------- evaluation
def evaluate(prog, mode: str, pts: np.ndarray, backend: str | None):
    """One evaluation; ``backend=None`` calls without the keyword (pre-backend API)."""
    if backend == WHOLE:
        from csdf.backends import numpy_backend

        res = numpy_backend.evaluate(prog, pts, prog.param_values(None), _KERNEL_MODE[mode],
                                     chunk=max(len(pts), 1))
        return tuple(res[k] for k in ("value", "grad", "jac") if k in res)
    kw = {} if backend is None else {"backend": backend}
    if mode == "value":
        return prog(pts, **kw)
    if mode == "grad":
        return prog.value_and_grad(pts, **kw)
    if mode == "jac":
        return prog.value_grad_param_jacobian(pts, **kw)
    raise ValueError(mode)


def probe_backends(prog) -> tuple[dict[str, str | None], bool]:
    """Which backends work: ``({backend: None or error text}, keyword supported)``.

    If the ``backend=`` keyword is not accepted at all, the NumPy reference (the only
    evaluator before the keyword existed) is called without it.
    """
    pts = unit_points(64, seed=1)
    status: dict[str, str | None] = {}
    for b in BACKENDS:
        try:
            evaluate(prog, "value", pts, b)
            status[b] = None
        except Exception as exc:  # reported, not hidden
            status[b] = err_text(exc)
    kw_ok = status["numpy"] is None
    if not kw_ok:
        status[WHOLE] = "needs the backend= keyword era reference"
        try:
            evaluate(prog, "value", pts, None)
            status["numpy"] = None
        except Exception as exc:
            status["numpy"] = err_text(exc)
    return status, kw_ok


def err_text(exc: BaseException, limit: int = 200) -> str:
    """One-line description of an exception (for logs and Markdown cells)."""
    text = " ".join(f"{type(exc).__name__}: {exc}".split()).replace("|", "/")
    return text if len(text) <= limit else text[: limit - 3] + "..."


@dataclass
class Timing:
    samples: list[float] = field(default_factory=list)
    note: str = ""
    skipped: bool = False
    estimate: float | None = None  # extrapolated seconds when skipped
    error: str | None = None

    @property
    def median(self) -> float | None:
        if self.samples:
            return statistics.median(self.samples)
        return self.estimate


def time_calls(fn, repeats: int, warmup_fn=None, stop_after: float | None = None):
    """Median-ready timings of ``fn()`` after one warm-up (``warmup_fn`` or ``fn``).

    Returns ``(samples, last result, note)``. With ``stop_after``, a warm-up slower than
    that many seconds is kept as the only sample (the remaining runs are skipped).
    """
    t0 = time.perf_counter()
    out = (warmup_fn or fn)()
    t_warm = time.perf_counter() - t0
    del out
    if stop_after is not None and warmup_fn is None and t_warm > stop_after:
        return [t_warm], None, f"1 run only (>{stop_after:.0f} s)"
    samples = []
    out = None
    for _ in range(repeats):
        out = None
        t0 = time.perf_counter()
        out = fn()
        samples.append(time.perf_counter() - t0)
    return samples, out, ""


def max_abs_diff(a, b) -> float | None:
    """Largest ``|a - b|`` over the arrays of two results (NaN in both counts as equal;
    NaN in one only gives NaN)."""
    if a is None or b is None:
        return None
    if not isinstance(a, tuple):
        a, b = (a,), (b,)
    worst = 0.0
    for x, y in zip(a, b):
        if x.size:
            d = np.abs(np.asarray(x, np.float64) - np.asarray(y, np.float64))
            d[np.isnan(x) & np.isnan(y)] = 0.0
            if np.isnan(d).any():
                return float("nan")
            worst = max(worst, float(d.max()))
    return worst


# ---------------------------------------------------------------------------- machine info
# ---------------------------------------------------------------------------- children
def _status_kib(field: str) -> int:
    """A ``/proc/self/status`` field in KiB (``VmRSS``: now, ``VmHWM``: peak); -1 if none."""
    for line in read_text("/proc/self/status").splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1])
    return -1


def _maxrss_kib() -> int:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss  # KiB on Linux


def _mem_snapshot(tag: str) -> dict[str, int]:
    return {f"rss_{tag}_kib": _status_kib("VmRSS"), f"hwm_{tag}_kib": _status_kib("VmHWM"),
            f"maxrss_{tag}_kib": _maxrss_kib()}


def child_startup(model: str, n: int) -> dict:
    """Fresh process: time ``import csdf``, build + compile, first and second fast call."""
    pts = unit_points(n, seed=2) * 2.0 - 1.0
    t0 = time.perf_counter()
    import csdf

    t1 = time.perf_counter()
    numba_loaded_by_import = "numba" in sys.modules
    prog = csdf.compile(build_model(model))
    t2 = time.perf_counter()
    prog(pts, backend="fast")
    t3 = time.perf_counter()
    prog(pts, backend="fast")
    t4 = time.perf_counter()
    return {
        "import": t1 - t0, "compile": t2 - t1, "first_call": t3 - t2, "second_call": t4 - t3,
        "total": t3 - t0, "numba_imported_by_csdf": numba_loaded_by_import,
    }


def child_memory(model: str, n: int, backend: str) -> dict:
    """Fresh process: RSS increase while evaluating ``n`` points (value only)."""
    import csdf

    shape = build_model(model)
    prog = csdf.compile(shape)
    lo, hi = model_box(shape)
    prog(scale_points(unit_points(1000, seed=3), lo, hi), backend=backend)  # load kernels
    snap = _mem_snapshot("before_inputs")
    pts = scale_points(unit_points(n), lo, hi, inplace=True)  # the only big allocation
    snap |= _mem_snapshot("before_eval")
    out = prog(pts, backend=backend)
    snap |= _mem_snapshot("after_eval")
    return {"n": n, "input_bytes": pts.nbytes, "output_bytes": out.nbytes, **snap}


def kernel_cache_dir() -> Path | None:
    """The fast backend's on-disk kernel cache (generated sources + Numba's files), if any.

    Asks the backend (``csdf.backends.fast.cache_dir()``); ``None`` when it has no such
    function (then only Numba's cache next to csdf's own modules exists).
    """
    try:
        from csdf.backends import fast
    except Exception:  # no fast backend module
        return None
    fn = getattr(fast, "cache_dir", None)
    if fn is None:
        return None
    try:
        return Path(fn()).resolve()
    except Exception:
        return None


def numba_cache_files() -> list[Path]:
    """Numba cache files (``*.nbi``, ``*.nbc``) of csdf.

    Looks in ``__pycache__`` directories under the installed package, under the fast
    backend's kernel cache directory (:func:`kernel_cache_dir`), and, when
    ``NUMBA_CACHE_DIR`` is set, in its files whose path mentions csdf.
    """
    import csdf

    roots = [Path(csdf.__file__).resolve().parent]
    kdir = kernel_cache_dir()
    if kdir is not None and kdir.is_dir():
        roots.append(kdir)
    files: list[Path] = []
    for root in roots:
        for d in root.rglob("__pycache__"):
            files += [f for f in d.iterdir() if f.suffix in (".nbi", ".nbc")]
    extra = os.environ.get("NUMBA_CACHE_DIR")
    if extra and Path(extra).is_dir():
        for f in Path(extra).rglob("*"):
            if f.suffix in (".nbi", ".nbc") and "csdf" in str(f):
                files.append(f)
    return sorted(set(files))


def clear_numba_cache() -> int:
    """Delete :func:`numba_cache_files`; returns how many were deleted."""
    files = numba_cache_files()
    for f in files:
        f.unlink(missing_ok=True)
    return len(files)


# ---------------------------------------------------------------------------- formatting
def fmt_s(t: float | None) -> str:
    if t is None:
        return "-"
    if t < 1e-3:
        return f"{t * 1e6:.0f} µs"
    if t < 1.0:
        return f"{t * 1e3:.1f} ms"
    return f"{t:.2f} s"


def fmt_n(n: int) -> str:
    e = int(round(np.log10(n)))
    return f"10^{e}" if 10**e == n else f"{n:,}"


def status(ok: bool | None) -> str:
    return "n/a" if ok is None else ("PASS" if ok else "FAIL")


# ---------------------------------------------------------------------------- main run
@dataclass
class Config:
    sizes: list[int]
    repeats: int
    numpy_large_repeats: int
    large: int
    numpy_max_seconds: float
    models: list[str]
    startup_models: list[str]
    memory: bool
    output: Path
    command: str


def log(msg: str) -> None:
    print(msg, flush=True)


def bench_throughput(cfg: Config, progs: dict, boxes: dict, backends_ok: dict, kw_ok: bool):
    """Times every (model, size, mode, backend); returns results and copy baselines."""
    results: dict[tuple, Timing] = {}
    diffs: dict[tuple, float | None] = {}
    copy_times: dict[int, list[float]] = {}
    for n in cfg.sizes:
        log(f"\n== {fmt_n(n)} points ==")
        u = unit_points(n)
        samples, _, _ = time_calls(u.copy, max(cfg.repeats, 5))
        copy_times[n] = samples
        med = statistics.median(samples)
        log(f"  pts.copy() ({u.nbytes / 2**20:.0f} MiB): median {fmt_s(med)}")
        for model in cfg.models:
            prog = progs[model]
            pts = scale_points(u, *boxes[model])
            for mode in MODES:
                outs = {}
                for backend in BACKENDS:
                    key = (model, n, mode, backend)
                    tm = Timing()
                    results[key] = tm
                    if backends_ok[backend] is not None:
                        tm.error = "unavailable"
                        continue
                    bkw = backend if kw_ok else None
                    fn = partial(evaluate, prog, mode, pts, bkw)
                    repeats, warm_fn, stop = cfg.repeats, None, None
                    if backend == WHOLE and n >= cfg.large and mode != "value":
                        tm.note = f"not run at {fmt_n(n)} points (memory)"
                        continue
                    if backend != "fast" and n >= cfg.large:
                        repeats = min(cfg.repeats, cfg.numpy_large_repeats)
                        tm.note = f"{repeats} runs"
                        small = pts[: max(n // 10, 1)]
                        warm_fn = partial(evaluate, prog, mode, small, bkw)
                        est = _extrapolate(results, model, n, mode, cfg.sizes, backend)
                        if est is not None and est > cfg.numpy_max_seconds:
                            tm.skipped, tm.estimate = True, est
                            tm.note = (f"skipped: est. {est:.0f} s/run > "
                                       f"{cfg.numpy_max_seconds:.0f} s (extrapolated "
                                       "from the smaller size)")
                            log(f"  {model:8s} {MODE_LABEL[mode]:15s} {backend:11s} {tm.note}")
                            continue
                    elif backend != "fast":
                        stop = cfg.numpy_max_seconds
                    try:
                        tm.samples, outs[backend], note = time_calls(fn, repeats, warm_fn, stop)
                    except Exception as exc:  # reported in the table
                        tm.error = err_text(exc)
                        log(f"  {model:8s} {MODE_LABEL[mode]:15s} {backend:11s} ERROR {tm.error}")
                        continue
                    if note:
                        tm.note = note
                    med = tm.median
                    log(f"  {model:8s} {MODE_LABEL[mode]:15s} {backend:11s} median {fmt_s(med):>9s}"
                        f"  {n / med / 1e6:8.2f} Mpts/s  ({len(tm.samples)} runs)")
                diffs[(model, n, mode)] = max_abs_diff(outs.get("fast"), outs.get("numpy"))
                if outs.get(WHOLE) is not None and outs.get("numpy") is not None:
                    # one evaluator, two chunkings: the results must be identical
                    whole = outs[WHOLE]
                    ref = outs["numpy"] if isinstance(outs["numpy"], tuple) else (outs["numpy"],)
                    same = all(np.allclose(a, b, rtol=1e-12, atol=1e-12, equal_nan=True)
                               for a, b in zip(whole, ref))
                    if not same:
                        results[(model, n, mode, WHOLE)].error = "differs from chunked numpy"
                del outs
            del pts
        del u
    return results, diffs, copy_times


def _extrapolate(results, model, n, mode, sizes, backend="numpy") -> float | None:
    smaller = [s for s in sizes if s < n and results.get((model, s, mode, backend))]
    if not smaller:
        return None
    s = max(smaller)
    med = results[(model, s, mode, backend)].median
    return None if med is None else med * n / s


def bench_startup(cfg: Config) -> dict:
    """Cold and warm first calls in fresh subprocesses.

    The children get a private, initially empty kernel cache (``CSDF_CACHE_DIR`` set to
    a temporary directory), so the cold run is cold without wiping the user's cache of
    other kernels; Numba's cache files under the csdf package are deleted as well.
    """
    import tempfile

    out = {}
    saved = os.environ.get("CSDF_CACHE_DIR")
    with tempfile.TemporaryDirectory(prefix="csdf-bench-cache-") as tmp:
        os.environ["CSDF_CACHE_DIR"] = tmp
        try:
            kdir = kernel_cache_dir()
            for model in cfg.startup_models:
                n_cleared = clear_numba_cache()
                child = ["--child", "startup", "--model", model]
                cold, cold_wall, cold_err = run_child(__file__, child)
                warm, warm_wall, warm_err = run_child(__file__, child)
                out[model] = {
                    "cleared": n_cleared, "cold": cold, "cold_wall": cold_wall,
                    "cold_err": cold_err, "warm": warm, "warm_wall": warm_wall,
                    "warm_err": warm_err, "cache_files_after": len(numba_cache_files()),
                    "kernel_dir": "private temporary directory"
                    if kdir is not None and kdir == Path(tmp).resolve()
                    else str(kdir) if kdir is not None else "none",
                }
                for tag, r, err in (("cold", cold, cold_err), ("warm", warm, warm_err)):
                    if r is None:
                        log(f"  start-up {model:8s} {tag}: ERROR {err}")
                    else:
                        log(f"  start-up {model:8s} {tag}: import {fmt_s(r['import'])}, "
                            f"compile {fmt_s(r['compile'])}, first call "
                            f"{fmt_s(r['first_call'])}, second call {fmt_s(r['second_call'])}")
        finally:
            if saved is None:
                os.environ.pop("CSDF_CACHE_DIR", None)
            else:
                os.environ["CSDF_CACHE_DIR"] = saved
    return out


def bench_memory(cfg: Config) -> dict:
    n = max(cfg.sizes)
    out = {}
    runs = [(m, "fast") for m in cfg.models] + [("sphere", "numpy")]
    for model, backend in runs:
        r, wall, err = run_child(
            __file__, ["--child", "memory", "--model", model, "--n", str(n), "--backend", backend],
            via_shell=True,
        )
        out[(model, backend)] = (r, err)
        if r is None:
            log(f"  memory {model:8s} {backend:5s}: ERROR {err}")
        else:
            m = memory_metrics(r)
            log(f"  memory {model:8s} {backend:5s}: eval RSS increase {m['inc_mib']:.0f} MiB, "
                f"peak/(in+out) = {m['ratio']:.2f}")
    return out


def memory_metrics(r: dict) -> dict:
    """Eval memory from a ``child_memory`` record.

    Peak RSS after the call is the larger of ``ru_maxrss`` and ``VmHWM`` (they agree when
    the child is started through ``run_child(via_shell=True)``; without it ``ru_maxrss``
    would still hold this parent's peak, which Linux carries across fork + exec).
    """
    io = r["input_bytes"] + r["output_bytes"]
    peak = max(r["hwm_after_eval_kib"], r["maxrss_after_eval_kib"])
    inc = max(0, peak - r["rss_before_eval_kib"]) * 1024
    ru_inc = max(0, r["maxrss_after_eval_kib"] - r["maxrss_before_eval_kib"]) * 1024
    hwm_inc = max(0, r["hwm_after_eval_kib"] - r["rss_before_eval_kib"]) * 1024
    return {
        "io_mib": io / 2**20, "inc_mib": inc / 2**20, "ru_inc_mib": ru_inc / 2**20,
        "hwm_inc_mib": hwm_inc / 2**20, "inc_ratio": inc / io,
        "ratio": (r["input_bytes"] + inc) / io,
        "upper_bound": peak <= max(r["hwm_before_eval_kib"], r["maxrss_before_eval_kib"]),
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--quick", action="store_true",
                   help="smoke test: 10^5 and 10^6 points, 3 repeats, start-up for sphere only")
    p.add_argument("--sizes", nargs="+", type=float, help="point counts (default 1e6 1e7)")
    p.add_argument("--repeats", type=int, help="timed runs per measurement (default 5)")
    p.add_argument("--numpy-large-repeats", type=int, default=3,
                   help="timed runs of the NumPy reference at >= 10^7 points (default 3)")
    p.add_argument("--numpy-max-seconds", type=float, default=60.0,
                   help="skip a NumPy measurement whose runs would exceed this (default 60)")
    p.add_argument("--models", nargs="+", choices=MODELS, default=list(MODELS))
    p.add_argument("--no-startup", action="store_true", help="skip the cold/warm start test")
    p.add_argument("--no-memory", action="store_true", help="skip the peak-memory test")
    p.add_argument("--output", type=Path, default=HERE / "RESULTS.md",
                   help="Markdown results file (default benchmarks/RESULTS.md)")
    p.add_argument("--child", choices=("startup", "memory"), help=argparse.SUPPRESS)
    p.add_argument("--model", default="sphere", help=argparse.SUPPRESS)
    p.add_argument("--n", type=int, default=1000, help=argparse.SUPPRESS)
    p.add_argument("--backend", default="fast", help=argparse.SUPPRESS)
    a = p.parse_args(argv)

    if a.child == "startup":
        print(json.dumps(child_startup(a.model, a.n)))
        return 0
    if a.child == "memory":
        print(json.dumps(child_memory(a.model, a.n, a.backend)))
        return 0

    sizes = [int(s) for s in (a.sizes or ([1e5, 1e6] if a.quick else [1e6, 1e7]))]
    repeats = a.repeats or (3 if a.quick else 5)
    if repeats < 1 or any(s < 1 for s in sizes):
        p.error("--repeats and --sizes must be positive")
    cfg = Config(
        sizes=sorted(set(sizes)), repeats=repeats, numpy_large_repeats=a.numpy_large_repeats,
        large=10**7, numpy_max_seconds=a.numpy_max_seconds, models=a.models,
        startup_models=[] if a.no_startup else (["sphere"] if a.quick else a.models),
        memory=not a.no_memory, output=a.output,
        command=shlex.join(["python", *sys.argv]) if argv is None
        else shlex.join(["python", "benchmarks/bench_eval.py", *argv]),
    )
    return run(cfg)


def run(cfg: Config) -> int:
    import csdf

    t_start = time.perf_counter()
    info = machine_info()
    info.update(thread_scaling())
    log("csdf evaluation benchmark\n" + "\n".join(f"  {k}: {v}" for k, v in info.items()))

    shapes = {m: build_model(m) for m in cfg.models}
    progs = {m: csdf.compile(s) for m, s in shapes.items()}
    boxes = {m: model_box(s) for m, s in shapes.items()}
    backends_ok, kw_ok = probe_backends(progs[cfg.models[0]])
    for b, err in backends_ok.items():
        log(f"  backend {b!r}: {'available' if err is None else 'UNAVAILABLE - ' + err}")
    if not kw_ok and backends_ok["numpy"] is None:
        log("  (backend= keyword not accepted: the NumPy reference is called without it)")
    fast_ok = backends_ok["fast"] is None

    results, diffs, copy_times = bench_throughput(cfg, progs, boxes, backends_ok, kw_ok)
    memory = {}
    if cfg.memory and fast_ok:
        log(f"\n== peak memory at {fmt_n(max(cfg.sizes))} points (fresh subprocesses) ==")
        memory = bench_memory(cfg)
    startup = {}
    if cfg.startup_models and fast_ok:
        log("\n== start-up (fresh subprocesses) ==")
        startup = bench_startup(cfg)
    elapsed = time.perf_counter() - t_start

    md = report(cfg, info, progs, boxes, backends_ok, kw_ok, results, diffs, copy_times,
                startup, memory, elapsed)
    cfg.output.parent.mkdir(parents=True, exist_ok=True)
    cfg.output.write_text(md)
    log("\n" + md)
    log(f"written to {cfg.output}")
    return 0


# ---------------------------------------------------------------------------- report
def report(cfg, info, progs, boxes, backends_ok, kw_ok, results, diffs, copy_times,
           startup, memory, elapsed) -> str:
    from csdf.backends.numpy_backend import CHUNK

    big = max(cfg.sizes)
    L: list[str] = []
    L.append("# csdf evaluation benchmark\n")
    L.append(f"Command: `{cfg.command}`  \nTotal benchmark time: {elapsed:.0f} s\n")
    L.append("## Machine\n")
    L.append(md_table(["", ""], [[k, v] for k, v in info.items()]
                      + [["load average at end", loadavg()]]) + "\n")
    for b, err in backends_ok.items():
        if err is not None:
            L.append(f"**backend `{b}` unavailable**: `{err}`\n")
    if not kw_ok and backends_ok["numpy"] is None:
        L.append("The `backend=` keyword was not accepted: the NumPy reference was called "
                 "without it (it was the only evaluator).\n")

    L.append("## Models\n")
    rows = []
    for m in cfg.models:
        prog = progs[m]
        lo, hi = boxes[m]
        box = "[" + ", ".join(f"{a:.2f}..{b:.2f}" for a, b in zip(lo, hi)) + "]"
        rows.append([m, MODEL_DESC[m], str(len(prog)), ", ".join(prog.param_names), box])
    L.append(md_table(["model", "definition", "instructions", "params", "point box (x, y, z)"],
                      rows) + "\n")
    L.append(f"Points: float64, uniform in the model's bounding box grown by {BOX_PAD:.0%} per "
             f"side, generated once per size (seed {POINT_SEED}).\n")

    L.append("## Throughput\n")
    L.append(
        f"Median wall time of {cfg.repeats} timed runs after one warm-up run (fast backend, "
        f"and the NumPy reference below 10^7 points). The NumPy reference at >= 10^7 points "
        f"is timed with {min(cfg.repeats, cfg.numpy_large_repeats)} runs after a warm-up on "
        f"the first 10% of the points (it has no JIT; the warm-up only touches the code "
        f"paths); a NumPy measurement estimated to take more than "
        f"{cfg.numpy_max_seconds:.0f} s per run is skipped and its time extrapolated "
        f"linearly from the smaller size (marked `~`). Modes: `value` = `prog(pts)`, "
        f"`value+grad` = `prog.value_and_grad(pts)`, `value+grad+jac` = "
        f"`prog.value_grad_param_jacobian(pts)`. *numpy* is the shipped reference backend "
        f"(`backend='numpy'`): it runs the tape one instruction at a time over cache-sized "
        f"chunks ({CHUNK:,} points in value mode, fewer when tangents ride along). "
        f"*whole-array numpy* is the same evaluator with one chunk "
        f"holding all points, so every instruction materialises a full (N,) array: the "
        f"NumPy reference as the issue describes it (fogleman/sdf evaluates this way); "
        f"its results must equal the chunked ones. Speedup = numpy time / fast time. "
        f"max |fast - numpy| is over all returned arrays of the timed runs.\n")
    head = ["model", "points", "mode", "fast", "fast Mpts/s", "numpy", "numpy Mpts/s",
            "speedup", "whole-array numpy Mpts/s", "speedup vs whole-array", "max abs diff",
            "notes"]
    rows = []
    for n in cfg.sizes:
        for m in cfg.models:
            for mode in MODES:
                f, q = results[(m, n, mode, "fast")], results[(m, n, mode, "numpy")]
                w = results[(m, n, mode, WHOLE)]
                sp, spw = _speedup(f, q), _speedup(f, w)
                d = diffs.get((m, n, mode))
                notes = "; ".join(x for x in (
                    f"fast: {f.error}" if f.error else "",
                    f"numpy: {q.error}" if q.error else "",
                    f"numpy {q.note}" if q.note else "",
                    f"whole-array: {w.error}" if w.error and w.error != "unavailable" else "",
                    f"whole-array {w.note}" if w.note else "") if x)
                tilde = "~" if q.skipped else ""
                tw = "~" if w.skipped else ""
                rows.append([
                    m, fmt_n(n), MODE_LABEL[mode], fmt_s(f.median), _mpts(n, f.median),
                    tilde + fmt_s(q.median), tilde + _mpts(n, q.median),
                    "-" if sp is None else f"{tilde}{sp:.1f}x",
                    "-" if w.median is None else tw + _mpts(n, w.median),
                    "-" if spw is None else f"{tw}{spw:.1f}x",
                    "-" if d is None else f"{d:.1e}", notes,
                ])
    L.append(md_table(head, rows) + "\n")

    # baselines
    L.append("## Baselines\n")
    copy_med = statistics.median(copy_times[big])
    sph = results.get(("sphere", big, "value", "fast"))
    rows = [["`pts.copy()` of the (N, 3) float64 input", fmt_n(big), fmt_s(copy_med),
             f"{3 * 8 * big / copy_med / 2**30:.1f} GiB/s copied"]]
    ratio_copy = None
    if sph is not None and sph.median is not None:
        ratio_copy = sph.median / copy_med
        rows.append(["sphere value-only (fast) / copy", fmt_n(big), f"{ratio_copy:.2f}x",
                     f"target <= {TARGET_COPY_RATIO:g}x"])
    grad_ratios = {}
    for m in cfg.models:
        v, g = results[(m, big, "value", "fast")], results[(m, big, "grad", "fast")]
        if v.median and g.median:
            grad_ratios[m] = g.median / v.median
            rows.append([f"{m} value+grad / value (fast)", fmt_n(big),
                         f"{grad_ratios[m]:.2f}x", f"target <= {TARGET_GRAD_RATIO:g}x"])
        j = results[(m, big, "jac", "fast")]
        if v.median and j.median:
            rows.append([f"{m} value+grad+jac / value (fast)", fmt_n(big),
                         f"{j.median / v.median:.2f}x", "(information)"])
    L.append(md_table(["measurement", "points", "result", ""], rows) + "\n")

    # memory
    L.append("## Peak memory\n")
    mem_ratio = None
    if memory:
        L.append(
            f"Each row is a fresh subprocess (`bench_eval.py --child memory`, started from "
            f"a small `/bin/sh` so that its `ru_maxrss` does not inherit this process's "
            f"peak: Linux keeps `ru_maxrss` across exec): build and compile the model and "
            f"evaluate 1000 points once (loads the kernels); record `ru_maxrss` and VmRSS / "
            f"VmHWM (/proc/self/status); allocate the {fmt_n(big)} input points (in place, "
            f"no temporaries); record them again; evaluate (value only); record them again. "
            f"*Eval increase* = peak RSS after the call (the larger of `ru_maxrss` and VmHWM) "
            f"- RSS just before the call: the output array plus every temporary. "
            f"*ru_maxrss increase* is the plain difference of the two `ru_maxrss` readings "
            f"(a cross-check). *Peak / (in+out)* = (input bytes + eval increase) / (input "
            f"bytes + output bytes); 1.0 means nothing beyond the input and output arrays.\n")
        rows = []
        for (m, b), (r, err) in memory.items():
            if r is None:
                rows.append([m, b, "-", "-", "-", "-", "-", f"error: {err}"])
                continue
            mm = memory_metrics(r)
            if m == "sphere" and b == "fast":
                mem_ratio = mm["ratio"]
            note = "upper bound: an earlier peak was not exceeded" if mm["upper_bound"] else ""
            if b == "numpy":
                note = (note + "; " if note else "") + "reference (chunked evaluator)"
            rows.append([m, b, f"{mm['io_mib']:.0f} MiB", f"{mm['inc_mib']:.0f} MiB",
                         f"{mm['inc_ratio']:.2f}", f"{mm['ratio']:.2f}",
                         f"{mm['ru_inc_mib']:.0f} MiB", note])
        L.append(md_table(["model", "backend", "input+output", "eval increase",
                           "increase / (in+out)", "peak / (in+out)", "ru_maxrss increase",
                           "notes"], rows) + "\n")
    else:
        L.append("Not measured (fast backend unavailable or --no-memory).\n")

    # start-up
    L.append("## Cold and warm start\n")
    warm_first = None
    if startup:
        L.append(
            "Each run is a fresh subprocess (`bench_eval.py --child startup`) that times "
            "`import csdf`, building + `csdf.compile(model)`, then the first and a second "
            "`prog(pts_small, backend='fast')` on 1000 points. *Cold*: right after deleting "
            "Numba's cache files for csdf (`*.nbi`/`*.nbc` in the `__pycache__` directories "
            "under the installed package and under the fast backend's kernel cache), so the "
            "first call includes code generation and JIT compilation. The children are given "
            "a private, initially empty kernel cache (`CSDF_CACHE_DIR` = a temporary "
            "directory), so the user's cache of other kernels is left alone. *Warm*: a second "
            "fresh subprocess right after, so the first call loads the cached kernel. "
            "*process* is the subprocess wall time including interpreter start-up.\n")
        rows = []
        for m, s in startup.items():
            for tag in ("cold", "warm"):
                r = s[tag]
                if r is None:
                    rows.append([m, tag, "-", "-", "-", "-", "-", "-", s[f"{tag}_err"]])
                    continue
                if tag == "warm":
                    warm_first = r["first_call"] if warm_first is None else max(
                        warm_first, r["first_call"])
                note = ""
                if tag == "cold":
                    note = (f"{s['cleared']} Numba cache files deleted before, "
                            f"{s['cache_files_after']} after the two runs; kernel cache: "
                            f"{s['kernel_dir']}")
                if r.get("numba_imported_by_csdf"):
                    note += ("; " if note else "") + "`import csdf` imports numba"
                rows.append([m, tag, fmt_s(r["import"]), fmt_s(r["compile"]),
                             fmt_s(r["first_call"]), fmt_s(r["second_call"]),
                             fmt_s(r["total"]), fmt_s(s[f"{tag}_wall"]), note])
        L.append(md_table(["model", "start", "import csdf", "compile", "first call",
                           "second call", "import+compile+first", "process", "notes"], rows)
                 + "\n")
    else:
        L.append("Not measured (fast backend unavailable or --no-startup).\n")

    # targets
    L.append("## Targets\n")
    rows = []
    at = f"at {fmt_n(big)} points"
    for m in ("union20", "csg"):
        if m not in cfg.models:
            continue
        for ref, label, is_target in ((WHOLE, "whole-array NumPy reference (the issue's)", True),
                                      ("numpy", "chunked NumPy reference (shipped)", False)):
            sps = {}
            for mode in MODES:  # the largest size at which the reference ran this mode
                for n in sorted(cfg.sizes, reverse=True):
                    sp = _speedup(results[(m, n, mode, "fast")], results[(m, n, mode, ref)])
                    if sp is not None:
                        sps[mode] = (sp, n, results[(m, n, mode, ref)].skipped)
                        break
            name = f"{m}: fast >= {TARGET_SPEEDUP:g}x {label}, every mode"
            if not sps:
                rows.append([name, "not measured", "n/a" if is_target else "(information)"])
                continue
            worst = min(v[0] for v in sps.values())
            detail = ", ".join(f"{MODE_LABEL[k]} {v[0]:.1f}x at {fmt_n(v[1])}"
                               + (" ~" if v[2] else "") for k, v in sps.items())
            missing = [MODE_LABEL[k] for k in MODES if k not in sps]
            text = f"min {worst:.1f}x ({detail})"
            if missing:
                text += f"; not measured: {', '.join(missing)}"
            ok = worst >= TARGET_SPEEDUP and not missing
            rows.append([name, text, status(ok) if is_target else
                         f"(information: {'met' if ok else 'not met'})"])
    rows.append([f"sphere value-only <= {TARGET_COPY_RATIO:g}x `pts.copy()` ({at})",
                 "not measured" if ratio_copy is None else f"{ratio_copy:.2f}x",
                 status(None if ratio_copy is None else ratio_copy <= TARGET_COPY_RATIO)])
    for m in cfg.models:
        gr = grad_ratios.get(m)
        rows.append([f"{m}: value+grad <= {TARGET_GRAD_RATIO:g}x value (fast, {at})",
                     "not measured" if gr is None else f"{gr:.2f}x",
                     status(None if gr is None else gr <= TARGET_GRAD_RATIO)])
    rows.append([f"peak memory <= {TARGET_MEMORY_RATIO:g}x input+output (sphere, fast, "
                 f"value, {at})",
                 "not measured" if mem_ratio is None else f"{mem_ratio:.2f}x",
                 status(None if mem_ratio is None else mem_ratio <= TARGET_MEMORY_RATIO)])
    rows.append([f"warm start: first fast call in a fresh process <= {TARGET_WARM_START:g} s "
                 "(worst model)",
                 "not measured" if warm_first is None else fmt_s(warm_first),
                 status(None if warm_first is None else warm_first <= TARGET_WARM_START)])
    if big < 10**7:
        L.append(f"(Largest size here is {fmt_n(big)}, not 10^7: the targets are defined at "
                 f"10^7 points, so these rows are indicative only.)\n")
    L.append(md_table(["target", "measured", "result"], rows) + "\n")

    # raw samples
    L.append("## Raw samples\n")
    L.append("<details><summary>every timed run, seconds</summary>\n")
    rows = [["copy", "-", fmt_n(n), "-", " ".join(f"{t:.4f}" for t in copy_times[n])]
            for n in cfg.sizes]
    for (m, n, mode, b), tm in results.items():
        if tm.samples:
            rows.append([m, b, fmt_n(n), MODE_LABEL[mode],
                         " ".join(f"{t:.4f}" for t in tm.samples)])
    L.append(md_table(["model", "backend", "points", "mode", "samples"], rows))
    L.append("\n</details>\n")
    return "\n".join(L)


def _speedup(f: Timing, q: Timing) -> float | None:
    if f.median and q.median:
        return q.median / f.median
    return None


def _mpts(n: int, t: float | None) -> str:
    return "-" if not t else f"{n / t / 1e6:.1f}"


if __name__ == "__main__":
    sys.exit(main())
