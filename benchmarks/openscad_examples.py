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

Resolution: each 3D example is meshed at ``--resolution`` voxels along its longest side
(256); when the comparison misses a goal, it is meshed again at twice the resolution,
up to ``--max-resolution`` (1024), and only while the next mesh is expected to take at
most ``--max-seconds`` (four times the last mesh's time: the mesher's work grows with
the surface's area, the square of the resolution). The table gives the resolution of
the last mesh and the seconds of all of them.

OpenSCAD's STL: where the parts of a model touch along a face, OpenSCAD 2021.01's export
keeps both parts' faces there: the same flat region covered once by triangles facing
one way and once by triangles facing the other, a sheet of no thickness inside the
solid that is not part of its boundary (the STL is then not closed: four triangles
meet at the sheet's edges). :func:`drop_double_sheets` removes exactly those triangles
(and nothing when a triangle lies only partly in such a region) before the comparison;
the result must be closed and keep the signed volume (the removed triangles' signed
tetrahedra cancel), else the STL is reported as not closed.

Run: ``python benchmarks/openscad_examples.py [--examples DIR] [--resolution 256]
[--max-resolution 1024] [--max-seconds 600] [--samples 20000] [--method dc]
[--no-fit-bounds]``; needs
``openscad`` on PATH (``apt-get install openscad``) and shapely. Prints a Markdown table
and a summary.
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
#: two faces lie in one plane when their unit normals and offsets (over the mesh's
#: bounding diagonal) differ by less than this
PLANE_TOLERANCE = 1e-6
#: a triangle is in a doubly covered region when this fraction of its area is (and
#: outside when at most 1 minus it is)
COVERED = 1.0 - 1e-6


def _plane_groups(mesh: trimesh.Trimesh) -> tuple[np.ndarray, np.ndarray]:
    """The faces' planes: ``(labels (F,), signs (F,))``, faces with one label lying in
    one plane (within :data:`PLANE_TOLERANCE`), and each face's sign: +1 where its
    normal is the plane's chosen normal (its largest component positive), else -1."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    n = np.asarray(mesh.face_normals, dtype=float)
    k = np.abs(n).argmax(axis=1)
    sign = np.where(n[np.arange(len(n)), k] < 0.0, -1, 1)
    n = n * sign[:, None]
    diag = float(np.linalg.norm(mesh.bounds[1] - mesh.bounds[0]))
    d = np.einsum("ij,ij->i", n, mesh.triangles_center) / diag
    pairs = cKDTree(np.column_stack([n, d])).query_pairs(PLANE_TOLERANCE,
                                                         output_type="ndarray")
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])),
                       shape=(len(n), len(n)))
    return connected_components(graph, directed=False)[1], sign


def drop_double_sheets(mesh: trimesh.Trimesh) -> tuple[trimesh.Trimesh, int]:
    """``mesh`` without its zero-thickness sheets, and how many triangles were removed.

    In each plane that holds triangles facing both ways, the region covered both ways
    (the intersection of the union of each orientation's triangles, by shapely in the
    plane's coordinates) is a sheet inside the solid; the triangles lying wholly in it
    (:data:`COVERED`) are removed. Nothing is removed (``(mesh, 0)``) when a triangle
    lies partly in such a region, or when the result is not closed and consistently
    wound, or does not keep the signed volume."""
    import shapely

    labels, sign = _plane_groups(mesh)
    tris = mesh.triangles
    drop: list[int] = []
    for g in np.unique(labels):
        ids = np.flatnonzero(labels == g)
        if len(np.unique(sign[ids])) < 2:
            continue
        normal = (mesh.face_normals[ids] * sign[ids, None]).mean(axis=0)
        u = np.cross(normal, np.eye(3)[np.abs(normal).argmin()])
        u /= np.linalg.norm(u)
        v = np.cross(normal / np.linalg.norm(normal), u)
        flat = [shapely.Polygon(np.column_stack([tris[i] @ u, tris[i] @ v])) for i in ids]
        both = shapely.intersection(
            shapely.union_all([t for t, i in zip(flat, ids) if sign[i] > 0]),
            shapely.union_all([t for t, i in zip(flat, ids) if sign[i] < 0]))
        if both.area == 0.0:
            continue
        for t, i in zip(flat, ids):
            inside = t.intersection(both).area / t.area if t.area > 0.0 else 0.0
            if inside >= COVERED:
                drop.append(int(i))
            elif inside > 1.0 - COVERED:
                return mesh, 0
    if not drop:
        return mesh, 0
    keep = np.setdiff1d(np.arange(len(mesh.faces)), drop)
    out = trimesh.Trimesh(mesh.vertices, mesh.faces[keep], process=True)
    if not (out.is_watertight and out.is_winding_consistent) or \
            abs(out.volume - mesh.volume) > 1e-9 * abs(mesh.volume):
        return mesh, 0
    return out, len(drop)


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


def compare(ours: trimesh.Trimesh, ref: trimesh.Trimesh, samples: int
            ) -> tuple[float, float | None]:
    """``(Hausdorff distance / ref's bounding diagonal, relative volume difference)``
    of csdf's mesh against OpenSCAD's; the volume difference is None unless both are
    closed."""
    diag = float(np.linalg.norm(ref.bounds[1] - ref.bounds[0]))
    hd = hausdorff(ours, ref, samples) / diag
    if not (ref.is_volume and ours.is_volume):
        return hd, None
    return hd, (ours.volume - ref.volume) / abs(ref.volume)


def _meets(hd: float, dv: float | None) -> bool:
    return hd <= HAUSDORFF_GOAL and dv is not None and abs(dv) <= VOLUME_GOAL


def run(path: Path, resolution: int, samples: int, method: str, tmp: Path,
        max_resolution: int, max_seconds: float, fit_bounds: bool = True) -> dict:
    """One example: its row of the table (strings). Meshed at ``resolution``, and
    again at twice it while the comparison misses a goal, up to ``max_resolution`` and
    while the next mesh is expected to take at most ``max_seconds``."""
    row = {"example": str(path.relative_to(path.parents[1])), "result": "", "dim": "",
           "hausdorff": "", "volume_diff": "", "goal": "", "resolution": "",
           "seconds": ""}
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
        seconds = time.perf_counter() - t0
    except csdf.CsdfError as exc:
        msg = str(exc).splitlines()[0]
        row["result"] = "not read: " + msg.split(": ", 1)[1] if ": " in msg else msg
        return row
    row["dim"] = f"{shape.dim}D"
    if shape.dim != 3:
        row["result"] = "read (2D)"
        return row
    r = _openscad(["-o", str(stl), str(path)], path.parent)
    if r.returncode != 0 or not stl.exists():
        row["result"] = "read; openscad could not export STL to compare"
        return row
    ref = trimesh.load(stl, force="mesh")
    if len(ref.faces) == 0:
        row["result"] = "read; OpenSCAD's STL is empty"
        return row
    row["result"] = "read"
    if not ref.is_volume:
        ref, dropped = drop_double_sheets(ref)
        if dropped:
            row["result"] = (f"read; {dropped} triangles of zero-thickness sheets "
                             f"removed from OpenSCAD's STL")
    res = resolution
    while True:
        t0 = time.perf_counter()
        m = csdf.mesh(shape, resolution=res, method=method, progress=False,
                      check_thin=False, fit_bounds=fit_bounds)
        took = time.perf_counter() - t0
        seconds += took
        row["resolution"] = str(res)
        row["seconds"] = f"{seconds:.1f}"
        ours = trimesh.Trimesh(m.vertices, m.faces, process=False)
        del m
        if len(ours.faces) == 0:
            row["result"] = f"read; no surface at resolution {res}"
            row["goal"] = "no"
        else:
            hd, dv = compare(ours, ref, samples)
            row["hausdorff"] = f"{hd:.2%}"
            row["volume_diff"] = ("(STL not closed)" if not ref.is_volume else
                                  "(mesh open)" if dv is None else f"{dv:+.2%}")
            row["goal"] = "yes" if _meets(hd, dv) else "no"
        if row["goal"] == "yes" or not ref.is_volume or 2 * res > max_resolution or \
                4.0 * took > max_seconds:
            return row
        res *= 2


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--examples", type=Path, default=EXAMPLES,
                    help="folder of .scad files (searched recursively)")
    ap.add_argument("--resolution", type=int, default=256,
                    help="mesh voxels along the longest side")
    ap.add_argument("--max-resolution", type=int, default=1024,
                    help="mesh again at twice the resolution while a goal is missed, "
                         "up to this")
    ap.add_argument("--max-seconds", type=float, default=600.0,
                    help="and while the next mesh is expected to take at most this")
    ap.add_argument("--samples", type=int, default=20000,
                    help="surface samples per mesh for the Hausdorff distance")
    ap.add_argument("--method", choices=("mc", "dc"), default="dc",
                    help="meshing: marching cubes or dual contouring")
    ap.add_argument("--only", default="", help="only examples whose path contains this")
    ap.add_argument("--fit-bounds", action=argparse.BooleanOptionalAction, default=True,
                    help="csdf.mesh(fit_bounds=...): sample planes just inside the faces "
                         "of the bounds (CAD parts' caps carry thin flanges)")
    a = ap.parse_args()
    if shutil.which("openscad") is None:
        sys.exit("openscad is not on PATH (apt-get install openscad)")
    files = [f for f in sorted(a.examples.rglob("*.scad")) if a.only in str(f)]
    print(f"| example | result | dim | Hausdorff / diagonal | volume vs OpenSCAD | "
          f"goals (<= {HAUSDORFF_GOAL:.1%}, <= {VOLUME_GOAL:.0%}) | resolution | "
          f"s (read + meshes) |")
    print("|---|---|---|---|---|---|---|---|")
    counts: dict[str, int] = {}
    goals = {"yes": 0, "no": 0}
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        for f in files:
            try:
                row = run(f, a.resolution, a.samples, a.method, Path(tmp),
                          a.max_resolution, a.max_seconds, a.fit_bounds)
            except subprocess.TimeoutExpired:
                row = {"example": str(f.relative_to(f.parents[1])),
                       "result": "openscad timed out", "dim": "", "hausdorff": "",
                       "volume_diff": "", "goal": "", "resolution": "", "seconds": ""}
            key = row["result"].split(":")[0].split(";")[0]
            counts[key] = counts.get(key, 0) + 1
            if row["goal"]:
                goals[row["goal"]] += 1
            print(f"| {row['example']} | {row['result']} | {row['dim']} | "
                  f"{row['hausdorff']} | {row['volume_diff']} | {row['goal']} | "
                  f"{row['resolution']} | {row['seconds']} |", flush=True)
    print()
    print(", ".join(f"{k}: {v}" for k, v in sorted(counts.items())))
    print(f"3D examples compared: {goals['yes'] + goals['no']}, meeting both goals: "
          f"{goals['yes']}; total {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
