"""Joint refinement of a CSG tree's continuous parameters: every primitive's sizes,
position and orientation, by Levenberg-Marquardt on the exact parameter Jacobian of the whole tree
(one forward-mode pass of the compiled tree gives values, gradients and
``d f / d params`` at every point).

The objective follows the search's score (:mod:`.search`), smoothed:

* data: ``mean(rho(f(p)))`` over a sample of the points, ``rho`` a Cauchy loss at
  half the noise level ``tau`` (redescending: a point the tree does not explain, one
  on a surface of no leaf, does not pull the leaves away from the points they do
  explain); a point whose normal points into the tree where it lies is left out (it
  is matched to the wrong surface);
* free space (a single-view scan): ``mean(min(f(q), 0)^2) / tau^2`` over points the
  sensor looked through: material there is pushed out of the rays.

Sizes stay positive. Orientations are refined as turns of each leaf's own frame by
angles that start at 0 (:func:`turn_matrix`: about the leaf's x and y axes, which tilt
a cylinder's, cone's or torus's axis, and for a box also about its z axis), each kept
within :data:`MAX_TURN` of the start; the caller names the angle parameters.
"""

from __future__ import annotations

import math

import numpy as np

from ..field import as_field

__all__ = ["refine_params", "turn_matrix", "ITERATIONS", "MAX_TURN"]

#: Levenberg-Marquardt iterations at most
ITERATIONS = 25
#: the smallest size (a share of ``tau``) a primitive keeps
MIN_SIZE = 0.5
#: the largest turn (radians, each angle) a refinement gives a leaf: about 17 degrees,
#: three times the largest error of a detected axis seen (5.5 degrees); a larger turn
#: is another candidate's job, not a correction
MAX_TURN = 0.3


def turn_matrix(ax: float = 0.0, ay: float = 0.0, az: float = 0.0) -> np.ndarray:
    """``(3, 3)`` the rotation ``Ry(ay) Rx(ax) Rz(az)`` (radians, right-hand rule): a
    leaf turned by the angles of a refinement is posed by ``R @ turn_matrix(...)``
    (the shape turned about its own z, then x, then y axis before its rotation
    ``R``)."""
    def rot(a: float, i: int) -> np.ndarray:
        c, s = math.cos(a), math.sin(a)
        j, k = (i + 1) % 3, (i + 2) % 3
        m = np.eye(3)
        m[j, j], m[j, k], m[k, j], m[k, k] = c, -s, s, c
        return m

    return rot(ay, 1) @ rot(ax, 0) @ rot(az, 2)


def refine_params(shape, values: dict[str, float], sizes: set[str], X: np.ndarray,
                  NX: np.ndarray | None, Q: np.ndarray | None, tau: float,
                  backend: str, turns: set[str] | None = None) -> dict[str, float]:
    """The parameter values of ``shape`` that fit the points best.

    Args:
        shape: the tree as a csdf shape with named parameters.
        values: their starting values ``{name: value}``.
        sizes: the names that are sizes (kept at least ``MIN_SIZE * tau``).
        X: ``(M, 3)`` points on the surface (scene units); ``NX`` ``(M, 3)`` their
            outward normals, or None.
        Q: ``(K, 3)`` free-space points (scene units), or None.
        tau: the noise level (scene units).
        backend: the evaluator.
        turns: the names that are turn angles (radians, kept within
            :data:`MAX_TURN` of their start).

    Returns:
        The refined ``{name: value}`` (the start when no step lowered the objective).
    """
    fld = as_field(shape, params=values, backend=backend, check_ranges=False)
    names = list(fld.param_names)
    theta = np.array([values[n] for n in names], dtype=np.float64)
    turns = turns or set()
    lo = np.array([MIN_SIZE * tau if n in sizes else -np.inf for n in names])
    hi = np.full(len(names), np.inf)
    for i, n in enumerate(names):
        if n in turns:
            lo[i], hi[i] = theta[i] - MAX_TURN, theta[i] + MAX_TURN
    c = 0.5 * tau
    pts = X if Q is None else np.concatenate([X, Q])
    m = len(X)
    wq = 0.0 if Q is None or not len(Q) else m / len(Q)  # the two terms' means weigh alike

    def evaluate(th: np.ndarray, jac: bool):
        f2 = fld.replace(params=dict(zip(names, th)), check_ranges=False)
        if jac:
            f, g, J = f2.value_grad_param_jacobian(pts)
        else:
            f, g, J = f2.value(pts), None, None
        return np.asarray(f, float), g, J

    def jacobian(th: np.ndarray) -> np.ndarray:
        # the parameter tangents alone (no spatial ones: the gradients are needed only
        # at the start); each tangent is its own forward pass, so J is the same
        return fld.replace(params=dict(zip(names, th)), check_ranges=False).param_jacobian(pts)

    def cost(f: np.ndarray, keep: np.ndarray) -> float:
        data = np.log1p((f[:m] / c) ** 2)[keep].sum()
        free = wq * np.minimum(f[m:], 0.0) ** 2 / c ** 2
        return float(data + free.sum())

    f, g, J = evaluate(theta, True)
    keep = np.ones(m, dtype=bool)
    if NX is not None:
        keep = np.einsum("ij,ij->i", np.asarray(g)[:m], NX) > 0.0
    best = cost(f, keep)
    lam = 1e-3
    for it in range(ITERATIONS):
        r = f[:m] / c
        w = np.where(keep, 1.0 / (1.0 + r * r), 0.0)  # IRLS weights of the Cauchy loss
        inside = f[m:] < 0.0
        wf = np.concatenate([w, np.where(inside, wq, 0.0)])
        rr = np.concatenate([f[:m], np.where(inside, f[m:], 0.0)]) / c
        Jc = np.asarray(J, float) / c
        # (einsum, not BLAS: OpenBLAS's threads slow to a crawl beside the
        # evaluators' thread pool)
        A = np.einsum("ni,nj->ij", Jc, wf[:, None] * Jc)
        b = np.einsum("ni,n->i", Jc, wf * rr)
        improved = False
        for _ in range(8):
            step = np.linalg.solve(A + lam * np.diag(np.diag(A) + 1e-12), -b)
            cand = np.clip(theta + step, lo, hi)
            f2, _, _ = evaluate(cand, False)
            c2 = cost(f2, keep)
            if np.isfinite(c2) and c2 < best:
                improved = True
                break
            lam *= 10.0
        if not improved:
            break
        gain = (best - c2) / max(best, 1e-300)
        theta, best, f = cand, c2, f2
        lam = max(lam / 10.0, 1e-9)
        if gain < 1e-6 or it == ITERATIONS - 1:
            break  # (no Jacobian for a step that will not be taken)
        J = jacobian(theta)
    return dict(zip(names, theta.tolist()))
