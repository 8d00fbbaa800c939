"""Generate a Numba kernel for one program structure (the ``'fast'`` backend's code).

The kernel evaluates a block of points at a time: it copies the block's coordinates
into three small arrays, then runs one loop over the block whose body is the whole tape
as straight-line code (one SSA temporary per instruction), which LLVM vectorises across
points with every intermediate value in a CPU register. Derivatives are sparse forward
mode: each value carries only the tangent components that are not structurally zero
(a value that depends on x alone has no d/dy code), so the generated code stays small.

Every op's code comes from its specification in :mod:`csdf.ops`: the derivative factors
are rendered from the spec's formulas (:meth:`csdf.opformula.Formula.render`) and
combined by :func:`csdf.ops.chain_tangent`, and ``min``/``max`` compare by
:func:`csdf.ops.tie_comparison`; only the value expressions and the scalar helpers of
:mod:`csdf.backends.scalar_ops` are written here.

Safety: the source is built only from the validated program: op names and formulas
from the fixed table in :mod:`csdf.ops`, integer indices, and identifiers made here. Constants,
parameter values and the parameter-only prefix are passed in an array ``u`` (so
programs that differ only in constants share a kernel); no user text ever reaches it.
"""

from __future__ import annotations

import hashlib
import re

from ..opformula import Formula, Target
from ..ops import OPS, OPS_BY_CODE, chain_tangent, tie_comparison
from .lowering import UNIFORM_BASE

__all__ = ["generate", "structure_key", "CODEGEN_VERSION"]

CODEGEN_VERSION = 7
BLOCK = 256
SEGMENT = 2000  # statements per generated function

# extra uniform constants appended after the program's uniform rows
_K_ZERO, _K_ONE, _K_TWO, _K_HALF, _K_NAN = range(5)
N_EXTRA = 5
# the literals a formula of csdf.ops may use, as those uniform constants
_LITERALS = {0.0: f"k{_K_ZERO}", 1.0: f"k{_K_ONE}", 2.0: f"k{_K_TWO}", 0.5: f"k{_K_HALF}"}
_CALLS = {
    "sin": "np.sin({0})", "cos": "np.cos({0})", "sqrt": "np.sqrt({0})",
    "floor": "np.floor({0})", "sign": f"sign_({{0}}, k{_K_ONE}, k{_K_ZERO})",
    "pos_div": f"safe_div_({{0}}, {{1}}, k{_K_ZERO})",
}


def _literal(x: float) -> str:
    try:
        return _LITERALS[x]
    except KeyError:
        raise ValueError(f"codegen has no uniform constant for the literal {x!r}") from None

_VALUE = {
    "add": "{a} + {b}",
    "sub": "{a} - {b}",
    "mul": "{a} * {b}",
    "div": "{a} / {b}",
    "square": "{a} * {a}",
    "neg": "-{a}",
    "abs": "abs({a})",
    "sqrt": "np.sqrt({a})",
    "sin": "np.sin({a})",
    "cos": "np.cos({a})",
    "tan": "np.tan({a})",
    "asin": "np.arcsin({a})",
    "acos": "np.arccos({a})",
    "atan": "np.arctan({a})",
    "exp": "np.exp({a})",
    "log": "np.log({a})",
    "floor": "np.floor({a})",
    "atan2": "np.arctan2({a}, {b})",
    "mod": "{a} - {b} * np.floor({a} / {b})",
}


def structure_key(low, mode: str) -> str:
    """Hash of everything the generated source depends on (kept on ``low`` per mode: a
    lowering does not change)."""
    keys = low.__dict__.setdefault("_structure_keys", {})
    key = keys.get(mode)
    if key is None:
        key = keys[mode] = _structure_key(low, mode)
    return key


def _structure_key(low, mode: str) -> str:
    h = hashlib.blake2b(digest_size=16)
    h.update(f"v{CODEGEN_VERSION}|{mode}|{low.n_params}|{low.n_consts}|{low.n_uniform_rows}|"
             f"{low.out_row}|".encode())  # (n_consts: which rows are constants, for ties)
    h.update(low.code[:, :4].tobytes())
    h.update(bytes(sorted(low.prefix_param_deps_key())))
    return h.hexdigest()


class _Gen:
    def __init__(self, low, mode: str):
        self.low = low
        self.lines: list[str] = []
        self.mode = mode
        P = low.n_params
        self.spatial = mode in ("grad", "all")
        self.wrt = mode == "all"
        self.T = (3 if self.spatial else 0) + (P if self.wrt else 0)
        self.off = 3 if self.spatial else 0
        U = low.n_uniform_rows
        self.K = {i: f"k{i}" for i in range(N_EXTRA)}
        self.U = U
        # value names and tangent lists per row
        self.val: dict[int, str] = {0: "x", 1: "y", 2: "z"}
        self.tan: dict[int, list] = {}
        for r in range(3):
            t = [None] * self.T
            if self.spatial:
                t[r] = "1"
            self.tan[r] = t
        for i in range(U):
            self.val[UNIFORM_BASE + i] = f"u{i}"
            self.tan[UNIFORM_BASE + i] = [None] * self.T
        if self.wrt:
            for i in range(P):
                self.tan[low.layout.param(i)][self.off + i] = "1"
            for row, deps in low.prefix_param_deps().items():
                for p in deps:
                    self.tan[row][self.off + p] = f"du{row - UNIFORM_BASE}_{p}"
        self.n_tmp = 0

    def tmp(self) -> str:
        self.n_tmp += 1
        return f"t{self.n_tmp}"

    def emit(self, expr: str) -> str:
        name = self.tmp()
        self.lines.append(f"{name} = {expr}")
        return name

    # tangent algebra on names; "1" is the constant one, None is zero
    def scale(self, f: str, t):
        if t is None:
            return None
        if t == "1":
            return f
        return self.emit(f"{f} * {t}")

    def add(self, u, v, neg_v: bool = False):
        if v is None:
            return u
        if u is None:
            return self.emit(f"-{self._v(v)}") if neg_v else v
        return self.emit(f"{self._v(u)} {'-' if neg_v else '+'} {self._v(v)}")

    def _v(self, t: str) -> str:
        return self.K[_K_ONE] if t == "1" else t

    # the tangent algebra of csdf.ops.chain_tangent, on names
    def neg(self, t):
        return self.emit(f"-{self._v(t)}")

    def sub(self, u, v):
        return self.add(u, v, neg_v=True)

    def instr(self, op: str, d: int, a: int, b: int | None):
        va = self.val[a]
        vb = self.val[b] if b is not None else None
        K = self.K
        c = None
        if op == "min" or op == "max":
            if self.T:  # which operand's tangent: the tie rule of csdf.ops
                cmp = tie_comparison(op, self.low.is_const_row(a))
                c = self.emit(f"{va} {cmp} {vb}")
            v = self.emit(f"{op}_({va}, {vb})")
        elif op == "step":
            v = self.emit(f"step_({va}, {K[_K_ONE]}, {K[_K_ZERO]})")
        elif op == "sign":
            v = self.emit(f"sign_({va}, {K[_K_ONE]}, {K[_K_ZERO]})")
        else:
            v = self.emit(_VALUE[op].format(a=va, b=vb))
        self.val[d] = v
        if self.T:
            tb = self.tan[b] if b is not None else [None] * self.T
            self.tan[d] = self.tangent(op, va, vb, v, self.tan[a], tb, c)

    def tangent(self, op, a, b, v, ta, tb, c):
        """Tangent names of ``v = op(a, b)`` by the op's rule in :mod:`csdf.ops`."""
        K = self.K
        T = self.T
        rule = OPS[op].derivative
        if rule.kind == "zero":
            return [None] * T
        if rule.kind == "select":
            out = []
            for x, y in zip(ta, tb):
                if x is None and y is None:
                    out.append(None)
                else:
                    xs = K[_K_ZERO] if x is None else self._v(x)
                    ys = K[_K_ZERO] if y is None else self._v(y)
                    out.append(self.emit(f"sel_({c}, {xs}, {ys})"))
            return out
        names = {"a": a, "b": b, "v": v}
        target = Target(name=names.__getitem__, literal=_literal, calls=_CALLS)
        cache: dict[Formula, str] = {}

        def coef(f: Formula) -> str:
            """The formula's value, emitted once per instruction (``let`` names first)."""
            if f not in cache:
                for name, g in rule.let:
                    if name not in names:
                        names[name] = self.emit(g.render(target))
                cache[f] = names[f.text] if f.is_name else self.emit(f.render(target))
            return cache[f]

        return [chain_tangent(rule, x, y, coef, self) for x, y in zip(ta, tb)]

    def source(self) -> str:
        low = self.low
        for op, d, a, b, _ in low.code.tolist():
            info = OPS_BY_CODE[op]
            self.instr(info.name, d, a, b if info.arity == 2 else None)
        out_v = self.val[low.out_row]
        out_t = self.tan.get(low.out_row, [None] * self.T) if self.T else []
        outs = [out_v] + [self.K[_K_ZERO] if t is None else self._v(t) for t in out_t]
        segs = [self.lines[i:i + SEGMENT] for i in range(0, len(self.lines), SEGMENT)] or [[]]
        if len(segs) == 1:
            return self._single(segs[0], outs)
        return self._segmented(segs, outs)

    # -- pieces shared by both layouts -------------------------------------------------
    def _uniform_loads(self, names: set[str] | None, ind: str) -> list[str]:
        """Scalar loads of the uniform values (all, or those in ``names``)."""
        U = self.U
        loads = [(f"u{i}", f"u[{i}]") for i in range(U)]
        loads += [(f"k{i}", f"u[{U + i}]") for i in range(N_EXTRA)]
        if self.wrt:
            for row, deps in self.low.prefix_param_deps().items():
                i = row - UNIFORM_BASE
                loads += [(f"du{i}_{p}", f"du[{i}, {p}]") for p in deps]
        return [f"{ind}{n} = {src}" for n, src in loads if names is None or n in names]

    def _stores(self, outs: list[str], ind: str) -> list[str]:
        nan = self.K[_K_NAN]
        lines = [f"{ind}bad = (x != x) | (y != y) | (z != z)",
                 f"{ind}O[0, j] = {nan} if bad else {outs[0]}"]
        if len(outs) > 1:
            lines.append(f"{ind}bad = bad | ({outs[0]} != {outs[0]})")
        lines += [f"{ind}O[{c}, j] = {nan} if bad else {o}" for c, o in enumerate(outs) if c]
        return lines

    def _tail(self) -> list[str]:
        tail = ["        for j in range(m):", "            out[s + j] = O[0, j]"]
        if self.spatial:
            tail += ["        for j in range(m):"]
            tail += [f"            grad[s + j, {i}] = O[{1 + i}, j]" for i in range(3)]
        if self.wrt and self.low.n_params:
            tail += [f"        for c in range({self.low.n_params}):",
                     "            for j in range(m):",
                     f"                jac[s + j, c] = O[{1 + self.off} + c, j]"]
        return tail + [""]

    def _head(self) -> list[str]:
        return [
            "# generated by csdf.backends.codegen from a validated program; do not edit",
            "import numpy as np",
            "from numba import njit",
            "",
            "from csdf.backends.scalar_ops import max_, min_, safe_div_, sel_, sign_, step_",
            "",
        ]

    def _single(self, body: list[str], outs: list[str]) -> str:
        """Small programs: the whole tape inline, every value in a register."""
        ind = " " * 12
        lines = self._head() + [
            "",
            _DECOR,
            "def kernel(pts, u, du, out, grad, jac, start, stop):",
            f"    B = {BLOCK}",
            "    X = np.empty(B, pts.dtype)",
            "    Y = np.empty(B, pts.dtype)",
            "    Z = np.empty(B, pts.dtype)",
            f"    O = np.empty(({1 + self.T}, B), pts.dtype)",
            "    d3 = pts.shape[1] == 3",
            *self._uniform_loads(None, "    "),
            "    for s in range(start, stop, B):",
            "        m = min(B, stop - s)",
            "        for j in range(m):",
            "            X[j] = pts[s + j, 0]",
            "            Y[j] = pts[s + j, 1]",
            f"            Z[j] = pts[s + j, 2] if d3 else k{_K_ZERO}",
            "        for j in range(m):",
            "            x = X[j]",
            "            y = Y[j]",
            "            z = Z[j]",
            *[ind + ln for ln in body],
            *self._stores(outs, ind),
            *self._tail(),
        ]
        return "\n".join(lines)

    def _segmented(self, segs: list[list[str]], outs: list[str]) -> str:
        """Large programs: the tape split into functions of at most ``SEGMENT`` statements
        (Numba's compile time and recursion depth grow with function size); values that
        cross a split live in a small per-block scratch array ``S``."""
        defined_in: dict[str, int] = {"x": -1, "y": -1, "z": -1}
        uses: list[set[str]] = []
        for si, seg in enumerate(segs):
            used: set[str] = set()
            for ln in seg:
                name, expr = ln.split(" = ", 1)
                used |= set(_NAME.findall(expr))
                defined_in[name] = si
            uses.append(used)
        final_uses = {n for o in outs for n in _NAME.findall(o)} | {"x", "y", "z"}
        crossing: set[str] = {"x", "y", "z"}
        for si, used in enumerate(uses):
            crossing |= {n for n in used if n in defined_in and defined_in[n] < si}
        crossing |= {n for n in final_uses if n in defined_in}
        rows = {"x": 0, "y": 1, "z": 2}
        for n in sorted(crossing - {"x", "y", "z"}, key=lambda n: int(n[1:])):
            rows[n] = len(rows)
        lines = self._head()
        for si, seg in enumerate(segs):
            used = uses[si]
            own = {ln.split(" = ", 1)[0] for ln in seg}
            live_in = sorted(n for n in used if n in rows and n not in own)
            live_out = sorted(n for n in own if n in rows)
            lines += [
                "",
                _DECOR,
                f"def seg{si}(S, u, du, m):",
                *self._uniform_loads(used, "    "),
                "    for j in range(m):",
                *[f"        {n} = S[{rows[n]}, j]" for n in live_in],
                *["        " + ln for ln in seg],
                *[f"        S[{rows[n]}, j] = {n}" for n in live_out],
            ]
        ind = " " * 12
        lines += [
            "",
            _DECOR,
            "def kernel(pts, u, du, out, grad, jac, start, stop):",
            f"    B = {BLOCK}",
            f"    S = np.empty(({len(rows)}, B), pts.dtype)",
            f"    O = np.empty(({1 + self.T}, B), pts.dtype)",
            "    d3 = pts.shape[1] == 3",
            *self._uniform_loads(final_uses | {f"k{_K_ZERO}", f"k{_K_NAN}"}, "    "),
            "    for s in range(start, stop, B):",
            "        m = min(B, stop - s)",
            "        for j in range(m):",
            "            S[0, j] = pts[s + j, 0]",
            "            S[1, j] = pts[s + j, 1]",
            f"            S[2, j] = pts[s + j, 2] if d3 else k{_K_ZERO}",
            *[f"        seg{si}(S, u, du, m)" for si in range(len(segs))],
            "        for j in range(m):",
            *[f"{ind}{n} = S[{rows[n]}, j]" for n in sorted(final_uses & set(rows))],
            *self._stores(outs, ind),
            *self._tail(),
        ]
        return "\n".join(lines)


_DECOR = '@njit(nogil=True, cache=True, error_model="numpy", boundscheck=False)'
_NAME = re.compile(r"\b(t\d+|x|y|z|u\d+|k\d+|du\d+_\d+)\b")


def generate(low, mode: str) -> str:
    """Python source of the kernel for a lowered program in ``mode``
    (``'value' | 'grad' | 'all'``): ``kernel(pts, u, du, out, grad, jac, start, stop)``
    writes ``out (N,)``, ``grad (N, 3)`` (``grad``, ``all``) and ``jac (N, P)`` (``all``)
    for the points ``[start, stop)``. ``u`` holds the uniform rows then the constants
    0, 1, 2, 0.5, NaN; ``du (U, P)`` the parameter derivatives of the uniform rows."""
    return _Gen(low, mode).source()
