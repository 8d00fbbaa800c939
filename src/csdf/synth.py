"""``csdf.synth``: synthetic depth-image sequences with ground truth, for tracking and
pose-estimation benchmarks.

:func:`sequence` moves a shape on a smooth random rigid path before a pinhole depth
camera (:class:`csdf.Camera`, OpenCV frame: x right, y down, z forward), renders every
frame with csdf's sphere tracer (the shape is compiled once; each frame's rays are moved
into the object's frame, as :func:`csdf.scan` does with ``object_pose``), optionally
adds a sphere passing in front of the object, and degrades the depth with a
structured-light sensor model:

* **range noise**: Gaussian along the optical axis with standard deviation
  ``sigma(z) = noise_base + noise_quad * z**2`` (quadratic in depth, as for
  structured-light sensors; the default ``noise_quad = 1.425e-3`` per metre is
  Khoshelham and Elberink's (2012) fit for the Kinect v1: 1.4 mm at 1 m, 5.7 mm at 2 m);
* **grazing dropouts**: pixels whose surface normal makes ``|n . ray| < min_cos`` with
  the viewing ray return nothing (depth 0);
* **outliers**: each remaining return is, with probability ``outliers``, replaced by a
  depth drawn uniformly between the frame's nearest and farthest true depths.

Every length is in model units; the noise defaults assume metres. Everything random
comes from ``numpy.random.default_rng(seed)``: equal seeds give identical sequences,
and the path does not depend on the sensor or occluder options (they draw from separate
streams).

``import csdf.synth`` is light (so that :mod:`csdf.io` can name :class:`Sequence`);
the renderer, and with it Numba, loads on the first call of :func:`sequence`.

The result is a :class:`Sequence`; :func:`csdf.io.write_bop` writes it in the BOP
layout and :func:`csdf.io.read_bop` reads it back.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .errors import CsdfError
from .pose import Pose
from .shapes import sphere

if TYPE_CHECKING:  # the renderer loads Numba: imported where it is used
    from .field import Field
    from .render.camera import Camera

__all__ = ["Sequence", "sequence", "noise_sigma", "MAX_FRAMES", "MAX_SEQUENCE_PIXELS",
           "NOISE_QUAD", "MIN_COS", "OUTLIERS", "DEFAULT_SIZE", "KINECT_FOCAL"]

#: most frames of one sequence
MAX_FRAMES = 100_000
#: most pixels of one sequence, all frames together (memory: about 15 bytes per pixel
#: while it is made, 11 kept; each frame's trace needs about 200 bytes per pixel of
#: the frame while it runs). 640 x 480 x 218 frames, 320 x 240 x 873 frames
MAX_SEQUENCE_PIXELS = 1 << 26
#: default quadratic noise coefficient (per model unit): Kinect v1, metres
NOISE_QUAD = 1.425e-3
#: default grazing threshold: returns with ``|n . ray| <`` this (about 78 degrees) drop out
MIN_COS = 0.2
#: default fraction of returns replaced by outliers
OUTLIERS = 0.005
#: default image size ``(width, height)`` when no camera is given
DEFAULT_SIZE = (320, 240)
#: focal length in pixels of the default camera at 480 rows (Kinect v1's 525 px,
#: scaled with the image height)
KINECT_FOCAL = 525.0

#: the object's bounding sphere spans this fraction of the smaller half field of view
#: at the default distance
_FILL = 0.4
#: the distance to the camera varies by this fraction either way
_DEPTH_SWING = 0.15
#: lateral excursions use this fraction of the room that keeps the object in view
_LATERAL_USE = 0.9
#: frequencies of the path's sinusoids, cycles per frame (periods of 20 to 90 frames)
_FREQ = (1.0 / 90.0, 1.0 / 20.0)
#: sinusoids per coordinate of the path
_TERMS = 3
#: the occluder overlaps the object's silhouette during this fraction of the sequence,
#: with its peak at the middle frame
_PASS = 0.6


@dataclass(eq=False, repr=False)
class Sequence:
    """A depth-image sequence of one object, with ground truth.

    Attributes:
        depth: ``(N, H, W)`` float64 depth along the optical axis (camera-frame z, model
            units), 0 where the sensor returned nothing.
        masks: ``(N, H, W)`` bool, the object's visible pixels: where the (noiseless)
            object is the first surface along the pixel's ray, occluded parts excluded
            (BOP's ``mask_visib``). Sensor dropouts and outliers do not change it.
        poses: ``N`` :class:`csdf.Pose`, rigid model-to-camera transforms
            (``p_cam = R q + t``, BOP's ``cam_R_m2c``, ``cam_t_m2c``).
        camera: the :class:`csdf.Camera` (intrinsics; its own world pose plays no part:
            everything is in the camera frame).
        occluder_masks: ``(N, H, W)`` bool, pixels where the occluder is the first
            surface (all False without one).
        visib_fract: ``(N,)`` float64, visible object pixels over the pixels of the
            object's whole silhouette (1 when nothing covers it; NaN when unknown).
        silhouettes: ``(N, H, W)`` bool, the object's whole silhouette ignoring the
            occluder (BOP's ``mask``), or None when unknown.
        colors: ``(N, H, W, 3)`` float32 RGB in [0, 1], the colour camera's images
            (``sequence(colors=True)``: the same camera as the depth), or None.
    """

    depth: np.ndarray
    masks: np.ndarray
    poses: list[Pose]
    camera: Camera
    occluder_masks: np.ndarray
    visib_fract: np.ndarray
    silhouettes: np.ndarray | None = None
    colors: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.poses)

    def __repr__(self) -> str:
        n, h, w = np.shape(self.depth)
        occ = bool(np.any(self.occluder_masks))
        return (f"<Sequence of {n} frames, {w}x{h}, {self.camera!r}"
                f"{', with an occluder' if occ else ''}>")

    @property
    def shape(self) -> tuple[int, int, int]:
        """``(N, H, W)``: frames, rows, columns."""
        return tuple(int(v) for v in self.depth.shape)  # type: ignore[return-value]


#: the colour camera's Gaussian pixel noise (RGB in [0, 1])
COLOR_NOISE = 0.02


def noise_sigma(z, noise_base: float = 0.0, noise_quad: float = NOISE_QUAD) -> np.ndarray:
    """Standard deviation of the sensor's range noise at depth ``z`` (model units):
    ``noise_base + noise_quad * z**2``, same shape as ``z``."""
    z = np.asarray(z, dtype=np.float64)
    return noise_base + noise_quad * z * z


# ------------------------------------------------------------------------- checks
def _real(v, name: str, lo: float = 0.0, hi: float = math.inf, *,
          open_lo: bool = False) -> float:
    """``v`` as a finite float in ``[lo, hi]`` (``(lo, hi]`` with ``open_lo``)."""
    try:
        x = float(v)
    except (TypeError, ValueError):
        raise CsdfError(f"{name} must be a real number, got {v!r}") from None
    low_ok = x > lo if open_lo else x >= lo
    if not (math.isfinite(x) and low_ok and x <= hi):
        left = "(" if open_lo else "["
        right = f"{hi:g}]" if math.isfinite(hi) else "inf)"
        raise CsdfError(f"{name} must be finite and in {left}{lo:g}, {right}, got {x}")
    return x


def _count(v, name: str, hi: int) -> int:
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
        raise CsdfError(f"{name} must be a positive integer, got {v!r}")
    if not 1 <= v <= hi:
        raise CsdfError(f"{name} must be between 1 and {hi:,}, got {int(v)}")
    return int(v)


def _camera(camera: Camera | None, width: int | None, height: int | None) -> Camera:
    """The sequence's camera: the given one (rescaled to ``width`` x ``height`` when
    given) or the default Kinect-like one."""
    from .render.camera import Camera, check_resolution

    if camera is None:
        w, h = check_resolution(DEFAULT_SIZE[0] if width is None else width,
                                DEFAULT_SIZE[1] if height is None else height)
        f = KINECT_FOCAL * h / 480.0
        return Camera(f, f, (w - 1) / 2.0, (h - 1) / 2.0, w, h)
    if not isinstance(camera, Camera):
        raise CsdfError(f"camera must be a csdf.Camera or None, got {type(camera).__name__}")
    w = camera.width if width is None else width
    h = camera.height if height is None else height
    check_resolution(w, h)
    return camera.scaled(w, h)


# ------------------------------------------------------------------------- the path
def _smooth(rng: np.random.Generator, n: int, dim: int) -> tuple[np.ndarray, float]:
    """``(n, dim)`` smooth random signals in ``[-1, 1]`` (per coordinate, a sum of
    :data:`_TERMS` sinusoids of random frequency in :data:`_FREQ`, amplitude and phase,
    divided by the sum of the amplitudes), and the bound ``2 pi max(freq)`` of their
    change per frame."""
    k = np.arange(n, dtype=np.float64)[:, None, None]
    amp = rng.uniform(0.2, 1.0, (1, dim, _TERMS))
    freq = rng.uniform(_FREQ[0], _FREQ[1], (1, dim, _TERMS))
    phase = rng.uniform(0.0, 2.0 * math.pi, (1, dim, _TERMS))
    s = (amp * np.sin(2.0 * math.pi * freq * k + phase)).sum(2) / amp.sum(2)
    return s, 2.0 * math.pi * _FREQ[1]


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A uniformly distributed rotation ``(3, 3)`` (from a random unit quaternion)."""
    q = rng.normal(size=4)
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def _half_angles(cam: Camera) -> tuple[float, float]:
    """Tangents of the smaller half field of view across and down the image (from the
    principal point to the nearest image edge)."""
    tx = min(cam.cx + 0.5, cam.width - 0.5 - cam.cx) / cam.fx
    ty = min(cam.cy + 0.5, cam.height - 0.5 - cam.cy) / cam.fy
    if not (tx > 0 and ty > 0):
        raise CsdfError("the camera's principal point must lie inside the image")
    return tx, ty


def _path(rng: np.random.Generator, n: int, cam: Camera, radius: float,
          distance: float | None, max_rotation: float,
          max_translation: float) -> tuple[np.ndarray, np.ndarray, float]:
    """Rotations ``(n, 3, 3)`` and bounding-sphere centres ``(n, 3)`` in the camera
    frame, and the distance used.

    Rotation: ``R[k+1] = R[k] exp(w[k])`` from a uniformly random start, with the
    body-frame rotation vector ``w`` a smooth signal of norm at most ``max_rotation``
    (radians per frame). Centre: around ``(0, 0, distance)`` on the optical axis, each
    coordinate a smooth signal inside the room that keeps the whole bounding sphere in
    the image at the nearest depth, scaled down until no step exceeds
    ``max_translation``.
    """
    tx, ty = _half_angles(cam)
    if distance is None:
        distance = radius / math.sin(_FILL * math.atan(min(tx, ty)))
    z_near = distance * (1.0 - _DEPTH_SWING)
    room = []
    for t in (tx, ty):
        # a sphere (centre x, depth z) is inside the side planes when
        # |x| <= z tan(a) - r / cos(a)
        room.append(z_near * t - radius * math.sqrt(1.0 + t * t))
    if min(room) < 0 or z_near <= radius:
        raise CsdfError(f"the object (bounding radius {radius:.4g}) does not fit in the "
                        f"camera's view at distance {distance:.4g}: choose a larger "
                        "distance (or leave distance=None)")
    amp = np.array([_LATERAL_USE * room[0], _LATERAL_USE * room[1],
                    _DEPTH_SWING * distance])
    # rotation: constant drift plus smooth variation, every component within
    # max_rotation / sqrt(3) so that the norm stays within max_rotation
    drift = rng.uniform(0.3, 0.8, 3) * rng.choice([-1.0, 1.0], 3)
    vary, _ = _smooth(rng, max(n - 1, 1), 3)
    w = (drift + (1.0 - np.abs(drift)) * vary) * (max_rotation / math.sqrt(3.0))
    R = np.empty((n, 3, 3))
    R[0] = _random_rotation(rng)
    for k in range(1, n):
        R[k] = R[k - 1] @ Pose.from_rotvec(w[k - 1]).rotation
    wave, _ = _smooth(rng, n, 3)
    offsets = wave * amp
    if n > 1:
        step = float(np.max(np.linalg.norm(np.diff(offsets, axis=0), axis=1)))
        if step > max_translation:
            offsets *= max_translation / step
    centres = offsets + np.array([0.0, 0.0, distance])
    return R, centres, distance


# ------------------------------------------------------------------------- the occluder
def _sphere_hits(c: np.ndarray, r: float, dirs: np.ndarray) -> np.ndarray:
    """Which unit rays ``(M, 3)`` from the origin meet the sphere (centre ``c``,
    radius ``r``): ``(M,)`` bool."""
    cd = dirs @ c
    return (cd > 0) & (float(c @ c) - cd * cd <= r * r)


def _occluder_path(rng: np.random.Generator, n: int, centres: np.ndarray, radius: float,
                   silhouettes: list[np.ndarray], dirs: np.ndarray, focal: float,
                   occlusion: float) -> tuple[np.ndarray, float]:
    """Centres ``(n, 3)`` (camera frame) and radius of a sphere that passes in front of
    the object, covering at most ``occlusion`` of the object's silhouette pixels, as near
    as the pixels allow at the frame where it covers most.

    Args:
        centres: ``(n, 3)`` the object's bounding-sphere centres (camera frame), of
            radius ``radius``.
        silhouettes: per frame the flat indices of the object's pixels.
        dirs: ``(H*W, 3)`` unit pixel rays (camera frame).
        focal: the smaller focal length, pixels.

    In normalised image coordinates (``x / z``, ``y / z``) the sphere's centre moves at
    constant speed relative to the centroid of the object's silhouette, along a random
    direction ``u`` offset by ``beta`` along the normal ``v``: it is clear of the
    silhouette except during the fraction :data:`_PASS` of the sequence around the
    middle frame ``(n - 1) // 2``, where it passes closest. Its depth is half the
    object's nearest possible depth. Its radius starts at ``0.2 + sqrt(occlusion)``
    times the silhouette's mean equivalent radius and grows until a central pass covers
    the fraction; ``beta`` is then found by bisection.
    """
    z_occ = 0.5 * float(np.min(centres[:, 2] - radius))
    rays = [dirs[s] for s in silhouettes]
    img = [r[:, :2] / r[:, 2:] for r in rays]  # normalised image coordinates
    centroid = np.array([m.mean(0) if len(m) else [0.0, 0.0] for m in img])
    reach = np.array([np.max(np.linalg.norm(m - c, axis=1)) if len(m) else 0.0
                      for m, c in zip(img, centroid)]) + 1.0 / focal
    area = float(np.mean([len(s) for s in silhouettes])) / focal**2
    rho = (0.2 + math.sqrt(occlusion)) * math.sqrt(area / math.pi)
    theta = rng.uniform(0.0, 2.0 * math.pi)
    u = np.array([math.cos(theta), math.sin(theta)])
    v = np.array([-u[1], u[0]])
    # the peak is a whole frame; the pass lasts _PASS of the sequence, at least 2 frames
    along = (np.arange(n) - (n - 1) // 2) / max(0.5 * _PASS * (n - 1), 1.0)
    passing = [i for i in range(n) if abs(along[i]) <= 1.0 and len(rays[i])]

    def place(beta: float, rho: float) -> np.ndarray:
        clear = reach + 1.5 * rho  # centre offset at which it misses the silhouette
        q = centroid + clear[:, None] * (along[:, None] * u + beta * v)
        return z_occ * np.column_stack([q, np.ones(n)])

    def coverage(beta: float, rho: float) -> float:
        c = place(beta, rho)
        return max((float(np.mean(_sphere_hits(c[i], z_occ * rho, rays[i])))
                    for i in passing), default=0.0)

    for _ in range(8):  # grow the sphere until a central pass covers enough
        if coverage(0.0, rho) >= occlusion or rho * z_occ >= 0.5 * z_occ:
            break
        rho *= 1.25
    best, best_err = 0.0, abs(coverage(0.0, rho) - occlusion)
    if coverage(0.0, rho) > occlusion:
        lo, hi = 0.0, 1.0
        for _ in range(30):
            mid = 0.5 * (lo + hi)
            cov = coverage(mid, rho)
            if abs(cov - occlusion) < best_err:
                best, best_err = mid, abs(cov - occlusion)
            if cov > occlusion:
                lo = mid
            else:
                hi = mid
    return place(best, rho), z_occ * rho


# ------------------------------------------------------------------------- rendering
def _trace(fld: Field, pose: Pose, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Range along each unit camera ray ``(M, 3)`` to the posed field (inf for a
    miss) and ``|n . ray|`` there: ``((M,), (M,))``."""
    from .render.trace import trace_hits

    d_obj = pose.apply_inverse_dirs(dirs)
    t, n_obj, _ = trace_hits(fld, pose.apply_inverse(np.zeros(3)), d_obj)
    with np.errstate(invalid="ignore"):
        cos = np.abs(np.einsum("ij,ij->i", n_obj, d_obj))
    return t, cos


def _background(rng: np.random.Generator, W: int, H: int) -> np.ndarray:
    """``(H*W, 3)`` a background: two random colours mixed by a smooth pattern (a sum
    of four random plane waves of 1-4 periods across the image)."""
    a, b = rng.uniform(0.05, 0.95, (2, 3))
    v, u = np.mgrid[0:H, 0:W]
    pattern = np.zeros((H, W))
    for _ in range(4):
        k = rng.uniform(1.0, 4.0) * 2.0 * math.pi / max(W, H)
        ang, phase = rng.uniform(0.0, 2.0 * math.pi, 2)
        pattern += np.sin(k * (u * math.cos(ang) + v * math.sin(ang)) + phase)
    w = (0.5 + 0.125 * pattern).clip(0.0, 1.0).reshape(-1, 1)
    return (1.0 - w) * a + w * b


def _colour_frame(fld: Field, pose: Pose, dirs: np.ndarray, t: np.ndarray,
                  cos: np.ndarray, mask: np.ndarray, occ: np.ndarray,
                  background: np.ndarray, occ_colour: np.ndarray, noise: float,
                  rng: np.random.Generator) -> np.ndarray:
    """``(H*W, 3)`` one colour image: the object's colours where it is seen (``mask``),
    the occluder's where it is (``occ``), each Lambert-shaded by ``cos`` (a light at
    the camera), the background elsewhere, plus noise."""
    from .colors import colors_of

    out = background.copy()
    shade = (0.35 + 0.65 * np.nan_to_num(cos)).reshape(-1, 1)
    if mask.any():
        q = pose.apply_inverse(dirs[mask] * t[mask, None])
        out[mask] = colors_of(fld, q)[:, :3] * shade[mask]
    out[occ] = occ_colour * shade[occ]
    out += noise * rng.standard_normal(out.shape)
    return np.clip(out, 0.0, 1.0)


def sequence(shape, n_frames: int = 30, camera: Camera | None = None, seed=0, *,
             width: int | None = None, height: int | None = None,
             distance: float | None = None, max_rotation: float = 3.0,
             max_translation: float | None = None, noise_base: float = 0.0,
             noise_quad: float = NOISE_QUAD, outliers: float = OUTLIERS,
             min_cos: float = MIN_COS, occlusion: float = 0.0,
             params: dict | None = None, backend: str = "auto", bounds=None,
             check_ranges: bool = True, colors: bool = False,
             color_noise: float = COLOR_NOISE) -> Sequence:
    """A synthetic depth sequence of a shape moving before a camera (see the module
    docs for the motion and the sensor model).

    Args:
        shape: a 3D :class:`csdf.Shape` or :class:`csdf.Program` in its own frame
            (model units, metres for the default noise).
        n_frames: number of frames ``N`` (at most :data:`MAX_FRAMES`).
        camera: a :class:`csdf.Camera` (only its intrinsics are used), or None for a
            Kinect-like one: square pixels, focal length 525 px at 480 rows scaled with
            the height, centred principal point, ``width`` x ``height`` (default
            320 x 240).
        seed: seed of ``numpy.random.default_rng`` (an int, a SeedSequence or a
            Generator); equal seeds give identical sequences.
        width, height: image size in pixels (with a camera: rescales its intrinsics).
        distance: mean distance from the camera to the centre of the shape's bounding
            box (model units); default such that its bounding sphere spans 40 % of the
            smaller half field of view. The object's depth varies by 15 % either way and
            its whole bounding sphere stays in the image in every frame.
        max_rotation: bound on the rotation between consecutive frames, degrees (the
            typical rotation is about half of it: a 30 fps tracker's few degrees).
        max_translation: bound on the motion of the bounding-box centre between
            consecutive frames, model units (default 2 % of the bounding-box diagonal:
            7 mm for a 35 cm object).
        noise_base, noise_quad: range noise ``sigma(z) = noise_base + noise_quad z**2``
            (model units; :func:`noise_sigma`), Gaussian along the optical axis; 0 and 0
            for none. Default: Kinect v1's ``1.425e-3 z**2`` (metres).
        outliers: probability in ``[0, 1]`` that a return's depth is replaced by one
            uniform between the frame's nearest and farthest true depths.
        min_cos: returns with ``|n . ray| < min_cos`` drop out (depth 0); 0 keeps
            all. Default 0.2 (about 78 degrees from the normal).
        occlusion: peak fraction in ``[0, 1]`` of the object's silhouette covered by an
            occluding sphere that passes in front of it during the middle 60 % of the
            sequence (at least 2 frames), closest to the object's centre at frame
            ``(N - 1) // 2``; 0 for no occluder. The occluder
            appears in the depth and in :attr:`Sequence.occluder_masks`. Its size
            suits the fraction asked; a fraction larger than it can cover gives its
            central pass.
        params: parameter values ``{name: value}`` of the shape.
        backend: evaluation backend (``'auto'``: the fast Numba kernels).
        bounds: ``(2, 3)`` box containing the surface (for unbounded shapes).
        check_ranges: refuse a parameter value outside its declared range.
        colors: also render colour images (:attr:`Sequence.colors`, an RGB-D sensor):
            the object in its colours (:mod:`csdf.colors`) and the occluder in one
            random colour, both Lambert-shaded by a light at the camera, before a
            background of two random colours mixed by a smooth random pattern; every
            pixel (dropouts too: the colour camera sees them) with Gaussian noise of
            ``color_noise``.

    Returns:
        :class:`Sequence` with ``N`` frames of ``(H, W)`` images.

    Raises:
        CsdfError: a bad count, size or option, an image over the limits of
            :func:`csdf.render`, ``N * H * W`` over :data:`MAX_SEQUENCE_PIXELS`, a
            distance at which the object does not fit in the view, a 2D or unbounded
            shape without ``bounds``; ParamError: a value outside its range.
    """
    from .render.trace import trace_field

    n = _count(n_frames, "n_frames", MAX_FRAMES)
    cam = _camera(camera, width, height)
    W, H = cam.width, cam.height
    if n * W * H > MAX_SEQUENCE_PIXELS:
        raise CsdfError(f"a sequence of {n} frames of {W}x{H} pixels is over the limit of "
                        f"{MAX_SEQUENCE_PIXELS:,} pixels in all; use fewer frames or "
                        "smaller images")
    if distance is not None:
        distance = _real(distance, "distance", open_lo=True)
    rot = math.radians(_real(max_rotation, "max_rotation", 0.0, 180.0))
    noise_base = _real(noise_base, "noise_base")
    noise_quad = _real(noise_quad, "noise_quad")
    outliers = _real(outliers, "outliers", 0.0, 1.0)
    min_cos = _real(min_cos, "min_cos", 0.0, 1.0)
    occlusion = _real(occlusion, "occlusion", 0.0, 1.0)

    fld = trace_field(shape, params, backend, bounds, what="synth.sequence",
                      check_ranges=check_ranges)
    box = np.asarray(fld.bounds, dtype=np.float64)
    centre_obj = 0.5 * (box[0] + box[1])
    radius = 0.5 * float(np.linalg.norm(box[1] - box[0]))
    if max_translation is None:
        max_translation = 0.02 * 2.0 * radius
    max_translation = _real(max_translation, "max_translation")

    # (a fourth stream for the colours leaves the first three, and so the depth, as
    # they are without colours)
    path_rng, occ_rng, sensor_rng, color_rng = np.random.default_rng(seed).spawn(4)
    R, centres, _ = _path(path_rng, n, cam, radius, distance, rot, max_translation)
    poses = [Pose(R[k], centres[k] - R[k] @ centre_obj) for k in range(n)]

    dirs = cam.pixel_directions()  # (H*W, 3) unit, camera frame
    dz = dirs[:, 2]
    # pass 1: the object alone (the occluder's path needs every frame's silhouette);
    # its ranges are overwritten by the frames' depths in pass 2
    depth = np.empty((n, H * W))
    cos_obj = np.empty((n, H * W), dtype=np.float32)
    for k in range(n):
        depth[k], cos_obj[k] = _trace(fld, poses[k], dirs)
    hit = np.isfinite(depth)
    ofld = occ_centres = None
    if occlusion > 0:
        occ_centres, r_occ = _occluder_path(
            occ_rng, n, centres, radius, [np.flatnonzero(h) for h in hit], dirs,
            min(cam.fx, cam.fy), occlusion)
        ofld = trace_field(sphere(r_occ), what="synth.sequence")

    # pass 2: the occluder, the first surface per pixel, the sensor
    color_noise = _real(color_noise, "color_noise", 0.0, 1.0)
    rgb = np.empty((n, H * W, 3), dtype=np.float32) if colors else None
    background = _background(color_rng, W, H) if colors else None
    occ_colour = color_rng.uniform(0.1, 0.9, 3) if colors else None
    masks = np.empty((n, H * W), dtype=bool)
    occ_masks = np.zeros((n, H * W), dtype=bool)
    for k in range(n):
        t = depth[k]
        cos = cos_obj[k].astype(np.float64)
        if ofld is not None:
            t_occ, cos_occ = _trace(ofld, Pose(None, occ_centres[k]), dirs)
            front = t_occ < t
            occ_masks[k] = front
            t = np.where(front, t_occ, t)
            cos[front] = cos_occ[front]
        masks[k] = hit[k] & ~occ_masks[k]
        gauss = sensor_rng.standard_normal(H * W)
        pick = sensor_rng.random(H * W)
        spread = sensor_rng.random(H * W)
        ok = np.isfinite(t)
        z_true = t[ok] * dz[ok]
        z = z_true + noise_sigma(z_true, noise_base, noise_quad) * gauss[ok]
        if z_true.size and outliers > 0:
            lo, hi = float(z_true.min()), float(z_true.max())
            bad = pick[ok] < outliers
            z[bad] = lo + (hi - lo) * spread[ok][bad]
        z[cos[ok] < min_cos] = 0.0
        depth[k] = 0.0
        depth[k, ok] = np.maximum(z, 0.0)
        if colors:
            rgb[k] = _colour_frame(fld, poses[k], dirs, t, cos, masks[k], occ_masks[k],
                                   background, occ_colour, color_noise, color_rng)
    n_all = hit.sum(1)
    visib = np.where(n_all > 0, masks.sum(1) / np.maximum(n_all, 1), 0.0)
    return Sequence(depth=depth.reshape(n, H, W), masks=masks.reshape(n, H, W),
                    poses=poses, camera=cam, occluder_masks=occ_masks.reshape(n, H, W),
                    visib_fract=visib.astype(np.float64),
                    silhouettes=hit.reshape(n, H, W),
                    colors=rgb.reshape(n, H, W, 3) if colors else None)
