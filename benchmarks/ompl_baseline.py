"""A sampling-based baseline for ``bench_plan.py``: OMPL's RRTConnect with csdf as its
collision checker.

The state space is OMPL's ``RealVectorStateSpace`` over the robot's joint limits (a
continuous joint's infinite limits are clipped to +-pi, without wrap-around). A state
is valid when no sphere of the robot's cover (:meth:`csdf.plan.Robot.sphere_cover`)
reaches within ``margin`` of the scene (``scene.collide`` with the radii grown by
``margin``) and, with ``self_collision``, the robot's own sphere pairs
(:meth:`csdf.plan.Robot.self_pairs`) do not overlap (their smallest gap, as
:meth:`csdf.plan.Robot.self_clearance` computes it, is >= 0).

OMPL checks a motion at points at most ``resolution`` apart in the space's (Euclidean)
distance, so at most ``resolution`` apart in every joint too: no coarser than
``csdf.plan.check``'s max-norm step of the same size. By default the motions are
checked by a Python ``MotionValidator`` that tests the same points OMPL's
``DiscreteMotionValidator`` would (the end state and the interior points, not the start,
which the planner holds valid) in one vectorised csdf call per motion instead of one
Python callback per point; ``batch_motions=False`` leaves OMPL's own validator, which
calls the per-state checker for every point.

A result counts as a success only when the planner reports an exact solution and the
(simplified) path passes the same dense check ``bench_plan.py`` applies to its own plans
(``csdf.plan.check`` with 0.01 rad steps, margin 0, self-collision on).

Seeding: OMPL draws every random generator's seed from one global seed generator.
``ompl.util.RNG.setSeed`` reseeds it; generators created afterwards (this module builds
a fresh space, planner and simplifier per call) get seeds that follow from it, so a
call is reproducible for a given ``seed`` as long as the planner finishes within
``time_limit`` (a run cut short by the clock is not). OMPL logs an error when the seed
is set after generators have been made; this module silences OMPL's log output while it
reseeds.

Run the smoke test: ``python benchmarks/ompl_baseline.py [--problems 10]`` (needs the
``plan`` extra and ``pip install ompl``).
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

#: the dense check's step (rad) that bench_plan.py applies (``csdf.plan.check``'s default)
CHECK_STEP = 0.01


@dataclass
class RRTResult:
    """What one RRTConnect run gives.

    Attributes:
        success: OMPL found an exact solution and the returned path passes
            ``csdf.plan.check`` (``CHECK_STEP`` steps, margin 0).
        seconds: wall time of the setup, planning and simplification (not the check).
        q: ``(T, dof)`` waypoints from start to goal (straight segments between them);
            None without an exact solution.
        length: the path's length in joint space (sum of the steps' Euclidean norms,
            rad); ``nan`` without a path.
        status: OMPL's planner status as text (``'Exact solution'``, ``'Timeout'``,
            ``'Invalid start state'``, ...).
        info: counts: ``states`` (per-state validity calls), ``motions`` (batched
            motion checks), ``check`` (the :class:`csdf.plan.Check` of the path).
    """

    success: bool
    seconds: float
    q: np.ndarray | None
    length: float
    status: str = ""
    info: dict = field(default_factory=dict)


class _Validity:
    """Per-state validity through csdf (OMPL calls it with one state at a time)."""

    def __init__(self, scene: Any, robot: Any, margin: float, self_collision: bool):
        self.scene = scene
        self.robot = robot
        self.dof = robot.dof
        self.radii = np.asarray(robot.sphere_cover()[1], dtype=np.float64) + float(margin)
        pairs = robot.self_pairs() if self_collision else np.zeros((0, 2), np.int64)
        self.pi, self.pj = pairs[:, 0], pairs[:, 1]
        r = robot.sphere_cover()[1]
        self.pair_r2 = (r[self.pi] + r[self.pj]) ** 2  # gap >= 0 <=> dist^2 >= (ri + rj)^2
        self.calls = 0

    def valid_many(self, Q: np.ndarray) -> np.ndarray:
        """``(B,)`` bool: which of the joint positions ``Q`` ``(B, dof)`` are valid."""
        centers = self.robot.spheres_many(Q)  # (B, S, 3), one forward-kinematics pass
        B, S = centers.shape[:2]
        hit = self.scene.collide(centers.reshape(-1, 3), np.tile(self.radii, B))
        ok = ~hit.reshape(B, S).any(axis=1)
        if len(self.pi) and ok.any():  # self_clearance >= 0, from the same spheres
            rows = np.flatnonzero(ok)
            c = centers[rows]
            d = c[:, self.pi] - c[:, self.pj]
            dist2 = np.einsum("bpk,bpk->bp", d, d)
            ok[rows] = (dist2 >= self.pair_r2).all(axis=1)
        return ok

    def __call__(self, state: Any) -> bool:
        self.calls += 1
        q = np.array(state[0:self.dof], dtype=np.float64)
        return bool(self.valid_many(q[None])[0])


def _motion_validator_class() -> type:
    """A ``MotionValidator`` subclass that checks a motion's points in one csdf call
    (made on first use, so that importing this module does not need OMPL)."""
    from ompl import base as ob

    class BatchMotionValidator(ob.MotionValidator):
        """Checks the end state and the interior points ``j / n`` (``n`` as in OMPL's
        ``DiscreteMotionValidator``: the distance over the longest valid segment,
        rounded up), coarse points first so that a collision is found early."""

        def __init__(self, si: Any, validity: _Validity):
            super().__init__(si)
            self.validity = validity
            self.space = si.getStateSpace()
            self.dof = validity.dof
            self.motions = 0

        def checkMotion(self, s1: Any, s2: Any) -> bool:  # noqa: N802 - OMPL's name
            self.motions += 1
            a = np.array(s1[0:self.dof], dtype=np.float64)
            b = np.array(s2[0:self.dof], dtype=np.float64)
            n = max(1, int(self.space.validSegmentCount(s1, s2)))
            j = np.arange(n, 0, -1)  # the end state first, then the interior points
            stride = max(1, n // 16)
            coarse = (j % stride == 0) | (j == n)
            for part in (j[coarse], j[~coarse]):
                if len(part):
                    Q = a + (part / n)[:, None] * (b - a)
                    if not self.validity.valid_many(Q).all():
                        return False
            return True

    return BatchMotionValidator


def _states(path: Any, dof: int) -> np.ndarray:
    """A ``PathGeometric``'s states as ``(T, dof)``."""
    return np.array([path.getState(k)[0:dof] for k in range(path.getStateCount())],
                    dtype=np.float64).reshape(-1, dof)


def rrtconnect(scene: Any, robot: Any, q_start: Any, q_goal: Any, *,
               time_limit: float = 1.0, margin: float = 0.0, seed: int = 0,
               simplify: bool = True, resolution: float = 0.01,
               self_collision: bool = True, batch_motions: bool = True) -> RRTResult:
    """Plan from ``q_start`` to ``q_goal`` with OMPL's RRTConnect (see the module docs).

    Args:
        scene: a :class:`csdf.Scene` (obstacles in the robot's root frame).
        robot: a :class:`csdf.plan.Robot`.
        q_start, q_goal: ``(dof,)`` joint positions.
        time_limit: the planner's time budget (s); simplification comes on top.
        margin: a state is invalid where a sphere comes within ``margin`` (m) of the
            scene (the success check itself uses margin 0, like bench_plan's).
        seed: reseeds OMPL's global seed generator (with ``seed + 1``: OMPL refuses 0).
        simplify: shorten the path with OMPL's ``PathSimplifier.simplifyMax``
            (shortcutting, vertex reduction, B-spline smoothing, all validity-checked).
        resolution: the motion check's step (rad, Euclidean over the joints).
        self_collision: states where the robot's own spheres overlap are invalid.
        batch_motions: check each motion's points in one vectorised csdf call (a
            Python ``MotionValidator``) rather than one OMPL callback per point.

    Returns:
        :class:`RRTResult`.
    """
    from ompl import base as ob
    from ompl import geometric as og
    from ompl import util as ou

    from csdf.plan import check

    t0 = time.perf_counter()
    dof = robot.dof
    a = np.asarray(q_start, dtype=np.float64).reshape(dof)
    b = np.asarray(q_goal, dtype=np.float64).reshape(dof)
    level = ou.getLogLevel()
    ou.setLogLevel(ou.LOG_NONE)  # setSeed logs an error once generators exist
    try:
        ou.RNG.setSeed(int(seed) % (2**32 - 1) + 1)  # OMPL refuses seed 0
    finally:
        ou.setLogLevel(level)

    space = ob.RealVectorStateSpace(dof)
    bounds = ob.RealVectorBounds(dof)
    lim = np.clip(robot.limits, -np.pi, np.pi)  # only infinite (continuous) ones change
    lim = np.where(np.isfinite(robot.limits), robot.limits, lim)
    for k in range(dof):
        bounds.setLow(k, float(lim[k, 0]))
        bounds.setHigh(k, float(lim[k, 1]))
    space.setBounds(bounds)
    space.setLongestValidSegmentFraction(float(resolution) / space.getMaximumExtent())

    si = ob.SpaceInformation(space)
    validity = _Validity(scene, robot, margin, self_collision)
    si.setStateValidityChecker(validity)
    motion = None
    if batch_motions:
        motion = _motion_validator_class()(si, validity)
        si.setMotionValidator(motion)
    ss = og.SimpleSetup(si)
    start, goal = si.allocState(), si.allocState()
    for k in range(dof):
        start[k] = float(a[k])
        goal[k] = float(b[k])
    ss.setStartAndGoalStates(start, goal)
    planner = og.RRTConnect(si)
    ss.setPlanner(planner)
    ss.setup()

    status = ss.solve(float(time_limit))
    exact = (status.getStatus() == ob.PlannerStatus.EXACT_SOLUTION
             and ss.haveExactSolutionPath())
    q = None
    if exact:
        if simplify:
            ss.simplifySolution()  # duration 0: PathSimplifier.simplifyMax
        q = _states(ss.getSolutionPath(), dof)
    seconds = time.perf_counter() - t0

    info: dict = {"states": validity.calls,
                  "motions": motion.motions if motion is not None else None}
    ok, length = False, float("nan")
    if q is not None:
        length = float(np.linalg.norm(np.diff(q, axis=0), axis=1).sum())
        chk = check(scene, robot, q, step=CHECK_STEP, self_collision=True)
        info["check"] = chk
        ok = bool(chk.ok)
    return RRTResult(success=ok, seconds=seconds, q=q, length=length,
                     status=status.asString(), info=info)


def main(argv: list[str] | None = None) -> int:
    """Smoke test: the first problems of ``bench_plan.py`` (same robot, scene and
    problem draw), planned by RRTConnect."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--problems", type=int, default=10)
    p.add_argument("--seed", type=int, default=0, help="bench_plan's problem seed")
    p.add_argument("--time-limit", type=float, default=1.0)
    p.add_argument("--margin", type=float, default=0.0)
    p.add_argument("--no-simplify", action="store_true")
    p.add_argument("--per-state", action="store_true",
                   help="OMPL's own motion validator (one callback per point)")
    p.add_argument("--robot", choices=("panda", "panda_like"), default=None,
                   help="bench_plan's arm (default: bench_plan's default)")
    args = p.parse_args(argv)
    from ompl import util as ou

    ou.setLogLevel(ou.LOG_WARN)  # not OMPL's per-run Info lines

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import bench_plan

    from csdf.plan import Robot, check

    if hasattr(bench_plan, "load_robot"):  # bench_plan's --robot choice and default
        name = args.robot or bench_plan.default_robot()
        robot = bench_plan.load_robot(name)
    else:
        name = "panda_like"
        robot = Robot.from_urdf(bench_plan.URDF)
    print(f"{name}: {robot}; {len(robot.sphere_cover()[1])} spheres, "
          f"{len(robot.self_pairs())} self pairs")
    scene = bench_plan.make_scene()
    problems = bench_plan.problems
    probs = problems(robot, scene, args.problems, args.seed)
    # warm up csdf's kernels (not timed)
    rrtconnect(scene, robot, probs[0][0], probs[0][1], time_limit=0.05)
    rows = []
    for k, (qs, qg) in enumerate(probs):
        straight = check(scene, robot, np.stack([qs, qg]), step=CHECK_STEP).ok
        r = rrtconnect(scene, robot, qs, qg, time_limit=args.time_limit,
                       margin=args.margin, seed=k, simplify=not args.no_simplify,
                       batch_motions=not args.per_state)
        rows.append((r.success, r.seconds, r.length, straight))
        chk = r.info.get("check")
        print(f"{k:3d}  {'ok  ' if r.success else 'FAIL'}  {r.seconds * 1e3:7.0f} ms  "
              f"length {r.length:5.2f}  straight line {'clear' if straight else 'hits '}  "
              f"{r.status}; states {r.info['states']}, motions {r.info['motions']}"
              + (f"; check min clearance {chk.min_clearance:+.4f}" if chk else ""))
    ok = np.array([x[0] for x in rows])
    secs = np.array([x[1] for x in rows])
    lens = np.array([x[2] for x in rows])
    hard = ~np.array([x[3] for x in rows])
    print()
    for label, sel in (("all", np.ones(len(rows), bool)), ("straight line collides", hard)):
        if not sel.any():
            continue
        good = sel & ok
        med_len = np.median(lens[good]) if good.any() else float("nan")
        print(f"{label}: {sel.sum()} problems, success {ok[sel].mean():.0%}, median "
              f"{np.median(secs[sel]) * 1e3:.0f} ms, 90th percentile "
              f"{np.percentile(secs[sel], 90) * 1e3:.0f} ms, median length {med_len:.2f} rad")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
