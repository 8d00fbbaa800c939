"""The points trees are scored on, and every candidate's values there
(:class:`Pool`): a sample of the cloud with its normals, the free space a single-view
sensor looked through (:func:`free_points`, :func:`background_points`), and points on
each candidate's own surface, each marked where measured points support it."""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import ConvexHull, QhullError, cKDTree

from .candidates import Leaf, leaf_surface, same_leaf
from .search import Scorer

__all__ = ["Pool", "free_points", "background_points", "oriented_normals", "support_scales",
           "foreshortening",
           "SURFACE_SAMPLES", "ORIENTED", "SUPPORT_COS"]

#: points on each candidate's surface for the made-up-surface term (clouds without a
#: viewpoint)
SURFACE_SAMPLES = 200
#: hull points whose normals must point outwards for given normals to be taken as
#: oriented (a share; below ``1 -`` this they are taken as pointing inwards)
ORIENTED = 0.8
#: a measured point supports a surface point when its normal is within this cosine of
#: the surface's
SUPPORT_COS = 0.5


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
        dd, _ = cKDTree(sub).query(sub, k=2)
        cell = 2.5 * max(float(np.median(dd[:, 1])), 1e-9) * math.sqrt(ok.sum() / len(sub))
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
    """

    def __init__(self, S, NS, free, kd, N, reach: float, area: float, tau: float,
                 penalty: float, rng, view: View | None = None):
        self.S, self.NS, self.free, self.kd, self.N, self.view = S, NS, free, kd, N, view
        self.reach, self.area, self.tau, self.penalty, self.rng = reach, area, tau, penalty, rng
        self.leaves: list[Leaf] = []
        self.at_points = np.zeros((0, len(S)))
        self.dots = None if NS is None else np.zeros((0, len(S)))
        self.at_free = None if free is None else np.zeros((0, len(free)))
        self.surf = np.zeros((0, 3))
        self.owner = np.zeros(0, dtype=int)
        self.weight = np.zeros(0)
        self.unsupported = np.zeros((2, 0), dtype=bool)
        self.at_surface = np.zeros((0, 0))
        self._scorer: Scorer | None = None

    def index(self, lf: Leaf) -> int | None:
        """The index of a candidate that is ``lf`` within ``tau / 10``, or None."""
        for i, o in enumerate(self.leaves):
            if same_leaf(lf, o, 0.1 * self.tau):
                return i
        return None

    def add(self, new: list[Leaf]) -> list[int]:
        """Add candidates (those not already held); returns each one's index."""
        out, fresh = [], []
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
        rows, drows, frows = [], [], []
        for lf in fresh:
            f, g = lf.values(self.S)
            rows.append(f)
            if self.NS is not None:
                drows.append(np.einsum("ij,ij->i", g, self.NS))
            if self.free is not None:
                frows.append(lf.values(self.free)[0])
        self.at_points = np.vstack([self.at_points, rows])
        if self.dots is not None:
            self.dots = np.vstack([self.dots, drows])
        if self.at_free is not None:
            self.at_free = np.vstack([self.at_free, frows])
        if self.kd is not None:
            n0 = len(self.leaves) - len(fresh)
            pts, own, wt, grads = [], [], [], []
            for k, lf in enumerate(fresh):
                q, nrm, area = leaf_surface(lf, SURFACE_SAMPLES, self.rng)
                pts.append(q)
                grads.append(nrm)
                own.append(np.full(len(q), n0 + k))
                w = np.full(len(q), area / len(q))
                # one view: surface counts as much as it shows the sensor
                wt.append(w if self.view is None else
                          w * foreshortening(q, nrm, self.view.vp))
            q = np.concatenate(pts)
            far = self._unsupported(q, np.concatenate(grads))
            old = np.array([lf.values(self.surf)[0] for lf in fresh]).reshape(
                len(fresh), len(self.surf))
            cols = np.array([lf.values(q)[0] for lf in self.leaves])
            self.at_surface = np.hstack([np.vstack([self.at_surface, old]), cols])
            self.surf = np.vstack([self.surf, q])
            self.owner = np.concatenate([self.owner, *own])
            self.weight = np.concatenate([self.weight, *wt])
            self.unsupported = np.concatenate([self.unsupported, far], axis=1)
        return out

    def truncate(self, n: int, keep: int | None = None) -> int | None:
        """Drop the candidates from index ``n`` on (trial variants), except ``keep``,
        which becomes candidate ``n`` with its values and surface points as they were;
        returns its new index (None without ``keep``)."""
        rows = list(range(min(n, len(self.leaves))))
        if keep is not None and keep >= n:
            rows.append(keep)
        elif keep is not None:
            return keep
        if len(rows) == len(self.leaves):
            return None if keep is None else n
        self._scorer = None
        self.leaves = [self.leaves[i] for i in rows]
        self.at_points = self.at_points[rows]
        if self.dots is not None:
            self.dots = self.dots[rows]
        if self.at_free is not None:
            self.at_free = self.at_free[rows]
        if self.kd is not None:
            cols = np.isin(self.owner, rows)
            self.at_surface = self.at_surface[rows][:, cols]
            self.surf, self.weight = self.surf[cols], self.weight[cols]
            self.owner = np.where(self.owner[cols] == keep, n, self.owner[cols])
            self.unsupported = self.unsupported[:, cols]
        return None if keep is None else n

    def _unsupported(self, q: np.ndarray, g: np.ndarray) -> np.ndarray:
        """``(2, K)`` which surface points ``q`` ``(K, 3)`` whose leaf's outward normal is
        ``g`` ``(K, 3)`` should have been measured but were not: row 0 where the leaf is
        material (the surface faces along ``g``), row 1 where it is cut away (against
        ``g``). A measured point supports a surface point within ``reach`` with its
        normal within 60 degrees of the surface's (any normal when their signs are
        unknown): the surface of a cut inside a thin wall is near the wall's points,
        but faces the other way. With a single view, only surface the sensor could see
        needs support: facing it, and not behind what it measured (:meth:`View.hidden`)."""
        d, idx = self.kd.query(q, k=8, distance_upper_bound=self.reach)
        near = np.isfinite(d)
        if self.N is None:
            sup = near.any(axis=1)
            out = np.stack([~sup, ~sup])
        else:
            c = np.einsum("ikj,ij->ik", self.N[np.where(near, idx, 0)], g)
            out = np.stack([~(near & (c > SUPPORT_COS)).any(axis=1),
                            ~(near & (c < -SUPPORT_COS)).any(axis=1)])
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
                                      self.penalty, self.at_surface, self.owner,
                                      self.weight / self.area, self.unsupported, signs)
        return self._scorer

    @property
    def kinds(self) -> list[str]:
        """Each candidate's primitive kind."""
        return [lf.kind for lf in self.leaves]
