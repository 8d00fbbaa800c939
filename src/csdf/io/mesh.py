"""Triangle meshes to files: :func:`write_mesh` (STL, OBJ, PLY, GLB by extension),
atomic through :func:`csdf.io.atomic_path`."""

from __future__ import annotations

import os
from pathlib import Path

from ..errors import CsdfError
from .atomic import atomic_path

__all__ = ["write_mesh", "MESH_FORMATS"]

#: file extension -> trimesh export format
MESH_FORMATS = {".stl": "stl", ".obj": "obj", ".ply": "ply", ".glb": "glb"}


def write_mesh(mesh, path: str | os.PathLike) -> Path:
    """Write a ``trimesh.Trimesh`` as binary STL, OBJ, PLY (binary) or GLB, chosen by the
    file extension; atomic.

    Raises:
        CsdfError: unknown extension, or the file cannot be written (naming the path
            and the reason).
    """
    target = Path(path)
    fmt = MESH_FORMATS.get(target.suffix.lower())
    if fmt is None:
        raise CsdfError(
            f"cannot tell the mesh format of {target.name!r}; use one of "
            f"{', '.join(sorted(MESH_FORMATS))}"
        )
    # the bytes first (the long part for a large mesh), so the temporary file exists
    # only while they are written
    if fmt == "glb":
        data = mesh.export(file_type="glb")
    elif fmt == "ply":
        data = mesh.export(file_type="ply", encoding="binary")
    else:
        data = mesh.export(file_type=fmt)
    if isinstance(data, str):
        data = data.encode()
    with atomic_path(target) as tmp:
        tmp.write_bytes(data)
    return target
