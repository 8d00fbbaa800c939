"""``csdf.mesh``: a watertight triangle mesh of a shape's zero set."""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from ..errors import CsdfError
from .extract import Grid, extract

__all__ = ["mesh", "auto_bounds", "MAX_RESOLUTION", "MAX_VOXELS"]

MAX_RESOLUTION = 4096
_JITTER = np.array([0.3819660112501051, 0.2360679774997897, 0.1458980337503155])  # golden
MAX_VOXELS = 4096**3


def _program(shape):
    """``(Program, Shape or None)``; a 2D Shape is refused (a 2D Program, an infinite
    prism, can still be meshed inside given bounds)."""
    from ..compiler.program import as_program

    prog, shp = as_program(shape, "mesh")
    if shp is not None and shp.dim != 3:
        raise CsdfError("mesh needs a 3D shape; extrude or revolve a 2D shape first")
    return prog, shp


def auto_bounds(prog, params: dict | None = None, extent: float = 1e4, rel: float = 1 / 128):
    """Bounding box ``(2, 3)`` of a program's zero set found by interval arithmetic.

    Cubes of ``[-extent, extent]^3`` are split, keeping every cube whose interval may
    contain the surface (``lo <= 0 <= hi``), until the cubes are smaller than ``rel``
    times the box they span; the result is that box, so it contains the whole surface
    (intervals are conservative) and overshoots it by at most about ``rel``.

    Raises:
        CsdfError: nothing found, or the surface reaches the search limit (unbounded
            shapes such as planes need explicit bounds).
    """
    from ..backends.interval_eval import evaluate_intervals

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


def mesh(
    shape,
    resolution: int | None = None,
    voxel_size: float | None = None,
    bounds=None,
    method: str = "mc",
    params: dict | None = None,
    progress: bool = True,
):
    """Triangle mesh of the surface ``f = 0``.

    Args:
        shape: a :class:`csdf.Shape` (or a compiled :class:`csdf.Program`).
        resolution: voxels along the longest side of the bounds (default 128).
        voxel_size: voxel edge length in model units (instead of ``resolution``).
        bounds: ``((xmin, ymin, zmin), (xmax, ymax, zmax))``; default: the shape's
            bounding box, else one found by interval arithmetic; padded by 2 voxels.
            Parts outside are clipped (the mesh is closed on the box).
        method: ``'mc'`` marching cubes, or ``'dc'`` dual contouring (keeps sharp edges
            and corners, using exact gradients).
        params: parameter values ``{name: value}``.
        progress: show a progress bar on stderr (Rich).

    Returns:
        ``trimesh.Trimesh``: watertight, 2-manifold, consistently wound (normals point
        outwards), vertices on the zero set to ``1e-6`` voxel (``mc``).

    Raises:
        CsdfError: bad arguments, or a grid over the limits (4096 voxels per side).
    """
    import trimesh

    from ..backends.interval_eval import evaluate_intervals

    prog, shp = _program(shape)
    if method not in ("mc", "dc"):
        raise CsdfError(f"method must be 'mc' or 'dc', got {method!r}")
    if resolution is not None and voxel_size is not None:
        raise CsdfError("give resolution or voxel_size, not both")
    pv = dict(params or {})
    prog.param_values(pv)  # validates names now
    if bounds is None:
        known = shp.bounds if shp is not None and shp.bounds is not None else None
        if known is not None and not np.all(np.isfinite(known)):
            known = None
        b = known if not pv else None
        if b is None:
            try:
                b = auto_bounds(prog, pv)
            except CsdfError:
                # interval arithmetic can be too loose to find the box (polygons' winding
                # sign, blends); a shape's own bounds hold for every parameter value
                # inside the declared ranges, so use them when the given values are
                if known is None or not _in_ranges(prog, pv):
                    raise
                b = known
    else:
        try:
            b = np.asarray(bounds, dtype=np.float64).reshape(2, 3)
        except ValueError:
            raise CsdfError("bounds must be ((xmin, ymin, zmin), (xmax, ymax, zmax))") from None
        if not np.all(np.isfinite(b)) or np.any(b[1] <= b[0]):
            raise CsdfError(f"bounds must be finite with min < max, got {b.tolist()}")
    extent = b[1] - b[0]
    if voxel_size is not None:
        h = float(voxel_size)
        if not (h > 0 and math.isfinite(h)):
            raise CsdfError(f"voxel_size must be a positive number, got {voxel_size}")
    else:
        n = 128 if resolution is None else resolution
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 2:
            raise CsdfError(f"resolution must be an integer >= 2, got {resolution!r}")
        h = float(extent.max()) / int(n)
    # shift the grid by irrational fractions of a voxel, so faces at round coordinates
    # (an axis-aligned box) never lie on sample planes, where the sign test and the
    # gradient are ambiguous
    origin = b[0] - h * (2.0 + _JITTER)
    dims = tuple(int(math.ceil(e / h)) + 5 for e in extent)
    if max(dims) > MAX_RESOLUTION or math.prod(dims) > MAX_VOXELS:
        raise CsdfError(
            f"grid of {dims} voxels is over the limit of {MAX_RESOLUTION} per side; "
            "use a coarser resolution or voxel_size"
        )
    grid = Grid(origin=origin, h=h, dims=dims)

    # one backend for the whole mesh: a sample shared by two bricks must get the same
    # value (and sign) whichever chunk evaluates it; backends differ in the last bits
    from ..backends import fast

    backend = "fast" if fast.available() else "numpy"

    def values(p):
        return prog(p, pv, backend=backend)

    def gradients(p):
        return prog.gradient(p, pv, backend=backend)

    def intervals(lo, hi):
        return evaluate_intervals(prog, lo, hi, params=pv)

    t0 = time.perf_counter()
    reporter = _Progress() if progress else None
    try:
        if backend == "fast":
            # compiled, streamed over the octree's bricks (same results, see stream.py)
            from .stream import extract_dc, extract_mc

            update = reporter.update if reporter else None
            serial = fast.serial_values(prog, prog.param_values(pv))
            if method == "mc":
                verts, faces = extract_mc(grid, values, intervals, update, serial=serial)
            else:
                verts, faces = extract_dc(
                    grid, values, gradients, intervals, update, serial=serial,
                    values_and_gradients=lambda p: prog.value_and_grad(p, pv, backend=backend))
        else:
            verts, faces = extract(grid, values, gradients, intervals, method,
                                   reporter.update if reporter else None)
    finally:
        if reporter:
            reporter.close()
    m = trimesh.Trimesh(vertices=verts, faces=faces, process=False, validate=False)
    m.metadata["csdf"] = {
        "method": method, "voxel_size": h, "dims": dims, "seconds": time.perf_counter() - t0,
    }
    return m


def _in_ranges(prog, pv: dict) -> bool:
    """Every given parameter value lies inside its declared range (both ends finite)."""
    decl = {p.name: p for p in prog.params}
    return all(math.isfinite(decl[k].lo) and math.isfinite(decl[k].hi)
               and decl[k].lo <= float(v) <= decl[k].hi for k, v in pv.items())


class _Progress:
    """A Rich progress bar over the mesher's stages (octree levels, samples, roots)."""

    def __init__(self) -> None:
        from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

        self.bar: Any = Progress(TextColumn("meshing {task.description}"), BarColumn(),
                                 TimeElapsedColumn(), transient=True)
        self.bar.start()
        self.task = self.bar.add_task("octree", total=4)

    def update(self, stage: str, a: int, b: int) -> None:
        # octree: up to 1; samples (a of b bricks, called per chunk): 1 to 3; roots: 4
        done = {"octree": 1.0, "samples": 1.0 + 2.0 * a / max(b, 1)}.get(stage, 4.0)
        label = f"{stage} ({b:,} {'cells' if stage == 'octree' else 'items'})"
        self.bar.update(self.task, description=label, completed=done)

    def close(self) -> None:
        self.bar.stop()
