"""Synthetic depth sequences (``csdf.synth.sequence``): seeded repeatability, a smooth
path that keeps the object in view, masks equal to an independent render at the
ground-truth poses, range noise that grows as the documented model says, grazing
dropouts, outliers, an occluder covering the requested fraction at its peak, and clear
errors."""

from __future__ import annotations

import math

import numpy as np
import pytest

import csdf
from csdf.render import Camera, render
from csdf.synth import MAX_SEQUENCE_PIXELS, Sequence, noise_sigma, sequence

W, H = 80, 60
#: a box with a bump: not symmetric, and its bounding-box centre is not its origin
SHAPE = csdf.box((0.3, 0.2, 0.15)) | csdf.sphere(0.08).translate((0.15, 0.0, 0.075))
QUIET = {"noise_quad": 0.0, "outliers": 0.0, "min_cos": 0.0}


def angle(Ra: np.ndarray, Rb: np.ndarray) -> float:
    """The rotation angle of ``Ra^T Rb``, radians (accurate for small angles too)."""
    D = Ra.T @ Rb
    s = 0.5 * np.linalg.norm([D[2, 1] - D[1, 2], D[0, 2] - D[2, 0], D[1, 0] - D[0, 1]])
    return math.atan2(s, 0.5 * (np.trace(D) - 1.0))


def rotvec(D: np.ndarray) -> np.ndarray:
    """The rotation vector of a rotation ``D`` (angle below pi)."""
    v = np.array([D[2, 1] - D[1, 2], D[0, 2] - D[2, 0], D[1, 0] - D[0, 1]])
    th = angle(np.eye(3), D)
    return v * (0.5 * th / math.sin(th)) if th > 1e-12 else 0.5 * v


def reference(seq: Sequence, k: int):
    """csdf.render of the shape alone, at frame ``k``'s ground-truth pose: the camera
    placed in the object's frame (``pose^-1``)."""
    P = seq.poses[k]
    c = seq.camera
    cam = Camera(c.fx, c.fy, c.cx, c.cy, c.width, c.height, R=P.rotation.T,
                 t=-P.rotation.T @ P.translation)
    return render(SHAPE, cam)


@pytest.fixture(scope="module")
def occluded() -> Sequence:
    return sequence(SHAPE, n_frames=9, width=W, height=H, seed=7, occlusion=0.3)


def test_sequence_fields_and_types(occluded):
    seq = occluded
    assert len(seq) == 9 and seq.shape == (9, H, W)
    assert seq.depth.dtype == np.float64 and seq.depth.shape == (9, H, W)
    for a in (seq.masks, seq.occluder_masks, seq.silhouettes):
        assert a.dtype == bool and a.shape == (9, H, W)
    assert all(isinstance(p, csdf.Pose) and p.scale == 1.0 for p in seq.poses)
    assert isinstance(seq.camera, Camera) and (seq.camera.width, seq.camera.height) == (W, H)
    assert seq.visib_fract.shape == (9,)
    assert np.all(seq.depth >= 0) and np.all(np.isfinite(seq.depth))
    # the masks of the object and of the occluder are disjoint parts of the silhouette
    assert not np.any(seq.masks & seq.occluder_masks)
    assert np.all(seq.silhouettes | ~seq.masks)
    np.testing.assert_allclose(seq.visib_fract,
                               seq.masks.sum((1, 2)) / seq.silhouettes.sum((1, 2)))


def test_same_seed_same_sequence_and_other_seeds_differ(occluded):
    again = sequence(SHAPE, n_frames=9, width=W, height=H, seed=7, occlusion=0.3)
    assert np.array_equal(again.depth, occluded.depth)
    assert np.array_equal(again.masks, occluded.masks)
    assert np.array_equal(again.occluder_masks, occluded.occluder_masks)
    assert all(a == b for a, b in zip(again.poses, occluded.poses))
    other = sequence(SHAPE, n_frames=9, width=W, height=H, seed=8, occlusion=0.3)
    assert not other.poses[0].allclose(occluded.poses[0], atol=1e-3)
    assert not np.array_equal(other.depth, occluded.depth)
    # a Generator works as a seed too
    g = sequence(SHAPE, n_frames=2, width=W, height=H, seed=np.random.default_rng(7))
    h = sequence(SHAPE, n_frames=2, width=W, height=H, seed=np.random.default_rng(7))
    assert np.array_equal(g.depth, h.depth)


def test_path_is_smooth_bounded_and_in_view():
    n, rot, step = 40, 4.0, 0.006
    seq = sequence(SHAPE, n_frames=n, width=W, height=H, seed=3, max_rotation=rot,
                   max_translation=step, **QUIET)
    R = np.array([p.rotation for p in seq.poses])
    centre_obj = 0.5 * (np.asarray(SHAPE.bounds)[0] + np.asarray(SHAPE.bounds)[1])
    centres = np.array([p.apply(centre_obj) for p in seq.poses])
    angles = np.degrees([angle(R[k], R[k + 1]) for k in range(n - 1)])
    assert angles.max() <= rot * (1 + 1e-9)
    assert angles.mean() > 0.25 * rot  # it does move
    steps = np.linalg.norm(np.diff(centres, axis=0), axis=1)
    assert steps.max() <= step * (1 + 1e-9)
    assert steps.max() > 0.5 * step
    # smooth: the per-frame motion itself changes slowly
    w = np.degrees([rotvec(R[k].T @ R[k + 1]) for k in range(n - 1)])
    assert np.linalg.norm(np.diff(w, axis=0), axis=1).max() <= 0.35 * rot
    assert np.linalg.norm(np.diff(centres, n=2, axis=0), axis=1).max() <= 0.35 * step
    # always in view: every frame sees the object, never touching the image border
    assert np.all(seq.silhouettes.sum((1, 2)) > 20)
    border = np.zeros((H, W), dtype=bool)
    border[[0, -1], :] = border[:, [0, -1]] = True
    assert not np.any(seq.silhouettes & border)
    # the default speeds are a 30 fps tracker's: a few degrees, a few mm per frame
    fast = sequence(SHAPE, n_frames=12, width=W, height=H, seed=5, **QUIET)
    Rf = [p.rotation for p in fast.poses]
    assert max(np.degrees(angle(Rf[k], Rf[k + 1])) for k in range(11)) <= 3.0 * (1 + 1e-9)


def test_masks_and_depth_match_an_independent_render(occluded):
    seq = occluded
    mismatched = 0
    for k in range(len(seq)):
        ref = reference(seq, k)
        want = ref.mask & ~seq.occluder_masks[k]
        mismatched += int(np.sum(want != seq.masks[k]))
        np.testing.assert_array_equal(ref.mask, seq.silhouettes[k])
    assert mismatched == 0
    # without noise, outliers and dropouts the depth is the render's on the object and
    # nearer than it where the occluder covers it
    clean = sequence(SHAPE, n_frames=9, width=W, height=H, seed=7, occlusion=0.3, **QUIET)
    for k in range(len(clean)):
        ref = reference(clean, k)
        m = clean.masks[k]
        np.testing.assert_allclose(clean.depth[k][m], ref.depth[m], rtol=1e-9)
        covered = ref.mask & clean.occluder_masks[k]
        assert np.all(clean.depth[k][covered] < ref.depth[covered])
        assert np.all(clean.depth[k][~(m | clean.occluder_masks[k])] == 0)


def test_noise_grows_with_range_as_documented():
    # the path does not depend on the sensor options: a clean twin gives the truth
    stats = []
    for dist in (0.9, 2.7):
        opts = dict(n_frames=6, width=W, height=H, seed=11, distance=dist)
        noisy = sequence(SHAPE, noise_quad=2e-3, noise_base=1e-4, outliers=0.0, min_cos=0.0,
                         **opts)
        clean = sequence(SHAPE, **QUIET, **opts)
        both = (noisy.depth > 0) & (clean.depth > 0)
        z = clean.depth[both]
        r = noisy.depth[both] - z
        assert r.size > 150
        stats.append((np.std(r), np.std(r / noise_sigma(z, 1e-4, 2e-3)), abs(np.mean(r))))
    (near, near_unit, near_bias), (far, far_unit, far_bias) = stats
    # quadratic: three times the range, about nine times the noise (2e-3 z^2 + 1e-4)
    assert 6.0 < far / near < 12.0
    for unit in (near_unit, far_unit):
        assert 0.85 < unit < 1.15
    assert near_bias < 0.3 * near and far_bias < 0.3 * far


def test_grazing_dropouts_and_outliers():
    opts = dict(n_frames=4, width=W, height=H, seed=2, noise_quad=0.0)
    graze = sequence(SHAPE, outliers=0.0, min_cos=0.4, **opts)
    dropped = kept = 0
    for k in range(len(graze)):
        ref = reference(graze, k)
        c = graze.camera
        cam = Camera(c.fx, c.fy, c.cx, c.cy, W, H)
        d = cam.pixel_directions().reshape(H, W, 3) @ graze.poses[k].rotation
        cos = np.abs(np.einsum("hwi,hwi->hw", ref.normals, d))
        m = graze.masks[k]
        low = m & (cos < 0.4 - 1e-6)
        high = m & (cos > 0.4 + 1e-6)
        assert np.all(graze.depth[k][low] == 0)
        assert np.all(graze.depth[k][high] > 0)
        dropped += int(low.sum())
        kept += int(high.sum())
    assert dropped > 0 and kept > dropped

    clean = sequence(SHAPE, outliers=0.0, min_cos=0.0, **opts)
    wild = sequence(SHAPE, outliers=0.2, min_cos=0.0, **opts)
    changed = (wild.depth != clean.depth) & clean.masks
    frac = changed.sum() / clean.masks.sum()
    assert 0.12 < frac < 0.28
    for k in range(len(clean)):
        z = clean.depth[k][clean.depth[k] > 0]
        out = wild.depth[k][changed[k]]
        assert np.all((out >= z.min()) & (out <= z.max()))


@pytest.mark.parametrize("target", [0.3, 0.6])
def test_occluder_covers_the_requested_fraction_at_its_peak(occluded, target):
    seq = occluded if target == 0.3 else sequence(SHAPE, n_frames=9, width=W, height=H,
                                                  seed=7, occlusion=target)
    covered = 1.0 - seq.visib_fract
    assert abs(covered.max() - target) < 0.06
    peak = int(np.argmax(covered))
    assert 2 <= peak <= 6  # during the middle of the sequence
    assert covered[0] == 0.0 and covered[-1] == 0.0
    assert seq.occluder_masks[peak].sum() > 0
    none = sequence(SHAPE, n_frames=3, width=W, height=H, seed=7)
    assert not none.occluder_masks.any() and np.all(none.visib_fract == 1.0)
    np.testing.assert_array_equal(none.masks, none.silhouettes)


def test_default_and_given_cameras():
    seq = sequence(SHAPE, n_frames=1, seed=0, **QUIET)
    assert (seq.camera.width, seq.camera.height) == (320, 240)
    np.testing.assert_allclose(seq.camera.K, [[262.5, 0, 159.5], [0, 262.5, 119.5],
                                              [0, 0, 1]])
    cam = Camera(100.0, 110.0, 41.0, 28.0, 80, 60)
    given = sequence(SHAPE, n_frames=1, camera=cam, seed=0, **QUIET)
    np.testing.assert_array_equal(given.camera.K, cam.K)
    half = sequence(SHAPE, n_frames=1, camera=cam, width=40, height=30, seed=0, **QUIET)
    assert half.depth.shape == (1, 30, 40)


def test_clear_errors():
    def bad(match: str, *args, **kwargs):
        with pytest.raises(csdf.CsdfError, match=match):
            sequence(*args, **kwargs)

    bad("over the limit", SHAPE, n_frames=2, width=10000, height=60)
    bad("over the limit of", SHAPE, n_frames=MAX_SEQUENCE_PIXELS // (W * H) + 1,
        width=W, height=H)
    bad("n_frames", SHAPE, n_frames=0)
    bad("n_frames", SHAPE, n_frames=2.5)
    bad("occlusion", SHAPE, n_frames=2, width=W, height=H, occlusion=1.5)
    bad("noise_quad", SHAPE, n_frames=2, width=W, height=H, noise_quad=-1.0)
    bad("outliers", SHAPE, n_frames=2, width=W, height=H, outliers=float("nan"))
    bad("max_rotation", SHAPE, n_frames=2, width=W, height=H, max_rotation=-1)
    bad("does not fit", SHAPE, n_frames=2, width=W, height=H, distance=0.2)
    bad("camera must be", SHAPE, n_frames=2, camera="kinect")
    bad("3D shape", csdf.circle(1.0), n_frames=2, width=W, height=H)


def test_colour_images_show_the_object_in_its_colours_and_leave_the_depth_alone():
    red = (0.9, 0.1, 0.1)
    shape = SHAPE.color(red)
    seq = sequence(shape, n_frames=3, width=W, height=H, seed=7, occlusion=0.3,
                   colors=True, color_noise=0.0)
    plain = sequence(shape, n_frames=3, width=W, height=H, seed=7, occlusion=0.3)
    np.testing.assert_array_equal(seq.depth, plain.depth)  # the same sensor draws
    assert plain.colors is None
    assert seq.colors.shape == (3, H, W, 3) and seq.colors.dtype == np.float32
    assert seq.colors.min() >= 0 and seq.colors.max() <= 1
    obj = seq.colors[seq.masks]
    # Lambert shading of red: every object pixel is red times a factor in [0.35, 1]
    factor = obj[:, 0] / red[0]
    assert factor.min() >= 0.35 - 1e-6 and factor.max() <= 1 + 1e-6
    np.testing.assert_allclose(obj[:, 1] / red[1], factor, rtol=1e-5)
    occ = seq.colors[seq.occluder_masks]
    assert len(occ) and not np.allclose(occ[:, 1] / np.maximum(occ[:, 0], 1e-9), 1 / 9)
    back = seq.colors[~(seq.masks | seq.occluder_masks)]
    assert back.std(axis=0).max() < 0.3 and len(back) > 0.5 * back.size / 3
    again = sequence(shape, n_frames=3, width=W, height=H, seed=7, occlusion=0.3,
                     colors=True)
    noisy = again.colors - seq.colors
    assert 0.01 < float(noisy[~(seq.masks | seq.occluder_masks)].std()) < 0.03
    with pytest.raises(csdf.CsdfError, match="color_noise"):
        sequence(shape, n_frames=3, width=W, height=H, colors=True, color_noise=-1)
