"""Evaluators of compiled programs, all with one contract (see ``numpy_backend.evaluate``
and :class:`csdf.backends.registry.PointEvaluator`); :mod:`csdf.backends.registry` lists
them with their capabilities and says how to add one.

* ``'numpy'``: the reference; one NumPy array operation per instruction over chunks;
* ``'interp'``: Numba kernels interpreting the tape over blocks of points, on all cores;
  compiled once for all programs (``interp.py``);
* ``'fast'``: a Numba kernel generated per program structure, vectorised across points,
  on all cores; compiled on first use and cached on disk (``fast.py``);
* ``'auto'``: ``'numpy'`` below ``AUTO_MIN_POINTS`` points unless the fast kernel is
  ready; ``'fast'`` when its kernel is ready (memory or disk) or the call has at least
  ``AUTO_COMPILE_POINTS`` points; else ``'interp'``.

Backends read a program as data and never import :mod:`csdf.compiler` (whose
``Program.__call__`` imports :func:`select`).
"""

from __future__ import annotations

from ..errors import CsdfError
from . import registry

__all__ = ["BACKENDS", "AUTO_MIN_POINTS", "AUTO_COMPILE_POINTS", "select"]

#: ``'auto'`` then the point evaluators of the registry: numpy, interp, fast
BACKENDS = ("auto", *(e.name for e in registry.point_evaluators()))
AUTO_MIN_POINTS = 2048
AUTO_COMPILE_POINTS = 1_000_000


def _named(name: str):
    info = registry.get(name)
    if not info.available():
        raise CsdfError(f"backend {name!r} needs {info.needs or 'a missing library'}, "
                        "which could not be imported")
    return info.load()


def select(name: str, n_points: int, prog=None, mode: str = "value"):
    """The evaluator module for backend ``name`` and a call on ``n_points`` points."""
    if name not in BACKENDS:
        raise CsdfError(f"backend must be one of {', '.join(BACKENDS)}; got {name!r}")
    if name != "auto":
        return _named(name)
    fast = registry.get("fast")
    if fast.available():
        impl = fast.load()
        if prog is not None and impl.is_ready(prog, mode):
            return impl
        if n_points >= AUTO_COMPILE_POINTS:
            return impl
        if n_points >= AUTO_MIN_POINTS:
            return registry.get("interp").load()
    return registry.get("numpy").load()
