"""Primitive detection in point clouds (paper §4.4): :func:`detect_primitives`.

The search follows Schnabel, Wahl and Klein's Efficient RANSAC (2007), with csdf's exact
distances and :func:`csdf.fit` doing the refinement:

1. **Neighbourhoods.** One k-nearest-neighbour query gives normals (when not given),
   the point spacing, a noise estimate (the default ``epsilon`` is three times it) and
   the graph that connected components are cut from (:mod:`.neighbours`).
2. **Hypotheses from local minimal sets.** Each round draws a batch of samples: a seed
   point among those not yet explained and three of its neighbours at a random level of
   a coarse-to-fine pyramid of random subsets (so that neighbourhoods span small and
   large primitives alike). Every sample proposes a plane, a sphere, a cylinder, a cone
   and a torus (:mod:`.surfaces`), kept when its own points agree with it.
3. **Scoring.** Every hypothesis counts the points of a random subset within
   ``epsilon`` whose normals agree within ``normal_tolerance`` degrees; the best few are
   then scored on all unexplained points, keeping their largest connected component
   (in the 12-nearest-neighbour graph, edges shorter than ``cluster_epsilon``). A
   simpler kind wins over a more complex one that explains at most
   ``1/SIMPLER_WINS`` more points (a flat face is a plane, not a
   huge cylinder; a ring of small radius is a sphere, not a torus).
4. **Refinement.** The winner becomes a csdf solid (:mod:`.solids`: a sphere, capped
   cylinder, frustum or torus spanning its points), which :func:`csdf.fit` refines in
   pose and size on the points near it (caps included); its inliers are then the
   connected unexplained points within ``epsilon`` of the solid with agreeing normals.
   Planes are refined by principal component analysis (the least-squares plane).
5. **Greedy acceptance.** The largest detection is accepted and its points removed,
   until a round finds nothing with ``min_points`` points (or ``max_primitives`` are
   found).
6. **Composition.** Planes whose points lie on an accepted solid (a cylinder's or
   cone's cap) join it; groups of mutually adjacent orthogonal planes are fitted with a
   box, which replaces them when it explains their points.

Everything random comes from ``numpy.random.default_rng(seed)``: the same input and seed
give the same detections.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from ..errors import CsdfError
from ..fit import fit
from .neighbours import (
    Neighbourhood,
    components,
    linked_edges,
    neighbourhood,
    normals_arg,
    points_arg,
    viewpoint_arg,
)
from .solids import SOLID_BACKEND, SOLID_PARAMS, posed, solid_values
from .surfaces import (
    KINDS,
    cones_from,
    cylinders_from,
    frame_z,
    planes_from,
    spheres_from,
    surface_distance,
    tori_from,
)

__all__ = ["PrimitiveDetection", "detect_primitives", "ALL_KINDS", "SAMPLES_PER_ROUND",
           "SUBSET", "SIMPLER_WINS", "MAX_PRIMITIVES"]

#: the kinds :func:`detect_primitives` finds
ALL_KINDS = ("plane", "sphere", "cylinder", "cone", "torus", "box")
#: minimal samples drawn per round
SAMPLES_PER_ROUND = 120
#: points of the random subset hypotheses are first scored on
SUBSET = 1500
#: a simpler kind wins when it explains at least this fraction of the best's points
SIMPLER_WINS = 0.97
#: hypotheses scored on all unexplained points per round (the best estimates)
FULL_SCORES = 3
#: rounds in a row that may find nothing before the search stops
MAX_FAILURES = 3
#: default limit on the number of detections
MAX_PRIMITIVES = 64
#: points a refinement fit uses at most (a seeded subsample of the inliers)
FIT_POINTS = 600
#: least-squares refits of a plane hypothesis before it is compared with the others
PLANE_REFITS = 1
#: fits of a solid at most, each on the inliers of the one before (while they grow)
SOLID_REFITS = 3
#: neighbours searched around a seed point for its minimal set
SAMPLE_NEIGHBOURS = 10


@dataclass
class PrimitiveDetection:
    """One primitive found in a cloud.

    Attributes:
        kind: ``'plane'``, ``'sphere'``, ``'cylinder'``, ``'cone'``, ``'torus'`` or
            ``'box'``.
        shape: the posed csdf primitive (scene frame): ``plane(normal, offset)`` (a
            half-space), ``sphere``, a capped ``cylinder`` and a frustum
            (``capped_cone``) spanning the inliers, ``torus``, ``box``; the sizes are
            named parameters whose defaults are the detected values.
        params: the geometry, scene units and radians (lists for vectors):
            plane ``normal``, ``offset`` (``normal . p = offset``); sphere ``center``,
            ``radius``; cylinder ``center`` (middle of the axis segment), ``axis``,
            ``radius``, ``height``; cone ``apex``, ``axis`` (from the apex into the
            cone), ``angle`` (half angle), ``height`` (apex to the far end of the
            inliers); torus ``center``, ``axis``, ``major``, ``minor``; box ``center``,
            ``rotation`` (3x3, columns the box axes), ``size`` (full side lengths).
            Solids also give ``rotation`` and ``translation`` of ``shape``'s canonical
            frame and the solid's size parameters (``radius``, ``height``, ``r1``,
            ``r2``, ``major``, ``minor``, ``size_x``...).
        inliers: ``(K,)`` indices of the points it explains.
        rmse: root mean square distance of the inliers to the surface (scene units).
    """

    kind: str
    shape: object
    params: dict
    inliers: np.ndarray
    rmse: float
    solid: tuple | None = field(default=None, repr=False)  # (kind, R, t, values)

    def __repr__(self) -> str:
        return (f"PrimitiveDetection({self.kind}, {len(self.inliers)} points, "
                f"rmse={self.rmse:.3g})")


@dataclass
class _Ctx:
    """The state of one detection run."""

    P: np.ndarray
    N: np.ndarray
    nb: Neighbourhood
    eps: float
    cos_tol: float
    conn: float | None
    linked: np.ndarray
    min_points: int
    max_radius: float
    rng: np.random.Generator
    kinds: tuple[str, ...]
    viewpoint: np.ndarray | None
    levels: list[tuple[np.ndarray, cKDTree]] = field(default_factory=list)


def _kinds_arg(kinds) -> tuple[str, ...]:
    if isinstance(kinds, str):
        kinds = tuple(k.strip() for k in kinds.split(",") if k.strip())
    try:
        ks = tuple(str(k) for k in kinds)
    except TypeError:
        raise CsdfError(f"kinds must be a sequence of kind names; got {kinds!r}") from None
    bad = [k for k in ks if k not in ALL_KINDS]
    if bad or not ks:
        raise CsdfError(f"kinds: unknown kind {bad[0] if bad else '(none given)'!r}; "
                        f"choose from {', '.join(ALL_KINDS)}")
    return ks


def _positive(v, what: str) -> float:
    try:
        x = float(v)
    except (TypeError, ValueError):
        raise CsdfError(f"{what} must be a positive number; got {v!r}") from None
    if not (math.isfinite(x) and x > 0):
        raise CsdfError(f"{what} must be a positive number; got {v!r}")
    return x


def detect_primitives(points, normals=None, kinds=ALL_KINDS, epsilon=None,
                      min_points=None, seed=0, *, viewpoint=None, normal_tolerance=25.0,
                      cluster_epsilon=None, max_primitives=MAX_PRIMITIVES
                      ) -> list[PrimitiveDetection]:
    """Find planes, spheres, cylinders, cones, tori and boxes in a point cloud.

    Args:
        points: ``(N, 3)`` scene points (scene units, e.g. metres).
        normals: ``(N, 3)`` normals (any sign), or None to estimate them from each
            point's 12 nearest neighbours (turned towards ``viewpoint`` when given).
        kinds: the kinds to report (names or one comma-separated string). Planes are
            still searched for when only ``'box'`` is asked (boxes are made of them).
        epsilon: the largest distance of an inlier from its surface (scene units);
            default three times the estimated noise (at least 1e-4 of the cloud's
            bounding diagonal).
        min_points: the fewest points a detection explains; default
            ``max(30, N // 200)``.
        seed: seed of the random sampling (an int): equal seeds give equal results.
        viewpoint: ``(3,)`` sensor position for a single-view scan (orients estimated
            normals and planes' normals towards it).
        normal_tolerance: the largest angle in degrees between a point's normal and the
            surface's for an inlier.
        cluster_epsilon: the longest neighbour link inside one detection (scene
            units); default twice the local sampling scale (the distance to the 6th
            nearest neighbour) of either end, so that sparse and dense parts of one scan
            both hold together.
        max_primitives: stop after this many detections.

    Returns:
        :class:`PrimitiveDetection` list, largest first (boxes and solids that absorbed
        planes keep their place of first detection). A point belongs to at most one.

    Raises:
        CsdfError: points or normals of the wrong shape or not finite, unknown kinds,
            a non-positive ``epsilon``, ``min_points`` or ``normal_tolerance`` outside
            (0, 90).
    """
    P = points_arg(points)
    n = len(P)
    ks = _kinds_arg(kinds)
    vp = viewpoint_arg(viewpoint)
    tol = float(normal_tolerance)
    if not 0.0 < tol < 90.0:
        raise CsdfError(f"normal_tolerance must be an angle in (0, 90) degrees; got {tol}")
    if n < 4:
        return []
    nb = neighbourhood(P, viewpoint=vp, want_normals=normals is None)
    if normals is None:
        N = nb.normals
    else:
        N = normals_arg(normals, P)
    diag = float(np.linalg.norm(P.max(axis=0) - P.min(axis=0)))
    eps = (max(3.0 * nb.noise, 1e-4 * diag) if epsilon is None
           else _positive(epsilon, "epsilon"))
    conn = None if cluster_epsilon is None else _positive(cluster_epsilon, "cluster_epsilon")
    mp = max(30, n // 200) if min_points is None else int(_positive(min_points, "min_points"))
    ctx = _Ctx(P=P, N=N, nb=nb, eps=eps, cos_tol=math.cos(math.radians(tol)),
               conn=conn, linked=linked_edges(nb, conn), min_points=max(mp, 4),
               max_radius=max(diag, eps),
               rng=np.random.default_rng(seed), kinds=ks, viewpoint=vp)
    _build_levels(ctx)
    found = _extract(ctx, int(max_primitives))
    found = _absorb_planes(ctx, found)
    if "box" in ks:
        found = _make_boxes(ctx, found)
    return [d for d in found if d.kind in ks]


def _build_levels(ctx: _Ctx) -> None:
    """The sampling pyramid: random subsets of 1, 1/4, 1/16, ... of the points (down to
    about 64 points), each with its k-d tree."""
    n = len(ctx.P)
    perm = ctx.rng.permutation(n)
    m = n
    while True:
        idx = np.sort(perm[:m])
        ctx.levels.append((idx, ctx.nb.tree if m == n else cKDTree(ctx.P[idx])))
        m //= 4
        if m < 64:
            break


def _samples(ctx: _Ctx, free: np.ndarray, count: int) -> np.ndarray:
    """``(M, 4)`` point indices: a free seed point and three free neighbours of it at a
    random pyramid level each; rows without enough free neighbours are dropped."""
    fidx = np.flatnonzero(free)
    seeds = fidx[ctx.rng.integers(0, len(fidx), count)]
    lev = ctx.rng.integers(0, len(ctx.levels), count)
    out = []
    for li in range(len(ctx.levels)):
        sel = seeds[lev == li]
        if not len(sel):
            continue
        idx, tree = ctx.levels[li]
        k = min(SAMPLE_NEIGHBOURS, len(idx))
        _, nn = tree.query(ctx.P[sel], k=k)
        nn = idx[np.asarray(nn).reshape(len(sel), k)]
        keys = ctx.rng.random(nn.shape)
        keys[~free[nn] | (nn == sel[:, None])] = np.inf
        order = np.argsort(keys, axis=1)[:, :3]
        pick = np.take_along_axis(nn, order, axis=1)
        good = np.isfinite(np.take_along_axis(keys, order, axis=1)).all(axis=1)
        out.append(np.concatenate([sel[good, None], pick[good]], axis=1))
    return np.concatenate(out) if out else np.zeros((0, 4), dtype=int)


def _hypotheses(ctx: _Ctx, S: np.ndarray) -> dict[str, np.ndarray]:
    """The hypotheses of every surface kind from samples ``S`` ``(M, 4)``."""
    p, nrm = ctx.P[S], ctx.N[S]
    eps, rmax = ctx.eps, ctx.max_radius
    want = set(ctx.kinds)
    out = {}
    H, ok = planes_from(p[:, :3], nrm[:, :3], ctx.cos_tol)
    out["plane"] = H[ok]
    if "sphere" in want:
        H, ok = spheres_from(p[:, :2], nrm[:, :2], eps, rmax)
        out["sphere"] = H[ok]
    if "cylinder" in want:
        H, ok = cylinders_from(p[:, :2], nrm[:, :2], eps, rmax)
        out["cylinder"] = H[ok]
    if "cone" in want:
        H, ok = cones_from(p[:, :3], nrm[:, :3], eps, rmax)
        out["cone"] = H[ok]
    if "torus" in want:
        H, ok = tori_from(p, nrm, eps, rmax)
        out["torus"] = H[ok]
    return out


def _inlier_mask(ctx: _Ctx, d: np.ndarray, c: np.ndarray) -> np.ndarray:
    return (np.abs(d) <= ctx.eps) & (c >= ctx.cos_tol)


def _extract(ctx: _Ctx, max_primitives: int) -> list[PrimitiveDetection]:
    """Steps 2-5 of the module docstring: the greedy extraction loop."""
    free = np.ones(len(ctx.P), dtype=bool)
    found: list[PrimitiveDetection] = []
    failures = 0
    rank = {k: i for i, k in enumerate(KINDS)}
    while free.sum() >= ctx.min_points and len(found) < max_primitives:
        S = _samples(ctx, free, SAMPLES_PER_ROUND)
        fidx = np.flatnonzero(free)
        sub = fidx if len(fidx) <= SUBSET else np.sort(ctx.rng.choice(fidx, SUBSET,
                                                                      replace=False))
        scale = len(fidx) / len(sub)
        cands = []  # (estimated count, kind, row)
        for kind, H in _hypotheses(ctx, S).items():
            if not len(H):
                continue
            d, c = surface_distance(kind, H, ctx.P[sub], ctx.N[sub])
            cnt = _inlier_mask(ctx, d, c).sum(axis=1) * scale
            top = np.argsort(-cnt, kind="stable")[:FULL_SCORES]
            cands += [(float(cnt[i]), kind, H[i]) for i in top]
        cands.sort(key=lambda x: (-x[0], rank[x[1]]))
        best = None
        scored = []
        for est, kind, h in cands[:FULL_SCORES]:
            if est < 0.5 * ctx.min_points:
                break
            inl = _connected_inliers(ctx, kind, h, fidx)
            if kind == "plane":  # refitted by least squares: three close points tilt it
                for _ in range(PLANE_REFITS):
                    if len(inl) < 3:
                        break
                    h = _lsq_plane(ctx.P[inl])
                    inl = _connected_inliers(ctx, kind, h, fidx)
            scored.append((len(inl), kind, h, inl))
        if scored:
            top = max(s[0] for s in scored)
            ok = [s for s in scored if s[0] >= SIMPLER_WINS * top]
            best = min(ok, key=lambda s: (rank[s[1]], -s[0]))
        if best is None or best[0] < ctx.min_points:
            failures += 1
            if failures >= MAX_FAILURES:
                break
            continue
        det = _refine(ctx, best[1], best[2], best[3], free)
        if det is None or len(det.inliers) < ctx.min_points:
            failures += 1
            if failures >= MAX_FAILURES:
                break
            continue
        failures = 0
        free[det.inliers] = False
        found.append(det)
    return found


def _connected_inliers(ctx: _Ctx, kind: str, h: np.ndarray, fidx: np.ndarray) -> np.ndarray:
    """The largest connected component of the points among ``fidx`` that are inliers
    of surface hypothesis ``h``."""
    d, c = surface_distance(kind, h[None], ctx.P[fidx], ctx.N[fidx])
    mask = np.zeros(len(ctx.P), dtype=bool)
    mask[fidx[_inlier_mask(ctx, d[0], c[0])]] = True
    return np.flatnonzero(components(ctx.nb, mask, ctx.linked) == 0)


def _lsq_plane(Q: np.ndarray) -> np.ndarray:
    """The least-squares plane ``(normal, offset)`` ``(4,)`` of points ``Q`` ``(K, 3)``."""
    c = Q.mean(axis=0)
    _, _, Vt = np.linalg.svd(Q - c, full_matrices=False)
    return np.append(Vt[2], Vt[2] @ c)


def _plane_detection(ctx: _Ctx, inl: np.ndarray) -> PrimitiveDetection:
    from ..shapes import plane

    Q = ctx.P[inl]
    c = Q.mean(axis=0)
    nrm = _lsq_plane(Q)[:3]
    if ctx.viewpoint is not None:
        if nrm @ (ctx.viewpoint - c) < 0:
            nrm = -nrm
    elif nrm @ ctx.N[inl].sum(axis=0) < 0:
        nrm = -nrm
    off = float(nrm @ c)
    r = Q @ nrm - off
    return PrimitiveDetection(
        kind="plane", shape=plane(tuple(nrm.tolist()), off),
        params={"normal": nrm.tolist(), "offset": off}, inliers=inl,
        rmse=float(np.sqrt(np.mean(r * r))))


def _initial_solid(ctx: _Ctx, kind: str, h: np.ndarray, inl: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, dict]:
    """The canonical solid's pose ``(R, t)`` and sizes spanning the inliers of a
    surface hypothesis ``h``."""
    Q = ctx.P[inl]
    if kind == "sphere":
        return np.eye(3), h[:3].copy(), {"radius": float(h[3])}
    a = h[3:6] / np.linalg.norm(h[3:6])
    z = (Q - h[:3]) @ a
    if kind == "cylinder":
        lo, hi = float(z.min()), float(z.max())
        return frame_z(a), h[:3] + 0.5 * (lo + hi) * a, {
            "radius": float(h[6]), "height": max(hi - lo, ctx.eps)}
    if kind == "cone":
        lo, hi = max(float(z.min()), 0.0), float(z.max())
        tn = math.tan(float(h[6]))
        return frame_z(-a), h[:3] + hi * a, {
            "r1": hi * tn, "r2": lo * tn, "height": max(hi - lo, ctx.eps)}
    return frame_z(a), h[:3].copy(), {"major": float(h[6]), "minor": float(h[7])}


def _on_solid(ctx: _Ctx, kind: str, R, t, values, idx: np.ndarray) -> np.ndarray:
    """``(K,)`` which points ``idx`` are inliers of the solid: within ``epsilon`` of it,
    their normals within the tolerance of its gradient."""
    d, g = solid_values(kind, R, t, values, ctx.P[idx])
    return (np.abs(d) <= ctx.eps) & (np.abs(np.einsum("ij,ij->i", g, ctx.N[idx]))
                                     >= ctx.cos_tol)


def _near_solid(ctx: _Ctx, kind: str, R, t, values, cand: np.ndarray, seedset: np.ndarray
                ) -> np.ndarray:
    """Indices among ``cand`` within ``epsilon`` of the solid with agreeing normals,
    in the connected components that hold points of ``seedset``."""
    ok = _on_solid(ctx, kind, R, t, values, cand)
    good = np.zeros(len(ctx.P), dtype=bool)
    good[cand[ok]] = True
    mask = good.copy()
    mask[seedset] = True
    lab = components(ctx.nb, mask, ctx.linked)
    keep = np.unique(lab[seedset])
    return np.flatnonzero(np.isin(lab, keep[keep >= 0]) & good)


def _fit_solid(ctx: _Ctx, kind: str, R, t, values: dict, pts_idx: np.ndarray):
    """Refine a solid's pose and sizes with :func:`csdf.fit` on the points
    ``pts_idx`` (a seeded subsample of at most ``FIT_POINTS``)."""
    from .solids import canonical

    shape, _ = canonical(kind)
    idx = pts_idx
    if len(idx) > FIT_POINTS:
        idx = np.sort(ctx.rng.choice(idx, FIT_POINTS, replace=False))
    res = fit(shape, ctx.P[idx], init={"rotation": R, "translation": t, "scale": 1.0,
                                       "params": dict(values)},
              estimate=("pose", "params"), loss="huber", f_scale=ctx.eps / 3.0,
              escape=False, debias=False, backend=SOLID_BACKEND, max_iter=60)
    vals = {k: float(res.params[k]) for k in SOLID_PARAMS[kind]}
    return res.rotation, np.asarray(res.translation, float), vals


def _solid_detection(ctx: _Ctx, kind: str, R, t, vals, inl: np.ndarray) -> PrimitiveDetection:
    """The :class:`PrimitiveDetection` of a refined solid and its inliers."""
    d, _ = solid_values(kind, R, t, vals, ctx.P[inl])
    a = R[:, 2]
    if kind == "sphere":
        geo = {"center": t.tolist(), "radius": vals["radius"]}
    elif kind == "cylinder":
        geo = {"center": t.tolist(), "axis": a.tolist(), "radius": vals["radius"],
               "height": vals["height"]}
    elif kind == "cone":
        # canonical z runs from the base (r1) towards the apex (r2)
        r1, r2, hgt = vals["r1"], vals["r2"], vals["height"]
        slope = (r1 - r2) / max(hgt, 1e-300)
        full = r1 / max(slope, 1e-300)
        geo = {"apex": (t + full * a).tolist(), "axis": (-a).tolist(),
               "angle": math.atan(slope), "height": full}
    elif kind == "torus":
        geo = {"center": t.tolist(), "axis": a.tolist(), "major": vals["major"],
               "minor": vals["minor"]}
    else:
        geo = {"center": t.tolist(), "rotation": R.tolist(),
               "size": [vals["size_x"], vals["size_y"], vals["size_z"]]}
    geo.update({"rotation": R.tolist(), "translation": t.tolist()} if kind != "box" else {})
    geo.update(vals)
    return PrimitiveDetection(kind=kind, shape=posed(kind, R, t, vals), params=geo,
                              inliers=np.sort(inl), rmse=float(np.sqrt(np.mean(d * d))),
                              solid=(kind, R, t, vals))


def _refine(ctx: _Ctx, kind: str, h: np.ndarray, inl: np.ndarray, free: np.ndarray
            ) -> PrimitiveDetection | None:
    """Step 4: the refined detection of hypothesis ``h`` with connected inliers
    ``inl``, or None when the refined solid is degenerate."""
    if kind == "plane":
        # the least-squares plane, then its own inliers
        return _plane_detection(ctx, _connected_inliers(ctx, "plane", _lsq_plane(ctx.P[inl]),
                                                        np.flatnonzero(free)))
    R, t, vals = _initial_solid(ctx, kind, h, inl)
    fidx = np.flatnonzero(free)
    pts = np.union1d(inl, _near_solid(ctx, kind, R, t, vals, fidx, inl))
    for _ in range(SOLID_REFITS):
        try:
            R, t, vals = _fit_solid(ctx, kind, R, t, vals, pts)
        except CsdfError:
            return None
        if not all(np.isfinite(v) for v in vals.values()):
            return None
        near = _near_solid(ctx, kind, R, t, vals, fidx, pts)
        grown = len(near) > 1.01 * len(pts)
        pts = near
        if not grown:
            break
    if len(pts) < ctx.min_points:
        return None
    return _solid_detection(ctx, kind, R, t, vals, pts)


def _absorb_planes(ctx: _Ctx, found: list[PrimitiveDetection]) -> list[PrimitiveDetection]:
    """Step 6a: a plane whose points (nearly all) lie on an accepted solid, with agreeing
    normals, is that solid's cap: its points join the solid, which is refitted."""
    solids = [i for i, d in enumerate(found) if d.solid is not None]
    if not solids:
        return found
    out = list(found)
    drop = set()
    for i, d in enumerate(found):
        if d.kind != "plane":
            continue
        for j in solids:
            kind, R, t, vals = out[j].solid
            if _on_solid(ctx, kind, R, t, vals, d.inliers).mean() >= 0.9:
                pts = np.union1d(out[j].inliers, d.inliers)
                try:
                    R2, t2, v2 = _fit_solid(ctx, kind, R, t, vals, pts)
                except CsdfError:
                    R2, t2, v2 = R, t, vals
                out[j] = _solid_detection(ctx, kind, R2, t2, v2, pts)
                drop.add(i)
                break
    return [d for i, d in enumerate(out) if i not in drop]


def _make_boxes(ctx: _Ctx, found: list[PrimitiveDetection]) -> list[PrimitiveDetection]:
    """Step 6b: groups of adjacent, mutually orthogonal planes fitted with boxes."""
    planes = [i for i, d in enumerate(found) if d.kind == "plane"]
    if len(planes) < 2:
        return found
    trees = {i: cKDTree(ctx.P[found[i].inliers]) for i in planes}
    link = (2.0 * ctx.conn if ctx.conn is not None
            else 4.0 * float(np.median(ctx.nb.local)))
    parent = {i: i for i in planes}

    def root(i: int) -> int:
        while parent[i] != i:
            i = parent[i]
        return i

    for a_i, i in enumerate(planes):
        ni = np.asarray(found[i].params["normal"])
        for j in planes[a_i + 1:]:
            nj = np.asarray(found[j].params["normal"])
            if abs(ni @ nj) > 0.15:
                continue
            dd, _ = trees[i].query(ctx.P[found[j].inliers], k=1,
                                   distance_upper_bound=link)
            if np.isfinite(dd).any():
                parent[root(j)] = root(i)
    groups: dict[int, list[int]] = {}
    for i in planes:
        groups.setdefault(root(i), []).append(i)
    out: dict[int, PrimitiveDetection] = dict(enumerate(found))
    for members in groups.values():
        members = sorted(members, key=lambda i: -len(found[i].inliers))
        # all members, then without the largest (a floor the box stands on)
        for trial in (members, members[1:]):
            if len(trial) < 2:
                continue
            box = _box_of(ctx, [found[i] for i in trial])
            if box is not None:
                first = min(trial)
                for i in trial:
                    out.pop(i, None)
                out[first] = box
                break
    return [out[i] for i in sorted(out)]


def _box_of(ctx: _Ctx, faces: list[PrimitiveDetection]) -> PrimitiveDetection | None:
    """A box fitted to the points of ``faces`` (planes), or None when it does not
    explain at least 90% of them."""
    n0 = np.asarray(faces[0].params["normal"])
    n1 = next((np.asarray(f.params["normal"]) for f in faces[1:]
               if abs(np.asarray(f.params["normal"]) @ n0) < 0.15), None)
    if n1 is None:
        return None
    e1 = n0
    e2 = n1 - (n1 @ e1) * e1
    e2 /= np.linalg.norm(e2)
    R = np.stack([e1, e2, np.cross(e1, e2)], axis=1)
    idx = np.unique(np.concatenate([f.inliers for f in faces]))
    q = ctx.P[idx] @ R
    lo, hi = q.min(axis=0), q.max(axis=0)
    size = np.maximum(hi - lo, ctx.eps)
    t = R @ (0.5 * (lo + hi))
    vals = {"size_x": float(size[0]), "size_y": float(size[1]), "size_z": float(size[2])}
    try:
        R, t, vals = _fit_solid(ctx, "box", R, t, vals, idx)
    except CsdfError:
        return None
    if _on_solid(ctx, "box", R, t, vals, idx).mean() < 0.9 or min(vals.values()) <= 2 * ctx.eps:
        return None
    return _solid_detection(ctx, "box", R, t, vals, idx)
