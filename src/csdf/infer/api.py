"""``csdf.infer``: a parametric CSG model of csdf primitives from a point cloud.

1. **Candidates**: :func:`csdf.detect_primitives` finds spheres, cylinders, cones,
   tori and boxes (each refined by :func:`csdf.fit` on its inliers).
2. **Structure**: a beam search over union / intersection / difference trees of the
   candidates (:mod:`.search`), scored on the candidates' exact distances at a sample
   of the points: a truncated quadratic of the residuals, a size penalty, and with a
   viewpoint the material put where the sensor saw free space (without one, the
   tree's surface where no point was measured).
3. **Parameters**: the best trees' continuous parameters (every primitive's sizes and
   position, named ``cylinder_1_radius``, ``cylinder_1_x``, ...) refined jointly by
   :func:`csdf.fit` (Levenberg-Marquardt on the exact parameter Jacobian of the whole
   tree, Huber loss at the noise level); the refined tree with the lowest score wins.

Deterministic for a seed. The orientations of the primitives are the detected ones
(not refined jointly).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from ..detect.neighbours import normals_arg, points_arg, viewpoint_arg
from ..detect.primitives import detect_primitives
from ..detect.solids import SOLID_BACKEND, SOLID_PARAMS, solid_values
from ..errors import CsdfError
from ..expr import param
from ..fit import fit
from ..lang.printer import dumps
from ..shapes import box, capped_cone, cylinder, sphere, torus
from ..shapes.domain import orient_matrix
from . import tree as T
from .search import Scorer, beam_search, polish, through_cuts

__all__ = ["infer", "InferResult", "SOLID_KINDS", "SEARCH_POINTS", "FIT_POINTS"]

#: the primitive kinds a tree is made of
SOLID_KINDS = ("box", "cylinder", "sphere", "cone", "torus")
#: points the structure search scores trees on (a seeded subsample)
SEARCH_POINTS = 4000
#: free-space points (with a viewpoint)
FREE_POINTS = 2000
#: points the joint refinement fits (a seeded subsample)
FIT_POINTS = 3000
#: trees refined jointly after the search
REFINE_TREES = 3
#: axes within this many degrees of a coordinate axis are turned onto it
SNAP_DEGREES = 1.0
#: a face of a detected box or cylinder with fewer inliers than this is moved out to the
#: cloud's extent in an extra candidate
EXTEND_BELOW = 10
#: points on each candidate's surface for the made-up-surface term (clouds without a
#: viewpoint)
SURFACE_SAMPLES = 150
#: trees kept per size in the beam
BEAM = 8
#: seconds the local polish of the refined trees may run past the time limit at most
POLISH_SECONDS = 5.0


@dataclass
class InferResult:
    """A model inferred from a point cloud.

    Attributes:
        shape: the csdf shape, with named parameters (``cylinder_1_radius``,
            ``cylinder_1_x``, ...) whose defaults are the fitted values.
        text: the model as ``.csdf`` text (:func:`csdf.dumps`).
        tree: the structure as infix text over the primitives' names
            (``(box_1 - cylinder_1)``).
        primitives: one dict per primitive of the tree: ``name``, ``kind``,
            ``rotation`` (3x3), ``translation`` (3,), and its size parameters.
        cost: the final score (see :mod:`csdf.infer.search`).
        rmse: root mean square distance of the points (scene units) to the model's
            surface, of the points within ``3 tau`` of it.
        inlier_fraction: the share of points within ``3 tau``.
        seconds: wall time.
        history: ``(seconds, primitives, cost, tree text)`` of each better tree found.
        candidates: the number of candidate primitives the search had.
    """

    shape: object
    text: str
    tree: str
    primitives: list[dict]
    cost: float
    rmse: float
    inlier_fraction: float
    seconds: float
    history: list[tuple] = field(default_factory=list)
    candidates: int = 0


@dataclass
class _Leaf:
    kind: str
    R: np.ndarray
    t: np.ndarray
    vals: dict


_AXIS_NAMES = {(0, 1): "x", (0, -1): "-x", (1, 1): "y", (1, -1): "-y", (2, 1): "z",
               (2, -1): "-z"}


def _snap(lf: _Leaf) -> _Leaf:
    """A leaf whose axes lie within :data:`SNAP_DEGREES` of the coordinate axes, turned
    onto them (CAD parts are mostly axis-aligned, and the model reads better: no
    rotation, or ``orient('x')``); others unchanged. A cylinder's, cone's or torus's
    turn about its own axis is dropped (it changes nothing)."""
    tol = math.sin(math.radians(SNAP_DEGREES))
    if lf.kind == "box":
        P = np.round(lf.R)
        if np.abs(lf.R - P).max() > tol or abs(abs(np.linalg.det(P)) - 1) > 1e-9 or \
                np.abs(P).sum() != 3:
            return lf
        sizes = [lf.vals[k] for k in ("size_x", "size_y", "size_z")]
        world = [sizes[int(np.argmax(np.abs(P[k])))] for k in range(3)]
        return _Leaf("box", np.eye(3), lf.t, dict(zip(("size_x", "size_y", "size_z"), world)))
    if lf.kind == "sphere":
        return _Leaf("sphere", np.eye(3), lf.t, lf.vals)
    a = lf.R[:, 2]
    k = int(np.argmax(np.abs(a)))
    if math.sqrt(max(0.0, 1.0 - a[k] ** 2)) <= tol:
        a = np.zeros(3)
        a[k] = 1.0 if lf.R[k, 2] > 0 or lf.kind != "cone" else -1.0
        if lf.kind != "cone" and a[k] < 0:
            a = -a
    return _Leaf(lf.kind, orient_matrix(a), lf.t, lf.vals)


def _kinds(kinds) -> tuple[str, ...]:
    if isinstance(kinds, str):
        kinds = [k.strip() for k in kinds.split(",") if k.strip()]
    ks = tuple(kinds)
    bad = [k for k in ks if k not in SOLID_KINDS]
    if bad or not ks:
        raise CsdfError(f"kinds must be some of {', '.join(SOLID_KINDS)}; got "
                        f"{', '.join(map(repr, bad)) or 'none'}")
    return ks


def _names(tree, leaves: list[_Leaf]) -> dict[int, str]:
    """``{leaf index: 'cylinder_1', ...}``: numbered per kind in the tree's leaf order."""
    count: dict[str, int] = {}
    out = {}
    for i in T.leaves(tree):
        k = leaves[i].kind
        count[k] = count.get(k, 0) + 1
        out[i] = f"{k}_{count[k]}"
    return out


def _leaf_shape(lf: _Leaf, name: str):
    """A leaf as a csdf shape: sizes and position as parameters named after ``name``."""
    p = {k: param(f"{name}_{k}", float(v), 0.0, math.inf) for k, v in lf.vals.items()}
    if lf.kind == "sphere":
        s = sphere(p["radius"])
    elif lf.kind == "cylinder":
        s = cylinder(p["radius"], p["height"])
    elif lf.kind == "cone":
        s = capped_cone(p["r1"], p["r2"], p["height"])
    elif lf.kind == "torus":
        s = torus(p["major"], p["minor"])
    else:
        s = box((p["size_x"], p["size_y"], p["size_z"]))
    a = lf.R[:, 2]
    if lf.kind in ("cylinder", "cone", "torus") and np.allclose(lf.R, orient_matrix(a),
                                                                atol=1e-15):
        k = int(np.argmax(np.abs(a)))
        if abs(a[k]) == 1.0:  # onto a coordinate axis: by name
            if k != 2 or a[k] < 0:
                s = s.orient(_AXIS_NAMES[(k, int(a[k]))])
        else:
            s = s.orient(tuple(float(v) for v in a))
    elif lf.kind != "sphere" and not np.allclose(lf.R, np.eye(3), atol=1e-12):
        s = s.rotate(np.asarray(lf.R, dtype=np.float64))
    pos = tuple(param(f"{name}_{a}", float(v)) for a, v in zip("xyz", lf.t))
    return s.translate(pos)


def _shape(tree, leaves: list[_Leaf]):
    names = _names(tree, leaves)
    return T.build(tree, lambda i: _leaf_shape(leaves[i], names[i])), names


def _free_points(P: np.ndarray, vp: np.ndarray, tau: float, rng, n: int) -> np.ndarray:
    """Points the sensor looked through: on the rays from ``vp`` to a sample of the
    points, at least ``3 tau`` in front of them."""
    idx = rng.choice(len(P), size=min(n, len(P)), replace=False)
    Q = P[idx]
    d = Q - vp
    r = np.linalg.norm(d, axis=1)
    ok = r > 6 * tau
    Q, d, r = Q[ok], d[ok], r[ok]
    u = rng.uniform(0.2, 1.0, size=len(Q)) * (1.0 - 3 * tau / r)
    return vp + u[:, None] * d


def _refine(tree, leaves: list[_Leaf], P: np.ndarray, tau: float, viewpoint, max_iter: int
            ) -> list[_Leaf]:
    """The tree's leaves after a joint fit of all their sizes and positions."""
    shape, names = _shape(tree, leaves)
    init = {"rotation": np.eye(3), "translation": np.zeros(3), "scale": 1.0}
    res = fit(shape, P, init=init, estimate=("params",), loss="huber", f_scale=tau / 3.0,
              escape=False, debias=False, backend=SOLID_BACKEND, max_iter=max_iter,
              viewpoint=viewpoint, check_ranges=False)
    out = list(leaves)
    for i, name in names.items():
        lf = leaves[i]
        vals = {k: max(float(res.params[f"{name}_{k}"]), 0.0) for k in SOLID_PARAMS[lf.kind]}
        t = np.array([res.params[f"{name}_{a}"] for a in "xyz"], dtype=np.float64)
        out[i] = _Leaf(lf.kind, lf.R, t, vals)
    return out


def _extended(lf: _Leaf, P: np.ndarray, inl: np.ndarray) -> _Leaf | None:
    """The box or cylinder ``lf`` with each face that holds few of its inliers moved out
    to the cloud ``P``'s extent along that axis (None when every face holds some, or
    for other kinds)."""
    if lf.kind not in ("box", "cylinder"):
        return None
    q = (inl - lf.t) @ lf.R  # the inliers in the solid's frame
    a = (P - lf.t) @ lf.R  # the cloud in the solid's frame
    axes = (0, 1, 2) if lf.kind == "box" else (2,)
    half = [lf.vals[k] / 2 for k in ("size_x", "size_y", "size_z")] if lf.kind == "box" \
        else [0.0, 0.0, lf.vals["height"] / 2]
    lo, hi = [-h for h in half], list(half)
    changed = False
    for k in axes:
        tol = 0.02 * max(2 * half[k], 1e-12)
        # points on the face itself, not on the faces around it near its edges
        if lf.kind == "box":
            inside = np.all([np.abs(q[:, j]) < half[j] - 0.02 * 2 * half[j]
                             for j in range(3) if j != k], axis=0)
        else:
            inside = np.hypot(q[:, 0], q[:, 1]) < 0.9 * lf.vals["radius"]
        if np.sum(inside & (np.abs(q[:, k] - hi[k]) <= tol)) < EXTEND_BELOW:
            hi[k], changed = max(hi[k], float(a[:, k].max())), True
        if np.sum(inside & (np.abs(q[:, k] - lo[k]) <= tol)) < EXTEND_BELOW:
            lo[k], changed = min(lo[k], float(a[:, k].min())), True
    if not changed:
        return None
    mid = np.array([(lo[k] + hi[k]) / 2 for k in range(3)])
    vals = dict(lf.vals)
    if lf.kind == "box":
        for k, name in enumerate(("size_x", "size_y", "size_z")):
            vals[name] = hi[k] - lo[k]
    else:
        vals["height"] = hi[2] - lo[2]
        mid[:2] = 0.0
    return _Leaf(lf.kind, lf.R, lf.t + lf.R @ mid, vals)


def _leaf_surface(lf: _Leaf, n: int, rng) -> np.ndarray:
    """``(n, 3)`` points on a leaf's surface: random points around it moved onto it along
    the exact distance's gradient (two steps)."""
    size = max(lf.vals.values())
    q = lf.t + rng.normal(0.0, size, (n, 3))
    for _ in range(2):
        f, g = solid_values(lf.kind, lf.R, lf.t, lf.vals, q)
        q = q - f[:, None] * g
    return q


def _refined(tree, leaves: list[_Leaf], P: np.ndarray, tau: float, viewpoint) -> list[_Leaf]:
    """:func:`_refine`, or the leaves unchanged when the joint fit fails."""
    try:
        return _refine(tree, leaves, P, tau, viewpoint, 40)
    except CsdfError:
        return leaves


def infer(points, normals=None, max_primitives: int = 8, kinds=SOLID_KINDS, viewpoint=None,
          time_limit: float = 30.0, seed: int = 0, *, epsilon: float | None = None,
          penalty: float | None = None) -> InferResult:
    """Infer a CSG tree of csdf primitives, with named parameters, from a point cloud.

    Args:
        points: ``(N, 3)`` points on the object's surface (scene units).
        normals: ``(N, 3)`` normals, or None to estimate them.
        max_primitives: the most primitives in the tree.
        kinds: the primitive kinds to use (some of ``'box'``, ``'cylinder'``,
            ``'sphere'``, ``'cone'``, ``'torus'``; names or one comma string).
        viewpoint: ``(3,)`` the sensor position of a single-view scan: estimated
            normals face it, and the search penalises material where the sensor saw
            through.
        time_limit: seconds; the search stops with the best tree found by then (the
            detection before it and one refinement after it may add a little).
        seed: equal seeds give equal results.
        epsilon: the noise level ``tau`` (scene units) of the score; default three
            times the detections' median rmse, at least ``1e-3`` of the cloud's
            diagonal.
        penalty: the cost of one more primitive; default the share of the points the
            smallest detection explains, halved, at least 0.002.

    Returns:
        :class:`InferResult`.

    Raises:
        CsdfError: bad arguments, or no primitive found in the cloud.
    """
    t0 = time.perf_counter()
    P = points_arg(points)
    if len(P) < 50:
        raise CsdfError(f"infer needs at least 50 points, got {len(P)}")
    N = None if normals is None else normals_arg(normals, P)
    vp = viewpoint_arg(viewpoint)
    ks = _kinds(kinds)
    if isinstance(max_primitives, bool) or not isinstance(max_primitives, (int, np.integer)) \
            or not 1 <= max_primitives <= 32:
        raise CsdfError(f"max_primitives must be an integer in [1, 32], got {max_primitives!r}")
    if not (isinstance(time_limit, (int, float)) and time_limit > 0):
        raise CsdfError(f"time_limit must be a positive number of seconds, got {time_limit!r}")
    rng = np.random.default_rng(seed)
    dets = detect_primitives(P, N, kinds=ks, seed=seed, viewpoint=vp,
                             max_primitives=max(3 * int(max_primitives), 12))
    dets = [d for d in dets if d.solid is not None]
    if not dets:
        raise CsdfError("infer: no primitive of the kinds "
                        f"{', '.join(ks)} found in the cloud")
    leaves = [_Leaf(d.solid[0], np.asarray(d.solid[1], float), np.asarray(d.solid[2], float),
                    dict(d.solid[3])) for d in dets]
    # a solid's faces that no point lies on may reach further than its inliers do (a
    # box cut by an intersection shows only what is inside the other operand): the
    # candidates also hold each box and cylinder with those faces out to the cloud's
    # extent
    through: dict[int, int] = {}
    for i, (d, lf) in enumerate(zip(dets, list(leaves))):
        v = _extended(lf, P, P[d.inliers])
        if v is not None:
            through[i] = len(leaves)
            leaves.append(v)
    leaves = [_snap(lf) for lf in leaves]
    diag = float(np.linalg.norm(P.max(axis=0) - P.min(axis=0)))
    if epsilon is None:
        tau = max(3.0 * float(np.median([d.rmse for d in dets])), 1e-3 * diag)
    else:
        if not (isinstance(epsilon, (int, float)) and epsilon > 0):
            raise CsdfError(f"epsilon must be a positive number, got {epsilon!r}")
        tau = float(epsilon)
    if penalty is None:
        penalty = max(0.5 * min(len(d.inliers) for d in dets) / len(P), 0.002)
    sample = np.sort(rng.choice(len(P), size=min(SEARCH_POINTS, len(P)), replace=False))
    S = P[sample]
    free = _free_points(P, vp, tau, rng, FREE_POINTS) if vp is not None else None

    def table(X: np.ndarray, lvs: list[_Leaf]) -> np.ndarray:
        return np.stack([solid_values(lf.kind, lf.R, lf.t, lf.vals, X)[0] for lf in lvs])

    tree_kd = cKDTree(P) if vp is None else None
    reach = 0.0
    if tree_kd is not None:  # how far a measured point may be from surface it supports
        d2, _ = tree_kd.query(S[: min(len(S), 2000)], k=2)
        reach = max(3.0 * tau, 3.0 * float(np.median(d2[:, 1])))

    def scorer_for(lvs: list[_Leaf]) -> Scorer:
        at_free = None if free is None else table(free, lvs)
        if tree_kd is None:
            return Scorer(table(S, lvs), at_free, tau, penalty)
        Q = np.concatenate([_leaf_surface(lf, SURFACE_SAMPLES, rng) for lf in lvs])
        far = tree_kd.query(Q, distance_upper_bound=reach)[0] > reach
        return Scorer(table(S, lvs), at_free, tau, penalty, table(Q, lvs), far)

    scorer = scorer_for(leaves)
    history: list = []
    found = beam_search(scorer, len(leaves), int(max_primitives), BEAM,
                        t0 + float(time_limit), history, t0)
    # joint refinement of the best few; each scored again with its own leaves, its
    # structure polished with them (local moves), and refined again if that changed it
    fit_idx = np.sort(rng.choice(len(P), size=min(FIT_POINTS, len(P)), replace=False))
    polish_until = t0 + float(time_limit) + POLISH_SECONDS
    best = None
    for cand in found[:REFINE_TREES]:
        lvs = _refined(cand.tree, leaves, P[fit_idx], tau, vp)
        scorer = scorer_for(lvs)
        sc = polish(scorer, cand.tree, len(lvs), int(max_primitives), polish_until)
        if T.canonical(sc.tree) != T.canonical(cand.tree):
            lvs = _refined(sc.tree, lvs, P[fit_idx], tau, vp)
            scorer = scorer_for(lvs)
            sc = scorer.score(sc.tree)
        if best is None or sc.total < best[0].total:
            best = (sc, lvs, scorer)
    assert best is not None
    sc, lvs, scorer = best
    # the winner's cuts go through where nothing shows their ends (search.through_cuts)
    swapped = through_cuts(scorer, sc.tree, through)
    if T.canonical(swapped.tree) != T.canonical(sc.tree):
        lvs2 = _refined(swapped.tree, lvs, P[fit_idx], tau, vp)
        sc2 = scorer_for(lvs2).score(swapped.tree)
        if sc2.total <= sc.total + 0.01 * penalty:
            sc, lvs = sc2, lvs2
    shape, names = _shape(sc.tree, lvs)
    label = names.__getitem__
    if not history or abs(history[-1][2] - sc.total) > 1e-15:
        history.append((time.perf_counter() - t0, T.size(sc.tree), sc.total, sc.tree))
    f = T.evaluate(sc.tree, table(P, lvs))
    near = np.abs(f) <= 3 * tau
    prims = []
    for i in T.leaves(sc.tree):
        lf = lvs[i]
        prims.append({"name": names[i], "kind": lf.kind, "rotation": lf.R.tolist(),
                      "translation": lf.t.tolist(), **lf.vals})
    hist = [(s, k, c, T.to_text(t, lambda i, t=t: _names(t, lvs)[i])) for s, k, c, t in
            history]
    return InferResult(
        shape=shape, text=dumps(shape), tree=T.to_text(sc.tree, label), primitives=prims,
        cost=sc.total, rmse=float(np.sqrt(np.mean(f[near] ** 2))) if near.any() else math.inf,
        inlier_fraction=float(near.mean()), seconds=time.perf_counter() - t0,
        history=hist, candidates=len(leaves))
