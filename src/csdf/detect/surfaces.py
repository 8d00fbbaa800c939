"""The surfaces of primitive detection: hypotheses from minimal sets of oriented points,
and each surface's distance and normal, vectorised over many hypotheses at once.

A hypothesis is one row of a parameter array whose layout depends on the kind:

==========  ====================================================  ======
kind        row                                                   width
==========  ====================================================  ======
plane       normal (3), offset ``n . p``                          4
sphere      centre (3), radius                                    4
cylinder    point on the axis (3), axis (3), radius               7
cone        apex (3), axis from the apex into the cone (3), half angle  7
torus       centre (3), axis (3), major radius, minor radius      8
==========  ====================================================  ======

The surfaces are unbounded here (a whole plane, an infinite cylinder, one nappe of a
cone): detection bounds them afterwards by the extent of the points they explain.
Distances are Euclidean and exact for plane, sphere, cylinder and torus; for the cone
it is the distance to the nappe's generating line in the point's half plane, exact
wherever the nearest point of the nappe is not the apex's other side (that is, for
every point the detection keeps).

The minimal sets (Schnabel, Wahl and Klein, "Efficient RANSAC for point-cloud shape
detection", 2007): a plane from three points, a sphere or a cylinder from two points
with normals, a cone from three, a torus from four (the tube centres ``p_i - r n_i``
are coplanar: a cubic in the minor radius ``r``).
"""

from __future__ import annotations

import numpy as np

from .kernels import inlier_counts as _counts
from .kernels import surface_values

__all__ = ["KINDS", "WIDTH", "KIND_ID", "surface_distance", "inlier_counts", "planes_from",
           "spheres_from", "cylinders_from", "cones_from", "tori_from", "frame_z"]

#: the surface kinds, simplest first (a tie in explained points goes to the simpler)
KINDS = ("plane", "sphere", "cylinder", "cone", "torus")
#: parameters per hypothesis of each kind
WIDTH = {"plane": 4, "sphere": 4, "cylinder": 7, "cone": 7, "torus": 8}
#: each kind's number in the compiled kernels (:mod:`.kernels`)
KIND_ID = {k: i for i, k in enumerate(KINDS)}


def _unit(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    n = np.linalg.norm(v, axis=-1)
    return v / np.maximum(n, 1e-300)[..., None], n


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("...i,...i->...", a, b)


def surface_distance(kind: str, H: np.ndarray, P: np.ndarray, N: np.ndarray | None = None
                     ) -> tuple[np.ndarray, np.ndarray | None]:
    """Distances and normal agreements of points to hypotheses (compiled:
    :func:`csdf.detect.kernels.surface_values`).

    Args:
        kind: one of :data:`KINDS`.
        H: ``(M, WIDTH[kind])`` hypotheses (the table above).
        P: ``(S, 3)`` points, or ``(M, S, 3)``: points of each hypothesis's own.
        N: unit normals of the points, shaped as ``P``, or None.

    Returns:
        ``(d, c)``: ``d`` ``(M, S)`` signed distances (positive outside a sphere,
        cylinder, cone or torus and on the normal's side of a plane); ``c`` ``(M, S)``
        ``|cos|`` of the angle between each point's normal and the surface normal at its
        nearest point, or None without normals.
    """
    P3 = np.ascontiguousarray(P[None] if P.ndim == 2 else P, dtype=np.float64)
    N3 = (np.zeros((0, 1, 3)) if N is None
          else np.ascontiguousarray(N[None] if N.ndim == 2 else N, dtype=np.float64))
    d, c = surface_values(KIND_ID[kind], np.ascontiguousarray(H, dtype=np.float64), P3, N3)
    return d, (None if N is None else c)


def inlier_counts(kind: str, H: np.ndarray, P: np.ndarray, N: np.ndarray, eps: float,
                  cos_tol: float) -> np.ndarray:
    """``(M,)`` how many of the points ``P`` ``(S, 3)`` with unit normals ``N``
    ``(S, 3)`` are inliers of each hypothesis ``H`` ``(M, WIDTH[kind])``: within
    ``eps`` (scene units) of it, normals within ``acos(cos_tol)`` of its normal."""
    return _counts(KIND_ID[kind], np.ascontiguousarray(H, dtype=np.float64), P, N,
                   float(eps), float(cos_tol))


def planes_from(p: np.ndarray, n: np.ndarray, cos_tol: float) -> tuple[np.ndarray, np.ndarray]:
    """Planes through three points each: ``p`` ``(M, 3, 3)`` points, ``n`` ``(M, 3, 3)``
    their normals. Returns ``(H (M, 4), ok (M,))``: ``ok`` where the points are not
    collinear and every normal is within ``acos(cos_tol)`` of the plane's."""
    nn, ln = _unit(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]))
    ok = ln > 1e-12 * np.maximum(_dot(p[:, 1] - p[:, 0], p[:, 1] - p[:, 0]), 1e-300)
    ok &= np.all(np.abs(_dot(n, nn[:, None, :])) >= cos_tol, axis=1)
    return np.concatenate([nn, _dot(nn, p[:, 0])[:, None]], axis=1), ok


def _closest(p1, n1, p2, n2):
    """Parameters ``s, t`` of the closest points ``p1 + s n1``, ``p2 + t n2`` of two
    lines with unit directions, and ``1 - (n1 . n2)^2``."""
    w = p1 - p2
    b = _dot(n1, n2)
    dd = _dot(n1, w)
    e = _dot(n2, w)
    den = 1.0 - b * b
    s = (b * e - dd) / np.maximum(den, 1e-300)
    t = e + s * b
    return s, t, den


def spheres_from(p: np.ndarray, n: np.ndarray, tol: float, max_radius: float
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Spheres from two oriented points each (``p``, ``n`` ``(M, 2, 3)``): the centre is
    the midpoint of the closest points of the two normal lines. ``ok`` where the lines
    are not parallel, pass within ``tol`` of each other, the two radii agree within
    ``tol`` and the radius is below ``max_radius``."""
    s, t, den = _closest(p[:, 0], n[:, 0], p[:, 1], n[:, 1])
    q1 = p[:, 0] + s[:, None] * n[:, 0]
    q2 = p[:, 1] + t[:, None] * n[:, 1]
    c = 0.5 * (q1 + q2)
    r1 = np.linalg.norm(p[:, 0] - c, axis=1)
    r2 = np.linalg.norm(p[:, 1] - c, axis=1)
    r = 0.5 * (r1 + r2)
    ok = (den > 1e-4) & (np.linalg.norm(q1 - q2, axis=1) <= tol) & (np.abs(r1 - r2) <= tol)
    ok &= r < max_radius
    return np.concatenate([c, r[:, None]], axis=1), ok


def cylinders_from(p: np.ndarray, n: np.ndarray, tol: float, max_radius: float
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Cylinders from two oriented points each (``(M, 2, 3)``): the axis is along
    ``n1 x n2``; in the plane across it the two normal lines meet on the axis. ``ok``
    where the normals are not nearly parallel, the radii agree within ``tol`` and the
    radius is below ``max_radius``."""
    a, la = _unit(np.cross(n[:, 0], n[:, 1]))
    q = p - _dot(p, a[:, None, :])[..., None] * a[:, None, :]
    m = n - _dot(n, a[:, None, :])[..., None] * a[:, None, :]
    m, _ = _unit(m)
    s, t, den = _closest(q[:, 0], m[:, 0], q[:, 1], m[:, 1])
    c = q[:, 0] + s[:, None] * m[:, 0]
    r1 = np.linalg.norm(q[:, 0] - c, axis=1)
    r2 = np.linalg.norm(q[:, 1] - c, axis=1)
    r = 0.5 * (r1 + r2)
    ok = (la > 0.05) & (den > 1e-4) & (np.abs(r1 - r2) <= tol) & (r < max_radius)
    return np.concatenate([c, a, r[:, None]], axis=1), ok


def cones_from(p: np.ndarray, n: np.ndarray, tol: float, max_radius: float
               ) -> tuple[np.ndarray, np.ndarray]:
    """Cones from three oriented points each (``(M, 3, 3)``): the apex is where the
    three tangent planes meet; the axis is the normal of the plane through the tips of
    the unit vectors from the apex to the points. ``ok`` where the planes meet in one
    point (not farther than ``max_radius`` from the points), the half angle lies in
    5-80 degrees and the three points agree with it within ``tol``."""
    b = _dot(n, p)
    det = np.linalg.det(n)
    ok = np.abs(det) > 1e-3
    A = np.zeros((len(p), 3))
    if ok.any():
        A[ok] = np.linalg.solve(n[ok], b[ok][..., None])[..., 0]
    u, lu = _unit(p - A[:, None, :])
    ax, lax = _unit(np.cross(u[:, 1] - u[:, 0], u[:, 2] - u[:, 0]))
    flip = _dot(ax, u.sum(axis=1)) < 0
    ax[flip] *= -1
    cth = np.clip(_dot(u, ax[:, None, :]).mean(axis=1), -1.0, 1.0)
    th = np.arccos(cth)
    H = np.concatenate([A, ax, th[:, None]], axis=1)
    ok &= (lax > 1e-6) & (th > np.radians(5.0)) & (th < np.radians(80.0))
    ok &= np.all(lu < max_radius, axis=1)
    if ok.any():
        d, _ = surface_distance("cone", H[ok], p[ok])
        good = np.all(np.abs(d) <= tol, axis=1)
        ok[np.flatnonzero(ok)[~good]] = False
    return H, ok


#: the minor radii at which the coplanarity determinant of :func:`tori_from` is sampled
#: (times the sample's spread) to recover its cubic coefficients
_R_SAMPLES = np.array([0.0, 1.0, -1.0, 2.0])
_VANDER_INV = np.linalg.inv(np.vander(_R_SAMPLES, 4, increasing=True))


def tori_from(p: np.ndarray, n: np.ndarray, tol: float, max_radius: float
              ) -> tuple[np.ndarray, np.ndarray]:
    """Tori from four oriented points each (``(M, 4, 3)``; normals made to agree in sign
    with the first). For a minor radius ``r`` the tube centres ``p_i - r n_i`` lie on
    the centre circle, so they are coplanar: ``det[c2 - c1, c3 - c1, c4 - c1] = 0``, a
    cubic in ``r``; each real root gives the circle through three centres (axis, centre,
    major radius), kept when the fourth centre lies on it within ``tol``. Returns up to
    three hypotheses per sample: ``(H (K, 8), ok (K,))``."""
    m = len(p)
    n = n * np.where(_dot(n, n[:, :1, :]) < 0, -1.0, 1.0)[..., None]
    scale = np.maximum(np.linalg.norm(p - p[:, :1], axis=2).max(axis=1), 1e-12)
    D = p[:, 1:] - p[:, :1]  # (M, 3, 3) rows
    E = n[:, 1:] - n[:, :1]
    vals = np.stack([np.linalg.det(D - (r * scale)[:, None, None] * E)
                     for r in _R_SAMPLES], axis=1)  # (M, 4)
    coef = vals @ _VANDER_INV.T  # c0 + c1 x + c2 x^2 + c3 x^3, x = r / scale
    lead = coef[:, 3]
    ok_poly = np.abs(lead) > 1e-12 * np.abs(coef).max(axis=1)
    comp = np.zeros((m, 3, 3))
    safe = np.where(ok_poly, lead, 1.0)
    comp[:, 0, :] = -coef[:, 2::-1] / safe[:, None]
    comp[:, 1, 0] = comp[:, 2, 1] = 1.0
    roots = np.linalg.eigvals(comp)  # (M, 3)
    real = ok_poly[:, None] & (np.abs(roots.imag) <= 1e-6 * np.maximum(np.abs(roots.real), 1))
    r = roots.real * scale[:, None]  # (M, 3) signed minor radii
    # hypotheses, one per (sample, root)
    P4 = np.repeat(p, 3, axis=0)
    N4 = np.repeat(n, 3, axis=0)
    rr = r.ravel()
    C = P4 - rr[:, None, None] * N4  # tube centres (K, 4, 3)
    ax, la = _unit(np.cross(C[:, 1] - C[:, 0], C[:, 2] - C[:, 0]))
    # circumcentre of the triangle c1 c2 c3
    u = C[:, 1] - C[:, 0]
    v = C[:, 2] - C[:, 0]
    uxv = np.cross(u, v)
    den = 2.0 * np.maximum(_dot(uxv, uxv), 1e-300)
    cc = C[:, 0] + (np.cross(uxv, u) * _dot(v, v)[:, None]
                    + np.cross(v, uxv) * _dot(u, u)[:, None]) / den[:, None]
    R = np.linalg.norm(C[:, 0] - cc, axis=1)
    w = C[:, 3] - cc
    hh = _dot(w, ax)
    rho = np.linalg.norm(w - hh[:, None] * ax, axis=1)
    minor = np.abs(rr)
    H = np.concatenate([cc, ax, R[:, None], minor[:, None]], axis=1)
    ok = real.ravel() & (la > 1e-9) & (minor > 0) & (minor < R) & (R < max_radius)
    ok &= np.hypot(rho - R, hh) <= tol
    return H, ok


def frame_z(a: np.ndarray) -> np.ndarray:
    """A rotation ``(3, 3)`` whose third column is the unit vector ``a`` ``(3,)`` (the
    first two complete a right-handed frame; deterministic)."""
    a = np.asarray(a, float) / np.linalg.norm(a)
    helper = np.array([1.0, 0.0, 0.0]) if abs(a[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, a)
    x /= np.linalg.norm(x)
    y = np.cross(a, x)
    return np.stack([x, y, a], axis=1)
