"""Trajectory optimisation (``csdf.plan.optimize``) and the dense check
(``csdf.plan.check``) on a small arm and a scene (issue 17)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import csdf
from csdf.errors import CsdfError

pytest.importorskip("yourdfpy")
from csdf.plan import Robot, check, optimize, sphere_jacobian  # noqa: E402

URDF = Path(__file__).parent / "data" / "arm3.urdf"


@pytest.fixture(scope="module")
def arm() -> Robot:
    return Robot.from_urdf(URDF)


@pytest.fixture(scope="module")
def wall() -> csdf.Scene:
    scene = csdf.Scene()
    scene.add(csdf.box((0.1, 0.1, 0.1)), pose=csdf.Pose(translation=[0.0, 0.5, 0.6]))
    return scene


def test_sphere_motion_by_each_joint_matches_finite_differences(arm):
    rng = np.random.default_rng(2)
    for q in rng.uniform([-3, -2, 0], [3, 2, 0.1], (4, 3)):
        c, r, J = sphere_jacobian(arm, q)
        for k in range(arm.dof):
            dq = np.zeros(arm.dof)
            dq[k] = 1e-6
            fd = (arm.spheres(q + dq)[0] - arm.spheres(q - dq)[0]) / 2e-6
            np.testing.assert_allclose(J[:, :, k], fd, rtol=0, atol=1e-8)
    base = [i for i, link in enumerate(arm.sphere_cover()[2]) if arm.links[link] == "base"]
    assert np.all(J[base] == 0)  # nothing moves the base


def test_a_path_around_an_obstacle(arm, wall):
    qs, qg = np.array([0.0, 0.0, 0.0]), np.array([np.pi, 0.0, 0.0])
    straight = check(wall, arm, np.stack([qs, qg]))
    assert not straight.ok and straight.first_collision > 0
    assert straight.where.shape == (3,) and straight.min_clearance < 0
    tr = optimize(wall, arm, qs, qg, n_waypoints=24, seed=0)
    assert tr.success and tr.min_clearance >= 0
    assert tr.q.shape == (24, 3)
    np.testing.assert_array_equal(tr.q[0], qs)
    np.testing.assert_array_equal(tr.q[-1], qg)
    assert all(arm.in_limits(q) for q in tr.q)
    again = check(wall, arm, tr.q, step=0.005)  # a finer check agrees
    assert again.ok and again.positions > 600
    assert np.pi <= tr.length < 1.5 * np.pi and tr.seconds > 0


def test_an_unreachable_goal_is_reported_not_hidden(arm):
    scene = csdf.Scene()
    scene.add(csdf.sphere(0.25), pose=csdf.Pose(translation=[0.0, 0.55, 0.6]))
    qg = np.array([np.pi / 2 - 0.3, 0.0, 0.0])  # the forearm ends inside the sphere
    tr = optimize(scene, arm, [0.0, 0.0, 0.0], qg, n_waypoints=8, restarts=1, max_nfev=30,
                  refine=0)
    assert not tr.success and tr.min_clearance < 0 and tr.attempts == 2 and len(tr.q) == 8
    finer = optimize(scene, arm, [0.0, 0.0, 0.0], qg, n_waypoints=8, restarts=1,
                     max_nfev=30)  # then twice more, on paths of 15 and 29 waypoints
    assert not finer.success and finer.attempts == 4 and len(finer.q) in (8, 15, 29)


def test_bad_requests(arm, wall):
    with pytest.raises(CsdfError, match="q_goal is outside the joint limits"):
        optimize(wall, arm, [0, 0, 0], [0, 2.5, 0])
    with pytest.raises(CsdfError, match="n_waypoints must be >= 3"):
        optimize(wall, arm, [0, 0, 0], [1, 0, 0], n_waypoints=2)
    with pytest.raises(CsdfError, match=r"q must have shape \(T, 3\)"):
        check(wall, arm, np.zeros((4, 2)))
    with pytest.raises(CsdfError, match="step must be positive"):
        check(wall, arm, np.zeros((4, 3)), step=0)


def test_the_plan_command(wall, tmp_path):
    import json

    from typer.testing import CliRunner

    from csdf.cli import app

    wall.save(tmp_path / "wall.json")
    out = tmp_path / "traj.json"
    args = ["plan", str(tmp_path / "wall.json"), str(URDF), "-o", str(out)]
    r = CliRunner().invoke(app, args + ["--start", "0,0,0", "--goal", "3.14159,0,0",
                                        "--waypoints", "16"])
    assert r.exit_code == 0, r.output
    doc = json.loads(out.read_text())
    assert doc["success"] and len(doc["q"]) == 16 and doc["joints"][0] == "shoulder_yaw"
    r = CliRunner().invoke(app, args + ["--start", "0,0", "--goal", "1,0,0"])
    assert r.exit_code == 2 and "--start expects q1,q2,q3" in r.output
    r = CliRunner().invoke(app, args[:-1] + [str(tmp_path / "t.txt"), "--start", "0,0,0",
                                             "--goal", "1,0,0"])
    assert r.exit_code == 2 and "must end in .json" in r.output


def test_self_collision_pairs_and_clearance(arm):
    _, r, link = arm.sphere_cover()
    pairs = arm.self_pairs()
    got = {(arm.links[link[i]], arm.links[link[j]]) for i, j in pairs}
    # adjacent links and links glued by the fixed joint (hand, tool) are not tested
    assert got == {("base", "fore"), ("base", "hand"), ("base", "tool"), ("upper", "hand"),
                   ("upper", "tool")}
    fewer = arm.self_pairs(ignore=[("base", "tool")])
    assert ("base", "tool") not in {(arm.links[link[i]], arm.links[link[j]]) for i, j in fewer}
    with pytest.raises(CsdfError, match="unknown link 'gripper'"):
        arm.self_pairs(ignore=[("base", "gripper")])
    rng = np.random.default_rng(4)
    Q = rng.uniform([-3, -2, 0], [3, 2, 0.1], (20, 3))
    got = arm.self_clearance(Q)
    for q, g in zip(Q, got):
        c, _, _ = arm.spheres(q)
        i, j = pairs[:, 0], pairs[:, 1]
        want = (np.linalg.norm(c[i] - c[j], axis=1) - r[i] - r[j]).min()
        assert g == pytest.approx(want, abs=1e-12)
    folded = np.array([[0.0, 2.0, 0.1]])  # the forearm bent down beside the upper arm
    assert arm.self_clearance(folded)[0] < arm.self_clearance([[0.0, 0.0, 0.0]])[0]


def test_margins_must_be_finite_and_not_negative(arm):
    scene = csdf.Scene()
    scene.add(csdf.sphere(0.1), pose=csdf.Pose(translation=[2.0, 0.0, 0.0]))
    for kw in ({"margin": -0.1}, {"margin": float("nan")}, {"self_margin": -1.0}):
        with pytest.raises(CsdfError, match="must be a finite number >= 0"):
            optimize(scene, arm, [0.0, 0.0, 0.0], [0.5, 0.0, 0.0], n_waypoints=4, **kw)
