"""Reading and writing files. Every writer is atomic: it writes a temporary file in the
destination folder and renames it over the target, so a failure never leaves a
half-written file behind."""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from .errors import CsdfError

__all__ = ["atomic_path", "write_mesh", "MESH_FORMATS", "read_points", "write_points",
           "read_point_properties"]

MESH_FORMATS = {".stl": "stl", ".obj": "obj", ".ply": "ply", ".glb": "glb"}


@contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; on success it replaces ``path``.

    Raises:
        CsdfError: the folder does not exist or is not writable.
    """
    target = Path(path)
    folder = target.parent if str(target.parent) else Path(".")
    if not folder.is_dir():
        raise CsdfError(f"cannot write {target}: folder {folder} does not exist")
    fd, tmp = tempfile.mkstemp(dir=folder, prefix=f".{target.name}.", suffix=".tmp")
    os.close(fd)
    umask = os.umask(0)  # mkstemp makes 0600 files: give the usual permissions instead
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        os.replace(tmp_path, target)
    except BaseException:
        tmp_path.unlink(missing_ok=True)
        raise


def write_mesh(mesh, path: str | os.PathLike) -> Path:
    """Write a ``trimesh.Trimesh`` as binary STL, OBJ, PLY (binary) or GLB, chosen by the
    file extension; atomic.

    Raises:
        CsdfError: unknown extension or unwritable folder.
    """
    target = Path(path)
    fmt = MESH_FORMATS.get(target.suffix.lower())
    if fmt is None:
        raise CsdfError(
            f"cannot tell the mesh format of {target.name!r}; use one of "
            f"{', '.join(sorted(MESH_FORMATS))}"
        )
    with atomic_path(target) as tmp:
        if fmt == "glb":
            data = mesh.export(file_type="glb")
        elif fmt == "ply":
            data = mesh.export(file_type="ply", encoding="binary")
        else:
            data = mesh.export(file_type=fmt)
        if isinstance(data, str):
            data = data.encode()
        tmp.write_bytes(data)
    return target


from .pointio import read_point_properties, read_points, write_points  # noqa: E402
