"""The stages of ``solver='lm'`` (the default engine of :func:`csdf.fit`), which run the
Levenberg-Marquardt iteration of :mod:`.lm`.

Coarse to fine with a graduated residual scale: the first iterations run on a fixed
subsample of the cloud with the loss's residual scale ``f_scale`` widened (8x, then 4x,
2x, 1x); a wide scale turns the robust cost into a smooth, nearly quadratic bowl whose
basin reaches much larger initial errors, and narrowing it then rejects outliers. Then
the escape step, and the last iterations use every point and the requested ``f_scale``.

Scale and size parameters: if the estimated parameters can resize the whole shape (a
sphere's radius; a chair whose every dimension is a parameter), ``s`` and the parameters
describe the same change and the problem is singular or nearly so. This is measured at
the start of the joint stage (:func:`scale_ambiguity`: the sine of the angle between the
Jacobian column of ``log s`` and the span of the parameters' columns); below
``AMBIGUITY_SIN`` the scale is held at its start (1 unless ``init`` gives one) and the
parameters absorb the size; the reason is listed in :attr:`csdf.FitResult.notes`.
Otherwise both are estimated. The joint stage ends with the noise-bias correction
(:mod:`.bias`).
"""

from __future__ import annotations

import math

import numpy as np

from .bias import BOUND_SLACK, correct_noise_bias
from .lm import State, Visibility, evaluate, lm_rounds, lm_solve
from .lm import escape as lm_escape
from .problem import Problem, merge_values

__all__ = ["solve_lm", "refine", "scale_ambiguity", "AMBIGUITY_SIN", "GRADUATION",
           "N_COARSE", "SMALL_START"]

#: the graduated residual scales of the coarse stage (multiples of f_scale)
GRADUATION = (8.0, 4.0, 2.0, 1.0)
#: points in the coarse stage's subsample
N_COARSE = 1500
AMBIGUITY_SIN = 0.25  # scale is fixed when sin(angle(scale column, parameter span)) < this
SMALL_START = 0.1  # the joint stage also tries parameters this far into their ranges


def scale_ambiguity(prob: Problem, P: np.ndarray) -> float:
    """How well the estimated parameters can imitate a change of scale at the current
    state: the sine of the angle between the Jacobian column of ``log s`` and the span of
    the parameters' columns, on points ``P`` (N, 3) (0: a uniform resize is exactly a
    parameter change, so scale and parameters cannot both be identified; 1: independent)."""
    idx = [i for i, q in enumerate(prob.prog.params) if q.name in prob.names]
    st = State(prob.R, prob.t, math.log(prob.s), prob.values[idx])
    pose, scale = prob.pose, prob.scale
    prob.pose, prob.scale = False, True
    try:
        _, Jm = evaluate(prob, P, st, idx, prob.f_scale)
    finally:
        prob.pose, prob.scale = pose, scale
    js, Jc = Jm[:, 0], Jm[:, 1:]
    ns = np.linalg.norm(js)
    if ns == 0 or Jc.shape[1] == 0:
        return 1.0
    coef, *_ = np.linalg.lstsq(Jc, js, rcond=None)
    return float(np.linalg.norm(js - Jc @ coef) / ns)


def _small_start(prob: Problem, P: np.ndarray, st: State, idx: list[int], max_iter: int
                 ) -> tuple[State, int]:
    """The better of two starts for the joint stage, by their cost after a short solve on
    a subsample: the parameters as given, or every parameter near the low end of its range
    (``lo + SMALL_START * span``).

    The residuals measure the distance from each point to the model, not from the model to
    the points: a part made too long (legs below the floor) adds surface where there are
    no points, which costs nothing, while the points beyond a part made too short pull it
    out. Parameters that start too large can therefore stay there; starting small avoids
    that trap."""
    n = len(P)
    sub = P if n <= N_COARSE else P[np.random.default_rng(2).choice(n, N_COARSE, False)]
    lo = np.array([prob.prog.params[i].lo for i in idx])
    hi = np.array([prob.prog.params[i].hi for i in idx])
    span = hi - lo
    finite = np.isfinite(span)  # (an unbounded range: inf - inf is not computed)
    small = st.cvals.copy()
    small[finite] = lo[finite] + SMALL_START * span[finite]
    best, nev = None, 0
    starts = (st.cvals,) if np.array_equal(small, st.cvals) else (st.cvals, small)
    for cvals in starts:  # (an unbounded range has no small start: one solve)
        cand = lm_solve(prob, sub, State(st.R, st.t, st.sigma, cvals), idx, prob.f_scale,
                        max(10, max_iter // 4))
        nev += cand[2]
        if best is None or cand[1] < best[1]:
            best = cand
    return best[0], nev


def solve_lm(prob: Problem, max_iter: int = 100, viewpoint=None, escape: bool = True,
             correct_bias: bool = False, coarse: bool = True) -> tuple[Problem, dict]:
    """The default engine: coarse-to-fine robust Levenberg-Marquardt (:mod:`.lm`) with
    the fixed loss ``prob.loss``.

    Stages: (1) the pose alone on a fixed subsample of at most ``N_COARSE`` points, with
    the residual scale graduated from ``8 f_scale`` down to ``f_scale`` (``GRADUATION``),
    then the escape step (:func:`csdf.fit.lm.escape`); (2) when only the pose is
    estimated, the pose on all points; otherwise everything jointly on all points (scale
    held if ambiguous, see :func:`scale_ambiguity`; parameters from the better of two
    starts, see :func:`_small_start`), then the noise-bias correction
    (:func:`csdf.fit.bias.correct_noise_bias`). Without ``coarse`` (a start already
    close), stage (1) and the second parameter start are left out: stage (2) runs from
    the start. ``max_iter`` bounds the evaluations of
    each stage; ``viewpoint`` (3,) or None turns on the visibility term. Runs in place;
    returns ``(prob, stats)`` with ``stats`` keys ``nfev``, ``converged``, ``cost``,
    ``notes``, ``loss`` and ``scale_held``. (``loss='auto'`` is
    :func:`csdf.fit.api.auto_continue` after this.)"""
    P = prob.points
    n = len(P)
    radius = 0.5 * prob.size * prob.s * 1.05
    vis = None if viewpoint is None else Visibility(np.asarray(viewpoint, dtype=float),
                                                    radius)
    idx = [i for i, q in enumerate(prob.prog.params) if q.name in prob.names]
    st = State(prob.R, prob.t, math.log(prob.s), prob.values[idx])
    nev, cost, converged = 0, math.nan, False
    notes: list[str] = []
    held = False
    if not coarse:
        if prob.pose and not (prob.scale or prob.names):  # the pose alone, on all points
            st, cost, k, converged = lm_rounds(prob, P, st, [], max_iter, vis)
            nev += k
    elif prob.pose:
        scale, names = prob.scale, prob.names
        prob.scale, prob.names = False, []
        st0 = State(st.R, st.t, st.sigma, np.zeros(0))
        sub = P if n <= N_COARSE else P[np.random.default_rng(0).choice(n, N_COARSE, False)]
        per = max(3, min(10, max_iter // 4))
        for mult in GRADUATION:
            st0, cost, k, converged = lm_solve(prob, sub, st0, [], prob.f_scale * mult, per,
                                               vis=vis, tol=1e-5)
            nev += k
        if escape:
            st0, _ = lm_escape(prob, sub, st0, prob.f_scale, vis=vis)
        if not (scale or names):  # (otherwise the joint stage refines the pose on all)
            st0, cost, k, converged = lm_rounds(prob, P, st0, [], max_iter, vis)
            nev += k
        prob.scale, prob.names = scale, names
        st = State(st0.R, st0.t, st.sigma, st.cvals)
        prob.R, prob.t = st.R, st.t
    if prob.scale or prob.names:
        if prob.scale and prob.names:
            sub = P if n <= N_COARSE else P[np.random.default_rng(1).choice(n, N_COARSE,
                                                                             False)]
            sin = scale_ambiguity(prob, sub)
            if sin < AMBIGUITY_SIN:
                prob.scale, held = False, True
                notes.append(
                    f"scale held at {prob.s:.6g}: the estimated parameters can imitate a "
                    f"uniform resize (sin of the angle between the scale and parameter "
                    f"Jacobian columns {sin:.3f} < {AMBIGUITY_SIN}): scale and size are "
                    "ambiguous, so the parameters absorb the size")
        if prob.names and prob.pose and coarse:
            st, k = _small_start(prob, P, st, idx, max_iter)
            nev += k
        # with the bias correction, the biased estimate may leave the ranges a little
        # (a true value near a bound); the corrected one is clipped to them
        st, cost, k, converged = lm_rounds(prob, P, st, idx, max_iter, vis,
                                           slack=BOUND_SLACK if correct_bias else 0.0)
        nev += k
        if correct_bias:
            st, k = correct_noise_bias(prob, st, idx)
            nev += k
        prob.scale = "scale" in prob.estimate
    _store(prob, st, idx)
    return prob, {"nfev": nev, "converged": converged, "cost": cost, "notes": notes,
                  "loss": prob.loss, "scale_held": held}


def _store(prob: Problem, st: State, idx: list[int]) -> None:
    """Write state ``st`` back into ``prob`` (rotation re-orthonormalised)."""
    prob.R, prob.t, prob.s = st.R, np.asarray(st.t, dtype=float), math.exp(st.sigma)
    prob.values = merge_values(prob, idx, st.cvals)
    U, _, Vt = np.linalg.svd(prob.R)
    prob.R = U @ Vt


def refine(prob: Problem, max_iter: int, viewpoint, correct_bias: bool,
           held: bool) -> tuple[Problem, dict]:
    """Refine every estimated unknown from ``prob``'s state on all points with
    ``prob.loss`` (no coarse stage, no escape; the scale held if ``held``), then the
    noise-bias correction if asked. In place; returns ``(prob, stats)`` like
    :func:`solve_lm` (without ``scale_held``)."""
    vis = None if viewpoint is None else Visibility(
        np.asarray(viewpoint, dtype=float), 0.5 * prob.size * prob.s * 1.05)
    idx = [i for i, q in enumerate(prob.prog.params) if q.name in prob.names]
    st = State(prob.R, prob.t, math.log(prob.s), prob.values[idx])
    joint = bool(prob.scale or prob.names)
    if held:
        prob.scale = False
    st, cost, nev, converged = lm_rounds(prob, prob.points, st, idx, max_iter, vis,
                                         slack=BOUND_SLACK if joint and correct_bias
                                         else 0.0)
    if joint and correct_bias:
        st, k = correct_noise_bias(prob, st, idx)
        nev += k
    prob.scale = "scale" in prob.estimate
    _store(prob, st, idx)
    return prob, {"nfev": nev, "converged": converged, "cost": cost, "notes": [],
                  "loss": prob.loss}
