"""csdf: continuous signed distance functions for 3D vision.

Build shapes from primitives and operators, with named parameters::

    import csdf
    r = csdf.param("r", 1.0, 0.5, 2.0)
    shape = csdf.sphere(r) & csdf.box(1.5)
    prog = csdf.compile(shape)
    d = prog(points, r=1.2)           # (N,) signed distances
    g = prog.gradient(points)         # (N, 3) exact gradients
    J = prog.param_jacobian(points)   # (N, P) derivatives by parameter
"""

from __future__ import annotations

from . import io
from .compiler import Call, Program
from .errors import BytecodeError, CsdfError, ModelError, ParamError, ShapeError
from .expr import Expr, Param, param
from .field import Field, as_field, glsl_params, shadertoy, to_glsl
from .fit import FitResult, fit, icp
from .lang import dumps, load, loads
from .mesh import mesh
from .pose import Pose
from .render import Camera, Render, render
from .sample import sample_surface, sample_volume
from .scan import scan
from .shapes import *  # noqa: F403
from .shapes import REGISTRY, Shape
from .shapes import __all__ as _shape_names
from .slicing import save_slice
from .slicing import slice as slice  # noqa: A004 - public name csdf.slice (not in __all__)
from .version import __version__


def compile(shape: Shape) -> Program:  # noqa: A001 - public API name
    """Compile a shape into a :class:`Program` (cached on the shape)."""
    if not isinstance(shape, Shape):
        raise ShapeError(f"csdf.compile expects a Shape, got {type(shape).__name__}")
    return shape.compile()


__all__ = [
    "compile", "param", "Param", "mesh", "io", "Expr", "Program", "Call", "Shape", "REGISTRY",
    "CsdfError", "BytecodeError", "ParamError", "ShapeError", "ModelError", "__version__",
    "sample_surface", "sample_volume", "save_slice", "Camera", "Render", "render", "scan",
    "load", "loads", "dumps", "to_glsl", "shadertoy", "glsl_params", "fit", "icp", "FitResult",
    "Field", "as_field", "Pose", *_shape_names,
]
