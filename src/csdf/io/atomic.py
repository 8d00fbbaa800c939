"""Atomic file writes: :func:`atomic_path` writes a temporary file in the destination
folder and renames it over the target, so a failure never leaves a half-written file
behind. Every csdf writer (meshes, point clouds, images, slices, the editor's saves)
goes through it.

Every operating-system error of a write (a folder that cannot hold new files, a full
disk, a target that is a folder, ...) becomes a :class:`csdf.CsdfError` naming the
target and the reason; the temporary file is removed whatever stops the write (an
error, ``KeyboardInterrupt``, or a signal that the caller turns into an exception, as
the command line does for SIGTERM)."""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from ..errors import CsdfError

__all__ = ["atomic_path", "check_writable"]


def _reason(exc: OSError) -> str:
    """The operating system's words for an error (``'Permission denied'``)."""
    return exc.strerror or str(exc) or type(exc).__name__


def check_writable(path: str | os.PathLike) -> Path:
    """``path``'s folder, checked before a long job writes ``path`` (the job's work is
    not lost to a typo in the output's folder).

    Raises:
        CsdfError: ``"cannot write PATH: folder FOLDER does not exist"``, or it is not
            writable.
    """
    target = Path(path)
    folder = target.parent if str(target.parent) else Path(".")
    if not folder.is_dir():
        raise CsdfError(f"cannot write {target}: folder {folder} does not exist")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise CsdfError(f"cannot write {target}: folder {folder} is not writable")
    return folder


@contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; on success it replaces ``path``.

    Raises:
        CsdfError: the folder does not exist, or any ``OSError`` while making the
            temporary file, writing it (inside the ``with`` block) or renaming it:
            ``"cannot write PATH: REASON"``. Nothing is left behind.
    """
    target = Path(path)
    folder = check_writable(target)
    try:
        fd, tmp = tempfile.mkstemp(dir=folder, prefix=f".{target.name}.", suffix=".tmp")
    except OSError as exc:
        raise CsdfError(f"cannot write {target}: {_reason(exc)} (cannot create a file in "
                        f"{folder})") from None
    tmp_path = Path(tmp)
    try:
        os.close(fd)
        umask = os.umask(0)  # mkstemp makes 0600 files: give the usual permissions instead
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        yield tmp_path
        os.replace(tmp_path, target)
    except OSError as exc:
        tmp_path.unlink(missing_ok=True)
        raise CsdfError(f"cannot write {target}: {_reason(exc)}") from None
    except BaseException:
        tmp_path.unlink(missing_ok=True)
        raise
