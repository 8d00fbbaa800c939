"""Compiler from expressions to the register tape, the tape's serialised forms, and its
simplification over a region.

Modules: :mod:`~csdf.compiler.tape` (compile), :mod:`~csdf.compiler.regalloc` (the
register allocator), :mod:`~csdf.compiler.program` (the :class:`Program`),
:mod:`~csdf.compiler.calls` (primitive call records), :mod:`~csdf.compiler.binary` and
:mod:`~csdf.compiler.text` (bytecode and listing, ``docs/bytecode.md``),
:mod:`~csdf.compiler.simplify` (a shorter tape for one box).
"""

from .program import Call, Program, as_program
from .tape import compile_expr, compile_shape

__all__ = ["Program", "Call", "as_program", "compile_shape", "compile_expr"]
