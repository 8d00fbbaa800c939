"""Recall, average recall (BOP 2019) and the area under the accuracy curve (ADD, ADD-S).

An instance is one ground-truth object in one image; its error is ``inf`` (or NaN) when
the method gave no estimate for it. BOP counts only the instances with at least 10 % of
the object visible (``visib_fract >= 0.1``), in the numerator and the denominator.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import CsdfError
from .inputs import errors_arg, nonnegative, per_instance, positive, thresholds_arg

__all__ = ["recall", "average_recall", "bop_average_recall", "auc", "VSD_THETAS",
           "MSSD_THETAS", "MSPD_THETAS", "MSPD_REFERENCE_WIDTH", "VSD_DELTA_MM",
           "ADD_THRESHOLD"]

#: BOP 2019 thresholds theta of VSD's error (``e < theta``)
VSD_THETAS = tuple(round(0.05 * k, 2) for k in range(1, 11))
#: BOP 2019 thresholds of MSSD, as fractions of the object's diameter
MSSD_THETAS = tuple(round(0.05 * k, 2) for k in range(1, 11))
#: BOP 2019 thresholds of MSPD, in pixels of an image :data:`MSPD_REFERENCE_WIDTH` wide
MSPD_THETAS = tuple(float(5 * k) for k in range(1, 11))
#: the image width MSPD's thresholds refer to (errors are scaled by ``640 / width``)
MSPD_REFERENCE_WIDTH = 640.0
#: BOP's visibility tolerance delta of VSD, in millimetres (``0.015`` in metres)
VSD_DELTA_MM = 15.0
#: ADD / ADD-S: correct below this fraction of the object's diameter
ADD_THRESHOLD = 0.1

_METRICS = ("vsd", "mssd", "mspd")


def _selected(n: int, visib_fract: Any, min_visib: float) -> np.ndarray:
    """Mask ``(n,)`` of the instances that count (visible fraction ``>= min_visib``)."""
    mv = nonnegative(min_visib, "min_visib")
    if visib_fract is None:
        return np.ones(n, dtype=bool)
    try:
        v = np.asarray(visib_fract, dtype=np.float64)
    except (TypeError, ValueError):
        raise CsdfError(f"visib_fract must be an array of shape ({n},)") from None
    if v.shape != (n,) or not np.all(np.isfinite(v)):
        raise CsdfError(f"visib_fract must be finite with shape ({n},) (one per instance), "
                        f"got {v.shape}")
    keep = v >= mv
    if not keep.any():
        raise CsdfError(f"no instance is at least {mv:g} visible (visib_fract); recall "
                        "is undefined")
    return keep


def recall(errors: Any, thresholds: Any, *, scale: Any = None, visib_fract: Any = None,
           min_visib: float = 0.1) -> float | np.ndarray:
    """The fraction of instances whose error is below a threshold.

    Instance ``i`` is correct at threshold ``theta`` when ``errors[i] < theta *
    scale[i]``: ``scale`` is the object's diameter for MSSD, ADD and ADD-S (thresholds
    as fractions of the diameter) and ``image_width / 640`` for MSPD (BOP's thresholds
    in pixels of a 640-pixel-wide image); ``None`` compares the errors directly.

    Args:
        errors: ``(N,)`` one error per instance, or ``(N, T)`` (VSD: one per tau);
            ``inf`` or NaN: no estimate (never correct).
        thresholds: a number or ``(M,)``.
        scale: ``None``, a number, or ``(N,)`` one per instance (> 0).
        visib_fract: ``(N,)`` visible fraction of each instance
            (:func:`csdf.metrics.visible_fraction`); ``None``: every instance counts.
        min_visib: instances less visible than this do not count (BOP: 0.1).

    Returns:
        A float for ``(N,)`` errors and one threshold; else an array ``(T, M)``,
        ``(T,)`` or ``(M,)`` (the error columns first, then the thresholds).

    Raises:
        CsdfError: bad shapes or values, naming the argument; no instance visible
            enough.
    """
    e = errors_arg(errors)
    th, scalar = thresholds_arg(thresholds)
    n = e.shape[0]
    s = np.ones(n) if scale is None else per_instance(scale, n, "scale")
    keep = _selected(n, visib_fract, min_visib)
    e, s = e[keep], s[keep]
    e2 = e.reshape(len(e), -1)  # (N', T)
    ok = e2[:, :, None] < th[None, None, :] * s[:, None, None]  # (N', T, M)
    r = ok.mean(axis=0)
    if e.ndim == 1:
        r = r[0]
    if scalar:
        r = r[..., 0]
    return float(r) if np.ndim(r) == 0 else r


def average_recall(errors: Any, metric: str, *, diameter: Any = None,
                   image_width: Any = None, thresholds: Any = None,
                   visib_fract: Any = None, min_visib: float = 0.1) -> float:
    """BOP's average recall of one metric: the mean of :func:`recall` over the metric's
    thresholds (for VSD over every pair of tau and theta).

    Args:
        errors: per-instance errors: ``(N, T)`` for ``'vsd'`` (one column per tau, as
            :func:`csdf.metrics.vsd` returns them; ``(N,)`` for one tau), ``(N,)`` model
            units for ``'mssd'``, ``(N,)`` pixels for ``'mspd'``; ``inf``: no estimate.
        metric: ``'vsd'``, ``'mssd'`` or ``'mspd'``.
        diameter: the object's diameter, a number or ``(N,)`` (``'mssd'``).
        image_width: the test images' width in pixels, a number or ``(N,)`` (``'mspd'``:
            the errors are scaled by ``640 / image_width``).
        thresholds: override the metric's thresholds: theta of VSD (default
            :data:`VSD_THETAS`), fractions of the diameter for MSSD (default
            :data:`MSSD_THETAS`), pixels at width 640 for MSPD (default
            :data:`MSPD_THETAS`).
        visib_fract, min_visib: as for :func:`recall`.

    Returns:
        The average recall in ``[0, 1]``.

    Raises:
        CsdfError: an unknown metric, a missing ``diameter`` / ``image_width``, or what
            :func:`recall` raises.
    """
    if metric not in _METRICS:
        raise CsdfError(f"metric must be one of {', '.join(map(repr, _METRICS))}, "
                        f"got {metric!r}")
    n = errors_arg(errors, ndim=(1, 2) if metric == "vsd" else (1,)).shape[0]
    scale = None
    if metric == "vsd":
        th = VSD_THETAS if thresholds is None else thresholds
    elif metric == "mssd":
        if diameter is None:
            raise CsdfError("average_recall('mssd') needs diameter (MSSD's thresholds are "
                            "fractions of it)")
        th = MSSD_THETAS if thresholds is None else thresholds
        scale = per_instance(diameter, n, "diameter")
    else:
        if image_width is None:
            raise CsdfError("average_recall('mspd') needs image_width (BOP scales MSPD by "
                            "640 / image_width)")
        th = MSPD_THETAS if thresholds is None else thresholds
        scale = per_instance(image_width, n, "image_width") / MSPD_REFERENCE_WIDTH
    r = recall(errors, th, scale=scale, visib_fract=visib_fract, min_visib=min_visib)
    return float(np.mean(r))


def bop_average_recall(vsd_errors: Any, mssd_errors: Any, mspd_errors: Any, *,
                       diameter: Any, image_width: Any, visib_fract: Any = None,
                       min_visib: float = 0.1) -> float:
    """BOP's average recall of a method: the mean of AR_VSD, AR_MSSD and AR_MSPD
    (:func:`average_recall` with the default thresholds).

    Args:
        vsd_errors: ``(N, T)`` VSD errors at BOP's taus.
        mssd_errors: ``(N,)`` MSSD errors, model units.
        mspd_errors: ``(N,)`` MSPD errors, pixels.
        diameter, image_width, visib_fract, min_visib: as for :func:`average_recall`.

    Returns:
        The average recall in ``[0, 1]``.
    """
    kw = {"visib_fract": visib_fract, "min_visib": min_visib}
    return float(np.mean([
        average_recall(vsd_errors, "vsd", **kw),
        average_recall(mssd_errors, "mssd", diameter=diameter, **kw),
        average_recall(mspd_errors, "mspd", image_width=image_width, **kw),
    ]))


def auc(errors: Any, max_threshold: float, *, scale: Any = None, visib_fract: Any = None,
        min_visib: float = 0.1) -> float:
    """Area under the accuracy-threshold curve, normalised to ``[0, 1]``: the mean over
    thresholds ``t`` in ``[0, max_threshold]`` of the fraction of instances with
    ``error < t * scale`` (e.g. ADD-S AUC up to 10 % of the diameter:
    ``auc(adds_errors, 0.1, scale=diameters)``).

    Computed exactly, not on a grid of thresholds: the curve is a step function, and its
    mean equals the mean over instances of ``clip(1 - error / (max_threshold * scale),
    0, 1)``.

    Args:
        errors: ``(N,)`` per-instance errors (``inf``/NaN: no estimate, counts 0).
        max_threshold: the upper end of the threshold range (> 0).
        scale, visib_fract, min_visib: as for :func:`recall`.

    Returns:
        The normalised area in ``[0, 1]``.

    Raises:
        CsdfError: bad shapes or values, naming the argument.
    """
    e = errors_arg(errors, ndim=(1,))
    m = positive(max_threshold, "max_threshold")
    n = e.shape[0]
    s = np.ones(n) if scale is None else per_instance(scale, n, "scale")
    keep = _selected(n, visib_fract, min_visib)
    return float(np.mean(np.clip(1.0 - e[keep] / (m * s[keep]), 0.0, 1.0)))
