"""csdf on a Dask cluster (the ``csdf[dask]`` extra): meshing, evaluation, sampling and
batch fitting that outgrow one machine.

* :func:`mesh`: the octree cut into super-bricks, one task each, stitched by grid edge
  into the mesh :func:`csdf.mesh` makes on one machine (``out=`` streams it to disk);
* :func:`evaluate`: values, gradients or parameter Jacobians of a ``dask.array`` of
  points, block by block;
* :func:`sample_surface`, :func:`sample_volume`: very large point counts as lazy
  ``dask.array`` s;
* :func:`fit_many`: one :func:`csdf.fit` per cloud, failures reported per cloud;
* :func:`connect`: a client to a scheduler address, or to a local cluster.

Tasks carry the program's bytes, not pickled shapes; each worker process makes a
field once per job and keeps it (:mod:`.tasks`), so the compiled kernels load once per
worker. ``docs/distributed.md`` says how to run on a real cluster.
"""

from .api import (
    EVAL_CHUNK,
    SAMPLE_CHUNK,
    TASK_SURFACE,
    TASKS_PER_THREAD,
    WORKER_ENV,
    FitFailure,
    MeshFile,
    connect,
    disconnect,
    evaluate,
    fit_many,
    mesh,
    sample_surface,
    sample_volume,
)
from .tasks import worker_stats

__all__ = ["mesh", "evaluate", "sample_surface", "sample_volume", "fit_many", "connect",
           "disconnect", "MeshFile", "FitFailure", "worker_stats", "EVAL_CHUNK",
           "SAMPLE_CHUNK", "TASKS_PER_THREAD", "TASK_SURFACE", "WORKER_ENV"]
