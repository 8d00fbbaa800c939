"""Every example that Debian's ``openscad`` package ships, through csdf's CSG reader
(issue 20): flattened to ``.csg`` by ``openscad``, read by ``csdf.io.load_csg`` in both
faceting modes, and for the 3D ones that load, the ``facets='openscad'`` shape (OpenSCAD's
own facets) meshed by ``csdf.mesh`` and compared with OpenSCAD's STL export of the same
file: the symmetric Hausdorff distance between the two surfaces (as a fraction of the
bounding diagonal) and the relative volume difference. Goals (issue 20): <= 0.5 % and
<= 1 %.

The Hausdorff distance: points sampled uniformly on each surface (``--samples`` per
surface, plus every vertex of both), each measured to the other *surface* (the exact
point-to-triangle distance of ``csdf.backends.meshdist``, or trimesh's closest points
when a mesh is not closed), the largest of the two directions.

Run: ``python benchmarks/openscad_examples.py [--examples DIR] [--resolution 256]
[--samples 20000] [--method dc]``; needs ``openscad`` on PATH (``apt-get install
openscad``). Prints a Markdown table and a summary.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import trimesh

import csdf
from csdf.io import load_csg

EXAMPLES = Path("/usr/share/openscad/examples")
#: goals of issue 20
HAUSDORFF_GOAL = 0.005
VOLUME_GOAL = 0.01
#: seconds an openscad export may take
OPENSCAD_TIMEOUT = 300


def _to_surface(points: np.ndarray, mesh: trimesh.Trimesh) -> np.ndarray:
    """Unsigned distances ``(N,)`` of ``points`` ``(N, 3)`` to the surface of ``mesh``."""
    try:
        from csdf.backends.meshdist import MeshDistance

        return np.abs(MeshDistance(mesh.vertices, mesh.faces).value(points))
    except csdf.CsdfError:  # not closed: trimesh's (slower) closest points
        return trimesh.proximity.closest_point(mesh, points)[1]


def hausdorff(a: trimesh.Trimesh, b: trimesh.Trimesh, n: int, seed: int = 0) -> float:
    """Symmetric Hausdorff distance between two surfaces (model units), from ``n``
    uniform samples and the vertices of each measured to the other surface."""
    out = 0.0
    for src, dst in ((a, b), (b, a)):
        pts = np.concatenate([trimesh.sample.sample_surface(src, n, seed=seed)[0],
                              src.vertices])
        out = max(out, float(_to_surface(pts, dst).max()))
    return out


def _openscad(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run(["openscad", *args], capture_output=True, text=True,
                          timeout=OPENSCAD_TIMEOUT, cwd=cwd, stdin=subprocess.DEVNULL)


def run(path: Path, resolution: int, samples: int, method: str, tmp: Path) -> dict:
    """One example: its row of the table (strings)."""
    row = {"example": str(path.relative_to(path.parents[1])), "result": "", "dim": "",
           "hausdorff": "", "volume_diff": "", "goal": "", "seconds": ""}
    csg = tmp / (path.stem + ".csg")
    stl = tmp / (path.stem + ".stl")
    r = _openscad(["-o", str(csg), str(path)], path.parent)
    if r.returncode != 0 or not csg.exists():
        row["result"] = "openscad could not export CSG"
        return row
    try:
        load_csg(csg)  # the ideal mode reads the same nodes
        t0 = time.perf_counter()
        shape = load_csg(csg, facets="openscad")
    except csdf.CsdfError as exc:
        msg = str(exc).splitlines()[0]
        row["result"] = "not read: " + msg.split(": ", 1)[1] if ": " in msg else msg
        return row
    row["dim"] = f"{shape.dim}D"
    if shape.dim != 3:
        row["result"] = "read (2D)"
        return row
    m = csdf.mesh(shape, resolution=resolution, method=method, progress=False,
                  check_thin=False)
    row["seconds"] = f"{time.perf_counter() - t0:.1f}"
    ours = trimesh.Trimesh(m.vertices, m.faces, process=False)
    r = _openscad(["-o", str(stl), str(path)], path.parent)
    if r.returncode != 0 or not stl.exists():
        row["result"] = "read; openscad could not export STL to compare"
        return row
    ref = trimesh.load(stl, force="mesh")
    if len(ours.faces) == 0 or len(ref.faces) == 0:
        row["result"] = (f"read; no surface at resolution {resolution}" if len(ref.faces)
                         else "read; OpenSCAD's STL is empty")
        return row
    diag = float(np.linalg.norm(ref.bounds[1] - ref.bounds[0]))
    row["result"] = "read"
    hd = hausdorff(ours, ref, samples) / diag
    row["hausdorff"] = f"{hd:.2%}"
    ok = hd <= HAUSDORFF_GOAL
    if ref.is_volume and ours.is_volume:
        dv = (ours.volume - ref.volume) / abs(ref.volume)
        row["volume_diff"] = f"{dv:+.2%}"
        ok = ok and abs(dv) <= VOLUME_GOAL
    else:
        row["volume_diff"] = "(STL not closed)" if not ref.is_volume else "(mesh open)"
        ok = False
    row["goal"] = "yes" if ok else "no"
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--examples", type=Path, default=EXAMPLES,
                    help="folder of .scad files (searched recursively)")
    ap.add_argument("--resolution", type=int, default=256,
                    help="mesh voxels along the longest side")
    ap.add_argument("--samples", type=int, default=20000,
                    help="surface samples per mesh for the Hausdorff distance")
    ap.add_argument("--method", choices=("mc", "dc"), default="dc",
                    help="meshing: marching cubes or dual contouring")
    ap.add_argument("--only", default="", help="only examples whose path contains this")
    a = ap.parse_args()
    if shutil.which("openscad") is None:
        sys.exit("openscad is not on PATH (apt-get install openscad)")
    files = [f for f in sorted(a.examples.rglob("*.scad")) if a.only in str(f)]
    print(f"| example | result | dim | Hausdorff / diagonal | volume vs OpenSCAD | "
          f"goals (<= {HAUSDORFF_GOAL:.1%}, <= {VOLUME_GOAL:.0%}) | s (read + mesh) |")
    print("|---|---|---|---|---|---|---|")
    counts: dict[str, int] = {}
    goals = {"yes": 0, "no": 0}
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        for f in files:
            try:
                row = run(f, a.resolution, a.samples, a.method, Path(tmp))
            except subprocess.TimeoutExpired:
                row = {"example": str(f.relative_to(f.parents[1])),
                       "result": "openscad timed out", "dim": "", "hausdorff": "",
                       "volume_diff": "", "goal": "", "seconds": ""}
            key = row["result"].split(":")[0]
            counts[key] = counts.get(key, 0) + 1
            if row["goal"]:
                goals[row["goal"]] += 1
            print(f"| {row['example']} | {row['result']} | {row['dim']} | "
                  f"{row['hausdorff']} | {row['volume_diff']} | {row['goal']} | "
                  f"{row['seconds']} |", flush=True)
    print()
    print(", ".join(f"{k}: {v}" for k, v in sorted(counts.items())))
    print(f"3D examples compared: {goals['yes'] + goals['no']}, meeting both goals: "
          f"{goals['yes']}; total {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
