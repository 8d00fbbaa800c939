"""The points trees are scored on, and every candidate's values there
(:class:`Pool`): a sample of the cloud with its normals, the free space a single-view
sensor looked through (:func:`free_points`, :func:`background_points`), and points on
each candidate's own surface, each marked where measured points support it."""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import ConvexHull, QhullError, cKDTree

from ..points import sample_spacing
from .candidates import Leaf, leaf_area, leaf_surface, same_leaf
from .search import Scored, Scorer, swap
from .tree import leaves as tree_leaves
from .tree import relabel

__all__ = ["Pool", "free_points", "background_points", "oriented_normals", "support_scales",
           "foreshortening",
           "surface_samples", "SURFACE_SAMPLES", "SURFACE_SHARE", "SURFACE_MAX", "ORIENTED",
           "SUPPORT_COS", "SUPPORT_COS_ESTIMATED"]

#: the fewest points drawn on each candidate's surface for the made-up-surface term
SURFACE_SAMPLES = 200
#: the most of the measured surface's area one of those points may stand for (a share):
#: a large leaf gets more points (:func:`surface_samples`), so that one point that
#: happens to fall where nothing was measured (near an edge, on a sliver the tree
#: keeps) cannot cost a quarter of a primitive's penalty or more. With a fixed count, a
#: box mostly trimmed away (seven times the area the sensor saw) had points standing
#: for 0.036 each, nine penalties: the made-up surface of the true tree came out
#: anywhere from 0.000 to 0.08 with the draw (benchmarks/INFER_RESULTS.md, session 18)
SURFACE_SHARE = 0.001
#: the most points drawn on one candidate's surface
SURFACE_MAX = 4000
#: hull points whose normals must point outwards for given normals to be taken as
#: oriented (a share; below ``1 -`` this they are taken as pointing inwards)
ORIENTED = 0.8
#: a measured point supports a surface point when its normal is within this cosine of
#: the surface's
SUPPORT_COS = 0.5
#: the same for normals estimated from the points (a scan's): any normal on the
#: surface's side. Near an edge the neighbours of an estimated normal lie on both
#: faces, so it leans up to 90 degrees off either: with :data:`SUPPORT_COS` the true
#: tree of a box trimmed by a cylinder made up 0.009-0.016 of surface along the
#: trimmed edge (two to four penalties), 0.001 with this (benchmarks/INFER_RESULTS.md,
#: session 18). A cut's wall inside a thin part still faces against the part's points.
SUPPORT_COS_ESTIMATED = 0.0


def _fit(buf: np.ndarray, rows: int | None, cols: int | None = None) -> np.ndarray:
    """``buf`` (1-D, or 2-D for ``cols``) with room for ``rows`` rows and ``cols``
    columns (None: as they are), at least doubled when it grows, its content kept."""
    shape = list(buf.shape)
    want = list(shape)
    if rows is not None and rows > shape[0]:
        want[0] = max(rows, 2 * shape[0])
    if cols is not None and cols > shape[1]:
        want[1] = max(cols, 2 * shape[1])
    if want == shape:
        return buf
    out = np.zeros(want, dtype=buf.dtype)
    out[tuple(slice(0, k) for k in shape)] = buf
    return out


def surface_samples(area: float, measured: float) -> int:
    """How many points to draw on a candidate's surface of ``area`` (scene units
    squared) for the made-up-surface term, against the ``measured`` surface's area
    (the same units): each stands for at most :data:`SURFACE_SHARE` of the measured
    area, at least :data:`SURFACE_SAMPLES` and at most :data:`SURFACE_MAX` of them."""
    if not (measured > 0 and math.isfinite(area)):
        return SURFACE_SAMPLES
    return int(min(SURFACE_MAX, max(SURFACE_SAMPLES,
                                    math.ceil(area / (SURFACE_SHARE * measured)))))


def free_points(P: np.ndarray, vp: np.ndarray, tau: float, diag: float, rng, n: int
                 ) -> np.ndarray:
    """``(n, 3)`` points the sensor looked through: on the rays from ``vp`` to a sample
    of the points ``P`` ``(N, 3)``, between ``3 tau`` and half the cloud's diagonal
    ``diag`` in front of them (scene units)."""
    idx = rng.choice(len(P), size=min(n, len(P)), replace=False)
    Q = P[idx]
    d = vp - Q
    r = np.linalg.norm(d, axis=1)
    ok = r > 6 * tau
    Q, d, r = Q[ok], d[ok], r[ok]
    s = rng.uniform(3 * tau, np.maximum(np.minimum(0.5 * diag, r - 3 * tau), 3 * tau))
    return Q + (s / r)[:, None] * d


class View:
    """What a single-view sensor at ``vp`` ``(3,)`` saw of the cloud ``P`` ``(N, 3)``: a
    grid of directions on the image plane facing the cloud (cells 2.5 angular point
    spacings wide, out to 15 % past the cloud's extent), each cell's nearest and
    farthest measured range (scene units; empty cells none). ``rng`` draws the spacing
    sample."""

    def __init__(self, P: np.ndarray, vp: np.ndarray, rng):
        self.vp = vp
        d = P - vp
        r = np.linalg.norm(d, axis=1)
        u = d / r[:, None]
        z = u.mean(axis=0)
        self.z = z / np.linalg.norm(z)
        x = np.cross(self.z, np.eye(3)[int(np.argmin(np.abs(self.z)))])
        self.x = x / np.linalg.norm(x)
        self.y = np.cross(self.z, self.x)
        self.r_lo, self.r_hi = float(r.min()), float(r.max())
        uv, ok = self._plane(P)
        sub = uv[ok][rng.choice(int(ok.sum()), size=min(int(ok.sum()), 20000), replace=False)]
        gap = sample_spacing(cKDTree(sub), sub)
        cell = 2.5 * max(gap, 1e-9) * math.sqrt(ok.sum() / len(sub))
        lo, hi = uv[ok].min(axis=0), uv[ok].max(axis=0)
        pad = 0.15 * (hi - lo) + cell
        self.lo, self.hi = lo - pad, hi + pad
        self.shape = np.minimum(np.ceil((self.hi - self.lo) / cell).astype(int), 2000)
        ij, inside = self.cells(P)
        keep = ok & inside
        flat = np.ravel_multi_index((ij[keep, 0], ij[keep, 1]), self.shape)
        self.near = np.full(self.shape, np.inf).ravel()
        self.far = np.full(self.shape, -np.inf).ravel()
        np.minimum.at(self.near, flat, r[keep])
        np.maximum.at(self.far, flat, r[keep])
        self.near, self.far = self.near.reshape(self.shape), self.far.reshape(self.shape)

    def _plane(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Image-plane coordinates ``(M, 2)`` of points ``X`` ``(M, 3)`` and which lie in
        front of the sensor."""
        d = X - self.vp
        dz = d @ self.z
        ok = dz > 1e-12
        safe = np.where(ok, dz, 1.0)
        return np.stack([(d @ self.x) / safe, (d @ self.y) / safe], axis=1), ok

    def cells(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The grid cell ``(M, 2)`` of each point of ``X`` ``(M, 3)`` and whether it falls
        on the grid (in front of the sensor)."""
        uv, ok = self._plane(X)
        ij = np.floor((uv - self.lo) / (self.hi - self.lo) * self.shape).astype(int)
        inside = ok & np.all((ij >= 0) & (ij < self.shape), axis=1)
        return np.clip(ij, 0, self.shape - 1), inside

    def background(self, diag: float, rng, n: int) -> np.ndarray:
        """``(<= n, 3)`` points on rays that met nothing: through cells with no measured
        point in them or next to them (around the silhouette and through holes), at the
        depths of the cloud, give or take a quarter of its diagonal ``diag``."""
        occ = np.isfinite(self.near)
        grown = occ.copy()  # a cell next to a measured one is seen
        grown[1:] |= occ[:-1]
        grown[:-1] |= occ[1:]
        grown[:, 1:] |= occ[:, :-1]
        grown[:, :-1] |= occ[:, 1:]
        empty = np.argwhere(~grown)
        if not len(empty):
            return np.zeros((0, 3))
        pick = empty[rng.integers(0, len(empty), n)]
        a = self.lo + (pick + rng.random((n, 2))) / self.shape * (self.hi - self.lo)
        rays = self.z + a[:, :1] * self.x + a[:, 1:] * self.y
        rays /= np.linalg.norm(rays, axis=1, keepdims=True)
        depth = rng.uniform(max(self.r_lo - 0.25 * diag, 0.0), self.r_hi + 0.25 * diag, n)
        return self.vp + depth[:, None] * rays

    def hidden(self, X: np.ndarray, tol: float) -> np.ndarray:
        """``(M,)`` which points ``X`` ``(M, 3)`` lie behind what the sensor measured in
        their cell (farther than the cell's farthest point by more than ``tol``): the
        sensor could not have seen them."""
        ij, inside = self.cells(X)
        r = np.linalg.norm(X - self.vp, axis=1)
        far = self.far[ij[:, 0], ij[:, 1]]
        return inside & np.isfinite(far) & (r > far + tol)


def background_points(P: np.ndarray, vp: np.ndarray, diag: float, rng, n: int
                      ) -> np.ndarray:
    """``(<= n, 3)`` points on rays from ``vp`` ``(3,)`` that met nothing: the directions
    around the silhouette of the cloud ``P`` ``(N, 3)`` (and through its holes) where no
    point was measured, at the cloud's depths (scene units; :class:`View`)."""
    return View(P, vp, rng).background(diag, rng, n)


def support_scales(kd: cKDTree, S: np.ndarray, n: int, tau: float,
                   NS: np.ndarray | None = None, vp: np.ndarray | None = None
                   ) -> tuple[float, float]:
    """``(reach, area)`` of a cloud of ``n`` points (its k-d tree ``kd``, a sample ``S``
    ``(M, 3)`` of it): how far (scene units) a measured point may be from surface it
    supports (three point spacings, at least ``3 tau``), and the measured surface's
    area (scene units squared: each point stands for ``pi r^2 / k``, ``r`` the distance
    to its ``k``-th neighbour, ``k = 8``). With a single view (``vp`` ``(3,)`` and the
    sample's normals ``NS`` ``(M, 3)``), the area as the sensor sees it: each point's
    share foreshortened by the cosine between its normal and its ray
    (:func:`foreshortening`), the same measure as the made-up surface's."""
    k = 8
    m = min(len(S), 2000)
    d, _ = kd.query(S[:m], k=k + 1)
    reach = max(3.0 * tau, 3.0 * float(np.median(d[:, 1])))
    if vp is None or NS is None:
        return reach, n * math.pi * float(np.median(d[:, k])) ** 2 / k
    share = math.pi * d[:, k] ** 2 / k * foreshortening(S[:m], NS[:m], vp)
    return reach, n * float(np.mean(share))


def foreshortening(q: np.ndarray, g: np.ndarray, vp: np.ndarray) -> np.ndarray:
    """``(K,)`` ``|cos|`` of the angle between the unit normals ``g`` ``(K, 3)`` at the
    points ``q`` ``(K, 3)`` and the rays from the sensor at ``vp`` ``(3,)``: the
    share of its area a surface element shows the sensor, so the share of the returns
    it is expected to give (a face seen edge-on gives almost none, and a sensor drops
    the grazing returns it does measure)."""
    ray = q - vp
    ray /= np.maximum(np.linalg.norm(ray, axis=1, keepdims=True), 1e-300)
    return np.abs(np.einsum("ij,ij->i", g, ray))


def oriented_normals(P: np.ndarray, N: np.ndarray) -> np.ndarray | None:
    """Given normals turned outwards, or None when their signs are not consistent: on
    the points of the cloud's convex hull, outward normals point away from the
    centroid (:data:`ORIENTED` of them at least)."""
    try:
        hull = ConvexHull(P)
    except (QhullError, ValueError):
        return None
    v = hull.vertices
    out = float(np.mean(np.einsum("ij,ij->i", N[v], P[v] - P.mean(axis=0)) > 0))
    if out >= ORIENTED:
        return N
    if out <= 1 - ORIENTED:
        return -N
    return None


class Pool:
    """The candidate leaves and their values at the points trees are scored on, grown
    as candidates are added (a refined tree's primitives, residual detections).

    Args:
        S: ``(M, 3)`` the sample of the points; ``NS`` ``(M, 3)`` their outward
            normals, or None.
        free: ``(Q, 3)`` free-space points, or None.
        kd: a k-d tree of the cloud, or None (no made-up-surface term); ``N``
            ``(N, 3)`` the cloud's outward normals, or None.
        reach: how far a measured point may be from surface it supports.
        area: the measured surface's area (scene units squared; with ``kd``).
        tau, penalty: as :class:`Scorer`'s.
        rng: draws the points on the candidates' surfaces.
        view: what a single-view sensor saw (:class:`View`), or None (a cloud taken
            all around).
        estimated: whether the normals ``N`` were estimated from the points (a
            measured point then supports surface facing within 90 degrees of its
            normal, :data:`SUPPORT_COS_ESTIMATED`; else 60, :data:`SUPPORT_COS`).
    """

    def __init__(self, S, NS, free, kd, N, reach: float, area: float, tau: float,
                 penalty: float, rng, view: View | None = None, estimated: bool = False):
        self.support_cos = SUPPORT_COS_ESTIMATED if estimated else SUPPORT_COS
        self.S, self.NS, self.free, self.kd, self.N, self.view = S, NS, free, kd, N, view
        self.reach, self.area, self.tau, self.penalty, self.rng = reach, area, tau, penalty, rng
        self.leaves: list[Leaf] = []
        # growable buffers (rows: candidates; columns of the surface ones: points on
        # the candidates' surfaces), so that adding a candidate copies nothing
        m = len(S)
        self._pts = np.zeros((16, m))
        self._dots = None if NS is None else np.zeros((16, m))
        self._free = None if free is None else np.zeros((16, len(free)))
        self._ns = 0  # surface points held
        self._surf = np.zeros((1024, 3))
        self._owner = np.zeros(1024, dtype=int)
        self._weight = np.zeros(1024)
        self._uns = np.zeros((2, 1024), dtype=bool)
        # the candidates' values at the surface points, evaluated on demand, one
        # candidate at one candidate's points at a time (:meth:`surface_block`): a
        # tree's score needs its own leaves' values at its own leaves' points only,
        # and most pairs of candidates never meet in a tree scored
        self._span = np.zeros((16, 2), dtype=int)  # each one's points: columns [lo, hi)
        self._have = np.zeros((16, 16), dtype=bool)  # [i, j]: i's values at j's points
        self._srows: list[np.ndarray] = []  # [i]: i's values (S,) where _have says
        self._scorer: Scorer | None = None

    # views of the buffers: ``(L, M)``, ``(L, M)``, ``(L, Q)``, ``(L, S)``, ``(S, 3)``,
    # ``(S,)``, ``(S,)``, ``(2, S)`` for ``L`` candidates and ``S`` surface points
    @property
    def at_points(self) -> np.ndarray:
        """``(L, M)`` each candidate's signed distance at the sample of the points."""
        return self._pts[:len(self.leaves)]

    @property
    def dots(self) -> np.ndarray | None:
        """``(L, M)`` cosines between each candidate's gradient and the sample's
        normals, or None."""
        return None if self._dots is None else self._dots[:len(self.leaves)]

    @property
    def at_free(self) -> np.ndarray | None:
        """``(L, Q)`` each candidate's signed distance at the free-space points, or
        None."""
        return None if self._free is None else self._free[:len(self.leaves)]

    @property
    def at_surface(self) -> np.ndarray:
        """``(L, S)`` each candidate's signed distance at the surface points: the whole
        table, every entry evaluated now (the search asks for blocks of it,
        :meth:`surface_block`)."""
        everyone = list(range(len(self.leaves)))
        return self.surface_block(everyone, np.arange(self._ns))

    def surface_block(self, rows: list[int], idx: np.ndarray) -> np.ndarray:
        """``(len(rows), len(idx))`` the candidates ``rows``' signed distances at the
        surface points ``idx`` (column indices), which must lie on the surfaces of
        ``rows`` (as a tree's score needs them): the values of one candidate at
        another's points are evaluated the first time they are asked for, at all of
        that candidate's points (:meth:`filled`). The values are those evaluating
        every candidate at every surface point gives (a leaf's value at a point does
        not depend on the other points evaluated with it)."""
        self._fill(rows)
        out = np.empty((len(rows), len(idx)))
        for r, i in enumerate(rows):
            out[r] = self._srows[i][idx]
        return out

    def _fill(self, rows: list[int]) -> None:
        """Evaluate each candidate of ``rows`` at the surface points of those of
        ``rows`` where it has not been yet."""
        have = self._have
        for i in rows:
            miss = [j for j in rows if not have[i, j]]
            if not miss:
                continue
            spans = self._span[miss]
            cols = np.concatenate([np.arange(lo, hi) for lo, hi in spans])
            if len(cols):
                row = self._srows[i]
                if len(row) < self._ns:  # room for every surface point held
                    grown = np.zeros(max(self._ns, 2 * len(row)))
                    grown[:len(row)] = row
                    row = self._srows[i] = grown
                row[cols] = self.leaves[i].values(self._surf[cols])[0]
            have[i, miss] = True

    def filled(self) -> float:
        """The share of the ``(L, S)`` table of the candidates' values at the surface
        points evaluated so far (:meth:`surface_block`)."""
        if not self._ns:
            return 1.0
        n = len(self.leaves)
        width = (self._span[:n, 1] - self._span[:n, 0]).astype(float)
        return float((self._have[:n, :n] * width).sum() / (n * self._ns))

    @property
    def surf(self) -> np.ndarray:
        """``(S, 3)`` the points on the candidates' surfaces that no measured point
        supports (:meth:`_unsupported`: only those can count)."""
        return self._surf[:self._ns]

    @property
    def owner(self) -> np.ndarray:
        """``(S,)`` the candidate each surface point lies on."""
        return self._owner[:self._ns]

    @property
    def weight(self) -> np.ndarray:
        """``(S,)`` the area (scene units squared) each surface point stands for
        (foreshortened with a viewpoint)."""
        return self._weight[:self._ns]

    @property
    def unsupported(self) -> np.ndarray:
        """``(2, S)`` which surface points measured points do not support: row 0 for
        a material leaf, row 1 for a cut."""
        return self._uns[:, :self._ns]

    def index(self, lf: Leaf) -> int | None:
        """The index of a candidate that is ``lf`` within ``tau / 10``, or None."""
        for i, o in enumerate(self.leaves):
            if same_leaf(lf, o, 0.1 * self.tau):
                return i
        return None

    def _rows(self, leaves: list[Leaf]) -> tuple[np.ndarray, np.ndarray | None,
                                                  np.ndarray | None]:
        """``leaves``' values ``(K, M)`` at the sample, cosines ``(K, M)`` (or None) and
        values ``(K, Q)`` at the free-space points (or None)."""
        rows, drows, frows = [], [], []
        for lf in leaves:
            f, g = lf.values(self.S)
            rows.append(f)
            if self.NS is not None:
                drows.append(np.einsum("ij,ij->i", g, self.NS))
            if self.free is not None:
                frows.append(lf.values(self.free)[0])
        m = len(self.S)
        return (np.array(rows).reshape(len(leaves), m),
                None if self.NS is None else np.array(drows).reshape(len(leaves), m),
                None if self.free is None else
                np.array(frows).reshape(len(leaves), len(self.free)))

    def _draw(self, leaves: list[Leaf], wanted: list[bool] | None = None
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Points on the surfaces of ``leaves`` (:func:`surface_samples` of each) that
        measured points do not support: ``(points (K, 3), unsupported (2, K), the leaf
        each lies on (K,) as an index into leaves, weight (K,))``. A point measured
        points support, the way its leaf may be used (as material for a leaf of sign
        +1, as a cut for -1, either for 0: :func:`.search.consistent`), never counts:
        only the others are kept. ``wanted``: which leaves' points to return (the
        others' are drawn all the same, so that the draws do not depend on it, but
        not looked at)."""
        pts, own, wt, grads = [], [], [], []
        for k, lf in enumerate(leaves):
            n = surface_samples(leaf_area(lf), self.area)
            q, nrm, area = leaf_surface(lf, n, self.rng)
            if wanted is not None and not wanted[k]:
                continue
            pts.append(q)
            grads.append(nrm)
            own.append(np.full(len(q), k))
            w = np.full(len(q), area / len(q))
            # one view: surface counts as much as it shows the sensor
            wt.append(w if self.view is None else w * foreshortening(q, nrm, self.view.vp))
        if not pts:
            return np.zeros((0, 3)), np.zeros((2, 0), bool), np.zeros(0, int), np.zeros(0)
        q = np.concatenate(pts)
        far = self._unsupported(q, np.concatenate(grads))
        owner = np.concatenate(own)
        sign = np.array([lf.sign for lf in leaves], dtype=int)[owner]
        keep = np.where(sign > 0, far[0], np.where(sign < 0, far[1], far[0] | far[1]))
        return q[keep], far[:, keep], owner[keep], np.concatenate(wt)[keep]

    @staticmethod
    def _values(leaves: list[Leaf], X: np.ndarray) -> np.ndarray:
        """``(len(leaves), len(X))`` the leaves' signed distances at ``X`` ``(K, 3)``."""
        out = np.empty((len(leaves), len(X)))
        for i, lf in enumerate(leaves):
            out[i] = lf.values(X)[0] if len(X) else 0.0
        return out

    def add(self, new: list[Leaf]) -> list[int]:
        """Add candidates (those not already held); returns each one's index."""
        out, fresh = [], []
        n0 = len(self.leaves)
        for lf in new:
            i = self.index(lf)
            if i is None:
                i = len(self.leaves)
                self.leaves.append(lf)
                fresh.append(lf)
            out.append(i)
        if not fresh:
            return out
        self._scorer = None
        n1 = len(self.leaves)
        rows, drows, frows = self._rows(fresh)
        self._pts = _fit(self._pts, n1)
        self._pts[n0:n1] = rows
        if self._dots is not None:
            self._dots = _fit(self._dots, n1)
            self._dots[n0:n1] = drows
        if self._free is not None:
            self._free = _fit(self._free, n1)
            self._free[n0:n1] = frows
        if self.kd is not None:
            q, far, own, wt = self._draw(fresh)
            s0, s1 = self._ns, self._ns + len(q)
            # own is grouped by leaf, in order: each new leaf's points are one run
            k = np.arange(len(fresh))
            self._span = _fit(self._span, n1)
            self._span[n0:n1, 0] = s0 + np.searchsorted(own, k, "left")
            self._span[n0:n1, 1] = s0 + np.searchsorted(own, k, "right")
            self._have = _fit(self._have, n1, n1)
            self._srows += [np.zeros(0) for _ in fresh]
            self._surf = _fit(self._surf, s1)
            self._surf[s0:s1] = q
            self._owner = _fit(self._owner, s1)
            self._owner[s0:s1] = n0 + own
            self._weight = _fit(self._weight, s1)
            self._weight[s0:s1] = wt
            self._uns = _fit(self._uns, None, s1)
            self._uns[:, s0:s1] = far
            self._ns = s1
        return out

    def trial(self, tree, c: int, variants: list[Leaf], below: float = math.inf
              ) -> list[Scored | None]:
        """The scores of ``tree`` with its leaf ``c`` replaced by each of ``variants``
        (leaves not added to the pool): as :meth:`scorer` would give them once added,
        but computed over the tree's own leaves alone (a face moved: a dozen trial
        leaves per face, where adding them would evaluate every candidate at their
        surface points). The trees of the returned :class:`Scored` are in the indices
        of a sub-pool (``tree``'s leaves, then the variants): use only their scores.
        None for a variant whose score is ``below`` or more: its data and free-space
        terms are taken first, and when they reach ``below`` its surface points are
        drawn (the others' draws stay as they were) but not looked at."""
        used = sorted({int(i) for i in tree_leaves(tree)})
        u, m = len(used), len(variants)
        sub = {i: k for k, i in enumerate(used)}
        rows, drows, frows = self._rows(variants)
        at_points = np.vstack([self.at_points[used], rows])
        dots = None if drows is None else np.vstack([self.dots[used], drows])
        at_free = None if frows is None else np.vstack([self.at_free[used], frows])
        signs = np.array([self.leaves[i].sign for i in used] + [v.sign for v in variants],
                         dtype=int)
        base = relabel(tree, sub)
        trees = [swap(base, sub[c], u + j) for j in range(m)]
        # the score less the made-up surface: a lower bound
        scorer = Scorer(at_points, dots, at_free, self.tau, self.penalty, signs=signs)
        live = [scorer.score_below(t, below) is not None for t in trees]
        if self.kd is not None:
            cols = np.flatnonzero(np.isin(self.owner, used))
            q, far, own, wt = self._draw(variants, live)
            old_q = self.surf[cols]
            mine = [self.leaves[i] for i in used]
            # a variant at another variant's points is never needed (no tree holds
            # two of them): those entries stay 0
            own_vals = np.zeros((m, len(q)))
            at_old = np.zeros((m, len(old_q)))  # a variant that cannot win: 0
            for j, v in enumerate(variants):
                if not live[j]:
                    continue
                on = own == j
                if on.any():
                    own_vals[j, on] = v.values(q[on])[0]
                if len(old_q):
                    at_old[j] = v.values(old_q)[0]
            at_surface = np.block([
                [self.surface_block(used, cols), self._values(mine, q)],
                [at_old, own_vals]])
            owner = np.concatenate([np.array([sub[int(i)] for i in self.owner[cols]],
                                             dtype=int), u + own])
            weight = np.concatenate([self.weight[cols], wt])
            unsupported = np.concatenate([self.unsupported[:, cols], far], axis=1)
            scorer = Scorer(at_points, dots, at_free, self.tau, self.penalty, at_surface,
                            owner, weight / self.area, unsupported, signs)
        return [scorer.score_below(t, below) if ok else None for t, ok in zip(trees, live)]

    def _unsupported(self, q: np.ndarray, g: np.ndarray) -> np.ndarray:
        """``(2, K)`` which surface points ``q`` ``(K, 3)`` whose leaf's outward normal is
        ``g`` ``(K, 3)`` should have been measured but were not: row 0 where the leaf is
        material (the surface faces along ``g``), row 1 where it is cut away (against
        ``g``). A measured point supports a surface point within ``reach`` with its
        normal within 60 degrees of the surface's (90 for estimated normals; any
        normal when their signs are unknown): the surface of a cut inside a thin wall
        is near the wall's points, but faces the other way. With a single view, only
        surface the sensor could see needs support: facing it, and not behind what it
        measured (:meth:`View.hidden`)."""
        d, idx = self.kd.query(q, k=8, distance_upper_bound=self.reach)
        near = np.isfinite(d)
        if self.N is None:
            sup = near.any(axis=1)
            out = np.stack([~sup, ~sup])
        else:
            c = np.einsum("ikj,ij->ik", self.N[np.where(near, idx, 0)], g)
            out = np.stack([~(near & (c > self.support_cos)).any(axis=1),
                            ~(near & (c < -self.support_cos)).any(axis=1)])
        if self.view is not None:
            seen = ~self.view.hidden(q, 3 * self.tau)
            facing = np.einsum("ij,ij->i", g, self.view.vp - q) > 0
            out &= np.stack([seen & facing, seen & ~facing])
        return out

    def scorer(self) -> Scorer:
        """The :class:`Scorer` of trees over the held candidates."""
        if self._scorer is None:
            signs = np.array([lf.sign for lf in self.leaves], dtype=int)
            if self.kd is None:
                self._scorer = Scorer(self.at_points, self.dots, self.at_free, self.tau,
                                      self.penalty, signs=signs)
            else:
                self._scorer = Scorer(self.at_points, self.dots, self.at_free, self.tau,
                                      self.penalty, None, self.owner,
                                      self.weight / self.area, self.unsupported, signs,
                                      surface=self.surface_block)
        return self._scorer

    @property
    def kinds(self) -> list[str]:
        """Each candidate's primitive kind."""
        return [lf.kind for lf in self.leaves]
