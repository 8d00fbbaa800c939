"""CSG inference from point clouds (issue 21): ``csdf.infer`` on random CSG trees of csdf
primitives, sampled in full and scanned from one view, scored against the truth.

Trees (seeded): 2-8 primitives (boxes, cylinders, spheres, cones, tori; axis-aligned
or turned by a random angle about a random axis), grown from a base solid by unions
(parts attached at a surface point), differences (notches and holes cut at a surface
point) and intersections (trims), each new leaf applied at the root or at a random
subtree. A tree is kept when every leaf is the tree's surface for at least 5 % of 400
points sampled on that leaf's surface (a leaf that shows nowhere cannot be recovered
from points).

Clouds: ``csdf.sample_surface`` (20,000 points with normals, all around) and
``csdf.scan`` from one camera (640 x 480, 30 degrees field of view, normals not given: ``infer``
estimates them, turned to the viewpoint), Gaussian noise of 0.2 % of the bounding
diagonal.

Measures: **exact structure up to the truth's symmetries** (:func:`structure`: the
truth's kinds and count of primitives, matched by kind and position, and a tree that,
built of the true primitives, is the true solid: the true tree up to the rewritings
that leave the true object unchanged, as BOP scores a pose up to the object's
symmetries), **as written** (the issue's stricter reading: the tree as written equals
the truth up to the order of commutative operands and of a chain's subtrahends, which
counts a cut placed before or after a union it does not reach as a miss although no
data can tell them apart), the same of the tree ``infer(prefer='global')`` returns,
**Chamfer** (the mean of both directed distances from 5,000 points on one surface to
the other's mesh, marching cubes at 160, as a fraction of the truth's bounding
diagonal), **IoU** of the signs on a 64^3 grid over the truth's box padded by 10 %, the
**primitive count** against the truth's, and **seconds** per shape.

Run: ``python benchmarks/bench_infer.py [--trees 100] [--time-limit 30] [--effort S]
[--seed 0] [--views full,scan] [--bands 2-3,4-5] [--only 5,72] [--verbose]``;
``--zoo [--out DIR]`` for the zoo parts. ``--effort 30 --time-limit 300`` gives the
effort of a 30 s limit with results that do not depend on the machine's load (its
seconds do).

Two revisions side by side: ``--verbose`` prints each tree's cost to the last digit and
its CPU seconds, so the same command run from a checkout of each revision (``git
worktree add``), alternating or at the same time under the same load, shows whether a
speed change left every result as it was and what it saved in CPU time, which wall
seconds on a shared machine do not. ``--only`` runs the listed trees alone (every
cloud is still drawn, so each tree keeps its cloud).
"""

from __future__ import annotations

import argparse
import math
import platform
import statistics
import time

import numpy as np
from scipy.optimize import linear_sum_assignment

import csdf
from csdf.backends.meshdist import MeshDistance
from csdf.infer import infer
from csdf.infer import tree as T

KINDS = ("box", "cylinder", "sphere", "cone", "torus")
#: every tree is a new program: the interpreter where it is enough, so that fewer
#: kernels are compiled (meshing and surface sampling use the compiled evaluator)
BACKEND = "interp"


def _rotation(rng) -> np.ndarray:
    if rng.random() < 0.6:  # axis-aligned: one of the three axis choices
        perms = [np.eye(3), np.eye(3)[[1, 2, 0]], np.eye(3)[[2, 0, 1]]]
        return perms[rng.integers(3)].T
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    return csdf.Pose.from_rotvec(axis * rng.uniform(0.2, 1.2)).rotation


def _leaf(rng, kind: str, scale: float, centre: np.ndarray) -> tuple:
    s = scale
    if kind == "box":
        vals = {k: float(rng.uniform(0.5, 1.0) * s) for k in ("size_x", "size_y", "size_z")}
    elif kind == "cylinder":
        vals = {"radius": float(rng.uniform(0.2, 0.45) * s),
                "height": float(rng.uniform(0.6, 1.2) * s)}
    elif kind == "sphere":
        vals = {"radius": float(rng.uniform(0.3, 0.55) * s)}
    elif kind == "cone":
        r1 = float(rng.uniform(0.3, 0.5) * s)
        vals = {"r1": r1, "r2": float(rng.uniform(0.05, 0.6) * r1),
                "height": float(rng.uniform(0.6, 1.0) * s)}
    else:
        R = float(rng.uniform(0.3, 0.45) * s)
        vals = {"major": R, "minor": float(rng.uniform(0.25, 0.45) * R)}
    return (kind, _rotation(rng), np.asarray(centre, float), vals)


def solid(kind: str, R: np.ndarray, t: np.ndarray, v: dict):
    """A posed primitive with plain numbers (no parameters)."""
    if kind == "sphere":
        s = csdf.sphere(v["radius"])
    elif kind == "cylinder":
        s = csdf.cylinder(v["radius"], v["height"])
    elif kind == "cone":
        s = csdf.capped_cone(v["r1"], v["r2"], v["height"])
    elif kind == "torus":
        s = csdf.torus(v["major"], v["minor"])
    else:
        s = csdf.box((v["size_x"], v["size_y"], v["size_z"]))
    return s.rotate(R).translate(tuple(float(c) for c in t))


def _shape_of(tree, leaves):
    return T.build(tree, lambda i: solid(*leaves[i]))


def random_tree(rng, k: int, tries: int = 200):
    """A random tree of ``k`` primitives whose every leaf shows (see the module docs):
    ``(tree, leaves [(kind, R, t, sizes)])``."""
    for _ in range(tries):
        base = _leaf(rng, str(rng.choice(["box", "cylinder", "sphere"])), 1.6, np.zeros(3))
        leaves = [base]
        tree = 0
        ok = True
        for i in range(1, k):
            p, _ = _tree_surface(tree, leaves, rng, 64)
            if len(p) == 0:
                ok = False
                break
            centre = p[rng.integers(len(p))]
            op = str(rng.choice(["union", "difference", "intersection"], p=[0.45, 0.4, 0.15]))
            scale = {"union": 0.8, "difference": 0.6, "intersection": 1.4}[op]
            if op == "intersection":
                centre = 0.7 * centre
            leaves.append(_leaf(rng, str(rng.choice(KINDS)), scale, centre))
            paths = [pt for pt, _ in T.subtrees(tree)]
            path = () if rng.random() < 0.7 else paths[rng.integers(len(paths))]
            sub = dict(T.subtrees(tree))[path]
            tree = T.replace(tree, path, (op, sub, i))
        if ok and _all_show(tree, leaves, rng):
            return tree, leaves
    raise RuntimeError("no valid tree found")


def _leaf_points(leaf, n: int, rng) -> np.ndarray:
    """``(n, 3)`` points on a leaf's surface: random points around it moved onto it by
    one step along the exact distance's gradient (the primitives' distances are exact,
    so the step lands on the surface; a second step for round-off)."""
    fld = csdf.as_field(solid(*leaf), backend=BACKEND)
    q = leaf[2] + rng.normal(0.0, max(leaf[3].values()), (n, 3))
    for _ in range(2):
        f, g = fld.value_and_grad(q)
        q = q - f[:, None] * g / np.maximum(np.sum(g * g, axis=1, keepdims=True), 1e-300)
    return q


def _tree_surface(tree, leaves, rng, per_leaf: int) -> tuple[np.ndarray, np.ndarray]:
    """Points on the tree's surface ``(M, 3)`` and the leaf each lies on ``(M,)``: points
    on each leaf's surface where the tree's field is 0 too (that leaf is the tree's
    surface there)."""
    fld = csdf.as_field(_shape_of(tree, leaves), backend=BACKEND)
    pts, which = [], []
    for i, lf in enumerate(leaves):
        q = _leaf_points(lf, per_leaf, rng)
        on = np.abs(fld.value(q)) <= 1e-9
        pts.append(q[on])
        which.append(np.full(int(on.sum()), i))
    return np.concatenate(pts), np.concatenate(which)


def _all_show(tree, leaves, rng) -> bool:
    """Every leaf is the tree's surface for at least 5 % of the points sampled on it."""
    _, which = _tree_surface(tree, leaves, rng, 400)
    share = np.bincount(which, minlength=len(leaves)) / 400
    return bool(share.min() >= 0.05)


def _match(res, leaves) -> dict[int, int] | None:
    """Inferred primitive index -> truth leaf index (same kind, nearest centres), or
    None when the counts or kinds differ."""
    if len(res.primitives) != len(leaves):
        return None
    n = len(leaves)
    cost = np.full((n, n), 1e9)
    for i, p in enumerate(res.primitives):
        for j, lf in enumerate(leaves):
            if p["kind"] == lf[0]:
                cost[i, j] = float(np.linalg.norm(np.asarray(p["translation"]) - lf[2]))
    r, c = linear_sum_assignment(cost)
    if cost[r, c].max() >= 1e9:
        return None
    return {int(i): int(j) for i, j in zip(r, c)}


def exact_structure(res, tree, leaves, text: str | None = None, form=T.canonical) -> bool:
    """Whether the inferred tree (``text``, default ``res.tree``) is the truth up to
    the order of commutative operands (``form``: :func:`tree.canonical`; or
    :func:`tree.normal_form`, up to the writings of one set), leaves matched by kind
    and position."""
    m = _match(res, leaves)
    if m is None:
        return False
    name_to_index = {p["name"]: i for i, p in enumerate(res.primitives)}
    inferred = T.from_text(text or res.tree, name_to_index.__getitem__)
    return form(inferred, lambda i: str(m[i])) == form(tree)


def preferred(res, prefer: str) -> str:
    """Of the trees the points cannot tell from the inferred one
    (``res.alternatives``), the one ``infer(prefer=prefer)`` returns: whose trims and
    cuts reach the fewest (``'local'``) or the most (``'global'``) primitives, then
    the best score, written with its cuts after its intersections."""
    alts = res.alternatives or [res.tree]
    names = {p["name"]: i for i, p in enumerate(res.primitives)}
    trees = [T.from_text(a, names.__getitem__) for a in alts]
    sign = 1 if prefer == "local" else -1
    # (the alternatives after the first are in score order; the first is the search's)
    order = sorted(range(len(trees)), key=lambda k: (sign * T.scope(trees[k]), k))
    inv = {i: n for n, i in names.items()}
    return T.to_text(T.cuts_last(trees[order[0]]), inv.__getitem__)


def _grid(box: np.ndarray, n: int) -> np.ndarray:
    """The ``(n^3, 3)`` points of an ``n``^3 grid over ``box`` ``(2, 3)`` padded by 10 %
    on every side."""
    lo, hi = box
    pad = 0.1 * (hi - lo)
    axes = [np.linspace(lo[d] - pad[d], hi[d] + pad[d], n) for d in range(3)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


def same_solid(a, b, box: np.ndarray, n: int = 96) -> bool:
    """Whether two shapes are one solid: their signs agree at every point of an
    ``n``^3 grid over ``box`` padded by 10 % and at 4,000 points 0.2 % of the diagonal
    inside and outside ``a``'s surface (so that a thin sliver between the grid's
    samples is not missed)."""
    g = _grid(box, n)
    sp, sn = csdf.sample_surface(a, 2000, seed=2)
    h = 0.002 * float(np.linalg.norm(box[1] - box[0]))
    p = np.concatenate([g, sp + h * sn, sp - h * sn])
    fa = csdf.as_field(a, backend=BACKEND).value(p)
    fb = csdf.as_field(b, backend=BACKEND).value(p)
    return bool(np.all((fa <= 0) == (fb <= 0)))


def _rebuilt(res, leaves, text: str | None = None):
    """The inferred tree (``text``, default ``res.tree``) built of the **true**
    primitives, matched by kind and position; None when the kinds or count differ."""
    m = _match(res, leaves)
    if m is None:
        return None
    names = {p["name"]: i for i, p in enumerate(res.primitives)}
    inferred = T.from_text(text or res.tree, names.__getitem__)
    return T.build(inferred, lambda i: solid(*leaves[m[i]]))


def structure(res, tree, leaves, box: np.ndarray, text: str | None = None) -> bool:
    """**Exact structure up to the truth's symmetries**: the inferred tree (``text``,
    default ``res.tree``) has the truth's primitives (kinds and count; matched by kind
    and position) and, built of the **true** primitives, is the truth's solid
    (:func:`same_solid`). So it is the true tree up to the rewritings that leave the
    true object unchanged: the order of commutative operands, a difference as an
    intersection with a complement (``(a - b) & c`` is ``(a & c) - b``), and a cut or
    trim moved across a union or a feature that it does not reach
    (``(a | d) - c`` is ``(a - c) | d`` when ``c`` and ``d`` do not meet). The data
    cannot tell these apart whatever the noise, just as a pose metric cannot tell the
    poses a symmetric object's symmetries relate (BOP scores a pose over them)."""
    rebuilt = _rebuilt(res, leaves, text)
    return rebuilt is not None and same_solid(_shape_of(tree, leaves), rebuilt, box)


def view_camera(eye: np.ndarray, box: np.ndarray) -> csdf.Camera:
    """The one-view clouds' sensor at ``eye``, looking at the centre of ``box``."""
    return csdf.Camera.look_at(eye, 0.5 * (box[0] + box[1]), fov=30.0, width=640,
                               height=480)


def depth_image(shape, cam: csdf.Camera) -> np.ndarray:
    """``(H*W,)`` noise-free depth (camera-frame z) of what ``cam`` sees of ``shape``,
    row-major, ``inf`` where it sees nothing (the sensor's own drop of grazing returns
    included: :func:`csdf.scan` without noise)."""
    pc, _ = csdf.scan(shape, cam, backend=BACKEND)
    z = np.full(cam.width * cam.height, np.inf)
    u = np.rint(cam.fx * pc[:, 0] / pc[:, 2] + cam.cx).astype(np.int64)
    v = np.rint(cam.fy * pc[:, 1] / pc[:, 2] + cam.cy).astype(np.int64)
    z[v * cam.width + u] = pc[:, 2]
    return z


def seen_leaves(leaves, shape, cam: csdf.Camera) -> np.ndarray:
    """``(k,)`` bool: the leaves the sensor sees enough of to find them. A noise-free
    return lies on the leaf nearest to it; a leaf is seen when it holds at least
    ``max(30, M // 200)`` of the ``M`` returns, the fewest points
    :func:`csdf.detect_primitives` accepts by default (so a leaf under it cannot be
    found by any candidate search built on detection, and a cut hidden at the back of
    the object by none at all)."""
    pc, _ = csdf.scan(shape, cam, backend=BACKEND)
    if not len(pc):
        return np.zeros(len(leaves), bool)
    pw = cam.camera_to_world(pc)
    d = np.stack([np.abs(csdf.as_field(solid(*lf), backend=BACKEND).value(pw))
                  for lf in leaves])
    count = np.bincount(np.argmin(d, axis=0), minlength=len(leaves))
    return count >= max(30, len(pw) // 200)


def same_view(a, b, cam: csdf.Camera, tol: float, share: float = 0.002) -> bool:
    """Whether ``cam`` sees the same of two shapes: their noise-free depth images
    differ by more than ``tol`` (or one sees a surface where the other sees none) at
    no more than ``share`` of the pixels where either sees one (the pixels on a
    silhouette that a ray grazes)."""
    za, zb = depth_image(a, cam), depth_image(b, cam)
    hit = np.isfinite(za) | np.isfinite(zb)
    with np.errstate(invalid="ignore"):
        differ = hit & ~(np.abs(za - zb) <= tol)
    return bool(differ.sum() <= share * max(int(hit.sum()), 1))


def view_structure(res, tree, leaves, cam: csdf.Camera, tol: float,
                   text: str | None = None) -> bool:
    """**Exact structure up to the view** (one view): as :func:`structure`, but the
    inferred tree built of the true primitives need only look the same as the truth
    from the sensor (:func:`same_view`), not be the same solid at the back, which no
    data from this view shows."""
    rebuilt = _rebuilt(res, leaves, text)
    return rebuilt is not None and same_view(_shape_of(tree, leaves), rebuilt, cam, tol)


_SURFACES: dict[int, tuple] = {}  # id(shape) -> (its surface points, its mesh distance)


def _surface(shape) -> tuple:
    """5,000 points on a shape's surface (``sample_surface``: on the zero set to 1e-10)
    and the exact distance to its mesh (marching cubes at 160), kept for the truths."""
    key = id(shape)
    if key not in _SURFACES:
        pts, _ = csdf.sample_surface(shape, 5000, seed=1)
        m = csdf.mesh(shape, resolution=160, method="mc", progress=False, check_thin=False)
        _SURFACES[key] = (pts, MeshDistance(m), shape)  # (the shape keeps its id)
    return _SURFACES[key]


def chamfer(a, b, diag: float) -> float:
    """Symmetric mean distance between the surfaces, as a fraction of ``diag``: from
    5,000 points on each surface to the other surface's mesh (exact distance to its
    triangles), so that no sampling gap between two point sets adds to it."""
    pa, ma, _ = _surface(a)
    pb, mb, _ = _surface(b)
    total = float(np.abs(mb.value(pa)).mean()) + float(np.abs(ma.value(pb)).mean())
    if id(a) in _SURFACES and a is not b:
        del _SURFACES[id(a)]  # (only the truths are kept)
    return 0.5 * total / diag


def iou(a, b, box: np.ndarray, n: int = 64) -> float:
    g = _grid(box, n)
    ia = csdf.as_field(a, backend=BACKEND).value(g) <= 0
    ib = csdf.as_field(b, backend=BACKEND).value(g) <= 0
    u = np.logical_or(ia, ib).sum()
    return float(np.logical_and(ia, ib).sum() / u) if u else 1.0


def cloud(shape, view: str, sigma: float, rng, box):
    if view == "full":
        p, n = csdf.sample_surface(shape, 20000, seed=int(rng.integers(1 << 30)))
        return p + rng.normal(0, sigma, p.shape), n, None
    centre = 0.5 * (box[0] + box[1])
    r = 2.5 * float(np.linalg.norm(box[1] - box[0]))
    az, el = rng.uniform(0, 2 * math.pi), rng.uniform(0.3, 0.8)
    eye = centre + r * np.array([math.cos(az) * math.cos(el), math.sin(az) * math.cos(el),
                                 math.sin(el)])
    cam = csdf.Camera.look_at(eye, centre, fov=30.0, width=640, height=480)
    pc, _ = csdf.scan(shape, cam, noise=sigma, seed=int(rng.integers(1 << 30)),
                      backend=BACKEND)
    M = cam.pose
    return pc @ M[:3, :3].T + M[:3, 3], None, eye


def four_views(shape, sigma: float, rng) -> tuple[np.ndarray, np.ndarray]:
    """Points and normals (facing each camera: outwards) of four scans from around and
    above, merged in the world frame."""
    box = csdf.as_field(shape, backend=BACKEND).bounds
    centre = 0.5 * (box[0] + box[1])
    r = 2.5 * float(np.linalg.norm(box[1] - box[0]))
    pts, nrm = [], []
    for k in range(4):
        az = math.pi / 4 + k * math.pi / 2
        eye = centre + r * np.array([math.cos(az) * 0.8, math.sin(az) * 0.8, 0.6])
        cam = csdf.Camera.look_at(eye, centre, fov=30.0, width=640, height=480)
        pc, nc = csdf.scan(shape, cam, noise=sigma, seed=int(rng.integers(1 << 30)),
                           backend=BACKEND)
        M = cam.pose
        pts.append(pc @ M[:3, :3].T + M[:3, 3])
        nrm.append(nc @ M[:3, :3].T)
    return np.concatenate(pts), np.concatenate(nrm)


def bench_zoo(time_limit: float, seed: int, out_dir: str | None,
              effort: float | None = None) -> None:
    """The zoo parts scanned from four views: structure, IoU and Chamfer."""
    rng = np.random.default_rng(seed)
    print("\n## Zoo parts, four views merged\n")
    print("| part | points | primitives (inferred / hand-written leaves) | IoU | Chamfer | "
          "s | inferred structure |")
    print("|---|---|---|---|---|---|---|")
    for name in ("flange", "electrical_box", "connector", "cross_shaft"):
        shape = csdf.zoo.load(name)
        box = csdf.as_field(shape, backend=BACKEND).bounds
        diag = float(np.linalg.norm(box[1] - box[0]))
        pts, nrm = four_views(shape, 0.002 * diag, rng)
        res = infer(pts, nrm, time_limit=time_limit, seed=seed, effort=effort)
        n_hand = sum(1 for c in csdf.as_field(shape).program.calls)
        print(f"| {name} | {len(pts):,} | {len(res.primitives)} / {n_hand} | "
              f"{iou(res.shape, shape, box):.3f} | {chamfer(res.shape, shape, diag):.2%} | "
              f"{res.seconds:.1f} | `{res.tree.replace('|', chr(92) + '|')}` |", flush=True)
        if out_dir:
            from pathlib import Path

            Path(out_dir, f"{name}.inferred.csdf").write_text(res.text)


def _seen_table(rows: dict) -> None:
    """One view: how many trees show every primitive to the sensor, and the measures on
    those (a primitive the sensor does not see cannot be recovered from its points)."""
    print("\nOne view, by what the sensor sees (:func:`seen_leaves`, "
          ":func:`view_structure`):\n")
    print("| primitives | trees | every primitive seen | up to the view (all) | seen: "
          "up to the view | seen: up to the truth's symmetries | seen: as written | "
          "seen: IoU (median) | seen: IoU >= 0.97 | seen: Chamfer (median) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for band in ("2-3", "4-5", "2-5", "6-8"):
        r = rows.get(("scan", band), []) if band != "2-5" else \
            rows.get(("scan", "2-3"), []) + rows.get(("scan", "4-5"), [])
        if not r:
            continue
        s = [x for x in r if x[7]]
        vst = sum(x[8] for x in r) / len(r)
        if not s:
            print(f"| {band} | {len(r)} | 0 | {vst:.0%} | - | - | - | - | - | - |")
            continue
        n = len(s)
        print(f"| {band} | {len(r)} | {n} | {vst:.0%} | {sum(x[8] for x in s) / n:.0%} | "
              f"{sum(x[0] for x in s) / n:.0%} | {sum(x[1] for x in s) / n:.0%} | "
              f"{statistics.median(x[4] for x in s):.3f} | "
              f"{sum(x[4] >= 0.97 for x in s) / n:.0%} | "
              f"{statistics.median(x[3] for x in s):.2%} |", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--trees", type=int, default=100)
    ap.add_argument("--time-limit", type=float, default=30.0)
    ap.add_argument("--effort", type=float, default=None,
                    help="infer's effort (default: the time limit); with a larger time "
                    "limit the results do not depend on the machine's load")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--views", default="full,scan")
    ap.add_argument("--bands", default="2-3,4-5,6-8", help="only trees of these sizes "
                    "(the others' clouds are drawn all the same, so a tree's cloud does "
                    "not depend on this)")
    ap.add_argument("--zoo", action="store_true", help="only the zoo parts")
    ap.add_argument("--out", default=None, help="a folder for the zoo parts' inferred "
                    ".csdf models")
    ap.add_argument("--only", default=None, help="comma-separated tree numbers: run only "
                    "these (their clouds are the same as in a full run)")
    ap.add_argument("--verbose", action="store_true", help="a line for every tree, with "
                    "its cost to the last digit and its CPU seconds")
    a = ap.parse_args()
    only = None
    if a.only:
        try:
            only = {int(k) for k in a.only.split(",")}
        except ValueError:
            ap.error(f"--only: expected comma-separated tree numbers, got {a.only!r}")
    if a.zoo:
        bench_zoo(a.time_limit, a.seed, a.out, a.effort)
        return
    rng = np.random.default_rng(a.seed)
    print(f"machine: {platform.processor() or platform.machine()}, "
          f"{csdf.parallel.N_THREADS} cores; {a.trees} trees, time limit {a.time_limit} s, "
          f"effort {a.effort or a.time_limit}")
    truths = [random_tree(rng, int(rng.integers(2, 9))) for _ in range(a.trees)]
    shapes = [_shape_of(tree, leaves) for tree, leaves in truths]
    rows: dict[tuple[str, str], list] = {}
    for view in a.views.split(","):
        for k, ((tree, leaves), shape) in enumerate(zip(truths, shapes)):
            box = csdf.as_field(shape).bounds
            diag = float(np.linalg.norm(box[1] - box[0]))
            pts, nrm, eye = cloud(shape, view, 0.002 * diag, rng, box)
            n = len(leaves)
            band = "2-3" if n <= 3 else ("4-5" if n <= 5 else "6-8")
            if band not in a.bands.split(",") or (only is not None and k not in only):
                continue
            t0, c0 = time.perf_counter(), time.process_time()
            try:
                res = infer(pts, nrm, viewpoint=eye, time_limit=a.time_limit, seed=a.seed,
                            effort=a.effort)
            except csdf.CsdfError as exc:
                print(f"{view} tree {k}: {exc}")
                continue
            dt, cpu = time.perf_counter() - t0, time.process_time() - c0
            st = structure(res, tree, leaves, box)
            ex = exact_structure(res, tree, leaves)
            exw = exact_structure(res, tree, leaves, preferred(res, "global"))
            seen = vst = None
            if eye is not None:
                cam = view_camera(eye, box)
                seen = bool(seen_leaves(leaves, shape, cam).all())
                vst = view_structure(res, tree, leaves, cam, 0.002 * diag)
            row = (st, ex, exw, chamfer(res.shape, shape, diag), iou(res.shape, shape, box),
                   len(res.primitives) / n, dt, seen, vst)
            rows.setdefault((view, band), []).append(row)
            if a.verbose:
                one = "" if eye is None else f", every primitive seen {seen}, up to the " \
                    f"view {vst}"
                kinds = [f"{lf[0]}{i}" for i, lf in enumerate(leaves)]
                print(f"{view} tree {k} ({n}): structure {st}, as written {ex} (global "
                      f"{exw}){one}, Chamfer {row[3]:.2%}, IoU {row[4]:.3f}, {dt:.1f} s "
                      f"({cpu:.1f} CPU s), cost {res.cost!r}, "
                      f"truth {T.to_text(tree, kinds.__getitem__)}, "
                      f"inferred {res.tree}", flush=True)
        print(f"\n## {view}\n")
        print("| primitives | trees | exact structure (up to the truth's symmetries) | "
              "as written | as written, prefer global | Chamfer (median) | "
              "Chamfer <= 0.5 % | IoU (median) | IoU >= 0.97 | count / truth (median, max) "
              "| s (median, max) |")
        print("|---|---|---|---|---|---|---|---|---|---|---|")
        for band in ("2-3", "4-5", "2-5", "6-8"):
            r = rows.get((view, band), []) if band != "2-5" else \
                rows.get((view, "2-3"), []) + rows.get((view, "4-5"), [])
            if not r:
                continue
            st, ex, exw, ch, io, cnt, ts, _, _ = (list(x) for x in zip(*r))
            print(f"| {band} | {len(r)} | {sum(st) / len(r):.0%} | {sum(ex) / len(r):.0%} | "
                  f"{sum(exw) / len(r):.0%} | {statistics.median(ch):.2%} | "
                  f"{sum(v <= 0.005 for v in ch) / len(r):.0%} | "
                  f"{statistics.median(io):.3f} | {sum(v >= 0.97 for v in io) / len(r):.0%} | "
                  f"{statistics.median(cnt):.2f}, {max(cnt):.2f} | "
                  f"{statistics.median(ts):.1f}, {max(ts):.1f} |", flush=True)
        if view == "scan":
            _seen_table(rows)


if __name__ == "__main__":
    main()
