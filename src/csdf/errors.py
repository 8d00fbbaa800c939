"""Exceptions raised by csdf.

Every error csdf raises on bad input derives from :class:`CsdfError` and says what
was wrong and where (argument name, byte offset, line number, ...).
"""

from __future__ import annotations

__all__ = ["CsdfError", "BytecodeError", "ParamError", "ShapeError", "ModelError",
           "MeshWarning", "interrupt_in"]


def interrupt_in(exc: BaseException) -> KeyboardInterrupt | None:
    """The ``KeyboardInterrupt`` (Ctrl-C, or a signal a command turned into one) in
    ``exc``'s chain of causes and contexts, or None.

    A signal handler that raises while a compiled (Numba) function is being called or
    loaded comes out as a ``SystemError`` ("returned a result with an exception set")
    whose context is the interrupt; code that falls back to another way on an
    ``Exception`` calls this first and re-raises the interrupt, so a stop request is
    never taken for a failed kernel."""
    seen: set[int] = set()
    cur: BaseException | None = exc
    while cur is not None and id(cur) not in seen:
        if isinstance(cur, KeyboardInterrupt):
            return cur
        seen.add(id(cur))
        cur = cur.__cause__ or cur.__context__
    return None


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


class ModelError(CsdfError):
    """An error in a ``.csdf`` model: where it is, what is wrong, and a hint.

    Attributes:
        file: the file name (or ``'<string>'``).
        line, column: 1-based position of the offending text (0 when unknown).
        message: what is wrong.
        hint: a suggestion (closest known names, the expected signature, ...), or ''.
        source_line: the text of the line, for the caret display.
    """

    def __init__(self, message: str, *, file: str = "<string>", line: int = 0,
                 column: int = 0, hint: str = "", source_line: str = "", width: int = 1):
        self.message = message
        self.file = file
        self.line = line
        self.column = column
        self.hint = hint
        self.source_line = source_line
        self.width = max(1, width)
        super().__init__(self._render())

    def _render(self) -> str:
        where = f"{self.file}:{self.line}:{self.column}" if self.line else self.file
        out = f"{where}: {self.message}"
        if self.source_line:
            caret = " " * (max(self.column, 1) - 1) + "^" * min(self.width, 60)
            out += f"\n    {self.source_line.rstrip()}\n    {caret}"
        if self.hint:
            out += f"\nhint: {self.hint}"
        return out


class MeshWarning(UserWarning):
    """:func:`csdf.mesh` made a mesh that misses something the field has (parts or gaps
    thinner than a voxel); the message says how much, where, and what to change."""
