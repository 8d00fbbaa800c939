"""Per-scene summary of :func:`csdf.detect` on the seeded clutter scenes of
``bench_detect.py`` (issue 19): for every ground-truth object the best MSSD (over its
symmetries, as a fraction of its diameter) of any detection of its model, the turn
about its axis of that detection against the truth (degrees, before the symmetries),
and found or missed; for every detection its points and which scene instances they
belong to (-1: outliers; a distractor's or another object's id shows a false
positive's source). The truth is only reported.

Run: ``python benchmarks/detect_summary.py --scene-cache DIR [--scenes 10]
[--first-scene 0]``.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_detect import MSSD_THRESHOLD, _cached_scene, _match, _model_points  # noqa: E402
from detect_scenes import CLUTTER_MODELS  # noqa: E402

import csdf  # noqa: E402
from csdf.metrics import mssd  # noqa: E402


def _turn(gt: csdf.Pose, est: csdf.Pose) -> float:
    """The turn (degrees) about the truth's z axis from pose ``gt`` to pose ``est``."""
    R = gt.rotation.T @ est.rotation
    return math.degrees(math.atan2(R[1, 0], R[0, 0]))


def summary(seeds: range, cache: str | None) -> list[str]:
    """The summary lines of the scenes ``seeds`` (saved in / loaded from ``cache``)."""
    scenes = {s: _cached_scene(s, cache) for s in seeds}
    out, found, total, false, secs = [], 0, 0, 0, 0.0
    for s, sc in scenes.items():
        for tr in sc["truth"]:
            tr["_points"] = _model_points(tr["model"], tr["params"])
        t0 = time.perf_counter()
        dets = csdf.detect(sc["points"], list(CLUTTER_MODELS), viewpoint=(0.0, 0.0, 0.0),
                           seed=0)
        sec = time.perf_counter() - t0
        f, fp, _ = _match([(d.model, d.pose) for d in dets], sc["truth"])
        found, total, false, secs = found + f, total + len(sc["truth"]), false + fp, secs + sec
        out.append(f"scene {s}: {f}/{len(sc['truth'])} found, {fp} false, {sec:.2f} s")
        for tr in sc["truth"]:
            errs = [(mssd(tr["_points"], d.pose, tr["pose"], tr.get("symmetries"))
                     / tr["diameter"], i) for i, d in enumerate(dets) if d.model == tr["model"]]
            e, i = min(errs) if errs else (math.inf, -1)
            turn = f"turn {_turn(tr['pose'], dets[i].pose):+.0f}" if i >= 0 else ""
            seen = int(np.count_nonzero(sc["instance"] == tr["instance"]))
            out.append(f"   {tr['model']:9s} #{tr['instance']} {seen:5d} points  best "
                       f"{e:.3f} (det {i}) {turn} "
                       f"{'found' if e < MSSD_THRESHOLD else 'MISSED'}")
        for i, d in enumerate(dets):
            ids, counts = np.unique(sc["instance"][d.inliers], return_counts=True)
            owners = dict(zip(ids.tolist(), counts.tolist()))
            out.append(f"   det {i}: {d.model} {len(d.inliers)} points, score "
                       f"{d.score:.2f}, instances {owners}")
    out.append(f"recall {found}/{total} = {found / max(total, 1):.1%}, false positives "
               f"{false / max(len(scenes), 1):.2f} a scene, {secs / max(total, 1):.2f} s "
               "an object (the first scene includes loading the models' kernels)")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenes", type=int, default=10)
    ap.add_argument("--first-scene", type=int, default=0)
    ap.add_argument("--scene-cache", default=None, metavar="DIR",
                    help="save the clutter scenes here on the first run, load them after")
    a = ap.parse_args()
    print("\n".join(summary(range(a.first_scene, a.first_scene + a.scenes), a.scene_cache)))


if __name__ == "__main__":
    main()
