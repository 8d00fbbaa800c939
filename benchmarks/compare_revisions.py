"""A/B timing of two csdf revisions in the same run: this tree against an earlier commit.

Machine state on a shared VM moves timings by tens of percent between runs (memory
compaction, the other tenant's use of the vector units), so "is this change slower?" is
answered only by timing both revisions now, alternately, in fresh processes. This
script checks the other revision out into a temporary git worktree, then for
``--rounds`` rounds runs one child process per revision (order alternating) that times

* the fast evaluator on the README's CSG example, a parametric sphere and a union of 20
  primitives at 10^6 and 10^7 points (value, value+grad, value+grad+jac), and
* ``csdf.mesh`` of the CSG example at 512^3 (``mc`` and ``dc``),

and prints, per measurement, the median over rounds of each child's median, and the
ratio new / old (below 1: the new revision is faster).

Usage::

    .venv/bin/python benchmarks/compare_revisions.py 608cde1 [--rounds 3] [--output F]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

CHILD = r'''
import json, sys, time
import numpy as np
import csdf

def med(fn, repeats):
    fn()  # warm: kernels compiled and cached, result memory recycled
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter(); fn(); ts.append(time.perf_counter() - t0)
    return float(np.median(ts))

r = csdf.param("r", 1.0, 0.5, 1.5)
c = csdf.cylinder(0.5, 3.0)
csg = (csdf.sphere(r) & csdf.box(1.5)) - c - c.orient("x") - c.orient("y")
rng = np.random.default_rng(0)
acc = None
for i in range(20):
    s = float(rng.uniform(0.2, 0.6)); t = tuple(rng.uniform(-2, 2, 3))
    p = csdf.sphere(csdf.param("r0", s, 0.1, 1.0) if i == 0 else s) if i % 2 == 0 else \
        csdf.box(csdf.param("b1", 2 * s, 0.1, 2.0) if i == 1 else 2 * s)
    p = p.translate(t)
    acc = p if acc is None else (csdf.union(acc, p, k=0.1) if i % 4 == 1 else acc | p)
models = {"sphere": csdf.sphere(r), "csg": csg, "union20": acc}
out = {}
for n in (10**6, 10**7):
    pts = np.random.default_rng(1).uniform(-1.5, 1.5, (n, 3))
    for name, shape in models.items():
        prog = shape.compile()
        reps = 5 if n == 10**7 else 9
        out[f"eval {name} 1e{len(str(n)) - 1} value"] = med(
            lambda: prog(pts, backend="fast"), reps)
        out[f"eval {name} 1e{len(str(n)) - 1} value+grad"] = med(
            lambda: prog.value_and_grad(pts, backend="fast"), reps)
        out[f"eval {name} 1e{len(str(n)) - 1} all"] = med(
            lambda: prog.value_grad_param_jacobian(pts, backend="fast"), reps)
    del pts
for method in ("mc", "dc"):
    out[f"mesh csg 512 {method}"] = med(
        lambda: csdf.mesh(csg, resolution=512, method=method, progress=False), 3)
print("RESULT " + json.dumps(out))
'''


def run_child(src: Path) -> dict[str, float]:
    env = dict(os.environ, PYTHONPATH=str(src))
    res = subprocess.run([sys.executable, "-c", CHILD], env=env, capture_output=True,
                         text=True, cwd=tempfile.gettempdir(), check=False)
    for line in res.stdout.splitlines():
        if line.startswith("RESULT "):
            return json.loads(line[7:])
    raise RuntimeError(f"child for {src} failed:\n{res.stdout[-2000:]}\n{res.stderr[-4000:]}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("rev", help="the earlier revision (a commit) to compare against")
    ap.add_argument("--rounds", type=int, default=3, help="child runs per revision")
    ap.add_argument("--output", type=Path, default=None, help="also write Markdown here")
    args = ap.parse_args()
    t_start = time.time()
    with tempfile.TemporaryDirectory(prefix="csdf-ab-") as tmp:
        wt = Path(tmp) / "old"
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(wt),
                        args.rev], check=True, capture_output=True)
        try:
            runs: dict[str, list[dict[str, float]]] = {"old": [], "new": []}
            for k in range(args.rounds):
                order = ("old", "new") if k % 2 == 0 else ("new", "old")
                for which in order:
                    src = wt / "src" if which == "old" else ROOT / "src"
                    runs[which].append(run_child(src))
                    print(f"round {k + 1}/{args.rounds}: {which} done", flush=True)
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force",
                            str(wt)], check=False, capture_output=True)
    head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"],
                          capture_output=True, text=True, check=False).stdout.strip()
    lines = [f"A/B against {args.rev} (this tree: {head}), {args.rounds} rounds, fresh "
             f"processes, alternating order; {os.cpu_count()} CPUs; "
             f"{time.time() - t_start:.0f} s", "",
             "| measurement | old (median) | new (median) | new / old |", "|---|---|---|---|"]
    for key in runs["old"][0]:
        old = statistics.median(r[key] for r in runs["old"])
        new = statistics.median(r[key] for r in runs["new"])
        lines.append(f"| {key} | {old * 1e3:.1f} ms | {new * 1e3:.1f} ms | {new / old:.2f} |")
    text = "\n".join(lines)
    print(text)
    if args.output:
        args.output.write_text(text + "\n")


if __name__ == "__main__":
    main()
