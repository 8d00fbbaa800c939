"""The ``.csdf`` model language: grammar (``grammar.lark``), loader, printer."""

from .loader import MAX_FILE_BYTES, load, loads
from .printer import dumps

__all__ = ["load", "loads", "dumps", "MAX_FILE_BYTES"]
