"""Evaluators of compiled programs, all with one contract (see ``numpy_backend.evaluate``
and :class:`csdf.backends.registry.PointEvaluator`); :mod:`csdf.backends.registry` lists
them with their capabilities and says how to add one.

* ``'numpy'``: the reference; one NumPy array operation per instruction over chunks;
* ``'interp'``: Numba kernels interpreting the tape over blocks of points, on all cores;
  compiled once for all programs (``interp.py``);
* ``'fast'``: a Numba kernel generated per program structure, vectorised across points,
  on all cores; compiled on first use and cached on disk (``fast.py``);
* ``'auto'``: for a program with mesh calls (``csdf.from_mesh``), the evaluator that
  runs them (``'numpy'``, whose mesh op is a multithreaded Numba query); else
  ``'numpy'`` below ``AUTO_MIN_POINTS`` points unless the fast kernel is ready;
  ``'fast'`` when its kernel is ready (memory or disk) or the call has at least
  ``AUTO_COMPILE_POINTS`` points; else ``'interp'``.

Backends read a program as data and never import :mod:`csdf.compiler` (whose
``Program.__call__`` imports :func:`select`).
"""

from __future__ import annotations

from ..errors import CsdfError
from . import registry

__all__ = ["BACKENDS", "AUTO_MIN_POINTS", "AUTO_COMPILE_POINTS", "select",
           "check_mesh_calls"]

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


def check_mesh_calls(name: str, prog) -> None:
    """Raise unless evaluator ``name`` can run ``prog`` (one with mesh calls needs an
    evaluator whose registry entry has ``mesh_calls``).

    Raises:
        CsdfError: naming the evaluator and the ones that can run it.
    """
    if prog is None or not getattr(prog, "data", ()):
        return
    info = registry.get(name)
    if not info.mesh_calls:
        able = ", ".join(repr(e.name) for e in registry.point_evaluators() if e.mesh_calls)
        raise CsdfError(
            f"the {name!r} evaluator cannot run this program: it calls the distance to a "
            f"triangle mesh (csdf.from_mesh / polyhedron), which only {able} evaluates "
            "(backend='auto' picks it)")


def select(name: str, n_points: int, prog=None, mode: str = "value"):
    """The evaluator module for backend ``name`` and a call on ``n_points`` points."""
    if name not in BACKENDS:
        raise CsdfError(f"backend must be one of {', '.join(BACKENDS)}; got {name!r}")
    if name != "auto":
        check_mesh_calls(name, prog)
        return _named(name)
    if prog is not None and prog.data:
        return registry.get("numpy").load()
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
