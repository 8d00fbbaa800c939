"""The client side of :mod:`csdf.distributed`: cut the job into tasks, hand them to the
cluster, put the answers together."""

from __future__ import annotations

import os
import shutil
import tempfile
import time
from collections import deque
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import CsdfError
from ..field import Field, as_field, check_bounds, choose_backend
from ..io.meshstream import ARRAYS, MeshLayout, check_stream_path, mesh_file, shared_block
from ..mesh.api import mesh_grid, prepare_field
from ..mesh.parts import MAX_TASKS, SharedVertices, Stitcher, default_max_tasks, plan_parts
from ..parallel import cores
from . import tasks

__all__ = ["mesh", "evaluate", "sample_surface", "sample_volume", "fit_many", "connect",
           "disconnect", "MeshFile", "FitFailure", "EVAL_CHUNK", "SAMPLE_CHUNK",
           "TASKS_PER_THREAD", "TASK_SURFACE", "WORKER_ENV", "SHARED_FOLDER"]

#: points per block when :func:`evaluate` is given a NumPy array (~24 MB of points)
EVAL_CHUNK = 1_000_000
#: points per task of :func:`sample_surface` and :func:`sample_volume`
SAMPLE_CHUNK = 1_000_000


@dataclass
class MeshFile:
    """What :func:`mesh` wrote with ``out=``.

    Attributes:
        path: the file; vertices, faces: the counts written; seconds: wall time;
        tasks: parts meshed; super_brick: the largest part's cube edge (voxels);
        voxel_size: the grid's voxel edge (model units); dims: the grid's voxels along
        x, y, z.
    """

    path: Path
    vertices: int
    faces: int
    seconds: float
    tasks: int
    super_brick: int
    voxel_size: float
    dims: tuple[int, int, int]


@dataclass
class FitFailure:
    """A cloud of :func:`fit_many` that could not be fitted.

    Attributes:
        index: its place in the input; source: its path, or ``'array'``; error: the
        exception's type name; message: its text. ``success`` is False, like a failed
        :class:`csdf.FitResult`'s, so a loop can test every entry the same way.
    """

    index: int
    source: str
    error: str
    message: str
    success: bool = False

    def __str__(self) -> str:
        return f"cloud {self.index} ({self.source}): {self.error}: {self.message}"


def _dask():
    """``(dask, distributed)``, or a clear error when the extra is not installed."""
    try:
        import dask
        import distributed
    except ImportError as exc:
        raise CsdfError("csdf.distributed needs Dask: pip install 'csdf[dask]' "
                        f"({exc})") from None
    return dask, distributed


#: the environment of :func:`connect`'s worker processes, set before each starts (Dask's
#: ``distributed.nanny.pre-spawn-environ``; the nanny's own ``env`` comes too late for a
#: worker process that first imports the client's main module, and csdf with it):
#: ``CSDF_THREADS`` (each worker's share of the cores, added by :func:`connect`;
#: measured without it: two workers of a script importing csdf ran 2 mesher threads
#: each on 2 cores) and no ``MALLOC_TRIM_THRESHOLD_`` (Dask sets 65536, which also turns
#: off glibc's adaptive thresholds, so that every buffer above 128 KB is fresh memory:
#: measured, the 1024^3 CSG mesh took 1.53 s of CPU instead of 1.26 s on one thread,
#: 490,000 page faults instead of 140,000). Give a real cluster's workers the same
#: (``docs/distributed.md``).
WORKER_ENV: dict[str, str | None] = {"MALLOC_TRIM_THRESHOLD_": None}


def connect(scheduler: str | None = None, workers: int | None = None,
            threads_per_worker: int = 1, timeout: float = 10.0):
    """A ``distributed.Client``: to the scheduler at ``scheduler`` (``'tcp://host:8786'``),
    or to a new local cluster of ``workers`` processes (closed with the client).

    Raises:
        CsdfError: both or neither given, a bad count, or no scheduler answering within
            ``timeout`` seconds (naming the address).
    """
    _, distributed = _dask()
    if (scheduler is None) == (workers is None):
        raise CsdfError("give a scheduler address or a number of local workers (one)")
    if scheduler is not None:
        try:
            return distributed.Client(scheduler, timeout=timeout)
        except (OSError, TimeoutError) as exc:
            raise CsdfError(f"cannot reach the Dask scheduler at {scheduler!r}: {exc}"
                            ) from None
    if isinstance(workers, bool) or not isinstance(workers, int) or not 1 <= workers <= 1024:
        raise CsdfError(f"workers must be an integer in [1, 1024], got {workers!r}")
    # each worker's share of the cores for csdf's own threads (one thread per worker
    # on 2 cores and 2 workers): without it every worker would start a thread per core
    share = max(1, cores() // workers)
    dask, _ = _dask()
    env = {**dask.config.get("distributed.nanny.pre-spawn-environ", {}), **WORKER_ENV,
           "CSDF_THREADS": str(share)}
    saved = {k: os.environ.pop(k) for k in env if k in os.environ}
    try:
        with dask.config.set({"distributed.nanny.pre-spawn-environ": env}):
            cluster = distributed.LocalCluster(
                n_workers=workers, threads_per_worker=threads_per_worker, processes=True,
                dashboard_address=":0", env={"CSDF_THREADS": str(share)})
    finally:  # (the nanny sets them in this process too, to spawn the workers with them)
        for k in env:
            os.environ.pop(k, None)
        os.environ.update(saved)
    client = distributed.Client(cluster)
    client._csdf_cluster = cluster  # closed by disconnect
    return client


def disconnect(client) -> None:
    """Close a client of :func:`connect` (and the local cluster it started)."""
    cluster = getattr(client, "_csdf_cluster", None)
    client.close()
    if cluster is not None:
        cluster.close()


@contextmanager
def _client(client) -> Iterator[Any]:
    """The client to use: the one given, else the default one (``distributed.get_client``),
    else a local cluster of one worker per core for this call."""
    if client is not None:
        yield client
        return
    _, distributed = _dask()
    try:
        yield distributed.get_client()
        return
    except ValueError:  # no client in this process
        pass
    made = connect(workers=cores())
    try:
        yield made
    finally:
        disconnect(made)


def _ship(shape: Any, params: dict | None, what: str, check_ranges: bool,
          solid: bool = False) -> Field:
    """The field of the caller's model, checked here (its values against their ranges),
    so the workers need not; with ``solid``, a 3D one without a pose."""
    fld = as_field(shape, params, what=what, check_ranges=check_ranges)
    if solid and fld.dim != 3:
        raise CsdfError(f"{what} needs a 3D shape; extrude or revolve a 2D shape first")
    if solid and not fld.pose.is_identity():
        raise CsdfError(f"{what} works on a model in its own frame: give it without its "
                        "pose, and place the result")
    return fld


def _window(client) -> int:
    """Tasks kept in flight: a few per worker, so that results wait on the workers, not
    in this process."""
    return max(4, 3 * max(1, len(client.scheduler_info().get("workers", {}))))


def _blob(fld: Field) -> tuple[bytes, dict[str, float]]:
    return fld.program.to_bytes(), {k: float(v) for k, v in fld.params.items()}


# ---------------------------------------------------------------------- meshing
def mesh(shape: Any, resolution: int | None = None, voxel_size: float | None = None,
         bounds: Any = None, method: str = "mc", params: dict | None = None, *,
         client: Any = None, out: str | os.PathLike | None = None,
         super_brick: int | None = None, max_tasks: int | None = None, progress: bool = True,
         check_ranges: bool = True):
    """A marching-cubes mesh made by a Dask cluster, the same as :func:`csdf.mesh`'s.

    The client descends the octree to cells of :func:`csdf.mesh.parts.plan_level` voxels
    and cuts it into cubes of similar work (:func:`csdf.mesh.parts.plan_parts`), the
    fullest first; each task meshes one from the program's bytes, going on from its
    cells down to bricks, and keeps each vertex as its grid edge inside the cube and its
    place ``t`` along it (:class:`csdf.mesh.parts.Part`). Then the mesh is put together
    in one of three ways (``metadata['csdf']['assembled']``):

    * ``'shared'`` (the workers run on this machine: they see a file made in
      :data:`SHARED_FOLDER`): each part sends its counts and its shared vertices (those
      on its cube's faces, merged here by grid edge), and each worker writes its part's
      vertices and faces, in their final numbers, straight into a block of shared
      memory that becomes the mesh's arrays; the client never touches the bulk;
    * ``'parts'`` (workers elsewhere): the parts come back, 12 bytes a vertex and 6 a
      face (:meth:`csdf.mesh.parts.Part.encoded`), and are stitched here as they arrive
      (:class:`csdf.mesh.parts.Stitcher`);
    * ``'records'`` (no room in the shared folder): as ``'shared'``, but the workers
      send their parts' records and the client writes them.

    Positions are rebuilt with the mesher's own formula, so the result equals
    ``csdf.mesh(shape, resolution, check_thin=False)`` vertex for vertex and face for
    face, up to their order (:func:`csdf.mesh.parts.canonical`), and is watertight where
    that one is.

    Args:
        shape: a 3D :class:`csdf.Shape`, :class:`csdf.Program` or :class:`csdf.Field`.
        resolution, voxel_size, bounds, params, check_ranges: as for :func:`csdf.mesh`
            (default resolution 128; no thin-part search, which needs the whole grid).
        method: ``'mc'`` only (a dual-contouring vertex depends on voxels across the
            tasks' faces).
        client: a ``distributed.Client``; default the current one, else a local
            cluster for this call.
        out: a ``.ply`` or ``.stl`` path: written by the workers themselves, each part
            at the place the client plans from the parts' counts
            (:mod:`csdf.io.meshstream`), so no machine holds the whole mesh and the
            client never touches the bulk (a worker that does not see the path's folder
            sends its records to the client, which writes them); returns a
            :class:`MeshFile` instead of the mesh. The parts wait on their workers
            (Dask spills them to disk under memory pressure) until all are counted.
        super_brick: every task a cube of this edge in voxels (a power of two, at least
            8). Default: cubes of any size, the fullest split first, at most
            ``max_tasks`` of them.
        max_tasks: see ``super_brick``; default :data:`TASKS_PER_THREAD` per worker
            thread of the cluster, at most 96, up to 1024 voxels a side; ``(side / 1024)^2``
            times as many beyond (a task's share of the surface stays the same); and
            no more than one per :data:`TASK_SURFACE` voxels of surface (at least 2 per
            worker thread).
        progress: a progress bar on stderr (Rich).

    Returns:
        ``trimesh.Trimesh`` (``metadata['csdf']`` with ``tasks``, ``super_brick``, the
        largest cube's edge, and ``assembled``), or a :class:`MeshFile` with ``out``.

    Raises:
        CsdfError: bad arguments (as :func:`csdf.mesh`), ``method='dc'``, a 2D shape, a
            posed field, or an ``out`` that cannot be written.
    """
    import trimesh

    if method != "mc":
        raise CsdfError(f"csdf.distributed.mesh makes marching-cubes meshes only "
                        f"(method='mc'), got method={method!r}: a dual-contouring vertex "
                        "depends on the voxels around it, across the tasks' faces; use "
                        "csdf.mesh(..., method='dc') on one machine")
    fld = _ship(shape, params, "csdf.distributed.mesh", check_ranges, solid=True)
    if bounds is not None:
        fld = Field(fld, bounds=check_bounds(bounds))
    grid = mesh_grid(fld.bounds, resolution, voxel_size)
    path = check_stream_path(out) if out is not None else None  # (before the work)
    t0 = time.perf_counter()
    with _client(client) as c:
        prepare_field(fld, grid)
        surface, least = 0, 1
        if max_tasks is None and super_brick is None:
            most = default_max_tasks(grid)  # (MAX_TASKS times the surface's growth)
            threads = _threads(c)
            max_tasks = min(most, round(TASKS_PER_THREAD * threads * most / MAX_TASKS))
            surface, least = TASK_SURFACE, min(max_tasks, 2 * threads)
        plan = plan_parts(fld, grid, super_brick, max_tasks, surface, least)
        blob, pvals = _blob(fld)
        g = (np.asarray(grid.origin, dtype=np.float64), float(grid.h), tuple(grid.dims))
        bounds_ = np.asarray(fld.bounds, dtype=np.float64)
        # (one message to the scheduler for all the tasks; faces encoded when they come
        # back here, not when the workers write them)
        # the workers write the mesh themselves into a file, or into a block of shared
        # memory when they run on this machine; else they send their parts back here
        folder = None if path is not None else _shared_folder(c)
        gather = path is None and folder is None
        parts = c.map(partial(tasks.mesh_task, blob, pvals, bounds_, g, encode=gather),
                      plan, pure=False)
        try:
            if gather:
                verts, faces = _gather_mesh(parts, grid, plan, progress)
                assembled = "parts"
            elif path is None:
                (verts, faces), _, where = _write_parts(
                    c, parts, grid, progress, ARRAYS,
                    lambda lay: shared_block(lay, folder if _room(folder, lay) else None))
                assembled = "records" if where is None else "shared"
            else:
                _, layout, _ = _write_parts(c, parts, grid, progress, path.suffix.lower(),
                                            lambda lay: mesh_file(path, lay))
                counts = (layout.vertices, layout.faces)
        finally:
            for fut in parts:
                fut.cancel()
    seconds = time.perf_counter() - t0
    size = max((task.size for task in plan), default=0)
    if path is not None:
        return MeshFile(path, counts[0], counts[1], seconds, len(plan), size,
                        float(grid.h), tuple(grid.dims))
    m = trimesh.Trimesh(vertices=verts, faces=faces, process=False, validate=False)
    m.metadata["csdf"] = {"method": "mc", "voxel_size": float(grid.h), "dims": grid.dims,
                          "seconds": seconds, "resolution": resolution, "tasks": len(plan),
                          "super_brick": size, "assembled": assembled}
    return m


#: tasks per worker thread of the cluster that :func:`mesh` plans by default (up to
#: 1024 voxels a side): enough that the last ones, the smallest, leave no worker idle
#: for long, few enough that a task's fixed cost (a few ms) stays small
TASKS_PER_THREAD = 8
#: ... but no more than one task per this many voxels of surface (about twice as many
#: triangles; 30-40 ms of meshing on the benchmark's machine), and at least 2 per worker
#: thread: a task costs 5-7 ms beyond its work (scheduling, the octree below its cells,
#: the mesher's set-up; measured on the zoo chair at 1024^3, 0.18 s in one process)
TASK_SURFACE = 1 << 18


def _threads(client) -> int:
    """The cluster's worker threads now (at least 1)."""
    return max(1, sum(client.nthreads().values()))


def _gather_mesh(parts: list, grid, plan: list, progress: bool
                 ) -> tuple[np.ndarray, np.ndarray]:
    """The parts fetched as they finish and stitched in plan order (a deterministic
    vertex order): ``(vertices (V, 3), faces (F, 3) int64)``."""
    st = None
    total = sum(task.weight for task in plan)
    for part, task in zip(_in_order(parts, progress, "meshing parts"), plan):
        if st is None:  # outputs sized from the first (fullest) part: 2x its share
            scale = 2.0 * total / max(1, task.weight)
            st = Stitcher(grid, int(scale * len(part.edges)), int(scale * len(part.faces)))
        st.add(part)
    if st is None:
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
    return st.result()


#: where :func:`mesh` asks workers on this machine to write an in-memory mesh (a shared
#: memory folder; None: never, the parts come back to the client)
SHARED_FOLDER: str | None = "/dev/shm"


def _shared_folder(c) -> str | None:
    """:data:`SHARED_FOLDER` when every worker sees it (they run on this machine: a file
    made here is found there), else None."""
    folder = SHARED_FOLDER
    if folder is None or not os.path.isdir(folder) or not os.access(folder, os.W_OK):
        return None
    fd, probe = tempfile.mkstemp(dir=folder, prefix="csdf-probe-")
    os.close(fd)
    try:
        seen = c.run(os.path.exists, probe)
    finally:
        os.unlink(probe)
    return folder if seen and all(seen.values()) else None


def _room(folder: str, layout: MeshLayout) -> bool:
    """Whether ``folder`` has room for ``layout`` (a tenth to spare)."""
    return shutil.disk_usage(folder).free > 1.1 * layout.size()


def _write_parts(c, parts: list, grid, progress: bool, fmt: str, sink
                 ) -> tuple[Any, MeshLayout, str | None]:
    """The parts written by their workers (:mod:`csdf.io.meshstream`): first their counts
    and shared vertices (merged here, numbered after all the own vertices), then each
    part's records at their planned places in ``sink(layout)``, a file or a shared
    memory block of format ``fmt`` (a worker that does not see it sends its records,
    written here). Returns what the sink gives (a block's arrays), the layout, and the
    path the workers were given (None: they sent their records)."""
    summaries = c.map(tasks.part_summary, parts, pure=False)
    shared = SharedVertices(grid)
    own, n_faces, ids = [], [], []
    for n_own, nf, keys, t in _in_order(summaries, progress, "meshing parts"):
        own.append(n_own)
        n_faces.append(nf)
        ids.append(shared.add(keys, t))
    own_total = int(sum(own))
    layout = MeshLayout(fmt, own_total + shared.count, int(sum(n_faces)))
    own_base = np.concatenate([[0], np.cumsum(own, dtype=np.int64)])
    face_base = np.concatenate([[0], np.cumsum(n_faces, dtype=np.int64)])
    with sink(layout) as fh:
        if layout.format != ".stl" and shared.count:
            fh.write(layout.vertex_offset(own_total), layout.vertex_records(shared.vertices()))
        where = None if fh.path is None else str(Path(fh.path).resolve())
        writes = c.map(partial(tasks.write_part, where, layout), parts,
                       [int(b) for b in own_base[:-1]], [int(b) for b in face_base[:-1]],
                       [own_total + i for i in ids], pure=False)
        try:
            for i, blocks in enumerate(_in_order(writes, progress, "writing parts")):
                parts[i].release()
                for offset, records in blocks or ():
                    fh.write(offset, records)
        finally:
            for fut in writes:
                fut.cancel()
        result = fh.arrays() if layout.format == ARRAYS else None
    return result, layout, where


def _in_order(futures: list, progress: bool, label: str) -> Iterator[Any]:
    """The futures' results in their order, fetched as each finishes (a result that
    comes early waits here for those before it); each future is released once its
    result is given."""
    from distributed import as_completed

    index = {f.key: i for i, f in enumerate(futures)}
    early: dict[int, Any] = {}
    nxt = 0
    with _bar(progress, label, len(futures)) as advance:
        for fut, result in as_completed(futures, with_results=True):
            early[index[fut.key]] = result
            advance()
            while nxt in early:
                futures[nxt].release()
                yield early.pop(nxt)
                nxt += 1


@contextmanager
def _bar(progress: bool, label: str, total: int) -> Iterator[Any]:
    """A transient Rich progress bar on stderr (when ``progress``); yields a function
    that advances it by one."""
    if not progress:
        yield lambda: None
        return
    from rich.progress import Progress

    bar = Progress(transient=True)
    bar.start()
    job = bar.add_task(label, total=total)
    try:
        yield lambda: bar.advance(job)
    finally:
        bar.stop()


def _ordered(submit, items: list, window: int, progress: bool, label: str) -> Iterator[Any]:
    """Results of ``submit(item)`` for every item, in order, with at most ``window`` tasks
    submitted and not yet taken."""
    pending: deque = deque()
    nxt = 0
    with _bar(progress, label, len(items)) as advance:
        try:
            while nxt < len(items) or pending:
                while nxt < len(items) and len(pending) < window:
                    pending.append(submit(items[nxt]))
                    nxt += 1
                fut = pending.popleft()
                result = fut.result()
                fut.release()
                advance()
                yield result
        finally:
            for fut in pending:
                fut.cancel()


# ---------------------------------------------------------------------- evaluation
def evaluate(shape: Any, points: Any, params: dict | None = None, what: str = "value", *,
             backend: str = "auto", chunk: int = EVAL_CHUNK, check_ranges: bool = True):
    """Evaluate a field on a ``dask.array`` of points, block by block (``map_blocks``).

    Args:
        shape: a :class:`csdf.Shape`, :class:`csdf.Program` or :class:`csdf.Field` (a
            posed field is evaluated in the world frame).
        points: ``(N, 3)``: a ``dask.array.Array`` (re-chunked to whole rows if its
            columns are split) or an array-like (cut into blocks of ``chunk`` rows).
        params: parameter values ``{name: value}``.
        what: ``'value'`` (``(N,)`` signed distances), ``'gradient'`` (``(N, 3)``) or
            ``'param_jacobian'`` (``(N, P)``, program parameter order).
        backend: the evaluator (:class:`csdf.Program`); the same on every block, so the
            values equal ``csdf.as_field(shape, params, backend=...)``'s on one machine.
        chunk: rows per block for an array-like.

    Returns:
        a lazy ``dask.array.Array`` float64 (compute it, store it, or reduce it).

    Raises:
        CsdfError: points of another shape, an unknown ``what`` or backend, bad
            parameters.
    """
    _dask()
    import dask.array as da

    if what not in ("value", "gradient", "param_jacobian"):
        raise CsdfError(f"what must be 'value', 'gradient' or 'param_jacobian', got {what!r}")
    fld = _ship(shape, params, "distributed.evaluate", check_ranges)
    choose_backend(backend)  # (checks the name)
    if not isinstance(points, da.Array):
        arr = np.asarray(points, dtype=np.float64)
        if isinstance(chunk, bool) or not isinstance(chunk, int) or chunk < 1:
            raise CsdfError(f"chunk must be a positive integer, got {chunk!r}")
        points = da.from_array(arr, chunks=(chunk, -1))
    if points.ndim != 2 or points.shape[1] != 3:
        raise CsdfError(f"points must have shape (N, 3), got {tuple(points.shape)}")
    if points.dtype != np.float64:
        points = points.astype(np.float64)
    points = points.rechunk({1: 3})
    blob, pvals = _blob(fld)
    pose = None if fld.pose.is_identity() else fld.pose.matrix
    args = (blob, pvals, what, backend, pose)
    if what == "value":
        return points.map_blocks(tasks.eval_block, *args, drop_axis=1, dtype=np.float64,
                                 meta=np.empty((0,), dtype=np.float64))
    cols = 3 if what == "gradient" else len(fld.program.params)
    return points.map_blocks(tasks.eval_block, *args, chunks=(points.chunks[0], (cols,)),
                             dtype=np.float64, meta=np.empty((0, 0), dtype=np.float64))


# ---------------------------------------------------------------------- sampling
def _sample(shape: Any, n: int, seed: Any, params: dict | None, chunk: int, volume: bool,
            check_ranges: bool, kwargs: dict[str, Any]):
    _dask()
    import dask
    import dask.array as da

    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 0:
        raise CsdfError(f"n must be an integer >= 0, got {n!r}")
    n = int(n)
    if isinstance(chunk, bool) or not isinstance(chunk, int) or chunk < 1:
        raise CsdfError(f"chunk must be a positive integer, got {chunk!r}")
    fld = _ship(shape, params, "csdf.distributed sampling", check_ranges, solid=True)
    if isinstance(seed, np.random.Generator):
        raise CsdfError("seed must be None or an integer here (each task gets a child "
                        "seed of it), not a Generator")
    blob, pvals = _blob(fld)
    counts = [min(chunk, n - s) for s in range(0, n, chunk)]
    children = np.random.SeedSequence(seed).spawn(len(counts))
    task = dask.delayed(tasks.sample_task, pure=True)
    a, b = [], []
    for k, child in zip(counts, children):
        d = task(blob, pvals, k, child, volume, kwargs)
        a.append(da.from_delayed(d[0], (k, 3), dtype=np.float64))
        b.append(da.from_delayed(d[1], (k,) if volume else (k, 3), dtype=np.float64))
    if not counts:
        return (da.zeros((0, 3), chunks=(1, 3)),
                da.zeros((0,), chunks=(1,)) if volume else da.zeros((0, 3), chunks=(1, 3)))
    return da.concatenate(a), da.concatenate(b)


def sample_surface(shape: Any, n: int, seed: int | None = None, params: dict | None = None,
                   *, chunk: int = SAMPLE_CHUNK, resolution: int | None = None,
                   check_ranges: bool = True):
    """``n`` points on the surface with normals, as lazy ``dask.array`` s ``(n, 3)``, made
    ``chunk`` at a time by :func:`csdf.sample_surface` from child seeds of ``seed``
    (``numpy.random.SeedSequence(seed).spawn``): the same points for the same ``seed``
    and ``chunk`` on any cluster (not the points of one ``csdf.sample_surface(n, seed)``
    call, which draws from one stream).

    Raises:
        CsdfError: as :func:`csdf.sample_surface`; a ``Generator`` seed.
    """
    return _sample(shape, n, seed, params, chunk, False, check_ranges,
                   {"resolution": resolution})


def sample_volume(shape: Any, n: int, near_surface: float = 0.5, sigma: float | None = None,
                  seed: int | None = None, params: dict | None = None, bounds: Any = None,
                  *, chunk: int = SAMPLE_CHUNK, check_ranges: bool = True):
    """``n`` points in and around the shape with their field values, as lazy
    ``dask.array`` s ``((n, 3), (n,))``: :func:`csdf.sample_volume` ``chunk`` points at a
    time from child seeds of ``seed`` (see :func:`sample_surface`).

    Raises:
        CsdfError: as :func:`csdf.sample_volume`; a ``Generator`` seed.
    """
    return _sample(shape, n, seed, params, chunk, True, check_ranges,
                   {"near_surface": near_surface, "sigma": sigma, "bounds": bounds})


# ---------------------------------------------------------------------- batch fitting
def fit_many(shape: Any, clouds: Any, client: Any = None, *, progress: bool = False,
             **fit_kwargs) -> list:
    """Fit one model to many point clouds, one task per cloud.

    Args:
        shape: a :class:`csdf.Shape` or :class:`csdf.Program` (shipped as its bytes).
        clouds: ``(N_i, 3)`` arrays, :class:`csdf.io.PointCloud` s, paths of point
            clouds (read by the workers: a file system they share), a mix, or a
            ``dask.bag.Bag`` of these. A path's or ``PointCloud``'s recorded viewpoint
            (``csdf scan`` writes it) is used unless ``viewpoint=`` is given.
        client: as for :func:`mesh`.
        progress: a progress bar on stderr.
        **fit_kwargs: passed to :func:`csdf.fit` for every cloud (``estimate=``,
            ``multistart=``, ``viewpoint=``, ...).

    Returns:
        one entry per cloud, in order: a :class:`csdf.FitResult` (the same as
        ``csdf.fit(shape, cloud, **fit_kwargs)`` on one machine), or a
        :class:`FitFailure` for a cloud that could not be read or fitted (the batch
        goes on).

    Raises:
        CsdfError: a bad model; an argument :func:`csdf.fit` does not take.
    """
    import inspect

    from ..fit import fit

    known = set(inspect.signature(fit).parameters) - {"shape", "points"}
    unknown = sorted(set(fit_kwargs) - known)
    if unknown:
        raise CsdfError(f"fit_many: csdf.fit takes no argument {', '.join(unknown)}")
    fld = _ship(shape, None, "distributed.fit_many", True)
    blob = fld.program.to_bytes()
    if hasattr(clouds, "map") and hasattr(clouds, "npartitions"):  # a dask bag
        with _client(client) as c:
            raw = c.compute(clouds.map(lambda cl: (_source(cl),
                                                   tasks.fit_task(blob, cl, fit_kwargs))),
                            sync=True)
        return [_entry(i, src, r) for i, (src, r) in enumerate(raw)]
    items = list(clouds) if isinstance(clouds, Iterable) and not isinstance(
        clouds, (str, bytes, np.ndarray)) else [clouds]
    if isinstance(clouds, np.ndarray) and clouds.ndim == 3:
        items = list(clouds)
    with _client(client) as c:
        results = list(_ordered(
            lambda cl: c.submit(tasks.fit_task, blob, cl, fit_kwargs, pure=False),
            items, _window(c), progress, "fitting clouds"))
    return [_entry(i, _source(cl), r) for i, (cl, r) in enumerate(zip(items, results))]


def _source(cloud: Any) -> str:
    if isinstance(cloud, (str, Path)):
        return str(cloud)
    return "point cloud" if hasattr(cloud, "points") else "array"


def _entry(i: int, source: str, result: Any):
    if isinstance(result, tuple):
        return FitFailure(i, source, result[0], result[1])
    return result
