"""Check the ``csdf`` primitives against independent NumPy references.

For every primitive (1-3 argument sets) we check

* the exactness label,
* the values against the closed-form reference of ``reference_shapes`` (or,
  for the documented bounds, against the documented bound formula),
* exact shapes: ``|grad f| == 1`` almost everywhere (central differences of
  the library's values) and agreement with the brute-force signed distance to
  densely sampled boundary points (cKDTree; sign from an inside test),
* bounds: the sign matches the inside test and ``|f|`` never exceeds the
  brute-force distance (which itself over-estimates the true distance),
* the empirical Lipschitz constant does not exceed ``shape.lipschitz``,
* 2D shapes: ``(N, 2)`` input and ``(N, 3)`` input (z ignored) agree.

The references themselves are validated against the brute-force distance
without the library (``test_reference_*``), so a failure of a library test
with a passing reference test points at the library.

Brute-force tolerance: with boundary samples ``S``, the kd-tree distance
``d_S`` satisfies ``d <= d_S <= d + cover`` where ``cover`` is the covering
radius of ``S``; ``cover`` is estimated as the largest nearest-sample
distance of 20k fresh boundary samples, and ``2 * cover`` is used.
"""

from __future__ import annotations

import zlib
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pytest
from scipy.spatial import cKDTree

try:  # tests/ as a package or as a plain directory on sys.path
    from . import reference_shapes as rs
except ImportError:
    import reference_shapes as rs

N_SURFACE_3D = 200_000
N_SURFACE_2D = 100_000
N_FRESH = 20_000
N_UNIFORM = 1500
N_NEAR = 1000
N_GRAD = 1000
VALUE_RTOL = 1e-9  # value tolerance relative to the shape size
GRAD_TOL = 1e-4
GRAD_BAD_FRACTION = 0.01


@dataclass(frozen=True)
class Case:
    id: str
    make: Callable[[Any], Any]  # csdf module -> shape
    ref: Callable[[np.ndarray], np.ndarray]  # value the library must return
    inside: Callable[[np.ndarray], np.ndarray]
    sample: Callable[[int, np.random.Generator], np.ndarray]
    exactness: str = "exact"
    dim: int = 3
    exact_ref: Callable[[np.ndarray], np.ndarray] | None = None  # true SDF for bounds
    query_half: tuple | None = None  # override of the query box half extents
    extra: dict = field(default_factory=dict)


def _c(id, make, name, exactness="exact", dim=3, query_half=None, exact_ref=None, **kw):
    """Case for ``rs.ref_<name>`` / ``rs.inside_<name>`` / ``rs.sample_<name>``."""
    ref = getattr(rs, f"ref_{name}")
    inside = getattr(rs, f"inside_{name}")
    sample = getattr(rs, f"sample_{name}")
    return Case(
        id=id,
        make=make,
        ref=lambda p: ref(p, **kw),
        inside=lambda p: inside(p, **kw),
        sample=lambda n, rng: sample(n, rng, **kw),
        exactness=exactness,
        dim=dim,
        exact_ref=None if exact_ref is None else (lambda p: exact_ref(p, **kw)),
        query_half=query_half,
    )


STAR = [
    (np.cos(t) * r, np.sin(t) * r)
    for t, r in zip(
        np.pi / 2 + np.arange(10) * np.pi / 5, [1.0, 0.45] * 5, strict=True
    )
]  # counter-clockwise 5-point star
L_SHAPE_CW = [(-0.4, -0.4), (-0.4, 0.6), (0.0, 0.6), (0.0, 0.0), (0.6, 0.0), (0.6, -0.4)]
TRI_CCW = ((-0.5, -0.3), (0.8, 0.1), (0.1, 0.9))
TRI_CW_OBTUSE = ((0.0, 0.0), (-0.3, 0.4), (1.2, 0.1))

PRIMITIVE_CASES = [
    # ---------------------------------------------------------------- 3D
    _c("sphere-0.7", lambda c: c.sphere(0.7), "sphere", radius=0.7),
    _c("sphere-1.3", lambda c: c.sphere(1.3), "sphere", radius=1.3),
    _c("box-1x2x0.6", lambda c: c.box((1.0, 2.0, 0.6)), "box", size=(1.0, 2.0, 0.6)),
    _c("box-scalar1.5", lambda c: c.box(1.5), "box", size=1.5),
    _c("rounded_box-a", lambda c: c.rounded_box((1.2, 2.0, 0.8), 0.15), "rounded_box",
       size=(1.2, 2.0, 0.8), radius=0.15),
    _c("rounded_box-b", lambda c: c.rounded_box((2.0, 1.0, 1.4), 0.45), "rounded_box",
       size=(2.0, 1.0, 1.4), radius=0.45),
    _c("box_frame-a", lambda c: c.box_frame((1.0, 1.6, 1.2), 0.2), "box_frame",
       size=(1.0, 1.6, 1.2), thickness=0.2),
    _c("box_frame-b", lambda c: c.box_frame((2.0, 1.0, 1.0), 0.3), "box_frame",
       size=(2.0, 1.0, 1.0), thickness=0.3),
    _c("cylinder-tall", lambda c: c.cylinder(0.5, 2.0), "cylinder", radius=0.5, height=2.0),
    _c("cylinder-flat", lambda c: c.cylinder(1.2, 0.4), "cylinder", radius=1.2, height=0.4),
    _c("rounded_cylinder-a", lambda c: c.rounded_cylinder(0.8, 1.5, 0.2), "rounded_cylinder",
       radius=0.8, height=1.5, rounding=0.2),
    _c("rounded_cylinder-b", lambda c: c.rounded_cylinder(0.5, 2.0, 0.45), "rounded_cylinder",
       radius=0.5, height=2.0, rounding=0.45),
    _c("capsule-oblique",
       lambda c: c.capsule((-0.5, 0.2, 0.1), (0.7, -0.3, 0.9), 0.25), "capsule",
       a=(-0.5, 0.2, 0.1), b=(0.7, -0.3, 0.9), radius=0.25),
    _c("capsule-z", lambda c: c.capsule((0.0, 0.0, -1.0), (0.0, 0.0, 1.0), 0.5), "capsule",
       a=(0.0, 0.0, -1.0), b=(0.0, 0.0, 1.0), radius=0.5),
    _c("cone-tall", lambda c: c.cone(0.8, 1.5), "cone", radius=0.8, height=1.5),
    _c("cone-flat", lambda c: c.cone(1.5, 0.6), "cone", radius=1.5, height=0.6),
    _c("capped_cone-r1>r2", lambda c: c.capped_cone(0.9, 0.4, 1.2), "capped_cone",
       r1=0.9, r2=0.4, height=1.2),
    _c("capped_cone-r1<r2", lambda c: c.capped_cone(0.3, 1.0, 0.8), "capped_cone",
       r1=0.3, r2=1.0, height=0.8),
    _c("round_cone-r1>r2", lambda c: c.round_cone(0.5, 0.2, 1.2), "round_cone",
       r1=0.5, r2=0.2, height=1.2),
    _c("round_cone-r1<r2", lambda c: c.round_cone(0.15, 0.6, 1.0), "round_cone",
       r1=0.15, r2=0.6, height=1.0),
    _c("torus-a", lambda c: c.torus(1.0, 0.3), "torus", major=1.0, minor=0.3),
    _c("torus-fat", lambda c: c.torus(0.5, 0.45), "torus", major=0.5, minor=0.45),
    _c("capped_torus-2.0", lambda c: c.capped_torus(1.0, 0.25, 2.0), "capped_torus",
       major=1.0, minor=0.25, angle=2.0),
    _c("capped_torus-0.7", lambda c: c.capped_torus(0.8, 0.2, 0.7), "capped_torus",
       major=0.8, minor=0.2, angle=0.7),
    _c("link-a", lambda c: c.link(1.0, 0.5, 0.15), "link", length=1.0, major=0.5, minor=0.15),
    _c("link-b", lambda c: c.link(0.4, 0.3, 0.1), "link", length=0.4, major=0.3, minor=0.1),
    _c("plane-default", lambda c: c.plane(), "plane", query_half=(1.5, 1.5, 1.5)),
    _c("plane-oblique", lambda c: c.plane((1.0, 2.0, -0.5), 0.3), "plane",
       query_half=(1.5, 1.5, 1.5), normal=(1.0, 2.0, -0.5), offset=0.3),
    _c("slab-z", lambda c: c.slab(0.5), "slab", query_half=(1.5, 1.5, 1.5), thickness=0.5),
    _c("slab-oblique", lambda c: c.slab(0.8, (1.0, -1.0, 2.0)), "slab",
       query_half=(1.5, 1.5, 1.5), thickness=0.8, normal=(1.0, -1.0, 2.0)),
    _c("ellipsoid-a", lambda c: c.ellipsoid((1.0, 0.5, 0.8)), "ellipsoid", exactness="bound",
       radii=(1.0, 0.5, 0.8)),
    _c("ellipsoid-b", lambda c: c.ellipsoid((0.3, 1.2, 0.6)), "ellipsoid", exactness="bound",
       radii=(0.3, 1.2, 0.6)),
    _c("octahedron-1", lambda c: c.octahedron(1.0), "octahedron", exactness="bound",
       exact_ref=rs.ref_octahedron_exact, size=1.0),
    _c("octahedron-0.6", lambda c: c.octahedron(0.6), "octahedron", exactness="bound",
       exact_ref=rs.ref_octahedron_exact, size=0.6),
    _c("pyramid-default-base", lambda c: c.pyramid(1.2), "pyramid", height=1.2),
    _c("pyramid-wide", lambda c: c.pyramid(0.5, 1.6), "pyramid", height=0.5, base=1.6),
    _c("hex_prism-a", lambda c: c.hex_prism(0.6, 1.0), "hex_prism", radius=0.6, height=1.0),
    _c("hex_prism-b", lambda c: c.hex_prism(1.0, 0.3), "hex_prism", radius=1.0, height=0.3),
    _c("tri_prism-a", lambda c: c.tri_prism(0.7, 1.2), "tri_prism", radius=0.7, height=1.2),
    _c("tri_prism-b", lambda c: c.tri_prism(1.0, 0.4), "tri_prism", radius=1.0, height=0.4),
    # ---------------------------------------------------------------- 2D
    _c("circle-0.8", lambda c: c.circle(0.8), "circle", dim=2, radius=0.8),
    _c("circle-0.3", lambda c: c.circle(0.3), "circle", dim=2, radius=0.3),
    _c("rectangle-1.5x0.6", lambda c: c.rectangle((1.5, 0.6)), "rectangle", dim=2,
       size=(1.5, 0.6)),
    _c("rectangle-scalar", lambda c: c.rectangle(1.0), "rectangle", dim=2, size=1.0),
    _c("rounded_rectangle-a", lambda c: c.rounded_rectangle((1.6, 1.0), 0.25),
       "rounded_rectangle", dim=2, size=(1.6, 1.0), radius=0.25),
    _c("rounded_rectangle-b", lambda c: c.rounded_rectangle((1.0, 2.0), 0.4),
       "rounded_rectangle", dim=2, size=(1.0, 2.0), radius=0.4),
    _c("regular_polygon-5", lambda c: c.regular_polygon(5, 0.8), "regular_polygon", dim=2,
       n=5, radius=0.8),
    _c("regular_polygon-3", lambda c: c.regular_polygon(3, 1.0), "regular_polygon", dim=2,
       n=3, radius=1.0),
    _c("regular_polygon-8", lambda c: c.regular_polygon(8, 0.6), "regular_polygon", dim=2,
       n=8, radius=0.6),
    _c("polygon-L-cw", lambda c: c.polygon(L_SHAPE_CW), "polygon", dim=2, vertices=L_SHAPE_CW),
    _c("polygon-star-ccw", lambda c: c.polygon(STAR), "polygon", dim=2, vertices=STAR),
    _c("triangle-ccw", lambda c: c.triangle(*TRI_CCW), "triangle", dim=2,
       a=TRI_CCW[0], b=TRI_CCW[1], c=TRI_CCW[2]),
    _c("triangle-cw-obtuse", lambda c: c.triangle(*TRI_CW_OBTUSE), "triangle", dim=2,
       a=TRI_CW_OBTUSE[0], b=TRI_CW_OBTUSE[1], c=TRI_CW_OBTUSE[2]),
    _c("hexagon-0.7", lambda c: c.hexagon(0.7), "hexagon", dim=2, radius=0.7),
    _c("hexagon-1.2", lambda c: c.hexagon(1.2), "hexagon", dim=2, radius=1.2),
    _c("ring-thin", lambda c: c.ring(0.8, 0.2), "ring", dim=2, radius=0.8, thickness=0.2),
    _c("ring-thick", lambda c: c.ring(0.5, 0.6), "ring", dim=2, radius=0.5, thickness=0.6),
    _c("segment-thick", lambda c: c.segment((-0.5, 0.2), (0.6, -0.4), 0.3), "segment", dim=2,
       a=(-0.5, 0.2), b=(0.6, -0.4), thickness=0.3),
    _c("segment-zero", lambda c: c.segment((0.0, 0.0), (1.0, 1.0)), "segment", dim=2,
       a=(0.0, 0.0), b=(1.0, 1.0), thickness=0.0),
    _c("trapezoid-r1>r2", lambda c: c.trapezoid(0.8, 0.3, 1.0), "trapezoid", dim=2,
       r1=0.8, r2=0.3, height=1.0),
    _c("trapezoid-r1<r2", lambda c: c.trapezoid(0.2, 0.7, 0.6), "trapezoid", dim=2,
       r1=0.2, r2=0.7, height=0.6),
    _c("rhombus-wide", lambda c: c.rhombus((1.6, 0.8)), "rhombus", dim=2, size=(1.6, 0.8)),
    _c("rhombus-tall", lambda c: c.rhombus((0.6, 1.4)), "rhombus", dim=2, size=(0.6, 1.4)),
    _c("ellipse-wide", lambda c: c.ellipse((1.0, 0.4)), "ellipse", exactness="bound", dim=2,
       radii=(1.0, 0.4)),
    _c("ellipse-tall", lambda c: c.ellipse((0.5, 0.9)), "ellipse", exactness="bound", dim=2,
       radii=(0.5, 0.9)),
]


def _extrude_case(id, make2d, ref2d, inside2d, pieces, lo, hi, height):
    return Case(
        id=id,
        make=lambda c: c.extrude(make2d(c), height),
        ref=lambda p: rs.ref_extrude(p, ref2d, height),
        inside=lambda p: rs.inside_extrude(p, inside2d, height),
        sample=lambda n, rng: rs.sample_extrude(n, rng, pieces, inside2d, height, lo, hi),
    )


def _revolve_case(id, make2d, ref2d, inside2d, pieces, offset):
    return Case(
        id=id,
        make=lambda c: c.revolve(make2d(c), offset=offset),
        ref=lambda p: rs.ref_revolve(p, ref2d, offset),
        inside=lambda p: rs.inside_revolve(p, inside2d, offset),
        sample=lambda n, rng: rs.sample_revolve(n, rng, pieces, offset),
    )


REV_TRI = ((-0.2, -0.3), (0.4, 0.0), (0.0, 0.5))

OPERATOR_CASES = [
    _extrude_case("extrude-circle", lambda c: c.circle(0.5),
                  lambda q: rs.ref_circle(q, 0.5), lambda q: rs.inside_circle(q, 0.5),
                  rs.curve_circle(0.5), (-0.5, -0.5), (0.5, 0.5), 1.0),
    _extrude_case("extrude-star", lambda c: c.polygon(STAR),
                  lambda q: rs.ref_polygon(q, STAR), lambda q: rs.inside_polygon(q, STAR),
                  rs.curve_polygon(STAR), (-1.0, -1.0), (1.0, 1.0), 0.6),
    _extrude_case("extrude-rounded_rectangle", lambda c: c.rounded_rectangle((1.0, 0.6), 0.2),
                  lambda q: rs.ref_rounded_rectangle(q, (1.0, 0.6), 0.2),
                  lambda q: rs.inside_rounded_rectangle(q, (1.0, 0.6), 0.2),
                  rs.curve_rounded_rectangle((1.0, 0.6), 0.2), (-0.5, -0.3), (0.5, 0.3), 2.0),
    _revolve_case("revolve-rectangle-offset1", lambda c: c.rectangle((0.4, 1.0)),
                  lambda q: rs.ref_rectangle(q, (0.4, 1.0)),
                  lambda q: rs.inside_rectangle(q, (0.4, 1.0)),
                  rs.curve_rectangle((0.4, 1.0)), 1.0),
    _revolve_case("revolve-circle-offset0.8", lambda c: c.circle(0.3),
                  lambda q: rs.ref_circle(q, 0.3), lambda q: rs.inside_circle(q, 0.3),
                  rs.curve_circle(0.3), 0.8),
    _revolve_case("revolve-triangle-offset0.5", lambda c: c.triangle(*REV_TRI),
                  lambda q: rs.ref_triangle(q, *REV_TRI),
                  lambda q: rs.inside_triangle(q, *REV_TRI),
                  rs.curve_triangle(*REV_TRI), 0.5),
    # symmetric cross-section straddling the axis: a cylinder of radius 0.5
    _revolve_case("revolve-rectangle-offset0", lambda c: c.rectangle((1.0, 0.6)),
                  lambda q: rs.ref_rectangle(q, (1.0, 0.6)),
                  lambda q: rs.inside_rectangle(q, (1.0, 0.6)),
                  rs.meridian_cylinder(0.5, 0.6), 0.0),
]

CASES = PRIMITIVE_CASES + OPERATOR_CASES


# --------------------------------------------------------------------------
# fixtures (module scoped and parametrised, so pytest groups all tests of one
# case together and the expensive surface samples are built once per case)
# --------------------------------------------------------------------------


def _seed(text: str) -> int:
    return zlib.crc32(text.encode())


@dataclass
class Data:
    surface: np.ndarray
    tree: cKDTree
    cover: float  # estimated covering radius of the surface samples
    scale: float
    lo: np.ndarray
    hi: np.ndarray
    query: np.ndarray
    d_brute: np.ndarray  # kd-tree distance (an upper bound of the true distance)
    inside: np.ndarray
    ref: np.ndarray


@pytest.fixture(scope="module", params=CASES, ids=[c.id for c in CASES])
def case(request) -> Case:
    return request.param


@pytest.fixture(scope="module")
def data(case: Case) -> Data:
    rng = np.random.default_rng(_seed(case.id))
    n = N_SURFACE_3D if case.dim == 3 else N_SURFACE_2D
    surface = case.sample(n, rng)
    assert surface.shape == (n, case.dim)
    tree = cKDTree(surface)
    cover = float(tree.query(case.sample(N_FRESH, rng))[0].max())
    if case.query_half is not None:
        half = np.asarray(case.query_half, dtype=float)
        lo, hi = -half, half
    else:
        lo, hi = surface.min(axis=0), surface.max(axis=0)
        pad = 0.3 * float(np.max(hi - lo))
        lo, hi = lo - pad, hi + pad
    scale = float(np.max(hi - lo)) / 2
    uniform = lo + (hi - lo) * rng.random((N_UNIFORM, case.dim))
    near_base = case.sample(N_NEAR, rng)
    if case.query_half is not None:  # unbounded shapes: keep to the query box
        while True:
            keep = np.all((near_base >= lo) & (near_base <= hi), axis=1)
            if keep.sum() >= N_NEAR:
                break
            near_base = np.concatenate([near_base[keep], case.sample(20 * N_NEAR, rng)])
        near_base = near_base[keep][:N_NEAR]
    sig = np.where(rng.random((N_NEAR, 1)) < 0.5, 0.01, 0.1) * scale
    near = near_base + sig * rng.normal(size=near_base.shape)
    query = np.concatenate([uniform, near])
    return Data(
        surface=surface,
        tree=tree,
        cover=cover,
        scale=scale,
        lo=lo,
        hi=hi,
        query=query,
        d_brute=tree.query(query)[0],
        inside=np.asarray(case.inside(query), dtype=bool),
        ref=np.asarray(case.ref(query), dtype=float),
    )


@pytest.fixture(scope="module")
def shape(case: Case):
    csdf = pytest.importorskip("csdf")
    return case.make(csdf)


def _eval(shape, pts: np.ndarray) -> np.ndarray:
    out = np.asarray(shape(np.ascontiguousarray(pts, dtype=float)), dtype=float)
    assert out.shape == (pts.shape[0],), f"expected shape {(pts.shape[0],)}, got {out.shape}"
    return out


def _worst(pts, got, want, bad, k=3) -> str:
    err = np.abs(got - want)
    idx = np.flatnonzero(bad)
    idx = idx[np.argsort(-err[idx])][:k]
    lines = [f"{bad.sum()} / {bad.size} points off; worst:"]
    for i in idx:
        lines.append(f"  p={np.array2string(pts[i], precision=6)}  expected={want[i]:.9g}"
                     f"  got={got[i]:.9g}")
    return "\n".join(lines)


def _central_gradient(fun, pts: np.ndarray, eps: float) -> np.ndarray:
    dim = pts.shape[1]
    shifts = np.eye(dim) * eps
    stacked = np.concatenate([pts + s for s in shifts] + [pts - s for s in shifts])
    vals = fun(stacked).reshape(2, dim, pts.shape[0])
    return ((vals[0] - vals[1]) / (2 * eps)).T


# --------------------------------------------------------------------------
# reference self-checks (do not need the library)
# --------------------------------------------------------------------------


def test_reference_inside_agrees_with_sign(case: Case, data: Data):
    """The closed-form reference and the independent inside test agree."""
    clear = np.abs(data.ref) > 1e-12 * data.scale
    bad = clear & ((data.ref <= 0) != data.inside)
    assert not bad.any(), _worst(data.query, data.ref, data.inside.astype(float), bad)


def test_reference_matches_brute_force(case: Case, data: Data):
    """Reference value vs. distance to the sampled boundary (exact cases), or the
    bound property |ref| <= distance (bound cases)."""
    tol = 2 * data.cover
    eps = 1e-9 * data.scale
    if case.exactness == "exact":
        ref_abs = np.abs(data.ref)
        bad = (ref_abs > data.d_brute + eps) | (ref_abs < data.d_brute - tol)
        want = np.where(data.inside, -data.d_brute, data.d_brute)
        assert not bad.any(), f"tol={tol:.3g}\n" + _worst(data.query, data.ref, want, bad)
    else:
        bad = np.abs(data.ref) > data.d_brute + eps
        assert not bad.any(), _worst(data.query, data.ref, data.d_brute, bad)
        if case.exact_ref is not None:
            exact = case.exact_ref(data.query)
            bad = (np.abs(exact) > data.d_brute + eps) | (np.abs(exact) < data.d_brute - tol)
            assert not bad.any(), _worst(data.query, exact, data.d_brute, bad)


# --------------------------------------------------------------------------
# library tests
# --------------------------------------------------------------------------


def test_exactness_label(case: Case, shape):
    assert shape.exactness == case.exactness
    assert isinstance(shape.lipschitz, float)


def test_values_match_reference(case: Case, data: Data, shape):
    got = _eval(shape, data.query)
    bad = ~(np.abs(got - data.ref) <= VALUE_RTOL * data.scale)
    assert not bad.any(), _worst(data.query, got, data.ref, bad)


def test_brute_force_distance(case: Case, data: Data, shape):
    """Exact: f == +-(distance to the sampled boundary) within the sampling
    tolerance (never beyond it on the far side).  Bound: sign and |f| <= distance."""
    got = _eval(shape, data.query)
    eps = 1e-9 * data.scale
    tol = 2 * data.cover
    sign_bad = (np.abs(got) > eps) & ((got < 0) != data.inside)
    want = np.where(data.inside, -data.d_brute, data.d_brute)
    assert not sign_bad.any(), "sign vs inside test: " + _worst(data.query, got, want, sign_bad)
    got_abs = np.abs(got)
    if case.exactness == "exact":
        bad = (got_abs > data.d_brute + eps) | (got_abs < data.d_brute - tol)
        assert not bad.any(), f"tol={tol:.3g}\n" + _worst(data.query, got, want, bad)
    else:
        bad = got_abs > data.d_brute + eps
        assert not bad.any(), "bound exceeds distance: " + _worst(data.query, got, want, bad)
        if case.exact_ref is not None:
            exact = case.exact_ref(data.query)
            bad = got_abs > np.abs(exact) + eps
            assert not bad.any(), "bound exceeds exact distance: " + _worst(
                data.query, got, exact, bad
            )


def test_gradient_and_lipschitz(case: Case, data: Data, shape):
    rng = np.random.default_rng(_seed(case.id + "grad"))
    pts = data.lo + (data.hi - data.lo) * rng.random((N_GRAD, case.dim))
    eps = 1e-6 * data.scale
    g = np.linalg.norm(_central_gradient(lambda q: _eval(shape, q), pts, eps), axis=1)
    assert g.max() <= shape.lipschitz * (1 + 1e-4) + 1e-6, (
        f"empirical Lipschitz {g.max():.6g} > declared {shape.lipschitz}"
    )
    if case.exactness == "exact":
        bad = np.abs(g - 1.0) > GRAD_TOL
        assert bad.mean() <= GRAD_BAD_FRACTION, (
            f"|grad| != 1 at {bad.sum()} / {bad.size} points; e.g. "
            + _worst(pts, g, np.ones_like(g), bad)
        )


@pytest.mark.parametrize("case", [c for c in CASES if c.dim == 2], indirect=True,
                         ids=[c.id for c in CASES if c.dim == 2])
def test_2d_input_forms(case: Case, data: Data, shape):
    rng = np.random.default_rng(_seed(case.id + "2d"))
    q2 = data.query
    got2 = _eval(shape, q2)
    for z in (np.zeros(q2.shape[0]), rng.uniform(-5, 5, q2.shape[0])):
        got3 = _eval(shape, np.column_stack([q2, z]))
        bad = ~(np.abs(got3 - got2) <= 1e-12 * data.scale)
        assert not bad.any(), "(N,3) input differs from (N,2): " + _worst(q2, got3, got2, bad)


def test_extrude_of_bound_is_not_exact():
    csdf = pytest.importorskip("csdf")
    assert csdf.extrude(csdf.ellipse((1.0, 0.5)), 1.0).exactness != "exact"
    assert csdf.extrude(csdf.circle(1.0), 1.0).exactness == "exact"
    assert csdf.revolve(csdf.circle(0.2), offset=1.0).exactness == "exact"
