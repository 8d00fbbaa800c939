"""``csdf.render``: sphere-traced images with exact normals, shading and PNG output."""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import CsdfError
from ..field import Field
from .camera import Camera
from .trace import trace_field, trace_frame, trace_hits

__all__ = ["Render", "render", "auto_camera", "ALBEDO", "BACKGROUND"]

#: linear-RGB surface colour
ALBEDO = np.array([0.36, 0.55, 0.85])
#: background (sRGB, 0..1): top and bottom of a vertical gradient
BACKGROUND = (np.array([0.96, 0.96, 0.97]), np.array([0.82, 0.83, 0.86]))
#: unit direction towards the key light in the camera frame (x right, y down, z forward):
#: up and to the right, slightly behind the camera
LIGHT_CAM = np.array([0.45, -0.85, -0.15]) / np.linalg.norm([0.45, -0.85, -0.15])
AMBIENT = 0.22
KEY = 0.85


@dataclass
class Render:
    """A rendered image and its per-pixel geometry.

    Attributes:
        color: ``(H, W, 3)`` uint8 sRGB image.
        depth: ``(H, W)`` float64 depth of the first hit **along the optical axis** (the
            camera-frame z, model units), ``inf`` where the ray hits nothing. The
            distance along the ray is ``depth / d_z`` with ``d_z`` the z of the pixel's
            unit direction in the camera frame.
        normals: ``(H, W, 3)`` world-frame unit outward normals, the exact gradient of
            the field (forward-mode) normalised, taken ``1e-7`` of the scene size before
            the hit along the ray (zeros on the background).
        mask: ``(H, W)`` bool silhouette (the ray hit the surface).
        camera: the camera at the render's size.
        stats: ``{'seconds', 'iterations', 'evaluations', 'backend'}`` of the trace.
    """

    color: np.ndarray
    depth: np.ndarray
    normals: np.ndarray
    mask: np.ndarray
    camera: Camera
    stats: dict = field(default_factory=dict)
    #: ``(H, W)`` int64 the id of the scene instance each pixel sees (-1: background);
    #: None for a shape
    instance: np.ndarray | None = None

    def save(self, path: str | os.PathLike) -> Path:
        """Write :attr:`color` as a PNG (Pillow), atomically.

        Raises:
            CsdfError: the path does not end in ``.png``, Pillow is missing, or the
                folder does not exist.
        """
        from ..io import atomic_path

        target = Path(path)
        if target.suffix.lower() != ".png":
            raise CsdfError(f"render.save writes PNG files; {target.name!r} does not end in .png")
        try:
            from PIL import Image
        except ImportError:  # pragma: no cover - Pillow is a dependency
            raise CsdfError("saving images needs Pillow: pip install pillow") from None
        with atomic_path(target) as tmp:
            Image.fromarray(np.ascontiguousarray(self.color)).save(tmp, format="PNG")
        return target


# ------------------------------------------------------------------------- shading
def _soft_shadow(fld: Field, p: np.ndarray, light: np.ndarray, steps: int = 64,
                 k: float = 10.0) -> np.ndarray:
    """Soft shadow factor in ``[0, 1]`` (``(M,)``) for points ``p`` ``(M, 3)`` lit from
    direction ``light`` ``(3,)``: march towards the light and keep the smallest
    ``k * r / t`` (penumbra estimate; Quilez), ``r = f / L`` the unbounding radius.
    Shading only: with no Lipschitz bound (``L = inf``) it assumes ``L = 2``."""
    from .trace import ray_box

    L = fld.lipschitz if math.isfinite(fld.lipschitz) else 2.0
    frame = trace_frame(fld)
    res = np.ones(len(p))
    dirs = np.broadcast_to(light, p.shape)
    _, t1 = ray_box(p, dirs, frame.box)
    t = np.full(len(p), 2e-3 * frame.scale)
    idx = np.arange(len(p))
    lo, hi = 2e-3 * frame.scale, 0.1 * frame.scale
    for _ in range(steps):
        if idx.size == 0:
            break
        r = fld.value(p[idx] + t[idx, None] * light) / L
        res[idx] = np.minimum(res[idx], k * r / t[idx])
        t[idx] += np.clip(r, lo, hi)
        keep = (r > 1e-4 * frame.scale) & (t[idx] < t1[idx])
        idx = idx[keep]
    res = np.clip(res, 0.0, 1.0)
    return res * res * (3.0 - 2.0 * res)


def _ambient_occlusion(fld: Field, p: np.ndarray, n: np.ndarray,
                       samples: int = 6) -> np.ndarray:
    """Ambient occlusion in ``[0, 1]`` (``(M,)``, 1 = open) from field samples along the
    normals ``n`` ``(M, 3)`` at distances up to 6 % of the scene size (``L = inf``:
    assumes ``L = 2``)."""
    L = fld.lipschitz if math.isfinite(fld.lipschitz) else 2.0
    scale = trace_frame(fld).scale
    occ = np.zeros(len(p))
    w = 1.0
    total = 0.0
    for i in range(1, samples + 1):
        h = scale * 0.06 * i / samples
        r = fld.value(p + h * n) / L
        occ += w * np.clip(h - r, 0.0, h) / h
        total += w
        w *= 0.8
    return np.clip(1.0 - 1.2 * occ / total, 0.0, 1.0)


def _srgb(linear: np.ndarray) -> np.ndarray:
    c = np.clip(linear, 0.0, 1.0)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * np.power(c, 1 / 2.4) - 0.055)


def _shade(fld: Field, cam: Camera, p: np.ndarray, n: np.ndarray, dirs: np.ndarray,
           shadows: bool, ao: bool, albedo: np.ndarray | None = None) -> np.ndarray:
    """Linear RGB ``(M, 3)`` of hits ``p`` with world normals ``n`` seen along ``dirs``;
    ``albedo`` ``(M, 3)`` linear RGB per hit (default :data:`ALBEDO`)."""
    light = cam.R @ LIGHT_CAM
    up = cam.R @ np.array([0.0, -1.0, 0.0])
    ndl = np.clip(n @ light, 0.0, None)
    sky = 0.5 + 0.5 * (n @ up)  # hemisphere ambient: brighter facing up the image
    amb = AMBIENT * (0.6 + 0.4 * sky)
    if ao:
        amb = amb * _ambient_occlusion(fld, p, n)
    if shadows:
        lit = ndl > 0
        sh = np.zeros(len(p))
        if lit.any():
            sh[lit] = _soft_shadow(fld, p[lit] + n[lit] * (1e-3 * trace_frame(fld).scale),
                                   light)
        ndl = ndl * sh
    # a faint rim from the view direction keeps silhouettes of dark sides readable
    rim = 0.08 * np.clip(1.0 + (n * dirs).sum(1), 0.0, 1.0) ** 3
    base = ALBEDO[None, :] if albedo is None else albedo
    return base * (amb + KEY * ndl)[:, None] + rim[:, None]


def _linear(srgb: np.ndarray) -> np.ndarray:
    c = np.clip(srgb, 0.0, 1.0)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _albedo(fld, p: np.ndarray, params, check_ranges: bool,
            ids: np.ndarray | None = None) -> np.ndarray | None:
    """Linear RGB ``(M, 3)`` of a coloured shape (or scene, with the instance ``ids``
    of the hits) at world hits ``p`` (its ``color`` nodes, :mod:`csdf.colors`;
    uncoloured parts keep :data:`ALBEDO`), or None without colours."""
    from ..colors import colors_of, scene_has_colors

    if ids is not None:
        if not scene_has_colors(fld):
            return None
    elif fld.program.colors is None:
        return None
    rgba = colors_of(fld, p, params, check_ranges=check_ranges,
                     default=tuple(_srgb(ALBEDO)) + (1.0,), instances=ids)
    return _linear(np.nan_to_num(rgba[:, :3], nan=0.5))


def _background(h: int, w: int) -> np.ndarray:
    a = np.linspace(0.0, 1.0, h)[:, None, None]
    img = BACKGROUND[0] * (1 - a) + BACKGROUND[1] * a
    return np.broadcast_to(img, (h, w, 3))


# ------------------------------------------------------------------------- render
def auto_camera(shape, width: int = 640, height: int = 480, fov: float = 40.0, *,
                eye=None, target=None, direction=(1.2, -1.5, 1.0),
                params: dict | None = None, bounds=None, check_ranges: bool = True
                ) -> Camera:
    """A camera that frames a shape (z up in the image).

    Args:
        shape: a 3D :class:`csdf.Shape` or :class:`csdf.Program`.
        width, height: image size in pixels.
        fov: vertical field of view in degrees.
        eye: ``(3,)`` camera position; default: from ``target`` along ``direction``, far
            enough that the sphere around the shape's bounding box fits the view.
        target: ``(3,)`` point looked at; default the centre of the bounding box.
        direction: ``(3,)`` from the target towards the default eye (default the
            (+x, -y, +z) octant).
        params: parameter values ``{name: value}`` (they may change the bounds).
        bounds: ``(2, 3)`` box of the surface (default: the shape's, see :func:`render`).
        check_ranges: refuse a parameter value outside its declared range (False: use
            it anyway).

    Raises:
        CsdfError: bad arguments (see :meth:`Camera.look_at`), an unbounded shape;
            ParamError: a value outside its range (with ``check_ranges``).
    """
    from .camera import _vector, check_resolution

    w, h = check_resolution(width, height)
    b = shape.bounds if getattr(shape, "__csdf_scene__", False) else \
        trace_field(shape, params, "numpy", bounds, check_ranges=check_ranges).bounds
    centre = 0.5 * (b[0] + b[1])
    tgt = centre if target is None else _vector(target, "target")
    if eye is None:
        v = _vector(direction, "direction")
        if not np.linalg.norm(v) > 0:
            raise CsdfError("direction must not be zero")
        v = v / np.linalg.norm(v)
        half_v = math.radians(float(fov)) / 2.0
        if not 0.0 < half_v < math.pi / 2:
            raise CsdfError(f"fov must be in (0, 180) degrees, got {fov}")
        half = min(half_v, math.atan(math.tan(half_v) * w / h))
        radius = 0.5 * float(np.linalg.norm(b[1] - b[0])) + float(np.linalg.norm(tgt - centre))
        eye = tgt + v * (radius / math.sin(half))
    e = _vector(eye, "eye")
    up = (0.0, 0.0, 1.0)
    fwd = tgt - e
    if np.linalg.norm(np.cross(fwd, up)) <= 1e-9 * np.linalg.norm(fwd):
        up = (0.0, 1.0, 0.0)  # looking straight up or down
    return Camera.look_at(e, tgt, up=up, fov=fov, width=w, height=h)


def render(shape, camera: Camera, width: int | None = None, height: int | None = None,
           params: dict | None = None, shadows: bool = False, ao: bool = False,
           backend: str = "auto", *, bounds=None, check_ranges: bool = True) -> Render:
    """Sphere-trace an image of a shape (see :mod:`csdf.render.trace` for the tracer).

    Shading: Lambert from one key light (up and to the right of the camera) plus a
    hemisphere ambient term, in linear RGB, converted to sRGB; optional soft shadows
    (march towards the light) and ambient occlusion (field samples along the normal).
    A shape with ``color`` nodes is drawn in its colours (:mod:`csdf.colors`: the
    nearest coloured surface; uncoloured parts in the default blue).

    Args:
        shape: a 3D :class:`csdf.Shape`, a compiled :class:`csdf.Program`, or a
            :class:`csdf.Scene` (traced by :meth:`csdf.Scene.raycast`; the render's
            ``instance`` then gives the instance id per pixel).
        camera: a :class:`csdf.Camera` (OpenCV frame: x right, y down, z forward).
        width, height: image size in pixels (default the camera's); a different size
            scales the camera's intrinsics (:meth:`Camera.scaled`).
        params: parameter values ``{name: value}``.
        shadows: soft shadows from the key light.
        ao: ambient occlusion.
        backend: evaluation backend; ``'auto'`` uses the fast Numba kernels.
        bounds: ``(2, 3)`` box containing the surface; needed for unbounded shapes
            (default the shape's box, else one found by interval arithmetic).
        check_ranges: refuse a parameter value outside its declared range
            (:class:`csdf.ParamError` naming the range); False renders it anyway.

    Returns:
        :class:`Render`: ``color`` (H, W, 3) uint8, ``depth`` (H, W) along the optical
        axis (inf = background), ``normals`` (H, W, 3) world frame, ``mask`` (H, W).

    Raises:
        CsdfError: bad image size (0, over 8192 per side or 4096x4096 pixels), a camera
            that is not a :class:`Camera`, unknown parameters, an unbounded shape
            without ``bounds``; ParamError: a value outside its range (with
            ``check_ranges``).
    """
    if not isinstance(camera, Camera):
        raise CsdfError(f"camera must be a csdf.Camera, got {type(camera).__name__}")
    w = camera.width if width is None else width
    h = camera.height if height is None else height
    cam = camera.scaled(w, h)
    t_start = time.perf_counter()
    dcam = cam.pixel_directions()
    dirs = dcam @ cam.R.T
    ids = None
    if getattr(shape, "__csdf_scene__", False):
        if params or bounds is not None:
            raise CsdfError("a scene's instances carry their own parameters and bounds")
        fld = shape
        hits = shape.raycast(cam.t, dirs)
        t, normals, ids = hits.distance, hits.normal, hits.instance
        stats = {"iterations": None, "evaluations": None}
    else:
        fld = trace_field(shape, params, backend, bounds, check_ranges=check_ranges)
        t, normals, stats = trace_hits(fld, cam.t, dirs)
    hit = np.isfinite(t)
    depth = np.where(hit, t * dcam[:, 2], np.inf)
    color = _background(cam.height, cam.width).reshape(-1, 3).copy()
    hi = np.flatnonzero(hit)
    if hi.size:
        p = cam.t + t[hi, None] * dirs[hi]
        albedo = _albedo(fld, p, params, check_ranges, None if ids is None else ids[hi])
        color[hi] = _srgb(_shade(fld, cam, p, normals[hi], dirs[hi], shadows, ao, albedo))
    rgb = np.round(np.clip(color, 0.0, 1.0) * 255.0).astype(np.uint8)
    stats.update(seconds=time.perf_counter() - t_start,
                 backend=getattr(fld, "backend", "scene"))
    H, W = cam.height, cam.width
    return Render(color=rgb.reshape(H, W, 3), depth=depth.reshape(H, W),
                  normals=normals.reshape(H, W, 3), mask=hit.reshape(H, W), camera=cam,
                  stats=stats, instance=None if ids is None else ids.reshape(H, W))
