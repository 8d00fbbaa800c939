"""Compile an expression DAG into a linear register tape (:class:`~csdf.Program`).

Steps:

1. build the shape's expression at (x, y, z) (interned: common subexpressions are
   already shared, constants already folded);
2. order the op nodes children-first, with every *uniform* node (one that depends
   only on parameters and constants) before every *varying* one, so evaluators can
   compute the uniform prefix once per call;
3. lay out the slot file: ``x y z | params (sorted by name) | constants (first-use
   order) | registers``;
4. allocate registers by linear scan: a register is freed after its value's last use
   and reused lowest-first, so the register count is the peak number of live values;
5. record the primitive calls (for the paper's primitive-level Table-1 counts).
"""

from __future__ import annotations

import heapq
import math
import struct

import numpy as np

from ..errors import CsdfError
from ..expr import Expr, expr_params, walk
from ..ops import OPS
from .program import Call, Program

__all__ = ["compile_shape", "compile_expr", "MAX_SLOTS"]

MAX_SLOTS = 65535
INSTR_REF = 0x80000000


def compile_shape(shape) -> Program:
    """Compile a :class:`csdf.Shape` (see :func:`compile_expr`)."""
    root, ctx = shape.build()
    calls = [(name, out, inputs) for name, out, inputs in ctx.calls.values()]
    return compile_expr(
        root, dim=shape.dim, exactness=shape.exactness, lipschitz=shape.lipschitz, calls=calls
    )


def compile_expr(
    root: Expr,
    *,
    dim: int = 3,
    exactness: str = "neither",
    lipschitz: float = math.inf,
    calls: list[tuple[str, Expr, tuple[Expr, ...]]] | None = None,
) -> Program:
    """Compile an expression over x, y, z into a :class:`Program`.

    Args:
        root: the distance expression.
        dim: 3, or 2 when it uses only x and y.
        exactness, lipschitz: metadata stored with the program.
        calls: primitive invocations ``(name, output node, input nodes)``.

    Raises:
        CsdfError: the program would need more than 65535 slots.
    """
    params = expr_params(root)
    order = list(walk(root))
    uniform: dict[int, bool] = {}
    for n in order:
        if n.op in ("x", "y", "z"):
            uniform[id(n)] = False
        elif n.op in ("const", "param"):
            uniform[id(n)] = True
        else:
            uniform[id(n)] = all(uniform[id(a)] for a in n.args)
    ops = [n for n in order if n.op in OPS]
    sched = [n for n in ops if uniform[id(n)]] + [n for n in ops if not uniform[id(n)]]

    n_p = len(params)
    slot: dict[int, int] = {}
    fixed_xyz = {"x": 0, "y": 1, "z": 2}
    pslot = {p.name: 3 + i for i, p in enumerate(params)}
    consts: list[float] = []
    const_index: dict[bytes, int] = {}

    def leaf_slot(n: Expr) -> int | None:
        if n.op in fixed_xyz:
            return fixed_xyz[n.op]
        if n.op == "param":
            return pslot[n.value.name]  # type: ignore[union-attr]
        if n.op == "const":
            bits = struct.pack("<d", n.value)
            j = const_index.get(bits)
            if j is None:
                j = const_index[bits] = len(consts)
                consts.append(float(n.value))  # type: ignore[arg-type]
            return -1 - j  # placeholder: final slot known once all constants are seen
        return None

    # constants in first-use order: instructions, then output, then call inputs
    for n in sched:
        for a in n.args:
            leaf_slot(a)
    leaf_slot(root)
    for _, _out, inputs in calls or ():
        for e in inputs:
            leaf_slot(e)
    n_fixed = 3 + n_p + len(consts)

    def fixed(n: Expr) -> int | None:
        s = leaf_slot(n)
        if s is None:
            return None
        return s if s >= 0 else 3 + n_p + (-1 - s)

    # linear-scan register allocation
    index = {id(n): i for i, n in enumerate(sched)}
    last_use: dict[int, int] = {}
    for i, n in enumerate(sched):
        for a in n.args:
            last_use[id(a)] = i
    last_use[id(root)] = len(sched)
    free: list[int] = []
    n_regs = 0
    code = np.zeros((len(sched), 4), dtype=np.int64)
    for i, n in enumerate(sched):
        operands = []
        for a in n.args:
            f = fixed(a)
            operands.append(f if f is not None else slot[id(a)])
        for a in {id(a): a for a in n.args}.values():
            if a.op in OPS and last_use[id(a)] == i:
                heapq.heappush(free, slot[id(a)] - n_fixed)
        if free:
            r = heapq.heappop(free)
        else:
            r = n_regs
            n_regs += 1
        slot[id(n)] = n_fixed + r
        info = OPS[n.op]
        code[i] = (info.code, n_fixed + r, operands[0], operands[1] if info.arity == 2 else 0)
    if n_fixed + n_regs > MAX_SLOTS:
        raise CsdfError(
            f"the program needs {n_fixed + n_regs} slots; at most {MAX_SLOTS} are supported"
        )
    out_slot = fixed(root)
    if out_slot is None:
        out_slot = slot[id(root)]

    def source(e: Expr) -> int | None:
        f = fixed(e)
        if f is not None:
            return f
        i = index.get(id(e))
        return None if i is None else INSTR_REF | i

    call_list: list[Call] = []
    for name, out, inputs in calls or ():
        i = index.get(id(out))
        if i is None:
            continue
        srcs = tuple(s for s in (source(e) for e in inputs) if s is not None)
        call_list.append(Call(name, i, srcs))
    call_list.sort(key=lambda c: c.out)
    return Program(
        params=tuple(params),
        consts=np.array(consts, dtype=np.float64),
        code=code,
        output=out_slot,
        n_regs=n_regs,
        dim=dim,
        exactness=exactness,
        lipschitz=lipschitz,
        calls=tuple(call_list),
    )
