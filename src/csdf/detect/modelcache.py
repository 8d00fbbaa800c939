"""Prepared detection models kept on disk between processes.

:func:`csdf.detect` prepares each model once per process (a mesh of it, surface
samples and normals, a bank of parameter sets and each one's height; later its bounds at
other sizes, a finer surface, its exchangeable sizes): about half a second a model, so
that ``csdf detect`` on one scan spent 2.5 of its 7 s preparing the five furniture
models, every call. The results are a pure function of the model's program, of
detection's settings and of csdf's code, so they are kept in files named for all three
(a SHA-256 of the program's bytecode, the settings and every source file of the
package): a file written by other code or for other settings is never read. They hold
only NumPy arrays and JSON text (no pickles), are written to a temporary file and
renamed, and a file that cannot be read is made anew.

Where: ``detect-models`` in the compiled evaluator's cache (``$CSDF_CACHE_DIR``, default
``~/.cache/csdf/kernels``). ``CSDF_MODEL_CACHE=0`` turns the cache off.
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
import tempfile
import zipfile
from pathlib import Path

import numpy as np

from ..field import kernel_cache_dir

__all__ = ["ENV", "directory", "entry_key", "load", "store"]

#: the environment variable that turns the cache off when set to ``0``
ENV = "CSDF_MODEL_CACHE"


@functools.cache
def _code_digest() -> str:
    """SHA-256 of csdf's Python sources (each file's path in the package and its bytes),
    computed once per process: a prepared model depends on the meshing, sampling and
    bounds code as well as on this package's."""
    root = Path(__file__).resolve().parent.parent
    h = hashlib.sha256()
    for p in sorted(root.rglob("*.py")):
        h.update(p.relative_to(root).as_posix().encode())
        h.update(b"\0")
        h.update(p.read_bytes())
    return h.hexdigest()


def entry_key(program: bytes, settings: tuple) -> str:
    """The file name (hex) of a prepared model: a SHA-256 of its program's bytecode
    ``program``, detection's ``settings`` (a tuple with a stable ``repr``) and csdf's
    code."""
    h = hashlib.sha256()
    h.update(_code_digest().encode())
    h.update(repr(settings).encode())
    h.update(program)
    return h.hexdigest()


def directory() -> Path | None:
    """The folder of the kept models (created on demand), or None when the cache is
    turned off or cannot be written."""
    if os.environ.get(ENV, "1").strip() == "0":
        return None
    d = kernel_cache_dir() / "detect-models"
    try:
        d.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None
    return d


def load(key: str) -> tuple[dict[str, np.ndarray], dict] | None:
    """The arrays and the JSON metadata kept under ``key``, or None (no such file, the
    cache off, or a file that cannot be read)."""
    d = directory()
    if d is None:
        return None
    try:
        with np.load(d / f"{key}.npz", allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
        meta = json.loads(str(arrays.pop("meta")))
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
        return None
    if not isinstance(meta, dict):
        return None
    return arrays, meta


def store(key: str, arrays: dict[str, np.ndarray], meta: dict) -> None:
    """Keep ``arrays`` (name to array) and ``meta`` (JSON-ready) under ``key``: written to
    a temporary file in the cache's folder and renamed over the old one. Nothing
    happens when the cache is off or the folder cannot be written."""
    d = directory()
    if d is None:
        return
    tmp = None
    try:
        fd, tmp = tempfile.mkstemp(dir=d, prefix=".model-", suffix=".npz")
        with os.fdopen(fd, "wb") as f:
            np.savez(f, meta=np.array(json.dumps(meta)), **arrays)
        os.replace(tmp, d / f"{key}.npz")
        tmp = None
    except OSError:
        pass
    finally:
        if tmp is not None:
            try:
                os.unlink(tmp)
            except OSError:
                pass
