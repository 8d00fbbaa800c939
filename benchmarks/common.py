"""Helpers shared by the benchmark scripts: machine description, load, Markdown tables."""

from __future__ import annotations

import datetime as _dt
import os
import platform
import subprocess
import sys
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
