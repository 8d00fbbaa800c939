"""Fidget's ``.vm`` text format in and out: :func:`load_vm` / :func:`loads_vm` (from
:mod:`csdf.lang.vm`, which documents the format and the opcodes) and :func:`save_vm` /
:func:`dumps_vm`.

Writing: the compiled program (the tape) becomes one node per instruction, its
constants ``const`` nodes and the coordinates it reads ``var-x`` / ``var-y`` /
``var-z`` nodes, each written just before its first use; only what the output depends
on is written, and the output is the last node. Names are ``_0, _1, ...`` (hex, as
Fidget writes them). csdf ops are written with Fidget's opcodes (``log`` as ``ln``);
the ones Fidget lacks are written as Fidget ops that compute the same values:

* ``sign(a)`` as ``compare a 0``;
* ``step(a)`` as ``min(compare(a, 0) + 1, 1)``;
* ``mod(a, b)`` (floored, sign of ``b``) as ``a - b * floor(a / b)`` -- the very
  arithmetic of csdf's ``mod``, not Fidget's Euclidean ``mod``.

Parameters become ``const`` nodes with their values (the defaults, or ``params``), and
a comment says so. The distance contract, Lipschitz bound and bounds go into comment
lines only (the format has no place for them; :func:`load_vm` reads a field that states
nothing). Reading a written file back gives a program that evaluates bit-identically
wherever csdf's and the written ops agree (all of them, for finite values).
"""

from __future__ import annotations

import os
import struct
from collections.abc import Callable

from ..compiler.program import as_program
from ..errors import CsdfError
from ..lang.vm import MAX_VM_BYTES, MAX_VM_NODES, OPCODES, load_vm, loads_vm
from ..layout import N_COORDS
from ..ops import OPS_BY_CODE
from ..version import __version__
from .atomic import atomic_path

__all__ = ["load_vm", "loads_vm", "save_vm", "dumps_vm", "MAX_VM_BYTES", "MAX_VM_NODES"]

#: csdf ops written as the Fidget opcode of the same (or another) name
_SAME: dict[str, str] = {
    "neg": "neg", "abs": "abs", "sqrt": "sqrt", "square": "square", "sin": "sin",
    "cos": "cos", "tan": "tan", "asin": "asin", "acos": "acos", "atan": "atan",
    "exp": "exp", "log": "ln", "floor": "floor", "add": "add", "sub": "sub",
    "mul": "mul", "div": "div", "min": "min", "max": "max", "atan2": "atan2",
}
assert all(v in OPCODES for v in _SAME.values())

_COORD_OPS = ("var-x", "var-y", "var-z")


class _Writer:
    """The nodes of a ``.vm`` file under construction, as a DAG over indices."""

    def __init__(self) -> None:
        #: ``(opcode, argument node indices, const value or None)``
        self.nodes: list[tuple[str, tuple[int, ...], float | None]] = []
        self._consts: dict[bytes, int] = {}

    def add(self, op: str, *args: int) -> int:
        self.nodes.append((op, args, None))
        return len(self.nodes) - 1

    def const(self, v: float) -> int:
        key = struct.pack("<d", v)
        i = self._consts.get(key)
        if i is None:
            self.nodes.append(("const", (), float(v)))
            i = self._consts[key] = len(self.nodes) - 1
        return i

    def text(self, out: int, header: list[str]) -> str:
        """The file: comment ``header`` lines, then the nodes ``out`` depends on, in
        order (so ``out`` is last), renamed ``_0, _1, ...``."""
        live = [False] * len(self.nodes)
        live[out] = True
        for i in range(out, -1, -1):
            if live[i]:
                for a in self.nodes[i][1]:
                    live[a] = True
        names: dict[int, str] = {}
        lines = [f"# {h}" for h in header]
        for i in range(out + 1):
            if not live[i]:
                continue
            op, args, value = self.nodes[i]
            name = names[i] = f"_{len(names):x}"
            if op == "const":
                lines.append(f"{name} const {value!r}")
            else:
                lines.append(" ".join([name, op, *(names[a] for a in args)]))
        return "\n".join(lines) + "\n"


def _derived(w: _Writer) -> dict[str, Callable[..., int]]:
    """Writers of the csdf ops that Fidget lacks, in Fidget ops."""
    def sign(a: int) -> int:
        return w.add("compare", a, w.const(0.0))

    def step(a: int) -> int:
        return w.add("min", w.add("add", sign(a), w.const(1.0)), w.const(1.0))

    def mod(a: int, b: int) -> int:
        return w.add("sub", a, w.add("mul", b, w.add("floor", w.add("div", a, b))))

    return {"sign": sign, "step": step, "mod": mod}


def dumps_vm(model, params: dict | None = None) -> str:
    """The ``.vm`` text of a shape or program (see the module docs).

    Args:
        model: a :class:`csdf.Shape` (compiled; cached on it) or a
            :class:`csdf.Program`.
        params: values of the parameters, written as constants (default: each
            parameter's default); checked against their ranges.

    Raises:
        CsdfError: ``model`` is neither; an op with no ``.vm`` form (the message names
            it); a bad parameter value (:class:`csdf.ParamError`).
    """
    prog, _ = as_program(model, "dumps_vm")
    if prog.data:
        raise CsdfError("a .vm file has no mesh op: a shape with a mesh call "
                        "(csdf.from_mesh / polyhedron) cannot be written as .vm")
    pvals = prog.param_values(params)
    layout = prog.layout
    w = _Writer()
    derived = _derived(w)
    coords: dict[int, int] = {}
    current: dict[int, int] = {}  # register slot -> node

    def read(slot: int) -> int:
        if slot < N_COORDS:
            if slot not in coords:
                coords[slot] = w.add(_COORD_OPS[slot])
            return coords[slot]
        if slot < layout.const_base:
            return w.const(float(pvals[slot - layout.param_base]))
        if slot < layout.reg_base:
            return w.const(float(prog.consts[slot - layout.const_base]))
        try:
            return current[slot]
        except KeyError:
            raise CsdfError(f"dumps_vm: register slot {slot} is read before it is "
                            "written; the program is malformed") from None

    for k, (opcode, dst, a, b) in enumerate(prog.code.tolist()):
        info = OPS_BY_CODE.get(opcode)
        if info is None:
            raise CsdfError(f"dumps_vm: instruction {k} has unknown opcode {opcode}")
        args = [read(a)] if info.arity == 1 else [read(a), read(b)]
        if info.name in _SAME:
            node = w.add(_SAME[info.name], *args)
        elif info.name in derived:
            node = derived[info.name](*args)
        else:
            raise CsdfError(f"dumps_vm: the op {info.name!r} (instruction {k}) has no form "
                            "in Fidget's .vm format")
        current[dst] = node
    out = read(prog.output)
    header = [f"written by csdf {__version__}: a {prog.dim}D field; the last node is "
              "the field",
              f"csdf exactness {prog.exactness}, lipschitz {prog.lipschitz!r}"
              + ("" if prog.bounds is None else
                 f", bounds {prog.bounds[0].tolist()} {prog.bounds[1].tolist()}")]
    if prog.params:
        given = ", ".join(f"{p.name} = {v!r}" for p, v in zip(prog.params, pvals.tolist()))
        header.append(f"parameters written as constants: {given}")
    text = w.text(out, header)
    if prog.dim == 3 and 2 not in coords:
        # a 3D field that does not read z: an unused var-z node says so (the reader
        # takes the dimension from it); "_z" is no hex name, so it cannot collide
        cut = text.index("\n", len("\n".join(f"# {h}" for h in header)))
        text = text[:cut] + "\n_z var-z" + text[cut:]
    return text


def save_vm(model, path: str | os.PathLike, params: dict | None = None) -> None:
    """Write a shape or program as a ``.vm`` file (:func:`dumps_vm`), atomically."""
    text = dumps_vm(model, params)
    with atomic_path(path) as tmp:
        with open(tmp, "w", encoding="utf-8", newline="\n") as fh:
            fh.write(text)

