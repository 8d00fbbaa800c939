"""csdf.infer's search: bounded scoring (:meth:`Scorer.score_below`) makes the same
decisions as full scores in the beam search and the polish, and the memo of normal
forms gives the forms computed afresh."""

from __future__ import annotations

import math

import numpy as np
import pytest

from csdf.infer import search as S
from csdf.infer import tree as T
from csdf.infer.search import Scorer, beam_search, polish
from strategies import random_csg_tree


def _scorer(seed: int, n: int = 9, m: int = 3000) -> Scorer:
    """A scorer over ``n`` made-up leaves with every term: ``m`` points (more than
    :data:`.search.BOUND_POINTS`, so the bound on the first points is used), normals,
    free-space points and surface points."""
    rng = np.random.default_rng(seed)
    # leaves whose fields are near 0 on a share of the points each: trees differ
    at_points = rng.normal(size=(n, m)) * rng.uniform(0.05, 1.0, (n, 1))
    dots = rng.uniform(-0.2, 1.0, (n, m))
    at_free = rng.normal(0.3, 0.3, (n, 800))
    s = 40 * n
    owner = np.repeat(np.arange(n), 40)
    at_surface = rng.normal(size=(n, s)) * 0.2
    at_surface[owner, np.arange(s)] = 0.0  # each on its own leaf's surface
    weight = rng.uniform(0.0, 0.002, s)
    unsupported = rng.random((2, s)) < 0.5
    return Scorer(at_points, dots, at_free, 0.1, 0.004, at_surface, owner, weight,
                  unsupported, np.zeros(n, dtype=int))


def test_score_below_is_none_exactly_when_the_total_reaches_the_bound():
    sc = _scorer(0)
    rng = np.random.default_rng(1)
    pruned = kept = 0
    for _ in range(300):
        t = random_csg_tree(rng, list(rng.permutation(9)[: int(rng.integers(1, 7))]))
        full = sc.score(t)
        for bound in (full.total - 0.05, full.total - 1e-6, full.total, full.total + 1e-6,
                      full.total + 0.05, math.inf):
            got = sc.score_below(t, bound)
            if full.total >= bound:
                assert got is None
                pruned += 1
            else:
                assert got is not None
                assert (got.data, got.free, got.total) == (full.data, full.free, full.total)
                kept += 1
    assert pruned > 500 and kept > 500


def _full_scores(monkeypatch):
    """Scores always taken in full, whatever the bound (the search before bounded
    scoring)."""
    def full(self, tree, bound):
        return Scorer.score(self, tree)

    def score(self, tree):
        self.count += 1
        return _plain(self, tree)

    monkeypatch.setattr(Scorer, "score_below", full)
    monkeypatch.setattr(Scorer, "score", score)


def _plain(self, tree):
    """The score as written before bounded scoring (every term, all the points)."""
    data = float(np.mean(self._costs(tree)))
    g, _ = S.evaluate_oriented(tree, self.at_free, None)
    free = float(np.mean(np.minimum((np.maximum(-g, 0.0) / self.tau) ** 2, 1.0)))
    block, weight, row = self._bare(S.parities(tree))
    h = T.field_of(tree, lambda i: block[row[i]])
    free += float(weight[np.abs(h) <= S.ON_SURFACE * self.tau].sum())
    return S.Scored(tree, data, free, data + free + self.penalty * T.size(tree))


@pytest.mark.parametrize("seed", [2, 3])
def test_bounded_scores_change_no_beam_and_no_polish(seed, monkeypatch):
    """The beam search and the polish give the same trees and scores whether trees that
    cannot win are scored in part or in full, and score fewer points."""
    sc = _scorer(seed)
    cands = list(range(sc.n_leaves))
    kinds = ["box", "box", "box", "cylinder", "cylinder", "cylinder", "sphere", "sphere",
             "sphere"]
    found = beam_search(sc, cands, 5, 6, math.inf)
    start = found[len(found) // 2].tree
    polished = polish(sc, start, cands, 6, math.inf, kinds)
    with monkeypatch.context() as mp:
        _full_scores(mp)
        want = beam_search(_scorer(seed), cands, 5, 6, math.inf)
        want_polished = polish(_scorer(seed), start, cands, 6, math.inf, kinds)
    assert [(s.tree, s.total) for s in found] == [(s.tree, s.total) for s in want]
    assert (polished.tree, polished.total) == (want_polished.tree, want_polished.total)
    assert T.size(polished.tree) >= 2


def test_memoised_normal_forms_are_the_forms():
    rng = np.random.default_rng(4)
    T._NF_MEMO.clear()
    for _ in range(2000):
        t = random_csg_tree(rng, list(rng.permutation(8)[: int(rng.integers(1, 8))]))
        fresh = T._nf_text(T._nf(t, str))
        assert T.normal_form(t) == fresh
        assert T.normal_form(t) == T.normal_form(t, lambda i: str(i))
    assert len(T._NF_MEMO) > 2000  # subtrees kept


def test_kept_subtree_fields_change_no_score():
    """Scores with the fields of some trees' subtrees kept (:meth:`Scorer.keep`) are
    those computed afresh, for trees built around those subtrees and for others."""
    sc = _scorer(5)
    rng = np.random.default_rng(6)
    base = random_csg_tree(rng, [0, 1, 2, 3, 4, 5])
    fresh = {}
    trees = [base] + [T.replace(base, path, (op, sub, c)) for path, sub in T.subtrees(base)
                      for op in ("union", "difference") for c in (6, 7)]
    trees += [random_csg_tree(rng, list(rng.permutation(9)[:5])) for _ in range(50)]
    for t in trees:
        s = sc.score(t)
        fresh[t] = (s.data, s.free, s.total)
    sc.keep([base] + [T.remove(base, c) for c in range(6)])
    assert len(sc._kept[0]) >= 5 and len(sc._kept[1]) >= 5
    for t in trees:
        s = sc.score(t)
        assert (s.data, s.free, s.total) == fresh[t]
