"""The fitting problem of :func:`csdf.fit`: its validated inputs, residuals, their exact
Jacobian and the robust losses (paper §4.5, Eq. 12-13).

Convention: the object sits in the scene at ``p = s R q + t`` (``q`` in the model's frame,
``p`` in the cloud's frame); :attr:`csdf.FitResult.transform` is that 4x4 map. The
residual of a scene point is its signed distance to the posed model, in scene units::

    r(p) = s * f(R^T (p - t) / s; c)        (uniform scaling keeps distances, Eq. 10)

No nearest-neighbour search is needed: the model gives the distance and its gradient.
The unknowns are a rotation increment ``w`` (the Lie algebra of SO(3), applied on the
left of the current rotation and re-centred after every step), ``t``, ``log s`` and the
parameters ``c`` (clipped to their ranges); their Jacobian (:func:`jacobian`) is exact:
the spatial gradient and the parameter derivatives come from one forward-mode pass
(:meth:`csdf.Program.value_grad_param_jacobian`).

Robust losses follow SciPy's ``least_squares`` conventions (:func:`loss_weights`), so
that both engines (:mod:`.lm`, :mod:`.scipy_engine`) minimise the same cost.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import CsdfError, ParamError
from ..field import as_field, field_bounds, step_evaluator
from ..pose import Pose
from .quality import assess
from .result import FitResult

__all__ = ["ESTIMATES", "LOSSES", "Problem", "prepare", "residuals", "jacobian",
           "loss_weights", "loss_rho", "merge_values", "make_result"]

ESTIMATES = ("pose", "scale", "params")
LOSSES = ("auto", "huber", "cauchy", "linear", "soft_l1", "arctan")


@dataclass
class Problem:
    """Everything a fit needs, validated: program, points, what to estimate, start.

    The pose, scale and parameter values are the current state; the engines update them
    in place."""

    prog: object
    points: np.ndarray  # (N, 3) scene points, scene units
    pose: bool
    scale: bool
    names: list[str]  # parameters to estimate
    values: np.ndarray  # all parameter values (P,), current
    R: np.ndarray  # (3, 3) object-to-scene rotation
    t: np.ndarray  # (3,) translation, scene units
    s: float  # uniform scale
    centre: np.ndarray  # object-frame centre of the model (for initial translation)
    size: float  # object size (bounding diagonal), model units
    f_scale: float  # residual scale of the loss, scene units
    loss: str
    backend: str
    estimate: tuple = ()
    bounds: np.ndarray | None = None  # (2, 3) object-frame box of the model, model units
    _evaluators: dict = field(default_factory=dict, repr=False, compare=False)
    tol: float = 1e-7  # the final LM stages stop below this relative cost decrease

    @property
    def pnames(self) -> list[str]:
        """Names of all the program's parameters, in order."""
        return [q.name for q in self.prog.params]

    def evaluator(self, mode: str):
        """The program's evaluator in ``mode`` (``'value'``, ``'grad'`` or ``'all'``) for this
        problem's backend (:func:`csdf.field.step_evaluator`), made once:
        ``f(q (N, 3) model-frame points, all parameter values (P,))`` -> dict."""
        ev = self._evaluators.get(mode)
        if ev is None:
            ev = self._evaluators[mode] = step_evaluator(self.prog, self.backend, mode)
        return ev


def _as_points(points) -> np.ndarray:
    try:
        P = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError):
        raise CsdfError("points must be an (N, 3) array of numbers") from None
    if P.ndim != 2 or P.shape[1] != 3:
        raise CsdfError(f"points must have shape (N, 3); got {P.shape}")
    if len(P) == 0:
        raise CsdfError("the point cloud is empty")
    bad = ~np.isfinite(P).all(axis=1)
    if bad.any():
        rows = np.flatnonzero(bad)
        raise CsdfError(f"{len(rows)} point(s) contain NaN or inf (rows {rows[:5].tolist()}"
                        f"{' ...' if len(rows) > 5 else ''}); remove them first")
    return P


def _parse_estimate(estimate) -> tuple[str, ...]:
    if isinstance(estimate, str):
        estimate = tuple(e.strip() for e in estimate.split(",") if e.strip())
    est = tuple(estimate)
    bad = [e for e in est if e not in ESTIMATES]
    if bad or not est:
        raise CsdfError(f"estimate must be a subset of {ESTIMATES}, got {estimate!r}")
    return est


def _init_pose(init, prob_params: dict) -> tuple:
    """``(R, t, s, params)`` from an init of any supported kind (None: identity)."""
    if init is None:
        return None, None, None, {}
    if isinstance(init, FitResult):
        return init.rotation, init.translation, init.scale, dict(init.params)
    if isinstance(init, Pose):
        return init.rotation.copy(), init.translation.copy(), init.scale, {}
    if isinstance(init, dict):
        R = np.asarray(init.get("rotation", np.eye(3)), dtype=float)
        t = init.get("translation")
        return R, None if t is None else np.asarray(t, dtype=float), \
            float(init.get("scale", 1.0)), dict(init.get("params", {}))
    try:
        M = np.asarray(init, dtype=float)
    except (TypeError, ValueError):
        M = np.zeros(0)
    if M.shape != (4, 4):
        raise CsdfError("init must be a (4, 4) transform, a csdf.Pose, a FitResult, a dict "
                        "or None")
    if not np.all(np.isfinite(M)):
        raise CsdfError("init: the (4, 4) transform must be finite")
    pose = Pose.nearest(M, "init transform")  # the similarity nearest to it
    return pose.rotation.copy(), pose.translation.copy(), pose.scale, {}


def prepare(shape, points, init=None, estimate=("pose",), params=None, loss="huber",
            f_scale=None, backend="auto", *, check_ranges: bool = True) -> Problem:
    """Validate the inputs of :func:`csdf.fit` and build the starting state (arguments as
    there; ``loss`` may still be ``'auto'``, which the caller resolves).

    Initial values of estimated parameters are clipped to their ranges (the solvers
    keep them inside); those of held parameters are range-checked unless
    ``check_ranges`` is False (then used as given)."""
    P = _as_points(points)
    # a point-set job for the backend policy: the compiled backend (values, gradients
    # and parameter derivatives in one call) for clouds of 2,000 points or more
    fld = as_field(shape, backend=backend, work=len(P), what="fit")
    prog = fld.program
    if prog.dim != 3:
        raise CsdfError("fit needs a 3D shape")
    est = _parse_estimate(estimate)
    if loss not in LOSSES:
        raise CsdfError(f"loss must be one of {', '.join(LOSSES)}; got {loss!r}")
    known = [p.name for p in prog.params]
    if "params" in est:
        names = list(known) if params is None else list(params)
        unknown = [n for n in names if n not in known]
        if unknown:
            raise ParamError(f"unknown parameter(s) {unknown}; this shape's parameters: "
                             f"{', '.join(known) or 'none'}")
    else:
        if params:
            raise CsdfError("params names were given but 'params' is not in estimate")
        names = []
    R0, t0, s0, p0 = _init_pose(init, {})
    # validates names and numbers of the initial values
    values = prog.param_values(p0, check_ranges=False)
    prog.param_values({k: v for k, v in p0.items() if k not in names},
                      check_ranges=check_ranges)
    for i, p in enumerate(prog.params):
        if p.name in names:
            values[i] = np.clip(values[i], p.lo, p.hi)
    # the box must hold while the parameters move: the program's own box (valid over
    # the declared ranges), else the bounds policy at the initial values, else a unit box
    bounds = fld.own_bounds
    if bounds is None:
        try:
            bounds = field_bounds(prog, dict(zip(known, values)))
        except CsdfError:
            bounds = np.array([[-1.0] * 3, [1.0] * 3])
    centre = 0.5 * (bounds[0] + bounds[1])
    size = float(np.linalg.norm(bounds[1] - bounds[0]))
    n_unknowns = (6 if "pose" in est else 0) + ("scale" in est) + len(names)
    if len(P) < max(n_unknowns, 1):
        raise CsdfError(f"{len(P)} point(s) cannot determine {n_unknowns} unknowns; "
                        "give at least as many points as unknowns")
    s = 1.0 if s0 is None else s0
    R = np.eye(3) if R0 is None else R0
    t = (P.mean(axis=0) - s * R @ centre) if t0 is None else t0
    fs = 0.01 * size * s if f_scale is None else float(f_scale)
    if not fs > 0:
        raise CsdfError(f"f_scale must be positive, got {f_scale}")
    return Problem(prog, P, "pose" in est, "scale" in est, names, values, R, t, s, centre,
                   size, fs, loss, fld.backend, est, np.asarray(bounds, dtype=float))


def merge_values(prob: Problem, idx: list[int], cvals: np.ndarray) -> np.ndarray:
    """All parameter values (P,): ``prob.values`` with those at indices ``idx`` replaced
    by the estimated values ``cvals`` (len(idx),)."""
    values = prob.values.copy()
    values[idx] = cvals
    return values


def residuals(prob: Problem, R, t, s, values) -> np.ndarray:
    """Signed distances (N,) (scene units) of the points to the model posed by ``R``
    (3, 3), ``t`` (3,), ``s`` with parameter values ``values`` (P,)."""
    q = np.ascontiguousarray(((prob.points - t) @ R) / s, dtype=np.float64)
    return s * prob.evaluator("value")(q, np.asarray(values, dtype=np.float64))["value"]


def _cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Row-wise cross product of (N, 3) arrays (cheaper than ``np.cross``)."""
    out = np.empty_like(u)
    out[:, 0] = u[:, 1] * v[:, 2] - u[:, 2] * v[:, 1]
    out[:, 1] = u[:, 2] * v[:, 0] - u[:, 0] * v[:, 2]
    out[:, 2] = u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]
    return out


def jacobian(pose: bool, scale: bool, s: float, a: np.ndarray, f: np.ndarray,
             gw: np.ndarray, Jp: np.ndarray | None) -> np.ndarray:
    """Jacobian (N, n) of ``r = s f(q)`` for a left rotation increment ``w`` (3), the
    translation ``t`` (3), ``log s`` and the parameters, at the linearisation point.

    ``a`` = ``p - t`` (N, 3), ``f`` model values (N,), ``gw``
    model gradients turned into the scene frame (N, 3), ``Jp`` scaled parameter
    derivatives ``s df/dc`` (N, k) or None."""
    cols = []
    if pose:
        cols += [_cross(gw, a), -gw]
    if scale:
        gq = np.einsum("ij,ij->i", gw, a) / s  # g . q (rotation-invariant)
        cols.append((s * (f - gq))[:, None])
    if Jp is not None and Jp.shape[1]:
        cols.append(Jp)
    return np.concatenate(cols, axis=1) if cols else np.zeros((len(f), 0))


def _rho_w(z: np.ndarray, loss: str) -> tuple[np.ndarray, np.ndarray]:
    if loss == "linear":
        return z, np.ones_like(z)
    if loss == "huber":
        sq = np.sqrt(z)
        big = z > 1.0
        return np.where(big, 2.0 * sq - 1.0, z), np.where(big, 1.0 / np.maximum(sq, 1.0), 1.0)
    if loss == "soft_l1":
        return 2.0 * (np.sqrt(1.0 + z) - 1.0), 1.0 / np.sqrt(1.0 + z)
    if loss == "cauchy":
        return np.log1p(z), 1.0 / (1.0 + z)
    if loss == "arctan":
        return np.arctan(z), 1.0 / (1.0 + z * z)
    raise ValueError(loss)  # pragma: no cover - validated by prepare()


def loss_rho(z: np.ndarray, loss: str) -> np.ndarray:
    """SciPy's ``rho(z)`` of a robust loss at ``z = (r / f_scale)^2`` (any shape)."""
    return _rho_w(z, loss)[0]


try:  # the Huber loss of a step in one pass (the few microseconds of each of its five
    # NumPy passes add up over a fit's steps); the same numbers: only exact operations
    from numba import njit

    @njit(cache=True, fastmath=False)
    def _huber_nb(r, fs):  # pragma: no cover - compiled
        n = r.shape[0]
        rho = np.empty(n)
        w = np.empty(n)
        for k in range(n):
            x = r[k] / fs
            z = x * x
            if z > 1.0:
                sq = np.sqrt(z)
                rho[k] = 2.0 * sq - 1.0
                w[k] = 1.0 / max(sq, 1.0)
            else:
                rho[k] = z
                w[k] = 1.0
        return rho, w
except ImportError:  # pragma: no cover
    _huber_nb = None


def loss_weights(r: np.ndarray, fs: float, loss: str) -> tuple[float, np.ndarray]:
    """Robust cost ``0.5 fs^2 sum rho((r / fs)^2)`` (SciPy's convention) and the IRLS
    weights ``rho'((r / fs)^2)``, shape (N,), for residuals ``r`` (N,) in scene units."""
    if loss == "huber" and _huber_nb is not None and r.ndim == 1 and r.dtype == np.float64:
        rho, w = _huber_nb(r, float(fs))
    else:
        rho, w = _rho_w((r / fs) ** 2, loss)
    return 0.5 * fs * fs * float(np.sum(rho)), w


def make_result(prob: Problem, stats: dict, seconds: float, method: str,
                inlier_threshold: float | None, viewpoint=None, *,
                check_visible: bool = True) -> FitResult:
    """The :class:`FitResult` of ``prob``'s current state, scored by its signed-distance
    residuals; ``stats`` holds ``nfev``, ``converged``, ``notes`` and optionally
    ``cost`` and ``loss``; ``seconds`` is the wall time; ``inlier_threshold`` in scene
    units (default ``3 f_scale``); ``viewpoint`` (3,) or None for the success test
    (:func:`csdf.fit.quality.assess`, timed in ``quality['seconds']`` and included in
    the result's ``seconds``); ``check_visible`` False leaves its visible-surface part
    out though a viewpoint is given."""
    r = residuals(prob, prob.R, prob.t, prob.s, prob.values)
    thr = 3.0 * prob.f_scale if inlier_threshold is None else float(inlier_threshold)
    inl = np.abs(r) <= thr
    rmse = float(np.sqrt(np.mean(r[inl] ** 2))) if inl.any() else math.inf
    t0 = time.perf_counter()
    pv = {p.name: float(v) for p, v in zip(prob.prog.params, prob.values)}
    ok, quality = assess(prob.prog, pv, prob.backend, prob.R, prob.t, prob.s, prob.bounds,
                         prob.points, r, thr, prob.f_scale,
                         viewpoint if check_visible else None)
    if viewpoint is not None and not check_visible:
        quality["visible_note"] = "not asked (check_visible=False)"
    quality["seconds"] = time.perf_counter() - t0
    return FitResult(
        rotation=prob.R.copy(), translation=prob.t.copy(), scale=float(prob.s),
        params={p.name: float(v) for p, v in zip(prob.prog.params, prob.values)},
        rmse=rmse, inlier_fraction=float(inl.mean()), inlier_threshold=thr,
        converged=bool(stats["converged"]), iterations=int(stats["nfev"]),
        seconds=seconds + quality["seconds"],
        cost=float(stats.get("cost", math.nan)), method=method, notes=list(stats["notes"]),
        loss=stats.get("loss"), success=bool(ok), quality=quality,
    )
