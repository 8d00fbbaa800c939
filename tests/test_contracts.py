"""Exactness labels, Lipschitz bounds, bounding boxes and operand-order independence."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy.spatial import cKDTree

import csdf
from catalogue import catalogue, sample_box

CAT = catalogue()


@pytest.mark.parametrize("name", sorted(CAT))
def test_gradient_norm_within_lipschitz_bound(name):
    shape = CAT[name]()
    rng = np.random.default_rng(5)
    if shape.bounds is not None:
        lo, hi = sample_box(shape, pad=0.1)
    else:
        lo, hi = np.full(3, -2.0), np.full(3, 2.0)
    pts = rng.uniform(lo, hi, (4000, 3))
    g = shape.gradient(pts)
    norm = np.linalg.norm(g, axis=1)
    assert np.nanmax(norm) <= shape.lipschitz + 1e-9, (
        f"{name}: |grad| reaches {np.nanmax(norm):.4f} > declared {shape.lipschitz:.4f}"
    )
    if shape.exactness == "exact":
        assert np.mean(np.abs(norm - 1) < 1e-9) > 0.95


@pytest.mark.parametrize("name", sorted(n for n in CAT if CAT[n]().bounds is not None))
def test_zero_set_lies_inside_bounds(name):
    shape = CAT[name]()
    b = shape.bounds
    lo, hi = sample_box(shape, pad=1.0)
    rng = np.random.default_rng(6)
    pts = rng.uniform(lo, hi, (20000, 3))
    inside_box = np.all((pts[:, : shape.dim] >= b[0]) & (pts[:, : shape.dim] <= b[1]), axis=1)
    v = shape(pts)
    assert np.all(v[~inside_box] > 0), f"{name}: part of the shape lies outside its bounds"


def _surface_points(shape, n=60000, seed=7):
    """Points on the zero set by Newton projection along the gradient."""
    lo, hi = sample_box(shape, pad=0.2)
    rng = np.random.default_rng(seed)
    p = rng.uniform(lo, hi, (n, 3))
    prog = shape.compile()
    for _ in range(30):
        v, g = prog.value_and_grad(p)
        gg = np.maximum((g * g).sum(1), 1e-12)
        p = p - (v / gg)[:, None] * g
    v = prog(p)
    return p[np.abs(v) < 1e-10]


BOUND_CASES = {
    "union": lambda: csdf.sphere(0.5) | csdf.box(0.6).translate((0.5, 0.1, 0)),
    "smooth3": lambda: csdf.union(csdf.sphere(0.4), csdf.sphere(0.4).translate((0.5, 0, 0)),
                                  csdf.sphere(0.4).translate((0.2, 0.5, 0)), k=0.3),
    "exponential": lambda: csdf.union(csdf.sphere(0.4), csdf.box(0.5).translate((0.5, 0, 0)),
                                      k=0.1, blend="exponential"),
    "stairs": lambda: csdf.union(csdf.box(0.6), csdf.sphere(0.4).translate((0.4, 0.3, 0)),
                                 k=0.2, blend="stairs", n=3),
    "difference": lambda: csdf.box(1.0) - csdf.box(0.5).translate((0.4, 0.4, 0.4)),
    "ellipsoid": lambda: csdf.ellipsoid((0.6, 0.3, 0.2)),
    "octahedron": lambda: csdf.octahedron(0.6),
    "scale_vector": lambda: csdf.box(0.5).scale((1.0, 2.0, 0.5)),
    "mirror": lambda: csdf.sphere(0.3).translate((0.2, 0.1, 0)).mirror("x"),
    "repeat_mirrored": lambda: csdf.box(0.3).translate((0.1, 0, 0)).repeat_mirrored(
        (0.7, 0, 0), count=(3, 1, 1)),
    "elongate": lambda: csdf.sphere(0.3).elongate((0.3, 0, 0.1)),
    "shell": lambda: csdf.box(0.8).shell(0.1),
}


@pytest.mark.parametrize("name", sorted(BOUND_CASES))
def test_bounds_never_overestimate(name):
    shape = BOUND_CASES[name]()
    assert shape.exactness in ("bound", "exact")
    surf = _surface_points(shape)
    assert len(surf) > 5000
    tree = cKDTree(surf)
    lo, hi = sample_box(shape, pad=0.5)
    q = np.random.default_rng(8).uniform(lo, hi, (3000, 3))
    dist, _ = tree.query(q)
    # sampling leaves gaps: the true distance is at most ``dist``; |f| must not exceed it
    v = np.abs(shape(q))
    assert np.all(v <= dist + 2e-3), f"{name}: |f| exceeds the distance by {np.max(v - dist)}"


def test_exactness_labels_of_operators():
    s, b = csdf.sphere(1), csdf.box(1)
    assert (s | b).exactness == "bound"
    assert (s & b).exactness == "bound"
    assert (s - b).exactness == "bound"
    assert (~s).exactness == "exact"
    assert s.translate((1, 0, 0)).rotate(0.3).scale(2).exactness == "exact"
    assert s.scale((1, 2, 3)).exactness == "bound"
    assert s.repeat(3).exactness == "neither"
    assert s.repeat_mirrored(3).exactness == "bound"
    assert s.repeat_polar(4).exactness == "neither"
    assert b.twist(1).exactness == "neither" and b.twist(1).lipschitz > 1
    assert csdf.union(s, b, k=0.1, blend="chamfer").exactness == "neither"
    assert csdf.union(s, b, k=0.1).exactness == "bound"
    assert csdf.extrude(csdf.circle(1), 1).exactness == "exact"
    assert csdf.extrude(csdf.ellipse((1, 2)), 1).exactness == "bound"
    assert s.twist(0.5).lipschitz == pytest.approx(1.5 * 1.0, rel=0.5)
    assert csdf.plane().twist(1).lipschitz == float("inf")


def test_smooth_union_of_two_matches_polynomial_smooth_min():
    a, b = csdf.sphere(0.5), csdf.sphere(0.5).translate((0.8, 0, 0))
    k = 0.3
    u = csdf.union(a, b, k=k)
    pts = np.random.default_rng(9).uniform(-1, 2, (2000, 3))
    da, db = a(pts), b(pts)
    h = np.maximum(k - np.abs(da - db), 0) / k
    np.testing.assert_allclose(u(pts), np.minimum(da, db) - h * h * k / 4, atol=1e-14)


@pytest.mark.parametrize("blend", [None, *csdf.BLENDS])
def test_nary_union_does_not_depend_on_operand_order(blend):
    parts = [
        csdf.sphere(0.4),
        csdf.box(0.5).translate((0.5, 0, 0)),
        csdf.cylinder(0.2, 1.0).translate((0.2, 0.4, 0)),
        csdf.torus(0.3, 0.08).translate((0.0, -0.3, 0.2)),
    ]
    kw = {} if blend is None else {"k": 0.25, "blend": blend}
    ref = csdf.union(*parts, **kw).compile().to_bytes()
    pts = np.random.default_rng(10).uniform(-1, 1, (500, 3))
    ref_v = csdf.union(*parts, **kw)(pts)
    for perm in itertools.permutations(range(4)):
        shape = csdf.union(*[parts[i] for i in perm], **kw)
        assert shape.compile().to_bytes() == ref
        np.testing.assert_array_equal(shape(pts), ref_v)


def test_smooth_union_is_smooth_and_below_min():
    a = csdf.sphere(0.5)
    b = csdf.box(0.6).translate((0.6, 0, 0))
    c = csdf.sphere(0.3).translate((0.3, 0.5, 0))
    u = csdf.union(a, b, c, k=0.2)
    pts = np.random.default_rng(11).uniform(-1, 1.5, (5000, 3))
    hard = np.minimum(np.minimum(a(pts), b(pts)), c(pts))
    v = u(pts)
    assert np.all(v <= hard + 1e-15)
    assert np.all(v >= hard - 0.2 * 0.25 * 2 - 1e-12)
