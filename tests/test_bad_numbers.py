"""Bad numbers and oversized models fail with a clear :class:`csdf.CsdfError` (issue 15).

Covers: overflowing, infinite and NaN integer/scalar arguments and parameter values;
negative sizes of primitives; the expression-node budget while building (an
exponential ``let`` expansion fails at once); the bound on the number of parameters.
"""

from __future__ import annotations

import resource
import time

import numpy as np
import pytest

import csdf
from csdf.compiler.tape import MAX_PARAMS
from csdf.shapes.base import MAX_EXPANSION, MAX_EXPR_NODES

HUGE = 10**400
PTS = np.zeros((1, 3))


# ------------------------------------------------------------------ 1. bad numbers
@pytest.mark.parametrize(
    "build, arg",
    [
        (lambda: csdf.sphere(0.2).repeat_polar(float("inf")), "repeat_polar: n"),
        (lambda: csdf.sphere(0.2).repeat_polar(float("nan")), "repeat_polar: n"),
        (lambda: csdf.sphere(0.2).repeat_polar(HUGE), "repeat_polar: n"),
        (lambda: csdf.sphere(0.2).repeat(1.0, count=float("inf")), "repeat: count"),
        (lambda: csdf.regular_polygon(n=float("inf")), "regular_polygon: n"),
        (lambda: csdf.sphere(HUGE), "sphere: radius"),
        (lambda: csdf.box((1, HUGE, 1)), "box: size[1]"),
        (lambda: csdf.sphere(1).translate((HUGE, 0, 0)), "translate: offset[0]"),
    ],
)
def test_bad_numbers_are_shape_errors(build, arg):
    with pytest.raises(csdf.ShapeError) as info:
        build()
    msg = str(info.value)
    assert arg in msg
    assert len(msg) < 300  # a huge integer is not printed whole


def test_bad_number_message_names_the_value():
    with pytest.raises(csdf.ShapeError, match=r"inf"):
        csdf.sphere(0.2).repeat_polar(float("inf"))
    with pytest.raises(csdf.ShapeError, match=r"nan"):
        csdf.sphere(0.2).repeat_polar(float("nan"))
    with pytest.raises(csdf.ShapeError, match=r"10\*\*400"):
        csdf.sphere(HUGE)


def test_huge_parameter_value_is_a_param_error():
    prog = csdf.sphere(csdf.param("r", 1.0)).compile()
    with pytest.raises(csdf.ParamError, match=r"'r'.*10\*\*400"):
        prog(PTS, r=HUGE)
    with pytest.raises(csdf.ParamError, match="'r'"):
        prog.param_values({"r": -HUGE})
    assert prog.param_values(r=2) == pytest.approx([2.0])


def test_huge_parameter_declaration_is_a_param_error():
    with pytest.raises(csdf.ParamError, match="default"):
        csdf.param("r", HUGE)
    with pytest.raises(csdf.ParamError, match="upper bound"):
        csdf.param("r", 1.0, 0.0, HUGE)


def test_huge_number_in_expression_arithmetic():
    with pytest.raises(csdf.CsdfError):
        csdf.param("r", 1.0) + HUGE


def test_huge_numbers_in_model_text():
    with pytest.raises(csdf.CsdfError):
        csdf.loads("export sphere(0.2).repeat_polar(1e400)")
    with pytest.raises(csdf.CsdfError):
        csdf.loads("export sphere(0.2).repeat_polar(inf)")


# ------------------------------------------------------------------ 2. negative sizes
NEGATIVE = [
    (lambda: csdf.sphere(-1), "sphere: radius"),
    (lambda: csdf.box((1, -1, 1)), "box: size[1]"),
    (lambda: csdf.rounded_box(1, -0.1), "rounded_box: radius"),
    (lambda: csdf.box_frame(1, -0.1), "box_frame: thickness"),
    (lambda: csdf.cylinder(-0.5, 1), "cylinder: radius"),
    (lambda: csdf.cylinder(0.5, -1), "cylinder: height"),
    (lambda: csdf.rounded_cylinder(0.5, 1, -0.1), "rounded_cylinder: rounding"),
    (lambda: csdf.capsule(radius=-0.1), "capsule: radius"),
    (lambda: csdf.cone(-0.5, 1), "cone: radius"),
    (lambda: csdf.capped_cone(0.5, -0.2, 1), "capped_cone: r2"),
    (lambda: csdf.round_cone(-0.1, 0.2, 1), "round_cone: r1"),
    (lambda: csdf.torus(0.5, -0.1), "torus: minor"),
    (lambda: csdf.capped_torus(-0.5, 0.1), "capped_torus: major"),
    (lambda: csdf.link(-1, 0.3, 0.1), "link: length"),
    (lambda: csdf.slab(-0.1), "slab: thickness"),
    (lambda: csdf.ellipsoid((0.5, -0.3, 0.2)), "ellipsoid: radii[1]"),
    (lambda: csdf.octahedron(-0.5), "octahedron: size"),
    (lambda: csdf.pyramid(-1, 1), "pyramid: height"),
    (lambda: csdf.hex_prism(-0.5, 1), "hex_prism: radius"),
    (lambda: csdf.tri_prism(0.5, -1), "tri_prism: height"),
    (lambda: csdf.circle(-0.5), "circle: radius"),
    (lambda: csdf.rectangle((-1, 1)), "rectangle: size[0]"),
    (lambda: csdf.rounded_rectangle(1, -0.1), "rounded_rectangle: radius"),
    (lambda: csdf.regular_polygon(5, -0.5), "regular_polygon: radius"),
    (lambda: csdf.equilateral_triangle(-0.5), "equilateral_triangle: radius"),
    (lambda: csdf.hexagon(-0.5), "hexagon: radius"),
    (lambda: csdf.ring(0.5, -0.1), "ring: thickness"),
    (lambda: csdf.segment(thickness=-0.1), "segment: thickness"),
    (lambda: csdf.trapezoid(0.5, 0.25, -1), "trapezoid: height"),
    (lambda: csdf.rhombus((1, -0.6)), "rhombus: size[1]"),
    (lambda: csdf.ellipse((-0.5, 0.3)), "ellipse: radii[0]"),
    (lambda: csdf.extrude(csdf.circle(0.5), -1), "extrude: height"),
    (lambda: csdf.sphere(1).shell(-0.1), "shell: thickness"),
    (lambda: csdf.sphere(1).round(-0.1), "round: radius"),
    (lambda: csdf.sphere(1).elongate((0.1, -0.1, 0)), "elongate: h[1]"),
]


@pytest.mark.parametrize("build, arg", NEGATIVE, ids=[a for _, a in NEGATIVE])
def test_negative_sizes_are_refused(build, arg):
    with pytest.raises(csdf.ShapeError, match="must be >= 0|must be > 0") as info:
        build()
    assert arg in str(info.value)


def test_zero_sizes():
    # a zero size is a degenerate shape whose field is still the exact distance to it
    assert csdf.sphere(0)(np.array([[3.0, 4.0, 0.0]]))[0] == pytest.approx(5.0)
    assert csdf.rounded_box(1, 0).exactness == "exact"
    csdf.box((1, 0, 1))
    csdf.circle(0)
    csdf.sphere(1).shell(0)
    # where a zero size divides, it is refused
    for build in (lambda: csdf.ellipsoid((0.5, 0.0, 0.2)), lambda: csdf.pyramid(1, 0),
                  lambda: csdf.ellipse((0.0, 0.3)), lambda: csdf.round_cone(0.1, 0.1, 0)):
        with pytest.raises(csdf.ShapeError, match="> 0"):
            build()


def test_negative_parameter_sizes():
    with pytest.raises(csdf.ShapeError, match="sphere: radius"):
        csdf.sphere(csdf.param("r", -1.0))
    with pytest.raises(csdf.ShapeError, match="cylinder: height"):
        csdf.cylinder(0.5, csdf.param("h", -1.0, -2.0, -0.5))
    with pytest.raises(csdf.ShapeError, match="sphere: radius"):
        csdf.sphere(csdf.param("r", 1.0) - 2.0)
    # unknown sign (unbounded parameter, or a range that straddles 0, with a positive
    # default) and positive ranges build
    csdf.sphere(csdf.param("r", 1.0))
    csdf.sphere(csdf.param("r", 1.0, -1.0, 2.0))
    csdf.sphere(csdf.param("r", 1.0, 0.5, 2.0) * 0.5)
    with pytest.raises(csdf.CsdfError, match="radius"):
        csdf.loads("param r = -1\nexport sphere(r)")


# ------------------------------------------------------------------ 3. node budget
def _let_chain(levels: int) -> str:
    lines = ["let a0 = sphere(0.1)"]
    for i in range(1, levels + 1):
        lines.append(f"let a{i} = a{i - 1}.translate((0.{i}1, 0, 0)) "
                     f"| a{i - 1}.translate((0, 0.{i}2, 0))")
    lines.append(f"export a{levels}")
    return "\n".join(lines)


def test_exponential_let_expansion_fails_fast():
    text = _let_chain(17)
    assert len(text) < 1500
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    t0 = time.perf_counter()
    with pytest.raises(csdf.CsdfError, match="expands to more than"):
        csdf.loads(text)
    assert time.perf_counter() - t0 < 1.0
    grown_mb = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - rss0) / 1024
    assert grown_mb < 20


def test_exponential_python_expansion_fails_fast():
    s = csdf.sphere(0.1)
    for i in range(20):
        s = s.translate((0.1 + i, 0, 0)) | s.translate((0, 0.2 + i, 0))
    t0 = time.perf_counter()
    with pytest.raises(csdf.CsdfError, match="expands to more than"):
        s.compile()
    with pytest.raises(csdf.CsdfError, match="expands to more than"):
        s.expr  # noqa: B018
    assert time.perf_counter() - t0 < 1.0


def test_node_budget_counts_nodes_while_building(monkeypatch):
    import csdf.shapes.base as base

    s = csdf.union(*[csdf.sphere(0.1).translate((i, 0, 0)) for i in range(50)])
    monkeypatch.setattr(base, "MAX_EXPR_NODES", 100)
    with pytest.raises(csdf.CsdfError, match="more than 100 expression nodes"):
        s.build()
    monkeypatch.setattr(base, "MAX_EXPR_NODES", 10_000)
    s.build()


def test_shared_subtrees_do_not_count_twice():
    # the same shape used twice at the same coordinates is evaluated once
    s = csdf.sphere(0.1)
    for _ in range(40):
        s = s | s
    assert s.compile() is not None


def test_limits_are_generous_for_normal_models():
    assert MAX_EXPR_NODES >= 1_000_000
    assert MAX_EXPANSION >= 100_000
    from csdf import zoo

    for name in zoo.names():
        zoo.load(name).compile()


# ------------------------------------------------------------------ 4. parameters
def test_too_many_parameters():
    n = MAX_PARAMS + 1
    text = "".join(f"param p{i} = 0.1\n" for i in range(n))
    text += "export union(" + ", ".join(f"sphere(p{i})" for i in range(n)) + ")"
    t0 = time.perf_counter()
    with pytest.raises(csdf.CsdfError, match=f"more than {MAX_PARAMS} parameters"):
        csdf.loads(text)
    assert time.perf_counter() - t0 < 30


def test_many_parameters_below_the_limit():
    s = csdf.union(*[csdf.sphere(csdf.param(f"p{i}", 0.1)).translate((i, 0, 0))
                     for i in range(64)])
    jac = s.param_jacobian(PTS)
    assert jac.shape == (1, 64)


def test_bytecode_with_too_many_parameters_is_refused():
    """A program read from bytecode was never compiled: the loader checks the limit."""
    from csdf.compiler import compile_expr
    from csdf.compiler.program import Program
    from csdf.expr import Param, X

    prog = compile_expr(X + 1.0)
    many = tuple(Param(f"q{i}", 0.0) for i in range(MAX_PARAMS + 1))
    big = Program(params=many, consts=prog.consts, code=prog.code, output=prog.output,
                  n_regs=prog.n_regs)
    data = big.to_bytes()
    with pytest.raises(csdf.BytecodeError, match=f"more than {MAX_PARAMS}"):
        Program.from_bytes(data)


@pytest.mark.parametrize("text", ["export sphere(0/0)", "export sphere(1/0)",
                                  "export sphere(1).translate((0/0, 0, 0))",
                                  "export box((1e308 * 10, 1, 1))"])
def test_folded_non_finite_constants_are_refused(text):
    """The language folds ``0/0`` to a constant NaN: shapes refuse it like a float NaN."""
    with pytest.raises(csdf.ModelError, match="must be finite"):
        csdf.loads(text)
