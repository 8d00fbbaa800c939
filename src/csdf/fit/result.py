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
            "loss": self.loss,
        }
