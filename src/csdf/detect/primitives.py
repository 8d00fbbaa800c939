"""Primitive detection in point clouds (paper §4.4): :func:`detect_primitives`.

The search follows Schnabel, Wahl and Klein's Efficient RANSAC (2007), with csdf's exact
distances and :func:`csdf.fit` doing the refinement:

1. **Neighbourhoods.** One k-nearest-neighbour search (on a grid of cells, compiled)
   gives normals (when not given), the point spacing, a noise estimate (the default
   ``epsilon`` is three times it) and the graph that connected components are cut from
   (:mod:`.neighbours`).
2. **Hypotheses from local minimal sets.** Each round draws a batch of samples: a seed
   point among those not yet explained and three of its neighbours at a random level of
   a coarse-to-fine pyramid of random subsets (so that neighbourhoods span small and
   large primitives alike). Every sample proposes a plane, a sphere, a cylinder, a cone
   and a torus (:mod:`.surfaces`), kept when its own points agree with it.
3. **Scoring.** Every hypothesis counts the points of a random subset within
   ``epsilon`` whose normals agree within ``normal_tolerance`` degrees, on growing
   prefixes of it: one that cannot be among the best is dropped after each doubling
   (:func:`_best_hypotheses`). The best are grown from their sample points into their
   connected inliers among all unexplained points (the 12-nearest-neighbour graph,
   edges shorter than ``cluster_epsilon``); one that is the same surface as a better
   one of its kind is not grown again (:func:`_repeated`). A simpler kind wins over a
   more complex one that explains at most ``1/SIMPLER_WINS`` more points (a flat face
   is a plane, not a huge cylinder; a ring of small radius is a sphere, not a torus).
   Candidates not taken stay in a pool for the next rounds; a pooled plane that
   nothing can beat is taken without drawing again (:func:`_sure`).
4. **Refinement.** The winner becomes a csdf solid (:mod:`.solids`: a sphere, capped
   cylinder, frustum or torus spanning its points), which :func:`csdf.fit` refines in
   pose and size from that start: on a subsample while the points near it (caps
   included) grow, then on every point within ``FIT_BAND`` times ``epsilon`` but those
   near its edges, collected again after each fit (:func:`_settle`). Its inliers are
   the connected unexplained points within ``epsilon`` of the solid with agreeing
   normals. A candidate of another kind on the same points is refined too and wins
   when it explains them better (:func:`_replaces`); a curved detection that one plane
   explains more than half of is dropped (:func:`_flat_share`), and so is one whose
   nearby unexplained points mostly have normals that disagree with it (a shell
   through a scattered cloud, :func:`_agreement`). Planes are refined by principal
   component analysis (the least-squares plane).
5. **Greedy acceptance.** The largest detection is accepted and its points removed,
   until rounds find nothing with ``min_points`` points (a cylinder's or cone's caps
   count towards it) or ``max_primitives`` are found.
6. **Composition.** Planes whose points lie on an accepted solid (a cylinder's or
   cone's flat end, moved onto them) join it; groups of mutually adjacent orthogonal
   planes are fitted with a box, which replaces them when it explains their points, and
   takes the unexplained points on it (faces too small to be found alone).

The search runs on the points in Morton (Z-curve) order (``reorder=True``), so that the
graph searches and gathers stay in the caches; detections name the input's indices.
Everything random comes from ``numpy.random.default_rng(seed)``: the same input and seed
give the same detections, whatever the order of the points (``reorder=False``: the same
input in the same order).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import CsdfError
from ..fit import fit
from ..seeds import rng_arg
from .kernels import (
    any_within,
    ball_in_frame,
    best_counts,
    bounds,
    cell_keys,
    close_agreeing,
    grid_knn,
    grow_inliers,
    in_box_and_slab,
    inlier_mask,
    largest_component,
    linked_graph,
    scatter,
    seeded_components,
    within_ball,
)
from .neighbours import (
    Neighbourhood,
    distinct_points,
    linked_edges,
    neighbourhood,
    normals_arg,
    points_arg,
    spatial_order,
    viewpoint_arg,
    with_copies,
)
from .solids import (
    SOLID_BACKEND,
    SOLID_PARAMS,
    away_from_edges,
    bounding_sphere,
    end_moved,
    frame_values,
    posed,
    solid_values,
)
from .surfaces import (
    KIND_ID,
    KINDS,
    cones_from,
    cylinders_from,
    frame_z,
    planes_from,
    spheres_from,
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
FULL_SCORES = 2
#: a round's hypothesis whose inliers on the subset lie mostly (more than this share)
#: among the connected inliers of a better one of its kind is the same surface, and is
#: not grown again (:func:`_repeated`)
REPEAT_SHARE = 0.5
#: rounds in a row that may find nothing before the search stops
MAX_FAILURES = 3
#: default limit on the number of detections
MAX_PRIMITIVES = 64
#: points the refinement fits before the last use at most (a seeded subsample of the
#: inliers); the last fit uses them all
FIT_POINTS = 600
#: points of the random subset every hypothesis is first counted on; those that cannot
#: be among the best ``FULL_SCORES`` are dropped before the next, twice as many, points
#: (Schnabel et al.'s scoring on growing subsets)
SCORE_FIRST = 250
#: the dropping test's width in standard deviations of a count (Poisson)
SCORE_Z = 3.0
#: the last fits of a solid use the points within this many ``epsilon`` of it
FIT_BAND = 2.0
#: fits of the last refinement at most (each on the points its predecessor collected)
SETTLE_FITS = 3
#: a fit stops when a step lowers its cost by less than this fraction (``csdf.fit``'s
#: ``tol``; its default 1e-7 took every fit to its ``max_iter`` evaluations; with 1e-4
#: the benchmark's errors were the same and the fits used a tenth fewer)
FIT_TOL = 1e-4
#: evaluations of each of those fits at most
SETTLE_ITER = 5
#: planes tried on a curved detection's inliers (:func:`_flat_share`)
FLAT_TRIES = 32
#: ... counted on at most this many of them
FLAT_POINTS = 400
#: a curved detection one plane explains more than this share of is a flat patch, not
#: the solid (a cylinder's or cone's cap holds less than half of its surface)
FLAT_SHARE = 0.5
#: a solid detection is dropped when fewer than this share of the unexplained points
#: within ``epsilon`` of its surface have normals that agree with it (:func:`_agreement`):
#: on a surface nearly all do (at least 0.97 of every solid found in the benchmark's 20
#: scenes, 0.99 the median), while a shell through a scattered cloud (a volume of
#: noise) gathers points whose normals agree by chance (0.12-0.2)
AGREEMENT = 0.5
#: the kinds a pooled candidate of may be accepted without new samples (a plane's
#: hypothesis is exact and cheap to refine; a solid's may be a poor one that a fresh
#: round would beat)
SURE_KINDS = ("plane",)
#: candidates kept from round to round
POOL = 9
#: a candidate of another kind on the same points is refined too when it holds at
#: least this share of the best's inliers (the refined ones then compete)
RIVAL_SHARE = 0.5
#: ... and replaces the best when its refined inliers hold this share of the best's
RIVAL_COVER = 0.9
#: ... with an rmse at most this times the best's
RIVAL_RMSE = 1.1
#: kinds whose solids have flat ends (caps), which count towards ``min_points``
CAPPED = ("cylinder", "cone")
#: the share of a plane's points that must lie on a solid for it to be the solid's
#: face (a cap, a box side)
CAP_SHARE = 0.9
#: least-squares refits of a plane hypothesis before it is compared with the others
PLANE_REFITS = 1
#: fits of a solid at most, each on the inliers of the one before (while they grow)
SOLID_REFITS = 3
#: evaluations of each of those fits at most (the last fits converge)
REFIT_ITER = 5
#: neighbours searched around a seed point for its minimal set
SAMPLE_NEIGHBOURS = 10
#: the cells of a sampling level's grid are this many times its points' estimated
#: distance to their ``SAMPLE_NEIGHBOURS``-th neighbour (:func:`_build_levels`)
LEVEL_CELL = 1.5
#: ... and at most this many in all (wider when they would be more)
LEVEL_MAX_CELLS = 1_000_000


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
            ``r2``, ``major``, ``minor``, ``size_x``...; a cone's frustum, ``r1`` at its
            base and ``r2`` at its top, has ``frustum_height``).
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
    flat_share: float = FLAT_SHARE
    levels: list[_Level] = field(default_factory=list)
    graph: tuple[np.ndarray, np.ndarray] | None = None  # linked_graph(nbr, linked)


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
                      cluster_epsilon=None, max_primitives=MAX_PRIMITIVES,
                      flat_share: float | None = None, reorder: bool = True
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
        flat_share: a curved detection of which one plane explains more than this
            share (in ``(0, 1]``) is dropped as a flat patch (:func:`_flat_share`);
            default :data:`FLAT_SHARE`. ``1`` keeps every curved detection: a small
            curved patch whose bulge is within a few ``epsilon`` (a shallow notch)
            is then reported too, and so may a flat face as a large sphere or
            cylinder when no plane explains it first.
        reorder: search the points in Morton order (:func:`.neighbours.spatial_order`):
            near points near in memory keep the graph searches and gathers that follow
            in the caches (a 40k-point cloud in random order took a fifth longer in
            the given order), and the answer does not depend on the order the points
            came in. False searches them in the given order (a scan's rows are near
            enough; :func:`csdf.detect`'s support planes), with other random draws.

    Returns:
        :class:`PrimitiveDetection` list, largest first (boxes and solids that absorbed
        planes keep their place of first detection). A point belongs to at most one;
        repeated points count once (the search runs on the distinct points) and every
        copy is among the inliers of what explains it.

    Raises:
        CsdfError: points or normals of the wrong shape or not finite, unknown kinds,
            a non-positive ``epsilon``, ``min_points`` or ``normal_tolerance`` outside
            (0, 90), a bad seed.
    """
    P = points_arg(points)
    rng = rng_arg(seed)
    ks = _kinds_arg(kinds)
    vp = viewpoint_arg(viewpoint)
    tol = float(normal_tolerance)
    if not 0.0 < tol < 90.0:
        raise CsdfError(f"normal_tolerance must be an angle in (0, 90) degrees; got {tol}")
    N = None if normals is None else normals_arg(normals, P)
    opts = _Options(
        kinds=ks, viewpoint=vp, cos_tol=math.cos(math.radians(tol)), rng=rng,
        eps=None if epsilon is None else _positive(epsilon, "epsilon"),
        min_points=None if min_points is None else int(_positive(min_points, "min_points")),
        conn=None if cluster_epsilon is None else _positive(cluster_epsilon,
                                                            "cluster_epsilon"),
        flat=FLAT_SHARE if flat_share is None else _positive(flat_share, "flat_share"),
        max_primitives=int(max_primitives))
    if opts.flat > 1.0:
        raise CsdfError(f"flat_share must be in (0, 1]; got {flat_share!r}")
    if len(P) < 4:
        return []
    if not reorder:
        return _detect(P, N, opts)
    order = spatial_order(P)
    found = _detect(P[order], None if N is None else N[order], opts)
    for d in found:
        d.inliers = np.sort(order[d.inliers])
    return found


@dataclass
class _Options:
    """The checked options of :func:`detect_primitives` (``eps``, ``min_points`` None:
    from the cloud)."""

    kinds: tuple[str, ...]
    viewpoint: np.ndarray | None
    cos_tol: float
    rng: np.random.Generator
    eps: float | None
    min_points: int | None
    conn: float | None
    flat: float
    max_primitives: int


def _detect(P: np.ndarray, N: np.ndarray | None, opts: _Options
            ) -> list[PrimitiveDetection]:
    """:func:`detect_primitives` on checked points ``P`` ``(N, 3)`` (at least four) and
    unit normals ``N`` (or None: estimated)."""
    n = len(P)
    nb = neighbourhood(P, viewpoint=opts.viewpoint, want_normals=N is None)
    copies = distinct_points(P, nb)
    if copies is not None:
        # repeated points: found on the distinct ones, each detection given every copy
        keep, owner = copies
        found = _detect(P[keep], None if N is None else N[keep], opts) if len(keep) >= 4 \
            else []
        for d in found:
            d.inliers = with_copies(d.inliers, owner)
        return found
    if N is None:
        N = nb.normals
    lo, hi = bounds(P)
    diag = float(np.linalg.norm(hi - lo))
    eps = max(3.0 * nb.noise, 1e-4 * diag) if opts.eps is None else opts.eps
    mp = max(30, n // 200) if opts.min_points is None else opts.min_points
    ctx = _Ctx(P=P, N=N, nb=nb, eps=eps, cos_tol=opts.cos_tol,
               conn=opts.conn, linked=linked_edges(nb, opts.conn), min_points=max(mp, 4),
               max_radius=max(diag, eps), rng=opts.rng, kinds=opts.kinds,
               viewpoint=opts.viewpoint, flat_share=opts.flat)
    ctx.graph = linked_graph(nb.nbr, ctx.linked)
    _build_levels(ctx)
    found = _extract(ctx, opts.max_primitives)
    found = _absorb_planes(ctx, found)
    if "box" in opts.kinds:
        found = _make_boxes(ctx, found)
    return [d for d in found if d.kind in opts.kinds]


@dataclass
class _Level:
    """One level of the sampling pyramid: its points ``idx`` (sorted indices) and, past
    the first, a grid of them (:func:`.kernels.grid_knn`): the points ``S`` ``(K, 3)``
    and their indices ``ids`` sorted by cell, where each cell's run begins
    (``first``), the cells a side ``dims`` and their side ``h`` (scene units), from the
    cloud's least corner ``lo``."""

    idx: np.ndarray
    S: np.ndarray | None = None
    ids: np.ndarray | None = None
    first: np.ndarray | None = None
    dims: np.ndarray | None = None
    lo: np.ndarray | None = None
    h: float = 0.0


def _build_levels(ctx: _Ctx) -> None:
    """The sampling pyramid: random subsets of 1, 1/4, 1/16, ... of the points (down to
    about 64 points), each past the first binned in cells about as wide as its points'
    distance to their ``SAMPLE_NEIGHBOURS``-th neighbour (estimated from the cloud's
    sampling scale: a quarter of the points as dense reach twice as far)."""
    from ..cellsort import group_by_cell

    n = len(ctx.P)
    perm = ctx.rng.permutation(n)
    lo, hi = bounds(ctx.P)
    span = hi - lo
    # the whole cloud's distance to the SAMPLE_NEIGHBOURS-th neighbour, from that to the
    # (k // 2)-th (nb.local; on a surface the count within a radius grows as its square)
    reach = float(np.median(ctx.nb.local)) * math.sqrt(
        SAMPLE_NEIGHBOURS / max(ctx.nb.nbr.shape[1] // 2, 1))
    ctx.levels.append(_Level(idx=np.arange(n)))
    m, scale = n // 4, 2.0
    while m >= 64:
        idx = np.sort(perm[:m])
        h = max(LEVEL_CELL * reach * scale, 1e-12 * float(span.max()), 1e-300)
        dims = (span // h).astype(np.int64) + 1
        while np.prod(dims.astype(float)) > LEVEL_MAX_CELLS:
            h *= 1.5
            dims = (span // h).astype(np.int64) + 1
        P = ctx.P[idx]
        order, first = group_by_cell(cell_keys(P, lo, h, dims), int(np.prod(dims)))
        ctx.levels.append(_Level(idx=idx, S=np.ascontiguousarray(P[order]), ids=idx[order],
                                 first=first, dims=dims, lo=lo, h=h))
        m //= 4
        scale *= 2.0


def _samples(ctx: _Ctx, free: np.ndarray, count: int, fidx: np.ndarray | None = None
             ) -> np.ndarray:
    """``(M, 4)`` point indices: a free seed point and three free neighbours of it at a
    random pyramid level each; rows without enough free neighbours are dropped.
    ``fidx``: the free points' indices when known (``np.flatnonzero(free)``)."""
    if fidx is None:
        fidx = np.flatnonzero(free)
    seeds = fidx[ctx.rng.integers(0, len(fidx), count)]
    lev = ctx.rng.integers(0, len(ctx.levels), count)
    sels, nns = [], []
    for li in range(len(ctx.levels)):
        sel = seeds[lev == li]
        if not len(sel):
            continue
        lv = ctx.levels[li]
        k = min(SAMPLE_NEIGHBOURS, len(lv.idx))
        if li == 0:
            # level 0 holds every point: the seed and then its nearest neighbours are
            # the neighbourhood's (it holds min(12, N - 1) a point, k - 1 at most)
            nn = np.concatenate([sel[:, None], ctx.nb.nbr[sel, :k - 1]], axis=1)
        else:
            nn = grid_knn(np.ascontiguousarray(ctx.P[sel]), lv.S, lv.ids, lv.first, lv.dims,
                          lv.lo, lv.h, k)
        sels.append(sel)
        nns.append(nn)
    if not sels:
        return np.zeros((0, 4), dtype=int)
    # every level has the same k: levels past the first hold 64 points or more, and a
    # cloud of fewer than 256 has no level past the first
    sel, nn = np.concatenate(sels), np.concatenate(nns)
    # three candidates drawn at random among the free ones but the seed itself
    keys = ctx.rng.random(nn.shape)
    keys[~free[nn] | (nn == sel[:, None])] = np.inf
    order = np.argsort(keys, axis=1)[:, :3]
    pick = np.take_along_axis(nn, order, axis=1)
    good = np.isfinite(np.take_along_axis(keys, order, axis=1)).all(axis=1)
    return np.concatenate([sel[good, None], pick[good]], axis=1)


def _hypotheses(ctx: _Ctx, S: np.ndarray) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """The hypotheses of every surface kind from samples ``S`` ``(M, 4)``: per kind, the
    rows and the sample each came from (degenerate samples, whose solutions overflow or
    are NaN, are not ``ok`` and are dropped)."""
    p, nrm = ctx.P[S], ctx.N[S]
    eps, rmax = ctx.eps, ctx.max_radius
    want = set(ctx.kinds)
    rows = np.arange(len(S))
    out = {}
    H, ok = planes_from(p[:, :3], nrm[:, :3], ctx.cos_tol)
    out["plane"] = H[ok], rows[ok]
    if "sphere" in want:
        H, ok = spheres_from(p[:, :2], nrm[:, :2], eps, rmax)
        out["sphere"] = H[ok], rows[ok]
    if "cylinder" in want:
        H, ok = cylinders_from(p[:, :2], nrm[:, :2], eps, rmax)
        out["cylinder"] = H[ok], rows[ok]
    if "cone" in want:
        H, ok = cones_from(p[:, :3], nrm[:, :3], eps, rmax)
        out["cone"] = H[ok], rows[ok]
    if "torus" in want:
        H, ok = tori_from(p, nrm, eps, rmax)  # up to three a sample
        out["torus"] = H[ok], np.repeat(rows, 3)[ok]
    return out


def _best_hypotheses(ctx: _Ctx, hyps: dict[str, np.ndarray], sub: np.ndarray, k: int
                     ) -> list[tuple[int, str, int]]:
    """The ``k`` hypotheses with the most inliers among the points ``sub`` ``(S,)`` (in
    random order), as ``(count, kind, index in hyps[kind])``, most first (a tie to the
    simpler kind, then the earlier row).

    Every hypothesis is counted on the first ``SCORE_FIRST`` points of ``sub``, the
    survivors on twice as many, and so on up to all of ``sub``; after each step a
    hypothesis is dropped when its count plus ``SCORE_Z`` standard deviations (Poisson)
    stays below the ``k``-th best count less as many of its own: it cannot be among the
    best. The survivors' counts are over all of ``sub``."""
    kinds = [kd for kd, H in hyps.items() if len(H)]
    if not kinds:
        return []
    T = sum(len(hyps[kd]) for kd in kinds)
    H = np.zeros((T, 8))
    kind = np.empty(T, dtype=np.int64)
    row = np.empty(T, dtype=np.int64)
    a = 0
    for kd in kinds:
        m = len(hyps[kd])
        H[a:a + m, :hyps[kd].shape[1]] = hyps[kd]
        kind[a:a + m] = KIND_ID[kd]
        row[a:a + m] = np.arange(m)
        a += m
    counts, alive = best_counts(kind, H, np.ascontiguousarray(ctx.P[sub]),
                                np.ascontiguousarray(ctx.N[sub]), ctx.eps, ctx.cos_tol,
                                SCORE_FIRST, k, SCORE_Z)
    live = np.flatnonzero(alive)
    # most first; a tie to the simpler kind (KIND_ID follows KINDS), then the earlier row
    top = live[np.lexsort((row[live], kind[live], -counts[live]))[:k]]
    return [(int(counts[i]), KINDS[kind[i]], int(row[i])) for i in top]


@dataclass(eq=False)
class _Candidate:
    """A scored surface hypothesis: its kind, row ``h`` and connected inliers ``inl``
    (sorted indices); ``fresh`` when ``inl`` was cut on the current free points (else
    it is what is left of an earlier round's: an upper bound)."""

    kind: str
    h: np.ndarray
    inl: np.ndarray
    fresh: bool = True


def _round_candidates(ctx: _Ctx, free: np.ndarray) -> list[_Candidate]:
    """One round's new candidates: minimal samples, their hypotheses, the best
    ``FULL_SCORES`` by their counts on a random subset, each with its connected inliers
    among the free points (planes refitted by least squares first)."""
    fidx = np.flatnonzero(free)
    S = _samples(ctx, free, SAMPLES_PER_ROUND, fidx)
    # in random order: the growing prefixes that hypotheses are counted on must be
    # random samples too (a scan's points come in scan order)
    sub = (ctx.rng.permutation(fidx) if len(fidx) <= SUBSET
           else ctx.rng.choice(fidx, SUBSET, replace=False))
    scale = len(fidx) / len(sub)
    hyps = _hypotheses(ctx, S)
    out: list[_Candidate] = []
    for cnt, kind, i in _best_hypotheses(ctx, {k: H for k, (H, _) in hyps.items()}, sub,
                                         FULL_SCORES):
        if cnt * scale < 0.5 * ctx.min_points:
            break
        h = hyps[kind][0][i]
        if any(c.kind == kind and _repeated(ctx, kind, h, sub, c.inl) for c in out):
            continue  # the same surface again (two rounds in three): not grown twice
        inl = _connected_inliers(ctx, kind, h, free, S[hyps[kind][1][i]])
        if kind == "plane":  # refitted by least squares: three close points tilt it
            for _ in range(PLANE_REFITS):
                if len(inl) < 3:
                    break
                h, _ = _lsq_plane(ctx, inl)
                inl = _connected_inliers(ctx, kind, h, free, inl)
        out.append(_Candidate(kind, h, inl))
    return out


def _repeated(ctx: _Ctx, kind: str, h: np.ndarray, sub: np.ndarray, inl: np.ndarray
              ) -> bool:
    """Whether more than ``REPEAT_SHARE`` of the inliers of hypothesis ``h`` among the
    points ``sub`` (the round's random subset) are among ``inl`` (sorted indices, a
    candidate's connected inliers): the same surface as that candidate's."""
    mine = sub[inlier_mask(KIND_ID[kind], np.ascontiguousarray(h, dtype=np.float64), ctx.P,
                           ctx.N, np.asarray(sub, dtype=np.int64), ctx.eps, ctx.cos_tol)]
    if not len(mine) or not len(inl):
        return False
    pos = np.minimum(np.searchsorted(inl, mine), len(inl) - 1)
    return np.count_nonzero(inl[pos] == mine) > REPEAT_SHARE * len(mine)


def _pick(ctx: _Ctx, cands: list[_Candidate], free: np.ndarray) -> _Candidate | None:
    """The candidate with the most inliers, a simpler kind winning when it explains at
    least ``SIMPLER_WINS`` of the most; an earlier round's candidate is cut on the
    current free points before it can win."""
    rank = {k: i for i, k in enumerate(KINDS)}
    while cands:
        top = max(len(c.inl) for c in cands)
        ok = [c for c in cands if len(c.inl) >= SIMPLER_WINS * top]
        best = min(ok, key=lambda c: (rank[c.kind], -len(c.inl)))
        if best.fresh:
            return best
        best.inl = _connected_inliers(ctx, best.kind, best.h, free, best.inl)
        best.fresh = True
    return None


def _rival(best: _Candidate, cands: list[_Candidate]) -> _Candidate | None:
    """The largest candidate of another kind on (mostly) the same points as ``best``,
    with at least ``RIVAL_SHARE`` of its inliers: a poor torus hypothesis may explain
    fewer points than a sphere that fits a piece of it, yet more once refined."""
    n = len(best.inl)
    out = None
    for c in cands:
        if (c.kind == best.kind or len(c.inl) < RIVAL_SHARE * n
                or (out is not None and len(c.inl) <= len(out.inl))):
            continue
        if _shared(c.inl, best.inl) >= 0.5 * min(len(c.inl), n):
            out = c
    return out


def _extract(ctx: _Ctx, max_primitives: int) -> list[PrimitiveDetection]:
    """Steps 2-5 of the module docstring: the greedy extraction loop. Candidates that
    were not accepted stay in a pool for the next rounds (at most ``POOL`` of them, their
    inliers cut to the free points), so that a round whose samples missed a large
    primitive does not accept a lesser one (Schnabel et al. keep their candidates
    likewise); a pooled candidate that is sure to win (:func:`_sure`) is taken without
    drawing new samples."""
    free = np.ones(len(ctx.P), dtype=bool)
    found: list[PrimitiveDetection] = []
    pool: list[_Candidate] = []
    failures = 0
    rank = {k: i for i, k in enumerate(KINDS)}
    while free.sum() >= ctx.min_points and len(found) < max_primitives:
        for c in pool:
            left = c.inl[free[c.inl]]
            c.fresh = c.fresh and len(left) == len(c.inl)
            c.inl = left
        pool = [c for c in pool if len(c.inl) >= 0.5 * ctx.min_points]
        best = _sure(ctx, pool, rank)
        if best is None:
            cands = _round_candidates(ctx, free) + pool
            best = _pick(ctx, cands, free)
        else:
            cands = pool
        det = None
        if best is not None and len(best.inl) < ctx.min_points:
            # a cylinder's or cone's caps may make up what its side lacks
            capped = [c for c in cands if c.kind in CAPPED and c.fresh
                      and len(c.inl) >= 0.5 * ctx.min_points]
            best = max(capped, key=lambda c: len(c.inl)) if capped else None
        if best is not None:
            det = _refine(ctx, best.kind, best.h, best.inl, free)
            rival = _rival(best, cands)
            if rival is not None:
                other = _refine(ctx, rival.kind, rival.h, rival.inl, free)
                if other is not None and (det is None or _replaces(other, det, rank)):
                    best, det = rival, other
            if det is not None and det.kind != "plane" and (
                    (ctx.flat_share < 1.0 and _flat_share(ctx, det) > ctx.flat_share)
                    or _repeats(ctx, det, found) or _agreement(ctx, det, free) < AGREEMENT):
                det = None  # a patch of a plane (a box's face), what an accepted solid
                # left of its own surface, or a shell through scattered points
        pool = sorted((c for c in cands if c is not best), key=lambda c: -len(c.inl))[:POOL]
        if det is None or len(det.inliers) < ctx.min_points:
            failures += 1
            if failures >= MAX_FAILURES or _scattered(ctx, free):
                break
            continue
        failures = 0
        free[det.inliers] = False
        found.append(det)
    return found


def _flat_share(ctx: _Ctx, det: PrimitiveDetection) -> float:
    """The largest share of a detection's inliers that one plane explains (within
    ``epsilon``, normals agreeing), of the planes through ``FLAT_TRIES`` of its inliers
    along their normals (drawn from the context's generator; shares counted on
    ``FLAT_POINTS`` of the inliers at most)."""
    inl = det.inliers
    pick = inl[ctx.rng.integers(0, len(inl), FLAT_TRIES)]
    if len(inl) > FLAT_POINTS:  # the shares on a random subset
        inl = inl[ctx.rng.integers(0, len(inl), FLAT_POINTS)]
    n, p = ctx.N[pick], ctx.P[pick]
    d = ctx.P[inl] @ n.T - np.einsum("ij,ij->i", n, p)  # (K, T)
    c = np.abs(ctx.N[inl] @ n.T)
    return float(((np.abs(d) <= ctx.eps) & (c >= ctx.cos_tol)).sum(axis=0).max() / len(inl))


def _agreement(ctx: _Ctx, det: PrimitiveDetection, free: np.ndarray) -> float:
    """The share of the unexplained points within ``epsilon`` of a solid detection's
    surface whose normals agree with it (1 when there are none)."""
    _, d, agree = _close_to_solid(ctx, *det.solid, np.flatnonzero(free), 1.0)
    close = d <= ctx.eps
    return float((close & agree).sum() / max(int(close.sum()), 1))


def _repeats(ctx: _Ctx, det: PrimitiveDetection, found: list[PrimitiveDetection]) -> bool:
    """Whether most of a solid detection's inliers lie within ``FIT_BAND`` times
    ``epsilon`` of an accepted solid (normals not asked): what that solid left of its
    own surface (noise tails, a rim) taken for another one."""
    inl = det.inliers[::max(1, len(det.inliers) // FLAT_POINTS)]
    for d in found:
        if d.solid is not None:
            kind, R, t, vals = d.solid
            c, rad = bounding_sphere(kind, R, t, vals)
            near = within_ball(ctx.P, inl, c, rad + FIT_BAND * ctx.eps)
            if near.mean() > 0.5:
                dist, _ = solid_values(kind, R, t, vals, ctx.P[inl[near]])
                if np.count_nonzero(np.abs(dist) <= FIT_BAND * ctx.eps) > 0.5 * len(inl):
                    return True
    return False


def _scattered(ctx: _Ctx, free: np.ndarray) -> bool:
    """Whether the free points are too scattered to hold another detection: no
    connected component of them has half ``min_points`` (a detection starts from the
    connected inliers of one hypothesis)."""
    fidx = np.flatnonzero(free)
    return len(largest_component(fidx, ctx.nb.nbr, ctx.linked, free)) < 0.5 * ctx.min_points


def _sure(ctx: _Ctx, pool: list[_Candidate], rank: dict) -> _Candidate | None:
    """A candidate of the pool that can be accepted without another round of samples,
    the largest such, or None: none of its inliers has been taken since it was scored
    (so they are still its connected inliers), it has ``min_points`` of them, and
    every candidate on any of the same points would lose to it in :func:`_pick` (fewer
    inliers, and not a simpler kind with ``SIMPLER_WINS`` of them). What is left of a
    region once its best explanation is taken is then taken in turn (a box's faces
    one by one) without a round of samples each."""
    best = None
    for c in pool:
        if (c.kind not in SURE_KINDS or not c.fresh or len(c.inl) < ctx.min_points
                or (best is not None and len(c.inl) <= len(best.inl))):
            continue
        if all(not _shared(o.inl, c.inl) or (
                len(o.inl) < len(c.inl) and not (rank[o.kind] < rank[c.kind] and len(o.inl)
                                                 >= SIMPLER_WINS * len(c.inl)))
               for o in pool if o is not c):
            best = c
    return best


def _replaces(a: PrimitiveDetection, b: PrimitiveDetection, rank: dict) -> bool:
    """Whether refined detection ``a`` (a rival) replaces ``b`` on the same points: it
    explains them as well (holds at least ``RIVAL_COVER`` of ``b``'s inliers, with an
    rmse at most ``RIVAL_RMSE`` times ``b``'s) and more of them (a simpler kind winning
    within ``SIMPLER_WINS``). A solid that merely grew over a neighbour does neither."""
    na, nb = len(a.inliers), len(b.inliers)
    held = _shared(a.inliers, b.inliers)
    if held < RIVAL_COVER * nb or a.rmse > RIVAL_RMSE * b.rmse:
        return False
    if rank[a.kind] < rank[b.kind]:
        return na >= SIMPLER_WINS * nb
    return na * SIMPLER_WINS > nb


def _union(*sets: np.ndarray) -> np.ndarray:
    """The sorted union of index arrays (of one cloud)."""
    n = max((int(x.max()) + 1 for x in sets if len(x)), default=0)
    mask = np.zeros(n, dtype=bool)
    for x in sets:
        mask[x] = True
    return np.flatnonzero(mask)


def _shared(a: np.ndarray, b: np.ndarray) -> int:
    """How many indices the index arrays ``a`` and ``b`` (each without repeats) share."""
    if not len(a) or not len(b):
        return 0
    mask = np.zeros(max(int(a.max()), int(b.max())) + 1, dtype=bool)
    mask[a] = True
    return int(np.count_nonzero(mask[b]))


def _connected_inliers(ctx: _Ctx, kind: str, h: np.ndarray, free: np.ndarray,
                       seeds: np.ndarray) -> np.ndarray:
    """The free inliers of surface hypothesis ``h`` in the connected components that
    hold one of ``seeds`` (the hypothesis's own sample points, or the inliers of the
    candidate it refines): sorted indices."""
    return grow_inliers(KIND_ID[kind], np.ascontiguousarray(h, dtype=np.float64), ctx.P,
                        ctx.N, free, np.asarray(seeds, dtype=np.int64), ctx.eps,
                        ctx.cos_tol, *ctx.graph)


def _lsq_plane(ctx: _Ctx, inl: np.ndarray) -> tuple[np.ndarray, float]:
    """The least-squares plane ``(normal, offset)`` ``(4,)`` of the points ``inl``
    ``(K,)``: through their centroid, normal to the least principal axis of their
    scatter matrix (a ``3 x 3`` eigenproblem, the matrix summed without gathering the
    points), and the root mean square distance of the points to it (scene units)."""
    c, S = scatter(ctx.P, np.asarray(inl, dtype=np.int64))
    w, v = np.linalg.eigh(S)
    return np.append(v[:, 0], v[:, 0] @ c), math.sqrt(max(float(w[0]), 0.0) / max(len(inl), 1))


def _plane_detection(ctx: _Ctx, inl: np.ndarray) -> PrimitiveDetection:
    from ..shapes import plane

    h, rmse = _lsq_plane(ctx, inl)
    nrm, off = h[:3], float(h[3])
    if ctx.viewpoint is not None:
        if nrm @ ctx.viewpoint - off < 0:
            nrm, off = -nrm, -off
    elif nrm @ ctx.N[inl].sum(axis=0) < 0:
        nrm, off = -nrm, -off
    return PrimitiveDetection(
        kind="plane", shape=plane(tuple(nrm.tolist()), off),
        params={"normal": nrm.tolist(), "offset": off}, inliers=inl, rmse=rmse)


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


def _close_to_solid(ctx: _Ctx, kind: str, R, t, values, idx: np.ndarray, band: float,
                    limit: float = math.inf) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The points ``idx`` ``(K,)`` within the solid's bounding sphere grown by ``band``
    times ``epsilon`` (the others are not evaluated): their positions in ``idx``
    ``(M,)``, their unsigned distances to the solid ``(M,)`` (scene units) and whether
    their normals lie within the tolerance of its gradient ``(M,)``. With a finite
    ``limit`` (scene units) only the points within it of the surface whose normals
    agree are given (and ``agree`` is all true)."""
    c, rad = bounding_sphere(kind, R, t, values)
    idx = np.asarray(idx, dtype=np.int64)
    near, q = ball_in_frame(ctx.P, idx, c, rad + band * ctx.eps, R, t)
    if not len(near):
        return near, np.zeros(0), np.zeros(0, dtype=bool)
    d, gq = frame_values(kind, values, q)
    if math.isfinite(limit):
        pos, dist = close_agreeing(d, gq, R, ctx.N, idx[near], limit, ctx.cos_tol)
        return near[pos], dist, np.ones(len(pos), dtype=bool)
    pos, _ = close_agreeing(d, gq, R, ctx.N, idx[near], math.inf, ctx.cos_tol)
    agree = np.zeros(len(near), dtype=bool)
    agree[pos] = True
    return near, np.abs(d), agree


def _on_solid(ctx: _Ctx, kind: str, R, t, values, idx: np.ndarray, band: float = 1.0
              ) -> tuple[np.ndarray, np.ndarray]:
    """Which points ``idx`` ``(K,)`` are inliers of the solid: within ``band`` times
    ``epsilon`` of it, their normals within the tolerance of its gradient (``(K,)``
    bool), and the distances of those inliers (scene units, unsigned)
    (:func:`_close_to_solid`)."""
    near, d, _ = _close_to_solid(ctx, kind, R, t, values, idx, band, band * ctx.eps)
    out = np.zeros(len(idx), dtype=bool)
    out[near] = True
    return out, d


def _near_solid(ctx: _Ctx, kind: str, R, t, values, cand: np.ndarray, seedset: np.ndarray,
                band: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """The points among ``cand`` (sorted indices) within ``band`` times ``epsilon`` of
    the solid with agreeing normals, in the connected components that hold points of
    ``seedset``: their indices (sorted) and distances (scene units, unsigned)."""
    cand = np.asarray(cand, dtype=np.int64)
    near, dist, _ = _close_to_solid(ctx, kind, R, t, values, cand, band, band * ctx.eps)
    good = cand[near]
    out = seeded_components(good, np.asarray(seedset, dtype=np.int64), *ctx.graph)
    return out, dist[np.searchsorted(good, out)]


def _fit_solid(ctx: _Ctx, kind: str, R, t, values: dict, pts_idx: np.ndarray,
               limit: int | None = FIT_POINTS, max_iter: int = 60):
    """Refine a solid's pose and sizes with :func:`csdf.fit` (from this start, Huber
    loss at the noise level, at most ``max_iter`` evaluations) on the points
    ``pts_idx`` (a seeded subsample of at most ``limit``; all of them when None)."""
    from .solids import canonical

    shape, _ = canonical(kind)
    idx = pts_idx
    if limit is not None and len(idx) > limit:
        idx = np.sort(ctx.rng.choice(idx, limit, replace=False))
    res = fit(shape, ctx.P[idx], init={"rotation": R, "translation": t, "scale": 1.0,
                                       "params": dict(values)},
              estimate=("pose", "params"), loss="huber", f_scale=ctx.eps / 3.0,
              escape=False, debias=False, backend=SOLID_BACKEND, max_iter=max_iter,
              coarse=False, tol=FIT_TOL)
    vals = {k: float(res.params[k]) for k in SOLID_PARAMS[kind]}
    if not all(math.isfinite(v) for v in vals.values()):
        raise CsdfError(f"the {kind} fit diverged")
    return res.rotation, np.asarray(res.translation, float), vals


def _solid_detection(ctx: _Ctx, kind: str, R, t, vals, inl: np.ndarray, d: np.ndarray
                     ) -> PrimitiveDetection:
    """The :class:`PrimitiveDetection` of a refined solid, its inliers ``inl`` (sorted
    indices) and their distances to it ``d`` (scene units, either sign)."""
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
    # the solid's sizes; a frustum's height is not the cone's (apex to base)
    geo.update({("frustum_height" if kind == "cone" and k == "height" else k): v
                for k, v in vals.items()})
    return PrimitiveDetection(kind=kind, shape=posed(kind, R, t, vals), params=geo,
                              inliers=inl, rmse=float(np.sqrt(np.mean(d * d))),
                              solid=(kind, R, t, vals))


def _settle(ctx: _Ctx, kind: str, R, t, vals, pts: np.ndarray, cand: np.ndarray,
            wide: bool = False):
    """The last refinement of a solid from its points ``pts``: fitted on every point
    among ``cand`` within ``FIT_BAND`` times ``epsilon`` of it (with agreeing normals,
    connected to ``pts``; those near its edges left out, see
    :func:`.solids.away_from_edges`), collected again after each fit until they change
    by at most 1 % (``SETTLE_FITS`` fits at most). The wide band keeps the fit
    unbiased: points cut at ``epsilon`` from a surface that is still off lean towards
    it, and a flat end held by few points would then creep to the truth one fit at a
    time. ``wide``: ``pts`` are that band's points already. Returns ``(R, t, vals,
    inliers, distances)``, the inliers within ``epsilon`` (sorted indices) and their
    unsigned distances (scene units)."""
    if not wide:
        pts = _union(pts, _near_solid(ctx, kind, R, t, vals, cand, pts, FIT_BAND)[0])
    for _ in range(SETTLE_FITS):
        use = pts[away_from_edges(kind, R, t, vals, ctx.P[pts])]
        R, t, vals = _fit_solid(ctx, kind, R, t, vals, use if len(use) >= 4 else pts,
                                limit=None, max_iter=SETTLE_ITER)
        near, dist = _near_solid(ctx, kind, R, t, vals, cand, pts, FIT_BAND)
        same = len(near) + len(pts) - 2 * _shared(near, pts) <= 0.01 * len(pts)
        pts = near
        if same or len(pts) < 4:
            break
    # the inliers within epsilon connected to ``pts`` are those of ``pts`` (the band's
    # connected points of this very solid) within epsilon: a point within epsilon next
    # to one of them would be one of them
    close = dist <= ctx.eps
    return R, t, vals, pts[close], dist[close]


def _refine(ctx: _Ctx, kind: str, h: np.ndarray, inl: np.ndarray, free: np.ndarray
            ) -> PrimitiveDetection | None:
    """Step 4: the refined detection of hypothesis ``h`` with connected inliers
    ``inl``, or None when the refined solid is degenerate: fits on a subsample of its
    points (within ``epsilon``), each on the points the one before collected, while
    they grow, then :func:`_settle`."""
    fidx = np.flatnonzero(free)
    if kind == "plane":
        # the least-squares plane, then its own inliers
        return _plane_detection(ctx, _connected_inliers(ctx, "plane", _lsq_plane(ctx, inl)[0],
                                                        free, inl))
    R, t, vals = _initial_solid(ctx, kind, h, inl)
    pts = _union(inl, _near_solid(ctx, kind, R, t, vals, fidx, inl)[0])
    band = None
    try:
        for _ in range(SOLID_REFITS):
            R, t, vals = _fit_solid(ctx, kind, R, t, vals, pts, max_iter=REFIT_ITER)
            band, dist = _near_solid(ctx, kind, R, t, vals, fidx, pts, FIT_BAND)
            near = band[dist <= ctx.eps]
            grown = len(near) > 1.01 * len(pts)
            pts = near
            if not grown or len(pts) < 4:
                break
        if len(pts) < ctx.min_points:
            return None
        R, t, vals, pts, dist = _settle(ctx, kind, R, t, vals,
                                        pts if band is None else band, fidx,
                                        wide=band is not None)
    except CsdfError:
        return None
    if len(pts) < ctx.min_points:
        return None
    return _solid_detection(ctx, kind, R, t, vals, pts, dist)


def _free_of(ctx: _Ctx, found: list[PrimitiveDetection]) -> np.ndarray:
    """``(K,)`` the points no detection in ``found`` holds (sorted indices)."""
    free = np.ones(len(ctx.P), dtype=bool)
    for d in found:
        free[d.inliers] = False
    return np.flatnonzero(free)


def _as_cap(ctx: _Ctx, solid: tuple, plane: PrimitiveDetection) -> tuple | None:
    """The solid ``(kind, R, t, values)`` with its nearer flat end moved onto the plane
    detection, when the plane's points (nearly all) lie on that end; else None. A
    sphere or torus (no flat ends) takes the plane as it stands."""
    kind, R, t, vals = solid
    Q = plane.inliers
    if kind in CAPPED:
        if abs(np.asarray(plane.params["normal"]) @ R[:, 2]) < ctx.cos_tol:
            return None
        z = float(np.median((ctx.P[Q] - t) @ R[:, 2]))
        moved = end_moved(kind, R, t, vals, z)
        if moved is None:
            return None
        t, vals = moved
    if _on_solid(ctx, kind, R, t, vals, Q)[0].mean() < CAP_SHARE:
        return None
    return kind, R, t, vals


def _absorb_planes(ctx: _Ctx, found: list[PrimitiveDetection]) -> list[PrimitiveDetection]:
    """Step 6a: a plane whose points (nearly all) lie on an accepted solid with agreeing
    normals, once the solid's nearer flat end is moved onto it, is that solid's cap:
    its points join the solid, which is fitted again on all its points (and the
    unexplained points on it join too)."""
    solids = [i for i, d in enumerate(found) if d.solid is not None]
    if not solids:
        return found
    out = list(found)
    drop = set()
    for i, d in enumerate(found):
        if d.kind != "plane":
            continue
        for j in solids:
            moved = _as_cap(ctx, out[j].solid, d)
            if moved is None:
                continue
            kind, R, t, vals = moved
            pts = _union(out[j].inliers, d.inliers)
            cand = _union(pts, _free_of(ctx, out))
            try:
                R, t, vals, pts, dist = _settle(ctx, kind, R, t, vals, pts, cand)
            except CsdfError:
                continue
            out[j] = _solid_detection(ctx, kind, R, t, vals, pts, dist)
            drop.add(i)
            break
    return [d for i, d in enumerate(out) if i not in drop]


def _make_boxes(ctx: _Ctx, found: list[PrimitiveDetection]) -> list[PrimitiveDetection]:
    """Step 6b: groups of adjacent, mutually orthogonal planes fitted with boxes."""
    planes = [i for i, d in enumerate(found) if d.kind == "plane"]
    if len(planes) < 2:
        return found
    link = (2.0 * ctx.conn if ctx.conn is not None
            else 4.0 * float(np.median(ctx.nb.local)))
    box, pts, plane, spread = {}, {}, {}, {}
    for i in planes:
        pts[i] = ctx.P[found[i].inliers]
        lo, hi = bounds(pts[i])
        box[i] = (lo - link, hi + link)
        plane[i] = (np.asarray(found[i].params["normal"]), found[i].params["offset"])
        spread[i] = float(np.abs(pts[i] @ plane[i][0] - plane[i][1]).max())

    def near(i: int, j: int) -> np.ndarray:
        """The points of plane ``i`` that may lie within ``link`` of one of plane
        ``j``'s: in ``j``'s box grown by ``link``, and within ``link`` of the slab of
        ``j``'s plane that holds its points."""
        return in_box_and_slab(pts[i], box[j][0], box[j][1], plane[j][0],
                               float(plane[j][1]), link + spread[j])

    def touch(i: int, j: int) -> bool:
        """Whether a point of plane ``j`` lies within ``link`` of one of plane ``i``
        (only the points that :func:`near` keeps are compared)."""
        if np.any(box[i][0] > box[j][1] - 2.0 * link) or np.any(box[j][0] > box[i][1]
                                                               - 2.0 * link):
            return False  # (neither has a point in the other's grown box)
        return any_within(near(i, j), near(j, i), link)

    parent = {i: i for i in planes}

    def root(i: int) -> int:
        while parent[i] != i:
            i = parent[i]
        return i

    for a_i, i in enumerate(planes):
        ni = np.asarray(found[i].params["normal"])
        for j in planes[a_i + 1:]:
            nj = np.asarray(found[j].params["normal"])
            if abs(ni @ nj) <= 0.15 and touch(i, j):
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
            box = _box_of(ctx, [found[i] for i in trial],
                          _free_of(ctx, list(out.values())))
            if box is not None:
                first = min(trial)
                for i in trial:
                    out.pop(i, None)
                out[first] = box
                break
    return [out[i] for i in sorted(out)]


def _box_of(ctx: _Ctx, faces: list[PrimitiveDetection], free: np.ndarray
            ) -> PrimitiveDetection | None:
    """A box fitted to the points of ``faces`` (planes), or None when it does not
    explain at least 90% of them. Unexplained points ``free`` on the fitted box
    (connected to its faces: faces too small to be detected on their own) join it
    before the last fit."""
    n0 = np.asarray(faces[0].params["normal"])
    n1 = next((np.asarray(f.params["normal"]) for f in faces[1:]
               if abs(np.asarray(f.params["normal"]) @ n0) < 0.15), None)
    if n1 is None:
        return None
    e1 = n0
    e2 = n1 - (n1 @ e1) * e1
    e2 /= np.linalg.norm(e2)
    R = np.stack([e1, e2, np.cross(e1, e2)], axis=1)
    idx = _union(*[f.inliers for f in faces])
    q = ctx.P[idx] @ R
    lo, hi = bounds(q)
    size = np.maximum(hi - lo, ctx.eps)
    t = R @ (0.5 * (lo + hi))
    vals = {"size_x": float(size[0]), "size_y": float(size[1]), "size_z": float(size[2])}
    try:
        R, t, vals = _fit_solid(ctx, "box", R, t, vals, idx, max_iter=REFIT_ITER)
        if (_on_solid(ctx, "box", R, t, vals, idx)[0].mean() < CAP_SHARE
                or min(vals.values()) <= 2 * ctx.eps):
            return None
        R, t, vals, pts, dist = _settle(ctx, "box", R, t, vals, idx, _union(idx, free))
    except CsdfError:
        return None
    if min(vals.values()) <= 2 * ctx.eps:
        return None
    return _solid_detection(ctx, "box", R, t, vals, pts, dist)
