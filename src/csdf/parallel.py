"""Process-wide worker threads: the one pool per purpose that evaluators and consumers
share, and a helper that splits a range of points over the cores.

Work handed to these threads must release the GIL (Numba ``nogil`` kernels, NumPy on
large arrays) to run in parallel.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor

__all__ = ["N_THREADS", "MIN_PER_THREAD", "cores", "executor", "run_parallel"]



def cores() -> int:
    """The cores this process may run on (its CPU affinity where the OS has one)."""
    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity")
               else (os.cpu_count() or 1))


def _threads() -> int:
    """``$CSDF_THREADS`` when set to a positive integer, else :func:`cores`."""
    text = os.environ.get("CSDF_THREADS", "").strip()
    if text:
        try:
            n = int(text)
        except ValueError:
            n = 0
        if n < 1:
            raise ValueError(f"CSDF_THREADS must be a positive integer, got {text!r}")
        return n
    return cores()


#: the threads csdf's evaluators and meshers use in this process: the cores it may run
#: on, or ``$CSDF_THREADS`` (read at import; a Dask worker process sharing a machine
#: with others sets it to its own share, see :func:`csdf.distributed.connect`)
N_THREADS = _threads()
#: :func:`run_parallel` gives each thread at least this many items
MIN_PER_THREAD = 8192
_pools: dict[tuple[str, int], ThreadPoolExecutor] = {}
_pool_lock = threading.Lock()


def executor(name: str = "csdf", workers: int = N_THREADS) -> ThreadPoolExecutor:
    """A process-wide pool of ``workers`` threads named ``name`` (made on first use)."""
    with _pool_lock:
        pool = _pools.get((name, workers))
        if pool is None:
            pool = _pools[(name, workers)] = ThreadPoolExecutor(
                max_workers=workers, thread_name_prefix=name)
        return pool


def run_parallel(job: Callable[[tuple[int, int]], object], n: int, align: int) -> None:
    """Call ``job((start, stop))`` on one contiguous range of ``[0, n)`` per core (range
    lengths a multiple of ``align``, at least :data:`MIN_PER_THREAD` items each); a
    single range runs on the calling thread."""
    if n == 0:
        return
    nt = max(1, min(N_THREADS, n // MIN_PER_THREAD))
    step = -(-n // nt)
    step = -(-step // align) * align
    ranges = [(s, min(n, s + step)) for s in range(0, n, step)]
    if len(ranges) == 1:
        job(ranges[0])
    else:
        list(executor().map(job, ranges))
