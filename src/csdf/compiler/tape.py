"""Compile an expression DAG into a linear register tape (:class:`~csdf.Program`).

Steps:

1. build the shape's expression at (x, y, z) (interned: common subexpressions are
   already shared, constants already folded);
2. order the op nodes children-first, with every *uniform* node (one that depends
   only on parameters and constants) before every *varying* one, so evaluators can
   compute the uniform prefix once per call;
3. lay out the slot file (:class:`csdf.layout.SlotLayout`): ``x y z | params (sorted
   by name) | constants (first-use order) | registers``;
4. allocate registers by linear scan (:func:`csdf.compiler.regalloc.linear_scan`): a
   register is freed after its value's last use and reused lowest-first, so the
   register count is the peak number of live values;
5. record the primitive calls (for the paper's primitive-level Table-1 counts) and the
   shape's metadata: exactness, Lipschitz bound and bounding box.
"""

from __future__ import annotations

import math
import struct

import numpy as np

from ..errors import CsdfError
from ..expr import DATA_OPS, Expr, expr_params, walk
from ..layout import MAX_PARAMS, MAX_SLOTS, SlotLayout
from ..ops import ARG_CODE, MESH_CODE, OPS
from .calls import INSTR_REF, Call
from .program import Program
from .regalloc import linear_scan

__all__ = ["compile_shape", "compile_expr", "color_section", "MAX_SLOTS", "MAX_PARAMS"]



def compile_shape(shape) -> Program:
    """Compile a :class:`csdf.Shape` (see :func:`compile_expr`).

    The program carries the shape's exactness, Lipschitz bound and bounds
    (``shape.bounds``, the box of its zero set, or None). ``shape`` is anything with
    ``build()``, ``dim``, ``exactness``, ``lipschitz`` and ``bounds`` (the compiler does
    not import the shapes layer).
    """
    root, ctx = shape.build()
    calls = [(name, out, inputs) for name, out, inputs in ctx.calls.values()]
    prog = compile_expr(
        root, dim=shape.dim, exactness=shape.exactness, lipschitz=shape.lipschitz,
        calls=calls, bounds=shape.bounds,
    )
    rule = ctx.color_rule() if hasattr(ctx, "color_rule") else None
    if rule is not None:
        prog.colors = color_section(rule, shape.dim)
    return prog


def color_section(rule, dim: int = 3) -> tuple:
    """The colour section of a program from a shape's colour rule
    (:class:`csdf.shapes.colorrule.ColorRule`, given duck-typed: ``index``, ``palette``,
    ``channels``): ``(program, palette)`` (the program's value at a point is the row of
    ``palette`` ``(K, 4)`` float64 RGBA, NaN rows for uncoloured surfaces), or
    ``(programs, None)`` with the five channel programs ``r, g, b, a, u`` (colour
    ``(r, g, b, a) + u * default``). See :mod:`csdf.colors`."""
    if rule.index is not None:
        return compile_expr(rule.index, dim=dim, exactness="neither"), rule.palette
    return tuple(compile_expr(c, dim=dim, exactness="neither") for c in rule.channels), None


def compile_expr(
    root: Expr,
    *,
    dim: int = 3,
    exactness: str = "neither",
    lipschitz: float = math.inf,
    calls: list[tuple[str, Expr, tuple[Expr, ...]]] | None = None,
    bounds: np.ndarray | None = None,
) -> Program:
    """Compile an expression over x, y, z into a :class:`Program`.

    Args:
        root: the distance expression.
        dim: 3, or 2 when it uses only x and y.
        exactness, lipschitz: metadata stored with the program.
        calls: primitive invocations ``(name, output node, input nodes)``.
        bounds: ``(2, dim)`` ``[lo, hi]`` box of the zero set (model units), or None
            when unbounded or unknown; stored with the program.

    Raises:
        CsdfError: the program would need more than :data:`csdf.layout.MAX_SLOTS` slots,
            or it has more than :data:`MAX_PARAMS` parameters.
    """
    params = expr_params(root)
    if len(params) > MAX_PARAMS:
        raise CsdfError(
            f"the model has {len(params)} parameters, more than {MAX_PARAMS} parameters "
            "are not supported (the parameter Jacobian grows as their square); make the "
            "values that need not vary constants"
        )
    order = list(walk(root))
    uniform: dict[int, bool] = {}
    for n in order:
        if n.op in ("x", "y", "z"):
            uniform[id(n)] = False
        elif n.op in ("const", "param"):
            uniform[id(n)] = True
        elif n.op in DATA_OPS:
            uniform[id(n)] = False  # a mesh call runs with the points (never folded)
        else:
            uniform[id(n)] = all(uniform[id(a)] for a in n.args)
    ops = [n for n in order if n.op in OPS or n.op in DATA_OPS]
    sched = [n for n in ops if uniform[id(n)]] + [n for n in ops if not uniform[id(n)]]

    param_index = {p.name: i for i, p in enumerate(params)}
    consts: list[float] = []
    const_index: dict[bytes, int] = {}

    def note_const(n: Expr) -> None:
        if n.op == "const":
            bits = struct.pack("<d", n.value)
            if bits not in const_index:
                const_index[bits] = len(consts)
                consts.append(float(n.value))  # type: ignore[arg-type]

    # constants in first-use order: instructions, then output, then call inputs
    for n in sched:
        for a in n.args:
            note_const(a)
    note_const(root)
    for _, _out, inputs in calls or ():
        for e in inputs:
            note_const(e)

    # linear-scan register allocation
    index = {id(n): i for i, n in enumerate(sched)}
    reads = [[index[id(a)] for a in n.args if a.op in OPS or a.op in DATA_OPS]
             for n in sched]
    regs, n_regs = linear_scan(reads, [index[id(root)]] if id(root) in index else ())
    layout = SlotLayout(len(params), len(consts), n_regs)
    if layout.n_slots > MAX_SLOTS:
        raise CsdfError(
            f"the program needs {layout.n_slots} slots; at most {MAX_SLOTS} are supported"
        )

    def fixed(n: Expr) -> int | None:
        """The fixed slot of a leaf (None for an op node)."""
        if n.op in ("x", "y", "z"):
            return "xyz".index(n.op)
        if n.op == "param":
            return layout.param(param_index[n.value.name])  # type: ignore[union-attr]
        if n.op == "const":
            return layout.const(const_index[struct.pack("<d", n.value)])
        return None

    def slot(n: Expr) -> int:
        f = fixed(n)
        return f if f is not None else layout.reg(regs[index[id(n)]])

    # the data blocks (meshes) in first-use order; a mesh call takes two rows
    data: list = []
    data_index: dict[str, int] = {}
    row_of: list[int] = []
    rows: list[tuple[int, int, int, int]] = []
    for i, n in enumerate(sched):
        row_of.append(len(rows))
        operands = [slot(a) for a in n.args]
        dst = layout.reg(regs[i])
        if n.op in DATA_OPS:
            k = data_index.get(n.value.digest)  # type: ignore[union-attr]
            if k is None:
                k = data_index[n.value.digest] = len(data)  # type: ignore[union-attr]
                data.append(n.value)
            rows.append((MESH_CODE, dst, operands[0], operands[1]))
            rows.append((ARG_CODE, dst, operands[2], k))
            continue
        info = OPS[n.op]
        rows.append((info.code, dst, operands[0], operands[1] if info.arity == 2 else 0))
    code = np.array(rows, dtype=np.int64).reshape(-1, 4)

    def source(e: Expr) -> int | None:
        f = fixed(e)
        if f is not None:
            return f
        i = index.get(id(e))
        return None if i is None else INSTR_REF | row_of[i]

    call_list: list[Call] = []
    for name, out, inputs in calls or ():
        i = index.get(id(out))
        if i is None:
            continue
        srcs = tuple(s for s in (source(e) for e in inputs) if s is not None)
        call_list.append(Call(name, row_of[i], srcs))
    call_list.sort(key=lambda c: c.out)
    return Program(
        params=tuple(params),
        consts=np.array(consts, dtype=np.float64),
        code=code,
        output=slot(root),
        n_regs=n_regs,
        dim=dim,
        exactness=exactness,
        lipschitz=lipschitz,
        calls=tuple(call_list),
        bounds=bounds,
        data=tuple(data),
    )
