"""Exceptions raised by csdf.

Every error csdf raises on bad input derives from :class:`CsdfError` and says what
was wrong and where (argument name, byte offset, line number, ...).
"""

from __future__ import annotations

__all__ = ["CsdfError", "BytecodeError", "ParamError", "ShapeError"]


class CsdfError(ValueError):
    """Base class of every csdf error caused by bad input."""


class BytecodeError(CsdfError):
    """A byte string or text listing is not a valid csdf program.

    Raised by :meth:`csdf.Program.from_bytes` and :meth:`csdf.Program.from_text`;
    the message names the offset (or line) and what was expected there.
    """


class ParamError(CsdfError):
    """A parameter is declared or given wrongly (unknown name, bad default, ...)."""


class ShapeError(CsdfError):
    """A shape was built with invalid arguments (wrong vector length, 2D vs 3D, ...)."""
