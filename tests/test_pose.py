"""csdf.Pose: a similarity transform p = s R q + t."""

from __future__ import annotations

import numpy as np
import pytest

import csdf
from csdf import Pose


def _random_pose(rng, scale=True):
    w = rng.normal(size=3)
    return Pose.from_rotvec(w, rng.normal(size=3), float(np.exp(rng.normal())) if scale else 1.0)


def test_matrix_round_trip_and_apply():
    rng = np.random.default_rng(0)
    for _ in range(20):
        a = _random_pose(rng)
        T = a.matrix
        assert T.shape == (4, 4) and np.allclose(T[3], [0, 0, 0, 1])
        b = Pose.from_matrix(T)
        assert b.allclose(a, atol=1e-12)
        q = rng.normal(size=(5, 3))
        ph = np.c_[q, np.ones(5)] @ T.T
        np.testing.assert_allclose(a.apply(q), ph[:, :3], atol=1e-12)


def test_compose_and_inverse():
    rng = np.random.default_rng(1)
    q = rng.normal(size=(7, 3))
    for _ in range(20):
        a, b = _random_pose(rng), _random_pose(rng)
        np.testing.assert_allclose((a @ b).apply(q), a.apply(b.apply(q)), atol=1e-10)
        np.testing.assert_allclose((a @ b).matrix, a.matrix @ b.matrix, atol=1e-10)
        assert (a.inverse() @ a).allclose(Pose(), atol=1e-10)
        np.testing.assert_allclose(a.apply_inverse(a.apply(q)), q, atol=1e-10)
        assert a.inverse().allclose(Pose.from_matrix(np.linalg.inv(a.matrix)), atol=1e-10)


def test_directions_ignore_translation_and_scale():
    a = Pose.from_rotvec([0, 0, np.pi / 2], [5, 6, 7], 3.0)
    np.testing.assert_allclose(a.apply_dirs([1.0, 0, 0]), [0, 1, 0], atol=1e-15)
    np.testing.assert_allclose(a.apply_inverse_dirs([0, 1.0, 0]), [1, 0, 0], atol=1e-15)


def test_apply_box_holds_the_mapped_corners():
    rng = np.random.default_rng(2)
    a = _random_pose(rng)
    box = np.array([[-1.0, -2.0, -0.5], [1.0, 0.5, 3.0]])
    wb = a.apply_box(box)
    q = rng.uniform(box[0], box[1], (1000, 3))
    p = a.apply(q)
    assert np.all(p >= wb[0] - 1e-12) and np.all(p <= wb[1] + 1e-12)


@pytest.mark.parametrize("bad, match", [
    (np.eye(3), "shape"),
    (np.full((4, 4), np.nan), "finite"),
    (np.diag([1.0, 1.0, -1.0, 1.0]), "positive determinant"),
    (np.diag([1.0, 2.0, 1.0, 1.0]), "similarity"),
    (np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 1, 1.0]]), "last row"),
    ("not a matrix", "transform"),
])
def test_bad_matrices_are_refused(bad, match):
    with pytest.raises(csdf.CsdfError, match=match):
        Pose.from_matrix(bad)


def test_rigid_refuses_a_scale():
    with pytest.raises(csdf.CsdfError, match="rigid"):
        Pose.from_matrix(np.diag([2.0, 2.0, 2.0, 1.0]), "object_pose", rigid=True)
    with pytest.raises(csdf.CsdfError, match="scale"):
        Pose(scale=0.0)
    with pytest.raises(csdf.CsdfError, match="rotation"):
        Pose(rotation=np.ones((3, 3)))


def test_nearest_projects_a_noisy_matrix():
    a = Pose.from_rotvec([0.3, -0.2, 0.1], [1, 2, 3], 1.5)
    noisy = a.matrix + 1e-4 * np.random.default_rng(3).normal(size=(4, 4))
    b = Pose.nearest(noisy)
    assert b.allclose(a, atol=1e-3)


def test_immutable_and_hashable():
    a = Pose.from_rotvec([0.1, 0.2, 0.3])
    with pytest.raises(AttributeError):
        a.scale = 2.0
    with pytest.raises(ValueError):
        a.translation[0] = 1.0
    b = Pose.from_rotvec([0.1, 0.2, 0.3])
    assert a == b and len({a, b}) == 1


def test_fit_result_pose_matches_its_transform():
    shape = csdf.box((0.4, 0.3, 0.2))
    truth = Pose.from_rotvec([0.2, -0.1, 0.3], [0.05, -0.02, 0.1])
    pts, _ = csdf.sample_surface(shape, 2000, seed=0)
    res = csdf.fit(shape, truth.apply(pts), init=Pose.from_rotvec([0.15, -0.05, 0.25],
                                                                   [0.04, 0, 0.09]))
    assert isinstance(res.pose, Pose)
    np.testing.assert_allclose(res.pose.matrix, res.transform, atol=1e-12)
    assert res.pose.allclose(truth, atol=1e-4)


def test_exact_identity_test_agrees_with_the_tolerant_one():
    """``is_identity()`` (exact: compared without temporaries) answers as the general
    test with ``tol`` 0 does, signed zeros and one-ulp changes included."""

    def general(p: Pose) -> bool:
        return bool(np.max(np.abs(p.rotation - np.eye(3))) <= 0.0
                    and np.max(np.abs(p.translation)) <= 0.0 and abs(p.scale - 1.0) <= 0.0)

    tiny = np.nextafter(0.0, 1.0)
    poses = [Pose(), Pose(np.eye(3), [-0.0, 0.0, -0.0]), Pose(np.eye(3), [0.0, tiny, 0.0]),
             Pose(None, None, np.nextafter(1.0, 2.0)), Pose.from_rotvec([0.0, 0.0, 1e-12]),
             Pose.from_rotvec([0.1, 0.2, 0.3], [1.0, 2.0, 3.0], 1.5),
             Pose.from_rotvec([0.0, 0.0, np.pi])]
    for p in poses:
        assert p.is_identity() == general(p)
    assert [p.is_identity() for p in poses[:4]] == [True, True, False, False]
