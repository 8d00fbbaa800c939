"""Meshing: sparse octree evaluation with interval arithmetic, marching cubes and manifold
dual contouring, on a case table derived in ``cases.py``.

Modules: ``api`` (:func:`mesh`), ``grid`` (the voxel grid and its octree), ``stream``
with ``kernels`` and ``dc_kernels`` (the compiled streaming mesher), ``dual`` (the
dual-contouring steps both meshers share), ``reference`` (the NumPy mesher: the oracle
the compiled one is tested against, and the fallback without a compiled evaluator)."""

from .api import MAX_RESOLUTION, auto_bounds, mesh

__all__ = ["mesh", "auto_bounds", "MAX_RESOLUTION"]
