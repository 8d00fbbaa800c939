"""Text form of a program: a readable listing that assembles back to the same program.

Example (a sphere of parameter radius ``r`` in ``[0.5, 2]``)::

    csdf-program 1
    dim 3
    exactness exact
    lipschitz 1.0
    bounds -2.0 -2.0 -2.0 2.0 2.0 2.0
    param r 1.0 0.5 2.0
    r0 = square y
    r1 = square x
    r0 = add r0 r1
    r1 = square z
    r0 = add r0 r1
    r0 = sqrt r0
    r0 = sub r0 $r
    output r0
    call sphere @6 x y z $r

Header lines: ``dim``, ``exactness``, ``lipschitz`` and, for a program with bounds,
``bounds`` (the box of the zero set: ``dim`` numbers lo, then ``dim`` numbers hi; a
listing without it, as older csdf wrote them, gives ``bounds=None``). Operands: ``x y
z``, ``$name`` (parameter), ``c<k>`` (constant ``k``, declared by a ``const c<k>
<value>`` line), ``r<k>`` (register). In ``call`` lines ``@i`` is the result of
instruction ``i``. Floats are written with ``repr`` so they round-trip exactly (a NaN
as ``nan:0x<16 hex digits>``, its bit pattern). Comments start with ``;``.

A mesh call is one line, ``r0 = mesh d0 x y z`` (the signed distance to data block
``d0`` at the three operands), and two instructions of the tape (so ``@i`` counts it
twice). Its data block is listed before the instructions as ``data d0 mesh <vertices>
<triangles>``, then one ``v <x> <y> <z>`` line per vertex and one ``f <i> <j> <k>``
line per triangle.
"""

from __future__ import annotations

import math
import re
import struct
from typing import Any

import numpy as np

from ..errors import BytecodeError, CsdfError
from ..expr import Param
from ..layout import COLOR_CHANNELS, MAX_SLOTS, N_COORDS, SlotLayout
from ..meshdata import MeshData
from ..ops import ARG_CODE, MESH_CODE, OPS, OPS_BY_CODE
from .calls import INSTR_REF, Call

__all__ = ["disassemble", "assemble_fields"]

_MAX_LINES = 20_000_000


def _slot_name(layout: SlotLayout, prog: Any, s: int) -> str:
    if s < N_COORDS:
        return "xyz"[s]
    if layout.is_param(s):
        return "$" + prog.params[s - layout.param_base].name
    if layout.is_const(s):
        return f"c{s - layout.const_base}"
    return f"r{s - layout.reg_base}"


def disassemble(prog: Any) -> str:
    """The listing of a :class:`csdf.Program` (see the module docs)."""
    lines = [
        "csdf-program 1",
        f"dim {prog.dim}",
        f"exactness {prog.exactness}",
        f"lipschitz {prog.lipschitz!r}",
    ]
    if prog.bounds is not None:
        lines.append("bounds " + " ".join(_fmt(v) for v in prog.bounds.reshape(-1).tolist()))
    layout = prog.layout
    for p in prog.params:
        lines.append(f"param {p.name} {p.default!r} {p.lo!r} {p.hi!r}")
    for i, c in enumerate(prog.consts.tolist()):
        lines.append(f"const c{i} {_fmt(c)}")
    for i, block in enumerate(getattr(prog, "data", ())):
        lines.append(f"data d{i} mesh {len(block.vertices)} {len(block.faces)}")
        lines += ["v " + " ".join(_fmt(c) for c in row) for row in block.vertices.tolist()]
        lines += [f"f {i} {j} {k}" for i, j, k in block.faces.tolist()]
    rows = prog.code.tolist()
    for k, (op, dst, a, b) in enumerate(rows):
        if op == ARG_CODE:
            continue
        if op == MESH_CODE:
            _, _, c, block = rows[k + 1]
            args = " ".join(_slot_name(layout, prog, s) for s in (a, b, c))
            lines.append(f"{_slot_name(layout, prog, dst)} = mesh d{block} {args}")
            continue
        info = OPS_BY_CODE[op]
        args = [_slot_name(layout, prog, a)]
        if info.arity == 2:
            args.append(_slot_name(layout, prog, b))
        lines.append(f"{_slot_name(layout, prog, dst)} = {info.name} {' '.join(args)}")
    lines.append(f"output {_slot_name(layout, prog, prog.output)}")
    for c in prog.calls:
        ins = [f"@{s & ~INSTR_REF}" if s & INSTR_REF else _slot_name(layout, prog, s)
               for s in c.inputs]
        lines.append(f"call {c.name} @{c.out} {' '.join(ins)}".rstrip())
    colors = getattr(prog, "colors", None)
    if colors is not None:
        cprog, palette = colors
        if palette is None:
            lines.append(f"colors channels {len(cprog)}")
            programs = cprog
        else:
            lines.append(f"colors {len(palette)}")
            lines += ["palette " + " ".join(_fmt(v) for v in row)
                      for row in palette.tolist()]
            programs = (cprog,)
        for p in programs:
            lines.append("colors-program")
            lines += disassemble(p).rstrip("\n").split("\n")
            lines.append("end-colors")
    return "\n".join(lines) + "\n"


def _fmt(v: float) -> str:
    """``repr`` (exact for every finite and infinite float); NaN with its bit pattern."""
    if v != v:
        return "nan:0x" + struct.pack(">d", v).hex()
    return repr(v)


def _float(tok: str, ln: int) -> float:
    m = re.fullmatch(r"nan:0x([0-9a-f]{16})", tok)
    if m:
        v = struct.unpack(">d", bytes.fromhex(m.group(1)))[0]
        if v == v:
            raise BytecodeError(f"line {ln}: {tok!r} is not a NaN bit pattern")
        return v
    if not re.fullmatch(r"[-+]?(inf|nan|(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?)", tok):
        raise BytecodeError(f"line {ln}: {tok!r} is not a number")
    return float(tok)


def assemble_fields(text: str) -> dict[str, Any]:
    """Parse a listing (see module docs) into :class:`csdf.Program` keyword arguments;
    raise :class:`BytecodeError` with the line. :meth:`csdf.Program.from_text` builds
    the program and validates it like a decoded one."""
    if not isinstance(text, str):
        raise BytecodeError(f"a program listing must be text, got {type(text).__name__}")
    raw_lines = text.splitlines()
    if len(raw_lines) > _MAX_LINES:
        raise BytecodeError(f"listing has {len(raw_lines)} lines; at most {_MAX_LINES}")
    header = {"dim": 3, "exactness": "neither", "lipschitz": math.inf}
    bounds_row: tuple[int, list[float]] | None = None
    params: list[Param] = []
    consts: list[float] = []
    code: list[tuple[int, int, int, int]] = []
    reg_rows: list[tuple[int, str, str, str | None]] = []
    output_tok: tuple[int, str] | None = None
    call_rows: list[tuple[int, list[str]]] = []
    data: list[MeshData] = []
    block: tuple[int, int, int, list, list] | None = None  # line, nv, nt, vertices, faces

    def close_block() -> None:
        nonlocal block
        if block is None:
            return
        ln0, nv, nt, vs, fs = block
        if len(vs) != nv or len(fs) != nt:
            raise BytecodeError(f"line {ln0}: data d{len(data)} declares {nv} vertices and "
                                f"{nt} triangles; {len(vs)} and {len(fs)} follow")
        try:
            data.append(MeshData(np.array(vs, dtype=np.float64).reshape(-1, 3),
                                 np.array(fs, dtype=np.int64).reshape(-1, 3)))
        except CsdfError as exc:
            raise BytecodeError(f"line {ln0}: data d{len(data)}: {exc}") from None
        block = None

    seen_magic = False
    palette: list[list[float]] = []
    colors_fields: list[dict] = []
    channels: int | None = None  # 'colors channels N': that many channel programs
    nested: list[str] | None = None  # the colour program's lines while they are read
    nested_at = 0
    for ln, line in enumerate(raw_lines, 1):
        if nested is not None:
            if line.strip() == "end-colors":
                try:
                    colors_fields.append(assemble_fields("\n".join(nested)))
                except BytecodeError as exc:
                    raise BytecodeError(f"line {nested_at}: the colour program: "
                                        f"{exc}") from None
                nested = None
            else:
                nested.append(line)
            continue
        line = line.split(";", 1)[0].strip()
        if not line:
            continue
        toks = line.split()
        if not seen_magic:
            if toks != ["csdf-program", "1"]:
                raise BytecodeError(f"line {ln}: expected 'csdf-program 1'")
            seen_magic = True
            continue
        kw = toks[0]
        if block is not None and kw == "v" and len(toks) == 4:
            block[3].append([_float(t, ln) for t in toks[1:]])
            continue
        if block is not None and kw == "f" and len(toks) == 4:
            if not all(re.fullmatch(r"\d{1,10}", t) for t in toks[1:]):
                raise BytecodeError(f"line {ln}: a triangle is three vertex indices")
            block[4].append([int(t) for t in toks[1:]])
            continue
        close_block()
        if kw == "data" and len(toks) == 5 and toks[2] == "mesh":
            if toks[1] != f"d{len(data)}":
                raise BytecodeError(f"line {ln}: expected data block d{len(data)}, got "
                                    f"{toks[1]}")
            if not all(re.fullmatch(r"\d{1,9}", t) for t in toks[3:]):
                raise BytecodeError(f"line {ln}: data counts must be whole numbers")
            block = (ln, int(toks[3]), int(toks[4]), [], [])
        elif kw == "dim" and len(toks) == 2 and toks[1] in ("2", "3"):
            header["dim"] = int(toks[1])
        elif kw == "exactness" and len(toks) == 2 and toks[1] in ("exact", "bound", "neither"):
            header["exactness"] = toks[1]
        elif kw == "lipschitz" and len(toks) == 2:
            header["lipschitz"] = _float(toks[1], ln)
        elif kw == "bounds":
            bounds_row = (ln, [_float(t, ln) for t in toks[1:]])
        elif kw == "param" and len(toks) == 5:
            params.append(Param(toks[1], *(_float(t, ln) for t in toks[2:])))
        elif kw == "const" and len(toks) == 3:
            if toks[1] != f"c{len(consts)}":
                raise BytecodeError(f"line {ln}: expected constant c{len(consts)}, got {toks[1]}")
            consts.append(_float(toks[2], ln))
        elif kw == "output" and len(toks) == 2:
            output_tok = (ln, toks[1])
        elif kw == "call" and len(toks) >= 3:
            call_rows.append((ln, toks[1:]))
        elif kw == "colors" and len(toks) == 2 and toks[1].isdigit():
            pass  # (the palette lines that follow give the count)
        elif kw == "colors" and len(toks) == 3 and toks[1] == "channels" and \
                toks[2].isdigit():
            channels = int(toks[2])
        elif kw == "palette" and len(toks) == 5:
            palette.append([_float(t, ln) for t in toks[1:]])
        elif kw == "colors-program" and len(toks) == 1:
            nested, nested_at = [], ln
        elif len(toks) == 7 and toks[1] == "=" and toks[2] == "mesh":
            reg_rows.append((ln, toks[0], "mesh", " ".join(toks[3:])))
        elif len(toks) in (4, 5) and toks[1] == "=":
            if toks[2] not in OPS:
                raise BytecodeError(f"line {ln}: unknown op {toks[2]!r}")
            arity = OPS[toks[2]].arity
            if len(toks) != 3 + arity:
                raise BytecodeError(f"line {ln}: {toks[2]} takes {arity} operand(s)")
            reg_rows.append((ln, toks[0], toks[2], " ".join(toks[3:])))
        else:
            raise BytecodeError(f"line {ln}: cannot read {line[:60]!r}")
    close_block()
    if nested is not None:
        raise BytecodeError(f"line {nested_at}: the colour program has no 'end-colors' "
                            "line")
    if channels is not None:
        if palette or len(colors_fields) != channels or channels != COLOR_CHANNELS:
            raise BytecodeError(f"'colors channels' needs {COLOR_CHANNELS} colour programs "
                                "and no palette lines")
    elif len(colors_fields) != (1 if palette else 0):
        raise BytecodeError("a colour program needs its palette lines, and palette lines "
                            "their colour program")
    if not seen_magic:
        raise BytecodeError("line 1: empty listing (expected 'csdf-program 1')")
    layout = SlotLayout(len(params), len(consts))
    pindex = {p.name: layout.param(i) for i, p in enumerate(params)}
    n_fixed = layout.n_fixed

    def slot(tok: str, ln: int) -> int:
        if tok in ("x", "y", "z"):
            return "xyz".index(tok)
        if tok.startswith("$") and tok[1:] in pindex:
            return pindex[tok[1:]]
        m = re.fullmatch(r"c(\d{1,6})", tok)
        if m and int(m.group(1)) < len(consts):
            return layout.const(int(m.group(1)))
        m = re.fullmatch(r"r(\d{1,5})", tok)
        if m:
            return n_fixed + int(m.group(1))
        raise BytecodeError(f"line {ln}: unknown operand {tok!r}")

    n_regs = 0
    for ln, dst_tok, opname, operands in reg_rows:
        if not re.fullmatch(r"r\d{1,5}", dst_tok):
            raise BytecodeError(f"line {ln}: destination must be a register r<k>, got {dst_tok!r}")
        dst = slot(dst_tok, ln)
        n_regs = max(n_regs, dst - n_fixed + 1)
        if opname == "mesh":
            toks = operands.split()
            m = re.fullmatch(r"d(\d{1,6})", toks[0])
            if not m:
                raise BytecodeError(f"line {ln}: a mesh call names its data block d<k>")
            a, b, c = (slot(t, ln) for t in toks[1:])
            code.append((MESH_CODE, dst, a, b))
            code.append((ARG_CODE, dst, c, int(m.group(1))))
            continue
        ops = [slot(t, ln) for t in operands.split()]
        code.append((OPS[opname].code, dst, ops[0], ops[1] if len(ops) > 1 else 0))
    if output_tok is None:
        raise BytecodeError("missing 'output' line")
    output = slot(output_tok[1], output_tok[0])
    calls = []
    for ln, toks in call_rows:
        name = toks[0]
        if not re.fullmatch(r"@\d{1,9}", toks[1]):
            raise BytecodeError(f"line {ln}: call output must be @<instruction>")
        ins = []
        for t in toks[2:]:
            ins.append(INSTR_REF | int(t[1:]) if re.fullmatch(r"@\d{1,9}", t) else slot(t, ln))
        calls.append(Call(name, int(toks[1][1:]), tuple(ins)))
    if n_fixed + n_regs > MAX_SLOTS:
        raise BytecodeError(f"too many slots (limit {MAX_SLOTS})")
    bounds = None
    if bounds_row is not None:
        ln, vals = bounds_row
        dim = int(header["dim"])
        if len(vals) != 2 * dim:
            raise BytecodeError(
                f"line {ln}: bounds of a {dim}D program are {2 * dim} numbers "
                f"({dim} lo, then {dim} hi); got {len(vals)}"
            )
        bounds = np.array(vals, dtype=np.float64).reshape(2, dim)
    try:
        code_arr = np.array(code, dtype=np.int64).reshape(-1, 4)
    except (ValueError, OverflowError) as exc:
        raise BytecodeError(f"invalid program: {exc}") from None
    return dict(
        params=tuple(params), consts=np.array(consts, dtype=np.float64), code=code_arr,
        output=output, n_regs=n_regs, dim=int(header["dim"]),
        exactness=str(header["exactness"]), lipschitz=float(header["lipschitz"]),
        calls=tuple(calls), bounds=bounds, data=tuple(data),
        colors=None if not colors_fields else (tuple(colors_fields), None)
        if channels is not None else (
            colors_fields[0], np.array(palette, dtype=np.float64).reshape(-1, 4)),
    )
