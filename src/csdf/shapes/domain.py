"""Domain operations: rigid transforms, scaling, mirroring and repetition.

Each is a method on every shape (``shape.translate(v)``) and substitutes new coordinate
expressions into the child: ``f(T^-1 p)``.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from ..errors import ShapeError
from ..expr import Expr, atan2, cos, floor, maximum, minimum, mod, sin
from ..interval import expr_range
from ..vec import Vec, length
from .base import (
    Shape,
    box_bounds,
    derive_exactness,
    int_arg,
    mag,
    radius_of,
    register,
    scalar_arg,
    vector_arg,
)

__all__ = [
    "translate", "rotate", "orient", "transform", "scale", "mirror", "repeat", "repeat_mirrored",
    "repeat_polar", "axis_vector",
]

AXES = {"x": 0, "y": 1, "z": 2}


def _derived(
    shape: Shape, name: str, fn: Callable[[Vec, object], Expr], *, args: tuple, kwargs=None,
    keeps_exact: bool, lipschitz: float | None = None, bounds=None, continuous: bool = True,
    neither: bool = False,
) -> Shape:
    """A one-child operator node; ``neither`` forces the 'neither' label."""
    lip = shape.lipschitz if lipschitz is None else lipschitz
    label = "neither" if neither else derive_exactness(
        [shape], keeps_exact=keeps_exact, lipschitz=lip, continuous=continuous
    )
    return Shape(
        name, fn, dim=shape.dim, lipschitz=lip, bounds=bounds, args=args, kwargs=kwargs,
        children=(shape,), exactness=label,
    )


def _check(shape, what: str) -> None:
    if not isinstance(shape, Shape):
        raise ShapeError(f"{what} is a shape method; got {type(shape).__name__}")


@register("method")
def translate(shape: Shape, offset) -> Shape:
    """Move the shape by ``offset`` (a ``dim``-vector). Keeps exactness."""
    _check(shape, "translate")
    v = vector_arg(offset, shape.dim, "translate: offset")
    b = shape.bounds
    if b is not None:
        rng = [expr_range(c) for c in v]
        b = box_bounds([b[0, i] + rng[i][0] for i in range(shape.dim)],
                       [b[1, i] + rng[i][1] for i in range(shape.dim)])
    return _derived(
        shape, "translate", lambda p, ctx: shape.sdf(p - Vec(v), ctx), args=(offset,),
        keeps_exact=True, bounds=b,
    )


def axis_vector(axis) -> np.ndarray:
    """A unit 3-vector from ``'x' | 'y' | 'z' | '-x' | ...`` or a constant 3-vector."""
    if isinstance(axis, str):
        s = axis.strip().lower()
        neg = s.startswith("-")
        s = s.lstrip("+-")
        if s not in AXES:
            raise ShapeError(
                f"axis must be 'x', 'y', 'z' (optionally signed) or a 3-vector; got {axis!r}"
            )
        v = np.zeros(3)
        v[AXES[s]] = -1.0 if neg else 1.0
        return v
    try:
        v = np.asarray(axis, dtype=np.float64)
    except (TypeError, ValueError):
        raise ShapeError(
            f"axis must be a constant 3-vector or an axis name, got {axis!r}"
        ) from None
    if v.shape != (3,) or not np.all(np.isfinite(v)) or not np.linalg.norm(v) > 0:
        raise ShapeError(f"axis must be a non-zero finite 3-vector, got {axis!r}")
    return v / np.linalg.norm(v)


def _rotated_bounds(b: np.ndarray | None, R: np.ndarray) -> np.ndarray | None:
    if b is None or not np.all(np.isfinite(b)):
        return None  # unknown (inf * 0 would make NaN bounds)
    corners = np.array(
        [[b[i, 0], b[j, 1], b[k, 2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)]
    )
    rc = corners @ R.T
    return np.array([rc.min(0), rc.max(0)])


def _apply_inverse(R: list[list[Expr | float]], p: Vec) -> Vec:
    """``R^T p`` for a 3x3 matrix of expressions or floats."""
    return Vec(tuple(R[0][i] * p.x + R[1][i] * p.y + R[2][i] * p.z for i in range(3)))


@register("method")
def rotate(shape: Shape, angle, axis="z") -> Shape:
    """Rotate by ``angle`` radians about ``axis`` through the origin (right-hand rule), or
    by a 3x3 rotation matrix given as ``angle``. 2D shapes rotate in their plane.
    Keeps exactness."""
    _check(shape, "rotate")
    if isinstance(angle, (list, tuple, np.ndarray)):
        R = np.asarray(angle, dtype=np.float64)
        if R.shape != (3, 3) or shape.dim != 3:
            raise ShapeError("rotate: a matrix must be 3x3 and the shape 3D")
        if not np.allclose(R.T @ R, np.eye(3), atol=1e-9) or not np.linalg.det(R) > 0:
            raise ShapeError("rotate: the matrix is not a rotation (orthonormal, det +1)")
        Rl = R.tolist()
        return _derived(
            shape, "rotate", lambda p, ctx: shape.sdf(_apply_inverse(Rl, p), ctx),
            args=(R.tolist(),), keeps_exact=True, bounds=_rotated_bounds(shape.bounds, R),
        )
    a = scalar_arg(angle, "rotate: angle")
    if shape.dim == 2:
        def f2(p: Vec, ctx) -> Expr:
            c, s = cos(a), sin(a)
            return shape.sdf(Vec((c * p.x + s * p.y, -s * p.x + c * p.y)), ctx)

        r = radius_of(shape.bounds)
        b = None if not math.isfinite(r) else box_bounds([-r, -r], [r, r])
        return _derived(shape, "rotate", f2, args=(angle,), keeps_exact=True, bounds=b)
    u = axis_vector(axis)
    K = np.array([[0, -u[2], u[1]], [u[2], 0, -u[0]], [-u[1], u[0], 0]]).tolist()
    uu = np.outer(u, u).tolist()

    def matrix(c, s) -> list[list]:
        # Rodrigues: R = c I + s K + (1 - c) u u^T
        return [[c * float(i == j) + s * K[i][j] + (1.0 - c) * uu[i][j] for j in range(3)]
                for i in range(3)]

    def f(p: Vec, ctx) -> Expr:
        return shape.sdf(_apply_inverse(matrix(cos(a), sin(a)), p), ctx)

    if a.op == "const":
        num = np.array(matrix(math.cos(float(a.value)), math.sin(float(a.value))), dtype=float)  # type: ignore[arg-type]
        b = _rotated_bounds(shape.bounds, num)
    else:
        r = radius_of(shape.bounds)
        b = None if not math.isfinite(r) else box_bounds([-r] * 3, [r] * 3)
    kw = {} if isinstance(axis, str) and axis == "z" else {"axis": axis}
    return _derived(shape, "rotate", f, args=(angle,), kwargs=kw, keeps_exact=True, bounds=b)


def orient_matrix(axis) -> np.ndarray:
    """The rotation ``(3, 3)`` :func:`orient` applies: the shortest turn taking +z onto
    ``axis`` (name or 3-vector); a half turn about x for -z."""
    u = axis_vector(axis)
    z = np.array([0.0, 0.0, 1.0])
    c = float(z @ u)
    if c > 1 - 1e-15:
        return np.eye(3)
    if c < -1 + 1e-15:
        return np.diag([1.0, -1.0, -1.0])  # half turn about x
    v = np.cross(z, u)
    s = np.linalg.norm(v)
    K = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]]) / s
    ang = math.atan2(s, c)
    R = np.eye(3) + math.sin(ang) * K + (1 - math.cos(ang)) * (K @ K)
    # axis-aligned targets give a signed permutation: make it exact (cos 90 deg is
    # 6e-17 in floating point), so no x * 1e-16 terms reach the bytecode
    snapped = np.round(R)
    return np.where(np.abs(R - snapped) < 1e-12, snapped, R)


@register("method")
def orient(shape: Shape, axis) -> Shape:
    """Rotate the shape so that its +z axis points along ``axis`` (name or 3-vector).
    Keeps exactness."""
    _check(shape, "orient")
    if shape.dim != 3:
        raise ShapeError("orient needs a 3D shape")
    R = orient_matrix(axis)
    Rl = R.tolist()
    return _derived(
        shape, "orient", lambda p, ctx: shape.sdf(_apply_inverse(Rl, p), ctx), args=(axis,),
        keeps_exact=True, bounds=_rotated_bounds(shape.bounds, R),
    )


@register("method")
def transform(shape: Shape, matrix) -> Shape:
    """Apply the affine map ``p -> A p + t`` given as a homogeneous matrix ``[[A, t],
    [0, 1]]`` (``(d+1, d+1)``, or its first ``d`` rows; ``d`` the shape's dimension),
    as OpenSCAD's ``multmatrix``: ``f(A^-1 (p - t)) * s_min`` with ``s_min`` the
    smallest singular value of ``A``. **Exact** when ``A`` is a rotation or reflection
    times a uniform scale (distances then scale by it); otherwise a **bound** (never
    overestimates; Lipschitz unchanged). ``A`` must be invertible."""
    _check(shape, "transform")
    d = shape.dim
    try:
        M = np.asarray(matrix, dtype=np.float64)
    except (TypeError, ValueError):
        raise ShapeError("transform: matrix must be numbers") from None
    if M.shape not in ((d + 1, d + 1), (d, d + 1)) or not np.all(np.isfinite(M)):
        raise ShapeError(f"transform: matrix must be {d + 1}x{d + 1} (or {d}x{d + 1}) "
                         f"finite numbers for a {d}D shape, got shape {M.shape}")
    if M.shape[0] == d + 1 and not np.allclose(M[d], [0.0] * d + [1.0]):
        raise ShapeError("transform: the last row must be (0, ..., 0, 1) (no projection)")
    A, t = M[:d, :d], M[:d, d]
    sv = np.linalg.svd(A, compute_uv=False)
    if not sv[-1] > 1e-12 * max(sv[0], 1e-300):
        raise ShapeError("transform: the matrix is singular")
    smin = float(sv[-1])
    uniform = bool(sv[0] - sv[-1] <= 1e-12 * sv[0])
    inv = np.linalg.inv(A)
    # exact zeros and ones where they were meant (a rotation by 90 degrees in floats)
    inv = np.where(np.abs(inv) < 1e-15 * np.abs(inv).max(), 0.0, inv)
    rows, tl = inv.tolist(), t.tolist()

    def f(p: Vec, ctx) -> Expr:
        q = [c - tl[i] if tl[i] != 0.0 else c for i, c in enumerate(p.c)]
        out = []
        for row in rows:
            terms = [q[j] * a if a != 1.0 else q[j] for j, a in enumerate(row) if a != 0.0]
            e = terms[0]
            for term in terms[1:]:
                e = e + term
            out.append(e)
        v = shape.sdf(Vec(tuple(out)), ctx)
        return v * smin if smin != 1.0 else v

    b = shape.bounds
    if b is not None and np.all(np.isfinite(b)):
        corners = np.array(np.meshgrid(*[b[:, i] for i in range(d)], indexing="ij")
                           ).reshape(d, -1).T
        w = corners @ A.T + t
        b = np.array([w.min(0), w.max(0)])
    else:
        b = None
    return _derived(shape, "transform", f, args=(M.tolist(),), keeps_exact=uniform,
                    bounds=b)


@register("method")
def scale(shape: Shape, factor) -> Shape:
    """Scale by ``factor`` about the origin.

    A scalar scales uniformly as ``f(p/k) * k`` (paper Eq. 10): keeps exactness.
    A vector scales each axis: ``f(p/k) * min(k)``, a **bound** (never overestimates).
    Factors must be positive.
    """
    _check(shape, "scale")
    if isinstance(factor, (list, tuple, np.ndarray)):
        ks = vector_arg(factor, shape.dim, "scale: factor")
        for i, k in enumerate(ks):
            if k.op == "const" and not float(k.value) > 0:  # type: ignore[arg-type]
                raise ShapeError(f"scale: factor[{i}] must be > 0, got {float(k.value)}")
        kv = Vec(ks)
        kmin = kv.min_comp()
        b = shape.bounds
        if b is not None:
            m = [mag(k) for k in ks]
            b = np.array([b[0] * m, b[1] * m])
            b = np.array([np.minimum(b[0], b[1]), np.maximum(b[0], b[1])])
        return _derived(
            shape, "scale", lambda p, ctx: shape.sdf(p / kv, ctx) * kmin, args=(factor,),
            keeps_exact=False, bounds=b,
        )
    k = scalar_arg(factor, "scale: factor")
    if k.op == "const" and not float(k.value) > 0:  # type: ignore[arg-type]
        raise ShapeError(f"scale: factor must be > 0, got {float(k.value)}")
    b = shape.bounds
    if b is not None:
        b = b * mag(k)
    return _derived(
        shape, "scale", lambda p, ctx: shape.sdf(p / k, ctx) * k, args=(factor,),
        keeps_exact=True, bounds=b,
    )


def _axes(spec: str, dim: int, what: str) -> list[int]:
    if not isinstance(spec, str) or not spec or any(ch not in "xyz"[:dim] for ch in spec.lower()):
        raise ShapeError(f"{what}: axes must be letters from {'xyz'[:dim]!r}, got {spec!r}")
    return sorted({AXES[ch] for ch in spec.lower()})


@register("method")
def mirror(shape: Shape, axes="x") -> Shape:
    """Mirror the half ``coordinate >= 0`` onto the other side for each axis letter in
    ``axes`` (``'x'``, ``'xy'``, ``'xyz'``...): ``f(|x|, y, z)``. **Bound** (exact when the
    shape lies in the positive half or is symmetric)."""
    _check(shape, "mirror")
    idx = _axes(axes, shape.dim, "mirror")

    def f(p: Vec, ctx) -> Expr:
        return shape.sdf(Vec(tuple(abs(c) if i in idx else c for i, c in enumerate(p.c))), ctx)

    b = shape.bounds
    if b is not None:
        b = b.copy()
        for i in idx:
            m = max(abs(b[0, i]), abs(b[1, i]))
            b[0, i], b[1, i] = -m, m
    return _derived(shape, "mirror", f, args=(axes,), keeps_exact=False, bounds=b)


def _spacing(spacing, dim: int, what: str) -> tuple[Expr, ...]:
    s = vector_arg(spacing, dim, f"{what}: spacing", broadcast=True)
    for i, c in enumerate(s):
        if c.op == "const" and float(c.value) < 0:  # type: ignore[arg-type]
            raise ShapeError(f"{what}: spacing[{i}] must be >= 0 (0 = no repetition)")
    return s


def _counts(count, dim: int, what: str) -> list[int] | None:
    if count is None:
        return None
    if isinstance(count, (list, tuple, np.ndarray)):
        vals = list(count)
        if len(vals) != dim:
            raise ShapeError(f"{what}: count must have {dim} components, got {len(vals)}")
    else:
        vals = [count] * dim
    return [int_arg(c, f"{what}: count", 1, 100_000) for c in vals]


def _is_zero(e: Expr) -> bool:
    return e.op == "const" and float(e.value) == 0.0  # type: ignore[arg-type]


def _rep_bounds(shape: Shape, s, counts) -> np.ndarray | None:
    b = shape.bounds
    if b is None or counts is None and not all(_is_zero(c) for c in s):
        return None
    b = b.copy()
    for i, c in enumerate(s):
        if counts is not None and not _is_zero(c):
            ext = mag(c) * (counts[i] - 1) / 2
            b[0, i] -= ext
            b[1, i] += ext
    return b


def _per_axis(p: Vec, s: tuple[Expr, ...], fold: Callable[[int, Expr, Expr], Expr]) -> Vec:
    """Apply ``fold(axis, coordinate, spacing)`` on every axis whose spacing is not 0."""
    return Vec(tuple(c if _is_zero(sp) else fold(i, c, sp)
                     for i, (c, sp) in enumerate(zip(p.c, s))))


@register("method")
def repeat(shape: Shape, spacing, count=None) -> Shape:
    """Repeat the shape on a grid with cell size ``spacing`` (scalar or per axis; 0 turns
    an axis off). ``count`` (int or per axis) gives a finite number of copies centred on
    the origin; None repeats forever. **Neither**: the field jumps at cell borders unless
    the shape is symmetric and fits its cell (paper Fig. 8); use ``repeat_mirrored`` for a
    continuous field."""
    _check(shape, "repeat")
    s = _spacing(spacing, shape.dim, "repeat")
    counts = _counts(count, shape.dim, "repeat")

    def fold(i: int, c: Expr, sp: Expr) -> Expr:
        if counts is None:
            return c - sp * floor(c / sp + 0.5)
        o = (counts[i] - 1) / 2.0
        j = minimum(maximum(floor(c / sp + o + 0.5), 0.0), float(counts[i] - 1))
        return c - sp * (j - o)

    def f(p: Vec, ctx) -> Expr:
        return shape.sdf(_per_axis(p, s, fold), ctx)

    kw = {} if count is None else {"count": count}
    return _derived(
        shape, "repeat", f, args=(spacing,), kwargs=kw, keeps_exact=False, continuous=False,
        bounds=_rep_bounds(shape, s, counts),
    )


def _tri(u: Expr, sp: Expr) -> Expr:
    """Triangle wave of period ``2 sp``: identity near 0, mirrored in odd cells."""
    return sp * 0.5 - abs(mod(u + sp * 0.5, sp * 2.0) - sp)


@register("method")
def repeat_mirrored(shape: Shape, spacing, count=None) -> Shape:
    """Repeat like :meth:`repeat`, mirroring every other copy so the field stays
    continuous. **Bound** when the child is a bound or exact."""
    _check(shape, "repeat_mirrored")
    s = _spacing(spacing, shape.dim, "repeat_mirrored")
    counts = _counts(count, shape.dim, "repeat_mirrored")

    def fold(i: int, c: Expr, sp: Expr) -> Expr:
        if counts is None:
            return _tri(c, sp)
        n = counts[i]
        u = c + sp * ((n - 1) / 2.0)
        uc = minimum(maximum(u, 0.0), sp * float(n - 1))
        end_sign = 1.0 if (n - 1) % 2 == 0 else -1.0
        beyond = end_sign * maximum(u - sp * float(n - 1), 0.0)
        return _tri(uc, sp) + minimum(u, 0.0) + beyond

    def f(p: Vec, ctx) -> Expr:
        return shape.sdf(_per_axis(p, s, fold), ctx)

    kw = {} if count is None else {"count": count}
    b = _rep_bounds(shape, s, counts)
    if b is not None:
        # mirrored copies: make each repeated axis symmetric
        for i, sp in enumerate(s):
            if not _is_zero(sp):
                m = max(abs(b[0, i]), abs(b[1, i]))
                b[0, i], b[1, i] = -m, m
    return _derived(
        shape, "repeat_mirrored", f, args=(spacing,), kwargs=kw, keeps_exact=False, bounds=b,
    )


@register("method")
def repeat_polar(shape: Shape, n, axis="z") -> Shape:
    """Repeat the shape ``n`` times around ``axis`` (``'x' | 'y' | 'z'``; 2D shapes: about
    the origin). The copy in the sector around the +x direction (for ``axis='z'``) is the
    original. **Neither** (the field may jump at sector borders unless the shape is
    symmetric about its sector's mid-plane)."""
    _check(shape, "repeat_polar")
    k = int_arg(n, "repeat_polar: n", 1, 10_000)
    if shape.dim == 2:
        plane = (0, 1)
    else:
        if axis not in AXES:
            raise ShapeError(f"repeat_polar: axis must be 'x', 'y' or 'z', got {axis!r}")
        plane = {"z": (0, 1), "x": (1, 2), "y": (2, 0)}[axis]
    sector = 2.0 * math.pi / k

    def f(p: Vec, ctx) -> Expr:
        u, v = p.c[plane[0]], p.c[plane[1]]
        a = mod(atan2(v, u) + sector / 2.0, sector) - sector / 2.0
        r = length(Vec((u, v)))
        c = list(p.c)
        c[plane[0]], c[plane[1]] = r * cos(a), r * sin(a)
        return shape.sdf(Vec(c), ctx)

    b = shape.bounds
    if b is not None:
        r = float(np.hypot(np.maximum(np.abs(b[0, plane[0]]), np.abs(b[1, plane[0]])),
                           np.maximum(np.abs(b[0, plane[1]]), np.abs(b[1, plane[1]]))))
        b = b.copy()
        for i in plane:
            b[0, i], b[1, i] = -r, r
    kw = {} if axis == "z" else {"axis": axis}
    return _derived(
        shape, "repeat_polar", f, args=(n,), kwargs=kw, keeps_exact=False, continuous=False,
        bounds=b,
    )
