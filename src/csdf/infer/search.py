"""Search over CSG trees of candidate primitives, scored on sampled distances.

Every candidate's exact signed distance is evaluated once at a sample of the points
(with the cosine between its gradient and each point's normal), at points of the free
space a single-view sensor looked through, and at points on every candidate's own
surface; a tree's field at those points is then min/max of its leaves' rows, so
scoring a tree costs a few array operations, not an evaluation of the tree.

Score (lower is better), with ``tau`` a few noise levels:

* data: ``mean(min((f(p) / tau)^2, 1))`` over the points (a truncated quadratic: a
  point explained within the noise costs ~0, one not explained at all costs 1); a point
  on the tree's surface whose normal points into the tree there is not explained (it
  costs 1): a bump and a dent through the same points differ in their normals;
* free space: with a viewpoint, the same of ``max(0, -f(q)) / tau`` over the free-space
  points ``q`` (material where the sensor saw through, towards measured points or past
  the object's silhouette); without one (a cloud taken all around), the area of the
  tree's surface with no measured point near it facing its way (surface the tree
  makes up), as a share of the measured surface's area;
* size: ``penalty`` per primitive (a primitive must explain more than that share of
  the points to be kept).

A tree must agree with its leaves' orientations (:attr:`csdf.infer.candidates.Leaf.sign`):
a leaf whose points face out of it lies under an even number of right operands of
differences, one whose points face into it (a cut) under an odd number.

:func:`beam_search` grows trees by one leaf a step: any subtree ``S`` becomes
``S | c``, ``S & c``, ``S - c`` or ``c - S`` for an unused candidate ``c`` that may
explain points the tree leaves unexplained (:meth:`Scorer.useful`); the ``beam`` best
distinct trees of each size go on (distinct sets: :func:`csdf.infer.tree.normal_form`,
so that ``(a - b) & c`` and ``(a & c) - b`` take one place). :func:`polish` improves one
tree by local moves (a leaf moved elsewhere, dropped, added, or swapped for another
candidate of its kind).
"""

from __future__ import annotations

import heapq
import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .tree import Tree, field_of, leaves, normal_form, remove, replace, size

#: a point sampled on a leaf's surface counts as the tree's surface when the tree's
#: field there is within this share of ``tau`` of 0. ``1`` (the default) also counts
#: the samples of a leaf just inside another operand, within ``tau`` of its surface,
#: though that operand's surface is the tree's there: unmeasured surface where there is
#: none, which penalises larger trees. ``1e-6`` counts only where the leaf is the
#: active operand (its own value is 0 there, to round-off): the made-up surface as
#: defined, but the search then finds some larger trees that the size penalty alone
#: does not stop (benchmarks/INFER_RESULTS.md, sessions 16 and 17: with orientations
#: refined it keeps tree 88 and one-view 28, and loses one-view 79)
ON_SURFACE = 1.0

#: the most leaf sets whose unsupported surface points a :class:`Scorer` keeps
#: gathered (:meth:`Scorer._bare`)
BARE_CACHE = 512

__all__ = ["Scorer", "Scored", "beam_search", "polish", "consistent", "parities", "swap",
           "evaluate_oriented", "grow"]


@dataclass
class Scored:
    """A tree with its score: ``total = data + free + penalty * leaves``."""

    tree: Tree
    data: float
    free: float
    total: float


def evaluate_oriented(tree: Tree, values: np.ndarray, dots: np.ndarray | None,
                      memo: dict | None = None, fill: bool = False
                      ) -> tuple[np.ndarray, np.ndarray | None]:
    """The tree's field ``(N,)`` from its leaves' fields ``values`` ``(L, N)``, and the
    cosine ``(N,)`` between the tree's outward gradient and the points' normals from
    the leaves' ``dots`` ``(L, N)`` (None without normals): the active leaf's, negated
    under a difference's right operand. ``memo``: ``{subtree: (field, cosine)}`` of
    subtrees already evaluated at these points (never changed in place), looked up
    first; with ``fill``, every inner subtree evaluated is added to it."""
    if isinstance(tree, (int, np.integer)):
        return values[int(tree)], None if dots is None else dots[int(tree)]
    if memo:
        got = memo.get(tree)
        if got is not None:
            return got
    if dots is None and memo is None:
        return field_of(tree, values.__getitem__), None
    op, a, b = tree
    fa, da = evaluate_oriented(a, values, dots, memo, fill)
    fb, db = evaluate_oriented(b, values, dots, memo, fill)
    if dots is None:
        if op == "union":
            out = np.minimum(fa, fb), None
        elif op == "intersection":
            out = np.maximum(fa, fb), None
        else:
            out = np.maximum(fa, -fb), None
    else:
        if op == "difference":
            fb = -fb
            db = -db
            pick_a = fa >= fb
        elif op == "union":
            pick_a = fa <= fb
        else:
            pick_a = fa >= fb
        out = np.where(pick_a, fa, fb), np.where(pick_a, da, db)
    if fill and memo is not None:
        memo[tree] = out
    return out


def parities(tree: Tree, odd: bool = False) -> dict[int, bool]:
    """``{leaf: under an odd number of right operands of differences}``."""
    if isinstance(tree, (int, np.integer)):
        return {int(tree): odd}
    op, a, b = tree
    return {**parities(a, odd), **parities(b, odd ^ (op == "difference"))}


def consistent(tree: Tree, signs: np.ndarray) -> bool:
    """Whether every leaf's orientation ``signs[leaf]`` (+1, -1, 0: any) agrees with
    its place in the tree (module docs)."""
    for leaf, odd in parities(tree).items():
        s = signs[leaf]
        if s and (s < 0) != odd:
            return False
    return True


class Scorer:
    """Scores trees from their leaves' values at sampled points.

    Args:
        at_points: ``(L, M)`` the leaves' signed distances at the sample of the points.
        dots: ``(L, M)`` cosines between each leaf's gradient and each point's normal,
            or None (normals of unknown sign).
        at_free: ``(L, Q)`` the leaves' distances at free-space points, or None.
        tau: the noise level (scene units).
        penalty: the cost of one leaf.
        at_surface: ``(L, S)`` the leaves' distances at points sampled on the leaves'
            own surfaces (clouds taken all around), or None.
        owner: ``(S,)`` the leaf each surface point lies on.
        weight: ``(S,)`` the share of the measured surface's area each surface point
            stands for.
        unsupported: ``(2, S)`` which surface points have no measured point near them
            facing their way: row 0 on a material leaf, row 1 on a cut one.
        signs: ``(L,)`` the leaves' orientations (+1, -1, 0).
        surface: in place of ``at_surface``, a callable that gives ``(len(rows),
            len(idx))`` the leaves ``rows``' distances at the surface points ``idx``
            (points on those leaves' own surfaces): a table evaluated as the trees
            scored need it (:meth:`.pool.Pool.surface_block`).
    """

    def __init__(self, at_points: np.ndarray, dots: np.ndarray | None,
                 at_free: np.ndarray | None, tau: float, penalty: float,
                 at_surface: np.ndarray | None = None, owner: np.ndarray | None = None,
                 weight: np.ndarray | None = None, unsupported: np.ndarray | None = None,
                 signs: np.ndarray | None = None,
                 surface: Callable[[list[int], np.ndarray], np.ndarray] | None = None):
        self.at_points = at_points
        self.dots = dots
        self.at_free = at_free
        self.tau = float(tau)
        self.penalty = float(penalty)
        self.at_surface = at_surface
        if surface is None and at_surface is not None:
            def surface(rows: list[int], idx: np.ndarray) -> np.ndarray:
                return at_surface[np.ix_(rows, idx)]
        #: the made-up-surface term's values (None: no such term)
        self.surface = surface
        self.owner = owner
        self.weight = weight
        self.unsupported = unsupported
        n = at_points.shape[0]
        self.signs = np.zeros(n, dtype=int) if signs is None else np.asarray(signs, int)
        self.count = 0
        self._cache: dict[tuple, tuple] = {}
        # the subtrees :meth:`keep` was given: at the points (with normals: their
        # field and data costs at even and odd parity, :meth:`_field_cost`; without:
        # their field and None), at the free-space points (their field and None)
        self._kept: tuple[dict, dict] = ({}, {})
        # {leaf: its data costs (M,) at even and odd parity} (with normals)
        self._leaf_costs: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        if surface is not None:
            order = np.argsort(owner, kind="stable")
            self._order = order
            starts = np.searchsorted(owner[order], np.arange(n + 1))
            self._slices = [order[starts[i]:starts[i + 1]] for i in range(n)]

    def keep(self, trees: list[Tree]) -> None:
        """Keep the fields of ``trees`` and of all their subtrees (at the points and at
        the free-space points) for the trees scored next, forgetting those kept
        before: a local move rebuilds a tree around subtrees of the tree it moves from
        and of that tree without one leaf (:func:`polish`), and its score then
        evaluates only the nodes the move made (the same arrays: the same score)."""
        self._kept = ({}, {})
        for t in trees:
            if self.dots is None:
                evaluate_oriented(t, self.at_points, None, self._kept[0], True)
            else:
                self._keep_costs(t)
            if self.at_free is not None:
                evaluate_oriented(t, self.at_free, None, self._kept[1], True)

    @property
    def n_leaves(self) -> int:
        return self.at_points.shape[0]

    def _leaf_cost(self, i: int, odd: bool) -> np.ndarray:
        """``(M,)`` the data cost of each sample point explained by leaf ``i`` (with
        normals): at even parity ``min((f / tau)^2, 1)`` where the cosine of its
        gradient and the point's normal is positive, else 1; at odd parity (under
        the right operand of a difference) the same of ``-f`` and the negated cosine
        (computed once per leaf)."""
        got = self._leaf_costs.get(i)
        if got is None:
            f, d = self.at_points[i], self.dots[i]
            sq = np.minimum((f / self.tau) ** 2, 1.0)
            got = self._leaf_costs[i] = (np.where(d > 0.0, sq, 1.0),
                                         np.where(-d > 0.0, sq, 1.0))
        return got[1 if odd else 0]

    def _field_cost(self, tree: Tree, odd: bool, field: bool = True
                    ) -> tuple[np.ndarray | None, np.ndarray]:
        """``tree``'s field ``(M,)`` at the sample (with normals; None without
        ``field``, where it is not kept: the costs alone) and each point's data cost
        ``(M,)`` with the tree at parity ``odd``: at each point that of the active
        leaf (:meth:`_leaf_cost`) at the parity it has there, as a point's cost from
        the tree's field and oriented cosine (:func:`evaluate_oriented`) would be: the
        same leaf is active, and negating its field and cosine is what an odd parity
        does to them."""
        if isinstance(tree, (int, np.integer)):
            return self.at_points[int(tree)], self._leaf_cost(int(tree), odd)
        got = self._kept[0].get(tree)
        if got is not None:
            return got[0], got[2 if odd else 1]
        op, a, b = tree
        fa, ca = self._field_cost(a, odd)
        if op == "difference":
            fb, cb = self._field_cost(b, not odd)
            fb = -fb
            pick_a = fa >= fb
        else:
            fb, cb = self._field_cost(b, odd)
            pick_a = fa <= fb if op == "union" else fa >= fb
        return np.where(pick_a, fa, fb) if field else None, np.where(pick_a, ca, cb)

    def _keep_costs(self, tree: Tree) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(field, costs at even parity, at odd)`` of ``tree`` (:meth:`_field_cost`),
        kept for it and each of its subtrees (:meth:`keep`)."""
        if isinstance(tree, (int, np.integer)):
            i = int(tree)
            return self.at_points[i], self._leaf_cost(i, False), self._leaf_cost(i, True)
        got = self._kept[0].get(tree)
        if got is not None:
            return got
        op, a, b = tree
        fa, ea, oa = self._keep_costs(a)
        fb, eb, ob = self._keep_costs(b)
        if op == "difference":
            fb = -fb
            eb, ob = ob, eb
            pick_a = fa >= fb
        else:
            pick_a = fa <= fb if op == "union" else fa >= fb
        out = (np.where(pick_a, fa, fb), np.where(pick_a, ea, eb), np.where(pick_a, oa, ob))
        self._kept[0][tree] = out
        return out

    def _costs(self, tree: Tree) -> np.ndarray:
        """``(M,)`` each sample point's data cost under ``tree``."""
        if self.dots is not None:
            return self._field_cost(tree, False, False)[1]
        f, _ = evaluate_oriented(tree, self.at_points, None, self._kept[0])
        return np.minimum((f / self.tau) ** 2, 1.0)

    def useful(self, tree: Tree, candidates: list[int], free: float, share: float = 0.5
               ) -> list[int]:
        """The candidates that may pay for their place in ``tree``: a point the tree
        does not explain can only come to be explained on a new leaf's surface, so a
        leaf on whose surface fewer than ``penalty / 2`` of the points lie that the
        tree leaves unexplained (cost above 1/4) cannot lower the data term by its
        penalty. Every candidate is useful while the tree's free-space term ``free``
        exceeds the penalty (a leaf may trim material without explaining points)."""
        if free > self.penalty:
            return list(candidates)
        bad = self._costs(tree) > 0.25
        if not bad.any():
            return []
        on = np.abs(self.at_points[np.asarray(candidates, int)][:, bad]) <= self.tau
        gain = on.sum(axis=1) / self.at_points.shape[1]
        return [c for c, g in zip(candidates, gain) if g >= share * self.penalty]

    def score(self, tree: Tree) -> Scored:
        """The :class:`Scored` tree."""
        out = self.score_below(tree, math.inf)
        assert out is not None
        return out

    def score_below(self, tree: Tree, bound: float) -> Scored | None:
        """The :class:`Scored` tree, or None when its total is ``bound`` or more. The
        terms are taken cheapest first (the size, the data, the free space, the
        made-up surface), each one 0 or more, and the rest are skipped as soon as
        those taken reach ``bound``: a local move or a beam's tree that cannot win
        costs its data term alone (the same decisions as comparing full scores:
        floating-point addition of terms of one sign is monotone)."""
        self.count += 1
        pen = self.penalty * size(tree)
        data = _mean(self._costs(tree))
        if data + pen >= bound:
            return None
        free = 0.0
        if self.at_free is not None and self.at_free.shape[1]:
            g, _ = evaluate_oriented(tree, self.at_free, None, self._kept[1])
            free = _mean(np.minimum((np.maximum(-g, 0.0) / self.tau) ** 2, 1.0))
            if data + free + pen >= bound:
                return None
        if self.surface is not None:
            # the share of the tree's own surface where no point was measured: a
            # leaf's surface point counts where the tree's field is near 0 there
            # (ON_SURFACE)
            block, weight, row = self._bare(parities(tree))
            h = field_of(tree, lambda i: block[row[i]])
            free += float(weight[np.abs(h) <= ON_SURFACE * self.tau].sum())
        total = data + free + pen
        return None if total >= bound else Scored(tree, data, free, total)

    def _bare(self, par: dict[int, bool]) -> tuple[np.ndarray, np.ndarray, dict[int, int]]:
        """For a tree's leaves and their parities ``par``: the surface points of those
        leaves that no measured point supports the way each is used, as ``(the leaves'
        values there (K, B), their weights (B,), {leaf: its row})``, kept for the next
        tree of the same leaves (the search's moves put one leaf elsewhere: the same
        set, in hundreds of trees), :data:`BARE_CACHE` sets at most."""
        key = tuple(sorted(par.items()))
        got = self._cache.get(key)
        if got is None:
            rows = [i for i, _ in key]
            idx = np.concatenate([self._slices[i][self.unsupported[int(odd), self._slices[i]]]
                                  for i, odd in key])
            got = (self.surface(rows, idx), self.weight[idx],
                   {i: k for k, i in enumerate(rows)})
            if len(self._cache) >= BARE_CACHE:
                self._cache.clear()
            self._cache[key] = got
        return got


def _mean(x: np.ndarray) -> float:
    """``float(np.mean(x))`` of a 1-D float64 array, without its checks: the same
    sum (``np.add.reduce``, pairwise) divided by the same count, so the same value
    bit for bit."""
    return float(np.add.reduce(x) / len(x))


def _paths(tree: Tree, path: tuple = (), odd: bool = False
           ) -> list[tuple[tuple, Tree, bool]]:
    """``(path, subtree, odd)`` of every subtree, ``odd`` its parity (under an odd
    number of right operands of differences)."""
    if isinstance(tree, (int, np.integer)):
        return [(path, tree, odd)]
    op, a, b = tree
    left = _paths(a, path + (1,), odd)
    right = _paths(b, path + (2,), odd ^ (op == "difference"))
    return [(path, tree, odd)] + left + right


def grow(tree: Tree, c: int, signs: np.ndarray) -> list[Tree]:
    """Every tree with one more leaf ``c`` (see the module docs) that agrees with the
    leaves' orientations ``signs`` (``tree`` itself is taken to agree)."""
    out = []
    sc = signs[c]
    for path, sub, odd in _paths(tree):
        # c's parity: that of the subtree's place, flipped as a right operand of "-"
        c_even_ok = sc >= 0  # c may sit at even parity
        c_odd_ok = sc <= 0
        c_ok_here = c_odd_ok if odd else c_even_ok
        c_ok_flip = c_even_ok if odd else c_odd_ok
        if c_ok_here:
            out.append(replace(tree, path, ("union", sub, c)))
            out.append(replace(tree, path, ("intersection", sub, c)))
        if c_ok_flip:
            out.append(replace(tree, path, ("difference", sub, c)))
        if c_ok_here and _flips(sub, odd, signs):
            out.append(replace(tree, path, ("difference", c, sub)))
    return out


def _flips(sub: Tree, odd: bool, signs: np.ndarray) -> bool:
    """Whether the subtree ``sub`` (at parity ``odd``) may take the opposite parity."""
    for leaf, o in parities(sub, not odd).items():
        s = signs[leaf]
        if s and (s < 0) != o:
            return False
    return True


def beam_search(scorer: Scorer, candidates: list[int], max_primitives: int, beam: int,
                deadline: float, history: list | None = None, t0: float | None = None,
                seeds: list[Tree] | None = None) -> list[Scored]:
    """The best trees found, best first (the ``beam`` best of every size tried).

    Args:
        scorer: scores trees over the leaves ``0 .. scorer.n_leaves - 1``.
        candidates: the leaves the trees may use.
        max_primitives: the most leaves of a tree.
        beam: trees kept per size.
        deadline: a ``time.perf_counter()`` to stop at.
        history: gets ``(seconds, leaves, total, tree)`` of each new best.
        t0: the start of the run (for ``history``).
        seeds: trees that join the beam at their size (a search resumed with more
            candidates).
    """
    t0 = time.perf_counter() if t0 is None else t0
    signs = scorer.signs
    by_size: dict[int, list[Scored]] = {}
    for t in seeds or []:
        by_size.setdefault(size(t), []).append(scorer.score(t))
    level = [scorer.score(i) for i in candidates if signs[i] >= 0]
    level = sorted(level + by_size.get(1, []), key=lambda s: s.total)[:beam]
    if not level:
        return []
    best = level[0]
    kept = list(level)
    if history is not None:
        history.append((time.perf_counter() - t0, 1, best.total, best.tree))
    stale = 0
    for k in range(2, max_primitives + 1):
        if time.perf_counter() > deadline:
            break
        # every tree of size k met (None: one that cannot make the beam), and the
        # beam's best totals so far (negated: a max-heap); a tree is scored only as far
        # as it may still beat the worst of them (Scorer.score_below: the same beam)
        seen: dict[str, Scored | None] = {normal_form(s.tree): s
                                          for s in by_size.get(k, [])}
        top = [-s.total for s in sorted(seen.values(), key=lambda s: s.total)[:beam]]
        heapq.heapify(top)
        for st in level:
            used = set(leaves(st.tree))
            # the trees grown from it are built around its subtrees (Scorer.keep)
            scorer.keep([st.tree])
            for c in scorer.useful(st.tree, candidates, st.free):
                if c in used:
                    continue
                for t in grow(st.tree, c, signs):
                    key = normal_form(t)
                    if key in seen:
                        continue
                    # a tree scoring above the beam's worst cannot make the beam
                    worst = -top[0] if len(top) >= beam else math.inf
                    sc = seen[key] = scorer.score_below(t, np.nextafter(worst, math.inf))
                    if sc is None:
                        continue
                    if len(top) < beam:
                        heapq.heappush(top, -sc.total)
                    elif sc.total < -top[0]:
                        heapq.heapreplace(top, -sc.total)
                if time.perf_counter() > deadline:
                    break
            if time.perf_counter() > deadline:
                break
        if not seen:
            break
        level = sorted((s for s in seen.values() if s is not None),
                       key=lambda s: s.total)[:beam]
        kept += level
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
    scorer.keep([])
    uniq: dict[str, Scored] = {}
    for s in sorted(kept, key=lambda s: s.total):
        uniq.setdefault(normal_form(s.tree), s)
    return list(uniq.values())


def swap(tree: Tree, old: int, new: int) -> Tree:
    """The tree with leaf ``old`` replaced by ``new``."""
    if isinstance(tree, (int, np.integer)):
        return new if int(tree) == old else tree
    return (tree[0], swap(tree[1], old, new), swap(tree[2], old, new))


def _moves(tree: Tree, candidates: list[int], useful: list[int], max_primitives: int,
           signs: np.ndarray, kinds: list[str]) -> list[Tree]:
    """The local moves from ``tree`` (see :func:`polish`); ``useful``: the candidates
    worth adding (:meth:`Scorer.useful`)."""
    out: list[Tree] = []
    used = leaves(tree)
    for c in used:
        rest = remove(tree, c)
        if rest is None:
            continue
        out.append(rest)
        out += grow(rest, c, signs)
        for o in candidates:  # the same place, another candidate of the kind
            if o not in used and kinds[o] == kinds[c]:
                t = swap(tree, c, o)
                if consistent(t, signs):
                    out.append(t)
    if len(used) < max_primitives:
        for c in useful:
            if c not in used:
                out += grow(tree, c, signs)
    return out


def polish(scorer: Scorer, tree: Tree, candidates: list[int], max_primitives: int,
           deadline: float, kinds: list[str]) -> Scored:
    """Local moves from ``tree`` while one lowers the score: take a leaf out and put it
    back anywhere with any op (the beam grew the tree in one order; an operand may
    belong elsewhere), drop a leaf, swap it for another candidate of its kind, or add
    an unused candidate anywhere. ``kinds``: each leaf's primitive kind."""
    best = scorer.score(tree)
    seen = {normal_form(tree)}
    while time.perf_counter() < deadline:
        found = best
        # the moves are built of the subtrees of the tree and of it less one leaf
        scorer.keep([best.tree] + [r for r in (remove(best.tree, c)
                                               for c in leaves(best.tree)) if r is not None])
        useful = scorer.useful(best.tree, candidates, best.free, 1.0)
        for t in _moves(best.tree, candidates, useful, max_primitives, scorer.signs, kinds):
            key = normal_form(t)
            if key in seen:
                continue
            seen.add(key)
            sc = scorer.score_below(t, found.total - 1e-12)
            if sc is not None and sc.total < found.total - 1e-12:
                found = sc
            if time.perf_counter() > deadline:
                break
        if found is best:
            break
        best = found
    scorer.keep([])
    return best
