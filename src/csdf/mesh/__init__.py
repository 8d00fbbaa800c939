"""Meshing: sparse octree evaluation with interval arithmetic, marching cubes and manifold
dual contouring (``extract.py``), on a case table derived in ``cases.py``."""

from .api import MAX_RESOLUTION, auto_bounds, mesh

__all__ = ["mesh", "auto_bounds", "MAX_RESOLUTION"]
