"""Trajectory optimisation on a scene: a robot's path between two joint positions that
keeps its spheres clear of the scene (CHOMP's obstacle cost on the scene's exact
clearances and gradients, solved as a bounded least-squares problem, TrajOpt-style),
and a dense check of any path.

The path is ``n_waypoints`` joint positions from ``q_start`` to ``q_goal`` (both
fixed). The residuals are the steps between consecutive waypoints (smoothness: their
sum of squares is the path's squared length over the waypoints) and, for every
interior waypoint and every sphere of the robot's cover, how far the sphere's
clearance falls short of a margin (``max(0, margin - clearance)``, weighted), and how
far the gaps between the robot's own spheres (:meth:`Robot.self_pairs`) fall short of
a smaller one. Their
Jacobian is exact: the scene's gradient at the sphere times the sphere's motion by
each joint (:func:`csdf.plan.robot.sphere_jacobian`). Joint limits are the problem's
bounds. ``scipy.optimize.least_squares`` solves it from the straight line in joint
space and, if the dense check fails, from seeded random detours.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import CsdfError
from .robot import Robot, pair_gaps, sphere_jacobian_many

__all__ = ["Trajectory", "Check", "optimize", "check"]


@dataclass
class Check:
    """What :func:`check` finds along a path.

    Attributes:
        ok: no sphere of the robot's cover reaches into the scene at any checked
            position; min_clearance: the smallest sphere clearance found (m);
            first_collision: the index of the first colliding checked position (-1:
            none); where: ``(dof,)`` that position (None); positions: how many
            positions were checked.
    """

    ok: bool
    min_clearance: float
    first_collision: int
    where: np.ndarray | None
    positions: int


@dataclass
class Trajectory:
    """A planned path.

    Attributes:
        q: ``(T, dof)`` waypoints from start to goal; success: the dense check found
            no collision and every waypoint is within the joint limits;
            min_clearance: the dense check's smallest clearance (m); seconds: planning
            time; attempts: solver runs (1 + restarts); length: the path's length in
            joint space (sum of step norms).
    """

    q: np.ndarray
    success: bool
    min_clearance: float
    seconds: float
    attempts: int = 1
    length: float = 0.0
    info: dict = field(default_factory=dict)


def _dense(q: np.ndarray, step: float) -> np.ndarray:
    """Positions along the polyline ``q`` ``(T, dof)`` at most ``step`` apart (max norm)."""
    out = [q[:1]]
    for a, b in zip(q[:-1], q[1:]):
        n = max(1, int(np.ceil(np.max(np.abs(b - a)) / step)))
        t = np.arange(1, n + 1)[:, None] / n
        out.append(a + t * (b - a))
    return np.concatenate(out)


def check(scene, robot: Robot, q, step: float = 0.01, spacing: float | None = None,
          margin: float = 0.0, self_collision: bool = True) -> Check:
    """Check a path densely: positions along the waypoints ``q`` ``(T, dof)`` at most
    ``step`` apart in every joint (radians or metres), each tested by the robot's sphere
    cover against the scene (a sphere reaching within ``margin`` of a surface counts as a
    collision) and, with ``self_collision``, against itself (:meth:`Robot.self_pairs`).
    The cover holds the robot, so a path that passes is clear of the scene at every
    checked position.

    Raises:
        CsdfError: a bad shape of ``q`` or a step that is not positive.
    """
    q = np.asarray(q, dtype=np.float64)
    if q.ndim != 2 or q.shape[1] != robot.dof or len(q) < 1:
        raise CsdfError(f"q must have shape (T, {robot.dof}), got {q.shape}")
    if not (np.isfinite(step) and step > 0):
        raise CsdfError(f"step must be positive, got {step}")
    dense = _dense(q, float(step))
    cover = robot.sphere_cover(spacing)
    S = len(cover[1])
    centers = robot.spheres_many(dense, spacing)
    radii = np.tile(cover[1], len(dense))
    clear, _ = scene.sphere_distance(centers.reshape(-1, 3), radii, max_distance=1.0)
    per = clear.reshape(len(dense), S).min(axis=1)
    pairs = robot.self_pairs(spacing) if self_collision else None
    if pairs is not None and len(pairs):  # the robot's own spheres count too
        gap = pair_gaps(centers, cover[1], pairs[:, 0], pairs[:, 1])[2]
        per = np.minimum(per, gap.min(axis=1))
    bad = np.flatnonzero(per < margin)
    first = int(bad[0]) if len(bad) else -1
    return Check(ok=first < 0, min_clearance=float(per.min()), first_collision=first,
                 where=None if first < 0 else dense[first], positions=len(dense))


def optimize(scene, robot: Robot, q_start, q_goal, n_waypoints: int = 32, *,
             margin: float = 0.05, smooth: float = 1.0, obstacle: float = 10.0,
             restarts: int = 4, seed: int = 0, step: float = 0.02,
             spacing: float | None = None, max_nfev: int = 200,
             self_collision: bool = True, self_margin: float = 0.01,
             refine: int = 2) -> Trajectory:
    """Plan a path from ``q_start`` to ``q_goal`` (see the module docs).

    Args:
        scene: a :class:`csdf.Scene` (the obstacles, in the robot's root frame).
        robot: a :class:`csdf.plan.Robot`.
        q_start, q_goal: ``(dof,)`` joint positions within the limits.
        n_waypoints: waypoints including both ends (>= 3).
        margin: the clearance the obstacle cost asks of every sphere (m).
        smooth, obstacle: the weights of the step and clearance residuals.
        restarts: further seeded attempts (random detours of the start path) when the
            dense check fails.
        seed: their seed; step: the dense check's step (:func:`check`).
        spacing: the sphere cover's spacing (:meth:`Robot.sphere_cover`).
        max_nfev: solver evaluations per attempt.
        self_collision: keep the robot's own spheres apart too (the pairs of
            :meth:`Robot.self_pairs`), by ``self_margin`` (m).
        refine: when every attempt fails, up to this many further attempts, each
            from the best path so far with twice as many steps between waypoints
            (a finer path bends around what a coarse one cuts through).

    Returns:
        :class:`Trajectory`; ``success`` False (with the best attempt) when no
        attempt passes the check. ``q`` has ``n_waypoints`` rows, or more after
        refinement (``2 * (T - 1) + 1`` for each).

    Raises:
        CsdfError: bad shapes, ends outside the limits, or fewer than 3 waypoints.
    """
    t0 = time.perf_counter()
    a, b = robot._q(q_start), robot._q(q_goal)
    for name, q in (("q_start", a), ("q_goal", b)):
        if not robot.in_limits(q):
            raise CsdfError(f"{name} is outside the joint limits")
    T = int(n_waypoints)
    if T < 3:
        raise CsdfError(f"n_waypoints must be >= 3, got {n_waypoints}")
    for name, v in (("margin", margin), ("self_margin", self_margin)):
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
            raise CsdfError(f"{name} must be a finite number >= 0, got {v!r}")
    lim = robot.limits
    line = a + np.linspace(0, 1, T)[:, None] * (b - a)
    opts = dict(margin=margin, smooth=smooth, obstacle=obstacle, spacing=spacing,
                max_nfev=max_nfev, self_collision=self_collision, self_margin=self_margin)

    def attempt(start: np.ndarray):
        q = _solve(scene, robot, start, **opts)
        chk = check(scene, robot, q, step=step, spacing=spacing,
                    self_collision=self_collision)
        length = float(np.linalg.norm(np.diff(q, axis=0), axis=1).sum())
        return chk.ok, chk.min_clearance, q, length, chk

    rng = np.random.default_rng(seed)
    best = None
    attempts = 0
    for k in range(1 + max(0, int(restarts))):
        attempts += 1
        start = line.copy()
        if k:  # a random detour: a bump through a random mid-point
            mid = rng.uniform(np.clip(lim[:, 0], -np.pi, np.pi),
                              np.clip(lim[:, 1], -np.pi, np.pi))
            w = np.sin(np.linspace(0, np.pi, T))[:, None]
            start = start + w * (mid - line[T // 2])
        cand = attempt(start)
        if best is None or (cand[0], cand[1]) > (best[0], best[1]):
            best = cand
        if cand[0]:
            break
    for _ in range(max(0, int(refine)) if not best[0] else 0):
        attempts += 1
        q = best[2]  # each step halved: the waypoints and their midpoints
        finer = np.empty((2 * len(q) - 1, q.shape[1]))
        finer[0::2] = q
        finer[1::2] = 0.5 * (q[:-1] + q[1:])
        cand = attempt(finer)
        if (cand[0], cand[1]) > (best[0], best[1]):
            best = cand
        if cand[0]:
            break
    ok, clear, q, length, chk = best
    return Trajectory(q=q, success=bool(ok), min_clearance=float(clear),
                      seconds=time.perf_counter() - t0, attempts=attempts, length=length,
                      info={"check": chk})


def _solve(scene, robot: Robot, start: np.ndarray, *, margin: float, smooth: float,
           obstacle: float, spacing: float | None, max_nfev: int, self_collision: bool,
           self_margin: float) -> np.ndarray:
    """One bounded least-squares solve (module docs) from the path ``start`` ``(T,
    dof)`` (its ends are held): the solved ``(T, dof)`` path."""
    from scipy.optimize import least_squares
    from scipy.sparse import coo_matrix

    T, dof = start.shape
    a, b = start[0], start[-1]
    lim = robot.limits
    lo = np.tile(lim[:, 0], T - 2)
    hi = np.tile(lim[:, 1], T - 2)
    S = len(robot.sphere_cover(spacing)[1])
    ws, wo = float(np.sqrt(smooth)), float(np.sqrt(obstacle))

    def unpack(x: np.ndarray) -> np.ndarray:
        return np.vstack([a, x.reshape(T - 2, dof), b])

    pairs = robot.self_pairs(spacing) if self_collision else np.zeros((0, 2), np.int64)
    P = len(pairs)
    pi, pj = pairs[:, 0], pairs[:, 1]
    radii1 = robot.sphere_cover(spacing)[1]
    cache: dict = {}

    def terms(x: np.ndarray):
        key = x.tobytes()
        if key not in cache:
            cache.clear()
            q = unpack(x)
            c, J = sphere_jacobian_many(robot, q[1:-1], spacing)
            clear, grad = scene.sphere_distance(c.reshape(-1, 3), np.tile(radii1, T - 2),
                                                max_distance=margin)
            d, dist, gap = pair_gaps(c, radii1, pi, pj)  # (T-2, P, 3), (T-2, P) x 2
            cache[key] = (q, clear, grad, J, d, dist, gap)
        return cache[key]

    def residuals(x: np.ndarray) -> np.ndarray:
        q, clear, _, _, _, _, gap = terms(x)
        return np.concatenate([ws * np.diff(q, axis=0).ravel(),
                               wo * np.maximum(0.0, margin - clear),
                               wo * np.maximum(0.0, self_margin - gap).ravel()])

    # the steps' rows: q[t+1] - q[t], variable t holds waypoint t + 1
    st = np.repeat(np.arange(T - 1), dof)
    sk = np.tile(np.arange(dof), T - 1)
    up, down = st < T - 2, st > 0
    step_rows = np.concatenate([(st * dof + sk)[up], (st * dof + sk)[down]])
    step_cols = np.concatenate([(st * dof + sk)[up], ((st - 1) * dof + sk)[down]])
    step_vals = np.concatenate([np.full(up.sum(), ws), np.full(down.sum(), -ws)])
    n_step = (T - 1) * dof
    n_rows = n_step + (T - 2) * S + (T - 2) * P

    def jacobian(x: np.ndarray):
        _, clear, grad, J, d, dist, gap = terms(x)
        rows, cols, vals = [step_rows], [step_cols], [step_vals]
        # the scene: d clearance / d q_t = grad . J for the spheres within the margin
        t, sph = np.nonzero((clear < margin).reshape(T - 2, S))
        if len(t):
            dcl = np.einsum("ni,nij->nj", grad.reshape(T - 2, S, 3)[t, sph], J[t, sph])
            rows.append(np.repeat(n_step + t * S + sph, dof))
            cols.append((t[:, None] * dof + np.arange(dof)).ravel())
            vals.append((-wo * dcl).ravel())
        # the robot itself: d gap / d q_t = u . (J_i - J_j) for pairs within the margin
        t, pr = np.nonzero(gap < self_margin)
        if len(t):
            u = d[t, pr] / np.maximum(dist[t, pr], 1e-12)[:, None]
            dg = np.einsum("ni,nij->nj", u, J[t, pi[pr]] - J[t, pj[pr]])
            rows.append(np.repeat(n_step + (T - 2) * S + t * P + pr, dof))
            cols.append((t[:, None] * dof + np.arange(dof)).ravel())
            vals.append((-wo * dg).ravel())
        return coo_matrix((np.concatenate(vals), (np.concatenate(rows),
                                                  np.concatenate(cols))),
                          shape=(n_rows, (T - 2) * dof)).tocsr()

    x0 = np.clip(start[1:-1].ravel(), lo, hi)
    sol = least_squares(residuals, x0, jac=jacobian, bounds=(lo, hi), method="trf",
                        tr_solver="lsmr", tr_options={"maxiter": 40},
                        max_nfev=max_nfev, xtol=1e-8, ftol=1e-8)
    return unpack(sol.x)
