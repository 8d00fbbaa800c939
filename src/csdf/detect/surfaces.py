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
from .minimal import (
    cones_kernel,
    cylinders_kernel,
    planes_kernel,
    spheres_kernel,
    tori_kernel,
)

__all__ = ["KINDS", "WIDTH", "KIND_ID", "surface_distance", "inlier_counts", "planes_from",
           "spheres_from", "cylinders_from", "cones_from", "tori_from", "frame_z"]

#: the surface kinds, simplest first (a tie in explained points goes to the simpler)
KINDS = ("plane", "sphere", "cylinder", "cone", "torus")
#: parameters per hypothesis of each kind
WIDTH = {"plane": 4, "sphere": 4, "cylinder": 7, "cone": 7, "torus": 8}
#: each kind's number in the compiled kernels (:mod:`.kernels`)
KIND_ID = {k: i for i, k in enumerate(KINDS)}


def _f64(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64)


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
    return planes_kernel(_f64(p), _f64(n), float(cos_tol))


def spheres_from(p: np.ndarray, n: np.ndarray, tol: float, max_radius: float
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Spheres from two oriented points each (``p``, ``n`` ``(M, 2, 3)``): the centre is
    the midpoint of the closest points of the two normal lines. ``ok`` where the lines
    are not parallel, pass within ``tol`` of each other, the two radii agree within
    ``tol`` and the radius is below ``max_radius``."""
    return spheres_kernel(_f64(p), _f64(n), float(tol), float(max_radius))


def cylinders_from(p: np.ndarray, n: np.ndarray, tol: float, max_radius: float
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Cylinders from two oriented points each (``(M, 2, 3)``): the axis is along
    ``n1 x n2``; in the plane across it the two normal lines meet on the axis. ``ok``
    where the normals are not nearly parallel, the radii agree within ``tol`` and the
    radius is below ``max_radius``."""
    return cylinders_kernel(_f64(p), _f64(n), float(tol), float(max_radius))


def cones_from(p: np.ndarray, n: np.ndarray, tol: float, max_radius: float
               ) -> tuple[np.ndarray, np.ndarray]:
    """Cones from three oriented points each (``(M, 3, 3)``): the apex is where the
    three tangent planes meet; the axis is the normal of the plane through the tips of
    the unit vectors from the apex to the points. ``ok`` where the planes meet in one
    point (not farther than ``max_radius`` from the points), the half angle lies in
    5-80 degrees and the three points agree with it within ``tol``."""
    return cones_kernel(_f64(p), _f64(n), float(tol), float(max_radius))


def tori_from(p: np.ndarray, n: np.ndarray, tol: float, max_radius: float
              ) -> tuple[np.ndarray, np.ndarray]:
    """Tori from four oriented points each (``(M, 4, 3)``; normals made to agree in sign
    with the first). For a minor radius ``r`` the tube centres ``p_i - r n_i`` lie on
    the centre circle, so they are coplanar: ``det[c2 - c1, c3 - c1, c4 - c1] = 0``, a
    cubic in ``r``; each real root gives the circle through three centres (axis, centre,
    major radius), kept when the fourth centre lies on it within ``tol``. Returns up to
    three hypotheses per sample: ``(H (K, 8), ok (K,))``."""
    return tori_kernel(_f64(p), _f64(n), float(tol), float(max_radius))


def frame_z(a: np.ndarray) -> np.ndarray:
    """A rotation ``(3, 3)`` whose third column is the unit vector ``a`` ``(3,)`` (the
    first two complete a right-handed frame; deterministic)."""
    a = np.asarray(a, float) / np.linalg.norm(a)
    helper = np.array([1.0, 0.0, 0.0]) if abs(a[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, a)
    x /= np.linalg.norm(x)
    y = np.cross(a, x)
    return np.stack([x, y, a], axis=1)
