"""Detection in point clouds (csdf.detect): primitives by Efficient RANSAC scored with
exact distances, known models in a cluttered scan, the scene they make, the CLI."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

import csdf
from csdf.detect import surfaces as S
from csdf.detect.neighbours import (
    components,
    distinct_points,
    exact_copies,
    linked_edges,
    neighbourhood,
    sparse_points,
    with_copies,
)
from csdf.detect.objects import GAIN_CAP_LOG, MAX_INTRUDERS, RAY_SPREAD, YAW_DOUBT, _rz
from csdf.fit.quality import VIEW_RAYS, _edge_rays

# -- the minimal-set solvers, on exact data -------------------------------------------


def _frame(a):
    return S.frame_z(np.asarray(a, float))


def test_sphere_and_cylinder_from_two_oriented_points():
    rng = np.random.default_rng(1)
    c = np.array([0.1, 0.2, 0.3])
    u = rng.normal(size=(2, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    H, ok = S.spheres_from((c + 0.2 * u)[None], (u * [[1], [-1]])[None], 1e-9, 10.0)
    assert ok[0] and np.allclose(H[0], [0.1, 0.2, 0.3, 0.2])
    R = _frame([0.3, 0.4, 0.5])
    ang = np.array([0.3, 2.0])
    loc = np.stack([0.15 * np.cos(ang), 0.15 * np.sin(ang), [0.2, -0.4]], 1)
    nl = np.stack([np.cos(ang), np.sin(ang), [0, 0]], 1)
    H, ok = S.cylinders_from((loc @ R.T + c)[None], (nl @ R.T)[None], 1e-9, 10.0)
    assert ok[0] and math.isclose(H[0, 6], 0.15)
    assert abs(abs(H[0, 3:6] @ R[:, 2]) - 1) < 1e-12
    d, cos = S.surface_distance("cylinder", H, loc @ R.T + c, nl @ R.T)
    assert np.allclose(d, 0, atol=1e-12) and np.allclose(cos, 1)


def test_cone_and_torus_from_oriented_points():
    rng = np.random.default_rng(2)
    c = np.array([0.1, -0.2, 0.3])
    R = _frame([0.3, -0.4, 0.5])
    th = math.radians(30)
    hs, ang = rng.uniform(0.1, 0.5, 3), rng.uniform(0, 6.28, 3)
    loc = np.stack([hs * math.tan(th) * np.cos(ang), hs * math.tan(th) * np.sin(ang), hs], 1)
    nl = np.stack([math.cos(th) * np.cos(ang), math.cos(th) * np.sin(ang),
                   -math.sin(th) * np.ones(3)], 1)
    H, ok = S.cones_from((loc @ R.T + c)[None], (nl @ R.T)[None], 1e-9, 10.0)
    assert ok[0] and np.allclose(H[0, :3], c) and math.isclose(H[0, 6], th)
    assert np.allclose(H[0, 3:6], R[:, 2])
    # a torus from four nearby oriented points (one normal flipped: signs are unknown)
    phi, psi = rng.uniform(0, 0.5, 4), rng.uniform(0, 0.9, 4)
    nl = np.stack([np.cos(psi) * np.cos(phi), np.cos(psi) * np.sin(phi), np.sin(psi)], 1)
    loc = np.stack([0.3 * np.cos(phi), 0.3 * np.sin(phi), 0 * phi], 1) + 0.08 * nl
    n = nl @ R.T
    n[2] *= -1
    H, ok = S.tori_from((loc @ R.T + c)[None], n[None], 1e-9, 10.0)
    good = H[ok]
    assert len(good) == 1 and np.allclose(good[0, [0, 1, 2, 6, 7]], [*c, 0.3, 0.08])


def test_torus_cubic_roots_are_the_companion_matrixs_eigenvalues():
    # the closed-form roots behind tori_from against the eigenvalues of the companion
    # matrix: three real roots, one real and a complex pair, a double root
    from csdf.detect.minimal import _cubic_roots

    rng = np.random.default_rng(11)
    for roots in [rng.uniform(-3, 3, 3) for _ in range(200)] + [
            [0.5, 0.5, -2.0], [1.0, 1.0, 1.0], [0.0, 2.0, -1e-3]]:
        a, b, c = np.poly(roots)[1:]
        x = _cubic_roots(a, b, c)
        assert all(x[3:])
        assert np.allclose(sorted(x[:3]), sorted(roots), atol=1e-6)
    for _ in range(200):  # one real root and a complex pair
        r, re, im = rng.uniform(-3, 3), rng.uniform(-3, 3), rng.uniform(0.1, 3)
        a, b, c = np.real(np.poly([r, re + 1j * im, re - 1j * im]))[1:]
        x = _cubic_roots(a, b, c)
        assert x[3] and not x[4] and not x[5]
        assert math.isclose(x[0], r, abs_tol=1e-9) and math.isclose(x[1], re, abs_tol=1e-9)


def test_the_neighbour_graph_lists_each_linked_edge_once_at_both_ends():
    from csdf.detect.kernels import linked_graph

    rng = np.random.default_rng(12)
    P = rng.normal(size=(2000, 3))
    nb = neighbourhood(P, want_normals=False)
    linked = linked_edges(nb, radius=float(np.median(nb.lengths)))
    start, adj = linked_graph(nb.nbr, linked)
    want = [set() for _ in range(len(P))]
    for i, c in zip(*np.nonzero(linked)):
        want[i].add(int(nb.nbr[i, c]))
        want[int(nb.nbr[i, c])].add(int(i))
    for i in range(len(P)):
        row = adj[start[i]:start[i + 1]].tolist()
        assert len(row) == len(set(row)) and set(row) == want[i]


def test_surface_distances_are_exact():
    # the compiled distances against csdf's exact primitives (sphere, torus), the
    # unbounded cylinder, the plane, and a brute-force nearest point on a cone's nappe
    rng = np.random.default_rng(4)
    P = rng.uniform(-0.5, 0.5, (400, 3))
    c = np.array([0.05, -0.02, 0.03])
    R = _frame([0.2, 0.9, -0.4])
    a = R[:, 2]
    d, _ = S.surface_distance("sphere", np.r_[c, 0.2][None], P)
    assert np.allclose(d[0], csdf.sphere(0.2).translate(tuple(c))(P), atol=1e-12)
    d, _ = S.surface_distance("torus", np.r_[c, a, 0.25, 0.07][None], P)
    exact = csdf.torus(0.25, 0.07).rotate(R).translate(tuple(c))(P)
    assert np.allclose(d[0], exact, atol=1e-12)
    d, _ = S.surface_distance("plane", np.r_[a, 0.1][None], P)
    assert np.allclose(d[0], P @ a - 0.1, atol=1e-15)
    d, _ = S.surface_distance("cylinder", np.r_[c, a, 0.15][None], P)
    v = P - c
    assert np.allclose(d[0], np.linalg.norm(v - np.outer(v @ a, a), axis=1) - 0.15)
    th = 0.5
    d, cosines = S.surface_distance("cone", np.r_[c, a, th][None], P, P * 0 + a)
    rho = np.linalg.norm(v - np.outer(v @ a, a), axis=1)
    s_ = np.linspace(0, 2.0, 200_001)  # along the generator in each point's half plane
    brute = np.sqrt((rho[:, None] - s_ * math.sin(th)) ** 2
                    + ((v @ a)[:, None] - s_ * math.cos(th)) ** 2).min(axis=1)
    assert np.allclose(np.abs(d[0]), brute, atol=2e-5)
    assert np.allclose(cosines[0], math.sin(th), atol=1e-12)  # axis vs the nappe normal
    # counts agree with the distances and normal test
    H = np.stack([np.r_[c, 0.2], np.r_[c, 0.3]])
    N = rng.normal(size=P.shape)
    N /= np.linalg.norm(N, axis=1, keepdims=True)
    d, cos = S.surface_distance("sphere", H, P, N)
    want = ((np.abs(d) <= 0.05) & (cos >= 0.5)).sum(axis=1)
    assert np.array_equal(S.inlier_counts("sphere", H, P, N, 0.05, 0.5), want)


def test_scoring_on_growing_prefixes_drops_only_hypotheses_that_cannot_win():
    # kernels.best_counts against the rule it documents, counted with the distances
    from csdf.detect.kernels import best_counts

    rng = np.random.default_rng(13)
    P = rng.uniform(-0.5, 0.5, (700, 3))
    N = rng.normal(size=P.shape)
    N /= np.linalg.norm(N, axis=1, keepdims=True)
    hyps = {"plane": np.c_[np.tile([0.0, 0.0, 1.0], (6, 1)), rng.uniform(-0.3, 0.3, 6)],
            "sphere": np.c_[rng.uniform(-0.2, 0.2, (6, 3)), rng.uniform(0.1, 0.4, 6)]}
    eps, cos_tol, first, k, z = 0.05, 0.3, 100, 2, 3.0
    H = np.zeros((12, 8))
    H[:6, :4], H[6:, :4] = hyps["plane"], hyps["sphere"]
    kind = np.repeat([S.KIND_ID["plane"], S.KIND_ID["sphere"]], 6)
    counts, alive = best_counts(kind, H, P, N, eps, cos_tol, first, k, z)
    inl = np.concatenate([(np.abs(d) <= eps) & (c >= cos_tol) for d, c in
                          (S.surface_distance(kd, h, P, N) for kd, h in hyps.items())])
    want = np.zeros(12, dtype=int)
    live = np.ones(12, dtype=bool)
    a, b = 0, first
    while True:
        want[live] += inl[live, a:b].sum(axis=1)
        if b >= len(P):
            break
        if live.sum() > k:
            c = np.sort(want[live])[live.sum() - k]
            live &= want + z * np.sqrt(want) >= c - z * math.sqrt(c)
        a, b = b, min(2 * b, len(P))
    assert np.array_equal(alive, live) and np.array_equal(counts, want)
    assert 0 < live.sum() < 12  # some were dropped, the best kept
    assert want[live].max() == inl.sum(axis=1).max()


def test_knn_on_the_grid_is_the_trees():
    from scipy.spatial import cKDTree

    from csdf.detect.neighbours import GRID_MIN_POINTS, knn

    rng = np.random.default_rng(5)
    n = 3 * GRID_MIN_POINTS
    u = rng.uniform(0, 2 * math.pi, n)
    sheet = np.c_[np.cos(u), np.sin(u), rng.uniform(-1, 1, n)]  # a cylinder's surface
    P = np.concatenate([sheet, rng.uniform(-3, 3, (300, 3))])  # and sparse outliers
    tree = cKDTree(P)
    d0, i0 = tree.query(P, k=13)
    d1, i1 = knn(P, tree, 12)
    assert np.array_equal(d1, d0[:, 1:]) and np.array_equal(i1, i0[:, 1:])


def test_a_surfaces_neighbours_need_no_tree_of_every_point():
    """The grid's cell side comes from a third of the points, the points its 3 x 3 x 3
    blocks leave are searched in 5 x 5 x 5: a surface without outliers builds no k-d
    tree of every point, and the neighbours are still the tree's."""
    from scipy.spatial import cKDTree

    from csdf.detect.neighbours import GRID_MIN_POINTS, neighbourhood

    rng = np.random.default_rng(6)
    n = 3 * GRID_MIN_POINTS
    u = rng.uniform(0, 2 * math.pi, n)
    P = np.c_[np.cos(u), np.sin(u), rng.uniform(-1, 1, n)]
    nb = neighbourhood(P, want_normals=False)
    assert nb._tree is None
    d0, i0 = cKDTree(P).query(P, k=13)
    assert np.array_equal(nb.lengths, d0[:, 1:]) and np.array_equal(nb.nbr, i0[:, 1:])
    assert nb.tree.n == n  # built when asked


def test_compiled_grid_searches_are_exact():
    from scipy.spatial import cKDTree

    from csdf.cellsort import group_by_cell
    from csdf.detect.kernels import any_within, bounds, cell_keys, grid_knn

    rng = np.random.default_rng(9)
    P = np.concatenate([rng.normal(size=(3000, 3)) * [1, 1, 0.05],
                        rng.uniform(-4, 4, (50, 3))])
    lo, hi = bounds(P)
    for h in (0.05, 0.2, 1.0):
        dims = ((hi - lo) // h).astype(np.int64) + 1
        key = cell_keys(P, lo, h, dims)
        ijk = np.minimum(((P - lo) // h).astype(np.int64), dims - 1)
        assert np.array_equal(key, ijk[:, 0] + dims[0] * (ijk[:, 1] + dims[1] * ijk[:, 2]))
        sub = np.sort(rng.choice(len(P), 700, replace=False))
        order, first = group_by_cell(cell_keys(P[sub], lo, h, dims), int(np.prod(dims)))
        Q = P[rng.choice(len(P), 200, replace=False)]
        got = grid_knn(Q, np.ascontiguousarray(P[sub][order]), sub[order], first, dims, lo,
                       h, 10)
        _, want = cKDTree(P[sub]).query(Q, k=10)
        assert np.array_equal(got, sub[want])
    A, B = P[:1500], P[1500:]
    d = np.sqrt(((A[:, None, :] - B[None, :, :]) ** 2).sum(axis=2)).min()
    assert any_within(A, B, 1.0001 * d) and not any_within(A, B, 0.9999 * d)
    assert not any_within(A[:0], B, 1.0)


def test_compiled_bounds_and_cell_order_are_numpys():
    from csdf.cellsort import group_by_cell
    from csdf.detect.kernels import bounds

    rng = np.random.default_rng(8)
    P = rng.normal(size=(1000, 3))
    lo, hi = bounds(P)
    assert np.array_equal(lo, P.min(axis=0)) and np.array_equal(hi, P.max(axis=0))
    key = rng.integers(0, 50, 1000)  # many ties: the order within a cell is kept
    first = np.zeros(51, dtype=np.int64)
    np.cumsum(np.bincount(key, minlength=50), out=first[1:])
    order, counts = group_by_cell(key, 50)
    assert np.array_equal(order, np.argsort(key, kind="stable"))
    assert np.array_equal(counts, first)


def test_points_near_edges_are_left_out_on_both_sides():
    from csdf.detect.solids import away_from_edges, solid_values

    # a box face's points 1 mm above and below it: within a millimetre of an edge, the
    # distance of the one inside is to the other face (its normal disagrees with that
    # face's), and the one outside fails the reflection test: both go, the rest stay
    R, t = np.eye(3), np.zeros(3)
    vals = {"size_x": 0.2, "size_y": 0.2, "size_z": 0.2}
    x = np.linspace(0.05, 0.0999, 60)
    face = np.c_[x, np.zeros_like(x), np.full_like(x, 0.1)]

    def kept(Q):
        _, g = solid_values("box", R, t, vals, Q)
        return away_from_edges("box", R, t, vals, Q) & (np.abs(g[:, 2]) > 0.9)

    up, down = kept(face + [0, 0, 0.001]), kept(face - [0, 0, 0.001])
    assert np.array_equal(up, down)
    assert up[x < 0.0989].all() and not up[x > 0.0991].any()
    u = np.random.default_rng(0).normal(size=(50, 3))
    sph = u / np.linalg.norm(u, axis=1, keepdims=True) * np.linspace(0.49, 0.51, 50)[:, None]
    assert away_from_edges("sphere", R, t, {"radius": 0.5}, sph).all()  # no edges


def test_normals_and_components():
    rng = np.random.default_rng(0)
    a = np.c_[rng.uniform(0, 1, (400, 2)), np.zeros(400)]
    b = a + [3.0, 0, 0]
    P = np.concatenate([a, b])
    nb = neighbourhood(P, viewpoint=np.array([0.0, 0.0, 5.0]))
    assert np.allclose(nb.normals, [0, 0, 1], atol=1e-9)
    lab = components(nb, np.ones(len(P), bool), linked_edges(nb))
    assert set(lab[:400]) == {lab[0]} and set(lab[400:]) == {lab[400]} and lab[0] != lab[400]
    n2 = csdf.estimate_normals(P)
    assert np.allclose(np.abs(n2[:, 2]), 1)


def test_closed_form_normals_agree_with_lapack_and_fall_back_where_ill_defined():
    """The compiled closed-form principal axes (``_pca_normals``) give LAPACK's least
    eigenvector (up to sign) and eigenvalue on curved, flat and noisy neighbourhoods,
    and LAPACK's answer itself where the axis is ill-defined: neighbours along a line,
    or all at one point."""
    from scipy.spatial import cKDTree

    from csdf.detect.neighbours import _pca_normals, knn

    rng = np.random.default_rng(3)
    u = rng.normal(size=(6000, 3))
    sphere = u / np.linalg.norm(u, axis=1, keepdims=True) * 0.3
    flat = np.c_[rng.uniform(-1, 1, (6000, 2)), rng.normal(0, 1e-3, 6000)] + [3, 0, 0]
    line = np.c_[np.linspace(0, 1, 300), np.zeros((300, 2))] + [0, 3, 0]
    dup = np.repeat([[0.0, 0.0, 5.0]], 40, axis=0)
    P = np.concatenate([sphere, flat, line, dup])
    _, idx = knn(P, cKDTree(P), 12)
    Q = P[idx]
    c = Q - Q.mean(axis=1, keepdims=True)
    w, v = np.linalg.eigh(np.matmul(c.transpose(0, 2, 1), c) / 12)
    normals, least = _pca_normals(P, idx)
    assert np.allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-12)
    assert np.abs(np.einsum("ij,ij->i", normals, v[:, :, 0])).min() > 1 - 1e-9
    assert np.allclose(least, w[:, 0], rtol=0, atol=1e-12 * w[:, 2].max())
    ill = slice(12000, None)  # the line and the copies: LAPACK's own axes
    assert np.array_equal(normals[ill], v[ill, :, 0]) and np.array_equal(least[ill], w[ill, 0])


def test_frustum_outliers_are_sparse_and_do_not_join_surfaces():
    # two patches 3 m from the sensor, 0.6 m apart, and outliers scattered through the
    # frustum between them: linked by their own scale they would chain the patches
    rng = np.random.default_rng(0)
    g = np.stack(np.meshgrid(np.linspace(-0.3, 0.3, 40), np.linspace(-0.3, 0.3, 40)),
                 -1).reshape(-1, 2)
    a = np.c_[g[:, 0] - 0.5, g[:, 1], np.full(len(g), 3.0)]
    b = np.c_[g[:, 0] + 0.5, g[:, 1], np.full(len(g), 3.0)]
    z = rng.uniform(1.0, 4.0, 300)
    out = np.c_[rng.uniform(-0.3, 0.3, 300) * z, rng.uniform(-0.15, 0.15, 300) * z, z]
    P = np.concatenate([a, b, out])
    vp = np.zeros(3)
    nb = neighbourhood(P, viewpoint=vp)
    sp = sparse_points(nb, P, vp)
    assert sp[-300:].mean() > 0.8 and not sp[:-300].any()
    lab = components(nb, ~sp, linked_edges(nb, strict=True))
    n = len(g)
    assert len(set(lab[:n])) == 1 and len(set(lab[n:2 * n])) == 1 and lab[0] != lab[n]
    # without a viewpoint the expected scale is the cloud's median
    assert not sparse_points(nb, P)[:-300].any()


def test_edge_rays_of_the_visibility_check():
    v = VIEW_RAYS
    D = np.full((v, v), 2.0)
    D[:, v // 2:] = 2.5  # a step of 0.5 m between two columns
    D[:3, :3] = np.inf  # no hit: its neighbours are edge rays
    tan = np.zeros(v * v)
    e = _edge_rays(D.reshape(-1), tan, 0.01, 0.01).reshape(v, v)
    assert e[:, v // 2 - 1].all() and e[:, v // 2].all()  # both sides of the step
    assert e[:3, :3].all() and e[3, 0] and e[0, 3]
    assert not e[10:, 5:v // 2 - 1].any() and not e[10:, v // 2 + 1:].any()
    # a slanted plane (depth changing smoothly across the grid) has no edges
    slope = np.linspace(2.0, 2.6, v)[None, :].repeat(v, 0)
    tan_s = np.full(v * v, 0.6 / (2.3 * 0.01 * (v - 1)) * 1.01)
    assert not _edge_rays(slope.reshape(-1), tan_s, 0.0, 0.01).any()


# -- detect_primitives ----------------------------------------------------------------

def _primitive_scene(seed=0, n=12_000, noise=0.001):
    rng = np.random.default_rng(seed)
    shapes = [
        ("sphere", csdf.sphere(0.1).translate((0.3, 0.3, 0.2))),
        ("cylinder", csdf.cylinder(0.08, 0.3).rotate(0.7, (1, 0, 0)).translate((-0.3, 0.3, 0.25))),
        ("cone", csdf.cone(0.1, 0.2).rotate(0.4, (0, 1, 0)).translate((0.3, -0.3, 0.1))),
        ("torus", csdf.torus(0.12, 0.04).rotate(0.5, (1, 1, 0)).translate((-0.3, -0.3, 0.2))),
        ("box", csdf.box((0.2, 0.15, 0.25)).rotate(0.3, (0, 0, 1)).translate((0, 0, 0.3))),
    ]
    per = n // 6
    pts, nrm, lab = [], [], []
    for i, (_, s) in enumerate(shapes):
        p, q = csdf.sample_surface(s, per, seed=i)
        pts.append(p), nrm.append(q), lab.append(np.full(len(p), i))
    pts.append(np.c_[rng.uniform(-0.5, 0.5, (per, 2)), np.zeros(per)])
    nrm.append(np.tile([0, 0, 1.0], (per, 1)))
    lab.append(np.full(per, 5))
    P = np.concatenate(pts)
    return P + rng.normal(0, noise, P.shape), np.concatenate(nrm), np.concatenate(lab)


@pytest.fixture(scope="module")
def prim_scene():
    return _primitive_scene()


def test_detect_primitives_finds_every_kind(prim_scene):
    P, N, L = prim_scene
    dets = csdf.detect_primitives(P, N, seed=0)
    kinds = ["sphere", "cylinder", "cone", "torus", "box", "plane"]
    got = {}
    for d in dets:
        lab = np.bincount(L[d.inliers], minlength=6)
        j = int(np.argmax(lab))
        assert lab[j] >= 0.98 * len(d.inliers), d  # one primitive's points
        got[kinds[j]] = d
    assert {k: d.kind for k, d in got.items()} == {k: k for k in kinds}
    assert len(dets) == 6
    p = {k: d.params for k, d in got.items()}
    assert abs(p["sphere"]["radius"] - 0.1) < 5e-4
    assert np.allclose(p["sphere"]["center"], [0.3, 0.3, 0.2], atol=5e-4)
    assert abs(p["cylinder"]["radius"] - 0.08) < 5e-4 and abs(p["cylinder"]["height"] - 0.3) < 2e-3
    assert abs(p["torus"]["major"] - 0.12) < 5e-4 and abs(p["torus"]["minor"] - 0.04) < 5e-4
    assert abs(p["cone"]["angle"] - math.atan(0.5)) < 0.01
    assert np.allclose(sorted(p["box"]["size"]), [0.15, 0.2, 0.25], atol=2e-3)
    assert abs(abs(p["plane"]["offset"])) < 5e-4 and abs(abs(p["plane"]["normal"][2]) - 1) < 1e-3
    # the shapes are posed csdf primitives: their surfaces pass through their inliers
    for d in dets:
        if d.kind != "plane":
            rms = float(np.sqrt(np.mean(np.asarray(d.shape(P[d.inliers])) ** 2)))
            assert rms < 2e-3 and math.isclose(d.rmse, rms, rel_tol=0.05)
    # no point is in two detections
    allin = np.concatenate([d.inliers for d in dets])
    assert len(allin) == len(np.unique(allin))


def test_detect_primitives_does_not_depend_on_the_points_order(prim_scene):
    """The search runs on the points in Morton order: the same cloud shuffled gives the
    same detections (inliers named in the input's order); ``reorder=False`` searches the
    points as given and still finds every kind."""
    P, N, _ = prim_scene
    perm = np.random.default_rng(3).permutation(len(P))
    a = csdf.detect_primitives(P, N, seed=0)
    b = csdf.detect_primitives(P[perm], N[perm], seed=0)
    assert [d.kind for d in a] == [d.kind for d in b]
    for x, y in zip(a, b):
        assert np.array_equal(x.inliers, np.sort(perm[y.inliers]))
        assert x.rmse == pytest.approx(y.rmse, rel=1e-9)
    c = csdf.detect_primitives(P, N, seed=0, reorder=False)
    assert sorted(d.kind for d in c) == sorted(d.kind for d in a)


def test_detect_primitives_finds_no_shell_in_a_volume_of_noise():
    # a shell through a scattered cloud gathers points whose normals agree only by
    # chance (_agreement); a sphere's surface among the same noise is still found. (A
    # plane through such a cloud is found in about 1 draw of 120, 4 before the search
    # ran in Morton order: its normals agree as poorly as a real floor's at 2.8 cm of
    # range noise, so they cannot tell it.)
    for s in (2, 3, 4):  # clouds where cylinders and a torus were found before the test
        P = np.random.default_rng(s).uniform(-1, 1, (5000, 3))
        for seed in (0, 1, 2):
            assert [d for d in csdf.detect_primitives(P, seed=seed) if d.kind != "plane"] == []
    rng = np.random.default_rng(14)
    u = rng.normal(size=(3000, 3))
    shell = 0.4 * u / np.linalg.norm(u, axis=1, keepdims=True) + rng.normal(0, 0.002,
                                                                            (3000, 3))
    dets = csdf.detect_primitives(np.concatenate([shell, rng.uniform(-1, 1, (1500, 3))]),
                                  seed=0)
    assert [d.kind for d in dets] == ["sphere"]
    assert abs(dets[0].params["radius"] - 0.4) < 0.005


def test_detect_primitives_is_deterministic_and_filters_kinds(prim_scene):
    P, N, _ = prim_scene
    a = csdf.detect_primitives(P, N, seed=3, kinds="plane,sphere")
    b = csdf.detect_primitives(P, N, seed=3, kinds=("plane", "sphere"))
    assert [d.kind for d in a] == [d.kind for d in b]
    assert all(np.array_equal(x.inliers, y.inliers) for x, y in zip(a, b))
    assert {d.kind for d in a} <= {"plane", "sphere"} and "sphere" in {d.kind for d in a}


def test_detect_primitives_estimates_normals(prim_scene):
    P, _, L = prim_scene
    dets = csdf.detect_primitives(P, kinds=("sphere", "plane"), seed=0)
    sph = [d for d in dets if d.kind == "sphere"]
    assert sph and abs(sph[0].params["radius"] - 0.1) < 1e-3


def _noisy_samples(shape, n, seed, noise=0.001):
    """``n`` points on ``shape`` with Gaussian noise of ``noise`` along the normals, and
    the normals."""
    rng = np.random.default_rng(seed)
    p, q = csdf.sample_surface(shape, n, seed=rng)
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    return p + rng.normal(0.0, noise, (len(p), 1)) * q, q



def test_exact_copies_are_what_numpy_unique_finds():
    """The hashed grouping against ``np.unique(axis=0)``: copies scattered through the
    cloud, rows that are each other's permutations, signed zeros; NaN rows equal none."""
    rng = np.random.default_rng(3)
    P = rng.integers(0, 4, (5000, 3)).astype(float)  # many copies, many permuted rows
    P[::11] = -0.0
    P[7] = [0.0, 0.0, 0.0]
    _, first, inv = np.unique(P, axis=0, return_index=True, return_inverse=True)
    assert np.array_equal(exact_copies(P), first[inv.ravel()])
    assert exact_copies(P)[7] == 0 and P[0].tolist() == [0.0, 0.0, 0.0]
    Q = rng.normal(size=(200, 3))
    Q[[4, 9]] = np.nan
    Q[12] = Q[3]
    rep = exact_copies(Q)
    assert rep[4] == 4 and rep[9] == 9 and rep[12] == 3
    assert np.array_equal(np.delete(rep, 12), np.delete(np.arange(200), 12))
    assert exact_copies(np.zeros((0, 3))).shape == (0,)


def test_repeated_points_are_found_as_the_distinct_ones_with_every_copy():
    P = np.array([[0, 0, 0], [1, 0, 0], [0, 0, 0], [2, 0, 0], [1, 0, 0], [0, 0, 0.0]])
    keep, owner = distinct_points(P)
    assert keep.tolist() == [0, 1, 3] and owner.tolist() == [0, 1, 0, 2, 1, 0]
    assert with_copies(np.array([0, 2]), owner).tolist() == [0, 2, 3, 5]
    assert distinct_points(P[[0, 1, 3]]) is None
    # a sphere whose points each come six times (a cloud read off a mesh's triangles
    # repeats every vertex about that often): its neighbours were its own copies at
    # distance 0, and from five copies up the sphere was lost; now it is the sphere of
    # the distinct points, with every copy
    p, q = _noisy_samples(csdf.sphere(0.3), 2000, seed=4)
    one = csdf.detect_primitives(p, q, seed=0)
    six = csdf.detect_primitives(np.repeat(p, 6, axis=0), np.repeat(q, 6, axis=0), seed=0)
    assert [d.kind for d in six] == [d.kind for d in one] == ["sphere"]
    assert six[0].params == one[0].params
    assert np.array_equal(six[0].inliers, with_copies(one[0].inliers, np.repeat(
        np.arange(len(p)), 6)))

@pytest.fixture(scope="module")
def hard_scene():
    """Primitives at 1 mm noise and the density of a 40k-point benchmark scene (25,000
    points per square metre), with the cases that went wrong: a
    long box whose end faces hold fewer points than ``min_points`` (found with the
    box, not on their own), a small cone (base and side), a torus, a sphere, a
    cylinder, a floor plane."""
    R = S.frame_z([0.3, -0.5, 0.8])
    shapes = [
        ("box", csdf.box((0.09, 0.085, 0.27)).rotate(R).translate((0.3, 0.3, 0.25))),
        ("cone", csdf.cone(0.05, 0.06).rotate(0.7, (1, 0, 0)).translate((-0.3, 0.3, 0.15))),
        ("torus", csdf.torus(0.12, 0.035).rotate(0.5, (1, 1, 0)).translate((-0.3, -0.3, 0.2))),
        ("sphere", csdf.sphere(0.1).translate((0.3, -0.3, 0.2))),
        ("cylinder", csdf.cylinder(0.1, 0.2).rotate(1.1, (0, 1, 0)).translate((0.0, 0.0, 0.3))),
    ]
    areas = [2 * (0.09 * 0.085 + 0.085 * 0.27 + 0.09 * 0.27),
             math.pi * 0.05 * (0.05 + math.hypot(0.05, 0.06)),
             4 * math.pi ** 2 * 0.12 * 0.035, 4 * math.pi * 0.01,
             2 * math.pi * 0.1 * 0.2 + 2 * math.pi * 0.01]
    pts, nrm, lab = [], [], []
    for i, ((_, s), a) in enumerate(zip(shapes, areas)):
        p, q = _noisy_samples(s, int(25_000 * a), seed=10 + i)
        pts.append(p), nrm.append(q), lab.append(np.full(len(p), i))
    rng = np.random.default_rng(3)
    k = int(25_000 * 0.49)
    pts.append(np.c_[rng.uniform(-0.35, 0.35, (k, 2)), rng.normal(-0.2, 0.001, k)])
    nrm.append(np.tile([0, 0, 1.0], (k, 1)))
    lab.append(np.full(k, len(shapes)))
    return (np.concatenate(pts), np.concatenate(nrm), np.concatenate(lab), R,
            [k for k, _ in shapes] + ["plane"])


def test_detect_primitives_sizes_within_a_fifth_of_a_millimetre(hard_scene):
    # at 1 mm noise; the statistical bound (Cramer-Rao) of these sizes is 0.01-0.06 mm
    # (the small cone's base radius about 0.15 mm); before this was checked, the long
    # box came out 0.8 mm short (its end faces missed), sizes fitted on 600 of the
    # points were several bounds off, and cone radii 0.09 mm large on average (points
    # inside near an edge measured to the other face)
    P, N, L, R, kinds = hard_scene
    dets = csdf.detect_primitives(P, N, seed=0, min_points=200)
    got = {}
    for d in dets:
        lab = np.bincount(L[d.inliers], minlength=len(kinds))
        j = int(np.argmax(lab))
        assert lab[j] >= 0.98 * len(d.inliers), d
        assert kinds[j] not in got, (d, got)  # one detection a primitive
        got[kinds[j]] = d
    assert {k: d.kind for k, d in got.items()} == {k: k for k in kinds}
    assert all(np.count_nonzero(L[got[k].inliers] == j) > 0.9 * np.count_nonzero(L == j)
               for j, k in enumerate(kinds))
    p = {k: d.params for k, d in got.items()}
    box = got["box"]
    axis = np.abs(np.asarray(box.params["rotation"]).T @ R).argmax(axis=0)
    size = np.asarray(box.params["size"])[axis]
    assert np.all(np.abs(size - [0.09, 0.085, 0.27]) / 2 < 2e-4), size
    assert abs(p["cone"]["r1"] - 0.05) < 5e-4  # (its bound: about 0.15 mm)
    assert abs(p["torus"]["major"] - 0.12) < 2e-4 and abs(p["torus"]["minor"] - 0.035) < 2e-4
    assert abs(p["sphere"]["radius"] - 0.1) < 2e-4
    assert abs(p["cylinder"]["radius"] - 0.1) < 2e-4
    assert abs(p["cylinder"]["height"] - 0.2) < 1e-3
    assert abs(p["plane"]["offset"] - (-0.2)) < 1e-4


def test_detected_cone_radius_is_unbiased():
    # 20,000 points on one cone at 1 mm noise: the bound of its base radius is about
    # 0.02 mm, so a bias of 0.09 mm (points inside near the rim measured to the base)
    # would show
    P, N = _noisy_samples(csdf.cone(0.1, 0.15).rotate(0.4, (1, 0, 0)), 20_000, seed=5)
    dets = csdf.detect_primitives(P, N, seed=0, kinds=("cone",))
    assert len(dets) == 1 and dets[0].kind == "cone"
    p = dets[0].params
    assert abs(p["r1"] - 0.1) < 5e-5
    assert abs(p["angle"] - math.atan2(0.1, 0.15)) < 1e-3
    assert abs(p["height"] - 0.15) < 2e-4  # apex to base, not the frustum's height
    assert p["frustum_height"] < p["height"]


def test_flat_share_keeps_a_shallow_cap():
    """A spherical cap whose bulge is about four noise levels: one plane explains about
    0.3-0.47 of it (:func:`_flat_share`'s random planes), so ``flat_share=0.25`` drops
    the sphere as a flat patch, while the default (0.5) and ``flat_share=1`` (csdf.infer's
    search among unexplained points) keep it; both held for detection seeds 0-9."""
    rng = np.random.default_rng(0)
    z = rng.uniform(math.cos(0.3), 1.0, 400)  # uniform by area on the cap
    a = rng.uniform(0.0, 2 * math.pi, 400)
    N = np.column_stack([np.sqrt(1 - z * z) * np.cos(a), np.sqrt(1 - z * z) * np.sin(a), z])
    P = 0.5 * N + rng.normal(0.0, 0.002, (400, 3))
    assert csdf.detect_primitives(P, N, kinds=("sphere",), seed=0, min_points=30,
                                  flat_share=0.25) == []
    for share in (None, 1.0):
        dets = csdf.detect_primitives(P, N, kinds=("sphere",), seed=0, min_points=30,
                                      flat_share=share)
        assert [d.kind for d in dets] == ["sphere"]
        assert abs(dets[0].params["radius"] - 0.5) < 0.02
    for bad in (0.0, 1.5):
        with pytest.raises(csdf.CsdfError, match="flat_share"):
            csdf.detect_primitives(P, N, flat_share=bad)


@pytest.mark.parametrize("kw, match", [
    ({"points": np.zeros((5, 2))}, "shape"),
    ({"points": np.array([[0, 0, np.nan]] * 5)}, "row 0"),
    ({"kinds": ("plane", "blob")}, "unknown kind 'blob'"),
    ({"epsilon": -1.0}, "epsilon"),
    ({"normal_tolerance": 95}, "normal_tolerance"),
    ({"normals": np.zeros((10, 3))}, "normals"),
])
def test_detect_primitives_bad_input(kw, match):
    args = {"points": np.random.default_rng(0).random((10, 3))}
    args.update(kw)
    with pytest.raises(csdf.CsdfError, match=match):
        csdf.detect_primitives(**args)


# -- detect: known models in a scan ---------------------------------------------------

def _floor_scene() -> csdf.Scene:
    """A scene holding a 6 m x 6 m floor slab whose top is z = 0."""
    scene = csdf.Scene()
    scene.add(csdf.box((6.0, 6.0, 0.05)), pose=csdf.Pose(translation=(0, 0, -0.025)),
              name="floor")
    return scene


def _yawed(angle: float, t) -> csdf.Pose:
    """A pose turned by ``angle`` radians about z and moved by ``t``."""
    c, s = math.cos(angle), math.sin(angle)
    return csdf.Pose([[c, -s, 0], [s, c, 0], [0, 0, 1]], t)


def _scanned(model: str, pose: csdf.Pose, params: dict, eye, target, fov: float,
             size: tuple[int, int], noise: float, seed: int):
    """``(points, instance ids, camera)``: the zoo ``model`` at ``pose`` with ``params``
    on the floor (instance 1), scanned from ``eye`` looking at ``target`` (no
    outliers)."""
    scene = _floor_scene()
    scene.add(model, pose=pose, params=params, name=model)
    cam = csdf.Camera.look_at(eye=eye, target=target, fov=fov, width=size[0],
                              height=size[1])
    P, _, inst = csdf.scan(scene, cam, noise=noise, outliers=0.0, seed=seed)
    return P, inst, cam


@pytest.fixture(scope="module")
def clutter():
    scene = _floor_scene()
    stool_pose = _yawed(0.4, (0.1, 0.0, 0.0))
    params = {"height": 0.6, "seat_radius": 0.17}
    scene.add("stool", pose=stool_pose, params=params, name="stool")
    scene.add(csdf.sphere(0.15), pose=csdf.Pose(translation=(-0.7, 0.3, 0.15)), name="ball")
    cam = csdf.Camera.look_at(eye=(0.0, -2.6, 1.6), target=(-0.2, 0.1, 0.3), fov=50,
                              width=200, height=150)
    P, N, inst = csdf.scan(scene, cam, noise=0.004, outliers=0.005, seed=1)
    return P, N, inst, cam, stool_pose, params


def _camera_pose(cam, pose):
    """The object-to-camera pose of an object-to-world one."""
    R = cam.R.T @ pose.rotation
    t = cam.R.T @ (pose.translation - cam.t)
    return csdf.Pose(R, t)


def test_detect_finds_the_model_and_rejects_the_distractor(clutter):
    P, N, inst, cam, pose, params = clutter
    dets = csdf.detect(P, ["stool", "table"], viewpoint=(0, 0, 0), seed=0)
    assert [d.model for d in dets] == ["stool"], dets
    d = dets[0]
    gt = _camera_pose(cam, pose)
    pts = csdf.metrics.model_points(csdf.zoo.load("stool"), 300, params=params)
    syms = csdf.metrics.symmetries(csdf.zoo.load("stool"), params=params)
    diam = csdf.metrics.diameter(pts)
    assert csdf.metrics.mssd(pts, d.pose, gt, syms) < 0.05 * diam
    assert abs(d.params["height"] - 0.6) < 0.03
    assert 0.8 <= d.score <= 1.0
    assert np.mean(inst[d.inliers] == 1) > 0.95  # the stool's own points
    again = csdf.detect(P, "stool,table", viewpoint=(0, 0, 0), seed=0)
    assert np.array_equal(again[0].pose.matrix, d.pose.matrix)
    sc = csdf.detections_to_scene(dets)
    assert len(sc) == 1
    q = sc.query(gt.apply(pts[:50]))
    assert np.all(np.abs(q.distance) < 0.05)


def test_detect_bad_models():
    P = np.random.default_rng(0).random((100, 3))
    with pytest.raises(csdf.CsdfError, match="unknown zoo model 'chiar'"):
        csdf.detect(P, ["chiar"])
    with pytest.raises(csdf.CsdfError, match="no models"):
        csdf.detect(P, [])
    with pytest.raises(csdf.CsdfError, match="viewpoint"):
        csdf.detect(P, ["stool"], viewpoint=(0, 0))
    with pytest.raises(csdf.CsdfError, match="three numbers"):
        csdf.detect(P, ["stool"], viewpoint="0,0,0")
    with pytest.raises(csdf.CsdfError, match="model 'model_0' has no finite bounds") as e:
        csdf.detect(P, [csdf.plane((0, 0, 1), 0)])
    assert "bounds=" not in str(e.value)  # detect takes no bounds
    with pytest.raises(csdf.CsdfError, match="twice"):
        csdf.detect(P, ["stool", "stool"])
    for bad in (0, -1, 1.5, True):
        with pytest.raises(csdf.CsdfError, match="max_instances"):
            csdf.detect(P, ["stool"], max_instances=bad)


def test_cli_detect(clutter, tmp_path):
    from typer.testing import CliRunner

    from csdf.cli import app
    from csdf.io import write_points

    P, N, *_ = clutter
    ply = tmp_path / "scan.ply"
    write_points(ply, P, N, viewpoint=(0.0, 0.0, 0.0))
    out = tmp_path / "scene.json"
    png = tmp_path / "det.png"
    r = CliRunner().invoke(app, ["detect", str(ply), "--models", "stool,table", "-o",
                                 str(out), "--picture", str(png)])
    assert r.exit_code == 0, r.output
    data = json.loads(out.read_text())
    assert "stool" in json.dumps(data)
    sc = csdf.Scene.load(out)
    assert len(sc) == 1
    assert png.stat().st_size > 10_000
    r = CliRunner().invoke(app, ["detect", str(ply), "--models", "nosuch", "-o", str(out)])
    assert r.exit_code != 0 and "nosuch" in r.output
    # an output folder that does not exist is reported before the work, and nothing is
    # written (the scene was written before the picture failed)
    other = tmp_path / "other.json"
    r = CliRunner().invoke(app, ["detect", str(ply), "--models", "stool", "-o", str(other),
                                 "--picture", str(tmp_path / "no" / "p.png")])
    assert r.exit_code == 2 and "folder" in r.output and "does not exist" in r.output
    assert not other.exists()
    # a bad row is reported with the file's name; an empty scan is an error
    bad = tmp_path / "bad.ply"
    bad.write_text("ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\n"
                   "property float y\nproperty float z\nend_header\n0 0 1\nnan 0 1\n")
    r = CliRunner().invoke(app, ["detect", str(bad), "--models", "stool", "-o", str(other)])
    assert r.exit_code == 2 and "bad.ply: points: row 1 is not finite" in r.output
    empty = tmp_path / "empty.ply"
    empty.write_text("ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\n"
                     "property float y\nproperty float z\nend_header\n")
    r = CliRunner().invoke(app, ["detect", str(empty), "--models", "stool", "-o", str(other)])
    assert r.exit_code == 2 and "no points" in r.output and not other.exists()


def test_a_cloud_in_millimetres_is_named_when_nothing_is_found(clutter):
    P, *_ = clutter
    with pytest.warns(UserWarning, match=r"millimetres against metres: scale them by 0.001"):
        assert csdf.detect(1000.0 * P, ["stool"], viewpoint=(0, 0, 0), seed=0) == []


def test_picture_projection_camera_and_world_frames():
    from csdf.detect.picture import _project

    # camera frame (x right, y down, z forward): a pinhole at the origin
    P = np.array([[0.0, 0.0, 2.0], [1.0, -1.0, 2.0]])
    uv = _project(P, np.zeros(3))
    assert np.allclose(uv, [[0, 0], [0.5, 0.5]])
    # world frame, z up: the target at the centre, higher points higher in the
    # picture, and points to the right of the sensor (looking along -x) on the right
    vp = np.array([3.0, 0.0, 1.0])
    target = np.array([0.0, 0.0, 1.0])
    Q = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 2.0], [0.0, 1.0, 1.0]])  # +y: right
    uv = _project(Q, vp, target)
    assert np.allclose(uv[0], 0)
    assert uv[1, 1] > 0.2 and abs(uv[1, 0]) < 1e-12
    assert uv[2, 0] > 0.2 and abs(uv[2, 1]) < 1e-12
    # no viewpoint: a view down -z
    assert np.allclose(_project(Q, None), Q[:, :2])



def test_detect_without_a_viewpoint_takes_up_from_what_stands_on_the_floor(clutter):
    # without a sensor to face, the floor's normal from unoriented normals had either
    # sign; when it pointed down every object lay "below the support" and nothing was
    # found (the benchmark's scene 5: 0 detections without a viewpoint, 4 of 5 with
    # the side that holds the points off the floor taken as up)
    P, N, inst, cam, pose, params = clutter
    dets = csdf.detect(P, ["stool", "table"], seed=0)
    assert [d.model for d in dets] == ["stool"], dets
    pts = csdf.metrics.model_points(csdf.zoo.load("stool"), 300, params=params)
    syms = csdf.metrics.symmetries(csdf.zoo.load("stool"), params=params)
    err = csdf.metrics.mssd(pts, dets[0].pose, _camera_pose(cam, pose), syms)
    assert err < 0.1 * csdf.metrics.diameter(pts)
    # the same cloud upside down (every normal's sign flipped with it) gives the same
    # stool, turned over with the cloud
    flip = csdf.Pose(np.diag([1.0, -1.0, -1.0]))
    again = csdf.detect(flip.apply(P), ["stool", "table"], seed=0)
    assert [d.model for d in again] == ["stool"], again
    err = csdf.metrics.mssd(pts, again[0].pose, flip @ _camera_pose(cam, pose), syms)
    assert err < 0.1 * csdf.metrics.diameter(pts)


def test_detect_on_a_scan_given_twice_finds_the_same_stool_with_both_copies(clutter):
    P, N, *_ = clutter
    once = csdf.detect(P, ["stool"], viewpoint=(0, 0, 0), seed=0)
    twice = csdf.detect(np.concatenate([P, P]), ["stool"], viewpoint=(0, 0, 0), seed=0)
    assert [d.model for d in twice] == [d.model for d in once] == ["stool"]
    assert np.array_equal(twice[0].pose.matrix, once[0].pose.matrix)
    assert np.array_equal(twice[0].inliers, np.concatenate([once[0].inliers,
                                                            once[0].inliers + len(P)]))


def test_detect_on_a_scan_given_twice_with_jitter_finds_the_same_stool(clutter):
    """The copy moved by 1 mm (at 4 mm noise; a frame added twice, say) is a cloud of
    near-copies: the nearest-neighbour spacing collapsed to the jitter and the fit's
    visibility check found every model ray empty, so nothing was found from 0.5 to
    2 mm. The near-copies fold into the first copy, so the result is the single scan's
    (to the few points that fold with another point of the scan) with the copies among
    the inliers."""
    P, N, *_ = clutter
    once = csdf.detect(P, ["stool"], viewpoint=(0, 0, 0), seed=0)
    rng = np.random.default_rng(5)
    for jitter in (0.0005, 0.001):
        Q = np.concatenate([P, P + rng.normal(0.0, jitter, P.shape)])
        twice = csdf.detect(Q, ["stool"], viewpoint=(0, 0, 0), seed=0)
        assert [d.model for d in twice] == ["stool"], (jitter, twice)
        assert np.allclose(twice[0].pose.matrix, once[0].pose.matrix, atol=1e-4)
        copies = np.setdiff1d(twice[0].inliers, once[0].inliers) - len(P)
        assert len(copies) >= 0.95 * len(once[0].inliers)
        assert np.isin(copies, once[0].inliers).mean() > 0.95


def test_near_copies_fold_only_where_most_points_have_one():
    rng = np.random.default_rng(0)
    g = np.stack(np.meshgrid(np.arange(30.0), np.arange(30.0)), -1).reshape(-1, 2) * 0.01
    P = np.c_[g, rng.normal(0.0, 0.001, len(g))]  # a grid of 1 cm, 1 mm noise
    assert distinct_points(P) is None
    near = P + rng.normal(0.0, 0.0005, P.shape)  # each point again, 0.5 mm off
    keep, owner = distinct_points(np.concatenate([P, near, P[:5]]))
    assert keep.tolist() == list(range(len(P)))
    assert owner.tolist() == [*range(len(P)), *range(len(P)), *range(5)]
    # random samples of a surface have close pairs, not near-copies: left alone
    Q = rng.uniform(0.0, 1.0, (3000, 3)) * (1.0, 1.0, 0.0)
    assert distinct_points(Q) is None


def test_a_cloud_s_own_neighbourhood_tells_its_copies_as_its_own_search_does():
    """``distinct_points(P, nb)`` with the cloud's neighbourhood answers as without it:
    None for a cloud without copies (from the neighbour distances, no search of its
    own), the same groups for exact copies, near-copies, and both."""
    rng = np.random.default_rng(5)
    g = np.stack(np.meshgrid(np.arange(30.0), np.arange(30.0)), -1).reshape(-1, 2) * 0.01
    P = np.c_[g, rng.normal(0.0, 0.001, len(g))]
    near = np.concatenate([P, P + rng.normal(0.0, 0.0005, P.shape)])
    clouds = {"plain": P, "exact": np.concatenate([P, P[::7]]), "near": near,
              "both": np.concatenate([near, P[:40]]),
              "random": rng.uniform(0.0, 1.0, (3000, 3)) * (1.0, 1.0, 0.0),
              "tiny": P[:6], "tiny copies": P[[0, 1, 2, 0, 3, 1]]}
    for name, Q in clouds.items():
        a, b = distinct_points(Q), distinct_points(Q, neighbourhood(Q, want_normals=False))
        assert (a is None) == (b is None), name
        if a is not None:
            assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1]), name
    assert distinct_points(P, neighbourhood(P, want_normals=False)) is None
    assert distinct_points(clouds["exact"]) is not None


def test_typical_spacing_skips_near_copies():
    from scipy.spatial import cKDTree

    from csdf.points import NEAR_K, has_near_copies, typical_spacing

    g = np.stack(np.meshgrid(np.arange(20.0), np.arange(20.0)), -1).reshape(-1, 2)
    P = np.c_[g, np.zeros(len(g))] * 0.01

    def spacing(X):
        dd, _ = cKDTree(X).query(X, k=NEAR_K + 1)
        return typical_spacing(dd[:, 1:]), has_near_copies(dd[:, 1:])

    assert spacing(P) == (pytest.approx(0.01), False)
    twice = np.concatenate([P, P + (0.0003, 0.0002, 0.0)])
    assert spacing(twice) == (pytest.approx(0.01, rel=0.05), True)
    with pytest.raises(ValueError, match="neighbour distances"):
        typical_spacing(np.zeros((5, 2)))


def test_feet_split_a_cluster_wider_than_the_model():
    from csdf.detect.objects import FEET_SPLIT, _feet

    rng = np.random.default_rng(0)
    F = np.concatenate([rng.normal((0, 0, 0), 0.05, (200, 3)),
                        rng.normal((1, 0, 0), 0.05, (200, 3))])
    F[:, 2] = 0
    one = _feet(F, foot=2.0)  # the model is wider than the cluster: its centre only
    assert len(one) == 1 and np.allclose(one[0], F.mean(0))
    feet = _feet(F, foot=0.3)
    assert len(feet) == 1 + sum(range(2, FEET_SPLIT + 1))
    two = np.array(sorted(feet[1:3], key=lambda c: c[0]))
    assert np.allclose(two, [[0, 0, 0], [1, 0, 0]], atol=0.02)
    assert all(np.array_equal(a, b) for a, b in zip(feet, _feet(F, foot=0.3)))


# -- detect: the pieces of the object detector ----------------------------------------

def test_gain_is_a_capped_soft_count():
    from csdf.detect.objects import GAIN_CAP, GAIN_CAP_LOG, _gain

    d = np.array([0.0, 0.5, 1.0, 2.0, GAIN_CAP, 10.0]) * 0.01
    g = _gain(d, 0.01)
    assert g[0] == pytest.approx(GAIN_CAP_LOG)
    assert np.all(np.diff(g) <= 0) and g[-2] == 0.0 and g[-1] == 0.0


def test_model_heights_follow_their_parameters():
    from csdf.detect.objects import _heights
    from csdf.field import as_field

    fld = as_field(csdf.zoo.load("table"), what="test")
    b = np.array(fld.bounds)
    h = _heights(fld, [None, {"height": 0.65}, {"height": 1.0}], b)
    # the probe's tolerance is half a column spacing over the footprint
    assert h == pytest.approx([0.75, 0.65, 1.0], abs=0.03)


@pytest.fixture(scope="module")
def chair_scan():
    scene = _floor_scene()
    pose = _yawed(1.0, (0.0, 0.2, 0.0))
    scene.add("chair", pose=pose, name="chair")
    scene.add(csdf.box((0.4, 0.4, 0.4)), pose=csdf.Pose(translation=(0.1, -0.6, 0.2)),
              name="crate")  # in front of the chair: hides part of it
    cam = csdf.Camera.look_at(eye=(0.3, -2.6, 1.6), target=(0.0, 0.2, 0.4), fov=45,
                              width=200, height=150)
    P, N, inst = csdf.scan(scene, cam, noise=0.006, outliers=0.0, seed=2)
    return P, inst, _camera_pose(cam, pose)


def _prepared(P, models):
    from csdf.detect.objects import _models_arg, _prepare

    return _prepare(P, _models_arg(models), None, np.zeros(3), 0, None, None, True)


def test_yaw_scan_turns_a_fit_back_to_the_seen_yaw(chair_scan):
    P, inst, gt = chair_scan
    run = _prepared(P, ["chair"])
    m = run.models[0]
    nrm = run.plane[0]
    R0, t0 = gt.rotation, gt.translation
    for turn in (math.pi / 2, math.pi):  # a side view's and a front/back confusion
        K = np.array([[0, -nrm[2], nrm[1]], [nrm[2], 0, -nrm[0]], [-nrm[1], nrm[0], 0]])
        Rt = np.eye(3) + math.sin(turn) * K + (1 - math.cos(turn)) * K @ K
        c = R0 @ m.centre + t0
        R, t = Rt @ R0, Rt @ (t0 - c) + c
        angles, score, _ = run._yaw_scan(m, R, t, {})
        best = float(angles[int(np.argmax(score))])
        back = (best + turn) % (2 * math.pi)  # zero when the scan undoes the turn
        assert min(back, 2 * math.pi - back) < math.radians(10)


def test_screen_costs_only_what_can_win_and_finds_the_same_best(chair_scan):
    """The screen's pruned search (the lower bound first) returns exactly the best of
    costing every pose at every parameter set."""
    from csdf.detect.objects import REFINE_TOP

    P, inst, _ = chair_scan
    run = _prepared(P, ["chair", "table"])
    idx = max(run.clusters, key=lambda c: int(np.sum(inst[c] == 1)))
    S = run.P[run._subsample(idx, 200)]
    for m in run.models:
        poses = run._upright(m, run.P[idx])
        sets = [0, 1, 2]
        full = sorted((float(c), i, k) for k in sets
                      for i, c in enumerate(run._two_sided(m, poses, S, m.starts[k])))
        assert run._screen(m, poses, S, sets) == full[:REFINE_TOP]


def test_occluded_points_are_those_behind_scan_points(chair_scan):
    P, inst, gt = chair_scan
    run = _prepared(P, ["chair"])
    d = P / np.linalg.norm(P, axis=1, keepdims=True)
    r = np.linalg.norm(P, axis=1)
    pick = np.arange(0, len(P), 97)
    behind = d[pick] * (r[pick] + 0.2)[:, None]
    before = d[pick] * (r[pick] - 0.2)[:, None]
    assert run._occluded(behind, 0.05).all()
    assert not run._occluded(before, 0.05).any()
    assert not run._occluded(P[pick], 0.05).any()


def test_detect_rejects_a_model_that_is_not_there(clutter):
    P, *_ = clutter
    assert csdf.detect(P, ["chair"], viewpoint=(0, 0, 0), seed=0) == []


def test_band_fraction_counts_the_fits_own_clusters():
    from csdf.detect.objects import BAND, _band_fraction

    s = 0.01
    on = np.full(300, 1.0 * s)             # on the surface, cluster 0
    off_own = np.full(100, 4.0 * s)        # just off it, cluster 0: structure it lacks
    far = np.full(50, 2.0 * BAND * s)      # outside the band: not judged
    d = np.concatenate([on, off_own, far])
    lab = np.zeros(len(d), dtype=int)
    keep = np.ones(len(d), dtype=bool)
    assert _band_fraction(d, lab, keep, s, 50) == pytest.approx(0.75)
    # the same points off the surface in a neighbour's cluster are no evidence
    lab2 = lab.copy()
    lab2[300:400] = 1
    assert _band_fraction(d, lab2, keep, s, 50) == 1.0
    # ... unless the fit also explains many of that cluster's points (its own too)
    d3 = d.copy()
    d3[300:360] = 0.5 * s
    assert _band_fraction(d3, lab2, keep, s, 50) == pytest.approx(360 / 400)
    # support points are not judged
    assert _band_fraction(d, lab, np.arange(len(d)) < 300, s, 50) == 1.0


def test_detect_finds_a_partly_hidden_chair(chair_scan):
    P, inst, gt = chair_scan
    dets = csdf.detect(P, ["chair", "table"], viewpoint=(0, 0, 0), seed=0)
    assert [d.model for d in dets] == ["chair"], dets
    pts = csdf.metrics.model_points(csdf.zoo.load("chair"), 300)
    diam = csdf.metrics.diameter(pts)
    assert csdf.metrics.mssd(pts, dets[0].pose, gt) < 0.1 * diam


def test_detect_on_a_bare_floor_finds_nothing():
    rng = np.random.default_rng(0)
    P = np.column_stack([rng.uniform(-1, 1, 3000), rng.uniform(-1, 1, 3000),
                         2.0 + rng.normal(0, 0.002, 3000)])  # a plane facing the sensor
    assert csdf.detect(P, ["stool"], viewpoint=(0, 0, 0), seed=0) == []


def _lamp_prepared(pose, params, eye, target, noise, seed):
    """A lamp at ``pose`` with ``params`` scanned from ``eye`` (200 x 150, 40 degrees)
    and prepared for lamps: ``(points, instance ids, run, model, camera-frame pose,
    all its parameters)``."""
    P, inst, cam = _scanned("lamp", pose, params, eye, target, 40, (200, 150), noise, seed)
    run = _prepared(P, ["lamp"])
    m = run.models[0]
    full = {p.name: float(p.default) for p in m.fld.program.params}
    full.update(params)
    return P, inst, run, m, _camera_pose(cam, pose), full


@pytest.fixture(scope="module")
def lamp_scan():
    """A lamp turned by 0.7 rad, seen from above into its shade at 12 mm range noise
    (the benchmark's clutter scenes have 11-23 mm): its turn rests on three 5 mm
    spokes."""
    P, inst, run, m, gt, full = _lamp_prepared(
        _yawed(0.7, (0.0, 0.3, 0.0)), {"shade_height": 0.2, "stem_height": 0.3},
        (0.0, -1.4, 1.5), (0.0, 0.3, 0.3), 0.012, 3)
    base = csdf.fit(m.shape, P[inst == 1][:200], init={
        "rotation": gt.rotation, "translation": gt.translation, "params": full},
        estimate=("pose",), max_iter=1, escape=False, coarse=False)
    truth = dataclasses.replace(base, rotation=gt.rotation, translation=gt.translation,
                                params=full)
    return P, inst, run, m, gt, truth


def test_turn_profile_finds_the_lamps_symmetry_and_its_spokes(lamp_scan):
    _, _, run, m, _, _ = lamp_scan
    full = np.radians(np.arange(0.0, 360.0, 5.0))
    sym, moved = run._turn_profile(m, full)
    assert np.degrees(full[sym]).round().tolist() == [0.0, 120.0, 240.0]
    assert moved[12] < YAW_DOUBT  # 60 degrees moves only the spokes
    chair = _prepared(run.P, ["chair"])
    cs, cm = chair._turn_profile(chair.models[0], full)
    assert cs.tolist() == [True] + [False] * 71
    assert cm[6:67].min() > YAW_DOUBT  # a chair's turn moves much of it


def test_ray_cast_turns_peak_at_the_lamps_own(lamp_scan):
    _, _, run, m, _, truth = lamp_scan
    rays = run._ray_set(m, truth)
    angles = np.radians(np.arange(0.0, 120.0, 5.0))
    score, _ = run._yaw_scan_rays(m, truth, rays, angles)
    assert int(np.argmax(score)) == 0
    # the spokes' rays: tens of explained points above the typical turn
    assert score[0] - np.median(score) > 10 * GAIN_CAP_LOG


def test_a_ray_refit_brings_a_shade_fitted_short_back(lamp_scan):
    """The lamp at its true pose with its shade 15 mm short and its stem 7.5 mm long
    (the detector's point fits of the benchmark's lamps: shade heights 10 mm off at
    the median, 23 mm at the 90th percentile): refitted to its rays
    (:meth:`_Run._ray_refit`, the last step's refit), both come within 3 mm of the
    truth, and its rays score the refit more than the start (a
    range sensor's rays place the shade's rims, seen in outline, where the points,
    blurred by 12 mm of noise, do not)."""
    _, inst, run, m, _, truth = lamp_scan
    p = dict(truth.params)
    off = dataclasses.replace(truth, params={**p, "shade_height": p["shade_height"] - 0.015,
                                             "stem_height": p["stem_height"] + 0.0075})
    rays = run._ray_set(m, off)
    own = run._own_clusters(np.flatnonzero(inst == 1))
    ref = run._ray_refit(m, off, rays, own)
    assert abs(ref.params["shade_height"] - p["shade_height"]) < 0.003
    assert abs(ref.params["stem_height"] - p["stem_height"]) < 0.003
    pose = [(np.asarray(off.rotation), np.asarray(off.translation))]
    before = run._ray_scores(m, dict(off.params), pose, rays, own)[0]
    after = run._ray_scores(m, dict(ref.params), pose, rays, own)[0]
    assert after > before + 5 * GAIN_CAP_LOG
    assert np.array_equal(ref.rotation, off.rotation)  # its pose is held


def test_own_points_in_front_count_against_a_turn(lamp_scan):
    """A lamp turned by 60 degrees (its spokes halfway between the true ones): with the
    lamp's own cluster given, the true spokes' points floating in front of its shade
    count against it too, so the true turn's lead grows."""
    _, inst, run, m, gt, truth = lamp_scan
    rays = run._ray_set(m, truth)
    idx = max(run.clusters, key=lambda c: int(np.sum(inst[c] == 1)))
    labs = run._own_clusters(idx)
    assert len(labs) == 1
    angles = np.radians([0.0, 60.0])
    plain, _ = run._yaw_scan_rays(m, truth, rays, angles)
    mine, _ = run._yaw_scan_rays(m, truth, rays, angles, labs)
    assert mine[0] - mine[1] > plain[0] - plain[1] + 2 * GAIN_CAP_LOG
    assert abs(mine[0] - plain[0]) <= 5 * GAIN_CAP_LOG  # the right turn: noise tails


def test_spread_rays_find_spokes_fitted_a_few_millimetres_off(lamp_scan):
    """The shade 7 mm too tall and its top 3 mm too narrow (as fits to points at
    11-23 mm noise come out): the spokes, 5 mm thick, miss the rays that saw them and
    the true turn trails a wrong one; with bundles of rays ``RAY_SPREAD`` noise levels
    apart it leads again."""
    _, inst, run, m, _, truth = lamp_scan
    rays = run._ray_set(m, truth)
    idx = max(run.clusters, key=lambda c: int(np.sum(inst[c] == 1)))
    labs = run._own_clusters(idx)
    off = dataclasses.replace(truth, params=dict(
        truth.params, shade_height=truth.params["shade_height"] + 0.007,
        shade_top=truth.params["shade_top"] - 0.003))
    angles = np.radians(np.arange(0.0, 120.0, 5.0))
    wrong = (angles >= np.radians(35.0)) & (angles <= np.radians(85.0))
    lead = []
    for spread in (0.0, RAY_SPREAD * run.sigma):
        s, _ = run._yaw_scan_rays(m, off, rays, angles, labs, spread)
        lead.append((s[0] - s[wrong].max()) / GAIN_CAP_LOG)
    assert lead[0] < 0.0 < 2.0 < lead[1], lead


def test_subsamples_depend_only_on_the_set(lamp_scan):
    run = lamp_scan[2]
    idx = np.flatnonzero(run.label >= 0)
    a = run._subsample(idx, 100)
    run._subsample(idx[::2], 50)  # other work in between changes nothing
    b = run._subsample(idx.copy(), 100)
    assert np.array_equal(a, b) and len(a) == 100
    assert np.all(np.diff(a) > 0) and np.isin(a, idx).all()
    assert run._subsample(idx[:80], 100) is not None and len(run._subsample(idx[:80], 100)) == 80


@pytest.mark.parametrize("turn", [pytest.param(0.9, marks=pytest.mark.xfail(
    strict=True, reason="session 19: with the turn scan's rays spread (RAY_SPREAD) a "
    "turn 50 degrees off scores 9.7 explained points over the refit's own turn, the "
    "true one 9.4: a tie the spread lost here (it won more on the benchmark's lamps)")),
    -0.8])
def test_resolve_yaw_turns_a_lamp_back(lamp_scan, turn):
    P, inst, run, m, gt, truth = lamp_scan
    idx = max(run.clusters, key=lambda c: int(np.sum(inst[c] == 1)))
    # wrong by 40-50 degrees (modulo its 120-degree symmetry) and its shade 3 cm short:
    # where its spokes are is wrong twice over
    bad = dict(truth.params, shade_height=0.17, stem_height=0.32)
    start = dataclasses.replace(truth, rotation=gt.rotation @ _rz(turn), params=bad)
    ok, score, inl, checked, gain = run._verify(m, start)
    assert ok  # verification cannot tell: the shade and stem explain the points
    out = run._resolve_yaw(m, idx, (gain, score, start, inl, checked))
    shape = csdf.zoo.load("lamp")
    pts = csdf.metrics.model_points(shape, 300, params=truth.params)
    syms = csdf.metrics.symmetries(shape, params=truth.params)
    diam = csdf.metrics.diameter(pts)
    assert csdf.metrics.mssd(pts, start.pose, gt, syms) > 0.15 * diam
    assert csdf.metrics.mssd(pts, out[2].pose, gt, syms) < 0.05 * diam
    assert abs(out[2].params["shade_height"] - 0.2) < 0.015
    assert abs(out[2].rotation[:, 2] @ run.plane[0]) > 0.9999  # still upright


def test_polish_gathers_its_band_again_until_it_reaches_the_shades_rim(lamp_scan,
                                                                       monkeypatch):
    """A winner whose shade is 8 cm short (a free fit left one so in scene 219, whose
    points at 8 mm noise made the band 40 mm wide): the points of the shade's upper
    part lie outside the first round's band (here two noise levels, 24 mm), so one
    round of the upright refit stops short; gathering the band again about each
    round's surface brings them in and the shade near its height."""
    from csdf.detect import objects

    P, inst, run, m, gt, truth = lamp_scan
    idx = max(run.clusters, key=lambda c: int(np.sum(inst[c] == 1)))
    short = dataclasses.replace(truth, params=dict(truth.params, shade_height=0.12))
    full = objects.POLISH_ROUNDS
    assert full > 1
    monkeypatch.setattr(objects, "POLISH_BAND", 2.0)
    heights = {}
    for rounds in (1, full):
        monkeypatch.setattr(objects, "POLISH_ROUNDS", rounds)
        heights[rounds] = run._polish(m, idx, short).params["shade_height"]
    assert heights[1] < 0.2 - 0.04, heights
    assert abs(heights[full] - 0.2) < 0.02, heights


def _table_fit(run, m, P, inst, gt, params, **changes):
    """The table ``m`` placed at ``gt`` with ``params`` (the rest at their defaults)
    changed by ``changes`` (``shift``: moved along its own x, metres; the rest
    parameter values), asserted to pass ``run``'s verification, as an item of its
    ``found`` lists: ``(explained mass, score, result, inliers, checked)``."""
    full = {p.name: float(p.default) for p in m.fld.program.params}
    full.update(params)
    base = csdf.fit(m.shape, P[inst == 1][:200], init={
        "rotation": gt.rotation, "translation": gt.translation, "params": full},
        estimate=("pose",), max_iter=1, escape=False, coarse=False)
    shift = changes.pop("shift", 0.0)
    res = dataclasses.replace(base, rotation=gt.rotation, translation=gt.translation
                              + gt.rotation @ np.array([shift, 0.0, 0.0]),
                              params=dict(full, **changes))
    ok, score, inl, checked, gain = run._verify(m, res)
    assert ok
    return gain, score, res, inl, checked


def test_trim_cuts_a_table_grown_past_the_image_back_to_its_legs():
    """A table seen end-on whose far end lies at the image's top border: a winner 0.4 m
    longer, grown past the far legs into space no ray looked at, passes verification
    (scene 230 of the benchmark had one). Cut back to its points' footprint and
    refitted, it explains the far legs again, by more than ``TRIM_GAIN``, at the true
    length and place."""
    from csdf.detect.objects import TRIM_GAIN

    pose = _yawed(0.0, (0.0, 0.0, 0.0))
    params = {"length": 1.4, "width": 0.8, "height": 0.9}
    P, inst, cam = _scanned("table", pose, params, (3.1, 0.9, 1.85), (-0.2, 0.0, 0.55),
                            30, (200, 150), 0.012, 4)
    run = _prepared(P, ["table"])
    m = run.models[0]
    gt = _camera_pose(cam, pose)
    idx = max(run.clusters, key=lambda c: int(np.sum(inst[c] == 1)))
    # its far end 0.4 m further; it passes verification: nothing the sensor saw says
    # otherwise
    grown = _table_fit(run, m, P, inst, gt, params, length=1.8, shift=-0.2)
    cut = run._trimmed(m, idx, grown)
    assert len(cut) == 1
    assert cut[0][0] > (1.0 + TRIM_GAIN) * grown[0]
    res = cut[0][2]
    assert abs(res.params["length"] - 1.4) < 0.03
    assert np.linalg.norm(res.translation - gt.translation) < 0.03
    # a winner of the right size is left alone
    assert run._trimmed(m, idx, _table_fit(run, m, P, inst, gt, params)) == []


def _squat_lamp_over(truth, solid, z: float, **sizes):
    """A scan of ``solid`` standing on the floor at ``(0, 0.3, z)`` (its centre) from the
    lamp tests' camera, prepared for lamps, and the lamp detection ``truth`` moved
    there with ``sizes`` replacing its parameters: ``(run, detection)``."""
    scene = _floor_scene()
    scene.add(solid, pose=csdf.Pose(translation=(0.0, 0.3, z)), name="distractor")
    cam = csdf.Camera.look_at(eye=(0.0, -1.4, 1.5), target=(0.0, 0.3, 0.3), fov=40,
                              width=200, height=150)
    P, _, _ = csdf.scan(scene, cam, noise=0.012, outliers=0.0, seed=3)
    gt = _camera_pose(cam, _yawed(0.0, (0.0, 0.3, 0.0)))
    over = dataclasses.replace(truth, rotation=gt.rotation, translation=gt.translation,
                               params=dict(truth.params, **sizes))
    return _prepared(P, ["lamp"]), over


def test_intruders_reject_a_squat_lamp_over_a_can(lamp_scan, monkeypatch):
    """A lamp stretched to its range limits over a cylinder passes the other tests of
    verification (its base and shade explain the can's side within three noise
    levels); the can's points between them float in the lamp's free space. The real
    lamp has few there. (Four of its sizes at their ends, it also fails
    ``MAX_AT_BOUND``.)"""
    from csdf.detect import objects as O

    _, _, run, m, _, truth = lamp_scan
    surf, _ = run._surface_at(m, truth.params)
    box = np.array([surf.min(axis=0), surf.max(axis=0)])
    assert run._intruders(m, truth, box) < 0.5 * MAX_INTRUDERS
    can, over = _squat_lamp_over(truth, csdf.cylinder(0.12, 0.25), 0.125, base_radius=0.13,
                                 shade_bottom=0.11, shade_height=0.157, shade_top=0.108,
                                 stem_height=0.15, wall=0.006)
    assert not can._verify(m, over)[0]  # squeezed
    monkeypatch.setattr(O, "MAX_AT_BOUND", None)
    assert can._verify(m, over)[0]  # the other tests pass it
    surf, _ = can._surface_at(m, over.params)
    box = np.array([surf.min(axis=0), surf.max(axis=0)])
    assert can._intruders(m, over, box) > 1.5 * MAX_INTRUDERS


def test_lamp_symmetries_are_its_three_turns_only():
    """The benchmark's MSSD minimises over csdf.metrics.symmetries: for a lamp the
    three turns by 120 degrees (its spokes), not every turn about its axis, checked
    on the exact field (a turn by 60 degrees moves its spokes by centimetres)."""
    lamp = csdf.zoo.load("lamp")
    syms = csdf.metrics.symmetries(lamp)
    angles = sorted(round(math.degrees(math.atan2(S[1, 0], S[0, 0]))) for S in syms)
    assert angles == [-120, 0, 120]
    assert all(np.allclose(S[2, :3], [0, 0, 1]) for S in syms)
    from csdf.field import as_field

    fld = as_field(lamp)
    x, _ = csdf.sample_surface(fld, 4000, seed=0, resolution=96)
    for deg, lo, hi in ((120, 0.0, 1e-6), (60, 0.03, 1.0), (15, 0.01, 1.0)):
        f = np.abs(fld.value(x @ _rz(math.radians(deg))))
        assert lo <= f.max() <= hi, deg


def test_front_fraction_rejects_a_lamp_laid_over_a_ball(lamp_scan, monkeypatch):
    """A squat lamp laid over a ball explains the ball's points with its shade and
    base, but the ball's side bulges out between them: points of the lamp's own
    cluster float in front of its visible surface along the sensor's rays. The real
    lamp has few there (noise tails). (Four of its sizes at their ends, it also fails
    ``MAX_AT_BOUND``.)"""
    from csdf.detect import objects as O
    from csdf.detect.objects import MAX_FRONT

    _, _, run, m, _, truth = lamp_scan
    inl = run._verify(m, truth)[2]
    surf, _ = run._surface_at(m, truth.params)
    assert run._front_fraction(m, truth, inl, surf) < 0.5 * MAX_FRONT
    ball, over = _squat_lamp_over(truth, csdf.sphere(0.12), 0.12, base_radius=0.13,
                                  shade_bottom=0.13, shade_height=0.147, shade_top=0.05,
                                  stem_height=0.15, wall=0.006)
    assert not ball._verify(m, over)[0]  # squeezed
    monkeypatch.setattr(O, "MAX_AT_BOUND", None)
    ok, _, inl, _, _ = ball._verify(m, over)
    assert ok  # the other tests pass it
    surf, _ = ball._surface_at(m, over.params)
    box = np.array([surf.min(axis=0), surf.max(axis=0)])
    assert ball._intruders(m, over, box) <= MAX_INTRUDERS  # the intruder test too
    assert ball._front_fraction(m, over, inl, surf) > MAX_FRONT


def test_span_is_the_clusters_diameter_whatever_its_turn():
    """A cluster's size is its diameter, not the diagonal of its box along the
    sensor's axes (larger for a turned object), and a few outliers linked to it do
    not make it larger."""
    from csdf.detect.objects import _span

    rng = np.random.default_rng(0)
    size = np.array([2.0, 1.0, 0.9])
    Q = (rng.uniform(-0.5, 0.5, (3000, 3)) * size) @ _rz(math.radians(30.0)).T
    diam = float(np.linalg.norm(size))
    assert np.linalg.norm(Q.max(axis=0) - Q.min(axis=0)) > 1.1 * diam  # the box's
    with_outliers = np.vstack([Q, [[2.0, 2.0, 0.0], [-2.0, 1.5, 0.5], [0.0, -2.2, 1.0]]])
    assert 0.9 * diam < _span(with_outliers) <= diam
    assert _span(Q[:1]) == 0.0


def test_a_planes_widest_piece_is_its_widest_connected_part():
    """Two table tops of one height side by side are one plane, but two pieces: the
    widest piece is one top's length, however unevenly the scan samples it; one top
    with a sparse stripe across it (farther from the sensor) stays whole."""
    from csdf.detect.objects import _widest_piece

    rng = np.random.default_rng(1)
    top = rng.uniform([0.0, 0.0], [1.8, 0.9], (4000, 2))
    other = rng.uniform([2.2, 0.0], [3.9, 0.8], (3000, 2))
    assert _widest_piece(np.vstack([top, other])) == pytest.approx(1.8, abs=0.02)
    assert _widest_piece(top) == pytest.approx(1.8, abs=0.02)
    sparse = np.vstack([top[top[:, 0] < 0.8], top[top[:, 0] > 1.0],
                        rng.uniform([0.8, 0.0], [1.0, 0.9], (40, 2))])
    assert _widest_piece(sparse) == pytest.approx(1.8, abs=0.02)
    assert _widest_piece(np.zeros((0, 2))) == 0.0
    assert _widest_piece(np.array([[0.0, 0.0], [1.0, 0.5]])) == 1.0


def test_models_are_prepared_once_per_shape_and_name():
    from csdf.detect.objects import _models_arg

    a = _models_arg(["stool"])[0]
    assert _models_arg("stool")[0] is a  # the zoo's one shape: prepared once
    b = _models_arg({"seat": "stool"})[0]
    assert b is not a and b.name == "seat"
    assert _models_arg([csdf.zoo.load("stool", height=0.6)])[0] is not a


def test_ray_evidence_confirms_a_seen_model_not_a_hidden_one(lamp_scan):
    """The scan confirms most of the rays on a lamp it sees; behind a screen, the same
    lamp at the same pose has its silhouette hidden behind nearer points, and a
    detection there would rest on nothing the sensor saw."""
    from csdf.detect.objects import MAX_FRONT, MIN_CONFIRMED

    _, _, run, m, _, truth = lamp_scan
    inl = run._verify(m, truth)[2]
    surf, _ = run._surface_at(m, truth.params)
    front, confirmed = run._ray_evidence(m, truth, inl, surf)
    assert confirmed > 2 * MIN_CONFIRMED
    assert front == run._front_fraction(m, truth, inl, surf) < 0.5 * MAX_FRONT
    scene = _floor_scene()
    scene.add("lamp", pose=_yawed(0.7, (0.0, 0.3, 0.0)),
              params={"shade_height": 0.2, "stem_height": 0.3}, name="lamp")
    scene.add(csdf.box((1.0, 0.05, 1.2)), pose=csdf.Pose(translation=(0.0, -0.15, 0.6)),
              name="screen")
    cam = csdf.Camera.look_at(eye=(0.0, -1.4, 1.5), target=(0.0, 0.3, 0.3), fov=40,
                              width=200, height=150)
    P, _, _ = csdf.scan(scene, cam, noise=0.012, outliers=0.0, seed=3)
    hidden = _prepared(P, ["lamp"])
    _, confirmed = hidden._ray_evidence(m, truth, np.zeros(0, dtype=int), surf)
    assert confirmed < 0.5 * MIN_CONFIRMED


def test_a_detection_claims_its_own_clusters_not_a_neighbours_points():
    """A detection's inliers (the points it claims) keep its own clusters' points, a
    piece of another cluster it mostly explains, and unclustered points, but not the
    few points of a neighbour that lie within three noise levels of its surface."""
    from types import SimpleNamespace

    from csdf.detect.objects import _Run

    label = np.array([0] * 10 + [1] * 10 + [2] * 4 + [-1] * 2)
    run = SimpleNamespace(label=label, claimed=np.zeros(len(label), dtype=bool),
                          sizes=np.array([10, 10, 4]))
    idx = np.arange(10)
    inl = np.concatenate([idx, [10, 11, 12], [20, 21, 22], [24, 25]])
    kept = _Run._own_inliers(run, inl, idx)
    assert kept.tolist() == [*range(10), 20, 21, 22, 24, 25]
    run.claimed[13:20] = True  # the neighbour's other points claimed already: a piece
    assert _Run._own_inliers(run, inl, idx).tolist() == inl.tolist()


def _front_of_a_bookshelf():
    """A bookshelf seen from the front, and a fit of it whose depth grew to its range's
    top (the box pushed back so its front stays where it was seen): the prepared run,
    the model, the shelf's points, the grown fit and its start."""
    from csdf.detect.objects import AT_BOUND

    scene = _floor_scene()
    pose = _yawed(0.35, (0.0, 0.4, 0.0))
    scene.add("bookshelf", pose=pose, params={"depth": 0.32}, name="shelf")
    cam = csdf.Camera.look_at(eye=(0.6, -2.2, 1.3), target=(0.0, 0.4, 0.8), fov=50,
                              width=160, height=120)
    P, _, inst = csdf.scan(scene, cam, noise=0.008, outliers=0.0, seed=4)
    run = _prepared(P, ["bookshelf"])
    m = run.models[0]
    gt = _camera_pose(cam, pose)
    idx = np.flatnonzero((inst == 1) & ~run.support)
    depth = next(p for p in m.fld.program.params if p.name == "depth")
    # the depth at its bound, the box pushed back so its front stays where it was seen
    grown = float(depth.hi)
    back = gt.rotation @ np.array([0.0, 0.5 * (grown - 0.32), 0.0])
    start = {"rotation": gt.rotation, "translation": gt.translation + back,
             "params": {"depth": grown}}
    res = run._candidate(m, idx, start, held=("depth",))
    assert res is not None and res.params["depth"] >= depth.hi - AT_BOUND * (
        depth.hi - depth.lo)
    return run, m, idx, res, start


def test_a_size_grown_to_its_bound_is_fitted_again_held_back():
    """A bookshelf seen from the front: no point holds its depth, and a fit that pushed
    it to the range's top reaches into space the sensor saw empty. Fitted again with
    the depth held back towards its default (the other sizes held too, the pose
    refitted), it explains the scan better, and that fit wins by explained mass."""
    run, m, idx, res, _ = _front_of_a_bookshelf()
    grown = res.params["depth"]
    gain0 = run._verify(m, res)[4]
    found: list = []
    run._shrunk(m, idx, res, found)
    assert found
    best = max(found, key=lambda f: f[0])
    assert best[0] > gain0  # explains more than the grown fit, which still passes
    assert best[2].params["depth"] < grown - 0.05
    # the other sizes held: the width does not grow in the depth's place
    assert best[2].params["width"] == pytest.approx(res.params["width"])


def _back_of_a_bookshelf():
    """A bookshelf seen from behind (the sensor sees its back panel), scanned at 2 cm
    noise: the prepared run, the model, the shelf's points, the truth's camera pose and
    model points."""
    pose = _yawed(0.3, (0.0, 0.4, 0.0))
    params = {"width": 1.0, "depth": 0.35}
    P, inst, cam = _scanned("bookshelf", pose, params, (-0.5, 2.9, 1.4), (0.0, 0.4, 0.7),
                            50, (160, 120), 0.02, 3)
    run = _prepared(P, ["bookshelf"])
    pts = csdf.metrics.model_points(csdf.zoo.load("bookshelf"), 300, params=params)
    idx = np.flatnonzero((inst == 1) & ~run.support)
    return run, run.models[0], idx, _camera_pose(cam, pose), pts


def test_a_turned_fit_that_falls_over_is_fitted_again_standing(monkeypatch):
    """A turn's refit (``_turns``) whose free fit falls over is fitted again from its
    start held upright on the support, and kept: it explains the points better than the
    fallen fit. (A bookshelf seen from the back fell 23 degrees in a benchmark scene;
    here every tilt over 0.2 degrees counts as falling, so the free fit falls.)"""
    from csdf.detect import objects as O

    run, m, idx, gt, pts = _back_of_a_bookshelf()
    monkeypatch.setattr(O, "UPRIGHT_SNAP", 0.2)
    init = {"rotation": gt.rotation,
            "translation": gt.translation + gt.rotation @ np.array([0.05, 0.03, 0.0]),
            "params": {}}
    assert run._candidate(m, idx, init) is None  # fell over: dropped
    res = run._candidate(m, idx, init, stand=True)
    assert res is not None
    assert run._verify(m, res)[0]
    assert res.rotation[:, 2] @ run.plane[0] == pytest.approx(1.0, abs=1e-9)  # upright
    assert csdf.metrics.mssd(pts, res.pose, gt) < 0.05  # metres; the truth's pose
    assert res.params["width"] == pytest.approx(1.0, abs=0.05)
    monkeypatch.setattr(O, "HELD_UPRIGHT", False)
    assert run._candidate(m, idx, init, stand=True) is None


def test_a_fallen_fit_that_stands_no_better_is_dropped():
    """A lamp fitted over a ball from an upright start falls over; held upright it
    explains the ball's points no better than lying, so the refit is dropped (a lamp
    over a ball was a false positive of a benchmark scene without this test)."""
    from csdf.detect import objects as O

    scene = _floor_scene()
    scene.add(csdf.sphere(0.14), pose=csdf.Pose(translation=(0.0, 0.4, 0.14)), name="ball")
    cam = csdf.Camera.look_at(eye=(0.4, -1.8, 1.3), target=(0.0, 0.4, 0.1), fov=40,
                              width=160, height=120)
    P, _, inst = csdf.scan(scene, cam, noise=0.015, outliers=0.0, seed=3)
    run = _prepared(P, ["lamp"])
    m = run.models[0]
    idx = np.flatnonzero((inst == 1) & ~run.support)
    nrm, off = run.plane
    c = P[idx].mean(axis=0)
    R0, t0 = run._stood(m, O.frame_z(nrm), c)
    init = {"rotation": R0, "translation": t0, "params": {}}
    assert run._candidate(m, idx, init) is None  # the free fit fell over
    # standing, the lamp does fit the ball's points (a refit exists) ...
    start = csdf.FitResult(rotation=R0, translation=t0, scale=1.0, params={}, rmse=0.0,
                           inlier_fraction=0.0, inlier_threshold=0.0, converged=False,
                           iterations=0, seconds=0.0)
    stood = run._polish(m, idx, start)
    assert stood is not None
    # ... but no better than the fallen fit: dropped
    assert run._candidate(m, idx, init, stand=True) is None


@pytest.fixture(scope="module")
def long_table_scan():
    """A 2.1 m x 1.05 m table on the floor (its top spans more than the largest model's
    diameter at its defaults), scanned from above one end."""
    scene = _floor_scene()
    pose = _yawed(0.55, (0.0, 0.3, 0.0))
    params = {"length": 2.1, "width": 1.05, "height": 0.85}
    scene.add("table", pose=pose, params=params, name="table")
    cam = csdf.Camera.look_at(eye=(0.4, -2.6, 2.0), target=(0.0, 0.3, 0.5), fov=55,
                              width=200, height=150)
    P, _, inst = csdf.scan(scene, cam, noise=0.006, outliers=0.0, seed=4)
    return P, inst, _camera_pose(cam, pose), params


def test_a_large_table_top_is_not_a_support(long_table_scan):
    """A plane above the floor and parallel to it is a support only if it spans more than
    any model could at its largest sizes (``_Model.reach``): a 2.1 m table's top is the
    table's, not a second floor (a 1.94 m table's top was taken for a support in a
    benchmark scene, and the table was fitted to its legs alone)."""
    from csdf.detect import objects as O

    P, inst, gt, params = long_table_scan
    top = inst == 1
    run = _prepared(P, ["table", "stool"])
    assert run.models[0].reach > 1.4 * run.models[0].radius
    assert np.mean(run.support[top]) < 0.05
    dets = csdf.detect(P, ["table", "stool"], viewpoint=(0, 0, 0), seed=0)
    assert [d.model for d in dets] == ["table"]
    table = csdf.zoo.load("table")
    pts = csdf.metrics.model_points(table, 300, params=params)
    syms = csdf.metrics.symmetries(table, params=params)
    # found: within the benchmark's tenth of its diameter (the legs alone gave 1.3)
    assert csdf.metrics.mssd(pts, dets[0].pose, gt, syms) < 0.1 * csdf.metrics.diameter(pts)
    assert dets[0].params["width"] == pytest.approx(1.05, abs=0.05)
    # at the defaults' radius, the top would be a support (the old rule)
    ms = [dataclasses.replace(m, reach=m.radius) for m in O._models_arg(["table", "stool"])]
    run = O._prepare(P, ms, None, np.zeros(3), 0, None, None, True)
    assert np.mean(run.support[top]) > 0.3


@pytest.mark.parametrize("shrink", [True, False])
def test_a_passing_winner_grown_to_its_bound_is_held_back(monkeypatch, shrink):
    """A winner that passes verification with a size at its bound and part of its
    visible surface unexplained (``_refit_unexplained``) also competes with fits held
    back from the bound (``SHRINK_PASSED``): a bookshelf grown over a chair beside it
    passed with 12 % unexplained in a benchmark scene."""
    from csdf.detect import objects as O

    run, m, idx, res, start = _front_of_a_bookshelf()
    ok, score, inl, checked, gain = run._verify(m, res)
    assert ok and 1.0 - score > O.REFIT_UNEXPLAINED  # passes, part unexplained
    monkeypatch.setattr(O, "SHRINK_PASSED", shrink)
    # other parameter starts off: here they find the right depth too, but not in the
    # benchmark's scene
    monkeypatch.setattr(O, "RETRY_STARTS", 0)
    # nor the refits cut back and held (``_narrowed``, tested on their own): they
    # compete too
    monkeypatch.setattr(O, "NARROW_STEPS", None)
    fits = run._refit_unexplained(m, idx, (gain, score, res, inl, checked), start)
    assert fits[0][2] is res  # the winner first, then the fits that compete with it
    top = max(fits, key=lambda f: f[0])
    if shrink:
        assert top[0] > gain and top[2].params["depth"] < res.params["depth"] - 0.05
    else:
        assert top[2] is res


@pytest.mark.parametrize("stand", [True, False])
def test_the_screens_own_fit_is_asked_to_stand(monkeypatch, stand):
    """With ``STAND_FIRST`` the fit from each model's screened placement is made with
    ``stand`` (:meth:`_candidate` stands a fit that falls over, as the turns' refits
    are: a benchmark bookshelf seen from behind fell from its own, right placement and
    was missed when only the refits at other yaws stood); the stand-up itself is tested
    above."""
    from csdf.detect import objects as O

    run, m, idx, gt, pts = _back_of_a_bookshelf()
    calls = []
    orig = O._Run._candidate

    def spy(self, m, idx, init, held=(), stand=False):
        calls.append((init is not None, stand))
        return orig(self, m, idx, init, held=held, stand=stand)

    monkeypatch.setattr(O._Run, "_candidate", spy)
    monkeypatch.setattr(O, "STAND_FIRST", stand)
    monkeypatch.setattr(O, "TURN_MODELS", 0)
    monkeypatch.setattr(O, "YAW_REFITS", 0)
    run.best_for(idx)
    assert calls and calls[0] == (True, stand)


def test_width_and_depth_parameters_are_found_from_the_bounds():
    """``_extents``: the parameters that widen a model along its x axis alone and along
    its y axis alone; none for a stool, whose seat radius widens it both ways."""
    from csdf.detect import objects as O

    ms = {n: O._model(n, csdf.zoo.load(n), None) for n in
          ("bookshelf", "table", "chair", "stool")}
    assert O._extents(ms["bookshelf"])[:2] == ("width", "depth")
    assert O._extents(ms["table"])[:2] == ("length", "width")
    assert O._extents(ms["chair"])[:2] == ("seat_width", "seat_depth")
    assert O._extents(ms["stool"]) is None
    # asked about parameters that are neither, it stops there
    assert O._extents(ms["bookshelf"], ["board", "plinth"]) is None
    assert O._extents(ms["bookshelf"], ["board", "depth"])[:2] == ("width", "depth")



def test_width_and_depth_grow_the_bounds_one_for_one():
    """``_growth`` over a size's whole range: a bookshelf's width and depth, a table's
    length and width and a chair's seat width and depth widen their models by their
    own amount (within 2 %). From a tenth of the range the bounds' millimetres of
    error made a bookshelf's depth grow 1.53 a unit."""
    from csdf.detect import objects as O

    for name in ("bookshelf", "table", "chair"):
        _, _, sx, sy = O._extents(O._model(name, csdf.zoo.load(name), None))
        assert sx == pytest.approx(1.0, abs=0.02) and sy == pytest.approx(1.0, abs=0.02)


def test_a_bookshelf_seen_end_on_grows_away_from_its_seen_side():
    """A bookshelf 0.94 m wide seen exactly end-on shows the sensor one side panel;
    fitted 0.58 m wide (a width nothing holds) with that panel in place, it is grown
    to the default width (0.8 m) away from the panel (``_completed``), the panel kept
    within a noise level of where it was and the explained mass kept to 1 %. With the
    width's growth rate off by a fifth the panel had moved 2 cm and the grown fit
    explained a third less, so the narrow one stayed."""
    scene = _floor_scene()
    params = {"width": 0.94, "depth": 0.27}
    pose = _yawed(0.0, (0.0, 0.0, 0.0))
    scene.add("bookshelf", pose=pose, params=params, name="bookshelf")
    cam = csdf.Camera.look_at(eye=(2.9, 0.0, 1.5), target=(0.0, 0.0, 0.7), fov=50,
                              width=200, height=150)
    P, _, inst = csdf.scan(scene, cam, noise=0.006, outliers=0.0, seed=4)
    gt = _camera_pose(cam, pose)
    run = _prepared(P, ["bookshelf"])
    m = run.models[0]
    # the +x panel (the one seen) stays where it is: the centre moves +0.18 m
    top = _table_fit(run, m, P, inst, gt, params, width=0.58, shift=0.18)
    gain, _, out, _, _ = run._completed(m, top)
    assert out.params["width"] == pytest.approx(0.8)
    assert gain >= 0.99 * top[0]
    x_panel = [np.asarray(r.translation) + np.asarray(r.rotation) @ np.array(
        [0.5 * r.params["width"], 0.0, 0.0]) for r in (top[2], out)]
    assert np.linalg.norm(x_panel[1] - x_panel[0]) < 0.006


def test_a_quarter_turned_fit_with_sizes_at_their_bounds_is_refitted_swapped():
    """A bookshelf seen from its side, fitted a quarter turn off with its width and depth
    at their bounds (its side taken for its front: a benchmark scene's false positive
    and miss): ``_swapped`` refits it turned back either way with the two sizes traded,
    and the refit that matches the truth explains the points better."""
    from csdf.detect import objects as O

    pose = _yawed(0.2, (0.0, 0.5, 0.0))
    params = {"width": 0.6, "depth": 0.35}
    P, inst, cam = _scanned("bookshelf", pose, params, (2.4, -0.6, 1.3), (0.0, 0.5, 0.7),
                            50, (160, 120), 0.012, 5)
    run = _prepared(P, ["bookshelf"])
    m = run.models[0]
    gt = _camera_pose(cam, pose)
    idx = np.flatnonzero((inst == 1) & ~run.support)
    Rt = O._yaw_matrix(run.plane[0], math.pi / 2)  # a quarter turn about the support
    c = gt.rotation @ m.centre + gt.translation
    start = {"rotation": Rt @ gt.rotation, "translation": Rt @ (gt.translation - c) + c,
             "params": {"width": 0.4, "depth": 0.45}}
    res = run._candidate(m, idx, start, held=("width", "depth"), stand=True)
    assert res is not None
    ok, _, _, _, gain = run._verify(m, res)
    pts = csdf.metrics.model_points(csdf.zoo.load("bookshelf"), 300, params=params)
    diam = csdf.metrics.diameter(pts)
    assert csdf.metrics.mssd(pts, res.pose, gt) > 0.1 * diam  # the wrong turn
    found: list = []
    run._swapped(m, idx, res, found)
    assert found
    best = max(found, key=lambda f: f[0])
    assert not ok or best[0] > gain
    assert csdf.metrics.mssd(pts, best[2].pose, gt) < 0.1 * diam
    assert best[2].params["width"] == pytest.approx(0.6, abs=0.08)


def _cropped_scan(name: str, model: str | None = None):
    """A benchmark scan cropped about an object, saved in ``tests/data/NAME.npz``:
    ``(the file, its points (N, 3) float64, error)``, where ``error(pose)`` is the
    MSSD of ``model`` at ``pose`` against the saved truth over its diameter (None
    without ``model``)."""
    from pathlib import Path

    z = np.load(Path(__file__).parent / "data" / f"{name}.npz")
    P = z["points"].astype(np.float64)
    if model is None:
        return z, P, None
    params = {str(k): float(v) for k, v in zip(z["param_names"], z["params"])}
    shape = csdf.zoo.load(model)
    pts = csdf.metrics.model_points(shape, 500, params=params)
    syms = csdf.metrics.symmetries(shape, params=params)
    gt = csdf.Pose(z["pose"][:3, :3], z["pose"][:3, 3])
    diameter = csdf.metrics.diameter(pts)
    return z, P, lambda pose: csdf.metrics.mssd(pts, pose, gt, syms) / diameter


def test_a_lamp_in_one_cluster_with_a_distractor_is_found_in_parts(monkeypatch):
    # benchmark scene 141 (cropped: the lamp, a squat distractor cylinder beside it that
    # its cluster also holds, and the floor within 1 m): a lamp fitted to the whole
    # cluster falls over and no model passes; fitted to the lamp's half of the
    # footprint, with the cylinder's half taken as another object, it is found
    from csdf.detect import objects as O

    z, P, error = _cropped_scan("lamp_beside_cylinder", "lamp")
    monkeypatch.setattr(O, "PARTS_WHEN_UNFIT", False)
    assert csdf.detect(P, ["lamp"], viewpoint=(0, 0, 0), seed=0) == []
    monkeypatch.setattr(O, "PARTS_WHEN_UNFIT", True)
    dets = csdf.detect(P, ["lamp"], viewpoint=(0, 0, 0), seed=0)
    assert [d.model for d in dets] == ["lamp"]
    assert error(dets[0].pose) < 0.1
    # its inliers are the lamp's points, not the cylinder's
    inst = z["instance"][dets[0].inliers]
    assert np.mean(inst == 1) > 0.95



def test_a_kept_lamp_fit_is_turned_by_its_own_rays(monkeypatch):
    # benchmark scene 192 (cropped: the lamp and the floor within 1 m): the upright
    # refit neither beat the fit as found nor offered a turn that beat it, so that
    # fit's turn, 0.11 diameters off, was kept; its own rays score another turn higher
    from csdf.detect import objects as O

    _, P, error = _cropped_scan("lamp_turned_at_its_own_parameters", "lamp")
    # the last step would turn it too (the next test): only judged here, so that the
    # turn ORIG_TURNS gives is what this compares
    monkeypatch.setattr(O._Run, "settle_turn", O._Run.turn_settled)
    monkeypatch.setattr(O, "ORIG_TURNS", False)
    # the wrong turn is kept though unsettled (the default leaves it out)
    before = csdf.detect(P, ["lamp"], viewpoint=(0, 0, 0), seed=0, keep_unsettled=True)
    monkeypatch.setattr(O, "ORIG_TURNS", True)
    after = csdf.detect(P, ["lamp"], viewpoint=(0, 0, 0), seed=0, keep_unsettled=True)
    assert [d.model for d in before] == [d.model for d in after] == ["lamp"]
    assert error(before[0].pose) > 0.1 and error(after[0].pose) < 0.05
    assert not before[0].settled and after[0].settled


def test_the_last_step_turns_a_lamp_to_its_best_turn_at_fine_steps(monkeypatch):
    """The same lamp without ``ORIG_TURNS``: the last step (:meth:`_Run.settle_turn`)
    ray-casts its turns ``SETTLE_STEP`` degrees apart, turns it to the best, and finds
    that turn settled; judged without turning it (as before that step), it is 0.11
    diameters off and unsettled."""
    from csdf.detect import objects as O

    _, P, error = _cropped_scan("lamp_turned_at_its_own_parameters", "lamp")
    monkeypatch.setattr(O, "ORIG_TURNS", False)
    turned = csdf.detect(P, ["lamp"], viewpoint=(0, 0, 0), seed=0, keep_unsettled=True)
    assert [(d.model, d.settled) for d in turned] == [("lamp", True)]
    assert error(turned[0].pose) < 0.05
    monkeypatch.setattr(O._Run, "settle_turn", O._Run.turn_settled)
    judged = csdf.detect(P, ["lamp"], viewpoint=(0, 0, 0), seed=0, keep_unsettled=True)
    assert [(d.model, d.settled) for d in judged] == [("lamp", False)]
    assert error(judged[0].pose) > 0.1


def test_a_lamp_whose_turn_the_scan_does_not_settle_is_left_out(tmp_path):
    """Benchmark scene 32 (cropped: its fourth object, a lamp, and the floor within
    1 m): the lamp is found, and its best turn at ``SETTLE_STEP`` degrees leads the
    turns 20 degrees or more away by under ``SETTLED_PLAIN_RAYS`` explained points: a
    guess (before that step the lamp was kept 0.185 of its diameter off). ``detect``
    leaves it out by default; with
    ``keep_unsettled`` it comes back marked; the CLI says so and keeps it when asked."""
    from typer.testing import CliRunner

    from csdf.cli import app
    from csdf.io import write_points

    _, P, _ = _cropped_scan("lamp_turn_unsettled")
    assert csdf.detect(P, ["lamp"], viewpoint=(0, 0, 0), seed=0) == []
    kept = csdf.detect(P, ["lamp"], viewpoint=(0, 0, 0), seed=0, keep_unsettled=True)
    assert [(d.model, d.settled) for d in kept] == [("lamp", False)]
    assert kept[0].to_dict()["settled"] is False and "turn unsettled" in repr(kept[0])
    ply = tmp_path / "scan.ply"
    write_points(ply, P, viewpoint=(0.0, 0.0, 0.0))
    out = tmp_path / "scene.json"
    r = CliRunner().invoke(app, ["detect", str(ply), "--models", "lamp", "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert "1 more detection(s) left out" in r.output and len(csdf.Scene.load(out)) == 0
    r = CliRunner().invoke(app, ["detect", str(ply), "--models", "lamp", "-o", str(out),
                                 "--keep-unsettled"])
    assert r.exit_code == 0 and "unsettled" in r.output and "left out" not in r.output
    assert len(csdf.Scene.load(out)) == 1


def _as_detection(m, res, inliers):
    return csdf.Detection(model=m.name, pose=res.pose, params=dict(res.params), score=1.0,
                          inliers=inliers, shape=m.shape, fit=res)


def test_a_lamps_turn_is_settled_at_its_spokes_and_not_between_them(lamp_scan):
    """Seen from above into the shade, the true turn's rays lead every turn 20 degrees
    or more away by far; turned by 60 degrees (the spokes halfway between the true
    ones) the rays and the points both prefer another turn."""
    from csdf.detect import objects as O

    _, inst, run, m, _, truth = lamp_scan
    idx = max(run.clusters, key=lambda c: int(np.sum(inst[c] == 1)))
    assert run.turn_settled(_as_detection(m, truth, idx))
    turned = dataclasses.replace(
        truth, rotation=O._yaw_matrix(run.plane[0], math.radians(60.0)) @ truth.rotation)
    claimed = run.claimed.copy()
    assert not run.turn_settled(_as_detection(m, turned, idx))
    assert np.array_equal(run.claimed, claimed)  # the inliers' claims are as they were


def test_a_model_whose_turn_moves_much_of_it_is_judged_by_its_half_turn_alone(chair_scan):
    """A chair's turn is not in doubt (it moves much of its surface), so its turn is
    judged by the fit (step 8), and here only against its half turn
    (``_half_turn_tied``): the true turn is settled and so is a quarter turn whose
    half turn scores less (the fit's to reject), while the half turn, and the other
    quarter turn, whose half turns score hundreds of points more, are not."""
    from csdf.detect import objects as O

    P, inst, gt = chair_scan
    run = _prepared(P, ["chair"])
    m = run.models[0]
    assert not run._doubt(m)[2]
    got = {}
    for deg in (0, 90, -90, 180):
        res = csdf.fit(m.shape, P[inst == 1][:200], init={
            "rotation": O._yaw_matrix(run.plane[0], math.radians(deg)) @ gt.rotation,
            "translation": gt.translation}, estimate=("pose",), max_iter=1, escape=False,
            coarse=False)
        got[deg] = run.turn_settled(_as_detection(m, res, np.flatnonzero(inst == 1)))
    assert got == {0: True, 90: False, -90: True, 180: False}


def _bookshelf_scan(eye):
    """``(points, instance ids, run, model, true pose, truth fit)``: a default
    bookshelf at the origin, scanned from ``eye`` at 10 mm range noise, and a fit
    placed at its true pose and sizes."""
    pose = _yawed(0.0, (0.0, 0.0, 0.0))
    P, inst, cam = _scanned("bookshelf", pose, {}, eye, (0.0, 0.0, 0.7), 45, (240, 180),
                            0.01, 5)
    run = _prepared(P, ["bookshelf"])
    m = run.models[0]
    gt = _camera_pose(cam, pose)
    full = {p.name: float(p.default) for p in m.fld.program.params}
    base = csdf.fit(m.shape, P[inst == 1][:200], init={
        "rotation": gt.rotation, "translation": gt.translation, "params": full},
        estimate=("pose",), max_iter=1, escape=False, coarse=False)
    truth = dataclasses.replace(base, rotation=gt.rotation, translation=gt.translation,
                                params=full)
    return P, inst, run, m, gt, truth


@pytest.fixture(scope="module")
def bookshelf_side_scan():
    """A bookshelf seen nearly side-on (the camera 8 degrees round from its side
    towards its open front) at 10 mm range noise: its front and back differ only in
    the few columns of the front seen at a grazing angle."""
    return _bookshelf_scan((3.0, -0.42, 1.7))[2:]


@pytest.mark.parametrize("shrink", [True, False])
def test_a_turns_refit_that_fails_at_a_bound_is_held_back(bookshelf_side_scan, shrink):
    """A turn's refit (``_turns``) that fails verification with a size at an end of its
    range is held back from it with ``SHRINK_TURNS``: a benchmark bookshelf seen
    side-on, refitted the right way round, grew its depth to the bound and was seen
    through, and its wrong half turn won. Here the depth is held at the bound."""
    run, m, gt, truth = bookshelf_side_scan
    idx = max(run.clusters, key=len)
    start = {"rotation": gt.rotation, "translation": gt.translation,
             "params": dict(truth.params, depth=0.45)}
    found: list = []
    run._add_verified(m, idx, start, found, shrink=shrink, held=("depth",), stand=True)
    if not shrink:
        assert found == []  # seen through: it fails
        return
    assert found
    best = max(found, key=lambda f: f[0])
    assert best[2].params["depth"] < 0.45 - 0.05
    pts = csdf.metrics.model_points(csdf.zoo.load("bookshelf"), 300)
    assert csdf.metrics.mssd(pts, best[2].pose, gt) < 0.1 * csdf.metrics.diameter(pts)


def test_a_bookshelfs_half_turn_is_not_in_doubt_and_the_lamps_turn_is(
        bookshelf_side_scan, lamp_scan):
    run, m, _, _ = bookshelf_side_scan
    full, sym, doubt = run._doubt(m)
    assert not doubt
    # its back panel (6 mm) is in the samples the turn is judged on: the half turn
    # moves a quarter of them (from a 48-voxel mesh, which loses the panel, it moved
    # none at the benchmark's scene 163)
    _, moved = run._turn_profile(m, np.array([math.pi]))
    assert moved[0] > 5 * YAW_DOUBT
    _, _, lrun, lm, _, _ = lamp_scan
    assert lrun._doubt(lm)[2]


def _half_turned(run, res):
    """The fit ``res`` turned half round about the support's normal of ``run``."""
    nrm = run.plane[0]
    K = np.array([[0, -nrm[2], nrm[1]], [nrm[2], 0, -nrm[0]], [-nrm[1], nrm[0], 0]])
    return dataclasses.replace(res, rotation=(np.eye(3) + 2.0 * K @ K) @ res.rotation)


def _verified(run, m, fits) -> list:
    """Each fit of ``fits`` verified, as ``found``'s items (each must pass)."""
    items = []
    for res in fits:
        ok, score, inl, checked, gain = run._verify(m, res)
        assert ok
        items.append((gain, score, res, inl, checked))
    return items


def test_rays_break_a_tie_between_a_bookshelfs_front_and_back(bookshelf_side_scan):
    from csdf.detect.objects import RAY_TIE

    run, m, _, truth = bookshelf_side_scan
    items = _verified(run, m, [truth, _half_turned(run, truth)])
    right, wrong = items
    # the points alone do not tell them apart: a tie by explained mass
    assert abs(right[0] - wrong[0]) <= RAY_TIE * right[0]
    done = [(m, None, None, items)]
    assert run._ray_tie(done, (m, wrong, None))[1] is right
    assert run._ray_tie(done, (m, right, None))[1] is right


def test_a_winner_turned_half_round_is_turned_back_by_its_rays(bookshelf_side_scan):
    """``_half_turn``: a bookshelf seen nearly side-on, its winner turned half round
    (front and back swapped, the same sizes), is turned back: the rays score the
    right turn far higher. The right winner stays as it is, and so does a table's
    (its half turn is a symmetry)."""
    run, m, gt, truth = bookshelf_side_scan
    right, wrong = _verified(run, m, [truth, _half_turned(run, truth)])
    back = run._half_turn(m, wrong)
    assert back is not wrong
    pts = csdf.metrics.model_points(csdf.zoo.load("bookshelf"), 300)
    assert csdf.metrics.mssd(pts, back[2].pose, gt) < 0.02 * csdf.metrics.diameter(pts)
    assert back[0] > 0.0 and run._verify(m, back[2])[0]
    assert run._half_turn(m, right) is right
    table = _prepared(np.asarray(run.P), ["table"])
    tm = table.models[0]
    full, sym, _ = table._doubt(tm)
    assert sym[int(np.argmin(np.abs(full - math.pi)))]  # so _half_turn leaves it


@pytest.fixture(scope="module")
def bookshelf_edge_on_scan():
    """A bookshelf seen exactly side-on at 10 mm range noise: its open front and 6 mm
    back panel are both seen edge-on, so nothing in the scan tells its front from its
    back."""
    return _bookshelf_scan((3.0, 0.0, 1.7))


def test_a_bookshelf_seen_edge_on_is_unsettled_and_one_seen_from_its_front_is_not(
        bookshelf_edge_on_scan, bookshelf_side_scan, monkeypatch):
    """``_half_turn_tied``: seen exactly side-on, the true bookshelf and its half turn
    score within ``HALF_TURN_TIE`` explained points by its rays, so its turn is
    unsettled; 8 degrees round towards its open front, the half turn scores hundreds
    of points less and it is settled, and turned half round it is not."""
    from csdf.detect import objects as O

    _, inst, run, m, _, truth = bookshelf_edge_on_scan
    idx = np.flatnonzero(inst == 1)
    for res in (truth, _half_turned(run, truth)):
        det = _as_detection(m, res, idx)
        assert run._half_turn_tied(det) and not run.turn_settled(det)
        assert not run.settle_turn(det) and det.fit is res  # judged, not turned
    side, sm, _, struth = bookshelf_side_scan
    sdet = _as_detection(sm, struth, max(side.clusters, key=len))
    assert not side._half_turn_tied(sdet) and side.turn_settled(sdet)
    rays = side._ray_set(sm, struth)
    s = side._ray_scores(sm, dict(struth.params),
                         side._turned_in_place(struth, np.array([0.0, math.pi])), rays,
                         side._own_clusters(sdet.inliers))
    assert s[0] - s[1] > 100 * O.HALF_TURN_TIE * O.GAIN_CAP_LOG
    # turned half round, its own turn scores far below its half turn: unsettled too
    wrong = _as_detection(sm, _half_turned(side, struth), sdet.inliers)
    assert side._half_turn_tied(wrong) and not side.turn_settled(wrong)
    # off, the rule never unsettles
    monkeypatch.setattr(O, "HALF_TURN_TIE", None)
    assert run.turn_settled(_as_detection(m, truth, idx))


def test_detect_leaves_out_a_bookshelf_whose_front_the_scan_cannot_tell_from_its_back(
        bookshelf_edge_on_scan):
    """End to end: the edge-on bookshelf is found, its turn marked unsettled, and left
    out of the default result (a coin toss between front and back was a false
    positive half the time)."""
    P, _, _, _, gt, _ = bookshelf_edge_on_scan
    kept = csdf.detect(P, ["bookshelf"], viewpoint=(0, 0, 0), seed=0, keep_unsettled=True)
    assert [(d.model, d.settled) for d in kept] == [("bookshelf", False)]
    assert np.linalg.norm(kept[0].pose.translation - gt.translation) < 0.1
    assert csdf.detect(P, ["bookshelf"], viewpoint=(0, 0, 0), seed=0) == []


def test_a_rival_at_its_bound_is_held_back_and_then_wins_the_tie(bookshelf_side_scan,
                                                                 monkeypatch):
    """``_trim_rivals``: a verified fit in another pose that explains nearly as much as
    the winner, with a size at the end of its range, is held back from it and joins
    the competition. A benchmark bookshelf seen from its side, fitted the right way
    round with its depth pushed to its bound, lost to its half turn by 2 %; here the
    right turn at the bound explains 5.5 % less than the half turn, the held-back
    fit as much, and the rays then choose it."""
    from csdf.detect import objects as O

    run, m, gt, truth = bookshelf_side_scan
    monkeypatch.setattr(O, "TRIM_RIVALS", 0.1)
    idx = max(run.clusters, key=len)
    deep = dataclasses.replace(truth, params=dict(truth.params, depth=0.45))
    items = _verified(run, m, [_half_turned(run, truth), deep])
    wrong, bound = items
    assert 0.9 * wrong[0] < bound[0] < 0.95 * wrong[0]
    done = [(m, None, None, list(items))]
    best = run._trim_rivals(idx, done, (m, wrong, None))
    added = [f for d in done[1:] for f in d[3]]
    assert added and all(f[2].params["depth"] < 0.45 - 0.05 for f in added)
    pts = csdf.metrics.model_points(csdf.zoo.load("bookshelf"), 300)
    right = max(added, key=lambda f: f[0])
    assert csdf.metrics.mssd(pts, right[2].pose, gt) < 0.1 * csdf.metrics.diameter(pts)
    assert right[0] > 0.98 * wrong[0]
    # it explains about as much as the half turn: the rays break the tie
    tied = run._ray_tie(done, best)[1][2]
    assert tied.params["depth"] < 0.4
    assert csdf.metrics.mssd(pts, tied.pose, gt) < 0.1 * csdf.metrics.diameter(pts)
    # without a rival within reach, nothing is added
    done = [(m, None, None, [wrong])]
    assert run._trim_rivals(idx, done, (m, wrong, None))[1] is wrong and len(done) == 1


def test_a_table_is_reported_with_its_length_along_its_x_axis():
    """A table 0.94 m long and 1.2 m wide, turned a quarter, is the same surface as one
    1.2 m long and 0.94 m wide: the detection reports the form nearer the defaults
    (length 1.4, width 0.8), which the benchmark's truth (length along x) uses; two
    such tables had counted as a miss and a false positive each."""
    from csdf.detect.objects import _canonical, _model, _swaps
    from csdf.fit.lie import rotation_angle

    m = _model("table", csdf.zoo.load("table"), None)
    assert _swaps(m) == [("length", "width", 0.5 * math.pi)]
    assert _swaps(_model("bookshelf", csdf.zoo.load("bookshelf"), None)) == []
    full = {p.name: float(p.default) for p in m.fld.program.params}
    pose = _yawed(0.4, (0.3, -0.2, 0.0))
    base = csdf.fit(m.shape, m.surface[:50], init={
        "rotation": pose.rotation, "translation": pose.translation, "params": full},
        estimate=("pose",), max_iter=1, escape=False, coarse=False)
    wide = dataclasses.replace(base, rotation=pose.rotation, translation=pose.translation,
                               params=dict(full, length=0.94, width=1.2))
    out = _canonical(m, wide)
    assert out.params["length"] == 1.2 and out.params["width"] == 0.94
    assert math.degrees(rotation_angle(out.rotation, wide.rotation)) == pytest.approx(90.0)
    X = np.random.default_rng(1).uniform(-1.5, 1.5, (2000, 3))

    def posed(r):
        return m.shape.bind(**r.params).transform(r.pose.matrix)

    np.testing.assert_allclose(posed(out)(X), posed(wide)(X), atol=1e-9)
    # already the nearer form, or the exchanged values out of their ranges: unchanged
    for lw in ((1.5, 0.8), (2.0, 1.1)):
        r = dataclasses.replace(wide, params=dict(full, length=lw[0], width=lw[1]))
        assert _canonical(m, r) is r
    assert _canonical(m, None) is None


@pytest.mark.parametrize("screen", [True, False])
def test_a_table_cut_short_by_what_hides_it_grows_to_its_default_length(screen):
    """A table 1.7 m long fitted as its visible half, 0.9 m long, is grown to the
    default length (1.4 m) into the side the sensor did not see (``_completed``):
    behind a screen, or under the true table's own top. Its error falls from twice
    the benchmark's threshold to under it. A short table in full view, fitted at its
    size, stays as it is: grown, it would stand where the sensor saw the floor."""
    scene = _floor_scene()
    params = {"length": 1.7, "width": 0.9, "height": 0.75}
    pose = _yawed(0.0, (0.0, 0.0, 0.0))
    scene.add("table", pose=pose, params=params, name="table")
    if screen:  # hides the table's +x half from the camera
        scene.add(csdf.box((1.1, 0.1, 1.4)), pose=csdf.Pose(translation=(0.75, -0.9, 0.7)),
                  name="screen")
    cam = csdf.Camera.look_at(eye=(0.3, -3.0, 1.7), target=(0.0, 0.0, 0.4), fov=50,
                              width=200, height=150)
    P, _, inst = csdf.scan(scene, cam, noise=0.008, outliers=0.0, seed=3)
    gt = _camera_pose(cam, pose)
    run = _prepared(P, ["table"])
    m = run.models[0]
    top = _table_fit(run, m, P, inst, gt, params, length=0.9, shift=-0.4)
    out = run._completed(m, top)[2]
    assert out.params["length"] == pytest.approx(1.4)
    pts = csdf.metrics.model_points(csdf.zoo.load("table"), 300, params=params)
    d = csdf.metrics.diameter(pts)
    assert csdf.metrics.mssd(pts, top[2].pose, gt) > 0.15 * d
    assert csdf.metrics.mssd(pts, out.pose, gt) < 0.1 * d
    if not screen:
        scene = _floor_scene()
        short = {"length": 0.9, "width": 0.7, "height": 0.75}
        scene.add("table", pose=_yawed(0.3, (0.0, 0.0, 0.0)), params=short, name="table")
        P, _, inst = csdf.scan(scene, cam, noise=0.008, outliers=0.0, seed=3)
        run = _prepared(P, ["table"])
        top = _table_fit(run, run.models[0], P, inst,
                         _camera_pose(cam, _yawed(0.3, (0.0, 0.0, 0.0))), short)
        assert run._completed(run.models[0], top) is top


@pytest.mark.parametrize("retry", [True, False])
def test_a_cluster_whose_fits_took_a_neighbour_is_searched_again_once_it_is_found(
        monkeypatch, retry):
    """Benchmark scene 263, cropped to 0.75 m about a stool and the lamp beside it:
    the stool's cluster is searched first, its fits take the lamp's cluster as a
    piece of the stool and fail; once the lamp is found and its points claimed, the
    stool's cluster is searched again (``RETRY_JOINED``) and the stool is found."""
    from csdf.detect import objects as O

    z, P, error = _cropped_scan("stool_against_lamp", "stool")
    monkeypatch.setattr(O, "RETRY_JOINED", retry)
    # the refit on the stool's own cluster (OWN_REFIT) finds it on the first search
    # too; held off, the second search alone is tested
    monkeypatch.setattr(O, "OWN_REFIT", False)
    dets = csdf.detect(P, ["stool", "lamp"], viewpoint=(0, 0, 0), seed=0)
    errs = [(error(d.pose), d) for d in dets if d.model == "stool"]
    assert "lamp" in [d.model for d in dets]
    found = [d for e, d in errs if e < 0.1]
    assert bool(found) == retry, [e for e, _ in errs]
    if retry:  # its inliers are the stool's points, not the lamp's
        assert np.mean(z["instance"][found[0].inliers] == 1) > 0.9


@pytest.mark.parametrize("own", [False, True])
def test_a_fit_that_failed_over_a_neighbours_cluster_is_fitted_again_without_it(
        monkeypatch, own):
    """Benchmark scene 292, cropped to 1.2 m about a bookshelf (the floor thinned to
    every fourth point): the bookshelf's fits take the clusters beside it (a chair's,
    a lamp's and a distractor's) as pieces of their object and fail verification.
    Fitted again from the same start on its own cluster alone (``OWN_REFIT``), it is
    found."""
    from csdf.detect import objects as O

    z, P, error = _cropped_scan("bookshelf_beside_chair", "bookshelf")
    monkeypatch.setattr(O, "OWN_REFIT", own)
    dets = csdf.detect(P, ["bookshelf"], viewpoint=(0, 0, 0), seed=0)
    found = [d for d in dets if error(d.pose) < 0.1]
    assert len(found) == int(own), [error(d.pose) for d in dets]
    if own:  # its inliers are the bookshelf's points, not the chair's
        assert np.mean(z["instance"][found[0].inliers] == 5) > 0.95


def test_a_cluster_wider_than_any_model_is_tried_in_parts(monkeypatch):
    """Benchmark scene 920, cropped to 2 m about a 1.59 m table and the bookshelf
    behind it (the floor thinned to a quarter): the two touch in the scan and make one
    cluster 3.0 m across, more than a table or a bookshelf may span
    (``SIZE_SLACK``), so no model was fitted to it and neither was found. Such a
    cluster is split in two like one that no fit explains, and the table is found
    on its own points; the bookshelf's, 23 % of the cluster, are searched next
    (``CLUSTER_LEFT`` 0.2; at 0.3 they were not)."""
    from csdf.detect import objects as O

    z, P, error = _cropped_scan("table_before_bookshelf", "table")
    dets = csdf.detect(P, ["table", "bookshelf"], viewpoint=(0, 0, 0), seed=0)
    assert [d.model for d in dets] == ["table", "bookshelf"]
    assert error(dets[0].pose) < 0.1
    assert np.mean(z["instance"][dets[0].inliers] == 1) > 0.99
    params = {str(k): float(v) for k, v in zip(z["bookshelf_param_names"],
                                                z["bookshelf_params"])}
    shelf = csdf.zoo.load("bookshelf")
    pts = csdf.metrics.model_points(shelf, 500, params=params)
    truth = csdf.Pose(z["bookshelf_pose"][:3, :3], z["bookshelf_pose"][:3, 3])
    syms = csdf.metrics.symmetries(shelf, params=params)
    assert csdf.metrics.mssd(pts, dets[1].pose, truth, syms) / csdf.metrics.diameter(pts) < 0.1
    assert np.mean(z["instance"][dets[1].inliers] == 3) > 0.99
    monkeypatch.setattr(O, "CLUSTER_LEFT", 0.3)
    monkeypatch.setattr(O, "LEFT_PIECE", None)  # which would search its piece too
    dets = csdf.detect(P, ["table", "bookshelf"], viewpoint=(0, 0, 0), seed=0)
    assert [d.model for d in dets] == ["table"]


@pytest.mark.parametrize("piece", [5.0, None])
def test_an_object_left_of_a_large_cluster_is_searched_on_its_own(monkeypatch, piece):
    """Benchmark scene 721, cropped to 1.8 m about a chair and the bookshelf beside it
    (the floor thinned to a quarter): the two make one cluster of 11,900 points, and
    once the bookshelf has claimed its points the chair's 733 left are 6 % of it, too
    few to search the cluster again (``CLUSTER_LEFT``). They are one connected piece
    of what is left, off the bookshelf's surface, and such a piece is searched on its
    own (``LEFT_PIECE``; a piece on a detection's surface is not:
    ``test_a_large_table_top_is_not_a_support`` finds one table)."""
    from csdf.detect import objects as O

    z, P, error = _cropped_scan("chair_beside_bookshelf", "chair")
    monkeypatch.setattr(O, "LEFT_PIECE", piece)
    dets = csdf.detect(P, ["chair", "bookshelf"], viewpoint=(0, 0, 0), seed=0)
    if piece is None:
        assert [d.model for d in dets] == ["bookshelf"]
        return
    assert [d.model for d in dets] == ["bookshelf", "chair"]
    assert error(dets[1].pose) < 0.1
    assert np.all(z["instance"][dets[1].inliers] == 1)


@pytest.mark.parametrize("limit", [3, None])
def test_a_box_squeezed_into_a_lamp_is_dropped(monkeypatch, limit):
    """Benchmark scene 260, cropped to 0.6 m about a 0.27 m box (a distractor) at
    2.8 cm range noise: its lower third is taken for the floor, and the rest fits a
    lamp with most of its sizes at the ends of their ranges. More than
    ``MAX_AT_BOUND`` of them there, it is dropped."""
    from csdf.detect import objects as O

    z, P, _ = _cropped_scan("box_taken_for_a_lamp")
    monkeypatch.setattr(O, "MAX_AT_BOUND", limit)
    # kept even when unsettled: a box shows no spokes, and the squeezed fit is judged here
    dets = csdf.detect(P, ["lamp"], viewpoint=(0, 0, 0), seed=0, keep_unsettled=True)
    if limit is not None:
        assert dets == []
        return
    assert [d.model for d in dets] == ["lamp"]
    assert np.all(z["instance"][dets[0].inliers] == 1)  # the box's points
    m = O._model("lamp", csdf.zoo.load("lamp"), None)
    assert len(O._at_bound(m, dets[0].params)) > 3


def test_the_picture_draws_a_lamps_thin_shade():
    """The picture's samples of a detected lamp lie on its shade too (a wall of 1.5 mm,
    the range's end, that the mesh for 4,000 samples at its default resolution lost:
    a tenth of the samples there against two fifths, and a warning), and no mesh
    warning reaches the user."""
    import warnings

    from csdf.detect.picture import _samples

    lamp = csdf.zoo.load("lamp")
    params = {p.name: float(p.default) for p in lamp.params}
    params["wall"] = 0.0015
    d = csdf.Detection(model="lamp", pose=csdf.Pose(), params=params, score=1.0,
                       inliers=np.zeros(0, dtype=int), shape=lamp)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        S, N = _samples(d, 0)
    z0 = 0.025 + params["stem_height"] - 0.06  # the shade's lower rim
    r = np.hypot(S[:, 0], S[:, 1])
    shade = (S[:, 2] > z0 + 0.01) & (r > params["shade_top"] - 0.01)
    assert shade.mean() > 0.3
    assert np.allclose(np.linalg.norm(N, axis=1), 1.0)


@pytest.mark.parametrize("sized", [True, False])
def test_a_tall_models_fit_gathers_the_points_of_its_own_top(monkeypatch, sized):
    """``_gather`` takes the points in the bounding sphere of the model stretched up to
    its top at the start's parameters (``GATHER_SIZED``): a lamp on a 0.38 m stem (the
    default is 0.3) with a 0.22 m shade (0.18) reaches 0.12 m above the default
    lamp's top, and about the defaults' centre and radius the top of its shade was
    left out of its fit (benchmark scene 269: the shade came out 0.08 m short)."""
    from csdf.detect import objects as O

    P, inst, run, m, gt, full = _lamp_prepared(
        _yawed(0.3, (0.0, 0.3, 0.0)), {"stem_height": 0.38, "shade_height": 0.22},
        (0.0, -1.6, 1.6), (0.0, 0.3, 0.4), 0.01, 4)
    own = np.flatnonzero((inst == 1) & (run.label >= 0))
    idx = np.flatnonzero(np.isin(run.label, np.unique(run.label[own])))
    monkeypatch.setattr(O, "GATHER_SIZED", sized)
    got = run._gather(m, idx, {"rotation": gt.rotation, "translation": gt.translation,
                               "params": full})
    top = (P[own] - gt.translation) @ gt.rotation[:, 2] > 0.5  # the shade's upper part
    assert top.sum() > 50
    share = np.isin(own[top], got).mean()
    if sized:
        assert share == 1.0
    else:
        assert share < 0.8


@pytest.mark.parametrize("bad", [-1, "a", 1.5, True])
def test_bad_seeds_are_named_before_any_work(bad):
    P, N = _noisy_samples(csdf.sphere(0.3), 200, seed=0)
    cam = csdf.Camera.look_at(eye=(0, -2, 0), target=(0, 0, 0), fov=40, width=8, height=6)
    calls = [lambda: csdf.detect_primitives(P, N, seed=bad),
             lambda: csdf.detect(P, ["stool"], seed=bad),
             lambda: csdf.infer(P, N, seed=bad),
             lambda: csdf.scan(csdf.sphere(0.3), cam, seed=bad),
             lambda: csdf.sample_surface(csdf.sphere(0.3), 10, seed=bad)]
    for call in calls:
        with pytest.raises(csdf.CsdfError, match="seed must be None, a whole number >= 0"):
            call()


def test_noise_free_cone_caps_join_the_cone():
    """A capped cone sampled without noise is one cone: its caps join it (they came out
    as two planes while the frustum's gradient was 0 on them)."""
    P, N = csdf.sample_surface(csdf.capped_cone(0.3, 0.1, 0.5), 3000, seed=0)
    dets = csdf.detect_primitives(P, N, seed=0)
    assert [d.kind for d in dets] == ["cone"] and len(dets[0].inliers) == 3000


def test_range_noise_reads_a_single_views_noise_where_neighbourhoods_do_not():
    """csdf.scan's range noise from the scan alone: the ranges against their angular
    neighbours' (the rays' directions are exact), at noise below and far above the
    point spacing; the neighbourhoods' spread reads a fraction of it."""
    from csdf.detect.neighbours import range_noise

    lamp = csdf.zoo.load("lamp")
    cam = csdf.Camera.look_at(eye=(0.9, -0.9, 0.8), target=(0.0, 0.0, 0.3), fov=40,
                              width=320, height=240)
    for noise in (0.002, 0.01):
        P, _ = csdf.scan(lamp, cam, noise=noise, seed=3)
        P = np.asarray(P)
        est = range_noise(P, np.zeros(3))  # (csdf.scan's points: the camera frame)
        assert abs(est - noise) < 0.25 * noise, (noise, est)  # (curvature: +17 % at 2 mm)
        assert neighbourhood(P).noise < 0.7 * noise
    assert range_noise(P[:5], np.zeros(3)) == 0.0


def test_an_object_scanned_without_a_floor_is_found_at_the_scans_noise(tmp_path):
    """A new user's first try, on the command line: ``csdf scan chair --noise 0.003``
    then ``csdf detect``. With no support plane to read the noise from, the
    neighbourhoods' estimate (1.3 mm) made every fit fail its checks, and nothing was
    found; the noise is read off the ranges now (3.1 mm)."""
    import json

    from typer.testing import CliRunner

    from csdf.cli import app

    runner = CliRunner()
    ply, out = tmp_path / "chair.ply", tmp_path / "scene.json"
    r = runner.invoke(app, ["scan", "chair", "-o", str(ply), "--noise", "0.003",
                            "--seed", "1"])
    assert r.exit_code == 0, r.output
    r = runner.invoke(app, ["detect", str(ply), "--models", "chair,stool", "-o", str(out)])
    assert r.exit_code == 0, r.output
    found = [i["model"]["zoo"] for i in json.loads(out.read_text())["instances"]]
    assert found == ["chair"], r.output


@pytest.mark.parametrize("model, noise", [("lamp", "0.003"), ("lamp", "0.0"),
                                          ("table", "0.01")])
def test_an_object_scanned_on_its_own_in_pieces_is_found_once(tmp_path, model, noise):
    """With no support there are no upright hypotheses to gather an object's pieces:
    a lamp's scan falls into two clusters (its shade; its stem and base) whose fits
    each failed, so nothing was found; a table's at 1 cm noise into four (its top and
    legs), and its top alone was fitted as a table 5 cm too high (with joining tried
    only after a cluster failed, its legs were then fitted as a second table). Each
    cluster is now also fitted joined by its nearest clusters, which competes with
    its own fit. With no support, the last step ray-casts its turns about its own
    axis and turns it to the best (the lamp came out 23 degrees off without it at 3
    mm noise, 30 degrees off without noise)."""
    import json

    from typer.testing import CliRunner

    from csdf.cli import app

    runner = CliRunner()
    ply, out = tmp_path / "one.ply", tmp_path / "scene.json"
    r = runner.invoke(app, ["scan", model, "-o", str(ply), "--noise", noise, "--seed", "1",
                            "--world"])
    assert r.exit_code == 0, r.output
    r = runner.invoke(app, ["detect", str(ply), "--models", "chair,table,stool,lamp",
                            "-o", str(out)])
    assert r.exit_code == 0, r.output
    found = json.loads(out.read_text())["instances"]
    assert [i["model"]["zoo"] for i in found] == [model], r.output
    pose = found[0]["pose"]
    R = np.asarray(pose["rotation"])
    assert np.linalg.norm(pose["translation"]) < 0.02  # scanned at the origin, upright
    assert R[2, 2] > math.cos(math.radians(2.0))
    period = {"lamp": 120.0, "table": 180.0}[model]  # its symmetry about z
    turn = math.degrees(math.atan2(R[1, 0], R[0, 0])) % period
    assert min(turn, period - turn) < 5.0


def test_a_bookshelf_scanned_side_on_with_no_floor_is_unsettled(tmp_path):
    """Found as a new user: a bookshelf scanned on its own (no floor, so no support to
    turn it about) exactly side-on was reported settled, turned half round. Its half
    turn about its own z axis ties with its turn in the rays, so it is left out unless
    ``--keep-unsettled``; scanned from the default corner (its open front seen), it is
    settled."""
    import json

    from typer.testing import CliRunner

    from csdf.cli import app

    runner = CliRunner()
    side, front, out = tmp_path / "side.ply", tmp_path / "front.ply", tmp_path / "s.json"
    for ply, extra in ((side, ["--eye", "3,0,1.7", "--target", "0,0,0.7"]), (front, [])):
        r = runner.invoke(app, ["scan", "bookshelf", "-o", str(ply), "--noise", "0.01",
                                "--size", "320x240", "--world", *extra])
        assert r.exit_code == 0, r.output
    models = ["--models", "bookshelf,table,chair", "-o", str(out)]
    r = runner.invoke(app, ["detect", str(side), *models])
    assert r.exit_code == 0 and "left out" in r.output, r.output
    assert json.loads(out.read_text())["instances"] == []
    r = runner.invoke(app, ["detect", str(side), *models, "--keep-unsettled"])
    assert r.exit_code == 0, r.output
    assert [i["model"]["zoo"] for i in json.loads(out.read_text())["instances"]] == [
        "bookshelf"]
    r = runner.invoke(app, ["detect", str(front), *models])
    assert r.exit_code == 0 and "left out" not in r.output, r.output
    found = json.loads(out.read_text())["instances"]
    assert [i["model"]["zoo"] for i in found] == ["bookshelf"]
    assert np.asarray(found[0]["pose"]["rotation"])[0, 0] > 0.99  # not turned half round


@pytest.mark.parametrize("lift", [True, False])
def test_a_lamp_standing_on_a_table_is_found_on_its_top(monkeypatch, lift):
    """Every upright hypothesis stood on the support (the floor), so a lamp standing
    on a table was not found: its shade's cluster fits no lamp whose base is on the
    floor. A cluster that nothing standing on the support explains is tried again
    standing on each surface facing up under it (``best_lifted``): here the table's
    top (0.75 m) and its own base's top (2.5 cm higher), and the fit on the table's
    top, which explains more, wins. (Its spokes are hidden in its shade from here, so
    its half turn scores as well as its turn: it is kept with ``keep_unsettled``.)"""
    from csdf.detect import objects as O

    monkeypatch.setattr(O, "LIFT", lift)
    scene = _floor_scene()
    scene.add("table", pose=csdf.Pose(), name="table")
    scene.add("lamp", pose=csdf.Pose(translation=(0.3, 0.1, 0.75)), name="lamp")
    cam = csdf.Camera.look_at(eye=(1.5, -2.5, 1.8), target=(0.0, 0.0, 0.6), fov=50,
                              width=320, height=240)
    P, _, _ = csdf.scan(scene, cam, noise=0.003, seed=1)
    dets = csdf.detect(P, ["table", "lamp", "chair"], viewpoint=(0, 0, 0),
                       keep_unsettled=True)
    lamps = [cam.R @ d.pose.translation + cam.t for d in dets if d.model == "lamp"]
    assert [d.model for d in dets].count("table") == 1
    if not lift:
        assert lamps == []  # the old behaviour: the lamp is not found
        return
    assert len(lamps) == 1
    assert np.linalg.norm(lamps[0] - np.array([0.3, 0.1, 0.75])) < 0.01


@pytest.mark.parametrize("narrow", [True, False])
def test_a_bookshelf_grown_over_a_stool_beside_it_is_cut_back(monkeypatch, narrow):
    """A bookshelf seen from behind with a stool against its unseen side: one
    cluster, and every free fit grew the bookshelf over the stool (width 1.1 m
    against 0.64, its centre 0.24 m off), the far side panel unseen and part of its
    back seen through. Refits held at narrower widths from either side
    (``_narrowed``) explain as much with nothing seen through, and win."""
    from csdf.detect import objects as O

    monkeypatch.setattr(O, "NARROW_STEPS", (0.5, 0.7) if narrow else None)
    scene = _floor_scene()
    scene.add("bookshelf", pose=csdf.Pose(), name="shelf",
              params={"width": 0.64, "depth": 0.33, "shelf_spacing": 0.32})
    scene.add("stool", pose=_yawed(math.radians(156.0), (-0.6, 0.36, 0.0)), name="stool")
    cam = csdf.Camera.look_at(eye=(2.14, 1.79, 1.62), target=(0.0, 0.0, 0.6), fov=50,
                              width=320, height=240)
    P, _, _ = csdf.scan(scene, cam, noise=0.015, seed=1)
    dets = csdf.detect(P, ["bookshelf", "stool", "table"], viewpoint=(0, 0, 0))
    shelves = [d for d in dets if d.model == "bookshelf"]
    assert len(shelves) == 1 and [d.model for d in dets].count("stool") == 1
    centre = cam.R @ shelves[0].pose.translation + cam.t
    if not narrow:
        assert shelves[0].params["width"] > 0.95  # the old behaviour: grown over the stool
        return
    assert shelves[0].params["width"] < 0.8
    assert np.linalg.norm(centre[:2]) < 0.08


@pytest.mark.parametrize("merge", [True, False])
def test_a_table_split_by_an_occluder_is_found_once(monkeypatch, merge):
    """A bookshelf in front of a table's middle splits the table's points in two
    clusters, and each was found as a short table turned a quarter, the two
    overlapping (benchmark scene 170). Two detections of one model that share space
    are fitted again as one (``_merge_overlaps``), from each's fit with its length
    and width traded too: the table is found once, at its size. (The growth of a
    short winner into what the sensor did not see, ``_completed``, also joins the
    halves here, as a 1.4 m table 4 cm off centre; it is turned off to see the merge
    alone. The bookshelf is seen side-on, its front and back alike: it is kept with
    ``keep_unsettled``.)"""
    from csdf.detect import objects as O

    monkeypatch.setattr(O, "MERGE_OVERLAP", 0.2 if merge else None)
    monkeypatch.setattr(O, "COMPLETE_LOSS", None)
    scene = _floor_scene()
    size = {"height": 0.846, "length": 1.49, "width": 0.943, "top": 0.044, "leg": 0.085,
            "inset": 0.09}
    scene.add("table", pose=csdf.Pose(), params=size, name="table")
    scene.add("bookshelf", pose=_yawed(math.radians(-94.5), (-0.12, 1.487, 0.0)),
              params={"width": 0.777, "depth": 0.34}, name="shelf")
    cam = csdf.Camera.look_at(eye=(-0.1, 3.35, 1.87), target=(0.0, 0.0, 0.5), fov=50,
                              width=320, height=240)
    P, _, _ = csdf.scan(scene, cam, noise=0.02, seed=1)
    dets = csdf.detect(P, ["table", "bookshelf", "chair"], viewpoint=(0, 0, 0),
                       keep_unsettled=True)
    tables = [d for d in dets if d.model == "table"]
    if not merge:
        assert len(tables) == 2  # the old behaviour: two short tables
        return
    assert len(tables) == 1 and [d.model for d in dets].count("bookshelf") == 1
    centre = cam.R @ tables[0].pose.translation + cam.t
    assert np.linalg.norm(centre) < 0.03
    assert abs(tables[0].params["length"] - 1.49) < 0.05
    assert abs(tables[0].params["width"] - 0.943) < 0.05


@pytest.mark.parametrize("hidden", [0.5, None])
def test_a_table_split_apart_by_an_occluder_is_found_once(monkeypatch, hidden):
    """Benchmark scene 316 (fresh seed), cropped to the table, the two bookshelves in
    front of it and the floor within 1.6 m: a 1.88 m table whose middle a bookshelf
    hid was found as two tables a quarter turned, 1.40 and 0.99 m long and about 0.3 m
    apart, sharing no space, so the merge of overlapping detections never tried them.
    A start grown along the line between them to span both, whose surface between
    them the sensor could not see (``MERGE_HIDDEN``), is fitted to both's points: one
    table at its length."""
    from csdf.detect import objects as O

    z, P, error = _cropped_scan("table_split_apart", "table")
    monkeypatch.setattr(O, "MERGE_HIDDEN", hidden)
    dets = csdf.detect(P, ["table"], viewpoint=(0, 0, 0), seed=0)
    if hidden is None:
        assert len(dets) == 2 and all(error(d.pose) > 0.5 for d in dets)  # as before
        return
    assert len(dets) == 1 and error(dets[0].pose) < 0.05
    assert abs(dets[0].params["length"] - 1.883) < 0.08
    assert np.mean(z["instance"][dets[0].inliers] == 2) > 0.95  # the table's points


def test_offset_noise_leaves_each_point_out_of_its_own_plane():
    """A plane sampled 1 cm apart with 2 mm of noise: each point's offset from its
    neighbours' plane reads the noise; the neighbourhoods' spread, whose planes take
    in each point's own noise, reads less."""
    from csdf.detect.neighbours import offset_noise

    rng = np.random.default_rng(4)
    P = np.c_[rng.uniform(0.0, 1.0, (6000, 2)), rng.normal(0.0, 0.002, 6000)]
    nb = neighbourhood(P)
    assert abs(offset_noise(P, nb) - 0.002) < 0.2 * 0.002
    assert offset_noise(P, nb) > nb.noise


def test_prepared_models_are_kept_on_disk_and_detect_the_same(clutter, tmp_path,
                                                              monkeypatch):
    """A model prepared for detection (mesh, samples, parameter bank, and what is made on
    first use) is kept in the cache folder; a new process (the in-process models
    dropped) reads it instead of preparing the model again and detects exactly the same.
    A file that cannot be read is made anew; ``CSDF_MODEL_CACHE=0`` keeps nothing."""
    import importlib

    O = importlib.import_module("csdf.detect.objects")
    MC = importlib.import_module("csdf.detect.modelcache")
    monkeypatch.setattr(MC, "kernel_cache_dir", lambda: tmp_path)
    monkeypatch.setattr(O, "_MODELS", {})
    P = clutter[0]
    first = csdf.detect(P, ["stool", "table"], viewpoint=(0, 0, 0), seed=0)
    files = sorted((tmp_path / "detect-models").glob("*.npz"))
    assert len(files) == 2
    O._MODELS.clear()

    def no_meshing(*a, **k):
        raise AssertionError("a kept model was prepared again")

    with monkeypatch.context() as mp:
        mp.setattr(csdf.metrics, "model_points", no_meshing)
        again = csdf.detect(P, ["stool", "table"], viewpoint=(0, 0, 0), seed=0)
    assert [d.model for d in again] == [d.model for d in first]
    for a, b in zip(first, again):
        np.testing.assert_array_equal(a.pose.matrix, b.pose.matrix)
        assert a.params == b.params and np.array_equal(a.inliers, b.inliers)
    # a damaged file is made anew
    files[0].write_bytes(b"not a zip file")
    O._MODELS.clear()
    third = csdf.detect(P, ["stool", "table"], viewpoint=(0, 0, 0), seed=0)
    np.testing.assert_array_equal(third[0].pose.matrix, first[0].pose.matrix)
    assert MC.load(files[0].stem) is not None
    # other settings, another entry; the cache turned off keeps nothing
    assert MC.entry_key(b"x", (1,)) != MC.entry_key(b"x", (2,))
    monkeypatch.setenv("CSDF_MODEL_CACHE", "0")
    assert MC.directory() is None and MC.load(files[0].stem) is None
