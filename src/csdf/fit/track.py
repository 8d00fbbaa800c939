"""Tracking over a depth video (paper §4.5): :func:`track` fits each frame with
:func:`csdf.fit_depth` from a constant-velocity prediction, tells when it has lost the
object, and re-initialises.

* **Prediction.** With model-to-camera poses ``T_{k-1}``, ``T_k`` of the last two
  frames, frame ``k + 1`` starts from ``(T_k T_{k-1}^-1) T_k``: the same motion again
  (one pose after a start or a re-initialisation).
* **Lost-track detector.** A frame whose fit fails :attr:`csdf.FitResult.success` (too
  few depth points within ``3 f_scale`` of the model, their RMS beyond ``1.5 f_scale``,
  the visible model surface unexplained by the measurements, or, with masks, a
  silhouette residual over :data:`csdf.fit.images.SILHOUETTE_LIMIT`) is *lost*. With
  ``reinit`` it is fitted again from scratch (``multistart``: a search over rotations
  on the frame's points) and the better of the two fits is kept; the motion history
  restarts there. The
  re-initialisation also tries the multistart pose turned half a turn about each of
  the model's axes (a search on depth points alone confuses them; the silhouette
  tells them apart).
* **Shape parameters** (``'params'`` in ``estimate``): each frame's fit starts from the
  running mean of the estimates of the frames tracked so far, and that mean (the
  accumulated evidence) is what the frame reports, so the estimate settles as frames
  come in.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np

from ..errors import CsdfError
from ..pose import Pose
from .images import GateError, fit_depth
from .result import FitResult

__all__ = ["track", "Tracker", "TrackFrame", "TrackResult", "MIN_PIXELS"]


@dataclass
class TrackFrame:
    """One tracked frame.

    Attributes:
        index: the frame's index; pose: the model-to-camera :class:`csdf.Pose`;
        params: parameter values (the running estimate when parameters are tracked);
        success: the fit explains the frame (its :attr:`FitResult.success`);
        lost: the detector fired on the frame's first fit; reinitialised: a
        multistart fit was made; rmse, inlier_fraction: of the depth points;
        silhouette_rmse: of the silhouette residuals (NaN without masks); seconds:
        the frame's time; result: the kept :class:`FitResult` (None for a frame with
        too few valid pixels to fit: it is lost and keeps the prediction).
    """

    index: int
    pose: Pose
    params: dict[str, float]
    success: bool
    lost: bool
    reinitialised: bool
    rmse: float
    inlier_fraction: float
    silhouette_rmse: float
    seconds: float
    result: FitResult | None = field(repr=False)


@dataclass
class TrackResult:
    """All frames of a :func:`track` run."""

    frames: list[TrackFrame]

    def __len__(self) -> int:
        return len(self.frames)

    def __getitem__(self, k: int) -> TrackFrame:
        return self.frames[k]

    @property
    def poses(self) -> list[Pose]:
        """The model-to-camera pose of every frame."""
        return [f.pose for f in self.frames]

    @property
    def success(self) -> np.ndarray:
        """``(F,)`` bool: the frames whose fit explains them."""
        return np.array([f.success for f in self.frames], dtype=bool)

    @property
    def seconds(self) -> np.ndarray:
        """``(F,)`` each frame's time (s)."""
        return np.array([f.seconds for f in self.frames])


def _as_pose(init, what: str = "init") -> tuple[Pose, dict]:
    if isinstance(init, FitResult):
        return Pose(init.rotation, init.translation, init.scale), dict(init.params)
    if isinstance(init, Pose):
        return init, {}
    try:
        M = np.asarray(init, dtype=float)
    except (TypeError, ValueError):
        M = np.zeros(0)
    if M.shape != (4, 4):
        raise CsdfError(f"{what} must be a csdf.Pose, a FitResult or a (4, 4) transform")
    return Pose.nearest(M, what), {}


def _frames(frames, masks) -> Iterable[tuple[np.ndarray, np.ndarray | None]]:
    ms = None if masks is None else list(masks)
    for k, fr in enumerate(frames):
        if isinstance(fr, tuple):
            if len(fr) != 2:
                raise CsdfError(f"frames[{k}]: a tuple must be (depth, mask)")
            yield fr[0], fr[1]
            continue
        if ms is not None and k >= len(ms):
            raise CsdfError(f"masks has {len(ms)} entries but frames has more")
        yield fr, (None if ms is None else ms[k])


#: a frame with fewer valid depth pixels (inside its mask) than this is not fitted
MIN_PIXELS = 20


def _valid_pixels(depth, mask, camera, index: int) -> int:
    """How many pixels of frame ``index`` have a depth (inside the mask, if any)."""
    try:
        z = np.asarray(depth, dtype=np.float64)
    except (TypeError, ValueError):
        raise CsdfError(f"frames[{index}]: the depth must be an image of numbers") from None
    if z.shape != (camera.height, camera.width):
        raise CsdfError(f"frames[{index}]: the depth must have the camera's shape "
                        f"({camera.height}, {camera.width}), got {z.shape}")
    ok = np.isfinite(z) & (z > 0)
    if mask is not None:
        m = np.asarray(mask)
        if m.shape != z.shape:
            raise CsdfError(f"frames[{index}]: the mask must have the depth's shape "
                            f"{z.shape}, got {m.shape}")
        ok &= m.astype(bool)
    return int(ok.sum())


def _reinitialise(shape, depth, camera, mask, centre: np.ndarray, opts: dict) -> FitResult:
    """A lost frame fitted from scratch: the multistart fit, and the same pose turned
    half a turn about each of the model's axes through its centre (the usual ambiguity
    of a search on depth points alone, which the silhouette resolves), each refined;
    the first that succeeds, else the one of lowest cost."""
    best = fit_depth(shape, depth, camera, init=None, mask=mask, multistart=True, **opts)
    if best.success:
        return best
    R, t, s = best.rotation, best.translation, best.scale
    for axis in np.eye(3):
        turn = Pose.from_rotvec(np.pi * axis).rotation
        R2 = R @ turn
        start = {"rotation": R2, "translation": t + s * (R - R2) @ centre, "scale": s,
                 "params": dict(best.params)}
        alt = fit_depth(shape, depth, camera, init=start, mask=mask, **opts)
        if alt.success:
            return alt
        if alt.cost < best.cost:
            best = alt
    return best


class Tracker:
    """Frame-by-frame tracking (what :func:`track` runs over a sequence): ``update``
    fits the next frame from the constant-velocity prediction, ``reset`` restarts from
    a given pose (a re-detection, or a benchmark's reset to the truth after a failure).

    Args: as :func:`track` (``init``: the first frame's model-to-camera pose).
    """

    def __init__(self, shape, camera, init, estimate=("pose",), params=None, *,
                 masks: bool = False, reinit: bool = True,
                 max_points: int | None = None, max_rays: int | None = 120,
                 max_iter: int = 20, f_scale: float | None = None, seed: int = 0,
                 backend: str = "auto", **fit_kwargs):
        from ..field import as_field

        self.shape, self.camera = shape, camera
        est = tuple(e.strip() for e in estimate.split(",")) if isinstance(estimate, str) \
            else tuple(estimate)
        self.track_params = "params" in est
        self.reinit = bool(reinit)
        if max_points is None:  # shape parameters need more evidence per frame
            max_points = 1500 if self.track_params else 600
        self.opts = dict(estimate=est, params=params, max_points=max_points,
                         max_rays=max_rays, max_iter=max_iter, f_scale=f_scale, seed=seed,
                         backend=backend)
        if masks:  # the silhouette term checks what the ray cast would
            self.opts["check_visibility"] = False
        import inspect

        known = set(inspect.signature(fit_depth).parameters) - {
            "shape", "depth", "camera", "init", "mask", "multistart", "color"}
        bad = sorted(set(fit_kwargs) - known)
        if bad:
            raise CsdfError(f"track: unknown option(s) {', '.join(bad)} (fit_depth's options "
                            f"are {', '.join(sorted(known))})")
        self.opts.update(fit_kwargs)
        box = as_field(shape, backend=backend, what="track").model_bounds
        self.centre = 0.5 * (box[0] + box[1])
        self.frames = 0
        self.mean: dict[str, float] = {}
        self.n_mean = 0
        self.reset(init)

    def reset(self, pose) -> None:
        """Restart from ``pose`` (as ``init``): the motion history is forgotten; the
        parameter estimate is kept (a :class:`FitResult`'s parameters replace it)."""
        self.pose, pvals = _as_pose(pose)
        if pvals:
            self.mean, self.n_mean = dict(pvals), 0
        self.prev: Pose | None = None

    def predict(self) -> Pose:
        """The next frame's start: the last motion applied once more."""
        if self.prev is None:
            return self.pose
        return Pose.nearest(self.pose.matrix @ np.linalg.inv(self.prev.matrix)
                            @ self.pose.matrix, "the prediction")

    def _carry(self, guess: Pose, t0: float) -> TrackFrame:
        """A lost frame without a fit: the prediction stands in for it and the motion
        goes on."""
        self.prev, self.pose = self.pose, guess
        frame = TrackFrame(index=self.frames, pose=guess, params=dict(self.mean),
                           success=False, lost=True, reinitialised=False,
                           rmse=math.nan, inlier_fraction=0.0, silhouette_rmse=math.nan,
                           seconds=time.perf_counter() - t0, result=None)
        self.frames += 1
        return frame

    def update(self, depth, mask=None, color=None) -> TrackFrame:
        """Fit the next frame (depth ``(H, W)``, optional mask, optional colour image
        ``(H, W, 3)`` for the colour term of :func:`csdf.fit_depth`) and return it."""
        t0 = time.perf_counter()
        guess = self.predict()
        start = {"rotation": guess.rotation, "translation": guess.translation,
                 "scale": guess.scale, "params": dict(self.mean)}
        shape, camera, opts = self.shape, self.camera, self.opts
        if _valid_pixels(depth, mask, camera, self.frames) < MIN_PIXELS:
            # nothing to fit (the object fully hidden, a dropped frame)
            return self._carry(guess, t0)
        try:
            res: FitResult | None = fit_depth(shape, depth, camera, init=start, mask=mask,
                                              color=color, **opts)
        except GateError:  # no depth points near the prediction: the object is lost
            res = None
        lost = res is None or not res.success
        again = False
        self.prev = self.pose
        if lost and self.reinit:
            alt = _reinitialise(shape, depth, camera, mask, self.centre, opts)
            again = True
            if res is None or alt.success or alt.cost < res.cost:
                res = alt
                self.prev = None  # the motion history restarts
        if res is None:  # lost, not re-initialised: the prediction stands in for it
            return self._carry(guess, t0)
        self.pose = Pose.nearest(res.transform, "the fitted pose")  # (re-orthonormalised)
        if self.track_params and res.success:
            self.n_mean += 1
            for name, v in res.params.items():
                old = self.mean.get(name, v)
                self.mean[name] = old + (v - old) / self.n_mean
        reported = dict(res.params)
        if self.track_params and self.n_mean:
            reported.update(self.mean)
        q = res.quality or {}
        frame = TrackFrame(
            index=self.frames, pose=self.pose, params=reported, success=bool(res.success),
            lost=lost, reinitialised=again, rmse=float(res.rmse),
            inlier_fraction=float(res.inlier_fraction),
            silhouette_rmse=float(q.get("silhouette_rmse", math.nan)),
            seconds=time.perf_counter() - t0, result=res)
        self.frames += 1
        return frame


def track(shape, frames, camera, init, masks=None, estimate=("pose",), params=None, *,
          colors=None, reinit: bool = True, max_points: int | None = None,
          max_rays: int | None = 120, max_iter: int = 20, f_scale: float | None = None,
          seed: int = 0, backend: str = "auto", **fit_kwargs) -> TrackResult:
    """Track a model through depth frames (see the module docs; :class:`Tracker` does it
    frame by frame).

    Args:
        shape: a 3D :class:`csdf.Shape` or :class:`csdf.Program`.
        frames: depth images ``(H, W)`` (scene units, 0 missing), or ``(depth, mask)``
            pairs; any iterable.
        camera: the :class:`csdf.Camera` of the frames.
        init: the first frame's model-to-camera pose (:class:`csdf.Pose`, a (4, 4)
            transform or a :class:`csdf.FitResult`, whose parameters start the
            estimate).
        masks: the object's visible pixels per frame (optional; adds the silhouette
            term and restricts the depth term; without masks, the depth points far
            from the predicted model are left out as clutter).
        estimate, params: as :func:`csdf.fit_depth`; with ``'params'`` the parameters
            are tracked as a running mean.
        colors: the colour image ``(H, W, 3)`` of each frame (same camera), adding
            :func:`csdf.fit_depth`'s region-based colour term: the object's and the
            background's colour statistics, learnt each frame around the predicted
            silhouette, pull the silhouette to where the colours change; no masks
            needed.
        reinit: re-initialise a lost frame with a multistart fit.
        max_points, max_rays, max_iter, f_scale, seed, backend, fit_kwargs: passed to
            :func:`csdf.fit_depth` (fewer points and evaluations than a single fit's
            defaults: a prediction starts close). ``max_points`` defaults to 600, or
            1,500 when parameters are tracked (measured on the chair: per-frame
            parameter estimates from 600 points scatter by several % of their ranges).

    Returns:
        :class:`TrackResult`, one :class:`TrackFrame` per frame.
    """
    tracker = Tracker(shape, camera, init, estimate, params, masks=masks is not None,
                      reinit=reinit, max_points=max_points, max_rays=max_rays,
                      max_iter=max_iter, f_scale=f_scale, seed=seed, backend=backend,
                      **fit_kwargs)
    cs = None if colors is None else iter(colors)
    out = []
    for k, (depth, mask) in enumerate(_frames(frames, masks)):
        color = None
        if cs is not None:
            color = next(cs, None)
            if color is None:
                raise CsdfError(f"colors has {k} images but frames has more")
        out.append(tracker.update(depth, mask, color))
    return TrackResult(out)
