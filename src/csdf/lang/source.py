"""Checks shared by the readers of model text (``.csdf``, Fidget's ``.vm``)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from ..errors import ModelError

__all__ = ["check_source", "read_source"]


def read_source(path: str | os.PathLike, limit: int, what: str = "the file") -> str:
    """The UTF-8 text of the file at ``path``, refused (a :class:`~csdf.ModelError`
    naming the file; ``what`` names it in the message) when it cannot be read, is over
    ``limit`` bytes or is not UTF-8."""
    p = Path(path)
    try:
        size = p.stat().st_size
    except OSError as exc:
        raise ModelError(f"cannot read {what}: {exc.strerror}", file=str(p)) from None
    if size > limit:
        raise ModelError(f"{what} is {size} bytes; the limit is {limit}", file=str(p))
    try:
        return p.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise ModelError(f"{what} is not UTF-8 text ({exc.reason} at byte {exc.start})",
                         file=str(p)) from None
    except OSError as exc:
        raise ModelError(f"cannot read {what}: {exc.strerror}", file=str(p)) from None


def check_source(text: Any, file: str, limit: int, what: str) -> None:
    """Refuse ``text`` that is not a string or is over ``limit`` bytes (UTF-8), with a
    :class:`~csdf.ModelError` naming ``file``; ``what`` names the text in the message
    (``'model text'``, ``'.vm text'``)."""
    if not isinstance(text, str):
        raise ModelError(f"{what} must be a string, got {type(text).__name__}", file=file)
    size = len(text.encode("utf-8", "surrogatepass"))
    if size > limit:
        raise ModelError(f"{what} is {size} bytes; the limit is {limit}", file=file)
