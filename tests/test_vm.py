"""Fidget's ``.vm`` format: csdf.io.load_vm / loads_vm / save_vm / dumps_vm and
csdf.load("x.vm").

The three models of ``shared/data/vm`` (from the Fidget repository, MPL-2.0) are read
by path; the tests that need them skip when the folder is absent.
"""

from __future__ import annotations

import importlib.util
import math
from decimal import ROUND_HALF_UP, Decimal
from pathlib import Path

import numpy as np
import pytest

import csdf
from csdf.errors import CsdfError, ModelError
from csdf.expr import X, Y, Z
from csdf.io import dumps_vm, load_vm, loads_vm, save_vm
from csdf.lang import vm as vm_mod
from csdf.shapes.exprfield import expr_dim, expr_shape, substitute

VM_DIR = Path(__file__).resolve().parents[2] / "shared" / "data" / "vm"
FILES = ("hi", "quarter", "prospero")


def vm_path(name: str) -> Path:
    p = VM_DIR / f"{name}.vm"
    if not p.is_file():
        pytest.skip(f"{p} is not available")
    return p


# ------------------------------------------------------------------ an independent oracle
def tiny_eval(text: str, x: float, y: float, z: float = 0.0) -> float:
    """Evaluate ``.vm`` text at one point with Python floats (the format's opcodes that
    the test files use, with their plain definitions)."""
    un = {"neg": lambda a: -a, "square": lambda a: a * a, "sqrt": math.sqrt,
          "abs": abs}
    bi = {"add": lambda a, b: a + b, "sub": lambda a, b: a - b, "mul": lambda a, b: a * b,
          "div": lambda a, b: a / b, "min": min, "max": max}
    env: dict[str, float] = {}
    last = math.nan
    for line in text.splitlines():
        t = line.split()
        if not t or t[0].startswith("#"):
            continue
        name, op, args = t[0], t[1], t[2:]
        if op == "const":
            v = float(args[0])
        elif op.startswith("var-"):
            v = {"var-x": x, "var-y": y, "var-z": z}[op]
        elif op in un:
            v = un[op](env[args[0]])
        else:
            v = bi[op](env[args[0]], env[args[1]])
        env[name] = last = v
    return last


def pixel_grid(n: int) -> np.ndarray:
    """Pixel centres over [-1, 1]^2, row 0 at y = +1, as ``(n*n, 2)``."""
    c = (np.arange(n) + 0.5) / n * 2.0 - 1.0
    gx, gy = np.meshgrid(c, -c)
    return np.stack([gx.ravel(), gy.ravel()], axis=-1)


# ------------------------------------------------------------------ loading the files
@pytest.mark.parametrize("name", FILES)
def test_files_load_as_2d_fields_that_state_nothing(name):
    s = load_vm(vm_path(name))
    assert isinstance(s, csdf.Shape)
    assert s.dim == 2
    assert s.exactness == "neither"
    assert s.lipschitz == math.inf
    assert s.bounds is None
    prog = s.compile()
    assert prog.dim == 2 and prog.params == ()


def test_prospero_keeps_its_sharing():
    path = vm_path("prospero")
    lines = [ln for ln in path.read_text().splitlines() if ln.strip() and ln[0] != "#"]
    assert len(lines) == 7866
    prog = load_vm(path).compile()
    ops = sum(1 for ln in lines if ln.split()[1] not in ("const", "var-x", "var-y"))
    # one instruction per operation node at most (interning may merge a few)
    assert 0.9 * ops <= len(prog) <= ops


def test_prospero_matches_an_independent_evaluator():
    path = vm_path("prospero")
    text = path.read_text()
    s = load_vm(path)
    pts = pixel_grid(1024)[np.random.default_rng(1).choice(1024 * 1024, 20, replace=False)]
    pts = np.vstack([pts, [[-0.5, 0.5], [0.0, 0.0]]])
    want = np.array([tiny_eval(text, x, y) for x, y in pts.tolist()])
    for backend in ("numpy", "interp"):
        got = s(pts, backend=backend)
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)
    assert (want < 0).any() and (want > 0).any()


def test_hi_is_in_the_upper_right_quadrant():
    path = vm_path("hi")
    s = load_vm(path)
    pts = pixel_grid(64)
    inside = s(pts, backend="numpy") < 0
    assert inside.sum() > 50
    assert (pts[inside] > 0).all()
    text = path.read_text()
    want = np.array([tiny_eval(text, x, y) for x, y in pts[::37].tolist()])
    np.testing.assert_allclose(s(pts[::37], backend="numpy"), want, rtol=1e-12, atol=1e-12)


def test_quarter_is_a_quarter_disk_in_the_lower_left():
    s = load_vm(vm_path("quarter"))
    pts = pixel_grid(64)  # no pixel centre lies on an axis or on the circle
    x, y = pts[:, 0], pts[:, 1]
    want = (x < 0) & (y < 0) & (x * x + y * y < 0.5)
    assert np.array_equal(s(pts, backend="numpy") < 0, want)
    g = s.gradient(np.array([[-0.3, -0.2]]), backend="numpy")
    np.testing.assert_allclose(g, [[0.0, 1.0]])  # max(x, y) wins there: d/dy y


def test_quarter_on_every_backend_with_intervals_and_gradients():
    s = load_vm(vm_path("quarter"))
    pts = np.random.default_rng(2).uniform(-1, 1, (200, 2))
    ref = s(pts, backend="numpy")
    backends = ["interp"] + (["fast"] if importlib.util.find_spec("numba") else [])
    for b in backends:
        np.testing.assert_allclose(s(pts, backend=b), ref, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(s.gradient(pts, backend=b),
                                   s.gradient(pts, backend="numpy"), atol=1e-12)
    fld = csdf.as_field(s)
    lo, hi = fld.intervals(np.array([[-0.4, -0.4, 0.0]]), np.array([[-0.3, -0.3, 0.0]]))
    assert hi[0] < 0  # wholly inside
    lo, hi = fld.intervals(np.array([[0.2, 0.2, 0.0]]), np.array([[0.5, 0.5, 0.0]]))
    assert lo[0] > 0  # wholly outside


def test_csdf_load_reads_vm_files():
    s = csdf.load(vm_path("quarter"))
    assert s.dim == 2
    assert s(np.array([[-0.2, -0.2]]))[0] < 0 < s(np.array([[0.2, 0.2]]))[0]
    assert csdf.load(str(vm_path("quarter"))).compile() == s.compile()


def test_a_loaded_field_transforms_like_any_shape():
    s = load_vm(vm_path("quarter"))
    moved = s.translate((0.5, 0.25))
    pts = np.random.default_rng(3).uniform(-1, 1, (100, 2))
    np.testing.assert_allclose(moved(pts), s(pts - [0.5, 0.25]), atol=1e-12)
    both = s | csdf.circle(0.1).translate((0.5, 0.5))
    assert both(np.array([[0.5, 0.5]]))[0] < 0


# ------------------------------------------------------------------ opcodes
def test_var_z_makes_a_3d_field():
    s = loads_vm("x var-x\ny var-y\nz var-z\nr add x y\nout add r z\n")
    assert s.dim == 3
    np.testing.assert_allclose(s(np.array([[1.0, 2.0, 4.0]])), [7.0])
    # var-z present but unused: still 3D
    assert loads_vm("z var-z\nx var-x\n").dim == 3


def _rust_round(a: float) -> float:
    """Rust's f64::round: to the nearest integer, halves away from zero (exactly)."""
    return math.copysign(float(Decimal(a).to_integral_value(rounding=ROUND_HALF_UP)), a)


UNARY = {
    "neg": lambda a: -a, "abs": abs, "recip": lambda a: 1 / a, "sqrt": math.sqrt,
    "square": lambda a: a * a, "floor": math.floor, "ceil": math.ceil, "round": _rust_round,
    "sin": math.sin, "cos": math.cos, "tan": math.tan, "asin": math.asin,
    "acos": math.acos, "atan": math.atan, "exp": math.exp, "ln": math.log,
    "not": lambda a: float(a == 0),
}
BINARY = {
    "add": lambda a, b: a + b, "sub": lambda a, b: a - b, "mul": lambda a, b: a * b,
    "div": lambda a, b: a / b, "min": min, "max": max, "atan2": math.atan2,
    "mod": lambda a, b: a % abs(b), "compare": lambda a, b: float((a > b) - (a < b)),
    "and": lambda a, b: a if a == 0 else b, "or": lambda a, b: a if a != 0 else b,
}


def test_the_opcode_table_is_complete():
    assert set(vm_mod.OPCODES) == set(UNARY) | set(BINARY)


@pytest.mark.parametrize("op", sorted(UNARY))
def test_unary_opcodes(op):
    a = {"sqrt": [0.0, 0.25, 2.0], "ln": [0.5, 1.0, 3.0], "asin": [-0.5, 0.0, 0.9],
         "acos": [-0.5, 0.0, 0.9], "recip": [-2.0, 0.5, 4.0],
         "round": [-2.5, -0.5, -0.49999999999999994, 0.5, 1.5, 2.4, 3.0],
         "not": [0.0, -0.0, 2.0, -1.0]}.get(op, [-1.7, -0.5, 0.0, 0.3, 2.5])
    s = loads_vm(f"x var-x\nout {op} x\n")
    pts = np.array([[v, 0.0] for v in a])
    np.testing.assert_allclose(s(pts, backend="numpy"), [UNARY[op](v) for v in a],
                               rtol=1e-14, atol=1e-15)


@pytest.mark.parametrize("op", sorted(BINARY))
def test_binary_opcodes(op):
    pairs = [(1.5, 0.5), (-1.25, 2.0), (0.0, 3.0), (2.0, 2.0), (-3.5, -1.5), (0.0, 0.0),
             (0.7, -0.2)]
    if op in ("div", "mod"):
        pairs = [p for p in pairs if p[1] != 0]
    s = loads_vm(f"x var-x\ny var-y\nout {op} x y\n")
    got = s(np.array(pairs), backend="numpy")
    np.testing.assert_allclose(got, [BINARY[op](a, b) for a, b in pairs], rtol=1e-14,
                               atol=1e-15)


def test_format_details():
    # comments, blank lines, any name tokens, CRLF line ends, indentation, numbers
    text = ("# comment\r\n\r\n  a.b var-x\r\nc!2 const -1.5e-1\n\t# indented comment\n"
            "out add a.b c!2\n")
    s = loads_vm(text)
    np.testing.assert_allclose(s(np.array([[1.0, 0.0]])), [0.85])
    for tok, v in [("inf", math.inf), ("-Infinity", -math.inf), ("+.5", 0.5), ("3.", 3.0),
                   ("1E3", 1000.0)]:
        got = loads_vm(f"x var-x\nc const {tok}\nout add x c\n")(np.array([[0.0, 0.0]]))
        assert got[0] == v
    assert math.isnan(loads_vm("x var-x\nc const NaN\nout add x c\n")(
        np.array([[0.0, 0.0]]))[0])


# ------------------------------------------------------------------ errors
@pytest.mark.parametrize("text, line, col, words", [
    ("x var-x\ny frob x\n", 2, 3, "unknown opcode 'frob'"),
    ("x var-x\ny sqr x\n", 2, 3, "did you mean 'sqrt' or 'square'"),
    ("x var-x\ny add x\n", 2, 6, "add takes 2 argument(s), got 1"),
    ("x var-x\ny neg x x\n", 2, 9, "neg takes 1 argument(s), got 2"),
    ("x var-x 3\n", 1, 9, "var-x takes 0 argument(s), got 1"),
    ("c const\n", 1, 8, "const takes a number, got 0"),
    ("x var-x\ny add x q\n", 2, 9, "undefined node 'q'"),
    ("x var-x\nx var-y\n", 2, 1, "node 'x' is defined twice"),
    ("c const 1.2.3\n", 1, 9, "const expects a number, got '1.2.3'"),
    ("c const 1_000\n", 1, 9, "const expects a number"),
    ("c const 0x10\n", 1, 9, "const expects a number"),
    ("# nothing\n\n", 0, 0, "no nodes"),
    ("", 0, 0, "no nodes"),
    ("x var-x\n  lonely\n", 2, 9, "has no opcode"),
])
def test_errors_are_located(text, line, col, words):
    with pytest.raises(ModelError) as info:
        loads_vm(text, name="m.vm")
    err = info.value
    assert words in str(err)
    assert (err.line, err.column) == (line, col)
    assert err.file == "m.vm"
    if line:
        assert f"m.vm:{line}:{col}:" in str(err)


def test_errors_from_files_name_the_file(tmp_path):
    p = tmp_path / "bad.vm"
    p.write_text("x var-x\ny add x x x\n")
    with pytest.raises(CsdfError, match=r"bad\.vm:2:11: add takes 2"):
        load_vm(p)
    with pytest.raises(ModelError, match="cannot read"):
        load_vm(tmp_path / "missing.vm")
    p.write_bytes(b"x var-x\n\xff\n")
    with pytest.raises(ModelError, match="not UTF-8"):
        load_vm(p)


def test_limits(monkeypatch):
    monkeypatch.setattr(vm_mod, "MAX_VM_NODES", 3)
    with pytest.raises(ModelError, match="more than 3 nodes") as info:
        loads_vm("a var-x\nb var-y\nc add a b\nd mul c c\n")
    assert info.value.line == 4
    monkeypatch.setattr(vm_mod, "MAX_VM_BYTES", 10)
    with pytest.raises(ModelError, match="the limit is 10"):
        loads_vm("a var-x\nb var-y\n")
    monkeypatch.setattr(vm_mod, "MAX_VM_BYTES", 1000)
    monkeypatch.setattr(vm_mod, "MAX_VM_NODES", 1000)
    monkeypatch.setattr(vm_mod, "MAX_EXPR_NODES", 5)
    lines = ["a var-x"] + [f"n{i} add {'a' if i == 0 else f'n{i - 1}'} a" for i in range(20)]
    with pytest.raises(ModelError, match="more than 5 expression nodes") as info:
        loads_vm("\n".join(lines))
    assert info.value.line > 1


def test_the_default_limits_admit_prospero():
    assert vm_mod.MAX_VM_NODES >= 7866
    assert vm_mod.MAX_VM_BYTES >= 64 * 1024 * 1024


# ------------------------------------------------------------------ writing
@pytest.mark.parametrize("name", FILES)
def test_round_trip_is_bit_identical(name, tmp_path):
    first = load_vm(vm_path(name))
    out = tmp_path / f"{name}.vm"
    save_vm(first, out)
    again = load_vm(out)
    assert again.dim == first.dim
    pts = np.random.default_rng(4).uniform(-1.2, 1.2, (3000, 2))
    assert np.array_equal(first(pts, backend="numpy"), again(pts, backend="numpy"))
    assert again.compile() == first.compile()
    # and a third time, through the text form and csdf.load
    assert csdf.load(out).compile() == loads_vm(dumps_vm(again)).compile()


def _check_saved(shape, pts, exact=True):
    text = dumps_vm(shape)
    back = loads_vm(text)
    assert back.dim == shape.dim
    a, b = shape(pts, backend="numpy"), back(pts, backend="numpy")
    if exact:
        assert np.array_equal(a, b)
    else:
        np.testing.assert_allclose(a, b, atol=1e-12)
    return text


def test_saving_primitives():
    rng = np.random.default_rng(5)
    p2, p3 = rng.uniform(-1, 1, (500, 2)), rng.uniform(-1.5, 1.5, (500, 3))
    text = _check_saved(csdf.circle(0.5), p2)
    assert "var-z" not in text and text.rstrip().splitlines()[-1].split()[1] == "sub"
    assert "exactness exact" in text
    assert "var-z" in _check_saved(csdf.sphere(1), p3)
    _check_saved(csdf.box(1).rotate(0.3, 'x') - csdf.cylinder(0.3, 2), p3)
    # ops Fidget lacks: step (polygon), sign, mod and atan2 (repeat_polar)
    poly = csdf.polygon([(0, 0.5), (-0.5, -0.5), (0.3, -0.2), (0.5, -0.5)])
    text = _check_saved(poly, p2)
    assert "compare" in text
    text = _check_saved(csdf.circle(0.1).translate((0.5, 0)).repeat_polar(5), p2)
    assert "atan2" in text and "floor" in text


def test_saving_a_program_and_parameters(tmp_path):
    r = csdf.param("r", 0.5, 0.1, 1.0)
    shape = csdf.circle(r)
    pts = np.random.default_rng(6).uniform(-1, 1, (200, 2))
    text = dumps_vm(shape.compile(), params={"r": 0.25})
    assert "r = 0.25" in text
    np.testing.assert_array_equal(loads_vm(text)(pts), shape(pts, r=0.25))
    # without params= the defaults are written
    np.testing.assert_array_equal(loads_vm(dumps_vm(shape))(pts), csdf.circle(0.5)(pts))
    with pytest.raises(csdf.ParamError):
        dumps_vm(shape, params={"r": 5.0})
    with pytest.raises(CsdfError, match="expects a Shape or Program"):
        dumps_vm(42)


def test_saving_3d_fields_that_ignore_z_and_constant_fields():
    s = expr_shape(X * 2.0 - 1.0, dim=3)
    text = dumps_vm(s)
    back = loads_vm(text)
    assert back.dim == 3
    assert text.rstrip().splitlines()[-1].split()[1] == "sub"  # the output stays last
    s = expr_shape(X - X + 3.0, dim=2)
    np.testing.assert_array_equal(loads_vm(dumps_vm(s))(np.zeros((2, 2))), [3.0, 3.0])
    s = expr_shape(Y, dim=2)
    assert dumps_vm(s).rstrip().splitlines()[-1] == "_0 var-y"


# ------------------------------------------------------------------ the expression shape
def test_expr_shape_api():
    e = csdf.expr.sqrt(X * X + Y * Y) - 1.0
    assert expr_dim(e) == 2 and expr_dim(e + Z) == 3
    s = expr_shape(e)
    assert (s.dim, s.exactness, s.lipschitz, s.bounds) == (2, "neither", math.inf, None)
    s3 = expr_shape(e, dim=3, exactness="exact", lipschitz=1.0, bounds=[[-1] * 3, [1] * 3])
    assert s3.dim == 3 and s3.bounds.shape == (2, 3)
    assert substitute(e, (X, Y, Z)) is e
    moved = substitute(e, (X - 1.0, Y))
    assert moved is (csdf.expr.sqrt((X - 1.0) * (X - 1.0) + Y * Y) - 1.0)
    for bad in [dict(dim=4), dict(exactness="nope"), dict(lipschitz=-1.0),
                dict(bounds=[[0, 0, 0], [1, 1, 1]])]:
        with pytest.raises(csdf.ShapeError):
            expr_shape(e, **bad)
    with pytest.raises(csdf.ShapeError, match="may not use z"):
        expr_shape(e + Z, dim=2)
    with pytest.raises(csdf.ShapeError):
        expr_shape(1.0)


def test_cli_compiles_to_vm_and_back(tmp_path):
    """`csdf compile model.csdf -o x.vm`, then `csdf info x.vm`: the same field."""
    from typer.testing import CliRunner

    from csdf.cli import app

    model = tmp_path / "m.csdf"
    model.write_text("export sphere(1) - box(1.5)\n")
    out = tmp_path / "m.vm"
    r = CliRunner().invoke(app, ["compile", str(model), "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert "as Fidget .vm" in r.output
    back = csdf.load(out)
    pts = np.random.default_rng(3).uniform(-1.5, 1.5, size=(500, 3))
    np.testing.assert_array_equal(back(pts), csdf.load(model)(pts))
    r = CliRunner().invoke(app, ["compile", str(model), "-o", str(tmp_path / "m.txt")])
    assert r.exit_code == 2 and ".csdfb, .csdft or .vm" in r.output
