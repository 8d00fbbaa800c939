"""Recycled memory for large results (the fast evaluator's outputs), and private memory
maps (the mesher's chunk buffers).

Writing a fresh large result first costs a page fault per page, which can take longer
than the evaluation that fills it (more when NumPy's huge-page advice makes the OS
compact memory first; figures in ``benchmarks/MEMORY_NOTES.md``). Code that evaluates
in a loop (fitting, rendering, meshing, benchmarks) drops each result before asking for
the next, so the same memory can serve again with its pages already in place.

:func:`result_array` hands out arrays over private anonymous memory maps kept in a
small pool. A map is reused only when no array or view of an earlier result still uses
it: the map then has no exported buffer, which ``mmap.resize`` to its own size checks
(it raises ``BufferError`` while any export is alive), so a result the caller still
holds is never overwritten. Bounds: only results of ``MIN_BYTES`` to ``MAX_BYTES`` are
pooled, at most ``MAX_MAPS`` maps are kept (idle ones of another size are dropped when
a new size is asked for), and :func:`release_memory` drops every idle map. Where that
check does not work (probed once at import), nothing is pooled.
"""

from __future__ import annotations

import math
import mmap
import threading

import numpy as np

__all__ = ["result_array", "release_memory", "private_map", "map_array", "MIN_BYTES",
           "MAX_BYTES", "MAX_MAPS"]

MIN_BYTES = 4 << 20  # smaller results come from np.empty (malloc reuses its memory)
MAX_BYTES = 512 << 20  # larger ones too: the pool never holds more than MAX_MAPS of these
MAX_MAPS = 2

_maps: list[mmap.mmap] = []
_lock = threading.Lock()


def private_map(nbytes: int, huge: bool = False) -> mmap.mmap:
    """A private anonymous memory map of ``nbytes`` (pages never written cost address
    space only), advised to use transparent huge pages when ``huge`` (``MADV_HUGEPAGE``,
    where the OS has it). Private, not Python's default shared mapping: shared anonymous
    memory never gets huge pages."""
    m = mmap.mmap(-1, nbytes, flags=mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS)
    if huge:
        try:
            m.madvise(mmap.MADV_HUGEPAGE)
        except (AttributeError, OSError, ValueError):  # pragma: no cover - platform
            pass
    return m


def map_array(m: mmap.mmap, shape: tuple[int, ...], dtype) -> np.ndarray:
    """An array ``shape, dtype`` over the start of map ``m`` (which it exports)."""
    return np.frombuffer(m, dtype=dtype, count=int(np.prod(shape))).reshape(shape)


def _in_use(m: mmap.mmap) -> bool:
    """True while some array (or view) still exports the map's buffer."""
    try:
        m.resize(len(m))
    except BufferError:
        return True
    except (OSError, SystemError, TypeError, ValueError):  # pragma: no cover - platform
        return True  # cannot tell: never reuse it
    return False


def _check_works() -> bool:
    """Whether :func:`_in_use` tells a held map from a free one on this platform (where
    it cannot, nothing is pooled)."""
    try:
        m = private_map(mmap.PAGESIZE)
        a = map_array(m, (mmap.PAGESIZE,), np.uint8)
        held = _in_use(m)
        del a
        ok = held and not _in_use(m)
        m.close()
        return ok
    except Exception:  # pragma: no cover - platform
        return False


_WORKS = _check_works()


def result_array(shape: tuple[int, ...], dtype) -> np.ndarray:
    """An uninitialised, writable, C-contiguous array like ``np.empty(shape, dtype)``,
    on recycled memory when its size is in the pooled range and a pooled map of exactly
    that size is free."""
    dtype = np.dtype(dtype)
    count = math.prod(int(n) for n in shape)  # (np.prod: ~10 us a call)
    nbytes = count * dtype.itemsize
    if not (_WORKS and MIN_BYTES <= nbytes <= MAX_BYTES):
        return np.empty(shape, dtype)
    with _lock:
        idle = [m for m in _maps if not _in_use(m)]
        mine = next((m for m in idle if len(m) == nbytes), None)
        if mine is None:
            for m in idle:  # another size: free it rather than keep it
                _maps.remove(m)
                m.close()
            if len(_maps) >= MAX_MAPS:
                return np.empty(shape, dtype)
            try:
                mine = private_map(nbytes)
            except (OSError, ValueError, AttributeError):  # pragma: no cover - platform
                return np.empty(shape, dtype)
            _maps.append(mine)
        # exported before the lock is released, so no other caller can take it
        return map_array(mine, shape, dtype)


def release_memory() -> int:
    """Unmap every pooled map that no result uses any more; returns the bytes freed."""
    freed = 0
    with _lock:
        for m in [m for m in _maps if not _in_use(m)]:
            _maps.remove(m)
            freed += len(m)
            m.close()
    return freed
