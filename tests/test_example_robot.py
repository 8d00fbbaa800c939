"""``csdf.plan.example_robot``: robots of the example-robot-data package (the
``bench-plan`` extra). Runs only where that package is installed; CI does not install
it (the planning benchmark does)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("yourdfpy")
from csdf.errors import CsdfError  # noqa: E402
from csdf.plan import example_robot, example_robot_files  # noqa: E402

try:
    example_robot_files("panda")
except CsdfError:
    pytest.skip("example-robot-data is not installed", allow_module_level=True)


def test_the_panda_collision_model():
    panda = example_robot("panda", lock={"panda_finger_joint1": 0.04})
    assert panda.dof == 7 and panda.joint_names[0] == "panda_joint1"
    assert len(panda.primitives) == 39  # 13 capsules, each a cylinder and two spheres
    assert ("panda_hand", "panda_link5") in panda.ignore
    # the SRDF's "default" position is clear of itself
    q = np.array([0, -0.785398, 0, -2.35619, 0, 1.5707, 0.785398])
    assert panda.self_clearance(q[None])[0] > 0
    hand = panda.fk(q)["panda_hand"][:3, 3]
    assert 0.2 < hand[0] < 0.5 and 0.3 < hand[2] < 0.8  # in front of the base, above it


def test_an_unknown_robot_is_named():
    with pytest.raises(CsdfError, match="no robot 'robbie' .*panda"):
        example_robot("robbie")


def test_the_panda_mesh_model_as_spheres():
    panda = example_robot("panda", lock={"panda_finger_joint1": 0.04}, meshes=True,
                          mesh_spacing=0.1)
    assert panda.dof == 7 and all(p.kind in ("sphere", "box") for p in panda.primitives)
    capsules = example_robot("panda", lock={"panda_finger_joint1": 0.04})
    q = np.array([0, -0.785398, 0, -2.35619, 0, 1.5707, 0.785398])
    for link in ("panda_link4", "panda_hand"):  # the same kinematics
        np.testing.assert_allclose(panda.fk(q)[link], capsules.fk(q)[link], atol=1e-12)
    c, r, _ = panda.spheres(q)
    assert 50 < len(r) < 600
