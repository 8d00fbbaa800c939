"""What the thin-part check costs (issue 15): ``csdf.mesh`` at an explicit resolution with
``check_thin=True`` (the default: the check scans the mesher's own samples, then refines
its candidate voxels with interval arithmetic) against ``check_thin=False``, and the
default resolution (chosen by the check) of the zoo models against a plain 128.

Run: ``python benchmarks/bench_thin.py [--runs 5]``; prints a Markdown table of medians
(seconds, warm, one process) and the ratio measured in the same run.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import machine_info, md_table  # noqa: E402


def _median(runs: int, shape, **kw) -> float:
    """Median seconds of ``csdf.mesh(shape, progress=False, **kw)`` after a warm-up."""
    import csdf

    csdf.mesh(shape, progress=False, **kw)  # warm (kernels compiled, caches filled)
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        csdf.mesh(shape, progress=False, **kw)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--runs", type=int, default=5, help="timed runs per case (median)")
    p.add_argument("--models", default="bookshelf,lamp,street_sign,chair,gear",
                   help="zoo models for the default-resolution table")
    args = p.parse_args(argv)

    import csdf
    from csdf import zoo
    from csdf.demo import csg_example

    warnings.simplefilter("ignore", csdf.MeshWarning)
    info = machine_info()
    print("\n".join(f"* {k}: {v}" for k, v in info.items()))
    rows = []
    for name, shape in (("CSG example", csg_example()), ("zoo house", zoo.load("house"))):
        for res in (256, 512):
            on = _median(args.runs, shape, resolution=res)
            off = _median(args.runs, shape, resolution=res, check_thin=False)
            rows.append([name, str(res), f"{off:.3f}", f"{on:.3f}", f"{on / off:.2f}x"])
    print("\n### Explicit resolution: the check's cost\n")
    print(md_table(["shape", "resolution", "check_thin=False s", "check_thin=True s",
                    "ratio"], rows))
    rows = []
    for name in args.models.split(","):
        shape = zoo.load(name)
        m = csdf.mesh(shape, progress=False)
        auto = _median(args.runs, shape)
        plain = _median(args.runs, shape, check_thin=False)
        rows.append([name, str(m.metadata["csdf"]["resolution"]), f"{len(m.faces):,}",
                     f"{plain:.3f}", f"{auto:.3f}", f"{auto / plain:.2f}x"])
    print("\n### Default resolution: chosen by the check, against a plain 128\n")
    print(md_table(["model", "chosen resolution", "faces", "128 without check s",
                    "default s", "ratio"], rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
