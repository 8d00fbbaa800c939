"""Tests of conservative interval evaluation (``csdf.backends.interval_eval``).

1. Containment (hypothesis): for random expression DAGs over every op and random
   shapes, random boxes (degenerate, straddling 0, huge, infinite) and parameter
   intervals, every non-NaN value the NumPy evaluator computes at points sampled in a
   box (corners, special values, random interior points) lies in the box's interval;
   a box reported empty gives NaN at every sampled point.
2. Per-op ranges checked by hand.
3. Exact SDFs: boxes away from the surface get the right sign.
4. :func:`csdf.compiler.simplify.simplify` gives a valid, shorter program that is
   bit-identical in its box.
5. Errors, and the CSG example over 100k boxes (time printed, not asserted).

``CSDF_FUZZ_EXAMPLES=<n>`` raises every hypothesis test to at least ``n`` examples.
"""

from __future__ import annotations

import math
import os
import time

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import csdf
from csdf.backends.interval_eval import evaluate_intervals
from csdf.compiler import compile_expr
from csdf.compiler.binary import validate
from csdf.compiler.simplify import simplify
from csdf.expr import X, Y, const, make, param

try:  # tests/ as a package or as a plain directory on sys.path
    from . import strategies as S
except ImportError:
    import strategies as S

expr_dags = S.expr_dags
shapes = S.shapes

pytestmark = pytest.mark.filterwarnings("ignore::RuntimeWarning")
_SLOW_OK = [HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much]
_FUZZ = int(os.environ.get("CSDF_FUZZ_EXAMPLES", "0") or 0)


def _settings(n: int):
    """``n`` examples (at least ``CSDF_FUZZ_EXAMPLES`` for long fuzzing runs)."""
    return settings(max_examples=max(n, _FUZZ), deadline=None, suppress_health_check=_SLOW_OK)

PI = math.pi
INF = math.inf
# values worth sampling when they fall inside a box: zeros, integers, poles and extrema
# of the trigonometric functions, domain edges, huge numbers and infinities
SPECIALS = np.array(
    [0.0, -0.0, 1.0, -1.0, 2.0, -2.0, 0.5, -0.5, 3.0, 1e-300, -1e-300, 1e16, -1e16, 1e300,
     -1e300, INF, -INF, 7.0]
    + [k * PI / 2 for k in range(-8, 9)]
)


# ------------------------------------------------------------------------- helpers
def box1(x: tuple[float, float], y: tuple[float, float] = (0.0, 0.0),
         z: tuple[float, float] = (0.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    """One box as ``(1, 3)`` lo and hi arrays."""
    return np.array([[x[0], y[0], z[0]]]), np.array([[x[1], y[1], z[1]]])


def rng_of(prog, **kw) -> tuple[float, float]:
    """``(lo, hi)`` of ``prog`` over the box given as keyword intervals x=, y=, z=."""
    lo, hi = box1(kw.pop("x", (0.0, 0.0)), kw.pop("y", (0.0, 0.0)), kw.pop("z", (0.0, 0.0)))
    ol, oh = evaluate_intervals(prog, lo, hi, **kw)
    return float(ol[0]), float(oh[0])


def axis_samples(rng: np.random.Generator, lo: float, hi: float, n: int) -> np.ndarray:
    """``(n,)`` values in ``[lo, hi]``: both ends, specials inside, random interior."""
    inside = SPECIALS[(SPECIALS >= lo) & (SPECIALS <= hi)]
    cands = [np.array([lo, hi]), inside]
    if math.isfinite(lo) and math.isfinite(hi):
        w = hi - lo
        if math.isfinite(w):
            u = lo + rng.uniform(0.0, 1.0, n) * w
        else:  # width overflows: split at 0
            u = np.concatenate([rng.uniform(lo / 2, 0, n) * 2, rng.uniform(0, hi / 2, n) * 2])
        cands.append(np.clip(u, lo, hi))
    else:
        mid = rng.uniform(-10, 10, n)
        cands.append(np.clip(mid, lo, hi))
        cands.append(np.clip(np.geomspace(1, 1e300, 8) * rng.choice([-1, 1], 8), lo, hi))
    pool = np.concatenate(cands)
    out = rng.choice(pool, n)
    out[:2] = lo, hi
    return out


def sample_box(rng: np.random.Generator, lo: np.ndarray, hi: np.ndarray, n: int) -> np.ndarray:
    """``(n, 3)`` points in the box ``[lo, hi]`` (``(3,)`` each), corners included."""
    cols = [axis_samples(rng, float(lo[k]), float(hi[k]), n) for k in range(3)]
    pts = np.stack(cols, axis=1)
    corners = np.array([[(lo, hi)[(c >> k) & 1][k] for k in range(3)] for c in range(8)])
    return np.concatenate([corners, pts])


def assert_contains(vals: np.ndarray, ol: float, oh: float, what: str) -> None:
    """Every non-NaN value in ``[ol, oh]``; if ``(ol, oh)`` is empty, every value NaN."""
    if math.isnan(ol):
        assert math.isnan(oh)
        assert np.isnan(vals).all(), f"{what}: reported empty but got {vals[~np.isnan(vals)]}"
        return
    ok = np.isnan(vals) | ((vals >= ol) & (vals <= oh))
    assert ok.all(), f"{what}: values {vals[~ok][:5]} outside [{ol!r}, {oh!r}]"


# ------------------------------------------------------------------------- strategies
_finite = st.one_of(
    st.floats(-10.0, 10.0),
    st.sampled_from([float(v) for v in SPECIALS if math.isfinite(v)]),
    st.floats(allow_nan=False, allow_infinity=False),
)


@st.composite
def intervals(draw) -> tuple[float, float]:
    """An interval: a point, a small or large range, one straddling 0, or infinite."""
    kind = draw(st.integers(0, 5))
    if kind == 0:
        v = draw(st.one_of(_finite, st.sampled_from([INF, -INF])))
        return (v, v)
    if kind == 1:
        c = draw(st.floats(-5.0, 5.0))
        w = draw(st.sampled_from([0.0, 1e-12, 1e-3, 0.1, 1.0, 4.0, 10.0]))
        return (c - w, c + w)
    if kind == 2:
        return (-draw(st.floats(0.0, 5.0)), draw(st.floats(0.0, 5.0)))
    if kind == 3:
        a, b = sorted((draw(_finite), draw(_finite)))
        return (a, b)
    if kind == 4:
        a = draw(st.one_of(_finite, st.just(-INF)))
        b = draw(st.one_of(_finite, st.just(INF)))
        return (min(a, b), max(a, b))
    return (-INF, INF)


@st.composite
def boxes(draw, n: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """``n`` boxes as ``(n, 3)`` lo and hi arrays."""
    rows = [[draw(intervals()) for _ in range(3)] for _ in range(n)]
    lo = np.array([[r[k][0] for k in range(3)] for r in rows])
    hi = np.array([[r[k][1] for k in range(3)] for r in rows])
    return lo, hi


@st.composite
def param_ranges(draw, params) -> dict[str, tuple[float, float]]:
    """Intervals for some of ``params`` around their defaults."""
    out = {}
    for p in params:
        kind = draw(st.integers(0, 3))
        if kind == 0:
            continue
        if kind == 1:
            out[p.name] = (p.default, p.default)
        elif kind == 2:
            w = draw(st.floats(0.0, 3.0))
            out[p.name] = (p.default - w, p.default + w)
        else:
            out[p.name] = tuple(sorted((draw(_finite), draw(_finite))))
    return out


def check_program(prog, lo, hi, pint, seed: int, n: int = 48) -> None:
    """Containment over every box for a few parameter settings inside ``pint``."""
    rng = np.random.default_rng(seed)
    ol, oh = evaluate_intervals(prog, lo, hi, param_intervals=pint, empty_as_nan=True)
    assert ol.shape == oh.shape == (lo.shape[0],)
    assert not (np.isnan(ol) ^ np.isnan(oh)).any()
    ne = ~np.isnan(ol)
    assert (ol[ne] <= oh[ne]).all()
    settings_ = [{}]
    if pint:
        settings_ += [{k: v[0] for k, v in pint.items()}, {k: v[1] for k, v in pint.items()}]
        for _ in range(2):
            settings_.append({k: float(rng.choice(axis_samples(rng, a, b, 4)))
                              for k, (a, b) in pint.items()})
    for i in range(lo.shape[0]):
        pts = sample_box(rng, lo[i], hi[i], n)
        for pv in settings_:
            if not pv:  # parameters without an interval are at their defaults
                pv = {k: v[0] for k, v in pint.items()}
            vals = prog(pts, pv, backend="numpy", check_ranges=False)
            assert_contains(vals, ol[i], oh[i], f"box {i} {lo[i]}..{hi[i]} params {pv}")


# ------------------------------------------------------------------------- 1. containment
@_settings(600)
@given(e=expr_dags(), bx=boxes(), data=st.data(), seed=st.integers(0, 2**31))
def test_expr_dag_intervals_contain_samples(e, bx, data, seed):
    prog = compile_expr(e)
    pint = data.draw(param_ranges(prog.params))
    check_program(prog, *bx, pint, seed)


@_settings(600)
@given(
    e=expr_dags(max_depth=4, max_params=0,
                ops=("add", "sub", "mul", "div", "mod", "atan2", "sin", "cos", "tan")),
    bx=boxes(),
    seed=st.integers(0, 2**31),
)
def test_tricky_binary_ops_contain_samples(e, bx, seed):
    check_program(compile_expr(e), *bx, {}, seed)


@_settings(100)
@given(s=shapes(), data=st.data(), seed=st.integers(0, 2**31))
def test_shape_intervals_contain_samples(s, data, seed):
    prog = s.compile()
    rng = np.random.default_rng(seed)
    c = rng.uniform(-2.0, 2.0, (4, 3))
    w = rng.choice([0.0, 0.05, 0.5, 2.0], (4, 1))
    lo, hi = c - w, c + w
    extra_lo, extra_hi = data.draw(boxes(2))
    lo, hi = np.concatenate([lo, extra_lo]), np.concatenate([hi, extra_hi])
    pint = data.draw(param_ranges(prog.params))
    check_program(prog, lo, hi, pint, seed, n=32)


@_settings(60)
@given(e=expr_dags(max_depth=5), seed=st.integers(0, 2**31))
def test_many_boxes_match_one_at_a_time(e, seed):
    """Chunked evaluation over M boxes equals evaluating each box alone."""
    prog = compile_expr(e)
    rng = np.random.default_rng(seed)
    c = rng.uniform(-3, 3, (50, 3))
    w = rng.uniform(0, 1, (50, 3))
    ol, oh = evaluate_intervals(prog, c - w, c + w)
    for i in range(0, 50, 7):
        a, b = evaluate_intervals(prog, (c - w)[i:i + 1], (c + w)[i:i + 1])
        np.testing.assert_array_equal([ol[i], oh[i]], [a[0], b[0]])


def test_chunking(monkeypatch):
    from csdf.backends import interval_eval

    prog = (csdf.sphere(1.0) | csdf.box(0.5).translate((1.0, 0.0, 0.0))).compile()
    rng = np.random.default_rng(1)
    c = rng.uniform(-2, 2, (1000, 3))
    ref = evaluate_intervals(prog, c - 0.1, c + 0.1)
    monkeypatch.setattr(interval_eval, "CHUNK", 64)
    got = evaluate_intervals(prog, c - 0.1, c + 0.1)
    np.testing.assert_array_equal(ref, got)


# ------------------------------------------------------------------------- 2. per op
def unary(op: str):
    return compile_expr(make(op, X))


def binary(op: str, b=None):
    return compile_expr(make(op, X, Y if b is None else const(b)))


def close(got: tuple[float, float], want: tuple[float, float], tol: float = 1e-12) -> None:
    """``got`` contains ``want`` and is at most ``tol`` (relative) wider."""
    for g, w, side in ((got[0], want[0], -1), (got[1], want[1], 1)):
        if math.isinf(w) or math.isnan(w):
            assert g == w or (math.isnan(g) and math.isnan(w)), (got, want)
        else:
            assert side * (g - w) >= 0, (got, want)  # never narrower than the true range
            assert abs(g - w) <= tol * max(1.0, abs(w)), (got, want)


def test_add_sub_neg():
    close(rng_of(binary("add"), x=(1, 2), y=(3, 4)), (4, 6))
    close(rng_of(binary("sub"), x=(1, 2), y=(3, 4)), (-3, -1))
    close(rng_of(unary("neg"), x=(1, 2)), (-2, -1))
    # inf - inf is NaN: [inf, inf] + [-inf, 5] has the non-NaN values {inf}... and 5 + inf
    close(rng_of(binary("add"), x=(INF, INF), y=(-INF, 5)), (INF, INF))
    close(rng_of(binary("add"), x=(-INF, INF), y=(-INF, INF)), (-INF, INF))
    lo, hi = rng_of(binary("sub"), x=(INF, INF), y=(INF, INF), empty_as_nan=True)
    assert math.isnan(lo) and math.isnan(hi)
    close(rng_of(compile_expr(make("sub", X, X)), x=(-3, 7)), (0, 0))


def test_mul_div():
    close(rng_of(binary("mul"), x=(-1, 2), y=(3, 4)), (-4, 8))
    close(rng_of(binary("mul"), x=(-1, 2), y=(-3, 4)), (-6, 8))
    # 0 * inf is NaN; values near such a corner still need covering
    close(rng_of(binary("mul"), x=(0, 0), y=(-INF, INF)), (0, 0))
    close(rng_of(binary("mul"), x=(0, 1), y=(1, INF)), (0, INF))
    close(rng_of(binary("mul"), x=(-1, 0), y=(1, INF)), (-INF, 0))
    close(rng_of(binary("mul"), x=(0, 2), y=(INF, INF)), (INF, INF))  # 0 * inf is NaN
    close(rng_of(binary("div"), x=(1, 2), y=(2, 4)), (0.25, 1))
    close(rng_of(binary("div"), x=(-1, 2), y=(-4, -2)), (-1, 0.5))
    close(rng_of(binary("div"), x=(1, 2), y=(-1, 1)), (-INF, INF))
    close(rng_of(binary("div"), x=(1, 2), y=(0, 1)), (-INF, INF))  # -0.0 is in [0, 1]
    close(rng_of(binary("div"), x=(1, INF), y=(1, INF)), (0, INF))
    close(rng_of(compile_expr(make("div", X, X)), x=(-3, 7)), (1, 1))


def test_abs_square_sqrt():
    close(rng_of(unary("abs"), x=(-3, 2)), (0, 3))
    close(rng_of(unary("abs"), x=(-3, -2)), (2, 3))
    close(rng_of(unary("square"), x=(-3, 2)), (0, 9))
    close(rng_of(unary("square"), x=(2, 3)), (4, 9))
    close(rng_of(unary("sqrt"), x=(-4, 9)), (0, 3))
    close(rng_of(unary("sqrt"), x=(4, INF)), (2, INF))
    lo, hi = rng_of(unary("sqrt"), x=(-4, -1), empty_as_nan=True)
    assert math.isnan(lo) and math.isnan(hi)
    assert rng_of(unary("sqrt"), x=(-4, -1)) == (-INF, INF)  # default: nothing known


def test_sin_cos_tan():
    close(rng_of(unary("sin"), x=(0, PI)), (0, 1))
    close(rng_of(unary("sin"), x=(0.1, 0.2)), (math.sin(0.1), math.sin(0.2)))
    close(rng_of(unary("sin"), x=(2, 4)), (math.sin(4), math.sin(2)))
    close(rng_of(unary("sin"), x=(4, 5)), (-1, math.sin(4)))
    close(rng_of(unary("sin"), x=(0, 2 * PI + 1)), (-1, 1))
    close(rng_of(unary("sin"), x=(-INF, 0)), (-1, 1))
    close(rng_of(unary("sin"), x=(1e300, 1e300)), (-1, 1))  # loose but valid
    close(rng_of(unary("cos"), x=(-0.5, 0.5)), (math.cos(0.5), 1))
    close(rng_of(unary("cos"), x=(1, 2)), (math.cos(2), math.cos(1)))
    close(rng_of(unary("cos"), x=(3, 3.5)), (-1, max(math.cos(3), math.cos(3.5))))
    close(rng_of(unary("cos"), x=(100.0, 100.5)), (math.cos(100.0), math.cos(100.5)))
    close(rng_of(unary("tan"), x=(-1, 1)), (math.tan(-1), math.tan(1)))
    close(rng_of(unary("tan"), x=(2, 3)), (math.tan(2), math.tan(3)))
    close(rng_of(unary("tan"), x=(1, 2)), (-INF, INF))  # contains the pole pi/2
    lo, hi = rng_of(unary("sin"), x=(INF, INF), empty_as_nan=True)
    assert math.isnan(lo) and math.isnan(hi)


def test_inverse_trig_exp_log():
    close(rng_of(unary("asin"), x=(-2, 0.5)), (-PI / 2, math.asin(0.5)))
    close(rng_of(unary("acos"), x=(0, 2)), (0, PI / 2))
    close(rng_of(unary("acos"), x=(-1, 1)), (0, PI))
    lo, hi = rng_of(unary("asin"), x=(2, 3), empty_as_nan=True)
    assert math.isnan(lo) and math.isnan(hi)
    close(rng_of(unary("atan"), x=(-INF, INF)), (-PI / 2, PI / 2))
    close(rng_of(unary("atan"), x=(0, 1)), (0, PI / 4))
    close(rng_of(unary("exp"), x=(0, 1)), (1, math.e))
    close(rng_of(unary("exp"), x=(-INF, 0)), (0, 1))
    close(rng_of(unary("exp"), x=(1000, 1000)), (INF, INF))
    close(rng_of(unary("log"), x=(0, math.e)), (-INF, 1))
    close(rng_of(unary("log"), x=(-1, 1)), (-INF, 0))
    close(rng_of(unary("log"), x=(1, INF)), (0, INF))
    lo, hi = rng_of(unary("log"), x=(-2, -1), empty_as_nan=True)
    assert math.isnan(lo) and math.isnan(hi)


def test_floor_step_sign_min_max():
    assert rng_of(unary("floor"), x=(0.5, 2.5)) == (0, 2)
    assert rng_of(unary("floor"), x=(-INF, -0.5)) == (-INF, -1)
    assert rng_of(unary("step"), x=(-1, 1)) == (0, 1)
    assert rng_of(unary("step"), x=(0, 1)) == (1, 1)
    assert rng_of(unary("step"), x=(-2, -1)) == (0, 0)
    assert rng_of(unary("sign"), x=(-2, 0)) == (-1, 0)
    assert rng_of(unary("sign"), x=(1, 2)) == (1, 1)
    assert rng_of(unary("sign"), x=(-INF, INF)) == (-1, 1)
    assert rng_of(binary("min"), x=(0, 2), y=(1, 3)) == (0, 2)
    assert rng_of(binary("max"), x=(0, 2), y=(1, 3)) == (1, 3)
    assert rng_of(binary("min"), x=(0, 2), y=(-INF, -5)) == (-INF, -5)


def test_atan2():
    close(rng_of(binary("atan2"), x=(1, 2), y=(1, 2)),  # atan2(y=x slot, x=y slot)
          (math.atan2(1, 2), math.atan2(2, 1)))
    close(rng_of(binary("atan2"), x=(-1, 1), y=(1, 2)), (math.atan2(-1, 1), PI / 4))
    close(rng_of(binary("atan2"), x=(1, 1), y=(-1, 1)), (PI / 4, 3 * PI / 4))
    close(rng_of(binary("atan2"), x=(-2, -1), y=(-1, 1)), (-3 * PI / 4, -PI / 4))
    # touching the branch cut (y = 0, x < 0) or the origin: the full range
    close(rng_of(binary("atan2"), x=(-1, 1), y=(-2, -1)), (-PI, PI))
    close(rng_of(binary("atan2"), x=(0, 1), y=(-1, 1)), (-PI, PI))
    close(rng_of(binary("atan2"), x=(0, 0), y=(0, 0)), (-PI, PI))
    close(rng_of(binary("atan2"), x=(1, INF), y=(1, INF)), (0, PI / 2))


def test_mod():
    close(rng_of(binary("mod", 3.0), x=(3.5, 5)), (0.5, 2))
    close(rng_of(binary("mod", 3.0), x=(-2, -1)), (1, 2))
    close(rng_of(binary("mod", -3.0), x=(3.5, 5)), (-2.5, -1))
    lo, hi = rng_of(binary("mod", 3.0), x=(2, 4))  # across a period boundary
    assert -1e-12 < lo <= 0 and 3 <= hi < 3 + 1e-12
    lo, hi = rng_of(binary("mod", -3.0), x=(2, 4))
    assert -3 - 1e-12 < lo <= -3 and 0 <= hi < 1e-12
    lo, hi = rng_of(binary("mod"), x=(0, 10), y=(2, 3))
    assert -1e-12 < lo <= 0 and 3 <= hi < 3 + 1e-12
    close(rng_of(binary("mod"), x=(0, 10), y=(-1, 1)), (-INF, INF))
    close(rng_of(binary("mod", 1e-300), x=(1e10, 1e10)), (-INF, INF))  # a/b overflows
    close(rng_of(compile_expr(make("mod", X, X)), x=(-3, 7)), (0, 0))


def test_mod_rounding_huge_quotient():
    """mod(a, 3) for huge a is not in [0, 3) as evaluated; the interval still holds it."""
    prog = binary("mod", 3.0)
    rng = np.random.default_rng(0)
    a = rng.uniform(-1e20, 1e20, 10_000)
    vals = prog(np.stack([a, 0 * a, 0 * a], axis=1), backend="numpy")
    assert ((vals < 0) | (vals >= 3)).any()  # e.g. mod(7.78e18, 3) evaluates to 1024
    lo, hi = evaluate_intervals(prog, np.array([[-1e20, 0, 0]]), np.array([[1e20, 0, 0]]))
    assert ((vals >= lo[0]) & (vals <= hi[0])).all(), (vals, lo, hi)


def test_parameters_as_points_and_intervals():
    r = param("r", 1.0, 0.5, 2.0)
    prog = csdf.sphere(r).compile()
    lo, hi = np.array([[3.0, 0, 0]]), np.array([[4.0, 0, 0]])
    close(tuple(float(v[0]) for v in evaluate_intervals(prog, lo, hi)), (2, 3))
    close(tuple(float(v[0]) for v in evaluate_intervals(prog, lo, hi, {"r": 1.5})), (1.5, 2.5))
    got = evaluate_intervals(prog, lo, hi, param_intervals={"r": (0.5, 2.0)})
    close((float(got[0][0]), float(got[1][0])), (1.0, 3.5))
    lo_nan, hi_nan = evaluate_intervals(prog, lo, hi, {"r": math.nan}, empty_as_nan=True)
    assert np.isnan(lo_nan).all() and np.isnan(hi_nan).all()


def test_fixed_slot_output_and_2d():
    assert rng_of(compile_expr(X), x=(-1, 2)) == (-1, 2)
    assert rng_of(compile_expr(const(4.5)), x=(-1, 2)) == (4.5, 4.5)
    prog = csdf.circle(1.0).compile()
    assert prog.dim == 2
    ol, oh = evaluate_intervals(prog, np.array([[3.0, 0.0]]), np.array([[4.0, 0.0]]))
    close((float(ol[0]), float(oh[0])), (2, 3))
    ol3, oh3 = evaluate_intervals(prog, np.array([[3.0, 0.0, 9.0]]), np.array([[4.0, 0.0, 9.0]]))
    assert (ol3[0], oh3[0]) == (ol[0], oh[0])


def test_nan_boxes_are_empty():
    prog = csdf.sphere(1.0).compile()
    lo = np.array([[0.0, 0, 0], [np.nan, 0, 0]])
    hi = np.array([[1.0, 0, 0], [1.0, 0, 0]])
    ol, oh = evaluate_intervals(prog, lo, hi, empty_as_nan=True)
    assert not np.isnan(ol[0]) and np.isnan(ol[1]) and np.isnan(oh[1])
    ol, oh = evaluate_intervals(prog, lo, hi)
    assert (ol[1], oh[1]) == (-INF, INF)
    assert evaluate_intervals(prog, np.zeros((0, 3)), np.zeros((0, 3)))[0].shape == (0,)


# ------------------------------------------------------------------------- 3. exact SDFs
def csg_example() -> csdf.Shape:
    cyl = csdf.cylinder(0.5, 3.0)
    return (csdf.sphere(1) & csdf.box(1.5)) - cyl - cyl.orient("x") - cyl.orient("y")


@pytest.mark.parametrize("shape", [csdf.sphere(1.0), csdf.box(1.0), csdf.box((0.5, 1, 2))])
def test_exact_sdf_signs(shape):
    prog = shape.compile()
    far = np.array([[3.0, 3.0, 3.0], [-5.0, -0.1, -0.1], [2.5, -9.0, 0.0]])
    ol, oh = evaluate_intervals(prog, far, far + 0.5)
    assert (ol > 0).all()
    ol, oh = evaluate_intervals(prog, np.full((1, 3), -0.1), np.full((1, 3), 0.1))
    assert (oh < 0).all()
    edge = shape.bounds[1][0]  # where the surface crosses the +x axis
    lo, hi = np.array([[edge - 0.1, -0.1, -0.1]]), np.array([[edge + 0.1, 0.1, 0.1]])
    ol, oh = evaluate_intervals(prog, lo, hi)
    assert ol[0] < 0 < oh[0]
    # an exact SDF changes by at most the box diagonal over the box: a far box's lower
    # bound is no worse than the distance to the box centre minus the half-diagonal
    c = far + 0.25
    d = prog(c, backend="numpy")
    ol, _ = evaluate_intervals(prog, far, far + 0.5)
    assert (ol >= d - 0.25 * math.sqrt(3) * 3).all()


def test_grid_classification_csg():
    prog = csg_example().compile()
    n = 16
    edges = np.linspace(-2.0, 2.0, n + 1)
    g = np.stack(np.meshgrid(edges[:-1], edges[:-1], edges[:-1], indexing="ij"), -1)
    lo = g.reshape(-1, 3)
    hi = lo + (edges[1] - edges[0])
    ol, oh = evaluate_intervals(prog, lo, hi)
    rng = np.random.default_rng(0)
    pts = lo[:, None, :] + rng.uniform(0, 1, (lo.shape[0], 16, 3)) * (hi - lo)[:, None, :]
    vals = prog(pts.reshape(-1, 3), backend="numpy").reshape(lo.shape[0], 16)
    assert ((vals >= ol[:, None]) & (vals <= oh[:, None])).all()
    assert (ol > 0).mean() > 0.5  # most of the grid is recognised as empty
    assert ((ol > 0) | (oh < 0) | ((vals.min(1) <= 0.2) & (vals.max(1) >= -0.2))).all()


def test_performance_csg_100k_boxes():
    prog = csg_example().compile()
    rng = np.random.default_rng(0)
    c = rng.uniform(-2, 2, (100_000, 3))
    w = rng.uniform(0, 0.05, (100_000, 1))
    evaluate_intervals(prog, c[:10] - w[:10], c[:10] + w[:10])
    t0 = time.perf_counter()
    ol, oh = evaluate_intervals(prog, c - w, c + w)
    dt = time.perf_counter() - t0
    print(f"\ninterval evaluation of {len(prog)} instructions over 100k boxes: {dt * 1e3:.1f} ms")
    v = prog(c, backend="numpy")
    assert ((v >= ol) & (v <= oh)).all()


# ------------------------------------------------------------------------- 4. simplify
def assert_same_values(a: np.ndarray, b: np.ndarray) -> None:
    """Bit-identical apart from NaN payloads (signs of zero compared too)."""
    both_nan = np.isnan(a) & np.isnan(b)
    same = (a == b) & (np.signbit(a) == np.signbit(b))
    assert (both_nan | same).all(), (a[~(both_nan | same)][:5], b[~(both_nan | same)][:5])


def test_simplify_csg_example():
    prog = csg_example().compile()
    rng = np.random.default_rng(0)
    shortened = 0
    for lo in ([1.2, 1.2, 1.2], [-0.3, -0.3, 0.8], [0.6, 0.6, -0.1], [-2.0, -2.0, -2.0]):
        lo = np.array(lo)
        hi = lo + np.array([0.3, 0.3, 0.3]) if lo[0] > -2 else np.full(3, 2.0)
        small = simplify(prog, lo, hi)
        validate(small)
        assert Program_roundtrip(small)
        assert len(small) <= len(prog)
        shortened += len(small) < len(prog)
        pts = sample_box(rng, lo, hi, 200)
        assert_same_values(prog(pts, backend="numpy"), small(pts, backend="numpy"))
    assert shortened >= 3


def Program_roundtrip(p) -> bool:  # noqa: N802 - reads as a predicate
    return csdf.Program.from_bytes(p.to_bytes()) == p


@_settings(300)
@given(e=expr_dags(), bx=boxes(1), data=st.data(), seed=st.integers(0, 2**31))
def test_simplify_agrees_in_box(e, bx, data, seed):
    prog = compile_expr(e)
    lo, hi = bx[0][0], bx[1][0]
    pint = data.draw(param_ranges(prog.params))
    small = simplify(prog, lo, hi, param_intervals=pint)
    validate(small)
    assert len(small) <= len(prog)
    rng = np.random.default_rng(seed)
    pts = sample_box(rng, lo, hi, 48)
    pv = {k: v[0] for k, v in pint.items()}
    kw = {"backend": "numpy", "check_ranges": False}  # the intervals may leave the ranges
    assert_same_values(prog(pts, pv, **kw), small(pts, pv, **kw))
    if pint:
        pv = {k: v[1] for k, v in pint.items()}
        assert_same_values(prog(pts, pv, **kw), small(pts, pv, **kw))


@_settings(60)
@given(s=shapes(), seed=st.integers(0, 2**31))
def test_simplify_shapes(s, seed):
    prog = s.compile()
    rng = np.random.default_rng(seed)
    lo = rng.uniform(-2, 2, 3)
    hi = lo + rng.choice([0.0, 0.1, 0.5], 3)
    small = simplify(prog, lo, hi)
    pts = sample_box(rng, lo, hi, 64)
    assert_same_values(prog(pts, backend="numpy"), small(pts, backend="numpy"))
    from csdf.backends import interp

    if interp.available():  # the simplified tape runs on the other evaluators too
        assert_same_values(prog(pts, backend="interp"), small(pts, backend="interp"))


# ------------------------------------------------------------------------- 5. errors
def test_errors():
    r = param("r", 1.0)
    prog = csdf.sphere(r).compile()
    lo, hi = np.zeros((1, 3)), np.ones((1, 3))
    with pytest.raises(csdf.ParamError, match="r"):
        evaluate_intervals(prog, lo, hi, {"nope": 1.0})
    with pytest.raises(csdf.ParamError, match="this shape's parameters: r"):
        evaluate_intervals(prog, lo, hi, param_intervals={"nope": (0, 1)})
    with pytest.raises(csdf.ParamError, match="lo <= hi"):
        evaluate_intervals(prog, lo, hi, param_intervals={"r": (2, 1)})
    with pytest.raises(csdf.ParamError, match="lo <= hi"):
        evaluate_intervals(prog, lo, hi, param_intervals={"r": (math.nan, 1)})
    with pytest.raises(csdf.ParamError, match="pair"):
        evaluate_intervals(prog, lo, hi, param_intervals={"r": 1.0})
    with pytest.raises(csdf.ParamError, match="both"):
        evaluate_intervals(prog, lo, hi, {"r": 1.0}, {"r": (0, 1)})
    with pytest.raises(csdf.CsdfError, match="lo <= hi"):
        evaluate_intervals(prog, hi, lo)
    with pytest.raises(csdf.CsdfError, match="shape"):
        evaluate_intervals(prog, np.zeros(3), np.ones(3))
    with pytest.raises(csdf.CsdfError, match="differ"):
        evaluate_intervals(prog, np.zeros((2, 3)), np.ones((1, 3)))
    with pytest.raises(csdf.CsdfError, match="NaN"):
        simplify(prog, [0, 0, math.nan], [1, 1, 1])
