"""Helpers shared by the benchmark scripts: machine description, load, Markdown tables,
child processes."""

from __future__ import annotations

import datetime as _dt
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


def read_text(path: str) -> str:
    """A file's text, or '' when it cannot be read."""
    try:
        return Path(path).read_text()
    except OSError:
        return ""


def loadavg() -> str:
    try:
        return " ".join(f"{v:.2f}" for v in os.getloadavg()) + " (1, 5, 15 min)"
    except OSError:
        return "unknown"


def run_child(script: str | Path, args: list[str], timeout: float = 600,
              via_shell: bool = False) -> tuple[dict | None, float, str]:
    """Run a benchmark ``script`` as a child process whose last stdout line is JSON.

    Returns ``(that JSON record or None, wall seconds, error text)``.

    ``via_shell``: start it from a small ``/bin/sh`` that forks it (``"$@"; exit $?`` is
    not exec'd in place), so that its ``ru_maxrss`` starts from the shell's size instead
    of this process's (Linux keeps the peak RSS across exec, not across fork).
    """
    cmd = [sys.executable, str(Path(script).resolve()), *args]
    if via_shell and Path("/bin/sh").exists():
        cmd = ["/bin/sh", "-c", '"$@"; exit $?', "sh", *cmd]
    t0 = time.perf_counter()
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, check=False)
    except subprocess.TimeoutExpired:
        return None, time.perf_counter() - t0, f"timed out after {timeout:.0f} s"
    wall = time.perf_counter() - t0
    lines = proc.stdout.strip().splitlines()
    if proc.returncode != 0 or not lines:
        tail = (proc.stderr.strip().splitlines() or ["(no output)"])[-1]
        return None, wall, f"exit {proc.returncode}: {tail}"
    try:
        return json.loads(lines[-1]), wall, ""
    except json.JSONDecodeError:
        return None, wall, f"bad output: {lines[-1][:200]}"


def md_table(head: list[str], rows: list[list[str]]) -> str:
    out = ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
    out += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(out)


def machine_info(extra: dict[str, str] | None = None) -> dict[str, str]:
    """Date, CPU, cores, RAM, OS, Python, NumPy, Numba, ``extra`` versions, the csdf
    version with the commit of the checkout it is imported from, and the load average."""
    cpu = "unknown"
    for line in read_text("/proc/cpuinfo").splitlines():
        if line.lower().startswith("model name"):
            cpu = line.split(":", 1)[1].strip()
            break
    ram = "unknown"
    for line in read_text("/proc/meminfo").splitlines():
        if line.startswith("MemTotal:"):
            ram = f"{int(line.split()[1]) / 2**20:.1f} GiB"
            break
    logical = os.cpu_count() or 0
    usable = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else logical
    try:
        import numba

        numba_v = f"{numba.__version__} (NUMBA_NUM_THREADS = {numba.config.NUMBA_NUM_THREADS})"
    except Exception as exc:
        numba_v = f"unavailable ({type(exc).__name__})"
    try:
        import csdf

        csdf_v, csdf_dir = csdf.__version__, Path(csdf.__file__).resolve().parent
    except Exception as exc:
        csdf_v, csdf_dir = f"unavailable ({type(exc).__name__})", HERE.parent
    commit = "unknown"
    try:  # the checkout that the imported csdf comes from
        commit = subprocess.run(
            ["git", "-C", str(csdf_dir), "describe", "--always", "--dirty"],
            capture_output=True, text=True, timeout=10, check=False,
        ).stdout.strip() or "unknown"
    except (OSError, subprocess.SubprocessError):
        pass
    return {
        "date": _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d %H:%M:%S UTC"),
        "CPU": cpu,
        "cores": f"{logical} logical, {usable} usable by this process",
        "RAM": ram,
        "OS": f"{platform.system()} {platform.release()} ({platform.machine()})",
        "Python": f"{platform.python_version()} ({sys.executable})",
        "NumPy": np.__version__,
        "Numba": numba_v,
        **(extra or {}),
        "csdf": f"{csdf_v} (git {commit}, imported from {csdf_dir})",
        "load average at start": loadavg(),
    }


def thread_scaling(seconds: float = 0.5) -> dict[str, str]:
    """How much a second thread adds on this machine, for two kinds of Numba loop.

    Runs a job alone, then two copies at once on two threads, and reports
    ``time(one job) * 2 / time(two jobs)`` (2.0 = the second thread doubles the work done;
    1.0 = it adds nothing). *Vector-bound*: a SIMD multiply-add loop over an L1-resident
    array (the kind of code the fast backend runs); *latency-bound*: a scalar dependency
    chain. Virtual CPUs that are hyper-threads of one core share its vector units: the
    first ratio then stays near 1 while the second reaches 2.

    Returns ``{'thread scaling, vector-bound': '1.05x', 'thread scaling, latency-bound':
    '1.98x'}`` (or one 'unavailable' entry without Numba).
    """
    import time
    from concurrent.futures import ThreadPoolExecutor

    try:
        from numba import njit
    except Exception as exc:  # pragma: no cover - numba is a dependency
        return {"thread scaling": f"unavailable ({type(exc).__name__})"}

    @njit(nogil=True, cache=False)
    def vector_job(a, out, reps):
        for _ in range(reps):
            for j in range(a.shape[0]):
                x = a[j]
                out[j] = x * 1.1 + (x + 1.0) * 1.3 + (x + 2.0) * x * 0.5 + out[j] * 0.25

    @njit(nogil=True, cache=False)
    def latency_job(n):
        s = 0.0
        for i in range(n):
            s = s * 0.999999 + i
        return s

    a = np.random.default_rng(0).random(2048)
    outs = [np.zeros_like(a), np.zeros_like(a)]
    vector_job(a, outs[0], 1)
    latency_job(10)

    def calibrate(run) -> int:
        """Repetitions for one job to take about ``seconds``."""
        n = 1
        while True:
            t0 = time.perf_counter()
            run(0, n)
            dt = time.perf_counter() - t0
            if dt > seconds / 4:
                return max(1, int(n * seconds / dt))
            n *= 4

    jobs = {
        "vector-bound": lambda k, n: vector_job(a, outs[k], n),
        "latency-bound": lambda k, n: latency_job(n * 1000),
    }
    res = {}
    with ThreadPoolExecutor(2) as ex:
        for name, run in jobs.items():
            n = calibrate(run)
            t0 = time.perf_counter()
            run(0, n)
            one = time.perf_counter() - t0
            t0 = time.perf_counter()
            for f in [ex.submit(run, k, n) for k in (0, 1)]:
                f.result()
            two = time.perf_counter() - t0
            res[f"thread scaling, {name}"] = f"{2 * one / two:.2f}x (2 threads, 2.00x = ideal)"
    return res


def median_time(fn, repeat: int) -> tuple[float, object]:
    """``(median seconds of `repeat` calls of fn(), the last result)``, after one
    warm-up call."""
    import statistics
    import time

    fn()
    ts, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts), out
