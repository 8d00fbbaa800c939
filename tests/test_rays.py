"""The nearest-ray index of detection (csdf.detect.rays): the grid of a sensor's rays
answers what a KD-tree of the unit directions answers."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial import cKDTree

from csdf.detect.rays import RayIndex


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _camera_rays(half_angle_deg: float, n: int, axis, seed: int) -> np.ndarray:
    """Jittered rays of a pinhole camera looking along ``axis``: ``(about n, 3)``."""
    rng = np.random.default_rng(seed)
    k = int(math.sqrt(n))
    s = math.tan(math.radians(half_angle_deg)) / math.sqrt(2.0)  # the corners' angle
    u, v = np.meshgrid(np.linspace(-s, s, k), np.linspace(-s, s, k))
    d = np.stack([u.ravel(), v.ravel(), np.ones(k * k)], axis=1)
    d[:, :2] += rng.normal(scale=0.2 * 2 * s / k, size=(k * k, 2))
    z = _unit(np.asarray(axis, float)[None])[0]
    x = _unit(np.cross(z, [0.3, 1.0, 0.2])[None])[0]
    return _unit(d) @ np.stack([x, np.cross(z, x), z])


@pytest.mark.parametrize("half_angle,axis", [(30.0, (0, 0, 1)), (62.0, (0.3, -0.5, -1.0)),
                                             (75.0, (1, 0, 0))])
def test_the_grid_gives_the_kd_trees_nearest_ray_within_the_tolerance(half_angle, axis):
    D = _camera_rays(half_angle, 40_000, axis, seed=int(half_angle))
    tree = cKDTree(D)
    tol = 1.5 * float(np.median(tree.query(D[::7], k=2)[0][:, 1]))
    index = RayIndex(D, tol)
    assert index.gridded
    rng = np.random.default_rng(3)
    near = D[rng.integers(0, len(D), 60_000)] + rng.normal(scale=0.8 * tol, size=(60_000, 3))
    Q = _unit(np.concatenate([near, rng.normal(size=(5_000, 3)), D[:50], -D[:50]]))
    want_d, want_j = tree.query(Q, k=1, distance_upper_bound=tol)
    got_d, got_j = index.nearest(Q)
    assert np.array_equal(got_j, want_j)
    assert np.array_equal(got_d, want_d)
    # the rays themselves are their own nearest, at distance 0; none lies behind
    assert np.array_equal(got_j[-100:-50], np.arange(50)) and got_d[-100:-50].max() < 1e-12
    assert np.all(got_j[-50:] == len(D)) and np.all(np.isinf(got_d[-50:]))
    assert 0.3 < np.isfinite(got_d[:60_000]).mean() < 1.0


def test_a_bundle_too_wide_to_grid_uses_the_kd_tree():
    rng = np.random.default_rng(5)
    D = _unit(rng.normal(size=(20_000, 3)))  # all around: no axis to project about
    index = RayIndex(D, 0.02)
    assert not index.gridded
    Q = _unit(rng.normal(size=(2_000, 3)))
    want = cKDTree(D).query(Q, k=1, distance_upper_bound=0.02)
    got = index.nearest(Q)
    assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])


def test_no_rays_and_a_bad_tolerance_find_nothing_or_fall_back():
    index = RayIndex(np.zeros((0, 3)), 0.01)
    d, j = index.nearest(np.array([[0.0, 0.0, 1.0]]))
    assert np.isinf(d[0]) and j[0] == 0
    D = _camera_rays(20.0, 400, (0, 0, 1), seed=1)
    assert not RayIndex(D, 0.0).gridded and not RayIndex(D, math.nan).gridded


@pytest.mark.parametrize("radius", [0.004, 0.02, 0.08])
def test_the_nearest_scan_point_by_its_rays_is_the_kd_trees(radius):
    rng = np.random.default_rng(7)
    D = _camera_rays(55.0, 30_000, (0.2, 0.1, 1.0), seed=2)
    P = D * rng.uniform(1.0, 4.0, size=(len(D), 1)) + [0.5, -0.2, 0.1]  # seen from there
    o = np.array([0.5, -0.2, 0.1])
    tree = cKDTree(P)
    tol = 1.5 * float(np.median(cKDTree(D).query(D[::7], k=2)[0][:, 1]))
    index = RayIndex(D, tol)
    X = P[rng.integers(0, len(P), 40_000)] + rng.normal(scale=radius, size=(40_000, 3))
    # and points near the sensor (looked up by the tree), behind it and off to the side
    X = np.concatenate([X, o + rng.normal(scale=0.5 * radius, size=(20, 3)),
                        o - 2.0 * (P[:20] - o), o + [[5.0, 0.0, -0.5]] * np.ones((5, 3))])
    want_d, want_j = tree.query(X, k=1, distance_upper_bound=radius)
    got_d, got_j = index.nearest_point(X, P, o, radius, tree)
    assert np.array_equal(got_j, want_j) and np.array_equal(got_d, want_d)
    assert 0.1 < np.isfinite(got_d[:40_000]).mean() < 1.0
