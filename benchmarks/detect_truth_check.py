"""Does each clutter scene's stored truth match the points that were scanned of it?

For every zoo object of the seeded clutter scenes of ``bench_detect.py`` (issue 19):
the model's signed distance, at the stored pose and parameters, at the scan points
whose instance label is that object's: mean of its absolute value and its mean (mm),
both also as a fraction of the scene's range-noise level ``sigma``. Range noise along
the rays puts a right truth's mean ``|f|`` under about ``0.8 sigma`` (a ray's error
projected on the surface normal; 0.3-0.6 sigma on the saved scans); a truth whose
parameters or pose are not those of the scanned solid shows up far above it. Objects
over ``--limit`` (default 1.0) sigma are flagged.

Run: ``python benchmarks/detect_truth_check.py --scene-cache DIR [--scenes 10]
[--first-scene 0] [--limit 1.0]``; exit status 1 when an object is flagged.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_detect import _cached_scene  # noqa: E402

import csdf  # noqa: E402


def check(seeds: range, cache: str | None, limit: float) -> tuple[list[str], int]:
    """``(report lines, number of flagged objects)`` for the scenes ``seeds``."""
    models: dict[str, csdf.Shape] = {}
    lines, flagged = [], 0
    for seed in seeds:
        sc = _cached_scene(seed, cache)
        sigma = float(sc["noise"])
        for tr in sc["truth"]:
            name = tr["model"]
            if name not in models:
                models[name] = csdf.zoo.load(name)
            pts = sc["points"][sc["instance"] == tr["instance"]]  # (M, 3) camera frame
            local = tr["pose"].inverse().apply(pts)                 # (M, 3) model frame
            f = np.asarray(models[name](local, params=tr["params"]), dtype=float)  # (M,) m
            mean_abs = float(np.abs(f).mean())
            bad = mean_abs > limit * sigma
            flagged += int(bad)
            lines.append(f"seed {seed:3d} id {tr['instance']} {name:10s} {len(pts):6d} pts  "
                         f"mean |f| {mean_abs * 1e3:6.2f} mm ({mean_abs / sigma:4.2f} sigma)"
                         f"  mean f {f.mean() * 1e3:6.2f} mm{'  <-- MISMATCH' if bad else ''}")
    return lines, flagged


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene-cache", default=None, metavar="DIR")
    ap.add_argument("--scenes", type=int, default=10)
    ap.add_argument("--first-scene", type=int, default=0)
    ap.add_argument("--limit", type=float, default=1.0,
                    help="flag mean |f| over this many noise levels")
    a = ap.parse_args()
    lines, flagged = check(range(a.first_scene, a.first_scene + a.scenes), a.scene_cache,
                           a.limit)
    print("\n".join(lines))
    print(f"{flagged} of {len(lines)} objects over {a.limit:g} sigma")
    return 1 if flagged else 0


if __name__ == "__main__":
    sys.exit(main())
