"""Compiler from expressions to the register tape, and the tape's serialised forms."""

from .program import Call, Program, as_program
from .tape import compile_expr, compile_shape

__all__ = ["Program", "Call", "as_program", "compile_shape", "compile_expr"]
