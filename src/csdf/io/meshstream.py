"""A mesh written in blocks, by several processes at once, so that no process holds the
whole mesh or copies another's part: the binary PLY or STL layout of a mesh whose counts
are known (:class:`MeshLayout`: the header and where each vertex and face record goes),
the records of a block of vertices or faces, and the file itself (:func:`mesh_file`:
made beside the target at its full size, filled at offsets by whoever sees it, renamed
over the target when complete).

The same for a mesh in memory (:func:`shared_block`, layout ``'array'``: the vertex
array ``(V, 3)`` float64 then the face array ``(F, 3)`` int64, in a file of a shared
memory folder that the processes of one machine map, and the caller keeps as arrays).

:func:`csdf.distributed.mesh` uses them: the workers write their parts' vertices and
faces straight into the file or the block (:func:`write_at`, :func:`map_block`), the
client only the header and the vertices that parts share.
"""

from __future__ import annotations

import mmap
import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import CsdfError
from .atomic import atomic_path

__all__ = ["MeshLayout", "mesh_file", "write_at", "write_whole", "check_stream_path",
           "shared_block", "map_block", "STREAM_FORMATS", "ARRAYS"]

#: the formats written in blocks, by file extension
STREAM_FORMATS = (".ply", ".stl")
#: the layout of a mesh in memory: the vertex array (V, 3) float64, then the face array
#: (F, 3) int64 (what trimesh keeps)
ARRAYS = "array"
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
    uint16 (50 bytes); STL has no vertex list. :data:`ARRAYS`: no header, the vertices
    (3 float64), the faces (3 int64, 24 bytes), native byte order.

    Attributes:
        format: ``'.ply'``, ``'.stl'`` or :data:`ARRAYS`; vertices, faces: the counts.
    """

    format: str
    vertices: int
    faces: int

    def header(self) -> bytes:
        """The bytes before the first record."""
        if self.format == ARRAYS:
            return b""
        if self.format == ".stl":
            return b"csdf binary STL".ljust(80, b" ") + np.uint32(self.faces).tobytes()
        return ("ply\nformat binary_little_endian 1.0\ncomment csdf\n"
                f"element vertex {self.vertices}\nproperty double x\nproperty double y\n"
                f"property double z\nelement face {self.faces}\n"
                "property list uchar int vertex_indices\nend_header\n").encode("ascii")

    def vertex_offset(self, i: int) -> int:
        """Byte offset of vertex ``i`` (not STL)."""
        return len(self.header()) + 24 * int(i)

    def face_offset(self, j: int) -> int:
        """Byte offset of face ``j``."""
        if self.format == ".stl":
            return 84 + 50 * int(j)
        return self.vertex_offset(self.vertices) + (24 if self.format == ARRAYS else 13) * int(j)

    def size(self) -> int:
        """The file's size in bytes."""
        return self.face_offset(self.faces)

    @staticmethod
    def vertex_records(verts: np.ndarray) -> np.ndarray:
        """PLY records of vertices ``(n, 3)`` (model units)."""
        return np.ascontiguousarray(verts, dtype="<f8")

    def face_records(self, faces: np.ndarray, verts: np.ndarray | None = None
                     ) -> np.ndarray:
        """Records of faces ``(m, 3)``: PLY and :data:`ARRAYS`, their indices (file vertex
        numbers); STL, their corners ``verts[faces]`` with ``verts (n, 3)`` float64
        (model units)."""
        if self.format == ARRAYS:
            return np.ascontiguousarray(faces, dtype=np.int64)
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


class _Block:
    """A mesh in a shared memory block: its file (while it is written), the map."""

    def __init__(self, path: Path | None, m: mmap.mmap | None, layout: MeshLayout) -> None:
        self.path, self._map, self.layout = path, m, layout

    def write(self, offset: int, data) -> None:
        """Write ``data`` (bytes or a contiguous array) at byte ``offset``."""
        view = _bytes(data)
        self._map[offset:offset + len(view)] = view

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """``(vertices (V, 3) float64, faces (F, 3) int64)``, views of the block."""
        lay = self.layout
        if self._map is None:
            return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
        verts = np.frombuffer(self._map, dtype=np.float64, count=3 * lay.vertices)
        faces = np.frombuffer(self._map, dtype=np.int64, count=3 * lay.faces,
                              offset=lay.face_offset(0))
        return verts.reshape(-1, 3), faces.reshape(-1, 3)


@contextmanager
def shared_block(layout: MeshLayout, folder: str | os.PathLike | None) -> Iterator[_Block]:
    """A block for a mesh of ``layout`` (format :data:`ARRAYS`) in memory: a file in
    ``folder`` (a shared memory folder such as ``/dev/shm``: other processes of this
    machine map it, :func:`map_block`), or private memory when ``folder`` is None (then
    only this process writes it). Yields an object with ``path`` (None without a
    folder), ``write(offset, data)`` and ``arrays()``; the file is removed when the
    block ends (the arrays stay valid: they map its memory)."""
    size = layout.size()
    if size == 0:
        yield _Block(None, None, layout)
        return
    if folder is None:
        yield _Block(None, mmap.mmap(-1, size, flags=mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS),
                     layout)
        return
    fd, name = tempfile.mkstemp(dir=folder, prefix="csdf-mesh-", suffix=".block")
    try:
        os.ftruncate(fd, size)
        yield _Block(Path(name), mmap.mmap(fd, size, flags=mmap.MAP_SHARED), layout)
    finally:
        os.close(fd)
        os.unlink(name)


def map_block(path: str | os.PathLike) -> mmap.mmap | None:
    """The block ``path`` of :func:`shared_block` mapped for writing, or None when this
    process does not see it (another machine)."""
    try:
        fd = os.open(path, os.O_RDWR)
    except FileNotFoundError:
        return None
    try:
        return mmap.mmap(fd, 0, flags=mmap.MAP_SHARED)
    finally:
        os.close(fd)


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


def _bytes(data) -> memoryview:
    """``data`` (bytes or an array) as a flat byte view."""
    if isinstance(data, np.ndarray):
        data = np.ascontiguousarray(data).reshape(-1).view(np.uint8)
    return memoryview(data)


def _pwrite_all(fd: int, data, offset: int) -> None:
    """``os.pwrite`` until all of ``data`` is written."""
    view = _bytes(data)
    while len(view):
        n = os.pwrite(fd, view, offset)
        view, offset = view[n:], offset + n
