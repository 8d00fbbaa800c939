"""Property-based tests of the compiled tape and its two serialised forms.

1. Round trips: ``Program.from_bytes(p.to_bytes())`` and ``Program.from_text(p.disassemble())``
   give the same bytes and bit-identical values, gradients and parameter Jacobians, for
   random expression DAGs (every op, 0-3 parameters) and random shapes of the public API.
2. The tape computes what the expression DAG means: an independent recursive NumPy
   interpreter of the (already folded) DAG agrees with the compiled program.
3. Decoder robustness: random bytes, every truncation, single- and multi-byte mutations
   (raw, and with the CRC recomputed so that the structural checks run), header,
   parameter, instruction and call field mutations, instruction reordering. Every input
   either raises :class:`csdf.BytecodeError` (nothing else) or gives a program that is
   canonical (re-encodes to the same bytes), never reads a register before writing it,
   and evaluates without raising. The same for ``from_text`` on mutated listings.

``CSDF_FUZZ_EXAMPLES=<n>`` raises every hypothesis test to at least ``n`` examples for
long fuzzing runs (the default keeps the whole module well under a minute).
"""

from __future__ import annotations

import math
import os
import struct
import zlib
from functools import cache

import numpy as np
import pytest
from hypothesis import HealthCheck, given, note, settings
from hypothesis import strategies as st

import csdf
from csdf import BytecodeError, Program
from csdf.compiler.tape import compile_expr
from csdf.expr import Expr, X, Y, Z, const, expr_params, make, param
from csdf.ops import OPS, OPS_BY_CODE

try:  # tests/ as a package or as a plain directory on sys.path
    from . import strategies as S
except ImportError:
    import strategies as S

_FUZZ = int(os.environ.get("CSDF_FUZZ_EXAMPLES", "0") or 0)
# huge constants and points overflow to inf when evaluated in float32; NumPy warns
pytestmark = pytest.mark.filterwarnings("ignore:overflow encountered in cast:RuntimeWarning")
_SLOW_OK = [HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much]


def _settings(n: int):
    return settings(max_examples=max(n, _FUZZ), deadline=None, suppress_health_check=_SLOW_OK)


INSTR_REF = 0x80000000
HEADER = struct.Struct("<4sHHHHHHIId")
HEADER_FIELDS = {  # name: (offset, struct format)
    "version": (4, "<H"), "flags": (6, "<H"), "n_params": (8, "<H"), "n_consts": (10, "<H"),
    "n_regs": (12, "<H"), "output": (14, "<H"), "n_instr": (16, "<I"), "n_calls": (20, "<I"),
    "lipschitz": (24, "<d"),
}
INT_MAX = {"<B": 0xFF, "<H": 0xFFFF, "<I": 0xFFFFFFFF}
SPECIAL_F64 = (math.nan, -math.nan, math.inf, -math.inf, -0.0, 0.0, -1.0, 1.0, 5e-324,
               1e308, -1e308, 0.5)


# =============================================================================== helpers
def with_crc(body: bytes) -> bytes:
    """``body`` followed by its little-endian zlib CRC-32 (the format's trailer)."""
    body = bytes(body)
    return body + struct.pack("<I", zlib.crc32(body) & 0xFFFFFFFF)


def f64_bits(v: float) -> bytes:
    return struct.pack("<d", v)


def assert_bitwise_equal(a, b, what: str) -> None:
    """Same shape, dtype, values, NaN positions, signs of zero and NaN payloads."""
    a, b = np.asarray(a), np.asarray(b)
    assert a.shape == b.shape, f"{what}: shapes {a.shape} != {b.shape}"
    assert a.dtype == b.dtype, f"{what}: dtypes {a.dtype} != {b.dtype}"
    np.testing.assert_array_equal(a, b, err_msg=what)
    assert a.tobytes() == b.tobytes(), f"{what}: equal values but different bits"


def all_outputs(prog: Program, pts: np.ndarray, pv: dict) -> dict[str, np.ndarray]:
    # one backend for bitwise comparisons: 'auto' may pick another backend per mode
    # (whichever kernel is ready), and backends may differ in NaN sign bits
    # (the strategies draw values inside and outside the parameters' ranges)
    be, kw = "numpy", {"check_ranges": False}
    v = prog(pts, pv, backend=be, **kw)
    g = prog.gradient(pts, pv, backend=be, **kw)
    j = prog.param_jacobian(pts, pv, backend=be, **kw)
    v2, g2, j2 = prog.value_grad_param_jacobian(pts, pv, backend=be, **kw)
    return {"value": v, "grad": g, "jac": j, "value(all)": v2, "grad(all)": g2, "jac(all)": j2}


def assert_same_outputs(p: Program, q: Program, pts: np.ndarray, pv: dict) -> None:
    a, b = all_outputs(p, pts, pv), all_outputs(q, pts, pv)
    for key in a:
        assert_bitwise_equal(a[key], b[key], key)
    assert_modes_agree(a)


def assert_modes_agree(out: dict[str, np.ndarray]) -> None:
    """The one-pass ``value_grad_param_jacobian`` agrees with the three separate calls
    where everything is finite (with a NaN or infinite intermediate the two passes may
    legitimately mix ``0 * inf`` differently, see the module report)."""
    assert_bitwise_equal(out["value"], out["value(all)"], "value vs value(all)")
    ok = np.isfinite(out["value"])
    ok &= np.isfinite(out["grad"]).reshape(len(ok), -1).all(axis=1)
    ok &= np.isfinite(out["jac"]).reshape(len(ok), -1).all(axis=1)
    for key in ("grad", "jac"):
        np.testing.assert_array_equal(out[key][ok], out[key + "(all)"][ok],
                                      err_msg=f"{key} vs {key}(all)")


def tape_problems(prog: Program) -> list[str]:
    """Independent static check of a program's tape (what the validator must guarantee):
    known opcodes, operands in range, no register read before it is written, writes only
    to registers, an output that holds a value, no ``z`` read by a 2D program."""
    n_fixed = 3 + len(prog.params) + len(prog.consts)
    n_slots = n_fixed + prog.n_regs
    written: set[int] = set()
    problems = []
    for k, (op, dst, a, b) in enumerate(np.asarray(prog.code).tolist()):
        info = OPS_BY_CODE.get(op)
        if info is None:
            problems.append(f"instruction {k}: opcode {op}")
            continue
        reads = (a, b) if info.arity == 2 else (a,)
        for s in reads:
            if not 0 <= s < n_slots:
                problems.append(f"instruction {k}: operand slot {s} out of range")
            elif s >= n_fixed and s not in written:
                problems.append(f"instruction {k}: reads slot {s} before it is written")
        if prog.dim == 2 and 2 in reads:
            problems.append(f"instruction {k}: 2D program reads z")
        if not n_fixed <= dst < n_slots:
            problems.append(f"instruction {k}: writes slot {dst}")
        written.add(dst)
    if not (0 <= prog.output < n_fixed or prog.output in written):
        problems.append(f"output slot {prog.output} holds no value")
    return problems


_EVAL_PTS = np.array([
    [0.0, 0.0, 0.0], [0.3, -1.2, 2.0], [-0.0, 1e300, -5.0], [np.nan, 0.0, 1.0],
    [np.inf, -np.inf, 0.5], [1.0, 1.0, 1.0],
])
_EVAL_PTS_32 = np.where(np.abs(_EVAL_PTS) > 1e30, np.float32(3e38), _EVAL_PTS).astype(np.float32)


def exercise(prog: Program, origin: str) -> None:
    """Everything a caller may do with an accepted program must work."""
    try:
        problems = tape_problems(prog)
        assert not problems, f"accepted program has tape problems: {problems}"
        inputs = [_EVAL_PTS, _EVAL_PTS_32]
        if prog.dim == 2:
            inputs.append(_EVAL_PTS[:, :2])
        # any value, inside its range or not (the evaluators must cope with both)
        pv_sets = [{}, {p.name: -1.5 for p in prog.params}]
        for pts in inputs:
            for pv in pv_sets:
                v = prog(pts, pv, check_ranges=False)
                g = prog.gradient(pts, pv, check_ranges=False)
                j = prog.param_jacobian(pts, pv, check_ranges=False)
                assert v.shape == (len(pts),)
                assert g.shape == pts.shape
                assert j.shape == (len(pts), len(prog.params))
        prog.counts("expanded")
        prog.counts("primitive")
        prog.disassemble()
        repr(prog)
    except Exception as exc:  # add the input that produced the program
        raise AssertionError(f"{type(exc).__name__}: {exc}\n  program from {origin}") from exc


def check_bytes(data: bytes, *, origin: str = "") -> Program | None:
    """``from_bytes`` must raise BytecodeError or return a canonical, safe program."""
    data = bytes(data)
    where = f"{origin} bytes {data.hex()}"
    try:
        prog = Program.from_bytes(data)
    except BytecodeError:
        return None
    except Exception as exc:
        raise AssertionError(f"from_bytes raised {type(exc).__name__}: {exc}\n  {where}") from exc
    exercise(prog, where)
    assert prog.to_bytes() == data, f"accepted bytes do not re-encode identically: {where}"
    return prog


def check_text(text: str, *, origin: str = "") -> Program | None:
    """``from_text`` must raise BytecodeError or return a safe program that survives the
    binary round trip."""
    where = f"{origin} listing {text!r}"
    try:
        prog = Program.from_text(text)
    except BytecodeError:
        return None
    except Exception as exc:
        raise AssertionError(f"from_text raised {type(exc).__name__}: {exc}\n  {where}") from exc
    exercise(prog, where)
    try:
        raw = prog.to_bytes()
    except Exception as exc:
        raise AssertionError(
            f"from_text accepted a program that to_bytes cannot encode: "
            f"{type(exc).__name__}: {exc}\n  {where}"
        ) from exc
    assert Program.from_bytes(raw).to_bytes() == raw
    return prog


# =============================================================================== layout
def layout(data: bytes) -> dict:
    """Offsets of every field of a *valid* program (an independent reading of the format:
    header 32 bytes, params, f64 constants, 8-byte instructions, calls, in version 2 the
    bounds (2 x dim f64), CRC)."""
    (magic, version, flags, n_p, n_c, n_r, out, n_i, n_calls, lip) = HEADER.unpack_from(data, 0)
    assert magic == b"CSDF"
    pos = HEADER.size
    params = []
    for _ in range(n_p):
        n = data[pos]
        params.append({"len": pos, "name": pos + 1, "name_len": n, "default": pos + 1 + n,
                       "lo": pos + 9 + n, "hi": pos + 17 + n})
        pos += 1 + n + 24
    consts = pos
    pos += 8 * n_c
    code = pos
    pos += 8 * n_i
    calls = []
    for _ in range(n_calls):
        n = data[pos]
        (n_in,) = struct.unpack_from("<H", data, pos + 5 + n)
        calls.append({"len": pos, "name": pos + 1, "name_len": n, "out": pos + 1 + n,
                      "n_in": pos + 5 + n, "inputs": pos + 7 + n, "count": n_in})
        pos += 7 + n + 4 * n_in
    bounds = None
    if version == 2:
        bounds = pos
        pos += 2 * (2 if flags & 4 else 3) * 8
    assert pos == len(data) - 4, "layout does not cover the program"
    return {"n_params": n_p, "n_consts": n_c, "n_regs": n_r, "output": out, "n_instr": n_i,
            "n_calls": n_calls, "params": params, "consts": consts, "code": code,
            "calls": calls, "bounds": bounds, "n_fixed": 3 + n_p + n_c, "end": pos}


def put(buf: bytearray, offset: int, fmt: str, value) -> None:
    size = struct.calcsize(fmt)
    if offset + size <= len(buf):
        buf[offset:offset + size] = struct.pack(fmt, value)


# =============================================================================== corpus
def _all_ops_expr() -> tuple[Expr, list]:
    a = param("a", 0.5, -1.0, 1.0)
    terms = [make(name, X + a * Y) for name in S.UNARY_OPS]
    terms += [make(name, Y - 0.25, Z * a) for name in S.BINARY_OPS]
    terms.append(make("mul", const(-2.5), make("sqrt", const(-1.0))))  # folded NaN constant
    root = terms[0]
    for t in terms[1:]:
        root = make("add", root, t)
    calls = [("first", terms[0], (X, Y, a)), ("second", terms[3], (terms[1], Z))]
    return root, calls


@cache
def corpus() -> dict[str, Program]:
    """A few valid programs covering every section, flag and opcode."""
    r = csdf.param("r", 0.8, 0.2, 2.0)
    k = csdf.param("k", 0.1, 0.01, 0.5)
    radius = csdf.param("radius", 0.8, 0.2, 2.0)
    root, calls = _all_ops_expr()
    blend = csdf.union(csdf.box(1.0).translate((0.2, r, 0.0)), csdf.torus(r, 0.2), k=k)
    return {
        "x_only": compile_expr(X),
        "const_root_2d": compile_expr(const(2.5), dim=2, exactness="bound", lipschitz=0.0),
        "sphere": csdf.sphere(radius).compile(),
        "circle_2d": csdf.circle(r).compile(),
        "all_ops": compile_expr(root, exactness="neither", lipschitz=math.inf, calls=calls),
        "blend": blend.compile(),
    }


SMALL = ("x_only", "const_root_2d", "sphere", "circle_2d")


def test_corpus_is_valid_and_covers_every_opcode():
    progs = corpus()
    used = set()
    for name, prog in progs.items():
        raw = prog.to_bytes()
        assert layout(raw)["end"] == len(raw) - 4
        assert check_bytes(raw, origin=name) == prog
        used |= {int(op) for op in prog.code[:, 0]}
    assert used == set(OPS_BY_CODE)


# =============================================================================== interpreter
def _step(a):
    return np.where(np.isnan(a), np.nan, np.where(a >= 0, 1.0, 0.0))


_REF = {
    "neg": lambda a: -a,
    "abs": np.absolute,
    "sqrt": np.sqrt,
    "square": lambda a: a * a,
    "sin": np.sin,
    "cos": np.cos,
    "tan": np.tan,
    "asin": np.arcsin,
    "acos": np.arccos,
    "atan": np.arctan,
    "exp": np.exp,
    "log": np.log,
    "floor": np.floor,
    "step": _step,
    "sign": np.sign,
    "add": lambda a, b: a + b,
    "sub": lambda a, b: a - b,
    "mul": lambda a, b: a * b,
    "div": lambda a, b: a / b,
    "min": np.minimum,
    "max": np.maximum,
    "atan2": np.arctan2,
    "mod": lambda a, b: a - b * np.floor(a / b),
}


def interpret(root: Expr, pts: np.ndarray, values: dict[str, float]) -> np.ndarray:
    """Evaluate the expression DAG directly (float64), children before parents, each
    node once. Parameters and constants stay scalars, x/y/z are the point columns.
    Points with a NaN coordinate and any NaN parameter give NaN (documented rule)."""
    n = len(pts)
    cols = {"x": pts[:, 0], "y": pts[:, 1],
            "z": pts[:, 2] if pts.shape[1] == 3 else np.zeros(n)}
    memo: dict[int, object] = {}
    stack = [root]
    with np.errstate(all="ignore"):
        while stack:
            node = stack[-1]
            if id(node) in memo:
                stack.pop()
                continue
            pending = [a for a in node.args if id(a) not in memo]
            if pending:
                stack.extend(pending)
                continue
            stack.pop()
            if node.op in cols:
                val = cols[node.op]
            elif node.op == "const":
                val = np.float64(node.value)
            elif node.op == "param":
                val = np.float64(values[node.value.name])
            else:
                val = _REF[node.op](*[memo[id(a)] for a in node.args])
            memo[id(node)] = val
    out = np.array(np.broadcast_to(np.asarray(memo[id(root)], np.float64), (n,)))
    bad = np.isnan(pts).any(axis=1)
    if any(math.isnan(v) for v in values.values()):
        bad[:] = True
    out[bad] = np.nan
    return out


def full_values(root: Expr, given: dict[str, float]) -> dict[str, float]:
    vals = {p.name: p.default for p in expr_params(root)}
    vals.update(given)
    return vals


def assert_matches_interpreter(prog: Program, root: Expr, pts: np.ndarray, pv: dict):
    got = prog(pts, pv, check_ranges=False)  # (any value: in range or not)
    want = interpret(root, pts, full_values(root, pv))
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=0, equal_nan=True)


def test_interpreter_covers_every_op():
    assert set(_REF) == set(OPS)


@pytest.mark.parametrize("op", S.ALL_OPS)
def test_each_op_matches_interpreter(op):
    a = param("a", 0.7, -2.0, 2.0)
    specials = np.array(S.POINT_SPECIALS + S.SPECIAL_FLOATS)
    grid = np.stack(np.meshgrid(specials, specials, indexing="ij"), -1).reshape(-1, 2)
    pts = np.column_stack([grid, np.full(len(grid), 0.25)])
    args = [(X,), (X, Y)][OPS[op].arity - 1]
    for root in (make(op, *args), make(op, *(e * a + Z for e in args))):
        prog = compile_expr(root)
        for pv in ({}, {"a": -0.0}, {"a": 1e300}):
            if prog.params or not pv:
                assert_matches_interpreter(prog, root, pts, pv)


@_settings(150)
@given(root=S.expr_dags(), pts=S.points(), data=st.data())
def test_expr_tape_matches_interpreter(root, pts, data):
    prog = compile_expr(root)
    note(prog.disassemble())
    pv = data.draw(S.param_values(prog.params))
    assert_matches_interpreter(prog, root, pts, pv)


@_settings(60)
@given(shape=S.shapes(), pts=S.points(), data=st.data())
def test_shape_tape_matches_interpreter(shape, pts, data):
    prog = shape.compile()
    pv = data.draw(S.param_values(prog.params))
    assert_matches_interpreter(prog, shape.expr, pts, pv)


@_settings(30)
@given(shape=S.shapes_2d(), pts=S.points(dim=2), data=st.data())
def test_2d_shape_tape_matches_interpreter(shape, pts, data):
    prog = shape.compile()
    assert prog.dim == 2
    pv = data.draw(S.param_values(prog.params))
    assert_matches_interpreter(prog, shape.expr, pts, pv)


# =============================================================================== round trips
def _uses_z(root: Expr) -> bool:
    seen, stack = set(), [root]
    while stack:
        n = stack.pop()
        if n is Z:
            return True
        if id(n) not in seen:
            seen.add(id(n))
            stack.extend(n.args)
    return False


@st.composite
def compiled_exprs(draw):
    """A compiled random DAG with random metadata, dimension and primitive calls."""
    root = draw(S.expr_dags())
    dim = 2 if not _uses_z(root) and draw(st.booleans()) else 3
    exactness = draw(st.sampled_from(("exact", "bound", "neither")))
    lipschitz = draw(st.one_of(st.sampled_from((0.0, -0.0, 1.0, math.inf, 5e-324)),
                               st.floats(0.0, 1e308)))
    ops = []
    seen, stack = set(), [root]
    while stack:
        n = stack.pop()
        if id(n) not in seen:
            seen.add(id(n))
            ops.append(n)
            stack.extend(n.args)
    candidates = [n for n in ops if n.op in OPS]
    calls = []
    if candidates:
        for i in range(draw(st.integers(0, 3))):
            out = draw(st.sampled_from(candidates))
            inputs = tuple(draw(st.lists(st.sampled_from(ops), max_size=4)))
            calls.append((f"prim{i}", out, inputs))
    return compile_expr(root, dim=dim, exactness=exactness, lipschitz=lipschitz, calls=calls)


def _points_for(prog: Program, pts: np.ndarray, flat: bool) -> np.ndarray:
    return pts[:, :2] if prog.dim == 2 and flat else pts


def check_bytes_roundtrip(prog: Program, pts: np.ndarray, pv: dict) -> None:
    raw = prog.to_bytes()
    back = Program.from_bytes(raw)
    assert back.to_bytes() == raw
    assert back == prog and hash(back) == hash(prog)
    assert back.disassemble() == prog.disassemble()
    assert_same_outputs(prog, back, pts, pv)


def check_text_roundtrip(prog: Program, pts: np.ndarray, pv: dict) -> None:
    text = prog.disassemble()
    again = Program.from_text(text)
    assert again.to_bytes() == prog.to_bytes(), "from_text(disassemble(p)) is not p"
    assert again.disassemble() == text
    assert_same_outputs(prog, again, pts, pv)


@_settings(120)
@given(prog=compiled_exprs(), pts=S.points(), flat=st.booleans(), data=st.data())
def test_expr_bytes_roundtrip(prog, pts, flat, data):
    note(prog.disassemble())
    pv = data.draw(S.param_values(prog.params))
    check_bytes_roundtrip(prog, _points_for(prog, pts, flat), pv)


@_settings(120)
@given(prog=compiled_exprs(), pts=S.points(), flat=st.booleans(), data=st.data())
def test_expr_text_roundtrip(prog, pts, flat, data):
    note(prog.disassemble())
    pv = data.draw(S.param_values(prog.params))
    check_text_roundtrip(prog, _points_for(prog, pts, flat), pv)


@_settings(60)
@given(shape=S.shapes(), pts=S.points(), data=st.data())
def test_shape_bytes_and_text_roundtrip(shape, pts, data):
    prog = shape.compile()
    pv = data.draw(S.param_values(prog.params))
    check_bytes_roundtrip(prog, pts, pv)
    check_text_roundtrip(prog, pts, pv)


@_settings(30)
@given(shape=S.shapes_2d(), pts=S.points(), flat=st.booleans(), data=st.data())
def test_2d_shape_bytes_and_text_roundtrip(shape, pts, flat, data):
    prog = shape.compile()
    pv = data.draw(S.param_values(prog.params))
    pts = _points_for(prog, pts, flat)
    check_bytes_roundtrip(prog, pts, pv)
    check_text_roundtrip(prog, pts, pv)


@_settings(30)
@given(shape=S.shapes(max_depth=2), pts=S.points(allow_nonfinite=False))
def test_float32_points_roundtrip(shape, pts):
    prog = shape.compile()
    with np.errstate(over="ignore"):
        p32 = pts.astype(np.float32)
    back = Program.from_bytes(prog.to_bytes())
    again = Program.from_text(prog.disassemble())
    for other in (back, again):
        assert_same_outputs(prog, other, p32, {})
        assert prog(p32).dtype == np.float32


# =============================================================================== from_bytes fuzz
@pytest.mark.parametrize("value", ["CSDF", None, 3, [1, 2], 1.5, {"a": 1}])
def test_from_bytes_rejects_non_bytes(value):
    with pytest.raises(BytecodeError):
        Program.from_bytes(value)


@_settings(300)
@given(data=st.one_of(
    st.binary(max_size=200),
    st.binary(max_size=200).map(lambda b: b"CSDF" + b),
    st.binary(max_size=200).map(lambda b: with_crc(b"CSDF" + b)),
))
def test_from_bytes_random_bytes(data):
    check_bytes(data, origin="random")


@st.composite
def random_structured(draw):
    """A header with small random counts, random sections and a correct CRC, so that
    decoding goes past the header."""
    small = st.integers(0, 6)
    fields = (
        b"CSDF", draw(st.sampled_from((1, 1, 1, 0, 2))), draw(st.integers(0, 8)), draw(small),
        draw(small), draw(small), draw(st.integers(0, 20)), draw(small), draw(st.integers(0, 2)),
        draw(st.sampled_from(SPECIAL_F64)),
    )
    tail = b""
    for _ in range(fields[3]):
        name = draw(st.sampled_from((b"a", b"b", b"r", b"\n", b"", b"points", b"\xff", b"a\n")))
        vals = draw(st.lists(st.sampled_from(SPECIAL_F64), min_size=3, max_size=3))
        tail += bytes([len(name)]) + name + struct.pack("<3d", *vals)
    tail += b"".join(f64_bits(draw(st.sampled_from(SPECIAL_F64))) for _ in range(fields[4]))
    codes = st.one_of(st.sampled_from(sorted(OPS_BY_CODE)), st.integers(0, 255))
    for _ in range(fields[7]):
        tail += struct.pack("<BBHHH", draw(codes), draw(st.sampled_from((0, 0, 0, 1))),
                            draw(st.integers(0, 24)), draw(st.integers(0, 24)),
                            draw(st.integers(0, 24)))
    for _ in range(fields[8]):
        name = draw(st.sampled_from((b"f", b"g", b"", b"f\n")))
        ins = draw(st.lists(st.one_of(st.integers(0, 24), st.integers(0, 8).map(
            lambda i: i | INSTR_REF)), max_size=3))
        tail += bytes([len(name)]) + name + struct.pack(
            f"<IH{len(ins)}I", draw(st.integers(0, 8)), len(ins), *ins)
    tail += draw(st.sampled_from((b"", b"", b"\x00", b"junk")))
    return with_crc(HEADER.pack(*fields) + tail)


@_settings(400)
@given(data=random_structured())
def test_from_bytes_random_structured(data):
    check_bytes(data, origin="structured")


@pytest.mark.parametrize("name", list(corpus()))
def test_every_truncation_is_rejected(name):
    raw = corpus()[name].to_bytes()
    for n in range(len(raw)):
        for data in (raw[:n], with_crc(raw[:max(n - 4, 0)])):
            with pytest.raises(BytecodeError):
                Program.from_bytes(data)
    # extra bytes after a valid body are rejected too
    for extra in (b"\x00", b"\x00" * 8, raw[32:40]):
        with pytest.raises(BytecodeError):
            Program.from_bytes(with_crc(raw[:-4] + extra))


@pytest.mark.parametrize("name", SMALL + ("all_ops",))
def test_every_single_byte_mutation(name):
    """Every byte position, a few replacement values each: raw mutations break the CRC
    (always rejected); with the CRC recomputed the structural checks must hold."""
    raw = corpus()[name].to_bytes()
    body = raw[:-4]
    accepted = 0
    for i in range(len(raw)):
        for v in {raw[i] ^ 0x01, raw[i] ^ 0x80, 0x00, 0xFF, (raw[i] + 1) & 0xFF, 0x0A}:
            if v == raw[i]:
                continue
            data = bytearray(raw)
            data[i] = v
            with pytest.raises(BytecodeError):
                Program.from_bytes(bytes(data))
            if i < len(body):
                accepted += check_bytes(with_crc(data[:-4]), origin=f"{name}[{i}]={v}") is not None
    assert accepted > 0  # e.g. constant bits: the structural path was reached


@st.composite
def multi_byte_mutations(draw):
    name = draw(st.sampled_from(sorted(corpus())))
    raw = bytearray(corpus()[name].to_bytes())
    body = raw[:-4]
    for _ in range(draw(st.integers(1, 6))):
        kind = draw(st.sampled_from(("set", "set", "xor", "insert", "delete", "copy")))
        if not body:
            break
        i = draw(st.integers(0, len(body) - 1))
        if kind == "set":
            body[i] = draw(st.integers(0, 255))
        elif kind == "xor":
            body[i] ^= 1 << draw(st.integers(0, 7))
        elif kind == "insert":
            body[i:i] = draw(st.binary(min_size=1, max_size=9))
        elif kind == "delete":
            del body[i:i + draw(st.integers(1, 9))]
        else:
            j = draw(st.integers(0, len(body) - 1))
            n = draw(st.integers(1, 8))
            body[i:i + n] = body[j:j + n]
    if draw(st.integers(0, 4)) == 0:
        return name, bytes(body) + bytes(raw[-4:])  # stale CRC
    return name, with_crc(body)


@_settings(400)
@given(case=multi_byte_mutations())
def test_multi_byte_mutations(case):
    name, data = case
    check_bytes(data, origin=f"mutated {name}")


def _int_values(orig: int, fmt: str) -> st.SearchStrategy[int]:
    top = INT_MAX[fmt]
    near = [orig - 2, orig - 1, orig + 1, orig + 2, orig * 2, 0, 1, 2, 3, top, top - 1,
            top // 2 + 1]
    return st.one_of(st.sampled_from(sorted({v for v in near if 0 <= v <= top})),
                     st.integers(0, top))


def _f64_values() -> st.SearchStrategy[float]:
    return st.one_of(st.sampled_from(SPECIAL_F64), st.floats())


@st.composite
def field_mutations(draw):
    """Edits of whole fields (header, parameter table, constants, instructions, calls)
    with the CRC recomputed, so each edit reaches the structural validation."""
    name = draw(st.sampled_from(sorted(corpus())))
    raw = corpus()[name].to_bytes()
    lay = layout(raw)
    buf = bytearray(raw[:-4])
    edits = []
    for _ in range(draw(st.integers(1, 3))):
        area = draw(st.sampled_from(("header", "header", "param", "const", "code", "code",
                                     "call")))
        if area == "header":
            field = draw(st.sampled_from(sorted(HEADER_FIELDS)))
            off, fmt = HEADER_FIELDS[field]
            if fmt == "<d":
                value = draw(_f64_values())
            else:
                (orig,) = struct.unpack_from(fmt, buf, off)
                value = draw(_int_values(orig, fmt))
            put(buf, off, fmt, value)
            edits.append((field, value))
        elif area == "param" and lay["params"]:
            p = draw(st.sampled_from(lay["params"]))
            part = draw(st.sampled_from(("len", "name", "default", "lo", "hi")))
            if part == "len":
                value = draw(st.sampled_from((0, 1, 2, p["name_len"] + 1, 255)))
                put(buf, p["len"], "<B", value)
            elif part == "name":
                pool = (b"\n", b"_", b"9", b"-", b"\xff", b"\xc3", b"a", b"z", b" ")
                value = draw(st.sampled_from(pool))
                pos = p["name"] + draw(st.integers(0, p["name_len"] - 1))
                buf[pos:pos + 1] = value
            else:
                value = draw(_f64_values())
                put(buf, p[part], "<d", value)
            edits.append((f"param.{part}", value))
        elif area == "const" and lay["n_consts"]:
            i = draw(st.integers(0, lay["n_consts"] - 1))
            value = draw(st.one_of(_f64_values(), st.binary(min_size=8, max_size=8)))
            bits = value if isinstance(value, bytes) else f64_bits(value)
            buf[lay["consts"] + 8 * i:lay["consts"] + 8 * i + 8] = bits
            edits.append(("const", bits.hex()))
        elif area == "code" and lay["n_instr"]:
            k = draw(st.integers(0, lay["n_instr"] - 1))
            base = lay["code"] + 8 * k
            part, off, fmt = draw(st.sampled_from((
                ("opcode", 0, "<B"), ("reserved", 1, "<B"), ("dst", 2, "<H"), ("a", 4, "<H"),
                ("b", 6, "<H"))))
            n_slots = lay["n_fixed"] + lay["n_regs"]
            if part == "opcode":
                value = draw(st.one_of(st.sampled_from(sorted(OPS_BY_CODE)), st.integers(0, 255)))
            elif part == "reserved":
                value = draw(st.integers(1, 255))
            else:
                value = draw(st.one_of(st.integers(0, n_slots + 2), st.just(0xFFFF)))
            put(buf, base + off, fmt, value)
            edits.append((f"code[{k}].{part}", value))
        elif area == "call" and lay["calls"]:
            c = draw(st.sampled_from(lay["calls"]))
            part = draw(st.sampled_from(("out", "n_in", "input", "len")))
            if part == "out":
                value = draw(st.one_of(st.integers(0, lay["n_instr"] + 2),
                                       st.sampled_from((INSTR_REF, 0xFFFFFFFF))))
                put(buf, c["out"], "<I", value)
            elif part == "n_in":
                value = draw(st.sampled_from((0, c["count"] + 1, max(c["count"] - 1, 0),
                                              0xFFFF)))
                put(buf, c["n_in"], "<H", value)
            elif part == "input" and c["count"]:
                i = draw(st.integers(0, c["count"] - 1))
                value = draw(st.one_of(
                    st.integers(0, lay["n_fixed"] + 2),
                    st.integers(0, lay["n_instr"] + 2).map(lambda j: j | INSTR_REF),
                    st.sampled_from((0xFFFFFFFF, INSTR_REF - 1, 0xFFFF)),
                ))
                put(buf, c["inputs"] + 4 * i, "<I", value)
            else:
                value = draw(st.sampled_from((0, 1, 255, c["name_len"] + 1)))
                put(buf, c["len"], "<B", value)
            edits.append((f"call.{part}", value))
    return name, edits, with_crc(buf)


@_settings(500)
@given(case=field_mutations())
def test_field_mutations(case):
    name, edits, data = case
    check_bytes(data, origin=f"{name} with {edits}")


@pytest.mark.parametrize("name", ["sphere", "all_ops", "blend"])
def test_every_opcode_and_reserved_value(name):
    """Each instruction: every opcode byte value, and a non-zero reserved byte."""
    raw = corpus()[name].to_bytes()
    lay = layout(raw)
    for k in range(lay["n_instr"]):
        base = lay["code"] + 8 * k
        for op in range(256):
            buf = bytearray(raw[:-4])
            buf[base] = op
            check_bytes(with_crc(buf), origin=f"{name} code[{k}].opcode={op}")
        buf = bytearray(raw[:-4])
        buf[base + 1] = 1
        with pytest.raises(BytecodeError):
            Program.from_bytes(with_crc(buf))


@st.composite
def code_shuffles(draw):
    """Instructions swapped, duplicated, deleted or moved (n_instr kept consistent)."""
    name = draw(st.sampled_from(("sphere", "all_ops", "blend", "circle_2d")))
    raw = corpus()[name].to_bytes()
    lay = layout(raw)
    start, n = lay["code"], lay["n_instr"]
    instrs = [raw[start + 8 * k:start + 8 * k + 8] for k in range(n)]
    for _ in range(draw(st.integers(1, 3))):
        if not instrs:
            break
        kind = draw(st.sampled_from(("swap", "dup", "delete", "move")))
        i = draw(st.integers(0, len(instrs) - 1))
        j = draw(st.integers(0, len(instrs) - 1))
        if kind == "swap":
            instrs[i], instrs[j] = instrs[j], instrs[i]
        elif kind == "dup":
            instrs.insert(j, instrs[i])
        elif kind == "delete":
            del instrs[i]
        else:
            instrs.insert(j, instrs.pop(i))
    code_end = start + 8 * n
    buf = bytearray(raw[:start]) + b"".join(instrs) + raw[code_end:-4]
    put(buf, 16, "<I", len(instrs))
    return name, with_crc(buf)


def _reads_before_write(data: bytes) -> bool:
    """Independent oracle on raw bytes: does some instruction read a register that no
    earlier instruction wrote? (Only called on inputs whose layout parses.)"""
    lay = layout(data)
    n_fixed = lay["n_fixed"]
    written = set()
    for k in range(lay["n_instr"]):
        op, _, dst, a, b = struct.unpack_from("<BBHHH", data, lay["code"] + 8 * k)
        info = OPS_BY_CODE.get(op)
        reads = (a, b) if info is not None and info.arity == 2 else (a,)
        if any(s >= n_fixed and s not in written for s in reads):
            return True
        written.add(dst)
    return False


@_settings(300)
@given(case=code_shuffles())
def test_reordered_code_never_reads_unwritten_registers(case):
    name, data = case
    prog = check_bytes(data, origin=f"shuffled {name}")
    if _reads_before_write(data):
        assert prog is None, "a program reading a register before writing it was accepted"


def test_register_read_before_write_is_rejected():
    """Deterministic: move each instruction of a valid program to the front."""
    raw = corpus()["all_ops"].to_bytes()
    lay = layout(raw)
    start, n = lay["code"], lay["n_instr"]
    instrs = [raw[start + 8 * k:start + 8 * k + 8] for k in range(n)]
    rejected = 0
    for k in range(1, n):
        order = [instrs[k]] + instrs[:k] + instrs[k + 1:]
        data = with_crc(raw[:start] + b"".join(order) + raw[start + 8 * n:-4])
        if _reads_before_write(data):
            with pytest.raises(BytecodeError):
                Program.from_bytes(data)
            rejected += 1
        else:
            check_bytes(data, origin=f"all_ops with instruction {k} first")
    assert rejected > 0


# =============================================================================== from_text fuzz
@pytest.mark.parametrize("value", [b"csdf-program 1\n", None, 3, ["csdf-program 1"]])
def test_from_text_rejects_non_text(value):
    with pytest.raises(BytecodeError):
        Program.from_text(value)


TEXT_VOCAB = (
    "x", "y", "z", "r0", "r1", "r7", "r99999", "r65535", "c0", "c1", "c999999", "c00", "$r",
    "$a", "$zz", "$", "@0", "@1", "@999999999", "@", "=", "output", "param", "const", "call",
    "dim", "2", "3", "exactness", "exact", "bound", "neither", "lipschitz", "csdf-program",
    "1", "0", "-0.0", "nan", "-nan", "inf", "-inf", "1e999", "1e-400", "0x10", "1_0", ";",
    "r\u0663", "points", "r0=", *S.ALL_OPS,
)


@st.composite
def text_mutations(draw):
    name = draw(st.sampled_from(sorted(corpus())))
    lines = corpus()[name].disassemble().splitlines()
    tokens = sorted({t for line in lines for t in line.split()} | set(TEXT_VOCAB))
    for _ in range(draw(st.integers(1, 4))):
        kind = draw(st.sampled_from((
            "del_line", "dup_line", "swap_lines", "replace_token", "delete_token",
            "insert_token", "char_edit", "new_line", "comment")))
        if not lines:
            lines.append("")
        i = draw(st.integers(0, len(lines) - 1))
        words = lines[i].split()
        if kind == "del_line":
            del lines[i]
        elif kind == "dup_line":
            lines.insert(draw(st.integers(0, len(lines))), lines[i])
        elif kind == "swap_lines":
            j = draw(st.integers(0, len(lines) - 1))
            lines[i], lines[j] = lines[j], lines[i]
        elif kind == "replace_token" and words:
            words[draw(st.integers(0, len(words) - 1))] = draw(st.sampled_from(tokens))
            lines[i] = " ".join(words)
        elif kind == "delete_token" and words:
            del words[draw(st.integers(0, len(words) - 1))]
            lines[i] = " ".join(words)
        elif kind == "insert_token":
            words.insert(draw(st.integers(0, len(words))), draw(st.sampled_from(tokens)))
            lines[i] = " ".join(words)
        elif kind == "char_edit" and lines[i]:
            j = draw(st.integers(0, len(lines[i]) - 1))
            ch = draw(st.one_of(st.sampled_from("0159-+.e$@rcxn=; \t"), st.characters()))
            lines[i] = lines[i][:j] + ch + lines[i][j + 1:]
        elif kind == "new_line":
            lines.insert(draw(st.integers(0, len(lines))),
                         " ".join(draw(st.lists(st.sampled_from(tokens), max_size=5))))
        elif kind == "comment":
            lines[i] = lines[i] + " ; " + draw(st.sampled_from(tokens))
    sep = draw(st.sampled_from(("\n", "\n", "\r\n", "\n\n")))
    return name, sep.join(lines) + sep


@_settings(500)
@given(case=text_mutations())
def test_from_text_mutations(case):
    name, text = case
    check_text(text, origin=f"mutated {name}")


@_settings(200)
@given(text=st.one_of(
    st.text(max_size=200),
    st.text(max_size=200).map(lambda t: "csdf-program 1\n" + t),
    st.lists(st.lists(st.sampled_from(TEXT_VOCAB), max_size=5).map(" ".join),
             max_size=8).map(lambda ls: "csdf-program 1\n" + "\n".join(ls)),
))
def test_from_text_random_text(text):
    check_text(text, origin="random")


@pytest.mark.parametrize("name", list(corpus()))
def test_every_line_deletion_and_duplication(name):
    lines = corpus()[name].disassemble().splitlines()
    for i in range(len(lines)):
        check_text("\n".join(lines[:i] + lines[i + 1:]) + "\n", origin=f"{name} -line {i}")
        check_text("\n".join(lines[:i + 1] + lines[i:]) + "\n", origin=f"{name} +line {i}")


# =============================================================================== accepted input
# Programs accepted from mutated bytes must be first-class programs: the text listing of
# such a program loads back to the same program (the documented contract of disassemble).
@_settings(150)
@given(case=st.one_of(
    field_mutations(),
    multi_byte_mutations().map(lambda c: (c[0], "multi-byte edits", c[1])),
))
def test_accepted_bytes_roundtrip_through_text(case):
    name, edits, data = case
    prog = check_bytes(data, origin=f"{name} with {edits}")
    if prog is not None:
        check_text_roundtrip(prog, _EVAL_PTS, {})


# =============================================================================== regressions
# Minimal reproducers of the library bugs the properties above found.
def test_regression_text_keeps_nan_constant_bits():
    """sqrt(-1) folds to the default NaN of the FPU (sign bit set on x86); the listing
    writes 'nan', which reads back as +NaN: different bytes, different program."""
    prog = compile_expr(make("add", X, make("sqrt", const(-1.0))))
    assert Program.from_text(prog.disassemble()).to_bytes() == prog.to_bytes()


def test_regression_param_name_with_trailing_newline():
    """'^...$' with re.match accepts a trailing newline: 'r\\n' passes as a name."""
    with pytest.raises(csdf.ParamError):
        csdf.param("r\n", 1.0)


def test_regression_decoded_name_with_trailing_newline():
    """The decoder accepts the parameter name 'r\\n'; the listing of the program it
    returns cannot be loaded back."""
    name = b"r\n"
    body = HEADER.pack(b"CSDF", 1, 0, 1, 0, 1, 4, 1, 0, 1.0)
    body += bytes([len(name)]) + name + struct.pack("<3d", 1.0, -math.inf, math.inf)
    body += struct.pack("<BBHHH", OPS["add"].code, 0, 4, 0, 3)
    try:
        prog = Program.from_bytes(with_crc(body))
    except BytecodeError:
        return
    check_text_roundtrip(prog, _EVAL_PTS, {})


def test_regression_text_rejects_unencodable_programs():
    """from_text must not accept what to_bytes cannot write (u8 name lengths, u16 call
    input counts): today these raise struct.error from to_bytes / == / hash."""
    long_name = "a" * 300
    listings = [
        f"csdf-program 1\nparam {long_name} 1.0 -inf inf\nr0 = add x ${long_name}\noutput r0\n",
        f"csdf-program 1\nr0 = add x y\noutput r0\ncall {long_name} @0\n",
        "csdf-program 1\nr0 = add x y\noutput r0\ncall f @0 " + " x" * 70000 + "\n",
    ]
    for text in listings:
        check_text(text, origin="unencodable")


def test_regression_unused_registers_survive_text():
    """A decoded program may declare more registers than it writes; the listing has no
    way to say so and loads back as a different program."""
    raw = bytearray(corpus()["sphere"].to_bytes()[:-4])
    (n_regs,) = struct.unpack_from("<H", raw, 12)
    put(raw, 12, "<H", n_regs + 3)
    prog = check_bytes(with_crc(raw), origin="sphere with extra registers")
    if prog is not None:
        check_text_roundtrip(prog, _EVAL_PTS, {})
