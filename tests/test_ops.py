"""The canonical per-op test: every op of the specification (:mod:`csdf.ops`) on every
evaluator of the registry (:mod:`csdf.backends.registry`).

* The specification itself: each op has a value, a derivative rule whose formulas are
  in the formula language and agree with central differences where the op is smooth,
  a kink convention and an interval rule; the hand-written table of kinks and ties
  (:data:`KINKS`) holds for it.
* Every point evaluator, in every mode and dtype it states: one-instruction programs of
  each op, with operands from the coordinates, a constant, a parameter or the same
  slot twice, on a grid of values with the kinks, ties, signed zeros, infinities and
  NaN, give the specification's values, gradients and parameter derivatives.
* GLSL (``to_glsl`` run by WebGL2 in headless Chromium, float32) on the same programs,
  wherever GLSL defines the result (finite inputs and outputs, inside the domain):
  values and ``sdf_grad`` gradients, ties included. Skipped without Chromium and
  Playwright, a failure under ``CSDF_REQUIRE_TOOLS=1``.
* Every interval evaluator: the value at any point of a box (corners, kinks, infinite
  ends) lies in the interval it gives for the box.

Expected derivatives come from the specification's rule (:func:`csdf.ops.chain_tangent`
with the NumPy values of its formulas) in two forms: *dense* (a tangent is a vector
whose other components are zeros, so ``0 * inf`` is NaN: the NumPy reference and the
interpreter) and *sparse* (structurally zero components stay 0: the generated kernels
and GLSL). The two differ only where a factor or operand is infinite; an evaluator
must match one of them in each component (see :mod:`csdf.ops`).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np
import pytest

import csdf
from csdf.backends import registry
from csdf.backends.glsl import to_glsl
from csdf.expr import Param
from csdf.layout import SlotLayout
from csdf.opformula import FUNCTIONS, Formula, Target
from csdf.ops import OPS, chain_tangent, tie_comparison, tie_mask, tie_strict

GRID = np.array([-np.inf, -3.25, -2.0, -1.5, -1.0, -0.5, -0.0, 0.0, 0.5, 1.0, 1.5, 2.0, 3.25,
                 np.inf, np.nan])
#: values of a constant or parameter operand of a binary op
UNIFORM = np.array([-1.0, 0.0, 2.0, np.inf, np.nan])
UNARY_KINDS = [("x",), ("c",), ("k",)]
BINARY_KINDS = [("x", "y"), ("x", "x"), ("c", "x"), ("x", "c"), ("k", "x"), ("x", "k")]
ALL_MODES = ("value", "grad", "jac", "all")
TOL = {np.float64: (1e-12, 1e-14), np.float32: (2e-6, 1e-6)}

REQUIRE_TOOLS = os.environ.get("CSDF_REQUIRE_TOOLS") == "1"


# ---------------------------------------------------------------------------- cases
def op_program(op: str, kinds: tuple[str, ...], const: float | None = None) -> csdf.Program:
    """``r0 = op(a, b)`` with operands from ``kinds``: ``'x'``/``'y'`` coordinates, ``'c'``
    the constant ``const``, ``'k'`` the parameter ``k``."""
    P, C = int("k" in kinds), int("c" in kinds)
    lay = SlotLayout(P, C, 1)
    slot = {"x": 0, "y": 1, "k": lay.param(0) if P else -1, "c": lay.const(0) if C else -1}
    a = slot[kinds[0]]
    b = slot[kinds[1]] if len(kinds) == 2 else 0
    return csdf.Program(params=(Param("k", 0.0),) if P else (),
                        consts=np.array([const] if C else [], dtype=np.float64),
                        code=np.array([[OPS[op].code, lay.reg(0), a, b]]),
                        output=lay.reg(0), n_regs=1)


@dataclass
class Case:
    """One evaluation: a program, its points and parameter value, and the operand
    values ``a``, ``b`` ``(N,)`` at each point."""

    op: str
    kinds: tuple[str, ...]
    prog: csdf.Program
    pts: np.ndarray
    pval: float | None
    a: np.ndarray
    b: np.ndarray | None

    @property
    def uniform_only(self) -> bool:
        return "x" not in self.kinds and "y" not in self.kinds

    @property
    def point_only(self) -> bool:
        """Operands are distinct coordinates (these cases run in every mode)."""
        return self.kinds in (("x",), ("x", "y"))

    def pvals(self) -> np.ndarray:
        return np.array([] if self.pval is None else [self.pval], dtype=np.float64)

    def label(self, i: int | None = None) -> str:
        s = f"{self.op}{self.kinds}" + (f" k={self.pval}" if self.pval is not None else "")
        if self.prog.consts.size:
            s += f" c={self.prog.consts[0]}"
        if i is not None:
            s += f" at a={self.a[i]}" + (f", b={self.b[i]}" if self.b is not None else "")
        return s


def _pts(x: np.ndarray, y: np.ndarray | None = None) -> np.ndarray:
    pts = np.zeros((len(x), 3))
    pts[:, 0] = x
    if y is not None:
        pts[:, 1] = y
    return pts


def _cases(op: str) -> list[Case]:
    out: list[Case] = []
    unary = OPS[op].arity == 1
    spare = _pts(np.array([0.0, 1.0, np.nan]))  # points of a program that reads no coordinate
    for kinds in UNARY_KINDS if unary else BINARY_KINDS:
        if kinds == ("x",):
            out.append(Case(op, kinds, op_program(op, kinds), _pts(GRID), None, GRID, None))
        elif kinds == ("x", "y"):
            A, B = (m.ravel() for m in np.meshgrid(GRID, GRID, indexing="ij"))
            out.append(Case(op, kinds, op_program(op, kinds), _pts(A, B), None, A, B))
        elif kinds == ("x", "x"):
            out.append(Case(op, kinds, op_program(op, kinds), _pts(GRID), None, GRID, GRID))
        elif kinds == ("c",):
            for c in GRID:
                out.append(Case(op, kinds, op_program(op, kinds, c), spare, None,
                                np.full(3, c), None))
        elif kinds == ("k",):
            prog = op_program(op, kinds)
            for k in GRID:
                out.append(Case(op, kinds, prog, spare, float(k), np.full(3, k), None))
        else:
            uni = "c" if "c" in kinds else "k"
            prog = op_program(op, kinds) if uni == "k" else None
            for u in UNIFORM:
                p = prog if prog is not None else op_program(op, kinds, u)
                full = np.full(len(GRID), u)
                a, b = (full, GRID) if kinds[0] == uni else (GRID, full)
                out.append(Case(op, kinds, p, _pts(GRID), float(u) if uni == "k" else None,
                                a, b))
    return out


CASES = {op: _cases(op) for op in OPS}


# ---------------------------------------------------------------------------- expected
class _Dense:
    """Tangents as ``(N, T)`` arrays."""

    @staticmethod
    def scale(f, t):
        return np.asarray(f)[..., None] * t

    add, sub, neg = staticmethod(np.add), staticmethod(np.subtract), staticmethod(np.negative)


class _Component:
    """One tangent component as an ``(N,)`` array."""

    scale, add = staticmethod(np.multiply), staticmethod(np.add)
    sub, neg = staticmethod(np.subtract), staticmethod(np.negative)


def _seed(kind: str, T: int, spatial: bool, wrt: bool) -> np.ndarray | None:
    """Seed tangent ``(T,)`` of an operand kind (None: structurally zero)."""
    e = np.zeros(T)
    if kind in ("x", "y") and spatial:
        e["xy".index(kind)] = 1.0
        return e
    if kind == "k" and wrt:
        e[3 if spatial else 0] = 1.0
        return e
    return None


def expected(case: Case, mode: str, dtype) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(value (N,), dense (N, T), sparse (N, T))`` by the specification, with the NaN
    rules of the evaluator contract applied; T = 3 gradient + P parameter columns as
    the mode asks."""
    info = OPS[case.op]
    dt = np.dtype(dtype)
    a = case.a.astype(dt)
    b = case.b.astype(dt) if case.b is not None else None
    n = len(a)
    spatial, wrt = mode in ("grad", "all"), mode in ("jac", "all")
    T = (3 if spatial else 0) + (len(case.prog.params) if wrt else 0)
    seeds = [_seed(k, T, spatial, wrt) for k in case.kinds]
    ta, tb = seeds[0], (seeds[1] if len(seeds) == 2 else None)
    rule = info.derivative
    with np.errstate(all="ignore"):
        v = np.asarray(info.value(a, b) if b is not None else info.value(a), dtype=dt)
        dense = np.zeros((n, T), dt)
        sparse = np.zeros((n, T), dt)
        if rule.kind == "select":
            m = tie_mask(case.op, a, b, case.kinds[0] == "c")
            za = np.zeros(T) if ta is None else ta
            zb = np.zeros(T) if tb is None else tb
            dense[:] = sparse[:] = np.where(m[:, None], za, zb)
        elif rule.kind == "chain" and T:
            env = {"a": a, "b": b, "v": v}
            for name, f in rule.let:
                env[name] = f.numpy(env, dt)

            def coef(f: Formula):
                return np.broadcast_to(f.numpy(env, dt), (n,))

            full = [None if t is None else np.broadcast_to(t.astype(dt), (n, T))
                    for t in (ta, tb)]
            d = chain_tangent(rule, full[0], full[1], coef, _Dense())
            if d is not None:
                dense[:] = d
            for j in range(T):
                comp = [None if t is None or t[j] == 0 else np.ones(n, dt) for t in (ta, tb)]
                s = chain_tangent(rule, comp[0], comp[1], coef, _Component())
                if s is not None:
                    sparse[:, j] = s
    bad = np.isnan(case.pts).any(axis=1)
    if case.pval is not None and math.isnan(case.pval):
        bad[:] = True
    v[bad] = np.nan
    nan_d = bad | np.isnan(v)
    dense[nan_d] = np.nan
    sparse[nan_d] = np.nan
    return v, dense, sparse


def _assert_close(case: Case, what: str, got: np.ndarray, options: list[np.ndarray],
                  rtol: float, atol: float) -> None:
    ok = np.zeros(got.shape, dtype=bool)
    for e in options:
        ok |= np.isclose(got, e, rtol=rtol, atol=atol, equal_nan=True)
    if not ok.all():
        bad = np.argwhere(~ok)[:5]
        rows = [f"  {case.label(int(i[0]))}: got {got[tuple(i)]!r}, expected "
                f"{' or '.join(repr(e[tuple(i)]) for e in options)}" for i in bad]
        raise AssertionError(f"{what}: {int((~ok).sum())} wrong\n" + "\n".join(rows))


def check_result(case: Case, res: dict, mode: str, dtype, who: str) -> None:
    """Compare an evaluator's result with the specification."""
    dt = np.dtype(dtype)
    assert set(res) == set(registry.MODES[mode]), f"{who} {mode}: keys {sorted(res)}"
    for k, arr in res.items():
        assert arr.dtype == dt, f"{who} {mode}: {k} is {arr.dtype}"
    v, dense, sparse = expected(case, mode, dt)
    rtol, atol = TOL[dt.type]
    _assert_close(case, f"{who} {mode} value", res["value"], [v], rtol, atol)
    col = 0
    if "grad" in res:
        _assert_close(case, f"{who} {mode} gradient", res["grad"],
                      [dense[:, :3], sparse[:, :3]], rtol, atol)
        col = 3
    if "jac" in res:
        _assert_close(case, f"{who} {mode} parameter derivative", res["jac"],
                      [dense[:, col:], sparse[:, col:]], rtol, atol)


# ---------------------------------------------------------------------------- the spec
_LANGUAGE_NAMES = {"a", "b", "v"}


@pytest.mark.parametrize("op", sorted(OPS))
def test_spec_is_complete(op):
    info = OPS[op]
    assert callable(info.value) and callable(info.interval)
    rule = info.derivative
    assert rule.kind in ("chain", "select", "zero")
    assert (rule.kind == "select") == (op in ("min", "max"))
    lets = {n for n, _ in rule.let}
    for f in rule.formulas:
        assert f.names <= _LANGUAGE_NAMES | lets, (op, f)
        if info.arity == 1:
            assert "b" not in f.names, (op, f)
    if rule.kind == "chain":
        assert rule.terms, op
        assert info.arity == 2 or all(w == "a" for w, _, _ in rule.terms)
    non_smooth = {"abs", "sqrt", "floor", "step", "sign", "min", "max", "atan2", "mod", "log",
                  "asin", "acos"}
    assert bool(info.kink) == (op in non_smooth), op


def _smooth_points(op: str, rng) -> tuple[np.ndarray, np.ndarray]:
    """Points inside the domain and away from kinks."""
    a = rng.uniform(0.2, 0.8, 200) * rng.choice([-1.0, 1.0], 200)
    b = rng.uniform(0.3, 2.0, 200) * rng.choice([-1.0, 1.0], 200)
    if op in ("sqrt", "log"):
        a = np.abs(a)
    if op in ("min", "max"):
        b = a + np.where(rng.random(200) < 0.5, -0.1, 0.1)
    if op == "mod":  # away from the jumps of floor(a / b)
        q = a / b
        a = np.where(np.abs(q - np.round(q)) < 0.05, a + 0.1 * np.abs(b), a)
    return a, b


@pytest.mark.parametrize("op", sorted(OPS))
def test_spec_partials_match_central_differences(op):
    info = OPS[op]
    a, b = _smooth_points(op, np.random.default_rng(sorted(OPS).index(op)))
    b = b if info.arity == 2 else None
    pa, pb = info.partials(a, b)
    h = 1e-6

    def f(a_, b_):
        return info.value(a_, b_) if info.arity == 2 else info.value(a_)

    np.testing.assert_allclose(pa, (f(a + h, b) - f(a - h, b)) / (2 * h), rtol=1e-5,
                               atol=1e-7, err_msg=f"{op} d/da")
    if info.arity == 2:
        np.testing.assert_allclose(pb, (f(a, b + h) - f(a, b - h)) / (2 * h), rtol=1e-5,
                                   atol=1e-7, err_msg=f"{op} d/db")
    else:
        assert np.all(pb == 0)


def test_tie_rule():
    assert not tie_strict(False) and tie_strict(True)
    assert [tie_comparison(op, c) for op in ("min", "max") for c in (False, True)] == \
        ["<=", "<", ">=", ">"]
    with pytest.raises(ValueError):
        tie_comparison("add", False)
    assert tie_mask("min", np.float64(2.0), np.float64(2.0), False)
    assert not tie_mask("min", np.float64(2.0), np.float64(2.0), True)


#: hand-written conventions: (op, kinds, constant, parameter, a, b, value,
#: gradient (3,), parameter derivative or None)
KINKS = [
    ("abs", ("x",), None, None, 0.0, None, 0.0, (0, 0, 0), None),
    ("abs", ("x",), None, None, -2.0, None, 2.0, (-1, 0, 0), None),
    ("sqrt", ("x",), None, None, 0.0, None, 0.0, (0, 0, 0), None),
    ("sqrt", ("x",), None, None, 2.25, None, 1.5, (1 / 3, 0, 0), None),
    ("sqrt", ("k",), None, 0.0, 0.0, None, 0.0, (0, 0, 0), 0.0),
    ("floor", ("x",), None, None, 2.0, None, 2.0, (0, 0, 0), None),
    ("step", ("x",), None, None, 0.0, None, 1.0, (0, 0, 0), None),
    ("step", ("x",), None, None, -0.5, None, 0.0, (0, 0, 0), None),
    ("sign", ("x",), None, None, 0.0, None, 0.0, (0, 0, 0), None),
    ("atan2", ("x", "y"), None, None, 0.0, 0.0, 0.0, (0, 0, 0), None),
    ("atan2", ("x", "y"), None, None, 1.0, 0.0, math.pi / 2, (0, -1, 0), None),
    ("mod", ("x", "y"), None, None, 5.0, 2.0, 1.0, (1, -2, 0), None),
    ("mod", ("x", "y"), None, None, -1.0, 2.0, 1.0, (1, 1, 0), None),
    # ties: operand a's derivative, unless a is a constant slot
    ("min", ("x", "y"), None, None, 2.0, 2.0, 2.0, (1, 0, 0), None),
    ("max", ("x", "y"), None, None, 2.0, 2.0, 2.0, (1, 0, 0), None),
    ("min", ("x", "x"), None, None, 2.0, 2.0, 2.0, (1, 0, 0), None),
    ("min", ("c", "x"), 2.0, None, 2.0, 2.0, 2.0, (1, 0, 0), None),  # b = x
    ("max", ("c", "x"), 2.0, None, 2.0, 2.0, 2.0, (1, 0, 0), None),
    ("min", ("x", "c"), 2.0, None, 2.0, 2.0, 2.0, (1, 0, 0), None),  # a = x
    ("min", ("k", "x"), None, 2.0, 2.0, 2.0, 2.0, (0, 0, 0), 1.0),  # a = k: not constant
    ("max", ("x", "k"), None, 2.0, 2.0, 2.0, 2.0, (1, 0, 0), 0.0),
    ("min", ("c", "x"), 2.0, None, 2.0, 3.0, 2.0, (0, 0, 0), None),  # a wins strictly
]


def _kink_case(row) -> Case:
    op, kinds, c, k, a, b, *_ = row
    pts = np.zeros((1, 3))
    for i, kind in enumerate(kinds):
        if kind in ("x", "y"):
            pts[0, "xy".index(kind)] = (a, b)[i]
    return Case(op, kinds, op_program(op, kinds, c), pts, k, np.array([a]),
                None if b is None else np.array([b]))


def _kink_ids():
    return [f"{r[0]}{r[1]}@{r[4]},{r[5]}" for r in KINKS]


@pytest.mark.parametrize("row", KINKS, ids=_kink_ids())
def test_kink_table_is_the_spec(row):
    case = _kink_case(row)
    v, dense, sparse = expected(case, "all", np.float64)
    assert v[0] == pytest.approx(row[6])
    want = list(row[7]) + ([] if row[8] is None else [row[8]])
    np.testing.assert_allclose(sparse[0], want, atol=1e-15)
    np.testing.assert_allclose(dense[0], want, atol=1e-15)


# ---------------------------------------------------------------------------- formulas
_PY = Target(name=lambda n: n, literal=repr,
             calls={"sin": "np.sin({0})", "cos": "np.cos({0})", "sqrt": "np.sqrt({0})",
                    "floor": "np.floor({0})", "sign": "np.sign({0})",
                    "pos_div": "pd({0}, {1})"})


def test_formulas_render_as_they_evaluate():
    """Every formula of the spec, rendered as Python, computes what Formula.numpy
    computes, bit for bit (the rendering keeps the evaluation order)."""
    rng = np.random.default_rng(5)
    env = {"a": rng.normal(size=50), "b": rng.normal(size=50), "v": rng.normal(size=50),
           "r2": rng.uniform(0, 2, 50)}
    ns = {"np": np, "pd": lambda n, d: np.where(d > 0, n / d, 0), **env}
    for info in OPS.values():
        for f in info.derivative.formulas:
            with np.errstate(all="ignore"):
                got = eval(f.render(_PY), ns)  # noqa: S307 - test of our own text
                want = f.numpy(env, np.dtype(np.float64))
            np.testing.assert_array_equal(np.broadcast_to(got, (50,)),
                                          np.broadcast_to(want, (50,)), err_msg=f.text)
    assert Formula("a - (b - v)").render(_PY) == "a - (b - v)"
    assert Formula("a + (b + v)").render(_PY) == "a + (b + v)"
    assert Formula("(a + b) + v").render(_PY) == "a + b + v"
    assert Formula("-(-a)").render(_PY) == "-(-a)"
    assert Formula("1 / b").render(_PY, atom=True) == "(1.0 / b)"
    assert Formula("-floor(a / b)").split_sign() == (True, Formula("floor(a / b)"))
    assert Formula("-1").split_sign() == (True, None)
    assert Formula("1").split_sign() == (False, None)
    assert set(FUNCTIONS) == set(_PY.calls)


@pytest.mark.parametrize("bad", ["a ** 2", "__import__('os')", "a.real", "max(a, b)",
                                 "sin(a, b)", "a if b else v", "'x'", "a < b", "sin"])
def test_formula_language_is_closed(bad):
    with pytest.raises((ValueError, SyntaxError)):
        Formula(bad)


# ---------------------------------------------------------------------------- evaluators
def _evaluators(kind: str):
    return [pytest.param(e, id=e.name, marks=pytest.mark.skipif(
        not e.available(), reason=f"{e.name} needs {e.needs}")) for e in registry.EVALUATORS
        if e.kind == kind]


@pytest.mark.parametrize("op", sorted(OPS))
@pytest.mark.parametrize("ev", _evaluators("points"))
def test_op_on_point_evaluator(ev, op):
    impl = ev.load()
    assert isinstance(impl, registry.PointEvaluator)
    modes = [m for m in ALL_MODES if (m != "grad" or ev.gradients)
             and (m not in ("jac", "all") or ev.param_jacobians)]
    widest = modes[-1]  # 'all' where it has derivatives
    for case in CASES[op]:
        # every mode where the operands are coordinates; the widest one elsewhere (each
        # mode is one more kernel to compile for a generating evaluator)
        for mode in modes if case.point_only else [widest]:
            res = impl.evaluate(case.prog, case.pts, case.pvals(), mode)
            check_result(case, res, mode, np.float64, ev.name)
        if "float32" in ev.dtypes and case.point_only:
            res = impl.evaluate(case.prog, case.pts.astype(np.float32), case.pvals(), widest)
            check_result(case, res, widest, np.float32, f"{ev.name} float32")


@pytest.mark.parametrize("row", KINKS, ids=_kink_ids())
@pytest.mark.parametrize("ev", _evaluators("points"))
def test_kinks_and_ties_on_point_evaluator(ev, row):
    case = _kink_case(row)
    res = ev.load().evaluate(case.prog, case.pts, case.pvals(), "all")
    assert res["value"][0] == pytest.approx(row[6])
    np.testing.assert_allclose(res["grad"][0], row[7], atol=1e-15)
    if row[8] is not None:
        np.testing.assert_allclose(res["jac"][0], [row[8]], atol=1e-15)


def test_program_call_ties_follow_the_spec():
    """Through the public API: ``min(2, x)`` at ``x = 2`` (the issue's example)."""
    from csdf import expr as E
    from csdf.compiler import compile_expr

    prog = compile_expr(E.minimum(2.0, E.X))
    for backend in csdf.backends.BACKENDS:
        if backend != "auto" and not registry.get(backend).available():
            continue
        _, g = prog.value_and_grad(np.array([[2.0, 0.0, 0.0]]), backend=backend)
        np.testing.assert_array_equal(g, [[1.0, 0.0, 0.0]], err_msg=backend)


# ---------------------------------------------------------------------------- intervals
def _axis_samples(lo: float, hi: float, rng) -> np.ndarray:
    """Points of ``[lo, hi]``: the ends, the kink values inside, and interior points
    (huge ones toward an infinite end)."""
    s = [lo, hi]
    if lo < hi:
        flo, fhi = max(lo, -1e300), min(hi, 1e300)
        if flo < fhi:
            s += [flo, fhi, 0.5 * flo + 0.5 * fhi, *rng.uniform(flo, fhi, 3),
                  *np.clip(rng.normal(0.0, 3.0, 3), flo, fhi)]
        s += [v for v in (0.0, -1.0, 1.0, 2.0) if lo <= v <= hi]
    return np.array(s)


def _boxes(rng, n: int) -> list[tuple[float, float]]:
    vals = GRID[~np.isnan(GRID)]
    pairs = [(lo, hi) for i, lo in enumerate(vals) for hi in vals[i:]]
    idx = rng.choice(len(pairs), size=min(n, len(pairs)), replace=False)
    return [pairs[i] for i in idx]


@pytest.mark.parametrize("op", sorted(OPS))
@pytest.mark.parametrize("ev", _evaluators("intervals"))
def test_interval_rule_contains_the_values(ev, op):
    impl = ev.load()
    assert isinstance(impl, registry.IntervalEvaluator)
    ref = registry.get("numpy").load()
    rng = np.random.default_rng(sorted(OPS).index(op))
    for kinds in UNARY_KINDS if OPS[op].arity == 1 else BINARY_KINDS:
        xboxes = _boxes(rng, 60)
        yboxes = _boxes(rng, 8) if "y" in kinds else [(0.0, 0.0)]
        boxes = [(bx, by) for bx in xboxes for by in yboxes]
        lo = np.array([[bx[0], by[0], 0.0] for bx, by in boxes])
        hi = np.array([[bx[1], by[1], 0.0] for bx, by in boxes])
        # sample points of every box, with the index of their box
        pts, owner = [], []
        for i in range(len(boxes)):
            xs = _axis_samples(lo[i, 0], hi[i, 0], rng)
            ys = _axis_samples(lo[i, 1], hi[i, 1], rng) if "y" in kinds else np.zeros(1)
            X, Y = (m.ravel() for m in np.meshgrid(xs, ys, indexing="ij"))
            pts.append(_pts(X, Y))
            owner.append(np.full(len(X), i))
        pts_all, own = np.concatenate(pts), np.concatenate(owner)
        if "c" in kinds:
            uniforms = [(c, None) for c in GRID]
        elif "k" in kinds:
            uniforms = [(None, kb) for kb in _boxes(rng, 12)]
        else:
            uniforms = [(None, None)]
        for c, kbox in uniforms:
            prog = op_program(op, kinds, c)
            pint = {"k": kbox} if kbox is not None else None
            out_lo, out_hi = impl.evaluate_intervals(prog, lo, hi, param_intervals=pint)
            for k in (_axis_samples(*kbox, rng) if kbox is not None else [None]):
                pv = np.array([] if k is None else [k])
                v = ref.evaluate(prog, pts_all, pv, "value")["value"]
                seen = ~np.isnan(v)
                ok = ~seen | ((out_lo[own] <= v) & (v <= out_hi[own]))
                if not ok.all():
                    j = int(np.argmax(~ok))
                    i = own[j]
                    raise AssertionError(
                        f"{op}{kinds} c={c} k={k}: box x {lo[i, 0]}..{hi[i, 0]}, y "
                        f"{lo[i, 1]}..{hi[i, 1]}: interval [{out_lo[i]}, {out_hi[i]}] misses "
                        f"{v[j]} at {pts_all[j, :2]}")


# ---------------------------------------------------------------------------- GLSL
GLSL_WIDTH = 64
_GLSL_FRAG = """
uniform highp sampler2D csdf_points;
layout(location = 0) out vec4 csdf_value;
layout(location = 1) out vec4 csdf_grad;
void main() {
    vec3 p = texelFetch(csdf_points, ivec2(gl_FragCoord.xy), 0).xyz;
    csdf_value = vec4(sdf(p), 0.0, 0.0, 0.0);
    csdf_grad = sdf_grad(p);
}
"""
#: SwiftShader's trigonometric functions are fast approximations (GLSL ES allows it)
GLSL_TRIG = {"sin", "cos", "tan", "asin", "acos", "atan", "atan2"}


def _glsl_defined(case: Case, v: np.ndarray, dense: np.ndarray,
                  sparse: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Masks (value defined, gradient defined) of the points where GLSL defines the
    result: finite inputs, finite value, one unambiguous finite gradient."""
    inputs = np.isfinite(case.a) & (np.isfinite(case.b) if case.b is not None else True)
    val_ok = inputs & np.isfinite(v)
    grad_ok = val_ok & np.all(np.isfinite(dense) & (dense == sparse), axis=1)
    if case.op == "atan2":  # atan(0, 0) is undefined in GLSL, and the sign of a zero y
        val_ok &= case.a != 0  # is not kept; the gradient (0 at the origin) is defined
    return val_ok, grad_ok


def _glsl_cases() -> list[Case]:
    """The cases GLSL can run: finite constants and parameters."""
    out = []
    for op in sorted(OPS):
        for case in CASES[op]:
            if case.prog.consts.size and not np.isfinite(case.prog.consts).all():
                continue
            if case.pval is not None and not math.isfinite(case.pval):
                continue
            out.append(case)
    return out


@pytest.fixture(scope="module")
def glsl_results():
    """Every GLSL case run in one headless page: ``{'cases': [(case, value (N,), grad
    (N, 3))], 'kinks': [(row, value (1,), grad (1, 3))]}``."""
    from glsl_runner import ES_PRELUDE, WebGL2Runner, WebGLUnavailable

    kinks = [(row, _kink_case(row)) for row in KINKS]
    cases = _glsl_cases() + [c for _, c in kinks]
    groups: dict[int, list[Case]] = {}
    for case in cases:
        groups.setdefault(id(case.prog), []).append(case)
    jobs = []
    for group in groups.values():
        n = len(group[0].pts)
        h = -(-n // GLSL_WIDTH)
        texels = np.zeros((h * GLSL_WIDTH, 4), np.float32)
        texels[:n, :3] = np.nan_to_num(group[0].pts, nan=0.0, posinf=0.0, neginf=0.0)
        runs = [{"uniforms": {"u_k": c.pval} if c.pval is not None else {}} for c in group]
        jobs.append({"frag": ES_PRELUDE + to_glsl(group[0].prog) + _GLSL_FRAG,
                     "width": GLSL_WIDTH, "height": h, "outputs": 2, "points": texels,
                     "runs": runs})
    try:
        with WebGL2Runner() as runner:
            results = runner.run(jobs)
    except WebGLUnavailable as e:
        if REQUIRE_TOOLS:
            pytest.fail(f"CSDF_REQUIRE_TOOLS=1 but WebGL2 in Chromium is unavailable: {e}")
        pytest.skip(f"WebGL2 in headless Chromium unavailable ({e}); needs the 'playwright' "
                    "Python package and Debian's chromium")
    got: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    for group, res in zip(groups.values(), results):
        assert "error" not in res, f"{group[0].label()}: WebGL rejected:\n{res['error']}"
        for case, run in zip(group, res["runs"]):
            assert run["missing"] == [], run["missing"]
            n = len(case.pts)
            got[id(case)] = (run["outputs"][0][:n, 0].astype(np.float64),
                             run["outputs"][1][:n, 1:].astype(np.float64))
    return {"cases": [(c, *got[id(c)]) for c in cases[:len(cases) - len(kinks)]],
            "kinks": [(row, *got[id(c)]) for row, c in kinks]}


@pytest.mark.parametrize("op", sorted(OPS))
def test_op_on_glsl(glsl_results, op):
    checked = 0
    for case, val, grad in glsl_results["cases"]:
        if case.op != op:
            continue
        v, dense, sparse = expected(case, "grad", np.float32)
        val_ok, grad_ok = _glsl_defined(case, v, dense, sparse)
        vt, gt = (5e-4, 5e-3) if op in GLSL_TRIG else (1e-5, 1e-5)
        for what, ok, g, want, tol in (("value", val_ok, val, v, vt),
                                       ("gradient", grad_ok, grad, sparse, gt)):
            if ok.any():
                sub = Case(case.op, case.kinds, case.prog, case.pts[ok], case.pval,
                           case.a[ok], None if case.b is None else case.b[ok])
                _assert_close(sub, f"GLSL {what}", g[ok], [want[ok].astype(np.float64)],
                              rtol=tol, atol=tol)
        checked += int(val_ok.sum() + grad_ok.sum())
    assert checked > 0


@pytest.mark.parametrize("row", KINKS, ids=_kink_ids())
def test_glsl_kinks_and_ties_equal_the_cpu(glsl_results, row):
    """The kink table on the GPU path (the ties of ``min(2, x)`` at ``x = 2`` included:
    gradient (1, 0, 0), as on the CPU)."""
    got = {id(r): (v, g) for r, v, g in glsl_results["kinks"]}
    val, grad = got[id(row)]
    assert val[0] == pytest.approx(row[6], abs=1e-6)
    np.testing.assert_allclose(grad[0], row[7], atol=1e-6, err_msg=str(row))
