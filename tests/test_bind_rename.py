"""``Shape.bind`` and ``Shape.rename``: copies of one parametric model in one shape, each
with its own parameters (issue 17), in Python and in the language."""

from __future__ import annotations

import numpy as np
import pytest

import csdf
from csdf.errors import ModelError, ParamError, ShapeError

PTS = np.random.default_rng(0).uniform(-1.0, 2.0, (2000, 3))


def test_two_chairs_with_parameters_of_their_own():
    chair = csdf.zoo.load("chair")
    # two copies that differ in a parameter's default cannot share its name
    with pytest.raises(ParamError, match="declared twice"):
        (chair | csdf.zoo.load("chair", seat_height=0.5)).params  # noqa: B018
    left = chair.rename(prefix="left_")
    right = csdf.zoo.load("chair", seat_height=0.5).rename(prefix="right_")
    two = left | right.translate((1.0, 0.0, 0.0))
    names = [p.name for p in two.params]
    assert names == sorted(["left_" + p.name for p in chair.params]
                           + ["right_" + p.name for p in chair.params])
    by_name = {p.name: p for p in two.params}
    for p in chair.params:  # defaults and ranges kept
        q = by_name["left_" + p.name]
        assert (q.default, q.lo, q.hi) == (p.default, p.lo, p.hi)
    assert by_name["right_seat_height"].default == 0.5
    got = two(PTS, {"left_seat_height": 0.45, "right_back_height": 0.5})
    want = np.minimum(chair(PTS, {"seat_height": 0.45}),
                      chair(PTS - (1.0, 0.0, 0.0), {"seat_height": 0.5, "back_height": 0.5}))
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
    # each copy's parameter moves only its copy: Jacobian columns of the other are zero
    prog = two.compile()
    J = prog.param_jacobian(PTS)
    right_wins = two(PTS) == chair(PTS - (1.0, 0, 0), {"seat_height": 0.5})
    right_wins &= two(PTS) < chair(PTS)
    assert right_wins.sum() > 100
    for name in ("left_seat_height", "left_leg"):
        assert np.all(J[right_wins, prog.param_names.index(name)] == 0.0)
        assert np.any(J[~right_wins, prog.param_names.index(name)] != 0.0)


def test_bind_fixes_values_and_checks_them():
    chair = csdf.zoo.load("chair")
    bound = chair.bind(seat_height=0.5, leg=0.03)
    assert {p.name for p in bound.params} == {p.name for p in chair.params} - {
        "seat_height", "leg"}
    np.testing.assert_array_equal(bound(PTS), chair(PTS, {"seat_height": 0.5, "leg": 0.03}))
    assert (bound.exactness, bound.lipschitz) == (chair.exactness, chair.lipschitz)
    np.testing.assert_array_equal(bound.bounds, chair.bounds)
    assert len(bound.compile().calls) == len(chair.compile().calls)  # Table-1 counts kept
    with pytest.raises(ParamError, match=r"unknown parameter\(s\) 'seat'.*seat_height"):
        chair.bind(seat=0.5)
    with pytest.raises(ParamError, match=r"outside its range \[0.38, 0.55\]"):
        chair.bind(seat_height=0.9)
    with pytest.raises(ParamError, match="finite number"):
        chair.bind(seat_height=float("nan"))
    with pytest.raises(ParamError, match="finite number"):
        chair.bind(seat_height="0.5")
    with pytest.raises(ShapeError, match="at least one"):
        chair.bind()


def test_rename_leaves_the_callers_parameters_alone():
    r = csdf.param("r", 0.5, 0.1, 1.0)
    x0 = csdf.param("x0", 0.0, -2.0, 2.0)
    inner = csdf.sphere(r).rename(prefix="a_").translate((x0, 0, 0))
    assert [p.name for p in inner.params] == ["a_r", "x0"]
    outer = csdf.sphere(r).translate((x0, 0, 0)).rename(suffix="_2")
    assert [p.name for p in outer.params] == ["r_2", "x0_2"]
    v = inner(PTS, {"a_r": 0.3, "x0": 0.7})
    np.testing.assert_allclose(v, np.linalg.norm(PTS - (0.7, 0, 0), axis=1) - 0.3,
                               atol=1e-12)
    with pytest.raises(ParamError, match="rename: parameter name '9r'"):
        csdf.sphere(r).rename(prefix="9")
    with pytest.raises(ParamError, match="reserved"):
        csdf.sphere(csdf.param("check", 1.0)).rename(suffix="_ranges")
    with pytest.raises(ShapeError, match="prefix or a suffix"):
        csdf.sphere(r).rename()
    with pytest.raises(ShapeError, match="strings"):
        csdf.sphere(r).rename(prefix=1)


def test_printed_models_load_back_to_the_same_bytecode():
    chair = csdf.zoo.load("chair")
    two = chair.rename(prefix="l_") | chair.bind(seat_height=0.5).translate((1, 0, 0))
    text = csdf.dumps(two)
    assert ".rename(prefix=\"l_\")" in text and ".bind(seat_height=0.5)" in text
    assert csdf.loads(text).compile().to_bytes() == two.compile().to_bytes()


def test_the_language_has_bind_and_rename_with_located_errors():
    shape = csdf.loads("""
        param r = 1 in [0.5, 2]
        let c = sphere(r)
        export c.rename(prefix="a_") | c.rename(prefix="b_").translate((3, 0, 0))
               | c.bind(r=0.7).translate((0, 3, 0))
    """)
    assert [p.name for p in shape.params] == ["a_r", "b_r"]
    np.testing.assert_allclose(shape([[3, 0, 0], [0, 3, 0.7]], {"b_r": 1.5}), [-1.5, 0.0],
                               atol=1e-12)
    with pytest.raises(ModelError, match=r"<string>:2:8: bind: unknown parameter\(s\) 'q'"):
        csdf.loads("param r = 1\nexport sphere(r).bind(q=2)")
    with pytest.raises(ModelError, match="2:8: bind: r must be a finite number"):
        csdf.loads("param r = 1\nexport sphere(r).bind(r=1/0)")
    with pytest.raises(ModelError, match="wrong arguments for rename"):
        csdf.loads("param r = 1\nexport sphere(r).rename(\"a_\", \"b\", \"c\")")
