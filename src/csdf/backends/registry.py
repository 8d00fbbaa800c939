"""The evaluator interface and the registry of csdf's evaluators.

An *evaluator* computes a compiled program's values (and derivatives) on points. Every
point evaluator is a module (or object) with the :class:`PointEvaluator` interface;
the interval evaluator has :class:`IntervalEvaluator`'s; the GLSL export generates code
that runs elsewhere (a GPU). :data:`EVALUATORS` states, for each, what it computes
(values, gradients, parameter Jacobians, intervals), in which dtypes, whether it can
run on this machine (:meth:`EvaluatorInfo.available`) and what it is.
:func:`csdf.backends.select` and :data:`csdf.backends.BACKENDS` are built on it, and
the conformance suite (``tests/test_conformance.py``) and the per-op suite
(``tests/test_ops.py``) run over it, skipping what is unavailable.

How to add an evaluator (a GPU one, say)
    1. Write one module in ``src/csdf/backends/`` with ``available() -> bool`` (cheap:
       no compilation; False where its hardware or library is missing) and
       ``evaluate(prog, pts, pvals, mode)`` with the contract of
       :func:`csdf.backends.numpy_backend.evaluate`. Read the program as data only
       (``prog.code``, ``prog.consts``, ``prog.params``, ``prog.output``,
       ``prog.layout``): a backend never imports :mod:`csdf.compiler`. Follow the op
       specification :mod:`csdf.ops` (values, derivative rules with their kink
       conventions, the ``min``/``max`` tie rule), generating code from its formulas
       as :mod:`csdf.backends.codegen` and :mod:`csdf.backends.glsl` do.
    2. Add one :class:`EvaluatorInfo` to :data:`EVALUATORS` below, with its honest
       capabilities. Its name becomes a backend name (``backend='<name>'``, listed in
       ``BACKENDS``); ``'auto'`` does not pick it until the two policies are taught
       to: ``csdf.field.choose_backend`` (per job) and :func:`csdf.backends.select`
       (per call).
    3. Run ``tests/test_conformance.py`` and ``tests/test_ops.py``: both parametrise
       over this registry, so the new evaluator is checked against the NumPy reference
       and the op specification (kinks, ties, NaN, infinities) with no test edits.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from types import ModuleType
from typing import Any, Protocol, runtime_checkable

import numpy as np

__all__ = ["PointEvaluator", "IntervalEvaluator", "EvaluatorInfo", "EVALUATORS", "get",
           "point_evaluators", "MODES"]

#: evaluation modes of :meth:`PointEvaluator.evaluate` and the keys each returns
MODES: dict[str, tuple[str, ...]] = {
    "value": ("value",), "grad": ("value", "grad"), "jac": ("value", "jac"),
    "all": ("value", "grad", "jac"),
}


@runtime_checkable
class PointEvaluator(Protocol):
    """What a point evaluator provides (a module satisfies it by its functions)."""

    def available(self) -> bool:
        """True when it can run on this machine (cheap; compiles nothing)."""
        ...

    def evaluate(self, prog: Any, pts: np.ndarray, pvals: np.ndarray,
                 mode: str) -> dict[str, np.ndarray]:
        """Values and derivatives of ``prog`` at points.

        Args:
            prog: the :class:`csdf.Program` (read as data).
            pts: ``(N, D)`` float32 or float64 points, D = 2 or 3, C-contiguous.
            pvals: ``(P,)`` float64 parameter values (:meth:`Program.param_values`).
            mode: ``'value' | 'grad' | 'jac' | 'all'``.

        Returns:
            ``{'value': (N,), 'grad': (N, 3), 'jac': (N, P)}``, the keys of
            :data:`MODES` ``[mode]``, in the points' dtype; NaN (values and
            derivatives) at points with a NaN coordinate, everywhere when a parameter
            is NaN, and derivatives NaN wherever the value is.
        """
        ...


@runtime_checkable
class IntervalEvaluator(Protocol):
    """What an interval evaluator provides (:mod:`csdf.backends.interval_eval`)."""

    def evaluate_intervals(self, prog: Any, lo: Any, hi: Any, params: Any = None,
                           param_intervals: Any = None, *,
                           empty_as_nan: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """``(out_lo, out_hi)`` ``(M,)`` float64 bounding the program's non-NaN values
        over each box ``[lo[i], hi[i]]`` (``(M, 3)``)."""
        ...


@dataclass(frozen=True)
class EvaluatorInfo:
    """One registered evaluator and what it can do.

    Attributes:
        name: the backend name (``backend='<name>'`` for point evaluators).
        module: the module holding it, relative to :mod:`csdf.backends`.
        kind: ``'points'`` (:class:`PointEvaluator`, a backend of ``Program.__call__``),
            ``'intervals'`` (:class:`IntervalEvaluator`) or ``'source'`` (generates
            code that runs outside Python: no in-process evaluation).
        description: what it is, in a line.
        values, gradients, param_jacobians, intervals: what it computes.
        dtypes: the point dtypes it evaluates in (``'float32'``, ``'float64'``).
        needs: what it needs beyond NumPy, for messages (``'Numba'``), or ``''``.
        mesh_calls: whether it runs programs with mesh calls (``csdf.from_mesh``:
            a data block per mesh, see ``docs/bytecode.md``).
    """

    name: str
    module: str
    kind: str
    description: str
    values: bool = True
    gradients: bool = True
    param_jacobians: bool = True
    intervals: bool = False
    dtypes: tuple[str, ...] = ("float32", "float64")
    needs: str = ""
    mesh_calls: bool = False

    def load(self) -> ModuleType:
        """The evaluator's module (imported on first use, then kept: every evaluation
        call asks for it)."""
        mod = _LOADED.get(self.module)
        if mod is None:
            mod = _LOADED[self.module] = importlib.import_module(
                f"{__package__}.{self.module}")
        return mod

    def available(self) -> bool:
        """True when it can run on this machine (its module's ``available()``, where it
        has one; compiles nothing). Asked once per process: what a machine can import
        does not change while it runs."""
        ok = _AVAILABLE.get(self.module)
        if ok is None:
            check = getattr(self.load(), "available", None)
            ok = _AVAILABLE[self.module] = bool(check()) if callable(check) else True
        return ok


#: evaluator modules already imported, and whether each can run (by module name)
_LOADED: dict[str, ModuleType] = {}
_AVAILABLE: dict[str, bool] = {}


#: every evaluator, the reference first (the order of ``BACKENDS``)
EVALUATORS: tuple[EvaluatorInfo, ...] = (
    EvaluatorInfo(
        "numpy", "numpy_backend", "points",
        "the reference: one NumPy array operation per instruction over chunks of points",
        mesh_calls=True),
    EvaluatorInfo(
        "interp", "interp", "points",
        "Numba kernels interpreting the tape over blocks of points, on all cores; "
        "compiled once for all programs", needs="Numba"),
    EvaluatorInfo(
        "fast", "fast", "points",
        "a Numba kernel generated per program structure, vectorised across points, on "
        "all cores; compiled on first use and cached on disk", needs="Numba"),
    EvaluatorInfo(
        "interval", "interval_eval", "intervals",
        "interval arithmetic over boxes: bounds of the values over each box (pruning, "
        "bounds, tape simplification)",
        values=False, gradients=False, param_jacobians=False, intervals=True,
        dtypes=("float64",), mesh_calls=True),
    EvaluatorInfo(
        "glsl", "glsl", "source",
        "GLSL ES 3.00 / 3.30 source of the value and its gradient (float32 on a GPU; "
        "no parameter Jacobian)",
        param_jacobians=False, dtypes=("float32",)),
)

_BY_NAME = {e.name: e for e in EVALUATORS}


def get(name: str) -> EvaluatorInfo:
    """The registered evaluator ``name`` (KeyError if there is none)."""
    return _BY_NAME[name]


def point_evaluators() -> tuple[EvaluatorInfo, ...]:
    """The evaluators of kind ``'points'`` (the backends of ``Program.__call__``)."""
    return tuple(e for e in EVALUATORS if e.kind == "points")
