"""VSD, the visible surface discrepancy (BOP 2019), on depth rendered by csdf's own
sphere tracer, and the visible fraction of an object in a depth image.

The model is traced in its own frame, as :func:`csdf.scan` does: for a model-to-camera
pose ``P`` the rays leave ``P^-1(0)`` (the camera centre in the model frame) along
``R^T d`` (``d`` the unit pixel directions in the camera frame), so one field serves
every pose. The distance along a unit ray is the distance from the camera centre; a
test depth ``z`` (along the optical axis) becomes the distance ``z / d_z``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import CsdfError
from ..field import Field
from ..pose import Pose
from ..render.camera import Camera
from ..render.trace import trace_field, trace_hits
from .inputs import camera_arg, depth_arg, nonnegative, pose_arg, positive, thresholds_arg

__all__ = ["vsd", "visible_fraction", "VSD_TAUS"]

#: BOP 2019 misalignment tolerances tau of VSD, as fractions of the object's diameter
VSD_TAUS = tuple(round(0.05 * k, 2) for k in range(1, 11))


def _model_distance(fld: Field, pose: Pose, dirs: np.ndarray) -> np.ndarray:
    """Distance ``(H*W,)`` from the camera centre to the model posed by ``pose`` along
    the unit camera-frame rays ``dirs`` ``(H*W, 3)``; ``inf`` where a ray misses."""
    origin = pose.apply_inverse(np.zeros(3))
    t, _, _ = trace_hits(fld, origin, np.ascontiguousarray(pose.apply_inverse_dirs(dirs)))
    return t * pose.scale


def _visible(dist: np.ndarray, test: np.ndarray, missing: np.ndarray,
             delta: float) -> np.ndarray:
    """Visibility mask ``(H*W,)``: the model is present and not behind the test surface
    by more than ``delta``, or the test depth is missing."""
    with np.errstate(invalid="ignore"):
        return np.isfinite(dist) & (missing | (dist - test <= delta))


class _Scene:
    """The checked inputs shared by :func:`vsd` and :func:`visible_fraction`: the
    field, the camera's unit ray directions and the test image's distance map."""

    def __init__(self, shape: Any, depth: Any, camera: Any, params: dict | None,
                 backend: str, bounds: Any, check_ranges: bool, what: str):
        cam: Camera = camera_arg(camera)
        z = depth_arg(depth, cam)
        self.field = trace_field(shape, params, backend, bounds, what=what,
                                 check_ranges=check_ranges)
        self.dirs = cam.pixel_directions()
        self.missing = z.reshape(-1) == 0.0
        self.test = z.reshape(-1) / self.dirs[:, 2]

    def visible(self, pose: Pose, delta: float) -> tuple[np.ndarray, np.ndarray]:
        """``(distance (H*W,), visibility mask (H*W,))`` of the model at ``pose``."""
        dist = _model_distance(self.field, pose, self.dirs)
        return dist, _visible(dist, self.test, self.missing, delta)


def _taus(tau: Any, diameter: Any) -> tuple[np.ndarray, bool]:
    if tau is not None:
        taus, scalar = thresholds_arg(tau, "tau")
        if np.any(taus <= 0):
            raise CsdfError("tau must be > 0 (model units)")
        return taus, scalar
    if diameter is None:
        raise CsdfError("vsd needs tau (model units) or diameter (for BOP's taus, "
                        "0.05 to 0.5 of the diameter)")
    return np.asarray(VSD_TAUS) * positive(diameter, "diameter"), False


def vsd(shape: Any, est_pose: Any, gt_pose: Any, depth: Any, camera: Any, *,
        delta: float, tau: Any = None, diameter: float | None = None,
        params: dict | None = None, backend: str = "auto", bounds: Any = None,
        check_ranges: bool = True) -> float | np.ndarray:
    """Visible surface discrepancy (BOP 2019).

    The model's distance maps ``D̂``, ``D̄`` (from the camera centre) at the estimated
    and the true pose are sphere-traced at the camera's pixels; with the test image's
    distance map ``D`` the visibility masks are the pixels where the model is present
    and ``D_model - D <= delta`` or the test depth is missing; then::

        e = (#{p in V̂ ∩ V̄ : |D̂ - D̄| >= tau} + #(V̂ ∪ V̄ minus V̂ ∩ V̄)) / #(V̂ ∪ V̄)

    and ``e = 1`` when the union is empty.

    Units: every length is in the model's units (metres for csdf models). BOP's
    ``delta`` is 15 mm: pass ``delta=0.015`` for a model in metres, ``15`` in mm.

    Args:
        shape: a 3D :class:`csdf.Shape`, :class:`csdf.Program` or field (model frame).
        est_pose, gt_pose: model-to-camera poses (:class:`csdf.Pose` or ``(4, 4)``).
        depth: ``(H, W)`` test depth along the optical axis (OpenCV camera frame), model
            units, at the camera's size; ``0`` (or NaN) = missing, ``inf`` = nothing.
        camera: a :class:`csdf.Camera`; only its intrinsics and size are used.
        delta: the visibility tolerance, model units (required: BOP's 15 mm in the
            model's units).
        tau: the misalignment tolerance, a number or ``(T,)``, model units; default:
            BOP's ``VSD_TAUS`` (0.05, 0.10, ..., 0.50) times ``diameter``.
        diameter: the object's diameter (:func:`csdf.metrics.diameter`), needed
            without ``tau``.
        params, backend, bounds, check_ranges: as for :func:`csdf.render`.

    Returns:
        The error in ``[0, 1]``: a float for a number ``tau``, else ``(T,)`` float64
        (one per tau, in order).

    Raises:
        CsdfError: a bad argument, naming it and the shape it expects; neither ``tau``
            nor ``diameter``; what :func:`csdf.render` raises for the shape.
    """
    d = nonnegative(delta, "delta")
    taus, scalar = _taus(tau, diameter)
    est = pose_arg(est_pose, "est_pose")
    gt = pose_arg(gt_pose, "gt_pose")
    scene = _Scene(shape, depth, camera, params, backend, bounds, check_ranges, "vsd")
    d_est, v_est = scene.visible(est, d)
    d_gt, v_gt = scene.visible(gt, d)
    both = v_est & v_gt
    n_union = int(np.count_nonzero(v_est | v_gt))
    if n_union == 0:
        e = np.ones(len(taus))
    else:
        only_one = n_union - int(np.count_nonzero(both))
        diff = np.abs(d_est[both] - d_gt[both])
        far = np.count_nonzero(diff[:, None] >= taus[None, :], axis=0)
        e = (far + only_one) / n_union
    return float(e[0]) if scalar else e


def visible_fraction(shape: Any, pose: Any, depth: Any, camera: Any, *, delta: float,
                     params: dict | None = None, backend: str = "auto",
                     bounds: Any = None, check_ranges: bool = True) -> float:
    """The fraction of the object's silhouette that is visible in a depth image: the
    pixels of VSD's visibility mask (model present and ``D_model - D <= delta`` or the
    depth missing) over the pixels where the model is present (BOP counts an instance
    when this is at least 0.1; :func:`csdf.metrics.recall`'s ``visib_fract``).

    Args:
        shape: a 3D :class:`csdf.Shape`, :class:`csdf.Program` or field.
        pose: the model-to-camera pose (:class:`csdf.Pose` or ``(4, 4)``).
        depth, camera, delta, params, backend, bounds, check_ranges: as for :func:`vsd`.

    Returns:
        The fraction in ``[0, 1]``; 0 when the object is not in the image.

    Raises:
        CsdfError: a bad argument, naming it and the shape it expects.
    """
    d = nonnegative(delta, "delta")
    p = pose_arg(pose, "pose")
    scene = _Scene(shape, depth, camera, params, backend, bounds, check_ranges,
                   "visible_fraction")
    dist, vis = scene.visible(p, d)
    n = int(np.count_nonzero(np.isfinite(dist)))
    return int(np.count_nonzero(vis)) / n if n else 0.0
