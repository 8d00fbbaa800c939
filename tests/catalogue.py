"""A catalogue of shapes covering every primitive and operator, for conformance tests.

Each entry is ``name -> factory`` (a fresh shape per call). Parametrised entries use
``csdf.param`` so derivatives by parameters are exercised too.
"""

from __future__ import annotations

import math

import csdf


def _pair():
    return csdf.sphere(0.6), csdf.box((0.8, 0.7, 0.9)).translate((0.3, 0.2, 0.1))


def primitives() -> dict:
    """Every registered primitive at its default arguments."""
    return {
        name: entry.fn
        for name, entry in sorted(csdf.REGISTRY.items())
        if entry.kind in ("primitive3d", "primitive2d")
    }


def operators() -> dict:
    r = lambda: csdf.param("r", 0.6, 0.3, 0.9)  # noqa: E731
    k = lambda: csdf.param("k", 0.2, 0.05, 0.4)  # noqa: E731
    out = {
        "extrude": lambda: csdf.extrude(csdf.hexagon(0.5), 1.0),
        "revolve": lambda: csdf.revolve(csdf.circle(0.2), 0.6),
        "revolve_faceted": lambda: csdf.revolve(csdf.rectangle((0.3, 0.4)), 0.5,
                                                segments=7),
        "difference": lambda: _pair()[0] - _pair()[1],
        "complement": lambda: ~csdf.sphere(0.5),
        "union3_smooth": lambda: csdf.union(
            csdf.sphere(r()), csdf.box(0.5).translate((0.5, 0, 0)),
            csdf.cylinder(0.2, 1.2).translate((-0.4, 0.1, 0)), k=k()),
        "translate": lambda: csdf.torus(0.5, 0.1).translate((0.1, -0.2, 0.3)),
        "rotate_axis": lambda: csdf.box((1, 0.5, 0.3)).rotate(0.7, (1, 1, 0)),
        "rotate_param": lambda: csdf.box((1, 0.5, 0.3)).rotate(csdf.param("a", 0.4, -1, 1)),
        "rotate_matrix": lambda: csdf.box((1, 0.5, 0.3)).rotate(
            [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]),
        "orient": lambda: csdf.cylinder(0.3, 1.0).orient((1, 1, 1)),
        "scale": lambda: csdf.box(0.8).scale(csdf.param("s", 1.5, 0.5, 2)),
        "scale_vector": lambda: csdf.sphere(0.5).scale((1.0, 2.0, 0.5)),
        "mirror": lambda: csdf.sphere(0.3).translate((0.4, 0.2, 0)).mirror("xy"),
        "repeat": lambda: csdf.sphere(0.2).repeat(0.6),
        "repeat_count": lambda: csdf.sphere(0.2).repeat((0.6, 0.6, 0), count=(3, 2, 1)),
        "repeat_mirrored": lambda: csdf.box(0.3).translate((0.1, 0, 0)).repeat_mirrored(0.7),
        "repeat_mirrored_count": lambda: csdf.box(0.3).translate((0.1, 0, 0)).repeat_mirrored(
            (0.7, 0, 0), count=(4, 1, 1)),
        "repeat_polar": lambda: csdf.sphere(0.2).translate((0.7, 0, 0)).repeat_polar(6),
        "twist": lambda: csdf.box((1, 0.5, 2)).twist(csdf.param("t", 1.0, 0.0, 2.0)),
        "bend": lambda: csdf.box((2, 0.3, 0.3)).bend(0.5),
        "taper": lambda: csdf.box(1).taper(0.3),
        "elongate": lambda: csdf.sphere(0.3).elongate((0.3, 0, 0.1)),
        "round": lambda: csdf.box(0.6).round(0.1),
        "shell": lambda: csdf.sphere(0.6).shell(0.05),
        "offset": lambda: csdf.sphere(0.6).offset(-0.1),
        "rename": lambda: csdf.sphere(r()).rename(prefix="left_")
        | csdf.sphere(r()).translate((0.7, 0, 0)).rename(suffix="_b"),
        "bind": lambda: csdf.union(csdf.sphere(r()), csdf.box(0.5).translate((0.5, 0, 0)),
                                   k=k()).bind(k=0.1),
        "rotate_2d": lambda: csdf.extrude(csdf.rectangle((1, 0.4)).rotate(0.3), 0.5),
        "polar_2d": lambda: csdf.extrude(
            csdf.circle(0.1).translate((0.5, 0)).repeat_polar(5), 0.3),
        "transform": lambda: csdf.box((0.8, 0.5, 0.4)).transform(
            [[1.0, 0.4, 0.0, 0.1], [0.0, 1.2, 0.0, 0.0], [0.0, 0.0, 0.8, -0.1],
             [0.0, 0.0, 0.0, 1.0]]),
        "polygon_holes": lambda: csdf.extrude(csdf.polygon(
            [[-0.6, -0.6], [0.6, -0.6], [0.6, 0.6], [-0.6, 0.6], [-0.2, -0.2], [0.2, -0.2],
             [0.2, 0.2], [-0.2, 0.2]], paths=[[0, 1, 2, 3], [4, 5, 6, 7]]), 0.4),
        "field_param": lambda: csdf.field(
            csdf.sqrt(csdf.x * csdf.x + csdf.y * csdf.y + csdf.z * csdf.z) - r(),
            exact=True, bounds=((-0.9, -0.9, -0.9), (0.9, 0.9, 0.9))),
        "normalized": lambda: csdf.field(
            csdf.x * csdf.x / 0.5 + csdf.y * csdf.y + csdf.z * csdf.z - 0.4,
            bounds=((-1, -1, -1), (1, 1, 1))).normalized(),
        "remap": lambda: csdf.box((0.8, 0.5, 0.4)).remap(
            x=csdf.x + 0.3 * csdf.sin(2.0 * csdf.y)) & csdf.box(1.2),
    }
    for blend in (None, *csdf.BLENDS):
        for op in ("union", "intersection"):
            def make(op=op, blend=blend):
                a, b = _pair()
                fn = getattr(csdf, op)
                if blend is None:
                    return fn(a, b)
                return fn(a, b, k=0.2, blend=blend)
            out[f"{op}_{blend or 'hard'}"] = make
    return out


#: primitives whose program holds a mesh call: only the CPU evaluators run them (GLSL
#: and C export refuse them, tested in test_from_mesh.py)
MESH_CALLS = ("polyhedron",)


def catalogue(mesh_calls: bool = True) -> dict:
    """Every primitive and operator; ``mesh_calls=False`` leaves out :data:`MESH_CALLS`
    (for the consumers that do not run them)."""
    out = {**primitives(), **operators()}
    return out if mesh_calls else {k: v for k, v in out.items() if k not in MESH_CALLS}


def sample_box(shape, pad: float = 0.3, default: float = 1.5):
    """A box around the shape's bounds (or ``[-default, default]^3``), padded."""
    import numpy as np

    b = shape.bounds
    if b is None or not np.all(np.isfinite(b)):
        lo, hi = -default * np.ones(3), default * np.ones(3)
    else:
        lo, hi = np.full(3, -default), np.full(3, default)
        lo[: shape.dim], hi[: shape.dim] = b[0] - pad, b[1] + pad
        lo, hi = np.maximum(lo, -5), np.minimum(hi, 5)
    return lo, hi


TAU = 2 * math.pi
