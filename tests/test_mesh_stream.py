"""The compiled, streamed marching cubes (``csdf.mesh.stream``): the same mesh as the
NumPy reference extraction, independent of the chunking, and watertight 2-manifold
meshes on random CSG shapes."""

from __future__ import annotations

import math

import numpy as np
import pytest

import csdf
from csdf.backends.interval_eval import evaluate_intervals
from csdf.mesh import kernels as K
from csdf.mesh.api import _JITTER
from csdf.mesh.grid import Grid
from csdf.mesh.reference import extract
from csdf.mesh.stream import extract_mc

pytest.importorskip("numba")


def _setup(shape, resolution, bounds=None):
    """The grid and field callables csdf.mesh would use (fast backend)."""
    prog = shape.compile()
    b = np.asarray(shape.bounds if bounds is None else bounds, dtype=np.float64)
    h = float((b[1] - b[0]).max()) / resolution
    dims = tuple(int(math.ceil(e / h)) + 5 for e in b[1] - b[0])
    grid = Grid(origin=b[0] - h * (2.0 + _JITTER), h=h, dims=dims)

    def values(p):
        return prog(p, backend="fast")

    def gradients(p):
        return prog.gradient(p, backend="fast")

    def intervals(lo, hi):
        return evaluate_intervals(prog, lo, hi)

    return grid, values, gradients, intervals


def _triangles(verts, faces, h):
    """The faces as a set of vertex-coordinate triples (in voxels, rounded), each
    rotated to start at its smallest vertex (orientation kept)."""
    q = np.round(verts / h, 7)
    out = set()
    for f in faces:
        tri = [tuple(q[i]) for i in f]
        k = min(range(3), key=lambda i: tri[i])
        out.add(tuple(tri[k:] + tri[:k]))
    return out


def _csg():
    c = csdf.cylinder(0.5, 3.0)
    return (csdf.sphere(1.0) & csdf.box(1.5)) - c - c.orient("x") - c.orient("y")


CASES = {
    "sphere": (lambda: csdf.sphere(1.0), None),
    "csg": (_csg, None),
    "twisted box": (lambda: csdf.box((1.0, 0.4, 2.0)).twist(1.2), None),
    "cut by bounds": (lambda: csdf.sphere(1.0), ((-1, -1, 0), (1, 1, 1))),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_compiled_path_equals_reference(name):
    make, bounds = CASES[name]
    grid, values, gradients, intervals = _setup(make(), 28, bounds)
    rv, rf = extract(grid, values, gradients, intervals, "mc")
    cv, cf = extract_mc(grid, values, intervals)
    assert cv.dtype == np.float64 and cf.dtype == np.int64
    assert len(cv) == len(rv) and len(cf) == len(rf)
    # the same roots (same search on the same edges) ...
    order_r = np.lexsort(rv.T[::-1])
    order_c = np.lexsort(cv.T[::-1])
    np.testing.assert_allclose(cv[order_c], rv[order_r], rtol=0, atol=1e-9 * grid.h)
    # ... joined into the same oriented triangles
    assert _triangles(cv, cf, grid.h) == _triangles(rv, rf, grid.h)


def test_chunking_does_not_change_the_mesh():
    grid, values, _, intervals = _setup(_csg(), 40)
    v1, f1 = extract_mc(grid, values, intervals)
    # one brick per chunk: every shared edge crosses chunks through the hash map
    v2, f2 = extract_mc(grid, values, intervals, chunk_samples=1)
    assert len(v1) == len(v2) and len(f1) == len(f2)
    assert _triangles(v1, f1, grid.h) == _triangles(v2, f2, grid.h)


def test_hash_map_keeps_entries_when_it_grows():
    table = K.new_hash(16)
    keys = np.random.default_rng(0).choice(10**11, size=3000, replace=False)
    for i, key in enumerate(keys.tolist()):
        if 2 * (i + 1) > len(table):
            table = K._rehash(table)
        s = K._slot(table, key)
        assert table[s, 0] == -1
        table[s] = (key, i)
    assert len(table) >= 6000
    for i, key in enumerate(keys.tolist()):
        s = K._slot(table, key)
        assert table[s, 0] == key and table[s, 1] == i
    assert table[K._slot(table, 10**11 + 1), 0] == -1


def _random_shape(rng):
    shape = None
    for _ in range(rng.integers(2, 5)):
        if rng.random() < 0.5:
            part = csdf.sphere(float(rng.uniform(0.3, 0.7)))
        else:
            part = csdf.box(tuple(float(x) for x in rng.uniform(0.3, 1.0, 3)))
        part = part.rotate(float(rng.uniform(0, np.pi)), tuple(rng.normal(size=3).tolist()))
        part = part.translate(tuple(float(x) for x in rng.uniform(-0.4, 0.4, 3)))
        if shape is None:
            shape = part
        else:
            shape = shape | part if rng.random() < 0.6 else shape - part
    if rng.random() < 0.5:  # not a distance: intervals, not distances, prune the octree
        shape = shape.twist(float(rng.uniform(-1.5, 1.5)))
    return shape


@pytest.mark.parametrize("seed", range(6))
def test_random_shapes_are_watertight_and_manifold(seed):
    rng = np.random.default_rng(seed)
    shape = _random_shape(rng)
    m = csdf.mesh(shape, resolution=int(rng.integers(20, 48)), progress=False)
    if len(m.faces) == 0:
        pytest.skip("empty shape")  # (a part cut away all)
    assert m.is_watertight and m.is_winding_consistent
    edges = np.sort(m.edges, axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert np.all(counts == 2)
    assert m.volume > 0
    h = m.metadata["csdf"]["voxel_size"]
    lip = max(shape.lipschitz, 1.0)
    assert np.max(np.abs(shape(np.asarray(m.vertices)))) <= 1e-3 * h * lip


def test_fresh_arrays_are_ordinary_writable_arrays():
    small = K.fresh_array((10, 3), np.int64)
    big = K.fresh_array((1 << 19, 3), np.int64)  # 12 MB: its own memory map
    for a in (small, big):
        assert a.dtype == np.int64 and a.flags.writeable and a.flags.c_contiguous
    assert big.shape == (1 << 19, 3) and not big.any()  # fresh anonymous memory is zero
    big[-1] = (1, 2, 3)
    assert big[-1].tolist() == [1, 2, 3]


def test_large_mesh_on_mapped_memory_is_watertight():
    # big enough that the output arrays come from fresh_array's memory maps
    m = csdf.mesh(csdf.torus(0.6, 0.2), resolution=160, progress=False)
    root = m.faces
    while isinstance(root, np.ndarray) and root.base is not None:
        root = root.base
    assert isinstance(root, memoryview)  # np.frombuffer over an mmap, not a copy
    assert m.is_watertight and m.euler_number == 0


@pytest.mark.parametrize("method", ["mc", "dc"])
def test_pipelined_stream_gives_the_sequential_mesh(method):
    """With a single-threaded evaluator the stages overlap on worker threads (value and
    edge buffers recycled between chunks); the mesh must be the same, bit for bit."""
    from csdf.backends import fast
    from csdf.mesh.stream import extract_dc

    shape = _csg()
    grid, values, gradients, intervals = _setup(shape, 36)
    prog = shape.compile()
    serial = fast.serial_values(prog, prog.param_values({}))
    for chunk in (1, 3000, 1 << 18):  # one brick per chunk, a few, one chunk
        if method == "mc":
            a = extract_mc(grid, values, intervals, chunk_samples=chunk)
            b = extract_mc(grid, values, intervals, chunk_samples=chunk, serial=serial)
        else:
            a = extract_dc(grid, values, gradients, intervals, chunk_samples=chunk)
            b = extract_dc(grid, values, gradients, intervals, chunk_samples=chunk,
                           serial=serial)
        np.testing.assert_array_equal(a[0], b[0])
        np.testing.assert_array_equal(a[1], b[1])


def test_serial_values_match_the_fast_backend():
    from csdf.backends import fast

    prog = _csg().compile()
    pts = np.random.default_rng(1).uniform(-1, 1, (5000, 3))
    f = fast.serial_values(prog, prog.param_values({}))
    np.testing.assert_array_equal(f(pts), prog(pts, backend="fast"))
    out = np.full(6000, 7.0)
    r = f(pts, out=out)
    assert r.base is out and np.array_equal(out[:5000], r) and out[5000] == 7.0
    sph = csdf.sphere(csdf.param("r", 1.0)).compile()
    g = fast.serial_values(sph, sph.param_values({"r": float("nan")}))
    assert np.isnan(g(pts)).all()  # NaN parameter in, NaN out, as the backend


def test_column_masks_give_every_voxel_case():
    """The bit-parallel case computation against the corner-by-corner definition."""
    rng = np.random.default_rng(3)
    B = 8
    vals = rng.normal(size=(2, B + 1, B + 1, B + 1))
    vals[1] = np.abs(vals[1])  # a brick all outside ...
    vals[1, 3:6, 2:7, 4:8] *= -1  # ... but for a block inside
    masks = np.empty((B + 1, B + 1), dtype=np.int64)
    for b in range(2):
        K.neg_columns(vals, b, masks)
        for x in range(B):
            for y in range(B):
                m = (masks[x, y], masks[x + 1, y], masks[x, y + 1], masks[x + 1, y + 1])
                crossed = K.column_crossed(*m, B)
                for z in range(B):
                    case = sum(1 << c for c in range(8)
                               if vals[b, x + (c & 1), y + (c >> 1 & 1), z + (c >> 2 & 1)] < 0)
                    assert bool(crossed >> z & 1) == (case not in (0, 255))
                    if case not in (0, 255):
                        assert K.voxel_case(*m, z) == case
                if crossed:
                    assert K.lowest_bit(crossed) == min(
                        z for z in range(B) if crossed >> z & 1)


def test_face_index_numbers_a_bricks_face_edges_compactly():
    B = 8
    seen = set()
    for a in range(3):
        for r in np.ndindex(B, B, B):
            others = [r[d] for d in range(3) if d != a]
            if 0 not in others:
                continue  # not on a lower face
            seen.add(K.face_index(*r, a, B))
    assert seen == set(range(3 * B * (2 * B - 1)))
    assert 3 * B * (2 * B - 1) <= 1 << K._LOCAL_BITS


def test_concurrent_meshes_share_the_workers_safely():
    """Two meshes at once (the editor's server can be asked for two exports) share the
    mesher's worker threads and still give the meshes they give alone."""
    from concurrent.futures import ThreadPoolExecutor

    shapes = [_csg(), csdf.torus(0.6, 0.25).twist(0.8)]
    alone = [csdf.mesh(s, resolution=48, progress=False) for s in shapes]
    with ThreadPoolExecutor(2) as ex:
        together = list(ex.map(lambda s: csdf.mesh(s, resolution=48, progress=False), shapes))
    for a, b in zip(alone, together):
        np.testing.assert_array_equal(a.vertices, b.vertices)
        np.testing.assert_array_equal(a.faces, b.faces)
