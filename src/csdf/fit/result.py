"""The result of a fit: :class:`FitResult` (returned by :func:`csdf.fit` and
:func:`csdf.icp`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..pose import Pose

__all__ = ["FitResult"]


@dataclass
class FitResult:
    """The recovered object pose, scale and parameters, with quality measures.

    Attributes:
        rotation: (3, 3) object-to-scene rotation ``R``.
        translation: (3,) object origin in the scene ``t`` (scene units).
        scale: uniform scale ``s`` (``p = s R q + t``).
        params: all parameter values ``{name: value}`` (estimated and fixed).
        rmse: root mean square of the residuals of the inliers (scene units).
        inlier_fraction: fraction of points with ``|r| <= inlier_threshold``.
        inlier_threshold: the threshold used (scene units).
        converged: the optimiser met a convergence test (not the iteration limit).
        iterations: residual evaluations used.
        seconds: wall time.
        cost: final robust cost.
        method: ``'csdf'`` (SDF-to-cloud least squares) or ``'icp'``.
        notes: remarks such as scale/parameter ambiguity, or what ``loss='auto'`` did.
        loss: the robust loss of the final solve (``'huber'`` or ``'cauchy'`` when
            ``loss='auto'`` was asked; None for :func:`csdf.icp`).
        success: the fit explains the cloud (unlike ``converged``, which only says how
            the optimiser stopped). All of: (1) ``inlier_fraction >= INLIER_MIN``
            (0.8); (2) the inlier ``rmse <= RMSE_MAX`` (1.5) ``x f_scale``, the noise
            level the fit assumes; (3) when a viewpoint is known, at most
            ``VISIBLE_MAX_UNEXPLAINED`` (5%) of the fitted model's surface visible from
            it (ray-cast on a ``VIEW_RAYS`` x ``VIEW_RAYS`` grid, within the cloud's view)
            is unexplained: seen through (the measured points there lie behind it) or
            without points. The constants and the exact rules are in
            :mod:`csdf.fit.quality`.
        quality: the figures of the success test: ``inlier_fraction``, ``rmse``,
            ``noise_level`` (f_scale), ``rmse_ratio``, ``visible_checked``,
            ``visible_rays``, ``visible_unexplained``, ``visible_see_through``,
            ``visible_empty`` (fractions of the judged rays), the thresholds used,
            ``seconds`` (cost of the test) and ``reasons``: one sentence per failed
            criterion (empty on success).
    """

    rotation: np.ndarray
    translation: np.ndarray
    scale: float
    params: dict[str, float]
    rmse: float
    inlier_fraction: float
    inlier_threshold: float
    converged: bool
    iterations: int
    seconds: float
    cost: float = math.nan
    method: str = "csdf"
    notes: list[str] = field(default_factory=list)
    loss: str | None = None
    success: bool = False
    quality: dict = field(default_factory=dict)

    @property
    def pose(self) -> Pose:
        """The object-to-scene :class:`csdf.Pose` ``p = s R q + t``."""
        return Pose(self.rotation, self.translation, self.scale)

    @property
    def transform(self) -> np.ndarray:
        """(4, 4) object-to-scene transform ``[[s R, t], [0, 1]]``."""
        T = np.eye(4)
        T[:3, :3] = self.scale * self.rotation
        T[:3, 3] = self.translation
        return T

    def to_dict(self) -> dict:
        """JSON-ready dictionary."""
        return {
            "method": self.method, "transform": self.transform.tolist(),
            "rotation": self.rotation.tolist(), "translation": self.translation.tolist(),
            "scale": self.scale, "params": dict(self.params), "rmse": self.rmse,
            "inlier_fraction": self.inlier_fraction, "inlier_threshold": self.inlier_threshold,
            "converged": self.converged, "iterations": self.iterations,
            "seconds": self.seconds, "cost": self.cost, "notes": list(self.notes),
            "loss": self.loss, "success": self.success,
            "quality": _jsonable(self.quality),
        }


def _jsonable(v):
    """``v`` with NumPy scalars and non-finite floats made JSON-ready (inf -> None)."""
    if isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    if isinstance(v, (int, np.integer)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        return float(v) if math.isfinite(v) else None
    return v
