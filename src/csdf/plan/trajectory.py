"""Trajectory optimisation on a scene: a robot's path between two joint positions that
keeps its spheres clear of the scene (CHOMP's obstacle cost on the scene's exact
clearances and gradients, solved as a bounded least-squares problem, TrajOpt-style),
and a dense check of any path.

The path is ``n_waypoints`` joint positions from ``q_start`` to ``q_goal`` (both
fixed). The residuals are the steps between consecutive waypoints (smoothness: their
sum of squares is the path's squared length over the waypoints) and, for every
interior waypoint and every sphere of the robot's cover, how far the sphere's
clearance falls short of a margin (``max(0, margin - clearance)``, weighted). Their
Jacobian is exact: the scene's gradient at the sphere times the sphere's motion by
each joint (:func:`csdf.plan.robot.sphere_jacobian`). Joint limits are the problem's
bounds. ``scipy.optimize.least_squares`` solves it from the straight line in joint
space and, if the dense check fails, from seeded random detours.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import CsdfError
from .robot import Robot, sphere_jacobian_many

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
          margin: float = 0.0) -> Check:
    """Check a path densely: positions along the waypoints ``q`` ``(T, dof)`` at most
    ``step`` apart in every joint (radians or metres), each tested by the robot's sphere
    cover against the scene (a sphere reaching within ``margin`` of a surface counts as a
    collision). The cover holds the robot, so a path that passes is clear of the scene
    at every checked position.

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
    centers = robot.spheres_many(dense, spacing).reshape(-1, 3)
    radii = np.tile(cover[1], len(dense))
    clear, _ = scene.sphere_distance(centers, radii, max_distance=1.0)
    per = clear.reshape(len(dense), S).min(axis=1)
    bad = np.flatnonzero(per < margin)
    first = int(bad[0]) if len(bad) else -1
    return Check(ok=first < 0, min_clearance=float(per.min()), first_collision=first,
                 where=None if first < 0 else dense[first], positions=len(dense))


def optimize(scene, robot: Robot, q_start, q_goal, n_waypoints: int = 32, *,
             margin: float = 0.05, smooth: float = 1.0, obstacle: float = 10.0,
             restarts: int = 4, seed: int = 0, step: float = 0.02,
             spacing: float | None = None, max_nfev: int = 200) -> Trajectory:
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

    Returns:
        :class:`Trajectory`; ``success`` False (with the best attempt) when no
        attempt passes the check.

    Raises:
        CsdfError: bad shapes, ends outside the limits, or fewer than 3 waypoints.
    """
    from scipy.optimize import least_squares
    from scipy.sparse import csr_matrix

    t0 = time.perf_counter()
    a, b = robot._q(q_start), robot._q(q_goal)
    for name, q in (("q_start", a), ("q_goal", b)):
        if not robot.in_limits(q):
            raise CsdfError(f"{name} is outside the joint limits")
    T = int(n_waypoints)
    if T < 3:
        raise CsdfError(f"n_waypoints must be >= 3, got {n_waypoints}")
    dof = robot.dof
    lim = robot.limits
    lo = np.tile(lim[:, 0], T - 2)
    hi = np.tile(lim[:, 1], T - 2)
    line = a + np.linspace(0, 1, T)[:, None] * (b - a)
    S = len(robot.sphere_cover(spacing)[1])
    ws, wo = float(np.sqrt(smooth)), float(np.sqrt(obstacle))

    def unpack(x: np.ndarray) -> np.ndarray:
        return np.vstack([a, x.reshape(T - 2, dof), b])

    cache: dict = {}

    def terms(x: np.ndarray):
        key = x.tobytes()
        if key not in cache:
            cache.clear()
            q = unpack(x)
            c, J = sphere_jacobian_many(robot, q[1:-1], spacing)
            radii = np.tile(robot.sphere_cover(spacing)[1], T - 2)
            clear, grad = scene.sphere_distance(c.reshape(-1, 3), radii,
                                                max_distance=margin)
            cache[key] = (q, clear, grad, J)
        return cache[key]

    def residuals(x: np.ndarray) -> np.ndarray:
        q, clear, _, _ = terms(x)
        return np.concatenate([ws * np.diff(q, axis=0).ravel(),
                               wo * np.maximum(0.0, margin - clear)])

    def jacobian(x: np.ndarray) -> np.ndarray:
        _, clear, grad, J = terms(x)
        n = (T - 1) * dof
        out = np.zeros((n + (T - 2) * S, (T - 2) * dof))
        for t in range(T - 1):  # step t: q[t+1] - q[t]
            for k in range(dof):
                row = t * dof + k
                if t < T - 2:
                    out[row, t * dof + k] += ws  # q[t+1] is variable t
                if t > 0:
                    out[row, (t - 1) * dof + k] -= ws  # q[t] is variable t-1
        active = clear < margin
        g = grad.reshape(T - 2, S, 3)
        dcl = np.einsum("tsi,tsij->tsj", g, J)  # d clearance / d q_t
        dcl[~active.reshape(T - 2, S)] = 0.0
        for t in range(T - 2):
            out[n + t * S:n + (t + 1) * S, t * dof:(t + 1) * dof] = -wo * dcl[t]
        return csr_matrix(out)  # mostly zeros: the iterative solver's products are cheap

    rng = np.random.default_rng(seed)
    best = None
    attempts = 0
    for attempt in range(1 + max(0, int(restarts))):
        attempts += 1
        start = line.copy()
        if attempt:  # a random detour: a bump through a random mid-point
            mid = rng.uniform(np.clip(lim[:, 0], -np.pi, np.pi),
                              np.clip(lim[:, 1], -np.pi, np.pi))
            w = np.sin(np.linspace(0, np.pi, T))[:, None]
            start = start + w * (mid - line[T // 2])
        x0 = np.clip(start[1:-1].ravel(), lo, hi)
        sol = least_squares(residuals, x0, jac=jacobian, bounds=(lo, hi), method="trf",
                            tr_solver="lsmr",
                            max_nfev=max_nfev, xtol=1e-8, ftol=1e-8)
        q = unpack(sol.x)
        chk = check(scene, robot, q, step=step, spacing=spacing)
        length = float(np.linalg.norm(np.diff(q, axis=0), axis=1).sum())
        cand = (chk.ok, chk.min_clearance, q, length, chk)
        if best is None or (cand[0], cand[1]) > (best[0], best[1]):
            best = cand
        if chk.ok:
            break
    ok, clear, q, length, chk = best
    return Trajectory(q=q, success=bool(ok), min_clearance=float(clear),
                      seconds=time.perf_counter() - t0, attempts=attempts, length=length,
                      info={"check": chk})
