"""A mesh written to disk in parts, so that no machine holds it whole:
:class:`MeshStreamWriter` takes the parts of :mod:`csdf.mesh.parts` one at a time and
writes a binary PLY or STL.

Each part's own vertices (those off the faces between super-bricks) go straight to a
temporary file, numbered as they come; its faces go to another, with each shared vertex
(on a face between parts, which a neighbour holds too) as a placeholder. Only the
shared vertices stay in memory (a few per cent of a large mesh: the surface's traces on
the super-bricks' faces). At the end the shared vertices are merged by grid edge and
numbered after the others, the placeholders are replaced in one pass over the faces,
and the file is assembled next to the target and renamed over it (atomic, like every
csdf writer: :func:`csdf.io.atomic_path`).
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

import numpy as np

from ..errors import CsdfError
from ..mesh.parts import Part, Stitcher
from .atomic import atomic_path

__all__ = ["MeshStreamWriter", "STREAM_FORMATS"]

#: the formats the writer streams, by file extension
STREAM_FORMATS = (".ply", ".stl")
_BLOCK = 1 << 20  # faces per block in the final pass


class MeshStreamWriter:
    """Write a mesh that arrives in parts to a binary PLY or STL file.

    Use as a context manager: ``with MeshStreamWriter(path) as w: w.add(part)``; the
    file appears (atomically) when the block ends without an error; on an error nothing
    is left behind. ``vertices``/``faces`` then hold the counts written.

    Args:
        path: the target, ``.ply`` (float64 vertices, int32 indices) or ``.stl``
            (float32, as the format has it).

    Raises:
        CsdfError: another extension, or a file that cannot be written.
    """

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = Path(path)
        self.format = self.path.suffix.lower()
        if self.format not in STREAM_FORMATS:
            raise CsdfError(f"cannot stream a mesh to {self.path.name!r}: use a .ply or "
                            ".stl file")
        folder = self.path.parent if str(self.path.parent) else Path(".")
        if not folder.is_dir():
            raise CsdfError(f"cannot write {self.path}: folder {folder} does not exist")
        self.vertices = 0
        self.faces = 0
        self._dir: tempfile.TemporaryDirectory | None = None
        self._folder = folder

    def __enter__(self) -> MeshStreamWriter:
        try:
            self._dir = tempfile.TemporaryDirectory(dir=self._folder,
                                                    prefix=f".{self.path.name}.")
        except OSError as exc:
            raise CsdfError(f"cannot write {self.path}: {exc.strerror or exc}") from None
        tmp = Path(self._dir.name)
        self._vfile = open(tmp / "vertices", "wb")  # noqa: SIM115 (closed in __exit__)
        self._ffile = open(tmp / "faces", "wb")  # noqa: SIM115
        self._st = Stitcher(  # (tofile: no copy of the block as bytes)
            lambda v: np.ascontiguousarray(v, dtype="<f8").tofile(self._vfile),
            lambda f: np.ascontiguousarray(f, dtype="<i8").tofile(self._ffile))
        return self

    def add(self, part: Part) -> None:
        """Append one :class:`csdf.mesh.parts.Part`."""
        self._st.add(part)

    def __exit__(self, kind, exc, tb) -> None:
        try:
            self._vfile.close()
            self._ffile.close()
            if kind is None:
                self._finish()
        finally:
            assert self._dir is not None
            self._dir.cleanup()

    def _finish(self) -> None:
        """Merge the shared vertices, replace the placeholders, assemble the file."""
        st = self._st
        shared_verts, shared_ids = st.shared()
        self.vertices, self.faces = st.own + len(shared_verts), st.faces
        if self.format == ".ply" and self.vertices >= 2**31:
            raise CsdfError(f"cannot write {self.path}: {self.vertices} vertices exceed "
                            "the PLY index type (int32)")
        tmp = Path(self._dir.name)  # type: ignore[union-attr]
        faces = _Blocks(tmp / "faces", self.faces)
        with atomic_path(self.path) as out, open(out, "wb") as fh:
            if self.format == ".ply":
                self._ply(fh, tmp / "vertices", shared_verts, faces, shared_ids)
            else:
                self._stl(fh, tmp / "vertices", shared_verts, faces, shared_ids)

    def _ply(self, fh, vpath: Path, shared_verts: np.ndarray, faces: _Blocks,
             shared_ids: np.ndarray) -> None:
        header = ("ply\nformat binary_little_endian 1.0\ncomment csdf\n"
                  f"element vertex {self.vertices}\nproperty double x\nproperty double y\n"
                  f"property double z\nelement face {self.faces}\n"
                  "property list uchar int vertex_indices\nend_header\n")
        fh.write(header.encode("ascii"))
        with open(vpath, "rb") as src:
            shutil.copyfileobj(src, fh, 1 << 24)
        fh.write(np.ascontiguousarray(shared_verts, dtype="<f8").tobytes())
        rec = np.dtype([("n", "u1"), ("v", "<i4", (3,))])
        for block in faces:
            block = Stitcher.resolve(block, shared_ids)
            out = np.empty(len(block), dtype=rec)
            out["n"] = 3
            out["v"] = block
            fh.write(out.tobytes())

    def _stl(self, fh, vpath: Path, shared_verts: np.ndarray, faces: _Blocks,
             shared_ids: np.ndarray) -> None:
        fh.write(b"csdf binary STL".ljust(80, b" "))
        fh.write(np.uint32(self.faces).tobytes())
        n_own = self._st.own
        own = np.memmap(vpath, dtype="<f8", mode="r", shape=(n_own, 3)) \
            if n_own else np.zeros((0, 3))
        rec = np.dtype([("n", "<f4", (3,)), ("v", "<f4", (3, 3)), ("a", "<u2")])
        for block in faces:
            block = Stitcher.resolve(block, shared_ids)
            tri = np.empty(block.shape + (3,))
            is_own = block < n_own
            tri[is_own] = own[block[is_own]]
            tri[~is_own] = shared_verts[block[~is_own] - n_own]
            n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
            length = np.linalg.norm(n, axis=1, keepdims=True)
            n = np.divide(n, length, out=np.zeros_like(n), where=length > 0)
            out = np.zeros(len(block), dtype=rec)
            out["n"] = n
            out["v"] = tri
            fh.write(out.tobytes())
        del own


class _Blocks:
    """The faces file ``(F, 3)`` int64 read block by block (read, not mapped, so the
    pages do not stay in this process's memory)."""

    def __init__(self, path: Path, n: int) -> None:
        self.path, self.n = path, n

    def __iter__(self):
        if not self.n:
            return
        with open(self.path, "rb") as fh:
            for s in range(0, self.n, _BLOCK):
                k = min(_BLOCK, self.n - s)
                yield np.fromfile(fh, dtype="<i8", count=3 * k).reshape(k, 3)
