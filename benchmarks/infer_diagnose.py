"""Why :func:`csdf.infer` gets a random tree's structure wrong (issue 21): per seeded tree
of ``bench_infer.py``, which stage failed.

For every tree (the benchmark's trees and clouds, drawn from the same seed in the same
order) this runs ``infer`` and, when the structure is not exact, reports:

* ``cands``: for each leaf of the truth, whether a candidate of its kind lies on the
  part of the leaf's surface that shows (median distance of those points below
  ``2 tau``), and which candidate;
* ``truth``: the score of the true tree made of the true primitives (with the run's
  scorer: its samples, noise level and penalty) against the score of the inferred
  tree: lower means the search missed a better tree, higher means the score itself
  prefers the wrong tree;
* ``cand-truth``: the true tree made of the matched candidates, refined jointly as
  ``infer`` refines its trees, scored the same way (what the search could reach);
* ``same solid``: the IoU of the inferred and true solids on a 64^3 grid (a tree of
  another structure that makes the same solid: the data cannot tell them apart).

The truth is used only to *report*; nothing here feeds back into ``infer``.

Run: ``python benchmarks/infer_diagnose.py [--trees 50] [--views full] [--bands 4-5]
[--only 3,17] [--time-limit 30] [--effort S]``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_infer import (  # noqa: E402
    _shape_of,
    _tree_surface,
    cloud,
    exact_structure,
    iou,
    random_tree,
)

import csdf  # noqa: E402
from csdf.infer import api as A  # noqa: E402
from csdf.infer import tree as T  # noqa: E402


def _band(n: int) -> str:
    return "2-3" if n <= 3 else ("4-5" if n <= 5 else "6-8")


def match_candidates(prob, tree, leaves, rng) -> dict[int, tuple[int, float]]:
    """Truth leaf -> (the best candidate of its kind, the median distance in ``tau`` of
    the leaf's showing surface points to it); candidate -1 when none of its kind."""
    pts, which = _tree_surface(tree, leaves, rng, 300)
    out = {}
    for j, lf in enumerate(leaves):
        q = pts[which == j]
        best = (-1, np.inf)
        for i, c in enumerate(prob.pool.leaves):
            if c.kind != lf[0] or not len(q) or c.origin == "truth":
                continue
            d = float(np.median(np.abs(c.values(q)[0]))) / prob.tau
            if d < best[1]:
                best = (i, d)
        out[j] = best
    return out


def _relabel(tree, m: dict[int, int]):
    if isinstance(tree, (int, np.integer)):
        return m[int(tree)]
    return (tree[0], _relabel(tree[1], m), _relabel(tree[2], m))


def diagnose(k: int, tree, leaves, shape, view: str, pts, nrm, eye, time_limit: float,
             seed: int, rng, effort: float | None = None) -> str:
    """Lines of findings for tree ``k``."""
    t0 = time.perf_counter()
    res = A.infer(pts, nrm, viewpoint=eye, time_limit=time_limit, seed=seed,
                  effort=effort)
    dt = time.perf_counter() - t0
    box = csdf.as_field(shape).bounds
    same = iou(res.shape, shape, box)
    ok = exact_structure(res, tree, leaves)
    head = (f"{view} tree {k:2d} ({_band(len(leaves))}, {len(leaves)} leaves) "
            f"{'EXACT' if ok else 'miss '} iou {same:.3f} {dt:5.1f} s, "
            f"{res.candidates} candidates")
    truth_text = T.to_text(tree, lambda i: f"{leaves[i][0]}#{i}")
    lines = [head, f"    truth:    {truth_text}", f"    inferred: {res.tree}  "
             f"cost {res.cost:.4f}"]
    if ok:
        return "\n".join(lines)
    P = np.asarray(pts, float)
    vp = None if eye is None else np.asarray(eye, float)
    prob = A._setup(P, None if nrm is None else np.asarray(nrm, float), vp,
                    A.SOLID_KINDS, 8, seed, None, None)
    m = match_candidates(prob, tree, leaves, rng)
    lines.append("    cands:    " + ", ".join(
        f"{leaves[j][0]}#{j}->" + (f"c{i} ({d:.1f} tau)" if i >= 0 else "none")
        for j, (i, d) in m.items()) + f"  [{len(prob.pool.leaves)} first candidates, "
        f"tau {prob.tau:.4g}, penalty {prob.pool.penalty:.4f}]")
    true_leaves = [A.Leaf(lf[0], np.asarray(lf[1], float), np.asarray(lf[2], float),
                          dict(lf[3]), origin="truth") for lf in leaves]
    idx = prob.pool.add(true_leaves)
    st = prob.pool.scorer().score(_relabel(tree, dict(enumerate(idx))))
    lines.append(f"    truth score {st.total:.4f} (data {st.data:.4f}, free {st.free:.4f})"
                 f" vs inferred {res.cost:.4f}")
    if all(i >= 0 and d < 2.0 for i, d in m.values()):
        ct = _relabel(tree, {j: i for j, (i, _) in m.items()})
        sc = prob.pool.scorer().score(ct)
        lines.append(f"    cand-truth score {sc.total:.4f} (data {sc.data:.4f}, free "
                     f"{sc.free:.4f})")
        rt = A._refined_tree(prob, ct)
        sc = prob.pool.scorer().score(rt)
        lines.append(f"    refined cand-truth score {sc.total:.4f} (data {sc.data:.4f}, "
                     f"free {sc.free:.4f})")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--trees", type=int, default=50)
    ap.add_argument("--time-limit", type=float, default=30.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--views", default="full")
    ap.add_argument("--bands", default="2-3,4-5,6-8")
    ap.add_argument("--first", type=int, default=0, help="skip trees before this one")
    ap.add_argument("--only", default="", help="only these trees (comma-separated)")
    ap.add_argument("--effort", type=float, default=None, help="infer's effort")
    a = ap.parse_args()
    rng = np.random.default_rng(a.seed)
    truths = [random_tree(rng, int(rng.integers(2, 9))) for _ in range(a.trees)]
    shapes = [_shape_of(tree, leaves) for tree, leaves in truths]
    bands = set(a.bands.split(","))
    only = {int(k) for k in a.only.split(",") if k.strip()}
    diag_rng = np.random.default_rng(12345)
    for view in a.views.split(","):
        for k, ((tree, leaves), shape) in enumerate(zip(truths, shapes)):
            box = csdf.as_field(shape).bounds
            diag = float(np.linalg.norm(box[1] - box[0]))
            pts, nrm, eye = cloud(shape, view, 0.002 * diag, rng, box)  # (same draws)
            if k < a.first or _band(len(leaves)) not in bands or (only and k not in only):
                continue
            print(diagnose(k, tree, leaves, shape, view, pts, nrm, eye, a.time_limit, a.seed,
                           diag_rng, a.effort), flush=True)


if __name__ == "__main__":
    main()
