"""The compiled dual contouring (``csdf.mesh.dc_kernels``): the same mesh as the NumPy
dual contouring, and watertight 2-manifold meshes on random CSG shapes."""

from __future__ import annotations

import numpy as np
import pytest

import csdf
from csdf.mesh.reference import extract

pytest.importorskip("numba")

from scipy.spatial import cKDTree  # noqa: E402

from csdf.mesh import dc_kernels as D  # noqa: E402
from csdf.mesh.stream import extract_dc  # noqa: E402
from test_mesh_stream import _csg, _random_shape, _setup, _triangles  # noqa: E402

CASES = {
    "sphere": (lambda: csdf.sphere(1.0), None),
    "box": (lambda: csdf.box((1.0, 0.8, 0.6)).rotate(0.3, (1, 2, 3)), None),
    "csg": (_csg, None),
    "twisted box": (lambda: csdf.box((1.0, 0.4, 2.0)).twist(1.2), None),
    "cut by bounds": (lambda: csdf.sphere(1.0), ((-1, -1, 0), (1, 1, 1))),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_compiled_dc_equals_numpy_dc(name):
    make, bounds = CASES[name]
    grid, values, gradients, intervals = _setup(make(), 28, bounds)
    rv, rf = extract(grid, values, gradients, intervals, "dc")
    cv, cf = extract(grid, values, gradients, intervals, "dc", compiled=True)
    assert cv.dtype == np.float64 and cf.dtype == np.int64
    assert len(cv) == len(rv) and len(cf) == len(rf)
    # the same vertices in the same (voxel, component) order ...
    np.testing.assert_allclose(cv, rv, rtol=0, atol=1e-9 * grid.h)
    # ... joined into the same oriented triangles
    assert _triangles(cv, cf, grid.h) == _triangles(rv, rf, grid.h)


@pytest.mark.parametrize("name", sorted(CASES))
@pytest.mark.parametrize("chunk_samples", [1, 1 << 18])
def test_streamed_dc_equals_numpy_dc(name, chunk_samples):
    # streamed (one brick per chunk, or whole): vertices numbered in stream order, so
    # compare the vertex sets and the triangles by coordinates
    make, bounds = CASES[name]
    grid, values, gradients, intervals = _setup(make(), 30, bounds)
    rv, rf = extract(grid, values, gradients, intervals, "dc")
    sv, sf = extract_dc(grid, values, gradients, intervals, chunk_samples=chunk_samples)
    assert sv.dtype == np.float64 and sf.dtype == np.int64
    assert len(sv) == len(rv) and len(sf) == len(rf)
    dist, idx = cKDTree(rv).query(sv)
    assert dist.max() <= 1e-9 * grid.h
    assert len(np.unique(idx)) == len(rv)
    assert _triangles(sv, sf, grid.h) == _triangles(rv, rf, grid.h)


def test_symmetric_eigensolver_matches_numpy():
    rng = np.random.default_rng(1)
    vec = np.empty((3, 3))
    for rank in (0, 1, 2, 3, 3, 3):
        n = rng.normal(size=(5, 3))[:rank]
        a = n.T @ n
        m = a.copy()
        D.sym_eig3(m, vec)
        np.testing.assert_allclose(vec @ np.diag(np.diag(m)) @ vec.T, a, atol=1e-12)
        np.testing.assert_allclose(vec.T @ vec, np.eye(3), atol=1e-12)
        np.testing.assert_allclose(np.sort(np.diag(m)), np.linalg.eigvalsh(a), atol=1e-12)


@pytest.mark.parametrize("seed", range(4))
def test_random_shapes_dc_are_watertight_and_manifold(seed):
    rng = np.random.default_rng(seed + 100)
    shape = _random_shape(rng)
    m = csdf.mesh(shape, resolution=int(rng.integers(20, 40)), method="dc", progress=False)
    if len(m.faces) == 0:
        pytest.skip("empty shape")
    assert m.is_watertight and m.is_winding_consistent
    edges = np.sort(m.edges, axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert np.all(counts == 2)
    assert m.volume > 0


def test_qef_solve_in_ranges_equals_one_pass(monkeypatch):
    """The voxels split into ranges solved side by side give the one-pass result."""
    from csdf.mesh import dual as X

    grid, values, gradients, intervals = _setup(_csg(), 40)
    monkeypatch.setattr(X, "SPLIT_MIN", 1000)
    seen = {}
    solve = X.dc_solve

    def spy(*a, **k):
        seen["args"] = a
        return solve(*a, **k)

    monkeypatch.setattr(X, "dc_solve", spy)
    extract_dc(grid, values, gradients, intervals)
    args = seen["args"]
    assert len(args[1]) >= 1000  # big enough for the split path
    one = solve(*args, threads=1)
    for threads in (2, 3):
        many = solve(*args, threads=threads)
        for a, b in zip(one, many):
            np.testing.assert_array_equal(a, b)


def test_compiled_newton_step_matches_numpy_projection():
    from csdf.mesh.reference import _project

    rng = np.random.default_rng(5)
    verts = rng.normal(size=(500, 3))
    f = rng.normal(size=500)
    g = rng.normal(size=(500, 3))
    g[:10] = 0.0  # no gradient: no step
    f[10:20] = np.nan  # NaN field: no step
    f[20:25] = np.inf  # infinite field: no step
    g[25:30, 0] = np.inf
    f[30:40] *= 100.0  # long steps: limited to half a voxel
    h = 0.3
    expect = _project(verts.copy(), lambda v: (f, g), h, steps=1)
    got = verts.copy()
    D.newton_step(got, f, g, h)
    np.testing.assert_array_equal(got, expect)
    assert np.all(np.linalg.norm(got - verts, axis=1) <= 0.5 * h * (1 + 1e-12))
