"""Register allocation for a straight-line tape: one linear scan for every tape builder.

The compiler (:mod:`csdf.compiler.tape`) and the simplifier
(:mod:`csdf.compiler.simplify`) both produce a list of instructions in execution order,
each reading the results of earlier instructions (and fixed slots, which need no
register). :func:`linear_scan` gives each result a register:

* a register is freed right after the instruction that reads its value for the last
  time, before that instruction's own result is placed, so an instruction may write
  the register of an operand it consumes;
* a new value takes the lowest free register, or a new one when none is free.

So the register count is the peak number of values alive at once. A value that no
later instruction reads and that is not in ``live_out`` keeps its register to the end
(the tape builders emit no such values).
"""

from __future__ import annotations

import heapq
from collections.abc import Collection, Sequence

__all__ = ["linear_scan"]


def linear_scan(
    reads: Sequence[Sequence[int]], live_out: Collection[int] = ()
) -> tuple[list[int], int]:
    """Registers for the results of a straight-line tape.

    Args:
        reads: per instruction ``i``, the indices ``j < i`` of the instructions whose
            results it reads (fixed-slot operands are left out; repeats are allowed).
        live_out: instructions whose results must stay alive after the last
            instruction (the program's output).

    Returns:
        ``(regs, n_regs)``: ``regs[i]`` is the register number (0-based, add the
        layout's :attr:`~csdf.layout.SlotLayout.reg_base` for its slot) holding the
        result of instruction ``i``; ``n_regs`` registers are used in all.

    Raises:
        ValueError: an instruction reads a result that is not computed before it.
    """
    n = len(reads)
    last_use: dict[int, int] = {}
    for i, srcs in enumerate(reads):
        for j in srcs:
            if not 0 <= j < i:
                raise ValueError(f"instruction {i} reads instruction {j}, not an earlier one")
            last_use[j] = i
    for j in live_out:
        last_use[j] = n
    regs: list[int] = [0] * n
    free: list[int] = []
    n_regs = 0
    for i, srcs in enumerate(reads):
        for j in set(srcs):
            if last_use[j] == i:
                heapq.heappush(free, regs[j])
        if free:
            r = heapq.heappop(free)
        else:
            r = n_regs
            n_regs += 1
        regs[i] = r
    return regs, n_regs
