"""Robots: a kinematic tree read from a URDF, with two views of its collision geometry.

* **The robot as one csdf model** (:meth:`Robot.shape`): every link's collision
  primitives (boxes, cylinders, spheres) placed by the chain of joint transforms, with
  the joint positions as parameters (named after the joints, ranges from their limits).
  The distance from any point to the robot and its derivative by every joint then come
  from :meth:`csdf.Program.param_jacobian`: exact, in one forward pass.
* **Spheres on the links** (:meth:`Robot.spheres`): a cover of each primitive by
  spheres, placed by forward kinematics (:meth:`Robot.fk`), for queries against a scene
  (CHOMP's form). The spheres hold the primitive, so their clearance never exceeds the
  true clearance.

The URDF is parsed by ``yourdfpy`` (the ``plan`` extra: ``pip install csdf[plan]``).
Joint types: revolute, continuous, prismatic and fixed (a floating or planar joint is
refused); collision geometry: box, cylinder and sphere (a mesh is refused, naming the
link, until meshes can be read as shapes).
"""

from __future__ import annotations

import io
import math
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import CsdfError
from ..expr import param
from ..shapes import box, cylinder, sphere, union

__all__ = ["Robot", "Joint", "Primitive", "sphere_jacobian", "sphere_jacobian_many",
           "pair_gaps"]

_IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
#: the most spheres one primitive is covered by
MAX_SPHERES_PER_PRIMITIVE = 64


@dataclass(frozen=True)
class Joint:
    """One joint of the tree.

    Attributes:
        name: the URDF name; param: the csdf parameter name of its position (None for a
            fixed joint); type: ``'revolute' | 'continuous' | 'prismatic' | 'fixed'``.
        parent, child: link names; origin: ``(4, 4)`` child frame in the parent's at
            position 0; axis: ``(3,)`` unit axis (child frame).
        lower, upper: position limits (radians or metres; +-inf for continuous).
    """

    name: str
    param: str | None
    type: str
    parent: str
    child: str
    origin: np.ndarray
    axis: np.ndarray
    lower: float
    upper: float


@dataclass(frozen=True)
class Primitive:
    """A collision primitive of a link, in the link's frame.

    Attributes:
        link: the link's name; kind: ``'box' | 'cylinder' | 'sphere'``; size: its
            dimensions (box: full sizes (3,); cylinder: radius, length along z;
            sphere: radius); origin: ``(4, 4)`` its pose in the link frame.
    """

    link: str
    kind: str
    size: tuple
    origin: np.ndarray


def _read_urdf(source: str | os.PathLike):
    try:
        import yourdfpy
    except ImportError:  # pragma: no cover - the plan extra
        raise CsdfError("reading URDF files needs yourdfpy: pip install 'csdf[plan]'") \
            from None
    opts = dict(build_scene_graph=False, build_collision_scene_graph=False,
                load_meshes=False, load_collision_meshes=False)
    text = str(source)
    what = "the URDF text" if "<robot" in text else str(source)
    try:
        if "<robot" in text:
            return yourdfpy.URDF.load(io.StringIO(text), **opts).robot, what
        path = Path(source)
        if not path.is_file():
            raise CsdfError(f"cannot read {path}: no such file")
        return yourdfpy.URDF.load(str(path), **opts).robot, what
    except CsdfError:
        raise
    except Exception as exc:  # the parser's own errors (XML, missing attributes)
        raise CsdfError(f"{what}: not a URDF csdf can read: {exc}") from None


def _param_name(joint: str, taken: set[str]) -> str:
    name = joint if _IDENT.match(joint) else re.sub(r"\W", "_", joint)
    if not _IDENT.match(name):
        name = "q_" + name
    base, k = name, 2
    while name in taken:
        name, k = f"{base}_{k}", k + 1
    taken.add(name)
    return name


class Robot:
    """A robot read from a URDF (see the module docs).

    Attributes:
        name: the URDF's robot name; root: the base link; links: link names (the root
            first, parents before children); joints: every :class:`Joint`, parents
            before children; movable: the joints that move, in that order (``dof`` of
            them); primitives: every :class:`Primitive`.
    """

    def __init__(self, name: str, root: str, links: list[str], joints: list[Joint],
                 primitives: list[Primitive]):
        self.name = name
        self.root = root
        self.links = links
        self.joints = joints
        self.movable = [j for j in joints if j.type != "fixed"]
        self.primitives = primitives
        self._shape = None
        self._covers: dict = {}  # sphere covers by spacing

    @property
    def dof(self) -> int:
        return len(self.movable)

    @property
    def joint_names(self) -> list[str]:
        """The movable joints' URDF names, in the order of ``q``."""
        return [j.name for j in self.movable]

    @property
    def limits(self) -> np.ndarray:
        """``(dof, 2)`` lower and upper limits."""
        return np.array([[j.lower, j.upper] for j in self.movable]).reshape(-1, 2)

    def __repr__(self) -> str:
        return (f"<Robot {self.name!r}: {len(self.links)} links, {self.dof} joints, "
                f"{len(self.primitives)} collision primitives>")

    # ------------------------------------------------------------------ reading
    @classmethod
    def from_urdf(cls, source: str | os.PathLike) -> Robot:
        """Read a URDF file (or URDF text).

        Raises:
            CsdfError: an unreadable file, a malformed URDF, a joint type or geometry
                csdf cannot model (naming the joint or link), or not one tree.
        """
        robot, what = _read_urdf(source)
        links = {link.name: link for link in robot.links}
        children: dict[str, list] = {}
        has_parent: set[str] = set()
        for j in robot.joints:
            for end in (j.parent, j.child):
                if end not in links:
                    raise CsdfError(f"{what}: joint {j.name!r} names an unknown link {end!r}")
            children.setdefault(j.parent, []).append(j)
            if j.child in has_parent:
                raise CsdfError(f"{what}: link {j.child!r} has two parent joints")
            has_parent.add(j.child)
        roots = [n for n in links if n not in has_parent]
        if len(roots) != 1:
            raise CsdfError(f"{what}: the links must form one tree (roots: {roots})")
        order, joints, taken = [roots[0]], [], set()
        stack = [roots[0]]
        while stack:
            parent = stack.pop()
            for j in children.get(parent, []):
                jtype = j.type
                if jtype not in ("revolute", "continuous", "prismatic", "fixed"):
                    raise CsdfError(f"{what}: joint {j.name!r} is {jtype!r}; csdf models "
                                    "revolute, continuous, prismatic and fixed joints")
                origin = np.eye(4) if j.origin is None else np.asarray(j.origin, float)
                axis = np.array([1.0, 0.0, 0.0]) if j.axis is None else \
                    np.asarray(j.axis, float)
                if jtype != "fixed" and not np.linalg.norm(axis) > 0:
                    raise CsdfError(f"{what}: joint {j.name!r} has a zero axis")
                axis = axis / (np.linalg.norm(axis) or 1.0)
                lo, hi = -math.inf, math.inf
                if jtype in ("revolute", "prismatic"):
                    lim = j.limit
                    if lim is None or lim.lower is None or lim.upper is None:
                        raise CsdfError(f"{what}: joint {j.name!r} ({jtype}) needs "
                                        "<limit lower=... upper=...>")
                    lo, hi = float(lim.lower), float(lim.upper)
                    if not lo <= hi:
                        raise CsdfError(f"{what}: joint {j.name!r} has limits {lo} > {hi}")
                param = None if jtype == "fixed" else _param_name(j.name, taken)
                joints.append(Joint(j.name, param, jtype, j.parent, j.child, origin, axis,
                                    lo, hi))
                order.append(j.child)
                stack.append(j.child)
        prims = []
        for name in order:
            for c in links[name].collisions:
                g = c.geometry
                origin = np.eye(4) if c.origin is None else np.asarray(c.origin, float)
                if g.box is not None:
                    prims.append(Primitive(name, "box", tuple(float(v) for v in g.box.size),
                                           origin))
                elif g.cylinder is not None:
                    prims.append(Primitive(name, "cylinder", (float(g.cylinder.radius),
                                                              float(g.cylinder.length)),
                                           origin))
                elif g.sphere is not None:
                    prims.append(Primitive(name, "sphere", (float(g.sphere.radius),), origin))
                else:
                    raise CsdfError(f"{what}: link {name!r} has mesh collision geometry; "
                                    "csdf models boxes, cylinders and spheres")
        return cls(robot.name, roots[0], order, joints, prims)

    # ------------------------------------------------------------------ kinematics
    def _q(self, q: Any) -> np.ndarray:
        arr = np.asarray(q, dtype=np.float64)
        if arr.shape != (self.dof,):
            raise CsdfError(f"q must have shape ({self.dof},) (joints "
                            f"{', '.join(self.joint_names)}), got {arr.shape}")
        if not np.isfinite(arr).all():
            raise CsdfError("q must be finite")
        return arr

    def fk(self, q: Any) -> dict[str, np.ndarray]:
        """Forward kinematics: ``{link: (4, 4) pose in the root's frame}`` at joint
        positions ``q`` ``(dof,)`` (:meth:`fk_many` of one position)."""
        return {k: v[0] for k, v in self.fk_many(self._q(q)[None]).items()}

    def fk_many(self, Q: Any) -> dict[str, np.ndarray]:
        """Forward kinematics of many joint positions at once: ``Q`` ``(B, dof)`` ->
        ``{link: (B, 4, 4)}`` (the same poses as :meth:`fk`, vectorised)."""
        Q = np.asarray(Q, dtype=np.float64)
        if Q.ndim != 2 or Q.shape[1] != self.dof:
            raise CsdfError(f"Q must have shape (B, {self.dof}), got {Q.shape}")
        B = len(Q)
        col = {j.name: k for k, j in enumerate(self.movable)}
        pose = {self.root: np.broadcast_to(np.eye(4), (B, 4, 4))}
        for j in self.joints:
            T = pose[j.parent] @ j.origin
            if j.type in ("revolute", "continuous"):
                th = Q[:, col[j.name]]
                a = j.axis
                K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
                M = np.broadcast_to(np.eye(4), (B, 4, 4)).copy()
                M[:, :3, :3] = (np.eye(3) + np.sin(th)[:, None, None] * K
                                + (1 - np.cos(th))[:, None, None] * (K @ K))
                T = T @ M
            elif j.type == "prismatic":
                M = np.broadcast_to(np.eye(4), (B, 4, 4)).copy()
                M[:, :3, 3] = Q[:, col[j.name], None] * j.axis
                T = T @ M
            pose[j.child] = T
        return pose

    def spheres_many(self, Q: Any, spacing: float | None = None) -> np.ndarray:
        """Sphere centres at many joint positions: ``(B, S, 3)`` (radii and links as in
        :meth:`sphere_cover`)."""
        c, _, link = self.sphere_cover(spacing)
        poses = self.fk_many(Q)
        out = np.empty((len(next(iter(poses.values()))), len(c), 3))
        for k, name in enumerate(self.links):
            sel = link == k
            if sel.any():
                T = poses[name]
                out[:, sel] = np.einsum("bij,sj->bsi", T[:, :3, :3], c[sel]) + T[:, None, :3, 3]
        return out

    def in_limits(self, q: Any) -> bool:
        """Whether ``q`` lies within every joint's limits."""
        q = self._q(q)
        lim = self.limits
        return bool(np.all((q >= lim[:, 0]) & (q <= lim[:, 1])))

    # ------------------------------------------------------------------ views
    def _primitive_shape(self, p: Primitive):
        if p.kind == "box":
            s = box(tuple(0.5 * v for v in p.size))
        elif p.kind == "cylinder":
            s = cylinder(p.size[0], p.size[1])
        else:
            s = sphere(p.size[0])
        return _placed(s, p.origin)

    def shape(self):
        """The robot as one csdf shape whose parameters are the joint positions
        (:attr:`Joint.param`, defaults at the middle of the limits or 0, ranges from
        the limits): ``robot.shape()(points, {'joint1': 0.3, ...})`` is the distance
        from points (root frame) to the robot, and ``param_jacobian`` its derivative by
        every joint. Cached."""
        if self._shape is not None:
            return self._shape
        params = {}
        for j in self.movable:
            lo, hi = j.lower, j.upper
            default = 0.0 if not (math.isfinite(lo) and math.isfinite(hi)) else \
                min(max(0.0, lo), hi)
            params[j.name] = param(j.param, default,
                                        lo if math.isfinite(lo) else None,
                                        hi if math.isfinite(hi) else None)
        chain = {j.child: j for j in self.joints}
        parts = []
        for prim in self.primitives:
            s = self._primitive_shape(prim)
            link = prim.link
            while link in chain:  # up the tree: each joint's motion, then its origin
                j = chain[link]
                if j.type in ("revolute", "continuous"):
                    s = s.rotate(params[j.name], tuple(j.axis))
                elif j.type == "prismatic":
                    s = s.translate(tuple(params[j.name] * float(a) for a in j.axis))
                s = _placed(s, j.origin)
                link = j.parent
            parts.append(s)
        if not parts:
            raise CsdfError(f"robot {self.name!r} has no collision geometry")
        self._shape = union(*parts) if len(parts) > 1 else parts[0]
        return self._shape

    def params(self, q: Any) -> dict[str, float]:
        """The parameter values of :meth:`shape` for joint positions ``q``."""
        q = self._q(q)
        return {j.param: float(v) for j, v in zip(self.movable, q)}

    def sphere_cover(self, spacing: float | None = None) -> tuple[np.ndarray, np.ndarray,
                                                                   np.ndarray]:
        """Spheres covering every primitive, in the primitive's link frame:
        ``(centers (S, 3), radii (S,), link index into links (S,))``. A box is cut into
        near-cubic cells along its longer sides (at most ``spacing`` apart, default its
        shortest side), each covered by its circumscribed sphere; a cylinder into
        slices along its axis, each covered by the sphere through its rims."""
        hit = self._covers.get(spacing)
        if hit is not None:
            return hit
        cs, rs, ls = [], [], []
        for prim in self.primitives:
            k = self.links.index(prim.link)
            if prim.kind == "sphere":
                c, r = np.zeros((1, 3)), np.array([prim.size[0]])
            elif prim.kind == "box":
                size = np.array(prim.size)
                h = spacing or max(float(size.min()), 1e-9)
                n = np.clip(np.ceil(size / h).astype(int), 1, None)
                while np.prod(n) > MAX_SPHERES_PER_PRIMITIVE:
                    n = np.maximum(1, (n + 1) // 2)
                cell = size / n
                grids = [(np.arange(n[a]) + 0.5) * cell[a] - size[a] / 2 for a in range(3)]
                c = np.stack(np.meshgrid(*grids, indexing="ij"), -1).reshape(-1, 3)
                r = np.full(len(c), 0.5 * float(np.linalg.norm(cell)))
            else:
                radius, length = prim.size
                h = spacing or max(radius, 1e-9)
                m = int(min(max(1, math.ceil(length / h)), MAX_SPHERES_PER_PRIMITIVE))
                dz = length / m
                z = (np.arange(m) + 0.5) * dz - length / 2
                c = np.stack([np.zeros(m), np.zeros(m), z], 1)
                r = np.full(m, math.hypot(radius, dz / 2))
            T = prim.origin
            cs.append(c @ T[:3, :3].T + T[:3, 3])
            rs.append(r)
            ls.append(np.full(len(r), k))
        out = (np.concatenate(cs), np.concatenate(rs), np.concatenate(ls))
        for a in out:
            a.setflags(write=False)
        self._covers[spacing] = out
        return out

    def self_pairs(self, spacing: float | None = None, samples: int = 1000, seed: int = 0,
                   ignore: Any = (), touch: float = 0.01) -> np.ndarray:
        """The sphere pairs of the cover that self-collision checks test: ``(P, 2)``
        indices into the cover, one sphere of each of two links. Link pairs are left out
        when a joint joins them (adjacent), when ``ignore`` names them (pairs of link
        names, like an SRDF's disabled collisions), and when their spheres come within
        ``touch`` (m) of each other in every one of ``samples`` seeded random positions
        within the limits (always touching, as at a wrist: the cover is coarser than the
        links). Cached per
        arguments."""
        key = ("pairs", spacing, samples, seed, float(touch),
               tuple(sorted(tuple(sorted(p)) for p in ignore)))
        if key in self._covers:
            return self._covers[key]
        _, r, link = self.sphere_cover(spacing)
        # links joined by fixed joints are one body; bodies joined by a joint are adjacent
        body = {name: name for name in self.links}
        for jt in self.joints:  # parents come before children
            if jt.type == "fixed":
                body[jt.child] = body[jt.parent]
        skip = {tuple(sorted((body[jt.parent], body[jt.child]))) for jt in self.joints}
        for a, b in ignore:
            for name in (a, b):
                if name not in self.links:
                    raise CsdfError(f"ignore: unknown link {name!r}")
            skip.add(tuple(sorted((body[a], body[b]))))
        i, j = np.triu_indices(len(r), 1)
        la, lb = link[i], link[j]
        names = self.links
        keep = np.array([body[names[a]] != body[names[b]]
                         and tuple(sorted((body[names[a]], body[names[b]]))) not in skip
                         for a, b in zip(la, lb)], dtype=bool)
        i, j = i[keep], j[keep]
        if len(i) and samples > 0:
            rng = np.random.default_rng(seed)
            lim = np.clip(self.limits, -np.pi, np.pi)
            Q = rng.uniform(lim[:, 0], lim[:, 1], (int(samples), self.dof))
            always = np.ones(len(i), bool)
            for part in np.array_split(np.arange(len(Q)), max(1, len(Q) // 100)):
                gap = pair_gaps(self.spheres_many(Q[part], spacing), r, i, j)[2]
                always &= (gap < touch).all(axis=0)
            pair_link = la[keep] * len(self.links) + lb[keep]
            bad_links = np.unique(pair_link[always])
            drop = np.isin(pair_link, bad_links)
            i, j = i[~drop], j[~drop]
        out = np.stack([i, j], axis=1).astype(np.int64)
        out.setflags(write=False)
        self._covers[key] = out
        return out

    def self_clearance(self, Q: Any, spacing: float | None = None) -> np.ndarray:
        """The smallest gap between the spheres of :meth:`self_pairs` at joint positions
        ``Q`` ``(B, dof)``: ``(B,)``, negative where the robot may touch itself (inf
        without pairs)."""
        pairs = self.self_pairs(spacing)
        Q = np.asarray(Q, dtype=np.float64)
        if not len(pairs):
            return np.full(len(Q), np.inf)
        _, r, _ = self.sphere_cover(spacing)
        c = self.spheres_many(Q, spacing)
        return pair_gaps(c, r, pairs[:, 0], pairs[:, 1])[2].min(axis=1)

    def spheres(self, q: Any, spacing: float | None = None
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The sphere cover (:meth:`sphere_cover`) placed at joint positions ``q``:
        ``(centers (S, 3) root frame, radii (S,), link index (S,))``."""
        _, r, link = self.sphere_cover(spacing)
        return self.spheres_many(self._q(q)[None], spacing)[0], r, link


def pair_gaps(c: np.ndarray, r: np.ndarray, i: np.ndarray, j: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sphere pairs ``(i, j)`` of centres ``c`` ``(B, S, 3)`` and radii ``r`` ``(S,)``:
    ``(c_i - c_j (B, P, 3), their distance (B, P), the gap between the spheres (B, P))``."""
    d = c[:, i] - c[:, j]
    dist = np.linalg.norm(d, axis=2)
    return d, dist, dist - (r[i] + r[j])


def _ancestors(robot: Robot) -> dict[str, set[int]]:
    """For each link, the indices (into ``movable``) of the joints that move it."""
    index = {j.name: k for k, j in enumerate(robot.movable)}
    up = {j.child: j for j in robot.joints}
    out: dict[str, set[int]] = {}
    for link in robot.links:
        s: set[int] = set()
        cur = link
        while cur in up:
            j = up[cur]
            if j.name in index:
                s.add(index[j.name])
            cur = j.parent
        out[link] = s
    return out


def sphere_jacobian_many(robot: Robot, Q: Any, spacing: float | None = None
                         ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`sphere_jacobian` at many joint positions ``Q`` ``(B, dof)``: ``(centers
    (B, S, 3), J (B, S, 3, dof))``."""
    Q = np.asarray(Q, dtype=np.float64)
    _, _, link = robot.sphere_cover(spacing)
    c = robot.spheres_many(Q, spacing)
    poses = robot.fk_many(Q)
    anc = _ancestors(robot)
    J = np.zeros(c.shape + (robot.dof,))
    for k, j in enumerate(robot.movable):
        moved = np.array([k in anc[robot.links[i]] for i in link])
        if not moved.any():
            continue
        T = poses[j.parent] @ j.origin
        a = T[:, :3, :3] @ j.axis  # (B, 3)
        Jk = J[..., k]  # (B, S, 3), a view
        if j.type == "prismatic":
            Jk[:, moved] = a[:, None, :]
        else:
            Jk[:, moved] = np.cross(a[:, None, :], c[:, moved] - T[:, None, :3, 3])
    return c, J


def sphere_jacobian(robot: Robot, q: Any, spacing: float | None = None
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The sphere cover at ``q`` and how its centres move: ``(centers (S, 3), radii
    (S,), J (S, 3, dof))`` with ``J[s, :, j]`` the derivative of centre ``s`` by joint
    ``j`` (``a x (c - o)`` for a revolute joint of world axis ``a`` through ``o``, ``a``
    for a prismatic one, 0 for a joint that does not move the sphere)."""
    c, J = sphere_jacobian_many(robot, robot._q(q)[None], spacing)
    return c[0], robot.sphere_cover(spacing)[1], J[0]


def _placed(shape, T: np.ndarray):
    """``shape`` moved by the rigid transform ``T`` ``(4, 4)`` (rotation, then
    translation); identity parts are skipped."""
    R, t = T[:3, :3], T[:3, 3]
    if not np.allclose(R, np.eye(3), atol=1e-15):
        shape = shape.rotate(R)
    if np.any(t != 0):
        shape = shape.translate(tuple(float(v) for v in t))
    return shape
