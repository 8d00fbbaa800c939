"""The compiled program (tape) and its evaluation entry points.

A :class:`Program` is immutable data: the parameter table, the constant pool, the
instructions (``opcode, dst, a, b`` over one slot file) and metadata. Parameter values
are given at evaluation time, so changing them never recompiles.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..errors import BytecodeError, CsdfError, ParamError
from ..expr import Param, describe_number
from ..layout import SlotLayout
from ..ops import ARG_CODE, CATEGORIES, MESH_CODE, OPS_BY_CODE
from .binary import decode_fields, encode, validate
from .calls import INSTR_REF, Call
from .text import assemble_fields, disassemble

__all__ = ["Program", "Call", "as_program", "INSTR_REF", "RANGE_HINT", "range_message"]

#: how the range error of :meth:`Program.param_values` says the check can be skipped
RANGE_HINT = "pass check_ranges=False to evaluate it anyway"


def range_message(p: Param, value: float, hint: str = RANGE_HINT) -> str:
    """The message for a value given to parameter ``p`` outside its declared range, e.g.
    ``"parameter 'board' = 0.5 is outside its range [0.012, 0.03]; pass
    check_ranges=False to evaluate it anyway"`` (``hint`` appended when not empty)."""
    lo = "-inf" if math.isinf(p.lo) else f"{p.lo:g}"
    hi = "inf" if math.isinf(p.hi) else f"{p.hi:g}"
    msg = f"parameter {p.name!r} = {value:g} is outside its range [{lo}, {hi}]"
    return f"{msg}; {hint}" if hint else msg


def as_program(shape, what: str):
    """``(Program, Shape or None)`` for a :class:`csdf.Shape` (compiled; cached on the
    shape) or a :class:`Program` (returned as is, with no shape).

    A shape is anything with a ``compile()`` method that returns a :class:`Program`
    (the compiler does not import the shapes layer).

    Raises:
        CsdfError: anything else, as ``"{what} expects a Shape or Program, got T"``.
    """
    if isinstance(shape, Program):
        return shape, None
    compile_ = getattr(shape, "compile", None)
    if callable(compile_) and not isinstance(shape, type):
        prog = compile_()
        if isinstance(prog, Program):
            return prog, shape
    raise CsdfError(f"{what} expects a Shape or Program, got {type(shape).__name__}")


class Program:
    """A compiled signed distance function: a linear register tape.

    Slot file: ``0..2`` = x, y, z; then one slot per parameter (``params`` order, sorted
    by name); then the constants; then ``n_regs`` registers. Instruction ``k`` is
    ``code[k] = (opcode, dst, a, b)`` computing ``slot[dst] = op(slot[a], slot[b])``
    (``b`` is 0 and unused for unary ops). See ``docs/bytecode.md``.

    Attributes:
        params: the parameters (``.name``, ``.default``, ``.lo``, ``.hi``).
        consts: ``(C,)`` float64 constant pool.
        code: ``(K, 4)`` int64 instructions.
        output: slot holding the distance after the last instruction.
        n_regs: number of registers.
        dim: 3, or 2 for planar shapes.
        exactness: ``'exact' | 'bound' | 'neither'``; lipschitz: gradient-norm bound.
        calls: primitive invocations (:class:`Call`).
        bounds: ``(2, dim)`` float64 ``[lo, hi]`` box (model units) containing the zero
            set, read-only, or None when unbounded or unknown (a shape's
            :attr:`~csdf.Shape.bounds`, kept in the bytecode since format version 2).
        data: the data blocks of the program's mesh calls
            (:class:`csdf.meshdata.MeshData`; format version 3), empty for most.
        colors: ``(program, palette)`` of the shape's colours, or ``(programs, None)``
            with five channel programs for colours that vary continuously
            (:mod:`csdf.colors`:
            a program whose value is the index of the winning row of ``palette``
            ``(K, 4)`` RGBA, NaN rows for uncoloured parts; format version 3), or None.
            Evaluating the distance never runs it.

    With its metadata (exactness, Lipschitz bound, bounds) a program alone is enough
    for every consumer; :meth:`to_bytes` and :meth:`disassemble` keep all of it, and two
    programs are equal when their bytecode is.
    """

    def __init__(
        self,
        *,
        params: tuple[Param, ...],
        consts: np.ndarray,
        code: np.ndarray,
        output: int,
        n_regs: int,
        dim: int = 3,
        exactness: str = "neither",
        lipschitz: float = math.inf,
        calls: tuple[Call, ...] = (),
        bounds: np.ndarray | None = None,
        data: tuple = (),
        colors: tuple | None = None,
    ):
        self.params = tuple(params)
        self.data = tuple(data)
        self.colors = colors
        self.consts = np.asarray(consts, dtype=np.float64)
        self.code = np.asarray(code, dtype=np.int64).reshape(-1, 4)
        self.output = int(output)
        self.n_regs = int(n_regs)
        self.dim = int(dim)
        self.exactness = exactness
        self.lipschitz = float(lipschitz)
        self.calls = tuple(calls)
        if bounds is None:
            self.bounds: np.ndarray | None = None
        else:
            box = np.array(bounds, dtype=np.float64)
            if box.shape != (2, self.dim):
                raise ValueError(
                    f"bounds must have shape (2, {self.dim}) for a {self.dim}D program; "
                    f"got {box.shape}"
                )
            box.setflags(write=False)
            self.bounds = box
        self._param_index = {p.name: i for i, p in enumerate(self.params)}
        self._param_order = tuple(p.name for p in self.params)
        self._defaults = np.array([p.default for p in self.params], dtype=np.float64)
        self._defaults.setflags(write=False)
        self.consts.setflags(write=False)
        self.code.setflags(write=False)

    # ------------------------------------------------------------------ layout
    @property
    def layout(self) -> SlotLayout:
        """The slot numbering of this program (:class:`csdf.layout.SlotLayout`)."""
        return SlotLayout(len(self.params), len(self.consts), self.n_regs)

    @property
    def n_fixed(self) -> int:
        """Number of preloaded slots (x, y, z, parameters, constants)."""
        return self.layout.n_fixed

    @property
    def n_slots(self) -> int:
        return self.layout.n_slots

    def __len__(self) -> int:
        return len(self.code)

    def operands(self, k: int) -> tuple[int, ...]:
        """The slots instruction ``k`` reads: ``(a,)``, ``(a, b)``, ``(a, b, c)`` for a
        mesh call (its second row, ``ARG_CODE``, reads none of its own)."""
        op, _, a, b = (int(v) for v in self.code[k])
        if op == MESH_CODE:
            return (a, b, int(self.code[k + 1, 2]))
        if op == ARG_CODE:
            return ()
        return (a, b) if OPS_BY_CODE[op].arity == 2 else (a,)

    @property
    def param_names(self) -> list[str]:
        return [p.name for p in self.params]

    def __repr__(self) -> str:
        return (
            f"<Program {len(self.code)} instructions, {len(self.params)} params, "
            f"{len(self.consts)} constants, {self.n_regs} registers, {self.exactness}>"
        )

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Program):
            return NotImplemented
        return self.to_bytes() == other.to_bytes()

    def __hash__(self) -> int:
        return hash(self.to_bytes())

    def with_bounds(self, bounds: np.ndarray | None) -> Program:
        """The same program with other bounds: a ``(2, dim)`` ``[lo, hi]`` box of the
        zero set in model units, or None (e.g. to give a program read from a version-1
        file, which has none, its box)."""
        return Program(
            params=self.params, consts=self.consts, code=self.code, output=self.output,
            n_regs=self.n_regs, dim=self.dim, exactness=self.exactness,
            lipschitz=self.lipschitz, calls=self.calls, bounds=bounds, data=self.data,
            colors=self.colors,
        )

    # ------------------------------------------------------------------ parameters
    def param_values(self, params: dict | None = None, *, check_ranges: bool = True,
                     range_hint: str = RANGE_HINT, **kw: Any) -> np.ndarray:
        """Parameter vector ``(P,)`` float64 from defaults overridden by ``params``/``kw``.

        This is the one place where parameter values are resolved: every evaluation
        method, :class:`csdf.field.Field` and the consumers come through it.

        Args:
            params: ``{name: value}``; keyword arguments work too.
            check_ranges: refuse a given value outside its parameter's declared range
                ``[lo, hi]`` (an infinite end is unbounded). NaN is not refused (NaN
                in, NaN out). Defaults always lie inside their ranges.
            range_hint: the end of that error's message (what to do about it; the
                command line names its own flag); ``''`` for none.

        Raises:
            ParamError: an unknown name (the message lists the known ones), a value
                that is not a real number, one too large for float64 (``10**400``),
                or, with ``check_ranges``, one outside its range (the message names
                the parameter, the value and the range).
        """
        if (not check_ranges and not kw and type(params) is dict
                and tuple(params) == self._param_order
                and all(type(v) is float or type(v) is np.float64 for v in params.values())):
            # every value given, in order, as floats (a solver's state): what the loop
            # below gives, without its per-name checks
            return np.fromiter(params.values(), dtype=np.float64, count=len(params))
        if not params and not kw:  # the defaults (a field at them asks on every call)
            return self._defaults.copy()
        vals = np.array([p.default for p in self.params], dtype=np.float64)
        given = dict(params or {})
        overlap = set(given) & set(kw)
        if overlap:
            raise ParamError(f"parameter(s) {sorted(overlap)} given twice")
        given.update(kw)
        for name, v in given.items():
            i = self._param_index.get(name)
            if i is None:
                known = ", ".join(self.param_names) or "none"
                raise ParamError(f"unknown parameter {name!r}; this shape's parameters: {known}")
            if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
                if not (isinstance(v, np.ndarray) and v.shape == ()):
                    raise ParamError(
                        f"parameter {name!r} must be a real number, got {type(v).__name__}"
                    )
            try:
                vals[i] = float(v)
            except OverflowError:
                raise ParamError(
                    f"parameter {name!r} = {describe_number(v)} is too large for a float64 "
                    "number (at most about 1.8e308)"
                ) from None
            except (TypeError, ValueError):
                raise ParamError(
                    f"parameter {name!r} must be a real number, got {type(v).__name__}"
                ) from None
            if check_ranges:
                p = self.params[i]
                x = vals[i]
                if x < p.lo or x > p.hi:  # (False for NaN: NaN in, NaN out)
                    raise ParamError(range_message(p, float(x), range_hint))
        return vals

    # ------------------------------------------------------------------ evaluation
    def _run(self, points, params, kw, mode: str, backend: str, check_ranges: bool = True):
        select, as_points = _evaluation_helpers()
        pts, batch, dtype = as_points(points, self.dim)
        pv = self.param_values(params, check_ranges=check_ranges, **kw)
        impl = select(backend, pts.shape[0], self, mode)
        return impl.evaluate(self, pts, pv, mode), batch, pts.shape[1]

    def __call__(
        self, points, params: dict | None = None, *, backend: str = "auto",
        check_ranges: bool = True, **kw: Any
    ) -> np.ndarray:
        """Signed distances.

        Args:
            points: ``(N, 3)`` (or any ``(..., 3)``) float32/float64 array in model units;
                2D programs also take ``(..., 2)``. Integers are converted to float64.
            params: optional ``{name: value}``; keyword arguments work too.
            backend: ``'auto' | 'numpy' | 'interp' | 'fast'`` (see :mod:`csdf.backends`);
                every evaluation method takes it.
            check_ranges: refuse a parameter value outside its declared range
                (:class:`csdf.ParamError` naming the range); False evaluates it anyway
                (the shape's distance contract and bounds are then not promised).
                Every evaluation method takes it.

        Returns:
            ``(N,)`` (or ``(...)``) distances in the points' dtype. A point with a NaN
            coordinate gives NaN (NaN in, NaN out), as does a NaN parameter value.
        """
        res, batch, _ = self._run(points, params, kw, "value", backend, check_ranges)
        return res["value"].reshape(batch)

    def gradient(
        self, points, params: dict | None = None, *, backend: str = "auto",
        check_ranges: bool = True, **kw: Any
    ) -> np.ndarray:
        """Exact spatial gradient ``(..., D)`` (D = the points' last dimension), by
        forward-mode differentiation of the tape. Where the function is not
        differentiable (a kink of ``min``/``abs``) one of the one-sided gradients is
        returned; ``sqrt`` at 0 gets derivative 0."""
        res, batch, d = self._run(points, params, kw, "grad", backend, check_ranges)
        return res["grad"][:, :d].reshape(*batch, d)

    def value_and_grad(
        self, points, params: dict | None = None, *, backend: str = "auto",
        check_ranges: bool = True, **kw: Any
    ):
        """``(values (...), gradients (..., D))`` in one pass."""
        res, batch, d = self._run(points, params, kw, "grad", backend, check_ranges)
        return res["value"].reshape(batch), res["grad"][:, :d].reshape(*batch, d)

    def param_jacobian(
        self, points, params: dict | None = None, *, backend: str = "auto",
        check_ranges: bool = True, **kw: Any
    ) -> np.ndarray:
        """Exact derivatives of the distance by each parameter, ``(..., P)``, columns in
        :attr:`params` order."""
        res, batch, _ = self._run(points, params, kw, "jac", backend, check_ranges)
        return res["jac"].reshape(*batch, len(self.params))

    def value_grad_param_jacobian(
        self, points, params: dict | None = None, *, backend: str = "auto",
        check_ranges: bool = True, **kw: Any
    ):
        """``(values (...), gradients (..., D), param Jacobian (..., P))`` in one pass."""
        res, batch, d = self._run(points, params, kw, "all", backend, check_ranges)
        return (
            res["value"].reshape(batch),
            res["grad"][:, :d].reshape(*batch, d),
            res["jac"].reshape(*batch, len(self.params)),
        )

    def contains(
        self, points, params: dict | None = None, *, backend: str = "auto",
        check_ranges: bool = True, **kw: Any
    ) -> np.ndarray:
        """Boolean ``(...)``: True where the distance is ``<= 0`` (NaN gives False)."""
        v = self(points, params, backend=backend, check_ranges=check_ranges, **kw)
        with np.errstate(invalid="ignore"):
            return v <= 0

    # ------------------------------------------------------------------ counts
    def counts(self, level: str = "expanded") -> dict[str, int]:
        """The paper's Table-1 instruction counts.

        Args:
            level: ``'expanded'`` counts every scalar instruction of the tape by category
                (see :mod:`csdf.ops`); ``'primitive'`` counts each primitive invocation as
                one ``call`` and only the instructions outside primitives by category.

        Returns:
            ``{'add': .., 'mul': .., 'div': .., 'call': .., 'branch': ..}``.
        """
        if level not in ("expanded", "primitive"):
            raise CsdfError(f"level must be 'expanded' or 'primitive', got {level!r}")
        out = dict.fromkeys(CATEGORIES, 0)
        inside = self._primitive_bodies() if level == "primitive" else set()
        for k, row in enumerate(self.code):
            op = int(row[0])
            if k in inside or op == ARG_CODE:
                continue
            out["call" if op == MESH_CODE else OPS_BY_CODE[op].category] += 1
        if level == "primitive":
            out["call"] += len(self.calls)
        return out

    def _primitive_bodies(self) -> set[int]:
        """Instruction indices computed inside primitive calls."""
        writer: list[tuple[int, ...]] = []  # per instruction: producers of its operands
        last: dict[int, int] = {}
        rows = self.code.tolist()
        for k, (op, dst, _a, _b) in enumerate(rows):
            if op == ARG_CODE:
                writer.append(())
                continue
            writer.append(tuple(last.get(s, -1) for s in self.operands(k)))
            last[dst] = k
        inside: set[int] = set()
        for call in self.calls:
            stop = {s & ~INSTR_REF for s in call.inputs if s & INSTR_REF}
            stack = [call.out]
            while stack:
                k = stack.pop()
                if k < 0 or k in inside or k in stop:
                    continue
                inside.add(k)
                stack.extend(writer[k])
        return inside

    # ------------------------------------------------------------------ serialisation
    def to_bytes(self) -> bytes:
        """The binary bytecode (versioned, fixed-width instructions; docs/bytecode.md)."""
        return encode(self)

    @classmethod
    def from_bytes(cls, data: bytes) -> Program:
        """Decode and validate bytecode (format version 1 or 2; a version-1 program has
        no bounds). Raises :class:`csdf.BytecodeError` on any flaw; a program it returns
        is safe to evaluate."""
        fields = decode_fields(data)
        _colour_programs(cls, fields)
        prog = cls(**fields)
        validate(prog)
        return prog

    def disassemble(self) -> str:
        """A readable text listing that :meth:`from_text` loads back to the same program."""
        return disassemble(self)

    @classmethod
    def from_text(cls, text: str) -> Program:
        """Assemble a listing made by :meth:`disassemble`; runs the same validation as
        :meth:`from_bytes` (raises BytecodeError naming the line)."""
        fields = assemble_fields(text)
        try:
            _colour_programs(cls, fields)
            prog = cls(**fields)
        except (ValueError, OverflowError) as exc:
            raise BytecodeError(f"invalid program: {exc}") from None
        validate(prog)
        return prog

    @property
    def nbytes(self) -> int:
        """Size of :meth:`to_bytes` in bytes (the expanded tape)."""
        return len(self.to_bytes())

    def compact_nbytes(self) -> int:
        """Size of the call-level form, in bytes: the same layout as :meth:`to_bytes`, but
        each primitive is one 8-byte ``call`` instruction (its body is the library's, not
        the model's) and the call table is not needed; constants used only inside
        primitive bodies are dropped; the bounds section is not counted either. This
        is what the paper's "about 100 bytes" counts.
        """
        inside = self._primitive_bodies()
        n_instr = len(self.code) - len(inside) + len(self.calls)
        used: set[int] = set()
        layout = self.layout
        for k in range(len(self.code)):
            if k in inside:
                continue
            used.update(self.operands(k))
        for c in self.calls:
            used.update(s for s in c.inputs if not s & INSTR_REF)
        n_consts = sum(1 for s in used if layout.is_const(s))
        params = sum(1 + len(p.name.encode()) + 24 for p in self.params)
        data = sum(13 + d.nbytes for d in self.data) + (4 if self.data else 0)
        return 32 + params + 8 * n_consts + 8 * n_instr + 4 + data


def _colour_programs(cls: type, fields: dict) -> None:
    """Turn the colour section's program fields (one program, or the channel programs)
    into programs, in place."""
    if fields.get("colors") is None:
        return
    inner, palette = fields["colors"]
    if palette is None:
        fields["colors"] = (tuple(cls(**f) for f in inner), None)
    else:
        fields["colors"] = (cls(**inner), palette)


_HELPERS: tuple = ()


def _evaluation_helpers() -> tuple:
    """``(csdf.backends.select, csdf.points.as_points)``, imported on the first
    evaluation (the backends import this module's package lazily too) and kept: an
    import statement in :meth:`Program._run` cost a few microseconds on every call, and
    a fit makes thousands of small calls."""
    global _HELPERS
    if not _HELPERS:
        from ..backends import select
        from ..points import as_points

        _HELPERS = (select, as_points)
    return _HELPERS
