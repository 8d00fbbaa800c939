"""The field layer: what every consumer stands on.

A :class:`Field` is one signed distance field ready to use: a compiled
:class:`~csdf.Program`, parameter values, a bounding box, a pose in the world and an
evaluator. Consumers (meshing, rendering, scanning, sampling, slicing, fitting, the
editor's server, the command line) take their inputs through :func:`as_field`, and so
share one answer to each of the questions they all have:

**Which box holds the surface?** (:func:`field_bounds`, the one bounds policy)
    1. the ``bounds=`` the caller gave (validated: finite, ``min < max``);
    2. else the program's own box (from its shape) when it has no parameters;
    3. else a box found by interval arithmetic for the parameter values, given or
       default (:func:`auto_bounds`: tighter than the program's own box, which holds
       for every value in the declared ranges); so a model meshed with ``params=``
       and the same model with those values as defaults get the same box;
    4. where interval arithmetic is too loose to find one (polygons' winding sign,
       blends), the program's box when every given value lies inside its parameter's
       finite range;
    5. else :class:`~csdf.CsdfError` (an unbounded shape needs ``bounds=``).

**Which evaluator?** (:func:`choose_backend`, the one ``'auto'`` policy)
    A named backend is used as given. ``'auto'`` gives the compiled ``'fast'`` backend
    when Numba is available and the job is a sweep (``work=None``: meshing, rendering,
    scanning, slicing, which evaluate one field on many points and need every value of
    it from the same evaluator) or a point set of at least :data:`AUTO_FAST_POINTS`
    points; otherwise ``'auto'`` stays, and each call picks its evaluator by its size
    (:func:`csdf.backends.select`). Without Numba every job runs on ``'numpy'``. A
    field whose ``'fast'`` kernel cannot be built falls back to ``'interp'`` (same
    values).

**Where is the object?** (:class:`~csdf.Pose`)
    A field with a pose ``p = s R q + t`` is evaluated at world points: its value is
    ``s f(q)``, its gradient ``R grad f(q)``, its parameter derivatives ``s df/dk``,
    its intervals those of the object-frame box around the world box, times ``s``;
    exactness and the Lipschitz bound are unchanged.

Only this module and :mod:`csdf.backends` name evaluator modules; consumers ask a field.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from .backends import BACKENDS, check_mesh_calls, select
from .backends import fast as _fast_backend
from .backends.cexport import to_c, to_numpy
from .backends.glsl import albedo_functions, glsl_float, glsl_params, shadertoy, to_glsl
from .backends.interval_eval import evaluate_intervals
from .cache import memo
from .compiler.program import Program, as_program
from .errors import CsdfError, interrupt_in
from .interval import check_boxes
from .pose import as_pose

__all__ = [
    "Field", "as_field", "field_bounds", "planar_bounds", "auto_bounds", "choose_backend",
    "check_bounds", "params_in_ranges", "AUTO_FAST_POINTS", "to_glsl", "shadertoy", "glsl_params",
    "to_c", "to_numpy",
    "glsl_float", "albedo_functions", "numba_available", "kernel_cache_dir",
    "evaluate_intervals", "step_evaluator",
]

#: point sets at least this large get the compiled backend under ``'auto'``
AUTO_FAST_POINTS = 2000
#: programs longer than this are not compiled into per-program kernels under ``'auto'``
#: (the compile time grows with the length: ~4-8 s at 1,000-2,000 instructions on the
#: 2-core machine of ``benchmarks/``); they are interpreted, with pruned tapes
FAST_MAX_INSTRUCTIONS = 1500
#: programs at least this long are evaluated with tapes shortened per spatial cell
#: (:mod:`csdf.backends.pruned`) for values, gradients and intervals
PRUNE_MIN_INSTRUCTIONS = 1500


# ---------------------------------------------------------------------- backend policy
def numba_available() -> bool:
    """True when the compiled (Numba) evaluators can run on this machine."""
    return bool(_fast_backend.available())


def kernel_cache_dir() -> Path:
    """Where the compiled evaluator caches its kernels on disk (``$CSDF_CACHE_DIR``,
    default ``~/.cache/csdf/kernels``; created on demand), for messages such as the
    mesher's "compiling kernels (first use only; cached in ...)"."""
    return _fast_backend.cache_dir()


def choose_backend(backend: str = "auto", work: int | None = None,
                   instructions: int = 0) -> str:
    """The evaluator for a job (see the module docs).

    Args:
        backend: ``'auto'`` or a backend name (:data:`csdf.backends.BACKENDS`).
        work: ``None`` for a sweep (many evaluations of one field, which must agree
            with each other), else the number of points of a point-set job.
        instructions: the program's length; above :data:`FAST_MAX_INSTRUCTIONS`
            ``'auto'`` gives ``'interp'`` (no per-program compilation).

    Returns:
        ``'fast'``, ``'numpy'``, or ``'auto'`` (per-call choice) for small point sets.

    Raises:
        CsdfError: an unknown backend name.
    """
    if backend not in BACKENDS:
        raise CsdfError(f"backend must be one of {', '.join(BACKENDS)}; got {backend!r}")
    if backend != "auto":
        return backend
    if not numba_available():
        return "numpy"
    if instructions > FAST_MAX_INSTRUCTIONS:
        return "interp"
    if work is None or work >= AUTO_FAST_POINTS:
        return "fast"
    return "auto"


# ---------------------------------------------------------------------- bounds policy
def check_bounds(bounds: Any, dim: int = 3, what: str = "bounds") -> np.ndarray:
    """Validate a user's box: ``(2, dim)`` float64, finite, ``min < max``.

    Raises:
        CsdfError: another shape, non-finite values or an empty box.
    """
    names = "((xmin, ymin, zmin), (xmax, ymax, zmax))" if dim == 3 else \
        "((xmin, ymin), (xmax, ymax))"
    try:
        b = np.asarray(bounds, dtype=np.float64).reshape(2, dim)
    except (TypeError, ValueError):
        raise CsdfError(f"{what} must be {names}") from None
    if not np.all(np.isfinite(b)) or np.any(b[1] <= b[0]):
        raise CsdfError(f"{what} must be finite with min < max, got {b.tolist()}")
    return b


def params_in_ranges(prog: Program, params: Mapping[str, float] | None) -> bool:
    """Every given parameter value lies inside its declared range (both ends finite):
    then a program's own box holds for these values (see :mod:`csdf.shapes.base`)."""
    decl = {p.name: p for p in prog.params}
    for name, v in (params or {}).items():
        p = decl.get(name)
        if p is None:
            return False
        lo, hi = float(p.lo), float(p.hi)
        if not (math.isfinite(lo) and math.isfinite(hi) and lo <= float(v) <= hi):
            return False
    return True


def auto_bounds(prog: Program, params: Mapping[str, float] | None = None,
                extent: float = 1e4, rel: float = 1 / 128) -> np.ndarray:
    """Bounding box ``(2, 3)`` of a program's zero set found by interval arithmetic.

    Cubes of ``[-extent, extent]^3`` are split, keeping every cube whose interval may
    contain the surface (``lo <= 0 <= hi``), until the cubes are smaller than ``rel``
    times the box they span; the result is that box, so it contains the whole surface
    (intervals are conservative) and overshoots it by at most about ``rel``.

    Raises:
        CsdfError: nothing found, or the surface reaches the search limit (unbounded
            shapes such as planes need explicit bounds).
    """
    lo = np.full((1, 3), -extent)
    size = 2.0 * extent
    offs = np.array([[i & 1, (i >> 1) & 1, (i >> 2) & 1] for i in range(8)], dtype=float)
    for _ in range(60):
        size /= 2.0
        lo = (lo[:, None, :] + offs[None] * size).reshape(-1, 3)
        flo, fhi = evaluate_intervals(prog, lo, lo + size, params=params)
        lo = lo[(flo <= 0) & (fhi >= 0)]
        if len(lo) == 0:
            raise CsdfError(f"the shape has no surface inside +-{extent:g} (empty shape?)")
        span = (lo + size).max(0) - lo.min(0)
        if size <= rel * span.max() or len(lo) > 100_000:
            break
    b = np.array([lo.min(0), (lo + size).max(0)])
    if np.any(np.abs(b) >= extent * 0.999):
        raise CsdfError(f"the shape looks unbounded (it reaches +-{extent:g}); pass bounds=")
    return b


def _cached_auto_bounds(prog: Program, pv: dict) -> np.ndarray:
    """:func:`auto_bounds` kept on the program per parameter values (a scene makes a new
    field for every pose update of an instance; the box does not move with the pose).
    A copy is returned."""
    key = tuple(np.asarray(prog.param_values(pv, check_ranges=False), dtype=float).tolist())
    return memo(prog, "_auto_bounds", key, lambda: auto_bounds(prog, pv), 16).copy()


def _own_bounds(prog: Program, shape: Any = None) -> np.ndarray | None:
    """The program's (or its shape's) analytic box when finite, else None."""
    b = getattr(prog, "bounds", None)
    if b is None and shape is not None:
        b = getattr(shape, "bounds", None)
    if b is None:
        return None
    b = np.asarray(b, dtype=np.float64)
    # a box is kept as the shape computed it: it may be infinite (unbounded shapes),
    # NaN, or empty (lo > hi: an intersection of disjoint shapes); none of these is one
    if b.ndim != 2 or b.shape[0] != 2 or not np.all(np.isfinite(b)) or np.any(b[1] < b[0]):
        return None
    return b


def field_bounds(prog: Program, params: Mapping[str, float] | None = None, bounds: Any = None,
                 *, shape: Any = None) -> np.ndarray:
    """The object-frame box ``(2, 3)`` holding the surface, by the one bounds policy
    (module docs). ``shape`` supplies the analytic box of programs compiled without
    one.

    A 2D program is evaluated in 3D as its infinite prism, so it has a box only when
    ``bounds`` are given (:func:`planar_bounds` gives its box in the plane).

    Raises:
        CsdfError: bad ``bounds``, or no box could be found (an unbounded shape, or a
            2D program without ``bounds``).
    """
    if bounds is not None:
        return check_bounds(bounds)
    if prog.dim != 3:
        raise CsdfError("a 2D program is an infinite prism in 3D; pass bounds=")
    own = _own_bounds(prog, shape)
    pv = dict(params or {})
    if own is not None and not prog.params:
        return own
    try:
        return _cached_auto_bounds(prog, pv)
    except CsdfError:
        # interval arithmetic can be too loose to find the box (polygons' winding sign,
        # blends); a program's own box holds for every value inside the declared ranges
        if own is None or not params_in_ranges(prog, pv):
            raise
        return own


def planar_bounds(prog: Program, params: Mapping[str, float] | None = None, *,
                  shape: Any = None) -> np.ndarray:
    """The ``(2, 2)`` box in the xy plane of a 2D program's zero set: its own box when
    no parameter values are given or all lie inside their finite ranges.

    Raises:
        CsdfError: a 3D program, or no box is known.
    """
    if prog.dim != 2:
        raise CsdfError("planar_bounds needs a 2D program")
    own = _own_bounds(prog, shape)
    if own is None or not params_in_ranges(prog, params):
        raise CsdfError("the bounds of this 2D program are not known; pass an extent")
    return own


# ---------------------------------------------------------------------- the field
class Field:
    """A signed distance field ready to evaluate: program, parameter values, bounds,
    pose and evaluator (see the module docs for the policies).

    Args:
        model: a :class:`csdf.Shape`, a :class:`csdf.Program` or another Field (whose
            program, and unless given here, parameters, bounds, pose and backend, are
            kept).
        params: ``{name: value}`` parameter values (validated now; others at their
            defaults).
        backend: ``'auto'`` or a backend name (:func:`choose_backend`).
        bounds: ``(2, 3)`` object-frame box holding the surface (default: the bounds
            policy, found when first asked for).
        pose: where the object is in the world (a :class:`csdf.Pose`, a ``(4, 4)``
            similarity matrix, or None for the identity).
        work: the job's size for the ``'auto'`` policy: None for a sweep, else the
            number of points.
        check_ranges: refuse a value of ``params`` outside its parameter's declared
            range (:class:`csdf.ParamError` naming the range); False accepts it (the
            shape's distance contract and own box are then not promised). Only the
            values given here are checked: those of a given Field were accepted when
            it was made.

    Attributes:
        program: the :class:`csdf.Program`; shape: the :class:`csdf.Shape` it was
            compiled from, or None; params: the given values ``{name: value}``;
            pvals: ``(P,)`` float64 all parameter values in program order; pose: the
            :class:`csdf.Pose`; backend: the resolved evaluator name;
            check_ranges: whether this field's given values were range-checked.

    Raises:
        CsdfError: not a shape or program, unknown parameters, a bad pose, backend or
            box; ParamError (a CsdfError): a value outside its range (with
            ``check_ranges``).
    """

    def __init__(self, model: Any, params: Mapping[str, float] | None = None,
                 backend: str = "auto", bounds: Any = None, *, pose: Any = None,
                 work: int | None = None, what: str = "field", check_ranges: bool = True):
        given = dict(params or {})
        if isinstance(model, Field):
            base = model
            self.program, self.shape = base.program, base.shape
            merged = dict(base.params)
            merged.update(given)
            params = merged
            pose = base.pose if pose is None else pose
            if bounds is None and base._bounds_given is not None:
                bounds = base._bounds_given
        else:
            self.program, self.shape = as_program(model, what)
        self.params = dict(params or {})
        self.check_ranges = bool(check_ranges)
        # validates names and values: the ranges of the values given now (a base
        # field's own values were accepted when it was made)
        self.program.param_values(given, check_ranges=self.check_ranges)
        self.pvals = self.program.param_values(self.params, check_ranges=False)
        self.pose = as_pose(pose, "pose")
        if self.program.dim != 3 and not self.pose.is_identity():
            raise CsdfError("a 2D program cannot be posed in 3D; extrude or revolve it")
        self._auto = backend == "auto"
        self.backend = choose_backend(backend, work, len(self.program.code))
        if self.program.data:  # mesh calls: only some evaluators run them
            if self.backend == "auto" or self._auto:
                self.backend = "numpy"
            check_mesh_calls(self.backend, self.program)
        if isinstance(model, Field) and backend == "auto" and work is None and \
                model.backend != "auto":
            # a field made from a field keeps its evaluator (one chosen per call is
            # chosen anew: a sweep needs one evaluator for all its calls)
            self._auto, self.backend = model._auto, model.backend
        self._cells: Any = None  # the CellTapes of pruned evaluation, made on first use
        #: the compiled evaluator's values with no per-call checks, made after the first
        #: call that ran it (its kernel then built): see :meth:`_call`
        self._values_at: Any = None
        self._region: tuple[np.ndarray, int | None] | None = None
        self._bounds_given = None if bounds is None else check_bounds(bounds)
        self._model_bounds: np.ndarray | None = self._bounds_given

    # ------------------------------------------------------------------ metadata
    @property
    def dim(self) -> int:
        """3, or 2 for a planar program (evaluated as its infinite prism)."""
        return self.program.dim

    @property
    def exactness(self) -> str:
        """``'exact' | 'bound' | 'neither'`` (a similarity pose keeps it)."""
        return self.program.exactness

    @property
    def lipschitz(self) -> float:
        """Upper bound of ``|grad f|`` (may be inf; a similarity pose keeps it)."""
        return float(self.program.lipschitz)

    @property
    def param_names(self) -> list[str]:
        return self.program.param_names

    @property
    def model_bounds(self) -> np.ndarray:
        """``(2, 3)`` box of the surface in the object frame (bounds policy; found on
        first use and kept).

        Raises:
            CsdfError: no box can be found (pass ``bounds=``).
        """
        if self._model_bounds is None:
            self._model_bounds = field_bounds(self.program, self.params, shape=self.shape)
        return self._model_bounds

    @property
    def own_bounds(self) -> np.ndarray | None:
        """The program's analytic box (object frame, finite), or None: what the shape
        declares, with no interval search."""
        return _own_bounds(self.program, self.shape)

    @property
    def planar_bounds(self) -> np.ndarray:
        """``(2, 2)`` xy box of a 2D program's zero set (:func:`planar_bounds`)."""
        return planar_bounds(self.program, self.params, shape=self.shape)

    @property
    def bounds(self) -> np.ndarray:
        """``(2, 3)`` box of the surface in the world frame (the object-frame box's
        corners mapped by the pose, when there is one)."""
        b = self.model_bounds
        return b if self.pose.is_identity() else self.pose.apply_box(b)

    @property
    def diagonal(self) -> float:
        """Length of the diagonal of :attr:`bounds` (world units): the field's scale."""
        b = self.bounds
        return float(np.linalg.norm(b[1] - b[0]))

    def replace(self, *, params: Mapping[str, float] | None = None, pose: Any = None,
                bounds: Any = None, backend: str | None = None,
                check_ranges: bool = True) -> Field:
        """A new field with some of its inputs changed (parameters are merged; the
        values given here are range-checked unless ``check_ranges`` is False)."""
        out = Field(self, params, self.backend if backend is None else backend, bounds,
                    pose=pose, check_ranges=check_ranges)
        out._auto = self._auto if backend is None else backend == "auto"
        return out

    def __repr__(self) -> str:
        return (f"<Field {len(self.program)} instructions, params={self.params}, "
                f"backend={self.backend!r}, {self.pose!r}>")

    # ------------------------------------------------------------------ evaluation
    def pruned(self) -> bool:
        """True when this field evaluates values, gradients and intervals with tapes
        shortened per spatial cell (:mod:`csdf.backends.pruned`): programs of at least
        :data:`PRUNE_MIN_INSTRUCTIONS` on the Numba evaluators, with no NaN parameter.
        Values are bit-identical to the ``'interp'`` backend's."""
        return (len(self.program.code) >= PRUNE_MIN_INSTRUCTIONS
                and self.backend in ("interp", "fast") and numba_available()
                and not np.isnan(self.pvals).any())

    def set_region(self, box: Any, depth: int | None = None) -> Field:
        """Where pruned evaluation keeps its cells: the box ``(2, 3)`` (model units)
        cut into ``2**depth`` cells per axis (default: the field's bounds, depth 5);
        a mesher aligns it with its octree. Returns self."""
        self._region = (np.asarray(box, dtype=np.float64).reshape(2, -1), depth)
        self._cells = None
        return self

    def _cell_tapes(self):
        if self._cells is None:
            from .backends.pruned import cell_tapes

            if self._region is not None:
                box, depth = self._region
            else:
                box, depth = self.model_bounds, None
                pad = 0.02 * (box[1] - box[0]) + 1e-9
                box = np.array([box[0] - pad, box[1] + pad])
            self._cells = cell_tapes(self.program, self.pvals, box, depth)
        return self._cells

    def empty_cells(self) -> tuple[np.ndarray, np.ndarray, int, np.ndarray] | None:
        """The cells of pruned evaluation that interval arithmetic has proved empty, for
        consumers that skip space (the sphere tracer): ``(lo (3,), span (3,), n,
        empty (n**3,) uint8)``, an ``n x n x n`` grid of cells over the box ``lo + [0,
        span]`` (model units, the field's frame; the cell ``(i, j, k)`` is entry
        ``(i * n + j) * n + k``; one level finer than the cells of the tapes) with 1
        where the field is positive throughout the cell. The flags are filled in as
        evaluation builds cells (0 means not empty or not yet known) and stay valid
        for this field. None unless this field is
        :meth:`pruned`, 3D and not posed."""
        if not self.pruned() or self.dim != 3 or not self.pose.is_identity():
            return None
        ct = self._cell_tapes()
        empty = ct.track_empty()
        return ct.lo, ct.span, 1 << ct.empty_depth, empty

    def _pruned_points(self, points: Any) -> np.ndarray | None:
        """``(N, 3)`` float64 points for pruned evaluation, or None when it does not
        apply (not pruned, another dtype or shape)."""
        if not self.pruned() or not isinstance(points, np.ndarray) or \
                points.dtype != np.float64 or points.ndim < 1 or points.shape[-1] != 3:
            return None
        return np.ascontiguousarray(points.reshape(-1, 3))

    def _call(self, method: str, p: np.ndarray):
        if (method == "__call__" and self._values_at is not None
                and self.backend == "fast" and type(p) is np.ndarray and p.ndim == 2
                and p.shape[1] == 3 and p.dtype == np.float64 and p.flags.c_contiguous):
            # the values of the compiled evaluator without the checks of a program's
            # call (points, parameter values, backend): the same kernel and numbers; a
            # tracer or search makes thousands of small calls
            return self._values_at(p, self.pvals)["value"]
        q = self._pruned_points(p) if method in ("__call__", "gradient",
                                                 "value_and_grad") else None
        if q is not None:
            shape = p.shape[:-1]
            if method == "__call__":
                return self._cell_tapes().evaluate(q).reshape(shape)
            v, g = self._cell_tapes().evaluate(q, grad=True)
            if method == "gradient":
                return g.reshape(shape + (3,))
            return v.reshape(shape), g.reshape(shape + (3,))
        fn = getattr(self.program, method)
        # the values were checked (or accepted) when the field was made
        try:
            out = fn(p, self.params, backend=self.backend, check_ranges=False)
            if (method == "__call__" and self._values_at is None and self.backend == "fast"
                    and not self.program.data and not self.pruned()):
                self._values_at = _fast_backend.bound_evaluator(self.program, "value")
            return out
        except CsdfError:
            raise
        except Exception as exc:  # a kernel the fast backend cannot build: same values elsewhere
            stop = interrupt_in(exc)
            if stop is not None:  # (a stop request during a kernel's build, not a failure)
                raise stop from None
            if not self._auto or self.backend != "fast":
                raise
            self.backend = "interp"
            return fn(p, self.params, backend=self.backend, check_ranges=False)

    def _local(self, points: Any) -> Any:
        return points if self.pose.is_identity() else self.pose.apply_inverse(points)

    def value(self, points: Any) -> np.ndarray:
        """Signed distances ``(...)`` at world points ``(..., 3)`` (see
        :meth:`csdf.Program.__call__` for dtypes and NaN)."""
        v = self._call("__call__", self._local(points))
        return v if self.pose.is_identity() else v * self.pose.scale

    __call__ = value

    def gradient(self, points: Any) -> np.ndarray:
        """Exact spatial gradients ``(..., 3)`` at world points."""
        g = self._call("gradient", self._local(points))
        return g if self.pose.is_identity() else self.pose.apply_dirs(g)

    def value_and_grad(self, points: Any) -> tuple[np.ndarray, np.ndarray]:
        """``(values (...), gradients (..., 3))`` in one pass."""
        v, g = self._call("value_and_grad", self._local(points))
        if self.pose.is_identity():
            return v, g
        return v * self.pose.scale, self.pose.apply_dirs(g)

    def param_jacobian(self, points: Any) -> np.ndarray:
        """Derivatives by every parameter ``(..., P)`` (program order)."""
        J = self._call("param_jacobian", self._local(points))
        return J if self.pose.is_identity() else J * self.pose.scale

    def value_grad_param_jacobian(self, points: Any):
        """``(values, gradients (..., 3), parameter Jacobian (..., P))`` in one pass."""
        v, g, J = self._call("value_grad_param_jacobian", self._local(points))
        if self.pose.is_identity():
            return v, g, J
        s = self.pose.scale
        return v * s, self.pose.apply_dirs(g), J * s

    def contains(self, points: Any) -> np.ndarray:
        """Boolean ``(...)``: True where the distance is ``<= 0`` (NaN gives False)."""
        v = self.value(points)
        with np.errstate(invalid="ignore"):
            return v <= 0

    def intervals(self, lo: Any, hi: Any,
                  param_intervals: Mapping[str, tuple[float, float]] | None = None
                  ) -> tuple[np.ndarray, np.ndarray]:
        """Conservative bounds ``(flo (M,), fhi (M,))`` of the field over world boxes
        ``[lo, hi]`` (each ``(M, 3)``; see
        :func:`csdf.backends.interval_eval.evaluate_intervals`); with a pose, over the
        object-frame box around each world box, times the scale."""
        if self.pose.is_identity():
            if param_intervals is None and self.pruned():
                blo, bhi = check_boxes(self.program.dim, lo, hi)
                if not (np.isnan(blo).any() or np.isnan(bhi).any()):
                    return self._cell_tapes().intervals(blo, bhi)
            return evaluate_intervals(self.program, lo, hi, params=self.params,
                                      param_intervals=param_intervals)
        blo = np.asarray(lo, dtype=np.float64)
        bhi = np.asarray(hi, dtype=np.float64)
        if blo.ndim != 2 or blo.shape[1] != 3 or blo.shape != bhi.shape:
            raise CsdfError(f"box lo and hi must both have shape (M, 3); got {blo.shape} "
                            f"and {bhi.shape}")
        sel = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
        corners = np.where(sel[None, :, :] == 0, blo[:, None, :], bhi[:, None, :])
        q = self.pose.apply_inverse(corners)  # (M, 8, 3)
        flo, fhi = evaluate_intervals(self.program, q.min(axis=1), q.max(axis=1),
                                      params=self.params, param_intervals=param_intervals)
        s = self.pose.scale
        return flo * s, fhi * s

    def serial_values(self) -> Callable[..., np.ndarray] | None:
        """A single-threaded value evaluator with no per-call setup,
        ``f(pts (M, 3) float64 C-contiguous, out=None) -> (M,)``, for callers that run
        many small evaluations on threads of their own (the streaming mesher); None
        when this field's evaluator has none (only ``'fast'`` has) or it has a pose."""
        if self.backend != "fast" or not self.pose.is_identity():
            return None
        return _fast_backend.serial_values(self.program, self.pvals)

    def kernels_ready(self, modes: tuple[str, ...] = ("value",)) -> bool:
        """False when this field's evaluator is the compiled one and the kernel of one
        of ``modes`` (``'value'``, ``'grad'``, ``'jac'``, ``'all'``) is neither in memory
        nor cached on disk (:func:`kernel_cache_dir`): its first evaluation in that
        mode then compiles it (seconds to a minute, once per machine). True otherwise,
        and for every other evaluator (nothing to compile)."""
        if self.backend != "fast":
            return True
        return all(_fast_backend.is_ready(self.program, m) for m in modes)

    def raster(self, xs: np.ndarray, ys: np.ndarray, values: bool = False,
               leaf: int = 16) -> np.ndarray | None:
        """A 2D field's image at pixel centres ``xs`` (``(W,)``) by ``ys`` (``(H,)``,
        decreasing) by the compiled quadtree of shortened tapes
        (:func:`csdf.backends.pruned.raster_image`): ``(H, W)`` float64 values, or
        bool ``value < 0``; bit-identical to the ``'interp'`` backend. None where Numba
        is missing, a parameter is NaN or the program has mesh calls."""
        if not numba_available() or np.isnan(self.pvals).any() or self.program.data:
            return None
        from .backends.pruned import raster_image

        return raster_image(self.program, self.pvals, xs, ys, values, leaf)[0]

    def glsl(self, name: str = "sdf", gradient: bool = True) -> str:
        """This field's program as GLSL (:func:`csdf.to_glsl`; parameters as
        uniforms, no pose)."""
        return to_glsl(self.program, name=name, gradient=gradient)


def step_evaluator(program: Program, backend: str, mode: str
                   ) -> Callable[[np.ndarray, np.ndarray], dict[str, np.ndarray]]:
    """``f(pts, pvals) -> {'value': (N,), 'grad': (N, 3), 'jac': (N, P)}`` (the keys of
    ``mode``, as :meth:`csdf.Program.value_grad_param_jacobian` and its kin give them) for
    a solver that evaluates one program many times: ``pts`` (N, 3) float64 C-contiguous
    model-frame points, ``pvals`` (P,) float64 every parameter's value, ranges not
    checked. The same numbers as the program's own methods with ``backend``, without
    their per-call checks; the compiled evaluator's kernel is looked up once."""
    if backend == "fast" and not program.data:
        return _fast_backend.bound_evaluator(program, mode)

    def f(pts: np.ndarray, pvals: np.ndarray) -> dict[str, np.ndarray]:
        return select(backend, pts.shape[0], program, mode).evaluate(program, pts, pvals,
                                                                     mode)

    return f


def as_field(model: Any, params: Mapping[str, float] | None = None, pose: Any = None, *,
             bounds: Any = None, backend: str = "auto", work: int | None = None,
             what: str | None = None, check_ranges: bool = True) -> Field:
    """The :class:`Field` of a shape, program or field (a field given with nothing to
    change is returned as is).

    Args:
        model: a :class:`csdf.Shape`, :class:`csdf.Program` or :class:`Field`.
        params, pose, bounds, backend, work, check_ranges: as for :class:`Field` (only
            the values given here are range-checked).
        what: the caller's name for error messages (``"mesh expects a Shape or
            Program, got int"``).

    Raises:
        CsdfError: as for :class:`Field`.
    """
    if isinstance(model, Field):
        if not params and pose is None and bounds is None and backend == "auto":
            return model
        return model.replace(params=params, pose=pose, bounds=bounds,
                             backend=None if backend == "auto" else backend,
                             check_ranges=check_ranges)
    return Field(model, params, backend, bounds, pose=pose, work=work,
                 what="field" if what is None else what, check_ranges=check_ranges)
