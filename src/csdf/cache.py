"""Small per-object memo tables: results kept on the object they derive from (a
program, its lowering), keyed by parameter values and options, and dropped all at once
when the table is full (a few entries suffice: callers repeat the same values)."""

from __future__ import annotations

from collections.abc import Callable, Hashable
from typing import Any, TypeVar

__all__ = ["memo"]

T = TypeVar("T")


def memo(owner: Any, table: str, key: Hashable, make: Callable[[], T], size: int) -> T:
    """``owner``'s kept result for ``key`` in its table ``table`` (an attribute dict),
    made by ``make()`` on a miss (``None`` results are kept too); the table is emptied
    first when it already holds ``size`` entries."""
    cache = owner.__dict__.setdefault(table, {})
    if key in cache:
        return cache[key]
    if len(cache) >= size:
        cache.clear()
    value = cache[key] = make()
    return value
