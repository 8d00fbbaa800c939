"""A compiled program as C and as a NumPy module (paper §4.3: a distance function is "a
function that accepts a triplet of floating-point coordinates and returns a distance",
in the language of choice): :func:`to_c`, :func:`to_numpy`.

**C** (:func:`to_c`): a self-contained header (C99, also valid C++) with, for a model
named ``NAME``:

* ``NAME_params``: a struct of ``double`` members, one per parameter (in
  :attr:`Program.params` order, named as the parameters; a C keyword gets a trailing
  ``_``), and ``NAME_defaults`` holding the defaults; ``NAME_NPARAMS``;
* ``double NAME(const double p[3], const NAME_params *prm)``: the value;
* ``double NAME_all(const double p[3], const NAME_params *prm, double grad[3], double
  *dparams)``: the value, its gradient into ``grad`` and its derivatives by the
  parameters into ``dparams`` (``NAME_NPARAMS`` values; either pointer may be NULL);
* ``float NAME_f(...)`` and ``float NAME_all_f(...)``: the same in float arithmetic.

The code is the tape as straight-line statements, one temporary per instruction, and the
derivatives are forward mode from the op specification (:mod:`csdf.ops`), rendered
from the same formulas as every evaluator, so the double functions agree with csdf's to
rounding. ``min``/``max`` follow csdf's tie rule; NaN does not propagate through them
(a comparison picks an operand), ``sign(NaN)`` is 0.

**NumPy** (:func:`to_numpy`): a module with ``PARAMS`` (name -> default), ``value(points,
**params) -> (N,)`` and ``value_and_grad(points, **params) -> ((N,), (N, 3))``, on
float64 arrays with NumPy only.

Safety: the text is built only from the program's validated numbers, op names, the
fixed derivative formulas and parameter names (identifiers by construction); the model
name must be a plain identifier.
"""

from __future__ import annotations

import math
import re

from ..errors import CsdfError
from ..opformula import Formula, Target
from ..ops import OPS, OPS_BY_CODE, chain_tangent, tie_comparison
from ..version import __version__

__all__ = ["to_c", "to_numpy"]

_IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_C_KEYWORDS = frozenset("""
auto break case char const continue default do double else enum extern float for goto if
inline int long register restrict return short signed sizeof static struct switch
typedef union unsigned void volatile while bool true false class new delete this
template typename namespace public private protected virtual operator friend
""".split())

_C_UNARY = {
    "neg": "-{a}", "abs": "{fabs}({a})", "sqrt": "{sqrt}({a})", "square": "{a} * {a}",
    "sin": "{sin}({a})", "cos": "{cos}({a})", "tan": "{tan}({a})", "asin": "{asin}({a})",
    "acos": "{acos}({a})", "atan": "{atan}({a})", "exp": "{exp}({a})", "log": "{log}({a})",
    "floor": "{floor}({a})", "step": "({a} >= 0 ? ({T})1 : ({T})0)",
    "sign": "({T})(({a} > 0) - ({a} < 0))",
}
_C_BINARY = {
    "add": "{a} + {b}", "sub": "{a} - {b}", "mul": "{a} * {b}", "div": "{a} / {b}",
    "min": "({a} < {b} ? {a} : {b})", "max": "({a} > {b} ? {a} : {b})",
    "atan2": "{atan2}({a}, {b})", "mod": "{a} - {b} * {floor}({a} / {b})",
}
_C_FUNCS = ("fabs", "sqrt", "sin", "cos", "tan", "asin", "acos", "atan", "exp", "log",
            "floor", "atan2")

_NP_UNARY = {
    "neg": "-{a}", "abs": "np.abs({a})", "sqrt": "np.sqrt({a})", "square": "{a} * {a}",
    "sin": "np.sin({a})", "cos": "np.cos({a})", "tan": "np.tan({a})",
    "asin": "np.arcsin({a})", "acos": "np.arccos({a})", "atan": "np.arctan({a})",
    "exp": "np.exp({a})", "log": "np.log({a})", "floor": "np.floor({a})",
    "step": "np.heaviside({a}, 1.0)", "sign": "np.sign({a})",
}
_NP_BINARY = {
    "add": "{a} + {b}", "sub": "{a} - {b}", "mul": "{a} * {b}", "div": "{a} / {b}",
    "min": "np.minimum({a}, {b})", "max": "np.maximum({a}, {b})",
    "atan2": "np.arctan2({a}, {b})", "mod": "{a} - {b} * np.floor({a} / {b})",
}
_NP_CMP = {"<": "np.less", "<=": "np.less_equal", ">": "np.greater",
           ">=": "np.greater_equal"}


def _program(obj):
    from ..compiler.program import Program

    prog = obj if isinstance(obj, Program) else getattr(obj, "compile", lambda: None)()
    if not isinstance(prog, Program):
        raise CsdfError(f"expected a shape or a program, got {type(obj).__name__}")
    if prog.dim not in (2, 3):
        raise CsdfError(f"program dim must be 2 or 3, got {prog.dim}")
    if prog.data:
        raise CsdfError("C and NumPy source export cannot hold a mesh call "
                        "(csdf.from_mesh / polyhedron): its triangle hierarchy is not "
                        "written out; evaluate the shape in Python, or mesh it")
    return prog


def _check_name(name: str) -> None:
    if not isinstance(name, str) or not _IDENT.fullmatch(name) or name in _C_KEYWORDS:
        raise CsdfError(f"the model name must be a C identifier (not a keyword), got "
                        f"{name!r}")


def _c_num(v: float, T: str) -> str:
    if math.isnan(v):
        return f"(({T})NAN)"
    if math.isinf(v):
        return f"(({T})INFINITY)" if v > 0 else f"(-({T})INFINITY)"
    return f"(({T}){float(v)!r})"


def _member(name: str) -> str:
    return name + "_" if name in _C_KEYWORDS else name


class _C:
    """Straight-line C for one program and one float type."""

    def __init__(self, prog, T: str):
        self.prog, self.T = prog, T
        suffix = "f" if T == "float" else ""
        self.fn = {f: f + suffix for f in _C_FUNCS}
        lay = prog.layout
        z = "p[2]" if prog.dim == 3 else f"({T})0"
        self.fixed = {0: "p[0]", 1: "p[1]", 2: z}
        for i, prm in enumerate(prog.params):
            self.fixed[lay.param(i)] = f"(({T})prm->{_member(prm.name)})"
        for i, c in enumerate(prog.consts.tolist()):
            self.fixed[lay.const(i)] = _c_num(c, T)
        self.n = 3 + len(prog.params)
        self.fixed_tan = {0: f"({T})(i == 0)", 1: f"({T})(i == 1)",
                          2: f"({T})(i == 2)" if prog.dim == 3 else None}
        for i in range(len(prog.params)):
            self.fixed_tan[lay.param(i)] = f"({T})(i == {3 + i})"

    def _op(self, name: str, a: str, b: str) -> str:
        tmpl = _C_BINARY.get(name) or _C_UNARY[name]
        return tmpl.format(a=a, b=b, T=self.T, **self.fn)

    def value(self) -> list[str]:
        cur = dict(self.fixed)
        out = []
        for k, (op, dst, a, b) in enumerate(self.prog.code.tolist()):
            info = OPS_BY_CODE[op]
            out.append(f"const {self.T} t{k} = "
                       f"{self._op(info.name, cur[a], cur[b] if info.arity == 2 else '')};")
            cur[dst] = f"t{k}"
        out.append(f"return {cur[self.prog.output]};")
        return out

    def all(self) -> list[str]:
        T, n = self.T, self.n
        cur = dict(self.fixed)
        tan: dict[int, str | None] = dict(self.fixed_tan)
        lines: list[str] = [f"{T} zero_[{n}] = {{0}};", "int i;", "(void)zero_;"]
        calls = {"sin": self.fn["sin"] + "({0})", "cos": self.fn["cos"] + "({0})",
                 "sqrt": self.fn["sqrt"] + "({0})", "floor": self.fn["floor"] + "({0})",
                 "sign": f"({T})(({{0}} > 0) - ({{0}} < 0))",
                 "pos_div": f"({{1}} > 0 ? {{0}} / {{1}} : ({T})0)"}
        n_c = 0
        for k, (op, dst, a, b) in enumerate(self.prog.code.tolist()):
            name, va, vb, ta, tb, rule = _step(op, a, b, cur, tan)
            lines.append(f"const {T} t{k} = {self._op(name, va, vb)};")
            v = cur[dst] = f"t{k}"
            if rule is None:
                tan[dst] = None
                continue
            if rule.kind == "select":
                cmp = tie_comparison(name, self.prog.layout.is_const(a))
                expr = f"({va} {cmp} {vb}) ? {ta or '0'} : {tb or '0'}"
            else:
                names = {"a": va, "b": vb, "v": v}
                target = Target(name=names.__getitem__, literal=lambda x: _c_num(x, T),
                                calls=calls, atom_args=frozenset({"pos_div", "sign"}))
                cache: dict[Formula, str] = {}

                def coef(f: Formula, names=names, target=target, cache=cache, rule=rule):
                    nonlocal n_c
                    if f not in cache:
                        for lname, g in rule.let:
                            if lname not in names:
                                names[lname] = f"c{n_c}"
                                n_c += 1
                                lines.append(f"const {T} {names[lname]} = "
                                             f"{g.render(target)};")
                        names_c = f"c{n_c}"
                        n_c += 1
                        lines.append(f"const {T} {names_c} = {f.render(target)};")
                        cache[f] = names_c
                    return cache[f]

                expr = chain_tangent(rule, ta, tb, coef, _StrAlg())
            lines.append(f"{T} g{k}[{n}];")
            lines.append(f"for (i = 0; i < {n}; ++i) g{k}[i] = {expr};")
            tan[dst] = f"g{k}[i]"
        out_t = tan.get(self.prog.output)
        g = out_t.replace("[i]", "") if out_t and out_t.endswith("[i]") else None
        src = g if g else "zero_"
        if out_t and not g:  # the output is a coordinate or a parameter itself
            lines.append(f"{T} gout_[{n}];")
            lines.append(f"for (i = 0; i < {n}; ++i) gout_[i] = {out_t};")
            src = "gout_"
        lines.append(f"if (grad) {{ grad[0] = {src}[0]; grad[1] = {src}[1]; "
                     f"grad[2] = {src}[2]; }}")
        if len(self.prog.params):
            lines.append(f"if (dparams) for (i = 0; i < {len(self.prog.params)}; ++i) "
                         f"dparams[i] = {src}[3 + i];")
        lines.append(f"return {cur[self.prog.output]};")
        return lines


def _step(op: int, a: int, b: int, cur: dict, tan: dict) -> tuple:
    """``(op name, operand a, operand b, tangent a, tangent b, rule)`` of one instruction
    (``b``'s are empty for a unary op; ``rule`` None when the result's tangent is
    structurally zero)."""
    info = OPS_BY_CODE[op]
    binary = info.arity == 2
    ta, tb = tan.get(a), (tan.get(b) if binary else None)
    rule = OPS[info.name].derivative
    if rule.kind == "zero" or (ta is None and tb is None):
        rule = None
    return info.name, cur[a], (cur[b] if binary else ""), ta, tb, rule


def _mark_unused(lines: list[str]) -> list[str]:
    """``(void)`` casts for the temporaries that no statement reads (dead values or
    tangents of the tape), so the header compiles under ``-Wall -Wextra -Werror``."""
    declared, read = [], set()
    for ln in lines:
        m = re.match(r"(?:const )?\w+ ([tg][0-9]+)(?:\[[0-9]+\])?( = |;)", ln)
        if m:
            declared.append(m.group(1))
            rhs = ln.split(" = ", 1)[1] if m.group(2) == " = " else ""
        elif ln.startswith("for (i = 0;") and "] = " in ln:
            rhs = ln.split("] = ", 1)[1]
        else:
            rhs = ln
        read.update(re.findall(r"\b[tg][0-9]+\b", rhs))
    unused = [f"(void){n};" for n in declared if n not in read]
    return lines[:-1] + unused + lines[-1:]


class _StrAlg:
    """Tangent algebra on source text (C element expressions with index ``i``, or
    NumPy ``(N, 3)`` array expressions)."""

    def scale(self, f, t):
        return f"{f} * {t}"

    def add(self, u, v):
        return f"({u} + {v})"

    def sub(self, u, v):
        return f"({u} - ({v}))"

    def neg(self, t):
        return f"(-({t}))"


def to_c(shape_or_program, name: str = "sdf") -> str:
    """A self-contained C header of the model (see the module documentation).

    Raises:
        CsdfError: not a shape or program, or a name that is not a C identifier.
    """
    _check_name(name)
    prog = _program(shape_or_program)
    P = len(prog.params)
    guard = f"CSDF_{name.upper()}_H"
    out = [f"/* {name}: generated by csdf {__version__} from a compiled program: "
           f"{len(prog.code)} instructions, {P} parameters, {prog.dim}D; exactness "
           f"{prog.exactness}, Lipschitz bound {prog.lipschitz!r} */",
           f"#ifndef {guard}", f"#define {guard}", "#include <math.h>", "",
           f"#define {name.upper()}_NPARAMS {P}", ""]
    if P:
        members = " ".join(f"double {_member(p.name)};" for p in prog.params)
        out.append(f"typedef struct {{ {members} }} {name}_params;")
        vals = ", ".join(repr(float(p.default)) for p in prog.params)
        out.append(f"static const {name}_params {name}_defaults = {{ {vals} }};")
        for p in prog.params:
            out.append(f"/*   {p.name}: default {p.default!r}, range [{p.lo!r}, {p.hi!r}] */")
    else:
        out.append(f"typedef struct {{ int unused_; }} {name}_params;")
        out.append(f"static const {name}_params {name}_defaults = {{ 0 }};")
    out.append("")
    for T, sfx in (("double", ""), ("float", "_f")):
        c = _C(prog, T)
        head = f"static inline {T} {name}{sfx}(const {T} p[3], const {name}_params *prm)"
        out += [head + " {", "    (void)prm;",
                *("    " + ln for ln in _mark_unused(c.value())), "}", ""]
        head = (f"static inline {T} {name}_all{sfx}(const {T} p[3], const {name}_params *prm, "
                f"{T} grad[3], {T} *dparams)")
        out += [head + " {", "    (void)prm; (void)dparams;",
                *("    " + ln for ln in _mark_unused(c.all())), "}", ""]
    out.append(f"#endif /* {guard} */")
    return "\n".join(out) + "\n"


def to_numpy(shape_or_program, name: str = "sdf") -> str:
    """The source of a NumPy module of the model (see the module documentation).

    Raises:
        CsdfError: not a shape or program, or a name that is not an identifier.
    """
    _check_name(name)
    prog = _program(shape_or_program)
    lay = prog.layout
    fixed = {0: "x", 1: "y", 2: "z" if prog.dim == 3 else "0.0"}
    for i in range(len(prog.params)):
        fixed[lay.param(i)] = f"_p[{i}]"
    for i, c in enumerate(prog.consts.tolist()):
        fixed[lay.const(i)] = (f"np.float64({c!r})" if math.isfinite(c) else
                               f"np.float64({'np.inf' if c > 0 else '-np.inf'})"
                               if not math.isnan(c) else "np.nan")
    tans: dict[int, str | None] = {0: "_E[0]", 1: "_E[1]",
                                   2: "_E[2]" if prog.dim == 3 else None}
    calls = {"sin": "np.sin({0})", "cos": "np.cos({0})", "sqrt": "np.sqrt({0})",
             "floor": "np.floor({0})", "sign": "np.sign({0})",
             "pos_div": "np.where({1} > 0, {0} / np.where({1} > 0, {1}, 1.0), 0.0)"}
    val: list[str] = []
    grad: list[str] = []
    cur = dict(fixed)
    n_c = 0
    for k, (op, dst, a, b) in enumerate(prog.code.tolist()):
        nm, va, vb, ta, tb, rule = _step(op, a, b, cur, tans)
        tmpl = _NP_BINARY.get(nm) or _NP_UNARY[nm]
        stmt = f"t{k} = {tmpl.format(a=va, b=vb)}"
        val.append(stmt)
        grad.append(stmt)
        v = cur[dst] = f"t{k}"
        if rule is None:
            tans[dst] = None
            continue
        if rule.kind == "select":
            cmp = _NP_CMP[tie_comparison(nm, lay.is_const(a))]
            expr = (f"np.where(({cmp}({va}, {vb}))[:, None], {ta or '0.0'}, "
                    f"{tb or '0.0'})")
        else:
            names = {"a": va, "b": vb, "v": v}
            target = Target(name=names.__getitem__, literal=lambda x: repr(float(x)),
                            calls=calls, atom_args=frozenset({"pos_div"}))

            def coef(f: Formula, names=names, target=target, rule=rule):
                nonlocal n_c
                for lname, g in rule.let:
                    if lname not in names:
                        names[lname] = f"c{n_c}"
                        n_c += 1
                        grad.append(f"{names[lname]} = {g.render(target)}")
                cname = f"c{n_c}"
                n_c += 1
                grad.append(f"{cname} = np.broadcast_to({f.render(target)}, x.shape)")
                return f"{cname}[:, None]"

            expr = chain_tangent(rule, ta, tb, coef, _StrAlg())
        grad.append(f"g{k} = np.broadcast_to({expr}, (len(x), 3))")
        tans[dst] = f"g{k}"
    out_v = cur[prog.output]
    out_g = tans.get(prog.output)
    lines = [f'"""{name}: generated by csdf {__version__} from a compiled program '
             f"({len(prog.code)} instructions, {len(prog.params)} parameters, "
             f'{prog.dim}D, {prog.exactness}). Needs NumPy only."""', "",
             "import numpy as np", "",
             "PARAMS = {" + ", ".join(f"{p.name!r}: {float(p.default)!r}"
                                      for p in prog.params) + "}",
             "_E = np.eye(3)", "", "",
             "def _args(points, params):",
             "    unknown = set(params) - set(PARAMS)",
             "    if unknown:",
             "        raise ValueError(f'unknown parameters: {sorted(unknown)}')",
             "    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)",
             "    vals = dict(PARAMS, **params)",
             "    return pts[:, 0], pts[:, 1], pts[:, 2], [float(vals[n]) for n in PARAMS]",
             "", "",
             "def value(points, **params):",
             '    """(N,) signed distances of points (N, 3)."""',
             "    x, y, z, _p = _args(points, params)",
             "    with np.errstate(all='ignore'):",
             *("        " + s for s in val or ["pass"]),
             f"    return np.broadcast_to({out_v}, x.shape).astype(np.float64)",
             "", "",
             "def value_and_grad(points, **params):",
             '    """((N,), (N, 3)): signed distances and their gradients."""',
             "    x, y, z, _p = _args(points, params)",
             "    with np.errstate(all='ignore'):",
             *("        " + s for s in grad or ["pass"]),
             f"    v = np.broadcast_to({out_v}, x.shape).astype(np.float64)",
             f"    g = np.broadcast_to({out_g or '0.0'}, (len(x), 3)).astype(np.float64)",
             "    return v, g", ""]
    return "\n".join(lines)
