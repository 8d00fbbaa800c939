"""Recover pose, scale and shape parameters from a point cloud (paper §4.5, Eq. 12-13).

Convention: the object sits in the scene at ``p = s R q + t`` (``q`` in the model's frame,
``p`` in the cloud's frame); :attr:`FitResult.transform` is that 4x4 map. The residual of a
scene point is its signed distance to the posed model, in scene units::

    r(p) = s * f(R^T (p - t) / s; c)        (uniform scaling keeps distances, Eq. 10)

No nearest-neighbour search is needed: the model gives the distance and its gradient.
The unknowns are a rotation increment ``w`` (the Lie algebra of SO(3), applied on the
left of the current rotation and re-centred after every step), ``t``, ``log s`` and the
parameters ``c`` (clipped to their ranges); their Jacobian is exact: the spatial gradient
and the parameter derivatives come from one forward-mode pass
(:meth:`csdf.Program.value_grad_param_jacobian`).

Engines (``solver=``): ``'lm'`` (default, :mod:`.gn`): a hand-written robust
Levenberg-Marquardt, coarse to fine with a graduated residual scale, an escape step for
the minima of near-symmetric parts, an optional visibility term for single-view scans and
a noise-bias correction of shape parameters; ``'scipy'``: SciPy's ``least_squares``
(trust region reflective), in rounds re-centred on the current rotation.

Losses (``loss=``): SciPy's robust losses at the residual scale ``f_scale``, and the
default ``'auto'``: Huber first; when the Huber solution leaves more than 1% of the points
farther than ``3 f_scale`` from the surface, Cauchy refines that solution (and, beyond 10%,
also restarts from the same start), and the lowest Cauchy cost wins (:func:`auto_continue`).

Scale and size parameters: if the estimated parameters can resize the whole shape (a
sphere's radius; a chair whose every dimension is a parameter), ``s`` and the parameters
describe the same change and the problem is singular or nearly so. With ``'lm'`` csdf
measures this at the start of the joint stage (:func:`scale_ambiguity`: the sine of the
angle between the Jacobian column of ``log s`` and the span of the parameters' columns);
below ``AMBIGUITY_SIN`` the scale is held at its start (1 unless ``init`` gives one) and
the parameters absorb the size; the reason is listed in :attr:`FitResult.notes`.
Otherwise both are estimated. (``'scipy'`` instead adds a weak prior pulling ``log s`` to
its start when both are estimated.)
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from ..errors import CsdfError, ParamError
from .gn import jacobian, loss_weights
from .lie import exp_so3, left_jacobian

__all__ = ["FitResult", "fit", "Problem", "prepare"]

ESTIMATES = ("pose", "scale", "params")
LOSSES = ("auto", "huber", "cauchy", "linear", "soft_l1", "arctan")
#: ``loss='auto'``: Huber first; if the fraction of points with ``|r| <= AUTO_INLIER_K *
#: f_scale`` is below ``AUTO_CLEAN``, Cauchy continues from the Huber solution, and below
#: ``AUTO_SWITCH`` Cauchy also restarts from the start (see :func:`auto_continue`)
AUTO_SWITCH = 0.9
AUTO_CLEAN = 0.99
AUTO_INLIER_K = 3.0


@dataclass
class FitResult:
    """The recovered object pose, scale and parameters, with quality measures.

    Attributes:
        rotation: (3, 3) object-to-scene rotation ``R``.
        translation: (3,) object origin in the scene ``t`` (scene units).
        scale: uniform scale ``s`` (``p = s R q + t``).
        params: all parameter values ``{name: value}`` (estimated and fixed).
        rmse: root mean square of the residuals of the inliers (scene units).
        inlier_fraction: fraction of points with ``|r| <= inlier_threshold``.
        inlier_threshold: the threshold used (scene units).
        converged: the optimiser met a convergence test (not the iteration limit).
        iterations: residual evaluations used.
        seconds: wall time.
        cost: final robust cost.
        method: ``'csdf'`` (SDF-to-cloud least squares) or ``'icp'``.
        notes: remarks such as scale/parameter ambiguity, or what ``loss='auto'`` did.
        loss: the robust loss of the final solve (``'huber'`` or ``'cauchy'`` when
            ``loss='auto'`` was asked; None for :func:`csdf.icp`).
    """

    rotation: np.ndarray
    translation: np.ndarray
    scale: float
    params: dict[str, float]
    rmse: float
    inlier_fraction: float
    inlier_threshold: float
    converged: bool
    iterations: int
    seconds: float
    cost: float = math.nan
    method: str = "csdf"
    notes: list[str] = field(default_factory=list)
    loss: str | None = None

    @property
    def transform(self) -> np.ndarray:
        """(4, 4) object-to-scene transform ``[[s R, t], [0, 1]]``."""
        T = np.eye(4)
        T[:3, :3] = self.scale * self.rotation
        T[:3, 3] = self.translation
        return T

    def to_dict(self) -> dict:
        """JSON-ready dictionary."""
        return {
            "method": self.method, "transform": self.transform.tolist(),
            "rotation": self.rotation.tolist(), "translation": self.translation.tolist(),
            "scale": self.scale, "params": dict(self.params), "rmse": self.rmse,
            "inlier_fraction": self.inlier_fraction, "inlier_threshold": self.inlier_threshold,
            "converged": self.converged, "iterations": self.iterations,
            "seconds": self.seconds, "cost": self.cost, "notes": list(self.notes),
            "loss": self.loss,
        }


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


@dataclass
class Problem:
    """Everything a fit needs, validated: program, points, what to estimate, start."""

    prog: object
    points: np.ndarray
    pose: bool
    scale: bool
    names: list[str]  # parameters to estimate
    values: np.ndarray  # all parameter values (P,), current
    R: np.ndarray
    t: np.ndarray
    s: float
    centre: np.ndarray  # object-frame centre of the model (for initial translation)
    size: float  # object size (bounding diagonal), model units
    f_scale: float
    loss: str
    backend: str
    estimate: tuple = ()

    @property
    def pnames(self) -> list[str]:
        """Names of all the program's parameters, in order."""
        return [q.name for q in self.prog.params]


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
    if isinstance(init, dict):
        R = np.asarray(init.get("rotation", np.eye(3)), dtype=float)
        t = init.get("translation")
        return R, None if t is None else np.asarray(t, dtype=float), \
            float(init.get("scale", 1.0)), dict(init.get("params", {}))
    M = np.asarray(init, dtype=float)
    if M.shape != (4, 4) or not np.all(np.isfinite(M)):
        raise CsdfError("init must be a (4, 4) transform, a FitResult, a dict or None")
    A = M[:3, :3]
    s = float(np.cbrt(np.linalg.det(A)))
    if not s > 0:
        raise CsdfError("init transform must have a positive determinant")
    U, _, Vt = np.linalg.svd(A / s)
    return U @ Vt, M[:3, 3].copy(), s, {}


def _resolve_backend(backend: str, prog, n: int) -> str:
    """``'auto'`` becomes ``'fast'`` (values, gradients and parameter derivatives in one
    compiled call) for clouds of 2,000 points or more when Numba is there."""
    if backend != "auto":
        return backend
    from ..backends import fast

    return "fast" if fast.available() and n >= 2000 else "auto"


def prepare(shape, points, init=None, estimate=("pose",), params=None, loss="huber",
            f_scale=None, backend="auto") -> Problem:
    """Validate the inputs of :func:`fit` and build the starting state."""
    from ..compiler.program import as_program

    prog, shp = as_program(shape, "fit")
    bounds = None if shp is None else shp.bounds
    if prog.dim != 3:
        raise CsdfError("fit needs a 3D shape")
    P = _as_points(points)
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
    values = prog.param_values(p0)  # validates names of the initial values
    if bounds is None:
        from ..mesh.api import auto_bounds

        try:
            bounds = auto_bounds(prog, dict(zip(known, values)))
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
                   size, fs, loss, _resolve_backend(backend, prog, len(P)), est)


class _Residuals:
    """Residuals and exact Jacobian for one linearisation rotation ``R0``."""

    def __init__(self, prob: Problem, R0: np.ndarray, weight_prior: float):
        self.p = prob
        self.R0 = R0
        self.idx = [i for i, p in enumerate(prob.prog.params) if p.name in prob.names]
        self.prior = weight_prior
        self._cache_x = None
        self._cache = None

    def unpack(self, x: np.ndarray):
        p = self.p
        k = 0
        w = np.zeros(3)
        t = p.t
        if p.pose:
            w, t = x[0:3], x[3:6]
            k = 6
        sigma = math.log(p.s)
        if p.scale:
            sigma = x[k]
            k += 1
        values = p.values.copy()
        values[self.idx] = x[k:k + len(self.idx)]
        return w, t, sigma, values

    def pack(self) -> np.ndarray:
        p = self.p
        parts = []
        if p.pose:
            parts += [np.zeros(3), p.t]
        if p.scale:
            parts.append([math.log(p.s)])
        parts.append(p.values[self.idx])
        return np.concatenate([np.ravel(a) for a in parts])

    def _eval(self, x: np.ndarray):
        if self._cache_x is not None and np.array_equal(x, self._cache_x):
            return self._cache
        p = self.p
        w, t, sigma, values = self.unpack(x)
        R = exp_so3(w) @ self.R0
        s = math.exp(sigma)
        a = p.points - t
        q = (a @ R) / s  # rows: R^T a / s
        pv = dict(zip((q_.name for q_ in p.prog.params), values))
        f, g, J = p.prog.value_grad_param_jacobian(q, pv, backend=p.backend)
        self._cache_x = x.copy()
        self._cache = (R, s, a, q, f, g, J)
        return self._cache

    def fun(self, x: np.ndarray) -> np.ndarray:
        R, s, a, q, f, g, J = self._eval(x)
        r = s * f
        if self.prior:
            r = np.append(r, self.prior * self.unpack(x)[2])
        return r

    def jac(self, x: np.ndarray) -> np.ndarray:
        p = self.p
        R, s, a, q, f, g, J = self._eval(x)
        w = self.unpack(x)[0]
        Jm = jacobian(p.pose, p.scale, s, a, f, g @ R.T, s * J[:, self.idx] if self.idx
                      else None)
        if p.pose:
            Jm[:, :3] = Jm[:, :3] @ left_jacobian(w)
        if self.prior:
            row = np.zeros((1, Jm.shape[1]))
            row[0, 6 if p.pose else 0] = self.prior
            Jm = np.vstack([Jm, row])
        return Jm

    def x_scale(self, x0: np.ndarray) -> np.ndarray | str:
        """Scale of each unknown: the inverse norm of its Jacobian column at the start
        (like ``x_scale='jac'``), except for unknowns the data hardly sees (the rotation
        of a sphere), which get a typical size instead of a huge scale."""
        typical = self._typical()
        norms = np.linalg.norm(self.jac(x0)[: len(self.p.points)], axis=0)
        ok = norms > 1e-6 * max(norms.max(initial=0.0), 1e-300)
        if ok.all():
            return "jac"  # every unknown is observed: SciPy's adaptive scaling
        return np.where(ok, 1.0 / np.where(ok, norms, 1.0), typical)

    def _typical(self) -> np.ndarray:
        """Typical size of each unknown: radians, the model size, 1 for log-scale, a
        tenth of a parameter's range (or its magnitude)."""
        p = self.p
        sc = []
        if p.pose:
            sc += [1.0] * 3 + [p.size * p.s] * 3
        if p.scale:
            sc.append(1.0)
        for i in self.idx:
            q = p.prog.params[i]
            span = q.hi - q.lo
            sc.append(span / 10 if np.isfinite(span) and span > 0
                      else max(abs(q.default), 0.01 * p.size))
        return np.array(sc)

    def bounds(self):
        p = self.p
        n = (6 if p.pose else 0) + (1 if p.scale else 0)
        lo = [-np.inf] * n + [p.prog.params[i].lo for i in self.idx]
        hi = [np.inf] * n + [p.prog.params[i].hi for i in self.idx]
        return np.array(lo), np.array(hi)


def _ambiguity_notes(res: _Residuals, x: np.ndarray) -> list[str]:
    p = res.p
    if not (p.scale and p.names):
        return []
    Jm = res.jac(x)[: len(p.points)]
    k = 6 if p.pose else 0
    sc = Jm[:, k]
    notes = []
    for j, name in enumerate(p.names):
        col = Jm[:, k + 1 + j]
        den = np.linalg.norm(sc) * np.linalg.norm(col)
        if den > 0 and abs(sc @ col) / den > 0.98:
            notes.append(f"scale and parameter {name!r} are nearly ambiguous (both resize the "
                         "shape); a weak prior keeps the scale near its start")
    return notes


def solve(prob: Problem, max_iter: int = 100, rounds: int = 4) -> tuple[Problem, dict]:
    """Run the least-squares refinement in place; returns the problem and statistics."""
    nfev = 0
    converged = False
    cost = math.nan
    n = len(prob.points)
    prior = 0.05 * prob.f_scale * math.sqrt(n) if (prob.scale and prob.names) else 0.0
    notes: list[str] = []
    for rnd in range(rounds):
        res = _Residuals(prob, prob.R, prior)
        x0 = res.pack()
        lo, hi = res.bounds()
        x0 = np.clip(x0, lo, hi)
        if len(x0) == 0:
            break
        out = least_squares(res.fun, x0, jac=res.jac, bounds=(lo, hi), method="trf",
                            loss=prob.loss, f_scale=prob.f_scale, max_nfev=max_iter,
                            x_scale=res.x_scale(x0))
        nfev += out.nfev
        cost = float(out.cost)
        w, t, sigma, values = res.unpack(out.x)
        prob.R = exp_so3(w) @ prob.R
        prob.t, prob.s, prob.values = np.asarray(t, dtype=float), math.exp(sigma), values
        if rnd == 0:
            notes = _ambiguity_notes(res, out.x)
        converged = out.status > 0
        if np.linalg.norm(w) < 1e-3 or not converged:
            break
    U, _, Vt = np.linalg.svd(prob.R)
    prob.R = U @ Vt
    return prob, {"nfev": nfev, "converged": converged, "cost": cost, "notes": notes}


def residuals(prob: Problem, R, t, s, values) -> np.ndarray:
    """Signed distances (scene units) of the points to the posed model."""
    q = ((prob.points - t) @ R) / s
    pv = dict(zip((p.name for p in prob.prog.params), values))
    return s * prob.prog(q, pv, backend=prob.backend)


def make_result(prob: Problem, stats: dict, seconds: float, method: str,
                inlier_threshold: float | None) -> FitResult:
    r = residuals(prob, prob.R, prob.t, prob.s, prob.values)
    thr = 3.0 * prob.f_scale if inlier_threshold is None else float(inlier_threshold)
    inl = np.abs(r) <= thr
    rmse = float(np.sqrt(np.mean(r[inl] ** 2))) if inl.any() else math.inf
    return FitResult(
        rotation=prob.R.copy(), translation=prob.t.copy(), scale=float(prob.s),
        params={p.name: float(v) for p, v in zip(prob.prog.params, prob.values)},
        rmse=rmse, inlier_fraction=float(inl.mean()), inlier_threshold=thr,
        converged=bool(stats["converged"]), iterations=int(stats["nfev"]), seconds=seconds,
        cost=float(stats.get("cost", math.nan)), method=method, notes=list(stats["notes"]),
        loss=stats.get("loss"),
    )


AMBIGUITY_SIN = 0.25  # scale is fixed when sin(angle(scale column, parameter span)) < this
BIAS_COPIES = 2  # noisy copies of the projected cloud in the bias simulation
BIAS_ROUNDS = 2  # iterations of the bootstrap bias correction
SMALL_START = 0.1  # the joint stage also tries parameters this far into their ranges
BOUND_SLACK = 0.1  # parameter ranges widened by this fraction before the bias correction


def scale_ambiguity(prob: Problem, P: np.ndarray) -> float:
    """How well the estimated parameters can imitate a change of scale at the current
    state: the sine of the angle between the Jacobian column of ``log s`` and the span of
    the parameters' columns, on points ``P`` (N, 3) (0: a uniform resize is exactly a
    parameter change, so scale and parameters cannot both be identified; 1: independent)."""
    from .gn import _evaluate, _State

    idx = [i for i, q in enumerate(prob.prog.params) if q.name in prob.names]
    st = _State(prob.R, prob.t, math.log(prob.s), prob.values[idx])
    pose, scale = prob.pose, prob.scale
    prob.pose, prob.scale = False, True
    try:
        _, Jm = _evaluate(prob, P, st, idx, prob.f_scale)
    finally:
        prob.pose, prob.scale = pose, scale
    js, Jc = Jm[:, 0], Jm[:, 1:]
    ns = np.linalg.norm(js)
    if ns == 0 or Jc.shape[1] == 0:
        return 1.0
    coef, *_ = np.linalg.lstsq(Jc, js, rcond=None)
    return float(np.linalg.norm(js - Jc @ coef) / ns)


def correct_noise_bias(prob: Problem, st, idx: list[int], max_iter: int = 50):
    """Parametric-bootstrap correction of the noise bias of scale and shape parameters.

    Noise makes a signed-distance fit biased at curved and thin features: the distance
    of a convex shape is a convex function, so noisy points look outside on average
    (Jensen) and the fitted part grows (thin legs fattest: the bias grows like
    ``sigma^2 * curvature``). Estimate: the inliers are projected onto the fitted surface,
    Gaussian noise of the residuals' RMS is added (seeded), the same problem is solved
    again from the fitted state (``BIAS_COPIES`` noisy copies of the cloud, which lowers
    the variance the correction adds), and the change of ``log s`` and of the parameters
    is the bias at that noise (the pose is solved with them but kept); it is scaled by
    the squared ratio of the real to the simulated RMS (the RMS of signed distances
    underestimates the noise near edges, and the bias goes with ``sigma^2``) and
    subtracted. Returns the corrected state and the number of evaluations. No effect on
    noiseless data."""
    from .gn import _State, lm_solve

    s = math.exp(st.sigma)
    pv = dict(zip(prob.pnames, _merge(prob, idx, st.cvals)))
    q = ((prob.points - st.t) @ st.R) / s
    f = np.asarray(prob.prog(q, pv, backend=prob.backend))
    inl = np.abs(s * f) <= 3.0 * prob.f_scale
    if inl.sum() < 10:
        return st, 0
    rms = float(np.sqrt(np.mean((s * f[inl]) ** 2)))
    if not rms > 1e-9 * prob.size * s:
        return st, 0
    lo = np.array([prob.prog.params[i].lo for i in idx])
    hi = np.array([prob.prog.params[i].hi for i in idx])
    P_in = prob.points[inl]
    cur, k, nev = st, None, 0
    for _ in range(BIAS_ROUNDS):
        sim = _simulate(prob, P_in, cur, idx, rms)
        if sim is None:
            return st, nev
        # the pose is solved too (a seat height's bias comes with a shift along the legs)
        # but only the scale and parameters are corrected
        st_sim, _, n_ev, _ = lm_solve(prob, sim, cur, idx, prob.f_scale, max_iter,
                                      slack=BOUND_SLACK)
        nev += n_ev
        if k is None:
            s2 = math.exp(st_sim.sigma)
            pv2 = dict(zip(prob.pnames, _merge(prob, idx, st_sim.cvals)))
            rs = s2 * np.asarray(prob.prog(((sim - st_sim.t) @ st_sim.R) / s2, pv2,
                                           backend=prob.backend))
            rs = rs[np.abs(rs) <= 3.0 * prob.f_scale]
            rms_sim = float(np.sqrt(np.mean(rs ** 2))) if len(rs) else rms
            k = (rms / rms_sim) ** 2 if rms_sim > 0 else 1.0
        # iterated bootstrap: the bias is re-evaluated at the corrected values
        cvals = np.clip(st.cvals - k * (st_sim.cvals - cur.cvals), lo, hi) if idx \
            else st.cvals
        sigma = st.sigma - k * (st_sim.sigma - cur.sigma) if prob.scale else st.sigma
        cur = _State(st.R, st.t, sigma, cvals)
    return cur, nev


def _simulate(prob: Problem, P: np.ndarray, st, idx: list[int], rms: float):
    """Scene points ``P`` (N, 3) projected onto the surface of state ``st`` (Newton steps
    in the model frame) with Gaussian noise of ``rms`` (scene units) added, in
    ``BIAS_COPIES`` seeded copies; None if too few project."""
    s = math.exp(st.sigma)
    pv = dict(zip(prob.pnames, _merge(prob, idx, st.cvals)))
    y = ((P - st.t) @ st.R) / s
    for _ in range(4):
        fy, gy = prob.prog.value_and_grad(y, pv, backend=prob.backend)
        gy = np.asarray(gy)
        y = y - (np.asarray(fy) / np.maximum(np.sum(gy * gy, axis=1), 1e-30))[:, None] * gy
    fy = np.asarray(prob.prog(y, pv, backend=prob.backend))
    y = y[np.abs(fy) < 1e-3 * rms / s]
    if len(y) < 10:
        return None
    rng = np.random.default_rng(20261122)
    y = np.concatenate([y] * BIAS_COPIES)  # more copies: less variance in the estimate
    return s * (y + rng.normal(0.0, rms / s, y.shape)) @ st.R.T + st.t


def _merge(prob: Problem, idx: list[int], cvals: np.ndarray) -> np.ndarray:
    values = prob.values.copy()
    values[idx] = cvals
    return values


def _small_start(prob: Problem, P: np.ndarray, st, idx: list[int], max_iter: int):
    """The better of two starts for the joint stage, by their cost after a short solve on
    a subsample: the parameters as given, or every parameter near the low end of its range
    (``lo + SMALL_START * span``).

    The residuals measure the distance from each point to the model, not from the model to
    the points: a part made too long (legs below the floor) adds surface where there are
    no points, which costs nothing, while the points beyond a part made too short pull it
    out. Parameters that start too large can therefore stay there; starting small avoids
    that trap."""
    from .gn import N_COARSE, _State, lm_solve

    n = len(P)
    sub = P if n <= N_COARSE else P[np.random.default_rng(2).choice(n, N_COARSE, False)]
    lo = np.array([prob.prog.params[i].lo for i in idx])
    hi = np.array([prob.prog.params[i].hi for i in idx])
    small = np.where(np.isfinite(hi - lo), lo + SMALL_START * (hi - lo), st.cvals)
    best, nev = None, 0
    for cvals in (st.cvals, small):
        cand = lm_solve(prob, sub, _State(st.R, st.t, st.sigma, cvals), idx, prob.f_scale,
                        max(10, max_iter // 4))
        nev += cand[2]
        if best is None or cand[1] < best[1]:
            best = cand
    return best[0], nev


def solve_lm(prob: Problem, max_iter: int = 100, viewpoint=None,
             escape: bool = True, correct_bias: bool = False,
             auto: bool = False) -> tuple[Problem, dict]:
    """The default engine: coarse-to-fine robust Levenberg-Marquardt (:mod:`.gn`).

    Stages: (1) the pose alone on a fixed subsample of at most ``gn.N_COARSE`` points,
    with the residual scale graduated from ``8 f_scale`` down to ``f_scale``, then the
    escape step (:func:`csdf.fit.gn.escape`); (2) when only the pose is estimated, the
    pose on all points; otherwise everything jointly on all points (scale held if
    ambiguous, see :func:`scale_ambiguity`; parameters from the better of two starts, see
    :func:`_small_start`), then the noise-bias correction (:func:`correct_noise_bias`).
    ``max_iter`` bounds the evaluations of each stage. With ``auto`` (``loss='auto'``)
    this runs with Huber and then :func:`auto_continue` decides on Cauchy. Runs in place;
    ``prob.loss`` ends as the loss of the returned solution."""
    if not auto:
        return _solve_lm(prob, max_iter, viewpoint, escape, correct_bias)
    start = (prob.R, prob.t, prob.s, prob.values.copy())
    prob.loss = "huber"
    prob, stats = _solve_lm(prob, max_iter, viewpoint, escape, correct_bias)
    return auto_continue(prob, stats, start, max_iter, viewpoint, escape, correct_bias)


def _solve_lm(prob: Problem, max_iter: int, viewpoint, escape: bool,
              correct_bias: bool) -> tuple[Problem, dict]:
    """:func:`solve_lm` with the fixed loss ``prob.loss``."""
    from .gn import GRADUATION, N_COARSE, Visibility, _State, lm_rounds, lm_solve
    from .gn import escape as _escape

    P = prob.points
    n = len(P)
    radius = 0.5 * prob.size * prob.s * 1.05
    vis = None if viewpoint is None else Visibility(np.asarray(viewpoint, dtype=float),
                                                    radius)
    idx = [i for i, q in enumerate(prob.prog.params) if q.name in prob.names]
    st = _State(prob.R, prob.t, math.log(prob.s), prob.values[idx])
    nev, cost, converged = 0, math.nan, False
    notes: list[str] = []
    held = False
    if prob.pose:
        scale, names = prob.scale, prob.names
        prob.scale, prob.names = False, []
        st0 = _State(st.R, st.t, st.sigma, np.zeros(0))
        sub = P if n <= N_COARSE else P[np.random.default_rng(0).choice(n, N_COARSE, False)]
        per = max(3, min(10, max_iter // 4))
        for mult in GRADUATION:
            st0, cost, k, converged = lm_solve(prob, sub, st0, [], prob.f_scale * mult, per,
                                               vis=vis, tol=1e-5)
            nev += k
        if escape:
            st0, _ = _escape(prob, sub, st0, prob.f_scale, vis=vis)
        if not (scale or names):  # (otherwise the joint stage refines the pose on all)
            st0, cost, k, converged = lm_rounds(prob, P, st0, [], max_iter, vis)
            nev += k
        prob.scale, prob.names = scale, names
        st = _State(st0.R, st0.t, st.sigma, st.cvals)
        prob.R, prob.t = st.R, st.t
    if prob.scale or prob.names:
        if prob.scale and prob.names:
            sub = P if n <= N_COARSE else P[np.random.default_rng(1).choice(n, N_COARSE,
                                                                             False)]
            sin = scale_ambiguity(prob, sub)
            if sin < AMBIGUITY_SIN:
                prob.scale, held = False, True
                notes.append(
                    f"scale held at {prob.s:.6g}: the estimated parameters can imitate a "
                    f"uniform resize (sin of the angle between the scale and parameter "
                    f"Jacobian columns {sin:.3f} < {AMBIGUITY_SIN}): scale and size are "
                    "ambiguous, so the parameters absorb the size")
        if prob.names and prob.pose:
            st, k = _small_start(prob, P, st, idx, max_iter)
            nev += k
        # with the bias correction, the biased estimate may leave the ranges a little
        # (a true value near a bound); the corrected one is clipped to them
        st, cost, k, converged = lm_rounds(prob, P, st, idx, max_iter, vis,
                                           slack=BOUND_SLACK if correct_bias else 0.0)
        nev += k
        if correct_bias:
            st, k = correct_noise_bias(prob, st, idx)
            nev += k
        prob.scale = "scale" in prob.estimate
    _store(prob, st, idx)
    return prob, {"nfev": nev, "converged": converged, "cost": cost, "notes": notes,
                  "loss": prob.loss, "scale_held": held}


def _store(prob: Problem, st, idx: list[int]) -> None:
    """Write state ``st`` back into ``prob`` (rotation re-orthonormalised)."""
    prob.R, prob.t, prob.s = st.R, np.asarray(st.t, dtype=float), math.exp(st.sigma)
    prob.values = _merge(prob, idx, st.cvals)
    U, _, Vt = np.linalg.svd(prob.R)
    prob.R = U @ Vt


def _refine(prob: Problem, max_iter: int, viewpoint, correct_bias: bool,
            held: bool) -> tuple[Problem, dict]:
    """Refine every estimated unknown from ``prob``'s state on all points with
    ``prob.loss`` (no coarse stage, no escape; the scale held if ``held``), then the
    noise-bias correction if asked. In place."""
    from .gn import Visibility, _State, lm_rounds

    vis = None if viewpoint is None else Visibility(
        np.asarray(viewpoint, dtype=float), 0.5 * prob.size * prob.s * 1.05)
    idx = [i for i, q in enumerate(prob.prog.params) if q.name in prob.names]
    st = _State(prob.R, prob.t, math.log(prob.s), prob.values[idx])
    joint = bool(prob.scale or prob.names)
    if held:
        prob.scale = False
    st, cost, nev, converged = lm_rounds(prob, prob.points, st, idx, max_iter, vis,
                                         slack=BOUND_SLACK if joint and correct_bias
                                         else 0.0)
    if joint and correct_bias:
        st, k = correct_noise_bias(prob, st, idx)
        nev += k
    prob.scale = "scale" in prob.estimate
    _store(prob, st, idx)
    return prob, {"nfev": nev, "converged": converged, "cost": cost, "notes": [],
                  "loss": prob.loss}


def _auto_measure(prob: Problem) -> tuple[int, float]:
    """At ``prob``'s state: the inliers (``|r| <= AUTO_INLIER_K * f_scale``, signed
    distances of all points) and the Cauchy cost at ``f_scale`` of the same residuals."""
    r = residuals(prob, prob.R, prob.t, prob.s, prob.values)
    n_in = int(np.count_nonzero(np.abs(r) <= AUTO_INLIER_K * prob.f_scale))
    return n_in, loss_weights(r, prob.f_scale, "cauchy")[0]


def _snapshot(prob: Problem) -> tuple:
    return prob.R.copy(), np.array(prob.t, dtype=float), prob.s, prob.values.copy()


def auto_continue(prob: Problem, stats: dict, start: tuple, max_iter: int, viewpoint,
                  escape: bool, correct_bias: bool,
                  scipy_solver=None) -> tuple[Problem, dict]:
    """The second half of ``loss='auto'`` (graduated non-convexity), given the finished
    Huber fit in ``prob`` (its statistics ``stats``) and the state it started from,
    ``start = (R, t, s, values)``.

    Count the inliers ``|r| <= AUTO_INLIER_K * f_scale`` of the Huber solution (signed
    distances of all points). If they are at least ``AUTO_CLEAN`` of the cloud, the Huber
    fit is returned unchanged. Otherwise some points are outliers, which pull Huber's
    optimum (their influence never vanishes; a few percent of clutter already biases
    size parameters by centimetres on a chair), and fits with the redescending Cauchy loss
    at the same ``f_scale`` are made: (a) the continuation: every estimated unknown
    refined from the Huber solution on all points; and, when fewer than ``AUTO_SWITCH``
    are inliers, (b) the complete fit (coarse stage, escape, final) with Cauchy from the
    same start as the Huber fit (heavy outliers can lead Huber's coarse stage into a wrong
    basin). Of the Huber solution and these, the one with the lowest Cauchy cost (signed
    distances of all points, ``f_scale``; the cost Cauchy minimises, on the same
    residuals for all) is
    returned; ``prob.loss`` is set to its loss. (The inlier count is no criterion: a
    biased Huber fit still has nearly every true inlier within ``3 f_scale``.)

    ``scipy_solver``: for ``solver='scipy'``, a function ``prob -> (prob, stats)`` used
    for both Cauchy fits instead. Returns ``(prob, stats)``; ``stats['notes']`` says what
    was done when Cauchy was tried."""
    n = len(prob.points)
    n_h, c_h = _auto_measure(prob)
    if n_h >= AUTO_CLEAN * n:
        stats["loss"] = prob.loss = "huber"
        return prob, stats
    held = bool(stats.get("scale_held"))
    cands = [("Huber", _snapshot(prob), stats, c_h)]
    total = stats["nfev"]
    labels = ("continued", "restarted") if n_h < AUTO_SWITCH * n else ("continued",)
    for label in labels:
        prob.loss = "cauchy"
        if label == "restarted":
            prob.R, prob.t, prob.s, prob.values = (start[0], start[1], start[2],
                                                   start[3].copy())
        if scipy_solver is not None:
            prob, st2 = scipy_solver(prob)
        elif label == "continued":
            prob, st2 = _refine(prob, max_iter, viewpoint, correct_bias, held)
        else:
            prob, st2 = _solve_lm(prob, max_iter, viewpoint, escape, correct_bias)
        total += st2["nfev"]
        cands.append((label, _snapshot(prob), st2, _auto_measure(prob)[1]))
    # the lowest Cauchy cost; ties go to the Cauchy fits (listed later)
    label, snap, best, c = min(reversed(cands), key=lambda x: x[3])
    prob.R, prob.t, prob.s, prob.values = snap
    prob.loss = "huber" if label == "Huber" else "cauchy"
    out = dict(best)
    out["nfev"], out["loss"] = total, prob.loss
    tried = ", ".join(f"{lab if lab == 'Huber' else 'Cauchy ' + lab} {c / prob.f_scale ** 2:.6g}"
                      for lab, _, _, c in cands)
    out["notes"] = list(stats["notes"]) + [
        f"loss='auto': the Huber fit has {n_h / n:.1%} inliers (|r| <= {AUTO_INLIER_K:g} "
        f"f_scale) < {AUTO_CLEAN:.0%}, so Cauchy was tried at the same f_scale; Cauchy "
        f"cost (x f_scale^2): {tried}: "
        + ("the Huber fit kept" if label == "Huber" else f"Cauchy ({label}) kept")]
    return prob, out


def fit(shape, points, init=None, estimate=("pose",), params=None, loss="auto",
        f_scale=None, multistart=False, seed=None, max_iter=100, inlier_threshold=None,
        backend="auto", viewpoint=None, solver="lm", debias=None,
        escape=True) -> FitResult:
    """Fit a model to a point cloud: pose, optionally scale and shape parameters.

    Args:
        shape: a :class:`csdf.Shape` (or compiled :class:`csdf.Program`).
        points: ``(N, 3)`` scene points (metres, or the model's units).
        init: starting pose: None (identity rotation, centroids aligned), a (4, 4)
            transform ``[[s R, t], [0, 1]]``, a :class:`FitResult`, or a dict with
            ``rotation``, ``translation``, ``scale``, ``params``.
        estimate: any of ``'pose'``, ``'scale'``, ``'params'`` (tuple or comma string).
            With both ``'scale'`` and ``'params'``, scale is held at its start (1 by
            default) when the parameters can imitate a uniform resize (see
            :func:`scale_ambiguity`; the reason is added to ``FitResult.notes``).
        params: names of the parameters to estimate (default: all); others stay at their
            values in ``init`` (or defaults).
        loss: robust loss: ``'auto'`` (default), ``'huber'``, ``'cauchy'``,
            ``'soft_l1'``, ``'arctan'``, ``'linear'`` (SciPy ``least_squares``
            conventions, residual scale ``f_scale``). Huber has a wide basin but its
            optimum is pulled by outliers (their influence never vanishes); Cauchy's is
            not (redescending) but its basin is narrower. ``'auto'`` combines them
            (graduated non-convexity): the whole fit is made with Huber; if fewer than
            ``AUTO_CLEAN`` (99%) of the points are then inliers (``|r| <= 3
            f_scale``), a Cauchy fit at the same ``f_scale`` refines the Huber solution,
            and below ``AUTO_SWITCH`` (90%) another redoes the fit from the same start;
            of the solutions the one with the lowest Cauchy cost (signed distances of
            all points) is returned (see :func:`auto_continue`). On clean clouds it is
            exactly ``'huber'``. :attr:`FitResult.loss` says which loss gave the
            result, and :attr:`FitResult.notes` what ``'auto'`` did when it tried
            Cauchy. With ``multistart`` the search is unchanged and its final fit uses
            this logic (the Cauchy restart starts from the search's result).
        f_scale: residual scale of the loss (scene units); default 1% of the model size.
        multistart: search many initial rotations first (see
            :func:`csdf.fit.init.multistart`); needed for large initial errors.
        seed: seeds the multistart subsampling (results are reproducible).
        max_iter: residual evaluations per stage (refinement round with ``'scipy'``).
        inlier_threshold: ``|r|`` counted as inlier (default ``3 * f_scale``).
        backend: evaluator backend (``'auto'`` uses the compiled one for large clouds).
        viewpoint: ``(3,)`` sensor position in the cloud's frame for a single-view scan
            (the origin for :func:`csdf.scan`'s camera-frame clouds). Points matched to a
            model surface facing away from it are re-matched to the first surface along
            their ray (see :mod:`csdf.fit.gn`): needed for partial views of thin parts.
        solver: ``'lm'`` (hand-written coarse-to-fine robust Levenberg-Marquardt, the
            default) or ``'scipy'`` (``scipy.optimize.least_squares``, trust region
            reflective; no ``viewpoint``).
        debias: correct the noise bias of the estimated scale and parameters (see
            :func:`correct_noise_bias`; ``'lm'`` only). Default: when ``'params'`` is
            estimated.
        escape: after the coarse stage, test turns about the model's axes and the cloud's
            principal axes for a lower minimum (:func:`csdf.fit.gn.escape`; ``'lm'``
            only): near-symmetric parts have wrong minima one feature spacing away.

    Returns:
        :class:`FitResult`.

    Raises:
        CsdfError: empty cloud, NaNs, bad options, fewer points than unknowns;
        ParamError: unknown parameter names.
    """
    t0 = time.perf_counter()
    if solver not in ("lm", "scipy"):
        raise CsdfError(f"solver must be 'lm' or 'scipy'; got {solver!r}")
    prob = prepare(shape, points, init, estimate, params, loss, f_scale, backend)
    auto = prob.loss == "auto"
    if auto:
        prob.loss = "huber"  # first; auto_continue may switch to 'cauchy'
    if viewpoint is not None:
        vp = np.asarray(viewpoint, dtype=float)
        if vp.shape != (3,) or not np.all(np.isfinite(vp)):
            raise CsdfError(f"viewpoint must be a finite (3,) position; got {viewpoint!r}")
        if solver != "lm":
            raise CsdfError("viewpoint needs solver='lm'")
        viewpoint = vp
    if multistart:
        from .init import multistart as _ms

        _ms(prob, seed=seed)
    if solver == "lm":
        if debias is None:
            debias = bool(prob.names)
        prob, stats = solve_lm(prob, max_iter=max_iter, viewpoint=viewpoint,
                               escape=bool(escape), correct_bias=bool(debias), auto=auto)
        return make_result(prob, stats, time.perf_counter() - t0, "csdf", inlier_threshold)
    start = (prob.R, prob.t, prob.s, prob.values.copy())
    if prob.pose and (prob.scale or prob.names):
        # staged: the pose alone first (scale and shape held), then everything jointly;
        # starting the joint problem near the right pose keeps scale and size parameters
        # from shrinking the model onto a wrong alignment
        scale, names = prob.scale, prob.names
        prob.scale, prob.names = False, []
        prob, first = solve(prob, max_iter=max_iter)
        prob.scale, prob.names = scale, names
    else:
        first = {"nfev": 0}
    prob, stats = solve(prob, max_iter=max_iter)
    stats["nfev"] += first["nfev"]
    if auto:
        def cauchy_scipy(p: Problem) -> tuple[Problem, dict]:
            p, st2 = solve(p, max_iter=max_iter)
            r = residuals(p, p.R, p.t, p.s, p.values)
            st2["cost"] = loss_weights(r, p.f_scale, "cauchy")[0]
            return p, st2

        prob, stats = auto_continue(prob, stats, start, max_iter, None, False, False,
                                    scipy_solver=cauchy_scipy)
    stats["loss"] = prob.loss
    return make_result(prob, stats, time.perf_counter() - t0, "csdf", inlier_threshold)
