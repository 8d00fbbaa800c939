"""The field layer: csdf.field.Field, the one bounds policy and the one backend policy."""

from __future__ import annotations

import numpy as np
import pytest

import csdf
from csdf import Pose
from csdf.field import (
    AUTO_FAST_POINTS,
    Field,
    as_field,
    auto_bounds,
    choose_backend,
    field_bounds,
    numba_available,
    step_evaluator,
)


def _ranged_sphere():
    r = csdf.param("r", 1.0, 0.5, 2.0)
    return csdf.sphere(r)


def test_as_field_accepts_shape_program_and_field():
    s = csdf.sphere(1.0)
    f1 = as_field(s)
    f2 = as_field(s.compile())
    assert f1.shape is s and f2.shape is None
    assert f1.program == f2.program
    assert as_field(f1) is f1
    with pytest.raises(csdf.CsdfError, match="mesh expects a Shape or Program, got int"):
        as_field(3, what="mesh")


def test_values_match_the_program():
    shape = (csdf.sphere(1.0) & csdf.box(1.5)) - csdf.cylinder(0.5, 3.0)
    prog = shape.compile()
    pts = np.random.default_rng(0).uniform(-1, 1, (500, 3))
    fld = as_field(shape)
    np.testing.assert_array_equal(fld.value(pts), prog(pts, backend=fld.backend))
    v, g = fld.value_and_grad(pts)
    v0, g0 = prog.value_and_grad(pts, backend=fld.backend)
    np.testing.assert_array_equal(v, v0)
    np.testing.assert_array_equal(g, g0)
    assert fld.exactness == prog.exactness and fld.lipschitz == prog.lipschitz


def test_pose_moves_the_field():
    shape = _ranged_sphere() | csdf.box(0.8).translate((1.0, 0.0, 0.0))
    pose = Pose.from_rotvec([0.3, 0.2, -0.4], [0.5, -1.0, 2.0], 1.7)
    rng = np.random.default_rng(1)
    q = rng.uniform(-2, 2, (400, 3))
    p = pose.apply(q)
    base = as_field(shape, {"r": 0.9})
    moved = as_field(shape, {"r": 0.9}, pose)
    np.testing.assert_allclose(moved.value(p), 1.7 * base.value(q), rtol=1e-12, atol=1e-12)
    v, g = moved.value_and_grad(p)
    np.testing.assert_allclose(g, base.gradient(q) @ pose.rotation.T, atol=1e-12)
    np.testing.assert_allclose(moved.param_jacobian(p), 1.7 * base.param_jacobian(q),
                               atol=1e-12)
    # the world box holds the moved surface, and intervals bound the moved values
    sp, _ = csdf.sample_surface(shape, 300, seed=0, params={"r": 0.9})
    wp = pose.apply(sp)
    b = moved.bounds
    assert np.all(wp >= b[0] - 1e-9) and np.all(wp <= b[1] + 1e-9)
    lo = p - 0.05
    hi = p + 0.05
    flo, fhi = moved.intervals(lo, hi)
    inner = rng.uniform(lo, hi)
    fv = moved.value(inner)
    assert np.all(flo <= fv) and np.all(fv <= fhi)


def test_bounds_policy():
    s = _ranged_sphere()
    prog = s.compile()
    # given bounds win
    np.testing.assert_array_equal(field_bounds(prog, bounds=((-3, -3, -3), (3, 3, 3))),
                                  [[-3] * 3, [3] * 3])
    # a program with parameters: the interval search at its values (defaults here), not
    # its own box (which holds over the whole range, r up to 2), so defaults and the
    # same values given as params= get the same box
    b = as_field(s).bounds
    assert np.all(b[1] >= 1.0) and np.all(b[0] <= -1.0) and np.all(np.abs(b) < 1.02)
    np.testing.assert_array_equal(as_field(s, {"r": 1.0}).bounds, b)
    # values given: the interval search, tighter, and close to the surface
    b = as_field(s, {"r": 0.6}).bounds
    assert np.all(b[1] - b[0] < 1.4) and np.all(b[1] >= 0.6) and np.all(b[0] <= -0.6)
    with pytest.raises(csdf.CsdfError, match="unbounded"):
        _ = as_field(csdf.plane((0, 0, 1), 0.0)).bounds
    with pytest.raises(csdf.CsdfError, match="min < max"):
        as_field(s, bounds=((1, 1, 1), (0, 0, 0)))
    with pytest.raises(csdf.CsdfError, match="2D"):
        field_bounds(csdf.circle(1.0).compile())
    np.testing.assert_allclose(as_field(csdf.circle(1.0)).planar_bounds, [[-1, -1], [1, 1]])
    # an empty parameter dict gives no values: the own box; the search contains it
    np.testing.assert_array_equal(as_field(csdf.sphere(1.0), {}).bounds, [[-1] * 3, [1] * 3])
    ab = auto_bounds(csdf.sphere(1.0).compile())
    assert np.all(ab[0] <= -1.0) and np.all(ab[1] >= 1.0) and np.all(np.abs(ab) < 1.02)


def test_backend_policy():
    with pytest.raises(csdf.CsdfError, match="backend must be one of"):
        choose_backend("gpu")
    assert choose_backend("numpy") == "numpy"
    if numba_available():
        assert choose_backend("auto") == "fast"  # a sweep
        assert choose_backend("auto", AUTO_FAST_POINTS) == "fast"
        assert choose_backend("auto", AUTO_FAST_POINTS - 1) == "auto"
    else:
        assert choose_backend("auto") == "numpy"


def test_params_are_validated_and_merged():
    s = _ranged_sphere() | csdf.sphere(csdf.param("k", 0.3)).translate((2, 0, 0))
    with pytest.raises(csdf.ParamError, match="unknown parameter"):
        as_field(s, {"nope": 1.0})
    f = as_field(s, {"r": 0.7})
    g = Field(f, {"k": 0.4})
    assert g.params == {"r": 0.7, "k": 0.4}
    np.testing.assert_array_equal(g.pvals, s.compile().param_values({"r": 0.7, "k": 0.4}))


def test_serial_values_matches_value():
    f = as_field(csdf.sphere(1.0) - csdf.box(0.6))
    serial = f.serial_values()
    pts = np.ascontiguousarray(np.random.default_rng(2).uniform(-1, 1, (1000, 3)))
    if f.backend == "fast":
        np.testing.assert_array_equal(serial(pts), f.value(pts))
    else:
        assert serial is None
    assert as_field(csdf.sphere(1.0), backend="numpy").serial_values() is None


@pytest.mark.parametrize("backend", ["fast", "numpy", "auto"])
def test_step_evaluator_gives_the_programs_own_numbers(backend):
    """csdf.field.step_evaluator (a fit's per-step evaluator) gives what the program's
    methods give with the same backend, to the bit, in every mode, and again after the
    parameters change (the compiled one keeps the last vector's uniform inputs)."""
    if backend == "fast" and not numba_available():
        pytest.skip("needs Numba")
    r, k = csdf.param("r", 0.8, 0.1, 2.0), csdf.param("k", 0.2, 0.0, 1.0)
    prog = csdf.union(csdf.sphere(r), csdf.box((r, 0.5, 0.3)).translate((0.4, 0, 0)),
                      k=k).compile()
    pts = np.ascontiguousarray(np.random.default_rng(5).uniform(-1.5, 1.5, (700, 3)))
    evs = {mode: step_evaluator(prog, backend, mode) for mode in ("value", "grad", "all")}
    for pv in ({"r": 0.8, "k": 0.2}, {"r": 1.1, "k": 0.05}, {"r": 0.8, "k": 0.2}):
        vec = prog.param_values(pv)
        f, g, J = prog.value_grad_param_jacobian(pts, pv, backend=backend)
        got = evs["all"](pts, vec)
        np.testing.assert_array_equal(got["value"], f)
        np.testing.assert_array_equal(got["grad"], g)
        np.testing.assert_array_equal(got["jac"], J)
        f2, g2 = prog.value_and_grad(pts, pv, backend=backend)
        got = evs["grad"](pts, vec)
        np.testing.assert_array_equal(got["value"], f2)
        np.testing.assert_array_equal(got["grad"], g2)
        np.testing.assert_array_equal(evs["value"](pts, vec)["value"],
                                      prog(pts, pv, backend=backend))


def test_field_values_after_the_first_call_are_the_programs():
    """A compiled field's value calls after the first skip the program call's checks
    (Field._values_at): the same numbers as the program's own call, for a posed field
    too, and float32 or batched points still take the checked path."""
    if not numba_available():
        pytest.skip("needs Numba")
    r = csdf.param("r", 0.8, 0.1, 2.0)
    shape = csdf.union(csdf.sphere(r), csdf.box((0.6, 0.5, 0.3)).translate((0.4, 0, 0)), k=0.1)
    prog = shape.compile()
    pts = np.ascontiguousarray(np.random.default_rng(6).uniform(-1.5, 1.5, (900, 3)))
    f = as_field(shape, {"r": 1.1}, backend="fast")
    assert f._values_at is None
    first = f.value(pts)
    assert f._values_at is not None
    want = prog(pts, {"r": 1.1}, backend="fast")
    np.testing.assert_array_equal(first, want)
    np.testing.assert_array_equal(f.value(pts), want)
    np.testing.assert_array_equal(f.value(pts.reshape(30, 30, 3)), want.reshape(30, 30))
    np.testing.assert_array_equal(f.value(pts.astype(np.float32)),
                                  prog(pts.astype(np.float32), {"r": 1.1}, backend="fast"))
    posed = as_field(shape, {"r": 1.1}, pose=Pose.from_rotvec((0.1, 0.2, 0.3), (0.5, 0, 0), 2.0),
                     backend="fast")
    posed.value(pts)
    np.testing.assert_array_equal(posed.value(pts),
                                  2.0 * prog(posed.pose.apply_inverse(pts), {"r": 1.1},
                                             backend="fast"))


def test_a_field_of_a_field_keeps_its_evaluator():
    """Field(field, bounds=...) (what csdf.mesh makes of a given field) keeps the
    field's backend, as the docs say; a per-call choice ('auto') is made anew."""
    base = csdf.as_field(csdf.sphere(1.0), backend="interp")
    assert csdf.Field(base, bounds=((-2, -2, -2), (2, 2, 2))).backend == "interp"
    assert csdf.Field(base, backend="numpy").backend == "numpy"
    small = csdf.as_field(csdf.sphere(1.0), work=10)
    assert small.backend == "auto"
    assert csdf.Field(small, bounds=((-2, -2, -2), (2, 2, 2))).backend != "auto"
