"""A mesh file written in blocks, by several processes at once, so that no process holds
the whole mesh: the binary PLY or STL layout of a mesh whose counts are known
(:class:`MeshLayout`: the header and where each vertex and face record goes), the
records of a block of vertices or faces, and the file itself (:func:`mesh_file`: made
beside the target at its full size, filled at offsets by whoever sees it, renamed over
the target when complete).

:func:`csdf.distributed.mesh` uses it with ``out=``: the workers write their parts'
vertices and faces straight into the file (:func:`write_at`), the client only the
header and the vertices that parts share.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import CsdfError
from .atomic import atomic_path

__all__ = ["MeshLayout", "mesh_file", "write_at", "write_whole", "check_stream_path",
           "STREAM_FORMATS"]

#: the formats written in blocks, by file extension
STREAM_FORMATS = (".ply", ".stl")
_PLY_FACE = np.dtype([("n", "u1"), ("v", "<i4", (3,))])
_STL_FACE = np.dtype([("n", "<f4", (3,)), ("v", "<f4", (3, 3)), ("a", "<u2")])


def check_stream_path(path: str | os.PathLike) -> Path:
    """``path`` as a :class:`~pathlib.Path`, checked: a ``.ply`` or ``.stl`` file in a
    folder that exists.

    Raises:
        CsdfError: another extension, or no such folder.
    """
    path = Path(path)
    if path.suffix.lower() not in STREAM_FORMATS:
        raise CsdfError(f"cannot stream a mesh to {path.name!r}: use a .ply or .stl file")
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise CsdfError(f"cannot write {path}: folder {folder} does not exist")
    return path


@dataclass(frozen=True)
class MeshLayout:
    """Where the records of a binary mesh file of ``vertices`` and ``faces`` go.

    PLY (little-endian): the header, the vertices (3 float64, 24 bytes each), the faces
    (a uint8 3 and 3 int32 indices, 13 bytes each). STL: an 80-byte header, the uint32
    face count, and per face its unit normal, its three corners (float32) and a zero
    uint16 (50 bytes); STL has no vertex list.

    Attributes:
        format: ``'.ply'`` or ``'.stl'``; vertices, faces: the counts.
    """

    format: str
    vertices: int
    faces: int

    def header(self) -> bytes:
        """The bytes before the first record."""
        if self.format == ".stl":
            return b"csdf binary STL".ljust(80, b" ") + np.uint32(self.faces).tobytes()
        return ("ply\nformat binary_little_endian 1.0\ncomment csdf\n"
                f"element vertex {self.vertices}\nproperty double x\nproperty double y\n"
                f"property double z\nelement face {self.faces}\n"
                "property list uchar int vertex_indices\nend_header\n").encode("ascii")

    def vertex_offset(self, i: int) -> int:
        """Byte offset of vertex ``i`` (PLY only)."""
        return len(self.header()) + 24 * int(i)

    def face_offset(self, j: int) -> int:
        """Byte offset of face ``j``."""
        if self.format == ".stl":
            return 84 + 50 * int(j)
        return self.vertex_offset(self.vertices) + 13 * int(j)

    def size(self) -> int:
        """The file's size in bytes."""
        return self.face_offset(self.faces)

    @staticmethod
    def vertex_records(verts: np.ndarray) -> np.ndarray:
        """PLY records of vertices ``(n, 3)`` (model units)."""
        return np.ascontiguousarray(verts, dtype="<f8")

    def face_records(self, faces: np.ndarray, verts: np.ndarray | None = None
                     ) -> np.ndarray:
        """Records of faces ``(m, 3)``: PLY, their indices (file vertex numbers); STL,
        their corners ``verts[faces]`` with ``verts (n, 3)`` float64 (model units)."""
        if self.format == ".ply":
            out = np.empty(len(faces), dtype=_PLY_FACE)
            out["n"] = 3
            out["v"] = faces
            return out
        assert verts is not None
        tri = verts[np.asarray(faces)]
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        length = np.linalg.norm(n, axis=1, keepdims=True)
        n = np.divide(n, length, out=np.zeros_like(n), where=length > 0)
        out = np.zeros(len(faces), dtype=_STL_FACE)
        out["n"] = n
        out["v"] = tri
        return out


class _File:
    """The file being written: its temporary path and an open descriptor."""

    def __init__(self, path: Path, fd: int) -> None:
        self.path, self._fd = path, fd

    def write(self, offset: int, data) -> None:
        """Write ``data`` (bytes or a contiguous array) at byte ``offset``."""
        _pwrite_all(self._fd, data, offset)


@contextmanager
def mesh_file(path: str | os.PathLike, layout: MeshLayout) -> Iterator[_File]:
    """The file for ``layout``, made beside ``path`` at its full size with its header
    written; yields an object with ``path`` (where others write too: :func:`write_at`)
    and ``write(offset, data)``. When the block ends without an error, the file is
    renamed over ``path`` (atomic); on an error nothing is left.

    Raises:
        CsdfError: the file cannot be made or written (naming the path and the reason);
            a PLY of 2^31 vertices or more (its indices are int32).
    """
    target = check_stream_path(path)
    if layout.format == ".ply" and layout.vertices >= 2**31:
        raise CsdfError(f"cannot write {target}: {layout.vertices} vertices exceed the PLY "
                        "index type (int32)")
    with atomic_path(target) as tmp:
        fd = os.open(tmp, os.O_RDWR)
        try:
            os.ftruncate(fd, layout.size())
            _pwrite_all(fd, layout.header(), 0)
            yield _File(tmp, fd)
        finally:
            os.close(fd)


def write_whole(path: str | os.PathLike, vertices: np.ndarray, faces: np.ndarray,
                block: int = 1 << 20) -> MeshLayout:
    """A mesh held in memory, ``vertices (V, 3)`` float64 (model units) and ``faces (F,
    3)``, written to ``path`` in the same layout as the blocks of a mesh made in parts
    (PLY: float64 vertices, so that it reads back bit for bit; ``csdf.io.write_mesh``
    writes float32 ones through trimesh), ``block`` faces at a time. Returns the
    layout."""
    path = check_stream_path(path)
    verts = np.asarray(vertices, dtype=np.float64)
    layout = MeshLayout(path.suffix.lower(), len(verts), len(faces))
    with mesh_file(path, layout) as fh:
        if layout.format == ".ply":
            fh.write(layout.vertex_offset(0), layout.vertex_records(verts))
        for s in range(0, len(faces), block):
            fh.write(layout.face_offset(s), layout.face_records(faces[s:s + block], verts))
    return layout


def write_at(path: str | os.PathLike, blocks: list[tuple[int, np.ndarray]]) -> bool:
    """Write ``blocks`` (``(byte offset, records)``) into the file ``path`` that
    :func:`mesh_file` made; False (and nothing written) when this process does not see
    that file (another machine without the shared folder)."""
    try:
        fd = os.open(path, os.O_WRONLY)
    except FileNotFoundError:
        return False
    try:
        for offset, data in blocks:
            _pwrite_all(fd, data, offset)
    finally:
        os.close(fd)
    return True


def _pwrite_all(fd: int, data, offset: int) -> None:
    """``os.pwrite`` until all of ``data`` is written."""
    if isinstance(data, np.ndarray):
        data = np.ascontiguousarray(data).reshape(-1).view(np.uint8)
    view = memoryview(data)
    while len(view):
        n = os.pwrite(fd, view, offset)
        view, offset = view[n:], offset + n
