"""Checks shared by the readers of model text (``.csdf``, Fidget's ``.vm``)."""

from __future__ import annotations

from typing import Any

from ..errors import ModelError

__all__ = ["check_source"]


def check_source(text: Any, file: str, limit: int, what: str) -> None:
    """Refuse ``text`` that is not a string or is over ``limit`` bytes (UTF-8), with a
    :class:`~csdf.ModelError` naming ``file``; ``what`` names the text in the message
    (``'model text'``, ``'.vm text'``)."""
    if not isinstance(text, str):
        raise ModelError(f"{what} must be a string, got {type(text).__name__}", file=file)
    size = len(text.encode("utf-8", "surrogatepass"))
    if size > limit:
        raise ModelError(f"{what} is {size} bytes; the limit is {limit}", file=file)
