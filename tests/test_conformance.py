"""One conformance suite, run over every point evaluator of the registry
(:mod:`csdf.backends.registry`; what is unavailable on this machine is skipped): values,
gradients and parameter derivatives agree with the NumPy reference (float64: 1e-9
relative; float32: 1e-5) on every primitive and operator of the catalogue and on random
expression DAGs. A new evaluator is checked by adding its registry entry."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import csdf
from catalogue import catalogue, sample_box
from csdf.backends import BACKENDS, registry
from csdf.compiler import compile_expr
from strategies import expr_dags

CAT = catalogue()


def _evaluators(*, dtype: str = "float64", exclude: tuple[str, ...] = ()) -> list:
    """The registry's point evaluators (by backend name) that state ``dtype``, each
    skipped where it is unavailable."""
    return [pytest.param(e.name, id=e.name, marks=pytest.mark.skipif(
        not e.available(), reason=f"{e.name} needs {e.needs}"))
        for e in registry.point_evaluators() if dtype in e.dtypes and e.name not in exclude]


EVAL_BACKENDS = _evaluators()
TOL = {np.float64: (1e-9, 1e-9), np.float32: (1e-5, 1e-5)}


def _points(shape, n=3000, seed=0, dtype=np.float64):
    rng = np.random.default_rng(seed)
    lo, hi = sample_box(shape)
    pts = rng.uniform(lo, hi, (n, 3)).astype(dtype)
    pts[:7] = [[0, 0, 0], [np.nan, 0, 0], [0, 0, np.nan], [1e-300, 0, 0], [0, 0, 1e30],
               [np.inf, 0, 0], [0, -np.inf, 0]]
    return pts


def _close(got, ref, dtype, what):
    rtol, atol = TOL[dtype]
    assert got.dtype == ref.dtype, what
    np.testing.assert_array_equal(np.isnan(got), np.isnan(ref), err_msg=f"{what}: NaN mask")
    ok = ~np.isnan(ref)
    g, r = got[ok].astype(np.float64), ref[ok].astype(np.float64)
    inf = np.isinf(r)
    np.testing.assert_array_equal(g[inf], r[inf], err_msg=f"{what}: infinities")
    err = np.abs(g[~inf] - r[~inf])
    lim = rtol * np.abs(r[~inf]) + atol
    assert np.all(err <= lim), f"{what}: worst error {np.max(err - lim):.3e} over tolerance"


def _check(prog, pts, backend, dtype):
    # derivatives at infinite coordinates are undefined (0 * inf): values only there
    caps = registry.get(backend)  # (what the evaluator computes)
    fin = ~np.isinf(pts).any(axis=1)
    ref = prog.value_grad_param_jacobian(pts, backend="numpy")
    if caps.gradients and caps.param_jacobians:
        got = prog.value_grad_param_jacobian(pts, backend=backend)
        _close(got[0], ref[0], dtype, f"{backend} value")
        _close(got[1][fin], ref[1][fin], dtype, f"{backend} gradient")
        _close(got[2][fin], ref[2][fin], dtype, f"{backend} param jacobian")
    _close(prog(pts, backend=backend), ref[0], dtype, f"{backend} value-only")
    if caps.gradients:
        v, g = prog.value_and_grad(pts, backend=backend)
        _close(v, ref[0], dtype, f"{backend} value_and_grad value")
        _close(g[fin], ref[1][fin], dtype, f"{backend} value_and_grad gradient")
    if caps.param_jacobians:
        _close(prog.param_jacobian(pts, backend=backend)[fin], ref[2][fin], dtype,
               f"{backend} jacobian")


@pytest.mark.parametrize("backend", EVAL_BACKENDS)
@pytest.mark.parametrize("name", sorted(CAT))
def test_catalogue_float64(backend, name):
    shape = CAT[name]()
    prog = shape.compile()
    if prog.data and not registry.get(backend).mesh_calls:
        # an evaluator that cannot run a mesh call says so (the registry states which)
        with pytest.raises(csdf.CsdfError, match="triangle mesh"):
            prog(_points(shape), backend=backend)
        return
    _check(prog, _points(shape), backend, np.float64)


FLOAT32_SHAPES = ["sphere", "box", "capped_cone", "pyramid", "polygon", "union_smooth",
                  "intersection_exponential", "twist", "repeat_polar", "rotate_param"]


@pytest.mark.parametrize("backend", _evaluators(dtype="float32"))
@pytest.mark.parametrize("name", FLOAT32_SHAPES)
def test_catalogue_float32(backend, name):
    shape = CAT[name]()
    pts = _points(shape, dtype=np.float32)
    pts[3:7] = 0.5  # no coordinates that overflow float32 when squared
    prog = shape.compile()
    ref = prog.value_grad_param_jacobian(pts, backend="numpy")
    got = prog.value_grad_param_jacobian(pts, backend=backend)
    fin = ~np.isinf(pts).any(axis=1)
    for what, g, r in zip(("value", "gradient", "jacobian"), got, ref):
        assert g.dtype == np.float32
        if what != "value":
            g, r = g[fin], r[fin]
        ok = np.isfinite(r) & np.isfinite(g)
        np.testing.assert_array_equal(np.isnan(g), np.isnan(r), err_msg=what)
        np.testing.assert_allclose(g[ok], r[ok], rtol=1e-5, atol=1e-5, err_msg=what)


@pytest.mark.parametrize("backend", EVAL_BACKENDS)
def test_parameter_values_and_2d_points(backend):
    shape = CAT["union3_smooth"]()
    prog = shape.compile()
    pts = _points(shape)
    for r in (0.35, 0.8):
        _close(prog(pts, r=r, backend=backend), prog(pts, r=r, backend="numpy"),
               np.float64, f"{backend} r={r}")
    poly = csdf.polygon([(0, 0), (1, 0), (1, 1), (0.3, 0.6)]).compile()
    p2 = np.random.default_rng(1).uniform(-1, 2, (500, 2))
    _close(poly(p2, backend=backend), poly(p2, backend="numpy"), np.float64, backend)
    g = poly.gradient(p2, backend=backend)
    assert g.shape == (500, 2)
    _close(g, poly.gradient(p2, backend="numpy"), np.float64, backend)
    nanp = prog(pts[:10], r=np.nan, backend=backend)
    assert np.isnan(nanp).all()
    assert prog(np.zeros((0, 3)), backend=backend).shape == (0,)


def _random_case_settings(n):
    return settings(max_examples=n, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


@pytest.mark.parametrize("backend", _evaluators(exclude=("numpy",)))
def test_random_expression_dags(backend):
    n = 12 if backend == "fast" else 60  # each new structure compiles a fast kernel

    @_random_case_settings(n)
    @given(e=expr_dags(max_depth=5, allow_nonfinite=False), seed=st.integers(0, 2**16))
    def check(e, seed):
        prog = compile_expr(e)
        pts = np.random.default_rng(seed).uniform(-3, 3, (257, 3))
        ref = prog.value_grad_param_jacobian(pts, backend="numpy")
        got = prog.value_grad_param_jacobian(pts, backend=backend)
        # ill-conditioned points (tan(exp(exp(x))) at x = 3: tan of 5e8) turn one-ulp
        # differences between math libraries into large ones; compare where nudges of
        # the input move the reference by less than the tolerance: one ulp either way,
        # and a few ulps either way (a one-ulp nudge of x can leave acos(x) where it
        # was, while the libraries' acos differ by an ulp: sin(acos(x) * 1e16))
        stable = np.ones(len(pts), dtype=bool)
        for q in (np.nextafter(pts, np.inf), np.nextafter(pts, -np.inf),
                  pts * (1 + 1e-15), pts * (1 - 1e-15)):
            nudged = prog(q, backend="numpy")
            with np.errstate(invalid="ignore"):
                stable &= ~(np.abs(nudged - ref[0]) > 1e-11 * (1 + np.abs(ref[0])))
            # a value that turns NaN or infinite under a nudge is on an edge too (exp
            # overflowing at the last ulp of its argument, then mod(a, inf))
            stable &= (np.isnan(nudged) == np.isnan(ref[0])) & (
                np.isinf(nudged) == np.isinf(ref[0]))
        ref = tuple(r[stable] for r in ref)
        got = tuple(g[stable] for g in got)
        finite = np.isfinite(ref[0])
        for what, g, r in zip(("value", "gradient", "jacobian"), got, ref):
            if what != "value":  # derivatives where the value is finite (NaN -> NaN)
                assert np.isnan(g[np.isnan(ref[0])]).all()
                g, r = g[finite], r[finite]
                # 0 * inf: a component whose seed is zero may be 0 or NaN (csdf.ops);
                # e.g. d/dx of acos(sin(acos(a))) at a = 0, a parameter-only part the
                # evaluators compute once without tangents
                r = np.where(np.isnan(r) & (g == 0), 0.0, r)
            np.testing.assert_array_equal(np.isnan(g), np.isnan(r), err_msg=what)
            ok = np.isfinite(r)
            np.testing.assert_array_equal(g[~ok & ~np.isnan(r)], r[~ok & ~np.isnan(r)])
            np.testing.assert_allclose(g[ok], r[ok], rtol=1e-9, atol=1e-9, err_msg=what)

    check()


def test_registry_states_every_evaluator():
    """BACKENDS and select are built on the registry; each entry's module has the
    interface of its kind and the capabilities it states."""
    assert BACKENDS == ("auto", "numpy", "interp", "fast")
    assert [e.name for e in registry.point_evaluators()] == list(BACKENDS[1:])
    names = [e.name for e in registry.EVALUATORS]
    assert len(set(names)) == len(names) and {"interval", "glsl"} <= set(names)
    for e in registry.EVALUATORS:
        impl = e.load()
        assert e.description and set(e.dtypes) <= {"float32", "float64"}
        assert isinstance(e.available(), bool)
        if e.kind == "points":
            assert isinstance(impl, registry.PointEvaluator) and e.values
        elif e.kind == "intervals":
            assert isinstance(impl, registry.IntervalEvaluator) and e.intervals
        else:
            assert e.kind == "source" and callable(impl.to_glsl)
    assert registry.get("numpy").available()
    from csdf.backends import select

    for e in registry.point_evaluators():
        if e.available():
            assert select(e.name, 10) is e.load()


def test_auto_backend_choice():
    from csdf.backends import AUTO_MIN_POINTS, fast, numpy_backend, select

    prog = csdf.sphere(csdf.param("r", 1.0)).compile()
    assert select("numpy", 10**7) is numpy_backend
    small = select("auto", 10, csdf.torus(0.3, 0.1).compile())
    assert small is numpy_backend or fast.is_ready(csdf.torus(0.3, 0.1).compile(), "value")
    prog(np.zeros((AUTO_MIN_POINTS, 3)), backend="fast")
    assert select("auto", 10, prog, "value") is fast  # its kernel is ready now
    with pytest.raises(csdf.CsdfError, match="backend must be one of"):
        prog(np.zeros((1, 3)), backend="gpu")


@pytest.mark.parametrize("mode", ["value", "grad", "jac", "all"])
def test_reference_chunking_does_not_change_results(mode):
    """The reference evaluates chunk by chunk; any chunk size (1 point, an odd size, all
    points at once: the whole-array evaluator the benchmark compares against) gives the
    same numbers bit for bit."""
    from csdf.backends import numpy_backend

    r = csdf.param("r", 1.0, 0.5, 1.5)
    c = csdf.cylinder(0.5, 3.0)
    prog = csdf.compile((csdf.sphere(r) & csdf.box(1.5)) - c - c.orient("x") - c.orient("y"))
    pts = np.random.default_rng(3).uniform(-1.2, 1.2, (501, 3))
    pv = prog.param_values(None)
    ref = numpy_backend.evaluate(prog, pts, pv, mode)
    for chunk in (1, 37, len(pts), 10 * len(pts)):
        got = numpy_backend.evaluate(prog, pts, pv, mode, chunk=chunk)
        assert got.keys() == ref.keys()
        for k in ref:
            np.testing.assert_array_equal(got[k], ref[k], err_msg=f"{k}, chunk={chunk}")
    with pytest.raises(ValueError, match="chunk"):
        numpy_backend.evaluate(prog, pts, pv, mode, chunk=0)


def test_a_prefix_op_with_zero_derivative_carries_no_tangent_into_the_kernel():
    """d/da of ``sign(a) / floor(y)`` where ``floor(y) = 0``: ``sign``'s derivative is
    structurally zero (:mod:`csdf.ops`), so the quotient has none by ``a`` and every
    evaluator gives 0. The fast kernel gave NaN (its parameter-only prefix passed
    ``sign(a)``'s explicit zero tangent in, times ``1 / 0``): a CI run's hypothesis
    example, ``abs(abs(a) / (sign(a) / floor(y)))``."""
    from csdf.expr import Y, make, param

    a = param("a", 0.5)
    pts = np.array([[0.0, 0.5, 0.0], [0.0, 1.5, 0.0]])
    for e in (make("div", make("sign", a), make("floor", Y)),
              make("abs", make("div", make("abs", a),
                               make("div", make("sign", a), make("floor", Y))))):
        prog = compile_expr(e)
        ref = prog.value_grad_param_jacobian(pts, backend="numpy")
        for backend in [e.name for e in registry.point_evaluators()
                        if "float64" in e.dtypes and e.name != "numpy" and e.available()]:
            got = prog.value_grad_param_jacobian(pts, backend=backend)
            np.testing.assert_array_equal(got[2], ref[2], err_msg=backend)
            assert np.isfinite(got[2]).all()
