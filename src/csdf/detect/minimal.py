"""Compiled minimal-set solutions: the surfaces through a few oriented points each.

The kernels behind :func:`.surfaces.planes_from`, :func:`.surfaces.spheres_from`,
:func:`.surfaces.cylinders_from`, :func:`.surfaces.cones_from` and
:func:`.surfaces.tori_from` (which document the constructions and the hypothesis rows).
Each loops over the samples and writes one row (three for a torus) and its ``ok`` flag:
a round of detection proposes a few hundred hypotheses, too few for NumPy's
whole-array operations to pay for their own overhead. Degenerate samples give rows that
may hold NaN or infinities; their ``ok`` is false.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .kernels import CONE, _surface_point

__all__ = ["planes_kernel", "spheres_kernel", "cylinders_kernel", "cones_kernel",
           "tori_kernel"]

_TINY = 1e-300
#: the cone's half angle must lie strictly inside these (radians)
_MIN_ANGLE = math.radians(5.0)
_MAX_ANGLE = math.radians(80.0)


@njit(cache=True, nogil=True, inline="always")
def _sub(a, b):
    return a[0] - b[0], a[1] - b[1], a[2] - b[2]


@njit(cache=True, nogil=True, inline="always")
def _add(a, b):
    return a[0] + b[0], a[1] + b[1], a[2] + b[2]


@njit(cache=True, nogil=True, inline="always")
def _mul(k, a):
    return k * a[0], k * a[1], k * a[2]


@njit(cache=True, nogil=True, inline="always")
def _dot(a, b) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True, nogil=True, inline="always")
def _cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0])


@njit(cache=True, nogil=True, inline="always")
def _norm(a) -> float:
    return math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])


@njit(cache=True, nogil=True, inline="always")
def _row(X: np.ndarray, i: int, j: int):
    return X[i, j, 0], X[i, j, 1], X[i, j, 2]


@njit(cache=True, nogil=True, inline="always")
def _det(a, b, c) -> float:
    """The determinant of the ``3 x 3`` matrix of rows ``a``, ``b``, ``c``."""
    return _dot(a, _cross(b, c))


@njit(cache=True, nogil=True, inline="always")
def _closest(p1, n1, p2, n2) -> tuple[float, float, float]:
    """Parameters ``s, t`` of the closest points ``p1 + s n1``, ``p2 + t n2`` of two
    lines with unit directions, and ``1 - (n1 . n2)^2``."""
    w = _sub(p1, p2)
    b = _dot(n1, n2)
    dd = _dot(n1, w)
    e = _dot(n2, w)
    den = 1.0 - b * b
    s = (b * e - dd) / max(den, _TINY)
    return s, e + s * b, den


@njit(cache=True, nogil=True)
def _rows(m: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    """``m`` hypothesis rows of ``width`` (NaN until written) and their ``ok`` flags
    (false until set)."""
    return np.full((m, width), np.nan), np.zeros(m, dtype=np.bool_)


@njit(cache=True, nogil=True)
def planes_kernel(p: np.ndarray, n: np.ndarray, cos_tol: float
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Planes through ``p`` ``(M, 3, 3)`` with normals ``n`` ``(M, 3, 3)``:
    ``(H (M, 4), ok (M,))``."""
    H, ok = _rows(p.shape[0], 4)
    for i in range(p.shape[0]):
        p0 = _row(p, i, 0)
        u = _sub(_row(p, i, 1), p0)
        c = _cross(u, _sub(_row(p, i, 2), p0))
        ln = _norm(c)
        c = _mul(1.0 / max(ln, _TINY), c)
        H[i, 0], H[i, 1], H[i, 2] = c
        H[i, 3] = _dot(c, p0)
        good = ln > 1e-12 * max(_dot(u, u), _TINY)
        for j in range(3):
            if not abs(_dot(_row(n, i, j), c)) >= cos_tol:
                good = False
        ok[i] = good
    return H, ok


@njit(cache=True, nogil=True)
def spheres_kernel(p: np.ndarray, n: np.ndarray, tol: float, max_radius: float
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Spheres from two oriented points each (``p``, ``n`` ``(M, 2, 3)``):
    ``(H (M, 4), ok (M,))``."""
    H, ok = _rows(p.shape[0], 4)
    for i in range(p.shape[0]):
        p0, p1 = _row(p, i, 0), _row(p, i, 1)
        n0, n1 = _row(n, i, 0), _row(n, i, 1)
        s, t, den = _closest(p0, n0, p1, n1)
        q1 = _add(p0, _mul(s, n0))
        q2 = _add(p1, _mul(t, n1))
        c = _mul(0.5, _add(q1, q2))
        r1 = _norm(_sub(p0, c))
        r2 = _norm(_sub(p1, c))
        r = 0.5 * (r1 + r2)
        H[i, 0], H[i, 1], H[i, 2] = c
        H[i, 3] = r
        ok[i] = (den > 1e-4 and _norm(_sub(q1, q2)) <= tol and abs(r1 - r2) <= tol
                 and r < max_radius)
    return H, ok


@njit(cache=True, nogil=True)
def cylinders_kernel(p: np.ndarray, n: np.ndarray, tol: float, max_radius: float
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Cylinders from two oriented points each (``(M, 2, 3)``): ``(H (M, 7), ok (M,))``."""
    H, ok = _rows(p.shape[0], 7)
    for i in range(p.shape[0]):
        p0, p1 = _row(p, i, 0), _row(p, i, 1)
        n0, n1 = _row(n, i, 0), _row(n, i, 1)
        a = _cross(n0, n1)
        la = _norm(a)
        a = _mul(1.0 / max(la, _TINY), a)
        q0 = _sub(p0, _mul(_dot(p0, a), a))
        q1 = _sub(p1, _mul(_dot(p1, a), a))
        m0 = _sub(n0, _mul(_dot(n0, a), a))
        m0 = _mul(1.0 / max(_norm(m0), _TINY), m0)
        m1 = _sub(n1, _mul(_dot(n1, a), a))
        m1 = _mul(1.0 / max(_norm(m1), _TINY), m1)
        s, _, den = _closest(q0, m0, q1, m1)
        c = _add(q0, _mul(s, m0))
        r1 = _norm(_sub(q0, c))
        r2 = _norm(_sub(q1, c))
        r = 0.5 * (r1 + r2)
        H[i, 0], H[i, 1], H[i, 2] = c
        H[i, 3], H[i, 4], H[i, 5] = a
        H[i, 6] = r
        ok[i] = la > 0.05 and den > 1e-4 and abs(r1 - r2) <= tol and r < max_radius
    return H, ok


@njit(cache=True, nogil=True)
def cones_kernel(p: np.ndarray, n: np.ndarray, tol: float, max_radius: float
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Cones from three oriented points each (``(M, 3, 3)``): ``(H (M, 7), ok (M,))``.
    The apex solves the three tangent planes by Cramer's rule."""
    H, ok = _rows(p.shape[0], 7)
    for i in range(p.shape[0]):
        n0, n1, n2 = _row(n, i, 0), _row(n, i, 1), _row(n, i, 2)
        p0, p1, p2 = _row(p, i, 0), _row(p, i, 1), _row(p, i, 2)
        det = _det(n0, n1, n2)
        if not abs(det) > 1e-3:
            continue
        b = (_dot(n0, p0), _dot(n1, p1), _dot(n2, p2))
        # the apex A with n_j . A = b_j: A = (b0 n1 x n2 + b1 n2 x n0 + b2 n0 x n1) / det
        A = _mul(1.0 / det, _add(_add(_mul(b[0], _cross(n1, n2)), _mul(b[1], _cross(n2, n0))),
                                 _mul(b[2], _cross(n0, n1))))
        d0, d1, d2 = _sub(p0, A), _sub(p1, A), _sub(p2, A)
        l0, l1, l2 = _norm(d0), _norm(d1), _norm(d2)
        u0 = _mul(1.0 / max(l0, _TINY), d0)
        u1 = _mul(1.0 / max(l1, _TINY), d1)
        u2 = _mul(1.0 / max(l2, _TINY), d2)
        ax = _cross(_sub(u1, u0), _sub(u2, u0))
        lax = _norm(ax)
        ax = _mul(1.0 / max(lax, _TINY), ax)
        if _dot(ax, _add(_add(u0, u1), u2)) < 0:
            ax = _mul(-1.0, ax)
        cth = min(max((_dot(u0, ax) + _dot(u1, ax) + _dot(u2, ax)) / 3.0, -1.0), 1.0)
        th = math.acos(cth)
        H[i, 0], H[i, 1], H[i, 2] = A
        H[i, 3], H[i, 4], H[i, 5] = ax
        H[i, 6] = th
        good = (max(l0, l1, l2) < max_radius and lax > 1e-6
                and _MIN_ANGLE < th < _MAX_ANGLE)
        if good:
            ct, st = math.cos(th), math.sin(th)
            for j in range(3):
                d, _, _, _ = _surface_point(CONE, H[i], ct, st, p[i, j, 0], p[i, j, 1],
                                            p[i, j, 2])
                if not abs(d) <= tol:
                    good = False
        ok[i] = good
    return H, ok


@njit(cache=True, nogil=True, inline="always")
def _polish(a: float, b: float, c: float, x: float) -> float:
    """Two Newton steps on ``x^3 + a x^2 + b x + c`` from root estimate ``x``."""
    for _ in range(2):
        f = ((x + a) * x + b) * x + c
        g = (3.0 * x + 2.0 * a) * x + b
        if g == 0.0 or not math.isfinite(f / g):
            break
        x -= f / g
    return x


@njit(cache=True, nogil=True)
def _cubic_roots(a: float, b: float, c: float) -> tuple[float, float, float, bool, bool,
                                                          bool]:
    """The roots of ``x^3 + a x^2 + b x + c``, as the real parts of three roots and
    whether each is real: three real roots by the trigonometric solution, else the
    real root by Cardano's and the complex pair's real part, that pair counted real
    when its imaginary part is at most ``1e-6`` of ``max(|real part|, 1)`` (a double
    root that rounding split), as the eigenvalues of the companion matrix were."""
    q3 = (3.0 * b - a * a) / 9.0  # p / 3 of the depressed cubic y^3 + p y + q
    r2 = (9.0 * a * b - 27.0 * c - 2.0 * a * a * a) / 54.0  # -q / 2
    disc = q3 * q3 * q3 + r2 * r2
    shift = a / 3.0
    if disc <= 0.0:
        if q3 == 0.0:
            return -shift, -shift, -shift, True, True, True
        m = 2.0 * math.sqrt(-q3)
        th = math.acos(min(max(r2 / math.sqrt(-q3 * q3 * q3), -1.0), 1.0)) / 3.0
        y0 = m * math.cos(th) - shift
        y1 = m * math.cos(th + 2.0 * math.pi / 3.0) - shift
        y2 = m * math.cos(th + 4.0 * math.pi / 3.0) - shift
        return (_polish(a, b, c, y0), _polish(a, b, c, y1), _polish(a, b, c, y2), True,
                True, True)
    sq = math.sqrt(disc)
    u = math.copysign(abs(r2 + math.copysign(sq, r2)) ** (1.0 / 3.0), r2)
    v = -q3 / u if u != 0.0 else 0.0
    y = u + v
    x0 = _polish(a, b, c, y - shift)
    re = -0.5 * y - shift
    im = 0.5 * math.sqrt(3.0) * abs(u - v)
    pair = im <= 1e-6 * max(abs(re), 1.0)
    return x0, re, re, True, pair, pair


@njit(cache=True, nogil=True)
def tori_kernel(p: np.ndarray, n: np.ndarray, tol: float, max_radius: float
                ) -> tuple[np.ndarray, np.ndarray]:
    """Tori from four oriented points each (``p``, ``n`` ``(M, 4, 3)``; see
    :func:`.surfaces.tori_from`): ``(H (3 M, 8), ok (3 M,))``, sample ``i``'s three
    roots in rows ``3 i .. 3 i + 2``. The coplanarity determinant
    ``det[D_j - r E_j]`` (``D_j = p_j - p_0``, ``E_j = n_j - n_0``, ``j = 1, 2, 3``) is
    expanded by multilinearity into its cubic's coefficients, in ``x = r / scale``
    (``scale``: the sample's spread)."""
    H, ok = _rows(3 * p.shape[0], 8)
    for i in range(p.shape[0]):
        p0, p1, p2, p3 = _row(p, i, 0), _row(p, i, 1), _row(p, i, 2), _row(p, i, 3)
        n0 = _row(n, i, 0)
        n1, n2, n3 = _row(n, i, 1), _row(n, i, 2), _row(n, i, 3)
        n1 = _mul(-1.0, n1) if _dot(n1, n0) < 0 else n1
        n2 = _mul(-1.0, n2) if _dot(n2, n0) < 0 else n2
        n3 = _mul(-1.0, n3) if _dot(n3, n0) < 0 else n3
        D1, D2, D3 = _sub(p1, p0), _sub(p2, p0), _sub(p3, p0)
        sc = max(_norm(D1), _norm(D2), _norm(D3), 1e-12)
        E1 = _mul(sc, _sub(n1, n0))  # (r E = x scale E)
        E2 = _mul(sc, _sub(n2, n0))
        E3 = _mul(sc, _sub(n3, n0))
        c0 = _det(D1, D2, D3)
        c1 = -(_det(E1, D2, D3) + _det(D1, E2, D3) + _det(D1, D2, E3))
        c2 = _det(D1, E2, E3) + _det(E1, D2, E3) + _det(E1, E2, D3)
        lead = -_det(E1, E2, E3)
        if not abs(lead) > 1e-12 * max(abs(c0), abs(c1), abs(c2), abs(lead)):
            continue
        x0, x1, x2, k0, k1, k2 = _cubic_roots(c2 / lead, c1 / lead, c0 / lead)
        for k in range(3):
            row = 3 * i + k
            x = x0 if k == 0 else x1 if k == 1 else x2
            real = k0 if k == 0 else k1 if k == 1 else k2
            r = x * sc
            c0, c1 = _sub(p0, _mul(r, n0)), _sub(p1, _mul(r, n1))
            c2, c3 = _sub(p2, _mul(r, n2)), _sub(p3, _mul(r, n3))
            u = _sub(c1, c0)
            v = _sub(c2, c0)
            uxv = _cross(u, v)
            la = _norm(uxv)
            ax = _mul(1.0 / max(la, _TINY), uxv)
            den = 2.0 * max(_dot(uxv, uxv), _TINY)
            cc = _add(c0, _mul(1.0 / den, _add(_mul(_dot(v, v), _cross(uxv, u)),
                                                _mul(_dot(u, u), _cross(v, uxv)))))
            R = _norm(_sub(c0, cc))
            w = _sub(c3, cc)
            hh = _dot(w, ax)
            rho = _norm(_sub(w, _mul(hh, ax)))
            minor = abs(r)
            H[row, 0], H[row, 1], H[row, 2] = cc
            H[row, 3], H[row, 4], H[row, 5] = ax
            H[row, 6] = R
            H[row, 7] = minor
            ok[row] = (real and la > 1e-9 and minor > 0 and minor < R
                       and R < max_radius and math.hypot(rho - R, hh) <= tol)
    return H, ok
