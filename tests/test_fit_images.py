"""Registration from depth images and masks (issue 18): ``csdf.fit_depth``,
``csdf.fit_silhouette`` and ``csdf.track`` on images rendered by csdf's own tracer at
known poses."""

from __future__ import annotations

import numpy as np
import pytest

import csdf
from csdf.errors import CsdfError
from csdf.fit.images import Rays, backproject, ray_minima
from csdf.fit.lie import exp_so3, rotation_angle

W, H, F = 96, 72, 90.0
CAM = csdf.Camera(F, F, (W - 1) / 2, (H - 1) / 2, W, H)
SHAPE = (csdf.box((0.2, 0.1, 0.15)) | csdf.cylinder(0.04, 0.3).translate((0.1, 0, 0))
         | csdf.sphere(0.04).translate((-0.07, 0.05, 0.07)))  # no symmetry


def _view(shape, R, t, params=None):
    """Depth (0 = nothing) and mask of ``shape`` at model-to-camera pose (R, t)."""
    cam = csdf.Camera(F, F, (W - 1) / 2, (H - 1) / 2, W, H, R=R.T, t=-R.T @ t)
    r = csdf.render(shape, cam, params=params)
    return np.where(r.mask, r.depth, 0.0), r.mask


def _pose(rng, z=0.7):
    return exp_so3(rng.normal(size=3)), np.array([0.01, -0.02, z])


def _off(rng, R, t, deg=10.0, mm=10.0):
    w = rng.normal(size=3)
    return csdf.Pose(exp_so3(w / np.linalg.norm(w) * np.radians(deg)) @ R,
                     t + rng.normal(size=3) / np.sqrt(3) * mm * 1e-3)


def test_backprojection_of_a_plane():
    depth = np.full((H, W), 2.0)
    depth[0, 0] = 0.0
    depth[1, 1] = np.nan
    pts, idx = backproject(depth, CAM)
    assert len(pts) == H * W - 2 and np.allclose(pts[:, 2], 2.0)
    u, v = idx % W, idx // W
    np.testing.assert_allclose(pts[:, 0], (u - CAM.cx) / F * 2.0)
    np.testing.assert_allclose(pts[:, 1], (v - CAM.cy) / F * 2.0)
    mask = np.zeros((H, W), bool)
    mask[10:20, 30:40] = True
    assert len(backproject(depth, CAM, mask)[0]) == 100
    with pytest.raises(CsdfError, match=r"depth must have the camera's shape \(72, 96\)"):
        backproject(np.zeros((4, 4)), CAM)
    with pytest.raises(CsdfError, match="mask must be binary"):
        backproject(depth, CAM, np.full((H, W), 0.5))


def test_the_ray_minimum_of_a_sphere_is_its_distance_from_the_centre_less_the_radius():
    prog = csdf.sphere(0.2).compile()
    rng = np.random.default_rng(0)
    d = rng.normal(size=(50, 3)) * [0.3, 0.3, 0.0] + [0, 0, 1]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    C = np.array([0.05, 0.0, 1.0])
    rays = Rays(np.zeros((50, 3)), d, np.tile([0, 0, 1.0], (50, 1)), np.zeros(50),
                np.zeros(50, bool), np.full(50, np.inf))
    X, m = ray_minima(prog, {}, "numpy", np.eye(3), C, 1.0, np.zeros(3), 0.2, rays)
    delta = np.linalg.norm(np.cross(d, C), axis=1)  # the rays' distances from the centre
    np.testing.assert_allclose(m, delta - 0.2, atol=2e-5)  # (3 refinement rounds)
    np.testing.assert_allclose(np.linalg.norm(X - C, axis=1), np.maximum(delta, 0), atol=2e-3)


@pytest.mark.parametrize("silhouette", [False, True])
def test_fit_depth_recovers_the_pose(silhouette):
    rng = np.random.default_rng(1)
    for _ in range(3):
        R, t = _pose(rng)
        depth, mask = _view(SHAPE, R, t)
        depth = np.where(mask, depth + rng.normal(0, 0.001, depth.shape), 0.0)
        res = csdf.fit_depth(SHAPE, depth, CAM, init=_off(rng, R, t), mask=mask,
                             silhouette=silhouette)
        assert res.success
        assert np.degrees(rotation_angle(res.rotation, R)) < 1.0
        assert np.linalg.norm(res.translation - t) < 0.003
        assert ("silhouette_rmse" in res.quality) == silhouette


def test_an_occluder_in_front_does_not_pull_the_silhouette():
    rng = np.random.default_rng(2)
    R, t = _pose(rng)
    depth, mask = _view(SHAPE, R, t)
    cols = np.arange(W) < W // 2 + 4  # a wall in front of the left part of the object
    occluded = mask & cols[None, :]
    depth = np.where(cols[None, :], 0.4, depth)
    visible = mask & ~occluded
    assert 0.2 < occluded.sum() / mask.sum() < 0.8
    res = csdf.fit_depth(SHAPE, depth, CAM, init=_off(rng, R, t, 6, 6), mask=visible)
    assert res.quality["silhouette_rays_used"] < res.quality["silhouette_rays"]
    assert np.degrees(rotation_angle(res.rotation, R)) < 1.5
    assert np.linalg.norm(res.translation - t) < 0.004


def test_fit_silhouette_from_one_and_from_two_views():
    rng = np.random.default_rng(3)
    R, t = _pose(rng)
    _, mask = _view(SHAPE, R, t)
    res = csdf.fit_silhouette(SHAPE, mask, CAM, init=_off(rng, R, t, 10, 10))
    assert res.success and np.degrees(rotation_angle(res.rotation, R)) < 3.0
    # a second camera beside the first, looking at the object: depth is pinned too
    side = csdf.Camera.look_at([0.6, 0.0, 0.35], t, width=W, height=H, fov=60)
    obj = csdf.Pose(R, t)
    m2 = csdf.render(SHAPE, csdf.Camera(side.fx, side.fy, side.cx, side.cy, W, H,
                                        R=R.T @ side.R, t=R.T @ (side.t - t))).mask
    start = _off(rng, R, t, 10, 10)
    two = csdf.fit_silhouette(SHAPE, [mask, m2], [CAM, side], init=start)
    assert np.linalg.norm(two.translation - obj.translation) < 0.006
    assert np.degrees(rotation_angle(two.rotation, R)) < 3.0
    with pytest.raises(CsdfError, match="masks\\[0\\] is empty"):
        csdf.fit_silhouette(SHAPE, np.zeros((H, W), bool), CAM)
    with pytest.raises(CsdfError, match="one camera per mask"):
        csdf.fit_silhouette(SHAPE, [mask, mask], [CAM, CAM, CAM])


def _sequence(shape, n, rng, jump=None, params=None):
    w = rng.normal(size=3)
    w /= np.linalg.norm(w)
    out = []
    for k in range(n):
        R = exp_so3(w * np.radians(2.5) * k) @ exp_so3([0.3, 0.2, 0.1])
        t = np.array([0.04 * np.sin(k / 6), 0.02 * np.cos(k / 5), 0.7])
        if jump is not None and k >= jump:
            R = exp_so3([2.6, 0.0, 0.0]) @ R  # the object is turned over while nobody looks
            t = t + [0.05, 0.0, 0.0]
        depth, mask = _view(shape, R, t, params)
        out.append((np.where(mask, depth + rng.normal(0, 0.001, depth.shape), 0.0), mask,
                    R, t))
    return out


def test_track_follows_a_moving_object_and_reinitialises_when_lost():
    rng = np.random.default_rng(4)
    seq = _sequence(SHAPE, 12, rng, jump=8)
    res = csdf.track(SHAPE, [(d, m) for d, m, _, _ in seq], CAM,
                     csdf.Pose(seq[0][2], seq[0][3]))
    assert len(res) == 12 and res.success.all()
    err = [np.degrees(rotation_angle(f.pose.rotation, R)) for f, (_, _, R, _) in
           zip(res.frames, seq)]
    assert max(err) < 2.0
    assert [f.lost for f in res.frames].index(True) == 8  # the jump is noticed
    assert res[8].reinitialised and not any(f.lost for f in res.frames[9:])
    plain = csdf.track(SHAPE, [d for d, _, _, _ in seq[:8]], CAM,
                       csdf.Pose(seq[0][2], seq[0][3]), reinit=False)
    assert plain.success.all() and not any(f.reinitialised for f in plain.frames)


def test_track_accumulates_shape_parameters():
    width = csdf.param("width", 0.2, 0.1, 0.3)
    shape = csdf.box((width, 0.1, 0.15)) | csdf.sphere(0.05).translate((0, 0, 0.1))
    rng = np.random.default_rng(5)
    seq = _sequence(shape, 10, rng, params={"width": 0.24})
    # the start's width is the default, 0.2: 0.04 off
    res = csdf.track(shape, [(d, m) for d, m, _, _ in seq], CAM,
                     csdf.Pose(seq[0][2], seq[0][3]), estimate=("pose", "params"))
    assert res.success.all()
    assert abs(res[-1].params["width"] - 0.24) < 0.004  # 2 % of the range


def test_a_blank_frame_is_lost_and_tracking_goes_on():
    rng = np.random.default_rng(6)
    seq = _sequence(SHAPE, 6, rng)
    frames = [(d, m) for d, m, _, _ in seq]
    frames[2] = (np.zeros_like(frames[2][0]), np.zeros_like(frames[2][1]))  # all hidden
    res = csdf.track(SHAPE, frames, CAM, csdf.Pose(seq[0][2], seq[0][3]))
    assert res[2].lost and not res[2].success and res[2].result is None
    assert res.success[3:].all()  # the prediction carried it over the gap
    with pytest.raises(CsdfError, match=r"frames\[1\]: the depth must have"):
        csdf.track(SHAPE, [frames[0][0], np.zeros((3, 3))], CAM, csdf.Pose(seq[0][2],
                                                                          seq[0][3]))
    with pytest.raises(CsdfError, match="track: unknown option\\(s\\) bogus"):
        csdf.track(SHAPE, [frames[0][0]], CAM, csdf.Pose(seq[0][2], seq[0][3]), bogus=1)


@pytest.mark.parametrize("option, value, match", [
    ("band", 0, "band must be a finite number of pixels > 0"),
    ("max_iter", 0, "max_iter must be an integer >= 1"),
    ("max_rays", 0, "max_rays must be an integer >= 1"),
    ("seed", -1, "seed must be an integer >= 0"),
    ("silhouette_weight", float("nan"), "silhouette_weight must be a finite number"),
    ("occlusion_margin", -1, "occlusion_margin must be a finite number >= 0"),
    ("gate", -1, "gate must be a finite number >= 0"),
])
def test_bad_options_are_named(option, value, match):
    depth, mask = _view(SHAPE, np.eye(3), np.array([0, 0, 0.7]))
    with pytest.raises(CsdfError, match=match):
        csdf.fit_depth(SHAPE, depth, CAM, init=csdf.Pose(translation=[0, 0, 0.7]),
                       mask=mask, **{option: value})
    with pytest.raises(CsdfError, match="init: the \\(4, 4\\) transform must be finite"):
        csdf.fit_depth(SHAPE, depth, CAM, init=np.full((4, 4), np.nan))
    with pytest.raises(CsdfError, match="one camera per mask"):
        csdf.fit_silhouette(SHAPE, [mask, mask], [CAM])


def _plate_scene(core: float = 0.6):
    """A red 40 x 30 cm plate facing the camera 1 m away before a green wall: the depth
    only in the plate's central ``core`` part (a sensor that loses the edges), the colour
    image everywhere."""
    w, h = 160, 120
    cam = csdf.Camera(200.0, 200.0, (w - 1) / 2, (h - 1) / 2, w, h)
    d = cam.pixel_directions().reshape(h, w, 3)
    zf = 1.0 - 0.01
    x, y = d[..., 0] / d[..., 2] * zf, d[..., 1] / d[..., 2] * zf
    inside = (np.abs(x) < 0.2) & (np.abs(y) < 0.15)
    seen = (np.abs(x) < 0.2 * core) & (np.abs(y) < 0.15 * core)
    rng = np.random.default_rng(0)
    rgb = np.where(inside[..., None], [0.8, 0.2, 0.1], [0.2, 0.7, 0.3])
    rgb = np.clip(rgb + 0.02 * rng.standard_normal((h, w, 3)), 0, 1)
    return csdf.box((0.4, 0.3, 0.02)), cam, np.where(seen, zf, 0.0), rgb


def test_the_colour_term_finds_what_the_depth_cannot():
    plate, cam, depth, rgb = _plate_scene()
    truth = np.array([0.0, 0.0, 1.0])
    start = csdf.Pose(translation=truth + [0.025, -0.02, 0.0])
    alone = csdf.fit_depth(plate, depth, cam, init=start)
    # the depth points all lie on the plate's face: sliding it sideways costs nothing
    assert np.linalg.norm(alone.translation[:2] - truth[:2]) > 0.02
    both = csdf.fit_depth(plate, depth, cam, init=start, color=rgb)
    # with the colours the plate's outline lands on the red patch: within a pixel
    # (5 mm at 1 m)
    assert np.linalg.norm(both.translation - truth) < 0.004
    assert both.quality["color_rays"] == 300 and both.quality["color_rays_used"] > 250
    eight = csdf.fit_depth(plate, depth, cam, init=start,
                           color=np.rint(rgb * 255).astype(np.uint8))
    assert np.linalg.norm(eight.translation - truth) < 0.004
    for bad, match in [(rgb[:, :, :2], "RGB image of the camera's shape"),
                       (rgb * 2, r"RGB values in \[0, 1\]")]:
        with pytest.raises(CsdfError, match=match):
            csdf.fit_depth(plate, depth, cam, init=start, color=bad)
    with pytest.raises(CsdfError, match="color_weight must be a finite number"):
        csdf.fit_depth(plate, depth, cam, init=start, color=rgb, color_weight=-1)


def test_track_with_colour_images():
    shape = SHAPE.color((0.85, 0.3, 0.1))
    seq = csdf.synth.sequence(shape, n_frames=8, width=160, height=120, seed=3,
                              colors=True)
    res = csdf.track(shape, seq.depth, seq.camera, seq.poses[0], colors=seq.colors)
    assert res.success.all()
    assert all(f.result.quality["color_rays_used"] > 50 for f in res.frames)
    err = [np.linalg.norm(f.pose.translation - p.translation)
           for f, p in zip(res.frames, seq.poses)]
    assert max(err) < 0.005
    with pytest.raises(CsdfError, match="colors has 2 images but frames has more"):
        csdf.track(shape, seq.depth[:3], seq.camera, seq.poses[0], colors=seq.colors[:2])


def test_a_track_whose_prediction_sees_no_points_is_lost_not_ended():
    rng = np.random.default_rng(7)
    seq = _sequence(SHAPE, 6, rng)
    frames = [d for d, _, _, _ in seq]
    # frame 3: the object half a metre behind the prediction (no depth point within
    # the gate of 10 % of its size), then back
    R, t = seq[3][2], seq[3][3] + [0.0, 0.0, 0.5]
    depth, mask = _view(SHAPE, R, t)
    frames[3] = depth
    start = csdf.Pose(seq[0][2], seq[0][3])
    res = csdf.track(SHAPE, frames, CAM, start)
    assert res[3].lost and res[3].reinitialised
    assert np.linalg.norm(res[3].pose.translation - t) < 0.01  # found where it went
    plain = csdf.track(SHAPE, frames, CAM, start, reinit=False)
    assert plain[3].lost and plain[3].result is None and not plain[3].reinitialised
    assert plain.success[:3].all()
