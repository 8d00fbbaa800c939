"""Numba kernels of batched queries over many posed instances (a scene): the nearest
instance of each point, its signed distance and gradient, and collision tests of
spheres, with a bounding volume hierarchy over the instances' world boxes.

Compiled once for all programs: each instance runs a register tape
(:class:`csdf.backends.pruned.RegTape`) with the lane interpreter of
:mod:`csdf.backends.tape_kernels` on one lane, so values are bit-identical to the
``'interp'`` backend's in the instance's frame.

Data (packed to keep the call cheap):

* ``inst_f`` ``(K, 19)`` float64 per instance: the rotation ``R`` row by row (9), the
  translation ``t`` (3), the scale ``s`` (1), the world box ``lo`` (3) and ``hi`` (3);
  the instance's field at a world point ``p`` is ``s f(R^T (p - t) / s)``.
* ``inst_i`` ``(K, 2)`` int64: the instance's tape and its contract (0 exact, 1 bound,
  2 neither).
* ``tape_i`` ``(T, 6)`` int64 per tape: first row in ``code``/``imm``, row count, output
  register, registers used, and for a tape kept per cell of a grid over the model's
  region (long models) the cells per axis ``n`` (0: none) and the first entry of its
  ``n**3`` cells in ``cell_tab`` (``(C,)`` int64: the cell's tape); ``tape_f`` ``(T,
  6)`` float64: that region's ``lo`` and ``span`` (object frame). A point of the region
  runs its cell's tape (bit-identical there), any other the whole tape.
* ``node_f`` ``(M, 6)`` float64 per BVH node: its box ``lo``, ``hi``; ``node_i`` ``(M,
  2)`` int64: the two children, or ``(-1 - first, count)`` for a leaf holding
  ``order[first:first + count]``.

Pruning by boxes is sound for every contract whose sign is right: outside an
instance's box its true distance is at least the distance to the box, so an instance
whose box is farther than the best value so far cannot hold the nearest surface.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .tape_kernels import run_lanes, run_lanes_grad

_OPTS = dict(nogil=True, cache=True, boundscheck=False, error_model="numpy")
#: BVH traversal stack depth (the tree is built balanced: depth ~ log2(instances) + 1)
STACK = 64


@njit(inline="always", **_OPTS)
def _box_distance(p0, p1, p2, f, off):
    """Distance from a point to the box ``f[off:off+3]`` (lo), ``f[off+3:off+6]`` (hi);
    0 inside."""
    s = 0.0
    for ax in range(3):
        v = p0 if ax == 0 else (p1 if ax == 1 else p2)
        lo = f[off + ax]
        hi = f[off + 3 + ax]
        if v < lo:
            s += (lo - v) * (lo - v)
        elif v > hi:
            s += (v - hi) * (v - hi)
    return np.sqrt(s)


@njit(inline="always", **_OPTS)
def _cell_tape(t, q0, q1, q2, tape_i, tape_f, cell_tab):
    """The tape to run at object point ``q`` for tape ``t``: its cell's, or itself."""
    n = tape_i[t, 4]
    if n == 0:
        return t
    f = tape_f[t]
    u0 = (q0 - f[0]) / f[3]
    u1 = (q1 - f[1]) / f[4]
    u2 = (q2 - f[2]) / f[5]
    if not (0.0 <= u0 <= 1.0 and 0.0 <= u1 <= 1.0 and 0.0 <= u2 <= 1.0):
        return t
    c0 = min(int(np.floor(u0 * n)), n - 1)
    c1 = min(int(np.floor(u1 * n)), n - 1)
    c2 = min(int(np.floor(u2 * n)), n - 1)
    return cell_tab[tape_i[t, 5] + (c0 * n + c1) * n + c2]


@njit(inline="always", **_OPTS)
def _eval_instance(k, p0, p1, p2, inst_f, inst_i, code, imm, tape_i, tape_f, cell_tab, R,
                   D, tmp, grad, g_out):
    """The value ``s f(q)`` of instance ``k`` at world point ``p``; with ``grad`` also
    the world gradient ``R grad f(q)`` into ``g_out`` (3,)."""
    f = inst_f[k]
    d0, d1, d2 = p0 - f[9], p1 - f[10], p2 - f[11]
    s = f[12]
    # q = R^T d / s
    R[0, 0] = (f[0] * d0 + f[3] * d1 + f[6] * d2) / s
    R[1, 0] = (f[1] * d0 + f[4] * d1 + f[7] * d2) / s
    R[2, 0] = (f[2] * d0 + f[5] * d1 + f[8] * d2) / s
    t = _cell_tape(inst_i[k, 0], R[0, 0], R[1, 0], R[2, 0], tape_i, tape_f, cell_tab)
    start = tape_i[t, 0]
    n = tape_i[t, 1]
    o = tape_i[t, 2]
    if grad:
        for r in range(3):
            for c in range(3):
                D[r, c, 0] = 1.0 if r == c else 0.0
        run_lanes_grad(code, imm, start, n, R, D, tmp, 1)
        a, b, c = D[o, 0, 0], D[o, 1, 0], D[o, 2, 0]
        g_out[0] = f[0] * a + f[1] * b + f[2] * c
        g_out[1] = f[3] * a + f[4] * b + f[5] * c
        g_out[2] = f[6] * a + f[7] * b + f[8] * c
    else:
        run_lanes(code, imm, start, n, R, 1)
    return s * R[o, 0]


@njit(**_OPTS)
def _search(p0, p1, p2, best, stop, inst_f, inst_i, code, imm, tape_i, tape_f, cell_tab,
            node_f, node_i, order, R, D, tmp, g, stack):
    """The search of one point: ``(best, winner, nmin)``: the smallest instance value
    below the start ``best``, its instance (-1: none below it) and the nearest box of an
    evaluated instance of contract 'neither' (inf: none). ``stop``: end at the first
    value below the start."""
    win = -1
    nmin = np.inf
    stack[0] = 0
    top = 1
    done = False
    while top > 0 and not done:
        top -= 1
        node = stack[top]
        bd = _box_distance(p0, p1, p2, node_f[node], 0)
        if bd > 0.0 and bd >= best:
            continue
        c0 = node_i[node, 0]
        c1 = node_i[node, 1]
        if c0 < 0:  # a leaf
            first = -1 - c0
            for j in range(first, first + c1):
                k = order[j]
                bk = _box_distance(p0, p1, p2, inst_f[k], 13)
                if bk > 0.0 and bk >= best:
                    continue
                v = _eval_instance(k, p0, p1, p2, inst_f, inst_i, code, imm, tape_i,
                                   tape_f, cell_tab, R, D, tmp, False, g)
                if inst_i[k, 1] == 2 and bk < nmin:
                    nmin = bk
                if v < best:
                    best = v
                    win = k
                    if stop:
                        done = True
                        break
        else:
            # the nearer child is searched first
            d0 = _box_distance(p0, p1, p2, node_f[c0], 0)
            d1 = _box_distance(p0, p1, p2, node_f[c1], 0)
            if top + 2 > STACK:  # pragma: no cover - a balanced tree is shallow
                raise RuntimeError("BVH too deep")
            if d0 <= d1:
                stack[top] = c1
                stack[top + 1] = c0
            else:
                stack[top] = c0
                stack[top + 1] = c1
            top += 2
    return best, win, nmin


@njit(**_OPTS)
def nearest(pts, below, stop, want_grad, inst_f, inst_i, code, imm, tape_i, tape_f,
            cell_tab, node_f, node_i, order, max_regs, dist, grad, inst, exact, part,
            n_parts):
    """For points ``pts`` ``(N, 3)`` (the ``part``-th of ``n_parts`` slices): the
    smallest instance value ``dist`` ``(N,)``, its instance ``inst`` ``(N,)`` (-1: no
    instance holds a value below the start), its world gradient ``grad`` ``(N, 3)``
    (with ``want_grad``) and whether the value is the exact distance ``exact`` ``(N,)``
    (the winner is exact and no instance of contract 'neither' could be nearer).

    ``below`` ``(N,)``: the search starts with this value as the best (inf for a plain
    nearest query; a sphere's radius for a collision test: only instances nearer than it
    are evaluated). ``stop``: end a point's search at the first value below ``below``
    (a collision test). Points with a NaN coordinate get NaN and -1.
    """
    # the search of _search written out here: as a call (even inlined) this kernel ran
    # 5x slower on a 20-primitive scene (3.2 against 17 us for 100 spheres, measured)
    N = pts.shape[0]
    R = np.empty((max(max_regs, 3), 1))
    D = np.empty((max(max_regs, 3), 3, 1))
    tmp = np.empty((1, 1))
    g = np.zeros(3)
    stack = np.empty(STACK, np.int64)
    a = (N * part) // n_parts
    b = (N * (part + 1)) // n_parts
    for i in range(a, b):
        p0, p1, p2 = pts[i, 0], pts[i, 1], pts[i, 2]
        if p0 != p0 or p1 != p1 or p2 != p2:
            dist[i] = np.nan
            inst[i] = -1
            exact[i] = False
            if want_grad:
                grad[i, 0] = np.nan
                grad[i, 1] = np.nan
                grad[i, 2] = np.nan
            continue
        best = below[i]
        win = -1
        nmin = np.inf  # the nearest box of an evaluated instance of contract 'neither'
        top = 0
        stack[0] = 0
        top = 1
        done = False
        while top > 0 and not done:
            top -= 1
            node = stack[top]
            bd = _box_distance(p0, p1, p2, node_f[node], 0)
            if bd > 0.0 and bd >= best:
                continue
            c0 = node_i[node, 0]
            c1 = node_i[node, 1]
            if c0 < 0:  # a leaf
                first = -1 - c0
                for j in range(first, first + c1):
                    k = order[j]
                    bk = _box_distance(p0, p1, p2, inst_f[k], 13)
                    if bk > 0.0 and bk >= best:
                        continue
                    v = _eval_instance(k, p0, p1, p2, inst_f, inst_i, code, imm, tape_i,
                                       tape_f, cell_tab, R, D, tmp, False, g)
                    if inst_i[k, 1] == 2 and bk < nmin:
                        nmin = bk
                    if v < best:
                        best = v
                        win = k
                        if stop:
                            done = True
                            break
            else:
                # the nearer child is searched first
                d0 = _box_distance(p0, p1, p2, node_f[c0], 0)
                d1 = _box_distance(p0, p1, p2, node_f[c1], 0)
                if top + 2 > STACK:  # pragma: no cover - a balanced tree is shallow
                    raise RuntimeError("BVH too deep")
                if d0 <= d1:
                    stack[top] = c1
                    stack[top + 1] = c0
                else:
                    stack[top] = c0
                    stack[top + 1] = c1
                top += 2
        dist[i] = best
        inst[i] = win
        if win >= 0:
            exact[i] = inst_i[win, 1] == 0 and not (nmin < best)
            if want_grad:
                _eval_instance(win, p0, p1, p2, inst_f, inst_i, code, imm, tape_i, tape_f,
                               cell_tab, R, D, tmp, True, g)
                grad[i, 0] = g[0]
                grad[i, 1] = g[1]
                grad[i, 2] = g[2]
        else:
            exact[i] = False
            if want_grad:
                grad[i, 0] = 0.0
                grad[i, 1] = 0.0
                grad[i, 2] = 0.0


@njit(**_OPTS)
def raycast(orig, shared, dirs, tmax, inv_L, eps, tol, max_iter, inst_f, inst_i, code,
            imm, tape_i, tape_f, cell_tab, node_f, node_i, order, max_regs, t_out, inst,
            normal, part, n_parts):
    """First hits of rays ``orig + t dirs`` (``dirs`` ``(N, 3)`` unit; ``orig`` ``(N,
    3)``, or ``(1, 3)`` with ``shared``) with the instances' union, ``t`` in ``[0,
    tmax[i]]``, by sphere tracing: steps of the scene's value times ``inv_L`` (one over
    the largest Lipschitz bound), steps of ``eps`` where the value is below ``eps``,
    and a hit where the value changes sign, refined to ``tol`` (a ray that starts
    inside hits at its start). Rays are clipped to the hierarchy's root box.
    Writes ``t_out`` (inf: no hit), ``inst`` (-1: none) and ``normal`` (the unit world
    gradient of the hit instance there; 0 for misses)."""
    N = dirs.shape[0]
    R = np.empty((max(max_regs, 3), 1))
    D = np.empty((max(max_regs, 3), 3, 1))
    tmp = np.empty((1, 1))
    g = np.zeros(3)
    stack = np.empty(STACK, np.int64)
    box = node_f[0]
    a = (N * part) // n_parts
    b = (N * (part + 1)) // n_parts
    for i in range(a, b):
        oi = 0 if shared else i
        t0 = 0.0
        t1 = tmax[i]
        for ax in range(3):
            o = orig[oi, ax]
            d = dirs[i, ax]
            lo = box[ax] - eps
            hi = box[3 + ax] + eps
            if d != 0.0:
                u = (lo - o) / d
                w = (hi - o) / d
                if u > w:
                    u, w = w, u
                t0 = max(t0, u)
                t1 = min(t1, w)
            elif o < lo or o > hi:
                t1 = -1.0
        t_out[i] = np.inf
        inst[i] = -1
        normal[i, 0] = 0.0
        normal[i, 1] = 0.0
        normal[i, 2] = 0.0
        if not t0 <= t1:
            continue
        t = t0
        t_prev = t0
        v_prev = np.inf
        for it in range(max_iter):
            v, win = _value_at(orig, oi, dirs, i, t, inst_f, inst_i, code, imm, tape_i,
                               tape_f, cell_tab, node_f, node_i, order, R, D, tmp, g, stack)
            if v != v:
                break
            if v <= 0.0:
                if it > 0:  # a crossing between the last two samples: refine it
                    t = _refine(orig, oi, dirs, i, t_prev, t, v_prev, v, tol, inst_f,
                                inst_i, code, imm, tape_i, tape_f, cell_tab, node_f,
                                node_i, order, R, D, tmp, g, stack)
                # the instance and normal just outside (a kink may sit on the surface)
                tn = max(t - tol, t0) if it > 0 else t
                vn, wn = _value_at(orig, oi, dirs, i, tn, inst_f, inst_i, code, imm,
                                   tape_i, tape_f, cell_tab, node_f, node_i, order, R, D,
                                   tmp, g, stack)
                if wn < 0:
                    wn = win
                t_out[i] = t
                inst[i] = wn
                _eval_instance(wn, orig[oi, 0] + tn * dirs[i, 0],
                               orig[oi, 1] + tn * dirs[i, 1], orig[oi, 2] + tn * dirs[i, 2],
                               inst_f, inst_i, code, imm, tape_i, tape_f, cell_tab, R, D,
                               tmp, True, g)
                n = np.sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2])
                if n > 0.0 and n < np.inf:
                    normal[i, 0] = g[0] / n
                    normal[i, 1] = g[1] / n
                    normal[i, 2] = g[2] / n
                break
            t_prev = t
            v_prev = v
            # near the surface, small steps look for the sign change (a ray that only
            # grazes it sees the value grow again and goes on)
            t += eps if v < eps else v * inv_L
            if t > t1:
                break


@njit(**_OPTS)
def _value_at(orig, oi, dirs, i, t, inst_f, inst_i, code, imm, tape_i, tape_f, cell_tab,
              node_f, node_i, order, R, D, tmp, g, stack):
    """The scene's value and nearest instance at ``orig[oi] + t dirs[i]``."""
    v, win, _ = _search(orig[oi, 0] + t * dirs[i, 0], orig[oi, 1] + t * dirs[i, 1],
                        orig[oi, 2] + t * dirs[i, 2], np.inf, False, inst_f, inst_i, code,
                        imm, tape_i, tape_f, cell_tab, node_f, node_i, order, R, D, tmp, g,
                        stack)
    return v, win


@njit(**_OPTS)
def _refine(orig, oi, dirs, i, ta, tb, fa, fb, tol, inst_f, inst_i, code, imm, tape_i,
            tape_f, cell_tab, node_f, node_i, order, R, D, tmp, g, stack):
    """The root in ``[ta, tb]`` (``fa > 0 >= fb``) by the Illinois variant of regula
    falsi, to ``tol``; returns the end where the value is not positive."""
    side = 0
    for _ in range(100):
        if tb - ta <= tol or fb == 0.0:
            break
        x = tb - fb * (tb - ta) / (fb - fa)
        if not (ta < x < tb):
            x = 0.5 * (ta + tb)
        v, _ = _value_at(orig, oi, dirs, i, x, inst_f, inst_i, code, imm, tape_i, tape_f,
                         cell_tab, node_f, node_i, order, R, D, tmp, g, stack)
        if v != v:
            break
        if v > 0.0:
            ta = x
            fa = v
            if side == 1:
                fb *= 0.5
            side = 1
        else:
            tb = x
            fb = v
            if side == -1:
                fa *= 0.5
            side = -1
    return tb
