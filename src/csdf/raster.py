"""``csdf.raster``: a 2D field sampled on an image grid, by a quadtree of tiles.

Each tile takes its parent's program and shortens it for the box of its own pixel
centres (:func:`csdf.compiler.simplify.simplify`: a ``min``/``max`` whose operands'
intervals do not overlap keeps only the winner, dead instructions go), so deep tiles
run a few dozen instructions where the whole field has thousands. Interval arithmetic
over a tile that is wholly inside or outside fills it without evaluating it (for the
boolean image). Leaves evaluate their short program at their pixel centres.

Because a simplified program gives bit-identical values inside its box, the image is
the same, pixel for pixel, as evaluating the whole field at every pixel (on the same
backend).

Pixel ``(row, col)`` of a ``width x height`` image over bounds ``((x0, y0), (x1, y1))``
has its centre at ``x = x0 + (col + 0.5) (x1 - x0) / width``, ``y = y1 - (row + 0.5)
(y1 - y0) / height`` (row 0 at the top, ``y = y1``), the convention of the Prospero
challenge.

The default (``backend='auto'``) runs the same algorithm compiled, level by level
over all tiles at once (:func:`csdf.backends.pruned.raster_image`, reached through the
field layer's :meth:`csdf.Field.raster`); this module's Python quadtree, which
shortens programs one tile at a time with :func:`csdf.compiler.simplify.simplify`,
remains as the reference (``backend='numpy'`` or ``'interp'``). Measured on Prospero
(``../shared/data/vm/prospero.vm``, 1024 x 1024, 2 cores): see
``benchmarks/bench_prospero.py``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .errors import CsdfError
from .field import as_field, check_bounds, planar_bounds

__all__ = ["raster", "MAX_RASTER_SIDE", "MAX_RASTER_PIXELS", "LEAF"]

#: the largest image side and pixel count
MAX_RASTER_SIDE = 16384
MAX_RASTER_PIXELS = 1 << 26
#: tiles of at most ``LEAF x LEAF`` pixels are evaluated, not split
LEAF = 128


def raster(shape: Any, width: int, height: int, bounds: Any = None, *,
           values: bool = False, params: dict | None = None, backend: str = "auto",
           leaf: int | None = None, check_ranges: bool = True) -> np.ndarray:
    """The field of a 2D shape on a ``width x height`` image.

    Args:
        shape: a 2D :class:`csdf.Shape`, a 2D :class:`csdf.Program` (e.g. from a
            ``.vm`` file) or a field of one.
        width, height: image size in pixels, each in ``[1, 16384]``, at most 2^26
            pixels in all.
        bounds: ``((x0, y0), (x1, y1))`` the image covers (model units); default: the
            shape's own box, when it has one.
        values: return the field values ``(height, width)`` float64; default: the
            boolean image ``(height, width)``, True where the value is negative
            (inside).
        params: parameter values ``{name: value}``.
        backend: ``'auto'``: the compiled quadtree
            (:func:`csdf.backends.pruned.raster_image`, through
            :meth:`csdf.Field.raster`; bit-identical to the ``'interp'`` backend on the
            whole field), or this module's Python quadtree where Numba is missing;
            ``'numpy'`` or ``'interp'``: the Python quadtree with that evaluator at the
            leaves (the same bits as that backend on the whole field).
        leaf: tiles of at most ``leaf x leaf`` pixels are evaluated (default 16
            compiled, :data:`LEAF` in Python).
        check_ranges: refuse parameter values outside their declared ranges.

    Returns:
        ``(height, width)`` bool (inside) or float64 (values); row 0 is the top
        (``y = y1``).

    Raises:
        CsdfError: a 3D shape, bad sizes or bounds, no bounds known.
    """
    from .compiler.simplify import simplify

    fld = as_field(shape, params, check_ranges=check_ranges)
    prog = fld.program
    if prog.dim != 2:
        raise CsdfError("raster needs a 2D shape (a 3D one: use csdf.slice or render)")
    w, h = _size(width, "width"), _size(height, "height")
    if w * h > MAX_RASTER_PIXELS:
        raise CsdfError(f"the image has {w * h:,} pixels; the limit is {MAX_RASTER_PIXELS:,}")
    if leaf is not None and (isinstance(leaf, bool) or not isinstance(leaf, (int, np.integer))
                             or not 1 <= leaf <= 256):
        raise CsdfError(f"leaf must be an integer in [1, 256], got {leaf!r}")
    if backend not in ("auto", "numpy", "interp"):
        raise CsdfError(f"raster's backend must be 'auto', 'numpy' or 'interp', got "
                        f"{backend!r}")
    if bounds is None:
        try:
            box = planar_bounds(prog, fld.params, shape=fld.shape)
        except CsdfError:
            raise CsdfError("the bounds of this 2D field are not known: pass bounds=((x0, "
                            "y0), (x1, y1)) (csdf raster: --bounds x0,y0,x1,y1)") from None
    else:
        box = check_bounds(bounds, dim=2, what="bounds")
    xs = box[0, 0] + (np.arange(w) + 0.5) * ((box[1, 0] - box[0, 0]) / w)
    ys = box[1, 1] - (np.arange(h) + 0.5) * ((box[1, 1] - box[0, 1]) / h)
    if backend == "auto":
        img = fld.raster(xs, ys, values=values, leaf=16 if leaf is None else int(leaf))
        if img is not None:
            return img
        backend = "numpy"
    leaf = LEAF if leaf is None else int(leaf)
    out = np.empty((h, w), dtype=np.float64 if values else bool)
    pv = fld.params
    # tiles: (row0, row1, col0, col1, program shortened for the tile's parent box)
    tiles = [(0, h, 0, w, prog)]
    while tiles:
        r0, r1, c0, c1, p = tiles.pop()
        lo = np.array([xs[c0], ys[r1 - 1]])
        hi = np.array([xs[c1 - 1], ys[r0]])
        if not values:
            flo, fhi = _intervals(p, lo, hi, pv)
            if fhi < 0 or flo >= 0:  # wholly inside, or outside (0 is outside)
                out[r0:r1, c0:c1] = fhi < 0
                continue
        p = simplify(p, lo, hi, params=pv)
        if (r1 - r0) <= leaf and (c1 - c0) <= leaf:
            gx, gy = np.meshgrid(xs[c0:c1], ys[r0:r1])
            f = p(np.stack([gx.ravel(), gy.ravel()], axis=1), pv, backend=backend,
                  check_ranges=False).reshape(r1 - r0, c1 - c0)
            out[r0:r1, c0:c1] = f if values else f < 0
            continue
        rm, cm = (r0 + r1) // 2, (c0 + c1) // 2
        for a, b in ((r0, rm), (rm, r1)):
            for c, d in ((c0, cm), (cm, c1)):
                if a < b and c < d:
                    tiles.append((a, b, c, d, p))
    return out


def _intervals(prog, lo: np.ndarray, hi: np.ndarray, params: dict) -> tuple[float, float]:
    """The program's interval over one 2D box."""
    from .field import evaluate_intervals  # (the field layer's interval arithmetic)

    flo, fhi = evaluate_intervals(prog, lo[None], hi[None], params=params)
    return float(flo[0]), float(fhi[0])


def _size(n: Any, what: str) -> int:
    """An image side checked: an integer in ``[1, MAX_RASTER_SIDE]``."""
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or \
            not 1 <= n <= MAX_RASTER_SIDE:
        raise CsdfError(f"{what} must be an integer in [1, {MAX_RASTER_SIDE}], got {n!r}")
    return int(n)

