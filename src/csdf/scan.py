"""``csdf.scan``: a synthetic depth sensor.

A pinhole depth camera (:class:`csdf.Camera`, OpenCV frame: x right, y down, z forward)
casts one ray per pixel centre at a shape placed in the world by ``object_pose`` and
returns the first hits as a point cloud **in the camera frame**, with exact normals
(from the field's gradient) in the same frame. Like a real sensor it sees only first
hits (self-occlusion comes from the ray casting), drops grazing returns, and can add
Gaussian range noise and uniform outliers.
"""

from __future__ import annotations

import math

import numpy as np

from .errors import CsdfError
from .pose import as_pose
from .render.camera import Camera
from .render.trace import trace_field, trace_hits
from .seeds import rng_arg

__all__ = ["scan", "MIN_COS"]

#: returns with ``|normal . ray| <`` this (grazing incidence, ~87 degrees) are dropped
MIN_COS = 0.05


def _fraction(v, name: str, hi: float = math.inf) -> float:
    try:
        x = float(v)
    except (TypeError, ValueError):
        raise CsdfError(f"{name} must be a real number, got {v!r}") from None
    if not (math.isfinite(x) and 0.0 <= x <= hi):
        rng = f"[0, {hi:g}]" if math.isfinite(hi) else ">= 0 and finite"
        raise CsdfError(f"{name} must be {rng}, got {x}")
    return x


def scan(shape, camera: Camera, width: int | None = None, height: int | None = None,
         noise: float = 0.0, outliers: float = 0.0, seed=None, object_pose=None,
         params: dict | None = None, *, min_cos: float = MIN_COS, backend: str = "auto",
         bounds=None, check_ranges: bool = True, colors: bool = False) -> tuple:
    """Simulate a depth sensor: the visible surface points of a shape as a point cloud.

    Args:
        shape: a 3D :class:`csdf.Shape` or :class:`csdf.Program` (in its own frame), or
            a :class:`csdf.Scene`.
        camera: the sensor, a :class:`csdf.Camera` (pose in world coordinates).
        width, height: sensor resolution in pixels (default the camera's; another size
            scales the intrinsics). One ray per pixel centre.
        noise: standard deviation of Gaussian range noise, model units (metres), applied
            along each ray.
        outliers: fraction in ``[0, 1]`` of the returned points replaced by outliers:
            each point independently with this probability (so the count is binomial),
            replaced by a point uniform in the view frustum (uniform pixel position and
            uniform depth between the nearest and farthest depth of the true returns),
            with a random unit normal turned towards the camera.
        seed: seed of ``numpy.random.default_rng`` (an int or a Generator); equal seeds
            give identical clouds.
        object_pose: the rigid object-to-world :class:`csdf.Pose` placing the shape in
            the world, or its ``(4, 4)`` matrix (default identity). Rays are moved into
            the object's frame; the shape is not rebuilt.
        params: parameter values ``{name: value}``.
        min_cos: returns whose normal makes ``|n . ray| < min_cos`` are dropped (grazing
            incidence), as are back-facing ones (a camera inside the solid).
        backend: evaluation backend (``'auto'``: the fast Numba kernels).
        bounds: ``(2, 3)`` box containing the surface in the object frame (for unbounded
            shapes).
        check_ranges: refuse a parameter value outside its declared range
            (:class:`csdf.ParamError` naming the range); False scans it anyway.
        colors: an RGB-D sensor: also each point's colour, the shape's (or the hit
            instance's) at the surface point the ray hit (:func:`csdf.colors.colors_of`;
            outliers get a random
            colour drawn after everything else, so the points are those of
            ``colors=False``).

    Returns:
        ``(points (M, 3), normals (M, 3))`` float64 in the **camera frame** (OpenCV),
        in row-major pixel order; normals are unit and face the camera
        (``n . (0 - p) > 0``). ``M`` is 0 when nothing is seen. For a
        :class:`csdf.Scene` (traced by :meth:`csdf.Scene.raycast`, ``object_pose``
        placing the whole scene): ``(points, normals, instance (M,))``, the id of the
        instance each point lies on (-1 for outliers). With ``colors``, ``(points,
        normals, colors (M, 4))`` RGBA in ``[0, 1]`` (a scene's: ``(points, normals,
        instance, colors)``, each point in its instance's colours).

    Raises:
        CsdfError: bad resolution, non-finite or negative noise, an outlier fraction
            outside ``[0, 1]``, a pose that is not rigid, unknown parameters;
            ParamError: a value outside its range (with ``check_ranges``).
    """
    if not isinstance(camera, Camera):
        raise CsdfError(f"camera must be a csdf.Camera, got {type(camera).__name__}")
    cam = camera.scaled(camera.width if width is None else width,
                        camera.height if height is None else height)
    noise = _fraction(noise, "noise")
    outliers = _fraction(outliers, "outliers", 1.0)
    min_cos = _fraction(min_cos, "min_cos", 1.0)
    pose = as_pose(object_pose, "object_pose", rigid=True)
    rng = rng_arg(seed)
    scene = getattr(shape, "__csdf_scene__", False)
    if scene and (params or bounds is not None):
        raise CsdfError("a scene's instances carry their own parameters and bounds")

    dcam = cam.pixel_directions()  # (N, 3) unit, camera frame
    M = pose.rotation.T @ cam.R  # camera frame -> object frame (rotation)
    d_obj = dcam @ M.T
    o_obj = pose.apply_inverse(cam.t)
    if scene:
        hits = shape.raycast(o_obj, d_obj)
        t, n_obj, ids = hits.distance, hits.normal, hits.instance
    else:
        fld = trace_field(shape, params, backend, bounds, what="scan",
                          check_ranges=check_ranges)
        t, n_obj, _ = trace_hits(fld, o_obj, d_obj)
    with np.errstate(invalid="ignore"):
        facing = -(n_obj * d_obj).sum(1)
        keep = np.isfinite(t) & (facing >= min_cos)
    t, dk = t[keep], dcam[keep]
    ids = ids[keep] if scene else None
    rgba = None
    if colors:
        from .colors import colors_of

        hit_obj = o_obj + t[:, None] * d_obj[keep]
        rgba = colors_of(shape if scene else fld, hit_obj, check_ranges=check_ranges,
                         instances=ids)
    normals = n_obj[keep] @ M  # object frame -> camera frame: M^T n
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    m = len(t)
    if noise > 0:
        t = np.maximum(t + rng.normal(0.0, noise, m), 0.0)
    points = t[:, None] * dk
    if outliers > 0 and m:
        sel = np.flatnonzero(rng.random(m) < outliers)
        k = len(sel)
        z_true = (t[:, None] * dk)[:, 2]
        zlo, zhi = float(z_true.min()), float(z_true.max())
        u = rng.uniform(-0.5, cam.width - 0.5, k)
        v = rng.uniform(-0.5, cam.height - 0.5, k)
        z = rng.uniform(zlo, zhi, k)
        points[sel] = np.stack([(u - cam.cx) / cam.fx * z, (v - cam.cy) / cam.fy * z, z], 1)
        rn = rng.normal(size=(k, 3))
        rn /= np.maximum(np.linalg.norm(rn, axis=1, keepdims=True), 1e-300)
        towards = (rn * points[sel]).sum(1) > 0  # facing away from the camera: flip
        rn[towards] *= -1.0
        normals[sel] = rn
        if scene:
            ids[sel] = -1
        if rgba is not None:
            rgba[sel] = np.column_stack([rng.random((k, 3)), np.ones(k)])
    if rgba is not None:
        return (points, normals, ids, rgba) if scene else (points, normals, rgba)
    return (points, normals, ids) if scene else (points, normals)
