"""The modelling API: primitives, CSG, domain operations and deformations."""

from . import appearance as _appearance  # noqa: F401  (registers Shape.color)
from . import deform as _deform  # noqa: F401  (registers shape methods)
from . import params as _params  # noqa: F401  (registers bind and rename)
from .base import REGISTRY, ApiEntry, Shape
from .convex import convex_polyhedron
from .csg import BLENDS, complement, difference, intersection, union
from .domain import (
    mirror,
    orient,
    repeat,
    repeat_mirrored,
    repeat_polar,
    rotate,
    scale,
    transform,
    translate,
)
from .polyhedron import from_mesh, polyhedron
from .primitives2d import (
    circle,
    cross_section,
    ellipse,
    equilateral_triangle,
    extrude,
    hexagon,
    polygon,
    rectangle,
    regular_polygon,
    revolve,
    rhombus,
    ring,
    rounded_rectangle,
    segment,
    trapezoid,
    triangle,
)
from .primitives3d import (
    box,
    box_frame,
    capped_cone,
    capped_torus,
    capsule,
    cone,
    cylinder,
    ellipsoid,
    hex_prism,
    link,
    octahedron,
    plane,
    pyramid,
    round_cone,
    rounded_box,
    rounded_cylinder,
    slab,
    sphere,
    torus,
    tri_prism,
)
from .userfield import field, gyroid, normalized, remap, superquadric, tanglecube

__all__ = [
    "Shape", "REGISTRY", "ApiEntry", "BLENDS",
    "sphere", "box", "rounded_box", "box_frame", "cylinder", "rounded_cylinder", "capsule",
    "cone", "capped_cone", "round_cone", "torus", "capped_torus", "link", "plane", "slab",
    "ellipsoid", "octahedron", "pyramid", "hex_prism", "tri_prism", "convex_polyhedron",
    "polyhedron", "from_mesh",
    "circle", "rectangle", "rounded_rectangle", "regular_polygon", "polygon", "triangle",
    "equilateral_triangle", "hexagon", "ring", "segment", "trapezoid", "rhombus", "ellipse",
    "extrude", "revolve", "cross_section",
    "union", "intersection", "difference", "complement",
    "translate", "rotate", "orient", "transform", "scale", "mirror", "repeat",
    "repeat_mirrored", "repeat_polar",
    "field", "normalized", "remap", "gyroid", "superquadric", "tanglecube",
]
