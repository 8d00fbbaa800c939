"""Preparing a program for the Numba backends (``'interp'`` and ``'fast'``).

Per program (cached on the Program) the tape is *lowered*:

* the leading instructions that depend only on parameters and constants (the compiler
  puts them first) are split off; their values, and their derivatives by the
  parameters, are computed once per call by a compiled interpreter of one point
  (:func:`csdf.backends.interp_kernels.prefix_kernel`: the kernels' own rules);
* every uniform value (parameter, constant, prefix result) gets its own row, and the
  rest of the tape is renamed to read them, so a block never reloads them;
* each instruction is flagged when an operand's tangent is structurally zero, so the
  derivative kernels skip that half of a product or sum, and with the tie rule of
  ``min``/``max`` (:func:`csdf.ops.tie_strict`).

Rows: ``0 .. 2`` x, y, z; from :data:`UNIFORM_BASE` the parameters then the constants
(at their slot numbers, :class:`csdf.layout.SlotLayout`), then the prefix results; then
the registers. The points are split over the cores by :func:`csdf.parallel.run_parallel`.
"""

from __future__ import annotations

import numpy as np

from ..cache import memo
from ..layout import N_COORDS
from ..ops import OPS_BY_CODE, tie_strict
from .interp_kernels import prefix_kernel
from .rows import FLAG_A_ZERO, FLAG_B_ZERO, FLAG_OUT_ZERO, FLAG_TIE_STRICT, UNIFORM_BASE

__all__ = ["Lowered", "lowered", "numba_available", "UNIFORM_BASE", "FLAG_B_ZERO",
           "FLAG_A_ZERO", "FLAG_OUT_ZERO", "FLAG_TIE_STRICT"]


def numba_available() -> bool:
    """True when Numba can be imported."""
    try:
        import numba  # noqa: F401
    except Exception:  # pragma: no cover - numba is a dependency
        return False
    return True


class Lowered:
    """A program prepared for the kernels (see the module docstring)."""

    def __init__(self, prog):
        lay = prog.layout
        n_fixed = lay.n_fixed
        P = lay.n_params
        code = prog.code.tolist()
        # 1. the uniform prefix
        uniform_slots = set(range(lay.param_base, n_fixed))
        n_prefix = 0
        for op, dst, a, b in code:
            arity = OPS_BY_CODE[op].arity
            if a in uniform_slots and (arity == 1 or b in uniform_slots):
                uniform_slots.add(dst)
                n_prefix += 1
            else:
                break
        self.n_prefix = n_prefix
        # 2. rows: x y z | params consts | prefix results | registers
        loc = {i: i for i in range(N_COORDS)}
        for s in range(lay.param_base, n_fixed):
            loc[s] = s  # same index: rows UNIFORM_BASE.. hold params then constants
        row = n_fixed
        self.prefix_rows: list[tuple[int, int]] = []  # (instruction index, row)
        for k in range(n_prefix):
            loc[code[k][1]] = row
            self.prefix_rows.append((k, row))
            row += 1
        n_uniform_rows = row - UNIFORM_BASE
        reg_base = row
        lowered = []
        for op, dst, a, b in code[n_prefix:]:
            arity = OPS_BY_CODE[op].arity
            ra = loc[a]
            rb = loc[b] if arity == 2 else 0
            rd = reg_base + (dst - n_fixed)
            loc[dst] = rd
            lowered.append([op, rd, ra, rb, 0])
        self.code = np.array(lowered, dtype=np.int32).reshape(-1, 5)
        self.n_rows = reg_base + prog.n_regs
        self.n_uniform_rows = n_uniform_rows
        self.out_row = loc[prog.output]
        self.n_params = P
        self.n_consts = lay.n_consts
        self.layout = lay
        self.prog = prog
        # per prefix result: the parameters it depends on (structurally: none for an op
        # whose derivative is zero, as csdf.ops's kink conventions have it for floor,
        # step and sign, so that no tangent of it enters the kernel, where 0 times an
        # infinite factor would make NaN: d/da of sign(a) / floor(y) at floor(y) = 0);
        # and the prefix on local rows (parameters, constants, then one row per result)
        # for interp_kernels.prefix_kernel, where a parameter's tangent is not zero and
        # a constant's is
        deps: dict[int, set[int]] = {lay.param(i): {i} for i in range(P)}
        self._prefix_deps: dict[int, list[int]] = {}
        pre = np.zeros((n_prefix, 5), dtype=np.int32)
        for k, row in self.prefix_rows:
            op, _dst, a, b = code[k]
            src = [_src_row(code, k, a, n_fixed)]
            if OPS_BY_CODE[op].arity == 2:
                src.append(_src_row(code, k, b, n_fixed))
            deps[row] = (set() if OPS_BY_CODE[op].derivative.kind == "zero"
                         else set().union(*(deps.get(r, set()) for r in src)))
            self._prefix_deps[row] = sorted(deps[row])
            local = [r - UNIFORM_BASE for r in src] + [0]
            pre[k, :4] = (op, row - UNIFORM_BASE, local[0], local[1])
        zero = np.zeros(n_fixed - UNIFORM_BASE + n_prefix, dtype=bool)
        zero[P:n_fixed - UNIFORM_BASE] = True
        _flag_code(pre, zero, lambda r: P <= r < n_fixed - UNIFORM_BASE)
        self._prefix_code = pre

    def prefix_param_deps(self) -> dict[int, list[int]]:
        """``row -> sorted parameter indices`` for the prefix rows that depend on any."""
        return {r: d for r, d in self._prefix_deps.items() if d}

    def prefix_param_deps_key(self) -> bytes:
        return repr(sorted(self.prefix_param_deps().items())).encode()

    def uniform(self, pvals: np.ndarray, dtype, spatial: bool, wrt_params: bool):
        """Uniform row values ``(U,)`` and tangents ``(U, T)`` for this call (and the
        rows whose tangents are all zero). The last few answers are kept: a fit or a
        tracker calls with the same parameter values many times (copies are
        returned)."""
        key = (np.asarray(pvals, dtype=np.float64).tobytes(), np.dtype(dtype).str,
               bool(spatial), bool(wrt_params))
        hit = memo(self, "_uniform_cache", key,
                   lambda: self._uniform(pvals, dtype, spatial, wrt_params), 16)
        return hit[0].copy(), hit[1].copy(), hit[2].copy()

    def _uniform(self, pvals: np.ndarray, dtype, spatial: bool, wrt_params: bool):
        P = self.n_params
        uvals, drows = self.uniform_rows(pvals, wrt_params)
        T = (3 if spatial else 0) + (P if wrt_params else 0)
        utans = np.zeros((self.n_uniform_rows, max(T, 1)), dtype=np.float64)
        if wrt_params:
            off = 3 if spatial else 0
            utans[:, off:off + P] = drows
        zero = np.all(utans == 0, axis=1)
        with np.errstate(over="ignore"):  # values beyond float32 range become inf
            return uvals.astype(dtype), utans[:, :T].astype(dtype), zero

    def uniform_rows(self, pvals: np.ndarray, wrt_params: bool
                     ) -> tuple[np.ndarray, np.ndarray | None]:
        """The uniform rows' values ``(U,)`` float64 (the parameters, the constants,
        then the prefix's results) and, with ``wrt_params``, their derivatives by the
        parameters ``(U, P)`` (else None); new arrays, made afresh each call (the
        compiled evaluator asks for them at every step of a fit)."""
        P = self.n_params
        pv = np.asarray(pvals, dtype=np.float64).reshape(-1)
        vals, dparams = self.prefix(pv, wrt_params)
        # prefix result k is row k after the constants
        uvals = np.concatenate([pv, self.prog.consts, vals])
        if not wrt_params:
            return uvals, None
        drows = np.zeros((self.n_uniform_rows, P), dtype=np.float64)
        drows.reshape(-1)[:P * P:P + 1] = 1.0  # the parameters' own rows: the identity
        drows[P + self.n_consts:] = dparams
        return uvals, drows

    def prefix(self, pvals: np.ndarray, tangents: bool) -> tuple[np.ndarray, np.ndarray]:
        """Values ``(K,)`` and parameter derivatives ``(K, P)`` of the prefix
        instructions (as :func:`csdf.backends.numpy_backend.uniform_prefix`, computed by
        :func:`csdf.backends.interp_kernels.prefix_kernel`: the same rules, compiled;
        the derivatives are not computed, and left undefined, without ``tangents``)."""
        pv = np.asarray(pvals, dtype=np.float64).reshape(-1)
        uv = np.concatenate([pv, np.asarray(self.prog.consts, dtype=np.float64)])
        K = self.n_prefix
        vals = np.empty(K)
        tans = np.empty((K, self.n_params if tangents else 0))
        with np.errstate(all="ignore"):
            prefix_kernel(self._prefix_code, uv, self.n_params, bool(tangents), vals, tans)
        return vals, tans

    def is_const_row(self, row: int) -> bool:
        """True when ``row`` holds a constant of the program (rows of parameters and
        constants have their slot numbers)."""
        return self.layout.is_const(row)

    def flagged_code(self, zero_uniform: np.ndarray) -> np.ndarray:
        """Instructions with flag bits: :data:`FLAG_B_ZERO` = ``b``'s tangent is
        structurally zero, :data:`FLAG_A_ZERO` = ``a``'s, :data:`FLAG_OUT_ZERO` = the
        result's (as the reference treats it: no tangent, not ``0 * factor``; always for
        ops whose derivative rule is ``'zero'``), :data:`FLAG_TIE_STRICT` = a ``min``/``max``
        takes ``a``'s derivative only where ``a`` wins strictly (:func:`csdf.ops.tie_strict`
        of ``a`` being a constant)."""
        code = self.code.copy()
        if len(code) == 0:
            return code
        zero = np.zeros(self.n_rows, dtype=bool)
        zero[UNIFORM_BASE:UNIFORM_BASE + self.n_uniform_rows] = zero_uniform
        _flag_code(code, zero, self.is_const_row)
        return code

    def tangent_plan(self, utans: np.ndarray, zero_uniform: np.ndarray, off: int
                     ) -> tuple[np.ndarray, np.ndarray]:
        """The flagged instructions (:meth:`flagged_code` of ``zero_uniform``, the
        uniform rows whose tangents are all zero) and, per instruction, the parameter
        tangent columns it computes and those it clears, for the uniform rows'
        tangents ``utans`` ``(U, T)`` whose parameter columns start at ``off`` (3 after
        the spatial ones, else 0). Kept per pattern of zero tangents (a fit repeats
        it).

        A row's *support* is the hull ``[lo, hi)`` of the parameter columns where its
        tangent may be non-zero: a uniform row's non-zero columns; an instruction's the
        hull of its operands' that are not structurally zero (empty when its result's
        tangent is structurally zero). The kernel computes an instruction's tangents on
        its support only (and on the spatial columns ``[0, off)``, always), then
        clears the columns of the register's previous support outside it (its previous
        support: that of the register's previous write, or of its last one in the tape
        for the first write: the block before), so that every row is zero outside its
        support: a tree of many leaves carries each leaf's parameter tangents through
        that leaf's instructions alone. Within the support the arithmetic is the dense
        kernel's on the same operands, so the tangents are the same; outside it they
        are exact zeros (where the dense kernel could make ``0 * inf``).

        Returns:
            ``(code (K, 5), cols (K, 4))``: ``cols[k] = (lo, hi, clo, chi)``, the
            support ``[lo, hi)`` and previous support ``[clo, chi)`` of instruction
            ``k``'s destination, in tangent columns (``off`` added).
        """
        zero_uniform = np.asarray(zero_uniform, dtype=bool)
        nz = utans[:, off:] != 0
        any_nz = nz.any(axis=1)
        if nz.shape[1]:
            lo = np.where(any_nz, np.argmax(nz, axis=1), 0)
            hi = np.where(any_nz, nz.shape[1] - np.argmax(nz[:, ::-1], axis=1), 0)
        else:
            lo = hi = np.zeros(len(nz), dtype=np.int64)
        key = (zero_uniform.tobytes(), lo.astype(np.int64).tobytes(),
               hi.astype(np.int64).tobytes(), int(off))
        return memo(self, "_tangent_plans", key,
                    lambda: self._tangent_plan(zero_uniform, lo, hi, off), 16)

    def _tangent_plan(self, zero_uniform: np.ndarray, ulo: np.ndarray, uhi: np.ndarray,
                      off: int) -> tuple[np.ndarray, np.ndarray]:
        code = self.flagged_code(zero_uniform)
        K = len(code)
        cols = np.zeros((K, 4), dtype=np.int32)
        if K == 0:
            return code, cols
        sup_lo = np.zeros(self.n_rows, dtype=np.int64)
        sup_hi = np.zeros(self.n_rows, dtype=np.int64)
        U = len(ulo)
        sup_lo[UNIFORM_BASE:UNIFORM_BASE + U] = ulo
        sup_hi[UNIFORM_BASE:UNIFORM_BASE + U] = uhi
        last: dict[int, tuple[int, int]] = {}
        for k in range(K):
            op, d, a, b, flags = (int(v) for v in code[k])
            binary = OPS_BY_CODE[op].arity == 2
            spans = []
            if not flags & FLAG_OUT_ZERO:
                if not flags & FLAG_A_ZERO:
                    spans.append((sup_lo[a], sup_hi[a]))
                if binary and not flags & FLAG_B_ZERO:
                    spans.append((sup_lo[b], sup_hi[b]))
            spans = [(s, e) for s, e in spans if s < e]
            if spans:
                lo, hi = min(s for s, _ in spans), max(e for _, e in spans)
            else:
                lo = hi = 0
            cols[k, 0], cols[k, 1] = lo + off, hi + off
            cols[k, 2], cols[k, 3] = sup_lo[d] + off, sup_hi[d] + off
            sup_lo[d], sup_hi[d] = lo, hi
            last[d] = (lo, hi)
        # a register's first write follows its last one of the block before
        first: set[int] = set()
        for k in range(K):
            d = int(code[k, 1])
            if d in first:
                continue
            first.add(d)
            s, e = last[d]
            cols[k, 2], cols[k, 3] = s + off, e + off
        return code, cols


def _flag_code(code: np.ndarray, zero: np.ndarray, is_const) -> None:
    """Set the flag column of the instructions ``code`` ``(K, 5)`` in place (see
    :meth:`Lowered.flagged_code`), from ``zero`` (per row: its tangent is structurally
    zero; updated as the instructions write) and ``is_const(row)``."""
    for k in range(len(code)):
        op, d, a, b, _ = code[k]
        info = OPS_BY_CODE[int(op)]
        binary = info.arity == 2
        za = bool(zero[a])
        zb = bool(zero[b]) if binary else True
        zd = (za and zb) or info.derivative.kind == "zero"
        code[k, 4] = ((FLAG_B_ZERO if (binary and zb) else 0) | (FLAG_A_ZERO if za else 0)
                      | (FLAG_OUT_ZERO if zd else 0)
                      | (FLAG_TIE_STRICT if tie_strict(is_const(int(a))) else 0))
        zero[d] = zd


def _src_row(code, k: int, slot: int, n_fixed: int) -> int:
    """Row holding ``slot`` as read by prefix instruction ``k`` (prefix rows are numbered
    from ``n_fixed`` in instruction order)."""
    if slot < n_fixed:
        return slot
    for j in range(k - 1, -1, -1):
        if code[j][1] == slot:
            return n_fixed + j
    return -1


def lowered(prog) -> Lowered:
    """The (cached) lowering of a program."""
    low = prog.__dict__.get("_lowered")
    if low is None:
        if prog.data:
            from . import check_mesh_calls

            check_mesh_calls("interp", prog)
        low = Lowered(prog)
        prog.__dict__["_lowered"] = low
    return low
