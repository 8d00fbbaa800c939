"""Point sampling on and around a shape: uniform surface samples with exact normals, and
volume samples with their field values (training data for learned distance fields).

* :func:`sample_surface` draws points uniformly by area on the zero set ``f = 0``: the
  shape is meshed (dual contouring, so flat faces and sharp edges are kept), triangles
  are drawn with probability proportional to their area and a uniform point is taken in
  each, and every point is then moved onto the zero set by Newton steps along the exact
  gradient, ``p <- p - f g / |g|^2``, until ``|f| <= 1e-10 * diag`` (``diag`` = the
  diagonal of the shape's bounding box). Normals are the normalised exact gradients, so
  they point outwards (towards ``f > 0``).
* :func:`sample_volume` mixes Gaussian perturbations of surface samples with uniform
  points in the (padded) bounding box and returns the field value at each.

Every random choice comes from one ``numpy.random.Generator`` made from ``seed``, so the
same seed gives the same samples (bit for bit with the same evaluation backend; the
backends agree to about 1e-15, and ``backend='auto'`` may switch between them).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .errors import CsdfError
from .field import Field, as_field
from .seeds import rng_arg

__all__ = ["sample_surface", "sample_volume", "MAX_SAMPLES"]

MAX_SAMPLES = 100_000_000
_NEWTON_ITERS = 30
_REL_TOL = 1e-10          # |f| target after projection, relative to the bounds diagonal
_MAX_MOVE_VOXELS = 4.0    # a projection that moves a point further than this is redrawn
_MAX_ROUNDS = 12
_MAX_CENTROID_VOXELS = 0.5  # mesh triangles further from the zero set are not sampled
_MIN_NORMAL_COS = 0.99      # the gradient at a point vs. just off it: agreement needed


# ---------------------------------------------------------------------- helpers
def _field(shape: Any, what: str, params: dict | None, backend: str, n: int,
           bounds: Any = None, check_ranges: bool = True) -> Field:
    """The :class:`csdf.field.Field` of a 3D shape or program (a point-set job of ``n``
    points for the backend policy); its bounds follow the field layer's policy."""
    fld = as_field(shape, params, bounds=bounds, backend=backend, work=n, what=what,
                   check_ranges=check_ranges)
    if fld.dim != 3:
        raise CsdfError(f"{what} needs a 3D shape; extrude or revolve a 2D shape first")
    return fld


def _count(n: Any, what: str = "n") -> int:
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)):
        raise CsdfError(f"{what} must be a non-negative integer, got {n!r}")
    if not 0 <= int(n) <= MAX_SAMPLES:
        raise CsdfError(f"{what} must be in [0, {MAX_SAMPLES:,}], got {int(n)}")
    return int(n)


def _resolution(n: int, bounds: np.ndarray) -> int:
    """Mesh resolution (voxels along the longest side) for ``n`` samples.

    Enough triangles that each is small against the features (64..160 voxels, growing
    with ``sqrt(n)``), and at least 8 voxels across the thinnest side of the bounds.
    """
    ext = bounds[1] - bounds[0]
    res = int(np.clip(math.sqrt(max(n, 1)), 64, 160))
    thin = float(ext.max() / max(ext.min(), 1e-300))
    return int(min(max(res, math.ceil(8 * thin)), 512))


def _project(fld: Field, p: np.ndarray, hint: np.ndarray, tol: float, delta: float):
    """Newton steps onto the zero set along the exact gradient, and unit normals there.

    Args:
        p: ``(M, 3)`` float64 start points (model units); not modified.
        hint: ``(M, 3)`` approximate outward unit normals (the mesh triangles').
        tol: stop when ``|f| <= tol`` (units of the field).
        delta: offset (model units) for the normal fallback below.

    Returns:
        ``(points (M, 3), normals (M, 3), ok (M,) bool)``: ``ok`` is False where the
        iteration did not reach ``tol`` or no normal could be found.

    Normals are the normalised exact gradient at the point, except where it disagrees
    (by more than ~8 degrees) with the sum of the gradients at ``p +- delta * hint``:
    exactly on the surface some formulas give no usable gradient, either 0 (``sqrt(0)``
    has derivative 0 by convention; a ``max``/``min`` tie with a constant) or a
    direction made of round-off (``sqrt(d) * sign(s)`` forms where the vector to the
    closest point is ~1e-16 long: cones, polygon profiles). There the normal is taken
    from the gradients just off the surface, which for a distance are the same normal.
    """
    p = p.copy()
    active = np.arange(len(p))
    ok = np.zeros(len(p), dtype=bool)
    for _ in range(_NEWTON_ITERS):
        if len(active) == 0:
            break
        f, g = fld.value_and_grad(p[active])
        gg = np.einsum("ij,ij->i", g, g)
        with np.errstate(invalid="ignore"):
            done = np.abs(f) <= tol
        bad = ~np.isfinite(f) | ~(gg > 0)
        ok[active[done]] = True
        step = ~done & ~bad
        idx = active[step]
        p[idx] -= (f[step] / gg[step])[:, None] * g[step]
        active = idx
    normals = np.zeros_like(p)
    sel = np.flatnonzero(ok)
    if len(sel) == 0:
        return p, normals, ok
    q, h = p[sel], hint[sel]
    f, g = fld.value_and_grad(q)
    g_near = fld.gradient(q + delta * h) + fld.gradient(q - delta * h)
    norm = np.linalg.norm(g, axis=1)
    norm_near = np.linalg.norm(g_near, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        cos = np.einsum("ij,ij->i", g, g_near) / (norm * norm_near)
        trust = (norm > 0) & np.isfinite(norm) & (cos >= _MIN_NORMAL_COS)
        n_at = g / norm[:, None]
        n_near = g_near / norm_near[:, None]
        good = (np.abs(f) <= tol) & np.where(trust, True, (norm_near > 0) &
                                             np.isfinite(norm_near))
    normals[sel] = np.where(trust[:, None], n_at, n_near)
    ok[sel[~good]] = False
    normals[~ok] = 0.0
    return p, normals, ok


def _surface(fld: Field, n: int, rng: np.random.Generator,
             resolution: int | None) -> tuple[np.ndarray, np.ndarray]:
    """The work of :func:`sample_surface` on validated arguments."""
    from .mesh.api import mesh as mesh_fn

    bounds = fld.bounds
    if resolution is None:
        resolution = _resolution(n, bounds)
    m = mesh_fn(fld, resolution=resolution, bounds=bounds, method="dc", progress=False)
    verts = np.asarray(m.vertices, dtype=np.float64)
    tris = verts[np.asarray(m.faces, dtype=np.int64)]
    if len(tris) == 0:
        raise CsdfError("sample_surface: the shape has no surface inside its bounds")
    voxel = float(m.metadata["csdf"]["voxel_size"])
    # drop triangles away from the zero set: the faces that close a shape cut by the
    # bounds (and any other stray part); first-order distance |f| / |grad f| of centroids
    f, g = fld.value_and_grad(tris.mean(axis=1))
    gn = np.linalg.norm(g, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        near = (f == 0) | (np.abs(f) <= _MAX_CENTROID_VOXELS * voxel * gn)
    tris = tris[near]
    if len(tris) == 0:
        raise CsdfError("sample_surface: the shape has no surface inside its bounds")
    area = 0.5 * np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]),
                                axis=1)
    cum = np.cumsum(area)
    total = float(cum[-1])
    if not (total > 0 and math.isfinite(total)):
        raise CsdfError("sample_surface: the mesh of the shape has no area")
    diag = float(np.linalg.norm(bounds[1] - bounds[0]))
    tol = _REL_TOL * diag
    delta = 1e-7 * diag
    max_move = _MAX_MOVE_VOXELS * voxel

    pts_out: list[np.ndarray] = []
    nrm_out: list[np.ndarray] = []
    have = 0
    for _ in range(_MAX_ROUNDS):
        k = n - have
        if k == 0:
            break
        idx = np.minimum(np.searchsorted(cum, rng.random(k) * total, side="right"),
                         len(cum) - 1)
        s = np.sqrt(rng.random(k))[:, None]
        r2 = rng.random(k)[:, None]
        t = tris[idx]
        start = (1.0 - s) * t[:, 0] + s * (1.0 - r2) * t[:, 1] + s * r2 * t[:, 2]
        e1, e2 = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
        hint = np.cross(e1, e2)
        hint /= np.maximum(np.linalg.norm(hint, axis=1), 1e-300)[:, None]
        p, nrm, ok = _project(fld, start, hint, tol, delta)
        ok &= np.linalg.norm(p - start, axis=1) <= max_move
        pts_out.append(p[ok])
        nrm_out.append(nrm[ok])
        have += int(ok.sum())
    if have < n:
        raise CsdfError(
            f"sample_surface: could not project {n - have} of {n} points onto the surface "
            "(the field's gradient vanishes or Newton steps do not converge there)"
        )
    return np.concatenate(pts_out), np.concatenate(nrm_out)


# ---------------------------------------------------------------------- public API
def sample_surface(
    shape: Any,
    n: int,
    seed: Any = None,
    params: dict | None = None,
    *,
    resolution: int | None = None,
    backend: str = "auto",
    check_ranges: bool = True,
    colors: bool = False,
) -> tuple:
    """Points uniformly distributed by area on the surface ``f = 0``, with normals.

    Method: mesh the shape by dual contouring (``resolution`` voxels along the longest
    side of its bounds; default from ``n`` and the bounds' aspect, 64..512), draw
    triangles with probability proportional to area and a uniform barycentric point in
    each, then project every point onto the zero set with Newton steps along the exact
    gradient until ``|f| <= 1e-10 * diag`` (``diag``: the bounding-box diagonal). A
    point whose projection fails (vanishing gradient, no convergence, or a jump of more
    than 4 voxels) is redrawn, so the result is uniform up to the mesh's approximation
    of the surface (triangles a voxel across; faces of boxes are exact with dual
    contouring). Mesh triangles further than half a voxel from the zero set (the faces
    that close a shape cut by its bounds) are not sampled.

    Args:
        shape: a 3D :class:`csdf.Shape` or :class:`csdf.Program`, or a
            :class:`csdf.Scene` (:meth:`csdf.Scene.sample_surface`: then ``(points,
            normals, instance (n,))``).
        n: number of points (``>= 0``).
        seed: ``None``, an integer, or a ``numpy.random.Generator`` (used and advanced).
        params: parameter values ``{name: value}`` (defaults otherwise).
        resolution: mesh resolution override (voxels along the longest side).
        backend: evaluation backend for the projection (see :class:`csdf.Program`).
        check_ranges: refuse a parameter value outside its declared range
            (:class:`csdf.ParamError` naming the range); False samples it anyway.
        colors: also each point's colour (:func:`csdf.colors.colors_at`), a third
            array ``(n, 4)`` RGBA in ``[0, 1]``.

    Returns:
        ``(points (n, 3), normals (n, 3))`` float64: points in model units with
        ``|f| <= 1e-10 * diag`` (far below ``1e-6`` for unit-sized shapes); unit normals
        ``grad f / |grad f|`` pointing outwards. Where a formula's exact gradient is
        unusable exactly on the surface (0, or round-off: see :func:`_project`) the
        normal comes from the gradients ``1e-7 * diag`` off the surface on either side.

    Raises:
        CsdfError: bad arguments, a 2D shape, an empty shape (no surface found), or
            points that cannot be projected onto the surface; ParamError: a value
            outside its range (with ``check_ranges``).
    """
    n = _count(n)
    if getattr(shape, "__csdf_scene__", False):  # a csdf.Scene samples its instances
        if params:
            raise CsdfError("a scene's instances carry their own parameters")
        if colors:
            raise CsdfError("colors=True samples a shape; a scene's colours are not "
                            "drawn yet")
        return shape.sample_surface(n, rng_arg(seed), resolution=resolution)
    fld = _field(shape, "sample_surface", params, backend, n, check_ranges=check_ranges)
    rng = rng_arg(seed)
    if n == 0:
        out = np.zeros((0, 3)), np.zeros((0, 3))
    else:
        out = _surface(fld, n, rng, resolution)
    if not colors:
        return out
    from .colors import colors_of

    return out[0], out[1], colors_of(fld, out[0], check_ranges=check_ranges)


def sample_volume(
    shape: Any,
    n: int,
    near_surface: float = 0.5,
    sigma: float | None = None,
    seed: Any = None,
    params: dict | None = None,
    bounds: Any = None,
    *,
    backend: str = "auto",
    check_ranges: bool = True,
) -> tuple[np.ndarray, np.ndarray]:
    """Points in and around a shape with their field values (SDF training data).

    ``round(near_surface * n)`` points are surface samples (:func:`sample_surface`)
    plus isotropic Gaussian offsets of standard deviation ``sigma``; the rest are uniform
    in the bounds padded by 5% of their size on each side. The two sets are shuffled
    together.

    Args:
        shape: a 3D :class:`csdf.Shape` or :class:`csdf.Program`.
        n: number of points.
        near_surface: fraction in ``[0, 1]`` of points near the surface.
        sigma: offset standard deviation in model units (default: 1% of the diagonal of
            the bounds).
        seed: ``None``, an integer, or a ``numpy.random.Generator``.
        params: parameter values ``{name: value}``.
        bounds: ``((xmin, ymin, zmin), (xmax, ymax, zmax))`` for the uniform part and
            the surface part (only the surface inside is sampled; needed for unbounded
            shapes such as planes); default the shape's bounding box (analytic, else by
            interval arithmetic).
        backend: evaluation backend (see :class:`csdf.Program`).
        check_ranges: refuse a parameter value outside its declared range
            (:class:`csdf.ParamError` naming the range); False samples it anyway.

    Returns:
        ``(points (n, 3) float64, distances (n,) float64)``: the field value at each
        point, ``prog(points, params)``. For shapes with ``exactness == 'exact'`` these
        are the exact signed distances; otherwise they are the field's values (a
        ``'bound'`` field never overestimates the distance; see the distance contract).

    Raises:
        CsdfError: bad arguments, a 2D shape, or an empty shape; ParamError: a value
            outside its range (with ``check_ranges``).
    """
    n = _count(n)
    fld = _field(shape, "sample_volume", params, backend, n, bounds, check_ranges)
    if isinstance(near_surface, bool) or not isinstance(near_surface, (int, float, np.number)):
        raise CsdfError(f"near_surface must be a number in [0, 1], got {near_surface!r}")
    frac = float(near_surface)
    if not 0.0 <= frac <= 1.0:
        raise CsdfError(f"near_surface must be in [0, 1], got {near_surface}")
    rng = rng_arg(seed)
    b = fld.bounds
    ext = b[1] - b[0]
    if sigma is None:
        sig = 0.01 * float(np.linalg.norm(ext))
    else:
        if isinstance(sigma, bool) or not isinstance(sigma, (int, float, np.number)):
            raise CsdfError(f"sigma must be a positive number, got {sigma!r}")
        sig = float(sigma)
        if not (sig >= 0 and math.isfinite(sig)):
            raise CsdfError(f"sigma must be a finite number >= 0, got {sigma}")
    n_near = int(round(frac * n))
    parts = []
    if n_near:
        surf, _ = _surface(fld, n_near, rng, None)
        parts.append(surf + rng.normal(0.0, sig, size=(n_near, 3)) if sig > 0 else surf)
    if n - n_near:
        lo, hi = b[0] - 0.05 * ext, b[1] + 0.05 * ext
        parts.append(lo + (hi - lo) * rng.random((n - n_near, 3)))
    pts = np.concatenate(parts) if parts else np.zeros((0, 3))
    pts = pts[rng.permutation(len(pts))]
    dist = np.asarray(fld.value(pts), dtype=np.float64) if len(pts) else \
        np.zeros(0)
    return pts, dist
