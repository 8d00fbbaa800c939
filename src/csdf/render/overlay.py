"""Fit overlays: the fitted model rendered with the measured points drawn over it.

A quick visual check of :func:`csdf.fit`: the scan is mapped into the object frame with
the recovered transform, the model is rendered with the recovered parameters, and every
point is drawn as a dot coloured by its residual (green: inlier, red: outlier). Points
hidden behind the rendered surface are drawn faded, so a good fit shows green dots on
the visible surface and nothing floating beside it.
"""

from __future__ import annotations

import numpy as np

from ..errors import CsdfError
from .image import auto_camera, render
from .trace import trace_field

__all__ = ["fit_overlay"]

INLIER = np.array([40, 200, 70], dtype=np.float64)
OUTLIER = np.array([230, 40, 40], dtype=np.float64)
MAX_DOTS = 200_000  # points drawn at most (a seeded subset beyond that)


def fit_overlay(shape, points, result, width: int = 640, height: int = 480,
                *, seed: int = 0, check_ranges: bool = True) -> np.ndarray:
    """Render the fitted model and draw the scan points over it.

    Args:
        shape: the 3D :class:`csdf.Shape` or :class:`csdf.Program` that was fitted.
        points: ``(N, 3)`` scan points in scene units (what was passed to ``fit``).
        result: the :class:`csdf.fit.FitResult` (object-to-scene ``p = s R q + t``).
        width, height: image size in pixels.
        seed: seed of the subset drawn when there are more than ``MAX_DOTS`` points.
        check_ranges: refuse result parameter values outside their declared ranges
            (a fit keeps estimated ones inside; a held one is as it was given).

    Returns:
        ``(height, width, 3)`` uint8 sRGB image.

    Raises:
        CsdfError: points that are not an ``(N, 3)`` array, or a bad image size;
            ParamError: a value outside its range (with ``check_ranges``).
    """
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise CsdfError(f"points must be an (N, 3) array, got shape {pts.shape}")
    pts = pts[np.isfinite(pts).all(axis=1)]
    if len(pts) > MAX_DOTS:
        pts = pts[np.random.default_rng(seed).choice(len(pts), MAX_DOTS, replace=False)]
    pose = result.pose
    s = pose.scale
    q = pose.apply_inverse(pts)  # object frame: q = R^T (p - t) / s
    params = dict(result.params)
    fld = trace_field(shape, params, "numpy", what="fit_overlay", check_ranges=check_ranges)
    prog = fld.program
    # frame the model and the points (their 1-99 % box: a few outliers far away must not
    # shrink the view to nothing)
    box = fld.bounds
    if len(q):
        lo, hi = np.percentile(q, 1, axis=0), np.percentile(q, 99, axis=0)
        box = np.stack([np.minimum(box[0], lo), np.maximum(box[1], hi)])
    # the values were checked (or accepted) above
    cam = auto_camera(prog, width, height, params=params, bounds=box, check_ranges=False)
    img = render(prog, cam, params=params, check_ranges=False)
    resid = np.abs(prog(q, params, check_ranges=False)) * s  # scene units, as the fit measures them
    inlier = resid <= float(result.inlier_threshold)

    uv, depth = cam.project(q)
    ok = np.isfinite(uv).all(axis=1)
    px = np.zeros((len(q), 2), np.int64)
    px[ok] = np.floor(uv[ok]).astype(np.int64)
    ok &= (px[:, 0] >= 0) & (px[:, 0] < width) & (px[:, 1] >= 0) & (px[:, 1] < height)
    surf = img.depth[px[ok, 1], px[ok, 0]]
    # a point further than the rendered surface (beyond a small tolerance) is hidden
    tol = 0.01 * float(np.linalg.norm(cam.t - q[ok].mean(axis=0))) if ok.any() else 0.0
    visible = np.zeros(len(q), bool)
    visible[ok] = depth[ok] <= surf + tol
    color = img.color.astype(np.float64)
    # far points first, so near ones end on top
    order = np.argsort(-np.where(ok, depth, -np.inf))
    order = order[ok[order]]
    u, v = px[order, 0], px[order, 1]
    dot = np.where(inlier[order, None], INLIER, OUTLIER)
    alpha = np.where(visible[order], 0.9, 0.3)[:, None]
    for du in (0, 1):  # 2x2 dots
        for dv in (0, 1):
            uu, vv = np.minimum(u + du, width - 1), np.minimum(v + dv, height - 1)
            color[vv, uu] = (1 - alpha) * color[vv, uu] + alpha * dot
    return np.clip(np.rint(color), 0, 255).astype(np.uint8)
