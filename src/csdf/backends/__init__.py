"""Evaluators of compiled programs, all with one contract (see ``numpy_backend.evaluate``).

* ``'numpy'``: the reference; one NumPy array operation per instruction over chunks;
* ``'interp'``: Numba kernels interpreting the tape over blocks of points, on all cores;
  compiled once for all programs (``interp.py``);
* ``'fast'``: a Numba kernel generated per program structure, vectorised across points,
  on all cores; compiled on first use and cached on disk (``fast.py``);
* ``'auto'``: ``'numpy'`` below ``AUTO_MIN_POINTS`` points unless the fast kernel is
  ready; ``'fast'`` when its kernel is ready (memory or disk) or the call has at least
  ``AUTO_COMPILE_POINTS`` points; else ``'interp'``.
"""

from __future__ import annotations

from ..errors import CsdfError

__all__ = ["BACKENDS", "AUTO_MIN_POINTS", "AUTO_COMPILE_POINTS", "select"]

BACKENDS = ("auto", "numpy", "interp", "fast")
AUTO_MIN_POINTS = 2048
AUTO_COMPILE_POINTS = 1_000_000


def select(name: str, n_points: int, prog=None, mode: str = "value"):
    """The evaluator module for backend ``name`` and a call on ``n_points`` points."""
    if name not in BACKENDS:
        raise CsdfError(f"backend must be one of {', '.join(BACKENDS)}; got {name!r}")
    if name == "numpy":
        from . import numpy_backend

        return numpy_backend
    from . import fast, interp

    if name in ("fast", "interp"):
        impl = fast if name == "fast" else interp
        if not impl.available():
            raise CsdfError(f"backend {name!r} needs Numba, which could not be imported")
        return impl
    if fast.available():
        if prog is not None and fast.is_ready(prog, mode):
            return fast
        if n_points >= AUTO_COMPILE_POINTS:
            return fast
        if n_points >= AUTO_MIN_POINTS:
            return interp
    from . import numpy_backend

    return numpy_backend
