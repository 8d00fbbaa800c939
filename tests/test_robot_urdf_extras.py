"""``csdf.plan.Robot`` beyond plain URDFs (issue 17): capsules (which yourdfpy does not
read), mimic joints, locked joints, and an SRDF's disabled collision pairs.

Forward kinematics is checked against yourdfpy's (which follows mimic joints itself),
the model against capsules placed by hand, derivatives by a mimicked joint against
finite differences.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import csdf
from csdf.errors import CsdfError

yourdfpy = pytest.importorskip("yourdfpy")
from csdf.plan import Robot, sphere_jacobian  # noqa: E402

DATA = Path(__file__).parent / "data"
URDF, SRDF = DATA / "gripper.urdf", DATA / "gripper.srdf"
RNG = np.random.default_rng(11)


@pytest.fixture(scope="module")
def grip() -> Robot:
    return Robot.from_urdf(URDF, srdf=SRDF)


def _qs(robot: Robot, n: int) -> np.ndarray:
    lim = robot.limits
    return RNG.uniform(lim[:, 0], lim[:, 1], (n, robot.dof))


def test_mimic_joints_follow_their_leader_as_yourdfpy_does(grip):
    assert grip.dof == 3 and grip.joint_names == ["yaw", "pitch", "finger_left"]
    right = next(j for j in grip.joints if j.name == "finger_right")
    assert (right.mimic, right.multiplier, right.offset, right.param) == \
        ("finger_left", -1.0, -0.005, None)
    text = URDF.read_text().replace("capsule", "cylinder")  # yourdfpy cannot read capsules
    ref = yourdfpy.URDF.load(__import__("io").StringIO(text))
    for q in _qs(grip, 5):
        ref.update_cfg(dict(zip(grip.joint_names, q)))
        poses = grip.fk(q)
        for link in grip.links:
            np.testing.assert_allclose(poses[link], ref.get_transform(link, "base"),
                                       atol=1e-12)


def test_capsules_are_exact_csdf_capsules_in_both_views(grip):
    caps = [p for p in grip.primitives if p.kind == "capsule"]
    assert [(p.link, p.size) for p in caps] == [("arm", (0.04, 0.4)), ("palm", (0.03, 0.1))]
    q = np.array([0.4, -0.7, 0.02])
    T = grip.fk(q)["arm"] @ caps[0].origin
    a, b = T[:3, :3] @ [0, 0, -0.2] + T[:3, 3], T[:3, :3] @ [0, 0, 0.2] + T[:3, 3]
    pts = RNG.uniform(-0.3, 0.3, (3000, 3)) + (a + b) / 2
    want = csdf.capsule(tuple(a), tuple(b), 0.04)(pts)
    got = grip._primitive_shape(caps[0])(  # the primitive alone, moved by hand
        (pts - T[:3, 3]) @ T[:3, :3] @ caps[0].origin[:3, :3].T + caps[0].origin[:3, 3])
    np.testing.assert_allclose(got, want, atol=1e-12)
    whole = grip.shape()(pts, grip.params(q))
    assert np.all(whole <= want + 1e-12)  # the union is at most each part
    c, r, link = grip.spheres(q)  # the cover holds the capsule, caps included
    u = RNG.normal(size=(2000, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    t = RNG.uniform(0, 1, (2000, 1))
    inside = a + t * (b - a) + u * 0.04 * RNG.uniform(0, 1, (2000, 1)) ** (1 / 3)
    ends = np.concatenate([a + u[:500] * 0.0399, b + u[500:1000] * 0.0399])
    for p in (inside, ends):
        assert (np.linalg.norm(p[:, None] - c[None], axis=2) <= r + 1e-12).any(1).all()


def test_derivatives_by_a_mimicked_joint(grip):
    prog = grip.shape().compile()
    assert sorted(prog.param_names) == ["finger_left", "pitch", "yaw"]
    q = np.array([0.3, 0.5, 0.02])
    fingers = grip.fk(q)
    mid = (fingers["left"][:3, 3] + fingers["right"][:3, 3]) / 2
    pts = mid + RNG.uniform(-0.06, 0.06, (800, 3))
    J = prog.param_jacobian(pts, grip.params(q))[:, prog.param_names.index("finger_left")]
    h = 1e-6
    fd = (prog(pts, grip.params(q + [0, 0, h])) - prog(pts, grip.params(q - [0, 0, h]))) \
        / (2 * h)
    keep = np.abs(fd - J) < 1e-3  # leaves out the few points where the nearest part flips
    assert keep.mean() > 0.95
    np.testing.assert_allclose(J[keep], fd[keep], atol=2e-6)
    assert np.abs(J).max() > 0.5  # both fingers move the field
    c, _, Js = sphere_jacobian(grip, q)
    for k in range(grip.dof):
        dq = np.zeros(grip.dof)
        dq[k] = h
        fd = (grip.spheres(q + dq)[0] - grip.spheres(q - dq)[0]) / (2 * h)
        np.testing.assert_allclose(Js[..., k], fd, atol=1e-7)
    right = grip.links.index("right")
    assert np.allclose(Js[grip.spheres(q)[2] == right, :, 2], -Js[grip.spheres(q)[2]
                       == grip.links.index("left"), :, 2])


def test_locked_joints_and_their_mimics_hold_still(grip):
    held = Robot.from_urdf(URDF, lock={"finger_left": 0.03})
    assert held.dof == 2 and held.joint_names == ["yaw", "pitch"]
    for q in _qs(held, 3):
        want = grip.fk(np.r_[q, 0.03])
        got = held.fk(q)
        for link in grip.links:
            np.testing.assert_allclose(got[link], want[link], atol=1e-12)
    with pytest.raises(CsdfError, match=r"lock: joint 'finger_left' at 0.5 is outside"):
        Robot.from_urdf(URDF, lock={"finger_left": 0.5})
    with pytest.raises(CsdfError, match=r"lock: .* has no joint 'thumb'"):
        Robot.from_urdf(URDF, lock={"thumb": 0.0})


def test_srdf_pairs_are_left_out_of_self_collision(grip):
    assert set(grip.ignore) == {("left", "right"), ("base", "palm")}
    plain = Robot.from_urdf(URDF)
    _, _, link = grip.sphere_cover()
    names = np.array(grip.links)

    def link_pairs(robot):
        pairs = robot.self_pairs(samples=0)
        return {tuple(sorted(p)) for p in zip(names[link[pairs[:, 0]]],
                                              names[link[pairs[:, 1]]])}

    assert ("left", "right") in link_pairs(plain) and ("base", "palm") in link_pairs(plain)
    assert link_pairs(grip) == link_pairs(plain) - {("left", "right"), ("base", "palm")}
    with pytest.raises(CsdfError, match="unknown link 'wrist'"):
        Robot.from_urdf(URDF, srdf='<robot name="g"><disable_collisions link1="wrist" '
                                   'link2="left"/></robot>')


@pytest.mark.parametrize("edit, match", [
    (('<capsule radius="0.04" length="0.4"/>', '<capsule radius="a" length="0.4"/>'),
     r"link 'arm': a <capsule> needs numeric radius and length"),
    (('<mimic joint="finger_left"', '<mimic joint="finger_up"'),
     r"joint 'finger_right' mimics an unknown joint 'finger_up'"),
    (('<capsule radius="0.03" length="0.1"/>', '<capsule radius="-0.03" length="0.1"/>'),
     r"link 'palm' has a capsule of size"),
])
def test_bad_extras_are_refused_naming_what(edit, match):
    with pytest.raises(CsdfError, match=match):
        Robot.from_urdf(URDF.read_text().replace(*edit))


def test_locking_a_follower_or_a_fixed_joint_is_refused():
    with pytest.raises(CsdfError, match="lock: joint 'finger_right' mimics 'finger_left'"):
        Robot.from_urdf(URDF, lock={"finger_right": 0.01})
    fixed = URDF.read_text().replace('<joint name="pitch" type="revolute">',
                                     '<joint name="pitch" type="fixed">')
    with pytest.raises(CsdfError, match="lock: joint 'pitch' is fixed already"):
        Robot.from_urdf(fixed, lock={"pitch": 0.0})
