"""The expression DAG: interning, folding, canonical order, simplification."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

import csdf
from csdf.expr import X, Y, Z, const, make, maximum, minimum, param, walk


def test_structurally_equal_expressions_are_the_same_object():
    a = (X * X + Y * Y) - 1.0
    b = (Y * Y + X * X) - 1.0
    assert a is b
    assert make("min", X, Y) is make("min", Y, X)
    assert minimum(X, Y, Z) is minimum(Z, X, Y)
    assert maximum(X, Y, Z) is maximum(Y, Z, X)


def test_constant_folding_and_identities():
    assert const(2.0) * 3.0 is const(6.0)
    assert X + 0.0 is X and 0.0 + X is X and X * 1.0 is X and X / 1.0 is X
    assert make("neg", make("neg", X)) is X
    assert abs(-X) is abs(X)
    assert X * X is make("square", X)
    assert (X * 0.0).op == "const"
    assert make("sqrt", const(4.0)) is const(2.0)


def test_shared_subexpressions_compile_once():
    s = csdf.sphere(1.0).translate((1, 0, 0)) | csdf.sphere(2.0).translate((1, 0, 0))
    prog = s.compile()
    # x - 1 and the squared length are shared between the two spheres
    names = [r for r in prog.disassemble().splitlines() if " = sub x" in r]
    assert len(names) == 1


def test_params_are_interned_by_declaration():
    assert param("r", 1.0, 0, 2) is param("r", 1.0, 0, 2)
    assert param("r", 1.0) is not param("r", 2.0)


def test_expressions_have_no_truth_value():
    with pytest.raises(TypeError, match="truth value"):
        bool(X < 1) if False else bool(X)


def test_pickle_round_trip_preserves_identity():
    e = csdf.sphere(param("r", 1.0)).expr
    assert pickle.loads(pickle.dumps(e)) is e


def test_walk_visits_children_first():
    e = (X + Y) * (X + Y) + Z
    seen = []
    for n in walk(e):
        for a in n.args:
            assert a in seen
        seen.append(n)
    assert seen[-1] is e


@pytest.mark.parametrize("axis,perm", [("x", (1, 2, 0)), ("y", (2, 0, 1)), ("-z", None)])
def test_orient_to_an_axis_is_an_exact_permutation(axis, perm):
    """Orienting onto a coordinate axis swaps coordinates exactly: no 6e-17 * x terms
    (cos 90 degrees in floating point) reach the tape, and values match bit for bit."""
    cyl = csdf.cylinder(0.5, 3.0)
    oriented = csdf.compile(cyl.orient(axis))
    assert len(oriented.code) == len(csdf.compile(cyl).code)
    assert all(abs(c) >= 1e-9 or c == 0 for c in oriented.consts)
    pts = np.random.default_rng(0).uniform(-2, 2, (200, 3))
    if perm is not None:
        # +z maps to the axis, so the shape's own z is read from that axis
        np.testing.assert_array_equal(oriented(pts, backend="numpy"),
                                      csdf.compile(cyl)(pts[:, perm], backend="numpy"))
