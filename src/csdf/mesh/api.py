"""``csdf.mesh``: a watertight triangle mesh of a shape's zero set."""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from ..errors import CsdfError
from ..field import Field, as_field, auto_bounds, check_bounds
from .grid import Grid
from .reference import extract

__all__ = ["mesh", "auto_bounds", "MAX_RESOLUTION", "MAX_VOXELS"]

MAX_RESOLUTION = 4096
_JITTER = np.array([0.3819660112501051, 0.2360679774997897, 0.1458980337503155])  # golden
MAX_VOXELS = 4096**3


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

    if method not in ("mc", "dc"):
        raise CsdfError(f"method must be 'mc' or 'dc', got {method!r}")
    if resolution is not None and voxel_size is not None:
        raise CsdfError("give resolution or voxel_size, not both")
    # a sweep (csdf.field): one evaluator for the whole mesh, since a sample shared by
    # two bricks must get the same value (and sign) whichever chunk evaluates it
    fld = as_field(shape, params, what="mesh")
    if fld.shape is not None and fld.shape.dim != 3:
        raise CsdfError("mesh needs a 3D shape; extrude or revolve a 2D shape first")
    if bounds is not None:
        fld = Field(fld, bounds=check_bounds(bounds))
    b = fld.bounds
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

    def values(p):
        return fld.value(p)

    def gradients(p):
        return fld.gradient(p)

    def intervals(lo, hi):
        return fld.intervals(lo, hi)

    t0 = time.perf_counter()
    reporter = _Progress() if progress else None
    try:
        serial = fld.serial_values()
        if serial is not None:
            # compiled, streamed over the octree's bricks (same results, see stream.py)
            from .stream import extract_dc, extract_mc

            update = reporter.update if reporter else None
            if method == "mc":
                verts, faces = extract_mc(grid, values, intervals, update, serial=serial)
            else:
                verts, faces = extract_dc(
                    grid, values, gradients, intervals, update, serial=serial,
                    values_and_gradients=fld.value_and_grad)
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
