"""The row layout and instruction flags shared by the lowering and its kernels.

Rows of a lowered program (:mod:`csdf.backends.lowering`): ``0 .. 2`` x, y, z; from
:data:`UNIFORM_BASE` the parameters, the constants and the parameter-only prefix's
results; then the registers. Column 4 of a lowered instruction holds the flag bits
(:meth:`csdf.backends.lowering.Lowered.flagged_code`).
"""

from __future__ import annotations

from ..layout import N_COORDS

__all__ = ["UNIFORM_BASE", "FLAG_B_ZERO", "FLAG_A_ZERO", "FLAG_OUT_ZERO", "FLAG_TIE_STRICT"]

#: first row of the uniform values (the rows before it hold x, y, z)
UNIFORM_BASE = N_COORDS
#: ``b``'s tangent is structurally zero
FLAG_B_ZERO = 1
#: ``a``'s tangent is structurally zero
FLAG_A_ZERO = 2
#: the result's tangent is structurally zero
FLAG_OUT_ZERO = 4
#: ``min``/``max`` take ``a``'s tangent only where ``a`` wins strictly
FLAG_TIE_STRICT = 8
