"""Binary bytecode: encoding, decoding and validation (format v3, ``docs/bytecode.md``).

Layout (little-endian)::

    header   32 bytes  magic "CSDF", u16 version, u16 flags, u16 n_params, u16 n_consts,
                       u16 n_regs, u16 output slot, u32 n_instr, u32 n_calls, f64 lipschitz
    params   n_params x (u8 name length, UTF-8 name, f64 default, f64 lo, f64 hi)
    consts   n_consts x f64
    code     n_instr x 8 bytes: u8 opcode, u8 reserved (0), u16 dst, u16 a, u16 b
    calls    n_calls x (u8 name length, name, u32 out instruction, u16 n_in, n_in x u32)
    bounds   version 2, and version 3 with flag 8: dim x f64 lo, then dim x f64 hi
    data     version 3 with flag 16: u32 n_blocks, then per block u8 kind (1: a closed
             triangle mesh), u32 n_vertices, u32 n_triangles, n_vertices x 3 f64,
             n_triangles x 3 u32 (vertex indices, oriented outwards)
    colors   version 3 with flag 32: u32 K, K x 4 f64 palette (RGBA; NaN rows for
             uncoloured parts), u32 n_bytes, the colour program's own bytecode (a
             version 1-3 program without colours); or, for colours that vary
             continuously (blends, colour fields), u32 0 (no palette), u8 5, then five
             times u32 n_bytes and a channel program's bytecode (r, g, b, a, u)
    crc32    u32 of everything before it

Version 2 added the bounds section, version 3 the data blocks of mesh calls and the
colour section. A program with either is written as version 3 (flags 8, 16 and 32 say
which of bounds, data and colours it holds); one without, with bounds, as version 2;
one with neither as version 1, byte for byte what earlier csdf wrote, so each program
has one encoding. All three versions are read (version 1 gives ``bounds=None``).

:func:`decode_fields` checks every field and raises :class:`~csdf.BytecodeError` naming
the byte offset; :func:`validate` checks a program built from them (every operand refers
to a slot written before it is read), so a program :meth:`csdf.Program.from_bytes`
returns is safe to evaluate. The codecs read a program through its attributes and
return :class:`~csdf.Program` keyword arguments, so that they need not import the
program module (which calls them).
"""

from __future__ import annotations

import math
import re
import struct
import zlib
from typing import Any

import numpy as np

from ..errors import BytecodeError, CsdfError
from ..expr import RESERVED_PARAM_NAMES, Param
from ..layout import COLOR_CHANNELS, MAX_PARAMS, MAX_SLOTS
from ..meshdata import MAX_TRIANGLES, MeshData
from ..ops import ARG_CODE, MESH_CODE, OPS_BY_CODE
from .calls import INSTR_REF, Call

__all__ = ["encode", "decode_fields", "validate", "VERSION", "VERSIONS", "MAGIC",
           "MAX_SLOTS"]

MAGIC = b"CSDF"
#: the newest format version (written for programs with bounds)
VERSION = 3
#: the versions :func:`decode` reads
VERSIONS = (1, 2, 3)
#: the version that has the bounds section
_BOUNDS_VERSION = 2
#: the version that has data blocks (and flags the bounds section)
_DATA_VERSION = 3
#: flags (version 3): the bounds, data and colour sections are present
FLAG_BOUNDS = 8
FLAG_DATA = 16
FLAG_COLORS = 32
#: the most palette entries (coloured nodes and uncoloured leaves) of a program
MAX_PALETTE = 1_000_000
#: data block kind: a closed triangle mesh
MESH_BLOCK = 1
HEADER = struct.Struct("<4sHHHHHHIId")
INSTR = struct.Struct("<BBHHH")
EXACTNESS_CODES = {"exact": 0, "bound": 1, "neither": 2}
EXACTNESS_NAMES = {v: k for k, v in EXACTNESS_CODES.items()}
FLAG_DIM2 = 4
_IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
#: inputs a call record can list (its count is a u16)
MAX_CALL_INPUTS = 0xFFFF


def encode(prog: Any) -> bytes:
    """Serialise a :class:`csdf.Program` (see the module docstring for the layout)."""
    flags = EXACTNESS_CODES[prog.exactness] | (FLAG_DIM2 if prog.dim == 2 else 0)
    data = getattr(prog, "data", ())
    colors = getattr(prog, "colors", None)
    if data or colors is not None:
        version = _DATA_VERSION
        flags |= (FLAG_BOUNDS if prog.bounds is not None else 0) | \
            (FLAG_DATA if data else 0) | (FLAG_COLORS if colors is not None else 0)
    else:
        version = 1 if prog.bounds is None else _BOUNDS_VERSION
    out = bytearray(
        HEADER.pack(
            MAGIC, version, flags, len(prog.params), len(prog.consts), prog.n_regs,
            prog.output, len(prog.code), len(prog.calls), prog.lipschitz,
        )
    )
    for p in prog.params:
        name = p.name.encode()
        out += struct.pack("<B", len(name)) + name + struct.pack("<ddd", p.default, p.lo, p.hi)
    out += prog.consts.astype("<f8").tobytes()
    for op, dst, a, b in prog.code.tolist():
        out += INSTR.pack(op, 0, dst, a, b)
    for c in prog.calls:
        name = c.name.encode()
        out += struct.pack("<B", len(name)) + name + struct.pack("<IH", c.out, len(c.inputs))
        out += struct.pack(f"<{len(c.inputs)}I", *c.inputs)
    if prog.bounds is not None:
        out += prog.bounds.astype("<f8").tobytes()  # row-major: lo, then hi
    if data:
        out += struct.pack("<I", len(data))
        for block in data:
            out += struct.pack("<BII", MESH_BLOCK, len(block.vertices), len(block.faces))
            out += block.vertices.astype("<f8").tobytes()
            out += block.faces.astype("<u4").tobytes()
    if colors is not None:
        cprog, palette = colors
        if palette is None:  # five channel programs
            out += struct.pack("<IB", 0, len(cprog))
            for channel in cprog:
                inner = encode(channel)
                out += struct.pack("<I", len(inner)) + inner
        else:
            inner = encode(cprog)
            out += struct.pack("<I", len(palette)) + np.asarray(palette, "<f8").tobytes()
            out += struct.pack("<I", len(inner)) + inner
    out += struct.pack("<I", zlib.crc32(out) & 0xFFFFFFFF)
    return bytes(out)


class _Reader:
    def __init__(self, data: bytes):
        self.data = data
        self.pos = 0

    def take(self, n: int, what: str) -> bytes:
        if n < 0 or self.pos + n > len(self.data):
            raise BytecodeError(
                f"truncated at byte {self.pos}: {what} needs {n} bytes, "
                f"{len(self.data) - self.pos} left"
            )
        b = self.data[self.pos:self.pos + n]
        self.pos += n
        return b

    def unpack(self, fmt: str, what: str):
        s = struct.calcsize(fmt)
        return struct.unpack(fmt, self.take(s, what))

    def name(self, what: str) -> str:
        at = self.pos
        (n,) = self.unpack("<B", f"{what} length")
        raw = self.take(n, what)
        try:
            s = raw.decode("utf-8")
        except UnicodeDecodeError:
            raise BytecodeError(f"byte {at}: {what} is not valid UTF-8") from None
        if not _IDENT.fullmatch(s):
            raise BytecodeError(f"byte {at}: {what} {s!r} is not an identifier")
        return s


def decode_fields(data: bytes) -> dict[str, Any]:
    """Parse bytecode into :class:`csdf.Program` keyword arguments.

    Raises :class:`BytecodeError` on any flaw of the bytes; pass the program built from
    the result to :func:`validate` for the checks of its contents.
    """
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise BytecodeError(f"bytecode must be bytes, got {type(data).__name__}")
    data = bytes(data)
    if len(data) < HEADER.size + 4:
        raise BytecodeError(
            f"too short: {len(data)} bytes, a program has at least {HEADER.size + 4}"
        )
    if data[:4] != MAGIC:
        raise BytecodeError(f"byte 0: bad magic {data[:4]!r}, expected {MAGIC!r}")
    (crc,) = struct.unpack("<I", data[-4:])
    if zlib.crc32(data[:-4]) & 0xFFFFFFFF != crc:
        raise BytecodeError(f"byte {len(data) - 4}: checksum mismatch (corrupt or truncated)")
    r = _Reader(data[:-4])
    (_, version, flags, n_params, n_consts, n_regs, output, n_instr, n_calls,
     lipschitz) = HEADER.unpack(r.take(HEADER.size, "header"))
    if version not in VERSIONS:
        known = " and ".join(str(v) for v in VERSIONS)
        raise BytecodeError(f"byte 4: unsupported version {version} (this csdf reads {known})")
    allowed = 3 | FLAG_DIM2 | (FLAG_BOUNDS | FLAG_DATA | FLAG_COLORS
                               if version == _DATA_VERSION else 0)
    if version == _DATA_VERSION and not flags & (FLAG_DATA | FLAG_COLORS):
        raise BytecodeError("byte 6: a version-3 program holds data or colours (flag 16 "
                            "or 32); one with neither is written as version 1 or 2")
    if flags & ~allowed or (flags & 3) == 3:
        raise BytecodeError(f"byte 6: invalid flags 0x{flags:04x}")
    params = []
    for i in range(n_params):
        name = r.name(f"parameter {i} name")
        d, lo, hi = r.unpack("<ddd", f"parameter {name!r} values")
        params.append(Param(name, d, lo, hi))
    consts = np.frombuffer(r.take(8 * n_consts, "constant pool"), dtype="<f8").astype(np.float64)
    raw = r.take(INSTR.size * n_instr, "instructions")
    code = np.zeros((n_instr, 4), dtype=np.int64)
    reserved = []
    for k in range(n_instr):
        op, res, dst, a, b = INSTR.unpack_from(raw, k * INSTR.size)
        code[k] = (op, dst, a, b)
        reserved.append(res)
    if any(reserved):
        k = next(i for i, v in enumerate(reserved) if v)
        raise BytecodeError(f"instruction {k}: reserved byte must be 0")
    calls = []
    for i in range(n_calls):
        name = r.name(f"call {i} name")
        out, n_in = r.unpack("<IH", f"call {i} header")
        inputs = r.unpack(f"<{n_in}I", f"call {i} inputs")
        calls.append(Call(name, out, tuple(inputs)))
    dim = 2 if flags & FLAG_DIM2 else 3
    bounds = None
    if version == _BOUNDS_VERSION or flags & FLAG_BOUNDS:
        raw_box = r.take(16 * dim, "bounds")
        bounds = np.frombuffer(raw_box, dtype="<f8").astype(np.float64).reshape(2, dim)
    data = []
    if version == _DATA_VERSION and flags & FLAG_DATA:
        at = r.pos
        (n_blocks,) = r.unpack("<I", "data block count")
        if not 1 <= n_blocks <= max(n_instr, 1):
            raise BytecodeError(f"byte {at}: {n_blocks} data blocks for {n_instr} "
                                "instructions")
        for i in range(n_blocks):
            at = r.pos
            kind, nv, nt = r.unpack("<BII", f"data block {i} header")
            if kind != MESH_BLOCK:
                raise BytecodeError(f"byte {at}: data block {i} has unknown kind {kind}")
            if nt > MAX_TRIANGLES or nv > 3 * MAX_TRIANGLES:
                raise BytecodeError(f"byte {at}: data block {i} has {nt} triangles and "
                                    f"{nv} vertices (at most {MAX_TRIANGLES} triangles)")
            V = np.frombuffer(r.take(24 * nv, f"data block {i} vertices"), dtype="<f8")
            T = np.frombuffer(r.take(12 * nt, f"data block {i} triangles"), dtype="<u4")
            try:
                block = MeshData(V.reshape(nv, 3), T.reshape(nt, 3).astype(np.int64))
            except CsdfError as exc:
                raise BytecodeError(f"byte {at}: data block {i}: {exc}") from None
            data.append(block)
    colors = None
    if version == _DATA_VERSION and flags & FLAG_COLORS:
        at = r.pos
        (k,) = r.unpack("<I", "palette size")
        if k == 0:  # channel programs
            (c,) = r.unpack("<B", "channel count")
            if c != COLOR_CHANNELS:
                raise BytecodeError(f"byte {at}: {c} colour channels (expected "
                                    f"{COLOR_CHANNELS})")
            colors = (tuple(_colour_program(r, f"colour channel {i}")
                            for i in range(c)), None)
        else:
            if k > MAX_PALETTE:
                raise BytecodeError(f"byte {at}: a palette of {k} colours (1 to "
                                    f"{MAX_PALETTE})")
            palette = np.frombuffer(r.take(32 * k, "palette"), dtype="<f8").astype(
                np.float64).reshape(k, 4)
            bad = _bad_palette_row(palette)
            if bad is not None:
                raise BytecodeError(f"byte {at}: palette colour {bad} is not RGBA in [0, 1]")
            colors = (_colour_program(r, "colour program"), palette)
    if r.pos != len(r.data):
        raise BytecodeError(f"byte {r.pos}: {len(r.data) - r.pos} unexpected trailing bytes")
    return dict(
        params=tuple(params), consts=consts, code=code, output=output, n_regs=n_regs,
        dim=dim, exactness=EXACTNESS_NAMES[flags & 3],
        lipschitz=lipschitz, calls=tuple(calls), bounds=bounds, data=tuple(data),
        colors=colors,
    )


def _bad_palette_row(palette: np.ndarray) -> int | None:
    """The first palette row that is neither all NaN (uncoloured) nor RGBA in [0, 1]."""
    ok = np.isnan(palette).all(axis=1) | ((palette >= 0) & (palette <= 1)).all(axis=1)
    return None if ok.all() else int(np.argmin(ok))


def _colour_program(r: Any, what: str) -> dict:
    """The fields of a colour section's program (u32 size, then its bytecode)."""
    (n,) = r.unpack("<I", f"{what} size")
    at = r.pos
    inner = r.take(n, what)
    try:
        fields = decode_fields(inner)
    except BytecodeError as exc:
        raise BytecodeError(f"byte {at}: the {what}: {exc}") from None
    if fields["colors"] is not None or fields["data"]:
        raise BytecodeError(f"byte {at}: the {what} holds its own colours or mesh data")
    return fields


def validate(prog: Any) -> None:
    """Check a :class:`csdf.Program`'s internal consistency; raise
    :class:`BytecodeError` if broken."""
    if len(prog.params) > MAX_PARAMS:
        raise BytecodeError(f"the program has {len(prog.params)} parameters, more than "
                            f"{MAX_PARAMS}")
    seen = set()
    for p in prog.params:
        if not _IDENT.fullmatch(p.name) or p.name in RESERVED_PARAM_NAMES:
            raise BytecodeError(f"parameter name {p.name!r} is not allowed")
        if len(p.name.encode()) > 255:
            raise BytecodeError(f"parameter name {p.name[:20]!r}... is longer than 255 bytes")
        if p.name in seen:
            raise BytecodeError(f"parameter {p.name!r} appears twice")
        seen.add(p.name)
        if not math.isfinite(p.default) or math.isnan(p.lo) or math.isnan(p.hi):
            raise BytecodeError(f"parameter {p.name!r}: default/bounds are not numbers")
        if not p.lo <= p.default <= p.hi:
            raise BytecodeError(f"parameter {p.name!r}: default outside [lo, hi]")
    if [p.name for p in prog.params] != sorted(p.name for p in prog.params):
        raise BytecodeError("parameters must be sorted by name")
    n_fixed = prog.n_fixed
    n_slots = prog.n_slots
    if n_slots > MAX_SLOTS:
        raise BytecodeError(f"{n_slots} slots exceed the limit of {MAX_SLOTS}")
    if math.isnan(prog.lipschitz) or prog.lipschitz < 0:
        raise BytecodeError(f"lipschitz bound {prog.lipschitz} is not a non-negative number")
    if prog.bounds is not None and np.shape(prog.bounds) != (2, prog.dim):
        raise BytecodeError(
            f"bounds have shape {np.shape(prog.bounds)}; a {prog.dim}D program needs "
            f"(2, {prog.dim})"
        )
    written = set()
    rows = prog.code.tolist()
    data = getattr(prog, "data", ())
    for k, (op, dst, a, b) in enumerate(rows):
        if op == ARG_CODE:
            if k == 0 or rows[k - 1][0] != MESH_CODE:
                raise BytecodeError(f"instruction {k}: a mesh argument row must follow a "
                                    "mesh call")
            continue
        if op == MESH_CODE:
            if k + 1 >= len(rows) or rows[k + 1][0] != ARG_CODE or rows[k + 1][1] != dst:
                raise BytecodeError(f"instruction {k}: a mesh call must be followed by "
                                    "its argument row (same destination)")
            block = rows[k + 1][3]
            if not 0 <= block < len(data):
                raise BytecodeError(f"instruction {k}: mesh call reads data block {block}; "
                                    f"the program has {len(data)}")
            operands = (("a", a), ("b", b), ("c", rows[k + 1][2]))
        else:
            info = OPS_BY_CODE.get(op)
            if info is None:
                raise BytecodeError(f"instruction {k}: unknown opcode {op}")
            operands = (("a", a), ("b", b)) if info.arity == 2 else (("a", a),)
            if info.arity == 1 and b != 0:
                raise BytecodeError(f"instruction {k}: unary op {info.name} has operand "
                                    f"b = {b}")
        if not n_fixed <= dst < n_slots:
            raise BytecodeError(f"instruction {k}: destination slot {dst} is not a register")
        for name, s in operands:
            if not 0 <= s < n_slots:
                raise BytecodeError(f"instruction {k}: operand {name} slot {s} out of range")
            if s >= n_fixed and s not in written:
                raise BytecodeError(f"instruction {k}: operand {name} reads register "
                                    f"r{s - n_fixed} before it is written")
        written.add(dst)
    if not 0 <= prog.output < n_slots or (prog.output >= n_fixed and prog.output not in written):
        raise BytecodeError(f"output slot {prog.output} is never written")
    used = max(written) - n_fixed + 1 if written else 0
    if prog.n_regs != used:
        raise BytecodeError(
            f"register count {prog.n_regs} does not match the registers written ({used})"
        )
    if len(prog.code) >= 2**32 or len(prog.calls) >= 2**32:
        raise BytecodeError("too many instructions or calls")
    if prog.dim == 2 and any(2 in prog.operands(k) for k in range(len(rows))):
        raise BytecodeError("a 2D program reads z")
    if len(data) and any(not isinstance(d, MeshData) for d in data):
        raise BytecodeError("a program's data blocks must be MeshData")
    colors = getattr(prog, "colors", None)
    if colors is not None:
        cprog, palette = colors
        if palette is None:
            if not isinstance(cprog, tuple) or len(cprog) != COLOR_CHANNELS:
                raise BytecodeError(f"colours without a palette are {COLOR_CHANNELS} "
                                    "channel programs")
            programs = cprog
        else:
            if np.shape(palette) != (np.shape(palette)[0], 4) or not len(palette):
                raise BytecodeError("the palette must be (K, 4) RGBA rows")
            bad = _bad_palette_row(palette)
            if bad is not None:
                raise BytecodeError(f"palette colour {bad} is not RGBA in [0, 1]")
            programs = (cprog,)
        for p in programs:
            validate(p)
            if p.dim != prog.dim:
                raise BytecodeError("a colour program must have the program's dimension")
    used_blocks = {rows[k][3] for k in range(len(rows)) if rows[k][0] == ARG_CODE}
    if used_blocks != set(range(len(data))):
        raise BytecodeError(f"the program has {len(data)} data blocks but its mesh calls "
                            f"read {len(used_blocks)}")
    n_instr = len(prog.code)
    for i, c in enumerate(prog.calls):
        if not _IDENT.fullmatch(c.name) or len(c.name.encode()) > 255:
            raise BytecodeError(f"call {i}: bad name {c.name[:40]!r}")
        if len(c.inputs) > MAX_CALL_INPUTS:
            raise BytecodeError(
                f"call {i}: {len(c.inputs)} inputs; at most {MAX_CALL_INPUTS}"
            )
        if not 0 <= c.out < n_instr:
            raise BytecodeError(f"call {i}: output instruction {c.out} out of range")
        for s in c.inputs:
            if s & INSTR_REF:
                if (s & ~INSTR_REF) >= n_instr:
                    raise BytecodeError(
                        f"call {i}: input instruction {s & ~INSTR_REF} out of range"
                    )
            elif s >= n_fixed:
                raise BytecodeError(f"call {i}: input slot {s} is not a fixed slot")
