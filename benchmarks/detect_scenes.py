"""Seeded synthetic test scenes with ground truth, for the detection benchmark.

Two scene generators (``benchmarks/bench_detect.py`` imports them with ``benchmarks/`` on
``sys.path``)::

    from detect_scenes import primitive_scene, clutter_scene

* :func:`primitive_scene`: separate primitives (a plane patch, spheres, cylinders,
  cones, tori, boxes) in about a 1 m cube, sampled uniformly by area on their full
  surfaces, with per-point labels and the analytic parameters of every primitive
  (primitive detection / RANSAC-style fitting).
* :func:`clutter_scene`: zoo furniture standing on a floor, with a few non-zoo
  distractors, seen by one simulated depth camera (:func:`csdf.scan`): points in the
  camera frame with instance ids, and each object's model, parameters and
  object-to-camera pose (6D pose estimation / instance detection).

Everything is in metres and radians. All randomness comes from one
``numpy.random.default_rng(seed)``, so equal seeds give identical scenes.

Speed: csdf compiles one evaluation kernel per distinct program, and a shape whose
sizes are numeric constants is a new program for every new size (a fraction of a second
each). The solids are therefore sampled and placed as shapes whose sizes are
*parameters* (one program per kind, made once per process) with the sizes passed as
parameter values; only the ``shape`` returned in the truth carries its sizes as
constants (it is built, not compiled, here).

Run ``python benchmarks/detect_scenes.py`` for a summary of seed 0 of each and a
picture in ``/tmp/detect_scene_0.png``.
"""

from __future__ import annotations

import math
import time
from functools import cache
from typing import Any

import numpy as np

import csdf

__all__ = ["primitive_scene", "clutter_scene", "CLUTTER_MODELS", "param_solid"]

#: the zoo models :func:`clutter_scene` draws from by default
CLUTTER_MODELS: tuple[str, ...] = ("chair", "table", "stool", "lamp", "bookshelf")

# ----------------------------------------------------------------------------- settings
_CUBE = 0.5             # primitive scene: bounding spheres inside [-_CUBE, _CUBE]^3 (m)
_GAP = 0.02             # primitive scene: least clearance between bounding volumes (m)
_CLUTTER_AREA = 1.25    # clutter scene: footprint centres in [-a, a]^2 (m)
_FOOTPRINT_GAP = (0.03, 0.35)  # clutter scene: clearance between neighbour footprints (m)
_FLOOR_SIZE = (6.0, 6.0, 0.05)  # floor slab (m); its top face is z = 0
_FOV = 60.0             # clutter camera: a first vertical field of view (degrees) ...
_FOV_RANGE = (30.0, 75.0)  # ... then the one that frames all objects, within these
_FOV_MARGIN = 1.1       # ... with this margin on the tangent of the half angle
_MIN_VISIBLE_320 = 300  # least scan points per object at 320 x 240 (scaled with pixels)


# ----------------------------------------------------------------------------- helpers
def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A rotation matrix ``(3, 3)`` uniform on SO(3) (normalised Gaussian quaternion)."""
    q = rng.normal(size=4)
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def _yaw(angle: float) -> np.ndarray:
    """``(3, 3)`` rotation by ``angle`` radians about world +z."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _split(total: int, weights: np.ndarray) -> np.ndarray:
    """Integer counts ``(K,)`` proportional to ``weights`` ``(K,)`` summing to ``total``
    (largest remainders; deterministic)."""
    exact = total * weights / weights.sum()
    counts = np.floor(exact).astype(np.int64)
    short = total - int(counts.sum())
    if short > 0:
        counts[np.argsort(-(exact - counts), kind="stable")[:short]] += 1
    return counts


def _diameter(points: np.ndarray) -> float:
    """:func:`csdf.metrics.diameter` of ``points`` ``(N, 3)`` (m), exactly, after
    dropping points that cannot be in the farthest pair.

    For any centre ``c`` with ``rmax`` the largest ``|p - c|``, and ``d0`` any pair
    distance (a lower bound of the diameter ``D``), both points ``p, q`` of the farthest
    pair have ``|p - c| >= D - |q - c| >= d0 - rmax``. Points failing this for any of
    three centres (centroid, box centre, middle of the best pair found) are dropped
    before csdf's exact computation (convex hull, then pairwise distances), which is
    slow on models whose hull has thousands of vertices (the lamp: ~0.35 s).
    """
    c = points.mean(axis=0)
    r = np.linalg.norm(points - c, axis=1)
    a = points[int(np.argmax(r))]
    d0, mid = 0.0, c
    for _ in range(3):  # a few farthest-point hops: a good lower bound
        da = np.linalg.norm(points - a, axis=1)
        j = int(np.argmax(da))
        if da[j] > d0:
            d0, mid = float(da[j]), 0.5 * (a + points[j])
        a = points[j]
    keep = np.ones(len(points), dtype=bool)
    for centre in (c, 0.5 * (points.min(axis=0) + points.max(axis=0)), mid):
        rr = np.linalg.norm(points - centre, axis=1)
        keep &= rr >= d0 - float(rr.max()) - 1e-12
    return float(csdf.metrics.diameter(points[keep]))


def _point_to_rectangle(p: np.ndarray, centre: np.ndarray, u: np.ndarray, v: np.ndarray,
                        half: tuple[float, float]) -> float:
    """Distance (m) from point ``p`` ``(3,)`` to the filled rectangle ``centre + a u + b v``,
    ``|a| <= half[0]``, ``|b| <= half[1]`` (``u``, ``v`` orthonormal ``(3,)``)."""
    d = p - centre
    a = float(np.clip(d @ u, -half[0], half[0]))
    b = float(np.clip(d @ v, -half[1], half[1]))
    return float(np.linalg.norm(d - a * u - b * v))


@cache
def param_solid(kind: str) -> csdf.Shape:
    """The primitive of ``kind`` in its own frame with its sizes as parameters (metres):
    one compiled program per kind, whatever the sizes.

    Parameters: sphere ``r``; cylinder ``r``, ``h`` (axis z, centred); cone ``r``, ``h``
    (base disk at z = 0, apex at z = h); torus ``R``, ``r`` (axis z); box ``sx``, ``sy``,
    ``sz`` (full sides).
    """
    def p(name: str) -> Any:
        return csdf.param(name, 0.1, 0.0, 2.0)

    if kind == "sphere":
        return csdf.sphere(p("r"))
    if kind == "cylinder":
        return csdf.cylinder(p("r"), p("h"))
    if kind == "cone":
        return csdf.cone(p("r"), p("h"))
    if kind == "torus":
        return csdf.torus(p("R"), p("r"))
    if kind == "box":
        return csdf.box((p("sx"), p("sy"), p("sz")))
    raise ValueError(f"unknown solid kind {kind!r}")


@cache
def _floor_shape() -> csdf.Shape:
    """The floor slab, centred at the origin (its pose puts the top face at z = 0)."""
    return csdf.box(_FLOOR_SIZE)


# ----------------------------------------------------------------------------- primitives
_SOLID_KINDS = ("sphere", "cylinder", "cone", "torus", "box")


def _draw_solid(kind: str, rng: np.random.Generator) -> dict[str, Any]:
    """Random sizes of one solid, in its own frame.

    Returns:
        ``{'kind', 'values': parameter values of :func:`param_solid` (m), 'area': surface
        area (m^2), 'bcentre': (3,) centre of a bounding sphere in the solid's frame (m),
        'bradius': its radius (m)}``.
    """
    if kind == "sphere":
        r = rng.uniform(0.04, 0.15)
        return {"kind": kind, "values": {"r": r}, "area": 4 * math.pi * r * r,
                "bcentre": np.zeros(3), "bradius": r}
    if kind == "cylinder":
        r, h = rng.uniform(0.04, 0.15), rng.uniform(0.08, 0.30)
        return {"kind": kind, "values": {"r": r, "h": h},
                "area": 2 * math.pi * r * h + 2 * math.pi * r * r,
                "bcentre": np.zeros(3), "bradius": math.hypot(r, h / 2)}
    if kind == "cone":
        angle = math.radians(rng.uniform(15.0, 45.0))
        r = rng.uniform(0.04, min(0.15, 0.30 * math.tan(angle)))  # height at most 0.3 m
        h = r / math.tan(angle)
        z0 = (h * h - r * r) / (2 * h)  # centre of the sphere through apex and base rim
        bc, br = ((0.0, 0.0, z0), h - z0) if z0 >= 0 else ((0.0, 0.0, 0.0), r)
        return {"kind": kind, "values": {"r": r, "h": h}, "angle": angle,
                "area": math.pi * r * r + math.pi * r * math.hypot(r, h),
                "bcentre": np.array(bc), "bradius": br}
    if kind == "torus":
        big, small = rng.uniform(0.08, 0.15), rng.uniform(0.02, 0.05)
        return {"kind": kind, "values": {"R": big, "r": small},
                "area": 4 * math.pi ** 2 * big * small,
                "bcentre": np.zeros(3), "bradius": big + small}
    if kind == "box":
        s = rng.uniform(0.08, 0.30, 3)
        return {"kind": kind, "values": {"sx": s[0], "sy": s[1], "sz": s[2]},
                "area": 2 * (s[0] * s[1] + s[1] * s[2] + s[0] * s[2]),
                "bcentre": np.zeros(3), "bradius": 0.5 * float(np.linalg.norm(s))}
    raise ValueError(f"unknown solid kind {kind!r}")


def _solid_truth(d: dict[str, Any], R: np.ndarray, t: np.ndarray) -> dict[str, Any]:
    """The truth record of a solid of :func:`_draw_solid` posed by ``x -> R x + t``."""
    kind, v = d["kind"], d["values"]
    z = R[:, 2]
    if kind == "sphere":
        params = {"center": t.tolist(), "radius": v["r"]}
        shape = csdf.sphere(v["r"])
    elif kind == "cylinder":
        params = {"center": t.tolist(), "axis": z.tolist(), "radius": v["r"],
                  "height": v["h"]}
        shape = csdf.cylinder(v["r"], v["h"])
    elif kind == "cone":  # local apex (0, 0, h); the axis runs apex -> base: R (-z)
        apex = R @ np.array([0.0, 0.0, v["h"]]) + t
        params = {"apex": apex.tolist(), "axis": (-z).tolist(), "angle": d["angle"],
                  "height": v["h"]}
        shape = csdf.cone(v["r"], v["h"])
    elif kind == "torus":
        params = {"center": t.tolist(), "axis": z.tolist(), "major": v["R"],
                  "minor": v["r"]}
        shape = csdf.torus(v["R"], v["r"])
    else:  # box
        size = [v["sx"], v["sy"], v["sz"]]
        params = {"center": t.tolist(), "rotation": R.tolist(), "size": size}
        shape = csdf.box(tuple(size))
    params = {k: (float(x) if isinstance(x, (float, np.floating)) else x)
              for k, x in params.items()}
    return {"kind": kind, "params": params, "shape": shape.rotate(R).translate(tuple(t)),
            "frame": {"rotation": R.tolist(), "translation": [float(x) for x in t],
                      "values": {k: float(x) for k, x in v.items()}}}


def primitive_scene(seed: int, n_points: int = 40_000, noise: float = 0.001) -> dict:
    """Separate primitives in about a 1 m cube, sampled uniformly on their surfaces.

    The scene holds one plane patch (a rectangle 0.6-1.0 m a side with a random normal,
    through a point within 0.15 m of the origin) and one or two each of sphere,
    cylinder (capped: the caps belong to it), cone (solid: base disk plus lateral
    surface), torus and box, each with random sizes (radii 4-15 cm, cylinder heights
    8-30 cm, box sides 8-30 cm, torus major radius 8-15 cm and minor 2-5 cm, cone half
    angle 15-45 degrees and height at most 30 cm), a rotation uniform on SO(3) and a
    position such that its bounding sphere lies inside ``[-0.5, 0.5]^3`` m and keeps
    2 cm from every other bounding sphere and from the plane rectangle. The layout is
    redrawn (same generator) until everything fits.

    Points: the whole surface of every solid (:func:`csdf.sample_surface` in the solid's
    frame, then posed) and of the rectangle (uniform, NumPy), with counts proportional
    to area (equal density everywhere, largest-remainder rounding) summing to
    ``n_points``; then Gaussian noise of standard deviation ``noise`` **along the true
    normal** of each point, and the points shuffled.

    Args:
        seed: seed of ``numpy.random.default_rng``; equal seeds give identical scenes.
        n_points: total number of points.
        noise: standard deviation of the noise along the normals (m); 0 for none.

    Returns:
        A dict:

        * ``'points'``: ``(N, 3)`` float64, metres (``N = n_points``).
        * ``'normals'``: ``(N, 3)`` float64 unit true outward normals (of the noise-free
          surface point; the plane's is its ``normal``).
        * ``'labels'``: ``(N,)`` int64, the index in ``truth`` of each point's primitive.
        * ``'truth'``: list of dicts ``{'kind', 'params', 'shape'}``, the plane first;
          ``shape`` is the posed csdf shape (the plane: ``csdf.plane(normal, offset)``,
          the half-space ``n . p <= offset``); a solid's ``'frame'`` holds its pose
          (``rotation`` 3x3, ``translation`` (3)) and the values of the parameters
          of :func:`param_solid` that make ``shape``. ``params`` (floats and lists of
          floats):

          - plane: ``normal`` (3, unit), ``offset`` (``n . p = offset`` on it); the plane
            record also has ``'patch': {'center' (3), 'u' (3), 'v' (3), 'size' [su, sv]}``,
            the rectangle ``center + a u + b v``, ``|a| <= su/2``, ``|b| <= sv/2``;
          - sphere: ``center`` (3), ``radius``;
          - cylinder: ``center`` (3, middle of the axis), ``axis`` (3, unit),
            ``radius``, ``height``;
          - cone: ``apex`` (3), ``axis`` (3, unit, from the apex into the cone),
            ``angle`` (half angle, rad), ``height`` (apex to base along the axis; the
            base radius is ``height * tan(angle)``);
          - torus: ``center`` (3), ``axis`` (3, unit), ``major``, ``minor``;
          - box: ``center`` (3), ``rotation`` (3x3 nested list; its columns are the
            box's axes in the scene), ``size`` (3 full side lengths along them).

        * ``'noise'``: ``noise``; ``'seed'``: ``seed``.
    """
    rng = np.random.default_rng(seed)
    n_points = int(n_points)
    if n_points < 0:
        raise ValueError(f"n_points must be >= 0, got {n_points}")
    if not noise >= 0:
        raise ValueError(f"noise must be >= 0, got {noise}")

    # ---- layout (redrawn until every solid fits)
    while True:
        normal = rng.normal(size=3)
        normal /= np.linalg.norm(normal)
        helper = np.eye(3)[int(np.argmin(np.abs(normal)))]
        u = np.cross(normal, helper)
        u /= np.linalg.norm(u)
        v = np.cross(normal, u)
        turn = rng.uniform(0.0, 2 * math.pi)
        u, v = math.cos(turn) * u + math.sin(turn) * v, -math.sin(turn) * u + math.cos(turn) * v
        p_centre = rng.uniform(-0.15, 0.15, 3)
        p_size = rng.uniform(0.6, 1.0, 2)
        half = (p_size[0] / 2, p_size[1] / 2)

        solids = [_draw_solid(kind, rng) for kind in _SOLID_KINDS
                  for _ in range(int(rng.integers(1, 3)))]
        placed: list[tuple[dict[str, Any], np.ndarray, np.ndarray, np.ndarray]] = []
        for d in solids:
            R = _random_rotation(rng)
            rad = d["bradius"]
            if rad > _CUBE - 0.01:
                break
            for _ in range(300):
                c = rng.uniform(-_CUBE + rad, _CUBE - rad, 3)  # bounding-sphere centre
                if _point_to_rectangle(c, p_centre, u, v, half) < rad + _GAP:
                    continue
                if any(np.linalg.norm(c - c2) < rad + d2["bradius"] + _GAP
                       for d2, _, _, c2 in placed):
                    continue
                placed.append((d, R, c - R @ d["bcentre"], c))
                break
            else:
                break
        if len(placed) == len(solids):
            break

    # ---- points
    areas = np.array([p_size[0] * p_size[1]] + [d["area"] for d in solids])
    counts = _split(n_points, areas)
    offset = float(normal @ p_centre)
    truth: list[dict[str, Any]] = [{
        "kind": "plane", "params": {"normal": normal.tolist(), "offset": offset},
        "shape": csdf.plane(tuple(normal), offset),
        "patch": {"center": p_centre.tolist(), "u": u.tolist(), "v": v.tolist(),
                  "size": p_size.tolist()},
    }]
    k0 = int(counts[0])
    ab = rng.uniform(-0.5, 0.5, (k0, 2)) * p_size
    pts = [p_centre + ab[:, :1] * u + ab[:, 1:] * v]
    nrm = [np.tile(normal, (k0, 1))]
    for (d, R, t, _), k in zip(placed, counts[1:]):
        q, m = csdf.sample_surface(param_solid(d["kind"]), int(k), seed=rng,
                                   params=d["values"])
        pts.append(q @ R.T + t)
        nrm.append(m @ R.T)
        truth.append(_solid_truth(d, R, t))
    points = np.concatenate(pts)
    normals = np.concatenate(nrm)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    labels = np.repeat(np.arange(len(truth), dtype=np.int64), counts)
    if noise > 0:
        points = points + rng.normal(0.0, noise, (len(points), 1)) * normals
    order = rng.permutation(len(points))
    return {"points": points[order], "normals": normals[order], "labels": labels[order],
            "truth": truth, "noise": float(noise), "seed": seed}


# ----------------------------------------------------------------------------- clutter
def _distractor(kind: str, rng: np.random.Generator) -> dict[str, Any]:
    """Random sizes (largest dimension 0.1-0.3 m) of a non-zoo distractor resting on the
    floor: ``{'kind', 'values': parameter values of :func:`param_solid`, 'z': height
    of its origin above the floor (m), 'radius': its footprint radius about its origin
    (m), 'corner': (3,) half extents of its local box (m)}``. Spheres, upright
    cylinders, boxes standing on a face, tori lying flat."""
    s = rng.uniform(0.1, 0.3)
    if kind == "sphere":
        r = s / 2
        return {"kind": kind, "values": {"r": r}, "z": r, "radius": r,
                "corner": np.array([r, r, r])}
    if kind == "box":
        sides = s * np.array([1.0, rng.uniform(0.4, 1.0), rng.uniform(0.4, 1.0)])
        sides = sides[rng.permutation(3)]
        return {"kind": kind, "values": dict(zip(("sx", "sy", "sz"), sides.tolist())),
                "z": sides[2] / 2, "radius": 0.5 * math.hypot(sides[0], sides[1]),
                "corner": sides / 2}
    if kind == "torus":
        minor = s / 2 * rng.uniform(0.2, 0.35)
        major = s / 2 - minor
        return {"kind": kind, "values": {"R": major, "r": minor}, "z": minor,
                "radius": s / 2, "corner": np.array([s / 2, s / 2, minor])}
    if kind == "cylinder":
        if rng.random() < 0.5:
            r, h = s / 2, s * rng.uniform(0.4, 1.0)
        else:
            r, h = s / 2 * rng.uniform(0.4, 1.0), s
        return {"kind": kind, "values": {"r": r, "h": h}, "z": h / 2, "radius": r,
                "corner": np.array([r, r, h / 2])}
    raise ValueError(f"unknown distractor kind {kind!r}")


def _middle_params(name: str, rng: np.random.Generator) -> dict[str, float]:
    """Parameter values of zoo model ``name``, each uniform in the middle 60 % of its
    declared range."""
    out = {}
    for prm, _doc in csdf.zoo.info(name).params:
        lo, hi = float(prm.lo), float(prm.hi)
        out[prm.name] = float(lo + (hi - lo) * rng.uniform(0.2, 0.8))
    return out


def _place(radii: list[float], rng: np.random.Generator, tries: int = 200
           ) -> np.ndarray | None:
    """Footprint-circle centres ``(K, 2)`` (m) for circles of ``radii``: the first
    near the middle, each next one beside a random earlier one at a clearance in
    ``_FOOTPRINT_GAP``, all centres in the clutter area and no two circles closer than
    the least clearance; None when one does not fit."""
    centres: list[np.ndarray] = []
    lo_gap, hi_gap = _FOOTPRINT_GAP
    for i, r in enumerate(radii):
        if i == 0:
            centres.append(rng.uniform(-0.3, 0.3, 2))
            continue
        for _ in range(tries):
            j = int(rng.integers(i))
            th = rng.uniform(0.0, 2 * math.pi)
            c = centres[j] + (r + radii[j] + rng.uniform(lo_gap, hi_gap)) * np.array(
                [math.cos(th), math.sin(th)])
            if np.abs(c).max() > _CLUTTER_AREA:
                continue
            if all(np.linalg.norm(c - c2) >= r + r2 + lo_gap
                   for c2, r2 in zip(centres, radii)):
                centres.append(c)
                break
        else:
            return None
    return np.array(centres)


def clutter_scene(seed: int, models: tuple[str, ...] = CLUTTER_MODELS,
                  n_objects: tuple[int, int] = (3, 5), n_distractors: int = 2,
                  width: int = 320, height: int = 240, noise_fraction: float = 0.005,
                  outliers: float = 0.01, min_visible: int | None = None) -> dict:
    """A cluttered single-view depth scan of zoo furniture on a floor.

    The scene (a :class:`csdf.Scene`, world frame z up, metres): a floor slab of
    6 x 6 x 0.05 m whose top face is z = 0, centred under the objects; between
    ``n_objects[0]`` and ``n_objects[1]`` zoo objects drawn from ``models`` (repeats
    allowed), upright on the floor with a random yaw, every parameter uniform in the
    middle 60 % of its declared range; and ``n_distractors`` shapes that are not in the
    zoo (kinds drawn without repeats while there are kinds left: sphere, box standing
    on a face, torus lying flat, upright cylinder; largest dimension 0.1-0.3 m) resting
    on the floor with a random yaw. Footprints (the bounding circles of the objects'
    mesh vertices and of the distractors) do not overlap: each is placed 3-35 cm from a
    random earlier one, centres within a 2.5 x 2.5 m square, so neighbours occlude
    each other from most viewpoints.

    The camera (:meth:`csdf.Camera.look_at`, world +z up the image) stands at a random
    azimuth 2.8-3.2 m from a target 0.4 m above the middle of the objects' box,
    1.5-2.0 m above the floor, looking down at it; its vertical field of view is the
    one that just frames the world boxes of all objects and distractors (10 % margin on
    the tangent), clamped to 30-75 degrees (so objects fill the image, and at 75
    degrees some may be cut by its border). The scene is scanned by :func:`csdf.scan`
    with range noise (along each ray) of standard deviation
    ``noise = noise_fraction * scene_size`` where **scene_size is the diagonal of the
    axis-aligned world box holding all objects and distractors (not the floor)**, and
    an ``outliers`` fraction of outliers (uniform in the view frustum). Viewpoints (up
    to 8) and then placements are redrawn with the same generator until every object
    has at least ``min_visible`` scan points.

    Args:
        seed: seed of ``numpy.random.default_rng``; equal seeds give identical scenes.
        models: zoo model names to draw the objects from.
        n_objects: ``(least, most)`` number of zoo objects (inclusive).
        n_distractors: number of non-zoo shapes.
        width, height: sensor resolution (pixels).
        noise_fraction: range-noise standard deviation relative to the scene size.
        outliers: fraction of scan points replaced by outliers (see :func:`csdf.scan`).
        min_visible: least scan points per object (default 300 at 320 x 240, scaled with
            the number of pixels, at least 20).

    Returns:
        A dict:

        * ``'points'``: ``(M, 3)`` float64 scan points in the **camera frame** (OpenCV:
          x right, y down, z forward; metres), row-major pixel order.
        * ``'normals'``: ``(M, 3)`` unit normals (camera frame), facing the camera.
        * ``'instance'``: ``(M,)`` int64 scene instance id of each point (-1 outliers).
        * ``'camera'``: the :class:`csdf.Camera` (its pose is camera-to-world).
        * ``'scene'``: the :class:`csdf.Scene` (world frame).
        * ``'truth'``: one dict per zoo object: ``'model'`` (zoo name), ``'pose'``
          (rigid :class:`csdf.Pose`, object (model) frame to **camera** frame),
          ``'params'`` ``{name: value}``, ``'instance'`` (scene id), ``'diameter'``
          (m, :func:`csdf.metrics.diameter` of :func:`csdf.metrics.model_points`),
          ``'symmetries'`` (``(K, 4, 4)`` from :func:`csdf.metrics.symmetries`, model
          frame; None where it failed), ``'visible_points'`` (scan
          points with its id), ``'world_pose'`` (object to world).
        * ``'distractors'``: one dict per distractor: ``'kind'``, ``'pose'`` (object to
          camera; the shape's own frame: centred, axis z), ``'instance'``, ``'params'``
          (sizes in m: sphere ``radius``; box ``size`` [3]; torus ``major``, ``minor``;
          cylinder ``radius``, ``height``), ``'visible_points'``.
        * ``'floor_instance'``: the floor's scene id.
        * ``'noise'``: range-noise standard deviation (m); ``'scene_size'`` (m).
        * ``'viewpoint'``: ``[0, 0, 0]``, the sensor origin in the camera frame.
    """
    rng = np.random.default_rng(seed)
    lo_n, hi_n = int(n_objects[0]), int(n_objects[1])
    if not 1 <= lo_n <= hi_n:
        raise ValueError(f"n_objects must be (least, most) with 1 <= least <= most, "
                         f"got {n_objects}")
    if not models:
        raise ValueError("models must name at least one zoo model")
    if min_visible is None:
        min_visible = max(20, round(_MIN_VISIBLE_320 * width * height / (320 * 240)))
    min_distractor = max(5, min_visible // 10)
    kinds = ("sphere", "box", "torus", "cylinder")
    base_shapes: dict[str, Any] = {}

    for _attempt in range(50):
        # ---- what: objects and distractors with their sizes, footprints in own frames
        objects = []
        for _ in range(int(rng.integers(lo_n, hi_n + 1))):
            name = models[int(rng.integers(len(models)))]
            if name not in base_shapes:
                base_shapes[name] = csdf.zoo.load(name)
            params = _middle_params(name, rng)
            pts = csdf.metrics.model_points(base_shapes[name], params=params)
            lo, hi = pts.min(0), pts.max(0)
            mid = 0.5 * (lo[:2] + hi[:2])
            rad = float(np.linalg.norm(pts[:, :2] - mid, axis=1).max())
            objects.append({"model": name, "params": params, "points": pts,
                            "mid": mid, "radius": rad, "yaw": rng.uniform(0, 2 * math.pi)})
        picks: list[str] = []
        while len(picks) < n_distractors:
            picks += [kinds[i] for i in rng.permutation(len(kinds))]
        distractors = [_distractor(k, rng) for k in picks[:n_distractors]]
        for d in distractors:
            d["yaw"] = rng.uniform(0, 2 * math.pi)

        # ---- where: footprint centres (objects first, then distractors at the edges)
        centres = _place([o["radius"] for o in objects] + [d["radius"] for d in distractors],
                         rng)
        if centres is None:
            continue
        boxes = []
        for o, c in zip(objects, centres):
            Rz = _yaw(o["yaw"])
            t = np.array([*(c - Rz[:2, :2] @ o["mid"]), 0.0])
            o["world_pose"] = csdf.Pose(Rz, t)
            w = o["world_pose"].apply(o["points"])
            boxes.append(np.array([w.min(0), w.max(0)]))
        for d, c in zip(distractors, centres[len(objects):]):
            Rz = _yaw(d["yaw"])
            d["world_pose"] = csdf.Pose(Rz, (c[0], c[1], d["z"]))
            boxes.append(d["world_pose"].apply_box(np.array([-d["corner"], d["corner"]])))
        allb = np.array(boxes)
        lo3, hi3 = allb[:, 0].min(0), allb[:, 1].max(0)
        scene_size = float(np.linalg.norm(hi3 - lo3))
        noise = noise_fraction * scene_size
        middle = 0.5 * (centres.min(0) + centres.max(0))

        # ---- the scene
        scene = csdf.Scene()
        floor_id = scene.add(_floor_shape(), csdf.Pose(
            translation=(middle[0], middle[1], -_FLOOR_SIZE[2] / 2)), name="floor")
        for i, o in enumerate(objects):
            o["instance"] = scene.add(o["model"], o["world_pose"], params=o["params"],
                                      name=f"{o['model']}_{i}")
        for i, d in enumerate(distractors):
            d["instance"] = scene.add(param_solid(d["kind"]), d["world_pose"],
                                      params=d["values"], name=f"distractor_{d['kind']}_{i}")

        # ---- the view: the field of view frames every object's and distractor's box
        target = np.array([*(0.5 * (lo3[:2] + hi3[:2])), 0.4])
        corners = np.array([[b[i, 0], b[j, 1], b[k, 2]] for b in allb
                            for i in (0, 1) for j in (0, 1) for k in (0, 1)])
        # views are judged on a quick noise-free scan at half the resolution (a quarter
        # of the rays): the first whose objects all look visible enough and whose
        # distractors show too, or from the fourth view on the first whose objects do
        qw, qh = max(16, width // 2), max(12, height // 2)
        ratio = width * height / (qw * qh)
        chosen, fallback = None, None
        for _view in range(8):
            az = rng.uniform(0, 2 * math.pi)
            dist = rng.uniform(2.8, 3.2)
            eye_z = rng.uniform(1.5, 2.0)
            horiz = math.sqrt(max(dist ** 2 - (eye_z - target[2]) ** 2, 0.25))
            eye = target + np.array([horiz * math.cos(az), horiz * math.sin(az), 0.0])
            eye[2] = eye_z
            probe = csdf.Camera.look_at(eye, target, up=(0.0, 0.0, 1.0), fov=_FOV,
                                        width=width, height=height)
            q = probe.world_to_camera(corners)
            if q[:, 2].min() < 0.3:
                continue
            need = max(np.abs(q[:, 1] / q[:, 2]).max(),
                       np.abs(q[:, 0] / q[:, 2]).max() * height / width) * _FOV_MARGIN
            fov = float(np.clip(2 * math.degrees(math.atan(need)), *_FOV_RANGE))
            cam = csdf.Camera.look_at(eye, target, up=(0.0, 0.0, 1.0), fov=fov,
                                      width=width, height=height)
            ids = csdf.scan(scene, cam, width=qw, height=qh)[2]
            if min(np.count_nonzero(ids == o["instance"]) for o in objects) * ratio \
                    < 0.8 * min_visible:
                continue
            fallback = fallback or cam
            if _view >= 3 or not distractors or min(np.count_nonzero(ids == d["instance"])
                                      for d in distractors) * ratio >= min_distractor:
                chosen = cam
                break
        cam = chosen or fallback
        if cam is None:
            continue
        points, normals, inst = csdf.scan(scene, cam, noise=noise, outliers=outliers,
                                          seed=rng)
        seen = [int(np.count_nonzero(inst == o["instance"])) for o in objects]
        if min(seen) >= min_visible:
            break
    else:
        raise RuntimeError(f"clutter_scene(seed={seed}): no placement and view in 50 "
                           "attempts gave every object enough visible points")

    # ---- truth
    world_to_cam = csdf.Pose(cam.R, cam.t).inverse()
    truth = []
    for o, n_seen in zip(objects, seen):
        try:
            sym = csdf.metrics.symmetries(base_shapes[o["model"]], params=o["params"])
        except csdf.CsdfError:
            sym = None
        truth.append({
            "model": o["model"], "pose": world_to_cam @ o["world_pose"],
            "params": dict(o["params"]), "instance": o["instance"],
            "diameter": _diameter(o["points"]), "symmetries": sym,
            "visible_points": n_seen, "world_pose": o["world_pose"],
        })
    named = {"sphere": {"r": "radius"}, "torus": {"R": "major", "r": "minor"},
             "cylinder": {"r": "radius", "h": "height"}}
    dtruth = []
    for d in distractors:
        v = d["values"]
        if d["kind"] == "box":
            dparams: dict[str, Any] = {"size": [v["sx"], v["sy"], v["sz"]]}
        else:
            dparams = {named[d["kind"]][k]: float(x) for k, x in v.items()}
        dtruth.append({"kind": d["kind"], "pose": world_to_cam @ d["world_pose"],
                       "instance": d["instance"], "params": dparams,
                       "visible_points": int(np.count_nonzero(inst == d["instance"]))})
    return {"points": points, "normals": normals, "instance": np.asarray(inst, np.int64),
            "camera": cam, "scene": scene, "truth": truth, "distractors": dtruth,
            "floor_instance": floor_id, "noise": float(noise), "scene_size": scene_size,
            "viewpoint": [0.0, 0.0, 0.0]}


# ----------------------------------------------------------------------------- demo
def _main() -> None:
    """Build seed 0 of each scene, print a summary and save a picture."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    primitive_scene(1)  # warm-up: kernels, zoo files
    clutter_scene(1)
    t0 = time.perf_counter()
    prim = primitive_scene(0)
    t1 = time.perf_counter()
    clut = clutter_scene(0)
    t2 = time.perf_counter()
    print(f"build times after warm-up: primitive_scene(0) {t1 - t0:.2f} s, "
          f"clutter_scene(0) {t2 - t1:.2f} s")

    print(f"\nprimitive_scene(0): {len(prim['points'])} points, noise {prim['noise']:g} m "
          "(along normals)")
    for i, tr in enumerate(prim["truth"]):
        k = int(np.count_nonzero(prim["labels"] == i))
        pretty = {key: (np.round(val, 3).tolist() if isinstance(val, list) else round(val, 4))
                  for key, val in tr["params"].items() if key != "rotation"}
        print(f"  [{i}] {tr['kind']:8s} {k:6d} pts  {pretty}")

    cam = clut["camera"]
    print(f"\nclutter_scene(0): {len(clut['points'])} points, noise {clut['noise'] * 1e3:.1f} mm"
          f" (scene size {clut['scene_size']:.2f} m), camera at "
          f"{np.round(cam.t, 2).tolist()}")
    inst = clut["instance"]
    print(f"  floor (id {clut['floor_instance']}): "
          f"{int(np.count_nonzero(inst == clut['floor_instance']))} pts, outliers: "
          f"{int(np.count_nonzero(inst < 0))}")
    for tr in clut["truth"]:
        nsym = None if tr["symmetries"] is None else len(tr["symmetries"])
        print(f"  id {tr['instance']} {tr['model']:10s} {tr['visible_points']:6d} pts  "
              f"diameter {tr['diameter']:.2f} m  symmetries {nsym}  "
              f"t_cam {np.round(tr['pose'].translation, 2).tolist()}")
    for dd in clut["distractors"]:
        print(f"  id {dd['instance']} {dd['kind']:10s} {dd['visible_points']:6d} pts  "
              f"{dd['params']}")

    fig, axes = plt.subplots(1, 3, figsize=(18, 6))
    p = prim["points"]
    axes[0].scatter(p[:, 0], p[:, 1], c=prim["labels"], s=0.3, cmap="tab20")
    axes[0].set_title("primitive_scene(0): top view (x, y), colour = label")
    axes[0].set_aspect("equal")
    q = clut["points"]
    wp = cam.camera_to_world(q)
    keep = inst != clut["floor_instance"]
    axes[1].scatter(wp[~keep, 0], wp[~keep, 1], c="0.85", s=0.2)
    axes[1].scatter(wp[keep, 0], wp[keep, 1], c=inst[keep], s=0.3, cmap="tab10")
    axes[1].plot(*cam.t[:2], "k^")
    axes[1].set_title("clutter_scene(0): world top view, colour = instance")
    axes[1].set_aspect("equal")
    uv, _ = cam.project(wp)
    axes[2].scatter(uv[:, 0], uv[:, 1], c=inst, s=1.0, cmap="tab10")
    axes[2].set_xlim(0, cam.width)
    axes[2].set_ylim(cam.height, 0)
    axes[2].set_title("clutter_scene(0): camera image, colour = instance (-1 outliers)")
    axes[2].set_aspect("equal")
    fig.tight_layout()
    fig.savefig("/tmp/detect_scene_0.png", dpi=90)
    print("\nsaved /tmp/detect_scene_0.png")


if __name__ == "__main__":
    _main()
