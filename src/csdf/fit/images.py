"""Registration from images (paper §4.5: SDF-RGBD and SDF-RGB): :func:`fit_depth` from
a depth image with an optional silhouette term, :func:`fit_silhouette` from binary masks
alone.

Frames: a camera is a :class:`csdf.Camera` (OpenCV: x right, y down, z forward; its
pose is camera-to-world). :func:`fit_depth` works in the **camera frame**: the result's
pose maps the model into the camera (BOP's ``cam_R_m2c``, ``cam_t_m2c``).
:func:`fit_silhouette` works in the **world frame** of its cameras.

Residuals (all in scene units, metres for csdf's models):

* **Depth points.** Each valid pixel (depth > 0 and finite; inside ``mask`` when one is
  given) is back-projected to ``p = depth / d_z * d`` (``d`` the pixel's unit ray) and
  scored by its signed distance to the posed model, ``r = s f(R^T (p - t) / s)``, with
  a robust loss (no correspondences: :mod:`.problem`).
* **Silhouette.** For pixels within ``band`` pixels of the mask's boundary (both sides),
  the ray's minimum of the posed field, ``m = min_u s f(...(o + u d))``, should equal
  the pixel's signed distance to the boundary turned into metres at the depth ``z`` of
  the minimising point: ``m = e z / f_px`` (``e`` in pixels, positive outside the mask,
  from the Euclidean distance transform; ``f_px`` the focal length). For a sphere this is
  exact (a ray passing ``delta`` from the centre has ``m = delta - radius``); for other
  shapes it is first order near the contour. So pixels inside the mask pull the model's
  silhouette out to them and pixels outside push it in, smoothly, and a pose whose
  silhouette matches the mask has zero residual. The minimum's derivative by pose and
  parameters is the field's at the minimising point (the derivative along the ray
  vanishes there), from the same forward-mode pass as the depth points.
  Occlusion: a pixel outside the mask whose measured depth lies in front of the model's
  minimising point (by more than ``occlusion_margin``) sees an occluder, not the
  background, and is left out.

* **Colour** (``color=``, an RGB image of the same camera; SDF-RGBD's region-based
  statistics, as PWP3D and RBOT use them). With the model posed at the start, the
  pixels inside its silhouette give a foreground colour histogram and a ring of pixels
  outside it a background one (``COLOR_BINS`` per channel, Laplace-smoothed; pixels
  whose measured depth lies well in front of the model, an occluder, are left out);
  each pixel's colour then has a foreground posterior ``P_f = h_f / (h_f + h_b)``.
  For pixels within ``COLOR_BAND`` pixels of the silhouette's edge the residual is
  ``w (H(phi) - P_f)``: ``phi`` the pixel's signed distance to the posed model's
  silhouette in pixels (the ray minimum over the depth times the focal length, as for
  the silhouette term), ``H`` a smoothed Heaviside (1 inside, width
  ``COLOR_SOFTNESS`` pixels) and ``w = color_weight * f_scale``. So the silhouette is
  pulled to where the colours change from the object's to the background's, without a
  mask; pixels whose measured depth is in front of the model are left out. It is the
  least-squares form of the region term (the posterior fitted by the soft silhouette)
  rather than its log-likelihood, so that it joins the Levenberg-Marquardt solve of the
  other residuals.

The ray minimum is found by sampling the ray across the posed model's bounding sphere
(``RAY_SAMPLES`` points), then ``REFINE_ROUNDS`` rounds of ``REFINE_POINTS`` samples
in the bracket around the smallest so far (one evaluation call a round).
"""

from __future__ import annotations

import functools
import math
import time
from dataclasses import dataclass

import numpy as np

from ..errors import CsdfError, interrupt_in
from ..pose import Pose
from .lm import State, damped_step, linearise, normal_equations
from .problem import jacobian, loss_weights, make_result, prepare, residuals
from .result import FitResult

__all__ = ["backproject", "fit_depth", "fit_silhouette", "contour_rays", "ray_minima",
           "color_term", "ColorTerm", "GateError", "COLOR_BAND", "COLOR_SOFTNESS", "COLOR_BINS",
           "RAY_SAMPLES", "REFINE_ROUNDS", "REFINE_POINTS", "SILHOUETTE_LIMIT"]

#: samples along a silhouette ray across the model's bounding sphere
RAY_SAMPLES = 16
#: refinement rounds around the smallest sample, and the points each samples
REFINE_ROUNDS = 3
REFINE_POINTS = 4
#: the colour term: pixels within this many pixels of the model's silhouette, the
#: smoothed Heaviside's width (pixels), histogram bins per channel
COLOR_BAND = 8.0
COLOR_SOFTNESS = 1.5
COLOR_BINS = 8
#: the silhouette residual's RMS passes up to the larger of these times f_scale and
#: times a pixel's footprint at the object's depth
SILHOUETTE_LIMIT = (2.0, 1.25)


class GateError(CsdfError):
    """:func:`fit_depth` from a start without a mask found too few depth points near
    the model to fit (a tracker's prediction that lost the object)."""


# ------------------------------------------------------------------ image inputs
def _camera(camera, what: str = "camera"):
    from ..render.camera import Camera

    if not isinstance(camera, Camera):
        raise CsdfError(f"{what} must be a csdf.Camera, got {type(camera).__name__}")
    return camera


def _image(a, camera, what: str, dtype=np.float64) -> np.ndarray:
    try:
        img = np.asarray(a, dtype=dtype)
    except (TypeError, ValueError):
        raise CsdfError(f"{what} must be an image of numbers") from None
    if img.shape != (camera.height, camera.width):
        raise CsdfError(f"{what} must have the camera's shape ({camera.height}, "
                        f"{camera.width}), got {img.shape}")
    return img


def _mask(mask, camera, what: str = "mask") -> np.ndarray:
    m = _image(mask, camera, what, dtype=np.float64)
    if not np.isin(m, (0.0, 1.0)).all():
        raise CsdfError(f"{what} must be binary (0/1 or bool)")
    return m > 0.5


@functools.lru_cache(maxsize=8)
def _directions_of(fx: float, fy: float, cx: float, cy: float, w: int, h: int) -> np.ndarray:
    from ..render.camera import Camera

    d = Camera(fx, fy, cx, cy, w, h).pixel_directions()
    d.setflags(write=False)
    return d


def _directions(cam) -> np.ndarray:
    """``(H*W, 3)`` the camera's unit pixel rays in its own frame (cached per
    intrinsics: a video asks for the same ones every frame)."""
    return _directions_of(cam.fx, cam.fy, cam.cx, cam.cy, cam.width, cam.height)


def backproject(depth, camera, mask=None) -> tuple[np.ndarray, np.ndarray]:
    """The valid pixels of a depth image as camera-frame points.

    Args:
        depth: ``(H, W)`` depth along the optical axis (scene units); 0, negative,
            NaN or inf is missing.
        camera: the :class:`csdf.Camera` of the image (its size is the image's).
        mask: optional ``(H, W)`` bool: only pixels inside it.

    Returns:
        ``(points (N, 3), pixels (N,) flat indices v * W + u)``.
    """
    cam = _camera(camera)
    z = _image(depth, cam, "depth")
    ok = np.isfinite(z) & (z > 0)
    if mask is not None:
        ok &= _mask(mask, cam)
    idx = np.flatnonzero(ok.ravel())
    d = _directions(cam)[idx]
    pts = d * (z.ravel()[idx] / d[:, 2])[:, None]
    return pts, idx


def _check_options(**opts) -> None:
    """Refuse option values that make no sense, naming the option: ``band`` (> 0),
    counts (``max_iter``, ``max_points``, ``max_rays``: >= 1 or None), ``seed`` (an int
    >= 0), distances and weights (finite, >= 0; ``gate`` may be None)."""
    for name, v in opts.items():
        if v is None and name in ("max_points", "max_rays", "gate", "occlusion_margin"):
            continue
        if name == "seed":
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
                raise CsdfError(f"seed must be an integer >= 0, got {v!r}")
            continue
        try:
            x = float(v)
        except (TypeError, ValueError):
            raise CsdfError(f"{name} must be a number, got {v!r}") from None
        if name in ("max_iter", "max_points", "max_rays"):
            if not (x >= 1 and x == int(x)):
                raise CsdfError(f"{name} must be an integer >= 1, got {v!r}")
        elif name == "band":
            if not (math.isfinite(x) and x > 0):
                raise CsdfError(f"band must be a finite number of pixels > 0, got {v!r}")
        elif not (math.isfinite(x) and x >= 0):
            raise CsdfError(f"{name} must be a finite number >= 0, got {v!r}")


def _subsample(n: int, k: int | None, rng: np.random.Generator) -> np.ndarray:
    if k is None or n <= k:
        return np.arange(n)
    return np.sort(rng.choice(n, size=int(k), replace=False))


# ------------------------------------------------------------------ silhouette rays
@dataclass
class Rays:
    """Silhouette rays of one or more views (scene frame).

    Attributes:
        origins: ``(M, 3)``; dirs: ``(M, 3)`` unit; axis: ``(M, 3)`` the optical axis of
        each ray's camera (depth is measured along it); target: ``(M,)`` the pixel's
        signed distance to the mask boundary over the focal length (positive outside;
        ``m = target * z``); outside: ``(M,)`` bool; depth: ``(M,)`` the measured depth
        of the pixel (inf where none).
    """

    origins: np.ndarray
    dirs: np.ndarray
    axis: np.ndarray
    target: np.ndarray
    outside: np.ndarray
    depth: np.ndarray

    def __len__(self) -> int:
        return len(self.dirs)


def _signed_distance(mask: np.ndarray, reach: float = np.inf) -> np.ndarray:
    """Signed distance in pixels from each pixel centre to the mask's boundary (which
    runs between pixels): positive outside, negative inside. With ``reach``, only
    values within ``reach`` are exact (computed on the mask's box grown by it; farther
    pixels get +-inf)."""
    from scipy import ndimage

    if mask.all() or not mask.any():
        return np.full(mask.shape, -np.inf if mask.all() else np.inf)
    out = np.where(mask, -np.inf, np.inf)
    v, u = np.nonzero(mask)
    g = int(math.ceil(reach)) + 2 if math.isfinite(reach) else max(mask.shape)
    r0, r1 = max(v.min() - g, 0), min(v.max() + g + 1, mask.shape[0])
    c0, c1 = max(u.min() - g, 0), min(u.max() + g + 1, mask.shape[1])
    m = mask[r0:r1, c0:c1]
    if m.all():  # the box is the mask: the boundary is the image's edge
        return out
    outside = ndimage.distance_transform_edt(~m) - 0.5
    inside = ndimage.distance_transform_edt(m) - 0.5 if (~m).any() else np.full(m.shape, np.inf)
    out[r0:r1, c0:c1] = np.where(m, -inside, outside)
    return out


def contour_rays(mask, camera, band: float = 4.0, max_rays: int | None = 400,
                 depth=None, seed: int = 0) -> Rays:
    """The rays of the pixels within ``band`` pixels of a mask's boundary (both sides),
    in the world frame of ``camera``, at most ``max_rays`` of them (a seeded subset)."""
    cam = _camera(camera)
    m = _mask(mask, cam)
    e = _signed_distance(m, band)
    sel = np.flatnonzero((np.abs(e) <= band).ravel())
    sel = sel[_subsample(len(sel), max_rays, np.random.default_rng(seed))]
    dc = _directions(cam)[sel]
    fpx = 0.5 * (cam.fx + cam.fy)
    z = np.full(len(sel), np.inf)
    if depth is not None:
        zz = _image(depth, cam, "depth").ravel()[sel]
        good = np.isfinite(zz) & (zz > 0)
        z[good] = zz[good]
    R = cam.R
    return Rays(origins=np.broadcast_to(cam.t, (len(sel), 3)).copy(), dirs=dc @ R.T,
                axis=np.broadcast_to(R[:, 2], (len(sel), 3)).copy(),
                target=e.ravel()[sel] / fpx, outside=~m.ravel()[sel], depth=z)


def ray_minima(prog, pv: dict, backend: str, R: np.ndarray, t: np.ndarray, s: float,
               centre: np.ndarray, radius: float, rays: Rays
               ) -> tuple[np.ndarray, np.ndarray]:
    """The minimum of the posed field along each ray over the model's bounding sphere
    (centre ``centre``, radius ``radius``, model units): ``(points (M, 3) scene frame,
    values (M,))``."""
    M = len(rays)
    C = s * (R @ centre) + t
    rw = s * radius
    b = np.einsum("ij,ij->i", rays.dirs, C - rays.origins)
    u0 = np.maximum(b - rw, 1e-9)
    u1 = np.maximum(b + rw, u0 + 1e-9)

    fn = _value_function(prog, pv, backend)

    def values(u: np.ndarray) -> np.ndarray:  # u (M, k) -> (M, k)
        X = rays.origins[:, None, :] + u[..., None] * rays.dirs[:, None, :]
        q = np.ascontiguousarray(((X.reshape(-1, 3) - t) @ R) / s)
        return s * np.asarray(fn(q)).reshape(u.shape)

    K = RAY_SAMPLES
    u = u0[:, None] + (u1 - u0)[:, None] * np.linspace(0.0, 1.0, K)[None, :]
    v = values(u)
    k = np.argmin(v, axis=1)
    rows = np.arange(M)
    best_u, best_v = u[rows, k], v[rows, k]
    lo = u[rows, np.maximum(k - 1, 0)]
    hi = u[rows, np.minimum(k + 1, K - 1)]
    # each round samples REFINE_POINTS inside the bracket in one call and keeps the
    # neighbourhood of the smallest: the bracket shrinks by 2 / (REFINE_POINTS + 1) a
    # call (a call's fixed cost, not its points, is what a tracker's frame pays)
    frac = np.arange(1, REFINE_POINTS + 1) / (REFINE_POINTS + 1)
    for _ in range(REFINE_ROUNDS):
        uu = lo[:, None] + (hi - lo)[:, None] * frac[None, :]
        vv = values(uu)
        j = np.argmin(vv, axis=1)
        better = vv[rows, j] < best_v
        best_u = np.where(better, uu[rows, j], best_u)
        best_v = np.where(better, vv[rows, j], best_v)
        step = (hi - lo) / (REFINE_POINTS + 1)
        lo, hi = best_u - step, best_u + step
    ub, vb = best_u, best_v
    return rays.origins + ub[:, None] * rays.dirs, vb


def _value_function(prog, pv: dict, backend: str):
    """``f(q (M, 3)) -> (M,)`` model values at these parameter values: the compiled
    evaluator's serial kernel where there is one (no per-call setup: the ray search
    makes many small calls), else the program's own call."""
    from ..field import as_field

    if backend in ("auto", "fast"):
        try:
            fn = as_field(prog, pv, backend="fast", check_ranges=False).serial_values()
        except Exception as exc:  # no Numba, or a program the compiled backend cannot take
            stop = interrupt_in(exc)
            if stop is not None:
                raise stop from None
            fn = None
        if fn is not None:
            return fn
    return lambda q: prog(q, pv, backend=backend, check_ranges=False)


# ------------------------------------------------------------------ the colour term
@dataclass
class ColorTerm:
    """The region-based colour term's pixels (camera frame).

    Attributes:
        rays: their rays (:class:`Rays`: origins at the camera centre, ``depth`` the
            measured depth or inf).
        posterior: ``(M,)`` each pixel's probability of showing the object, from its
            colour: ``h_f / (h_f + h_b)`` of the foreground and background colour
            histograms.
        fpx: the focal length (pixels).
        softness: the smoothed Heaviside's width (pixels).
    """

    rays: Rays
    posterior: np.ndarray
    fpx: float
    softness: float = COLOR_SOFTNESS


def _color_image(color, cam) -> np.ndarray:
    """``(H*W, 3)`` float RGB in [0, 1] of a colour image of the camera's size."""
    try:
        img = np.asarray(color)
    except (TypeError, ValueError):
        raise CsdfError("color must be an (H, W, 3) image") from None
    if img.shape != (cam.height, cam.width, 3) or img.dtype.kind not in "uif":
        raise CsdfError(f"color must be an RGB image of the camera's shape ({cam.height}, "
                        f"{cam.width}, 3), got {img.shape} of {img.dtype}")
    out = img.astype(np.float64).reshape(-1, 3)
    if img.dtype == np.uint8:
        out /= 255.0
    if not np.isfinite(out).all() or out.min() < 0.0 or out.max() > 1.0:
        raise CsdfError("color must hold RGB values in [0, 1] (or 8-bit)")
    return out


def _model_pixels(prob, cam, margin: float, max_pixels: int = 1500
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The pixels (flat indices) of a grid over the posed model's projected bounding
    sphere grown by ``margin`` pixels (every ``k``-th pixel, so at most about
    ``max_pixels``), their signed distance to the model's silhouette in pixels
    (positive outside: the ray minima of the field over the depth along the ray), and
    for every pixel of the grid's box the index of its nearest grid pixel (``(B,)``
    pairs ``(pixel, grid pixel)`` as a ``(2, B)`` array)."""
    s = prob.s
    C = s * (prob.R @ prob.centre) + prob.t
    rw = s * 0.5 * prob.size
    if C[2] <= rw:  # the camera is inside the bounding sphere: the whole image
        u0, u1, v0, v1 = 0, cam.width - 1, 0, cam.height - 1
    else:
        uc, vc = cam.fx * C[0] / C[2] + cam.cx, cam.fy * C[1] / C[2] + cam.cy
        rp = max(cam.fx, cam.fy) * rw / math.sqrt(C[2] ** 2 - rw ** 2) + margin
        u0, u1 = max(int(uc - rp), 0), min(int(uc + rp) + 1, cam.width - 1)
        v0, v1 = max(int(vc - rp), 0), min(int(vc + rp) + 1, cam.height - 1)
    if u1 < u0 or v1 < v0:
        return np.zeros(0, np.int64), np.zeros(0), np.zeros((2, 0), np.int64)
    step = max(1, int(math.ceil(math.sqrt((u1 - u0 + 1) * (v1 - v0 + 1) / max_pixels))))
    vv, uu = np.mgrid[v0:v1 + 1:step, u0:u1 + 1:step]
    idx = (vv * cam.width + uu).ravel()
    fv, fu = np.mgrid[v0:v1 + 1, u0:u1 + 1]
    gv = np.minimum(np.rint((fv - v0) / step).astype(np.int64), vv.shape[0] - 1)
    gu = np.minimum(np.rint((fu - u0) / step).astype(np.int64), vv.shape[1] - 1)
    near = np.stack([(fv * cam.width + fu).ravel(), (gv * vv.shape[1] + gu).ravel()])
    d = _directions(cam)[idx]
    n = len(idx)
    rays = Rays(np.zeros((n, 3)), d, np.broadcast_to([0.0, 0.0, 1.0], (n, 3)).copy(),
                np.zeros(n), np.ones(n, bool), np.full(n, np.inf))
    pv = dict(zip(prob.pnames, prob.values))
    X, m = ray_minima(prob.prog, pv, prob.backend, prob.R, prob.t, s, prob.centre,
                      0.5 * prob.size, rays)
    fpx = 0.5 * (cam.fx + cam.fy)
    return idx, m * fpx / np.maximum(X[:, 2], 1e-300), near


def color_term(prob, rgb: np.ndarray, depth, cam, occlusion: float, *,
               band: float = 8.0, max_rays: int | None = 300, bins: int = COLOR_BINS,
               seed: int = 0) -> ColorTerm | None:
    """The colour term's pixels and their foreground posteriors, from the model posed
    at ``prob``'s start: colour histograms (``bins`` per channel) of the pixels inside
    its silhouette (foreground) and of a ring of pixels outside it (background), each
    left out where the measured depth says something stands in front of the model;
    the pixels within ``band`` pixels of the silhouette's edge (a seeded subset of
    ``max_rays``) are the term's. None when the model at the start covers fewer than
    four grid pixels, or fewer than four background pixels are seen around it.
    """
    idx, phi, nearest = _model_pixels(prob, cam, margin=4.0 * band)
    z_meas = _image(depth, cam, "depth").ravel()[idx]
    z_meas = np.where(np.isfinite(z_meas) & (z_meas > 0), z_meas, np.inf)
    fg = phi < -1.0
    bg = (phi > 2.0) & (phi < 4.0 * band)
    if fg.sum() < 4 or bg.sum() < 4:
        return None  # nothing to learn the colours from: no colour term
    # an occluder in front of the model is neither the object's colour nor the
    # background's: its pixels teach nothing (the model's depth there is unknown, so
    # the nearest measured depth in the model's box stands for it)
    near = float(np.median(z_meas[fg][np.isfinite(z_meas[fg])])) \
        if np.isfinite(z_meas[fg]).any() else np.inf
    front = z_meas < near - max(occlusion, 0.5 * prob.size * prob.s)
    q = np.minimum((rgb[idx] * bins).astype(np.int64), bins - 1)
    code = (q[:, 0] * bins + q[:, 1]) * bins + q[:, 2]
    hf = np.bincount(code[fg & ~front], minlength=bins ** 3) + 1.0
    hb = np.bincount(code[bg & ~front], minlength=bins ** 3) + 1.0
    hf, hb = hf / hf.sum(), hb / hb.sum()
    posterior = hf / (hf + hb)
    # the term's pixels: every pixel (not only the grid's, whose regular spacing would
    # let the silhouette's edge sit anywhere between two columns of it) whose nearest
    # grid pixel lies within the band
    cand = nearest[0][np.abs(phi[nearest[1]]) <= band]
    pix = cand[_subsample(len(cand), max_rays, np.random.default_rng(seed))]
    n = len(pix)
    z_pix = _image(depth, cam, "depth").ravel()[pix]
    z_pix = np.where(np.isfinite(z_pix) & (z_pix > 0), z_pix, np.inf)
    q = np.minimum((rgb[pix] * bins).astype(np.int64), bins - 1)
    rays = Rays(np.zeros((n, 3)), _directions(cam)[pix],
                np.broadcast_to([0.0, 0.0, 1.0], (n, 3)).copy(), np.zeros(n),
                np.zeros(n, bool), z_pix)
    return ColorTerm(rays, posterior[(q[:, 0] * bins + q[:, 1]) * bins + q[:, 2]],
                     0.5 * (cam.fx + cam.fy))


def _color_residuals(prob, st: State, idx: list[int], terms) -> tuple[np.ndarray,
                                                                      np.ndarray]:
    """The colour term's residuals ``w (H(phi) - P_f)`` (M,) and Jacobian rows: ``H``
    the smoothed Heaviside (the model's silhouette, 1 inside) of the pixel's signed
    distance ``phi`` to it (pixels: the ray minimum over the depth times the focal
    length), ``P_f`` the pixel's colour posterior; pixels whose measured depth lies in
    front of the model's are left out (an occluder)."""
    ct = terms.color
    rays = ct.rays
    s = math.exp(st.sigma)
    values = prob.values.copy()
    values[idx] = st.cvals
    pv = dict(zip(prob.pnames, values))
    X, _ = ray_minima(prob.prog, pv, prob.backend, st.R, st.t, s, prob.centre,
                      0.5 * prob.size, rays)
    z = np.maximum(X[:, 2], 1e-300)
    keep = np.flatnonzero(~(rays.depth < z - terms.occlusion))
    if not len(keep):
        n = 6 * prob.pose + prob.scale + len(idx)
        return np.zeros(0), np.zeros((0, n))
    m, J = _linearise(prob, st, idx, X[keep])
    k = ct.fpx / z[keep]
    phi = m * k
    w = ct.softness
    heav = 0.5 - np.arctan(phi / w) / math.pi
    dheav = -(w / math.pi) / (w * w + phi * phi)
    wt = terms.color_weight
    return wt * (heav - ct.posterior[keep]), (wt * dheav * k)[:, None] * J


# ------------------------------------------------------------------ the solve
def _linearise(prob, st: State, idx: list[int], P: np.ndarray):
    """Residuals ``s f`` (N,) and Jacobian rows (N, n) of points ``P`` (N, 3) at ``st``."""
    s, _, a, f, gw, Jp = linearise(prob, P, st, idx)
    return s * f, jacobian(prob.pose, prob.scale, s, a, f, gw, Jp)


@dataclass
class _Terms:
    """Which residuals a solve uses: depth points (in ``prob.points``) and silhouette
    rays, with the silhouette's weight and occlusion margin."""

    rays: Rays | None
    weight: float
    occlusion: float
    depth: bool = True
    color: ColorTerm | None = None
    color_weight: float = 0.0


def _evaluate(prob, st: State, idx: list[int], terms: _Terms):
    """All residuals (N,), Jacobian (N, n) and robust weights at ``st``, and the
    silhouette rays used."""
    rs, Js = [], []
    if terms.depth:
        r, J = _linearise(prob, st, idx, prob.points)
        rs.append(r)
        Js.append(J)
    used = np.zeros(0, dtype=np.int64)
    if terms.rays is not None and len(terms.rays):
        rays = terms.rays
        s = math.exp(st.sigma)
        values = prob.values.copy()
        values[idx] = st.cvals
        pv = dict(zip(prob.pnames, values))
        X, m = ray_minima(prob.prog, pv, prob.backend, st.R, st.t, s, prob.centre,
                          0.5 * prob.size, rays)
        z = np.einsum("ij,ij->i", X - rays.origins, rays.axis)
        keep = np.ones(len(rays), bool)
        # an outside pixel whose measured depth is in front of the model sees an occluder
        keep &= ~(rays.outside & (rays.depth < z - terms.occlusion))
        used = np.flatnonzero(keep)
        if len(used):
            r, J = _linearise(prob, st, idx, X[used])
            rs.append(terms.weight * (r - rays.target[used] * z[used]))
            Js.append(terms.weight * J)
    n_color = 0
    if terms.color is not None:
        r, J = _color_residuals(prob, st, idx, terms)
        n_color = len(r)
        rs.append(r)
        Js.append(J)
    r = np.concatenate(rs) if rs else np.zeros(0)
    J = np.concatenate(Js) if Js else np.zeros((0, 0))
    return r, J, (used, n_color)


def _solve(prob, terms: _Terms, max_iter: int, tol: float = 1e-4, step_tol: float = 1e-5,
           max_rejects: int = 3):
    """Robust Levenberg-Marquardt over the terms' residuals from ``prob``'s state
    (updated in place); converged when an accepted step lowers the cost by less than
    ``tol`` of it or moves less than ``step_tol`` (radians and scene units relative to
    the model's size), or after ``max_rejects`` rejected steps in a row (the silhouette
    term's ray minima make the cost slightly rough at the optimum). Returns stats as
    :mod:`.stages` does."""
    idx = [prob.pnames.index(n) for n in prob.names]
    lo = np.array([prob.prog.params[i].lo for i in idx])
    hi = np.array([prob.prog.params[i].hi for i in idx])
    st = State(prob.R, np.asarray(prob.t, float), math.log(prob.s), prob.values[idx].copy())
    r, J, used = _evaluate(prob, st, idx, terms)
    if len(r) < J.shape[1]:
        raise CsdfError(f"{len(r)} residual(s) cannot determine {J.shape[1]} unknowns")
    cost, w = loss_weights(r, prob.f_scale, prob.loss)
    lam, nev, converged = 1e-3, 1, False
    while nev < max_iter:
        A, b = normal_equations(J, w, r)
        accepted = False
        rejects = 0
        while nev < max_iter:
            dx, new, lam = damped_step(prob, A, b, lam, st, lo, hi, 0.5)
            r2, J2, used2 = _evaluate(prob, new, idx, terms)
            nev += 1
            c2, w2 = loss_weights(r2, prob.f_scale, prob.loss)
            if c2 <= cost and len(r2) >= J.shape[1]:
                rel = (cost - c2) / max(cost, 1e-300)
                st, r, J, w, used = new, r2, J2, w2, used2
                cost = c2
                lam = max(lam / 3.0, 1e-9)
                accepted = True
                scale = np.ones(len(dx))
                if prob.pose:
                    scale[3:6] = 1.0 / max(prob.size * prob.s, 1e-300)
                converged = rel < tol or float(np.abs(dx * scale).max()) < step_tol
                break
            lam *= 4.0
            rejects += 1
            if lam > 1e10 or rejects >= max_rejects:
                converged = True
                break
        if converged or not accepted:
            break
    prob.R, prob.t, prob.s = st.R, st.t, math.exp(st.sigma)
    prob.values[idx] = st.cvals
    return {"nfev": nev, "converged": converged, "cost": cost, "notes": [],
            "loss": prob.loss, "residuals": r, "rays_used": len(used[0]),
            "color_used": used[1]}


def _silhouette_quality(r_sil: np.ndarray, rays: Rays | None, used: int, f_scale: float,
                        pixel: float) -> dict:
    """The silhouette term's figures; its RMS passes up to ``SILHOUETTE_LIMIT`` (the
    larger of ``2 f_scale`` and 1.25 pixel footprints at the object's depth, ``pixel``
    in scene units: a mask's boundary is only known to the pixel; right poses measured
    0.25-0.9 footprints, a half-turned one 1.7)."""
    if rays is None or not len(rays):
        return {}
    rms = float(np.sqrt(np.mean(r_sil ** 2))) if len(r_sil) else math.nan
    limit = max(SILHOUETTE_LIMIT[0] * f_scale, SILHOUETTE_LIMIT[1] * pixel)
    return {"silhouette_rays": int(len(rays)), "silhouette_rays_used": int(used),
            "silhouette_rmse": rms, "silhouette_pixel": pixel, "silhouette_limit": limit,
            "silhouette_ok": bool(rms <= limit)}


def _silhouette_reason(sq: dict) -> str:
    return (f"the silhouette's residual RMS {sq['silhouette_rmse']:.3g} is over "
            f"{sq['silhouette_limit']:.3g} (the larger of {SILHOUETTE_LIMIT[0]:g} f_scale "
            f"and {SILHOUETTE_LIMIT[1]:g} pixel footprints)")


def fit_depth(shape, depth, camera, init=None, mask=None, estimate=("pose",), params=None,
              *, silhouette: bool = True, silhouette_weight: float = 1.0,
              band: float = 4.0, max_points: int | None = 2000,
              max_rays: int | None = 400, occlusion_margin: float | None = None,
              loss: str = "huber", f_scale: float | None = None, max_iter: int = 50,
              multistart: bool = False, seed: int = 0, backend: str = "auto",
              check_ranges: bool = True, check_visibility: bool = True,
              gate: float | None = None, color=None, color_weight: float = 1.0,
              max_color_rays: int | None = 300) -> FitResult:
    """Fit a model to a depth image (SDF-RGBD, paper §4.5; see the module docs).

    Args:
        shape: a 3D :class:`csdf.Shape` or :class:`csdf.Program`.
        depth: ``(H, W)`` depth along the optical axis (scene units; 0/NaN missing).
        camera: its :class:`csdf.Camera` (the result is in this camera's frame).
        init: starting model-to-camera pose, as :func:`csdf.fit` takes it (default:
            identity rotation at the back-projected points' centroid).
        mask: ``(H, W)`` bool: the object's visible pixels. The depth term uses only
            these; the silhouette term needs it.
        estimate, params, loss, f_scale, backend, check_ranges: as :func:`csdf.fit`
            (``f_scale`` default 1 % of the model's size).
        silhouette: add the silhouette term (when ``mask`` is given).
        silhouette_weight: its weight against the depth residuals (scaled down by
            ``f_scale / (half a pixel's footprint)`` where pixels are coarser than the
            depth noise).
        band: the contour band's half-width (pixels).
        max_points, max_rays: seeded subsets of the depth pixels and contour rays.
        occlusion_margin: an outside pixel whose measured depth is this much in front of
            the model is occluded (default ``3 f_scale``).
        max_iter: evaluations of the Levenberg-Marquardt solve.
        multistart: find the start first with :func:`csdf.fit` ``(multistart=True)`` on
            the back-projected points (large initial errors, a lost track).
        seed: seeds the subsets and the multistart.
        gate: without a mask, from a start (``init``, no ``multistart``), only the
            points within this distance of the model posed at the start count; the
            others are clutter (another object, a table). Default 10 % of the model's
            size; 0 keeps every point. (The visibility check is skipped then: the
            points gated away would look like holes.)
        check_visibility: include the success test's check that the model's surface
            visible from the camera is explained by the measurements (a ray cast of
            the fitted model: about 10 ms; the silhouette term checks much the same).
        color: ``(H, W, 3)`` the colour image of the same camera (floats in [0, 1] or
            8-bit): adds the region-based colour term (module docs), which needs no
            mask.
        color_weight: the colour term's weight (a full disagreement of a pixel counts
            as ``color_weight * f_scale``).
        max_color_rays: a seeded subset of the colour term's pixels.

    Returns:
        :class:`csdf.FitResult` of the model-to-camera pose; ``success`` is the point
        fit's test (:mod:`.quality`, with the camera centre as viewpoint) and, with the
        silhouette term, its residual's RMS within :data:`SILHOUETTE_LIMIT` (the
        larger of 2 ``f_scale`` and 1.25 pixel footprints at the object's depth: a
        mask's boundary is known to a pixel); ``quality`` adds ``silhouette_rmse``,
        ``silhouette_pixel``, ``silhouette_limit`` and the ray counts.

    Raises:
        CsdfError: a depth or mask of the wrong shape, no valid pixels, bad options.
    """
    t0 = time.perf_counter()
    _check_options(band=band, max_iter=max_iter, max_points=max_points, max_rays=max_rays,
                   seed=seed, silhouette_weight=silhouette_weight, gate=gate,
                   occlusion_margin=occlusion_margin, color_weight=color_weight,
                   max_color_rays=max_color_rays)
    cam = _camera(camera)
    m = None if mask is None else _mask(mask, cam)
    pts, _ = backproject(depth, cam, m)
    if not len(pts):
        raise CsdfError("the depth image has no valid pixels"
                        + (" inside the mask" if m is not None else ""))
    rng = np.random.default_rng(seed)
    gating = m is None and init is not None and not multistart and gate != 0
    # (gating keeps a part of the points: draw more first)
    pts = pts[_subsample(len(pts), None if max_points is None else
                         (4 * max_points if gating else max_points), rng)]
    if multistart:
        from .api import fit

        init = fit(shape, pts, estimate=("pose",), multistart=True, seed=seed,
                   viewpoint=np.zeros(3), backend=backend, check_ranges=check_ranges,
                   max_iter=40, f_scale=f_scale)
    prob = prepare(shape, pts, init, estimate, params, loss, f_scale, backend,
                   check_ranges=check_ranges)
    if prob.loss == "auto":
        prob.loss = "huber"
    kept = 1.0
    if gating:  # clutter: only the points near the model at the start
        g = 0.1 * prob.size * prob.s if gate is None else float(gate)
        r0 = residuals(prob, prob.R, prob.t, prob.s, prob.values)
        near = np.flatnonzero(np.abs(r0) <= g)
        kept = len(near) / len(r0)
        if len(near) < 10:
            raise GateError(f"no depth points within {g:.4g} of the model at the start "
                            "(pass a better init, multistart=True or a mask)")
        near = near[_subsample(len(near), max_points, rng)]
        prob.points = prob.points[near]
    rays = None
    if silhouette and m is not None:
        # (the camera's own frame: the fit is in camera coordinates)
        local = _camera_at_origin(cam)
        rays = contour_rays(m, local, band=band, max_rays=max_rays, depth=depth, seed=seed)
    occ = 3.0 * prob.f_scale if occlusion_margin is None else float(occlusion_margin)
    # a mask's boundary is known to about half a pixel: where that is coarser than the
    # depth noise the silhouette counts for less (measured: masks at 160x120 made fits
    # of the flange worse than depth alone at full weight)
    pixel = float(np.median(prob.points[:, 2])) / (0.5 * (cam.fx + cam.fy))
    weight = float(silhouette_weight) * min(1.0, prob.f_scale / max(0.5 * pixel, 1e-300))
    terms = _Terms(rays, weight, occ)
    if color is not None:
        terms.color = color_term(prob, _color_image(color, cam), depth, cam, occ,
                                 band=COLOR_BAND, max_rays=max_color_rays, seed=seed)
        terms.color_weight = float(color_weight) * prob.f_scale
    stats = _solve(prob, terms, max_iter)
    n_sil = stats["rays_used"]
    r_sil = stats["residuals"][len(prob.points):len(prob.points) + n_sil] / \
        max(weight, 1e-300)
    res = make_result(prob, stats, time.perf_counter() - t0, "csdf-depth", None,
                      viewpoint=np.zeros(3) if check_visibility and not gating else None)
    sq = _silhouette_quality(r_sil, rays, n_sil, prob.f_scale, pixel)
    res.quality.update(sq)
    res.quality["gated"] = kept
    if color is not None:
        res.quality["color_rays"] = 0 if terms.color is None else len(terms.color.rays)
        res.quality["color_rays_used"] = int(stats["color_used"])
    if sq and not sq["silhouette_ok"]:
        res.success = False
        res.quality.setdefault("reasons", []).append(_silhouette_reason(sq))
    res.seconds = time.perf_counter() - t0
    return res


def _camera_at_origin(cam):
    """The same camera with the identity pose (its own frame as the world)."""
    from ..render.camera import Camera

    return Camera(cam.fx, cam.fy, cam.cx, cam.cy, cam.width, cam.height)


def fit_silhouette(shape, masks, cameras, init=None, estimate=("pose",), params=None, *,
                   band: float = 4.0, max_rays: int | None = 600, loss: str = "huber",
                   f_scale: float | None = None, max_iter: int = 60, seed: int = 0,
                   backend: str = "auto", check_ranges: bool = True) -> FitResult:
    """Fit a model to one or more binary masks alone (SDF-RGB, paper §4.5; the
    silhouette term of the module docs, in the cameras' world frame).

    Args:
        shape: a 3D :class:`csdf.Shape` or :class:`csdf.Program`.
        masks: one ``(H, W)`` bool mask or a sequence of them.
        cameras: one :class:`csdf.Camera` or one per mask (posed in the world).
        init: starting model-to-world pose (as :func:`csdf.fit`); default: the model
            placed on the first view's ray through the mask's centroid, at the depth
            where the model's size matches the mask's.
        estimate, params, loss, f_scale, max_iter, seed, backend, check_ranges: as
            :func:`fit_depth`.

    Returns:
        :class:`csdf.FitResult` of the model-to-world pose; ``rmse`` and the inlier
        fraction are of the silhouette residuals (scene units); ``success`` when their
        RMS is within :data:`SILHOUETTE_LIMIT`.

    Raises:
        CsdfError: masks and cameras that do not match, an empty or full mask.
    """
    t0 = time.perf_counter()
    _check_options(band=band, max_iter=max_iter, max_rays=max_rays, seed=seed)
    if isinstance(masks, np.ndarray) and masks.ndim == 2:
        masks = [masks]
    masks = list(masks)
    one = not isinstance(cameras, (list, tuple))
    cams = [cameras] if one else list(cameras)
    if one and len(masks) > 1:  # one camera for every mask
        cams = cams * len(masks)
    if len(cams) != len(masks) or not masks:
        raise CsdfError(f"fit_silhouette needs one camera per mask; got {len(masks)} "
                        f"mask(s) and {len(cams)} camera(s)")
    ms = [_mask(mk, _camera(c, f"cameras[{i}]"), f"masks[{i}]")
          for i, (mk, c) in enumerate(zip(masks, cams))]
    for i, mk in enumerate(ms):
        if not mk.any() or mk.all():
            raise CsdfError(f"masks[{i}] is {'empty' if not mk.any() else 'full'}: no "
                            "silhouette to fit")
    per = None if max_rays is None else max(1, int(max_rays) // len(ms))
    parts = [contour_rays(mk, c, band=band, max_rays=per, seed=seed + i)
             for i, (mk, c) in enumerate(zip(ms, cams))]
    rays = Rays(*(np.concatenate([getattr(p, f) for p in parts])
                  for f in ("origins", "dirs", "axis", "target", "outside", "depth")))
    if init is None:
        init = _silhouette_start(shape, ms[0], cams[0], backend)
    # the rays' points stand in for a cloud: prepare() validates the rest
    prob = prepare(shape, rays.origins + rays.dirs, init, estimate, params, loss, f_scale,
                   backend, check_ranges=check_ranges)
    if prob.loss == "auto":
        prob.loss = "huber"
    terms = _Terms(rays, 1.0, math.inf, depth=False)
    stats = _solve(prob, terms, max_iter)
    r = stats["residuals"]
    thr = 3.0 * prob.f_scale
    inl = np.abs(r) <= thr
    depth = float(np.median(np.einsum("ij,ij->i", prob.t - rays.origins, rays.axis)))
    fpx = float(np.mean([0.5 * (c.fx + c.fy) for c in cams]))
    sq = _silhouette_quality(r, rays, stats["rays_used"], prob.f_scale, depth / fpx)
    ok = bool(sq and sq["silhouette_ok"])
    sq["reasons"] = [] if ok else [_silhouette_reason(sq)]
    return FitResult(
        rotation=prob.R.copy(), translation=np.asarray(prob.t, float).copy(),
        scale=float(prob.s), params=dict(zip(prob.pnames, map(float, prob.values))),
        rmse=float(np.sqrt(np.mean(r[inl] ** 2))) if inl.any() else math.inf,
        inlier_fraction=float(inl.mean()) if len(r) else 0.0, inlier_threshold=thr,
        converged=bool(stats["converged"]), iterations=int(stats["nfev"]),
        seconds=time.perf_counter() - t0, cost=float(stats["cost"]),
        method="csdf-silhouette", notes=[], loss=prob.loss, success=ok, quality=sq)


def _silhouette_start(shape, mask: np.ndarray, cam, backend: str) -> Pose:
    """A start on the ray through the mask's centroid, at the depth where the model's
    bounding diagonal spans the mask's bounding-box diagonal; identity rotation."""
    from ..field import as_field

    fld = as_field(shape, backend=backend, what="fit_silhouette")
    box = fld.model_bounds
    diag = float(np.linalg.norm(box[1] - box[0]))
    v, u = np.nonzero(mask)
    span = math.hypot(u.max() - u.min() + 1, v.max() - v.min() + 1)
    z = 0.5 * (cam.fx + cam.fy) * diag / span
    d = np.array([(u.mean() - cam.cx) / cam.fx, (v.mean() - cam.cy) / cam.fy, 1.0])
    centre_world = cam.R @ (d * z) + cam.t
    centre = 0.5 * (box[0] + box[1])
    return Pose(np.eye(3), centre_world - centre)
