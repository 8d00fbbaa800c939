"""Global initialisation for :func:`csdf.fit` with ``multistart=True``.

Hypotheses: the cloud's principal axes aligned with the model's (all sign and order
choices), composed with the 24 rotations of the cube group, plus rotations spread evenly
over SO(3); each places the model's centroid on the cloud's centroid. Each hypothesis gets
a few cheap robust Gauss-Newton steps on a fixed random subsample of the cloud (seeded);
the best robust cost wins and is refined on all points by the caller.
"""

from __future__ import annotations

import math

import numpy as np

from ..seeds import rng_arg
from .lie import cube_rotations, exp_so3, sphere_rotations
from .lm import normal_equations
from .problem import jacobian

__all__ = ["multistart", "model_points"]


def model_points(prob, n: int = 2000) -> np.ndarray:
    """Points on the model's surface in its frame (a coarse mesh's vertices)."""
    from ..field import as_field
    from ..mesh.api import mesh

    pv = dict(zip((p.name for p in prob.prog.params), prob.values))
    b = np.array([prob.centre - prob.size / 2, prob.centre + prob.size / 2])
    # the fit's own values (a held one as given): accepted, not range-checked again
    fld = as_field(prob.prog, pv, what="multistart", check_ranges=False)
    m = mesh(fld, resolution=32, bounds=b, progress=False, check_thin=False)
    V = np.asarray(m.vertices)
    if len(V) > n:
        V = V[np.random.default_rng(0).choice(len(V), n, replace=False)]
    return V


def _frame(P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    c = P.mean(axis=0)
    _, _, Vt = np.linalg.svd(P - c, full_matrices=False)
    E = Vt.T
    if np.linalg.det(E) < 0:
        E[:, 2] *= -1
    return c, E


def _gn_pose(prob, P, R, t, s, iters: int, fs: float):
    """A few robust (Huber-weighted) Gauss-Newton steps on the pose; returns R, t, cost."""
    pv = dict(zip((p.name for p in prob.prog.params), prob.values))
    cost = math.inf
    for _ in range(iters + 1):
        a = P - t
        q = (a @ R) / s
        f, g = prob.prog.value_and_grad(q, pv, backend=prob.backend, check_ranges=False)
        r = s * f
        ar = np.abs(r)
        cost = float(np.sum(np.where(ar <= fs, 0.5 * r * r, fs * (ar - 0.5 * fs))))
        if _ == iters:
            break
        wgt = np.where(ar <= fs, 1.0, fs / np.maximum(ar, 1e-300))
        J = jacobian(True, False, s, a, f, np.asarray(g) @ R.T, None)
        A, b = normal_equations(J, wgt, r)
        try:
            d = -np.linalg.solve(A + 1e-6 * np.trace(A) / 6 * np.eye(6), b)
        except np.linalg.LinAlgError:
            break
        R = exp_so3(d[:3]) @ R
        t = t + d[3:]
    return R, t, cost


def multistart(prob, seed=None, n_sub: int = 400, iters: int = 6, n_sphere: int = 72) -> None:
    """Replace ``prob``'s starting pose by the best of many hypotheses (in place)."""
    rng = rng_arg(seed)
    P = prob.points
    sub = P if len(P) <= n_sub else P[rng.choice(len(P), n_sub, replace=False)]
    s = prob.s
    cp, Ep = _frame(P)
    M = model_points(prob)
    cm, Em = _frame(M)
    cands = [Ep @ C @ Em.T for C in cube_rotations()]
    cands += list(sphere_rotations(n_sphere))
    fs = max(prob.f_scale, 0.02 * prob.size * s)  # a wide basin for the coarse search
    best = (math.inf, prob.R, prob.t)
    for R in cands:
        t = cp - s * R @ cm
        R2, t2, c = _gn_pose(prob, sub, R, t, s, iters, fs)
        if c < best[0]:
            best = (c, R2, t2)
    prob.R, prob.t = best[1], best[2]
