"""Random clutter: a union of many small primitives, the test scene of pruned evaluation
and of scene queries (unions of hundreds or thousands of parts)."""

from __future__ import annotations

import numpy as np

from ..shapes.base import Shape
from ..shapes.csg import union
from ..shapes.primitives3d import box, sphere, torus

__all__ = ["clutter"]

#: the most parts :func:`clutter` makes
MAX_PARTS = 100_000


def clutter(n: int, seed: int = 0, spacing: float = 1.0) -> Shape:
    """A union of ``n`` random primitives: spheres (radius 0.15-0.3), boxes (half sizes
    0.15-0.4) and tori (0.25, 0.08) in turn, centred uniformly in a cube of side
    ``spacing * n ** (1/3)`` about the origin, so that the density of parts (and the
    surface per part) stays the same as ``n`` grows (model units).

    The distance is a bound (a union of exact distances is exact outside and a bound
    inside). The same ``n``, ``seed`` and ``spacing`` give the same shape.

    Raises:
        ValueError: ``n`` not in ``[1, 100000]`` or ``spacing`` not positive and finite.
    """
    n = int(n)
    if not 1 <= n <= MAX_PARTS:
        raise ValueError(f"clutter: n must be in [1, {MAX_PARTS}], got {n}")
    if not (np.isfinite(spacing) and spacing > 0):
        raise ValueError(f"clutter: spacing must be positive and finite, got {spacing}")
    rng = np.random.default_rng(seed)
    half = 0.5 * spacing * n ** (1 / 3)
    parts = []
    for i in range(n):
        c = rng.uniform(-1, 1, 3) * half
        radius = rng.uniform(0.15, 0.3)  # both drawn for every part: a part's kind
        size = rng.uniform(0.15, 0.4, 3)  # does not change the parts after it
        kind = i % 3
        s = sphere(radius) if kind == 0 else box(size) if kind == 1 else torus(0.25, 0.08)
        parts.append(s.translate(c))
    return union(*parts) if n > 1 else parts[0]
