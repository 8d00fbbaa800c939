"""Reading and writing files. Every writer is atomic (:func:`atomic_path`): it writes a
temporary file in the destination folder and renames it over the target, so a failure
never leaves a half-written file behind.

Modules: ``atomic`` (the temporary-file-and-rename helper), ``mesh`` (triangle meshes:
STL, OBJ, PLY, GLB), ``points`` (point clouds as PLY files), ``vm`` (fields in Fidget's
``.vm`` text format, read and written), ``bop`` (depth sequences in the BOP scene
layout, written and read); OpenSCAD's ``.csg`` and ``.scad`` are read by
:mod:`csdf.lang.csg` (``load_csg``, ``loads_csg``, ``load_scad`` here too).
"""

from ..lang.csg import load_csg, load_scad, loads_csg
from .atomic import atomic_path, check_writable
from .bop import DepthClipWarning, read_bop, read_frames, write_bop
from .mesh import MESH_FORMATS, write_mesh
from .points import PointCloud, read_point_cloud, read_point_properties, read_points, write_points
from .vm import dumps_vm, load_vm, loads_vm, save_vm

__all__ = ["atomic_path", "check_writable", "write_mesh", "MESH_FORMATS", "read_points",
           "write_points",
           "read_point_properties", "read_point_cloud", "PointCloud", "load_vm", "loads_vm",
           "save_vm", "dumps_vm", "write_bop", "read_bop", "read_frames", "DepthClipWarning",
           "load_csg", "loads_csg", "load_scad"]
