"""``csdf.plan.Robot`` (issue 17): a URDF read with yourdfpy, forward kinematics, the
robot as one csdf model whose joint positions are parameters, and spheres on its links.

Forward kinematics is checked against yourdfpy's own; the model against its primitives
placed by forward kinematics; its joint derivatives (``param_jacobian``) against finite
differences; the spheres against the primitives they cover.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import csdf
from csdf.errors import CsdfError

yourdfpy = pytest.importorskip("yourdfpy")
from csdf.plan import Robot  # noqa: E402

URDF = Path(__file__).parent / "data" / "arm3.urdf"
RNG = np.random.default_rng(5)


@pytest.fixture(scope="module")
def arm() -> Robot:
    return Robot.from_urdf(URDF)


def _random_q(arm: Robot, n: int) -> np.ndarray:
    lim = np.clip(arm.limits, -3.0, 3.0)
    return RNG.uniform(lim[:, 0], lim[:, 1], (n, arm.dof))


def _primitive_values(arm: Robot, q: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """``(N, K)`` each primitive's own distance at points, placed by forward kinematics."""
    poses = arm.fk(q)
    out = []
    for prim in arm.primitives:
        T = poses[prim.link] @ prim.origin
        local = (pts - T[:3, 3]) @ T[:3, :3]
        out.append(arm._primitive_shape(prim)(local @ prim.origin[:3, :3].T
                                              + prim.origin[:3, 3]))
    return np.stack(out, axis=1)


def test_the_tree_and_its_kinematics(arm):
    assert arm.dof == 3 and arm.joint_names == ["shoulder_yaw", "elbow", "slide"]
    assert [j.param for j in arm.movable] == ["shoulder_yaw", "elbow", "slide"]
    assert arm.links[0] == "base" and len(arm.primitives) == 5
    np.testing.assert_array_equal(arm.limits[1:], [[-2, 2], [0, 0.1]])
    assert np.isinf(arm.limits[0]).all()
    urdf = yourdfpy.URDF.load(str(URDF))
    for q in _random_q(arm, 5):
        urdf.update_cfg(dict(zip(arm.joint_names, q)))
        poses = arm.fk(q)
        for link in arm.links:
            want = urdf.get_transform(frame_to=link, frame_from="base")
            np.testing.assert_allclose(poses[link], want, atol=1e-12)
    assert arm.in_limits([0.0, 0.5, 0.05]) and not arm.in_limits([0.0, 2.5, 0.05])
    with pytest.raises(CsdfError, match=r"q must have shape \(3,\)"):
        arm.fk([0.0, 1.0])


def test_the_robot_as_one_model_matches_its_placed_primitives(arm):
    shape = arm.shape()
    assert [p.name for p in shape.params] == ["elbow", "shoulder_yaw", "slide"]
    prog = shape.compile()
    for q in _random_q(arm, 4):
        pts = RNG.uniform([-0.9, -0.9, -0.2], [0.9, 0.9, 1.3], (3000, 3))
        want = _primitive_values(arm, q, pts).min(axis=1)
        got = prog(pts, arm.params(q))
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)


def test_joint_derivatives_from_param_jacobian_match_finite_differences(arm):
    prog = arm.shape().compile()
    names = prog.param_names
    for q in _random_q(arm, 3):
        pts = RNG.uniform([-0.8, -0.8, 0.0], [0.8, 0.8, 1.2], (400, 3))
        vals = _primitive_values(arm, q, pts)
        srt = np.sort(vals, axis=1)
        clear = srt[:, 1] - srt[:, 0] > 1e-3  # away from where the nearest part changes
        J = prog.param_jacobian(pts[clear], arm.params(q))
        for k, j in enumerate(arm.movable):
            h = 1e-6
            qp, qm = q.copy(), q.copy()
            qp[k] += h
            qm[k] -= h
            fd = (prog(pts[clear], arm.params(qp)) - prog(pts[clear], arm.params(qm))) / (2 * h)
            np.testing.assert_allclose(J[:, names.index(j.param)], fd, rtol=0, atol=2e-6)
        assert np.abs(J).max() > 0.1


def test_spheres_cover_the_links_and_never_overstate_clearance(arm):
    for q in _random_q(arm, 3):
        c, r, link = arm.spheres(q)
        assert c.shape == (len(r), 3) and link.max() < len(arm.links)
        poses = arm.fk(q)
        for prim in arm.primitives:  # points inside each primitive are in some sphere
            T = poses[prim.link] @ prim.origin
            if prim.kind == "box":
                local = RNG.uniform(-0.5, 0.5, (500, 3)) * prim.size
            elif prim.kind == "cylinder":
                rad, length = prim.size
                a = RNG.uniform(0, 2 * np.pi, 500)
                rr = rad * np.sqrt(RNG.uniform(0, 1, 500))
                local = np.stack([rr * np.cos(a), rr * np.sin(a),
                                  RNG.uniform(-length / 2, length / 2, 500)], 1)
            else:
                u = RNG.normal(size=(500, 3))
                local = u / np.linalg.norm(u, axis=1, keepdims=True) * prim.size[0] \
                    * RNG.uniform(0, 1, (500, 1)) ** (1 / 3)
            p = local @ T[:3, :3].T + T[:3, 3]
            inside = (np.linalg.norm(p[:, None] - c[None], axis=2) <= r + 1e-12).any(1)
            assert inside.all(), prim
        pts = RNG.uniform(-1, 1, (2000, 3)) + [0, 0, 0.5]
        sphere_clear = (np.linalg.norm(pts[:, None] - c[None], axis=2) - r).min(axis=1)
        model = arm.shape()(pts, arm.params(q))
        outside = model >= 0  # (inside, penetration depths are not compared)
        assert np.all(sphere_clear[outside] <= model[outside] + 1e-12)
        far = model > 0.05
        assert np.median(model[far] - sphere_clear[far]) < 0.03  # and not much less


def test_robot_spheres_against_a_scene(arm):
    scene = csdf.Scene()
    scene.add(csdf.box((0.2, 0.2, 0.4)), pose=csdf.Pose(translation=[0.6, 0.0, 0.4]))
    c, r, _ = arm.spheres([0.0, 0.0, 0.1])  # the arm reaches towards +x
    hits = scene.collide(c, r)
    c2, r2, _ = arm.spheres([np.pi, 0.0, 0.0])  # turned away
    assert hits.any() and not scene.collide(c2, r2).any()


@pytest.mark.parametrize("edit, match", [
    (('type="fixed">', 'type="floating">'), r"joint 'tool-mount' is 'floating'"),
    (('<sphere radius="0.06"/>', '<mesh filename="hand.stl"/>'),
     r"link 'hand': cannot find its collision mesh 'hand.stl'"),
    (('<limit lower="-2" upper="2" effort="1" velocity="1"/>', ''),
     r"joint 'elbow' \(revolute\) needs <limit"),
    (('<child link="tool"/>', '<child link="nowhere"/>'), r"unknown link 'nowhere'"),
])
def test_bad_urdfs_are_refused_naming_what(edit, match):
    text = URDF.read_text().replace(*edit)
    with pytest.raises(CsdfError, match=match):
        Robot.from_urdf(text)


def test_missing_and_malformed_files(tmp_path):
    with pytest.raises(CsdfError, match="no such file"):
        Robot.from_urdf(tmp_path / "none.urdf")
    with pytest.raises(CsdfError, match="not valid XML: .*line 1, column"):
        Robot.from_urdf("<robot name='x'><link name='a'></robot")
