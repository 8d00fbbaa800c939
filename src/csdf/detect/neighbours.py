"""What detection needs to know about a cloud's neighbourhoods: normals by local principal
component analysis, the point spacing and noise level, and the k-nearest-neighbour graph
that connected components are cut from.

All of it comes from one exact search of the ``k`` nearest neighbours of every point,
made on a grid of cells (:func:`knn`); a :class:`scipy.spatial.cKDTree` of the points is
built only when something asks for it (:attr:`Neighbourhood.tree`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ..errors import CsdfError
from ..points import NEAR_COPY, NEAR_K, has_near_copies, typical_spacing

__all__ = ["Neighbourhood", "neighbourhood", "knn", "estimate_normals", "points_arg",
           "viewpoint_arg", "distinct_points", "exact_copies", "with_copies", "offset_noise",
           "range_noise", "along_rays", "tangent_frames", "spatial_order",
           "normals_arg", "components",
           "linked_edges", "sparse_points", "K_NORMALS", "MAX_DETECT_POINTS", "LINK",
           "SPARSE"]

#: neighbours per point for normals and the neighbour graph
K_NORMALS = 12
#: an edge links two points when no longer than this times the local sampling scale of
#: either end (see :func:`components`)
LINK = 2.0
#: a point is isolated (an outlier) when its local sampling scale is more than this
#: times the scale expected where it lies (see :func:`sparse_points`)
SPARSE = 4.0
#: points whose neighbourhoods estimate the noise level when normals are given
NOISE_SAMPLE = 4000
#: clouds of at least this many points find their neighbours on a grid (:func:`knn`)
GRID_MIN_POINTS = 5000
#: points of the sample that sizes the grid's cells
GRID_SAMPLE = 500
#: the grid's cell side: this quantile of the sample's k-th neighbour distances
GRID_QUANTILE = 0.98
#: the grid's cell side is estimated on every this-many-th point (:func:`_knn`)
SIZING_STEP = 3
#: a point whose neighbours the 3 x 3 x 3 block does not settle searches the cells
#: this many around its own (:func:`_knn`)
WIDE = 2
#: the most cells the grid may have (else the tree answers)
GRID_MAX_CELLS = 4_000_000
#: points of the sample that tells whether a cloud has near-copies (:func:`distinct_points`)
NEAR_SAMPLE = 2000
#: the most points detection accepts in one cloud
MAX_DETECT_POINTS = 5_000_000


def points_arg(points, what: str = "points") -> np.ndarray:
    """``points`` as a finite ``(N, 3)`` float64 array, or a :class:`CsdfError` naming
    ``what`` and the problem."""
    try:
        p = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise CsdfError(f"{what} must be an (N, 3) array of numbers: {e}") from None
    if p.ndim != 2 or p.shape[1] != 3:
        raise CsdfError(f"{what} must be an (N, 3) array; got shape {p.shape}")
    if len(p) > MAX_DETECT_POINTS:
        raise CsdfError(f"{what}: {len(p)} points is more than the limit of "
                        f"{MAX_DETECT_POINTS}; subsample the cloud first")
    bad = ~np.all(np.isfinite(p), axis=1)
    if bad.any():
        raise CsdfError(f"{what}: row {int(np.argmax(bad))} is not finite "
                        f"({int(bad.sum())} such rows)")
    return p


def viewpoint_arg(viewpoint) -> np.ndarray | None:
    """``viewpoint`` as a finite ``(3,)`` array (None stays None), or a CsdfError."""
    if viewpoint is None:
        return None
    try:
        vp = np.asarray(viewpoint, dtype=float)
    except (TypeError, ValueError):
        raise CsdfError(f"viewpoint must be a finite (3,) position (three numbers); got "
                        f"{viewpoint!r}") from None
    if vp.shape != (3,) or not np.all(np.isfinite(vp)):
        raise CsdfError(f"viewpoint must be a finite (3,) position; got {viewpoint!r}")
    return vp


def distinct_points(P: np.ndarray, nb: Neighbourhood | None = None
                    ) -> tuple[np.ndarray, np.ndarray] | None:
    """Repeated points of a cloud ``P`` ``(N, 3)``: None when every row is distinct and
    the cloud has no near-copies, else ``(keep (K,), owner (N,))``: ``keep`` the
    ascending indices of the first point of each group of copies, ``owner[j]`` the
    position in ``keep`` of the point that stands for point ``j``.

    ``nb``, the :class:`Neighbourhood` of ``P`` itself when the caller needs it anyway,
    answers the common case without a search of its own (:func:`_without_copies`: 12 ms
    of a 40k-point cloud's 200 ms in :func:`csdf.detect_primitives`); the answer is the
    same with or without it.

    Copies break the neighbour structure every detector stands on (a point's nearest
    neighbours are its own copies at distance 0, so the sampling scale, the noise and
    the links collapse): a cloud read off a mesh's triangles (each vertex about six
    times) or with a frame added twice found nothing. So did a scan given twice with
    0.5-2 mm of jitter (at 4 mm of noise): when most points have a near-copy
    (:func:`csdf.points.has_near_copies`, judged on a sample of ``NEAR_SAMPLE``), two
    points nearer than ``NEAR_COPY`` times the smaller of their ``NEAR_K``-th neighbour
    distances are copies too (and copies of copies). A cloud without near-copies keeps
    every distinct row. The detectors run on the distinct points and give each result
    every copy (:func:`with_copies`)."""
    if nb is not None and _without_copies(P, nb):
        return None
    rep = exact_copies(P)  # (N,) each point's first exact copy
    folded = _near_copies(P, np.flatnonzero(rep == np.arange(len(P))))
    if folded is not None:
        rep = folded[rep]
    # each group's first point stands for itself (no sort: 3.6 ms on 40k points)
    keep = np.flatnonzero(rep == np.arange(len(P)))
    if len(keep) == len(P):
        return None
    return keep, np.searchsorted(keep, rep)


def _without_copies(P: np.ndarray, nb: Neighbourhood) -> bool:
    """Whether the cloud ``P`` ``(N, 3)`` is known to hold no copies from its own
    neighbourhood ``nb``: no point's nearest other point lies at distance 0 (no exact
    copies), and, when :func:`_near_copies` would look for near-copies, they are not
    found on the same sample of points and the same distances as it uses. False when
    ``nb`` cannot tell (fewer than ``NEAR_K`` neighbours a point)."""
    d = nb.lengths
    if d.ndim != 2 or len(d) != len(P) or d.shape[1] < NEAR_K or np.any(d[:, 0] == 0.0):
        return False
    if len(P) <= 2 * NEAR_K:
        return True
    return not has_near_copies(d[::max(1, len(P) // NEAR_SAMPLE), :NEAR_K])


#: odd 64-bit multipliers of :func:`exact_copies`' row hash
_ROW_HASH = np.array([0x9E3779B97F4A7C15, 0xC2B2AE3D27D4EB4F, 0x165667B19E3779F9],
                     dtype=np.uint64)


def exact_copies(P: np.ndarray) -> np.ndarray:
    """``(N,)`` for each row of ``P`` ``(N, D)`` (float64) the index of the first row
    equal to it (``0.0`` equals ``-0.0``; a row holding NaN equals no other).

    What ``np.unique(P, axis=0, return_index=True, return_inverse=True)`` gives, in a
    fifth of its time on a million rows: the rows are sorted by a 64-bit hash of their
    bits (one integer sort, not a sort of rows), and equal rows are then neighbours.
    When two different rows share a hash (or NaN makes a row unequal to itself) the
    rows are sorted lexicographically instead."""
    P = np.ascontiguousarray(P, dtype=np.float64)
    n = len(P)
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    bits = (P + 0.0).view(np.uint64)  # (+ 0.0: -0.0 becomes 0.0, as == has it)
    h = np.zeros(n, dtype=np.uint64)
    for j in range(P.shape[1]):
        h ^= bits[:, j] * _ROW_HASH[j % len(_ROW_HASH)] + np.uint64(j)
    order = np.argsort(h, kind="stable")
    S = P[order]
    same = np.all(S[1:] == S[:-1], axis=1)
    hs = h[order]
    if np.any((hs[1:] == hs[:-1]) & ~same):  # a shared hash, or NaN
        order = np.lexsort(P.T[::-1])
        S = P[order]
        same = np.all(S[1:] == S[:-1], axis=1)
    new = np.empty(n, dtype=bool)
    new[0] = True
    new[1:] = ~same
    first = order[new]  # (a stable sort: each group's lowest index comes first)
    rep = np.empty(n, dtype=np.int64)
    rep[order] = first[np.cumsum(new) - 1]
    return rep


def _near_copies(P: np.ndarray, distinct: np.ndarray) -> np.ndarray | None:
    """``(N,)`` for each of the ``distinct`` rows of ``P`` the first row (by index) of
    its group of near-copies (other rows: themselves), or None when the cloud has no
    near-copies (see :func:`distinct_points`)."""
    if len(distinct) <= 2 * NEAR_K:
        return None
    D = P[distinct]
    tree = cKDTree(D, balanced_tree=False)
    step = max(1, len(D) // NEAR_SAMPLE)
    dd, _ = tree.query(D[::step], k=NEAR_K + 1)
    if not has_near_copies(dd[:, 1:]):
        return None
    dd, ii = tree.query(D, k=NEAR_K + 1)
    dd, ii = dd[:, 1:], ii[:, 1:]
    far = dd[:, NEAR_K - 1]
    near = dd < NEAR_COPY * np.minimum(far[:, None], far[ii])
    rows = np.repeat(np.arange(len(D)), NEAR_K)[near.ravel()]
    graph = coo_matrix((np.ones(len(rows)), (rows, ii[near])), shape=(len(D), len(D)))
    _, comp = connected_components(graph, directed=False)
    lowest = np.full(comp.max() + 1, len(D))
    np.minimum.at(lowest, comp, np.arange(len(D)))  # distinct is ascending: first row
    out = np.arange(len(P))
    out[distinct] = distinct[lowest[comp]]
    return out


def spatial_order(P: np.ndarray) -> np.ndarray:
    """``(N,)`` the order of the points ``P`` ``(N, 3)`` along a Morton (Z-order) curve
    through their bounding box (:func:`.kernels.morton_keys`; points in one cell keep
    their order): near points come near in that order, so that searches over a
    neighbour graph of the reordered cloud stay in the caches."""
    from .kernels import bounds, morton_keys

    if len(P) < 2:
        return np.arange(len(P))
    lo, hi = bounds(P)
    span = float(np.max(hi - lo))
    scale = ((1 << 21) - 1) / span if span > 0 else 0.0
    return np.argsort(morton_keys(P, lo, scale), kind="stable")


def with_copies(idx: np.ndarray, owner: np.ndarray) -> np.ndarray:
    """The ascending indices of every point whose distinct copy is among ``idx``
    ``(K,)`` (positions in the ``keep`` of :func:`distinct_points`; ``owner`` its
    ``(N,)``)."""
    hit = np.zeros(int(owner.max()) + 1, dtype=bool)
    hit[np.asarray(idx, dtype=np.int64)] = True
    return np.flatnonzero(hit[owner])


def normals_arg(normals, points: np.ndarray) -> np.ndarray:
    """Given normals as unit ``(N, 3)`` rows matching ``points``, or a CsdfError naming
    the first bad row."""
    N = points_arg(normals, "normals")
    if N.shape != points.shape:
        raise CsdfError(f"normals must have the shape of points {points.shape}; got {N.shape}")
    ln = np.linalg.norm(N, axis=1)
    if np.any(ln < 1e-12):
        raise CsdfError(f"normals: row {int(np.argmax(ln < 1e-12))} has zero length")
    return N / ln[:, None]


@dataclass
class Neighbourhood:
    """The k-nearest-neighbour structure of a cloud.

    Attributes:
        tree: the :class:`cKDTree` of the points (a property, built on first use).
        nbr: ``(N, k)`` the indices of each point's ``k`` nearest neighbours (itself
            excluded).
        lengths: ``(N, k)`` their distances (scene units).
        spacing: the median distance to the nearest neighbour, near-copies not counted
            (:func:`csdf.points.typical_spacing`; scene units).
        local: ``(N,)`` each point's distance to its ``k // 2``-th neighbour: the local
            sampling scale (scene units).
        noise: a robust estimate of the noise standard deviation: the median over points
            of the smallest principal standard deviation of their neighbourhoods (scene
            units; curvature raises it a little on curved surfaces).
        normals: ``(N, 3)`` unit normals (the neighbourhoods' least principal axes),
            oriented towards the viewpoint when one was given, else unoriented (None
            when not asked for).
    """

    nbr: np.ndarray
    lengths: np.ndarray
    spacing: float
    local: np.ndarray
    noise: float
    normals: np.ndarray | None
    points: np.ndarray = field(repr=False)
    _tree: cKDTree | None = field(default=None, repr=False)

    @property
    def tree(self) -> cKDTree:
        """The :class:`cKDTree` of the points (built on first use: the neighbours
        themselves are found on a grid)."""
        if self._tree is None:
            self._tree = cKDTree(self.points, balanced_tree=False)
        return self._tree


def neighbourhood(points: np.ndarray, k: int = K_NORMALS, viewpoint=None,
                  want_normals: bool = True) -> Neighbourhood:
    """The :class:`Neighbourhood` of ``points`` ``(N, 3)`` with ``k`` neighbours each
    (fewer when the cloud is smaller); ``viewpoint`` ``(3,)`` orients the normals towards
    the sensor. Without ``want_normals`` the normals are None and the noise level is
    estimated on a subsample of about ``NOISE_SAMPLE`` points."""
    n = len(points)
    k = int(min(k, n - 1))
    if k < 2:
        raise CsdfError(f"a cloud of {n} points is too small to estimate normals")
    held: list[cKDTree] = []

    def get_tree() -> cKDTree:  # (a third quicker to build, as quick to ask)
        if not held:
            held.append(cKDTree(points, balanced_tree=False))
        return held[0]

    dist, idx = _knn(points, get_tree, k)
    # the noise level from a fixed subsample (every point when normals are wanted)
    normals = None
    if not want_normals:
        _, least = _pca_normals(points, idx[::max(1, n // NOISE_SAMPLE)])
    else:
        normals, least = _pca_normals(points, idx)
        if viewpoint is not None:
            flip = np.einsum("ij,ij->i", normals, np.asarray(viewpoint, float) - points) < 0
            normals[flip] *= -1
    return Neighbourhood(points=points, _tree=held[0] if held else None,
                         nbr=np.ascontiguousarray(idx), lengths=dist,
                         spacing=(typical_spacing(dist) if k >= NEAR_K
                                  else float(np.median(dist[:, 0]))),
                         local=dist[:, k // 2 - 1],
                         noise=float(np.median(np.sqrt(np.maximum(least, 0.0)))),
                         normals=normals)


def along_rays(r: np.ndarray, cos: np.ndarray) -> np.ndarray:
    """Offsets ``r`` ``(K,)`` of points from a surface as range errors: a range sensor's
    error lies along its rays, so a point seen at incidence ``theta`` is off the surface
    by the range error times ``cos`` ``(K,)`` (``|cos theta|``). Only the rays within 78
    degrees of the normal (``cos >= 0.2``) are kept and divided; ``r`` unchanged when
    fewer than 20 are."""
    keep = cos >= 0.2
    return r[keep] / cos[keep] if keep.sum() >= 20 else r


def tangent_frames(D: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(u, v)``, each ``(K, 3)``: two unit vectors perpendicular to each unit direction
    of ``D`` ``(K, 3)`` and to each other (``u`` off ``z``, or off ``x`` for directions
    near ``z``)."""
    ref = np.where(np.abs(D[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    u = np.cross(D, ref)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    return u, np.cross(D, u)


def offset_noise(points: np.ndarray, nb: Neighbourhood, viewpoint=None) -> float:
    """A robust noise level of ``points`` ``(N, 3)`` (scene units) that does not fit the
    noise away: the offset of each of about ``NOISE_SAMPLE`` points from the plane of
    its neighbours in ``nb`` (itself not among them), divided, when a ``viewpoint``
    ``(3,)`` is given, by the cosine between that plane's normal and the point's ray (a
    range sensor's noise lies along its rays; rays within 78 degrees of the normal),
    and 1.4826 times the median of those.

    :attr:`Neighbourhood.noise` fits each neighbourhood's plane to the point's own noise
    too, and reads about 0.4 of the noise once it is not small against the spacing (a
    chair scanned at 3 mm read 1.3 mm); curvature raises this one a little."""
    P = np.asarray(points, dtype=float)
    n = len(P)
    sub = np.arange(0, n, max(1, n // NOISE_SAMPLE))
    c = P[nb.nbr[sub]].mean(axis=1)  # (S, 3)
    normal, _ = _pca_normals(P, nb.nbr[sub])
    r = np.abs(np.einsum("ij,ij->i", P[sub] - c, normal))
    if viewpoint is not None:
        ray = P[sub] - np.asarray(viewpoint, dtype=float)
        r = along_rays(r, np.abs(np.einsum("ij,ij->i", ray, normal)) / np.maximum(
            np.linalg.norm(ray, axis=1), 1e-300))
    return 1.4826 * float(np.median(r)) if len(r) else 0.0


def range_noise(points: np.ndarray, viewpoint, k: int = K_NORMALS) -> float:
    """The range noise of a single-view scan ``points`` ``(N, 3)`` seen from
    ``viewpoint`` ``(3,)`` (scene units): a range sensor's noise lies along its rays and
    the rays' directions are exact, so each of about ``NOISE_SAMPLE`` points' range is
    predicted from its ``k`` angularly nearest rays (a plane in the ray directions'
    tangent coordinates, itself left out) and the prediction's residual, divided by
    ``sqrt(1 + h)`` (``h``: the prediction's leverage), is the noise plus the range's
    curvature; 1.4826 times the median of those. Unlike a spatial neighbourhood's
    spread, this does not shrink when the noise is large against the spacing (a lamp
    scanned at 10 mm with 2 mm spacing); depth edges and sharp creases are a minority
    that the median passes over. 0 for fewer than ``k + 2`` points."""
    P = np.asarray(points, dtype=float)
    n = len(P)
    if n < k + 2:
        return 0.0
    ray = P - np.asarray(viewpoint, dtype=float)
    rng = np.linalg.norm(ray, axis=1)
    D = ray / np.maximum(rng, 1e-300)[:, None]
    sub = np.arange(0, n, max(1, n // NOISE_SAMPLE))
    _, idx = cKDTree(D).query(D[sub], k=k + 1)
    idx = idx[:, 1:]  # (S, k) without the point itself
    d0 = D[sub]
    # tangent coordinates of the neighbours' directions about each point's direction
    e1, e2 = tangent_frames(d0)
    dd = D[idx] - d0[:, None, :]  # (S, k, 3)
    X = np.stack([np.ones(idx.shape), np.einsum("skj,sj->sk", dd, e1),
                  np.einsum("skj,sj->sk", dd, e2)], axis=2)  # (S, k, 3)
    A = np.matmul(X.transpose(0, 2, 1), X)  # (S, 3, 3)
    good = np.linalg.det(A) > 1e-30
    A, X, idx, sub = A[good], X[good], idx[good], sub[good]
    Ainv = np.linalg.inv(A)
    coef = np.einsum("sij,skj,sk->si", Ainv, X, rng[idx])
    h = Ainv[:, 0, 0]  # the leverage of the prediction at the point (tangent 0, 0)
    r = np.abs(rng[sub] - coef[:, 0]) / np.sqrt(1.0 + h)
    return 1.4826 * float(np.median(r)) if len(r) else 0.0


def _pca_normals(points: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The least principal axis ``(S, 3)`` (unit, unoriented) and the least eigenvalue
    ``(S,)`` (squared scene units) of the covariance of each row's neighbours
    ``points[idx[i]]`` (``points`` ``(N, 3)``, ``idx`` ``(S, k)``: every point's, or a
    subsample's): in closed form, compiled, on every core
    (:func:`.kernels.pca_normals`); LAPACK's ``eigh`` for the few whose axis the closed
    form leaves ill-defined (neighbours along a line)."""
    from ..parallel import run_parallel
    from .kernels import pca_normals

    n = len(idx)
    P = np.ascontiguousarray(points, dtype=float)
    nbr = np.ascontiguousarray(idx)
    normals = np.empty((n, 3))
    least = np.empty(n)
    ok = np.empty(n, dtype=bool)
    run_parallel(lambda r: pca_normals(P, nbr, r[0], r[1], normals, least, ok), n, 1)
    bad = np.flatnonzero(~ok)
    if len(bad):
        nb = P[nbr[bad]]
        centred = nb - nb.mean(axis=1, keepdims=True)
        w, v = np.linalg.eigh(np.matmul(centred.transpose(0, 2, 1), centred)
                              / nbr.shape[1])
        least[bad] = w[:, 0]
        normals[bad] = v[:, :, 0]
    return normals, least


def knn(points: np.ndarray, tree: cKDTree, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` nearest neighbours of every point of ``points`` ``(N, 3)`` but itself:
    distances ``(N, k)`` (scene units, nearest first) and indices ``(N, k)``.

    Exact, as ``tree.query`` (``tree`` the points' own k-d tree, asked only for small
    clouds and the points the grid leaves; :func:`_knn`)."""
    return _knn(points, lambda: tree, k)


def _knn(points: np.ndarray, get_tree, k: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`knn` with the points' k-d tree from ``get_tree()``, called only when it
    is needed.

    Large clouds are binned in cubic cells whose side ``h`` is the ``GRID_QUANTILE``
    quantile of a sample's ``k``-th neighbour distance, and each point searches the
    3 x 3 x 3 cells around its own (compiled, on every core). That block holds every
    point within ``h``; a point whose ``k``-th neighbour found there is farther (a
    sparse part) searches the ``(2 WIDE + 1)^3`` cells around its own, which hold every
    point within ``WIDE h``, and only the few still farther (outliers) ask the tree.
    ``h`` comes from every ``SIZING_STEP``-th point (its ``k / SIZING_STEP``-th
    neighbour among them stands for the ``k``-th among all: a third of the points as
    dense holds a third as many within any radius), so that no tree of every point is
    built (7 of a 40k-point cloud's 30 ms)."""
    from ..cellsort import group_by_cell
    from ..parallel import N_THREADS, executor
    from .kernels import bounds, cell_keys, knn_block, knn_cells

    n = len(points)
    if n < GRID_MIN_POINTS:
        d, i = get_tree().query(points, k=k + 1, workers=-1)
        return d[:, 1:], i[:, 1:]
    sub = points[::SIZING_STEP]
    ks = max(1, round(k / SIZING_STEP))
    ds, _ = cKDTree(sub, balanced_tree=False).query(sub[::max(1, len(sub) // GRID_SAMPLE)],
                                                    k=ks + 1)
    h = float(np.quantile(ds[:, -1], GRID_QUANTILE))
    lo, hi = bounds(points)
    span = hi - lo
    if not (h > 0 and np.prod(span / h + 1.0) <= GRID_MAX_CELLS):
        d, i = get_tree().query(points, k=k + 1, workers=-1)
        return d[:, 1:], i[:, 1:]
    dims = (span // h).astype(np.int64) + 1
    key = cell_keys(points, lo, h, dims)
    order, first = group_by_cell(key, int(np.prod(dims)))  # a stable sort by key
    skey = key[order]
    cstart = np.concatenate([[0], np.flatnonzero(np.diff(skey)) + 1, [n]])
    ckey = skey[cstart[:-1]]
    dist = np.empty((n, k))
    idx = np.empty((n, k), dtype=np.int64)
    exact = np.empty(n, dtype=bool)
    S = np.ascontiguousarray(points[order])
    # one run of cells per thread, of about equal numbers of points
    parts = min(N_THREADS, max(1, n // GRID_MIN_POINTS))
    cuts = np.searchsorted(cstart, np.linspace(0, n, parts + 1)).tolist()
    cuts[0], cuts[-1] = 0, len(ckey)
    jobs = [(a, b) for a, b in zip(cuts[:-1], cuts[1:]) if b > a]

    def job(r: tuple[int, int]) -> None:
        knn_cells(S, order, first, cstart, ckey, dims, lo, h, k, r[0], r[1], dist, idx,
                  exact)

    if len(jobs) == 1:
        job(jobs[0])
    else:
        list(executor().map(job, jobs))
    redo = np.flatnonzero(~exact)
    if len(redo):
        pos = np.empty(n, dtype=np.int64)
        pos[order] = np.arange(n)
        rows = np.sort(pos[redo])
        knn_block(S, order, first, skey, dims, lo, h, k, rows, WIDE, dist, idx, exact)
        redo = np.flatnonzero(~exact)
    if len(redo):
        d, i = get_tree().query(points[redo], k=k + 1, workers=-1)
        dist[redo], idx[redo] = d[:, 1:], i[:, 1:]
    return dist, idx


def estimate_normals(points, k: int = K_NORMALS, viewpoint=None) -> np.ndarray:
    """Unit normals ``(N, 3)`` of a cloud ``(N, 3)`` by principal component analysis of
    each point's ``k`` nearest neighbours, turned towards ``viewpoint`` ``(3,)`` when
    given (a single-view scan: the sensor position), else of arbitrary sign.

    Raises:
        CsdfError: points not ``(N, 3)``, not finite, or fewer than three.
    """
    p = points_arg(points)
    return neighbourhood(p, k, viewpoint).normals


def linked_edges(nb: Neighbourhood, radius: float | None = None, strict: bool = False
                 ) -> np.ndarray:
    """``(N, k)`` which neighbour edges link their ends: no longer than ``radius``
    (scene units), or, when None, than ``LINK`` times the local sampling scale of either
    end (so that sparse and dense parts of a scan both hold together); ``strict``: of
    both ends (so that an isolated outlier, whose own scale is large, links nothing)."""
    if radius is not None:
        return nb.lengths <= radius
    pick = np.minimum if strict else np.maximum
    return nb.lengths <= LINK * pick(nb.local[:, None], nb.local[nb.nbr])


def sparse_points(nb: Neighbourhood, points: np.ndarray, viewpoint=None) -> np.ndarray:
    """``(N,)`` which points are isolated: their local sampling scale (``nb.local``) is
    more than ``SPARSE`` times the one expected where they lie. With a ``viewpoint``
    ``(3,)`` (a single-view scan, whose spacing grows with the range) the expected
    scale is the median of ``local / range`` times the point's range; without one it is
    the median of ``local``.

    Outliers scattered through a sensor's frustum are far from everything but each
    other, so a linking rule relative to each point's own scale would chain them into
    one web that joins every object; against the expected scale they stand out."""
    if viewpoint is None:
        return nb.local > SPARSE * float(np.median(nb.local))
    rng = np.linalg.norm(points - np.asarray(viewpoint, float), axis=1)
    ratio = nb.local / np.maximum(rng, 1e-300)
    return ratio > SPARSE * float(np.median(ratio))


def components(nb: Neighbourhood, mask: np.ndarray, linked: np.ndarray) -> np.ndarray:
    """Connected components of the points where ``mask`` ``(N,)`` is true, joined by the
    neighbour edges marked in ``linked`` ``(N, k)`` (:func:`linked_edges`; the graph is
    undirected). Returns a ``(N,)`` int label per point, -1 where ``mask`` is false;
    labels are numbered by decreasing size (0 the largest; ties by lowest point)."""
    from .kernels import component_roots

    lab = np.full(len(mask), -1, dtype=np.int64)
    sel = np.flatnonzero(mask)
    if not len(sel):
        return lab
    roots = component_roots(sel, nb.nbr, linked, mask)
    ids, inv, counts = np.unique(roots, return_inverse=True, return_counts=True)
    order = np.argsort(-counts, kind="stable")
    rank = np.empty(len(ids), dtype=np.int64)
    rank[order] = np.arange(len(ids))
    lab[sel] = rank[inv]
    return lab
