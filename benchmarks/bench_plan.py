"""Trajectory optimisation (issue 17, the part that exists): a 7-joint arm among zoo
furniture, seeded start/goal pairs, planned with ``csdf.plan.optimize``.

The arm is ``benchmarks/data/panda_like.urdf``: the Franka Emika Panda's kinematics and
joint limits (its published DH parameters) with capsule-like collision geometry written
for csdf (cylinders and spheres), not the manufacturer's collision model; the robot's
own sphere pairs (``Robot.self_pairs``: not adjacent, not always touching) are kept
apart too. The scene: a table in front of the arm, a chair beside it and a
bookshelf behind. Start and goal are uniform in the joint limits, redrawn until the
robot's sphere cover is clear of the scene and of itself at both. For every problem: success (the
dense check, 0.01 rad steps, finds no collision), planning time, path length in joint
space; and the straight line's verdict for comparison.

Run: ``python benchmarks/bench_plan.py [--problems 100] [--waypoints 32]`` (needs the
``plan`` extra: ``pip install 'csdf[plan]'``).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import machine_info, md_table  # noqa: E402

URDF = Path(__file__).resolve().parent / "data" / "panda_like.urdf"


def make_scene():
    import csdf

    scene = csdf.Scene()
    scene.add("table", pose=csdf.Pose.from_rotvec([0, 0, np.pi / 2], [0.75, 0.0, -0.35]))
    scene.add("chair", pose=csdf.Pose.from_rotvec([0, 0, 0.4], [0.1, 0.8, -0.35]))
    scene.add("bookshelf", pose=csdf.Pose.from_rotvec([0, 0, np.pi / 2], [-0.8, 0.0, -0.35]))
    return scene


def problems(robot, scene, n: int, seed: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """``n`` start/goal pairs whose sphere covers are clear of the scene."""
    rng = np.random.default_rng(seed)
    lim = robot.limits
    out: list[np.ndarray] = []
    while len(out) < 2 * n:
        q = rng.uniform(lim[:, 0], lim[:, 1])
        c, r, _ = robot.spheres(q)
        if not scene.collide(c, r + 0.01).any() and robot.self_clearance(q[None])[0] > 0:
            out.append(q)
    return [(out[2 * k], out[2 * k + 1]) for k in range(n)]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--problems", type=int, default=100)
    p.add_argument("--waypoints", type=int, default=32)
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)
    from csdf.plan import Robot, check, optimize

    print("\n".join(f"* {k}: {v}" for k, v in machine_info().items()))
    robot = Robot.from_urdf(URDF)
    scene = make_scene()
    probs = problems(robot, scene, args.problems, args.seed)
    # warm up the kernels once (not timed)
    optimize(scene, robot, probs[0][0], probs[0][1], n_waypoints=8, restarts=0, max_nfev=2)
    ok, times, lengths, clear, straight_ok, attempts = [], [], [], [], [], []
    for k, (qs, qg) in enumerate(probs):
        straight_ok.append(check(scene, robot, np.stack([qs, qg])).ok)
        t0 = time.perf_counter()
        tr = optimize(scene, robot, qs, qg, n_waypoints=args.waypoints, seed=k)
        times.append(time.perf_counter() - t0)
        ok.append(tr.success)
        lengths.append(tr.length)
        clear.append(tr.min_clearance)
        attempts.append(tr.attempts)
    ok_a, times_a, len_a = np.array(ok), np.array(times), np.array(lengths)
    hard = ~np.array(straight_ok)
    rows = []
    for label, sel in (("all", np.ones(len(probs), bool)),
                       ("straight line collides", hard)):
        if not sel.any():
            continue
        good = sel & ok_a
        rows.append([label, f"{sel.sum()}", f"{ok_a[sel].mean():.0%}",
                     f"{np.median(times_a[sel]) * 1e3:.0f}",
                     f"{np.percentile(times_a[sel], 90) * 1e3:.0f}",
                     f"{np.median(len_a[good]) if good.any() else float('nan'):.2f}",
                     f"{np.mean(np.array(attempts)[sel]):.2f}"])
    print()
    print(md_table(["problems", "count", "planned clear", "median ms", "90th percentile ms",
                    "median length (rad, clear ones)", "attempts (mean)"], rows))
    print(f"\nthe straight line in joint space is clear for {np.mean(straight_ok):.0%}")
    print(f"\n{robot}; sphere cover: {len(robot.sphere_cover()[1])} spheres; "
          f"scene: {len(scene)} instances; {args.waypoints} waypoints; margin 0.05 m")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
