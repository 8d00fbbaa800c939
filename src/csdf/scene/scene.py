"""``csdf.Scene``: many posed instances of models, queried together.

A scene holds instances: a model (a shape, a program, a zoo name or a model file) with
a pose (``csdf.Pose`` or a ``(4, 4)`` similarity matrix), a scale and parameter
values. One model used by many instances is compiled once (programs are kept per
model; a zoo name or file is loaded once per scene). Queries are batched, NumPy in and
out, and run in compiled kernels over a bounding volume hierarchy of the instances'
world boxes (:class:`csdf.fieldset.FieldSet`): the distance to the nearest surface, its
gradient and instance, the signed clearance of spheres and collision tests.

The scene's field is the union (the minimum) of its instances' fields. Where the
winning instance's model is an exact distance and no instance of contract 'neither'
could be nearer, the value is the exact Euclidean distance to the scene's nearest
surface (outside every instance; inside one it is that instance's signed distance);
:attr:`SceneQuery.exact` says so per point.
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import CsdfError
from ..field import Field, as_field
from ..fieldset import FieldSet
from ..pose import Pose, as_pose
from ..seeds import rng_arg
from . import fileformat

__all__ = ["Scene", "Instance", "SceneQuery", "SceneHits", "MAX_INSTANCES",
           "MAX_QUERY_POINTS"]

#: the most instances a scene holds
MAX_INSTANCES = 1_000_000
#: the most points (or spheres, rays) one query takes
MAX_QUERY_POINTS = 50_000_000


@dataclass(frozen=True)
class Instance:
    """One instance of a scene.

    Attributes:
        id: its id in the scene (never reused); name: its name (unique in the scene).
        model: the shape or program it places; source: how the scene file names the
            model (``{'zoo': name}``, ``{'file': path, 'resolved': absolute path}``,
            ``{'csdf': text}`` or ``{'program': text}``; a file's path as it was given,
            written relative to the folder of the scene file it is saved in).
        pose: the :class:`csdf.Pose` (the scale included) from the model's frame to the
            world; params: its parameter values ``{name: value}`` (the others at their
            defaults).
    """

    id: int
    name: str
    model: Any
    source: dict
    pose: Pose
    params: dict = field(default_factory=dict)


@dataclass
class SceneHits:
    """What :meth:`Scene.raycast` finds along each ray.

    Attributes:
        hit: ``(N,)`` bool; distance: ``(N,)`` along the (unit) ray to the first hit,
            inf for a miss; instance: ``(N,)`` int64 the id hit (-1: none); normal:
            ``(N, 3)`` the unit outward normal there (the hit instance's gradient; 0
            for a miss).
    """

    hit: np.ndarray
    distance: np.ndarray
    instance: np.ndarray
    normal: np.ndarray


@dataclass
class SceneQuery:
    """What :meth:`Scene.query` finds at each point.

    Attributes:
        distance: ``(N,)`` the scene's signed distance (inf where the scene is empty,
            NaN for a NaN point).
        gradient: ``(N, 3)`` its gradient (the winning instance's, in the world frame).
        instance: ``(N,)`` int64 the id of the instance nearest the point (-1: none).
        exact: ``(N,)`` bool: ``distance`` is the exact Euclidean distance (the
            instance's model is exact and no model of contract 'neither' could be
            nearer); elsewhere it is a bound (never more than the true distance) for
            models that are bounds, and a plain field value for models that are
            neither.
    """

    distance: np.ndarray
    gradient: np.ndarray
    instance: np.ndarray
    exact: np.ndarray


def _points(points: Any, what: str) -> np.ndarray:
    try:
        p = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError):
        raise CsdfError(f"{what} must be numbers of shape (N, 3)") from None
    if p.ndim == 1 and p.shape == (3,):
        p = p[None]
    if p.ndim != 2 or p.shape[1] != 3:
        raise CsdfError(f"{what} must have shape (N, 3), got {p.shape}")
    if len(p) > MAX_QUERY_POINTS:
        raise CsdfError(f"{what}: at most {MAX_QUERY_POINTS} per call, got {len(p)}")
    return np.ascontiguousarray(p)


def _finite(p: np.ndarray, what: str) -> np.ndarray:
    """``p`` when every coordinate is finite: a sphere query never answers "clear" for a
    sphere it cannot place (a planner would take NaN's "no collision" at its word)."""
    if not np.isfinite(p).all():
        rows = np.flatnonzero(~np.isfinite(p).all(axis=1))
        raise CsdfError(f"{what} must be finite ({len(rows)} row(s) are not, e.g. row "
                        f"{int(rows[0])})")
    return p


def _cap(max_distance: Any, n: int) -> np.ndarray | None:
    """The search's start values for ``max_distance`` (None: no cap)."""
    try:
        m = float(max_distance)
    except (TypeError, ValueError):
        raise CsdfError(f"max_distance must be a number, got {max_distance!r}") from None
    if m != m:
        raise CsdfError("max_distance must not be NaN")
    if m < 0:
        raise CsdfError(f"max_distance must be >= 0, got {m:g}")
    return None if m == np.inf else np.full(n, m)


def _radii(radii: Any, n: int) -> np.ndarray:
    try:
        r = np.asarray(radii, dtype=np.float64)
    except (TypeError, ValueError):
        raise CsdfError("radii must be numbers") from None
    if r.ndim == 0:
        r = np.full(n, float(r))
    if r.shape != (n,):
        raise CsdfError(f"radii must be one number or shape ({n},), got {r.shape}")
    if n and not (r.min() >= 0.0 and r.max() < np.inf):  # (NaN fails both)
        raise CsdfError("radii must be finite and not negative")
    return np.ascontiguousarray(r)


class _TracedScene:
    """What the sphere tracer reads of a field, for a scene's :class:`FieldSet`:
    values, values with gradients, the Lipschitz bound and the box (no cells proved
    empty)."""

    def __init__(self, fs: FieldSet):
        self.fs = fs
        self.lipschitz = fs.lipschitz
        self.bounds = fs.node_f[0].reshape(2, 3).copy()
        self.scale = float(np.linalg.norm(self.bounds[1] - self.bounds[0]))

    def value(self, points: np.ndarray) -> np.ndarray:
        return self.fs.nearest(points)[0]

    def value_and_grad(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        d, g, _, _ = self.fs.nearest(points, grad=True)
        return d, g

    def empty_cells(self) -> None:
        return None


class Scene:
    """Posed instances of models, queried together (see the module docs).

    Instances are added with :meth:`add` (which returns their id), changed with
    :meth:`update` and removed with :meth:`remove`; ``len(scene)`` counts them,
    iterating yields :class:`Instance` records in id order and ``scene[id]`` gives one.
    """

    #: consumers that cannot import this module (it imports them) recognise a scene by it
    __csdf_scene__ = True

    def __init__(self) -> None:
        self._inst: dict[int, Instance] = {}
        self._fields: dict[int, Field] = {}
        self._next = 0
        self._models: dict[tuple, Any] = {}  # zoo names and files, loaded once
        self._set: FieldSet | None = None
        self._ids: np.ndarray = np.zeros(0, np.int64)

    # ------------------------------------------------------------------ instances
    def __len__(self) -> int:
        return len(self._inst)

    def __iter__(self) -> Iterator[Instance]:
        return iter([self._inst[k] for k in sorted(self._inst)])

    def __getitem__(self, id: int) -> Instance:
        try:
            return self._inst[int(id)]
        except (KeyError, TypeError, ValueError):
            raise CsdfError(f"no instance {id!r} in this scene") from None

    def __repr__(self) -> str:
        return f"<Scene of {len(self)} instances>"

    def _model(self, model: Any, base: Path | None = None) -> tuple[Any, dict]:
        """``(shape or program, source)`` of a model given as a shape, a program, a zoo
        name or a model file path (``.csdf``, ``.vm``, ``.csdfb``, ``.csdft``)."""
        from ..compiler.program import Program
        from ..shapes.base import Shape

        if isinstance(model, (Shape, Program)):
            return model, {}
        if isinstance(model, os.PathLike) or (isinstance(model, str) and (
                os.sep in model or "/" in model or Path(model).suffix)):
            path = Path(model)
            if base is not None and not path.is_absolute():
                path = base / path
            key = ("file", str(path.resolve()))
            if key not in self._models:
                from ..io.model import load_model

                self._models[key] = load_model(path)
            # the path as given (the scene's own files write it relative to their
            # folder: :func:`csdf.scene.fileformat.save`) and the file it named
            return self._models[key], {"file": str(model), "resolved": key[1]}
        if isinstance(model, str):
            from .. import zoo

            key = ("zoo", model)
            if key not in self._models:
                self._models[key] = zoo.load(model)
            return self._models[key], {"zoo": model}
        raise CsdfError(f"a scene's model must be a shape, a program, a zoo name or a "
                        f"model file, got {type(model).__name__}")

    def add(self, model: Any, pose: Any = None, scale: float = 1.0,
            params: Mapping[str, float] | None = None, name: str | None = None) -> int:
        """Add an instance; returns its id.

        Args:
            model: a :class:`csdf.Shape`, a :class:`csdf.Program`, a zoo name
                (``'chair'``) or a model file (``'part.csdf'``, ``.vm``, ``.csdfb``).
            pose: a :class:`csdf.Pose` or ``(4, 4)`` similarity matrix (model frame to
                world); default identity.
            scale: multiplies the pose's scale (> 0).
            params: parameter values (checked against the model's ranges).
            name: unique name (default ``'{model}_{id}'``).

        Raises:
            CsdfError: a bad model, pose, scale or name, a 2D or unbounded model;
                ParamError: an unknown parameter or a value outside its range.
        """
        if len(self._inst) >= MAX_INSTANCES:
            raise CsdfError(f"a scene holds at most {MAX_INSTANCES} instances")
        shape, source = self._model(model)
        return self._put(self._next, shape, source, pose, scale, params, name)

    def _put(self, id: int, model: Any, source: dict, pose: Any, scale: float,
             params: Mapping[str, float] | None, name: str | None) -> int:
        p = as_pose(pose, "pose")
        try:
            s = p.scale * float(scale)
        except (TypeError, ValueError):
            raise CsdfError(f"scale must be a positive number, got {scale!r}") from None
        p = Pose(p.rotation, p.translation, s)  # (which checks the scale)
        fld = as_field(model, params, pose=p, what="Scene.add")
        if fld.dim != 3:
            raise CsdfError("a scene holds 3D models; extrude or revolve a 2D shape first")
        fld.bounds  # noqa: B018 - an unbounded model fails here, not in a query
        if not source:
            source = self._embedded(model)
        if name is None:
            if "zoo" in source:
                label = source["zoo"]
            elif "file" in source:
                label = Path(source["file"]).stem or "model"
            else:
                label = getattr(model, "name", None) or "program"
            name = f"{label}_{id}"
        if not isinstance(name, str) or not name:
            raise CsdfError(f"an instance name must be a non-empty string, got {name!r}")
        if any(i.name == name and i.id != id for i in self._inst.values()):
            raise CsdfError(f"the scene already has an instance named {name!r}")
        self._inst[id] = Instance(id, name, model, source, p, dict(params or {}))
        self._fields[id] = fld
        self._next = max(self._next, id + 1)
        self._set = None
        return id

    @staticmethod
    def _embedded(model: Any) -> dict:
        """The scene file's text of an in-memory model: ``.csdf`` text for a shape
        (printed by :func:`csdf.dumps`), the bytecode text for a program."""
        from ..shapes.base import Shape

        if isinstance(model, Shape):
            return {"csdf": None}  # printed when saved (a shape may not print: said then)
        return {"program": None}

    def update(self, id: int, *, pose: Any = None, scale: float | None = None,
               params: Mapping[str, float] | None = None) -> None:
        """Change an instance's pose (and scale), or parameter values (merged with its
        current ones).

        Raises:
            CsdfError: an unknown id or a bad pose or scale; ParamError: as for
                :meth:`add`.
        """
        old = self[id]
        if pose is None:
            new_pose, new_scale = old.pose, 1.0 if scale is None else scale
        else:
            new_pose, new_scale = as_pose(pose, "pose"), 1.0 if scale is None else scale
        merged = dict(old.params)
        merged.update(params or {})
        self._put(old.id, old.model, old.source, new_pose, new_scale, merged, old.name)

    def remove(self, id: int) -> None:
        """Remove an instance (its id is not reused).

        Raises:
            CsdfError: an unknown id.
        """
        inst = self[id]
        del self._inst[inst.id]
        del self._fields[inst.id]
        self._set = None

    @property
    def bounds(self) -> np.ndarray:
        """``(2, 3)`` the world box of all instances.

        Raises:
            CsdfError: an empty scene.
        """
        fs = self._fieldset()
        if fs is None:
            raise CsdfError("an empty scene has no bounds")
        return fs.node_f[0].reshape(2, 3).copy()

    @property
    def lipschitz(self) -> float:
        """The largest Lipschitz bound of the instances' models (inf: one has none)."""
        fs = self._fieldset()
        return 1.0 if fs is None else fs.lipschitz

    def value(self, points: Any) -> np.ndarray:
        """The scene's field at points ``(..., 3)`` (:meth:`distance`, any leading
        shape): what shading and sampling evaluate."""
        p = np.asarray(points, dtype=np.float64)
        return self.distance(p.reshape(-1, 3)).reshape(p.shape[:-1])

    def field(self, id: int) -> Field:
        """The posed :class:`csdf.field.Field` of an instance."""
        return self._fields[self[id].id]

    # ------------------------------------------------------------------ queries
    def _fieldset(self) -> FieldSet | None:
        if self._set is None and self._inst:
            ids = sorted(self._inst)
            self._set = FieldSet([self._fields[k] for k in ids])
            self._ids = np.array(ids, dtype=np.int64)
        return self._set

    def _nearest(self, pts: np.ndarray, grad: bool, below: np.ndarray | None = None,
                 stop: bool = False, ids: bool = True):
        fs = self._fieldset()
        n = len(pts)
        if fs is None:  # an empty scene: nothing anywhere
            d = np.where(np.isnan(pts).any(axis=1), np.nan, np.inf)
            return d, np.zeros((n, 3)) if grad else None, np.full(n, -1), np.zeros(n, bool)
        d, g, k, ex = fs.nearest(pts, grad=grad, below=below, stop=stop)
        if ids:  # the FieldSet's indices as instance ids (-1 stays -1)
            k = np.where(k >= 0, self._ids[k], -1)
        return d, g, k, ex  # nothing below ``below``: d is ``below`` and k is -1

    def distance(self, points: Any, max_distance: float = np.inf) -> np.ndarray:
        """``(N,)`` the scene's signed distance at world points ``(N, 3)`` (inf for an
        empty scene); see :meth:`query` for ``max_distance``."""
        pts = _points(points, "points")
        return self._nearest(pts, False, _cap(max_distance, len(pts)))[0]

    def query(self, points: Any, max_distance: float = np.inf) -> SceneQuery:
        """Distance, gradient, nearest instance and exactness at points ``(N, 3)``.

        Args:
            max_distance: search only for surfaces nearer than this (a planner's
                margin): a point farther from every surface gets exactly this value,
                gradient 0, instance -1 and ``exact`` False, at the cost of the
                hierarchy's boxes alone.
        """
        pts = _points(points, "points")
        d, g, k, ex = self._nearest(pts, True, _cap(max_distance, len(pts)))
        return SceneQuery(distance=d, gradient=g, instance=k, exact=ex)

    def sphere_distance(self, centers: Any, radii: Any, max_distance: float = np.inf
                        ) -> tuple[np.ndarray, np.ndarray]:
        """Signed clearance of spheres: ``(distance(centre) - radius (N,), its gradient by
        the centre (N, 3))``; negative where a sphere penetrates the scene (a bound of
        the penetration where the model is a bound). With ``max_distance``, clearances
        beyond it are reported as ``max_distance`` with gradient 0, and only surfaces
        within it of a sphere are searched."""
        c = _finite(_points(centers, "centers"), "centers")
        r = _radii(radii, len(c))
        below = None if max_distance == np.inf else _cap(max_distance, len(c)) + r
        d, g, _, _ = self._nearest(c, True, below, ids=False)
        return d - r, g

    def collide(self, centers: Any, radii: Any) -> np.ndarray:
        """``(N,)`` bool: the sphere reaches inside the scene (``distance(centre) <
        radius``). Only instances whose boxes come within the radius are evaluated,
        and each search stops at the first hit."""
        c = _finite(_points(centers, "centers"), "centers")
        r = _radii(radii, len(c))
        _, _, k, _ = self._nearest(c, False, below=r, stop=True, ids=False)
        return k >= 0

    def raycast(self, origins: Any, directions: Any, max_distance: float = np.inf
                ) -> SceneHits:
        """First hits of rays with the scene, by csdf's sphere tracer
        (:func:`csdf.render.trace.sphere_trace`, on the scene's values from the
        hierarchy): steps of the value over the largest Lipschitz bound of the models,
        over-relaxed; hits are sign changes refined to 1e-9 of the scene's size (a ray
        that grazes a surface goes on; one that crosses a sliver thinner than 1e-4 of
        the scene may pass it; a ray starting inside a model hits at 0). Normals are the
        hit instance's exact gradient.

        Args:
            origins: ``(N, 3)`` or one ``(3,)`` origin for all rays (world).
            directions: ``(N, 3)`` ray directions (normalised here).
            max_distance: the farthest hit reported.

        Raises:
            CsdfError: bad shapes, a zero or non-finite direction or origin, or a model
                without a Lipschitz bound.
        """
        from ..render.trace import trace_hits

        d = _points(directions, "directions")
        o = np.asarray(origins, dtype=np.float64)
        if o.shape != (3,):
            o = _points(origins, "origins")
            if len(o) != len(d):
                raise CsdfError(f"origins must have shape (3,) or {d.shape}, got {o.shape}")
        if not (np.isfinite(d).all() and np.isfinite(o).all()):
            raise CsdfError("ray origins and directions must be finite")
        norm = np.linalg.norm(d, axis=1)
        if len(d) and not norm.min() > 0:
            raise CsdfError("ray directions must not be zero")
        d = d / norm[:, None]
        m = float(max_distance)
        if not m >= 0:
            raise CsdfError(f"max_distance must be >= 0, got {max_distance!r}")
        n = len(d)
        fs = self._fieldset()
        if fs is None:
            return SceneHits(np.zeros(n, bool), np.full(n, np.inf), np.full(n, -1),
                             np.zeros((n, 3)))
        if not np.isfinite(fs.lipschitz):
            bad = next(f for f in self._inst.values()
                       if not np.isfinite(self._fields[f.id].lipschitz))
            raise CsdfError(f"ray casts step by the field's value over its Lipschitz bound; "
                            f"instance {bad.name!r} has none (its model is neither a "
                            "distance nor a bound)")
        tracer = _TracedScene(fs)
        t, nrm, _ = trace_hits(tracer, o, d)
        t[t > m] = np.inf
        hit = np.isfinite(t)
        k = np.full(n, -1)
        if hit.any():  # the instance nearest a point just before the hit
            back = t[hit] - 1e-7 * tracer.scale
            p = (o if o.ndim == 1 else o[hit]) + back[:, None] * d[hit]
            k[hit] = self._ids[np.maximum(fs.nearest(p)[2], 0)]
        nrm[~hit] = 0.0
        return SceneHits(hit, t, k, nrm)

    # ------------------------------------------------------------------ consumers
    def _groups(self) -> dict[tuple, list[Instance]]:
        """Instances by (model, parameter values): each group is meshed or sampled once
        in its model's frame."""
        out: dict[tuple, list[Instance]] = {}
        for inst in self:
            fld = self._fields[inst.id]  # equal programs group together
            key = (fld.program, tuple(sorted(fld.params.items())))
            out.setdefault(key, []).append(inst)
        return out

    def mesh(self, resolution: int | None = None, voxel_size: float | None = None,
             method: str = "mc", progress: bool = False, **kw: Any):
        """One triangle mesh of all instances (what :func:`csdf.mesh` returns for a
        scene): each model is meshed once per parameter values in its own frame
        (``resolution`` as for the model alone, or ``voxel_size`` in world units,
        divided by the group's largest scale) and placed by each instance's pose.
        Overlapping instances are not merged. ``mesh.metadata['csdf']['instance']``
        holds the instance id of every face. Other keywords go to :func:`csdf.mesh`.

        Raises:
            CsdfError: an empty scene, or as :func:`csdf.mesh`.
        """
        import trimesh

        from ..mesh import mesh as mesh_model

        if not self._inst:
            raise CsdfError("an empty scene has no surface to mesh")
        verts, faces, ids = [], [], []
        n = 0
        for group in self._groups().values():
            first = group[0]
            h = None if voxel_size is None else \
                float(voxel_size) / max(i.pose.scale for i in group)
            m = mesh_model(first.model, resolution=resolution, voxel_size=h, method=method,
                           params=self._fields[first.id].params, progress=progress, **kw)
            v = np.asarray(m.vertices)
            f = np.asarray(m.faces)
            for inst in group:
                verts.append(inst.pose.apply(v))
                faces.append(f + n)
                ids.append(np.full(len(f), inst.id, np.int64))
                n += len(v)
        out = trimesh.Trimesh(vertices=np.concatenate(verts), faces=np.concatenate(faces),
                              process=False, validate=False)
        out.metadata["csdf"] = {"instance": np.concatenate(ids), "method": method}
        return out

    def sample_surface(self, n: int, seed: Any = None, *,
                       resolution: int | None = None
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``n`` points uniform by area on the surface of the scene (the union of its
        instances: points of one instance inside another are redrawn), with unit
        normals and the id of the instance each lies on (what
        :func:`csdf.sample_surface` returns for a scene). Each instance's share is
        drawn from the surface areas of its model's mesh (times its scale squared).

        Returns:
            ``(points (n, 3), normals (n, 3), instance (n,))`` world frame.
        """
        from ..mesh import mesh as mesh_model
        from ..sample import sample_surface as sample_model

        n = int(n)
        if n < 0:
            raise CsdfError(f"n must be >= 0, got {n}")
        if not self._inst:
            raise CsdfError("an empty scene has no surface to sample")
        rng = rng_arg(seed)
        insts: list[Instance] = []
        area: list[float] = []
        for g in self._groups().values():
            m = mesh_model(g[0].model, resolution=resolution or 64, progress=False,
                           params=self._fields[g[0].id].params, check_thin=False)
            insts += g
            area += [float(m.area) * i.pose.scale ** 2 for i in g]
        w = np.array(area)
        pts, nrm, ids = [], [], []
        got = 0
        diag = float(np.linalg.norm(self.bounds[1] - self.bounds[0]))
        for _ in range(20):
            if got >= n:
                break
            need = n - got
            counts = rng.multinomial(need + need // 4 + 8, w / w.sum())
            for inst, k in zip(insts, counts):
                if k == 0:
                    continue
                fld = self._fields[inst.id]
                p, q = sample_model(inst.model, int(k), rng, fld.params,
                                    resolution=resolution)
                pw = inst.pose.apply(p)
                keep = self.distance(pw) > -1e-9 * diag  # not inside another instance
                pts.append(pw[keep])
                nrm.append(inst.pose.apply_dirs(q)[keep])
                ids.append(np.full(int(keep.sum()), inst.id, np.int64))
                got += int(keep.sum())
        if got < n:
            raise CsdfError("could not draw enough points on the scene's surface (most of "
                            "it lies inside other instances)")
        P, Q, K = np.concatenate(pts), np.concatenate(nrm), np.concatenate(ids)
        pick = np.sort(rng.choice(len(P), n, replace=False))
        return P[pick], Q[pick] / np.linalg.norm(Q[pick], axis=1, keepdims=True), K[pick]

    # ------------------------------------------------------------------ files
    def save(self, path: str | os.PathLike) -> None:
        """Write the scene as a readable JSON text file (written to a temporary file
        and renamed); see :mod:`csdf.scene.fileformat`."""
        fileformat.save(self, path)

    def dumps(self) -> str:
        """The scene file's text (see :mod:`csdf.scene.fileformat`)."""
        return fileformat.dumps(self)

    @classmethod
    def load(cls, path: str | os.PathLike) -> Scene:
        """Read a scene file written by :meth:`save` (or by hand); model files are
        found relative to the scene file.

        Raises:
            CsdfError: naming the file and the line and column or the record.
        """
        return fileformat.load(path, cls())

    @classmethod
    def loads(cls, text: str, source: str = "<string>",
              base: str | os.PathLike | None = None) -> Scene:
        """A scene from the file's text; ``base``: the folder model files are
        relative to."""
        return fileformat.loads(text, cls(), source, None if base is None else Path(base))
