"""Region-pruned evaluation (``csdf.backends.pruned``, ``csdf.backends.tape_kernels``).

Properties: the scalar interval rules of the kernels agree with :mod:`csdf.interval`;
a register tape shortened for a box, and again for a sub-box, gives the ``'interp'``
backend's values bit for bit (NaN where it gives NaN) at every point sampled in the
box, with the same gradients; the cell evaluator of the field layer and the compiled
raster agree with brute force; the field layer picks pruning only for long programs.
"""

from __future__ import annotations

import importlib
import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import csdf
from csdf.backends import pruned
from csdf.backends import tape_kernels as TK
from csdf.compiler import compile_expr
from csdf.expr import atan2, cos, param
from csdf.interval import RULES, SAME_OPERAND_RULES
from csdf.ops import OPS_BY_CODE

try:  # tests/ as a package or as a plain directory on sys.path
    from . import strategies as S
    from .test_simplify import _settings, _sub_box, assert_same_values, boxes, sample_box
except ImportError:
    import strategies as S
    from test_simplify import _settings, _sub_box, assert_same_values, boxes, sample_box

pytestmark = pytest.mark.filterwarnings("ignore::RuntimeWarning")
INF = math.inf
_ENDS = [-INF, -1e300, -7.5, -math.pi, -1.0, -0.25, 0.0, 1e-300, 0.5, 1.0, 1.5, math.pi,
         4.0, 1e12, 1e300, INF]


_LIBRARY = {"sin", "cos", "tan", "asin", "acos", "atan", "atan2", "exp", "log"}


def _intervals() -> list[tuple[float, float]]:
    out = [(a, b) for a in _ENDS for b in _ENDS if a <= b]
    return out + [(math.nan, math.nan)]


@pytest.mark.parametrize("code", sorted(OPS_BY_CODE))
def test_kernel_interval_rules_match_the_interval_module(code):
    name = OPS_BY_CODE[code].name
    ivs = _intervals()
    rng = np.random.default_rng(code)
    pairs = [(a, b) for a in ivs for b in (ivs if OPS_BY_CODE[code].arity == 2 else [ivs[0]])]
    pick = rng.choice(len(pairs), min(len(pairs), 3000), replace=False)
    for i in pick:
        (alo, ahi), (blo, bhi) = pairs[i]
        with np.errstate(all="ignore"):
            if OPS_BY_CODE[code].arity == 1:
                want = RULES[name](np.array([alo]), np.array([ahi]))
            else:
                want = RULES[name](np.array([alo]), np.array([ahi]), np.array([blo]),
                                   np.array([bhi]))
        got = TK.interval(code, alo, ahi, blo, bhi, False)
        for g, w in zip(got, want):
            # library functions (Numba's libm vs NumPy's) may differ by an ulp or two;
            # both are widened by 16 ulps
            ok = (math.isnan(g) and math.isnan(w[0])) or g == w[0] or (
                name in _LIBRARY and abs(g - w[0]) <= 1e-14 * abs(w[0]))
            assert ok, f"{name}({alo, ahi}, {blo, bhi}): {got} != {(want[0][0], want[1][0])}"
    if name in SAME_OPERAND_RULES:
        for alo, ahi in ivs:
            with np.errstate(all="ignore"):
                want = SAME_OPERAND_RULES[name](np.array([alo]), np.array([ahi]))
            got = TK.interval(code, alo, ahi, alo, ahi, True)
            for g, w in zip(got, want):
                assert (math.isnan(g) and math.isnan(w[0])) or g == w[0], (name, alo, ahi)


def _eval_tape(pool: pruned.TapePool, t: int, pts: np.ndarray, grad: bool = False):
    """Values (and gradients) of pool tape ``t`` at every point."""
    n = len(pts)
    out = np.empty(n)
    g = np.empty((n, 3))
    TK.eval_cells(pool.code, pool.imm, pool.start, pool.length, pool.out, pool.regs,
                  np.array([t], np.int64), np.arange(n, dtype=np.int64),
                  np.array([0, n], np.int64), np.ascontiguousarray(pts), out, g, grad, 64,
                  0, 1)
    return (out, g) if grad else out


def _check(prog, lo, hi, seed):
    rng = np.random.default_rng(seed)
    pv = prog.param_values({}, check_ranges=False)
    tape = pruned.RegTape(prog, pv)
    pool = pruned.TapePool(tape.code, tape.imm, tape.out, tape.n_regs)
    t1, flo, fhi = pool.shorten(np.zeros(1, np.int64), lo[None], hi[None])
    lo2, hi2 = _sub_box(rng, lo, hi)
    t2, _, _ = pool.shorten(t1, lo2[None], hi2[None])
    assert pool.length[t2[0]] <= pool.length[t1[0]] <= len(tape.code)
    pts1 = sample_box(rng, lo, hi, 40)
    pts2 = sample_box(rng, lo2, hi2, 40)
    kw = {"backend": "interp", "check_ranges": False}
    full1 = prog(pts1, **kw)
    assert_same_values(full1, _eval_tape(pool, 0, pts1), "whole tape")
    assert_same_values(full1, _eval_tape(pool, int(t1[0]), pts1), "box")
    assert_same_values(prog(pts2, **kw), _eval_tape(pool, int(t2[0]), pts2), "sub-box")
    with np.errstate(invalid="ignore"):
        ok = ~np.isnan(full1)
        assert np.all((full1[ok] >= flo[0]) & (full1[ok] <= fhi[0])), "interval"
    # gradients of the shortened tape: the interpreter's (finite points)
    fin = np.isfinite(pts2).all(axis=1)
    if fin.any():
        v, g = _eval_tape(pool, int(t2[0]), pts2[fin], grad=True)
        gref = prog.gradient(pts2[fin], **kw)
        np.testing.assert_array_equal(np.isnan(g), np.isnan(gref))
        both = np.isfinite(g) & np.isfinite(gref)
        np.testing.assert_allclose(g[both], gref[both], rtol=1e-12, atol=0)


@_settings(150)
@given(e=S.expr_dags(), bx=boxes(), seed=st.integers(0, 2**31))
def test_shortened_tapes_of_expressions_are_bit_identical(e, bx, seed):
    _check(compile_expr(e), *bx, seed)


@_settings(40)
@given(s=S.shapes(), seed=st.integers(0, 2**31))
def test_shortened_tapes_of_shapes_are_bit_identical(s, seed):
    prog = s.compile()
    b = prog.bounds
    if b is None or not np.isfinite(b).all() or (b[0] > b[1]).any():
        lo, hi = np.full(3, -2.0), np.full(3, 2.0)
    else:
        lo, hi = b[0] - 0.1, b[1] + 0.1
    _check(prog, lo, hi, seed)


def test_long_programs_are_pruned_and_agree_with_the_interpreter(monkeypatch):
    F = importlib.import_module("csdf.field")  # (csdf.field is the user-field function)

    monkeypatch.setattr(F, "PRUNE_MIN_INSTRUCTIONS", 100)
    prog = csdf.zoo.clutter(12).compile()
    fld = csdf.as_field(prog)
    assert fld.pruned()
    rng = np.random.default_rng(3)
    b = prog.bounds
    pts = rng.uniform(b[0] - 0.5, b[1] + 0.5, (5000, 3))  # some outside the cells
    pts[0] = np.nan
    assert_same_values(prog(pts, backend="interp"), fld.value(pts), "values")
    v, g = fld.value_and_grad(pts)
    gref = prog.gradient(pts, backend="interp")
    np.testing.assert_allclose(g, gref, rtol=1e-12, atol=0)
    assert np.isnan(g[0]).all() and np.isnan(v[0])
    lo = rng.uniform(b[0], b[1], (300, 3))
    hi = lo + rng.uniform(0, 0.5, (300, 3))
    flo, fhi = fld.intervals(lo, hi)
    wlo, whi = importlib.import_module("csdf.field").evaluate_intervals(prog, lo, hi)
    assert np.all(flo >= wlo) and np.all(fhi <= whi)  # as tight or tighter
    for i in range(0, 300, 30):  # and still bounds
        p = rng.uniform(lo[i], hi[i], (50, 3))
        f = prog(p, backend="interp")
        assert np.all((f >= flo[i]) & (f <= fhi[i]))
    # meshes: the same vertices as without pruning (the unpruned one on the reference
    # mesher, so only the set of vertices is compared)
    m1 = csdf.mesh(prog, resolution=40, check_thin=False)
    monkeypatch.setattr(F, "PRUNE_MIN_INSTRUCTIONS", 10**9)
    monkeypatch.setattr(F, "FAST_MAX_INSTRUCTIONS", 100)
    m2 = csdf.mesh(prog, resolution=40, check_thin=False)
    a = np.unique(np.round(m1.vertices, 9), axis=0)
    z = np.unique(np.round(m2.vertices, 9), axis=0)
    assert a.shape == z.shape and np.allclose(a, z, atol=1e-8)


def test_policy_long_programs_are_not_compiled():
    F = importlib.import_module("csdf.field")  # (csdf.field is the user-field function)

    assert F.choose_backend("auto", None, F.FAST_MAX_INSTRUCTIONS + 1) == "interp"
    assert F.choose_backend("auto", None, 10) == "fast"
    assert not csdf.as_field(csdf.sphere(1)).pruned()  # short: the compiled kernels


@pytest.mark.parametrize("values", [False, True])
def test_compiled_raster_matches_brute_force(values):
    shape = (csdf.circle(0.6) | csdf.rectangle([0.3, 0.9]).translate([0.5, 0])) \
        - csdf.circle(0.2)
    prog = shape.compile()
    w, h = 97, 61
    xs = -1 + (np.arange(w) + 0.5) * (2 / w)
    ys = 1 - (np.arange(h) + 0.5) * (2 / h)
    gx, gy = np.meshgrid(xs, ys)
    ref = prog(np.stack([gx.ravel(), gy.ravel()], 1), backend="interp").reshape(h, w)
    for leaf in (1, 4, 16):
        img, stats = pruned.raster_image(prog, prog.param_values({}), xs, ys, values, leaf)
        if values:
            assert_same_values(ref, img, f"leaf {leaf}")
        else:
            np.testing.assert_array_equal(img, ref < 0)
        assert stats["levels"] >= 1


def test_a_tape_folds_parameter_only_terms_as_the_interpreter_does():
    """NumPy's ``arctan2`` and libm's differ in the last bit for this parameter value; the
    register tape folds the parameter-only prefix with the interpreter's own rules."""
    a = param("a", 3.158535541215322)
    prog = compile_expr(atan2(a, cos(a) - a))
    tape = pruned.RegTape(prog, prog.param_values({}, check_ranges=False))
    pool = pruned.TapePool(tape.code, tape.imm, tape.out, tape.n_regs)
    pts = np.zeros((2, 3))
    assert_same_values(prog(pts, backend="interp", check_ranges=False),
                       _eval_tape(pool, 0, pts), "parameter-only atan2")
