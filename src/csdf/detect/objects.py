"""Known models in cluttered scans (paper §4.4): :func:`detect` and
:func:`detections_to_scene`.

The pipeline, for a cloud that holds several objects, a floor or table and clutter:

1. **Neighbourhoods** (:mod:`.neighbours`): normals (turned towards the viewpoint), the
   noise level and the neighbour graph.
2. **Support planes.** :func:`detect_primitives` looks for planes holding at least
   ``SUPPORT_MIN_FRACTION`` of the points; a plane wider than ``SUPPORT_SPAN`` times the
   largest model's diameter is a support (a floor, a table top larger than any model).
   Its points are set aside; the largest support's normal (towards the sensor) is *up*.
3. **Clusters.** The other points split into connected components of the neighbour
   graph (an edge links points no farther apart than ``LINK`` times the local spacing of
   both ends, so isolated outliers join nothing); components of fewer than
   ``min_points`` points are dropped.
4. **Hypotheses per cluster and model**, largest cluster first. With a support, models
   stand upright on it (their +z along *up*, their lowest point on the plane):
   ``YAWS`` turns about *up* at two positions each (the cluster's footprint centre, and
   pushed away from the sensor by a third of the model's radius: a single view sees the
   near side), scored at once, both ways: the robust (Huber) cost of the model's exact
   signed distance at a fixed subsample of the cluster, plus the truncated squared
   distance from each of the model's surface samples that face the sensor to the
   nearest scan point (a model standing where the sensor saw nothing pays); the best
   ``REFINE_TOP`` get a few
   pose-only Gauss-Newton steps (:func:`csdf.fit` on the subsample). Without a support,
   :func:`csdf.fit`'s ``multistart`` search replaces this step.
5. **Refinement.** The best hypothesis is refined by :func:`csdf.fit` in pose and shape
   parameters (``viewpoint=`` visibility, ``loss='auto'``) on the cluster's points near
   it.
6. **Verification.** The fitted model is ray-cast from the viewpoint against every scan
   point in its direction, the support's included (:func:`csdf.fit.check_fit`): its
   visible surface must be seen (at most ``MAX_SEE_THROUGH`` of it where the sensor saw
   farther, through the model, and at most ``MAX_UNEXPLAINED`` see-through or empty in
   all), and it must explain at least ``min_points`` points (within three noise levels).
   Without a viewpoint only the points explained and the inlier rmse are judged.
7. **Competition.** Of the models that pass for a cluster, the one that explains most
   points wins (ties: the lower fit cost). Its inliers are claimed: other clusters that
   are mostly claimed are skipped (one object split in two by an occluder), and a
   cluster with enough unclaimed points left is searched again (two objects touching).

Deterministic: every random choice comes from ``numpy.random.default_rng(seed)``.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import CsdfError
from ..field import as_field
from ..fit import FitResult, check_fit, fit
from ..pose import Pose
from .neighbours import (
    components,
    linked_edges,
    neighbourhood,
    normals_arg,
    points_arg,
    sparse_points,
    viewpoint_arg,
)
from .primitives import PrimitiveDetection, detect_primitives
from .surfaces import frame_z

__all__ = ["Detection", "detect", "detections_to_scene", "YAWS", "REFINE_TOP",
           "SUPPORT_SPAN", "SUPPORT_MIN_FRACTION", "MAX_SEE_THROUGH", "MAX_UNEXPLAINED",
           "MAX_MODELS"]

#: upright hypotheses: turns about the support's normal
YAWS = 16
#: hypotheses refined by pose-only steps before the full fit
REFINE_TOP = 3
#: a plane is a support when its points span at least this times the largest model's
#: diameter
SUPPORT_SPAN = 1.2
#: planes holding fewer than this fraction of the points are not searched as supports
SUPPORT_MIN_FRACTION = 0.05
#: largest fraction of a detection's visible surface where the sensor saw through it
MAX_SEE_THROUGH = 0.12
#: largest fraction of a detection's visible surface see-through or without points
MAX_UNEXPLAINED = 0.25
#: the most models one call searches for
MAX_MODELS = 64
#: a cluster is searched (again) while at least this fraction of it is unclaimed
CLUSTER_LEFT = 0.3
#: the least fraction of the free points inside the fitted model's box (its bounds at
#: the fitted parameters, padded by three noise levels) within three noise levels of
#: its surface
MIN_INLIER_FRACTION = 0.75
#: another cluster joins a fit when at least this fraction of it lies inside the placed
#: model's bounding sphere
PIECE_INSIDE = 0.5
#: a cluster may span this times a model's diameter (its parameters may grow it)
SIZE_SLACK = 1.6
#: points of a cluster that score the upright hypotheses
SCREEN_POINTS = 200
#: mesh resolution of the models' surface extent (tight bounds, centre, radius)
MODEL_RESOLUTION = 48
#: surface samples per model for the screen's model-to-scan term
SURFACE_SAMPLES = 300
#: weight of the model-to-scan term of the screening cost
BACK_WEIGHT = 4.0
#: parameter sets besides the defaults that the hypotheses are screened with
PARAM_STARTS = 4
#: models refined per cluster: those whose best upright hypothesis costs least
MODELS_REFINED = 3
#: a fit whose up axis is within this many degrees of the support's normal is stood
#: upright on the support; one tilted more is rejected (``upright=True``)
UPRIGHT_SNAP = 15.0
#: a cluster reaching farther than this times a model's footprint radius from its
#: centroid also gets hypotheses at the centres of k-means groups of its footprint
FEET_REACH = 1.2
#: the most k-means groups tried (k = 2 .. FEET_SPLIT)
FEET_SPLIT = 3
#: the winner is also fitted from its turns by 360 / TURNS degrees about the support's
#: normal
TURNS = 4
#: the most failed models (ranked above the winner by the screen) whose placements
#: are turned
TURN_MODELS = 2
#: verification scores within this of the best tie (the lower fit cost wins)
TURN_TIE = 0.02
#: points of the final fit at most (a seeded subsample)
FIT_POINTS = 1200


@dataclass
class Detection:
    """One known object found in a scan.

    Attributes:
        model: the model's name (the zoo name, the file's stem, or the key it was given
            under).
        pose: the rigid model-to-scan :class:`csdf.Pose`.
        params: the model's parameter values (all of them; estimated by the fit).
        score: the fraction of the model's visible surface that the scan confirms
            (``1 - visible_unexplained`` from the viewpoint; without a viewpoint the
            fraction of the fitted points within three noise levels).
        inliers: ``(K,)`` indices of the scan points it explains.
        shape: the model (a :class:`csdf.Shape` or :class:`csdf.Program`).
        source: what :func:`detections_to_scene` hands to :meth:`csdf.Scene.add`: the
            zoo name or model file given, else the shape.
        fit: the :class:`csdf.FitResult` of the refinement (its ``quality`` holds the
            verification's figures).
    """

    model: str
    pose: Pose
    params: dict[str, float]
    score: float
    inliers: np.ndarray
    shape: Any = field(repr=False, default=None)
    source: Any = field(repr=False, default=None)
    fit: FitResult | None = field(repr=False, default=None)

    def __repr__(self) -> str:
        t = np.round(self.pose.translation, 3).tolist()
        return (f"Detection({self.model!r}, at {t}, score={self.score:.2f}, "
                f"{len(self.inliers)} points)")

    def to_dict(self) -> dict:
        """JSON-ready: model, pose matrix, params, score, inlier count."""
        return {"model": self.model, "pose": self.pose.matrix.tolist(),
                "params": {k: float(v) for k, v in self.params.items()},
                "score": float(self.score), "points": int(len(self.inliers))}


@dataclass
class _Model:
    name: str
    shape: Any
    source: Any
    bounds: np.ndarray  # (2, 3) of the surface at the defaults (mesh vertices)
    centre: np.ndarray
    radius: float
    fld: Any
    backend: str
    surface: np.ndarray  # (K, 3) surface samples at the defaults (model frame)
    normals: np.ndarray  # (K, 3) their outward unit normals
    starts: list  # parameter sets the hypotheses start from (None: the defaults)
    foot: float  # radius of the footprint (model xy) about the centre, at the defaults


def _model(name: str, shape: Any, source: Any) -> _Model:
    from ..metrics import model_points

    fld = as_field(shape, what="detect")  # the sweep backend: compiled once per model
    if fld.bounds is None or not np.all(np.isfinite(fld.bounds)):
        raise CsdfError(f"detect: model {name!r} has no finite bounds")
    v = model_points(fld, resolution=MODEL_RESOLUTION)
    b = np.array([v.min(axis=0), v.max(axis=0)])
    c = 0.5 * (b[0] + b[1])
    surf = model_points(fld, SURFACE_SAMPLES, resolution=MODEL_RESOLUTION)
    g = np.asarray(fld.gradient(surf), dtype=float)
    g /= np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-300)
    # the defaults, and seeded draws from the middle of the declared ranges
    rng = np.random.default_rng(0)
    starts: list = [None]
    ranged = [p for p in fld.program.params if math.isfinite(p.lo) and math.isfinite(p.hi)]
    for _ in range(PARAM_STARTS if ranged else 0):
        starts.append({p.name: float(rng.uniform(p.lo + 0.2 * (p.hi - p.lo),
                                                 p.hi - 0.2 * (p.hi - p.lo)))
                       for p in ranged})
    return _Model(name, shape, source, b, c, float(np.linalg.norm(v - c, axis=1).max()),
                  fld, fld.backend, surf, g, starts,
                  float(np.linalg.norm(v[:, :2] - c[:2], axis=1).max()))


def _load(spec: Any, what: str) -> tuple[str, Any, Any]:
    """``(name, shape, source)`` of one model given as a shape, a program, a zoo name or
    a model file."""
    from ..compiler.program import Program
    from ..shapes.base import Shape

    if isinstance(spec, (Shape, Program)):
        return what, spec, spec
    if isinstance(spec, os.PathLike) or (isinstance(spec, str) and (
            os.sep in spec or "/" in spec or Path(spec).suffix)):
        from ..io.model import load_model

        return Path(spec).stem, load_model(Path(spec)), str(spec)
    if isinstance(spec, str):
        from .. import zoo

        return spec, zoo.load(spec), spec
    raise CsdfError(f"detect: {what} must be a shape, a program, a zoo name or a model "
                    f"file; got {type(spec).__name__}")


def _models_arg(models: Any) -> list[_Model]:
    if isinstance(models, str):
        models = [m.strip() for m in models.split(",") if m.strip()]
    if isinstance(models, dict):
        items = [(str(k), *_load(v, str(k))[1:]) for k, v in models.items()]
    else:
        try:
            seq = list(models)
        except TypeError:
            seq = [models]
        items = []
        for i, m in enumerate(seq):
            items.append(_load(m, f"model_{i}"))
    if not items:
        raise CsdfError("detect: no models given")
    if len(items) > MAX_MODELS:
        raise CsdfError(f"detect: {len(items)} models is more than the limit of {MAX_MODELS}")
    names = [n for n, _, _ in items]
    dup = next((n for n in names if names.count(n) > 1), None)
    if dup is not None:
        raise CsdfError(f"detect: model name {dup!r} is given twice")
    return [_model(n, s, src) for n, s, src in items]


def _feet(F: np.ndarray, foot: float) -> list[np.ndarray]:
    """Where a model of footprint radius ``foot`` may stand among the points ``F``
    ``(N, 3)`` (a cluster dropped onto the support plane): the centroid, and when the
    cluster reaches farther than ``foot`` from it (two objects touching, an object and
    clutter) also the centres of ``k = 2 .. FEET_SPLIT`` k-means groups (deterministic:
    farthest-point starts, a few Lloyd steps)."""
    c0 = F.mean(axis=0)
    feet = [c0]
    if len(F) < 2 or float(np.linalg.norm(F - c0, axis=1).max()) <= FEET_REACH * foot:
        return feet
    for k in range(2, FEET_SPLIT + 1):
        centres = [F[int(np.argmax(np.linalg.norm(F - c0, axis=1)))]]
        for _ in range(1, k):
            d = np.min([np.linalg.norm(F - c, axis=1) for c in centres], axis=0)
            centres.append(F[int(np.argmax(d))])
        C = np.array(centres)
        for _ in range(8):
            lab = np.argmin(((F[:, None, :] - C[None]) ** 2).sum(axis=2), axis=1)
            C = np.array([F[lab == j].mean(axis=0) if (lab == j).any() else C[j]
                          for j in range(k)])
        feet += list(C)
    return feet


def _rz(yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def detect(points, models, normals=None, viewpoint=None, max_instances=None, seed=0, *,
           noise=None, min_points=None, upright=True) -> list[Detection]:
    """Find known models in a cluttered scan: their poses and shape parameters.

    Args:
        points: ``(N, 3)`` scan points (scene units, metres for the zoo; for
            :func:`csdf.scan` clouds the camera frame, so ``viewpoint=(0, 0, 0)``).
        models: the models to look for: zoo names (a list, or one comma-separated
            string ``'chair,table,stool'``), model files, shapes, or a dict ``{name:
            model}``.
        normals: ``(N, 3)`` normals, or None to estimate them (12 nearest neighbours).
        viewpoint: ``(3,)`` sensor position in the points' frame, for a single-view scan:
            fits match points to the visible surface and detections are verified
            against free space (strongly recommended).
        max_instances: stop after this many detections (default: no limit).
        seed: seed of every random choice (an int); equal seeds give equal results.
        noise: the scan's noise standard deviation (scene units); default estimated
            from the support plane's residuals (the median absolute residual of the
            points near it, times 1.4826), or else from the neighbourhoods.
        min_points: the fewest points a detection explains and a cluster holds; default
            ``max(50, N // 500)``.
        upright: with a support plane, hypotheses stand models upright on it (their
            +z along its normal); False searches all rotations (:func:`csdf.fit`'s
            multistart), for objects that may lie on their side.

    Returns:
        :class:`Detection` list in the order found (largest clusters first).

    Raises:
        CsdfError: bad points, normals, viewpoint or models, a model without bounds.
    """
    P = points_arg(points)
    ms = _models_arg(models)
    n = len(P)
    vp = viewpoint_arg(viewpoint)
    cap = math.inf if max_instances is None else int(max_instances)
    if cap <= 0 or n < 10:
        return []
    nb = neighbourhood(P, viewpoint=vp, want_normals=normals is None)
    if normals is None:
        N = nb.normals
    else:
        N = normals_arg(normals, P)
    sigma = nb.noise if noise is None else float(noise)
    if not (math.isfinite(sigma) and sigma > 0):
        raise CsdfError(f"noise must be a positive number; got {noise!r}")
    mp = max(50, n // 500) if min_points is None else max(4, int(min_points))
    rng = np.random.default_rng(seed)
    run = _Run(P, N, nb, vp, sigma, mp, rng, ms)
    run.estimate_noise = noise is None
    run.upright = bool(upright)
    run.find_supports()
    run.find_clusters()
    out: list[Detection] = []
    for members in run.clusters:
        while len(out) < cap:
            free = members[~run.claimed[members]]
            if len(free) < mp or len(free) < CLUSTER_LEFT * len(members):
                break
            det = run.best_for(free)
            if det is None:
                break
            run.claimed[det.inliers] = True
            out.append(det)
        if len(out) >= cap:
            break
    return out


class _Run:
    """The state of one :func:`detect` call."""

    def __init__(self, P, N, nb, vp, sigma, mp, rng, models):
        self.P, self.N, self.nb, self.vp = P, N, nb, vp
        self.sigma, self.mp, self.rng, self.models = sigma, mp, rng, models
        self.support = np.zeros(len(P), dtype=bool)
        self.claimed = np.zeros(len(P), dtype=bool)
        self.plane: tuple[np.ndarray, float] | None = None
        self.clusters: list[np.ndarray] = []
        self.label = np.full(len(P), -1)  # cluster of each point (-1: none)
        self.sizes = np.zeros(0, dtype=int)
        self.estimate_noise = True
        self.upright = True
        if vp is not None:
            d = P - vp
            self.dirs = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-300)

    def find_supports(self) -> None:
        n = len(self.P)
        span_min = SUPPORT_SPAN * 2.0 * max(m.radius for m in self.models)
        planes = detect_primitives(
            self.P, self.N, kinds=("plane",), epsilon=3.0 * self.sigma,
            min_points=max(self.mp, int(SUPPORT_MIN_FRACTION * n)),
            seed=int(self.rng.integers(2**31)), viewpoint=self.vp, max_primitives=4)
        for pl in planes:
            Q = self.P[pl.inliers]
            nrm = np.asarray(pl.params["normal"])
            R = frame_z(nrm)
            uv = Q @ R[:, :2]
            span = float(np.max(uv.max(axis=0) - uv.min(axis=0)))
            if span < span_min:
                continue
            off = float(pl.params["offset"])
            d = self.P @ nrm - off
            if self.plane is None and self.estimate_noise:
                # the noise level from the support's residuals (the neighbourhoods'
                # estimate is low when the noise is not small against the spacing)
                band = np.abs(d) <= 8.0 * self.sigma
                off += float(np.median(d[band]))
                d = self.P @ nrm - off
                r = np.abs(d[band])
                if self.vp is not None:
                    # a range sensor's noise lies along its rays: a point on a plane
                    # seen at incidence theta is off it by the range error times
                    # cos(theta), and frontal surfaces get the whole range error
                    cos = np.abs(self.dirs[band] @ nrm)
                    r = r[cos >= 0.2] / cos[cos >= 0.2] if (cos >= 0.2).sum() >= 20 else r
                self.sigma = max(self.sigma, 1.4826 * float(np.median(r)))
            # the plane's slab: its points and every point within three noise levels
            self.support |= np.abs(d) <= 3.0 * self.sigma
            self.support[pl.inliers] = True
            if self.plane is None:  # the largest support: its normal is up
                self.plane = (nrm, off)

    def find_clusters(self) -> None:
        mask = ~self.support & ~sparse_points(self.nb, self.P, self.vp)
        if self.plane is not None:  # below the support is not an object on it
            nrm, off = self.plane
            mask &= self.P @ nrm - off > 0
        lab = components(self.nb, mask, linked_edges(self.nb, strict=True))
        sizes = np.bincount(lab[lab >= 0]) if (lab >= 0).any() else np.zeros(0, int)
        big = sizes >= self.mp
        self.label = np.where(lab >= 0, np.where(big[np.maximum(lab, 0)], lab, -1), -1)
        self.sizes = sizes
        order = np.argsort(-sizes, kind="stable")
        self.clusters = [np.flatnonzero(lab == i) for i in order if big[i]]

    # -- hypotheses -----------------------------------------------------------------
    def _upright(self, m: _Model, Q: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
        """Upright poses ``(R, t)`` of model ``m`` on the support near points ``Q``."""
        nrm, off = self.plane
        Rup = frame_z(nrm)
        poses = []
        for foot in _feet(Q - np.outer(Q @ nrm - off, nrm), m.foot):
            away = None
            if self.vp is not None:
                a = foot - self.vp
                a = a - (a @ nrm) * nrm
                if np.linalg.norm(a) > 0:
                    away = a / np.linalg.norm(a)
            shifts = [np.zeros(3)] + ([away * m.radius / 3.0] if away is not None else [])
            for k in range(YAWS):
                R = Rup @ _rz(2.0 * math.pi * k / YAWS)
                c = R @ m.centre
                for sh in shifts:
                    t = foot + sh - (c - (c @ nrm) * nrm)  # footprint centre over the foot
                    t = t - (t @ nrm - off + m.bounds[0, 2]) * nrm  # lowest point on plane
                    poses.append((R, t))
        return poses

    def _two_sided(self, m: _Model, poses, S: np.ndarray, params: dict | None = None
                   ) -> np.ndarray:
        """``(H,)`` the screening cost of each pose ``(R, t)`` of model ``m``, in units
        of ``fs^2`` (``fs`` the wide residual scale): the mean Huber cost of the model's
        signed distance at the scan points ``S``, plus the mean truncated squared
        distance from the model's surface samples that face the sensor to the nearest
        scan point (a model standing where the sensor saw nothing pays)."""
        fs = self._fs_wide(m)
        fld = m.fld if params is None else m.fld.replace(params=params, check_ranges=False)
        q = np.concatenate([(S - t) @ R for R, t in poses])
        f = np.asarray(fld.value(q), dtype=float).reshape(len(poses), len(S))
        a = np.abs(f)
        fwd = np.where(a <= fs, 0.5 * a * a, fs * (a - 0.5 * fs)).mean(axis=1)
        surf, nrm = m.surface, m.normals
        if params is not None:  # the surface samples moved onto the varied model
            g = np.asarray(fld.gradient(surf), dtype=float)
            surf = surf - np.asarray(fld.value(surf), dtype=float)[:, None] * g
        X = np.stack([surf @ R.T + t for R, t in poses])  # (H, K, 3)
        if self.vp is not None:
            Nw = np.stack([nrm @ R.T for R, _ in poses])
            front = np.einsum("hki,hki->hk", Nw, self.vp - X) > 0
        else:
            front = np.ones(X.shape[:2], dtype=bool)
        dd, _ = self.nb.tree.query(X.reshape(-1, 3), k=1, distance_upper_bound=fs)
        dd = np.minimum(dd, fs).reshape(X.shape[:2])
        back = (np.where(front, 0.5 * dd * dd, 0.0).sum(axis=1)
                / np.maximum(front.sum(axis=1), 1))
        return (fwd + BACK_WEIGHT * back) / fs ** 2

    def _fs_wide(self, m: _Model) -> float:
        return max(3.0 * self.sigma, 0.02 * m.radius)

    def _placed(self, m: _Model, idx: np.ndarray, S: np.ndarray
                ) -> tuple[float, FitResult | None]:
        """Step 4 for model ``m``: the best upright hypothesis after pose-only steps,
        and its screening cost (:meth:`_two_sided`)."""
        poses = self._upright(m, self.P[idx])
        cands = []  # (cost, pose index, parameter set)
        for k, pv in enumerate(m.starts):
            cost = self._two_sided(m, poses, S, pv)
            cands += [(float(cost[i]), i, k) for i in range(len(poses))]
        cands.sort()
        best: tuple[float, FitResult | None] = (math.inf, None)
        for _, i, k in cands[:REFINE_TOP]:
            R, t = poses[i]
            pv = m.starts[k]
            r = fit(m.shape, S, init={"rotation": R, "translation": t, "params": pv or {}},
                    estimate=("pose",), loss="huber", f_scale=self._fs_wide(m),
                    escape=False, max_iter=15, backend=m.backend, check_ranges=False)
            c = float(self._two_sided(m, [(r.rotation, r.translation)], S, pv)[0])
            if c < best[0]:
                best = (c, r)
        return best

    def _gather(self, m: _Model, idx: np.ndarray, init: FitResult | dict) -> np.ndarray:
        """The points a fit of ``m`` placed at ``init`` (a result or a dict of
        ``rotation`` and ``translation``) uses: the free points of the clusters the
        placed model covers: its own (those of ``idx``), and any other that lies mostly
        inside its bounding sphere (a piece of the same object cut off by an occluder),
        not a neighbour that only reaches into it."""
        if isinstance(init, dict):
            c = init["rotation"] @ m.centre + init["translation"]
        else:
            c = init.pose.apply(m.centre[None])[0]
        inside = ~self.claimed & (self.label >= 0) & (
            np.linalg.norm(self.P - c, axis=1) <= 1.1 * m.radius)
        labs, counts = np.unique(self.label[inside], return_counts=True)
        own = set(np.unique(self.label[idx]).tolist())
        keep = [lab for lab, k in zip(labs, counts)
                if lab in own or k >= PIECE_INSIDE * self.sizes[lab]]
        return np.flatnonzero(inside & np.isin(self.label, keep))

    def _candidate(self, m: _Model, idx: np.ndarray, init: FitResult | dict | None
                   ) -> FitResult | None:
        """Step 5: the refined fit of model ``m`` to the points ``idx`` from the placed
        hypothesis ``init`` (a result or a dict of ``rotation``, ``translation`` and
        ``params``; None: :func:`csdf.fit`'s multistart search)."""
        if init is not None:
            idx = self._gather(m, idx, init)
        F = idx if len(idx) <= FIT_POINTS else np.sort(
            self.rng.choice(idx, FIT_POINTS, replace=False))
        try:
            res = fit(m.shape, self.P[F], init=init, estimate=("pose", "params"),
                      loss="cauchy", f_scale=max(self.sigma, 0.005 * m.radius),
                      viewpoint=self.vp, multistart=init is None,
                      seed=int(self.rng.integers(2**31)), max_iter=40, escape=False,
                      debias=False, backend=m.backend, check_ranges=False)
        except CsdfError:
            return None
        if init is None or self.plane is None:
            return res
        return self._upright_fit(m, F, res)

    def _upright_fit(self, m: _Model, F: np.ndarray, res: FitResult) -> FitResult | None:
        """``res`` stood on the support (upright, the model's floor on the plane), then
        its parameters fitted again with that pose held. None when ``res`` tilts more
        than ``UPRIGHT_SNAP`` degrees (it fell over: not an object standing on the
        support)."""
        nrm, off = self.plane
        R = res.rotation
        if R[:, 2] @ nrm < math.cos(math.radians(UPRIGHT_SNAP)):
            return None
        x = R[:, 0] - (R[:, 0] @ nrm) * nrm
        x /= np.linalg.norm(x)
        R = np.stack([x, np.cross(nrm, x), nrm], axis=1)
        t = np.asarray(res.translation, float)
        t = t - (t @ nrm - off + m.bounds[0, 2]) * nrm
        try:
            return fit(m.shape, self.P[F], init={"rotation": R, "translation": t,
                                                 "params": res.params},
                       estimate=("params",), loss="cauchy", f_scale=res.quality.get(
                           "noise_level", self.sigma), viewpoint=self.vp, max_iter=30,
                       escape=False, debias=False, backend=m.backend, check_ranges=False)
        except CsdfError:
            return res

    def _verify(self, m: _Model, res: FitResult) -> tuple[bool, float, np.ndarray, FitResult]:
        """Step 6: ``(accepted, score, inliers, checked result)``."""
        pose = res.pose
        fld = as_field(m.shape, res.params, pose=pose, backend=m.backend, what="detect",
                       check_ranges=False)
        free = ~self.claimed
        c = pose.apply(m.centre[None])[0]
        near = np.flatnonzero(free & (np.linalg.norm(self.P - c, axis=1)
                                      <= 1.2 * m.radius + 3 * self.sigma))
        d = np.abs(np.asarray(fld.value(self.P[near]), dtype=float))
        close = d <= 3.0 * self.sigma
        inl = near[close & ~self.support[near]]
        if len(inl) < self.mp:
            return False, 0.0, inl, res
        # of the free points inside the fitted model's box (a neighbour's points outside
        # it are not the model's business), enough must lie on its surface
        b = as_field(m.shape, res.params, backend=m.backend, what="detect",
                     check_ranges=False).bounds
        q = (self.P[near] - pose.translation) @ pose.rotation
        pad = 3.0 * self.sigma
        boxed = np.all((q >= b[0] - pad) & (q <= b[1] + pad), axis=1) & ~self.support[near]
        if close[boxed].sum() < MIN_INLIER_FRACTION * boxed.sum():
            return False, 0.0, inl, res
        if self.vp is None:
            frac = len(inl) / max(len(near[~self.support[near]]), 1)
            return frac >= 0.5, float(frac), inl, res
        dist = float(np.linalg.norm(c - self.vp))
        if dist <= m.radius:
            return True, 1.0, inl, res
        ang = math.asin(min(1.0, (1.2 * m.radius) / dist))
        axis = (c - self.vp) / dist
        view = np.flatnonzero(self.dirs @ axis >= math.cos(ang))
        checked = check_fit(m.shape, self.P[view], res, viewpoint=self.vp,
                            f_scale=max(self.sigma, 1e-9), backend=m.backend)
        q = checked.quality
        if not q.get("visible_checked"):
            return True, float(len(inl) / max(len(near), 1)), inl, checked
        unexpl = float(q["visible_unexplained"])
        ok = q["visible_see_through"] <= MAX_SEE_THROUGH and unexpl <= MAX_UNEXPLAINED
        return bool(ok), 1.0 - unexpl, inl, checked

    def best_for(self, idx: np.ndarray) -> Detection | None:
        """Steps 4-7 for the points ``idx``: the best verified detection, or None."""
        ext = self.P[idx].max(axis=0) - self.P[idx].min(axis=0)
        span = float(np.linalg.norm(ext))
        fits = [m for m in self.models if span <= 2.0 * m.radius * SIZE_SLACK + 6 * self.sigma]
        if not fits:
            return None
        sub = idx if len(idx) <= SCREEN_POINTS else np.sort(
            self.rng.choice(idx, SCREEN_POINTS, replace=False))
        S = self.P[sub]
        if self.plane is not None and self.upright:
            placed = [(*self._placed(m, idx, S), i) for i, m in enumerate(fits)]
            ranked = sorted(placed, key=lambda x: (x[0], x[2]))[:MODELS_REFINED]
            tries = [(fits[i], init) for _, init, i in ranked]
        else:
            tries = [(m, None) for m in fits]
        done = []  # per model tried: (model, init, base result or None, verified fits)
        for m, init in tries:
            found = []
            res = self._candidate(m, idx, init)
            if res is not None:
                ok, score, inl, checked = self._verify(m, res)
                if ok:
                    found.append((score, float(res.cost), res, inl, checked))
            done.append((m, init, res, found))
        if self.plane is not None and self.upright:
            # the winner's quarter turns, and those of the placements of models the
            # screen ranked higher but whose fits failed (at most TURN_MODELS)
            win = [d for d in done if d[3]]
            turn = []
            if win:
                w = max(win, key=lambda d: (len(d[3][0][3]), -d[3][0][1]))
                turn = [w]
                ranked_above = done[:next(i for i, d in enumerate(done) if d is w)]
            else:
                ranked_above = done
            # models the screen ranked above the winner (or all, when none passed)
            turn += [d for d in ranked_above if d[1] is not None][:TURN_MODELS]
            for m, init, res, found in turn:
                # a verified fit is checked against its half turn (front and back
                # alike from one view); a failed placement tries every quarter turn
                steps = (TURNS // 2,) if found else range(1, TURNS)
                self._turns(m, idx, res if found else init, found, steps)
        best = None
        for m, _, _, found in done:
            if not found:
                continue
            score, cost, res, inl, checked = _pick(found)
            key = (len(inl), -cost)
            if best is None or key > best[0]:
                best = (key, Detection(model=m.name, pose=Pose(res.rotation, res.translation),
                                       params=dict(res.params), score=score, inliers=inl,
                                       shape=m.shape, source=m.source, fit=checked))
        return None if best is None else best[1]

    def _turns(self, m: _Model, idx: np.ndarray, base: FitResult, found: list,
               steps=range(1, TURNS)) -> list:
        """``found`` with the fits from ``base`` turned about the support's normal by
        ``steps`` times ``360 / TURNS`` degrees (through the model's centre) that pass verification
        (items ``(score, cost, result, inliers, checked)``). A single view often leaves
        a box-like object's front and back, or its sides, nearly alike, and the screen's
        pick among them is a close call."""
        nrm = self.plane[0]
        cw = base.rotation @ m.centre + base.translation
        X = np.array([[0.0, -nrm[2], nrm[1]], [nrm[2], 0.0, -nrm[0]], [-nrm[1], nrm[0], 0.0]])
        for k in steps:
            th = 2.0 * math.pi * k / TURNS
            Rt = math.cos(th) * np.eye(3) + math.sin(th) * X + (1 - math.cos(th)) * np.outer(
                nrm, nrm)
            init = {"rotation": Rt @ base.rotation,
                    "translation": Rt @ (base.translation - cw) + cw,
                    "params": dict(base.params)}
            r = self._candidate(m, idx, init)
            if r is None:
                continue
            ok, sc, il, ch = self._verify(m, r)
            if ok:
                found.append((sc, float(r.cost), r, il, ch))
        return found


def _pick(found: list) -> tuple:
    """The best of verified fits ``(score, cost, result, inliers, checked)``: scores
    within ``TURN_TIE`` of the best tie, and the lower cost wins."""
    top = max(f[0] for f in found)
    return min((f for f in found if f[0] >= top - TURN_TIE), key=lambda f: f[1])


def detections_to_scene(detections, scene=None):
    """A :class:`csdf.Scene` holding every detection (model, pose, parameters; named
    ``'{model}_{k}'``), added to ``scene`` when given.

    Raises:
        CsdfError: an item that is not a :class:`Detection` or :class:`PrimitiveDetection`.
    """
    from ..scene import Scene

    sc = Scene() if scene is None else scene
    count: dict[str, int] = {}
    for d in detections:
        if isinstance(d, Detection):
            k = count[d.model] = count.get(d.model, 0) + 1
            sc.add(d.source if d.source is not None else d.shape, pose=d.pose,
                   params=d.params, name=f"{d.model}_{k}")
        elif isinstance(d, PrimitiveDetection):
            if d.kind == "plane":
                continue  # unbounded: a scene holds bounded models
            k = count[d.kind] = count.get(d.kind, 0) + 1
            sc.add(d.shape, name=f"{d.kind}_{k}")
        else:
            raise CsdfError(f"detections_to_scene: expected Detection items, got "
                            f"{type(d).__name__}")
    return sc

