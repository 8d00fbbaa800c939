"""The exact signed distance to a closed triangle mesh (issue 20's ``from_mesh`` core):
distances against brute force over every triangle (an independent formula), signs
inside thin and non-convex meshes, gradients, and the mesh checks."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

import csdf
from csdf.backends.meshdist import MeshDistance

RNG = np.random.default_rng(3)


def _seg_d2(P, a, b):
    """``(N, K)`` squared distances of points ``(N, 3)`` to segments ``a, b`` ``(K, 3)``."""
    ab = b - a
    t = np.einsum("nkj,kj->nk", P[:, None] - a[None], ab) / np.maximum(
        np.einsum("kj,kj->k", ab, ab), 1e-300)
    t = np.clip(t, 0, 1)
    q = a[None] + t[..., None] * ab[None]
    return ((P[:, None] - q) ** 2).sum(-1)


def brute_unsigned(P, V, F):
    """Distance to the nearest triangle by another route than the kernel's: the plane
    projection when it falls inside the triangle (barycentric coordinates), else the
    nearest of the three edges."""
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    h = np.einsum("nkj,kj->nk", P[:, None] - a[None], n)  # (N, K) heights
    proj = P[:, None] - h[..., None] * n[None]
    inside = np.ones(h.shape, bool)
    for p, q in ((a, b), (b, c), (c, a)):
        inside &= np.einsum("nkj,kj->nk", np.cross(q[None] - p[None], proj - p[None]), n) \
            >= 0
    edge = np.minimum(np.minimum(_seg_d2(P, a, b), _seg_d2(P, b, c)), _seg_d2(P, c, a))
    d2 = np.where(inside, h * h, edge)
    return np.sqrt(d2.min(axis=1))


@pytest.fixture(scope="module")
def torus():
    m = trimesh.creation.torus(1.0, 0.25, major_sections=48, minor_sections=24)
    return m, MeshDistance(m)


def test_distances_equal_brute_force_also_near_edges_and_vertices(torus):
    m, md = torus
    V, F = np.asarray(m.vertices), np.asarray(m.faces)
    far = RNG.uniform(-1.6, 1.6, (300, 3))
    # points just off vertices and edge midpoints, where the nearest feature switches
    vs = V[RNG.integers(0, len(V), 100)] + RNG.normal(0, 1e-3, (100, 3))
    e = F[RNG.integers(0, len(F), 100)]
    mid = 0.5 * (V[e[:, 0]] + V[e[:, 1]]) + RNG.normal(0, 1e-3, (100, 3))
    P = np.concatenate([far, vs, mid])
    d = md.value(P)
    assert np.allclose(np.abs(d), brute_unsigned(P, V, F), rtol=0, atol=1e-9)
    # the sign: trimesh's ray-based containment away from the surface
    ok = np.abs(d) > 1e-3
    assert np.array_equal(d[ok] < 0, m.contains(P[ok]))


def test_gradients_and_nearest_points(torus):
    _, md = torus
    P = RNG.uniform(-1.5, 1.5, (200, 3))
    d, g = md.value_and_grad(P)
    assert np.allclose(np.linalg.norm(g, axis=1), 1.0)
    h = 1e-6
    for ax in range(3):
        e = np.zeros(3)
        e[ax] = h
        fd = (md.value(P + e) - md.value(P - e)) / (2 * h)
        assert np.allclose(fd, g[:, ax], atol=1e-5)
    d2, c = md.closest(P)
    assert np.allclose(d2, d)
    assert np.allclose(np.abs(md.value(c)), 0.0, atol=1e-12)
    assert np.allclose(np.linalg.norm(P - c, axis=1), np.abs(d))
    lo, hi = md.interval([0.9, -0.1, -0.1], [1.1, 0.1, 0.1])
    assert lo <= md.value([[1.0, 0, 0]])[0] <= hi and hi - lo == pytest.approx(
        2 * np.sqrt(0.03))


def test_signs_inside_a_thin_non_convex_part():
    # a box with a hole through it, meshed by csdf: thin walls and a concave hole
    part = csdf.box((2.0, 2.0, 0.3)) - csdf.cylinder(0.7, 1.0)
    m = csdf.mesh(part, resolution=96, progress=False)
    md = MeshDistance(m.vertices, m.faces)
    P = np.array([[0, 0, 0], [0.85, 0, 0], [0.85, 0, 0.12], [0.85, 0, 0.18],
                  [0.95, 0.95, 0.0], [0.6, 0, 0], [0, 0, 0.5]])
    d = md.value(P)
    assert np.array_equal(d < 0, [False, True, True, False, True, False, False])
    # the exact distances (the field of the difference is only a bound: 0.5 at the
    # centre, where the nearest surface is the hole's wall 0.7 away)
    exact = [0.7, -0.15, -0.03, 0.03, -0.05, 0.1, np.hypot(0.7, 0.35)]
    assert np.allclose(d, exact, atol=0.01)  # to the mesh's faceting


def test_orientation_and_checks():
    box = trimesh.creation.box((1, 2, 3))
    V, F = np.asarray(box.vertices), np.asarray(box.faces)
    flipped = MeshDistance(V, F[:, ::-1])  # inwards: turned outwards
    assert flipped.value([[0, 0, 0]])[0] == pytest.approx(-0.5)
    assert flipped.volume == pytest.approx(6.0)
    with pytest.raises(csdf.CsdfError, match="not closed"):
        MeshDistance(V, F[:-1])
    bad = F.copy()
    bad[0] = bad[0, ::-1]
    with pytest.raises(csdf.CsdfError, match="consistently oriented"):
        MeshDistance(V, bad)
    with pytest.raises(csdf.CsdfError, match="outside"):
        MeshDistance(V, F + 100)
    with pytest.raises(csdf.CsdfError, match=r"\(N, 3\)"):
        MeshDistance(V[:, :2], F)
    with pytest.raises(csdf.CsdfError, match="finite"):
        MeshDistance(V, F).value([[np.nan, 0, 0]])
