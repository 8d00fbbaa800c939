"""Every example that Debian's ``openscad`` package ships, through csdf's CSG reader
(issue 20): flattened to ``.csg`` by ``openscad``, read by ``csdf.io.load_csg``
(``facets='ideal'``), and for the 3D ones that load, meshed by ``csdf.mesh`` and
compared with OpenSCAD's own STL export: volumes (csdf's true curves against OpenSCAD's
facets, so curved models differ by the faceting) and the symmetric Hausdorff distance
between the two surfaces (sampled, as a fraction of the bounding diagonal).

Run: ``python benchmarks/openscad_examples.py [--examples DIR] [--resolution 96]
[--markdown]``; needs ``openscad`` on PATH (``apt-get install openscad``).
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
from scipy.spatial import cKDTree

import csdf
from csdf.io import load_csg

EXAMPLES = Path("/usr/share/openscad/examples")


def _hausdorff(a: trimesh.Trimesh, b: trimesh.Trimesh, n: int = 20000) -> float:
    pa = a.sample(n, return_index=False)
    pb = b.sample(n, return_index=False)
    da = cKDTree(pb).query(pa)[0].max()
    db = cKDTree(pa).query(pb)[0].max()
    return float(max(da, db))


def run(path: Path, resolution: int, tmp: Path) -> dict:
    row = {"example": str(path.relative_to(path.parents[1])), "result": "", "dim": "",
           "volume_diff": "", "hausdorff": "", "seconds": ""}
    csg = tmp / (path.stem + ".csg")
    stl = tmp / (path.stem + ".stl")
    r = subprocess.run(["openscad", "-o", str(csg), str(path)], capture_output=True,
                       text=True, timeout=300, cwd=path.parent)
    if r.returncode != 0 or not csg.exists():
        row["result"] = "openscad could not export CSG"
        return row
    t0 = time.perf_counter()
    try:
        shape = load_csg(csg)
    except csdf.CsdfError as exc:
        msg = str(exc).splitlines()[0]
        row["result"] = "not read: " + msg.split(": ", 1)[1] if ": " in msg else msg
        return row
    row["dim"] = f"{shape.dim}D"
    if shape.dim != 3:
        row["result"] = "read (2D)"
        row["seconds"] = f"{time.perf_counter() - t0:.2f}"
        return row
    m = csdf.mesh(shape, resolution=resolution, progress=False, check_thin=False)
    row["seconds"] = f"{time.perf_counter() - t0:.2f}"
    ours = trimesh.Trimesh(m.vertices, m.faces, process=False)
    r = subprocess.run(["openscad", "-o", str(stl), str(path)], capture_output=True,
                       text=True, timeout=600, cwd=path.parent)
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
    if ref.is_volume and ours.is_volume:
        row["volume_diff"] = f"{(ours.volume - ref.volume) / abs(ref.volume):+.2%}"
    row["hausdorff"] = f"{_hausdorff(ours, ref) / diag:.2%}"
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--examples", type=Path, default=EXAMPLES)
    ap.add_argument("--resolution", type=int, default=96)
    a = ap.parse_args()
    if shutil.which("openscad") is None:
        sys.exit("openscad is not on PATH (apt-get install openscad)")
    files = sorted(a.examples.rglob("*.scad"))
    print("| example | result | dim | volume vs OpenSCAD | Hausdorff / diagonal | "
          "s (read + mesh) |")
    print("|---|---|---|---|---|---|")
    counts: dict[str, int] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for f in files:
            try:
                row = run(f, a.resolution, Path(tmp))
            except subprocess.TimeoutExpired:
                row = {"example": str(f.relative_to(f.parents[1])),
                       "result": "openscad timed out", "dim": "", "volume_diff": "",
                       "hausdorff": "", "seconds": ""}
            key = row["result"].split(":")[0]
            counts[key] = counts.get(key, 0) + 1
            print(f"| {row['example']} | {row['result']} | {row['dim']} | "
                  f"{row['volume_diff']} | {row['hausdorff']} | {row['seconds']} |",
                  flush=True)
    print()
    print(", ".join(f"{k}: {v}" for k, v in sorted(counts.items())))


if __name__ == "__main__":
    main()
