"""Conservative interval evaluation of compiled programs over many boxes at once.

:func:`evaluate_intervals` runs the tape of a :class:`csdf.Program` once over ``M``
axis-aligned boxes, with every slot holding an interval ``[lo, hi]`` per box (two
``(M,)`` float64 arrays, processed in chunks of :data:`CHUNK` boxes like the reference
evaluator in ``numpy_backend``). The result bounds the distance at every point of each
box, for every parameter value in its interval. Meshing relies on it to skip empty
space: ``out_lo > 0`` means the whole box is outside, ``out_hi < 0`` inside.

The interval rules of the ops, what they bound (the float64 values of the reference
evaluator, library functions widened by 16 ulps) and the NaN convention (an interval
bounds the non-NaN values of its slot; ``(nan, nan)`` is empty) are those of
:mod:`csdf.interval`, the one interval arithmetic of csdf. By default an empty *output*
is reported as ``(-inf, inf)`` ("nothing known"); pass ``empty_as_nan=True`` to get
``(nan, nan)``. A box with a NaN bound, or a NaN parameter value, is empty (the
evaluator gives NaN there too).

Shortening a program for one box by the same intervals is
:func:`csdf.compiler.simplify.simplify`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from ..interval import check_boxes, init_slots, param_bounds, run_tape, tape_steps
from ..layout import N_COORDS
from ..ops import OPS_BY_CODE

__all__ = ["evaluate_intervals", "CHUNK", "mesh_rule"]

#: boxes per chunk (bounds memory: about ``2 * n_slots`` arrays of this length)
CHUNK = 1 << 15

_OP_NAMES = {code: info.name for code, info in OPS_BY_CODE.items()}


def evaluate_intervals(
    prog,
    lo: Any,
    hi: Any,
    params: Mapping[str, float] | None = None,
    param_intervals: Mapping[str, tuple[float, float]] | None = None,
    *,
    empty_as_nan: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """Bounds of a program's value over many axis-aligned boxes.

    Args:
        prog: the :class:`csdf.Program`.
        lo, hi: ``(M, 3)`` box corners (``(M, 2)`` also accepted for 2D programs), any
            real dtype; ``lo <= hi`` elementwise; infinite bounds are allowed.
        params: ``{name: value}`` parameter values (others take their defaults); each
            is a point interval.
        param_intervals: ``{name: (lo, hi)}``: these parameters range over ``[lo, hi]``.
        empty_as_nan: report a box where the value is NaN everywhere as ``(nan, nan)``
            instead of ``(-inf, inf)`` (see the module docs).

    Returns:
        ``(out_lo, out_hi)``, two ``(M,)`` float64 arrays with
        ``out_lo <= f(p) <= out_hi`` for every point ``p`` of each box and every
        parameter value in its interval at which ``f(p)`` is not NaN.

    Raises:
        CsdfError: badly shaped boxes or ``lo > hi``.
        ParamError: an unknown parameter name (the message lists the known ones), a
            non-numeric value, a bad interval, or a name given both ways.
    """
    blo, bhi = check_boxes(prog.dim, lo, hi)
    plo, phi = param_bounds(prog, params, param_intervals)
    steps = tape_steps(prog.code, _OP_NAMES, mesh_rule(prog) if prog.data else None)
    m_all = blo.shape[0]
    out_lo = np.empty(m_all)
    out_hi = np.empty(m_all)
    slots_lo, slots_hi = init_slots(prog.layout, prog.consts, plo, phi)
    for start in range(0, m_all, CHUNK):
        stop = min(m_all, start + CHUNK)
        sl, sh = list(slots_lo), list(slots_hi)
        for k in range(N_COORDS):
            sl[k] = np.ascontiguousarray(blo[start:stop, k])
            sh[k] = np.ascontiguousarray(bhi[start:stop, k])
        run_tape(steps, sl, sh)
        out_lo[start:stop] = sl[prog.output]
        out_hi[start:stop] = sh[prog.output]
    bad = np.isnan(blo).any(axis=1) | np.isnan(bhi).any(axis=1)
    if np.isnan(plo).any():
        bad[:] = True
    out_lo[bad] = math.nan
    out_hi[bad] = math.nan
    if not empty_as_nan:
        empty = np.isnan(out_lo)
        out_lo[empty] = -math.inf
        out_hi[empty] = math.inf
    return out_lo, out_hi


def mesh_rule(prog):
    """The interval rule of ``prog``'s mesh calls (for :func:`csdf.interval.tape_steps`):
    :meth:`csdf.backends.meshdist.MeshDistance.intervals` over the box of its three
    operands."""
    from .meshdist import for_data

    def rule(block, alo, ahi, blo, bhi, clo, chi):
        lo3 = np.stack(np.broadcast_arrays(alo, blo, clo), axis=1)
        hi3 = np.stack(np.broadcast_arrays(ahi, bhi, chi), axis=1)
        return for_data(prog.data[block]).intervals(lo3, hi3)

    return rule
