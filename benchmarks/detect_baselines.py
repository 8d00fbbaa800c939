"""Comparison baselines for ``bench_detect.py``: Open3D model registration and CGAL's
Efficient RANSAC primitive detection.

Both functions import their library inside the call and raise
:class:`BaselineNotInstalled` (an :class:`ImportError`) naming the pip package when it
is missing, so the benchmark can report "not installed" and carry on.

* :func:`open3d_detect` finds known models (given as surface samples in their own frame)
  in a scene cloud with the pipeline of Open3D's global-registration tutorial: floor
  removal with ``segment_plane``, voxel downsampling, FPFH features, RANSAC on feature
  matches, point-to-plane ICP; several instances of a model by removing the points an
  accepted instance explains and registering again.  Requirement: ``open3d>=0.18``.
* :func:`cgal_ransac` runs CGAL's Efficient RANSAC (Schnabel, Wahl and Klein 2007)
  through the CGAL SWIG bindings (pip package ``cgal``; module ``CGAL``), which expose
  it as ``CGAL.CGAL_Shape_detection.efficient_RANSAC`` for planes, spheres, cylinders,
  cones and tori.  Requirement: ``cgal>=6.0``.

Things found about the CGAL bindings (``cgal`` 6.0.1, CGAL 6.0.1):

* ``efficient_RANSAC(point_set, int_map, min_points, epsilon, cluster_epsilon,
  normal_threshold, probability, planes, cones, cylinders, spheres, tori)`` takes a
  ``Point_set_3`` with a normal map and fills ``int_map`` with each point's shape index
  (-1: unassigned). Shapes come back only as the C++ ``Shape::info()`` text, printed at
  the default stream precision (6 significant digits), so parameters are parsed from
  text and carry a relative rounding of up to 5e-6 (about 1e-6 m for a unit-sized
  scene). The plane's text reads ``(n)x - d= 0`` but the printed number is CGAL's
  ``d`` of ``n.p + d = 0`` (checked: a plane z = 0.3 with n = +z prints ``- -0.3``).
* The random generator (``CGAL::get_default_random()``, a static ``CGAL::Random`` in
  the compiled module, seeded from the wall clock in seconds when first used) is not
  exposed: no seed can be passed, and repeated calls in one process continue one random
  stream. Results therefore vary between runs (see :func:`cgal_ransac`).
* ``detect()`` permutes the point set's internal order; the int map is indexed by the
  original insertion index, which is what is read back here.
"""

from __future__ import annotations

import re
import time
from typing import Any

import numpy as np

#: shape kinds of CGAL's Efficient RANSAC, and the bindings' keyword enabling each
CGAL_KINDS = {
    "plane": "planes",
    "sphere": "spheres",
    "cylinder": "cylinders",
    "cone": "cones",
    "torus": "tori",
}
#: pip requirement lines for the ``bench`` extra
REQUIREMENTS = {"open3d": "open3d>=0.18", "cgal": "cgal>=6.0"}


class BaselineNotInstalled(ImportError):
    """A baseline's library cannot be imported; the message names the pip package."""


def _require(module: str, package: str) -> Any:
    """Import ``module`` or raise :class:`BaselineNotInstalled` naming pip ``package``."""
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError as e:
        raise BaselineNotInstalled(
            f'{module} is not installed (pip install "{package}"): {e}'
        ) from e


# --------------------------------------------------------------------------- Open3D


def _o3d_cloud(o3d: Any, points: np.ndarray, normals: np.ndarray | None) -> Any:
    """An ``open3d.geometry.PointCloud`` of ``points (n, 3)`` and ``normals (n, 3)``."""
    pcd = o3d.geometry.PointCloud()
    pcd.points = o3d.utility.Vector3dVector(np.ascontiguousarray(points, dtype=np.float64))
    if normals is not None:
        pcd.normals = o3d.utility.Vector3dVector(
            np.ascontiguousarray(normals, dtype=np.float64)
        )
    return pcd


def _o3d_prepare(o3d: Any, pcd: Any, voxel: float) -> tuple[Any, Any]:
    """``(downsampled cloud with unit normals, its FPFH feature)`` at ``voxel`` metres.

    Normals, when the cloud has them, are the voxel averages of the given ones
    (renormalised); otherwise they are estimated from neighbours within 2 voxels
    (at most 30). FPFH uses neighbours within 5 voxels (at most 100), as in Open3D's
    global-registration tutorial.
    """
    reg = o3d.pipelines.registration
    down = pcd.voxel_down_sample(voxel)
    if down.has_normals():
        down.normalize_normals()
    else:
        down.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=2 * voxel, max_nn=30))
    fpfh = reg.compute_fpfh_feature(
        down, o3d.geometry.KDTreeSearchParamHybrid(radius=5 * voxel, max_nn=100)
    )
    return down, fpfh


def open3d_detect(
    points: np.ndarray,
    normals: np.ndarray | None,
    models: dict[str, tuple[np.ndarray, np.ndarray]],
    voxel: float,
    seed: int = 0,
    max_instances: int = 5,
    *,
    min_fitness: float = 0.3,
    remove_floor: bool = True,
    ransac_iterations: int = 100_000,
    ransac_confidence: float = 0.999,
    threads: int | None = None,
) -> list[dict]:
    """Find instances of known models in a scene cloud with Open3D's standard pipeline.

    Steps (Open3D >= 0.18, ``open3d.pipelines.registration``):

    1. ``open3d.utility.random.seed(seed)``, once per call (it seeds ``segment_plane``
       and the feature-matching RANSAC).
    2. Floor: the dominant plane of the scene (``segment_plane``, inliers within one
       voxel, 3 points per sample, 1000 iterations) is removed, as a typical user does,
       when ``remove_floor``. Without a floor this removes the largest planar face.
    3. Scene and each model cloud are voxel downsampled (``voxel`` metres); normals are
       the voxel means of the given ones, or estimated (2 voxels, 30 neighbours) when
       ``normals`` is None (then the models' normals are re-estimated too, so both
       sides have normals of the same kind); FPFH features on 5 voxels, 100 neighbours.
    4. Per model, up to ``max_instances`` times:
       ``registration_ransac_based_on_feature_matching`` (model -> remaining scene,
       mutual filter off, correspondences within 1.5 voxels, point-to-point estimation,
       3 points per sample, edge-length (0.9) and distance (1.5 voxels) checkers,
       ``RANSACConvergenceCriteria(ransac_iterations, ransac_confidence)``), then
       point-to-plane ``registration_icp`` of the full-resolution model cloud onto the
       full-resolution remaining scene, correspondences within 1 voxel, 50 iterations.
       The instance is accepted while the ICP ``fitness`` (the fraction of the model's
       points with a scene point within 1 voxel after ICP) is at least ``min_fitness``
       (default 0.3: a model seen from one side covers about half of its surface);
       the first registration below it ends that model's search. Scene points within
       2 voxels of the accepted, transformed model cloud are removed before the next
       registration of the same model. Each model starts again from the whole
       (floor-free) scene: models are searched independently, so two models may claim
       the same points.

    Determinism: the seed fixes the random stream, but Open3D's feature-matching
    RANSAC runs its iterations on several TBB threads, and which thread draws which
    sample depends on scheduling: with the default threads, the same call gave
    different poses in different processes when the CPUs were busy (seen with Open3D
    0.20 on 2 cores: 4 cm against 6 mm translation error on one scan). ``threads=1``
    makes it repeatable (at the cost of speed).

    Args:
        points: ``(n, 3)`` scene points, metres.
        normals: ``(n, 3)`` unit scene normals, or None to estimate them.
        models: name -> ``(points (m, 3), normals (m, 3))`` sampled on the model's
            surface in its own frame, metres.
        voxel: downsampling voxel size, metres (all distances above scale with it).
        seed: Open3D's global random seed.
        max_instances: the most instances returned per model.
        min_fitness: ICP fitness (0..1) an instance needs to be accepted.
        remove_floor: remove the scene's dominant plane first.
        ransac_iterations, ransac_confidence: the RANSAC stopping criteria.
        threads: if given, ``open3d.utility.set_max_threads(threads)`` for the call
            (process-wide; the previous limit is put back after).

    Returns:
        One dict per accepted instance, models in the order of ``models``, each
        model's instances in the order found: ``{'model': name, 'pose': (4, 4) float64
        model-to-scene rigid transform (metres), 'fitness': ICP fitness in [0, 1],
        'inlier_rmse': ICP inlier RMSE, metres}``.

    Raises:
        BaselineNotInstalled: open3d cannot be imported (``pip install open3d``).
    """
    o3d = _require("open3d", REQUIREMENTS["open3d"])
    if threads is None:
        return _open3d_detect(o3d, points, normals, models, voxel, seed, max_instances,
                              min_fitness, remove_floor, ransac_iterations, ransac_confidence)
    previous = o3d.utility.get_max_threads()
    o3d.utility.set_max_threads(int(threads))
    try:
        return _open3d_detect(o3d, points, normals, models, voxel, seed, max_instances,
                              min_fitness, remove_floor, ransac_iterations, ransac_confidence)
    finally:
        o3d.utility.set_max_threads(previous)


def _open3d_detect(
    o3d: Any,
    points: np.ndarray,
    normals: np.ndarray | None,
    models: dict[str, tuple[np.ndarray, np.ndarray]],
    voxel: float,
    seed: int,
    max_instances: int,
    min_fitness: float,
    remove_floor: bool,
    ransac_iterations: int,
    ransac_confidence: float,
) -> list[dict]:
    """:func:`open3d_detect` with the ``open3d`` module ``o3d`` imported."""
    reg = o3d.pipelines.registration
    o3d.utility.random.seed(int(seed))

    points = np.asarray(points, dtype=np.float64)
    scene = _o3d_cloud(o3d, points, normals)
    if normals is None:
        scene.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=2 * voxel, max_nn=30))
    if remove_floor and len(points) >= 3:
        _, floor = scene.segment_plane(
            distance_threshold=voxel, ransac_n=3, num_iterations=1000
        )
        scene = scene.select_by_index(floor, invert=True)

    checkers = [
        reg.CorrespondenceCheckerBasedOnEdgeLength(0.9),
        reg.CorrespondenceCheckerBasedOnDistance(1.5 * voxel),
    ]
    criteria = reg.RANSACConvergenceCriteria(int(ransac_iterations), float(ransac_confidence))
    icp_criteria = reg.ICPConvergenceCriteria(max_iteration=50)

    found: list[dict] = []
    for name, (m_points, m_normals) in models.items():
        model = _o3d_cloud(o3d, m_points, None if normals is None else m_normals)
        if normals is None:
            model.estimate_normals(
                o3d.geometry.KDTreeSearchParamHybrid(radius=2 * voxel, max_nn=30)
            )
        model_down, model_fpfh = _o3d_prepare(o3d, model, voxel)
        remaining = scene
        for _ in range(max_instances):
            if len(remaining.points) < 3:
                break
            remaining_down, remaining_fpfh = _o3d_prepare(o3d, remaining, voxel)
            if len(remaining_down.points) < 3:
                break
            coarse = reg.registration_ransac_based_on_feature_matching(
                model_down,
                remaining_down,
                model_fpfh,
                remaining_fpfh,
                False,
                1.5 * voxel,
                reg.TransformationEstimationPointToPoint(False),
                3,
                checkers,
                criteria,
            )
            fine = reg.registration_icp(
                model,
                remaining,
                voxel,
                coarse.transformation,
                reg.TransformationEstimationPointToPlane(),
                icp_criteria,
            )
            if fine.fitness < min_fitness:
                break
            pose = np.array(fine.transformation, dtype=np.float64)
            found.append(
                {
                    "model": name,
                    "pose": pose,
                    "fitness": float(fine.fitness),
                    "inlier_rmse": float(fine.inlier_rmse),
                }
            )
            placed = _o3d_cloud(o3d, np.asarray(model.points), None).transform(pose)
            dist = np.asarray(remaining.compute_point_cloud_distance(placed))
            remaining = remaining.select_by_index(np.flatnonzero(dist > 2 * voxel).tolist())
    return found


# ---------------------------------------------------------------------------- CGAL

_FLOAT = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?|[-+]?(?:nan|inf)")
#: numbers in each kind's info() text before "#Pts: <count>", in order
_INFO_FIELDS = {
    "plane": 4,  # normal (3), d of n.p + d = 0
    "sphere": 4,  # center (3), radius
    "cylinder": 7,  # point on axis (3), axis (3), radius
    "cone": 7,  # apex (3), axis (3), half angle
    "torus": 8,  # center (3), axis (3), major, minor
}


def _unit(v: np.ndarray) -> np.ndarray:
    """``v (3,)`` scaled to unit length (undoing the 6-digit rounding of the text)."""
    return v / np.linalg.norm(v)


def parse_cgal_info(info: str) -> tuple[str, dict[str, Any], int]:
    """``(kind, params, point count)`` from one CGAL ``Shape::info()`` string.

    ``params`` follow :func:`cgal_ransac`'s conventions (metres, radians).

    Raises:
        ValueError: an unknown kind or an unexpected number of fields.
    """
    m = re.match(r"\s*Type:\s*(\w+)", info)
    kind = m.group(1) if m else ""
    if kind not in _INFO_FIELDS:
        raise ValueError(f"unknown CGAL shape text: {info!r}")
    body, sep, tail = info[m.end():].partition("#Pts:")
    if kind == "plane":  # "(nx, ny, nz)x - d= 0": drop the "= 0"
        body = body.rpartition("=")[0]
    values = [float(x) for x in _FLOAT.findall(body)]
    if not sep or len(values) != _INFO_FIELDS[kind]:
        raise ValueError(f"unexpected CGAL {kind} text: {info!r}")
    v = np.array(values, dtype=np.float64)
    count = int(tail)
    params: dict[str, Any]
    if kind == "plane":
        normal = v[:3]
        norm = np.linalg.norm(normal)
        params = {"normal": normal / norm, "offset": float(-v[3] / norm)}
    elif kind == "sphere":
        params = {"center": v[:3], "radius": float(v[3])}
    elif kind == "cylinder":
        params = {"center": v[:3], "axis": _unit(v[3:6]), "radius": float(v[6])}
    elif kind == "cone":
        params = {"apex": v[:3], "axis": _unit(v[3:6]), "angle": float(v[6])}
    else:
        params = {
            "center": v[:3],
            "axis": _unit(v[3:6]),
            "major": float(v[6]),
            "minor": float(v[7]),
        }
    return kind, params, count


def cgal_ransac(
    points: np.ndarray,
    normals: np.ndarray,
    epsilon: float,
    min_points: int,
    kinds: tuple[str, ...] = ("plane", "sphere", "cylinder", "cone", "torus"),
    seed: int = 0,
    *,
    cluster_epsilon: float | None = None,
    normal_threshold: float = 0.9,
    probability: float = 0.01,
) -> list[dict]:
    """Primitive shapes found by CGAL's Efficient RANSAC (pip package ``cgal``).

    The points and normals are copied into a ``CGAL.CGAL_Point_set_3.Point_set_3``
    and passed to ``CGAL.CGAL_Shape_detection.efficient_RANSAC`` with the shape
    factories of ``kinds``. CGAL draws minimal samples from an octree, scores each
    candidate on growing random subsets, keeps the best candidate once it is found with
    probability ``1 - probability``, refits it to its inliers, keeps its largest
    connected component (``cluster_epsilon``) and removes those points; it stops when
    no candidate of ``min_points`` can still be expected.

    Not deterministic: the bindings give no way to seed CGAL's random generator
    (``CGAL::get_default_random()``, seeded from the clock at its first use in the
    process, then one stream for all later calls), so ``seed`` is accepted for a
    uniform interface and ignored; repeated calls with the same input may give
    different shapes, orders and inlier sets.

    Args:
        points: ``(n, 3)`` points, metres.
        normals: ``(n, 3)`` normals (unit; their sign does not matter to CGAL).
        epsilon: the most distance from a point to a shape for it to be an inlier,
            metres.
        min_points: the fewest inliers of a shape.
        kinds: the shape kinds to look for, among ``CGAL_KINDS``.
        seed: ignored (see above).
        cluster_epsilon: the largest gap between neighbouring inliers of one shape,
            metres; None: CGAL's default, 1 % of the bounding-box diagonal.
        normal_threshold: the least ``|cos|`` between a point's normal and the shape's
            normal at it (0.9: about 25 degrees).
        probability: the probability of missing the largest candidate (CGAL's
            "search endurance"; smaller is slower and more thorough).

    Returns:
        One dict per shape, in CGAL's order of detection: ``{'kind': str, 'params':
        dict, 'inliers': (k,) int64 indices into points}`` with params (metres,
        radians, vectors as ``(3,)`` float64 arrays): plane ``normal`` (unit),
        ``offset`` (``normal . p = offset``); sphere ``center``, ``radius``; cylinder
        ``center`` (a point on the axis), ``axis`` (unit, sign arbitrary), ``radius``;
        cone ``apex``, ``axis`` (unit, from the apex into the cone), ``angle`` (half
        angle); torus ``center``, ``axis`` (unit), ``major``, ``minor``. Values are
        CGAL's, parsed from its 6-significant-digit text.

    Raises:
        BaselineNotInstalled: the ``CGAL`` bindings cannot be imported
            (``pip install cgal``).
        ValueError: an unknown kind, or points and normals of different shapes.
    """
    _require("CGAL", REQUIREMENTS["cgal"])
    from CGAL.CGAL_Kernel import Point_3, Vector_3
    from CGAL.CGAL_Point_set_3 import Point_set_3
    from CGAL.CGAL_Shape_detection import efficient_RANSAC

    unknown = set(kinds) - set(CGAL_KINDS)
    if unknown:
        raise ValueError(f"unknown kinds {sorted(unknown)}; known: {list(CGAL_KINDS)}")
    points = np.asarray(points, dtype=np.float64)
    normals = np.asarray(normals, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3 or normals.shape != points.shape:
        raise ValueError(f"points {points.shape} and normals {normals.shape}: want (n, 3)")
    n = len(points)
    if n == 0:
        return []

    point_set = Point_set_3()
    point_set.add_normal_map()
    point_set.reserve(n)
    for p, q in zip(points.tolist(), normals.tolist()):
        point_set.insert(Point_3(*p), Vector_3(*q))
    shape_map = point_set.add_int_map("shape_index")

    flags = {flag: kind in kinds for kind, flag in CGAL_KINDS.items()}
    infos = efficient_RANSAC(
        point_set,
        shape_map,
        min_points=int(min_points),
        epsilon=float(epsilon),
        cluster_epsilon=-1.0 if cluster_epsilon is None else float(cluster_epsilon),
        normal_threshold=float(normal_threshold),
        probability=float(probability),
        **flags,
    )
    labels = np.fromiter((shape_map.get(i) for i in range(n)), dtype=np.int64, count=n)
    order = np.argsort(labels, kind="stable")
    bounds = np.searchsorted(labels[order], np.arange(len(infos) + 1))
    shapes = []
    for i, info in enumerate(infos):
        kind, params, count = parse_cgal_info(info)
        inliers = np.sort(order[bounds[i]:bounds[i + 1]])
        if len(inliers) != count:  # the map and the text disagree: not expected
            raise RuntimeError(f"CGAL shape {i}: {count} points in {info!r}, "
                               f"{len(inliers)} in the index map")
        shapes.append({"kind": kind, "params": params, "inliers": inliers})
    return shapes


# ----------------------------------------------------------------------- self-check


def _rotation(rng: np.random.Generator) -> np.ndarray:
    """A random ``(3, 3)`` rotation matrix (uniform, from a unit quaternion)."""
    w, x, y, z = rng.normal(size=4)
    s = np.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w / s, x / s, y / s, z / s
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def _check_open3d() -> None:
    """A zoo chair moved by a known pose onto a floor plane; prints the pose error."""
    import csdf

    rng = np.random.default_rng(1)
    shape = csdf.zoo.load("chair")
    m_pts, m_nrm = csdf.sample_surface(shape, 5000, seed=0)
    s_pts, s_nrm = csdf.sample_surface(shape, 5000, seed=1)  # other samples for the scene
    size = np.ptp(m_pts, axis=0).max()
    # yaw only, so the chair stands on the floor (the usual case); tilt is tested too
    for label, rot in (("yaw", None), ("random rotation", _rotation(rng))):
        if rot is None:
            a = 0.7
            rot = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
        truth = np.eye(4)
        truth[:3, :3] = rot
        placed = s_pts @ rot.T
        truth[:3, 3] = [0.3, -0.2, -placed[:, 2].min()]
        placed = placed + truth[:3, 3]
        floor = np.c_[rng.uniform(-1.5, 1.5, (8000, 2)) * size, np.zeros(8000)]
        scene = np.vstack([placed, floor])
        scene_n = np.vstack([s_nrm @ rot.T, np.tile([0.0, 0.0, 1.0], (8000, 1))])
        scene = scene + rng.normal(scale=1e-3 * size, size=scene.shape)
        voxel = size / 40
        for given in (True, False):
            t0 = time.perf_counter()
            found = open3d_detect(scene, scene_n if given else None,
                                  {"chair": (m_pts, m_nrm)}, voxel, seed=0)
            dt = time.perf_counter() - t0
            print(f"open3d {label}, normals {'given' if given else 'estimated'}: "
                  f"{len(found)} found in {dt:.2f} s (chair size {size:.3f} m, "
                  f"voxel {voxel:.4f} m)")
            for f in found:
                d = np.linalg.inv(truth) @ f["pose"]
                ang = np.degrees(np.arccos(np.clip((np.trace(d[:3, :3]) - 1) / 2, -1, 1)))
                print(f"  fitness {f['fitness']:.3f} rmse {f['inlier_rmse']:.5f} m: "
                      f"error {np.linalg.norm(f['pose'][:3, 3] - truth[:3, 3]):.5f} m, "
                      f"{ang:.3f} deg")


def _check_cgal() -> None:
    """Sphere + cylinder + plane with 1 mm noise; prints shapes, median time of 3."""
    rng = np.random.default_rng(0)
    n = 6000
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    sphere = (np.array([0.5, 0.4, 0.35]) + 0.2 * d, d)
    t = rng.uniform(0, 2 * np.pi, n)
    radial = np.stack([np.cos(t), np.sin(t), np.zeros(n)], 1)
    cyl = (np.array([-0.4, -0.3, 0.0]) + 0.15 * radial
           + np.outer(rng.uniform(0.0, 0.6, n), [0, 0, 1]), radial)
    plane = (np.c_[rng.uniform(-1, 1, (2 * n, 2)), np.zeros(2 * n)],
             np.tile([0.0, 0.0, 1.0], (2 * n, 1)))
    truth = np.repeat([0, 1, 2], [n, n, 2 * n])
    pts = np.vstack([sphere[0], cyl[0], plane[0]])
    nrm = np.vstack([sphere[1], cyl[1], plane[1]])
    pts = pts + rng.normal(scale=1e-3, size=pts.shape)
    times, runs = [], []
    for _ in range(3):
        t0 = time.perf_counter()
        runs.append(cgal_ransac(pts, nrm, epsilon=0.004, min_points=500,
                                cluster_epsilon=0.05))
        times.append(time.perf_counter() - t0)
    print(f"cgal: {len(pts)} points, median {np.median(times):.3f} s "
          f"({', '.join(f'{x:.3f}' for x in times)})")
    for r, shapes in enumerate(runs):
        print(f" run {r}:")
        for s in shapes:
            parts = np.bincount(truth[s["inliers"]], minlength=3)
            params = {k: np.round(v, 5).tolist() if isinstance(v, np.ndarray)
                      else round(v, 5) for k, v in s["params"].items()}
            print(f"  {s['kind']:8s} {len(s['inliers']):5d} inliers "
                  f"(sphere/cyl/plane {parts.tolist()}) {params}")
    same = all(
        len(a) == len(b) and all(
            x["kind"] == y["kind"] and np.array_equal(x["inliers"], y["inliers"])
            for x, y in zip(a, b))
        for a, b in zip(runs, runs[1:]))
    print(f" identical output in the 3 runs: {same}")


if __name__ == "__main__":
    import sys

    for check in (_check_open3d, _check_cgal):
        try:
            check()
        except BaselineNotInstalled as e:
            print(f"{check.__name__}: not installed ({e})")
        sys.stdout.flush()
