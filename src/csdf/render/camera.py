"""A pinhole camera with OpenCV conventions.

Frames
    The camera frame is OpenCV's: **x right, y down, z forward** (the optical axis),
    origin at the centre of projection. A camera's pose is the camera-to-world rigid
    transform ``p_world = R @ p_cam + t``: the columns of ``R`` are the camera's x, y and
    z axes in world coordinates and ``t`` is the camera's position in the world.

Pixels
    Pixel ``(u, v)`` is column ``u``, row ``v``; integer coordinates are pixel *centres*
    (OpenCV), so an image of width ``W`` spans ``u`` in ``[-0.5, W - 0.5]`` and a centred
    principal point is ``cx = (W - 1) / 2``. Projection of a camera-frame point
    ``(x, y, z)`` is ``u = fx * x / z + cx``, ``v = fy * y / z + cy``.

All lengths (``t``, points, depths) are in model units (metres for a sensor); focal
lengths and principal points are in pixels.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ..errors import CsdfError
from ..pose import check_rotation

__all__ = ["Camera", "MAX_SIDE", "MAX_PIXELS", "check_resolution"]

#: largest image side accepted by rendering and scanning, in pixels
MAX_SIDE = 8192
#: largest number of pixels of one image (memory: about 200 bytes per pixel while tracing)
MAX_PIXELS = 4096 * 4096


def check_resolution(width, height) -> tuple[int, int]:
    """Validate an image size; returns ``(width, height)`` as ints.

    Raises:
        CsdfError: not positive integers, or over :data:`MAX_SIDE` / :data:`MAX_PIXELS`.
    """
    out = []
    for name, v in (("width", width), ("height", height)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
            raise CsdfError(f"{name} must be a positive integer number of pixels, got {v!r}")
        if v < 1:
            raise CsdfError(f"{name} must be at least 1 pixel, got {int(v)}")
        if v > MAX_SIDE:
            raise CsdfError(f"{name} of {int(v)} pixels is over the limit of {MAX_SIDE}")
        out.append(int(v))
    if out[0] * out[1] > MAX_PIXELS:
        raise CsdfError(
            f"image of {out[0]}x{out[1]} pixels is over the limit of {MAX_PIXELS:,} pixels "
            f"({int(math.isqrt(MAX_PIXELS))}x{int(math.isqrt(MAX_PIXELS))}); render tiles "
            "with cameras of shifted principal points instead"
        )
    return out[0], out[1]


def _finite_scalar(v, name: str, positive: bool = False) -> float:
    try:
        x = float(v)
    except (TypeError, ValueError):
        raise CsdfError(f"camera {name} must be a real number, got {v!r}") from None
    if not math.isfinite(x):
        raise CsdfError(f"camera {name} must be finite, got {x}")
    if positive and x <= 0:
        raise CsdfError(f"camera {name} must be positive, got {x}")
    return x


def _vector(v, name: str, n: int = 3) -> np.ndarray:
    try:
        a = np.asarray(v, dtype=np.float64)
    except (TypeError, ValueError):
        raise CsdfError(f"{name} must be {n} real numbers, got {v!r}") from None
    if a.shape != (n,):
        raise CsdfError(f"{name} must have shape ({n},), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise CsdfError(f"{name} must be finite, got {a.tolist()}")
    return a


def _rotation(R, name: str = "camera rotation R") -> np.ndarray:
    return check_rotation(R, name)


def _points(points, name: str = "points") -> tuple[np.ndarray, tuple[int, ...]]:
    try:
        a = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError):
        raise CsdfError(f"{name} must be an array of shape (N, 3)") from None
    if a.ndim < 1 or a.shape[-1] != 3:
        raise CsdfError(f"{name} must have shape (N, 3) or (..., 3), got {a.shape}")
    return a.reshape(-1, 3), a.shape[:-1]


class Camera:
    """A pinhole camera: intrinsics (pixels) and a camera-to-world pose.

    Camera frame: OpenCV (x right, y down, z forward). ``p_world = R @ p_cam + t``.

    Args:
        fx, fy: focal lengths in pixels (> 0).
        cx, cy: principal point in pixels (pixel centres at integer coordinates).
        width, height: image size in pixels.
        R: ``(3, 3)`` camera-to-world rotation (default identity: the camera looks
            along world +z with world +y down the image).
        t: ``(3,)`` camera position in world units (default the origin).

    Raises:
        CsdfError: a non-finite or non-positive focal length, a non-finite principal
            point or pose, ``R`` not a rotation, or a bad image size.
    """

    __slots__ = ("fx", "fy", "cx", "cy", "width", "height", "R", "t")

    def __init__(self, fx: float, fy: float, cx: float, cy: float, width: int, height: int,
                 R=None, t=None):
        self.fx = _finite_scalar(fx, "fx", positive=True)
        self.fy = _finite_scalar(fy, "fy", positive=True)
        self.cx = _finite_scalar(cx, "cx")
        self.cy = _finite_scalar(cy, "cy")
        self.width, self.height = check_resolution(width, height)
        self.R = np.eye(3) if R is None else _rotation(R)
        self.t = np.zeros(3) if t is None else _vector(t, "camera position t")
        self.R.setflags(write=False)
        self.t.setflags(write=False)

    # ------------------------------------------------------------------ constructors
    @classmethod
    def look_at(cls, eye: Sequence[float], target: Sequence[float],
                up: Sequence[float] = (0.0, 0.0, 1.0), fov: float = 60.0,
                width: int = 640, height: int = 480) -> Camera:
        """A camera at ``eye`` looking at ``target``, with ``up`` pointing up the image.

        Args:
            eye, target, up: ``(3,)`` world points / direction (model units).
            fov: vertical field of view in degrees, in ``(0, 180)``.
            width, height: image size in pixels; square pixels, centred principal point.

        Raises:
            CsdfError: non-finite input, ``eye == target``, ``up`` parallel to the view
                direction, or a field of view out of range.
        """
        e = _vector(eye, "eye")
        g = _vector(target, "target")
        u = _vector(up, "up")
        f = _finite_scalar(fov, "fov")
        if not 0.0 < f < 180.0:
            raise CsdfError(f"fov must be in (0, 180) degrees, got {f}")
        w, h = check_resolution(width, height)
        z = g - e
        nz = np.linalg.norm(z)
        if nz == 0.0:
            raise CsdfError("look_at: eye and target are the same point")
        z = z / nz
        x = np.cross(z, u)
        nx = np.linalg.norm(x)
        if nx < 1e-9 * max(np.linalg.norm(u), 1e-300):
            raise CsdfError("look_at: up is parallel to the view direction; pass another up")
        x = x / nx
        y = np.cross(z, x)
        focal = 0.5 * h / math.tan(math.radians(f) / 2.0)
        return cls(focal, focal, (w - 1) / 2.0, (h - 1) / 2.0, w, h,
                   R=np.stack([x, y, z], axis=1), t=e)

    def scaled(self, width: int, height: int) -> Camera:
        """The same camera at another image size: intrinsics scaled per axis, keeping
        the field of view (pixel-centre convention: ``c' = (c + 0.5) * s - 0.5``)."""
        w, h = check_resolution(width, height)
        if (w, h) == (self.width, self.height):
            return self
        sx, sy = w / self.width, h / self.height
        return Camera(self.fx * sx, self.fy * sy, (self.cx + 0.5) * sx - 0.5,
                      (self.cy + 0.5) * sy - 0.5, w, h, R=self.R, t=self.t)

    # ------------------------------------------------------------------ properties
    @property
    def K(self) -> np.ndarray:
        """``(3, 3)`` intrinsic matrix ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]``."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def position(self) -> np.ndarray:
        """``(3,)`` centre of projection in world coordinates (same as ``t``)."""
        return self.t.copy()

    @property
    def pose(self) -> np.ndarray:
        """``(4, 4)`` camera-to-world homogeneous transform."""
        T = np.eye(4)
        T[:3, :3] = self.R
        T[:3, 3] = self.t
        return T

    def __repr__(self) -> str:
        return (f"Camera(fx={self.fx:g}, fy={self.fy:g}, cx={self.cx:g}, cy={self.cy:g}, "
                f"width={self.width}, height={self.height}, t={self.t.tolist()})")

    # ------------------------------------------------------------------ geometry
    def world_to_camera(self, points) -> np.ndarray:
        """World points ``(..., 3)`` to the camera frame ``(..., 3)``: ``R^T (p - t)``."""
        p, batch = _points(points)
        return ((p - self.t) @ self.R).reshape(*batch, 3)

    def camera_to_world(self, points) -> np.ndarray:
        """Camera-frame points ``(..., 3)`` to the world ``(..., 3)``: ``R p + t``."""
        p, batch = _points(points)
        return (p @ self.R.T + self.t).reshape(*batch, 3)

    def pixel_directions(self, width: int | None = None,
                         height: int | None = None) -> np.ndarray:
        """Unit ray directions in the **camera** frame, ``(H*W, 3)``, row-major (pixel
        ``(u, v)`` at index ``v * W + u``), at the camera's size or a scaled one."""
        cam = self._at(width, height)
        u = (np.arange(cam.width, dtype=np.float64) - cam.cx) / cam.fx
        v = (np.arange(cam.height, dtype=np.float64) - cam.cy) / cam.fy
        d = np.empty((cam.height, cam.width, 3))
        d[..., 0] = u[None, :]
        d[..., 1] = v[:, None]
        d[..., 2] = 1.0
        d = d.reshape(-1, 3)
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        return d

    def rays(self, width: int | None = None,
             height: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """One ray per pixel centre, in the world frame.

        Args:
            width, height: image size (default the camera's; another size scales the
                intrinsics, see :meth:`scaled`).

        Returns:
            ``(origins (H*W, 3), directions (H*W, 3))``: every origin is the camera
            position; directions are unit vectors; row-major pixel order (index
            ``v * W + u``).
        """
        d = self.pixel_directions(width, height) @ self.R.T
        o = np.broadcast_to(self.t, d.shape).copy()
        return o, d

    def project(self, points) -> tuple[np.ndarray, np.ndarray]:
        """Project world points.

        Args:
            points: ``(N, 3)`` (or ``(..., 3)``) world points.

        Returns:
            ``(uv (N, 2) pixels, depth (N,))``: depth is the camera-frame z (distance
            along the optical axis, model units); ``uv`` is NaN for points with
            ``depth <= 0`` (behind the camera or on its plane).
        """
        p, batch = _points(points)
        q = (p - self.t) @ self.R
        z = q[:, 2]
        uv = np.full((len(q), 2), np.nan)
        ok = z > 0
        uv[ok, 0] = self.fx * q[ok, 0] / z[ok] + self.cx
        uv[ok, 1] = self.fy * q[ok, 1] / z[ok] + self.cy
        return uv.reshape(*batch, 2), z.reshape(batch)

    def _at(self, width: int | None, height: int | None) -> Camera:
        if width is None and height is None:
            return self
        return self.scaled(self.width if width is None else width,
                           self.height if height is None else height)
