"""Pose and shape recovery benchmark for csdf: ``csdf.fit`` against ICP baselines.

Run from the repository root::

    .venv/bin/python benchmarks/bench_fit.py            # full run (~10 min on 2 cores)
    .venv/bin/python benchmarks/bench_fit.py --quick --output /tmp/fit_quick.md   # ~1 min

Seeded synthetic scenes of zoo models (``csdf.zoo``): full-surface clouds
(``csdf.sample_surface``) and single-view partial scans (``csdf.scan``), 10k points,
Gaussian noise of 0.5% of the object size, 0 / 20 / 50% outliers. Every method starts
from the same perturbed pose (15 to 180 degrees about a random axis, and 10% of the size
in translation) on the same clouds. Methods: ``csdf.fit`` (pose; pose+scale;
pose+scale+params; ``multistart=True``), ``csdf.icp``, and when Open3D is installed its
point-to-plane ICP and FPFH + RANSAC global registration. Success: rotation error < 2
degrees and centre error < 1% of the size (modulo the model's rotational symmetries).

It prints each cell as it goes, then writes a Markdown report with the exact command
line, the machine and the PASS/FAIL targets (``benchmarks/FIT_RESULTS.md`` by default).
See ``benchmarks/README.md``.
"""

from __future__ import annotations

import argparse
import math
import shlex
import statistics
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import loadavg, machine_info, md_table  # noqa: E402

HERE = Path(__file__).resolve().parent

# ---------------------------------------------------------------------------- settings
N_POINTS = 10_000  # points per cloud (scans are subsampled to this)
NOISE = 0.005  # Gaussian noise, fraction of the object size (bounding-box diagonal)
OUTLIER_BOX = 1.5  # outliers are uniform in the object's bounds grown 1.5x about the centre
T_INIT = 0.10  # initial centre error, fraction of the size
ANGLES = (15, 30, 60, 90, 180)  # initial rotation errors, degrees
SUCCESS_DEG = 2.0  # success: rotation error below this (degrees) ...
SUCCESS_T = 0.01  # ... and centre error below this fraction of the size
PARAM_TOL = 0.02  # ... and (params) every parameter within this fraction of its range
SCALE_RANGE = (0.8, 1.25)  # true scale of the pose+scale scenes (log-uniform)
O3D_THRESHOLD = 0.05  # Open3D ICP correspondence distance, fraction of the size
FPFH_VOXELS = (0.03, 0.04)  # FPFH + RANSAC voxel sizes tried, fractions of the size
FPFH_SELECT = 0.015  # the best voxel's result: most scene points within this (x size)
MODEL_POOL = 100_000  # surface samples per model, drawn once; full clouds subsample them
BASE_SEED = 20261122

MODELS = ("chair", "cross_shaft", "flange")  # pose experiments
PARAM_MODELS = ("chair", "cross_shaft")  # pose+scale+params experiments

# targets (see README.md)
TARGET_60 = 0.95
TARGET_90 = 0.75
TARGET_MULTI = 0.95
TARGET_MULTI_S = 0.5
TARGET_OUTLIERS = 0.95
TARGET_PARTIAL = 0.95
TARGET_PARAMS = 0.90
TARGET_PARAMS_S = 0.100

METHODS = {
    "fit": "csdf.fit pose",
    "fit_huber": "csdf.fit pose, loss='huber'",
    "fit_cauchy": "csdf.fit pose, loss='cauchy'",
    "fit_vis": "csdf.fit pose, viewpoint=sensor",
    "fit_vis_huber": "csdf.fit pose, viewpoint=sensor, loss='huber'",
    "fit_vis_cauchy": "csdf.fit pose, viewpoint=sensor, loss='cauchy'",
    "fit_noescape": "csdf.fit pose, escape=False (extra)",
    "fit_scipy": "csdf.fit pose, solver='scipy' (extra)",
    "fit_scale": "csdf.fit pose+scale",
    "fit_params": "csdf.fit pose+scale+params",
    "multistart": "csdf.fit multistart",
    "multistart_huber": "csdf.fit multistart, loss='huber'",
    "icp": "csdf.icp",
    "o3d_icp": "Open3D ICP (point-to-plane)",
    "o3d_fpfh": "Open3D FPFH+RANSAC (+ICP)",
}
GLOBAL_METHODS = ("multistart", "multistart_huber", "o3d_fpfh")
# csdf.fit variants called with the default loss ('auto'): their tables count how often it
# went on to Cauchy
AUTO_METHODS = ("fit", "fit_vis", "fit_noescape", "fit_scipy", "fit_scale", "fit_params",
                "multistart")  # independent of the initial rotation
# csdf.fit variants whose failures are diagnosed by a second fit started at the truth:
# method -> the keyword arguments of that reference fit (the loss also scores the costs;
# for the default 'auto', the loss the failed run ended with)
DIAGNOSED = {"fit": {}, "fit_huber": {"loss": "huber"}, "fit_cauchy": {"loss": "cauchy"},
             "fit_vis": {"viewpoint": True}, "fit_vis_cauchy": {"viewpoint": True,
                                                                "loss": "cauchy"},
             "fit_vis_huber": {"viewpoint": True, "loss": "huber"},
             "multistart_huber": {"loss": "huber"},
             "fit_noescape": {"escape": False}, "fit_scipy": {"solver": "scipy"},
             "fit_scale": {"estimate": ("pose", "scale")},
             "fit_params": {"estimate": ("pose", "scale", "params")},
             "multistart": {}}


def set_base_seed(seed: int) -> None:
    """Use another base seed for every scene (``--base-seed``: development runs)."""
    global BASE_SEED
    BASE_SEED = int(seed)


def log(msg: str) -> None:
    print(msg, flush=True)


def err_text(exc: BaseException, limit: int = 160) -> str:
    text = " ".join(f"{type(exc).__name__}: {exc}".split()).replace("|", "/")
    return text if len(text) <= limit else text[: limit - 3] + "..."


# ---------------------------------------------------------------------------- machine info
# ---------------------------------------------------------------------------- models
def local_models() -> dict:
    """Stand-ins used when ``csdf.zoo`` cannot be imported: two small parametric parts."""
    import csdf

    w = csdf.param("width", 0.08, 0.06, 0.12)
    hole = csdf.param("hole", 0.008, 0.005, 0.012)
    boss = csdf.param("boss", 0.015, 0.01, 0.02)
    plate = csdf.box((w, 0.05, 0.01)) - csdf.cylinder(hole, 0.02).translate((0.025, 0, 0))
    bracket = plate | csdf.cylinder(boss, 0.03).translate((-0.02, 0.0, 0.015))
    r = csdf.param("radius", 0.02, 0.015, 0.03)
    hub = csdf.cylinder(r, 0.04) - csdf.cylinder(r * 0.5, 0.05)
    beams = csdf.cylinder(0.006, 0.06).orient("x").translate((0.03, 0, 0)).repeat_polar(4)
    return {"bracket": bracket, "shaft": hub | beams}


def load_models(names: list[str], use_zoo: bool) -> tuple[dict, str]:
    """``({name: Shape}, note)``: zoo models if the zoo is there, else the local stand-ins."""
    if use_zoo:
        try:
            from csdf import zoo

            known = zoo.names()
            missing = [n for n in names if n not in known]
            if missing:
                raise ValueError(f"models {missing} not in the zoo ({', '.join(known)})")
            return {n: zoo.load(n) for n in names}, "csdf.zoo"
        except Exception as exc:
            note = f"csdf.zoo unavailable ({err_text(exc)}): local stand-in models used"
            log(note)
            return local_models(), note
    return local_models(), "local stand-in models (--no-zoo)"


def get_scanner():
    """``(scan, Camera)`` from the library, or ``(None, reason)``."""
    try:
        from csdf.render import Camera
        from csdf.scan import scan

        return scan, Camera
    except Exception as exc:
        return None, err_text(exc)


@dataclass
class Model:
    name: str
    shape: object
    prog: object
    pool: np.ndarray  # (MODEL_POOL, 3) surface samples at the default parameters
    lo: np.ndarray  # tight bounds of the pool (object frame)
    hi: np.ndarray
    centre: np.ndarray  # reference point for the centre error (on every symmetry axis)
    size: float  # bounding-box diagonal of the surface at the defaults
    sym: list[np.ndarray]  # rotations G (about ``centre``) that map the model onto itself
    params: list  # the program's Param declarations


def angle_deg(A: np.ndarray, B: np.ndarray) -> float:
    c = (np.trace(A.T @ B) - 1.0) / 2.0
    return math.degrees(math.acos(min(1.0, max(-1.0, c))))


def axis_angle(axis, deg: float) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    a = np.asarray(axis, dtype=float)
    return Rotation.from_rotvec(math.radians(deg) * a / np.linalg.norm(a)).as_matrix()


def symmetry_group(prog, pts: np.ndarray, centre: np.ndarray, size: float) -> list[np.ndarray]:
    """Rotational symmetries of the surface about ``centre``, found numerically.

    Candidates: turns by 360/n degrees (n = 2..64) about the coordinate axes, the face
    diagonals and the body diagonals (zoo models are axis-aligned). A candidate is a
    symmetry if it maps 2000 exact surface samples onto the surface (|f| below 1e-6 of
    the size for 99% of them, below 1e-3 for all). The accepted turns are closed under
    composition (the full finite group, identity included).
    """
    rng = np.random.default_rng(0)
    q = pts[rng.choice(len(pts), min(2000, len(pts)), replace=False)] - centre
    axes = [np.eye(3)[i] for i in range(3)]
    for i, j in ((0, 1), (1, 2), (0, 2)):
        for sgn in (1, -1):
            v = np.zeros(3)
            v[i], v[j] = 1, sgn
            axes.append(v)
    axes += [np.array(v) for v in ((1, 1, 1), (1, 1, -1), (1, -1, 1), (-1, 1, 1))]

    def is_sym(G):
        f = np.abs(prog(q @ G.T + centre))
        return np.quantile(f, 0.99) < 1e-6 * size and f.max() < 1e-3 * size

    gens = []
    for a in axes:
        for n in range(64, 1, -1):
            G = axis_angle(a, 360.0 / n)
            if is_sym(G):
                if n == 64:
                    log(f"  warning: the model looks rotationally symmetric about {a.tolist()}"
                        "; rotation errors about it are counted modulo 360/64 degrees")
                gens.append(G)
                break  # the smallest turn about this axis generates the others
    group = [np.eye(3)]
    frontier = list(gens)
    while frontier and len(group) < 512:
        G = frontier.pop()
        if any(np.abs(G - H).max() < 1e-6 for H in group):
            continue
        group.append(G)
        frontier += [G @ H for H in gens]
    return group


def build_model(name: str, shape) -> Model:
    import csdf

    prog = shape.compile()
    pool, _ = csdf.sample_surface(shape, MODEL_POOL, seed=BASE_SEED)
    lo, hi = pool.min(0), pool.max(0)
    size = float(np.linalg.norm(hi - lo))
    b = np.asarray(shape.bounds, dtype=float) if shape.bounds is not None else None
    centre = 0.5 * (b[0] + b[1]) if b is not None else 0.5 * (lo + hi)
    sym = symmetry_group(prog, pool, centre, size)
    return Model(name, shape, prog, pool, lo, hi, centre, size, sym, list(prog.params))


# ---------------------------------------------------------------------------- scenes
@dataclass
class Scene:
    model: Model
    kind: str  # 'full' or 'partial'
    outliers: float
    points: np.ndarray
    R: np.ndarray  # true object-to-scene pose: p = s R q + t
    t: np.ndarray
    s: float
    params: dict[str, float]  # true parameter values
    size: float  # object size in the scene (s * bounding-box diagonal)
    inliers: np.ndarray  # (N,) bool: False for the points replaced by outliers
    note: str = ""


def random_rotation(rng) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return Rotation.random(random_state=rng).as_matrix()


def unit(rng) -> np.ndarray:
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def add_outliers(pts, frac, lo, hi, R, t, s, rng) -> tuple[np.ndarray, np.ndarray]:
    """Replace ``frac`` of the points (a random subset) by points uniform in the object's
    bounds grown ``OUTLIER_BOX`` times about its centre, posed like the object; returns
    the points and the mask of the points kept (inliers)."""
    k = int(round(frac * len(pts)))
    keep = np.ones(len(pts), dtype=bool)
    if k == 0:
        return pts, keep
    c, half = 0.5 * (lo + hi), 0.5 * OUTLIER_BOX * (hi - lo)
    q = c + half * rng.uniform(-1.0, 1.0, (k, 3))
    out = pts.copy()
    sel = rng.choice(len(pts), k, replace=False)
    out[sel] = s * q @ R.T + t
    keep[sel] = False
    return out, keep


def full_scene(model: Model, outliers: float, rng, scale_range=None, params=None) -> Scene:
    """A full-surface cloud: pool samples (or fresh samples at ``params``), random pose."""
    import csdf

    s = 1.0
    if scale_range is not None:
        s = float(math.exp(rng.uniform(math.log(scale_range[0]), math.log(scale_range[1]))))
    if params:
        q, _ = csdf.sample_surface(model.shape, N_POINTS, seed=rng, params=params)
        lo, hi = q.min(0), q.max(0)
    else:
        q = model.pool[rng.choice(len(model.pool), N_POINTS, replace=False)]
        lo, hi = model.lo, model.hi
    size = s * float(np.linalg.norm(hi - lo))
    R = random_rotation(rng)
    t = rng.normal(size=3) * size
    p = s * q @ R.T + t + rng.normal(0.0, NOISE * size, q.shape)
    p, keep = add_outliers(p, outliers, lo, hi, R, t, s, rng)
    return Scene(model, "full", outliers, p, R, t, s, dict(params or {}), size, keep)


def partial_scene(model: Model, outliers: float, rng, scanner) -> Scene:
    """A single-view scan (camera frame) of the model in a random pose, seen from a random
    direction at a distance where its bounding sphere fills a 45-degree view; range noise
    of 0.5% of the size along the rays; subsampled to ``N_POINTS``."""
    scan, Camera = scanner
    size = model.size
    Rw = random_rotation(rng)
    tw = rng.normal(size=3) * size
    centre_w = Rw @ model.centre + tw
    fov = 45.0
    eye = centre_w + unit(rng) * 0.5 * size / math.sin(math.radians(fov / 2)) * 1.05
    up = unit(rng)
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = Rw, tw
    res = 256
    for _ in range(4):  # finer sensor until enough points are seen
        cam = Camera.look_at(eye, centre_w, up=up, fov=fov, width=res, height=res)
        pts, _ = scan(model.shape, cam, noise=NOISE * size, seed=rng, object_pose=T)
        if len(pts) >= N_POINTS:
            break
        res *= 2
    note = "" if len(pts) >= N_POINTS else f"only {len(pts)} points seen"
    if len(pts) > N_POINTS:
        pts = pts[rng.choice(len(pts), N_POINTS, replace=False)]
    R = cam.R.T @ Rw
    t = cam.R.T @ (tw - cam.t)
    pts, keep = add_outliers(pts, outliers, model.lo, model.hi, R, t, 1.0, rng)
    return Scene(model, "partial", outliers, pts, R, t, 1.0, {}, size, keep, note)


def initial_pose(scene: Scene, deg: float, rng) -> np.ndarray:
    """The start: the true rotation turned by ``deg`` about a random axis (about the object's
    centre), the centre moved by ``T_INIT`` of the size in a random direction, scale 1."""
    m = scene.model
    R0 = axis_angle(unit(rng), deg) @ scene.R
    c_true = scene.s * scene.R @ m.centre + scene.t
    T = np.eye(4)
    T[:3, :3] = R0
    T[:3, 3] = c_true + T_INIT * scene.size * unit(rng) - R0 @ m.centre
    return T


# ---------------------------------------------------------------------------- methods
@dataclass
class Outcome:
    R: np.ndarray
    t: np.ndarray
    s: float = 1.0
    params: dict[str, float] = field(default_factory=dict)
    seconds: float = math.nan
    error: str | None = None
    loss: str | None = None  # csdf.fit: the loss of the final solve (FitResult.loss)


def _timed(fn: Callable[[], tuple]) -> Outcome:
    """Time ``fn``, which returns ``(R, t, s, params)`` or ``(R, t, s, params, loss)``."""
    t0 = time.perf_counter()
    try:
        out = fn()
    except Exception as exc:  # a crashed fit counts as a failure, with its message
        return Outcome(np.eye(3), np.zeros(3), math.nan, {}, time.perf_counter() - t0,
                       err_text(exc))
    dt = time.perf_counter() - t0
    R, t, s, params = out[:4]
    return Outcome(np.asarray(R), np.asarray(t), float(s), dict(params), dt,
                   loss=out[4] if len(out) > 4 else None)


def _res(r) -> tuple:
    return r.rotation, r.translation, r.scale, r.params, r.loss


class Runner:
    """Runs the methods; holds the Open3D model clouds (built once per model, untimed)."""

    def __init__(self, o3d, models: dict[str, Model]):
        self.o3d = o3d
        self.o3d_model: dict[str, tuple] = {}
        if o3d is not None:
            for name, m in models.items():
                self.o3d_model[name] = self._o3d_model(m)

    def _o3d_model(self, m: Model):
        """Model cloud for ICP (exact normals) and its FPFH features at each voxel size."""
        import csdf

        o3d = self.o3d
        P, N = csdf.sample_surface(m.shape, 20_000, seed=BASE_SEED + 1)
        pc = o3d.geometry.PointCloud()
        pc.points = o3d.utility.Vector3dVector(P)
        pc.normals = o3d.utility.Vector3dVector(N)
        feats = [self._features(self._cloud(P), v * m.size) for v in FPFH_VOXELS]
        return pc, feats

    def _features(self, pc, voxel: float) -> tuple:
        """Voxel-downsampled cloud (normals estimated) and its FPFH features; the same
        processing for the scene and the model."""
        o3d = self.o3d
        down = pc.voxel_down_sample(voxel)
        down.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=2 * voxel, max_nn=30))
        feat = o3d.pipelines.registration.compute_fpfh_feature(
            down, o3d.geometry.KDTreeSearchParamHybrid(radius=5 * voxel, max_nn=100))
        return down, feat

    def run(self, method: str, scene: Scene, init: np.ndarray, seed: int) -> Outcome:
        import csdf

        shape, P = scene.model.shape, scene.points
        if method == "fit":
            return _timed(lambda: _res(csdf.fit(shape, P, init=init)))
        if method in ("fit_huber", "fit_cauchy"):
            loss = method.split("_")[1]
            return _timed(lambda: _res(csdf.fit(shape, P, init=init, loss=loss)))
        if method == "fit_vis":  # the sensor sits at the origin of a scan's frame
            return _timed(lambda: _res(csdf.fit(shape, P, init=init, viewpoint=np.zeros(3))))
        if method in ("fit_vis_huber", "fit_vis_cauchy"):
            loss = method.split("_")[2]
            return _timed(lambda: _res(csdf.fit(shape, P, init=init, viewpoint=np.zeros(3),
                                                loss=loss)))
        if method == "fit_noescape":
            return _timed(lambda: _res(csdf.fit(shape, P, init=init, escape=False)))
        if method == "fit_scipy":
            return _timed(lambda: _res(csdf.fit(shape, P, init=init, solver="scipy")))
        if method == "fit_scale":
            return _timed(lambda: _res(csdf.fit(shape, P, init=init,
                                                estimate=("pose", "scale"))))
        if method == "fit_params":
            return _timed(lambda: _res(csdf.fit(shape, P, init=init,
                                                estimate=("pose", "scale", "params"))))
        if method in ("multistart", "multistart_huber"):
            vp = np.zeros(3) if scene.kind == "partial" else None
            kw = {"loss": "huber"} if method == "multistart_huber" else {}
            return _timed(lambda: _res(csdf.fit(shape, P, init=init, multistart=True,
                                                seed=seed, viewpoint=vp, **kw)))
        if method == "icp":
            return _timed(lambda: _res(csdf.icp(shape, P, init=init, seed=seed)))
        if method == "o3d_icp":
            return _timed(lambda: self._o3d_icp(scene, init))
        if method == "o3d_fpfh":
            return _timed(lambda: self._o3d_fpfh(scene, seed))
        raise ValueError(method)

    def _cloud(self, P):
        pc = self.o3d.geometry.PointCloud()
        pc.points = self.o3d.utility.Vector3dVector(P)
        return pc

    def _icp(self, src, target, init_scene_to_model, size) -> np.ndarray:
        reg = self.o3d.pipelines.registration
        r = reg.registration_icp(
            src, target, O3D_THRESHOLD * size, init_scene_to_model,
            reg.TransformationEstimationPointToPlane(),
            reg.ICPConvergenceCriteria(max_iteration=60))
        return np.linalg.inv(r.transformation)  # object to scene

    def _o3d_icp(self, scene: Scene, init: np.ndarray) -> tuple:
        """The scene registered to the model's samples (exact normals), like csdf.icp."""
        target = self.o3d_model[scene.model.name][0]
        T = self._icp(self._cloud(scene.points), target, np.linalg.inv(init), scene.size)
        return T[:3, :3], T[:3, 3], 1.0, {}

    def _o3d_fpfh(self, scene: Scene, seed: int) -> tuple:
        """FPFH + RANSAC at each voxel size, each refined by the ICP above; the result
        with the most scene points within ``FPFH_SELECT`` of the model wins."""
        o3d = self.o3d
        reg = o3d.pipelines.registration
        pc_model, feats_model = self.o3d_model[scene.model.name]
        src = self._cloud(scene.points)
        best = (-1.0, math.inf, None)
        for v, (down_model, feat_model) in zip(FPFH_VOXELS, feats_model):
            voxel = v * scene.size
            down, feat = self._features(src, voxel)
            o3d.utility.random.seed(seed % 2**31)
            r = reg.registration_ransac_based_on_feature_matching(
                down, down_model, feat, feat_model, True, 1.5 * voxel,
                reg.TransformationEstimationPointToPoint(False), 3,
                [reg.CorrespondenceCheckerBasedOnEdgeLength(0.9),
                 reg.CorrespondenceCheckerBasedOnDistance(1.5 * voxel)],
                reg.RANSACConvergenceCriteria(100_000, 0.999))
            T = self._icp(src, pc_model, r.transformation, scene.size)
            ev = reg.evaluate_registration(src, pc_model, FPFH_SELECT * scene.size,
                                           np.linalg.inv(T))
            if (ev.fitness, -ev.inlier_rmse) > (best[0], -best[1]):
                best = (ev.fitness, ev.inlier_rmse, T)
        T = best[2]
        return T[:3, :3], T[:3, 3], 1.0, {}


# ---------------------------------------------------------------------------- scoring
@dataclass
class Trial:
    model: str
    cell: str
    method: str
    angle: int
    rot_err: float  # degrees, modulo the model's symmetries
    t_err: float  # centre error, fraction of the size
    s_err: float  # |s / s_true - 1|
    p_err: float  # largest parameter error, fraction of its range (nan: none estimated)
    seconds: float
    success: bool
    error: str | None = None
    failure: str = ""  # csdf.fit failures: 'local', 'off' or 'other' (see diagnose)
    backface: float = math.nan  # partial scans: share of points on back faces (backfacing)
    loss: str | None = None  # csdf.fit: the loss of the final solve


def backfacing(scene: Scene, R, t, s, params) -> float:
    """Share of a scan's points whose nearest model surface at pose ``(R, t, s)`` faces away
    from the camera (at the origin of the scan's frame): such points are explained by the
    back of the model, which the sensor cannot have seen. Outliers are not counted."""
    P = scene.points[scene.inliers]
    q = ((P - t) @ R) / s
    _, g = scene.model.prog.value_and_grad(q, params) if params else \
        scene.model.prog.value_and_grad(q)
    return float(np.mean(np.sum((g @ R.T) * P, axis=1) > 0))


def score(scene: Scene, out: Outcome, method: str, cell: str, angle: int) -> Trial:
    m = scene.model
    if out.error is not None:
        return Trial(m.name, cell, method, angle, math.nan, math.nan, math.nan, math.nan,
                     out.seconds, False, out.error, loss=out.loss)
    rot = min(angle_deg(out.R, scene.R @ G) for G in m.sym)
    c_est = out.s * out.R @ m.centre + out.t
    c_true = scene.s * scene.R @ m.centre + scene.t
    t_err = float(np.linalg.norm(c_est - c_true)) / scene.size
    s_err = abs(out.s / scene.s - 1.0)
    p_err = math.nan
    if method == "fit_params":
        errs = [abs(out.params[p.name] - scene.params[p.name]) / (p.hi - p.lo)
                for p in m.params if p.hi > p.lo]
        p_err = max(errs) if errs else 0.0
    ok = rot < SUCCESS_DEG and t_err < SUCCESS_T
    if method == "fit_params":
        ok = ok and p_err <= PARAM_TOL
    back = math.nan
    if scene.kind == "partial":
        back = backfacing(scene, out.R, out.t, out.s, out.params)
    return Trial(m.name, cell, method, angle, rot, t_err, s_err, p_err, out.seconds, ok,
                 backface=back, loss=out.loss)


def robust_cost(scene: Scene, out: Outcome, loss: str) -> float:
    """The robust cost of a solution on the scene's points: SciPy's ``loss`` on the
    residuals ``s f(R^T (p - t) / s; c)`` with a residual scale of 1% of the size."""
    q = ((scene.points - out.t) @ out.R) / out.s
    pv = out.params or None
    r = out.s * np.asarray(scene.model.prog(q, pv) if pv else scene.model.prog(q))
    z = (r / (0.01 * scene.size)) ** 2
    rho = np.log1p(z) if loss == "cauchy" else np.where(z <= 1, z, 2 * np.sqrt(z) - 1)
    return float(np.sum(rho))


def diagnose(trial: Trial, out: Outcome, ref: tuple[Outcome, Trial], loss: str,
             scene: Scene) -> str:
    """Why a csdf.fit run failed, from a second fit started at the true pose (and, for the
    parameter trials, the true parameters):

    * ``off``: that fit fails the success test too: the optimum near the truth is itself
      off (bias from noise, outliers or a partial view; a scale/parameter trade-off);
    * ``local``: it succeeds with a lower robust cost: the failed run stopped in a local
      minimum;
    * ``other``: it succeeds but the failed run's cost is as low (an ambiguity the
      symmetry test did not catch).
    """
    ref_out, ref_trial = ref
    if ref_out.error is not None or not ref_trial.success:
        return "off"
    if robust_cost(scene, out, loss) > robust_cost(scene, ref_out, loss) * (1 + 1e-3):
        return "local"
    return "other"


# ---------------------------------------------------------------------------- experiment
@dataclass
class Cell:
    key: str
    title: str
    kind: str  # full / partial
    outliers: float
    methods: dict[str, tuple[int, ...]]  # method -> initial rotation errors (degrees) run
    models: tuple[str, ...]
    trials: int  # scenes per model
    scale: bool = False
    params: bool = False
    truth_backface: list[float] = field(default_factory=list)  # partial: at the true poses

    @property
    def angles(self) -> tuple[int, ...]:
        return tuple(sorted({a for v in self.methods.values() for a in v}))


def make_cells(args, have_o3d: bool, have_scan: bool, models, param_models) -> list[Cell]:
    """The experiment grid. Single-start methods run at every listed start angle (the same
    starts for all); the global ones (multistart, FPFH) once per scene, from 180°."""
    q = args.quick
    A = (30, 90) if q else ANGLES

    def grid(single: tuple[int, ...], icp: tuple[int, ...], glob: bool, fpfh: bool,
             cauchy: bool = False, vis: bool = False, extra: dict | None = None) -> dict:
        d = {"fit": single, "fit_huber": single}  # the default ('auto') and Huber
        if cauchy:
            d["fit_cauchy"] = single
        if vis:
            d["fit_vis"] = single
            d["fit_vis_huber"] = single
        if vis and cauchy:
            d["fit_vis_cauchy"] = single
        d.update(extra or {})
        if icp:
            d["icp"] = icp
        if have_o3d:
            d["o3d_icp"] = single
        if glob:
            d["multistart"] = (180,)
            d["multistart_huber"] = (180,)
        if fpfh and have_o3d:
            d["o3d_fpfh"] = (180,)
        return d

    n, no = args.trials, args.outlier_trials
    cells = [
        Cell("full0", "Full clouds, no outliers", "full", 0.0,
             grid(A, (30, 90), True, True,
                  extra={"fit_noescape": (60, 90), "fit_scipy": (30, 60)}), models, n),
        Cell("full20", "Full clouds, 20% outliers", "full", 0.2,
             grid((30,), (), True, False, True), models, no),
        Cell("full50", "Full clouds, 50% outliers", "full", 0.5,
             grid((30,), () if q else (30,), True, True, True), models, no),
    ]
    if q:
        cells.pop(1)
    if have_scan:
        cells.append(Cell("partial0", "Single-view partial scans, no outliers", "partial", 0.0,
                          grid((30,) if q else (15, 30, 60, 90), () if q else (30,), True,
                               True, vis=True), models, n))
        if not q:
            cells.append(Cell("partial50", "Single-view partial scans, 50% outliers",
                              "partial", 0.5, grid((30,), (), False, False, True, vis=True),
                              models, no))
    cells.append(Cell("scale", "Full clouds, unknown scale "
                      f"(true scale log-uniform in [{SCALE_RANGE[0]:g}, {SCALE_RANGE[1]:g}], "
                      "start 1)", "full", 0.0, {"fit_scale": (30,) if q else (30, 60)},
                      models, no, scale=True))
    cells.append(Cell("params", "Full clouds, unknown scale and parameters (true parameters "
                      "uniform in their ranges, start at the defaults; true scale 1)",
                      "full", 0.0, {"fit_params": (30,)}, param_models,
                      args.param_trials, params=True))
    return cells


def reference_fit(scene: Scene, kwargs: dict) -> Outcome:
    """``csdf.fit`` started at the true pose, scale and parameters (failure diagnosis),
    with the keyword arguments of the diagnosed method (``viewpoint=True``: the sensor)."""
    import csdf

    truth = {"rotation": scene.R, "translation": scene.t, "scale": scene.s,
             "params": scene.params}
    kw = dict(kwargs)
    if kw.get("viewpoint"):
        kw["viewpoint"] = np.zeros(3)
    return _timed(lambda: _res(csdf.fit(scene.model.shape, scene.points, init=truth, **kw)))


def run_cell(cell: Cell, models: dict[str, Model], runner: Runner, scanner, results: list,
             notes: list) -> None:
    log(f"\n== {cell.key}: {cell.title} ==")
    for mi, name in enumerate(cell.models):
        model = models[name]
        for k in range(cell.trials):
            ss = np.random.SeedSequence([BASE_SEED, mi, sum(map(ord, cell.key)), k])
            rng = np.random.default_rng(ss)
            params = None
            if cell.params:
                params = {p.name: float(rng.uniform(p.lo, p.hi)) for p in model.params}
            if cell.kind == "partial":
                scene = partial_scene(model, cell.outliers, rng, scanner)
                cell.truth_backface.append(backfacing(scene, scene.R, scene.t, 1.0, None))
                if scene.note:
                    notes.append(f"{cell.key} {name} trial {k}: {scene.note}")
            else:
                scene = full_scene(model, cell.outliers, rng,
                                   SCALE_RANGE if cell.scale else None, params)
            seed = int(ss.generate_state(1)[0])
            inits = {a: initial_pose(scene, a, rng) for a in cell.angles}
            refs: dict = {}  # fits started at the truth, for the failure diagnosis
            for method, angles in cell.methods.items():
                for a in angles:
                    out = runner.run(method, scene, inits[a], seed)
                    trial = score(scene, out, method, cell.key, a)
                    if not trial.success and out.error is None and method in DIAGNOSED:
                        kw = DIAGNOSED[method]
                        key = repr(sorted(kw.items()))
                        if key not in refs:
                            ref_out = reference_fit(scene, kw)
                            refs[key] = (ref_out, score(scene, ref_out, method, cell.key, 0))
                        trial.failure = diagnose(trial, out, refs[key],
                                                 kw.get("loss") or out.loss or "huber",
                                                 scene)
                    results.append(trial)
        summary = []
        for method in cell.methods:
            rs = [r for r in results if r.cell == cell.key and r.model == name
                  and r.method == method]
            ok = sum(r.success for r in rs)
            summary.append(f"{method} {ok}/{len(rs)} ({med([r.seconds for r in rs], 's')})")
        log(f"  {name:12s} " + ", ".join(summary))


# ---------------------------------------------------------------------------- formatting
def med(xs, unit: str = "") -> str:
    xs = [x for x in xs if x is not None and not math.isnan(x)]
    if not xs:
        return "-"
    v = statistics.median(xs)
    if unit == "s":
        return f"{v * 1e3:.0f} ms" if v < 10 else f"{v:.1f} s"
    if unit == "%":
        return f"{100 * v:.2f}%"
    if unit == "deg":
        return f"{v:.2f}°"
    return f"{v:.3g}"


def median_or_none(xs) -> float | None:
    xs = [x for x in xs if not math.isnan(x)]
    return statistics.median(xs) if xs else None


def status(ok: bool | None) -> str:
    return "n/a" if ok is None else ("PASS" if ok else "FAIL")


def select(results, cell=None, method=None, angle=None, model=None) -> list[Trial]:
    return [r for r in results if (cell is None or r.cell == cell)
            and (method is None or r.method == method) and (angle is None or r.angle == angle)
            and (model is None or r.model == model)]


def rate(rs: list[Trial]) -> float | None:
    return sum(r.success for r in rs) / len(rs) if rs else None


def pct(x: float | None) -> str:
    return "-" if x is None else f"{100 * x:.0f}%"


def cell_table(cell: Cell, results: list[Trial]) -> str:
    head = ["method", "init rotation error", "trials", "success", "median rotation error",
            "median centre error (% size)"]
    if cell.scale or cell.params:
        head.append("median scale error")
    if cell.params:
        head += ["median max param error (% range)", "param errors <= 2%"]
    partial = cell.kind == "partial"
    if partial:
        head.append("back-facing points: successes / failures (median)")
    head += ["median time", "failures: local min / off optimum / other",
             "'auto' went on to Cauchy", "errors"]
    rows = []
    for method, angles in cell.methods.items():
        for a in angles:
            rs = select(results, cell.key, method, a)
            if not rs:
                continue
            label = f"any (started at {a}°)" if method in GLOBAL_METHODS else f"{a}°"
            row = [METHODS[method], label, str(len(rs)), pct(rate(rs)),
                   med([r.rot_err for r in rs], "deg"), med([r.t_err for r in rs], "%")]
            if cell.scale or cell.params:
                row.append(med([r.s_err for r in rs], "%"))
            if cell.params:
                good = sum(r.p_err <= PARAM_TOL for r in rs if not math.isnan(r.p_err))
                row += [med([r.p_err for r in rs], "%"), f"{good}/{len(rs)}"]
            errs = [r for r in rs if r.error]
            fails = [r for r in rs if not r.success]
            if partial:
                row.append(f"{med([r.backface for r in rs if r.success], '%')} / "
                           f"{med([r.backface for r in fails], '%')}")
            diag = "-"
            if method in DIAGNOSED and fails:
                diag = " / ".join(str(sum(r.failure == f for r in fails))
                                  for f in ("local", "off", "other"))
            elif method in DIAGNOSED:
                diag = "none"
            switched = (f"{sum(r.loss == 'cauchy' for r in rs)}/{len(rs)}"
                        if method in AUTO_METHODS else "-")
            row += [med([r.seconds for r in rs], "s"), diag, switched,
                    f"{len(errs)}: {errs[0].error}" if errs else ""]
            rows.append(row)
    return md_table(head, rows)


def per_model_table(cell: Cell, results: list[Trial]) -> str:
    head = ["method", "init"] + list(cell.models)
    rows = []
    for method, angles in cell.methods.items():
        for a in angles:
            cells = []
            for m in cell.models:
                rs = select(results, cell.key, method, a, m)
                cells.append(f"{pct(rate(rs))} · {med([r.rot_err for r in rs], 'deg')} · "
                             f"{med([r.seconds for r in rs], 's')}" if rs else "-")
            rows.append([METHODS[method], "any" if method in GLOBAL_METHODS else f"{a}°"]
                        + cells)
    return md_table(head, rows)


# ---------------------------------------------------------------------------- targets
def targets(results: list[Trial], cells: list[Cell], have_o3d: bool, param_models,
            quick: bool) -> list[list[str]]:
    keys = {c.key for c in cells}
    rows = []

    def row(text, rs, goal, extra=""):
        r = rate(rs)
        measured = "not measured" if r is None else \
            f"{pct(r)} ({sum(x.success for x in rs)}/{len(rs)}){extra}"
        rows.append([text, measured, status(None if r is None else r >= goal)])

    fit60 = select(results, "full0", "fit", 60)
    row(f"pose only, full clouds, single start: >= {TARGET_60:.0%} success at 60°", fit60,
        TARGET_60)
    row(f"pose only, full clouds, single start: >= {TARGET_90:.0%} success at 90°",
        select(results, "full0", "fit", 90), TARGET_90)
    fit_t = median_or_none([r.seconds for r in select(results, "full0", "fit")])
    o3d_t = median_or_none([r.seconds for r in select(results, "full0", "o3d_icp")])
    if have_o3d and fit_t is not None and o3d_t is not None:
        rows.append(["csdf.fit pose-only median time < Open3D point-to-plane ICP's (full "
                     "clouds, all single-start trials)",
                     f"{fit_t * 1e3:.0f} ms vs {o3d_t * 1e3:.0f} ms ({fit_t / o3d_t:.1f}x)",
                     status(fit_t < o3d_t)])
    else:
        rows.append(["csdf.fit pose-only median time < Open3D point-to-plane ICP's",
                     "Open3D not installed" if not have_o3d else "not measured", "n/a"])
    ms = select(results, "full0", "multistart")
    ms_t = median_or_none([r.seconds for r in ms])
    r = rate(ms)
    rows.append([f"multistart, full clouds: >= {TARGET_MULTI:.0%} success from any rotation "
                 f"(180° start), median <= {TARGET_MULTI_S:g} s",
                 "not measured" if r is None else
                 f"{pct(r)} ({sum(x.success for x in ms)}/{len(ms)}), median "
                 f"{ms_t * 1e3:.0f} ms",
                 status(None if r is None else r >= TARGET_MULTI and ms_t <= TARGET_MULTI_S)])
    row(f"pose only, full clouds with 50% outliers: >= {TARGET_OUTLIERS:.0%} success at 30° "
        "(default `loss='auto'`)", select(results, "full50", "fit", 30), TARGET_OUTLIERS)
    row("(the same with `loss='cauchy'`)", select(results, "full50", "fit_cauchy", 30),
        TARGET_OUTLIERS)
    row("(the same with `loss='huber'`, the default before 'auto')",
        select(results, "full50", "fit_huber", 30), TARGET_OUTLIERS)
    if "partial0" in keys:
        row(f"pose only, single-view partial scans: >= {TARGET_PARTIAL:.0%} success at 30° "
            "(`viewpoint=` the sensor)", select(results, "partial0", "fit_vis", 30),
            TARGET_PARTIAL)
        row("(the same without `viewpoint`)", select(results, "partial0", "fit", 30),
            TARGET_PARTIAL)
    else:
        rows.append(["pose only, single-view partial scans: >= 95% at 30°",
                     "not measured (csdf.scan unavailable)", "n/a"])
    for m in param_models:
        rs = select(results, "params", "fit_params", 30, m)
        t = median_or_none([x.seconds for x in rs])
        r = rate(rs)
        rows.append([f"pose+scale+params, {m}: >= {TARGET_PARAMS:.0%} success at 30° with "
                     f"param errors <= {PARAM_TOL:.0%} of range, median <= "
                     f"{TARGET_PARAMS_S * 1e3:.0f} ms",
                     "not measured" if r is None else
                     f"{pct(r)} ({sum(x.success for x in rs)}/{len(rs)}), median "
                     f"{t * 1e3:.0f} ms",
                     status(None if r is None else r >= TARGET_PARAMS and t <= TARGET_PARAMS_S)])
    return rows


# ---------------------------------------------------------------------------- report
def report(args, command, info, models, model_note, scan_note, o3d_note, cells, results,
           notes, elapsed) -> str:
    L: list[str] = ["# csdf pose and shape recovery benchmark\n"]
    L.append(f"Command: `{command}`  \nTotal benchmark time: {elapsed:.0f} s\n")
    L.append("## Machine\n")
    L.append(md_table(["", ""], [[k, v] for k, v in info.items()]
                      + [["load average at end", loadavg()]]) + "\n")
    L.append("Timings are wall-clock medians of single calls on this machine. Other jobs "
             "running at the same time (see the load averages) inflate them, not necessarily "
             "every method alike (csdf.fit uses both cores through Numba); the methods of a "
             "cell run interleaved, scene by scene, so they share the same conditions.\n")
    if args.quick:
        L.append("**Quick run** (`--quick`): few trials, few cells; the numbers are a smoke "
                 "test, not results.\n")

    L.append("## Setup\n")
    L.append(f"Models: {model_note}. *Size* = diagonal of the bounding box of the surface "
             f"(of {MODEL_POOL:,} `sample_surface` points at the default parameters). "
             f"*Symmetries*: the rotations mapping the surface onto itself, found numerically "
             f"(turns by 360°/n about the coordinate axes and diagonals through the centre of "
             f"`shape.bounds`); errors are taken modulo this group.\n")
    rows = []
    for m in models.values():
        rows.append([m.name, f"{m.size:.4g}", str(len(m.sym)),
                     ", ".join(f"{p.name} [{p.lo:g}, {p.hi:g}]" for p in m.params) or "-",
                     str(len(m.prog))])
    L.append(md_table(["model", "size", "symmetries (group order)", "parameters (range)",
                       "instructions"], rows) + "\n")
    L.append(
        f"* **Full clouds**: {N_POINTS:,} points drawn without replacement from the model's "
        f"{MODEL_POOL:,} surface samples (for the parameter trials: fresh `sample_surface` "
        f"samples at the true parameters), posed by a random rotation and a translation "
        f"~N(0, size²) per axis, with isotropic Gaussian noise of σ = {NOISE:.1%} of the size "
        f"per coordinate.\n"
        f"* **Partial scans**: {scan_note}\n"
        f"* **Outliers**: a random fraction (20% or 50%) "
        f"of the {N_POINTS:,} points replaced by points uniform in the object's bounding box "
        f"grown {OUTLIER_BOX:g}x about its centre, posed like the object.\n"
        f"* **Start**: the true rotation turned by the given angle about a uniformly random "
        f"axis through the object's centre, and the centre moved {T_INIT:.0%} of the size in "
        f"a random direction; scale 1; parameters at their defaults. Every method gets the "
        f"same start on the same cloud.\n"
        f"* **Success**: rotation error < {SUCCESS_DEG:g}° and centre error < "
        f"{SUCCESS_T:.0%} of the size (error of the posed object centre, so independent of "
        f"where the model's origin is), both modulo the symmetries; for pose+scale+params "
        f"also every parameter within {PARAM_TOL:.0%} of its range of the truth. Scale "
        f"error = |s / s_true - 1|. Medians are over all trials, failures included.\n"
        f"* **Seeds**: every scene and start comes from "
        f"`SeedSequence([{BASE_SEED}, model index, cell, trial])`; the multistart subsampling, "
        f"`csdf.icp`'s model sampling and Open3D's RANSAC are seeded from it too. "
        f"csdf.fit's engine, escape step, visibility term, scale hold and bias correction "
        f"were developed on scenes from a different base seed (777); the failure analysis "
        f"of an earlier recorded run with this seed motivated them, but their settings "
        f"were not tuned on it. `loss='auto'` (its 90% switch and its choice between the "
        f"Huber and Cauchy solutions) was developed on scenes from base seed 4242 "
        f"(`--base-seed 4242`), before this run.\n")
    L.append("Methods (wall time of the call; every csdf call is warmed up first, so Numba "
             "kernels are compiled or loaded before timing):\n")
    vox = " and ".join(f"{v:.0%}" for v in FPFH_VOXELS)
    L.append(
        "* `csdf.fit pose`: `csdf.fit(shape, points, init=T0)` (defaults: `loss='auto'` with "
        "`f_scale` 1% of the diagonal of `shape.bounds`, one start, `solver='lm'`: the "
        "hand-written coarse-to-fine robust Levenberg-Marquardt of `csdf.fit.lm`, whose "
        "`escape` step tests turns about the model's axes and the cloud's principal axes "
        "after the coarse stage). `loss='auto'`: the fit is made with the Huber loss; if "
        "fewer than 99% of the points are then within 3 `f_scale` of the surface, the "
        "Huber solution is refined with Cauchy, and below 90% the whole fit is also "
        "redone with Cauchy from the same start; the solution with the lowest Cauchy "
        "cost is returned; otherwise the result is exactly the Huber fit's. "
        "The column *'auto' went on to Cauchy* counts the runs whose result came from a "
        "Cauchy fit (`FitResult.loss`); rows of other methods show '-'. Every row without "
        "a `loss=` label uses the default 'auto' (also escape=False, solver='scipy', "
        "pose+scale, pose+scale+params and multistart).\n"
        "* `csdf.fit pose, loss='huber'`: the same with the Huber loss alone (the default "
        "before 'auto'), for comparison; likewise `viewpoint=sensor, loss='huber'` and "
        "`multistart, loss='huber'`.\n"
        "* `csdf.fit pose, escape=False` (extra): the same without that step (the plain "
        "local solver).\n"
        "* `csdf.fit pose, solver='scipy'` (extra): the same problem solved by SciPy's "
        "`least_squares` (TRF) instead, for the engine comparison.\n"
        "* `csdf.fit pose, loss='cauchy'` (outlier cells): the same with `loss='cauchy'`, "
        "whose optimum the outliers do not pull (Huber's they do).\n"
        "* `csdf.fit pose, viewpoint=sensor` (partial scans): the same with "
        "`viewpoint=(0, 0, 0)` (the sensor's position in the scan's frame): points matched "
        "to back faces are re-matched to the first hit of their ray (`csdf.fit.lm`); with "
        "outliers also with `loss='cauchy'`.\n"
        "* `csdf.fit pose+scale` / `pose+scale+params`: the same with `estimate=('pose', "
        "'scale')` / `('pose', 'scale', 'params')` (all parameters). With parameters, "
        "`csdf.fit` holds the scale at its start when the parameters can imitate a uniform "
        "resize (the chair: every dimension is a parameter; noted in `FitResult.notes`) and "
        "corrects the noise bias of the parameters (`debias`, on by default).\n"
        "* `csdf.fit multistart`: `multistart=True, seed=...` (independent of the start "
        "rotation; run from the 180° start; on partial scans also `viewpoint=`).\n"
        "* `csdf.icp`: the library's point-to-plane ICP baseline (it meshes and samples the "
        "model in every call; that time is included).\n"
        f"* `Open3D ICP`: `registration_icp` with `TransformationEstimationPointToPlane`: the "
        f"scene cloud registered to 20,000 `sample_surface` points of the model with exact "
        f"normals (built once per model, not timed), correspondence distance "
        f"{O3D_THRESHOLD:.0%} of the size, at most 60 iterations, same start; the timed call "
        f"includes wrapping the scene in a `PointCloud`. {o3d_note}\n"
        f"* `Open3D FPFH+RANSAC (+ICP)`: for voxel sizes {vox} of the size: both clouds "
        f"voxel-downsampled, normals estimated (radius 2 voxels) and FPFH features computed "
        f"(radius 5 voxels) the same way on both sides, "
        f"`registration_ransac_based_on_feature_matching` (mutual filter, distance 1.5 "
        f"voxels, edge-length 0.9 and distance checkers, at most 100k iterations, confidence "
        f"0.999), then the point-to-plane ICP above; the voxel size whose result has the most "
        f"scene points within {FPFH_SELECT:.1%} of the size of the model wins. Global: the "
        f"start is not used. The model side is prepared once per model, not timed.\n")
    L.append(
        "*Failure diagnosis* (csdf.fit rows): each failed run is compared with a second "
        "`csdf.fit` of the same kind started at the true pose (scale, parameters). "
        "**local min**: that fit succeeds and has a lower robust cost (the loss of the row, "
        "for 'auto' rows the loss the failed run ended with; residual scale 1% of the "
        "size), so the failed run stopped in a local minimum; "
        "**off optimum**: even the fit started at the truth fails the success test, so the "
        "optimum itself is off (bias from noise, outliers or the partial view, or a "
        "scale/parameter trade-off): no start would have succeeded; **other**: the "
        "truth-started fit succeeds but the failed one reached as low a cost (an ambiguity "
        "not covered by the symmetry group). The second fit is not timed.\n")

    L.append("## Results\n")
    L.append("Rows: method and initial rotation error; success rate; medians over the trials "
             "(all models pooled). *Centre error* in % of the object size.\n")
    for cell in cells:
        L.append(f"### {cell.title}\n")
        L.append(f"Models: {', '.join(cell.models)}; {cell.trials} scenes per model.\n")
        if cell.truth_backface:
            L.append(
                "*Back-facing points*: share of the scan's points (outliers not counted) whose "
                "nearest surface of the model, at the result's pose, faces away from the "
                "camera (the sensor cannot see those faces; the signed-distance residual does "
                f"not know that). At the true poses: median {med(cell.truth_backface, '%')} "
                "(noise and grazing returns on thin parts).\n")
        L.append(cell_table(cell, results) + "\n")
    L.append("### Per model\n")
    L.append("Each entry: success rate · median rotation error · median time.\n")
    for cell in cells:
        L.append(f"**{cell.title}**\n")
        L.append(per_model_table(cell, results) + "\n")

    L.append("## Targets\n")
    if args.quick:
        L.append("(Quick run: too few trials for these to mean much.)\n")
    L.append(md_table(["target", "measured", "result"],
                      targets(results, cells, o3d_note == "", args.param_models, args.quick))
             + "\n")
    if notes:
        L.append("## Notes\n")
        L.append("\n".join(f"* {n}" for n in notes) + "\n")
    L.append("## Raw samples\n")
    L.append("<details><summary>every run: time (ms) / rotation error (degrees), in trial "
             "order (models in the order listed, scenes in seed order); * = success</summary>"
             "\n")
    rows = []
    for cell in cells:
        for method, angles in cell.methods.items():
            for a in angles:
                for m in cell.models:
                    rs = select(results, cell.key, method, a, m)
                    if rs:
                        rows.append([cell.key, METHODS[method], f"{a}°", m, " ".join(
                            f"{r.seconds * 1e3:.0f}/{r.rot_err:.2f}{'*' if r.success else ''}"
                            for r in rs)])
    L.append(md_table(["cell", "method", "start", "model", "runs"], rows))
    L.append("\n</details>\n")
    return "\n".join(L)


# ---------------------------------------------------------------------------- main
def warm_up(models: dict[str, Model], runner: Runner, have_o3d: bool) -> None:
    """Calls that compile or load every kernel the timed calls use (per model: the fit's
    Jacobian, multistart's value+gradient, the visibility term's ray casting), and Open3D's
    first call; on full-size clouds (csdf.fit picks the compiled backend from 2,000
    points), not timed."""
    for i, m in enumerate(models.values()):
        rng = np.random.default_rng(1)
        scene = full_scene(m, 0.0, rng)
        init = initial_pose(scene, 10, rng)
        methods = ["fit", "fit_params", "multistart", "fit_vis", "fit_scipy"]
        if have_o3d and i == 0:
            methods += ["o3d_icp", "o3d_fpfh"]
        for meth in methods:
            out = runner.run(meth, scene, init, 1)
            if out.error:
                log(f"  warm-up {m.name} {meth}: {out.error}")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--quick", action="store_true", help="smoke test: 3 trials, fewer cells")
    p.add_argument("--trials", type=int,
                   help="scenes per model, no-outlier cells (default 8; 1 with --quick)")
    p.add_argument("--outlier-trials", type=int,
                   help="scenes per model, outlier and scale cells (default 5; 1 with --quick)")
    p.add_argument("--param-trials", type=int,
                   help="scenes per model for pose+scale+params (default 10; 2 with --quick)")
    p.add_argument("--models", nargs="+", default=list(MODELS))
    p.add_argument("--param-models", nargs="+", default=list(PARAM_MODELS))
    p.add_argument("--no-zoo", action="store_true", help="use the local stand-in models")
    p.add_argument("--no-open3d", action="store_true", help="skip the Open3D rows")
    p.add_argument("--no-scan", action="store_true", help="skip the partial-scan cells")
    p.add_argument("--output", type=Path, default=HERE / "FIT_RESULTS.md")
    p.add_argument("--base-seed", type=int, default=BASE_SEED,
                   help=f"base of every scene's seed (default {BASE_SEED}, the recorded run; "
                   "develop on others)")
    args = p.parse_args(argv)
    set_base_seed(args.base_seed)
    if args.trials is None:
        args.trials = 1 if args.quick else 8
    if args.outlier_trials is None:
        args.outlier_trials = 1 if args.quick else 5
    if args.param_trials is None:
        args.param_trials = 2 if args.quick else 10
    command = "python " + " ".join(shlex.quote(a) for a in
                                   ["benchmarks/bench_fit.py", *sys.argv[1:]])
    t_start = time.perf_counter()

    o3d, o3d_note = None, ""
    if args.no_open3d:
        o3d_note = "Skipped (--no-open3d): no Open3D rows."
    else:
        try:
            import open3d as o3d  # noqa: F811

            o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
        except Exception as exc:
            o3d = None
            o3d_note = (f"Open3D is not importable ({err_text(exc)}): its rows are skipped "
                        "(install it with `pip install open3d`, or the `bench` extra).")
            log(o3d_note)
    import scipy

    info = machine_info({"SciPy": scipy.__version__,
                         "Open3D": o3d.__version__ if o3d is not None else "not used"})
    for k, v in info.items():
        log(f"{k}: {v}")

    if args.no_zoo:
        args.models, args.param_models = ["bracket", "shaft"], ["bracket", "shaft"]
    shapes, model_note = load_models(sorted(set(args.models) | set(args.param_models)),
                                     not args.no_zoo)
    if set(shapes) != set(args.models) | set(args.param_models):  # stand-ins took over
        args.models = args.param_models = sorted(shapes)
    scanner = (None, "--no-scan") if args.no_scan else get_scanner()
    have_scan = scanner[0] is not None
    if have_scan:
        scan_note = (
            f"`csdf.scan` of the model in a random pose, seen by a `csdf.Camera.look_at` "
            f"camera from a uniformly random direction (random up vector), 45° field of "
            f"view, at the distance where the bounding sphere fills the view, 256x256 pixels "
            f"(doubled until at least {N_POINTS:,} points are seen); range noise σ = "
            f"{NOISE:.1%} of the size along the rays (`noise=`); subsampled to "
            f"{N_POINTS:,} points; fitted in the camera frame.")
    else:
        scan_note = f"not run (`csdf.scan` unavailable: {scanner[1]})."
        log(f"partial scans skipped: {scanner[1]}")

    log("\nbuilding models (surface pool, symmetry group) ...")
    models = {}
    for name, shape in shapes.items():
        t0 = time.perf_counter()
        models[name] = build_model(name, shape)
        m = models[name]
        log(f"  {name}: size {m.size:.4g}, {len(m.sym)} symmetries, {len(m.params)} params "
            f"({time.perf_counter() - t0:.1f} s)")
    runner = Runner(o3d, models)
    log("warming up ...")
    warm_up(models, runner, o3d is not None)

    cells = make_cells(args, o3d is not None, have_scan, tuple(args.models),
                       tuple(args.param_models))
    results: list[Trial] = []
    notes: list[str] = []
    for cell in cells:
        run_cell(cell, models, runner, scanner, results, notes)
    elapsed = time.perf_counter() - t_start
    text = report(args, command, info, models, model_note, scan_note, o3d_note, cells,
                  results, notes, elapsed)
    print("\n" + text)
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(text)
    log(f"\nwritten to {args.output} ({elapsed:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
