"""Beam search over CSG trees of candidate primitives, scored on sampled distances.

Every candidate's exact signed distance is evaluated once at a sample of the points
(and, with a viewpoint, at points of the free space the sensor looked through); a
tree's field at those points is then min/max of its leaves' rows, so scoring a tree
costs a few array operations, not an evaluation of the tree.

Score (lower is better), with ``tau`` a few noise levels:

* data: ``mean(min((f(p) / tau)^2, 1))`` over the points (a truncated quadratic: a
  point explained within the noise costs ~0, one not explained at all costs 1);
* free space: the same of ``max(0, -f(q)) / tau`` over the free-space points ``q``
  (material where the sensor saw through costs); without a viewpoint (a cloud taken
  all around) instead the share of sample points on the candidates' surfaces that lie
  on the tree's surface (``|f| <= tau``) with no measured point near them (surface the
  tree makes up);
* size: ``penalty`` per primitive (about the share of the points the smallest
  detection explains, so a primitive must explain more than that to be kept).

A step grows a tree by one leaf: any subtree ``S`` becomes ``S | c``, ``S & c``,
``S - c`` or ``c - S`` for an unused candidate ``c``. The ``beam`` best distinct trees
(up to the order of commutative operands) of each size go on; the search stops at
``max_primitives`` leaves, when no tree of a size beats the best smaller one by more
than the penalty twice running, or at the time limit.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from .tree import Tree, canonical, evaluate, leaves, remove, replace, size, subtrees

__all__ = ["Scorer", "beam_search", "polish", "through_cuts", "Scored"]


@dataclass
class Scored:
    """A tree with its score: ``total = data + free + penalty * leaves``."""

    tree: Tree
    data: float
    free: float
    total: float


class Scorer:
    """Scores trees from their leaves' distances at the sample points ``(L, M)`` and the
    free-space points ``(L, Q)``."""

    def __init__(self, at_points: np.ndarray, at_free: np.ndarray | None, tau: float,
                 penalty: float, at_surface: np.ndarray | None = None,
                 unsupported: np.ndarray | None = None):
        self.at_points = at_points
        self.at_free = at_free
        self.tau = float(tau)
        self.penalty = float(penalty)
        self.at_surface = at_surface
        self.unsupported = unsupported

    def score(self, tree: Tree) -> Scored:
        f = evaluate(tree, self.at_points)
        data = float(np.mean(np.minimum((f / self.tau) ** 2, 1.0)))
        free = 0.0
        if self.at_free is not None and self.at_free.shape[1]:
            g = evaluate(tree, self.at_free)
            free = float(np.mean(np.minimum((np.maximum(-g, 0.0) / self.tau) ** 2, 1.0)))
        if self.at_surface is not None and self.at_surface.shape[1]:
            # the tree's own surface where no point was measured (a full scan)
            h = evaluate(tree, self.at_surface)
            free += float(np.mean((np.abs(h) <= self.tau) & self.unsupported))
        return Scored(tree, data, free, data + free + self.penalty * size(tree))


def _grow(tree: Tree, c: int) -> list[Tree]:
    """Every tree with one more leaf ``c`` (see the module docs)."""
    out = []
    for path, sub in subtrees(tree):
        for new in (("union", sub, c), ("intersection", sub, c), ("difference", sub, c),
                    ("difference", c, sub)):
            out.append(replace(tree, path, new))
    return out


def beam_search(scorer: Scorer, n_leaves: int, max_primitives: int, beam: int,
                deadline: float, history: list | None = None, t0: float | None = None
                ) -> list[Scored]:
    """The best trees found, best first (at most ``beam`` of the last size tried and the
    best of every smaller size). ``history`` gets ``(seconds, leaves, total, tree)`` of
    each new best; ``deadline``: a ``time.perf_counter()`` to stop at."""
    t0 = time.perf_counter() if t0 is None else t0
    level = sorted((scorer.score(i) for i in range(n_leaves)), key=lambda s: s.total)
    level = level[:beam]
    best = level[0]
    kept = [best]
    if history is not None:
        history.append((time.perf_counter() - t0, 1, best.total, best.tree))
    stale = 0
    for _ in range(2, min(max_primitives, n_leaves) + 1):
        if time.perf_counter() > deadline:
            break
        seen: dict[str, Scored] = {}
        for st in level:
            used = set(leaves(st.tree))
            for c in range(n_leaves):
                if c in used:
                    continue
                for t in _grow(st.tree, c):
                    key = canonical(t)
                    if key in seen:
                        continue
                    seen[key] = scorer.score(t)
                if time.perf_counter() > deadline:
                    break
            if time.perf_counter() > deadline:
                break
        if not seen:
            break
        level = sorted(seen.values(), key=lambda s: s.total)[:beam]
        kept.append(level[0])
        if level[0].total < best.total - 1e-12:
            improved = best.total - level[0].total
            best = level[0]
            if history is not None:
                history.append((time.perf_counter() - t0, size(best.tree), best.total,
                                best.tree))
            stale = 0 if improved > scorer.penalty else stale + 1
        else:
            stale += 1
        if stale >= 2:
            break
    out = sorted(kept + level, key=lambda s: s.total)
    uniq: dict[str, Scored] = {}
    for s in out:
        uniq.setdefault(canonical(s.tree), s)
    return list(uniq.values())



def _subtrahends(tree: Tree) -> set[int]:
    """The leaves that are cut away: the right operands of differences (directly, or
    through unions and intersections under them)."""
    out: set[int] = set()
    if not isinstance(tree, (int, np.integer)):
        op, a, b = tree
        out |= _subtrahends(a) | _subtrahends(b)
        if op == "difference":
            out |= set(leaves(b))
    return out


def _swap(tree: Tree, old: int, new: int) -> Tree:
    if isinstance(tree, (int, np.integer)):
        return new if int(tree) == old else tree
    return (tree[0], _swap(tree[1], old, new), _swap(tree[2], old, new))


def through_cuts(scorer: Scorer, tree: Tree, through: dict[int, int]) -> Scored:
    """``tree`` with each cut (a leaf cut away) turned into its variant in ``through``
    (candidate -> the same with its point-less faces moved out) unless that scores
    worse by more than a hundredth of the penalty: a hole whose bottom no point shows
    goes through (the points seen on its wall say nothing of its length, and a closed
    skin over its opening costs only the few free-space samples that fall in it)."""
    best = scorer.score(tree)
    for c in sorted(_subtrahends(best.tree)):
        v = through.get(c)
        if v is not None and v not in leaves(best.tree):
            sc = scorer.score(_swap(best.tree, c, v))
            if sc.total <= best.total + 0.01 * scorer.penalty:
                best = sc
    return best


def polish(scorer: Scorer, tree: Tree, n_leaves: int, max_primitives: int, deadline: float
           ) -> Scored:
    """Local moves from ``tree`` while one lowers the score: take a leaf out and put it
    back anywhere with any op (the beam grew the tree in one order; an operand may
    belong elsewhere), drop a leaf, or add an unused candidate anywhere."""
    best = scorer.score(tree)
    while time.perf_counter() < deadline:
        found = best
        used = leaves(best.tree)
        for c in used:
            rest = remove(best.tree, c)
            if rest is None:
                continue
            for t in [rest, *_grow(rest, c)]:
                sc = scorer.score(t)
                if sc.total < found.total - 1e-12:
                    found = sc
        if len(used) < max_primitives:
            for c in range(n_leaves):
                if c not in used:
                    for t in _grow(best.tree, c):
                        sc = scorer.score(t)
                        if sc.total < found.total - 1e-12:
                            found = sc
        if found is best:
            break
        best = found
    return best
