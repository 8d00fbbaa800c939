"""Validation of point arrays given to evaluators, and a cloud's typical point spacing
(near-copies not counted)."""

from __future__ import annotations

import numpy as np

from .errors import CsdfError

__all__ = ["as_points", "MAX_POINTS", "typical_spacing", "sample_spacing", "has_near_copies",
           "NEAR_K", "NEAR_COPY"]

MAX_POINTS = 2**31 - 1
#: :func:`typical_spacing` reads each point's distances to this many nearest others
NEAR_K = 4
#: a neighbour nearer than this fraction of a point's ``NEAR_K``-th neighbour distance
#: is a near-copy of it (see :func:`typical_spacing`)
NEAR_COPY = 0.2
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


def typical_spacing(dd: np.ndarray) -> float:
    """The typical distance between neighbouring points of a cloud (its units).

    Args:
        dd: ``(S, k)``, ``k >= NEAR_K``: for each of ``S`` points of the cloud (all, or
            a sample), its distances to its ``k`` nearest other points, ascending.

    Returns:
        The median distance to the nearest other point. When most points have a
        near-copy (that median is below ``NEAR_COPY`` times the median distance to the
        ``NEAR_K``-th neighbour: a scan given twice with millimetres of jitter, frames
        stacked), the median distance to the nearest point that is not a near-copy
        (farther than ``NEAR_COPY`` times the point's own ``NEAR_K``-th neighbour
        distance). A cloud without near-copies gets the plain median (random samples
        of a surface give about 0.4 times, grids about 1).
    """
    dd = _distances(dd)
    first = float(np.median(dd[:, 0]))
    if not has_near_copies(dd):
        return first
    far = dd[:, NEAR_K - 1]
    # the NEAR_K-th is apart unless it is 0 (exact copies): then the nearest, 0
    apart = dd > NEAR_COPY * far[:, None]
    return float(np.median(dd[np.arange(len(dd)), np.argmax(apart, axis=1)]))


def sample_spacing(tree, sample: np.ndarray) -> float:
    """:func:`typical_spacing` of the cloud in ``tree`` (a :class:`scipy.spatial.cKDTree`)
    from the neighbours of ``sample`` ``(S, D)``, points of that cloud; a cloud of at
    most ``NEAR_K`` points gets the median distance to the nearest other point."""
    if tree.n > NEAR_K:
        dd, _ = tree.query(sample, k=NEAR_K + 1)
        return typical_spacing(dd[:, 1:])
    dd, _ = tree.query(sample, k=2)
    return float(np.median(dd[:, 1]))


def has_near_copies(dd: np.ndarray) -> bool:
    """Whether most points of a cloud have a near-copy: the median distance to the
    nearest other point is below ``NEAR_COPY`` times the median distance to the
    ``NEAR_K``-th (``dd`` as :func:`typical_spacing`'s)."""
    dd = _distances(dd)
    return bool(np.median(dd[:, 0]) < NEAR_COPY * np.median(dd[:, NEAR_K - 1]))


def _distances(dd) -> np.ndarray:
    dd = np.asarray(dd, np.float64)
    if dd.ndim != 2 or dd.shape[1] < NEAR_K or len(dd) == 0:
        raise ValueError(f"need (S, >= {NEAR_K}) neighbour distances, got {dd.shape}")
    return dd
