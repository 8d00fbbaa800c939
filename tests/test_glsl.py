"""GLSL export (:mod:`csdf.backends.glsl`).

* the text itself: literals, uniform names and comments, one temporary per instruction;
* ``glslangValidator`` accepts the snippet (GLSL ES 3.00 and GLSL 3.30) and the Shadertoy
  shader for every shape of the catalogue (skipped when glslang-tools is missing);
* the GLSL run by another route, WebGL2 in headless Chromium (SwiftShader, float32),
  agrees with the CPU evaluator: values, ``sdf_grad`` gradients, and parameter uniforms
  (skipped when Playwright or Chromium is missing).
"""

from __future__ import annotations

import math
import os
import re
import zlib

import numpy as np
import pytest

import csdf
from catalogue import catalogue, sample_box
from csdf import expr as E
from csdf.backends.glsl import glsl_float, glsl_params, shadertoy, to_glsl, uniform_name
from csdf.compiler import compile_expr
from csdf.errors import CsdfError
from csdf.ops import OPS, OPS_BY_CODE
from glsl_runner import ES_PRELUDE, WebGL2Runner, WebGLUnavailable, glslang, validate

N_POINTS = 512
WIDTH = 64
# Tolerances (value: |GPU - CPU| / shape size; gradient: |GPU - CPU| away from kinks).
# Float32 arithmetic alone stays below 1e-7 x size; but SwiftShader's sin/cos/tan/acos
# are fast approximations (absolute error up to ~2e-4, which GLSL ES allows), so programs
# using them get a looser tier.
TOL_PLAIN = (1e-6, 2e-5)
TOL_TRIG = (3e-4, 5e-3)
TRIG_OPS = {"sin", "cos", "tan", "asin", "acos"}
PARAM_RUNS = 4  # defaults, lo, hi, a random interior value


def _all_ops():
    """A smooth-enough field that uses every op of csdf.ops on well-defined inputs, with
    parameters whose GLSL names need mangling (``_r``, ``a__b``)."""
    x, y, z = E.X, E.Y, E.Z
    r = E.param("_r", 0.5, 0.2, 1.0)
    w = E.param("a__b", 0.3, -1.0, 1.0)
    terms = [
        E.sqrt(1.0 + E.square(x)) - r,
        E.asin(0.5 * E.sin(x)) + E.acos(0.5 * E.cos(y)) * w,
        E.atan(z) + E.tan(0.4 * x),
        E.exp(0.3 * y) - E.log(1.5 + E.sin(z)),
        0.1 * E.floor(2.0 * x) + 0.1 * E.step(y) + 0.1 * E.sign(z),
        0.2 * E.mod(x + w, 0.7) + E.atan2(y, x + 3.0) / (2.0 + E.cos(x)),
        E.minimum(abs(x), -y) + E.maximum(z * w, y),
    ]
    root = terms[0]
    for t in terms[1:]:
        root = root + t
    return compile_expr(-root * 0.25, lipschitz=math.inf)


CAT = catalogue(mesh_calls=False)
MODELS: dict = {name: f for name, f in CAT.items()}
MODELS["all_ops"] = _all_ops


def _model(name: str):
    """(shape or None, program) for a model name."""
    obj = MODELS[name]()
    if isinstance(obj, csdf.Program):
        return None, obj
    return obj, csdf.compile(obj)


def _box(shape):
    if shape is None:
        return -1.5 * np.ones(3), 1.5 * np.ones(3)
    return sample_box(shape)


def _points(name: str, shape) -> np.ndarray:
    rng = np.random.default_rng(zlib.crc32(name.encode()))
    lo, hi = _box(shape)
    return rng.uniform(lo, hi, (N_POINTS, 3)).astype(np.float32)


def _tol(prog) -> tuple[float, float]:
    """(value, gradient) tolerance tier of a program (see TOL_PLAIN / TOL_TRIG)."""
    names = {OPS_BY_CODE[int(op)].name for op in prog.code[:, 0]}
    return TOL_TRIG if names & TRIG_OPS else TOL_PLAIN


def _size(shape) -> float:
    lo, hi = _box(shape)
    return float(np.linalg.norm(hi - lo))


# ---------------------------------------------------------------------------- text
def test_all_ops_model_uses_every_op():
    prog = _all_ops()
    used = {row[0] for row in prog.code.tolist()}
    assert used == {info.code for info in OPS.values()}


def test_float_literals_round_trip():
    rng = np.random.default_rng(1)
    vals = np.concatenate([
        rng.standard_normal(2000) * 10.0 ** rng.integers(-40, 38, 2000),
        [0.0, -0.0, 1.0, -1.0, 0.1, 2.0 / 3.0, 1e-45, 3.4028235e38, 16777217.0, 1e-5, 1e9],
    ])
    for v in vals:
        s = glsl_float(v)
        core = s[1:-1] if s.startswith("(") else s
        assert re.fullmatch(r"-?[0-9]+\.[0-9]+(e[+-][0-9]+)?", core), s
        assert np.float32(float(core)).tobytes() == np.float32(v).tobytes(), (v, s)
        assert len(core.lstrip("-").split("e")[0].replace(".", "").lstrip("0")) <= 10
    assert glsl_float(1.0) == "1.0" and glsl_float(2) == "2.0" and glsl_float(-0.5) == "(-0.5)"
    assert glsl_float(math.inf) == "uintBitsToFloat(0x7F800000u)"
    assert glsl_float(-math.inf) == "uintBitsToFloat(0xFF800000u)"
    assert glsl_float(1e39) == "uintBitsToFloat(0x7F800000u)"  # beyond float32
    assert glsl_float(math.nan) == "uintBitsToFloat(0x7FC00000u)"


def test_uniform_names():
    assert uniform_name("r", 0) == "u_r"
    assert uniform_name("k_1", 3) == "u_k_1"
    assert uniform_name("_t", 2) == "u2_t"  # u__t would be reserved in GLSL
    assert uniform_name("a__b", 0) == "u0_a_b"
    with pytest.raises(CsdfError):
        uniform_name("1x", 0)


def test_snippet_structure():
    r = csdf.param("r", 1.0, 0.5, 2)
    shape = csdf.union(csdf.sphere(r), csdf.box(0.8).translate((0.6, 0, 0)),
                       k=csdf.param("k", 0.2, 0.05, 0.4))
    prog = csdf.compile(shape)
    src = to_glsl(shape)
    assert src == to_glsl(prog)
    assert "uniform float u_k; // default 0.2, range [0.05, 0.4]" in src
    assert "uniform float u_r; // default 1.0, range [0.5, 2.0]" in src
    assert src.index("u_k;") < src.index("u_r;")  # Program.params order
    assert "float sdf(vec3 p) {" in src and "vec4 sdf_grad(vec3 p) {" in src
    value = src.split("float sdf(vec3 p) {")[1].split("}")[0]
    assert len(re.findall(r"^\s+float t\d+ = ", value, re.M)) == len(prog.code)
    code = "\n".join(ln.split("//")[0] for ln in src.splitlines())
    assert "#version" not in code and "precision" not in code
    # no integer literals: every number has a decimal point
    nums = re.findall(r"(?<![\w.])\d+(?:\.\d*)?(?:e[+-]?\d+)?(?![\w.])", code)
    assert nums and all("." in n for n in nums), nums
    assert "sdf_grad" not in to_glsl(shape, gradient=False)
    named = to_glsl(shape, name="myShape")
    assert "float myShape(vec3 p)" in named and "vec4 myShape_grad(vec3 p)" in named


def test_2d_ignores_z_and_names_checked():
    src = to_glsl(csdf.hexagon(0.5))
    assert "p.z" not in src and "float sdf(vec3 p)" in src
    for bad in ("sin", "main", "gl_x", "a__b", "t3", "p", "u_r", "1a", "", "csdf_x", "x y"):
        with pytest.raises(CsdfError):
            to_glsl(csdf.sphere(1.0), name=bad)
    with pytest.raises(CsdfError):
        to_glsl("sphere")


def test_glsl_params():
    shape = csdf.sphere(csdf.param("r", 1.0, 0.5, 2.0)).translate(
        (csdf.param("_dx", 0.0), 0, 0))
    assert glsl_params(shape) == [
        {"name": "_dx", "uniform": "u0_dx", "default": 0.0, "lo": -math.inf, "hi": math.inf},
        {"name": "r", "uniform": "u_r", "default": 1.0, "lo": 0.5, "hi": 2.0},
    ]
    assert glsl_params(csdf.compile(shape)) == glsl_params(shape)
    assert "uniform float u0_dx; // default 0.0, range [-inf, inf]" in to_glsl(shape)


def test_shadertoy_text():
    shape = csdf.box(1).twist(csdf.param("t", 1.0, 0.0, 2.0))
    src = shadertoy(shape)
    assert "void mainImage(out vec4 fragColor, in vec2 fragCoord)" in src
    assert "const float u_t = 1.0; // default 1.0, range [0.0, 2.0]" in src
    assert "uniform" not in src and "iTime" in src and "iResolution" in src
    lip = csdf.compile(shape).lipschitz
    assert lip > 1
    assert f"const float CSDF_STEP = {glsl_float(1.0 / lip)};" in src
    assert "const float CSDF_STEP = 0.5;" in shadertoy(_all_ops())  # infinite bound
    assert "const float CSDF_STEP = 1.0;" in shadertoy(csdf.sphere(1.0))


def _nonfinite_program() -> csdf.Program:
    """``min(x + inf, max(y, nan)) - (-2)``, built by hand (the compiler folds such)."""
    return csdf.Program(
        params=(), consts=np.array([math.inf, math.nan, -2.0]),
        code=np.array([[OPS["add"].code, 6, 0, 3], [OPS["max"].code, 7, 1, 4],
                       [OPS["min"].code, 6, 6, 7], [OPS["sub"].code, 6, 6, 5]]),
        output=6, n_regs=2)


def test_nonfinite_constants_and_bad_programs():
    src = to_glsl(_nonfinite_program())
    assert "p.x + uintBitsToFloat(0x7F800000u)" in src
    assert "max(p.y, uintBitsToFloat(0x7FC00000u))" in src
    assert "t2 - (-2.0)" in src
    bad = csdf.Program(params=(), consts=np.array([1.0]),
                       code=np.array([[OPS["add"].code, 4, 0, 5]]), output=4, n_regs=2)
    with pytest.raises(CsdfError, match="reads slot 5"):
        to_glsl(bad)


# ---------------------------------------------------------------------------- glslang
# CI sets CSDF_REQUIRE_TOOLS=1 after installing the tools: then a missing tool fails
REQUIRE_TOOLS = os.environ.get("CSDF_REQUIRE_TOOLS") == "1"
if REQUIRE_TOOLS and glslang() is None:
    raise RuntimeError("CSDF_REQUIRE_TOOLS=1 but glslangValidator is missing")
needs_glslang = pytest.mark.skipif(
    glslang() is None,
    reason="glslangValidator not found: apt-get install glslang-tools",
)



def _es_main(fn: str = "sdf") -> str:
    return f"""
out vec4 fragColor;
void main() {{
    vec3 p = gl_FragCoord.xyz;
    fragColor = vec4({fn}(p)) + {fn}_grad(p);
}}
"""

_SHADERTOY_PRELUDE = ES_PRELUDE + "uniform vec3 iResolution;\nuniform float iTime;\n"
_SHADERTOY_MAIN = """
out vec4 csdf_color;
void main() {
    mainImage(csdf_color, gl_FragCoord.xy);
}
"""


@needs_glslang
@pytest.mark.parametrize("name", sorted(MODELS))
def test_glslang_accepts(name):
    _, prog = _model(name)
    src = to_glsl(prog)
    for label, full in (("GLSL ES 3.00", ES_PRELUDE + src + _es_main()),
                        ("GLSL 3.30", "#version 330\n" + src + _es_main())):
        ok, log = validate(full)
        assert ok, f"{name}: {label} rejected:\n{log}"
    shape, _ = _model(name)
    toy = shadertoy(shape if shape is not None else prog)
    ok, log = validate(_SHADERTOY_PRELUDE + toy + _SHADERTOY_MAIN)
    assert ok, f"{name}: Shadertoy shader rejected:\n{log}"


@needs_glslang
def test_glslang_nonfinite_and_odd_names():
    for src, fn in ((to_glsl(_nonfinite_program()), "sdf"),
                    (to_glsl(_all_ops(), name="Shape_2"), "Shape_2")):
        for prelude in (ES_PRELUDE, "#version 330\n"):
            ok, log = validate(prelude + src + _es_main(fn))
            assert ok, log


# ---------------------------------------------------------------------------- WebGL2
_VALUE_FRAG = """
uniform highp sampler2D csdf_points;
layout(location = 0) out vec4 csdf_value;
layout(location = 1) out vec4 csdf_grad;
void main() {
    vec3 p = texelFetch(csdf_points, ivec2(gl_FragCoord.xy), 0).xyz;
    csdf_value = vec4(sdf(p), 0.0, 0.0, 0.0);
    csdf_grad = sdf_grad(p);
}
"""
TOY_MODELS = ("sphere", "box", "twist", "union3_smooth", "circle", "complement")
TOY_W, TOY_H = 40, 24


def _param_sets(prog, rng) -> list[dict]:
    """Parameter values for the runs: defaults, all lo, all hi, random interior."""
    if not prog.params:
        return [{}]
    sets = [{}, {}, {}, {}]
    for p in prog.params:
        lo = p.lo if math.isfinite(p.lo) else p.default - 0.5
        hi = p.hi if math.isfinite(p.hi) else p.default + 0.5
        sets[0][p.name] = p.default
        sets[1][p.name] = lo
        sets[2][p.name] = hi
        sets[3][p.name] = float(rng.uniform(lo, hi))
    return sets


@pytest.fixture(scope="module")
def gpu():
    """Everything run in one headless page: {name: (runs, points, param sets)} plus the
    Shadertoy renders {('toy', name): image}."""
    jobs, keys, meta = [], [], {}
    rng = np.random.default_rng(7)
    for name in sorted(MODELS):
        shape, prog = _model(name)
        pts = _points(name, shape)
        texels = np.zeros((N_POINTS, 4), np.float32)
        texels[:, :3] = pts
        sets = _param_sets(prog, rng)
        unif = {p["name"]: p["uniform"] for p in glsl_params(prog)}
        runs = [{"uniforms": {unif[k]: v for k, v in s.items()}} for s in sets]
        jobs.append({"frag": ES_PRELUDE + to_glsl(prog) + _VALUE_FRAG, "width": WIDTH,
                     "height": N_POINTS // WIDTH, "outputs": 2, "points": texels,
                     "runs": runs})
        keys.append(name)
        meta[name] = (shape, prog, pts, sets)
    for name in TOY_MODELS:
        shape, _ = _model(name)
        jobs.append({"frag": _SHADERTOY_PRELUDE + shadertoy(shape) + _SHADERTOY_MAIN,
                     "width": TOY_W, "height": TOY_H, "outputs": 1,
                     "runs": [{"uniforms": {"iTime": 0.0, "iResolution": [TOY_W, TOY_H, 1]}}]})
        keys.append(("toy", name))
    try:
        with WebGL2Runner() as runner:
            results = runner.run(jobs)
            renderer = runner.renderer
    except WebGLUnavailable as e:
        if REQUIRE_TOOLS:
            pytest.fail(f"CSDF_REQUIRE_TOOLS=1 but WebGL2 in Chromium is unavailable: {e}")
        pytest.skip(f"WebGL2 in headless Chromium unavailable ({e}); needs the 'playwright' "
                    "Python package and Debian's chromium")
    return {"results": dict(zip(keys, results)), "meta": meta, "renderer": renderer}


def _kink_free(prog, pts, params, h) -> np.ndarray:
    """Points where the CPU gradient is stable under perturbations of size ``h``."""
    p64 = pts.astype(np.float64)
    g0 = prog.gradient(p64, params, backend="numpy")
    ok = np.all(np.isfinite(g0), axis=1)
    rng = np.random.default_rng(3)
    for _ in range(3):
        g1 = prog.gradient(p64 + rng.uniform(-h, h, p64.shape), params, backend="numpy")
        ok &= np.max(np.abs(g1 - g0), axis=1) < 1e-2
    return ok


def _compare(name, gpu, run_index):
    """(value error / size, gradient error, #gradient points) for one run; asserts."""
    shape, prog, pts, sets = gpu["meta"][name]
    res = gpu["results"][name]
    assert "error" not in res, f"{name}: WebGL rejected the shader:\n{res['error']}"
    assert res["glError"] == 0, f"{name}: GL error {res['glError']}"
    run = res["runs"][run_index]
    assert run["missing"] == [], f"{name}: uniforms not found: {run['missing']}"
    params = sets[run_index]
    val, grad = run["outputs"][0][:, 0], run["outputs"][1]
    ref, gref = prog.value_and_grad(pts.astype(np.float64), params, backend="numpy")
    size = _size(shape)
    vtol, gtol = _tol(prog)
    fin = np.isfinite(ref)
    assert fin.mean() > 0.9, f"{name}: CPU gives too few finite values"
    assert np.all(np.isfinite(val[fin])), f"{name}: GPU NaN/inf where the CPU is finite"
    err = np.max(np.abs(val[fin] - ref[fin])) / size
    assert err <= vtol, f"{name} {params}: worst value error {err:.2e} x size"
    # sdf_grad's value is the same computation as sdf's
    gv_err = np.max(np.abs(grad[fin, 0] - ref[fin])) / size
    assert gv_err <= vtol, f"{name}: sdf_grad value error {gv_err:.2e} x size"
    smooth = _kink_free(prog, pts, params, 1e-4 * size) & fin
    gerr = np.max(np.abs(grad[smooth, 1:] - gref[smooth]), initial=0.0)
    scale = max(1.0, float(np.max(np.abs(gref[smooth]), initial=0.0)))
    assert gerr <= gtol * scale, f"{name}: worst gradient error {gerr:.2e}"
    assert smooth.sum() >= 0.5 * N_POINTS or name in ("all_ops",), \
        f"{name}: only {smooth.sum()} kink-free points"
    return err, gerr, int(smooth.sum())


@pytest.mark.parametrize("name", sorted(MODELS))
def test_webgl_matches_cpu(gpu, name):
    _compare(name, gpu, 0)


PARAM_MODELS = sorted(n for n in MODELS if _model(n)[1].params)


def test_param_models_exist():
    assert len(PARAM_MODELS) >= 4


@pytest.mark.parametrize("name", PARAM_MODELS)
def test_webgl_param_uniforms(gpu, name):
    _, prog, _, sets = gpu["meta"][name]
    for i in range(1, len(sets)):
        _compare(name, gpu, i)
    runs = gpu["results"][name]["runs"]
    lo, hi = runs[1]["outputs"][0][:, 0], runs[2]["outputs"][0][:, 0]
    shape, _, pts, _ = gpu["meta"][name]
    cpu_lo = prog(pts.astype(np.float64), sets[1], backend="numpy")
    cpu_hi = prog(pts.astype(np.float64), sets[2], backend="numpy")
    assert np.max(np.abs(cpu_hi - cpu_lo)) > 1e-3  # the parameters matter here
    # the change made by the uniforms is the CPU's change (two runs' errors add up)
    np.testing.assert_allclose(hi - lo, cpu_hi - cpu_lo, rtol=0,
                               atol=2 * _tol(prog)[0] * _size(shape))


def test_webgl_worst_error(gpu):
    """All models and runs together; the worst errors are in the failure message and
    printed with ``pytest -s``."""
    worst = {TOL_PLAIN: [0.0, 0.0, ""], TOL_TRIG: [0.0, 0.0, ""]}
    for name in sorted(MODELS):
        tier = worst[_tol(gpu["meta"][name][1])]
        for i in range(len(gpu["meta"][name][3])):
            ev, eg, _ = _compare(name, gpu, i)
            if ev > tier[0]:
                tier[0], tier[2] = ev, f"{name} run {i}"
            tier[1] = max(tier[1], eg)
    lines = [f"WebGL2 ({gpu['renderer']}) vs CPU (numpy, float64):"]
    for label, key in (("without trig", TOL_PLAIN), ("with sin/cos/tan/acos", TOL_TRIG)):
        v, g, where = worst[key]
        lines.append(f"  {label}: worst value error {v:.2e} x shape size ({where}), "
                     f"worst gradient error {g:.2e}")
    print("\n" + "\n".join(lines))
    assert worst[TOL_PLAIN][0] <= TOL_PLAIN[0] and worst[TOL_TRIG][0] <= TOL_TRIG[0]


@pytest.mark.parametrize("name", TOY_MODELS)
def test_webgl_shadertoy_renders(gpu, name):
    res = gpu["results"][("toy", name)]
    assert "error" not in res, f"{name}: WebGL rejected the Shadertoy shader:\n{res['error']}"
    img = res["runs"][0]["outputs"][0].reshape(TOY_H, TOY_W, 4)
    assert np.all(np.isfinite(img)) and img.min() >= 0.0 and img.max() <= 1.0
    assert np.all(img[..., 3] == 1.0)
    centre = img[TOY_H // 2, TOY_W // 2, :3]
    corner = img[TOY_H - 1, 0, :3]  # top-left: sky, no shape
    assert np.max(np.abs(centre - corner)) > 0.05, f"{name}: the centre ray hit nothing"
    assert len({tuple(np.round(px, 3)) for px in img.reshape(-1, 4)[:, :3]}) > 20
