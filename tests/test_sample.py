"""Surface and volume sampling (on the zero set, uniform by area, outward unit normals,
seeded) and point-cloud PLY I/O (round trips, other writers' files, malformed files)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

import csdf
from csdf.io import read_point_properties, read_points, write_points
from csdf.sample import sample_surface, sample_volume


def csg_example():
    c = csdf.cylinder(0.5, 3.0)
    return (csdf.sphere(1.0) & csdf.box(1.5)) - c - c.orient("x") - c.orient("y")


HALF = np.array([0.5, 0.3, 0.15])  # half sides of a box with three different face areas

SHAPES = {
    "sphere": lambda: csdf.sphere(1.0),
    "box": lambda: csdf.box(2 * HALF),
    "csg": csg_example,
    "torus": lambda: csdf.torus(0.6, 0.2),
    "smooth union": lambda: csdf.union(csdf.sphere(0.5), csdf.box(0.6).translate((0.6, 0, 0)),
                                       k=0.3, blend="smooth"),
    "twisted box": lambda: csdf.box((1.0, 0.4, 2.0)).twist(1.2),
    # exact primitives whose formula has a zero gradient at many points exactly on the
    # surface (f = 0 through sqrt(0) or a max/min tie with a constant), and for the cone
    # also a round-off direction at points within ~1e-16 of it
    "hex prism": lambda: csdf.hex_prism(0.5, 1.0),
    "cone": lambda: csdf.cone(0.5, 1.0),
}


@pytest.fixture(scope="module")
def surface_samples():
    out = {}
    for name, make in SHAPES.items():
        shape = make()
        out[name] = (shape, *sample_surface(shape, 4000, seed=7))
    return out


# ---------------------------------------------------------------------- sample_surface
@pytest.mark.parametrize("name", sorted(SHAPES))
def test_surface_points_lie_on_the_zero_set(surface_samples, name):
    shape, pts, nrm = surface_samples[name]
    assert pts.shape == (4000, 3) and nrm.shape == (4000, 3)
    assert pts.dtype == np.float64 and nrm.dtype == np.float64
    assert np.max(np.abs(shape(pts, backend="numpy"))) <= 1e-6
    assert np.max(np.abs(shape(pts))) <= 1e-9


@pytest.mark.parametrize("name", sorted(SHAPES))
def test_normals_are_unit_and_point_outwards(surface_samples, name):
    shape, pts, nrm = surface_samples[name]
    assert np.allclose(np.linalg.norm(nrm, axis=1), 1.0, atol=1e-12)
    eps = 1e-6
    assert np.all(shape(pts + eps * nrm) > 0)
    assert np.all(shape(pts - eps * nrm) < 0)
    # normals are the normalised exact gradient: at the point where it is usable, and
    # just off the surface everywhere (there the formulas have no 0/0 round-off)
    g = shape.gradient(pts)
    gn = np.linalg.norm(g, axis=1)
    at = gn > 0
    cos_at = np.einsum("ij,ij->i", g[at], nrm[at]) / gn[at]
    assert at.sum() > 100 and np.mean(cos_at > 1 - 1e-9) > 0.75  # cone: 0.81
    go = shape.gradient(pts + 1e-7 * nrm)
    cos_out = np.einsum("ij,ij->i", go, nrm) / np.linalg.norm(go, axis=1)
    assert np.all(cos_out > 0) and np.mean(cos_out > 1 - 1e-6) > 0.999


def test_normals_where_the_formula_gradient_vanishes(surface_samples):
    shape, pts, nrm = surface_samples["cone"]
    base = np.abs(pts[:, 2]) < 1e-9
    assert base.sum() > 100
    np.testing.assert_allclose(nrm[base], np.tile([0.0, 0.0, -1.0], (base.sum(), 1)),
                               atol=1e-9)
    side = ~base & (pts[:, 2] < 0.99)  # cone side: normal (h, r) / |(h, r)| in (rho, z)
    rho = np.hypot(pts[side, 0], pts[side, 1])
    want = np.column_stack([pts[side, 0] / rho * 2, pts[side, 1] / rho * 2,
                            np.ones(side.sum())]) / np.sqrt(5.0)
    np.testing.assert_allclose(nrm[side], want, atol=1e-6)
    shape, pts, nrm = surface_samples["hex prism"]
    side = np.abs(pts[:, 2]) < 0.5 - 1e-6
    ang = np.arctan2(nrm[side, 1], nrm[side, 0])  # side normals at 30 + 60 k degrees
    k = (ang - np.pi / 6) / (np.pi / 3)
    np.testing.assert_allclose(k, np.round(k), atol=1e-6)
    np.testing.assert_allclose(nrm[side, 2], 0.0, atol=1e-9)


def _box_face_bins(pts, cells):
    """Bin index of each point on the box: face (6) x ``cells`` x ``cells``; expected
    probabilities proportional to area."""
    rows = np.arange(len(pts))
    axis = np.argmin(HALF - np.abs(pts), axis=1)
    face = 2 * axis + (pts[rows, axis] > 0)
    others = np.array([[1, 2], [0, 2], [0, 1]])[axis]
    u = pts[rows, others[:, 0]] / HALF[others[:, 0]]
    v = pts[rows, others[:, 1]] / HALF[others[:, 1]]
    cu = np.clip(((u + 1) / 2 * cells).astype(int), 0, cells - 1)
    cv = np.clip(((v + 1) / 2 * cells).astype(int), 0, cells - 1)
    bins = (face * cells + cu) * cells + cv
    areas = np.array([HALF[1] * HALF[2], HALF[0] * HALF[2], HALF[0] * HALF[1]]).repeat(2)
    prob = np.repeat(areas / areas.sum(), cells * cells) / (cells * cells)
    return bins, prob


@pytest.mark.parametrize("cells", [1, 4])
def test_uniform_by_area_on_a_box(cells):
    pts, _ = sample_surface(csdf.box(2 * HALF), 20_000, seed=11)
    assert np.max(np.abs(np.abs(pts) - HALF).min(axis=1)) <= 1e-9  # on a face
    bins, prob = _box_face_bins(pts, cells)
    counts = np.bincount(bins, minlength=len(prob))
    assert stats.chisquare(counts, prob * len(pts)).pvalue > 1e-3


def test_uniform_by_area_on_curved_surfaces():
    # sphere: z is uniform on [-1, 1] (Archimedes), the longitude uniform
    pts, _ = sample_surface(csdf.sphere(1.0), 20_000, seed=3)
    assert stats.kstest(pts[:, 2], stats.uniform(-1, 2).cdf).pvalue > 1e-3
    lon = np.arctan2(pts[:, 1], pts[:, 0])
    assert stats.kstest(lon, stats.uniform(-np.pi, 2 * np.pi).cdf).pvalue > 1e-3
    # torus: the tube angle has density (R + r cos t) / (2 pi R)
    big, small = 0.6, 0.2
    pts, _ = sample_surface(csdf.torus(big, small), 20_000, seed=5)
    t = np.arctan2(pts[:, 2], np.hypot(pts[:, 0], pts[:, 1]) - big)

    def cdf(x):
        return (x + np.pi + small / big * np.sin(x)) / (2 * np.pi)

    assert stats.kstest(t, cdf).pvalue > 1e-3


def test_surface_sampling_is_seeded():
    s = csdf.torus(0.6, 0.2)
    a, na = sample_surface(s, 500, seed=1)
    b, nb = sample_surface(s, 500, seed=1)
    c, _ = sample_surface(s, 500, seed=2)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(na, nb)
    assert not np.allclose(a, c)
    # a Generator is used and advanced
    rng = np.random.default_rng(1)
    d, _ = sample_surface(s, 500, seed=rng)
    np.testing.assert_array_equal(a, d)
    e, _ = sample_surface(s, 500, seed=rng)
    assert not np.allclose(d, e)


def test_surface_sampling_with_parameters_and_programs():
    r = csdf.param("r", 1.0, lo=0.5, hi=2.0)
    s = csdf.sphere(r)
    pts, nrm = sample_surface(s, 300, seed=0, params={"r": 1.5})
    assert np.allclose(np.linalg.norm(pts, axis=1), 1.5, atol=1e-9)
    assert np.allclose(nrm, pts / 1.5, atol=1e-9)
    pts2, _ = sample_surface(s.compile(), 300, seed=0)  # a Program: bounds by intervals
    assert np.allclose(np.linalg.norm(pts2, axis=1), 1.0, atol=1e-9)
    empty_p, empty_n = sample_surface(s, 0)
    assert empty_p.shape == (0, 3) and empty_n.shape == (0, 3)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"n": -1}, "n must be"),
        ({"n": 2.5}, "n must be"),
        ({"n": True}, "n must be"),
        ({"n": 10, "params": {"nope": 1.0}}, "unknown parameter"),
        ({"n": 10, "seed": "abc"}, "seed"),
    ],
)
def test_surface_sampling_errors(kwargs, match):
    with pytest.raises(csdf.CsdfError, match=match):
        sample_surface(csdf.sphere(1.0), **kwargs)


def test_surface_sampling_rejects_bad_shapes():
    with pytest.raises(csdf.CsdfError, match="3D"):
        sample_surface(csdf.circle(1.0), 10)
    with pytest.raises(csdf.CsdfError, match="Shape or Program"):
        sample_surface("sphere", 10)


# ---------------------------------------------------------------------- sample_volume
def test_volume_samples_and_distances():
    shape = csg_example()
    pts, d = sample_volume(shape, 6000, near_surface=0.5, seed=4)
    assert pts.shape == (6000, 3) and d.shape == (6000,)
    np.testing.assert_allclose(d, shape(pts), rtol=0, atol=1e-12)
    diag = np.linalg.norm(shape.bounds[1] - shape.bounds[0])
    sigma = 0.01 * diag
    near = np.abs(d) < 5 * sigma
    # half the points are within a few sigma of the surface (plus the uniform ones that
    # land there: this shape is mostly surface)
    assert near.mean() >= 0.5
    lo, hi = shape.bounds
    pad = 0.05 * (hi - lo)
    far = pts[~near]
    assert np.all(far >= lo - pad) and np.all(far <= hi + pad)
    assert (d < 0).mean() > 0.1 and (d > 0).mean() > 0.1


def test_volume_samples_exact_distances_of_a_sphere():
    pts, d = sample_volume(csdf.sphere(0.7), 2000, near_surface=0.3, sigma=0.05, seed=0)
    np.testing.assert_allclose(d, np.linalg.norm(pts, axis=1) - 0.7, atol=1e-12)
    assert (np.abs(d) < 0.25).mean() >= 0.3
    # near-surface offsets have the requested spread (normal to the surface: N(0, sigma))
    pts, d = sample_volume(csdf.sphere(0.7), 4000, near_surface=1.0, sigma=0.05, seed=1)
    assert np.std(d) == pytest.approx(0.05, rel=0.05)
    assert abs(np.mean(d)) < 0.005


def test_volume_fractions_and_bounds():
    s = csdf.box((1.0, 0.6, 0.3))
    pts, d = sample_volume(s, 1000, near_surface=1.0, sigma=0.0, seed=2)
    assert np.max(np.abs(d)) <= 1e-9
    box = ((-2, -2, -2), (2, 2, 2))
    pts, d = sample_volume(s, 1000, near_surface=0.0, seed=2, bounds=box)
    assert np.all(np.abs(pts) <= 2.2) and np.abs(pts).max() > 1.9
    np.testing.assert_allclose(d, s(pts), atol=1e-12)


def test_volume_sampling_is_seeded():
    s = csdf.torus(0.6, 0.2)
    a = sample_volume(s, 800, seed=9)
    b = sample_volume(s, 800, seed=9)
    c = sample_volume(s, 800, seed=10)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])
    assert not np.allclose(a[0], c[0])


def test_volume_of_an_unbounded_shape_with_bounds():
    plane = csdf.plane((0, 0, 1), 0.0)
    box = ((-1, -1, -1), (1, 1, 1))
    pts, d = sample_volume(plane, 500, near_surface=0.5, sigma=0.01, seed=0, bounds=box)
    np.testing.assert_allclose(d, pts[:, 2], atol=1e-12)
    assert (np.abs(d) < 0.05).mean() >= 0.5


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"near_surface": 1.5}, "near_surface"),
        ({"near_surface": -0.1}, "near_surface"),
        ({"near_surface": "half"}, "near_surface"),
        ({"sigma": -1.0}, "sigma"),
        ({"sigma": float("nan")}, "sigma"),
        ({"bounds": ((0, 0, 0), (0, 1, 1))}, "bounds"),
        ({"bounds": (1, 2)}, "bounds"),
    ],
)
def test_volume_sampling_errors(kwargs, match):
    with pytest.raises(csdf.CsdfError, match=match):
        sample_volume(csdf.sphere(1.0), 10, **kwargs)


# ---------------------------------------------------------------------- PLY point clouds
@pytest.mark.parametrize("ascii", [False, True])
@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_ply_round_trip(tmp_path, ascii, dtype):
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(257, 3)).astype(dtype)
    nrm = rng.normal(size=(257, 3)).astype(dtype)
    cols = rng.integers(0, 256, size=(257, 3)).astype(np.uint8)
    path = tmp_path / "cloud.ply"
    assert write_points(path, pts, nrm, colors=cols, ascii=ascii) == path
    p, n = read_points(path)
    assert p.dtype == np.float64 and n is not None
    np.testing.assert_array_equal(p, pts.astype(np.float64))
    np.testing.assert_array_equal(n, nrm.astype(np.float64))
    write_points(path, pts, ascii=ascii)  # overwrite, no normals
    p, n = read_points(path)
    assert n is None
    np.testing.assert_array_equal(p, pts.astype(np.float64))
    assert [f.name for f in tmp_path.iterdir()] == ["cloud.ply"]  # no temporary left


@pytest.mark.parametrize("ascii", [False, True])
def test_ply_scalars_of_volume_samples(tmp_path, ascii):
    pts, d = sample_volume(csdf.sphere(1.0), 200, seed=0)
    path = write_points(tmp_path / "v.ply", pts, scalars={"distance": d}, ascii=ascii)
    props = read_point_properties(path)
    assert list(props) == ["x", "y", "z", "distance"]
    np.testing.assert_array_equal(props["distance"], d)
    np.testing.assert_array_equal(read_points(path)[0], pts)
    with pytest.raises(csdf.CsdfError, match="twice"):
        write_points(path, pts, scalars={"x": d})
    with pytest.raises(csdf.CsdfError, match="letters"):
        write_points(path, pts, scalars={"dist ance": d})
    with pytest.raises(csdf.CsdfError, match="distance"):
        write_points(path, pts, scalars={"distance": d[:-1]})


def test_ply_of_surface_samples_is_read_by_trimesh(tmp_path):
    import trimesh

    pts, nrm = sample_surface(csdf.sphere(1.0), 500, seed=0)
    path = write_points(tmp_path / "s.ply", pts, nrm, colors=np.full((500, 4), 0.5))
    cloud = trimesh.load(path)
    np.testing.assert_allclose(np.asarray(cloud.vertices), pts)
    p, n = read_points(path)
    np.testing.assert_array_equal(p, pts)
    np.testing.assert_array_equal(n, nrm)


def test_read_points_of_a_mesh_ply(tmp_path):
    m = csdf.mesh(csdf.box(1.0), resolution=8, progress=False)
    path = tmp_path / "m.ply"
    csdf.io.write_mesh(m, path)  # binary PLY with a face list after the vertices
    p, n = read_points(path)
    np.testing.assert_allclose(p, np.asarray(m.vertices))
    # an ASCII file with a face element before the vertices (legal PLY)
    text = ("ply\r\nformat ascii 1.0\r\ncomment x\r\nelement face 1\r\n"
            "property list uchar int vertex_indices\r\nelement vertex 2\r\n"
            "property float x\r\nproperty float y\r\nproperty float z\r\n"
            "property uchar red\r\nend_header\r\n3 0 1 0\r\n1 2 3 255\r\n4 5 6 0\r\n")
    path.write_bytes(text.encode())
    p, n = read_points(path)
    np.testing.assert_array_equal(p, [[1, 2, 3], [4, 5, 6]])
    assert n is None


def test_read_big_endian_and_integer_types(tmp_path):
    rec = np.array([(1, 2, 3, 0.0, 0.0, 1.0)], dtype=[
        ("x", ">i2"), ("y", ">i2"), ("z", ">i2"), ("nx", ">f4"), ("ny", ">f4"), ("nz", ">f4")])
    head = (b"ply\nformat binary_big_endian 1.0\nelement vertex 1\nproperty short x\n"
            b"property short y\nproperty short z\nproperty float nx\nproperty float ny\n"
            b"property float nz\nend_header\n")
    path = tmp_path / "be.ply"
    path.write_bytes(head + rec.tobytes())
    p, n = read_points(path)
    np.testing.assert_array_equal(p, [[1, 2, 3]])
    np.testing.assert_array_equal(n, [[0, 0, 1]])


GOOD_HEAD = ("ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty float x\n"
             "property float y\nproperty float z\nend_header\n")
GOOD_BODY = np.arange(6, dtype="<f4").tobytes()

MALFORMED = {
    "empty": (b"", "not a PLY"),
    "not ply": (b"solid cube\nfacet normal 0 0 1\n", "not a PLY"),
    "no end_header": (GOOD_HEAD.replace("end_header\n", "").encode(), "end_header"),
    "no format": (GOOD_HEAD.replace("format binary_little_endian 1.0\n", "").encode()
                  + GOOD_BODY, "format"),
    "bad format": (GOOD_HEAD.replace("binary_little_endian", "binary_middle_endian").encode()
                   + GOOD_BODY, "format"),
    "bad version": (GOOD_HEAD.replace("1.0", "2.0").encode() + GOOD_BODY, "format"),
    "count not int": (GOOD_HEAD.replace("vertex 2", "vertex two").encode(), "not an integer"),
    "negative count": (GOOD_HEAD.replace("vertex 2", "vertex -2").encode(), "negative"),
    "absurd count": (GOOD_HEAD.replace("vertex 2", "vertex 99999999999999").encode()
                     + GOOD_BODY, "truncated"),
    "truncated": (GOOD_HEAD.encode() + GOOD_BODY[:-1], "truncated"),
    "no vertex": (GOOD_HEAD.replace("element vertex", "element point").encode() + GOOD_BODY,
                  "no 'vertex'"),
    "missing z": (GOOD_HEAD.replace("property float z\n", "").encode() + GOOD_BODY,
                  "no z"),
    "bad type": (GOOD_HEAD.replace("float x", "float128 x").encode() + GOOD_BODY,
                 "bad property"),
    "property first": (b"ply\nformat ascii 1.0\nproperty float x\nend_header\n",
                       "before any element"),
    "unknown keyword": (GOOD_HEAD.replace("end_header", "elephant 3\nend_header").encode()
                        + GOOD_BODY, "unknown keyword"),
    "partial normals": (GOOD_HEAD.replace("end_header", "property float nx\nend_header")
                        .encode() + GOOD_BODY, "nx, ny, nz"),
    "duplicate x": (GOOD_HEAD.replace("end_header", "property float x\nend_header").encode()
                    + GOOD_BODY, "twice"),
    "binary header": (b"ply\nformat ascii 1.0\n\xff\xfe\nend_header\n", "ASCII"),
    "ascii truncated": (GOOD_HEAD.replace("binary_little_endian", "ascii").encode()
                        + b"1 2 3\n", "truncated"),
    "ascii absurd count": (GOOD_HEAD.replace("binary_little_endian", "ascii")
                           .replace("vertex 2", "vertex 1000000000000").encode()
                           + b"1 2 3\n4 5 6\n", "truncated"),
    "ascii short row": (GOOD_HEAD.replace("binary_little_endian", "ascii").encode()
                        + b"1 2 3\n4 5\n7 8 9\n", "values"),
    "ascii not a number": (GOOD_HEAD.replace("binary_little_endian", "ascii").encode()
                           + b"1 2 3\n4 5 six\n", "not a number"),
    "list vertex": (GOOD_HEAD.replace("end_header", "property list uchar float w\nend_header")
                    .encode() + GOOD_BODY, "list"),
}


@pytest.mark.parametrize("name", sorted(MALFORMED))
def test_read_points_rejects_malformed_files(tmp_path, name):
    data, match = MALFORMED[name]
    path = tmp_path / "bad.ply"
    path.write_bytes(data)
    with pytest.raises(csdf.CsdfError, match=match):
        read_points(path)


def test_read_points_fuzzed_headers_raise_only_csdf_errors(tmp_path):
    rng = np.random.default_rng(1)
    good = GOOD_HEAD.encode() + GOOD_BODY
    path = tmp_path / "fuzz.ply"
    for _ in range(300):
        data = bytearray(good)
        for _ in range(rng.integers(1, 4)):
            op = rng.integers(3)
            i = int(rng.integers(len(data)))
            if op == 0:
                data[i] = int(rng.integers(256))
            elif op == 1:
                del data[i]
            else:
                data[i:i] = bytes([int(rng.integers(32, 127))])
        path.write_bytes(bytes(data))
        try:
            p, _ = read_points(path)
        except csdf.CsdfError:
            continue
        assert p.ndim == 2 and p.shape[1] == 3


def test_read_points_missing_file(tmp_path):
    with pytest.raises(csdf.CsdfError, match="cannot read"):
        read_points(tmp_path / "nothing.ply")


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"points": np.zeros((3, 2))}, "points must have shape"),
        ({"points": np.zeros((3, 3)), "normals": np.zeros((4, 3))}, "normals"),
        ({"points": np.zeros((3, 3)), "colors": np.full((3, 3), 2.0)}, r"\[0, 1\]"),
        ({"points": np.zeros((3, 3)), "colors": np.full((3, 3), 300)}, "0, 255"),
        ({"points": np.array([["a", "b", "c"]])}, "numeric"),
    ],
)
def test_write_points_errors(tmp_path, kwargs, match):
    with pytest.raises(csdf.CsdfError, match=match):
        write_points(tmp_path / "x.ply", **kwargs)
    assert list(tmp_path.iterdir()) == []


def test_write_points_to_a_missing_folder(tmp_path):
    with pytest.raises(csdf.CsdfError, match="does not exist"):
        write_points(tmp_path / "no" / "x.ply", np.zeros((1, 3)))
