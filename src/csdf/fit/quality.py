"""Does a fit explain the cloud? The success test of :func:`csdf.fit` (``FitResult.success``
and ``FitResult.quality``).

``converged`` only says that the optimiser stopped on a convergence test; a converged fit
can still be wrong (a chair turned by 180 degrees, a plate whose scanned top face lies on
the model's bottom face). A fit is a **success** when all of these hold:

1. **Inliers**: ``inlier_fraction >= INLIER_MIN`` (points with ``|r| <= inlier_threshold``,
   default ``3 f_scale``).
2. **Residual against the noise level**: the inliers' ``rmse <= RMSE_MAX * f_scale``. The
   loss's residual scale ``f_scale`` is the noise level the fit assumes (default 1% of the
   model's size; give the sensor's noise to make the test sharper): Gaussian noise of
   standard deviation ``f_scale`` gives an inlier rmse of about ``0.99 f_scale``, residuals
   spread evenly over the inlier band about ``1.7 f_scale``.
3. **Visible surface explained** (only when a viewpoint is known): the fitted model is
   ray-cast from the viewpoint on a grid of ``VIEW_RAYS x VIEW_RAYS`` rays over its
   bounding sphere. A ray that hits a front face of the model, within the cloud's view (the
   convex hull of the points' directions as seen from the viewpoint, since the sensor's
   field of view is not known), is *explained* when one of the ``NEIGHBOURS`` measured
   points nearest in direction, within ``GAP_FACTOR`` times the cloud's median angular
   spacing, lies at the model's depth or in front of it (an occluder); it is
   *see-through* when all of those lie behind the model's surface (the sensor saw through
   where the model says a surface is: the back-face solution), and *empty* when no
   measured point lies in that direction (the model shows a surface where the sensor
   returned nothing).
   Rays on a depth edge of the model (a 4-neighbour on the grid misses the model or
   hits it at a depth beyond both rays' tolerances) are not judged when at least
   ``MIN_VIEW_RAYS`` others are: under a pose error of a ray or two they see another
   surface than the model says (the background past a silhouette, the inside of a
   shelf past a board's edge). ``quality['visible_edge_rays']`` counts them.
   The fraction of see-through and empty rays must be at most ``VISIBLE_MAX_UNEXPLAINED``.
   The depth tolerance is ``inlier_threshold`` plus the depth change across the angular
   offset on the model's (slanted) surface, ``depth * offset * min(tan(incidence),
   TAN_MAX)``. With fewer than ``MIN_VIEW_RAYS`` judged rays (or the viewpoint inside the
   model's bounding sphere) the test is not made (``quality['visible_checked']`` is False).

``quality`` holds every figure, the thresholds used and ``reasons``: one sentence per
failed criterion (empty when ``success``).
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import CsdfError
from ..points import sample_spacing

__all__ = ["assess", "INLIER_MIN", "RMSE_MAX", "VISIBLE_MAX_UNEXPLAINED", "VIEW_RAYS",
           "GAP_FACTOR", "NEIGHBOURS", "TAN_MAX", "TRACE_ITER", "MIN_VIEW_RAYS", "GRAZING"]

#: least fraction of inliers (``|r| <= inlier_threshold``)
INLIER_MIN = 0.8
#: largest inlier rmse, in multiples of ``f_scale`` (the noise level the fit assumes)
RMSE_MAX = 1.5
#: largest fraction of the model's visible rays (in the cloud's view) left unexplained
VISIBLE_MAX_UNEXPLAINED = 0.05
#: rays per side of the grid the fitted model is ray-cast on
VIEW_RAYS = 48
#: a ray is "empty" when the nearest measured direction is farther than this times the
#: cloud's median angular spacing
GAP_FACTOR = 3.0
#: measured directions compared with each model ray (the nearest ones within the gap)
NEIGHBOURS = 4
#: cap on ``tan(incidence)`` in the depth tolerance (about 84 degrees)
TAN_MAX = 10.0
#: sphere-tracing iterations per ray (rays still marching then are not judged)
TRACE_ITER = 64
#: fewer judged rays than this: the visibility test is not made
MIN_VIEW_RAYS = 20
#: model hits with ``|normal . ray| <`` this are grazing and not judged (as csdf.scan)
GRAZING = 0.05


def _edge_rays(depth: np.ndarray, tan: np.ndarray, thr: float, step: float) -> np.ndarray:
    """``(V*V,)`` which rays of the ``VIEW_RAYS x VIEW_RAYS`` grid lie on a depth edge of
    the model: a 4-neighbour misses the model, or its depth differs by more than the two
    rays' tolerances (``thr`` plus the depth change across one grid ``step``, in tangent
    units, on each ray's slanted surface). Under a pose error of a ray or two such rays
    see another surface than the model says (the background past a silhouette, the
    inside of a shelf past a board's edge), so they are not evidence either way.

    ``depth`` ``(V*V,)`` is the model's depth along each ray (non-finite: no hit),
    ``tan`` ``(V*V,)`` the tangent of each hit's incidence."""
    v = VIEW_RAYS
    D = depth.reshape(v, v)
    with np.errstate(invalid="ignore"):
        tol = (thr + np.abs(D) * step * np.minimum(np.nan_to_num(tan.reshape(v, v),
                                                                 nan=TAN_MAX), TAN_MAX))
    ok = np.isfinite(D)
    edge = ~ok
    for axis in (0, 1):
        a = [slice(None)] * 2
        b = [slice(None)] * 2
        a[axis], b[axis] = slice(1, None), slice(None, -1)
        a, b = tuple(a), tuple(b)
        with np.errstate(invalid="ignore"):
            jump = ~(ok[a] & ok[b]) | (np.abs(D[a] - D[b]) > tol[a] + tol[b])
        edge[a] |= jump
        edge[b] |= jump
    # the grid's border rays have no neighbour outside: they lie past the bounding
    # sphere's silhouette anyway
    return edge.reshape(-1)


def _basis(axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors completing the unit ``axis`` (3,) to an orthonormal frame."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(axis, helper)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(axis, e1)


def _visibility(prog, pvals: dict, backend: str, R: np.ndarray, t: np.ndarray, s: float,
                bounds: np.ndarray | None, points: np.ndarray, viewpoint: np.ndarray,
                thr: float) -> dict:
    """The visibility figures of criterion 3 (see the module docs) for the model posed
    by ``R`` (3, 3), ``t`` (3,), ``s`` (``bounds``: its (2, 3) object-frame box, model
    units) against ``points`` (N, 3) seen from ``viewpoint`` (3,), scene units; ``thr``
    the inlier threshold (scene units)."""
    from scipy.spatial import ConvexHull, QhullError, cKDTree

    from ..render.trace import trace_field, trace_hits

    out: dict = {"visible_checked": False}
    if bounds is None:
        out["visible_note"] = "the model has no bounding box"
        return out
    D = points - viewpoint
    depth = np.linalg.norm(D, axis=1)
    ok = depth > 0
    D, depth = D[ok], depth[ok]
    if len(D) < 3:
        out["visible_note"] = "fewer than 3 points away from the viewpoint"
        return out
    u = D / depth[:, None]
    axis = u.mean(axis=0)
    if not np.linalg.norm(axis) > 1e-6:
        out["visible_note"] = "the points surround the viewpoint"
        return out
    axis /= np.linalg.norm(axis)
    e1, e2 = _basis(axis)
    ua = u @ axis
    front = ua > 0.05
    q2 = np.stack([(u @ e1)[front] / ua[front], (u @ e2)[front] / ua[front]], axis=1)
    depth = depth[front]
    if len(q2) < 3:
        out["visible_note"] = "fewer than 3 points in front of the viewpoint"
        return out
    # the model's bounding sphere as seen from the viewpoint
    centre = 0.5 * (bounds[0] + bounds[1])
    c_scene = s * (R @ centre) + t
    radius = 0.5 * float(np.linalg.norm(bounds[1] - bounds[0])) * s
    to_c = c_scene - viewpoint
    dist = float(np.linalg.norm(to_c))
    if not dist > radius * 1.001:
        out["visible_note"] = "the viewpoint is inside the model's bounding sphere"
        return out
    a2 = to_c / dist
    f1, f2 = _basis(a2)
    half = math.tan(math.asin(radius / dist))
    g = np.linspace(-half, half, VIEW_RAYS)
    gx, gy = np.meshgrid(g, g)
    dirs = a2 + gx.reshape(-1, 1) * f1 + gy.reshape(-1, 1) * f2
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    # trace in the model's frame: q = R^T (p - t) / s
    fld = trace_field(prog, pvals, backend, bounds, what="fit", check_ranges=False)
    o_m = (R.T @ (viewpoint - t)) / s
    d_m = dirs @ R
    tm, n_m, _ = trace_hits(fld, o_m, d_m, max_iter=TRACE_ITER)
    with np.errstate(invalid="ignore"):
        cosi = -(n_m * d_m).sum(axis=1)
        hit = np.isfinite(tm) & (cosi >= GRAZING)
    da = dirs @ axis
    hit &= da > 0.05
    idx = np.flatnonzero(hit)
    h2 = np.stack([(dirs[idx] @ e1) / da[idx], (dirs[idx] @ e2) / da[idx]], axis=1)
    try:
        hull = ConvexHull(q2)
        eq = hull.equations
        inside = np.all(h2 @ eq[:, :2].T + eq[:, 2] <= 1e-12, axis=1)
    except (QhullError, ValueError):  # degenerate (collinear) directions: no view area
        inside = np.zeros(len(idx), dtype=bool)
    idx, h2 = idx[inside], h2[inside]
    d_all = s * tm
    tan_all = (np.sqrt(np.maximum(1.0 - cosi ** 2, 0.0))
               / np.maximum(cosi, GRAZING))
    edge = _edge_rays(d_all, tan_all, thr, 2.0 * half / (VIEW_RAYS - 1))[idx]
    if int((~edge).sum()) >= MIN_VIEW_RAYS:  # judge the rays away from depth edges
        idx, h2 = idx[~edge], h2[~edge]
    out["visible_edge_rays"] = int(edge.sum())
    out["visible_rays"] = int(len(idx))
    if len(idx) < MIN_VIEW_RAYS:
        out["visible_note"] = (f"only {len(idx)} model rays within the cloud's view "
                               f"(< {MIN_VIEW_RAYS})")
        return out
    tree = cKDTree(q2)
    sub = q2 if len(q2) <= 2000 else q2[np.random.default_rng(0).choice(len(q2), 2000,
                                                                         False)]
    spacing = sample_spacing(tree, sub)
    gap = GAP_FACTOR * max(spacing, 1e-12)
    k = min(NEIGHBOURS, len(q2))
    off, j = tree.query(h2, k=k)
    off, j = off.reshape(len(h2), k), j.reshape(len(h2), k)
    near = off <= gap
    d_model = s * tm[idx]
    tan = np.sqrt(np.maximum(1.0 - cosi[idx] ** 2, 0.0)) / np.maximum(cosi[idx], GRAZING)
    tol = thr + d_model[:, None] * off * np.minimum(tan, TAN_MAX)[:, None]
    empty = ~near.any(axis=1)
    # seen through: every measured point in that direction lies behind the model
    ahead = near & (depth[np.minimum(j, len(depth) - 1)] <= d_model[:, None] + tol)
    behind = ~empty & ~ahead.any(axis=1)
    n = len(idx)
    out.update({
        "visible_checked": True,
        "visible_unexplained": float((empty.sum() + behind.sum()) / n),
        "visible_see_through": float(behind.sum() / n),
        "visible_empty": float(empty.sum() / n),
        "angular_spacing": spacing,
    })
    return out


def assess(prog, pvals: dict, backend: str, R: np.ndarray, t: np.ndarray, s: float,
           bounds: np.ndarray | None, points: np.ndarray, residuals: np.ndarray,
           inlier_threshold: float, f_scale: float, viewpoint=None) -> tuple[bool, dict]:
    """The success test (module docs) of the model ``prog`` with parameter values
    ``pvals`` posed by ``R`` (3, 3), ``t`` (3,), ``s`` against ``points`` (N, 3) with
    their signed-distance ``residuals`` (N,) (scene units); ``bounds``: the model's
    (2, 3) object-frame box (model units); ``viewpoint``: (3,) or None.

    Returns:
        ``(success, quality)``: ``quality`` has ``inlier_fraction``, ``inlier_min``,
        ``rmse``, ``noise_level`` (``f_scale``), ``rmse_ratio`` (``rmse / f_scale``),
        ``rmse_max``, ``visible_checked`` and, when checked, ``visible_rays``,
        ``visible_unexplained``, ``visible_see_through``, ``visible_empty``,
        ``visible_max_unexplained`` (or ``visible_note`` saying why not), and
        ``reasons`` (list of str, empty on success).
    """
    r = np.asarray(residuals, dtype=float)
    inl = np.abs(r) <= inlier_threshold
    frac = float(inl.mean()) if len(r) else 0.0
    rmse = float(np.sqrt(np.mean(r[inl] ** 2))) if inl.any() else math.inf
    q: dict = {"inlier_fraction": frac, "inlier_min": INLIER_MIN, "rmse": rmse,
               "noise_level": float(f_scale), "rmse_ratio": rmse / f_scale,
               "rmse_max": RMSE_MAX}
    reasons: list[str] = []
    if frac < INLIER_MIN:
        reasons.append(f"only {frac:.1%} of the points are inliers (|r| <= "
                       f"{inlier_threshold:.3g}); at least {INLIER_MIN:.0%} are needed")
    if not rmse <= RMSE_MAX * f_scale:
        reasons.append(f"the inlier rmse {rmse:.3g} is {rmse / f_scale:.2f} x the noise "
                       f"level f_scale {f_scale:.3g} (at most {RMSE_MAX:g} x)")
    if viewpoint is None:
        q["visible_checked"] = False
        q["visible_note"] = "no viewpoint"
    else:
        try:
            q.update(_visibility(prog, pvals, backend, R, t, s, bounds,
                                 np.asarray(points, dtype=float),
                                 np.asarray(viewpoint, dtype=float), inlier_threshold))
        except CsdfError as exc:  # a model the tracer refuses (no bounds, ...)
            q["visible_checked"] = False
            q["visible_note"] = f"not ray-cast: {exc}"
        if q.get("visible_checked"):
            q["visible_max_unexplained"] = VISIBLE_MAX_UNEXPLAINED
            if q["visible_unexplained"] > VISIBLE_MAX_UNEXPLAINED:
                reasons.append(
                    f"{q['visible_unexplained']:.0%} of the model's surface visible from "
                    f"the viewpoint is not explained by the cloud ("
                    f"{q['visible_see_through']:.0%} seen through: measured points lie "
                    f"behind it; {q['visible_empty']:.0%} with no points); at most "
                    f"{VISIBLE_MAX_UNEXPLAINED:.0%} allowed")
    q["reasons"] = reasons
    return not reasons, q
