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
ratio new / old (below 1: the new revision is faster). Other suites (``--suite``):

* ``calls``: the small calls a fit and a detector make thousands of times, where the
  time is the call's own overhead more than the kernel's: a program's values, and
  values, gradients and parameter Jacobian at new parameters, on 700 points (a
  cluster); a field's values on 50 points (a sphere tracer's late steps); one robust
  pose-and-shape fit of the chair to 1,200 noisy points with a viewpoint;
* ``shapes``: polygon-based primitives (an extruded 200-gon, a hexagonal prism, a
  pyramid): values and values with gradients at 10^6 points, and ``csdf.mesh`` at
  128^3 (``dc``);
* ``detect``: ``csdf.detect`` on the benchmark's cluttered scenes
  (``bench_detect.py``'s, seeds ``--first-scene`` on, ``--scenes`` of them), CPU and
  wall seconds per object after a warm-up scene, and whether both revisions return
  the same detections (poses to 1e-9);
* ``normals``: ``csdf.estimate_normals`` on those scans (the median over them) and
  ``csdf.detect_primitives`` on the benchmark's first 40k-point primitive scene with
  its normals estimated, and whether both revisions find the same primitives (kinds
  and inliers);
* ``primitives``: ``csdf.detect_primitives`` on ``bench_detect.py``'s primitive scenes
  (40k points, normals given; seeds ``--first-scene`` on, ``--scenes`` of them), the
  median over the scenes of each scene's median of 3, and whether both revisions find
  the same primitives (kinds, inliers, rmse to 8 digits).

Usage::

    .venv/bin/python benchmarks/compare_revisions.py 608cde1 [--rounds 3] [--output F]
    .venv/bin/python benchmarks/compare_revisions.py a1c9e75 --suite calls
    .venv/bin/python benchmarks/compare_revisions.py a1c9e75 --suite detect --scenes 5
    .venv/bin/python benchmarks/compare_revisions.py 9cb5157 --suite shapes
    .venv/bin/python benchmarks/compare_revisions.py 80ad40a --suite normals --scenes 3
    .venv/bin/python benchmarks/compare_revisions.py c2fcb78 --suite primitives \
        --first-scene 0 --scenes 20
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

import numpy as np

ROOT = Path(__file__).resolve().parent.parent

#: the median of a call's times after one warm-up call (the timing children's helper)
MED = r'''
def med(fn, repeats):
    fn()  # warm: kernels compiled and cached, result memory recycled
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter(); fn(); ts.append(time.perf_counter() - t0)
    return float(np.median(ts))
'''

CHILD = r'''
import json, sys, time
import numpy as np
import csdf
''' + MED + r'''
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

CHILD_CALLS = r'''
import json, time
import numpy as np
import csdf

def per_call(fn, n):
    fn()
    ts = []
    for _ in range(5):
        t0 = time.perf_counter()
        for _ in range(n):
            fn()
        ts.append((time.perf_counter() - t0) / n)
    return float(np.median(ts))

chair = csdf.zoo.load("chair")
prog = chair.compile()
rng = np.random.default_rng(0)
q = rng.normal(scale=0.3, size=(700, 3))
pv = {p.name: float(p.default) for p in prog.params}
first = prog.params[0].name
step = [0]

def moved():  # a solver's next step: parameters never seen before
    step[0] += 1
    p = dict(pv)
    p[first] = pv[first] * (1.0 + 1e-9 * step[0])
    return prog.value_grad_param_jacobian(q, p, check_ranges=False)

fld = csdf.as_field(chair)
q50 = np.ascontiguousarray(q[:50])
pts = csdf.sample_surface(chair, 1200, seed=1)[0]
pts = pts + rng.normal(scale=0.004, size=pts.shape) + [0.1, -0.05, 0.02]
init = {"rotation": np.eye(3), "translation": np.zeros(3), "params": pv}
out = {
    "program value, 700 points": per_call(lambda: prog(q, pv, check_ranges=False), 400),
    "program value+grad+jac, new parameters, 700 points": per_call(moved, 200),
    "field value, 50 points": per_call(lambda: fld.value(q50), 400),
    "fit chair pose+params, 1200 points": per_call(lambda: csdf.fit(
        chair, pts, init=init, estimate=("pose", "params"), loss="cauchy", f_scale=0.005,
        viewpoint=(0.0, 0.0, -3.0), max_iter=40, check_ranges=False), 2),
}
print("RESULT " + json.dumps(out))
'''

CHILD_DETECT = r'''
import hashlib, json, sys, time
import numpy as np
import csdf

data = np.load(sys.argv[1])
clouds = [data[f"points_{i}"] for i in range(int(data["count"]))]
objects = int(data["objects"])
models = sys.argv[2].split(",")
csdf.detect(clouds[0], models, viewpoint=(0.0, 0.0, 0.0), seed=0)  # kernels compiled
h = hashlib.sha1()
c0, t0 = time.process_time(), time.perf_counter()
for P in clouds:
    for d in csdf.detect(P, models, viewpoint=(0.0, 0.0, 0.0), seed=0):
        h.update(d.model.encode())
        h.update(np.round(d.pose.matrix, 9).tobytes())
cpu, wall = time.process_time() - c0, time.perf_counter() - t0
print("RESULT " + json.dumps({"detect CPU s / object": cpu / objects,
                              "detect wall s / object": wall / objects,
                              "_detections": h.hexdigest()}))
'''

CHILD_NORMALS = r'''
import hashlib, json, sys, time
import numpy as np
import csdf
''' + MED + r'''
data = np.load(sys.argv[1])
clouds = [data[f"points_{i}"] for i in range(int(data["count"]))]
prim = data["primitive"]
vp = (0.0, 0.0, 0.0)
h = hashlib.sha1()
for d in csdf.detect_primitives(prim, seed=0):
    h.update(d.kind.encode())
    h.update(np.asarray(d.inliers).tobytes())
out = {
    "estimate_normals, one scan (median over the scans)": float(np.median(
        [med(lambda: csdf.estimate_normals(P, viewpoint=vp), 5) for P in clouds])),
    "detect_primitives, 40k points, normals estimated": med(
        lambda: csdf.detect_primitives(prim, seed=0), 5),
    "_detections": h.hexdigest(),
}
print("RESULT " + json.dumps(out))
'''


CHILD_PRIMITIVES = r'''
import hashlib, json, sys, time
import numpy as np
import csdf
''' + MED + r'''
data = np.load(sys.argv[1])
scenes = [(data[f"points_{i}"], data[f"normals_{i}"]) for i in range(int(data["count"]))]
csdf.detect_primitives(scenes[0][0], scenes[0][1], seed=0)  # warm caches
h = hashlib.sha1()
times = []
for P, N in scenes:
    for d in csdf.detect_primitives(P, N, seed=0):
        h.update(d.kind.encode())
        h.update(np.asarray(d.inliers).tobytes())
        h.update(f"{d.rmse:.8e}".encode())
    times.append(med(lambda: csdf.detect_primitives(P, N, seed=0), 3))
out = {"detect_primitives, 40k points, normals given (median over the scenes)":
       float(np.median(times)), "_detections": h.hexdigest()}
print("RESULT " + json.dumps(out))
'''


CHILD_SHAPES = r'''
import json, time
import numpy as np
import csdf
''' + MED + r'''
a = np.linspace(0.0, 2.0 * np.pi, 200, endpoint=False)
rad = 0.5 + 0.15 * np.sin(5.0 * a)
shapes = {
    "polygon200": csdf.extrude(csdf.polygon(np.c_[rad * np.cos(a), rad * np.sin(a)]), 0.5),
    "hex_prism": csdf.hex_prism(0.5, 0.8),
    "pyramid": csdf.pyramid(0.8, 0.9),
}
pts = np.random.default_rng(1).uniform(-0.8, 0.8, (10**6, 3))
out = {}
for name, shape in shapes.items():
    prog = shape.compile()
    out[f"{name} 1e6 value"] = med(lambda: prog(pts, backend="fast"), 5)
    out[f"{name} 1e6 value+grad"] = med(lambda: prog.value_and_grad(pts, backend="fast"), 5)
    out[f"{name} mesh 128 dc"] = med(
        lambda: csdf.mesh(shape, resolution=128, method="dc", progress=False), 3)
print("RESULT " + json.dumps(out))
'''


def detect_scenes(first: int, count: int, path: Path, primitive: bool = False) -> list[str]:
    """The benchmark's cluttered scenes ``first .. first + count - 1`` (this tree's
    ``bench_detect.py``) saved to ``path`` for the children, with its primitive scene
    of seed 0 (``primitive``); returns the models."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from detect_scenes import CLUTTER_MODELS, clutter_scene, primitive_scene

    arrays: dict = {}
    if primitive:
        arrays["primitive"] = np.asarray(primitive_scene(0)["points"], dtype=np.float64)
    objects = 0
    for i in range(count):
        sc = clutter_scene(first + i)
        arrays[f"points_{i}"] = np.asarray(sc["points"], dtype=np.float64)
        objects += len(sc["truth"])
    np.savez(path, count=count, objects=objects, **arrays)
    return list(CLUTTER_MODELS)


def primitive_scenes(first: int, count: int, path: Path) -> None:
    """The benchmark's primitive scenes ``first .. first + count - 1`` (points and
    normals) saved to ``path`` for the children."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from detect_scenes import primitive_scene

    arrays: dict = {}
    for i in range(count):
        sc = primitive_scene(first + i)
        arrays[f"points_{i}"] = np.asarray(sc["points"], dtype=np.float64)
        arrays[f"normals_{i}"] = np.asarray(sc["normals"], dtype=np.float64)
    np.savez(path, count=count, **arrays)


def run_child(src: Path, code: str = CHILD, args: tuple[str, ...] = ()) -> dict[str, float]:
    env = dict(os.environ, PYTHONPATH=str(src))
    res = subprocess.run([sys.executable, "-c", code, *args], env=env, capture_output=True,
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
    ap.add_argument("--suite", choices=("eval", "calls", "shapes", "detect", "normals",
                                        "primitives"),
                    default="eval",
                    help="what to time (module docs)")
    ap.add_argument("--first-scene", type=int, default=100,
                    help="detect, normals and primitives suites: the first scene's seed")
    ap.add_argument("--scenes", type=int, default=5,
                    help="detect, normals and primitives suites: scenes timed (the first "
                    "detected once before too, to warm up)")
    args = ap.parse_args()
    if not 1 <= args.scenes <= 100:
        ap.error(f"--scenes must be 1-100, got {args.scenes}")
    t_start = time.time()
    with tempfile.TemporaryDirectory(prefix="csdf-ab-") as tmp:
        code, child_args = {"eval": CHILD, "calls": CHILD_CALLS, "shapes": CHILD_SHAPES,
                            "detect": CHILD_DETECT, "normals": CHILD_NORMALS,
                            "primitives": CHILD_PRIMITIVES}[args.suite], ()
        if args.suite in ("detect", "normals"):
            data = Path(tmp) / "scenes.npz"
            models = detect_scenes(args.first_scene, args.scenes, data,
                                   primitive=args.suite == "normals")
            child_args = (str(data), ",".join(models))
        elif args.suite == "primitives":
            data = Path(tmp) / "primitives.npz"
            primitive_scenes(args.first_scene, args.scenes, data)
            child_args = (str(data),)
        wt = Path(tmp) / "old"
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(wt),
                        args.rev], check=True, capture_output=True)
        try:
            runs: dict[str, list[dict[str, float]]] = {"old": [], "new": []}
            for k in range(args.rounds):
                order = ("old", "new") if k % 2 == 0 else ("new", "old")
                for which in order:
                    src = wt / "src" if which == "old" else ROOT / "src"
                    runs[which].append(run_child(src, code, child_args))
                    print(f"round {k + 1}/{args.rounds}: {which} done", flush=True)
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force",
                            str(wt)], check=False, capture_output=True)
    head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"],
                          capture_output=True, text=True, check=False).stdout.strip()
    lines = [f"A/B against {args.rev} (this tree: {head}), suite {args.suite}, "
             f"{args.rounds} rounds, fresh processes, alternating order; "
             f"{os.cpu_count()} CPUs; {time.time() - t_start:.0f} s", "",
             "| measurement | old (median) | new (median) | new / old |", "|---|---|---|---|"]
    for key in runs["old"][0]:
        if key.startswith("_"):
            continue
        old = statistics.median(r[key] for r in runs["old"])
        new = statistics.median(r[key] for r in runs["new"])
        unit, f = ("s", 1.0) if "/ object" in key else (("us", 1e6) if old < 1e-3
                                                        else ("ms", 1e3))
        lines.append(f"| {key} | {old * f:.{2 if unit == 's' else 1}f} {unit} | "
                     f"{new * f:.{2 if unit == 's' else 1}f} {unit} | {new / old:.2f} |")
    if "_detections" in runs["old"][0]:
        same = {r["_detections"] for r in runs["old"] + runs["new"]}
        lines += ["", "same detections in every run: " + ("yes" if len(same) == 1 else
                                                           f"NO ({len(same)} different)")]
    text = "\n".join(lines)
    print(text)
    if args.output:
        args.output.write_text(text + "\n")


if __name__ == "__main__":
    main()
