"""Noise-bias correction of the scale and shape parameters estimated by ``solver='lm'``
(:func:`csdf.fit` with ``debias=True``, the default when ``'params'`` is estimated).

A parametric bootstrap: the fitted surface is re-scanned with simulated noise of the
residuals' size, refitted with :func:`.lm.lm_solve`, and the change of the estimates is
subtracted (see :func:`correct_noise_bias`).
"""

from __future__ import annotations

import math

import numpy as np

from .lm import State, lm_solve
from .problem import Problem, merge_values

__all__ = ["correct_noise_bias", "BIAS_COPIES", "BIAS_ROUNDS", "BOUND_SLACK"]

BIAS_COPIES = 2  # noisy copies of the projected cloud in the bias simulation
BIAS_ROUNDS = 2  # iterations of the bootstrap bias correction
BOUND_SLACK = 0.1  # parameter ranges widened by this fraction before the bias correction


def correct_noise_bias(prob: Problem, st: State, idx: list[int], max_iter: int = 50
                       ) -> tuple[State, int]:
    """Parametric-bootstrap correction of the noise bias of scale and shape parameters.

    Noise makes a signed-distance fit biased at curved and thin features: the distance
    of a convex shape is a convex function, so noisy points look outside on average
    (Jensen) and the fitted part grows (thin legs fattest: the bias grows like
    ``sigma^2 * curvature``). Estimate: the inliers are projected onto the fitted surface,
    Gaussian noise of the residuals' RMS is added (seeded), the same problem is solved
    again from the fitted state (``BIAS_COPIES`` noisy copies of the cloud, which lowers
    the variance the correction adds), and the change of ``log s`` and of the parameters
    is the bias at that noise (the pose is solved with them but kept); it is scaled by
    the squared ratio of the real to the simulated RMS (the RMS of signed distances
    underestimates the noise near edges, and the bias goes with ``sigma^2``) and
    subtracted. Returns the corrected state and the number of evaluations. No effect on
    noiseless data."""
    s = math.exp(st.sigma)
    pv = dict(zip(prob.pnames, merge_values(prob, idx, st.cvals)))
    q = ((prob.points - st.t) @ st.R) / s
    f = np.asarray(prob.prog(q, pv, backend=prob.backend, check_ranges=False))
    inl = np.abs(s * f) <= 3.0 * prob.f_scale
    if inl.sum() < 10:
        return st, 0
    rms = float(np.sqrt(np.mean((s * f[inl]) ** 2)))
    if not rms > 1e-9 * prob.size * s:
        return st, 0
    lo = np.array([prob.prog.params[i].lo for i in idx])
    hi = np.array([prob.prog.params[i].hi for i in idx])
    P_in = prob.points[inl]
    cur, k, nev = st, None, 0
    for _ in range(BIAS_ROUNDS):
        sim = _simulate(prob, P_in, cur, idx, rms)
        if sim is None:
            return st, nev
        # the pose is solved too (a seat height's bias comes with a shift along the legs)
        # but only the scale and parameters are corrected
        st_sim, _, n_ev, _ = lm_solve(prob, sim, cur, idx, prob.f_scale, max_iter,
                                      slack=BOUND_SLACK)
        nev += n_ev
        if k is None:
            s2 = math.exp(st_sim.sigma)
            pv2 = dict(zip(prob.pnames, merge_values(prob, idx, st_sim.cvals)))
            rs = s2 * np.asarray(prob.prog(((sim - st_sim.t) @ st_sim.R) / s2, pv2,
                                           backend=prob.backend, check_ranges=False))
            rs = rs[np.abs(rs) <= 3.0 * prob.f_scale]
            rms_sim = float(np.sqrt(np.mean(rs ** 2))) if len(rs) else rms
            k = (rms / rms_sim) ** 2 if rms_sim > 0 else 1.0
        # iterated bootstrap: the bias is re-evaluated at the corrected values
        cvals = np.clip(st.cvals - k * (st_sim.cvals - cur.cvals), lo, hi) if idx \
            else st.cvals
        sigma = st.sigma - k * (st_sim.sigma - cur.sigma) if prob.scale else st.sigma
        cur = State(st.R, st.t, sigma, cvals)
    return cur, nev


def _simulate(prob: Problem, P: np.ndarray, st: State, idx: list[int], rms: float):
    """Scene points ``P`` (N, 3) projected onto the surface of state ``st`` (Newton steps
    in the model frame) with Gaussian noise of ``rms`` (scene units) added, in
    ``BIAS_COPIES`` seeded copies; None if too few project."""
    s = math.exp(st.sigma)
    pv = dict(zip(prob.pnames, merge_values(prob, idx, st.cvals)))
    y = ((P - st.t) @ st.R) / s
    for _ in range(4):
        fy, gy = prob.prog.value_and_grad(y, pv, backend=prob.backend, check_ranges=False)
        gy = np.asarray(gy)
        y = y - (np.asarray(fy) / np.maximum(np.sum(gy * gy, axis=1), 1e-30))[:, None] * gy
    fy = np.asarray(prob.prog(y, pv, backend=prob.backend, check_ranges=False))
    y = y[np.abs(fy) < 1e-3 * rms / s]
    if len(y) < 10:
        return None
    rng = np.random.default_rng(20261122)
    y = np.concatenate([y] * BIAS_COPIES)  # more copies: less variance in the estimate
    return s * (y + rng.normal(0.0, rms / s, y.shape)) @ st.R.T + st.t
