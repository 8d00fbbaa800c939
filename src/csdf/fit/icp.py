"""``csdf.icp``: the cloud-to-cloud baseline of the paper's §4.5.

The model's surface is sampled (points uniform by area with exact normals), and the
scene cloud is registered to it by point-to-plane ICP: nearest model points from a SciPy
k-d tree, pairs farther than a trimmed threshold rejected, and the linearised
point-to-plane step solved in closed form. It estimates the pose only (scale 1); the
result is scored with the same exact signed-distance residuals as :func:`csdf.fit`.
"""

from __future__ import annotations

import time

import numpy as np
from scipy.spatial import cKDTree

from .lie import exp_so3
from .problem import make_result, prepare
from .result import FitResult

__all__ = ["icp"]


def _model_samples(prob, n: int, seed) -> tuple[np.ndarray, np.ndarray]:
    import trimesh

    from ..field import as_field
    from ..mesh.api import mesh

    pv = dict(zip((p.name for p in prob.prog.params), prob.values))
    b = np.array([prob.centre - prob.size / 2, prob.centre + prob.size / 2])
    # the fit's own values (a held one as given): accepted, not range-checked again
    fld = as_field(prob.prog, pv, what="icp", check_ranges=False)
    m = mesh(fld, resolution=64, bounds=b, progress=False, check_thin=False)
    pts, _ = trimesh.sample.sample_surface(m, n, seed=seed)
    pts = np.asarray(pts)
    for _ in range(3):  # onto the exact surface
        f, g = prob.prog.value_and_grad(pts, pv, backend=prob.backend, check_ranges=False)
        gg = np.maximum(np.sum(g * g, axis=1), 1e-300)
        pts = pts - (f / gg)[:, None] * g
    _, g = prob.prog.value_and_grad(pts, pv, backend=prob.backend, check_ranges=False)
    nrm = g / np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-300)
    return pts, nrm


def icp(shape, points, init=None, n_model: int = 20000, max_iter: int = 60,
        tol: float = 1e-7, trim: float = 3.0, seed=None, params=None,
        inlier_threshold=None, backend="auto", *, check_ranges: bool = True) -> FitResult:
    """Point-to-plane ICP of the cloud to samples of the model's surface (pose only).

    Args:
        shape, points, init, params, inlier_threshold, backend: as in :func:`csdf.fit`
            (``params`` here are fixed parameter values ``{name: value}``).
        n_model: number of model surface samples.
        max_iter: ICP iterations.
        tol: stop when the pose update (radians + model units) is below this.
        trim: reject pairs farther than ``trim`` times the median pair distance.
        seed: seeds the model sampling.
        check_ranges: refuse a parameter value outside its declared range
            (:class:`csdf.ParamError` naming the range); False uses it anyway.

    Returns:
        :class:`FitResult` with ``method='icp'`` and ``scale = 1``.
    """
    t0 = time.perf_counter()
    init_d = init
    if params:
        init_d = {"params": dict(params)} if init is None else init
    prob = prepare(shape, points, init_d, ("pose",), None, "linear", None, backend,
                   check_ranges=check_ranges)
    M, N = _model_samples(prob, n_model, seed)
    tree = cKDTree(M)
    # work with the inverse transform: scene point p -> model frame q = Ri p + ti
    Ri = prob.R.T
    ti = -Ri @ prob.t
    P = prob.points
    it = 0
    converged = False
    while it < max_iter:
        it += 1
        q = P @ Ri.T + ti
        d, j = tree.query(q, workers=-1)
        keep = d <= trim * max(np.median(d), 1e-12)
        if keep.sum() < 6:
            break
        qk, m, n = q[keep], M[j[keep]], N[j[keep]]
        A = np.concatenate([np.cross(qk, n), n], axis=1)
        b = -np.sum((qk - m) * n, axis=1)
        x, *_ = np.linalg.lstsq(A, b, rcond=None)
        Rd = exp_so3(x[:3])
        Ri = Rd @ Ri
        ti = Rd @ ti + x[3:]
        if np.linalg.norm(x) < tol:
            converged = True
            break
    prob.R = Ri.T
    prob.t = -prob.R @ ti
    prob.s = 1.0
    stats = {"nfev": it, "converged": converged, "cost": float("nan"), "notes": []}
    return make_result(prob, stats, time.perf_counter() - t0, "icp", inlier_threshold)
