"""The rotational symmetries of a model, found on its exact field.

A rigid transform ``S`` is a symmetry of the surface ``f = 0`` when it maps the surface
onto itself; since ``S`` is an isometry of a compact surface, mapping it *into* itself
suffices, and that is what is tested: at surface samples ``x`` (:func:`csdf.sample_surface`),
``max |f(S x)|`` must stay within a tolerance of 0.

Candidates are rotations about axes through the model's centre of mass (every symmetry
fixes it): the model frame's x, y and z axes and the principal axes of inertia of the
model's mesh, by ``2 pi / n`` for ``n = 2 .. max_order`` (``n = 2``: the 180-degree
flips). The centre of mass of the mesh is only as exact as the mesh, so a candidate that
nearly passes has its centre corrected by a few Gauss-Newton steps on
``sum f(c + R (x - c))^2`` before it is judged. The accepted rotations generate a
finite group (closed under composition, each member tested again). An axis about which
rotations by angles incommensurate with ``2 pi`` (the golden angle and 1 radian) pass is
*continuous*; its rotations are discretised in steps that move no model point by more
than ``continuous_step`` times the diameter (a multiple of 12 steps), together with one
180-degree flip about a perpendicular axis where there is one.

The mesh that gives the samples, the centre and the axes is :func:`csdf.mesh`'s own
choice of resolution by default: 128 voxels, finer where the grid would lose thin
parts (up to :data:`MAX_RESOLUTION`). A grid that loses a part gives samples without
it (a bookshelf's 6 mm back panel unsampled made its half turn a symmetry; a table top
thinner than a voxel left no surface at all) and a centre of mass off the true centre
(a table's half turn about it failed). A centre that fails from the centre of mass is
tried again from the model's origin and from the samples' mean.

Limits: axes other than the frame's and the principal axes are not tried (a rotated
hexagonal prism's flips about axes in its degenerate principal plane are missed: give
such symmetries yourself); parts thinner than a voxel of the finest grid may go
unsampled.
"""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np

from ..errors import CsdfError, MeshWarning
from ..field import Field, as_field
from ..pose import Pose
from ..sample import sample_surface
from .inputs import positive
from .model import MAX_RESOLUTION, diameter, model_mesh

__all__ = ["symmetries", "MAX_GROUP", "MAX_RESOLUTION"]

#: the most symmetries a finite group found by :func:`symmetries` may have
MAX_GROUP = 120
#: angles incommensurate with 2 pi: an axis about which both pass is continuous
_IRRATIONAL = (math.pi * (3.0 - math.sqrt(5.0)), 1.0)
_SAME_AXIS = 1e-2      # |a x b| under which two axes are one
_SAME_ROTATION = 1e-2  # max |R1 - R2| under which two rotations are one
_REFINE = 30.0         # residuals (in tolerances) up to which a centre is refined


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    return Pose.from_rotvec(axis * angle).rotation


class _Tester:
    """The field, the surface samples and the first guesses ``(G, 3)`` of the centre
    that candidate rotations turn about."""

    def __init__(self, fld: Field, x: np.ndarray, centres: np.ndarray, tol: float):
        self.fld, self.x, self.centres, self.tol = fld, x, centres, tol

    def fit(self, R: np.ndarray) -> np.ndarray | None:
        """The centre ``c`` about which ``R`` maps the samples onto the surface within
        the tolerance, or None: :meth:`_fit_from` each first guess in turn."""
        for c in self.centres:
            out = self._fit_from(R, c)
            if out is not None:
                return out
        return None

    def _fit_from(self, R: np.ndarray, c: np.ndarray) -> np.ndarray | None:
        """From the guess ``c``, a few Gauss-Newton steps on ``sum f(R x + (I - R)
        c)^2`` correct it (the mesh's centre of mass is only as exact as the mesh); a
        rotation far from a symmetry is not refined."""
        A0 = np.eye(3) - R
        for it in range(4):
            f, g = self.fld.value_and_grad((self.x - c) @ R.T + c)
            worst = float(np.max(np.abs(f)))
            if worst <= self.tol:
                return c
            if it == 3 or worst > _REFINE * self.tol:
                return None
            step, *_ = np.linalg.lstsq(g @ A0, -f, rcond=1e-9)
            c = c + step
        return None

    def r_max(self, axis: np.ndarray, c: np.ndarray) -> float:
        """The samples' largest distance from the axis through ``c``."""
        q = self.x - c
        return float(np.max(np.linalg.norm(q - np.outer(q @ axis, axis), axis=1)))


def _unit_axes(vectors: list[np.ndarray]) -> list[np.ndarray]:
    """Unit axes without repeats (``a`` and ``-a`` are one axis), in order."""
    out: list[np.ndarray] = []
    for v in vectors:
        n = float(np.linalg.norm(v))
        if n < 1e-9:
            continue
        a = v / n
        if any(np.linalg.norm(np.cross(a, b)) <= _SAME_AXIS for b in out):
            continue
        out.append(a)
    return out


def _candidate_axes(m) -> list[np.ndarray]:
    """The frame axes, then the principal axes of inertia of the mesh ``m``."""
    frame = list(np.eye(3))
    try:
        principal = list(np.asarray(m.principal_inertia_vectors, dtype=np.float64))
    except Exception:  # noqa: BLE001 - a degenerate mesh: the frame axes only
        principal = []
    return _unit_axes(frame + [p for p in principal if np.all(np.isfinite(p))])


def _centres(m, x: np.ndarray, tol: float) -> np.ndarray:
    """``(G, 3)`` first guesses of the centre: the mesh's centre of mass (the model
    origin when it is that to ``tol / 10``), then the origin and the samples ``x``'s
    mean where they differ from it by more than ``tol / 10``."""
    c = np.asarray(m.center_mass, dtype=np.float64) if m.volume > 0 else None
    if c is None or not np.all(np.isfinite(c)):
        c = np.asarray(m.vertices, dtype=np.float64).mean(axis=0)
    if np.linalg.norm(c) <= 0.1 * tol:
        c = np.zeros(3)
    out = [c]
    for g in (np.zeros(3), x.mean(axis=0)):
        if all(np.linalg.norm(g - o) > 0.1 * tol for o in out):
            out.append(g)
    return np.asarray(out)


def _closure(gens: list[np.ndarray], tester: _Tester) -> list[np.ndarray]:
    """The group generated by the rigid transforms ``gens`` ``(4, 4)`` (identity
    first); each new member is tested on the field (its centre refined) and dropped
    when it fails."""
    group = [np.eye(4)]
    frontier = [np.eye(4)]
    while frontier:
        new = []
        for g in frontier:
            for h in gens:
                r = h @ g
                if min(np.abs(r[:3, :3] - q[:3, :3]).max() for q in group) <= _SAME_ROTATION:
                    continue
                c = tester.fit(r[:3, :3])
                if c is None:
                    continue
                group.append(_transform(r[:3, :3], c))
                new.append(group[-1])
                if len(group) > MAX_GROUP:
                    raise CsdfError(
                        f"more than {MAX_GROUP} symmetries found (a nearly continuous "
                        "symmetry?): lower tol, or pass the symmetries yourself")
        frontier = new
    return group


def _transform(R: np.ndarray, c: np.ndarray) -> np.ndarray:
    """``(4, 4)``: the rotation ``R`` about the centre ``c``."""
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = c - R @ c
    return T


def _continuous_group(axis: np.ndarray, c: np.ndarray, axes: list[np.ndarray],
                      tester: _Tester, step: float) -> list[np.ndarray]:
    """Rotations about a continuous ``axis`` through ``c``, discretised so that no
    sample moves more than ``step`` between neighbours, times a perpendicular flip when
    one passes."""
    r = tester.r_max(axis, c)
    angle = 2.0 * math.asin(min(1.0, step / (2.0 * r))) if r > 0 else 2.0 * math.pi
    m = 12 * math.ceil(2.0 * math.pi / angle / 12.0)  # n-fold steps for n | 12 included
    turns = [_transform(_rotation(axis, 2.0 * math.pi * k / m), c) for k in range(m)]
    perp = [b for b in axes if abs(float(b @ axis)) <= _SAME_AXIS]
    perp += [e - (e @ axis) * axis for e in np.eye(3)]
    for b in _unit_axes(perp):
        flip = _rotation(b, math.pi)
        cf = tester.fit(flip)
        if cf is not None:
            F = _transform(flip, cf)
            return turns + [t @ F for t in turns]
    return turns


def symmetries(shape: Any, *, params: dict | None = None, tol: float = 1e-3,
               max_order: int = 12, continuous_step: float = 0.01, samples: int = 2000,
               seed: int = 0, resolution: int | None = None, check_ranges: bool = True
               ) -> np.ndarray:
    """The discrete rotational symmetries of a model (continuous ones discretised), as
    the transforms BOP's MSSD and MSPD minimise over.

    See the module's documentation for the method. Deterministic: the same arguments
    give the same transforms.

    Args:
        shape: a 3D :class:`csdf.Shape`, :class:`csdf.Program` or field.
        params: parameter values ``{name: value}``.
        tol: a rotation is a symmetry when ``|f|`` at every rotated sample is at most
            ``tol`` times the model's diameter (the field's value is the distance for an
            exact field; a bound under-estimates it and accepts more).
        max_order: the largest ``n`` of the ``n``-fold rotations tried (``>= 2``).
        continuous_step: a continuous symmetry is discretised in steps that move no
            surface point by more than this fraction of the diameter (so MSSD's error
            from the discretisation is at most that).
        samples: surface samples the candidates are tested on.
        seed: the samples' seed.
        resolution: resolution of the meshes that give the samples (parts thinner than
            a voxel may go unsampled) and the centre of mass and principal axes.
            Default: :func:`csdf.mesh`'s choice, finer where it has thin parts (up to
            :data:`MAX_RESOLUTION`).
        check_ranges: refuse a parameter value outside its declared range.

    Returns:
        ``(K, 4, 4)`` float64 rigid transforms ``[[R, c - R c], [0, 0, 0, 1]]`` in the
        model frame (rotations by ``R`` about a centre ``c``), the identity first.

    Raises:
        CsdfError: bad arguments; continuous symmetry about more than one axis (a
            sphere: pass the symmetries yourself); more than :data:`MAX_GROUP` found.
    """
    rel = positive(tol, "tol")
    step = positive(continuous_step, "continuous_step")
    for v, name, lo in ((max_order, "max_order", 2), (samples, "samples", 10),
                        (8 if resolution is None else resolution, "resolution", 8)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < lo:
            raise CsdfError(f"{name} must be an integer >= {lo}, got {v!r}")
    fld = as_field(shape, params, work=samples, what="symmetries", check_ranges=check_ranges)
    if fld.dim != 3:
        raise CsdfError("symmetries needs a 3D shape")
    m = model_mesh(fld, resolution)
    resolution = int(m.metadata["csdf"]["resolution"])
    with warnings.catch_warnings():  # thin parts: said in the docs, not per call
        warnings.simplefilter("ignore", MeshWarning)
        x, _ = sample_surface(fld, samples, seed=seed, resolution=resolution)
    size = diameter(x)
    tester = _Tester(fld, x, _centres(m, x, rel * size), rel * size)
    axes = _candidate_axes(m)
    continuous = []
    for a in axes:
        c = tester.fit(_rotation(a, _IRRATIONAL[0]))
        if c is not None and tester.fit(_rotation(a, _IRRATIONAL[1])) is not None:
            continuous.append((a, c))
    if len(continuous) > 1:
        raise CsdfError("the model is symmetric under every rotation about more than one "
                        "axis (a sphere?); pass its symmetries yourself")
    if continuous:
        (a, c), = continuous
        return np.asarray(_continuous_group(a, c, axes, tester, step * size))
    gens = []
    for a in axes:
        for n in range(2, int(max_order) + 1):
            R = _rotation(a, 2.0 * math.pi / n)
            c = tester.fit(R)
            if c is not None:
                gens.append(_transform(R, c))
    return np.asarray(_closure(gens, tester))
