"""The solids behind detected primitives: each kind as one csdf primitive in a canonical
frame with named size parameters, placed by a pose, so that :func:`csdf.fit` refines
pose and sizes together on the exact signed distance, and the result is an ordinary
posed csdf shape.

==========  =============================================  ===========================
kind        canonical solid (axis z)                        parameters
==========  =============================================  ===========================
sphere      ``sphere(radius)``                              radius
cylinder    ``cylinder(radius, height)``, centred           radius, height
cone        ``capped_cone(r1, r2, height)``: ``r1`` at the  r1, r2, height
            base (z = 0), ``r2`` towards the apex
torus       ``torus(major, minor)``                         major, minor
box         ``box((size_x, size_y, size_z))``, centred      size_x, size_y, size_z
==========  =============================================  ===========================

All five distances are exact (csdf's primitives), so residuals are true distances.
"""

from __future__ import annotations

import math
from functools import cache

import numpy as np

from ..expr import param
from ..field import as_field, choose_backend, step_evaluator
from ..shapes import box, capped_cone, cylinder, sphere, torus

__all__ = ["canonical", "SOLID_PARAMS", "posed", "solid_values", "SOLID_BACKEND",
           "bounding_sphere", "end_moved", "away_from_edges", "frame_values"]

#: the evaluator of the solids: the compiled one (a kernel per canonical solid and
#: evaluation mode, compiled once and cached on disk; ten times the interpreter's speed
#: on a few thousand points), NumPy without Numba (the field layer's choice for sweeps)
SOLID_BACKEND = choose_backend("auto")

#: the size parameters of each solid kind, in order
SOLID_PARAMS = {
    "sphere": ("radius",), "cylinder": ("radius", "height"), "cone": ("r1", "r2", "height"),
    "torus": ("major", "minor"), "box": ("size_x", "size_y", "size_z"),
}


@cache
def canonical(kind: str):
    """The canonical solid of ``kind`` (a :class:`csdf.Shape`, parameters declared
    non-negative, defaults 1) and its :class:`csdf.Field` for evaluation."""
    s = _solid(kind, dict.fromkeys(SOLID_PARAMS[kind], 1.0))
    return s, as_field(s, backend=SOLID_BACKEND, what="detection")


def _solid(kind: str, values: dict):
    """The canonical solid of ``kind`` with named parameters defaulting to ``values``."""
    p = {name: param(name, float(values[name]), 0.0, math.inf) for name in SOLID_PARAMS[kind]}
    if kind == "sphere":
        return sphere(p["radius"])
    if kind == "cylinder":
        return cylinder(p["radius"], p["height"])
    if kind == "cone":
        return capped_cone(p["r1"], p["r2"], p["height"])
    if kind == "torus":
        return torus(p["major"], p["minor"])
    if kind == "box":
        return box((p["size_x"], p["size_y"], p["size_z"]))
    raise ValueError(f"no solid for kind {kind!r}")


def solid_values(kind: str, R: np.ndarray, t: np.ndarray, values: dict, P: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Signed distances ``(S,)`` and unit outward gradients ``(S, 3)`` (scene frame) of
    the solid of ``kind`` with sizes ``values``, placed by rotation ``R`` and
    translation ``t`` (``p = R q + t``), at points ``P`` ``(S, 3)``."""
    q = np.ascontiguousarray((np.asarray(P, dtype=np.float64) - t) @ R)
    d, gq = frame_values(kind, values, q)
    g = gq @ R.T
    g /= np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-300)
    return d, g


def frame_values(kind: str, values: dict, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Signed distances ``(S,)`` and gradients ``(S, 3)`` (not normalised) of the
    canonical solid of ``kind`` with sizes ``values`` at points ``q`` ``(S, 3)`` of its
    own frame (float64, C-contiguous)."""
    defaults, ev = _evaluator(kind)
    res = ev(q, np.array([values.get(n, v) for n, v in defaults], dtype=np.float64))
    return res["value"], res["grad"]


@cache
def _evaluator(kind: str):
    """``(each parameter's (name, default) in the program's order, values-and-gradients
    evaluator)`` of the canonical solid of ``kind`` (:func:`csdf.field.step_evaluator`:
    the detector evaluates its solids some hundreds of times a scan)."""
    prog = canonical(kind)[1].program
    return ([(p.name, float(p.default)) for p in prog.params],
            step_evaluator(prog, SOLID_BACKEND, "grad"))


def away_from_edges(kind: str, R: np.ndarray, t: np.ndarray, values: dict, P: np.ndarray
                    ) -> np.ndarray:
    """``(S,)`` which points ``P`` ``(S, 3)`` keep their distance when reflected
    through the solid's surface along its gradient (the reflection's signed distance is
    the point's negated, within 5 %).

    Near an edge the distance of a point inside is that to the nearer face, shorter
    than its offset from its own face, while a point the same offset outside keeps its
    own: a fit on both pulls the surface outwards (a cone's base radius came out
    0.09 mm too large at 1 mm noise). The test drops the points on both sides alike,
    so the rest are unbiased."""
    d, g = solid_values(kind, R, t, values, P)
    d2, _ = solid_values(kind, R, t, values, P - 2.0 * d[:, None] * g)
    return np.abs(d2 + d) <= 0.05 * np.abs(d)


def bounding_sphere(kind: str, R: np.ndarray, t: np.ndarray, values: dict
                    ) -> tuple[np.ndarray, float]:
    """A sphere around the posed solid: centre ``(3,)`` and radius (scene units)."""
    v = values
    if kind == "sphere":
        return np.asarray(t, float), v["radius"]
    if kind == "cylinder":
        return np.asarray(t, float), math.hypot(v["radius"], 0.5 * v["height"])
    if kind == "cone":
        c = np.asarray(t, float) + 0.5 * v["height"] * R[:, 2]
        return c, math.hypot(max(v["r1"], v["r2"]), 0.5 * v["height"])
    if kind == "torus":
        return np.asarray(t, float), v["major"] + v["minor"]
    return np.asarray(t, float), 0.5 * math.sqrt(v["size_x"] ** 2 + v["size_y"] ** 2
                                                 + v["size_z"] ** 2)


def end_moved(kind: str, R: np.ndarray, t: np.ndarray, values: dict, z: float
              ) -> tuple[np.ndarray, dict] | None:
    """The cylinder or frustum with the end nearer to canonical height ``z`` (scene
    units along its axis ``R[:, 2]``) moved to ``z``, the rest kept (a frustum's radius
    follows its slope): its translation ``(3,)`` and sizes, or None when that leaves no
    solid (a non-positive height or radius) or ``kind`` has no flat ends."""
    a = R[:, 2]
    if kind == "cylinder":
        lo, hi = -0.5 * values["height"], 0.5 * values["height"]
        lo, hi = (lo, z) if z > 0.5 * (lo + hi) else (z, hi)
        if hi - lo <= 0:
            return None
        return t + 0.5 * (lo + hi) * a, {"radius": values["radius"], "height": hi - lo}
    if kind == "cone":
        r1, r2, h = values["r1"], values["r2"], values["height"]
        rz = r1 + (r2 - r1) * z / h
        if rz <= 0:
            return None
        if z > 0.5 * h:  # the top (r2) end
            return (None if z <= 0 else
                    (np.asarray(t, float), {"r1": r1, "r2": rz, "height": z}))
        if h - z <= 0:
            return None
        return t + z * a, {"r1": rz, "r2": r2, "height": h - z}
    return None


def posed(kind: str, R: np.ndarray, t: np.ndarray, values: dict):
    """The posed csdf shape of a detected solid: the canonical solid with its parameters'
    defaults set to ``values`` (so they stay named and adjustable), rotated by ``R`` and
    moved by ``t``."""
    s = _solid(kind, values)
    if not np.allclose(R, np.eye(3), atol=1e-12):
        s = s.rotate(np.asarray(R, float))
    return s.translate(tuple(float(v) for v in t))
