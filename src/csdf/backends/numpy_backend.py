"""The NumPy reference evaluator: values and forward-mode derivatives over the tape.

It interprets one instruction at a time over a chunk of points (so memory stays
bounded: at most ``n_slots`` arrays of ``chunk`` values plus their tangents), with
every op computed by NumPy in the points' dtype. Tangents are carried per slot as
``None`` (zero), a ``(T,)`` vector (uniform over the chunk) or a ``(chunk, T)`` array,
where the T seeds are x, y, z (gradient), the parameters (Jacobian), or both.

Where a value is NaN (a NaN coordinate or parameter, or a NaN made inside the tape)
its derivatives are NaN too. Every op's value, derivative rule, tie rule (``min``/``max``)
and kink conventions are those of its specification in :mod:`csdf.ops`, evaluated here
with NumPy (:func:`csdf.ops.chain_tangent`, :func:`csdf.ops.tie_mask`).
"""

from __future__ import annotations

import numpy as np

from ..ops import ARG_CODE, MESH_CODE, OPS, OPS_BY_CODE, chain_tangent, numpy_impl, tie_mask

__all__ = ["evaluate", "available", "uniform_prefix", "CHUNK"]

CHUNK = 1 << 16


def available() -> bool:
    """Always True: the reference needs only NumPy."""
    return True


def _sc(c, d):
    """Scale tangent ``d`` by the per-point (or scalar) factor ``c``."""
    if d is None:
        return None
    if np.ndim(c):
        return c[:, None] * d
    return c * d


def _add(u, v):
    if u is None:
        return v
    if v is None:
        return u
    return u + v


def _sub(u, v):
    if v is None:
        return u
    if u is None:
        return -v
    return u - v


def _select(mask, da, db, n: int, t: int, dtype):
    if da is None and db is None:
        return None
    if np.ndim(mask) == 0:
        return da if bool(mask) else db
    za = da if da is not None else np.zeros(t, dtype)
    zb = db if db is not None else np.zeros(t, dtype)
    return np.where(mask[:, None], za, zb)


class _Arrays:
    """Tangent algebra on NumPy tangents (``None`` | ``(T,)`` | ``(chunk, T)``)."""

    scale = staticmethod(_sc)
    add = staticmethod(_add)
    sub = staticmethod(_sub)

    @staticmethod
    def neg(t):
        return -t


_ARRAYS = _Arrays()


def _tangent(op: str, a, b, out, da, db, n: int, t: int, dtype, a_const: bool = False):
    """Tangent of ``out = op(a, b)`` given tangents ``da``, ``db``, by the op's rule in
    :mod:`csdf.ops`; ``a_const``: operand ``a`` is a constant slot (the tie rule of
    ``min``/``max``)."""
    rule = OPS[op].derivative
    if rule.kind == "select":
        return _select(tie_mask(op, a, b, a_const), da, db, n, t, dtype)
    if rule.kind == "zero" or (da is None and db is None):
        return None
    env = {"a": a, "b": b, "v": out}
    for name, f in rule.let:
        env[name] = f.numpy(env, dtype)
    return chain_tangent(rule, da, db, lambda f: f.numpy(env, dtype), _ARRAYS)


def evaluate(prog, pts: np.ndarray, pvals: np.ndarray, mode: str, *,
             chunk: int | None = None) -> dict[str, np.ndarray]:
    """Evaluate a program on points.

    Args:
        prog: the :class:`csdf.Program`.
        pts: ``(N, D)`` float32/float64, D = 2 or 3.
        pvals: ``(P,)`` float64 parameter values.
        mode: ``'value' | 'grad' | 'jac' | 'all'``.
        chunk: points per pass over the tape. ``None`` picks a cache-sized chunk
            (``CHUNK`` values; fewer when tangents ride along); ``len(pts)`` gives the
            textbook array evaluator that materialises a full ``(N,)`` array per
            instruction (what the benchmark compares against).

    Returns:
        ``{'value': (N,), 'grad': (N, 3), 'jac': (N, P)}`` (the keys the mode asks for),
        in the points' dtype.
    """
    dtype = pts.dtype
    n, d = pts.shape
    P = len(prog.params)
    spatial = mode in ("grad", "all")
    wrt_params = mode in ("jac", "all")
    T = (3 if spatial else 0) + (P if wrt_params else 0)
    res: dict[str, np.ndarray] = {"value": np.empty(n, dtype)}
    if spatial:
        res["grad"] = np.zeros((n, 3), dtype)
    if wrt_params:
        res["jac"] = np.zeros((n, P), dtype)

    with np.errstate(over="ignore"):  # constants beyond float32 range become inf
        consts = prog.consts.astype(dtype)
        pv = pvals.astype(dtype)
    code = _steps(prog)
    fns = {name: numpy_impl(name) for name, *_ in code if name != "mesh"}
    lay = prog.layout
    n_slots = lay.n_slots
    c_lo, c_hi = lay.const_base, lay.reg_base  # constant slots (the tie rule of min/max)
    if chunk is None:
        chunk = CHUNK if T == 0 else max(1024, (1 << 20) // max(T, 1) // 4)
    elif chunk < 1:
        raise ValueError(f"chunk must be >= 1, got {chunk}")

    seeds: list = [None] * n_slots
    if T:
        eye = np.eye(T, dtype=dtype)
        if spatial:
            for i in range(3):
                seeds[i] = eye[i]
        if wrt_params:
            off = 3 if spatial else 0
            for i in range(P):
                seeds[lay.param(i)] = eye[off + i]

    for start in range(0, n, chunk):
        stop = min(n, start + chunk)
        m = stop - start
        vals: list = [None] * n_slots
        vals[0] = pts[start:stop, 0]
        vals[1] = pts[start:stop, 1]
        vals[2] = pts[start:stop, 2] if d == 3 else np.zeros(m, dtype)
        for i in range(P):
            vals[lay.param(i)] = pv[i]
        for i, c in enumerate(consts):
            vals[lay.const(i)] = c
        tans = list(seeds) if T else None
        with np.errstate(all="ignore"):
            for name, arity, dst, a, b in code:
                if name == "mesh":
                    vals[dst], t = _mesh_step(prog, vals, tans, a, b, m, dtype)
                    if T:
                        tans[dst] = t
                    continue
                va = vals[a]
                vb = vals[b] if arity == 2 else None
                out = fns[name](va, vb) if arity == 2 else fns[name](va)
                if T:
                    tans[dst] = _tangent(name, va, vb, out, tans[a],
                                         tans[b] if arity == 2 else None, m, T, dtype,
                                         c_lo <= a < c_hi)
                vals[dst] = out
        v = vals[prog.output]
        res["value"][start:stop] = v
        if T:
            tv = tans[prog.output]
            if tv is not None:
                if spatial:
                    res["grad"][start:stop] = tv[..., :3]
                if wrt_params:
                    res["jac"][start:stop] = tv[..., (3 if spatial else 0):]

    bad = np.isnan(pts).any(axis=1)
    if np.isnan(pvals).any():
        bad[:] = True
    if bad.any():
        for arr in res.values():
            arr[bad] = np.nan
    if T:
        vnan = np.isnan(res["value"])
        if vnan.any():
            for key in ("grad", "jac"):
                if key in res:
                    res[key][vnan] = np.nan
    return res


def _steps(prog) -> list[tuple]:
    """``(name, arity, dst, a, b)`` per instruction; a mesh call is one step
    ``('mesh', 3, dst, (a, b, c), block)`` (its argument row is folded in)."""
    rows = prog.code.tolist()
    out: list[tuple] = []
    for k, (op, dst, a, b) in enumerate(rows):
        if op == ARG_CODE:
            continue
        if op == MESH_CODE:
            out.append(("mesh", 3, dst, (a, b, rows[k + 1][2]), rows[k + 1][3]))
            continue
        info = OPS_BY_CODE[op]
        out.append((info.name, info.arity, dst, a, b))
    return out


def _mesh_step(prog, vals: list, tans: list | None, ops: tuple[int, int, int], block: int,
               m: int, dtype):
    """Value ``(m,)`` and tangent of a mesh call: the signed distance to data block
    ``block`` at the three operand slots, and ``sum_i g_i * d(operand_i)`` with ``g`` the
    distance's unit gradient (computed in float64, returned in ``dtype``)."""
    from .meshdist import for_data

    md = for_data(prog.data[block])
    p = [np.broadcast_to(np.asarray(vals[s], dtype=np.float64), (m,)) for s in ops]
    want = tans is not None and any(tans[s] is not None for s in ops)
    v, g = md.field(p[0], p[1], p[2], want)
    t = None
    if want:
        g = g.astype(dtype)
        for i, s in enumerate(ops):
            t = _add(t, _sc(g[:, i], tans[s]))  # type: ignore[index]
        if t is not None and t.ndim == 1:
            t = np.broadcast_to(t, (m, len(t))).copy()
    return v.astype(dtype), t


def uniform_prefix(prog, pvals: np.ndarray, n_prefix: int, tangents: bool = True):
    """Values and parameter derivatives of the first ``n_prefix`` instructions, which
    must read only parameters, constants and earlier prefix results (float64). (The
    Numba backends compute the same with :func:`csdf.backends.interp_kernels.prefix_kernel`,
    bit for bit on the zoo's models.)

    Returns:
        ``(values, dparams)``: lists indexed by instruction; ``dparams[k]`` is ``(P,)``
        (``dparams`` is empty when ``tangents`` is False: values only, faster).
    """
    P = len(prog.params)
    lay = prog.layout
    dtype = np.dtype(np.float64)
    vals: list = [None] * lay.n_slots
    tans: list = [None] * lay.n_slots
    eye = np.eye(P, dtype=dtype)
    for i in range(P):
        vals[lay.param(i)] = np.float64(pvals[i])
        tans[lay.param(i)] = eye[i]
    for i, c in enumerate(prog.consts):
        vals[lay.const(i)] = np.float64(c)
    out_v: list = []
    out_d: list = []
    with np.errstate(all="ignore"):
        for op, dst, a, b in prog.code[:n_prefix].tolist():
            info = OPS_BY_CODE[op]
            va, vb = vals[a], (vals[b] if info.arity == 2 else None)
            v = numpy_impl(info.name)(va, vb) if info.arity == 2 else numpy_impl(info.name)(va)
            vals[dst] = v
            out_v.append(float(v))
            if not tangents:
                continue
            t = _tangent(info.name, va, vb, v, tans[a], tans[b] if info.arity == 2 else None,
                         1, P, dtype, lay.is_const(a))
            tans[dst] = t
            out_d.append(np.zeros(P) if t is None else np.asarray(t, dtype=np.float64))
    return out_v, out_d
