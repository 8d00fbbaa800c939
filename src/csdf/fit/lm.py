"""The hand-written robust Levenberg-Marquardt of :func:`csdf.fit` (``solver='lm'``, the
default): the iteration (:func:`lm_solve`), the visibility term and the escape step. The
stages that run it (coarse to fine, joint, bias correction) are in :mod:`.stages`.

Each iteration evaluates the model's values, spatial gradients (and parameter derivatives
when shape parameters are estimated) at all points in one call of the problem's
evaluator, forms the Jacobian of the residuals ``r = s f(R^T (p - t) / s; c)`` (see
:mod:`.problem`), and solves the small normal equations ``(J^T W J + lambda D) dx = -J^T
W r`` with iteratively reweighted least-squares weights ``W`` of the robust loss
(``rho'(z)``, SciPy's loss conventions). No dense ``N x n`` factorisation, no finite
differences: the cost of an iteration is one evaluation plus an ``N x n`` product (``n``
= 6 for a pose).

Visibility (``viewpoint=``): a point seen by a sensor at ``c`` is the *first* surface
along its ray. A point whose nearest model surface faces away from ``c`` (it is explained
by a back face the sensor cannot see, the typical wrong minimum for thin parts) is
instead matched to the first hit of its ray on the posed model (sphere tracing from
``c``), with a point-to-plane residual at that hit; rays that miss the model keep the
signed-distance residual.
"""

from __future__ import annotations

import math

import numpy as np

from .lie import exp_so3, hat
from .problem import jacobian, loss_rho, loss_weights

__all__ = ["State", "Visibility", "linearise", "evaluate", "normal_equations", "damped_step",
           "lm_solve",
           "lm_rounds", "escape", "axis_turns"]

#: points on which escape() refines its turns (ranked on half as many)
N_RANK = 1000
#: escape() refines a turn only if its unrefined cost is below this times the current one
PROMISING = 2.0
#: residual scale (x f_scale) at which escape() ranks its turns
RANK_SCALE = 2.0


def _normal_equations_np(J: np.ndarray, w: np.ndarray, r: np.ndarray):
    Jw = J * w[:, None]
    return Jw.T @ J, Jw.T @ r


try:  # a compiled loop: multi-threaded BLAS on these thin products is slow when cores
    # are shared, and a single pass over J is all that is needed
    from numba import njit

    @njit(cache=True, fastmath=False)
    def _normal_equations_nb(J, w, r):  # pragma: no cover - compiled
        N, n = J.shape
        A = np.zeros((n, n))
        b = np.zeros(n)
        for k in range(N):
            wk = w[k]
            for i in range(n):
                ji = J[k, i] * wk
                b[i] += ji * r[k]
                for j in range(i + 1):
                    A[i, j] += ji * J[k, j]
        for i in range(n):
            for j in range(i):
                A[j, i] = A[i, j]
        return A, b

    @njit(cache=True, fastmath=False)
    def _pose_equations_nb(a, gw, X, w, r):  # pragma: no cover - compiled
        # the rows of jacobian(pose=True, ...) formed one at a time, each summed as
        # _normal_equations_nb sums them (the same products in the same order)
        N = r.shape[0]
        m = X.shape[1]
        n = 6 + m
        A = np.zeros((n, n))
        b = np.zeros(n)
        row = np.empty(n)
        for k in range(N):
            u0, u1, u2 = gw[k, 0], gw[k, 1], gw[k, 2]
            v0, v1, v2 = a[k, 0], a[k, 1], a[k, 2]
            row[0] = u1 * v2 - u2 * v1
            row[1] = u2 * v0 - u0 * v2
            row[2] = u0 * v1 - u1 * v0
            row[3] = -u0
            row[4] = -u1
            row[5] = -u2
            for c in range(m):
                row[6 + c] = X[k, c]
            wk = w[k]
            for i in range(n):
                ji = row[i] * wk
                b[i] += ji * r[k]
                for j in range(i + 1):
                    A[i, j] += ji * row[j]
        for i in range(n):
            for j in range(i):
                A[j, i] = A[i, j]
        return A, b
except ImportError:  # pragma: no cover
    _normal_equations_nb = None
    _pose_equations_nb = None


def normal_equations(J: np.ndarray, w: np.ndarray, r: np.ndarray):
    """``(J^T W J, J^T W r)`` for a Jacobian ``J`` (N, n), weights ``w`` (N,) and
    residuals ``r`` (N,)."""
    if _normal_equations_nb is not None:
        return _normal_equations_nb(np.ascontiguousarray(J), np.ascontiguousarray(w),
                                    np.ascontiguousarray(r))
    return _normal_equations_np(J, w, r)


class State:
    """The unknowns of an LM solve: rotation ``R`` (3, 3), translation ``t`` (3,) (scene
    units), log-scale ``sigma`` and the estimated parameter values ``cvals`` (k,)."""

    def __init__(self, R, t, sigma, cvals):
        self.R, self.t, self.sigma, self.cvals = R, t, sigma, cvals

    def step(self, dx: np.ndarray, pose: bool, scale: bool, lo, hi) -> State:
        """The state moved by ``dx`` (rotation increment applied on the left, then
        translation, log-scale, parameters; only the estimated ones present), the
        parameters clipped to ``[lo, hi]`` (k,)."""
        k = 0
        R, t, sigma = self.R, self.t, self.sigma
        if pose:
            R = exp_so3(dx[0:3]) @ R
            t = t + dx[3:6]
            k = 6
        if scale:
            sigma = sigma + dx[k]
            k += 1
        c = np.clip(self.cvals + dx[k:], lo, hi) if len(self.cvals) else self.cvals
        return State(R, t, sigma, c)


def _raycast(values_at, c_m: np.ndarray, D_m: np.ndarray, centre: np.ndarray,
             radius: float, tol: float, steps: int = 32) -> tuple[np.ndarray, np.ndarray]:
    """First hits of rays ``c_m + u D_m`` (model frame, ``D_m`` unit (M, 3)) on the zero set
    of the field ``values_at(x (K, 3)) -> (K,)`` by sphere tracing from the entry of the
    bounding sphere; returns the hit distances ``u`` (M,) and a mask of rays that hit."""
    oc = c_m - centre
    bproj = D_m @ oc
    disc = bproj * bproj - (oc @ oc - radius * radius)
    ok = disc > 0
    u = np.where(ok, np.maximum(-bproj - np.sqrt(np.where(ok, disc, 0.0)), 0.0), 0.0)
    hit = np.zeros(len(u), dtype=bool)
    u_far = np.where(ok, -bproj + np.sqrt(np.where(ok, disc, 0.0)), 0.0)
    active = ok.copy()
    for _ in range(steps):
        idx = np.flatnonzero(active)
        if len(idx) == 0:
            break
        x = c_m + u[idx, None] * D_m[idx]
        f = values_at(x)
        done = f < tol
        hit[idx[done]] = True
        u[idx[~done]] += 0.9 * f[~done]
        active[idx[done]] = False
        active &= u < u_far
    return u, hit


class Visibility:
    """The sensor position (3,) and the bounding radius of the posed model (scene units),
    with the ray matches of the current :func:`lm_solve` call: indices of the points
    re-matched to the first hit of their ray, and those hits in the model frame. The
    matches are made at the first evaluation of a call and held during it (so that the
    cost the LM compares is one function), like ICP's correspondences."""

    def __init__(self, viewpoint: np.ndarray, radius: float):
        self.viewpoint = viewpoint
        self.radius = radius
        self.sel: np.ndarray | None = None
        self.X: np.ndarray | None = None

    def reset(self) -> None:
        self.sel = self.X = None

    def match(self, prob, P, st: State, values: np.ndarray, gw: np.ndarray, fs: float
              ) -> None:
        """Find the points whose nearest surface faces away from the sensor (model
        gradients ``gw`` (N, 3) in the scene frame; all parameter values ``values``
        (P,)) and their rays' first hits."""
        s = math.exp(st.sigma)
        d = P - self.viewpoint
        d /= np.maximum(np.linalg.norm(d, axis=1), 1e-300)[:, None]
        back = np.flatnonzero(np.einsum("ij,ij->i", gw, d) > 0)
        self.sel, self.X = back[:0], np.zeros((0, 3))
        if len(back):
            c_m = ((self.viewpoint - st.t) @ st.R) / s
            D_m = d[back] @ st.R
            ev = prob.evaluator("value")
            u, hit = _raycast(lambda x: ev(np.ascontiguousarray(x), values)["value"], c_m,
                              D_m, prob.centre, self.radius / s, 0.05 * fs / s)
            self.sel = back[hit]
            self.X = c_m + u[hit, None] * D_m[hit]


def linearise(prob, P: np.ndarray, st: State, idx):
    """The model at points ``P`` (N, 3) posed by ``st``: ``(s, all parameter values
    (P,), a = P - t (N, 3), values f (N,), world gradients (N, 3), scaled parameter
    derivatives s df/dc (N, k) or None)``."""
    s = math.exp(st.sigma)
    values = prob.values.copy()
    values[idx] = st.cvals
    a = P - st.t
    q = np.ascontiguousarray((a @ st.R) / s, dtype=np.float64)
    if idx:
        res = prob.evaluator("all")(q, values)
        Jp = s * res["jac"][:, idx]
    else:
        res = prob.evaluator("grad")(q, values)
        Jp = None
    return s, values, a, res["value"], res["grad"] @ st.R.T, Jp


def evaluate(prob, P, st: State, idx, fs, vis: Visibility | None = None):
    """Residuals (N,) and Jacobian (N, n) at state ``st``."""
    r, lin = _linearised(prob, P, st, idx, fs, vis)
    return r, jacobian(prob.pose, prob.scale, *lin)


def _system(prob, lin: tuple, w: np.ndarray, r: np.ndarray):
    """``(J^T W J, J^T W r)`` of the Jacobian :func:`jacobian` makes of the
    linearisation ``lin`` (:func:`_linearised`), weights ``w`` (N,) and residuals ``r``
    (N,): what :func:`normal_equations` gives on that Jacobian, to the last bit, without
    forming it when the pose is estimated (its columns are made row by row)."""
    s, a, f, gw, Jp = lin
    if not prob.pose or _pose_equations_nb is None:
        return normal_equations(jacobian(prob.pose, prob.scale, *lin), w, r)
    cols = []
    if prob.scale:
        cols.append(jacobian(False, True, s, a, f, gw, None))
    if Jp is not None and Jp.shape[1]:
        cols.append(Jp)
    X = (np.zeros((len(r), 0)) if not cols else cols[0] if len(cols) == 1
         else np.concatenate(cols, axis=1))
    return _pose_equations_nb(np.ascontiguousarray(a), np.ascontiguousarray(gw),
                              np.ascontiguousarray(X), np.ascontiguousarray(w),
                              np.ascontiguousarray(r))


def _linearised(prob, P, st: State, idx, fs, vis: Visibility | None = None):
    """Residuals (N,) at state ``st`` and the linearisation ``(s, a, f, gw, Jp)`` that
    :func:`jacobian` turns into their Jacobian (back-face matches re-matched by
    ``vis``)."""
    s, values, a, f, gw, Jp = linearise(prob, P, st, idx)
    r = s * f
    if vis is not None:
        if vis.sel is None:
            vis.match(prob, P, st, values, gw, fs)
        sel, X = vis.sel, vis.X
        if len(sel):
            # back-face matches: point-to-plane residual at the ray's first hit instead
            Xc = np.ascontiguousarray(X, dtype=np.float64)
            if idx:
                res = prob.evaluator("all")(Xc, values)
                Jp[sel] = s * res["jac"][:, idx]
            else:
                res = prob.evaluator("grad")(Xc, values)
            fh, gh = res["value"], res["grad"]
            n = gh / np.maximum(np.linalg.norm(gh, axis=1), 1e-300)[:, None]
            nw = n @ st.R.T
            xw = s * X @ st.R.T + st.t
            # (plus the small model value at the hit, whose parameter derivatives move
            # the plane)
            r[sel] = np.einsum("ij,ij->i", nw, P[sel] - xw) + s * np.asarray(fh)
            gw[sel] = nw
            a[sel] = xw - st.t
            f[sel] = 0.0  # the scale column of a point-to-plane residual: -s n . X
    return r, (s, a, f, gw, Jp)


def damped_step(prob, A: np.ndarray, b: np.ndarray, lam: float, st: State, lo, hi,
                max_rotation: float) -> tuple[np.ndarray, State, float]:
    """One Levenberg-Marquardt step: ``(A + lam D) dx = -b`` with ``D`` the diagonal of
    ``A`` (floored), ``lam`` grown tenfold while the system is singular, the rotation
    part capped at ``max_rotation`` (rad); returns ``(dx, the moved state, lam)``."""
    D = np.maximum(A.diagonal(), 1e-12 * max(np.trace(A), 1e-300))
    while True:
        M = A.copy()
        M.flat[::len(A) + 1] += lam * D  # A + lam diag(D)
        try:
            dx = -np.linalg.solve(M, b)
            break
        except np.linalg.LinAlgError:
            lam *= 10.0
    if prob.pose and np.linalg.norm(dx[:3]) > max_rotation:  # keep rotation steps sane
        dx *= max_rotation / np.linalg.norm(dx[:3])
    return dx, st.step(dx, prob.pose, prob.scale, lo, hi), lam


def lm_solve(prob, P: np.ndarray, st: State, idx: list[int], fs: float, max_iter: int,
             prior: float = 0.0, vis: Visibility | None = None, tol: float = 1e-7,
             slack: float = 0.0):
    """Robust LM on points ``P`` (N, 3) from state ``st`` with residual scale ``fs``;
    returns ``(state, cost, evaluations, converged)``. ``prior`` weights a pull of
    ``log s`` towards 0; ``vis`` re-matches back-facing points (matched afresh);
    ``slack`` widens the parameters' ranges by that fraction of their spans."""
    if vis is not None:
        vis.reset()
    lo = np.array([prob.prog.params[i].lo for i in idx])
    hi = np.array([prob.prog.params[i].hi for i in idx])
    span = np.where(np.isfinite(hi - lo), hi - lo, 0.0)
    lo, hi = lo - slack * span, hi + slack * span
    lam = 1e-3
    r, lin = _linearised(prob, P, st, idx, fs, vis)
    cost, w = loss_weights(r, fs, prob.loss)
    kscale = 6 if prob.pose else 0

    def with_prior(cost, sigma):
        return cost + 0.5 * (prior * sigma) ** 2

    cost = with_prior(cost, st.sigma)
    nev = 1
    converged = False
    while nev < max_iter:
        A, b = _system(prob, lin, w, r)
        if prior and prob.scale:
            A[kscale, kscale] += prior * prior
            b[kscale] += prior * prior * st.sigma
        accepted = False
        while nev < max_iter:
            dx, new, lam = damped_step(prob, A, b, lam, st, lo, hi, 1.0)
            r2, lin2 = _linearised(prob, P, new, idx, fs, vis)
            nev += 1
            c2, w2 = loss_weights(r2, fs, prob.loss)
            c2 = with_prior(c2, new.sigma)
            if c2 <= cost:
                pred = -(b @ dx) - 0.5 * dx @ (A @ dx)
                rel = (cost - c2) / max(cost, 1e-300)
                st, r, lin, w = new, r2, lin2, w2
                small = rel < tol or (pred > 0 and cost - c2 < tol * cost)
                cost = c2
                lam = max(lam / 3.0, 1e-9)
                accepted = True
                if small:
                    converged = True
                break
            lam *= 4.0
            if lam > 1e10:
                converged = True
                break
        if converged or not accepted:
            break
    return st, cost, nev, converged


def lm_rounds(prob, P: np.ndarray, st: State, idx: list[int], max_iter: int,
              vis: Visibility | None, slack: float = 0.0):
    """:func:`lm_solve` at ``prob.f_scale`` and ``prob.tol``; with visibility, repeated
    (re-matching the back-facing points each time, like ICP) up to 3 times while the
    cost drops."""
    cost, nev, converged = math.inf, 0, False
    for _ in range(1 if vis is None else 3):
        st, c2, k, converged = lm_solve(prob, P, st, idx, prob.f_scale, max_iter, vis=vis,
                                        slack=slack, tol=prob.tol)
        nev += k
        done = not (c2 < cost * (1 - 1e-4))
        cost = c2
        if done:
            break
    return st, cost, nev, converged


def axis_turns(P: np.ndarray, R: np.ndarray, centre: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    """Turns to test: every 6 degrees about each axis of the model's frame at rotation
    ``R`` (3, 3) through the posed model centre ``centre`` (3,) (parts are usually
    modelled along their axes of near-symmetry), and every 15 degrees about each principal
    axis of the cloud ``P`` (N, 3) through its centroid; identity excluded. Returns the
    rotations (K, 3, 3) and their pivots (K, 3)."""
    c = P.mean(axis=0)
    _, _, Vt = np.linalg.svd(P - c, full_matrices=False)
    fine = np.deg2rad(np.arange(6.0, 360.0 - 1e-9, 6.0))
    coarse = np.deg2rad(np.arange(15.0, 360.0 - 1e-9, 15.0))
    fine_turns = _turns(R.T, fine)
    coarse_turns = _turns(Vt, coarse)
    pivots = np.concatenate([np.repeat(centre[None], len(fine_turns), axis=0),
                             np.repeat(c[None], len(coarse_turns), axis=0)])
    return np.concatenate([fine_turns, coarse_turns]), pivots


def _turns(axes: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """Rotations (len(axes) * len(angles), 3, 3) by each angle (radians) about each unit
    axis (rows of ``axes``), axis-major (Rodrigues, vectorised)."""
    K = np.array([hat(a) for a in axes])  # (A, 3, 3)
    KK = K @ K
    sn, cs = np.sin(angles)[None, :, None, None], np.cos(angles)[None, :, None, None]
    out = np.eye(3) + sn * K[:, None] + (1.0 - cs) * KK[:, None]
    return out.reshape(-1, 3, 3)


def escape(prob, P: np.ndarray, st: State, fs: float, keep: int = 4, iters: int = 8,
           vis: Visibility | None = None) -> tuple[State, bool]:
    """Leave a local minimum of the pose by turns about the model's and the cloud's axes.

    Near-symmetric parts (a flange whose bolt holes are off by one hole spacing, a shaft
    whose arms sit between their true places) have minima that differ by a turn about
    one axis; they are far apart in rotation but cheap to test. Every turn of
    :func:`axis_turns` applied to the converged pose is scored by its robust cost on the
    first ``N_RANK / 2`` points of ``P`` (a random subsample) at ``RANK_SCALE * fs``, all
    in one evaluation; the ``keep`` best, if no worse than ``PROMISING`` times the
    converged pose's cost, get ``iters`` LM evaluations on the first ``N_RANK`` points,
    and the best of those
    replaces ``st`` if its cost is lower than the converged one's. Returns the state and
    whether it changed. Deterministic."""
    s = math.exp(st.sigma)
    pv = dict(zip(prob.pnames, prob.values))
    Q = P[:N_RANK]  # ranking and refinement need fewer points
    base = lm_solve(prob, Q, st, [], fs, iters, vis=vis)
    best_state, best_cost = base[0], base[1]
    Ts, C = axis_turns(P, st.R, s * st.R @ prob.centre + st.t)
    # all turns in one evaluation
    Rs = Ts @ st.R  # (K, 3, 3)
    ts = C + np.einsum("kij,kj->ki", Ts, st.t - C)  # (K, 3): turned about the pivots
    Qr = Q[:N_RANK // 2]
    K, M = len(Ts), len(Qr)
    # q_kp = R_k^T (Q_p - t_k) / s, all at once: Q @ [R_1 .. R_K] minus t_k R_k
    QR = (Qr @ np.transpose(Rs, (1, 0, 2)).reshape(3, 3 * K)).reshape(M, K, 3)
    q = (np.transpose(QR, (1, 0, 2)) - np.einsum("ki,kij->kj", ts, Rs)[:, None]) / s
    f = np.asarray(prob.prog(q.reshape(-1, 3), pv, backend=prob.backend, check_ranges=False))
    z = (s * f.reshape(len(Ts), -1) / (RANK_SCALE * fs)) ** 2
    costs = np.sum(loss_rho(z, prob.loss), axis=1)
    f0 = np.asarray(prob.prog(((Qr - st.t) @ st.R) / s, pv, backend=prob.backend,
                              check_ranges=False))
    c0 = float(np.sum(loss_rho((s * f0 / (RANK_SCALE * fs)) ** 2, prob.loss)))
    changed = False
    for j in np.argsort(costs)[:keep]:
        if costs[j] > PROMISING * c0:
            break  # sorted: the rest are worse
        cand = State(Rs[j], ts[j], st.sigma, st.cvals)
        cand = lm_solve(prob, Q, cand, [], 2.0 * fs, iters // 2, tol=1e-5)[0]
        cand, cost, _, _ = lm_solve(prob, Q, cand, [], fs, iters // 2, vis=vis, tol=1e-5)
        if cost < best_cost * (1.0 - 1e-3):
            best_state, best_cost, changed = cand, cost, True
    return best_state, changed
