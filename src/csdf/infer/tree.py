"""CSG trees over candidate primitives, as plain data: what the search builds, evaluates
on sampled distances, compares and turns into a csdf shape.

A tree is ``int`` (a leaf: the index of a candidate primitive) or ``(op, a, b)`` with
``op`` one of ``'union'``, ``'intersection'``, ``'difference'`` and ``a``, ``b`` trees.
On distances the ops are csdf's: ``min(a, b)``, ``max(a, b)``, ``max(a, -b)``.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator

import numpy as np

__all__ = ["OPS", "Tree", "evaluate", "field_of", "leaves", "size", "subtrees", "replace",
           "remove", "canonical", "normal_form", "to_text", "from_text", "build", "scope",
           "relocations", "cuts_last"]

Tree = int | tuple
OPS = ("union", "intersection", "difference")


def evaluate(tree: Tree, leaf_values: np.ndarray) -> np.ndarray:
    """The tree's field ``(N,)`` from its leaves' fields ``leaf_values (L, N)``."""
    return field_of(tree, leaf_values.__getitem__)


def field_of(tree: Tree, row: Callable[[int], np.ndarray]) -> np.ndarray:
    """The tree's field from ``row(leaf)``, each leaf's field ``(N,)`` at the same
    points."""
    if isinstance(tree, (int, np.integer)):
        return row(int(tree))
    op, a, b = tree
    fa, fb = field_of(a, row), field_of(b, row)
    if op == "union":
        return np.minimum(fa, fb)
    if op == "intersection":
        return np.maximum(fa, fb)
    return np.maximum(fa, -fb)


def leaves(tree: Tree) -> list[int]:
    """The leaves, left to right."""
    if isinstance(tree, (int, np.integer)):
        return [int(tree)]
    return leaves(tree[1]) + leaves(tree[2])


def relabel(tree: Tree, mapping: dict[int, int]) -> Tree:
    """The tree with each leaf ``i`` in ``mapping`` renamed ``mapping[i]`` (the others
    kept)."""
    if isinstance(tree, (int, np.integer)):
        return mapping.get(int(tree), int(tree))
    return (tree[0], relabel(tree[1], mapping), relabel(tree[2], mapping))


def size(tree: Tree) -> int:
    """The number of leaves."""
    if isinstance(tree, (int, np.integer)):
        return 1
    return size(tree[1]) + size(tree[2])


def subtrees(tree: Tree, path: tuple = ()) -> Iterator[tuple[tuple, Tree]]:
    """Every ``(path, subtree)``; a path is the sequence of child indices (1 or 2)."""
    yield path, tree
    if not isinstance(tree, (int, np.integer)):
        yield from subtrees(tree[1], path + (1,))
        yield from subtrees(tree[2], path + (2,))


def replace(tree: Tree, path: tuple, new: Tree) -> Tree:
    """The tree with the subtree at ``path`` replaced by ``new``."""
    if not path:
        return new
    op, a, b = tree
    if path[0] == 1:
        return (op, replace(a, path[1:], new), b)
    return (op, a, replace(b, path[1:], new))


def remove(tree: Tree, leaf: int) -> Tree | None:
    """The tree without ``leaf`` (its parent replaced by its sibling); None when the
    tree is that leaf alone."""
    if isinstance(tree, (int, np.integer)):
        return None if int(tree) == leaf else tree
    op, a, b = tree
    if a == leaf:
        return b
    if b == leaf:
        return a
    ra, rb = remove(a, leaf), remove(b, leaf)
    return (op, ra, rb)


def canonical(tree: Tree, label: Callable[[int], str] = str) -> str:
    """A text that is equal for two trees exactly when they are the same up to the order
    of the operands of unions and intersections (and of the subtrahends of a chain of
    differences: ``(a - b) - c`` is ``a - (b | c)``); leaves printed by ``label``."""
    if isinstance(tree, (int, np.integer)):
        return label(int(tree))
    op, a, b = tree
    if op == "difference":
        base, subs = a, [b]
        while not isinstance(base, (int, np.integer)) and base[0] == "difference":
            subs.append(base[2])
            base = base[1]
        parts = sorted(x for s in subs for x in _operands(s, "union", label))
        sub = parts[0] if len(parts) == 1 else "U(" + ",".join(parts) + ")"
        return f"D({canonical(base, label)},{sub})"
    return _flat(tree, op, label)


def _operands(tree: Tree, op: str, label: Callable[[int], str]) -> list[str]:
    """The canonical texts of the operands of a chain of ``op``, flattened."""
    items: list[str] = []
    stack = [tree]
    while stack:
        t = stack.pop()
        if not isinstance(t, (int, np.integer)) and t[0] == op:
            stack.extend((t[1], t[2]))
        else:
            items.append(canonical(t, label))
    return items


def _flat(tree: Tree, op: str, label: Callable[[int], str]) -> str:
    """A union's or intersection's operands flattened and sorted."""
    items = _operands(tree, op, label)
    if len(items) == 1:
        return items[0]
    return ("U(" if op == "union" else "I(") + ",".join(sorted(items)) + ")"


def normal_form(tree: Tree, label: Callable[[int], str] = str) -> str:
    """A text that is equal for two trees that are the same set whatever their leaves:
    :func:`canonical`'s forms, and also a difference's subtrahends moved out of an
    intersection (``(a - b) & c`` is ``(a & c) - b``). On distances the two are the
    same field (``max`` is associative and commutative), so trees of one normal form
    score the same."""
    if label is str:
        return _nf_text(_nf_memo(tree))
    return _nf_text(_nf(tree, label))


#: the most subtrees whose normal forms (leaves labelled by ``str``) are kept: the
#: search's moves rebuild a tree around subtrees it has met before
NF_MEMO = 200_000
_NF_MEMO: dict = {}


def _nf_memo(tree: Tree) -> tuple[tuple[str, list[str]], list[str]]:
    """:func:`_nf` with ``str`` labels, each subtree's kept (:data:`NF_MEMO` at most; the
    values are never changed in place)."""
    got = _NF_MEMO.get(tree)
    if got is None:
        got = _nf(tree, str, _nf_memo)
        if len(_NF_MEMO) >= NF_MEMO:
            _NF_MEMO.clear()
        _NF_MEMO[tree] = got
    return got


def _nf(tree: Tree, label: Callable[[int], str], sub: Callable | None = None
        ) -> tuple[tuple[str, list[str]], list[str]]:
    """``((kind, items), subtrahends)``: the set ``base - U(subtrahends)`` with ``base``
    a leaf (kind ``'L'``, one item), a union (``'U'``) or an intersection (``'I'``) of
    the items (texts, sorted). ``sub``: gives the operands' (default: this)."""
    if isinstance(tree, (int, np.integer)):
        return ("L", [label(int(tree))]), []
    op, a, b = tree
    if sub is None:
        na, nb = _nf(a, label), _nf(b, label)
    else:
        na, nb = sub(a), sub(b)
    if op == "union":
        items = [x for n in (na, nb) for x in (n[0][1] if n[0][0] == "U" and not n[1]
                                               else [_nf_text(n)])]
        return ("U", sorted(items)), []
    if op == "intersection":
        items = [x for n in (na, nb) for x in (n[0][1] if n[0][0] == "I"
                                               else [_nf_text((n[0], []))])]
        return ("I", sorted(items)), sorted(na[1] + nb[1])
    subs = nb[0][1] if nb[0][0] == "U" and not nb[1] else [_nf_text(nb)]
    return na[0], sorted(na[1] + subs)


def _nf_text(n: tuple[tuple[str, list[str]], list[str]]) -> str:
    (kind, items), subs = n
    base = items[0] if kind == "L" else f"{kind}(" + ",".join(items) + ")"
    if not subs:
        return base
    return f"D({base}," + (subs[0] if len(subs) == 1 else "U(" + ",".join(subs) + ")") + ")"


def to_text(tree: Tree, label: Callable[[int], str] = str) -> str:
    """Infix text: ``(a | b) - c``."""
    if isinstance(tree, (int, np.integer)):
        return label(int(tree))
    sym = {"union": "|", "intersection": "&", "difference": "-"}[tree[0]]
    return f"({to_text(tree[1], label)} {sym} {to_text(tree[2], label)})"


def from_text(text: str, index: Callable[[str], int]) -> Tree:
    """The tree of :func:`to_text`'s infix text (fully parenthesised; leaves numbered by
    ``index(name)``)."""
    ops = {"|": "union", "&": "intersection", "-": "difference"}
    tokens = text.replace("(", " ( ").replace(")", " ) ").split()
    pos = 0

    def node() -> Tree:
        nonlocal pos
        tok = tokens[pos]
        pos += 1
        if tok != "(":
            return index(tok)
        a = node()
        op = ops[tokens[pos]]
        pos += 1
        b = node()
        pos += 1  # ')'
        return (op, a, b)

    return node()


def build(tree: Tree, leaf: Callable[[int], object]):
    """The csdf shape of a tree, leaves made by ``leaf(i)``."""
    if isinstance(tree, (int, np.integer)):
        return leaf(int(tree))
    op, a, b = tree
    sa, sb = build(a, leaf), build(b, leaf)
    if op == "union":
        return sa | sb
    if op == "intersection":
        return sa & sb
    return sa - sb


def scope(tree: Tree) -> int:
    """The number of leaves each intersection and difference applies to, summed: how
    many primitives the trims and cuts reach in the tree's writing. Of two trees the
    points cannot tell apart, the one of smaller scope applies each trim or cut to
    fewer parts (``(a - b) | c`` rather than ``(a | c) - b`` when ``b`` misses ``c``)."""
    if isinstance(tree, (int, np.integer)):
        return 0
    op, a, b = tree
    own = 0 if op == "union" else size(tree)
    return own + scope(a) + scope(b)


def _detach(tree: Tree, path: tuple) -> Tree:
    """The tree without the subtree at ``path`` (not the root): its parent replaced by
    its sibling."""
    parent = _at(tree, path[:-1])
    sibling = parent[2] if path[-1] == 1 else parent[1]
    return replace(tree, path[:-1], sibling)


def _at(tree: Tree, path: tuple) -> Tree:
    for k in path:
        tree = tree[k]
    return tree


def relocations(tree: Tree) -> list[Tree]:
    """Every tree with one trim or cut moved: a subtree ``S`` that is an operand of an
    intersection or the right operand of a difference, taken out (its parent replaced
    by its sibling) and applied by the same operation to another subtree of the rest
    (``(a | c) - b`` gives ``(a - b) | c``, ``(a | c) - b`` back, ``(c - b) | a``...).
    The same leaves; the sets may differ (the caller scores them)."""
    out: list[Tree] = []
    seen: set[str] = {canonical(tree)}
    for path, _ in subtrees(tree):
        if not path:
            continue
        parent = _at(tree, path[:-1])
        op = parent[0]
        if op == "union" or (op == "difference" and path[-1] == 1):
            continue
        moved = _at(tree, path)
        rest = _detach(tree, path)
        for where, sub in subtrees(rest):
            t = replace(rest, where, (op, sub, moved))
            key = canonical(t)
            if key not in seen:
                seen.add(key)
                out.append(t)
    return out


def cuts_last(tree: Tree) -> Tree:
    """The same set with every difference taken out of the intersections it lies in:
    ``(a - b) & c`` written ``(a & c) - b`` (on distances both are ``max(a, -b, c)``),
    so that a tree reads as :func:`normal_form` does: the material (unions and
    intersections), then the cuts."""
    if isinstance(tree, (int, np.integer)):
        return tree
    op, a, b = tree
    a, b = cuts_last(a), cuts_last(b)
    if op == "intersection":
        if not isinstance(a, (int, np.integer)) and a[0] == "difference":
            return ("difference", cuts_last(("intersection", a[1], b)), a[2])
        if not isinstance(b, (int, np.integer)) and b[0] == "difference":
            return ("difference", cuts_last(("intersection", a, b[1])), b[2])
    return (op, a, b)
