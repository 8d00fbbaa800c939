"""csdf's one interval arithmetic (``csdf.interval``): the rule table, the tape runner
and the parameter ranges that shapes size their bounding boxes with.

The rules' containment over compiled programs is tested through
``evaluate_intervals`` in ``test_interval_eval.py``; here: every op has a rule of its
arity, the module stays low in the layering, the runner is what ``evaluate_intervals``
runs, and :func:`expr_range` contains every value the evaluator computes.
"""

from __future__ import annotations

import ast
import inspect
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import csdf
import csdf.interval as interval
from csdf.backends.interval_eval import evaluate_intervals
from csdf.compiler import compile_expr
from csdf.expr import X, const, make, param
from csdf.ops import OPS, OPS_BY_CODE

try:  # tests/ as a package or as a plain directory on sys.path
    from . import strategies as S
except ImportError:
    import strategies as S

pytestmark = pytest.mark.filterwarnings("ignore::RuntimeWarning")
INF = math.inf


def test_every_op_has_a_rule_of_its_arity():
    assert set(interval.RULES) == set(OPS)
    for name, rule in interval.RULES.items():
        assert len(inspect.signature(rule).parameters) == 2 * OPS[name].arity, name
    for name in interval.SAME_OPERAND_RULES:
        assert OPS[name].arity == 2


def test_module_imports_only_the_low_layers():
    """``csdf.ops`` and ``csdf.expr`` may refer to the rules, so the rules must not
    import them (nor anything else of csdf but errors and layout)."""
    tree = ast.parse(Path(interval.__file__).read_text())
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            found.add("." * node.level + (node.module or ""))
    assert found <= {"__future__", "math", "collections.abc", "typing", "numpy", ".errors",
                     ".layout"}, found


def test_runner_is_what_evaluate_intervals_runs():
    r = param("r", 1.0, 0.5, 2.0)
    prog = csdf.union(csdf.sphere(r), csdf.box(0.8).translate((1, 0, 0)), k=0.2).compile()
    rng = np.random.default_rng(0)
    lo = rng.uniform(-2, 2, (20, 3))
    hi = lo + rng.uniform(0, 0.5, (20, 3))
    plo, phi = interval.param_bounds(prog, None, {"r": (0.6, 1.5)})
    sl, sh = interval.init_slots(prog.layout, prog.consts, plo, phi)
    sl[:3] = list(lo.T)
    sh[:3] = list(hi.T)
    record: list = []
    steps = interval.tape_steps(prog.code, {c: i.name for c, i in OPS_BY_CODE.items()})
    interval.run_tape(steps, sl, sh, record)
    assert len(record) == len(prog)
    want = evaluate_intervals(prog, lo, hi, param_intervals={"r": (0.6, 1.5)})
    np.testing.assert_array_equal(sl[prog.output], want[0])
    np.testing.assert_array_equal(sh[prog.output], want[1])


def test_expr_range_examples():
    r = param("r", 1.0, 0.5, 2.0)
    free = param("f", 3.0)  # unbounded: taken at its default
    assert interval.expr_range(r) == (0.5, 2.0)
    assert interval.expr_range(free) == (3.0, 3.0)
    assert interval.expr_range(make("mul", r, const(-2.0))) == (-4.0, -1.0)
    assert interval.expr_range(make("sub", r, r)) == (0.0, 0.0)  # same operand
    assert interval.expr_range(make("add", X, r)) == (-INF, INF)
    assert interval.expr_range(make("div", const(1.0), make("sub", r, const(1.0)))) == (
        -INF, INF)
    lo, hi = interval.expr_range(make("sin", r))
    assert lo <= math.sin(0.5) and hi >= 1.0 and hi - 1.0 < 1e-14
    assert interval.expr_range(make("sqrt", make("neg", r))) == (-INF, INF)  # always NaN
    assert interval.magnitude(make("sub", const(0.25), r)) == 1.75


@settings(max_examples=300, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
@given(e=S.expr_dags(max_depth=5), seed=st.integers(0, 2**31))
def test_expr_range_contains_evaluated_values(e, seed):
    """Every non-NaN value the evaluator computes, at any point and any parameter value
    the range rule allows (inside finite bounds, else the default), is in the range."""
    lo, hi = interval.expr_range(e)
    prog = compile_expr(e)
    rng = np.random.default_rng(seed)
    pts = rng.choice([0.0, -0.0, 1.0, -1.0, 0.5, 3.0, 1e300, -INF, INF], (16, 3))
    for _ in range(4):
        pv = {}
        for p in prog.params:
            if math.isfinite(p.lo) and math.isfinite(p.hi):
                pv[p.name] = float(rng.choice([p.lo, p.hi, rng.uniform(p.lo, p.hi)]))
        vals = prog(pts, pv, backend="numpy")
        ok = np.isnan(vals) | ((vals >= lo) & (vals <= hi))
        assert ok.all(), (vals[~ok][:4], (lo, hi), pv)
