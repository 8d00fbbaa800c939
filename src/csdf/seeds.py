"""The ``seed`` argument of csdf's random functions, checked."""

from __future__ import annotations

from typing import Any

import numpy as np

from .errors import CsdfError

__all__ = ["rng_arg"]


def rng_arg(seed: Any, what: str = "seed") -> np.random.Generator:
    """``numpy.random.default_rng(seed)``, or a :class:`CsdfError` naming ``what`` when
    ``seed`` is not one it takes (None, a whole number >= 0, a sequence of those, a
    ``SeedSequence``, a bit generator or a ``Generator``): NumPy's own errors name
    neither the argument nor what it accepts."""
    if isinstance(seed, bool):
        raise CsdfError(f"{what} must be None, a whole number >= 0 or a numpy Generator; "
                        f"got {seed!r}")
    try:
        return np.random.default_rng(seed)
    except (TypeError, ValueError):
        raise CsdfError(f"{what} must be None, a whole number >= 0 or a numpy Generator; "
                        f"got {seed!r}") from None
