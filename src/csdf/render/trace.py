"""Sphere tracing of compiled signed distance programs, vectorised over rays.

The tracer marches every still-active ray at once: each iteration evaluates the field
once, on the active rays only, with the fast (Numba) backend, then drops the rays that
finished. Rays start where they enter the shape's bounding box and stop where they leave.

Steps (per ray, ``f`` the field at the current point, ``L`` the program's Lipschitz
bound, ``r = f / L`` a radius that holds no surface):

* **Over-relaxation** (Keinert et al. 2014, *Enhanced Sphere Tracing*): step ``omega * r``
  with ``omega = 1.6``; the step is kept when the unbounding spheres of its two ends
  overlap (``r_old + |r_new| >= step``: the segment between them is covered, so nothing
  was skipped), otherwise the ray goes back to the last safe point, steps by ``r_old``
  and continues with ``omega = 1``. On the benchmark scenes (rays mostly meet faces
  head-on) this is about neutral: +2.5 % field evaluations against ``omega = 1``
  (``benchmarks/RENDER_RESULTS.md``); it pays off for rays running along surfaces.
* **Hits** are sign changes: once ``r < eps`` (``eps = 1e-4`` of the bounding box
  diagonal) the ray steps by ``eps`` until ``f <= 0`` (a crossing, then refined) or
  ``f`` grows again (the ray grazed the surface and goes on, so silhouettes are not
  dilated). A crossing ``[t_a, t_b]`` with ``f(t_a) > 0 >= f(t_b)`` is refined by the
  Illinois variant of regula falsi to ``1e-9`` of the scene size, so depths are as precise
  as the field itself. The first crossing along a ray is found, except where the ray
  is inside the solid for less than ``eps`` (it grazes an edge or corner, or crosses a
  sheet thinner than ``eps``): such a sliver may be stepped over.
* **Unknown Lipschitz bound** (``L = inf``): each step ``s = max(f, eps)`` is certified
  with interval arithmetic (:func:`csdf.backends.interval_eval.evaluate_intervals`) over
  the axis-aligned box of the segment, and quartered until the interval is positive
  (at most 4 times; an uncertified step is then taken anyway, and a crossing it makes is
  still found by the sign test). No over-relaxation.
* After ``max_iter`` iterations a ray that is within ``16 eps`` of the surface counts as
  a hit there, any other as a miss.

* **Empty space** (fields evaluated with tapes pruned per spatial cell, see
  :meth:`csdf.field.Field.empty_cells`): where a sample lies in a cell whose interval
  proves the field positive, the ray steps to where the run of such cells ends along
  it (a 3D DDA over the cells) when that is further than its sphere step. Only cells
  already built are known (they are kept between calls), so the first image of a
  program skips less than the next.

A ray whose first sample is already inside (``f <= 0``; a camera inside the solid)
reports a hit at its start. NaN values end a ray as a miss.

Normals are the exact gradient (forward-mode, ``prog.value_and_grad``) normalised,
evaluated ``1e-7`` of the scene size before the hit along the ray: exactly on the
surface, formulas whose kinks meet there (the exact box, ``|max(q, 0)| +
min(max(q), 0)``) give a one-sided gradient of zero.

Bookkeeping between field evaluations (step rules, hit and exit tests, compaction of
the active rays, the root refinement) runs in small Numba kernels, so a 512x512 image
costs little more than its field evaluations.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import CsdfError
from ..field import Field, as_field

try:
    from numba import njit
except Exception:  # pragma: no cover - numba is a dependency; plain Python then

    def njit(*args, **kwargs):  # type: ignore[no-redef]
        """Stand-in for ``numba.njit`` that returns the function unchanged."""
        return lambda fn: fn

__all__ = ["Field", "TraceResult", "TraceFrame", "sphere_trace", "ray_box", "trace_hits",
           "trace_field", "trace_frame", "EPS_REL", "OMEGA", "MAX_ITER", "MAX_ITER_SCALE",
           "CHUNK"]

#: hit tolerance relative to the bounding-box diagonal
EPS_REL = 1e-4
#: over-relaxation factor (Keinert et al. 2014)
OMEGA = 1.6
#: iterations per ray (for a 1-Lipschitz field; see MAX_ITER_SCALE)
MAX_ITER = 256
#: a field whose Lipschitz bound L exceeds 1 takes steps L times shorter, so it gets
#: up to ceil(L) times the iterations, at most this many times (a polynomial field
#: with an interval bound L = 12 needs ~1300 iterations on rays that graze it)
MAX_ITER_SCALE = 16
#: rays traced at once (bounds memory: about 200 bytes per ray)
CHUNK = 1 << 18
#: bisection/secant tolerance relative to the scene size
REFINE_REL = 1e-9
_JIT = {"cache": True, "nogil": True}
#: normals are evaluated this far (relative to the scene size) before the hit
NORMAL_BACKOFF = 1e-7
#: relative padding of the bounding box (rays start just outside the surface's box)
PAD_REL = 1e-3


def trace_field(shape, params: dict | None = None, backend: str = "auto", bounds=None,
                what: str = "rendering", *, check_ranges: bool = True) -> Field:
    """The :class:`csdf.field.Field` a tracer runs on (a sweep: one evaluator for every
    ray); a 2D Shape is refused (a 2D Program renders as an infinite prism inside given
    bounds), as is a field whose Lipschitz bound is not positive. ``check_ranges``: as
    for :class:`csdf.field.Field` (a value outside its range raises ParamError)."""
    fld = as_field(shape, params, backend=backend, bounds=bounds, what=what,
                   check_ranges=check_ranges)
    if fld.shape is not None and fld.shape.dim != 3:
        raise CsdfError(f"{what} needs a 3D shape; extrude or revolve a 2D shape first")
    if not fld.lipschitz > 0:
        raise CsdfError(f"the program's Lipschitz bound must be positive, got "
                        f"{fld.lipschitz}")
    return fld


@dataclass(frozen=True)
class TraceFrame:
    """Where and how finely a field is traced.

    Attributes:
        box: ``(2, 3)`` the field's bounds padded by :data:`PAD_REL` of their diagonal
            (rays start where they enter it and stop where they leave).
        scale: diagonal of the unpadded bounds (model units).
        eps: hit tolerance, :data:`EPS_REL` times ``scale``.
    """

    box: np.ndarray
    scale: float
    eps: float


def trace_frame(field: Field) -> TraceFrame:
    """The :class:`TraceFrame` of a field (from its bounds).

    Raises:
        CsdfError: no bounds (an unbounded shape without ``bounds=``) or an empty box.
    """
    b = field.bounds
    scale = float(np.linalg.norm(b[1] - b[0]))
    if not scale > 0:
        raise CsdfError("the shape's bounding box is empty")
    pad = PAD_REL * scale
    return TraceFrame(box=np.array([b[0] - pad, b[1] + pad]), scale=scale,
                      eps=EPS_REL * scale)


@dataclass
class TraceResult:
    """Result of :func:`sphere_trace`.

    Attributes:
        t: ``(N,)`` distance along each (unit) ray to its first hit, inf for a miss.
        hit: ``(N,)`` bool.
        iterations: sphere-tracing iterations run (the slowest ray's count).
        evaluations: field evaluations, summed over rays (tracing and refinement).
    """

    t: np.ndarray
    hit: np.ndarray
    iterations: int
    evaluations: int


def ray_box(origins: np.ndarray, dirs: np.ndarray,
            box: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Slab test: where rays enter and leave an axis-aligned box.

    Args:
        origins: ``(N, 3)`` or ``(3,)`` ray origins.
        dirs: ``(N, 3)`` ray directions.
        box: ``(2, 3)`` ``[min, max]``.

    Returns:
        ``(t_enter (N,), t_exit (N,))`` in units of ``|dir|``; the ray meets the box
        where ``t_enter <= t_exit`` (``t_enter`` may be negative: the origin is inside).
    """
    o = np.broadcast_to(origins, dirs.shape)
    t0 = np.full(len(dirs), -np.inf)
    t1 = np.full(len(dirs), np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        for k in range(3):
            inv = 1.0 / dirs[:, k]
            a = (box[0, k] - o[:, k]) * inv
            b = (box[1, k] - o[:, k]) * inv
            # fmin/fmax ignore the NaN of 0 * inf (origin on a slab plane, parallel ray)
            np.fmax(t0, np.fmin(a, b), out=t0)
            np.fmin(t1, np.fmax(a, b), out=t1)
    return t0, t1


# ------------------------------------------------------------------------- kernels
# The per-iteration bookkeeping (step rules, hit/exit tests, compaction of the active
# rays) runs in small Numba kernels; the field itself is evaluated by the program's
# backend between kernel calls. Without Numba the same functions run as plain Python.


@njit(**_JIT)
def _start(origins, shared, dirs, box, t_near, idx, o, d, t, tmax, pts):  # pragma: no cover
    """Clip rays ``(N, 3)`` to ``box``; write the rays that meet it, compacted, into
    ``idx, o, d, t, tmax`` and their first sample points into ``pts``; return the count."""
    m = 0
    for i in range(dirs.shape[0]):
        oi = 0 if shared else i
        t0 = t_near
        t1 = np.inf
        for k in range(3):
            ok = origins[oi, k]
            dk = dirs[i, k]
            if dk != 0.0:
                a = (box[0, k] - ok) / dk
                b = (box[1, k] - ok) / dk
                if a > b:
                    a, b = b, a
                if a > t0:
                    t0 = a
                if b < t1:
                    t1 = b
            elif ok < box[0, k] or ok > box[1, k]:
                t1 = -np.inf
        if t0 <= t1:
            idx[m] = i
            t[m] = t0
            tmax[m] = t1
            for k in range(3):
                d[m, k] = dirs[i, k]
                if not shared:
                    o[m, k] = origins[i, k]
                pts[m, k] = origins[oi, k] + t0 * dirs[i, k]
            m += 1
    return m


@njit(**_JIT)
def _cell_exit(o, d, c, lo, h, ax):  # pragma: no cover
    """Where the ray ``o + t d`` leaves cell index ``c`` (cells of size ``h`` from
    ``lo``) along axis ``ax``: inf for a ray parallel to it."""
    if d[ax] > 0.0:
        return (lo[ax] + (c + 1) * h - o[ax]) / d[ax]
    if d[ax] < 0.0:
        return (lo[ax] + c * h - o[ax]) / d[ax]
    return np.inf


@njit(**_JIT)
def _empty_run(o, d, t, tmax, lo, span, n, empty):  # pragma: no cover
    """Where the run of cells proved empty that holds the point ``o + t d`` ends along
    the ray (``o``, ``d``: ``(3,)``; cells: the ``n**3`` grid ``empty`` over ``lo +
    [0, span]``, see :meth:`csdf.field.Field.empty_cells`): ``t`` itself when that
    cell is not known to be empty, at most ``tmax``. A 3D digital differential
    analyser steps from cell to cell through the face the ray leaves by."""
    u0 = (o[0] + t * d[0] - lo[0]) / span[0]
    u1 = (o[1] + t * d[1] - lo[1]) / span[1]
    u2 = (o[2] + t * d[2] - lo[2]) / span[2]
    if not (0.0 <= u0 <= 1.0 and 0.0 <= u1 <= 1.0 and 0.0 <= u2 <= 1.0):
        return t
    c0 = min(int(math.floor(u0 * n)), n - 1)
    c1 = min(int(math.floor(u1 * n)), n - 1)
    c2 = min(int(math.floor(u2 * n)), n - 1)
    h0, h1, h2 = span[0] / n, span[1] / n, span[2] / n
    te = t
    for _ in range(3 * n):
        if empty[(c0 * n + c1) * n + c2] == 0:
            return te
        e0 = _cell_exit(o, d, c0, lo, h0, 0)
        e1 = _cell_exit(o, d, c1, lo, h1, 1)
        e2 = _cell_exit(o, d, c2, lo, h2, 2)
        best = min(e0, e1, e2)
        if best >= tmax:
            return tmax
        if best > te:
            te = best
        if best == e0:
            c0 += 1 if d[0] > 0.0 else -1
        elif best == e1:
            c1 += 1 if d[1] > 0.0 else -1
        else:
            c2 += 1 if d[2] > 0.0 else -1
        if not (0 <= c0 < n and 0 <= c1 < n and 0 <= c2 < n):
            return te
    return te


@njit(**_JIT)
def _march(n, f, shared, idx, o, d, t, tmax, ts, rs, step, rel, om, inv_L, L, eps,
           t_out, br, br_ta, br_tb, br_fa, br_fb, pts, skip, c_lo, c_span, c_n,
           c_empty):  # pragma: no cover
    """One sphere-tracing update of the ``n`` active rays given their field values
    ``f`` (``(n,)``). Finished rays are recorded (``t_out`` for hits at the start,
    ``br*`` for crossings, indexed by global ray) and dropped; the others are compacted
    to the front with their next sample points in ``pts``. With ``skip``, a ray whose
    sample lies in cells proved empty (``c_*``, see :func:`_empty_run`) steps to
    where they end when that is further than its sphere step. Returns the new count."""
    j = 0
    for i in range(n):
        fi = f[i]
        if fi != fi:  # NaN: a miss
            continue
        ri = fi * inv_L
        rsi = rs[i]
        tsi = ts[i]
        omi = om[i]
        reli = False
        if rel[i] and rsi + abs(ri) < step[i]:
            # the over-relaxed step left a gap between the two spheres: go back to the
            # safe point, take the plain step, stop relaxing
            s = rsi
            omi = 1.0
        elif fi <= 0.0:
            g = idx[i]
            if rsi < 0.0:  # inside at the first sample: a hit at the start
                t_out[g] = t[i]
            else:  # crossing between the safe point and here
                br[g] = True
                br_ta[g] = tsi
                br_tb[g] = t[i]
                br_fa[g] = rsi * L
                br_fb[g] = fi
            continue
        else:
            tsi = t[i]
            rsi = ri
            if ri < eps:
                s = eps
                safe = eps
            else:
                s = omi * ri
                safe = ri
            if skip:
                te = _empty_run(o[0 if shared else i], d[i], tsi, tmax[i], c_lo, c_span,
                                c_n, c_empty)
                jumped = te - tsi > s
                if jumped:  # certified by intervals: no relaxation to check
                    s = te - tsi
                    safe = s
            else:
                jumped = False
            if tsi + safe >= tmax[i]:  # the safe region reaches the exit: a miss
                continue
            rem = tmax[i] - tsi
            if s > rem:
                s = rem
            reli = ri >= eps and s > ri and not jumped
        idx[j] = idx[i]
        tmax[j] = tmax[i]
        ts[j] = tsi
        rs[j] = rsi
        step[j] = s
        rel[j] = reli
        om[j] = omi
        tn = tsi + s
        t[j] = tn
        for k in range(3):
            d[j, k] = d[i, k]
            if not shared:
                o[j, k] = o[i, k]
            pts[j, k] = o[0 if shared else j, k] + tn * d[j, k]
        j += 1
    return j


@njit(**_JIT)
def _secant_points(m, act, o, d, ta, tb, fa, fb, tm, pts):  # pragma: no cover
    """Regula-falsi points ``tm`` of the ``m`` active brackets, and their positions."""
    for j in range(m):
        i = act[j]
        a = ta[i]
        b = tb[i]
        den = fb[i] - fa[i]
        x = b - fb[i] * (b - a) / den if den != 0.0 else 0.5 * (a + b)
        if not (a < x < b):
            x = 0.5 * (a + b)
        tm[i] = x
        for k in range(3):
            pts[j, k] = o[i, k] + x * d[i, k]


@njit(**_JIT)
def _illinois(m, act, fm, ta, tb, fa, fb, side, tm, tol):  # pragma: no cover
    """Update the ``m`` active brackets with the values ``fm`` at ``tm`` (Illinois rule:
    halve the retained end's value when the same end moves twice); compact ``act`` to
    the brackets still wider than ``tol``; return their count."""
    k = 0
    for j in range(m):
        i = act[j]
        v = fm[j]
        x = tm[i]
        if v != v:
            ta[i] = x
            tb[i] = x
        elif v > 0.0:
            ta[i] = x
            fa[i] = v
            if side[i] == 1:
                fb[i] *= 0.5
            side[i] = 1
        else:
            tb[i] = x
            fb[i] = v
            if v == 0.0:
                ta[i] = x
            if side[i] == -1:
                fa[i] *= 0.5
            side[i] = -1
        if tb[i] - ta[i] > tol:
            act[k] = i
            k += 1
    return k


def _certified_steps(field: Field, eps: float, o: np.ndarray, d: np.ndarray,
                     ts: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Shorten candidate steps ``s`` (``(n,)``) from ``o + ts d`` (``o`` ``(n, 3)`` or
    ``(1, 3)``) until interval arithmetic proves the field positive on the segment's box
    (at most 4 quarterings; then the step is taken anyway). Used when the Lipschitz bound
    is unknown."""
    s = s.copy()
    todo = np.arange(len(s))
    for _ in range(5):
        if todo.size == 0:
            break
        oo = o if len(o) == 1 else o[todo]
        a = oo + ts[todo, None] * d[todo]
        b = a + s[todo, None] * d[todo]
        flo, _ = field.intervals(np.minimum(a, b), np.maximum(a, b))
        todo = todo[~(flo > 0)]
        s[todo] *= 0.25
    if todo.size:
        s[todo] *= 4.0  # undo the last quartering: the step is taken uncertified
    return np.maximum(s, eps)


def _refine(field: Field, scale: float, o: np.ndarray, d: np.ndarray, ta: np.ndarray,
            tb: np.ndarray, fa: np.ndarray, fb: np.ndarray) -> tuple[np.ndarray, int]:
    """Roots of ``f(o + t d)`` in brackets ``[ta, tb]`` (``fa > 0 >= fb``), all ``(m,)``
    (``o``, ``d`` ``(m, 3)``), by the Illinois variant of regula falsi, to
    :data:`REFINE_REL` of the scene size; returns ``(t (m,), evaluations)``."""
    tol = REFINE_REL * scale
    ta, tb, fa, fb = ta.copy(), tb.copy(), fa.copy(), fb.copy()
    closed = fb == 0.0
    ta[closed] = tb[closed]
    side = np.zeros(len(ta), dtype=np.int8)
    tm = np.zeros(len(ta))
    act = np.flatnonzero(tb - ta > tol)
    m = len(act)
    pts = np.empty((m, 3))
    evals = 0
    for _ in range(60):
        if m == 0:
            break
        _secant_points(m, act, o, d, ta, tb, fa, fb, tm, pts)
        fm = field.value(pts[:m])
        evals += m
        m = _illinois(m, act, fm, ta, tb, fa, fb, side, tm, tol)
    return 0.5 * (ta + tb), evals


def sphere_trace(field: Field, origins: np.ndarray, dirs: np.ndarray, *,
                 t_near: float = 0.0, max_iter: int = MAX_ITER,
                 omega: float = OMEGA, skip_empty: bool = True) -> TraceResult:
    """First hits of rays with the zero set of ``field`` (see the module docs).

    Args:
        field: the :class:`Field` to trace.
        origins: ``(N, 3)`` ray origins, or ``(3,)`` for one shared origin (a pinhole
            camera), model units, in the field's frame.
        dirs: ``(N, 3)`` **unit** ray directions.
        t_near: rays start no closer than this to their origin.
        max_iter: sphere-tracing iterations per ray, times ``ceil(L)`` (at most
            :data:`MAX_ITER_SCALE`) for a field whose Lipschitz bound ``L`` exceeds 1
            (its steps are ``f / L``: that much shorter).
        omega: over-relaxation factor (1 disables it).
        skip_empty: step over the cells that pruned evaluation has proved empty
            (:meth:`csdf.field.Field.empty_cells`; fields of long programs only).

    Returns:
        :class:`TraceResult` with ``t`` the distance to the first hit along each ray.

    Raises:
        CsdfError: non-finite or mis-shaped rays.
    """
    dirs = np.ascontiguousarray(dirs, dtype=np.float64)
    origins = np.ascontiguousarray(origins, dtype=np.float64)
    if dirs.ndim != 2 or dirs.shape[1] != 3:
        raise CsdfError(f"ray directions must have shape (N, 3), got {dirs.shape}")
    shared = origins.shape == (3,)
    if shared:
        origins = origins.reshape(1, 3)
    elif origins.shape != dirs.shape:
        raise CsdfError(f"ray origins must have shape (3,) or {dirs.shape}, got "
                        f"{origins.shape}")
    if not (np.all(np.isfinite(dirs)) and np.all(np.isfinite(origins))):
        raise CsdfError("ray origins and directions must be finite")
    n = len(dirs)
    frame = trace_frame(field)
    L = field.lipschitz
    finite_L = math.isfinite(L)
    if finite_L and L > 1.0:
        max_iter = int(max_iter * min(math.ceil(L), MAX_ITER_SCALE))
    eps = frame.eps
    t_out = np.full(n, np.inf)
    br = np.zeros(n, dtype=bool)
    br_ta, br_tb, br_fa, br_fb = (np.empty(n) for _ in range(4))
    idx = np.empty(n, dtype=np.int64)
    o = origins.copy() if shared else np.empty((n, 3))
    d = np.empty((n, 3))
    t = np.empty(n)
    tmax = np.empty(n)
    pts = np.empty((n, 3))
    m = _start(origins, shared, dirs, frame.box, float(t_near), idx, o, d, t, tmax, pts)
    ts = t.copy()  # the last safe point of each ray
    rs = np.full(n, -1.0)  # its unbounding radius (-1: none yet)
    step = np.zeros(n)  # the step taken from ts to t
    rel = np.zeros(n, dtype=bool)  # that step was over-relaxed
    om = np.full(n, omega if finite_L else 1.0)
    inv_L = 1.0 / L if finite_L else 1.0
    L_fa = L if finite_L else 1.0
    cells = field.empty_cells() if skip_empty else None
    skip = cells is not None
    if skip:
        c_lo, c_span, c_n, c_empty = cells
    else:
        c_lo = c_span = np.zeros(3)
        c_n, c_empty = 1, np.zeros(1, np.uint8)
    evals = 0
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007 - the count is reported
        if m == 0:
            break
        f = field.value(pts[:m])
        evals += m
        m = _march(m, f, shared, idx, o, d, t, tmax, ts, rs, step, rel, om, inv_L, L_fa,
                   eps, t_out, br, br_ta, br_tb, br_fa, br_fb, pts, skip, c_lo, c_span,
                   c_n, c_empty)
        if not finite_L and m:
            far = np.flatnonzero(step[:m] > eps)
            if far.size:
                oo = o if shared else o[far]
                s = _certified_steps(field, eps, oo, d[far], ts[far], step[far])
                step[far] = s
                t[far] = ts[far] + s
                pts[far] = (o[0] if shared else o[far]) + t[far, None] * d[far]
    if m:  # out of iterations: close to the surface counts as a hit
        close = (rs[:m] >= 0) & (rs[:m] < 16.0 * eps)
        t_out[idx[:m][close]] = ts[:m][close]
    bi = np.flatnonzero(br)
    if bi.size:
        ob = np.broadcast_to(origins[0], (bi.size, 3)) if shared else origins[bi]
        troot, e = _refine(field, frame.scale, np.ascontiguousarray(ob), dirs[bi], br_ta[bi],
                           br_tb[bi], br_fa[bi], br_fb[bi])
        t_out[bi] = troot
        evals += e
    return TraceResult(t=t_out, hit=np.isfinite(t_out), iterations=it, evaluations=evals)


def trace_hits(field: Field, origins: np.ndarray, dirs: np.ndarray, *, t_near: float = 0.0,
               max_iter: int = MAX_ITER) -> tuple[np.ndarray, np.ndarray, dict]:
    """Trace in chunks of :data:`CHUNK` rays and compute exact normals at the hits.

    Args:
        field: the :class:`Field`.
        origins: ``(N, 3)`` ray origins or ``(3,)`` for a shared one, the field's frame.
        dirs: ``(N, 3)`` unit ray directions.

    Returns:
        ``(t (N,), normals (N, 3), stats)``: ``t`` is inf for a miss; normals are unit
        outward gradients ``grad f / |grad f|`` (exact, by forward differentiation) at
        :data:`NORMAL_BACKOFF` of the scene size before the hit along the ray (zero for
        misses; ``-dir`` where the gradient vanishes); ``stats`` has ``iterations`` and
        ``evaluations``.
    """
    origins = np.asarray(origins, dtype=np.float64)
    shared = origins.shape == (3,)
    n = len(dirs)
    t = np.full(n, np.inf)
    stats = {"iterations": 0, "evaluations": 0}
    for a in range(0, n, CHUNK):
        b = min(a + CHUNK, n)
        res = sphere_trace(field, origins if shared else origins[a:b], dirs[a:b],
                           t_near=t_near, max_iter=max_iter)
        t[a:b] = res.t
        stats["iterations"] = max(stats["iterations"], res.iterations)
        stats["evaluations"] += res.evaluations
    normals = np.zeros((n, 3))
    hit = np.flatnonzero(np.isfinite(t))
    if hit.size:
        # the gradient is taken NORMAL_BACKOFF (relative) before the hit, on the outside:
        # exactly on the surface, fields built from kinks that meet there (a box's
        # ``|max(q, 0)| + min(max(q), 0)``) may give a one-sided gradient of zero
        tn = t[hit] - NORMAL_BACKOFF * trace_frame(field).scale
        p = (origins if shared else origins[hit]) + tn[:, None] * dirs[hit]
        _, g = field.value_and_grad(p)
        stats["evaluations"] += hit.size
        norm = np.sqrt(np.einsum("ij,ij->i", g, g))
        good = np.isfinite(norm) & (norm > 0)
        nrm = -dirs[hit]
        nrm[good] = g[good] / norm[good, None]
        normals[hit] = nrm
    return t, normals, stats
