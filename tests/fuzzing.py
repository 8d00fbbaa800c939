"""Shared machinery of the seeded mutation fuzzers (``tests/test_fuzz_*.py``).

Each fuzzer draws input ``i`` from its own generator ``numpy.random.default_rng((seed, i))``,
so any single input can be rebuilt from ``(seed, i)`` without replaying the others
(:func:`case`). :func:`run` feeds the inputs to a check function and enforces

* only the allowed exceptions (``csdf.CsdfError`` subclasses, plus whatever the check
  itself asserts) escape;
* each input finishes within a time limit (``SIGALRM`` interrupts a hang; the elapsed
  time is also checked after the fact);
* the process's peak resident memory does not grow by more than a bound on any input.

The number of inputs comes from :func:`count`: ``CSDF_FUZZ_N=<n>`` sets it, ``CSDF_FUZZ=1``
makes it 10^5, otherwise each module's default (a few thousand) is used;
``CSDF_FUZZ_SEED=<s>`` replaces every fuzzer's seed (:func:`seed`). A failure
names the fuzzer, its seed and index, the exception and the input's ``repr`` (truncated).
"""

from __future__ import annotations

import os
import resource
import signal
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

LONG_RUN = 100_000
TIME_LIMIT_S = 2.0
MEMORY_LIMIT_MB = 512
REPR_LIMIT = 600

#: byte values that often sit on a decoder's edge cases
INTERESTING_BYTES = (0x00, 0x01, 0x02, 0x0A, 0x0D, 0x20, 0x7F, 0x80, 0xFE, 0xFF)
#: little-endian multi-byte values of the same kind (counts, offsets, floats)
INTERESTING_CHUNKS = (
    b"\xff\xff", b"\x00\x00", b"\xff\xff\xff\xff", b"\x00\x00\x00\x80", b"\xff\xff\xff\x7f",
    b"\x00\x00\x00\x00\x00\x00\xf0\x7f",  # inf
    b"\x00\x00\x00\x00\x00\x00\xf8\x7f",  # nan
    b"\x00\x00\x00\x00\x00\x00\xf0\xff",  # -inf
    b"\x01\x00\x00\x00\x00\x00\x00\x00",  # 5e-324
    b"\xff\xff\xff\xff\xff\xff\xef\x7f",  # max float
)


def count(default: int) -> int:
    """Inputs per fuzzer: ``CSDF_FUZZ_N``, else 10^5 under ``CSDF_FUZZ=1``, else ``default``."""
    n = os.environ.get("CSDF_FUZZ_N", "").strip()
    if n:
        return int(n)
    if os.environ.get("CSDF_FUZZ", "").strip() not in ("", "0"):
        return LONG_RUN
    return default


def seed(default: int) -> int:
    """The fuzzer's seed: ``CSDF_FUZZ_SEED`` (to explore other inputs), else ``default``."""
    value = os.environ.get("CSDF_FUZZ_SEED", "").strip()
    return int(value) if value else default


def case(make: Callable[[np.random.Generator], Any], seed: int, index: int) -> Any:
    """Input ``index`` of the fuzzer with ``make`` and ``seed`` (to reproduce a failure)."""
    return make(np.random.default_rng((seed, index)))


class Hang(BaseException):
    """Raised by the alarm when one input runs past the time limit (a ``BaseException``,
    so that no ``except Exception`` in the code under test swallows it)."""


def _on_alarm(signum: int, frame: Any) -> None:
    raise Hang()


def _short(value: Any) -> str:
    r = repr(value)
    if len(r) > REPR_LIMIT:
        r = r[: REPR_LIMIT // 2] + f" ...<{len(r) - REPR_LIMIT} chars>... " + r[-REPR_LIMIT // 2:]
    return r


def _peak_rss_mb() -> float:
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / (1024 * 1024) if sys.platform == "darwin" else peak / 1024


@dataclass
class Stats:
    """What one fuzzing run saw."""

    n: int = 0
    accepted: int = 0
    rejected: int = 0
    seconds: float = 0.0
    slowest: float = 0.0
    errors: dict[str, int] = field(default_factory=dict)


def run(
    name: str,
    seed: int,
    n: int,
    make: Callable[[np.random.Generator], Any],
    check: Callable[[Any], Any],
    allowed: tuple[type[BaseException], ...],
    *,
    time_limit: float = TIME_LIMIT_S,
    memory_limit_mb: float = MEMORY_LIMIT_MB,
) -> Stats:
    """Run ``check(make(rng_i))`` for ``i < n``; raise ``AssertionError`` on the first input
    that raises anything but ``allowed``, hangs or blows up memory.

    ``check`` returns normally for an accepted input and raises one of ``allowed`` for a
    rejected one; it may itself raise ``AssertionError`` (a broken contract).
    """
    stats = Stats(n=n)
    use_alarm = hasattr(signal, "setitimer") and \
        signal.getsignal(signal.SIGALRM) in (signal.SIG_DFL, None)
    old = signal.signal(signal.SIGALRM, _on_alarm) if use_alarm else None
    start = time.perf_counter()
    try:
        for i in range(n):
            data = case(make, seed, i)
            where = f"fuzzer {name!r}, seed {seed}, index {i}"
            rss0 = _peak_rss_mb()
            t0 = time.perf_counter()
            try:
                if use_alarm:
                    signal.setitimer(signal.ITIMER_REAL, time_limit * 1.5 + 1.0)
                try:
                    check(data)
                finally:
                    if use_alarm:
                        signal.setitimer(signal.ITIMER_REAL, 0)
            except allowed as exc:
                stats.rejected += 1
                key = type(exc).__name__
                stats.errors[key] = stats.errors.get(key, 0) + 1
            except Hang:
                raise AssertionError(f"{where}: still running after {time_limit * 1.5 + 1:.1f} s"
                                     f"\n  input: {_short(data)}") from None
            except Exception as exc:
                raise AssertionError(f"{where}: {type(exc).__name__}: {exc}"
                                     f"\n  input: {_short(data)}") from exc
            else:
                stats.accepted += 1
            dt = time.perf_counter() - t0
            stats.slowest = max(stats.slowest, dt)
            assert dt <= time_limit, \
                f"{where}: took {dt:.2f} s (limit {time_limit} s)\n  input: {_short(data)}"
            grown = _peak_rss_mb() - rss0
            assert grown <= memory_limit_mb, \
                f"{where}: peak memory grew by {grown:.0f} MB\n  input: {_short(data)}"
    finally:
        if use_alarm:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, old)
    stats.seconds = time.perf_counter() - start
    return stats


# ------------------------------------------------------------------------------ mutations
def mutate_bytes(rng: np.random.Generator, data: bytes, pool: Sequence[bytes] = (),
                 dictionary: Sequence[bytes] = (), max_edits: int = 6) -> bytes:
    """``data`` with 1..``max_edits`` random edits: bit flips, byte sets, insertions,
    deletions, duplications, interesting values, dictionary tokens and splices with
    other inputs of ``pool``."""
    buf = bytearray(data)
    for _ in range(int(rng.integers(1, max_edits + 1))):
        kind = int(rng.integers(0, 10))
        i = int(rng.integers(0, len(buf) + 1))
        if kind == 0 and buf:  # bit flip
            j = min(i, len(buf) - 1)
            buf[j] ^= 1 << int(rng.integers(0, 8))
        elif kind == 1 and buf:  # random byte
            buf[min(i, len(buf) - 1)] = int(rng.integers(0, 256))
        elif kind == 2 and buf:  # interesting byte
            buf[min(i, len(buf) - 1)] = INTERESTING_BYTES[int(rng.integers(len(INTERESTING_BYTES)))]
        elif kind == 3:  # insert random bytes
            buf[i:i] = rng.integers(0, 256, size=int(rng.integers(1, 9))).astype(np.uint8).tobytes()
        elif kind == 4 and buf:  # delete a run
            del buf[i:i + int(rng.integers(1, 17))]
        elif kind == 5 and buf:  # duplicate a run of the input elsewhere
            j = int(rng.integers(0, len(buf)))
            buf[i:i] = buf[j:j + int(rng.integers(1, 33))]
        elif kind == 6 and buf:  # overwrite with an interesting chunk
            chunk = INTERESTING_CHUNKS[int(rng.integers(len(INTERESTING_CHUNKS)))]
            buf[i:i + len(chunk)] = chunk
        elif kind == 7 and dictionary:  # insert or overwrite with a token
            tok = dictionary[int(rng.integers(len(dictionary)))]
            if rng.random() < 0.5:
                buf[i:i] = tok
            else:
                buf[i:i + len(tok)] = tok
        elif kind == 8 and pool:  # splice: a prefix of this input, a suffix of another
            other = pool[int(rng.integers(len(pool)))]
            j = int(rng.integers(0, len(other) + 1))
            buf = buf[:i] + bytearray(other[j:])
        elif kind == 9 and buf:  # swap two runs
            j = int(rng.integers(0, len(buf)))
            k = int(rng.integers(1, 17))
            a, b = bytes(buf[i:i + k]), bytes(buf[j:j + k])
            buf[i:i + len(a)] = b
            buf[j:j + len(b)] = a
    return bytes(buf)


def mutate_text(rng: np.random.Generator, text: str, pool: Sequence[str] = (),
                tokens: Sequence[str] = (), max_edits: int = 4) -> str:
    """``text`` with 1..``max_edits`` edits at character and token level (deletions,
    insertions of tokens or printable and odd characters, line duplications and
    deletions, splices with other texts of ``pool``)."""
    s = text
    odd = "()[]{},.=:;#\"'\\\n\t\r \x00\u00e9\u2028\ud800\U0001f600-+*/|&~^<>!?@$%0123456789e"
    for _ in range(int(rng.integers(1, max_edits + 1))):
        kind = int(rng.integers(0, 8))
        i = int(rng.integers(0, len(s) + 1))
        if kind == 0 and s:  # delete a run
            s = s[:i] + s[i + int(rng.integers(1, 9)):]
        elif kind == 1 and tokens:  # insert a token
            s = s[:i] + tokens[int(rng.integers(len(tokens)))] + s[i:]
        elif kind == 2 and tokens and s:  # replace a run by a token
            s = s[:i] + tokens[int(rng.integers(len(tokens)))] + s[i + int(rng.integers(1, 6)):]
        elif kind == 3:  # insert an odd character
            s = s[:i] + odd[int(rng.integers(len(odd)))] + s[i:]
        elif kind == 4 and s:  # replace a character
            s = s[:i] + odd[int(rng.integers(len(odd)))] + s[i + 1:]
        elif kind == 5:  # delete or duplicate a line
            lines = s.split("\n")
            k = int(rng.integers(0, len(lines)))
            if rng.random() < 0.5:
                del lines[k]
            else:
                lines.insert(int(rng.integers(0, len(lines) + 1)), lines[k])
            s = "\n".join(lines)
        elif kind == 6 and pool:  # splice with another text
            other = pool[int(rng.integers(len(pool)))]
            s = s[:i] + other[int(rng.integers(0, len(other) + 1)):]
        elif kind == 7 and s:  # duplicate a run
            j = int(rng.integers(0, len(s)))
            s = s[:i] + s[j:j + int(rng.integers(1, 40))] + s[i:]
    return s
