"""GLSL export: a compiled program as a GLSL function, and a paste-ready Shadertoy shader.

:func:`to_glsl` turns a :class:`csdf.Program` (or anything with a ``compile()`` method
that returns one, such as a :class:`csdf.Shape`) into a self-contained snippet for
GLSL ES 3.00 (WebGL2) and desktop GLSL 3.30 or later:

* one ``uniform float u_<name>;`` per parameter (in :attr:`Program.params` order, with
  its default and range in a comment), so changing a parameter never recompiles;
* ``float sdf(vec3 p)``: the tape as straight-line code, one ``float`` temporary per
  instruction (``t<k>`` for instruction ``k``);
* ``vec4 sdf_grad(vec3 p)`` (unless ``gradient=False``): ``vec4(value, dvalue/dp)`` by
  forward-mode differentiation, generated from the op specification (:mod:`csdf.ops`)
  that the CPU evaluators follow: the derivative factors are rendered from its
  formulas, and ``min``/``max`` pick an operand's gradient by its tie rule (ties follow
  the first operand unless that is a constant, then the second: ``min(2, x)`` at
  ``x = 2`` has gradient ``(1, 0, 0)`` here as on the CPU); ``abs`` has derivative
  ``sign(a)``, ``floor``/``step``/``sign`` 0, ``sqrt`` at 0 gets 0, ``atan2`` at the
  origin 0.

The snippet has no ``#version`` line and no precision statement: the host shader gives
them (``#version 300 es`` + ``precision highp float;`` for WebGL2, or ``#version 330``).
2D programs (``dim == 2``) still take a ``vec3`` and ignore ``p.z``.

:func:`shadertoy` wraps the same function in a complete Shadertoy "Image" shader (sphere
tracing, orbiting camera, normals by central differences) with the parameters as
``const float`` values, and :func:`glsl_params` lists the uniforms for a live editor.

Op mapping (:mod:`csdf.ops`): ``step(a)`` is ``step(0.0, a)`` (1 where ``a >= 0``);
``atan2(a, b)`` is ``atan(a, b)`` (GLSL's two-argument ``atan`` is ``atan(y, x)``);
``mod`` is GLSL ``mod`` (both are ``a - b*floor(a/b)``); ``square(a)`` is ``a * a``; the
rest have GLSL built-ins of the same name. Differences from the CPU evaluators, all
where GLSL leaves the result undefined: NaN is not guaranteed to propagate through
``min``/``max`` (the CPU ones return NaN), and ``sqrt``/``log`` of negative numbers,
``asin``/``acos`` outside ``[-1, 1]`` and ``atan(0, 0)`` are undefined. Arithmetic is
float32 (``highp``): constants are rounded to float32 and written with the shortest
decimal that reads back as the same float32; infinite or NaN constants are written as
``uintBitsToFloat(...)``.

Safety: the text is built only from the program's validated numbers, op names and
derivative formulas from the fixed table in :mod:`csdf.ops`, parameter names
(identifiers by construction, checked again here) and the function name, which must be a
plain GLSL identifier.
"""

from __future__ import annotations

import math
import re

import numpy as np

from ..errors import CsdfError
from ..opformula import Formula, Target
from ..ops import OPS, OPS_BY_CODE, chain_tangent, tie_comparison
from ..version import __version__

__all__ = ["to_glsl", "shadertoy", "glsl_params", "glsl_float", "uniform_name"]

_IDENT = re.compile(r"[A-Za-z][A-Za-z0-9_]*")
_PARAM_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_LOCAL = re.compile(r"[tgs][0-9]+|p|u_.*|u[0-9].*|csdf.*|CSDF.*", re.IGNORECASE)

# GLSL ES 3.00 / GLSL 3.30 keywords, reserved words and built-in functions that a
# function name must not redeclare.
_RESERVED = frozenset("""
attribute const uniform varying layout centroid flat smooth noperspective break continue
do for while switch case default if else in out inout float int void bool true false
invariant discard return mat2 mat3 mat4 mat2x2 mat2x3 mat2x4 mat3x2 mat3x3 mat3x4 mat4x2
mat4x3 mat4x4 vec2 vec3 vec4 ivec2 ivec3 ivec4 bvec2 bvec3 bvec4 uint uvec2 uvec3 uvec4
lowp mediump highp precision sampler2D sampler3D samplerCube sampler2DShadow
samplerCubeShadow sampler2DArray sampler2DArrayShadow isampler2D isampler3D isamplerCube
isampler2DArray usampler2D usampler3D usamplerCube usampler2DArray struct attribute
asm class union enum typedef template this goto inline noinline volatile public static
extern external interface long short double half fixed unsigned superp input output
hvec2 hvec3 hvec4 dvec2 dvec3 dvec4 fvec2 fvec3 fvec4 sampler3DRect filter image1D
image2D image3D imageCube iimage1D iimage2D iimage3D iimageCube uimage1D uimage2D
uimage3D uimageCube image1DArray image2DArray iimage1DArray iimage2DArray uimage1DArray
uimage2DArray imageBuffer iimageBuffer uimageBuffer sampler1D sampler1DShadow
sampler1DArray sampler1DArrayShadow isampler1D isampler1DArray usampler1D
usampler1DArray sampler2DRect sampler2DRectShadow isampler2DRect usampler2DRect
samplerBuffer isamplerBuffer usamplerBuffer sampler2DMS isampler2DMS usampler2DMS
sampler2DMSArray isampler2DMSArray usampler2DMSArray sizeof cast namespace using
resource patch sample subroutine coherent readonly writeonly shared buffer common
partition active main mainImage
radians degrees sin cos tan asin acos atan sinh cosh tanh asinh acosh atanh pow exp log
exp2 log2 sqrt inversesqrt abs sign floor trunc round roundEven ceil fract mod modf min
max clamp mix step smoothstep isnan isinf floatBitsToInt floatBitsToUint intBitsToFloat
uintBitsToFloat packSnorm2x16 unpackSnorm2x16 packUnorm2x16 unpackUnorm2x16
packHalf2x16 unpackHalf2x16 length distance dot cross normalize faceforward reflect
refract matrixCompMult outerProduct transpose determinant inverse lessThan
lessThanEqual greaterThan greaterThanEqual equal notEqual any all not textureSize
texture textureProj textureLod textureOffset texelFetch texelFetchOffset
textureProjOffset textureLodOffset textureProjLod textureProjLodOffset textureGrad
textureGradOffset textureProjGrad textureProjGradOffset dFdx dFdy fwidth
""".split())

_UNARY = {
    "neg": "-{a}",
    "abs": "abs({a})",
    "sqrt": "sqrt({a})",
    "square": "{a} * {a}",
    "sin": "sin({a})",
    "cos": "cos({a})",
    "tan": "tan({a})",
    "asin": "asin({a})",
    "acos": "acos({a})",
    "atan": "atan({a})",
    "exp": "exp({a})",
    "log": "log({a})",
    "floor": "floor({a})",
    "step": "step(0.0, {a})",
    "sign": "sign({a})",
}
_BINARY = {
    "add": "{a} + {b}",
    "sub": "{a} - {b}",
    "mul": "{a} * {b}",
    "div": "{a} / {b}",
    "min": "min({a}, {b})",
    "max": "max({a}, {b})",
    "atan2": "atan({a}, {b})",
    "mod": "mod({a}, {b})",
}
# the functions of csdf.opformula (derivative factors) in GLSL
_CALLS = {
    "sin": "sin({0})", "cos": "cos({0})", "sqrt": "sqrt({0})", "floor": "floor({0})",
    "sign": "sign({0})", "pos_div": "({1} > 0.0 ? {0} / {1} : 0.0)",
}
_ZERO_VEC = "vec3(0.0)"
_ATOM = re.compile(r"g[0-9]+|vec3\([0-9., ]*\)")


def _vec_atom(t: str) -> str:
    """A gradient expression as an operand (parenthesised unless an atom)."""
    return t if _ATOM.fullmatch(t) else f"({t})"


class _Vec3Algebra:
    """Tangent algebra of :func:`csdf.ops.chain_tangent` on ``vec3`` expressions."""

    @staticmethod
    def scale(f: str, t: str) -> str:
        return f"{f} * {_vec_atom(t)}"

    @staticmethod
    def add(u: str, v: str) -> str:
        return f"{u} + {v}"

    @staticmethod
    def sub(u: str, v: str) -> str:
        return f"{u} - {v}"

    @staticmethod
    def neg(t: str) -> str:
        return f"-{_vec_atom(t)}"


_VEC3 = _Vec3Algebra()
_AXES = ("vec3(1.0, 0.0, 0.0)", "vec3(0.0, 1.0, 0.0)", "vec3(0.0, 0.0, 1.0)")


# ---------------------------------------------------------------------------- helpers
def glsl_float(v: float) -> str:
    """A GLSL float literal for ``v`` rounded to float32.

    The shortest decimal that reads back as the same float32 (at most 9 significant
    digits), always with a decimal point (``1.0``, never ``1``); negative values are
    parenthesised (``(-0.5)``) so the literal is an atom in any expression. Infinities
    and NaN, which GLSL has no literal for, become ``uintBitsToFloat(0x...u)``.
    """
    with np.errstate(over="ignore"):
        f = np.float32(v)
    if np.isnan(f):
        return "uintBitsToFloat(0x7FC00000u)"
    if np.isinf(f):
        return "uintBitsToFloat(0x7F800000u)" if f > 0 else "uintBitsToFloat(0xFF800000u)"
    a = abs(float(f))
    if a == 0.0 or 1e-4 <= a < 1e9:
        s = np.format_float_positional(f, unique=True, trim="0")
    else:
        s = np.format_float_scientific(f, unique=True, trim="0")
    return f"({s})" if s.startswith("-") else s


def uniform_name(param_name: str, index: int) -> str:
    """The GLSL identifier of parameter ``param_name`` (at ``index`` in the program).

    ``u_<name>``, except where that would contain two consecutive underscores (reserved
    in GLSL): then ``u<index>_<name with underscore runs collapsed>``. The two forms
    cannot collide (``u_`` versus ``u`` + digit).
    """
    if not _PARAM_NAME.fullmatch(param_name):
        raise CsdfError(f"parameter name {param_name!r} is not an identifier")
    plain = f"u_{param_name}"
    if "__" not in plain:
        return plain
    return f"u{index}_{re.sub('_+', '_', param_name).strip('_')}".rstrip("_")


def _is_program(obj) -> bool:
    """Duck-typed :class:`csdf.Program` (the backends do not import the compiler)."""
    return all(hasattr(obj, a) for a in ("code", "consts", "params", "output", "layout"))


def _refuse_mesh(prog) -> None:
    if getattr(prog, "data", ()):
        raise CsdfError("GLSL export cannot hold a mesh call (csdf.from_mesh / polyhedron): "
                        "its triangle hierarchy runs on the CPU evaluators only; "
                        "mesh the shape first (csdf.mesh) to draw it elsewhere")


def _program(shape_or_program):
    """The program of a Shape (anything whose ``compile()`` returns a Program; compiled,
    cached) or the Program itself."""
    if _is_program(shape_or_program):
        _refuse_mesh(shape_or_program)
        return shape_or_program
    compile_ = getattr(shape_or_program, "compile", None)
    if callable(compile_) and not isinstance(shape_or_program, type):
        prog = compile_()
        if _is_program(prog):
            _refuse_mesh(prog)
            return prog
    raise CsdfError(
        f"GLSL export expects a Shape or Program, got {type(shape_or_program).__name__}")


def _check_name(name: str) -> None:
    if not isinstance(name, str) or not _IDENT.fullmatch(name):
        raise CsdfError(f"GLSL function name {name!r} is not an identifier ([A-Za-z][A-Za-z0-9_]*)")
    if (
        "__" in name
        or name.startswith(("gl_", "webgl_"))
        or name in _RESERVED
        or _LOCAL.fullmatch(name)
        or f"{name}_grad" in _RESERVED
    ):
        raise CsdfError(
            f"GLSL function name {name!r} is reserved (a GLSL keyword or built-in, "
            "'gl_'/'webgl_' prefix, '__', or a name the generated code uses); pick another"
        )
    if len(name) > 200:
        raise CsdfError("GLSL function name is longer than 200 characters")


def _num(v: float) -> str:
    """A float for comments: the shortest repr (``1.0``, ``0.25``, ``inf``)."""
    return repr(float(v))


def _param_comment(p) -> str:
    return f"default {_num(p.default)}, range [{_num(p.lo)}, {_num(p.hi)}]"


def glsl_params(shape_or_program) -> list[dict]:
    """The parameters as the generated GLSL sees them, in :attr:`Program.params` order.

    Returns:
        ``[{'name', 'uniform', 'default', 'lo', 'hi'}, ...]``: the csdf parameter name,
        its GLSL identifier (``u_<name>``, see :func:`uniform_name`), its default and
        range as floats (``lo``/``hi`` may be infinite).
    """
    prog = _program(shape_or_program)
    return [
        {
            "name": p.name,
            "uniform": uniform_name(p.name, i),
            "default": float(p.default),
            "lo": float(p.lo),
            "hi": float(p.hi),
        }
        for i, p in enumerate(prog.params)
    ]


# ---------------------------------------------------------------------------- emitter
class _Emitter:
    """Straight-line GLSL for one program: operand atoms per slot, then statements."""

    def __init__(self, prog, names: dict[str, str] | None = None):
        self.prog = prog
        self.layout = lay = prog.layout
        self.n_fixed = lay.n_fixed
        self.n_lets = 0
        z = "p.z" if prog.dim == 3 else "0.0"
        atoms: dict[int, str] = {0: "p.x", 1: "p.y", 2: z}
        for i, prm in enumerate(prog.params):
            # (names: another program's identifiers, for a colour program that reads
            # the parameters of the program it belongs to)
            atoms[lay.param(i)] = (names or {}).get(prm.name) or uniform_name(prm.name, i)
        for i, c in enumerate(prog.consts.tolist()):
            atoms[lay.const(i)] = glsl_float(c)
        self.fixed = atoms
        self.fixed_tans: dict[int, str | None] = {
            0: _AXES[0], 1: _AXES[1], 2: _AXES[2] if prog.dim == 3 else None,
        }
        self._validate()

    def _validate(self) -> None:
        prog = self.prog
        if prog.dim not in (2, 3):
            raise CsdfError(f"program dim must be 2 or 3, got {prog.dim}")
        written: set[int] = set()
        n_slots = prog.n_slots
        for k, (op, dst, a, b) in enumerate(prog.code.tolist()):
            info = OPS_BY_CODE.get(op)
            if info is None:
                raise CsdfError(f"instruction {k}: unknown opcode {op}")
            reads = (a, b) if info.arity == 2 else (a,)
            for s in reads:
                if not 0 <= s < n_slots or (s >= self.n_fixed and s not in written):
                    raise CsdfError(f"instruction {k}: reads slot {s}, which holds no value")
            if not self.n_fixed <= dst < n_slots:
                raise CsdfError(f"instruction {k}: writes slot {dst}, which is not a register")
            written.add(dst)
        out = prog.output
        if not 0 <= out < n_slots or (out >= self.n_fixed and out not in written):
            raise CsdfError(f"output slot {out} holds no value")

    def value_body(self) -> list[str]:
        """Statements of ``float sdf(vec3 p)`` (without the braces)."""
        cur = dict(self.fixed)
        lines = []
        for k, (op, dst, a, b) in enumerate(self.prog.code.tolist()):
            info = OPS_BY_CODE[op]
            if info.arity == 2:
                expr = _BINARY[info.name].format(a=cur[a], b=cur[b])
            else:
                expr = _UNARY[info.name].format(a=cur[a])
            lines.append(f"float t{k} = {expr};")
            cur[dst] = f"t{k}"
        lines.append(f"return {cur[self.prog.output]};")
        return lines

    def grad_body(self) -> list[str]:
        """Statements of ``vec4 sdf_grad(vec3 p)``: values ``t<k>`` and, where not
        structurally zero, gradients ``g<k>`` (``s<k>`` is the ``atan2`` radius)."""
        cur = dict(self.fixed)
        tan: dict[int, str | None] = dict(self.fixed_tans)
        lines = []
        for k, (op, dst, a, b) in enumerate(self.prog.code.tolist()):
            info = OPS_BY_CODE[op]
            name = info.name
            va = cur[a]
            ta = tan.get(a)
            vb = cur[b] if info.arity == 2 else ""
            tb = tan.get(b) if info.arity == 2 else None
            if info.arity == 2:
                expr = _BINARY[name].format(a=va, b=vb)
            else:
                expr = _UNARY[name].format(a=va)
            v = f"t{k}"
            lines.append(f"float {v} = {expr};")
            g = self._tangent(name, va, vb, v, ta, tb, self.layout.is_const(a), lines)
            if g is not None and not _ATOM.fullmatch(g):
                lines.append(f"vec3 g{k} = {g};")
                g = f"g{k}"
            cur[dst] = v
            tan[dst] = g
        out_v = cur[self.prog.output]
        out_g = tan.get(self.prog.output)
        lines.append(f"return vec4({out_v}, {out_g or _ZERO_VEC});")
        return lines

    def _tangent(
        self, op: str, a: str, b: str, v: str, ta: str | None, tb: str | None,
        a_const: bool, lines: list[str],
    ) -> str | None:
        """The gradient expression of ``v = op(a, b)`` by the op's rule in
        :mod:`csdf.ops` (None when structurally zero); ``a_const``: operand ``a`` is a
        constant slot (the tie rule). ``let`` values become ``float s<n>`` lines."""
        rule = OPS[op].derivative
        if rule.kind == "zero" or (ta is None and tb is None):
            return None
        if rule.kind == "select":
            cmp = tie_comparison(op, a_const)
            return f"{a} {cmp} {b} ? {ta or _ZERO_VEC} : {tb or _ZERO_VEC}"
        names = {"a": a, "b": b, "v": v}
        target = Target(name=names.__getitem__, literal=glsl_float, calls=_CALLS,
                        atom_args=frozenset({"pos_div"}))
        cache: dict[Formula, str] = {}

        def coef(f: Formula) -> str:
            if f not in cache:
                for name, g in rule.let:
                    if name not in names:
                        names[name] = f"s{self.n_lets}"
                        self.n_lets += 1
                        lines.append(f"float {names[name]} = {g.render(target)};")
                cache[f] = f.render(target, atom=True)
            return cache[f]

        return chain_tangent(rule, ta, tb, coef, _VEC3)


def _header(prog, what: str) -> list[str]:
    lip = prog.lipschitz
    return [
        f"// {what} generated by csdf {__version__} from a compiled program: "
        f"{len(prog.code)} instructions, {len(prog.params)} parameters, {prog.dim}D",
        f"// exactness: {prog.exactness}; Lipschitz bound: {_num(lip)}",
    ]


def _function(kind: str, name: str, body: list[str]) -> list[str]:
    return [f"{kind} {name}(vec3 p) {{", *("    " + ln for ln in body), "}"]


def to_glsl(shape_or_program, name: str = "sdf", *, gradient: bool = True) -> str:
    """GLSL source of the signed distance function (see the module docstring).

    Args:
        shape_or_program: a :class:`csdf.Shape` (compiled first) or a :class:`csdf.Program`.
        name: the function name (a GLSL identifier that is not a keyword or built-in);
            the gradient function is ``<name>_grad``.
        gradient: also emit ``vec4 <name>_grad(vec3 p)`` = ``vec4(value, gradient)``.

    Returns:
        The snippet: parameter uniforms then the function(s), ending with a newline.
        It needs a ``#version 300 es`` (plus ``precision highp float;``) or
        ``#version 330`` host shader.

    Raises:
        CsdfError: not a Shape/Program, a bad function name, or a malformed program.
    """
    _check_name(name)
    prog = _program(shape_or_program)
    em = _Emitter(prog)
    lines = _header(prog, "GLSL (ES 3.00 / 3.30)")
    lines.append("// host shader: #version 300 es + precision highp float; (or #version 330)")
    for i, p in enumerate(prog.params):
        lines.append(f"uniform float {uniform_name(p.name, i)}; // {_param_comment(p)}")
    lines.append("")
    lines += _function("float", name, em.value_body())
    if gradient:
        lines.append("")
        lines.append(f"// vec4({name}(p), d{name}/dx, d{name}/dy, d{name}/dz) by forward mode")
        lines += _function("vec4", f"{name}_grad", em.grad_body())
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------------- colours
def albedo_functions(prog, name: str = "sdf_albedo",
                     default: tuple[float, ...] = (0.8, 0.8, 0.8)
                     ) -> tuple[list[str], list[str]]:
    """GLSL of a program's colour section (:attr:`csdf.Program.colors`, the rule of
    :mod:`csdf.colors`): ``(params, lines)``, the main program's parameters that the
    colour programs read (``(identifier, comment)``; the caller declares them, as
    uniforms or constants) and the functions, ending in ``vec3 <name>(vec3 p)``, the RGB
    colour at ``p``; ``default`` (RGB) for uncoloured surfaces, and everywhere for a
    program without colours."""
    _check_name(name)

    def vec3(c) -> str:
        return "vec3(" + ", ".join(glsl_float(float(v)) for v in tuple(c)[:3]) + ")"

    section = getattr(prog, "colors", None)
    if section is None:
        return [], [f"vec3 {name}(vec3 p) {{", f"    return {vec3(default)};", "}"]
    ids = {p.name: uniform_name(p.name, i) for i, p in enumerate(prog.params)}
    progs, palette = section
    chans = progs if palette is None else (progs,)
    used = {p.name for c in chans for p in c.params}
    params = [(ids[p.name], _param_comment(p)) for p in prog.params if p.name in used]
    lines: list[str] = []
    if palette is None:  # channel programs r, g, b, a, u
        for c, cp in zip("rgbu", (progs[0], progs[1], progs[2], progs[4])):
            lines += _function("float", f"{name}_{c}", _Emitter(cp, ids).value_body())
        lines += [f"vec3 {name}(vec3 p) {{",
                  f"    vec3 c = vec3({name}_r(p), {name}_g(p), {name}_b(p)) + "
                  f"{name}_u(p) * {vec3(default)};",
                  "    return clamp(c, 0.0, 1.0);", "}"]
        return params, lines
    rows = np.where(np.isnan(palette), np.array(tuple(default)[:3] + (1.0,)), palette)
    lines += _function("float", f"{name}_index", _Emitter(progs, ids).value_body())
    lines += [f"vec3 {name}(vec3 p) {{", f"    float k = {name}_index(p);"]
    for k in range(len(rows) - 1):
        lines.append(f"    if (k < {k}.5) return {vec3(rows[k])};")
    lines += [f"    return {vec3(rows[-1])};", "}"]
    return params, lines


# ---------------------------------------------------------------------------- Shadertoy
_DEFAULT_RADIUS = 1.5

_SHADERTOY_MAIN = """
const vec3 CSDF_CENTER = {center};
const float CSDF_RADIUS = {radius}; // bounding radius of the shape
const float CSDF_STEP = {step}; // sphere-tracing step scale: 1 / Lipschitz bound
const int CSDF_STEPS = {steps};

vec3 csdfNormal(vec3 p) {{
    vec2 e = vec2(1e-3 * CSDF_RADIUS, 0.0);
    return normalize(vec3(
        sdf(p + e.xyy) - sdf(p - e.xyy),
        sdf(p + e.yxy) - sdf(p - e.yxy),
        sdf(p + e.yyx) - sdf(p - e.yyx)));
}}

vec3 csdfBackground(vec3 rd) {{
    return mix(vec3(0.08, 0.09, 0.11), vec3(0.30, 0.34, 0.40), 0.5 + 0.5 * rd.z);
}}

void mainImage(out vec4 fragColor, in vec2 fragCoord) {{
    vec2 uv = (2.0 * fragCoord - iResolution.xy) / iResolution.y;
    // camera orbiting the z axis (csdf's up axis), looking at the shape's centre
    float a = 0.5 * iTime + 0.6;
    float e = 0.45;
    vec3 ro = CSDF_CENTER + 2.2 * CSDF_RADIUS * vec3(cos(a) * cos(e), sin(a) * cos(e), sin(e));
    vec3 ww = normalize(CSDF_CENTER - ro);
    vec3 uu = normalize(cross(ww, vec3(0.0, 0.0, 1.0)));
    vec3 vv = cross(uu, ww);
    vec3 rd = normalize(uv.x * uu + uv.y * vv + 1.8 * ww);
    float far = 12.0 * CSDF_RADIUS;
    float eps = 2e-4 * CSDF_RADIUS;
    float t = 0.0;
    bool hit = false;
    for (int i = 0; i < CSDF_STEPS; i++) {{
        float d = abs(sdf(ro + t * rd));
        if (d < eps * (1.0 + t)) {{ hit = true; break; }}
        t += d * CSDF_STEP;
        if (t > far) break;
    }}
    vec3 col = csdfBackground(rd);
    if (hit) {{
        vec3 p = ro + t * rd;
        vec3 n = csdfNormal(p);
        if (dot(n, rd) > 0.0) n = -n; // seen from inside the solid (e.g. a complement)
        vec3 l = normalize(vec3(0.6, 0.4, 0.9));
        float dif = clamp(dot(n, l), 0.0, 1.0);
        float amb = 0.5 + 0.5 * n.z;
        float spe = pow(clamp(dot(reflect(rd, n), l), 0.0, 1.0), 24.0);
        vec3 base = {base};
        col = base * (0.25 * amb + 0.85 * dif) + 0.25 * spe;
        col = mix(col, csdfBackground(rd), smoothstep(0.4 * far, far, t));
    }}
    fragColor = vec4(pow(clamp(col, 0.0, 1.0), vec3(0.4545)), 1.0);
}}
"""


def _view(shape_or_program) -> tuple[np.ndarray, float]:
    """Centre and radius to frame: the Shape's bounds, else the origin and 1.5."""
    bounds = getattr(shape_or_program, "bounds", None)
    if _is_program(shape_or_program) or bounds is None:
        return np.zeros(3), _DEFAULT_RADIUS
    b = np.asarray(bounds, dtype=np.float64)
    if b.shape[0] != 2 or not np.all(np.isfinite(b)):
        return np.zeros(3), _DEFAULT_RADIUS
    center = np.zeros(3)
    center[: b.shape[1]] = 0.5 * (b[0] + b[1])
    radius = 0.5 * float(np.linalg.norm(b[1] - b[0]))
    return center, radius if radius > 1e-6 else _DEFAULT_RADIUS


def shadertoy(shape_or_program) -> str:
    """A complete Shadertoy "Image" shader rendering the shape (paste-ready).

    It sphere-traces ``sdf`` from a camera orbiting the shape (``iTime``,
    ``iResolution``), with steps divided by the program's Lipschitz bound when it is
    above 1 (0.5 step scale when the bound is infinite), shading by normals from central
    differences. Parameters become ``const float u_<name> = <default>;`` (Shadertoy has
    no custom uniforms): edit them there. A Shape is framed by its bounds; a Program (or
    an unbounded shape) by a radius-1.5 sphere about the origin. A coloured model is
    drawn in its colours (:func:`albedo_functions`), others in a normal-tinted grey.
    """
    prog = _program(shape_or_program)
    em = _Emitter(prog)
    lip = prog.lipschitz
    if math.isinf(lip) or math.isnan(lip):
        step = 0.5
    else:
        step = 1.0 / lip if lip > 1.0 else 1.0
    center, radius = _view(shape_or_program)
    lines = _header(prog, "Shadertoy Image shader")
    lines.append("// paste into the Image tab; parameters are constants below")
    for i, p in enumerate(prog.params):
        lines.append(
            f"const float {uniform_name(p.name, i)} = {glsl_float(p.default)}; "
            f"// {_param_comment(p)}"
        )
    lines.append("")
    lines += _function("float", "sdf", em.value_body())
    base = "0.55 + 0.35 * n"
    if prog.colors is not None:  # the model's colours (sRGB) as linear albedo
        lines.append("")
        lines += albedo_functions(prog, "sdf_albedo")[1]
        base = "pow(sdf_albedo(p), vec3(2.2))"
    main = _SHADERTOY_MAIN.format(
        center="vec3({})".format(", ".join(glsl_float(c) for c in center)),
        radius=glsl_float(radius),
        step=glsl_float(step),
        steps=int(min(1024, math.ceil(160 / step))),
        base=base,
    )
    return "\n".join(lines) + "\n" + main
