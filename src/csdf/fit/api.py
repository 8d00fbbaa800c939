"""The public API of pose, scale and shape recovery: :func:`fit` (paper §4.5, Eq. 12-13)
and the ``loss='auto'`` strategy over both engines (:func:`auto_continue`).

The problem, its residuals ``r(p) = s f(R^T (p - t) / s; c)`` and conventions are in
:mod:`.problem`; the result type in :mod:`.result`.

Engines (``solver=``): ``'lm'`` (default, :mod:`.stages` running :mod:`.lm`): a
hand-written robust Levenberg-Marquardt, coarse to fine with a graduated residual scale,
an escape step for the minima of near-symmetric parts, an optional visibility term for
single-view scans, a scale hold when scale and size parameters are ambiguous, and a
noise-bias correction of shape parameters (:mod:`.bias`); ``'scipy'``
(:mod:`.scipy_engine`): SciPy's ``least_squares`` (trust region reflective), in rounds
re-centred on the current rotation.

Losses (``loss=``): SciPy's robust losses at the residual scale ``f_scale``, and the
default ``'auto'``: Huber first; when the Huber solution leaves more than 1% of the points
farther than ``3 f_scale`` from the surface, Cauchy refines that solution (and, beyond 10%,
also restarts from the same start), and the lowest Cauchy cost wins (:func:`auto_continue`).
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from ..errors import CsdfError
from ..seeds import rng_arg
from .problem import Problem, loss_weights, make_result, prepare, residuals
from .quality import assess
from .result import FitResult
from .scipy_engine import solve_scipy, solve_scipy_staged
from .stages import refine, solve_lm

__all__ = ["fit", "check_fit", "FitResult", "auto_continue", "AUTO_SWITCH", "AUTO_CLEAN",
           "AUTO_INLIER_K"]

#: ``loss='auto'``: Huber first; if the fraction of points with ``|r| <= AUTO_INLIER_K *
#: f_scale`` is below ``AUTO_CLEAN``, Cauchy continues from the Huber solution, and below
#: ``AUTO_SWITCH`` Cauchy also restarts from the start (see :func:`auto_continue`)
AUTO_SWITCH = 0.9
AUTO_CLEAN = 0.99
AUTO_INLIER_K = 3.0


def _auto_measure(prob: Problem) -> tuple[int, float]:
    """At ``prob``'s state: the inliers (``|r| <= AUTO_INLIER_K * f_scale``, signed
    distances of all points) and the Cauchy cost at ``f_scale`` of the same residuals."""
    r = residuals(prob, prob.R, prob.t, prob.s, prob.values)
    n_in = int(np.count_nonzero(np.abs(r) <= AUTO_INLIER_K * prob.f_scale))
    return n_in, loss_weights(r, prob.f_scale, "cauchy")[0]


def _snapshot(prob: Problem) -> tuple:
    return prob.R.copy(), np.array(prob.t, dtype=float), prob.s, prob.values.copy()


def auto_continue(prob: Problem, stats: dict, start: tuple, max_iter: int, viewpoint,
                  escape: bool, correct_bias: bool,
                  scipy_solver=None, coarse: bool = True) -> tuple[Problem, dict]:
    """The second half of ``loss='auto'`` (graduated non-convexity), given the finished
    Huber fit in ``prob`` (its statistics ``stats``) and the state it started from,
    ``start = (R, t, s, values)``.

    Count the inliers ``|r| <= AUTO_INLIER_K * f_scale`` of the Huber solution (signed
    distances of all points). If they are at least ``AUTO_CLEAN`` of the cloud, the Huber
    fit is returned unchanged. Otherwise some points are outliers, which pull Huber's
    optimum (their influence never vanishes; a few percent of clutter already biases
    size parameters by centimetres on a chair), and fits with the redescending Cauchy loss
    at the same ``f_scale`` are made: (a) the continuation: every estimated unknown
    refined from the Huber solution on all points; and, when fewer than ``AUTO_SWITCH``
    are inliers, (b) the complete fit (coarse stage, escape, final) with Cauchy from the
    same start as the Huber fit (heavy outliers can lead Huber's coarse stage into a wrong
    basin). Of the Huber solution and these, the one with the lowest Cauchy cost (signed
    distances of all points, ``f_scale``; the cost Cauchy minimises, on the same
    residuals for all) is
    returned; ``prob.loss`` is set to its loss. (The inlier count is no criterion: a
    biased Huber fit still has nearly every true inlier within ``3 f_scale``.)

    ``scipy_solver``: for ``solver='scipy'``, a function ``prob -> (prob, stats)`` used
    for both Cauchy fits instead; ``coarse`` as in :func:`fit` (for the restart).
    Returns ``(prob, stats)``; ``stats['notes']`` says what was done when Cauchy was
    tried."""
    n = len(prob.points)
    n_h, c_h = _auto_measure(prob)
    if n_h >= AUTO_CLEAN * n:
        stats["loss"] = prob.loss = "huber"
        return prob, stats
    held = bool(stats.get("scale_held"))
    cands = [("Huber", _snapshot(prob), stats, c_h)]
    total = stats["nfev"]
    labels = ("continued", "restarted") if n_h < AUTO_SWITCH * n else ("continued",)
    for label in labels:
        prob.loss = "cauchy"
        if label == "restarted":
            prob.R, prob.t, prob.s, prob.values = (start[0], start[1], start[2],
                                                   start[3].copy())
        if scipy_solver is not None:
            prob, st2 = scipy_solver(prob)
        elif label == "continued":
            prob, st2 = refine(prob, max_iter, viewpoint, correct_bias, held)
        else:
            prob, st2 = solve_lm(prob, max_iter, viewpoint, escape, correct_bias, coarse)
        total += st2["nfev"]
        cands.append((label, _snapshot(prob), st2, _auto_measure(prob)[1]))
    # the lowest Cauchy cost; ties go to the Cauchy fits (listed later)
    label, snap, best, c = min(reversed(cands), key=lambda x: x[3])
    prob.R, prob.t, prob.s, prob.values = snap
    prob.loss = "huber" if label == "Huber" else "cauchy"
    out = dict(best)
    out["nfev"], out["loss"] = total, prob.loss
    tried = ", ".join(f"{lab if lab == 'Huber' else 'Cauchy ' + lab} {c / prob.f_scale ** 2:.6g}"
                      for lab, _, _, c in cands)
    out["notes"] = list(stats["notes"]) + [
        f"loss='auto': the Huber fit has {n_h / n:.1%} inliers (|r| <= {AUTO_INLIER_K:g} "
        f"f_scale) < {AUTO_CLEAN:.0%}, so Cauchy was tried at the same f_scale; Cauchy "
        f"cost (x f_scale^2): {tried}: "
        + ("the Huber fit kept" if label == "Huber" else f"Cauchy ({label}) kept")]
    return prob, out


def fit(shape, points, init=None, estimate=("pose",), params=None, loss="auto",
        f_scale=None, multistart=False, seed=None, max_iter=100, inlier_threshold=None,
        backend="auto", viewpoint=None, solver="lm", debias=None,
        escape=True, *, check_ranges: bool = True, coarse: bool = True,
        check_visible: bool = True, tol: float = 1e-7) -> FitResult:
    """Fit a model to a point cloud: pose, optionally scale and shape parameters.

    Args:
        shape: a :class:`csdf.Shape` (or compiled :class:`csdf.Program`).
        points: ``(N, 3)`` scene points (metres, or the model's units).
        init: starting pose: None (identity rotation, centroids aligned), a (4, 4)
            transform ``[[s R, t], [0, 1]]``, a :class:`FitResult`, or a dict with
            ``rotation``, ``translation``, ``scale``, ``params``.
        estimate: any of ``'pose'``, ``'scale'``, ``'params'`` (tuple or comma string).
            With both ``'scale'`` and ``'params'``, scale is held at its start (1 by
            default) when the parameters can imitate a uniform resize (see
            :func:`csdf.fit.stages.scale_ambiguity`; the reason is added to
            ``FitResult.notes``).
        params: names of the parameters to estimate (default: all); others stay at their
            values in ``init`` (or defaults).
        loss: robust loss: ``'auto'`` (default), ``'huber'``, ``'cauchy'``,
            ``'soft_l1'``, ``'arctan'``, ``'linear'`` (SciPy ``least_squares``
            conventions, residual scale ``f_scale``). Huber has a wide basin but its
            optimum is pulled by outliers (their influence never vanishes); Cauchy's is
            not (redescending) but its basin is narrower. ``'auto'`` combines them
            (graduated non-convexity): the whole fit is made with Huber; if fewer than
            ``AUTO_CLEAN`` (99%) of the points are then inliers (``|r| <= 3
            f_scale``), a Cauchy fit at the same ``f_scale`` refines the Huber solution,
            and below ``AUTO_SWITCH`` (90%) another redoes the fit from the same start;
            of the solutions the one with the lowest Cauchy cost (signed distances of
            all points) is returned (see :func:`auto_continue`). On clean clouds it is
            exactly ``'huber'``. :attr:`FitResult.loss` says which loss gave the
            result, and :attr:`FitResult.notes` what ``'auto'`` did when it tried
            Cauchy. With ``multistart`` the search is unchanged and its final fit uses
            this logic (the Cauchy restart starts from the search's result).
        f_scale: residual scale of the loss (scene units); default 1% of the model size.
        multistart: search many initial rotations first (see
            :func:`csdf.fit.init.multistart`); needed for large initial errors.
        seed: seeds the multistart subsampling (results are reproducible).
        max_iter: residual evaluations per stage (refinement round with ``'scipy'``).
        inlier_threshold: ``|r|`` counted as inlier (default ``3 * f_scale``).
        backend: evaluator backend (``'auto'`` uses the compiled one for large clouds).
        viewpoint: ``(3,)`` sensor position in the cloud's frame for a single-view scan
            (the origin for :func:`csdf.scan`'s camera-frame clouds). Points matched to a
            model surface facing away from it are re-matched to the first surface along
            their ray (see :mod:`csdf.fit.lm`): needed for partial views of thin parts.
        solver: ``'lm'`` (hand-written coarse-to-fine robust Levenberg-Marquardt, the
            default) or ``'scipy'`` (``scipy.optimize.least_squares``, trust region
            reflective; no ``viewpoint``).
        debias: correct the noise bias of the estimated scale and parameters (see
            :func:`csdf.fit.bias.correct_noise_bias`; ``'lm'`` only). Default: when ``'params'`` is
            estimated.
        escape: after the coarse stage, test turns about the model's axes and the cloud's
            principal axes for a lower minimum (:func:`csdf.fit.lm.escape`; ``'lm'``
            only): near-symmetric parts have wrong minima one feature spacing away.
        check_ranges: refuse an initial value (``init``'s ``params``) of a parameter
            that is not estimated when it lies outside the parameter's declared range
            (:class:`csdf.ParamError` naming the range); False fits with it anyway.
            Estimated parameters never leave their ranges: their initial values are
            clipped to them, as are the solvers' steps.
        coarse: run the coarse stage (``'lm'`` only; see :mod:`csdf.fit.stages`). False
            when the start is already close (a detection's hypothesis, the previous
            frame): every estimated unknown is refined jointly on all points from the
            start at once (no subsampled pose stage, no escape step, no second
            parameter start; the scale is still held when ambiguous), a few
            evaluations instead of dozens; ``multistart`` still runs first when
            asked.
        check_visible: with a ``viewpoint``, make the success test's visible-surface
            part (the model ray-cast from the viewpoint: a sixth of the time of
            ``csdf.detect``'s short fits). False leaves it out, as without a viewpoint
            (``quality['visible_checked']`` False, ``visible_note`` saying so): for
            callers that judge the fit otherwise (:func:`check_fit` on other points).
            The fit itself still uses the viewpoint.
        tol: the last stage (``'lm'``) stops when an accepted step lowers the robust cost
            by less than this fraction of it (default ``1e-7``; in ``(0, 1)``). A
            caller refining close starts many times can stop sooner:
            :func:`csdf.detect_primitives` uses ``1e-4`` (its errors on its benchmark
            unchanged, a tenth fewer evaluations).

    Returns:
        :class:`FitResult`. Its ``success`` says whether the fit explains the cloud
        (inliers, residual against ``f_scale``, and with ``viewpoint`` the model's
        visible surface; :mod:`csdf.fit.quality`, a few percent of the fit's time), with
        the figures and reasons in ``quality``; ``converged`` only says how the
        optimiser stopped. :func:`check_fit` judges a result against a viewpoint the fit
        did not use.

    Raises:
        CsdfError: empty cloud, NaNs, bad options, fewer points than unknowns;
        ParamError: unknown parameter names, a held value outside its range (with
            ``check_ranges``).
    """
    t0 = time.perf_counter()
    if solver not in ("lm", "scipy"):
        raise CsdfError(f"solver must be 'lm' or 'scipy'; got {solver!r}")
    if multistart:
        rng_arg(seed)  # checked before any work
    try:
        tol = float(tol)
    except (TypeError, ValueError):
        raise CsdfError(f"tol must be a number in (0, 1); got {tol!r}") from None
    if not 0.0 < tol < 1.0:
        raise CsdfError(f"tol must be in (0, 1); got {tol}")
    prob = prepare(shape, points, init, estimate, params, loss, f_scale, backend,
                   check_ranges=check_ranges)
    prob.tol = tol
    auto = prob.loss == "auto"
    if auto:
        prob.loss = "huber"  # first; auto_continue may switch to 'cauchy'
    if viewpoint is not None:
        vp = np.asarray(viewpoint, dtype=float)
        if vp.shape != (3,) or not np.all(np.isfinite(vp)):
            raise CsdfError(f"viewpoint must be a finite (3,) position; got {viewpoint!r}")
        if solver != "lm":
            raise CsdfError("viewpoint needs solver='lm'")
        viewpoint = vp
    if multistart:
        from .init import multistart as _ms

        _ms(prob, seed=seed)
    if solver == "lm":
        if debias is None:
            debias = bool(prob.names)
        start = (prob.R, prob.t, prob.s, prob.values.copy())
        prob, stats = solve_lm(prob, max_iter=max_iter, viewpoint=viewpoint,
                               escape=bool(escape), correct_bias=bool(debias),
                               coarse=bool(coarse))
        if auto:
            prob, stats = auto_continue(prob, stats, start, max_iter, viewpoint,
                                        bool(escape), bool(debias), coarse=bool(coarse))
        return make_result(prob, stats, time.perf_counter() - t0, "csdf", inlier_threshold,
                           viewpoint, check_visible=check_visible)
    start = (prob.R, prob.t, prob.s, prob.values.copy())
    prob, stats = solve_scipy_staged(prob, max_iter=max_iter)
    if auto:
        def cauchy_scipy(p: Problem) -> tuple[Problem, dict]:
            p, st2 = solve_scipy(p, max_iter=max_iter)
            r = residuals(p, p.R, p.t, p.s, p.values)
            st2["cost"] = loss_weights(r, p.f_scale, "cauchy")[0]
            return p, st2

        prob, stats = auto_continue(prob, stats, start, max_iter, None, False, False,
                                    scipy_solver=cauchy_scipy)
    stats["loss"] = prob.loss
    return make_result(prob, stats, time.perf_counter() - t0, "csdf", inlier_threshold)


def check_fit(shape, points, result: FitResult, viewpoint=None, f_scale=None,
              inlier_threshold=None, backend: str = "auto") -> FitResult:
    """The success test of :attr:`FitResult.success` (:mod:`csdf.fit.quality`) for a
    given result, e.g. with a viewpoint the fit itself did not use (``solver='scipy'``,
    a fit made before the sensor position was known).

    Args:
        shape: the fitted :class:`csdf.Shape` or :class:`csdf.Program`.
        points: ``(N, 3)`` the scene points it was fitted to (scene units).
        result: the :class:`FitResult` (its pose, scale and parameters are judged).
        viewpoint: ``(3,)`` sensor position in the scene frame, or None.
        f_scale: the noise level (default: the result's ``quality['noise_level']``,
            else 1% of the model's size times its scale, as :func:`fit`).
        inlier_threshold: default the result's.
        backend: evaluator backend.

    Returns:
        A copy of ``result`` with ``success`` and ``quality`` replaced.

    Raises:
        CsdfError: as :func:`fit` for bad points or a bad viewpoint.
    """
    if f_scale is None:
        f_scale = result.quality.get("noise_level") if result.quality else None
    # the result's values are the fit's (estimated ones kept inside their ranges)
    prob = prepare(shape, points, init=result, f_scale=f_scale, backend=backend,
                   check_ranges=False)
    vp = None
    if viewpoint is not None:
        vp = np.asarray(viewpoint, dtype=float)
        if vp.shape != (3,) or not np.all(np.isfinite(vp)):
            raise CsdfError(f"viewpoint must be a finite (3,) position; got {viewpoint!r}")
    thr = result.inlier_threshold if inlier_threshold is None else float(inlier_threshold)
    t0 = time.perf_counter()
    r = residuals(prob, prob.R, prob.t, prob.s, prob.values)
    pv = {p.name: float(v) for p, v in zip(prob.prog.params, prob.values)}
    ok, quality = assess(prob.prog, pv, prob.backend, prob.R, prob.t, prob.s, prob.bounds,
                         prob.points, r, thr, prob.f_scale, vp)
    quality["seconds"] = time.perf_counter() - t0
    return dataclasses.replace(result, success=bool(ok), quality=quality)
