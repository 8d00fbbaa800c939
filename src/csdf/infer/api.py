"""``csdf.infer``: a parametric CSG model of csdf primitives from a point cloud.

1. **Candidates** (:mod:`.candidates`): :func:`csdf.detect_primitives` finds spheres,
   cylinders, cones, tori, boxes and planes; boxes are also assembled from the planes
   (a box cut or hidden in part shows as a few faces), a cylinder is also offered as a
   cone and a cone as a cylinder when that fits their points better, and boxes and
   cylinders also with their faces that hold no points moved out beyond the cloud,
   and a material cylinder or cone of the cloud's detection whose one cap holds no
   points with that cap moved in to its side's points, in place of itself
   (:data:`TRIM`); each curved detection is detected again on
   the points near it (:func:`_redetected`: a band seen from one side fits several
   axes); a small curved detection is also tried as planes (:func:`_corner_planes`).
   Each candidate knows from the points' normals whether it is material or a cut.
2. **Structure** (:mod:`.search`): a beam search over union / intersection /
   difference trees of the candidates, scored on the candidates' exact distances at a
   sample of the points: a truncated quadratic of the residuals (a point whose normal
   disagrees with the tree's is not explained), a size penalty, and the free space:
   with a viewpoint, material where the sensor saw through (towards its points and past
   the object's silhouette), without one the share of the tree's surface where no
   point was measured.
3. **Residuals**: the points the best tree leaves unexplained are searched for
   primitives again (a small feature the first detection missed, or took for part of
   another surface), all kinds together and each curved kind on its own with every
   curved detection kept (:func:`_residual`), and two such detections in different
   places as arcs of one torus (:func:`_joined`); the beam search resumes with those
   candidates too.
4. **Parameters**: the best trees' continuous parameters (every primitive's sizes and
   position, named ``cylinder_1_radius``, ``cylinder_1_x``, ..., and its orientation
   as turns about its own axes) refined jointly (:mod:`.refine`: Levenberg-Marquardt
   on the exact parameter Jacobian of the whole tree, a Cauchy loss at the noise
   level); the trees refined are the best of the best tree's size and of one leaf
   fewer or more, and the best of every other size; each refined tree is polished by
   local moves over all candidates and its own refined primitives, and refined again
   when that changed it; the lowest score wins. After the final face moves, leaves
   are dropped while that lowers the score (:func:`_drop_leaves`). A cone whose
   taper is within the noise is written as its cylinder (:func:`_straighten`).
5. **Alternatives**: the trees the points cannot tell from the winner (its trims and
   cuts applied elsewhere, scoring within :data:`INDISTINCT` of the penalty) are
   ``InferResult.alternatives``; ``prefer='local'`` or ``'global'`` returns the one
   whose trims and cuts reach the fewest or the most primitives (:func:`_preferred`).

The effort (beam width, trees refined) is fixed for a given ``time_limit``, so that a
seed gives the same result on any machine; the time limit stops the search early only
on a machine too slow for that effort.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from ..detect.neighbours import (
    K_NORMALS,
    distinct_points,
    neighbourhood,
    normals_arg,
    points_arg,
    viewpoint_arg,
)
from ..detect.primitives import detect_primitives
from ..detect.solids import SOLID_PARAMS
from ..errors import CsdfError
from ..expr import param
from ..lang.printer import dumps
from ..seeds import rng_arg
from ..shapes import box, capped_cone, cylinder, sphere, torus
from ..shapes.domain import orient_matrix
from . import tree as T
from .candidates import (
    Leaf,
    cap_cylinder,
    extended,
    face_moves,
    joined_torus,
    orientation,
    other_kind,
    plane_boxes,
    snap,
    trimmed,
)
from .pool import Pool, View, free_points, oriented_normals, support_scales
from .refine import refine_params, turn_matrix
from .search import (
    Scored,
    beam_search,
    consistent,
    evaluate_oriented,
    parities,
    polish,
    swap,
)

__all__ = ["infer", "InferResult", "SOLID_KINDS", "SEARCH_POINTS", "FIT_POINTS"]

#: the primitive kinds a tree is made of
SOLID_KINDS = ("box", "cylinder", "sphere", "cone", "torus")
#: points the structure search scores trees on (a seeded subsample)
SEARCH_POINTS = 4000
#: free-space points on the rays to measured points (with a viewpoint)
FREE_POINTS = 2000
#: free-space points on rays past the object's silhouette (with a viewpoint)
BACKGROUND_POINTS = 2000
#: curved detections of at most this many points are also tried as planes meeting at a
#: corner (:func:`_corner_planes`)
CORNER_MAX = 3000
#: the share of such a detection's points the planes must explain
CORNER_SHARE = 0.8
#: neighbours whose plane gives a point's normal when a single-view scan comes without
#: normals (detection's own default, 12, otherwise: measured on scans only). A scan's
#: noise is of the order of its point spacing (0.2 % of the diagonal against 0.3 % at
#: 640 x 480), so the normals of 12 neighbours are 8 degrees off (median; 21 at the
#: 90th percentile) and detection splits a cylinder into tangent planes and a cone;
#: with 24 they are 4 degrees off (the error falls as ``1 / k``) while an edge blurs
#: over about one more point spacing (benchmarks/INFER_RESULTS.md, session 17)
NORMAL_NEIGHBOURS = 24
#: points the joint refinement fits (a seeded subsample)
FIT_POINTS = 2000
#: free-space points the joint refinement keeps out of the material (with a viewpoint)
FIT_FREE_POINTS = 1500
#: shares of the time limit by which the search (beams, refinements) and the face moves
#: stop at the latest (the rest builds the result)
SEARCH_UNTIL, FACES_UNTIL = 0.85, 0.95
#: the cost of one primitive: it must explain more than this share of the points
PENALTY = 0.004
#: trees kept per size in the beam, per second of the time limit (at least 8)
BEAM_PER_SECOND = 0.5
#: trees refined jointly after the search, per second of the time limit (at least 3)
REFINE_PER_SECOND = 0.3
#: whether each curved detection of the cloud is detected again on the points near it
#: (:func:`_redetected`)
REDETECT = True
#: whether a material cylinder or cone of the whole cloud's detection whose one cap
#: holds no points is offered with that cap moved in to where its side's points end
#: (:func:`.candidates.trimmed`), in place of the detected one (its moved-out variant
#: stays). Session 19 offered it beside the detected one, for residual detections too
#: and with both caps moved: one view 2-5 lost 72 and 74. This way: 11 and 33 right,
#: 74 lost (an unseen tree the score prefers wrong); benchmarks/INFER_RESULTS.md,
#: session 21
TRIM = True
#: whether a detected plane of the whole cloud whose outline is in part a circle's arc
#: is also offered as the cap of a cylinder (:func:`.candidates.cap_cylinder`)
CAP_CYLINDERS = True
#: rounds of detection on the points the best tree leaves unexplained
RESIDUAL_ROUNDS = 2
#: the fewest unexplained points a residual detection looks at
RESIDUAL_MIN = 30
#: the most detections of one curved kind on the unexplained points
#: (:func:`_residual`: each kind on its own, besides all kinds together)
RESIDUAL_PER_KIND = 3
#: whether two curved detections among the unexplained points (of one residual round
#: or of two) are also tried as arcs of one torus (:func:`_joined`)
JOIN_TORI = True
#: rounds of dropping each leaf of the best tree and refining the rest
DROP_ROUNDS = 1
#: the evaluator of the joint refinement: the interpreter, as every tree refined is a
#: new program (the compiled evaluator compiles a kernel per tree: seconds each, far
#: more than the refinement's evaluations cost; 2-3x slower than a cached kernel)
REFINE_BACKEND = "interp"
#: rounds of moving the best tree's faces (:func:`_move_faces`)
FACE_ROUNDS = 3
#: trees whose scores differ by less than this share of the penalty are ones the
#: points cannot tell apart (:func:`_indistinct`): under one point in 4,000
INDISTINCT = 0.05
#: the most trees :func:`_indistinct` returns, and the most it scores (a second or so)
ALTERNATIVES, ALTERNATIVE_SCORES = 32, 2500


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
        searched: the tree as the search found it (the primitives' names as in
            ``tree``): ``tree`` itself unless ``prefer`` chose another.
        alternatives: the trees the points cannot tell from ``searched`` (its leaves
            with trims or cuts applied elsewhere, scoring within :data:`INDISTINCT` of
            the penalty), ``searched`` first, then best score first.
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
    searched: str = ""
    alternatives: list[str] = field(default_factory=list)


_AXIS_NAMES = {(0, 1): "x", (0, -1): "-x", (1, 1): "y", (1, -1): "-y", (2, 1): "z",
               (2, -1): "-z"}


def _detect_primitives(*args, **kwargs) -> list:
    """:func:`csdf.detect_primitives` on the points in their given order
    (``reorder=False``): inference's measured results (``benchmarks/INFER_RESULTS.md``)
    were made so, and the Morton order's other random draws would need that benchmark
    run again."""
    return detect_primitives(*args, reorder=False, **kwargs)


def _kinds(kinds) -> tuple[str, ...]:
    if isinstance(kinds, str):
        kinds = [k.strip() for k in kinds.split(",") if k.strip()]
    ks = tuple(kinds)
    bad = [k for k in ks if k not in SOLID_KINDS]
    if bad or not ks:
        raise CsdfError(f"kinds must be some of {', '.join(SOLID_KINDS)}; got "
                        f"{', '.join(map(repr, bad)) or 'none'}")
    return ks


def _names(tree, leaves: list[Leaf]) -> dict[int, str]:
    """``{leaf index: 'cylinder_1', ...}``: numbered per kind in the tree's leaf order."""
    count: dict[str, int] = {}
    out = {}
    for i in T.leaves(tree):
        k = leaves[i].kind
        count[k] = count.get(k, 0) + 1
        out[i] = f"{k}_{count[k]}"
    return out


#: a cone whose two radii differ by less than this share of the larger is written as
#: the cylinder it is (the same solid)
STRAIGHT_CONE = 1e-6


def _straight_cones(leaves: list[Leaf], used) -> list[Leaf]:
    """``leaves`` with each cone of ``used`` (indices) whose radii are equal (to
    :data:`STRAIGHT_CONE`) replaced by the same solid as a cylinder, so that a straight
    hole is reported as ``cylinder_1``, not as ``cone_1`` with ``r1 = r2``. The cone's
    frame starts at its base; the cylinder's is centred."""
    out = list(leaves)
    for i in used:
        lf = out[i]
        if lf.kind != "cone":
            continue
        r1, r2 = lf.vals["r1"], lf.vals["r2"]
        if abs(r1 - r2) <= STRAIGHT_CONE * max(r1, r2):
            out[i] = _cylinder_of(lf).moved(origin=lf.origin)
    return out


def _cylinder_of(lf: Leaf) -> Leaf:
    """The cylinder of a cone ``lf``'s axis, height and mean radius (the cone's frame
    starts at its base; the cylinder's is centred): within ``|r1 - r2| / 2`` of the
    cone everywhere."""
    r1, r2, h = lf.vals["r1"], lf.vals["r2"], lf.vals["height"]
    return lf.moved(kind="cylinder", t=lf.t + lf.R[:, 2] * (0.5 * h),
                    vals={"radius": 0.5 * (r1 + r2), "height": h},
                    origin=lf.origin + "+straight")


#: a cone whose surface lies within this share of ``tau`` of its cylinder's
#: (:func:`_straighten`): about one standard deviation of the points' noise, as
#: ``tau`` is three times the detections' rmse
TAPER_NOISE = 1.0 / 3.0


def _straighten(prob: _Problem, best: Scored) -> Scored:
    """``best`` with each cone replaced by its cylinder (:func:`_cylinder_of`, one size
    fewer) when the taper is not a finding: the cone's surface lies within the noise
    of the cylinder's (``|r1 - r2| / 2`` at most :data:`TAPER_NOISE` ``tau``: no
    point can show it, and a fit on thousands of points finds such a taper in any
    slight bias of the noise), or the tree with the cylinder scores within
    :data:`INDISTINCT` of the penalty of ``best``'s score (the points cannot tell the
    two apart). Tried cone by cone, each against the tree as it stands."""
    pool = prob.pool
    for c in sorted(set(T.leaves(best.tree))):
        lf = pool.leaves[c]
        if lf.kind != "cone" or "cylinder" not in prob.ks:
            continue
        v = pool.add([_cylinder_of(lf)])[0]
        sc = pool.scorer().score(swap(best.tree, c, v))
        flat = 0.5 * abs(lf.vals["r1"] - lf.vals["r2"]) <= TAPER_NOISE * prob.tau
        if flat or sc.total <= best.total + INDISTINCT * pool.penalty:
            best = sc
    return best


#: the turn angles (radians) the joint refinement gives each kind of leaf
#: (:func:`.refine.turn_matrix`): about its own x and y axes (a tilt of a cylinder's,
#: cone's or torus's axis; a turn about that axis changes nothing), a box also about z
TURNS = {"box": ("x", "y", "z"), "cylinder": ("x", "y"), "cone": ("x", "y"),
         "torus": ("x", "y"), "sphere": ()}


def _leaf_shape(lf: Leaf, name: str, turn: bool = False):
    """A leaf as a csdf shape: sizes and position as parameters named after ``name``;
    with ``turn``, also the leaf's turn angles :data:`TURNS` (``{name}_turn_x``, ...,
    radians, 0 here) about its own axes, for the joint refinement."""
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
    if turn:  # about z first, then x, then y (turn_matrix's order)
        for ax in sorted(TURNS[lf.kind], key="zxy".index):
            s = s.rotate(param(f"{name}_turn_{ax}", 0.0), ax)
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


def _shape(tree, leaves: list[Leaf], turn: bool = False):
    names = _names(tree, leaves)
    return T.build(tree, lambda i: _leaf_shape(leaves[i], names[i], turn)), names


@dataclass
class _Problem:
    """One inference's data.

    Attributes:
        P: ``(N, 3)`` the points (scene units); ``N`` ``(N, 3)`` their outward normals
            or None (unknown sign).
        vp: ``(3,)`` the viewpoint or None.
        ks: the primitive kinds.
        fit_points: ``(F, 3)`` the sample of the points the joint refinement fits;
            ``fit_normals`` their outward normals or None; ``fit_free`` ``(G, 3)`` the
            free-space points it keeps out of the material, or None.
        tau: the noise level of the score (scene units).
        diag: the cloud's bounding diagonal (scene units).
        spacing: the median distance between neighbouring points (scene units).
        pool: the candidates and their score tables.
        rng: the seeded generator of the run.
        seed: the run's seed.
        pieces: the curved detections among the points earlier trees left
            unexplained (:func:`_residual`), as ``(inlier indices into P (K,), rmse)``.
    """

    P: np.ndarray
    N: np.ndarray | None
    vp: np.ndarray | None
    ks: tuple[str, ...]
    fit_points: np.ndarray
    fit_normals: np.ndarray | None
    fit_free: np.ndarray | None
    tau: float
    diag: float
    spacing: float
    pool: Pool
    rng: np.random.Generator
    seed: int
    pieces: list = field(default_factory=list)

    def tree_values(self, tree, X: np.ndarray) -> np.ndarray:
        """``(len(X),)`` the tree's field at points ``X`` ``(M, 3)``."""
        used = T.leaves(tree)
        vals = np.zeros((len(self.pool.leaves), len(X)))
        for i in set(used):
            vals[i] = self.pool.leaves[i].values(X)[0]
        return T.evaluate(tree, vals)


def _candidates(prob: _Problem, dets: list, sub: np.ndarray, eps: float,
                corners: bool = True, redetect: bool = False, trim: bool = False
                ) -> list[Leaf]:
    """Candidate leaves from detections ``dets`` made on the points ``P[sub]``: the solids
    (and a cylinder's cone, a cone's cylinder), boxes from the planes, each box and
    cylinder also with its point-less faces moved out. ``eps``: the detections' inlier
    distance; ``corners``: whether small curved detections are also tried as planes
    (:func:`_corner_planes`); ``redetect``: whether each curved solid's kind is also
    detected again on the points of ``sub`` within ``eps`` of it (:func:`_redetected`);
    ``trim``: whether a material cylinder or cone whose one cap holds no points comes
    with that cap moved in to its side's points (:func:`.candidates.trimmed`) in place
    of itself (the whole cloud's detection only, both: :data:`TRIM`)."""
    P, N = prob.P, prob.N
    out: list[tuple[Leaf, Leaf | None]] = []  # (leaf, its variant moved out)

    def sign_of(lf: Leaf, inl: np.ndarray) -> int:
        return 0 if N is None else orientation(lf, P[inl], N[inl])

    planes = []
    for d in dets:
        inl = sub[d.inliers]
        if d.kind == "plane":
            planes.append((np.asarray(d.params["normal"], float), float(d.params["offset"]),
                           P[inl]))
            continue
        if d.solid is None or d.kind not in prob.ks:
            continue
        lf = Leaf(d.solid[0], np.asarray(d.solid[1], float), np.asarray(d.solid[2], float),
                  dict(d.solid[3]))
        lf = lf.moved(sign=sign_of(lf, inl))
        alt = other_kind(lf, P[inl], d.rmse, eps)
        for c in (lf, alt):
            if c is not None and c.kind in prob.ks:
                cut = None
                if trim and c.sign > 0 and c.kind in ("cylinder", "cone"):
                    near = sub[np.abs(c.values(P[sub])[0]) <= eps]
                    cut = trimmed(c, P[near], eps)
                out.append((snap(c if cut is None else cut),
                            _snapped(extended(c, P, P[inl]))))
        if redetect:
            near = sub[np.abs(lf.values(P[sub])[0]) <= eps]
            for c, ci in _redetected(prob, lf, near, eps):
                out.append((snap(c), _snapped(extended(c, P, P[ci]))))
    caps: list[Leaf] = []
    if trim and CAP_CYLINDERS and "cylinder" in prob.ks and N is not None:
        cyls = [lf for lf, _ in out if lf.kind == "cylinder"]
        for nrm, _, Q in planes:
            c = cap_cylinder(nrm, Q, P, prob.spacing, prob.seed)
            if c is not None and not any(_same_cylinder(c, o) for o in cyls + caps):
                caps.append(snap(c))
    if "box" in prob.ks:
        for d in dets if corners else ():
            if d.kind in ("sphere", "cylinder", "cone", "torus"):
                planes += _corner_planes(prob, sub[d.inliers], d.rmse, eps)
        out += [(snap(b), None) for b in plane_boxes(planes, P, eps, 4.0 * prob.spacing)]
    leaves: list[Leaf] = []
    for lf, v in out:
        leaves.append(lf)
        if v is not None:
            leaves.append(v)
    return leaves + caps


def _same_cylinder(a: Leaf, b: Leaf) -> bool:
    """Whether two cylinders share their axis (within 5 degrees and a fifth of the
    radius) and radius (15 %)."""
    if abs(float(a.R[:, 2] @ b.R[:, 2])) < math.cos(math.radians(5.0)):
        return False
    ra, rb = a.vals["radius"], b.vals["radius"]
    if abs(ra - rb) > 0.15 * max(ra, rb):
        return False
    d = b.t - a.t
    off = d - (d @ a.R[:, 2]) * a.R[:, 2]
    return float(np.linalg.norm(off)) <= 0.2 * max(ra, rb)


#: curved detections (cylinder, cone, torus) with at least this many points within the
#: inlier distance are detected again on those points alone (:func:`_redetected`; on
#: the detection's own inliers the cones found were 69 and 88 degrees off, not 10)
REDETECT_MIN = 200
#: the most detections of that kind on them
REDETECT_MAX = 3
#: a detection again is kept when its axis is this many degrees or more off the
#: detection's (and off every one kept before)
REDETECT_DEGREES = 5.0
#: ... and it holds at least this share of the points
REDETECT_SHARE = 0.3


def _redetected(prob: _Problem, lf: Leaf, inl: np.ndarray, eps: float
                ) -> list[tuple[Leaf, np.ndarray]]:
    """Solids of ``lf``'s kind (a cylinder, cone or torus) detected again on the points
    ``P[inl]`` near it alone (``inl`` ``(K,)`` indices), each with its own inliers ``(K',)``
    (indices into ``P``): a band of a cone or a torus seen from one side fits solids of
    several axes within the noise, and detection on the whole cloud takes the first it
    samples; on the band alone it samples more of them. Kept: those whose axis is at
    least :data:`REDETECT_DEGREES` off ``lf``'s and every other kept one's, holding
    :data:`REDETECT_SHARE` of those points. ``eps``: the inlier distance (scene
    units)."""
    if lf.kind not in ("cylinder", "cone", "torus") or len(inl) < REDETECT_MIN:
        return []
    P, N = prob.P, prob.N
    try:
        dets = _detect_primitives(P[inl], None if N is None else N[inl], kinds=(lf.kind,),
                                 epsilon=eps, seed=prob.seed, viewpoint=prob.vp,
                                 min_points=max(RESIDUAL_MIN,
                                                int(REDETECT_SHARE * len(inl))),
                                 max_primitives=REDETECT_MAX, flat_share=1.0)
    except CsdfError:
        return []
    cos_tol = math.cos(math.radians(REDETECT_DEGREES))
    axes = [lf.R[:, 2]]
    out = []
    for d in dets:
        if d.solid is None or d.solid[0] != lf.kind:
            continue
        new = Leaf(d.solid[0], np.asarray(d.solid[1], float), np.asarray(d.solid[2], float),
                   dict(d.solid[3]), origin="redetected")
        a = new.R[:, 2]
        if any(abs(float(a @ b)) >= cos_tol for b in axes):
            continue
        ci = inl[d.inliers]
        axes.append(a)
        out.append((new.moved(sign=0 if N is None else orientation(new, P[ci], N[ci])), ci))
    return out


def _corner_planes(prob: _Problem, idx: np.ndarray, rmse: float, eps: float) -> list:
    """Planes ``[(normal (3,), offset, inliers (K, 3))]`` that explain the points
    ``P[idx]`` of a curved detection better than it does: a small notch shows as two
    or three faces at right angles, which a cylinder (or a cone, a sphere) fitted to
    them follows within a few noise levels, so detection may take it for one. Kept
    when at least two planes explain :data:`CORNER_SHARE` of the points with a
    smaller rmse than the curved fit's ``rmse`` (scene units; ``eps`` the inlier
    distance). Only for detections of at most :data:`CORNER_MAX` points and outward
    normals."""
    if prob.N is None or not 2 * RESIDUAL_MIN <= len(idx) <= CORNER_MAX:
        return []
    Q, NQ = prob.P[idx], prob.N[idx]
    try:
        found = _detect_primitives(Q, NQ, kinds=("plane",), epsilon=eps,
                                  min_points=max(RESIDUAL_MIN, len(idx) // 10),
                                  seed=prob.seed, viewpoint=prob.vp, max_primitives=3)
    except CsdfError:
        return []
    found = [d for d in found if d.kind == "plane"]
    if len(found) < 2 or sum(len(d.inliers) for d in found) < CORNER_SHARE * len(idx) or \
            max(d.rmse for d in found) >= rmse:
        return []
    return [(np.asarray(d.params["normal"], float), float(d.params["offset"]), Q[d.inliers])
            for d in found]


def _snapped(lf: Leaf | None) -> Leaf | None:
    return None if lf is None else snap(lf)


def _setup(P: np.ndarray, N: np.ndarray | None, vp: np.ndarray | None, ks: tuple[str, ...],
           max_primitives: int, seed: int, epsilon, penalty) -> _Problem:
    """Normals, detection, candidates, the noise level, penalty and score samples."""
    rng = rng_arg(seed)
    k = NORMAL_NEIGHBOURS if N is None and vp is not None else K_NORMALS
    nb = neighbourhood(P, k=k, viewpoint=vp, want_normals=N is None)
    estimated = N is None
    if N is None:  # estimated: oriented when turned to a viewpoint
        N_det = nb.normals
        N = nb.normals if vp is not None else None
    else:  # given: detection ignores their signs, the score needs them outward
        oriented = oriented_normals(P, N)
        N_det = N if oriented is None else oriented
        N = oriented
    det_kinds = tuple(ks) + (("plane",) if "box" in ks else ())
    dets = _detect_primitives(P, N_det, kinds=det_kinds, seed=seed, viewpoint=vp,
                             max_primitives=max(3 * max_primitives, 12))
    solids = [d for d in dets if d.solid is not None]
    if not solids and not any(d.kind == "plane" for d in dets):
        raise CsdfError("infer: no primitive of the kinds "
                        f"{', '.join(ks)} found in the cloud")
    diag = float(np.linalg.norm(P.max(axis=0) - P.min(axis=0)))
    rmse = [d.rmse for d in dets] or [0.0]
    if epsilon is None:
        tau = max(3.0 * float(np.median(rmse)), 1e-3 * diag)
    else:
        if not (isinstance(epsilon, (int, float)) and epsilon > 0):
            raise CsdfError(f"epsilon must be a positive number, got {epsilon!r}")
        tau = float(epsilon)
    if penalty is None:
        penalty = PENALTY
    sample = np.sort(rng.choice(len(P), size=min(SEARCH_POINTS, len(P)), replace=False))
    S = P[sample]
    NS = None if N is None else N[sample]
    free = view = None
    if vp is not None:
        view = View(P, vp, rng)
        free = np.concatenate([free_points(P, vp, tau, diag, rng, FREE_POINTS),
                               view.background(diag, rng, BACKGROUND_POINTS)])
    kd = cKDTree(P)
    reach, area = support_scales(kd, S, len(P), tau, NS, vp)
    pool = Pool(S, NS, free, kd, N, reach, area, tau, float(penalty), rng, view, estimated)
    fit_idx = np.sort(rng.choice(len(P), size=min(FIT_POINTS, len(P)), replace=False))
    fit_free = None if free is None else free[np.sort(rng.choice(
        len(free), size=min(FIT_FREE_POINTS, len(free)), replace=False))]
    prob = _Problem(P, N, vp, ks, P[fit_idx], None if N is None else N[fit_idx], fit_free,
                    tau, diag,
                    nb.spacing, pool, rng, seed)
    eps = max(3.0 * float(np.median(rmse)), 1e-4 * diag)
    leaves = _candidates(prob, dets, np.arange(len(P)), eps, redetect=REDETECT, trim=TRIM)
    if not leaves:
        raise CsdfError("infer: no primitive of the kinds "
                        f"{', '.join(ks)} found in the cloud")
    prob.pool.add(leaves)
    return prob


#: whether the joint refinement also turns the leaves (:data:`TURNS`;
#: :func:`_refined_tree`)
REFINE_TURNS = True


def _refine(prob: _Problem, tree, turn: bool = False) -> dict[int, Leaf]:
    """The tree's leaves after a joint fit of all their sizes, positions and (with
    ``turn``) orientations (:func:`.refine.refine_params` on the fit
    sample and, with a viewpoint, the free-space points): ``{leaf index: refined
    Leaf}`` (unchanged when the fit fails). A turned leaf's axes within
    :data:`.candidates.SNAP_DEGREES` of the coordinate axes are turned onto them, as
    a detection's are (:func:`.candidates.snap`)."""
    leaves = prob.pool.leaves
    shape, names = _shape(tree, leaves, turn)
    values: dict[str, float] = {}
    sizes: set[str] = set()
    turns: set[str] = set()
    for i, name in names.items():
        lf = leaves[i]
        for k in SOLID_PARAMS[lf.kind]:
            values[f"{name}_{k}"] = float(lf.vals[k])
            sizes.add(f"{name}_{k}")
        for a, v in zip("xyz", lf.t):
            values[f"{name}_{a}"] = float(v)
        for ax in TURNS[lf.kind] if turn else ():
            values[f"{name}_turn_{ax}"] = 0.0
            turns.add(f"{name}_turn_{ax}")
    try:
        res = refine_params(shape, values, sizes, prob.fit_points, prob.fit_normals,
                            prob.fit_free, prob.tau, REFINE_BACKEND, turns)
    except (CsdfError, np.linalg.LinAlgError):
        return {i: leaves[i] for i in names}
    out = {}
    for i, name in names.items():
        lf = leaves[i]
        vals = {k: float(res[f"{name}_{k}"]) for k in SOLID_PARAMS[lf.kind]}
        t = np.array([res[f"{name}_{a}"] for a in "xyz"], dtype=np.float64)
        ang = {ax: float(res.get(f"{name}_turn_{ax}", 0.0)) for ax in "xyz"}
        if not (np.all(np.isfinite(t)) and all(np.isfinite(v) for v in vals.values())
                and all(np.isfinite(v) for v in ang.values())):
            return {i: leaves[i] for i in names}
        new = lf.moved(t=t, vals=vals, origin="refined")
        if any(ang.values()):
            new = _turned(new, ang["x"], ang["y"], ang["z"])
        out[i] = new
    return out


def _turned(lf: Leaf, ax: float, ay: float, az: float) -> Leaf:
    """``lf`` turned about its own axes by the refinement's angles (radians,
    :func:`.refine.turn_matrix`); a cylinder's, cone's or torus's frame then is
    :func:`orient_matrix` of its axis (its turn about the axis changes nothing), and
    axes within :data:`.candidates.SNAP_DEGREES` of the coordinate axes are turned
    onto them (:func:`.candidates.snap`). The frame's origin stays where it is."""
    R = lf.R @ turn_matrix(ax, ay, az)
    if lf.kind in ("cylinder", "cone", "torus"):
        R = orient_matrix(R[:, 2])
    return snap(lf.moved(R=R))


def _refine_and_polish(prob: _Problem, tree, maxp: int, deadline: float,
                       polish_below: float = math.inf) -> Scored:
    """``tree`` refined jointly, polished by local moves (:func:`search.polish`) over
    every candidate and its refined leaves, and refined again when that changed it.
    Not polished when the refined tree scores ``polish_below`` or more (a tree refined
    only in case its refinement makes it the best)."""
    pool = prob.pool
    sc = pool.scorer().score(tree)
    for _ in range(2):
        tree = _refined_tree(prob, tree)
        if polish_below < math.inf:
            sc = pool.scorer().score(tree)
            if sc.total >= polish_below:
                return sc
        sc = polish(pool.scorer(), tree, list(range(len(pool.leaves))), maxp, deadline,
                    pool.kinds)
        if T.normal_form(sc.tree) == T.normal_form(tree):
            break
        tree = sc.tree
    return sc


def _refined_tree(prob: _Problem, tree):
    """The tree over its jointly refined leaves (added to the pool): sizes and
    positions first; then (:data:`REFINE_TURNS`, a tree with a leaf other than a
    sphere) orientations too, from there, kept when the tree then scores lower. The
    refinement's objective knows the points, not the made-up surface: with more
    freedom it can move an end no point holds (a hole's end into the part it should
    pass through), so the score decides."""
    new = _refine(prob, tree, False)
    keys = list(new)
    idx = prob.pool.add([new[k] for k in keys])
    out = T.relabel(tree, dict(zip(keys, idx)))
    if REFINE_TURNS and any(TURNS[prob.pool.leaves[i].kind] for i in T.leaves(out)):
        new = _refine(prob, out, True)
        keys = list(new)
        idx = prob.pool.add([new[k] for k in keys])
        turned = T.relabel(out, dict(zip(keys, idx)))
        scorer = prob.pool.scorer()
        if scorer.score(turned).total < scorer.score(out).total - 1e-12:
            out = turned
    return _cuts_through(prob, out) if REFINE_THROUGH else out


#: whether :func:`_refined_tree` moves the faces of each refined cut
#: (:func:`_cuts_through`)
REFINE_THROUGH = True


def _cuts_through(prob: _Problem, tree):
    """``tree`` with faces of its cut boxes and caps of its cut cylinders (under an odd
    number of differences' right operands) moved (:func:`.candidates.face_moves`: by
    shares of the size, or out to the cloud's extent), the best move of each cut at a
    time, up to :data:`FACE_ROUNDS` of them, while it lowers the score. The
    refinement fits a cut's faces to the points on them and leaves a face with none
    where it was, as its objective knows nothing of the made-up surface: a hole
    drilled into one part of a union, whose far end no point shows, was refined short,
    leaving a skin of that part where the sensor saw none (made-up surface of four
    penalties: benchmarks/INFER_RESULTS.md, session 18, one-view tree 86), and the
    search then preferred the hole drilled through the whole union."""
    pool = prob.pool
    best = pool.scorer().score(tree)
    for c, odd in sorted(parities(tree).items()):
        lf = pool.leaves[c]
        if not odd or lf.kind not in ("box", "cylinder"):
            continue
        for _ in range(FACE_ROUNDS):
            moved = _best_move(prob, best, c)
            if moved is None:
                break
            best, c = moved
    return best.tree


def _best_move(prob: _Problem, best: Scored, c: int) -> tuple[Scored, int] | None:
    """``best`` with its leaf ``c`` (a box or cylinder) replaced by the best of its face
    moves (:func:`.candidates.face_moves`, scored by :meth:`.pool.Pool.trial`),
    added to the pool, and the leaf's new index; None when no move lowers the score.
    The winner's score is taken again once it is added (its surface points drawn
    anew), and it is kept only when that is lower too."""
    pool = prob.pool
    moves = face_moves(pool.leaves[c], prob.P)
    if not moves:
        return None
    # only a move scoring below the tree's score can be taken
    scores = pool.trial(best.tree, c, moves, best.total - 1e-9)
    live = [(s.total, j) for j, s in enumerate(scores) if s is not None]
    if not live:
        return None
    j = min(live)[1]  # the first of the lowest
    v = pool.add([moves[j]])[0]
    sc = pool.scorer().score(swap(best.tree, c, v))
    if sc.total >= best.total - 1e-9:
        return None
    return sc, v


def _residual(prob: _Problem, tree) -> list[Leaf]:
    """Candidates detected among the points ``tree`` leaves unexplained (farther than
    ``2 tau`` from its surface, or on it with the normal the other way): by one
    detection of all kinds, and by one of each curved kind alone (at most
    :data:`RESIDUAL_PER_KIND` detections each) that keeps every curved detection
    (``flat_share=1``); and tori through two of the curved detections of this round
    and earlier ones (:func:`_joined`)."""
    P, N = prob.P, prob.N
    used = sorted(set(T.leaves(tree)))
    vals = np.zeros((len(prob.pool.leaves), len(P)))
    dots = None if N is None else np.zeros_like(vals)
    for i in used:
        f, g = prob.pool.leaves[i].values(P)
        vals[i] = f
        if dots is not None:
            dots[i] = np.einsum("ij,ij->i", g, N)
    f, d = evaluate_oriented(tree, vals, dots)
    bad = np.abs(f) > 2 * prob.tau
    if d is not None:
        bad |= d <= 0
    sub = np.flatnonzero(bad)
    if len(sub) < RESIDUAL_MIN:
        return []
    det_kinds = tuple(prob.ks) + (("plane",) if "box" in prob.ks else ())
    NS = None if N is None else N[sub]
    try:
        dets = _detect_primitives(P[sub], NS, kinds=det_kinds, seed=prob.seed,
                                 viewpoint=prob.vp, min_points=RESIDUAL_MIN,
                                 max_primitives=12)
    except CsdfError:
        dets = []
    out = _candidates(prob, dets, sub, prob.tau)
    pieces = _pieces(dets, sub)
    # each curved kind on its own, every curved detection kept: detection prefers the
    # simpler kind (two cylinders along a torus's groove) and drops a curved patch that
    # one plane explains more than half of (a shallow spherical or conical notch);
    # the score decides between them
    for kind in ("sphere", "cylinder", "cone", "torus"):
        if kind not in prob.ks:
            continue
        try:
            dets = _detect_primitives(P[sub], NS, kinds=(kind,), seed=prob.seed,
                                     viewpoint=prob.vp, min_points=RESIDUAL_MIN,
                                     max_primitives=RESIDUAL_PER_KIND, flat_share=1.0)
        except CsdfError:
            continue
        out += _candidates(prob, dets, sub, prob.tau, corners=False)
        pieces += _pieces(dets, sub)
    return out + _joined(prob, pieces, out)


def _pieces(dets: list, sub: np.ndarray) -> list[tuple[np.ndarray, float]]:
    """The curved detections of ``dets`` (made on the points ``P[sub]``) as
    ``(inlier indices into P (K,), rmse)``."""
    return [(sub[d.inliers], float(d.rmse)) for d in dets
            if d.kind in ("sphere", "cylinder", "cone", "torus")]


#: a joined torus is not offered when this share of its two patches' points is in a
#: joined torus offered before (of more points): the same two places
JOIN_SAME = 0.5


def _joined(prob: _Problem, new: list[tuple[np.ndarray, float]], others: list[Leaf]
            ) -> list[Leaf]:
    """Tori through two separate patches (:func:`.candidates.joined_torus`): each of
    the curved detections ``new`` (``(inlier indices into P, rmse)``, of one residual
    round) with each earlier one (:attr:`_Problem.pieces`, which then holds ``new``
    too) and each other one of ``new``, where they share no point (two detections of
    one patch, as the kinds on their own give, are not two places). A torus groove
    across an object shows as separate arcs, each too short to fix its ring, and the
    detections that take each arc for a cut leave the other unexplained, for a later
    round. One torus per two places: of those sharing :data:`JOIN_SAME` of their
    points, the one of the most points; none where a candidate torus of that ring
    exists (in the pool, or among ``others``: :func:`_same_torus`). Only with outward
    normals and tori among the kinds (:data:`JOIN_TORI`)."""
    if not JOIN_TORI or "torus" not in prob.ks or prob.N is None:
        return []
    P, N = prob.P, prob.N
    found: list[tuple[Leaf, np.ndarray]] = []
    for j, (ib, rb) in enumerate(new):
        for ia, ra in prob.pieces + new[:j]:
            if np.intersect1d(ia, ib).size:
                continue
            lf = joined_torus(P[ia], P[ib], N[ia], N[ib], max(ra, rb), prob.tau)
            if lf is not None:
                found.append((lf, np.union1d(ia, ib)))
    prob.pieces = prob.pieces + new
    out: list[tuple[Leaf, np.ndarray]] = []
    for lf, pts in sorted(found, key=lambda x: -len(x[1])):  # stable: ties as found
        if all(np.intersect1d(pts, q).size < JOIN_SAME * len(pts) for _, q in out):
            out.append((lf, pts))
    tori = [lf for lf in prob.pool.leaves + others if lf.kind == "torus"]
    return [snap(lf) for lf, _ in out if not any(_same_torus(lf, o) for o in tori)]


def _same_torus(a: Leaf, b: Leaf) -> bool:
    """Whether two tori share their ring and tube: axes within 5 degrees, centres
    within a fifth of the larger minor radius, major and minor radii within 15 %."""
    if abs(float(a.R[:, 2] @ b.R[:, 2])) < math.cos(math.radians(5.0)):
        return False
    big = {k: max(a.vals[k], b.vals[k]) for k in ("major", "minor")}
    if any(abs(a.vals[k] - b.vals[k]) > 0.15 * big[k] for k in big):
        return False
    return float(np.linalg.norm(a.t - b.t)) <= 0.2 * big["minor"]


def _move_faces(prob: _Problem, best: Scored, deadline: float, rounds: int = FACE_ROUNDS
                ) -> Scored:
    """``best`` with faces of its boxes and caps of its cylinders moved
    (:func:`.candidates.face_moves`) while that lowers the score: the joint refinement
    fits faces to the points on them, but leaves a face with none where it was, though
    it may make up surface there (a box's back reaching too little into the part it
    is joined to). Stops at ``deadline`` (a ``time.perf_counter()``)."""
    for _ in range(rounds):
        start = best
        for c in T.leaves(start.tree):
            if c not in T.leaves(best.tree) or time.perf_counter() > deadline:
                continue
            moved = _best_move(prob, best, c)
            if moved is not None:
                best = moved[0]
        if best is start:
            break
    return best


def _drop_leaves(prob: _Problem, best: Scored) -> Scored:
    """``best`` with leaves dropped, one at a time, while that lowers the score (the
    leaves as they are, not refined again). After the face moves: a trim that made up
    for a face the moves have put right then only costs its penalty (the drops of
    :meth:`_Search.drops` come before the face moves, and refine the rest, which can
    move a face no point holds)."""
    scorer = prob.pool.scorer()
    while T.size(best.tree) > 1:
        for c in T.leaves(best.tree):
            rest = T.remove(best.tree, c)
            if rest is None or not consistent(rest, scorer.signs):
                continue
            sc = scorer.score(rest)
            if sc.total < best.total - 1e-12:
                best = sc
                break
        else:
            break
    return best


def _through_final(prob: _Problem, best: Scored) -> Scored:
    """``best`` with each cut (a box or cylinder cut away) moved out where no point
    shows its faces, unless that scores worse by more than a hundredth of the penalty:
    a hole whose bottom no point shows goes through (the points seen on its wall say
    nothing of its length, and a closed skin over its opening costs only the few
    free-space samples that fall in it)."""
    pool = prob.pool
    tree = best.tree
    for c, odd in sorted(parities(tree).items()):
        lf = pool.leaves[c]
        if not odd or lf.kind not in ("box", "cylinder"):
            continue
        inl = prob.P[np.abs(lf.values(prob.P)[0]) <= 2 * prob.tau]
        ext = extended(lf, prob.P, inl)
        if ext is None:
            continue
        v = pool.add([ext])[0]
        if v in T.leaves(tree):
            continue
        sc = pool.scorer().score(swap(tree, c, v))
        if sc.total <= best.total + 0.01 * pool.penalty:
            best, tree = sc, sc.tree
    return best


def _indistinct(prob: _Problem, best: Scored) -> list[Scored]:
    """The trees the points cannot tell from ``best``: the same leaves with trims or
    cuts moved elsewhere (:func:`.tree.relocations`, repeatedly), each scoring within
    :data:`INDISTINCT` of the penalty of ``best``'s score; one per set, ``best`` first,
    then best score first, :data:`ALTERNATIVES` at most (after
    :data:`ALTERNATIVE_SCORES` trees scored, those found so far)."""
    scorer = prob.pool.scorer()
    limit = best.total + INDISTINCT * prob.pool.penalty
    seen = {T.normal_form(best.tree)}
    found = [best]
    todo = [best.tree]
    scored = 0
    while todo and len(found) < ALTERNATIVES and scored < ALTERNATIVE_SCORES:
        for t in T.relocations(todo.pop(0)):
            key = T.normal_form(t)
            if key in seen or not consistent(t, scorer.signs):
                continue
            seen.add(key)
            scored += 1
            sc = scorer.score(t)
            if sc.total <= limit:
                found.append(sc)
                todo.append(t)
    return [best] + sorted(found[1:], key=lambda s: s.total)[:ALTERNATIVES - 1]


#: the conventions ``infer(prefer=...)`` knows
PREFER = ("local", "global")


def _preferred(alternatives: list[Scored], prefer: str) -> Scored:
    """Of trees the points cannot tell apart (:func:`_indistinct`), the one whose trims
    and cuts reach the fewest primitives (``'local'``: a cut that misses a part is not
    applied to it) or the most (``'global'``: cuts and trims applied to all that was
    built before them, as a feature tree applies them), by :func:`.tree.scope`, then
    the best score; written with its cuts after its intersections
    (:func:`.tree.cuts_last`: the same set). A convention, not a finding
    (docs/infer.md)."""
    sign = 1 if prefer == "local" else -1
    win = min(alternatives, key=lambda s: (sign * T.scope(s.tree), s.total))
    return Scored(T.cuts_last(win.tree), win.data, win.free, win.total)


#: whether :func:`_to_refine` also takes the best tree of every other size
REFINE_EVERY_SIZE = True


def _to_refine(found: list[Scored], n: int) -> tuple[list, int]:
    """The trees of ``found`` (best first) to refine, and how many of them to polish
    whatever their refined score (the first ones): up to ``n`` taken by turns, the
    best not yet taken of the best tree's size, of one leaf fewer and of one leaf
    more; then (:data:`REFINE_EVERY_SIZE`) the best tree of each other size, smallest
    first (polished only when refined it is the best so far: a polish from a small
    tree is a search of its own). Refinement moves scores by more than a penalty, and
    an unrefined larger tree can beat a smaller one only because the smaller one was
    never refined."""
    k = T.size(found[0].tree)
    groups = [[s.tree for s in found if T.size(s.tree) == m] for m in (k, k - 1, k + 1)]
    out: list = []
    while len(out) < n and any(groups):
        for g in groups:
            if g and len(out) < n:
                out.append(g.pop(0))
    n = len(out)
    if REFINE_EVERY_SIZE:
        for m in sorted({T.size(s.tree) for s in found} - {k, k - 1, k + 1}):
            out.append(next(s.tree for s in found if T.size(s.tree) == m))
    return out, n


class _Search:
    """The search's state: the best tree so far and what has been refined.

    Args:
        prob: the problem.
        maxp: the most leaves of a tree.
        beam: trees kept per size in a beam search.
        deadline: a ``time.perf_counter()`` to stop at (a safety net: the effort is
            fixed by the other arguments).
        t0: the start of the run.
    """

    def __init__(self, prob: _Problem, maxp: int, beam: int, deadline: float, t0: float):
        self.prob, self.maxp, self.width, self.deadline, self.t0 = prob, maxp, beam, \
            deadline, t0
        self.best: Scored | None = None
        self.history: list = []
        self.done: set[str] = set()
        self.slowest = 0.0

    def _better(self, sc: Scored) -> None:
        if self.best is None or sc.total < self.best.total - 1e-12:
            self.best = sc
            self.history.append((time.perf_counter() - self.t0, T.size(sc.tree), sc.total,
                                 sc.tree))

    def _time_left(self) -> bool:
        return time.perf_counter() + self.slowest <= self.deadline

    def beam(self, seeds: list | None = None) -> list[Scored]:
        """A beam search over every candidate (seeded with ``seeds``); its best trees."""
        pool = self.prob.pool
        found = beam_search(pool.scorer(), list(range(len(pool.leaves))), self.maxp,
                            self.width, self.deadline, None, self.t0, seeds)
        _note(self.t0, "beam", len(pool.leaves), found[0].total, found[0].tree)
        self._better(found[0])
        return found

    def refine(self, tree, polish: bool = True) -> None:
        """Refine and polish ``tree`` (:func:`_refine_and_polish`) unless one of its
        normal form was, or no time is left; without ``polish``, polished only when
        the refined tree is the best so far."""
        key = T.normal_form(tree)
        if key in self.done or (self.best is not None and not self._time_left()):
            return
        self.done.add(key)
        ts = time.perf_counter()
        below = math.inf if polish or self.best is None else self.best.total
        sc = _refine_and_polish(self.prob, tree, self.maxp, self.deadline, below)
        self.slowest = max(self.slowest, time.perf_counter() - ts)
        self._better(sc)
        _note(self.t0, "refined", sc.total, sc.tree)

    def drops(self) -> None:
        """Each leaf of the best tree dropped and the rest refined (a leaf that only
        made up for the others' extents before they were refined), for up to
        :data:`DROP_ROUNDS` rounds while that lowers the score."""
        for _ in range(DROP_ROUNDS):
            start = self.best
            if start is None or T.size(start.tree) < 2:
                break
            for c in T.leaves(start.tree):
                self.refine(T.remove(start.tree, c))
            if self.best is start:
                break


#: a callable that gets ``(seconds, stage, ...)`` of each stage of :func:`infer` (for
#: diagnosis), or None
TRACE = None


def _note(t0: float, *what) -> None:
    if TRACE is not None:
        TRACE(time.perf_counter() - t0, *what)


def infer(points, normals=None, max_primitives: int = 8, kinds=SOLID_KINDS, viewpoint=None,
          time_limit: float = 30.0, seed: int = 0, *, epsilon: float | None = None,
          penalty: float | None = None, effort: float | None = None,
          prefer: str | None = None) -> InferResult:
    """Infer a CSG tree of csdf primitives, with named parameters, from a point cloud.

    Args:
        points: ``(N, 3)`` points on the object's surface (scene units); repeated
            points count once.
        normals: ``(N, 3)`` outward normals (as :func:`csdf.sample_surface` and
            :func:`csdf.scan` give), or None to estimate them (turned to the viewpoint
            when one is given). Normals whose signs are not consistent are used for
            detection only.
        max_primitives: the most primitives in the tree.
        kinds: the primitive kinds to use (some of ``'box'``, ``'cylinder'``,
            ``'sphere'``, ``'cone'``, ``'torus'``; names or one comma string).
        viewpoint: ``(3,)`` the sensor position of a single-view scan: estimated
            normals face it, and the search penalises material where the sensor saw
            through (towards its points, and past the object's silhouette: the whole
            object should be in the sensor's view).
        time_limit: seconds. The search's effort grows with it (beam width, trees
            refined) and is otherwise fixed, so that a seed gives the same result on
            any machine; on a machine too slow for that effort the search stops at
            :data:`SEARCH_UNTIL` of the limit and the final face moves at
            :data:`FACES_UNTIL`, with the best tree found by then.
        seed: equal seeds give equal results.
        epsilon: the noise level ``tau`` (scene units) of the score; default three
            times the detections' median rmse, at least ``1e-3`` of the cloud's
            diagonal.
        penalty: the cost of one more primitive (>= 0), as a share of the points it
            must explain; default :data:`PENALTY`.
        effort: the search's effort in seconds of this project's machine (beam width
            and trees refined, as ``time_limit`` sets them); default ``time_limit``.
            Give it with a larger ``time_limit`` for a result that no machine's speed
            or load can cut short (tests, reproducible runs).

    Returns:
        :class:`InferResult`.

    Raises:
        CsdfError: bad arguments, or no primitive found in the cloud.
    """
    t0 = time.perf_counter()
    P = points_arg(points)
    N = None if normals is None else normals_arg(normals, P)
    copies = distinct_points(P)
    if copies is not None:  # repeated points (a mesh's triangles) weigh nothing more
        P = P[copies[0]]
        N = None if N is None else N[copies[0]]
    if len(P) < 50:
        raise CsdfError(f"infer needs at least 50 distinct points, got {len(P)}")
    vp = viewpoint_arg(viewpoint)
    ks = _kinds(kinds)
    if isinstance(max_primitives, bool) or not isinstance(max_primitives, (int, np.integer)) \
            or not 1 <= max_primitives <= 32:
        raise CsdfError(f"max_primitives must be an integer in [1, 32], got {max_primitives!r}")
    if not (isinstance(time_limit, (int, float)) and time_limit > 0):
        raise CsdfError(f"time_limit must be a positive number of seconds, got {time_limit!r}")
    if prefer is not None and prefer not in PREFER:
        raise CsdfError(f"prefer must be None or one of {', '.join(PREFER)}; got {prefer!r}")
    if penalty is not None and (isinstance(penalty, bool) or not isinstance(
            penalty, (int, float)) or not math.isfinite(penalty) or penalty < 0):
        raise CsdfError(f"penalty must be None or a number >= 0, got {penalty!r}")
    rng_arg(seed)  # checked before any work
    if effort is None:
        effort = time_limit
    elif isinstance(effort, bool) or not (isinstance(effort, (int, float)) and effort > 0):
        raise CsdfError(f"effort must be a positive number of seconds, got {effort!r}")
    maxp = int(max_primitives)
    prob = _setup(P, N, vp, ks, maxp, seed, epsilon, penalty)
    _note(t0, "setup", len(prob.pool.leaves))
    pool = prob.pool
    run = _Search(prob, maxp, max(8, int(BEAM_PER_SECOND * effort)),
                  t0 + SEARCH_UNTIL * float(time_limit), t0)
    found = run.beam()
    # the points the best tree leaves unexplained: detected again, and the search
    # resumed with what they show
    for _ in range(RESIDUAL_ROUNDS):
        n0 = len(pool.leaves)
        pool.add(_residual(prob, found[0].tree))
        if len(pool.leaves) == n0:
            break
        found = run.beam([s.tree for s in found])
    # joint refinement of the best trees (of the best one's size and one leaf fewer or
    # more, and the best of every other size: refinement moves scores by more than a
    # penalty), then of the best with each leaf dropped
    trees, polished = _to_refine(found, max(3, int(REFINE_PER_SECOND * effort)))
    for j, tree in enumerate(trees):
        run.refine(tree, j < polished)
    run.drops()
    assert run.best is not None
    best = _move_faces(prob, run.best, t0 + FACES_UNTIL * float(time_limit))
    dropped = _drop_leaves(prob, best)
    if dropped is not best:
        best = _move_faces(prob, dropped, t0 + FACES_UNTIL * float(time_limit))
    if best is not run.best:
        run.history.append((time.perf_counter() - t0, T.size(best.tree), best.total, best.tree))
    history = run.history
    _note(t0, "searched", prob, best)
    # the winner's cuts go through where nothing shows their ends
    swapped = _through_final(prob, best)
    if T.normal_form(swapped.tree) != T.normal_form(best.tree):
        tree = _refined_tree(prob, swapped.tree)
        sc2 = pool.scorer().score(tree)
        best = sc2 if sc2.total <= best.total + 0.01 * pool.penalty else swapped
    # a cone whose taper the points do not show is the cylinder it is
    best = _straighten(prob, best)
    # the trees the points cannot tell apart; a convention picks one only when asked
    searched = best.tree
    alternatives = _indistinct(prob, best)
    if prefer is not None:
        best = _preferred(alternatives, prefer)
    sc = best
    lvs = _straight_cones(pool.leaves, T.leaves(sc.tree))
    shape, names = _shape(sc.tree, lvs)
    label = names.__getitem__
    if not history or abs(history[-1][2] - sc.total) > 1e-15:
        history.append((time.perf_counter() - t0, T.size(sc.tree), sc.total, sc.tree))
    f = prob.tree_values(sc.tree, P)
    near = np.abs(f) <= 3 * prob.tau
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
        history=hist, candidates=len(pool.leaves), searched=T.to_text(searched, label),
        alternatives=[T.to_text(a.tree, label) for a in alternatives])
