"""Tape simplification (``csdf.compiler.simplify``) applied recursively.

The mesher and tracer will descend an octree, simplifying each child region starting
from its parent's shortened tape. Properties: a simplified program is a valid program
that can be simplified again; at every point of a box (every point of the sub-box for
the second step) and every parameter value in its interval, each simplified program
gives the full program's float64 values bit for bit (NaN where it gives NaN; NaN
payloads are not compared), with the reference (NumPy) backend.

``CSDF_FUZZ_EXAMPLES=<n>`` raises every hypothesis test to at least ``n`` examples.
"""

from __future__ import annotations

import math
import os

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import csdf
from csdf.compiler import compile_expr
from csdf.compiler.binary import validate
from csdf.compiler.simplify import simplify

try:  # tests/ as a package or as a plain directory on sys.path
    from . import strategies as S
except ImportError:
    import strategies as S

pytestmark = pytest.mark.filterwarnings("ignore::RuntimeWarning")
_SLOW_OK = [HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much]
_FUZZ = int(os.environ.get("CSDF_FUZZ_EXAMPLES", "0") or 0)
INF = math.inf
# values worth sampling when they fall inside a box
_SPECIALS = np.array([0.0, -0.0, 1.0, -1.0, 0.5, -0.5, 2.0, 3.0, math.pi / 2, -math.pi / 2,
                      1e-300, 1e300, -1e300, INF, -INF])


def _settings(n: int):
    return settings(max_examples=max(n, _FUZZ), deadline=None, suppress_health_check=_SLOW_OK)


def assert_same_values(a: np.ndarray, b: np.ndarray, what: str) -> None:
    """Bit-identical apart from NaN payloads (signs of zero compared too)."""
    both_nan = np.isnan(a) & np.isnan(b)
    same = (a == b) & (np.signbit(a) == np.signbit(b))
    ok = both_nan | same
    assert ok.all(), f"{what}: {a[~ok][:5]} != {b[~ok][:5]}"


def axis_samples(rng: np.random.Generator, lo: float, hi: float, n: int) -> np.ndarray:
    """``(n,)`` values in ``[lo, hi]``: both ends, specials inside, random interior."""
    pool = [np.array([lo, hi]), _SPECIALS[(_SPECIALS >= lo) & (_SPECIALS <= hi)]]
    if math.isfinite(lo) and math.isfinite(hi) and math.isfinite(hi - lo):
        pool.append(lo + rng.uniform(0.0, 1.0, n) * (hi - lo))
    else:
        pool.append(rng.uniform(-10.0, 10.0, n))
        pool.append(np.geomspace(1.0, 1e300, 6) * rng.choice([-1.0, 1.0], 6))
    vals = np.clip(np.concatenate(pool), lo, hi)
    out = rng.choice(vals, n)
    out[:2] = lo, hi
    return out


def sample_box(rng: np.random.Generator, lo: np.ndarray, hi: np.ndarray, n: int) -> np.ndarray:
    """``(n + 8, 3)`` points of the box ``[lo, hi]`` (``(3,)`` each), corners first."""
    corners = np.array([[(lo, hi)[(c >> k) & 1][k] for k in range(3)] for c in range(8)])
    cols = [axis_samples(rng, float(lo[k]), float(hi[k]), n) for k in range(3)]
    return np.concatenate([corners, np.stack(cols, axis=1)])


@st.composite
def intervals(draw) -> tuple[float, float]:
    """A point, a small or large range, one straddling 0, or (half-)infinite."""
    kind = draw(st.integers(0, 4))
    if kind == 0:
        v = draw(st.floats(-5.0, 5.0))
        return (v, v)
    if kind == 1:
        c = draw(st.floats(-5.0, 5.0))
        w = draw(st.sampled_from([1e-12, 1e-3, 0.1, 1.0, 4.0, 10.0]))
        return (c - w, c + w)
    if kind == 2:
        return (-draw(st.floats(0.0, 5.0)), draw(st.floats(0.0, 5.0)))
    if kind == 3:
        a, b = sorted((draw(st.floats(-1e6, 1e6)), draw(st.floats(-1e6, 1e6))))
        return (a, b)
    return draw(st.sampled_from([(-INF, INF), (-INF, 0.0), (1.0, INF)]))


@st.composite
def boxes(draw) -> tuple[np.ndarray, np.ndarray]:
    rows = [draw(intervals()) for _ in range(3)]
    return np.array([r[0] for r in rows]), np.array([r[1] for r in rows])


@st.composite
def param_ranges(draw, params) -> dict[str, tuple[float, float]]:
    """Intervals (some points, some ranges) around the defaults of some parameters."""
    out = {}
    for p in params:
        kind = draw(st.integers(0, 2))
        if kind == 1:
            w = draw(st.sampled_from([0.0, 0.1, 1.0]))
            out[p.name] = (p.default - w, p.default + w)
        elif kind == 2:
            out[p.name] = (min(p.default, 0.0) - 2.0, max(p.default, 0.0) + 2.0)
    return out


def _sub_box(rng: np.random.Generator, lo: np.ndarray, hi: np.ndarray):
    """A random sub-box of ``[lo, hi]`` (corners drawn from points of the box)."""
    a, b = sample_box(rng, lo, hi, 6)[rng.choice(14, 2)]
    return np.minimum(a, b), np.maximum(a, b)


def _param_settings(rng: np.random.Generator, pint: dict) -> list[dict]:
    """Parameter values to evaluate at: interval ends and a random value inside."""
    out = [{}]
    if pint:
        out += [{k: v[0] for k, v in pint.items()}, {k: v[1] for k, v in pint.items()}]
        out.append({k: float(rng.uniform(a, b)) for k, (a, b) in pint.items()})
    return out


def _check_chain(prog, lo, hi, pint, seed: int) -> None:
    """simplify over the box, then over a sub-box, then the same sub-box again."""
    rng = np.random.default_rng(seed)
    p1 = simplify(prog, lo, hi, param_intervals=pint)
    lo2, hi2 = _sub_box(rng, lo, hi)
    p2 = simplify(p1, lo2, hi2, param_intervals=pint)
    p3 = simplify(p2, lo2, hi2, param_intervals=pint)
    for p in (p1, p2, p3):
        validate(p)
        assert csdf.Program.from_bytes(p.to_bytes()) == p
        assert (p.params, p.dim, p.exactness) == (prog.params, prog.dim, prog.exactness)
        assert (p.bounds is None) == (prog.bounds is None)
    assert len(p3) <= len(p2) <= len(p1) <= len(prog)
    pts1 = sample_box(rng, lo, hi, 40)
    pts2 = sample_box(rng, lo2, hi2, 40)
    kw = {"backend": "numpy", "check_ranges": False}  # the intervals may leave the ranges
    for pv in _param_settings(rng, pint):
        full1 = prog(pts1, pv, **kw)
        assert_same_values(full1, p1(pts1, pv, **kw), f"box, params {pv}")
        full2 = prog(pts2, pv, **kw)
        for name, p in (("sub-box", p2), ("sub-box again", p3)):
            assert_same_values(full2, p(pts2, pv, **kw), f"{name}, params {pv}")


@_settings(250)
@given(e=S.expr_dags(), bx=boxes(), data=st.data(), seed=st.integers(0, 2**31))
def test_recursive_simplify_of_expressions_is_bit_identical(e, bx, data, seed):
    prog = compile_expr(e)
    pint = data.draw(param_ranges(prog.params))
    _check_chain(prog, *bx, pint, seed)


@_settings(60)
@given(s=S.shapes(), seed=st.integers(0, 2**31))
def test_octree_descent_on_shapes_is_bit_identical(s, seed):
    """Two levels of an octree over a box around the shape, each child simplified from
    its parent's program, every leaf compared with the full program."""
    prog = s.compile()
    rng = np.random.default_rng(seed)
    b = prog.bounds
    if b is None or not np.isfinite(b).all() or (b[0] > b[1]).any():
        lo, hi = np.full(3, -2.0), np.full(3, 2.0)
    else:
        lo, hi = b[0] - 0.1, b[1] + 0.1
    p1 = simplify(prog, lo, hi)
    mid = (lo + hi) / 2
    for child in rng.choice(8, 3, replace=False):
        pick = [(child >> k) & 1 for k in range(3)]
        clo = np.where(pick, mid, lo)
        chi = np.where(pick, hi, mid)
        pc = simplify(p1, clo, chi)
        cmid = (clo + chi) / 2
        gclo, gchi = cmid, chi  # the child's last octant
        pg = simplify(pc, gclo, gchi)
        assert len(pg) <= len(pc) <= len(p1) <= len(prog)
        for p, (a, z) in ((pc, (clo, chi)), (pg, (gclo, gchi))):
            pts = sample_box(rng, a, z, 60)
            assert_same_values(prog(pts, backend="numpy"), p(pts, backend="numpy"),
                               f"octant {a}..{z}")


def test_simplify_shortens_step_by_step():
    """Descending an octree toward one point, each octant simplified from its parent's
    program: the CSG example gets shorter (never longer) and keeps its metadata."""
    cyl = csdf.cylinder(0.5, 3.0)
    shape = (csdf.sphere(1) & csdf.box(1.5)) - cyl - cyl.orient("x") - cyl.orient("y")
    prog = shape.compile()
    target = np.array([0.8, 0.7, 0.6])  # outside the cylinders, near the sphere
    lo, hi = np.full(3, -2.0), np.full(3, 2.0)
    p = prog
    sizes = [len(p)]
    for _ in range(4):
        mid = (lo + hi) / 2
        up = target >= mid
        lo, hi = np.where(up, mid, lo), np.where(up, hi, mid)
        p = simplify(p, lo, hi)
        sizes.append(len(p))
        np.testing.assert_array_equal(p.bounds, prog.bounds)
        assert (p.exactness, p.lipschitz) == (prog.exactness, prog.lipschitz)
    assert sizes == sorted(sizes, reverse=True) and sizes[-1] < sizes[0] / 2, sizes
    pts = sample_box(np.random.default_rng(0), lo, hi, 100)
    assert_same_values(prog(pts, backend="numpy"), p(pts, backend="numpy"), "deepest box")
