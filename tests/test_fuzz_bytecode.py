"""Seeded fuzzing of the bytecode loaders, ``Program.from_bytes`` and ``Program.from_text``.

Seeds are the compiled zoo models and a few small programs, as bytes and as text
listings. Byte inputs get bit flips, byte sets, insertions, deletions, duplications,
interesting values (counts of 0xFFFF..., inf, nan) and splices with other programs; most
get their CRC-32 trailer recomputed so that the structural checks behind it run. Text
inputs get token and character edits, line deletions and duplications and splices.
Every input must either raise :class:`csdf.BytecodeError` or give a program that
evaluates (values, gradients, parameter Jacobians) and re-encodes without raising;
nothing else may escape, no input may take more than 2 s or grow peak memory by more
than 512 MB (see ``tests/fuzzing.py``). ``tests/test_bytecode_props.py`` holds the
hypothesis-driven, field-aware properties (canonical re-encoding, register use); these
fuzzers add volume and splices of real programs.

Inputs per run: ``CSDF_FUZZ_N=<n>`` (per fuzzer), or ``CSDF_FUZZ=1`` for 10^5; the
default (5,000 each) takes about 0.6 s (bytes) and 1 s (text) here. Input ``i`` of a
failure report is rebuilt with ``fuzzing.case(make_bytes, seed, i)`` (or ``make_text``;
the seed the report names). ``CSDF_FUZZ_SEED=<s>`` explores other inputs.
"""

from __future__ import annotations

import struct
import warnings
import zlib

import numpy as np

import csdf
from csdf import BytecodeError, Program, zoo

try:  # tests/ as a package or as a plain directory on sys.path
    from . import fuzzing
except ImportError:
    import fuzzing

SEED = 20261203
N_DEFAULT = 5000


def _programs() -> list[Program]:
    progs = [zoo.load(n).compile() for n in zoo.names()]
    progs += [
        csdf.sphere(1).compile(),
        (csdf.box(1) - csdf.sphere(0.6)).compile(),
        csdf.union(csdf.sphere(0.5), csdf.box(0.4).translate((1, 0, 0)), k=0.1).compile(),
        csdf.extrude(csdf.circle(0.5), 1).twist(0.5).compile(),
        csdf.circle(1).compile(),
        # colours that mix (a blend of two colours, a colour field): channel programs
        csdf.union(csdf.sphere(0.5).color((1, 0, 0)),
                   csdf.box(0.4).translate((1, 0, 0)).color_field((csdf.x, 0.5, 0.2)),
                   k=0.1).compile(),
    ]
    return progs


PROGRAMS = _programs()
BYTES = [p.to_bytes() for p in PROGRAMS]
TEXTS = [p.disassemble() for p in PROGRAMS]
BYTE_TOKENS = [b"CSDF", b"\x01\x00", b"\x02\x00", b"\x00\x00\x00\x00", b"\x80", b"\n",
               b"\xff\xfe", b"\xc3"]
TEXT_TOKENS = sorted({w for t in TEXTS for w in t.split()}) + [
    "nan", "-nan", "inf", "-inf", "1e999", "1e-400", "r65535", "c999999", "@999999999",
    "0x10", "1_0", ";", "\u0663", "\n", " ", "=", "-0.0", "99999999999999999999",
]
_PTS = np.array([[0.0, 0.0, 0.0], [0.1, -0.2, 0.3], [1.0, 1.0, 1.0], [-0.5, 0.25, 2.0]])


def with_crc(body: bytes) -> bytes:
    """``body`` followed by its little-endian CRC-32 (the format's trailer)."""
    return bytes(body) + struct.pack("<I", zlib.crc32(body) & 0xFFFFFFFF)


def make_bytes(rng: np.random.Generator) -> bytes:
    """A mutated program; four times out of five with a correct CRC."""
    raw = BYTES[int(rng.integers(len(BYTES)))]
    r = rng.random()
    if r < 0.2:
        return fuzzing.mutate_bytes(rng, raw, BYTES, BYTE_TOKENS)
    body = fuzzing.mutate_bytes(rng, raw[:-4], [b[:-4] for b in BYTES], BYTE_TOKENS)
    return with_crc(body)


def make_text(rng: np.random.Generator) -> str:
    """A mutated program listing."""
    text = TEXTS[int(rng.integers(len(TEXTS)))]
    return fuzzing.mutate_text(rng, text, TEXTS, TEXT_TOKENS)


def exercise(prog: Program) -> None:
    """Everything a caller does with an accepted program must work (no exception)."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            pts = _PTS if prog.dim == 3 else _PTS[:, :2]
            v = prog(pts)
            g = prog.gradient(pts)
            j = prog.param_jacobian(pts)
            assert v.shape == (len(pts),) and g.shape == pts.shape
            assert j.shape == (len(pts), len(prog.params))
            raw = prog.to_bytes()
            prog.disassemble()
        assert Program.from_bytes(raw).to_bytes() == raw
    except Exception as exc:
        raise AssertionError(f"accepted program fails: {type(exc).__name__}: {exc}") from exc


def check_bytes(data: bytes) -> None:
    exercise(Program.from_bytes(data))


def check_text(text: str) -> None:
    exercise(Program.from_text(text))


def test_seeds_load():
    for raw, text in zip(BYTES, TEXTS):
        check_bytes(raw)
        check_text(text)


def test_fuzz_from_bytes():
    stats = fuzzing.run("from_bytes", fuzzing.seed(SEED), fuzzing.count(N_DEFAULT),
                        make_bytes, check_bytes, (BytecodeError,))
    print(f"from_bytes fuzz: {stats}")
    assert stats.rejected > 0


def test_fuzz_from_text():
    stats = fuzzing.run("from_text", fuzzing.seed(SEED), fuzzing.count(N_DEFAULT),
                        make_text, check_text, (BytecodeError,))
    print(f"from_text fuzz: {stats}")
    assert stats.accepted > 0 and stats.rejected > 0
