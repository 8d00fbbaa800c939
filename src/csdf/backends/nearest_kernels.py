"""Numba kernels of batched queries over many posed instances (a scene): the nearest
instance of each point, its signed distance and gradient, and collision tests of
spheres, with a bounding volume hierarchy over the instances' world boxes (ray casts
are the sphere tracer's, on these values).

Compiled once for all programs: each instance runs a register tape
(:class:`csdf.backends.pruned.RegTape`) with the lane interpreter of
:mod:`csdf.backends.tape_kernels` on one lane, so values are bit-identical to the
``'interp'`` backend's in the instance's frame.

Data (packed to keep the call cheap):

* Entries: an instance is one entry, or one per part when its model is a hard union
  (:func:`csdf.fieldset.union_parts`). ``inst_f`` ``(E, 19)`` float64 per entry: the
  instance's rotation ``R`` row by row (9), translation ``t`` (3) and scale ``s`` (1),
  the entry's world box ``lo`` (3) and ``hi`` (3); the entry's field at a world point
  ``p`` is ``s f(R^T (p - t) / s)``. ``inst_i`` ``(E, 2)`` int64: the entry's tape and
  the instance's contract (0 exact, 1 bound, 2 neither).
* ``inst_box`` ``(K, 6)`` float64 per instance: its world box (holding its entries'
  boxes); ``ent_range`` ``(K, 2)`` int64: its first entry and entry count.
* ``tape_i`` ``(T, 6)`` int64 per tape: first row in ``code``/``imm``, row count, output
  register, registers used, and for a tape kept per cell of a grid over the model's
  region (long models) the cells per axis ``n`` (0: none) and the first entry of its
  ``n**3`` cells in ``cell_tab`` (``(C,)`` int64: the cell's tape); ``tape_f`` ``(T,
  6)`` float64: that region's ``lo`` and ``span`` (object frame). A point of the region
  runs its cell's tape (bit-identical there), any other the whole tape.
* ``node_f`` ``(M, 6)`` float64 per BVH node (over the instances): its box ``lo``,
  ``hi``; ``node_i`` ``(M, 2)`` int64: the two children, or ``(-1 - first, count)`` for
  a leaf holding instances ``order[first:first + count]``, whose entries are searched
  in turn (a two-level hierarchy: a tree of instances, then each instance's parts).

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


@njit(**_OPTS)
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


@njit(**_OPTS)
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


@njit(**_OPTS)
def _eval_instance(k, p0, p1, p2, inst_f, inst_i, code, imm, tape_i, tape_f, cell_tab, R):
    """The value ``s f(q)`` of instance ``k`` at world point ``p`` (one lane of ``R``)."""
    f = inst_f[k]
    d0, d1, d2 = p0 - f[9], p1 - f[10], p2 - f[11]
    s = f[12]
    # q = R^T d / s
    R[0, 0] = (f[0] * d0 + f[3] * d1 + f[6] * d2) / s
    R[1, 0] = (f[1] * d0 + f[4] * d1 + f[7] * d2) / s
    R[2, 0] = (f[2] * d0 + f[5] * d1 + f[8] * d2) / s
    t = _cell_tape(inst_i[k, 0], R[0, 0], R[1, 0], R[2, 0], tape_i, tape_f, cell_tab)
    run_lanes(code, imm, tape_i[t, 0], tape_i[t, 1], R, 1)
    return s * R[tape_i[t, 2], 0]


@njit(**_OPTS)
def nearest(pts, below, stop, want_grad, inst_f, inst_i, code, imm, tape_i, tape_f,
            cell_tab, node_f, node_i, order, inst_box, ent_range, max_regs, dist, grad,
            inst, exact, part, n_parts):
    """For points ``pts`` ``(N, 3)`` (the ``part``-th of ``n_parts`` slices): the
    smallest entry value ``dist`` ``(N,)``, its entry ``inst`` ``(N,)`` (-1: no
    entry holds a value below the start), its world gradient ``grad`` ``(N, 3)``
    (with ``want_grad``) and whether the value is the exact distance ``exact`` ``(N,)``
    (the winner is exact and no instance of contract 'neither' could be nearer).

    ``below`` ``(N,)``: the search starts with this value as the best (inf for a plain
    nearest query; a sphere's radius for a collision test: only instances nearer than it
    are evaluated). ``stop``: end a point's search at the first value below ``below``
    (a collision test). Points with a NaN coordinate get NaN and -1.
    """
    # the search is written out here, not called: a call per point passing these arrays
    # made the kernel 5x slower (3 against 17 us for 100 spheres, measured)
    N = pts.shape[0]
    R = np.empty((max(max_regs, 3), 1))
    stack = np.empty(STACK, np.int64)
    sdist = np.empty(STACK)
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
        stack[0] = 0
        sdist[0] = _box_distance(p0, p1, p2, node_f[0], 0)
        top = 1
        done = False
        while top > 0 and not done:
            top -= 1
            node = stack[top]
            bd = sdist[top]  # the node's box distance, found when it was pushed
            if bd > 0.0 and bd >= best:
                continue
            c0 = node_i[node, 0]
            c1 = node_i[node, 1]
            if c0 < 0:  # a leaf: its instances, each with its entries (parts)
                first = -1 - c0
                for j in range(first, first + c1):
                    k = order[j]
                    e0 = ent_range[k, 0]
                    e1 = e0 + ent_range[k, 1]
                    if e1 - e0 > 1:
                        bk = _box_distance(p0, p1, p2, inst_box[k], 0)
                        if bk > 0.0 and bk >= best:
                            continue
                    for e in range(e0, e1):
                        bk = _box_distance(p0, p1, p2, inst_f[e], 13)
                        if bk > 0.0 and bk >= best:
                            continue
                        v = _eval_instance(e, p0, p1, p2, inst_f, inst_i, code, imm,
                                           tape_i, tape_f, cell_tab, R)
                        if inst_i[e, 1] == 2 and bk < nmin:
                            nmin = bk
                        if v < best:
                            best = v
                            win = e
                            if stop:
                                done = True
                                break
                    if done:
                        break
            else:
                # the nearer child is searched first
                d0 = _box_distance(p0, p1, p2, node_f[c0], 0)
                d1 = _box_distance(p0, p1, p2, node_f[c1], 0)
                if top + 2 > STACK:  # pragma: no cover - a balanced tree is shallow
                    raise RuntimeError("BVH too deep")
                if d0 <= d1:
                    stack[top] = c1
                    sdist[top] = d1
                    stack[top + 1] = c0
                    sdist[top + 1] = d0
                else:
                    stack[top] = c0
                    sdist[top] = d0
                    stack[top + 1] = c1
                    sdist[top + 1] = d1
                top += 2
        dist[i] = best
        inst[i] = win
        if win >= 0:
            exact[i] = inst_i[win, 1] == 0 and not (nmin < best)
        else:
            exact[i] = False
        if want_grad:
            grad[i, 0] = 0.0
            grad[i, 1] = 0.0
            grad[i, 2] = 0.0
    if want_grad:
        _winner_gradients(pts, inst, a, b, inst_f, inst_i, code, imm, tape_i, tape_f,
                          cell_tab, max_regs, grad)


#: lanes of one gradient pass over points that share a winning tape
GRAD_LANES = 32


@njit(**_OPTS)
def _winner_gradients(pts, inst, a, b, inst_f, inst_i, code, imm, tape_i, tape_f,
                      cell_tab, max_regs, grad):
    """World gradients ``grad[i]`` of the winning instance ``inst[i]`` at points ``a <= i
    < b`` (left as they are where ``inst[i] < 0``). Points are grouped by the tape they
    run (the winner's, or its cell's) and each group runs the forward-mode tape on up
    to ``GRAD_LANES`` lanes at once: the interpreter's cost is per instruction, so one
    pass for many points costs little more than for one (the tangents of each lane are
    the same arithmetic as on a lane of its own)."""
    m = b - a
    tp = np.full(m, -1, np.int64)
    q = np.empty((m, 3))
    for i in range(a, b):
        k = inst[i]
        if k < 0:
            continue
        f = inst_f[k]
        d0, d1, d2 = pts[i, 0] - f[9], pts[i, 1] - f[10], pts[i, 2] - f[11]
        s = f[12]
        q0 = (f[0] * d0 + f[3] * d1 + f[6] * d2) / s
        q1 = (f[1] * d0 + f[4] * d1 + f[7] * d2) / s
        q2 = (f[2] * d0 + f[5] * d1 + f[8] * d2) / s
        q[i - a, 0] = q0
        q[i - a, 1] = q1
        q[i - a, 2] = q2
        tp[i - a] = _cell_tape(inst_i[k, 0], q0, q1, q2, tape_i, tape_f, cell_tab)
    order = np.argsort(tp, kind="mergesort")
    L = GRAD_LANES
    R = np.empty((max(max_regs, 3), L))
    D = np.empty((max(max_regs, 3), 3, L))
    tmp = np.empty((1, L))
    lanes = np.empty(L, np.int64)
    j = 0
    while j < m and tp[order[j]] < 0:
        j += 1
    while j < m:
        t = tp[order[j]]
        B = 0
        while j < m and B < L and tp[order[j]] == t:
            r = order[j]
            lanes[B] = r
            R[0, B] = q[r, 0]
            R[1, B] = q[r, 1]
            R[2, B] = q[r, 2]
            B += 1
            j += 1
        for r in range(3):
            for c in range(3):
                for u in range(B):
                    D[r, c, u] = 1.0 if r == c else 0.0
        run_lanes_grad(code, imm, tape_i[t, 0], tape_i[t, 1], R, D, tmp, B)
        o = tape_i[t, 2]
        for u in range(B):
            i = a + lanes[u]
            f = inst_f[inst[i]]
            x, y, z = D[o, 0, u], D[o, 1, u], D[o, 2, u]
            grad[i, 0] = f[0] * x + f[1] * y + f[2] * z
            grad[i, 1] = f[3] * x + f[4] * y + f[5] * z
            grad[i, 2] = f[6] * x + f[7] * y + f[8] * z
