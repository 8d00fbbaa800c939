"""Checks of the arguments of :mod:`csdf.metrics`: each returns a clean float64 array
(or a :class:`csdf.Pose` / :class:`csdf.Camera`) or raises :class:`csdf.CsdfError`
naming the argument and the shape it expects."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..errors import CsdfError
from ..pose import Pose, as_pose
from ..render.camera import Camera

__all__ = ["model_pts", "pose_arg", "symmetry_arg", "camera_arg", "depth_arg",
           "positive", "nonnegative", "thresholds_arg", "errors_arg", "per_instance"]

#: ``|R^T R - I|`` allowed in a given symmetry rotation
ROT_TOL = 1e-6


def _float_array(value: Any, what: str, expected: str) -> np.ndarray:
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise CsdfError(f"{what} must be an array of numbers of shape {expected}") from None
    return a


def model_pts(points: Any, what: str = "points") -> np.ndarray:
    """``points`` as a ``(N, 3)`` finite float64 array with ``N >= 1``."""
    a = _float_array(points, what, "(N, 3)")
    if a.ndim != 2 or a.shape[1] != 3 or a.shape[0] < 1:
        raise CsdfError(f"{what} must have shape (N, 3) with N >= 1, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise CsdfError(f"{what} must be finite")
    return a


def pose_arg(pose: Any, what: str) -> Pose:
    """A model-to-camera :class:`csdf.Pose` from a Pose or a ``(4, 4)`` matrix."""
    if pose is None:
        raise CsdfError(f"{what} must be a csdf.Pose or a (4, 4) model-to-camera matrix, "
                        "got None")
    return as_pose(pose, what)


def symmetry_arg(symmetries: Any, what: str = "symmetries") -> np.ndarray:
    """Symmetry transforms as ``(K, 4, 4)`` float64 with the identity first.

    Accepts ``None`` (the identity only), a ``(3, 3)`` / ``(4, 4)`` matrix or a stack
    ``(K, 3, 3)`` (rotations about the model origin) / ``(K, 4, 4)`` (rigid transforms
    ``[[R, t], [0, 0, 0, 1]]``). The identity is added when missing (to 1e-9).

    Raises:
        CsdfError: another shape, non-finite entries, a block that is not a rotation, or
            a last row that is not ``(0, 0, 0, 1)``.
    """
    if symmetries is None:
        return np.eye(4)[None]
    expected = "(K, 3, 3) or (K, 4, 4)"
    a = _float_array(symmetries, what, expected)
    if a.ndim == 2:
        a = a[None]
    if a.ndim != 3 or a.shape[1:] not in ((3, 3), (4, 4)) or a.shape[0] < 1:
        raise CsdfError(f"{what} must have shape {expected}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise CsdfError(f"{what} must be finite")
    if a.shape[1] == 3:
        T = np.tile(np.eye(4), (len(a), 1, 1))
        T[:, :3, :3] = a
        a = T
    elif np.max(np.abs(a[:, 3] - [0.0, 0.0, 0.0, 1.0])) > 1e-9:
        raise CsdfError(f"{what}: the last row of every (4, 4) transform must be (0, 0, 0, 1)")
    R = a[:, :3, :3]
    ortho = np.abs(np.einsum("kji,kjl->kil", R, R) - np.eye(3)).max(axis=(1, 2))
    bad = np.flatnonzero((ortho > ROT_TOL) | (np.linalg.det(R) < 0))
    if bad.size:
        raise CsdfError(f"{what}[{int(bad[0])}] is not a rotation (orthonormal, determinant "
                        "+1): symmetries are proper rigid transforms")
    is_id = np.abs(a - np.eye(4)).max(axis=(1, 2)) <= 1e-9
    if is_id.any():
        first = int(np.flatnonzero(is_id)[0])
        order = [first] + [k for k in range(len(a)) if k != first]
        return a[order]
    return np.concatenate([np.eye(4)[None], a])


def camera_arg(camera: Any, what: str = "camera") -> Camera:
    """``camera`` if it is a :class:`csdf.Camera`."""
    if not isinstance(camera, Camera):
        raise CsdfError(f"{what} must be a csdf.Camera, got {type(camera).__name__}")
    return camera


def depth_arg(depth: Any, camera: Camera, what: str = "depth") -> np.ndarray:
    """The test depth map as ``(H, W)`` float64 at the camera's size: ``0`` and NaN
    mean missing (returned as 0), ``inf`` is allowed (nothing in front); negative
    values are refused."""
    expected = f"(H, W) = ({camera.height}, {camera.width})"
    a = _float_array(depth, what, expected)
    if a.shape != (camera.height, camera.width):
        raise CsdfError(f"{what} must have shape {expected} (the camera's image size), "
                        f"got {a.shape}")
    a = np.where(np.isnan(a), 0.0, a)
    if np.any(a < 0):
        raise CsdfError(f"{what} must be >= 0 (0 = missing), got a minimum of {a.min():g}")
    return a


def positive(value: Any, what: str, allow_zero: bool = False) -> float:
    """A finite number ``> 0`` (``>= 0`` with ``allow_zero``)."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise CsdfError(f"{what} must be a number, got {value!r}") from None
    if not math.isfinite(x) or x < 0 or (x == 0 and not allow_zero):
        bound = ">= 0" if allow_zero else "> 0"
        raise CsdfError(f"{what} must be a finite number {bound}, got {x:g}")
    return x


def nonnegative(value: Any, what: str) -> float:
    """A finite number ``>= 0``."""
    return positive(value, what, allow_zero=True)


def thresholds_arg(thresholds: Any, what: str = "thresholds") -> tuple[np.ndarray, bool]:
    """``(thresholds (M,) finite float64, was a scalar)``."""
    a = _float_array(thresholds, what, "() or (M,)")
    if a.ndim > 1 or a.size < 1:
        raise CsdfError(f"{what} must be a number or have shape (M,) with M >= 1, "
                        f"got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise CsdfError(f"{what} must be finite")
    return a.reshape(-1), a.ndim == 0


def errors_arg(errors: Any, what: str = "errors", ndim: tuple[int, ...] = (1, 2)
               ) -> np.ndarray:
    """Per-instance errors ``(N,)`` (or ``(N, T)``) as float64; NaN becomes ``inf`` (a
    missing estimate: never correct); negative values are refused."""
    shapes = " or ".join({1: "(N,)", 2: "(N, T)"}[d] for d in ndim)
    a = _float_array(errors, what, shapes)
    if a.ndim not in ndim or a.shape[0] < 1:
        raise CsdfError(f"{what} must have shape {shapes} with N >= 1, got {a.shape}")
    a = np.where(np.isnan(a), np.inf, a)
    if np.any(a < 0):
        raise CsdfError(f"{what} must be >= 0 (inf or NaN: no estimate), got {a.min():g}")
    return a


def per_instance(value: Any, n: int, what: str) -> np.ndarray:
    """A positive finite number or ``(N,)`` array of them, as ``(N,)`` float64."""
    a = _float_array(value, what, f"() or ({n},)")
    if a.ndim == 0:
        a = np.full(n, float(a))
    if a.shape != (n,):
        raise CsdfError(f"{what} must be a number or have shape ({n},) (one per instance), "
                        f"got {a.shape}")
    if not (np.all(np.isfinite(a)) and np.all(a > 0)):
        raise CsdfError(f"{what} must be finite and > 0")
    return a
