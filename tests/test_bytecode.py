"""Binary and text bytecode: round trips, layout, and validation errors."""

from __future__ import annotations

import struct
import zlib

import numpy as np
import pytest

import csdf


def _sample():
    r = csdf.param("r", 0.8, 0.5, 1.2)
    return csdf.union(csdf.sphere(r), csdf.box(1.0).twist(0.5), k=0.1)


def test_round_trips_are_identical():
    p = _sample().compile()
    b = p.to_bytes()
    q = csdf.Program.from_bytes(b)
    assert q.to_bytes() == b and q == p
    t = csdf.Program.from_text(p.disassemble())
    assert t.to_bytes() == b
    pts = np.random.default_rng(0).uniform(-1, 1, (300, 3))
    for prog in (q, t):
        np.testing.assert_array_equal(prog(pts), p(pts))
        np.testing.assert_array_equal(prog.param_jacobian(pts), p.param_jacobian(pts))
    assert q.params == p.params and q.exactness == p.exactness and q.lipschitz == p.lipschitz


def test_instructions_are_eight_bytes_and_header_is_documented():
    p = csdf.sphere(1.0).compile()
    b = p.to_bytes()
    magic, version, flags, n_p, n_c, n_r, out, n_i, n_calls, lip = struct.unpack_from(
        "<4sHHHHHHIId", b)
    # a program with bounds is format version 2: the bounds section follows the calls
    assert (magic, version, flags, n_p, n_c, n_i, n_calls) == (b"CSDF", 2, 0, 0, 1, 7, 1)
    assert lip == 1.0 and out == 3 + 0 + 1 + 0
    assert len(b) == 32 + 8 + 7 * 8 + (1 + 6 + 4 + 2 + 4 * 4) + 2 * 3 * 8 + 4
    box = np.frombuffer(b[-4 - 48:-4], dtype="<f8").reshape(2, 3)
    np.testing.assert_array_equal(box, [[-1.0] * 3, [1.0] * 3])
    np.testing.assert_array_equal(p.bounds, box)
    # without bounds: version 1, the layout earlier csdf wrote, byte for byte
    b1 = p.with_bounds(None).to_bytes()
    magic, version, flags, n_p, n_c, n_r, out, n_i, n_calls, lip = struct.unpack_from(
        "<4sHHHHHHIId", b1)
    assert (magic, version, flags, n_p, n_c, n_i, n_calls) == (b"CSDF", 1, 0, 0, 1, 7, 1)
    assert len(b1) == 32 + 8 + 7 * 8 + (1 + 6 + 4 + 2 + 4 * 4) + 4
    assert b1[6:-4] == b[6:-4 - 48]


def _recrc(b: bytes) -> bytes:
    return b[:-4] + struct.pack("<I", zlib.crc32(b[:-4]) & 0xFFFFFFFF)


def test_validation_errors_name_the_problem():
    b = bytearray(csdf.sphere(1.0).compile().to_bytes())
    with pytest.raises(csdf.BytecodeError, match="checksum"):
        csdf.Program.from_bytes(bytes(b[:-5]) + b[-4:])
    with pytest.raises(csdf.BytecodeError, match="magic"):
        csdf.Program.from_bytes(b"XXXX" + bytes(b[4:]))
    bad = bytearray(b)
    bad[4] = 9
    with pytest.raises(csdf.BytecodeError, match="version"):
        csdf.Program.from_bytes(_recrc(bytes(bad)))
    code_at = 32 + 8
    bad = bytearray(b)
    bad[code_at] = 200
    with pytest.raises(csdf.BytecodeError, match="instruction 0: unknown opcode 200"):
        csdf.Program.from_bytes(_recrc(bytes(bad)))
    bad = bytearray(b)
    struct.pack_into("<H", bad, code_at + 4, 5)  # instruction 0 reads r1, written later
    with pytest.raises(csdf.BytecodeError, match="before it is written"):
        csdf.Program.from_bytes(_recrc(bytes(bad)))
    with pytest.raises(csdf.BytecodeError, match="trailing"):
        csdf.Program.from_bytes(_recrc(bytes(b[:-4]) + b"\0\0\0\0" + b"\0\0\0\0"))
    with pytest.raises(csdf.BytecodeError, match="too short"):
        csdf.Program.from_bytes(b"CSDF")
    with pytest.raises(csdf.BytecodeError, match="must be bytes"):
        csdf.Program.from_bytes("CSDF")


def test_text_errors_name_the_line():
    good = csdf.sphere(1.0).compile().disassemble()
    with pytest.raises(csdf.BytecodeError, match="line 1"):
        csdf.Program.from_text("hello")
    lines = good.splitlines()
    lines[6] = "r0 = frobnicate y"
    with pytest.raises(csdf.BytecodeError, match="line 7: unknown op 'frobnicate'"):
        csdf.Program.from_text("\n".join(lines))
    lines = good.splitlines()
    lines[6] = "r0 = square $nope"
    with pytest.raises(csdf.BytecodeError, match="line 7: unknown operand"):
        csdf.Program.from_text("\n".join(lines))
    with pytest.raises(csdf.BytecodeError, match="missing 'output'"):
        csdf.Program.from_text("\n".join(x for x in good.splitlines() if "output" not in x))


def test_2d_program_round_trip():
    p = csdf.polygon([(0, 0), (1, 0), (0.5, 1)]).compile()
    q = csdf.Program.from_bytes(p.to_bytes())
    assert q.dim == 2
    np.testing.assert_array_equal(q(np.array([[0.5, 0.2]])), p(np.array([[0.5, 0.2]])))
