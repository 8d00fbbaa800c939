"""The scalar operation set shared by expressions, the compiler and every backend.

Each op has a fixed opcode (part of the bytecode format, see ``docs/bytecode.md``),
an arity (1 or 2), and a Table-1 category of the paper (§4.3):

========  ===============================================================
category  ops
========  ===============================================================
add       ``add sub neg``
mul       ``mul square``
div       ``div mod``
call      ``sqrt sin cos tan asin acos atan atan2 exp log floor``
branch    ``min max abs step sign``
========  ===============================================================

Semantics follow IEEE double / float arithmetic as NumPy implements it. Special
cases worth knowing: ``mod(a, b) = a - b*floor(a/b)`` (GLSL ``mod``, result has the
sign of ``b``), ``step(a) = 1 if a >= 0 else 0``, ``sign(0) = 0``; every op
propagates NaN (NaN in, NaN out).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

__all__ = ["OpInfo", "OPS", "OPS_BY_CODE", "CATEGORIES", "numpy_impl"]

CATEGORIES = ("add", "mul", "div", "call", "branch")


@dataclass(frozen=True)
class OpInfo:
    """Static description of one scalar operation."""

    name: str
    code: int
    arity: int
    category: str
    commutative: bool = False


_TABLE = [
    # unary
    ("neg", 1, 1, "add"),
    ("abs", 2, 1, "branch"),
    ("sqrt", 3, 1, "call"),
    ("square", 4, 1, "mul"),
    ("sin", 5, 1, "call"),
    ("cos", 6, 1, "call"),
    ("tan", 7, 1, "call"),
    ("asin", 8, 1, "call"),
    ("acos", 9, 1, "call"),
    ("atan", 10, 1, "call"),
    ("exp", 11, 1, "call"),
    ("log", 12, 1, "call"),
    ("floor", 13, 1, "call"),
    ("step", 14, 1, "branch"),
    ("sign", 15, 1, "branch"),
    # binary
    ("add", 32, 2, "add"),
    ("sub", 33, 2, "add"),
    ("mul", 34, 2, "mul"),
    ("div", 35, 2, "div"),
    ("min", 36, 2, "branch"),
    ("max", 37, 2, "branch"),
    ("atan2", 38, 2, "call"),
    ("mod", 39, 2, "div"),
]
_COMMUTATIVE = {"add", "mul", "min", "max"}

OPS: dict[str, OpInfo] = {
    name: OpInfo(name, code, arity, cat, name in _COMMUTATIVE)
    for name, code, arity, cat in _TABLE
}
OPS_BY_CODE: dict[int, OpInfo] = {info.code: info for info in OPS.values()}


def _step(a):
    return np.heaviside(a, 1.0).astype(np.result_type(a), copy=False)


def _mod(a, b):
    return a - b * np.floor(a / b)


_NUMPY: dict[str, Callable] = {
    "neg": np.negative,
    "abs": np.abs,
    "sqrt": np.sqrt,
    "square": np.square,
    "sin": np.sin,
    "cos": np.cos,
    "tan": np.tan,
    "asin": np.arcsin,
    "acos": np.arccos,
    "atan": np.arctan,
    "exp": np.exp,
    "log": np.log,
    "floor": np.floor,
    "step": _step,
    "sign": np.sign,
    "add": np.add,
    "sub": np.subtract,
    "mul": np.multiply,
    "div": np.divide,
    "min": np.minimum,
    "max": np.maximum,
    "atan2": np.arctan2,
    "mod": _mod,
}


def numpy_impl(name: str) -> Callable:
    """Return the NumPy function computing op ``name`` element-wise."""
    return _NUMPY[name]
