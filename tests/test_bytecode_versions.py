"""Bytecode format versions: programs carry their bounds (version 2), old files load.

``tests/data/old_v1_*.csdfb`` (and their ``.csdft`` listings) were written by the
version-1 encoder, before programs had bounds; ``*_values.npy`` holds their values
(reference backend) at 64 fixed points (``default_rng(7).uniform(-1.5, 1.5, (64, 3))``,
the first ``dim`` columns).
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np
import pytest

import csdf
import csdf.compiler.binary as binary
import csdf.compiler.tape as tape
import csdf.layout
from csdf.compiler import compile_expr
from csdf.expr import X, Y, const, make

DATA = Path(__file__).resolve().parent / "data"
OLD = {
    "old_v1_blend": lambda: csdf.union(
        csdf.sphere(csdf.param("r", 0.8, 0.5, 1.2)), csdf.box(1.0).twist(0.5), k=0.1),
    "old_v1_polygon_2d": lambda: csdf.polygon([(0, 0), (1, 0), (0.5, 1)]),
}
#: files whose shape csdf now compiles with another formula of the same distance (the
#: polygon's edge lines, for gradients defined on the outline): the old program still
#: loads and gives its values; today's gives them to rounding
REFORMULATED = {"old_v1_polygon_2d"}


def _points(dim: int) -> np.ndarray:
    return np.random.default_rng(7).uniform(-1.5, 1.5, (64, 3))[:, :dim]


def _with_crc(body: bytes) -> bytes:
    return body + struct.pack("<I", zlib.crc32(body) & 0xFFFFFFFF)


def _same_tape(p: csdf.Program, q: csdf.Program) -> None:
    np.testing.assert_array_equal(p.code, q.code)
    assert p.consts.tobytes() == q.consts.tobytes()
    assert (p.params, p.output, p.n_regs, p.dim, p.calls) == (
        q.params, q.output, q.n_regs, q.dim, q.calls)
    assert (p.exactness, p.lipschitz) == (q.exactness, q.lipschitz)


# ------------------------------------------------------------------------- old files
@pytest.mark.parametrize("name", sorted(OLD))
def test_old_version_1_files_load(name):
    raw = (DATA / f"{name}.csdfb").read_bytes()
    assert struct.unpack_from("<H", raw, 4)[0] == 1
    old = csdf.Program.from_bytes(raw)
    assert old.bounds is None
    assert old.to_bytes() == raw  # a program without bounds is still written as v1
    fresh = OLD[name]().compile()
    if name not in REFORMULATED:
        _same_tape(old, fresh)
    pts = _points(old.dim)
    want = np.load(DATA / f"{name}_values.npy")
    np.testing.assert_array_equal(old(pts, backend="numpy"), want)
    # the old listing loads to the same program
    listing = (DATA / f"{name}.csdft").read_text()
    assert "bounds" not in listing
    assert csdf.Program.from_text(listing) == old
    if name in REFORMULATED:
        np.testing.assert_allclose(fresh(pts, backend="numpy"), want, rtol=0, atol=1e-14)
        return
    np.testing.assert_array_equal(fresh(pts, backend="numpy"), want)
    # and giving it the shape's bounds makes it the program csdf compiles today
    assert old.with_bounds(OLD[name]().bounds) == fresh


# ------------------------------------------------------------------------- bounds kept
@pytest.mark.parametrize("make_shape", [
    lambda: csdf.sphere(csdf.param("r", 0.8, 0.5, 1.2)),
    lambda: csdf.box((1, 2, 3)).translate((0.5, 0, -1)),
    lambda: csdf.circle(0.4).translate((1, 2)),
    lambda: csdf.sphere(1) & csdf.sphere(1).translate((5, 0, 0)),  # empty box lo > hi
])
def test_program_carries_shape_bounds_through_bytes_and_text(make_shape):
    s = make_shape()
    p = s.compile()
    assert p.bounds is not None and p.bounds.shape == (2, s.dim)
    assert p.bounds.tobytes() == np.asarray(s.bounds, dtype=np.float64).tobytes()
    assert not p.bounds.flags.writeable
    b = p.to_bytes()
    assert struct.unpack_from("<H", b, 4)[0] == 2  # (version 3 only with data blocks)
    q = csdf.Program.from_bytes(b)
    assert q == p and q.to_bytes() == b and q.bounds.tobytes() == p.bounds.tobytes()
    text = p.disassemble()
    assert text.startswith("csdf-program 1\n") and "\nbounds " in text
    t = csdf.Program.from_text(text)
    assert t.to_bytes() == b


def test_bounds_take_part_in_equality_and_hash():
    p = csdf.sphere(1.0).compile()
    q = p.with_bounds(None)
    r = p.with_bounds(p.bounds * 2)
    assert p != q and p != r and q != r
    assert len({p, q, r, p.with_bounds(p.bounds.copy())}) == 3
    assert q.with_bounds(p.bounds) == p


def test_special_bounds_round_trip_bit_for_bit():
    """Bounds are stored as the shape computed them (consumers judge their validity):
    infinite, NaN (with its payload), signed zeros and lo > hi all survive."""
    nan = struct.unpack("<d", bytes.fromhex("0100000000f8ff7f"))[0]
    box = np.array([[-np.inf, nan, -0.0], [np.inf, -1.0, 0.0]])
    p = compile_expr(make("add", X, Y), bounds=box)
    for q in (csdf.Program.from_bytes(p.to_bytes()), csdf.Program.from_text(p.disassemble())):
        assert q.bounds.tobytes() == box.tobytes()
        assert q.to_bytes() == p.to_bytes()


def test_compile_expr_has_no_bounds_by_default():
    p = compile_expr(make("add", X, const(1.0)))
    assert p.bounds is None
    assert struct.unpack_from("<H", p.to_bytes(), 4)[0] == 1
    assert "bounds" not in p.disassemble()


def test_bad_bounds_are_rejected():
    with pytest.raises(ValueError, match=r"shape \(2, 3\)"):
        compile_expr(X, bounds=np.zeros((2, 2)))
    with pytest.raises(ValueError, match=r"shape \(2, 2\)"):
        compile_expr(X, dim=2, bounds=np.zeros(4))
    p = csdf.sphere(1.0).compile()
    raw = p.to_bytes()
    # version 2 without its bounds section, version 1 with one
    with pytest.raises(csdf.BytecodeError, match="bounds needs 48 bytes"):
        csdf.Program.from_bytes(_with_crc(raw[:-4 - 48]))
    v1 = bytearray(raw[:-4])
    struct.pack_into("<H", v1, 4, 1)
    with pytest.raises(csdf.BytecodeError, match="48 unexpected trailing bytes"):
        csdf.Program.from_bytes(_with_crc(bytes(v1)))
    bad = bytearray(raw[:-4])
    struct.pack_into("<H", bad, 4, 4)
    with pytest.raises(csdf.BytecodeError, match="unsupported version 4 .*reads 1 and 2 and 3"):
        csdf.Program.from_bytes(_with_crc(bytes(bad)))
    text = p.disassemble()
    lines = text.splitlines()
    assert lines[4].startswith("bounds ")
    lines[4] = "bounds 0 0 0 1 1"
    with pytest.raises(csdf.BytecodeError, match="line 5: bounds of a 3D program are 6"):
        csdf.Program.from_text("\n".join(lines))
    lines[4] = "bounds 0 0 0 1 1 one"
    with pytest.raises(csdf.BytecodeError, match="line 5: 'one' is not a number"):
        csdf.Program.from_text("\n".join(lines))


def test_one_slot_limit():
    assert tape.MAX_SLOTS is csdf.layout.MAX_SLOTS
    assert binary.MAX_SLOTS is csdf.layout.MAX_SLOTS
