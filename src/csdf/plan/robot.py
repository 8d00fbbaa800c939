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
refused); ``<mimic>`` joints follow their leader (they are not degrees of freedom), and
``lock=`` turns chosen joints into fixed ones (a gripper held open). Collision geometry:
box, cylinder, sphere and capsule (the ``<capsule radius length>`` tag of the URDFs made
for MoveIt and Drake, which yourdfpy does not read itself: csdf reads it), and meshes
as sets of spheres that hold their surface (:mod:`csdf.plan.meshcover`; a bound: the
spheres reach up to ``mesh_spacing`` beyond it). An SRDF's
``<disable_collisions>`` give the link pairs that self-collision checks leave out.
"""

from __future__ import annotations

import io
import math
import os
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import CsdfError
from ..expr import param
from ..shapes import box, capsule, cylinder, sphere, union

__all__ = ["Robot", "Joint", "Primitive", "sphere_jacobian", "sphere_jacobian_many",
           "pair_gaps", "read_srdf"]

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
        mimic: the movable joint whose position drives this one (``None`` for an
            independent joint); its position is ``multiplier * q[mimic] + offset``.
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
    mimic: str | None = None
    multiplier: float = 1.0
    offset: float = 0.0


@dataclass(frozen=True)
class Primitive:
    """A collision primitive of a link, in the link's frame.

    Attributes:
        link: the link's name; kind: ``'box' | 'cylinder' | 'sphere' | 'capsule'``;
            size: its dimensions (box: full sizes (3,); cylinder and capsule: radius,
            length of the axis along z (a capsule's caps add ``radius`` at each end);
            sphere: radius); origin: ``(4, 4)`` its pose in the link frame.
    """

    link: str
    kind: str
    size: tuple
    origin: np.ndarray


def _xml_root(text: str, what: str) -> ET.Element:
    try:
        return ET.fromstring(text)
    except ET.ParseError as exc:
        raise CsdfError(f"{what}: not valid XML: {exc}") from None


def _take_capsules(root: ET.Element) -> dict[tuple[str, int], tuple[float, float]]:
    """Capsules of the URDF tree ``root``: ``{(link, collision index): (radius,
    length)}``; each ``<capsule>`` tag is turned into a ``<cylinder>`` in place, so that
    yourdfpy reads the tree, and :meth:`Robot.from_urdf` makes it a capsule again."""
    out = {}
    for link in root.iter("link"):
        for k, col in enumerate(link.findall("collision")):
            geom = col.find("geometry")
            cap = None if geom is None else geom.find("capsule")
            if cap is not None:
                try:
                    out[(link.get("name"), k)] = (float(cap.get("radius")),
                                                  float(cap.get("length")))
                except (TypeError, ValueError):
                    raise CsdfError(f"link {link.get('name')!r}: a <capsule> needs numeric "
                                    "radius and length") from None
                cap.tag = "cylinder"
    return out


def _read_urdf(source: str | os.PathLike):
    """``(yourdfpy robot, capsules as in _take_capsules, what, directory)`` of a URDF
    file or text (the directory that relative mesh paths start from: the file's, or the
    working directory for text)."""
    try:
        import yourdfpy
    except ImportError:  # pragma: no cover - the plan extra
        raise CsdfError("reading URDF files needs yourdfpy: pip install 'csdf[plan]'") \
            from None
    opts = dict(build_scene_graph=False, build_collision_scene_graph=False,
                load_meshes=False, load_collision_meshes=False)
    text = str(source)
    where = Path.cwd()
    if "<robot" in text:
        what = "the URDF text"
    else:
        what = str(source)
        path = Path(source)
        if not path.is_file():
            raise CsdfError(f"cannot read {path}: no such file")
        text = path.read_text(encoding="utf-8", errors="replace")
        where = path.resolve().parent
    root = _xml_root(text, what)
    try:
        capsules = _take_capsules(root)
    except CsdfError as exc:
        raise CsdfError(f"{what}: {exc}") from None
    try:
        xml = ET.tostring(root, encoding="unicode")
        return yourdfpy.URDF.load(io.StringIO(xml), **opts).robot, capsules, what, where
    except Exception as exc:  # the parser's own errors (XML, missing attributes)
        raise CsdfError(f"{what}: not a URDF csdf can read: {exc}") from None


def _mesh_spheres(mesh: Any, where: Path, spacing: float | None, what: str
                  ) -> tuple[np.ndarray, np.ndarray]:
    """The spheres standing for a URDF ``<mesh>`` (its file found as yourdfpy finds it:
    relative to the URDF, or through a ``package://`` path), scaled as the URDF says."""
    import trimesh
    import yourdfpy

    from .meshcover import sphere_set

    name = str(mesh.filename)
    path = Path(yourdfpy.filename_handler_magic(name, dir=str(where)))
    if not path.is_file():
        raise CsdfError(f"{what}: cannot find its collision mesh {name!r}")
    try:
        m = trimesh.load(str(path), force="mesh")
    except Exception as exc:  # trimesh's own errors for unreadable files
        raise CsdfError(f"{what}: cannot read its collision mesh {name!r}: {exc}") from None
    if not isinstance(m, trimesh.Trimesh) or not len(m.faces):
        raise CsdfError(f"{what}: its collision mesh {name!r} has no triangles")
    scale = np.ones(3) if mesh.scale is None else \
        np.broadcast_to(np.asarray(mesh.scale, dtype=np.float64), (3,))
    try:
        return sphere_set(np.asarray(m.vertices) * scale, np.asarray(m.faces), spacing)
    except CsdfError as exc:
        raise CsdfError(f"{what}: collision mesh {name!r}: {exc}") from None


def read_srdf(source: str | os.PathLike) -> list[tuple[str, str]]:
    """The ``<disable_collisions link1=... link2=...>`` pairs of an SRDF file (or SRDF
    text): the link pairs a self-collision check leaves out."""
    text = str(source)
    what = "the SRDF text"
    if "<robot" not in text:
        what = text
        path = Path(source)
        if not path.is_file():
            raise CsdfError(f"cannot read {path}: no such file")
        text = path.read_text(encoding="utf-8", errors="replace")
    pairs = []
    for el in _xml_root(text, what).iter("disable_collisions"):
        a, b = el.get("link1"), el.get("link2")
        if not a or not b:
            raise CsdfError(f"{what}: <disable_collisions> needs link1 and link2")
        pairs.append((a, b))
    return pairs


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
            them; mimic joints are not among them); primitives: every
            :class:`Primitive`; ignore: link pairs that self-collision checks leave out
            (from an SRDF), besides adjacent links.
    """

    def __init__(self, name: str, root: str, links: list[str], joints: list[Joint],
                 primitives: list[Primitive], ignore: Any = ()):
        self.name = name
        self.root = root
        self.links = links
        self.joints = joints
        self.movable = [j for j in joints if j.type != "fixed" and j.mimic is None]
        self.primitives = primitives
        for a, b in ignore:
            for end in (a, b):
                if end not in links:
                    raise CsdfError(f"ignore: unknown link {end!r}")
        self.ignore = tuple((str(a), str(b)) for a, b in ignore)
        self._shape = None
        self._covers: dict = {}  # sphere covers by spacing

    @property
    def dof(self) -> int:
        """The number of joint positions in ``q``: the movable joints (not fixed, not
        mimicking another)."""
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
    def from_urdf(cls, source: str | os.PathLike, srdf: str | os.PathLike | None = None,
                  lock: dict[str, float] | None = None,
                  mesh_spacing: float | None = None) -> Robot:
        """Read a URDF file (or URDF text).

        Args:
            source: the URDF's path, or its text.
            srdf: an SRDF's path or text whose ``<disable_collisions>`` pairs
                self-collision checks leave out (:attr:`ignore`).
            lock: ``{joint name: position}`` of joints held still (fixed at that
                position, within their limits); mimic joints of a locked joint follow.
            mesh_spacing: for mesh collision geometry, about how far the spheres that
                stand for a mesh may reach beyond its surface (m; default a tenth of
                each mesh's largest extent; :func:`csdf.plan.meshcover.sphere_set`).

        Raises:
            CsdfError: an unreadable file, a malformed URDF, a joint type or geometry
                csdf cannot model (naming the joint or link), or not one tree.
        """
        robot, capsules, what, where = _read_urdf(source)
        lock = dict(lock or {})
        links = {link.name: link for link in robot.links}
        children: dict[str, list] = {}
        has_parent: set[str] = set()
        by_name = {j.name: j for j in robot.joints}
        for name in lock:
            if name not in by_name:
                raise CsdfError(f"lock: {what} has no joint {name!r}")
            if by_name[name].type == "fixed":
                raise CsdfError(f"lock: joint {name!r} is fixed already")
            if by_name[name].mimic is not None:
                raise CsdfError(f"lock: joint {name!r} mimics "
                                f"{by_name[name].mimic.joint!r}; lock that one")
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

        def leader(j) -> tuple[str, float, float]:
            """The independent joint driving ``j``: (name, multiplier, offset)."""
            mult, off, seen = 1.0, 0.0, {j.name}
            while j.mimic is not None:
                m = j.mimic
                if m.joint not in by_name:
                    raise CsdfError(f"{what}: joint {j.name!r} mimics an unknown joint "
                                    f"{m.joint!r}")
                a = 1.0 if m.multiplier is None else float(m.multiplier)
                b = 0.0 if m.offset is None else float(m.offset)
                mult, off = a * mult, a * off + b
                j = by_name[m.joint]
                if j.name in seen:
                    raise CsdfError(f"{what}: joint {j.name!r} mimics itself")
                seen.add(j.name)
            return j.name, mult, off

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
                mimic, mult, off = None, 1.0, 0.0
                if jtype != "fixed":
                    lead, mult, off = leader(j)
                    if lead in lock:
                        value = float(lock[lead])
                        lj = by_name[lead]
                        llo = -math.inf if lj.limit is None or lj.limit.lower is None \
                            else float(lj.limit.lower)
                        lhi = math.inf if lj.limit is None or lj.limit.upper is None \
                            else float(lj.limit.upper)
                        if lj.type in ("revolute", "prismatic") and not llo <= value <= lhi:
                            raise CsdfError(f"lock: joint {lead!r} at {value} is outside "
                                            f"its limits [{llo}, {lhi}]")
                        origin = origin @ _motion(jtype, axis, mult * value + off)
                        jtype, mult, off = "fixed", 1.0, 0.0
                    elif lead != j.name:
                        mimic = lead
                param = None if jtype == "fixed" or mimic else _param_name(j.name, taken)
                joints.append(Joint(j.name, param, jtype, j.parent, j.child, origin, axis,
                                    lo, hi, mimic, mult, off))
                order.append(j.child)
                stack.append(j.child)
        names = {j.name for j in joints if j.type != "fixed" and j.mimic is None}
        for j in joints:
            if j.mimic is not None and j.mimic not in names:
                raise CsdfError(f"{what}: joint {j.name!r} mimics {j.mimic!r}, which "
                                "does not move")
        prims = []
        for name in order:
            for k, c in enumerate(links[name].collisions):
                g = c.geometry
                origin = np.eye(4) if c.origin is None else np.asarray(c.origin, float)
                if (name, k) in capsules:
                    prims.append(Primitive(name, "capsule", capsules[(name, k)], origin))
                elif g.box is not None:
                    prims.append(Primitive(name, "box", tuple(float(v) for v in g.box.size),
                                           origin))
                elif g.cylinder is not None:
                    prims.append(Primitive(name, "cylinder", (float(g.cylinder.radius),
                                                              float(g.cylinder.length)),
                                           origin))
                elif g.sphere is not None:
                    prims.append(Primitive(name, "sphere", (float(g.sphere.radius),), origin))
                elif g.mesh is not None:
                    c, r = _mesh_spheres(g.mesh, where, mesh_spacing, f"{what}: link {name!r}")
                    for ck, rk in zip(c, r):
                        at = np.eye(4)
                        at[:3, 3] = ck
                        prims.append(Primitive(name, "sphere", (float(rk),), origin @ at))
                else:
                    raise CsdfError(f"{what}: link {name!r} has a collision without "
                                    "geometry csdf reads")
        for p in prims:
            if min(p.size) < 0 or not all(math.isfinite(v) for v in p.size):
                raise CsdfError(f"{what}: link {p.link!r} has a {p.kind} of size {p.size}")
        ignore = read_srdf(srdf) if srdf is not None else ()
        for a, b in ignore:
            for end in (a, b):
                if end not in links:
                    raise CsdfError(f"{srdf}: <disable_collisions> names an unknown link "
                                    f"{end!r}")
        return cls(robot.name, roots[0], order, joints, prims, ignore)

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
        pose = {self.root: np.broadcast_to(np.eye(4), (B, 4, 4))}
        for j in self.joints:
            T = pose[j.parent] @ j.origin
            if j.type != "fixed":
                T = T @ _motion_many(j.type, j.axis, self._position(Q, j))
            pose[j.child] = T
        return pose

    def _position(self, Q: np.ndarray, j: Joint) -> np.ndarray:
        """``(B,)`` the position of movable or mimic joint ``j`` at ``Q`` ``(B, dof)``."""
        col = self._columns()
        if j.mimic is None:
            return Q[:, col[j.name]]
        return j.multiplier * Q[:, col[j.mimic]] + j.offset

    def _columns(self) -> dict[str, int]:
        return {j.name: k for k, j in enumerate(self.movable)}

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
        elif p.kind == "capsule":
            h = 0.5 * p.size[1]
            s = capsule((0.0, 0.0, -h), (0.0, 0.0, h), p.size[0])
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
                if j.type != "fixed":
                    q = params[j.mimic or j.name]
                    if j.mimic is not None:
                        q = q * j.multiplier + j.offset
                    if j.type == "prismatic":
                        s = s.translate(tuple(q * float(a) for a in j.axis))
                    else:
                        s = s.rotate(q, tuple(j.axis))
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
        slices along its axis, each covered by the sphere through its rims; a capsule
        as its cylinder, plus a sphere on each cap."""
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
                if prim.kind == "capsule":  # and the caps
                    c = np.concatenate([c, [[0, 0, -length / 2], [0, 0, length / 2]]])
                    r = np.concatenate([r, [radius, radius]])
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
        when a joint joins them (adjacent), when ``ignore`` or :attr:`ignore` names them
        (pairs of link names, like an SRDF's disabled collisions), and when their
        spheres come within ``touch`` (m) of each other in every one of ``samples``
        seeded random positions within the limits (always touching, as at a wrist: the
        cover is coarser than the links). Cached per
        arguments."""
        ignore = tuple(self.ignore) + tuple(tuple(p) for p in ignore)
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


def _ancestors(robot: Robot) -> dict[str, list]:
    """For each link, the joints that move it (movable and mimic ones)."""
    up = {j.child: j for j in robot.joints}
    out: dict[str, list] = {}
    for link in robot.links:
        moving = []
        cur = link
        while cur in up:
            j = up[cur]
            if j.type != "fixed":
                moving.append(j)
            cur = j.parent
        out[link] = moving
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
    col = robot._columns()
    J = np.zeros(c.shape + (robot.dof,))
    for j in robot.joints:
        if j.type == "fixed":
            continue
        moved = np.array([any(m is j for m in anc[robot.links[i]]) for i in link])
        if not moved.any():
            continue
        T = poses[j.parent] @ j.origin
        a = T[:, :3, :3] @ j.axis  # (B, 3)
        Jk = J[..., col[j.mimic or j.name]]  # (B, S, 3), a view
        if j.type == "prismatic":
            Jk[:, moved] += j.multiplier * a[:, None, :]
        else:
            Jk[:, moved] += j.multiplier * np.cross(a[:, None, :],
                                                    c[:, moved] - T[:, None, :3, 3])
    return c, J


def sphere_jacobian(robot: Robot, q: Any, spacing: float | None = None
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The sphere cover at ``q`` and how its centres move: ``(centers (S, 3), radii
    (S,), J (S, 3, dof))`` with ``J[s, :, j]`` the derivative of centre ``s`` by joint
    ``j`` (``a x (c - o)`` for a revolute joint of world axis ``a`` through ``o``, ``a``
    for a prismatic one, 0 for a joint that does not move the sphere)."""
    c, J = sphere_jacobian_many(robot, robot._q(q)[None], spacing)
    return c[0], robot.sphere_cover(spacing)[1], J[0]


def _motion_many(jtype: str, axis: np.ndarray, q: np.ndarray) -> np.ndarray:
    """``(B, 4, 4)`` a joint's motion at positions ``q`` ``(B,)``: a rotation by ``q``
    (rad) about ``axis`` (Rodrigues), or a translation by ``q`` (m) along it."""
    q = np.asarray(q, dtype=np.float64).reshape(-1)
    M = np.broadcast_to(np.eye(4), (len(q), 4, 4)).copy()
    if jtype == "prismatic":
        M[:, :3, 3] = q[:, None] * axis
    else:
        a = axis
        K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
        M[:, :3, :3] = (np.eye(3) + np.sin(q)[:, None, None] * K
                        + (1 - np.cos(q))[:, None, None] * (K @ K))
    return M


def _motion(jtype: str, axis: np.ndarray, q: float) -> np.ndarray:
    """``(4, 4)`` one joint motion (:func:`_motion_many` at one position)."""
    return _motion_many(jtype, axis, np.array([q]))[0]


def _placed(shape, T: np.ndarray):
    """``shape`` moved by the rigid transform ``T`` ``(4, 4)`` (rotation, then
    translation); identity parts are skipped."""
    R, t = T[:3, :3], T[:3, 3]
    if not np.allclose(R, np.eye(3), atol=1e-15):
        shape = shape.rotate(R)
    if np.any(t != 0):
        shape = shape.translate(tuple(float(v) for v in t))
    return shape
