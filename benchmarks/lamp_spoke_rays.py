"""How much a scan tells about a lamp's turn, and whether :func:`csdf.detect` got it
(issue 19).

The zoo lamp is symmetric about its axis but for three 5 mm spokes under its shade
(its symmetries are its three 120-degree turns), so its turn shows only in the rays
that meet a spoke. For every lamp of the seeded clutter scenes of ``bench_detect.py``
this counts its *spoke rays*: the rays of its own scan points along which the true
lamp, ray-cast from the viewpoint, hits first at least two noise levels nearer than the
same lamp without its spokes (or hits where that one misses). It then runs
:func:`csdf.detect` and matches as the benchmark does (MSSD < 0.1 of the diameter over
the symmetries), and prints per lamp the spoke rays and the outcome, then the count of
lamps found and missed at each number of spoke rays. The truth is used only to report.

Run: ``python benchmarks/lamp_spoke_rays.py --first 200 --scenes 20 --scene-cache DIR``
(the scenes are made and saved there when missing, as ``bench_detect.py`` does).
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_detect import _cached_scene, _matches, _model_points  # noqa: E402
from detect_scenes import CLUTTER_MODELS  # noqa: E402

import csdf  # noqa: E402
from csdf.render.trace import sphere_trace, trace_field  # noqa: E402

#: the spokes' term of the zoo lamp's export line
SPOKES = " | spoke.repeat_polar(3).color((0.62, 0.64, 0.67))"
#: the lamp's bounds in its frame, padded (metres): the tracers' box
BOX = np.array([[-0.3, -0.3, -0.05], [0.3, 0.3, 0.8]])
#: spoke-ray counts of this many or more share the table's last row
TOP = 6


def lamp_shapes() -> tuple[csdf.Shape, csdf.Shape]:
    """The zoo lamp, and the same lamp without its spokes."""
    text = (Path(csdf.zoo.__file__).parent / "lamp.csdf").read_text()
    if SPOKES not in text:
        raise SystemExit("lamp.csdf's export line changed: update SPOKES")
    return csdf.loads(text), csdf.loads(text.replace(SPOKES, ""))


def spoke_rays(points: np.ndarray, pose: csdf.Pose, params: dict, sigma: float,
               shapes: tuple) -> int:
    """The number of the lamp's scan points ``points`` ``(N, 3)`` (viewpoint at the
    origin) whose rays meet a spoke of the true lamp (pose, parameters) first, by
    more than ``2 sigma`` (metres) ahead of the lamp without spokes."""
    R, t = np.asarray(pose.rotation), np.asarray(pose.translation)
    D = points / np.linalg.norm(points, axis=1, keepdims=True)
    O = np.broadcast_to(-R.T @ t, D.shape)
    Dm = np.ascontiguousarray(D @ R)
    ta, tb = (sphere_trace(trace_field(s, params, "auto", BOX, check_ranges=False),
                           np.ascontiguousarray(O), Dm).t for s in shapes)
    return int(np.sum(np.isfinite(ta) & (~np.isfinite(tb) | (tb - ta > 2.0 * sigma))))


def found_lamps(dets: list, truth: list[dict]) -> set[int]:
    """The instances of the lamps of ``truth`` that ``dets`` match (``bench_detect.py``'s
    greedy matching, all models at once)."""
    pairs = _matches([(d.model, d.pose) for d in dets], truth)
    return {truth[j]["instance"] for _, _, j in pairs if truth[j]["model"] == "lamp"}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--first", type=int, default=0, help="first scene seed")
    ap.add_argument("--scenes", type=int, default=10, help="number of scenes")
    ap.add_argument("--scene-cache", default=None, help="folder of saved scenes")
    a = ap.parse_args()
    shapes = lamp_shapes()
    table: Counter = Counter()
    for s in range(a.first, a.first + a.scenes):
        sc = _cached_scene(s, a.scene_cache)
        lamps = [tr for tr in sc["truth"] if tr["model"] == "lamp"]
        if not lamps:
            continue
        for tr in sc["truth"]:
            tr["_points"] = _model_points(tr["model"], tr["params"])
        dets = csdf.detect(sc["points"], list(CLUTTER_MODELS), viewpoint=(0.0, 0.0, 0.0),
                           seed=0)
        found = found_lamps(dets, sc["truth"])
        for tr in lamps:
            pts = sc["points"][sc["instance"] == tr["instance"]]
            k = spoke_rays(pts, tr["pose"], tr["params"], sc["noise"], shapes)
            ok = tr["instance"] in found
            table[(min(k, TOP), ok)] += 1
            print(f"scene {s} lamp #{tr['instance']}: {len(pts)} points, {k} spoke rays, "
                  f"noise {1000 * sc['noise']:.1f} mm: {'found' if ok else 'missed'}",
                  flush=True)
    print("\n| spoke rays | lamps found | lamps missed |\n|---|---|---|")
    for k in range(TOP + 1):
        if table[(k, True)] or table[(k, False)]:
            label = f"{k}+" if k == TOP else str(k)
            print(f"| {label} | {table[(k, True)]} | {table[(k, False)]} |")


if __name__ == "__main__":
    main()
