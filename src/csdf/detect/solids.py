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
from ..field import as_field
from ..pose import Pose
from ..shapes import box, capped_cone, cylinder, sphere, torus

__all__ = ["canonical", "SOLID_PARAMS", "posed", "solid_values", "SOLID_BACKEND"]

#: the evaluator of the solids: the bytecode interpreter (compiled once for every
#: program, so no kernel is compiled per solid)
SOLID_BACKEND = "interp"

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
    _, fld = canonical(kind)
    f, g = fld.replace(params=values, pose=Pose(R, t), check_ranges=False).value_and_grad(P)
    g = np.asarray(g, dtype=float)
    g /= np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-300)
    return np.asarray(f, dtype=float), g


def posed(kind: str, R: np.ndarray, t: np.ndarray, values: dict):
    """The posed csdf shape of a detected solid: the canonical solid with its parameters'
    defaults set to ``values`` (so they stay named and adjustable), rotated by ``R`` and
    moved by ``t``."""
    s = _solid(kind, values)
    if not np.allclose(R, np.eye(3), atol=1e-12):
        s = s.rotate(np.asarray(R, float))
    return s.translate(tuple(float(v) for v in t))
