"""coal and python-fcl counterparts of a ``csdf.Scene``, for ``bench_scene.py``.

A scene's instances are taken apart into the collision primitives both libraries have
(:func:`scene_parts`): each model's shape tree is walked at the instance's parameter
values; unions, translations, mirrors (of a part lying in the mirrored half), finite
repeats and polar repeats become several placed copies; boxes, spheres, cylinders and
capsules become the library's own shapes, exactly. Rounded boxes and rounded cylinders
are a box or cylinder swept by a sphere: coal has that (``setSweptSphereRadius``, still
exact); python-fcl does not, and gets the part's mesh (:func:`rounded_mesh`). Any other
node (a torus, a shell, an intersection...) is meshed whole with ``csdf.mesh`` and
becomes a BVH of triangles (a surface: a sphere inside a closed mesh but touching none
of its triangles is not a collision there, and its distance is unsigned). A part with a
side of zero (a flat box, such as the arms of a chair at ``arm_height`` 0, which lie on
its seat) is left out: it has no inside.

:class:`CoalScene` and :class:`FclScene` hold one collision object per part in a
``DynamicAABBTreeCollisionManager`` and answer one sphere at a time from Python, as a
user of these libraries would: a distance call against one object
(:meth:`pair_distance`), and a collide or distance query against the whole scene
through the broad phase with the library's default callbacks.

API differences met (coal 3.0, python-fcl 0.7):

* coal's ``CollisionObject.setTranslation`` does not update the object's box; the broad
  phase then tests the old one unless ``computeAABB()`` is called. python-fcl's does.
* coal's managers take objects one by one (``registerObject``; ``registerObjects``
  wants a C++ vector that Python lists do not convert to) and keep raw pointers: the
  Python objects must stay alive. python-fcl keeps them itself.
* coal's callbacks (``CollisionCallBackDefault``, ``DistanceCallBackDefault``) run in
  C++ and are reset with ``init()``; python-fcl calls a Python function
  (``defaultCollisionCallback``...) for every pair the broad phase proposes, with fresh
  ``CollisionData`` / ``DistanceData`` per query.
* coal's distances are signed by default (penetration from EPA); python-fcl returns -1
  for any overlapping pair unless ``DistanceRequest(enable_signed_distance=True)``, and
  that request also moves sphere-box pairs from the closed form (exact to 1e-16) to GJK
  (errors up to 0.09 mm seen): this module keeps python-fcl's default (-1 in contact).
* coal's ``distance`` overwrites the result it is given (python-fcl's keeps the smaller
  distance), and ``DistanceCallBackDefault`` passes one result to every pair the broad
  phase proposes: the manager's distance is that of the last pair evaluated, not the
  least (often centimetres off in bench_scene's rooms, where the least of the
  one-object calls agrees with csdf to 1e-12). Its Python bindings cannot subclass the
  callback (``DistanceCallBackBase`` cannot be instantiated from Python), so the
  figures show coal's broad-phase distance as it comes.
"""

from __future__ import annotations

import importlib
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

#: the libraries compared, by module name
LIBRARIES = ("coal", "fcl")
#: part kinds that both libraries have as shapes (the rest: coal's swept shapes, meshes)
EXACT_KINDS = ("box", "sphere", "cylinder", "capsule")


def load_library(name: str) -> tuple[Any, str]:
    """``(module, version)`` of ``coal`` or ``fcl``, or ``(None, why not)``."""
    try:
        mod = importlib.import_module(name)
    except ImportError as e:  # (also a broken binary: ImportError with its reason)
        return None, f"not importable ({e})"
    version = getattr(mod, "__version__", None)
    if version is None:
        try:
            from importlib.metadata import version as dist_version

            version = dist_version({"fcl": "python-fcl"}.get(name, name))
        except Exception:  # noqa: BLE001 - only a label
            version = "unknown version"
    return mod, str(version)


@dataclass(frozen=True)
class Part:
    """One collision primitive placed in a frame: ``p = rotation q + translation``.

    Attributes:
        kind: ``'box'`` (dims: full sides), ``'sphere'`` (radius), ``'cylinder'`` and
            ``'capsule'`` (radius, length of the axis, along local z, centred),
            ``'rounded_box'`` (outer full sides, rounding), ``'rounded_cylinder'``
            (radius, height, rounding) or ``'mesh'`` (``vertices``, ``faces``).
        rotation: ``(3, 3)`` orthogonal (a mirror may leave it improper; every kind but
            ``'mesh'`` is symmetric, see :meth:`proper`).
        label: for a mesh, the csdf node it replaces (``'torus'``...).
    """

    kind: str
    dims: tuple[float, ...]
    rotation: np.ndarray
    translation: np.ndarray
    vertices: np.ndarray | None = None
    faces: np.ndarray | None = None
    label: str = ""

    def moved(self, R: np.ndarray, t: np.ndarray, s: float = 1.0) -> Part:
        """The part placed by ``p -> s R p + t``."""
        verts = None if self.vertices is None else self.vertices * s
        return Part(self.kind, tuple(d * s for d in self.dims), R @ self.rotation,
                    s * (R @ self.translation) + t, verts, self.faces, self.label)

    def proper(self) -> tuple[np.ndarray, np.ndarray]:
        """``(rotation, translation)`` with a proper rotation: an improper one is
        composed with the flip of local z, which maps every kind but a mesh onto
        itself (a mesh's vertices are placed instead, see :meth:`world_vertices`)."""
        R = self.rotation
        if self.kind != "mesh" and np.linalg.det(R) < 0:
            R = R @ np.diag([1.0, 1.0, -1.0])
        return R, self.translation

    def world_vertices(self) -> np.ndarray:
        """A mesh's vertices in the frame the part is placed in."""
        return self.vertices @ self.rotation.T + self.translation

    def box(self) -> np.ndarray:
        """``(2, 3)`` an axis-aligned box around the part (in its placing frame)."""
        if self.kind == "mesh":
            v = self.world_vertices()
            return np.array([v.min(0), v.max(0)])
        A = np.abs(self.rotation)
        d = self.dims
        if self.kind in ("box", "rounded_box"):
            half = A @ (np.array(d[:3]) / 2)
        elif self.kind == "sphere":
            half = np.full(3, d[0])
        else:  # cylinders and capsules: axis along local z
            axis = A[:, 2]
            r, h = d[0], d[1] / 2
            side = r * np.sqrt(np.clip(1 - axis**2, 0, 1))
            half = axis * h + (r if self.kind == "capsule" else side)
        return np.array([self.translation - half, self.translation + half])


# --------------------------------------------------------------------- shape trees
def _value(v: Any, params: dict[str, float]) -> float:
    """A shape argument (a number or a csdf expression of parameters) as a float."""
    from csdf.expr import Expr, const, const_value, substitute

    if isinstance(v, Expr):
        def leaf(n: Expr) -> Expr | None:
            if n.op != "param":
                return None
            p = n.value
            return const(params.get(p.name, p.default))  # type: ignore[union-attr]

        out = const_value(substitute([v], leaf)[0])
        if out is None:
            raise ValueError(f"not a constant at the parameters' values: {v!r}")
        return float(out)
    return float(v)


def _vector(v: Any, params: dict[str, float]) -> np.ndarray:
    """A 3-vector argument (or a scalar, broadcast) as floats."""
    if isinstance(v, (tuple, list)):
        return np.array([_value(c, params) for c in v])
    return np.full(3, _value(v, params))


def _frame_z(d: np.ndarray) -> np.ndarray:
    """A rotation whose third column is the unit vector ``d``."""
    z = d / np.linalg.norm(d)
    helper = np.array([1.0, 0, 0]) if abs(z[0]) < 0.9 else np.array([0, 1.0, 0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z], axis=1)


def _leaf(shape: Any, params: dict[str, float]) -> list[Part] | None:
    """The part of a primitive both libraries know (or a rounded one), None for any
    other node; ``[]`` for a flat (zero-volume) one."""
    a, name, eye, zero = shape.args, shape.name, np.eye(3), np.zeros(3)
    if name in ("box", "rounded_box"):
        size = _vector(a[0] if a else 1.0, params)
        if not size.min() > 0:
            return []
        if name == "box":
            return [Part("box", tuple(size), eye, zero)]
        return [Part("rounded_box", (*size, _value(a[1], params)), eye, zero)]
    if name == "sphere":
        return [Part("sphere", (_value(a[0] if a else 1.0, params),), eye, zero)]
    if name in ("cylinder", "rounded_cylinder"):
        r, h = _value(a[0], params), _value(a[1], params)
        if not (r > 0 and h > 0):
            return []
        if name == "cylinder":
            return [Part("cylinder", (r, h), eye, zero)]
        return [Part("rounded_cylinder", (r, h, _value(a[2], params)), eye, zero)]
    if name == "capsule":
        p, q, r = _vector(a[0], params), _vector(a[1], params), _value(a[2], params)
        if np.linalg.norm(q - p) == 0:
            return [Part("sphere", (r,), eye, p)]
        return [Part("capsule", (r, float(np.linalg.norm(q - p))), _frame_z(q - p),
                     (p + q) / 2)]
    return None


def _mesh_part(shape: Any, params: dict[str, float], label: str) -> Part:
    """A csdf node meshed whole (default resolution, thin parts checked)."""
    import csdf

    own = {p.name for p in shape.params}
    m = csdf.mesh(shape, params={k: v for k, v in params.items() if k in own},
                  progress=False)
    return Part("mesh", (), np.eye(3), np.zeros(3), np.asarray(m.vertices, np.float64),
                np.asarray(m.faces, np.int64), label)


def _rotation_about(axis: str, angle: float) -> np.ndarray:
    i, j = {"z": (0, 1), "x": (1, 2), "y": (2, 0)}[axis]
    R = np.eye(3)
    c, s = np.cos(angle), np.sin(angle)
    R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
    return R


def shape_parts(shape: Any, params: dict[str, float] | None = None) -> list[Part]:
    """Parts of a csdf shape (its own frame) at ``params`` (others at defaults)."""
    params = dict(params or {})
    name, a = shape.name, shape.args
    eye = np.eye(3)
    leaf = _leaf(shape, params)
    if leaf is not None:
        return leaf
    if name == "union":
        return [p for c in shape.children for p in shape_parts(c, params)]
    if name == "translate":
        return [p.moved(eye, _vector(a[0], params)) for p in shape_parts(shape.children[0],
                                                                          params)]
    if name == "mirror":  # a union of reflections only where the child is in the half
        child = shape_parts(shape.children[0], params)
        axes = sorted({"xyz".index(ch) for ch in str(a[0]).lower()})
        if not child:
            return []
        if all(p.box()[0, i] >= -1e-12 for p in child for i in axes):
            out = []
            for signs in np.ndindex(*(2,) * len(axes)):
                F = np.ones(3)
                for i, sgn in zip(axes, signs):
                    F[i] = -1.0 if sgn else 1.0
                out += [p.moved(np.diag(F), np.zeros(3)) for p in child]
            return out
    if name == "repeat" and shape.kwargs.get("count") is not None:
        count = shape.kwargs["count"]
        counts = list(count) if isinstance(count, (tuple, list)) else [count] * 3
        sp = _vector(a[0], params)
        child = shape_parts(shape.children[0], params)
        out = []
        for idx in np.ndindex(*[int(n) if sp[i] != 0 else 1 for i, n in enumerate(counts)]):
            off = np.array([(j - (int(counts[i]) - 1) / 2) * sp[i] if sp[i] != 0 else 0.0
                            for i, j in enumerate(idx)])
            out += [p.moved(eye, off) for p in child]
        return out
    if name == "repeat_polar":
        n = int(_value(a[0], params))
        axis = shape.kwargs.get("axis", "z")
        child = shape_parts(shape.children[0], params)
        return [p.moved(_rotation_about(axis, 2 * np.pi * k / n), np.zeros(3))
                for k in range(n) for p in child]
    return [_mesh_part(shape, params, name)]


def scene_parts(scene: Any) -> list[tuple[int, Part]]:
    """``(instance id, part in the world)`` of every part of every instance of a
    ``csdf.Scene`` (each model taken apart once per parameter values)."""
    from csdf.shapes.base import Shape

    cache: dict[tuple, list[Part]] = {}
    out = []
    for inst in scene:
        if not isinstance(inst.model, Shape):
            raise TypeError(f"instance {inst.name!r}: only shapes are taken apart, "
                            f"not {type(inst.model).__name__}")
        key = (id(inst.model), tuple(sorted(inst.params.items())))
        if key not in cache:
            cache[key] = shape_parts(inst.model, inst.params)
        P = inst.pose
        out += [(inst.id, p.moved(P.rotation, P.translation, P.scale)) for p in cache[key]]
    return out


_MESHES: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}


def rounded_mesh(part: Part) -> tuple[np.ndarray, np.ndarray]:
    """``(vertices, faces)`` of a rounded box or cylinder in its own frame: csdf's mesh
    at the default resolution by dual contouring (whose vertices follow the rounded
    edges: 1.7 mm off at most on the table's top, where marching cubes' chords cut
    them by 4.8 mm); cached by kind and dimensions."""
    import csdf

    key = (part.kind, part.dims)
    if key not in _MESHES:
        d = part.dims
        shape = (csdf.rounded_box(tuple(d[:3]), d[3]) if part.kind == "rounded_box"
                 else csdf.rounded_cylinder(*d))
        m = csdf.mesh(shape, method="dc", progress=False)
        _MESHES[key] = (np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64))
    return _MESHES[key]


def describe(parts: list[Part], library: str) -> str:
    """What a library gets for these parts, e.g. ``'8 Box, 1 BVH (27,512 triangles)'``."""
    counts: dict[str, int] = {}
    tris = 0
    for p in parts:
        if p.kind in EXACT_KINDS:
            what = p.kind.capitalize()
        elif p.kind != "mesh" and library == "coal":
            what = {"rounded_box": "Box", "rounded_cylinder": "Cylinder"}[p.kind] + \
                " swept by a sphere"
        else:
            what = f"BVH mesh of {p.label or p.kind}"
            tris += len(p.faces) if p.kind == "mesh" else len(rounded_mesh(p)[1])
        counts[what] = counts.get(what, 0) + 1
    text = ", ".join(f"{n} {w}" for w, n in counts.items())
    return text + (f" ({tris:,} triangles)" if tris else "")


def is_exact(part: Part, library: str) -> bool:
    """The library's object has exactly the csdf part's surface (not a mesh)."""
    return part.kind in EXACT_KINDS or (library == "coal" and part.kind != "mesh")


# --------------------------------------------------------------------- libraries
class _Baseline:
    """One library's objects for a scene's parts, and a sphere of one radius to query
    them with. Subclasses fill ``objects`` and the query methods."""

    name = ""

    def __init__(self, parts: list[Part], radius: float):
        self.parts = parts
        self.radius = float(radius)
        self.objects: list[Any] = []

    def pair_distance(self, center: np.ndarray, k: int) -> tuple[float, float]:
        """``(seconds of one distance call, its distance)``: the sphere at ``center``
        against object ``k`` (the sphere is moved and the result made before timing)."""
        raise NotImplementedError

    def collide(self, centers: np.ndarray) -> np.ndarray:
        """``(N,)`` bool: each sphere touches the scene (broad phase)."""
        raise NotImplementedError

    def distance(self, centers: np.ndarray) -> np.ndarray:
        """``(N,)`` each sphere's distance to the scene (broad phase; a sphere in
        contact stops the search at the first overlapping object: a negative value)."""
        raise NotImplementedError


def _primitive(lib: Any, p: Part) -> Any:
    """``p`` as a shape of ``lib`` (coal or fcl: the same class names) when it is a
    plain box, sphere, cylinder or capsule; None otherwise."""
    d = p.dims
    if p.kind == "box":
        return lib.Box(*d)
    if p.kind == "sphere":
        return lib.Sphere(d[0])
    if p.kind == "cylinder":
        return lib.Cylinder(d[0], d[1])
    if p.kind == "capsule":
        return lib.Capsule(d[0], d[1])
    return None


class CoalScene(_Baseline):
    """coal objects: shapes, swept shapes for rounded parts, ``BVHModelOBBRSS``."""

    name = "coal"

    def __init__(self, parts: list[Part], radius: float):
        import coal

        super().__init__(parts, radius)
        self.coal = coal
        self.geometries = [self._geometry(p) for p in parts]
        self.objects = []
        for p, g in zip(parts, self.geometries):
            R, t = p.proper()
            self.objects.append(coal.CollisionObject(g, R, t) if p.kind != "mesh"
                                else coal.CollisionObject(g, np.eye(3), np.zeros(3)))
        self.manager = coal.DynamicAABBTreeCollisionManager()
        for o in self.objects:  # (coal keeps pointers: self.objects keeps them alive)
            self.manager.registerObject(o)
        self.manager.setup()
        self.sphere = coal.CollisionObject(coal.Sphere(self.radius), np.eye(3), np.zeros(3))
        self.request = coal.DistanceRequest()
        self._collide_cb = coal.CollisionCallBackDefault()
        self._distance_cb = coal.DistanceCallBackDefault()

    def _geometry(self, p: Part) -> Any:
        coal, d = self.coal, p.dims
        g = _primitive(coal, p)
        if g is not None:
            return g
        if p.kind == "rounded_box":
            g = coal.Box(*(max(s - 2 * d[3], 0.0) for s in d[:3]))
            g.setSweptSphereRadius(d[3])
            return g
        if p.kind == "rounded_cylinder":
            g = coal.Cylinder(max(d[0] - d[2], 0.0), max(d[1] - 2 * d[2], 0.0))
            g.setSweptSphereRadius(d[2])
            return g
        v, f = p.world_vertices(), p.faces
        g = coal.BVHModelOBBRSS()
        g.beginModel(len(f), len(v))
        g.addVertices(np.ascontiguousarray(v))
        g.addTriangles(np.ascontiguousarray(f, dtype=np.int64))
        g.endModel()
        return g

    def _move(self, c: np.ndarray) -> None:
        self.sphere.setTranslation(c)
        self.sphere.computeAABB()  # coal does not (the broad phase reads the box)

    def pair_distance(self, center: np.ndarray, k: int) -> tuple[float, float]:
        coal, obj, req = self.coal, self.objects[k], self.request
        self._move(center)
        res = coal.DistanceResult()
        t0 = time.perf_counter()
        d = coal.distance(self.sphere, obj, req, res)
        return time.perf_counter() - t0, d

    def collide(self, centers: np.ndarray) -> np.ndarray:
        out = np.empty(len(centers), bool)
        sphere, cb, mgr = self.sphere, self._collide_cb, self.manager
        for i, c in enumerate(centers):
            sphere.setTranslation(c)
            sphere.computeAABB()
            cb.init()
            mgr.collide(sphere, cb)
            out[i] = cb.data.result.isCollision()
        return out

    def distance(self, centers: np.ndarray) -> np.ndarray:
        out = np.empty(len(centers))
        sphere, cb, mgr = self.sphere, self._distance_cb, self.manager
        for i, c in enumerate(centers):
            sphere.setTranslation(c)
            sphere.computeAABB()
            cb.init()
            mgr.distance(sphere, cb)
            out[i] = cb.data.result.min_distance
        return out


class FclScene(_Baseline):
    """python-fcl objects: shapes, and ``BVHModel`` (OBBRSS) for rounded parts and
    meshes; the default distance request (unsigned: -1 for a sphere in contact)."""

    name = "fcl"

    def __init__(self, parts: list[Part], radius: float):
        import fcl

        super().__init__(parts, radius)
        self.fcl = fcl
        self.objects = []
        for p in parts:
            g = self._geometry(p)
            R, t = p.proper()
            tf = fcl.Transform(R, t) if p.kind != "mesh" else fcl.Transform()
            self.objects.append(fcl.CollisionObject(g, tf))
        self.manager = fcl.DynamicAABBTreeCollisionManager()
        self.manager.registerObjects(self.objects)
        self.manager.setup()
        self.sphere = fcl.CollisionObject(fcl.Sphere(self.radius), fcl.Transform())
        self.request = fcl.DistanceRequest()

    def _geometry(self, p: Part) -> Any:
        fcl = self.fcl
        g = _primitive(fcl, p)
        if g is not None:
            return g
        if p.kind == "mesh":
            v, f = p.world_vertices(), p.faces
        else:  # a rounded part: its mesh, in its own frame (the object is placed)
            v, f = rounded_mesh(p)
        g = fcl.BVHModel()
        g.beginModel(len(f), len(v))
        g.addSubModel(v, f)
        g.endModel()
        return g

    def pair_distance(self, center: np.ndarray, k: int) -> tuple[float, float]:
        fcl, obj, req = self.fcl, self.objects[k], self.request
        self.sphere.setTranslation(center)
        res = fcl.DistanceResult()
        t0 = time.perf_counter()
        d = fcl.distance(self.sphere, obj, req, res)
        return time.perf_counter() - t0, d

    def collide(self, centers: np.ndarray) -> np.ndarray:
        fcl = self.fcl
        out = np.empty(len(centers), bool)
        sphere, mgr, callback = self.sphere, self.manager, fcl.defaultCollisionCallback
        for i, c in enumerate(centers):
            sphere.setTranslation(c)  # (python-fcl updates the box)
            data = fcl.CollisionData()
            mgr.collide(sphere, data, callback)
            out[i] = data.result.is_collision
        return out

    def distance(self, centers: np.ndarray) -> np.ndarray:
        fcl = self.fcl
        out = np.empty(len(centers))
        sphere, mgr, callback = self.sphere, self.manager, fcl.defaultDistanceCallback
        for i, c in enumerate(centers):
            sphere.setTranslation(c)
            data = fcl.DistanceData(self.request)
            mgr.distance(sphere, data, callback)
            out[i] = data.result.min_distance
        return out


BASELINES: dict[str, type[_Baseline]] = {"coal": CoalScene, "fcl": FclScene}
