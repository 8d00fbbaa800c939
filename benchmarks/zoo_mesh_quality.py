"""Zoo mesh-quality sweep (issue #15): every zoo model at its defaults and at each end of
each parameter range, meshed at default settings and at 4x the resolution, against the
Monte Carlo volume of its field (the checks of ``tests/meshcheck.py``).

Run from the repository root::

    .venv/bin/python benchmarks/zoo_mesh_quality.py                    # the full sweep
    .venv/bin/python benchmarks/zoo_mesh_quality.py --models lamp,gear  # some models
    .venv/bin/python benchmarks/zoo_mesh_quality.py --fast              # defaults only

Prints one line per case as it finishes (to stderr), then a table sorted with failures
first (model, case, default dims / voxel size, faces, seconds, components at default
and at 4x, mesh volume, Monte Carlo volume +- standard error, relative error,
PASS/FAIL), the failures' reasons and a summary line. ``--output FILE`` also writes the
table there. The exit status is 0 even when cases fail (the table is the result).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))
import meshcheck  # noqa: E402


def _row(r: meshcheck.CaseResult) -> list[str]:
    """The table cells of one case."""
    if r.error and not r.faces:
        return [r.model, r.label, "-", "-", "-", "-", "-", "-", "-", "-", "FAIL"]
    dims = "x".join(str(d) for d in r.dims)
    comps = f"{r.components}/{r.components_4x}"
    mc = (f"{r.mc_volume:.5g} +- {r.mc_stderr / r.mc_volume:.2%}" if r.mc_volume > 0
          else "-")
    rel = f"{r.rel_error:+.2%}" if r.mc_volume > 0 else "-"
    wt = "" if r.watertight and r.watertight_4x else " (leaky)"
    if r.fine_factor < 3.999:
        wt += f" (fine {r.fine_factor:.3f}x)"
    secs = f"{r.seconds:.2f}+{r.seconds_4x:.2f}"
    return [r.model, r.label, f"{dims} / {r.voxel_size:.3g}", f"{r.faces}", secs, comps,
            f"{r.volume:.5g}", mc, rel, ("PASS" if r.passed else "FAIL") + wt]


HEAD = ["model", "case", "dims / voxel", "faces", "s (1x+4x)", "comp 1x/4x", "mesh vol",
        "MC vol +- se", "rel err", "result"]


def format_table(results: list[meshcheck.CaseResult]) -> str:
    """Fixed-width text table of ``results``, failures first (then by model, case)."""
    order = sorted(results, key=lambda r: (r.passed, r.model))
    rows = [HEAD] + [_row(r) for r in order]
    widths = [max(len(row[i]) for row in rows) for i in range(len(HEAD))]
    lines = ["  ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)).rstrip()
             for row in rows]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Run the sweep and print the table; returns the exit status (0)."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--models", default="", help="comma-separated zoo models (default: all)")
    ap.add_argument("--fast", action="store_true", help="only the default case of each model")
    ap.add_argument("--output", default="", help="also write the table to this file")
    ap.add_argument("--seed", type=int, default=0, help="Monte Carlo seed (default 0)")
    args = ap.parse_args(argv)

    from csdf import zoo

    models = [m.strip() for m in args.models.split(",") if m.strip()] or zoo.names()
    for m in models:
        zoo.path(m)  # an unknown name fails here, with the list of known ones
    cases = meshcheck.all_cases(models)
    if args.fast:
        cases = [c for c in cases if c[1] == "default"]
    results: list[meshcheck.CaseResult] = []
    t0 = time.perf_counter()
    for i, (model, label, params) in enumerate(cases, 1):
        t = time.perf_counter()
        r = meshcheck.check_case(model, label, params, seed=args.seed)
        results.append(r)
        print(f"[{i}/{len(cases)}] {time.perf_counter() - t:6.1f} s  "
              f"{'PASS' if r.passed else 'FAIL'}  {r.describe()}", file=sys.stderr, flush=True)
    wall = time.perf_counter() - t0

    failed = [r for r in results if not r.passed]
    out = [format_table(results), ""]
    if failed:
        out.append("failures:")
        out += [f"  {r.describe()}" for r in sorted(failed, key=lambda r: r.model)]
        out.append("")
    out.append(f"summary: {len(results) - len(failed)}/{len(results)} cases pass, "
               f"{len(failed)} fail ({len({r.model for r in failed})} of {len(models)} "
               f"models); volume tolerance {meshcheck.VOLUME_TOL:.0%}, Monte Carlo "
               f"stderr <= {meshcheck.MC_REL_SE_MAX:.1%}; {wall:.0f} s wall")
    text = "\n".join(out)
    print(text)
    if args.output:
        Path(args.output).write_text(text + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
