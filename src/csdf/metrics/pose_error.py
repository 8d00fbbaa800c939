"""Pose errors over model points: MSSD, MSPD (BOP 2019), ADD and ADD-S (Hinterstoisser).

Notation: model points ``x`` (model frame), estimated pose ``P̂ = (R̂, t̂)``, ground truth
``P̄ = (R̄, t̄)`` (model-to-camera), symmetry transforms ``S`` (model frame, identity
included). A :class:`csdf.Pose` with a scale ``s`` maps ``x`` to ``s R x + t``.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np

from ..pose import Pose
from .inputs import camera_arg, model_pts, pose_arg, symmetry_arg

__all__ = ["mssd", "mspd", "add", "adds"]

#: points x symmetries handled at once (memory: about 50 bytes each)
_CHUNK = 1 << 21


def _sym_chunks(x: np.ndarray, syms: np.ndarray, gt: Pose) -> Iterator[np.ndarray]:
    """Ground-truth camera-frame points of every symmetry, ``(k, N, 3)`` per chunk of
    ``k`` symmetries (in order): ``P̄ (S x)``."""
    k = max(1, _CHUNK // len(x))
    for a in range(0, len(syms), k):
        S = syms[a:a + k]
        sx = np.einsum("kij,nj->kni", S[:, :3, :3], x) + S[:, None, :3, 3]
        yield gt.apply(sx)



def _inputs(points, est_pose, gt_pose):
    """The checked model points and the two poses of a pose error."""
    return model_pts(points), pose_arg(est_pose, "est_pose"), pose_arg(gt_pose, "gt_pose")

def mssd(points: Any, est_pose: Any, gt_pose: Any, symmetries: Any = None) -> float:
    """Maximum symmetry-aware surface distance (BOP 2019).

    ``e = min over S of max over x of || P̂ x - P̄ (S x) ||``.

    Args:
        points: ``(N, 3)`` model points in the model frame (e.g.
            :func:`csdf.metrics.model_points`), model units.
        est_pose, gt_pose: the estimated and true model-to-camera poses
            (:class:`csdf.Pose` or ``(4, 4)`` matrices).
        symmetries: ``(K, 3, 3)`` rotations or ``(K, 4, 4)`` rigid transforms in the
            model frame (e.g. :func:`csdf.metrics.symmetries`); the identity is added
            when missing; ``None``: the identity only.

    Returns:
        The error in model units (BOP: correct when ``e < theta * diameter``).

    Raises:
        CsdfError: a bad argument, naming it and the shape it expects.
    """
    x, est, gt = _inputs(points, est_pose, gt_pose)
    syms = symmetry_arg(symmetries)
    e = est.apply(x)
    best = np.inf
    for y in _sym_chunks(x, syms, gt):
        d = np.sqrt(np.sum((y - e) ** 2, axis=2)).max(axis=1)
        best = min(best, float(d.min()))
    return best


def _project(camera, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixels ``(..., 2)`` of camera-frame points ``p`` ``(..., 3)`` and whether each
    lies in front of the camera (``z > 0``) ``(...)``."""
    z = p[..., 2]
    ok = z > 0
    zs = np.where(ok, z, 1.0)
    uv = np.stack([camera.fx * p[..., 0] / zs + camera.cx,
                   camera.fy * p[..., 1] / zs + camera.cy], axis=-1)
    return uv, ok


def mspd(points: Any, est_pose: Any, gt_pose: Any, camera: Any,
         symmetries: Any = None) -> float:
    """Maximum symmetry-aware projection distance (BOP 2019), in pixels.

    ``e = min over S of max over x of || proj(P̂ x) - proj(P̄ (S x)) ||`` with
    ``proj`` the pinhole projection by the camera's intrinsics (OpenCV: ``u = fx x / z
    + cx``, ``v = fy y / z + cy``).

    The error is in pixels of this camera, **not** multiplied by ``640 / image_width``:
    :func:`csdf.metrics.average_recall` (``metric='mspd'``) and
    :func:`csdf.metrics.recall` (``scale=image_width / 640``) apply BOP's normalisation.
    A model point at or behind the camera's plane (``z <= 0``) under the estimate makes
    the error ``inf``; under the ground truth, it rules out that symmetry.

    Args:
        points: ``(N, 3)`` model points in the model frame, model units.
        est_pose, gt_pose: model-to-camera poses (:class:`csdf.Pose` or ``(4, 4)``).
        camera: a :class:`csdf.Camera`; only its intrinsics are used (the poses are
            already in the camera frame).
        symmetries: as for :func:`mssd`.

    Returns:
        The error in pixels.

    Raises:
        CsdfError: a bad argument, naming it and the shape it expects.
    """
    x, est, gt = _inputs(points, est_pose, gt_pose)
    cam = camera_arg(camera)
    syms = symmetry_arg(symmetries)
    ue, ok_e = _project(cam, est.apply(x))
    if not ok_e.all():
        return float("inf")
    best = np.inf
    for y in _sym_chunks(x, syms, gt):
        ug, ok_g = _project(cam, y)
        d = np.sqrt(np.sum((ug - ue) ** 2, axis=2)).max(axis=1)
        d[~ok_g.all(axis=1)] = np.inf
        best = min(best, float(d.min()))
    return best


def add(points: Any, est_pose: Any, gt_pose: Any) -> float:
    """ADD (Hinterstoisser et al. 2012): ``mean over x of || P̂ x - P̄ x ||``.

    Args:
        points: ``(N, 3)`` model points in the model frame, model units.
        est_pose, gt_pose: model-to-camera poses (:class:`csdf.Pose` or ``(4, 4)``).

    Returns:
        The error in model units (correct when below 10 % of the diameter).

    Raises:
        CsdfError: a bad argument, naming it and the shape it expects.
    """
    x, est, gt = _inputs(points, est_pose, gt_pose)
    return float(np.sqrt(np.sum((est.apply(x) - gt.apply(x)) ** 2, axis=1)).mean())


def adds(points: Any, est_pose: Any, gt_pose: Any) -> float:
    """ADD-S: ``mean over x of min over y of || P̂ x - P̄ y ||`` (the distance from each
    estimated point to the nearest true point; a k-d tree, :class:`scipy.spatial.cKDTree`).

    Args:
        points: ``(N, 3)`` model points in the model frame, model units.
        est_pose, gt_pose: model-to-camera poses (:class:`csdf.Pose` or ``(4, 4)``).

    Returns:
        The error in model units.

    Raises:
        CsdfError: a bad argument, naming it and the shape it expects.
    """
    from scipy.spatial import cKDTree

    x, est, gt = _inputs(points, est_pose, gt_pose)
    d, _ = cKDTree(gt.apply(x)).query(est.apply(x), k=1)
    return float(np.mean(d))
