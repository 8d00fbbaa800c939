"""Fields written as math (issue 23, first increment): ``csdf.field`` and the
coordinates ``csdf.x/y/z``, symbolic gradients, Eq. 11 (``normalized``), ``remap``,
the language's ``field(...)``, and the catalogue fields (gyroid, superquadric,
tanglecube)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import csdf
from csdf.exprgrad import gradient
from csdf.shapes.exprfield import expr_shape

RNG = np.random.default_rng(11)
x, y, z = csdf.x, csdf.y, csdf.z


def _v(shape, pts, **kw):
    return np.asarray(csdf.as_field(shape, **kw).value(np.asarray(pts, float)), float)


def test_symbolic_gradient_is_the_evaluators_forward_mode():
    e = (csdf.sqrt(x * x + y * y + z * z) - 1.0 + 0.1 * csdf.sin(3 * x) * csdf.cos(2 * y)
         + csdf.minimum(x, z * z) + csdf.maximum(0.2, y) + csdf.atan2(y, x + 2.0)
         + csdf.exp(0.1 * z) + csdf.log(x * x + 1.0) + abs(z - 0.1) + csdf.mod(x, 0.7)
         + csdf.floor(3 * y) + csdf.tan(0.3 * z) + csdf.atan(y) + x / (2.0 + y * y))
    g = gradient(e)
    P = RNG.uniform(-1, 1, (200, 3))
    ref = np.asarray(csdf.as_field(expr_shape(e)).gradient(P))
    sym = np.stack([_v(expr_shape(c, dim=3), P) for c in g], axis=1)
    assert np.allclose(sym, ref, rtol=1e-12, atol=1e-12)
    # by a parameter too, and a constant has a zero gradient
    r = csdf.param("r", 1.0, 0.5, 2.0)
    (dr,) = gradient(csdf.sqrt(x * x + y * y) - r * r, (r.args[0] if r.args else r,))
    assert float(_v(expr_shape(dr, dim=3), [[0.3, 0.2, 0.0]])[0]) == pytest.approx(-2.0)
    assert [c.op for c in gradient(csdf.sqrt(2.0 + 0 * x))] == ["const"] * 3


def test_eq11_algebraic_sphere_is_exact_on_the_surface_and_errs_as_predicted():
    R = 0.8
    alg = csdf.field(x * x + y * y + z * z - R * R)
    assert alg.exactness == "neither"
    # no bounds given: found by intervals (tight to a cell), and the Lipschitz bound
    # over them (|grad| = 2 r <= 2 sqrt(3) R on the box's corners)
    assert np.allclose(alg.bounds, [[-R] * 3, [R] * 3], atol=0.01)
    assert 2 * math.sqrt(3) * R <= alg.lipschitz <= 2 * math.sqrt(3) * R * 1.05
    n = alg.normalized()
    assert n.exactness == "neither"
    # on the sphere: the exact distance (0) to 1e-12, and the gradient is unit
    u = RNG.normal(size=(300, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    on = R * u
    assert np.abs(_v(n, on)).max() < 1e-12
    g = np.asarray(csdf.as_field(n).gradient(on))
    assert np.allclose(np.linalg.norm(g, axis=1), 1.0, atol=1e-12)
    # off it, Eq. 11 gives (r^2 - R^2) / (2 r) = (r - R) - (r - R)^2 / (2 r)
    r = np.linspace(0.2, 3.0, 57)
    got = _v(n, np.c_[r, np.zeros_like(r), np.zeros_like(r)])
    assert np.allclose(got, (r - R) - (r - R) ** 2 / (2 * r), rtol=0, atol=1e-12)
    err = np.abs(got - (r - R))
    far = r > R
    assert np.all(np.diff(err[far]) > 0)  # the error grows away from the surface
    # where the gradient vanishes (the centre) the value is f / GRAD_FLOOR: large, signed
    assert _v(n, [[0, 0, 0]])[0] < -1e6
    # normalize=True is the same shape; far= takes the bounding shape's value outside it
    same = csdf.field(x * x + y * y + z * z - R * R, normalize=True)
    P = RNG.uniform(-2, 2, (100, 3))
    assert np.array_equal(_v(same, P), _v(n, P))
    clamped = alg.normalized(far=csdf.sphere(1.5))
    assert _v(clamped, [[3.0, 0, 0]])[0] == pytest.approx(1.5)
    assert _v(clamped, [[1.2, 0, 0]])[0] == pytest.approx((1.44 - R * R) / 2.4)
    assert np.allclose(_v(csdf.loads(csdf.dumps(clamped)), P), _v(clamped, P))
    with pytest.raises(csdf.ShapeError, match="far"):
        alg.normalized(far=csdf.circle(1.0))


def test_bounds_by_intervals():
    from csdf.shapes.userfield import interval_bounds

    off = csdf.field(csdf.sqrt((x - 3) * (x - 3) + y * y + z * z) - 0.5)
    b = off.bounds
    assert np.all(b[0] <= [2.5, -0.5, -0.5]) and np.all(b[1] >= [3.5, 0.5, 0.5])
    assert np.all(b[0] > [2.4, -0.6, -0.6]) and np.all(b[1] < [3.6, 0.6, 0.6])
    assert csdf.mesh(off, resolution=24, progress=False).is_watertight  # no bounds= needed
    assert interval_bounds(x + y + z, 3) is None  # a plane: unbounded
    assert interval_bounds(x * x + y * y + z * z + 1.0, 3) is None  # no surface
    assert csdf.field(x + y + z).bounds is None
    assert csdf.gyroid().bounds is None
    disk = csdf.field(lambda a, b, c: csdf.sqrt(a * a + b * b) - 2.0)
    assert disk.dim == 2 and np.allclose(disk.bounds, [[-2, -2], [2, 2]], atol=0.1)


def test_field_contracts_callables_and_checks():
    ball = csdf.field(csdf.sqrt(x * x + y * y + z * z) - 1.0, exact=True,
                      bounds=((-1, -1, -1), (1, 1, 1)))
    assert ball.exactness == "exact" and ball.lipschitz == 1.0
    P = RNG.uniform(-2, 2, (100, 3))
    assert np.allclose(_v(ball, P), np.linalg.norm(P, axis=1) - 1.0, atol=1e-14)
    assert csdf.field(lambda a, b, c: a + b + c, lipschitz=math.sqrt(3)).exactness == \
        "neither"
    assert csdf.field(lambda a, b, c: a / 2, lipschitz=0.5).exactness == "bound"
    disk = csdf.field(lambda a, b, c: csdf.sqrt(a * a + b * b) - 1)
    assert disk.dim == 2
    with pytest.raises(csdf.ShapeError, match="lipschitz"):
        csdf.field(x, lipschitz=-1)
    with pytest.raises(csdf.ShapeError, match="bounds"):
        csdf.field(x + y + z, bounds=((0, 0, 0), (0, 1, 1)))
    with pytest.raises(csdf.ShapeError, match="expression"):
        csdf.field("x + y")
    with pytest.raises(csdf.ShapeError, match=r"\(x, y, z\)"):
        csdf.field(lambda a: a)
    with pytest.raises(csdf.ShapeError, match="x, y or z"):
        csdf.sphere(x)  # no other argument may depend on the position


def test_remap_and_combination_with_everything():
    b = csdf.box((1.0, 0.6, 0.4))
    sheared = b.remap(x=x + 0.5 * y)
    P = RNG.uniform(-1, 1, (200, 3))
    Q = P.copy()
    Q[:, 0] += 0.5 * P[:, 1]
    assert np.allclose(_v(sheared, P), _v(b, Q), atol=1e-14)
    assert sheared.exactness == "neither" and sheared.bounds is None
    assert b.remap() is b
    mixed = (sheared.translate((1, 0, 0)) | csdf.field(x * x + y * y + z * z - 0.25))
    assert np.isfinite(_v(mixed, P)).all()
    with pytest.raises(csdf.ShapeError, match="2D shape"):
        csdf.circle(1.0).remap(x=x + z)


def test_language_fields_round_trip_and_stay_safe():
    text = ("param r = 1 in [0.5, 2]\n"
            "let warped = box(1).remap(x = x + 0.3 * sin(4 * y))\n"
            "export field(sqrt(x * x + y * y + z * z) - r, exact = 1) | warped.translate((2, 0, 0))"
            " | field(x * x + y * y + z * z - 0.04).normalized().translate((0, 3, 0))\n")
    s = csdf.loads(text)
    back = csdf.loads(csdf.dumps(s))
    P = RNG.uniform(-2, 4, (300, 3))
    assert np.allclose(_v(back, P), _v(s, P), atol=1e-14)
    assert _v(s, [[0, 0, 0]])[0] == pytest.approx(-1.0)
    assert _v(s, [[0, 0, 0]], params={"r": 1.5})[0] == pytest.approx(-1.5)
    for bad, msg in (("export sphere(x)", "unknown name 'x'"),
                     ("let a = x\nexport sphere(1)", "unknown name 'x'"),
                     ("export field(x * q)", "unknown name 'q'"),
                     ("export field(sphere(1))", "expression")):
        with pytest.raises(csdf.ModelError, match=msg):
            csdf.loads(bad)


def test_catalogue_fields():
    sq = csdf.superquadric((1.0, 1.0, 1.0), 1.0, 1.0)  # e1 = e2 = 1: the unit sphere
    P = RNG.uniform(-2, 2, (200, 3))
    assert np.allclose(_v(sq, P), np.linalg.norm(P, axis=1) - 1.0, atol=1e-9)
    boxy = csdf.superquadric((1.0, 0.5, 0.25), 0.2, 0.2)
    assert _v(boxy, [[0.9, 0.4, 0.15]])[0] < 0 < _v(boxy, [[1.05, 0.0, 0.0]])[0]
    assert np.allclose(boxy.bounds, [[-1, -0.5, -0.25], [1, 0.5, 0.25]])
    with pytest.raises(csdf.ShapeError, match="e1"):
        csdf.superquadric(1.0, 9.0, 1.0)
    g = csdf.gyroid(1.0, 0.1)
    assert _v(g, [[0, 0, 0]])[0] == pytest.approx(-0.05)  # the sum is 0 at the origin
    assert g.lipschitz == pytest.approx(2 * math.sqrt(3))
    tc = csdf.tanglecube()
    m = csdf.mesh(tc, resolution=40, progress=False)
    assert m.is_watertight and m.euler_number == 2 - 2 * 5  # genus 5
    sample = m.vertices[:200]
    assert np.abs(_v(tc, sample)).max() < 0.05  # on the surface, to the mesh's voxel


def test_fit_recovers_a_superquadrics_pose_and_exponents():
    e1 = csdf.param("e1", 1.0, 0.1, 2.0)
    e2 = csdf.param("e2", 1.0, 0.1, 2.0)
    sq = csdf.superquadric((0.3, 0.2, 0.1), e1, e2)
    P = csdf.sample_surface(sq, 3000, params={"e1": 0.5, "e2": 0.8}, seed=0)[0]
    c, s = math.cos(0.5), math.sin(0.5)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    t = np.array([0.1, -0.2, 0.05])
    Q = P @ R.T + t + RNG.normal(0, 0.001, P.shape)
    r = csdf.fit(sq, Q, estimate=("pose", "params"), init={"translation": Q.mean(0)},
                 f_scale=0.001, seed=0)
    assert r.success
    assert abs(r.params["e1"] - 0.5) < 0.01 and abs(r.params["e2"] - 0.8) < 0.01
    dR = r.rotation.T @ R
    assert math.degrees(math.acos(np.clip((np.trace(dR) - 1) / 2, -1, 1))) < 0.2
    assert np.linalg.norm(r.translation - t) < 1e-3


def test_a_field_that_is_not_a_distance_traces_like_its_mesh():
    # the tangle cube is a polynomial, not a distance: the sphere tracer steps by its
    # Lipschitz bound over the box, found by interval arithmetic of its gradient, and
    # must neither overstep nor miss
    import trimesh

    tc = csdf.tanglecube()
    assert tc.exactness == "neither" and 5.0 < tc.lipschitz < 20.0
    cam = csdf.Camera.look_at(eye=(6.0, 4.5, 3.5), target=(0, 0, 0), fov=40, width=48,
                              height=36)
    P, _ = csdf.scan(tc, cam)
    m = csdf.mesh(tc, resolution=128, progress=False)
    tm = trimesh.Trimesh(m.vertices, m.faces, process=False)
    o, d = cam.rays()
    loc, ri, _ = tm.ray.intersects_location(o, d, multiple_hits=False)
    depth = np.full(len(d), np.inf)
    depth[ri] = np.linalg.norm(loc - o[ri], axis=1)
    Pw = cam.camera_to_world(P)
    # the scanned points are on the surface (a ray out of iterations within 16 tracer
    # tolerances of it counts as a hit, as for any field) and at the mesh's first hit
    f = np.abs(_v(tc, Pw))
    assert np.median(f) < 1e-9 and f.max() / tc.lipschitz < 0.02
    u = (Pw - o[0]) / np.linalg.norm(Pw - o[0], axis=1, keepdims=True)
    hit_ray = np.argmax(u @ d.T, axis=1)
    assert np.allclose(np.linalg.norm(Pw - o[0], axis=1), depth[hit_ray], atol=0.05)
    # and it misses no ray that the mesh hits (up to the mesh's grazing rays)
    assert len(P) >= 0.98 * len(ri)
