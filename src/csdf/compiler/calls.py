"""Primitive call records of a program (for the paper's primitive-level counts).

A :class:`Call` says which instruction produces a primitive's distance and where the
primitive's inputs come from. It lives apart from :class:`csdf.Program` so that the
bytecode codecs (:mod:`csdf.compiler.binary`, :mod:`csdf.compiler.text`), which the
program's ``to_bytes``/``from_bytes`` call, need not import the program module.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Call", "INSTR_REF"]

#: a call input ``INSTR_REF | i`` is the result of instruction ``i`` (otherwise a slot)
INSTR_REF = 0x80000000


@dataclass(frozen=True)
class Call:
    """A primitive invocation inside a program (for primitive-level counts).

    Attributes:
        name: primitive name (``'sphere'``, ...).
        out: index of the instruction that produces the primitive's distance.
        inputs: where its inputs come from: a fixed slot index, or
            ``0x80000000 | i`` (:data:`INSTR_REF`) for the result of instruction ``i``.
    """

    name: str
    out: int
    inputs: tuple[int, ...]
