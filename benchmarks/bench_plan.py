"""Trajectory optimisation (issue 17): a 7-joint arm among zoo furniture, seeded
start/goal pairs, planned with ``csdf.plan.optimize``.

The arm (``--robot``): ``panda`` is the Franka Emika Panda of example-robot-data (its
``panda_collision.urdf``: 13 capsules, each a cylinder with two spheres; the SRDF's
disabled pairs; fingers locked open), the default where that package is installed (the
``bench-plan`` extra); ``panda_like`` is ``benchmarks/data/panda_like.urdf``, the
Panda's kinematics and joint limits (its published DH parameters) with collision
geometry written for csdf. The robot's own sphere pairs (``Robot.self_pairs``: not
adjacent, not disabled, not always touching) are kept apart too. The scene: a table
in front of the arm, a chair beside it and a bookshelf behind. Start and goal are
uniform in the joint limits, redrawn until the robot's sphere cover is clear of the
scene and of itself at both. For every problem: success (the dense check, 0.01 rad
steps, finds no collision), planning time, path length in joint space; and the
straight line's verdict for comparison. Beside it, on the same problems, OMPL's
RRTConnect with csdf as its collision checker (``ompl_baseline.py``; where ``ompl`` is
installed), its path shortened by OMPL's simplifier, judged by the same dense check.

Run: ``python benchmarks/bench_plan.py [--problems 100] [--waypoints 32] [--robot
panda]`` (needs the ``plan`` extra; the real Panda and the baselines need
``pip install 'csdf[bench-plan]'``).
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


def load_robot(name: str):
    """The benchmark's arm (see the module docs)."""
    from csdf.plan import Robot, example_robot

    if name == "panda":
        return example_robot("panda", lock={"panda_finger_joint1": 0.04})
    if name == "panda_mesh":  # the STL collision meshes, each as spheres holding it
        return example_robot("panda", lock={"panda_finger_joint1": 0.04}, meshes=True,
                             mesh_spacing=0.1)
    return Robot.from_urdf(URDF)


def default_robot() -> str:
    from csdf.errors import CsdfError
    from csdf.plan import example_robot_files

    try:
        example_robot_files("panda")
        return "panda"
    except CsdfError:
        return "panda_like"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--problems", type=int, default=100)
    p.add_argument("--waypoints", type=int, default=32)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--robot", choices=("panda", "panda_mesh", "panda_like"), default=None,
                   help="the arm (default: panda where example-robot-data is installed)")
    p.add_argument("--no-ompl", action="store_true", help="skip OMPL's RRTConnect")
    p.add_argument("--ompl-time", type=float, default=2.0,
                   help="RRTConnect's time limit per problem (s)")
    args = p.parse_args(argv)
    from csdf.plan import check, optimize

    rrt = None
    if not args.no_ompl:
        try:
            import ompl.util as ou
            from ompl_baseline import rrtconnect as rrt

            ou.setLogLevel(ou.LOG_WARN)
        except ImportError:
            print("OMPL is not installed (pip install 'csdf[bench-plan]'): no RRTConnect")

    print("\n".join(f"* {k}: {v}" for k, v in machine_info().items()))
    robot = load_robot(args.robot or default_robot())
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
        # judged by the same dense check as the baseline (0.01 rad), not the planner's own
        ok.append(bool(tr.success and check(scene, robot, tr.q).ok))
        lengths.append(tr.length)
        clear.append(tr.min_clearance)
        attempts.append(tr.attempts)
    runs = [("csdf.plan.optimize", np.array(ok), np.array(times), np.array(lengths),
             np.array(attempts, float))]
    if rrt is not None:
        rok, rtimes, rlen = [], [], []
        for k, (qs, qg) in enumerate(probs):
            r = rrt(scene, robot, qs, qg, time_limit=args.ompl_time, seed=k)
            rok.append(r.success)
            rtimes.append(r.seconds)
            rlen.append(r.length)
        runs.append(("OMPL RRTConnect + simplify", np.array(rok), np.array(rtimes),
                     np.array(rlen), np.full(len(probs), np.nan)))
    hard = ~np.array(straight_ok)
    rows = []
    for planner, ok_a, times_a, len_a, att in runs:
        for label, sel in (("all", np.ones(len(probs), bool)),
                           ("straight line collides", hard)):
            if not sel.any():
                continue
            good = sel & ok_a
            rows.append([planner, label, f"{sel.sum()}", f"{ok_a[sel].mean():.0%}",
                         f"{np.median(times_a[sel]) * 1e3:.0f}",
                         f"{np.percentile(times_a[sel], 90) * 1e3:.0f}",
                         f"{np.median(len_a[good]) if good.any() else float('nan'):.2f}",
                         "-" if np.isnan(att).all() else f"{np.mean(att[sel]):.2f}"])
    print()
    print(md_table(["planner", "problems", "count", "clear by the dense check", "median ms",
                    "90th percentile ms", "median length (rad, clear ones)",
                    "attempts (mean)"], rows))
    print(f"\nthe straight line in joint space is clear for {np.mean(straight_ok):.0%}")
    print(f"\n{robot}; sphere cover: {len(robot.sphere_cover()[1])} spheres; "
          f"scene: {len(scene)} instances; {args.waypoints} waypoints; margin 0.05 m")
    print()
    print(robot_model_view(robot, args.seed))
    return 0


def robot_model_view(robot, seed: int, positions: int = 20, points: int = 2000) -> str:
    """The robot as one model (joints as parameters) against finite differences and the
    sphere view: obstacle points around the arm at seeded positions; the derivative of
    their distance by every joint from ``param_jacobian`` against central differences
    (h = 1e-6 rad, points 1 mm or more from where the nearest part changes), and the
    model's distance against the sphere view's (never above it: the spheres hold the
    links). Returns a markdown table."""
    rng = np.random.default_rng(seed)
    prog = robot.shape().compile()
    names = prog.param_names
    lim = robot.limits
    warm = np.zeros((8, 3))
    prog.param_jacobian(warm, robot.params(lim.mean(axis=1)))  # compile outside the timing
    fd_err, gap, t_jac, t_val = [], [], [], []
    for _ in range(positions):
        q = rng.uniform(lim[:, 0], lim[:, 1])
        c, r, _ = robot.spheres(q)
        pts = c[rng.integers(len(c), size=points)] + rng.normal(scale=0.15, size=(points, 3))
        pv = robot.params(q)
        t0 = time.perf_counter()
        d = prog(pts, pv)
        t1 = time.perf_counter()
        J = prog.param_jacobian(pts, pv)
        t2 = time.perf_counter()
        t_val.append(t1 - t0)
        t_jac.append(t2 - t1)
        h = 1e-6
        for k, jt in enumerate(robot.movable):
            qp, qm = q.copy(), q.copy()
            qp[k] += h
            qm[k] -= h
            fd = (prog(pts, robot.params(qp)) - prog(pts, robot.params(qm))) / (2 * h)
            col = J[:, names.index(jt.param)]
            smooth = np.abs(fd - col) < 1e-3  # leaves out where the nearest part switches
            fd_err.append(np.abs(fd - col)[smooth].max())
        outside = d > 0
        sph = (np.linalg.norm(pts[:, None] - c[None], axis=2) - r).min(axis=1)
        gap.append(d[outside] - sph[outside])
    g = np.concatenate(gap)
    rows = [[f"{positions} x {points}", f"{max(fd_err):.1e}",
             f"{g.min():.2e}", f"{np.median(g) * 1e3:.1f}", f"{np.percentile(g, 95) * 1e3:.1f}",
             f"{np.median(t_val) / points * 1e9:.0f}", f"{np.median(t_jac) / points * 1e9:.0f}"]]
    return md_table(["positions x points", "max error of param_jacobian against FD (m/rad)",
                     "min (model - spheres) m", "median gap mm", "95th pct gap mm",
                     "value ns/point", "value + joint Jacobian ns/point"], rows)


if __name__ == "__main__":
    raise SystemExit(main())
