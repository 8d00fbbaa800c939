"""What runs on the workers of :mod:`csdf.distributed`: each task gets the program's bytes
(:meth:`csdf.Program.to_bytes`, a few KB) and its parameter values, not a pickled shape.

A worker keeps the fields it has made (a few, most recently used first), keyed by the
program's bytes, values, bounds and grid: the tasks of one job that land on a worker
share one field, so its compiled kernels are loaded (from the on-disk kernel cache,
:func:`csdf.field.kernel_cache_dir`, or compiled once per machine) once per worker
process, not once per task (the Numba-through-Dask recompilation of datashader #684
and numba #3026). :func:`worker_stats` counts fields made and tasks run, so the tests
can hold this to account.
"""

from __future__ import annotations

import gc
import hashlib
import mmap
import threading
from collections import OrderedDict
from pathlib import Path
from typing import Any

import numpy as np

from ..compiler.program import Program
from ..field import Field, as_field
from ..io.meshstream import ARRAYS, MeshLayout, map_block, write_at
from ..mesh.api import prepare_field
from ..mesh.grid import Grid
from ..mesh.part_kernels import file_part
from ..mesh.parts import Part, PartTask, mesh_part

__all__ = ["worker_field", "worker_stats", "mesh_task", "part_summary", "write_part",
           "eval_block", "sample_task", "fit_task", "FIELDS_KEPT"]

#: fields a worker keeps between tasks
FIELDS_KEPT = 8
_FIELDS: OrderedDict[tuple, Field] = OrderedDict()
_STATS = {"fields_made": 0, "tasks": 0}
_LOCK = threading.Lock()


def _grid_key(grid: tuple | None) -> tuple:
    if grid is None:
        return ()
    origin, h, dims = grid
    return (tuple(float(v) for v in origin), float(h), tuple(int(d) for d in dims))


def worker_field(blob: bytes, params: dict[str, float], bounds: Any = None,
                 grid: tuple | None = None, backend: str = "auto",
                 pose: Any = None) -> Field:
    """This worker's field of the program ``blob`` at ``params`` (made on first use,
    then kept): with ``bounds (2, 3)`` (no bounds search), ``grid = (origin (3,), h,
    dims)`` (prepared to mesh it), ``backend`` and ``pose`` (a ``(4, 4)`` matrix)."""
    key = (hashlib.blake2b(blob, digest_size=16).digest(),
           tuple(sorted((k, float(v)) for k, v in params.items())),
           None if bounds is None else np.asarray(bounds, dtype=np.float64).tobytes(),
           _grid_key(grid), backend,
           None if pose is None else np.asarray(pose, dtype=np.float64).tobytes())
    with _LOCK:
        _STATS["tasks"] += 1
        fld = _FIELDS.get(key)
        if fld is not None:
            _FIELDS.move_to_end(key)
            return fld
        fld = as_field(Program.from_bytes(blob), params, pose=pose, bounds=bounds,
                       backend=backend, check_ranges=False)  # (checked by the client)
        if grid is not None:
            prepare_field(fld, _grid(grid))
        _FIELDS[key] = fld
        _STATS["fields_made"] += 1
        while len(_FIELDS) > FIELDS_KEPT:
            _FIELDS.popitem(last=False)
        return fld


def worker_stats() -> dict[str, int]:
    """``{'fields_made': ..., 'tasks': ...}`` of this process (run it on every worker
    with ``client.run(worker_stats)``)."""
    with _LOCK:
        return dict(_STATS)


def _grid(grid: tuple) -> Grid:
    origin, h, dims = grid
    return Grid(origin=np.asarray(origin, dtype=np.float64), h=float(h),
                dims=tuple(int(d) for d in dims))


def mesh_task(blob: bytes, params: dict[str, float], bounds: np.ndarray, grid: tuple,
              task: PartTask, encode: bool = False) -> Part:
    """Marching cubes of one part (:func:`csdf.mesh.parts.mesh_part`): 12 bytes a vertex
    (its edge inside the cube, uint32, and ``t``) and 12 a face (int32); with
    ``encode``, 6 a face (:meth:`csdf.mesh.parts.Part.encoded`), to go back."""
    fld = worker_field(blob, params, bounds, grid)
    part = mesh_part(fld, _grid(grid), task)
    return part.encoded() if encode else part


def part_summary(part: Part) -> tuple[int, int, np.ndarray, np.ndarray]:
    """What the client needs to lay out a file of the whole mesh: ``(own vertices,
    faces, keys (S,) int64, t (S,))``, the counts and the shared vertices (on the cube's
    faces: grid-wide edge numbers and ``t``), while the part stays on this worker."""
    shared = part.shared()
    return (int(len(shared) - shared.sum()), len(part.faces), part.keys(shared),
            np.ascontiguousarray(part.t[shared]))


def write_part(path: str | None, layout: MeshLayout, part: Part, own_base: int,
               face_base: int, shared_ids: np.ndarray) -> list[tuple[int, np.ndarray]] | None:
    """Write one part's records into the file or shared memory block ``path``
    (:func:`csdf.io.meshstream.mesh_file`, :func:`~csdf.io.meshstream.shared_block`) at
    the places the client planned: its own vertices as vertices ``own_base, ...`` (not
    STL), its faces as faces ``face_base, ...``, its shared vertices numbered
    ``shared_ids (S,)`` (the mesh's vertex numbers, in the part's order). Returns None,
    or the ``(offset, records)`` blocks when this worker does not see ``path`` (or it
    is None): the client writes them."""
    if layout.format == ".stl":
        blocks = [(layout.face_offset(face_base),
                   layout.face_records(part.faces, part.vertices()))]
        return None if path is not None and write_at(path, blocks) else blocks
    n_own = len(part.edges) - len(shared_ids)
    block = map_block(path) if layout.format == ARRAYS and path is not None else None
    if block is not None:  # (positions and faces written in place, in their final form)
        verts = np.frombuffer(block, dtype=np.float64, count=3 * n_own,
                              offset=layout.vertex_offset(own_base)).reshape(-1, 3)
        faces = np.frombuffer(block, dtype=np.int64, count=part.faces.size,
                              offset=layout.face_offset(face_base)).reshape(-1, 3)
    else:
        verts = np.empty((n_own, 3))
        faces = np.empty(part.faces.shape, dtype=np.int64 if layout.format == ARRAYS
                         else np.int32)
    file_part(part.edges, part.t, part.face_indices(), np.asarray(part.cell, dtype=np.int64),
              int(part.size), np.asarray(part.grid.origin, dtype=np.float64),
              float(part.grid.h), int(own_base), np.asarray(shared_ids, dtype=np.int64),
              verts, faces)
    if block is not None:
        del verts, faces  # (the views first: a map with exported buffers cannot close)
        _close_map(block)
        return None
    blocks = [(layout.vertex_offset(own_base), layout.vertex_records(verts)),
              (layout.face_offset(face_base), layout.face_records(faces))]
    return None if layout.format != ARRAYS and path is not None and write_at(path, blocks) \
        else blocks


def _close_map(block: mmap.mmap) -> None:
    """Unmap ``block`` once this task's views of it are gone. A view can outlive its name
    for a moment (a cycle, or a frame a profiler or traceback holds): then collect and
    try again, and if one still holds it, leave the unmapping to that view's end. The
    records are in the shared pages either way (``MAP_SHARED``), so nothing is lost."""
    try:
        block.close()
    except BufferError:
        gc.collect()
        try:
            block.close()
        except BufferError:
            pass


def eval_block(points: np.ndarray, blob: bytes, params: dict[str, float], what: str,
               backend: str, pose: Any) -> np.ndarray:
    """One block of :func:`csdf.distributed.evaluate`: ``points (n, 3)`` to values
    ``(n,)``, gradients ``(n, 3)`` or parameter Jacobians ``(n, P)``."""
    fld = worker_field(blob, params, backend=backend, pose=pose)
    p = np.ascontiguousarray(points, dtype=np.float64)
    if what == "value":
        return fld.value(p)
    if what == "gradient":
        return fld.gradient(p)
    return fld.param_jacobian(p)


def sample_task(blob: bytes, params: dict[str, float], n: int, seed: np.random.SeedSequence,
                volume: bool, kwargs: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """``n`` surface points with normals (or volume points with values) from the child
    seed ``seed``: one chunk of :func:`csdf.distributed.sample_surface` /
    :func:`~csdf.distributed.sample_volume`."""
    from ..sample import sample_surface, sample_volume

    prog = Program.from_bytes(blob)
    rng = np.random.default_rng(seed)
    if volume:
        return sample_volume(prog, n, seed=rng, params=params, check_ranges=False, **kwargs)
    return sample_surface(prog, n, seed=rng, params=params, check_ranges=False, **kwargs)


def fit_task(blob: bytes, cloud: Any, kwargs: dict[str, Any]):
    """One cloud of :func:`csdf.distributed.fit_many`: a :class:`csdf.FitResult`, or the
    error ``(type name, message)`` that stopped it (so one bad scan does not fail the
    batch)."""
    from ..fit import fit
    from ..io import read_point_cloud

    try:
        if isinstance(cloud, (str, Path)):
            cloud = read_point_cloud(cloud)
        if hasattr(cloud, "points"):  # a csdf.io.PointCloud: its recorded viewpoint too
            if "viewpoint" not in kwargs and getattr(cloud, "viewpoint", None) is not None:
                kwargs = {**kwargs, "viewpoint": cloud.viewpoint}
            cloud = cloud.points
        points = np.asarray(cloud, dtype=np.float64)
        return fit(Program.from_bytes(blob), points, **kwargs)
    except Exception as exc:  # noqa: BLE001 (reported for this cloud, the batch goes on)
        return (type(exc).__name__, str(exc))
