"""csdf.infer's parts: tree normal forms, sign-aware growth, candidates from planes,
surface samples, the free space of a scan, the score's orientation and support terms,
and the joint refinement."""

from __future__ import annotations

import math

import numpy as np
import pytest

import csdf
from csdf.infer import tree as T
from csdf.infer.candidates import Leaf, leaf_area, leaf_surface, plane_boxes
from csdf.infer.pool import (
    Pool,
    background_points,
    free_points,
    oriented_normals,
    support_scales,
)
from csdf.infer.refine import refine_params
from csdf.infer.search import Scorer, consistent, grow, parities
from strategies import random_csg_tree


def test_normal_form_merges_only_trees_of_one_field():
    # (a - b) & c is (a & c) - b, and canonical's identities hold too
    assert T.normal_form(("intersection", ("difference", 0, 1), 2)) == \
        T.normal_form(("difference", ("intersection", 2, 0), 1))
    assert T.normal_form(("difference", ("difference", 0, 1), 2)) == \
        T.normal_form(("difference", 0, ("union", 2, 1)))
    assert T.normal_form(("union", ("difference", 0, 1), 2)) != \
        T.normal_form(("difference", ("union", 0, 2), 1))
    rng = np.random.default_rng(0)
    vals = rng.normal(size=(5, 2000))
    fields: dict[str, np.ndarray] = {}
    for _ in range(1500):
        t = random_csg_tree(rng, list(rng.permutation(5)[: int(rng.integers(1, 6))]))
        key = T.normal_form(t)
        f = T.evaluate(t, vals)
        if key in fields:
            assert np.array_equal(fields[key], f), t
        fields[key] = f
        # trees canonical calls equal have one normal form
        assert T.normal_form(t) == T.normal_form(_shuffled(t, rng))


def _shuffled(t, rng):
    """The tree with the operands of its unions and intersections swapped at random."""
    if isinstance(t, int):
        return t
    op, a, b = t
    a, b = _shuffled(a, rng), _shuffled(b, rng)
    if op != "difference" and rng.random() < 0.5:
        a, b = b, a
    return (op, a, b)


def test_relocations_scope_and_cuts_last():
    """A cut moved to another subtree keeps the leaves and their sides; of two
    writings the one whose cut reaches fewer parts has the smaller scope; cuts_last
    writes the same set (the same field everywhere) with no difference under an
    intersection."""
    t = ("difference", ("union", 0, 2), 1)  # (a | c) - b
    moved = {T.canonical(r) for r in T.relocations(t)}
    local = ("union", ("difference", 0, 1), 2)  # (a - b) | c
    assert T.canonical(local) in moved and T.canonical(t) not in moved
    assert T.scope(local) < T.scope(t)
    assert T.scope(("union", 0, 1)) == 0
    # (a | b) & c against a | (b & c): the trim of fewer parts has the smaller scope
    assert T.scope(("union", 0, ("intersection", 1, 2))) < \
        T.scope(("intersection", ("union", 0, 1), 2))
    rng = np.random.default_rng(3)
    vals = rng.normal(size=(6, 500))
    signs = rng.integers(-1, 2, 6)
    for _ in range(300):
        t = random_csg_tree(rng, list(rng.permutation(6)[: int(rng.integers(2, 7))]))
        for r in T.relocations(t):
            assert sorted(T.leaves(r)) == sorted(T.leaves(t))
            if consistent(t, signs) and parities(r) == parities(t):
                assert consistent(r, signs)
        c = T.cuts_last(t)
        assert np.array_equal(T.evaluate(c, vals), T.evaluate(t, vals))
        assert T.normal_form(c) == T.normal_form(t)
        assert not _cut_in_intersection(c), c
    assert T.cuts_last(("intersection", ("difference", 0, 1), 2)) == \
        ("difference", ("intersection", 0, 2), 1)


def _cut_in_intersection(t) -> bool:
    """Whether an operand of an intersection is a difference."""
    if isinstance(t, int):
        return False
    op, a, b = t
    if op == "intersection" and any(not isinstance(x, int) and x[0] == "difference"
                                    for x in (a, b)):
        return True
    return _cut_in_intersection(a) or _cut_in_intersection(b)


def test_grow_keeps_every_leaf_on_its_side():
    """A leaf whose points face into it (-1) only ever lies under an odd number of
    right operands of differences, one facing out (+1) under an even number; growth
    offers exactly the trees that keep that."""
    rng = np.random.default_rng(1)
    checked = 0
    for _ in range(600):
        signs = rng.integers(-1, 2, 7)
        t = random_csg_tree(rng, list(rng.permutation(6)[: int(rng.integers(1, 5))]))
        if not consistent(t, signs):
            continue
        want = []
        for path, sub in T.subtrees(t):
            for new in (("union", sub, 6), ("intersection", sub, 6), ("difference", sub, 6),
                        ("difference", 6, sub)):
                u = T.replace(t, path, new)
                if consistent(u, signs):
                    want.append(u)
        assert sorted(map(str, grow(t, 6, signs))) == sorted(map(str, want))
        checked += 1
    assert checked > 100
    assert parities(("difference", 0, ("difference", 1, 2))) == {0: False, 1: True, 2: False}


def _plane(P, N, mask):
    Q = P[mask]
    n = N[mask].mean(axis=0)
    n /= np.linalg.norm(n)
    return n, float(np.median(Q @ n)), Q


def test_plane_boxes_find_the_solid_and_the_cut():
    """A block with a notch cut from one edge: the candidates from its faces hold the
    block (material, +1) and the notch's box (a cut, -1, reaching past the block)."""
    block = csdf.box((2.0, 1.0, 1.0))
    notch = csdf.box((0.8, 2.0, 0.8)).translate((0.6, 0.0, 0.5))
    P, N = csdf.sample_surface(block - notch, 30_000, seed=0)
    faces = []
    for k in range(3):
        for side in (-1.0, 1.0):
            axis = np.eye(3)[k] * side
            on = N @ axis > 0.99
            offsets = np.round(P[on] @ axis, 3)
            for off in np.unique(offsets):
                m = on.copy()
                m[on] = offsets == off
                if m.sum() > 200:
                    faces.append(_plane(P, N, m))
    boxes = plane_boxes(faces, P, 0.005, 0.05)

    def has(sign, lo, hi):
        for b in boxes:
            if b.sign != sign or not np.allclose(np.abs(b.R), np.eye(3)[np.argmax(np.abs(b.R), 0)]):
                continue
            size = np.abs(b.R) @ np.array([b.vals["size_x"], b.vals["size_y"], b.vals["size_z"]])
            blo, bhi = b.t - size / 2, b.t + size / 2
            if np.all(np.abs(blo - lo) <= 0.02 + (lo == -9) * 9) and \
                    np.all(np.abs(bhi - hi) <= 0.02 + (hi == 9) * 9):
                return True
        return False

    assert has(1, np.array([-1.0, -0.5, -0.5]), np.array([1.0, 0.5, 0.5]))
    # the notch: its floor and inner wall are seen; it goes on past the block elsewhere
    cut = [b for b in boxes if b.sign < 0]
    assert cut
    q = np.array([[0.6, 0.0, 0.4], [0.9, 0.45, 0.45], [0.3, -0.45, 0.2]])  # in the notch
    assert any(np.all(b.values(q)[0] < 0) for b in cut)
    outside = np.array([[-0.5, 0.0, 0.0], [0.5, 0.0, -0.3]])  # block material left
    assert any(np.all(b.values(q)[0] < 0) and np.all(b.values(outside)[0] > 0) for b in cut)


@pytest.mark.parametrize("kind,vals", [
    ("sphere", {"radius": 0.7}), ("cylinder", {"radius": 0.3, "height": 1.1}),
    ("cone", {"r1": 0.5, "r2": 0.1, "height": 0.8}), ("torus", {"major": 0.5, "minor": 0.2}),
    ("box", {"size_x": 1.0, "size_y": 0.4, "size_z": 0.7})])
def test_leaf_surface_is_on_the_surface_and_uniform(kind, vals):
    R = csdf.Pose.from_rotvec(np.array([0.3, -0.5, 0.2])).rotation
    lf = Leaf(kind, R, np.array([0.1, 0.2, -0.3]), vals)
    q, nrm, area = leaf_surface(lf, 40_000, np.random.default_rng(0))
    assert np.abs(lf.values(q)[0]).max() < 1e-9
    # the normals: the distance's gradient just outside each point
    f, g = lf.values(q + 1e-6 * nrm)
    assert np.allclose(f, 1e-6, atol=1e-9) and np.einsum("ij,ij->i", g, nrm).min() > 0.999
    # the area from the shape's mesh
    m = csdf.mesh(lf_shape(lf), resolution=120, progress=False, check_thin=False)
    v, f = m.vertices, m.faces
    mesh_area = 0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]),
                                     axis=1).sum()
    assert area == pytest.approx(mesh_area, rel=0.02)
    assert leaf_area(lf) == pytest.approx(area, rel=1e-12)  # the same area without points
    # uniform by area: the share of the points on each half (by a plane through the
    # centre) matches the share of the area
    side = (q - lf.t) @ np.array([1.0, 0.0, 0.0]) > 0
    centres = v[f].mean(axis=1)
    tri = 0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)
    share = tri[(centres - lf.t) @ np.array([1.0, 0.0, 0.0]) > 0].sum() / tri.sum()
    assert side.mean() == pytest.approx(share, abs=0.02)


def lf_shape(lf: Leaf):
    from csdf.detect.solids import posed

    return posed(lf.kind, lf.R, lf.t, lf.vals)


def _scan(shape, eye, target, noise=0.002, seed=0):
    cam = csdf.Camera.look_at(eye, target, width=320, height=240)
    pc, _ = csdf.scan(shape, cam, noise=noise, seed=seed)
    M = cam.pose
    return pc @ M[:3, :3].T + M[:3, 3], M[:3, 3]


def test_free_space_of_a_scan_is_outside_the_object():
    """Points on the rays to the measured points and past the silhouette lie outside
    the scanned object; past the silhouette they surround it."""
    shape = csdf.sphere(0.5) | csdf.box((1.2, 0.3, 0.3))
    P, vp = _scan(shape, (2.5, -2.0, 1.5), (0, 0, 0))
    rng = np.random.default_rng(0)
    f = csdf.as_field(shape)
    a = free_points(P, vp, 0.004, 1.6, rng, 2000)
    b = background_points(P, vp, 1.6, rng, 2000)
    assert len(a) > 1500 and len(b) == 2000
    assert (f.value(a) > 0).mean() > 0.99
    assert (f.value(b) > 0).all()
    # around the silhouette: directions on all sides of the object
    d = (b - vp) / np.linalg.norm(b - vp, axis=1, keepdims=True)
    c = (P - vp).mean(axis=0)
    c /= np.linalg.norm(c)
    side = np.cross(d, c)
    assert np.ptp(side[:, 0]) > 0 and (side @ np.array([0.0, 0.0, 1.0]) > 0).any() and \
        (side @ np.array([0.0, 0.0, 1.0]) < 0).any()


def test_oriented_normals():
    P, N = csdf.sample_surface(csdf.box((1.0, 0.6, 0.4)), 4000, seed=0)
    assert oriented_normals(P, N) is N
    assert np.array_equal(oriented_normals(P, -N), N)
    flip = np.where(np.random.default_rng(0).random(len(N)) < 0.5, -1.0, 1.0)[:, None]
    assert oriented_normals(P, N * flip) is None


def _pool(P, N, leaves, tau=0.01):
    from scipy.spatial import cKDTree

    kd = cKDTree(P)
    reach, area = support_scales(kd, P, len(P), tau)
    pool = Pool(P, N, None, kd, N, reach, area, tau, 0.004, np.random.default_rng(0))
    pool.add(leaves)
    return pool


def test_normals_tell_a_bump_from_a_dent():
    """A sphere on a box's face through the same points: added (a bump) or cut (a dent)
    differ only in which way the points' normals face."""
    base = csdf.box((2.0, 2.0, 1.0))
    ball = csdf.sphere(0.4).translate((0.0, 0.0, 0.5))
    leaves = [Leaf("box", np.eye(3), np.zeros(3), {"size_x": 2.0, "size_y": 2.0, "size_z": 1.0}),
              Leaf("sphere", np.eye(3), np.array([0.0, 0.0, 0.5]), {"radius": 0.4})]
    for shape, good, bad in ((base | ball, "union", "difference"),
                             (base - ball, "difference", "union")):
        P, N = csdf.sample_surface(shape, 8000, seed=1)
        sc = _pool(P, N, leaves).scorer()
        assert sc.score((good, 0, 1)).total < sc.score((bad, 0, 1)).total - 0.02
        blind = Scorer(sc.at_points, None, None, sc.tau, sc.penalty)  # without normals
        assert abs(blind.score((good, 0, 1)).data - blind.score((bad, 0, 1)).data) < 0.1


def test_made_up_surface_needs_points_facing_its_way():
    """A thin plate's inside: a cut whose face runs just under the top face is near
    the top face's points but faces the other way, so it is made up."""
    plate = csdf.box((2.0, 2.0, 0.1))
    P, N = csdf.sample_surface(plate, 20_000, seed=2)
    leaves = [Leaf("box", np.eye(3), np.zeros(3), {"size_x": 2.0, "size_y": 2.0, "size_z": 0.1}),
              Leaf("box", np.eye(3), np.array([0.0, 0.0, -0.48]),
                   {"size_x": 1.0, "size_y": 1.0, "size_z": 1.04})]  # top at z = 0.04
    sc = _pool(P, N, leaves, tau=0.002).scorer()
    plain, cut = sc.score(0), sc.score(("difference", 0, 1))
    assert plain.free < 0.01
    assert cut.free > 0.1 and cut.total > plain.total + 0.05


def test_refinement_recovers_sizes_and_positions():
    shape = csdf.box((1.2, 0.8, 0.6)) - csdf.cylinder(0.25, 1.0).translate((0.2, 0.0, 0.0))
    P, N = csdf.sample_surface(shape, 6000, seed=3)
    from csdf.expr import param

    names = {"bx": 1.1, "by": 0.85, "bz": 0.55, "cr": 0.2, "ch": 1.0, "cx": 0.25,
             "ox": 0.03, "oy": -0.02, "oz": 0.02}
    p = {k: param(k, v) for k, v in names.items()}
    model = csdf.box((p["bx"], p["by"], p["bz"])).translate((p["ox"], p["oy"], p["oz"])) - \
        csdf.cylinder(p["cr"], p["ch"]).translate((p["cx"], 0.0, 0.0))
    out = refine_params(model, dict(names), {"bx", "by", "bz", "cr", "ch"}, P, N, None, 0.01,
                        "interp")
    want = {"bx": 1.2, "by": 0.8, "bz": 0.6, "cr": 0.25, "cx": 0.2, "ox": 0.0, "oy": 0.0,
            "oz": 0.0}
    for k, v in want.items():
        assert out[k] == pytest.approx(v, abs=0.005), k
    assert math.isclose(out["ch"], 1.0)  # the hole's length shows in no point


@pytest.mark.parametrize("kind,vals", [
    ("box", {"size_x": 1.0, "size_y": 0.5, "size_z": 0.3}),
    ("cone", {"r1": 0.4, "r2": 0.2, "height": 0.8}),
    ("torus", {"major": 0.4, "minor": 0.1}),
])
def test_a_leaf_turned_by_the_refinement_is_the_shape_it_fitted(kind, vals):
    """The refinement's shape (turn angles as parameters) and the leaf posed by
    ``R @ turn_matrix(...)`` are one solid."""
    from csdf.infer import api as A
    from csdf.infer.refine import turn_matrix
    from csdf.shapes.domain import orient_matrix

    R = np.eye(3) if kind == "box" else orient_matrix([0.3, 0.2, 0.9])
    lf = Leaf(kind, R, np.array([0.1, 0.2, 0.3]), vals)
    ang = {"x": 0.1, "y": -0.2, "z": 0.3 if kind == "box" else 0.0}
    X = np.random.default_rng(0).normal(size=(300, 3))
    params = {f"a_turn_{k}": v for k, v in ang.items() if k in A.TURNS[kind]}
    f = csdf.as_field(A._leaf_shape(lf, "a", True), params=params).value(X)
    posed = lf.moved(R=R @ turn_matrix(ang["x"], ang["y"], ang["z"]))
    assert np.allclose(f, posed.values(X)[0], atol=1e-12)
    assert np.allclose(A._turned(lf, ang["x"], ang["y"], ang["z"]).values(X)[0],
                       posed.values(X)[0], atol=1e-12)


def test_refinement_turns_an_axis_detected_askew():
    """A cone detected 5.5 degrees off its axis is turned onto it (and snapped to the
    coordinate axis it lies along) by the joint refinement, with its sizes."""
    from types import SimpleNamespace

    from csdf.infer import api as A
    from csdf.shapes.domain import orient_matrix

    shape = csdf.box((1.0, 1.0, 0.4)) | \
        csdf.capped_cone(0.35, 0.1, 0.6).translate((0.0, 0.0, 0.2))
    P, N = csdf.sample_surface(shape, 8000, seed=1)
    P = P + np.random.default_rng(0).normal(0.0, 0.003, P.shape)
    a = math.radians(5.5)
    leaves = [Leaf("box", np.eye(3), np.array([0.01, 0.0, 0.0]),
                   {"size_x": 1.0, "size_y": 1.02, "size_z": 0.4}, 1),
              Leaf("cone", orient_matrix([math.sin(a), 0.0, math.cos(a)]),
                   np.array([0.02, 0.01, 0.2]), {"r1": 0.34, "r2": 0.11, "height": 0.6}, 1)]
    idx = np.random.default_rng(0).choice(len(P), 2000, replace=False)
    prob = SimpleNamespace(pool=SimpleNamespace(leaves=leaves), fit_points=P[idx],
                           fit_normals=N[idx], fit_free=None, tau=0.01)
    still = A._refine(prob, ("union", 0, 1), False)[1]
    assert still.R[0, 2] == pytest.approx(math.sin(a))  # without turns: kept
    cone = A._refine(prob, ("union", 0, 1), True)[1]
    assert np.array_equal(cone.R[:, 2], [0.0, 0.0, 1.0])
    assert cone.vals["r1"] == pytest.approx(0.35, abs=0.005)
    assert cone.vals["r2"] == pytest.approx(0.1, abs=0.005)
    assert np.allclose(cone.t[:2], 0.0, atol=0.005)


def test_every_size_best_tree_is_refined():
    """The trees refined: by turns of the best tree's size and one leaf fewer or more,
    then the best of every other size (only those first ones polished whatever their
    score)."""
    from csdf.infer import api as A
    from csdf.infer.search import Scored

    trees = [("union", ("union", 0, 1), ("union", 2, 3)), ("union", ("union", 0, 1), 4),
             ("union", ("union", 0, 2), 4), ("union", 0, 1), 0,
             ("union", ("union", ("union", 0, 1), ("union", 2, 3)), 5)]
    found = [Scored(t, 0.0, 0.0, 0.1 + 0.01 * i) for i, t in enumerate(trees)]
    out, polished = A._to_refine(found, 3)
    assert out[:polished] == [trees[0], trees[1], trees[5]]  # sizes 4, 3, 5
    assert out[polished:] == [trees[4], trees[3]]  # sizes 1 and 2
    out, polished = A._to_refine(found, 5)
    assert out[:polished] == [trees[0], trees[1], trees[5], trees[2]]
    assert out[polished:] == [trees[4], trees[3]]


def test_a_notch_taken_for_a_cylinder_gives_its_planes():
    """Two faces at right angles (a notch's floor and wall), which a cylinder follows
    within a few noise levels, are found as two planes when they fit better."""
    from types import SimpleNamespace

    from csdf.infer import api as A

    rng = np.random.default_rng(4)
    floor = np.column_stack([rng.uniform(0, 0.3, 300), rng.uniform(-0.2, 0.2, 300),
                             np.zeros(300)])
    wall = np.column_stack([np.zeros(300), rng.uniform(-0.2, 0.2, 300),
                            rng.uniform(0, 0.3, 300)])
    Q = np.vstack([floor, wall]) + rng.normal(0, 0.001, (600, 3))
    NQ = np.vstack([np.tile([0.0, 0.0, 1.0], (300, 1)), np.tile([1.0, 0.0, 0.0], (300, 1))])
    prob = SimpleNamespace(P=Q, N=NQ, seed=0, vp=None)
    planes = A._corner_planes(prob, np.arange(600), rmse=0.02, eps=0.004)
    assert len(planes) == 2
    normals = sorted(tuple(np.round(np.abs(n), 2)) for n, _, _ in planes)
    assert normals == [(0.0, 0.0, 1.0), (1.0, 0.0, 0.0)]
    # a fit as good as the planes' keeps the curved detection alone
    assert A._corner_planes(prob, np.arange(600), rmse=0.0005, eps=0.004) == []


def test_a_cone_with_equal_radii_is_reported_as_its_cylinder():
    from scipy.spatial.transform import Rotation

    from csdf.infer.api import _straight_cones

    R = Rotation.from_euler("xyz", [0.3, -0.2, 0.5]).as_matrix()
    straight = Leaf("cone", R, np.array([0.1, 0.2, -0.3]),
                    {"r1": 0.3, "r2": 0.3 * (1 + 1e-9), "height": 1.7})
    tapered = Leaf("cone", R, np.array([0.1, 0.2, -0.3]),
                   {"r1": 0.3, "r2": 0.25, "height": 1.7})
    out = _straight_cones([straight, tapered, straight], [0, 1])
    assert [lf.kind for lf in out] == ["cylinder", "cone", "cone"]  # only those used
    X = np.random.default_rng(0).uniform(-2, 2, (2000, 3))
    assert np.abs(straight.values(X)[0] - out[0].values(X)[0]).max() < 1e-8
    assert out[1] is tapered


def test_a_face_inside_another_operand_is_not_made_up_surface(monkeypatch):
    """A box inside a cube, its top on the cube's: the strips of its sides within
    ``tau`` below the cube's top are near the tree's surface but are not it (the
    cube's top is, and points face its way there), so the union makes up no
    surface."""
    P, N = csdf.sample_surface(csdf.box((2.0, 2.0, 2.0)), 20_000, seed=5)
    leaves = [Leaf("box", np.eye(3), np.zeros(3), {"size_x": 2.0, "size_y": 2.0, "size_z": 2.0}),
              Leaf("box", np.eye(3), np.array([0.0, 0.0, 0.05]),
                   {"size_x": 1.0, "size_y": 1.0, "size_z": 1.9})]
    from csdf.infer import search

    sc = _pool(P, N, leaves, tau=0.05).scorer()
    assert sc.score(("union", 0, 1)).free > 0.005  # the default counts them
    monkeypatch.setattr(search, "ON_SURFACE", 1e-6)  # only the active operand's
    assert sc.score(0).free == 0.0
    assert sc.score(("union", 0, 1)).free == 0.0
    # surface that is the tree's and unmeasured still counts: the inner box cut out
    assert sc.score(("difference", 0, 1)).free > 0.3


def test_a_cone_whose_taper_is_within_the_noise_is_its_cylinder():
    """A cone fitted to a cylinder's points with a taper far below the noise is written
    as the cylinder; a cone whose taper the points show stays a cone."""
    from types import SimpleNamespace

    from csdf.infer.api import SOLID_KINDS, _straighten
    from csdf.infer.search import Scored

    tau = 0.01
    for r1, r2, want in ((0.402, 0.398, "cylinder"), (0.45, 0.3, "cone")):
        shape = csdf.capped_cone(r1, r2, 1.0).translate((0.0, 0.0, -0.5))
        P, N = csdf.sample_surface(shape, 6000, seed=6)
        P = P + np.random.default_rng(7).normal(0.0, tau / 3, P.shape)
        cone = Leaf("cone", np.eye(3), np.array([0.0, 0.0, -0.5]),
                    {"r1": r1, "r2": r2, "height": 1.0}, sign=1)
        pool = _pool(P, N, [cone], tau=tau)
        prob = SimpleNamespace(pool=pool, ks=SOLID_KINDS, tau=tau)
        sc = pool.scorer().score(0)
        out = _straighten(prob, Scored(0, sc.data, sc.free, sc.total))
        lf = pool.leaves[out.tree]
        assert lf.kind == want
        if want == "cylinder":
            assert lf.vals["radius"] == pytest.approx(0.4)
            assert np.allclose(lf.t, 0.0)


def test_a_trim_that_trims_nothing_is_dropped_after_the_face_moves():
    """A leaf whose removal lowers the score (a trim around the whole part: only its
    penalty) is dropped, and the rest stays as it is."""
    from types import SimpleNamespace

    from csdf.infer import api as A

    shape = csdf.box((1.0, 0.8, 0.6)) - csdf.sphere(0.3).translate((0.5, 0.0, 0.3))
    P, N = csdf.sample_surface(shape, 4000, seed=2)
    leaves = [Leaf("box", np.eye(3), np.zeros(3), {"size_x": 1.0, "size_y": 0.8,
                                                   "size_z": 0.6}, 1),
              Leaf("sphere", np.eye(3), np.array([0.5, 0.0, 0.3]), {"radius": 0.3}, -1),
              Leaf("box", np.eye(3), np.zeros(3), {"size_x": 2.0, "size_y": 2.0,
                                                   "size_z": 2.0}, 1)]
    prob = SimpleNamespace(pool=_pool(P, N, leaves))
    trimmed = prob.pool.scorer().score(("difference", ("intersection", 0, 2), 1))
    out = A._drop_leaves(prob, trimmed)
    assert out.tree == ("difference", 0, 1)
    assert out.total == pytest.approx(trimmed.total - 0.004, abs=1e-9)


def test_a_large_leaf_gets_more_surface_points_and_supported_ones_are_dropped():
    """A leaf's points for the made-up surface grow with its area, so that one stands
    for at most ``SURFACE_SHARE`` of the measured area; points measured points support
    (the way the leaf's sign lets it be used) never count, and only the others are
    kept."""
    from csdf.infer.pool import SURFACE_MAX, SURFACE_SAMPLES, SURFACE_SHARE, surface_samples

    assert surface_samples(0.01, 1.0) == SURFACE_SAMPLES
    n = surface_samples(1.0, 1.0)
    assert n == math.ceil(1.0 / SURFACE_SHARE) and SURFACE_SAMPLES < n < SURFACE_MAX
    assert surface_samples(1e6, 1.0) == SURFACE_MAX
    assert surface_samples(1.0, 0.0) == SURFACE_SAMPLES
    P, N = csdf.sample_surface(csdf.box((1.0, 1.0, 1.0)), 20_000, seed=3)
    cube = Leaf("box", np.eye(3), np.zeros(3), {"size_x": 1.0, "size_y": 1.0, "size_z": 1.0},
                1)
    big = Leaf("box", np.eye(3), np.zeros(3), {"size_x": 3.0, "size_y": 3.0, "size_z": 3.0},
               1)
    pool = _pool(P, N, [cube, big])
    kept = np.bincount(pool.owner, minlength=2)
    assert kept[0] < 0.01 * surface_samples(6.0, pool.area)  # the cube's: all supported
    assert kept[1] > 0.9 * surface_samples(54.0, pool.area)  # the big box's: none
    w = pool.weight[pool.owner == 1] / pool.area
    assert w.max() <= max(SURFACE_SHARE, 54.0 / pool.area / SURFACE_MAX) * 1.0001
    sc = pool.scorer()
    assert sc.score(0).free < 0.01 and sc.score(1).free > 5.0


def test_a_trial_scores_as_the_leaf_added():
    """:meth:`Pool.trial` scores a tree with one leaf replaced as the pool scores it once
    the leaf is added (the same draws of its surface points)."""
    import copy

    shape = csdf.box((2.0, 2.0, 0.5)) - csdf.cylinder(0.3, 1.0)
    P, N = csdf.sample_surface(shape, 8000, seed=4)
    box = Leaf("box", np.eye(3), np.zeros(3), {"size_x": 2.0, "size_y": 2.0, "size_z": 0.5}, 1)
    cyl = Leaf("cylinder", np.eye(3), np.array([0.0, 0.0, 0.1]),
               {"radius": 0.3, "height": 0.3}, -1)
    other = Leaf("sphere", np.eye(3), np.array([3.0, 0.0, 0.0]), {"radius": 0.2}, 1)
    pool = _pool(P, N, [box, other, cyl])
    tree = ("difference", 0, 2)
    longer = cyl.moved(t=np.zeros(3), vals={"radius": 0.3, "height": 0.7})
    twin = copy.deepcopy(pool)
    tried = pool.trial(tree, 2, [longer])[0]
    v = twin.add([longer])[0]
    added = twin.scorer().score(("difference", 0, v))
    assert tried.total == pytest.approx(added.total, abs=1e-12)
    assert tried.free == pytest.approx(added.free, abs=1e-12)
    assert tried.total < pool.scorer().score(tree).total - 0.01  # the skin is gone
    assert len(pool.leaves) == 3  # nothing added


def test_a_bounded_trial_scores_the_variants_that_can_win_as_before():
    """:meth:`Pool.trial` with a bound: None for exactly the variants scoring that or
    more, the others' scores as an unbounded trial gives them (the same draws), and
    the pool's generator left where the unbounded trial leaves it."""
    import copy

    shape = csdf.box((2.0, 2.0, 0.5)) - csdf.cylinder(0.3, 1.0)
    P, N = csdf.sample_surface(shape, 8000, seed=4)
    box = Leaf("box", np.eye(3), np.zeros(3), {"size_x": 2.0, "size_y": 2.0, "size_z": 0.5}, 1)
    cyl = Leaf("cylinder", np.eye(3), np.array([0.0, 0.0, 0.1]),
               {"radius": 0.3, "height": 0.3}, -1)
    pool = _pool(P, N, [box, cyl])
    tree = ("difference", 0, 1)
    variants = [cyl.moved(t=np.array([0.0, 0.0, z]), vals={"radius": r, "height": h})
                for z, r, h in ((0.0, 0.3, 0.7), (0.0, 0.3, 0.2), (0.1, 0.28, 0.7),
                                (0.0, 0.5, 0.7), (0.05, 0.3, 0.6), (0.3, 0.3, 0.2))]
    twin = copy.deepcopy(pool)
    full = twin.trial(tree, 1, variants)
    totals = sorted(s.total for s in full)
    below = 0.5 * (totals[2] + totals[3])
    got = pool.trial(tree, 1, variants, below)
    assert [g is None for g in got] == [f.total >= below for f in full]
    for g, f in zip(got, full):
        if g is not None:
            assert (g.data, g.free, g.total) == (f.data, f.free, f.total)
    assert pool.rng.random() == twin.rng.random()


def test_a_straight_stretch_of_a_huge_torus_is_offered_as_its_cylinder():
    """A strip of a cylinder's side (radius 0.2 along x) that detection took for a
    torus of major radius 40 (its tube along x there): the torus's other kind is the
    cylinder; a torus whose points go round its tube's bend has none."""
    from csdf.infer.candidates import other_kind

    rng = np.random.default_rng(7)
    ang = rng.uniform(-0.7, 0.7, 600)
    x = rng.uniform(-0.3, 0.3, 600)
    Q = np.stack([x, 0.2 * np.sin(ang), 0.2 * np.cos(ang)], axis=1)
    Q += rng.normal(0.0, 0.002, Q.shape)
    tor = Leaf("torus", np.eye(3), np.array([0.0, -40.0, 0.0]), {"major": 40.0, "minor": 0.2})
    rmse = float(np.sqrt(np.mean(tor.values(Q)[0] ** 2)))
    cyl = other_kind(tor, Q, rmse, 0.006)
    assert cyl is not None and cyl.kind == "cylinder" and cyl.origin == "straight-torus"
    assert abs(cyl.R[:, 2] @ np.array([1.0, 0.0, 0.0])) > 0.999
    assert cyl.vals["radius"] == pytest.approx(0.2, abs=0.005)
    assert np.abs(cyl.t[1:]).max() < 0.01 and abs(cyl.t[0]) < 0.03
    assert cyl.vals["height"] == pytest.approx(0.6, abs=0.05)
    # a ring: its points span its whole bend
    ring = Leaf("torus", np.eye(3), np.zeros(3), {"major": 0.5, "minor": 0.1})
    P, _ = csdf.sample_surface(csdf.torus(0.5, 0.1), 2000, seed=3)
    assert other_kind(ring, P, 0.002, 0.006) is None


def test_estimated_normals_support_surface_near_an_edge():
    """With estimated normals a measured point supports surface facing within 90
    degrees of its normal (near an edge they lean towards the other face); with given
    normals within 60. Surface facing away is unsupported either way."""
    from scipy.spatial import cKDTree

    P = np.zeros((1, 3))
    N = np.array([[0.0, 0.0, 1.0]])
    tilt = math.radians(75.0)
    g = np.array([[math.sin(tilt), 0.0, math.cos(tilt)], [0.0, 0.0, -1.0]])
    q = np.array([[0.001, 0.0, 0.0], [0.001, 0.0, 0.0]])
    for estimated, want in ((False, [True, True]), (True, [False, True])):
        pool = Pool(P, N, None, cKDTree(P), N, 0.01, 1.0, 0.01, 0.004,
                    np.random.default_rng(0), None, estimated)
        assert pool._unsupported(q, g)[0].tolist() == want  # as material


def test_a_cut_refined_short_is_moved_through():
    """A hole through a plate, given as a cut that stops short of the plate's bottom
    (a skin no point shows): :func:`_cuts_through` moves its end out and the tree then
    scores lower; a cut that is right stays as it is."""
    from types import SimpleNamespace

    from csdf.infer import api as A

    shape = csdf.box((2.0, 2.0, 0.5)) - csdf.cylinder(0.3, 1.0)
    P, N = csdf.sample_surface(shape, 20_000, seed=5)
    box = Leaf("box", np.eye(3), np.zeros(3), {"size_x": 2.0, "size_y": 2.0, "size_z": 0.5}, 1)
    short = Leaf("cylinder", np.eye(3), np.array([0.0, 0.0, 0.15]),
                 {"radius": 0.3, "height": 0.4}, -1)  # z from -0.05 to 0.35
    through = Leaf("cylinder", np.eye(3), np.zeros(3), {"radius": 0.3, "height": 1.0}, -1)
    prob = SimpleNamespace(pool=_pool(P, N, [box, short, through]), P=P)
    before = prob.pool.scorer().score(("difference", 0, 1))
    out = A._cuts_through(prob, ("difference", 0, 1))
    cut = prob.pool.leaves[out[2]]
    assert out[2] != 1 and cut.t[2] - cut.vals["height"] / 2 <= -0.25 + 1e-9
    assert prob.pool.scorer().score(out).total < before.total - 0.01
    kept = A._cuts_through(prob, ("difference", 0, 2))  # through already
    cut = prob.pool.leaves[kept[2]]
    assert cut.t[2] - cut.vals["height"] / 2 <= -0.25 + 1e-9
    assert cut.t[2] + cut.vals["height"] / 2 >= 0.25 - 1e-9


def _cone_band(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``n`` noisy points ``(n, 3)`` and outward normals ``(n, 3)`` of the side of a cone
    along z (radius 0.4 at z = 0, 0.1 at z = 0.6), all the way round."""
    rng = np.random.default_rng(seed)
    z = rng.uniform(0.0, 0.6, n)
    ang = rng.uniform(0.0, 2 * math.pi, n)
    r = 0.4 - 0.5 * z
    P = np.stack([r * np.cos(ang), r * np.sin(ang), z], axis=1)
    N = np.stack([np.cos(ang), np.sin(ang), np.full(n, 0.5)], axis=1)
    N /= np.linalg.norm(N, axis=1, keepdims=True)
    return P + rng.normal(0.0, 0.001, P.shape), N


def test_a_curved_candidate_is_detected_again_on_its_own_points():
    """A cone candidate 30 degrees off its points' axis (as a cone fitted to a narrow
    band may be): detection on those points alone offers the cone along their axis; a
    candidate already along it gets nothing more."""
    from types import SimpleNamespace

    from csdf.infer.api import _redetected

    P, N = _cone_band(3000, 11)
    prob = SimpleNamespace(P=P, N=N, seed=0, vp=None)
    vals = {"r1": 0.4, "r2": 0.1, "height": 0.6}
    tilt = math.radians(30.0)
    off = Leaf("cone", csdf.shapes.domain.orient_matrix(
        np.array([math.sin(tilt), 0.0, math.cos(tilt)])), np.zeros(3), vals, 1)
    found = _redetected(prob, off, np.arange(len(P)), 0.006)
    assert found, "no cone detected again"
    best = max(abs(float(c.R[:, 2] @ np.array([0.0, 0.0, 1.0]))) for c, _ in found)
    assert best > math.cos(math.radians(3.0))
    assert all(c.kind == "cone" and c.origin == "redetected" for c, _ in found)
    assert all(c.sign == 1 for c, _ in found)
    right = Leaf("cone", np.eye(3), np.zeros(3), vals, 1)
    assert _redetected(prob, right, np.arange(len(P)), 0.006) == []


def test_a_material_cylinder_s_pointless_cap_is_trimmed_to_its_side():
    """A cylinder candidate 0.1 too long at its top, where no cap point lies (hidden in
    another operand): :func:`trimmed` moves that cap in to where the side's points end
    and leaves the bottom cap, which holds points; a cylinder whose caps are right, or
    hold points, gets none. A cone's radii follow its trimmed height."""
    from csdf.infer.candidates import trimmed

    rng = np.random.default_rng(5)
    ang = rng.uniform(0.0, 2 * math.pi, 2000)
    z = rng.uniform(-0.5, 0.4, 2000)
    side = np.stack([0.3 * np.cos(ang), 0.3 * np.sin(ang), z], axis=1)
    rr = 0.28 * np.sqrt(rng.random(300))
    a2 = rng.uniform(0.0, 2 * math.pi, 300)
    base = np.stack([rr * np.cos(a2), rr * np.sin(a2), np.full(300, -0.5)], axis=1)
    Q = np.concatenate([side, base])
    long = Leaf("cylinder", np.eye(3), np.array([0.0, 0.0, 0.05]),
                {"radius": 0.3, "height": 1.1}, 1)
    cut = trimmed(long, Q, 0.005)
    assert cut is not None and cut.origin == "detected+trimmed"
    assert cut.vals["height"] == pytest.approx(0.9, abs=0.005)
    assert cut.t[2] == pytest.approx(-0.05, abs=0.003)
    right = Leaf("cylinder", np.eye(3), np.array([0.0, 0.0, -0.05]),
                 {"radius": 0.3, "height": 0.9}, 1)
    assert trimmed(right, Q, 0.005) is None
    top = Q[:, 2] >= 0.39
    capped = np.concatenate([Q, Q[top] * np.array([0.5, 0.5, 0.0]) + [0.0, 0.0, 0.6]])
    assert trimmed(long, capped, 0.005) is None
    # a cone (radius 0.4 at z = 0 to 0.1 at 0.6) whose points end at z = 0.4
    P, _ = _cone_band(3000, 2)
    cone = Leaf("cone", np.eye(3), np.zeros(3), {"r1": 0.4, "r2": 0.1, "height": 0.6}, 1)
    cc = trimmed(cone, P[P[:, 2] <= 0.4], 0.005)
    assert cc is not None and cc.vals["height"] == pytest.approx(0.4, abs=0.005)
    assert cc.vals["r2"] == pytest.approx(0.2, abs=0.003)
    assert cc.vals["r1"] == pytest.approx(0.4, abs=0.003)


def test_the_refinement_asks_for_spatial_gradients_once(monkeypatch):
    """The joint refinement needs the gradients only at the start (which points'
    normals agree with the tree): every later Jacobian is of the parameters alone (one
    forward pass fewer per spatial axis), and the values of an accepted step are
    reused. The result is the one every Jacobian with gradients gives, to the bit."""
    from csdf.expr import param
    from csdf.field import Field

    shape = csdf.box((1.2, 0.8, 0.6)) - csdf.cylinder(0.25, 1.0).translate((0.2, 0.0, 0.0))
    P, N = csdf.sample_surface(shape, 3000, seed=3)
    names = {"bx": 1.1, "by": 0.85, "bz": 0.55, "cr": 0.2, "ch": 1.0, "cx": 0.25}
    p = {k: param(k, v) for k, v in names.items()}
    model = csdf.box((p["bx"], p["by"], p["bz"])) - \
        csdf.cylinder(p["cr"], p["ch"]).translate((p["cx"], 0.0, 0.0))
    sizes = {"bx", "by", "bz", "cr", "ch"}
    calls = {"all": 0, "jac": 0}
    full, jac = Field.value_grad_param_jacobian, Field.param_jacobian

    def counted_full(self, pts):
        calls["all"] += 1
        return full(self, pts)

    def counted_jac(self, pts):
        calls["jac"] += 1
        return jac(self, pts)

    monkeypatch.setattr(Field, "value_grad_param_jacobian", counted_full)
    monkeypatch.setattr(Field, "param_jacobian", counted_jac)
    out = refine_params(model, dict(names), sizes, P, N, None, 0.01, "interp")
    assert calls["all"] == 1 and calls["jac"] >= 2
    # every Jacobian through the pass with gradients: the same parameters, bit for bit
    monkeypatch.setattr(Field, "param_jacobian", lambda self, pts: full(self, pts)[2])
    assert refine_params(model, dict(names), sizes, P, N, None, 0.01, "interp") == out


def test_a_cylinder_with_one_pointless_cap_is_offered_trimmed_in_its_place():
    """A material cylinder of the cloud's detection 0.2 too long at its top, where no
    point lies (the detection's height taken from another operand's points): with
    :data:`TRIM`, the candidates hold it with that cap moved in to its side's points
    *in place of* the detected one (its moved-out variant stays); residual detections'
    candidates (``trim`` off) keep it as detected; a cylinder too long at both caps is
    not trimmed (not one cap hidden in another operand)."""
    from types import SimpleNamespace

    from csdf.infer import api as A
    from csdf.infer.candidates import trimmed

    rng = np.random.default_rng(5)
    ang = rng.uniform(0.0, 2 * math.pi, 2000)
    z = rng.uniform(-0.5, 0.4, 2000)
    side = np.stack([0.3 * np.cos(ang), 0.3 * np.sin(ang), z], axis=1)
    nside = np.stack([np.cos(ang), np.sin(ang), np.zeros(2000)], axis=1)
    rr = 0.28 * np.sqrt(rng.random(300))
    a2 = rng.uniform(0.0, 2 * math.pi, 300)
    base = np.stack([rr * np.cos(a2), rr * np.sin(a2), np.full(300, -0.5)], axis=1)
    P = np.concatenate([side, base])
    N = np.concatenate([nside, np.tile([0.0, 0.0, -1.0], (300, 1))])
    prob = SimpleNamespace(P=P, N=N, ks=("cylinder",))
    det = SimpleNamespace(kind="cylinder", solid=("cylinder", np.eye(3), np.array([0.0, 0.0, 0.05]),
                                                  {"radius": 0.3, "height": 1.1}),
                          inliers=np.arange(len(P)), rmse=0.001, params={})
    sub = np.arange(len(P))
    got = A._candidates(prob, [det], sub, 0.005, corners=False, trim=A.TRIM)
    heights = {c.origin: c.vals["height"] for c in got}
    assert heights.get("detected+trimmed") == pytest.approx(0.9, abs=0.005)
    assert "detected" not in heights  # in its place, not beside it
    assert "detected+through" in heights
    kept = A._candidates(prob, [det], sub, 0.005, corners=False)  # as _residual calls it
    assert {c.origin: c.vals["height"] for c in kept}.get("detected") == pytest.approx(1.1)
    both = Leaf("cylinder", np.eye(3), np.zeros(3), {"radius": 0.3, "height": 1.3}, 1)
    assert trimmed(both, P, 0.005) is None


def _three_leaf_field():
    """A refinement's field: three posed, turnable leaves in a CSG tree (as
    ``api._shape`` builds them), on the interpreter."""
    from csdf.infer import api as A

    leaves = [Leaf("cylinder", np.eye(3), np.zeros(3), {"radius": 0.5, "height": 1.2}),
              Leaf("box", np.eye(3), np.array([0.3, 0.0, 0.2]),
                   {"size_x": 1.0, "size_y": 0.8, "size_z": 0.6}),
              Leaf("torus", np.eye(3), np.array([0.0, 0.1, -0.4]), {"major": 0.6,
                                                                     "minor": 0.15})]
    shape, _ = A._shape(("union", ("difference", 0, 1), 2), leaves, True)
    return csdf.as_field(shape, backend="interp", check_ranges=False)


@pytest.mark.parametrize("spatial", [False, True])
def test_interp_tangents_on_each_instructions_columns_are_the_dense_kernels(spatial):
    """The interpreter computes an instruction's parameter tangents on the columns of
    the parameters it depends on (:meth:`.lowering.Lowered.tangent_plan`): a
    refinement's Jacobian of a three-leaf tree is the kernel's over every column
    (the plan of one range for all), value for value (zeros of either sign), at a
    third of the tangent work or less."""
    from csdf.backends import interp, interp_kernels
    from csdf.backends.lowering import lowered

    fld = _three_leaf_field()
    X = np.random.default_rng(0).uniform(-1.2, 1.2, (3000, 3))
    prog = fld.program
    low = lowered(prog)
    pvals = np.array([p.default for p in prog.params], dtype=np.float64)
    P = len(pvals)
    off = 3 if spatial else 0
    T_ = off + P
    uvals, utans, zero_uniform = low.uniform(pvals, np.float64, spatial, True)
    code, cols = low.tangent_plan(utans, zero_uniform, off)
    dense = cols.copy()
    dense[:, 0], dense[:, 1], dense[:, 2], dense[:, 3] = off, T_, 0, 0
    width = (cols[:, 1] - cols[:, 0]).sum()
    assert width <= (T_ - off) * len(code) / 3
    B = interp._block_size(low.n_rows, T_, 8)
    outs = []
    for plan in (cols, dense):
        out, grad, jac = np.empty(len(X)), np.empty((len(X), 3)), np.empty((len(X), P))
        interp_kernels.tangent_kernel(code, plan, uvals, utans, X, out, grad, jac, 0,
                                      len(X), B, low.n_rows, low.out_row, spatial, P)
        outs.append((out, grad, jac))
    (f1, g1, j1), (f2, g2, j2) = outs
    assert np.array_equal(f1.view(np.int64), f2.view(np.int64))
    assert np.array_equal(j1, j2) and np.abs(j1).max() > 0
    if spatial:
        assert np.array_equal(g1.view(np.int64), g2.view(np.int64))
    # and through the public call
    J = fld.param_jacobian(X)
    assert np.array_equal(np.asarray(J), j1)


def test_the_pools_surface_table_filled_on_demand_scores_as_the_whole_table():
    """The pool evaluates a candidate at another's surface points only when a tree of
    both is scored (:meth:`Pool.surface_block`): the scores are those of a scorer
    over the whole table, every candidate evaluated at every surface point, bit for
    bit, and after a few trees most of the table was never evaluated."""
    shape = csdf.box((2.0, 2.0, 0.6)) - csdf.cylinder(0.3, 1.0) | \
        csdf.sphere(0.5).translate((0.9, 0.9, 0.3))
    P, N = csdf.sample_surface(shape, 8000, seed=3)
    leaves = [
        Leaf("box", np.eye(3), np.zeros(3), {"size_x": 2.0, "size_y": 2.0, "size_z": 0.6}, 1),
        Leaf("cylinder", np.eye(3), np.zeros(3), {"radius": 0.3, "height": 1.0}, -1),
        Leaf("sphere", np.eye(3), np.array([0.9, 0.9, 0.3]), {"radius": 0.5}, 1),
        Leaf("box", np.eye(3), np.array([0.1, 0.0, 0.0]),
             {"size_x": 1.6, "size_y": 2.2, "size_z": 0.5}, 1),
        Leaf("cylinder", np.eye(3), np.array([0.5, 0.0, 0.0]), {"radius": 0.2, "height": 2.0},
             -1),
        Leaf("sphere", np.eye(3), np.array([-0.9, 0.9, 0.3]), {"radius": 0.4}, 1)]
    pool = _pool(P, N, leaves[:4])
    pool.add(leaves[4:])  # a second batch of surface points
    trees = [0, ("difference", 0, 1), ("union", ("difference", 0, 1), 2),
             ("union", 2, ("difference", 0, 1)), ("difference", 3, 4),
             ("intersection", ("difference", 0, 1), 3)]
    lazy = [pool.scorer().score(t) for t in trees]
    assert pool.filled() < 0.6
    whole = np.array([lf.values(pool.surf)[0] for lf in pool.leaves])
    assert np.array_equal(pool.at_surface.view(np.int64), whole.view(np.int64))
    assert pool.filled() == 1.0
    signs = np.array([lf.sign for lf in pool.leaves])
    eager = Scorer(pool.at_points, pool.dots, pool.at_free, pool.tau, pool.penalty, whole,
                   pool.owner, pool.weight / pool.area, pool.unsupported, signs)
    for t, got in zip(trees, lazy):
        want = eager.score(t)
        assert (got.data, got.free, got.total) == (want.data, want.free, want.total)
    assert max(s.free for s in lazy) > 0  # the made-up surface counted


def test_data_costs_from_each_leafs_parity_rows_are_the_oriented_fields():
    """The scorer's data costs from each leaf's cost rows at even and odd parity
    (:meth:`Scorer._field_cost`) are those of the tree's oriented field
    (:func:`.search.evaluate_oriented`), bit for bit, with kept subtrees too."""
    from csdf.infer.search import evaluate_oriented

    rng = np.random.default_rng(7)
    n, m = 7, 2500
    at_points = rng.normal(size=(n, m)) * rng.uniform(0.05, 1.0, (n, 1))
    at_points[:, :50] = 0.0  # ties, and zeros of both signs below
    at_points[:3, 50:100] = -0.0
    dots = rng.uniform(-1.0, 1.0, (n, m))
    dots[:, 100:150] = 0.0
    sc = Scorer(at_points, dots, None, 0.1, 0.004)
    trees = [random_csg_tree(rng, list(rng.permutation(n)[: int(rng.integers(1, 7))]))
             for _ in range(300)]

    def oriented(t):
        f, d = evaluate_oriented(t, at_points, dots)
        return np.where(d > 0.0, np.minimum((f / 0.1) ** 2, 1.0), 1.0)

    for t in trees:
        assert np.array_equal(sc._costs(t).view(np.int64), oriented(t).view(np.int64))
    sc.keep(trees[:20])
    for t in trees:
        assert np.array_equal(sc._costs(t).view(np.int64), oriented(t).view(np.int64))


def test_a_plane_whose_outline_is_in_part_an_arc_is_offered_as_a_cylinders_cap():
    """A cylinder cut by a box and seen end-on shows its cap, a disk clipped by two
    straight edges, and almost none of its side: :func:`cap_cylinder` offers the
    cylinder of the disk's circle (axis the plane's normal, reaching to the cloud
    behind it). A square plane's outline holds no arc, and a whole disk's is an arc
    of more than half a turn (an end whose side the sensor sees too): neither is
    offered."""
    from csdf.infer.candidates import cap_cylinder

    rng = np.random.default_rng(0)
    spacing = 0.01
    g = np.arange(-0.6, 0.6, spacing)
    X, Y = np.meshgrid(g, g)
    xy = np.stack([X.ravel(), Y.ravel()], axis=1) + rng.normal(0, 0.001, (X.size, 2))
    disk = xy[(np.hypot(xy[:, 0], xy[:, 1]) <= 0.5) & (np.abs(xy[:, 0]) <= 0.25)]
    Q = np.column_stack([disk, np.full(len(disk), 0.8)])
    behind = np.column_stack([rng.uniform(-0.3, 0.3, (500, 2)), rng.uniform(-0.4, 0.8, 500)])
    P = np.concatenate([Q, behind])
    c = cap_cylinder(np.array([0.0, 0.0, 1.0]), Q, P, spacing)
    assert c is not None and c.kind == "cylinder" and c.sign == 1
    assert abs(c.vals["radius"] - 0.5) < 0.01 and abs(abs(c.R[2, 2]) - 1.0) < 1e-9
    assert abs(c.t[2] + c.vals["height"] / 2 - 0.8) < 1e-9  # the cap on the plane
    assert c.t[2] - c.vals["height"] / 2 <= -0.4  # down to the cloud behind it
    assert np.hypot(c.t[0], c.t[1]) < 0.01
    square = xy[(np.abs(xy[:, 0]) <= 0.35) & (np.abs(xy[:, 1]) <= 0.45)]
    Qs = np.column_stack([square, np.full(len(square), 0.8)])
    assert cap_cylinder(np.array([0.0, 0.0, 1.0]), Qs, np.concatenate([Qs, behind]),
                        spacing) is None
    whole = xy[np.hypot(xy[:, 0], xy[:, 1]) <= 0.5]
    Qw = np.column_stack([whole, np.full(len(whole), 0.8)])
    assert cap_cylinder(np.array([0.0, 0.0, 1.0]), Qw, np.concatenate([Qw, behind]),
                        spacing) is None


def _groove_arc(theta: tuple[float, float], phi: tuple[float, float], n: int, seed: int
                ) -> tuple[np.ndarray, np.ndarray]:
    """``n`` noisy points ``(n, 3)`` of a torus groove (major 0.24, minor 0.077, axis
    tilted 30 degrees from z about x, centre (0.1, -0.2, 0.3)) over ring angles
    ``theta`` and tube angles ``phi`` (degrees; 180 is the tube's inner side), with
    the object's outward normals ``(n, 3)``: into the tube, a cut, 3 degrees of noise."""
    rng = np.random.default_rng(seed)
    th = np.radians(rng.uniform(*theta, n))
    ph = np.radians(rng.uniform(*phi, n))
    radial = np.stack([np.cos(th), np.sin(th), np.zeros(n)], axis=1)
    out = np.cos(ph)[:, None] * radial + np.sin(ph)[:, None] * np.array([0.0, 0.0, 1.0])
    q = 0.24 * radial + 0.077 * out
    a = math.radians(30.0)
    R = np.array([[1.0, 0.0, 0.0], [0.0, math.cos(a), -math.sin(a)],
                  [0.0, math.sin(a), math.cos(a)]])
    P = q @ R.T + np.array([0.1, -0.2, 0.3]) + rng.normal(0.0, 0.002, (n, 3))
    N = -out @ R.T + rng.normal(0.0, 0.05, (n, 3))
    return P, N / np.linalg.norm(N, axis=1, keepdims=True)


def test_two_arcs_of_a_torus_groove_are_joined_into_its_torus():
    """A torus groove seen as two short arcs on opposite sides of its ring (as across a
    ball): the first arc alone fits tori of other axes as well (detection on it alone
    finds tori 73-89 degrees off, within the noise), the tube centres of both lie on
    the ring, and :func:`joined_torus` gives that torus (a cut); an arc with a
    patch of a plane, or of a sphere, gives none. :func:`api._joined` offers one torus
    for the two places, across rounds, and none for one place detected twice."""
    from types import SimpleNamespace

    from csdf.infer.api import _joined
    from csdf.infer.candidates import joined_torus

    Pa, Na = _groove_arc((160.0, 200.0), (135.0, 225.0), 120, 1)
    Pb, Nb = _groove_arc((-20.0, 20.0), (-90.0, 0.0), 50, 2)
    axis = np.array([0.0, -math.sin(math.radians(30.0)), math.cos(math.radians(30.0))])
    lf = joined_torus(Pa, Pb, Na, Nb, 0.003, 0.01)
    assert lf is not None and lf.kind == "torus" and lf.origin == "joined"
    assert lf.sign == -1
    assert abs(float(lf.R[:, 2] @ axis)) > math.cos(math.radians(3.0))
    assert lf.vals["major"] == pytest.approx(0.24, abs=0.01)
    assert lf.vals["minor"] == pytest.approx(0.077, abs=0.01)
    assert np.linalg.norm(lf.t - np.array([0.1, -0.2, 0.3])) < 0.02
    # an arc and a plane's patch; an arc and a sphere's patch
    rng = np.random.default_rng(3)
    flat = np.column_stack([rng.uniform(0.5, 0.6, 60), rng.uniform(0.0, 0.1, 60),
                            np.full(60, 0.2)]) + rng.normal(0.0, 0.002, (60, 3))
    up = np.tile([0.0, 0.0, 1.0], (60, 1))
    assert joined_torus(Pa, flat, Na, up, 0.003, 0.01) is None
    d = rng.normal(size=(60, 3)) * np.array([0.3, 0.3, 1.0]) + np.array([0.0, 0.0, 3.0])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    ball = np.array([0.6, 0.3, 0.0]) + 0.2 * d + rng.normal(0.0, 0.002, (60, 3))
    assert joined_torus(Pa, ball, Na, d, 0.003, 0.01) is None
    # two patches of one straight cylinder (radius 0.08 along x): a torus of a huge
    # ring fits them, but it is the cylinder's straight stretch
    x = np.concatenate([rng.uniform(0.0, 0.1, 60), rng.uniform(0.4, 0.5, 60)])
    u = rng.uniform(-0.8, 0.8, 120)
    out = np.column_stack([np.zeros(120), np.sin(u), np.cos(u)])
    tube = np.column_stack([x, np.zeros(120), np.zeros(120)]) + 0.08 * out
    tube += rng.normal(0.0, 0.002, tube.shape)
    assert joined_torus(tube[:60], tube[60:], out[:60], out[60:], 0.002, 0.01) is None
    # the residual rounds' pieces: one arc in each round, the first detected twice
    P = np.concatenate([Pa, Pb])
    prob = SimpleNamespace(P=P, N=np.concatenate([Na, Nb]), ks=("torus", "cylinder"),
                           tau=0.01, pieces=[], pool=SimpleNamespace(leaves=[]))
    a, b = np.arange(120), np.arange(120, 170)
    assert _joined(prob, [(a, 0.003), (a[5:], 0.003)], []) == []  # one place
    out = _joined(prob, [(b, 0.003)], [])
    assert len(out) == 1 and out[0].kind == "torus" and out[0].sign == -1
    assert len(prob.pieces) == 3
    # not when a candidate of that ring exists
    prob.pieces = prob.pieces[:2]
    assert _joined(prob, [(b, 0.003)], [lf.moved(sign=0)]) == []
