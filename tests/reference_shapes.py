"""Independent NumPy reference geometry for testing the ``csdf`` primitives.

Everything in this module is derived from the *geometric definition* of each
shape -- projections onto segments, arcs and faces, membership predicates and
parametrisations of the boundary -- and deliberately not from the GLSL-style
closed forms the library is modelled on, so that the two can check each other.

Conventions
-----------
* ``points`` is an ``(N, 3)`` float array; 2D shapes also accept ``(N, 2)``
  (a 2D shape evaluated in 3D ignores ``z``).
* ``ref_<name>(points, ...)`` returns the ``(N,)`` signed distance (negative
  inside).  For the shapes the library documents as *bounds* (ellipsoid,
  octahedron, ellipse) ``ref_<name>`` is the documented bound formula and the
  true distance must be obtained by brute force (or ``ref_octahedron_exact``).
* ``inside_<name>(points, ...)`` is a closed-set membership test written from
  the definition (independent of the distance formula where practical).
* ``sample_<name>(n, rng, ...)`` returns ``n`` points on the boundary: ``(n, 3)``
  for 3D shapes, ``(n, 2)`` (points of the boundary curve) for 2D shapes.
* 2D boundary curves are lists of *pieces*: ``("seg", a, b)`` or
  ``("arc", centre, radius, t0, t1)``, angles in radians counter-clockwise
  from +x (``curve_<name>`` builds them).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

TAU = 2.0 * np.pi

# --------------------------------------------------------------------------
# small helpers
# --------------------------------------------------------------------------


def _points(points) -> np.ndarray:
    p = np.asarray(points, dtype=float)
    if p.ndim != 2 or p.shape[1] not in (2, 3):
        raise ValueError(f"points must have shape (N, 2) or (N, 3), got {p.shape}")
    return p


def _xy(points) -> np.ndarray:
    return _points(points)[:, :2]


def _xyz(points) -> np.ndarray:
    p = _points(points)
    if p.shape[1] != 3:
        raise ValueError("3D shape needs (N, 3) points")
    return p


def _norm(v: np.ndarray) -> np.ndarray:
    return np.sqrt(np.sum(v * v, axis=-1))


def _half(size, dim: int) -> np.ndarray:
    s = np.asarray(size, dtype=float)
    if s.ndim == 0:
        s = np.full(dim, float(s))
    if s.shape != (dim,):
        raise ValueError(f"size must be scalar or length {dim}")
    return 0.5 * s


def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def _rho_z(points) -> np.ndarray:
    """Meridian coordinates (distance from the z axis, z) of 3D points."""
    p = _xyz(points)
    return np.stack([np.hypot(p[:, 0], p[:, 1]), p[:, 2]], axis=1)


def segment_distances(p, a, b) -> np.ndarray:
    """Distances ``(N, K)`` from points ``p (N, D)`` to segments ``a[k] -> b[k]``.

    The closest point is the orthogonal projection onto the carrier line with
    the line parameter clamped to the segment.
    """
    p = np.asarray(p, dtype=float)
    a = np.atleast_2d(np.asarray(a, dtype=float))
    b = np.atleast_2d(np.asarray(b, dtype=float))
    ab = b - a
    ap = p[:, None, :] - a[None, :, :]
    den = np.sum(ab * ab, axis=-1)
    safe = np.where(den > 0.0, den, 1.0)
    t = np.clip(np.sum(ap * ab[None], axis=-1) / safe, 0.0, 1.0)
    t = np.where(den > 0.0, t, 0.0)
    return _norm(ap - t[..., None] * ab[None])


def perpendicular_basis(w) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors completing ``w`` to a right-handed orthonormal frame."""
    w = _unit(w)
    helper = np.array([1.0, 0.0, 0.0]) if abs(w[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = _unit(np.cross(w, helper))
    e2 = np.cross(w, e1)
    return e1, e2


def unit_vectors(m: int, rng: np.random.Generator) -> np.ndarray:
    g = rng.normal(size=(m, 3))
    return g / _norm(g)[:, None]


# --------------------------------------------------------------------------
# generic 2D: polygons and boundary curves
# --------------------------------------------------------------------------


def _edges(vertices) -> tuple[np.ndarray, np.ndarray]:
    v = np.asarray(vertices, dtype=float)
    return v, np.roll(v, -1, axis=0)


def _even_odd(q: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Crossing-number test: count edges crossed by the ray q + s*(1, 0), s > 0."""
    qx, qy = q[:, 0:1], q[:, 1:2]
    ya, yb = a[None, :, 1], b[None, :, 1]
    straddle = (ya > qy) != (yb > qy)
    dy = np.where(yb != ya, yb - ya, 1.0)
    x_at = a[None, :, 0] + (qy - ya) * (b[None, :, 0] - a[None, :, 0]) / dy
    hits = straddle & (x_at > qx)
    return (np.count_nonzero(hits, axis=1) % 2) == 1


def winding_number(points, vertices) -> np.ndarray:
    """Winding number of a closed polygon around each point (sum of turning angles)."""
    q = _xy(points)
    a, b = _edges(vertices)
    u = a[None] - q[:, None]
    w = b[None] - q[:, None]
    cross = u[..., 0] * w[..., 1] - u[..., 1] * w[..., 0]
    dot = np.sum(u * w, axis=-1)
    return np.rint(np.arctan2(cross, dot).sum(axis=1) / TAU).astype(int)


def ref_polygon(points, vertices) -> np.ndarray:
    """Exact signed distance to a simple polygon (either winding)."""
    q = _xy(points)
    a, b = _edges(vertices)
    d = segment_distances(q, a, b).min(axis=1)
    return np.where(_even_odd(q, a, b), -d, d)


def inside_polygon(points, vertices) -> np.ndarray:
    return winding_number(points, vertices) != 0


def seg(a, b) -> tuple:
    return ("seg", np.asarray(a, dtype=float), np.asarray(b, dtype=float))


def arc(centre, radius, t0, t1) -> tuple:
    return ("arc", np.asarray(centre, dtype=float), float(radius), float(t0), float(t1))


def piece_length(piece) -> float:
    if piece[0] == "seg":
        return float(np.linalg.norm(piece[2] - piece[1]))
    return piece[2] * abs(piece[4] - piece[3])


def curve_length(pieces) -> float:
    return float(sum(piece_length(pc) for pc in pieces))


def sample_curve(pieces, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` points uniformly distributed by arc length on a piecewise curve."""
    lengths = np.array([piece_length(pc) for pc in pieces])
    counts = rng.multinomial(n, lengths / lengths.sum())
    out = []
    for pc, m in zip(pieces, counts, strict=True):
        if m == 0:
            continue
        u = rng.random(m)
        if pc[0] == "seg":
            out.append(pc[1] + u[:, None] * (pc[2] - pc[1]))
        else:
            _, c, r, t0, t1 = pc
            t = t0 + u * (t1 - t0)
            out.append(c + r * np.stack([np.cos(t), np.sin(t)], axis=1))
    return np.concatenate(out, axis=0)


def polygon_pieces(vertices) -> list:
    a, b = _edges(vertices)
    return [seg(p, q) for p, q in zip(a, b, strict=True)]


def regular_polygon_vertices(n: int, radius: float) -> np.ndarray:
    """Vertices of a regular n-gon, circumradius ``radius``, first vertex on +y."""
    t = TAU * np.arange(n) / n
    return radius * np.stack([np.sin(t), np.cos(t)], axis=1)


def hexagon_vertices(radius: float) -> np.ndarray:
    """Regular hexagon, circumradius ``radius``, a vertex on +x."""
    t = TAU * np.arange(6) / 6
    return radius * np.stack([np.cos(t), np.sin(t)], axis=1)


def trapezoid_vertices(r1: float, r2: float, height: float) -> np.ndarray:
    h = 0.5 * height
    return np.array([[-r1, -h], [r1, -h], [r2, h], [-r2, h]], dtype=float)


def rhombus_vertices(size) -> np.ndarray:
    hx, hy = _half(size, 2)
    return np.array([[hx, 0.0], [0.0, hy], [-hx, 0.0], [0.0, -hy]])


def _box_nd(q: np.ndarray, half: np.ndarray) -> np.ndarray:
    """Exact SDF of the centred axis-aligned box ``|q_i| <= half_i`` (any dimension).

    Outside: distance to the clamped (projected) point.  Inside: distance to
    the nearest face.
    """
    a = np.abs(q)
    out = _norm(a - np.minimum(a, half))
    depth = np.min(half - a, axis=1)
    return np.where(np.all(a <= half, axis=1), -depth, out)


def _dist_to_box(q: np.ndarray, half: np.ndarray) -> np.ndarray:
    """Unsigned distance from q to the (closed, solid) centred box."""
    a = np.abs(q)
    return _norm(a - np.minimum(a, half))


# --------------------------------------------------------------------------
# 2D primitives
# --------------------------------------------------------------------------


def ref_circle(points, radius):
    return _norm(_xy(points)) - radius


def inside_circle(points, radius):
    q = _xy(points)
    return np.sum(q * q, axis=1) <= radius * radius


def curve_circle(radius):
    return [arc((0.0, 0.0), radius, 0.0, TAU)]


def sample_circle(n, rng, radius):
    return sample_curve(curve_circle(radius), n, rng)


def ref_rectangle(points, size):
    return _box_nd(_xy(points), _half(size, 2))


def inside_rectangle(points, size):
    return np.all(np.abs(_xy(points)) <= _half(size, 2), axis=1)


def curve_rectangle(size):
    hx, hy = _half(size, 2)
    return polygon_pieces([(-hx, -hy), (hx, -hy), (hx, hy), (-hx, hy)])


def sample_rectangle(n, rng, size):
    return sample_curve(curve_rectangle(size), n, rng)


def ref_rounded_rectangle(points, size, radius):
    # Minkowski sum of the shrunken rectangle and a disk of ``radius``
    return _box_nd(_xy(points), _half(size, 2) - radius) - radius


def inside_rounded_rectangle(points, size, radius):
    return _dist_to_box(_xy(points), _half(size, 2) - radius) <= radius


def curve_rounded_rectangle(size, radius):
    hx, hy = _half(size, 2)
    cx, cy = hx - radius, hy - radius
    r = radius
    return [
        seg((-cx, -hy), (cx, -hy)),
        arc((cx, -cy), r, -0.5 * np.pi, 0.0),
        seg((hx, -cy), (hx, cy)),
        arc((cx, cy), r, 0.0, 0.5 * np.pi),
        seg((cx, hy), (-cx, hy)),
        arc((-cx, cy), r, 0.5 * np.pi, np.pi),
        seg((-hx, cy), (-hx, -cy)),
        arc((-cx, -cy), r, np.pi, 1.5 * np.pi),
    ]


def sample_rounded_rectangle(n, rng, size, radius):
    return sample_curve(curve_rounded_rectangle(size, radius), n, rng)


def ref_regular_polygon(points, n, radius):
    return ref_polygon(points, regular_polygon_vertices(n, radius))


def inside_regular_polygon(points, n, radius):
    # half-planes: outward normals point at the edge midpoints (between vertices)
    q = _xy(points)
    t = TAU * (np.arange(n) + 0.5) / n
    normals = np.stack([np.sin(t), np.cos(t)], axis=1)
    apothem = radius * np.cos(np.pi / n)
    return np.all(q @ normals.T <= apothem, axis=1)


def curve_regular_polygon(n, radius):
    return polygon_pieces(regular_polygon_vertices(n, radius))


def sample_regular_polygon(num, rng, n, radius):
    return sample_curve(curve_regular_polygon(n, radius), num, rng)


def curve_polygon(vertices):
    return polygon_pieces(vertices)


def sample_polygon(n, rng, vertices):
    return sample_curve(curve_polygon(vertices), n, rng)


def ref_triangle(points, a, b, c):
    return ref_polygon(points, [a, b, c])


def inside_triangle(points, a, b, c):
    # barycentric coordinates must all share the sign of the total area
    q = _xy(points)
    a, b, c = (np.asarray(v, dtype=float) for v in (a, b, c))

    def cross(u, v, w):  # z of (v - u) x (w - u), w an array
        return (v[0] - u[0]) * (w[:, 1] - u[1]) - (v[1] - u[1]) * (w[:, 0] - u[0])

    total = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
    s = np.sign(total)
    return (s * cross(a, b, q) >= 0) & (s * cross(b, c, q) >= 0) & (s * cross(c, a, q) >= 0)


def curve_triangle(a, b, c):
    return polygon_pieces([a, b, c])


def sample_triangle(n, rng, a, b, c):
    return sample_curve(curve_triangle(a, b, c), n, rng)


def ref_hexagon(points, radius):
    return ref_polygon(points, hexagon_vertices(radius))


def inside_hexagon(points, radius):
    q = _xy(points)
    t = np.pi / 6 + TAU * np.arange(6) / 6  # edge normals (vertex on +x)
    normals = np.stack([np.cos(t), np.sin(t)], axis=1)
    return np.all(q @ normals.T <= radius * np.cos(np.pi / 6), axis=1)


def curve_hexagon(radius):
    return polygon_pieces(hexagon_vertices(radius))


def sample_hexagon(n, rng, radius):
    return sample_curve(curve_hexagon(radius), n, rng)


def ref_ring(points, radius, thickness):
    return np.abs(_norm(_xy(points)) - radius) - 0.5 * thickness


def inside_ring(points, radius, thickness):
    r = _norm(_xy(points))
    return (r >= radius - 0.5 * thickness) & (r <= radius + 0.5 * thickness)


def curve_ring(radius, thickness):
    return [
        arc((0.0, 0.0), radius + 0.5 * thickness, 0.0, TAU),
        arc((0.0, 0.0), radius - 0.5 * thickness, 0.0, TAU),
    ]


def sample_ring(n, rng, radius, thickness):
    return sample_curve(curve_ring(radius, thickness), n, rng)


def ref_segment(points, a, b, thickness=0.0):
    return segment_distances(_xy(points), a, b)[:, 0] - 0.5 * thickness


def inside_segment(points, a, b, thickness=0.0):
    # closed set; for thickness 0 it has no interior (measure-zero set)
    d = segment_distances(_xy(points), a, b)[:, 0]
    return d < 0.5 * thickness if thickness == 0.0 else d <= 0.5 * thickness


def curve_segment(a, b, thickness=0.0):
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    if thickness == 0.0:
        return [seg(a, b)]
    r = 0.5 * thickness
    d = b - a
    ang = np.arctan2(d[1], d[0])
    nrm = np.array([-np.sin(ang), np.cos(ang)])  # left normal
    return [
        seg(a - r * nrm, b - r * nrm),
        arc(b, r, ang - 0.5 * np.pi, ang + 0.5 * np.pi),
        seg(b + r * nrm, a + r * nrm),
        arc(a, r, ang + 0.5 * np.pi, ang + 1.5 * np.pi),
    ]


def sample_segment(n, rng, a, b, thickness=0.0):
    return sample_curve(curve_segment(a, b, thickness), n, rng)


def ref_trapezoid(points, r1, r2, height):
    return ref_polygon(points, trapezoid_vertices(r1, r2, height))


def inside_trapezoid(points, r1, r2, height):
    q = _xy(points)
    s = (q[:, 1] + 0.5 * height) / height  # 0 at the bottom edge, 1 at the top
    half_width = r1 + (r2 - r1) * s
    return (np.abs(q[:, 1]) <= 0.5 * height) & (np.abs(q[:, 0]) <= half_width)


def curve_trapezoid(r1, r2, height):
    return polygon_pieces(trapezoid_vertices(r1, r2, height))


def sample_trapezoid(n, rng, r1, r2, height):
    return sample_curve(curve_trapezoid(r1, r2, height), n, rng)


def ref_rhombus(points, size):
    return ref_polygon(points, rhombus_vertices(size))


def inside_rhombus(points, size):
    q = _xy(points)
    hx, hy = _half(size, 2)
    return np.abs(q[:, 0]) / hx + np.abs(q[:, 1]) / hy <= 1.0


def curve_rhombus(size):
    return polygon_pieces(rhombus_vertices(size))


def sample_rhombus(n, rng, size):
    return sample_curve(curve_rhombus(size), n, rng)


def ref_ellipse(points, radii):
    """The documented *bound* ``(|p / r| - 1) * min(r)`` (not the true distance)."""
    r = np.asarray(radii, dtype=float)
    return (_norm(_xy(points) / r) - 1.0) * r.min()


def inside_ellipse(points, radii):
    r = np.asarray(radii, dtype=float)
    return np.sum((_xy(points) / r) ** 2, axis=1) <= 1.0


def sample_ellipse(n, rng, radii):
    """Uniform by arc length: parameter-uniform proposals thinned by the speed."""
    a, b = (float(v) for v in radii)
    out, have = [], 0
    while have < n:
        t = rng.uniform(0.0, TAU, 2 * (n - have) + 64)
        speed = np.hypot(a * np.sin(t), b * np.cos(t))
        t = t[rng.random(t.size) * max(a, b) < speed]
        out.append(np.stack([a * np.cos(t), b * np.sin(t)], axis=1))
        have += t.size
    return np.concatenate(out)[:n]


# --------------------------------------------------------------------------
# 3D surface patches (for area-weighted samplers)
# --------------------------------------------------------------------------

Patch = tuple[float, Callable[[int, np.random.Generator], np.ndarray]]


def mixture(n: int, rng: np.random.Generator, patches: Sequence[Patch]) -> np.ndarray:
    """Sample ``n`` points from a union of patches, proportionally to area."""
    areas = np.array([a for a, _ in patches], dtype=float)
    counts = rng.multinomial(n, areas / areas.sum())
    pts = [fn(m, rng) for (_, fn), m in zip(patches, counts, strict=True) if m > 0]
    return np.concatenate(pts, axis=0)


def rect_patch(o, u, v) -> Patch:
    """Parallelogram ``o + s u + t v`` with s, t in [0, 1]."""
    o, u, v = (np.asarray(x, dtype=float) for x in (o, u, v))

    def fn(m, rng):
        st = rng.random((m, 2))
        return o + st[:, :1] * u + st[:, 1:] * v

    return float(np.linalg.norm(np.cross(u, v))), fn


def triangle_patch(a, b, c) -> Patch:
    a, b, c = (np.asarray(x, dtype=float) for x in (a, b, c))

    def fn(m, rng):
        r1 = np.sqrt(rng.random((m, 1)))
        r2 = rng.random((m, 1))
        return a * (1 - r1) + b * (r1 * (1 - r2)) + c * (r1 * r2)

    return 0.5 * float(np.linalg.norm(np.cross(b - a, c - a))), fn


def octant_patch(centre, radius, signs) -> Patch:
    """One eighth of a sphere: the octant selected by ``signs``."""
    c = np.asarray(centre, dtype=float)
    s = np.asarray(signs, dtype=float)

    def fn(m, rng):
        return c + radius * np.abs(unit_vectors(m, rng)) * s

    return 0.5 * np.pi * radius * radius, fn


def hemisphere_patch(centre, radius, direction) -> Patch:
    c = np.asarray(centre, dtype=float)
    d = _unit(direction)

    def fn(m, rng):
        v = unit_vectors(m, rng)
        v = np.where((v @ d)[:, None] < 0, -v, v)
        return c + radius * v

    return TAU * radius * radius, fn


def cylinder_side_patch(base, axis, radius, e1=None, e2=None, t0=0.0, t1=TAU) -> Patch:
    """Side of the cylinder around segment base -> base + axis, angles in [t0, t1]
    measured in the frame (e1, e2) perpendicular to the axis."""
    base = np.asarray(base, dtype=float)
    axis = np.asarray(axis, dtype=float)
    if e1 is None:
        e1, e2 = perpendicular_basis(axis)
    e1 = np.asarray(e1, dtype=float)
    e2 = np.asarray(e2, dtype=float)

    def fn(m, rng):
        s = rng.random((m, 1))
        t = rng.uniform(t0, t1, (m, 1))
        return base + s * axis + radius * (np.cos(t) * e1 + np.sin(t) * e2)

    return radius * abs(t1 - t0) * float(np.linalg.norm(axis)), fn


def torus_arc_patch(centre, major, minor, t0, t1) -> Patch:
    """Tube of radius ``minor`` around the arc (xy plane, centre ``centre``) of
    radius ``major`` for azimuth in [t0, t1] (from +x).  Area-uniform by
    thinning with the area element ``(major + minor cos phi)``."""
    c = np.asarray(centre, dtype=float)

    def fn(m, rng):
        out, have = [], 0
        while have < m:
            k = 2 * (m - have) + 64
            phi = rng.uniform(0.0, TAU, k)
            phi = phi[rng.random(k) * (major + minor) < major + minor * np.cos(phi)]
            th = rng.uniform(t0, t1, phi.size)
            rad = major + minor * np.cos(phi)
            out.append(
                np.stack([rad * np.cos(th), rad * np.sin(th), minor * np.sin(phi)], axis=1)
            )
            have += phi.size
        return c + np.concatenate(out)[:m]

    return TAU * minor * major * abs(t1 - t0), fn


def _box_face_patches(centre, half) -> list[Patch]:
    centre = np.asarray(centre, dtype=float)
    half = np.asarray(half, dtype=float)
    eye = np.eye(3)
    patches = []
    for i in range(3):
        j, k = (i + 1) % 3, (i + 2) % 3
        for s in (-1.0, 1.0):
            o = centre.copy()
            o[i] += s * half[i]
            o[j] -= half[j]
            o[k] -= half[k]
            patches.append(rect_patch(o, 2 * half[j] * eye[j], 2 * half[k] * eye[k]))
    return patches


def sample_revolve(n, rng, pieces, offset=0.0) -> np.ndarray:
    """Sample the surface of revolution of a meridian curve (2D x -> radius - offset,
    2D y -> z).  ``pieces`` must lie in x >= -offset.  Area-uniform: the curve
    is thinned with probability proportional to the radius."""
    out, have = [], 0
    rmax = None
    while have < n:
        k = 3 * (n - have) + 256
        q = sample_curve(pieces, k, rng)
        rad = q[:, 0] + offset
        if np.any(rad < -1e-12):
            raise ValueError("meridian curve crosses the axis")
        if rmax is None:
            rmax = rad.max()
        q = q[rng.random(k) * rmax < rad]
        out.append(q[rng.permutation(q.shape[0])])  # pieces come in order: shuffle
        have += q.shape[0]
    q = np.concatenate(out)[:n]
    rad = q[:, 0] + offset
    phi = rng.uniform(0.0, TAU, n)
    return np.stack([rad * np.cos(phi), rad * np.sin(phi), q[:, 1]], axis=1)


# --------------------------------------------------------------------------
# convex polyhedra (pyramid, prisms, octahedron)
# --------------------------------------------------------------------------


def _oriented_faces(vertices, faces):
    """Faces as (corner array ordered counter-clockwise seen from outside,
    outward unit normal, plane offset)."""
    v = np.asarray(vertices, dtype=float)
    centroid = v.mean(axis=0)
    out = []
    for f in faces:
        poly = v[list(f)]
        nrm = np.sum(np.cross(poly, np.roll(poly, -1, axis=0)), axis=0)  # Newell
        if nrm @ (poly.mean(axis=0) - centroid) < 0:
            poly = poly[::-1]
            nrm = -nrm
        nrm = nrm / np.linalg.norm(nrm)
        out.append((poly, nrm, float(nrm @ poly[0])))
    return out


def ref_convex_polyhedron(points, vertices, faces) -> np.ndarray:
    """Exact SDF of a convex polyhedron.

    Inside: minus the distance to the nearest face plane.  Outside: minimum
    over faces of the distance to the face polygon (projection onto the face
    plane when it lands inside the face, otherwise the nearest face edge).
    """
    p = _xyz(points)
    fs = _oriented_faces(vertices, faces)
    plane = np.stack([p @ nrm - off for _, nrm, off in fs], axis=1)
    inside = np.all(plane <= 0.0, axis=1)
    d_out = np.full(p.shape[0], np.inf)
    for f_idx, (poly, nrm, _) in enumerate(fs):
        sd = plane[:, f_idx]
        proj = p - sd[:, None] * nrm
        a, b = poly, np.roll(poly, -1, axis=0)
        c = np.cross((b - a)[None], proj[:, None, :] - a[None])
        in_face = np.all(c @ nrm >= 0.0, axis=1)
        d_edge = segment_distances(p, a, b).min(axis=1)
        d_out = np.minimum(d_out, np.where(in_face, np.abs(sd), d_edge))
    return np.where(inside, plane.max(axis=1), d_out)


def sample_convex_polyhedron(n, rng, vertices, faces) -> np.ndarray:
    patches = []
    for poly, _, _ in _oriented_faces(vertices, faces):
        for i in range(1, len(poly) - 1):
            patches.append(triangle_patch(poly[0], poly[i], poly[i + 1]))
    return mixture(n, rng, patches)


def prism_polyhedron(vertices2d, height):
    v2 = np.asarray(vertices2d, dtype=float)
    k = len(v2)
    h = 0.5 * height
    verts = np.concatenate(
        [np.column_stack([v2, np.full(k, -h)]), np.column_stack([v2, np.full(k, h)])]
    )
    faces = [list(range(k)), list(range(k, 2 * k))]
    faces += [[i, (i + 1) % k, k + (i + 1) % k, k + i] for i in range(k)]
    return verts, faces


def pyramid_polyhedron(height, base=1.0):
    b = 0.5 * base
    verts = np.array([[-b, -b, 0], [b, -b, 0], [b, b, 0], [-b, b, 0], [0, 0, height]], float)
    faces = [[0, 1, 2, 3], [0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]]
    return verts, faces


def octahedron_polyhedron(size):
    verts = size * np.array(
        [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float
    )
    faces = [[ix, iy, iz] for ix in (0, 1) for iy in (2, 3) for iz in (4, 5)]
    return verts, faces


# --------------------------------------------------------------------------
# 3D primitives
# --------------------------------------------------------------------------


def ref_sphere(points, radius):
    return _norm(_xyz(points)) - radius


def inside_sphere(points, radius):
    p = _xyz(points)
    return np.sum(p * p, axis=1) <= radius * radius


def sample_sphere(n, rng, radius):
    return radius * unit_vectors(n, rng)


def ref_box(points, size):
    return _box_nd(_xyz(points), _half(size, 3))


def inside_box(points, size):
    return np.all(np.abs(_xyz(points)) <= _half(size, 3), axis=1)


def sample_box(n, rng, size):
    return mixture(n, rng, _box_face_patches(np.zeros(3), _half(size, 3)))


def ref_rounded_box(points, size, radius):
    return _box_nd(_xyz(points), _half(size, 3) - radius) - radius


def inside_rounded_box(points, size, radius):
    return _dist_to_box(_xyz(points), _half(size, 3) - radius) <= radius


def sample_rounded_box(n, rng, size, radius):
    h = _half(size, 3)
    c = h - radius  # half extents of the inner (core) box
    eye = np.eye(3)
    patches = []
    for i in range(3):
        j, k = (i + 1) % 3, (i + 2) % 3
        for s in (-1.0, 1.0):  # flat faces
            o = np.zeros(3)
            o[i] = s * h[i]
            o[j] = -c[j]
            o[k] = -c[k]
            patches.append(rect_patch(o, 2 * c[j] * eye[j], 2 * c[k] * eye[k]))
        for sj in (-1.0, 1.0):  # quarter cylinders along axis i
            for sk in (-1.0, 1.0):
                base = np.zeros(3)
                base[i] = -c[i]
                base[j] = sj * c[j]
                base[k] = sk * c[k]
                patches.append(
                    cylinder_side_patch(
                        base, 2 * c[i] * eye[i], radius, sj * eye[j], sk * eye[k], 0.0, np.pi / 2
                    )
                )
    for sx in (-1.0, 1.0):  # sphere octants at the corners
        for sy in (-1.0, 1.0):
            for sz in (-1.0, 1.0):
                s = np.array([sx, sy, sz])
                patches.append(octant_patch(s * c, radius, s))
    patches = [pt for pt in patches if pt[0] > 0]
    return mixture(n, rng, patches)


def box_frame_bars(size, thickness):
    """The 12 edge bars as (centre, half extents)."""
    h = _half(size, 3)
    t = thickness
    bars = []
    for i in range(3):
        j, k = (i + 1) % 3, (i + 2) % 3
        for sj in (-1.0, 1.0):
            for sk in (-1.0, 1.0):
                c = np.zeros(3)
                c[j] = sj * (h[j] - 0.5 * t)
                c[k] = sk * (h[k] - 0.5 * t)
                hh = np.empty(3)
                hh[i] = h[i]
                hh[j] = hh[k] = 0.5 * t
                bars.append((c, hh))
    return bars


def inside_box_frame(points, size, thickness):
    a = np.abs(_xyz(points))
    h = _half(size, 3)
    near = a >= h - thickness
    return np.all(a <= h, axis=1) & (np.count_nonzero(near, axis=1) >= 2)


def ref_box_frame(points, size, thickness):
    """Exact SDF of the box frame.

    Outside the frame: distance to the union of the edge bars (after folding
    into the first octant only the three bars at the +,+ corners matter).
    Inside: distance to the complement = min(distance to the outside of the
    box, distance to the "hollow" set where two coordinates are at least
    ``thickness`` away from their faces).  Note the hollow distance is
    sqrt(e_i^2 + e_j^2), which is larger than the depth inside any single
    bar where three bars overlap (the corner cubes).
    """
    p = _xyz(points)
    h = _half(size, 3)
    t = thickness
    a = np.abs(p)
    d_out = np.full(p.shape[0], np.inf)
    for i in range(3):
        j, k = (i + 1) % 3, (i + 2) % 3
        c = np.zeros(3)
        c[j] = h[j] - 0.5 * t
        c[k] = h[k] - 0.5 * t
        hh = np.empty(3)
        hh[i] = h[i]
        hh[j] = hh[k] = 0.5 * t
        d_out = np.minimum(d_out, _dist_to_box(a - c, hh))
    e = np.maximum(a - (h - t), 0.0)
    d_hollow = np.min(
        np.stack([np.hypot(e[:, 0], e[:, 1]), np.hypot(e[:, 1], e[:, 2]),
                  np.hypot(e[:, 0], e[:, 2])], axis=1),
        axis=1,
    )
    depth = np.minimum(np.min(h - a, axis=1), d_hollow)
    return np.where(inside_box_frame(p, size, thickness), -depth, d_out)


def sample_box_frame(n, rng, size, thickness):
    """Faces of all 12 bars, keeping the points not strictly inside another bar."""
    bars = box_frame_bars(size, thickness)
    patches = [pt for c, hh in bars for pt in _box_face_patches(c, hh)]
    margin = 1e-9 * float(np.max(size))
    out, have = [], 0
    while have < n:
        q = mixture(2 * (n - have) + 256, rng, patches)
        buried = np.zeros(q.shape[0], dtype=bool)
        for c, hh in bars:
            buried |= np.all(np.abs(q - c) < hh - margin, axis=1)
        q = q[~buried]
        out.append(q[rng.permutation(q.shape[0])])
        have += q.shape[0]
    return np.concatenate(out)[:n]


def ref_cylinder(points, radius, height):
    return _box_nd(_rho_z(points), np.array([radius, 0.5 * height]))


def inside_cylinder(points, radius, height):
    rz = _rho_z(points)
    return (rz[:, 0] <= radius) & (np.abs(rz[:, 1]) <= 0.5 * height)


def meridian_cylinder(radius, height):
    h = 0.5 * height
    return polygon_pieces([(0, -h), (radius, -h), (radius, h), (0, h)])[:3]


def sample_cylinder(n, rng, radius, height):
    return sample_revolve(n, rng, meridian_cylinder(radius, height))


def ref_rounded_cylinder(points, radius, height, rounding):
    core = np.array([radius - rounding, 0.5 * height - rounding])
    return _box_nd(_rho_z(points), core) - rounding


def inside_rounded_cylinder(points, radius, height, rounding):
    core = np.array([radius - rounding, 0.5 * height - rounding])
    return _dist_to_box(_rho_z(points), core) <= rounding


def meridian_rounded_cylinder(radius, height, rounding):
    h = 0.5 * height
    r = rounding
    return [
        seg((0, -h), (radius - r, -h)),
        arc((radius - r, -h + r), r, -0.5 * np.pi, 0.0),
        seg((radius, -h + r), (radius, h - r)),
        arc((radius - r, h - r), r, 0.0, 0.5 * np.pi),
        seg((radius - r, h), (0, h)),
    ]


def sample_rounded_cylinder(n, rng, radius, height, rounding):
    return sample_revolve(n, rng, meridian_rounded_cylinder(radius, height, rounding))


def ref_capsule(points, a, b, radius):
    return segment_distances(_xyz(points), a, b)[:, 0] - radius


def inside_capsule(points, a, b, radius):
    return segment_distances(_xyz(points), a, b)[:, 0] <= radius


def sample_capsule(n, rng, a, b, radius):
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    w = b - a
    if np.linalg.norm(w) == 0:
        return a + sample_sphere(n, rng, radius)
    patches = [
        cylinder_side_patch(a, w, radius),
        hemisphere_patch(a, radius, -w),
        hemisphere_patch(b, radius, w),
    ]
    return mixture(n, rng, patches)


def _cone_meridian_polygon(radius, height):
    return [(-radius, 0.0), (radius, 0.0), (0.0, height)]


def ref_cone(points, radius, height):
    # exact: the solid of revolution of the (axis-symmetric) meridian triangle
    return ref_polygon(_rho_z(points), _cone_meridian_polygon(radius, height))


def inside_cone(points, radius, height):
    rz = _rho_z(points)
    z = rz[:, 1]
    return (z >= 0) & (z <= height) & (rz[:, 0] <= radius * (1.0 - z / height))


def sample_cone(n, rng, radius, height):
    pieces = [seg((0, 0), (radius, 0)), seg((radius, 0), (0, height))]
    return sample_revolve(n, rng, pieces)


def ref_capped_cone(points, r1, r2, height):
    poly = [(-r1, 0.0), (r1, 0.0), (r2, height), (-r2, height)]
    return ref_polygon(_rho_z(points), poly)


def inside_capped_cone(points, r1, r2, height):
    rz = _rho_z(points)
    z = rz[:, 1]
    return (z >= 0) & (z <= height) & (rz[:, 0] <= r1 + (r2 - r1) * z / height)


def sample_capped_cone(n, rng, r1, r2, height):
    pieces = [seg((0, 0), (r1, 0)), seg((r1, 0), (r2, height)), seg((r2, height), (0, height))]
    return sample_revolve(n, rng, pieces)


def ref_round_cone(points, r1, r2, height):
    """Convex hull of two balls = union of the balls B(t*height*z, r1 + t*(r2-r1)),
    t in [0, 1].  f(t) = |p - c(t)| - r(t) is convex in t; its stationary
    point has (z - t*height) = -k*rho/sqrt(1-k^2), k = (r2-r1)/height, and the
    minimum over [0, 1] is the clamped stationary point."""
    rz = _rho_z(points)
    rho, z = rz[:, 0], rz[:, 1]
    k = (r2 - r1) / height
    u = -k * rho / np.sqrt(1.0 - k * k)
    t = np.clip((z - u) / height, 0.0, 1.0)
    return np.hypot(rho, z - t * height) - (r1 + t * (r2 - r1))


def _round_cone_tangent(r1, r2, height):
    s = (r1 - r2) / height  # sin of the tangent-point angle above the horizontal
    return np.arcsin(s)


def inside_round_cone(points, r1, r2, height):
    """Union of the two balls and the frustum between their tangent circles."""
    rz = _rho_z(points)
    rho, z = rz[:, 0], rz[:, 1]
    al = _round_cone_tangent(r1, r2, height)
    z1, q1 = r1 * np.sin(al), r1 * np.cos(al)
    z2, q2 = height + r2 * np.sin(al), r2 * np.cos(al)
    ball1 = rho**2 + z**2 <= r1**2
    ball2 = rho**2 + (z - height) ** 2 <= r2**2
    s = (z - z1) / (z2 - z1)
    frustum = (s >= 0) & (s <= 1) & (rho <= q1 + s * (q2 - q1))
    return ball1 | ball2 | frustum


def meridian_round_cone(r1, r2, height):
    al = _round_cone_tangent(r1, r2, height)
    t1 = (r1 * np.cos(al), r1 * np.sin(al))
    t2 = (r2 * np.cos(al), height + r2 * np.sin(al))
    return [
        arc((0, 0), r1, -0.5 * np.pi, al),
        seg(t1, t2),
        arc((0, height), r2, al, 0.5 * np.pi),
    ]


def sample_round_cone(n, rng, r1, r2, height):
    return sample_revolve(n, rng, meridian_round_cone(r1, r2, height))


def ref_torus(points, major, minor):
    rz = _rho_z(points)
    return np.hypot(rz[:, 0] - major, rz[:, 1]) - minor


def inside_torus(points, major, minor):
    rz = _rho_z(points)
    return (rz[:, 0] - major) ** 2 + rz[:, 1] ** 2 <= minor * minor


def sample_torus(n, rng, major, minor):
    return mixture(n, rng, [torus_arc_patch((0, 0, 0), major, minor, 0.0, TAU)])


def arc_distance_xy(points, centre, radius, t0, t1) -> np.ndarray:
    """Distance from 3D points to the circular arc {centre + radius*(cos t, sin t, 0),
    t in [t0, t1]} (t1 > t0, span <= 2 pi).

    When the azimuth of the point lies in the arc, the radial projection is the
    closest arc point; otherwise cos(azimuth - t) is unimodal over the arc, so
    the closest point is an end point."""
    p = _xyz(points)
    c = np.asarray(centre, dtype=float)
    qx, qy, qz = p[:, 0] - c[0], p[:, 1] - c[1], p[:, 2] - c[2]
    psi = np.arctan2(qy, qx)
    in_arc = np.mod(psi - t0, TAU) <= (t1 - t0)
    d_in = np.hypot(np.hypot(qx, qy) - radius, qz)
    ends = []
    for t in (t0, t1):
        ends.append(np.sqrt((qx - radius * np.cos(t)) ** 2 + (qy - radius * np.sin(t)) ** 2
                            + qz**2))
    return np.where(in_arc, d_in, np.minimum(*ends))


def ref_capped_torus(points, major, minor, angle):
    # centre-circle arc: azimuth (from +x) pi/2 - angle .. pi/2 + angle
    if angle >= np.pi:
        return ref_torus(points, major, minor)
    d = arc_distance_xy(points, (0, 0, 0), major, 0.5 * np.pi - angle, 0.5 * np.pi + angle)
    return d - minor


def inside_capped_torus(points, major, minor, angle):
    """In the torus with the projection azimuth (from +y) within the arc, or in
    one of the two end balls."""
    p = _xyz(points)
    phi = np.arctan2(p[:, 0], p[:, 1])  # azimuth measured from +y towards +x
    in_tube = inside_torus(p, major, minor) & (np.abs(phi) <= angle)
    ends = []
    for s in (-1.0, 1.0):
        e = major * np.array([s * np.sin(angle), np.cos(angle), 0.0])
        ends.append(np.sum((p - e) ** 2, axis=1) <= minor * minor)
    return in_tube | ends[0] | ends[1]


def sample_capped_torus(n, rng, major, minor, angle):
    if angle >= np.pi:
        return sample_torus(n, rng, major, minor)
    t0, t1 = 0.5 * np.pi - angle, 0.5 * np.pi + angle
    patches = [torus_arc_patch((0, 0, 0), major, minor, t0, t1)]
    for t, s in ((t0, -1.0), (t1, 1.0)):
        end = major * np.array([np.cos(t), np.sin(t), 0.0])
        tangent = s * np.array([-np.sin(t), np.cos(t), 0.0])  # pointing away from the arc
        patches.append(hemisphere_patch(end, minor, tangent))
    return mixture(n, rng, patches)


def _link_curve(length, major):
    """Stadium centre curve: two half circles and two straight segments."""
    h = 0.5 * length
    return (
        [((major, -h, 0.0), (major, h, 0.0)), ((-major, -h, 0.0), (-major, h, 0.0))],
        [((0.0, h, 0.0), 0.0, np.pi), ((0.0, -h, 0.0), np.pi, TAU)],
    )


def ref_link(points, length, major, minor):
    p = _xyz(points)
    segs, arcs = _link_curve(length, major)
    d = np.full(p.shape[0], np.inf)
    for a, b in segs:
        d = np.minimum(d, segment_distances(p, a, b)[:, 0])
    for c, t0, t1 in arcs:
        d = np.minimum(d, arc_distance_xy(p, c, major, t0, t1))
    return d - minor


def inside_link(points, length, major, minor):
    # fold the stadium: the distance in the xy plane to the centre curve is
    # | |(x, max(|y| - length/2, 0))| - major |
    p = _xyz(points)
    yy = np.maximum(np.abs(p[:, 1]) - 0.5 * length, 0.0)
    planar = np.hypot(p[:, 0], yy) - major
    return planar**2 + p[:, 2] ** 2 <= minor * minor


def sample_link(n, rng, length, major, minor):
    segs, arcs = _link_curve(length, major)
    patches = []
    for a, b in segs:
        a = np.asarray(a)
        patches.append(cylinder_side_patch(a, np.asarray(b) - a, minor))
    for c, t0, t1 in arcs:
        patches.append(torus_arc_patch(c, major, minor, t0, t1))
    return mixture(n, rng, patches)


def ref_plane(points, normal=(0.0, 0.0, 1.0), offset=0.0):
    return _xyz(points) @ _unit(normal) - offset


def inside_plane(points, normal=(0.0, 0.0, 1.0), offset=0.0):
    return _xyz(points) @ _unit(normal) <= offset


def sample_plane(n, rng, normal=(0.0, 0.0, 1.0), offset=0.0, extent=4.0):
    """A (2*extent)^2 square patch of the plane centred at offset*n."""
    nrm = _unit(normal)
    e1, e2 = perpendicular_basis(nrm)
    o = offset * nrm - extent * (e1 + e2)
    return mixture(n, rng, [rect_patch(o, 2 * extent * e1, 2 * extent * e2)])


def ref_slab(points, thickness, normal=(0.0, 0.0, 1.0)):
    return np.abs(_xyz(points) @ _unit(normal)) - 0.5 * thickness


def inside_slab(points, thickness, normal=(0.0, 0.0, 1.0)):
    return np.abs(_xyz(points) @ _unit(normal)) <= 0.5 * thickness


def sample_slab(n, rng, thickness, normal=(0.0, 0.0, 1.0), extent=4.0):
    nrm = _unit(normal)
    e1, e2 = perpendicular_basis(nrm)
    patches = []
    for s in (-1.0, 1.0):
        o = s * 0.5 * thickness * nrm - extent * (e1 + e2)
        patches.append(rect_patch(o, 2 * extent * e1, 2 * extent * e2))
    return mixture(n, rng, patches)


def ref_ellipsoid(points, radii):
    """The documented *bound* ``(|p / r| - 1) * min(r)``."""
    r = np.asarray(radii, dtype=float)
    return (_norm(_xyz(points) / r) - 1.0) * r.min()


def inside_ellipsoid(points, radii):
    r = np.asarray(radii, dtype=float)
    return np.sum((_xyz(points) / r) ** 2, axis=1) <= 1.0


def sample_ellipsoid(n, rng, radii):
    """Area-uniform: map unit-sphere samples by diag(r) and thin them with the
    area element, which is proportional to |u / r| for the sphere point u."""
    r = np.asarray(radii, dtype=float)
    out, have = [], 0
    while have < n:
        u = unit_vectors(2 * (n - have) + 64, rng)
        w = _norm(u / r)
        u = u[rng.random(u.shape[0]) * (1.0 / r.min()) < w]
        out.append(u * r)
        have += u.shape[0]
    return np.concatenate(out)[:n]


def ref_octahedron(points, size):
    """The documented *bound* ``(|x| + |y| + |z| - size) / sqrt(3)``."""
    return (np.sum(np.abs(_xyz(points)), axis=1) - size) / np.sqrt(3.0)


def ref_octahedron_exact(points, size):
    return ref_convex_polyhedron(points, *octahedron_polyhedron(size))


def inside_octahedron(points, size):
    return np.sum(np.abs(_xyz(points)), axis=1) <= size


def sample_octahedron(n, rng, size):
    return sample_convex_polyhedron(n, rng, *octahedron_polyhedron(size))


def ref_pyramid(points, height, base=1.0):
    return ref_convex_polyhedron(points, *pyramid_polyhedron(height, base))


def inside_pyramid(points, height, base=1.0):
    p = _xyz(points)
    z = p[:, 2]
    half = 0.5 * base * (1.0 - z / height)
    return (z >= 0) & (z <= height) & (np.max(np.abs(p[:, :2]), axis=1) <= half)


def sample_pyramid(n, rng, height, base=1.0):
    return sample_convex_polyhedron(n, rng, *pyramid_polyhedron(height, base))


def ref_hex_prism(points, radius, height):
    return ref_convex_polyhedron(points, *prism_polyhedron(hexagon_vertices(radius), height))


def inside_hex_prism(points, radius, height):
    p = _xyz(points)
    return inside_hexagon(p, radius) & (np.abs(p[:, 2]) <= 0.5 * height)


def sample_hex_prism(n, rng, radius, height):
    return sample_convex_polyhedron(n, rng, *prism_polyhedron(hexagon_vertices(radius), height))


def tri_prism_vertices(radius):
    return regular_polygon_vertices(3, radius)


def ref_tri_prism(points, radius, height):
    return ref_convex_polyhedron(points, *prism_polyhedron(tri_prism_vertices(radius), height))


def inside_tri_prism(points, radius, height):
    p = _xyz(points)
    # each edge is at distance radius/2 from the centroid, opposite a vertex
    t = TAU * np.arange(3) / 3
    away = -np.stack([np.sin(t), np.cos(t)], axis=1)
    in_tri = np.all(p[:, :2] @ away.T <= 0.5 * radius, axis=1)
    return in_tri & (np.abs(p[:, 2]) <= 0.5 * height)


def sample_tri_prism(n, rng, radius, height):
    verts = prism_polyhedron(tri_prism_vertices(radius), height)
    return sample_convex_polyhedron(n, rng, *verts)


# --------------------------------------------------------------------------
# operators
# --------------------------------------------------------------------------


def ref_extrude(points, ref2d, height):
    """Exact SDF of (2D set) x [-height/2, height/2] given the exact 2D SDF."""
    p = _xyz(points)
    d = ref2d(p[:, :2])
    dz = np.abs(p[:, 2]) - 0.5 * height
    outside = np.hypot(np.maximum(d, 0.0), np.maximum(dz, 0.0))
    return np.where((d <= 0) & (dz <= 0), np.maximum(d, dz), outside)


def inside_extrude(points, inside2d, height):
    p = _xyz(points)
    return inside2d(p[:, :2]) & (np.abs(p[:, 2]) <= 0.5 * height)


def sample_extrude(n, rng, pieces, inside2d, height, lo, hi):
    """Walls (boundary curve x z) and the two caps (rejection in the 2D box
    [lo, hi]) by area."""
    lo = np.asarray(lo, dtype=float)
    hi = np.asarray(hi, dtype=float)
    probe = lo + (hi - lo) * rng.random((20000, 2))
    cap_area = float(np.prod(hi - lo) * np.mean(inside2d(probe)))
    h = 0.5 * height

    def walls(m, rng):
        q = sample_curve(pieces, m, rng)
        return np.column_stack([q, rng.uniform(-h, h, m)])

    def cap(z):
        def fn(m, rng):
            out, have = [], 0
            while have < m:
                q = lo + (hi - lo) * rng.random((2 * (m - have) + 64, 2))
                q = q[inside2d(q)]
                out.append(q)
                have += q.shape[0]
            q = np.concatenate(out)[:m]
            return np.column_stack([q, np.full(m, z)])

        return fn

    patches = [(curve_length(pieces) * height, walls), (cap_area, cap(-h)), (cap_area, cap(h))]
    return mixture(n, rng, patches)


def ref_revolve(points, ref2d, offset=0.0):
    rz = _rho_z(points)
    return ref2d(np.stack([rz[:, 0] - offset, rz[:, 1]], axis=1))


def inside_revolve(points, inside2d, offset=0.0):
    rz = _rho_z(points)
    return inside2d(np.stack([rz[:, 0] - offset, rz[:, 1]], axis=1))
