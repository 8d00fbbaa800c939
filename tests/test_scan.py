"""The synthetic depth sensor: only visible surface points, camera-frame output, normals
facing the sensor, the requested noise and outliers, seeded repeatability, object poses
and clear errors."""

from __future__ import annotations

import numpy as np
import pytest

import csdf
from csdf.render import Camera, render
from csdf.scan import scan

W, H = 80, 60


def csg_example() -> csdf.Shape:
    c = csdf.cylinder(0.5, 3.0)
    return (csdf.sphere(1.0) & csdf.box(1.5)) - c - c.orient("x") - c.orient("y")


def rigid(angle: float, axis, t) -> np.ndarray:
    """``(4, 4)`` rotation by ``angle`` radians about ``axis``, then translation ``t``."""
    a = np.asarray(axis, dtype=float)
    a /= np.linalg.norm(a)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    T = np.eye(4)
    T[:3, :3] = np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K
    T[:3, 3] = t
    return T


POSE = rigid(0.5, (0.3, -0.2, 1.0), (0.4, -0.3, 0.2))
CAM = Camera.look_at((2.4, -2.8, 1.6), (0.4, -0.3, 0.2), fov=40.0, width=W, height=H)


def to_object(points_cam: np.ndarray, cam: Camera, pose: np.ndarray) -> np.ndarray:
    """Camera-frame points ``(N, 3)`` to the object's frame."""
    world = cam.camera_to_world(points_cam)
    return (world - pose[:3, 3]) @ pose[:3, :3]


@pytest.fixture(scope="module")
def clean():
    shape = csg_example()
    pts, nrm = scan(shape, CAM, object_pose=POSE)
    return shape, pts, nrm


def test_points_are_visible_surface_points_in_the_camera_frame(clean):
    shape, pts, nrm = clean
    assert pts.shape == nrm.shape and pts.shape[1] == 3 and len(pts) > 500
    scale = float(np.linalg.norm(np.ptp(shape.bounds, axis=0)))
    obj = to_object(pts, CAM, POSE)
    np.testing.assert_allclose(shape(obj), 0.0, atol=1e-8 * scale)  # on the surface
    # in front of the camera and inside its image
    uv, z = CAM.project(CAM.camera_to_world(pts))
    assert np.all(z > 0)
    np.testing.assert_allclose(pts[:, 2], z, atol=1e-12)
    assert np.all((uv > -0.5) & (uv < [W - 0.5, H - 0.5]))
    # the segment from the camera to the point stays outside the shape (no occluder)
    cam_obj = to_object(np.zeros((1, 3)), CAM, POSE)[0]
    s = np.linspace(0.0, 1.0, 400)[:-1]  # up to 1/400 of the way before the point
    seg = cam_obj + s[None, :, None] * (obj - cam_obj)[:, None, :]
    assert np.all(shape(seg.reshape(-1, 3)) > 0)
    # unit normals facing the sensor, not grazing, equal to the field's gradient
    np.testing.assert_allclose(np.linalg.norm(nrm, axis=1), 1.0, atol=1e-12)
    view = -pts / np.linalg.norm(pts, axis=1, keepdims=True)
    assert np.all((nrm * view).sum(1) >= 0.05)
    h = 1e-6  # central differences of the field, in the camera frame
    to_obj = POSE[:3, :3].T @ CAM.R
    g = np.stack([(shape(obj + h * e) - shape(obj - h * e)) / (2 * h) for e in to_obj.T], 1)
    g /= np.linalg.norm(g, axis=1, keepdims=True)
    cos = (g * nrm).sum(1)
    assert np.quantile(cos, 0.95) > 1 - 1e-8  # smooth points: the same direction
    assert np.quantile(cos, 0.01) > 0.5  # at creases: close to one side's normal


def test_self_occlusion_and_grazing_returns_are_dropped(clean):
    shape, pts, _ = clean
    # the rendered silhouette has more pixels than the scan: grazing returns are dropped
    r = render(shape, Camera(CAM.fx, CAM.fy, CAM.cx, CAM.cy, W, H,
                                  R=POSE[:3, :3].T @ CAM.R,
                                  t=POSE[:3, :3].T @ (CAM.t - POSE[:3, 3])))
    assert len(pts) < r.mask.sum()
    assert len(pts) >= 0.9 * r.mask.sum()
    # only first hits: each point's depth is the rendered depth of its pixel
    uv, z = CAM.project(CAM.camera_to_world(pts))
    u, v = np.round(uv).astype(int).T
    np.testing.assert_allclose(uv, np.stack([u, v], 1), atol=1e-9)  # pixel centres
    np.testing.assert_allclose(z, r.depth[v, u], atol=1e-8)


def test_object_pose_moves_the_cloud():
    shape = csg_example()
    moved, n_moved = scan(shape, CAM, object_pose=POSE)
    # the same view from the object's point of view: identity pose, camera moved by the
    # inverse pose -> the same camera-frame cloud
    inv = np.linalg.inv(POSE)
    cam2 = Camera(CAM.fx, CAM.fy, CAM.cx, CAM.cy, W, H, R=inv[:3, :3] @ CAM.R,
                  t=inv[:3, :3] @ CAM.t + inv[:3, 3])
    same, n_same = scan(shape, cam2)
    assert same.shape == moved.shape
    np.testing.assert_allclose(same, moved, atol=1e-9)
    np.testing.assert_allclose(n_same, n_moved, atol=1e-9)
    # without the pose the sensor sees something else
    plain, _ = scan(shape, CAM)
    assert plain.shape != moved.shape or not np.allclose(plain, moved)
    # a pure translation towards the camera brings every point closer along its ray
    axis = CAM.R[:, 2]
    pts0, _ = scan(shape, CAM, object_pose=rigid(0.0, (0, 0, 1), (0.0, 0.0, 0.0)))
    pts1, _ = scan(shape, CAM, object_pose=rigid(0.0, (0, 0, 1), -0.3 * axis))
    assert np.median(pts1[:, 2]) == pytest.approx(np.median(pts0[:, 2]) - 0.3, abs=0.05)


def test_range_noise_has_the_requested_std():
    shape = csg_example()
    sigma = 0.004
    p0, n0 = scan(shape, CAM, object_pose=POSE)
    p1, n1 = scan(shape, CAM, object_pose=POSE, noise=sigma, seed=3)
    assert p1.shape == p0.shape
    np.testing.assert_array_equal(n1, n0)
    r0, r1 = np.linalg.norm(p0, axis=1), np.linalg.norm(p1, axis=1)
    # along the ray: the noisy point is on the clean point's ray
    np.testing.assert_allclose(p1 / r1[:, None], p0 / r0[:, None], atol=1e-12)
    e = r1 - r0
    m = len(e)
    assert abs(e.mean()) <= 4 * sigma / np.sqrt(m)
    assert abs(e.std() / sigma - 1) <= 4 / np.sqrt(2 * m)


@pytest.mark.parametrize("frac", [0.05, 0.3])
def test_outlier_fraction_and_placement(frac):
    shape = csg_example()
    clean, _ = scan(shape, CAM, object_pose=POSE)
    pts, nrm = scan(shape, CAM, object_pose=POSE, outliers=frac, seed=11)
    m = len(pts)
    assert m == len(clean)
    f = shape(to_object(pts, CAM, POSE))
    out = np.abs(f) > 1e-6
    sd = np.sqrt(m * frac * (1 - frac))
    assert abs(out.sum() - frac * m) <= 3.5 * sd
    assert np.array_equal(pts[~out], clean[~out])  # the others are untouched
    # outliers are in the view frustum, within the depth range of the scene
    uv, z = CAM.project(CAM.camera_to_world(pts[out]))
    assert np.all((uv >= -0.5) & (uv <= [W - 0.5, H - 0.5]))
    assert np.all((z >= clean[:, 2].min()) & (z <= clean[:, 2].max()))
    np.testing.assert_allclose(np.linalg.norm(nrm, axis=1), 1.0, atol=1e-12)
    assert np.all((nrm[out] * -pts[out]).sum(1) >= 0)  # facing the camera too


def test_seeded_runs_repeat_exactly():
    shape = csg_example()
    kw = dict(noise=0.002, outliers=0.1, object_pose=POSE)
    a = scan(shape, CAM, seed=42, **kw)
    b = scan(shape, CAM, seed=42, **kw)
    c = scan(shape, CAM, seed=43, **kw)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])
    assert not np.array_equal(a[0], c[0])


def test_resolution_params_and_empty_views():
    r = csdf.param("r", 1.0, 0.8, 1.2)
    shape = csdf.sphere(r)
    cam = Camera.look_at((0, -4, 0), (0, 0, 0), fov=40.0, width=640, height=480)
    pts, _ = scan(shape, cam, 64, 48)
    big, _ = scan(shape, cam, 64, 48, params={"r": 1.2})
    assert len(big) > len(pts)
    np.testing.assert_allclose(np.linalg.norm(big - [0, 0, 4], axis=1), 1.2, atol=1e-8)
    away = Camera.look_at((0, -4, 0), (0, -8, 0), width=32, height=24)
    p, n = scan(shape, away, outliers=0.5, noise=0.1, seed=0)
    assert p.shape == (0, 3) and n.shape == (0, 3)


@pytest.mark.parametrize(
    "kw, match",
    [(dict(noise=-0.1), "noise"), (dict(noise=np.nan), "noise"),
     (dict(outliers=1.5), "outliers"), (dict(outliers=-0.1), "outliers"),
     (dict(width=0), "width"), (dict(width=8192, height=8192), "over the limit"),
     (dict(object_pose=np.eye(3)), "shape"), (dict(object_pose=2 * np.eye(4)), "rigid|row"),
     (dict(object_pose=np.diag([2.0, 1.0, 1.0, 1.0])), "rigid"),
     (dict(object_pose=np.full((4, 4), np.inf)), "finite")],
)
def test_bad_input_raises(kw, match):
    with pytest.raises(csdf.CsdfError, match=match):
        scan(csdf.sphere(1.0), CAM, **kw)
