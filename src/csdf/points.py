"""Validation of point arrays given to evaluators."""

from __future__ import annotations

import numpy as np

from .errors import CsdfError

__all__ = ["as_points", "MAX_POINTS"]

MAX_POINTS = 2**31 - 1
_FLOATS = (np.dtype(np.float32), np.dtype(np.float64))


def as_points(points, dim: int = 3) -> tuple[np.ndarray, tuple[int, ...], np.dtype]:
    """Check and flatten a point array.

    Args:
        points: array-like ``(..., 3)`` (``(..., 2)`` also accepted when ``dim == 2``),
            float32 or float64; integer and boolean arrays become float64.
        dim: the program's dimension.

    Returns:
        ``(pts (N, D) C-contiguous, batch shape, dtype)``.

    Raises:
        CsdfError: wrong shape or an unsupported dtype, naming the expected shape.
    """
    if (type(points) is np.ndarray and points.ndim == 2 and points.shape[1] == 3
            and points.dtype in _FLOATS and points.flags.c_contiguous
            and points.shape[0] <= MAX_POINTS):
        # already what the checks below make of it (an evaluator's hot path)
        return points, points.shape[:1], points.dtype
    try:
        arr = np.asarray(points)
    except (TypeError, ValueError) as exc:
        raise CsdfError(
            f"points must be an array of shape (N, 3); could not convert: {exc}"
        ) from None
    expected = "(N, 3) or (..., 3)" if dim == 3 else "(N, 2), (N, 3) or (..., 2|3)"
    if arr.dtype.kind in "biu":
        arr = arr.astype(np.float64)
    elif arr.dtype not in (np.float32, np.float64):
        raise CsdfError(f"points must be float32 or float64, got dtype {arr.dtype}")
    ok_last = (3,) if dim == 3 else (2, 3)
    if arr.ndim < 1 or arr.shape[-1] not in ok_last:
        raise CsdfError(f"points must have shape {expected}; got shape {arr.shape}")
    batch = arr.shape[:-1]
    flat = np.ascontiguousarray(arr.reshape(-1, arr.shape[-1]))
    if flat.shape[0] > MAX_POINTS:
        raise CsdfError(f"too many points ({flat.shape[0]}); evaluate in batches")
    return flat, batch, arr.dtype
