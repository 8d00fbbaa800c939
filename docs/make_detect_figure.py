"""Draw ``docs/detect.png``: one of the detection benchmark's seeded cluttered scans
(``benchmarks/detect_scenes.py``) with what :func:`csdf.detect` finds in it, as
``csdf detect --picture`` draws it.

Run: ``python docs/make_detect_figure.py [--seed 5]`` (about ten seconds).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from PIL import Image

import csdf
from csdf.detect.picture import detections_picture

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "benchmarks"))

from detect_scenes import CLUTTER_MODELS, clutter_scene  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seed", type=int, default=5)
    ap.add_argument("--out", type=Path, default=HERE / "detect.png")
    a = ap.parse_args()
    sc = clutter_scene(a.seed)
    dets = csdf.detect(sc["points"], list(CLUTTER_MODELS), normals=sc["normals"],
                       viewpoint=sc["viewpoint"], seed=0)
    img = detections_picture(sc["points"], dets, np.asarray(sc["viewpoint"], float))
    tmp = a.out.with_suffix(".tmp.png")
    Image.fromarray(img).save(tmp)
    tmp.replace(a.out)
    truth = ", ".join(t["model"] for t in sc["truth"])
    found = ", ".join(d.model for d in dets)
    print(f"wrote {a.out}: scene {a.seed} holds {truth}; found {found}")


if __name__ == "__main__":
    main()
