"""The candidate primitives of :func:`csdf.infer`: the solids a CSG tree is made of.

Sources, all from :func:`csdf.detect_primitives` run on the cloud (and again on the
points the best tree found so far leaves unexplained):

* every detected solid (sphere, cylinder, cone, torus, box), and for a cylinder or a
  cone the other of the two fitted to the same points when that fits them better (a
  narrow band of a cone is within the noise of a cylinder, and detection prefers the
  simpler kind);
* boxes assembled from the detected planes (:func:`plane_boxes`): a box shows as a few
  of its faces, cut or hidden in part by the rest of the tree, often not as a whole box;
* each box and cylinder also with its faces that hold no points moved out to the
  cloud's extent (:func:`extended`): a cutter's ends are outside the object, a trimmed
  solid's are beyond the trimming operand;
* a material cylinder or cone of the whole cloud's detection whose one cap holds no
  points with that cap moved in to where its side's points end, in place of the
  detected one (:func:`trimmed`, ``api.TRIM``): a cap hidden in another operand;
* each curved solid of the whole cloud's detection also as detected again on the
  points near it alone (``api._redetected``): a band seen from one side fits solids of
  several axes.
* a torus through two curved detections of the unexplained points in different places
  (:func:`joined_torus`, ``api._joined``): a torus groove shows as separate arcs, each
  too short to fix its ring.

Each candidate carries the orientation its points show (:attr:`Leaf.sign`): ``+1``
when the cloud's normals point out of it (material: a union or intersection operand,
the minuend of a difference), ``-1`` when they point into it (a cut: the subtrahend of
a difference), ``0`` when unknown. Orientations come from the normals: given, or
estimated and turned to the viewpoint of a single-view scan.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from ..detect.solids import SOLID_BACKEND, SOLID_PARAMS, canonical, solid_values
from ..detect.surfaces import surface_distance
from ..errors import CsdfError
from ..fit import fit
from ..shapes.domain import orient_matrix

__all__ = ["Leaf", "snap", "extended", "trimmed", "cap_cylinder", "joined_torus",
           "face_moves", "leaf_surface", "leaf_area", "plane_boxes", "other_kind",
           "orientation", "same_leaf", "SNAP_DEGREES", "EXTEND_BELOW", "FRAME_DEGREES"]

#: axes within this many degrees of a coordinate axis are turned onto it
SNAP_DEGREES = 1.0
#: a face of a detected box or cylinder with fewer inliers than this is moved out to the
#: cloud's extent in an extra candidate
EXTEND_BELOW = 10
#: planes whose normals are this close (degrees) to a frame's axes are faces of boxes in
#: that frame
FRAME_DEGREES = 4.0
#: a cylinder's (cone's) other kind is kept when its rmse is below this share of the
#: detected kind's
OTHER_KIND_GAIN = 0.9
#: points of a candidate's inliers that the other kind's fit uses at most
OTHER_KIND_POINTS = 600
#: a torus is also offered as a cylinder when its inliers span less than this share of
#: its major radius along its tube (a straight stretch of the tube: detection may take a
#: cylinder seen as a narrow strip of its side for a torus of a huge major radius)
STRAIGHT_TORUS = 0.5
#: the cylinder of such a torus is kept when its rmse is below this share of the
#: torus's (the two fit a straight stretch about as well: the score decides)
STRAIGHT_TORUS_RMSE = 1.1
#: the largest share of a candidate's points whose normals may disagree with its sign
SIGN_AGREE = 0.8


@dataclass
class Leaf:
    """A candidate primitive: the solid of ``kind`` with sizes ``vals`` (scene units)
    placed by rotation ``R`` ``(3, 3)`` and translation ``t`` ``(3,)``
    (``p = R q + t``); ``sign`` the orientation its points show (module docs)."""

    kind: str
    R: np.ndarray
    t: np.ndarray
    vals: dict
    sign: int = 0
    origin: str = field(default="detected", compare=False)

    def values(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Signed distances ``(M,)`` and unit outward gradients ``(M, 3)`` at ``X``
        ``(M, 3)``."""
        return solid_values(self.kind, self.R, self.t, self.vals, X)

    def moved(self, **changes) -> Leaf:
        """A copy with some fields changed."""
        d = {"kind": self.kind, "R": self.R, "t": self.t, "vals": self.vals,
             "sign": self.sign, "origin": self.origin}
        d.update(changes)
        return Leaf(**d)


def snap(lf: Leaf) -> Leaf:
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
        return lf.moved(R=np.eye(3), vals=dict(zip(("size_x", "size_y", "size_z"), world)))
    if lf.kind == "sphere":
        return lf.moved(R=np.eye(3))
    a = lf.R[:, 2]
    k = int(np.argmax(np.abs(a)))
    if math.sqrt(max(0.0, 1.0 - a[k] ** 2)) <= tol:
        a = np.zeros(3)
        a[k] = 1.0 if lf.R[k, 2] > 0 or lf.kind != "cone" else -1.0
        if lf.kind != "cone" and a[k] < 0:
            a = -a
    return lf.moved(R=orient_matrix(a))


def extended(lf: Leaf, P: np.ndarray, inl: np.ndarray) -> Leaf | None:
    """The box or cylinder ``lf`` with each face that holds few of its inliers ``inl``
    ``(K, 3)`` moved out to the cloud ``P``'s extent along that axis (None when every
    face holds some, or for other kinds)."""
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
    return lf.moved(t=lf.t + lf.R @ mid, vals=vals, origin=lf.origin + "+through")


def trimmed(lf: Leaf, Q: np.ndarray, eps: float) -> Leaf | None:
    """The cylinder or cone ``lf`` with each cap that holds fewer than
    :data:`EXTEND_BELOW` of the points ``Q`` ``(K, 3)`` (those near it) moved in to where
    the points on its side end, when that is more than ``eps`` (scene units, the inlier
    distance) in: detection sets the height from its inliers, which near a cap hidden
    in another operand include that operand's points within ``eps`` of the side's
    extension (origin ``'...+trimmed'``). None when no cap moves, when both would
    (the side's points end short of both caps: not one cap hidden in another operand),
    or for other kinds."""
    if lf.kind not in ("cylinder", "cone") or len(Q) < 20:
        return None
    r1, r2, z0, _, _, _ = _frustum(lf)
    h = lf.vals["height"]
    q = (Q - lf.t) @ lf.R
    z, rad = q[:, 2], np.hypot(q[:, 0], q[:, 1])
    on_side = np.abs(rad - (r1 + (r2 - r1) * (z - z0) / h)) <= eps
    if np.sum(on_side) < 20:
        return None
    lo, hi = z0, z0 + h
    if np.sum((np.abs(z - lo) <= eps) & (rad < r1 - eps)) < EXTEND_BELOW:
        lo = max(lo, float(z[on_side].min()))
    if np.sum((np.abs(z - hi) <= eps) & (rad < r2 - eps)) < EXTEND_BELOW:
        hi = min(hi, float(z[on_side].max()))
    if (lo - z0 <= eps and z0 + h - hi <= eps) or hi - lo <= 2 * eps:
        return None
    if lo - z0 > eps and z0 + h - hi > eps:
        # both caps: not a cap hidden in another operand, but a solid detected on
        # something else (a long cone over a flat stretch; benchmarks/INFER_RESULTS.md,
        # session 21)
        return None
    vals = dict(lf.vals)
    vals["height"] = hi - lo
    if lf.kind == "cylinder":
        return lf.moved(t=lf.t + lf.R[:, 2] * (0.5 * (lo + hi)), vals=vals,
                        origin=lf.origin + "+trimmed")
    vals["r1"] = r1 + (r2 - r1) * (lo - z0) / h
    vals["r2"] = r1 + (r2 - r1) * (hi - z0) / h
    return lf.moved(t=lf.t + lf.R[:, 2] * lo, vals=vals, origin=lf.origin + "+trimmed")


#: how far a face moves in :func:`face_moves`, as shares of the solid's size along it
FACE_STEPS = (-0.5, -0.25, -0.1, 0.1, 0.25, 0.5, 1.0)


def face_moves(lf: Leaf, P: np.ndarray) -> list[Leaf]:
    """The box or cylinder ``lf`` with one face (a cylinder: one cap) moved along its
    axis by each of :data:`FACE_STEPS` of the size there, or out to the extent of the
    cloud ``P`` ``(N, 3)``; none for other kinds. The points fix a face they lie on; a
    face none lies on (hidden in another operand, or cut away) is where the score's
    free-space terms put it."""
    if lf.kind not in ("box", "cylinder"):
        return []
    names = ("size_x", "size_y", "size_z") if lf.kind == "box" else (None, None, "height")
    axes = (0, 1, 2) if lf.kind == "box" else (2,)
    a = (P - lf.t) @ lf.R
    out = []
    for k in axes:
        size = lf.vals[names[k]]
        for side in (-1.0, 1.0):
            far = float(a[:, k].max()) if side > 0 else float(-a[:, k].min())
            for step in (*(f * size for f in FACE_STEPS), far - size / 2):
                new = size + step
                if new <= 1e-3 * size or abs(step) < 1e-9:
                    continue
                vals = dict(lf.vals)
                vals[names[k]] = new
                out.append(lf.moved(t=lf.t + lf.R[:, k] * (side * step / 2), vals=vals,
                                    origin=lf.origin))
    return out


def leaf_surface(lf: Leaf, n: int, rng: np.random.Generator
                 ) -> tuple[np.ndarray, np.ndarray, float]:
    """``n`` points spread uniformly by area over a leaf's surface: ``(points (n, 3),
    outward unit normals (n, 3), area)`` (scene frame and units; the normals from the
    solid's shape, as the distance's gradient can vanish on an edge or a cap)."""
    v = lf.vals
    area = leaf_area(lf)
    u = rng.random((n, 3))
    ang = 2 * math.pi * u[:, 0]
    c, s = np.cos(ang), np.sin(ang)
    radial = np.stack([c, s, np.zeros(n)], axis=1)
    z_axis = np.array([0.0, 0.0, 1.0])
    if lf.kind == "sphere":
        d = rng.normal(size=(n, 3))
        nrm = d / np.linalg.norm(d, axis=1, keepdims=True)
        q = v["radius"] * nrm
    elif lf.kind == "torus":
        R, r = v["major"], v["minor"]
        # the tube angle with density proportional to the distance from the axis
        phi = 2 * math.pi * u[:, 1]
        for _ in range(8):
            bad = u[:, 2] * (R + r) > R + r * np.cos(phi)
            if not bad.any():
                break
            phi[bad] = 2 * math.pi * rng.random(int(bad.sum()))
            u[bad, 2] = rng.random(int(bad.sum()))
        nrm = np.cos(phi)[:, None] * radial + np.sin(phi)[:, None] * z_axis
        q = R * radial + r * nrm
    elif lf.kind == "box":
        h, faces = _box_faces(v)
        axis = np.searchsorted(np.cumsum(faces) / faces.sum(), u[:, 0] * 0.999999)
        sign = np.where(u[:, 1] < 0.5, -1.0, 1.0)
        q = (2 * rng.random((n, 3)) - 1) * h
        q[np.arange(n), axis] = sign * h[axis]
        nrm = np.zeros((n, 3))
        nrm[np.arange(n), axis] = sign
    else:  # cylinder and cone: side and two caps
        r1, r2, z0, slant, side, caps = _frustum(lf)
        hgt = v["height"]
        w = u[:, 1] * area
        t = u[:, 2]
        # the side: height by area (radius linear in height)
        z = t if r1 == r2 else (np.sqrt(r1 * r1 + t * (r2 * r2 - r1 * r1)) - r1) / (r2 - r1)
        on_side = w < side
        on_base = ~on_side & (w < side + caps[0])
        cap_r = np.sqrt(rng.random(n)) * np.where(on_base, r1, r2)
        rad = np.where(on_side, r1 + (r2 - r1) * z, cap_r)
        zz = np.where(on_side, z, np.where(on_base, 0.0, 1.0))
        q = np.stack([rad * c, rad * s, z0 + zz * hgt], axis=1)
        side_n = (hgt * radial + (r1 - r2) * z_axis) / max(slant, 1e-300)
        cap_n = np.where(on_base, -1.0, 1.0)[:, None] * z_axis
        nrm = np.where(on_side[:, None], side_n, cap_n)
    return q @ lf.R.T + lf.t, nrm @ lf.R.T, float(area)


def _box_faces(v: dict) -> tuple[np.ndarray, np.ndarray]:
    """A box's half sizes ``(3,)`` and the areas ``(3,)`` of its faces across x, y, z."""
    h = np.array([v["size_x"], v["size_y"], v["size_z"]]) / 2
    return h, np.array([4 * h[1] * h[2], 4 * h[0] * h[2], 4 * h[0] * h[1]])


def _frustum(lf: Leaf) -> tuple[float, float, float, float, float, tuple[float, float]]:
    """A cylinder's or cone's ``(r1, r2, z0, slant, side area, (base cap area, top cap
    area))``: radii at its base and top, the base's height in the leaf's frame, the
    side's slant length (scene units and units squared)."""
    v = lf.vals
    if lf.kind == "cylinder":
        r1 = r2 = v["radius"]
        z0 = -0.5 * v["height"]
    else:
        r1, r2, z0 = v["r1"], v["r2"], 0.0
    slant = math.hypot(v["height"], r1 - r2)
    return (r1, r2, z0, slant, math.pi * (r1 + r2) * slant,
            (math.pi * r1 * r1, math.pi * r2 * r2))


def leaf_area(lf: Leaf) -> float:
    """The area of a leaf's surface (scene units squared), the one :func:`leaf_surface`
    gives, without drawing points."""
    v = lf.vals
    if lf.kind == "sphere":
        return 4 * math.pi * v["radius"] ** 2
    if lf.kind == "torus":
        return 4 * math.pi ** 2 * v["major"] * v["minor"]
    if lf.kind == "box":
        return 2 * float(_box_faces(v)[1].sum())
    _, _, _, _, side, caps = _frustum(lf)
    return side + caps[0] + caps[1]


def orientation(lf: Leaf, Q: np.ndarray, NQ: np.ndarray) -> int:
    """The sign its points ``Q`` ``(K, 3)`` with normals ``NQ`` ``(K, 3)`` show of the
    leaf: +1 when at least :data:`SIGN_AGREE` of the normals point out of it, -1 when
    as many point into it, else 0."""
    if not len(Q):
        return 0
    _, g = lf.values(Q)
    out = float(np.mean(np.einsum("ij,ij->i", g, NQ) > 0))
    return 1 if out >= SIGN_AGREE else (-1 if out <= 1 - SIGN_AGREE else 0)


def same_leaf(a: Leaf, b: Leaf, tol: float) -> bool:
    """Whether two candidates are the same solid within ``tol`` (scene units) in position
    and sizes, with the same axes and sign."""
    if a.kind != b.kind or a.sign != b.sign:
        return False
    if np.abs(a.t - b.t).max() > tol or np.abs(a.R - b.R).max() > 0.02:
        return False
    return all(abs(a.vals[k] - b.vals[k]) <= tol for k in a.vals)


def other_kind(lf: Leaf, Q: np.ndarray, rmse: float, eps: float) -> Leaf | None:
    """A cone fitted to a cylinder's inliers ``Q`` ``(K, 3)`` (or a cylinder to a
    cone's) when its rmse is below :data:`OTHER_KIND_GAIN` times ``rmse``, the detected
    kind's (scene units), or a cylinder fitted to a torus's straight stretch
    (:func:`straight_torus`); else None. ``eps``: the noise level of the robust
    loss."""
    if lf.kind == "torus" and len(Q) >= 20:
        return straight_torus(lf, Q, rmse, eps)
    if lf.kind not in ("cylinder", "cone") or len(Q) < 20:
        return None
    if lf.kind == "cylinder":
        r, h = lf.vals["radius"], lf.vals["height"]
        # capped_cone's base (r1) is at z = -h/2 of a centred cylinder's frame
        kind, vals = "cone", {"r1": 1.02 * r, "r2": 0.98 * r, "height": h}
    else:
        r1, r2, h = lf.vals["r1"], lf.vals["r2"], lf.vals["height"]
        kind, vals = "cylinder", {"radius": 0.5 * (r1 + r2), "height": h}
    t0 = lf.t - lf.R[:, 2] * (0.5 * lf.vals["height"]) if kind == "cone" else \
        lf.t + lf.R[:, 2] * (0.5 * lf.vals["height"])
    return _fitted_as(kind, Q, lf.R, t0, vals, lf.sign, eps, "other-kind",
                      OTHER_KIND_GAIN * rmse)


def _fitted_as(kind: str, Q: np.ndarray, R: np.ndarray, t: np.ndarray, vals: dict,
               sign: int, eps: float, origin: str, below: float) -> Leaf | None:
    """A ``kind`` solid fitted to the points ``Q`` ``(K, 3)`` (at most
    :data:`OTHER_KIND_POINTS` of them, evenly spaced) from the pose ``R`` ``(3, 3)``,
    ``t`` ``(3,)`` and sizes ``vals``, as a leaf of ``sign`` and ``origin``, when its
    sizes are finite and positive and its rmse over those points is below ``below``
    (scene units); else None. ``eps``: the noise level of the robust loss."""
    if len(Q) > OTHER_KIND_POINTS:
        Q = Q[np.linspace(0, len(Q) - 1, OTHER_KIND_POINTS).astype(int)]
    shape, _ = canonical(kind)
    try:
        res = fit(shape, Q, init={"rotation": R, "translation": t, "scale": 1.0,
                                  "params": vals},
                  estimate=("pose", "params"), loss="huber", f_scale=eps / 3.0,
                  escape=False, debias=False, backend=SOLID_BACKEND, max_iter=60)
    except CsdfError:
        return None
    new = Leaf(kind, np.asarray(res.rotation, float), np.asarray(res.translation, float),
               {k: float(res.params[k]) for k in SOLID_PARAMS[kind]}, sign, origin=origin)
    if not all(np.isfinite(v) and v > 0 for v in new.vals.values()):
        return None
    d, _ = new.values(Q)
    return new if float(np.sqrt(np.mean(d * d))) < below else None


def straight_torus(lf: Leaf, Q: np.ndarray, rmse: float, eps: float) -> Leaf | None:
    """A cylinder fitted to a torus's inliers ``Q`` ``(K, 3)`` when they span less than
    :data:`STRAIGHT_TORUS` of its major radius along its tube, started from the
    tube's tangent there (radius the minor radius, height the points' extent along the
    tangent), kept when its rmse is below :data:`STRAIGHT_TORUS_RMSE` times the
    torus's ``rmse`` (scene units); else None. ``eps``: the noise level of the robust
    loss."""
    R, major, minor = lf.R, lf.vals["major"], lf.vals["minor"]
    a = R[:, 2]
    c = Q.mean(axis=0) - lf.t
    v = c - (c @ a) * a  # towards the points, in the torus's plane
    if np.linalg.norm(v) < 1e-12 or major < 2.0 * minor:
        return None
    u = v / np.linalg.norm(v)
    axis = np.cross(a, u)  # the tube's direction there
    along = (Q - lf.t) @ axis
    if float(np.ptp(along)) >= STRAIGHT_TORUS * major:
        return None
    centre = lf.t + major * u + (c @ a) * a + 0.5 * (along.max() + along.min()) * axis
    vals = {"radius": minor, "height": max(float(np.ptp(along)), 2.0 * eps)}
    return _fitted_as("cylinder", Q, orient_matrix(axis), centre, vals, lf.sign, eps,
                      "straight-torus", STRAIGHT_TORUS_RMSE * rmse)


@dataclass
class _Wall:
    """A plane of the cloud as a face of boxes in a frame: on axis ``axis`` with outward
    normal ``side * e_axis`` at ``offset`` (along ``e_axis``); ``q`` ``(K, 3)`` its
    inliers in the frame's coordinates, ``lo``, ``hi`` ``(3,)`` their extent (2nd and
    98th percentiles)."""

    axis: int
    side: int
    offset: float
    q: np.ndarray
    lo: np.ndarray
    hi: np.ndarray


def _frames(normals: list[np.ndarray], sizes: list[int]) -> list[tuple[np.ndarray, list[int]]]:
    """Orthonormal frames ``(R (3, 3), member plane indices)`` covering the planes:
    the largest plane not yet covered gives the first axis, the largest plane nearly
    orthogonal to it the second; members lie within :data:`FRAME_DEGREES` of an axis."""
    cos_tol = math.cos(math.radians(FRAME_DEGREES))
    sin_tol = math.sin(math.radians(FRAME_DEGREES))
    left = sorted(range(len(normals)), key=lambda i: -sizes[i])
    out = []
    while left:
        e1 = normals[left[0]]
        e2 = None
        for j in left[1:]:
            if abs(float(normals[j] @ e1)) < sin_tol:
                e2 = normals[j] - float(normals[j] @ e1) * e1
                break
        if e2 is None:  # a lone direction: any completion (its in-plane sides go through)
            helper = np.eye(3)[int(np.argmin(np.abs(e1)))]
            e2 = helper - float(helper @ e1) * e1
        e2 = e2 / np.linalg.norm(e2)
        R = np.stack([e1, e2, np.cross(e1, e2)], axis=1)
        members = [i for i in left if np.abs(R.T @ normals[i]).max() >= cos_tol]
        out.append((R, members))
        left = [i for i in left if i not in members]
    return out


def _adjacent(a: np.ndarray, b: np.ndarray, link: float, trees: dict, ia: int) -> bool:
    """Whether any point of ``b`` lies within ``link`` of the points ``a`` (plane
    ``ia``'s, its k-d tree cached in ``trees``)."""
    if ia not in trees:
        trees[ia] = cKDTree(a)
    d, _ = trees[ia].query(b, k=1, distance_upper_bound=link)
    return bool(np.isfinite(d).any())


def plane_boxes(planes: list[tuple[np.ndarray, float, np.ndarray]], P: np.ndarray,
                eps: float, link: float) -> list[Leaf]:
    """Boxes whose faces are the detected planes.

    Args:
        planes: ``(normal (3,), offset, inliers (K, 3))`` of each plane, normals
            outward (towards the viewpoint of a scan, along the given normals of a full
            cloud).
        P: ``(N, 3)`` the cloud: unseen faces of cutting boxes, and the depth of a
            lone face, go to its extent.
        eps: the noise level (scene units): offsets closer than ``2 eps`` are one.
        link: how close (scene units) the points of two faces come where they meet.

    Returns:
        Candidate boxes, each with its role as :attr:`Leaf.sign`: material (``+1``:
        the planes' normals point out of it) or a cut (``-1``: they point into it).
        Planes whose normals lie along the axes of one frame are the walls a box of
        that frame may have: for each wall and role, the box with that wall as a face
        whose other faces are the walls that fit it best (each wall's points inside
        the box's other extents; the most points), for the roles the wall's
        neighbours allow (a wall meeting others at convex edges is a face of a solid,
        at concave edges of a cut; a wall without neighbours, both). A side without
        a wall reaches beyond the cloud (a cut; a lone wall; a solid trimmed by
        another operand: origin ``'planes+through'``) or, for a solid, as far as its
        walls' points (hidden in another operand).
    """
    if not planes:
        return []
    normals = [np.asarray(n, float) / np.linalg.norm(n) for n, _, _ in planes]
    out: list[Leaf] = []
    trees: dict[int, cKDTree] = {}
    for R, members in _frames(normals, [len(q) for _, _, q in planes]):
        walls: dict[int, _Wall] = {}
        for i in members:
            c = R.T @ normals[i]
            k = int(np.argmax(np.abs(c)))
            q = planes[i][2] @ R
            walls[i] = _Wall(k, 1 if c[k] > 0 else -1, float(np.median(q[:, k])), q,
                             np.percentile(q, 2, axis=0), np.percentile(q, 98, axis=0))
        a = P @ R
        span = a.max(axis=0) - a.min(axis=0)
        far_lo = a.min(axis=0) - 0.05 * span - 2 * eps
        far_hi = a.max(axis=0) + 0.05 * span + 2 * eps
        for i, w in walls.items():
            for role in _roles(i, w, walls, planes, link, trees, eps):
                faces = _best_faces(i, w, walls, role, eps)
                for through in (False, True) if role > 0 and len(faces) > 1 else (True,):
                    box = _bounds(faces, role, through, far_lo, far_hi)
                    if box is None or np.any(box[1] - box[0] <= 2 * eps):
                        continue
                    lo, hi = box
                    lf = Leaf("box", R, R @ (0.5 * (lo + hi)),
                              dict(zip(("size_x", "size_y", "size_z"), (hi - lo).tolist())),
                              role, origin="planes+through" if through and role > 0
                              else "planes")
                    if not any(same_leaf(lf, o, 2 * eps) for o in out):
                        out.append(lf)
    return out


def _roles(i: int, w: _Wall, walls: dict[int, _Wall], planes, link: float, trees: dict,
           eps: float) -> tuple[int, ...]:
    """The roles wall ``i`` may take: from the edges where its points meet another
    wall's (convex: a solid's face, +1; concave: a cut's, -1); both without such
    edges."""

    def behind(u: _Wall, v: _Wall) -> float:
        """The median signed height of ``v``'s points over ``u``'s plane, outward."""
        return float(np.median(u.side * (v.q[:, u.axis] - u.offset)))

    roles = set()
    for j, v in walls.items():
        if j == i or v.axis == w.axis or not _adjacent(planes[i][2], planes[j][2], link,
                                                        trees, i):
            continue
        h1, h2 = behind(w, v), behind(v, w)
        if h1 < -eps and h2 < -eps:
            roles.add(1)
        elif h1 > eps and h2 > eps:
            roles.add(-1)
    return tuple(sorted(roles, reverse=True)) or (1, -1)


#: walls of one axis and side a box of :func:`plane_boxes` chooses among (the largest)
BOX_WALL_CHOICES = 3


def _best_faces(i: int, w: _Wall, walls: dict[int, _Wall], role: int, eps: float
                ) -> list[_Wall]:
    """The walls of the box of ``role`` with wall ``i`` as a face: of every choice of at
    most one wall for each of its other five sides (the :data:`BOX_WALL_CHOICES`
    largest of each, or none), the one whose walls hold the most points, each wall's
    points lying inside the box's extents on the other two axes (within ``3 eps``)."""
    slots: dict[tuple[int, bool], list[_Wall]] = {}
    for j, v in walls.items():
        if j != i:
            slots.setdefault((v.axis, _is_hi(v, role)), []).append(v)
    own = (w.axis, _is_hi(w, role))
    keys = [(k, h) for k in range(3) for h in (False, True) if (k, h) != own]
    options = [[None] + sorted(slots.get(key, []), key=lambda v: -len(v.q))[:BOX_WALL_CHOICES]
               for key in keys]
    tol = 3 * eps
    best: list[_Wall] = [w]
    best_n = -1
    for combo in itertools.product(*options):
        faces = [w] + [v for v in combo if v is not None]
        lo, hi = _wall_bounds(faces, role, -np.inf, np.inf)
        if np.any(hi - lo <= 2 * eps):
            continue
        if not all(np.all((v.lo >= lo - tol) | (np.arange(3) == v.axis)) and
                   np.all((v.hi <= hi + tol) | (np.arange(3) == v.axis)) for v in faces):
            continue
        n = sum(len(v.q) for v in faces)
        if n > best_n:
            best, best_n = faces, n
    return best


def _is_hi(v: _Wall, role: int) -> bool:
    """Whether wall ``v`` is the high side of its axis in a box of ``role``: its outward
    normal is +e (a solid) or -e (a cut)."""
    return (v.side > 0) == (role > 0)


def _wall_bounds(faces: list[_Wall], role: int, lo0: float, hi0: float
                 ) -> tuple[np.ndarray, np.ndarray]:
    """``(lo (3,), hi (3,))``: the offsets of the walls ``faces`` of a box of ``role`` on
    its sides, ``lo0`` and ``hi0`` where it has no wall."""
    lo = np.full(3, lo0)
    hi = np.full(3, hi0)
    for v in faces:
        if _is_hi(v, role):
            hi[v.axis] = v.offset
        else:
            lo[v.axis] = v.offset
    return lo, hi


def _bounds(faces: list[_Wall], role: int, through: bool, far_lo: np.ndarray,
            far_hi: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """The box ``(lo (3,), hi (3,))`` in the frame of the walls ``faces`` of ``role``;
    sides without a wall reach beyond the cloud (``far_lo``, ``far_hi`` ``(3,)``) for a
    cut, a lone face or ``through``, else as far as the walls' points."""
    lo, hi = _wall_bounds(faces, role, np.nan, np.nan)
    pts = np.concatenate([v.q for v in faces])
    far = role < 0 or len(faces) == 1 or through
    for k in range(3):
        if np.isnan(lo[k]):
            lo[k] = far_lo[k] if far else pts[:, k].min()
        if np.isnan(hi[k]):
            hi[k] = far_hi[k] if far else pts[:, k].max()
    return lo, hi


#: a detected plane of at least this many points is tried as the cap of a cylinder
#: whose side the view barely shows (:func:`cap_cylinder`)
CAP_MIN = 200
#: the share of the plane's outline points the cap's circle must hold
CAP_OUTLINE_SHARE = 0.25
#: ... spread over at least this many degrees of the circle
CAP_ARC_DEGREES = 90.0
#: ... and at most this many: a disk bounded by its circle over more than half a turn
#: is an end the sensor sees past, so it sees the solid's side there too, and
#: detection finds that solid (a cone's base, a cylinder standing up); only a disk
#: clipped by other operands hides its side. On the one-view set 2-5 the arcs of
#: more than 180 degrees were cones' bases and a box face's island inside a torus cut
#: (trees 8, 77, 99: 77 lost with them), the kept ones 130-170 (5 gained)
CAP_ARC_MAX_DEGREES = 180.0


def cap_cylinder(normal: np.ndarray, Q: np.ndarray, P: np.ndarray, spacing: float,
                 seed: int = 0) -> Leaf | None:
    """A material cylinder whose cap is the detected plane of outward unit ``normal``
    ``(3,)`` and inliers ``Q`` ``(K, 3)``, when part of the plane's outline is a
    circle's arc (at least :data:`CAP_OUTLINE_SHARE` of its outline points over
    :data:`CAP_ARC_DEGREES` to :data:`CAP_ARC_MAX_DEGREES`, every inlier inside it):
    a cylinder cut by other operands may show its cap and little of its side, and
    detection then finds only the plane. Its axis is the normal, its radius the
    circle's, and it reaches from the cap to the cloud ``P``'s extent behind it.
    ``spacing``: the point spacing (scene units); ``seed``: the circle sampling's
    (its own generator). None when no arc fits."""
    if len(Q) < CAP_MIN:
        return None
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    F = orient_matrix(n)
    c0 = Q.mean(axis=0)
    x2 = (Q - c0) @ F[:, :2]
    # the outline: points whose neighbours leave a gap of more than 120 degrees
    # around them (the inliers of a plane seen obliquely are spaced unevenly)
    _, nb = cKDTree(x2).query(x2, k=13)
    rel = x2[nb[:, 1:]] - x2[:, None, :]
    ang = np.sort(np.arctan2(rel[..., 1], rel[..., 0]), axis=1)
    gaps = np.diff(np.concatenate([ang, ang[:, :1] + 2 * math.pi], axis=1), axis=1)
    B = x2[gaps.max(axis=1) > math.radians(120.0)]
    if len(B) < 30:
        return None
    rng = np.random.default_rng(seed)
    tol = 1.5 * spacing
    extent = float(np.linalg.norm(np.ptp(x2, axis=0)))
    best = None
    for _ in range(300):
        a, b, c = B[rng.choice(len(B), 3, replace=False)]
        # the circumcircle of a, b, c
        d = 2.0 * (a[0] * (b[1] - c[1]) + b[0] * (c[1] - a[1]) + c[0] * (a[1] - b[1]))
        if abs(d) < 1e-12:
            continue
        sa, sb, sc = a @ a, b @ b, c @ c
        cx = (sa * (b[1] - c[1]) + sb * (c[1] - a[1]) + sc * (a[1] - b[1])) / d
        cy = (sa * (c[0] - b[0]) + sb * (a[0] - c[0]) + sc * (b[0] - a[0])) / d
        ctr = np.array([cx, cy])
        r = float(np.linalg.norm(a - ctr))
        if not 4 * spacing < r < 2.0 * extent:
            continue
        on = np.abs(np.linalg.norm(B - ctr, axis=1) - r) <= tol
        if best is not None and on.sum() <= best[0]:
            continue
        best = (int(on.sum()), ctr, r)
    if best is None or best[0] < max(30, CAP_OUTLINE_SHARE * len(B)):
        return None
    _, ctr, r = best
    on = np.abs(np.linalg.norm(B - ctr, axis=1) - r) <= tol
    ctr, r = _kasa_circle(B[on])  # least squares circle through the arc's points
    if not 4 * spacing < r < 2.0 * extent:
        return None
    if np.mean(np.linalg.norm(x2 - ctr, axis=1) > r + tol) > 0.01:
        return None  # the cap holds points outside the circle
    ang = np.degrees(np.arctan2(*(B[on] - ctr).T[::-1]))
    bins = np.unique(np.floor((ang + 180.0) / 10.0).astype(int))
    if not CAP_ARC_DEGREES <= 10.0 * len(bins) <= CAP_ARC_MAX_DEGREES:
        return None
    centre = c0 + F[:, :2] @ ctr
    depth = float(np.max((centre - P) @ n))
    if depth <= 4 * spacing:
        return None
    h = depth + 2 * spacing
    return Leaf("cylinder", F, centre - n * (0.5 * h), {"radius": r, "height": h}, 1,
                origin="cap")


#: minor radii :func:`joined_torus` tries, as shares of the joined points' extent
#: (a geometric grid), each with the tube on either side of the points
JOIN_MINOR = tuple(float(x) for x in np.geomspace(0.02, 0.5, 12))
#: a joined torus is kept when its rmse over both pieces' points is at most this times
#: the larger of the pieces' own rmse (it explains them as well as each piece's fit)
JOIN_RMSE = 1.25
#: ... and it holds this share of each piece's points within the noise level
JOIN_INSIDE = 0.9
#: ... and its points span at least this share of its major radius (a chord of a
#: sixth of the ring at 1): two patches spanning less bend their tube's centre line
#: too little to tell a ring from a straight stretch (two patches of one cylinder) or
#: from a bend the noise makes. On the one-view set 2-5 tree 3's join spans 2.4 times
#: its ring's radius (arcs on opposite sides of it), the one dropped 0.85 (tree 2: a
#: ring of radius 2.2 through two patches of the object, used by no tree but
#: perturbing the search)
JOIN_SPAN = 1.0
#: the centres' circle is refined only when its torus's rmse is within this many
#: times the kept torus's bound (the fit moves it by a noise level or so)
JOIN_START = 4.0


def _kasa_circle(x: np.ndarray) -> tuple[np.ndarray, float]:
    """Kasa's algebraic least-squares circle of 2D points ``x`` ``(K, 2)``:
    ``(centre (2,), radius)``."""
    A = np.column_stack([2.0 * x, np.ones(len(x))])
    sol, *_ = np.linalg.lstsq(A, (x * x).sum(axis=1), rcond=None)
    ctr = sol[:2]
    return ctr, math.sqrt(max(float(sol[2] + ctr @ ctr), 0.0))


def _circle_3d(C: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """The least-squares circle of points ``C`` ``(K, 3)``: ``(centre (3,), unit axis
    (3,), radius)`` (the plane by principal components, then :func:`_kasa_circle` in
    it)."""
    c0 = C.mean(axis=0)
    _, _, Vt = np.linalg.svd(C - c0, full_matrices=False)
    ctr, r = _kasa_circle((C - c0) @ Vt[:2].T)
    return c0 + Vt[:2].T @ ctr, Vt[2], r


def joined_torus(Qa: np.ndarray, Qb: np.ndarray, Na: np.ndarray, Nb: np.ndarray,
                 rmse: float, eps: float) -> Leaf | None:
    """One torus through two separate patches, ``Qa`` ``(Ka, 3)`` and ``Qb`` ``(Kb, 3)``
    with normals ``Na``, ``Nb`` (oriented alike; outwards for the leaf's sign), or
    None. A torus cut into an object shows its groove wherever it enters the material,
    often as separate arcs (across a ball: two, on opposite sides of its ring); each arc
    alone fits tori of any axis within the noise (its tube's curvature is all it
    shows, and a short stretch of a tube bends either way), but the tube centres of
    both (each point moved by the minor radius along its normal) lie on the one
    circle. For each minor radius of :data:`JOIN_MINOR` and each side, the centres'
    least-squares circle gives a torus; the one closest to the points is refined by
    :func:`csdf.fit`, and kept when the points span at least :data:`JOIN_SPAN` of its
    major radius (else its ring is not shown: a straight stretch of a tube, as two
    patches of one cylinder show, or a bend within the noise), its rmse over the
    points is at most
    :data:`JOIN_RMSE` times ``rmse`` (scene units: the larger of the two patches' own
    fits') and it holds :data:`JOIN_INSIDE` of each patch's points within ``eps``
    (the noise level). Origin ``'joined'``; the sign from the normals."""
    Q = np.concatenate([Qa, Qb])
    NQ = np.concatenate([Na, Nb])
    NQ = NQ / np.maximum(np.linalg.norm(NQ, axis=1, keepdims=True), 1e-300)
    extent = float(np.linalg.norm(np.ptp(Q, axis=0)))
    if len(Qa) < 4 or len(Qb) < 4 or extent <= 0.0:
        return None
    best = None
    for share in JOIN_MINOR:
        r = share * extent
        for side in (1.0, -1.0):
            centre, axis, major = _circle_3d(Q - side * r * NQ)
            if not r < major <= extent / JOIN_SPAN:
                continue
            d, _ = surface_distance("torus", np.array([[*centre, *axis, major, r]]), Q)
            e = float(np.sqrt(np.mean(d[0] ** 2)))
            if best is None or e < best[0]:
                best = (e, centre, axis, major, r)
    if best is None or best[0] > JOIN_START * JOIN_RMSE * rmse:
        return None
    _, centre, axis, major, r = best
    lf = _fitted_as("torus", Q, orient_matrix(axis), centre, {"major": major, "minor": r},
                    0, eps, "joined", JOIN_RMSE * rmse)
    if lf is None or not lf.vals["minor"] < lf.vals["major"] <= extent / JOIN_SPAN:
        return None
    for X in (Qa, Qb):
        if np.mean(np.abs(lf.values(X)[0]) <= eps) < JOIN_INSIDE:
            return None
    return lf.moved(sign=orientation(lf, Q, np.concatenate([Na, Nb])))
