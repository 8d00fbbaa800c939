"""Colours cost nothing when only geometry is asked for (issue 24).

For each coloured zoo model: the distance at 10^6 uniform points in its box, for the
coloured model and for the same model with its ``color(...)`` calls taken out of the
source (the uncoloured twin), in the same run; then the cost of the colours themselves
(``csdf.colors.colors_at`` on the same points). Medians of ``--repeat`` runs after a
warm-up call (which compiles the kernels).

Run: ``python benchmarks/bench_colors.py [--points 1000000] [--repeat 5]``.
"""

from __future__ import annotations

import argparse
import platform
import re

import numpy as np
from common import median_time

import csdf
from csdf import zoo
from csdf.colors import colors_at

MODELS = ("chair", "car", "lamp", "gear")

#: a model whose colours mix: the chair's parts blended (its colours then need the five
#: channel programs, not a palette index)
BLENDED = """
let legs = union(cylinder(0.03, 0.45).translate((0.18, 0.18, 0.225)),
                 cylinder(0.03, 0.45).translate((-0.18, 0.18, 0.225)),
                 cylinder(0.03, 0.45).translate((0.18, -0.18, 0.225)),
                 cylinder(0.03, 0.45).translate((-0.18, -0.18, 0.225)))
let seat = box((0.46, 0.46, 0.04)).translate((0, 0, 0.47))
let back = box((0.46, 0.04, 0.45)).translate((0, 0.21, 0.715))
export union(legs.color((0.2, 0.2, 0.22)), seat.color((0.62, 0.42, 0.24)),
             back.color((0.8, 0.3, 0.2)), k = 0.03)
"""


def uncoloured(name: str) -> csdf.Shape:
    """The zoo model with every ``.color((r, g, b))`` call removed from its source."""
    return csdf.loads(_strip(zoo.source(name)))


def _strip(text: str) -> str:
    return re.sub(r"\.color\(\([^()]*\)\)", "", text)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--points", type=int, default=1_000_000)
    ap.add_argument("--repeat", type=int, default=5)
    a = ap.parse_args()
    print(f"machine: {platform.processor() or platform.machine()}, "
          f"{csdf.parallel.N_THREADS} threads; {a.points} points; median of {a.repeat}")
    print("| model | uncoloured s | coloured s | ratio | same values | colors_at s |")
    print("|---|---|---|---|---|---|")
    for name in MODELS + ("blended chair",):
        if name == "blended chair":
            shape = csdf.loads(BLENDED)
            plain = csdf.loads(_strip(BLENDED))
            assert shape.compile().colors[1] is None  # channel programs
        else:
            shape = zoo.load(name)
            plain = uncoloured(name)
        assert plain.compile().colors is None and shape.compile().colors is not None
        lo, hi = shape.bounds
        P = np.random.default_rng(0).uniform(lo, hi, (a.points, 3))
        f_col, f_plain = shape.compile(), plain.compile()
        t_plain, v_plain = median_time(lambda f=f_plain, P=P: f(P), a.repeat)
        t_col, v_col = median_time(lambda f=f_col, P=P: f(P), a.repeat)
        t_c, _ = median_time(lambda s=shape, P=P: colors_at(s, P), a.repeat)
        same = bool(np.array_equal(v_plain, v_col))
        print(f"| {name} | {t_plain:.3f} | {t_col:.3f} | {t_col / t_plain:.2f} | {same} | "
              f"{t_c:.3f} |")


if __name__ == "__main__":
    main()
