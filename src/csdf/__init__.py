"""csdf: continuous signed distance functions for 3D vision.

Build shapes from primitives and operators, with named parameters::

    import csdf
    r = csdf.param("r", 1.0, 0.5, 2.0)
    shape = csdf.sphere(r) & csdf.box(1.5)
    prog = csdf.compile(shape)
    d = prog(points, r=1.2)           # (N,) signed distances
    g = prog.gradient(points)         # (N, 3) exact gradients
    J = prog.param_jacobian(points)   # (N, P) derivatives by parameter

``import csdf`` loads only the expression, shape and compiler layers; the consumers
(meshing, rendering, fitting, I/O, the language, the zoo: whatever pulls in Numba, SciPy
or trimesh) load on first use of one of their names (``csdf.mesh``, ``csdf.zoo``,
``from csdf import fit``, ...), so that the command line and scripts start quickly.
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
import types
from typing import TYPE_CHECKING, Any

from .compiler import Call, Program
from .errors import BytecodeError, CsdfError, MeshWarning, ModelError, ParamError, ShapeError
from .expr import (
    Expr,
    Param,
    acos,
    asin,
    atan,
    atan2,
    clamp,
    cos,
    exp,
    floor,
    log,
    maximum,
    minimum,
    mix,
    mod,
    param,
    sign,
    sin,
    sqrt,
    square,
    step,
    tan,
)
from .expr import X as x
from .expr import Y as y
from .expr import Z as z
from .pose import Pose
from .shapes import *  # noqa: F403
from .shapes import REGISTRY, Shape
from .shapes import __all__ as _shape_names
from .version import __version__

if TYPE_CHECKING:  # what __getattr__ loads on first use (see _LAZY), for type checkers
    from . import colors, io, metrics, synth, zoo
    from .detect import (
        Detection,
        PrimitiveDetection,
        detect,
        detect_primitives,
        detections_to_scene,
        estimate_normals,
    )
    from .field import Field, as_field, glsl_params, shadertoy, to_c, to_glsl, to_numpy
    from .fit import (
        FitResult,
        Tracker,
        TrackFrame,
        TrackResult,
        fit,
        fit_depth,
        fit_silhouette,
        icp,
        track,
    )
    from .infer import InferResult, infer
    from .lang import dumps, load, loads
    from .mesh import mesh
    from .raster import raster
    from .render import Camera, Render, render
    from .sample import sample_surface, sample_volume
    from .scan import scan
    from .scene import Scene, SceneQuery
    from .slicing import save_slice
    from .slicing import slice as slice  # noqa: A004 - public name csdf.slice
    from .synth import Sequence

#: public name -> (module relative to this package, attribute; ``None``: the module
#: itself), loaded on first access by :func:`__getattr__`
_LAZY: dict[str, tuple[str, str | None]] = {
    "io": (".io", None),
    "colors": (".colors", None),
    "zoo": (".zoo", None),
    "synth": (".synth", None),
    "metrics": (".metrics", None),
    "Sequence": (".synth", "Sequence"),
    "plan": (".plan", None),
    "Field": (".field", "Field"),
    "as_field": (".field", "as_field"),
    "glsl_params": (".field", "glsl_params"),
    "shadertoy": (".field", "shadertoy"),
    "to_glsl": (".field", "to_glsl"),
    "to_c": (".field", "to_c"),
    "to_numpy": (".field", "to_numpy"),
    "FitResult": (".fit", "FitResult"),
    "fit": (".fit", "fit"),
    "icp": (".fit", "icp"),
    "fit_depth": (".fit", "fit_depth"),
    "fit_silhouette": (".fit", "fit_silhouette"),
    "track": (".fit", "track"),
    "TrackResult": (".fit", "TrackResult"),
    "Tracker": (".fit", "Tracker"),
    "TrackFrame": (".fit", "TrackFrame"),
    "detect": (".detect", "detect"),
    "detect_primitives": (".detect", "detect_primitives"),
    "detections_to_scene": (".detect", "detections_to_scene"),
    "Detection": (".detect", "Detection"),
    "PrimitiveDetection": (".detect", "PrimitiveDetection"),
    "estimate_normals": (".detect", "estimate_normals"),
    "infer": (".infer", "infer"),
    "InferResult": (".infer", "InferResult"),
    "dumps": (".lang", "dumps"),
    "load": (".lang", "load"),
    "loads": (".lang", "loads"),
    "mesh": (".mesh", "mesh"),
    "Camera": (".render", "Camera"),
    "Render": (".render", "Render"),
    "render": (".render", "render"),
    "sample_surface": (".sample", "sample_surface"),
    "sample_volume": (".sample", "sample_volume"),
    "scan": (".scan", "scan"),
    "Scene": (".scene", "Scene"),
    "SceneQuery": (".scene", "SceneQuery"),
    "raster": (".raster", "raster"),
    "save_slice": (".slicing", "save_slice"),
    "slice": (".slicing", "slice"),  # public name csdf.slice (not in __all__)
}

#: public functions named like the subpackage that defines them (``csdf.mesh`` is the
#: function ``csdf.mesh.mesh``): the import system's binding of the subpackage on this
#: package is refused, so the name always means the function
_FUNCTION_OVER_MODULE = frozenset(
    [name for name, (mod, attr) in _LAZY.items() if attr is not None and mod == "." + name]
    + ["field"])  # csdf.field is the user-field function; the field layer is csdf.Field


def compile(shape: Shape) -> Program:  # noqa: A001 - public API name
    """Compile a shape into a :class:`Program` (cached on the shape)."""
    if not isinstance(shape, Shape):
        raise ShapeError(f"csdf.compile expects a Shape, got {type(shape).__name__}")
    return shape.compile()


def __getattr__(name: str) -> Any:
    """Load a lazily exported name (see :data:`_LAZY`) on first access and keep it; any
    other submodule (``csdf.field``, ``csdf.backends``, ...) is imported on first access
    too, as if ``import csdf`` had loaded it."""
    try:
        module_name, attr = _LAZY[name]
    except KeyError:
        if name.startswith("_") or importlib.util.find_spec(f"{__name__}.{name}") is None:
            raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
        module_name, attr = "." + name, None
    module = importlib.import_module(module_name, __name__)
    value = module if attr is None else getattr(module, attr)
    globals()[name] = value  # (the module's dict: bypasses _Namespace.__setattr__)
    return value


def __dir__() -> list[str]:
    """The module's names, the lazy ones included."""
    return sorted(set(globals()) | set(_LAZY))


class _Namespace(types.ModuleType):
    """This package's module type: keeps ``csdf.mesh``, ``csdf.fit``, ``csdf.render``,
    ``csdf.scan``, ``csdf.detect`` and ``csdf.field`` the functions when their
    subpackages or modules are first imported (the import system then sets the module
    as an attribute of its parent; the field layer's module stays
    ``sys.modules['csdf.field']``, its classes ``csdf.Field``, ``csdf.as_field``)."""

    def __setattr__(self, name: str, value: Any) -> None:
        if (name in _FUNCTION_OVER_MODULE and isinstance(value, types.ModuleType)
                and value.__name__ == f"{__name__}.{name}"):
            return
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Namespace

__all__ = [
    "compile", "param", "Param", "mesh", "io", "colors", "zoo", "Expr", "Program", "Call", "Shape",
    "REGISTRY", "CsdfError", "BytecodeError", "ParamError", "ShapeError", "ModelError",
    "MeshWarning", "__version__", "sample_surface", "sample_volume", "save_slice", "Camera",
    "Render", "render", "scan", "raster", "load", "loads", "dumps", "to_glsl", "shadertoy",
    "glsl_params", "fit", "icp", "FitResult", "Field", "as_field", "Pose", "Scene",
    "SceneQuery", "fit_depth", "fit_silhouette", "track", "Tracker", "TrackFrame",
    "TrackResult", "synth", "Sequence", "metrics", "detect", "detect_primitives",
    "detections_to_scene", "Detection", "PrimitiveDetection", "estimate_normals",
    "to_c", "to_numpy", "infer", "InferResult", "x", "y", "z", "sqrt", "square", "sin",
    "cos", "tan", "asin",
    "acos", "atan", "atan2", "exp", "log", "floor", "step", "sign", "mod", "minimum",
    "maximum", "clamp", "mix",
    *_shape_names,
]
