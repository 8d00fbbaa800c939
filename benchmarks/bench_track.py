"""Tracking depth video (issue 18): seeded synthetic sequences of zoo models
(``csdf.synth.sequence``: smooth motion, range-dependent noise, outliers, dropouts at
grazing angles, an occluder passing in front), the RBOT protocol, and the BOP-style
scores.

Methods, on the same sequences:

* ``track: depth + silhouette``: :class:`csdf.fit.Tracker` with the masks;
* ``track: depth only``: the same without masks (clutter gated by distance to the
  predicted model);
* ``track: depth + colour``: depth only plus the colour images
  (``csdf.synth.sequence(colors=True)``: the object in its colours, the occluder in
  another, before a random two-colour background) through ``fit_depth``'s
  region-based colour term;
* ``silhouette only``: :func:`csdf.fit_silhouette` on each frame's mask from the
  constant-velocity prediction;
* ``csdf.fit per frame``: :func:`csdf.fit` on the frame's back-projected masked points
  from the previous pose (``viewpoint`` the camera);
* ``Open3D ICP``: point-to-plane ICP from the previous pose, model surface samples to
  the frame's masked points (the ``bench`` extra; skipped without Open3D).

RBOT protocol: a frame is tracked when its rotation is within 5 degrees and its
translation within 5 % of the model's diameter of the truth; after a failure the method
restarts from the truth. Occluded frames are those where the occluder hides at least 25 %
of the object (``visib_fract <= 0.75``). ADD-S AUC integrates the fraction of frames
whose ADD-S is below a threshold up to 10 % of the diameter (``csdf.metrics.auc``).

Beside the sequences: silhouette-only fits of single frames from starts turned 20
degrees, and the tracked shape parameters of the chair and the cross shaft after 30
frames (sequences made at other parameter values than the defaults the tracker starts
from).

Run: ``python benchmarks/bench_track.py [--sequences 20] [--frames 60]`` (Open3D from
``pip install 'csdf[bench]'``; ``--no-open3d`` skips it).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import machine_info, md_table  # noqa: E402

from csdf.synth import MIN_COS, NOISE_QUAD  # noqa: E402

MODELS = ["chair", "cross_shaft", "flange", "gear", "electrical_box"]
ROT_DEG, TRANS_FRAC = 5.0, 0.05
OCCLUDED = 0.75


def _rot_err(Ra: np.ndarray, Rb: np.ndarray) -> float:
    c = (np.trace(Ra.T @ Rb) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def _predict(pose, prev):
    import csdf

    if prev is None:
        return pose
    return csdf.Pose.nearest(pose.matrix @ np.linalg.inv(prev.matrix) @ pose.matrix)


class _Method:
    """One tracker under the RBOT protocol: ``step(k, depth, mask) -> pose``,
    ``reset(pose)``."""

    name = ""

    def reset(self, pose) -> None:
        self.pose, self.prev = pose, None

    def predicted(self):
        return _predict(self.pose, self.prev)

    def accept(self, pose) -> None:
        self.prev, self.pose = self.pose, pose


class TrackMethod(_Method):
    def __init__(self, shape, camera, init, masks: bool, colors: bool = False):
        from csdf.fit import Tracker

        self.name = "track: depth + silhouette" if masks else (
            "track: depth + colour" if colors else "track: depth only")
        self.masks, self.colors = masks, colors
        self.t = Tracker(shape, camera, init, masks=masks)

    def reset(self, pose) -> None:
        self.t.reset(pose)

    def step(self, depth, mask, color=None):
        return self.t.update(depth, mask if self.masks else None,
                             color if self.colors else None).pose


class SilhouetteMethod(_Method):
    name = "silhouette only"

    def __init__(self, shape, camera, init):
        self.shape, self.camera = shape, camera
        self.reset(init)

    def step(self, depth, mask):
        import csdf

        if not mask.any():
            return self.predicted()
        res = csdf.fit_silhouette(self.shape, mask, self.camera, init=self.predicted(),
                                  max_rays=200, max_iter=20)
        pose = csdf.Pose.nearest(res.transform)
        self.accept(pose)
        return pose


class FitMethod(_Method):
    name = "csdf.fit per frame"

    def __init__(self, shape, camera, init):
        self.shape, self.camera = shape, camera
        self.reset(init)

    def step(self, depth, mask):
        import csdf
        from csdf.fit import backproject

        pts, _ = backproject(depth, self.camera, mask)
        if len(pts) < 20:
            return self.predicted()
        if len(pts) > 2000:
            pts = pts[np.random.default_rng(0).choice(len(pts), 2000, replace=False)]
        res = csdf.fit(self.shape, pts, init=self.predicted(), viewpoint=np.zeros(3),
                       escape=False, max_iter=30)
        pose = csdf.Pose.nearest(res.transform)
        self.accept(pose)
        return pose


class ICPMethod(_Method):
    name = "Open3D ICP (point-to-plane)"

    def __init__(self, o3d, shape, camera, init):
        import csdf

        self.o3d, self.camera = o3d, camera
        pts, nrm = csdf.sample_surface(shape, 3000, seed=0)[:2]
        src = o3d.geometry.PointCloud()
        src.points = o3d.utility.Vector3dVector(pts)
        src.normals = o3d.utility.Vector3dVector(nrm)
        self.src = src
        box = csdf.as_field(shape).model_bounds
        self.radius = 0.05 * float(np.linalg.norm(box[1] - box[0]))
        self.reset(init)

    def step(self, depth, mask):
        import csdf
        from csdf.fit import backproject

        o3d = self.o3d
        pts, _ = backproject(depth, self.camera, mask)
        if len(pts) < 20:
            return self.predicted()
        tgt = o3d.geometry.PointCloud()
        tgt.points = o3d.utility.Vector3dVector(pts)
        tgt.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=self.radius,
                                                                  max_nn=30))
        reg = o3d.pipelines.registration
        out = reg.registration_icp(self.src, tgt, self.radius, self.predicted().matrix,
                                   reg.TransformationEstimationPointToPlane(),
                                   reg.ICPConvergenceCriteria(max_iteration=30))
        pose = csdf.Pose.nearest(np.asarray(out.transformation))
        self.accept(pose)
        return pose


def run_sequence(method, seq, pts, diam) -> dict:
    """One method over one sequence under the RBOT protocol."""
    from csdf import metrics

    ok, occl, adds, secs, resets = [], [], [], [], 0
    method.reset(seq.poses[0])
    for k in range(len(seq)):
        t0 = time.perf_counter()
        if seq.colors is not None and isinstance(method, TrackMethod):
            pose = method.step(seq.depth[k], seq.masks[k], seq.colors[k])
        else:
            pose = method.step(seq.depth[k], seq.masks[k])
        secs.append(time.perf_counter() - t0)
        gt = seq.poses[k]
        good = (_rot_err(pose.rotation, gt.rotation) < ROT_DEG
                and np.linalg.norm(pose.translation - gt.translation) < TRANS_FRAC * diam)
        ok.append(good)
        occl.append(seq.visib_fract[k] <= OCCLUDED)
        adds.append(metrics.adds(pts, pose, gt))
        if not good:
            resets += 1
            method.reset(gt)
    return {"ok": ok, "occluded": occl, "adds": adds, "seconds": secs, "resets": resets}


def silhouette_starts(models, n: int, seed: int, width: int, height: int) -> list:
    """Single-frame silhouette fits from starts turned 20 degrees: rotation errors."""
    import csdf

    rng = np.random.default_rng(seed)
    errs = []
    for name in models:
        shape = csdf.zoo.load(name)
        seq = csdf.synth.sequence(shape, n_frames=n, seed=int(rng.integers(1 << 30)),
                                  width=width, height=height)
        for k in range(n):
            gt = seq.poses[k]
            w = rng.normal(size=3)
            turn = csdf.Pose.from_rotvec(w / np.linalg.norm(w) * np.radians(20))
            start = csdf.Pose(turn.rotation @ gt.rotation, gt.translation)
            res = csdf.fit_silhouette(shape, seq.masks[k], seq.camera, init=start)
            errs.append(_rot_err(res.rotation, gt.rotation))
    return errs


def tracked_params(frames: int, seed: int, width: int, height: int) -> list[list[str]]:
    """Chair and cross shaft made at other parameter values: the tracked estimate after
    ``frames`` frames, as a fraction of each parameter's range."""
    import csdf

    rows = []
    for name in ("chair", "cross_shaft"):
        shape = csdf.zoo.load(name)
        prog = shape.compile()
        rng = np.random.default_rng(seed)
        truth = {}
        for p in prog.params:  # a value a quarter of the range from the default
            span = p.hi - p.lo
            sign = 1.0 if p.default + 0.25 * span <= p.hi else -1.0
            truth[p.name] = p.default + sign * 0.25 * span * rng.uniform(0.6, 1.0)
        seq = csdf.synth.sequence(shape, n_frames=frames, seed=seed, params=truth,
                                  width=width, height=height)
        t0 = time.perf_counter()
        run = csdf.track(shape, seq.depth, seq.camera, seq.poses[0], masks=seq.masks,
                         estimate=("pose", "params"))
        sec = (time.perf_counter() - t0) / frames
        est = run[-1].params
        errs = {p.name: abs(est[p.name] - truth[p.name]) / (p.hi - p.lo) for p in prog.params}
        worst = max(errs, key=errs.get)
        rows.append([name, f"{len(errs)}", f"{np.median(list(errs.values())):.2%}",
                     f"{errs[worst]:.2%} ({worst})",
                     f"{np.mean([v <= 0.02 for v in errs.values()]):.0%}",
                     f"{sec * 1e3:.0f}"])
    return rows


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--sequences", type=int, default=20, help="per model")
    p.add_argument("--frames", type=int, default=60)
    p.add_argument("--occlusion", type=float, default=0.3)
    p.add_argument("--width", type=int, default=320)
    p.add_argument("--height", type=int, default=240)
    p.add_argument("--models", default=",".join(MODELS))
    p.add_argument("--no-open3d", action="store_true")
    p.add_argument("--noise-scale", type=float, default=1.0,
                   help="depth noise as a multiple of Kinect v1's (csdf.synth.NOISE_QUAD)")
    p.add_argument("--min-cos", type=float, default=MIN_COS,
                   help="depth returns drop out where |n . ray| is below this (0.2: "
                   "grazing angles only; larger: a sensor that loses dark or shiny "
                   "surfaces and every silhouette edge)")
    p.add_argument("--no-colors", action="store_true",
                   help="no colour images, no depth + colour row")
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)
    import csdf
    from csdf import metrics

    o3d = None
    if not args.no_open3d:
        try:
            import open3d as o3d

            o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
        except ImportError:
            print("Open3D is not installed (pip install 'csdf[bench]'): no ICP rows")
    models = [m for m in args.models.split(",") if m]
    print("\n".join(f"* {k}: {v}" for k, v in machine_info().items()))
    print(f"* sequences: {args.sequences} per model x {len(models)} models, {args.frames} "
          f"frames at {args.width}x{args.height}, occluder covering up to "
          f"{args.occlusion:.0%}, depth noise {args.noise_scale:g} x Kinect v1's, "
          f"dropouts below |n . ray| = {args.min_cos:g}")
    stats: dict[str, list[dict]] = {}
    per_model: dict[tuple[str, str], list[dict]] = {}
    diam_of = {}
    t_all = time.perf_counter()
    for mi, name in enumerate(models):
        shape = csdf.zoo.load(name)
        pts = metrics.model_points(shape, 2000)
        diam = metrics.diameter(pts)
        diam_of[name] = diam
        for s in range(args.sequences):
            seq = csdf.synth.sequence(shape, n_frames=args.frames,
                                      seed=args.seed + 1000 * mi + s,
                                      occlusion=args.occlusion, width=args.width,
                                      height=args.height, colors=not args.no_colors,
                                      noise_quad=NOISE_QUAD * args.noise_scale,
                                      min_cos=args.min_cos)
            methods = [TrackMethod(shape, seq.camera, seq.poses[0], True),
                       TrackMethod(shape, seq.camera, seq.poses[0], False)]
            if not args.no_colors:
                methods.append(TrackMethod(shape, seq.camera, seq.poses[0], False, True))
            methods += [SilhouetteMethod(shape, seq.camera, seq.poses[0]),
                        FitMethod(shape, seq.camera, seq.poses[0])]
            if o3d is not None:
                methods.append(ICPMethod(o3d, shape, seq.camera, seq.poses[0]))
            for m in methods:
                r = run_sequence(m, seq, pts, diam)
                r["diam"] = diam
                stats.setdefault(m.name, []).append(r)
                per_model.setdefault((m.name, name), []).append(r)
        print(f"  {name}: done ({time.perf_counter() - t_all:.0f} s)", flush=True)

    def summary(runs: list[dict]) -> list[str]:
        ok = np.concatenate([r["ok"] for r in runs])
        occ = np.concatenate([r["occluded"] for r in runs])
        adds = np.concatenate([np.asarray(r["adds"]) / r["diam"] for r in runs])
        secs = np.concatenate([r["seconds"] for r in runs])
        return [f"{ok.mean():.1%}", f"{ok[occ].mean():.1%} of {occ.sum()}" if occ.any()
                else "-", f"{metrics.auc(adds, 0.1):.3f}",
                f"{statistics.median(secs) * 1e3:.1f}",
                f"{sum(r['resets'] for r in runs)}"]

    print()
    print(md_table(["method", "frames tracked", "occluded frames tracked",
                    "ADD-S AUC (10 % of diameter)", "median ms per frame", "resets"],
                   [[name, *summary(runs)] for name, runs in stats.items()]))
    print()
    first = next(iter(stats))
    print(md_table(["model", "diameter m", f"{first}: tracked", "occluded tracked",
                    "ADD-S AUC", "median ms", "resets"],
                   [[name, f"{diam_of[name]:.3f}", *summary(per_model[(first, name)])]
                    for name in models]))
    tracks = [m for m in stats if m.startswith("track:")]
    print()
    print(md_table(["model"] + [f"{m}: tracked / ADD-S AUC" for m in tracks],
                   [[name] + [" / ".join(summary(per_model[(m, name)])[i] for i in (0, 2))
                              for m in tracks] for name in models]))
    errs = silhouette_starts(models, 6, args.seed + 7, args.width, args.height)
    print(f"\nsilhouette only, one view, starts turned 20 degrees ({len(errs)} frames): "
          f"median rotation error {np.median(errs):.2f} degrees (90th percentile "
          f"{np.percentile(errs, 90):.2f})")
    print()
    print(md_table(["model", "parameters", "median error after 30 frames (of range)",
                    "worst", "within 2 %", "ms per frame"],
                   tracked_params(30, args.seed + 11, args.width, args.height)))
    print(f"\ntotal {time.perf_counter() - t_all:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
