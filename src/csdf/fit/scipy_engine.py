"""The SciPy engine of :func:`csdf.fit` (``solver='scipy'``): SciPy's ``least_squares``
(trust region reflective) on the residuals and exact Jacobian of :mod:`.problem`, in
rounds re-centred on the current rotation.

When both scale and parameters are estimated, a weak prior pulls ``log s`` to its start
(the parameters may imitate a uniform resize; ``solver='lm'`` instead measures that and
holds the scale, see :func:`csdf.fit.stages.scale_ambiguity`).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import least_squares

from .lie import exp_so3, left_jacobian
from .problem import Problem, jacobian

__all__ = ["solve_scipy", "solve_scipy_staged"]


class _Residuals:
    """Residuals and exact Jacobian for one linearisation rotation ``R0``."""

    def __init__(self, prob: Problem, R0: np.ndarray, weight_prior: float):
        self.p = prob
        self.R0 = R0
        self.idx = [i for i, p in enumerate(prob.prog.params) if p.name in prob.names]
        self.prior = weight_prior
        self._cache_x = None
        self._cache = None

    def unpack(self, x: np.ndarray):
        p = self.p
        k = 0
        w = np.zeros(3)
        t = p.t
        if p.pose:
            w, t = x[0:3], x[3:6]
            k = 6
        sigma = math.log(p.s)
        if p.scale:
            sigma = x[k]
            k += 1
        values = p.values.copy()
        values[self.idx] = x[k:k + len(self.idx)]
        return w, t, sigma, values

    def pack(self) -> np.ndarray:
        p = self.p
        parts = []
        if p.pose:
            parts += [np.zeros(3), p.t]
        if p.scale:
            parts.append([math.log(p.s)])
        parts.append(p.values[self.idx])
        return np.concatenate([np.ravel(a) for a in parts])

    def _eval(self, x: np.ndarray):
        if self._cache_x is not None and np.array_equal(x, self._cache_x):
            return self._cache
        p = self.p
        w, t, sigma, values = self.unpack(x)
        R = exp_so3(w) @ self.R0
        s = math.exp(sigma)
        a = p.points - t
        q = (a @ R) / s  # rows: R^T a / s
        pv = dict(zip((q_.name for q_ in p.prog.params), values))
        f, g, J = p.prog.value_grad_param_jacobian(q, pv, backend=p.backend, check_ranges=False)
        self._cache_x = x.copy()
        self._cache = (R, s, a, q, f, g, J)
        return self._cache

    def fun(self, x: np.ndarray) -> np.ndarray:
        R, s, a, q, f, g, J = self._eval(x)
        r = s * f
        if self.prior:
            r = np.append(r, self.prior * self.unpack(x)[2])
        return r

    def jac(self, x: np.ndarray) -> np.ndarray:
        p = self.p
        R, s, a, q, f, g, J = self._eval(x)
        w = self.unpack(x)[0]
        Jm = jacobian(p.pose, p.scale, s, a, f, g @ R.T, s * J[:, self.idx] if self.idx
                      else None)
        if p.pose:
            Jm[:, :3] = Jm[:, :3] @ left_jacobian(w)
        if self.prior:
            row = np.zeros((1, Jm.shape[1]))
            row[0, 6 if p.pose else 0] = self.prior
            Jm = np.vstack([Jm, row])
        return Jm

    def x_scale(self, x0: np.ndarray) -> np.ndarray | str:
        """Scale of each unknown: the inverse norm of its Jacobian column at the start
        (like ``x_scale='jac'``), except for unknowns the data hardly sees (the rotation
        of a sphere), which get a typical size instead of a huge scale."""
        typical = self._typical()
        norms = np.linalg.norm(self.jac(x0)[: len(self.p.points)], axis=0)
        ok = norms > 1e-6 * max(norms.max(initial=0.0), 1e-300)
        if ok.all():
            return "jac"  # every unknown is observed: SciPy's adaptive scaling
        return np.where(ok, 1.0 / np.where(ok, norms, 1.0), typical)

    def _typical(self) -> np.ndarray:
        """Typical size of each unknown: radians, the model size, 1 for log-scale, a
        tenth of a parameter's range (or its magnitude)."""
        p = self.p
        sc = []
        if p.pose:
            sc += [1.0] * 3 + [p.size * p.s] * 3
        if p.scale:
            sc.append(1.0)
        for i in self.idx:
            q = p.prog.params[i]
            span = q.hi - q.lo
            sc.append(span / 10 if np.isfinite(span) and span > 0
                      else max(abs(q.default), 0.01 * p.size))
        return np.array(sc)

    def bounds(self):
        p = self.p
        n = (6 if p.pose else 0) + (1 if p.scale else 0)
        lo = [-np.inf] * n + [p.prog.params[i].lo for i in self.idx]
        hi = [np.inf] * n + [p.prog.params[i].hi for i in self.idx]
        return np.array(lo), np.array(hi)


def _ambiguity_notes(res: _Residuals, x: np.ndarray) -> list[str]:
    p = res.p
    if not (p.scale and p.names):
        return []
    Jm = res.jac(x)[: len(p.points)]
    k = 6 if p.pose else 0
    sc = Jm[:, k]
    notes = []
    for j, name in enumerate(p.names):
        col = Jm[:, k + 1 + j]
        den = np.linalg.norm(sc) * np.linalg.norm(col)
        if den > 0 and abs(sc @ col) / den > 0.98:
            notes.append(f"scale and parameter {name!r} are nearly ambiguous (both resize the "
                         "shape); a weak prior keeps the scale near its start")
    return notes


def solve_scipy(prob: Problem, max_iter: int = 100, rounds: int = 4
                ) -> tuple[Problem, dict]:
    """SciPy's ``least_squares`` (trust region reflective, loss ``prob.loss``) on every
    estimated unknown, in up to ``rounds`` rounds of at most ``max_iter`` evaluations,
    each re-centred on the current rotation. In place; returns ``(prob, stats)`` with
    ``stats`` keys ``nfev``, ``converged``, ``cost`` and ``notes``."""
    nfev = 0
    converged = False
    cost = math.nan
    n = len(prob.points)
    prior = 0.05 * prob.f_scale * math.sqrt(n) if (prob.scale and prob.names) else 0.0
    notes: list[str] = []
    for rnd in range(rounds):
        res = _Residuals(prob, prob.R, prior)
        x0 = res.pack()
        lo, hi = res.bounds()
        x0 = np.clip(x0, lo, hi)
        if len(x0) == 0:
            break
        out = least_squares(res.fun, x0, jac=res.jac, bounds=(lo, hi), method="trf",
                            loss=prob.loss, f_scale=prob.f_scale, max_nfev=max_iter,
                            x_scale=res.x_scale(x0))
        nfev += out.nfev
        cost = float(out.cost)
        w, t, sigma, values = res.unpack(out.x)
        prob.R = exp_so3(w) @ prob.R
        prob.t, prob.s, prob.values = np.asarray(t, dtype=float), math.exp(sigma), values
        if rnd == 0:
            notes = _ambiguity_notes(res, out.x)
        converged = out.status > 0
        if np.linalg.norm(w) < 1e-3 or not converged:
            break
    U, _, Vt = np.linalg.svd(prob.R)
    prob.R = U @ Vt
    return prob, {"nfev": nfev, "converged": converged, "cost": cost, "notes": notes}


def solve_scipy_staged(prob: Problem, max_iter: int = 100) -> tuple[Problem, dict]:
    """:func:`solve_scipy` in stages when the pose is estimated with scale or
    parameters: the pose alone first (scale and shape held), then everything jointly;
    starting the joint problem near the right pose keeps scale and size parameters from
    shrinking the model onto a wrong alignment. In place; returns ``(prob, stats)``, the
    evaluations of both stages counted."""
    if prob.pose and (prob.scale or prob.names):
        scale, names = prob.scale, prob.names
        prob.scale, prob.names = False, []
        prob, first = solve_scipy(prob, max_iter=max_iter)
        prob.scale, prob.names = scale, names
    else:
        first = {"nfev": 0}
    prob, stats = solve_scipy(prob, max_iter=max_iter)
    stats["nfev"] += first["nfev"]
    return prob, stats
