"""csdf.metrics: the BOP 2019 pose errors (shared/specs/bop-metrics.md) against hand-worked
cases and against plain re-derivations."""

from __future__ import annotations

import math

import numpy as np
import pytest

import csdf
from csdf import metrics
from csdf.errors import CsdfError

A, B, C = 0.05, 0.03, 0.02  # half sizes of the test box (metres)
CORNERS = np.array([[sx * A, sy * B, sz * C]
                    for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])


def _rot(axis: str, angle: float) -> np.ndarray:
    v = {"x": (1.0, 0, 0), "y": (0, 1.0, 0), "z": (0, 0, 1.0)}[axis]
    return csdf.Pose.from_rotvec(np.array(v) * angle).rotation


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


@pytest.fixture(scope="module")
def box():
    return csdf.box((2 * A, 2 * B, 2 * C))


@pytest.fixture(scope="module")
def box_syms(box):
    return metrics.symmetries(box)


# ---------------------------------------------------------------- model points, diameter
def test_diameter_is_the_largest_pairwise_distance():
    assert metrics.diameter(CORNERS) == pytest.approx(2 * math.sqrt(A * A + B * B + C * C),
                                                      abs=1e-15)
    rng = np.random.default_rng(1)
    for p in (rng.normal(size=(300, 3)),
              np.c_[rng.normal(size=(50, 2)), np.zeros(50)],   # flat
              np.outer(rng.normal(size=40), [1.0, 2.0, 3.0]),  # on a line
              rng.normal(size=(1, 3))):
        brute = np.sqrt(((p[:, None] - p[None]) ** 2).sum(-1)).max()
        assert metrics.diameter(p) == pytest.approx(brute, abs=1e-12)


def test_model_points_are_mesh_vertices_with_the_corners(box):
    v = metrics.model_points(box)
    f = csdf.compile(box)(v)
    assert np.abs(f).max() < 1e-9
    assert metrics.diameter(v) == pytest.approx(metrics.diameter(CORNERS), abs=1e-12)
    sub = metrics.model_points(box, n=50)
    assert sub.shape == (50, 3)
    assert np.array_equal(sub, metrics.model_points(box, n=50))  # deterministic
    assert metrics.diameter(sub) == pytest.approx(metrics.diameter(CORNERS), abs=1e-12)


def test_model_points_of_the_meshs_own_resolution_keep_thin_parts():
    shelf = csdf.zoo.load("bookshelf")  # a 6 mm back panel at y = 0.15

    def back_panel(v):  # on its outer face, between the first two boards
        return int(np.count_nonzero((v[:, 1] > 0.148) & (np.abs(v[:, 0]) < 0.3)
                                    & (v[:, 2] > 0.128) & (v[:, 2] < 0.388)))

    assert back_panel(metrics.model_points(shelf, resolution=48)) == 0  # lost
    fine = metrics.model_points(shelf, resolution=None)
    assert back_panel(fine) > 100
    sub = fine[metrics.farthest_points(fine, 300)]
    assert back_panel(sub) > 0
    assert metrics.farthest_points(fine, 10 ** 6).shape == (len(fine),)


def test_farthest_points_is_the_greedy_farthest_first_order():
    """Each chosen point is the one farthest from those chosen before (the first the
    farthest from the centroid; ties to the lowest index), checked against the
    definition on points with many ties."""
    rng = np.random.default_rng(0)
    for v in (rng.normal(size=(400, 3)), rng.integers(0, 3, (300, 3)).astype(float)):
        idx = metrics.farthest_points(v, 40)
        assert idx[0] == int(np.argmax(np.sum((v - v.mean(axis=0)) ** 2, axis=1)))
        for i in range(1, len(idx)):
            d = np.min(np.linalg.norm(v[:, None, :] - v[idx[:i]][None], axis=2), axis=1)
            assert idx[i] == int(np.argmax(d))
    assert metrics.farthest_points(np.zeros((3, 3)), 0).shape == (0,)


# ---------------------------------------------------------------- symmetries
def test_symmetries_of_a_box_a_cube_and_a_hexagonal_prism(box, box_syms):
    assert len(box_syms) == 4  # D2: identity and the three 180-degree flips
    assert np.array_equal(box_syms[0], np.eye(4))
    for S in box_syms:  # each maps the corners onto the corners
        mapped = CORNERS @ S[:3, :3].T + S[:3, 3]
        assert np.abs(mapped[:, None] - CORNERS[None]).sum(-1).min(1).max() < 1e-9
    assert np.array_equal(box_syms, metrics.symmetries(box))  # deterministic
    assert len(metrics.symmetries(csdf.box(0.1))) == 24
    assert len(metrics.symmetries(csdf.hex_prism(0.03, 0.05))) == 12


def test_symmetries_about_an_offset_centre():
    shifted = csdf.box((2 * A, 2 * B, 2 * C)).translate((0.2, 0.1, 0.05))
    S = metrics.symmetries(shifted)
    assert len(S) == 4
    centre = np.array([0.2, 0.1, 0.05])
    for T in S:
        assert np.allclose(T[:3, :3] @ centre + T[:3, 3], centre, atol=1e-9)


def test_symmetries_of_models_with_parts_thinner_than_a_coarse_voxel():
    # found on a 48-voxel mesh before session 24, a 3 cm table top left the centre of
    # mass off (the half turn was missed), a bookshelf's 6 mm back went unsampled (its
    # half turn passed), and 1.7 cm boards left no surface to sample
    table = {"height": 0.971, "length": 1.744, "width": 0.827, "top": 0.030,
             "leg": 0.069, "inset": 0.119}
    assert len(metrics.symmetries(csdf.zoo.load("table"), params=table)) == 2
    for shelf in ({"width": 0.668, "depth": 0.341, "shelf_spacing": 0.365, "board": 0.020,
                   "plinth": 0.085},
                  {"width": 1.008, "depth": 0.272, "shelf_spacing": 0.369, "board": 0.017,
                   "plinth": 0.094}):
        assert len(metrics.symmetries(csdf.zoo.load("bookshelf"), params=shelf)) == 1


def test_a_sphere_is_refused():
    with pytest.raises(CsdfError, match="more than one axis"):
        metrics.symmetries(csdf.sphere(0.05))


# ---------------------------------------------------------------- MSSD, MSPD by hand
def test_mssd_of_a_known_rotation_of_a_box(box, box_syms):
    est = csdf.Pose(_rot("z", math.pi / 2), (0.01, -0.02, 0.5))
    gt = csdf.Pose(translation=(0.01, -0.02, 0.5))
    # |R x - x| for a quarter turn about z is sqrt(2) times the distance from the axis,
    # largest at the corners; the box's flips do not bring it closer: about z it is the
    # same, about x or y the corners' sqrt(2 (a + b)^2 + 4 c^2) = 0.12 is larger
    hand = math.sqrt(2.0) * math.hypot(A, B)
    assert metrics.mssd(CORNERS, est, gt) == pytest.approx(hand, abs=1e-12)
    assert metrics.mssd(CORNERS, est.matrix, gt.matrix, box_syms) == pytest.approx(
        hand, abs=1e-12)
    v = metrics.model_points(box)
    assert metrics.mssd(v, est, gt, box_syms) == pytest.approx(hand, abs=1e-12)


def test_a_half_turn_about_a_symmetry_axis_costs_nothing(box, box_syms):
    cam = csdf.Camera(500, 500, 319.5, 239.5, 640, 480)
    gt = csdf.Pose(_rot("x", 0.3), (0.02, 0.01, 0.6))
    est = gt @ csdf.Pose(_rot("z", math.pi))
    v = metrics.model_points(box)
    assert metrics.mssd(v, est, gt) == pytest.approx(2 * math.hypot(A, B), abs=1e-12)
    assert metrics.mssd(v, est, gt, box_syms) < 1e-12
    assert metrics.mspd(v, est, gt, cam, box_syms) < 1e-9
    assert metrics.mspd(v, est, gt, cam) > 10.0


def test_a_cylinder_turned_about_its_axis_or_flipped_is_within_the_step():
    cyl = csdf.cylinder(0.03, 0.1)
    S = metrics.symmetries(cyl, continuous_step=0.01)
    assert len(S) % 24 == 0 and len(S) > 100  # discretised turns, times a flip
    v = metrics.model_points(cyl, n=400)
    d = metrics.diameter(v)
    gt = csdf.Pose(translation=(0, 0, 0.5))
    for R in (_rot("z", 0.3), _rot("z", 2.0), _rot("x", math.pi), _rot("y", math.pi)):
        est = gt @ csdf.Pose(R)
        assert metrics.mssd(v, est, gt) > 0.008
        assert metrics.mssd(v, est, gt, S) <= 0.01 * d
    assert metrics.mssd(v, gt @ csdf.Pose(_rot("z", math.pi / 2)), gt, S) < 1e-12


def test_mspd_of_a_shift_by_hand():
    cam = csdf.Camera(500, 400, 320, 240, 640, 480)
    pts = np.array([[0.0, 0.0, 0.0], [0.01, 0.02, 0.0]])
    gt = csdf.Pose(translation=(0, 0, 1.0))
    est = csdf.Pose(translation=(0.002, 0.001, 1.0))
    assert metrics.mspd(pts, est, gt, cam) == pytest.approx(math.hypot(1.0, 0.4), abs=1e-12)
    behind = csdf.Pose(translation=(0, 0, -1.0))
    assert metrics.mspd(pts, behind, gt, cam) == math.inf


def _mssd_loops(x, est, gt, syms):
    best = math.inf
    for S in syms:
        worst = 0.0
        for p in x:
            a = est[:3, :3] @ p + est[:3, 3]
            q = S[:3, :3] @ p + S[:3, 3]
            b = gt[:3, :3] @ q + gt[:3, 3]
            worst = max(worst, math.sqrt(sum((a - b) ** 2)))
        best = min(best, worst)
    return best


def _mspd_loops(x, est, gt, syms, K):
    def proj(p):
        h = K @ p
        return h[:2] / h[2]

    best = math.inf
    for S in syms:
        worst = 0.0
        for p in x:
            a = proj(est[:3, :3] @ p + est[:3, 3])
            b = proj(gt[:3, :3] @ (S[:3, :3] @ p + S[:3, 3]) + gt[:3, 3])
            worst = max(worst, math.sqrt(sum((a - b) ** 2)))
        best = min(best, worst)
    return best


def test_mssd_and_mspd_equal_a_plain_rederivation_on_random_poses():
    rng = np.random.default_rng(7)
    cam = csdf.Camera(600, 580, 330, 250, 640, 480)
    x = rng.uniform(-0.05, 0.05, size=(40, 3))
    syms = np.tile(np.eye(4), (4, 1, 1))
    for k in range(1, 4):
        syms[k, :3, :3] = _random_rotation(rng)
        syms[k, :3, 3] = rng.normal(scale=0.01, size=3)
    rot_only = syms[1:, :3, :3]  # (K, 3, 3): rotations about the origin
    rot_ref = np.tile(np.eye(4), (4, 1, 1))
    rot_ref[1:, :3, :3] = rot_only
    for _ in range(5):
        gt, est = np.eye(4), np.eye(4)
        for T in (gt, est):
            T[:3, :3] = _random_rotation(rng)
            T[:3, 3] = rng.normal(scale=0.05, size=3) + [0, 0, 0.8]
        for s, ref in ((None, np.eye(4)[None]), (syms, syms), (rot_only, rot_ref)):
            assert metrics.mssd(x, est, gt, s) == pytest.approx(
                _mssd_loops(x, est, gt, ref), abs=1e-9)
            assert metrics.mspd(x, est, gt, cam, s) == pytest.approx(
                _mspd_loops(x, est, gt, ref, cam.K), abs=1e-9)


# ---------------------------------------------------------------- ADD, ADD-S
def test_add_and_adds_by_hand():
    gt = csdf.Pose(translation=(0, 0, 1.0))
    shifted = csdf.Pose(translation=(0.003, 0.004, 1.0))
    assert metrics.add(CORNERS, shifted, gt) == pytest.approx(0.005, abs=1e-15)
    assert metrics.adds(CORNERS, shifted, gt) == pytest.approx(0.005, abs=1e-15)
    flipped = gt @ csdf.Pose(_rot("z", math.pi))
    assert metrics.add(CORNERS, flipped, gt) == pytest.approx(2 * math.hypot(A, B), abs=1e-12)
    assert metrics.adds(CORNERS, flipped, gt) < 1e-12


# ---------------------------------------------------------------- VSD
# a 64x48 camera looking along +z at a box whose front face (z = 0.9 at the true pose)
# spans pixel columns 22..41 and rows 16..31: its edges fall at u = 31.5 +- 10.2 and
# v = 23.5 +- 8.3 (the box's half sizes are 10.2 and 8.3 pixels at depth 0.9)
CAM = csdf.Camera(50, 50, 31.5, 23.5, 64, 48)
HX, HY = 10.2 * 0.9 / 50, 8.3 * 0.9 / 50


@pytest.fixture(scope="module")
def vsd_scene():
    slab = csdf.box((2 * HX, 2 * HY, 0.2))
    gt = csdf.Pose(translation=(0, 0, 1.0))
    depth = np.full((48, 64), 2.0)  # a wall behind
    depth[16:32, 22:42] = 0.9       # the object at its true pose
    depth[:, :30] = 0.5             # an occluder in front of columns 0..29
    depth[20, 35:38] = 0.0          # missing depth on the visible part
    depth[18, 25] = 0.0             # missing depth behind the occluder
    return slab, gt, depth


def test_vsd_of_a_partly_occluded_object_by_hand(vsd_scene):
    slab, gt, depth = vsd_scene
    # true pose: visible where the occluder is not (columns 30..41 of rows 16..31: 192
    # pixels) plus the missing pixel at (18, 25): 193 of its 320 pixels
    assert metrics.visible_fraction(slab, gt, depth, CAM, delta=0.015) == 193 / 320
    # shifted 5 pixels right (0.09 at depth 0.9): columns 27..46; 27..29 are occluded,
    # 30..41 see the object's own surface, 42..46 the wall: 17 x 16 = 272 visible, 192
    # of them shared with the truth at equal distance; the union has 273 pixels
    est = csdf.Pose(translation=(0.09, 0, 1.0))
    e = metrics.vsd(slab, est, gt, depth, CAM, delta=0.015, tau=[0.005, 0.02])
    assert e == pytest.approx([81 / 273, 81 / 273], abs=1e-15)
    # also 0.01 nearer (front face at 0.89; the shift 0.089 is again 5 pixels): the same
    # masks, the shared pixels now differ by 0.01 to 0.0104 in distance
    est = csdf.Pose(translation=(0.089, 0, 0.99))
    e = metrics.vsd(slab, est, gt, depth, CAM, delta=0.015, tau=[0.005, 0.02])
    assert e == pytest.approx([273 / 273, 81 / 273], abs=1e-15)
    assert metrics.vsd(slab, est, gt, depth, CAM, delta=0.015, tau=0.02) == pytest.approx(
        81 / 273, abs=1e-15)
    # 0.03 further back: behind the observed surface by more than delta, so visible only
    # where depth is missing (3 pixels) against the truth's 193
    far = csdf.Pose(translation=(0, 0, 1.03))
    assert metrics.vsd(slab, far, gt, depth, CAM, delta=0.015, tau=0.02) == 1.0
    assert metrics.vsd(slab, gt, gt, depth, CAM, delta=0.015, tau=0.02) == 0.0


def test_vsd_default_taus_are_fractions_of_the_diameter(vsd_scene):
    slab, gt, depth = vsd_scene
    est = csdf.Pose(translation=(0.089, 0, 0.99))
    e = metrics.vsd(slab, est, gt, depth, CAM, delta=0.015, diameter=0.08)
    assert e.shape == (10,)  # taus 0.004, 0.008, 0.012, ..., 0.04 against 0.01 .. 0.0104
    assert np.all(e[:2] == 1.0) and np.all(e[2:] == 81 / 273)
    with pytest.raises(CsdfError, match="tau .* or diameter"):
        metrics.vsd(slab, est, gt, depth, CAM, delta=0.015)


def _vsd_by_render(shape, est, gt, depth, cam, delta, tau):
    """VSD from csdf.render with the camera moved to P^-1 (an independent path)."""
    dirs = cam.pixel_directions().reshape(cam.height, cam.width, 3)
    k = 1.0 / dirs[..., 2]
    test = depth * k
    masks, dists = [], []
    for P in (est, gt):
        inv = P.inverse()
        r = csdf.render(shape, csdf.Camera(cam.fx, cam.fy, cam.cx, cam.cy, cam.width,
                                           cam.height, R=inv.rotation, t=inv.translation))
        dist = np.where(r.mask, r.depth * k, np.inf)
        vis = r.mask & ((depth == 0) | (dist - test <= delta))
        masks.append(vis)
        dists.append(dist)
    union = masks[0] | masks[1]
    both = masks[0] & masks[1]
    diff = np.abs(np.where(both, dists[0], 0.0) - np.where(both, dists[1], 0.0))
    bad = (both & (diff >= tau)).sum() + (union & ~both).sum()
    return bad / union.sum()


def test_vsd_of_rotated_poses_equals_a_render_rederivation(box):
    rng = np.random.default_rng(3)
    gt = csdf.Pose(_random_rotation(rng), (0.01, 0.0, 0.35))
    est = csdf.Pose(_rot("y", 0.15) @ gt.rotation, (0.015, 0.005, 0.355))
    depth = np.full((48, 64), 0.5)
    depth[:, :20] = 0.3
    depth[10:14, 30:40] = 0.0
    e = metrics.vsd(box, est, gt, depth, CAM, delta=0.015, tau=[0.005, 0.01, 0.05])
    ref = [_vsd_by_render(box, est, gt, depth, CAM, 0.015, t) for t in (0.005, 0.01, 0.05)]
    assert e == pytest.approx(ref, abs=1e-12)
    assert 0.0 < e[-1] < 1.0


# ---------------------------------------------------------------- recall, AR, AUC
def test_recall_with_the_visibility_rule_by_hand():
    errors = [0.01, 0.04, 0.2, np.inf, np.nan]
    assert metrics.recall(errors, 0.05) == pytest.approx(2 / 5)
    assert metrics.recall(errors, [0.05, 0.3]) == pytest.approx([2 / 5, 3 / 5])
    visib = [1.0, 0.05, 0.5, 0.1, 0.9]  # the second is under 10 % visible: not counted
    assert metrics.recall(errors, 0.05, visib_fract=visib) == pytest.approx(1 / 4)
    # thresholds relative to per-instance diameters
    assert metrics.recall([0.01, 0.03], 0.1, scale=[0.2, 0.2]) == 0.5
    vsd_e = np.array([[0.1, 0.2], [0.3, 0.6]])  # (N, T): rows instances, columns taus
    assert np.array_equal(metrics.recall(vsd_e, [0.25, 0.5]), [[0.5, 1.0], [0.5, 0.5]])
    assert metrics.average_recall(vsd_e, "vsd") == pytest.approx(
        np.mean([[(vsd_e[:, t] < th).mean() for th in metrics.VSD_THETAS]
                 for t in range(2)]))


def test_average_recall_of_mssd_and_mspd_by_hand():
    # MSSD 0.012 with diameter 0.1 is correct for theta >= 0.15: 8 of 10 thresholds
    assert metrics.average_recall([0.012], "mssd", diameter=0.1) == pytest.approx(0.8)
    # MSPD 12 px in a 1280-wide image is 6 px at width 640: correct for theta >= 10
    assert metrics.average_recall([12.0], "mspd", image_width=1280) == pytest.approx(0.9)
    ar = metrics.bop_average_recall([[0.12]], [0.012], [12.0], diameter=0.1,
                                    image_width=1280)
    assert ar == pytest.approx((0.8 + 0.8 + 0.9) / 3)
    with pytest.raises(CsdfError, match="diameter"):
        metrics.average_recall([0.012], "mssd")
    with pytest.raises(CsdfError, match="metric must be one of"):
        metrics.average_recall([0.012], "add")


def test_auc_is_the_exact_area():
    assert metrics.auc([0.0, 0.05, np.inf], 0.1) == pytest.approx(0.5)
    e = np.array([0.003, 0.02, 0.007])
    d = np.array([0.1, 0.1, 0.05])
    grid = np.linspace(0, 0.1, 100001)
    curve = (e[:, None] < grid[None] * d[:, None]).mean(0)
    area = float(np.sum((curve[1:] + curve[:-1]) * np.diff(grid)) / 2)
    assert metrics.auc(e, 0.1, scale=d) == pytest.approx(area / 0.1, abs=1e-4)


# ---------------------------------------------------------------- bad input
@pytest.mark.parametrize("call, match", [
    (lambda: metrics.mssd(np.zeros((5, 2)), np.eye(4), np.eye(4)), r"points .*\(N, 3\)"),
    (lambda: metrics.mssd(CORNERS, np.eye(3), np.eye(4)), r"est_pose .*\(4, 4\)"),
    (lambda: metrics.mssd(CORNERS, np.eye(4), None), "gt_pose"),
    (lambda: metrics.mssd(CORNERS, np.eye(4), np.eye(4), np.zeros((2, 2, 2))),
     r"symmetries .*\(K, 3, 3\) or \(K, 4, 4\)"),
    (lambda: metrics.mssd(CORNERS, np.eye(4), np.eye(4), 2 * np.eye(3)), "not a rotation"),
    (lambda: metrics.mspd(CORNERS, np.eye(4), np.eye(4), np.eye(3)), "csdf.Camera"),
    (lambda: metrics.vsd(csdf.sphere(0.1), np.eye(4), np.eye(4), np.zeros((4, 4)), CAM,
                         delta=0.015, tau=0.01), r"depth .*\(48, 64\)"),
    (lambda: metrics.vsd(csdf.sphere(0.1), np.eye(4), np.eye(4), -np.ones((48, 64)), CAM,
                         delta=0.015, tau=0.01), "depth must be >= 0"),
    (lambda: metrics.vsd(csdf.sphere(0.1), np.eye(4), np.eye(4), np.zeros((48, 64)), CAM,
                         delta=-1, tau=0.01), "delta"),
    (lambda: metrics.recall([0.1, 0.2], 0.1, visib_fract=[1.0]), r"visib_fract .*\(2,\)"),
    (lambda: metrics.recall([[[0.1]]], 0.1), r"errors .*\(N,\) or \(N, T\)"),
    (lambda: metrics.recall([0.1], 0.1, visib_fract=[0.01]), "no instance"),
    (lambda: metrics.auc([0.1], 0.0), "max_threshold"),
    (lambda: metrics.diameter(np.zeros((0, 3))), r"points .*\(N, 3\)"),
    (lambda: metrics.model_points(csdf.sphere(0.1), n=0), "n must be"),
])
def test_bad_input_names_the_argument(call, match):
    with pytest.raises(CsdfError, match=match):
        call()
