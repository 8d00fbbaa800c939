"""The marching-cubes case table, derived here from first principles.

For each of the 256 inside/outside patterns of a cube's corners we build the surface
polygons that separate inside from outside:

1. an edge is *crossed* when its two corners differ;
2. on each face, crossed edges are paired: with 2 crossed edges they pair up; with 4 (the
   ambiguous face, diagonal corners alike) the pairing keeps the *inside* corners apart
   (each polygon segment cuts off one inside corner). The rule depends only on the face's
   own corner pattern, so the two cubes sharing a face always agree, which makes the
   extracted surface watertight and 2-manifold;
3. every crossed edge lies on two faces, so the pairs link the crossed edges into
   disjoint cycles: the polygons (one per surface component inside the cube);
4. each polygon is oriented so its normal points from inside to outside, and
   triangulated as a fan from an apex whose diagonals stay off the cube's faces (a
   diagonal on a face could be repeated by the neighbouring cube).

The same components give manifold dual contouring one vertex per component.

Corner ``i`` of a cube sits at offset ``(i & 1, (i >> 1) & 1, (i >> 2) & 1)``; edge ``e``
joins corners ``EDGES[e]`` along axis ``EDGE_AXIS[e]``.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "CORNERS", "EDGES", "EDGE_AXIS", "EDGE_ORIGIN", "cube_components", "TRI_TABLE",
    "COMPONENT_TABLE", "MAX_TRIS", "MAX_COMPONENTS",
]

CORNERS = np.array([[i & 1, (i >> 1) & 1, (i >> 2) & 1] for i in range(8)], dtype=np.int64)

_edges = []
for _a in range(8):
    for _axis in range(3):
        _b = _a | (1 << _axis)
        if _b != _a:
            _edges.append((_a, _b, _axis))
EDGES = np.array([(a, b) for a, b, _ in _edges], dtype=np.int64)  # (12, 2)
EDGE_AXIS = np.array([axis for _, _, axis in _edges], dtype=np.int64)  # (12,)
EDGE_ORIGIN = CORNERS[EDGES[:, 0]]  # (12, 3) lower corner of each edge

# faces: (axis, side) -> the 4 corners in cyclic order around the face
_FACES = []
for _axis in range(3):
    u, v = [a for a in range(3) if a != _axis]
    for _side in (0, 1):
        cyc = []
        for du, dv in ((0, 0), (1, 0), (1, 1), (0, 1)):
            off = [0, 0, 0]
            off[_axis], off[u], off[v] = _side, du, dv
            cyc.append(off[0] | (off[1] << 1) | (off[2] << 2))
        _FACES.append(cyc)

_EDGE_OF = {}
for _e, (_a, _b) in enumerate(EDGES.tolist()):
    _EDGE_OF[(_a, _b)] = _e
    _EDGE_OF[(_b, _a)] = _e


def cube_components(inside: list[bool]) -> list[list[int]]:
    """Oriented polygons (lists of edge indices) for one corner pattern.

    Args:
        inside: 8 booleans, corner ``i`` inside the shape (``f < 0``).

    Returns:
        Polygons as cyclic lists of crossed edges, each ordered counter-clockwise seen
        from outside (normal from inside to outside).
    """
    links: dict[int, list[int]] = {}
    for cyc in _FACES:
        crossed = []
        for k in range(4):
            a, b = cyc[k], cyc[(k + 1) % 4]
            if inside[a] != inside[b]:
                crossed.append((k, _EDGE_OF[(a, b)]))
        if not crossed:
            continue
        if len(crossed) == 2:
            pairs = [(crossed[0][1], crossed[1][1])]
        else:
            # ambiguous face: pair each edge with the next one around an inside corner
            pairs = []
            for k in range(4):
                if inside[cyc[k]]:
                    e_prev = _EDGE_OF[(cyc[(k - 1) % 4], cyc[k])]
                    e_next = _EDGE_OF[(cyc[k], cyc[(k + 1) % 4])]
                    pairs.append((e_prev, e_next))
        for a, b in pairs:
            links.setdefault(a, []).append(b)
            links.setdefault(b, []).append(a)
    polys: list[list[int]] = []
    seen: set[int] = set()
    for start in sorted(links):
        if start in seen:
            continue
        poly = [start]
        seen.add(start)
        prev, cur = None, start
        while True:
            nxt = [n for n in links[cur] if n != prev]
            n = nxt[0] if nxt else links[cur][0]
            if n == start:
                break
            poly.append(n)
            seen.add(n)
            prev, cur = cur, n
        polys.append(_orient(poly, inside))
    return polys


def _orient(poly: list[int], inside: list[bool]) -> list[int]:
    mid = np.array([(CORNERS[EDGES[e, 0]] + CORNERS[EDGES[e, 1]]) / 2.0 for e in poly])
    normal = np.zeros(3)
    for i in range(len(mid)):  # Newell's method
        a, b = mid[i], mid[(i + 1) % len(mid)]
        normal += np.cross(a, b)
    ins = np.array([CORNERS[EDGES[e, 0]] if inside[EDGES[e, 0]] else CORNERS[EDGES[e, 1]]
                    for e in poly], dtype=float)
    outward = mid.mean(0) - ins.mean(0)
    return poly if normal @ outward > 0 else poly[::-1]


def _edge_faces() -> dict[int, set[int]]:
    faces: dict[int, set[int]] = {}
    for fi, cyc in enumerate(_FACES):
        for k in range(4):
            faces.setdefault(_EDGE_OF[(cyc[k], cyc[(k + 1) % 4])], set()).add(fi)
    return faces


_FACES_OF_EDGE = _edge_faces()


def _fan_apex(poly: list[int]) -> int:
    """A fan apex whose diagonals never join two edges of one cube face.

    Such a diagonal could also be drawn by the neighbouring cube across that face (an
    ambiguous face), leaving a mesh edge shared by four triangles. Every polygon of the
    table has such an apex.
    """
    n = len(poly)
    for a in range(n):
        if all(not (_FACES_OF_EDGE[poly[a]] & _FACES_OF_EDGE[poly[j]])
               for j in range(n) if j not in (a, (a - 1) % n, (a + 1) % n)):
            return a
    raise AssertionError(f"no fan apex for polygon {poly}")  # pragma: no cover


def _build_tables():
    tri_lists = []
    comp_lists = []
    for case in range(256):
        inside = [bool(case >> i & 1) for i in range(8)]
        polys = cube_components(inside)
        tris = []
        for p in polys:
            a = _fan_apex(p)
            q = p[a:] + p[:a]
            for k in range(1, len(q) - 1):
                tris.append((q[0], q[k], q[k + 1]))
        tri_lists.append(tris)
        comp = [-1] * 12
        for ci, p in enumerate(polys):
            for e in p:
                comp[e] = ci
        comp_lists.append(comp)
    max_tris = max(len(t) for t in tri_lists)
    tri = np.full((256, max_tris, 3), -1, dtype=np.int8)
    for c, tris in enumerate(tri_lists):
        if tris:
            tri[c, : len(tris)] = tris
    comp = np.array(comp_lists, dtype=np.int8)
    return tri, comp, max_tris, int(comp.max()) + 1


TRI_TABLE, COMPONENT_TABLE, MAX_TRIS, MAX_COMPONENTS = _build_tables()
"""``TRI_TABLE[case]``: ``(MAX_TRIS, 3)`` edge triples (-1 padded);
``COMPONENT_TABLE[case]``: ``(12,)`` polygon index of each crossed edge, -1 elsewhere."""
